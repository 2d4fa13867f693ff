//! The traversal of link refinement: which node pairs become cluster links, exact pairs or
//! culled pairs, and which leaves are split, in parallel rounds.

use rayon::prelude::*;

use super::{ClusterLink, LinkParams, LinkStats, NodePoint};
use crate::geometry::bins::Bins;
use crate::hierarchy::cost::{self as budget, LinkBudget, Meter, ModelCounts, OverBudget};
use crate::hierarchy::ClusterTree;
use crate::transport::CouplingParams;

/// Solid angle of a sphere of radius `r` whose centre is at distance `d`, conservatively large.
fn sphere_solid_angle(r: f64, d: f64) -> f64 {
    if d <= r {
        return 4.0 * std::f64::consts::PI;
    }
    let s = (r / d).min(1.0);
    2.0 * std::f64::consts::PI * (1.0 - (1.0 - s * s).sqrt())
}

/// The spread of a sender node in the disk kernel `1 / (d^2 + spread)`: `area / pi`, or the
/// mean squared distance of its surface from its centroid when that is larger, at most its
/// radius squared.
///
/// `area / pi` is the disk's radius squared, for which the kernel is exact on the disk's axis;
/// for well-shaped triangles and compact clusters it is the larger and nothing changes. The
/// mean square follows the sender's extent, not its area: a sliver of length `L` has
/// `L^2 / 12`, the first-order correction of the point kernel along a segment, where
/// `area / pi` is about 0 and left the point kernel's overestimate in place for thin senders.
/// Twice the mean square (the first-order value with both cosines) was tried: the closed-box
/// furnace at albedo 0.8 then came out 1.5% low (row sums below 1).
pub fn sender_spread(node: &crate::hierarchy::Node) -> f64 {
    (node.area / std::f64::consts::PI)
        .max(node.mean_square)
        .min(node.radius * node.radius)
}

/// The spread of a flat node in the kernels of [`super::NodePoint::kernel_toward`]: twice its
/// mean squared distance from its centroid, `4 sigma^2` for an in-plane variance `sigma^2` per
/// axis (a disk of radius `a`: `a^2`; a right triangle with legs `L`: `2 L^2 / 9`).
pub fn flat_spread(node: &crate::hierarchy::Node) -> f64 {
    2.0 * node.mean_square
}

/// Upper bound of the solid angle node `seen` subtends at any point of node `from`'s bounding
/// sphere: its bounding sphere's, and for a leaf triangle also `pi * area / gap^2`, `gap` the
/// distance between the two spheres (> 0).
///
/// `area / gap^2` alone is a bound (every surface point is at least `gap` away), and `pi`
/// times it stays above the sphere's for a triangle whose area is at least its radius squared
/// (well shaped), so it only decides for thin triangles: a sliver of aspect 100 has about
/// 1/100 of its sphere's solid angle. The room fan-triangulated into 4 slivers per triangle:
/// 9.6M links without it, 7.0M with it, the same error. Clusters keep the sphere: a sparse
/// cluster linked by its area (a chain of triangles seen along its length) misplaces its
/// light by its extent, not its solid angle (room error 2.2% -> 3.7% when clusters used it).
fn solid_angle_bound(seen: &crate::hierarchy::Node, from: &crate::hierarchy::Node, d: f64) -> f64 {
    let gap = d - seen.radius - from.radius;
    let sphere = sphere_solid_angle(seen.radius, d - from.radius);
    if !seen.is_leaf() {
        return sphere;
    }
    sphere.min(std::f64::consts::PI * seen.area / (gap * gap))
}

/// The distance between the bounds of nodes `a` and `b` (0 when they overlap).
fn box_gap(a: &crate::hierarchy::Node, b: &crate::hierarchy::Node) -> f64 {
    let apart = (a.bounds.0 - b.bounds.1)
        .max(b.bounds.0 - a.bounds.1)
        .max(glam::DVec3::ZERO);
    apart.length()
}

