//! Mesh quality: the variant writers (`antiradiance scene variant`,
//! `antiradiance::scene::variants`) and the generated CAD-like interiors (`antiradiance scene
//! classroom` / `office`, `antiradiance::scene::interiors`); the solver's invariance under
//! re-triangulation is in `tests/mesh_invariance.rs`.
//!
//! Every variant is checked on the shipped Cornell box, written to files and read back: the
//! same area per material, a map that covers every output triangle and gives every input
//! triangle its area back, and the property the kind is about.

// `!(x < max)` is used on purpose: it is also true for NaN, which must fail too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use antiradiance::scene::generated::{furnace_box, write_obj};
use antiradiance::scene::interiors::{
    self, classroom, cos_sin_turn, office, CLASSROOM_TRIANGLES, OFFICE_TRIANGLES, REVERSED_SHARE,
};
use antiradiance::scene::variants::{
    aspect_ratio, make_variant, map_back, map_path, material_text, read_map, write_variant, MapRow,
    Variant, VariantKind, VariantOptions, MAP_CSV_HEADER,
};
use antiradiance::scene::{load_obj, Scene, SceneOptions};
use glam::DVec3;

mod common;
use common::{run, s, stderr};

fn cornell_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.obj")
}

fn cornell() -> Scene {
    load_obj(&cornell_path(), &SceneOptions::default()).unwrap()
}

/// A variant of the Cornell box written to `dir` and read back: (input, the variant in memory,
/// the scene read back, the map read back).
fn written(
    dir: &Path,
    kind: VariantKind,
    amount: Option<f64>,
) -> (Scene, Variant, Scene, Vec<MapRow>) {
    let input = cornell();
    let options = VariantOptions { seed: 1, amount };
    let variant = make_variant(&input, kind, &options).unwrap();
    let out = dir.join(format!("{}.obj", kind.name()));
    let mtl = material_text(&cornell_path()).unwrap();
    write_variant(&variant, &out, &mtl, "test variant", false).unwrap();
    let back = load_obj(&out, &SceneOptions::default()).unwrap();
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    let map = read_map(&map_path(&out)).unwrap();
    (input, variant, back, map)
}

fn normal(scene: &Scene, t: usize) -> DVec3 {
    let [a, b, c] = scene.corners(t);
    (b - a).cross(c - a)
}

/// Total area per material name.
fn area_per_material(scene: &Scene, keep: impl Fn(usize) -> bool) -> HashMap<String, f64> {
    let mut out = HashMap::new();
    for t in (0..scene.len()).filter(|&t| keep(t)) {
        *out.entry(scene.material_name(t).unwrap_or("").to_string())
            .or_insert(0.0) += scene.area(t);
    }
    out
}

fn assert_close(got: f64, want: f64, rel: f64, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs().max(1e-300),
        "{what}: {got} against {want} (relative {:e}, allowed {rel:e})",
        (got - want).abs() / want.abs()
    );
}

