//! glTF materials: colour factors, emissive strength, and the images of their base colour and
//! emissive textures (decoded once each, by image index).

use std::collections::HashMap;
use std::path::Path;

use super::data::read_uri;
use super::scene_err;
use crate::error::Result;
use crate::scene::lights::LUMENS_PER_WATT;
use crate::scene::texture::{Sampling, Texture, Wrap};

/// A material's colours and textures, resolved once.
pub(super) struct MaterialInfo {
    pub(super) name: String,
    pub(super) base: [f64; 3],
    pub(super) base_texture: Option<(usize, u32, Sampling)>,
    pub(super) emission: [f64; 3],
    pub(super) emissive_texture: Option<(usize, u32, Sampling)>,
}

fn sampling_of(sampler: &gltf::texture::Sampler) -> Sampling {
    use gltf::texture::{MagFilter, WrappingMode};
    let wrap = |m: WrappingMode| match m {
        WrappingMode::Repeat => Wrap::Repeat,
        WrappingMode::MirroredRepeat => Wrap::Mirror,
        WrappingMode::ClampToEdge => Wrap::Clamp,
    };
    Sampling {
        wrap_u: wrap(sampler.wrap_s()),
        wrap_v: wrap(sampler.wrap_t()),
        nearest: sampler.mag_filter() == Some(MagFilter::Nearest),
    }
}

/// Every material in file order, and the images they use (decoded once, by image index).
pub(super) fn read_materials(
    path: &Path,
    base: &Path,
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
) -> Result<(Vec<MaterialInfo>, HashMap<usize, Texture>)> {
    let mut images = Images {
        path,
        base,
        doc,
        buffers,
        decoded: HashMap::new(),
    };
    let mut materials: Vec<MaterialInfo> = Vec::new();
    for m in doc.materials() {
        let i = m.index().unwrap_or(materials.len());
        let name = m
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("material{i}"));
        let pbr = m.pbr_metallic_roughness();
        let bf = pbr.base_color_factor();
        let base_texture = match pbr.base_color_texture() {
            Some(info) => Some(images.texture_ref(
                &info,
                &format!("materials[{i}].pbrMetallicRoughness.baseColorTexture"),
            )?),
            None => None,
        };
        let strength = m.emissive_strength().map(f64::from).unwrap_or(1.0);
        let ef = m.emissive_factor();
        let emissive_texture = match m.emissive_texture() {
            Some(info) => {
                Some(images.texture_ref(&info, &format!("materials[{i}].emissiveTexture"))?)
            }
            None => None,
        };
        let emission = ef.map(|e| f64::from(e) * strength / LUMENS_PER_WATT);
        let base = [bf[0], bf[1], bf[2]].map(f64::from);
        if base
            .iter()
            .chain(&emission)
            .any(|x| !x.is_finite() || *x < 0.0)
        {
            return Err(scene_err(
                path,
                format!("materials[{i}] ('{name}'): colour factors must be finite and >= 0"),
            ));
        }
        materials.push(MaterialInfo {
            name,
            base,
            base_texture,
            emission,
            emissive_texture,
        });
    }
    Ok((materials, images.decoded))
}

/// The images of a file, decoded the first time a material uses them.
struct Images<'a> {
    path: &'a Path,
    base: &'a Path,
    doc: &'a gltf::Document,
    buffers: &'a [Vec<u8>],
    decoded: HashMap<usize, Texture>,
}

impl Images<'_> {
    /// A material's texture: its image (decoded), texture coordinate set and sampling.
    fn texture_ref(
        &mut self,
        info: &gltf::texture::Info,
        what: &str,
    ) -> Result<(usize, u32, Sampling)> {
        Ok((
            self.load(info.texture().source(), what)?,
            info.tex_coord(),
            sampling_of(&info.texture().sampler()),
        ))
    }

    /// Decodes `image` unless it was already: its index.
    fn load(&mut self, image: gltf::Image, what: &str) -> Result<usize> {
        let path = self.path;
        let index = image.index();
        if self.decoded.contains_key(&index) {
            return Ok(index);
        }
        let what = format!("{what} (images[{index}])");
        // Read from the JSON: gltf 1.4.1's `Image::source` panics on an image with a buffer
        // view but no MIME type, or with neither a URI nor a buffer view.
        let json = &self.doc.as_json().images[index];
        let (bytes, name) = if let Some(v) = json.buffer_view {
            let view = self
                .doc
                .views()
                .nth(v.value())
                .ok_or_else(|| scene_err(path, format!("{what}: missing buffer view")))?;
            let buffer = self
                .buffers
                .get(view.buffer().index())
                .ok_or_else(|| scene_err(path, format!("{what}: missing buffer")))?;
            let end = view.offset().checked_add(view.length());
            let data = end
                .and_then(|end| buffer.get(view.offset()..end))
                .ok_or_else(|| {
                    scene_err(
                        path,
                        format!(
                            "{what}: bufferViews[{}] lies outside its buffer",
                            view.index()
                        ),
                    )
                })?;
            (data.to_vec(), String::new())
        } else if let Some(uri) = &json.uri {
            (read_uri(path, self.base, uri, &what)?, uri.clone())
        } else {
            return Err(scene_err(
                path,
                format!("{what}: neither a uri nor a bufferView"),
            ));
        };
        let texture = Texture::decode(&bytes, &name, true)
            .map_err(|e| scene_err(path, format!("{what}: {e}")))?;
        self.decoded.insert(index, texture);
        Ok(index)
    }
}
