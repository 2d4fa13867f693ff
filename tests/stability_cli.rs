//! The stability battery's command-line cases: extreme scenes written to OBJ and solved by the
//! binary (finite outputs, the iteration-cap warning, negative radiance accounting, duplicate
//! and zero-area triangles). The library cases are in `tests/stability.rs`.

use std::path::{Path, PathBuf};

use antiradiance::mesh::{build_patches, Patches};
use antiradiance::scene::generated;
use antiradiance::scene::Scene;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::SolverOptions;
use glam::DVec3;
use serde_json::Value;

mod common;
use common::extremes::*;
use common::{run, s};

// ---------------------------------------------------------------------------------------------
// The command line: outputs, warnings, negative radiance

/// Writes `scene` as OBJ + MTL (one material per distinct albedo/emission) into `dir`.
fn write_scene(dir: &Path, scene: &Scene) -> PathBuf {
    let obj = dir.join("scene.obj");
    generated::write_obj(scene, &obj, "stability test scene").unwrap();
    obj
}

/// Parses the per-triangle CSV: (area, emissive, B) per row; every number must be finite.
fn read_csv(path: &Path) -> Vec<(f64, bool, [f64; 3])> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("index,area,emissive,r,g,b"));
    lines
        .map(|line| {
            let f: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            assert!(f.iter().all(|x| x.is_finite()), "{line}");
            (f[1], f[2] == 1.0, [f[3], f[4], f[5]])
        })
        .collect()
}

/// Checks that no output mentions NaN or infinity, every CSV and PLY number is finite, the
/// report's numbers are all present (a NaN would have become null) and the PNG decodes.
fn check_outputs(dir: &Path, triangles: usize) {
    for name in ["out.csv", "out.ply", "out.json"] {
        let text = std::fs::read_to_string(dir.join(name))
            .unwrap()
            .to_lowercase();
        assert!(!text.contains("nan") && !text.contains("inf"), "{name}");
    }
    assert_eq!(read_csv(&dir.join("out.csv")).len(), triangles);
    let ply = std::fs::read_to_string(dir.join("out.ply")).unwrap();
    let body = ply.split("end_header\n").nth(1).unwrap();
    for line in body.lines() {
        for x in line.split_whitespace() {
            let x: f64 = x.parse().unwrap();
            assert!(x.is_finite() && x.abs() <= f32::MAX as f64, "PLY: {line}");
        }
    }
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap();
    fn no_null(v: &Value, at: &str) {
        match v {
            Value::Null => panic!("null at {at}"),
            Value::Object(m) => m.iter().for_each(|(k, x)| no_null(x, &format!("{at}.{k}"))),
            Value::Array(a) => a.iter().for_each(|x| no_null(x, at)),
            _ => {}
        }
    }
    no_null(&report["stats"], "stats");
    no_null(&report["time_seconds"], "time_seconds");
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(dir.join("out.png")).unwrap(),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut pixels).unwrap();
    assert!(pixels.iter().any(|&p| p > 0), "the picture shows something");
}

