//! glTF 2.0 output: the baked result as a binary glTF (`.glb`), and a scene as glTF input.
//!
//! [`write_baked_glb`] (`--gltf OUT.glb`) writes the solver's patches in world coordinates,
//! one primitive per material (so colours stay sharp where materials meet; patches without a
//! material share one primitive), with:
//!
//! - `COLOR_0` (VEC3 FLOAT, linear): the area-weighted mean B of the patches sharing the
//!   vertex, welded as the PLY's are (same position, normals within 30 degrees, same emitter
//!   status), times the exposure, clipped to [0, 1] for display;
//! - an unlit material (`KHR_materials_unlit`, white base colour), so that viewers show the
//!   baked light as it is;
//! - per primitive, `extras.radiance`: the index of an accessor (VEC3 FLOAT, one row per
//!   triangle of the primitive, in its index order) with the raw outgoing radiance B in
//!   W / (m^2 sr), and `extras.input_triangle`: an accessor (SCALAR FLOAT, exact below 2^24)
//!   with the index of the input triangle each triangle comes from (the order of the CSV);
//! - in `asset.extras`: the exposure, the units and what the accessors hold.
//!
//! Zero-area and duplicate patches are left out (they add nothing to see). The file is written
//! atomically, like every output.
//!
//! [`write_scene_glb`] writes a [`Scene`] as glTF input that [`crate::scene::gltf`] reads back to
//! the same triangles in the same order with the same materials: one primitive per run of
//! consecutive triangles with the same material, albedo as `baseColorFactor`, emission as
//! `emissiveFactor` x `KHR_materials_emissive_strength` in the photometric convention of
//! [`crate::scene::lights::LUMENS_PER_WATT`], analytic lights (point, spot, sun) as
//! `KHR_lights_punctual` lights.

use std::io::Write;
use std::path::Path;

use glam::{DQuat, DVec3};
use serde_json::{json, Value};

use crate::error::{Error, Result};
use crate::files::write_atomic;
use crate::mesh::Patches;
use crate::output::render;
use crate::scene::lights::{Light, LUMENS_PER_WATT};
use crate::scene::Scene;
use crate::solve::solution::{sanitize, Solution};

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;

/// The binary chunk and the JSON arrays that describe it.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

fn f32_of(x: f64) -> f32 {
    sanitize(x).clamp(f32::MIN as f64, f32::MAX as f64) as f32
}

impl Builder {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut v = json!({
            "buffer": 0,
            "byteOffset": self.bin.len(),
            "byteLength": bytes.len(),
        });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// A VEC3 FLOAT accessor (with min and max, which POSITION needs).
    fn vec3(&mut self, rows: &[[f32; 3]], target: Option<u32>) -> usize {
        let mut bytes = Vec::with_capacity(rows.len() * 12);
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for r in rows {
            for c in 0..3 {
                bytes.extend_from_slice(&r[c].to_le_bytes());
                lo[c] = lo[c].min(r[c]);
                hi[c] = hi[c].max(r[c]);
            }
        }
        let view = self.view(&bytes, target);
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": FLOAT,
            "count": rows.len(),
            "type": "VEC3",
            "min": lo,
            "max": hi,
        }));
        self.accessors.len() - 1
    }

    fn scalar_f32(&mut self, values: &[f32]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, None);
        let lo = values.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": FLOAT,
            "count": values.len(),
            "type": "SCALAR",
            "min": [lo],
            "max": [hi],
        }));
        self.accessors.len() - 1
    }

    fn indices(&mut self, values: &[u32]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": UNSIGNED_INT,
            "count": values.len(),
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }

    /// The whole GLB: `json` completed with the buffer, views and accessors.
    fn glb(mut self, mut json: Value) -> Vec<u8> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        json["buffers"] = json!([{ "byteLength": self.bin.len() }]);
        json["bufferViews"] = Value::Array(std::mem::take(&mut self.views));
        json["accessors"] = Value::Array(std::mem::take(&mut self.accessors));
        let mut text = serde_json::to_vec(&json).unwrap_or_default();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let total = 12 + 8 + text.len() + 8 + self.bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        out
    }
}

