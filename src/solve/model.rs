//! What a scene requires the solver to model: the hierarchical solver pays only for
//! what a scene needs.
//!
//! - **Channels**: a grey scene (every albedo and every source radiance has equal R, G and B)
//!   is solved in one channel and expanded to RGB at the end; others in three.
//! - **Antiradiance**: a convex enclosure (every element lies on or in front of every other
//!   element's plane) has no occlusion at all, so antiradiance would carry nothing: it is solved
//!   as plain radiosity, with no antiradiance bins stored.
//! - **Bins**: an element stores only the antiradiance bins some link both writes into it and
//!   reads from it (see `LiveBins` in [`crate::solve::hierarchical`]); with one-sided surfaces that is
//!   at most the back hemisphere, and only the directions that lead to a receiver.
//!
//! What was decided is reported per solve in [`ModelStats`] (the JSON report's `stats.model`).

use std::sync::atomic::{AtomicU8, Ordering};

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::{Hit, RayScene};
use crate::geometry::sampling::{cosine_direction, point_on_triangle, Rng};
use crate::geometry::{Lanes, LANES};
use crate::hierarchy::ClusterTree;
use crate::mesh::Patches;
pub use crate::solve::solution::ModelStats;

/// Shadow-ray budget of [`exposed_backs`]: rays per patch are this over the patch count,
/// between [`BACK_RAYS_MIN`] and [`BACK_RAYS_MAX`].
pub const BACK_RAY_BUDGET: usize = 2_000_000;
/// Fewest rays per patch of [`exposed_backs`].
pub const BACK_RAYS_MIN: usize = 4;
/// Most rays per patch of [`exposed_backs`].
pub const BACK_RAYS_MAX: usize = 16;
/// Share of a patch's back rays meeting a surface that must meet a front for its back to
/// count as exposed.
pub const EXPOSED_SHARE: f64 = 0.25;

/// How far behind a patch's plane a back ray's hit must lie, in [`crate::geometry::SCENE_EPS`],
/// to count in [`exposed_backs`] (its rays start `2 SCENE_EPS` in front of the plane, and can
/// meet a neighbour sharing the patch's edge before they cross it).
const BEHIND_HIT: f64 = 4.0;

/// How far behind a patch's plane (unit frame) the scene's box may reach with the patch still
/// taken as having nothing behind it ([`exposed_backs`]): rounding only.
const BEHIND_NOTHING: f64 = 1e-12;

