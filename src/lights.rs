//! Analytic lights: point, spot, directional (sun) and a uniform sky.
//!
//! Units are radiometric, the solver's: a point or spot light has a radiant intensity `I`
//! (W / sr, per RGB channel), a sun an irradiance `E` (W / m^2 on a surface facing it), the sky a
//! radiance `L` (W / (m^2 sr)) arriving from every direction in which nothing of the scene is
//! in the way. Surfaces are lit on their front side only (the design note's one-sided
//! convention):
//!
//! ```text
//! point:  H(x) = I cos(theta_x) / r^2 * V(x, light)
//! spot:   H(x) = I a(angle) cos(theta_x) / r^2 * V,   a = clamp((cos angle - cos outer) / (cos inner - cos outer), 0, 1)^2
//! sun:    H(x) = E cos(theta_x) * V(x, -direction)
//! sky:    H(x) = L * integral over the front hemisphere of cos * V = pi L * (visible cosine-weighted fraction)
//! ```
//!
//! (`a` is the spot falloff of the KHR_lights_punctual specification's reference code: full
//! intensity inside the inner cone, none outside the outer one.) glTF gives lights in
//! photometric units; [`LUMENS_PER_WATT`] converts them, see [`crate::gltf_in`].
//!
//! Direct light from these lights is computed with shadow rays (the watertight test of
//! [`crate::raytrace`]) and enters the solvers as a source, the reflected direct radiance
//! `D = rho H / pi` of each patch ([`direct_source`]); the indirect bounces are then carried by
//! antiradiance, as for the exact direct light of emitting triangles ([`crate::direct`]).

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::mesh::Patches;
use crate::raytrace::RayScene;
use crate::sampling::{cosine_direction, point_on_triangle, Rng};

/// The luminous efficacy used to turn glTF's photometric units into radiometric ones, for every
/// light kind and for emissive materials alike: 683 lm / W (the peak of the photopic curve,
/// the definition of the candela). 1 cd = 1/683 W/sr, 1 lux = 1/683 W/m^2, 1 nit (cd/m^2) =
/// 1/683 W/(m^2 sr).
pub const LUMENS_PER_WATT: f64 = 683.0;

/// An analytic light, radiometric units, in the scene's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Emits equally in all directions from a point.
    Point {
        /// Position.
        position: DVec3,
        /// Radiant intensity, W / sr, RGB.
        intensity: [f64; 3],
    },
    /// A point light restricted to a cone.
    Spot {
        /// Position.
        position: DVec3,
        /// Unit axis of the cone (the way the light points).
        direction: DVec3,
        /// Radiant intensity on the axis, W / sr, RGB.
        intensity: [f64; 3],
        /// Half-angle of the fully lit cone, radians, in [0, outer).
        inner: f64,
        /// Half-angle beyond which nothing is lit, radians, in (0, pi/2].
        outer: f64,
    },
    /// A light at infinity (the sun).
    Sun {
        /// Unit direction in which the light travels.
        direction: DVec3,
        /// Irradiance on a surface facing the light, W / m^2, RGB.
        irradiance: [f64; 3],
    },
    /// Uniform radiance from every unblocked direction.
    Sky {
        /// Radiance, W / (m^2 sr), RGB.
        radiance: [f64; 3],
    },
}

fn finite_rgb(rgb: [f64; 3]) -> bool {
    rgb.iter().all(|x| x.is_finite() && *x >= 0.0)
}

