//! Stage 1: load an OBJ+MTL or glTF 2.0 scene into a flat list of input triangles with
//! materials (textures averaged per triangle, [`texture`]) and analytic lights ([`lights`]).
//!
//! Polygons are triangulated in file order (convex ones fanned from their first corner, concave
//! ones ear-clipped: [`crate::geometry::polygon::triangulate`]); a triangle's index is its
//! position in that order,
//! and this order is the contract for every per-triangle output. Positions are kept in f64 so that a
//! scene translated far from the origin keeps its precision. Every line-level problem is reported as
//! `file:line: message` before tobj ever sees the file (tobj 4.0.5 panics on some malformed lines).

pub mod generated;
pub mod gltf;
pub mod interiors;
pub mod lights;
mod mtllib;
mod obj;
pub mod texture;
pub mod variants;
pub mod write_obj;

use rayon::prelude::*;
use std::path::PathBuf;

use glam::DVec3;

use crate::error::{Error, Result, Warning};
use crate::geometry::point_key;

/// Largest number of patches a `max_edge` may split a scene into (and most triangles a generated scene may have) (a guard against a typo such
/// as a length in the wrong unit, which would otherwise exhaust memory before any message; a
/// scene that has more triangles than this to begin with is not refused).
pub const MAX_PATCHES: u64 = 1 << 22;

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
                "SceneOptions::default_albedo {} is outside [0, 1)",
                self.default_albedo
            )));
        }
        if !(self.emission.is_finite() && self.emission >= 0.0) {
            return Err(Error::Parameter(format!(
                "SceneOptions::emission {} must be finite and >= 0",
                self.emission
            )));
        }
        if let Some(y) = self.emit_above {
            if !y.is_finite() {
                return Err(Error::Parameter(format!(
                    "SceneOptions::emit_above {y} must be finite"
                )));
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
    /// Input triangles, indices into `positions`, in file order (convex polygons fanned from
    /// their first corner, concave ones ear-clipped: [`crate::geometry::polygon::triangulate`]).
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
    pub warnings: Vec<Warning>,
    /// The camera the scene was published with, if its file names one (a comment line
    /// `# camera eye X Y Z target X Y Z fov DEG`, see [`SceneCamera::parse`]); a picture of the
    /// scene uses it unless told otherwise.
    pub camera: Option<SceneCamera>,
    /// Analytic lights (point, spot, sun, sky) in the scene's frame, radiometric units
    /// ([`lights`]); from glTF's `KHR_lights_punctual` or the command line.
    pub lights: Vec<lights::Light>,
    /// Per-triangle: the surface is two-sided. It emits and reflects on both faces (each face
    /// has its own radiance, the back one reported as [`crate::solve::solution::Solution`]'s
    /// `triangle_radiance_back`) and blocks light arriving at either. May be shorter than the
    /// triangle list: missing entries mean one-sided (front = counter-clockwise). Set from
    /// glTF's `doubleSided`, [`Scene::set_two_sided`] or [`Scene::set_two_sided_material`].
    pub two_sided: Vec<bool>,
}

/// A camera stored with a scene: where the eye is, what it looks at, the vertical field of view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneCamera {
    /// Eye position, scene units.
    pub eye: DVec3,
    /// Point looked at, scene units (not the eye).
    pub target: DVec3,
    /// Vertical field of view, degrees, in (0, 180).
    pub fov_deg: f64,
}

impl SceneCamera {
    /// The prefix of the comment line that stores a camera in an OBJ file.
    pub const PREFIX: &'static str = "# camera ";