fn too_large(path: &Path, bytes: usize) -> Error {
    Error::Io {
        path: path.to_path_buf(),
        message: format!("the glTF would have {bytes} bytes, more than a GLB holds (4 GiB)"),
    }
}

/// Writes the baked result as a binary glTF (see the module doc). `exposure` scales B into the
/// vertex colours (see [`render::auto_exposure`]); it must be finite and > 0.
/// Precondition: `solution.patch_radiance.len() == patches.len()` (an error otherwise).
pub fn write_baked_glb(
    path: &Path,
    scene: &Scene,
    patches: &Patches,
    solution: &Solution,
    exposure: f64,
) -> Result<()> {
    super::check_per_patch(path, patches, solution, exposure)?;
    let groups = material_groups(scene, patches);
    let mut b = Builder::default();
    let mut primitives = Vec::new();
    let mut materials = Vec::new();
    for (m, list) in &groups {
        let baked = baked_primitive(&mut b, patches, solution, exposure, list);
        let name = m
            .and_then(|i| scene.material_names.get(i as usize).cloned())
            .unwrap_or_else(|| "(no material)".to_string());
        materials.push(json!({
            "name": name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0,
            },
            "extensions": { "KHR_materials_unlit": {} },
        }));
        primitives.push(json!({
            "attributes": { "POSITION": baked.pos, "COLOR_0": baked.col },
            "indices": baked.idx,
            "material": materials.len() - 1,
            "mode": 4,
            "extras": { "radiance": baked.rad, "input_triangle": baked.par },
        }));
    }
    let json = json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("antiradiance ", env!("CARGO_PKG_VERSION")),
            "extras": {
                "exposure": exposure,
                "color": "COLOR_0 = min(1, exposure * B), linear; B = outgoing radiance per vertex (area-weighted mean of its triangles)",
                "radiance_units": "W/(m^2 sr)",
                "primitive_extras": "radiance: accessor of B per triangle (VEC3); input_triangle: accessor of the input triangle index per triangle (SCALAR)",
            },
        },
        "extensionsUsed": ["KHR_materials_unlit"],
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": "baked" }],
        "meshes": [{ "name": "baked", "primitives": primitives }],
        "materials": materials,
    });
    let bytes = b.glb(json);
    if bytes.len() > u32::MAX as usize {
        return Err(too_large(path, bytes.len()));
    }
    write_atomic(path, |w| w.write_all(&bytes))
}

/// The active patches grouped by their input triangle's material, in order of first
/// appearance.
fn material_groups(scene: &Scene, patches: &Patches) -> Vec<(Option<u32>, Vec<usize>)> {
    let material_of = |p: usize| {
        scene
            .material
            .get(patches.parent[p] as usize)
            .copied()
            .flatten()
    };
    let mut groups: Vec<(Option<u32>, Vec<usize>)> = Vec::new();
    for p in (0..patches.len()).filter(|&p| patches.active[p]) {
        let m = material_of(p);
        match groups.iter_mut().find(|(g, _)| *g == m) {
            Some((_, list)) => list.push(p),
            None => groups.push((m, vec![p])),
        }
    }
    groups
}

/// The accessors of one baked primitive.
struct BakedAccessors {
    /// Welded vertex positions, world units.
    pos: usize,
    /// Vertex colours.
    col: usize,
    /// Triangle indices.
    idx: usize,
    /// Radiance per triangle.
    rad: usize,
    /// Input triangle per triangle.
    par: usize,
}

