//! Oracle tests: the hierarchical solver against the dense one, and the link structure's coverage.

use antiradiance::hierarchy::links;
use antiradiance::mesh::{build_patches, Patches};
use antiradiance::progress::Progress;
use antiradiance::scene::generated;
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::hierarchical::{solve_hierarchical, Prepared};
use antiradiance::solve::solution::{relative_error, Solution};
use antiradiance::solve::SolverOptions;

fn error(patches: &Patches, estimate: &Solution, truth: &Solution) -> f64 {
    error_of(patches, &estimate.patch_radiance, &truth.patch_radiance)
}

/// The design note's error of per-patch radiances `estimate` against `truth`, over the
/// non-emissive patches of `patches`.
fn error_of(patches: &Patches, estimate: &[[f64; 3]], truth: &[[f64; 3]]) -> f64 {
    let emissive: Vec<bool> = (0..patches.len()).map(|p| patches.is_emitter(p)).collect();
    relative_error(&patches.area, &emissive, estimate, truth)
}

#[test]
fn every_element_pair_is_covered_exactly_once() {
    for (name, scene, max_edge) in [
        ("occluder", generated::occluder_scene(), None),
        ("cornell", generated::cornell_box(), Some(150.0)),
    ] {
        let patches = build_patches(&scene, max_edge);
        for epsilon in [0.25, 1.0, 4.0] {
            for two_sided in [false, true] {
                let options = SolverOptions {
                    epsilon,
                    two_sided,
                    ..SolverOptions::default()
                };
                let prepared = Prepared::new(&patches, &options, true).unwrap();
                prepared.tree.validate().unwrap();
                assert!(
                    prepared.element_count() <= 3000,
                    "{name}: keep this test small"
                );
                links::validate(&prepared.tree, &prepared.links).unwrap_or_else(|e| {
                    panic!("{name} epsilon {epsilon} two_sided {two_sided}: {e}")
                });
            }
        }
    }
}

/// The link traversal runs in parallel: its links must not depend on how many threads walk it
/// or how the work is stolen (one thread against three, on a scene whose coarse walls are split
/// on demand, so the rounds of leaf splits are exercised too).
#[test]
fn refinement_does_not_depend_on_the_thread_count() {
    let patches = build_patches(&generated::cornell_box(), None);
    let options = SolverOptions::default();
    let refine_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| Prepared::new(&patches, &options, false).unwrap())
    };
    let (one, three) = (refine_with(1), refine_with(3));
    assert!(
        one.links.stats.leaf_splits > 0,
        "the scene should split leaves"
    );
    assert_eq!(one.tree.nodes.len(), three.tree.nodes.len());
    assert_eq!(one.links.cluster.len(), three.links.cluster.len());
    for (a, b) in one.links.cluster.iter().zip(&three.links.cluster) {
        assert_eq!((a.sender, a.receiver, a.bin), (b.sender, b.receiver, b.bin));
    }
    assert_eq!(one.links.exact_start, three.links.exact_start);
    assert_eq!(one.links.exact_sender, three.links.exact_sender);
}

#[test]
fn refined_to_element_pairs_equals_dense() {
    for (name, scene, max_edge) in [
        ("occluder", generated::occluder_scene(), None),
        ("cornell", generated::cornell_box(), Some(200.0)),
    ] {
        let patches = build_patches(&scene, max_edge);
        for two_sided in [false, true] {
            // Both solved to far below the comparison's tolerance: the same couplings have the
            // same fixed point, whatever the iteration (the dense solver sweeps plainly, the
            // hierarchical one accelerates).
            let options = SolverOptions {
                epsilon: 0.0,
                two_sided,
                max_iterations: 500,
                tol: 1e-8,
                clamp_negative: false,
                ..SolverOptions::default()
            };
            let dense = solve_dense(&patches, &options, &Progress::hidden()).unwrap();
            let hier = solve_hierarchical(&patches, &options, &Progress::hidden()).unwrap();
            assert!(
                dense.stats.converged && hier.stats.converged,
                "{name}: dense converged {} after {}, hierarchical {} after {}",
                dense.stats.converged,
                dense.stats.iterations,
                hier.stats.converged,
                hier.stats.iterations
            );
            // Relative to each value, or to 1e-4 of the scene's largest where antiradiance
            // cancels nearly all of a patch's light: the hierarchical solver stores antiradiance
            // in f32, so such a remainder carries the rounding of what it cancelled.
            let largest = dense
                .patch_radiance
                .iter()
                .flatten()
                .fold(0.0f64, |m, x| m.max(x.abs()));
            for (p, (a, b)) in dense
                .patch_radiance
                .iter()
                .zip(&hier.patch_radiance)
                .enumerate()
            {
                for c in 0..3 {
                    let scale = a[c].abs().max(1e-4 * largest).max(1e-6);
                    assert!(
                        (a[c] - b[c]).abs() <= 1e-5 * scale,
                        "{name} patch {p} channel {c}: dense {} hierarchical {}",
                        a[c],
                        b[c]
                    );
                }
            }
        }
    }
}

