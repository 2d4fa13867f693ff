//! Interactive relighting (`antiradiance::solve::relight`): relit solutions against from-scratch
//! solves, warm starts, analytic lights, per-material emission and bad input. The `relight`
//! command is checked in `tests/relight_cli.rs`.
//!
//! Scenes are small (the Cornell box, a 7-triangle test scene) so the whole file runs in
//! seconds in release.

use std::time::Duration;

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::generated::{self, CORNELL_BOX_PARTS};
use antiradiance::scene::lights::Light;
use antiradiance::scene::{load_obj, Scene, SceneOptions};
use antiradiance::solve::hierarchical::solve_hierarchical;
use antiradiance::solve::relight::{
    animated_light, check_light_changes, light_phase, LightChange, Relighter,
};
use antiradiance::solve::solution::error_against;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::SolverOptions;
use antiradiance::Error;
use glam::DVec3;

mod common;
use common::lamps::lamps_scene;

// ---------------------------------------------------------------------------------------------
// Helpers

/// Index range of a named part of the Cornell box (see `CORNELL_BOX_PARTS`).
fn cornell_part(name: &str) -> std::ops::Range<usize> {
    let mut start = 0;
    for (part, count) in CORNELL_BOX_PARTS {
        if part == name {
            return start..start + count;
        }
        start += count;
    }
    panic!("no part {name}");
}

/// `scene` with its emission replaced.
fn with_emission(scene: &Scene, emission: &[[f64; 3]]) -> Scene {
    let mut s = scene.clone();
    s.emission = emission.to_vec();
    s
}

/// A from-scratch hierarchical solve of `scene` (new patches, tree, links; cold start).
fn from_scratch(scene: &Scene, options: &SolverOptions) -> Solution {
    solve_hierarchical(&build_patches(scene, None), options, &Progress::hidden()).unwrap()
}

fn assert_finite(solution: &Solution) {
    for b in solution
        .triangle_radiance
        .iter()
        .chain(&solution.patch_radiance)
    {
        assert!(b.iter().all(|x| x.is_finite() && *x >= 0.0), "{b:?}");
    }
}

/// Mean of the red channel of the given triangles.
fn mean_red(solution: &Solution, triangles: std::ops::Range<usize>) -> f64 {
    let n = triangles.len() as f64;
    triangles
        .map(|t| solution.triangle_radiance[t][0])
        .sum::<f64>()
        / n
}

// ---------------------------------------------------------------------------------------------
// Relit solutions equal from-scratch solutions

#[test]
fn relit_frames_match_from_scratch_solves_within_one_percent() {
    let scene = generated::cornell_box();
    let options = SolverOptions::default();
    let mut relighter = Relighter::new(&scene, None, &options).unwrap();
    let light = cornell_part("light");
    let ceiling = cornell_part("ceiling");

    // A sequence of frames: the light as built, one half dimmed and tinted, the light off and
    // two ceiling triangles (no emitters at build time) glowing blue, then the light back.
    let mut frames = vec![scene.emission.clone()];
    let mut e = scene.emission.clone();
    e[light.start] = [2.0, 6.0, 1.0];
    frames.push(e);
    let mut e = scene.emission.clone();
    for t in light.clone() {
        e[t] = [0.0; 3];
    }
    e[ceiling.start] = [1.0, 2.0, 30.0];
    e[ceiling.start + 1] = [1.0, 2.0, 30.0];
    frames.push(e);
    frames.push(scene.emission.clone());

    for (f, emission) in frames.iter().enumerate() {
        let relit = relighter.relight(emission).unwrap();
        assert_eq!(relit.warm_started, f > 0, "frame {f}");
        assert_finite(&relit.solution);
        assert_eq!(relit.solution.triangle_radiance.len(), scene.len());
        let truth_scene = with_emission(&scene, emission);
        let truth = from_scratch(&truth_scene, &options);
        let err = error_against(&truth_scene, &relit.solution, &truth);
        assert!(err < 0.01, "frame {f}: {:.3}% from scratch", 100.0 * err);
        // Emitters keep their own radiance on top of what they reflect.
        for (t, (e, b)) in emission
            .iter()
            .zip(&relit.solution.triangle_radiance)
            .enumerate()
        {
            for (e_c, b_c) in e.iter().zip(b) {
                assert!(*b_c >= e_c * (1.0 - 1e-9), "frame {f} triangle {t}");
            }
        }
    }
    // The relighter's patches describe the last frame's emission (for rendering).
    let p = relighter.patches();
    for (patch, &t) in p.parent.iter().enumerate() {
        let e = frames[3][t as usize];
        for (normalized, e_c) in p.emission[patch].iter().zip(e) {
            assert!((normalized * p.emission_scale - e_c).abs() <= 1e-12 * e_c);
        }
    }
}

