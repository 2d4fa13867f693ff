//! The `sweep` command end to end (CSV, SVG, one-line errors) and exact direct light
//! (`--direct-light`): the furnace, an analytic form factor, a full umbra, the occluder scene
//! against the path tracer, and hostile geometry that must never produce NaN.

use std::path::{Path, PathBuf};

use antiradiance::mesh::{build_patches, Patches};
use antiradiance::progress::Progress;
use antiradiance::reference::{solve_reference, ReferenceOptions};
use antiradiance::scene::generated;
use antiradiance::scene::Scene;
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::direct::{solve_dense_direct, solve_hierarchical_direct};
use antiradiance::solve::hierarchical::solve_hierarchical;
use antiradiance::solve::solution::error_against as error; // the design note's error, per input triangle
use antiradiance::solve::solution::Solution;
use antiradiance::solve::SolverOptions;

/// The header of `sweep --csv` (the format the docs describe).
const CSV_HEADER: &str = "run,preset,solver,epsilon,bins,tol,max_iterations,direct_light,\
seconds,cpu_seconds,iterations,converged,residual,links,peak_memory_delta_bytes,negative_fraction,\
error,pareto";
use glam::DVec3;

mod common;
use common::{run, s, stderr};

// ---------------------------------------------------------------------------------------------
// Helpers

fn occluder_obj() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/occluder.obj")
}

fn hidden() -> Progress {
    Progress::hidden()
}

/// The two triangles of the quad a, b, c, d (counter-clockwise seen from its front).
fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> [[DVec3; 3]; 2] {
    [[a, b, c], [a, c, d]]
}

/// A horizontal square of side `side` centred on (0, y, 0), facing up or down.
fn square(y: f64, side: f64, up: bool) -> [[DVec3; 3]; 2] {
    let h = side / 2.0;
    let (a, b, c, d) = (
        DVec3::new(-h, y, -h),
        DVec3::new(-h, y, h),
        DVec3::new(h, y, h),
        DVec3::new(h, y, -h),
    );
    // a, b, c, d run counter-clockwise seen from above.
    if up {
        quad(a, b, c, d)
    } else {
        quad(a, d, c, b)
    }
}

/// A scene of squares: (y, side, facing up, albedo, emission).
fn squares(parts: &[(f64, f64, bool, f64, f64)]) -> Scene {
    let mut corners = Vec::new();
    let mut albedo = Vec::new();
    let mut emission = Vec::new();
    for &(y, side, up, rho, e) in parts {
        for tri in square(y, side, up) {
            corners.push(tri);
            albedo.push([rho; 3]);
            emission.push([e; 3]);
        }
    }
    Scene::from_triangles(&corners, &albedo, &emission)
}

/// Area-weighted mean of B over input triangles `range` (grey scenes: channel 0).
fn mean_b(scene: &Scene, solution: &Solution, range: std::ops::Range<usize>) -> f64 {
    let area: f64 = range.clone().map(|t| scene.area(t)).sum();
    range
        .map(|t| scene.area(t) * solution.triangle_radiance[t][0])
        .sum::<f64>()
        / area
}

fn both_direct(patches: &Patches, options: &SolverOptions) -> [(&'static str, Solution); 2] {
    [
        (
            "hierarchical",
            solve_hierarchical_direct(patches, options, &hidden()).unwrap(),
        ),
        (
            "dense",
            solve_dense_direct(patches, options, &hidden()).unwrap(),
        ),
    ]
}

// ---------------------------------------------------------------------------------------------
// The sweep command

/// Reads a sweep CSV: header and rows split on commas.
fn read_csv(path: &Path) -> (String, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).expect("sweep CSV written");
    let mut lines = text.lines();
    let header = lines.next().expect("header").to_string();
    let rows = lines
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    (header, rows)
}

