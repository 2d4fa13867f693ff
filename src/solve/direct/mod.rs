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
//!   with 1..6 x 6 points chosen by separation, as the solvers' couplings do); emitters joined
//!   edge to edge with the same emission and normal form an `EmitterGroup` whose members'
//!   far-field terms are one contour sum over the group's boundary (exactly the members' sum),
//!   so a light made of hundreds of triangles costs about as much as its rim;
//! - the visible fraction comes from shadow rays: stratified points on the element, emitter
//!   groups chosen in proportion to their unoccluded light at this element (so a receiver beside
//!   a small light aims its rays at that light, not at the scene's most powerful one), members
//!   by area, stratified points on the member; each sample's unoccluded contribution `f_i` is
//!   weighed by its visibility `V_i`, and each group's fraction is `sum f_i V_i / sum f_i` over
//!   its samples (a ratio estimator: its bias falls as 1/samples); a group no sample reached
//!   takes the fraction of all samples. Groups are never pooled: a lamp under its shade and a
//!   window beside it have nothing in common, and pooling the groups with fewer than 16 samples
//!   gave the lamp the window's visibility (the generated classroom's ceiling 10.8% too bright,
//!   the classroom 6.1% from the path tracer, bias +3.9%; each group on its own: 1.8% and
//!   2.7%, bias -0.7%; the seed room, one light, unchanged).
//!
//! Fully lit elements get exactly `U`, elements in umbra exactly 0, a well-sampled light wholly
//! seen or wholly hidden counts fully or not at all; noise is confined to penumbrae.
//! (Subtracting a Monte Carlo estimate of the blocked light from `U` instead, an unbiased
//! control variate, leaves noise of either sign in umbrae.)
//!
//! Sampling is seeded per element (the element's index), so results are reproducible and do not
//! depend on thread scheduling. Shadow rays use the watertight test of [`crate::geometry::raytrace`].

mod emitters;
mod member_tree;
mod solvers;

use emitters::*;
use member_tree::*;
#[cfg(test)]
use solvers::patch_receivers;
pub use solvers::{solve_dense_direct, solve_hierarchical_direct, DIRECT_LIGHT_OFF};
use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::geometry::sampling::{cumulative, interval_of, point_on_triangle, Rng};
use crate::geometry::tolerances::GROUP_NORMAL_TOLERANCE;
use crate::geometry::tolerances::{SAMPLE_BELOW_ONE, TIGHTER};
use crate::geometry::{self, plane_tol, point_key, Lanes, Tri, LANES, PLANE_EPS};
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solve::hierarchical::Element;
use crate::solve::solution::DirectStats;
use crate::transport::{separation, PatchGeom, FAR_RATIO};

/// Total shadow rays one direct-light pass aims at, spread over the receivers as
/// (area x reflected unoccluded light)^(2/3) (see [`DirectLight::reflected`]), then clamped to
/// [`MIN_SHADOW_SAMPLES`]..=[`MAX_SHADOW_SAMPLES`] per receiver. Spread evenly, 2M rays left
/// the room's direct light 0.33% and the bear's 1.63% from a 32M-ray run (design-note error);
/// spread by light, 1M rays leave 0.30% and 0.72% (0.5M: 0.51% and 1.05%).
pub const SHADOW_RAY_BUDGET: usize = 1_000_000;

/// Most unoccluded form-factor terms (receivers x emitter groups) a direct-light pass may cost;
/// above it the solvers skip exact direct light (and say so): a scene whose every triangle is
/// a separate emitter would otherwise pay receivers x emitters form factors.
pub const DIRECT_LIGHT_BUDGET: u64 = 200_000_000;

/// Most shadow rays the floor [`FLOOR_SAMPLES`] may raise a pass to: above
/// `MAX_SHADOW_RAYS / FLOOR_SAMPLES` receivers the floor falls, to [`MIN_SHADOW_SAMPLES`] at
/// half a million. It does not limit the receivers: every receiver gets at least
/// [`MIN_SHADOW_SAMPLES`], so the 1M-triangle Cornell box's pass costs 16M rays.
pub const MAX_SHADOW_RAYS: u64 = 8_000_000;

/// Fewest shadow samples per receiving element (a square, for stratification).
pub const MIN_SHADOW_SAMPLES: usize = 16;

/// Shadow samples per receiving element that the budget may not go below while the pass stays
/// within [`MAX_SHADOW_RAYS`] (a square). The pilot (`PILOT_SAMPLES`, 16 rays) stops wholly lit and
/// wholly shadowed receivers first, so the floor costs rays in penumbrae only. Each emitter
/// group takes the visible fraction of its own samples (a ratio estimator whose bias and noise
/// fall as 1 / samples per group), and a receiver in a penumbra is noisy at 16: against
/// path-traced references, the 66k-triangle Cornell box 2.42% -> 2.31% rms (the references'
/// noise removed) for 0.34 s more direct light; the generated classroom (16 groups) 2.40% ->
/// 2.30% against 16,384 spp, b90_office 4.28% (bias +1.42%) -> 3.83% (+0.51%) against 8,192
/// spp.
pub const FLOOR_SAMPLES: usize = 64;

