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

/// The exact header line of the per-element CSV (without the line break).
pub const ELEMENTS_CSV_HEADER: &str = "element,triangle,x0,y0,z0,x1,y1,z1,x2,y2,z2,area,r,g,b";

/// Writes the solved elements as CSV with the header [`ELEMENTS_CSV_HEADER`]: the solver's
/// own resolution inside the input triangles it split.
///
/// One row per element of `solution.elements` (see
/// [`crate::solve::SolverOptions::keep_elements`]), in the solver's order: its index, the input
/// triangle it is part of, its corners in the scene's frame and units, its area (units
/// squared), and the outgoing radiance B of its front face (RGB, W / (m^2 sr)). A solution
/// without elements (the dense solver, the path tracer) gets one row per patch, each its
/// patch's corners and radiance. Floats at full precision; a non-finite value is written as 0.
pub fn write_elements_csv(
    path: &Path,
    patches: &crate::mesh::Patches,
    solution: &Solution,
) -> Result<()> {
    let of_patches: Vec<crate::solve::solution::ElementRadiance>;
    let elements = if solution.elements.is_empty() {
        of_patches = (0..patches.len().min(solution.patch_radiance.len()))
            .map(|p| crate::solve::solution::ElementRadiance {
                triangle: patches.parent[p],
                corners: patches.corners[p].map(|c| patches.frame.world_from_unit(c)),
                radiance: solution.patch_radiance[p],
            })
            .collect();
        &of_patches
    } else {
        &solution.elements
    };
    let row = |k: usize, out: &mut String| {
        let e = &elements[k];
        let [a, b, c] = e.corners;
        let area = 0.5 * (b - a).cross(c - a).length();
        let _ = write!(out, "{},{}", k, e.triangle);
        for v in e.corners {
            let _ = write!(
                out,
                ",{},{},{}",
                format_f64(v.x),
                format_f64(v.y),
                format_f64(v.z)
            );
        }
        let r = e.radiance;
        let _ = writeln!(
            out,
            ",{},{},{},{}",
            format_f64(area),
            format_f64(r[0]),
            format_f64(r[1]),
            format_f64(r[2])
        );
    };
    write_atomic(path, |w| {
        writeln!(w, "{ELEMENTS_CSV_HEADER}")?;
        write_rows(w, elements.len(), 160, &row)
    })
}

/// Writes rows `0..n` in order, each formatted by `row` (about `row_bytes` long): blocks of
/// [`CSV_BLOCK`] rows formatted in parallel, [`CSV_BATCH`] blocks at a time (so the text held
/// at once stays bounded).
fn write_rows(
    w: &mut impl Write,
    n: usize,
    row_bytes: usize,
    row: &(impl Fn(usize, &mut String) + Sync),
) -> std::io::Result<()> {
    for batch in (0..n).step_by(CSV_BLOCK * CSV_BATCH) {
        let blocks: Vec<String> = (batch..n.min(batch + CSV_BLOCK * CSV_BATCH))
            .step_by(CSV_BLOCK)
            .collect::<Vec<usize>>()
            .into_par_iter()
            .map(|first| {
                let mut out = String::with_capacity(CSV_BLOCK * row_bytes);
                for k in first..n.min(first + CSV_BLOCK) {
                    row(k, &mut out);
                }
                out
            })
            .collect();
        for block in blocks {
            w.write_all(block.as_bytes())?;
        }
    }
    Ok(())
}

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
    write_atomic(path, |w| {
        write!(w, "{TRIANGLES_CSV_HEADER}")?;
        writeln!(w, "{}", if with_back { BACK_COLUMNS } else { "" })?;
        write_rows(w, scene.len(), 64, &row)
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
