//! The memory budget (`--memory-limit`, `SolverOptions::memory_limit_bytes`) and what the report
//! says a mesh cost (`stats.mesh`, `stats.memory`).

use std::path::{Path, PathBuf};
use std::process::Output;

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::generated;
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::hierarchical::Prepared;
use antiradiance::solve::SolverOptions;
use antiradiance::Error;
use serde_json::Value;

mod common;
use common::{run, s, stderr};

/// The shipped Cornell box.
fn cornell_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.obj")
}

/// The JSON report at `path`.
fn report(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("report written"))
        .expect("report is JSON")
}

/// Asserts that a run failed with exit code 1 and one `error:` line naming the memory limit,
/// without panic text.
fn assert_memory_error(o: &Output) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.starts_with("warning:")).collect();
    assert_eq!(lines.len(), 1, "one error line: {err}");
    assert!(
        lines[0].starts_with("error: does not fit the memory limit of"),
        "{err}"
    );
    assert!(lines[0].contains("--memory-limit"), "{err}");
    for bad in [
        "panicked",
        "stack backtrace",
        "memory allocation of",
        "internal error",
    ] {
        assert!(!err.contains(bad), "{bad}: {err}");
    }
}

/// A limit below what the process already holds: the hierarchical and the dense solver (with
/// and without exact direct light) stop with the one-line error, and no output file is written.
#[test]
fn a_tiny_memory_limit_is_a_one_line_error_and_writes_nothing() {
    let cornell = cornell_path();
    let tmp = tempfile::tempdir().unwrap();
    let (csv, json) = (tmp.path().join("out.csv"), tmp.path().join("out.json"));
    for extra in [
        &["--solver", "hierarchical"][..],
        &["--solver", "dense"],
        &["--solver", "dense", "--no-direct-light"],
        &["--solver", "hierarchical", "--no-direct-light"],
    ] {
        let mut args = vec!["solve", s(&cornell), "--memory-limit", "1M"];
        args.extend(extra);
        args.extend(["--triangles", s(&csv), "--report", s(&json), "--quiet"]);
        let o = run(&args);
        assert_memory_error(&o);
        assert!(!csv.exists() && !json.exists(), "{extra:?}: no output file");
    }
    // Every command that solves takes the limit.
    let out_dir = tmp.path().join("frames");
    for args in [
        vec!["compare", s(&cornell), "--memory-limit", "1M", "--quiet"],
        vec![
            "relight",
            s(&cornell),
            "--frames",
            "1",
            "--out",
            s(&out_dir),
            "--memory-limit",
            "1M",
            "--quiet",
        ],
    ] {
        assert_memory_error(&run(&args));
    }
    assert!(!out_dir.join("frame_0000.png").exists());
}

/// A limit that the asked model does not fit but a coarser one does: the solve coarsens,
/// warns on one line, says so in the report, and its peak stays within the limit.
#[test]
fn a_small_memory_limit_coarsens_with_a_warning() {
    let cornell = cornell_path();
    let tmp = tempfile::tempdir().unwrap();
    let (csv, json) = (tmp.path().join("out.csv"), tmp.path().join("out.json"));
    let asked = [
        "solve",
        s(&cornell),
        "--max-edge",
        "100",
        "--preset",
        "accurate",
    ];
    // Measured: the accurate preset on these 956 patches is estimated at about 70 MB, the
    // coarsest model at about 7 MB; 48 MB leaves room for about 25 MB beside the process.
    let o = run(&[
        &asked[..],
        &[
            "--memory-limit",
            "48M",
            "--triangles",
            s(&csv),
            "--report",
            s(&json),
            "--quiet",
        ],
    ]
    .concat());
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let warnings: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("warning: the model was coarsened to fit the memory limit"))
        .collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(warnings[0].contains("epsilon 0.25 -> 0.5"), "{err}");
    let r = report(&json);
    let m = &r["stats"]["memory"];
    assert_eq!(m["limit_bytes"], 48u64 << 20);
    let coarsened = m["coarsened"].as_array().expect("coarsened");
    assert!(!coarsened.is_empty());
    assert_eq!(coarsened[0], "epsilon 0.25 -> 0.5");
    assert!(m["epsilon"].as_f64().unwrap() > 0.25);
    assert!(m["attempts"].as_u64().unwrap() >= 2);
    let estimate = m["estimate_bytes"].as_u64().unwrap();
    let base = m["base_bytes"].as_u64().unwrap();
    assert!(estimate > 0 && estimate + base <= 48 << 20, "{m}");
    if let Some(peak) = r["peak_memory_bytes"].as_u64() {
        assert!(peak <= 48 << 20, "peak {peak} over the limit");
        let in_stats = m["peak_bytes"].as_u64().expect("peak on Linux");
        assert!(in_stats <= 48 << 20, "peak {in_stats} over the limit");
    }
    let in_report = r["warnings"].as_array().unwrap();
    assert!(in_report.iter().any(|w| w["kind"] == "memory"
        && w["message"]
            .as_str()
            .unwrap()
            .starts_with("the model was coarsened")));
    // The solver options in the report are those asked for; the memory stats say what ran.
    assert_eq!(r["parameters"]["solver_options"]["epsilon"], 0.25);
    assert_eq!(
        r["parameters"]["solver_options"]["memory_limit_bytes"],
        48u64 << 20
    );
    let rows = std::fs::read_to_string(&csv).unwrap().lines().count();
    assert_eq!(rows, 1 + 46, "header and one row per input triangle");
    // The attempts share one tree, each undoing the splits of the one before: the model that
    // fitted is the one a solve asking for it builds from scratch.
    let json_direct = tmp.path().join("direct.json");
    let (epsilon, split_depth, bins) = (
        m["epsilon"].to_string(),
        m["split_depth"].to_string(),
        m["bins"].to_string(),
    );
    let o = run(&[
        &asked[..],
        &[
            "--epsilon",
            &epsilon,
            "--split-depth",
            &split_depth,
            "--bins",
            &bins,
            "--report",
            s(&json_direct),
            "--quiet",
        ],
    ]
    .concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let direct = report(&json_direct);
    for key in ["elements", "links"] {
        assert_eq!(r["stats"][key], direct["stats"][key], "{key}");
    }
    assert_eq!(
        r["stats"]["link_stats"]["exact_links"],
        direct["stats"]["link_stats"]["exact_links"]
    );
}

