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
//! photometric units; [`LUMENS_PER_WATT`] converts them, see [`crate::scene::gltf`].
//!
//! Direct light from these lights is computed with shadow rays when the patches are built
//! ([`crate::mesh::lights`]) and enters the solvers as a source, the reflected direct radiance
//! `D = rho H / pi` of each patch; the indirect bounces are then carried by antiradiance, as
//! for the exact direct light of emitting triangles ([`crate::solve::direct`]).

use std::f64::consts::PI;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::geometry::tolerances::{CONE_ANGLE_SLACK, MIN_LIGHT_DIRECTION, SPOT_MIN_COS_SPAN};

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
        let dir_ok = |d: DVec3| d.is_finite() && d.length() > MIN_LIGHT_DIRECTION;
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
                if !(outer > 0.0
                    && outer <= PI / 2.0 + CONE_ANGLE_SLACK
                    && inner >= 0.0
                    && inner < outer)
                {
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
        let c = self.colour();
        c[0].max(c[1]).max(c[2])
    }

    /// Its colour: the intensity of a point or spot light (W / sr), the irradiance of a sun
    /// (W / m^2), the radiance of a sky (W / (m^2 sr)), RGB. The light it gives is linear in it.
    pub fn colour(&self) -> [f64; 3] {
        match *self {
            Light::Point { intensity, .. } | Light::Spot { intensity, .. } => intensity,
            Light::Sun { irradiance, .. } => irradiance,
            Light::Sky { radiance } => radiance,
        }
    }

    /// The same light with colour `rgb` ([`Light::colour`]).
    pub fn with_colour(&self, rgb: [f64; 3]) -> Light {
        let mut light = *self;
        match &mut light {
            Light::Point { intensity, .. } | Light::Spot { intensity, .. } => *intensity = rgb,
            Light::Sun { irradiance, .. } => *irradiance = rgb,
            Light::Sky { radiance } => *radiance = rgb,
        }
        light
    }

    /// The position of a point or spot light; `None` for the sun and the sky.
    pub fn position(&self) -> Option<DVec3> {
        match *self {
            Light::Point { position, .. } | Light::Spot { position, .. } => Some(position),
            Light::Sun { .. } | Light::Sky { .. } => None,
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
                let (w, r, r2) = towards_point(x, position)?;
                Some((w, r, intensity.map(|i| i / r2)))
            }
            Light::Spot {
                position,
                direction,
                intensity,
                inner,
                outer,
            } => {
                let (w, r, r2) = towards_point(x, position)?;
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

/// The unit direction from `x` to `position`, the distance and its square; `None` when they
/// coincide (or the distance is not finite).
fn towards_point(x: DVec3, position: DVec3) -> Option<(DVec3, f64, f64)> {
    let d = position - x;
    let r2 = d.length_squared();
    if !(r2 > 0.0 && r2.is_finite()) {
        return None;
    }
    let r = r2.sqrt();
    Some((d / r, r, r2))
}

/// The spot falloff at angle cosine `cos_angle` from the axis: 1 inside the inner cone, 0
/// outside the outer one, `t^2` between, `t` linear in the cosine (KHR_lights_punctual).
pub fn spot_falloff(cos_angle: f64, inner: f64, outer: f64) -> f64 {
    let (ci, co) = (inner.cos(), outer.cos());
    let t = ((cos_angle - co) / (ci - co).max(SPOT_MIN_COS_SPAN)).clamp(0.0, 1.0);
    t * t
}
