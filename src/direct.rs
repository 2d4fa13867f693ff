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
//!   edge to edge with the same emission and normal form an [`EmitterGroup`] whose members'
//!   far-field terms are one contour sum over the group's boundary (exactly the members' sum),
//!   so a light made of hundreds of triangles costs about as much as its rim;
//! - the visible fraction comes from shadow rays: stratified points on the element, emitter
//!   groups chosen in proportion to their unoccluded light at this element (so a receiver beside
//!   a small light aims its rays at that light, not at the scene's most powerful one), members
//!   by area, stratified points on the member; each sample's unoccluded contribution `f_i` is
//!   weighed by its visibility `V_i`, and each group's fraction is `sum f_i V_i / sum f_i` over
//!   its samples (a ratio estimator: its bias falls as 1/samples); groups with fewer than
//!   [`GROUP_SAMPLES`] samples share one fraction.
//!
//! Fully lit elements get exactly `U`, elements in umbra exactly 0, a well-sampled light wholly
//! seen or wholly hidden counts fully or not at all; noise is confined to penumbrae.
//! (Subtracting a Monte Carlo estimate of the blocked light from `U` instead, an unbiased
//! control variate, leaves noise of either sign in umbrae.)
//!
//! Sampling is seeded per element (the element's index), so results are reproducible and do not
//! depend on thread scheduling. Shadow rays use the watertight test of [`crate::raytrace`].

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::budget::{self, Budget};
use crate::dense;
use crate::error::Result;
use crate::geometry::{self, plane_tol, PLANE_EPS};
use crate::health::FailureKind;
use crate::hierarchical::{Element, Prepared};
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::raytrace::RayScene;
use crate::sampling::{point_on_triangle, Rng};
use crate::solution::{Solution, SolveStats};
use crate::solve::{emission_bound, finish, SolverOptions};
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

/// Most shadow rays a direct-light pass may need at [`MIN_SHADOW_SAMPLES`] per receiver; above
/// it (more than half a million receivers) the solvers skip exact direct light (and say so): on
/// a 1M-triangle box the pass (at 64 rays per receiver) took longer than the whole
/// antiradiance solve.
pub const MAX_SHADOW_RAYS: u64 = 8_000_000;

/// Fewest shadow samples per receiving element (a square, for stratification).
pub const MIN_SHADOW_SAMPLES: usize = 16;

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
/// rays.
const PILOT_SAMPLES: usize = 16;

/// Seed of the pilot pass's per-element streams.
const PILOT_SEED: u64 = 0x5eed_d12e_c71d_0002;

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

/// Fewest light-carrying shadow samples that give an emitter group its own visible fraction;
/// groups with fewer share the fraction of all such groups' samples.
const GROUP_SAMPLES: usize = 16;

/// Seed of the per-element random streams (fixed: the direct light is deterministic).
const SEED: u64 = 0x5eed_d12e_c71d_0001;

/// The emitting patches.
struct Emitters {
    /// Patch index of each emitter.
    patch: Vec<u32>,
    /// Geometry of each emitter (unit frame).
    geom: Vec<PatchGeom>,
    /// Emitted radiance (normalized units).
    emission: Vec<[f64; 3]>,
}

impl Emitters {
    /// True when patch `p` is an emitter: active and emitting in some channel (positive area x
    /// largest channel).
    fn emits(patches: &Patches, p: usize) -> bool {
        let e = patches.emission[p];
        let w = patches.area[p] * e[0].max(e[1]).max(e[2]);
        patches.active[p] && w > 0.0 && w.is_finite()
    }

    /// The number of emitters [`Emitters::new`] finds.
    fn count(patches: &Patches) -> usize {
        (0..patches.len())
            .filter(|&p| Emitters::emits(patches, p))
            .count()
    }

    /// The active patches that emit in some channel.
    fn new(patches: &Patches) -> Emitters {
        let mut emitters = Emitters {
            patch: Vec::new(),
            geom: Vec::new(),
            emission: Vec::new(),
        };
        for p in 0..patches.len() {
            let e = patches.emission[p];
            if Emitters::emits(patches, p) {
                emitters.patch.push(p as u32);
                emitters
                    .geom
                    .push(PatchGeom::new(patches.corners[p], patches.normal[p]));
                emitters.emission.push(e);
            }
        }
        emitters
    }

    fn len(&self) -> usize {
        self.patch.len()
    }
}

/// One emitter group's unoccluded light at one receiver: what the receiver's shadow rays are
/// distributed by.
#[derive(Clone, Copy, Debug)]
struct GroupLight {
    /// Index into the groups.
    group: u32,
    /// The group's mean unoccluded form factor seen from the receiver (> 0).
    form_factor: f64,
}

/// Largest deviation between the normals of two emitters merged into one group (|n_a - n_b|,
/// about the angle in radians).
const GROUP_NORMAL_TOLERANCE: f64 = 1e-3;

