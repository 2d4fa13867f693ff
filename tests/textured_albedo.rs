//! A textured quad's albedo equals the analytic mean of its texture over each triangle, from
//! glTF and from OBJ+MTL (PNG, TGA, JPEG), with wrap modes respected; emissive textures and
//! emissive strength; an unreadable texture is a warning and the factor is used.
#![allow(clippy::needless_range_loop)] // channels and triangles index several arrays at once

mod gltf_common;

use antiradiance::scene::{load_scene, Scene, SceneOptions};
use gltf_common::{linear, png, Doc};
use serde_json::json;

/// A 4 x 4 sRGB texture, rows from the top, all texels different.
fn texels() -> Vec<[u8; 3]> {
    (0..16u32)
        .map(|i| [(i * 16) as u8, (255 - i * 13) as u8, ((i * 37) % 256) as u8])
        .collect()
}

const FACTOR: [f64; 3] = [0.9, 0.8, 0.7];

/// The analytic mean over the triangle below the diagonal of the texel grid (texel space
/// y <= x, i.e. UV (0,0), (1,0), (1,1) with v down the image): texels with j < i count
/// fully, those on the diagonal by half; in linear colour.
fn lower_mean(t: &[[u8; 3]], channel: usize) -> f64 {
    let mut sum = 0.0;
    for j in 0..4 {
        for i in 0..4 {
            let w = if j < i {
                1.0
            } else if i == j {
                0.5
            } else {
                0.0
            };
            sum += w * linear(t[j * 4 + i][channel]);
        }
    }
    sum / 8.0
}

fn upper_mean(t: &[[u8; 3]], channel: usize) -> f64 {
    let whole: f64 = t.iter().map(|x| linear(x[channel])).sum::<f64>() / 16.0;
    2.0 * whole - lower_mean(t, channel)
}

/// A unit quad facing +z with UVs `scale` times the unit square: triangle 0 is UV (0,0),
/// (1,0), (1,1) (scaled), triangle 1 is (0,0), (1,1), (0,1).
fn textured_quad(
    dir: &std::path::Path,
    scale: f32,
    wrap: u32,
    image: Vec<u8>,
) -> std::path::PathBuf {
    let mut doc = Doc::default();
    let pos = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ]);
    let uv = doc.vec2(&[[0.0, 0.0], [scale, 0.0], [scale, scale], [0.0, scale]]);
    let idx = doc.indices(&[0, 1, 2, 0, 2, 3]);
    let img = doc.view(&image);
    let rest = json!({
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{
            "attributes": { "POSITION": pos, "TEXCOORD_0": uv }, "indices": idx, "material": 0
        }] }],
        "materials": [{ "name": "tex", "pbrMetallicRoughness": {
            "baseColorFactor": [FACTOR[0], FACTOR[1], FACTOR[2], 1.0],
            "baseColorTexture": { "index": 0 }
        } }],
        "textures": [{ "source": 0, "sampler": 0 }],
        "samplers": [{ "magFilter": 9728, "wrapS": wrap, "wrapT": wrap }],
        "images": [{ "bufferView": img, "mimeType": "image/png" }]
    });
    let path = dir.join("quad.glb");
    std::fs::write(&path, doc.glb_bytes(rest)).unwrap();
    path
}

fn check(scene: &Scene, t: usize, channel: usize, want: f64, what: &str) {
    let got = scene.albedo[t][channel];
    assert!(
        (got - want).abs() <= 1e-6 + 1e-4 * want,
        "{what}: triangle {t} channel {channel}: {got} against the analytic {want}"
    );
}

#[test]
fn a_textured_quad_has_the_analytic_mean_of_its_texture() {
    let dir = tempfile::tempdir().unwrap();
    let t = texels();
    let path = textured_quad(dir.path(), 1.0, 10497, png(4, 4, &t));
    let scene = load_scene(&path, &SceneOptions::default()).unwrap();
    assert_eq!(scene.len(), 2);
    for c in 0..3 {
        check(&scene, 0, c, FACTOR[c] * lower_mean(&t, c), "glTF");
        check(&scene, 1, c, FACTOR[c] * upper_mean(&t, c), "glTF");
    }
}

