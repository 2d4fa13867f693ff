//! The hierarchical antiradiance solver: transport over refined links with push/pull.
//!
//! Per sweep (Jacobi, like the dense solver):
//! 1. pull: every cluster link's sender node sums the radiant intensity its elements send along
//!    the link's direction, `I = sum_e a_e (B_e max(0, n_e . w) - A_e[bin(w)] |n_e . w|)` (the
//!    antiradiance term only where it leaves the element: through its back by default);
//! 2. push/gather: every element collects from the links into itself and into each of its
//!    ancestors: irradiance `max(0, -n_e . w) I / (pi d^2)` with its own cosine, and antiradiance
//!    `I / (d^2 Omega_bin)` in the link's bin when the light arrives at its front; plus the exact
//!    couplings of its element links (the same [`crate::transport::couple`] as the dense solver);
//! 3. every element forms `B = E + rho H` and its new antiradiance bins.

mod fields;
mod groups;
mod iterate;
mod live_bins;
mod pair_cache;
mod prepare;
mod sweep;

use fields::*;
use groups::*;
use live_bins::*;
use pair_cache::*;
use sweep::*;

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::Result;
use crate::geometry::bins::Bins;
use crate::geometry::tolerances::{SAME_NORMAL, UNIT_NORMAL_SLACK};
use crate::hierarchy::links::{self, ClusterLink, LinkParams, Links, NodePoint};
use crate::hierarchy::{ClusterTree, NONE};
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solve::accelerate::Anderson;
use crate::solve::budget::{
    self, Budget, HierarchicalCosts, LinkBudget, MemoryStats, ModelCounts, OverBudget,
};
use crate::solve::convergence::{damp_if_damped, end_sweep, start_damping};
use crate::solve::health::{self, Guard};
use crate::solve::model::{self, ModelStats};
pub use crate::solve::solution::HierarchyTimings;
use crate::solve::solution::{Solution, SolveStats};
use crate::solve::{change_ratio, Convergence, SolverOptions};
use crate::transport::gather_entries;

/// A scene prepared for hierarchical solving: tree, links and element arrays. Build it once and
/// solve it as many times as needed (different emission: see [`Prepared::solve_with_emission`]).
pub struct Prepared {
    /// The cluster tree (finalized).
    pub tree: ClusterTree,
    /// The refined links.
    pub links: Links,
    /// The direction bins.
    pub bins: Bins,
    /// Per element: area, unit normal, albedo, emission (normalized), patch.
    elem_area: Vec<f64>,
    elem_normal: Vec<DVec3>,
    elem_center: Vec<DVec3>,
    elem_albedo: Vec<[f64; 3]>,
    elem_patch: Vec<u32>,
    /// Per element: its area times its patch's visible share ([`Patches::visible_share`]),
    /// what it sends by; empty when every share is 1 (it is then `elem_area`, see
    /// [`Prepared::send_area`]).
    elem_send_area: Vec<f64>,
    /// Per element: it blocks light arriving at its back (two-sided coupling).
    elem_back: Vec<bool>,
    /// Per element: two-sided (its back face has a radiance of its own); empty when no element
    /// is.
    elem_two: Vec<bool>,
    /// The two-sided elements in element order: the back faces of [`Prepared::faces`].
    back_faces: Vec<u32>,
    /// Input patches that block light arriving at their back.
    back_blocking_patches: u64,
    /// Normal groups of the large nodes, for the pull.
    groups: SenderGroups,
    /// The antiradiance bins each element stores.
    live: LiveBins,
    /// Which cluster links are gathered through their receiver's field ([`Fields`]).
    fields: Fields,
    /// Cached geometric factors of the (element, cluster link) pairs, when they fit the budget.
    pairs: Option<PairCache>,
    /// What one sweep evaluates ([`Prepared::sweep_work`]).
    work: (u64, u64),
    /// True when every albedo is grey (a grey source is then solved in one channel).
    albedo_grey: bool,
    /// True when the scene is a convex enclosure ([`model::is_convex_enclosure`]).
    convex: bool,
    /// True when antiradiance is propagated: asked for and the scene is not convex.
    use_anti: bool,
    /// Solver options the links were refined for: those asked for, with the epsilon and bins
    /// of the model that fitted the memory limit ([`Prepared::memory`]).
    pub options: SolverOptions,
    /// The memory budget of the solves.
    budget: Budget,
    /// Most memory the Anderson history may take in a solve without deep rows
    /// ([`ACCELERATION_BUDGET_BYTES`]).
    acceleration_budget: u64,
    /// The part of the estimate a solve allocates when it starts and frees when it ends
    /// ([`crate::solve::budget::HierarchicalCosts::state_bytes`] and the fields' sums).
    state_bytes: u64,
    /// The estimate of the model through the sweeps, beside which the Anderson history must
    /// fit: the model's estimate with the solve's state and the exact direct light's result
    /// (not its working memory, freed before the sweeps start).
    sweep_bytes: u64,
    /// What the memory budget did: limit, estimate, what was coarsened.
    memory: MemoryStats,
    /// Build timings.
    pub timings: HierarchyTimings,
}

