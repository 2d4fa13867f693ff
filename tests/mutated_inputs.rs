//! Mutated scene files never panic: valid OBJ, MTL, glTF and GLB inputs, changed at random
//! (bytes flipped, cut, repeated, numbers replaced by extreme values), are each either loaded
//! or refused with an error. A fixed seed makes the cases reproducible; `MUTATION_CASES` sets
//! how many per input (default 500; a longer run: `MUTATION_CASES=20000 cargo test --release
//! --test mutated_inputs`).

mod gltf_common;

use std::path::Path;

use antiradiance::geometry::sampling::Rng;
use antiradiance::scene::{load_scene, SceneOptions};
use gltf_common::{png, Doc};
use serde_json::json;

fn cases() -> usize {
    std::env::var("MUTATION_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(500)
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

/// One random change of `bytes`.
fn mutate(bytes: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut out = bytes.to_vec();
    if out.is_empty() {
        return out;
    }
    let at = rng.below(out.len() as u64) as usize;
    match rng.below(6) {
        0 => out[at] ^= 1 << rng.below(8),
        1 => out.truncate(at),
        2 => {
            let end = (at + 1 + rng.below(16) as usize).min(out.len());
            let piece = out[at..end].to_vec();
            out.splice(at..at, piece);
        }
        3 => {
            let end = (at + 1 + rng.below(8) as usize).min(out.len());
            out.drain(at..end);
        }
        4 => out[at] = rng.below(256) as u8,
        _ => {
            // Replace the number starting at or after `at` by an extreme one.
            let start = (at..out.len()).find(|&i| out[i].is_ascii_digit());
            if let Some(s) = start {
                let e = (s..out.len())
                    .find(|&i| !(out[i].is_ascii_digit() || out[i] == b'.'))
                    .unwrap_or(out.len());
                let n = NUMBERS[rng.below(NUMBERS.len() as u64) as usize];
                out.splice(s..e, n.bytes());
            }
        }
    }
    out
}

/// Writes each mutation of `file` (the other files of `dir` kept as they are) and loads `entry`.
fn run(dir: &Path, entry: &str, file: &str, original: &[u8], seed: u64) {
    let mut rng = Rng::new(seed, 0);
    for case in 0..cases() {
        let mut bytes = original.to_vec();
        for _ in 0..1 + rng.below(3) {
            bytes = mutate(&bytes, &mut rng);
        }
        std::fs::write(dir.join(file), &bytes).unwrap();
        let path = dir.join(entry);
        let result = std::panic::catch_unwind(|| load_scene(&path, &SceneOptions::default()));
        match result {
            Ok(Ok(scene)) => {
                for t in 0..scene.len() {
                    assert!(
                        scene.corners(t).iter().all(|p| p.is_finite()),
                        "{file} case {case}"
                    );
                    assert!(
                        scene.albedo[t].iter().all(|a| (0.0..1.0).contains(a)),
                        "{file} case {case}"
                    );
                    assert!(
                        scene.emission[t].iter().all(|e| e.is_finite() && *e >= 0.0),
                        "{file} case {case}"
                    );
                }
            }
            Ok(Err(e)) => {
                let text = e.to_string();
                assert!(
                    !text.contains('\n'),
                    "{file} case {case}: not one line: {text}"
                );
            }
            Err(_) => {
                std::fs::write(dir.join(format!("panic-{file}")), &bytes).unwrap();
                panic!(
                    "{file} case {case} panicked (input kept as panic-{file} in {})",
                    dir.display()
                );
            }
        }
    }
    std::fs::write(dir.join(file), original).unwrap();
}

#[test]
fn mutated_obj_and_mtl_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let obj = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl a\nf 1/1 2/2 3/3 4\nusemtl b\nf -1 -2 -3\n";
    let mtl =
        b"newmtl a\nKd 0.5 0.25 0.125\nmap_Kd -s 2 2 t.png\nnewmtl b\nKe 1 2 3\nKd 0.1 0.2 0.3\n";
    std::fs::write(dir.path().join("s.obj"), obj).unwrap();
    std::fs::write(dir.path().join("m.mtl"), mtl).unwrap();
    let t = png(2, 2, &[[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]]);
    std::fs::write(dir.path().join("t.png"), &t).unwrap();
    run(dir.path(), "s.obj", "s.obj", obj, 1);
    run(dir.path(), "s.obj", "m.mtl", mtl, 2);
    run(dir.path(), "s.obj", "t.png", &t, 3);
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

#[test]
fn mutated_gltf_and_glb_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, rest) = textured_doc();
    let glb = doc.glb_bytes(rest.clone());
    run(dir.path(), "s.glb", "s.glb", &glb, 4);
    let gltf = serde_json::to_vec_pretty(&doc.json(rest, true)).unwrap();
    run(dir.path(), "s.gltf", "s.gltf", &gltf, 5);
}
