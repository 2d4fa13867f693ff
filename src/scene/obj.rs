//! OBJ and MTL reading: a line-level scan of every file first (every error is
//! `file:line: message`; tobj 4.0.5 panics on short colour lines, so it never sees one), then
//! tobj for the faces and materials.

use crate::error::{Error, Result, Warning, WarningKind};
use crate::scene::mtllib;
use crate::scene::*;
use glam::DVec3;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// Reads an OBJ file (and the MTL files it names) into a [`Scene`].
///
/// Errors name the file and, where known, the line: missing or unreadable file, empty or binary
/// file, malformed numbers, NaN or infinite coordinates, face index out of range, colour lines with
/// fewer than three numbers, albedo outside [0, 1], negative emission, no non-degenerate triangle.
/// These are warnings (in `Scene::warnings`): an albedo of 1 (a white `Kd 1 1 1`, lowered to
/// [`crate::scene::ALBEDO_MAX`]: the model needs albedo below 1), a transparent material (`d`
/// below 1, taken as opaque), a file that is not UTF-8 (read as Latin-1), a concave polygon
/// that cannot be ear-clipped (fanned), a missing MTL file, a `usemtl` naming a material no MTL
/// file defines, triangles that repeat an earlier one ([`Scene::duplicates`]) and a scene
/// without emitters.
///
/// Only what the model uses is read: vertex positions (`v x y z`, optionally `w`, vertex colours
/// ignored), faces (position indices; texture and normal references are ignored), `mtllib`,
/// `usemtl`, and the `newmtl`, `Kd` and `Ke` lines of material files. Comments may follow `#` on
/// any line; words may be separated by spaces or tabs; lines may end in CRLF.
pub fn load_obj(path: &Path, options: &SceneOptions) -> Result<Scene> {
    options.validate()?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let mut warnings = Vec::new();
    let text = as_text(path, &bytes, &mut warnings)?;
    let joined = join_continued_lines(&text);
    let text = joined.as_deref().unwrap_or(&text);
    let obj_scan = scan_obj(path, text)?;

    let mtl_texts = read_materials(path, &obj_scan, &mut warnings)?;
    let (models, materials) = parse_with_tobj(path, &obj_scan, &mtl_texts)?;

    let mut scene = Scene {
        path: path.to_path_buf(),
        material_names: materials.iter().map(|m| m.name.clone()).collect(),
        ..Scene::default()
    };
    for (i, raw) in text.lines().enumerate() {
        match SceneCamera::parse(raw) {
            Some(Ok(camera)) => scene.camera = Some(camera),
            Some(Err(message)) => warnings.push(Warning::in_file(
                WarningKind::Camera,
                path,
                Some(i + 1),
                message,
            )),
            None => {}
        }
    }
    let default_albedo = [options.default_albedo; 3];
    let mut not_simple = 0usize;
    // For each triangle, its corners' places in the face it was cut from.
    let mut polygon_corners: Vec<[u32; 3]> = Vec::with_capacity(obj_scan.triangle_count);
    for model in &models {
        let mesh = &model.mesh;
        let base = scene.positions.len() as u32;
        for p in mesh.positions.chunks_exact(3) {
            scene.positions.push(DVec3::new(p[0], p[1], p[2]));
        }
        let material_id = mesh
            .material_id
            .filter(|&i| i < materials.len())
            .map(|i| i as u32);
        let material = mesh.material_id.and_then(|i| materials.get(i));
        let albedo = material
            .and_then(|m| m.diffuse)
            .map(|d| [d[0], d[1], d[2]])
            .unwrap_or(default_albedo);
        let emission = material
            .and_then(|m| m.emissive)
            .map(|e| [e[0], e[1], e[2]])
            .unwrap_or([0.0; 3]);
        // Faces as tobj read them (every face a triangle when `face_arities` is empty),
        // triangulated here: fans for convex polygons, ear clipping for concave ones.
        let all_triangles = mesh.face_arities.is_empty();
        let faces = if all_triangles {
            mesh.indices.len() / 3
        } else {
            mesh.face_arities.len()
        };
        let mut start = 0usize;
        for f in 0..faces {
            let arity = if all_triangles {
                3
            } else {
                mesh.face_arities[f] as usize
            };
            let Some(face) = mesh.indices.get(start..start + arity) else {
                break;
            };
            start += arity;
            let corners: Vec<DVec3> = face
                .iter()
                .map(|&i| scene.positions[(base + i) as usize])
                .collect();
            let (triangles, how) = crate::geometry::polygon::triangulate(&corners);
            not_simple += usize::from(how == crate::geometry::polygon::Triangulated::NotSimple);
            for [a, b, c] in triangles {
                scene
                    .triangles
                    .push([base + face[a], base + face[b], base + face[c]]);
                polygon_corners.push([a as u32, b as u32, c as u32]);
                scene.albedo.push(albedo);
                scene.emission.push(emission);
                scene.material.push(material_id);
            }
        }
    }
    if scene.triangles.len() != obj_scan.triangle_count {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: format!(
                "internal: read {} triangles but the file has {}",
                scene.triangles.len(),
                obj_scan.triangle_count
            ),
        });
    }

    if not_simple > 0 {
        warnings.push(Warning::in_file(
            WarningKind::Polygon,
            path,
            None,
            format!(
                "concave polygons that could not be ear-clipped (crossing themselves, or more than {} corners): {not_simple}, fanned from their first corner; their triangles may cover area outside them",
                crate::geometry::polygon::MAX_EAR_CLIPPED_CORNERS,
            ),
        ));
    }
    super::texture::apply_obj_textures(&mut scene, path, text, &polygon_corners, &mut warnings);
    if let Some(y) = options.emit_above {
        for t in 0..scene.len() {
            if scene.corners(t).iter().all(|p| p.y > y) {
                scene.emission[t] = [options.emission; 3];
            }
        }
    }

    if scene.is_empty() {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: "no triangles (the file has no faces)".into(),
        });
    }
    if scene.degenerate_count() == scene.len() {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: format!(
                "no non-degenerate triangle among {} (all have zero area)",
                scene.len()
            ),
        });
    }
    let duplicates = scene.duplicates();
    if let Some(t) = duplicates.iter().position(Option::is_some) {
        let count = duplicates.iter().filter(|d| d.is_some()).count();
        let twin = duplicates[t].unwrap_or(0);
        let differ = duplicates.iter().enumerate().any(|(t, d)| {
            d.is_some_and(|u| {
                scene.albedo[t] != scene.albedo[u as usize]
                    || scene.emission[t] != scene.emission[u as usize]
            })
        });
        warnings.push(Warning::in_file(WarningKind::Duplicate, path, None, format!(
            "{} an earlier triangle (same corners, same orientation; first: triangle {t} repeats {twin}); each is solved once and reported with its first copy's radiance{}",
            if count == 1 { "1 triangle repeats".to_string() } else { format!("{count} triangles repeat") },
            if differ { " (some copies have other materials: the first copy's material is used)" } else { "" }
        )));
    }
    if scene.emitter_count() == 0 {
        warnings.push(Warning::in_file(
            WarningKind::NoEmitter,
            path,
            None,
            "no emitting triangle (no Ke in materials, no SceneOptions::emit_above match) and no light; the answer is all zero",
        ));
    }
    scene.warnings = warnings;
    Ok(scene)
}

