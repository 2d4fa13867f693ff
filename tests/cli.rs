//! End-to-end runs of the `antiradiance` binary on tiny scenes written into temporary
//! directories (and one shipped scene): outputs, reports, messages, exit codes.

use std::path::{Path, PathBuf};
use std::process::Output;

use serde_json::Value;

mod common;
use common::{run, s, stderr};

/// A light above a one-sided plate above a floor, plus one zero-area triangle: 7 triangles.
///
/// Triangles in file order: 0-1 floor (front +y, white), 2-3 light (front -y, emits), 4-5 plate
/// (front +y, red), 6 degenerate (three collinear points).
const TINY_OBJ: &str = "\
# tiny test scene
mtllib tiny.mtl
v -1 0 -1
v -1 0 1
v 1 0 1
v 1 0 -1
v -0.3 1 -0.3
v 0.3 1 -0.3
v 0.3 1 0.3
v -0.3 1 0.3
v -0.2 0.5 -0.2
v -0.2 0.5 0.2
v 0.2 0.5 0.2
v 0.2 0.5 -0.2
v 2 0 0
v 3 0 0
v 4 0 0
usemtl white
f 1 2 3 4
usemtl light
f 5 6 7 8
usemtl red
f 9 10 11 12
usemtl white
f 13 14 15
";

const TINY_MTL: &str = "\
newmtl white
Kd 0.7 0.7 0.7
newmtl light
Kd 0 0 0
Ke 4 4 4
newmtl red
Kd 0.6 0.1 0.1
";

const TINY_TRIANGLES: usize = 7;

/// Writes the tiny scene into `dir`; returns the OBJ path.
fn tiny_scene(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("tiny.mtl"), TINY_MTL).unwrap();
    let obj = dir.join("tiny.obj");
    std::fs::write(&obj, TINY_OBJ).unwrap();
    obj
}

/// The four output files in `dir`.
fn outputs(dir: &Path) -> [PathBuf; 4] {
    ["out.csv", "out.ply", "out.png", "out.json"].map(|n| dir.join(n))
}

/// Output flags writing every file of [`outputs`] with a small picture.
fn output_args(files: &[PathBuf; 4]) -> Vec<String> {
    let mut args = Vec::new();
    for (flag, path) in ["--triangles", "--ply", "--png", "--report"]
        .iter()
        .zip(files)
    {
        args.push(flag.to_string());
        args.push(path.to_str().unwrap().to_string());
    }
    args.extend(["--width", "64", "--height", "48"].map(String::from));
    args
}

fn run_owned(args: &[String]) -> Output {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    run(&refs)
}

/// Parses the per-triangle CSV: checks the header and the index column, returns the rows as
/// (area, emissive, [r, g, b]).
fn read_csv(path: &Path) -> Vec<(f64, bool, [f64; 3])> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("index,area,emissive,r,g,b"));
    lines
        .enumerate()
        .map(|(i, line)| {
            let cols: Vec<&str> = line.split(',').collect();
            assert_eq!(cols.len(), 6, "row {i}: {line}");
            assert_eq!(cols[0].parse::<usize>().unwrap(), i, "row {i}: {line}");
            let f = |k: usize| -> f64 {
                let x: f64 = cols[k].parse().unwrap();
                assert!(x.is_finite(), "row {i}: {line}");
                x
            };
            let emissive = match cols[2] {
                "0" => false,
                "1" => true,
                other => panic!("row {i}: emissive column {other}"),
            };
            (f(1), emissive, [f(3), f(4), f(5)])
        })
        .collect()
}

/// Checks the PLY header and returns its face count.
fn ply_faces(path: &Path) -> usize {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.starts_with("ply\n"), "{path:?}");
    assert!(text.contains("end_header\n"));
    text.lines()
        .find_map(|l| l.strip_prefix("element face "))
        .expect("element face line")
        .trim()
        .parse()
        .unwrap()
}

