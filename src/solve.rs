//! Solver parameters shared by the dense and hierarchical solvers, with named presets, and the
//! pieces of the iteration they share (residuals, convergence, finishing a solution).

use serde::Serialize;

use crate::error::{Error, Result};
use crate::mesh::Patches;
use crate::solution::{sanitize, Solution, SolveStats};
use crate::transport::CouplingParams;

/// Parameters of an antiradiance solve.
#[derive(Clone, Debug, Serialize)]
pub struct SolverOptions {
    /// Octahedral bins per side (R x R bins over the sphere). 4..16; 8 (64 bins) by default.
    /// More bins sharpen shadows from antiradiance and cost memory and time linearly in R^2.
    pub bins: usize,
    /// Stop when the estimated remaining relative error of B is under this. 1e-4..1e-2; 1e-3.
    pub tol: f64,
    /// Iteration cap; the report says when it was hit. Default 500.
    pub max_iterations: usize,
    /// Antiradiance from both sides of every surface (open scenes with back-lit one-sided
    /// surfaces). Default false: front-only, exact for closed, consistently oriented objects.
    pub two_sided: bool,
    /// Propagate antiradiance at all. Off gives unoccluded radiosity (light through walls); only
    /// useful to show what antiradiance does.
    pub antiradiance: bool,
    /// Clamp negative radiance to 0 in the result (the negative mass is reported either way).
    pub clamp_negative: bool,
    /// Receiver quadrature points per side for near pairs (see [`CouplingParams`]).
    pub near_quadrature: usize,
    /// Link refinement threshold of the hierarchical solver: the largest solid angle either end
    /// of a cluster link may subtend, in mean bins. 0.25..2; smaller is finer. 0 refines every
    /// link down to element pairs (the dense solver's couplings).
    pub epsilon: f64,
    /// Most times the hierarchical solver may split an input triangle in four where a near,
    /// smaller neighbour needs it finer. 0..6; 0 keeps the input mesh.
    pub split_depth: u8,
    /// Exact direct light: the first bounce from the emitters with shadow rays, antiradiance for
    /// the indirect bounces only (see [`crate::direct`]). On in the `default` and `accurate`
    /// presets (it lowered the error on every scene measured: room 2.53% -> 2.14%, Cornell box
    /// 2.19% -> 1.17%, bear in a room 1.57% -> 0.91%), off in `fast`. Skipped, with a warning,
    /// when the scene would cost more than [`crate::direct::DIRECT_LIGHT_BUDGET`] or
    /// [`crate::direct::MAX_SHADOW_RAYS`].
    pub direct_light: bool,
    /// Memory the hierarchical solver may spend caching the geometric factor of every (receiving
    /// element, cluster link) pair, MB. The cache makes each sweep a stream of multiply-adds
    /// (about 3x faster sweeps, which is what relighting needs); a scene whose pairs do not fit
    /// computes them on the fly every sweep instead, with the same result. 8 bytes per pair;
    /// 0 disables it. 1024 by default.
    pub pair_cache_mb: usize,
    /// Anderson acceleration of the hierarchical solver's sweeps: how many past sweeps each new
    /// state mixes ([`crate::accelerate`]). 0 gives plain Jacobi sweeps with the tail
    /// extrapolation. 1..8; 4 by default. The dense solver (the oracle) always sweeps plainly.
    pub acceleration_depth: usize,
    /// Most resident memory the process may hold during a solve, bytes (`--memory-limit`); what
    /// the process holds when the solve starts (scene, patches) counts against it. The solvers
    /// estimate what they will allocate before they allocate it ([`crate::budget`]): a
    /// hierarchical model that does not fit is coarsened (pair cache off, then epsilon doubled
    /// up to [`crate::budget::MAX_COARSE_EPSILON`], then the split depth lowered to 0, then
    /// fewer bins down to [`crate::budget::MIN_COARSE_BINS`] per side; see
    /// [`crate::budget::coarser`]), the exact direct light is skipped when it
    /// does not fit, and a solve that cannot fit even so (or a dense solve that does not fit)
    /// ends with [`Error::Memory`] before allocating; each change is reported. At least 1;
    /// by default half the machine's physical memory ([`crate::budget::default_memory_limit`]:
    /// `MemTotal` of `/proc/meminfo`, 4 GiB where that is unknown).
    pub memory_limit_bytes: u64,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions::default_preset()
    }
}

