//! Solver parameters shared by the dense and hierarchical solvers, with named presets, and the
//! pieces of the iteration they share (residuals, convergence, finishing a solution).

use serde::Serialize;

use crate::error::{Error, Result};
use crate::health::{self, FailureKind, SolveFailure};
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
    /// Antiradiance from both sides of every surface. Default false: each surface blocks on
    /// the sides [`Self::block_exposed_backs`] decides.
    pub two_sided: bool,
    /// Surfaces whose back is exposed to light ([`crate::model::exposed_backs`]: wrongly
    /// oriented walls, open sheets) also create antiradiance from light arriving at their back,
    /// so a one-sided surface lit from behind absorbs and casts a shadow. Default true; false
    /// gives front-only antiradiance everywhere (exact for closed, consistently oriented
    /// objects).
    pub block_exposed_backs: bool,
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
    /// Largest share of the scene's transport a geometrically coarse link may carry and still
    /// be kept ([`crate::links::LinkParams::flux_share`]): small receivers (furniture, slivers)
    /// are not refined for light they barely carry. 0 turns it off; 0..1e-4;
    /// [`crate::links::FLUX_SHARE`] (1e-5) by default.
    pub flux_share: f64,
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
            block_exposed_backs: true,
            antiradiance: true,
            clamp_negative: true,
            near_quadrature: 4,
            epsilon: 1.0,
            split_depth: 4,
            flux_share: crate::links::FLUX_SHARE,
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
        if !(self.flux_share >= 0.0 && self.flux_share <= 1.0) {
            return Err(Error::Parameter(format!(
                "flux share {} outside 0..=1",
                self.flux_share
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
    /// Forgets the measured contraction ratios (the iteration changed: its sweeps are damped
    /// from now on, see [`crate::health::DAMPING`]).
    pub fn restart(&mut self) {
        self.previous = None;
        self.ratios.clear();
        self.since_extrapolation = 0;
        self.q_at_jump = None;
    }

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

/// Area-weighted relative L1 change between two radiance vectors (NaN when the new vector is
/// not finite, never 0 for a change that overflowed).
pub fn relative_change(patches: &Patches, old: &[[f64; 3]], new: &[[f64; 3]]) -> f64 {
    let (num, den) = change_sums(patches, old, new);
    change_ratio(num, den)
}

/// The area-weighted L1 norms `(sum a |new - old|, sum a |new|)` over patches and RGB channels.
pub fn change_sums(patches: &Patches, old: &[[f64; 3]], new: &[[f64; 3]]) -> (f64, f64) {
    let mut num = 0.0;
    let mut den = 0.0;
    for p in 0..patches.len() {
        let a = patches.area[p];
        for c in 0..3 {
            num += a * (new[p][c] - old[p][c]).abs();
            den += a * new[p][c].abs();
        }
    }
    (num, den)
}

/// The relative change `num / den`: 0 when nothing is lit (`den == 0`), NaN when either sum is
/// not finite (an overflowed sweep must not read as "no change").
pub fn change_ratio(num: f64, den: f64) -> f64 {
    if !(num.is_finite() && den.is_finite()) {
        f64::NAN
    } else if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// The bound [`health::radiance_bound`] of the patches' own emission and albedos (normalized
/// units), for the [`finish`] of a solve of that emission with antiradiance (`antiradiance`
/// true; `None` otherwise: unoccluded radiosity has no such bound).
pub fn emission_bound(patches: &Patches, antiradiance: bool) -> Option<f64> {
    let (e_max, rho_max) = source_and_albedo_max(patches);
    antiradiance.then(|| health::radiance_bound(e_max, rho_max))
}

/// The largest source radiance (any channel, absolute) and the largest albedo over the active
/// patches, the two figures of the bound [`health::radiance_bound`].
pub fn source_and_albedo_max(patches: &Patches) -> (f64, f64) {
    let mut e_max = 0.0f64;
    let mut rho_max = 0.0f64;
    for p in (0..patches.len()).filter(|&p| patches.active[p]) {
        for c in 0..3 {
            let s = patches.source.get(p).map_or(0.0, |s| s[c]);
            e_max = e_max.max((patches.emission[p][c] + s).abs());
            rho_max = rho_max.max(patches.albedo[p][c]);
        }
    }
    (e_max, rho_max)
}

/// Turns normalized per-patch radiance into a [`Solution`]: measures and optionally clamps
/// negative radiance, checks the result's health, removes non-finite values, scales back to the
/// scene's units.
///
/// The checks ([`crate::health`]): a NaN or infinity among the active patches, a largest |B|
/// above 1 + [`health::BOUND_SLACK`] times `bound` (in the patches' normalized units: the
/// bound [`health::radiance_bound`] of the solve's source; `None` where none holds, as for
/// unoccluded radiosity) and negative mass above [`health::NEGATIVE_LIMIT`] of the positive
/// each set `stats.failure` (unless a failure is already there) and so `converged = false`.
/// The figures (`largest_b_over_bound`, `radiance_bound`, `negative_fraction`) are set either
/// way.
pub fn finish(
    patches: &Patches,
    mut radiance: Vec<[f64; 3]>,
    mut stats: SolveStats,
    clamp_negative: bool,
    bound: Option<f64>,
) -> Solution {
    let bound = bound.unwrap_or(0.0);
    let mut largest = 0.0f64;
    let mut finite = true;
    for (p, b) in radiance.iter().enumerate() {
        if patches.active[p] {
            for &x in b {
                finite &= x.is_finite();
                if x.is_finite() {
                    largest = largest.max(x.abs());
                }
            }
        }
    }
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
    let checked = bound > 0.0 && bound.is_finite();
    let ratio = if checked { largest / bound } else { 0.0 };
    stats.largest_b_over_bound = ratio;
    stats.radiance_bound = if checked {
        sanitize(bound * patches.emission_scale)
    } else {
        0.0
    };
    let new_failure = stats.failure.is_none();
    if new_failure {
        let kind = if !finite {
            Some(FailureKind::NonFinite)
        } else if ratio > 1.0 + health::BOUND_SLACK {
            Some(FailureKind::OverBound)
        } else if stats.negative_fraction > health::NEGATIVE_LIMIT {
            Some(FailureKind::NegativeMass)
        } else {
            None
        };
        stats.failure = kind.map(|kind| SolveFailure {
            kind,
            sweep: stats.iterations,
            in_result: true,
            residual: stats.residual,
            change_over_min: 0.0,
            growing_sweeps: 0,
            largest_b_over_bound: ratio,
            bound: 0.0,
            negative_fraction: 0.0,
            max_row_sum: 0.0,
        });
    }
    if let Some(f) = stats.failure.as_mut() {
        // A failure found here is against this call's bound; one found before (during the
        // sweeps, or by the inner solve of exact direct light) keeps the bound it was found with.
        if new_failure {
            f.bound = stats.radiance_bound;
        }
        f.max_row_sum = stats.max_row_sum;
        f.negative_fraction = stats.negative_fraction;
        stats.converged = false;
    }
    Solution::from_normalized(patches, &radiance, stats)
}