    /// Reads `# camera eye X Y Z target X Y Z fov DEG`; `None` for any other line. `Some(Err)`
    /// names what is wrong with a camera line that is malformed (a warning: the scene still
    /// loads).
    pub fn parse(line: &str) -> Option<std::result::Result<SceneCamera, String>> {
        let rest = line.trim().strip_prefix(Self::PREFIX.trim_end())?;
        let words: Vec<&str> = rest.split_whitespace().collect();
        let bad = || {
            format!(
                "camera comment '{}' is not '{}eye X Y Z target X Y Z fov DEG' with a finite eye \
                 apart from the target and a field of view in (0, 180); ignored",
                line.trim(),
                Self::PREFIX
            )
        };
        let numbers = |w: &[&str]| -> Option<Vec<f64>> {
            w.iter()
                .map(|x| x.parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect()
        };
        let camera = (|| {
            if words.len() != 10 || words[0] != "eye" || words[4] != "target" || words[8] != "fov" {
                return None;
            }
            let eye = numbers(&words[1..4])?;
            let target = numbers(&words[5..8])?;
            let fov_deg = numbers(&words[9..10])?[0];
            let camera = SceneCamera {
                eye: DVec3::new(eye[0], eye[1], eye[2]),
                target: DVec3::new(target[0], target[1], target[2]),
                fov_deg,
            };
            (camera.eye != camera.target && fov_deg > 0.0 && fov_deg < 180.0).then_some(camera)
        })();
        Some(camera.ok_or_else(bad))
    }

    /// The comment line [`SceneCamera::parse`] reads back.
    pub fn to_line(&self) -> String {
        let f = crate::files::format_f64;
        format!(
            "{}eye {} {} {} target {} {} {} fov {}",
            Self::PREFIX,
            f(self.eye.x),
            f(self.eye.y),
            f(self.eye.z),
            f(self.target.x),
            f(self.target.y),
            f(self.target.z),
            f(self.fov_deg)
        )
    }
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

pub use crate::geometry::tolerances::DEGENERATE_SIN;
pub use obj::load_obj;

/// Largest albedo the loaders keep from a texture or a glTF factor (the model needs albedo
/// below 1); higher values are lowered to it with a warning.
pub const ALBEDO_MAX: f64 = 0.99;

/// Reads a scene file: glTF 2.0 (`.gltf`, `.glb`, see [`gltf::load_gltf`]) by its extension,
/// Wavefront OBJ ([`load_obj`]) otherwise.
pub fn load_scene(path: &std::path::Path, options: &SceneOptions) -> Result<Scene> {
    if gltf::is_gltf(path) {
        gltf::load_gltf(path, options)
    } else {
        load_obj(path, options)
    }
}

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

    /// True when triangle `t` is two-sided ([`Scene::two_sided`]).
    pub fn is_two_sided(&self, t: usize) -> bool {
        self.two_sided.get(t).copied().unwrap_or(false)
    }

    /// True when some triangle is two-sided.
    pub fn has_two_sided(&self) -> bool {
        self.two_sided.iter().any(|&b| b)
    }

    /// Makes every triangle two-sided.
    pub fn set_two_sided(&mut self) {
        self.two_sided = vec![true; self.len()];
    }

    /// Makes the triangles of material `name` two-sided; returns how many there are.
    ///
    /// Errors: [`Error::Parameter`] when the scene defines no material of that name.
    pub fn set_two_sided_material(&mut self, name: &str) -> Result<usize> {
        let Some(m) = self.material_names.iter().position(|n| n == name) else {
            return Err(Error::Parameter(format!(
                "two-sided material '{name}' is not a material of {} (it has {})",
                self.path.display(),
                if self.material_names.is_empty() {
                    "none".to_string()
                } else {
                    self.material_names.join(", ")
                }
            )));
        };
        self.two_sided.resize(self.len(), false);
        let mut count = 0;
        for t in 0..self.len() {
            if self.material.get(t).copied().flatten() == Some(m as u32) {
                self.two_sided[t] = true;
                count += 1;
            }
        }
        Ok(count)
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
        if let Some(c) = s.camera.as_mut() {
            c.eye = c.eye * scale + offset;
            c.target = c.target * scale + offset;
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

    /// Per triangle, the earlier triangle it is the back-to-back twin of, if any: the same
    /// corners in the reverse order (bit for bit), the same albedo and emission, neither a
    /// duplicate ([`Scene::duplicates`]) nor already paired. Such a pair is one two-sided
    /// surface given as two one-sided ones (as CAD exports write it); the patches merge it
    /// into the earlier triangle made two-sided, whose back face is the twin
    /// ([`crate::mesh::Patches::back_twin`]).
    pub fn back_to_back_twins(&self) -> Vec<Option<u32>> {
        self.back_to_back_twins_given(&self.duplicates())
    }

    /// [`Scene::back_to_back_twins`] with the scene's [`Scene::duplicates`] already known
    /// (`duplicates`: one entry per triangle; a missing entry counts as not a duplicate).
    pub fn back_to_back_twins_given(&self, duplicates: &[Option<u32>]) -> Vec<Option<u32>> {
        let duplicate = |t: usize| duplicates.get(t).copied().flatten().is_some();
        // Every triangle that is neither degenerate nor a duplicate has a corner sequence of its
        // own: the later of a pair whose sequences are each other's reverse is the twin of the
        // earlier (each sequence being unique, "already paired" cannot happen).
        let keyed = self.sorted_corner_keys(|t| !duplicate(t));
        (0..self.len())
            .into_par_iter()
            .map(|t| {
                if self.is_degenerate(t) || duplicate(t) {
                    return None;
                }
                let [a, b, c] = self.corners(t).map(point_key);
                let reversed = canonical_rotation([a, c, b]);
                let i = keyed.partition_point(|(k, _)| *k < reversed);
                let &(k, u) = keyed.get(i)?;
                let same = self.albedo[u as usize] == self.albedo[t]
                    && self.emission[u as usize] == self.emission[t];
                (k == reversed && (u as usize) < t && same).then_some(u)
            })
            .collect()
    }

    /// For every triangle, the first earlier triangle it duplicates, if any: same three corner
    /// positions (bit for bit) in the same cyclic order, i.e. the same surface facing the same
    /// way. Degenerate triangles are never duplicates.
    ///
    /// Duplicates must take part in transport only once: two coincident one-sided surfaces
    /// would reflect the light they receive twice and, in front-only antiradiance, both send
    /// the antiradiance that cancels the light behind them, which then cancels it twice (a
    /// doubled plate made the shadow under it negative). Back-to-back copies (reversed corner
    /// order, a thin two-sided wall) are not duplicates: see [`Scene::back_to_back_twins`].
    pub fn duplicates(&self) -> Vec<Option<u32>> {
        let keyed = self.sorted_corner_keys(|_| true);
        let mut first = vec![None; self.len()];
        // Runs of equal keys are sorted by index: the first of a run is the earliest triangle.
        for run in keyed.chunk_by(|a, b| a.0 == b.0) {
            for &(_, t) in &run[1..] {
                first[t as usize] = Some(run[0].1);
            }
        }
        first
    }

    /// The non-degenerate triangles that `keep`, as (canonical corner key, index) sorted by key
    /// and then index: the key is the three corners' bits in cyclic order from the smallest
    /// (the same for every rotation of the same corners, different for the reversed order).
    fn sorted_corner_keys(&self, keep: impl Fn(usize) -> bool + Sync) -> Vec<(CornerKey, u32)> {
        let mut keyed: Vec<(CornerKey, u32)> = (0..self.len())
            .into_par_iter()
            .filter(|&t| keep(t) && !self.is_degenerate(t))
            .map(|t| (canonical_rotation(self.corners(t).map(point_key)), t as u32))
            .collect();
        keyed.par_sort_unstable();
        keyed
    }
}

/// A triangle's corners as bits, in a cyclic order ([`canonical_rotation`]).
type CornerKey = [[u64; 3]; 3];

/// The rotation of `k` that starts at its smallest corner: the same for every cyclic order of
/// the same corners, different for the reversed order.
fn canonical_rotation(k: CornerKey) -> CornerKey {
    let start = (0..3).min_by_key(|&i| k[i]).unwrap_or(0);
    [k[start], k[(start + 1) % 3], k[(start + 2) % 3]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene of the given corner triples over four points, albedo 0.5 unless listed in `dark`.
    fn scene_of(triangles: &[[u32; 3]], dark: &[usize]) -> Scene {
        let n = triangles.len();
        Scene {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, -0.0)],
            triangles: triangles.to_vec(),
            albedo: (0..n)
                .map(|t| [if dark.contains(&t) { 0.1 } else { 0.5 }; 3])
                .collect(),
            emission: vec![[0.0; 3]; n],
            ..Scene::default()
        }
    }

    #[test]
    fn duplicates_and_twins_follow_the_corner_order() {
        // 0: A; 1: A rotated (a duplicate); 2: B; 3: B reversed, darker (no twin);
        // 4: A reversed (the twin of 0); 5: B reversed and rotated (a duplicate of 3);
        // 6: degenerate (a point repeated).
        let scene = scene_of(
            &[
                [0, 1, 2],
                [1, 2, 0],
                [1, 3, 2],
                [1, 2, 3],
                [0, 2, 1],
                [2, 3, 1],
                [0, 0, 1],
            ],
            &[3, 5],
        );
        assert_eq!(
            scene.duplicates(),
            [None, Some(0), None, None, None, Some(3), None]
        );
        assert_eq!(
            scene.back_to_back_twins(),
            [None, None, None, None, Some(0), None, None]
        );
    }
}
