//! Exact direct light: the first bounce from the emitters with explicit visibility (shadow rays),
//! antiradiance for the indirect bounces only (as the original paper's interactive system did
//! with shadow maps).
//!
//! With `R = B - E` the reflected radiance, the model's equation `B = E + rho H[B]` becomes
//!
//! ```text
//! R_e = D_e + rho_e H_e[R],    D_e = rho_e / pi * (direct irradiance of e from the emitters, with visibility)
//! ```
//!
//! so the solvers are run with the source `D` instead of `E` (antiradiance then only has to cancel
//! indirect light, which is smoother and dimmer), and `E` is added back at the end.
//!
//! `D_e / rho_e`, the mean over the element of `(1/pi) * integral E cos cos V / r^2`, is computed
//! as **unoccluded x visible fraction**:
//!
//! - the unoccluded part `U = sum_s E_s F(e <- s)` is analytic (Lambert's point-to-triangle form
//!   factor, the emitter clipped to the receiver's front half-space, integrated over the element
//!   with 1..6 x 6 points chosen by separation, as the solvers' couplings do);
//! - the visible fraction comes from shadow rays: stratified points on the element, emitters
//!   chosen by power (area x largest emission channel) with stratified choices, stratified points
//!   on the chosen emitter; each sample's unoccluded contribution `f_i` is weighed by its
//!   visibility `V_i`, and the fraction is `sum f_i V_i / sum f_i` (a ratio estimator, per RGB
//!   channel: its bias falls as 1/samples).
//!
//! Fully lit elements get exactly `U`, elements in umbra exactly 0; noise is confined to
//! penumbrae. (Subtracting a Monte Carlo estimate of the blocked light from `U` instead, an
//! unbiased control variate, leaves noise of either sign in umbrae.)
//!
//! Sampling is seeded per element (the element's index), so results are reproducible and do not
//! depend on thread scheduling. Shadow rays use the watertight test of [`crate::raytrace`].

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::dense;
use crate::geometry::{self, PLANE_EPS};
use crate::hierarchical::{Element, Prepared};
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::raytrace::RayScene;
use crate::sampling::{point_on_triangle, Rng};
use crate::solution::Solution;
use crate::solve::{finish, SolverOptions};
use crate::transport::{separation, PatchGeom, FAR_RATIO};

/// Total shadow rays one direct-light pass aims at, spread evenly over the receivers (then
/// clamped to [`MIN_SHADOW_SAMPLES`]..=[`MAX_SHADOW_SAMPLES`] per receiver).
pub const SHADOW_RAY_BUDGET: usize = 2_000_000;

/// Fewest shadow samples per receiving element (a square, for stratification).
pub const MIN_SHADOW_SAMPLES: usize = 64;

/// Most shadow samples per receiving element (a square, for stratification).
pub const MAX_SHADOW_SAMPLES: usize = 1024;

/// Seed of the per-element random streams (fixed: the direct light is deterministic).
const SEED: u64 = 0x5eed_d12e_c71d_0001;

/// The emitting patches and the power distribution used to choose among them.
struct Emitters {
    /// Patch index of each emitter.
    patch: Vec<u32>,
    /// Geometry of each emitter (unit frame).
    geom: Vec<PatchGeom>,
    /// Emitted radiance (normalized units).
    emission: Vec<[f64; 3]>,
    /// Cumulative distribution of the choice probabilities (last entry exactly 1).
    cdf: Vec<f64>,
    /// Probability of choosing each emitter (power / total power).
    probability: Vec<f64>,
}

impl Emitters {
    /// The active patches that emit in some channel, weighted by area x largest channel.
    fn new(patches: &Patches) -> Emitters {
        let mut emitters = Emitters {
            patch: Vec::new(),
            geom: Vec::new(),
            emission: Vec::new(),
            cdf: Vec::new(),
            probability: Vec::new(),
        };
        let mut power = Vec::new();
        for p in 0..patches.len() {
            let e = patches.emission[p];
            let w = patches.area[p] * e[0].max(e[1]).max(e[2]);
            if patches.active[p] && w > 0.0 && w.is_finite() {
                emitters.patch.push(p as u32);
                emitters
                    .geom
                    .push(PatchGeom::new(patches.corners[p], patches.normal[p]));
                emitters.emission.push(e);
                power.push(w);
            }
        }
        let total: f64 = power.iter().sum();
        let mut acc = 0.0;
        for w in &power {
            acc += w;
            emitters.cdf.push(acc / total);
            emitters.probability.push(w / total);
        }
        if let Some(last) = emitters.cdf.last_mut() {
            *last = 1.0;
        }
        emitters
    }