/// Most shadow samples per receiving element (a square, for stratification).
pub const MAX_SHADOW_SAMPLES: usize = 1024;

/// Fewest shadow rays of the pilot pass (a square; the pilot takes a quarter of the receiver's
/// rays): a receiver whose pilot rays all agree (all visible or all blocked) gets no more, and
/// is taken as wholly lit or wholly in shadow. Measured with 2M rays spread evenly (196 per
/// receiver): on the room 55% of the receivers stopped there and the direct light took about
/// 30% less time; the result moves by 0.27% (design-note error
/// against the run without pilot) and its error against the path tracer does not move (2.13%
/// with it, 2.16% without; bear in a room, bear and legoBrick within 0.12%). A pilot of 16
/// rays stopped 71% but moved the room's result by 0.75%: thin penumbrae slipped between its
/// rays. A receiver that goes on shoots all its rays again: the pilot's are not counted, since
/// they are kept only where they disagreed, a biased sample (counting them with the rest of the
/// rays moved the seed room by 0.19%, 2.28% -> 2.31% from the path tracer, bias -0.98% ->
/// -1.06%, for 0.04 s less direct light).
const PILOT_SAMPLES: usize = 16;

/// Seed of the pilot pass's per-element streams.
const PILOT_SEED: u64 = 0x5eed_d12e_c71d_0002;

/// The shadow rays of one receiver ([`DirectStats`]'s parts); none when no emitter lights it.
#[derive(Clone, Copy, Debug, Default)]
struct Rays {
    /// Rays traced, pilot included.
    traced: u64,
    /// The pilot's rays all agreed, and no more were traced.
    settled: bool,
}

/// What one receiver's shadow rays found, per group of its lights.
struct Pass {
    /// Sums of the unoccluded contributions of the samples of each group.
    arriving: Vec<f64>,
    /// Sums of the visible ones.
    visible: Vec<f64>,
    /// Light-carrying samples per group.
    counts: Vec<usize>,
    /// Visible samples in all.
    seen: usize,
}

/// Most receivers [`DirectLight::lights_per_receiver`] samples.
pub const LIGHTS_SAMPLE: usize = 1024;

/// Bytes of every emitter group at every receiver (16 a group) up to which
/// [`DirectLight::lights_per_receiver`] counts every group instead of sampling: the estimate is
/// then at most this much above what the receivers keep, and the sample's share of the
/// unoccluded pass (a tenth of it on the seed room) is saved.
pub const LIGHTS_UNSAMPLED_BYTES: u64 = 16 << 20;

/// Factor on the sampled mean of groups per receiver in the direct light's memory estimate: 2
/// for the vectors' growth by doubling, 1.5 for the sample's error.
pub const LIGHTS_MARGIN: f64 = 3.0;

/// Seed of the per-element random streams (fixed: the direct light is deterministic).
const SEED: u64 = 0x5eed_d12e_c71d_0001;

/// Lambert's contour sum for a closed set of directed edges seen from `x` (normal `n_x`): the
/// form factor of any surface they bound that lies in front of `x` and faces it, in [0, 1].
/// The same sum as [`geometry::point_form_factor`] over each of the surface's triangles.
fn contour_form_factor(x: DVec3, n_x: DVec3, edges: &[(DVec3, DVec3)]) -> f64 {
    geometry::lambert_form_factor(geometry::lambert_edges_sum(x, n_x, edges))
}

/// The sum over the centroids `y` of the `q x q` pieces of the receiver triangle `corners`
/// (normal `n_x`) that lie in front of emitter `s`'s plane of the point form factors of
/// `parts` (the part of `s` in front of the receiver's plane) seen from `y`: the receiver
/// quadrature of [`DirectLight::emitter_form_factor`] and of a group's near members, `LANES`
/// points at a time.
fn points_form_factor(corners: &Tri, q: usize, n_x: DVec3, s: &PatchGeom, parts: &[Tri]) -> f64 {
    let (points, count) = geometry::piece_centroid_lanes(corners, q);
    let corner = [s.corners[0].x, s.corners[0].y, s.corners[0].z].map(Lanes::splat);
    let mut sum = Lanes::ZERO;
    for (c, p) in points.iter().enumerate() {
        let height = (p[0] - corner[0]) * s.normal.x
            + (p[1] - corner[1]) * s.normal.y
            + (p[2] - corner[2]) * s.normal.z;
        let counted = height.simd_gt(Lanes::ZERO) & geometry::lane_below(count - c * LANES);
        for part in parts {
            let f = geometry::point_form_factor_lanes(p, n_x, part);
            sum += counted.select(f, Lanes::ZERO);
        }
    }
    sum.reduce_add()
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

/// Mean shadow samples per receiver for `receivers` receivers: the ray budget
/// [`SHADOW_RAY_BUDGET`] spread evenly, at least [`FLOOR_SAMPLES`] while the pass stays within
/// [`MAX_SHADOW_RAYS`], clamped to [`MIN_SHADOW_SAMPLES`]..=[`MAX_SHADOW_SAMPLES`], rounded
/// down to a square k x k.
pub fn shadow_samples(receivers: usize) -> usize {
    let receivers = receivers.max(1);
    let floor = FLOOR_SAMPLES.min(MAX_SHADOW_RAYS as usize / receivers);
    let wanted = (SHADOW_RAY_BUDGET / receivers)
        .max(floor)
        .clamp(MIN_SHADOW_SAMPLES, MAX_SHADOW_SAMPLES);
    let k = wanted.isqrt();
    k * k
}

/// The direct light of a scene: its emitters, a BVH for shadow rays and the sample count.
pub struct DirectLight<'a> {
    patches: &'a Patches,
    emitters: Emitters,
    groups: Vec<EmitterGroup>,
    rays: RayScene<'a>,
    /// Mean shadow samples per receiving element (the budget; each receiver's own count follows
    /// its light, see [`Self::reflected`]).
    samples: usize,
}

