//! Stage 1 for glTF 2.0: `.gltf` (with `.bin` files or base64 `data:` URIs) and `.glb`.
//!
//! What is read, and how it maps to the model:
//!
//! - **Triangles**: every primitive of every mesh instanced by a node of the default scene (the
//!   file's `scene`, else its first scene), positions through the node's world transform
//!   (parent x child, a node's own transform as translation x rotation x scale or its
//!   `matrix`). TRIANGLES primitives as they are, TRIANGLE_STRIP and TRIANGLE_FAN converted by
//!   the specification's formulas; POINTS and LINES primitives are skipped with a warning.
//!   Under a transform with a negative determinant (a mirror) the triangles' corner order is
//!   reversed, so that counter-clockwise stays the front side, as glTF prescribes.
//! - **Triangle order**, the contract of every per-triangle output: nodes in depth-first
//!   order of the scene (a root, then its children in the order they are listed, then the next
//!   root), primitives in mesh order, triangles in index order.
//! - **Albedo**: `baseColorFactor` (linear RGB) times the mean of `baseColorTexture` over the
//!   triangle's UV footprint ([`crate::scene::texture`]: sRGB decoded, the sampler's wrap modes)
//!   times the mean of the corners' `COLOR_0`; a primitive without a material takes the grey
//!   `--albedo`. Alpha, metallic-roughness, normal maps and transmission are not modelled.
//!   The model needs albedo below 1: values at or above [`ALBEDO_MAX`] are lowered to it, with
//!   a warning naming the material.
//! - **Emission**: `emissiveFactor` x the mean of `emissiveTexture` x
//!   `KHR_materials_emissive_strength`, read as luminance in cd/m^2 (nits) and divided by
//!   [`LUMENS_PER_WATT`] into radiance, W / (m^2 sr).
//! - **Lights** (`KHR_lights_punctual`), through their nodes' transforms: point and spot lights
//!   (candela) become [`Light::Point`] / [`Light::Spot`] with intensity cd / 683 W/sr,
//!   directional lights (lux) become [`Light::Sun`] with irradiance lux / 683 W/m^2. A light's
//!   `range` is ignored (with a warning): the model's lights fall off as 1 / r^2 everywhere.
//! - `doubleSided` materials are two-sided surfaces ([`Scene::two_sided`]): both faces emit and
//!   reflect, each with its own radiance.
//!
//! Bad files give one-line errors naming the file and, where known, the JSON path (for example
//! `meshes[0].primitives[1].indices`) or byte offset: bad GLB header or truncated file, JSON
//! errors, failed validation (unsupported required extensions included), missing or short
//! buffers and images, accessors outside their buffer, non-finite positions, indices out of
//! range, no triangles. Accessors are read by this module, bounds checked, never by a reader
//! that may panic.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use glam::{DMat4, DQuat, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use crate::error::{Error, Result, Warning, WarningKind};
use crate::scene::lights::{Light, LUMENS_PER_WATT};
use crate::scene::texture::Texture;
use crate::scene::{Scene, SceneOptions, ALBEDO_MAX};

mod data;
mod materials;

use data::{check_glb, read_accessor, read_uri};
use materials::{read_materials, MaterialInfo};

fn scene_err(path: &Path, message: impl Into<String>) -> Error {
    Error::Scene {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// True when `path` names a glTF file (`.gltf` or `.glb`, any case).
pub fn is_gltf(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"))
}

/// A node's own transform in f64.
fn local_matrix(node: &gltf::Node) -> DMat4 {
    match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            DMat4::from_cols_array_2d(&matrix.map(|c| c.map(f64::from)))
        }
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let [x, y, z, w] = rotation.map(f64::from);
            let q = DQuat::from_xyzw(x, y, z, w);
            let q = if q.length() > 0.0 {
                q.normalize()
            } else {
                DQuat::IDENTITY
            };
            DMat4::from_scale_rotation_translation(
                DVec3::from_array(scale.map(f64::from)),
                q,
                DVec3::from_array(translation.map(f64::from)),
            )
        }
    }
}

