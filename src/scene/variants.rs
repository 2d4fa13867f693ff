//! Mesh-quality variants: the same geometry as a scene, triangulated badly, with a map from
//! every output triangle back to the input triangles it covers.
//!
//! Real interiors exported from CAD tools are meshed nothing like uniformly meshed test scenes:
//! long slivers, T-junctions, inconsistent orientation, huge polygons beside tiny detail,
//! coordinates far from the origin. Each [`VariantKind`] makes one of these out of a scene
//! without changing the surface it describes (up to `jitter`'s deliberate displacement), so a
//! solve of the variant can be compared with a solve of the original triangle by triangle:
//! [`map_back`] turns the variant's per-triangle radiance into per-original-triangle radiance
//! (the area-weighted mean over the variant triangles covering each original triangle, on the
//! side the original faces), and the design note's error measure
//! ([`crate::solve::solution::relative_error`]) compares it with the original's.
//!
//! [`make_variant`] builds a [`Variant`] in memory; [`write_variant`] writes it as OBJ + MTL
//! plus the map as CSV (`OUT.map.csv`, header [`MAP_CSV_HEADER`]), the way
//! `antiradiance scene variant KIND MESH.obj --out OUT.obj` does. Materials are kept by name:
//! the MTL file is a copy of the input's, and a triangle without a material is written without
//! one, so scene options (`--albedo`, `--emit-above`) apply to the output as they did to the
//! input. Coordinates are written in Rust's shortest round-trip form, so they read back exactly.
//!
//! Everything is deterministic: the same scene, kind, seed and amount give the same files.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};

use crate::error::{Error, Result};
use crate::files::{format_f64, write_atomic};
use crate::geometry::sampling::{mix64, Rng};
use crate::scene::Scene;
use crate::scene::MAX_PATCHES;

/// The kinds of bad triangulation [`make_variant`] makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum VariantKind {
    /// Every triangle split into long slivers: k thin triangles from the vertex opposite its
    /// shortest edge to points along that edge, plus k - 1 thin triangles in the strip along the
    /// edge (2k - 1 in all, no T-junction); k = `--amount` (default 8).
    Fan,
    /// A seeded random re-triangulation: every triangle gets `--amount` random interior points
    /// (default 3) and every edge 0, 1 or 2 random points shared by both triangles on it, so
    /// the triangles are irregular and there is no T-junction.
    Random,
    /// Every distinct vertex moved by a random vector of length at most `--amount` (world
    /// units, default 1e-6); vertices shared by several triangles move together.
    Jitter,
    /// The whole scene moved by `--amount` (default 1e3) along every axis, (x, y, z) +
    /// (a, a, a).
    Translate,
    /// Every triangle, then a reversed copy of it (the same corners, back to back); `--amount`
    /// does not apply.
    Twins,
    /// A share `--amount` (default 0.3) of the edges shared by two triangles split on one side
    /// only, so the new vertex lies on the neighbour's edge.
    Tjunction,
    /// The largest flat region (coplanar, same material, edge-connected, without holes; one
    /// that does not emit if there is one)
    /// re-triangulated from its outline (few huge triangles), and an object near it (the
    /// nearest of those at most half its size) split uniformly into at least `--amount` tiny
    /// triangles (default 4000).
    HugeTiny,
}

impl VariantKind {
    /// Every kind, in the order of the documentation.
    pub const ALL: [VariantKind; 7] = [
        VariantKind::Fan,
        VariantKind::Random,
        VariantKind::Jitter,
        VariantKind::Translate,
        VariantKind::Twins,
        VariantKind::Tjunction,
        VariantKind::HugeTiny,
    ];

    /// The kind's name on the command line (`fan`, ..., `huge-tiny`).
    pub fn name(self) -> &'static str {
        match self {
            VariantKind::Fan => "fan",
            VariantKind::Random => "random",
            VariantKind::Jitter => "jitter",
            VariantKind::Translate => "translate",
            VariantKind::Twins => "twins",
            VariantKind::Tjunction => "tjunction",
            VariantKind::HugeTiny => "huge-tiny",
        }
    }

    /// The amount used when none is given; `None` for [`VariantKind::Twins`], which takes none.
    pub fn default_amount(self) -> Option<f64> {
        match self {
            VariantKind::Fan => Some(8.0),
            VariantKind::Random => Some(3.0),
            VariantKind::Jitter => Some(1e-6),
            VariantKind::Translate => Some(1e3),
            VariantKind::Twins => None,
            VariantKind::Tjunction => Some(0.3),
            VariantKind::HugeTiny => Some(4000.0),
        }
    }
}

/// What [`make_variant`] is asked for besides the kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VariantOptions {
    /// Seed of the random choices (`random`, `jitter`, `tjunction`); the same seed gives the
    /// same variant.
    pub seed: u64,
    /// The kind's amount (see [`VariantKind`]); `None` for the kind's default.
    pub amount: Option<f64>,
}

impl Default for VariantOptions {
    fn default() -> Self {
        VariantOptions {
            seed: 1,
            amount: None,
        }
    }
}

/// One row of a variant's map: variant triangle `variant` covers `area` (world units squared,
/// measured on the original) of original triangle `original`.
///
/// Every variant triangle has at least one row; it has several only when it covers several
/// original triangles (the merged region of [`VariantKind::HugeTiny`]). For every original
/// triangle the areas of its rows with `same_side` sum to its own area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapRow {
    /// Index of the variant's triangle (its position in the variant's file order).
    pub variant: u32,
    /// Index of the input triangle it covers (its position in the input's file order).
    pub original: u32,
    /// Area of the original triangle this row covers, world units squared.
    pub area: f64,
    /// True when the variant triangle faces the way the original does (false for the reversed
    /// copies of [`VariantKind::Twins`]). Only these rows carry the original's result.
    pub same_side: bool,
}

