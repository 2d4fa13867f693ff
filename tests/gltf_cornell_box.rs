//! The Cornell box written by the project as glTF gives the OBJ box's per-triangle results,
//! and the baked `.glb` carries the per-triangle radiance its extras name.

use antiradiance::mesh::build_patches;
use antiradiance::output::gltf::{write_baked_glb, write_scene_glb};
use antiradiance::progress::Progress;
use antiradiance::scene::generated;
use antiradiance::scene::{load_scene, SceneOptions};
use antiradiance::solve::SolverKind;
use antiradiance::solve::SolverOptions;

#[test]
fn a_gltf_cornell_box_gives_the_obj_box_results() {
    let dir = tempfile::tempdir().unwrap();
    let box_scene = generated::cornell_box();
    let obj = dir.path().join("cornell_box.obj");
    let glb = dir.path().join("cornell_box.glb");
    generated::write_obj(&box_scene, &obj, "Cornell box").unwrap();
    let from_obj = load_scene(&obj, &SceneOptions::default()).unwrap();
    // Written from the OBJ file as read, so that the material names carry over.
    write_scene_glb(&glb, &from_obj).unwrap();
    let from_glb = load_scene(&glb, &SceneOptions::default()).unwrap();
    assert_eq!(from_obj.len(), from_glb.len());
    assert!(from_glb.warnings.is_empty(), "{:?}", from_glb.warnings);
    for t in 0..from_obj.len() {
        for (a, b) in from_obj.corners(t).iter().zip(from_glb.corners(t)) {
            assert!(
                (*a - b).length() <= 1e-4 * a.length().max(1.0),
                "triangle {t}: {a} vs {b}"
            );
        }
        for c in 0..3 {
            let (a, b) = (from_obj.albedo[t][c], from_glb.albedo[t][c]);
            assert!((a - b).abs() <= 1e-6, "triangle {t} albedo {a} vs {b}");
            let (e, f) = (from_obj.emission[t][c], from_glb.emission[t][c]);
            assert!(
                (e - f).abs() <= 1e-6 * e.max(1e-30),
                "triangle {t} emission {e} vs {f}"
            );
        }
        assert_eq!(
            from_obj.material_name(t),
            from_glb.material_name(t),
            "triangle {t}"
        );
    }
    let options = SolverOptions::default();
    let solve = |s| {
        let patches = build_patches(s, None);
        let solution = antiradiance::solve::run(
            SolverKind::Hierarchical,
            &patches,
            &options,
            &Progress::hidden(),
        )
        .unwrap();
        (patches, solution)
    };
    let (_, a) = solve(&from_obj);
    let (patches, b) = solve(&from_glb);
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..from_obj.len() {
        for c in 0..3 {
            let (x, y) = (a.triangle_radiance[t][c], b.triangle_radiance[t][c]);
            assert!(
                (x - y).abs() <= 0.005 * x.abs().max(1e-12),
                "triangle {t}: {x} vs {y}"
            );
            num += from_obj.area(t) * (x - y).abs();
            den += from_obj.area(t) * x;
        }
    }
    assert!(num / den < 0.005, "{}", num / den);

    // The baked result: per-triangle radiance and input-triangle accessors in each
    // primitive's extras, every input triangle once.
    let baked = dir.path().join("baked.glb");
    write_baked_glb(&baked, &from_glb, &patches, &b, 1.0).unwrap();
    let bytes = std::fs::read(&baked).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = gltf.blob.as_ref().unwrap();
    let read_f32 = |index: usize| -> Vec<f32> {
        let acc = gltf.accessors().nth(index).unwrap();
        let view = acc.view().unwrap();
        let start = view.offset() + acc.offset();
        let n = acc.count() * acc.dimensions().multiplicity();
        (0..n)
            .map(|i| {
                let at = start + 4 * i;
                f32::from_le_bytes(blob[at..at + 4].try_into().unwrap())
            })
            .collect()
    };
    let mut seen = vec![0usize; from_glb.len()];
    let mesh = gltf.meshes().next().unwrap();
    let materials: Vec<String> = gltf
        .materials()
        .map(|m| m.name().unwrap().to_string())
        .collect();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    for prim in mesh.primitives() {
        let extras = &json["meshes"][0]["primitives"][prim.index()]["extras"];
        let radiance = read_f32(extras["radiance"].as_u64().unwrap() as usize);
        let input = read_f32(extras["input_triangle"].as_u64().unwrap() as usize);
        assert_eq!(radiance.len(), 3 * input.len());
        assert_eq!(prim.indices().unwrap().count(), 3 * input.len());
        let material = &materials[prim.material().index().unwrap()];
        for (k, &t) in input.iter().enumerate() {
            let t = t as usize;
            seen[t] += 1;
            assert_eq!(from_glb.material_name(t), Some(material.as_str()));
            for c in 0..3 {
                let want = b.triangle_radiance[t][c] as f32;
                assert!((radiance[3 * k + c] - want).abs() <= 1e-6 * want.abs().max(1e-30));
            }
        }
        assert!(prim.get(&gltf::Semantic::Colors(0)).is_some());
    }
    assert!(seen.iter().all(|&n| n == 1), "{seen:?}");

    // A write into a missing directory fails and leaves nothing.
    let missing = dir.path().join("no/such/dir/baked.glb");
    assert!(write_baked_glb(&missing, &from_glb, &patches, &b, 1.0).is_err());
    assert!(!missing.exists());
}
