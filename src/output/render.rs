//! A small CPU rasterizer that turns a solution into a picture (PNG), plus the tone mapping shared
//! with the PLY writer.
//!
//! Perspective pinhole camera with square pixels, near-plane clipping, a z-buffer with
//! perspective-correct interpolation, both sides of every triangle drawn: the front side with its
//! radiance B (flat per patch, or Gouraud-smoothed from per-vertex averages), the back side in
//! [`BACK_FACE_RGB`] so one-sided surfaces are visible as such. Geometry is rendered in WORLD
//! coordinates (`patches.frame.world_from_unit`), so a user camera is given in the scene's units.
//!
//! # Auto-framing
//!
//! When neither `eye` nor `target` is given ([`resolve_view`]):
//! 1. Outside view: look at the centre `c` of the world bounds from `c + D * d`, where `D` is the
//!    unit diagonal (0.5, 0.4, 1.0)/|.| (front-right-above for +Y up, -Z forward, the OBJ
//!    convention) and `d` is the distance at which the bounding sphere fits the narrower of the
//!    two fields of view, plus 5%.
//! 2. Enclosure test: a coarse probe image (96 pixels wide) is rasterized from there. If back
//!    faces cover more than half of the covered pixels, the camera would only see the outside of
//!    a closed room, so the eye moves inside: at the centre height, pulled back along the longer
//!    horizontal axis (x or z), then the other, towards its + side wall and then its - side wall
//!    by 160% (just beyond the wall), 90%, 60%, 30% or 0% of the half extent, looking along the
//!    axis the other way. Of the candidates whose probe is front-dominated, the one showing the
//!    most distinct patches wins, then the most front-side pixels (the first on ties), so a room
//!    open on one side is seen through its opening from just outside; if none is
//!    front-dominated, the candidate with the smallest back-face fraction is used (the outside
//!    view included).
//!
//! With only `target` given the eye is placed on the diagonal at the fitting distance from the
//! target; with only `eye` given the camera looks at the bounds' centre. The image's up is world
//! +Y (world -Z or +Z when looking straight down or up).
//!
//! # Exposure
//!
//! Auto exposure maps the 95th percentile of the luminance of the visible (front-facing pixels),
//! non-emissive radiance to 0.8, then applies the sRGB transfer function, clamps and quantizes to
//! 8 bits ([`tone_map`]). Emitters usually saturate to white.

use std::collections::HashMap;
use std::path::Path;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::files::write_atomic;
use crate::geometry::point_key;
use crate::geometry::tolerances::{
    DEPTH_TIE_RELATIVE, MIN_SCREEN_AREA, NEAR_PLANE_RELATIVE, SAME_POINT_RELATIVE,
};
use crate::mesh::Patches;
use crate::solve::solution::{sanitize, Solution};

/// The colour (sRGB, 8 bit) of every pixel where the back side of a triangle is seen.
pub const BACK_FACE_RGB: [u8; 3] = [40, 40, 40];

/// Scene-referred value that auto exposure maps the 95th luminance percentile to (before sRGB).
pub const AUTO_EXPOSURE_TARGET: f64 = 0.8;

/// Faces meeting at an angle larger than this (degrees) do not share a smoothed vertex.
pub const CREASE_ANGLE_DEG: f64 = 30.0;

/// The unit direction from the bounds' centre towards the auto-framed outside eye.
const DIAGONAL: DVec3 = DVec3::new(0.5, 0.4, 1.0);

/// Width in pixels of the probe image of the enclosure test.
const PROBE_WIDTH: u32 = 96;

/// Where the camera is and how the image is made.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraOptions {
    /// Eye position in world (scene) units; `None` = automatic (see the module docs).
    pub eye: Option<DVec3>,
    /// Point looked at, world units; `None` = automatic (the centre of the bounds).
    pub target: Option<DVec3>,
    /// Vertical field of view in degrees, in (0, 180). Default 50.
    pub fov_deg: f64,
    /// Image width in pixels, >= 1. Default 800.
    pub width: u32,
    /// Image height in pixels, >= 1. Default 600.
    pub height: u32,
    /// Multiplier applied to B before the sRGB curve, > 0; `None` = auto exposure.
    pub exposure: Option<f64>,
}

impl Default for CameraOptions {
    fn default() -> Self {
        CameraOptions {
            eye: None,
            target: None,
            fov_deg: 50.0,
            width: 800,
            height: 600,
            exposure: None,
        }
    }
}

