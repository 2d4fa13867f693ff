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
//! A front is *lit by light* when a shadow ray from it reaches an emitter (toward points on
//! emitters chosen by power; or an analytic light shines on it), or when one of its
//! cosine-distributed rays ([`SEALED_RAYS`]) meets an emitting face or (under a sky) nothing;
//! it is *lit* when it is lit by light or when more than [`lit_rays_allowed`] of its rays meet
//! lit faces. A lit face counts only where the ray met it at a point that itself sees light:
//! a wall's end face, lit where it frames a window or a door, runs on through the lintel box
//! above the opening, on the box's own face, and the box's inside that meets it there meets no
//! light. A face lit by light counts where the point met sees an emitter (shadow rays as
//! above); a face lit only by what it sees lit counts where the point met sees one of the
//! points at which that face's own rays met light ([`LIT_POINTS_CHECKED`] of them,
//! unoccluded). Measured on that office solved two-sided (`--two-sided`), against two
//! two-sided path-traced references (2,048 spp, rms over both faces with the references' noise
//! removed): counted wherever it was met, a slow tail of 158 sweeps; checked at the point for
//! faces lit by light only, 11.1% in 30 sweeps (the door's end faces, lit by the room, lit the
//! lintel boxes above the doors, light that converged slowly in the boxes); checked at the
//! point for every lit face, 7.0% in 15 sweeps (63.5 -> 40.7 s in one batch). One-sided, the
//! MGF office, classroom and hospital floor, b90_office, the corridor and the bear in a room
//! move by at most 0.01 points from their references.
//! A face covered by a surface within [`crate::solve::cavity::COVERED_GAP`] of its size (at
//! every one of a 4 x 4 grid of points, the test of [`crate::solve::cavity`] for emitters,
//! [`crate::solve::cavity::covered`]) is sealed whatever its rays meet: it sees almost only
//! its cover, which it shades, and light reaches the gap only at its edges. Its rays count as
//! the others' do, and near its edges enough of them escape the gap to light it: the MGF
//! office's rails, 3 cm wide and 1 mm under its ceiling, solved two-sided, had the ceiling's
//! radiance on their tops, 8 times the path tracer's (half the scene's squared error).
//! The rest, once that has spread as far as it goes, are sealed: they see light through a
//! sixteenth of their (cosine-weighted) hemisphere at most, and are solved black (albedo 0;
//! they still block at their backs). A surface lit through less than that gets its emission:
//! a baseboard running through a wall slab is lit where it stands in the room, and the slab's
//! inside that sees the baseboard's hidden end is still sealed.
//!
//! The test runs in two passes so that a lit scene pays little for it: [`FIRST_RAYS`] shadow
//! rays from every candidate front find most lit ones; the others cast their cosine rays,
//! stopping once more than [`lit_rays_allowed`] meet fronts the first pass lit (at points that
//! see an emitter), and those still not lit [`DIRECT_RAYS`] more shadow rays; then the points
//! their rays met on faces the second pass lit by light are checked. On the seed room, where nothing is sealed,
//! it costs nothing measurable (0.649 against 0.633 s, medians of 9 whole-process runs
//! alternated with the build without it; in one pass of 64 shadow rays first, 0.653 against
//! 0.623 s).

//! Faces are tested, not patches: a two-sided patch's front and back each (the faces inside
//! a slab given two-sided, as MGF scenes are, look into it while their backs face the room).
//! A two-sided patch with one sealed face is solved one-sided with its lit face as its front
//! (turned around when that is its back), as `mesh/closed.rs` solves a two-sided closed
//! object, and reports 0 on the sealed face.
//!
//! Only [`crate::solve::run`] does this (the `solve` command, [`crate::solve()`]), as it turns
//! closed objects outward; the relighter, whose emission changes, solves the surfaces as given.

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::geometry::sampling::{
    cosine_direction, cumulative, interval_of, point_on_triangle, Rng,
};
use crate::mesh::Patches;
use crate::scene::lights::Light;
use crate::solve::cavity::covered;

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