/// What every variant must do: read back exactly, the same area per material (`area_tol`
/// relative; twins counted on their original side), materials and orientation kept through
/// the map, every output triangle mapped, every input triangle's area given back exactly.
fn check_common(
    kind: VariantKind,
    amount: Option<f64>,
    area_tol: f64,
) -> (Scene, Scene, Vec<MapRow>) {
    let dir = tempfile::tempdir().unwrap();
    let (input, variant, back, map) = written(dir.path(), kind, amount);
    let what = kind.name();
    // Read back bit for bit, materials included.
    assert_eq!(back.len(), variant.scene.len(), "{what}: triangle count");
    for t in 0..back.len() {
        assert_eq!(
            back.corners(t),
            variant.scene.corners(t),
            "{what}: corners of {t}"
        );
        assert_eq!(
            back.albedo[t], variant.scene.albedo[t],
            "{what}: albedo of {t}"
        );
        assert_eq!(
            back.emission[t], variant.scene.emission[t],
            "{what}: emission of {t}"
        );
        assert_eq!(
            back.material_name(t),
            variant.scene.material_name(t),
            "{what}: material of {t}"
        );
    }
    assert_eq!(map, variant.map, "{what}: the map reads back");
    // Area per material.
    let same_side: HashSet<u32> = map
        .iter()
        .filter(|r| r.same_side)
        .map(|r| r.variant)
        .collect();
    let want = area_per_material(&input, |_| true);
    let got = area_per_material(&back, |t| same_side.contains(&(t as u32)));
    assert_eq!(
        want.len(),
        got.len(),
        "{what}: materials {want:?} / {got:?}"
    );
    for (name, a) in &want {
        assert_close(
            got[name],
            *a,
            area_tol,
            &format!("{what}: area of material {name}"),
        );
    }
    // The map: every output triangle, every input triangle's area, the same material and side.
    let mut per_variant = vec![0.0; back.len()];
    let mut per_original = vec![0.0; input.len()];
    for r in &map {
        let (v, o) = (r.variant as usize, r.original as usize);
        assert!(
            v < back.len() && o < input.len(),
            "{what}: row {r:?} out of range"
        );
        per_variant[v] += r.area;
        if r.same_side {
            per_original[o] += r.area;
        }
        assert_eq!(
            back.albedo[v], input.albedo[o],
            "{what}: albedo through {r:?}"
        );
        assert_eq!(
            back.emission[v], input.emission[o],
            "{what}: emission through {r:?}"
        );
        assert_eq!(
            back.material_name(v),
            input.material_name(o),
            "{what}: material through {r:?}"
        );
        let facing = normal(&back, v).dot(normal(&input, o));
        assert!(
            if r.same_side {
                facing > 0.0
            } else {
                facing < 0.0
            },
            "{what}: {r:?} faces {facing}"
        );
    }
    for (v, &mapped) in per_variant.iter().enumerate() {
        assert!(
            map.iter().any(|r| r.variant as usize == v),
            "{what}: triangle {v} unmapped"
        );
        assert_close(
            mapped,
            back.area(v),
            area_tol,
            &format!("{what}: mapped area of variant triangle {v}"),
        );
    }
    for (o, &given) in per_original.iter().enumerate() {
        assert_close(
            given,
            input.area(o),
            1e-9,
            &format!("{what}: area given back to input triangle {o}"),
        );
    }
    (input, back, map)
}

/// The vertices of `scene` lying strictly inside an edge of a triangle they are not a corner
/// of (T-junctions), within `1e-9` of the edge's length.
fn t_junctions(scene: &Scene) -> usize {
    let key = |p: DVec3| p.to_array().map(|x| (x + 0.0).to_bits());
    let mut points: HashMap<[u64; 3], DVec3> = HashMap::new();
    for t in 0..scene.len() {
        for p in scene.corners(t) {
            points.insert(key(p), p);
        }
    }
    let points: Vec<DVec3> = points.into_values().collect();
    let mut count = 0;
    for t in 0..scene.len() {
        let c = scene.corners(t);
        for e in 0..3 {
            let (a, b) = (c[e], c[(e + 1) % 3]);
            let d = b - a;
            let len2 = d.length_squared();
            for &p in &points {
                let s = (p - a).dot(d) / len2;
                if s > 1e-9 && s < 1.0 - 1e-9 && (p - (a + d * s)).length() <= 1e-9 * len2.sqrt() {
                    count += 1;
                }
            }
        }
    }
    count
}

// ---------------------------------------------------------------------------------------------
// Variant writers

#[test]
fn fan_keeps_areas_and_maps_every_triangle() {
    check_common(VariantKind::Fan, None, 1e-9);
}

