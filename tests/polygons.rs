//! Polygons of more than three corners in OBJ files: convex ones are fanned, concave ones
//! ear-clipped, so a concave face covers its own outline and nothing else (a fan from the
//! wrong corner covers a notch with triangles facing the other way); faces continued over
//! lines (`\` at a line's end).

mod gltf_common;

use std::path::{Path, PathBuf};

use antiradiance::scene::{load_scene, Scene, SceneOptions};
use antiradiance::SolverOptions;
use glam::DVec3;
use gltf_common::{linear, png};

/// The L-shaped floor, (x, z) corners, facing up (+y), starting next to the notch (x > 2
/// and z > 2) so that a fan from the first corner covers part of the notch.
const L: [(f64, f64); 6] = [
    (4.0, 2.0),
    (4.0, 0.0),
    (0.0, 0.0),
    (0.0, 4.0),
    (2.0, 4.0),
    (2.0, 2.0),
];

/// The L as rectangles' triangles: the same surface, cut by hand.
const L_TRIANGLES: [[(f64, f64); 3]; 4] = [
    [(0.0, 0.0), (0.0, 2.0), (4.0, 2.0)],
    [(0.0, 0.0), (4.0, 2.0), (4.0, 0.0)],
    [(0.0, 2.0), (0.0, 4.0), (2.0, 4.0)],
    [(0.0, 2.0), (2.0, 4.0), (2.0, 2.0)],
];

/// An OBJ of the L-shaped floor (one polygon, or `L_TRIANGLES`), with planar texture
/// coordinates (u, v) = (x, z) / 4 and material `floor`, under a square light facing down.
fn write_floor(dir: &Path, name: &str, as_polygon: bool, floor_mtl: &str) -> PathBuf {
    let mut obj = String::from("mtllib floor.mtl\n");
    let mut faces = String::from("usemtl floor\n");
    let mut n = 0;
    let mut vertex = |obj: &mut String, x: f64, y: f64, z: f64| {
        obj.push_str(&format!("v {x} {y} {z}\nvt {} {}\n", x / 4.0, z / 4.0));
        n += 1;
        n
    };
    let face = |ids: &[usize]| {
        let refs: Vec<String> = ids.iter().map(|i| format!("{i}/{i}")).collect();
        format!("f {}\n", refs.join(" "))
    };
    if as_polygon {
        let ids: Vec<usize> = L
            .iter()
            .map(|&(x, z)| vertex(&mut obj, x, 0.0, z))
            .collect();
        faces.push_str(&face(&ids));
    } else {
        for t in L_TRIANGLES {
            let ids: Vec<usize> = t
                .iter()
                .map(|&(x, z)| vertex(&mut obj, x, 0.0, z))
                .collect();
            faces.push_str(&face(&ids));
        }
    }
    // The light: 1 x 1 at y = 2.9 over the L's corner, facing down.
    let light: Vec<usize> = [(0.5, 0.5), (1.5, 0.5), (1.5, 1.5), (0.5, 1.5)]
        .iter()
        .map(|&(x, z)| vertex(&mut obj, x, 2.9, z))
        .collect();
    faces.push_str("usemtl lamp\n");
    faces.push_str(&face(&light));
    obj.push_str(&faces);
    let path = dir.join(name);
    std::fs::write(&path, obj).unwrap();
    std::fs::write(
        dir.join("floor.mtl"),
        format!("newmtl floor\n{floor_mtl}\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n"),
    )
    .unwrap();
    path
}

/// The triangles of material `name`.
fn of_material(scene: &Scene, name: &str) -> Vec<usize> {
    (0..scene.len())
        .filter(|&t| scene.material_name(t) == Some(name))
        .collect()
}

fn normal(scene: &Scene, t: usize) -> DVec3 {
    let [a, b, c] = scene.corners(t);
    (b - a).cross(c - a).normalize()
}

#[test]
fn a_concave_polygon_is_ear_clipped_not_fanned() {
    let dir = tempfile::tempdir().unwrap();
    let poly = load_scene(
        &write_floor(dir.path(), "poly.obj", true, "Kd 0.7 0.7 0.7"),
        &SceneOptions::default(),
    )
    .unwrap();
    let floor = of_material(&poly, "floor");
    assert_eq!(floor.len(), L.len() - 2);
    let area: f64 = floor.iter().map(|&t| poly.area(t)).sum();
    assert!(
        (area - 12.0).abs() < 1e-12,
        "floor area {area} (the fan covers 16)"
    );
    for &t in &floor {
        assert!(
            normal(&poly, t).dot(DVec3::Y) > 1.0 - 1e-12,
            "triangle {t} faces down"
        );
        let c = poly.corners(t).iter().sum::<DVec3>() / 3.0;
        assert!(!(c.x > 2.0 && c.z > 2.0), "triangle {t} lies in the notch");
    }
    assert!(poly.warnings.is_empty(), "{:?}", poly.warnings);

    // Solved, it lights the floor as the hand-cut triangles do.
    let cut = load_scene(
        &write_floor(dir.path(), "cut.obj", false, "Kd 0.7 0.7 0.7"),
        &SceneOptions::default(),
    )
    .unwrap();
    let flux = |scene: &Scene| {
        let solved = antiradiance::solve(scene, Some(0.5), &SolverOptions::default()).unwrap();
        of_material(scene, "floor")
            .iter()
            .map(|&t| scene.area(t) * solved.solution.triangle_radiance[t][0])
            .sum::<f64>()
    };
    let (from_poly, from_cut) = (flux(&poly), flux(&cut));
    assert!(
        (from_poly / from_cut - 1.0).abs() < 0.01,
        "floor flux {from_poly} against {from_cut}"
    );
}