/// A scene re-triangulated by [`make_variant`], with its map back to the input.
#[derive(Clone, Debug)]
pub struct Variant {
    /// The kind of variant.
    pub kind: VariantKind,
    /// The amount used (the given one or the kind's default; `None` for twins).
    pub amount: Option<f64>,
    /// The seed used.
    pub seed: u64,
    /// The variant scene: materials (index, name, albedo, emission) copied from the input
    /// triangle each triangle comes from. Triangles without a material come first (an OBJ file
    /// cannot switch back to no material); the others keep the input's order.
    pub scene: Scene,
    /// Rows sorted by variant triangle, then original triangle.
    pub map: Vec<MapRow>,
    /// One line saying what was done (for titles and summaries).
    pub note: String,
}

/// Header of the map CSV written by [`write_variant`] and read by [`read_map`]; `facing` is 1
/// for `same_side` rows and -1 for the others.
pub const MAP_CSV_HEADER: &str = "variant_index,original_index,area,facing";

/// The map file written next to `out` (`OUT.obj` -> `OUT.map.csv`).
pub fn map_path(out: &Path) -> PathBuf {
    out.with_extension("map.csv")
}

/// `p` as a hash key: the bits of its coordinates (`+ 0.0` makes -0.0 and 0.0 equal).
fn key(p: DVec3) -> [u64; 3] {
    p.to_array().map(|x| (x + 0.0).to_bits())
}

/// An undirected edge by the keys of its two ends, the lower first.
type EdgeKey = ([u64; 3], [u64; 3]);

/// Area of a triangle given by its corners.
pub fn triangle_area(t: &[DVec3; 3]) -> f64 {
    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()
}

/// Aspect ratio of a triangle: its longest edge over its height on that edge
/// (`longest^2 / (2 area)`); about 1.15 for an equilateral triangle, infinite when degenerate.
pub fn aspect_ratio(t: &[DVec3; 3]) -> f64 {
    let longest = (0..3)
        .map(|i| (t[(i + 1) % 3] - t[i]).length_squared())
        .fold(0.0, f64::max);
    let area = triangle_area(t);
    if area > 0.0 {
        longest / (2.0 * area)
    } else {
        f64::INFINITY
    }
}

/// Triangles being made, each with the input triangle whose material it takes, and map rows.
#[derive(Default)]
struct Out {
    tris: Vec<[DVec3; 3]>,
    source: Vec<u32>,
    rows: Vec<MapRow>,
}

impl Out {
    /// Adds a triangle that covers `area` of input triangle `original` (and takes its
    /// material).
    fn push(&mut self, tri: [DVec3; 3], original: usize, area: f64, same_side: bool) {
        self.rows.push(MapRow {
            variant: self.tris.len() as u32,
            original: original as u32,
            area,
            same_side,
        });
        self.tris.push(tri);
        self.source.push(original as u32);
    }

    /// Adds a piece of input triangle `original`: it covers its own area of it.
    fn piece(&mut self, tri: [DVec3; 3], original: usize) {
        self.push(tri, original, triangle_area(&tri), true);
    }
}

/// The material index of triangle `t`, when it names a material the scene knows.
fn material_of(scene: &Scene, t: usize) -> Option<u32> {
    scene
        .material
        .get(t)
        .copied()
        .flatten()
        .filter(|&m| (m as usize) < scene.material_names.len())
}

/// The amount [`make_variant`] uses for `kind`: `amount`, or the kind's default when `None`.
///
/// Errors: [`Error::Parameter`] for an amount outside the kind's range: fan a whole number
/// 1..=1000, random a whole number 0..=1000, jitter finite and >= 0, translate finite, twins
/// none, tjunction in (0, 1], huge-tiny a whole number 1..=10^7.
pub fn resolve_amount(kind: VariantKind, amount: Option<f64>) -> Result<Option<f64>> {
    let Some(a) = amount else {
        return Ok(kind.default_amount());
    };
    let whole = |lo: f64, hi: f64, what: &str| -> Result<Option<f64>> {
        if a.is_finite() && a.fract() == 0.0 && (lo..=hi).contains(&a) {
            Ok(Some(a))
        } else {
            Err(Error::Parameter(format!(
                "VariantOptions::amount {a} ({what}) must be a whole number in {lo}..={hi}"
            )))
        }
    };
    let check = |ok: bool, what: &str| -> Result<Option<f64>> {
        if ok {
            Ok(Some(a))
        } else {
            Err(Error::Parameter(format!(
                "VariantOptions::amount {a} ({what})"
            )))
        }
    };
    match kind {
        VariantKind::Fan => whole(1.0, 1000.0, "slivers per triangle"),
        VariantKind::Random => whole(0.0, 1000.0, "interior points per triangle"),
        VariantKind::Jitter => check(
            a.is_finite() && a >= 0.0,
            "jitter distance: must be finite and >= 0",
        ),
        VariantKind::Translate => check(a.is_finite(), "translation: must be finite"),
        VariantKind::Twins => Err(Error::Parameter(format!(
            "VariantOptions::amount {a} does not apply to the twins variant"
        ))),
        VariantKind::Tjunction => check(
            a.is_finite() && a > 0.0 && a <= 1.0,
            "share of shared edges: must be in (0, 1]",
        ),
        VariantKind::HugeTiny => whole(1.0, 1e7, "tiny triangles"),
    }
}

