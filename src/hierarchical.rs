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

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::accelerate::Anderson;
use crate::bins::Bins;
use crate::budget::{
    self, Budget, HierarchicalCosts, LinkBudget, MemoryStats, ModelCounts, OverBudget,
};
use crate::error::Result;
use crate::health::{self, Guard};
use crate::hierarchy::{ClusterTree, NONE};
use crate::links::{self, ClusterLink, LinkParams, Links};
use crate::mesh::Patches;
use crate::model::{self, ModelStats};
use crate::progress::Progress;
use crate::solution::{Solution, SolveStats};
use crate::solve::{change_ratio, finish, Convergence, SolverOptions};
use crate::transport::gather_entries;

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
    /// Input patches that block light arriving at their back.
    back_blocking_patches: u64,
    /// Normal groups of the large nodes, for the pull.
    groups: SenderGroups,
    /// The antiradiance bins each element stores.
    live: LiveBins,
    /// Cached geometric factors of the (element, cluster link) pairs, when they fit the budget.
    pairs: Option<PairCache>,
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
/// element and bin. Pass it back to [`Prepared::solve_with_source`] to warm-start the next solve
/// of the same [`Prepared`] scene (interactive relighting).
#[derive(Clone, Debug, Default)]
pub struct ElementState {
    /// Outgoing radiance per element, RGB (normalized units).
    radiance: Vec<[f64; 3]>,
    /// Antiradiance per stored (element, bin) slot, `channels` values each.
    anti: Vec<f32>,
    /// Colour channels of `anti`: 1 (grey solve) or 3.
    channels: usize,
}

/// Radiance per element and antiradiance per stored slot, in `C` channels.
type ChannelState<const C: usize> = (Vec<[f64; C]>, Vec<[f32; C]>);

impl ElementState {
    /// Outgoing radiance per element (normalized units, element order of [`Prepared`]).
    pub fn radiance(&self) -> &[[f64; 3]] {
        &self.radiance
    }

    /// The state in `C` channels, or `None` when it does not belong to a scene with `n`
    /// elements and `slots` stored antiradiance bins. Grey to RGB repeats the channel; RGB to
    /// grey takes the mean.
    fn to_channels<const C: usize>(&self, n: usize, slots: usize) -> Option<ChannelState<C>> {
        let k = self.channels;
        if self.radiance.len() != n || k == 0 || self.anti.len() != slots * k {
            return None;
        }
        let radiance = self.radiance.iter().map(|&b| channels_of(b)).collect();
        let anti = self
            .anti
            .chunks_exact(k)
            .map(|a| {
                let rgb = [a[0], a[1 % k], a[2 % k]].map(f64::from);
                channels_of::<C>(rgb).map(|x| x as f32)
            })
            .collect();
        Some((radiance, anti))
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
    /// `options` ([`SolverOptions::memory_limit_bytes`], see [`crate::budget`]): a model whose
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
        let budget = Budget::start(options.memory_limit_bytes);
        let tree_bytes = HierarchicalCosts::tree_bytes(patches.len() as u64);
        if !budget.fits(tree_bytes) {
            return Err(budget.does_not_fit(
                &format!("the cluster tree of {} patches", patches.len()),
                tree_bytes,
                "raise --memory-limit",
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
                        "raise --memory-limit",
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
        let back_blocking = model::back_blocking(patches, options);
        tree.mark_back_blocking(&back_blocking);
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
            back_blocking_patches: back_blocking.iter().filter(|&&b| b).count() as u64,
            groups: SenderGroups::default(),
            live: LiveBins::default(),
            pairs: None,
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
        prepared.groups = SenderGroups::build(
            &prepared.tree,
            &prepared.elem_area,
            &prepared.elem_normal,
            &prepared.elem_back,
        );
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
            + self.links.cluster.len() as u64 * 24
            + self.groups.bytes(nb)
    }

    /// The elements, in the order of [`ElementState`] and of `elem_source` in
    /// [`Prepared::solve_with_source`].
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
        self.solve_with_emission(patches, &patches.emission_and_source(), None, progress)
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
        assert_eq!(patch_emission.len(), patches.len());
        let source: Vec<[f64; 3]> = self
            .elem_patch
            .iter()
            .map(|&p| patch_emission[p as usize])
            .collect();
        // Patches the tree does not hold (inactive: zero area, duplicates) are settled by
        // `Solution::from_normalized` from their own emission or their twin.
        self.solve_with_source(patches, &source, warm, progress)
    }

    /// Solves `B_e = source_e + rho_e H_e(B)` for a per-element source radiance (normalized
    /// units, element order of [`Prepared::elements`]). With the emission as the source this is
    /// the usual solve; with the reflected direct light as the source it gives the indirect
    /// part on top of exact direct lighting. Warm-starts from `warm` when it belongs to this
    /// scene (same element count and stored bins), else starts from the source.
    ///
    /// Solves one channel when the albedos and the source are grey, three otherwise
    /// ([`crate::model`]); the returned solution is RGB either way.
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
        assert_eq!(elem_source.len(), self.element_count());
        let grey = self.albedo_grey && elem_source.iter().all(|s| model::is_grey(*s));
        if grey {
            self.solve_channels::<1>(patches, elem_source, warm, progress)
        } else {
            self.solve_channels::<3>(patches, elem_source, warm, progress)
        }
    }

    /// What a sweep reads that does not change between sweeps.
    fn sweep_context(&self) -> SweepContext<'_> {
        SweepContext {
            tree: &self.tree,
            bins: &self.bins,
            live: &self.live,
            elem_area: &self.elem_area,
            elem_normal: &self.elem_normal,
            elem_center: &self.elem_center,
            elem_back: &self.elem_back,
            use_anti: self.use_anti,
            two_sided: self.options.two_sided,
        }
    }

