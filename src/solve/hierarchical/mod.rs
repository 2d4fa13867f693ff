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

mod groups;
mod live_bins;
mod pair_cache;
mod sweep;

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
    /// What the memory budget did: limit, estimate, what was coarsened.
    memory: MemoryStats,
    /// Build timings.
    pub timings: HierarchyTimings,
}

/// The solver's state over the elements after a solve: radiance per element and antiradiance per
/// element and bin, the source it was solved for and where its iteration stood. Pass it back to
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
}

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
}

/// Radiance per element, back faces' radiance per element (empty when none is two-sided) and
/// antiradiance per stored slot, in `C` channels.
type ChannelState<const C: usize> = (Vec<[f64; C]>, Vec<[f64; C]>, Vec<[f32; C]>);

impl ElementState {
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
    /// Builds the tree and refines the links for `patches` within the memory limit of
    /// `options` ([`SolverOptions::memory_limit_bytes`], see [`crate::solve::budget`]): a model whose
    /// estimate does not fit is coarsened step by step ([`budget::coarser`]; the pair cache is
    /// left out first), and [`Prepared::memory`] says what was changed. `record_culled` keeps
    /// the culled pairs (for [`links::validate`]).
    ///
    /// Errors: [`crate::Error::Memory`] when even the coarsest model does not fit (raised
    /// before its large arrays are allocated).
    pub fn new(
        patches: &Patches,
        options: &SolverOptions,
        record_culled: bool,
    ) -> Result<Prepared> {
        let budget = Budget::start(options.memory_limit());
        let tree_bytes = HierarchicalCosts::tree_bytes(patches.len() as u64);
        if !budget.fits(tree_bytes) {
            return Err(budget.does_not_fit(
                &format!("the cluster tree of {} patches", patches.len()),
                tree_bytes,
                "raise SolverOptions::memory_limit_bytes",
            ));
        }
        let channels = channels_needed(patches);
        let mut model = options.clone();
        let mut coarsened = Vec::new();
        let mut attempts = 0;
        let mut discarded_seconds = 0.0;
        loop {
            let link_budget = LinkBudget {
                costs: HierarchicalCosts::new(model.bins, channels),
                budget,
                patches: patches.len() as u64,
            };
            attempts += 1;
            let t_attempt = Instant::now();
            let over = match Prepared::build(patches, &model, record_culled, &link_budget) {
                Ok(mut prepared) => {
                    coarsened.append(&mut prepared.memory.coarsened);
                    prepared.memory = MemoryStats {
                        limit_bytes: budget.limit,
                        base_bytes: budget.base,
                        coarsened,
                        attempts,
                        epsilon: model.epsilon,
                        bins: model.bins,
                        split_depth: model.split_depth,
                        discarded_seconds,
                        ..prepared.memory
                    };
                    return Ok(prepared);
                }
                Err(over) => over,
            };
            discarded_seconds += t_attempt.elapsed().as_secs_f64();
            match budget::coarser(&model) {
                Some((next, step)) => {
                    coarsened.push(step);
                    model = next;
                }
                None => {
                    return Err(budget.does_not_fit(
                        &format!(
                            "the hierarchical model of {} patches even at its coarsest (epsilon {}, split depth {}, {}x{} bins, no pair cache)",
                            patches.len(),
                            model.epsilon,
                            model.split_depth,
                            model.bins,
                            model.bins
                        ),
                        over.estimate,
                        "raise SolverOptions::memory_limit_bytes",
                    ))
                }
            }
        }
    }

