//! Stage 5: write results to disk (per-triangle CSV, coloured PLY mesh, JSON reports) and read
//! the CSV back.
//!
//! Every writer is atomic: the bytes go to a temporary file in the target's directory, which is
//! flushed, synced and renamed over the target only once everything was written. A failed write
//! (missing directory, full disk, ...) therefore never leaves a partial file at the target path,
//! and any previous file there is kept intact. Errors are one line naming the target path.
//!
//! No NaN or infinity ever reaches a file: every number is passed through
//! [`crate::solve::solution::sanitize`] (non-finite becomes 0) even though solvers already sanitize.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};
use crate::mesh::Patches;
pub mod render;

use crate::scene::Scene;
use crate::solve::solution::{sanitize, Solution};

/// The exact header line of the per-triangle CSV (without the line break).
pub const TRIANGLES_CSV_HEADER: &str = "index,area,emissive,r,g,b";

/// Writes a file atomically: `fill` writes the content into a buffered temporary file next to
/// `path`, which is then synced and renamed to `path`.
///
/// On any failure the temporary file is removed, nothing appears at `path` (an existing file
/// there is left untouched) and the error is a one-line [`Error::Io`] naming `path`.
/// Precondition: `path` names a file (not a directory); its directory must exist.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let file_name = path.file_name().ok_or_else(|| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"),
        )
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let (tmp_path, file) = create_temp(&dir, file_name).map_err(|e| Error::io(path, e))?;
    let written = (|| {
        let mut writer = BufWriter::new(file);
        fill(&mut writer)?;
        let file = writer.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&tmp_path, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp_path);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// Creates a fresh temporary file `.<name>.tmp-<pid>-<n>` in `dir` (never overwrites one).
fn create_temp(dir: &Path, name: &std::ffi::OsStr) -> std::io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(".tmp-{}-{n}", std::process::id()));
        let tmp_path = dir.join(tmp_name);
        match File::options().write(true).create_new(true).open(&tmp_path) {
            Ok(f) => return Ok((tmp_path, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

/// Formats an f64 so that it parses back to the same value: plain decimal for moderate
/// magnitudes, scientific notation otherwise. Non-finite values are written as 0.
pub fn format_f64(x: f64) -> String {
    let x = sanitize(x);
    let a = x.abs();
    if x == 0.0 {
        "0".to_string()
    } else if (1e-4..1e15).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Writes the per-input-triangle results as CSV with the header `index,area,emissive,r,g,b`.
///
/// One row per input triangle of `scene`, in input order: index (0-based), area in the scene's
/// units squared, 1 if the triangle emits else 0, then the outgoing radiance B (RGB,
/// W / (m^2 sr), `solution.triangle_radiance`). Floats are written at full precision (they
/// round-trip through [`read_triangles_csv`]); a non-finite value is written as 0.
/// Precondition: `solution.triangle_radiance.len() == scene.len()` (an error otherwise).
pub fn write_triangles_csv(path: &Path, scene: &Scene, solution: &Solution) -> Result<()> {
    if solution.triangle_radiance.len() != scene.len() {
        return Err(Error::Parameter(format!(
            "{}: solution has {} triangle values but the scene has {} triangles",
            path.display(),
            solution.triangle_radiance.len(),
            scene.len()
        )));
    }
    write_atomic(path, |w| {
        writeln!(w, "{TRIANGLES_CSV_HEADER}")?;
        for (t, b) in solution.triangle_radiance.iter().enumerate() {
            writeln!(
                w,
                "{},{},{},{},{},{}",
                t,
                format_f64(scene.area(t)),
                u8::from(scene.is_emitter(t)),
                format_f64(b[0]),
                format_f64(b[1]),
                format_f64(b[2])
            )?;
        }
        Ok(())
    })
}

/// Reads the per-triangle radiance (r, g, b columns) back from a CSV written by
/// [`write_triangles_csv`], in row order.
///
/// The header must contain the columns `index`, `r`, `g` and `b` (extra columns are ignored);
/// rows must have every column, the index must count 0, 1, 2, ... and r, g, b must be finite
/// numbers. Blank lines are skipped. Errors are one line naming the file and, for a bad row,
/// the 1-based line (`file:line: message`).
pub fn read_triangles_csv(path: &Path) -> Result<Vec<[f64; 3]>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let parse_err = |line: usize, message: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    let Some((header_line, header)) = lines.next() else {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: format!("empty file, expected the header '{TRIANGLES_CSV_HEADER}'"),
        });
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |name: &str| {
        columns.iter().position(|c| *c == name).ok_or_else(|| {
            parse_err(
                header_line,
                format!("header has no '{name}' column (expected '{TRIANGLES_CSV_HEADER}')"),
            )
        })
    };
    let index_col = find("index")?;
    let rgb_cols = [find("r")?, find("g")?, find("b")?];

    let mut values = Vec::new();
    for (line_no, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != columns.len() {
            return Err(parse_err(
                line_no,
                format!(
                    "expected {} comma-separated fields, found {}",
                    columns.len(),
                    fields.len()
                ),
            ));
        }
        let index: usize = fields[index_col].parse().map_err(|_| {
            parse_err(
                line_no,
                format!("malformed triangle index '{}'", fields[index_col]),
            )
        })?;
        if index != values.len() {
            return Err(parse_err(
                line_no,
                format!(
                    "triangle index {index} out of order, expected {}",
                    values.len()
                ),
            ));
        }
        let mut rgb = [0.0; 3];
        for (k, &col) in rgb_cols.iter().enumerate() {
            let field = fields[col];
            let x: f64 = field.parse().map_err(|_| {
                parse_err(
                    line_no,
                    format!("malformed number '{field}' in column {}", columns[col]),
                )
            })?;
            if !x.is_finite() {
                return Err(parse_err(
                    line_no,
                    format!("value '{field}' in column {} is not finite", columns[col]),
                ));
            }
            rgb[k] = x;
        }
        values.push(rgb);
    }
    Ok(values)
}

/// Writes the patches as a coloured triangle mesh in ASCII PLY (opens in MeshLab and Blender).
///
/// Vertices are in WORLD coordinates (`patches.frame.world_from_unit`), as doubles, with
/// per-vertex `red green blue` (uchar): [`render::tone_map`] at `exposure` of the area-weighted
/// mean B of the faces sharing the vertex. Corners are welded where positions are identical,
/// the faces have normals within 30 degrees of each other and the same emitter status (so
/// colours stay sharp across creases and around lights); degenerate patches keep their own
/// three vertices. Each patch becomes one face, in patch order (degenerate ones included), with
/// float properties `radiance_r radiance_g radiance_b` = the raw B (W / (m^2 sr); non-finite
/// written as 0, beyond the f32 range clamped to it).
///
/// `exposure` multiplies B before tone mapping (see [`render::auto_exposure`]); a non-finite
/// or non-positive value is an [`Error::Parameter`].
/// Precondition: `solution.patch_radiance.len() == patches.len()` (an error otherwise).
pub fn write_ply(path: &Path, patches: &Patches, solution: &Solution, exposure: f64) -> Result<()> {
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
    let welded = render::weld(patches, solution);
    write_atomic(path, |w| {
        writeln!(w, "ply")?;
        writeln!(w, "format ascii 1.0")?;
        writeln!(
            w,
            "comment antiradiance: world coordinates; vertex colour = tone-mapped B (exposure {}); face radiance_* = raw B in W/(m^2 sr)",
            format_f64(exposure)
        )?;
        writeln!(w, "element vertex {}", welded.positions.len())?;
        for axis in ["x", "y", "z"] {
            writeln!(w, "property double {axis}")?;
        }
        for channel in ["red", "green", "blue"] {
            writeln!(w, "property uchar {channel}")?;
        }
        writeln!(w, "element face {}", patches.len())?;
        writeln!(w, "property list uchar int vertex_indices")?;
        for channel in ["r", "g", "b"] {
            writeln!(w, "property float radiance_{channel}")?;
        }
        writeln!(w, "end_header")?;
        for (v, p) in welded.positions.iter().enumerate() {
            let world = patches.frame.world_from_unit(*p);
            let [r, g, b] = render::tone_map(welded.radiance[v], exposure);
            writeln!(
                w,
                "{} {} {} {r} {g} {b}",
                format_f64(world.x),
                format_f64(world.y),
                format_f64(world.z)
            )?;
        }
        for (p, corners) in welded.faces.iter().enumerate() {
            let b = solution.patch_radiance[p].map(to_f32);
            writeln!(
                w,
                "3 {} {} {} {} {} {}",
                corners[0], corners[1], corners[2], b[0], b[1], b[2]
            )?;
        }
        Ok(())
    })
}

/// An f64 as a finite f32 (non-finite becomes 0, out of range clamps to the f32 range).
fn to_f32(x: f64) -> f32 {
    sanitize(x).clamp(f32::MIN as f64, f32::MAX as f64) as f32
}

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