/// The material step of [`load_obj`]: every MTL file the OBJ names, checked line by line
/// first (tobj panics on short colour lines) and reduced to the lines we use (tobj drops a
/// whole file over one line it cannot parse); missing files and undefined materials become
/// warnings. Returns the reduced texts, in the order the files are named.
fn read_materials(
    path: &Path,
    obj_scan: &ObjScan,
    warnings: &mut Vec<Warning>,
) -> Result<Vec<String>> {
    let base_dir = path.parent().unwrap_or(Path::new("."));
    let mut mtl_texts: Vec<String> = Vec::new();
    let mut defined: std::collections::HashSet<String> = Default::default();
    let mut mtl_missing = false;
    for (line, name) in &obj_scan.mtllibs {
        for name in mtllib::names(base_dir, name) {
            let mtl_path = base_dir.join(name);
            match std::fs::read(&mtl_path) {
                Ok(mtl_bytes) => {
                    let mtl_text = as_text(&mtl_path, &mtl_bytes, warnings)?;
                    let mtl_scan = scan_mtl(&mtl_path, &mtl_text)?;
                    warnings.extend(mtl_scan.warnings);
                    defined.extend(mtl_scan.names);
                    mtl_texts.push(mtl_scan.clean);
                }
                Err(e) => {
                    mtl_missing = true;
                    warnings.push(Warning::in_file(
                        WarningKind::Material,
                        path,
                        Some(*line),
                        format!(
                            "material file {} cannot be read ({e}); using SceneOptions::default_albedo for its materials",
                            mtl_path.display()
                        ),
                    ))
                }
            }
        }
    }
    if !mtl_missing {
        let mut reported = std::collections::HashSet::new();
        for (line, name) in &obj_scan.usemtls {
            if !defined.contains(name) && reported.insert(name.as_str()) {
                warnings.push(Warning::in_file(
                    WarningKind::Material,
                    path,
                    Some(*line),
                    format!(
                        "material '{name}' is not defined in any material file; using SceneOptions::default_albedo"
                    ),
                ));
            }
        }
    }

    Ok(mtl_texts)
}