/// The material files `obj_path` names (`mtllib`, resolved as [`crate::scene::load_obj`]
/// resolves them) that exist, in order.
///
/// Errors: [`Error::Io`] when `obj_path` cannot be read as text.
pub fn material_files(obj_path: &Path) -> Result<Vec<PathBuf>> {
    let text = std::fs::read_to_string(obj_path).map_err(|e| Error::io(obj_path, e))?;
    let dir = obj_path.parent().unwrap_or(Path::new("."));
    let mut files = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        let Some(rest) = line.strip_prefix("mtllib") else {
            continue;
        };
        if !rest.starts_with(char::is_whitespace) {
            continue;
        }
        let name = rest.trim();
        let names: Vec<&str> = if dir.join(name).is_file() || !name.contains(char::is_whitespace) {
            vec![name]
        } else {
            name.split_whitespace().collect()
        };
        files.extend(
            names
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

/// Builds a bad triangulation of `scene` (see [`VariantKind`] for each kind and its amount).
///
/// The input is any loaded scene; its triangles' materials (index, albedo, emission, name)
/// go to every triangle made from them. Degenerate input triangles are copied unchanged.
///
/// Errors: [`Error::Parameter`] for an empty scene, an amount outside its range
/// ([`resolve_amount`]), a variant of more than [`MAX_PATCHES`] triangles or one with a
/// non-finite vertex (a translation or jitter beyond the range of f64).
pub fn make_variant(scene: &Scene, kind: VariantKind, options: &VariantOptions) -> Result<Variant> {
    if scene.is_empty() {
        return Err(Error::Parameter(
            "variant: the scene has no triangles".into(),
        ));
    }
    let amount = resolve_amount(kind, options.amount)?;
    let a = amount.unwrap_or(0.0);
    let too_many = |count: u64| -> Result<()> {
        if count > MAX_PATCHES {
            Err(Error::Parameter(format!(
                "the {} variant would have {count} triangles (at most {MAX_PATCHES}); choose a smaller VariantOptions::amount",
                kind.name()
            )))
        } else {
            Ok(())
        }
    };
    let n = scene.len();
    let seed = options.seed;
    let (out, note) = match kind {
        VariantKind::Fan => {
            let k = a as usize;
            too_many(n as u64 * (2 * k as u64 - 1))?;
            (
                fan(scene, k),
                format!(
                    "fan: every triangle split into {} slivers (k = {k})",
                    2 * k - 1
                ),
            )
        }
        VariantKind::Random => {
            let points = a as usize;
            too_many(n as u64 * (2 * points as u64 + 7))?;
            (
                random(scene, points, seed),
                format!(
                    "random: {points} random interior points per triangle, 0-2 per edge, seed {seed}"
                ),
            )
        }
        VariantKind::Jitter => (
            jitter(scene, a, seed),
            format!("jitter: every vertex moved by at most {a}, seed {seed}"),
        ),
        VariantKind::Translate => (
            translate(scene, a),
            format!("translate: every vertex moved by ({a}, {a}, {a})"),
        ),
        VariantKind::Twins => {
            too_many(2 * n as u64)?;
            (
                twins(scene),
                format!(
                    "twins: triangles 0..{n} as given, {n}..{} their reversed copies",
                    2 * n
                ),
            )
        }
        VariantKind::Tjunction => {
            let out = tjunction(scene, a, seed);
            let added = out.tris.len() - n;
            (
                out,
                format!(
                    "tjunction: {added} shared edges (share {a}) split on one side only, seed {seed}"
                ),
            )
        }
        VariantKind::HugeTiny => {
            let tiny = a as usize;
            let (out, note) = huge_tiny(scene, tiny)?;
            too_many(out.tris.len() as u64)?;
            (out, note)
        }
    };
    if let Some(t) = out
        .tris
        .iter()
        .position(|t| !t.iter().all(|p| p.is_finite()))
    {
        return Err(Error::Parameter(format!(
            "the {} variant's triangle {t} has a non-finite vertex (VariantOptions::amount {a} too large)",
            kind.name()
        )));
    }
    Ok(assemble(scene, out, kind, amount, seed, note))
}

/// Turns the triangles made into a [`Scene`]: triangles without a material first, vertices
/// shared where bit-identical, materials copied; the map follows the new order.
fn assemble(
    source: &Scene,
    out: Out,
    kind: VariantKind,
    amount: Option<f64>,
    seed: u64,
    note: String,
) -> Variant {
    let count = out.tris.len();
    let mut order: Vec<usize> = (0..count)
        .filter(|&v| material_of(source, out.source[v] as usize).is_none())
        .collect();
    order.extend((0..count).filter(|&v| material_of(source, out.source[v] as usize).is_some()));
    let mut new_index = vec![0u32; count];
    for (i, &v) in order.iter().enumerate() {
        new_index[v] = i as u32;
    }
    let mut scene = Scene {
        material_names: source.material_names.clone(),
        ..Scene::default()
    };
    let mut vertex_of: HashMap<[u64; 3], u32> = HashMap::new();
    for &v in &order {
        let s = out.source[v] as usize;
        let tri = out.tris[v].map(|p| {
            *vertex_of.entry(key(p)).or_insert_with(|| {
                scene.positions.push(p);
                (scene.positions.len() - 1) as u32
            })
        });
        scene.triangles.push(tri);
        scene.albedo.push(source.albedo[s]);
        scene.emission.push(source.emission[s]);
        scene.material.push(material_of(source, s));
    }
    let mut map: Vec<MapRow> = out
        .rows
        .into_iter()
        .map(|r| MapRow {
            variant: new_index[r.variant as usize],
            ..r
        })
        .collect();
    map.sort_by_key(|r| (r.variant, r.original));
    Variant {
        kind,
        amount,
        seed,
        scene,
        map,
        note,
    }
}

// ---------------------------------------------------------------------------------------------
// The kinds

/// `fan`: k slivers from the vertex opposite the shortest edge, plus k - 1 in the strip along
/// that edge; the edge itself is not split, so neighbours see no new vertex.
fn fan(scene: &Scene, k: usize) -> Out {
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t);
        if k == 1 || scene.is_degenerate(t) {
            out.push(c, t, scene.area(t), true);
            continue;
        }
        let length = |i: usize| (c[(i + 1) % 3] - c[i]).length_squared();
        let e = (0..3)
            .min_by(|&i, &j| length(i).total_cmp(&length(j)))
            .unwrap_or(0);
        // (apex, b, c) is a cyclic rotation of the corners: the orientation is kept.
        let (apex, b, cc) = (c[(e + 2) % 3], c[e], c[(e + 1) % 3]);
        // Points on the line parallel to b-cc, a share `delta` of the way to the apex.
        let delta = 1.0 / (2 * k) as f64;
        let p: Vec<DVec3> = (0..=k)
            .map(|j| {
                if j == 0 {
                    b
                } else if j == k {
                    cc
                } else {
                    let on_edge = b + (cc - b) * (j as f64 / k as f64);
                    on_edge * (1.0 - delta) + apex * delta
                }
            })
            .collect();
        for j in 0..k {
            out.piece([apex, p[j], p[j + 1]], t);
        }
        // The strip between the edge b-cc and the chain p[1..k], fanned from b.
        for j in (1..k).rev() {
            let next = if j + 1 == k { cc } else { p[j + 1] };
            out.piece([b, next, p[j]], t);
        }
    }
    out
}

