//! What every solver returns: outgoing radiance per patch and per input triangle, plus statistics.

use serde::Serialize;

use crate::error::Result;
pub use crate::files::sanitize;
use crate::mesh::closed::Outward;
use crate::mesh::Patches;
use crate::solve::health::{self, FailureKind, SolveFailure};

/// What one exact direct-light pass cost ([`crate::solve::direct`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct DirectStats {
    /// Receiving faces (elements' fronts, and the backs of two-sided ones).
    pub receivers: u64,
    /// Receivers some emitter lights before visibility (the others cost no ray).
    pub lit_receivers: u64,
    /// Shadow rays traced, pilot rays included.
    pub shadow_rays: u64,
    /// Lit receivers whose pilot rays all agreed (wholly lit or wholly in shadow), which took
    /// no more rays.
    pub settled_by_pilot: u64,
}

/// What overlapping coplanar patches facing the same way cost a solve ([`crate::mesh::overlap`]).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct OverlapStats {
    /// Patches that another overlaps (visible share below 1).
    pub patches: u64,
    /// Their area that does not show, `sum area * (1 - share)`, over the active patches' area:
    /// the share of the scene's surface given twice.
    pub hidden_area_share: f64,
}

impl OverlapStats {
    /// The figures of `patches` (with their visible shares).
    pub fn of(patches: &Patches) -> OverlapStats {
        let (mut hidden, mut total, mut count) = (0.0, 0.0, 0);
        for p in (0..patches.len()).filter(|&p| patches.active[p]) {
            let share = patches.visible_share(p);
            total += patches.area[p];
            hidden += patches.area[p] * (1.0 - share);
            count += u64::from(share < 1.0);
        }
        OverlapStats {
            patches: count,
            hidden_area_share: if total > 0.0 { hidden / total } else { 0.0 },
        }
    }
}