/// The geometry step of [`load_obj`]: tobj reads the reduced text (every material file first,
/// named by its index, all vertices, then faces and `usemtl` lines with absolute position
/// indices only) with fan triangulation, models in file order.
fn parse_with_tobj(
    path: &Path,
    obj_scan: &ObjScan,
    mtl_texts: &[String],
) -> Result<(Vec<tobj::Model>, Vec<tobj::Material>)> {
    let mut clean = String::with_capacity(obj_scan.vertices.len() + obj_scan.body.len() + 64);
    for i in 0..mtl_texts.len() {
        clean.push_str(&format!("mtllib {i}\n"));
    }
    clean.push_str(&obj_scan.vertices);
    clean.push_str(&obj_scan.body);
    let load_options = tobj::LoadOptions {
        // Polygons are triangulated by `load_obj` (tobj fans them, which is wrong for
        // concave ones).
        triangulate: false,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let mtl_for = |p: &Path| -> tobj::MTLLoadResult {
        let index = p.to_str().and_then(|k| k.trim().parse::<usize>().ok());
        match index.and_then(|i| mtl_texts.get(i)) {
            Some(mtl_text) => tobj::load_mtl_buf(&mut mtl_text.as_bytes()),
            None => Err(tobj::LoadError::OpenFileFailed),
        }
    };
    let (models, materials) = tobj::load_obj_buf(&mut clean.as_bytes(), &load_options, mtl_for)
        .map_err(|e| Error::Scene {
            path: path.to_path_buf(),
            message: format!("cannot parse OBJ: {e}"),
        })?;
    let materials = materials.unwrap_or_default();
    Ok((models, materials))
}

/// The text with OBJ's continued lines joined (a line ending in `\` goes on in the next
/// one), or `None` when no line is continued. A joined line keeps the number of its first
/// line, and the lines it took are left empty after it, so every other line keeps its number.
pub(crate) fn join_continued_lines(text: &str) -> Option<String> {
    let continued = |line: &str| line.trim_end_matches(['\r', '\n']).ends_with('\\');
    if !text.split_inclusive('\n').any(continued) {
        return None;
    }
    let mut out = String::with_capacity(text.len());
    let mut taken = 0;
    for line in text.split_inclusive('\n') {
        let body = line.trim_end_matches(['\r', '\n']);
        if let Some(head) = body.strip_suffix('\\') {
            out.push_str(head);
            out.push(' ');
            taken += 1;
        } else {
            out.push_str(body);
            for _ in 0..=taken {
                out.push('\n');
            }
            taken = 0;
        }
    }
    Some(out)
}

/// The text of a scene file: UTF-8 (a byte-order mark dropped), or, when it is not valid
/// UTF-8, every byte read as the Latin-1 character of that code (some exporters write names
/// and comments in Latin-1), with a warning naming the first line that is not UTF-8. Binary
/// content (a NUL byte) is a one-line error.
pub(crate) fn as_text<'a>(
    path: &Path,
    bytes: &'a [u8],
    warnings: &mut Vec<Warning>,
) -> Result<std::borrow::Cow<'a, str>> {
    if bytes.contains(&0) {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: "binary file (contains NUL bytes), expected text".into(),
        });
    }
    match std::str::from_utf8(bytes) {
        Ok(text) => Ok(text.strip_prefix('\u{feff}').unwrap_or(text).into()),
        Err(e) => {
            let line = bytes[..e.valid_up_to()]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1;
            warnings.push(Warning::in_file(
                WarningKind::Encoding,
                path,
                Some(line),
                "not UTF-8 text: the file is read as Latin-1",
            ));
            Ok(bytes
                .iter()
                .map(|&b| char::from(b))
                .collect::<String>()
                .into())
        }
    }
}

