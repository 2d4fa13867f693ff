//! The baked `.glb` and the scene `.glb` the project writes pass the Khronos glTF validator
//! (npm package `gltf-validator`) with no errors and no warnings. Runs when `node` and `npm`
//! are on the PATH (the validator is installed into a temporary folder); skipped otherwise, or
//! when the package cannot be installed.

mod common;

use std::path::Path;
use std::process::Command;

fn have(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

const SCRIPT: &str = r#"
const v = require('gltf-validator');
const fs = require('fs');
const f = process.argv[2];
v.validateBytes(new Uint8Array(fs.readFileSync(f)), { maxIssues: 100 }).then(r => {
  console.log(JSON.stringify({
    errors: r.issues.numErrors, warnings: r.issues.numWarnings,
    messages: r.issues.messages.filter(m => m.severity <= 1).map(m => m.code + ' ' + m.pointer + ': ' + m.message)
  }));
}).catch(e => { console.error(String(e)); process.exit(2); });
"#;

fn lights() -> Vec<antiradiance::scene::lights::Light> {
    use antiradiance::scene::lights::Light;
    use glam::DVec3;
    vec![
        Light::Point {
            position: DVec3::new(278.0, 400.0, 279.0),
            intensity: [3e4, 2e4, 1e4],
        },
        Light::Spot {
            position: DVec3::new(100.0, 500.0, 100.0),
            direction: DVec3::new(0.3, -1.0, 0.2),
            intensity: [5e4; 3],
            inner: 0.3,
            outer: 0.6,
        },
        Light::Sun {
            direction: DVec3::new(-1.0, -2.0, -0.5),
            irradiance: [2.0, 2.0, 1.5],
        },
    ]
}

fn validate(tools: &Path, file: &Path) -> serde_json::Value {
    let o = Command::new("node")
        .current_dir(tools)
        .arg("validate.js")
        .arg(file)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn written_glb_files_pass_the_khronos_validator() {
    if !have("node") || !have("npm") {
        eprintln!("skipped: node or npm is not installed");
        return;
    }
    let tools = tempfile::tempdir().unwrap();
    let install = Command::new("npm")
        .current_dir(tools.path())
        .args([
            "install",
            "--silent",
            "--no-audit",
            "--no-fund",
            "--no-save",
            "gltf-validator@2.0.0-dev.3.10",
        ])
        .output();
    match install {
        Ok(o) if o.status.success() => {}
        Ok(o) => {
            eprintln!(
                "skipped: npm could not install gltf-validator: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            return;
        }
        Err(e) => {
            eprintln!("skipped: npm did not run: {e}");
            return;
        }
    }
    std::fs::write(tools.path().join("validate.js"), SCRIPT).unwrap();

    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("box.glb");
    let baked = dir.path().join("baked.glb");
    let o = common::run(&[
        "scene",
        "cornell-box",
        "--out",
        common::s(&scene),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    let o = common::run(&[
        "solve",
        common::s(&scene),
        "--light",
        "point:278,400,279:30000,30000,30000",
        "--max-edge",
        "150",
        "--gltf",
        common::s(&baked),
        "-q",
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    // A scene with every punctual light kind.
    let mut lit = antiradiance::scene::generated::cornell_box();
    lit.lights = lights();
    let lit_path = dir.path().join("lit.glb");
    antiradiance::output::gltf::write_scene_glb(&lit_path, &lit).unwrap();
    for file in [&scene, &baked, &lit_path] {
        let r = validate(tools.path(), file);
        assert_eq!(r["errors"], 0, "{}: {r}", file.display());
        assert_eq!(r["warnings"], 0, "{}: {r}", file.display());
    }
}