impl CameraOptions {
    /// Checks the camera before anything is rendered: a size from 1x1 to 16384x16384, a field
    /// of view in (0, 180) degrees, a finite positive exposure, finite eye and target apart
    /// from each other. The one camera check: the command line calls it before solving.
    pub fn validate(&self) -> Result<()> {
        let camera = self;
        if camera.width == 0 || camera.height == 0 || camera.width > 16384 || camera.height > 16384
        {
            return Err(Error::Parameter(format!(
                "CameraOptions::width {} CameraOptions::height {}: the picture must be between 1x1 and 16384x16384 pixels",
                camera.width, camera.height
            )));
        }
        if !(camera.fov_deg.is_finite() && camera.fov_deg > 0.0 && camera.fov_deg < 180.0) {
            return Err(Error::Parameter(format!(
                "CameraOptions::fov_deg {} must be in (0, 180) degrees",
                camera.fov_deg
            )));
        }
        check_exposure(camera.exposure)?;
        for (name, p) in [("eye", camera.eye), ("target", camera.target)] {
            if let Some(p) = p {
                if !p.is_finite() {
                    return Err(Error::Parameter(format!(
                        "CameraOptions::{name} {p} is not finite"
                    )));
                }
            }
        }
        if let (Some(eye), Some(target)) = (camera.eye, camera.target) {
            if eye == target {
                return Err(Error::Parameter(format!(
                    "CameraOptions::eye and CameraOptions::target are the same point {},{},{}",
                    eye.x, eye.y, eye.z
                )));
            }
        }
        Ok(())
    }
}

/// `exposure` when it is one the renderer takes (finite and > 0); `None` (auto exposure)
/// otherwise.
fn usable_exposure(exposure: Option<f64>) -> Option<f64> {
    exposure.filter(|e| e.is_finite() && *e > 0.0)
}

/// Errors: an [`Error::Parameter`] when `exposure` is given but not one the renderer takes
/// ([`usable_exposure`]).
fn check_exposure(exposure: Option<f64>) -> Result<()> {
    match exposure {
        Some(e) if usable_exposure(exposure).is_none() => Err(Error::Parameter(format!(
            "CameraOptions::exposure {e} must be finite and > 0"
        ))),
        _ => Ok(()),
    }
}

/// How the front side of a patch is coloured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Shading {
    /// Each patch in its own constant B: shows the solver's elements exactly.
    #[default]
    Flat,
    /// Gouraud: B interpolated from per-vertex area-weighted averages over the faces that share
    /// the vertex (same position, normals within [`CREASE_ANGLE_DEG`], same emitter status).
    Smooth,
}

/// sRGB opto-electronic transfer function on [0, 1].
fn srgb_encode(x: f64) -> f64 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Rec. 709 / sRGB luminance of a linear RGB radiance.
pub fn luminance(b: [f64; 3]) -> f64 {
    0.2126 * b[0] + 0.7152 * b[1] + 0.0722 * b[2]
}

/// Tone-maps a radiance B (RGB, W / (m^2 sr)) to 8-bit sRGB: each channel is multiplied by
/// `exposure`, clamped to [0, 1], passed through the sRGB transfer function and rounded.
///
/// Never fails: non-finite products and negative values give 0, values above 1 saturate at 255.
pub fn tone_map(b: [f64; 3], exposure: f64) -> [u8; 3] {
    b.map(|x| {
        let v = sanitize(x * exposure).clamp(0.0, 1.0);
        (srgb_encode(v) * 255.0).round().clamp(0.0, 255.0) as u8
    })
}

/// Exposure that maps the 95th percentile of `samples` (luminance, weight) to
/// [`AUTO_EXPOSURE_TARGET`]; `None` when no sample with positive weight and luminance exists.
fn exposure_from(samples: &[(f64, f64)]) -> Option<f64> {
    let mut samples: Vec<(f64, f64)> = samples
        .iter()
        .copied()
        .filter(|&(l, w)| l.is_finite() && w.is_finite() && w > 0.0 && l >= 0.0)
        .collect();
    let total: f64 = samples.iter().map(|s| s.1).sum();
    if samples.is_empty() || total <= 0.0 {
        return None;
    }
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0;
    let mut p95 = samples[samples.len() - 1].0;
    for &(l, w) in &samples {
        acc += w;
        if acc >= 0.95 * total {
            p95 = l;
            break;
        }
    }
    if p95 <= 0.0 {
        // Fewer than 5% of the samples are lit: expose for the brightest one instead.
        p95 = samples[samples.len() - 1].0;
    }
    (p95 > 0.0).then(|| AUTO_EXPOSURE_TARGET / p95)
}

