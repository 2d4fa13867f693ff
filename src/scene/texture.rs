//! Textures as per-triangle colours: the mean of a texture over a triangle's UV footprint.
//!
//! The solver keeps one albedo and one emission per triangle, so a texture enters as its mean
//! over the part of the image each triangle covers. Texels are decoded to linear colour first
//! (colour textures are sRGB-encoded, as glTF prescribes for base colour and emissive textures
//! and as OBJ tools write them), then averaged:
//!
//! - the footprint is the triangle's UV triangle in texel space (`u * width`, `v * height`);
//!   texel `(i, j)` covers `[i, i + 1) x [j, j + 1)`, and the wrap mode of each axis (repeat,
//!   mirrored repeat, clamp to edge) says which texel a cell outside the image shows;
//! - the mean is exact for the texels seen as constant squares (nearest filtering): each cell
//!   the footprint touches counts with the area of its overlap (the triangle clipped to the
//!   cell), so a triangle covering half of a texel pattern gets exactly the pattern's mean over
//!   that half;
//! - a footprint smaller than [`SMALL_FOOTPRINT`] texels with linear magnification is averaged
//!   over [`SMALL_SAMPLES`] stratified bilinear samples instead (a texel-exact mean would show
//!   the texel grid that bilinear filtering hides); a footprint spanning more than
//!   [`MAX_CELLS`] cells (UVs repeating a texture many times) over [`LARGE_SAMPLES`]
//!   stratified samples.

use std::collections::HashMap;
use std::path::Path;

use crate::error::{Warning, WarningKind};
use crate::geometry::tolerances::MIN_UV_AREA;
use crate::scene::mtllib;

/// Footprints (texel-space area) below this, with linear magnification, are averaged by
/// bilinear samples.
pub const SMALL_FOOTPRINT: f64 = 4.0;

/// Stratified samples of a small footprint.
pub const SMALL_SAMPLES: usize = 64;

/// Most texel cells clipped exactly per triangle; above, sampling.
pub const MAX_CELLS: u64 = 1 << 22;

/// Stratified samples of a footprint above [`MAX_CELLS`].
pub const LARGE_SAMPLES: usize = 1 << 16;

/// How a texture coordinate outside [0, 1) maps to the image (glTF sampler wrap modes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// The image repeats (the glTF and OBJ default).
    #[default]
    Repeat,
    /// The image repeats, every other copy mirrored.
    Mirror,
    /// The edge texels extend outwards.
    Clamp,
}

impl Wrap {
    /// The texel index shown at cell `i` of an axis of `n` texels.
    pub fn texel(self, i: i64, n: usize) -> usize {
        let n = n as i64;
        let k = match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n {
                    m
                } else {
                    2 * n - 1 - m
                }
            }
            Wrap::Clamp => i.clamp(0, n - 1),
        };
        k as usize
    }
}

/// How a texture is sampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Sampling {
    /// Wrap mode along u (image columns).
    pub wrap_u: Wrap,
    /// Wrap mode along v (image rows).
    pub wrap_v: Wrap,
    /// Nearest-texel magnification (glTF `magFilter` NEAREST); linear otherwise.
    pub nearest: bool,
}

/// A decoded texture in linear RGB (alpha dropped), rows from the top of the image.
#[derive(Clone, Debug)]
pub struct Texture {
    /// Width in texels (> 0).
    pub width: usize,
    /// Height in texels (> 0).
    pub height: usize,
    /// Linear RGB per texel, row-major from the top row.
    pub texels: Vec<[f32; 3]>,
}

/// sRGB transfer function, decoded: encoded value in [0, 1] to linear.
pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