/// Checks the PNG signature and returns (width, height) from its IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Checks the fields every report has and returns it.
fn check_report(path: &Path, command: &str, scene: &Path, triangles: usize) -> Value {
    let r = read_json(path);
    assert_eq!(r["tool"], "antiradiance");
    assert_eq!(r["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(r["command"], command);
    assert_eq!(r["scene"], scene.to_str().unwrap());
    let counts = &r["counts"];
    assert_eq!(counts["input_triangles"], triangles as u64);
    assert!(counts["patches"].as_u64().unwrap() >= triangles as u64);
    assert!(counts["degenerate_triangles"].is_u64());
    assert!(counts["emitters"].is_u64());
    let scene_options = &r["parameters"]["scene_options"];
    for key in ["albedo", "emit_above", "emission", "max_edge"] {
        assert!(scene_options.get(key).is_some(), "scene option {key}: {r}");
    }
    let t = &r["time_seconds"];
    for key in ["load", "build", "solve", "output", "total"] {
        let x = t[key].as_f64().unwrap_or_else(|| panic!("time {key}: {r}"));
        assert!(x >= 0.0 && x.is_finite());
    }
    let sum: f64 = ["load", "build", "solve", "output"]
        .iter()
        .map(|k| t[*k].as_f64().unwrap())
        .sum();
    assert!(t["total"].as_f64().unwrap() >= sum * 0.99, "{t}");
    if cfg!(target_os = "linux") {
        assert!(r["peak_memory_bytes"].as_u64().unwrap() > 0);
    }
    r
}

fn check_stats(stats: &Value) {
    for key in ["iterations", "negative_patches", "links", "solver_bytes"] {
        assert!(stats[key].is_u64(), "stats {key}: {stats}");
    }
    for key in ["residual", "negative_fraction", "max_row_sum"] {
        assert!(
            stats[key].is_f64() || stats[key].is_u64(),
            "stats {key}: {stats}"
        );
    }
    assert!(stats["converged"].is_boolean());
    // Hierarchical solves break their links down by kind.
    if let Some(detail) = stats["link_stats"].as_object() {
        let (cluster, exact) = (
            detail["cluster_links"].as_u64().unwrap(),
            detail["exact_links"].as_u64().unwrap(),
        );
        assert_eq!(cluster + exact, stats["links"].as_u64().unwrap(), "{stats}");
        assert!(detail["refinement"]["traverse_seconds"].is_f64(), "{stats}");
    }
}

/// Checks the tiny scene's per-triangle results: 7 rows, emitters flagged, the degenerate
/// triangle dark, the floor lit.
fn check_tiny_csv(path: &Path) {
    let rows = read_csv(path);
    assert_eq!(rows.len(), TINY_TRIANGLES);
    let emissive: Vec<bool> = rows.iter().map(|r| r.1).collect();
    assert_eq!(emissive, [false, false, true, true, false, false, false]);
    assert_eq!(rows[6].0, 0.0, "degenerate triangle area");
    assert_eq!(rows[6].2, [0.0; 3], "degenerate triangle keeps B = E = 0");
    for t in [2, 3] {
        assert!(
            rows[t].2.iter().all(|&b| (b - 4.0).abs() < 1e-9),
            "light: B = E (albedo 0): {:?}",
            rows[t]
        );
    }
    for t in [0, 1] {
        assert!(
            rows[t].2.iter().all(|&b| b > 0.0),
            "floor lit: {:?}",
            rows[t]
        );
        assert!((rows[t].0 - 2.0).abs() < 1e-12, "floor triangle area 2");
    }
    // The plate is red: more red than green.
    assert!(rows[4].2[0] > rows[4].2[1], "{:?}", rows[4]);
}

#[test]
fn solve_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let files = outputs(dir.path());
    for solver in ["dense", "hierarchical"] {
        let mut args: Vec<String> = ["solve", s(&scene), "--solver", solver]
            .map(String::from)
            .to_vec();
        args.extend(output_args(&files));
        let o = run_owned(&args);
        let err = stderr(&o);
        assert!(o.status.success(), "{solver}: {err}");
        assert!(!err.contains("error"), "{solver}: {err}");
        // The summary paragraph (stderr is not a terminal: no progress bars).
        assert!(err.starts_with("Solved 7 triangles"), "{solver}: {err}");
        assert!(err.contains(&format!("the {solver} solver")), "{err}");
        assert!(
            err.contains("converged") || err.contains("iteration cap"),
            "{err}"
        );
        assert_eq!(err.lines().count(), 1, "{err}");

        check_tiny_csv(&files[0]);
        assert_eq!(ply_faces(&files[1]), TINY_TRIANGLES);
        assert_eq!(png_size(&files[2]), (64, 48));
        let r = check_report(&files[3], "solve", &scene, TINY_TRIANGLES);
        assert_eq!(r["counts"]["patches"], 7);
        assert_eq!(r["counts"]["degenerate_triangles"], 1);
        assert_eq!(r["counts"]["emitters"], 2);
        assert_eq!(r["parameters"]["solver"], solver);
        assert_eq!(r["parameters"]["preset"], "default");
        assert_eq!(r["parameters"]["solver_options"]["bins"], 8);
        check_stats(&r["stats"]);
        assert!(r["stats"]["links"].as_u64().unwrap() > 0);
        assert_eq!(r["warnings"].as_array().unwrap().len(), 0);
        for f in &files {
            std::fs::remove_file(f).unwrap();
        }
    }
}

/// `--elements` keeps the hierarchical solver's elements: the shipped Cornell box's 46
/// triangles are solved as more pieces than that, and the file holds one row per piece, each
/// naming a triangle of the scene; the dense solver writes its patches.
#[test]
fn elements_flag_writes_the_solved_pieces() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.obj");
    let path = dir.path().join("elements.csv");
    let rows = |solver: &str| {
        let o = run(&[
            "solve",
            s(&scene),
            "--solver",
            solver,
            "--quiet",
            "--elements",
            s(&path),
        ]);
        assert!(o.status.success(), "{solver}: {}", stderr(&o));
        let text = std::fs::read_to_string(&path).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next(),
            Some("element,triangle,x0,y0,z0,x1,y1,z1,x2,y2,z2,area,r,g,b")
        );
        let triangles: Vec<usize> = lines
            .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
            .collect();
        assert!(triangles.iter().all(|&t| t < 46), "{solver}");
        triangles.len()
    };
    let hierarchical = rows("hierarchical");
    assert!(hierarchical > 2 * 46, "{hierarchical} elements");
    assert_eq!(rows("dense"), 46);
}