/// The solver's state over the elements after a solve: radiance per element and antiradiance per
/// element and bin, the source it was solved for, where its iteration stood and the states of
/// the solves before it for other sources (up to [`WARM_BASES`] in all). Pass it back to
/// [`Prepared::solve_with_source`] to warm-start the next solve of the same [`Prepared`] scene,
/// or to [`Prepared::resume_with_source`] to go on with the iteration (interactive relighting).
#[derive(Clone, Debug, Default)]
pub struct ElementState {
    /// Outgoing radiance per element, RGB (normalized units).
    radiance: Vec<[f64; 3]>,
    /// Outgoing radiance of each element's back face (0 for one-sided elements); empty when no
    /// element is two-sided.
    radiance_back: Vec<[f64; 3]>,
    /// Antiradiance per stored (element, bin) slot, `channels` values each.
    anti: Vec<f32>,
    /// Colour channels of `anti`: 1 (grey solve) or 3.
    channels: usize,
    /// The per-face source the state was solved for (RGB, normalized units, face order of
    /// [`Prepared::faces`]).
    source: Vec<[f64; 3]>,
    /// Where the iteration stood ([`Prepared::resume_with_source`] goes on from it).
    resume: Option<Box<Resume>>,
    /// The states of the solves before this one, for other sources (most recent first, at
    /// most [`WARM_BASES`] - 1, without history of their own): a warm start combines them with
    /// this one ([`warm_factors`]).
    earlier: Vec<std::sync::Arc<ElementState>>,
}

/// Most solved states a warm start combines: the warm state and the states of the solves
/// before it for other sources (each kept state holds one more copy of the radiance and
/// antiradiance). A source that moves smoothly from solve to solve (a light moving, a spot
/// sweeping) is close to a combination of the last few, and so is its solution, by linearity;
/// one state alone is only scaled. The seed room's relights (`relight --frames 30`, 29 warm
/// frames): the spot sweep 92 sweeps with one state, 77 with 2, 69 with 3, 65 with 4, 72 with
/// 5; the moved point light 84, 76, 75, 75, 75.
pub const WARM_BASES: usize = 3;

/// Where a solve's iteration stood when it stopped, so that the next solve of the same scene
/// can go on from there.
#[derive(Clone, Debug)]
struct Resume {
    /// Anderson's history. Its differences of sweeps do not depend on the source (the sweep is
    /// linear in it), so a solve of another source keeps them
    /// ([`crate::solve::accelerate::Anderson::new_source`]).
    anderson: Option<Anderson>,
    /// The convergence estimate, health guard and statistics of the source solved, continued
    /// only by a solve of the same source.
    convergence: Convergence,
    guard: Guard,
    /// Sweeps done for this source (over every call that went on with it).
    sweeps: usize,
    max_row_sum: f64,
    extrapolations: usize,
    damped_after: Option<usize>,
    radiance_damped_after: Option<usize>,
    floor_closed_after: Option<usize>,
}

/// Radiance per element, back faces' radiance per element (empty when none is two-sided) and
/// antiradiance per stored slot, in `C` channels.
type ChannelState<const C: usize> = (Vec<[f64; C]>, Vec<[f64; C]>, Vec<[f32; C]>);

impl ElementState {
    /// Bytes of this state's radiance, antiradiance and source (not its earlier states).
    fn bytes(&self) -> u64 {
        (std::mem::size_of_val(self.radiance.as_slice())
            + std::mem::size_of_val(self.radiance_back.as_slice())
            + std::mem::size_of_val(self.anti.as_slice())
            + std::mem::size_of_val(self.source.as_slice())) as u64
    }

    /// This state without its iteration and earlier states: what a later state keeps of it.
    fn without_history(&self) -> ElementState {
        ElementState {
            radiance: self.radiance.clone(),
            radiance_back: self.radiance_back.clone(),
            anti: self.anti.clone(),
            channels: self.channels,
            source: self.source.clone(),
            resume: None,
            earlier: Vec::new(),
        }
    }