/// Per patch: true when light can reach its back, so that it must block light arriving there
/// (antiradiance from its back as well as its front).
///
/// Front-only antiradiance is exact for closed, consistently oriented objects: light reaching
/// a back has passed through a front first, whose antiradiance cancels it. Files as found are
/// not like that: walls exported facing away from the room, open sheets (a seat, a table top
/// of one polygon), blinds. Their backs are lit directly, and without blocking there light
/// leaks through them. The test is geometric, so it needs no consistent topology: from
/// stratified points on the patch, cosine-distributed rays into its back hemisphere (from
/// `2 SCENE_EPS` in front of it; only what they meet behind its plane counts, not a neighbour
/// sharing its edge met before they cross it: the caps of a thin tube, whose rays met the
/// tube's sides at the rim, were found exposed; without them b90_office blocks at 4,093
/// patches instead of 7,221, 31.2M links instead of 33.1M); a patch with a back-to-back twin
/// (the same corners in reverse order) is not exposed: the twin's front covers its back;
/// the back is exposed when at least [`EXPOSED_SHARE`] of those that meet a surface first meet
/// the front of another (they see open space that light crosses), not when they meet backs
/// (the inside of a closed object, or a twin) or all leave the scene (the outside of a room
/// shell). A patch with the whole scene's box on or in front of its plane has nothing behind
/// it and is not exposed, without rays (the walls of a room shell; their back rays, started
/// just in front of them, could meet a coplanar neighbour's front where they cross the plane
/// and count it). A front that is itself dark (`DarkFronts`: every ray from it meets a
/// back, as the floor under a box standing open-bottomed on it) does not count: such a box's
/// backs see no light. Without that test the subdivided Cornell box's blocks were found exposed
/// (37,753 of its 258,750 patches blocking at their backs, against 3,298 with it: 4.59M ->
/// 4.31M links, 8 -> 10 sweeps, 8.44 -> 8.59 s, 2.77% -> 2.74% rms from its path-traced
/// references; the 1M-triangle box 226,734 -> 72,569); b90_office 10,267 -> 7,221 blocking
/// patches, 36.3M -> 33.1M links, peak 3.65 -> 3.31 GB, 1.56% -> 1.52% (bias -0.91% ->
/// -0.85%) from its reference. Where the floor under the box is one patch with
/// the floor around it (the 46-triangle Cornell box), the false positive stays: it costs
/// two-sided bins, not light.
///
/// A two-sided patch's back is also exposed where light reaches it across other two-sided
/// surfaces (`two_sided_exposed`).
pub fn exposed_backs(patches: &Patches) -> Vec<bool> {
    let twinned = back_to_back_twins(patches);
    let scene = RayScene::of(patches);
    // The box of every active patch: a patch with all of it on or in front of its plane has
    // nothing behind it for a back ray to meet (the walls of a room shell, of the 1M-triangle
    // box 90% of its patches and 4M rays).
    let (lo, hi) = (0..patches.len())
        .filter(|&p| patches.active[p])
        .flat_map(|p| patches.corners[p])
        .fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), v| (lo.min(v), hi.max(v)),
        );
    let box_corners: [DVec3; 8] = std::array::from_fn(|i| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    });
    let nothing_behind = |p: usize| {
        let (tri, n) = (&patches.corners[p], patches.normal[p]);
        box_corners
            .iter()
            .all(|&c| n.dot(c - tri[0]) >= -BEHIND_NOTHING)
    };
    let candidates: Vec<bool> = (0..patches.len())
        .into_par_iter()
        .map(|p| patches.active[p] && !twinned[p] && !nothing_behind(p))
        .collect();
    // Hits on fronts that are not dark (`DarkFronts`: the floor under an open-bottomed box)
    // first; then, for two-sided patches still unexposed, light arriving across other
    // two-sided surfaces ([`two_sided_exposed`]).
    let dark = DarkFronts::new(patches, &scene);
    let lit_front =
        |hit: usize, dir: DVec3| patches.normal[hit].dot(dir) < 0.0 && !dark.is_dark(hit);
    let mut exposed = exposed_where(patches, &scene, &candidates, lit_front);
    if patches.has_two_sided() {
        two_sided_exposed(patches, &scene, &candidates, &lit_front, &mut exposed);
    }
    exposed
}

/// Which fronts are dark, decided on demand and remembered: a one-sided patch that neither
/// emits nor has an analytic source, all of whose [`BACK_RAYS_MAX`] cosine-distributed rays from
/// its front meet the back of a one-sided patch that does not emit. Light reaches such a front
/// only through those backs: the floor under a box standing open-bottomed on it, the ground
/// under a closed cabinet. A back that sees such fronts sees no light there. (Whatever a ray
/// meets first decides; one ray that leaves the scene or meets a front, an emitter or a
/// two-sided patch makes the front lit.) Each patch's rays have their own seed, so the answer
/// does not depend on which thread asks first.
struct DarkFronts<'a> {
    patches: &'a Patches,
    scene: &'a RayScene<'a>,
    /// Per patch: [`UNKNOWN`], [`LIT`] or [`DARK`].
    state: Vec<AtomicU8>,
}

/// [`DarkFronts`]: not yet decided.
const UNKNOWN: u8 = 0;
/// [`DarkFronts`]: lit.
const LIT: u8 = 1;
/// [`DarkFronts`]: dark.
const DARK: u8 = 2;

