//! Stage 1: load an OBJ+MTL scene into a flat list of input triangles with materials.
//!
//! Polygons are fan-triangulated in file order; a triangle's index is its position in that order,
//! and this order is the contract for every per-triangle output. Positions are kept in f64 so that a
//! scene translated far from the origin keeps its precision. Every line-level problem is reported as
//! `file:line: message` before tobj ever sees the file (tobj 4.0.5 panics on some malformed lines).

use std::collections::{hash_map, HashMap};
use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::error::{Error, Result};

/// Options that complete or override what the scene files say about materials.
#[derive(Clone, Debug)]
pub struct SceneOptions {
    /// Grey albedo for triangles whose material has no `Kd` (or that have no material). In [0, 1).
    pub default_albedo: f64,
    /// The seed's emitter rule: a triangle whose three vertices all have y > this value emits.
    pub emit_above: Option<f64>,
    /// Radiance (W / (m^2 sr), grey) given to triangles selected by `emit_above`. >= 0.
    pub emission: f64,
}

impl Default for SceneOptions {
    fn default() -> Self {
        SceneOptions {
            default_albedo: 0.75,
            emit_above: None,
            emission: 1.0,
        }
    }
}

impl SceneOptions {
    /// Checks the ranges: albedo in [0, 1), emission finite and >= 0, threshold finite.
    pub fn validate(&self) -> Result<()> {
        if !(self.default_albedo.is_finite() && (0.0..1.0).contains(&self.default_albedo)) {
            return Err(Error::Parameter(format!(
                "--albedo {} is outside [0, 1)",
                self.default_albedo
            )));
        }
        if !(self.emission.is_finite() && self.emission >= 0.0) {
            return Err(Error::Parameter(format!(
                "--emission {} must be finite and >= 0",
                self.emission
            )));
        }
        if let Some(y) = self.emit_above {
            if !y.is_finite() {
                return Err(Error::Parameter(format!("--emit-above {y} must be finite")));
            }
        }
        Ok(())
    }
}

/// A scene: input triangles in file order with per-triangle RGB albedo and emitted radiance.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// The file the scene came from (for messages); empty for scenes built in code.
    pub path: PathBuf,
    /// Vertex positions in the file's units and frame.
    pub positions: Vec<DVec3>,
    /// Input triangles, indices into `positions`, in file order (polygons fan-triangulated).
    pub triangles: Vec<[u32; 3]>,
    /// Per-triangle albedo, RGB, each in [0, 1).
    pub albedo: Vec<[f64; 3]>,
    /// Per-triangle emitted radiance, RGB, W / (m^2 sr), each >= 0.
    pub emission: Vec<[f64; 3]>,
    /// Per-triangle material: an index into `material_names`, or `None` when the triangle has
    /// no material (no `usemtl`, or a `usemtl` naming a material no MTL file defines). As long as
    /// the triangle list for scenes from [`load_obj`] and [`Scene::from_triangles`]; a scene
    /// filled in field by field may leave it short (missing entries mean no material).
    pub material: Vec<Option<u32>>,
    /// Names of the materials defined by the scene's MTL files (`newmtl`), in the order tobj
    /// lists them; empty for scenes built in code.
    pub material_names: Vec<String>,
    /// Non-fatal findings (missing MTL, no emitter, ...), one line each.
    pub warnings: Vec<String>,
    /// Analytic lights (point, spot, sun, sky) in the scene's frame, radiometric units
    /// ([`crate::lights`]); from glTF's `KHR_lights_punctual` or the command line.
    pub lights: Vec<crate::lights::Light>,
}

/// The shapes of a scene's non-degenerate triangles ([`Scene::shapes`]). The aspect ratio of a
/// triangle is its longest edge squared over its area: 4/sqrt(3) = 2.31 for an equilateral
/// triangle, 4 for half a square, about 2 / sin(smallest angle) for a sliver.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct TriangleShapes {
    /// Non-degenerate triangles counted.
    pub triangles: usize,
    /// Median aspect ratio.
    pub aspect_p50: f64,
    /// 90th percentile of the aspect ratios (nearest rank).
    pub aspect_p90: f64,
    /// 99th percentile of the aspect ratios (nearest rank).
    pub aspect_p99: f64,
    /// Largest aspect ratio.
    pub aspect_max: f64,
    /// Smallest area, scene units squared.
    pub area_min: f64,
    /// Largest area, scene units squared.
    pub area_max: f64,
    /// `area_max / area_min` (1 when all areas are equal; 0 without triangles).
    pub area_range: f64,
}