/// Upper bound of the solid angle node `seen` subtends at any point of a node whose bounds are
/// `gap` (> 0) from `seen`'s: at most three faces of `seen`'s bounds face a point outside
/// them, each subtending at most its area over the squared distance. A thin cluster (a chair
/// leg) subtends a small fraction of its bounding sphere's solid angle.
fn box_solid_angle_bound(seen: &crate::hierarchy::Node, gap: f64) -> f64 {
    let e = seen.bounds.1 - seen.bounds.0;
    let faces = e.y * e.z + e.x * e.z + e.x * e.y;
    (faces / (gap * gap)).min(4.0 * std::f64::consts::PI)
}

/// Largest solid angle leaf triangle `to` subtends at the corners and centroid of leaf `from`.
fn most_solid_angle(from: &crate::hierarchy::Node, to: &crate::hierarchy::Node) -> f64 {
    let [a, b, c] = from.corners;
    let points = crate::geometry::lanes_of(&[a, b, c, from.centroid]);
    let w = crate::geometry::solid_angle_lanes(&points, &to.corners);
    w.to_array().into_iter().fold(0.0, f64::max)
}

/// True when nothing can travel from S to R: S lies entirely in or behind the plane of every
/// triangle of R (front-only antiradiance; the plane of a flat R, the normal cone and height of a
/// curved one), or S lies in R's plane (either mode), both within [`crate::geometry::plane_tol`].
fn culled(tree: &ClusterTree, s: u32, r: u32, two_sided: bool) -> bool {
    let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
    let tol = crate::geometry::plane_tol(sn.radius + rn.radius);
    let Some((n, d)) = rn.plane else {
        // A curved receiver: culled when S lies behind the plane of every triangle of R (its
        // normal cone and height bound that), front-only mode.
        return !two_sided && tree.behind_all(s, r, tol);
    };
    // Largest and smallest signed distance of S to R's plane: from S's corners when S is a
    // triangle, else from its bounds and sphere.
    let (min_dist, max_dist) = crate::hierarchy::signed_extent(sn, n, d);
    // Behind R (front-only), or within the tolerance of R's plane (coplanar: either mode,
    // whichever way S faces; nothing in a plane exchanges with it).
    max_dist <= tol && (!two_sided || min_dist >= -tol)
}

/// The largest `area * solid angle` of a link the flux rule accepts
/// ([`LinkParams::flux_share`] times `epsilon` of `pi` times the scene's area).
pub(super) fn flux_limit(params: &LinkParams, tree: &ClusterTree) -> f64 {
    params.flux_share * params.epsilon * std::f64::consts::PI * tree.nodes[0].area
}

/// The flux of the pair (`sn` sending to `rn`) that the flux rule compares with its limit:
/// `min(A_r * omega_s, A_s * omega_r)`, the form-factor flux at the solid angles given (each an
/// upper bound of what that node subtends from the other), times the sender's
/// [`crate::hierarchy::Node::light`] (a sender brighter than the scene's typical surface
/// carries that much more).
fn pair_flux(
    sn: &crate::hierarchy::Node,
    rn: &crate::hierarchy::Node,
    omega_s: f64,
    omega_r: f64,
) -> f64 {
    (rn.area * omega_s).min(sn.area * omega_r) * f64::from(sn.light)
}

/// True when the pair (`sn`, `rn`) carries at most `flux_limit` whatever its shape and holds
/// no emitter: [`pair_flux`] `<= flux_limit`, each solid angle bounded by
/// what a node can subtend from anywhere outside its bounds at their gap (a triangle of area
/// `A` at distance at least `g`: `A / g^2`; a cluster: its bounds' faces), and by `pi` (the
/// projected solid angle a receiver can gather, so that tiny triangles are faint next to
/// anything). Such a pair splits no leaf ([`LinkParams::flux_share`]).
pub(super) fn faint(
    sn: &crate::hierarchy::Node,
    rn: &crate::hierarchy::Node,
    params: &LinkParams,
    flux_limit: f64,
) -> bool {
    if !(params.epsilon > 0.0 && flux_limit > 0.0) || sn.emits || rn.emits {
        return false;
    }
    let g = box_gap(sn, rn);
    let omega = |n: &crate::hierarchy::Node| {
        let apart = if g <= 0.0 {
            f64::INFINITY
        } else if n.is_leaf() {
            n.area / (g * g)
        } else {
            box_solid_angle_bound(n, g)
        };
        apart.min(std::f64::consts::PI)
    };
    pair_flux(sn, rn, omega(sn), omega(rn)) <= flux_limit
}