#[test]
fn default_settings_agree_with_dense() {
    for (name, scene, max_edge) in [
        ("occluder", generated::occluder_scene(), None),
        ("cornell", generated::cornell_box(), Some(60.0)),
    ] {
        let patches = build_patches(&scene, max_edge);
        let options = SolverOptions::default();
        let dense = solve_dense(&patches, &options, &Progress::hidden()).unwrap();
        let mut errors = Vec::new();
        for (split_depth, epsilon) in [(0, 0.25), (0, 0.5), (4, 0.25)] {
            let options = SolverOptions {
                split_depth,
                epsilon,
                ..options.clone()
            };
            let hier = solve_hierarchical(&patches, &options, &Progress::hidden()).unwrap();
            let err = error(&patches, &hier, &dense);
            eprintln!(
                "{name}: hierarchical (split depth {split_depth}, epsilon {epsilon}) vs dense {err:.4} (patches {})",
                patches.len()
            );
            errors.push((split_depth, epsilon, err));
        }
        // On the same elements (no splitting), cluster links may only cost the approximation of
        // one exchange per link; with on-demand splitting the hierarchical solver resolves more
        // than the dense one and may legitimately differ (checked against the path tracer
        // elsewhere).
        for (split_depth, epsilon, err) in errors {
            if split_depth == 0 && epsilon <= 0.25 {
                assert!(
                    err < 0.02,
                    "{name} epsilon {epsilon}: hierarchical vs dense error {err}"
                );
            }
        }
    }
}

/// The report's per-sweep work counts what a sweep evaluates: without receiver fields, every
/// cluster link into an element or an ancestor, once per element below its receiver, so at
/// least one pair per cluster link; and as many pull terms as cluster links at least (a sender
/// has one element or normal group or more). With fields (the default), fewer pairs, and the
/// links and evaluations of the fields.
#[test]
fn sweep_work_counts_every_element_below_each_receiver() {
    let patches = build_patches(&generated::cornell_box(), Some(150.0));
    let options = SolverOptions {
        field_ratio: 0.0,
        ..SolverOptions::default()
    };
    let prepared = Prepared::new(&patches, &options, false).unwrap();
    let (tree, links) = (&prepared.tree, &prepared.links);
    let below: u64 = links
        .cluster
        .iter()
        .map(|l| {
            let (e0, e1) = tree.nodes[l.receiver as usize].elements;
            (e1 - e0) as u64
        })
        .sum();
    let (pairs, pull) = prepared.sweep_work();
    assert_eq!(pairs, below);
    assert!(pairs > links.cluster.len() as u64, "{pairs} pairs");
    assert!(pull >= links.cluster.len() as u64, "{pull} pull terms");
    let solution = solve_hierarchical(&patches, &options, &Progress::hidden()).unwrap();
    assert_eq!(solution.stats.element_link_pairs, pairs);
    assert_eq!(solution.stats.pull_terms, pull);
    assert_eq!(solution.stats.field_links, 0);
    let fielded =
        solve_hierarchical(&patches, &SolverOptions::default(), &Progress::hidden()).unwrap();
    assert!(fielded.stats.field_links > 0);
    assert!(fielded.stats.field_evaluations > 0);
    assert!(
        fielded.stats.element_link_pairs < pairs,
        "{} of {pairs}",
        fielded.stats.element_link_pairs
    );
}

/// The report says how the sweeps were accelerated, and why Anderson mixing was off when it
/// was: on by default on a small scene, off (tail extrapolation) at depth 0.
#[test]
fn report_names_the_acceleration_used() {
    let patches = build_patches(&generated::cornell_box(), None);
    let on = solve_hierarchical(&patches, &SolverOptions::default(), &Progress::hidden()).unwrap();
    assert_eq!(on.stats.acceleration, "anderson");
    let options = SolverOptions {
        acceleration_depth: 0,
        ..SolverOptions::default()
    };
    let off = solve_hierarchical(&patches, &options, &Progress::hidden()).unwrap();
    assert_eq!(
        off.stats.acceleration,
        "extrapolation (acceleration_depth 0)"
    );
    // Both reach the same fixed point.
    assert!(error(&patches, &off, &on) < 0.01);
}

