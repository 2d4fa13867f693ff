//! glTF input: node transform chains, triangle order, strips and fans, mirrors, skipped
//! primitives, and punctual lights placed by their nodes.

mod gltf_common;

use antiradiance::scene::lights::Light;
use antiradiance::scene::{load_scene, SceneOptions};
use glam::DVec3;
use gltf_common::Doc;
use serde_json::json;

fn close(a: DVec3, b: DVec3) -> bool {
    (a - b).length() < 1e-5
}

#[test]
fn a_node_transform_chain_is_applied_parent_first() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    // root: translate (10, 0, 0) then scale 2; child: rotate 90 degrees about z (quaternion);
    // grandchild: a matrix translating by (1, 0, 0), holding the mesh.
    let rest = json!({
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [
            { "translation": [10.0, 0.0, 0.0], "scale": [2.0, 2.0, 2.0], "children": [1] },
            { "rotation": [0.0, 0.0, s, s], "children": [2] },
            { "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 1,0,0,1], "mesh": 0 }
        ],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": pos } }] }]
    });
    let path = dir.path().join("chain.gltf");
    doc.write_gltf(&path, rest);
    let scene = load_scene(&path, &SceneOptions::default()).unwrap();
    assert_eq!(scene.len(), 1);
    let c = scene.corners(0);
    // v -> T(10,0,0) S(2) Rz(90) T(1,0,0) v
    assert!(close(c[0], DVec3::new(10.0, 2.0, 0.0)), "{:?}", c[0]);
    assert!(close(c[1], DVec3::new(10.0, 4.0, 0.0)), "{:?}", c[1]);
    assert!(close(c[2], DVec3::new(8.0, 2.0, 0.0)), "{:?}", c[2]);
}

#[test]
fn triangles_come_in_node_primitive_index_order_with_strips_and_fans_converted() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::default();
    let quad = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ]);
    let strip = doc.indices(&[0, 1, 2, 3]);
    let fan_pos = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ]);
    let tris = doc.indices(&[0, 1, 2, 2, 1, 3]);
    let rest = json!({
        "scene": 0,
        "scenes": [{ "nodes": [0, 2] }],
        "nodes": [
            { "mesh": 0, "children": [1] },
            { "mesh": 1, "translation": [0.0, 0.0, 5.0] },
            { "mesh": 2, "translation": [0.0, 0.0, 9.0] }
        ],
        "meshes": [
            { "primitives": [
                { "attributes": { "POSITION": quad }, "indices": strip, "mode": 5 },
                { "attributes": { "POSITION": fan_pos }, "mode": 6 }
            ] },
            { "primitives": [{ "attributes": { "POSITION": quad }, "indices": tris }] },
            { "primitives": [
                { "attributes": { "POSITION": quad }, "mode": 0 },
                { "attributes": { "POSITION": quad }, "indices": tris }
            ] }
        ]
    });
    let path = dir.path().join("order.gltf");
    doc.write_gltf(&path, rest);
    let scene = load_scene(&path, &SceneOptions::default()).unwrap();
    // node 0: strip (2) + fan (2); its child node 1: 2; root node 2: points skipped + 2.
    assert_eq!(scene.len(), 8);
    let z: Vec<f64> = (0..8).map(|t| scene.corners(t)[0].z).collect();
    assert_eq!(z, vec![0.0, 0.0, 0.0, 0.0, 5.0, 5.0, 9.0, 9.0]);
    // Strip (the specification's p_i = v_i, v_(i+1+i%2), v_(i+2-i%2)): (0,1,2), (1,3,2);
    // fan: (1,2,0), (2,3,0); all facing +z.
    let v = DVec3::new;
    assert_eq!(
        scene.corners(1),
        [v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0), v(0.0, 1.0, 0.0)]
    );
    assert_eq!(
        scene.corners(2),
        [v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0), v(0.0, 0.0, 0.0)]
    );
    for t in 0..8 {
        let [a, b, c] = scene.corners(t);
        assert!((b - a).cross(c - a).z > 0.0, "triangle {t} faces +z");
    }
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("meshes[2].primitives[0]") && w.contains("skipped")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn a_mirroring_node_keeps_the_front_side() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let rest = json!({
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "scale": [-1.0, 1.0, 1.0], "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": pos } }] }]
    });
    let path = dir.path().join("mirror.gltf");
    doc.write_gltf(&path, rest);
    let scene = load_scene(&path, &SceneOptions::default()).unwrap();
    let [a, b, c] = scene.corners(0);
    assert!(
        (b - a).cross(c - a).z > 0.0,
        "a mirror in x keeps the +z front"
    );
    assert!(a.x <= 0.0 && b.x <= 0.0 && c.x <= 0.0);
}