/// Loads a glTF 2.0 scene (see the module doc). `options.default_albedo` is the albedo of
/// primitives without a material; `options.emit_above` and `options.emission` apply as for
/// OBJ scenes.
pub fn load_gltf(path: &Path, options: &SceneOptions) -> Result<Scene> {
    options.validate()?;
    let (document, blob) = parse(path)?;
    let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut warnings: Vec<Warning> = Vec::new();
    let buffers = read_buffers(path, &base, &document, blob)?;
    for ext in document.extensions_used() {
        if ext == "KHR_texture_transform" {
            warn(&mut warnings, path, WarningKind::Unsupported, "KHR_texture_transform is used but not applied: textures are averaged with untransformed UVs".into());
        }
    }
    let (materials, images) = read_materials(path, &base, &document, &buffers)?;
    let Some(gscene) = document
        .default_scene()
        .or_else(|| document.scenes().next())
    else {
        return Err(scene_err(path, "no scene (the file defines no scenes)"));
    };
    let mut loader = Loader {
        path,
        options,
        buffers: &buffers,
        materials: &materials,
        images: &images,
        scene: Scene {
            path: path.to_path_buf(),
            material_names: materials.iter().map(|m| m.name.clone()).collect(),
            ..Scene::default()
        },
        warnings,
        clamped: HashMap::new(),
        skipped_modes: HashSet::new(),
    };
    loader.add_nodes(gscene)?;
    let (mut scene, warnings) = loader.finish_warnings();
    if let Some(y) = options.emit_above {
        for t in 0..scene.len() {
            if scene.corners(t).iter().all(|p| p.y > y) {
                scene.emission[t] = [options.emission; 3];
            }
        }
    }
    finish(path, scene, warnings)
}

/// Adds a warning about the file `path`.
fn warn(warnings: &mut Vec<Warning>, path: &Path, kind: WarningKind, message: String) {
    warnings.push(Warning::in_file(kind, path, None, message))
}

/// Reads the file, checks a GLB's headers or that it is a JSON object, parses and validates
/// it: the document and the GLB binary chunk, if any.
fn parse(path: &Path) -> Result<(gltf::Document, Option<Vec<u8>>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if bytes.starts_with(b"glTF") {
        check_glb(path, &bytes)?;
    } else if bytes.iter().take(64).all(|b| b.is_ascii_whitespace()) {
        return Err(scene_err(path, "empty file"));
    } else if bytes
        .iter()
        .find(|b| !b.is_ascii_whitespace())
        .is_none_or(|&b| b != b'{')
    {
        return Err(scene_err(
            path,
            "not glTF: neither the GLB magic 'glTF' at byte 0 nor a JSON object",
        ));
    }
    // Parsed first, validated after our own check of the POSITION references (gltf-json 1.4.1's
    // validation indexes the accessors with them unchecked, and panics on a bad one).
    let raw = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| gltf_error(path, e))?;
    check_attribute_accessors(path, raw.document.as_json())?;
    let blob = raw.blob;
    let document =
        gltf::Document::from_json(raw.document.into_json()).map_err(|e| gltf_error(path, e))?;
    Ok((document, blob))
}

/// The one-line error of a file the `gltf` crate rejects: the first validation problem with its
/// JSON path, or the JSON syntax error with its line and column.
fn gltf_error(path: &Path, e: gltf::Error) -> Error {
    match e {
        gltf::Error::Validation(list) => {
            let (p, err) = &list[0];
            let more = if list.len() > 1 {
                format!(" (and {} more problems)", list.len() - 1)
            } else {
                String::new()
            };
            let what = match err {
                gltf::json::validation::Error::Unsupported => {
                    "unsupported extension required".to_string()
                }
                other => other.to_string().to_lowercase(),
            };
            scene_err(path, format!("invalid glTF at {p}: {what}{more}"))
        }
        gltf::Error::Deserialize(e) => scene_err(
            path,
            format!(
                "invalid glTF JSON at line {}, column {}: {e}",
                e.line(),
                e.column()
            ),
        ),
        other => scene_err(path, format!("invalid glTF: {other}")),
    }
}

