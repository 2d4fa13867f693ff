use super::prepare::BaseTree;
use super::*;
use crate::mesh::build_patches;
use crate::scene::generated;

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
    let patches = build_patches(&generated::cornell_box(), Some(150.0));
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
    let mut patches = build_patches(&generated::cornell_box(), None);
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
        crate::solve::dense::solve_dense(&patches, &options, &hidden).unwrap(),
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

/// The attempts of a coarsened solve share one tree: an attempt after one that split leaves
/// builds the model a fresh tree gives.
#[test]
fn an_attempt_after_a_split_one_builds_the_fresh_model() {
    let patches = build_patches(&generated::cornell_box(), None);
    let fine = SolverOptions::accurate();
    let coarse = SolverOptions {
        epsilon: 1.0,
        split_depth: 2,
        ..fine.clone()
    };
    let budget = LinkBudget::unlimited(fine.bins);
    let mut base = BaseTree::new(&patches, &fine);
    let nodes = base.tree.nodes.len();
    let first = Prepared::build(&patches, &fine, false, &budget, &mut base).unwrap();
    assert!(
        first.tree.nodes.len() > nodes,
        "the fine model splits leaves"
    );
    // As a failed attempt does: the tree goes back to the base with its splits.
    base.tree = first.tree;
    let again = Prepared::build(&patches, &coarse, false, &budget, &mut base).unwrap();
    let fresh = Prepared::build(
        &patches,
        &coarse,
        false,
        &budget,
        &mut BaseTree::new(&patches, &coarse),
    )
    .unwrap();
    assert_eq!(again.tree.nodes.len(), fresh.tree.nodes.len());
    assert_eq!(again.links.cluster.len(), fresh.links.cluster.len());
    assert_eq!(again.links.exact_sender, fresh.links.exact_sender);
    let senders = |p: &Prepared| {
        p.links
            .cluster
            .iter()
            .map(|l| (l.sender, l.receiver, l.bin))
            .collect::<Vec<_>>()
    };
    assert_eq!(senders(&again), senders(&fresh));
}

/// A solve whose pair cache did not fit its own budget builds it once it has run
/// [`LATE_PAIR_CACHE_SWEEPS`] sweeps, counts it in its memory estimate, and gives the result of
/// the solve that never caches (the cached gather sums the same f32 factors).
#[test]
fn a_long_solve_builds_its_pair_cache_late() {
    let patches = build_patches(&generated::cornell_box(), Some(100.0));
    let options = |pair_cache_mb| SolverOptions {
        pair_cache_mb,
        // Long enough to pass the late cache: plain sweeps to a tight tolerance.
        acceleration_depth: 0,
        tol: 1e-7,
        direct_light: false,
        ..SolverOptions::default()
    };
    let hidden = Progress::hidden();
    // Both built without a cache (0 MB disables it); then `late` is allowed one of 1 MB, which
    // its factors do not fit up front but which does not bound the late cache.
    let prepare = || match Prepared::new(&patches, &options(0), false) {
        Ok(prepared) => prepared,
        Err(e) => panic!("the box does not fit: {e}"),
    };
    let mut late = prepare();
    late.options.pair_cache_mb = 1;
    assert!(late.pairs.is_none());
    let mut never = prepare();
    let (a, _) = late.solve(&patches, &hidden);
    let (b, _) = never.solve(&patches, &hidden);
    assert!(
        a.stats.iterations > LATE_PAIR_CACHE_SWEEPS,
        "{}",
        a.stats.iterations
    );
    assert!(never.pairs.is_none());
    let Some(cache) = late.pairs.as_ref() else {
        panic!("no late pair cache after {} sweeps", a.stats.iterations);
    };
    let (estimate_late, estimate_never) = (
        a.stats.memory.as_ref().map_or(0, |m| m.estimate_bytes),
        b.stats.memory.as_ref().map_or(0, |m| m.estimate_bytes),
    );
    assert_eq!(estimate_late, estimate_never + cache.bytes());
    for (x, y) in a.patch_radiance.iter().zip(&b.patch_radiance) {
        for c in 0..3 {
            assert!(
                (x[c] - y[c]).abs() <= 1e-6 * y[c].abs().max(1e-6),
                "{x:?} vs {y:?}"
            );
        }
    }
}