/// A set of emitters joined edge to edge, with the same emission and (nearly) the same normal,
/// such as a ceiling light made of hundreds of triangles.
///
/// Seen from a point in front of every member and with every member in front of the point's
/// plane, the members' form factors sum to Lambert's contour sum over the group's boundary
/// only: each shared edge appears in its two triangles with opposite directions, and its two
/// terms cancel exactly (whatever the triangles' planes). So the group costs its boundary edges
/// instead of three edges per member.
struct EmitterGroup {
    /// Indices into [`Emitters`].
    members: Vec<u32>,
    /// Directed boundary edges (start, end), in the members' counter-clockwise order.
    boundary: Vec<(DVec3, DVec3)>,
    /// The members' corners without repeats (for the receiver-plane test).
    vertices: Vec<DVec3>,
    /// Area-weighted mean unit normal and centroid.
    normal: DVec3,
    centroid: DVec3,
    /// Largest |n_member - normal|.
    normal_spread: f64,
    /// Largest distance of a vertex from the mean plane.
    thickness: f64,
    /// Bounding sphere of the vertices: centre and radius.
    center: DVec3,
    radius: f64,
    /// Largest bounding-sphere radius of a member (about its centroid, as
    /// [`separation`] measures it).
    member_radius: f64,
    /// For each member (in `members` order) and each of its edges (corner i to i + 1), the
    /// member across that edge (its position in `members`), or [`NO_NEIGHBOUR`].
    neighbours: Vec<[u32; 3]>,
    /// Every directed edge belongs to one member at most, so any subset of the members is
    /// bounded by the edges it does not share with itself (what a group cut by a receiver's
    /// plane needs).
    manifold: bool,
    /// The members' common emission (normalized units).
    emission: [f64; 3],
    /// Total area of the members.
    area: f64,
    /// Cumulative area fraction of the members, in member order (last entry exactly 1): a
    /// shadow ray's member is chosen by area, so its point is uniform over the group.
    member_cdf: Vec<f64>,
}

impl EmitterGroup {
    /// The member (index into [`Emitters`]) whose cumulative area interval holds `u` in [0, 1).
    fn pick(&self, u: f64) -> usize {
        self.members[interval_of(&self.member_cdf, u)] as usize
    }
}

/// No member across this edge (see [`EmitterGroup::neighbours`]).
const NO_NEIGHBOUR: u32 = u32::MAX;

/// A point's bits as a hash key (with -0.0 folded into 0.0, so equal points give equal keys).
fn point_key(p: DVec3) -> [u64; 3] {
    [
        (p.x + 0.0).to_bits(),
        (p.y + 0.0).to_bits(),
        (p.z + 0.0).to_bits(),
    ]
}