#[test]
fn explicit_options_override_the_preset() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let report = dir.path().join("r.json");
    let o = run(&[
        "solve",
        s(&scene),
        "--solver",
        "dense",
        "--preset",
        "accurate",
        "--bins",
        "5",
        "--tol",
        "0.01",
        "--epsilon",
        "0.75",
        "--max-iterations",
        "40",
        "--two-sided-antiradiance",
        "--keep-negative",
        "--albedo",
        "0.5",
        "--max-edge",
        "0.5",
        "--report",
        s(&report),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stderr(&o), "", "--quiet prints nothing on success");
    let r = read_json(&report);
    let so = &r["parameters"]["solver_options"];
    assert_eq!(r["parameters"]["preset"], "accurate");
    assert_eq!(so["bins"], 5);
    assert_eq!(so["tol"], 0.01);
    assert_eq!(so["epsilon"], 0.75);
    assert_eq!(so["max_iterations"], 40);
    assert_eq!(so["two_sided"], true);
    assert_eq!(so["clamp_negative"], false);
    assert_eq!(so["antiradiance"], true);
    assert_eq!(so["direct_light"], true, "the accurate preset's");
    assert_eq!(r["parameters"]["scene_options"]["albedo"], 0.5);
    assert_eq!(r["parameters"]["scene_options"]["max_edge"], 0.5);
    // --max-edge 0.5 splits the floor (edges 2 and 2.83) into 6 x 6 pieces per triangle.
    assert!(r["counts"]["patches"].as_u64().unwrap() > 7, "{r}");
    assert_eq!(r["counts"]["input_triangles"], 7);
}