/// What the line-level scan of an OBJ file learned.
pub(crate) struct ObjScan {
    /// `mtllib` lines: (line number, the rest of the line).
    mtllibs: Vec<(usize, String)>,
    /// `usemtl` lines: (line number, material name).
    usemtls: Vec<(usize, String)>,
    /// Number of triangles after fan triangulation.
    triangle_count: usize,
    /// Every vertex as `v x y z` (w applied, colours dropped), one per line, in file order.
    vertices: String,
    /// Faces (absolute position indices only) and `usemtl` lines, in file order.
    body: String,
}

impl ObjScan {
    /// An empty scan with room for the reduction of `bytes` bytes of OBJ text.
    fn with_capacity(bytes: usize) -> ObjScan {
        ObjScan {
            mtllibs: Vec::new(),
            usemtls: Vec::new(),
            triangle_count: 0,
            vertices: String::with_capacity(bytes / 2),
            body: String::with_capacity(bytes / 2),
        }
    }
}

pub(crate) fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> Error {
    Error::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// A line without its comment, trimmed.
pub(crate) fn content(raw: &str) -> &str {
    raw.split('#').next().unwrap_or("").trim()
}

/// The rest of `line` after its first word, trimmed (names may contain spaces).
pub(crate) fn rest_after_keyword(line: &str) -> &str {
    line.split_once(char::is_whitespace)
        .map(|(_, rest)| rest.trim())
        .unwrap_or("")
}

/// Checks every `v` and `f` line of an OBJ file and reduces the file to what tobj needs, so tobj
/// only ever sees well-formed input.
pub(crate) fn scan_obj(path: &Path, text: &str) -> Result<ObjScan> {
    scan_obj_in_chunks(path, text, SCAN_CHUNK)
}

/// [`scan_obj`] with chunks of about `chunk_bytes` bytes.
fn scan_obj_in_chunks(path: &Path, text: &str, chunk_bytes: usize) -> Result<ObjScan> {
    // Whole lines in chunks of about SCAN_CHUNK bytes, scanned in parallel: a first pass
    // counts each chunk's lines and `v` lines (relative face indices count back from the
    // vertices before them), the second checks and reduces each chunk; the pieces are joined
    // in file order, and the first error in file order is the one reported.
    let chunks = line_chunks(text, chunk_bytes.max(1));
    let counts: Vec<(usize, usize)> = chunks
        .par_iter()
        .map(|chunk| {
            chunk.lines().fold((0, 0), |(lines, vertices), l| {
                (lines + 1, vertices + usize::from(is_vertex_line(l)))
            })
        })
        .collect();
    let vertex_total: usize = counts.iter().map(|c| c.1).sum();
    let mut starts = Vec::with_capacity(chunks.len());
    let (mut line0, mut vertex0) = (0usize, 0usize);
    for &(lines, vertices) in &counts {
        starts.push((line0, vertex0));
        line0 += lines;
        vertex0 += vertices;
    }
    let pieces: Vec<Result<ObjScan>> = chunks
        .par_iter()
        .zip(&starts)
        .map(|(chunk, &(line0, vertex0))| scan_chunk(path, chunk, line0, vertex0, vertex_total))
        .collect();
    let mut scan = ObjScan::with_capacity(text.len());
    for piece in pieces {
        let piece = piece?;
        scan.mtllibs.extend(piece.mtllibs);
        scan.usemtls.extend(piece.usemtls);
        scan.triangle_count += piece.triangle_count;
        scan.vertices.push_str(&piece.vertices);
        scan.body.push_str(&piece.body);
    }
    if vertex_total == 0 || scan.triangle_count == 0 {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: "empty scene: no vertices or no faces".into(),
        });
    }
    Ok(scan)
}