/// The model of `patches` under `options` built without a pair cache (0 MB disables it), then
/// allowed one of 1 MB, which its factors do not fit up front but which does not bound the
/// late cache ([`LATE_PAIR_CACHE_SWEEPS`]).
fn late_cache_allowed(patches: &crate::mesh::Patches, options: SolverOptions) -> Prepared {
    let options = SolverOptions {
        pair_cache_mb: 0,
        ..options
    };
    let mut prepared = match Prepared::new(patches, &options, false) {
        Ok(prepared) => prepared,
        Err(e) => panic!("the model does not fit: {e}"),
    };
    prepared.options.pair_cache_mb = 1;
    prepared
}

/// A floor under a light, with `plates` 2 x 2 plates stacked between them 5 cm apart, facing
/// down: the floor sees every plate's front, unoccluded, so its rows sum to about one form
/// factor a plate.
fn stacked_plates(plates: usize) -> crate::mesh::Patches {
    let v = DVec3::new;
    let (up, down) = (DVec3::Y, -DVec3::Y);
    let mut b = generated::Builder::default();
    let floor = [v(0., 0., 0.), v(0., 0., 4.), v(4., 0., 4.), v(4., 0., 0.)];
    b.quad(floor, up, [0.75; 3], [0.0; 3]);
    let light = [v(1., 3., 1.), v(3., 3., 1.), v(3., 3., 3.), v(1., 3., 3.)];
    b.quad(light, down, [0.0; 3], [1.0; 3]);
    for k in 0..plates {
        let y = 0.3 + 0.05 * k as f64;
        let plate = [v(1., y, 1.), v(3., y, 1.), v(3., y, 3.), v(1., y, 3.)];
        b.quad(plate, down, [0.75; 3], [0.0; 3]);
    }
    build_patches(&b.build(), None)
}

/// The stacked plates with 8 plates (their floor's rows above
/// [`crate::solve::health::DAMP_ROW_SUM`]) and with 1 (below it), each prepared by `prepare`
/// and solved for `sweeps` sweeps without direct light: (deep, the model, the solution).
fn deep_and_shallow_plates(
    sweeps: usize,
    prepare: impl Fn(&crate::mesh::Patches, SolverOptions) -> Prepared,
) -> Vec<(bool, Prepared, crate::solve::solution::Solution)> {
    [(8, true), (1, false)]
        .into_iter()
        .map(|(plates, deep)| {
            let patches = stacked_plates(plates);
            let options = SolverOptions {
                max_iterations: sweeps,
                direct_light: false,
                ..SolverOptions::default()
            };
            let mut prepared = prepare(&patches, options);
            let (solution, _) = prepared.solve(&patches, &Progress::hidden());
            let rows = solution.stats.max_row_sum;
            assert_eq!(
                rows > crate::solve::health::DAMP_ROW_SUM,
                deep,
                "{plates} plates: rows {rows}"
            );
            (deep, prepared, solution)
        })
        .collect()
}

/// A solve whose first sweep's rows damp its antiradiance from the second
/// ([`crate::solve::health::DAMP_ROW_SUM`]) builds the pair cache it was built without right
/// after that sweep; one whose rows do not, does not.
#[test]
fn a_solve_with_deep_rows_builds_its_pair_cache_after_its_first_sweep() {
    for (deep, prepared, _) in deep_and_shallow_plates(1, late_cache_allowed) {
        assert_eq!(prepared.pairs.is_some(), deep, "deep rows: {deep}");
    }
}

