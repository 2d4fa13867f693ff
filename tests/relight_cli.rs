//! The `relight` command (and the `sweep` command's light spot): frames, reports, progressive
//! analytic lights, band mixes and bad arguments. The library's relighter is checked in
//! `tests/relight.rs`.

use std::path::Path;
use std::process::{Command, Output};

use antiradiance::solve::relight::{frame_path, sweep_weights};
use glam::DVec3;
use serde_json::Value;

mod common;
use common::lamps::lamps_scene;
use common::{run, s};

// ---------------------------------------------------------------------------------------------
// The sweep of the command line

#[test]
fn sweep_moves_a_spot_across_the_emitters() {
    let centroids: Vec<DVec3> = (0..5).map(|i| DVec3::new(i as f64, 2.0, 0.5)).collect();
    let frames = 5;
    for frame in 0..frames {
        let w = sweep_weights(&centroids, frame, frames, 0.1);
        assert!(w.iter().all(|&x| (0.1..=1.0).contains(&x)), "{w:?}");
        let brightest = (0..5).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap();
        assert_eq!(brightest, frame, "{w:?}");
        assert!((w[frame] - 1.0).abs() < 1e-12);
    }
    // A single emitter pulses: dim at the ends, full in the middle.
    let one = [DVec3::ZERO];
    assert!((sweep_weights(&one, 0, 3, 0.2)[0] - 0.2).abs() < 1e-12);
    assert!((sweep_weights(&one, 1, 3, 0.2)[0] - 1.0).abs() < 1e-12);
    assert!((sweep_weights(&one, 0, 1, 0.2)[0] - 1.0).abs() < 1e-12);
}

// ---------------------------------------------------------------------------------------------
// The command line

fn png_size(path: &Path) -> (u32, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    (info.width, info.height)
}