/// Cosine rays the test may cast in all: the cosine rays per candidate face are this spread
/// over the candidates, at most [`SEALED_RAYS`] and at least 16 (the shadow rays are not
/// counted: the first pass's [`FIRST_RAYS`] light most faces of a lit scene).
pub const SEALED_RAY_BUDGET: usize = 4_000_000;

/// Seed of the per-patch ray streams of the first pass.
const SEED: u64 = 0x5eed_5ea1_ed00_0001;

/// Seed of the per-patch ray streams of the second pass.
const SECOND_SEED: u64 = 0x5eed_5ea1_ed00_0002;

/// Seed of the per-patch ray streams that check the points the second pass met.
const THIRD_SEED: u64 = 0x5eed_5ea1_ed00_0003;

/// How many of `rays` cosine rays may meet lit fronts with the front still sealed: a
/// sixteenth of them.
pub fn lit_rays_allowed(rays: usize) -> usize {
    rays / 16
}

/// What [`blackened`] changed: the sealed faces, and the two-sided patches turned around.
#[derive(Clone, Debug, Default)]
pub struct Sealed {
    /// Faces sealed: fronts of one-sided patches, either face of two-sided ones.
    pub faces: u64,
    /// Two-sided patches whose front was sealed and back lit: solved turned around, one-sided,
    /// so that their solved front is their back face (`Solution::restore_outward` gives each
    /// its two faces back).
    pub turned_two_sided: Vec<u32>,
}

/// These patches with every sealed face solved dark, and what changed; `None` when no face is
/// sealed. A one-sided patch with a sealed front is made black (albedo 0). A two-sided patch
/// with one sealed face becomes one-sided, its lit face its front (turned around when that is
/// its back); with both sealed, one-sided and black.
pub fn blackened(patches: &Patches) -> Option<(Patches, Sealed)> {
    let (front, back) = sealed_faces(patches);
    let faces = front.iter().chain(&back).filter(|&&s| s).count() as u64;
    if faces == 0 {
        return None;
    }
    let mut out = patches.clone();
    let mut turned_two_sided = Vec::new();
    for p in 0..patches.len() {
        let two_sided = patches.is_two_sided(p);
        match (front[p], two_sided && back[p]) {
            (false, false) => continue,
            (true, false) if two_sided => {
                out.turn_around(p);
                turned_two_sided.push(p as u32);
            }
            (false, true) => {}
            _ => out.albedo[p] = [0.0; 3],
        }
        if two_sided {
            out.two_sided[p] = false;
        }
    }
    out.forget_two_sided_if_none();
    Some((
        out,
        Sealed {
            faces,
            turned_two_sided,
        },
    ))
}

/// What one candidate face's rays found.
struct Seen {
    /// It sees light itself: a shadow ray arrived at an emitter, or a cosine ray met an
    /// emitting face (or, under a sky, nothing).
    by_light: bool,
    /// Cosine rays that met a face the first pass lit, at a point that sees an emitter.
    lit_rays: usize,
    /// Those rays' points met, with the patch met: where the face saw light.
    lit_points: Vec<(DVec3, u32)>,
    /// The other candidate faces its cosine rays met (once per ray; `sees` is set in step 3).
    faces: Vec<Met>,
}

/// Per patch: its front is sealed (see the module). All false when no patch is.
pub fn sealed_fronts(patches: &Patches) -> Vec<bool> {
    sealed_faces(patches).0
}

