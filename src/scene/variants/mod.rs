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

use glam::DVec3;

use crate::error::{Error, Result};
use crate::geometry::point_key;
use crate::scene::Scene;
use crate::scene::MAX_PATCHES;

mod files;
mod huge_tiny;
mod kinds;

pub use files::{map_back, material_files, material_text, read_map, write_variant};
use huge_tiny::*;
use kinds::*;

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

/// The undirected edges of a scene: for every edge (by corner positions), the (triangle, edge)
/// pairs on it; edge `e` of a triangle runs from corner `e` to corner `e + 1`. `order` lists the
/// edges in order of first appearance (triangle order, then edge order).
pub(super) struct Edges {
    pub(super) on: HashMap<EdgeKey, Vec<(usize, usize)>>,
    pub(super) order: Vec<EdgeKey>,
}

pub(super) fn edge_key(a: DVec3, b: DVec3) -> EdgeKey {
    let (ka, kb) = (point_key(a), point_key(b));
    if ka <= kb {
        (ka, kb)
    } else {
        (kb, ka)
    }
}

impl Edges {
    pub(super) fn of(scene: &Scene, skip_degenerate: bool) -> Edges {
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
            *vertex_of.entry(point_key(p)).or_insert_with(|| {
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
// huge-tiny