#[test]
fn sweep_writes_one_row_per_run_and_a_plot() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, svg, reference) = (
        dir.path().join("sweep.csv"),
        dir.path().join("sweep.svg"),
        dir.path().join("ref.csv"),
    );
    let scene = occluder_obj();
    let out = run(&[
        "sweep",
        s(&scene),
        "--reference-spp",
        "16",
        "--save-reference",
        s(&reference),
        "--epsilon",
        "0.25,1",
        "--bins",
        "4,6",
        "--direct-light",
        "off,on",
        "--csv",
        s(&csv),
        "--svg",
        s(&svg),
        "--time-axis",
        "cpu",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (header, rows) = read_csv(&csv);
    assert_eq!(header, CSV_HEADER);
    let columns: Vec<&str> = header.split(',').collect();
    let col = |name: &str| columns.iter().position(|c| *c == name).unwrap();
    assert_eq!(rows.len(), 2 * 2 * 2, "epsilon x bins x direct light");
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), columns.len(), "row {i}: {row:?}");
        assert_eq!(row[col("run")], (i + 1).to_string());
        assert_eq!(row[col("solver")], "hierarchical");
        let error: f64 = row[col("error")].parse().unwrap();
        assert!(error > 0.0 && error < 0.5, "row {i}: error {error}");
        let seconds: f64 = row[col("seconds")].parse().unwrap();
        assert!(seconds > 0.0 && seconds.is_finite());
        let cpu: f64 = row[col("cpu_seconds")].parse().unwrap();
        assert!(cpu >= 0.0 && cpu.is_finite());
        assert!(row[col("iterations")].parse::<usize>().unwrap() >= 1);
        assert!(row[col("links")].parse::<u64>().unwrap() > 0);
    }
    // Every combination appears once.
    let mut combos: Vec<(String, String, String)> = rows
        .iter()
        .map(|r| {
            (
                r[col("epsilon")].clone(),
                r[col("bins")].clone(),
                r[col("direct_light")].clone(),
            )
        })
        .collect();
    combos.sort();
    combos.dedup();
    assert_eq!(combos.len(), 8, "{combos:?}");
    // The fastest (in CPU time, the chosen axis) and the most accurate runs are on the front
    // (ties broken by the other).
    let value = |r: &Vec<String>, c: &str| r[col(c)].parse::<f64>().unwrap();
    let by = |first: &'static str, second: &'static str| {
        move |a: &&Vec<String>, b: &&Vec<String>| {
            value(a, first)
                .total_cmp(&value(b, first))
                .then(value(a, second).total_cmp(&value(b, second)))
        }
    };
    let fastest = rows.iter().min_by(by("cpu_seconds", "error")).unwrap();
    let best = rows.iter().min_by(by("error", "cpu_seconds")).unwrap();
    assert_eq!(fastest[col("pareto")], "1");
    assert_eq!(best[col("pareto")], "1");
    let plot = std::fs::read_to_string(&svg).expect("SVG written");
    assert!(plot.starts_with("<svg"), "{}", &plot[..plot.len().min(80)]);
    assert!(plot.contains("Pareto front") && plot.contains("direct light on"));
    assert!(plot.matches("<circle").count() >= rows.len());
    let saved = antiradiance::output::read_triangles_csv(&reference).unwrap();
    assert_eq!(saved.len(), generated::occluder_scene().len());

    // The saved reference feeds a second sweep: dense, one run, no epsilon column value.
    let csv2 = dir.path().join("dense.csv");
    let out = run(&[
        "sweep",
        s(&scene),
        "--reference",
        s(&reference),
        "--solver",
        "dense",
        "--bins",
        "4",
        "--direct-light",
        "on",
        "--csv",
        s(&csv2),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("Pareto front"), "{stdout}");
    let (_, rows) = read_csv(&csv2);
    assert_eq!(rows.len(), 1, "dense ignores the epsilon list");
    assert_eq!(rows[0][col("epsilon")], "");
    assert_eq!(rows[0][col("direct_light")], "1");
    assert_eq!(rows[0][col("pareto")], "1");
}

