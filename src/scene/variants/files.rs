//! Variant files: the OBJ + MTL + map writer, the map reader, the mapping of results back to
//! the original triangles, and the input's material files (copied to the output).

use super::*;
use crate::error::{Error, Result};
use crate::files::{format_f64, write_atomic};
use crate::scene::mtllib;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// Writes `variant` as `out` (OBJ), the MTL file next to it (same name, extension `mtl`) and
/// the map next to it ([`map_path`]: CSV, header [`MAP_CSV_HEADER`], one row per
/// [`MapRow`], areas at full precision).
///
/// The MTL file is `title` as comments followed by `mtl_text` (the input's material files,
/// verbatim). The OBJ file names it, then lists the vertices (shortest round-trip form) and
/// the faces, each with the `usemtl` of its triangle's material name when it has one; so
/// [`crate::scene::load_obj`] reads back the variant's triangles in order with the input's
/// materials and scene options apply as they did to the input.
///
/// With `emitters_as_materials` (the input's emitters came from a rule such as `--emit-above`,
/// which re-applied to the variant's own triangles would select others: a wall's sliver with
/// its three corners above the line), every emitting triangle is written with a material of
/// its own emission (`Ke`) and, when it has a material, albedo (`Kd`), named `emitter_N`,
/// appended to the MTL file (and a triangle without a material after one gets `no_material`,
/// which has no `Kd`): the variant then solves with the input's emitters and no rule.
///
/// Each file is written atomically, the MTL and map files first; on failure the files this
/// call created are removed again.
///
/// Errors: [`Error::Parameter`] for an `out` without a file name or ending in `.mtl`, or a
/// triangle whose material has no name; [`Error::Io`] (one line naming the file) when a file
/// cannot be written.
pub fn write_variant(
    variant: &Variant,
    out: &Path,
    mtl_text: &str,
    title: &str,
    emitters_as_materials: bool,
) -> Result<()> {
    let scene = &variant.scene;
    let mtl_path = out.with_extension("mtl");
    let map = map_path(out);
    if out.file_name().is_none() || mtl_path == out || map == out {
        return Err(Error::Parameter(format!(
            "variant: {} must be a file name not ending in .mtl",
            out.display()
        )));
    }
    let mtl_name = mtl_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut header = String::new();
    for line in title.lines() {
        let _ = writeln!(header, "# {line}");
    }

    let mut mtl = header.clone();
    mtl.push_str(mtl_text);
    if !mtl.ends_with('\n') {
        mtl.push('\n');
    }
    let (emitter_of, emitters) = emitter_materials(scene, emitters_as_materials, &mut mtl);
    let mut obj = header;
    let _ = writeln!(
        obj,
        "# vertices: {}, triangles: {}; map: {}",
        scene.positions.len(),
        scene.len(),
        map.file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default()
    );
    let _ = writeln!(obj, "mtllib {mtl_name}");
    for p in &scene.positions {
        let _ = writeln!(obj, "v {} {} {}", p.x, p.y, p.z);
    }
    // Each triangle's material name: its emitter material's, else its own, else (after an
    // emitter material) `no_material`.
    let emitter_names: Vec<String> = (0..emitters).map(|i| format!("emitter_{i}")).collect();
    let mut current: Option<&str> = None;
    for (t, f) in scene.triangles.iter().enumerate() {
        let name = match (emitter_of[t], material_of(scene, t)) {
            (Some(e), _) => Some(emitter_names[e].as_str()),
            (None, Some(m)) => Some(scene.material_names[m as usize].as_str()),
            (None, None) if emitters > 0 && current.is_some() => Some("no_material"),
            (None, None) => None,
        };
        if name != current {
            let Some(name) = name else {
                return Err(Error::Parameter(format!(
                    "variant: triangle {t} has no material after triangles that have one"
                )));
            };
            let _ = writeln!(obj, "usemtl {name}");
            current = Some(name);
        }
        let _ = writeln!(obj, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1);
    }

    let mut csv = String::with_capacity(variant.map.len() * 32);
    let _ = writeln!(csv, "{MAP_CSV_HEADER}");
    for r in &variant.map {
        let _ = writeln!(
            csv,
            "{},{},{},{}",
            r.variant,
            r.original,
            format_f64(r.area),
            if r.same_side { 1 } else { -1 }
        );
    }

    let existed = [mtl_path.exists(), map.exists()];
    let remove_new = || {
        for (path, existed) in [(&mtl_path, existed[0]), (&map, existed[1])] {
            if !existed {
                let _ = std::fs::remove_file(path);
            }
        }
    };
    let written = write_atomic(&mtl_path, |w| w.write_all(mtl.as_bytes()))
        .and_then(|()| write_atomic(&map, |w| w.write_all(csv.as_bytes())))
        .and_then(|()| write_atomic(out, |w| w.write_all(obj.as_bytes())));
    if written.is_err() {
        remove_new();
    }
    written
}

