//! Sealed fronts: one-sided surfaces whose front the light does not reach.
//!
//! A one-sided surface lit from behind absorbs, and what its front receives is what the
//! surfaces in front of it send. Where the front sees only backs (a floor under a rug) and
//! fronts that are dark themselves (the faces inside a wall slab whose polygons all face in,
//! lit from the room at their backs), its radiance is its emission. The solvers reach that
//! answer only as far as antiradiance cancels the light that passes through the surfaces in
//! between, and a gap of millimetres or a slab of centimetres is where binned antiradiance
//! cancels worst. An office exported with its walls, floor and ceiling as slabs facing in
//! (26,932 triangles; its path tracer's walls black) had walls as bright as its furniture:
//! 47% from the path tracer, bias +44%. Solved black, its sealed fronts send nothing into the
//! slabs: 3.0% (bias -0.4%), and 14 sweeps instead of 38 (docs/mesh_quality.md).
//!
//! A front is *lit* when a shadow ray from it reaches an emitter (toward points on emitters
//! chosen by power; or an analytic light shines on it), or when one of its cosine-distributed
//! rays ([`SEALED_RAYS`]) meets a two-sided surface, an emitter's front or (under a sky)
//! nothing, or when more than [`lit_rays_allowed`] of them meet the fronts of lit surfaces.
//! The rest, once that has spread as far as it goes, are sealed: they see light through a
//! sixteenth of their (cosine-weighted) hemisphere at most, and are solved black (albedo 0;
//! they still block at their backs). A surface lit through less than that gets its emission:
//! a baseboard running through a wall slab is lit where it stands in the room, and the slab's
//! inside that sees the baseboard's hidden end is still sealed.
//!
//! The test runs in two passes so that a lit scene pays little for it: [`FIRST_RAYS`] shadow
//! rays from every candidate front find most lit ones; the others cast their cosine rays,
//! stopping once more than [`lit_rays_allowed`] meet fronts the first pass lit, and those
//! still not lit [`DIRECT_RAYS`] more shadow rays. On the seed room, where nothing is sealed,
//! it costs nothing measurable (0.649 against 0.633 s, medians of 9 whole-process runs
//! alternated with the build without it; in one pass of 64 shadow rays first, 0.653 against
//! 0.623 s).

//! Only [`crate::solve::run`] does this (the `solve` command, [`crate::solve()`]), as it turns
//! closed objects outward; the relighter, whose emission changes, solves the surfaces as given.

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::geometry::sampling::{cosine_direction, point_on_triangle, Rng};
use crate::mesh::Patches;
use crate::scene::lights::Light;

/// Most cosine-distributed rays per candidate front (a square, for stratification); fewer
/// when [`SEALED_RAY_BUDGET`] spread over the candidates gives less, down to 16.
pub const SEALED_RAYS: usize = 64;

/// Shadow rays per candidate toward points on the emitters, chosen by power (area times
/// largest channel), after the [`FIRST_RAYS`] of the first pass: one that arrives makes the
/// candidate lit. On the 27k-triangle office above, measured as the only shadow rays (one
/// pass), 16 left 1.7% of the path tracer's light on fronts solved black (3.7%, bias -2.2%),
/// 64 left 0.3% (2.8%, -0.2%); two passes, 3.0% (-0.4%).
pub const DIRECT_RAYS: usize = 64;

/// Shadow rays per candidate of the first pass, which finds most lit fronts; the others take
/// [`DIRECT_RAYS`] more once their cosine rays have not found them lit.
pub const FIRST_RAYS: usize = 4;

/// Rays the test may cast in all, beyond the first shadow ray of each candidate (which lights
/// most of a lit scene): the cosine rays per candidate are this spread over the candidates,
/// at most [`SEALED_RAYS`] and at least 16.
pub const SEALED_RAY_BUDGET: usize = 4_000_000;

/// Seed of the per-patch ray streams of the first pass.
const SEED: u64 = 0x5eed_5ea1_ed00_0001;

/// Seed of the per-patch ray streams of the second pass.
const SECOND_SEED: u64 = 0x5eed_5ea1_ed00_0002;

