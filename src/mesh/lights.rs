//! The analytic lights' direct light on the patches: the reflected direct radiance of every
//! patch from the scene's point, spot, sun and sky lights ([`crate::scene::lights`]), with
//! shadow rays against the patches, computed when the patches are built ([`attach`], called by
//! [`crate::mesh::build_patches`]) because it sets the patches' emission scale. The solvers add
//! it to the emission ([`Patches::source`]); the path tracer samples the lights themselves
//! ([`Patches::lights`]).

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::geometry::sampling::{cosine_direction, point_on_triangle, Rng};
use crate::geometry::tolerances::SAMPLE_BELOW_ONE;
use crate::mesh::{Patches, UnitFrame};
use crate::scene::lights::{spot_falloff, Light};

impl Light {
    /// The same light in the solver's unit frame (positions through `unit_from_world`,
    /// intensities times `scale^2` so that irradiance, hence radiance, is unchanged), with its
    /// colour divided by `emission_scale`.
    pub fn to_unit(&self, frame: &UnitFrame, emission_scale: f64) -> Light {
        let k = 1.0 / emission_scale;
        let s2 = frame.scale * frame.scale;
        match *self {
            Light::Point {
                position,
                intensity,
            } => Light::Point {
                position: frame.unit_from_world(position),
                intensity: intensity.map(|x| x * s2 * k),
            },
            Light::Spot {
                position,
                direction,
                intensity,
                inner,
                outer,
            } => Light::Spot {
                position: frame.unit_from_world(position),
                direction: direction.normalize(),
                intensity: intensity.map(|x| x * s2 * k),
                inner,
                outer,
            },
            Light::Sun {
                direction,
                irradiance,
            } => Light::Sun {
                direction: direction.normalize(),
                irradiance: irradiance.map(|x| x * k),
            },
            Light::Sky { radiance } => Light::Sky {
                radiance: radiance.map(|x| x * k),
            },
        }
    }
}

/// Fewest shadow points per patch and light (a square): a patch whose points all agree (all lit
/// or all in shadow) gets no more.
pub const PILOT_POINTS: usize = 16;

/// Shadow points per patch and light where the pilot points disagree (a penumbra, a shadow
/// edge or a spot's cone edge crosses the patch).
pub const EDGE_POINTS: usize = 256;

/// Cosine-weighted rays for the sky, spread evenly over the active patches and clamped to
/// [`MIN_SKY_RAYS`]..=[`MAX_SKY_RAYS`] per patch (the visible fraction's noise falls as
/// 1 / sqrt(rays): about 1.5% at 1024 rays for a half-covered patch).
pub const SKY_RAY_BUDGET: usize = 4_000_000;

/// Fewest sky rays per patch.
pub const MIN_SKY_RAYS: usize = 64;

/// Most sky rays per patch.
pub const MAX_SKY_RAYS: usize = 1024;

/// A distance beyond the whole scene in the unit frame (diameter 1): where a ray towards the
/// sun or the sky counts as having escaped.
const FAR: f64 = 1e3;

const SEED: u64 = 0x5eed_119a_7000_0001;

/// The reflected direct radiance `D_p = rho_p * (mean direct irradiance over p) / pi` of every
/// patch from `lights` (which must be in the unit frame, normalized as [`Light::to_unit`]
/// makes them), with shadow rays against the active patches. Inactive patches get 0.
///
/// The sum of [`light_source_faces`] over the lights, each light `k` with its own random streams:
/// so one light's share can be recomputed alone when it moves (relighting), and is the same
/// as in the sum.
pub fn direct_source(patches: &Patches, lights: &[Light]) -> Vec<[f64; 3]> {
    direct_source_faces(patches, lights, false)
}

/// [`direct_source`] of the patches' front faces, or of their back faces when `back` (then
/// one-sided patches get 0: their backs absorb).
pub fn direct_source_faces(patches: &Patches, lights: &[Light], back: bool) -> Vec<[f64; 3]> {
    sum_over_lights(patches, lights, patches.len(), |rays, light, k| {
        light_source_faces(patches, rays, light, k, back)
    })
}

