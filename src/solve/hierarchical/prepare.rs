//! Building a [`Prepared`] scene: the tree, the links and the element arrays within the
//! memory budget, coarsened step by step until the model fits.

use super::*;

/// A leaf is split while its radius exceeds this share of its distance from a point or spot
/// light in front of it ([`ClusterTree::split_toward_points`]).
pub const LIGHT_SPLIT_RATIO: f64 = 0.5;

/// Share of the bytes per element an attempt refused for what the solve adds beside its model
/// ([`OverBudget::solve_bytes_per_element`]) that the next attempts count while they refine
/// ([`LinkBudget::reserve_per_element`]). Below 1 because a coarser model adds a little less
/// per element (b90_office at `--memory-limit 2G`: about 12.2, 12.1 and 11.8 kB per element at
/// epsilon 2, 4 and 8), so the reserve does not refuse a model that would fit.
pub const RESERVE_SHARE: f64 = 0.9;

/// The cluster tree of a scene before any on-demand split, with the sides of each patch that
/// block light: built once and kept by the attempts of [`Prepared::new`] (each undoes the
/// splits of the one before, [`ClusterTree::unsplit`]), since coarsening changes neither.
pub(super) struct BaseTree {
    /// The tree, marked with the sides that block; an attempt takes it and hands it back when
    /// it does not fit.
    pub(super) tree: ClusterTree,
    /// Node count before any split.
    nodes: usize,
    /// Per patch: blocks light arriving at its back ([`model::Backs::blocking`]).
    back_blocking: Vec<bool>,
    /// Per patch: two-sided, with a back face of its own ([`model::Backs::faces`]).
    two_sided: Vec<bool>,
    /// Seconds the tree and the sides took.
    seconds: f64,
    /// The sender groups per element of the tree an attempt refines, by its node count once
    /// split toward the point lights ([`SenderGroups::share`]): attempts whose light splits give
    /// the same tree (every attempt, in a scene without point lights) count them once.
    share: Option<(usize, f64)>,
}

impl BaseTree {
    /// The tree of `patches` and the sides of each patch that block light under `options`
    /// ([`model::Backs::of`]).
    pub(super) fn new(patches: &Patches, options: &SolverOptions) -> BaseTree {
        let t0 = Instant::now();
        let mut tree = ClusterTree::build(patches);
        let model::Backs {
            blocking: back_blocking,
            faces: two_sided,
        } = model::Backs::of(patches, options);
        tree.mark_back_blocking(&back_blocking);
        tree.mark_two_sided(&two_sided);
        tree.mark_light(&model::light_factors(patches));
        BaseTree {
            nodes: tree.nodes.len(),
            tree,
            back_blocking,
            two_sided,
            seconds: t0.elapsed().as_secs_f64(),
            share: None,
        }
    }
}

