//! Ground truth: a Monte Carlo path tracer with explicit visibility.
//!
//! It estimates, for every active patch p, the outgoing radiance of the design note's model
//! (one-sided Lambertian triangles, constant B per triangle):
//!
//! ```text
//! B_p = E_p + rho_p * mean over x in p, w ~ cos/pi of L_in(x, w)
//! ```
//!
//! with stratified points x on the patch and cosine-weighted directions w in its front hemisphere.
//! `L_in` is estimated by a multi-bounce path: at every path vertex, next-event estimation to the
//! emitters (one-sided, shadow rays with explicit visibility) and a cosine-weighted bounce, the two
//! strategies combined by multiple importance sampling (power heuristic); light reaching a back side
//! is absorbed; Russian roulette after depth 3 (once a path's throughput is below 0.1) keeps the
//! estimator unbiased. Paths longer than `max_depth` segments are cut.
//!
//! Rays are traversed with an obvhs wide BVH built over padded f32 boxes, but every ray-triangle test is
//! ([`crate::geometry::raytrace`]) the watertight test of Woop, Benthin and Wald (2013) in f64 on the patch corners, so a ray through
//! the shared edge or vertex of two triangles never slips between them. Each patch has its own
//! random stream derived from the seed and the patch index: results are reproducible bit for bit
//! and independent of thread scheduling.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::geometry::sampling::{cosine_direction, point_on_triangle, Rng};
use crate::geometry::tolerances::SAMPLE_BELOW_ONE;
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solve::solution::{Solution, SolveStats};

/// Options of the reference path tracer.
#[derive(Clone, Debug)]
pub struct ReferenceOptions {
    /// Samples (point on the patch + first direction) per patch; 0 is treated as 1. Default 256.
    /// The noise of each patch's estimate falls as 1 / sqrt(spp).
    pub spp: usize,
    /// Seed of the random streams (each patch derives its own stream from it). Default 1.
    pub seed: u64,
    /// Largest number of path segments traced from a patch (the first one included); Russian
    /// roulette starts after 3 segments. Paths longer than this are cut (a bias of about
    /// rho^max_depth). Default 64; 0 gives B = E.
    pub max_depth: usize,
}

impl Default for ReferenceOptions {
    /// spp 256, seed 1, max_depth 64.
    fn default() -> Self {
        ReferenceOptions {
            spp: 256,
            seed: 1,
            max_depth: 64,
        }
    }
}

/// Path depth (segments) after which Russian roulette may end a path.
const RR_DEPTH: usize = 3;

/// Russian roulette only plays once the path throughput (largest channel) is below this value:
/// the survival probability is throughput / RR_THROUGHPUT, and survivors carry RR_THROUGHPUT.
/// Killing paths of throughput 1 (the textbook choice) makes the number of bounces the dominant
/// noise in bright closed scenes (a furnace with albedo 0.8 had 6x the noise).
const RR_THROUGHPUT: f64 = 0.1;

/// Largest side of the jittered grid of first samples (the grid has at most this squared cells).
const STRATA_MAX: usize = 1024;

/// Estimates the outgoing radiance B of every patch with a path tracer (see the module doc).
///
/// `patches` must be in the unit frame with normalized emission (as `mesh::build_patches` makes
/// them). Inactive (zero-area) patches and patches with zero albedo keep B = E. Returns B in the
/// scene's own radiance units; `stats.iterations` = spp, `stats.converged` = true. Calls
/// `progress.inc(1)` once per patch. Cost: about spp * (active patches) paths, run in parallel
/// over patches.
pub fn solve_reference(
    patches: &Patches,
    options: &ReferenceOptions,
    progress: &Progress,
) -> Solution {
    let spp = options.spp.max(1);
    let tracer = Tracer::new(patches);
    let faces = |back: bool| -> Vec<[f64; 3]> {
        (0..patches.len())
            .into_par_iter()
            .map(|p| {
                if back && !patches.is_two_sided(p) {
                    return [0.0; 3];
                }
                let b = tracer.estimate_patch(p, back, spp, options.seed, options.max_depth);
                if !back {
                    progress.inc(1);
                }
                b.map(|x| if x.is_finite() { x } else { 0.0 })
            })
            .collect()
    };
    let per_patch = faces(false);
    // Two-sided patches' back faces, each its own estimate.
    let per_patch_back = if patches.has_two_sided() {
        faces(true)
    } else {
        Vec::new()
    };
    let stats = SolveStats {
        iterations: spp,
        residual: 0.0,
        converged: true,
        ..SolveStats::default()
    };
    Solution::from_normalized_sides(patches, &per_patch, &per_patch_back, stats)
}