#[test]
fn fan_produces_triangles_of_higher_aspect_ratio() {
    let (input, back, _) = check_common(VariantKind::Fan, None, 1e-9);
    assert_eq!(
        back.len(),
        input.len() * 15,
        "2k - 1 = 15 slivers per triangle"
    );
    let mean = |s: &Scene| {
        let total: f64 = (0..s.len()).map(|t| s.area(t)).sum();
        (0..s.len())
            .map(|t| s.area(t) * aspect_ratio(&s.corners(t)))
            .sum::<f64>()
            / total
    };
    let max = |s: &Scene| {
        (0..s.len())
            .map(|t| aspect_ratio(&s.corners(t)))
            .fold(0.0, f64::max)
    };
    let (before, after) = (mean(&input), mean(&back));
    assert!(
        after > 4.0 * before,
        "area-weighted mean aspect ratio {before} -> {after}"
    );
    assert!(
        max(&back) > 4.0 * max(&input),
        "largest aspect ratio {} -> {}",
        max(&input),
        max(&back)
    );
    assert_eq!(
        t_junctions(&back),
        t_junctions(&input),
        "fan adds no T-junction"
    );
}

#[test]
fn random_keeps_areas_and_maps_every_triangle() {
    let (input, back, _) = check_common(VariantKind::Random, None, 1e-9);
    assert!(back.len() > 5 * input.len(), "{} triangles", back.len());
    // On a conforming mesh (edges meet edge to edge) it adds no T-junction.
    let furnace = furnace_box(1.0, 0.5);
    assert_eq!(t_junctions(&furnace), 0);
    let v = make_variant(&furnace, VariantKind::Random, &VariantOptions::default()).unwrap();
    assert!(v.scene.len() > 5 * furnace.len());
    assert_eq!(t_junctions(&v.scene), 0, "random adds no T-junction");
    // Irregular: the pieces of one input triangle have many different areas.
    let areas: HashSet<u64> = (0..back.len()).map(|t| back.area(t).to_bits()).collect();
    assert!(
        areas.len() > back.len() / 2,
        "{} distinct areas among {}",
        areas.len(),
        back.len()
    );
}

#[test]
fn random_is_seeded() {
    let input = cornell();
    let with = |seed| {
        make_variant(
            &input,
            VariantKind::Random,
            &VariantOptions { seed, amount: None },
        )
        .unwrap()
    };
    let (a, b, c) = (with(1), with(1), with(2));
    assert_eq!(a.scene.positions, b.scene.positions);
    assert_eq!(a.map, b.map);
    assert_ne!(a.scene.positions, c.scene.positions);
}

#[test]
fn jitter_moves_no_vertex_more_than_the_amount() {
    let amount = 1e-6;
    // Each triangle's area moves by at most its perimeter times the amount (to first order).
    let input = cornell();
    let bound = (0..input.len())
        .map(|t| {
            let c = input.corners(t);
            (0..3)
                .map(|i| (c[(i + 1) % 3] - c[i]).length())
                .sum::<f64>()
                * amount
                / input.area(t)
        })
        .fold(0.0, f64::max);
    let (input, back, map) = check_common(VariantKind::Jitter, Some(amount), 2.0 * bound);
    assert_eq!(back.len(), input.len());
    let mut moved_to: HashMap<[u64; 3], DVec3> = HashMap::new();
    let mut moved = 0;
    for r in &map {
        let (before, after) = (
            input.corners(r.original as usize),
            back.corners(r.variant as usize),
        );
        for i in 0..3 {
            let d = (after[i] - before[i]).length();
            assert!(d <= amount, "vertex {:?} moved by {d}", before[i]);
            moved += (d > 0.0) as usize;
            let k = before[i].to_array().map(f64::to_bits);
            let first = *moved_to.entry(k).or_insert(after[i]);
            assert_eq!(first, after[i], "a shared vertex moved consistently");
        }
    }
    assert!(moved > 3 * input.len() / 2, "{moved} corners moved");
}