/// What the traversal found below some node pairs (one task's share, merged in pair order).
#[derive(Default)]
pub(super) struct Found {
    /// Cluster links as `receiver << 32 | sender` (the links are made once sorted).
    pub(super) cluster: Vec<u64>,
    /// (sender, receiver) node pairs to couple element by element.
    pub(super) exact: Vec<(u32, u32)>,
    /// Pairs that exchange nothing (kept only when `record_culled`).
    pub(super) culled: Vec<(u32, u32)>,
    /// Pairs waiting for a leaf to be split: (sender, receiver, split the sender?).
    pub(super) deferred: Vec<(u32, u32, bool)>,
    pub(super) stats: LinkStats,
}

impl Found {
    /// The pieces' findings in order, each array concatenated once (into exact capacity),
    /// freeing each piece's array as soon as it is copied (so the peak is the result plus one
    /// piece, not twice the result: 52M cluster-link keys at 1M triangles are 0.4 GB). Their
    /// deferred pairs must have been taken (they are between rounds); the exact-pair counts are
    /// made from the final pairs.
    pub(super) fn concat(mut pieces: Vec<Found>) -> Found {
        fn gather<T: Copy>(
            pieces: &mut [Found],
            field: impl Fn(&mut Found) -> &mut Vec<T>,
        ) -> Vec<T> {
            let mut all = Vec::with_capacity(pieces.iter_mut().map(|p| field(p).len()).sum());
            for p in pieces.iter_mut() {
                all.extend_from_slice(&std::mem::take(field(p)));
            }
            all
        }
        let mut stats = LinkStats::default();
        for p in &pieces {
            stats.culled_pairs += p.stats.culled_pairs;
            stats.silent_links += p.stats.silent_links;
        }
        Found {
            cluster: gather(&mut pieces, |p| &mut p.cluster),
            exact: gather(&mut pieces, |p| &mut p.exact),
            culled: gather(&mut pieces, |p| &mut p.culled),
            deferred: Vec::new(),
            stats,
        }
    }
}

/// The fixed inputs of one traversal.
struct Traversal<'a> {
    tree: &'a ClusterTree,
    params: &'a LinkParams,
    coupling: &'a CouplingParams,
    record_culled: bool,
    /// Largest sender solid angle of a cluster link (steradians).
    limit: f64,
    /// Largest `area * solid angle` of a link accepted by [`LinkParams::flux_share`].
    flux_limit: f64,
    /// Counts what the round's tasks record against the memory budget.
    meter: &'a Meter<'a>,
}