    /// Outgoing radiance per element (normalized units, element order of [`Prepared`]).
    pub fn radiance(&self) -> &[[f64; 3]] {
        &self.radiance
    }

    /// Outgoing radiance of each element's back face (normalized units, element order; 0 for
    /// one-sided elements); empty when no element is two-sided.
    pub fn radiance_back(&self) -> &[[f64; 3]] {
        &self.radiance_back
    }

    /// The per-element source the state was solved for (normalized units, element order of
    /// [`Prepared`]).
    pub fn source(&self) -> &[[f64; 3]] {
        &self.source
    }

    /// Sweeps done for the source of this state, over every call that went on with it
    /// ([`Prepared::resume_with_source`]); 0 when unknown.
    pub fn sweeps(&self) -> usize {
        self.resume.as_ref().map_or(0, |r| r.sweeps)
    }

    /// The state in `C` channels, or `None` when it does not belong to a scene with `n`
    /// elements and `slots` stored antiradiance bins. Grey to RGB repeats the channel; RGB to
    /// grey takes the mean.
    fn to_channels<const C: usize>(
        &self,
        n: usize,
        backs: usize,
        slots: usize,
    ) -> Option<ChannelState<C>> {
        let k = self.channels;
        if self.radiance.len() != n
            || self.radiance_back.len() != backs
            || k == 0
            || self.anti.len() != slots * k
        {
            return None;
        }
        let radiance = self.radiance.iter().map(|&b| channels_of(b)).collect();
        let radiance_back = self.radiance_back.iter().map(|&b| channels_of(b)).collect();
        let anti = self
            .anti
            .chunks_exact(k)
            .map(|a| {
                let rgb = [a[0], a[1 % k], a[2 % k]].map(f64::from);
                channels_of::<C>(rgb).map(|x| x as f32)
            })
            .collect();
        Some((radiance, radiance_back, anti))
    }
}

/// One element (leaf triangle after on-demand subdivision) of a prepared scene, unit frame.
#[derive(Clone, Copy, Debug)]
pub struct Element {
    /// Corners, unit frame.
    pub corners: crate::geometry::Tri,
    /// Unit normal (front side).
    pub normal: DVec3,
    /// Area, unit frame.
    pub area: f64,
    /// The input patch (triangle) it is part of.
    pub patch: u32,
}

/// The link parameters implied by solver options.
pub fn link_params(options: &SolverOptions) -> LinkParams {
    LinkParams {
        epsilon: options.epsilon,
        max_split_depth: options.split_depth,
        flux_share: options.flux_share,
        faint_links: options.faint_links,
        ..LinkParams::default()
    }
}

/// Colour channels the sweeps of `patches` need when their source is their emission or the
/// direct light reflected by their albedos: 1 when every albedo and emission is grey, else 3.
fn channels_needed(patches: &Patches) -> usize {
    let grey = (0..patches.len())
        .all(|p| model::is_grey(patches.albedo[p]) && model::is_grey(patches.emission[p]))
        && patches.source.iter().all(|&s| model::is_grey(s));
    if grey {
        1
    } else {
        3
    }
}

impl Prepared {
    /// What the memory budget did: the limit, the estimate of the model solved, what was
    /// coarsened to fit (the peak is filled in by each solve's statistics).
    pub fn memory(&self) -> &MemoryStats {
        &self.memory
    }

    /// Bytes the memory limit leaves for the exact direct light: beside the model's estimate
    /// without the solve's state, which is allocated after the direct light is freed.
    pub(crate) fn spare_bytes(&self) -> u64 {
        self.budget
            .spare(self.memory.estimate_bytes.saturating_sub(self.state_bytes))
    }

    /// Counts the exact direct light, estimated at `bytes` ([`crate::solve::budget::direct_light_bytes`]),
    /// in the model's estimate: the peak is the larger of the model with the direct light and
    /// the model with the solve's state and the direct light's result (`faces` x 24 bytes),
    /// which lives through the sweeps.
    pub(crate) fn note_direct_light(&mut self, bytes: u64, faces: u64) {
        self.memory.estimate_bytes += bytes.saturating_sub(self.state_bytes).max(faces * 24);
        self.sweep_bytes += faces * 24;
    }

    /// Counts `bytes` more in the model's estimate and, when something was left out to fit,
    /// records it (`step`, e.g. `"exact direct light off"`).
    pub(crate) fn note_memory(&mut self, bytes: u64, step: Option<&str>) {
        self.memory.estimate_bytes += bytes;
        if let Some(step) = step {
            self.memory.coarsened.push(step.to_string());
        }
    }