impl Prepared {
    /// Builds the tree and refines the links for `patches` within the memory limit of
    /// `options` ([`SolverOptions::memory_limit_bytes`], see [`crate::solve::budget`]): a model whose
    /// estimate does not fit (with its Anderson history, unless it is the coarsest) is
    /// coarsened step by step ([`budget::coarser`]; the pair cache is left out first), and
    /// [`Prepared::memory`] says what was changed. `record_culled` keeps
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
        Prepared::within(patches, options, record_culled, budget)
    }

    /// [`Prepared::new`] within `budget` (the limit and what the process held before).
    pub(super) fn within(
        patches: &Patches,
        options: &SolverOptions,
        record_culled: bool,
        budget: Budget,
    ) -> Result<Prepared> {
        let tree_bytes = HierarchicalCosts::tree_bytes(patches.len() as u64);
        if !budget.fits(tree_bytes) {
            return Err(budget.does_not_fit(
                &format!("the cluster tree of {} patches", patches.len()),
                tree_bytes,
                "raise SolverOptions::memory_limit_bytes",
            ));
        }
        let channels = channels_needed(patches);
        let mut base = BaseTree::new(patches, options);
        let mut model = options.clone();
        let mut coarsened = Vec::new();
        let mut attempts = 0;
        let mut discarded_seconds = 0.0;
        // What the solve adds per element beside the model, once an attempt was refused for it.
        let mut reserve_per_element = 0;
        loop {
            let link_budget = LinkBudget {
                costs: HierarchicalCosts::new(model.bins, channels),
                budget,
                patches: patches.len() as u64,
                reserve_per_element,
            };
            attempts += 1;
            let t_attempt = Instant::now();
            let attempt = Prepared::build(patches, &model, record_culled, &link_budget, &mut base);
            let over = match attempt {
                Ok(mut prepared) if attempts > 1 && !prepared.solve_fits_beside_held(channels) => {
                    base.tree = std::mem::take(&mut prepared.tree);
                    OverBudget {
                        estimate: prepared.memory.estimate_bytes,
                        solve_bytes_per_element: 0,
                    }
                }
                Ok(mut prepared) => {
                    prepared.timings.tree += base.seconds;
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
            // What the refused attempt freed in small blocks goes back to the system before the
            // next one is measured against what the process holds.
            crate::memory::release_freed();
            if over.solve_bytes_per_element > 0 {
                reserve_per_element = (over.solve_bytes_per_element as f64 * RESERVE_SHARE) as u64;
            }
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

    /// True when what the solve allocates once the model is built (its state and, where the
    /// fit reserved it, the Anderson history) fits beside what the process holds now, or when
    /// the model is the coarsest or the resident memory is unknown. The refinements that did
    /// not fit leave memory the allocator keeps (the generated classroom at `--memory-limit
    /// 600M`: 250 MiB resident between attempts against 20 MiB before them), and the solve's
    /// large arrays do not reuse it: without this check the classroom peaked at 592 to 637 MiB
    /// there, with it at 508 to 550 MiB (one or two steps coarser: what the allocator keeps
    /// varies from run to run, and so does the model kept).
    pub(super) fn solve_fits_beside_held(&self, channels: usize) -> bool {
        // Where the resident memory is unknown the budget's base is 0, and the fit (with the
        // whole model beside the history) already passed against the limit.
        budget::coarser(&self.options).is_none()
            || Budget::start(self.budget.limit)
                .fits(self.state_bytes + self.planned_history_bytes(self.live.slots(), channels))
    }

    /// One attempt of [`Prepared::new`] with the model of `options`: tree (from `base`,
    /// every split of an earlier attempt undone), links, element arrays, groups, live bins and
    /// (when it fits) the pair cache, or [`OverBudget`] as soon as the estimate exceeds
    /// `link_budget` (the tree is then handed back to `base`).
    pub(super) fn build(
        patches: &Patches,
        options: &SolverOptions,
        record_culled: bool,
        link_budget: &LinkBudget,
        base: &mut BaseTree,
    ) -> std::result::Result<Prepared, OverBudget> {
        let bins = Bins::new(options.bins);
        let t0 = Instant::now();
        let mut tree = std::mem::take(&mut base.tree);
        tree.unsplit(base.nodes);
        let (back_blocking, two_sided) = (&base.back_blocking, &base.two_sided);
        // Every face gets its own direct light from point and spot lights
        // (`Prepared::light_source_of_faces`): elements near them are made small enough for it
        // to vary between them.
        let params = link_params(options);
        let points: Vec<_> = patches.lights.iter().filter_map(|l| l.position()).collect();
        tree.split_toward_points(
            &points,
            LIGHT_SPLIT_RATIO,
            params.max_split_depth,
            params.min_radius,
        );
        // The budget assumes the sender groups per element of the tree as it stands.
        let share = match base.share {
            Some((nodes, share)) if nodes == tree.nodes.len() => share,
            _ => {
                let share = SenderGroups::share(&mut tree);
                base.share = Some((tree.nodes.len(), share));
                share
            }
        };
        let link_budget = &LinkBudget {
            costs: link_budget.costs.with_group_share(share),
            ..*link_budget
        };
        let t1 = Instant::now();
        let links = match links::refine(
            &mut tree,
            &bins,
            &params,
            &options.coupling(),
            record_culled,
            link_budget,
        ) {
            Ok(links) => links,
            Err(over) => {
                base.tree = tree;
                return Err(over);
            }
        };
        let t2 = Instant::now();
        crate::memory::release_freed();
        debug_assert!(tree.validate().is_ok(), "{:?}", tree.validate());
        let mut prepared = Prepared {
            elem_area: Vec::with_capacity(tree.elements.len()),
            elem_normal: Vec::with_capacity(tree.elements.len()),
            elem_center: Vec::with_capacity(tree.elements.len()),
            elem_albedo: Vec::with_capacity(tree.elements.len()),
            elem_patch: Vec::with_capacity(tree.elements.len()),
            elem_send_area: Vec::new(),
            elem_back: Vec::with_capacity(tree.elements.len()),
            elem_two: Vec::new(),
            back_faces: Vec::new(),
            back_blocking_patches: back_blocking.iter().filter(|&&b| b).count() as u64,
            groups: SenderGroups::default(),
            live: LiveBins::default(),
            fields: Fields::default(),
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
            acceleration_budget: super::ACCELERATION_BUDGET_BYTES,
            state_bytes: 0,
            sweep_bytes: 0,
            memory: MemoryStats::default(),
            timings: HierarchyTimings {
                tree: (t1 - t0).as_secs_f64(),
                links: (t2 - t1).as_secs_f64(),
                model: 0.0,
                iterate: 0.0,
                direct: 0.0,
            },
        };
        prepared.fill_elements(patches, two_sided.iter().any(|&b| b));
        prepared.groups = SenderGroups::build(
            &prepared.tree,
            &prepared.elem_area,
            &prepared.elem_normal,
            &prepared.elem_back,
        );
        prepared.fields = Fields::build(&mut prepared, options.field_ratio, record_culled);
        crate::memory::release_freed();
        prepared.work = prepared.count_sweep_work();
        // Model only what the scene needs: grey albedos allow one-channel solves; a convex
        // enclosure needs no antiradiance; each element stores only the bins links use.
        prepared.albedo_grey = prepared.elem_albedo.iter().all(|&a| model::is_grey(a));
        prepared.convex = model::is_convex_enclosure(&prepared.tree);
        prepared.use_anti = options.antiradiance && !prepared.convex;
        if let Err(over) = prepared.fit_model(patches, link_budget) {
            base.tree = std::mem::take(&mut prepared.tree);
            return Err(over);
        }
        prepared.timings.model = t2.elapsed().as_secs_f64();
        Ok(prepared)
    }

    /// Weighs what each element sends by its patch's visible share
    /// ([`Patches::visible_share`]): its send area, and the entries of its exact links as
    /// sender (every entry weighs the sender's radiance or antiradiance).
    fn weigh_senders(&mut self, patches: &Patches) {
        let share = |e: usize| patches.visible_share(self.elem_patch[e] as usize);
        self.elem_send_area = (0..self.elem_area.len())
            .map(|e| self.elem_area[e] * share(e))
            .collect();
        let links = &mut self.links;
        for l in 0..links.exact_sender.len() {
            let w = share(links.exact_sender[l] as usize) as f32;
            if w == 1.0 {
                continue;
            }
            let (start, end) = (
                links.exact_entry_start[l] as usize,
                links.exact_entry_start[l + 1] as usize,
            );
            for entry in &mut links.exact_entries[start..end] {
                entry.f_b *= w;
                entry.f_a *= w;
                entry.o_b *= w;
                entry.o_a *= w;
            }
        }
    }

    /// Fills the per-element arrays from the finalized tree: area, normal, centroid, albedo,
    /// patch and back blocking, and (`any_two_sided`) which elements have a back face.
    fn fill_elements(&mut self, patches: &Patches, any_two_sided: bool) {
        for &node in &self.tree.elements {
            let n = &self.tree.nodes[node as usize];
            self.elem_area.push(n.area);
            self.elem_normal.push(n.plane_normal());
            self.elem_center.push(n.centroid);
            self.elem_albedo.push(patches.albedo[n.patch as usize]);
            self.elem_patch.push(n.patch);
            self.elem_back.push(n.blocks_back);
        }
        if !patches.visible_shares.is_empty() {
            self.weigh_senders(patches);
        }
        if any_two_sided {
            let tree = &self.tree;
            self.elem_two = (tree.elements.iter())
                .map(|&node| tree.nodes[node as usize].two_sided)
                .collect();
            self.back_faces = (0..self.elem_two.len() as u32)
                .filter(|&e| self.elem_two[e as usize])
                .collect();
        }
    }

    /// Sizes the model within the memory budget: the live bins and (when it fits its own
    /// budget and what the model and its Anderson history leave) the pair cache, then the
    /// estimate of the whole, or [`OverBudget`] when it does not fit beside the history.
    pub(super) fn fit_model(
        &mut self,
        patches: &Patches,
        link_budget: &LinkBudget,
    ) -> std::result::Result<(), OverBudget> {
        let options = &self.options;
        // What the model holds; the stored bins are bounded by every bin until they are known.
        let n = self.element_count() as u64;
        let mut counts = ModelCounts {
            patches: patches.len() as u64,
            nodes: self.tree.nodes.len() as u64,
            elements: n,
            cluster_links: self.links.cluster.len() as u64,
            exact_pairs: self.links.exact_sender.len() as u64,
            entries: Some(self.links.exact_entries.len() as u64),
            slots: Some(if self.use_anti {
                n * self.bins.len() as u64
            } else {
                0
            }),
            groups: Some(self.groups.normal.len() as u64),
        };
        let costs = &link_budget.costs;
        let budget = &link_budget.budget;
        // The Anderson history, reserved in the fit (and before the caches) while a coarser
        // model is left to fall back on: a solve whose damped sweeps stall or diverge needs it
        // more than it needs a finer model. The coarsest model fits without it. The exact
        // direct light's result (24 bytes a face) lives beside it.
        let channels = costs.channels() as usize;
        let reserve = budget::coarser(options).is_some();
        let history = |prepared: &Prepared, slots: u64| match prepared
            .planned_history_bytes(slots as usize, channels)
        {
            bytes if reserve && bytes > 0 => {
                bytes + 24 * (prepared.element_count() + prepared.elem_two.len()) as u64
            }
            _ => 0,
        };
        let build_live = |prepared: &Prepared| {
            if prepared.use_anti {
                LiveBins::build(prepared)
            } else {
                LiveBins::empty(prepared.element_count(), prepared.bins.len())
            }
        };
        // The pair cache, within its own budget and what the model, its fields and the history
        // leave of the memory limit (with every bin counted; if it does not fit so, the live
        // bins are found first and it is tried again with the bins the elements store).
        let own = options.pair_cache_mb as u64 * 1_000_000;
        let mut cache_dropped = false;
        // The fields and their per-sweep sums, every slot's until the live bins are known (an
        // upper bound).
        let fields_bytes = self.fields.bytes() + self.fields.sweep_bytes(channels);
        // The solved elements, when kept, are made while the model is held.
        let kept_elements = if options.keep_elements {
            n * std::mem::size_of::<crate::solve::solution::ElementRadiance>() as u64
        } else {
            0
        };
        let history_all_bins = history(self, counts.slots.unwrap_or(0));
        match PairCache::build(
            &*self,
            own.min(
                budget
                    .spare(costs.bytes(&counts) + history_all_bins + fields_bytes + kept_elements),
            ),
        ) {
            Ok(cache) => {
                self.pairs = Some(cache);
                self.live = build_live(&*self);
            }
            Err(cache_bytes) => {
                self.live = build_live(&*self);
                counts.slots = Some(self.live.slots() as u64);
                if cache_bytes <= own {
                    let history_live = history(self, self.live.slots() as u64);
                    let spare = budget
                        .spare(costs.bytes(&counts) + history_live + fields_bytes + kept_elements);
                    self.pairs = PairCache::build(&*self, own.min(spare)).ok();
                    cache_dropped = self.pairs.is_none();
                }
            }
        }
        counts.slots = Some(self.live.slots() as u64);
        self.fields.keep_live(&self.tree, &self.live);
        // What the model holds: the links' and elements' arrays, the pair cache, the fields
        // (with their cached terms once kept) and their per-sweep sums.
        let sweep_sums = self.fields.sweep_bytes(channels);
        let pair_bytes = self.pairs.as_ref().map_or(0, PairCache::bytes);
        let held = |fields: &Fields| {
            costs.bytes(&counts) + pair_bytes + fields.bytes() + sweep_sums + kept_elements
        };
        let history_live = history(self, self.live.slots() as u64);
        // The field links' terms, as many fields' as fit what the pair cache left of its
        // budget.
        let terms_budget = own
            .saturating_sub(pair_bytes)
            .min(budget.spare(held(&self.fields) + history_live));
        if self.fields.links > 0 && terms_budget > 0 {
            let mut fields = std::mem::take(&mut self.fields);
            fields.cache_terms(&self.sweep_context(), &self.links, terms_budget);
            self.fields = fields;
        }
        let estimate = held(&self.fields);
        if !budget.fits(estimate + history_live) {
            // What the fit adds to the model's arrays, but for the pair cache (which takes what
            // is spare), with the solved elements when they are kept.
            let beside = self.fields.bytes() + sweep_sums + history_live + kept_elements;
            return Err(OverBudget {
                estimate,
                solve_bytes_per_element: beside / self.element_count().max(1) as u64,
            });
        }
        self.memory.estimate_bytes = estimate;
        self.sweep_bytes = estimate;
        self.state_bytes = costs.state_bytes(&counts) + sweep_sums;
        if cache_dropped {
            self.memory.coarsened.push("pair cache off".into());
        }
        Ok(())
    }
}