impl SolverOptions {
    /// Balanced speed and accuracy: 8 x 8 bins, epsilon 1 (the default).
    pub fn default_preset() -> Self {
        SolverOptions {
            bins: 8,
            tol: 1e-3,
            max_iterations: 500,
            two_sided: false,
            antiradiance: true,
            clamp_negative: true,
            near_quadrature: 4,
            epsilon: 1.0,
            split_depth: 4,
            direct_light: true,
            pair_cache_mb: 1024,
            acceleration_depth: 4,
            memory_limit_bytes: crate::budget::default_memory_limit(),
        }
    }

    /// Fastest: 6 x 6 bins, epsilon 2, looser tolerance.
    pub fn fast() -> Self {
        SolverOptions {
            bins: 6,
            tol: 3e-3,
            epsilon: 2.0,
            near_quadrature: 4,
            direct_light: false,
            ..SolverOptions::default_preset()
        }
    }

    /// Most accurate: 12 x 12 bins, epsilon 0.25, tight tolerance.
    pub fn accurate() -> Self {
        SolverOptions {
            bins: 12,
            tol: 3e-4,
            epsilon: 0.25,
            near_quadrature: 6,
            ..SolverOptions::default_preset()
        }
    }

    /// A preset by name: `fast`, `default` or `accurate`.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "fast" => Ok(Self::fast()),
            "default" => Ok(Self::default_preset()),
            "accurate" => Ok(Self::accurate()),
            other => Err(Error::Parameter(format!(
                "unknown preset '{other}' (expected fast, default or accurate)"
            ))),
        }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        if !(1..=64).contains(&self.bins) {
            return Err(Error::Parameter(format!(
                "--bins {} outside 1..=64",
                self.bins
            )));
        }
        if !(self.tol > 0.0 && self.tol < 1.0) {
            return Err(Error::Parameter(format!(
                "--tol {} outside (0, 1)",
                self.tol
            )));
        }
        if self.max_iterations == 0 {
            return Err(Error::Parameter(
                "--max-iterations must be at least 1".into(),
            ));
        }
        if !(1..=16).contains(&self.near_quadrature) {
            return Err(Error::Parameter(format!(
                "near quadrature {} outside 1..=16",
                self.near_quadrature
            )));
        }
        if !(self.epsilon >= 0.0 && self.epsilon.is_finite()) {
            return Err(Error::Parameter(format!(
                "--epsilon {} must be >= 0",
                self.epsilon
            )));
        }
        if self.memory_limit_bytes == 0 {
            return Err(Error::Parameter(
                "--memory-limit must be at least 1 byte".into(),
            ));
        }
        if self.split_depth > 8 {
            return Err(Error::Parameter(format!(
                "--split-depth {} outside 0..=8",
                self.split_depth
            )));
        }
        Ok(())
    }

    /// The coupling parameters these options imply.
    pub fn coupling(&self) -> CouplingParams {
        CouplingParams {
            two_sided: self.two_sided,
            near_quadrature: self.near_quadrature,
            ..CouplingParams::default()
        }
    }
}

/// Tracks residuals across iterations and decides convergence.
///
/// The residual r_k = |B_k - B_(k-1)| / |B_k| underestimates the remaining error when the
/// iteration contracts slowly (albedo near 1): the remaining error is about r_k q / (1 - q) with
/// q the contraction ratio r_k / r_(k-1). Convergence is declared on that estimate.
#[derive(Clone, Debug, Default)]
pub struct Convergence {
    previous: Option<f64>,
    /// Contraction ratios of the last sweeps, newest last.
    ratios: Vec<f64>,
    /// Sweeps since the last extrapolation.
    since_extrapolation: usize,
    /// The contraction ratio at the last extrapolation: the error estimate of the sweep right
    /// after a jump uses it (that sweep's own ratio measures the jump, not the iteration).
    q_at_jump: Option<f64>,
    /// Last residual seen.
    pub residual: f64,
    /// Last estimate of the remaining relative error.
    pub error_estimate: f64,
    /// When set, the contraction ratio used for the error estimate is at least this (an
    /// accelerated iteration's residual ratios understate the plain iteration's, which is what
    /// turns a residual into an error: e = (I - T)^-1 f). The largest albedo bounds it.
    pub contraction_bound: Option<f64>,
}