/// A solve whose first sweep's rows damp its antiradiance takes its Anderson history after that
/// sweep, though the history is over the solver's own budget ([`ACCELERATION_BUDGET_BYTES`],
/// here 0); one whose rows do not, extrapolates.
#[test]
fn a_solve_with_deep_rows_takes_its_anderson_history_over_its_own_budget() {
    let no_budget = |patches: &crate::mesh::Patches, options: SolverOptions| {
        let mut prepared = match Prepared::new(patches, &options, false) {
            Ok(prepared) => prepared,
            Err(e) => panic!("the model does not fit: {e}"),
        };
        prepared.acceleration_budget = 0;
        prepared
    };
    for (deep, _, solution) in deep_and_shallow_plates(3, no_budget) {
        let acceleration = &solution.stats.acceleration;
        if deep {
            assert_eq!(acceleration, "anderson");
        } else {
            assert!(
                acceleration.starts_with("extrapolation (Anderson history of")
                    && acceleration.ends_with("over its 0 MB budget)"),
                "{acceleration}"
            );
        }
    }
}

/// The field links' cached terms give the sweeps of the solve that computes them each sweep,
/// and count in the memory estimate: the 4k-triangle Cornell box with the pair cache's
/// budget (which the terms share: every field's terms kept) and with 8 MB (the first fields'
/// kept, the others' computed each sweep). The cached terms are f32, whose rounding the
/// expansions' cancellations raise to about 1e-5 of a patch's brightest channel.
#[test]
fn cached_field_terms_give_the_same_sweeps() {
    let patches = build_patches(&generated::subdivided_cornell_box(4_000), None);
    let hidden = Progress::hidden();
    let prepare = |pair_cache_mb| {
        let options = SolverOptions {
            pair_cache_mb,
            ..SolverOptions::default()
        };
        match Prepared::new(&patches, &options, false) {
            Ok(prepared) => prepared,
            Err(e) => panic!("the box does not fit: {e}"),
        }
    };
    // 8 MB holds the box's pairs and a part of its field terms: both take the same links
    // (`fields::push` pushes more when the pairs are not cached).
    let (mut cached, mut partial) = (prepare(256), prepare(8));
    assert!(cached.pairs.is_some() && partial.pairs.is_some());
    assert_eq!(cached.links.cluster.len(), partial.links.cluster.len());
    assert!(cached.fields.links > 0, "no field links");
    assert_eq!(cached.fields.terms.len() as u64, cached.fields.links);
    let kept = partial.fields.terms.len() as u64;
    assert!(
        kept > 0 && kept < partial.fields.links,
        "{kept} of {}",
        partial.fields.links
    );
    assert_eq!(
        cached.memory.estimate_bytes - partial.memory.estimate_bytes,
        cached.fields.cached_terms_bytes() - partial.fields.cached_terms_bytes()
    );
    let (a, _) = cached.solve(&patches, &hidden);
    let (b, _) = partial.solve(&patches, &hidden);
    assert_eq!(a.stats.iterations, b.stats.iterations);
    for (x, y) in a.patch_radiance.iter().zip(&b.patch_radiance) {
        let scale = y.iter().fold(1e-6f64, |m, v| m.max(v.abs()));
        for c in 0..3 {
            assert!((x[c] - y[c]).abs() <= 1e-4 * scale, "{x:?} vs {y:?}");
        }
    }
}

/// A solve whose pair cache did not fit its own budget builds it after
/// [`crate::solve::MIN_SWEEPS`] sweeps when their contraction predicts at least
/// [`LATE_PAIR_CACHE_SWEEPS`] more (plain sweeps to a tolerance of 1e-12), and not when it
/// predicts fewer (the default tolerance, mixed sweeps).
#[test]
fn a_solve_predicted_long_builds_its_pair_cache_after_its_first_sweeps() {
    let patches = build_patches(&generated::cornell_box(), Some(100.0));
    let hidden = Progress::hidden();
    let cached_after_min_sweeps = |acceleration_depth, tol| {
        let options = SolverOptions {
            acceleration_depth,
            tol,
            max_iterations: crate::solve::MIN_SWEEPS,
            direct_light: false,
            ..SolverOptions::default()
        };
        let mut prepared = late_cache_allowed(&patches, options);
        assert!(prepared.pairs.is_none());
        let (solution, _) = prepared.solve(&patches, &hidden);
        assert_eq!(solution.stats.iterations, crate::solve::MIN_SWEEPS);
        prepared.pairs.is_some()
    };
    assert!(cached_after_min_sweeps(0, 1e-12));
    assert!(!cached_after_min_sweeps(4, 1e-3));
}

