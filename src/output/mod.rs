//! Stage 5: write results to disk (per-triangle CSV, coloured PLY mesh, binary glTF, JSON
//! reports) and read
//! the CSV back.
//!
//! Every writer is atomic: the bytes go to a temporary file in the target's directory, which is
//! flushed, synced and renamed over the target only once everything was written. A failed write
//! (missing directory, full disk, ...) therefore never leaves a partial file at the target path,
//! and any previous file there is kept intact. Errors are one line naming the target path.
//!
//! No NaN or infinity ever reaches a file: every number is passed through
//! [`crate::solve::solution::sanitize`] (non-finite becomes 0) even though solvers already sanitize.

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};
use crate::mesh::Patches;
use crate::solve::solution::Solution;

pub mod csv;
pub mod gltf;
pub mod ply;
pub mod render;

pub use crate::files::{format_f64, write_atomic};
pub use csv::{
    read_triangles_csv, write_elements_csv, write_triangles_csv, ELEMENTS_CSV_HEADER,
    TRIANGLES_CSV_HEADER,
};
pub use gltf::{write_baked_glb, write_scene_glb};
pub use ply::write_ply;

/// Writes a JSON value pretty-printed (two-space indentation) with a final line break.
///
/// serde_json cannot represent NaN or infinity (they serialize as `null`), so callers should
/// sanitize numbers they want to keep.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        writeln!(w)
    })
}

/// The inputs every per-patch writer ([`write_ply`], [`write_baked_glb`]) checks before writing
/// to `path`: one value of `solution` per patch, and an `exposure` that is finite and > 0.
/// Errors are an [`Error::Parameter`] naming `path`.
pub(crate) fn check_per_patch(
    path: &Path,
    patches: &Patches,
    solution: &Solution,
    exposure: f64,
) -> Result<()> {
    if solution.patch_radiance.len() != patches.len() {
        return Err(Error::Parameter(format!(
            "{}: solution has {} patch values but there are {} patches",
            path.display(),
            solution.patch_radiance.len(),
            patches.len()
        )));
    }
    if !(exposure.is_finite() && exposure > 0.0) {
        return Err(Error::Parameter(format!(
            "{}: exposure {exposure} must be finite and > 0",
            path.display()
        )));
    }
    Ok(())
}