/// How many of `rays` cosine rays may meet lit fronts with the front still sealed: a
/// sixteenth of them.
pub fn lit_rays_allowed(rays: usize) -> usize {
    rays / 16
}

/// These patches with every sealed front black (albedo 0), and how many; `None` when no front
/// is sealed.
pub fn blackened(patches: &Patches) -> Option<(Patches, u64)> {
    let sealed = sealed_fronts(patches);
    let count = sealed.iter().filter(|&&s| s).count() as u64;
    (count > 0).then(|| {
        let mut black = patches.clone();
        for (albedo, _) in black.albedo.iter_mut().zip(&sealed).filter(|(_, &s)| s) {
            *albedo = [0.0; 3];
        }
        (black, count)
    })
}

/// What one candidate's rays found: light itself (`direct`), or the candidates whose fronts
/// its cosine rays met (once per ray).
struct Seen {
    direct: bool,
    fronts: Vec<u32>,
}

/// Per patch: its front is sealed (see the module). All false when no patch is.
pub fn sealed_fronts(patches: &Patches) -> Vec<bool> {
    let n = patches.len();
    let bright = |p: usize| {
        patches.is_emitter(p)
            || patches.is_two_sided(p)
            || patches
                .source
                .get(p)
                .is_some_and(|s| s.iter().any(|&x| x > 0.0))
    };
    let candidate: Vec<bool> = (0..n)
        .map(|p| patches.active[p] && !bright(p) && patches.albedo[p].iter().any(|&a| a > 0.0))
        .collect();
    let candidates = candidate.iter().filter(|&&c| c).count();
    if candidates == 0 {
        return vec![false; n];
    }
    let k = (SEALED_RAY_BUDGET / candidates)
        .clamp(16, SEALED_RAYS)
        .isqrt();
    let allowed = lit_rays_allowed(k * k);
    let rays = RayScene::of(patches);
    let emitters = Emitters::of(patches);
    let sky = patches
        .lights
        .iter()
        .any(|l| matches!(l, Light::Sky { .. }));
    let rng_of = |p: usize| Rng::new(SEED, p as u64);
    // 1. Most lit fronts see a light at their first shadow rays.
    let first: Vec<bool> = (0..n)
        .into_par_iter()
        .map(|p| {
            candidate[p]
                && (lit_by_analytic(patches, &rays, p)
                    || emitters.seen_from(patches, &rays, p, &mut rng_of(p), FIRST_RAYS))
        })
        .collect();
    // 2. The others cast their cosine rays (a front that sees more than `allowed` of those
    //    already lit is lit, and stops), then the rest of their shadow rays.
    let seen: Vec<Option<Seen>> = (0..n)
        .into_par_iter()
        .map(|p| {
            if !candidate[p] {
                return None;
            }
            let mut seen = Seen {
                direct: first[p],
                fronts: Vec::new(),
            };
            let mut rng = Rng::new(SECOND_SEED, p as u64);
            let (tri, normal) = (&patches.corners[p], patches.normal[p]);
            let cell = 1.0 / k as f64;
            let mut lit_fronts = 0;
            for i in 0..k * k {
                if seen.direct {
                    return Some(seen);
                }
                let (a, b) = ((i % k) as f64, (i / k) as f64);
                let x = point_on_triangle(
                    tri,
                    ((a + rng.next_f64()) * cell).min(1.0),
                    ((b + rng.next_f64()) * cell).min(1.0),
                );
                let dir = cosine_direction(normal, rng.next_f64(), rng.next_f64());
                match rays.closest(x, dir, p) {
                    None => seen.direct = sky,
                    Some(hit) => {
                        let q = hit.patch;
                        let front = patches.normal[q].dot(dir) < 0.0;
                        if patches.is_two_sided(q) || (front && bright(q)) {
                            seen.direct = true;
                        } else if front && candidate[q] {
                            lit_fronts += usize::from(first[q]);
                            seen.direct = lit_fronts > allowed;
                            seen.fronts.push(q as u32);
                        }
                    }
                }
            }
            seen.direct =
                seen.direct || emitters.seen_from(patches, &rays, p, &mut rng, DIRECT_RAYS);
            Some(seen)
        })
        .collect();
    // Light spreads from the candidates that see it themselves to every candidate more than
    // `allowed` of whose rays meet a lit one.
    let mut seen_by: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (p, s) in seen.iter().enumerate() {
        if let Some(s) = s.as_ref().filter(|s| !s.direct) {
            for &q in &s.fronts {
                seen_by[q as usize].push(p as u32);
            }
        }
    }
    let mut lit: Vec<bool> = seen
        .iter()
        .map(|s| s.as_ref().is_none_or(|s| s.direct))
        .collect();
    let mut lit_rays = vec![0usize; n];
    let mut queue: Vec<usize> = (0..n).filter(|&p| candidate[p] && lit[p]).collect();
    while let Some(q) = queue.pop() {
        for &p in &seen_by[q] {
            let p = p as usize;
            lit_rays[p] += 1;
            if !lit[p] && lit_rays[p] > allowed {
                lit[p] = true;
                queue.push(p);
            }
        }
    }
    (0..n).map(|p| candidate[p] && !lit[p]).collect()
}

