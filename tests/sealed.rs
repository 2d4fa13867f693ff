//! Sealed fronts are solved black (`solve::sealed`): a slab whose faces all face in, standing
//! lit above the occluder scene's floor, its surface not closed by shared vertices (a T-junction),
//! so that it is not turned outward as a closed object.

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::generated::{occluder_scene, push_cube};
use antiradiance::scene::Scene;
use antiradiance::solve::sealed::sealed_fronts;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::{run, SolverKind, SolverOptions};
use glam::DVec3;

/// The occluder scene with a 0.4 m slab 0.1 m above its floor beside the plate, every face turned to
/// face in and one face's first triangle split at the middle of its diagonal (a T-junction:
/// the other triangle keeps the whole diagonal). `open_top` leaves out the top face, so that
/// the light above shines into the slab. Returns the scene and the slab's first triangle.
fn scene_with_slab(open_top: bool) -> (Scene, usize) {
    let mut scene = occluder_scene();
    let first = push_cube(&mut scene, DVec3::new(0.6, 0.1, 0.6), 0.4, 0.5);
    for t in &mut scene.triangles[first..] {
        t.swap(1, 2);
    }
    // Face 0 (z = 0.6, quad 0, 2, 3, 1) of the cube: its first triangle split at the middle of
    // the diagonal it shares with its second.
    let [a, b, c] = scene.triangles[first];
    let mid = scene.positions.len() as u32;
    scene
        .positions
        .push((scene.positions[a as usize] + scene.positions[c as usize]) / 2.0);
    scene.triangles[first] = [a, b, mid];
    scene.triangles.push([mid, b, c]);
    scene.albedo.push([0.5; 3]);
    scene.emission.push([0.0; 3]);
    scene.material.push(None);
    if open_top {
        // Quad 3 (y = 0.4 + 0.4: corners 2, 6, 7, 3) is the cube's top: triangles 6 and 7.
        for k in [first + 7, first + 6] {
            scene.triangles.remove(k);
            scene.albedo.remove(k);
            scene.emission.remove(k);
            scene.material.remove(k);
        }
    }
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

/// The slab's faces see only one another's fronts, lit from the room at their backs: they are
/// sealed, solved black (exactly the scene with every sealed front black), and report B = 0,
/// where antiradiance alone lets the light through the slab's faces into it. (So are the
/// floor's cells in the plate's umbra: they see the plate's back, the slab's and the open
/// sky, none of which sends light.)
#[test]
fn a_slab_whose_faces_face_in_is_dark_inside() {
    let (scene, first) = scene_with_slab(false);
    let slab = first..scene.len();
    let sealed = sealed_fronts(&build_patches(&scene, None));
    assert!(
        slab.clone().all(|t| sealed[t]),
        "{:?}",
        &sealed[slab.clone()]
    );
    let got = solve(&scene);
    let model = got.stats.model.clone().expect("hierarchical model stats");
    assert_eq!(model.closed_dark_objects, 0, "the T-junction keeps it open");
    let count = sealed.iter().filter(|&&s| s).count();
    assert_eq!(model.sealed_patches, count as u64);
    for t in slab {
        assert_eq!(got.triangle_radiance[t], [0.0; 3], "triangle {t}");
    }
    let mut black = scene.clone();
    for (t, _) in sealed.iter().enumerate().filter(|(_, &s)| s) {
        black.albedo[t] = [0.0; 3];
    }
    let expected = solve(&black);
    for (t, (b, want)) in got
        .triangle_radiance
        .iter()
        .zip(&expected.triangle_radiance)
        .enumerate()
    {
        for c in 0..3 {
            assert!(
                (b[c] - want[c]).abs() <= 1e-9 * (1.0 + want[c].abs()),
                "triangle {t}: {b:?} vs {want:?}"
            );
        }
    }
}

/// With its top left out the light shines into the slab: none of its faces is sealed, and
/// they are lit.
#[test]
fn a_slab_open_to_the_light_is_not_sealed() {
    let (scene, first) = scene_with_slab(true);
    let sealed = sealed_fronts(&build_patches(&scene, None));
    assert!(
        (first..scene.len()).all(|t| !sealed[t]),
        "{:?}",
        &sealed[first..]
    );
    let got = solve(&scene);
    let lit = (first..scene.len())
        .filter(|&t| got.triangle_radiance[t][0] > 0.0)
        .count();
    assert!(lit >= 8, "{lit} of the slab's faces lit");
}