/// Every primitive attribute names an accessor that exists.
fn check_attribute_accessors(path: &Path, root: &gltf::json::Root) -> Result<()> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (k, prim) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &prim.attributes {
                if index.value() >= root.accessors.len() {
                    let name = match semantic {
                        gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        gltf::json::validation::Checked::Invalid => "?".to_string(),
                    };
                    return Err(scene_err(
                        path,
                        format!(
                            "invalid glTF at meshes[{m}].primitives[{k}].attributes.{name}: accessor {} does not exist ({} accessors)",
                            index.value(),
                            root.accessors.len()
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Every buffer's bytes (the GLB binary chunk or a URI), at least as long as it says.
fn read_buffers(
    path: &Path,
    base: &Path,
    doc: &gltf::Document,
    blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>> {
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    for buffer in doc.buffers() {
        let what = format!("buffers[{}]", buffer.index());
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.clone().ok_or_else(|| {
                scene_err(
                    path,
                    format!("{what}: refers to the GLB binary chunk, which is missing"),
                )
            })?,
            gltf::buffer::Source::Uri(uri) => read_uri(path, base, uri, &what)?,
        };
        if data.len() < buffer.length() {
            return Err(scene_err(
                path,
                format!(
                    "{what}: byteLength {} but only {} bytes are there",
                    buffer.length(),
                    data.len()
                ),
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// What the node traversal reads from and adds to.
struct Loader<'a> {
    path: &'a Path,
    options: &'a SceneOptions,
    buffers: &'a [Vec<u8>],
    materials: &'a [MaterialInfo],
    images: &'a HashMap<usize, Texture>,
    scene: Scene,
    warnings: Vec<Warning>,
    /// Triangles whose albedo was lowered to [`ALBEDO_MAX`], by material name.
    clamped: HashMap<String, usize>,
    /// Primitives that are not triangles, by JSON path and mode.
    skipped_modes: HashSet<String>,
}

impl Loader<'_> {
    /// The nodes of `gscene` depth-first, children in order: their lights and primitives, in
    /// world space.
    fn add_nodes(&mut self, gscene: gltf::Scene) -> Result<()> {
        let path = self.path;
        let mut visited: HashSet<usize> = HashSet::new();
        // A stack of (node, parent's world matrix), reversed.
        let mut stack: Vec<(gltf::Node, DMat4)> =
            gscene.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
        stack.reverse();
        while let Some((node, parent)) = stack.pop() {
            if !visited.insert(node.index()) {
                return Err(scene_err(
                    path,
                    format!("nodes[{}] is reached twice (a node may have one parent; the hierarchy has a cycle or a shared child)", node.index()),
                ));
            }
            let world = parent * local_matrix(&node);
            if !world.is_finite() {
                return Err(scene_err(
                    path,
                    format!("nodes[{}]: transform is not finite", node.index()),
                ));
            }
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push((child, world));
            }
            if let Some(light) = node.light() {
                self.add_light(&node, &light, world)?;
            }
            let Some(mesh) = node.mesh() else { continue };
            for prim in mesh.primitives() {
                self.add_primitive(&mesh, &prim, world)?;
            }
        }
        Ok(())
    }

    /// A `KHR_lights_punctual` light of `node`, placed by its world transform.
    fn add_light(
        &mut self,
        node: &gltf::Node,
        light: &gltf::khr_lights_punctual::Light,
        world: DMat4,
    ) -> Result<()> {
        let path = self.path;
        let li = light.index();
        let color = light.color().map(f64::from);
        let intensity = f64::from(light.intensity());
        let rgb = color.map(|c| c * intensity / LUMENS_PER_WATT);
        let position = world.transform_point3(DVec3::ZERO);
        let axis = world.transform_vector3(DVec3::NEG_Z);
        let l = match light.kind() {
            gltf::khr_lights_punctual::Kind::Point => Light::Point {
                position,
                intensity: rgb,
            },
            gltf::khr_lights_punctual::Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => Light::Spot {
                position,
                direction: axis.normalize_or_zero(),
                intensity: rgb,
                inner: f64::from(inner_cone_angle),
                outer: f64::from(outer_cone_angle),
            },
            gltf::khr_lights_punctual::Kind::Directional => Light::Sun {
                direction: axis.normalize_or_zero(),
                irradiance: rgb,
            },
        };
        l.validate(&format!(
            "{}: KHR_lights_punctual.lights[{li}] (nodes[{}])",
            path.display(),
            node.index()
        ))
        .map_err(|e| {
            scene_err(
                path,
                e.to_string()
                    .trim_start_matches("invalid parameter: ")
                    .to_string(),
            )
        })?;
        if light.range().is_some() {
            warn(&mut self.warnings, path, WarningKind::Unsupported, format!("KHR_lights_punctual.lights[{li}]: range is ignored (lights fall off as 1/r^2 everywhere)"));
        }
        self.scene.lights.push(l);
        Ok(())
    }

    /// The triangles of one primitive (skipped with a warning when it is not triangles), in
    /// world space, with their albedo and emission.
    fn add_primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        world: DMat4,
    ) -> Result<()> {
        let path = self.path;
        let jp = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            self.skipped_modes.insert(format!("{jp} ({mode:?})"));
            return Ok(());
        }
        let local = self.positions(prim, &jp)?;
        let nverts = local.len();
        let indices = self.indices(prim, &jp, nverts)?;
        let tris = assemble(mode, &indices);
        let material = prim.material();
        let info = material.index().and_then(|i| self.materials.get(i));
        let colors = self.colors(prim, &jp, nverts)?;
        let base_uv = match info.and_then(|m| m.base_texture) {
            Some((_, set, _)) => self.uv(prim, &jp, nverts, set)?,
            None => None,
        };
        let emissive_uv = match info.and_then(|m| m.emissive_texture) {
            Some((_, set, _)) => self.uv(prim, &jp, nverts, set)?,
            None => None,
        };
        if info.is_some_and(|m| m.base_texture.is_some()) && base_uv.is_none() {
            warn(&mut self.warnings, path, WarningKind::Texture, format!("{jp}: material '{}' has a base colour texture but the primitive no texture coordinates; factor used", info.map_or("", |m| m.name.as_str())));
        }
        let base_index = self.scene.positions.len() as u32;
        for p in &local {
            self.scene
                .positions
                .push(world.transform_point3(DVec3::from_array(*p)));
        }
        let material_id = material.index().map(|i| i as u32);
        let mirrored = world.determinant() < 0.0;
        for t in &tris {
            let t = if mirrored { [t[0], t[2], t[1]] } else { *t };
            self.scene.triangles.push(t.map(|i| base_index + i as u32));
            self.scene.material.push(material_id);
            self.scene.two_sided.push(material.double_sided());
            let (albedo, emission) =
                self.colours_of(info, t, base_uv.as_deref(), emissive_uv.as_deref(), &colors);
            self.scene.albedo.push(albedo);
            self.scene.emission.push(emission);
        }
        Ok(())
    }

    /// A primitive's POSITION values (VEC3 FLOAT, finite), in its node's frame.
    fn positions(&self, prim: &gltf::Primitive, jp: &str) -> Result<Vec<[f64; 3]>> {
        let path = self.path;
        let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
            return Err(scene_err(path, format!("{jp}: no POSITION attribute")));
        };
        if pos_acc.data_type() != DataType::F32 || pos_acc.dimensions() != Dimensions::Vec3 {
            return Err(scene_err(
                path,
                format!("{jp}.attributes.POSITION: must be VEC3 FLOAT"),
            ));
        }
        let local = read_accessor::<3>(
            path,
            &pos_acc,
            self.buffers,
            &format!("{jp}.attributes.POSITION"),
        )?;
        if let Some(v) = local.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            return Err(scene_err(
                path,
                format!("{jp}.attributes.POSITION: vertex {v} is not finite"),
            ));
        }
        Ok(local)
    }

    /// A primitive's vertex indices (unsigned integer scalars below `nverts`), or every vertex
    /// in order when it has none.
    fn indices(&self, prim: &gltf::Primitive, jp: &str, nverts: usize) -> Result<Vec<usize>> {
        let path = self.path;
        let Some(acc) = prim.indices() else {
            return Ok((0..nverts).collect());
        };
        if !matches!(
            acc.data_type(),
            DataType::U8 | DataType::U16 | DataType::U32
        ) || acc.dimensions() != Dimensions::Scalar
        {
            return Err(scene_err(
                path,
                format!("{jp}.indices: must be unsigned integer scalars"),
            ));
        }
        let raw = read_accessor::<1>(path, &acc, self.buffers, &format!("{jp}.indices"))?;
        let mut out = Vec::with_capacity(raw.len());
        for (k, r) in raw.iter().enumerate() {
            let i = r[0] as usize;
            if i >= nverts {
                return Err(scene_err(
                    path,
                    format!(
                        "{jp}.indices: index {i} at position {k} out of range ({nverts} vertices)"
                    ),
                ));
            }
            out.push(i);
        }
        Ok(out)
    }

    /// A primitive's texture coordinates of set `set`, one per vertex, if it has them.
    fn uv(
        &self,
        prim: &gltf::Primitive,
        jp: &str,
        nverts: usize,
        set: u32,
    ) -> Result<Option<Vec<[f64; 2]>>> {
        let path = self.path;
        match prim.get(&gltf::Semantic::TexCoords(set)) {
            None => Ok(None),
            Some(acc) => {
                let uv = read_accessor::<2>(
                    path,
                    &acc,
                    self.buffers,
                    &format!("{jp}.attributes.TEXCOORD_{set}"),
                )?;
                if uv.len() != nverts {
                    return Err(scene_err(
                        path,
                        format!(
                            "{jp}.attributes.TEXCOORD_{set}: {} values for {nverts} vertices",
                            uv.len()
                        ),
                    ));
                }
                Ok(Some(uv))
            }
        }
    }

    /// A primitive's `COLOR_0`, one per vertex (negative and non-finite values as 0), if it
    /// has one.
    fn colors(
        &self,
        prim: &gltf::Primitive,
        jp: &str,
        nverts: usize,
    ) -> Result<Option<Vec<[f64; 3]>>> {
        let path = self.path;
        let Some(acc) = prim.get(&gltf::Semantic::Colors(0)) else {
            return Ok(None);
        };
        let c = read_accessor::<3>(
            path,
            &acc,
            self.buffers,
            &format!("{jp}.attributes.COLOR_0"),
        )?;
        if c.len() != nverts {
            return Err(scene_err(
                path,
                format!(
                    "{jp}.attributes.COLOR_0: {} values for {nverts} vertices",
                    c.len()
                ),
            ));
        }
        Ok(Some(
            c.into_iter()
                .map(|c| c.map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 }))
                .collect(),
        ))
    }

    /// One triangle's albedo (material factor x texture mean x vertex colour mean, lowered to
    /// [`ALBEDO_MAX`] and counted) and emission (factor x texture mean).
    fn colours_of(
        &mut self,
        info: Option<&MaterialInfo>,
        t: [usize; 3],
        base_uv: Option<&[[f64; 2]]>,
        emissive_uv: Option<&[[f64; 2]]>,
        colors: &Option<Vec<[f64; 3]>>,
    ) -> ([f64; 3], [f64; 3]) {
        let mut albedo = match info {
            Some(m) => m.base,
            None => [self.options.default_albedo; 3],
        };
        let mut emission = info.map_or([0.0; 3], |m| m.emission);
        if let (Some(m), Some(uv)) = (info, base_uv) {
            if let Some((img, _, s)) = m.base_texture {
                let mean = self.images[&img].mean_over(t.map(|i| uv[i]), &s);
                for c in 0..3 {
                    albedo[c] *= mean[c];
                }
            }
        }
        if let (Some(m), Some(uv)) = (info, emissive_uv) {
            if let Some((img, _, s)) = m.emissive_texture {
                let mean = self.images[&img].mean_over(t.map(|i| uv[i]), &s);
                for c in 0..3 {
                    emission[c] *= mean[c];
                }
            }
        }
        if let Some(col) = colors {
            for c in 0..3 {
                albedo[c] *= (col[t[0]][c] + col[t[1]][c] + col[t[2]][c]) / 3.0;
            }
        }
        if albedo.iter().any(|&a| a >= ALBEDO_MAX) {
            let name = info.map_or("(no material)".to_string(), |m| m.name.clone());
            *self.clamped.entry(name).or_default() += 1;
            albedo = albedo.map(|a| a.min(ALBEDO_MAX));
        }
        (albedo, emission)
    }

    /// The scene, and its warnings with those of the skipped primitives and lowered albedos
    /// (each sorted) at the end.
    fn finish_warnings(self) -> (Scene, Vec<Warning>) {
        let path = self.path;
        let mut warnings = self.warnings;
        let mut modes: Vec<String> = self.skipped_modes.into_iter().collect();
        modes.sort();
        for m in modes {
            warn(
                &mut warnings,
                path,
                WarningKind::Unsupported,
                format!("{m}: not triangles, skipped"),
            );
        }
        let mut clamped: Vec<(String, usize)> = self.clamped.into_iter().collect();
        clamped.sort();
        for (name, n) in clamped {
            warn(&mut warnings, path, WarningKind::Albedo, format!("material '{name}': albedo at or above {ALBEDO_MAX} on {n} triangles lowered to {ALBEDO_MAX} (the model needs albedo below 1)"));
        }
        (self.scene, warnings)
    }
}

/// A primitive's triangles from its indices: TRIANGLES as they are, TRIANGLE_STRIP and
/// TRIANGLE_FAN by the specification's formulas.
fn assemble(mode: Mode, indices: &[usize]) -> Vec<[usize; 3]> {
    match mode {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| [indices[i], indices[i + 1 + i % 2], indices[i + 2 - i % 2]])
            .collect(),
        _ => (0..indices.len().saturating_sub(2))
            .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
            .collect(),
    }
}

/// The checks every loader ends with: some triangle, some non-degenerate triangle; warnings
/// for repeated triangles and for a scene without any light.
pub(crate) fn finish(path: &Path, mut scene: Scene, mut warnings: Vec<Warning>) -> Result<Scene> {
    if scene.is_empty() {
        return Err(scene_err(
            path,
            "no triangles (the default scene instances no triangle primitives)",
        ));
    }
    if scene.degenerate_count() == scene.len() {
        return Err(scene_err(
            path,
            format!(
                "no non-degenerate triangle among {} (all have zero area)",
                scene.len()
            ),
        ));
    }
    let duplicates = scene.duplicates();
    let count = duplicates.iter().filter(|d| d.is_some()).count();
    if count > 0 {
        warnings.push(Warning::in_file(WarningKind::Duplicate, path, None, format!(
            "{count} triangles repeat an earlier one (same corners, same orientation); each is solved once and reported with its first copy's radiance"
        )));
    }
    if scene.emitter_count() == 0 && scene.lights.is_empty() {
        warnings.push(Warning::in_file(
            WarningKind::NoEmitter,
            path,
            None,
            "no emitting triangle and no light; the answer is all zero",
        ));
    }
    scene.warnings.extend(warnings);
    Ok(scene)
}