fn patch_b(solution: &Solution, p: usize) -> [f64; 3] {
    solution
        .patch_radiance
        .get(p)
        .copied()
        .unwrap_or([0.0; 3])
        .map(sanitize)
}

/// The radiance patch `p` is drawn in: its back face's when `back_face` (a two-sided patch seen
/// from behind), else its front's; missing values count as 0, non-finite ones are sanitized.
fn shown_b(solution: &Solution, p: usize, back_face: bool) -> [f64; 3] {
    if back_face {
        solution
            .patch_radiance_back
            .get(p)
            .copied()
            .unwrap_or([0.0; 3])
            .map(sanitize)
    } else {
        patch_b(solution, p)
    }
}

/// Auto exposure over the whole model (used for the PLY vertex colours): the area-weighted 95th
/// percentile of the luminance of the non-emissive active patches is mapped to 0.8.
///
/// Falls back to the emitters' percentile when nothing else is lit, and to 1 when nothing is.
/// The result is always finite and > 0.
pub fn auto_exposure(patches: &Patches, solution: &Solution) -> f64 {
    let collect = |emissive: bool| -> Vec<(f64, f64)> {
        (0..patches.len())
            .filter(|&p| patches.active[p] && patches.is_emitter(p) == emissive)
            .map(|p| (luminance(patch_b(solution, p)), patches.area[p]))
            .collect()
    };
    usable_exposure(exposure_from(&collect(false)).or_else(|| exposure_from(&collect(true))))
        .unwrap_or(1.0)
}

/// The patches as an indexed mesh with per-vertex radiance, shared by the PLY writer and the
/// smooth shading.
pub(crate) struct Welded {
    /// Vertex positions in the UNIT frame.
    pub positions: Vec<DVec3>,
    /// Per patch, its three vertex indices (in corner order).
    pub faces: Vec<[u32; 3]>,
    /// Per vertex, the area-weighted mean B of its faces (plain mean if they have no area).
    pub radiance: Vec<[f64; 3]>,
}

/// Welds patch corners into shared vertices: same position (bit for bit), normals within
/// [`CREASE_ANGLE_DEG`] of the vertex's first face and the same emitter status. Inactive
/// (degenerate) patches keep three vertices of their own.
pub(crate) fn weld(patches: &Patches, solution: &Solution) -> Welded {
    let cos_crease = CREASE_ANGLE_DEG.to_radians().cos();
    let mut buckets: HashMap<[u64; 3], Vec<u32>> = HashMap::new();
    let mut positions = Vec::new();
    let mut normals: Vec<DVec3> = Vec::new();
    let mut emissive: Vec<bool> = Vec::new();
    let mut weighted: Vec<([f64; 3], f64, [f64; 3], f64)> = Vec::new();
    let mut faces = Vec::with_capacity(patches.len());
    for p in 0..patches.len() {
        let b = patch_b(solution, p);
        let a = sanitize(patches.area[p]).max(0.0);
        let em = patches.is_emitter(p);
        let n = patches.normal[p];
        let mut face = [0u32; 3];
        for (k, &c) in patches.corners[p].iter().enumerate() {
            let existing = if patches.active[p] {
                buckets.get(&point_key(c)).and_then(|vs| {
                    vs.iter().copied().find(|&v| {
                        emissive[v as usize] == em && normals[v as usize].dot(n) >= cos_crease
                    })
                })
            } else {
                None
            };
            let v = existing.unwrap_or_else(|| {
                let v = positions.len() as u32;
                positions.push(c);
                normals.push(n);
                emissive.push(em);
                weighted.push(([0.0; 3], 0.0, [0.0; 3], 0.0));
                if patches.active[p] {
                    buckets.entry(point_key(c)).or_default().push(v);
                }
                v
            });
            let w = &mut weighted[v as usize];
            for (ch, &bc) in b.iter().enumerate() {
                w.0[ch] += a * bc;
                w.2[ch] += bc;
            }
            w.1 += a;
            w.3 += 1.0;
            face[k] = v;
        }
        faces.push(face);
    }
    let radiance = weighted
        .iter()
        .map(|(sum, area, plain, count)| {
            if *area > 0.0 {
                sum.map(|x| sanitize(x / area))
            } else {
                plain.map(|x| sanitize(x / count.max(1.0)))
            }
        })
        .collect();
    Welded {
        positions,
        faces,
        radiance,
    }
}