    /// Number of elements (leaf triangles after on-demand subdivision).
    pub fn element_count(&self) -> usize {
        self.elem_area.len()
    }

    /// Per sweep: (element, cluster link) pairs the gather evaluates and terms the pull sums
    /// ([`SolveStats::element_link_pairs`], [`SolveStats::pull_terms`]), counted once when the
    /// model is built.
    pub fn sweep_work(&self) -> (u64, u64) {
        self.work
    }

    /// Counts [`Prepared::sweep_work`] (tree, links and sender groups built).
    fn count_sweep_work(&self) -> (u64, u64) {
        let (tree, links) = (&self.tree, &self.links);
        let pairs = (0..self.element_count())
            .into_par_iter()
            .map(|e| near_links_into_ancestors(tree, links, &self.fields, e) as u64)
            .sum();
        let pull = links
            .cluster
            .par_iter()
            .map(|l| self.pull_terms(l.sender))
            .sum();
        (pairs, pull)
    }

    /// The terms a pull from node `s` sums: its sender groups, or its elements when it pulls
    /// per element.
    fn pull_terms(&self, s: u32) -> u64 {
        if self.groups.is_grouped(s) {
            let (g0, g1) = self.groups.range[s as usize];
            (g1 - g0) as u64
        } else {
            let (e0, e1) = self.tree.nodes[s as usize].elements;
            (e1 - e0) as u64
        }
    }

    /// Bytes held by tree, links and per-sweep arrays (three channels).
    pub fn bytes(&self) -> u64 {
        self.static_bytes() + self.state_bytes(3)
    }

    /// Bytes held by tree, links, element arrays and per-link and per-group sweep sums (three
    /// channels), without the per-element sweep state.
    fn static_bytes(&self) -> u64 {
        let n = self.element_count() as u64;
        let nb = self.bins.len() as u64;
        self.links.bytes()
            + (self.tree.nodes.len() * std::mem::size_of::<crate::hierarchy::Node>()) as u64
            + n * (8 + 24 + 24 + 24 + 4)
            + self.live.bytes()
            + self.pairs.as_ref().map_or(0, PairCache::bytes)
            + self.fields.bytes()
            + self.fields.sweep_bytes(3)
            + self.links.cluster.len() as u64 * 12
            + self.groups.bytes(nb)
    }