/// One scene with every extreme at once (wall triangles of area 1e4 next to a 1e-8 one, a pair
/// of 1e6 slivers, a zero-area triangle, a duplicated triangle, a light of radiance 1e30 or
/// 1e-30) through the command line with negatives kept and coarse bins: every output is finite,
/// the duplicate is reported as a warning, and B scales with the emission.
#[test]
fn extreme_scene_outputs_are_finite() {
    let s100 = 2f64.sqrt() * 100.0;
    let base = {
        let mut b = lit_box(s100);
        let c = DVec3::new(0.5, 0.3, 0.5) * s100;
        b.tri(
            [c, c + DVec3::Z * 1.4142e-4, c + DVec3::X * 1.4142e-4],
            0.5,
            0.0,
        );
        let y = 0.2 * s100;
        b.quad(
            [
                DVec3::new(0.0, y, 70.0),
                DVec3::new(0.0, y, 70.0 + 1e-4),
                DVec3::new(100.0, y, 70.0 + 1e-4),
                DVec3::new(100.0, y, 70.0),
            ],
            0.5,
            0.0,
        );
        b.tri([DVec3::ZERO, DVec3::X, DVec3::X * 2.0], 0.5, 0.0); // zero area
        let floor = b.tris[0];
        b.tri([floor[1], floor[2], floor[0]], 0.5, 0.0); // duplicate of triangle 0
        b
    };
    let mut results = Vec::new();
    for light in [1e30, 1e-30] {
        let mut b = base.clone();
        b.emission[2] = [light; 3];
        let scene = b.scene();
        let dir = tempfile::tempdir().unwrap();
        let obj = write_scene(dir.path(), &scene);
        let out = |n: &str| dir.path().join(n);
        let o = run(&[
            "solve",
            s(&obj),
            "--bins",
            "4",
            "--keep-negative",
            "--quiet",
            "--triangles",
            s(&out("out.csv")),
            "--ply",
            s(&out("out.ply")),
            "--png",
            s(&out("out.png")),
            "--report",
            s(&out("out.json")),
            "--width",
            "64",
            "--height",
            "48",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(
            err.contains("warning:") && err.contains("1 triangle repeats an earlier triangle"),
            "{err}"
        );
        check_outputs(dir.path(), scene.len());
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(out("out.json")).unwrap()).unwrap();
        assert!(
            report["warnings"]
                .to_string()
                .contains("repeats an earlier triangle"),
            "{report}"
        );
        let rows = read_csv(&out("out.csv"));
        assert_eq!(
            rows[scene.len() - 1].2,
            rows[0].2,
            "the duplicate reports its twin's B"
        );
        assert_eq!(rows[scene.len() - 2].2, [0.0; 3], "zero area: B = E = 0");
        results.push((light, rows));
    }
    let (big, small) = (&results[0].1, &results[1].1);
    for (t, (a, b)) in big.iter().zip(small).enumerate() {
        for c in 0..3 {
            let (x, y) = (a.2[c] / 1e30, b.2[c] / 1e-30);
            assert!(
                (x - y).abs() <= 1e-9 * y.abs().max(1e-12),
                "triangle {t}: {x} vs {y}"
            );
        }
    }
}

/// The furnace box with albedo 0.999 through the command line: at the default cap a
/// `warning:` line says the solve stopped unconverged, with the residual and how far off it may
/// be (also with --quiet), and the report carries it; with a large enough cap, no warning and
/// B = 1000 within 0.5%.
#[test]
fn iteration_cap_warning_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write_scene(dir.path(), &generated::furnace_box(1.0, 0.999));
    let (csv, report) = (dir.path().join("t.csv"), dir.path().join("r.json"));
    // The dense solver has no extrapolation: plain Jacobi sweeps hit the cap.
    let o = run(&[
        "solve",
        s(&obj),
        "--solver",
        "dense",
        "--quiet",
        "--triangles",
        s(&csv),
        "--report",
        s(&report),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.starts_with("warning: the dense solver stopped at the iteration cap (500 iterations) without converging: last residual "),
        "{err}"
    );
    assert!(err.contains("raise --max-iterations"), "{err}");
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["stats"]["converged"], false);
    assert!(
        r["warnings"]
            .to_string()
            .contains("stopped at the iteration cap"),
        "{r}"
    );
    let b = read_csv(&csv)[0].2[0];
    assert!(b < 500.0, "the capped answer is far from 1000: {b}");

    let o = run(&[
        "solve",
        s(&obj),
        "--quiet",
        "--max-iterations",
        "20000",
        "--triangles",
        s(&csv),
        "--report",
        s(&report),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && err.is_empty(), "{err}");
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["stats"]["converged"], true);
    assert_eq!(r["warnings"], Value::Array(vec![]));
    for (_, _, b) in read_csv(&csv) {
        assert!(rel(b[0], 1000.0) < 0.005, "{b:?}");
    }
}