/// The undirected edges of a scene: for every edge (by corner positions), the (triangle, edge)
/// pairs on it; edge `e` of a triangle runs from corner `e` to corner `e + 1`. `order` lists the
/// edges in order of first appearance (triangle order, then edge order).
struct Edges {
    on: HashMap<EdgeKey, Vec<(usize, usize)>>,
    order: Vec<EdgeKey>,
}

fn edge_key(a: DVec3, b: DVec3) -> EdgeKey {
    let (ka, kb) = (key(a), key(b));
    if ka <= kb {
        (ka, kb)
    } else {
        (kb, ka)
    }
}

impl Edges {
    fn of(scene: &Scene, skip_degenerate: bool) -> Edges {
        let mut on: HashMap<_, Vec<(usize, usize)>> = HashMap::new();
        let mut order = Vec::new();
        for t in 0..scene.len() {
            if skip_degenerate && scene.is_degenerate(t) {
                continue;
            }
            let c = scene.corners(t);
            for e in 0..3 {
                let k = edge_key(c[e], c[(e + 1) % 3]);
                let list = on.entry(k).or_default();
                if list.is_empty() {
                    order.push(k);
                }
                list.push((t, e));
            }
        }
        Edges { on, order }
    }
}

/// A point on the edge with canonical key `k` (its lower end `lo`, upper end `hi`) at parameter
/// `s` from `lo`: the same bits whichever triangle asks.
fn on_edge(lo: DVec3, hi: DVec3, s: f64) -> DVec3 {
    lo + (hi - lo) * s
}

/// A point added on edge `e` of a triangle: parameter `s` in (0, 1) from corner `e` to corner
/// `e + 1`, and its position.
type EdgePoint = (f64, DVec3);

/// A vertex of a triangle being split: barycentric weights of corners 1 and 2, position, and
/// (edge, parameter) when it was added on an edge.
type LocalVertex = (DVec2, DVec3, Option<(usize, f64)>);

/// Splits triangle `corners` by inserting `edge_points[e]` (points on its edges, see
/// [`EdgePoint`]) and then the interior points `interior` (barycentric weights of corners 1 and
/// 2), one at a time: an edge point splits the triangle on its piece of the edge in two, an
/// interior point the triangle containing it in three. An interior point that would make a
/// triangle smaller than `min_share` of the whole is left out. Orientation is kept; the
/// pieces cover the triangle exactly.
fn split_triangle(
    corners: [DVec3; 3],
    edge_points: &[Vec<EdgePoint>; 3],
    interior: &[(f64, f64)],
    min_share: f64,
) -> Vec<[DVec3; 3]> {
    // Local vertices: (barycentric weights of corners 1 and 2, position, (edge, parameter)).
    let unit = [
        DVec2::new(0.0, 0.0),
        DVec2::new(1.0, 0.0),
        DVec2::new(0.0, 1.0),
    ];
    let mut local: Vec<LocalVertex> = (0..3).map(|i| (unit[i], corners[i], None)).collect();
    let mut tris: Vec<[usize; 3]> = vec![[0, 1, 2]];
    // Parameter of local vertex `v` along edge `e`, when it lies on it.
    let param = |local: &[LocalVertex], v: usize, e: usize| {
        if v < 3 {
            if v == e {
                Some(0.0)
            } else if v == (e + 1) % 3 {
                Some(1.0)
            } else {
                None
            }
        } else {
            local[v].2.filter(|&(edge, _)| edge == e).map(|(_, s)| s)
        }
    };
    for (e, points) in edge_points.iter().enumerate() {
        for &(s, pos) in points {
            let at = unit[e].lerp(unit[(e + 1) % 3], s);
            let found = tris.iter().enumerate().find_map(|(i, tri)| {
                (0..3).find_map(|r| {
                    let (u, v) = (tri[r], tri[(r + 1) % 3]);
                    match (param(&local, u, e), param(&local, v, e)) {
                        (Some(su), Some(sv)) if su < s && s < sv => Some((i, r)),
                        _ => None,
                    }
                })
            });
            let Some((i, r)) = found else { continue };
            let tri = tris[i];
            let (u, v, w) = (tri[r], tri[(r + 1) % 3], tri[(r + 2) % 3]);
            local.push((at, pos, Some((e, s))));
            let p = local.len() - 1;
            tris[i] = [u, p, w];
            tris.push([p, v, w]);
        }
    }
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    for &(w1, w2) in interior {
        let q = DVec2::new(w1, w2);
        let found = tris.iter().position(|tri| {
            let [a, b, c] = tri.map(|v| local[v].0);
            cross(a, b, q) > 0.0 && cross(b, c, q) > 0.0 && cross(c, a, q) > 0.0
        });
        let Some(i) = found else { continue };
        let [a, b, c] = tris[i];
        let (pa, pb, pc) = (local[a].0, local[b].0, local[c].0);
        // Twice the area of the whole triangle in these coordinates is 1.
        if [cross(pa, pb, q), cross(pb, pc, q), cross(pc, pa, q)]
            .iter()
            .any(|&x| x < min_share)
        {
            continue;
        }
        let pos = corners[0] * (1.0 - w1 - w2) + corners[1] * w1 + corners[2] * w2;
        local.push((q, pos, None));
        let p = local.len() - 1;
        tris[i] = [a, b, p];
        tris.push([b, c, p]);
        tris.push([c, a, p]);
    }
    tris.iter().map(|tri| tri.map(|v| local[v].1)).collect()
}