/// Bytes of OBJ text one task of [`scan_obj`] scans (whole lines).
const SCAN_CHUNK: usize = 1 << 20;

/// `text` cut into pieces of whole lines (each ending after a newline, the last one where the
/// text ends), about `size` bytes each.
fn line_chunks(text: &str, size: usize) -> Vec<&str> {
    let mut chunks = Vec::new();
    let mut rest = text;
    while !rest.is_empty() {
        let cut = if rest.len() <= size {
            rest.len()
        } else {
            rest.as_bytes()[size..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(rest.len(), |i| size + i + 1)
        };
        let (chunk, tail) = rest.split_at(cut);
        chunks.push(chunk);
        rest = tail;
    }
    chunks
}

/// True for a `v` line (a vertex position): its first word, before any comment, is `v`
/// (`content(raw).split_whitespace().next() == Some("v")`, without splitting the line).
fn is_vertex_line(raw: &str) -> bool {
    let mut rest = raw.trim_start().chars();
    rest.next() == Some('v') && rest.next().is_none_or(|c| c.is_whitespace() || c == '#')
}

/// [`scan_obj`] of one chunk of whole lines, whose first line is the file's line `line0 + 1`
/// and which follows `vertex0` of the file's `vertex_total` `v` lines.
fn scan_chunk(
    path: &Path,
    chunk: &str,
    line0: usize,
    vertex0: usize,
    vertex_total: usize,
) -> Result<ObjScan> {
    let mut vertices_so_far = vertex0;
    let mut scan = ObjScan::with_capacity(chunk.len());
    let mut refs: Vec<&str> = Vec::new();
    for (i, raw) in chunk.lines().enumerate() {
        let line_no = line0 + i + 1;
        let line = content(raw);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                refs.clear();
                refs.extend(words);
                scan_vertex(path, line_no, &refs, &mut scan.vertices)?;
                vertices_so_far += 1;
            }
            Some("f") => {
                refs.clear();
                refs.extend(words);
                let counts = (vertices_so_far, vertex_total);
                scan_face(path, line_no, &refs, counts, &mut scan.body)?;
                scan.triangle_count += refs.len() - 2;
            }
            Some("mtllib") => {
                let name = rest_after_keyword(line);
                if !name.is_empty() {
                    scan.mtllibs.push((line_no, name.to_string()));
                }
            }
            Some("usemtl") => {
                let name = rest_after_keyword(line);
                if name.is_empty() {
                    return Err(parse_err(path, line_no, "usemtl needs a material name"));
                }
                scan.body.push_str("usemtl ");
                scan.body.push_str(name);
                scan.body.push('\n');
                scan.usemtls.push((line_no, name.to_string()));
            }
            _ => {}
        }
    }
    Ok(scan)
}