    /// Bytes of the per-sweep state with `channels` colour channels.
    fn state_bytes(&self, channels: u64) -> u64 {
        let n = self.element_count() as u64;
        2 * (n * 8 * channels + self.live.slots() as u64 * 4 * channels)
    }

    /// [`Prepared::solve_with_source`] in `C` colour channels (1 or 3).
    fn solve_channels<const C: usize>(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        let t0 = Instant::now();
        let options = &self.options;
        let nb = self.bins.len();
        let n = self.element_count();
        let two_sided = options.two_sided;
        let elem_back = &self.elem_back;
        let use_anti = self.use_anti;
        let live = &self.live;
        let slots = live.slots();
        let emission: Vec<[f64; C]> = elem_source.iter().map(|&s| channels_of(s)).collect();
        let albedo: Vec<[f64; C]> = self.elem_albedo.iter().map(|&a| channels_of(a)).collect();
        let (mut radiance, mut anti) = warm
            .and_then(|w| w.to_channels::<C>(n, slots))
            .unwrap_or_else(|| (emission.clone(), vec![[0.0f32; C]; slots]));
        let mut next_radiance = radiance.clone();
        let mut next_anti = anti.clone();
        let mut intensity = vec![[0.0f64; C]; self.links.cluster.len()];
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
        // The bound on B (maximum principle; not for unoccluded radiosity) and the mass the
        // sweeps' changes are measured against.
        let rho_max = albedo
            .iter()
            .flat_map(|a| a.iter().copied())
            .fold(0.0f64, f64::max);
        let source_max = emission
            .iter()
            .flat_map(|s| s.iter().map(|x| x.abs()))
            .fold(0.0f64, f64::max);
        let reference_mass: f64 = emission
            .iter()
            .zip(&self.elem_area)
            .map(|(s, &a)| a * s.iter().map(|x| x.abs()).sum::<f64>())
            .sum::<f64>()
            / (1.0 - rho_max.clamp(0.0, 0.9999));
        let bound = options
            .antiradiance
            .then(|| health::radiance_bound(source_max, rho_max));
        let mut guard = Guard::new(bound, reference_mass, patches.emission_scale);
        // Anderson acceleration when its history (and the flat copies of the state it mixes)
        // fits its own budget and what the model leaves of the memory limit; its residuals
        // shrink faster than the plain sweep's contraction, so the remaining error is estimated
        // with the largest albedo as the contraction bound instead.
        let state_len = (n + slots) * C;
        let depth = options.acceleration_depth;
        let history = Anderson::bytes(state_len, depth) + 16 * state_len as u64;
        let mut memory = self.memory.clone();
        let accelerate = depth > 0 && history <= ACCELERATION_BUDGET_BYTES;
        let accelerate = if accelerate && history > self.budget.spare(memory.estimate_bytes) {
            memory.coarsened.push("Anderson acceleration off".into());
            false
        } else {
            if accelerate {
                memory.estimate_bytes += history;
            }
            accelerate
        };
        let mut anderson = accelerate.then(|| {
            let mut weight = Vec::with_capacity(state_len);
            for &a in &self.elem_area {
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
            stats.extrapolations = 0;
        }
        let (mut x_flat, mut g_flat) = (Vec::new(), Vec::new());
        let tree = &self.tree;
        let links = &self.links;
        let elem_area = &self.elem_area;

        let groups = &self.groups;
        let mut group_b = vec![[0.0f64; C]; groups.normal.len()];
        let mut group_a = vec![[0.0f64; C]; groups.normal.len() * nb];
        let pairs = self.pairs.as_ref();
        let ctx = self.sweep_context();

        for iteration in 1..=options.max_iterations {
            // 1. Sender summaries: per normal group of every large node, the area-weighted sums of
            //    B and of each antiradiance bin (bottom-up, children before parents).
            groups.accumulate(
                &radiance,
                &anti,
                live,
                elem_area,
                nb,
                &mut group_b,
                &mut group_a,
            );

            // 2. Pull: the radiant intensity every cluster link's sender sends along the link.
            intensity
                .par_iter_mut()
                .zip(links.cluster.par_iter())
                .for_each(|(out, l)| {
                    *out = ctx.pull(l, groups, &group_b, &group_a, &radiance, &anti);
                });

            // 3. Gather per element: exact links, then the cluster links into it and its ancestors,
            //    each with the element's own direction and distance from the link's sender (the
            //    antiradiance goes to the link's bin, the one its sender reads when it passes it on).
            //    Only the element's stored bins are kept.
            let anti_out = split_by_start(&mut next_anti, &live.start);
            let change_parts: Vec<SweepSums> = next_radiance
                .par_iter_mut()
                .zip(anti_out.into_par_iter())
                .enumerate()
                .map_init(
                    || vec![[0.0f64; C]; nb],
                    |a_acc, (e, (b_out, a_out))| {
                        a_acc.fill([0.0; C]);
                        let mut h = [0.0f64; C];
                        let mut row = 0.0;
                        for l in links.exact_start[e]..links.exact_start[e + 1] {
                            let s = links.exact_sender[l as usize] as usize;
                            row += gather_entries(
                                links.exact_entries_of(l as usize),
                                radiance[s],
                                |bin| {
                                    live.slot(s, bin)
                                        .map_or([0.0; C], |k| anti[k].map(f64::from))
                                },
                                use_anti,
                                two_sided || elem_back[s],
                                &mut h,
                                a_acc,
                            );
                        }
                        let mut add = |l: &ClusterLink, i: &[f64; C], k: PairFactor| {
                            for c in 0..C {
                                h[c] += k.irradiance as f64 * i[c];
                            }
                            if k.anti != 0.0 {
                                let bin = l.bin as usize;
                                for c in 0..C {
                                    a_acc[bin][c] += k.anti as f64 * i[c];
                                }
                            }
                        };
                        match pairs {
                            Some(cache) => {
                                // A stream of multiply-adds: factors, intensities and bins
                                // side by side (a factor of 0 adds nothing).
                                cache.for_each_node(e, tree, links, |range, factors| {
                                    for ((f, i), &bin) in factors
                                        .iter()
                                        .zip(&intensity[range.clone()])
                                        .zip(&cache.link_bin[range])
                                    {
                                        let [irradiance, anti] = f.map(f64::from);
                                        for c in 0..C {
                                            h[c] += irradiance * i[c];
                                            a_acc[bin as usize][c] += anti * i[c];
                                        }
                                    }
                                });
                            }
                            None => ctx.for_each_pair(e, links, |i, l, k| add(l, &intensity[i], k)),
                        }
                        let mut largest = 0.0f64;
                        let mut finite = true;
                        for c in 0..C {
                            b_out[c] = emission[e][c] + albedo[e][c] * h[c];
                            largest = largest.max(b_out[c].abs());
                            finite &= b_out[c].is_finite();
                        }
                        for (dst, bin) in a_out.iter_mut().zip(live.bins_of(e)) {
                            *dst = a_acc[bin].map(|x| x as f32);
                            finite &= dst.iter().all(|x| x.is_finite());
                        }
                        let a = elem_area[e];
                        let num: f64 = (0..C).map(|c| a * (b_out[c] - radiance[e][c]).abs()).sum();
                        let den: f64 = (0..C).map(|c| a * b_out[c].abs()).sum();
                        SweepSums {
                            num,
                            den,
                            max_row: row,
                            largest,
                            finite,
                        }
                    },
                )
                .collect();

            let sums = change_parts
                .iter()
                .fold(SweepSums::default(), |acc, p| acc.add(*p));
            if iteration == 1 {
                stats.max_row_sum = sums.max_row;
            }
            let change = change_ratio(sums.num, sums.den);
            std::mem::swap(&mut radiance, &mut next_radiance);
            std::mem::swap(&mut anti, &mut next_anti);
            stats.iterations = iteration;
            progress.inc(1);
            progress.message(format!("residual {change:.2e}"));
            if let Some(failure) =
                guard.sweep(iteration, change, sums.num, sums.largest, sums.finite)
            {
                convergence.residual = change;
                stats.failure = Some(failure);
                break;
            }
            if convergence.sweep_done(iteration, change, options.tol) {
                stats.converged = true;
                break;
            }
            if guard.wants_damping() {
                stats.damped_after = Some(iteration);
                if let Some(acc) = anderson.as_mut() {
                    acc.restart();
                }
                convergence.restart();
            }
            if guard.damped() {
                health::damp(&mut radiance, &next_radiance);
                health::damp(&mut anti, &next_anti);
            }
            match anderson.as_mut() {
                // Anderson: the next state mixes the last sweeps' outputs.
                Some(acc) => {
                    pack(&next_radiance, &next_anti, &mut x_flat);
                    pack(&radiance, &anti, &mut g_flat);
                    acc.step(&mut x_flat, &g_flat);
                    unpack(&x_flat, &mut radiance, &mut anti);
                }
                // Else, once the sweeps contract at a steady ratio, jump over the geometric tail.
                None => {
                    if let Some(k) = convergence.extrapolation_factor() {
                        extrapolate(&mut radiance, &next_radiance, k);
                        extrapolate(&mut anti, &next_anti, k);
                        stats.extrapolations += 1;
                    }
                }
            }
        }
        stats.residual = convergence.residual;

        // Elements -> patches (area-weighted mean, RGB); patches without elements (inactive) get
        // 0 here and their emission from `solve_with_emission`.
        let radiance_rgb: Vec<[f64; 3]> = radiance.iter().map(|&b| rgb_of(b)).collect();
        let mut patch_sum = vec![[0.0f64; 3]; patches.len()];
        let mut patch_area = vec![0.0f64; patches.len()];
        for e in 0..n {
            let p = self.elem_patch[e] as usize;
            patch_area[p] += elem_area[e];
            for c in 0..3 {
                patch_sum[p][c] += elem_area[e] * radiance_rgb[e][c];
            }
        }
        let patch_radiance: Vec<[f64; 3]> = (0..patches.len())
            .map(|p| {
                if patch_area[p] > 0.0 {
                    patch_sum[p].map(|x| x / patch_area[p])
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        self.timings.iterate = t0.elapsed().as_secs_f64();
        stats.stage_seconds = Some(self.timings.clone());
        stats.link_stats = Some(crate::solution::LinkReport {
            cluster_links: self.links.cluster.len() as u64,
            exact_links: self.links.exact_sender.len() as u64,
            refinement: self.links.stats.clone(),
        });
        stats.elements = n;
        memory.peak_bytes = crate::memory::peak_rss_bytes();
        stats.memory = Some(memory);
        // The result is checked against the bound of this solve's source (with exact direct
        // light, the reflected direct light: a tighter bound than the emission's).
        let solution = finish(
            patches,
            patch_radiance,
            stats,
            options.clamp_negative,
            bound,
        );
        let state = ElementState {
            radiance: radiance_rgb,
            anti: anti.iter().flatten().copied().collect(),
            channels: C,
        };
        (solution, state)
    }
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

/// Nodes with at most this many elements pull per element; larger ones pull per normal group.
const PULL_PER_ELEMENT_MAX: u32 = 8;

/// Most distinct exact normals a node's groups keep; beyond it normals are grouped by cell of a
/// coarse direction grid (`GROUP_CELLS` x `GROUP_CELLS` octahedral cells, about 45 degrees wide).
const MAX_EXACT_GROUPS: usize = 8;
const GROUP_CELLS: usize = 4;

/// Two unit normals closer than this (1 - cos) are the same group.
const SAME_NORMAL: f64 = 1e-9;

/// Normal groups of the large nodes (more than [`PULL_PER_ELEMENT_MAX`] elements).
///
/// A cluster link's sender sends `sum_e a_e (B_e max(0, n_e . w) - A_e[bin] max(0, -n_e . w))`;
/// for elements sharing a normal that is `max(0, n . w) sum a_e B_e - ...`, so a node needs only
/// per-group sums. Flat (architectural) scenes have few exact normals per node and the pull is
/// exact; curved ones are grouped by normal cell with the group's area-weighted mean normal.
#[derive(Clone, Debug, Default)]
struct SenderGroups {
    /// Per node, its groups `range.0..range.1` (empty for small nodes).
    range: Vec<(u32, u32)>,
    /// Per group, the area-weighted mean normal (unit for exact groups, shorter for cells).
    normal: Vec<DVec3>,
    /// Per group, its area.
    area: Vec<f64>,
    /// Per group: its elements block light at their back (groups never mix the two kinds).
    both: Vec<bool>,
    /// Per group, the group of the parent node it adds into ([`NONE`] at the root).
    parent_group: Vec<u32>,
    /// Per element, the group of its lowest large ancestor it adds into ([`NONE`] if none).
    elem_group: Vec<u32>,
    /// Large nodes, children before parents.
    order: Vec<u32>,
    /// (group, its parent group) for every group with a parent, children before parents.
    child_parent: Vec<(u32, u32)>,
}

/// What feeds a group: a child's group or an element of a small child.
enum GroupInput {
    Group(u32),
    Element(u32),
}

impl SenderGroups {
    /// Builds the groups of every large node of a finalized tree.
    fn build(
        tree: &ClusterTree,
        elem_area: &[f64],
        elem_normal: &[DVec3],
        elem_back: &[bool],
    ) -> SenderGroups {
        let mut groups = SenderGroups {
            range: vec![(0, 0); tree.nodes.len()],
            elem_group: vec![NONE; elem_area.len()],
            ..SenderGroups::default()
        };
        if tree.nodes.is_empty() {
            return groups;
        }
        let large = |i: u32| {
            let (e0, e1) = tree.nodes[i as usize].elements;
            e1 - e0 > PULL_PER_ELEMENT_MAX
        };
        // Post-order over the large nodes.
        let mut stack = vec![(0u32, false)];
        while let Some((i, done)) = stack.pop() {
            if !large(i) {
                continue;
            }
            if done {
                groups.order.push(i);
            } else {
                stack.push((i, true));
                let node = &tree.nodes[i as usize];
                for c in node.first_child..node.first_child + node.child_count as u32 {
                    stack.push((c, false));
                }
            }
        }
        let cells = Bins::new(GROUP_CELLS);
        let order = std::mem::take(&mut groups.order);
        for &i in &order {
            // Inputs: the groups of large children, the elements of small ones.
            let node = &tree.nodes[i as usize];
            let mut inputs: Vec<(GroupInput, DVec3, f64)> = Vec::new();
            let mut input_back: Vec<bool> = Vec::new();
            for c in node.first_child..node.first_child + node.child_count as u32 {
                if large(c) {
                    let (g0, g1) = groups.range[c as usize];
                    for g in g0..g1 {
                        let (n, a) = (groups.normal[g as usize], groups.area[g as usize]);
                        inputs.push((GroupInput::Group(g), n, a));
                        input_back.push(groups.both[g as usize]);
                    }
                } else {
                    let (e0, e1) = tree.nodes[c as usize].elements;
                    for e in e0..e1 {
                        let (n, a) = (elem_normal[e as usize], elem_area[e as usize]);
                        inputs.push((GroupInput::Element(e), n, a));
                        input_back.push(elem_back[e as usize]);
                    }
                }
            }
            // Exact groups when every input has a unit normal and there are few distinct ones;
            // else cells of a coarse direction grid.
            let mut distinct: Vec<(DVec3, bool)> = Vec::new();
            let mut key_of: Vec<usize> = Vec::with_capacity(inputs.len());
            let mut exact = true;
            for ((_, n, _), &back) in inputs.iter().zip(&input_back) {
                if (n.length_squared() - 1.0).abs() > 1e-9 {
                    exact = false;
                    break;
                }
                match distinct
                    .iter()
                    .position(|(d, b)| *b == back && 1.0 - d.dot(*n) <= SAME_NORMAL)
                {
                    Some(k) => key_of.push(k),
                    None if distinct.len() < MAX_EXACT_GROUPS => {
                        key_of.push(distinct.len());
                        distinct.push((*n, back));
                    }
                    None => {
                        exact = false;
                        break;
                    }
                }
            }
            let mut group_back: Vec<bool> = distinct.iter().map(|&(_, b)| b).collect();
            let count = if exact {
                distinct.len()
            } else {
                key_of.clear();
                group_back.clear();
                let mut cell_keys: Vec<(usize, bool)> = Vec::new();
                for ((_, n, _), &back) in inputs.iter().zip(&input_back) {
                    let cell = (cells.bin_of(*n), back);
                    let k = cell_keys
                        .iter()
                        .position(|&c| c == cell)
                        .unwrap_or_else(|| {
                            cell_keys.push(cell);
                            group_back.push(back);
                            cell_keys.len() - 1
                        });
                    key_of.push(k);
                }
                cell_keys.len()
            };
            groups.both.extend_from_slice(&group_back);
            let first = groups.normal.len() as u32;
            groups.range[i as usize] = (first, first + count as u32);
            groups
                .normal
                .extend(std::iter::repeat_n(DVec3::ZERO, count));
            groups.area.extend(std::iter::repeat_n(0.0, count));
            groups.parent_group.extend(std::iter::repeat_n(NONE, count));
            // Wire the inputs; group normals are area-weighted means.
            for ((input, n, a), &k) in inputs.iter().zip(&key_of) {
                let g = first + k as u32;
                match input {
                    GroupInput::Group(child) => groups.parent_group[*child as usize] = g,
                    GroupInput::Element(e) => groups.elem_group[*e as usize] = g,
                }
                groups.normal[g as usize] += *a * *n;
                groups.area[g as usize] += *a;
            }
            for g in first as usize..first as usize + count {
                if exact {
                    groups.normal[g] = groups.normal[g].normalize_or_zero();
                } else if groups.area[g] > 0.0 {
                    groups.normal[g] /= groups.area[g];
                }
            }
        }
        for &i in &order {
            let (g0, g1) = groups.range[i as usize];
            for g in g0..g1 {
                let p = groups.parent_group[g as usize];
                if p != NONE {
                    debug_assert!(p > g, "parents' groups follow their children's");
                    groups.child_parent.push((g, p));
                }
            }
        }
        groups.order = order;
        groups
    }

    /// True when node `i` pulls per group.
    fn is_grouped(&self, i: u32) -> bool {
        let (g0, g1) = self.range[i as usize];
        g1 > g0
    }

    /// Bytes of the per-sweep group sums.
    fn bytes(&self, bins: u64) -> u64 {
        self.normal.len() as u64 * (24 + 8 + 4 + 24 * (1 + bins))
    }

    /// Area-weighted sums of B (`group_b`) and of every antiradiance bin (`group_a`) per group:
    /// elements into their lowest large ancestor's groups, then groups into their parents'.
    #[allow(clippy::too_many_arguments)]
    fn accumulate<const C: usize>(
        &self,
        radiance: &[[f64; C]],
        anti: &[[f32; C]],
        live: &LiveBins,
        elem_area: &[f64],
        nb: usize,
        group_b: &mut [[f64; C]],
        group_a: &mut [[f64; C]],
    ) {
        // group_a is bin-major: bin b of group g at b * ng + g, so the groups of one node in
        // one bin (what a link's pull reads) are side by side.
        let ng = self.normal.len();
        debug_assert_eq!(group_a.len(), ng * nb);
        group_b.fill([0.0; C]);
        group_a.fill([0.0; C]);
        for (e, &g) in self.elem_group.iter().enumerate() {
            if g == NONE {
                continue;
            }
            let (g, a) = (g as usize, elem_area[e]);
            for c in 0..C {
                group_b[g][c] += a * radiance[e][c];
            }
            let stored = &anti[live.start[e] as usize..live.start[e + 1] as usize];
            for (bin, s) in live.bins_of(e).zip(stored) {
                let dst = &mut group_a[bin * ng + g];
                for c in 0..C {
                    dst[c] += a * s[c] as f64;
                }
            }
        }
        // Children into parents; parents' groups come after their children's (post-order), so
        // one pass in group order sums whole subtrees.
        for &(g, p) in &self.child_parent {
            let child = group_b[g as usize];
            for (d, s) in group_b[p as usize].iter_mut().zip(child) {
                *d += s;
            }
        }
        for row in group_a.chunks_mut(ng.max(1)) {
            for &(g, p) in &self.child_parent {
                let child = row[g as usize];
                for (d, s) in row[p as usize].iter_mut().zip(child) {
                    *d += s;
                }
            }
        }
    }
}

/// Sums over a sweep's elements: relative change numerator and denominator, largest row sum
/// (exact links), largest |B|, and whether every value written was finite.
#[derive(Clone, Copy, Debug)]
struct SweepSums {
    num: f64,
    den: f64,
    max_row: f64,
    largest: f64,
    finite: bool,
}

impl Default for SweepSums {
    fn default() -> Self {
        SweepSums {
            num: 0.0,
            den: 0.0,
            max_row: 0.0,
            largest: 0.0,
            finite: true,
        }
    }
}

impl SweepSums {
    fn add(self, o: SweepSums) -> SweepSums {
        SweepSums {
            num: self.num + o.num,
            den: self.den + o.den,
            max_row: self.max_row.max(o.max_row),
            largest: self.largest.max(o.largest),
            finite: self.finite && o.finite,
        }
    }
}

/// Everything a sweep reads that does not change between sweeps.
struct SweepContext<'a> {
    tree: &'a ClusterTree,
    bins: &'a Bins,
    live: &'a LiveBins,
    elem_area: &'a [f64],
    elem_normal: &'a [DVec3],
    elem_center: &'a [DVec3],
    elem_back: &'a [bool],
    use_anti: bool,
    two_sided: bool,
}

impl SweepContext<'_> {
    /// Calls `f` with the index of every cluster link into element `e` or one of its ancestors (element
    /// first, then up the tree; links of a node in stored order) and the pair's factors.
    #[inline]
    fn for_each_pair(
        &self,
        e: usize,
        links: &Links,
        mut f: impl FnMut(usize, &ClusterLink, PairFactor),
    ) {
        let (n_e, x_e) = (self.elem_normal[e], self.elem_center[e]);
        let back = self.two_sided || self.elem_back[e];
        let mut node = self.tree.elements[e];
        while node != NONE {
            let range = links.cluster_start[node as usize] as usize
                ..links.cluster_start[node as usize + 1] as usize;
            for (i, l) in range.clone().zip(&links.cluster[range]) {
                f(i, l, self.pair_factor(l, n_e, x_e, back));
            }
            node = self.tree.nodes[node as usize].parent;
        }
    }

    /// What a cluster link gives an element with normal `n_e` at `x_e`: irradiance
    /// `max(0, cos) / (pi (d^2 + spread))` per unit of the link's intensity, with the element's
    /// own direction and distance from the sender, and antiradiance `1 / ((d^2 + spread)
    /// Omega_bin)` in the link's bin where the light arrives at a side that creates it (the
    /// front, and the back too when `back`).
    #[inline]
    fn pair_factor(&self, l: &ClusterLink, n_e: DVec3, x_e: DVec3, back: bool) -> PairFactor {
        let origin = DVec3::new(l.origin[0] as f64, l.origin[1] as f64, l.origin[2] as f64);
        let v = x_e - origin;
        let d2 = v.length_squared();
        if !(d2 > 0.0) {
            return PairFactor::default();
        }
        let cos = -n_e.dot(v) / d2.sqrt();
        let g = 1.0 / (d2 + l.spread as f64);
        let irradiance = if cos > 0.0 {
            cos * g * std::f64::consts::FRAC_1_PI
        } else {
            0.0
        };
        let anti = if self.use_anti && (cos > 0.0 || back) {
            g / self.bins.solid_angle[l.bin as usize]
        } else {
            0.0
        };
        PairFactor {
            irradiance: irradiance as f32,
            anti: anti as f32,
        }
    }

    /// The radiant intensity a cluster link's sender sends along the link: B through the front of
    /// every element, minus antiradiance through the back (both sides when two-sided).
    #[allow(clippy::needless_range_loop)]
    fn pull<const C: usize>(
        &self,
        l: &ClusterLink,
        groups: &SenderGroups,
        group_b: &[[f64; C]],
        group_a: &[[f64; C]],
        radiance: &[[f64; C]],
        anti: &[[f32; C]],
    ) -> [f64; C] {
        let w = DVec3::new(l.w[0] as f64, l.w[1] as f64, l.w[2] as f64);
        let bin = l.bin as usize;
        let mut acc = [0.0f64; C];
        let mut add = |cos: f64, b: [f64; C], a: [f64; C], both: bool| {
            if cos > 0.0 {
                for c in 0..C {
                    acc[c] += cos * b[c];
                }
            }
            if self.use_anti && (self.two_sided || both || cos < 0.0) {
                let k = cos.abs();
                for c in 0..C {
                    acc[c] -= k * a[c];
                }
            }
        };
        if groups.is_grouped(l.sender) {
            let (g0, g1) = groups.range[l.sender as usize];
            for g in g0 as usize..g1 as usize {
                add(
                    groups.normal[g].dot(w),
                    group_b[g],
                    group_a[bin * groups.normal.len() + g],
                    groups.both[g],
                );
            }
        } else {
            let (e0, e1) = self.tree.nodes[l.sender as usize].elements;
            for e in e0 as usize..e1 as usize {
                let a = self.elem_area[e];
                let a_e = self
                    .live
                    .slot(e, bin)
                    .map_or([0.0; C], |k| anti[k].map(|x| a * x as f64));
                add(
                    self.elem_normal[e].dot(w),
                    radiance[e].map(|x| a * x),
                    a_e,
                    self.elem_back[e],
                );
            }
        }
        acc
    }
}

/// The geometric factors of one (receiving element, cluster link) pair
/// ([`SweepContext::pair_factor`]).
#[derive(Clone, Copy, Debug, Default)]
struct PairFactor {
    /// Irradiance per unit of the link's intensity.
    irradiance: f32,
    /// Antiradiance in the link's bin per unit of the link's intensity (0 when none is created).
    anti: f32,
}

/// The factors of every (element, cluster link) pair, per element in the order of
/// [`SweepContext::for_each_pair`]: element `e`'s pairs are `factor[start[e] .. start[e + 1]]`.
#[derive(Clone, Debug, Default)]
struct PairCache {
    /// Bin of every cluster link (a compact copy of `ClusterLink::bin` for the stream).
    link_bin: Vec<u16>,
    start: Vec<u64>,
    /// Per pair, its [`PairFactor`] as `[irradiance, anti]` (an array of floats, so the
    /// allocation is zeroed lazily by the system instead of written element by element: on the
    /// room that serial fill of 80 MB took 75 ms).
    factor: Vec<[f32; 2]>,
}

impl PairCache {
    /// The cache for `prepared` (tree, links, element arrays and `use_anti` set), or the bytes
    /// it would take when that is more than `budget`.
    fn build(prepared: &Prepared, budget: u64) -> std::result::Result<PairCache, u64> {
        let (tree, links) = (&prepared.tree, &prepared.links);
        let n = prepared.element_count();
        let count = |e: usize| {
            let mut total = 0usize;
            let mut node = tree.elements[e];
            while node != NONE {
                total += (links.cluster_start[node as usize + 1]
                    - links.cluster_start[node as usize]) as usize;
                node = tree.nodes[node as usize].parent;
            }
            total
        };
        let counts: Vec<usize> = (0..n).into_par_iter().map(count).collect();
        let total: usize = counts.iter().sum();
        let bytes = (total * std::mem::size_of::<[f32; 2]>() + (n + 1) * 8) as u64;
        if bytes > budget {
            return Err(bytes);
        }
        let mut start = Vec::with_capacity(n + 1);
        start.push(0);
        for c in &counts {
            start.push(start.last().expect("pushed") + *c as u64);
        }
        let mut factor = vec![[0.0f32; 2]; total];
        let ctx = prepared.sweep_context();
        split_by_start(&mut factor, &start)
            .into_par_iter()
            .enumerate()
            .for_each(|(e, out)| {
                let mut k = 0;
                ctx.for_each_pair(e, links, |_, _, f| {
                    out[k] = [f.irradiance, f.anti];
                    k += 1;
                });
            });
        let link_bin = links.cluster.iter().map(|l| l.bin).collect();
        Ok(PairCache {
            link_bin,
            start,
            factor,
        })
    }

    /// Calls `f` for element `e` and each of its ancestors (element first, then up the tree,
    /// as [`SweepContext::for_each_pair`] orders them) with the node's incoming cluster links
    /// (a range of `links.cluster`) and their factors for `e`.
    #[inline]
    fn for_each_node(
        &self,
        e: usize,
        tree: &ClusterTree,
        links: &Links,
        mut f: impl FnMut(std::ops::Range<usize>, &[[f32; 2]]),
    ) {
        let mut k = self.start[e] as usize;
        let mut node = tree.elements[e];
        while node != NONE {
            let range = links.cluster_start[node as usize] as usize
                ..links.cluster_start[node as usize + 1] as usize;
            let len = range.len();
            f(range, &self.factor[k..k + len]);
            k += len;
            node = tree.nodes[node as usize].parent;
        }
    }

    /// Bytes held.
    fn bytes(&self) -> u64 {
        (self.start.len() * 8
            + self.link_bin.len() * 2
            + self.factor.len() * std::mem::size_of::<[f32; 2]>()) as u64
    }
}

/// The antiradiance bins each element stores: those some link both writes into the element
/// (light arriving at its front, or at either side when two-sided) and reads from it (a cluster
/// link sent by one of its ancestors, or an exact coupling it sends). Every other bin of the
/// element stays 0 or is never read, so it is not stored. Element `e`'s stored bins, in
/// increasing order, are slots `start[e] .. start[e + 1]` of the antiradiance array.
#[derive(Clone, Debug, Default)]
struct LiveBins {
    /// 64-bit words per element mask.
    words: usize,
    /// Per element, `words` words: bit b set when bin b is stored.
    mask: Vec<u64>,
    /// Per element, its first slot; `start[n]` is the slot count.
    start: Vec<u32>,
}

impl LiveBins {
    /// No bin stored for any of `n` elements (no antiradiance).
    fn empty(n: usize, nb: usize) -> LiveBins {
        let words = nb.div_ceil(64);
        LiveBins {
            words,
            mask: vec![0; n * words],
            start: vec![0; n + 1],
        }
    }

    /// The bins each element of `prepared` (tree, links, element arrays set) must store.
    fn build(prepared: &Prepared) -> LiveBins {
        let (tree, links) = (&prepared.tree, &prepared.links);
        let n = prepared.element_count();
        let words = prepared.bins.len().div_ceil(64);
        let ctx = prepared.sweep_context();
        let set = |m: &mut [u64], bin: usize| m[bin >> 6] |= 1u64 << (bin & 63);

        // Read: bins of the cluster links each node sends (inherited by its elements) and of the
        // exact couplings each element sends that carry its antiradiance.
        let mut node_sends = vec![0u64; tree.nodes.len() * words];
        for l in &links.cluster {
            let i = l.sender as usize;
            set(&mut node_sends[i * words..(i + 1) * words], l.bin as usize);
        }
        let mut read = vec![0u64; n * words];
        for e in 0..n {
            for l in links.exact_start[e]..links.exact_start[e + 1] {
                let s = links.exact_sender[l as usize] as usize;
                for entry in links.exact_entries_of(l as usize) {
                    if entry.f_a != 0.0 || entry.o_a != 0.0 {
                        set(&mut read[s * words..(s + 1) * words], entry.bin as usize);
                    }
                }
            }
        }
        // Written, per element: its exact couplings' bins, and the bins of the cluster links
        // into it and its ancestors where the light arrives at a side that creates antiradiance;
        // then keep the read ones.
        let mut mask = vec![0u64; n * words];
        mask.par_chunks_mut(words)
            .zip(read.par_chunks(words))
            .enumerate()
            .for_each(|(e, (m, r))| {
                for l in links.exact_start[e]..links.exact_start[e + 1] {
                    for entry in links.exact_entries_of(l as usize) {
                        if entry.o_b != 0.0 || entry.o_a != 0.0 {
                            set(m, entry.bin as usize);
                        }
                    }
                }
                // The sweep's own per-pair factors (from the cache when there is one): a bin is
                // written where the pair's antiradiance factor is not 0.
                match &prepared.pairs {
                    Some(cache) => cache.for_each_node(e, tree, links, |range, factors| {
                        for (f, l) in factors.iter().zip(&links.cluster[range]) {
                            if f[1] != 0.0 {
                                set(m, l.bin as usize);
                            }
                        }
                    }),
                    None => ctx.for_each_pair(e, links, |_, l, f| {
                        if f.anti != 0.0 {
                            set(m, l.bin as usize);
                        }
                    }),
                }
                let mut reads = r.to_vec();
                let mut node = tree.elements[e];
                while node != NONE {
                    let i = node as usize;
                    for (k, word) in reads.iter_mut().enumerate() {
                        *word |= node_sends[i * words + k];
                    }
                    node = tree.nodes[i].parent;
                }
                for (word, r) in m.iter_mut().zip(&reads) {
                    *word &= r;
                }
            });
        let mut start = Vec::with_capacity(n + 1);
        let mut total = 0u32;
        start.push(0);
        for m in mask.chunks(words.max(1)) {
            total += m.iter().map(|w| w.count_ones()).sum::<u32>();
            start.push(total);
        }
        start.truncate(n + 1);
        LiveBins { words, mask, start }
    }

    /// Stored slots in all.
    fn slots(&self) -> usize {
        self.start.last().map_or(0, |&s| s as usize)
    }

    /// Bytes of the masks and offsets.
    fn bytes(&self) -> u64 {
        (self.mask.len() * 8 + self.start.len() * 4) as u64
    }

    /// The slot of element `e`'s bin `bin`, or `None` when it is not stored.
    #[inline]
    fn slot(&self, e: usize, bin: usize) -> Option<usize> {
        let m = &self.mask[e * self.words..(e + 1) * self.words];
        let (w, bit) = (bin >> 6, bin & 63);
        if (m[w] >> bit) & 1 == 0 {
            return None;
        }
        let below: u32 = m[..w].iter().map(|x| x.count_ones()).sum();
        Some(self.start[e] as usize + (below + (m[w] & ((1u64 << bit) - 1)).count_ones()) as usize)
    }

    /// Element `e`'s stored bins, increasing (the order of its slots).
    fn bins_of(&self, e: usize) -> impl Iterator<Item = usize> + '_ {
        self.mask[e * self.words..(e + 1) * self.words]
            .iter()
            .enumerate()
            .flat_map(|(k, &word)| {
                let mut w = word;
                std::iter::from_fn(move || {
                    if w == 0 {
                        return None;
                    }
                    let b = w.trailing_zeros() as usize;
                    w &= w - 1;
                    Some(k * 64 + b)
                })
            })
    }
}

/// Most memory the Anderson history may take; above it the solver extrapolates the tail instead.
const ACCELERATION_BUDGET_BYTES: u64 = 512 << 20;

/// Radiance and antiradiance state as one flat vector (radiance first, then the antiradiance
/// slots in order).
fn pack<const C: usize>(radiance: &[[f64; C]], anti: &[[f32; C]], out: &mut Vec<f64>) {
    out.clear();
    out.extend(radiance.iter().flatten());
    out.extend(anti.iter().flatten().map(|&x| x as f64));
}

/// The inverse of [`pack`].
fn unpack<const C: usize>(flat: &[f64], radiance: &mut [[f64; C]], anti: &mut [[f32; C]]) {
    let (b, a) = flat.split_at(radiance.len() * C);
    for (dst, src) in radiance.iter_mut().zip(b.chunks_exact(C)) {
        dst.copy_from_slice(src);
    }
    for (dst, src) in anti.iter_mut().zip(a.chunks_exact(C)) {
        for c in 0..C {
            dst[c] = src[c] as f32;
        }
    }
}

/// `x += k (x - x_previous)`, element-wise.
fn extrapolate<const C: usize, T>(x: &mut [[T; C]], x_previous: &[[T; C]], k: f64)
where
    T: Copy + Into<f64> + FromF64 + Send + Sync,
{
    x.par_iter_mut()
        .zip(x_previous.par_iter())
        .for_each(|(a, b)| {
            for c in 0..C {
                let (v, p): (f64, f64) = (a[c].into(), b[c].into());
                a[c] = T::from_f64(v + k * (v - p));
            }
        });
}

/// Conversion back from f64 for [`extrapolate`].
trait FromF64 {
    fn from_f64(x: f64) -> Self;
}

impl FromF64 for f64 {
    fn from_f64(x: f64) -> Self {
        x
    }
}

impl FromF64 for f32 {
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::build_patches;
    use crate::scenes;

    impl LiveBins {
        /// Every bin of every element stored.
        fn every(n: usize, nb: usize) -> LiveBins {
            let words = nb.div_ceil(64);
            let mut mask = vec![0u64; n * words];
            for e in 0..n {
                for bin in 0..nb {
                    mask[e * words + (bin >> 6)] |= 1u64 << (bin & 63);
                }
            }
            let start = (0..=n).map(|e| (e * nb) as u32).collect();
            LiveBins { words, mask, start }
        }
    }

    /// Storing only the live bins gives the result of storing every bin, for one- and two-sided
    /// antiradiance and for a bin count above 64 (several mask words).
    #[test]
    fn live_bins_give_the_result_of_every_bin() {
        let patches = build_patches(&scenes::cornell_box(), Some(150.0));
        for (bins, two_sided) in [(8, false), (8, true), (9, false)] {
            let options = SolverOptions {
                bins,
                two_sided,
                max_iterations: 20,
                // Plain sweeps: bins stored but never read would still steer Anderson's mixing.
                acceleration_depth: 0,
                ..SolverOptions::default()
            };
            let mut pruned = Prepared::new(&patches, &options, false).unwrap();
            let mut every = Prepared::new(&patches, &options, false).unwrap();
            every.live = LiveBins::every(every.element_count(), every.bins.len());
            assert!(pruned.live.slots() < every.live.slots());
            let (a, _) = pruned.solve(&patches, &Progress::hidden());
            let (b, _) = every.solve(&patches, &Progress::hidden());
            assert_eq!(a.stats.iterations, b.stats.iterations);
            for (x, y) in a.patch_radiance.iter().zip(&b.patch_radiance) {
                for c in 0..3 {
                    assert!(
                        (x[c] - y[c]).abs() <= 1e-9 * y[c].abs().max(1e-6),
                        "bins {bins} two-sided {two_sided}: {x:?} vs {y:?}"
                    );
                }
            }
        }
    }

    /// Transport that creates energy (albedos far above 1, which no scene file can give) makes
    /// the iteration diverge: both solvers stop at the sweep whose radiance overflows and say
    /// so, instead of taking the overflow's zero change for convergence.
    #[test]
    fn an_overflowing_iteration_is_reported_as_diverged() {
        let mut patches = build_patches(&scenes::cornell_box(), None);
        for a in &mut patches.albedo {
            *a = a.map(|x| 100.0 * x.max(0.5));
        }
        let options = SolverOptions {
            direct_light: false,
            ..SolverOptions::default()
        };
        let hidden = Progress::hidden();
        for solution in [
            solve_hierarchical(&patches, &options, &hidden).unwrap(),
            crate::dense::solve_dense(&patches, &options, &hidden).unwrap(),
        ] {
            let stats = &solution.stats;
            assert!(stats.failure.is_some() && !stats.converged, "{stats:?}");
            assert!(stats.iterations < options.max_iterations, "{stats:?}");
            assert!(solution
                .patch_radiance
                .iter()
                .all(|b| b.iter().all(|x| x.is_finite())));
        }
    }

    #[test]
    fn live_bin_slots_follow_the_mask() {
        let mut live = LiveBins::empty(2, 130);
        for (e, bin) in [(0, 3), (0, 64), (0, 129), (1, 0), (1, 70)] {
            live.mask[e * live.words + (bin >> 6)] |= 1u64 << (bin & 63);
        }
        live.start = vec![0, 3, 5];
        assert_eq!(live.bins_of(0).collect::<Vec<_>>(), vec![3, 64, 129]);
        assert_eq!(live.bins_of(1).collect::<Vec<_>>(), vec![0, 70]);
        assert_eq!(live.slot(0, 3), Some(0));
        assert_eq!(live.slot(0, 64), Some(1));
        assert_eq!(live.slot(0, 129), Some(2));
        assert_eq!(live.slot(0, 4), None);
        assert_eq!(live.slot(1, 70), Some(4));
        assert_eq!(live.slots(), 5);
    }
}