/// True for a number strictly above zero (false for NaN).
fn positive(x: f64) -> bool {
    x > 0.0
}

/// Power heuristic weight of a strategy with density `a` against one with density `b`.
fn power_heuristic(a: f64, b: f64) -> f64 {
    if !positive(a) {
        return 0.0;
    }
    let r = b / a;
    if r.is_nan() {
        return 0.0;
    }
    1.0 / (1.0 + r * r)
}

// ---------------------------------------------------------------------------------------------
// Scene for tracing

/// The patches with a BVH over the active ones and the emitter distribution.
struct Tracer<'a> {
    patches: &'a Patches,
    /// Closest-hit and shadow rays.
    rays: RayScene<'a>,
    /// Active emitters and the cumulative distribution of their weights area * max emission.
    emitters: Vec<u32>,
    cdf: Vec<f64>,
    /// Per patch: probability of choosing it for next-event estimation divided by its area
    /// (area density of an emitter point); 0 for non-emitters.
    light_density: Vec<f64>,
}

impl<'a> Tracer<'a> {
    fn new(patches: &'a Patches) -> Tracer<'a> {
        let active: Vec<u32> = (0..patches.len())
            .filter(|&p| patches.active[p])
            .map(|p| p as u32)
            .collect();
        let mut emitters = Vec::new();
        let mut weights = Vec::new();
        for &p in &active {
            let e = patches.emission[p as usize];
            let w = patches.area[p as usize] * e[0].max(e[1]).max(e[2]);
            if w > 0.0 && w.is_finite() {
                emitters.push(p);
                weights.push(w);
            }
        }
        let total: f64 = weights.iter().sum();
        let mut cdf = Vec::with_capacity(weights.len());
        let mut acc = 0.0;
        for w in &weights {
            acc += w;
            cdf.push(acc / total);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        let mut light_density = vec![0.0; patches.len()];
        for (&p, &w) in emitters.iter().zip(&weights) {
            light_density[p as usize] = w / total / patches.area[p as usize];
        }
        Tracer {
            patches,
            rays: RayScene::of(patches),
            emitters,
            cdf,
            light_density,
        }
    }

    /// Next-event estimate of (1/pi) * integral of emitted radiance * cos over the front
    /// hemisphere of point `x` (normal `n`) on patch `here`, MIS-weighted against cosine sampling.
    fn direct(&self, x: DVec3, n: DVec3, here: usize, rng: &mut Rng) -> [f64; 3] {
        let (u, u1, u2) = (rng.next_f64(), rng.next_f64(), rng.next_f64());
        let mut analytic = self.analytic(x, n, here);
        if self.emitters.is_empty() {
            return analytic;
        }
        let area = self.emitter_light(x, n, here, (u, u1, u2));
        for c in 0..3 {
            analytic[c] += area[c];
        }
        analytic
    }

    /// Next-event estimate from the analytic delta lights (point, spot, sun) at `x`: each
    /// light's `E cos / pi` with one shadow ray (delta lights cannot be hit by bounce rays, so
    /// no MIS weight). The sky is picked up by bounce rays that leave the scene.
    fn analytic(&self, x: DVec3, n: DVec3, here: usize) -> [f64; 3] {
        let mut sum = [0.0; 3];
        for light in &self.patches.lights {
            let Some((w, dist, e)) = light.towards(x) else {
                continue;
            };
            let cos = n.dot(w);
            if !(cos > 0.0) || e.iter().all(|&v| v <= 0.0) {
                continue;
            }
            if self.rays.visible(x, w, dist.min(1e3), here, usize::MAX) {
                for c in 0..3 {
                    sum[c] += e[c] * cos / PI;
                }
            }
        }
        sum
    }

    /// Next-event estimate from the emitting patches (see [`Self::direct`]).
    fn emitter_light(
        &self,
        x: DVec3,
        n: DVec3,
        here: usize,
        (u, u1, u2): (f64, f64, f64),
    ) -> [f64; 3] {
        if self.emitters.is_empty() {
            return [0.0; 3];
        }
        let k = self
            .cdf
            .partition_point(|&c| c <= u)
            .min(self.emitters.len() - 1);
        let e = self.emitters[k] as usize;
        if e == here {
            return [0.0; 3];
        }
        let z = point_on_triangle(&self.patches.corners[e], u1, u2);
        let d = z - x;
        let dist2 = d.length_squared();
        if !(dist2 > 0.0 && dist2.is_finite()) {
            return [0.0; 3];
        }
        let dist = dist2.sqrt();
        let w = d / dist;
        let cos_x = n.dot(w);
        let mut cos_e = -self.patches.normal[e].dot(w);
        if self.patches.is_two_sided(e) {
            // A two-sided emitter emits from both faces.
            cos_e = cos_e.abs();
        }
        if !(cos_x > 0.0 && cos_e > 0.0) {
            return [0.0; 3];
        }
        if !self.rays.visible(x, w, dist, here, e) {
            return [0.0; 3];
        }
        let pdf_light = self.light_density[e] * dist2 / cos_e;
        let pdf_bsdf = cos_x / PI;
        let factor = pdf_bsdf / pdf_light * power_heuristic(pdf_light, pdf_bsdf);
        if !factor.is_finite() {
            return [0.0; 3];
        }
        self.patches.emission[e].map(|c| c * factor)
    }

    /// Estimate of the cosine-weighted mean incident radiance (1/pi) integral L_in cos dw at point
    /// `x` (normal `n`) on patch `here`; the first bounce direction comes from `first_u`.
    fn incident(
        &self,
        x: DVec3,
        n: DVec3,
        here: usize,
        first_u: (f64, f64),
        max_depth: usize,
        rng: &mut Rng,
    ) -> [f64; 3] {
        let mut radiance = [0.0; 3];
        let mut beta = [1.0f64; 3];
        let (mut pos, mut normal, mut patch) = (x, n, here);
        let mut u = first_u;
        for depth in 0..max_depth {
            let direct = self.direct(pos, normal, patch, rng);
            for c in 0..3 {
                radiance[c] += beta[c] * direct[c];
            }
            let dir = cosine_direction(normal, u.0, u.1);
            let cos_x = normal.dot(dir);
            if !positive(cos_x) {
                break;
            }
            let Some(hit) = self.rays.closest(pos, dir, patch) else {
                // Left the scene: the sky, if any, is seen along `dir`.
                for light in &self.patches.lights {
                    if let crate::scene::lights::Light::Sky { radiance: l } = light {
                        for c in 0..3 {
                            radiance[c] += beta[c] * l[c];
                        }
                    }
                }
                break;
            };
            let q = hit.patch;
            let mut normal_q = self.patches.normal[q];
            let mut cos_q = -normal_q.dot(dir);
            if cos_q < 0.0 && self.patches.is_two_sided(q) {
                // The back face of a two-sided patch: it emits and reflects like the front.
                normal_q = -normal_q;
                cos_q = -cos_q;
            }
            if !positive(cos_q) {
                break; // back side (or grazing): absorbed
            }
            let density = self.light_density[q];
            if density > 0.0 {
                let pdf_light = density * hit.t * hit.t / cos_q;
                let weight = power_heuristic(cos_x / PI, pdf_light);
                let e = self.patches.emission[q];
                for c in 0..3 {
                    radiance[c] += beta[c] * e[c] * weight;
                }
            }
            let rho = self.patches.albedo[q];
            for c in 0..3 {
                beta[c] *= rho[c];
            }
            if depth + 1 >= RR_DEPTH {
                let survive = beta[0].max(beta[1]).max(beta[2]) / RR_THROUGHPUT;
                if !positive(survive) {
                    break;
                }
                if survive < 1.0 {
                    if rng.next_f64() >= survive {
                        break;
                    }
                    for b in &mut beta {
                        *b /= survive;
                    }
                }
            } else if beta.iter().all(|&b| b <= 0.0) {
                break;
            }
            pos = hit.point;
            normal = normal_q;
            patch = q;
            u = (rng.next_f64(), rng.next_f64());
        }
        radiance
    }

    /// B of patch `p`'s front face, or of its back face when `back` (normalized units), from
    /// `spp` samples.
    fn estimate_patch(
        &self,
        p: usize,
        back: bool,
        spp: usize,
        seed: u64,
        max_depth: usize,
    ) -> [f64; 3] {
        let e = self.patches.emission[p];
        let rho = self.patches.albedo[p];
        if !self.patches.active[p]
            || rho.iter().all(|&r| r <= 0.0)
            || (self.emitters.is_empty() && self.patches.lights.is_empty())
        {
            return e;
        }
        let tri = self.patches.corners[p];
        let n = if back {
            -self.patches.normal[p]
        } else {
            self.patches.normal[p]
        };
        let mut rng = Rng::new(seed, if back { p as u64 | 1 << 63 } else { p as u64 });
        // Jittered k x k grids for the point (cell i) and the first direction (cell perm[i]),
        // paired by a random permutation (drawn anew for every round of k^2 samples) so the
        // estimator stays unbiased; the remainder spp mod k^2 samples are uniform. k is capped
        // so the permutation stays small (4 MiB) for any spp.
        let k = spp.isqrt().min(STRATA_MAX);
        let cells = k * k;
        let stratified = spp - spp % cells;
        let mut perm: Vec<u32> = (0..cells as u32).collect();
        let inv_k = 1.0 / k as f64;
        let mut sum = [0.0f64; 3];
        for i in 0..spp {
            let cell = i % cells;
            if cell == 0 && i < stratified {
                for a in (1..cells).rev() {
                    let b = rng.below(a as u64 + 1) as usize;
                    perm.swap(a, b);
                }
            }
            let (j1, j2, j3, j4) = (
                rng.next_f64(),
                rng.next_f64(),
                rng.next_f64(),
                rng.next_f64(),
            );
            let (point_u, dir_u) = if i < stratified {
                let c = perm[cell] as usize;
                (
                    (
                        ((cell % k) as f64 + j1) * inv_k,
                        ((cell / k) as f64 + j2) * inv_k,
                    ),
                    (((c % k) as f64 + j3) * inv_k, ((c / k) as f64 + j4) * inv_k),
                )
            } else {
                ((j1, j2), (j3, j4))
            };
            let x = point_on_triangle(&tri, point_u.0.min(1.0), point_u.1.min(1.0));
            let dir_u = (dir_u.0.min(SAMPLE_BELOW_ONE), dir_u.1);
            let l = self.incident(x, n, p, dir_u, max_depth, &mut rng);
            for c in 0..3 {
                if l[c].is_finite() {
                    sum[c] += l[c];
                }
            }
        }
        let inv = 1.0 / spp as f64;
        [0, 1, 2].map(|c| e[c] + rho[c] * sum[c] * inv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_heuristic_is_a_partition_of_unity() {
        // Power heuristic sums to one and never produces NaN.
        for (a, b) in [
            (1.0, 2.0),
            (0.0, 1.0),
            (1e300, 1e-300),
            (f64::INFINITY, 1.0),
        ] {
            let w = power_heuristic(a, b) + power_heuristic(b, a);
            assert!(w.is_finite());
            if a > 0.0 && b > 0.0 && a.is_finite() {
                assert!((w - 1.0).abs() < 1e-12);
            }
        }
    }
}