impl Light {
    /// Checks the light: finite, non-negative colour, unit-able directions, cone angles in
    /// range. `what` names the light in the message.
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::Parameter(format!("{what}: {m}")));
        let dir_ok = |d: DVec3| d.is_finite() && d.length() > 1e-12;
        match *self {
            Light::Point {
                position,
                intensity,
            } => {
                if !position.is_finite() {
                    return bad("position is not finite".into());
                }
                if !finite_rgb(intensity) {
                    return bad("intensity must be finite and >= 0".into());
                }
            }
            Light::Spot {
                position,
                direction,
                intensity,
                inner,
                outer,
            } => {
                if !position.is_finite() {
                    return bad("position is not finite".into());
                }
                if !dir_ok(direction) {
                    return bad("direction must be finite and non-zero".into());
                }
                if !finite_rgb(intensity) {
                    return bad("intensity must be finite and >= 0".into());
                }
                if !(outer > 0.0 && outer <= PI / 2.0 + 1e-9 && inner >= 0.0 && inner < outer) {
                    return bad(format!(
                        "cone angles inner {:.6} and outer {:.6} degrees need 0 <= inner < outer <= 90",
                        inner.to_degrees(),
                        outer.to_degrees()
                    ));
                }
            }
            Light::Sun {
                direction,
                irradiance,
            } => {
                if !dir_ok(direction) {
                    return bad("direction must be finite and non-zero".into());
                }
                if !finite_rgb(irradiance) {
                    return bad("irradiance must be finite and >= 0".into());
                }
            }
            Light::Sky { radiance } => {
                if !finite_rgb(radiance) {
                    return bad("radiance must be finite and >= 0".into());
                }
            }
        }
        Ok(())
    }

    /// The largest colour channel (intensity, irradiance or radiance).
    pub fn strength(&self) -> f64 {
        let c = match self {
            Light::Point { intensity, .. } | Light::Spot { intensity, .. } => intensity,
            Light::Sun { irradiance, .. } => irradiance,
            Light::Sky { radiance } => radiance,
        };
        c[0].max(c[1]).max(c[2])
    }

    /// The same light in the solver's unit frame (positions through `unit_from_world`,
    /// intensities times `scale^2` so that irradiance, hence radiance, is unchanged), with its
    /// colour divided by `emission_scale`.
    pub fn to_unit(&self, frame: &crate::mesh::UnitFrame, emission_scale: f64) -> Light {
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

    /// For a delta light (point, spot, sun): the unit direction from `x` towards the light,
    /// the distance to it (infinite for the sun) and the irradiance it gives a surface at `x`
    /// facing it (`I a / r^2` or `E`), without visibility. `None` for the sky and for a point on
    /// the light.
    pub fn towards(&self, x: DVec3) -> Option<(DVec3, f64, [f64; 3])> {
        match *self {
            Light::Point {
                position,
                intensity,
            } => {
                let d = position - x;
                let r2 = d.length_squared();
                if !(r2 > 0.0 && r2.is_finite()) {
                    return None;
                }
                let r = r2.sqrt();
                Some((d / r, r, intensity.map(|i| i / r2)))
            }
            Light::Spot {
                position,
                direction,
                intensity,
                inner,
                outer,
            } => {
                let d = position - x;
                let r2 = d.length_squared();
                if !(r2 > 0.0 && r2.is_finite()) {
                    return None;
                }
                let r = r2.sqrt();
                let w = d / r;
                let a = spot_falloff(-w.dot(direction.normalize()), inner, outer);
                Some((w, r, intensity.map(|i| i * a / r2)))
            }
            Light::Sun {
                direction,
                irradiance,
            } => Some((-direction.normalize(), f64::INFINITY, irradiance)),
            Light::Sky { .. } => None,
        }
    }
}

/// The spot falloff at angle cosine `cos_angle` from the axis: 1 inside the inner cone, 0
/// outside the outer one, `t^2` between, `t` linear in the cosine (KHR_lights_punctual).
pub fn spot_falloff(cos_angle: f64, inner: f64, outer: f64) -> f64 {
    let (ci, co) = (inner.cos(), outer.cos());
    let t = ((cos_angle - co) / (ci - co).max(1e-3)).clamp(0.0, 1.0);
    t * t
}

/// Parses `--light` values: `point:X,Y,Z:R,G,B`, `spot:X,Y,Z:DX,DY,DZ:INNER,OUTER:R,G,B`
/// (cone half-angles in degrees, the direction the spot points), `sun:DX,DY,DZ:R,G,B` (the
/// direction the light travels). Colours are radiometric (W/sr for point and spot, W/m^2 for
/// the sun).
pub fn parse_light(text: &str) -> std::result::Result<Light, String> {
    let parts: Vec<&str> = text.split(':').collect();
    let numbers = |s: &str, n: usize, what: &str| -> std::result::Result<Vec<f64>, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|w| w.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| format!("'{s}' in {what} is not {n} comma-separated numbers"))?;
        if v.len() != n || v.iter().any(|x| !x.is_finite()) {
            return Err(format!("'{s}' in {what} is not {n} finite numbers"));
        }
        Ok(v)
    };
    let v3 = |v: Vec<f64>| DVec3::new(v[0], v[1], v[2]);
    let rgb = |v: Vec<f64>| [v[0], v[1], v[2]];
    let light = match parts.as_slice() {
        ["point", p, c] => Light::Point {
            position: v3(numbers(p, 3, "the position")?),
            intensity: rgb(numbers(c, 3, "the colour")?),
        },
        ["spot", p, d, cone, c] => {
            let angles = numbers(cone, 2, "the cone angles")?;
            Light::Spot {
                position: v3(numbers(p, 3, "the position")?),
                direction: v3(numbers(d, 3, "the direction")?),
                intensity: rgb(numbers(c, 3, "the colour")?),
                inner: angles[0].to_radians(),
                outer: angles[1].to_radians(),
            }
        }
        ["sun", d, c] => Light::Sun {
            direction: v3(numbers(d, 3, "the direction")?),
            irradiance: rgb(numbers(c, 3, "the colour")?),
        },
        _ => {
            return Err(format!(
                "'{text}' is not point:X,Y,Z:R,G,B, spot:X,Y,Z:DX,DY,DZ:INNER,OUTER:R,G,B or sun:DX,DY,DZ:R,G,B"
            ))
        }
    };
    light.validate("--light").map_err(|e| e.to_string())?;
    Ok(light)
}