impl Texture {
    /// Decodes an image file's bytes (PNG, JPEG or TGA, told by content, TGA also by the
    /// `name`'s extension); `srgb` decodes the sRGB curve. Errors are one phrase (no file name).
    pub fn decode(bytes: &[u8], name: &str, srgb: bool) -> Result<Texture, String> {
        let reader = image::ImageReader::new(std::io::Cursor::new(bytes));
        let reader = match reader.with_guessed_format() {
            Ok(r) => r,
            Err(e) => return Err(format!("cannot read image: {e}")),
        };
        let mut reader = reader;
        if reader.format().is_none() {
            match image::ImageFormat::from_path(name) {
                Ok(f) => reader.set_format(f),
                Err(_) => return Err("unknown image format (PNG, JPEG and TGA are read)".into()),
            }
        }
        let decoded = reader
            .decode()
            .map_err(|e| format!("cannot decode image: {e}"))?;
        let rgb = decoded.to_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        if width == 0 || height == 0 {
            return Err("image has no texels".into());
        }
        let texels = rgb
            .pixels()
            .map(|p| {
                p.0.map(|c| {
                    let c = if c.is_finite() {
                        c.clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    if srgb {
                        srgb_to_linear(c)
                    } else {
                        c
                    }
                })
            })
            .collect();
        Ok(Texture {
            width,
            height,
            texels,
        })
    }

    /// Reads and decodes an image file (see [`Texture::decode`]).
    pub fn read(path: &Path, srgb: bool) -> Result<Texture, String> {
        let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
        Texture::decode(&bytes, &path.to_string_lossy(), srgb)
    }

    /// A texture of one colour per texel, for tests and generated scenes.
    pub fn from_texels(width: usize, height: usize, texels: Vec<[f32; 3]>) -> Texture {
        assert_eq!(texels.len(), width * height);
        Texture {
            width,
            height,
            texels,
        }
    }

    fn at(&self, i: i64, j: i64, s: &Sampling) -> [f64; 3] {
        let x = s.wrap_u.texel(i, self.width);
        let y = s.wrap_v.texel(j, self.height);
        self.texels[y * self.width + x].map(f64::from)
    }

    /// The texture at texel-space point `(x, y)`: the texel there (nearest) or the bilinear
    /// blend of the four nearest texel centres.
    fn sample(&self, x: f64, y: f64, s: &Sampling) -> [f64; 3] {
        if s.nearest {
            return self.at(x.floor() as i64, y.floor() as i64, s);
        }
        let (fx, fy) = (x - 0.5, y - 0.5);
        let (i, j) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - i, fy - j);
        let (i, j) = (i as i64, j as i64);
        let mut out = [0.0; 3];
        for (di, dj, w) in [
            (0, 0, (1.0 - tx) * (1.0 - ty)),
            (1, 0, tx * (1.0 - ty)),
            (0, 1, (1.0 - tx) * ty),
            (1, 1, tx * ty),
        ] {
            let t = self.at(i + di, j + dj, s);
            for c in 0..3 {
                out[c] += w * t[c];
            }
        }
        out
    }