#[test]
fn direct_light_follows_the_preset_unless_told() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let report = dir.path().join("r.json");
    for (flags, expected) in [
        (&[][..], true),
        (&["--preset", "fast"][..], false),
        (&["--no-direct-light"][..], false),
        (&["--preset", "fast", "--direct-light"][..], true),
    ] {
        let mut args = vec!["solve", s(&scene), "--report", s(&report), "--quiet"];
        args.extend_from_slice(flags);
        let o = run(&args);
        assert!(o.status.success(), "{flags:?}: {}", stderr(&o));
        let r = read_json(&report);
        assert_eq!(
            r["parameters"]["solver_options"]["direct_light"], expected,
            "{flags:?}"
        );
        assert_eq!(r["stats"]["direct_light_skipped"], false, "{flags:?}");
    }
    let o = run(&["solve", s(&scene), "--direct-light", "--no-direct-light"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn iteration_cap_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let report = dir.path().join("r.json");
    let o = run(&[
        "solve",
        s(&scene),
        "--solver",
        "dense",
        "--max-iterations",
        "1",
        "--report",
        s(&report),
    ]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("stopped at the iteration cap"), "{err}");
    let r = read_json(&report);
    assert_eq!(r["stats"]["converged"], false);
    assert_eq!(r["stats"]["iterations"], 1);
}

#[test]
fn reference_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let files = outputs(dir.path());
    let mut args: Vec<String> = [
        "reference",
        s(&scene),
        "--spp",
        "8",
        "--seed",
        "3",
        "--smooth",
    ]
    .map(String::from)
    .to_vec();
    args.extend(output_args(&files));
    let o = run_owned(&args);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.starts_with("Path-traced 7 triangles with 8 samples"),
        "{err}"
    );

    check_tiny_csv(&files[0]);
    assert_eq!(ply_faces(&files[1]), TINY_TRIANGLES);
    assert_eq!(png_size(&files[2]), (64, 48));
    let r = check_report(&files[3], "reference", &scene, TINY_TRIANGLES);
    assert_eq!(r["parameters"]["solver"], "reference");
    assert_eq!(r["parameters"]["reference_options"]["spp"], 8);
    assert_eq!(r["parameters"]["reference_options"]["seed"], 3);
    check_stats(&r["stats"]);

    // Same seed, same numbers.
    let first = std::fs::read_to_string(&files[0]).unwrap();
    let o = run_owned(&args);
    assert!(o.status.success());
    assert_eq!(std::fs::read_to_string(&files[0]).unwrap(), first);
}

#[test]
fn compare_prints_a_table_and_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let report = dir.path().join("c.json");
    let o = run(&[
        "compare",
        s(&scene),
        "--reference-spp",
        "4",
        "--report",
        s(&report),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    for word in [
        "dense",
        "hierarchical",
        "reference",
        "links",
        "vs reference",
    ] {
        assert!(table.contains(word), "{word}: {table}");
    }
    assert!(table.contains("hierarchical vs dense"), "{table}");
    let r = check_report(&report, "compare", &scene, TINY_TRIANGLES);
    for solver in ["dense", "hierarchical"] {
        let run = &r["solvers"][solver];
        assert!(run["seconds"].as_f64().unwrap() >= 0.0);
        check_stats(&run["stats"]);
        let e = run["error_vs_reference"].as_f64().unwrap();
        assert!(e.is_finite() && e >= 0.0);
        if cfg!(target_os = "linux") {
            assert!(run["peak_memory_delta_bytes"].is_u64(), "{run}");
        }
    }
    assert_eq!(r["reference"]["spp"], 4);
    let between = r["hierarchical_vs_dense_error"].as_f64().unwrap();
    assert!(between.is_finite() && between >= 0.0);
}

/// Expects a failure: non-zero exit, exactly one stderr line starting with `error:` that
/// contains `needle`, and none of `files` created.
fn expect_error(o: &Output, needle: &str, files: &[PathBuf]) {
    let err = stderr(o);
    assert!(!o.status.success(), "{needle}: succeeded, stderr {err:?}");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{needle}: stderr must be one line: {err:?}");
    assert!(lines[0].starts_with("error: "), "{err:?}");
    assert!(lines[0].contains(needle), "{needle}: {err:?}");
    for f in files {
        assert!(!f.exists(), "{needle}: {f:?} was written");
    }
    // No temporary files left behind either.
    if let Some(dir) = files.first().and_then(|f| f.parent()) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let name = entry.unwrap().file_name();
            assert!(
                !name.to_string_lossy().contains(".tmp-"),
                "{needle}: leftover {name:?}"
            );
        }
    }
}

