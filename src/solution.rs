//! What every solver returns: outgoing radiance per patch and per input triangle, plus statistics.

use serde::Serialize;

use crate::mesh::Patches;

/// Convergence and health figures of one solve.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SolveStats {
    /// Iterations performed (for the path tracer: samples per patch).
    pub iterations: usize,
    /// Final relative residual (L1, area weighted) of the last iteration; 0 for the path tracer.
    pub residual: f64,
    /// True when the residual went under the tolerance before the iteration cap.
    pub converged: bool,
    /// The sweep after which the solver damped its sweeps because their change kept growing
    /// ([`crate::health::DAMPING`]); `None` when every sweep was plain.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damped_after: Option<usize>,
    /// Area-weighted mass of negative radiance before clamping, relative to the positive mass:
    /// sum a_p max(0, -B_p,c) / sum a_p max(0, B_p,c), both sums over patches p and RGB
    /// channels c (one ratio, not a mean of per-channel ratios).
    pub negative_fraction: f64,
    /// Number of patches whose radiance was negative in some channel (before clamping); with no
    /// `--max-edge` splitting, the number of negative rows of the per-triangle CSV under
    /// `--keep-negative` (tested in tests/stability.rs).
    pub negative_patches: usize,
    /// Largest receiver form-factor row sum, before any capping: the unoccluded form factors of
    /// every sender a receiver reads (through the sender's front, and through its back where
    /// antiradiance can leave it). 1 in a closed convex enclosure; above 1 wherever surfaces
    /// stand behind one another, which is not an error (see [`crate::health`]). The dense
    /// solver counts every pair; the hierarchical one its exact links only, and its cluster
    /// links too in a convex enclosure (where rows are capped).
    pub max_row_sum: f64,
    /// Receivers whose form-factor row summed above 1 + [`crate::health::ROW_SUM_TOLERANCE`] in
    /// a convex enclosure and was scaled down to 1 (0 elsewhere: see [`crate::health`]).
    pub capped_rows: usize,
    /// The bound on every B the emission and albedos allow, `E_max / (1 - rho_max)`, in the
    /// scene's radiance units (E_max the largest source radiance of the solve); 0 when none is
    /// checked (unoccluded radiosity, or no light).
    pub radiance_bound: f64,
    /// Largest |B| of the result (before clamping) over [`SolveStats::radiance_bound`]; at most
    /// 1 for the exact model, checked against 1 + [`crate::health::BOUND_SLACK`].
    pub largest_b_over_bound: f64,
    /// Why the solve failed, when it did (diverged, non-finite values, radiance beyond the
    /// bound, negative mass comparable to the positive; see [`crate::health`]). A failed solve
    /// has `converged == false` and its radiance is not a solution of the scene:
    /// [`SolveStats::check`] turns it into an error. Left out of the JSON when `None`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<crate::health::SolveFailure>,
    /// Transport links (dense: ordered patch pairs that exchange anything).
    pub links: u64,
    /// Bytes held by the solver's main arrays at their peak.
    pub solver_bytes: u64,
    /// Times the hierarchical solver jumped over the geometric tail of its sweeps (see
    /// [`crate::solve::Convergence::extrapolation_factor`]).
    pub extrapolations: usize,
    /// What the hierarchical solver modelled (channels, antiradiance, stored bins) and what that
    /// saved; `None` for the dense solver and the path tracer.
    pub model: Option<crate::model::ModelStats>,
    /// Seconds per stage of the hierarchical solver (tree, links, model, iterate); `None` for
    /// the dense solver and the path tracer.
    pub stage_seconds: Option<crate::hierarchical::HierarchyTimings>,
    /// True when exact direct light was asked for but skipped: the scene's emitters would cost
    /// more than [`crate::direct::DIRECT_LIGHT_BUDGET`] unoccluded form factors.
    pub direct_light_skipped: bool,
    /// The hierarchical solver's links by kind, with the refinement's counts and times; `None`
    /// for the dense solver and the path tracer.
    pub link_stats: Option<LinkReport>,
    /// Elements solved: the hierarchical solver's leaf triangles after its on-demand splits,
    /// the dense solver's active patches; 0 for the path tracer.
    pub elements: usize,
    /// What the memory budget did (limit, estimate, what was coarsened, peak); `None` for the
    /// path tracer.
    pub memory: Option<crate::budget::MemoryStats>,
}