impl<'a> DarkFronts<'a> {
    fn new(patches: &'a Patches, scene: &'a RayScene<'a>) -> DarkFronts<'a> {
        DarkFronts {
            patches,
            scene,
            state: (0..patches.len()).map(|_| AtomicU8::new(UNKNOWN)).collect(),
        }
    }

    /// True when patch `p`'s front is dark (see [`DarkFronts`]).
    fn is_dark(&self, p: usize) -> bool {
        match self.state[p].load(Ordering::Relaxed) {
            UNKNOWN => {
                let dark = self.test(p);
                self.state[p].store(if dark { DARK } else { LIT }, Ordering::Relaxed);
                dark
            }
            known => known == DARK,
        }
    }

    /// A one-sided patch that neither emits nor has an analytic source.
    fn unlit(&self, p: usize) -> bool {
        let patches = self.patches;
        !patches.is_emitter(p)
            && !patches.is_two_sided(p)
            && patches
                .source
                .get(p)
                .is_none_or(|s| s.iter().all(|&x| x <= 0.0))
    }

    /// The rays of [`DarkFronts`] from patch `p`'s front.
    fn test(&self, p: usize) -> bool {
        let patches = self.patches;
        if !patches.active[p] || !self.unlit(p) {
            return false;
        }
        let side = (BACK_RAYS_MAX as f64).sqrt().ceil() as usize;
        let (tri, n) = (&patches.corners[p], patches.normal[p]);
        let mut rng = Rng::new(0x6461_726b, p as u64);
        (0..BACK_RAYS_MAX).all(|k| {
            let (org, dir) = stratified_ray(tri, n, n, (k, side), &mut rng);
            self.scene.closest(org, dir, p).is_some_and(|hit| {
                patches.normal[hit.patch].dot(dir) > 0.0 && self.unlit(hit.patch)
            })
        })
    }
}

/// Ray `k` of a patch's test rays (triangle `tri`, normal `n`): from a point stratified over
/// the triangle (a `side` x `side` grid of its unit square), `2 SCENE_EPS` in front of it,
/// cosine-distributed about `axis` (`n` into its front, `-n` into its back).
fn stratified_ray(
    tri: &[DVec3; 3],
    n: DVec3,
    axis: DVec3,
    (k, side): (usize, usize),
    rng: &mut Rng,
) -> (DVec3, DVec3) {
    let (i, j) = ((k % side) as f64, (k / side % side) as f64);
    let u1 = (i + rng.next_f64()) / side as f64;
    let u2 = (j + rng.next_f64()) / side as f64;
    let org = point_on_triangle(tri, u1, u2) + n * (2.0 * crate::geometry::SCENE_EPS);
    let dir = cosine_direction(axis, rng.next_f64(), rng.next_f64());
    (org, dir)
}

/// The second step of [`exposed_backs`] for the two-sided candidates it left unexposed: such a
/// back is exposed when one of its rays meets an emitter's front (direct light reaches it), or
/// when at least [`EXPOSED_SHARE`] of those that meet a surface meet a lit front or a
/// two-sided patch whose back is exposed (an emitter's back too: it emits only where its back
/// face exists), repeated until no more backs are found (the rays are traced once); the inside
/// of a closed object, whose rays meet only its own backs, stays unexposed (closed objects are
/// turned to face out before this test, `mesh::closed`; the inside of a closed tube light was
/// once reached from caps whose backs the first step found exposed, and, filled with its own
/// light, took the generated classroom's two-sided solve 9% off). A two-sided room whose walls
/// face out sees only their backs from inside: the backs that see its light are found first,
/// and the light spreads from them. Counting only backs found by the first step, none was,
/// and the room came out black (`two_sided_room_facing_out_is_lit_inside` in
/// `tests/two_sided.rs`); counting every two-sided patch met, whether lit or not, b90_office's
/// two-sided solve diverged.
fn two_sided_exposed(
    patches: &Patches,
    scene: &RayScene,
    candidates: &[bool],
    lit_front: &(impl Fn(usize, DVec3) -> bool + Sync),
    exposed: &mut [bool],
) {
    let back_rays = BackRays::of(patches);
    let emits_toward =
        |hit: usize, dir: DVec3| patches.is_emitter(hit) && patches.normal[hit].dot(dir) < 0.0;
    // Per open candidate: whether a ray met an emitting face, and the patches its rays met
    // with whether each met a lit front.
    type Met = (bool, Vec<(u32, bool)>);
    let open: Vec<usize> = (0..patches.len())
        .filter(|&p| candidates[p] && !exposed[p] && patches.is_two_sided(p))
        .collect();
    let met: Vec<Met> = open
        .par_iter()
        .map(|&p| {
            let mut hits = Vec::with_capacity(back_rays.rays);
            for (dir, hit) in back_rays.traced(patches, scene, p) {
                if let Some(hit) = hit {
                    if emits_toward(hit.patch, dir) {
                        return (true, Vec::new());
                    }
                    hits.push((hit.patch as u32, lit_front(hit.patch, dir)));
                }
            }
            (false, hits)
        })
        .collect();
    let mut changed = true;
    while changed {
        changed = false;
        for (&p, (direct, hits)) in open.iter().zip(&met) {
            if exposed[p] {
                continue;
            }
            let lit = hits
                .iter()
                .filter(|&&(hit, front)| {
                    front || (patches.is_two_sided(hit as usize) && exposed[hit as usize])
                })
                .count();
            if *direct || (lit > 0 && lit as f64 >= EXPOSED_SHARE * hits.len() as f64) {
                exposed[p] = true;
                changed = true;
            }
        }
    }
}

/// The back rays of [`exposed_backs`]: per patch, `rays` cosine-distributed rays into its back
/// from stratified points (see `stratified_ray`), the same for every step of the test.
struct BackRays {
    /// Rays per patch: [`BACK_RAY_BUDGET`] over the active patches, between [`BACK_RAYS_MIN`]
    /// and [`BACK_RAYS_MAX`].
    rays: usize,
    /// Side of the grid the ray origins are stratified on.
    side: usize,
}

impl BackRays {
    fn of(patches: &Patches) -> BackRays {
        let active = patches.active_count().max(1);
        let rays = (BACK_RAY_BUDGET / active).clamp(BACK_RAYS_MIN, BACK_RAYS_MAX);
        BackRays {
            rays,
            side: (rays as f64).sqrt().ceil() as usize,
        }
    }