    /// One attempt of [`Prepared::new`] with the model of `options`: tree, links, element
    /// arrays, groups, live bins and (when it fits) the pair cache, or [`OverBudget`] as soon
    /// as the estimate exceeds `link_budget`.
    fn build(
        patches: &Patches,
        options: &SolverOptions,
        record_culled: bool,
        link_budget: &LinkBudget,
    ) -> std::result::Result<Prepared, OverBudget> {
        let bins = Bins::new(options.bins);
        let t0 = Instant::now();
        let mut tree = ClusterTree::build(patches);
        let model::Backs {
            blocking: back_blocking,
            faces: two_sided,
        } = model::Backs::of(patches, options);
        tree.mark_back_blocking(&back_blocking);
        tree.mark_two_sided(&two_sided);
        let t1 = Instant::now();
        let links = links::refine(
            &mut tree,
            &bins,
            &link_params(options),
            &options.coupling(),
            record_culled,
            link_budget,
        )?;
        let t2 = Instant::now();
        debug_assert!(tree.validate().is_ok(), "{:?}", tree.validate());
        let mut prepared = Prepared {
            elem_area: Vec::with_capacity(tree.elements.len()),
            elem_normal: Vec::with_capacity(tree.elements.len()),
            elem_center: Vec::with_capacity(tree.elements.len()),
            elem_albedo: Vec::with_capacity(tree.elements.len()),
            elem_patch: Vec::with_capacity(tree.elements.len()),
            elem_back: Vec::with_capacity(tree.elements.len()),
            elem_two: Vec::new(),
            back_faces: Vec::new(),
            back_blocking_patches: back_blocking.iter().filter(|&&b| b).count() as u64,
            groups: SenderGroups::default(),
            live: LiveBins::default(),
            pairs: None,
            work: (0, 0),
            albedo_grey: true,
            convex: false,
            use_anti: options.antiradiance,
            tree,
            links,
            bins,
            options: options.clone(),
            budget: link_budget.budget,
            memory: MemoryStats::default(),
            timings: HierarchyTimings {
                tree: (t1 - t0).as_secs_f64(),
                links: (t2 - t1).as_secs_f64(),
                model: 0.0,
                iterate: 0.0,
                direct: 0.0,
            },
        };
        for &node in &prepared.tree.elements {
            let n = &prepared.tree.nodes[node as usize];
            prepared.elem_area.push(n.area);
            prepared
                .elem_normal
                .push(n.plane.map(|p| p.0).unwrap_or(DVec3::Z));
            prepared.elem_center.push(n.centroid);
            prepared.elem_albedo.push(patches.albedo[n.patch as usize]);
            prepared.elem_patch.push(n.patch);
            prepared.elem_back.push(n.blocks_back);
        }
        if two_sided.iter().any(|&b| b) {
            let tree = &prepared.tree;
            prepared.elem_two = (tree.elements.iter())
                .map(|&node| tree.nodes[node as usize].two_sided)
                .collect();
            prepared.back_faces = (0..prepared.elem_two.len() as u32)
                .filter(|&e| prepared.elem_two[e as usize])
                .collect();
        }
        prepared.groups = SenderGroups::build(
            &prepared.tree,
            &prepared.elem_area,
            &prepared.elem_normal,
            &prepared.elem_back,
        );
        prepared.work = prepared.count_sweep_work();
        // Model only what the scene needs: grey albedos allow one-channel solves; a convex
        // enclosure needs no antiradiance; each element stores only the bins links use.
        prepared.albedo_grey = prepared.elem_albedo.iter().all(|&a| model::is_grey(a));
        prepared.convex = model::is_convex_enclosure(&prepared.tree);
        prepared.use_anti = options.antiradiance && !prepared.convex;
        // What the model holds; the stored bins are bounded by every bin until they are known.
        let n = prepared.element_count() as u64;
        let mut counts = ModelCounts {
            patches: patches.len() as u64,
            nodes: prepared.tree.nodes.len() as u64,
            elements: n,
            cluster_links: prepared.links.cluster.len() as u64,
            exact_pairs: prepared.links.exact_sender.len() as u64,
            entries: Some(prepared.links.exact_entries.len() as u64),
            slots: Some(if prepared.use_anti {
                n * prepared.bins.len() as u64
            } else {
                0
            }),
            groups: Some(prepared.groups.normal.len() as u64),
        };
        let costs = &link_budget.costs;
        let budget = &link_budget.budget;
        let build_live = |prepared: &Prepared| {
            if prepared.use_anti {
                LiveBins::build(prepared)
            } else {
                LiveBins::empty(prepared.element_count(), prepared.bins.len())
            }
        };
        // The pair cache, within its own budget and what the model leaves of the memory limit
        // (with every bin counted; if it does not fit so, the live bins are found first and it
        // is tried again with the bins the elements store).
        let own = options.pair_cache_mb as u64 * 1_000_000;
        let mut cache_dropped = false;
        match PairCache::build(&prepared, own.min(budget.spare(costs.bytes(&counts)))) {
            Ok(cache) => {
                prepared.pairs = Some(cache);
                prepared.live = build_live(&prepared);
            }
            Err(cache_bytes) => {
                prepared.live = build_live(&prepared);
                counts.slots = Some(prepared.live.slots() as u64);
                if cache_bytes <= own {
                    let spare = budget.spare(costs.bytes(&counts));
                    prepared.pairs = PairCache::build(&prepared, own.min(spare)).ok();
                    cache_dropped = prepared.pairs.is_none();
                }
            }
        }
        counts.slots = Some(prepared.live.slots() as u64);
        let estimate = costs.bytes(&counts) + prepared.pairs.as_ref().map_or(0, PairCache::bytes);
        if !budget.fits(estimate) {
            return Err(OverBudget { estimate });
        }
        prepared.memory.estimate_bytes = estimate;
        if cache_dropped {
            prepared.memory.coarsened.push("pair cache off".into());
        }
        prepared.timings.model = t2.elapsed().as_secs_f64();
        Ok(prepared)
    }