/// The edge points of triangle `t` given per undirected edge as parameters from the edge's
/// lower end.
fn edge_points_of(
    scene: &Scene,
    t: usize,
    points: &HashMap<EdgeKey, Vec<(usize, f64)>>,
) -> [Vec<EdgePoint>; 3] {
    let c = scene.corners(t);
    std::array::from_fn(|e| {
        let (a, b) = (c[e], c[(e + 1) % 3]);
        let k = edge_key(a, b);
        let forward = key(a) <= key(b);
        let (lo, hi) = if forward { (a, b) } else { (b, a) };
        let mut list: Vec<EdgePoint> = points
            .get(&k)
            .map(|l| {
                l.iter()
                    .filter(|&&(side, _)| side == usize::MAX || side == t)
                    .map(|&(_, s)| {
                        let pos = on_edge(lo, hi, s);
                        (if forward { s } else { 1.0 - s }, pos)
                    })
                    .collect()
            })
            .unwrap_or_default();
        list.sort_by(|x, y| x.0.total_cmp(&y.0));
        list
    })
}

/// `random`: 0-2 random points per edge (shared by both sides), `points` random interior
/// points per triangle.
fn random(scene: &Scene, points: usize, seed: u64) -> Out {
    let edges = Edges::of(scene, true);
    let mut on: HashMap<EdgeKey, Vec<(usize, f64)>> = HashMap::new();
    for (i, k) in edges.order.iter().enumerate() {
        let mut rng = Rng::new(seed ^ 0x5eed_ed6e, i as u64);
        let count = rng.below(3) as usize;
        let mut s: Vec<f64> = (0..count).map(|_| 0.1 + 0.8 * rng.next_f64()).collect();
        s.sort_by(f64::total_cmp);
        s.dedup_by(|a, b| (*a - *b).abs() < 0.05);
        on.insert(*k, s.into_iter().map(|s| (usize::MAX, s)).collect());
    }
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t);
        if scene.is_degenerate(t) {
            out.push(c, t, 0.0, true);
            continue;
        }
        let mut rng = Rng::new(seed, t as u64);
        let interior: Vec<(f64, f64)> = (0..points)
            .map(|_| {
                // Uniform over the triangle.
                let (u1, u2) = (rng.next_f64(), rng.next_f64());
                let r = u1.sqrt();
                (u2 * r, r - u2 * r)
            })
            .collect();
        for piece in split_triangle(c, &edge_points_of(scene, t, &on), &interior, 1e-3) {
            out.piece(piece, t);
        }
    }
    out
}

/// `tjunction`: a share of the edges shared by exactly two triangles gets a point on one side.
fn tjunction(scene: &Scene, share: f64, seed: u64) -> Out {
    let edges = Edges::of(scene, true);
    let mut on: HashMap<EdgeKey, Vec<(usize, f64)>> = HashMap::new();
    for (i, k) in edges.order.iter().enumerate() {
        let sides = &edges.on[k];
        if sides.len() != 2 {
            continue;
        }
        let mut rng = Rng::new(seed ^ 0x7_1c7, i as u64);
        if rng.next_f64() >= share {
            continue;
        }
        let side = sides[rng.below(2) as usize].0;
        let s = 0.3 + 0.4 * rng.next_f64();
        on.insert(*k, vec![(side, s)]);
    }
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t);
        if scene.is_degenerate(t) {
            out.push(c, t, 0.0, true);
            continue;
        }
        let points = edge_points_of(scene, t, &on);
        if points.iter().all(Vec::is_empty) {
            out.push(c, t, scene.area(t), true);
            continue;
        }
        for piece in split_triangle(c, &points, &[], 0.0) {
            out.piece(piece, t);
        }
    }
    out
}

/// `jitter`: every distinct vertex moved by a random vector of length at most `distance`,
/// drawn from its own position's bits (so shared vertices move together).
fn jitter(scene: &Scene, distance: f64, seed: u64) -> Out {
    let mut moved: HashMap<[u64; 3], DVec3> = HashMap::new();
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t).map(|p| {
            *moved.entry(key(p)).or_insert_with(|| {
                let k = key(p);
                let index = mix64(k[0]) ^ mix64(k[1] ^ 0x9e37_79b9) ^ mix64(k[2] ^ 0x7f4a_7c15);
                let mut rng = Rng::new(seed, index);
                // Uniform in the ball, by rejection; a hair inside so that rounding p + d
                // never moves p by more than `distance`.
                let d = loop {
                    let d = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * 2.0
                        - DVec3::ONE;
                    if d.length_squared() <= 1.0 {
                        break d;
                    }
                };
                let moved = p + d * (distance * (1.0 - 1e-9));
                if (moved - p).length() <= distance {
                    moved
                } else {
                    p
                }
            })
        });
        out.push(c, t, scene.area(t), true);
    }
    out
}

/// `translate`: every vertex plus (a, a, a).
fn translate(scene: &Scene, a: f64) -> Out {
    let offset = DVec3::splat(a);
    let mut out = Out::default();
    for t in 0..scene.len() {
        out.push(scene.corners(t).map(|p| p + offset), t, scene.area(t), true);
    }
    out
}