    /// Patch `p`'s rays in order, each as its direction and what it meets behind the patch's
    /// plane (by [`BEHIND_HIT`]): a ray started in front of the patch can meet a neighbour
    /// sharing its edge before it crosses the plane (the caps and sides of a thin tube), which
    /// does not count.
    fn traced<'s>(
        &self,
        patches: &'s Patches,
        scene: &'s RayScene,
        p: usize,
    ) -> impl Iterator<Item = (DVec3, Option<Hit>)> + 's {
        let (tri, n) = (patches.corners[p], patches.normal[p]);
        let mut rng = Rng::new(0x6261_636b, p as u64);
        let side = self.side;
        (0..self.rays).map(move |k| {
            let (org, dir) = stratified_ray(&tri, n, -n, (k, side), &mut rng);
            let behind = |x: DVec3| n.dot(x - tri[0]) < -BEHIND_HIT * crate::geometry::SCENE_EPS;
            (
                dir,
                scene.closest(org, dir, p).filter(|hit| behind(hit.point)),
            )
        })
    }
}

/// [`exposed_backs`]'s ray test for the patches marked in `candidates` (false for the others),
/// `lit(hit, dir)` telling whether a back ray in direction `dir` met a lit face of patch `hit`.
fn exposed_where(
    patches: &Patches,
    scene: &RayScene,
    candidates: &[bool],
    lit: impl Fn(usize, DVec3) -> bool + Sync,
) -> Vec<bool> {
    let back_rays = BackRays::of(patches);
    let rays = back_rays.rays;
    (0..patches.len())
        .into_par_iter()
        .map(|p| {
            if !candidates[p] {
                return false;
            }
            let (mut fronts, mut hits) = (0usize, 0usize);
            for (k, (dir, hit)) in back_rays.traced(patches, scene, p).enumerate() {
                if let Some(hit) = hit {
                    hits += 1;
                    if lit(hit.patch, dir) {
                        fronts += 1;
                    }
                }
                // Stop once the remaining rays cannot change the answer: the fronts already
                // make the share of every ray, or would miss it even if all the rest met fronts.
                let rest = (rays - k - 1) as f64;
                if fronts > 0 && fronts as f64 >= EXPOSED_SHARE * rays as f64 {
                    return true;
                }
                if (fronts as f64 + rest) < EXPOSED_SHARE * (hits as f64 + rest) {
                    return false;
                }
            }
            fronts > 0 && fronts as f64 >= EXPOSED_SHARE * hits as f64
        })
        .collect()
}

/// Per patch: another active patch has its corners in the reverse order (on a grid of
/// [`crate::geometry::SCENE_EPS`]), a back-to-back twin that covers its back. Such pairs are a
/// two-sided surface given as two one-sided ones: each one's back is the other's front.
fn back_to_back_twins(patches: &Patches) -> Vec<bool> {
    let key = |tri: [DVec3; 3]| {
        let q = |v: DVec3| {
            (v / crate::geometry::SCENE_EPS)
                .round()
                .to_array()
                .map(|x| x as i64)
        };
        // Rotated so the smallest corner comes first: the same cycle gives the same key.
        let c = tri.map(q);
        let k = (0..3).min_by_key(|&i| c[i]).unwrap_or(0);
        [c[k], c[(k + 1) % 3], c[(k + 2) % 3]]
    };
    // Sorted keys and binary searches (in parallel; a hash map of 1M keys took 0.9 s).
    let mut seen: Vec<[[i64; 3]; 3]> = (0..patches.len())
        .into_par_iter()
        .filter(|&p| patches.active[p])
        .map(|p| key(patches.corners[p]))
        .collect();
    seen.par_sort_unstable();
    (0..patches.len())
        .into_par_iter()
        .map(|p| {
            let [a, b, c] = patches.corners[p];
            patches.active[p] && seen.binary_search(&key([a, c, b])).is_ok()
        })
        .collect()
}

