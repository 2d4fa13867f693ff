//! Closed objects with a dark inside are solved facing out (`mesh::closed`): a box standing
//! on the occluder scene's floor, some of its faces given reversed, one-sided or two-sided.

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::generated::{occluder_scene, push_cube};
use antiradiance::scene::Scene;
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::{run, SolverKind, SolverOptions};
use glam::DVec3;

/// The box's faces given reversed (triangle offsets within the box).
const REVERSED: [usize; 4] = [1, 4, 7, 10];

/// The occluder scene with a 0.4 m box on its floor beside the plate (12 triangles facing out,
/// albedo 0.5, the last 12 of the scene); returns the scene and the box's first triangle.
fn scene_with_box() -> (Scene, usize) {
    let mut scene = occluder_scene();
    let first = push_cube(&mut scene, DVec3::new(0.6, 0.0, 0.6), 0.4, 0.5);
    (scene, first)
}

fn solve(scene: &Scene) -> Solution {
    run(
        SolverKind::Hierarchical,
        &build_patches(scene, None),
        &SolverOptions::default(),
        &Progress::hidden(),
    )
    .expect("solves")
}

/// A one-sided box with reversed faces is solved as the box facing out with those faces black
/// (their outside is a back, which absorbs): the same result to rounding, the reversed faces'
/// fronts (inside) dark. And it agrees with the dense oracle solving the box as given.
#[test]
fn a_box_with_reversed_faces_solves_as_the_box_facing_out() {
    let (outward, first) = scene_with_box();
    let mut black = outward.clone();
    let mut reversed = outward.clone();
    for k in REVERSED {
        black.albedo[first + k] = [0.0; 3];
        reversed.triangles[first + k].swap(1, 2);
    }
    let (expected, got) = (solve(&black), solve(&reversed));
    let model = got.stats.model.clone().expect("hierarchical model stats");
    assert_eq!(
        (model.closed_dark_objects, model.turned_outward_patches),
        (1, 4)
    );
    for t in 0..outward.len() {
        let want = if t >= first && REVERSED.contains(&(t - first)) {
            0.0
        } else {
            expected.triangle_radiance[t][0]
        };
        let b = got.triangle_radiance[t][0];
        assert!(
            (b - want).abs() <= 1e-9 * (1.0 + want.abs()),
            "triangle {t}: {b}, expected {want}"
        );
    }
    // The dense oracle on the box as given (reversed faces blocking at their exposed backs).
    let patches = build_patches(&reversed, None);
    let dense = solve_dense(&patches, &SolverOptions::default(), &Progress::hidden()).unwrap();
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..reversed.len() {
        let a = reversed.area(t);
        num += a * (got.triangle_radiance[t][0] - dense.triangle_radiance[t][0]).abs();
        den += a * dense.triangle_radiance[t][0].abs();
    }
    let box_lit: f64 = (first..first + 12)
        .filter(|&t| !REVERSED.contains(&(t - first)))
        .map(|t| got.triangle_radiance[t][0])
        .sum();
    eprintln!(
        "box with reversed faces against the dense oracle: {:.4}",
        num / den
    );
    assert!(box_lit > 0.0, "the box's outward faces are lit");
    assert!(num / den < 0.03, "against the dense oracle {}", num / den);
}

/// A two-sided box with reversed faces is solved one-sided, facing out: each face's outside
/// (the front of the others, the back of the reversed ones) has the one-sided box's radiance,
/// its inside 0, and the rest of the scene the one-sided box's result.
#[test]
fn a_two_sided_box_with_reversed_faces_solves_as_the_box_facing_out() {
    let (outward, first) = scene_with_box();
    let mut two = outward.clone();
    two.two_sided = (0..two.len()).map(|t| t >= first).collect();
    for k in REVERSED {
        two.triangles[first + k].swap(1, 2);
    }
    let (expected, got) = (solve(&outward), solve(&two));
    assert_eq!(got.triangle_radiance_back.len(), two.len());
    for t in 0..two.len() {
        let reversed = t >= first && REVERSED.contains(&(t - first));
        let want = expected.triangle_radiance[t][0];
        let (outside, inside) = if reversed {
            (
                got.triangle_radiance_back[t][0],
                got.triangle_radiance[t][0],
            )
        } else {
            (
                got.triangle_radiance[t][0],
                got.triangle_radiance_back[t][0],
            )
        };
        assert!(
            (outside - want).abs() <= 1e-9 * (1.0 + want.abs()),
            "triangle {t}: outside {outside}, expected {want}"
        );
        assert_eq!(inside, 0.0, "triangle {t}: the inside is dark");
    }
}

/// The box opened (one face removed) is not closed: nothing is turned, and the reversed faces'
/// fronts, which now see the lit floor through the opening, are not forced dark.
#[test]
fn an_open_box_is_solved_as_given() {
    let (mut open, first) = scene_with_box();
    for k in REVERSED {
        open.triangles[first + k].swap(1, 2);
    }
    // Remove the top face (y = 0.4, the box's triangles 6 and 7).
    for _ in 0..2 {
        open.triangles.remove(first + 6);
        open.albedo.remove(first + 6);
        open.emission.remove(first + 6);
        open.material.remove(first + 6);
    }
    let got = solve(&open);
    let model = got.stats.model.clone().expect("hierarchical model stats");
    assert_eq!(
        (model.closed_dark_objects, model.turned_outward_patches),
        (0, 0)
    );
}
