//! Solver parameters shared by the dense and hierarchical solvers, with the named presets.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::hierarchy::links::LinkParams;
use crate::solve::Preset;
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
    /// Surfaces whose back is exposed to light ([`crate::solve::model::exposed_backs`]: wrongly
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
    /// be kept ([`crate::hierarchy::links::LinkParams::flux_share`]): small receivers
    /// (furniture, slivers) are not refined for light they barely carry. 0 turns it off;
    /// 0..1e-4; [`crate::hierarchy::links::FLUX_SHARE`] (2e-5) by default.
    pub flux_share: f64,
    /// Faint pairs whose bounding spheres overlap become one cluster link each instead of exact
    /// couplings between their elements ([`crate::hierarchy::links::LinkParams::faint_links`]):
    /// about twice as fast on CAD interiors full of small tessellated objects, and less
    /// accurate (b90_office 1.52% -> 2.34% from its reference). Off by default; on in `fast`.
    pub faint_links: bool,
    /// Receiver fields of the hierarchical solver ([`crate::solve::hierarchical`]): a cluster
    /// link whose receiver's extent is at most this times its distance from the sender (and
    /// whose sender lies on one side of every element below the receiver) is gathered once per
    /// sweep at the receiver node, as its field to second order over the node, instead of at
    /// every element below. The remainder is about `4 ratio^3` of the link's value at the
    /// node's edge. 0 gathers every link per element; 0..0.5; 0.3 by default.
    pub field_ratio: f64,
    /// Exact direct light: the first bounce from the emitters with shadow rays, antiradiance for
    /// the indirect bounces only (see [`crate::solve::direct`]). On in the `default` and `accurate`
    /// presets (it lowered the error on every scene measured: room 2.53% -> 2.14%, Cornell box
    /// 2.19% -> 1.17%, bear in a room 1.57% -> 0.91%), off in `fast`. Skipped, with a warning,
    /// when receivers x emitter groups would be more than
    /// [`crate::solve::direct::DIRECT_LIGHT_BUDGET`] (a scene whose every triangle is a separate
    /// light).
    pub direct_light: bool,
    /// Memory the hierarchical solver may spend caching the geometric factor of every (receiving
    /// element, cluster link) pair, MB. The cache makes each sweep a stream of multiply-adds
    /// (about 3x faster sweeps, which is what relighting needs); a scene whose pairs do not fit
    /// computes them on the fly every sweep instead, with the same result. 8 bytes per pair
    /// left to the per-element gather (the rest go through receiver fields, see
    /// [`Self::field_ratio`]); 0 disables it. 256 by default: the seed room's pairs take 1.3 MB
    /// and the 258k-triangle box's 35 MB; at 1024 the 1M-triangle box cached 523 MB of them
    /// and peaked at 4.4 GB. A solve still sweeping after 10 sweeps, or whose first 3 sweeps
    /// predict 10 more, or whose first sweep's rows damp it, builds the cache then, larger than
    /// this if need be, within what the memory limit leaves: the sweeps that remain pay for it
    /// many times over (b90_office, 14 sweeps: about 550 MB, built after its first). When the
    /// pairs do not fit it at the
    /// start, near links into large receivers are pushed down into the receivers' children
    /// where that costs the sweeps less (the 1M-triangle box: 133M pairs a sweep -> 28M).
    pub pair_cache_mb: usize,
    /// Anderson acceleration of the hierarchical solver's sweeps: how many past sweeps each new
    /// state mixes ([`crate::solve::accelerate`]). 0 gives plain Jacobi sweeps with the tail
    /// extrapolation. 1..8; 4 by default. The dense solver (the oracle) always sweeps plainly.
    pub acceleration_depth: usize,
    /// Most resident memory the process may hold during a solve, bytes (`--memory-limit`); what
    /// the process holds when the solve starts (scene, patches) counts against it. The solvers
    /// estimate what they will allocate before they allocate it ([`crate::solve::budget`]): a
    /// hierarchical model that does not fit is coarsened (pair cache off, then epsilon doubled
    /// up to [`crate::solve::budget::MAX_COARSE_EPSILON`], then fewer bins and a lower split
    /// depth in turn down to [`crate::solve::budget::MIN_COARSE_BINS`] per side and 0; see
    /// [`crate::solve::budget::coarser`]; while a coarser model remains, a model fits only with
    /// its Anderson history), the exact direct light is skipped when it
    /// does not fit, and a solve that cannot fit even so (or a dense solve that does not fit)
    /// ends with [`Error::Memory`] before allocating; each change is reported. At least 1;
    /// `None` (the default) is half the machine's physical memory
    /// ([`crate::memory::default_memory_limit`]: `MemTotal` of `/proc/meminfo`, 4 GiB where that
    /// is unknown), read when the solve starts ([`Self::memory_limit`]).
    pub memory_limit_bytes: Option<u64>,
    /// Keep every solved element's front radiance in [`crate::solve::Solution::elements`]
    /// (`--elements`): the solver's own resolution inside input triangles it split, at about
    /// 100 bytes an element. Default false. The hierarchical solver's elements; the dense
    /// solver and the path tracer keep none (their elements are the patches).
    pub keep_elements: bool,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions::default_preset()
    }
}