    /// The mean of the texture over the UV triangle `uv` (texture coordinates, `u` along the
    /// image's columns, `v` along its rows from the top, as glTF has them; OBJ's `vt` has `v`
    /// from the bottom: pass `1 - v`). See the module doc for how the mean is taken. A
    /// degenerate (zero-area) footprint takes the texture at the footprint's centre; non-finite
    /// coordinates give the texture's mean over the whole image.
    pub fn mean_over(&self, uv: [[f64; 2]; 3], s: &Sampling) -> [f64; 3] {
        let p = uv.map(|[u, v]| [u * self.width as f64, v * self.height as f64]);
        if p.iter().flatten().any(|x| !x.is_finite() || x.abs() > 1e9) {
            return self.image_mean();
        }
        let area = 0.5
            * ((p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]))
                .abs();
        let lo = [0, 1].map(|k| p.iter().map(|q| q[k]).fold(f64::INFINITY, f64::min).floor());
        let hi = [0, 1].map(|k| {
            p.iter()
                .map(|q| q[k])
                .fold(f64::NEG_INFINITY, f64::max)
                .ceil()
        });
        let cells =
            ((hi[0] - lo[0]).max(1.0) as u64).saturating_mul((hi[1] - lo[1]).max(1.0) as u64);
        if !(area > MIN_UV_AREA) {
            let c = [0, 1].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
            return self.sample(c[0], c[1], s);
        }
        if !s.nearest && area < SMALL_FOOTPRINT {
            return self.sampled_mean(&p, SMALL_SAMPLES, s);
        }
        if cells > MAX_CELLS {
            return self.sampled_mean(&p, LARGE_SAMPLES, s);
        }
        // Exact: clip the triangle to each row of cells, then to each cell of the row.
        let mut sum = [0.0f64; 3];
        let mut covered = 0.0f64;
        let tri: Vec<[f64; 2]> = p.to_vec();
        let (j0, j1) = (lo[1] as i64, hi[1] as i64);
        let (i0, i1) = (lo[0] as i64, hi[0] as i64);
        for j in j0..j1.max(j0 + 1) {
            let row = clip(&clip(&tri, 1, j as f64, true), 1, (j + 1) as f64, false);
            if row.len() < 3 {
                continue;
            }
            let rlo = row
                .iter()
                .map(|q| q[0])
                .fold(f64::INFINITY, f64::min)
                .floor() as i64;
            let rhi = row
                .iter()
                .map(|q| q[0])
                .fold(f64::NEG_INFINITY, f64::max)
                .ceil() as i64;
            for i in rlo.max(i0)..rhi.min(i1.max(i0 + 1)) {
                let cell = clip(&clip(&row, 0, i as f64, true), 0, (i + 1) as f64, false);
                let a = polygon_area(&cell);
                if a > 0.0 {
                    let t = self.at(i, j, s);
                    for c in 0..3 {
                        sum[c] += a * t[c];
                    }
                    covered += a;
                }
            }
        }
        if covered > 0.0 {
            sum.map(|x| x / covered)
        } else {
            self.sampled_mean(&p, SMALL_SAMPLES, s)
        }
    }

    /// Mean of `n` (rounded to a square) stratified samples over the texel-space triangle `p`.
    fn sampled_mean(&self, p: &[[f64; 2]; 3], n: usize, s: &Sampling) -> [f64; 3] {
        let k = n.isqrt().max(1);
        let mut sum = [0.0; 3];
        let mut count = 0usize;
        for a in 0..k {
            for b in 0..k {
                let (u1, u2) = ((a as f64 + 0.5) / k as f64, (b as f64 + 0.5) / k as f64);
                // Uniform on the triangle (square-root parametrization).
                let r = u1.sqrt();
                let (w0, w1, w2) = (1.0 - r, r * (1.0 - u2), r * u2);
                let x = w0 * p[0][0] + w1 * p[1][0] + w2 * p[2][0];
                let y = w0 * p[0][1] + w1 * p[1][1] + w2 * p[2][1];
                let t = self.sample(x, y, s);
                for c in 0..3 {
                    sum[c] += t[c];
                }
                count += 1;
            }
        }
        sum.map(|x| x / count as f64)
    }

    /// The mean of all texels.
    pub fn image_mean(&self) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for t in &self.texels {
            for c in 0..3 {
                sum[c] += f64::from(t[c]);
            }
        }
        sum.map(|x| x / self.texels.len() as f64)
    }
}

/// Sutherland-Hodgman: keeps the part of `poly` with coordinate `axis` >= `at` (`keep_above`)
/// or <= `at`.
fn clip(poly: &[[f64; 2]], axis: usize, at: f64, keep_above: bool) -> Vec<[f64; 2]> {
    let inside = |q: &[f64; 2]| {
        if keep_above {
            q[axis] >= at
        } else {
            q[axis] <= at
        }
    };
    let mut out = Vec::with_capacity(poly.len() + 2);
    for k in 0..poly.len() {
        let a = poly[k];
        let b = poly[(k + 1) % poly.len()];
        let (ia, ib) = (inside(&a), inside(&b));
        if ia {
            out.push(a);
        }
        if ia != ib {
            let t = (at - a[axis]) / (b[axis] - a[axis]);
            let mut q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            q[axis] = at;
            out.push(q);
        }
    }
    out
}