#[test]
fn translate_is_exact() {
    for amount in [1e3, 1e5] {
        let (input, back, map) = check_common(VariantKind::Translate, Some(amount), 1e-9);
        assert_eq!(back.len(), input.len());
        for r in &map {
            let (before, after) = (
                input.corners(r.original as usize),
                back.corners(r.variant as usize),
            );
            assert_eq!(
                after,
                before.map(|p| p + DVec3::splat(amount)),
                "{amount}: {r:?}"
            );
        }
    }
}

#[test]
fn twins_double_the_count_with_reversed_normals() {
    let (input, back, map) = check_common(VariantKind::Twins, None, 1e-9);
    assert_eq!(back.len(), 2 * input.len());
    assert_eq!(map.len(), back.len());
    for o in 0..input.len() {
        let rows: Vec<&MapRow> = map.iter().filter(|r| r.original as usize == o).collect();
        assert_eq!(rows.len(), 2, "two copies of {o}");
        assert_eq!(rows.iter().filter(|r| r.same_side).count(), 1);
        let [a, b] = [rows[0], rows[1]].map(|r| normal(&back, r.variant as usize));
        assert_close(a.dot(b), -a.length_squared(), 1e-9, "opposite normals");
    }
    // Back-to-back copies are not duplicates: the loader gave no warning.
    assert!(back.duplicates().iter().all(Option::is_none));
}

#[test]
fn tjunction_puts_vertices_on_other_triangles_edges() {
    let (input, back, _) = check_common(VariantKind::Tjunction, None, 1e-9);
    assert!(back.len() > input.len());
    let (before, after) = (t_junctions(&input), t_junctions(&back));
    assert!(after >= before + 10, "T-junctions {before} -> {after}");
    let furnace = furnace_box(1.0, 0.5);
    let v = make_variant(&furnace, VariantKind::Tjunction, &VariantOptions::default()).unwrap();
    assert!(t_junctions(&v.scene) > 0, "T-junctions on the furnace box");
}

#[test]
fn huge_tiny_has_a_huge_triangle_beside_thousands_of_tiny_ones() {
    let (input, back, map) = check_common(VariantKind::HugeTiny, None, 1e-9);
    let areas: Vec<f64> = (0..back.len()).map(|t| back.area(t)).collect();
    let largest = areas.iter().cloned().fold(0.0, f64::max);
    let tiny = areas.iter().filter(|&&a| a < 1e-3 * largest).count();
    assert!(tiny >= 4000, "{tiny} triangles under 1e-3 of the largest");
    let input_largest = (0..input.len()).map(|t| input.area(t)).fold(0.0, f64::max);
    assert!(largest >= input_largest, "{largest} < {input_largest}");
    // The largest covers what it replaced: its rows sum to its area.
    let v = areas.iter().position(|&a| a == largest).unwrap() as u32;
    let covered: f64 = map.iter().filter(|r| r.variant == v).map(|r| r.area).sum();
    assert_close(covered, largest, 1e-9, "the largest triangle's rows");
}