/// Largest `|sin|` of a triangle's corner angle below which it counts as degenerate (zero area).
///
/// Relative to the triangle's own edges, so it does not depend on the scene's scale: a sliver with
/// aspect ratio 1e6 (sin ~ 1e-6) is a real triangle, three collinear points (sin ~ 1e-16) are not.
pub const DEGENERATE_SIN: f64 = 1e-10;

impl Scene {
    /// Number of input triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// True when the scene has no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The three corners of input triangle `t`.
    pub fn corners(&self, t: usize) -> [DVec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Area of input triangle `t` in the scene's units squared.
    pub fn area(&self, t: usize) -> f64 {
        let [a, b, c] = self.corners(t);
        0.5 * (b - a).cross(c - a).length()
    }

    /// True when triangle `t` has (numerically) zero area; such triangles keep B = E.
    pub fn is_degenerate(&self, t: usize) -> bool {
        let [a, b, c] = self.corners(t);
        let (e1, e2) = (b - a, c - a);
        let cross = e1.cross(e2).length();
        let scale = e1.length() * e2.length();
        !(cross.is_finite() && cross > DEGENERATE_SIN * scale && cross > 0.0)
    }

    /// The name of triangle `t`'s material, `None` when it has none (or `t` is out of range).
    pub fn material_name(&self, t: usize) -> Option<&str> {
        let m = self.material.get(t).copied().flatten()?;
        self.material_names.get(m as usize).map(String::as_str)
    }

    /// True when triangle `t` emits in any channel.
    pub fn is_emitter(&self, t: usize) -> bool {
        self.emission[t].iter().any(|&e| e > 0.0)
    }

    /// Axis-aligned bounds of all vertices used by triangles, as (min, max).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for tri in &self.triangles {
            for &v in tri {
                let p = self.positions[v as usize];
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        (lo, hi)
    }

    /// Builds a scene from triangles given in code (tests, generators); applies no options.
    pub fn from_triangles(
        corners: &[[DVec3; 3]],
        albedo: &[[f64; 3]],
        emission: &[[f64; 3]],
    ) -> Scene {
        let mut scene = Scene::default();
        for (t, tri) in corners.iter().enumerate() {
            let base = scene.positions.len() as u32;
            scene.positions.extend_from_slice(tri);
            scene.triangles.push([base, base + 1, base + 2]);
            scene.albedo.push(albedo[t]);
            scene.emission.push(emission[t]);
            scene.material.push(None);
        }
        scene
    }

    /// Applies a uniform scale then a translation to every vertex (tests of invariance).
    pub fn transformed(&self, scale: f64, offset: DVec3) -> Scene {
        let mut s = self.clone();
        for p in &mut s.positions {
            *p = *p * scale + offset;
        }
        s
    }

    /// Number of emitting triangles.
    pub fn emitter_count(&self) -> usize {
        (0..self.len()).filter(|&t| self.is_emitter(t)).count()
    }

    /// Number of degenerate (zero-area) triangles.
    pub fn degenerate_count(&self) -> usize {
        (0..self.len()).filter(|&t| self.is_degenerate(t)).count()
    }

    /// The shapes of the non-degenerate triangles: their aspect ratios and area range (what
    /// makes a mesh costly to refine: slivers and areas spanning orders of magnitude).
    pub fn shapes(&self) -> TriangleShapes {
        let mut aspect = Vec::with_capacity(self.len());
        let (mut area_min, mut area_max) = (f64::INFINITY, 0.0f64);
        for t in (0..self.len()).filter(|&t| !self.is_degenerate(t)) {
            let corners = self.corners(t);
            let area = self.area(t);
            let edge = crate::geometry::longest_edge(&corners);
            aspect.push(edge * edge / area);
            area_min = area_min.min(area);
            area_max = area_max.max(area);
        }
        aspect.sort_unstable_by(f64::total_cmp);
        // Nearest rank: the smallest value with at least p of the values at or below it.
        let rank = |p: f64| {
            let k = ((p * aspect.len() as f64).ceil() as usize).clamp(1, aspect.len().max(1));
            aspect.get(k - 1).copied().unwrap_or(0.0)
        };
        let triangles = aspect.len();
        TriangleShapes {
            triangles,
            aspect_p50: rank(0.5),
            aspect_p90: rank(0.9),
            aspect_p99: rank(0.99),
            aspect_max: aspect.last().copied().unwrap_or(0.0),
            area_min: if triangles > 0 { area_min } else { 0.0 },
            area_max,
            area_range: if triangles > 0 {
                area_max / area_min
            } else {
                0.0
            },
        }
    }

    /// For every triangle, the first earlier triangle it duplicates, if any: same three corner
    /// positions (bit for bit) in the same cyclic order, i.e. the same surface facing the same
    /// way. Degenerate triangles are never duplicates.
    ///
    /// Duplicates must take part in transport only once: two coincident one-sided surfaces
    /// would reflect the light they receive twice and, in front-only antiradiance, both send
    /// the antiradiance that cancels the light behind them, which then cancels it twice (a
    /// doubled plate made the shadow under it negative). Back-to-back copies (reversed corner
    /// order, a thin two-sided wall) are not duplicates and are solved as they are.
    pub fn duplicates(&self) -> Vec<Option<u32>> {
        // `+ 0.0` turns -0.0 into 0.0, so that equal coordinates get equal keys.
        let key = |p: DVec3| p.to_array().map(|x| (x + 0.0).to_bits());
        let mut first: HashMap<[[u64; 3]; 3], u32> = HashMap::with_capacity(self.len());
        (0..self.len())
            .map(|t| {
                if self.is_degenerate(t) {
                    return None;
                }
                let k = self.corners(t).map(key);
                // The rotation that starts at the smallest corner: the same for every cyclic
                // order of the same corners, different for the reversed order.
                let start = (0..3).min_by_key(|&i| k[i]).unwrap_or(0);
                let canonical = [k[start], k[(start + 1) % 3], k[(start + 2) % 3]];
                match first.entry(canonical) {
                    hash_map::Entry::Occupied(e) => Some(*e.get()),
                    hash_map::Entry::Vacant(e) => {
                        e.insert(t as u32);
                        None
                    }
                }
            })
            .collect()
    }
}

/// Reads a scene file: glTF 2.0 (`.gltf`, `.glb`, see [`crate::gltf_in`]) by its extension,
/// Wavefront OBJ ([`load_obj`]) otherwise.
pub fn load_scene(path: &Path, options: &SceneOptions) -> Result<Scene> {
    if crate::gltf_in::is_gltf(path) {
        crate::gltf_in::load_gltf(path, options)
    } else {
        load_obj(path, options)
    }
}

/// Reads an OBJ file (and the MTL files it names) into a [`Scene`].
///
/// Errors name the file and, where known, the line: missing or unreadable file, empty or binary
/// file, malformed numbers, NaN or infinite coordinates, face index out of range, colour lines with
/// fewer than three numbers, albedo outside [0, 1), negative emission, no non-degenerate triangle.
/// A missing MTL file, a `usemtl` naming a material no MTL file defines, triangles that repeat
/// an earlier one ([`Scene::duplicates`]) and a scene without emitters are warnings (in
/// `Scene::warnings`).
///
/// Only what the model uses is read: vertex positions (`v x y z`, optionally `w`, vertex colours
/// ignored), faces (position indices; texture and normal references are ignored), `mtllib`,
/// `usemtl`, and the `newmtl`, `Kd` and `Ke` lines of material files. Comments may follow `#` on
/// any line; words may be separated by spaces or tabs; lines may end in CRLF.
pub fn load_obj(path: &Path, options: &SceneOptions) -> Result<Scene> {
    options.validate()?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let text = as_text(path, &bytes)?;
    let obj_scan = scan_obj(path, text)?;

    // Materials: every MTL file is checked line by line first (tobj panics on short colour lines)
    // and reduced to the lines we use (tobj drops a whole file over one line it cannot parse),
    // then tobj resolves `usemtl` names against them.
    let mut warnings = Vec::new();
    let base_dir = path.parent().unwrap_or(Path::new("."));
    let mut mtl_texts: Vec<String> = Vec::new();
    let mut defined: std::collections::HashSet<String> = Default::default();
    let mut mtl_missing = false;
    for (line, name) in &obj_scan.mtllibs {
        // `mtllib a.mtl b.mtl` names several files, unless a file of that whole name exists.
        let whole = base_dir.join(name);
        let names: Vec<&str> = if whole.is_file() || !name.contains(char::is_whitespace) {
            vec![name.as_str()]
        } else {
            name.split_whitespace().collect()
        };
        for name in names {
            let mtl_path = base_dir.join(name);
            match std::fs::read(&mtl_path) {
                Ok(mtl_bytes) => {
                    let mtl_text = as_text(&mtl_path, &mtl_bytes)?;
                    let mtl_scan = scan_mtl(&mtl_path, mtl_text)?;
                    defined.extend(mtl_scan.names);
                    mtl_texts.push(mtl_scan.clean);
                }
                Err(e) => {
                    mtl_missing = true;
                    warnings.push(format!(
                        "{}:{}: material file {} cannot be read ({e}); using --albedo for its materials",
                        path.display(),
                        line,
                        mtl_path.display()
                    ))
                }
            }
        }
    }
    if !mtl_missing {
        let mut reported = std::collections::HashSet::new();
        for (line, name) in &obj_scan.usemtls {
            if !defined.contains(name) && reported.insert(name.as_str()) {
                warnings.push(format!(
                    "{}:{}: material '{}' is not defined in any material file; using --albedo",
                    path.display(),
                    line,
                    name
                ));
            }
        }
    }

    // Geometry through tobj: fan triangulation, models in file order. tobj reads the reduced text:
    // every material file first (named by its index), all vertices, then faces and `usemtl`
    // lines with absolute position indices only.
    let mut clean = String::with_capacity(obj_scan.vertices.len() + obj_scan.body.len() + 64);
    for i in 0..mtl_texts.len() {
        clean.push_str(&format!("mtllib {i}\n"));
    }
    clean.push_str(&obj_scan.vertices);
    clean.push_str(&obj_scan.body);
    let load_options = tobj::LoadOptions {
        triangulate: true,
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

    let mut scene = Scene {
        path: path.to_path_buf(),
        material_names: materials.iter().map(|m| m.name.clone()).collect(),
        ..Scene::default()
    };
    let default_albedo = [options.default_albedo; 3];
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
        for tri in mesh.indices.chunks_exact(3) {
            scene
                .triangles
                .push([base + tri[0], base + tri[1], base + tri[2]]);
            scene.albedo.push(albedo);
            scene.emission.push(emission);
            scene.material.push(material_id);
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

    crate::texture::apply_obj_textures(&mut scene, path, text, &mut warnings);
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
        warnings.push(format!(
            "{}: {} an earlier triangle (same corners, same orientation; first: triangle {t} repeats {twin}); each is solved once and reported with its first copy's radiance{}",
            path.display(),
            if count == 1 { "1 triangle repeats".to_string() } else { format!("{count} triangles repeat") },
            if differ { " (some copies have other materials: the first copy's material is used)" } else { "" }
        ));
    }
    if scene.emitter_count() == 0 {
        warnings.push(format!(
            "{}: no emitting triangle (no Ke in materials, no --emit-above match); the answer is all zero",
            path.display()
        ));
    }
    scene.warnings = warnings;
    Ok(scene)
}

/// Rejects binary and non-UTF-8 content with a one-line error.
fn as_text<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str> {
    if bytes.contains(&0) {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: "binary file (contains NUL bytes), expected text".into(),
        });
    }
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let line = bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        Error::Parse {
            path: path.to_path_buf(),
            line,
            message: "not valid UTF-8 text (binary file?)".into(),
        }
    })?;
    Ok(text.strip_prefix('\u{feff}').unwrap_or(text))
}