/// Adds to `b` the accessors of the primitive of patches `list`: welded positions and colours
/// (B times `exposure`, clipped to [0, 1]), indices, radiance and input triangle per triangle.
fn baked_primitive(
    b: &mut Builder,
    patches: &Patches,
    solution: &Solution,
    exposure: f64,
    list: &[usize],
) -> BakedAccessors {
    let mut sub = Patches {
        frame: patches.frame,
        emission_scale: patches.emission_scale,
        ..Patches::default()
    };
    let mut sub_solution = Solution::default();
    for &p in list {
        sub.push(
            patches.corners[p],
            patches.parent[p],
            patches.albedo[p],
            patches.emission[p],
            true,
        );
        sub_solution.patch_radiance.push(solution.patch_radiance[p]);
    }
    let welded = render::weld(&sub, &sub_solution);
    let positions: Vec<[f32; 3]> = welded
        .positions
        .iter()
        .map(|&q| patches.frame.world_from_unit(q).to_array().map(f32_of))
        .collect();
    let colors: Vec<[f32; 3]> = welded
        .radiance
        .iter()
        .map(|r| r.map(|x| f32_of((x * exposure).clamp(0.0, 1.0))))
        .collect();
    let indices: Vec<u32> = welded.faces.iter().flatten().copied().collect();
    let radiance: Vec<[f32; 3]> = list
        .iter()
        .map(|&p| solution.patch_radiance[p].map(f32_of))
        .collect();
    let parents: Vec<f32> = list.iter().map(|&p| patches.parent[p] as f32).collect();
    BakedAccessors {
        pos: b.vec3(&positions, Some(ARRAY_BUFFER)),
        col: b.vec3(&colors, Some(ARRAY_BUFFER)),
        idx: b.indices(&indices),
        rad: b.vec3(&radiance, None),
        par: b.scalar_f32(&parents),
    }
}

/// Writes a scene as binary glTF input (see the module doc). Errors: an empty scene, arrays of
/// different lengths, a failed write.
pub fn write_scene_glb(path: &Path, scene: &Scene) -> Result<()> {
    let n = scene.len();
    if n == 0 || scene.albedo.len() != n || scene.emission.len() != n {
        return Err(Error::Parameter(format!(
            "{}: the scene has no triangles or its albedo or emission counts differ",
            path.display()
        )));
    }
    let (kind_of, materials) = scene_materials(scene);
    let mut b = Builder::default();
    let primitives = scene_primitives(&mut b, scene, &kind_of);
    let (nodes, lights) = light_nodes(scene);
    let mut used = Vec::new();
    if materials.iter().any(|m| m.get("extensions").is_some()) {
        used.push("KHR_materials_emissive_strength");
    }
    let mut json = json!({
        "asset": { "version": "2.0", "generator": concat!("antiradiance ", env!("CARGO_PKG_VERSION")) },
        "scene": 0,
        "scenes": [{ "nodes": (0..nodes.len()).collect::<Vec<_>>() }],
        "nodes": nodes,
        "meshes": [{ "primitives": primitives }],
        "materials": materials,
    });
    if !lights.is_empty() {
        used.push("KHR_lights_punctual");
        json["extensions"] = json!({ "KHR_lights_punctual": { "lights": lights } });
    }
    if !used.is_empty() {
        json["extensionsUsed"] = json!(used);
    }
    let bytes = b.glb(json);
    if bytes.len() > u32::MAX as usize {
        return Err(too_large(path, bytes.len()));
    }
    write_atomic(path, |w| w.write_all(&bytes))
}