/// Receiver fields (links gathered once at their receiver node, to first order over it) give
/// the per-element gather's answer: on the subdivided Cornell box and on the occluder scene,
/// one-sided and two-sided, the default `field_ratio` against 0 (every link per element), per
/// patch within 0.3% (measured: 0.10% and 0.19%; a first-order expansion gave 0.52% and
/// 0.79% at a smaller ratio), while gathering links through fields.
#[test]
fn receiver_fields_agree_with_the_per_element_gather() {
    for (name, scene, max_edge) in [
        ("cornell", generated::subdivided_cornell_box(4_000), None),
        ("occluder", generated::occluder_scene(), Some(0.05)),
    ] {
        let patches = build_patches(&scene, max_edge);
        for two_sided in [false, true] {
            let fielded = SolverOptions {
                two_sided,
                ..SolverOptions::default()
            };
            let per_element = SolverOptions {
                field_ratio: 0.0,
                ..fielded.clone()
            };
            let a = solve_hierarchical(&patches, &fielded, &Progress::hidden()).unwrap();
            let b = solve_hierarchical(&patches, &per_element, &Progress::hidden()).unwrap();
            assert!(a.stats.field_links > 0, "{name}: no field links");
            let e = error(&patches, &a, &b);
            assert!(e < 0.003, "{name} two-sided {two_sided}: {:.3}%", 100.0 * e);
        }
    }
}

/// Regression (bear in a room): a curved receiver's slabs are cells of normals whose side
/// margin is wide; a sender within that margin of a cell's range was once taken as lying in
/// its plane and gave the cell nothing, 0.68% darker than the per-element gather. Within 0.3%
/// now (measured 0.006%). Reads `../shared/meshes/bear.obj`; skipped when it is absent.
#[test]
fn curved_receiver_fields_bear_in_a_room() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes/bear.obj");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let bear = antiradiance::scene::load_obj(&path, &Default::default()).unwrap();
    let scene = generated::in_room(&bear, 10.0).unwrap();
    let patches = build_patches(&scene, None);
    let per_element = SolverOptions {
        field_ratio: 0.0,
        ..SolverOptions::default()
    };
    let a = solve_hierarchical(&patches, &SolverOptions::default(), &Progress::hidden()).unwrap();
    let b = solve_hierarchical(&patches, &per_element, &Progress::hidden()).unwrap();
    assert!(a.stats.field_links > 0);
    let e = error(&patches, &a, &b);
    assert!(e < 0.003, "{:.3}%", 100.0 * e);
}

/// A tiny object beside big surfaces (a 1 mm cube on the Cornell box's floor): every pair with
/// the cube or one of its triangles carries less than the flux rule's share whatever its
/// geometry, so the cube splits no leaf (its pairs are coupled exactly as they are); the box's
/// triangles stay within 0.5% of the box without it. The same cube as an emitter is never faint (near a light, a receiver's
/// resolution carries the light's gradient) and splits the floor around it.
#[test]
fn a_tiny_cube_on_a_floor_splits_nothing() {
    use antiradiance::scene::generated::push_cube;
    let with_cubes = |emission: f64| {
        let mut scene = generated::cornell_box();
        let first = push_cube(&mut scene, glam::DVec3::new(200.0, 0.0, 150.0), 1.0, 0.5);
        for t in first..scene.len() {
            scene.emission[t] = [emission; 3];
        }
        build_patches(&scene, None)
    };
    let options = SolverOptions::default();
    let stats = |patches: &Patches| {
        let prepared = Prepared::new(patches, &options, true).unwrap();
        links::validate(&prepared.tree, &prepared.links).unwrap();
        prepared.links.stats
    };
    let box_alone = stats(&build_patches(&generated::cornell_box(), None));
    let grit = with_cubes(0.0);
    let faint = stats(&grit);
    let lit = stats(&with_cubes(5.0));
    eprintln!(
        "leaf splits: box {}, with the cube {} ({} faint pairs), emitting cube {}",
        box_alone.leaf_splits, faint.leaf_splits, faint.faint_exact, lit.leaf_splits
    );
    assert!(faint.faint_exact > 0, "no faint pair");
    assert_eq!(
        faint.leaf_splits, box_alone.leaf_splits,
        "the cube split leaves"
    );
    assert!(
        lit.leaf_splits > box_alone.leaf_splits,
        "the emitting cube split nothing"
    );
    // The box's own triangles, with and without the cube.
    let boxed = build_patches(&generated::cornell_box(), None);
    let alone = solve_hierarchical(&boxed, &options, &Progress::hidden()).unwrap();
    let with = solve_hierarchical(&grit, &options, &Progress::hidden()).unwrap();
    let err = error_of(
        &boxed,
        &with.patch_radiance[..boxed.len()],
        &alone.patch_radiance,
    );
    eprintln!("the box's triangles with the cube against without: {err:.5}");
    assert!(err < 0.005, "the cube moved the box's result by {err}");
}

