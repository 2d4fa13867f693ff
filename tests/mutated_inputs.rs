//! Mutated scene files never panic, a property test (proptest): valid OBJ, MTL, PNG, glTF and
//! GLB inputs, changed by one to three random mutations (bytes flipped, cut, repeated, removed,
//! replaced, numbers replaced by extreme values), are each either loaded into a scene whose
//! corners are finite, albedos in [0, 1) and emission finite and non-negative, or refused with
//! a one-line error. A failing case is shrunk to its fewest, smallest mutations and printed.
//! `PROPTEST_CASES` sets the cases per input (default 600, 3,000 in all; a longer run:
//! `PROPTEST_CASES=20000 cargo test --release --test mutated_inputs`).

mod gltf_common;

use antiradiance::scene::{load_scene, SceneOptions};
use gltf_common::{png, Doc};
use proptest::prelude::*;
use serde_json::json;

/// Cases per input when `PROPTEST_CASES` is not set.
const DEFAULT_CASES: u32 = 600;

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_CASES);
    ProptestConfig {
        cases,
        // The library's own errors are values, not panics: a panic is the failure looked for,
        // and its message is enough.
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

const NUMBERS: [&str; 10] = [
    "0",
    "-1",
    "1e309",
    "nan",
    "-0",
    "4294967295",
    "99999999999",
    "0.5",
    "3",
    "-2147483648",
];

/// One change of a file: `kind` (0..6) at `at` (a fraction of its length), with `value`.
#[derive(Clone, Debug)]
struct Mutation {
    kind: u8,
    at: f64,
    value: u8,
}

fn mutation() -> impl Strategy<Value = Mutation> {
    (0u8..6, 0.0f64..1.0, any::<u8>()).prop_map(|(kind, at, value)| Mutation { kind, at, value })
}

/// One to three changes.
fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
    prop::collection::vec(mutation(), 1..4)
}

/// `bytes` changed by `m`.
fn mutate(bytes: &[u8], m: &Mutation) -> Vec<u8> {
    let mut out = bytes.to_vec();
    if out.is_empty() {
        return out;
    }
    let at = ((m.at * out.len() as f64) as usize).min(out.len() - 1);
    let v = m.value as usize;
    match m.kind {
        0 => out[at] ^= 1 << (v % 8),
        1 => out.truncate(at),
        2 => {
            let end = (at + 1 + v % 16).min(out.len());
            let piece = out[at..end].to_vec();
            out.splice(at..at, piece);
        }
        3 => {
            let end = (at + 1 + v % 8).min(out.len());
            out.drain(at..end);
        }
        4 => out[at] = m.value,
        _ => {
            // Replace the number starting at or after `at` by an extreme one.
            let start = (at..out.len()).find(|&i| out[i].is_ascii_digit());
            if let Some(s) = start {
                let e = (s..out.len())
                    .find(|&i| !(out[i].is_ascii_digit() || out[i] == b'.'))
                    .unwrap_or(out.len());
                out.splice(s..e, NUMBERS[v % NUMBERS.len()].bytes());
            }
        }
    }
    out
}

/// Writes `files` into a new directory, `target` changed by `changes`, and loads `entry`:
/// an error if the load panicked, returned a multi-line error, or a scene out of range.
fn check(
    files: &[(&str, &[u8])],
    entry: &str,
    target: &str,
    changes: &[Mutation],
) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    for &(name, bytes) in files {
        let bytes = if name == target {
            changes.iter().fold(bytes.to_vec(), |b, m| mutate(&b, m))
        } else {
            bytes.to_vec()
        };
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    let path = dir.path().join(entry);
    let loaded = std::panic::catch_unwind(|| load_scene(&path, &SceneOptions::default()));
    match loaded {
        Ok(Ok(scene)) => {
            for t in 0..scene.len() {
                prop_assert!(scene.corners(t).iter().all(|p| p.is_finite()));
                prop_assert!(scene.albedo[t].iter().all(|a| (0.0..1.0).contains(a)));
                prop_assert!(scene.emission[t].iter().all(|e| e.is_finite() && *e >= 0.0));
            }
            Ok(())
        }
        Ok(Err(e)) => {
            let text = e.to_string();
            prop_assert!(!text.contains('\n'), "not one line: {}", text);
            Ok(())
        }
        Err(_) => Err(TestCaseError::fail(format!("loading {entry} panicked"))),
    }
}

