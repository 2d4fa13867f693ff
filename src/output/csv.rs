//! The per-triangle CSV (`index,area,emissive,r,g,b`): writing and reading it back.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::files::{format_f64, write_atomic};
use crate::scene::Scene;
use crate::solve::solution::Solution;

/// The exact header line of the per-triangle CSV (without the line break).
pub const TRIANGLES_CSV_HEADER: &str = "index,area,emissive,r,g,b";

/// The columns added to [`TRIANGLES_CSV_HEADER`] when some triangle is two-sided: the back
/// face's outgoing radiance (0 for one-sided triangles).
pub const BACK_COLUMNS: &str = ",back_r,back_g,back_b";

/// Writes the per-input-triangle results as CSV with the header `index,area,emissive,r,g,b`
/// (and [`BACK_COLUMNS`] when the solution has back faces).
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
    let back = &solution.triangle_radiance_back;
    let with_back = back.len() == scene.len();
    // Rows formatted in parallel, a block of rows per task, and written in order a batch of
    // blocks at a time (so the text held at once stays bounded).
    let row = |t: usize, out: &mut String| {
        let b = solution.triangle_radiance[t];
        // Writing to a String cannot fail.
        let _ = write!(
            out,
            "{},{},{},{},{},{}",
            t,
            format_f64(scene.area(t)),
            u8::from(scene.is_emitter(t)),
            format_f64(b[0]),
            format_f64(b[1]),
            format_f64(b[2])
        );
        if with_back {
            let k = back[t];
            let _ = write!(
                out,
                ",{},{},{}",
                format_f64(k[0]),
                format_f64(k[1]),
                format_f64(k[2])
            );
        }
        out.push('\n');
    };
    let n = scene.len();
    write_atomic(path, |w| {
        write!(w, "{TRIANGLES_CSV_HEADER}")?;
        writeln!(w, "{}", if with_back { BACK_COLUMNS } else { "" })?;
        for batch in (0..n).step_by(CSV_BLOCK * CSV_BATCH) {
            let blocks: Vec<String> = (batch..n.min(batch + CSV_BLOCK * CSV_BATCH))
                .step_by(CSV_BLOCK)
                .collect::<Vec<usize>>()
                .into_par_iter()
                .map(|first| {
                    let mut out = String::with_capacity(CSV_BLOCK * 64);
                    for t in first..n.min(first + CSV_BLOCK) {
                        row(t, &mut out);
                    }
                    out
                })
                .collect();
            for block in blocks {
                w.write_all(block.as_bytes())?;
            }
        }
        Ok(())
    })
}

/// Rows of the per-triangle CSV one task formats.
const CSV_BLOCK: usize = 8192;

/// Blocks of rows formatted before they are written.
const CSV_BATCH: usize = 64;

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