    /// What the memory budget did: the limit, the estimate of the model solved, what was
    /// coarsened to fit (the peak is filled in by each solve's statistics).
    pub fn memory(&self) -> &MemoryStats {
        &self.memory
    }

    /// Bytes the memory limit leaves beside the model's estimate (for the exact direct light).
    pub(crate) fn spare_bytes(&self) -> u64 {
        self.budget.spare(self.memory.estimate_bytes)
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
            .map(|e| links_into_ancestors(tree, links, e) as u64)
            .sum();
        let pull = links
            .cluster
            .par_iter()
            .map(|l| {
                if self.groups.is_grouped(l.sender) {
                    let (g0, g1) = self.groups.range[l.sender as usize];
                    (g1 - g0) as u64
                } else {
                    let (e0, e1) = tree.nodes[l.sender as usize].elements;
                    (e1 - e0) as u64
                }
            })
            .sum();
        (pairs, pull)
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
        self.tree
            .elements
            .iter()
            .enumerate()
            .map(|(e, &node)| Element {
                corners: self.tree.nodes[node as usize].corners,
                normal: self.elem_normal[e],
                area: self.elem_area[e],
                patch: self.elem_patch[e],
            })
    }

    /// Solves with the patches' own emission.
    pub fn solve(&mut self, patches: &Patches, progress: &Progress) -> (Solution, ElementState) {
        let source = self.element_source_sides(
            &patches.emission_and_source(),
            &patches.emission_and_source_back(),
        );
        self.solve_with_source(patches, &source, None, progress)
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

    /// What a sweep reads that does not change between sweeps.
    fn sweep_context(&self) -> SweepContext<'_> {
        SweepContext {
            tree: &self.tree,
            points: &self.links.point,
            bins: &self.bins,
            live: &self.live,
            elem_area: &self.elem_area,
            elem_normal: &self.elem_normal,
            elem_center: &self.elem_center,
            elem_back: &self.elem_back,
            elem_two: &self.elem_two,
            use_anti: self.use_anti,
            two_sided: self.options.two_sided,
        }
    }

    /// Bytes of the per-sweep state with `channels` colour channels.
    fn state_bytes(&self, channels: u64) -> u64 {
        let n = (self.element_count() + self.elem_two.len()) as u64;
        2 * (n * 8 * channels + self.live.slots() as u64 * 4 * channels)
    }