#[test]
fn huge_tiny_merges_a_flat_region_into_few_triangles() {
    // A floor of 8 x 8 cells (128 triangles) under a small box, lit from above.
    let mut corners = Vec::new();
    for j in 0..8 {
        for i in 0..8 {
            let (x0, z0, x1, z1) = (i as f64, j as f64, i as f64 + 1.0, j as f64 + 1.0);
            let q = [
                DVec3::new(x0, 0.0, z0),
                DVec3::new(x0, 0.0, z1),
                DVec3::new(x1, 0.0, z1),
                DVec3::new(x1, 0.0, z0),
            ];
            corners.push([q[0], q[1], q[2]]);
            corners.push([q[0], q[2], q[3]]);
        }
    }
    let floor = corners.len();
    let b = |x, y, z| DVec3::new(x, y, z);
    corners.push([b(3.0, 0.5, 3.0), b(3.0, 0.5, 4.0), b(4.0, 0.5, 4.0)]);
    corners.push([b(3.0, 0.5, 3.0), b(4.0, 0.5, 4.0), b(4.0, 0.5, 3.0)]);
    corners.push([b(2.0, 3.0, 2.0), b(6.0, 3.0, 2.0), b(6.0, 3.0, 6.0)]);
    let mut albedo = vec![[0.5; 3]; corners.len()];
    let mut emission = vec![[0.0; 3]; corners.len()];
    albedo[floor + 2] = [0.0; 3];
    emission[floor + 2] = [1.0; 3];
    let scene = Scene::from_triangles(&corners, &albedo, &emission);
    let v = make_variant(
        &scene,
        VariantKind::HugeTiny,
        &VariantOptions {
            seed: 1,
            amount: Some(100.0),
        },
    )
    .unwrap();
    let merged: HashSet<u32> = v
        .map
        .iter()
        .filter(|r| (r.original as usize) < floor)
        .map(|r| r.variant)
        .collect();
    assert_eq!(
        merged.len(),
        2,
        "the 8 x 8 floor as two triangles: {}",
        v.note
    );
    let floor_area: f64 = merged.iter().map(|&t| v.scene.area(t as usize)).sum();
    assert_close(floor_area, 64.0, 1e-12, "floor area");
    // The plate (the object nearest to the floor, at most half its size) in >= 100 pieces.
    let plate = v
        .map
        .iter()
        .filter(|r| r.original as usize == floor || r.original as usize == floor + 1)
        .count();
    assert!(plate >= 100, "{plate} plate pieces");
    assert_eq!(
        v.map
            .iter()
            .filter(|r| r.original as usize == floor + 2)
            .count(),
        1,
        "the light is kept"
    );
}

#[test]
fn variants_keep_degenerate_triangles_and_materials_without_mtl() {
    // No MTL: scene options decide albedo and emitters; the variant keeps the emitters as
    // materials and the albedo as the scene option.
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("plain.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 4 0 0\nv 4 0 4\nv 0 0 4\nv 1 3 1\nv 3 3 1\nv 3 3 3\nv 1 3 3\nv 5 0 0\nv 6 0 0\nv 7 0 0\n\
         f 1 4 3 2\nf 5 6 7 8\nf 9 10 11\n",
    )
    .unwrap();
    let options = SceneOptions {
        emit_above: Some(2.0),
        default_albedo: 0.6,
        ..SceneOptions::default()
    };
    let input = load_obj(&obj, &options).unwrap();
    assert_eq!(input.degenerate_count(), 1);
    for kind in VariantKind::ALL {
        let out = dir.path().join(format!("{}.obj", kind.name()));
        let o = run(&[
            "scene",
            "variant",
            kind.name(),
            s(&obj),
            "--out",
            s(&out),
            "--emit-above",
            "2",
        ]);
        assert!(o.status.success(), "{}: {}", kind.name(), stderr(&o));
        // The rule's emitters are written as materials with their emission: read back without
        // the rule, the variant has the input's emitters (a translated one too).
        let back = load_obj(
            &out,
            &SceneOptions {
                emit_above: None,
                ..options.clone()
            },
        )
        .unwrap();
        assert!(
            back.warnings.is_empty(),
            "{}: {:?}",
            kind.name(),
            back.warnings
        );
        let emitting = |s: &Scene| {
            (0..s.len())
                .filter(|&t| s.is_emitter(t))
                .map(|t| s.area(t))
                .sum::<f64>()
        };
        let factor = if kind == VariantKind::Twins { 2.0 } else { 1.0 };
        // Jitter moves the light's corners by up to 1e-6 (its area by about 1e-6 relative).
        let tol = if kind == VariantKind::Jitter {
            1e-5
        } else {
            1e-9
        };
        assert_close(
            emitting(&back),
            factor * emitting(&input),
            tol,
            &format!(
                "{}: emitting area of the --emit-above emitters",
                kind.name()
            ),
        );
        assert!(
            back.albedo.iter().all(|a| *a == [0.6; 3]),
            "{}: --albedo applies",
            kind.name()
        );
        let map = read_map(&map_path(&out)).unwrap();
        assert!(
            map.iter().any(|r| r.original == 4),
            "{}: the degenerate triangle is mapped",
            kind.name()
        );
    }
}