/// The sum over `lights` of `per_light(rays, light, index)` (`len` values each; all zero
/// without lights), with one ray scene of the active patches for all of them.
fn sum_over_lights(
    patches: &Patches,
    lights: &[Light],
    len: usize,
    per_light: impl Fn(&RayScene, &Light, usize) -> Vec<[f64; 3]>,
) -> Vec<[f64; 3]> {
    let mut total = vec![[0.0; 3]; len];
    if lights.is_empty() {
        return total;
    }
    let rays = RayScene::of(patches);
    for (k, light) in lights.iter().enumerate() {
        add_into(&mut total, per_light(&rays, light, k));
    }
    total
}

/// Adds `values` to `sums`, channel by channel (as many as both have).
pub fn add_into(sums: &mut [[f64; 3]], values: impl IntoIterator<Item = [f64; 3]>) {
    for (sum, v) in sums.iter_mut().zip(values) {
        for c in 0..3 {
            sum[c] += v[c];
        }
    }
}

/// The reflected direct radiance of every patch's front face, or of its back face when `back`
/// (one-sided patches then get 0; a back face is its patch with the corners reversed and the
/// normal negated, with its own random streams), from one light (unit frame, as
/// [`direct_source`]), `index` its place among the scene's lights (which picks its random
/// streams), with shadow rays against `rays` (the active patches: `RayScene::new(&patches.corners,
/// &patches.active)`). Inactive patches get 0.
///
/// Delta lights: [`PILOT_POINTS`] stratified points on the patch, each with its exact
/// unoccluded irradiance times its visibility; where their visibilities differ,
/// [`EDGE_POINTS`] points instead. The sky: cosine-weighted rays from stratified points
/// ([`SKY_RAY_BUDGET`]), each that escapes the scene carries the sky's radiance. Deterministic
/// (each patch and light its own random stream). Linear in the light's colour.
pub fn light_source_faces(
    patches: &Patches,
    rays: &RayScene,
    light: &Light,
    index: usize,
    back: bool,
) -> Vec<[f64; 3]> {
    let sky_rays =
        (SKY_RAY_BUDGET / patches.active_count().max(1)).clamp(MIN_SKY_RAYS, MAX_SKY_RAYS);
    let seed = SEED.wrapping_add(index as u64);
    (0..patches.len())
        .into_par_iter()
        .map(|p| {
            let rho = patches.albedo[p];
            if !patches.active[p] || rho.iter().all(|&r| r <= 0.0) {
                return [0.0; 3];
            }
            if back && !patches.is_two_sided(p) {
                return [0.0; 3];
            }
            let stream = if back { p as u64 | 1 << 63 } else { p as u64 };
            let mut rng = Rng::new(seed, stream);
            let h = irradiance(patches, rays, p, back, light, sky_rays, &mut rng);
            reflected(rho, h)
        })
        .collect()
}

/// Mean direct irradiance of patch `p` from `light` (unit frame).
fn irradiance(
    patches: &Patches,
    rays: &RayScene,
    p: usize,
    back: bool,
    light: &Light,
    sky_rays: usize,
    rng: &mut Rng,
) -> [f64; 3] {
    let (tri, n) = if back {
        let [a, b, c] = patches.corners[p];
        ([a, c, b], -patches.normal[p])
    } else {
        (patches.corners[p], patches.normal[p])
    };
    irradiance_over(rays, &tri, n, p, light, sky_rays, rng)
}

/// The reflected direct radiance from `lights` (unit frame, as [`direct_source`]) of each of
/// `faces`, given as (corners, normal, patch): pieces of patches (the hierarchical solver's
/// elements, or their back faces with the corners reversed and the normal negated), each with
/// its patch's albedo and its own random streams. Over a patch lit unevenly (a point light
/// close by) its pieces get their own light where [`direct_source`] gives the patch's mean.
pub fn faces_source(
    patches: &Patches,
    lights: &[Light],
    faces: &[(crate::geometry::Tri, DVec3, u32)],
) -> Vec<[f64; 3]> {
    sum_over_lights(patches, lights, faces.len(), |rays, light, k| {
        light_faces_source(patches, rays, light, k, faces)
    })
}