    /// [`Prepared::solve_from`] in `C` colour channels (1 or 3).
    #[allow(clippy::too_many_arguments)]
    fn solve_channels<const C: usize>(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
        resume: Option<Resume>,
        deadline: Option<Instant>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        let t0 = Instant::now();
        let options = &self.options;
        let nb = self.bins.len();
        let n = self.element_count();
        let use_anti = self.use_anti;
        let live = &self.live;
        let slots = live.slots();
        // Back faces: dense per element (0 for one-sided ones) when some element is two-sided.
        let backs = self.elem_two.len();
        let dense_back = |faces: &[[f64; 3]]| -> Vec<[f64; C]> {
            let mut back = vec![[0.0; C]; backs];
            for (&e, &s) in self.back_faces.iter().zip(&faces[n..]) {
                back[e as usize] = channels_of(s);
            }
            back
        };
        let emission: Vec<[f64; C]> = elem_source[..n].iter().map(|&s| channels_of(s)).collect();
        let emission_back = dense_back(elem_source);
        let albedo: Vec<[f64; C]> = self.elem_albedo.iter().map(|&a| channels_of(a)).collect();
        // A warm start that belongs to this scene: the same source goes on with its iteration;
        // another one moves each element's radiance by the change of its source.
        let warm = (warm.and_then(|w| w.to_channels::<C>(n, backs, slots)))
            .zip(warm)
            .map(|(values, w)| (w, values));
        let matched = warm.is_some();
        let faces = elem_source.len();
        let same_source_len = warm.as_ref().is_some_and(|(w, _)| w.source.len() == faces);
        let same_source = warm.as_ref().is_some_and(|(w, _)| w.source == elem_source);
        let (mut radiance, mut radiance_back, mut anti) = match warm {
            Some((w, (mut radiance, mut radiance_back, mut anti))) => {
                if !same_source && w.source.len() == faces {
                    // The old state scaled per channel by the least-squares factor of the new
                    // source against the old one (exact when every light changed by one factor),
                    // then moved by what that leaves of the change.
                    let old: Vec<[f64; C]> =
                        w.source[..n].iter().map(|&s| channels_of(s)).collect();
                    let old_back = dense_back(&w.source);
                    let k = source_factor(&emission, &old, &self.elem_area);
                    let fronts = radiance.iter_mut().zip(emission.iter().zip(&old));
                    let back_faces = radiance_back
                        .iter_mut()
                        .zip(emission_back.iter().zip(&old_back));
                    for (b, (new, old)) in fronts.chain(back_faces) {
                        for c in 0..C {
                            b[c] = k[c] * b[c] + new[c] - k[c] * old[c];
                        }
                    }
                    for a in anti.iter_mut() {
                        for c in 0..C {
                            a[c] = (k[c] * a[c] as f64) as f32;
                        }
                    }
                }
                (radiance, radiance_back, anti)
            }
            None => (
                emission.clone(),
                emission_back.clone(),
                vec![[0.0f32; C]; slots],
            ),
        };
        let resume = resume.filter(|_| matched);
        let (resume, going_on) = match resume {
            Some(r) if same_source => (Some(r), true),
            other => (other, false),
        };
        let mut next_radiance = radiance.clone();
        let mut next_radiance_back = radiance_back.clone();
        let mut next_anti = anti.clone();
        let mut intensity = vec![[0.0f32; C]; self.links.cluster.len()];
        // Three channels and every bin of every element, against what this solve stores.
        let full_bytes = 2 * (n as u64 * 24 + (n * nb) as u64 * 12);
        let used_bytes = self.state_bytes(C as u64);
        let mut stats = SolveStats {
            links: self.links.len() as u64,
            solver_bytes: self.static_bytes() + used_bytes,
            model: Some(ModelStats {
                channels: C,
                antiradiance: use_anti,
                convex_enclosure: self.convex,
                back_blocking_patches: self.back_blocking_patches,
                anti_bins_stored: slots as u64,
                anti_bins_full: (n * nb) as u64,
                bytes_saved: full_bytes.saturating_sub(used_bytes),
            }),
            ..SolveStats::default()
        };
        let mut convergence = Convergence::default();
        convergence.warm = matched && same_source_len;
        // The bound on B (maximum principle; not for unoccluded radiosity) and the mass the
        // sweeps' changes are measured against.
        let rho_max = albedo
            .iter()
            .flat_map(|a| a.iter().copied())
            .fold(0.0f64, f64::max);
        let source_max = emission
            .iter()
            .chain(&emission_back)
            .flat_map(|s| s.iter().map(|x| x.abs()))
            .fold(0.0f64, f64::max);
        let reference_mass: f64 = emission
            .iter()
            .zip(&self.elem_area)
            .chain(emission_back.iter().zip(&self.elem_area))
            .map(|(s, &a)| a * s.iter().map(|x| x.abs()).sum::<f64>())
            .sum::<f64>()
            / (1.0 - rho_max.clamp(0.0, 0.9999));
        let bound = options
            .antiradiance
            .then(|| health::radiance_bound(source_max, rho_max));
        let mut guard = Guard::new(bound, reference_mass, patches.emission_scale);
        // Going on with the same source: its convergence estimate, health checks and counts.
        let mut first = 1;
        let mut kept_anderson = None;
        if let Some(r) = resume {
            kept_anderson = r
                .anderson
                .filter(|a| a.len() == state_len_of::<C>(n + backs, slots));
            if going_on {
                convergence = r.convergence;
                guard = r.guard;
                first = r.sweeps + 1;
                stats.max_row_sum = r.max_row_sum;
                stats.extrapolations = r.extrapolations;
                stats.damped_after = r.damped_after;
            }
        }
        // Anderson acceleration when its history (and the flat copies of the state it mixes)
        // fits its own budget and what the model leaves of the memory limit; its residuals
        // shrink faster than the plain sweep's contraction, so the remaining error is estimated
        // with the largest albedo as the contraction bound instead.
        let state_len = state_len_of::<C>(n + backs, slots);
        let depth = options.acceleration_depth;
        let history = Anderson::bytes(state_len, depth) + 16 * state_len as u64;
        let mut memory = self.memory.clone();
        let mb = |bytes: u64| bytes.div_ceil(1 << 20);
        let off = if depth == 0 {
            Some("acceleration_depth 0".to_string())
        } else if history > ACCELERATION_BUDGET_BYTES {
            Some(format!(
                "Anderson history of {} MB over its {} MB budget",
                mb(history),
                mb(ACCELERATION_BUDGET_BYTES)
            ))
        } else if history > self.budget.spare(memory.estimate_bytes) {
            memory.coarsened.push("Anderson acceleration off".into());
            Some(format!(
                "Anderson history of {} MB over what the memory limit leaves",
                mb(history)
            ))
        } else {
            memory.estimate_bytes += history;
            None
        };
        let accelerate = off.is_none();
        stats.acceleration = match off {
            None => "anderson".into(),
            Some(why) => format!("extrapolation ({why})"),
        };
        let mut anderson = accelerate.then(|| {
            if let Some(mut kept) = kept_anderson {
                if !going_on {
                    kept.new_source();
                }
                return kept;
            }
            let mut weight = Vec::with_capacity(state_len);
            for &a in self.elem_area.iter().chain(&self.elem_area[..backs]) {
                weight.extend(std::iter::repeat_n(a, C));
            }
            for e in 0..n {
                let w = self.elem_area[e] / nb as f64;
                let k = (live.start[e + 1] - live.start[e]) as usize * C;
                weight.extend(std::iter::repeat_n(w, k));
            }
            Anderson::new(depth, weight)
        });
        if anderson.is_some() {
            convergence.contraction_bound = Some(rho_max);
            if !going_on {
                stats.extrapolations = 0;
            }
        }
        let (mut x_flat, mut g_flat) = (Vec::new(), Vec::new());
        let links = &self.links;
        let elem_area = &self.elem_area;

        let groups = &self.groups;
        let mut group_b = vec![[0.0f64; C]; groups.normal.len()];
        let mut group_b_back = vec![[0.0f64; C]; if backs > 0 { groups.normal.len() } else { 0 }];
        let mut group_a = vec![[0.0f64; C]; groups.normal.len() * nb];
        let pairs = self.pairs.as_ref();
        let ctx = self.sweep_context();
        let sources = Sources {
            emission: &emission,
            emission_back: &emission_back,
            albedo: &albedo,
        };

        let mut last = first - 1;
        for iteration in first..first + options.max_iterations {
            let sweep_start = Instant::now();
            last = iteration;
            // 1. Sender summaries: per normal group of every large node, the area-weighted sums of
            //    B and of each antiradiance bin (bottom-up, children before parents).
            groups.accumulate(
                (&radiance, &radiance_back),
                &anti,
                live,
                elem_area,
                nb,
                (&mut group_b, &mut group_b_back),
                &mut group_a,
            );

            // 2. Pull: the radiant intensity every cluster link's sender sends along the link.
            intensity
                .par_iter_mut()
                .zip(links.cluster.par_iter())
                .for_each(|(out, l)| {
                    *out = ctx.pull(
                        l,
                        groups,
                        (&group_b, &group_b_back),
                        &group_a,
                        (&radiance, &radiance_back),
                        &anti,
                    );
                });

            // 3. Gather per element: exact links, then the cluster links into it and its ancestors,
            //    each with the element's own direction and distance from the link's sender (the
            //    antiradiance goes to the link's bin, the one its sender reads when it passes it on).
            //    Only the element's stored bins are kept.
            let anti_out = split_by_start(&mut next_anti, &live.start);
            let mut back_out: Vec<Option<&mut [f64; C]>> = if backs > 0 {
                next_radiance_back.iter_mut().map(Some).collect()
            } else {
                (0..n).map(|_| None).collect()
            };
            let state = SweepState {
                links,
                pairs,
                intensity: &intensity,
                radiance: &radiance,
                radiance_back: &radiance_back,
                anti: &anti,
            };
            let change_parts: Vec<SweepSums> = next_radiance
                .par_iter_mut()
                .zip(anti_out.into_par_iter())
                .zip(back_out.par_iter_mut())
                .enumerate()
                .map_init(
                    || vec![[0.0f64; C]; 2 * nb],
                    |a_acc, (e, ((b_out, a_out), back_out))| {
                        ctx.gather_element(
                            e,
                            (&sources, &state),
                            a_acc,
                            (b_out, a_out, back_out.as_deref_mut()),
                        )
                    },
                )
                .collect();

            let sums = change_parts
                .iter()
                .fold(SweepSums::default(), |acc, p| acc.add(*p));
            if iteration == first && !going_on {
                stats.max_row_sum = sums.max_row;
            }
            let change = change_ratio(sums.num, sums.den);
            drop(back_out);
            std::mem::swap(&mut radiance, &mut next_radiance);
            std::mem::swap(&mut radiance_back, &mut next_radiance_back);
            std::mem::swap(&mut anti, &mut next_anti);
            if end_sweep(
                iteration,
                change,
                sums.num,
                sums.largest,
                sums.finite,
                options.tol,
                &mut guard,
                &mut convergence,
                &mut stats,
                progress,
            ) {
                break;
            }
            if start_damping(iteration, &mut guard, &mut convergence, &mut stats) {
                if let Some(acc) = anderson.as_mut() {
                    acc.restart();
                }
            }
            damp_if_damped(
                &guard,
                (&mut radiance, &next_radiance),
                (&mut anti, &next_anti),
            );
            if guard.damped() {
                crate::solve::health::damp(&mut radiance_back, &next_radiance_back);
            }
            match anderson.as_mut() {
                // Anderson: the next state mixes the last sweeps' outputs.
                Some(acc) => {
                    pack(
                        (&next_radiance, &next_radiance_back),
                        &next_anti,
                        &mut x_flat,
                    );
                    pack((&radiance, &radiance_back), &anti, &mut g_flat);
                    acc.step(&mut x_flat, &g_flat);
                    unpack(&x_flat, (&mut radiance, &mut radiance_back), &mut anti);
                }
                // Else, once the sweeps contract at a steady ratio, jump over the geometric tail.
                None => {
                    if let Some(k) = convergence.extrapolation_factor() {
                        extrapolate(&mut radiance, &next_radiance, k);
                        extrapolate(&mut radiance_back, &next_radiance_back, k);
                        extrapolate(&mut anti, &next_anti, k);
                        stats.extrapolations += 1;
                    }
                }
            }
            // Out of time when the next sweep, as long as this one, would end after the
            // deadline.
            if let Some(deadline) = deadline {
                let now = Instant::now();
                if now + (now - sweep_start) > deadline {
                    break;
                }
            }
        }
        stats.iterations = last + 1 - first;
        stats.residual = convergence.residual;

        // Elements -> patches (area-weighted mean, RGB); patches without elements (inactive) get
        // 0 here and their emission from `solve_with_emission`.
        let radiance_rgb: Vec<[f64; 3]> = radiance.iter().map(|&b| rgb_of(b)).collect();
        let radiance_back_rgb: Vec<[f64; 3]> = radiance_back.iter().map(|&b| rgb_of(b)).collect();
        let means = |values: &[[f64; 3]]| -> Vec<[f64; 3]> {
            crate::mesh::patch_means(
                patches.len(),
                (0..values.len()).map(|e| (self.elem_patch[e] as usize, elem_area[e], values[e])),
            )
            .into_iter()
            .map(|m| m.unwrap_or([0.0; 3]))
            .collect()
        };
        let patch_radiance = means(&radiance_rgb);
        let patch_radiance_back = if backs > 0 {
            means(&radiance_back_rgb)
        } else {
            Vec::new()
        };
        self.timings.iterate = t0.elapsed().as_secs_f64();
        stats.stage_seconds = Some(self.timings.clone());
        stats.link_stats = Some(crate::solve::solution::LinkReport {
            cluster_links: self.links.cluster.len() as u64,
            exact_links: self.links.exact_sender.len() as u64,
            refinement: self.links.stats.clone(),
        });
        stats.elements = n;
        (stats.element_link_pairs, stats.pull_terms) = self.sweep_work();
        memory.peak_bytes = crate::memory::peak_rss_bytes();
        stats.memory = Some(memory);
        // The result is checked against the bound of this solve's source (with exact direct
        // light, the reflected direct light: a tighter bound than the emission's).
        let solution = crate::solve::solution::finish_sides(
            patches,
            patch_radiance,
            patch_radiance_back,
            stats,
            options.clamp_negative,
            bound,
        );
        let resume = Resume {
            anderson,
            convergence,
            guard,
            sweeps: last,
            max_row_sum: solution.stats.max_row_sum,
            extrapolations: solution.stats.extrapolations,
            damped_after: solution.stats.damped_after,
        };
        let state = ElementState {
            radiance: radiance_rgb,
            radiance_back: radiance_back_rgb,
            anti: anti.iter().flatten().copied().collect(),
            channels: C,
            source: elem_source.to_vec(),
            resume: Some(Box::new(resume)),
        };
        (solution, state)
    }
}