/// Convergence and health figures of one solve.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SolveStats {
    /// Iterations performed (for the path tracer: samples per patch).
    pub iterations: usize,
    /// Final relative residual (L1, area weighted) of the last iteration; 0 for the path tracer.
    pub residual: f64,
    /// True when the residual went under the tolerance before the iteration cap.
    pub converged: bool,
    /// Per sweep of this solve (dense or hierarchical), its relative change: the L1,
    /// area-weighted change of the radiance over its L1 norm, the figure the convergence
    /// estimate and the health checks read. In sweep order; empty for the path tracer and for
    /// mixes of precomputed lights.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sweep_changes: Vec<f64>,
    /// The sweep after which the solver damped its sweeps' antiradiance because their change
    /// kept growing or stalled, or (1) because the first sweep's rows were deeper than
    /// [`crate::solve::health::DAMP_ROW_SUM`] ([`crate::solve::health::Damping`]); `None` when
    /// every sweep was plain.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damped_after: Option<usize>,
    /// The sweep after which the solver damped its radiance as well, its damped sweeps having
    /// stalled again ([`crate::solve::health::Damping::All`]); `None` when it did not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radiance_damped_after: Option<usize>,
    /// The sweep after which damped antiradiance was held at 0 everywhere, its damped sweeps
    /// having stalled with it open below 0 at shallow rows
    /// ([`crate::solve::health::Guard::floor_open`]); `None` when it was not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor_closed_after: Option<usize>,
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
    /// stand behind one another, which is not an error (see [`crate::solve::health`]). The dense
    /// solver counts every pair; the hierarchical one its exact links only, and its cluster
    /// links too in a convex enclosure (where rows are capped).
    pub max_row_sum: f64,
    /// Receivers whose form-factor row summed above 1 + [`crate::solve::health::ROW_SUM_TOLERANCE`] in
    /// a convex enclosure and was scaled down to 1 (0 elsewhere: see [`crate::solve::health`]).
    pub capped_rows: usize,
    /// The bound on every B the emission and albedos allow, `E_max / (1 - rho_max)`, in the
    /// scene's radiance units (E_max the largest source radiance of the solve); 0 when none is
    /// checked (unoccluded radiosity, or no light).
    pub radiance_bound: f64,
    /// Largest |B| of the result (before clamping) over [`SolveStats::radiance_bound`]; at most
    /// 1 for the exact model, checked against 1 + [`crate::solve::health::BOUND_SLACK`].
    pub largest_b_over_bound: f64,
    /// Why the solve failed, when it did (diverged, non-finite values, radiance beyond the
    /// bound, negative mass comparable to the positive; see [`crate::solve::health`]). A failed solve
    /// has `converged == false` and its radiance is not a solution of the scene:
    /// [`SolveStats::check`] turns it into an error. Left out of the JSON when `None`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<crate::solve::health::SolveFailure>,
    /// Two-sided emitters just in front of a surface whose gap was solved on its own
    /// ([`crate::solve::cavity`]).
    pub covered_emitters: u64,
    /// Coplanar patches facing the same way that overlap ([`crate::mesh::overlap`]); `None`
    /// (left out of the JSON) when none do.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub overlap: Option<OverlapStats>,
    /// Transport links (dense: ordered patch pairs that exchange anything).
    pub links: u64,
    /// Bytes held by the solver's main arrays at their peak.
    pub solver_bytes: u64,
    /// Times the hierarchical solver jumped over the geometric tail of its sweeps (see
    /// [`crate::solve::Convergence::extrapolation_factor`]).
    pub extrapolations: usize,
    /// What the hierarchical solver modelled (channels, antiradiance, stored bins) and what that
    /// saved; `None` for the dense solver and the path tracer.
    pub model: Option<ModelStats>,
    /// Seconds per stage of the hierarchical solver (tree, links, model, iterate); `None` for
    /// the dense solver and the path tracer.
    pub stage_seconds: Option<HierarchyTimings>,
    /// True when exact direct light was asked for but skipped: the scene's emitters would cost
    /// more than [`crate::solve::direct::DIRECT_LIGHT_BUDGET`] unoccluded form factors.
    pub direct_light_skipped: bool,
    /// What the exact direct light cost (receivers, shadow rays); `None` when it was not
    /// computed. Left out of the JSON when `None`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub direct: Option<DirectStats>,
    /// The hierarchical solver's links by kind, with the refinement's counts and times; `None`
    /// for the dense solver and the path tracer.
    pub link_stats: Option<LinkReport>,
    /// Elements solved: the hierarchical solver's leaf triangles after its on-demand splits,
    /// the dense solver's active patches; 0 for the path tracer.
    pub elements: usize,
    /// Per sweep of the hierarchical solver: (element, cluster link) pairs its gather evaluates,
    /// every cluster link into an element or one of its ancestors that is not gathered through
    /// its receiver's field ([`crate::solve::SolverOptions::field_ratio`]); 0 for the other solvers.
    pub element_link_pairs: u64,
    /// Cluster links of the hierarchical solver gathered through their receiver's field
    /// (summed once per sweep at the receiver node); 0 for the other solvers.
    pub field_links: u64,
    /// Cluster links of the hierarchical solver that its refinement made into a receiver too
    /// large for the receiver's field and that were replaced by links into the receiver's
    /// children, where that costs the sweeps less; 0 for the other solvers.
    pub pushed_links: u64,
    /// Per sweep of the hierarchical solver: (element, receiver field) evaluations, every
    /// field of an element's node or one of its ancestors; 0 for the other solvers.
    pub field_evaluations: u64,
    /// Per sweep of the hierarchical solver: the terms its pull sums, a cluster link's sender
    /// elements (or normal groups, for a grouped sender) over every cluster link; 0 for the
    /// other solvers.
    pub pull_terms: u64,
    /// How the hierarchical solver sped up its sweeps: `"anderson"` (Anderson mixing), or
    /// `"extrapolation"` (the geometric tail jump of [`crate::solve::Convergence`]) followed by
    /// why Anderson was off (`acceleration_depth 0`, its history over its own budget, or over
    /// what the memory limit leaves); empty for the other solvers. Either reaches the same
    /// fixed point.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub acceleration: String,
    /// What the memory budget did (limit, estimate, what was coarsened, peak); `None` for the
    /// path tracer.
    pub memory: Option<crate::solve::budget::MemoryStats>,
}

/// The links of a hierarchical solve by kind (`cluster + exact = links`), with what the
/// refinement counted on the way ([`crate::hierarchy::links::LinkStats`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct LinkReport {
    /// Cluster links (node to node, one exchange each).
    pub cluster_links: u64,
    /// Exact element-to-element couplings.
    pub exact_links: u64,
    /// Counts and times of the refinement.
    pub refinement: crate::hierarchy::links::LinkStats,
}