/// [`faces_source`] of one light, `index` its place among the scene's lights (which picks its
/// random streams), with shadow rays against `rays` (the active patches): the same numbers as
/// its share of [`faces_source`], so that a relighter can recompute one light alone.
pub fn light_faces_source(
    patches: &Patches,
    rays: &RayScene,
    light: &Light,
    index: usize,
    faces: &[(crate::geometry::Tri, DVec3, u32)],
) -> Vec<[f64; 3]> {
    let sky_rays = (SKY_RAY_BUDGET / faces.len().max(1)).clamp(MIN_SKY_RAYS, MAX_SKY_RAYS);
    let seed = SEED.wrapping_add(index as u64);
    faces
        .par_iter()
        .enumerate()
        .map(|(i, (tri, n, p))| {
            let rho = patches.albedo[*p as usize];
            if rho.iter().all(|&r| r <= 0.0) {
                return [0.0; 3];
            }
            let mut rng = Rng::new(seed, i as u64 | 1 << 62);
            reflected(
                rho,
                irradiance_over(rays, tri, *n, *p as usize, light, sky_rays, &mut rng),
            )
        })
        .collect()
}

/// The reflected radiance `rho * h / pi` of irradiance `h`, non-negative and finite.
fn reflected(rho: [f64; 3], h: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        let d = rho[c] * h[c] / PI;
        if d.is_finite() {
            d.max(0.0)
        } else {
            0.0
        }
    })
}

/// Mean direct irradiance from `light` (unit frame) over triangle `tri` with normal `n`, a piece
/// of patch `p` (which its shadow rays skip).
fn irradiance_over(
    rays: &RayScene,
    tri: &crate::geometry::Tri,
    n: DVec3,
    p: usize,
    light: &Light,
    sky_rays: usize,
    rng: &mut Rng,
) -> [f64; 3] {
    let tri = *tri;
    match light {
        Light::Sky { radiance } => {
            let k = sky_rays.isqrt();
            let mut escaped = 0usize;
            for i in 0..k * k {
                let (a, b) = (
                    ((i % k) as f64 + rng.next_f64()) / k as f64,
                    ((i / k) as f64 + rng.next_f64()) / k as f64,
                );
                let x = point_on_triangle(&tri, a.min(1.0), b.min(1.0));
                let w = cosine_direction(n, rng.next_f64().min(SAMPLE_BELOW_ONE), rng.next_f64());
                if rays.visible(x, w, FAR, p, usize::MAX) {
                    escaped += 1;
                }
            }
            let f = escaped as f64 / (k * k) as f64;
            radiance.map(|l| PI * l * f)
        }
        _ => {
            let pilot = delta_points(rays, &tri, n, p, light, PILOT_POINTS, rng);
            if pilot.1 {
                delta_points(rays, &tri, n, p, light, EDGE_POINTS, rng).0
            } else {
                pilot.0
            }
        }
    }
}