#[test]
fn a_textured_concave_polygon_takes_its_texture_over_its_own_outline() {
    // A 16 x 16 texture of 4 x 4 blocks (each a colour of its own) over the L's 4 x 4 square:
    // every triangle covers whole texels' worth (the texel-exact mean), and the L's mean
    // albedo is the mean of the 12 blocks outside the notch, whichever way the L is cut.
    let dir = tempfile::tempdir().unwrap();
    let block = |i: u32, j: u32| {
        let k = 4 * j + i;
        [(k * 16) as u8, (255 - k * 13) as u8, ((k * 37) % 256) as u8]
    };
    let texels: Vec<[u8; 3]> = (0..256u32).map(|t| block((t % 16) / 4, t / 64)).collect();
    std::fs::write(dir.path().join("tex.png"), png(16, 16, &texels)).unwrap();
    const KD: f64 = 0.9;
    // Block (i, j), j from the top, covers x in [i, i + 1], z in [3 - j, 4 - j] (OBJ's v runs
    // up the image); the notch is x > 2, z > 2.
    let expected = [0, 1, 2].map(|c| {
        let outside: Vec<f64> = (0..4)
            .flat_map(|j| (0..4).map(move |i| (i, j)))
            .filter(|&(i, j)| !(i >= 2 && j < 2))
            .map(|(i, j)| linear(block(i, j)[c]))
            .collect();
        KD * outside.iter().sum::<f64>() / outside.len() as f64
    });
    let mtl = format!("Kd {KD} {KD} {KD}\nmap_Kd tex.png");
    let mean = |path: PathBuf| {
        let scene = load_scene(&path, &SceneOptions::default()).unwrap();
        assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
        let floor = of_material(&scene, "floor");
        let area: f64 = floor.iter().map(|&t| scene.area(t)).sum();
        [0, 1, 2].map(|c| {
            floor
                .iter()
                .map(|&t| scene.area(t) * scene.albedo[t][c])
                .sum::<f64>()
                / area
        })
    };
    for (name, as_polygon) in [("poly.obj", true), ("cut.obj", false)] {
        let got = mean(write_floor(dir.path(), name, as_polygon, &mtl));
        for c in 0..3 {
            assert!(
                (got[c] - expected[c]).abs() < 1e-6,
                "{name}, channel {c}: {} against {}",
                got[c],
                expected[c]
            );
        }
    }
}

#[test]
fn a_concave_polygon_too_large_to_clip_is_fanned_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("star.obj");
    // A star of corners alternately at radius 1 and 0.5, more than the clipper takes.
    let n = antiradiance::geometry::polygon::MAX_EAR_CLIPPED_CORNERS + 2;
    let mut text = String::new();
    for k in 0..n {
        let (s, c) = (std::f64::consts::TAU * k as f64 / n as f64).sin_cos();
        let r = if k % 2 == 0 { 1.0 } else { 0.5 };
        text.push_str(&format!("v {} {} 0\n", r * c, r * s));
    }
    let refs: Vec<String> = (1..=n).map(|k| k.to_string()).collect();
    text.push_str(&format!("f {}\n", refs.join(" ")));
    std::fs::write(&obj, text).unwrap();
    let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
    assert_eq!(scene.len(), n - 2);
    let warning = scene.warnings.iter().find(|w| w.contains("ear-clipped"));
    assert!(
        warning.is_some_and(|w| w.contains("star.obj") && w.contains("corners): 1, fanned")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn a_face_continued_over_lines_is_one_face_and_later_errors_keep_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("continued.obj");
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 \\\n  3 \\\r\n  4\nf 1 2 9\n";
    std::fs::write(&obj, text).unwrap();
    let err = load_scene(&obj, &SceneOptions::default()).unwrap_err();
    // The bad face is on line 8 of the file, after a face written over lines 5 to 7.
    let message = err.to_string();
    assert!(message.contains("continued.obj:8:"), "{message}");
    std::fs::write(&obj, text.replace("f 1 2 9\n", "")).unwrap();
    let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
    assert_eq!(scene.len(), 2);
    let area: f64 = (0..2).map(|t| scene.area(t)).sum();
    assert!((area - 1.0).abs() < 1e-12);
}