#[test]
fn wrap_modes_are_respected() {
    let dir = tempfile::tempdir().unwrap();
    let t = texels();
    let lin = |i: usize, c: usize| linear(t[i][c]);
    let image_mean = |c: usize| (0..16).map(|i| lin(i, c)).sum::<f64>() / 16.0;
    // UVs over [0, 2]^2: the lower triangle covers half of tile (0, 0), all of tile (1, 0)
    // and half of tile (1, 1). Repeat: (L/2 + W + L/2) / 2 = (L + W) / 2 with L the lower
    // half's mean and W the image's.
    let repeat = load_scene(
        &textured_quad(dir.path(), 2.0, 10497, png(4, 4, &t)),
        &SceneOptions::default(),
    )
    .unwrap();
    for c in 0..3 {
        let want = FACTOR[c] * 0.5 * (lower_mean(&t, c) + image_mean(c));
        assert!(
            (repeat.albedo[0][c] - want).abs() <= 1e-6,
            "repeat channel {c}: {} vs {want}",
            repeat.albedo[0][c]
        );
    }
    // Clamp: u > 1 shows the right column, v > 1 the bottom row, both the corner texel.
    let clamp = load_scene(
        &textured_quad(dir.path(), 2.0, 33071, png(4, 4, &t)),
        &SceneOptions::default(),
    )
    .unwrap();
    for c in 0..3 {
        let right = (0..4).map(|j| lin(j * 4 + 3, c)).sum::<f64>() / 4.0;
        let bottom = (0..4).map(|i| lin(12 + i, c)).sum::<f64>() / 4.0;
        let corner = lin(15, c);
        let want = FACTOR[c] * (image_mean(c) + right + bottom + corner) / 4.0;
        let quad = 0.5 * (clamp.albedo[0][c] + clamp.albedo[1][c]);
        assert!(
            (quad - want).abs() <= 1e-6,
            "clamp channel {c}: {quad} vs {want}"
        );
    }
    // Mirrored repeat: tile (1, 1) is the image turned half a turn, whose lower half is the
    // image's upper half: (L/2 + W + U/2) / 2 = W.
    let mirror = load_scene(
        &textured_quad(dir.path(), 2.0, 33648, png(4, 4, &t)),
        &SceneOptions::default(),
    )
    .unwrap();
    for c in 0..3 {
        let want = FACTOR[c] * image_mean(c);
        assert!(
            (mirror.albedo[0][c] - want).abs() <= 1e-6,
            "mirror channel {c}: {} vs {want}",
            mirror.albedo[0][c]
        );
    }
}

fn write_obj_quad(dir: &std::path::Path, map: &str, extra_mtl: &str) -> std::path::PathBuf {
    // The same quad; OBJ's v runs up the image, so vt = (u, 1 - v_glTF).
    let obj = dir.join("quad.obj");
    std::fs::write(
        &obj,
        "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\nusemtl tex\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("quad.mtl"),
        format!(
            "newmtl tex\nKd {} {} {}\nmap_Kd {map}\n{extra_mtl}",
            FACTOR[0], FACTOR[1], FACTOR[2]
        ),
    )
    .unwrap();
    obj
}

#[test]
fn obj_map_kd_in_png_and_tga_gives_the_same_mean() {
    let dir = tempfile::tempdir().unwrap();
    let t = texels();
    std::fs::write(dir.path().join("tex.png"), png(4, 4, &t)).unwrap();
    let raw: Vec<u8> = t.iter().flatten().copied().collect();
    image::RgbImage::from_raw(4, 4, raw)
        .unwrap()
        .save(dir.path().join("tex.tga"))
        .unwrap();
    for name in ["tex.png", "tex.tga"] {
        let obj = write_obj_quad(dir.path(), name, "");
        let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
        assert!(
            scene.warnings.iter().all(|w| !w.contains("texture")),
            "{:?}",
            scene.warnings
        );
        for c in 0..3 {
            check(&scene, 0, c, FACTOR[c] * lower_mean(&t, c), name);
            check(&scene, 1, c, FACTOR[c] * upper_mean(&t, c), name);
        }
    }
}