/// `twins`: the triangles, then their reversed copies.
fn twins(scene: &Scene) -> Out {
    let mut out = Out::default();
    for t in 0..scene.len() {
        out.push(scene.corners(t), t, scene.area(t), true);
    }
    for t in 0..scene.len() {
        let [a, b, c] = scene.corners(t);
        out.push([a, c, b], t, scene.area(t), false);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// huge-tiny

/// Disjoint sets over `0..n`.
struct UnionFind(Vec<usize>);

impl UnionFind {
    fn new(n: usize) -> UnionFind {
        UnionFind((0..n).collect())
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb)] = ra.min(rb);
        }
    }
    /// The sets, each sorted, in order of their smallest member.
    fn groups(&mut self, members: impl Iterator<Item = usize>) -> Vec<Vec<usize>> {
        let mut index: HashMap<usize, usize> = HashMap::new();
        let mut groups: Vec<Vec<usize>> = Vec::new();
        for x in members {
            let r = self.find(x);
            let g = *index.entry(r).or_insert_with(|| {
                groups.push(Vec::new());
                groups.len() - 1
            });
            groups[g].push(x);
        }
        groups
    }
}

/// The same material: index, albedo and emission bit for bit.
fn same_material(scene: &Scene, a: usize, b: usize) -> bool {
    material_of(scene, a) == material_of(scene, b)
        && scene.albedo[a].map(f64::to_bits) == scene.albedo[b].map(f64::to_bits)
        && scene.emission[a].map(f64::to_bits) == scene.emission[b].map(f64::to_bits)
}

fn unit_normal(c: &[DVec3; 3]) -> DVec3 {
    (c[1] - c[0]).cross(c[2] - c[0]).normalize_or_zero()
}

/// A flat region re-triangulated from its outline: the new triangles (3D, counter-clockwise
/// seen from the front) and, for each, the 2D coordinates of its corners in the region's plane.
struct Merged {
    tris: Vec<[DVec3; 3]>,
    flat: Vec<[DVec2; 3]>,
}

/// A frame of the plane through `origin` with unit normal `n`: 2D coordinates, counter-clockwise
/// seen from the side `n` points to.
struct PlaneFrame {
    origin: DVec3,
    u: DVec3,
    v: DVec3,
}

impl PlaneFrame {
    fn new(origin: DVec3, n: DVec3) -> PlaneFrame {
        let across = if n.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
        let u = across.cross(n).normalize();
        let v = n.cross(u);
        PlaneFrame { origin, u, v }
    }
    fn flat(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }
}

fn flat_area(t: &[DVec2; 3]) -> f64 {
    0.5 * (t[1] - t[0]).perp_dot(t[2] - t[0])
}

/// Tries to re-triangulate `region` (triangles of one plane) from its outline: one boundary
/// loop, exactly collinear outline vertices dropped, ear clipping. `None` when the region is
/// not a simple polygon (holes, touching loops, inconsistent orientation) or the new
/// triangles do not cover exactly its area.
fn merge_region(scene: &Scene, region: &[usize], frame: &PlaneFrame) -> Option<Merged> {
    let mut directed: HashMap<EdgeKey, usize> = HashMap::new();
    let mut position: HashMap<[u64; 3], DVec3> = HashMap::new();
    for &t in region {
        let c = scene.corners(t);
        for e in 0..3 {
            let (a, b) = (c[e], c[(e + 1) % 3]);
            position.insert(key(a), a);
            *directed.entry((key(a), key(b))).or_default() += 1;
        }
    }
    if directed.values().any(|&n| n > 1) {
        return None;
    }
    let mut next: HashMap<[u64; 3], [u64; 3]> = HashMap::new();
    let mut start = None;
    for &t in region {
        let c = scene.corners(t);
        for e in 0..3 {
            let (a, b) = (key(c[e]), key(c[(e + 1) % 3]));
            if !directed.contains_key(&(b, a)) {
                if next.insert(a, b).is_some() {
                    return None;
                }
                start.get_or_insert(a);
            }
        }
    }
    let start = start?;
    let mut outline = vec![start];
    let mut at = start;
    loop {
        at = *next.get(&at)?;
        if at == start {
            break;
        }
        outline.push(at);
        if outline.len() > next.len() {
            return None;
        }
    }
    if outline.len() != next.len() || outline.len() > 4000 {
        return None;
    }
    let mut points: Vec<DVec3> = outline.iter().map(|k| position[k]).collect();
    // Drop outline vertices exactly on the line through their neighbours (to rounding).
    let mut changed = true;
    while changed && points.len() > 3 {
        changed = false;
        let m = points.len();
        for i in 0..m {
            let (a, b, c) = (points[(i + m - 1) % m], points[i], points[(i + 1) % m]);
            let (d1, d2) = (b - a, c - b);
            if d1.cross(d2).length() <= 1e-12 * d1.length() * d2.length() && d1.dot(d2) > 0.0 {
                points.remove(i);
                changed = true;
                break;
            }
        }
    }
    let flat: Vec<DVec2> = points.iter().map(|&p| frame.flat(p)).collect();
    let ears = ear_clip(&flat)?;
    let merged = Merged {
        tris: ears.iter().map(|e| e.map(|i| points[i])).collect(),
        flat: ears.iter().map(|e| e.map(|i| flat[i])).collect(),
    };
    let region_area: f64 = region
        .iter()
        .map(|&t| flat_area(&scene.corners(t).map(|p| frame.flat(p))))
        .sum();
    let merged_area: f64 = merged.flat.iter().map(flat_area).sum();
    let all_positive = merged.flat.iter().all(|t| flat_area(t) > 0.0);
    (all_positive && (merged_area - region_area).abs() <= 1e-9 * region_area).then_some(merged)
}

