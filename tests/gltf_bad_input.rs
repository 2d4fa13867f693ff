//! Malformed glTF: one line naming the file (and the JSON path or byte offset), exit code 1,
//! no output, no panic.

mod common;
mod gltf_common;

use std::path::{Path, PathBuf};

use gltf_common::Doc;
use serde_json::{json, Value};

fn triangle_doc() -> (Doc, Value) {
    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let idx = doc.indices(&[0, 1, 2]);
    let rest = json!({
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": pos }, "indices": idx }] }]
    });
    (doc, rest)
}

/// Runs `solve` on `scene` and checks the error: exit 1, one line naming the file and
/// containing every `needle`, no CSV written.
fn expect_error(scene: &Path, needles: &[&str]) {
    let csv = scene.with_extension("csv");
    let o = common::run(&[
        "solve",
        common::s(scene),
        "--triangles",
        common::s(&csv),
        "-q",
    ]);
    let err = common::stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{}: {err}", scene.display());
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.starts_with("error: "), "{err}");
    assert!(!err.contains("internal error"), "a panic: {err}");
    assert!(
        err.contains(&scene.display().to_string()),
        "names the file: {err}"
    );
    for n in needles {
        assert!(err.contains(n), "'{n}' in: {err}");
    }
    assert!(!csv.exists(), "no output");
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn the_valid_triangle_loads() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, rest) = triangle_doc();
    let p = write(dir.path(), "ok.glb", &doc.glb_bytes(rest));
    let scene = antiradiance::scene::load_scene(&p, &Default::default()).unwrap();
    assert_eq!(scene.len(), 1);
}

#[test]
fn bad_magic_truncated_glb_and_bad_json() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, rest) = triangle_doc();
    let glb = doc.glb_bytes(rest);
    let mut magic = glb.clone();
    magic[..4].copy_from_slice(b"glTX");
    expect_error(
        &write(dir.path(), "magic.glb", &magic),
        &["not glTF", "byte 0"],
    );
    expect_error(
        &write(dir.path(), "cut.glb", &glb[..glb.len() / 2]),
        &["truncated GLB", "byte 8"],
    );
    expect_error(
        &write(dir.path(), "header.glb", &glb[..10]),
        &["truncated GLB"],
    );
    let mut version = glb.clone();
    version[4] = 1;
    expect_error(&write(dir.path(), "version.glb", &version), &["version 1"]);
    expect_error(
        &write(
            dir.path(),
            "json.gltf",
            b"{ \"asset\": { \"version\": \"2.0\" }, ",
        ),
        &["JSON", "line 1"],
    );
    expect_error(&write(dir.path(), "empty.gltf", b""), &["empty"]);
}

#[test]
fn accessors_outside_their_buffer_and_missing_buffers() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, rest) = triangle_doc();
    let mut json = doc.json(rest.clone(), true);
    json["accessors"][0]["count"] = json!(300);
    let p = write(
        dir.path(),
        "count.gltf",
        &serde_json::to_vec(&json).unwrap(),
    );
    expect_error(
        &p,
        &[
            "meshes[0].primitives[0].attributes.POSITION",
            "accessors[0]",
            "bufferViews[0]",
        ],
    );

    let mut json = doc.json(rest.clone(), true);
    json["bufferViews"][1]["byteOffset"] = json!(1000);
    let p = write(dir.path(), "view.gltf", &serde_json::to_vec(&json).unwrap());
    expect_error(&p, &["indices", "outside buffers[0]"]);

    let mut json = doc.json(rest.clone(), true);
    json["buffers"][0]["uri"] = json!("missing.bin");
    let p = write(
        dir.path(),
        "nobin.gltf",
        &serde_json::to_vec(&json).unwrap(),
    );
    expect_error(&p, &["buffers[0]", "missing.bin"]);

    let mut json = doc.json(rest.clone(), true);
    json["buffers"][0]["byteLength"] = json!(4096);
    let p = write(
        dir.path(),
        "short.gltf",
        &serde_json::to_vec(&json).unwrap(),
    );
    expect_error(&p, &["buffers[0]", "byteLength 4096"]);

    // A GLB whose buffer refers to a binary chunk it does not have.
    let json = doc.json(rest, false);
    let p = write(
        dir.path(),
        "nochunk.gltf",
        &serde_json::to_vec(&json).unwrap(),
    );
    expect_error(&p, &["buffers[0]"]);
}

#[test]
fn nan_positions_indices_out_of_range_and_a_missing_image() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let rest = json!({
        "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": pos } }] }]
    });
    let mut json = doc.json(rest, true);
    // Bounds as a careless exporter might leave them (NaN is not JSON).
    json["accessors"][0]["min"] = json!([0.0, 0.0, 0.0]);
    json["accessors"][0]["max"] = json!([1.0, 1.0, 0.0]);
    let p = write(dir.path(), "nan.gltf", &serde_json::to_vec(&json).unwrap());
    expect_error(&p, &["POSITION", "vertex 1 is not finite"]);

    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let idx = doc.indices(&[0, 1, 7]);
    let rest = json!({
        "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": pos }, "indices": idx }] }]
    });
    let p = dir.path().join("index.gltf");
    doc.write_gltf(&p, rest);
    expect_error(
        &p,
        &["meshes[0].primitives[0].indices", "index 7", "3 vertices"],
    );

    let (doc, mut rest) = triangle_doc();
    rest["meshes"][0]["primitives"][0]["material"] = json!(0);
    rest["materials"] = json!([{ "pbrMetallicRoughness": { "baseColorTexture": { "index": 0 } } }]);
    rest["textures"] = json!([{ "source": 0 }]);
    rest["images"] = json!([{ "uri": "missing.png" }]);
    let p = dir.path().join("image.gltf");
    doc.write_gltf(&p, rest);
    expect_error(&p, &["images[0]", "missing.png", "baseColorTexture"]);
}

#[test]
fn unsupported_required_extensions_and_bad_references() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, mut rest) = triangle_doc();
    rest["extensionsUsed"] = json!(["KHR_materials_iridescence"]);
    rest["extensionsRequired"] = json!(["KHR_materials_iridescence"]);
    let p = dir.path().join("required.gltf");
    doc.write_gltf(&p, rest);
    expect_error(
        &p,
        &[
            "extensionsRequired",
            "KHR_materials_iridescence",
            "unsupported",
        ],
    );

    let (doc, mut rest) = triangle_doc();
    rest["nodes"][0]["mesh"] = json!(5);
    let p = dir.path().join("reference.gltf");
    doc.write_gltf(&p, rest);
    expect_error(&p, &["nodes[0].mesh"]);

    // A node that is its own child.
    let (doc, mut rest) = triangle_doc();
    rest["nodes"][0]["children"] = json!([0]);
    let p = dir.path().join("cycle.gltf");
    doc.write_gltf(&p, rest);
    let o = common::run(&["solve", common::s(&p), "-q"]);
    assert_eq!(o.status.code(), Some(1), "{}", common::stderr(&o));
    assert!(common::stderr(&o).contains("nodes[0]"));

    // Points only: no triangles.
    let (doc, mut rest) = triangle_doc();
    rest["meshes"][0]["primitives"][0]["mode"] = json!(0);
    let p = dir.path().join("points.gltf");
    doc.write_gltf(&p, rest);
    expect_error(&p, &["no triangles"]);
}