/// Per patch: it blocks light arriving at its back ([`Backs::blocking`]). Shared by both
/// solvers.
pub fn back_blocking(patches: &Patches, options: &crate::solve::SolverOptions) -> Vec<bool> {
    Backs::of(patches, options).blocking
}

/// What the solvers model at the patches' backs.
#[derive(Clone, Debug)]
pub struct Backs {
    /// Per patch: it blocks light arriving at its back. [`exposed_backs`] when
    /// `options.block_exposed_backs` (and antiradiance is on), every patch when
    /// `options.two_sided`, none otherwise; and every patch with a back face.
    pub blocking: Vec<bool>,
    /// Per patch: a two-sided patch ([`Patches::two_sided`]) whose back face is solved: its
    /// back is exposed to light ([`exposed_backs`], or an analytic light shines on it, see
    /// [`lit_from_behind`]). The back face of a two-sided patch that no light can reach (a
    /// wall's outside, the inside of a closed object) costs nothing: it reflects nothing, and
    /// an emitting one's light reaches only what its shadow rays find (exact direct light;
    /// the inside of a closed emitting tube, which traps it).
    /// Every two-sided patch when `options.block_exposed_backs` is off or antiradiance is.
    pub faces: Vec<bool>,
}

impl Backs {
    /// The backs of `patches` under `options` (one [`exposed_backs`] test for both).
    pub fn of(patches: &Patches, options: &crate::solve::SolverOptions) -> Backs {
        let n = patches.len();
        let test = options.antiradiance && options.block_exposed_backs && !options.two_sided;
        let exposed = if test {
            exposed_backs(patches)
        } else {
            vec![false; n]
        };
        let faces: Vec<bool> = (0..n)
            .map(|p| {
                patches.is_two_sided(p) && (!test || exposed[p] || lit_from_behind(patches, p))
            })
            .collect();
        let blocking = (0..n)
            .map(|p| {
                options.antiradiance
                    && (options.two_sided || (exposed[p] && !patches.is_two_sided(p)) || faces[p])
            })
            .collect();
        Backs { blocking, faces }
    }
}

/// True when an analytic light of `patches` can shine on patch `p`'s back: a point or spot
/// light behind its plane, a sun whose light travels into its back, or a sky.
pub fn lit_from_behind(patches: &Patches, p: usize) -> bool {
    use crate::scene::lights::Light;
    let (n, x) = (patches.normal[p], patches.corners[p][0]);
    patches.lights.iter().any(|light| match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } => n.dot(position - x) < 0.0,
        Light::Sun { direction, .. } => n.dot(direction) > 0.0,
        Light::Sky { .. } => true,
    })
}

pub use crate::geometry::tolerances::CONVEX_TOLERANCE;

/// True when `rgb` is grey: its three channels equal up to a relative
/// [`crate::geometry::tolerances::GREY_RELATIVE`].
pub fn is_grey(rgb: [f64; 3]) -> bool {
    let scale = rgb[0].abs().max(rgb[1].abs()).max(rgb[2].abs());
    let tol = crate::geometry::tolerances::GREY_RELATIVE * scale;
    (rgb[0] - rgb[1]).abs() <= tol && (rgb[0] - rgb[2]).abs() <= tol
}

/// True when every element of a finalized tree lies on or in front of the plane of every other
/// element (within [`CONVEX_TOLERANCE`]): the elements bound a convex region from inside (or
/// part of its boundary), so no element can block the light between two others.
///
/// Each distinct plane is tested against the tree: a node whose bounding box lies wholly in front
/// of the plane is accepted without visiting its elements, so a convex scene costs about
/// (distinct planes) x (nodes near each plane), and a non-convex one usually stops at its first
/// plane. Elements without a plane (degenerate) make the scene non-convex.
pub fn is_convex_enclosure(tree: &ClusterTree) -> bool {
    if tree.elements.is_empty() {
        return false;
    }
    let mut element_planes = Vec::with_capacity(tree.elements.len());
    for &node in &tree.elements {
        let Some(plane) = tree.nodes[node as usize].plane else {
            return false;
        };
        element_planes.push(plane);
    }
    let planes = distinct_planes(element_planes);
    planes.par_iter().all(|&(n, d)| all_in_front(tree, n, d))
}