impl Convergence {
    /// Records a residual; returns true when the estimated remaining error is under `tol`.
    pub fn update(&mut self, residual: f64, tol: f64) -> bool {
        self.residual = residual;
        let q = match self.previous {
            Some(p) if p > 0.0 => (residual / p).min(0.9999),
            _ => self.q_at_jump.unwrap_or(0.9),
        };
        if self.previous.is_some() {
            self.ratios.push(q);
        }
        self.since_extrapolation += 1;
        self.previous = Some(residual);
        let q = q.max(self.contraction_bound.unwrap_or(0.0)).min(0.9999);
        self.error_estimate = if residual == 0.0 {
            0.0
        } else {
            residual * q.max(0.0) / (1.0 - q.max(0.0)) + residual
        };
        self.error_estimate < tol
    }

    /// Records the residual of sweep `iteration` (1-based); true when the solve should stop:
    /// the estimated remaining error is under `tol` and at least [`MIN_SWEEPS`] sweeps ran (the
    /// first ones only propagate emission: light must bounce once and antiradiance must have had
    /// a sweep to cancel it).
    pub fn sweep_done(&mut self, iteration: usize, residual: f64, tol: f64) -> bool {
        self.update(residual, tol) && iteration >= MIN_SWEEPS
    }
}

impl Convergence {
    /// The factor `q / (1 - q)` by which to extrapolate the last sweep's change (`x += k (x_k -
    /// x_(k-1))`, the geometric tail of a linear iteration contracting by `q`), when the
    /// contraction ratio has settled: the last three ratios agree within 2% and lie in (0.05,
    /// 0.9999), and three sweeps have passed since the last extrapolation. `None` otherwise.
    ///
    /// The tail of a Jacobi iteration is dominated by one slowly decaying mode (for a closed
    /// room, the overall light level), so one extrapolation removes most of what many sweeps
    /// would: at albedo 0.75, about half the sweeps; near albedo 1, nearly all of them.
    pub fn extrapolation_factor(&mut self) -> Option<f64> {
        if self.since_extrapolation < 3 || self.ratios.len() < 3 {
            return None;
        }
        let last = &self.ratios[self.ratios.len() - 3..];
        let q = last[2];
        let settled = last.iter().all(|r| (r - q).abs() <= 0.02 * q);
        if !(settled && q > 0.05 && q < 0.9999) {
            return None;
        }
        self.since_extrapolation = 0;
        // The change right after a jump is not a contraction ratio of the plain iteration.
        self.previous = None;
        self.q_at_jump = Some(q);
        self.ratios.clear();
        Some(q / (1.0 - q))
    }
}

/// Fewest sweeps before convergence may be declared.
pub const MIN_SWEEPS: usize = 3;

/// The relative change `num / den` of a sweep (0 when nothing is lit), or infinity when either
/// sum is not finite: the sweep's radiance overflowed, the iteration diverged (an infinite
/// denominator would otherwise give a change of 0 and look converged).
pub fn change_ratio(num: f64, den: f64) -> f64 {
    if !(num.is_finite() && den.is_finite()) {
        f64::INFINITY
    } else if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Area-weighted relative L1 change between two radiance vectors ([`change_ratio`]).
pub fn relative_change(patches: &Patches, old: &[[f64; 3]], new: &[[f64; 3]]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for p in 0..patches.len() {
        let a = patches.area[p];
        for c in 0..3 {
            num += a * (new[p][c] - old[p][c]).abs();
            den += a * new[p][c].abs();
        }
    }
    change_ratio(num, den)
}

/// Turns normalized per-patch radiance into a [`Solution`]: measures and optionally clamps
/// negative radiance, removes non-finite values, scales back to the scene's units.
pub fn finish(
    patches: &Patches,
    mut radiance: Vec<[f64; 3]>,
    mut stats: SolveStats,
    clamp_negative: bool,
) -> Solution {
    let mut negative = 0.0;
    let mut positive = 0.0;
    let mut negative_patches = 0;
    for (p, b) in radiance.iter_mut().enumerate() {
        let a = patches.area[p];
        let mut neg = false;
        for x in b.iter_mut() {
            *x = sanitize(*x);
            if *x < 0.0 {
                negative += a * -*x;
                neg = true;
                if clamp_negative {
                    *x = 0.0;
                }
            } else {
                positive += a * *x;
            }
        }
        negative_patches += neg as usize;
    }
    stats.negative_fraction = if positive > 0.0 {
        negative / positive
    } else {
        0.0
    };
    stats.negative_patches = negative_patches;
    Solution::from_normalized(patches, &radiance, stats)
}