impl Traversal<'_> {
    /// Decides one node pair: records it in `found` (a link, exact pair, culled pair, or a pair
    /// waiting for a leaf split), or hands the pairs it splits into to `push`. Reads the tree
    /// only: a leaf that must be split is deferred to the caller, which splits it between rounds.
    fn visit(&self, (s, r): (u32, u32), found: &mut Found, mut push: impl FnMut((u32, u32))) {
        let (tree, params, coupling) = (self.tree, self.params, self.coupling);
        // Self pair: a leaf does not exchange with itself; a cluster's children exchange pairwise.
        if s == r {
            let node = &tree.nodes[s as usize];
            if node.is_leaf() {
                // Recorded so that validation knows the pieces of this triangle, should it be split
                // later, exchange nothing among themselves (they are coplanar).
                if self.record_culled {
                    found.culled.push((s, s));
                }
                return;
            }
            let (first, count) = (node.first_child, node.child_count as u32);
            for a in first..first + count {
                for b in first..first + count {
                    push((a, b));
                }
            }
            return;
        }
        if culled(
            tree,
            s,
            r,
            coupling.two_sided || tree.nodes[r as usize].blocks_back,
        ) {
            found.stats.culled_pairs += 1;
            if self.record_culled {
                found.culled.push((s, r));
            }
            return;
        }
        let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
        let d = (rn.center - sn.center).length();
        let gap = d - sn.radius - rn.radius;
        if params.epsilon > 0.0 && gap > 0.0 {
            let small = |omega_s: f64, omega_r: f64| {
                omega_s <= self.limit && omega_r <= params.receiver_factor * self.limit
            };
            // Two triangles at least leaf_gap / epsilon receiver diameters apart: the receiver's
            // one point integrates the exchange well (finer epsilon asks more), and the
            // triangles' own solid angles (largest over the other's corners and centroid)
            // replace the bounding spheres' (which overestimate a triangle's by 2.4x or more;
            // the sphere test is tried first: it is cheaper and implies the exact one).
            let leaf_pair = sn.is_leaf()
                && rn.is_leaf()
                && gap * params.epsilon >= params.leaf_gap * 2.0 * rn.radius;
            let (omega_s, omega_r) = (solid_angle_bound(sn, rn, d), solid_angle_bound(rn, sn, d));
            // The flux rule bounds the light a link carries, so it takes the tighter of the
            // spheres' and the bounds' solid angles (a thin cluster, a chair leg, subtends a
            // small part of its sphere's). Where only the bounds are apart (two legs side by
            // side) it does not apply: a receiver inside the sender's sphere evaluates it badly
            // (a 1e-6-wide strip in a lit box 7% off, the sliver furnace 0.8%).
            let boxes_apart = box_gap(sn, rn);
            let (flux_s, flux_r) = if boxes_apart > 0.0 {
                (
                    omega_s.min(box_solid_angle_bound(sn, boxes_apart)),
                    omega_r.min(box_solid_angle_bound(rn, boxes_apart)),
                )
            } else {
                (omega_s, omega_r)
            };
            if small(omega_s, omega_r)
                || (leaf_pair && small(most_solid_angle(rn, sn), most_solid_angle(sn, rn)))
                || pair_flux(sn, rn, flux_s, flux_r) <= self.flux_limit
            {
                self.link((s, r), found);
                return;
            }
        }
        // Too coarse: split the larger node. A leaf triangle is split (into sub-triangles) only
        // when even its smallest piece would be as large as its partner, and it is larger than
        // the gap between them (a coarse floor under a small object), above the resolution
        // floor, never among similar neighbours, and never for a faint pair (the light it
        // carries is within the flux rule's share whatever its geometry: its leaves are coupled
        // exactly as they are). Measured by the pieces rather than by twice the partner's
        // radius, no piece is then split back because of its partner: two neighbours whose
        // pieces shrink by different factors (a sliver's by more than 2) cannot split each
        // other in turn down to the resolution floor.
        let faint = self.faint(sn, rn);
        // Spheres apart, the flux rule above has decided; overlapping, a faint pair is one link
        // when asked ([`LinkParams::faint_links`]).
        if faint && params.faint_links && params.epsilon > 0.0 && gap <= 0.0 {
            self.link((s, r), found);
            return;
        }
        let leaf_splittable = |n: &crate::hierarchy::Node, other: &crate::hierarchy::Node| {
            params.epsilon > 0.0
                && !faint
                && n.split_depth < params.max_split_depth
                && n.radius > params.min_radius
                && n.piece_radius >= other.radius
                && n.radius > gap.max(0.0)
        };
        let s_can = !sn.is_leaf() || leaf_splittable(sn, rn);
        let r_can = !rn.is_leaf() || leaf_splittable(rn, sn);
        let split_s = match (s_can, r_can) {
            (false, false) => {
                found.exact.push((s, r));
                return;
            }
            (true, false) => true,
            (false, true) => false,
            (true, true) => sn.radius >= rn.radius,
        };
        if tree.nodes[if split_s { s } else { r } as usize].is_leaf() {
            found.deferred.push((s, r, split_s));
            return;
        }
        split_pair(tree, (s, r), split_s, push);
    }

    /// Records the cluster link from `s` to `r`, unless it is silent. Receivers evaluate a
    /// cluster link at their elements' centroids with the direction from the sender's
    /// centroid, and (front-only) take nothing that arrives at their back: a link whose sender
    /// centroid lies behind every plane below the receiver adds exactly nothing. Such links are
    /// dropped (as culled).
    fn link(&self, (s, r): (u32, u32), found: &mut Found) {
        if silent(self.tree, s, r, self.coupling.two_sided) {
            found.stats.silent_links += 1;
            if self.record_culled {
                found.culled.push((s, r));
            }
            return;
        }
        found.cluster.push(u64::from(r) << 32 | u64::from(s));
    }

    /// [`faint`] with this traversal's limit.
    fn faint(&self, sn: &crate::hierarchy::Node, rn: &crate::hierarchy::Node) -> bool {
        faint(sn, rn, self.params, self.flux_limit)
    }

    /// Everything below `pairs`, in parallel, appended to `pieces`: each task walks its pairs
    /// depth first; the pieces are in the order of `pairs` (so what they hold, once
    /// concatenated, does not depend on scheduling).
    ///
    /// Every [`budget::CHECK_EVERY`] visits a task adds what it recorded to the meter; once the
    /// meter is over the budget every task stops (what they hold is then discarded).
    fn run(&self, pairs: &[(u32, u32)], pieces: &mut Vec<Found>) {
        let found: Vec<Found> = pairs
            .par_iter()
            .fold(
                || (Found::default(), Vec::new(), (0, 0), 0usize),
                |(mut found, mut stack, mut reported, mut visits), &pair| {
                    if self.meter.is_over() {
                        return (found, stack, reported, visits);
                    }
                    stack.push(pair);
                    while let Some(p) = stack.pop() {
                        self.visit(p, &mut found, |q| stack.push(q));
                        visits += 1;
                        if visits % budget::CHECK_EVERY == 0 {
                            let now = (found.cluster.len(), found.exact.len());
                            let fits = self.meter.add(
                                (now.0 - reported.0) as u64,
                                (now.1 - reported.1) as u64,
                                0,
                                0,
                            );
                            reported = now;
                            if !fits {
                                stack.clear();
                            }
                        }
                    }
                    (found, stack, reported, visits)
                },
            )
            .map(|(found, ..)| found)
            .collect();
        pieces.extend(found);
    }
}