impl SolverOptions {
    /// Balanced speed and accuracy: 8 x 8 bins, epsilon 1 (the default). The link and coupling
    /// knobs are those components' own defaults ([`LinkParams::DEFAULT`],
    /// [`CouplingParams::DEFAULT`]), so a component built on its own behaves as in this preset.
    pub const fn default_preset() -> Self {
        SolverOptions {
            bins: 8,
            tol: 1e-3,
            max_iterations: 500,
            two_sided: CouplingParams::DEFAULT.two_sided,
            block_exposed_backs: true,
            antiradiance: true,
            clamp_negative: true,
            near_quadrature: CouplingParams::DEFAULT.near_quadrature,
            epsilon: LinkParams::DEFAULT.epsilon,
            split_depth: LinkParams::DEFAULT.max_split_depth,
            flux_share: LinkParams::DEFAULT.flux_share,
            faint_links: LinkParams::DEFAULT.faint_links,
            field_ratio: 0.3,
            direct_light: true,
            pair_cache_mb: 256,
            acceleration_depth: 4,
            memory_limit_bytes: None,
            keep_elements: false,
        }
    }

    /// Fastest: 6 x 6 bins, epsilon 2, faint pairs as single links, looser tolerance, no exact
    /// direct light.
    pub const fn fast() -> Self {
        SolverOptions {
            bins: 6,
            tol: 3e-3,
            epsilon: 2.0,
            faint_links: true,
            direct_light: false,
            ..SolverOptions::default_preset()
        }
    }

    /// Most accurate: 12 x 12 bins, epsilon 0.25, tight tolerance, finer near quadrature.
    pub const fn accurate() -> Self {
        SolverOptions {
            bins: 12,
            tol: 3e-4,
            epsilon: 0.25,
            near_quadrature: 6,
            ..SolverOptions::default_preset()
        }
    }

    /// A preset by name: `fast`, `default` or `accurate` ([`Preset::from_name`]).
    pub fn preset(name: &str) -> Result<Self> {
        Preset::from_name(name).map(Preset::options).ok_or_else(|| {
            Error::Parameter(format!(
                "unknown preset '{name}' (expected fast, default or accurate)"
            ))
        })
    }

    /// The memory limit of a solve, bytes: [`Self::memory_limit_bytes`], or half the
    /// machine's physical memory when that is `None` ([`crate::memory::default_memory_limit`]).
    pub fn memory_limit(&self) -> u64 {
        self.memory_limit_bytes
            .unwrap_or_else(crate::memory::default_memory_limit)
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        if !(1..=64).contains(&self.bins) {
            return Err(Error::Parameter(format!(
                "SolverOptions::bins {} outside 1..=64",
                self.bins
            )));
        }
        if !(self.tol > 0.0 && self.tol < 1.0) {
            return Err(Error::Parameter(format!(
                "SolverOptions::tol {} outside (0, 1)",
                self.tol
            )));
        }
        if self.max_iterations == 0 {
            return Err(Error::Parameter(
                "SolverOptions::max_iterations must be at least 1".into(),
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
                "SolverOptions::epsilon {} must be >= 0",
                self.epsilon
            )));
        }
        if !(self.flux_share >= 0.0 && self.flux_share <= 1.0) {
            return Err(Error::Parameter(format!(
                "SolverOptions::flux_share {} outside 0..=1",
                self.flux_share
            )));
        }
        if !(self.field_ratio >= 0.0 && self.field_ratio <= 1.0) {
            return Err(Error::Parameter(format!(
                "SolverOptions::field_ratio {} outside 0..=1",
                self.field_ratio
            )));
        }
        if self.memory_limit_bytes == Some(0) {
            return Err(Error::Parameter(
                "SolverOptions::memory_limit_bytes must be at least 1 byte".into(),
            ));
        }
        if self.split_depth > 8 {
            return Err(Error::Parameter(format!(
                "SolverOptions::split_depth {} outside 0..=8",
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