impl<'a> DirectLight<'a> {
    /// Prepares the direct light of `patches` (unit frame, normalized emission, as
    /// [`crate::mesh::build_patches`] makes them) for `receivers` receiving elements (which sets
    /// the shadow samples per element, see [`shadow_samples`]).
    pub fn new(patches: &'a Patches, receivers: usize) -> DirectLight<'a> {
        DirectLight::with_back_faces(patches, receivers, None)
    }

    /// [`DirectLight::new`] where a two-sided emitter emits from its back face only when
    /// `back_faces[p]` (the solver solves that face: light can reach its back; the back of a
    /// closed emitting tube traps its light). `None`: every two-sided emitter's back emits.
    pub fn with_back_faces(
        patches: &'a Patches,
        receivers: usize,
        back_faces: Option<&[bool]>,
    ) -> DirectLight<'a> {
        let back = |p: usize| back_faces.is_none_or(|b| b.get(p).copied().unwrap_or(false));
        let emitters = Emitters::new(patches, &back);
        let mut light = DirectLight {
            patches,
            groups: group_emitters(&emitters),
            emitters,
            rays: RayScene::of(patches),
            samples: 0,
        };
        light.samples = shadow_samples(receivers);
        light
    }

    /// Mean shadow samples per receiving element.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// The reflected direct radiance `D_e = rho_e * (direct irradiance)_e / pi` of every
    /// receiver (normalized units, RGB, never negative), in the order of `receivers`.
    ///
    /// Each receiver's `patch` must index `patches`; its corners, normal and area are in the unit
    /// frame (as [`crate::solve::hierarchical::Prepared::elements`] gives them). Runs in parallel over receivers; sets the
    /// progress message.
    pub fn reflected(
        &self,
        receivers: &[Element],
        progress: &Progress,
    ) -> (Vec<[f64; 3]>, DirectStats) {
        progress.message(format!(
            "direct light: {} receivers x {} emitters, {} shadow rays each on average",
            receivers.len(),
            self.emitters.len(),
            self.samples
        ));
        // 1. Every receiver's unoccluded light, and the groups it comes from.
        let unoccluded: Vec<(Vec<GroupLight>, [f64; 3])> = receivers
            .par_iter()
            .map_init(Vec::new, |parts, r| {
                let rho = self.patches.albedo[r.patch as usize];
                if self.emitters.len() == 0 || !(r.area > 0.0) || rho.iter().all(|&x| x <= 0.0) {
                    return (Vec::new(), [0.0; 3]);
                }
                let mut lights = Vec::new();
                let u = self.unoccluded(r, &mut lights, parts);
                (lights, u)
            })
            .collect();
        // 2. Shadow rays where the light is: receiver i's share of the budget goes as
        //    (area x reflected unoccluded light)^(2/3), the split of a fixed number of rays that
        //    minimises the area-weighted error sum A_i D_i / sqrt(n_i) (equal noise per ray
        //    assumed), clamped to MIN..=MAX_SHADOW_SAMPLES.
        let weight: Vec<f64> = receivers
            .iter()
            .zip(&unoccluded)
            .map(|(r, (_, u))| {
                let rho = self.patches.albedo[r.patch as usize];
                let d = (0..3).map(|c| rho[c] * u[c]).fold(0.0, f64::max);
                let w = (r.area * d).powf(2.0 / 3.0);
                if w.is_finite() {
                    w
                } else {
                    0.0
                }
            })
            .collect();
        let total_weight: f64 = weight.iter().sum();
        let budget = (self.samples * receivers.len()) as f64;
        let samples_of = |w: f64| {
            let share = if total_weight > 0.0 {
                budget * w / total_weight
            } else {
                0.0
            };
            let n = (share as usize).clamp(MIN_SHADOW_SAMPLES, MAX_SHADOW_SAMPLES);
            n.isqrt().pow(2)
        };
        // 3. The visible part of it, with the rays each receiver took.
        let (reflected, rays): (Vec<[f64; 3]>, Vec<Rays>) = receivers
            .par_iter()
            .zip(&unoccluded)
            .zip(&weight)
            .enumerate()
            .map(|(index, ((r, (lights, u)), &w))| {
                if u.iter().all(|&x| x <= 0.0) {
                    return ([0.0; 3], Rays::default());
                }
                let rho = self.patches.albedo[r.patch as usize];
                let (visible, rays) = self.visible_light(r, index as u64, lights, samples_of(w));
                let d = [0, 1, 2].map(|c| {
                    let d = rho[c] * visible[c];
                    if d.is_finite() {
                        d.max(0.0)
                    } else {
                        0.0
                    }
                });
                (d, rays)
            })
            .unzip();
        let mut stats = DirectStats {
            receivers: receivers.len() as u64,
            ..DirectStats::default()
        };
        for r in &rays {
            stats.lit_receivers += u64::from(r.traced > 0);
            stats.shadow_rays += r.traced;
            stats.settled_by_pilot += u64::from(r.settled);
        }
        (reflected, stats)
    }