    /// The faces the solver gives a radiance: every element's front ([`Prepared::elements`]),
    /// then the back face of every two-sided element in element order (its corners in the
    /// reverse order, its normal negated). The order of `elem_source` in
    /// [`Prepared::solve_with_source`].
    pub fn faces(&self) -> impl Iterator<Item = Element> + '_ {
        let backs = self.back_faces.iter().map(|&e| {
            let front = self.element(e as usize);
            let [a, b, c] = front.corners;
            Element {
                corners: [a, c, b],
                normal: -front.normal,
                ..front
            }
        });
        self.elements().chain(backs)
    }

    /// What [`crate::solve::Solution::elements`] keeps of a solve: empty unless
    /// [`SolverOptions::keep_elements`], else every element's front face
    /// ([`Prepared::elements`]) with its radiance `radiance[e]` (normalized units, as a solve's
    /// [`ElementState`] holds the fronts), plus its patch's emission when `with_emission` (a
    /// solve whose source was the reflected direct light), in the scene's frame and units;
    /// negative radiance clamped to 0 under [`SolverOptions::clamp_negative`].
    ///
    /// # Panics
    /// When `radiance` holds fewer values than there are elements.
    pub fn kept_elements(
        &self,
        patches: &Patches,
        radiance: &[[f64; 3]],
        with_emission: bool,
    ) -> Vec<crate::solve::solution::ElementRadiance> {
        if !self.options.keep_elements {
            return Vec::new();
        }
        let (frame, clamp) = (&patches.frame, self.options.clamp_negative);
        self.elements()
            .zip(radiance)
            .map(|(element, b)| {
                let p = element.patch as usize;
                let emitted = if with_emission {
                    patches.emission[p]
                } else {
                    [0.0; 3]
                };
                let radiance = [0, 1, 2].map(|c| {
                    let x = crate::files::sanitize((b[c] + emitted[c]) * patches.emission_scale);
                    if clamp {
                        x.max(0.0)
                    } else {
                        x
                    }
                });
                crate::solve::solution::ElementRadiance {
                    triangle: patches.parent[p],
                    corners: element.corners.map(|c| frame.world_from_unit(c)),
                    radiance,
                }
            })
            .collect()
    }

    /// Per patch (of `patches` patches): some element of it has a back face
    /// ([`Prepared::faces`]).
    pub fn patches_with_back_faces(&self, patches: usize) -> Vec<bool> {
        let mut with = vec![false; patches];
        for &e in &self.back_faces {
            with[self.elem_patch[e as usize] as usize] = true;
        }
        with
    }

    /// Number of [`Prepared::faces`]: the elements and the two-sided elements' back faces.
    pub fn face_count(&self) -> usize {
        self.element_count() + self.back_faces.len()
    }

    /// Element `e`.
    fn element(&self, e: usize) -> Element {
        Element {
            corners: self.tree.nodes[self.tree.elements[e] as usize].corners,
            normal: self.elem_normal[e],
            area: self.elem_area[e],
            patch: self.elem_patch[e],
        }
    }

    /// The elements, in the order of [`ElementState`] (the front faces of
    /// [`Prepared::faces`]).
    pub fn elements(&self) -> impl ExactSizeIterator<Item = Element> + '_ {
        (0..self.element_count()).map(|e| self.element(e))
    }

    /// Solves with the patches' own emission and the direct light of their analytic lights
    /// (per face, [`Prepared::light_source_of_faces`]).
    pub fn solve(&mut self, patches: &Patches, progress: &Progress) -> (Solution, ElementState) {
        let mut source = self.element_source_sides(&patches.emission, &patches.emission_back());
        crate::mesh::lights::add_into(&mut source, self.light_source_of_faces(patches));
        self.solve_with_source(patches, &source, None, progress)
    }

    /// The reflected direct light (normalized units) on every face ([`Prepared::faces`]): of
    /// `patches.lights`, each piece of a patch with its own (`mesh::lights::faces_source`; near
    /// a point light the pieces differ, where [`Patches::source`] holds only the patch's mean);
    /// without lights, each face's patch's [`Patches::source`] (or `source_back`; 0 where they
    /// are empty).
    pub fn light_source_of_faces(&self, patches: &Patches) -> Vec<[f64; 3]> {
        if patches.lights.is_empty() {
            let of = |per_patch: &[[f64; 3]], p: u32| {
                per_patch.get(p as usize).copied().unwrap_or([0.0; 3])
            };
            let fronts = self.elem_patch.iter().map(|&p| of(&patches.source, p));
            let backs = (self.back_faces.iter())
                .map(|&e| of(&patches.source_back, self.elem_patch[e as usize]));
            return fronts.chain(backs).collect();
        }
        let faces: Vec<_> = self
            .faces()
            .map(|f| (f.corners, f.normal, f.patch))
            .collect();
        crate::mesh::lights::faces_source(patches, &patches.lights, &faces)
    }

    /// Solves for a given per-patch emission (normalized units, as in `Patches::emission`),
    /// optionally warm-starting from a previous [`ElementState`] of this scene.
    /// Returns the solution and the final element state for the next warm start.
    ///
    /// # Panics
    /// When `patch_emission.len() != patches.len()`.
    pub fn solve_with_emission(
        &mut self,
        patches: &Patches,
        patch_emission: &[[f64; 3]],
        warm: Option<&ElementState>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        let source = self.element_source(patch_emission);
        // Patches the tree does not hold (inactive: zero area, duplicates) are settled by
        // `Solution::from_normalized` from their own emission or their twin.
        self.solve_with_source(patches, &source, warm, progress)
    }

    /// The per-element source of a per-patch one (each element takes its patch's value), in
    /// the element order of [`Prepared::elements`].
    ///
    /// # Panics
    /// When a patch of an element is out of range of `patch_source`.
    pub fn element_source(&self, patch_source: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.element_source_sides(patch_source, patch_source)
    }

    /// The per-face source ([`Prepared::faces`]) of per-patch sources of the front faces and of
    /// the back faces (each face takes its patch's value).
    ///
    /// # Panics
    /// When a patch of an element is out of range of either source.
    pub fn element_source_sides(
        &self,
        patch_front: &[[f64; 3]],
        patch_back: &[[f64; 3]],
    ) -> Vec<[f64; 3]> {
        let fronts = self.elem_patch.iter().map(|&p| patch_front[p as usize]);
        let backs =
            (self.back_faces.iter()).map(|&e| patch_back[self.elem_patch[e as usize] as usize]);
        fronts.chain(backs).collect()
    }

    /// The area-weighted means per patch (of `patches` patches) of values given per face
    /// ([`Prepared::faces`]): over the fronts, and over the back faces (0 for a patch without
    /// faces there, and everywhere when `per_face` is empty).
    pub fn patch_means_of_faces(
        &self,
        per_face: &[[f64; 3]],
        patches: usize,
    ) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        if per_face.is_empty() {
            return (vec![[0.0; 3]; patches], vec![[0.0; 3]; patches]);
        }
        let n = self.element_count();
        let front = crate::mesh::patch_means(
            patches,
            (0..n).map(|e| (self.elem_patch[e] as usize, self.elem_area[e], per_face[e])),
        );
        let back = crate::mesh::patch_means(
            patches,
            self.back_faces.iter().enumerate().map(|(k, &e)| {
                let e = e as usize;
                (
                    self.elem_patch[e] as usize,
                    self.elem_area[e],
                    per_face[n + k],
                )
            }),
        );
        let zero =
            |v: Vec<Option<[f64; 3]>>| v.into_iter().map(|x| x.unwrap_or([0.0; 3])).collect();
        (zero(front), zero(back))
    }

    /// Solves `B_e = source_e + rho_e H_e(B)` for a per-element source radiance (normalized
    /// units, element order of [`Prepared::elements`]). With the emission as the source this is
    /// the usual solve; with the reflected direct light as the source it gives the indirect
    /// part on top of exact direct lighting. Warm-starts from `warm` when it belongs to this
    /// scene (same element count and stored bins), else starts from the source.
    ///
    /// Solves one channel when the albedos and the source are grey, three otherwise
    /// ([`crate::solve::model`]); the returned solution is RGB either way.
    ///
    /// # Panics
    /// When `elem_source.len() != self.element_count()`.
    pub fn solve_with_source(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        self.solve_from(patches, elem_source, warm, None, None, progress)
    }

    /// [`Prepared::solve_with_source`] going on from `state` (taken, with its Anderson history),
    /// for interactive relighting:
    ///
    /// - when `state` was solved for this same source, the iteration goes on where it stopped
    ///   (its sweep count, convergence estimate, health checks and Anderson history), so that
    ///   calls with a `deadline` converge over calls (progressive relighting);
    /// - for another source it starts from `state` with each element's radiance moved by the
    ///   change of its source (what the first sweep would do) and keeps Anderson's history,
    ///   whose differences of sweeps do not depend on the source: the slow modes the previous
    ///   solve found are removed from the first step on;
    /// - without a state that belongs to this scene, it solves from the source.
    ///
    /// With a `deadline` it stops after the last sweep expected to end before it (each sweep
    /// expected to take as long as the one before; at least one sweep), with `converged` false
    /// unless the tolerance was reached: call again with the returned state to go on. The
    /// solution's `iterations` are the sweeps of this call; [`ElementState::sweeps`] counts
    /// those of the source over every call.
    ///
    /// # Panics
    /// When `elem_source.len() != self.element_count()`.
    pub fn resume_with_source(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        state: Option<ElementState>,
        deadline: Option<Instant>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        let mut state = state;
        let resume = state.as_mut().and_then(|s| s.resume.take());
        self.solve_from(
            patches,
            elem_source,
            state.as_ref(),
            resume.map(|r| *r),
            deadline,
            progress,
        )
    }

    /// The solve of [`Prepared::solve_with_source`] and [`Prepared::resume_with_source`], in
    /// the channels the source and albedos need.
    fn solve_from(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
        resume: Option<Resume>,
        deadline: Option<Instant>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        assert_eq!(elem_source.len(), self.face_count());
        let grey = self.albedo_grey && elem_source.iter().all(|s| model::is_grey(*s));
        if grey {
            self.solve_channels::<1>(patches, elem_source, warm, resume, deadline, progress)
        } else {
            self.solve_channels::<3>(patches, elem_source, warm, resume, deadline, progress)
        }
    }

    /// Per element, the area it sends by: its area times its patch's visible share.
    fn send_area(&self) -> &[f64] {
        if self.elem_send_area.is_empty() {
            &self.elem_area
        } else {
            &self.elem_send_area
        }
    }

    /// What a sweep reads that does not change between sweeps.
    fn sweep_context(&self) -> SweepContext<'_> {
        SweepContext {
            tree: &self.tree,
            points: &self.links.point,
            bins: &self.bins,
            live: &self.live,
            elem_area: &self.elem_area,
            send_area: self.send_area(),
            elem_normal: &self.elem_normal,
            elem_center: &self.elem_center,
            elem_back: &self.elem_back,
            elem_two: &self.elem_two,
            fields: &self.fields,
            use_anti: self.use_anti,
            two_sided: self.options.two_sided,
        }
    }

    /// Bytes of the per-sweep state with `channels` colour channels.
    fn state_bytes(&self, channels: u64) -> u64 {
        let n = (self.element_count() + self.elem_two.len()) as u64;
        2 * (n * 8 * channels + self.live.slots() as u64 * 4 * channels)
    }
}