#[test]
fn bad_sweep_arguments_fail_with_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = occluder_obj();
    let csv = dir.path().join("out.csv");
    let svg = dir.path().join("out.svg");
    let short_ref = dir.path().join("short.csv");
    std::fs::write(&short_ref, "index,area,emissive,r,g,b\n0,1,0,0.5,0.5,0.5\n").unwrap();
    let missing_dir_svg = dir.path().join("no/such/dir/out.svg");
    let many: String = (1..=11)
        .map(|i| format!("{}e-4", i))
        .collect::<Vec<_>>()
        .join(",");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--reference-spp", "4", "--bins", "6,,8"], "--bins"),
        (vec!["--reference-spp", "4", "--bins", "six"], "--bins"),
        (vec!["--reference-spp", "4", "--epsilon", "-1"], "--epsilon"),
        (vec!["--reference-spp", "4", "--tol", "2"], "--tol"),
        (
            vec!["--reference-spp", "4", "--direct-light", "maybe"],
            "--direct-light",
        ),
        (
            vec!["--reference-spp", "4", "--preset", "quick"],
            "--preset",
        ),
        (vec!["--reference-spp", "4", "--repeat", "0"], "--repeat"),
        (vec!["--reference-spp", "0"], "--reference-spp"),
        (vec![], "reference"),
        (
            vec!["--reference", s(&short_ref), "--reference-spp", "4"],
            "not both",
        ),
        (vec!["--reference", "/no/such/ref.csv"], "/no/such/ref.csv"),
        (vec!["--reference", s(&short_ref)], "rows"),
        (
            vec!["--reference-spp", "4", "--svg", s(&missing_dir_svg)],
            "does not exist",
        ),
        (
            vec![
                "--reference-spp",
                "4",
                "--tol",
                &many,
                "--epsilon",
                "0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1",
                "--bins",
                "2,3,4,5,6,7,8,9,10,11",
            ],
            "runs",
        ),
    ];
    for (extra, expect) in cases {
        let mut args = vec!["sweep", s(&scene), "--csv", s(&csv), "--svg", s(&svg)];
        if extra.contains(&"--svg") {
            args.truncate(4);
        }
        args.extend(extra.iter().copied());
        let out = run(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("error: "), "{args:?}: {err}");
        assert!(
            err.contains(expect),
            "{args:?}: expected '{expect}' in {err}"
        );
        assert!(!csv.exists() && !svg.exists(), "{args:?} wrote output");
    }
    // A missing --csv is a malformed command line (exit 2), also one line.
    let out = run(&["sweep", s(&scene), "--reference-spp", "4"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_eq!(stderr(&out).lines().count(), 1, "{}", stderr(&out));
}

#[test]
fn direct_light_flag_reaches_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("r.json");
    let out = run(&[
        "solve",
        s(&occluder_obj()),
        "--direct-light",
        "--report",
        s(&report),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(
        json["parameters"]["solver_options"]["direct_light"],
        serde_json::Value::Bool(true)
    );
}

// ---------------------------------------------------------------------------------------------
// Exact direct light

#[test]
fn direct_light_furnace_keeps_b_equal_e_over_one_minus_rho() {
    for (emission, albedo) in [(1.0, 0.5), (2.0, 0.8)] {
        let scene = generated::furnace_box(emission, albedo);
        let patches = build_patches(&scene, Some(0.25));
        let expect = emission / (1.0 - albedo);
        let options = SolverOptions {
            tol: 1e-5,
            direct_light: true,
            ..SolverOptions::default()
        };
        for (name, solution) in both_direct(&patches, &options) {
            assert!(solution.stats.converged, "{name}");
            for b in &solution.triangle_radiance {
                for &x in b {
                    assert!(
                        (x - expect).abs() < 0.01 * expect,
                        "{name}: B = {x}, expected {expect} (albedo {albedo})"
                    );
                }
            }
        }
    }
}

#[test]
fn direct_light_matches_the_parallel_squares_form_factor() {
    // A black unit-square emitter facing down 1 above a unit-square receiver facing up:
    // B = rho E F with F = 0.19982, and nothing else reaches the receiver.
    let (rho, e) = (0.5, 1.0);
    let scene = squares(&[(1.0, 1.0, false, 0.0, e), (0.0, 1.0, true, rho, 0.0)]);
    let patches = build_patches(&scene, None);
    let expect = rho * e * 0.19982;
    let options = SolverOptions::default();
    for (name, solution) in both_direct(&patches, &options) {
        let b = mean_b(&scene, &solution, 2..4);
        eprintln!("parallel squares, {name}: B = {b:.6}, expected {expect:.6}");
        assert!(
            (b - expect).abs() < 0.005 * expect,
            "{name}: {b} vs {expect}"
        );
    }
}

#[test]
fn direct_light_leaves_a_full_umbra_black() {
    // Emitter (facing down) at y = 2, a wide plate facing up at y = 1, a receiver at y = 0: no
    // path of light reaches the receiver (the plate's top reflects upwards only).
    let scene = squares(&[
        (2.0, 1.0, false, 0.0, 1.0),
        (1.0, 3.0, true, 0.5, 0.0),
        (0.0, 1.0, true, 0.5, 0.0),
    ]);
    let patches = build_patches(&scene, None);
    let options = SolverOptions {
        clamp_negative: false,
        ..SolverOptions::default()
    };
    let without = mean_b(
        &scene,
        &solve_hierarchical(&patches, &options, &hidden()).unwrap(),
        4..6,
    );
    for (name, solution) in both_direct(&patches, &options) {
        let b = mean_b(&scene, &solution, 4..6);
        let plate = mean_b(&scene, &solution, 2..4);
        eprintln!(
            "umbra, {name}: receiver B = {b:e} (antiradiance alone {without:e}), plate {plate}"
        );
        assert!(b.abs() < 1e-12, "{name}: receiver in umbra has B = {b}");
        assert!(plate > 0.01, "{name}: the plate is lit: {plate}");
    }
}

#[test]
fn direct_light_is_at_least_as_close_to_the_path_tracer_on_the_occluder_scene() {
    let scene = generated::occluder_scene();
    let patches = build_patches(&scene, None);
    let truth = solve_reference(
        &patches,
        &ReferenceOptions {
            spp: 1024,
            ..ReferenceOptions::default()
        },
        &hidden(),
    );
    let off = SolverOptions::default();
    let on = SolverOptions {
        direct_light: true,
        ..SolverOptions::default()
    };
    let e_hier_off = error(
        &scene,
        &solve_hierarchical(&patches, &off, &hidden()).unwrap(),
        &truth,
    );
    let e_dense_off = error(
        &scene,
        &solve_dense(&patches, &off, &hidden()).unwrap(),
        &truth,
    );
    let e_hier_on = error(
        &scene,
        &solve_hierarchical_direct(&patches, &on, &hidden()).unwrap(),
        &truth,
    );
    let e_dense_on = error(
        &scene,
        &solve_dense_direct(&patches, &on, &hidden()).unwrap(),
        &truth,
    );
    eprintln!(
        "occluder vs path tracer: hierarchical {e_hier_off:.4} -> {e_hier_on:.4} with direct \
         light, dense {e_dense_off:.4} -> {e_dense_on:.4}"
    );
    // Measured 2.6% -> 1.1% (hierarchical), 3.2% -> 1.2% (dense); the path tracer's own noise
    // at 1024 spp is a few tenths of a percent, hence the tolerance.
    let tolerance = 0.002;
    assert!(
        e_hier_on <= e_hier_off + tolerance,
        "{e_hier_on} vs {e_hier_off}"
    );
    assert!(
        e_dense_on <= e_dense_off + tolerance,
        "{e_dense_on} vs {e_dense_off}"
    );
    assert!(
        e_hier_on < 0.02 && e_dense_on < 0.02,
        "{e_hier_on} {e_dense_on}"
    );
}

#[test]
fn direct_light_never_produces_nan() {
    // Hostile geometry around an emitter: a wall sharing its edge, a coplanar neighbour, a
    // triangle behind it, a back-to-back twin, a degenerate triangle, a 1e-6 sliver, a 1e-8
    // speck, and colour channels 30 orders of magnitude apart.
    let v = DVec3::new;
    let emitter = [v(0.0, 1.0, 0.0), v(1.0, 1.0, 0.0), v(0.0, 1.0, 1.0)]; // faces down
    let corners = vec![
        emitter,
        [v(0.0, 1.0, 0.0), v(0.0, 0.0, 0.0), v(1.0, 1.0, 0.0)], // wall on the shared edge
        [v(1.0, 1.0, 0.0), v(1.0, 1.0, 1.0), v(0.0, 1.0, 1.0)], // coplanar neighbour
        [v(0.0, 2.0, 0.0), v(0.0, 2.0, 1.0), v(1.0, 2.0, 0.0)], // behind the emitter
        [v(0.0, 1.0, 0.0), v(0.0, 1.0, 1.0), v(1.0, 1.0, 0.0)], // back-to-back twin
        [v(0.0, 0.0, 0.0), v(0.5, 0.0, 0.5), v(1.0, 0.0, 1.0)], // degenerate
        [v(0.0, 0.0, 0.0), v(1.0, 0.0, 1e-6), v(1.0, 0.0, 0.0)], // sliver
        [v(0.5, 0.0, 0.5), v(0.5, 0.0, 0.5001), v(0.5001, 0.0, 0.5)], // speck
        [v(-1.0, 0.0, -1.0), v(-1.0, 0.0, 2.0), v(2.0, 0.0, -1.0)], // floor
    ];
    let n = corners.len();
    let albedo = vec![[0.9, 0.5, 0.0]; n];
    let mut emission = vec![[0.0; 3]; n];
    emission[0] = [1e30, 1.0, 1e-30];
    let scene = Scene::from_triangles(&corners, &albedo, &emission);
    let no_light = Scene::from_triangles(&corners, &albedo, &vec![[0.0; 3]; n]);
    for (what, scene) in [("lit", &scene), ("no emitter", &no_light)] {
        for max_edge in [None, Some(0.3)] {
            let patches = build_patches(scene, max_edge);
            for clamp_negative in [true, false] {
                let options = SolverOptions {
                    clamp_negative,
                    two_sided: !clamp_negative,
                    ..SolverOptions::default()
                };
                for (name, solution) in both_direct(&patches, &options) {
                    let all = solution
                        .patch_radiance
                        .iter()
                        .chain(&solution.triangle_radiance);
                    for b in all {
                        for &x in b {
                            assert!(x.is_finite(), "{what} {name} {max_edge:?}: {b:?}");
                            if clamp_negative {
                                assert!(x >= 0.0, "{what} {name}: {b:?}");
                            }
                        }
                    }
                    if what == "no emitter" {
                        assert!(solution
                            .triangle_radiance
                            .iter()
                            .flatten()
                            .all(|&x| x == 0.0));
                    }
                }
            }
        }
    }
}