/// Negative-radiance accounting on the shipped occluder scene, where coarse bins drive a few
/// floor triangles at the shadow's edge negative: with --keep-negative, the report's
/// `negative_patches` is the number of CSV rows with a negative channel and its
/// `negative_fraction` is the negative over the positive area-weighted mass of the CSV; with
/// clamping (the default) no output value is negative, the same negatives are reported, and
/// the clamped CSV is exactly max(kept, 0).
#[test]
fn negative_radiance_accounting() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/occluder.obj");
    let dir = tempfile::tempdir().unwrap();
    // Without exact direct light: the negatives come from antiradiance in coarse bins, and exact
    // direct light removes most of them from this scene's shadow.
    for solver_args in [
        [
            "--solver",
            "hierarchical",
            "--bins",
            "4",
            "--no-direct-light",
        ],
        ["--solver", "dense", "--bins", "8", "--no-direct-light"],
    ] {
        let mut runs = Vec::new();
        for keep in [true, false] {
            let csv = dir.path().join(format!("{keep}.csv"));
            let report = dir.path().join(format!("{keep}.json"));
            let mut args = vec![
                "solve",
                s(&scene),
                "--triangles",
                s(&csv),
                "--report",
                s(&report),
            ];
            args.extend(solver_args);
            if keep {
                args.push("--keep-negative");
            }
            let o = run(&args);
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(o.status.success(), "{err}");
            let r: Value =
                serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
            assert_eq!(
                r["counts"]["patches"], r["counts"]["input_triangles"],
                "one patch per triangle"
            );
            let rows = read_csv(&csv);
            let stats = r["stats"].clone();
            let summary = if keep { "kept" } else { "clamped to 0" };
            assert!(err.contains(&format!("({summary})")), "{err}");
            runs.push((rows, stats));
        }
        let (kept, kept_stats) = &runs[0];
        let (clamped, clamped_stats) = &runs[1];
        let what = solver_args.join(" ");
        let negative_rows = kept.iter().filter(|r| r.2.iter().any(|&x| x < 0.0)).count();
        assert!(
            negative_rows > 0,
            "{what}: the scene must have negative radiance for this test"
        );
        assert_eq!(
            kept_stats["negative_patches"], negative_rows as u64,
            "{what}"
        );
        let (mut neg, mut pos) = (0.0, 0.0);
        for (area, _, b) in kept {
            for &x in b {
                if x < 0.0 {
                    neg -= area * x;
                } else {
                    pos += area * x;
                }
            }
        }
        let fraction = kept_stats["negative_fraction"].as_f64().unwrap();
        assert!(
            rel(fraction, neg / pos) < 1e-9,
            "{what}: reported {fraction}, CSV {}",
            neg / pos
        );
        assert_eq!(
            clamped_stats["negative_patches"], kept_stats["negative_patches"],
            "{what}"
        );
        assert_eq!(
            clamped_stats["negative_fraction"], kept_stats["negative_fraction"],
            "{what}"
        );
        for (t, (k, c)) in kept.iter().zip(clamped).enumerate() {
            assert!(
                c.2.iter().all(|&x| x >= 0.0),
                "{what}: clamped row {t}: {:?}",
                c.2
            );
            assert_eq!(c.2, k.2.map(|x| x.max(0.0)), "{what}: row {t}");
        }
    }
}

/// `Patches` built from a scene with a duplicate: the copy's patches are inactive, and a
/// solution built from any per-patch values reports the twin's value for it.
#[test]
fn duplicate_patches_are_inactive_and_report_their_twin() {
    let mut b = lit_box(1.0);
    let t0 = b.tris[4];
    b.tri([t0[2], t0[0], t0[1]], 0.5, 0.0);
    let scene = b.scene();
    for max_edge in [None, Some(0.3)] {
        let patches: Patches = build_patches(&scene, max_edge);
        let last = scene.len() - 1;
        assert_eq!(patches.twin[last], Some(4));
        let range = patches.first[last] as usize..patches.first[last + 1] as usize;
        assert!(range
            .clone()
            .all(|p| !patches.active[p] && patches.area[p] == 0.0));
        let values: Vec<[f64; 3]> = (0..patches.len()).map(|p| [p as f64 + 1.0; 3]).collect();
        let sol = Solution::from_normalized(&patches, &values, Default::default());
        assert_eq!(sol.triangle_radiance[last], sol.triangle_radiance[4]);
        for p in range {
            assert_eq!(sol.patch_radiance[p], sol.triangle_radiance[4]);
        }
    }
}

/// A zero-area triangle takes no part in transport and keeps B = E (design note), in scene
/// units, with both solvers; here it is the brightest emitter, so its E is not 1 in the
/// solvers' normalized units. (The hierarchical solver itself reported B = 0 for it in the
/// per-triangle result until `Solution::from_normalized` settled inactive patches, and still
/// writes its normalized E into the per-patch result, which `settle_inactive` corrects; the
/// command line always calls it.)
#[test]
fn zero_area_emitter_keeps_b_equal_e() {
    let mut b = lit_box(1.0);
    let t = b.tri(
        [DVec3::splat(0.2), DVec3::splat(0.4), DVec3::splat(0.6)],
        0.5,
        3.0,
    );
    let scene = b.scene();
    assert!(scene.is_degenerate(t));
    let patches = build_patches(&scene, None);
    for (name, mut sol) in solve_both(&scene, &SolverOptions::default()) {
        assert_eq!(sol.triangle_radiance[t], [3.0; 3], "{name}");
        sol.settle_inactive(&patches);
        assert_eq!(sol.patch_radiance[t], [3.0; 3], "{name}");
        assert_eq!(sol.triangle_radiance[t], [3.0; 3], "{name}");
        assert_finite_non_negative(name, &sol);
    }
}