#[test]
fn scene_variant_command_writes_obj_mtl_and_map() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fan.obj");
    let o = run(&[
        "scene",
        "variant",
        "fan",
        s(&cornell_path()),
        "--out",
        s(&out),
        "--amount",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("230 triangles from 46"),
        "{}",
        stderr(&o)
    );
    let map_text = std::fs::read_to_string(dir.path().join("fan.map.csv")).unwrap();
    assert_eq!(map_text.lines().next(), Some(MAP_CSV_HEADER));
    assert_eq!(map_text.lines().count(), 231);
    let mtl = std::fs::read_to_string(dir.path().join("fan.mtl")).unwrap();
    assert!(mtl.contains(&std::fs::read_to_string(cornell_path().with_extension("mtl")).unwrap()));
    // The same files as the library writes.
    let input = cornell();
    let v = make_variant(
        &input,
        VariantKind::Fan,
        &VariantOptions {
            seed: 1,
            amount: Some(3.0),
        },
    )
    .unwrap();
    assert_eq!(read_map(&map_path(&out)).unwrap(), v.map);
    // Mapping back a result that is its input triangle's index gives the index back.
    let mut b = vec![[0.0; 3]; v.scene.len()];
    for r in &v.map {
        b[r.variant as usize] = [r.original as f64; 3];
    }
    let mean = map_back(&v.map, input.len(), &b).unwrap();
    for (o, m) in mean.iter().enumerate() {
        assert!((m[0] - o as f64).abs() <= 1e-12 * o as f64, "{o}: {m:?}");
    }
    assert!(map_back(&v.map, 3, &b).is_err());
}