#[test]
fn bad_scene_is_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n").unwrap();
    let files = outputs(dir.path());
    for command in ["solve", "reference"] {
        let mut args: Vec<String> = vec![command.into(), s(&bad).into()];
        if command == "reference" {
            args.extend(["--spp".into(), "2".into()]);
        }
        args.extend(output_args(&files));
        expect_error(&run_owned(&args), "broken.obj:3", &files);
    }
    let o = run(&["compare", s(&bad), "--report", s(&files[3])]);
    expect_error(&o, "broken.obj:3", &files);

    // A missing file.
    let missing = dir.path().join("missing.obj");
    let mut args: Vec<String> = vec!["solve".into(), s(&missing).into()];
    args.extend(output_args(&files));
    expect_error(&run_owned(&args), "missing.obj", &files);

    // A face index out of range.
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap();
    let mut args: Vec<String> = vec!["solve".into(), s(&bad).into()];
    args.extend(output_args(&files));
    expect_error(&run_owned(&args), "broken.obj", &files);
}

#[test]
fn bad_parameters_are_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let files = outputs(dir.path());
    let cases: &[(&[&str], &str)] = &[
        (&["--albedo", "1.5"], "--albedo"),
        (&["--albedo", "-0.1"], "--albedo"),
        (&["--emission", "-1"], "--emission"),
        (&["--max-edge", "0"], "--max-edge"),
        (&["--bins", "0"], "--bins"),
        (&["--tol", "2"], "--tol"),
        (&["--epsilon", "-1"], "--epsilon"),
        (&["--max-iterations", "0"], "--max-iterations"),
        (&["--fov", "180"], "--fov"),
        (&["--width", "0"], "--width"),
        (&["--exposure", "0"], "--exposure"),
        (&["--eye", "1,2,3", "--target", "1,2,3"], "--eye"),
        (&["--max-edge", "1e-9"], "--max-edge"),
    ];
    for (extra, needle) in cases {
        let mut args: Vec<String> = vec!["solve".into(), s(&scene).into()];
        args.extend(extra.iter().map(|a| a.to_string()));
        args.extend(output_args(&files));
        if *needle == "--width" {
            // output_args gives a size already: keep only the bad one.
            let at = args.iter().rposition(|a| a == "--width").unwrap();
            args.drain(at..at + 2);
        }
        let o = run_owned(&args);
        expect_error(&o, needle, &files);
        assert_eq!(o.status.code(), Some(1), "{needle}");
    }
    let o = run(&[
        "reference",
        s(&scene),
        "--spp",
        "0",
        "--triangles",
        s(&files[0]),
    ]);
    expect_error(&o, "--spp", &files);
    let o = run(&["reference", s(&scene), "--spp", "1", "--albedo", "1.5"]);
    expect_error(&o, "--albedo", &files);
    let o = run(&["compare", s(&scene), "--albedo", "1.5"]);
    expect_error(&o, "--albedo", &files);
}

#[test]
fn command_line_errors_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let files = outputs(dir.path());
    let cases: &[(&[&str], &str)] = &[
        (&["solve"], "SCENE.obj"),
        (&["solve", s(&scene), "--bogus"], "--bogus"),
        (&["solve", s(&scene), "--albedo", "abc"], "--albedo"),
        (&["solve", s(&scene), "--eye", "1,2"], "--eye"),
        (&["solve", s(&scene), "--solver", "sparse"], "--solver"),
        (&["solve", s(&scene), "--preset", "slow"], "--preset"),
        (&["reference", s(&scene)], "--spp"),
        (&["frobnicate"], "frobnicate"),
    ];
    for (args, needle) in cases {
        let o = run(args);
        expect_error(&o, needle, &files);
        assert_eq!(o.status.code(), Some(2), "{needle}");
    }
    let o = run(&["--version"]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains(env!("CARGO_PKG_VERSION")));
    let o = run(&["solve", "--help"]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("--triangles"));
}