/// Ear clipping of a simple polygon given counter-clockwise; triangles as index triples.
fn ear_clip(p: &[DVec2]) -> Option<Vec<[usize; 3]>> {
    let area2: f64 = (0..p.len())
        .map(|i| p[i].perp_dot(p[(i + 1) % p.len()]))
        .sum();
    if !(area2 > 0.0) {
        return None;
    }
    let scale = p.iter().fold(0.0f64, |m, q| m.max(q.length()));
    let eps = 1e-14 * scale * scale;
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    let mut idx: Vec<usize> = (0..p.len()).collect();
    let mut out = Vec::with_capacity(p.len().saturating_sub(2));
    let mut from = 0;
    while idx.len() > 3 {
        let m = idx.len();
        let ear = (0..m).map(|step| (from + step) % m).find(|&j| {
            let (a, b, c) = (idx[(j + m - 1) % m], idx[j], idx[(j + 1) % m]);
            if cross(p[a], p[b], p[c]) <= eps {
                return false;
            }
            idx.iter().all(|&q| {
                q == a
                    || q == b
                    || q == c
                    || p[q] == p[a]
                    || p[q] == p[b]
                    || p[q] == p[c]
                    || cross(p[a], p[b], p[q]) < -eps
                    || cross(p[b], p[c], p[q]) < -eps
                    || cross(p[c], p[a], p[q]) < -eps
            })
        })?;
        out.push([idx[(ear + m - 1) % m], idx[ear], idx[(ear + 1) % m]]);
        idx.remove(ear);
        from = ear % idx.len();
    }
    out.push([idx[0], idx[1], idx[2]]);
    Some(out)
}

/// Area of the intersection of two counter-clockwise 2D triangles (Sutherland-Hodgman).
fn overlap_area(a: &[DVec2; 3], b: &[DVec2; 3]) -> f64 {
    let mut poly: Vec<DVec2> = a.to_vec();
    for e in 0..3 {
        let (p, q) = (b[e], b[(e + 1) % 3]);
        let side = |x: DVec2| (q - p).perp_dot(x - p);
        let input = std::mem::take(&mut poly);
        for i in 0..input.len() {
            let (s, t) = (input[i], input[(i + 1) % input.len()]);
            let (ds, dt) = (side(s), side(t));
            if ds >= 0.0 {
                poly.push(s);
            }
            if (ds >= 0.0) != (dt >= 0.0) {
                poly.push(s + (t - s) * (ds / (ds - dt)));
            }
        }
        if poly.len() < 3 {
            return 0.0;
        }
    }
    let area2: f64 = (0..poly.len())
        .map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()]))
        .sum();
    (0.5 * area2).max(0.0)
}