    /// True when `receivers` receivers would cost more than [`DIRECT_LIGHT_BUDGET`] unoccluded
    /// form-factor terms against the emitter groups (the receivers' count alone never is).
    pub fn over_budget(&self, receivers: usize) -> bool {
        receivers as u64 * self.group_count() as u64 > DIRECT_LIGHT_BUDGET
    }

    /// Number of emitter groups (see `EmitterGroup`); at most the number of emitters.
    pub fn group_count(&self) -> usize {
        self.groups.len()
    }

    /// An upper estimate of the emitter groups each receiver's unoccluded light keeps (what
    /// [`Self::reflected`] holds per receiver, 16 bytes a group): the mean over an even sample of
    /// at most [`LIGHTS_SAMPLE`] of `receivers`, times [`LIGHTS_MARGIN`] (the vectors' growth and
    /// the sample's error), at most every group. The bear lit by its own head: 20.8 groups per
    /// receiver of 779 (357,880 in all, 512,764 allocated). The sample costs at most
    /// [`LIGHTS_SAMPLE`] receivers' share of the unoccluded pass; over [`Self::over_budget`]
    /// (where the pass is skipped) it is not taken, nor where every group at every receiver
    /// would take at most [`LIGHTS_UNSAMPLED_BYTES`], and every group is counted.
    pub fn lights_per_receiver(&self, receivers: &[Element]) -> u64 {
        let groups = self.groups.len() as u64;
        if receivers.is_empty() || groups == 0 {
            return 0;
        }
        let every_group_bytes = (receivers.len() as u64).saturating_mul(groups) * 16;
        if self.over_budget(receivers.len()) || every_group_bytes <= LIGHTS_UNSAMPLED_BYTES {
            return groups;
        }
        let stride = receivers.len().div_ceil(LIGHTS_SAMPLE);
        let sample: Vec<&Element> = receivers.iter().step_by(stride).collect();
        let kept: usize = sample
            .par_iter()
            .map_init(
                || (Vec::new(), Vec::new()),
                |(lights, parts), r| {
                    self.unoccluded(r, lights, parts);
                    lights.len()
                },
            )
            .sum();
        let mean = kept as f64 / sample.len() as f64;
        ((mean * LIGHTS_MARGIN).ceil() as u64).min(groups)
    }

    /// Mean over the receiver of `sum_s E_s F(x <- s)` without visibility: the emitters' light
    /// arriving at its front side (H / pi), from the emitters' front sides, exact per point.
    ///
    /// A group wholly in front of the receiver's plane is integrated over its boundary
    /// ([`contour_form_factor`]) at every receiver point that is clearly in front of all its
    /// members; otherwise (a group cut by the receiver's plane, a point near the group's plane)
    /// member by member. `lights` is cleared and receives every group with a positive form
    /// factor (the distribution of [`Self::visible_light`]'s shadow rays).
    fn unoccluded(
        &self,
        r: &Element,
        lights: &mut Vec<GroupLight>,
        parts: &mut Vec<Part>,
    ) -> [f64; 3] {
        let receiver = PatchGeom::new(r.corners, r.normal);
        let mut sum = [0.0f64; 3];
        lights.clear();
        for (g, group) in self.groups.iter().enumerate() {
            if self.cannot_reach(r, &receiver, group) {
                continue;
            }
            let f = if group.members.len() > 1 && self.in_front_of_receiver(r, &receiver, group) {
                self.group_form_factor(r, &receiver, group, None)
            } else if group.members.len() > 1 && group.manifold {
                (group.planar)
                    .then(|| self.planar_cut_form_factor(r, &receiver, group))
                    .flatten()
                    .unwrap_or_else(|| self.cut_group_form_factor(r, &receiver, group, parts))
            } else {
                group
                    .members
                    .iter()
                    .map(|&k| self.emitter_form_factor(r, &receiver, k as usize))
                    .sum()
            };
            if f > 0.0 && f.is_finite() {
                lights.push(GroupLight {
                    group: g as u32,
                    form_factor: f,
                });
            }
            for (acc, e) in sum.iter_mut().zip(group.emission) {
                *acc += e * f;
            }
        }
        sum
    }

