//! Closed objects with a dark inside are solved facing out (`mesh::closed`): a box standing
//! on the occluder scene's floor, some of its faces given reversed, one-sided or two-sided.
//! Sealed fronts are solved black (`solve::sealed`): a slab whose faces all face in, lit above
//! that floor, its surface not closed by shared vertices (a T-junction), so that it is not
//! turned outward as a closed object.

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::generated::{occluder_scene, push_cube};
use antiradiance::scene::Scene;
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::sealed::sealed_fronts;
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

/// Asserts that every triangle of `faces` is sealed (in `sealed`, the scene's
/// [`sealed_fronts`]) and solved black; returns the solution.
fn assert_sealed_and_dark(
    scene: &Scene,
    sealed: &[bool],
    faces: std::ops::Range<usize>,
) -> Solution {
    assert!(
        faces.clone().all(|t| sealed[t]),
        "{:?}",
        &sealed[faces.clone()]
    );
    let got = solve(scene);
    for t in faces {
        assert_eq!(got.triangle_radiance[t], [0.0; 3], "triangle {t}");
    }
    got
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

/// The same slab two-sided: each face's inside is sealed and its outside lit, so it is solved
/// one-sided facing out (the slab turned around, as the box above): its outside has that
/// slab's radiance, its inside 0, and the rest of the scene that slab's result.
#[test]
fn a_two_sided_slab_is_dark_inside_and_lit_outside() {
    let (inward, first) = scene_with_slab(false);
    let mut two = inward.clone();
    two.two_sided = (0..two.len()).map(|t| t >= first).collect();
    let mut outward = inward.clone();
    for t in &mut outward.triangles[first..] {
        t.swap(1, 2);
    }
    let (expected, got) = (solve(&outward), solve(&two));
    assert_eq!(got.triangle_radiance_back.len(), two.len());
    for t in 0..two.len() {
        let want = expected.triangle_radiance[t];
        let (outside, inside) = if t >= first {
            (got.triangle_radiance_back[t], got.triangle_radiance[t])
        } else {
            (got.triangle_radiance[t], [0.0; 3])
        };
        for c in 0..3 {
            assert!(
                (outside[c] - want[c]).abs() <= 1e-9 * (1.0 + want[c].abs()),
                "triangle {t}: outside {outside:?}, expected {want:?}"
            );
        }
        assert_eq!(inside, [0.0; 3], "triangle {t}: the inside is dark");
    }
    assert!(
        (first..two.len()).any(|t| got.triangle_radiance_back[t][0] > 0.0),
        "the slab's outside is lit"
    );
}

/// The slab of `scene_with_slab(false)` with a plate through it (`corners`, a quad of albedo
/// 0.5, triangles (0, 1, 2) and (0, 2, 3)) whose normal has `facing` along it: checks that
/// the plate is not sealed and lit, and that the slab is sealed and solved dark inside.
fn slab_with_a_plate_through_it(corners: [DVec3; 4], facing: DVec3) {
    let (mut scene, first) = scene_with_slab(false);
    let slab = first..scene.len();
    let base = scene.positions.len() as u32;
    scene.positions.extend(corners);
    for t in [[0, 1, 2], [0, 2, 3]] {
        scene.triangles.push(t.map(|k| base + k));
        scene.albedo.push([0.5; 3]);
        scene.emission.push([0.0; 3]);
        scene.material.push(None);
    }
    let plate = slab.end..scene.len();
    let patches = build_patches(&scene, None);
    for t in plate.clone() {
        assert!(patches.normal[t].dot(facing) > 0.99, "plate triangle {t}");
    }
    let sealed = sealed_fronts(&patches);
    assert!(
        plate.clone().all(|t| !sealed[t]),
        "the plate is lit: {:?}",
        &sealed[plate.clone()]
    );
    let got = assert_sealed_and_dark(&scene, &sealed, slab);
    for t in plate {
        assert!(
            got.triangle_radiance[t][0] > 0.0,
            "plate triangle {t} is lit"
        );
    }
}

/// A wall through the slab: a quad in the plane of the slab's far face (z = 1), facing the
/// light as that face faces into the slab, from the slab's bottom to 0.8 m above its top. Its
/// front is lit above the slab, and where it runs through the slab it lies on the slab's face:
/// rays from inside the slab that meet it there meet no light (as a wall's end face, lit at a
/// window's reveal, runs through the lintel above the window). The slab stays sealed.
#[test]
fn a_slab_a_lit_wall_runs_through_is_dark_inside() {
    // Counter-clockwise seen from -z: the front faces the light (z < 1).
    let corners =
        [(0.6, 0.1), (0.6, 1.3), (1.0, 1.3), (1.0, 0.1)].map(|(x, y)| DVec3::new(x, y, 1.0));
    slab_with_a_plate_through_it(corners, -DVec3::Z);
}

/// A shelf through the slab: a plate facing down, 0.05 m under the slab's top, from inside
/// the slab out through its side into the room. Out in the room its underside sees the lit
/// floor but no light itself (the light is above its plane): it is lit only by what it sees.
/// Inside the slab it is a shelf whose underside sees only the slab: rays from the slab's
/// faces that meet it there meet no light (as a wall's end face that frames a door, lit by
/// the room through the opening, runs on through the lintel box above the door). The slab
/// stays sealed and dark inside; the plate is lit.
#[test]
fn a_slab_a_shelf_lit_by_the_room_runs_through_is_dark_inside() {
    let corners =
        [(0.65, 0.65), (1.4, 0.65), (1.4, 0.95), (0.65, 0.95)].map(|(x, z)| DVec3::new(x, 0.45, z));
    slab_with_a_plate_through_it(corners, -DVec3::Y);
}

/// A strip 1.5 mm over the occluder scene's plate (0.4 x 0.03 m), facing down at it: its front
/// sees almost only the plate right under it, which the strip itself shades, and light reaches
/// the gap only at its edges. Covered within 2% of its size (`solve::cavity::covered`), it is
/// sealed and solved black; the plate is lit. (Counted by its rays, the strip's front met the
/// plate at points near the strip's edges that see the light, more than a sixteenth of them,
/// and was lit as brightly as the plate's open part makes it: the MGF office's rails 1 mm
/// under its ceiling, two-sided, 8 times as bright as the path tracer's.)
#[test]
fn a_strip_just_over_a_lit_plate_is_dark_underneath() {
    let mut scene = occluder_scene();
    let base = scene.positions.len() as u32;
    // Counter-clockwise seen from below: the front faces down.
    scene.positions.extend(
        [(0.2, -0.015), (0.2, 0.015), (-0.2, 0.015), (-0.2, -0.015)]
            .map(|(x, z)| DVec3::new(x, 0.5015, z)),
    );
    for t in [[0, 1, 2], [0, 2, 3]] {
        scene.triangles.push(t.map(|k| base + k));
        scene.albedo.push([0.5; 3]);
        scene.emission.push([0.0; 3]);
        scene.material.push(None);
    }
    let strip = scene.len() - 2..scene.len();
    let patches = build_patches(&scene, None);
    for t in strip.clone() {
        assert!(patches.normal[t].y < -0.99, "the strip faces down: {t}");
    }
    let got = assert_sealed_and_dark(&scene, &sealed_fronts(&patches), strip);
    // The plate (triangles 2 and 3 of the occluder scene) is lit around the strip.
    assert!(got.triangle_radiance[2][0] > 0.0 && got.triangle_radiance[3][0] > 0.0);
}

/// A plate facing down 0.5 m over a floor, lit by a point light above it or by a sky, with no
/// emitting triangle: the plate's underside sees only the floor, which the light reaches
/// around the plate's shadow. The floor's direct light from the analytic light is a source,
/// so the underside's rays that meet the floor meet light: it is not sealed, and is lit.
#[test]
fn a_face_lit_by_what_analytic_lights_light_is_not_sealed() {
    use antiradiance::scene::lights::Light;
    for light in [
        Light::Point {
            position: DVec3::new(0.0, 1.0, 0.0),
            intensity: [1.0; 3],
        },
        Light::Sky { radiance: [1.0; 3] },
    ] {
        let mut scene = occluder_scene();
        // Drop the emitting square (triangles 0 and 1): the analytic light alone lights it.
        for k in [1, 0] {
            scene.triangles.remove(k);
            scene.albedo.remove(k);
            scene.emission.remove(k);
            scene.material.remove(k);
        }
        // The plate (now triangles 0 and 1) turned to face the floor.
        for t in &mut scene.triangles[..2] {
            t.swap(1, 2);
        }
        scene.lights.push(light);
        let patches = build_patches(&scene, None);
        assert!(patches.normal[0].y < -0.99, "the plate faces down");
        let sealed = sealed_fronts(&patches);
        assert!(
            !sealed[0] && !sealed[1],
            "{light:?}: the plate's underside is lit"
        );
        let got = solve(&scene);
        assert!(
            got.triangle_radiance[0][0] > 0.0 && got.triangle_radiance[1][0] > 0.0,
            "{light:?}: {:?}",
            &got.triangle_radiance[..2]
        );
    }
}