/// Hands `push` the pairs node pair (s, r) splits into: the children of `s` against `r` when
/// `split_s`, else `s` against the children of `r`.
fn split_pair(
    tree: &ClusterTree,
    (s, r): (u32, u32),
    split_s: bool,
    mut push: impl FnMut((u32, u32)),
) {
    let n = &tree.nodes[if split_s { s } else { r } as usize];
    for c in n.first_child..n.first_child + n.child_count as u32 {
        push(if split_s { (c, r) } else { (s, c) });
    }
}

/// True when the cluster link from node `s` to node `r` adds exactly nothing: receivers take
/// nothing arriving at their back (front-only, neither `two_sided` nor blocking `r`'s back), and
/// the sender's centroid lies behind every plane below the receiver.
pub fn silent(tree: &ClusterTree, s: u32, r: u32, two_sided: bool) -> bool {
    let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
    !two_sided
        && !rn.blocks_back
        && tree.point_behind_all(
            sn.centroid,
            r,
            crate::geometry::plane_tol(sn.radius + rn.radius),
            16,
        )
}

/// The cluster link from node `s` to node `r`.
pub fn cluster_link(tree: &ClusterTree, bins: &Bins, s: u32, r: u32) -> ClusterLink {
    let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
    let w = (rn.centroid - sn.centroid).normalize_or_zero();
    ClusterLink {
        sender: s,
        receiver: r,
        bin: bins.bin_of(w) as u16,
    }
}

/// The [`NodePoint`] of every node of `tree`.
pub(super) fn node_points(tree: &ClusterTree) -> Vec<NodePoint> {
    tree.nodes
        .par_iter()
        .map(|n| NodePoint {
            centroid: n.centroid.as_vec3().to_array(),
            spread: if n.plane.is_some() {
                flat_spread(n)
            } else {
                sender_spread(n)
            } as f32,
            disk_spread: sender_spread(n) as f32,
            normal: n
                .plane
                .map_or([0.0; 3], |(normal, _)| normal.as_vec3().to_array()),
        })
        .collect()
}