    /// True when no light of `group` can reach the receiver's front: the group lies wholly
    /// behind the receiver's plane, or the receiver wholly behind the group's (one-sided
    /// emitters), or the receiver lies behind or in the plane of every member within the
    /// tolerance [`Self::emitter_form_factor`] uses (a ceiling around a light made of many
    /// triangles: each member's form factor would be 0, found member by member). A cheap,
    /// conservative test (bounding sphere, plane margins).
    fn cannot_reach(&self, r: &Element, receiver: &PatchGeom, group: &EmitterGroup) -> bool {
        let tol = plane_tol(receiver.size.max(2.0 * group.radius));
        if r.normal.dot(group.center - r.corners[0]) <= tol - group.radius {
            return true;
        }
        // How far a member's plane can be from the group's at corner c.
        let spread = |c: DVec3| {
            group.normal_spread * ((c - group.center).length() + group.radius) + group.thickness
        };
        if r.corners
            .iter()
            .all(|&c| group.normal.dot(c - group.centroid) <= -(spread(c) + tol))
        {
            return true;
        }
        // Every member's own test (`emitter_form_factor`) uses at least this tolerance.
        let member_tol = plane_tol(receiver.size) * TIGHTER;
        r.corners
            .iter()
            .all(|&c| group.normal.dot(c - group.centroid) + spread(c) <= member_tol)
    }

    /// True when every vertex of `group` lies in the closed half-space in front of the
    /// receiver's plane (within the clipping tolerance; a vertex on the plane is fine: the
    /// contour sum, like the triangle form factor, only needs nothing behind the plane).
    fn in_front_of_receiver(
        &self,
        r: &Element,
        receiver: &PatchGeom,
        group: &EmitterGroup,
    ) -> bool {
        let tol = plane_tol(receiver.size.max(2.0 * group.radius));
        let height = |p: DVec3| r.normal.dot(p - r.corners[0]);
        if height(group.center) >= group.radius {
            return true;
        }
        // Every corner of every member at height -tol or more, node by node.
        let tree = &group.tree;
        let mut in_front = true;
        tree.walk(0, |_, node| {
            let h = height(node.center);
            if !in_front || h - node.radius >= -tol {
                return false;
            }
            if h + node.radius < -tol {
                in_front = false;
            } else if node.is_leaf() {
                let mut corners = tree
                    .members(node)
                    .iter()
                    .flat_map(|&i| self.emitters.geom[group.members[i as usize] as usize].corners);
                in_front = !corners.any(|c| height(c) < -tol);
            }
            in_front
        });
        in_front
    }

    /// Mean form factor of a group seen from the receiver, whose plane has the whole group in
    /// front of it (or, with `parts`, of those parts, which must be wholly in front of it, the
    /// group manifold): the same quadrature as member by member (each member's receiver points
    /// from its own separation), computed as the contour sum at the receiver's centroid (every
    /// member at one point) plus, for the few near members that need more points, their own
    /// quadrature in place of their centroid value. Falls back to member by member when the
    /// centroid is not clearly in front of every member.
    fn group_form_factor(
        &self,
        r: &Element,
        receiver: &PatchGeom,
        group: &EmitterGroup,
        parts: Option<&[Part]>,
    ) -> f64 {
        let tree = &group.tree;
        let whole = [Part::Node(0)];
        let chosen = parts.unwrap_or(&whole);
        let x = receiver.centroid;
        if !group.clearly_in_front(x) {
            let mut f = 0.0;
            for_each_member(tree, chosen, |i| {
                f += self.emitter_form_factor(r, receiver, group.members[i as usize] as usize);
            });
            return f;
        }
        let mut f = match parts {
            None => contour_form_factor(x, r.normal, &group.boundary),
            Some(parts) => {
                // The parts' rims: shared edges cancel, as in the whole group's boundary.
                let mut sum = 0.0;
                for &part in parts {
                    match part {
                        Part::Node(n) => {
                            let rim = tree.rim(&tree.nodes[n as usize]);
                            sum += geometry::lambert_edges_sum(x, r.normal, rim);
                        }
                        Part::Member(i) => {
                            let c = self.emitters.geom[group.members[i as usize] as usize].corners;
                            for j in 0..3 {
                                sum +=
                                    geometry::lambert_edge(c[j] - x, c[(j + 1) % 3] - x, r.normal);
                            }
                        }
                    }
                }
                geometry::lambert_form_factor(sum)
            }
        };
        // When every member is far from the receiver's centroid, every member's rule is one
        // point.
        if tree.nodes[0].farther_than(x, FAR_RATIO * receiver.size) {
            return f.max(0.0);
        }
        let mut near_member = |i: u32| {
            let s = &self.emitters.geom[group.members[i as usize] as usize];
            let q = receiver_points(separation(receiver, s));
            if q == 1 {
                return;
            }
            let near =
                points_form_factor(&r.corners, q, r.normal, s, std::slice::from_ref(&s.corners));
            f += near / (q * q) as f64 - geometry::point_form_factor(x, r.normal, &s.corners);
        };
        // The same bound node by node: only nodes near the receiver are visited.
        for &part in chosen {
            match part {
                Part::Member(i) => near_member(i),
                Part::Node(n) => tree.walk(n, |_, node| {
                    let near = !node.farther_than(x, FAR_RATIO * receiver.size);
                    if near && node.is_leaf() {
                        tree.members(node).iter().for_each(|&i| near_member(i));
                    }
                    near
                }),
            }
        }
        f.max(0.0)
    }

