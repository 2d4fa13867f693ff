//! What a scene requires the solver to model (issue 4): the hierarchical solver pays only for
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

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::geometry::sampling::{cosine_direction, point_on_triangle, Rng};
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

/// Per patch: true when light can reach its back, so that it must block light arriving there
/// (antiradiance from its back as well as its front).
///
/// Front-only antiradiance is exact for closed, consistently oriented objects: light reaching
/// a back has passed through a front first, whose antiradiance cancels it. Files as found are
/// not like that: walls exported facing away from the room, open sheets (a seat, a table top
/// of one polygon), blinds. Their backs are lit directly, and without blocking there light
/// leaks through them. The test is geometric, so it needs no consistent topology: from
/// stratified points on the patch, cosine-distributed rays into its back hemisphere (from
/// `2 SCENE_EPS` in front of it); a patch with a back-to-back twin (the same corners in reverse
/// order) is not exposed: the twin's front covers its back;
/// the back is exposed when at least [`EXPOSED_SHARE`] of those that meet a surface first meet
/// a face that sends light, or when an analytic light shines on it ([`analytic_reaches`]). Not
/// when they meet backs (the inside of a closed object, or a twin), fronts that no light
/// reaches (the inner faces of a closed object with some faces reversed), or all leave the
/// scene (the outside of a room shell). A face sends light when it emits, or when it reflects
/// (a front with albedo, either face of a two-sided patch) and its own rays meet a face that
/// sends light or an analytic light shines on it: the same rays from both faces of every
/// patch, propagated to a fixed point (at most [`LIT_PASSES_MAX`] passes). The test is per
/// patch: a box standing open-bottomed on a large floor patch that is lit elsewhere is exposed
/// inside, a false positive that costs two-sided bins, not light.
pub fn exposed_backs(patches: &Patches) -> Vec<bool> {
    let twinned = back_to_back_twins(patches);
    let scene = RayScene::new(&patches.corners, &patches.active);
    let n = patches.len();
    let active = patches.active_count().max(1);
    let rays = (BACK_RAY_BUDGET / active).clamp(BACK_RAYS_MIN, BACK_RAYS_MAX);
    let side = (rays as f64).sqrt().ceil() as usize;
    let traced = |p: usize| patches.active[p] && !twinned[p];
    // Face f is patch f / 2's front (f even) or back (f odd); `hits[f * rays + k]` is the face
    // ray k from face f meets first (NO_FACE when it leaves the scene).
    let mut hits = vec![NO_FACE; 2 * n * rays];
    hits.par_chunks_mut(rays).enumerate().for_each(|(f, out)| {
        let (p, back) = (f / 2, f % 2 == 1);
        if !traced(p) {
            return;
        }
        let (tri, n_p) = (&patches.corners[p], patches.normal[p]);
        let n_side = if back { -n_p } else { n_p };
        let mut rng = Rng::new(if back { 0x6261_636b } else { 0x6672_6f6e }, p as u64);
        for (k, hit) in out.iter_mut().enumerate() {
            // Stratified over the triangle (a side x side grid of its unit square), from
            // 2 SCENE_EPS on the other side of it (so a coincident twin is met).
            let (i, j) = ((k % side) as f64, (k / side % side) as f64);
            let u1 = (i + rng.next_f64()) / side as f64;
            let u2 = (j + rng.next_f64()) / side as f64;
            let org = point_on_triangle(tri, u1, u2) - n_side * (2.0 * crate::geometry::SCENE_EPS);
            let dir = cosine_direction(n_side, rng.next_f64(), rng.next_f64());
            if let Some(h) = scene.closest(org, dir, p) {
                let met_back = patches.normal[h.patch].dot(dir) >= 0.0;
                *hit = (2 * h.patch + usize::from(met_back)) as u32;
            }
        }
    });
    // Faces that send light: emitting faces, and faces that reflect (a front with albedo, or
    // either face of a two-sided patch) and receive light from a face that sends it (or from
    // an analytic light); to a fixed point.
    let reflects = |f: usize| {
        let p = f / 2;
        patches.active[p]
            && patches.albedo[p].iter().any(|&a| a > 0.0)
            && (f % 2 == 0 || patches.is_two_sided(p))
    };
    let lit_by_light = |f: usize| analytic_reaches(patches, f / 2, f % 2 == 1);
    let mut sends: Vec<bool> = (0..2 * n)
        .into_par_iter()
        .map(|f| {
            let p = f / 2;
            let emits = patches.active[p]
                && patches.emission[p].iter().any(|&e| e > 0.0)
                && (f % 2 == 0 || patches.is_two_sided(p));
            emits || (reflects(f) && lit_by_light(f))
        })
        .collect();
    for _ in 0..LIT_PASSES_MAX {
        let next: Vec<bool> = (0..2 * n)
            .into_par_iter()
            .map(|f| {
                sends[f]
                    || (reflects(f)
                        && hits[f * rays..(f + 1) * rays]
                            .iter()
                            .any(|&h| h != NO_FACE && sends[h as usize]))
            })
            .collect();
        let changed = next != sends;
        sends = next;
        if !changed {
            break;
        }
    }
    (0..n)
        .into_par_iter()
        .map(|p| {
            if !traced(p) {
                return false;
            }
            let back = &hits[(2 * p + 1) * rays..(2 * p + 2) * rays];
            let met = back.iter().filter(|&&h| h != NO_FACE).count();
            let lit = back
                .iter()
                .filter(|&&h| h != NO_FACE && sends[h as usize])
                .count();
            (lit > 0 && lit as f64 >= EXPOSED_SHARE * met as f64) || lit_by_light(2 * p + 1)
        })
        .collect()
}

/// No face: a ray of [`exposed_backs`] that leaves the scene.
const NO_FACE: u32 = u32::MAX;

/// Most passes of [`exposed_backs`]'s propagation of light from face to face (each pass carries
/// it one bounce further); light that needs more bounces to reach a face is not followed.
pub const LIT_PASSES_MAX: usize = 64;

/// True when an analytic light of `patches` can shine on patch `p`'s back (`back`) or front: a
/// point or spot light on that side of its plane, a sun whose light travels into that side,
/// or a sky.
pub fn analytic_reaches(patches: &Patches, p: usize, back: bool) -> bool {
    use crate::scene::lights::Light;
    let n = if back {
        -patches.normal[p]
    } else {
        patches.normal[p]
    };
    let x = patches.corners[p][0];
    patches.lights.iter().any(|light| match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } => n.dot(position - x) > 0.0,
        Light::Sun { direction, .. } => n.dot(direction) < 0.0,
        Light::Sky { .. } => true,
    })
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
    let mut seen: std::collections::HashMap<[[i64; 3]; 3], usize> =
        std::collections::HashMap::new();
    for p in 0..patches.len() {
        if patches.active[p] {
            seen.insert(key(patches.corners[p]), p);
        }
    }
    (0..patches.len())
        .map(|p| {
            let [a, b, c] = patches.corners[p];
            patches.active[p] && seen.contains_key(&key([a, c, b]))
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
    /// back is exposed to light ([`exposed_backs`]) or it emits. The back face of a two-sided patch that no light can
    /// reach (a wall's outside, the inside of a closed object) stays dark, and costs nothing.
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
                patches.is_two_sided(p)
                    && (!test || exposed[p] || patches.emission[p].iter().any(|&e| e > 0.0))
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
}