    fn len(&self) -> usize {
        self.patch.len()
    }

    /// The emitter whose cumulative interval holds `u` in [0, 1).
    fn pick(&self, u: f64) -> usize {
        self.cdf.partition_point(|&c| c <= u).min(self.len() - 1)
    }
}

/// Receiver points per side for an element and an emitter at [`separation`] `ratio`: the rule
/// of the solvers' couplings (`transport::couple`), so the direct light is integrated over the
/// receiver as finely as the transport it replaces.
fn receiver_points(ratio: f64) -> usize {
    if ratio > FAR_RATIO {
        1
    } else if ratio > 3.0 {
        2
    } else if ratio > 1.5 {
        3
    } else if ratio > 0.6 {
        4
    } else {
        6
    }
}

/// Shadow samples per receiver for `receivers` receivers: the ray budget spread evenly, clamped,
/// rounded down to a square k x k.
pub fn shadow_samples(receivers: usize) -> usize {
    let wanted =
        (SHADOW_RAY_BUDGET / receivers.max(1)).clamp(MIN_SHADOW_SAMPLES, MAX_SHADOW_SAMPLES);
    let k = wanted.isqrt();
    k * k
}

/// The direct light of a scene: its emitters, a BVH for shadow rays and the sample count.
pub struct DirectLight<'a> {
    patches: &'a Patches,
    emitters: Emitters,
    rays: RayScene<'a>,
    /// Shadow samples per receiving element (k x k).
    samples: usize,
}