/// Per patch: its front is sealed, and (two-sided patches only) its back is. Face `f` of the
/// test is patch `f`'s front below `patches.len()`, patch `f - patches.len()`'s back above.
pub fn sealed_faces(patches: &Patches) -> (Vec<bool>, Vec<bool>) {
    let n = patches.len();
    let patch = |f: usize| f % n;
    let is_back = |f: usize| f >= n;
    let exists =
        |f: usize| patches.active[patch(f)] && (!is_back(f) || patches.is_two_sided(patch(f)));
    let normal = |f: usize| {
        if is_back(f) {
            -patches.normal[patch(f)]
        } else {
            patches.normal[patch(f)]
        }
    };
    let bright = |f: usize| {
        let p = patch(f);
        let source = if is_back(f) {
            &patches.source_back
        } else {
            &patches.source
        };
        patches.is_emitter(p) || source.get(p).is_some_and(|s| s.iter().any(|&x| x > 0.0))
    };
    let candidate: Vec<bool> = (0..2 * n)
        .map(|f| exists(f) && !bright(f) && patches.albedo[patch(f)].iter().any(|&a| a > 0.0))
        .collect();
    let candidates = candidate.iter().filter(|&&c| c).count();
    if candidates == 0 {
        return (vec![false; n], vec![false; n]);
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
    let rng_of = |f: usize| Rng::new(SEED, f as u64);
    // 0. Faces covered by a surface within a gap of 2% of their size see almost only it.
    let covered: Vec<bool> = (0..2 * n)
        .into_par_iter()
        .map(|f| candidate[f] && covered(patches, &rays, patch(f), normal(f)))
        .collect();
    // 1. Most lit faces see a light at their first shadow rays.
    let first: Vec<bool> = (0..2 * n)
        .into_par_iter()
        .map(|f| {
            candidate[f]
                && !covered[f]
                && (lit_by_analytic(patches, &rays, patch(f), normal(f))
                    || emitters.seen_from(
                        patches,
                        &rays,
                        (patch(f), normal(f)),
                        &mut rng_of(f),
                        FIRST_RAYS,
                    ))
        })
        .collect();
    // 2. The others cast their cosine rays (a face that sees more than `allowed` of those
    //    already lit is lit, and stops), then the rest of their shadow rays.
    let mut seen: Vec<Option<Seen>> = (0..2 * n)
        .into_par_iter()
        .map(|f| {
            if !candidate[f] {
                return None;
            }
            let mut seen = Seen {
                by_light: first[f],
                lit_rays: 0,
                lit_points: Vec::new(),
                faces: Vec::new(),
            };
            if covered[f] {
                return Some(seen);
            }
            let mut rng = Rng::new(SECOND_SEED, f as u64);
            let (p, normal_f) = (patch(f), normal(f));
            let tri = &patches.corners[p];
            let cell = 1.0 / k as f64;
            for i in 0..k * k {
                if seen.by_light || seen.lit_rays > allowed {
                    return Some(seen);
                }
                let (a, b) = ((i % k) as f64, (i / k) as f64);
                let x = point_on_triangle(
                    tri,
                    ((a + rng.next_f64()) * cell).min(1.0),
                    ((b + rng.next_f64()) * cell).min(1.0),
                );
                let dir = cosine_direction(normal_f, rng.next_f64(), rng.next_f64());
                let Some(hit) = rays.closest(x, dir, p) else {
                    seen.by_light = sky;
                    continue;
                };
                // The face of the patch hit that looks back along the ray.
                let g = if patches.normal[hit.patch].dot(dir) < 0.0 {
                    hit.patch
                } else {
                    hit.patch + n
                };
                if exists(g) && bright(g) {
                    seen.by_light = true;
                } else if candidate[g] && first[g] {
                    // A face lit by light it sees itself counts where the ray met it: at a
                    // point that sees an emitter, checked as the first pass checks a face.
                    if emitters.seen_from_point(
                        patches,
                        &rays,
                        (hit.point, normal(g), hit.patch),
                        &mut rng,
                        FIRST_RAYS,
                    ) {
                        seen.lit_rays += 1;
                        seen.lit_points.push((hit.point, hit.patch as u32));
                    }
                } else if candidate[g] {
                    seen.faces.push(Met {
                        face: g as u32,
                        sees: false,
                        point: hit.point,
                        patch: hit.patch as u32,
                    });
                }
            }
            seen.by_light = seen.by_light
                || emitters.seen_from(patches, &rays, (p, normal_f), &mut rng, DIRECT_RAYS);
            Some(seen)
        })
        .collect();
    let by_light: Vec<bool> = seen
        .iter()
        .map(|s| s.as_ref().is_some_and(|s| s.by_light))
        .collect();
    // 3. The points the cosine rays met on faces lit by light they see themselves, now that
    //    those are known: whether each point sees an emitter.
    let met: Vec<Vec<Met>> = seen
        .par_iter()
        .enumerate()
        .map(|(f, s)| {
            let Some(s) = s.as_ref().filter(|s| !s.by_light && s.lit_rays <= allowed) else {
                return Vec::new();
            };
            let mut rng = Rng::new(THIRD_SEED, f as u64);
            // Once more than `allowed` points seen count, the face is lit whatever the rest
            // are (those faces are lit from the start of 4.): the rest are not checked.
            let mut counted = s.lit_rays;
            let mut hits = Vec::with_capacity(s.faces.len());
            for hit in &s.faces {
                if counted > allowed {
                    break;
                }
                let sees = by_light[hit.face as usize]
                    && emitters.seen_from_point(
                        patches,
                        &rays,
                        (hit.point, normal(hit.face as usize), hit.patch as usize),
                        &mut rng,
                        FIRST_RAYS,
                    );
                counted += usize::from(sees);
                hits.push(Met { sees, ..*hit });
            }
            hits
        })
        .collect();
    // 4. Light spreads from the candidates lit to every candidate more than `allowed` of whose
    //    rays meet a lit one: a face lit by light it sees itself where it was met at a point
    //    that sees an emitter, a face lit only by what it sees lit where it was met at a point
    //    that sees one of the points where its own rays met light (`sees_lit_point`).
    let mut seen_by: Vec<Vec<(u32, Met)>> = vec![Vec::new(); 2 * n];
    for (f, hits) in met.iter().enumerate() {
        for hit in hits {
            seen_by[hit.face as usize].push((f as u32, *hit));
        }
    }
    let mut lit_rays: Vec<usize> = seen
        .iter()
        .map(|s| s.as_ref().map_or(0, |s| s.lit_rays))
        .collect();
    // Per face, the points where its rays met light (step 2, then as light spreads).
    let mut lit_points: Vec<Vec<(DVec3, u32)>> = seen
        .iter_mut()
        .map(|s| {
            s.as_mut()
                .map_or(Vec::new(), |s| std::mem::take(&mut s.lit_points))
        })
        .collect();
    for (f, hits) in met.iter().enumerate() {
        for hit in hits.iter().filter(|h| h.sees) {
            lit_points[f].push((hit.point, hit.patch));
        }
    }
    let mut lit: Vec<bool> = seen
        .iter()
        .map(|s| {
            s.as_ref()
                .is_none_or(|s| s.by_light || s.lit_rays > allowed)
        })
        .collect();
    let mut queue: Vec<usize> = (0..2 * n).filter(|&f| candidate[f] && lit[f]).collect();
    while let Some(g) = queue.pop() {
        for &(f, hit) in &seen_by[g] {
            let f = f as usize;
            let counts = if by_light[g] {
                hit.sees
            } else {
                // Checked only while `f` is not lit: once it is, its count no longer matters.
                !lit[f] && sees_lit_point(&rays, (hit.point, normal(g), patch(g)), &lit_points[g])
            };
            if counts {
                lit_rays[f] += 1;
                if !hit.sees {
                    lit_points[f].push((hit.point, hit.patch));
                }
            }
            if !lit[f] && !covered[f] && lit_rays[f] > allowed {
                lit[f] = true;
                queue.push(f);
            }
        }
    }
    let sealed = |f: usize| candidate[f] && !lit[f];
    (
        (0..n).map(sealed).collect(),
        (n..2 * n).map(sealed).collect(),
    )
}

/// One cosine ray of a candidate face that met another candidate face (steps 3 and 4 of
/// [`sealed_faces`]).
#[derive(Clone, Copy, Debug)]
struct Met {
    /// The face met.
    face: u32,
    /// The point met sees an emitter (checked only on faces lit by light).
    sees: bool,
    /// The point met, and the patch it lies on.
    point: DVec3,
    patch: u32,
}

/// Most of the points where a face lit only by what it sees lit met light that a point met on
/// it is checked against (the first ones found; one visible is enough). A face is lit once
/// more than [`lit_rays_allowed`] of its rays met light, so it has at least that many.
pub const LIT_POINTS_CHECKED: usize = 8;

/// True when point `x` on patch `p`'s face of unit `normal` sees one of `lit` (the first
/// [`LIT_POINTS_CHECKED`]: points where that face's own rays met light, each with the patch
/// it lies on) in front of the face, unoccluded. A face lit only by what it sees lit is lit
/// where it sees that: a wall's end face that frames a door, lit by the room through the
/// opening, runs on through the lintel box above the door, and where a ray from inside the
/// box meets it, it sees only the box.
fn sees_lit_point(
    rays: &RayScene,
    (x, normal, p): (DVec3, DVec3, usize),
    lit: &[(DVec3, u32)],
) -> bool {
    (lit.iter().take(LIT_POINTS_CHECKED))
        .any(|&(y, q)| sees_point(rays, (x, normal, p), (y, q as usize), |_| true))
}

/// True when point `y` on patch `q` lies in front of the face of unit `normal` at point `x` on
/// patch `p`, `facing` holds for the unit direction from `x` to `y`, and nothing lies between
/// them.
fn sees_point(
    rays: &RayScene,
    (x, normal, p): (DVec3, DVec3, usize),
    (y, q): (DVec3, usize),
    facing: impl FnOnce(DVec3) -> bool,
) -> bool {
    let to = y - x;
    let dist = to.length();
    if !(dist > 0.0 && dist.is_finite()) {
        return false;
    }
    let dir = to / dist;
    normal.dot(dir) > 0.0 && facing(dir) && rays.visible(x, dir, dist, p, q)
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
            cumulative(power.into_iter())
        } else {
            Vec::new()
        };
        Emitters { patch, cdf }
    }

    /// True when one of `count` shadow rays from points on patch `p`, leaving its face of
    /// unit `normal`, to points on emitters (chosen by power, stratified) arrives at an
    /// emitting face.
    fn seen_from(
        &self,
        patches: &Patches,
        rays: &RayScene,
        (p, normal): (usize, DVec3),
        rng: &mut Rng,
        count: usize,
    ) -> bool {
        if self.cdf.is_empty() {
            return false;
        }
        (0..count).any(|i| {
            let x = point_on_triangle(&patches.corners[p], rng.next_f64(), rng.next_f64());
            self.ray_arrives(patches, rays, (x, normal, p), rng, (i, count))
        })
    }

    /// [`Emitters::seen_from`] from the one point `x` on patch `p`'s face of unit `normal`.
    fn seen_from_point(
        &self,
        patches: &Patches,
        rays: &RayScene,
        (x, normal, p): (DVec3, DVec3, usize),
        rng: &mut Rng,
        count: usize,
    ) -> bool {
        !self.cdf.is_empty()
            && (0..count).any(|i| self.ray_arrives(patches, rays, (x, normal, p), rng, (i, count)))
    }

    /// True when the `i`-th of `count` stratified shadow rays from point `x` on patch `p`'s
    /// face of unit `normal`, to a point on an emitter chosen by power, arrives at an emitting
    /// face. Requires at least one emitter.
    fn ray_arrives(
        &self,
        patches: &Patches,
        rays: &RayScene,
        (x, normal, p): (DVec3, DVec3, usize),
        rng: &mut Rng,
        (i, count): (usize, usize),
    ) -> bool {
        let u = (i as f64 + rng.next_f64()) / count as f64;
        let e = self.patch[interval_of(&self.cdf, u)];
        let y = point_on_triangle(&patches.corners[e], rng.next_f64(), rng.next_f64());
        sees_point(rays, (x, normal, p), (y, e), |dir| {
            patches.is_two_sided(e) || patches.normal[e].dot(dir) < 0.0
        })
    }
}

/// True when a point or spot light in front of patch `p`'s face of unit `normal` is visible
/// from its centroid, or the sun reaches its centroid through that face.
fn lit_by_analytic(patches: &Patches, rays: &RayScene, p: usize, normal: DVec3) -> bool {
    let x = patches.centroid[p];
    patches.lights.iter().any(|light| match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } => {
            sees_point(rays, (x, normal, p), (position, p), |_| true)
        }
        Light::Sun { direction, .. } => {
            normal.dot(-direction) > 0.0 && rays.closest(x, -direction, p).is_none()
        }
        Light::Sky { .. } => false,
    })
}