/// Root of `i` in a union-find forest (with path halving).
fn find_root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Groups the emitters: two emitters join when they share an edge traversed in opposite
/// directions (bit-identical end points), emit exactly the same radiance and have normals within
/// [`GROUP_NORMAL_TOLERANCE`]. Every emitter is in exactly one group (often alone).
fn group_emitters(emitters: &Emitters) -> Vec<EmitterGroup> {
    use std::collections::HashMap;
    let n = emitters.len();
    // 1. Union over shared edges.
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let mut edge_owner: HashMap<([u64; 3], [u64; 3]), u32> = HashMap::new();
    for (k, g) in emitters.geom.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (point_key(g.corners[i]), point_key(g.corners[(i + 1) % 3]));
            edge_owner.insert((a, b), k as u32);
        }
    }
    for (k, g) in emitters.geom.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (point_key(g.corners[i]), point_key(g.corners[(i + 1) % 3]));
            let Some(&other) = edge_owner.get(&(b, a)) else {
                continue;
            };
            let o = other as usize;
            if o == k
                || emitters.emission[o] != emitters.emission[k]
                || (emitters.geom[o].normal - g.normal).length() > GROUP_NORMAL_TOLERANCE
            {
                continue;
            }
            let (ra, rb) = (
                find_root(&mut parent, k as u32),
                find_root(&mut parent, other),
            );
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        }
    }
    // 2. Members per group, in emitter order.
    let mut members_of: HashMap<u32, Vec<u32>> = HashMap::new();
    for k in 0..n as u32 {
        let root = find_root(&mut parent, k);
        members_of.entry(root).or_default().push(k);
    }
    let mut roots: Vec<u32> = members_of.keys().copied().collect();
    roots.sort_unstable();
    // 3. Boundary, plane and bounds of each group.
    roots
        .into_iter()
        .map(|root| {
            let members = members_of.remove(&root).unwrap_or_default();
            // Directed edge (start key, end key) -> (start, end, copies).
            type DirectedEdges = HashMap<([u64; 3], [u64; 3]), (DVec3, DVec3, u32)>;
            let mut directed: DirectedEdges = HashMap::new();
            let mut vertices: HashMap<[u64; 3], DVec3> = HashMap::new();
            let mut normal_sum = DVec3::ZERO;
            let mut centroid_sum = DVec3::ZERO;
            let mut area = 0.0;
            for &m in &members {
                let g = &emitters.geom[m as usize];
                normal_sum += g.normal * g.area;
                centroid_sum += g.centroid * g.area;
                area += g.area;
                for i in 0..3 {
                    let (a, b) = (g.corners[i], g.corners[(i + 1) % 3]);
                    vertices.insert(point_key(a), a);
                    directed
                        .entry((point_key(a), point_key(b)))
                        .or_insert((a, b, 0))
                        .2 += 1;
                }
            }
            // An edge is interior when its reverse belongs to the group too: the pair cancels
            // (copies beyond a pair stay, so the sum always equals the members' sum).
            let mut boundary = Vec::new();
            let mut keys: Vec<_> = directed.keys().copied().collect();
            keys.sort_unstable();
            for key in keys {
                let (a, b, count) = directed[&key];
                let reverse = directed.get(&(key.1, key.0)).map_or(0, |e| e.2);
                for _ in 0..count.saturating_sub(reverse) {
                    boundary.push((a, b));
                }
            }
            let normal = normal_sum.normalize_or_zero();
            let centroid = centroid_sum / area;
            let mut vertex_list: Vec<([u64; 3], DVec3)> = vertices.into_iter().collect();
            vertex_list.sort_unstable_by_key(|v| v.0);
            let vertices: Vec<DVec3> = vertex_list.into_iter().map(|v| v.1).collect();
            let center = vertices.iter().copied().sum::<DVec3>() / vertices.len() as f64;
            let radius = vertices
                .iter()
                .map(|v| (*v - center).length())
                .fold(0.0, f64::max);
            let thickness = vertices
                .iter()
                .map(|v| normal.dot(*v - centroid).abs())
                .fold(0.0, f64::max);
            let normal_spread = members
                .iter()
                .map(|&m| (emitters.geom[m as usize].normal - normal).length())
                .fold(0.0, f64::max);
            let member_cdf = cumulative(members.iter().map(|&m| emitters.geom[m as usize].area));
            let member_radius = members
                .iter()
                .map(|&m| emitters.geom[m as usize].radius)
                .fold(0.0, f64::max);
            // Who is across each edge: the member owning its reverse.
            let edge_of = |m: u32, i: usize| {
                let c = emitters.geom[m as usize].corners;
                (point_key(c[i]), point_key(c[(i + 1) % 3]))
            };
            let mut owner: HashMap<([u64; 3], [u64; 3]), u32> = HashMap::new();
            let mut manifold = true;
            for (local, &m) in members.iter().enumerate() {
                for i in 0..3 {
                    manifold &= owner.insert(edge_of(m, i), local as u32).is_none();
                }
            }
            let neighbours: Vec<[u32; 3]> = members
                .iter()
                .map(|&m| {
                    [0, 1, 2].map(|i| {
                        let (a, b) = edge_of(m, i);
                        owner.get(&(b, a)).copied().unwrap_or(NO_NEIGHBOUR)
                    })
                })
                .collect();
            EmitterGroup {
                emission: emitters.emission[members[0] as usize],
                member_radius,
                neighbours,
                manifold,
                area,
                member_cdf,
                members,
                boundary,
                vertices,
                normal,
                centroid,
                normal_spread,
                thickness,
                center,
                radius,
            }
        })
        .collect()
}

/// Lambert's contour sum for a closed set of directed edges seen from `x` (normal `n_x`): the
/// form factor of any surface they bound that lies in front of `x` and faces it, in [0, 1].
/// The same sum as [`geometry::point_form_factor`] over each of the surface's triangles.
fn contour_form_factor(x: DVec3, n_x: DVec3, edges: &[(DVec3, DVec3)]) -> f64 {
    geometry::lambert_form_factor(
        edges
            .iter()
            .map(|&(a, b)| geometry::lambert_edge(a - x, b - x, n_x))
            .sum(),
    )
}

/// The cumulative distribution of `weights` (not all 0, finite), the last entry exactly 1.
fn cumulative(weights: impl Iterator<Item = f64>) -> Vec<f64> {
    let weights: Vec<f64> = weights.collect();
    let total: f64 = weights.iter().sum();
    let mut cdf: Vec<f64> = weights
        .iter()
        .scan(0.0, |acc, w| {
            *acc += w / total;
            Some(*acc)
        })
        .collect();
    if let Some(last) = cdf.last_mut() {
        *last = 1.0;
    }
    cdf
}