/// Where the pairs are not cached, near links into large receivers are pushed down into their
/// children when that costs the sweeps less (`fields::push`): every ordered pair of elements
/// is still covered exactly once, the sweeps evaluate fewer pairs than with the pairs cached
/// (where pushing seldom pays), and the result stays the per-element gather's.
#[test]
fn pushed_links_cover_every_pair_once_and_agree_with_the_per_element_gather() {
    let patches = build_patches(&generated::subdivided_cornell_box(4_000), None);
    let hidden = Progress::hidden();
    let prepare = |pair_cache_mb, field_ratio, record_culled| {
        let options = SolverOptions {
            pair_cache_mb,
            field_ratio,
            ..SolverOptions::default()
        };
        match Prepared::new(&patches, &options, record_culled) {
            Ok(prepared) => prepared,
            Err(e) => panic!("the box does not fit: {e}"),
        }
    };
    let mut pushed = prepare(0, 0.3, true);
    let kept = prepare(256, 0.3, false);
    assert!(pushed.fields.pushed > kept.fields.pushed, "nothing pushed");
    assert!(
        pushed.work.0 < kept.work.0,
        "{:?} {:?}",
        pushed.work,
        kept.work
    );
    if let Err(e) = crate::hierarchy::links::validate(&pushed.tree, &pushed.links) {
        panic!("pushed links: {e}");
    }
    let (a, _) = pushed.solve(&patches, &hidden);
    let (b, _) = prepare(0, 0.0, false).solve(&patches, &hidden);
    assert_eq!(b.stats.field_links, 0);
    let (mut num, mut den) = (0.0, 0.0);
    for ((x, y), area) in a
        .patch_radiance
        .iter()
        .zip(&b.patch_radiance)
        .zip(&patches.area)
    {
        for c in 0..3 {
            num += area * (x[c] - y[c]).abs();
            den += area * y[c].abs();
        }
    }
    assert!(num <= 0.003 * den, "{:.3}%", 100.0 * num / den);
}

#[test]
fn warm_factors_recover_a_combination_of_independent_sources() {
    let area = [1.0, 2.0, 0.5, 1.5];
    let s0 = [[1.0], [0.0], [2.0], [1.0]];
    let s1 = [[0.0], [1.0], [1.0], [3.0]];
    let s2 = [[2.0], [1.0], [0.0], [0.5]];
    let new: Vec<[f64; 1]> = (0..4)
        .map(|e| [0.5 * s0[e][0] - 1.5 * s1[e][0] + 2.0 * s2[e][0]])
        .collect();
    let k = warm_factors(&new, &[&s0, &s1, &s2], &area);
    for (got, want) in k.iter().zip([0.5, -1.5, 2.0]) {
        assert!((got[0] - want).abs() < 1e-12, "{k:?}");
    }
}

#[test]
fn warm_factors_leave_out_sources_that_add_nothing_independent() {
    // The older sources are multiples of the most recent one: it alone is scaled, exactly as
    // a single warm state is.
    let area = [1.0, 3.0, 0.25];
    let s0 = [[1.0, 2.0], [2.0, 0.0], [0.5, 1.0]];
    let s1 = s0.map(|x| x.map(|v| 3.0 * v));
    let s2 = s0.map(|x| x.map(|v| -0.5 * v));
    let new = [[2.0, 1.0], [4.5, 0.5], [1.0, 2.5]];
    let k = warm_factors(&new, &[&s0, &s1, &s2], &area);
    let alone = warm_factors(&new, &[&s0], &area);
    assert_eq!(k[0], alone[0]);
    assert_eq!(k[1], [0.0; 2]);
    assert_eq!(k[2], [0.0; 2]);
    // A zero source: factor 1, as before.
    let zero = [[0.0; 2]; 3];
    assert_eq!(warm_factors(&new, &[&zero], &area)[0], [1.0; 2]);
}

