//! The animation of the command line (`antiradiance relight`): a spot sweeping the emitters,
//! emitter bands, and analytic lights moved or recoloured over the frames.

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::light_kind;
use crate::error::{Error, Result};
use crate::geometry::tolerances::OPPOSITE_DIRECTIONS;
use crate::scene::lights::Light;
use crate::scene::Scene;

/// Width (standard deviation) of the sweeping spot, as a fraction of the emitters' extent
/// along the sweep axis.
pub const SPOT_WIDTH: f64 = 0.15;

/// The axis (0, 1, 2) along which `centroids` spread most, with the lowest corner of their
/// bounds and their extent along it (0 or NaN when they do not spread).
fn sweep_axis(centroids: &[DVec3]) -> (DVec3, usize, f64) {
    let (lo, hi) = centroids.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &c| (lo.min(c), hi.max(c)),
    );
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    (lo, axis, extent[axis])
}

/// The emitting triangles of `scene` (input order) and their centroids (scene units).
pub fn emitter_centroids(scene: &Scene) -> (Vec<usize>, Vec<DVec3>) {
    let emitters: Vec<usize> = (0..scene.len()).filter(|&t| scene.is_emitter(t)).collect();
    let centroids = emitters
        .iter()
        .map(|&t| {
            let [a, b, c] = scene.corners(t);
            (a + b + c) / 3.0
        })
        .collect();
    (emitters, centroids)
}

/// Brightness factor (in `[dim, 1]`) of each emitter in frame `frame` of `frames` of a sweep.
///
/// A bright spot moves along the axis in which the emitters' `centroids` (world units) spread
/// most, from the lowest to the highest coordinate over the frames (the middle when
/// `frames == 1`). An emitter at normalized distance `d` from the spot gets
/// `dim + (1 - dim) exp(-(d / SPOT_WIDTH)² / 2)`. When the emitters do not spread (a single
/// emitter, or all at one point) they all pulse together instead: `dim` at the ends, 1 in the
/// middle frame. Preconditions: `frame < frames`, `dim` in [0, 1].
pub fn sweep_weights(centroids: &[DVec3], frame: usize, frames: usize, dim: f64) -> Vec<f64> {
    let phase = if frames > 1 {
        frame as f64 / (frames - 1) as f64
    } else {
        0.5
    };
    let (lo, axis, span) = sweep_axis(centroids);
    if !(span > 0.0 && span.is_finite()) {
        let pulse = dim + (1.0 - dim) * (std::f64::consts::PI * phase).sin();
        return vec![pulse.clamp(dim, 1.0); centroids.len()];
    }
    centroids
        .iter()
        .map(|c| {
            let d = (c[axis] - lo[axis]) / span - phase;
            dim + (1.0 - dim) * (-0.5 * (d / SPOT_WIDTH).powi(2)).exp()
        })
        .collect()
}

/// Cuts emitters into `bands` bands of equal width along the axis their `centroids` spread most;
/// returns each emitter's band and each band's centroid (mean of its emitters; bands without
/// emitters are dropped, so there may be fewer than asked). Precondition: `bands >= 1`.
pub fn emitter_bands(centroids: &[DVec3], bands: usize) -> (Vec<usize>, Vec<DVec3>) {
    let (lo, axis, span) = sweep_axis(centroids);
    let raw: Vec<usize> = centroids
        .iter()
        .map(|c| {
            if span > 0.0 && span.is_finite() {
                (((c[axis] - lo[axis]) / span * bands as f64) as usize).min(bands - 1)
            } else {
                0
            }
        })
        .collect();
    // Renumber the non-empty bands in order.
    let mut used: Vec<usize> = raw.clone();
    used.sort_unstable();
    used.dedup();
    let band: Vec<usize> = raw
        .iter()
        .map(|b| used.binary_search(b).expect("present"))
        .collect();
    let mut sum = vec![(DVec3::ZERO, 0usize); used.len()];
    for (&b, &c) in band.iter().zip(centroids) {
        sum[b].0 += c;
        sum[b].1 += 1;
    }
    let centres = sum.iter().map(|(s, n)| *s / *n as f64).collect();
    (band, centres)
}

/// The file of frame `frame` in `dir`: `frame_0000.png`, ...
pub fn frame_path(dir: &Path, frame: usize) -> PathBuf {
    dir.join(format!("frame_{frame:04}.png"))
}