/// The entry of `cdf` (from [`cumulative`]) whose interval holds `u` in [0, 1).
fn interval_of(cdf: &[f64], u: f64) -> usize {
    cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
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

/// Mean shadow samples per receiver for `receivers` receivers: the ray budget spread evenly,
/// clamped, rounded down to a square k x k.
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
        let emitters = Emitters::new(patches);
        DirectLight {
            patches,
            groups: group_emitters(&emitters),
            emitters,
            rays: RayScene::new(patches),
            samples: shadow_samples(receivers),
        }
    }

    /// Mean shadow samples per receiving element.
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
            "direct light: {} receivers x {} emitters, {} shadow rays each on average",
            receivers.len(),
            self.emitters.len(),
            self.samples
        ));
        // 1. Every receiver's unoccluded light, and the groups it comes from.
        let unoccluded: Vec<(Vec<GroupLight>, [f64; 3])> = receivers
            .par_iter()
            .map_init(Vec::new, |whole, r| {
                let rho = self.patches.albedo[r.patch as usize];
                if self.emitters.len() == 0 || !(r.area > 0.0) || rho.iter().all(|&x| x <= 0.0) {
                    return (Vec::new(), [0.0; 3]);
                }
                let mut lights = Vec::new();
                let u = self.unoccluded(r, &mut lights, whole);
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
        // 3. The visible part of it.
        receivers
            .par_iter()
            .zip(&unoccluded)
            .zip(&weight)
            .enumerate()
            .map(|(index, ((r, (lights, u)), &w))| {
                if u.iter().all(|&x| x <= 0.0) {
                    return [0.0; 3];
                }
                let rho = self.patches.albedo[r.patch as usize];
                let visible = self.visible_light(r, index as u64, lights, samples_of(w));
                [0, 1, 2].map(|c| {
                    let d = rho[c] * visible[c];
                    if d.is_finite() {
                        d.max(0.0)
                    } else {
                        0.0
                    }
                })
            })
            .collect()
    }

    /// True when `receivers` receivers would cost more than [`DIRECT_LIGHT_BUDGET`] unoccluded
    /// form-factor terms against the emitter groups, or more than [`MAX_SHADOW_RAYS`] shadow
    /// rays at the fewest samples per receiver.
    pub fn over_budget(&self, receivers: usize) -> bool {
        receivers as u64 * self.group_count() as u64 > DIRECT_LIGHT_BUDGET
            || receivers as u64 * MIN_SHADOW_SAMPLES as u64 > MAX_SHADOW_RAYS
    }

    /// Number of emitter groups (see [`EmitterGroup`]); at most the number of emitters.
    pub fn group_count(&self) -> usize {
        self.groups.len()
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
        whole: &mut Vec<bool>,
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
                self.cut_group_form_factor(r, &receiver, group, whole)
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
    /// emitters). A cheap, conservative test (bounding sphere, plane margins).
    fn cannot_reach(&self, r: &Element, receiver: &PatchGeom, group: &EmitterGroup) -> bool {
        let tol = plane_tol(receiver.size.max(2.0 * group.radius));
        if r.normal.dot(group.center - r.corners[0]) <= tol - group.radius {
            return true;
        }
        r.corners.iter().all(|&c| {
            let margin = group.normal_spread * ((c - group.center).length() + group.radius)
                + group.thickness
                + tol;
            group.normal.dot(c - group.centroid) <= -margin
        })
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
        height(group.center) >= group.radius || group.vertices.iter().all(|&v| height(v) >= -tol)
    }

    /// Mean form factor of a group seen from the receiver, whose plane has the whole group in
    /// front of it (or, with `subset`, of the members marked in it, which must be wholly in
    /// front of it, the group manifold): the same quadrature as member by member (each
    /// member's receiver points from its own separation), computed as the contour sum at the
    /// receiver's centroid (every member at one point) plus, for the few near members that
    /// need more points, their own quadrature in place of their centroid value. Falls back to
    /// member by member when the centroid is not clearly in front of every member.
    fn group_form_factor(
        &self,
        r: &Element,
        receiver: &PatchGeom,
        group: &EmitterGroup,
        subset: Option<&[bool]>,
    ) -> f64 {
        let chosen = |i: usize| subset.is_none_or(|marked| marked[i]);
        let x = receiver.centroid;
        let height = group.normal.dot(x - group.centroid);
        let margin = group.normal_spread * ((x - group.center).length() + group.radius)
            + group.thickness
            + PLANE_EPS * group.radius;
        if height <= margin {
            return (group.members.iter().enumerate())
                .filter(|&(i, _)| chosen(i))
                .map(|(_, &k)| self.emitter_form_factor(r, receiver, k as usize))
                .sum();
        }
        let mut f = match subset {
            None => contour_form_factor(x, r.normal, &group.boundary),
            Some(marked) => {
                // The subset's rim: its members' edges whose neighbour is not in it (shared
                // edges cancel, as in the whole group's boundary).
                let mut sum = 0.0;
                for (i, &k) in group.members.iter().enumerate() {
                    if !marked[i] {
                        continue;
                    }
                    let c = self.emitters.geom[k as usize].corners;
                    for (j, &across) in group.neighbours[i].iter().enumerate() {
                        if across == NO_NEIGHBOUR || !marked[across as usize] {
                            sum += geometry::lambert_edge(c[j] - x, c[(j + 1) % 3] - x, r.normal);
                        }
                    }
                }
                geometry::lambert_form_factor(sum)
            }
        };
        // Every member's centroid lies in the group's sphere, so no member is nearer the
        // receiver's centroid than this; when that is far, every member's rule is one point.
        let nearest_gap = (x - group.center).length() - group.radius - group.member_radius;
        if nearest_gap > FAR_RATIO * receiver.size {
            return f.max(0.0);
        }
        for (i, &k) in group.members.iter().enumerate() {
            if !chosen(i) {
                continue;
            }
            let s = &self.emitters.geom[k as usize];
            let q = receiver_points(separation(receiver, s));
            if q == 1 {
                continue;
            }
            let mut near = 0.0;
            for piece in geometry::subdivide(&r.corners, q) {
                let y = geometry::centroid(&piece);
                if s.normal.dot(y - s.corners[0]) > 0.0 {
                    near += geometry::point_form_factor(y, r.normal, &s.corners);
                }
            }
            f += near / (q * q) as f64 - geometry::point_form_factor(x, r.normal, &s.corners);
        }
        f.max(0.0)
    }

    /// Mean form factor of a (manifold) group whose members the receiver's plane cuts: the
    /// members wholly in front of it together ([`Self::group_form_factor`] over that subset),
    /// those it cuts one by one (clipped), those behind it not at all. Exactly the members'
    /// sum, at the cost of the subset's rim instead of every member's form factor: a ceiling
    /// light cut by the plane of a cupboard's side cost 4M member form factors on the room.
    /// `whole` is scratch.
    fn cut_group_form_factor(
        &self,
        r: &Element,
        receiver: &PatchGeom,
        group: &EmitterGroup,
        whole: &mut Vec<bool>,
    ) -> f64 {
        whole.clear();
        let mut f = 0.0;
        let mut any_whole = false;
        for &k in &group.members {
            let s = &self.emitters.geom[k as usize];
            // The sides as `emitter_form_factor`'s clipping sees them.
            let tol = plane_tol(receiver.size.max(s.size));
            let height = geometry::plane_heights(&s.corners, r.corners[0], r.normal, tol);
            let in_front = height.iter().all(|&h| h >= 0.0)
                && height.iter().any(|&h| h > 0.0)
                && self.emitters.patch[k as usize] != r.patch;
            whole.push(in_front);
            if in_front {
                any_whole = true;
            } else if height.iter().any(|&h| h > 0.0) {
                f += self.emitter_form_factor(r, receiver, k as usize);
            }
        }
        if any_whole {
            f += self.group_form_factor(r, receiver, group, Some(whole));
        }
        f
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
        f / (q * q) as f64
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
    /// noise is confined to penumbrae. Groups with fewer than [`GROUP_SAMPLES`] light-carrying
    /// samples take the pooled fraction of all such groups' samples (failing that, of all
    /// samples; 1 when no sample carried light).
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
    ) -> [f64; 3] {
        let emission = |l: &GroupLight| self.groups[l.group as usize].emission;
        let unoccluded = |l: &GroupLight| emission(l).map(|e| e * l.form_factor);
        // The distribution over the groups that light this receiver.
        let weight = |l: &GroupLight| {
            let e = emission(l);
            l.form_factor * e[0].max(e[1]).max(e[2])
        };
        let total: f64 = lights.iter().map(weight).sum();
        if lights.is_empty() || !(total > 0.0 && total.is_finite()) {
            return lights.iter().fold([0.0; 3], |acc, l| {
                let u = unoccluded(l);
                [0, 1, 2].map(|c| acc[c] + u[c])
            });
        }
        let cdf = cumulative(lights.iter().map(weight));
        // A pilot of a quarter of the rays first; when they all agree (every ray that carries
        // light reaches it, or none does), the receiver is taken as wholly lit or wholly in
        // shadow.
        // (A receiver with too few rays for a smaller pilot gets them all at once.)
        let pilot_n = (samples / 4).isqrt().pow(2).max(PILOT_SAMPLES);
        let full = || self.shadow_pass(r, index, lights, &cdf, samples, SEED);
        let Pass {
            arriving,
            visible,
            counts,
            ..
        } = if pilot_n >= samples {
            full()
        } else {
            let pilot = self.shadow_pass(r, index, lights, &cdf, pilot_n, PILOT_SEED);
            let carried: usize = pilot.counts.iter().sum();
            if carried > 0 && (pilot.seen == 0 || pilot.seen == carried) {
                pilot
            } else {
                full()
            }
        };
        // Groups with few samples share the fraction of all such groups' samples (a ratio of a
        // handful of samples is noisy); failing that, of all samples; failing that, 1.
        let own = |j: usize| counts[j] >= GROUP_SAMPLES;
        let pool = |keep: &dyn Fn(usize) -> bool| {
            let (a, v) = (0..lights.len())
                .filter(|&j| keep(j))
                .fold((0.0, 0.0), |(a, v), j| (a + arriving[j], v + visible[j]));
            (a > 0.0).then(|| (v / a).clamp(0.0, 1.0))
        };
        let pooled = pool(&|j| !own(j))
            .or_else(|| pool(&|_| true))
            .unwrap_or(1.0);
        let mut light = [0.0f64; 3];
        for (j, l) in lights.iter().enumerate() {
            let fraction = if own(j) && arriving[j] > 0.0 {
                (visible[j] / arriving[j]).clamp(0.0, 1.0)
            } else {
                pooled
            };
            let u = unoccluded(l);
            for c in 0..3 {
                light[c] += u[c] * fraction;
            }
        }
        light
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
            let u = ((choice_perm[i] as f64 + rng.next_f64()) * inv_n).min(1.0 - f64::EPSILON);
            let j = interval_of(cdf, u);
            let low = if j == 0 { 0.0 } else { cdf[j - 1] };
            let probability = cdf[j] - low;
            if !(probability > 0.0) {
                continue;
            }
            let group = &self.groups[lights[j].group as usize];
            let k_s = group.pick(((u - low) / probability).clamp(0.0, 1.0 - f64::EPSILON));
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

/// Adds the analytic lights' reflected direct radiance ([`Patches::source`], per patch) to the
/// receivers' source.
fn add_light_source(patches: &Patches, receivers: &[Element], source: &mut [[f64; 3]]) {
    for (r, d) in receivers.iter().zip(source.iter_mut()) {
        if let Some(s) = patches.source.get(r.patch as usize) {
            for c in 0..3 {
                d[c] += s[c];
            }
        }
    }
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

/// The coarsening step recorded when the exact direct light does not fit the memory limit.
pub const DIRECT_LIGHT_OFF: &str = "exact direct light off";

/// The direct light of `patches` for `receivers` receivers when it fits `spare` bytes
/// ([`budget::direct_light_bytes`]: the shadow-ray scene and emitter groups are estimated
/// before they are built, each receiver's lights once the groups are known), with its estimate;
/// `None` when it does not fit.
fn direct_within(
    patches: &Patches,
    receivers: usize,
    spare: u64,
) -> Option<(DirectLight<'_>, u64)> {
    let (p, e, r) = (
        patches.len() as u64,
        Emitters::count(patches) as u64,
        receivers as u64,
    );
    if budget::direct_light_bytes(p, e, 0, Some(0)) > spare {
        return None;
    }
    let direct = DirectLight::new(patches, receivers);
    let bytes = budget::direct_light_bytes(p, e, r, Some(direct.group_count() as u64));
    (bytes <= spare).then_some((direct, bytes))
}

/// Solves the scene with the hierarchical solver and exact direct light: the reflected direct
/// light `D` per element (shadow rays) is the source of the antiradiance solve, which then
/// carries the indirect bounces only; the emission is added back at the end. The direct light
/// is skipped (`stats.direct_light_skipped`) when it would cost more than the work budget
/// ([`DirectLight::over_budget`]) or than the memory the model leaves (then
/// [`DIRECT_LIGHT_OFF`] is in `stats.memory.coarsened`).
/// Preconditions: `options.validate()` passed (`options.direct_light` itself is not read).
///
/// Errors: [`crate::Error::Memory`] as [`Prepared::new`].
pub fn solve_hierarchical_direct(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    let mut prepared = Prepared::new(patches, options, false)?;
    let receivers: Vec<Element> = prepared.elements().collect();
    let t_direct = std::time::Instant::now();
    let skip = |mut prepared: Prepared, step: Option<&str>| {
        prepared.note_memory(0, step);
        let (mut solution, _) = prepared.solve(patches, progress);
        solution.stats.direct_light_skipped = true;
        solution
    };
    let Some((direct, bytes)) = direct_within(patches, receivers.len(), prepared.spare_bytes())
    else {
        return Ok(skip(prepared, Some(DIRECT_LIGHT_OFF)));
    };
    if direct.over_budget(receivers.len()) {
        drop(direct);
        return Ok(skip(prepared, None));
    }
    prepared.note_memory(bytes, None);
    let mut source = direct.reflected(&receivers, progress);
    add_light_source(patches, &receivers, &mut source);
    drop(direct);
    prepared.timings.direct = t_direct.elapsed().as_secs_f64();
    let (reflected, state) = prepared.solve_with_source(patches, &source, None, progress);
    // `reflected` is R clamped and scaled; B is formed from the unclamped element values.
    let radiance = add_emission(patches, &receivers, state.radiance());
    Ok(finish(
        patches,
        radiance,
        without_negative_check(reflected.stats),
        options.clamp_negative,
        emission_bound(patches, options.antiradiance),
    ))
}

/// Solves the scene with the dense solver and exact direct light (the reflected direct light is
/// computed per patch and is the dense solve's source; the emission is added back at the end).
/// Skipped as in [`solve_hierarchical_direct`], the memory left being what the dense solver's
/// estimate leaves.
/// Preconditions: `options.validate()` passed (`options.direct_light` itself is not read).
///
/// Errors: [`crate::Error::Memory`] as [`dense::solve_dense`].
pub fn solve_dense_direct(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    let receivers = patch_receivers(patches);
    let budget = Budget::start(options.memory_limit_bytes);
    // The dense solve, and the copy of the patches that carries its source.
    let dense_bytes =
        budget::dense_bytes(patches.len() as u64, options.bins, options.near_quadrature)
            + patches.len() as u64 * 256;
    let skip = |step: Option<&str>| -> Result<Solution> {
        let mut solution = dense::solve_dense(patches, options, progress)?;
        solution.stats.direct_light_skipped = true;
        if let (Some(step), Some(memory)) = (step, solution.stats.memory.as_mut()) {
            memory.coarsened.push(step.to_string());
        }
        Ok(solution)
    };
    let Some((direct, _)) = direct_within(patches, receivers.len(), budget.spare(dense_bytes))
    else {
        return skip(Some(DIRECT_LIGHT_OFF));
    };
    if direct.over_budget(receivers.len()) {
        drop(direct);
        return skip(None);
    }
    let mut source = direct.reflected(&receivers, progress);
    add_light_source(patches, &receivers, &mut source);
    drop(direct);
    let mut with_source = patches.clone();
    with_source.source = Vec::new();
    with_source.emission = vec![[0.0; 3]; patches.len()];
    for (r, d) in receivers.iter().zip(&source) {
        with_source.emission[r.patch as usize] = *d;
    }
    let unclamped = SolverOptions {
        clamp_negative: false,
        ..options.clone()
    };
    let reflected = dense::solve_dense(&with_source, &unclamped, progress)?;
    // Back to normalized units (the solution was scaled by the scene's emission scale).
    let inv_scale = 1.0 / patches.emission_scale;
    let patch_reflected: Vec<[f64; 3]> = receivers
        .iter()
        .map(|r| reflected.patch_radiance[r.patch as usize].map(|x| x * inv_scale))
        .collect();
    let radiance = add_emission(patches, &receivers, &patch_reflected);
    Ok(finish(
        patches,
        radiance,
        without_negative_check(reflected.stats),
        options.clamp_negative,
        emission_bound(patches, options.antiradiance),
    ))
}

/// The statistics of the indirect solve without its negative-mass check, which is made again on
/// `B = E + R`, what the solve returns (R's negative mass against R's positive mass alone would
/// overstate it). Every other failure stays: in particular R beyond its own bound
/// `D_max / (1 - rho_max)`, far tighter than the emission's.
fn without_negative_check(mut stats: SolveStats) -> SolveStats {
    if stats
        .failure
        .as_ref()
        .is_some_and(|f| f.kind == FailureKind::NegativeMass)
    {
        stats.failure = None;
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::build_patches;
    use crate::scene::Scene;
    use crate::scenes;

    /// A 1 x 1 emitter (facing down, split into 4 x 4 x 2 triangles so it forms one group)
    /// over receivers in every relation to it: below, tilted, cutting its plane, beside it in its
    /// plane, above it (behind), touching its edge, and below it with their planes cutting it
    /// (between its triangles' corners, one of them close).
    fn grouped_scene() -> Scene {
        let v = DVec3::new;
        let light = [
            [v(0.0, 1.0, 0.0), v(1.0, 1.0, 0.0), v(1.0, 1.0, 1.0)],
            [v(0.0, 1.0, 0.0), v(1.0, 1.0, 1.0), v(0.0, 1.0, 1.0)],
        ];
        let mut corners: Vec<[DVec3; 3]> = Vec::new();
        let light_scene = scenes::subdivide(
            &Scene::from_triangles(&light, &[[0.0; 3]; 2], &[[1.0; 3]; 2]),
            4,
        );
        for t in 0..light_scene.len() {
            corners.push(light_scene.corners(t));
        }
        let emitters = corners.len();
        let receivers = [
            [v(0.2, 0.0, 0.2), v(0.8, 0.0, 0.8), v(0.8, 0.0, 0.2)], // below, facing up
            [v(-0.5, 0.2, 0.0), v(-0.5, 0.8, 1.0), v(-0.2, 0.0, 1.0)], // tilted, aside
            [v(0.5, 0.5, 0.0), v(0.5, 1.5, 0.0), v(0.5, 0.5, 1.0)], // cuts the light's plane
            [v(1.5, 1.0, 0.0), v(2.0, 1.0, 0.5), v(1.5, 1.0, 1.0)], // in its plane
            [v(0.2, 1.5, 0.2), v(0.2, 1.5, 0.8), v(0.8, 1.5, 0.2)], // above (behind it)
            [v(1.0, 1.0, 0.0), v(1.0, 0.0, 0.0), v(1.0, 1.0, 1.0)], // wall on its edge
            [v(0.3, 0.0, 0.1), v(0.3, 0.9, 0.1), v(0.3, 0.0, 0.9)], // below, its plane cuts it
            [v(0.62, 0.95, 0.0), v(0.62, 0.0, 1.0), v(0.62, 0.95, 1.0)], // near, cuts it
        ];
        corners.extend(receivers);
        let n = corners.len();
        let mut emission = vec![[0.0; 3]; n];
        emission[..emitters].fill([1.0; 3]);
        Scene::from_triangles(&corners, &vec![[0.5; 3]; n], &emission)
    }

    #[test]
    fn groups_give_the_sum_of_their_members() {
        let scene = grouped_scene();
        let patches = build_patches(&scene, None);
        let light = DirectLight::new(&patches, patches.len());
        assert_eq!(light.group_count(), 1, "the split light is one group");
        assert_eq!(
            light.groups[0].boundary.len(),
            4 * 4,
            "the square's rim, 4 x 4 edges"
        );
        for p in 0..patches.len() {
            let r = Element {
                corners: patches.corners[p],
                normal: patches.normal[p],
                area: patches.area[p],
                patch: p as u32,
            };
            let receiver = PatchGeom::new(r.corners, r.normal);
            let grouped = light.unoccluded(&r, &mut Vec::new(), &mut Vec::new())[0];
            let member_sum: f64 = (0..light.emitters.len())
                .map(|k| light.emitter_form_factor(&r, &receiver, k))
                .sum();
            assert!(
                (grouped - member_sum).abs() <= 1e-12 + 1e-9 * member_sum,
                "patch {p}: grouped {grouped} vs members {member_sum}"
            );
        }
    }
}

#[cfg(test)]
mod sampling_tests {
    use super::*;
    use crate::mesh::build_patches;
    use crate::scene::Scene;

    /// Reflected direct light of patch 0 (a unit receiver facing up at y = 0) in a scene of
    /// `corners` with `emission`, albedo 0.5 everywhere.
    fn direct_on_receiver(corners: &[[DVec3; 3]], emission: &[[f64; 3]]) -> f64 {
        let scene = Scene::from_triangles(corners, &vec![[0.5; 3]; corners.len()], emission);
        let patches = build_patches(&scene, None);
        let receivers = patch_receivers(&patches);
        let light = DirectLight::new(&patches, receivers.len());
        let reflected = light.reflected(&receivers, &Progress::hidden());
        let at = receivers.iter().position(|r| r.patch == 0).unwrap();
        reflected[at][0]
    }

    /// A small light just above a receiver, and a light ten million times as powerful hidden
    /// from it behind a plate: the hidden light must not change the receiver's direct light.
    /// (Shadow rays chosen by the emitters' power all went to the hidden light, found it
    /// blocked, and left the receiver dark: the bear lit by its own head was 11% off.)
    #[test]
    fn a_hidden_powerful_light_does_not_darken_a_receiver_lit_by_a_small_one() {
        let v = DVec3::new;
        let receiver = [v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(1.0, 0.0, 0.0)];
        let small = [v(0.3, 0.3, 0.3), v(0.4, 0.3, 0.3), v(0.3, 0.3, 0.4)];
        let square = |y: f64, half: f64, down: bool| {
            let (a, b, c, d) = (
                v(-half, y, -half),
                v(half, y, -half),
                v(half, y, half),
                v(-half, y, half),
            );
            if down {
                [[a, b, c], [a, c, d]]
            } else {
                [[a, c, b], [a, d, c]]
            }
        };
        let alone = direct_on_receiver(&[receiver, small], &[[0.0; 3], [1.0; 3]]);
        let [h0, h1] = square(20.0, 50.0, true);
        let [p0, p1] = square(10.0, 100.0, true);
        let hidden = direct_on_receiver(
            &[receiver, small, h0, h1, p0, p1],
            &[[0.0; 3], [1.0; 3], [1.0; 3], [1.0; 3], [0.0; 3], [0.0; 3]],
        );
        assert!(alone > 0.0);
        assert!(
            (hidden - alone).abs() <= 0.05 * alone,
            "with a hidden light {hidden}, without {alone}"
        );
    }
}

#[cfg(test)]
mod budget_tests {
    use super::*;
    use crate::mesh::build_patches;
    use crate::scenes;

    #[test]
    fn direct_light_budget_counts_receivers_times_groups() {
        let patches = build_patches(&scenes::cornell_box(), None);
        let direct = DirectLight::new(&patches, patches.len());
        let groups = direct.group_count() as u64;
        assert!(groups >= 1);
        assert!(!direct.over_budget(patches.len()));
        let limit = (DIRECT_LIGHT_BUDGET / groups).min(MAX_SHADOW_RAYS / MIN_SHADOW_SAMPLES as u64)
            as usize;
        assert!(!direct.over_budget(limit));
        assert!(direct.over_budget(limit + 1));
    }
}