/// A warm-started solve keeps the states of the solves before it, up to [`WARM_BASES`] in
/// all, and none that the memory limit does not leave room for.
#[test]
fn warm_states_keep_their_predecessors_within_the_memory_limit() {
    let patches = build_patches(&generated::cornell_box(), Some(100.0));
    let options = SolverOptions {
        direct_light: false,
        ..SolverOptions::default()
    };
    let hidden = Progress::hidden();
    let solve_chain = |prepared: &mut Prepared| {
        let n = prepared.faces().count();
        let mut state: Option<ElementState> = None;
        for k in 0..4 {
            // Each source a different mix of the emitters and one glowing face.
            let source: Vec<[f64; 3]> = prepared
                .faces()
                .enumerate()
                .map(|(e, f)| {
                    let emitted = patches.emission[f.patch as usize];
                    let glow = if e == k * n / 5 { 0.5 } else { 0.0 };
                    emitted.map(|x| x * (1.0 + 0.1 * k as f64) + glow)
                })
                .collect();
            let (solution, next) =
                prepared.solve_with_source(&patches, &source, state.as_ref(), &hidden);
            assert!(solution.stats.converged);
            state = Some(next);
        }
        state.map_or(0, |s| s.earlier.len())
    };
    let mut roomy = match Prepared::new(&patches, &options, false) {
        Ok(prepared) => prepared,
        Err(e) => panic!("the box does not fit: {e}"),
    };
    assert_eq!(solve_chain(&mut roomy), WARM_BASES - 1);
    // No room beside the solve's own estimate: nothing kept, and the solves still converge.
    let mut tight = match Prepared::new(&patches, &options, false) {
        Ok(prepared) => prepared,
        Err(e) => panic!("the box does not fit: {e}"),
    };
    tight.budget = crate::memory::Budget {
        limit: tight.memory.estimate_bytes,
        base: 0,
    };
    assert_eq!(solve_chain(&mut tight), 0);
}

/// A model that fits its memory limit only without its Anderson history gives way to it:
/// the caches shrink or the model is coarsened until the history fits beside it, and the solve
/// mixes its sweeps (b90_office two-sided at 3 GB had its history left out, and its damped
/// sweeps diverged). Here the limit is the least the model with full caches fits without the
/// history.
#[test]
fn a_model_that_fits_only_without_its_history_keeps_anderson() {
    let options = SolverOptions {
        direct_light: false,
        ..SolverOptions::default()
    };
    let (patches, prepared) = box_without_limit(&options);
    let channels = channels_needed(&patches);
    let history = prepared.history_bytes(channels);
    assert!(history > 0);
    let tight = crate::memory::Budget {
        limit: crate::memory::with_slack(prepared.memory.estimate_bytes),
        base: 0,
    };
    assert!(tight.fits(prepared.memory.estimate_bytes));
    assert!(!tight.fits(prepared.memory.estimate_bytes + history));
    let mut fitted = match Prepared::within(&patches, &options, false, tight) {
        Ok(prepared) => prepared,
        Err(e) => panic!("the box does not fit: {e}"),
    };
    let with_history = fitted.memory.estimate_bytes + fitted.history_bytes(channels);
    assert!(
        tight.fits(with_history),
        "{with_history} over {}",
        tight.limit
    );
    let (solution, _) = fitted.solve(&patches, &Progress::hidden());
    assert_eq!(solution.stats.acceleration, "anderson");
    assert!(solution.stats.converged);
    let memory = solution
        .stats
        .memory
        .as_ref()
        .map_or(0, |m| m.estimate_bytes);
    assert!(tight.fits(memory), "{memory} over {}", tight.limit);
}