/// The distinct planes (normal, offset) of `planes`, in first-seen order, deduplicated on a
/// grid of 1e-9: the planes the convexity tests check.
fn distinct_planes(planes: impl IntoIterator<Item = (DVec3, f64)>) -> Vec<(DVec3, f64)> {
    let mut seen = std::collections::HashSet::new();
    planes
        .into_iter()
        .filter(|&(n, d)| seen.insert([n.x, n.y, n.z, d].map(|x| (x * 1e9).round() as i64)))
        .collect()
}

/// [`is_convex_enclosure`] over patches rather than a tree (the dense solver's test): true when
/// every active patch lies on or in front of the plane of every other (within
/// [`CONVEX_TOLERANCE`]). Each distinct plane is tested against every corner, so a convex scene
/// costs (distinct planes) x (patches) and a non-convex one usually stops at its first plane.
pub fn patches_convex(patches: &crate::mesh::Patches) -> bool {
    let active: Vec<usize> = (0..patches.len()).filter(|&p| patches.active[p]).collect();
    if active.is_empty() {
        return false;
    }
    let planes = distinct_planes(active.iter().map(|&p| {
        let n = patches.normal[p];
        (n, n.dot(patches.corners[p][0]))
    }));
    planes.par_iter().all(|&(n, d)| {
        active.iter().all(|&p| {
            patches.corners[p]
                .iter()
                .all(|c| n.dot(*c) - d >= -CONVEX_TOLERANCE)
        })
    })
}

/// True when every element corner below the root lies at signed distance >= -tolerance from the
/// plane `n . x = d`.
fn all_in_front(tree: &ClusterTree, n: DVec3, d: f64) -> bool {
    let mut stack = vec![0u32];
    while let Some(i) = stack.pop() {
        let node = &tree.nodes[i as usize];
        // Lowest signed distance over the node's bounding box.
        let (lo, hi) = node.bounds;
        let center = 0.5 * (lo + hi);
        let half = 0.5 * (hi - lo);
        let lowest = n.dot(center) - d - n.abs().dot(half);
        if lowest >= -CONVEX_TOLERANCE {
            continue;
        }
        if node.is_leaf() {
            if node
                .corners
                .iter()
                .any(|c| n.dot(*c) - d < -CONVEX_TOLERANCE)
            {
                return false;
            }
        } else {
            stack.extend(node.first_child..node.first_child + node.child_count as u32);
        }
    }
    true
}

/// The emitting patches of [`light_factors`], [`LANES`] to a chunk, field by field (the
/// last chunk padded with emitters of area 0, which add nothing).
struct EmitterLanes {
    /// Per chunk: centroid, normal (x, y, z lanes each), area, emission (RGB lanes) and the
    /// two-sided mask.
    chunks: Vec<EmitterChunk>,
}

struct EmitterChunk {
    centroid: [Lanes; 3],
    normal: [Lanes; 3],
    area: Lanes,
    emission: [Lanes; 3],
    two_sided: Lanes,
}

impl EmitterLanes {
    fn of(patches: &Patches, emitters: &[usize]) -> EmitterLanes {
        let chunks = emitters
            .chunks(LANES)
            .map(|chunk| {
                let lane = |f: &dyn Fn(usize) -> f64| {
                    Lanes::new(std::array::from_fn(|l| chunk.get(l).map_or(0.0, |&e| f(e))))
                };
                let axes =
                    |f: &dyn Fn(usize) -> DVec3| [0, 1, 2].map(|k| lane(&|e| f(e).to_array()[k]));
                EmitterChunk {
                    centroid: axes(&|e| patches.centroid[e]),
                    normal: axes(&|e| patches.normal[e]),
                    area: lane(&|e| patches.area[e]),
                    emission: [0, 1, 2].map(|c| lane(&|e| patches.emission[e][c])),
                    two_sided: lane(&|e| f64::from(u8::from(patches.is_two_sided(e)))),
                }
            })
            .collect();
        EmitterLanes { chunks }
    }

    /// `sum_e E_e F_e` at `x` (normal `n_x`), RGB: each emitter's point form factor
    /// `A_e cos cos / (pi d^2 + A_e)` from its centroid, unoccluded (0 when either side
    /// faces away; a two-sided emitter faces both ways).
    fn light_at(&self, x: DVec3, n_x: DVec3) -> [f64; 3] {
        let zero = Lanes::ZERO;
        let mut sum = [zero; 3];
        for chunk in &self.chunks {
            let v = [0, 1, 2].map(|k| chunk.centroid[k] - Lanes::splat(x.to_array()[k]));
            let d2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            let d = d2.sqrt();
            let cos_x = (v[0] * n_x.x + v[1] * n_x.y + v[2] * n_x.z) / d;
            let cos_e =
                -(v[0] * chunk.normal[0] + v[1] * chunk.normal[1] + v[2] * chunk.normal[2]) / d;
            let cos_e = chunk.two_sided.simd_gt(zero).select(cos_e.abs(), cos_e);
            let lit = d2.simd_gt(zero) & cos_x.simd_gt(zero) & cos_e.simd_gt(zero);
            let f = chunk.area * cos_x * cos_e / (d2 * std::f64::consts::PI + chunk.area);
            let f = lit.select(f, zero);
            for (s, e) in sum.iter_mut().zip(&chunk.emission) {
                *s += *e * f;
            }
        }
        sum.map(|s| s.reduce_add())
    }
}

