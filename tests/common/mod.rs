//! Helpers shared by the integration tests: running the binary, and checking a mesh is closed.
//! Each test file that needs them declares `mod common;`; not every file uses every function.
#![allow(dead_code)]

use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;
use std::process::{Command, Output};

use antiradiance::scene::Scene;
use glam::DVec3;

pub mod extremes;
pub mod lamps;

/// Runs the `antiradiance` binary with `args` and collects its output.
pub fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_antiradiance"))
        .args(args)
        .output()
        .expect("run the antiradiance binary")
}

/// A run's standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Asserts that triangles `range` of `scene` form a closed surface: every directed edge (by
/// exact corner positions) is matched by its reverse exactly once. `what` names the scene in
/// the panic message.
pub fn assert_closed(scene: &Scene, range: Range<usize>, what: &str) {
    // `+ 0.0` turns -0.0 into 0.0, so that equal coordinates get equal keys.
    let key = |p: DVec3| p.to_array().map(|x| (x + 0.0).to_bits());
    let mut edges: HashMap<([u64; 3], [u64; 3]), usize> = HashMap::new();
    for t in range {
        let c = scene.corners(t);
        for e in 0..3 {
            *edges.entry((key(c[e]), key(c[(e + 1) % 3]))).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &edges {
        assert_eq!(n, 1, "{what}: directed edge used {n} times");
        assert_eq!(
            edges.get(&(b, a)),
            Some(&1),
            "{what}: edge without an opposite twin"
        );
    }
}