impl<'a> DirectLight<'a> {
    /// Prepares the direct light of `patches` (unit frame, normalized emission, as
    /// [`crate::mesh::build_patches`] makes them) for `receivers` receiving elements (which sets
    /// the shadow samples per element, see [`shadow_samples`]).
    pub fn new(patches: &'a Patches, receivers: usize) -> DirectLight<'a> {
        DirectLight {
            patches,
            emitters: Emitters::new(patches),
            rays: RayScene::new(patches),
            samples: shadow_samples(receivers),
        }
    }

    /// Shadow samples per receiving element.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// The reflected direct radiance `D_e = rho_e * (direct irradiance)_e / pi` of every
    /// receiver (normalized units, RGB, never negative), in the order of `receivers`.
    ///
    /// Each receiver's `patch` must index `patches`; its corners, normal and area are in the unit
    /// frame (as [`Prepared::elements`] gives them). Runs in parallel over receivers; sets the
    /// progress message.
    pub fn reflected(&self, receivers: &[Element], progress: &Progress) -> Vec<[f64; 3]> {
        progress.message(format!(
            "direct light: {} receivers x {} emitters, {} shadow rays each",
            receivers.len(),
            self.emitters.len(),
            self.samples
        ));
        receivers
            .par_iter()
            .enumerate()
            .map(|(index, r)| {
                let rho = self.patches.albedo[r.patch as usize];
                if self.emitters.len() == 0 || !(r.area > 0.0) || rho.iter().all(|&x| x <= 0.0) {
                    return [0.0; 3];
                }
                let unoccluded = self.unoccluded(r);
                if unoccluded.iter().all(|&x| x <= 0.0) {
                    return [0.0; 3];
                }
                let visible = self.visible_fraction(r, index as u64);
                [0, 1, 2].map(|c| {
                    let d = rho[c] * unoccluded[c] * visible[c];
                    if d.is_finite() {
                        d.max(0.0)
                    } else {
                        0.0
                    }
                })
            })
            .collect()
    }

    /// Mean over the receiver of `sum_s E_s F(x <- s)` without visibility: the emitters' light
    /// arriving at its front side (H / pi), from the emitters' front sides, exact per point.
    fn unoccluded(&self, r: &Element) -> [f64; 3] {
        let receiver = PatchGeom::new(r.corners, r.normal);
        let mut sum = [0.0f64; 3];
        for (k, s) in self.emitters.geom.iter().enumerate() {
            if self.emitters.patch[k] == r.patch {
                continue;
            }
            // A receiver wholly behind (or in) the emitter's plane sees none of its front.
            let size = receiver.size.max(s.size);
            let tol = PLANE_EPS * size;
            if r.corners
                .iter()
                .all(|&c| s.normal.dot(c - s.corners[0]) <= tol)
            {
                continue;
            }
            // The part of the emitter in front of the receiver's plane.
            let (front, _) = geometry::clip_by_plane(&s.corners, r.corners[0], r.normal, tol);
            if front.len == 0 {
                continue;
            }
            let q = receiver_points(separation(&receiver, s));
            let mut f = 0.0;
            let mut add_point = |x: DVec3| {
                if s.normal.dot(x - s.corners[0]) > 0.0 {
                    for part in front.triangles() {
                        f += geometry::point_form_factor(x, r.normal, &part);
                    }
                }
            };
            if q == 1 {
                add_point(receiver.centroid);
            } else {
                for piece in geometry::subdivide(&r.corners, q) {
                    add_point(geometry::centroid(&piece));
                }
            }
            let f = f / (q * q) as f64;
            let e = self.emitters.emission[k];
            for c in 0..3 {
                sum[c] += e[c] * f;
            }
        }
        sum
    }

    /// The fraction of the receiver's unoccluded direct light that shadow rays find visible,
    /// per RGB channel, in [0, 1] (1 when no sample carries light: nothing to weigh).
    ///
    /// Sample i pairs the receiver point of stratum i (k x k jittered grid on the triangle) with
    /// a stratified choice of emitter (1-D strata over the power distribution) and a stratified
    /// point on it (k x k grid), both strata drawn through random permutations so the pairing
    /// stays unbiased.
    fn visible_fraction(&self, r: &Element, index: u64) -> [f64; 3] {
        let n = self.samples;
        let k = n.isqrt();
        let inv_k = 1.0 / k as f64;
        let inv_n = 1.0 / n as f64;
        let mut rng = Rng::new(SEED, index);
        let mut choice_perm: Vec<u32> = (0..n as u32).collect();
        let mut point_perm: Vec<u32> = (0..n as u32).collect();
        for perm in [&mut choice_perm, &mut point_perm] {
            for a in (1..n).rev() {
                let b = rng.below(a as u64 + 1) as usize;
                perm.swap(a, b);
            }
        }
        let mut arriving = [0.0f64; 3];
        let mut visible = [0.0f64; 3];
        for i in 0..n {
            // 1. A point on the receiver (stratum i).
            let x = point_on_triangle(
                &r.corners,
                (((i % k) as f64 + rng.next_f64()) * inv_k).min(1.0),
                (((i / k) as f64 + rng.next_f64()) * inv_k).min(1.0),
            );
            // 2. An emitter by power, and a point on it.
            let choice = ((choice_perm[i] as f64 + rng.next_f64()) * inv_n).min(1.0 - f64::EPSILON);
            let k_s = self.emitters.pick(choice);
            let s = &self.emitters.geom[k_s];
            let cell = point_perm[i] as usize;
            let y = point_on_triangle(
                &s.corners,
                (((cell % k) as f64 + rng.next_f64()) * inv_k).min(1.0),
                (((cell / k) as f64 + rng.next_f64()) * inv_k).min(1.0),
            );
            // 3. Light that would arrive (both fronts facing), and whether it does.
            let to_light = y - x;
            let dist2 = to_light.length_squared();
            if !(dist2 > 0.0 && dist2.is_finite()) {
                continue;
            }
            let dist = dist2.sqrt();
            let w_in = to_light / dist;
            let cos_x = r.normal.dot(w_in);
            let cos_s = -s.normal.dot(w_in);
            if !(cos_x > 0.0 && cos_s > 0.0) {
                continue;
            }
            let g = cos_x * cos_s / (PI * dist2) * s.area / self.emitters.probability[k_s];
            if !g.is_finite() {
                continue;
            }
            let emitter_patch = self.emitters.patch[k_s] as usize;
            let seen = self
                .rays
                .visible(x, w_in, dist, r.patch as usize, emitter_patch);
            let e = self.emitters.emission[k_s];
            for c in 0..3 {
                arriving[c] += e[c] * g;
                if seen {
                    visible[c] += e[c] * g;
                }
            }
        }
        [0, 1, 2].map(|c| {
            if arriving[c] > 0.0 {
                (visible[c] / arriving[c]).clamp(0.0, 1.0)
            } else {
                1.0
            }
        })
    }
}

/// Per-patch outgoing radiance B = R + E (normalized units) from per-receiver reflected
/// radiance R: the area-weighted mean of each patch's receivers, plus the patch's emission.
/// Patches without receivers (inactive ones) get B = E.
///
/// # Panics
/// When `receivers` and `reflected` differ in length or a receiver's patch is out of range.
fn add_emission(patches: &Patches, receivers: &[Element], reflected: &[[f64; 3]]) -> Vec<[f64; 3]> {
    assert_eq!(receivers.len(), reflected.len());
    let mut sum = vec![[0.0f64; 3]; patches.len()];
    let mut area = vec![0.0f64; patches.len()];
    for (r, b) in receivers.iter().zip(reflected) {
        let p = r.patch as usize;
        area[p] += r.area;
        for c in 0..3 {
            sum[p][c] += r.area * b[c];
        }
    }
    (0..patches.len())
        .map(|p| {
            let e = patches.emission[p];
            if area[p] > 0.0 {
                [0, 1, 2].map(|c| e[c] + sum[p][c] / area[p])
            } else {
                e
            }
        })
        .collect()
}

/// The active patches as receivers (what the dense solver works on).
fn patch_receivers(patches: &Patches) -> Vec<Element> {
    (0..patches.len())
        .filter(|&p| patches.active[p])
        .map(|p| Element {
            corners: patches.corners[p],
            normal: patches.normal[p],
            area: patches.area[p],
            patch: p as u32,
        })
        .collect()
}

/// Solves the scene with the hierarchical solver and exact direct light: the reflected direct
/// light `D` per element (shadow rays) is the source of the antiradiance solve, which then
/// carries the indirect bounces only; the emission is added back at the end.
/// Preconditions: `options.validate()` passed (`options.direct_light` itself is not read).
pub fn solve_hierarchical_direct(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Solution {
    let mut prepared = Prepared::new(patches, options, false);
    let receivers: Vec<Element> = prepared.elements().collect();
    let source = DirectLight::new(patches, receivers.len()).reflected(&receivers, progress);
    let (reflected, state) = prepared.solve_with_source(patches, &source, None, progress);
    // `reflected` is R clamped and scaled; B is formed from the unclamped element values.
    let radiance = add_emission(patches, &receivers, state.radiance());
    finish(patches, radiance, reflected.stats, options.clamp_negative)
}

/// Solves the scene with the dense solver and exact direct light (the reflected direct light is
/// computed per patch and is the dense solve's source; the emission is added back at the end).
/// Preconditions: `options.validate()` passed (`options.direct_light` itself is not read).
pub fn solve_dense_direct(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Solution {
    let receivers = patch_receivers(patches);
    let source = DirectLight::new(patches, receivers.len()).reflected(&receivers, progress);
    let mut with_source = patches.clone();
    with_source.emission = vec![[0.0; 3]; patches.len()];
    for (r, d) in receivers.iter().zip(&source) {
        with_source.emission[r.patch as usize] = *d;
    }
    let unclamped = SolverOptions {
        clamp_negative: false,
        ..options.clone()
    };
    let reflected = dense::solve_dense(&with_source, &unclamped, progress);
    // Back to normalized units (the solution was scaled by the scene's emission scale).
    let inv_scale = 1.0 / patches.emission_scale;
    let patch_reflected: Vec<[f64; 3]> = receivers
        .iter()
        .map(|r| reflected.patch_radiance[r.patch as usize].map(|x| x * inv_scale))
        .collect();
    let radiance = add_emission(patches, &receivers, &patch_reflected);
    finish(patches, radiance, reflected.stats, options.clamp_negative)
}