/// Most receiver-emitter terms [`light_factors`] may evaluate; above it every factor is 1 (a
/// scene whose every triangle is a separate light).
pub const LIGHT_FACTOR_BUDGET: u64 = 50_000_000;

/// Area-weighted quantile of the patches' estimated direct light that [`light_factors`] takes
/// as the scene's typical brightness: a patch brighter than 90% of the scene's area weighs its
/// links by how much brighter it is.
pub const TYPICAL_LIGHT_QUANTILE: f64 = 0.9;

/// Per patch, how much brighter than the scene's typical patch its direct light may make it:
/// the estimate `max_c rho_c sum_e E_e,c F_e` over the emitting triangles `e` (the point form
/// factor at the patch's centroid, `A_e cos cos / (pi d^2 + A_e)`, unoccluded), over its
/// [`TYPICAL_LIGHT_QUANTILE`] over the area of the patches it lights; at least 1, and 1 everywhere when the
/// scene has no emitting triangle, nothing lit, or more than [`LIGHT_FACTOR_BUDGET`] terms.
///
/// The flux rule (`hierarchy::links::LinkParams::flux_share`) bounds what a link carries at
/// a typical radiance; a surface beside a light carries far more. A desk lamp's shade around
/// its bulb in `b90_office.obj` is about 200 times as bright as the room's surfaces: its
/// triangles, small, were faint pairs to each other, coupled coarsely and not split, and the
/// light it reflects into itself came out 5.4% short (that alone, with everything else black,
/// against the path tracer on patches of at most 0.25 m).
pub fn light_factors(patches: &Patches) -> Vec<f32> {
    let n = patches.len();
    let emitters: Vec<usize> = (0..n)
        .filter(|&p| patches.active[p] && patches.is_emitter(p))
        .collect();
    if emitters.is_empty() || (n as u64).saturating_mul(emitters.len() as u64) > LIGHT_FACTOR_BUDGET
    {
        return vec![1.0; n];
    }
    let lanes = EmitterLanes::of(patches, &emitters);
    let light: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|p| {
            let rho = patches.albedo[p];
            if !patches.active[p] || patches.is_emitter(p) || rho.iter().all(|&r| r <= 0.0) {
                return 0.0;
            }
            let sum = lanes.light_at(patches.centroid[p], patches.normal[p]);
            (0..3).map(|c| rho[c] * sum[c]).fold(0.0, f64::max)
        })
        .collect();
    // The area-weighted quantile over the area of the patches that reflect some direct light.
    // (Inactive patches and emitters have no light estimate: 0.)
    let mut lit: Vec<(f64, f64)> = light
        .iter()
        .zip(&patches.area)
        .map(|(&l, &a)| (l, a))
        .filter(|&(l, a)| l > 0.0 && l.is_finite() && a > 0.0)
        .collect();
    lit.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = lit.iter().map(|&(_, a)| a).sum();
    let mut acc = 0.0;
    let mut typical = 0.0;
    for &(l, a) in &lit {
        acc += a;
        typical = l;
        if acc >= TYPICAL_LIGHT_QUANTILE * total {
            break;
        }
    }
    if !(typical > 0.0 && typical.is_finite()) {
        return vec![1.0; n];
    }
    light
        .iter()
        .map(|&l| {
            let f = l / typical;
            if f > 1.0 && f.is_finite() {
                f as f32
            } else {
                1.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_is_exact_up_to_rounding() {
        assert!(is_grey([0.5, 0.5, 0.5]));
        assert!(is_grey([0.0, 0.0, 0.0]));
        assert!(is_grey([1e30, 1e30, 1e30]));
        assert!(!is_grey([0.5, 0.5, 0.51]));
        assert!(!is_grey([0.0, 0.0, 1e-30]));
    }

    /// A floor of 10 x 10 under a square light 3 above it, and a small plate 0.5 under the
    /// light: the plate is lit tens of times as brightly as the floor.
    fn plate_under_a_light(emission: f64) -> Patches {
        let v = DVec3::new;
        let quad = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| [[a, b, c], [a, c, d]];
        let mut tris = Vec::new();
        tris.extend(quad(
            v(-5., 0., -5.),
            v(-5., 0., 5.),
            v(5., 0., 5.),
            v(5., 0., -5.),
        ));
        tris.extend(quad(
            v(-0.5, 3., -0.5),
            v(0.5, 3., -0.5),
            v(0.5, 3., 0.5),
            v(-0.5, 3., 0.5),
        ));
        tris.extend(quad(
            v(-0.1, 2.5, -0.1),
            v(-0.1, 2.5, 0.1),
            v(0.1, 2.5, 0.1),
            v(0.1, 2.5, -0.1),
        ));
        let albedo = vec![[0.5; 3]; 6];
        let mut emitted = vec![[0.0; 3]; 6];
        emitted[2] = [emission; 3];
        emitted[3] = [emission; 3];
        crate::mesh::build_patches(
            &crate::Scene::from_triangles(&tris, &albedo, &emitted),
            None,
        )
    }

    #[test]
    fn a_plate_beside_a_light_weighs_its_links_by_how_much_brighter_it_is() {
        let patches = plate_under_a_light(1.0);
        assert!(
            patches.normal[0].y > 0.5 && patches.normal[2].y < -0.5 && patches.normal[4].y > 0.5
        );
        let f = light_factors(&patches);
        // The floor is the typical surface; the light's own triangles never weigh.
        assert_eq!(&f[..4], &[1.0; 4]);
        // Each floor triangle's centroid lies 2.4 off the light's axis, 3 below it; the plate's
        // right under it, 0.5 below: about 40 times the light.
        assert!(f[4] > 10.0 && f[4] < 100.0, "{f:?}");
        assert_eq!(f[4], f[5]);
        // Scale-free: ten times the emission gives the same factors.
        assert_eq!(light_factors(&plate_under_a_light(10.0)), f);
        // No light: every factor is 1.
        assert_eq!(light_factors(&plate_under_a_light(0.0)), vec![1.0; 6]);
    }

    /// The emitters' light at a point, four emitters at a time, is the sum of each one's term
    /// (to rounding): a subdivided Cornell box with seven more emitters, two of them
    /// two-sided, seen from every patch's centroid.
    #[test]
    fn emitter_lanes_sum_each_emitters_term() {
        let mut scene = crate::scene::generated::subdivided_cornell_box(400);
        for t in [3, 40, 77, 150, 151, 260, 333] {
            scene.emission[t] = [1.0, 0.5 + t as f64 / 1000.0, 2.0];
        }
        scene.two_sided = vec![false; scene.len()];
        scene.two_sided[40] = true;
        scene.two_sided[260] = true;
        let patches = crate::mesh::build_patches(&scene, None);
        let emitters: Vec<usize> = (0..patches.len())
            .filter(|&p| patches.is_emitter(p))
            .collect();
        // Its own light and these seven, the last chunk padded.
        assert!(emitters.len() > 7 && !emitters.len().is_multiple_of(LANES));
        let lanes = EmitterLanes::of(&patches, &emitters);
        let mut lit = 0;
        for p in 0..patches.len() {
            let (x, n_x) = (patches.centroid[p], patches.normal[p]);
            let mut sum = [0.0f64; 3];
            for &e in &emitters {
                let v = patches.centroid[e] - x;
                let d2 = v.length_squared();
                let (cos_x, mut cos_e) = (
                    n_x.dot(v) / d2.sqrt(),
                    -patches.normal[e].dot(v) / d2.sqrt(),
                );
                if patches.is_two_sided(e) {
                    cos_e = cos_e.abs();
                }
                if d2 > 0.0 && cos_x > 0.0 && cos_e > 0.0 {
                    let a = patches.area[e];
                    let f = a * cos_x * cos_e / (std::f64::consts::PI * d2 + a);
                    for (s, e) in sum.iter_mut().zip(patches.emission[e]) {
                        *s += e * f;
                    }
                }
            }
            let got = lanes.light_at(x, n_x);
            for c in 0..3 {
                assert!(
                    (got[c] - sum[c]).abs() <= 1e-12 * sum[c].max(1e-300),
                    "{p}: {got:?} {sum:?}"
                );
            }
            lit += usize::from(sum[0] > 0.0);
        }
        assert!(lit > patches.len() / 2, "{lit}");
    }
}