#[test]
fn bad_output_paths_fail_before_solving() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let csv = dir.path().join("out.csv");
    let missing_dir = dir.path().join("no-such-dir").join("out.png");
    let o = run(&[
        "solve",
        s(&scene),
        "--triangles",
        s(&csv),
        "--png",
        s(&missing_dir),
    ]);
    expect_error(&o, "no-such-dir", std::slice::from_ref(&csv));
    // An output over the scene itself is refused and the scene is left intact.
    let o = run(&["solve", s(&scene), "--triangles", s(&scene)]);
    expect_error(&o, "tiny.obj", std::slice::from_ref(&csv));
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), TINY_OBJ);
    // Two outputs on one file.
    let o = run(&[
        "solve",
        s(&scene),
        "--triangles",
        s(&csv),
        "--report",
        s(&csv),
    ]);
    expect_error(&o, "same file", std::slice::from_ref(&csv));
    // A directory as output.
    let o = run(&["solve", s(&scene), "--triangles", s(dir.path())]);
    expect_error(&o, "directory", &[csv]);
}

#[test]
fn warnings_go_to_stderr_and_the_solve_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    // No MTL file next to the OBJ: a warning; --emit-above makes the light emit.
    let scene = dir.path().join("tiny.obj");
    std::fs::write(&scene, TINY_OBJ).unwrap();
    let csv = dir.path().join("out.csv");
    let report = dir.path().join("out.json");
    let o = run(&[
        "solve",
        s(&scene),
        "--solver",
        "dense",
        "--emit-above",
        "0.9",
        "--emission",
        "2",
        "--triangles",
        s(&csv),
        "--report",
        s(&report),
        "--quiet",
    ]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(!err.is_empty());
    for line in err.lines() {
        assert!(line.starts_with("warning: "), "{err}");
    }
    assert!(err.contains("tiny.mtl"), "{err}");
    let rows = read_csv(&csv);
    assert_eq!(rows.len(), TINY_TRIANGLES);
    assert!(rows[2].1 && rows[3].1, "the light emits");
    let r = read_json(&report);
    // The report lists each warning as its kind, message, file and line; the message names
    // flags, as on stderr.
    let warnings = r["warnings"].as_array().unwrap();
    let material = warnings
        .iter()
        .find(|w| w["kind"] == "material")
        .expect("the missing MTL file");
    assert!(
        material["message"].as_str().unwrap().contains("tiny.mtl"),
        "{r}"
    );
    assert!(
        material["message"].as_str().unwrap().contains("--albedo"),
        "{r}"
    );
    assert!(
        material["file"].as_str().unwrap().ends_with("tiny.obj"),
        "{r}"
    );
    assert!(material["line"].as_u64().is_some(), "{r}");
    assert!(
        err.contains("warning: ") && err.contains("using --albedo"),
        "{err}"
    );
    assert_eq!(r["parameters"]["scene_options"]["emit_above"], 0.9);
    assert_eq!(r["parameters"]["scene_options"]["emission"], 2.0);
}

#[test]
fn shipped_cornell_box() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.obj");
    if !scene.exists() {
        eprintln!("skipped: {scene:?} is not there");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("cornell.csv");
    let png = dir.path().join("cornell.png");
    let o = run(&[
        "solve",
        s(&scene),
        "--solver",
        "dense",
        "--triangles",
        s(&csv),
        "--png",
        s(&png),
        "--width",
        "80",
        "--height",
        "60",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = read_csv(&csv);
    let text = std::fs::read_to_string(&scene).unwrap();
    let faces = text.lines().filter(|l| l.starts_with("f ")).count();
    assert!(rows.len() >= faces);
    assert!(rows.iter().any(|r| r.1), "the Cornell box has a light");
    assert_eq!(png_size(&png), (80, 60));
}