    /// Mean form factor of a (manifold) group whose members the receiver's plane cuts: the
    /// parts wholly in front of it together ([`Self::group_form_factor`] over them), the
    /// members it cuts one by one (clipped), those behind it not at all. Exactly the members'
    /// sum, at the cost of the rims of the parts in front and the members along the cut: a
    /// ceiling light cut by the plane of a cupboard's side cost 4M member form factors on the
    /// room, and one of 11,250 triangles cut by the planes of the boxes' sides most of the
    /// direct light of the 258k-triangle Cornell box. `parts` is scratch.
    fn cut_group_form_factor(
        &self,
        r: &Element,
        receiver: &PatchGeom,
        group: &EmitterGroup,
        parts: &mut Vec<Part>,
    ) -> f64 {
        parts.clear();
        let tree = &group.tree;
        let height = |p: DVec3| r.normal.dot(p - r.corners[0]);
        let mut f = 0.0;
        tree.walk(0, |n, node| {
            // At least every member's own tolerance below.
            let tol = plane_tol(receiver.size.max(node.size));
            let h = height(node.center);
            if h - node.radius > tol {
                parts.push(Part::Node(n));
                return false;
            }
            if h + node.radius < -tol {
                return false;
            }
            if !node.is_leaf() {
                return true;
            }
            for &i in tree.members(node) {
                let k = group.members[i as usize] as usize;
                let s = &self.emitters.geom[k];
                // The sides as `emitter_form_factor`'s clipping sees them.
                let tol = plane_tol(receiver.size.max(s.size));
                let height = geometry::plane_heights(&s.corners, r.corners[0], r.normal, tol);
                let in_front = height.iter().all(|&h| h >= 0.0)
                    && height.iter().any(|&h| h > 0.0)
                    && self.emitters.patch[k] != r.patch;
                if in_front {
                    parts.push(Part::Member(i));
                } else if height.iter().any(|&h| h > 0.0) {
                    f += self.emitter_form_factor(r, receiver, k);
                }
            }
            false
        });
        if !parts.is_empty() {
            f += self.group_form_factor(r, receiver, group, Some(parts));
        }
        f
    }

    /// Mean form factor of a planar, manifold group whose members the receiver's plane cuts, as
    /// one contour: the group's boundary clipped to the front of the receiver's plane, closed
    /// by the segments where that plane crosses the group (from each exit point to the next
    /// entry point along the line), plus the near members' own quadrature in place of their
    /// centroid value (a member the plane cuts: its clipped part's). The same sum as
    /// [`Self::cut_group_form_factor`] (to the plane tolerance) for the cost of the boundary
    /// and the members near the receiver: on the 1M-triangle Cornell box the boxes' sides cut
    /// a light of 43,808 triangles. `None` when the receiver's centroid is not clearly in
    /// front of every member, or the crossings do not pair (the caller then goes member by
    /// member).
    fn planar_cut_form_factor(
        &self,
        r: &Element,
        receiver: &PatchGeom,
        group: &EmitterGroup,
    ) -> Option<f64> {
        let x = receiver.centroid;
        if !group.clearly_in_front(x) {
            return None;
        }
        let tree = &group.tree;
        // Every member's own clipping tolerance is at most this one.
        let tol = plane_tol(receiver.size.max(tree.nodes[0].size));
        let height = |p: DVec3| geometry::plane_height(p, r.corners[0], r.normal, tol);
        let edge = |a: DVec3, b: DVec3| geometry::lambert_edge(a - x, b - x, r.normal);
        // 1. The boundary in front; where it leaves and re-enters the front half-space.
        let along = group.normal.cross(r.normal);
        let mut sum = 0.0;
        let mut crossings: Vec<(f64, DVec3, bool)> = Vec::new();
        for &(a, b) in &group.boundary {
            let (ha, hb) = (height(a), height(b));
            match (ha > 0.0, hb > 0.0) {
                (true, true) => sum += edge(a, b),
                (false, false) => {}
                (front_a, _) => {
                    let p = a + (b - a) * (ha / (ha - hb));
                    if front_a {
                        sum += edge(a, p);
                    } else {
                        sum += edge(p, b);
                    }
                    crossings.push((along.dot(p), p, front_a));
                }
            }
        }
        // 2. The cut: along the line, the crossings bound the group's chords in pairs, each an
        //    entry point then an exit point (the members counter-clockwise about the group's
        //    normal put the group's inside on the decreasing side of an exit); each chord
        //    closes the contour from its exit back to its entry.
        if !crossings.len().is_multiple_of(2) {
            return None;
        }
        crossings.sort_by(|c, d| c.0.total_cmp(&d.0));
        for pair in crossings.chunks_exact(2) {
            let [(_, entry, false), (_, exit, true)] = [pair[0], pair[1]] else {
                return None;
            };
            sum += edge(exit, entry);
        }
        let mut f = geometry::lambert_form_factor(sum);
        // 3. Near members: their own receiver points in place of the centroid (nodes wholly
        //    far from the receiver or behind its plane have none).
        tree.walk(0, |_, node| {
            let far = node.farther_than(x, FAR_RATIO * receiver.size);
            if far || r.normal.dot(node.center - r.corners[0]) + node.radius < -tol {
                return false;
            }
            if !node.is_leaf() {
                return true;
            }
            for &i in tree.members(node) {
                let k = group.members[i as usize] as usize;
                let s = &self.emitters.geom[k];
                if receiver_points(separation(receiver, s)) == 1 {
                    continue;
                }
                let (front, _) = geometry::clip_by_plane(&s.corners, r.corners[0], r.normal, tol);
                let at_centroid: f64 = front
                    .triangles()
                    .map(|part| geometry::point_form_factor(x, r.normal, &part))
                    .sum();
                f += self.emitter_form_factor(r, receiver, k) - at_centroid;
            }
            false
        });
        Some(f.max(0.0))
    }