/// The emitter materials of [`write_variant`]: per triangle the index of its own (distinct
/// albedo, when the triangle has a material, and emission, bit for bit, in order of first use),
/// appended to `mtl` with `no_material` for triangles without one; none unless `on`. Returns
/// the indices and the number of emitter materials.
fn emitter_materials(scene: &Scene, on: bool, mtl: &mut String) -> (Vec<Option<usize>>, usize) {
    // A triangle without a material keeps taking the solve's --albedo.
    type Emitter = (Option<[f64; 3]>, [f64; 3]);
    let mut emitters: Vec<Emitter> = Vec::new();
    let emitter_of: Vec<Option<usize>> = (0..scene.len())
        .map(|t| {
            let e = scene.emission[t];
            if !on || e.iter().all(|&x| x == 0.0) {
                return None;
            }
            let key: Emitter = (material_of(scene, t).map(|_| scene.albedo[t]), e);
            let bits = |k: &Emitter| (k.0.map(|a| a.map(f64::to_bits)), k.1.map(f64::to_bits));
            Some(
                emitters
                    .iter()
                    .position(|k| bits(k) == bits(&key))
                    .unwrap_or_else(|| {
                        emitters.push(key);
                        emitters.len() - 1
                    }),
            )
        })
        .collect();
    if !emitters.is_empty() {
        // For triangles without a material after an emitter's (no `Kd`: the solve's --albedo).
        mtl.push_str("\nnewmtl no_material\n");
    }
    for (i, (kd, ke)) in emitters.iter().enumerate() {
        let _ = writeln!(mtl, "\nnewmtl emitter_{i}");
        if let Some(kd) = kd {
            let _ = writeln!(mtl, "Kd {} {} {}", kd[0], kd[1], kd[2]);
        }
        let _ = writeln!(mtl, "Ke {} {} {}", ke[0], ke[1], ke[2]);
    }
    (emitter_of, emitters.len())
}

/// Reads a map written by [`write_variant`].
///
/// Errors: [`Error::Io`] when the file cannot be read; [`Error::Scene`] for an empty file or
/// a header other than [`MAP_CSV_HEADER`]; [`Error::Parse`] (file and 1-based line) for a row
/// without four fields, an index that is not a whole number, an area that is not finite and
/// >= 0, or a facing other than 1 or -1.
pub fn read_map(path: &Path) -> Result<Vec<MapRow>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    match lines.next() {
        Some((_, h)) if h == MAP_CSV_HEADER => {}
        Some((line, h)) => {
            return Err(Error::Parse {
                path: path.to_path_buf(),
                line,
                message: format!("header '{h}' is not '{MAP_CSV_HEADER}'"),
            })
        }
        None => {
            return Err(Error::Scene {
                path: path.to_path_buf(),
                message: format!("empty file, expected the header '{MAP_CSV_HEADER}'"),
            })
        }
    }
    let mut rows = Vec::new();
    for (line, l) in lines {
        let bad = |message: String| Error::Parse {
            path: path.to_path_buf(),
            line,
            message,
        };
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        if f.len() != 4 {
            return Err(bad(format!("expected 4 fields, found {}", f.len())));
        }
        let index = |w: &str| {
            w.parse::<u32>()
                .map_err(|_| bad(format!("malformed triangle index '{w}'")))
        };
        let area: f64 = f[2]
            .parse()
            .ok()
            .filter(|a: &f64| a.is_finite() && *a >= 0.0)
            .ok_or_else(|| bad(format!("area '{}' must be a finite number >= 0", f[2])))?;
        let same_side = match f[3] {
            "1" => true,
            "-1" => false,
            other => return Err(bad(format!("facing '{other}' must be 1 or -1"))),
        };
        rows.push(MapRow {
            variant: index(f[0])?,
            original: index(f[1])?,
            area,
            same_side,
        });
    }
    Ok(rows)
}