/// The gap between the bounding spheres of nodes `s` and `r` (negative when they overlap).
pub(super) fn sphere_gap(tree: &ClusterTree, s: u32, r: u32) -> f64 {
    let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
    (rn.center - sn.center).length() - sn.radius - rn.radius
}

/// Node pairs handed to the parallel traversal at a time, at least (the tree's top is expanded
/// breadth first until there are this many).
const PARALLEL_PAIRS: usize = 16384;

/// The traversal's rounds (see [`super::refine`]): each walks its node pairs in parallel over a
/// read-only tree, deferring the pairs that need a leaf triangle split; between rounds those
/// leaves are split (in a fixed order) and the deferred pairs continue below them. Returns what
/// the tasks found, in pair order, and the number of leaves split.
pub(super) fn rounds(
    tree: &mut ClusterTree,
    bins: &Bins,
    params: &LinkParams,
    coupling: &CouplingParams,
    record_culled: bool,
    budget: &LinkBudget,
) -> Result<(Vec<Found>, u64), OverBudget> {
    let mut pieces: Vec<Found> = Vec::new();
    let mut leaf_splits = 0;
    let mut pairs: Vec<(u32, u32)> = vec![(0, 0)];
    while !pairs.is_empty() {
        let held = ModelCounts {
            nodes: tree.nodes.len() as u64,
            elements: tree.nodes.iter().filter(|n| n.is_leaf()).count() as u64,
            cluster_links: pieces.iter().map(|p| p.cluster.len() as u64).sum(),
            exact_pairs: pieces.iter().map(|p| p.exact.len() as u64).sum(),
            ..ModelCounts::default()
        };
        budget.check(&held)?;
        let meter = Meter::new(budget, held);
        let traversal = Traversal {
            tree,
            params,
            coupling,
            record_culled,
            limit: params.epsilon * bins.mean_solid_angle(),
            flux_limit: flux_limit(params, tree),
            meter: &meter,
        };
        // 1. Expand the top breadth first until there is work for every thread.
        let mut queue: std::collections::VecDeque<(u32, u32)> = pairs.drain(..).collect();
        let mut top = Found::default();
        while queue.len() < PARALLEL_PAIRS {
            let Some(pair) = queue.pop_front() else {
                break;
            };
            traversal.visit(pair, &mut top, |q| queue.push_back(q));
        }
        let first_piece = pieces.len();
        pieces.push(top);
        // 2. Everything below, in parallel.
        traversal.run(queue.make_contiguous(), &mut pieces);
        if meter.is_over() {
            return Err(meter.over_budget());
        }
        // 3. Split the leaves this round's deferred pairs wait for (in node order), and continue
        //    below them next round.
        let deferred: Vec<(u32, u32, bool)> = pieces[first_piece..]
            .iter_mut()
            .flat_map(|p| std::mem::take(&mut p.deferred))
            .collect();
        let mut to_split: Vec<u32> = deferred
            .iter()
            .map(|&(s, r, split_s)| if split_s { s } else { r })
            .collect();
        to_split.sort_unstable();
        to_split.dedup();
        for &node in &to_split {
            tree.split_leaf(node);
        }
        leaf_splits += to_split.len() as u64;
        for (s, r, split_s) in deferred {
            split_pair(tree, (s, r), split_s, |q| pairs.push(q));
        }
        // 4. Exact pairs recorded against a leaf that is now split are decided again next round,
        //    below its pieces (where a serial walk that met the split first would have gone).
        if !to_split.is_empty() {
            let mut is_split = vec![false; tree.nodes.len()];
            for &node in &to_split {
                is_split[node as usize] = true;
            }
            for piece in &mut pieces {
                piece.exact.retain(|&(s, r)| {
                    let redo = is_split[s as usize] || is_split[r as usize];
                    if redo {
                        pairs.push((s, r));
                    }
                    !redo
                });
            }
        }
    }
    Ok((pieces, leaf_splits))
}