/// Parses `--sky R,G,B` (radiance, W/(m^2 sr)).
pub fn parse_sky(text: &str) -> std::result::Result<Light, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|w| w.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{text}' is not R,G,B"))?;
    if v.len() != 3 {
        return Err(format!("'{text}' is not R,G,B"));
    }
    let light = Light::Sky {
        radiance: [v[0], v[1], v[2]],
    };
    light.validate("--sky").map_err(|e| e.to_string())?;
    Ok(light)
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
/// Delta lights: [`PILOT_POINTS`] stratified points on the patch, each with its exact
/// unoccluded irradiance times its visibility; where their visibilities differ,
/// [`EDGE_POINTS`] points instead. The sky: cosine-weighted rays from stratified points
/// ([`SKY_RAY_BUDGET`]), each that escapes the scene carries the sky's radiance. Deterministic
/// (each patch its own random stream).
pub fn direct_source(patches: &Patches, lights: &[Light]) -> Vec<[f64; 3]> {
    if lights.is_empty() {
        return vec![[0.0; 3]; patches.len()];
    }
    let rays = RayScene::new(patches);
    let sky_rays =
        (SKY_RAY_BUDGET / patches.active_count().max(1)).clamp(MIN_SKY_RAYS, MAX_SKY_RAYS);
    (0..patches.len())
        .into_par_iter()
        .map(|p| {
            let rho = patches.albedo[p];
            if !patches.active[p] || rho.iter().all(|&r| r <= 0.0) {
                return [0.0; 3];
            }
            let h = irradiance(patches, &rays, p, lights, sky_rays);
            [0, 1, 2].map(|c| {
                let d = rho[c] * h[c] / PI;
                if d.is_finite() {
                    d.max(0.0)
                } else {
                    0.0
                }
            })
        })
        .collect()
}

/// Mean direct irradiance of patch `p` from `lights` (unit frame).
fn irradiance(
    patches: &Patches,
    rays: &RayScene,
    p: usize,
    lights: &[Light],
    sky_rays: usize,
) -> [f64; 3] {
    let tri = patches.corners[p];
    let n = patches.normal[p];
    let mut rng = Rng::new(SEED, p as u64);
    let mut total = [0.0f64; 3];
    for light in lights {
        let h = match light {
            Light::Sky { radiance } => {
                let k = sky_rays.isqrt();
                let mut escaped = 0usize;
                for i in 0..k * k {
                    let (a, b) = (
                        ((i % k) as f64 + rng.next_f64()) / k as f64,
                        ((i / k) as f64 + rng.next_f64()) / k as f64,
                    );
                    let x = point_on_triangle(&tri, a.min(1.0), b.min(1.0));
                    let w =
                        cosine_direction(n, rng.next_f64().min(1.0 - f64::EPSILON), rng.next_f64());
                    if rays.visible(x, w, FAR, p, usize::MAX) {
                        escaped += 1;
                    }
                }
                let f = escaped as f64 / (k * k) as f64;
                radiance.map(|l| PI * l * f)
            }
            _ => {
                let pilot = delta_points(rays, &tri, n, p, light, PILOT_POINTS, &mut rng);
                if pilot.1 {
                    delta_points(rays, &tri, n, p, light, EDGE_POINTS, &mut rng).0
                } else {
                    pilot.0
                }
            }
        };
        for c in 0..3 {
            total[c] += h[c];
        }
    }
    total
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
    let source_max = source.iter().flatten().fold(0.0f64, |m, &s| m.max(s));
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
    patches.lights = lights
        .iter()
        .map(|l| l.to_unit(&patches.frame, scale))
        .collect();
    patches.emission_scale = scale;
}