/// Per original triangle, the area-weighted mean of `variant_radiance` over the variant
/// triangles covering it on its own side (the map's `same_side` rows; the plain mean of them
/// when their areas sum to 0, as for a degenerate original; 0 when it has none).
///
/// Errors: [`Error::Parameter`] when a row names a variant triangle beyond
/// `variant_radiance` or an original triangle beyond `originals`.
pub fn map_back(
    map: &[MapRow],
    originals: usize,
    variant_radiance: &[[f64; 3]],
) -> Result<Vec<[f64; 3]>> {
    let mut weighted = vec![[0.0f64; 3]; originals];
    let mut area = vec![0.0f64; originals];
    let mut plain = vec![[0.0f64; 3]; originals];
    let mut count = vec![0usize; originals];
    for r in map.iter().filter(|r| r.same_side) {
        let (v, o) = (r.variant as usize, r.original as usize);
        let (Some(b), true) = (variant_radiance.get(v), o < originals) else {
            return Err(Error::Parameter(format!(
                "map row ({v}, {o}) is outside {} variant and {originals} original triangles",
                variant_radiance.len()
            )));
        };
        for c in 0..3 {
            weighted[o][c] += r.area * b[c];
            plain[o][c] += b[c];
        }
        area[o] += r.area;
        count[o] += 1;
    }
    Ok((0..originals)
        .map(|o| {
            if area[o] > 0.0 {
                weighted[o].map(|x| x / area[o])
            } else if count[o] > 0 {
                plain[o].map(|x| x / count[o] as f64)
            } else {
                [0.0; 3]
            }
        })
        .collect())
}

/// The material files `obj_path` names (`mtllib`, resolved as [`crate::scene::load_obj`]
/// resolves them) that exist, in order.
///
/// Errors: [`Error::Io`] when `obj_path` cannot be read as text.
pub fn material_files(obj_path: &Path) -> Result<Vec<PathBuf>> {
    let text = std::fs::read_to_string(obj_path).map_err(|e| Error::io(obj_path, e))?;
    let dir = obj_path.parent().unwrap_or(Path::new("."));
    let mut files = Vec::new();
    for argument in text.lines().filter_map(mtllib::argument) {
        files.extend(
            mtllib::names(dir, argument)
                .into_iter()
                .map(|n| dir.join(n))
                .filter(|p| p.is_file()),
        );
    }
    Ok(files)
}

/// The text of the material files `obj_path` names ([`material_files`]), concatenated in
/// order; files that cannot be read are left out (the loader warns about them).
///
/// Errors: [`Error::Io`] when `obj_path` cannot be read as text.
pub fn material_text(obj_path: &Path) -> Result<String> {
    let mut out = String::new();
    for path in material_files(obj_path)? {
        if let Ok(mtl) = std::fs::read_to_string(&path) {
            out.push_str(mtl.strip_prefix('\u{feff}').unwrap_or(&mtl));
            if !out.ends_with('\n') {
                out.push('\n');
            }
        }
    }
    Ok(out)
}