#[test]
fn mixed_lights_match_from_scratch_solves_within_one_percent() {
    let scene = generated::cornell_box();
    let options = SolverOptions::default();
    let mut relighter = Relighter::new(&scene, None, &options).unwrap();
    let light = cornell_part("light");
    let ceiling = cornell_part("ceiling");
    // Two lights: the first light triangle, and two ceiling triangles (not emitters in the scene).
    let mut first = vec![[0.0; 3]; scene.len()];
    first[light.start] = scene.emission[light.start];
    let mut glow = vec![[0.0; 3]; scene.len()];
    glow[ceiling.start] = [0.5, 1.0, 4.0];
    glow[ceiling.start + 1] = [0.5, 1.0, 4.0];
    assert_eq!(relighter.add_light("first", &first).unwrap(), 0);
    assert_eq!(relighter.add_light("glow", &glow).unwrap(), 1);
    assert_eq!(relighter.light_names(), vec!["first", "glow"]);
    assert!(relighter.add_light("bad", &glow[..3]).is_err());

    for intensities in [
        [[1.0; 3], [0.0; 3]],
        [[0.0; 3], [1.0; 3]],
        [[2.0, 0.5, 1.0], [0.3, 0.3, 3.0]],
        [[0.0; 3], [0.0; 3]],
    ] {
        let mixed = relighter.mix(&intensities).unwrap();
        assert_finite(&mixed.solution);
        // The relighter's emission is the mix's.
        let emission: Vec<[f64; 3]> = (0..scene.len())
            .map(|t| {
                std::array::from_fn(|c| {
                    intensities[0][c] * first[t][c] + intensities[1][c] * glow[t][c]
                })
            })
            .collect();
        assert_eq!(relighter.emission(), &emission[..]);
        let truth_scene = with_emission(&scene, &emission);
        let truth = from_scratch(&truth_scene, &options);
        if emission.iter().all(|e| e == &[0.0; 3]) {
            assert!(mixed
                .solution
                .triangle_radiance
                .iter()
                .all(|b| b == &[0.0; 3]));
            continue;
        }
        let err = error_against(&truth_scene, &mixed.solution, &truth);
        assert!(
            err < 0.01,
            "{intensities:?}: {:.3}% from scratch",
            100.0 * err
        );
    }
    assert!(
        relighter.mix(&[[1.0; 3]]).is_err(),
        "one intensity per light"
    );
    assert!(relighter.mix(&[[1.0; 3], [f64::NAN, 0.0, 0.0]]).is_err());
    // A solve after a mix is a cold solve of the mixed emission.
    let relit = relighter.solve(&Progress::hidden());
    assert!(!relit.warm_started);
}