/// Per channel, the factor `k` that brings `old` closest to `new` (least squares, area
/// weighted): `sum a new old / sum a old^2`; 1 where `old` is 0 or the sums are not finite.
/// Sums in f64.
fn source_factor<const C: usize>(new: &[[f64; C]], old: &[[f64; C]], area: &[f64]) -> [f64; C] {
    let (mut dot, mut norm) = ([0.0f64; C], [0.0f64; C]);
    for ((n, o), &a) in new.iter().zip(old).zip(area) {
        for c in 0..C {
            dot[c] += a * n[c] * o[c];
            norm[c] += a * o[c] * o[c];
        }
    }
    std::array::from_fn(|c| {
        let k = dot[c] / norm[c];
        if norm[c] > 0.0 && k.is_finite() {
            k
        } else {
            1.0
        }
    })
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
    Ok(prepared.solve(patches, progress).0)
}

/// Cluster links into element `e` and into each of its ancestors: the (element, link) pairs
/// of `e` in a sweep's gather.
fn links_into_ancestors(tree: &ClusterTree, links: &Links, e: usize) -> usize {
    let mut total = 0;
    let mut node = tree.elements[e];
    while node != NONE {
        total +=
            (links.cluster_start[node as usize + 1] - links.cluster_start[node as usize]) as usize;
        node = tree.nodes[node as usize].parent;
    }
    total
}

/// Most memory the Anderson history may take; above it the solver extrapolates the tail instead.
const ACCELERATION_BUDGET_BYTES: u64 = 512 << 20;

#[cfg(test)]
mod tests;