/// A change of an analytic light over the frames of an animation (`--move-light` and
/// `--scale-light` of `antiradiance relight`), applied by [`animated_light`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightChange {
    /// Light `light` (its index in [`Scene::lights`]) moves in a straight line from where it
    /// is to `to` (a point or spot light: its position; a sun: the direction its light
    /// travels, along the straight line between the two unit directions, normalized).
    MoveTo {
        /// Index of the light.
        light: usize,
        /// End position, or end direction for a sun.
        to: DVec3,
    },
    /// Light `light`'s colour goes from its own to `factor` times it, linearly.
    Scale {
        /// Index of the light.
        light: usize,
        /// Colour factor at the end, finite, >= 0.
        factor: f64,
    },
}

impl LightChange {
    /// The index of the light it changes.
    pub fn light(&self) -> usize {
        match *self {
            LightChange::MoveTo { light, .. } | LightChange::Scale { light, .. } => light,
        }
    }
}

/// Checks `changes` against the scene's analytic `lights`: every index names a light, a sky is
/// not moved (it has no position or direction), a sun is not turned to the opposite of its
/// direction (no straight path between them), factors are finite and >= 0, end positions and
/// directions finite (a direction non-zero).
///
/// Errors: [`Error::Parameter`] naming the change.
pub fn check_light_changes(lights: &[Light], changes: &[LightChange]) -> Result<()> {
    for change in changes {
        let k = change.light();
        let Some(light) = lights.get(k) else {
            let kinds: Vec<String> = lights
                .iter()
                .enumerate()
                .map(|(i, l)| format!("{i} {}", light_kind(l)))
                .collect();
            let known = if lights.is_empty() {
                "the scene has no analytic lights".to_string()
            } else {
                format!(
                    "the scene has {} (numbered from 0: {})",
                    lights.len(),
                    kinds.join(", ")
                )
            };
            return Err(Error::Parameter(format!("no analytic light {k}: {known}")));
        };
        match *change {
            LightChange::Scale { factor, .. } => {
                if !(factor.is_finite() && factor >= 0.0) {
                    return Err(Error::Parameter(format!(
                        "light {k}: the colour factor {factor} must be finite and >= 0"
                    )));
                }
            }
            LightChange::MoveTo { to, .. } => {
                if !to.is_finite() {
                    return Err(Error::Parameter(format!(
                        "light {k}: the end position is not finite"
                    )));
                }
                match light {
                    Light::Sky { .. } => {
                        return Err(Error::Parameter(format!(
                            "light {k} is a sky, which has no position or direction to move"
                        )))
                    }
                    Light::Sun { direction, .. } => {
                        let (a, b) = (direction.normalize_or_zero(), to.normalize_or_zero());
                        if b == DVec3::ZERO || (a + b).length() < OPPOSITE_DIRECTIONS {
                            return Err(Error::Parameter(format!(
                                "light {k} is a sun: its end direction must be non-zero and not opposite to its direction"
                            )));
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}

/// The phase in [0, 1] of frame `frame` of an animation of `frames` frames: 0 at the first,
/// 1 at the last (1 when there is one frame).
pub fn light_phase(frame: usize, frames: usize) -> f64 {
    if frames > 1 {
        (frame as f64 / (frames - 1) as f64).min(1.0)
    } else {
        1.0
    }
}

/// Light `index` as it stands at phase `t` in [0, 1] ([`light_phase`]) of the `changes` that
/// name it (moves first, then colour factors), starting from `light` (its place at phase 0).
/// Preconditions: the changes passed [`check_light_changes`].
pub fn animated_light(light: &Light, index: usize, changes: &[LightChange], t: f64) -> Light {
    let mut out = *light;
    for change in changes.iter().filter(|c| c.light() == index) {
        match (*change, &mut out) {
            (
                LightChange::MoveTo { to, .. },
                Light::Point { position, .. } | Light::Spot { position, .. },
            ) => *position += t * (to - *position),
            (LightChange::MoveTo { to, .. }, Light::Sun { direction, .. }) => {
                let from = direction.normalize();
                *direction = (from + t * (to.normalize() - from)).normalize();
            }
            _ => {}
        }
    }
    for change in changes.iter().filter(|c| c.light() == index) {
        if let LightChange::Scale { factor, .. } = *change {
            let k = 1.0 + (factor - 1.0) * t;
            out = out.with_colour(out.colour().map(|x| x * k));
        }
    }
    out
}