/// Mean irradiance from one delta light over the triangle, from `count` stratified points,
/// and whether the points disagreed (some lit, some not, or a spot's falloff changing over the
/// triangle), so that more points are worth it.
///
/// A point or spot light in front of the triangle's plane: the exact unoccluded mean
/// `I * Omega / A` (the integral of `cos / r^2` over the triangle is the solid angle `Omega` it
/// subtends at the light) times the ratio `sum f_i a_i V_i / sum f_i` over the points
/// (`f = cos / r^2`, `a` the spot falloff, `V` the visibility), exact when nothing blocks a
/// point light. A sun: `E cos` (constant over a flat triangle) times the visible fraction.
fn delta_points(
    rays: &RayScene,
    tri: &crate::geometry::Tri,
    n: DVec3,
    p: usize,
    light: &Light,
    count: usize,
    rng: &mut Rng,
) -> ([f64; 3], bool) {
    let area = crate::geometry::area(tri);
    if !(area > 0.0) {
        return ([0.0; 3], false);
    }
    // The exact unoccluded mean (per unit of the light's colour) and the colour.
    let (unoccluded, colour) = match *light {
        Light::Point {
            position,
            intensity,
        }
        | Light::Spot {
            position,
            intensity,
            ..
        } => {
            if !(n.dot(position - tri[0]) > 0.0) {
                return ([0.0; 3], false);
            }
            (
                crate::geometry::solid_angle(position, tri) / area,
                intensity,
            )
        }
        Light::Sun {
            direction,
            irradiance,
        } => {
            let cos = -n.dot(direction.normalize());
            if !(cos > 0.0) {
                return ([0.0; 3], false);
            }
            (cos, irradiance)
        }
        Light::Sky { .. } => return ([0.0; 3], false),
    };
    let k = count.isqrt().max(1);
    let (mut all, mut kept) = (0.0f64, 0.0f64);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for i in 0..k * k {
        let (a, b) = (
            ((i % k) as f64 + rng.next_f64()) / k as f64,
            ((i / k) as f64 + rng.next_f64()) / k as f64,
        );
        let x = point_on_triangle(tri, a.min(1.0), b.min(1.0));
        let Some((w, dist, _)) = light.towards(x) else {
            continue;
        };
        let cos = n.dot(w);
        if !(cos > 0.0) {
            continue;
        }
        let (f, falloff) = match *light {
            Light::Spot {
                direction,
                inner,
                outer,
                ..
            } => (
                cos / (dist * dist),
                spot_falloff(-w.dot(direction.normalize()), inner, outer),
            ),
            Light::Point { .. } => (cos / (dist * dist), 1.0),
            _ => (1.0, 1.0),
        };
        if !f.is_finite() {
            continue;
        }
        all += f;
        // The unit frame has diameter 1: a sun ray that got this far has left the scene.
        let seen = falloff > 0.0 && rays.visible(x, w, dist.min(FAR), p, usize::MAX);
        let g = if seen { falloff } else { 0.0 };
        kept += f * g;
        lo = lo.min(g);
        hi = hi.max(g);
    }
    // A spot's cone edge crossing the triangle between the points: its corners disagree.
    let mut edge = false;
    if let Light::Spot {
        position,
        direction,
        inner,
        outer,
        ..
    } = *light
    {
        let f = tri.map(|c| {
            spot_falloff(
                (c - position).normalize().dot(direction.normalize()),
                inner,
                outer,
            )
        });
        edge = f.iter().any(|&x| x != f[0]);
    }
    if !(all > 0.0) {
        return ([0.0; 3], edge);
    }
    let ratio = kept / all;
    (colour.map(|c| c * unoccluded * ratio), hi > lo || edge)
}

/// Attaches `lights` (scene frame, radiometric) to freshly built `patches`: computes their
/// reflected direct radiance ([`direct_source`]) into [`Patches::source`], stores the lights
/// in the unit frame in [`Patches::lights`], and renormalizes so that the largest of the
/// emission and the source is 1 (the emission scale then covers both).
pub fn attach(patches: &mut Patches, lights: &[Light]) {
    let old_scale = patches.emission_scale;
    let emission_max = patches
        .emission
        .iter()
        .flatten()
        .fold(0.0f64, |m, &e| m.max(e))
        * old_scale;
    let unit: Vec<Light> = lights
        .iter()
        .map(|l| l.to_unit(&patches.frame, 1.0))
        .collect();
    let source = direct_source(patches, &unit);
    let source_back = if patches.has_two_sided() {
        direct_source_faces(patches, &unit, true)
    } else {
        Vec::new()
    };
    let source_max = (source.iter().chain(&source_back))
        .flatten()
        .fold(0.0f64, |m, &s| m.max(s));
    let scale = emission_max.max(source_max);
    let scale = if scale > 0.0 && scale.is_finite() {
        scale
    } else {
        old_scale
    };
    let k = old_scale / scale;
    for e in &mut patches.emission {
        *e = e.map(|x| x * k);
    }
    patches.source = source.iter().map(|s| s.map(|x| x / scale)).collect();
    patches.source_back = source_back.iter().map(|s| s.map(|x| x / scale)).collect();
    patches.lights = lights
        .iter()
        .map(|l| l.to_unit(&patches.frame, scale))
        .collect();
    patches.emission_scale = scale;
}