    /// Mean form factor of emitter `k` seen from the receiver (the part of it in front of the
    /// receiver's plane, at points in front of the emitter).
    fn emitter_form_factor(&self, r: &Element, receiver: &PatchGeom, k: usize) -> f64 {
        let s = &self.emitters.geom[k];
        if self.emitters.patch[k] == r.patch {
            return 0.0;
        }
        // A receiver wholly behind (or in) the emitter's plane sees none of its front.
        let tol = plane_tol(receiver.size.max(s.size));
        if r.corners
            .iter()
            .all(|&c| s.normal.dot(c - s.corners[0]) <= tol)
        {
            return 0.0;
        }
        // The part of the emitter in front of the receiver's plane.
        let (front, _) = geometry::clip_by_plane(&s.corners, r.corners[0], r.normal, tol);
        if front.len == 0 {
            return 0.0;
        }
        let q = receiver_points(separation(receiver, s));
        let parts: smallvec::SmallVec<[Tri; 2]> = front.triangles().collect();
        if q == 1 {
            let x = receiver.centroid;
            if s.normal.dot(x - s.corners[0]) > 0.0 {
                return parts
                    .iter()
                    .map(|part| geometry::point_form_factor(x, r.normal, part))
                    .sum();
            }
            return 0.0;
        }
        points_form_factor(&r.corners, q, r.normal, s, &parts) / (q * q) as f64
    }