/// A finite number `w` of an OBJ line (`what` names it in the error).
fn obj_number(path: &Path, w: &str, line_no: usize, what: &str) -> Result<f64> {
    let x: f64 = w
        .parse()
        .map_err(|_| parse_err(path, line_no, format!("malformed number '{w}' in {what}")))?;
    if !x.is_finite() {
        return Err(parse_err(
            path,
            line_no,
            format!("{what} value '{w}' is not finite"),
        ));
    }
    Ok(x)
}

/// Checks the numbers `nums` of the `v` line `line_no` and appends it to `vertices` as
/// `v x y z` (w applied, colours dropped).
fn scan_vertex(path: &Path, line_no: usize, nums: &[&str], vertices: &mut String) -> Result<()> {
    if nums.len() < 3 {
        return Err(parse_err(path, line_no, "vertex needs three coordinates"));
    }
    if !matches!(nums.len(), 3 | 4 | 6) {
        return Err(parse_err(
            path,
            line_no,
            format!(
                "vertex has {} numbers; expected x y z, x y z w or x y z r g b",
                nums.len()
            ),
        ));
    }
    let mut xyz = [0.0; 3];
    for (k, w) in nums[..3].iter().enumerate() {
        xyz[k] = obj_number(path, w, line_no, "vertex coordinate")?;
    }
    for w in nums.iter().skip(4) {
        obj_number(path, w, line_no, "vertex colour")?;
    }
    if nums.len() == 4 {
        let w = obj_number(path, nums[3], line_no, "vertex weight")?;
        if w == 0.0 {
            return Err(parse_err(path, line_no, "vertex weight w is 0"));
        }
        let p = xyz.map(|x| x / w);
        if !p.iter().all(|x| x.is_finite()) {
            return Err(parse_err(
                path,
                line_no,
                "vertex coordinate is not finite after dividing by w",
            ));
        }
        // Writing to a String cannot fail.
        let _ = writeln!(vertices, "v {:e} {:e} {:e}", p[0], p[1], p[2]);
    } else {
        for (k, w) in nums[..3].iter().enumerate() {
            vertices.push_str(if k == 0 { "v " } else { " " });
            vertices.push_str(w);
        }
        vertices.push('\n');
    }
    Ok(())
}

/// Checks the vertex references `refs` of the `f` line `line_no`, after `vertices_so_far` of
/// the file's `vertex_total` `v` lines (relative indices count back from there), and appends
/// the face to `body` with absolute position indices only.
fn scan_face(
    path: &Path,
    line_no: usize,
    refs: &[&str],
    (vertices_so_far, vertex_total): (usize, usize),
    body: &mut String,
) -> Result<()> {
    if refs.len() < 3 {
        return Err(parse_err(
            path,
            line_no,
            "face needs at least three vertices",
        ));
    }
    body.push('f');
    for r in refs {
        let first = r.split('/').next().unwrap_or("");
        let idx: i64 = first
            .parse()
            .map_err(|_| parse_err(path, line_no, format!("malformed face index '{r}'")))?;
        let resolved = if idx > 0 {
            idx
        } else {
            vertices_so_far as i64 + idx + 1
        };
        if idx == 0 || resolved < 1 || resolved > vertex_total as i64 {
            return Err(parse_err(
                path,
                line_no,
                format!("face index {idx} out of range (the file has {vertex_total} vertices)"),
            ));
        }
        // Texture and normal references are not used: checked for syntax only.
        for part in r.split('/').skip(1) {
            if !part.is_empty() && part.parse::<i64>().is_err() {
                return Err(parse_err(
                    path,
                    line_no,
                    format!("malformed face index '{r}'"),
                ));
            }
        }
        // Writing to a String cannot fail.
        let _ = write!(body, " {resolved}");
    }
    body.push('\n');
    Ok(())
}