#[test]
fn obj_map_kd_in_jpeg_is_decoded() {
    let dir = tempfile::tempdir().unwrap();
    let colour = [200u8, 120, 40];
    let img = image::RgbImage::from_pixel(16, 16, image::Rgb(colour));
    img.save(dir.path().join("tex.jpg")).unwrap();
    let obj = write_obj_quad(dir.path(), "tex.jpg", "");
    let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
    for t in 0..2 {
        for c in 0..3 {
            let want = FACTOR[c] * linear(colour[c]);
            let got = scene.albedo[t][c];
            // JPEG is lossy: within a few codes of the colour.
            assert!((got - want).abs() <= 0.02 * want + 0.005, "{got} vs {want}");
        }
    }
}

#[test]
fn obj_map_ke_scales_the_emission() {
    let dir = tempfile::tempdir().unwrap();
    let t = texels();
    std::fs::write(dir.path().join("tex.png"), png(4, 4, &t)).unwrap();
    let obj = write_obj_quad(dir.path(), "tex.png", "Ke 2 4 8\nmap_Ke tex.png\n");
    let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
    for (c, k) in [2.0, 4.0, 8.0].iter().enumerate() {
        let want = k * lower_mean(&t, c);
        assert!(
            (scene.emission[0][c] - want).abs() <= 1e-4 * want + 1e-9,
            "{:?}",
            scene.emission[0]
        );
    }
}

#[test]
fn an_unreadable_texture_is_a_warning_and_the_factor_is_used() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write_obj_quad(dir.path(), "missing.png", "");
    let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
    let w: Vec<&antiradiance::Warning> = scene
        .warnings
        .iter()
        .filter(|w| w.contains("missing.png"))
        .collect();
    assert_eq!(w.len(), 1, "{:?}", scene.warnings);
    assert_eq!(w[0].kind, antiradiance::WarningKind::Texture);
    assert!(
        w[0].contains("'tex'") && w[0].contains("Kd used"),
        "{}",
        w[0]
    );
    assert_eq!(scene.albedo[0], FACTOR);
    // Not an image at all: the same.
    std::fs::write(dir.path().join("bad.png"), b"not a png").unwrap();
    let obj = write_obj_quad(dir.path(), "bad.png", "");
    let scene = load_scene(&obj, &SceneOptions::default()).unwrap();
    assert!(scene
        .warnings
        .iter()
        .any(|w| w.contains("bad.png") && w.contains("'tex'")));
    assert_eq!(scene.albedo[1], FACTOR);
}

#[test]
fn emissive_strength_multiplies_the_emissive_factor() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::default();
    let pos = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let rest = json!({
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scenes": [{ "nodes": [0, 1] }],
        "nodes": [{ "mesh": 0 }, { "mesh": 1 }],
        "meshes": [
            { "primitives": [{ "attributes": { "POSITION": pos }, "material": 0 }] },
            { "primitives": [{ "attributes": { "POSITION": pos }, "material": 1 }] }
        ],
        "materials": [
            { "emissiveFactor": [0.1, 0.5, 0.9] },
            { "emissiveFactor": [0.1, 0.5, 0.9],
              "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 8.0 } } }
        ]
    });
    let path = dir.path().join("emit.gltf");
    doc.write_gltf(&path, rest);
    let scene = load_scene(&path, &SceneOptions::default()).unwrap();
    for c in 0..3 {
        let base = [0.1, 0.5, 0.9][c] / antiradiance::scene::lights::LUMENS_PER_WATT;
        assert!((scene.emission[0][c] - base).abs() < 1e-9);
        assert!((scene.emission[1][c] - 8.0 * base).abs() < 1e-8);
    }
}