#[test]
fn scene_variant_bad_input_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v.obj");
    let missing = dir.path().join("missing.obj");
    let cb = cornell_path();
    let cases: Vec<(Vec<&str>, &str, i32)> = vec![
        (vec!["fan", s(&missing)], "missing.obj", 1),
        (vec!["fan", s(&cb), "--amount", "0"], "--amount 0", 1),
        (vec!["fan", s(&cb), "--amount", "2.5"], "whole number", 1),
        (vec!["twins", s(&cb), "--amount", "1"], "does not apply", 1),
        (vec!["tjunction", s(&cb), "--amount", "1.5"], "(0, 1]", 1),
        (vec!["jitter", s(&cb), "--amount", "-1"], ">= 0", 1),
        (vec!["fan", s(&cb), "--amount", "1001"], "1..=1000", 1),
        (vec!["sliver", s(&cb)], "invalid value", 2),
    ];
    for (args, message, code) in cases {
        let mut all = vec!["scene", "variant"];
        all.extend(args.iter());
        all.extend(["--out", s(&out)]);
        let o = run(&all);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(code), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.starts_with("error: ") && err.contains(message),
            "{args:?}: {err}"
        );
        assert!(!out.exists() && !map_path(&out).exists() && !out.with_extension("mtl").exists());
    }
    let o = run(&[
        "scene",
        "variant",
        "fan",
        s(&cb),
        "--out",
        s(&dir.path().join("v.mtl")),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
}

// ---------------------------------------------------------------------------------------------
// Generated interiors

#[test]
fn cos_sin_turn_matches_the_standard_library() {
    for n in [1, 3, 4, 6, 8, 10, 12, 16, 24, 360, 1000] {
        for i in 0..n {
            let (c, s) = cos_sin_turn(i, n);
            let theta = std::f64::consts::TAU * i as f64 / n as f64;
            assert!(
                (c - theta.cos()).abs() < 1e-15 && (s - theta.sin()).abs() < 1e-15,
                "{i}/{n}: {c} {s}"
            );
        }
    }
}

fn check_interior(
    what: &str,
    interior: &interiors::Interior,
    range: std::ops::RangeInclusive<usize>,
) {
    let scene = &interior.scene;
    assert!(
        range.contains(&scene.len()),
        "{what}: {} triangles outside {range:?}",
        scene.len()
    );
    assert_eq!(scene.degenerate_count(), 0, "{what}: every fan is valid");
    assert!(
        scene.duplicates().iter().all(Option::is_none),
        "{what}: no repeated triangle"
    );
    assert!(scene.emitter_count() > 0, "{what}: emitters");
    let share = interior.reversed_polygons as f64 / interior.polygons as f64;
    assert!(
        (share - REVERSED_SHARE).abs() < 0.05,
        "{what}: {share} of the polygons reversed"
    );
    assert_eq!(interior.reversed.len(), scene.len());
    for t in (0..scene.len()).filter(|&t| scene.is_emitter(t)) {
        assert!(!interior.reversed[t], "{what}: emitter {t} reversed");
    }
    // The floor: its triangles face up unless their polygon was reversed.
    let floor: Vec<usize> = (0..scene.len())
        .filter(|&t| scene.material_name(t) == Some("floor"))
        .collect();
    assert!(!floor.is_empty());
    for &t in &floor {
        assert!(scene.corners(t).iter().all(|p| p.y == 0.0));
        assert_eq!(
            normal(scene, t).y < 0.0,
            interior.reversed[t],
            "{what}: floor triangle {t}"
        );
    }
    assert!(
        interior.reversed.iter().any(|&r| r) && interior.reversed.iter().any(|&r| !r),
        "{what}: some polygons reversed, not all"
    );
    // Slivers, as CAD exports have: the walls' fans.
    let worst = (0..scene.len())
        .map(|t| aspect_ratio(&scene.corners(t)))
        .fold(0.0, f64::max);
    assert!(worst > 100.0, "{what}: largest aspect ratio {worst}");
    // Written and read back: the lights are Ke, so default options light the scene.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(format!("{what}.obj"));
    write_obj(scene, &path, what).unwrap();
    let back = load_obj(&path, &SceneOptions::default()).unwrap();
    assert!(back.warnings.is_empty(), "{what}: {:?}", back.warnings);
    assert_eq!(back.len(), scene.len());
    assert_eq!(back.emitter_count(), scene.emitter_count());
}

#[test]
fn classroom_is_in_range_lit_and_partly_reversed() {
    let room = classroom(1);
    check_interior("classroom", &room, CLASSROOM_TRIANGLES);
    assert!((8_000..=12_000).contains(&room.scene.len()));
    let tubes = (0..room.scene.len())
        .filter(|&t| room.scene.material_name(t) == Some("tube"))
        .count();
    assert_eq!(
        tubes,
        12 * (2 * 16 + 2 * 14),
        "twelve 16-sided tubes with caps"
    );
    for seed in [2, 3] {
        check_interior("classroom", &classroom(seed), CLASSROOM_TRIANGLES);
    }
}

#[test]
fn office_is_in_range_lit_and_partly_reversed() {
    let room = office(1);
    check_interior("office", &room, OFFICE_TRIANGLES);
    let slats = (0..room.scene.len())
        .filter(|&t| room.scene.material_name(t) == Some("slat"))
        .count();
    assert_eq!(
        slats,
        (66 + 2) * 12,
        "66 slats and two rails, boxes of 12 triangles"
    );
    for name in ["sky", "bulb"] {
        assert!(
            (0..room.scene.len())
                .any(|t| room.scene.material_name(t) == Some(name) && room.scene.is_emitter(t)),
            "{name} emits"
        );
    }
    for seed in [2, 3] {
        check_interior("office", &office(seed), OFFICE_TRIANGLES);
    }
}

#[test]
fn classroom_and_office_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    for what in ["classroom", "office"] {
        // Each file in its own directory under the same name (the OBJ file names its MTL).
        let file = |sub: &str, seed: &str| {
            let sub = dir.path().join(sub);
            std::fs::create_dir_all(&sub).unwrap();
            let out = sub.join(format!("{what}.obj"));
            let o = run(&["scene", what, "--seed", seed, "--out", s(&out), "--quiet"]);
            assert!(o.status.success(), "{what}: {}", stderr(&o));
            assert!(stderr(&o).is_empty());
            (
                std::fs::read(&out).unwrap(),
                std::fs::read(out.with_extension("mtl")).unwrap(),
            )
        };
        let (a, b, c) = (file("a", "7"), file("b", "7"), file("c", "8"));
        assert!(a == b, "{what}: the same seed gives the same files");
        assert!(a.0 != c.0, "{what}: another seed reverses other polygons");
        let loaded = load_obj(
            &dir.path().join("a").join(format!("{what}.obj")),
            &SceneOptions::default(),
        )
        .unwrap();
        let generated = if what == "classroom" {
            classroom(7)
        } else {
            office(7)
        };
        assert_eq!(loaded.len(), generated.scene.len());
        for t in 0..loaded.len() {
            assert_eq!(
                loaded.corners(t),
                generated.scene.corners(t),
                "{what}: corners of {t}"
            );
        }
    }
}