/// A pinhole camera in world coordinates with square pixels.
struct Camera {
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    /// Focal length in pixels.
    focal: f64,
    cx: f64,
    cy: f64,
    /// Near clipping distance (world units).
    near: f64,
}

impl Camera {
    fn new(eye: DVec3, target: DVec3, fov_deg: f64, width: u32, height: u32, near: f64) -> Camera {
        let mut forward = (target - eye).normalize_or_zero();
        if forward == DVec3::ZERO || !forward.is_finite() {
            forward = DVec3::NEG_Z;
        }
        let world_up = if forward.y.abs() > 0.999 {
            if forward.y < 0.0 {
                DVec3::NEG_Z
            } else {
                DVec3::Z
            }
        } else {
            DVec3::Y
        };
        let right = forward.cross(world_up).normalize();
        let up = right.cross(forward);
        let fov = fov_deg.clamp(1e-3, 179.0).to_radians();
        Camera {
            eye,
            right,
            up,
            forward,
            focal: 0.5 * height as f64 / (0.5 * fov).tan(),
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            near,
        }
    }

    /// Camera-space coordinates: x right, y up, z = depth along the view direction.
    fn to_camera(&self, p: DVec3) -> DVec3 {
        let d = p - self.eye;
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }
}

/// The rasterizer's buffers; `patch[i] == NO_PATCH` where nothing is seen.
struct Frame {
    width: usize,
    height: usize,
    inv_z: Vec<f64>,
    patch: Vec<u32>,
    front: Vec<bool>,
    radiance: Vec<[f64; 3]>,
}

const NO_PATCH: u32 = u32::MAX;

/// A clipped polygon vertex: camera-space position and radiance.
type ClipVertex = (DVec3, [f64; 3]);

impl Frame {
    fn new(width: u32, height: u32) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width: width as usize,
            height: height as usize,
            inv_z: vec![0.0; n],
            patch: vec![NO_PATCH; n],
            front: vec![false; n],
            radiance: vec![[0.0; 3]; n],
        }
    }

    /// Number of pixels showing a front side and a back side.
    fn side_counts(&self) -> (usize, usize) {
        let mut counts = (0, 0);
        for (i, &p) in self.patch.iter().enumerate() {
            if p != NO_PATCH {
                if self.front[i] {
                    counts.0 += 1;
                } else {
                    counts.1 += 1;
                }
            }
        }
        counts
    }

    /// Rasterizes one triangle given in camera space (all z >= near).
    fn triangle(&mut self, cam: &Camera, v: [ClipVertex; 3], patch: u32, front: bool) {
        let s = v.map(|(p, _)| {
            let iz = 1.0 / p.z;
            (
                cam.cx + cam.focal * p.x * iz,
                cam.cy - cam.focal * p.y * iz,
                iz,
            )
        });
        if s.iter()
            .any(|q| !(q.0.is_finite() && q.1.is_finite() && q.2.is_finite()))
        {
            return;
        }
        let edge = |a: (f64, f64, f64), b: (f64, f64, f64), px: f64, py: f64| {
            (b.0 - a.0) * (py - a.1) - (b.1 - a.1) * (px - a.0)
        };
        let area = edge(s[0], s[1], s[2].0, s[2].1);
        if area.abs() < MIN_SCREEN_AREA || !area.is_finite() {
            return;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        let min_x = s.iter().map(|q| q.0).fold(f64::INFINITY, f64::min);
        let max_x = s.iter().map(|q| q.0).fold(f64::NEG_INFINITY, f64::max);
        let min_y = s.iter().map(|q| q.1).fold(f64::INFINITY, f64::min);
        let max_y = s.iter().map(|q| q.1).fold(f64::NEG_INFINITY, f64::max);
        if max_x < 0.0 || max_y < 0.0 || min_x > w || min_y > h {
            return;
        }
        let x0 = (min_x - 0.5).floor().clamp(0.0, w - 1.0) as usize;
        let x1 = (max_x - 0.5).ceil().clamp(0.0, w - 1.0) as usize;
        let y0 = (min_y - 0.5).floor().clamp(0.0, h - 1.0) as usize;
        let y1 = (max_y - 0.5).ceil().clamp(0.0, h - 1.0) as usize;
        // Radiance divided by depth, for perspective-correct interpolation.
        let a = [0, 1, 2].map(|k| v[k].1.map(|x| x * s[k].2));
        for y in y0..=y1 {
            let py = y as f64 + 0.5;
            for x in x0..=x1 {
                let px = x as f64 + 0.5;
                let l0 = edge(s[1], s[2], px, py) / area;
                let l1 = edge(s[2], s[0], px, py) / area;
                let l2 = edge(s[0], s[1], px, py) / area;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let iz = l0 * s[0].2 + l1 * s[1].2 + l2 * s[2].2;
                let i = y * self.width + x;
                let cur = self.inv_z[i];
                // Nearer wins; at equal depth a front side wins over a back side.
                let nearer = iz > cur * (1.0 + DEPTH_TIE_RELATIVE);
                let tie_front = front && !self.front[i] && iz >= cur * (1.0 - DEPTH_TIE_RELATIVE);
                if !(nearer || tie_front) || iz.is_nan() || iz <= 0.0 {
                    continue;
                }
                self.inv_z[i] = iz;
                self.patch[i] = patch;
                self.front[i] = front;
                self.radiance[i] =
                    [0, 1, 2].map(|c| sanitize((l0 * a[0][c] + l1 * a[1][c] + l2 * a[2][c]) / iz));
            }
        }
    }
}

