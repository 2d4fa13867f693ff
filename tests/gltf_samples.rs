//! The Khronos glTF sample assets in `../shared/gltf/` load as their README describes. Read
//! there (never copied into the repository); each test is skipped when the folder is absent.

mod gltf_common;

use antiradiance::scene::lights::{Light, LUMENS_PER_WATT};
use antiradiance::scene::{load_scene, Scene, SceneOptions};

fn load(name: &str) -> Option<Scene> {
    let Some(dir) = gltf_common::samples_dir() else {
        eprintln!("skipped: ../shared/gltf is absent");
        return None;
    };
    let path = dir.join(name);
    if !path.is_file() {
        eprintln!("skipped: {} is absent", path.display());
        return None;
    }
    Some(load_scene(&path, &SceneOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}")))
}

/// The materials of two-sided triangles (glTF `doubleSided`); asserts nothing warns of them.
fn two_sided_materials(scene: &Scene) -> usize {
    assert!(scene.warnings.iter().all(|w| !w.contains("doubleSided")));
    let mut materials: Vec<Option<u32>> = (0..scene.len())
        .filter(|&t| scene.is_two_sided(t))
        .map(|t| scene.material[t])
        .collect();
    materials.sort();
    materials.dedup();
    materials.len()
}

#[test]
fn box_binary_and_embedded_are_the_same_box_under_a_matrix_node() {
    let (Some(glb), Some(embedded)) = (load("Box/Box.glb"), load("Box/Box_embedded.gltf")) else {
        return;
    };
    assert_eq!(glb.len(), 12);
    assert_eq!(embedded.len(), 12);
    for t in 0..12 {
        assert_eq!(glb.corners(t), embedded.corners(t));
        assert_eq!(glb.albedo[t], embedded.albedo[t]);
    }
    // The parent's matrix turns the mesh's y into -z: the box spans [-0.5, 0.5]^3 either way,
    // and the triangles stay a closed, outward-facing surface (front = outside).
    let (lo, hi) = glb.bounds();
    assert!(
        (lo + glam::DVec3::splat(0.5)).length() < 1e-6
            && (hi - glam::DVec3::splat(0.5)).length() < 1e-6
    );
    for t in 0..12 {
        let [a, b, c] = glb.corners(t);
        let n = (b - a).cross(c - a);
        assert!(n.dot((a + b + c) / 3.0) > 0.0, "triangle {t} faces out");
    }
    assert_eq!(glb.material_names.len(), 1);
    assert!((glb.albedo[0][0] - 0.8).abs() < 1e-6 && glb.albedo[0][1] == 0.0);
}

#[test]
fn textured_interleaved_and_coloured_boxes() {
    if let Some(s) = load("BoxTextured/BoxTextured.glb") {
        assert_eq!(s.len(), 12);
        // The texture darkens the white factor and varies from triangle to triangle.
        assert!(
            s.albedo
                .iter()
                .all(|a| a.iter().all(|&x| x > 0.0 && x < 0.99)),
            "{:?}",
            s.albedo
        );
        assert!(s.albedo.iter().any(|a| a != &s.albedo[0]));
    }
    if let (Some(s), Some(b)) = (
        load("BoxInterleaved/BoxInterleaved.glb"),
        load("Box/Box.glb"),
    ) {
        assert_eq!(s.len(), 12);
        assert_eq!(s.bounds(), b.bounds());
    }
    if let Some(s) = load("BoxVertexColors/BoxVertexColors.glb") {
        // No material: the grey --albedo times the corners' COLOR_0.
        assert!(s.material.iter().all(Option::is_none));
        assert!(
            s.albedo.iter().any(|a| a != &s.albedo[0]),
            "vertex colours read"
        );
        assert!(s
            .albedo
            .iter()
            .all(|a| a.iter().all(|&x| x <= 0.75 + 1e-12)));
    }
}

#[test]
fn meshes_shared_by_nodes_and_the_default_scene() {
    if let Some(s) = load("SimpleMeshes/SimpleMeshes.gltf") {
        // One mesh used by two nodes, the second translated by (1, 0, 0).
        assert_eq!(s.len(), 2);
        let (a, b) = (s.corners(0), s.corners(1));
        for k in 0..3 {
            assert!((b[k] - a[k] - glam::DVec3::X).length() < 1e-6);
        }
    }
    if let Some(s) = load("MultipleScenes/MultipleScenes.gltf") {
        // The default scene is the second: node 1 only.
        let dir = gltf_common::samples_dir().unwrap();
        let doc = gltf::Gltf::open(dir.join("MultipleScenes/MultipleScenes.gltf")).unwrap();
        let mesh = doc.nodes().nth(1).unwrap().mesh().unwrap();
        let count: usize = mesh
            .primitives()
            .map(|p| {
                p.indices()
                    .map_or(p.get(&gltf::Semantic::Positions).unwrap().count(), |i| {
                        i.count()
                    })
                    / 3
            })
            .sum();
        assert_eq!(s.len(), count);
    }
}

#[test]
fn orientation_truck_and_attenuation_panels_load() {
    if let Some(s) = load("OrientationTest/OrientationTest.glb") {
        assert_eq!(s.material_names.len(), 7);
        assert!(s.len() > 100);
        assert_eq!(s.degenerate_count(), 0);
    }
    if let Some(s) = load("CesiumMilkTruck/CesiumMilkTruck.glb") {
        assert!(s.len() > 3000);
        // The JPEG texture gives the truck's triangles different albedos.
        let truck: Vec<usize> = (0..s.len())
            .filter(|&t| s.material_name(t) == Some("truck"))
            .collect();
        assert!(!truck.is_empty());
        assert!(truck.iter().any(|&t| s.albedo[t] != s.albedo[truck[0]]));
        // Nested transforms: the wheels sit below the body, the scene is z-up after the root
        // node's rotation (y-up file turned), so it is longer than tall.
        let (lo, hi) = s.bounds();
        let size = hi - lo;
        assert!(size.x > size.y || size.z > size.y, "{size:?}");
    }
    if let Some(s) = load("AttenuationTest/AttenuationTest.glb") {
        assert_eq!(two_sided_materials(&s), 5);
    }
}

#[test]
fn punctual_lamp_lights_and_emissive_texture() {
    let Some(s) = load("LightsPunctualLamp/LightsPunctualLamp.gltf") else {
        return;
    };
    assert_eq!(s.lights.len(), 5);
    let mut intensities: Vec<f64> = s
        .lights
        .iter()
        .map(|l| match l {
            Light::Point { intensity, .. } => intensity.iter().fold(0.0f64, |m, &x| m.max(x)),
            other => panic!("{other:?}"),
        })
        .collect();
    intensities.sort_by(f64::total_cmp);
    // 1.5 cd to 180 cd (colours at most 1 per channel).
    assert!((intensities[0] - 1.5 / LUMENS_PER_WATT).abs() < 1e-9);
    assert!((intensities[4] - 180.0 / LUMENS_PER_WATT).abs() < 1e-6);
    assert!(
        s.emitter_count() > 0,
        "the emissive texture lights some triangles"
    );
    assert_eq!(two_sided_materials(&s), 3);
}

#[test]
fn emissive_strength_test_scales_by_strength() {
    let Some(s) = load("EmissiveStrengthTest/EmissiveStrengthTest.glb") else {
        return;
    };
    let emission_of = |name: &str| {
        let t = (0..s.len())
            .find(|&t| s.material_name(t) == Some(name))
            .unwrap();
        s.emission[t]
    };
    let one = emission_of("Emit1");
    assert!((one[2] - 0.9 / LUMENS_PER_WATT).abs() < 1e-9);
    for (name, k) in [
        ("Emit2", 2.0),
        ("Emit4", 4.0),
        ("Emit8", 8.0),
        ("Emit16", 16.0),
    ] {
        let e = emission_of(name);
        for c in 0..3 {
            assert!(
                (e[c] - k * one[c]).abs() <= 1e-9,
                "{name}: {e:?} vs {k} x {one:?}"
            );
        }
    }
}

#[test]
fn double_sided_samples_are_two_sided() {
    if let Some(s) = load("TwoSidedPlane/TwoSidedPlane.gltf") {
        assert_eq!(s.len(), 2);
        assert_eq!(two_sided_materials(&s), 1);
        assert!((0..s.len()).all(|t| s.is_two_sided(t)));
    }
    if let Some(s) = load("TextureCoordinateTest/TextureCoordinateTest.glb") {
        assert_eq!(two_sided_materials(&s), 5);
    }
}

#[test]
fn an_unsupported_required_extension_is_an_error() {
    let Some(dir) = gltf_common::samples_dir() else {
        return;
    };
    let path = dir.join("IridescenceSuzanne/IridescenceSuzanne.glb");
    if !path.is_file() {
        return;
    }
    let e = load_scene(&path, &SceneOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("KHR_materials_iridescence") && e.contains("extensionsRequired"),
        "{e}"
    );
    assert!(e.contains("IridescenceSuzanne.glb"));
}