/// `docs/mesh_quality.py` on a strip of two original triangles (radiance 1 and 3, area 1 each):
/// `error` compares per original triangle, `common` on the groups the map joins. Skipped when
/// python3 is absent.
#[test]
fn mesh_quality_script_compares_a_coarsened_variant_at_the_common_resolution() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let original = write(
        "original.csv",
        "index,area,emissive,r,g,b\n0,1,0,1,1,1\n1,1,0,3,3,3\n",
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/mesh_quality.py");
    let measure = |how: &str, variant: &Path, map: &Path| -> Option<f64> {
        let out = std::process::Command::new("python3")
            .arg(&script)
            .args([how])
            .args([&original, variant, map])
            .output()
            .ok()?;
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        Some(
            String::from_utf8(out.stdout)
                .unwrap()
                .trim()
                .parse()
                .unwrap(),
        )
    };
    // Coarsened: one variant triangle over both originals, at their mean (2).
    let coarse = write("coarse.csv", "index,area,emissive,r,g,b\n0,2,0,2,2,2\n");
    let coarse_map = write(
        "coarse.map.csv",
        "variant_index,original_index,area,facing\n0,0,1,1\n0,1,1,1\n",
    );
    let Some(per_triangle) = measure("error", &coarse, &coarse_map) else {
        eprintln!("skipped: python3 not found");
        return;
    };
    // |2 - 1| + |2 - 3| over 1 + 3.
    assert!((per_triangle - 0.5).abs() < 1e-9, "{per_triangle}");
    let common = measure("common", &coarse, &coarse_map).unwrap();
    assert!(common.abs() < 1e-12, "{common}");
    // Refined: each original cut in two, one piece of the second 10% off; both measures agree.
    let fine = write(
        "fine.csv",
        "index,area,emissive,r,g,b\n0,0.5,0,1,1,1\n1,0.5,0,1,1,1\n2,0.5,0,3,3,3\n3,0.5,0,3.3,3.3,3.3\n",
    );
    let fine_map = write(
        "fine.map.csv",
        "variant_index,original_index,area,facing\n0,0,0.5,1\n1,0,0.5,1\n2,1,0.5,1\n3,1,0.5,1\n",
    );
    let (a, b) = (
        measure("error", &fine, &fine_map).unwrap(),
        measure("common", &fine, &fine_map).unwrap(),
    );
    // |3.15 - 3| over 4.
    assert!(
        (a - 0.0375).abs() < 1e-9 && (b - a).abs() < 1e-12,
        "{a} {b}"
    );
}