/// Time spent in each stage of a hierarchical solve, seconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HierarchyTimings {
    /// Cluster tree (median splits and our arrays).
    pub tree: f64,
    /// Link refinement including exact couplings.
    pub links: f64,
    /// Deciding what to model: grey and convexity tests, the bins each element stores.
    pub model: f64,
    /// All iterations.
    pub iterate: f64,
    /// Exact direct light (shadow-ray BVH, unoccluded form factors, shadow rays); 0 when off.
    pub direct: f64,
}

/// What the hierarchical solver modelled for one solve, and what it saved.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ModelStats {
    /// Colour channels solved: 1 for a grey scene, 3 otherwise.
    pub channels: usize,
    /// True when antiradiance was propagated (false for a convex enclosure, or when switched off).
    pub antiradiance: bool,
    /// True when the scene is a convex enclosure: all elements see each other unoccluded.
    pub convex_enclosure: bool,
    /// Input patches whose back is exposed to light and blocks it ([`crate::solve::model::exposed_backs`]; all of
    /// them with `two_sided`, none with `block_exposed_backs` off).
    pub back_blocking_patches: u64,
    /// Closed objects whose inside no light reaches ([`crate::mesh::closed`]).
    pub closed_dark_objects: u64,
    /// Their patches that faced inside, solved turned outward and black.
    pub turned_outward_patches: u64,
    /// Faces the light does not reach, solved dark ([`crate::solve::sealed`]): fronts of
    /// one-sided patches, either face of two-sided ones.
    pub sealed_patches: u64,
    /// Antiradiance values stored per sweep state: (element, bin) slots that some link both
    /// writes and reads.
    pub anti_bins_stored: u64,
    /// Slots a solver storing every bin of every element would hold (elements x bins).
    pub anti_bins_full: u64,
    /// Bytes of per-sweep state (two copies of radiance and antiradiance) saved against three
    /// channels and every bin.
    pub bytes_saved: u64,
}

/// One solved element: a piece of an input triangle (or the whole of it), with the radiance of
/// its front face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElementRadiance {
    /// The input triangle it is part of (its index among the scene's triangles).
    pub triangle: u32,
    /// Corners in the scene's own frame and units, counter-clockwise about its front.
    pub corners: [glam::DVec3; 3],
    /// Outgoing radiance B of its front face, RGB, W / (m^2 sr) (negative values clamped to 0
    /// under `SolverOptions::clamp_negative`).
    pub radiance: [f64; 3],
}

/// A solved scene.
#[derive(Clone, Debug, Default)]
pub struct Solution {
    /// Outgoing radiance B per patch, RGB, in the scene's own radiance units.
    pub patch_radiance: Vec<[f64; 3]>,
    /// Outgoing radiance B per input triangle (area-weighted mean of its patches), in input order.
    pub triangle_radiance: Vec<[f64; 3]>,
    /// Outgoing radiance of each patch's back face, RGB, scene units: empty when no patch is
    /// two-sided ([`Patches::two_sided`]), else one value per patch (0 for one-sided patches,
    /// whose backs absorb).
    pub patch_radiance_back: Vec<[f64; 3]>,
    /// The back faces per input triangle, as `triangle_radiance` (empty when no patch is
    /// two-sided).
    pub triangle_radiance_back: Vec<[f64; 3]>,
    /// How the solve went.
    pub stats: SolveStats,
    /// Every solved element's front face, in the solver's element order, when
    /// [`crate::solve::SolverOptions::keep_elements`] asked for them (the hierarchical solver);
    /// empty otherwise. As solved: a closed object with a dark inside is solved facing out
    /// (`mesh::closed`), and its elements are its faces turned out.
    pub elements: Vec<ElementRadiance>,
}

impl SolveStats {
    /// `Ok` unless the solve failed its health checks ([`SolveStats::failure`]); then an
    /// [`crate::Error::Solve`] naming `solver` and what failed, where and by how much.
    pub fn check(&self, solver: &str) -> Result<()> {
        match &self.failure {
            None => Ok(()),
            Some(f) => Err(crate::error::Error::Solve(format!(
                "the {solver} solver failed: {f}"
            ))),
        }
    }
}