/// Every distinct (material, albedo, emission) of `scene` as a glTF material, in order of first
/// use, and each triangle's index among them.
fn scene_materials(scene: &Scene) -> (Vec<usize>, Vec<Value>) {
    let n = scene.len();
    let material_of = |t: usize| scene.material.get(t).copied().flatten();
    let mut kinds: Vec<(Option<u32>, [u64; 6])> = Vec::new();
    let key = |t: usize| {
        let a = scene.albedo[t];
        let e = scene.emission[t];
        [a[0], a[1], a[2], e[0], e[1], e[2]].map(f64::to_bits)
    };
    let mut kind_of = Vec::with_capacity(n);
    for t in 0..n {
        let k = (material_of(t), key(t));
        let i = match kinds.iter().position(|x| *x == k) {
            Some(i) => i,
            None => {
                kinds.push(k);
                kinds.len() - 1
            }
        };
        kind_of.push(i);
    }
    let mut materials = Vec::new();
    for (i, (m, _)) in kinds.iter().enumerate() {
        let t = kind_of.iter().position(|&k| k == i).unwrap_or(0);
        let a = scene.albedo[t];
        let e = scene.emission[t].map(|x| x * LUMENS_PER_WATT);
        let s = e.iter().copied().fold(0.0f64, f64::max);
        let name = m
            .and_then(|m| scene.material_names.get(m as usize).cloned())
            .unwrap_or_else(|| format!("material{i}"));
        let mut mat = json!({
            "name": name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [a[0], a[1], a[2], 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0,
            },
        });
        if s > 0.0 {
            let (factor, strength) = if s > 1.0 {
                (e.map(|x| x / s), s)
            } else {
                (e, 1.0)
            };
            mat["emissiveFactor"] = json!(factor);
            if strength != 1.0 {
                mat["extensions"] =
                    json!({ "KHR_materials_emissive_strength": { "emissiveStrength": strength } });
            }
        }
        materials.push(mat);
    }
    (kind_of, materials)
}

/// One primitive per run of consecutive triangles of the same material (`kind_of`), three
/// vertices per triangle, into `b`.
fn scene_primitives(b: &mut Builder, scene: &Scene, kind_of: &[usize]) -> Vec<Value> {
    let n = scene.len();
    let mut primitives = Vec::new();
    let mut t = 0;
    while t < n {
        let k = kind_of[t];
        let mut end = t;
        while end < n && kind_of[end] == k {
            end += 1;
        }
        let mut positions = Vec::with_capacity(3 * (end - t));
        for u in t..end {
            for p in scene.corners(u) {
                positions.push(p.to_array().map(f32_of));
            }
        }
        let pos = b.vec3(&positions, Some(ARRAY_BUFFER));
        let idx = b.indices(&(0..positions.len() as u32).collect::<Vec<_>>());
        primitives.push(json!({
            "attributes": { "POSITION": pos },
            "indices": idx,
            "material": k,
            "mode": 4,
        }));
        t = end;
    }
    primitives
}

/// The nodes (the mesh's, then one per analytic light but the sky) and the
/// `KHR_lights_punctual` lights they place.
fn light_nodes(scene: &Scene) -> (Vec<Value>, Vec<Value>) {
    let mut nodes = vec![json!({ "mesh": 0 })];
    let mut lights = Vec::new();
    for light in &scene.lights {
        let (kind, rgb, node) = match *light {
            Light::Point {
                position,
                intensity,
            } => (
                "point",
                intensity,
                json!({ "translation": position.to_array() }),
            ),
            Light::Spot {
                position,
                direction,
                intensity,
                ..
            } => (
                "spot",
                intensity,
                json!({ "translation": position.to_array(), "rotation": rotation_to(direction) }),
            ),
            Light::Sun {
                direction,
                irradiance,
            } => (
                "directional",
                irradiance,
                json!({ "rotation": rotation_to(direction) }),
            ),
            Light::Sky { .. } => continue,
        };
        let s = rgb.iter().copied().fold(0.0f64, f64::max);
        let color = if s > 0.0 {
            rgb.map(|x| x / s)
        } else {
            [1.0; 3]
        };
        let mut l = json!({ "type": kind, "color": color, "intensity": s * LUMENS_PER_WATT });
        if let Light::Spot { inner, outer, .. } = *light {
            l["spot"] = json!({ "innerConeAngle": inner, "outerConeAngle": outer });
        }
        let mut node = node;
        node["extensions"] = json!({ "KHR_lights_punctual": { "light": lights.len() } });
        lights.push(l);
        nodes.push(node);
    }
    (nodes, lights)
}

/// The unit quaternion (x, y, z, w) turning glTF's light axis -Z onto `direction`.
fn rotation_to(direction: DVec3) -> [f64; 4] {
    let d = direction.normalize_or_zero();
    let q = if d == DVec3::ZERO {
        DQuat::IDENTITY
    } else {
        DQuat::from_rotation_arc(DVec3::NEG_Z, d)
    };
    q.normalize().to_array()
}