const OBJ: &[u8] = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl a\nf 1/1 2/2 3/3 4\nusemtl b\nf -1 -2 -3\n";
const MTL: &[u8] =
    b"newmtl a\nKd 0.5 0.25 0.125\nmap_Kd -s 2 2 t.png\nnewmtl b\nKe 1 2 3\nKd 0.1 0.2 0.3\n";

/// The OBJ, its MTL and the texture it names.
fn obj_files(texture: &[u8]) -> [(&'static str, &[u8]); 3] {
    [("s.obj", OBJ), ("m.mtl", MTL), ("t.png", texture)]
}

fn texture() -> Vec<u8> {
    png(2, 2, &[[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]])
}

fn textured_doc() -> (Doc, serde_json::Value) {
    let mut doc = Doc::default();
    let pos = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ]);
    let uv = doc.vec2(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
    let idx = doc.indices(&[0, 1, 2, 0, 2, 3]);
    let img = doc.view(&png(
        2,
        2,
        &[[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]],
    ));
    let rest = json!({
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
        "extensions": { "KHR_lights_punctual": { "lights": [
            { "type": "spot", "intensity": 10.0, "spot": { "innerConeAngle": 0.1, "outerConeAngle": 0.5 } }
        ] } },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [
            { "mesh": 0, "translation": [1.0, 2.0, 3.0], "children": [1] },
            { "rotation": [0.0, 0.0, 0.0, 1.0], "scale": [1.0, 2.0, 1.0], "mesh": 0,
              "extensions": { "KHR_lights_punctual": { "light": 0 } } }
        ],
        "meshes": [{ "primitives": [
            { "attributes": { "POSITION": pos, "TEXCOORD_0": uv }, "indices": idx, "material": 0 },
            { "attributes": { "POSITION": pos }, "mode": 5 }
        ] }],
        "materials": [{
            "pbrMetallicRoughness": { "baseColorFactor": [0.5, 0.5, 0.5, 1.0], "baseColorTexture": { "index": 0 } },
            "emissiveFactor": [0.1, 0.2, 0.3],
            "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 5.0 } }
        }],
        "textures": [{ "source": 0, "sampler": 0 }],
        "samplers": [{ "wrapS": 33648, "wrapT": 33071 }],
        "images": [{ "bufferView": img, "mimeType": "image/png" }]
    });
    (doc, rest)
}

/// The textured document as GLB and as glTF with an embedded buffer.
fn gltf_files() -> (Vec<u8>, Vec<u8>) {
    let (doc, rest) = textured_doc();
    let glb = doc.glb_bytes(rest.clone());
    let gltf = serde_json::to_vec_pretty(&doc.json(rest, true)).unwrap();
    (glb, gltf)
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mutated_obj_files_never_panic(changes in mutations()) {
        check(&obj_files(&texture()), "s.obj", "s.obj", &changes)?;
    }

    #[test]
    fn mutated_mtl_files_never_panic(changes in mutations()) {
        check(&obj_files(&texture()), "s.obj", "m.mtl", &changes)?;
    }

    #[test]
    fn mutated_textures_never_panic(changes in mutations()) {
        check(&obj_files(&texture()), "s.obj", "t.png", &changes)?;
    }

    #[test]
    fn mutated_glb_files_never_panic(changes in mutations()) {
        let (glb, _) = gltf_files();
        check(&[("s.glb", &glb)], "s.glb", "s.glb", &changes)?;
    }

    #[test]
    fn mutated_gltf_files_never_panic(changes in mutations()) {
        let (_, gltf) = gltf_files();
        check(&[("s.gltf", &gltf)], "s.gltf", "s.gltf", &changes)?;
    }
}

/// The mutations reach every branch: each kind changes a file (a check on the test itself).
#[test]
fn every_mutation_kind_changes_the_obj() {
    for kind in 0..6 {
        let m = Mutation {
            kind,
            at: 0.3,
            value: 7,
        };
        assert_ne!(mutate(OBJ, &m), OBJ, "kind {kind}");
    }
}
