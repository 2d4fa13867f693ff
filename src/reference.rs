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
//! Rays are traversed with an obvhs BVH2 built over padded f32 boxes, but every ray-triangle test is
//! the watertight test of Woop, Benthin and Wald (2013) in f64 on the patch corners, so a ray through
//! the shared edge or vertex of two triangles never slips between them. Each patch has its own
//! random stream derived from the seed and the patch index: results are reproducible bit for bit
//! and independent of thread scheduling.

use std::f64::consts::PI;

use glam::DVec3;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use obvhs::ray::{Ray, RayHit};
use obvhs::{Boundable, BvhBuildParams};
use rayon::prelude::*;

use crate::geometry::{Tri, RAY_EPS};
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solution::{Solution, SolveStats};

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

/// Absolute padding (unit frame) of the f32 boxes the BVH is built over, so that rounding the
/// f64 corners and rays to f32 never culls a box that holds an f64 hit.
const BOX_PAD: f32 = 1e-5;

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
    let per_patch: Vec<[f64; 3]> = (0..patches.len())
        .into_par_iter()
        .map(|p| {
            let b = tracer.estimate_patch(p, spp, options.seed, options.max_depth);
            progress.inc(1);
            b.map(|x| if x.is_finite() { x } else { 0.0 })
        })
        .collect();
    let stats = SolveStats {
        iterations: spp,
        residual: 0.0,
        converged: true,
        ..SolveStats::default()
    };
    Solution::from_normalized(patches, &per_patch, stats)
}

// ---------------------------------------------------------------------------------------------
// Random numbers

/// SplitMix64 finalizer: a bijective 64-bit mix.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A small SplitMix64 generator; one stream per patch.
struct Rng {
    state: u64,
}

impl Rng {
    /// The stream of patch `index` under `seed`.
    fn new(seed: u64, index: u64) -> Rng {
        Rng {
            state: mix64(seed ^ mix64(index.wrapping_add(0x632b_e59b_d9b4_e019))),
        }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }

    /// Uniform in [0, 1), 53 bits.
    fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in 0..n (n > 0), by rejection (no modulo bias).
    fn below(&mut self, n: u64) -> u64 {
        let zone = u64::MAX - u64::MAX % n;
        loop {
            let x = self.next_u64();
            if x < zone {
                return x % n;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Sampling

/// Uniform point on a triangle from (u1, u2) in [0, 1)^2 (continuous map, keeps stratification).
fn point_on_triangle(tri: &Tri, u1: f64, u2: f64) -> DVec3 {
    let s = u1.sqrt();
    let b0 = 1.0 - s;
    let b1 = u2 * s;
    let b2 = s - b1;
    tri[0] * b0 + tri[1] * b1 + tri[2] * b2
}

/// Cosine-weighted direction about unit normal `n` from (u1, u2) in [0, 1)^2.
fn cosine_direction(n: DVec3, u1: f64, u2: f64) -> DVec3 {
    // Orthonormal basis of Duff et al. (2017).
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let s = DVec3::new(b, sign + n.y * n.y * a, -n.y);
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    (t * (r * phi.cos()) + s * (r * phi.sin()) + n * z).normalize_or_zero()
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
// Watertight ray-triangle intersection

/// A ray prepared for the watertight test of Woop, Benthin and Wald (2013), in f64.
#[derive(Clone, Copy, Debug)]
struct WatertightRay {
    org: DVec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f64,
    sy: f64,
    sz: f64,
}

/// A ray-triangle hit: distance and barycentric weights of corners 0, 1, 2.
#[derive(Clone, Copy, Debug)]
struct TriHit {
    t: f64,
    bary: [f64; 3],
}

impl WatertightRay {
    /// Precondition: `dir` is finite and not zero (its length is the unit of t).
    fn new(org: DVec3, dir: DVec3) -> WatertightRay {
        let abs = dir.abs();
        let kz = if abs.x >= abs.y && abs.x >= abs.z {
            0
        } else if abs.y >= abs.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        WatertightRay {
            org,
            kx,
            ky,
            kz,
            sx: dir[kx] / dir[kz],
            sy: dir[ky] / dir[kz],
            sz: 1.0 / dir[kz],
        }
    }

    /// Hit with `t_min < t < t_max`, either side of the triangle. Points exactly on an edge or a
    /// corner count as inside, and the edge functions of a shared edge are computed bit-identically
    /// (up to sign) by both triangles, so no ray slips between two triangles sharing an edge.
    fn intersect(&self, tri: &Tri, t_min: f64, t_max: f64) -> Option<TriHit> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = tri[0] - self.org;
        let b = tri[1] - self.org;
        let c = tri[2] - self.org;
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t = (u * az + v * bz + w * cz) / det;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let inv = 1.0 / det;
        Some(TriHit {
            t,
            bary: [u * inv, v * inv, w * inv],
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Scene for tracing

/// A padded f32 box around one patch, for the BVH build.
struct PaddedBox {
    aabb: Aabb,
}

impl Boundable for PaddedBox {
    fn aabb(&self) -> Aabb {
        self.aabb
    }
}

fn padded_box(tri: &Tri) -> PaddedBox {
    let lo = tri[0].min(tri[1]).min(tri[2]).as_vec3a();
    let hi = tri[0].max(tri[1]).max(tri[2]).as_vec3a();
    let pad_lo = lo.abs() * 1e-6 + BOX_PAD;
    let pad_hi = hi.abs() * 1e-6 + BOX_PAD;
    PaddedBox {
        aabb: Aabb {
            min: lo - pad_lo,
            max: hi + pad_hi,
        },
    }
}

/// An f32 distance bound at least as large as the f64 distance `t`, for BVH culling.
fn conservative_f32(t: f64) -> f32 {
    (t * (1.0 + 1e-5) + 1e-5) as f32
}

/// Closest hit of a ray: patch index, distance, point on the patch.
#[derive(Clone, Copy, Debug)]
struct Hit {
    patch: usize,
    t: f64,
    point: DVec3,
}

/// The patches with a BVH over the active ones and the emitter distribution.
struct Tracer<'a> {
    patches: &'a Patches,
    /// None when no patch is active.
    bvh: Option<Bvh2>,
    /// Patch index of each BVH primitive slot (already mapped through `primitive_indices`).
    slot_patch: Vec<u32>,
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
        let (bvh, slot_patch) = if active.is_empty() {
            (None, Vec::new())
        } else {
            let boxes: Vec<PaddedBox> = active
                .iter()
                .map(|&p| padded_box(&patches.corners[p as usize]))
                .collect();
            let mut build_time = std::time::Duration::ZERO;
            let bvh = obvhs::bvh2::builder::build_bvh2(
                &boxes,
                BvhBuildParams::medium_build(),
                &mut build_time,
            );
            let slot_patch = bvh
                .primitive_indices
                .iter()
                .map(|&i| active[i as usize])
                .collect();
            (Some(bvh), slot_patch)
        };

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
            bvh,
            slot_patch,
            emitters,
            cdf,
            light_density,
        }
    }

    /// Closest hit along `org + t dir` (unit `dir`), `RAY_EPS < t`, ignoring patch `skip`.
    fn closest(&self, org: DVec3, dir: DVec3, skip: usize) -> Option<Hit> {
        let bvh = self.bvh.as_ref()?;
        let wt = WatertightRay::new(org, dir);
        let ray = Ray::new(org.as_vec3a(), dir.as_vec3a(), 0.0, f32::INFINITY);
        let mut best: Option<(usize, TriHit)> = None;
        let mut best_t = f64::INFINITY;
        let mut ray_hit = RayHit::none();
        bvh.ray_traverse(ray, &mut ray_hit, |_, slot| {
            let patch = self.slot_patch[slot] as usize;
            if patch == skip {
                return f32::INFINITY;
            }
            match wt.intersect(&self.patches.corners[patch], RAY_EPS, best_t) {
                Some(h) => {
                    best_t = h.t;
                    best = Some((patch, h));
                    conservative_f32(h.t)
                }
                None => f32::INFINITY,
            }
        });
        best.map(|(patch, h)| {
            let tri = &self.patches.corners[patch];
            Hit {
                patch,
                t: h.t,
                point: tri[0] * h.bary[0] + tri[1] * h.bary[1] + tri[2] * h.bary[2],
            }
        })
    }

    /// True when nothing but patches `skip_a` and `skip_b` blocks `org + t dir` for
    /// `RAY_EPS < t < dist - RAY_EPS` (unit `dir`). Back sides block too.
    fn visible(&self, org: DVec3, dir: DVec3, dist: f64, skip_a: usize, skip_b: usize) -> bool {
        let Some(bvh) = self.bvh.as_ref() else {
            return true;
        };
        let t_max = dist - RAY_EPS;
        if t_max <= RAY_EPS {
            return true;
        }
        let wt = WatertightRay::new(org, dir);
        let ray = Ray::new(org.as_vec3a(), dir.as_vec3a(), 0.0, conservative_f32(t_max));
        bvh.ray_traverse_miss(ray, |_, slot| {
            let patch = self.slot_patch[slot] as usize;
            if patch == skip_a || patch == skip_b {
                return f32::INFINITY;
            }
            if wt
                .intersect(&self.patches.corners[patch], RAY_EPS, t_max)
                .is_some()
            {
                0.0
            } else {
                f32::INFINITY
            }
        })
    }

    /// Next-event estimate of (1/pi) * integral of emitted radiance * cos over the front
    /// hemisphere of point `x` (normal `n`) on patch `here`, MIS-weighted against cosine sampling.
    fn direct(&self, x: DVec3, n: DVec3, here: usize, rng: &mut Rng) -> [f64; 3] {
        let (u, u1, u2) = (rng.next_f64(), rng.next_f64(), rng.next_f64());
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
        let cos_e = -self.patches.normal[e].dot(w);
        if !(cos_x > 0.0 && cos_e > 0.0) {
            return [0.0; 3];
        }
        if !self.visible(x, w, dist, here, e) {
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
            let Some(hit) = self.closest(pos, dir, patch) else {
                break;
            };
            let q = hit.patch;
            let cos_q = -self.patches.normal[q].dot(dir);
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
            normal = self.patches.normal[q];
            patch = q;
            u = (rng.next_f64(), rng.next_f64());
        }
        radiance
    }

    /// B of patch `p` (normalized units) from `spp` samples.
    fn estimate_patch(&self, p: usize, spp: usize, seed: u64, max_depth: usize) -> [f64; 3] {
        let e = self.patches.emission[p];
        let rho = self.patches.albedo[p];
        if !self.patches.active[p] || rho.iter().all(|&r| r <= 0.0) || self.emitters.is_empty() {
            return e;
        }
        let tri = self.patches.corners[p];
        let n = self.patches.normal[p];
        let mut rng = Rng::new(seed, p as u64);
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
            let dir_u = (dir_u.0.min(1.0 - f64::EPSILON), dir_u.1);
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
    use crate::mesh::build_patches;
    use crate::scene::Scene;

    /// A fan of `m` triangles around `center` in a tilted plane, counter-clockwise.
    fn fan(m: usize) -> (Vec<Tri>, DVec3, Vec<DVec3>) {
        let center = DVec3::new(0.013, -0.027, 0.031);
        let u = DVec3::new(0.8, 0.35, -0.2).normalize();
        let v = u.cross(DVec3::new(0.1, 0.3, 0.9)).normalize();
        let rim: Vec<DVec3> = (0..m)
            .map(|i| {
                // Irregular angles and radii so no edge is axis-aligned.
                let a = 2.0 * PI * (i as f64 + 0.3 * ((i * 7 % 5) as f64 / 5.0)) / m as f64;
                let r = 0.3 + 0.1 * ((i * 3 % 4) as f64 / 4.0);
                center + u * (r * a.cos()) + v * (r * a.sin())
            })
            .collect();
        let tris = (0..m).map(|i| [center, rim[i], rim[(i + 1) % m]]).collect();
        (tris, center, rim)
    }

    fn fan_patches(tris: &[Tri]) -> Patches {
        let n = tris.len();
        let scene = Scene::from_triangles(tris, &vec![[0.5; 3]; n], &vec![[0.0; 3]; n]);
        build_patches(&scene, None)
    }

    #[test]
    fn watertight_fan_edges_and_vertices_never_missed() {
        let m = 9;
        let (tris, center, rim) = fan(m);
        let patches = fan_patches(&tris);
        let tracer = Tracer::new(&patches);
        // The fan in the unit frame (build_patches moved and scaled it).
        let frame = patches.frame;
        let c = frame.unit_from_world(center);
        let rim: Vec<DVec3> = rim.iter().map(|&p| frame.unit_from_world(p)).collect();
        let n = patches.normal[0];
        let mut rng = Rng::new(7, 0);
        let mut rays = 0;
        let mut f32_misses = 0;
        for trial in 0..400 {
            // Targets: the centre vertex (shared by all m triangles) and points on the m shared
            // spokes. (Rim vertices lie on the fan's outer boundary, where a ray rounded by
            // 1e-17 may legitimately pass outside, so they are not targets.)
            let i = trial % m;
            let s = 0.99 * rng.next_f64();
            let target = if trial % 4 == 0 {
                c
            } else {
                c + (rim[i] - c) * s
            };
            for side in [1.0, -1.0] {
                // Origins on both sides, at various angles (never in the plane).
                let off = DVec3::new(
                    rng.next_f64() - 0.5,
                    rng.next_f64() - 0.5,
                    rng.next_f64() - 0.5,
                ) * 0.8;
                let org = target + n * (side * (0.05 + 0.4 * rng.next_f64())) + off;
                if (org - target).dot(n) * side <= 0.0 {
                    continue;
                }
                let dir = (target - org).normalize();
                rays += 1;
                let hit = tracer.closest(org, dir, usize::MAX);
                assert!(
                    hit.is_some(),
                    "ray {org:?} -> {target:?} slipped through the fan"
                );
                let hit = hit.unwrap();
                assert!(
                    (hit.point - target).length() < 1e-9,
                    "hit far from the target"
                );
                // For information: obvhs' own f32 test.
                let hit_f32 = patches.corners.iter().any(|t| {
                    let tri = obvhs::triangle::Triangle {
                        v0: t[0].as_vec3a(),
                        v1: t[1].as_vec3a(),
                        v2: t[2].as_vec3a(),
                    };
                    let ray = Ray::new_inf(org.as_vec3a(), dir.as_vec3a());
                    tri.intersect(&ray).is_finite()
                });
                if !hit_f32 {
                    f32_misses += 1;
                }
            }
        }
        assert!(rays > 600, "{rays}");
        eprintln!("watertight: {rays} rays, f32 Moller-Trumbore missed {f32_misses}");
    }

    #[test]
    fn watertight_rejects_points_outside() {
        // Negative control: rays aimed just outside the fan's rim miss it.
        let (tris, center, rim) = fan(7);
        let patches = fan_patches(&tris);
        let tracer = Tracer::new(&patches);
        let frame = patches.frame;
        let c = frame.unit_from_world(center);
        let n = patches.normal[0];
        for (i, &r) in rim.iter().enumerate() {
            let r = frame.unit_from_world(r);
            let target = c + (r - c) * 1.001;
            let org = target + n * 0.3 + DVec3::new(0.01, 0.02, -0.01) * i as f64;
            let dir = (target - org).normalize();
            assert!(tracer.closest(org, dir, usize::MAX).is_none());
        }
    }

    #[test]
    fn watertight_exact_shared_edge_axis_aligned() {
        // Two triangles sharing the diagonal of a unit square; rays straight down at points of the
        // diagonal that are exactly representable.
        let a = DVec3::new(0.0, 0.0, 0.0);
        let b = DVec3::new(1.0, 0.0, 0.0);
        let c = DVec3::new(1.0, 1.0, 0.0);
        let d = DVec3::new(0.0, 1.0, 0.0);
        let t1 = [a, b, c];
        let t2 = [a, c, d];
        for i in 0..=64 {
            let s = i as f64 / 64.0;
            let org = DVec3::new(s, s, 1.0);
            let ray = WatertightRay::new(org, -DVec3::Z);
            let h1 = ray.intersect(&t1, 0.0, f64::INFINITY);
            let h2 = ray.intersect(&t2, 0.0, f64::INFINITY);
            assert!(h1.is_some() || h2.is_some(), "miss at s = {s}");
            for h in [h1, h2].into_iter().flatten() {
                assert_eq!(h.t, 1.0);
            }
        }
    }

    #[test]
    fn sampling_maps_stay_in_domain() {
        let tri = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let n = DVec3::new(0.3, -0.5, 0.8).normalize();
        let mut rng = Rng::new(3, 4);
        for _ in 0..1000 {
            let (u1, u2) = (rng.next_f64(), rng.next_f64());
            let p = point_on_triangle(&tri, u1, u2);
            assert!(p.x >= 0.0 && p.y >= 0.0 && p.x + p.y <= 1.0 + 1e-15 && p.z == 0.0);
            let d = cosine_direction(n, u1, u2);
            assert!((d.length() - 1.0).abs() < 1e-12 && d.dot(n) > 0.0);
        }
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