#[test]
fn punctual_lights_follow_their_nodes_in_radiometric_units() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let rest = json!({
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": { "KHR_lights_punctual": { "lights": [
            { "type": "point", "intensity": 683.0, "color": [1.0, 0.5, 0.0] },
            { "type": "spot", "intensity": 1366.0, "spot": { "innerConeAngle": 0.2, "outerConeAngle": 0.5 } },
            { "type": "directional", "intensity": 6830.0 }
        ] } },
        "scenes": [{ "nodes": [0, 1] }],
        "nodes": [
            { "mesh": 0, "translation": [0.0, 0.0, 3.0], "children": [2],
              "extensions": { "KHR_lights_punctual": { "light": 0 } } },
            { "rotation": [-s, 0.0, 0.0, s], "translation": [1.0, 2.0, 3.0],
              "extensions": { "KHR_lights_punctual": { "light": 1 } } },
            { "rotation": [-s, 0.0, 0.0, s],
              "extensions": { "KHR_lights_punctual": { "light": 2 } } }
        ],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": pos } }] }]
    });
    let path = dir.path().join("lights.gltf");
    doc.write_gltf(&path, rest);
    let scene = load_scene(&path, &SceneOptions::default()).unwrap();
    assert_eq!(scene.lights.len(), 3);
    // Depth-first: node 0 (point), its child node 2 (sun), then node 1 (spot).
    match scene.lights[0] {
        Light::Point {
            position,
            intensity,
        } => {
            assert!(close(position, DVec3::new(0.0, 0.0, 3.0)));
            assert!((intensity[0] - 1.0).abs() < 1e-9 && (intensity[1] - 0.5).abs() < 1e-9);
            assert_eq!(intensity[2], 0.0);
        }
        other => panic!("{other:?}"),
    }
    match scene.lights[1] {
        Light::Sun {
            direction,
            irradiance,
        } => {
            assert!(
                close(direction, DVec3::new(0.0, -1.0, 0.0)),
                "{direction:?}"
            );
            assert!((irradiance[0] - 10.0).abs() < 1e-9);
        }
        other => panic!("{other:?}"),
    }
    match scene.lights[2] {
        Light::Spot {
            position,
            direction,
            intensity,
            inner,
            outer,
        } => {
            assert!(close(position, DVec3::new(1.0, 2.0, 3.0)));
            assert!(
                close(direction, DVec3::new(0.0, -1.0, 0.0)),
                "{direction:?}"
            );
            assert!((intensity[1] - 2.0).abs() < 1e-9);
            assert!((inner - 0.2).abs() < 1e-6 && (outer - 0.5).abs() < 1e-6);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn lights_written_to_gltf_read_back_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = antiradiance::scene::generated::cornell_box();
    scene.lights = vec![
        Light::Point {
            position: DVec3::new(278.0, 400.0, 279.0),
            intensity: [3e4, 2e4, 1e4],
        },
        Light::Spot {
            position: DVec3::new(100.0, 500.0, 100.0),
            direction: DVec3::new(0.3, -1.0, 0.2).normalize(),
            intensity: [5e4; 3],
            inner: 0.3,
            outer: 0.6,
        },
        Light::Sun {
            direction: DVec3::new(-1.0, -2.0, -0.5).normalize(),
            irradiance: [2.0, 2.0, 1.5],
        },
    ];
    let path = dir.path().join("lit.glb");
    antiradiance::output::gltf::write_scene_glb(&path, &scene).unwrap();
    let back = load_scene(&path, &SceneOptions::default()).unwrap();
    assert_eq!(back.lights.len(), 3);
    let rgb_close =
        |a: [f64; 3], b: [f64; 3]| (0..3).all(|c| (a[c] - b[c]).abs() <= 1e-5 * b[c].max(1.0));
    for (a, b) in back.lights.iter().zip(&scene.lights) {
        match (a, b) {
            (
                Light::Point {
                    position: p,
                    intensity: i,
                },
                Light::Point {
                    position: q,
                    intensity: j,
                },
            ) => {
                assert!(
                    (*p - *q).length() < 1e-3 && rgb_close(*i, *j),
                    "{a:?} vs {b:?}"
                );
            }
            (
                Light::Spot {
                    position: p,
                    direction: d,
                    intensity: i,
                    inner,
                    outer,
                },
                Light::Spot {
                    position: q,
                    direction: e,
                    intensity: j,
                    inner: i2,
                    outer: o2,
                },
            ) => {
                assert!(
                    (*p - *q).length() < 1e-3 && (*d - *e).length() < 1e-5 && rgb_close(*i, *j)
                );
                assert!((inner - i2).abs() < 1e-6 && (outer - o2).abs() < 1e-6);
            }
            (
                Light::Sun {
                    direction: d,
                    irradiance: i,
                },
                Light::Sun {
                    direction: e,
                    irradiance: j,
                },
            ) => {
                assert!(
                    (*d - *e).length() < 1e-5 && rgb_close(*i, *j),
                    "{a:?} vs {b:?}"
                );
            }
            _ => panic!("{a:?} vs {b:?}"),
        }
    }
}