/// The 4k-triangle subdivided Cornell box and its model under `options` without a memory
/// limit (1 TiB).
fn box_without_limit(options: &SolverOptions) -> (crate::mesh::Patches, Prepared) {
    let patches = build_patches(&generated::subdivided_cornell_box(4_000), None);
    let roomy = crate::memory::Budget {
        limit: 1 << 40,
        base: 0,
    };
    match Prepared::within(&patches, options, false, roomy) {
        Ok(prepared) => (patches, prepared),
        Err(e) => panic!("the box does not fit: {e}"),
    }
}

/// A model refused once built, for what its solve adds beside it (fields' sums, Anderson
/// history), says how much that is per element, and a refinement that counts it
/// ([`LinkBudget::reserve_per_element`]) stops while it refines: b90_office at
/// `--memory-limit 2G` refined and coupled two models in full before refusing them.
#[test]
fn a_model_refused_for_its_solve_reserves_it_in_the_next_refinement() {
    // No pair cache, whose share would shrink to make room.
    let options = SolverOptions {
        direct_light: false,
        pair_cache_mb: 0,
        ..SolverOptions::default()
    };
    let (patches, prepared) = box_without_limit(&options);
    let channels = channels_needed(&patches);
    let estimate = prepared.memory.estimate_bytes;
    let tight = crate::memory::Budget {
        limit: crate::memory::with_slack(estimate),
        base: 0,
    };
    let link_budget = |reserve_per_element| LinkBudget {
        costs: HierarchicalCosts::new(options.bins, channels),
        budget: tight,
        patches: patches.len() as u64,
        reserve_per_element,
    };
    let mut base = BaseTree::new(&patches, &options);
    let refused = match Prepared::build(&patches, &options, false, &link_budget(0), &mut base) {
        Ok(_) => panic!("fitted beside its history at {}", tight.limit),
        Err(over) => over,
    };
    // Its history and sums, per element.
    let n = prepared.element_count() as u64;
    let beside = prepared.history_bytes(channels) + prepared.fields.sweep_bytes(channels);
    let per_element = refused.solve_bytes_per_element;
    assert!(
        per_element >= beside / n && per_element <= 2 * beside / n,
        "{per_element} per element against {} beside",
        beside / n
    );
    // Counted while refining, the same model stops there.
    let reserve = (per_element as f64 * super::prepare::RESERVE_SHARE) as u64;
    match Prepared::build(&patches, &options, false, &link_budget(reserve), &mut base) {
        Ok(_) => panic!("fitted with its reserve"),
        Err(over) => assert_eq!(over.solve_bytes_per_element, 0, "refused once built"),
    }
    // The refinement alone, without it, fits.
    assert!(tight.fits(estimate));
}

/// A model refused once built counts the solved elements it would keep
/// ([`SolverOptions::keep_elements`]) in what its solve adds per element.
#[test]
fn a_refused_model_reserves_the_elements_it_would_keep() {
    let per_element = |keep_elements| {
        let options = SolverOptions {
            direct_light: false,
            pair_cache_mb: 0,
            keep_elements,
            ..SolverOptions::default()
        };
        let (patches, prepared) = box_without_limit(&options);
        // A limit the model fits but not its history: refused once built.
        let tight = crate::memory::Budget {
            limit: crate::memory::with_slack(prepared.memory.estimate_bytes),
            base: 0,
        };
        let link_budget = LinkBudget {
            costs: HierarchicalCosts::new(options.bins, channels_needed(&patches)),
            budget: tight,
            patches: patches.len() as u64,
            reserve_per_element: 0,
        };
        let mut base = BaseTree::new(&patches, &options);
        match Prepared::build(&patches, &options, false, &link_budget, &mut base) {
            Ok(_) => panic!("fitted beside its history at {}", tight.limit),
            Err(over) => over.solve_bytes_per_element,
        }
    };
    let (without, with) = (per_element(false), per_element(true));
    let kept = std::mem::size_of::<crate::solve::solution::ElementRadiance>() as u64;
    assert!(
        with >= without + kept - 1 && with <= without + kept + 1,
        "{with} with the elements kept against {without} + {kept}"
    );
}