/// Unsigned area of a simple polygon (shoelace).
fn polygon_area(poly: &[[f64; 2]]) -> f64 {
    if poly.len() < 3 {
        return 0.0;
    }
    let mut twice = 0.0;
    for k in 0..poly.len() {
        let a = poly[k];
        let b = poly[(k + 1) % poly.len()];
        twice += a[0] * b[1] - b[0] * a[1];
    }
    0.5 * twice.abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Texture {
        // 2 x 2: top row black, white; bottom row white, black.
        Texture::from_texels(2, 2, vec![[0.0; 3], [1.0; 3], [1.0; 3], [0.0; 3]])
    }

    #[test]
    fn wrap_modes_pick_the_right_texel() {
        assert_eq!(Wrap::Repeat.texel(-1, 4), 3);
        assert_eq!(Wrap::Repeat.texel(5, 4), 1);
        assert_eq!(Wrap::Mirror.texel(4, 4), 3);
        assert_eq!(Wrap::Mirror.texel(-1, 4), 0);
        assert_eq!(Wrap::Clamp.texel(-7, 4), 0);
        assert_eq!(Wrap::Clamp.texel(9, 4), 3);
    }

    #[test]
    fn half_of_a_checker_is_exact() {
        let t = checker();
        let s = Sampling {
            nearest: true,
            ..Sampling::default()
        };
        // Lower-left half of the unit square: a quarter of white (top right) ... exact mean.
        // Triangle (0,0), (1,0), (0,1) covers all of texel (0,0) (black), half of (1,0) (white)
        // and half of (0,1) (white): mean = (0 * 0.25 + 1 * 0.125 + 1 * 0.125) / 0.5 = 0.5.
        let m = t.mean_over([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], &s);
        assert!((m[0] - 0.5).abs() < 1e-12, "{m:?}");
        // A quarter triangle inside texel (1, 0) only.
        let m = t.mean_over([[0.5, 0.0], [1.0, 0.0], [1.0, 0.5]], &s);
        assert!((m[0] - 1.0).abs() < 1e-12, "{m:?}");
    }

    #[test]
    fn clamp_and_repeat_differ_outside_the_image() {
        let t = Texture::from_texels(2, 1, vec![[0.0; 3], [1.0; 3]]);
        let uv = [[1.0, 0.0], [2.0, 0.0], [2.0, 1.0]];
        let repeat = t.mean_over(
            uv,
            &Sampling {
                nearest: true,
                ..Sampling::default()
            },
        );
        let clamp = t.mean_over(
            uv,
            &Sampling {
                wrap_u: Wrap::Clamp,
                wrap_v: Wrap::Clamp,
                nearest: true,
            },
        );
        // Repeat: u in [1, 2] is the image again, the triangle's mean over its columns:
        // area in [1, 1.5] is 1/8, in [1.5, 2] is 3/8 of the half square -> 0.75 white.
        assert!((repeat[0] - 0.75).abs() < 1e-12, "{repeat:?}");
        assert!((clamp[0] - 1.0).abs() < 1e-12, "{clamp:?}");
    }
}

/// A texture reference of an MTL file (`map_Kd` / `map_Ke`) with the options applied here.
#[derive(Clone, Debug)]
struct MapRef {
    /// The image file, resolved against the MTL file's directory.
    file: std::path::PathBuf,
    /// `-s u v`: texture coordinate scale.
    scale: [f64; 2],
    /// `-o u v`: texture coordinate offset.
    offset: [f64; 2],
    /// `-clamp on`.
    clamp: bool,
}

/// What the MTL files say about one material's textures.
#[derive(Clone, Debug, Default)]
struct MtlTextures {
    kd: Option<[f64; 3]>,
    ke: Option<[f64; 3]>,
    map_kd: Option<MapRef>,
    map_ke: Option<MapRef>,
}

/// Parses the arguments of a `map_*` line: options, then the file name (which may contain
/// spaces).
fn parse_map(dir: &Path, args: &[&str]) -> Option<MapRef> {
    let mut r = MapRef {
        file: std::path::PathBuf::new(),
        scale: [1.0, 1.0],
        offset: [0.0, 0.0],
        clamp: false,
    };
    let mut i = 0;
    let numbers = |i: &mut usize, max: usize| -> Vec<f64> {
        let mut v = Vec::new();
        while v.len() < max {
            match args.get(*i).and_then(|w| w.parse::<f64>().ok()) {
                Some(x) if x.is_finite() => {
                    v.push(x);
                    *i += 1;
                }
                _ => break,
            }
        }
        v
    };
    while i < args.len() && args[i].starts_with('-') && args.len() - i > 1 {
        let opt = args[i];
        i += 1;
        match opt {
            "-s" => {
                let v = numbers(&mut i, 3);
                if v.len() >= 2 {
                    r.scale = [v[0], v[1]];
                } else if v.len() == 1 {
                    r.scale = [v[0], v[0]];
                }
            }
            "-o" => {
                let v = numbers(&mut i, 3);
                if v.len() >= 2 {
                    r.offset = [v[0], v[1]];
                } else if v.len() == 1 {
                    r.offset = [v[0], 0.0];
                }
            }
            "-t" => {
                numbers(&mut i, 3);
            }
            "-mm" => {
                numbers(&mut i, 2);
            }
            "-clamp" => {
                r.clamp = args.get(i).is_some_and(|w| *w == "on");
                i += 1;
            }
            _ => i += 1, // -blendu on, -bm 1, -texres n, -imfchan c, -type t, ...
        }
    }
    let name = args[i.min(args.len())..].join(" ");
    if name.is_empty() {
        return None;
    }
    r.file = dir.join(name.replace('\\', "/"));
    Some(r)
}