    /// The receiver's visible direct light `sum_g E_g F_g V_g` (H / pi per RGB channel): each
    /// group's unoccluded light (`lights`, from [`Self::unoccluded`]) times the fraction `V_g`
    /// of it that shadow rays find visible.
    ///
    /// Rays go where this receiver's light comes from: the group of each sample is chosen in
    /// proportion to its unoccluded light here (form factor x largest emission channel), its
    /// member by area, so a point on the group is uniform. (A choice by the emitters' total
    /// power sends most rays of a receiver beside a small light to large lights it barely
    /// sees.) `V_g = sum g_i v_i / sum g_i` over the group's samples, with `g_i` a sample's
    /// unoccluded contribution and `v_i` its visibility (a ratio estimator, bias falling as
    /// 1/samples): a group wholly visible counts exactly `F_g`, a hidden one exactly 0, and
    /// noise is confined to penumbrae. A group without a light-carrying sample takes the
    /// fraction of all samples (1 when no sample carried light).
    ///
    /// Sample i pairs the receiver point of stratum i (k x k jittered grid on the triangle) with
    /// a stratified choice of group and member (1-D strata over the distribution) and a
    /// stratified point on the member (k x k grid), both strata drawn through random
    /// permutations so the pairing stays unbiased.
    fn visible_light(
        &self,
        r: &Element,
        index: u64,
        lights: &[GroupLight],
        samples: usize,
    ) -> ([f64; 3], Rays) {
        let emission = |l: &GroupLight| self.groups[l.group as usize].emission;
        let unoccluded = |l: &GroupLight| emission(l).map(|e| e * l.form_factor);
        // The distribution over the groups that light this receiver.
        let weight = |l: &GroupLight| {
            let e = emission(l);
            l.form_factor * e[0].max(e[1]).max(e[2])
        };
        let total: f64 = lights.iter().map(weight).sum();
        if lights.is_empty() || !(total > 0.0 && total.is_finite()) {
            let light = lights.iter().fold([0.0; 3], |acc, l| {
                let u = unoccluded(l);
                [0, 1, 2].map(|c| acc[c] + u[c])
            });
            return (light, Rays::default());
        }
        let cdf = cumulative(lights.iter().map(weight));
        // A pilot of a quarter of the rays first; when they all agree (every ray that carries
        // light reaches it, or none does), the receiver is taken as wholly lit or wholly in
        // shadow.
        // (A receiver with too few rays for a smaller pilot gets them all at once.)
        let pilot_n = (samples / 4).isqrt().pow(2).max(PILOT_SAMPLES);
        let full = || self.shadow_pass(r, index, lights, &cdf, samples, SEED);
        let mut rays = Rays::default();
        let Pass {
            arriving,
            visible,
            counts,
            ..
        } = if pilot_n >= samples {
            rays.traced = samples as u64;
            full()
        } else {
            let pilot = self.shadow_pass(r, index, lights, &cdf, pilot_n, PILOT_SEED);
            let carried: usize = pilot.counts.iter().sum();
            rays.traced = pilot_n as u64;
            if carried > 0 && (pilot.seen == 0 || pilot.seen == carried) {
                rays.settled = true;
                pilot
            } else {
                rays.traced += samples as u64;
                full()
            }
        };
        // A group no light-carrying sample reached takes the fraction of all samples; failing
        // that, 1.
        let (a, v) =
            (0..lights.len()).fold((0.0, 0.0), |(a, v), j| (a + arriving[j], v + visible[j]));
        let pooled = if a > 0.0 {
            (v / a).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let mut light = [0.0f64; 3];
        for (j, l) in lights.iter().enumerate() {
            let fraction = if counts[j] > 0 && arriving[j] > 0.0 {
                (visible[j] / arriving[j]).clamp(0.0, 1.0)
            } else {
                pooled
            };
            let u = unoccluded(l);
            for c in 0..3 {
                light[c] += u[c] * fraction;
            }
        }
        (light, rays)
    }

    /// `n` shadow rays of the receiver (a square count), stream `seed`: per group of `lights`
    /// (chosen by `cdf`), the unoccluded and visible sums of the samples' contributions and the
    /// number of light-carrying samples, and how many of those were visible.
    fn shadow_pass(
        &self,
        r: &Element,
        index: u64,
        lights: &[GroupLight],
        cdf: &[f64],
        n: usize,
        seed: u64,
    ) -> Pass {
        let mut arriving = vec![0.0f64; lights.len()];
        let mut visible = vec![0.0f64; lights.len()];
        let mut counts = vec![0usize; lights.len()];
        let mut seen_count = 0;
        let k = n.isqrt();
        let inv_k = 1.0 / k as f64;
        let inv_n = 1.0 / n as f64;
        let mut rng = Rng::new(seed, index);
        let mut choice_perm: Vec<u32> = (0..n as u32).collect();
        let mut point_perm: Vec<u32> = (0..n as u32).collect();
        for perm in [&mut choice_perm, &mut point_perm] {
            for a in (1..n).rev() {
                let b = rng.below(a as u64 + 1) as usize;
                perm.swap(a, b);
            }
        }
        for i in 0..n {
            // 1. A point on the receiver (stratum i).
            let x = point_on_triangle(
                &r.corners,
                (((i % k) as f64 + rng.next_f64()) * inv_k).min(1.0),
                (((i / k) as f64 + rng.next_f64()) * inv_k).min(1.0),
            );
            // 2. A group by its light here, a member by area (the choice's position within the
            //    group's interval, rescaled, keeps the strata), and a point on the member.
            let u = ((choice_perm[i] as f64 + rng.next_f64()) * inv_n).min(SAMPLE_BELOW_ONE);
            let j = interval_of(cdf, u);
            let low = if j == 0 { 0.0 } else { cdf[j - 1] };
            let probability = cdf[j] - low;
            if !(probability > 0.0) {
                continue;
            }
            let group = &self.groups[lights[j].group as usize];
            let k_s = group.pick(((u - low) / probability).clamp(0.0, SAMPLE_BELOW_ONE));
            let s = &self.emitters.geom[k_s];
            let cell = point_perm[i] as usize;
            let y = point_on_triangle(
                &s.corners,
                (((cell % k) as f64 + rng.next_f64()) * inv_k).min(1.0),
                (((cell / k) as f64 + rng.next_f64()) * inv_k).min(1.0),
            );
            // 3. Light that would arrive (both fronts facing), and whether it does. The point's
            //    density is probability / group area.
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
            let g = cos_x * cos_s / (PI * dist2) * group.area / probability;
            if !g.is_finite() {
                continue;
            }
            let emitter_patch = self.emitters.patch[k_s] as usize;
            arriving[j] += g;
            counts[j] += 1;
            if self
                .rays
                .visible(x, w_in, dist, r.patch as usize, emitter_patch)
            {
                visible[j] += g;
                seen_count += 1;
            }
        }
        Pass {
            arriving,
            visible,
            counts,
            seen: seen_count,
        }
    }
}

#[cfg(test)]
mod tests;