/// The same 1 mm cube on the Cornell box's floor: its pairs are faint, so they are integrated
/// over at most 2 x 2 receiver points, and they do not raise the quadrature of the floor
/// triangles they touch (whose other senders keep the points their own nearest needs). The
/// cube adds at most 4 points per exact pair it adds (with the rule of the nearest pair, a
/// floor triangle under the cube took 6 x 6 points for every one of its senders).
#[test]
fn faint_pairs_take_at_most_two_by_two_points() {
    use antiradiance::scene::generated::push_cube;
    let mut scene = generated::cornell_box();
    push_cube(&mut scene, glam::DVec3::new(200.0, 0.0, 150.0), 1.0, 0.5);
    let options = SolverOptions::default();
    let stats = |patches: &Patches| {
        let prepared = Prepared::new(patches, &options, false).unwrap();
        prepared.links.stats
    };
    let alone = stats(&build_patches(&generated::cornell_box(), None));
    let with = stats(&build_patches(&scene, None));
    let added_pairs = with.exact_element_pairs - alone.exact_element_pairs;
    let added_points = with.quadrature_points as i64 - alone.quadrature_points as i64;
    eprintln!(
        "exact pairs +{added_pairs} ({} faint), quadrature points {added_points:+}",
        with.faint_exact
    );
    assert!(with.faint_exact > 0 && added_pairs > 0);
    assert!(
        added_points <= 4 * added_pairs as i64,
        "the cube added {added_points} points for {added_pairs} exact pairs"
    );
}

/// A field of grit on the Cornell box's floor: 10 x 10 cubes of 4 mm, 5 mm apart. Their pairs
/// with one another are faint and their bounding spheres overlap, so by default they are
/// refined down to exact couplings between their faces; with `faint_links` each such pair is
/// one cluster link where it is first found faint. Every element pair is still covered exactly
/// once, the exact pairs fall by a quarter or more, and the box's own triangles move by under 1%.
#[test]
fn faint_links_couple_grit_as_clusters() {
    use antiradiance::scene::generated::push_cube;
    let mut scene = generated::cornell_box();
    for i in 0..10 {
        for k in 0..10 {
            let at = glam::DVec3::new(150.0 + 5.0 * i as f64, 0.0, 120.0 + 5.0 * k as f64);
            push_cube(&mut scene, at, 4.0, 0.5);
        }
    }
    let patches = build_patches(&scene, None);
    let solve = |faint_links: bool| {
        let options = SolverOptions {
            faint_links,
            ..SolverOptions::default()
        };
        let prepared = Prepared::new(&patches, &options, true).unwrap();
        links::validate(&prepared.tree, &prepared.links).unwrap();
        let stats = (prepared.links.stats.clone(), prepared.links.len());
        let solution = solve_hierarchical(&patches, &options, &Progress::hidden()).unwrap();
        (stats, solution)
    };
    let ((exact, exact_links), exact_solution) = solve(false);
    let ((linked, linked_links), linked_solution) = solve(true);
    eprintln!(
        "exact pairs {} -> {}, links {} -> {}",
        exact.exact_pairs, linked.exact_pairs, exact_links, linked_links
    );
    assert!(
        4 * linked.exact_pairs < 3 * exact.exact_pairs,
        "faint links left {} of {} exact pairs",
        linked.exact_pairs,
        exact.exact_pairs
    );
    let boxed = build_patches(&generated::cornell_box(), None);
    let err = error_of(
        &boxed,
        &linked_solution.patch_radiance[..boxed.len()],
        &exact_solution.patch_radiance[..boxed.len()],
    );
    eprintln!("the box's triangles, faint links against exact: {err:.5}");
    // Measured 0.63%: the floor under the grit 1.3% and 1.9% brighter (its two triangles),
    // the grit's blocking taken from its clusters' centroids.
    assert!(err < 0.01, "faint links moved the box by {err}");
}