/// Bad sizes are a one-line command-line error (exit code 2) naming the flag; good ones parse.
#[test]
fn memory_limit_sizes_are_checked() {
    let cornell = cornell_path();
    for bad in [
        "",
        "0",
        "0M",
        "-1G",
        "1.5",
        "abc",
        "4Q",
        "1e3M",
        "99999999999T",
        "G",
    ] {
        let o = run(&["solve", s(&cornell), "--memory-limit", bad, "--quiet"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{bad:?}: {err}");
        assert!(
            err.starts_with("error:") && err.contains("--memory-limit"),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
    let tmp = tempfile::tempdir().unwrap();
    let json = tmp.path().join("r.json");
    for (good, bytes) in [
        ("1.5G", 3u64 << 29),
        ("4GB", 4 << 30),
        ("3000000000", 3_000_000_000),
    ] {
        let o = run(&[
            "solve",
            s(&cornell),
            "--memory-limit",
            good,
            "--no-direct-light",
            "--report",
            s(&json),
            "--quiet",
        ]);
        assert!(o.status.success(), "{good}: {}", stderr(&o));
        let r = report(&json);
        assert_eq!(r["stats"]["memory"]["limit_bytes"], bytes, "{good}");
        assert_eq!(r["stats"]["memory"]["coarsened"], serde_json::json!([]));
    }
    // The library refuses a zero limit.
    let options = SolverOptions {
        memory_limit_bytes: Some(0),
        ..SolverOptions::default()
    };
    assert!(options.validate().is_err());
}

/// The report says what the Cornell box cost: its triangles' shapes (all halves of rectangles:
/// aspect ratio at least 4), its area range, the elements after splits, the links per
/// triangle, and the memory estimate next to the peak.
#[test]
fn the_report_has_the_mesh_fields() {
    let cornell = cornell_path();
    let tmp = tempfile::tempdir().unwrap();
    let json = tmp.path().join("r.json");
    for solver in ["hierarchical", "dense"] {
        let o = run(&[
            "solve",
            s(&cornell),
            "--solver",
            solver,
            "--report",
            s(&json),
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let r = report(&json);
        let stats = &r["stats"];
        let mesh = &stats["mesh"];
        let f = |k: &str| mesh[k].as_f64().unwrap_or_else(|| panic!("{k} in {mesh}"));
        assert_eq!(mesh["triangles"], 46);
        let (p50, p90, p99, max) = (
            f("aspect_p50"),
            f("aspect_p90"),
            f("aspect_p99"),
            f("aspect_max"),
        );
        assert!(p50 >= 4.0 - 1e-9, "{mesh}");
        assert!(
            p50 <= p90 && p90 <= p99 && p99 <= max && max < 100.0,
            "{mesh}"
        );
        let (lo, hi, range) = (f("area_min"), f("area_max"), f("area_range"));
        assert!(lo > 0.0 && hi > lo, "{mesh}");
        assert!((range - hi / lo).abs() <= 1e-9 * range, "{mesh}");
        let elements = mesh["elements"].as_u64().unwrap();
        let links = stats["links"].as_f64().unwrap();
        assert!((f("links_per_triangle") - links / 46.0).abs() <= 1e-9 * links);
        match solver {
            // Walls are split where the blocks need finer receivers.
            "hierarchical" => assert!(elements > 46, "{elements} elements"),
            _ => assert_eq!(elements, 46),
        }
        let m = &stats["memory"];
        assert!(m["estimate_bytes"].as_u64().unwrap() > 0, "{m}");
        assert!(m["limit_bytes"].as_u64().unwrap() > 0, "{m}");
        if let Some(peak) = r["peak_memory_bytes"].as_u64() {
            // (The kernel's resident counters are approximate per thread: the peak read at
            // the end of the solve may exceed the one read later by a few pages.)
            let in_stats = m["peak_bytes"].as_u64().expect("peak on Linux");
            assert!(in_stats > m["base_bytes"].as_u64().unwrap(), "{m}");
            assert!(in_stats < 2 * peak, "{m} against {peak}");
        }
    }
}

/// The library says the same: the dense solver and the hierarchical model refuse a limit they
/// do not fit, and a model that fits as asked reports no coarsening.
#[test]
fn the_library_respects_the_limit() {
    let patches = build_patches(&generated::cornell_box(), Some(100.0));
    let tiny = SolverOptions {
        memory_limit_bytes: Some(1 << 20),
        ..SolverOptions::default()
    };
    match solve_dense(&patches, &tiny, &Progress::hidden()) {
        Err(Error::Memory(message)) => assert!(!message.contains('\n'), "{message}"),
        other => panic!("expected a memory error, got {:?}", other.map(|s| s.stats)),
    }
    assert!(matches!(
        Prepared::new(&patches, &tiny, false),
        Err(Error::Memory(_))
    ));
    // (Coarsening under a limit between the two is tested on the command line: the tests of
    // this file run in parallel threads of one process, whose resident memory is not this
    // test's alone.)
    let generous = Prepared::new(&patches, &SolverOptions::default(), false).unwrap();
    let memory = generous.memory();
    assert!(memory.coarsened.is_empty(), "{memory:?}");
    assert_eq!(memory.attempts, 1);
    assert_eq!(memory.epsilon, SolverOptions::default().epsilon);
    assert!(memory.estimate_bytes > 0);
}

/// The office mesh (one-sided, slivers, areas spanning 1e7), when present, under a small limit:
/// it either finishes within the limit or stops with the one-line error, writing nothing.
#[test]
fn the_office_mesh_fits_a_small_limit_or_says_it_does_not() {
    let office = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes/b90_office.obj");
    if !office.is_file() {
        eprintln!("skipped: {} is not there", office.display());
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (csv, json) = (tmp.path().join("out.csv"), tmp.path().join("out.json"));
    let o = run(&[
        "solve",
        s(&office),
        "--memory-limit",
        "1G",
        "--triangles",
        s(&csv),
        "--report",
        s(&json),
        "--quiet",
    ]);
    if o.status.success() {
        let r = report(&json);
        if let Some(peak) = r["peak_memory_bytes"].as_u64() {
            assert!(peak <= 1 << 30, "peak {peak} over the 1 GB limit");
        }
        assert!(csv.is_file());
    } else {
        assert_memory_error(&o);
        assert!(!csv.exists() && !json.exists(), "no output file");
    }
}

/// The shape figures of known triangles: an equilateral one (aspect 4/sqrt(3)), half a square
/// (4), a sliver (2 / sin of its smallest angle, about), and a degenerate one (not counted).
#[test]
fn triangle_shapes_are_what_they_should_be() {
    use antiradiance::scene::Scene;
    use glam::DVec3;
    let v = DVec3::new;
    let h = 3f64.sqrt() / 2.0;
    let corners = [
        [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.5, h, 0.0)],
        [v(0.0, 0.0, 1.0), v(2.0, 0.0, 1.0), v(0.0, 2.0, 1.0)],
        [v(0.0, 0.0, 2.0), v(100.0, 0.0, 2.0), v(50.0, 0.5, 2.0)],
        [v(0.0, 0.0, 3.0), v(1.0, 0.0, 3.0), v(2.0, 0.0, 3.0)],
    ];
    let n = corners.len();
    let scene = Scene::from_triangles(&corners, &vec![[0.5; 3]; n], &vec![[0.0; 3]; n]);
    let shapes = scene.shapes();
    assert_eq!(
        shapes.triangles, 3,
        "the degenerate triangle is not counted"
    );
    let equilateral = 4.0 / 3f64.sqrt();
    let sliver = 100.0 * 100.0 / 25.0;
    // Nearest rank over three values: the median is the middle one, p90 and p99 the largest.
    assert!((shapes.aspect_p50 - 4.0).abs() < 1e-12, "{shapes:?}");
    assert!((shapes.aspect_p90 - sliver).abs() < 1e-9, "{shapes:?}");
    assert_eq!(shapes.aspect_p99, shapes.aspect_max);
    assert!((shapes.aspect_max - sliver).abs() < 1e-9, "{shapes:?}");
    assert!(equilateral < shapes.aspect_p50);
    assert!((shapes.area_min - 0.5 * h).abs() < 1e-12, "{shapes:?}");
    assert!((shapes.area_max - 25.0).abs() < 1e-9, "{shapes:?}");
    assert!(
        (shapes.area_range - 25.0 / (0.5 * h)).abs() < 1e-9,
        "{shapes:?}"
    );
    let one = Scene::from_triangles(&corners[..1], &[[0.5; 3]], &[[0.0; 3]]).shapes();
    assert!((one.aspect_p50 - equilateral).abs() < 1e-12 && one.area_range == 1.0);
}