/// Per channel, the factors `k_i` that bring `sum_i k_i old_i` closest to `new` (least
/// squares, area weighted; `old` most recent first, at least one). When the older sources add
/// nothing independent (their Gram matrix is singular to [`WARM_INDEPENDENT`]) they are left
/// out, down to the first alone: `k_0 = sum a new old_0 / sum a old_0^2`, 1 where `old_0` is
/// 0 or the sums are not finite. Sums in f64.
fn warm_factors<const C: usize>(
    new: &[[f64; C]],
    old: &[&[[f64; C]]],
    area: &[f64],
) -> Vec<[f64; C]> {
    let m = old.len();
    // Per channel: the Gram matrix of the old sources and their products with the new one.
    let mut gram = vec![[0.0f64; C]; m * m];
    let mut rhs = vec![[0.0f64; C]; m];
    for (e, &a) in area.iter().enumerate() {
        for i in 0..m {
            let x = old[i][e];
            for c in 0..C {
                rhs[i][c] += a * new[e][c] * x[c];
            }
            for j in 0..=i {
                let y = old[j][e];
                for c in 0..C {
                    gram[i * m + j][c] += a * x[c] * y[c];
                }
            }
        }
    }
    let mut k = vec![[0.0f64; C]; m];
    for c in 0..C {
        let solved = (1..=m).rev().find_map(|used| {
            let g = |i: usize, j: usize| gram[i.max(j) * m + i.min(j)][c];
            let b: Vec<f64> = (0..used).map(|i| rhs[i][c]).collect();
            solve_gram(used, &g, &b)
        });
        match solved {
            Some(x) => {
                for (i, v) in x.into_iter().enumerate() {
                    k[i][c] = v;
                }
            }
            None => k[0][c] = 1.0,
        }
    }
    k
}