/// What the line-level scan of an OBJ file learned.
struct ObjScan {
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

fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> Error {
    Error::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// A line without its comment, trimmed.
fn content(raw: &str) -> &str {
    raw.split('#').next().unwrap_or("").trim()
}

/// The rest of `line` after its first word, trimmed (names may contain spaces).
fn rest_after_keyword(line: &str) -> &str {
    line.split_once(char::is_whitespace)
        .map(|(_, rest)| rest.trim())
        .unwrap_or("")
}

/// Checks every `v` and `f` line of an OBJ file and reduces the file to what tobj needs, so tobj
/// only ever sees well-formed input.
fn scan_obj(path: &Path, text: &str) -> Result<ObjScan> {
    let vertex_total = text
        .lines()
        .filter(|l| content(l).split_whitespace().next() == Some("v"))
        .count();
    let mut vertices_so_far = 0usize;
    let mut scan = ObjScan {
        mtllibs: Vec::new(),
        usemtls: Vec::new(),
        triangle_count: 0,
        vertices: String::new(),
        body: String::new(),
    };
    let number = |w: &str, line_no: usize, what: &str| -> Result<f64> {
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
    };
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = content(raw);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let nums: Vec<&str> = words.collect();
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
                    xyz[k] = number(w, line_no, "vertex coordinate")?;
                }
                for w in nums.iter().skip(4) {
                    number(w, line_no, "vertex colour")?;
                }
                if nums.len() == 4 {
                    let w = number(nums[3], line_no, "vertex weight")?;
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
                    scan.vertices
                        .push_str(&format!("v {:e} {:e} {:e}\n", p[0], p[1], p[2]));
                } else {
                    scan.vertices
                        .push_str(&format!("v {} {} {}\n", nums[0], nums[1], nums[2]));
                }
                vertices_so_far += 1;
            }
            Some("f") => {
                let refs: Vec<&str> = words.collect();
                if refs.len() < 3 {
                    return Err(parse_err(
                        path,
                        line_no,
                        "face needs at least three vertices",
                    ));
                }
                scan.body.push('f');
                for r in &refs {
                    let first = r.split('/').next().unwrap_or("");
                    let idx: i64 = first.parse().map_err(|_| {
                        parse_err(path, line_no, format!("malformed face index '{r}'"))
                    })?;
                    let resolved = if idx > 0 {
                        idx
                    } else {
                        vertices_so_far as i64 + idx + 1
                    };
                    if idx == 0 || resolved < 1 || resolved > vertex_total as i64 {
                        return Err(parse_err(
                            path,
                            line_no,
                            format!(
                                "face index {idx} out of range (the file has {vertex_total} vertices)"
                            ),
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
                    scan.body.push_str(&format!(" {resolved}"));
                }
                scan.body.push('\n');
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
                scan.body.push_str(&format!("usemtl {name}\n"));
                scan.usemtls.push((line_no, name.to_string()));
            }
            _ => {}
        }
    }
    if vertex_total == 0 || scan.triangle_count == 0 {
        return Err(Error::Scene {
            path: path.to_path_buf(),
            message: "empty scene: no vertices or no faces".into(),
        });
    }
    Ok(scan)
}

/// What the line-level scan of an MTL file learned.
struct MtlScan {
    /// Names of the materials the file defines.
    names: Vec<String>,
    /// The file reduced to `newmtl`, `Kd` and `Ke` lines.
    clean: String,
}

/// Checks every colour line of an MTL file (tobj 4.0.5 panics on `Kd 0.5`) and the physical
/// ranges, and reduces the file to the lines we use.
fn scan_mtl(path: &Path, text: &str) -> Result<MtlScan> {
    let mut scan = MtlScan {
        names: Vec::new(),
        clean: String::new(),
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
        if !matches!(key, "Ka" | "Kd" | "Ks" | "Ke" | "Tf") {
            continue;
        }
        let nums: Vec<&str> = words.collect();
        if nums.first().is_some_and(|w| w.parse::<f64>().is_err()) {
            // `Kd spectral file.rfl` / `Ka xyz ...`: a form we do not support.
            return Err(parse_err(
                path,
                line_no,
                format!("{key} must be three numbers (r g b)"),
            ));
        }
        if nums.len() < 3 {
            return Err(parse_err(
                path,
                line_no,
                format!("{key} needs three numbers (r g b), found {}", nums.len()),
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
        if key == "Kd" && values.iter().any(|&x| !(0.0..1.0).contains(&x)) {
            return Err(parse_err(
                path,
                line_no,
                format!(
                    "albedo Kd {} {} {} is outside [0, 1)",
                    values[0], values[1], values[2]
                ),
            ));
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