/// What the line-level scan of an MTL file learned.
pub(crate) struct MtlScan {
    /// Names of the materials the file defines.
    names: Vec<String>,
    /// The file reduced to `newmtl`, `Kd` and `Ke` lines.
    clean: String,
    /// What was read but changed or left out: a `Kd` of 1 lowered to
    /// [`crate::scene::ALBEDO_MAX`], a transparent material (`d` below 1) taken as opaque.
    warnings: Vec<Warning>,
}

/// Checks the `Kd` and `Ke` lines of an MTL file (a single value is grey; tobj 4.0.5 panics on
/// `Kd 0.5`, so it is written out as three) and the physical
/// ranges, and reduces the file to the lines we use.
pub(crate) fn scan_mtl(path: &Path, text: &str) -> Result<MtlScan> {
    let mut scan = MtlScan {
        names: Vec::new(),
        clean: String::new(),
        warnings: Vec::new(),
    };
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = content(raw);
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        if key == "newmtl" {
            let name = rest_after_keyword(line);
            if name.is_empty() {
                return Err(parse_err(path, line_no, "newmtl needs a material name"));
            }
            scan.clean.push_str(&format!("newmtl {name}\n"));
            scan.names.push(name.to_string());
            continue;
        }
        // Dissolve below 1: a transparent surface, which the model takes as opaque.
        if key == "d" {
            let dissolve = words.next().and_then(|w| w.parse::<f64>().ok());
            if let Some(d) = dissolve.filter(|d| (0.0..1.0).contains(d)) {
                let material = scan.names.last().map_or("", String::as_str);
                scan.warnings.push(Warning::in_file(
                    WarningKind::Unsupported,
                    path,
                    Some(line_no),
                    format!("material '{material}': transparency (d {d}) is not modelled; the surface is opaque"),
                ));
            }
            continue;
        }
        // The colours the model uses (tobj sees nothing else: `Ka`, `Ks`, `Tf` and the rest
        // are dropped unread).
        if !matches!(key, "Kd" | "Ke") {
            continue;
        }
        let mut nums: Vec<&str> = words.collect();
        if nums.first().is_some_and(|w| w.parse::<f64>().is_err()) {
            // `Kd spectral file.rfl` / `Kd xyz ...`: a form we do not support.
            return Err(parse_err(
                path,
                line_no,
                format!("{key} must be numbers (r g b, or one grey value)"),
            ));
        }
        // One number is grey (the MTL format's g and b default to r); tobj 4.0.5 panics on
        // it, so it is written out as three.
        if nums.len() == 1 {
            nums = vec![nums[0]; 3];
        }
        if nums.len() < 3 {
            return Err(parse_err(
                path,
                line_no,
                format!(
                    "{key} needs three numbers (r g b) or one (grey), found {}",
                    nums.len()
                ),
            ));
        }
        let mut values = [0.0f64; 3];
        for (k, w) in nums[..3].iter().enumerate() {
            let x: f64 = w.parse().map_err(|_| {
                parse_err(path, line_no, format!("malformed number '{w}' in {key}"))
            })?;
            if !x.is_finite() {
                return Err(parse_err(
                    path,
                    line_no,
                    format!("{key} value '{w}' is not finite"),
                ));
            }
            values[k] = x;
        }
        if key == "Kd" && values.iter().any(|&x| !(0.0..=1.0).contains(&x)) {
            return Err(parse_err(
                path,
                line_no,
                format!(
                    "albedo Kd {} {} {} is outside [0, 1]",
                    values[0], values[1], values[2]
                ),
            ));
        }
        let max = crate::scene::ALBEDO_MAX;
        if key == "Kd" && values.contains(&1.0) {
            let material = scan.names.last().map_or("", String::as_str);
            scan.warnings.push(Warning::in_file(
                WarningKind::Albedo,
                path,
                Some(line_no),
                format!(
                    "material '{material}': albedo Kd {} {} {} lowered to {max} (the model needs albedo below 1)",
                    nums[0], nums[1], nums[2]
                ),
            ));
            let [r, g, b] = values.map(|x| x.min(max));
            scan.clean.push_str(&format!("Kd {r} {g} {b}\n"));
            continue;
        }
        if key == "Ke" && values.iter().any(|&x| x < 0.0) {
            return Err(parse_err(
                path,
                line_no,
                format!(
                    "negative emission Ke {} {} {}",
                    values[0], values[1], values[2]
                ),
            ));
        }
        if matches!(key, "Kd" | "Ke") {
            scan.clean
                .push_str(&format!("{key} {} {} {}\n", nums[0], nums[1], nums[2]));
        }
    }
    Ok(scan)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scans `text` in one chunk and in chunks of a few bytes: the same reduction, or the same
    /// error.
    fn same_in_chunks(text: &str) -> std::result::Result<(String, String, usize), String> {
        let path = Path::new("t.obj");
        let whole = scan_obj_in_chunks(path, text, usize::MAX);
        for size in [1, 7, 30] {
            let parts = scan_obj_in_chunks(path, text, size);
            match (&whole, &parts) {
                (Ok(a), Ok(b)) => {
                    assert_eq!(
                        (&a.vertices, &a.body, a.triangle_count),
                        (&b.vertices, &b.body, b.triangle_count)
                    );
                    assert_eq!((&a.mtllibs, &a.usemtls), (&b.mtllibs, &b.usemtls));
                }
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
                _ => panic!("chunks of {size} bytes disagree with one chunk"),
            }
        }
        whole
            .map(|s| (s.vertices, s.body, s.triangle_count))
            .map_err(|e| e.to_string())
    }

    #[test]
    fn continued_lines_are_joined_and_later_lines_keep_their_numbers() {
        assert_eq!(join_continued_lines("v 0 0 0\nf 1 2 3\n"), None);
        let joined = join_continued_lines("v 0 0 0\r\nf 1 \\\r\n 2 \\\n3\nbad\n").unwrap();
        assert_eq!(joined, "v 0 0 0\nf 1   2  3\n\n\nbad\n");
        assert_eq!(joined.lines().position(|l| l == "bad"), Some(4));
        // A continuation on the last line ends the text.
        assert_eq!(join_continued_lines("f 1 2 \\").unwrap(), "f 1 2  ");
    }

    #[test]
    fn vertex_lines_are_lines_whose_first_word_is_v() {
        for line in [
            "v 1 2 3",
            "  v\t1 2 3",
            "v",
            "v#c",
            "v # c",
            "vt 0 0",
            "vn 0 0 1",
            "#v 1 2 3",
            " # v",
            "",
            "f 1 2 3",
            "\u{3000}v 1 2 3",
            "v\u{3000}1",
            "w 1",
            "V 1 2 3",
        ] {
            let by_words = content(line).split_whitespace().next() == Some("v");
            assert_eq!(is_vertex_line(line), by_words, "{line:?}");
        }
    }

    #[test]
    fn chunked_scan_matches_one_chunk() {
        let text = "mtllib a.mtl\nv 0 0 0\nv 1 0 0 # c\nv 0 1 0\nusemtl m\nf -3 -2 -1\n\
                    v 0 0 1 2\nf 1/1 2//3 4 3\r\nf -1 1 2\n";
        let scanned = same_in_chunks(text);
        let Ok((vertices, body, triangles)) = scanned else {
            panic!("a valid file failed: {scanned:?}");
        };
        assert_eq!(
            vertices,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0e0 0e0 5e-1\n".to_string()
        );
        assert_eq!(body, "usemtl m\nf 1 2 3\nf 1 2 4 3\nf 4 1 2\n");
        assert_eq!(triangles, 4);
        // Two errors: the first in file order is reported, whatever the chunks.
        let bad = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\nv 1 x 0\n";
        let scanned = same_in_chunks(bad);
        let Err(message) = scanned else {
            panic!("an invalid file passed: {scanned:?}");
        };
        assert!(message.contains(":5:"), "{message}");
    }
}