/// The emitting patches and the cumulative distribution of their power, for shadow rays.
struct Emitters {
    patch: Vec<usize>,
    cdf: Vec<f64>,
}

impl Emitters {
    fn of(patches: &Patches) -> Emitters {
        let patch: Vec<usize> = (0..patches.len())
            .filter(|&p| patches.active[p] && patches.is_emitter(p))
            .collect();
        let power: Vec<f64> = patch
            .iter()
            .map(|&e| patches.area[e] * patches.emission[e].iter().fold(0.0f64, |m, &x| m.max(x)))
            .collect();
        let total: f64 = power.iter().sum();
        let cdf = if total > 0.0 && total.is_finite() {
            power
                .iter()
                .scan(0.0, |acc, w| {
                    *acc += w / total;
                    Some(*acc)
                })
                .collect()
        } else {
            Vec::new()
        };
        Emitters { patch, cdf }
    }

    /// True when one of `count` shadow rays from points on patch `p`'s front to points on
    /// emitters (chosen by power, stratified) arrives at an emitting face.
    fn seen_from(
        &self,
        patches: &Patches,
        rays: &RayScene,
        p: usize,
        rng: &mut Rng,
        count: usize,
    ) -> bool {
        if self.cdf.is_empty() {
            return false;
        }
        (0..count).any(|i| {
            let u = (i as f64 + rng.next_f64()) / count as f64;
            let e = self.patch[self
                .cdf
                .partition_point(|&c| c < u)
                .min(self.patch.len() - 1)];
            let x = point_on_triangle(&patches.corners[p], rng.next_f64(), rng.next_f64());
            let y = point_on_triangle(&patches.corners[e], rng.next_f64(), rng.next_f64());
            let to = y - x;
            let dist = to.length();
            if !(dist > 0.0 && dist.is_finite()) {
                return false;
            }
            let dir = to / dist;
            patches.normal[p].dot(dir) > 0.0
                && (patches.is_two_sided(e) || patches.normal[e].dot(dir) < 0.0)
                && rays.visible(x, dir, dist, p, e)
        })
    }
}

/// True when a point or spot light in front of patch `p` is visible from its centroid, or the
/// sun reaches its centroid.
fn lit_by_analytic(patches: &Patches, rays: &RayScene, p: usize) -> bool {
    let (x, normal) = (patches.centroid[p], patches.normal[p]);
    patches.lights.iter().any(|light| match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } => {
            let to: DVec3 = position - x;
            let dist = to.length();
            dist > 0.0 && normal.dot(to) > 0.0 && rays.visible(x, to / dist, dist, p, p)
        }
        Light::Sun { direction, .. } => {
            normal.dot(-direction) > 0.0 && rays.closest(x, -direction, p).is_none()
        }
        Light::Sky { .. } => false,
    })
}