/// Reads the texture references of the MTL files an OBJ file names (`mtllib`), per material
/// name (the first definition of a name wins, as for the colours).
fn obj_material_textures(obj_path: &Path, obj_text: &str) -> HashMap<String, MtlTextures> {
    let base = obj_path.parent().unwrap_or(Path::new("."));
    let mut out: HashMap<String, MtlTextures> = HashMap::new();
    for argument in obj_text.lines().filter_map(mtllib::argument) {
        for name in mtllib::names(base, argument) {
            let mtl_path = base.join(name);
            // Read as the scene loader read it (which warned of what it could not read).
            let Ok(bytes) = std::fs::read(&mtl_path) else {
                continue;
            };
            let Ok(text) = crate::scene::obj::as_text(&mtl_path, &bytes, &mut Vec::new()) else {
                continue;
            };
            let dir = mtl_path.parent().unwrap_or(Path::new(".")).to_path_buf();
            let mut current: Option<String> = None;
            for raw in text.lines() {
                let line = raw.split('#').next().unwrap_or("").trim();
                let words: Vec<&str> = line.split_whitespace().collect();
                let Some(&key) = words.first() else { continue };
                if key == "newmtl" {
                    let n = line["newmtl".len()..].trim().to_string();
                    // The first definition of a name wins.
                    current = if out.contains_key(&n) {
                        None
                    } else {
                        out.insert(n.clone(), MtlTextures::default());
                        Some(n)
                    };
                    continue;
                }
                let Some(m) = current.as_ref().and_then(|n| out.get_mut(n)) else {
                    continue;
                };
                let rgb = || -> Option<[f64; 3]> {
                    let v: Vec<f64> = words[1..]
                        .iter()
                        .take(3)
                        .filter_map(|w| w.parse().ok())
                        .collect();
                    (v.len() == 3).then(|| [v[0], v[1], v[2]])
                };
                match key {
                    "Kd" => m.kd = rgb(),
                    "Ke" => m.ke = rgb(),
                    "map_Kd" => m.map_kd = parse_map(&dir, &words[1..]),
                    "map_Ke" => m.map_ke = parse_map(&dir, &words[1..]),
                    _ => {}
                }
            }
        }
    }
    out
}

/// The texture coordinates of every triangle of an OBJ file, in the loader's order (faces in
/// file order, each cut into the triangles `polygon_corners` gives: for each triangle, its
/// corners' places in its face); `None` for a triangle whose corners do not
/// all have a `vt` reference in range. `v` is flipped (OBJ's `v` runs up the image).
fn obj_triangle_uvs(obj_text: &str, polygon_corners: &[[u32; 3]]) -> Vec<Option<[[f64; 2]; 3]>> {
    let mut vts: Vec<[f64; 2]> = Vec::new();
    let mut out = Vec::new();
    for raw in obj_text.lines() {
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        match words.next() {
            Some("vt") => {
                let v: Vec<f64> = words
                    .take(2)
                    .map(|w| w.parse().unwrap_or(f64::NAN))
                    .collect();
                let u = v.first().copied().unwrap_or(f64::NAN);
                let w = v.get(1).copied().unwrap_or(0.0);
                vts.push([u, 1.0 - w]);
            }
            Some("f") => {
                let corners: Vec<Option<[f64; 2]>> = words
                    .map(|r| {
                        let t = r.split('/').nth(1)?;
                        let i: i64 = t.parse().ok()?;
                        let k = if i > 0 { i - 1 } else { vts.len() as i64 + i };
                        (0..vts.len() as i64).contains(&k).then(|| vts[k as usize])
                    })
                    .collect();
                // The face's triangles as the loader cut them (their corners' places in the
                // face); past the loader's list (a count that differs), a fan.
                for i in 1..corners.len().saturating_sub(1) {
                    let fan = [0, i as u32, i as u32 + 1];
                    let [a, b, c] = polygon_corners.get(out.len()).copied().unwrap_or(fan);
                    let at = |k: u32| corners.get(k as usize).copied().flatten();
                    out.push(match (at(a), at(b), at(c)) {
                        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
                        _ => None,
                    });
                }
            }
            _ => {}
        }
    }
    out
}