/// The links of a hierarchical solve by kind (`cluster + exact = links`), with what the
/// refinement counted on the way ([`crate::links::LinkStats`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct LinkReport {
    /// Cluster links (node to node, one exchange each).
    pub cluster_links: u64,
    /// Exact element-to-element couplings.
    pub exact_links: u64,
    /// Counts and times of the refinement.
    pub refinement: crate::links::LinkStats,
}

/// A solved scene.
#[derive(Clone, Debug, Default)]
pub struct Solution {
    /// Outgoing radiance B per patch, RGB, in the scene's own radiance units.
    pub patch_radiance: Vec<[f64; 3]>,
    /// Outgoing radiance B per input triangle (area-weighted mean of its patches), in input order.
    pub triangle_radiance: Vec<[f64; 3]>,
    /// How the solve went.
    pub stats: SolveStats,
}

impl SolveStats {
    /// `Ok` unless the solve failed its health checks ([`SolveStats::failure`]); then an
    /// [`crate::Error::Solve`] naming `solver` and what failed, where and by how much.
    pub fn check(&self, solver: &str) -> crate::Result<()> {
        match &self.failure {
            None => Ok(()),
            Some(f) => Err(crate::Error::Solve(format!(
                "the {solver} solver failed: {f}"
            ))),
        }
    }
}

impl Solution {
    /// Builds a solution from per-patch radiance given in the patches' normalized emission units.
    /// Inactive patches are then settled as [`Solution::settle_inactive`] describes, whatever
    /// value `normalized` gave them.
    pub fn from_normalized(
        patches: &Patches,
        normalized: &[[f64; 3]],
        stats: SolveStats,
    ) -> Solution {
        let patch_radiance: Vec<[f64; 3]> = normalized
            .iter()
            .map(|b| b.map(|x| sanitize(x * patches.emission_scale)))
            .collect();
        let mut solution = Solution {
            patch_radiance,
            triangle_radiance: Vec::new(),
            stats,
        };
        solution.settle_inactive(patches);
        solution
    }

    /// Gives inactive patches the values the model fixes for them and recomputes the
    /// per-triangle radiance: a zero-area patch keeps B = E (scene units), a patch of a
    /// duplicate triangle ([`Patches::twin`]) takes the radiance of the triangle it repeats.
    /// Idempotent; a solution whose patch count does not match `patches` is left as it is.
    pub fn settle_inactive(&mut self, patches: &Patches) {
        if self.patch_radiance.len() != patches.len() {
            return;
        }
        for p in 0..patches.len() {
            if !patches.active[p] {
                self.patch_radiance[p] =
                    patches.emission[p].map(|e| sanitize(e * patches.emission_scale));
            }
        }
        self.triangle_radiance = patches.to_input(&self.patch_radiance);
        for p in 0..patches.len() {
            let t = patches.parent[p] as usize;
            if !patches.active[p] && patches.twin.get(t).is_some_and(Option::is_some) {
                self.patch_radiance[p] = self.triangle_radiance[t];
            }
        }
    }
}

/// Replaces a non-finite value by 0 so that no NaN or infinity ever reaches an output.
pub fn sanitize(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

/// The design note's error: area-weighted relative L1 error over non-emissive triangles, mean
/// over RGB channels, of `estimate` against `truth` (per input triangle). Channels where the
/// truth is all zero are skipped; returns 0 when nothing is lit.
pub fn relative_error(
    areas: &[f64],
    emissive: &[bool],
    estimate: &[[f64; 3]],
    truth: &[[f64; 3]],
) -> f64 {
    let mut sum = 0.0;
    let mut channels = 0;
    for c in 0..3 {
        let mut num = 0.0;
        let mut den = 0.0;
        for t in 0..areas.len() {
            if emissive[t] {
                continue;
            }
            num += areas[t] * (estimate[t][c] - truth[t][c]).abs();
            den += areas[t] * truth[t][c];
        }
        if den > 0.0 {
            sum += num / den;
            channels += 1;
        }
    }
    if channels == 0 {
        0.0
    } else {
        sum / channels as f64
    }
}
