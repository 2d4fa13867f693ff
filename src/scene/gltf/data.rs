//! The bytes of a glTF file: the GLB header and chunk checks, buffers named by URIs (files or
//! base64 `data:`), and accessors read as f64 rows, bounds checked.

use std::path::Path;

use base64::Engine;
use gltf::accessor::{DataType, Dimensions};

use super::scene_err;
use crate::error::{Error, Result};

/// Most elements of an accessor without a buffer view (zeros, optionally with sparse values).
const MAX_VIEWLESS: usize = 1 << 26;

/// Checks a binary glTF's 12-byte header and chunk headers before the parser sees them.
pub(super) fn check_glb(path: &Path, bytes: &[u8]) -> Result<()> {
    if bytes.len() < 12 {
        return Err(scene_err(
            path,
            format!(
                "truncated GLB: {} bytes, the header alone has 12",
                bytes.len()
            ),
        ));
    }
    let word =
        |at: usize| u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    let version = word(4);
    if version != 2 {
        return Err(scene_err(
            path,
            format!("GLB version {version} at byte 4 (only glTF 2.0 is read)"),
        ));
    }
    let length = word(8) as usize;
    if length < 20 {
        return Err(scene_err(
            path,
            format!("GLB length {length} at byte 8 is too small for a JSON chunk"),
        ));
    }
    if length > bytes.len() {
        return Err(scene_err(
            path,
            format!(
                "truncated GLB: the header at byte 8 says {length} bytes, the file has {}",
                bytes.len()
            ),
        ));
    }
    let mut at = 12usize;
    let mut chunk = 0;
    while at < length {
        if at + 8 > length {
            return Err(scene_err(
                path,
                format!("truncated GLB: chunk {chunk} header at byte {at} is cut off"),
            ));
        }
        let chunk_len = word(at) as usize;
        if at + 8 + chunk_len > length {
            return Err(scene_err(
                path,
                format!(
                    "truncated GLB: chunk {chunk} at byte {at} says {chunk_len} bytes, {} remain",
                    length - at - 8
                ),
            ));
        }
        at += 8 + chunk_len;
        chunk += 1;
    }
    Ok(())
}

/// Decodes `%XX` escapes of a relative URI.
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            let hex = std::str::from_utf8(&bytes[i + 1..i + 3])
                .ok()
                .and_then(|h| u8::from_str_radix(h, 16).ok());
            if let Some(b) = hex {
                out.push(b);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The bytes a URI names: a base64 `data:` URI, or a file relative to the glTF file.
pub(super) fn read_uri(path: &Path, base: &Path, uri: &str, what: &str) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((_, data)) = rest.split_once(";base64,") else {
            return Err(scene_err(
                path,
                format!("{what}: data URI is not base64 (only ';base64,' data URIs are read)"),
            ));
        };
        return base64::engine::general_purpose::STANDARD
            .decode(data.trim())
            .map_err(|e| scene_err(path, format!("{what}: bad base64 in data URI: {e}")));
    }
    if uri.contains("://") {
        return Err(scene_err(
            path,
            format!("{what}: URI '{uri}' is not a relative file (no network access)"),
        ));
    }
    let file = base.join(percent_decode(uri));
    std::fs::read(&file).map_err(|e| {
        scene_err(
            path,
            format!("{what}: cannot read '{}': {e}", file.display()),
        )
    })
}

/// An accessor's values as f64 rows of `N` components, bounds checked, sparse applied,
/// normalized integers mapped to [0, 1] (or [-1, 1]).
pub(super) fn read_accessor<const N: usize>(
    path: &Path,
    accessor: &gltf::Accessor,
    buffers: &[Vec<u8>],
    what: &str,
) -> Result<Vec<[f64; N]>> {
    let reader = Reader {
        path,
        what,
        accessor: accessor.index(),
        buffers,
        ty: accessor.data_type(),
        normalized: accessor.normalized(),
    };
    let dims = match accessor.dimensions() {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        other => return Err(reader.fail(format!("type {other:?} where {N} components are needed"))),
    };
    if dims < N {
        return Err(reader.fail(format!("{dims} components where {N} are needed")));
    }
    let size = reader.ty.size();
    let elem = size * dims;
    let count = accessor.count();
    let view = accessor.view();
    if let Some(view) = &view {
        let (data, stride) = reader.view_data(view, elem)?;
        reader.check_rows(data, accessor.offset(), stride, count, elem, view.index())?;
    } else if count > MAX_VIEWLESS {
        // Elements without a buffer view are zeros (and sparse values): no buffer bounds them.
        return Err(reader.fail(format!(
            "{count} elements without a buffer view (at most {MAX_VIEWLESS})"
        )));
    }
    let mut rows = vec![[0.0f64; N]; count];
    if let Some(view) = view {
        let (data, stride) = reader.view_data(&view, elem)?;
        for (i, row) in rows.iter_mut().enumerate() {
            let at = accessor.offset() + i * stride;
            for (k, x) in row.iter_mut().enumerate() {
                *x = reader.decode(&data[at + k * size..]);
            }
        }
    }
    if let Some(sparse) = accessor.sparse() {
        reader.apply_sparse(&sparse, elem, &mut rows)?;
    }
    Ok(rows)
}

