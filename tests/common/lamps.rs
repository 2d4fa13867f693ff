//! The lamps scene of the relighting tests (`tests/relight.rs`, `tests/relight_cli.rs`).

use std::path::{Path, PathBuf};

/// A floor under two lamps of different materials (lampA at x < 0, lampB at x > 0) under a
/// white ceiling, plus a triangle without a material and one with an undefined material: 10
/// triangles.
///
/// Triangles in file order: 0 no material (before any `usemtl`), 1-2 floor (white, facing up),
/// 3-4 lampA (facing down), 5-6 lampB (facing down), 7-8 ceiling (white, facing down), 9 the
/// undefined material `ghost`. The MTL file also defines `unused`, which no face uses.
pub const LAMPS_OBJ: &str = "\
mtllib lamps.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
v -0.8 1 -0.2
v -0.4 1 -0.2
v -0.4 1 0.2
v -0.8 1 0.2
v 0.4 1 -0.2
v 0.8 1 -0.2
v 0.8 1 0.2
v 0.4 1 0.2
v -1 1.01 -1
v 1 1.01 -1
v 1 1.01 1
v -1 1.01 1
v 3 0 0
v 4 0 0
v 3 0 1
v 3 0 2
v 4 0 2
v 3 0 3
f 17 19 18
usemtl white
f 1 4 3 2
usemtl lampA
f 5 6 7 8
usemtl lampB
f 9 10 11 12
usemtl white
f 13 14 15 16
usemtl ghost
f 20 22 21
";

pub const LAMPS_MTL: &str = "\
newmtl white
Kd 0.7 0.7 0.7
newmtl lampA
Kd 0.1 0.1 0.1
Ke 5 5 5
newmtl lampB
Kd 0.1 0.1 0.1
Ke 1 1 1
newmtl unused
Kd 0.5 0.5 0.5
";

/// Writes the lamps scene into `dir`; returns the OBJ path.
pub fn lamps_scene(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("lamps.mtl"), LAMPS_MTL).unwrap();
    let path = dir.join("lamps.obj");
    std::fs::write(&path, LAMPS_OBJ).unwrap();
    path
}