/// The pair cache gets only what the model, its fields' per-sweep sums and the Anderson
/// history leave: a model that fits without a cache is not refused for one (b90_office at
/// 2 GB had its cache take the room of the fields' sums, and the model that fitted without the
/// cache was coarsened a step further). The limit here leaves the cache more than the margin
/// the model spares but less than that and the sums together.
#[test]
fn the_pair_cache_leaves_room_for_the_fields_sums() {
    let patches = build_patches(&generated::subdivided_cornell_box(4_000), None);
    let options = |pair_cache_mb| SolverOptions {
        direct_light: false,
        pair_cache_mb,
        ..SolverOptions::default()
    };
    let roomy = crate::memory::Budget {
        limit: 1 << 40,
        base: 0,
    };
    let prepare = |options: &SolverOptions| match Prepared::within(&patches, options, false, roomy)
    {
        Ok(prepared) => prepared,
        Err(e) => panic!("the box does not fit: {e}"),
    };
    let cached = prepare(&options(256));
    let Some(cache_bytes) = cached.pairs.as_ref().map(PairCache::bytes) else {
        panic!("no pair cache in a roomy budget");
    };
    let mut uncached = prepare(&options(0));
    assert!(uncached.pairs.is_none() && uncached.fields.links > 0);
    let channels = channels_needed(&patches);
    let sums = uncached.fields.sweep_bytes(channels);
    assert!(sums > cache_bytes / 2, "sums {sums}, cache {cache_bytes}");
    let needed = uncached.memory.estimate_bytes + uncached.history_bytes(channels);
    let margin = cache_bytes - sums / 2;
    let tight = crate::memory::Budget {
        limit: crate::memory::with_slack(needed + margin),
        base: 0,
    };
    uncached.options.pair_cache_mb = 256;
    let link_budget = LinkBudget {
        costs: HierarchicalCosts::new(uncached.options.bins, channels),
        budget: tight,
        patches: patches.len() as u64,
        reserve_per_element: 0,
    };
    if let Err(over) = uncached.fit_model(&patches, &link_budget) {
        panic!(
            "refused at {} for a limit of {}",
            over.estimate, tight.limit
        );
    }
    let with_history = uncached.memory.estimate_bytes + uncached.history_bytes(channels);
    assert!(
        tight.fits(with_history),
        "{with_history} over {}",
        tight.limit
    );
}

/// After refinements that did not fit, a model is kept only when the solve's state and history
/// fit beside what the process holds then (the allocator keeps memory those refinements
/// freed): not when the limit is what the process already holds, unless the model is the
/// coarsest; always under a roomy limit.
#[test]
fn a_model_is_kept_only_when_its_solve_fits_beside_what_is_held() {
    let Some(held) = crate::memory::current_rss_bytes() else {
        return;
    };
    let patches = build_patches(&generated::cornell_box(), None);
    let options = SolverOptions::default();
    let roomy = crate::memory::Budget {
        limit: 1 << 40,
        base: 0,
    };
    let mut prepared = match Prepared::within(&patches, &options, false, roomy) {
        Ok(prepared) => prepared,
        Err(e) => panic!("the box does not fit: {e}"),
    };
    let channels = channels_needed(&patches);
    assert!(prepared.solve_fits_beside_held(channels));
    prepared.budget = crate::memory::Budget {
        limit: held,
        base: 0,
    };
    assert!(!prepared.solve_fits_beside_held(channels));
    prepared.options = SolverOptions {
        epsilon: budget::MAX_COARSE_EPSILON,
        bins: budget::MIN_COARSE_BINS,
        split_depth: 0,
        ..options
    };
    assert!(prepared.solve_fits_beside_held(channels));
}