impl Solution {
    /// The answer for a scene in which nothing emits and that has no analytic light
    /// ([`Patches::is_dark`]): radiance 0 on every face, converged after no iteration.
    pub fn dark(patches: &Patches) -> Solution {
        let zero = vec![[0.0; 3]; patches.len()];
        let stats = SolveStats {
            converged: true,
            ..SolveStats::default()
        };
        Solution::from_normalized_sides(patches, &zero, &zero, stats)
    }

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
            patch_radiance_back: Vec::new(),
            triangle_radiance_back: Vec::new(),
            stats,
            elements: Vec::new(),
        };
        solution.settle_inactive(patches);
        solution
    }

    /// [`Solution::from_normalized`] with the back faces' radiance too (`normalized_back`: one
    /// value per patch, or empty when no patch is two-sided); one-sided patches' backs are
    /// set to 0.
    pub fn from_normalized_sides(
        patches: &Patches,
        normalized: &[[f64; 3]],
        normalized_back: &[[f64; 3]],
        stats: SolveStats,
    ) -> Solution {
        let mut solution = Solution::from_normalized(patches, normalized, stats);
        if normalized_back.len() == patches.len() && patches.has_two_sided() {
            solution.patch_radiance_back = (0..patches.len())
                .map(|p| {
                    if patches.is_two_sided(p) {
                        normalized_back[p].map(|x| sanitize(x * patches.emission_scale))
                    } else {
                        [0.0; 3]
                    }
                })
                .collect();
            solution.settle_inactive(patches);
        }
        solution
    }

    /// Puts back the faces of this solution, solved on the patches
    /// [`Patches::closed_objects_outward`] made from `patches` (what changed: `outward`): a
    /// turned two-sided patch's solved front is its back face, and its front (inside) has the
    /// dark inside's radiance, 0; every other patch of `patches` with two faces keeps what was
    /// solved (0 behind for the objects' patches made one-sided). A two-sided emitting patch of
    /// such an object has its emission on its face inside (scene units). Call before
    /// [`Solution::settle_inactive`], which remakes the per-triangle values.
    pub fn restore_outward(&mut self, outward: &Outward, patches: &Patches) {
        if !patches.has_two_sided() {
            return;
        }
        self.patch_radiance_back
            .resize(self.patch_radiance.len(), [0.0; 3]);
        for &p in &outward.turned_two_sided {
            let p = p as usize;
            self.patch_radiance_back[p] = self.patch_radiance[p];
            self.patch_radiance[p] = [0.0; 3];
        }
        for &p in &outward.emitting_inside {
            let p = p as usize;
            let inside = if outward.turned_two_sided.binary_search(&(p as u32)).is_ok() {
                &mut self.patch_radiance[p]
            } else {
                &mut self.patch_radiance_back[p]
            };
            *inside = patches.emission[p].map(|e| sanitize(e * patches.emission_scale));
        }
    }

    /// The solution of `patches` by `solve_one_sided`, a solver of one-sided patches: when
    /// `patches` has two-sided patches, they are solved as the back-to-back pairs of one-sided
    /// patches they are equivalent to (each pair's faces cover each other's backs,
    /// [`Patches::with_back_faces`]) and the result is folded back
    /// ([`Solution::fold_back_faces`]).
    pub fn of_one_sided_faces(
        patches: &Patches,
        solve_one_sided: impl FnOnce(&Patches) -> Result<Solution>,
    ) -> Result<Solution> {
        if patches.has_two_sided() {
            let (expanded, back_of) = patches.with_back_faces();
            let solution = solve_one_sided(&expanded)?;
            return Ok(solution.fold_back_faces(patches, &back_of));
        }
        solve_one_sided(patches)
    }

    /// The solution of `patches` from that of [`Patches::with_back_faces`]: the first
    /// `patches.len()` values are the fronts, `back_of[p]` the patch holding `p`'s back face.
    pub fn fold_back_faces(self, patches: &Patches, back_of: &[Option<usize>]) -> Solution {
        let n = patches.len();
        let patch_radiance_back = back_of
            .iter()
            .map(|b| b.map_or([0.0; 3], |k| self.patch_radiance[k]))
            .collect();
        let mut solution = Solution {
            patch_radiance: self.patch_radiance[..n].to_vec(),
            triangle_radiance: Vec::new(),
            patch_radiance_back,
            triangle_radiance_back: Vec::new(),
            stats: self.stats,
            elements: self.elements,
        };
        solution.settle_inactive(patches);
        solution
    }

    /// The radiance leaving input triangle `t` on the side that faces `towards` (a world
    /// direction from the triangle to the viewer; `normal` its front normal): the back face's
    /// when the viewer is behind a two-sided triangle, else the front's.
    pub fn triangle_radiance_seen(
        &self,
        t: usize,
        normal: glam::DVec3,
        towards: glam::DVec3,
    ) -> [f64; 3] {
        match self.triangle_radiance_back.get(t) {
            Some(&back) if normal.dot(towards) < 0.0 => back,
            _ => self.triangle_radiance[t],
        }
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
        if self.patch_radiance_back.len() == patches.len() {
            self.triangle_radiance_back = patches.to_input(&self.patch_radiance_back);
        }
        // A back-to-back twin shows the back face of the triangle it pairs with, and that
        // triangle's front from behind.
        let faces = self.triangle_radiance_back.len() == self.triangle_radiance.len();
        for (u, t) in patches.back_twin.iter().enumerate() {
            if let (Some(t), true) = (t, faces) {
                let t = *t as usize;
                self.triangle_radiance[u] = self.triangle_radiance_back[t];
                self.triangle_radiance_back[u] = self.triangle_radiance[t];
            }
        }
        for p in 0..patches.len() {
            let t = patches.parent[p] as usize;
            let copies = patches.twin.get(t).is_some_and(Option::is_some)
                || patches.back_twin.get(t).is_some_and(Option::is_some);
            if !patches.active[p] && copies {
                self.patch_radiance[p] = self.triangle_radiance[t];
                if let Some(back) = self.patch_radiance_back.get_mut(p) {
                    *back = self.triangle_radiance_back[t];
                }
            }
        }
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

/// The design-note error of `estimate` against `truth`, per input triangle of `scene`.
pub fn error_against(scene: &crate::scene::Scene, estimate: &Solution, truth: &Solution) -> f64 {
    let areas: Vec<f64> = (0..scene.len()).map(|t| scene.area(t)).collect();
    let emissive: Vec<bool> = (0..scene.len()).map(|t| scene.is_emitter(t)).collect();
    relative_error(
        &areas,
        &emissive,
        &estimate.triangle_radiance,
        &truth.triangle_radiance,
    )
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
/// The checks ([`crate::solve::health`]): a NaN or infinity among the active patches, a largest |B|
/// above 1 + [`health::BOUND_SLACK`] times `bound` (in the patches' normalized units: the
/// bound [`health::radiance_bound`] of the solve's source; `None` where none holds, as for
/// unoccluded radiosity) and negative mass above [`health::NEGATIVE_LIMIT`] of the positive
/// each set `stats.failure` (unless a failure is already there) and so `converged = false`.
/// The figures (`largest_b_over_bound`, `radiance_bound`, `negative_fraction`) are set either
/// way.
pub fn finish(
    patches: &Patches,
    radiance: Vec<[f64; 3]>,
    stats: SolveStats,
    clamp_negative: bool,
    bound: Option<f64>,
) -> Solution {
    finish_sides(patches, radiance, Vec::new(), stats, clamp_negative, bound)
}

/// [`finish`] with the back faces' radiance of two-sided patches too (`back`: one value per
/// patch, 0 for one-sided ones, or empty when no patch is two-sided); the checks cover both
/// faces.
pub fn finish_sides(
    patches: &Patches,
    mut front: Vec<[f64; 3]>,
    mut back: Vec<[f64; 3]>,
    mut stats: SolveStats,
    clamp_negative: bool,
    bound: Option<f64>,
) -> Solution {
    let n = front.len();
    if back.len() != n {
        back.clear();
    }
    let bound = bound.unwrap_or(0.0);
    let mut largest = 0.0f64;
    let mut finite = true;
    let faces = |k: usize| if k < n { k } else { k - n };
    let mut radiance: Vec<&mut [f64; 3]> = front.iter_mut().chain(back.iter_mut()).collect();
    for (k, b) in radiance.iter().enumerate() {
        let p = faces(k);
        if patches.active[p] {
            for &x in b.iter() {
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
    for (k, b) in radiance.iter_mut().enumerate() {
        let a = patches.area[faces(k)];
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
    drop(radiance);
    Solution::from_normalized_sides(patches, &front, &back, stats)
}