#[test]
fn scene_without_emitters_at_build_time_relights_in_scene_units() {
    let lit = generated::cornell_box();
    let dark = with_emission(&lit, &vec![[0.0; 3]; lit.len()]);
    let options = SolverOptions::fast();
    let mut relighter = Relighter::new(&dark, None, &options).unwrap();

    // Nothing emits: all zero, no NaN.
    let relit = relighter.solve(&Progress::hidden());
    assert_finite(&relit.solution);
    assert!(relit
        .solution
        .triangle_radiance
        .iter()
        .all(|b| *b == [0.0; 3]));

    // The Cornell light switched on: the same answer, in the same units, as a scene built lit.
    let relit = relighter.relight(&lit.emission).unwrap();
    let truth = from_scratch(&lit, &options);
    let err = error_against(&lit, &relit.solution, &truth);
    assert!(err < 0.01, "{:.3}%", 100.0 * err);
    let floor = cornell_part("floor");
    let (relit_floor, truth_floor) = (
        mean_red(&relit.solution, floor.clone()),
        mean_red(&truth, floor),
    );
    assert!(truth_floor > 0.01, "{truth_floor}");
    assert!((relit_floor - truth_floor).abs() < 0.01 * truth_floor);

    // Brightness far beyond the warm state's scale (x 1e12, then x 1e-12): linear results,
    // nothing overflows in the solver's f32 antiradiance.
    for factor in [1e12, 1e-12] {
        let bright: Vec<[f64; 3]> = lit.emission.iter().map(|e| e.map(|x| x * factor)).collect();
        let relit = relighter.relight(&bright).unwrap();
        assert_finite(&relit.solution);
        let scaled = mean_red(&relit.solution, cornell_part("floor"));
        assert!(
            (scaled / factor - truth_floor).abs() < 0.01 * truth_floor,
            "x{factor}: {scaled}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Warm starts

#[test]
fn warm_start_takes_fewer_iterations_than_cold_for_a_small_change() {
    let scene = generated::cornell_box();
    let options = SolverOptions::default();
    let mut relighter = Relighter::new(&scene, None, &options).unwrap();
    relighter.solve(&Progress::hidden());

    // One light triangle 10% brighter.
    let mut e = scene.emission.clone();
    let t = cornell_part("light").start;
    e[t] = e[t].map(|x| 1.1 * x);
    let warm = relighter.relight(&e).unwrap();
    relighter.forget_warm_start();
    let cold = relighter.relight(&e).unwrap();
    assert!(warm.warm_started && !cold.warm_started);
    assert!(warm.solution.stats.converged && cold.solution.stats.converged);
    let (wi, ci) = (
        warm.solution.stats.iterations,
        cold.solution.stats.iterations,
    );
    assert!(wi < ci, "warm {wi} iterations, cold {ci}");
    let err = error_against(&scene, &warm.solution, &cold.solution);
    assert!(err < 0.01, "{:.3}%", 100.0 * err);
}

#[test]
fn a_source_combining_the_last_ones_starts_from_their_combined_solutions() {
    // Three solves, each with one more wall glowing, then a mix of the last two: by linearity
    // its solution is the same mix of theirs, which the warm start finds from the kept states.
    let scene = generated::cornell_box();
    let options = SolverOptions::default();
    let base = scene.emission.clone();
    let glow = |part: &str, k: f64| {
        let mut e = base.clone();
        for t in cornell_part(part) {
            e[t] = [k; 3];
        }
        e
    };
    let (left, right) = (glow("red wall", 0.3), glow("green wall", 0.3));
    let mix: Vec<[f64; 3]> = (0..base.len())
        .map(|t| std::array::from_fn(|c| 0.4 * left[t][c] + 0.6 * right[t][c]))
        .collect();

    let mut kept = Relighter::new(&scene, None, &options).unwrap();
    kept.solve(&Progress::hidden());
    kept.relight(&left).unwrap();
    kept.relight(&right).unwrap();
    let combined = kept.relight(&mix).unwrap();

    // The same last step from the last state alone (scaled and moved by the change).
    let mut alone = Relighter::new(&scene, None, &options).unwrap();
    alone.relight(&right).unwrap();
    let scaled = alone.relight(&mix).unwrap();

    assert!(combined.warm_started && scaled.warm_started);
    assert!(combined.solution.stats.converged && scaled.solution.stats.converged);
    let (c, s) = (
        combined.solution.stats.iterations,
        scaled.solution.stats.iterations,
    );
    assert!(
        c < s,
        "from the combined states {c} sweeps, from the last alone {s}"
    );
    let cold = from_scratch(&with_emission(&scene, &mix), &options);
    let err = error_against(&scene, &combined.solution, &cold);
    assert!(err < 0.01, "{:.3}%", 100.0 * err);
}

// ---------------------------------------------------------------------------------------------
// Analytic lights

/// `scene` with analytic light 0 replaced.
fn with_light(scene: &Scene, light: Light) -> Scene {
    let mut s = scene.clone();
    s.lights[0] = light;
    s
}

/// The Cornell box lit by its area light and a point light near the ceiling.
fn cornell_with_point() -> (Scene, Light) {
    let mut scene = generated::cornell_box();
    let light = Light::Point {
        position: DVec3::new(278.0, 450.0, 279.0),
        intensity: [4e4, 3.5e4, 3e4],
    };
    scene.lights.push(light);
    (scene, light)
}

/// The Cornell box without its ceiling and area light (open to the sky), lit by `light` alone:
/// the walls, floor and blocks exchange light.
fn open_box_lit_by(light: Light) -> Scene {
    let full = generated::cornell_box();
    let (ceiling, area) = (cornell_part("ceiling"), cornell_part("light"));
    let keep: Vec<usize> = (0..full.len())
        .filter(|t| !ceiling.contains(t) && !area.contains(t))
        .collect();
    let corners: Vec<[DVec3; 3]> = keep.iter().map(|&t| full.corners(t)).collect();
    let albedo: Vec<[f64; 3]> = keep.iter().map(|&t| full.albedo[t]).collect();
    let mut scene = Scene::from_triangles(&corners, &albedo, &vec![[0.0; 3]; keep.len()]);
    scene.lights.push(light);
    scene
}

#[test]
fn moved_analytic_lights_match_cold_solves_at_the_new_place() {
    let options = SolverOptions::default();
    let (cornell, _) = cornell_with_point();
    let spot = Light::Spot {
        position: DVec3::new(278.0, 500.0, 279.0),
        direction: DVec3::new(0.0, -1.0, 0.0),
        intensity: [6e4; 3],
        inner: 20f64.to_radians(),
        outer: 35f64.to_radians(),
    };
    let sun = Light::Sun {
        direction: DVec3::new(0.3, -1.0, 0.2),
        irradiance: [2.0, 1.8, 1.5],
    };
    let cases = [
        (
            "point moved",
            cornell.clone(),
            Light::Point {
                position: DVec3::new(120.0, 300.0, 420.0),
                intensity: [4e4, 3.5e4, 3e4],
            },
        ),
        (
            "spot turned towards the red wall",
            with_light(&cornell, spot),
            Light::Spot {
                position: DVec3::new(278.0, 500.0, 279.0),
                direction: DVec3::new(-1.0, -0.6, 0.1),
                intensity: [6e4; 3],
                inner: 20f64.to_radians(),
                outer: 35f64.to_radians(),
            },
        ),
        (
            "sun lowered",
            open_box_lit_by(sun),
            Light::Sun {
                direction: DVec3::new(-1.0, -0.4, 0.3),
                irradiance: [2.0, 1.8, 1.5],
            },
        ),
    ];
    for (name, scene, moved) in cases {
        let mut relighter = Relighter::new(&scene, None, &options).unwrap();
        let before = relighter.solve(&Progress::hidden());
        assert!(before.solution.stats.converged, "{name}");
        assert!(before.direct_seconds > 0.0, "{name}: shadow rays traced");
        relighter.set_analytic_light(0, moved).unwrap();
        assert_eq!(relighter.analytic_lights()[0], moved, "{name}");
        let relit = relighter.solve(&Progress::hidden());
        assert!(
            relit.warm_started && relit.solution.stats.converged,
            "{name}"
        );
        assert!(
            relit.direct_seconds > 0.0,
            "{name}: shadow rays traced again"
        );
        assert_finite(&relit.solution);
        let truth_scene = with_light(&scene, moved);
        // The relighter keeps its elements (split towards the lights where they were when it
        // was built): the same model solved cold gives its answer.
        let cold = relighter.converged(&Progress::hidden()).solution;
        let err = error_against(&truth_scene, &relit.solution, &cold);
        assert!(err < 0.005, "{name}: {:.3}% from a cold solve", 100.0 * err);
        // A new solve at the new place (its elements split towards the light there) differs
        // by the resolution only.
        let truth = from_scratch(&truth_scene, &options);
        let moved_err = error_against(&truth_scene, &relit.solution, &truth);
        eprintln!(
            "{name}: {:.3}% from its own cold solve, {:.3}% from a new solve",
            100.0 * err,
            100.0 * moved_err
        );
        assert!(
            moved_err < 0.02,
            "{name}: {:.3}% from a new solve",
            100.0 * moved_err
        );
        // The move matters: the light as it was is far from the new answer.
        let stale = error_against(&truth_scene, &before.solution, &truth);
        assert!(
            stale > 0.05,
            "{name}: the move changed only {:.2}%",
            100.0 * stale
        );
    }
}

#[test]
fn dimming_a_light_by_k_scales_the_result_by_k_without_new_shadow_rays() {
    let options = SolverOptions::default();
    let point = Light::Point {
        position: DVec3::new(200.0, 400.0, 300.0),
        intensity: [4e4, 3e4, 2e4],
    };
    let sky = Light::Sky {
        radiance: [0.3, 0.4, 0.5],
    };
    for light in [point, sky] {
        let scene = open_box_lit_by(light);
        let mut relighter = Relighter::new(&scene, None, &options).unwrap();
        let full = relighter.solve(&Progress::hidden());
        // Each channel by its own factor (the red one by 0.3).
        let k = [0.3, 0.5, 1.0];
        let c = light.colour();
        relighter
            .set_analytic_light(0, light.with_colour([0, 1, 2].map(|i| k[i] * c[i])))
            .unwrap();
        let dimmed = relighter.solve(&Progress::hidden());
        assert_eq!(
            dimmed.direct_seconds, 0.0,
            "{light:?}: no shadow ray traced again"
        );
        assert!(dimmed.warm_started && dimmed.solution.stats.converged);
        let (mut num, mut den) = ([0.0f64; 3], [0.0f64; 3]);
        for t in 0..scene.len() {
            let a = scene.area(t);
            for i in 0..3 {
                let want = k[i] * full.solution.triangle_radiance[t][i];
                num[i] += a * (dimmed.solution.triangle_radiance[t][i] - want).abs();
                den[i] += a * want;
            }
        }
        for i in 0..3 {
            assert!(den[i] > 0.0, "{light:?}: channel {i} lit");
            assert!(
                num[i] / den[i] < 0.002,
                "{light:?} channel {i}: {:.3}% from {} times the full light",
                100.0 * num[i] / den[i],
                k[i]
            );
        }
        // Off is black.
        relighter
            .set_analytic_light(0, light.with_colour([0.0; 3]))
            .unwrap();
        let off = relighter.solve(&Progress::hidden());
        assert!(off
            .solution
            .triangle_radiance
            .iter()
            .all(|b| b.iter().all(|&x| x.abs() < 1e-12)));
    }
}

#[test]
fn progressive_relighting_converges_over_frames_to_the_converged_answer() {
    let scene = generated::cornell_box();
    let options = SolverOptions::default();
    let mut relighter = Relighter::new(&scene, None, &options).unwrap();
    relighter.solve(&Progress::hidden());
    // One sweep per frame: a zero budget still sweeps once.
    relighter.frame_budget = Some(Duration::ZERO);
    let mut e = scene.emission.clone();
    let light = cornell_part("light");
    e[light.start] = [2.0, 6.0, 1.0];
    let ceiling = cornell_part("ceiling");
    e[ceiling.start] = [1.0, 2.0, 30.0];
    relighter.set_emission(&e).unwrap();
    let truth = relighter.converged(&Progress::hidden()).solution;
    let reference = from_scratch(&with_emission(&scene, &e), &options);
    assert!(error_against(&scene, &truth, &reference) < 0.005);
    let mut errors = Vec::new();
    loop {
        let relit = relighter.solve(&Progress::hidden());
        assert!(relit.warm_started);
        assert_eq!(relit.solution.stats.iterations, 1, "frame {}", errors.len());
        errors.push(error_against(&scene, &relit.solution, &truth));
        if relit.solution.stats.converged {
            break;
        }
        assert!(
            errors.len() < 60,
            "not converged after 60 frames: {errors:?}"
        );
    }
    assert!(errors.len() >= 3, "converged in {} frames", errors.len());
    let (first, last) = (errors[0], *errors.last().unwrap());
    assert!(last < 0.005, "{:.3}% at convergence", 100.0 * last);
    assert!(first > 2.0 * last, "frames: {errors:?}");
    // Nothing changed since the converged frame: no sweep, the same answer.
    let again = relighter.solve(&Progress::hidden());
    assert_eq!(again.solution.stats.iterations, 0);
    assert!(again.solution.stats.converged);
    assert!(error_against(&scene, &again.solution, &truth) <= last + 1e-12);
    // A generous budget converges within the frame.
    relighter.frame_budget = Some(Duration::from_secs(60));
    relighter.relight(&scene.emission).unwrap();
    let within = relighter.solve(&Progress::hidden());
    assert!(within.solution.stats.converged);
}

#[test]
fn bad_analytic_light_changes_are_rejected_and_change_nothing() {
    let (scene, point) = cornell_with_point();
    let mut relighter = Relighter::new(&scene, None, &SolverOptions::fast()).unwrap();
    assert_parameter_error(
        relighter.set_analytic_light(1, point),
        "no analytic light 1: the scene has 1 (numbered from 0: 0 point)",
    );
    let bad = Light::Point {
        position: DVec3::new(f64::NAN, 0.0, 0.0),
        intensity: [1.0; 3],
    };
    assert_parameter_error(relighter.set_analytic_light(0, bad), "analytic light 0");
    let negative = point.with_colour([1.0, -1.0, 0.0]);
    assert_parameter_error(
        relighter.set_analytic_light(0, negative),
        "analytic light 0",
    );
    assert_eq!(relighter.analytic_lights(), vec![point]);
    // A lit analytic light is not a precomputed emission light: mix refuses it.
    relighter.add_light("area", &scene.emission).unwrap();
    assert_parameter_error(relighter.mix(&[[1.0; 3]]), "analytic");
    relighter
        .set_analytic_light(0, point.with_colour([0.0; 3]))
        .unwrap();
    assert!(relighter.mix(&[[1.0; 3]]).is_ok());
    // A scene without analytic lights says so.
    let mut plain =
        Relighter::new(&generated::cornell_box(), None, &SolverOptions::fast()).unwrap();
    assert_parameter_error(
        plain.set_analytic_light(0, point),
        "the scene has no analytic lights",
    );
    // Animation changes: an index that names no light, a moving sky, a sun turned to its
    // opposite, a negative factor.
    let sky = Light::Sky { radiance: [1.0; 3] };
    let sun = Light::Sun {
        direction: DVec3::new(0.0, -1.0, 0.0),
        irradiance: [1.0; 3],
    };
    let lights = [point, sky, sun];
    let to = DVec3::new(1.0, 2.0, 3.0);
    for (change, needle) in [
        (LightChange::MoveTo { light: 3, to }, "no analytic light 3"),
        (LightChange::MoveTo { light: 1, to }, "sky"),
        (
            LightChange::MoveTo {
                light: 2,
                to: DVec3::new(0.0, 1.0, 0.0),
            },
            "opposite",
        ),
        (
            LightChange::Scale {
                light: 0,
                factor: -0.5,
            },
            ">= 0",
        ),
    ] {
        assert_parameter_error(check_light_changes(&lights, &[change]), needle);
    }
    assert!(check_light_changes(&lights, &[LightChange::MoveTo { light: 0, to }]).is_ok());
}

#[test]
fn animated_lights_move_in_straight_lines_and_scale_linearly() {
    let point = Light::Point {
        position: DVec3::new(0.0, 1.0, 0.0),
        intensity: [2.0, 4.0, 6.0],
    };
    let changes = [
        LightChange::MoveTo {
            light: 0,
            to: DVec3::new(2.0, 1.0, -4.0),
        },
        LightChange::Scale {
            light: 0,
            factor: 0.5,
        },
    ];
    assert_eq!(light_phase(0, 5), 0.0);
    assert_eq!(light_phase(4, 5), 1.0);
    assert_eq!(light_phase(0, 1), 1.0);
    assert_eq!(animated_light(&point, 0, &changes, 0.0), point);
    assert_eq!(
        animated_light(&point, 0, &changes, 0.5),
        Light::Point {
            position: DVec3::new(1.0, 1.0, -2.0),
            intensity: [1.5, 3.0, 4.5],
        }
    );
    // Changes of another light leave it as it is.
    assert_eq!(animated_light(&point, 1, &changes, 1.0), point);
    // A sun turns between unit directions.
    let sun = Light::Sun {
        direction: DVec3::new(0.0, -2.0, 0.0),
        irradiance: [1.0; 3],
    };
    let turn = [LightChange::MoveTo {
        light: 0,
        to: DVec3::new(1.0, 0.0, 0.0),
    }];
    let Light::Sun { direction, .. } = animated_light(&sun, 0, &turn, 0.5) else {
        panic!("a sun stays a sun");
    };
    let want = DVec3::new(1.0, -1.0, 0.0).normalize();
    assert!((direction - want).length() < 1e-12, "{direction}");
}

// ---------------------------------------------------------------------------------------------
// Per-material emission

#[test]
fn scene_keeps_material_identity_per_triangle() {
    let dir = tempfile::tempdir().unwrap();
    let scene = load_obj(&lamps_scene(dir.path()), &SceneOptions::default()).unwrap();
    assert_eq!(scene.len(), 10);
    assert_eq!(scene.material.len(), scene.len());
    let names: Vec<Option<&str>> = (0..scene.len()).map(|t| scene.material_name(t)).collect();
    assert_eq!(
        names,
        [
            None, // before any usemtl
            Some("white"),
            Some("white"),
            Some("lampA"),
            Some("lampA"),
            Some("lampB"),
            Some("lampB"),
            Some("white"),
            Some("white"),
            None, // ghost is not defined
        ]
    );
    for name in ["white", "lampA", "lampB", "unused"] {
        assert!(scene.material_names.iter().any(|n| n == name), "{name}");
    }
    // Materials still give albedo and emission as before.
    assert_eq!(scene.emission[3], [5.0; 3]);
    assert_eq!(scene.emission[5], [1.0; 3]);
    // Scenes built in code have no materials.
    let cornell = generated::cornell_box();
    assert_eq!(cornell.material, vec![None; cornell.len()]);
    assert_eq!(cornell.material_name(0), None);
}

#[test]
fn per_material_emission_matches_a_scene_with_that_emission() {
    let dir = tempfile::tempdir().unwrap();
    let scene = load_obj(&lamps_scene(dir.path()), &SceneOptions::default()).unwrap();
    let options = SolverOptions::default();
    let mut relighter = Relighter::new(&scene, None, &options).unwrap();
    let before = relighter.solve(&Progress::hidden());

    // Swap the lamps: A off, B bright and red.
    assert_eq!(
        relighter.set_material_emission("lampA", [0.0; 3]).unwrap(),
        2
    );
    assert_eq!(
        relighter
            .set_material_emission("lampB", [8.0, 1.0, 1.0])
            .unwrap(),
        2
    );
    assert_eq!(
        relighter.set_material_emission("unused", [3.0; 3]).unwrap(),
        0
    );
    let mut expected = scene.emission.clone();
    expected[3] = [0.0; 3];
    expected[4] = [0.0; 3];
    expected[5] = [8.0, 1.0, 1.0];
    expected[6] = [8.0, 1.0, 1.0];
    assert_eq!(relighter.emission(), &expected[..]);
    let after = relighter.solve(&Progress::hidden());
    assert!(after.warm_started);
    let truth_scene = with_emission(&scene, &expected);
    let truth = from_scratch(&truth_scene, &options);
    let err = error_against(&truth_scene, &after.solution, &truth);
    assert!(err < 0.01, "{:.3}%", 100.0 * err);

    // The floor (triangles 1-2) turned red.
    let floor = |s: &Solution| {
        let b = s.triangle_radiance[1];
        let c = s.triangle_radiance[2];
        [b[0] + c[0], b[1] + c[1]]
    };
    let (old, new) = (floor(&before.solution), floor(&after.solution));
    assert!(old[0] > 0.0 && (old[0] - old[1]).abs() < 1e-9 * old[0]);
    assert!(new[0] > 3.0 * new[1], "{new:?}");

    // Per triangle works as well: the undefined-material triangle can still be lit by index.
    relighter.set_triangle_emission(9, [0.5; 3]).unwrap();
    let relit = relighter.solve(&Progress::hidden());
    assert!(relit.solution.triangle_radiance[9]
        .iter()
        .all(|&b| b >= 0.5));
}

// ---------------------------------------------------------------------------------------------
// Bad input

fn assert_parameter_error<T: std::fmt::Debug>(result: antiradiance::Result<T>, needle: &str) {
    match result {
        Err(Error::Parameter(message)) => {
            assert!(message.contains(needle), "{needle}: {message}");
            assert!(!message.contains('\n'), "{message}");
        }
        other => panic!("{needle}: expected a parameter error, got {other:?}"),
    }
}

#[test]
fn bad_emission_is_rejected_and_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = load_obj(&lamps_scene(dir.path()), &SceneOptions::default()).unwrap();
    let mut relighter = Relighter::new(&scene, None, &SolverOptions::fast()).unwrap();
    let original = relighter.emission().to_vec();

    assert_parameter_error(relighter.set_emission(&original[1..]), "9 values");
    let mut longer = original.clone();
    longer.push([1.0; 3]);
    assert_parameter_error(relighter.relight(&longer), "11 values");
    for bad in [-1.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut e = original.clone();
        e[7] = [1.0, bad, 1.0];
        assert_parameter_error(relighter.set_emission(&e), "triangle 7");
        assert_parameter_error(relighter.relight(&e), "triangle 7");
        assert_parameter_error(
            relighter.set_triangle_emission(2, [bad, 0.0, 0.0]),
            "triangle 2",
        );
        assert_parameter_error(relighter.set_material_emission("lampA", [bad; 3]), "lampA");
    }
    assert_parameter_error(
        relighter.set_triangle_emission(10, [1.0; 3]),
        "out of range",
    );
    assert_parameter_error(
        relighter.set_material_emission("lampC", [1.0; 3]),
        "lampA, lampB",
    );
    assert_eq!(relighter.emission(), &original[..]);
    // No solve happened through a failed call: the first solve is still cold.
    assert!(!relighter.solve(&Progress::hidden()).warm_started);

    // Bad construction.
    let bad_options = SolverOptions {
        bins: 0,
        ..SolverOptions::default()
    };
    // Library errors name the API value, not the command line's flag.
    assert_parameter_error(
        Relighter::new(&scene, None, &bad_options).map(|_| ()),
        "SolverOptions::bins",
    );
    assert_parameter_error(
        Relighter::new(&scene, Some(0.0), &SolverOptions::fast()).map(|_| ()),
        "max edge",
    );
    let mut nan_scene = scene.clone();
    nan_scene.emission[4] = [f64::NAN; 3];
    assert_parameter_error(
        Relighter::new(&nan_scene, None, &SolverOptions::fast()).map(|_| ()),
        "triangle 4",
    );
    assert!(matches!(
        Relighter::new(&Scene::default(), None, &SolverOptions::fast()),
        Err(Error::Scene { .. })
    ));
    let other = build_patches(&generated::cornell_box(), None);
    assert_parameter_error(
        Relighter::from_patches(&scene, other, &SolverOptions::fast()).map(|_| ()),
        "46 triangles",
    );
}