/// World-space bounds of all patch corners, as (min, max); a unit box at the origin if empty.
fn world_bounds(patches: &Patches) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for tri in &patches.corners {
        for &c in tri {
            let p = patches.frame.world_from_unit(c);
            if p.is_finite() {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
    }
    if lo.x > hi.x {
        (DVec3::splat(-0.5), DVec3::splat(0.5))
    } else {
        (lo, hi)
    }
}

/// A resolved view: eye and target in world units, vertical field of view, image size.
#[derive(Clone, Copy)]
struct View {
    eye: DVec3,
    target: DVec3,
    fov_deg: f64,
    width: u32,
    height: u32,
}

impl View {
    /// The view `camera` gives of `patches`: its eye and target, or [`resolve_view`]'s.
    fn of(patches: &Patches, camera: &CameraOptions) -> View {
        let (eye, target) = resolve_view(patches, camera);
        View {
            eye,
            target,
            fov_deg: camera.fov_deg,
            width: camera.width,
            height: camera.height,
        }
    }
}

/// How patch `p` is seen from `eye` (world units): (drawn as a front, showing its back face).
/// A two-sided patch seen from behind shows its back face, lit as a front; a one-sided one
/// shows its back side (drawn in [`BACK_FACE_RGB`]).
fn sides_seen(patches: &Patches, p: usize, eye: DVec3) -> (bool, bool) {
    let corner = patches.frame.world_from_unit(patches.corners[p][0]);
    let facing = patches.normal[p].dot(eye - corner) > 0.0;
    let back_face = !facing && patches.is_two_sided(p);
    (facing || back_face, back_face)
}

/// Rasterizes the patches as seen in `view`: which patch each pixel shows and from which side,
/// and with `smooth` (a solution and its welded vertices) the radiance interpolated over each
/// patch (a two-sided patch seen from behind in its back face's B); without it, radiance 0.
fn rasterize(patches: &Patches, smooth: Option<(&Solution, &Welded)>, view: View) -> Frame {
    let View {
        eye,
        target,
        fov_deg,
        width,
        height,
    } = view;
    let (lo, hi) = world_bounds(patches);
    let diameter = (hi - lo).length().max((eye - target).length());
    let near = if diameter > 0.0 && diameter.is_finite() {
        diameter * NEAR_PLANE_RELATIVE
    } else {
        NEAR_PLANE_RELATIVE
    };
    let cam = Camera::new(eye, target, fov_deg, width, height, near);
    let mut frame = Frame::new(width, height);
    for p in 0..patches.len() {
        if !patches.active[p] {
            continue; // zero area: nothing to draw
        }
        let world = patches.corners[p].map(|c| patches.frame.world_from_unit(c));
        let (front, back_face) = sides_seen(patches, p, eye);
        let attrs = match smooth {
            Some((_, wd)) if !back_face => wd.faces[p].map(|v| wd.radiance[v as usize]),
            Some((solution, _)) => [shown_b(solution, p, back_face); 3],
            None => [[0.0; 3]; 3],
        };
        let verts: [ClipVertex; 3] = [0, 1, 2].map(|k| (cam.to_camera(world[k]), attrs[k]));
        // Sutherland-Hodgman against the near plane z = near.
        let mut poly: Vec<ClipVertex> = Vec::with_capacity(4);
        for k in 0..3 {
            let (pa, aa) = verts[k];
            let (pb, ab) = verts[(k + 1) % 3];
            let (ina, inb) = (pa.z >= cam.near, pb.z >= cam.near);
            if ina {
                poly.push((pa, aa));
            }
            if ina != inb {
                let t = (cam.near - pa.z) / (pb.z - pa.z);
                let pos = pa + (pb - pa) * t;
                let attr = [0, 1, 2].map(|c| aa[c] + (ab[c] - aa[c]) * t);
                poly.push((DVec3::new(pos.x, pos.y, cam.near), attr));
            }
        }
        for k in 1..poly.len().saturating_sub(1) {
            frame.triangle(&cam, [poly[0], poly[k], poly[k + 1]], p as u32, front);
        }
    }
    frame
}

/// What a coarse probe image of the view from `eye` towards `target` shows.
struct Probe {
    /// Fraction of the covered pixels that show back sides (0 when nothing is covered).
    back_fraction: f64,
    /// Distinct patches seen from the front.
    front_patches: usize,
    /// Fraction of all pixels that show front sides.
    front_coverage: f64,
}

fn probe(patches: &Patches, eye: DVec3, target: DVec3, camera: &CameraOptions) -> Probe {
    let aspect = camera.width.max(1) as f64 / camera.height.max(1) as f64;
    let w = PROBE_WIDTH;
    let h = ((w as f64 / aspect).round() as u32).clamp(8, 4 * PROBE_WIDTH);
    let view = View {
        eye,
        target,
        fov_deg: camera.fov_deg,
        width: w,
        height: h,
    };
    let frame = rasterize(patches, None, view);
    let (front, back) = frame.side_counts();
    let mut seen: Vec<u32> = (0..frame.patch.len())
        .filter(|&i| frame.patch[i] != NO_PATCH && frame.front[i])
        .map(|i| frame.patch[i])
        .collect();
    seen.sort_unstable();
    seen.dedup();
    Probe {
        back_fraction: if front + back == 0 {
            0.0
        } else {
            back as f64 / (front + back) as f64
        },
        front_patches: seen.len(),
        front_coverage: front as f64 / (w * h) as f64,
    }
}

/// The eye and target (world units) the renderer uses for `camera`: the given ones, or the
/// automatic choice described in the module documentation (outside diagonal view, or an inside
/// view when the scene is an enclosure seen from outside).
pub fn resolve_view(patches: &Patches, camera: &CameraOptions) -> (DVec3, DVec3) {
    let (lo, hi) = world_bounds(patches);
    let center = (lo + hi) * 0.5;
    let radius = {
        let r = 0.5 * (hi - lo).length();
        if r > 0.0 && r.is_finite() {
            r
        } else {
            1.0
        }
    };
    let half_v = 0.5 * camera.fov_deg.clamp(1e-3, 179.0).to_radians();
    let aspect = camera.width.max(1) as f64 / camera.height.max(1) as f64;
    let half_h = (half_v.tan() * aspect).atan();
    let fit = 1.05 * radius / half_v.min(half_h).sin();
    let diagonal = DIAGONAL.normalize();
    match (camera.eye, camera.target) {
        (Some(eye), Some(target)) => (eye, target),
        (None, Some(target)) => (
            target + diagonal * (fit + (target - center).length()),
            target,
        ),
        (Some(eye), None) => {
            if (eye - center).length() > radius * SAME_POINT_RELATIVE {
                (eye, center)
            } else {
                (eye, eye + DVec3::NEG_Z)
            }
        }
        (None, None) => {
            let outside = (center + diagonal * fit, center);
            let outside_back = probe(patches, outside.0, outside.1, camera).back_fraction;
            if outside_back <= 0.5 {
                return outside;
            }
            // An enclosure: try eyes inside, pulled back towards a wall along a horizontal axis.
            let extent = hi - lo;
            let axes = if extent.z >= extent.x {
                [(DVec3::Z, extent.z), (DVec3::X, extent.x)]
            } else {
                [(DVec3::X, extent.x), (DVec3::Z, extent.z)]
            };
            // Of the front-dominated views, the one that shows the most patches, then the most
            // front-side pixels (so a room open on one side, like the Cornell box, is seen
            // through its opening from just outside it, not towards it from inside).
            let mut best_front: Option<((usize, f64), (DVec3, DVec3))> = None;
            let mut best = (outside_back, outside);
            for (axis, len) in axes {
                for direction in [axis, -axis] {
                    for pull in [1.6, 0.9, 0.6, 0.3, 0.0] {
                        let eye = center + direction * (0.5 * len * pull);
                        let target = eye - direction * radius;
                        let seen = probe(patches, eye, target, camera);
                        if seen.back_fraction <= 0.5 {
                            let score = (seen.front_patches, seen.front_coverage);
                            if best_front.is_none_or(|(s, _)| score > s) {
                                best_front = Some((score, (eye, target)));
                            }
                        } else if seen.back_fraction < best.0 {
                            best = (seen.back_fraction, (eye, target));
                        }
                    }
                }
            }
            best_front.map_or(best.1, |(_, view)| view)
        }
    }
}

/// Renders the solution to an RGB8 image, row-major from the top-left, `3 * width * height`
/// bytes, with flat shading (each patch in its own B). See [`render_rgb_shaded`].
pub fn render_rgb(patches: &Patches, solution: &Solution, camera: &CameraOptions) -> Vec<u8> {
    render_rgb_shaded(patches, solution, camera, Shading::Flat)
}

/// Renders the solution to an RGB8 image, row-major from the top-left, `3 * width * height`
/// bytes: black background, front sides tone-mapped from B ([`tone_map`], exposure from
/// `camera.exposure` or auto), back sides in [`BACK_FACE_RGB`].
///
/// Never fails: a zero width or height gives an empty image, an out-of-range field of view is
/// clamped to [0.001, 179] degrees, an invalid exposure (non-finite or <= 0) means auto, and
/// missing patch values count as 0. [`render_png`] validates these instead.
pub fn render_rgb_shaded(
    patches: &Patches,
    solution: &Solution,
    camera: &CameraOptions,
    shading: Shading,
) -> Vec<u8> {
    let (width, height) = (camera.width, camera.height);
    if width == 0 || height == 0 {
        return Vec::new();
    }
    if shading == Shading::Flat {
        return Raster::new(patches, camera).rgb(patches, solution, camera.exposure);
    }
    let welded = weld(patches, solution);
    let frame = rasterize(
        patches,
        Some((solution, &welded)),
        View::of(patches, camera),
    );
    tone_pixels(
        patches,
        (&frame.patch, &frame.front),
        &frame.radiance,
        camera.exposure,
    )
}

/// The RGB8 pixels of a rasterized picture: black where `patch` is [`NO_PATCH`], front sides
/// tone-mapped from `radiance` ([`tone_map`], with `exposure` when it is finite and > 0, else
/// [`frame_exposure`]'s), back sides in [`BACK_FACE_RGB`].
fn tone_pixels(
    patches: &Patches,
    (patch, front): (&[u32], &[bool]),
    radiance: &[[f64; 3]],
    exposure: Option<f64>,
) -> Vec<u8> {
    let exposure = usable_exposure(exposure)
        .unwrap_or_else(|| frame_exposure(patches, (patch, front), radiance));
    let mut rgb = Vec::with_capacity(patch.len() * 3);
    for i in 0..patch.len() {
        let pixel = if patch[i] == NO_PATCH {
            [0; 3]
        } else if front[i] {
            tone_map(radiance[i], exposure)
        } else {
            BACK_FACE_RGB
        };
        rgb.extend_from_slice(&pixel);
    }
    rgb
}

/// The pixels of one view with flat shading: which patch each shows and from which side. The
/// view depends on the geometry only, so an animation whose light changes rasterizes once and
/// shades every frame from it ([`Raster::rgb`], [`Raster::write_png`]): on the seed room at
/// 400 x 300 the rasterization is most of a picture's time.
pub struct Raster {
    width: u32,
    height: u32,
    /// Per pixel, the patch it shows ([`NO_PATCH`]: none).
    patch: Vec<u32>,
    /// Per pixel, true when it shows a front (or a two-sided patch's back face).
    front: Vec<bool>,
    /// Per patch, true when it shows its back face (two-sided, seen from behind).
    back_face: Vec<bool>,
}

impl Raster {
    /// Rasterizes `patches` as `camera` sees them (its eye and target, or the automatic view
    /// of [`resolve_view`]); a zero width or height gives an empty raster.
    pub fn new(patches: &Patches, camera: &CameraOptions) -> Raster {
        let (width, height) = (camera.width, camera.height);
        if width == 0 || height == 0 {
            return Raster {
                width,
                height,
                patch: Vec::new(),
                front: Vec::new(),
                back_face: Vec::new(),
            };
        }
        let view = View::of(patches, camera);
        let frame = rasterize(patches, None, view);
        let back_face = (0..patches.len())
            .map(|p| patches.active[p] && sides_seen(patches, p, view.eye).1)
            .collect();
        Raster {
            width,
            height,
            patch: frame.patch,
            front: frame.front,
            back_face,
        }
    }

    /// The picture of `solution` in this view, as [`render_rgb_shaded`] with flat shading gives
    /// it: each pixel in its patch's B (the back face's for a two-sided patch seen from
    /// behind), `exposure` or auto.
    pub fn rgb(&self, patches: &Patches, solution: &Solution, exposure: Option<f64>) -> Vec<u8> {
        let radiance_of = |p: usize| shown_b(solution, p, self.back_face[p]);
        let exposure = usable_exposure(exposure).unwrap_or_else(|| {
            let radiance: Vec<[f64; 3]> = (self.patch.iter())
                .map(|&p| {
                    if p == NO_PATCH {
                        [0.0; 3]
                    } else {
                        radiance_of(p as usize)
                    }
                })
                .collect();
            frame_exposure(patches, (&self.patch, &self.front), &radiance)
        });
        // Flat: a pixel's colour is its patch's, tone-mapped once per patch.
        let mut colour: Vec<Option<[u8; 3]>> = vec![None; self.back_face.len()];
        let mut rgb = Vec::with_capacity(self.patch.len() * 3);
        for (&p, &front) in self.patch.iter().zip(&self.front) {
            let pixel = if p == NO_PATCH {
                [0; 3]
            } else if front {
                *colour[p as usize]
                    .get_or_insert_with(|| tone_map(radiance_of(p as usize), exposure))
            } else {
                BACK_FACE_RGB
            };
            rgb.extend_from_slice(&pixel);
        }
        rgb
    }

    /// [`Raster::rgb`] written as a PNG, as [`render_png`] writes it.
    ///
    /// Errors: an [`Error::Parameter`] for an `exposure` that is not finite and > 0, an
    /// [`Error::Io`] naming `path` when writing fails (no file is left behind).
    pub fn write_png(
        &self,
        path: &Path,
        patches: &Patches,
        solution: &Solution,
        exposure: Option<f64>,
    ) -> Result<()> {
        check_exposure(exposure)?;
        let rgb = self.rgb(patches, solution, exposure);
        write_png(path, (self.width, self.height), &rgb)
    }
}

/// Auto exposure from the visible front-side pixels: non-emissive ones first, then emitters,
/// else 1.
fn frame_exposure(
    patches: &Patches,
    (patch, front): (&[u32], &[bool]),
    radiance: &[[f64; 3]],
) -> f64 {
    let collect = |emissive: bool| -> Vec<(f64, f64)> {
        (0..patch.len())
            .filter(|&i| {
                patch[i] != NO_PATCH
                    && front[i]
                    && patches.is_emitter(patch[i] as usize) == emissive
            })
            .map(|i| (luminance(radiance[i]), 1.0))
            .collect()
    };
    usable_exposure(exposure_from(&collect(false)).or_else(|| exposure_from(&collect(true))))
        .unwrap_or(1.0)
}

/// Renders with flat shading and writes an 8-bit RGB PNG (sRGB chunk set) atomically.
///
/// Errors: an [`Error::Parameter`] for a size outside 1..=16384, a field of view outside
/// (0, 180) degrees, a non-finite or non-positive exposure, a non-finite eye or target, or
/// eye == target; an [`Error::Io`] naming `path` when writing fails (no file is left behind).
pub fn render_png(
    path: &Path,
    patches: &Patches,
    solution: &Solution,
    camera: &CameraOptions,
) -> Result<()> {
    render_png_shaded(path, patches, solution, camera, Shading::Flat)
}

/// [`render_png`] with a choice of [`Shading`].
pub fn render_png_shaded(
    path: &Path,
    patches: &Patches,
    solution: &Solution,
    camera: &CameraOptions,
    shading: Shading,
) -> Result<()> {
    camera.validate()?;
    let rgb = render_rgb_shaded(patches, solution, camera, shading);
    write_png(path, (camera.width, camera.height), &rgb)
}

/// Writes `rgb` (RGB8, row-major from the top-left) as an 8-bit RGB PNG of `width` x `height`
/// with the sRGB chunk set, atomically.
fn write_png(path: &Path, (width, height): (u32, u32), rgb: &[u8]) -> Result<()> {
    write_atomic(path, |w| {
        let mut encoder = png::Encoder::new(w, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(png_to_io)?;
        writer.write_image_data(rgb).map_err(png_to_io)?;
        writer.finish().map_err(png_to_io)
    })
}

fn png_to_io(e: png::EncodingError) -> std::io::Error {
    match e {
        png::EncodingError::IoError(e) => e,
        other => std::io::Error::other(other.to_string()),
    }
}
