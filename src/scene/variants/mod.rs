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
use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};

use crate::error::{Error, Result};
use crate::geometry::sampling::{mix64, Rng};
use crate::scene::Scene;
use crate::scene::MAX_PATCHES;

mod files;
mod huge_tiny;

pub use files::{map_back, read_map, write_variant};
use huge_tiny::*;

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