/// `huge-tiny`: the largest flat region merged, the object nearest to it split into at least
/// `tiny` triangles.
fn huge_tiny(scene: &Scene, tiny: usize) -> Result<(Out, String)> {
    let n = scene.len();
    let (lo, hi) = scene.bounds();
    let diameter = (hi - lo).length();
    let tol = 1e-6 * diameter;
    let normals: Vec<DVec3> = (0..n).map(|t| unit_normal(&scene.corners(t))).collect();
    let live: Vec<bool> = (0..n).map(|t| !scene.is_degenerate(t)).collect();

    // Flat regions: edge neighbours in the same plane, same material, opposite edge directions.
    let edges = Edges::of(scene, true);
    let mut sets = UnionFind::new(n);
    for k in &edges.order {
        let sides = &edges.on[k];
        if sides.len() != 2 {
            continue;
        }
        let ((t1, e1), (t2, e2)) = (sides[0], sides[1]);
        let (c1, c2) = (scene.corners(t1), scene.corners(t2));
        let opposite = key(c1[e1]) == key(c2[(e2 + 1) % 3]);
        let far = c2[(e2 + 2) % 3];
        if opposite
            && same_material(scene, t1, t2)
            && normals[t1].dot(normals[t2]) >= 1.0 - 1e-8
            && (far - c1[0]).dot(normals[t1]).abs() <= tol
        {
            sets.union(t1, t2);
        }
    }
    let mut regions = sets.groups((0..n).filter(|&t| live[t]));
    let region_area = |r: &Vec<usize>| r.iter().map(|&t| scene.area(t)).sum::<f64>();
    // Reflecting regions first (the huge triangle should receive light), then by area.
    let emits = |r: &Vec<usize>| scene.is_emitter(r[0]);
    regions.sort_by(|a, b| {
        emits(a)
            .cmp(&emits(b))
            .then(region_area(b).total_cmp(&region_area(a)))
    });

    let mut chosen = None;
    for region in regions.iter().take(50) {
        let area = region_area(region);
        let normal = region
            .iter()
            .map(|&t| normals[t] * scene.area(t))
            .sum::<DVec3>()
            .normalize_or_zero();
        let origin = scene.corners(region[0])[0];
        let flat_enough = region.iter().all(|&t| {
            scene
                .corners(t)
                .iter()
                .all(|p| (*p - origin).dot(normal).abs() <= tol)
        });
        if normal == DVec3::ZERO || !flat_enough {
            continue;
        }
        let frame = PlaneFrame::new(origin, normal);
        if let Some(merged) = merge_region(scene, region, &frame) {
            chosen = Some((region.clone(), frame, normal, merged, area));
            break;
        }
    }
    let (region, frame, normal, merged, area) = match chosen {
        Some(c) => c,
        None => {
            // Every large region has holes: the largest triangle is the huge one.
            let t = (0..n)
                .filter(|&t| live[t])
                .max_by(|&a, &b| scene.area(a).total_cmp(&scene.area(b)))
                .ok_or_else(|| Error::Parameter("variant: every triangle is degenerate".into()))?;
            let c = scene.corners(t);
            let frame = PlaneFrame::new(c[0], normals[t]);
            let merged = Merged {
                tris: vec![c],
                flat: vec![c.map(|p| frame.flat(p))],
            };
            (vec![t], frame, normals[t], merged, scene.area(t))
        }
    };
    let in_region: Vec<bool> = {
        let mut v = vec![false; n];
        for &t in &region {
            v[t] = true;
        }
        v
    };

    // Objects: the other triangles connected through shared vertices.
    let mut by_vertex: HashMap<[u64; 3], usize> = HashMap::new();
    let mut objects = UnionFind::new(n);
    for t in (0..n).filter(|&t| live[t] && !in_region[t]) {
        for p in scene.corners(t) {
            let first = *by_vertex.entry(key(p)).or_insert(t);
            objects.union(first, t);
        }
    }
    let objects = objects.groups((0..n).filter(|&t| live[t] && !in_region[t]));
    // Objects at most half the region's size, if there are any (else all): the nearest to the
    // region's plane (touching counts as 0), then the smallest by area.
    let extent = |tris: &[usize]| {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in tris.iter().flat_map(|&t| scene.corners(t)) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (hi - lo).length()
    };
    let region_extent = extent(&region);
    let small: Vec<&Vec<usize>> = objects
        .iter()
        .filter(|o| extent(o) <= 0.5 * region_extent)
        .collect();
    let candidates = if small.is_empty() {
        objects.iter().collect()
    } else {
        small
    };
    let rank = |o: &Vec<usize>| {
        let d = o
            .iter()
            .flat_map(|&t| scene.corners(t))
            .map(|p| (p - frame.origin).dot(normal).abs())
            .fold(f64::INFINITY, f64::min);
        let d = if d <= tol { 0.0 } else { d };
        (d, o.iter().map(|&t| scene.area(t)).sum::<f64>())
    };
    let nearest = candidates.into_iter().min_by(|a, b| {
        let (ra, rb) = (rank(a), rank(b));
        ra.0.total_cmp(&rb.0).then(ra.1.total_cmp(&rb.1))
    });
    let (object, k) = match nearest {
        Some(o) => {
            let k = ((tiny as f64 / o.len() as f64).sqrt().ceil() as usize).max(2);
            (o.clone(), k)
        }
        None => (Vec::new(), 1),
    };
    let in_object: HashMap<usize, usize> =
        object.iter().enumerate().map(|(i, &t)| (t, i)).collect();
    let pieces = if object.is_empty() {
        Scene::default()
    } else {
        let corners: Vec<[DVec3; 3]> = object.iter().map(|&t| scene.corners(t)).collect();
        let zero = vec![[0.0; 3]; object.len()];
        crate::scene::generated::subdivide(&Scene::from_triangles(&corners, &zero, &zero), k)
    };

    // Which original triangles each merged triangle covers (2D overlaps in the plane, scaled
    // so that each original's rows sum to its own area).
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); merged.tris.len()];
    for &t in &region {
        let flat = scene.corners(t).map(|p| frame.flat(p));
        let (fmin, fmax) = (
            flat[0].min(flat[1]).min(flat[2]),
            flat[0].max(flat[1]).max(flat[2]),
        );
        let mut overlaps: Vec<(usize, f64)> = Vec::new();
        for (m, tri) in merged.flat.iter().enumerate() {
            let (tmin, tmax) = (
                tri[0].min(tri[1]).min(tri[2]),
                tri[0].max(tri[1]).max(tri[2]),
            );
            if tmin.x > fmax.x || tmin.y > fmax.y || tmax.x < fmin.x || tmax.y < fmin.y {
                continue;
            }
            let a = overlap_area(&flat, tri);
            if a > 1e-12 * flat_area(&flat).abs() {
                overlaps.push((m, a));
            }
        }
        let total: f64 = overlaps.iter().map(|o| o.1).sum();
        for (m, a) in overlaps {
            rows[m].push((t, a * scene.area(t) / total));
        }
    }

    let mut out = Out::default();
    let mut region_done = false;
    for (t, &in_region) in in_region.iter().enumerate() {
        if in_region {
            if !region_done {
                region_done = true;
                for (m, tri) in merged.tris.iter().enumerate() {
                    let v = out.tris.len() as u32;
                    let source = rows[m].first().map(|r| r.0).unwrap_or(t);
                    out.tris.push(*tri);
                    out.source.push(source as u32);
                    for &(original, area) in &rows[m] {
                        out.rows.push(MapRow {
                            variant: v,
                            original: original as u32,
                            area,
                            same_side: true,
                        });
                    }
                }
            }
        } else if let Some(&i) = in_object.get(&t) {
            for p in i * k * k..(i + 1) * k * k {
                out.piece(pieces.corners(p), t);
            }
        } else {
            out.push(scene.corners(t), t, scene.area(t), true);
        }
    }
    let note = format!(
        "huge-tiny: a flat region of {} triangles (area {}) as {} triangles, an object of {} triangles as {} (k = {k})",
        region.len(),
        area,
        merged.tris.len(),
        object.len(),
        object.len() * k * k
    );
    Ok((out, note))
}

// ---------------------------------------------------------------------------------------------
// Files

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
/// Each file is written atomically, the MTL and map files first; on failure the files this
/// call created are removed again.
///
/// Errors: [`Error::Parameter`] for an `out` without a file name or ending in `.mtl`, or a
/// triangle whose material has no name; [`Error::Io`] (one line naming the file) when a file
/// cannot be written.
pub fn write_variant(variant: &Variant, out: &Path, mtl_text: &str, title: &str) -> Result<()> {
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
    let mut current: Option<u32> = None;
    for (t, f) in scene.triangles.iter().enumerate() {
        let m = material_of(scene, t);
        if m != current {
            let Some(m) = m else {
                return Err(Error::Parameter(format!(
                    "variant: triangle {t} has no material after triangles that have one"
                )));
            };
            let _ = writeln!(obj, "usemtl {}", scene.material_names[m as usize]);
            current = Some(m);
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