/// Smallest share of its own squared norm that a source must keep once the sources before it
/// in [`warm_factors`]' basis are projected out (a Cholesky pivot over the diagonal entry) to
/// count as independent of them.
const WARM_INDEPENDENT: f64 = 1e-8;

/// The solution of the `n x n` symmetric system `g x = b` (Cholesky), or `None` when a pivot is
/// not above [`WARM_INDEPENDENT`] times its diagonal entry or the solution is not finite.
fn solve_gram(n: usize, g: &dyn Fn(usize, usize) -> f64, b: &[f64]) -> Option<Vec<f64>> {
    if n == 1 {
        let x = b[0] / g(0, 0);
        return (g(0, 0) > 0.0 && x.is_finite()).then_some(vec![x]);
    }
    let mut l = vec![0.0f64; n * n];
    for i in 0..n {
        for j in 0..=i {
            let sum: f64 = (0..j).map(|p| l[i * n + p] * l[j * n + p]).sum();
            if i == j {
                let pivot = g(i, i) - sum;
                if !(pivot > WARM_INDEPENDENT * g(i, i)) {
                    return None;
                }
                l[i * n + i] = pivot.sqrt();
            } else {
                l[i * n + j] = (g(i, j) - sum) / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0f64; n];
    for i in 0..n {
        let sum: f64 = (0..i).map(|p| l[i * n + p] * y[p]).sum();
        y[i] = (b[i] - sum) / l[i * n + i];
    }
    let mut x = vec![0.0f64; n];
    for i in (0..n).rev() {
        let sum: f64 = (i + 1..n).map(|p| l[p * n + i] * x[p]).sum();
        x[i] = (y[i] - sum) / l[i * n + i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Entries of the flat state (radiance, then antiradiance slots) of `n` elements and `slots`
/// stored bins in `C` channels: what Anderson acceleration mixes.
fn state_len_of<const C: usize>(n: usize, slots: usize) -> usize {
    (n + slots) * C
}

/// The `C` channels (3: RGB as is; 1: the mean) of an RGB triple.
fn channels_of<const C: usize>(rgb: [f64; 3]) -> [f64; C] {
    if C == 3 {
        std::array::from_fn(|c| rgb[c])
    } else {
        [(rgb[0] + rgb[1] + rgb[2]) / 3.0; C]
    }
}

/// RGB from `C` channels (1: grey, repeated).
fn rgb_of<const C: usize>(x: [f64; C]) -> [f64; 3] {
    std::array::from_fn(|c| x[c % C])
}

/// The starts of consecutive pieces of lengths `counts`, and the end of the last: `start[0] =
/// 0`, `start[i + 1] = start[i] + counts[i]` (the layout [`split_by_start`] splits by).
fn starts_of<T: Copy + Default + std::ops::Add<Output = T>>(
    counts: impl ExactSizeIterator<Item = T>,
) -> Vec<T> {
    let mut start = Vec::with_capacity(counts.len() + 1);
    let mut total = T::default();
    start.push(total);
    for c in counts {
        total = total + c;
        start.push(total);
    }
    start
}

/// Splits `data` into consecutive pieces of lengths `start[i + 1] - start[i]`.
fn split_by_start<'a, T, I: Copy + Into<u64>>(
    mut data: &'a mut [T],
    start: &[I],
) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(start.len().saturating_sub(1));
    for w in start.windows(2) {
        let len = (w[1].into() - w[0].into()) as usize;
        let (head, tail) = std::mem::take(&mut data).split_at_mut(len);
        out.push(head);
        data = tail;
    }
    out
}

/// Solves the scene with the hierarchical solver. Preconditions: `options.validate()` passed.
///
/// Errors: [`crate::Error::Memory`] when the model does not fit the memory limit even
/// coarsened ([`Prepared::new`]).
pub fn solve_hierarchical(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    let mut prepared = Prepared::new(patches, options, false)?;
    let (mut solution, state) = prepared.solve(patches, progress);
    solution.elements = prepared.kept_elements(patches, state.radiance(), false);
    Ok(solution)
}

/// Cluster links into element `e` and into each of its ancestors that are gathered per
/// element (not through a field): the (element, link) pairs of `e` in a sweep's gather.
fn near_links_into_ancestors(
    tree: &ClusterTree,
    links: &Links,
    fields: &Fields,
    e: usize,
) -> usize {
    let mut total = 0;
    let mut node = tree.elements[e];
    while node != NONE {
        total += fields.near_links(links, node).len();
        node = tree.nodes[node as usize].parent;
    }
    total
}

/// Most memory the Anderson history may take; above it the solver extrapolates the tail
/// instead, unless the first sweep finds rows deep enough to damp its antiradiance
/// ([`crate::solve::health::DAMP_ROW_SUM`]): such a solve takes the history after that sweep,
/// within the memory limit. The damped sweeps of an office converted from MGF (26,932
/// triangles, its largest row sum 22.2, a 547 MB history) amplified a mode by about 1.14 per
/// sweep and failed at sweep 43; mixed, it converges (docs/stability.md). Well-meshed scenes of
/// a million triangles, whose rows are shallow, converge without it (8 to 10 sweeps) and keep
/// their memory.
const ACCELERATION_BUDGET_BYTES: u64 = 512 << 20;

/// Sweeps after which a solve still going builds the pair cache it was built without (its
/// factors over [`crate::solve::SolverOptions::pair_cache_mb`]), within what the memory limit
/// leaves; a solve whose contraction after [`crate::solve::MIN_SWEEPS`] sweeps predicts at
/// least this many more builds it then ([`crate::solve::Convergence::sweeps_left`]). Solves of
/// well-meshed scenes end before it (the seed room 6 sweeps, the boxes 8 to 10, the classroom
/// 9; the 1M-triangle box, whose pairs do not fit the cache's own budget, predicts 6 more after
/// its third), so their peak memory is unchanged. b90_office predicts 23 more after its third
/// sweep (26 in all): its cache built then instead of after the 10th took it from 55.7 / 57.5
/// s to 43.0 / 50.2 s (two alternated pairs), the same result and peak; the bear in a room
/// subdivided to 969,224 triangles predicts 10.5 (12 in all): 36.8 / 39.1 s -> 29.3 / 31.5 s,
/// the same peak. A solve whose first sweep's rows damp its antiradiance from the second
/// ([`crate::solve::health::DAMP_ROW_SUM`]) builds it after that first sweep: every such solve
/// measured took 13 sweeps or more (b90_office 14, 13 at the `fast` preset, two-sided 18; the
/// generated office 50).
const LATE_PAIR_CACHE_SWEEPS: usize = 10;

#[cfg(test)]
mod tests;