/// Applies the `map_Kd` and `map_Ke` textures of an OBJ scene's materials to its triangles:
/// albedo = `Kd` (1 when the material has none) x the texture's mean over the triangle's UV
/// footprint, emission likewise with `Ke` and `map_Ke` (sRGB decoded, `-s`, `-o` and
/// `-clamp` applied, repeat otherwise). A texture that cannot be read, or triangles without
/// texture coordinates, keep the material's colour, with a warning naming the file and the
/// material. Albedo at or above [`crate::scene::ALBEDO_MAX`] is lowered to it, with a
/// warning. Does nothing when no material has a texture.
pub(crate) fn apply_obj_textures(
    scene: &mut crate::scene::Scene,
    obj_path: &Path,
    obj_text: &str,
    polygon_corners: &[[u32; 3]],
    warnings: &mut Vec<Warning>,
) {
    let materials = obj_material_textures(obj_path, obj_text);
    if !materials
        .values()
        .any(|m| m.map_kd.is_some() || m.map_ke.is_some())
    {
        return;
    }
    let uvs = obj_triangle_uvs(obj_text, polygon_corners);
    if uvs.len() != scene.len() {
        warnings.push(Warning::in_file(
            WarningKind::Texture,
            obj_path,
            None,
            format!(
                "textures not applied: {} textured faces counted, {} triangles loaded",
                uvs.len(),
                scene.len()
            ),
        ));
        return;
    }
    let mut cache: HashMap<std::path::PathBuf, Option<Texture>> = HashMap::new();
    let mut missing_uv: HashMap<String, usize> = HashMap::new();
    let mut clamped: HashMap<String, usize> = HashMap::new();
    let max = crate::scene::ALBEDO_MAX;
    for (t, &uv_t) in uvs.iter().enumerate() {
        let Some(name) = scene.material_name(t).map(str::to_string) else {
            continue;
        };
        let Some(m) = materials.get(&name) else {
            continue;
        };
        for (map, emissive) in [(&m.map_kd, false), (&m.map_ke, true)] {
            let Some(map) = map else { continue };
            let texture = cache.entry(map.file.clone()).or_insert_with(|| {
                match Texture::read(&map.file, true) {
                    Ok(tex) => Some(tex),
                    Err(e) => {
                        warnings.push(Warning::in_file(
                            WarningKind::Texture,
                            obj_path,
                            None,
                            format!(
                                "material '{name}': cannot read texture {}: {e}; {} used instead",
                                map.file.display(),
                                if emissive { "Ke" } else { "Kd" }
                            ),
                        ));
                        None
                    }
                }
            });
            let Some(texture) = texture.as_ref() else {
                continue;
            };
            let Some(uv) = uv_t else {
                *missing_uv.entry(name.clone()).or_default() += 1;
                continue;
            };
            let uv = uv.map(|[u, v]| {
                // `v` was flipped: scale and offset apply to OBJ's own v.
                let v_obj = 1.0 - v;
                [
                    u * map.scale[0] + map.offset[0],
                    1.0 - (v_obj * map.scale[1] + map.offset[1]),
                ]
            });
            let wrap = if map.clamp { Wrap::Clamp } else { Wrap::Repeat };
            let sampling = Sampling {
                wrap_u: wrap,
                wrap_v: wrap,
                nearest: false,
            };
            let mean = texture.mean_over(uv, &sampling);
            if emissive {
                let f = m.ke.unwrap_or([1.0; 3]);
                scene.emission[t] = [0, 1, 2].map(|c| f[c] * mean[c]);
            } else {
                let f = m.kd.unwrap_or([1.0; 3]);
                let mut a = [0, 1, 2].map(|c| f[c] * mean[c]);
                if a.iter().any(|&x| x >= max) {
                    *clamped.entry(name.clone()).or_default() += 1;
                    a = a.map(|x| x.min(max));
                }
                scene.albedo[t] = a;
            }
        }
    }
    let mut missing: Vec<_> = missing_uv.into_iter().collect();
    missing.sort();
    for (name, n) in missing {
        warnings.push(Warning::in_file(WarningKind::Texture, obj_path, None, format!(
            "material '{name}': {n} textured triangles have no texture coordinates (vt); the material's colour is used for them"
        )));
    }
    let mut clamped: Vec<_> = clamped.into_iter().collect();
    clamped.sort();
    for (name, n) in clamped {
        warnings.push(Warning::in_file(WarningKind::Albedo, obj_path, None, format!(
            "material '{name}': textured albedo at or above {max} on {n} triangles lowered to {max} (the model needs albedo below 1)"
        )));
    }
}