#[test]
fn cli_writes_one_frame_per_relight_and_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let scene = lamps_scene(dir.path());
    let out = dir.path().join("frames");
    let report = dir.path().join("relight.json");
    let o = run(&[
        "relight",
        s(&scene),
        "--frames",
        "4",
        "--out",
        s(&out),
        "--report",
        s(&report),
        "--preset",
        "fast",
        "--width",
        "64",
        "--height",
        "48",
        "--quiet",
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout} {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    assert!(stdout.starts_with("Relit "), "{stdout}");
    assert!(stdout.contains("ms per relight"), "{stdout}");
    for frame in 0..4 {
        assert_eq!(
            png_size(&frame_path(&out, frame)),
            (64, 48),
            "frame {frame}"
        );
    }
    assert!(!frame_path(&out, 4).exists());
    // Fixed camera and exposure, moving light: the frames differ.
    let first = std::fs::read(frame_path(&out, 0)).unwrap();
    let last = std::fs::read(frame_path(&out, 3)).unwrap();
    assert_ne!(first, last);

    let json: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(json["command"], "relight");
    assert_eq!(json["parameters"]["frames"], 4);
    assert!(json["parameters"]["exposure"].as_f64().unwrap() > 0.0);
    assert!(json["build_seconds"].as_f64().unwrap() > 0.0);
    assert!(json["hierarchy"]["links"].as_u64().unwrap() > 0);
    let frames = json["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 4);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(frame["frame"], f);
        assert!(frame["seconds"].as_f64().unwrap() > 0.0);
        assert!(frame["iterations"].as_u64().unwrap() >= 1);
        assert_eq!(frame["warm_started"], f > 0);
        let power = frame["relative_power"].as_f64().unwrap();
        assert!((0.1..=1.0 + 1e-12).contains(&power), "{power}");
    }
    let mean = json["summary"]["mean_seconds"].as_f64().unwrap();
    assert!(mean > 0.0);
    assert!(json["summary"]["mean_warm_seconds"].as_f64().unwrap() > 0.0);
    assert!(json["time_seconds"]["total"].as_f64().unwrap() > 0.0);
}

#[test]
fn cli_moves_and_dims_an_analytic_light_progressively() {
    let dir = tempfile::tempdir().unwrap();
    let scene = lamps_scene(dir.path());
    let out = dir.path().join("frames");
    let report = dir.path().join("relight.json");
    // Emitters kept as they are (--dim 1); the point light moves and dims over frames 0..=2,
    // frame 3 holds it; one sweep per frame at most.
    let o = run(&[
        "relight",
        s(&scene),
        "--light",
        "point:0,0.5,0:0.2,0.2,0.2",
        "--frames",
        "4",
        "--hold",
        "1",
        "--dim",
        "1",
        "--move-light",
        "0:0.5,0.5,0.5",
        "--scale-light",
        "0:0.5",
        "--frame-budget",
        "0",
        "--errors",
        "--out",
        s(&out),
        "--report",
        s(&report),
        "--width",
        "64",
        "--height",
        "48",
        "--quiet",
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout} {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        stdout.contains("progressive within 0 ms per frame"),
        "{stdout}"
    );
    assert!(
        stdout.contains("error against the converged answer"),
        "{stdout}"
    );
    for frame in 0..4 {
        assert!(frame_path(&out, frame).exists(), "frame {frame}");
    }
    let json: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(json["parameters"]["frame_budget_ms"], 0.0);
    assert_eq!(json["parameters"]["move_light"][0], "0:0.5,0.5,0.5");
    assert_eq!(json["parameters"]["scale_light"][0], "0:0.5");
    assert!(json["initial_seconds"].as_f64().unwrap() > 0.0);
    let frames = json["frames"].as_array().unwrap();
    let field = |f: usize, name: &str| frames[f][name].as_f64().unwrap();
    // Frame 0 is the lighting the initial solve converged: nothing to do.
    assert_eq!(frames[0]["iterations"], 0);
    assert_eq!(field(0, "direct_seconds"), 0.0);
    assert!(field(0, "error_vs_converged") < 1e-3);
    // Frames 1 and 2 move the light: its shadow rays are traced again, one sweep each.
    for f in [1, 2] {
        assert_eq!(frames[f]["iterations"], 1, "frame {f}");
        assert!(field(f, "direct_seconds") > 0.0, "frame {f}");
        assert!(field(f, "error_vs_converged").is_finite());
        assert!(frames[f]["warm_started"].as_bool().unwrap());
    }
    // Frame 3 holds the light: no new shadow rays, the solve goes on and gets closer.
    assert_eq!(field(3, "direct_seconds"), 0.0);
    assert!(
        field(3, "error_vs_converged") < field(2, "error_vs_converged"),
        "{frames:?}"
    );
    let mean = json["summary"]["mean_error"].as_f64().unwrap();
    let max = json["summary"]["max_error"].as_f64().unwrap();
    assert!(mean > 0.0 && mean <= max, "{mean} {max}");

    // A scene without emitting triangles relights its analytic light alone.
    let plain = dir.path().join("plain.obj");
    std::fs::write(&plain, "v 0 0 0\nv 1 0 0\nv 0 0 -1\nf 1 2 3\n").unwrap();
    let o = run(&[
        "relight",
        s(&plain),
        "--light",
        "point:0.2,1,-0.2:1,1,1",
        "--frames",
        "2",
        "--scale-light",
        "0:0.25",
        "--out",
        s(&dir.path().join("plain_frames")),
        "--report",
        s(&report),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let frames = json["frames"].as_array().unwrap();
    assert!(frames[0]["direct_seconds"].as_f64().unwrap() > 0.0);
    assert_eq!(frames[1]["direct_seconds"].as_f64().unwrap(), 0.0);
}

#[test]
fn cli_mixes_precomputed_band_lights() {
    let dir = tempfile::tempdir().unwrap();
    let scene = lamps_scene(dir.path());
    let out = dir.path().join("frames");
    let report = dir.path().join("relight.json");
    let o = run(&[
        "relight",
        s(&scene),
        "--frames",
        "3",
        "--bands",
        "2",
        "--out",
        s(&out),
        "--report",
        s(&report),
        "--width",
        "32",
        "--height",
        "24",
        "--quiet",
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout} {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("band lights"), "{stdout}");
    for frame in 0..3 {
        assert!(frame_path(&out, frame).exists(), "frame {frame}");
    }
    let json: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let bands = json["bands"].as_u64().unwrap();
    assert!((1..=2).contains(&bands), "{bands}");
    assert!(json["lights_seconds"].as_f64().unwrap() > 0.0);
    for frame in json["frames"].as_array().unwrap() {
        // Mixing needs no sweep.
        assert_eq!(frame["iterations"], 0);
        assert_eq!(frame["warm_started"], false);
    }
    let o = run(&[
        "relight",
        s(&scene),
        "--frames",
        "2",
        "--bands",
        "100000",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--bands"));
}

#[test]
fn cli_fails_cleanly_on_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let scene = lamps_scene(dir.path());
    let out = dir.path().join("frames");
    let a_file = dir.path().join("lamps.mtl");
    let dark = dir.path().join("dark.obj");
    std::fs::write(&dark, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let missing = dir.path().join("missing.obj");
    let no_parent = dir.path().join("no-such-dir").join("frames");

    let base = |scene: &Path, out: &Path| -> Vec<String> {
        vec![
            "relight".into(),
            s(scene).into(),
            "--out".into(),
            s(out).into(),
            "--quiet".into(),
        ]
    };
    let cases: Vec<(Vec<String>, &str, i32)> = vec![
        (vec!["--frames".into(), "0".into()], "--frames", 1),
        (
            vec!["--frames".into(), "2".into(), "--dim".into(), "1.5".into()],
            "--dim",
            1,
        ),
        (
            vec!["--frames".into(), "2".into(), "--bins".into(), "0".into()],
            "--bins",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--exposure".into(),
                "-1".into(),
            ],
            "--exposure",
            1,
        ),
        (vec!["--frames".into(), "abc".into()], "--frames", 2),
        (vec![], "--frames", 2),
        (
            vec!["--frames".into(), "2".into(), "--hold".into(), "2".into()],
            "--hold",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--frame-budget".into(),
                "-5".into(),
            ],
            "--frame-budget",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--frame-budget".into(),
                "nan".into(),
            ],
            "--frame-budget",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--frame-budget".into(),
                "10".into(),
                "--bands".into(),
                "2".into(),
            ],
            "--frame-budget",
            2,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--move-light".into(),
                "0:1,2,3".into(),
            ],
            "no analytic light 0",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--light".into(),
                "point:0,0.5,0:1,1,1".into(),
                "--move-light".into(),
                "3:1,2,3".into(),
            ],
            "--move-light: no analytic light 3: the scene has 1 (numbered from 0: 0 point)",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--sky".into(),
                "1,1,1".into(),
                "--move-light".into(),
                "0:1,2,3".into(),
            ],
            "sky",
            1,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--move-light".into(),
                "zero:1,2,3".into(),
            ],
            "--move-light",
            2,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--scale-light".into(),
                "0:-1".into(),
            ],
            "--scale-light",
            2,
        ),
        (
            vec![
                "--frames".into(),
                "2".into(),
                "--light".into(),
                "point:0,0.5,0:1,1,1".into(),
                "--bands".into(),
                "2".into(),
            ],
            "--bands",
            1,
        ),
    ];
    for (extra, needle, code) in cases {
        let mut args = base(&scene, &out);
        args.extend(extra);
        let o = Command::new(env!("CARGO_BIN_EXE_antiradiance"))
            .args(&args)
            .output()
            .unwrap();
        expect_one_line_error(&o, needle, code);
        assert!(!out.exists(), "{needle}: the frame directory was created");
    }
    let frames2 = ["--frames", "2"];
    for (scene, out, needle) in [
        (&scene, &a_file, "lamps.mtl"),
        (&scene, &no_parent, "no-such-dir"),
        (&missing, &out, "missing.obj"),
        (&dark, &out, "dark.obj"),
    ] {
        let mut args = vec!["relight", s(scene), "--out", s(out), "--quiet"];
        args.extend(frames2);
        expect_one_line_error(&run(&args), needle, 1);
    }
    assert!(!out.exists());
    assert!(!no_parent.exists());
}

/// One `error:` line on stderr naming `needle`, exit code `code`, nothing on stdout.
fn expect_one_line_error(o: &Output, needle: &str, code: i32) {
    let err = String::from_utf8_lossy(&o.stderr);
    let errors: Vec<&str> = err.lines().filter(|l| !l.starts_with("warning:")).collect();
    assert_eq!(o.status.code(), Some(code), "{needle}: {err}");
    assert_eq!(errors.len(), 1, "{needle}: {err}");
    assert!(errors[0].starts_with("error: "), "{err}");
    assert!(errors[0].contains(needle), "{needle}: {err}");
    assert!(o.stdout.is_empty(), "{needle}");
}
