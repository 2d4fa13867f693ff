//! Helpers of the glTF tests: building small glTF files by hand (accessors over one buffer,
//! written as `.gltf` with a base64 data URI or as `.glb`), and encoding PNG textures.
#![allow(dead_code)]

use std::path::Path;

use base64::Engine;
use serde_json::{json, Value};

/// One buffer with its views and accessors; the rest of the document is given at the end.
#[derive(Default)]
pub struct Doc {
    pub bin: Vec<u8>,
    pub views: Vec<Value>,
    pub accessors: Vec<Value>,
}

impl Doc {
    pub fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(json!({
            "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()
        }));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    fn floats<const N: usize>(&mut self, rows: &[[f32; N]], ty: &str) -> usize {
        let bytes: Vec<u8> = rows
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let view = self.view(&bytes);
        let mut acc = json!({
            "bufferView": view, "componentType": 5126, "count": rows.len(), "type": ty
        });
        if N == 3 {
            let lo: Vec<f32> = (0..3)
                .map(|k| rows.iter().map(|r| r[k]).fold(f32::INFINITY, f32::min))
                .collect();
            let hi: Vec<f32> = (0..3)
                .map(|k| rows.iter().map(|r| r[k]).fold(f32::NEG_INFINITY, f32::max))
                .collect();
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    /// A VEC3 FLOAT accessor (POSITION), with min and max.
    pub fn vec3(&mut self, rows: &[[f32; 3]]) -> usize {
        self.floats(rows, "VEC3")
    }

    /// A VEC2 FLOAT accessor (TEXCOORD_n).
    pub fn vec2(&mut self, rows: &[[f32; 2]]) -> usize {
        self.floats(rows, "VEC2")
    }

    /// An UNSIGNED_INT SCALAR accessor (indices).
    pub fn indices(&mut self, values: &[u32]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5125, "count": values.len(), "type": "SCALAR"
        }));
        self.accessors.len() - 1
    }

    /// The document: `rest` (asset, scenes, nodes, meshes, ...) with the buffer, views and
    /// accessors; the buffer as a data URI when `uri`.
    pub fn json(&self, mut rest: Value, uri: bool) -> Value {
        let mut buffer = json!({ "byteLength": self.bin.len() });
        if uri {
            buffer["uri"] = json!(format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&self.bin)
            ));
        }
        if rest.get("asset").is_none() {
            rest["asset"] = json!({ "version": "2.0" });
        }
        rest["buffers"] = json!([buffer]);
        rest["bufferViews"] = json!(self.views);
        rest["accessors"] = json!(self.accessors);
        rest
    }

    /// Writes a `.gltf` with the buffer as a base64 data URI.
    pub fn write_gltf(&self, path: &Path, rest: Value) {
        std::fs::write(
            path,
            serde_json::to_vec_pretty(&self.json(rest, true)).unwrap(),
        )
        .unwrap();
    }

    /// The bytes of a `.glb` of this document.
    pub fn glb_bytes(&self, rest: Value) -> Vec<u8> {
        let mut text = serde_json::to_vec(&self.json(rest, false)).unwrap();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + text.len() + 8 + bin.len();
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}

/// A PNG of `width x height` 8-bit RGB texels (rows from the top).
pub fn png(width: u32, height: u32, texels: &[[u8; 3]]) -> Vec<u8> {
    let raw: Vec<u8> = texels.iter().flatten().copied().collect();
    let img = image::RgbImage::from_raw(width, height, raw).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// The sRGB decoding of an 8-bit value.
pub fn linear(v: u8) -> f64 {
    let x = v as f64 / 255.0;
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// The directory of the Khronos sample assets (`../shared/gltf` beside the repository), when
/// present.
pub fn samples_dir() -> Option<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/gltf");
    dir.is_dir().then_some(dir)
}