/// What reading one accessor needs: where its errors point, the buffers, its component type.
struct Reader<'a> {
    /// The glTF file, for messages.
    path: &'a Path,
    /// What the accessor holds, for messages.
    what: &'a str,
    /// The accessor's index, for messages.
    accessor: usize,
    /// The file's buffers.
    buffers: &'a [Vec<u8>],
    /// The component type.
    ty: DataType,
    /// Integer components are normalized.
    normalized: bool,
}

impl<'a> Reader<'a> {
    /// The error `m` about this accessor.
    fn fail(&self, m: String) -> Error {
        scene_err(
            self.path,
            format!("{} (accessors[{}]): {m}", self.what, self.accessor),
        )
    }

    /// The component at the start of `b`.
    fn decode(&self, b: &[u8]) -> f64 {
        let normalized = self.normalized;
        match self.ty {
            DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            DataType::U8 => {
                let v = b[0] as f64;
                if normalized {
                    v / 255.0
                } else {
                    v
                }
            }
            DataType::I8 => {
                let v = b[0] as i8 as f64;
                if normalized {
                    (v / 127.0).max(-1.0)
                } else {
                    v
                }
            }
            DataType::U16 => {
                let v = u16::from_le_bytes([b[0], b[1]]) as f64;
                if normalized {
                    v / 65535.0
                } else {
                    v
                }
            }
            DataType::I16 => {
                let v = i16::from_le_bytes([b[0], b[1]]) as f64;
                if normalized {
                    (v / 32767.0).max(-1.0)
                } else {
                    v
                }
            }
            DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        }
    }

    /// (data of the view, stride) after checking the view against its buffer; `elem`: bytes per
    /// element.
    fn view_data(&self, view: &gltf::buffer::View, elem: usize) -> Result<(&'a [u8], usize)> {
        let buffer = self.buffers.get(view.buffer().index()).ok_or_else(|| {
            self.fail(format!(
                "bufferViews[{}] names a missing buffer",
                view.index()
            ))
        })?;
        let end = view.offset().checked_add(view.length());
        let Some(data) = end.and_then(|end| buffer.get(view.offset()..end)) else {
            return Err(self.fail(format!(
                "bufferViews[{}] (bytes {}..{}) lies outside buffers[{}] ({} bytes)",
                view.index(),
                view.offset(),
                view.offset().saturating_add(view.length()),
                view.buffer().index(),
                buffer.len()
            )));
        };
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            return Err(self.fail(format!(
                "bufferViews[{}] byteStride {stride} is smaller than an element ({elem} bytes)",
                view.index()
            )));
        }
        Ok((data, stride))
    }

    /// Checks that `n` elements of `elem` bytes from byte `offset` with `stride` fit in `data`,
    /// the bytes of buffer view `view`.
    fn check_rows(
        &self,
        data: &[u8],
        offset: usize,
        stride: usize,
        n: usize,
        elem: usize,
        view: usize,
    ) -> Result<()> {
        if n == 0 {
            return Ok(());
        }
        let need = (n - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(offset))
            .and_then(|x| x.checked_add(elem));
        match need {
            Some(need) if need <= data.len() => Ok(()),
            _ => Err(self.fail(format!(
                "{n} elements from byte {offset} with stride {stride} need more than the {} bytes of bufferViews[{view}]",
                data.len()
            ))),
        }
    }

    /// Writes the `sparse` values (elements of `elem` bytes) into `rows`, bounds checked.
    fn apply_sparse<const N: usize>(
        &self,
        sparse: &gltf::accessor::sparse::Sparse,
        elem: usize,
        rows: &mut [[f64; N]],
    ) -> Result<()> {
        let count = rows.len();
        let size = self.ty.size();
        let n = sparse.count();
        let indices = sparse.indices();
        let isize = indices.index_type().size();
        let (idata, istride) = self.view_data(&indices.view(), isize)?;
        let istride = if indices.view().stride().is_some() {
            istride
        } else {
            isize
        };
        self.check_rows(
            idata,
            indices.offset(),
            istride,
            n,
            isize,
            indices.view().index(),
        )?;
        let values = sparse.values();
        let (vdata, vstride) = self.view_data(&values.view(), elem)?;
        let vstride = if values.view().stride().is_some() {
            vstride
        } else {
            elem
        };
        self.check_rows(
            vdata,
            values.offset(),
            vstride,
            n,
            elem,
            values.view().index(),
        )?;
        for s in 0..n {
            let at = indices.offset() + s * istride;
            let b = &idata[at..];
            let index = match isize {
                1 => b[0] as usize,
                2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            };
            if index >= count {
                return Err(self.fail(format!(
                    "sparse index {index} out of range ({count} elements)"
                )));
            }
            let vat = values.offset() + s * vstride;
            for k in 0..N {
                rows[index][k] = self.decode(&vdata[vat + k * size..]);
            }
        }
        Ok(())
    }
}
