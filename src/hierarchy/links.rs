//! Stage 3b: link refinement. Every ordered pair of elements (leaf triangles) is covered by
//! exactly one link: a cluster link between two nodes that are small as seen from each other,
//! an exact element-to-element coupling, or a culled pair that exchanges nothing.

use rayon::prelude::*;

use crate::geometry::bins::Bins;
use crate::hierarchy::cost::{self as budget, LinkBudget, Meter, ModelCounts, OverBudget};
use crate::hierarchy::ClusterTree;
use crate::transport::{couple, Coupling, CouplingParams, Entry, PatchGeom, Receiver};

/// Parameters of link refinement.
#[derive(Clone, Copy, Debug)]
pub struct LinkParams {
    /// Largest solid angle either end of a cluster link may subtend from the other, as a
    /// fraction of the mean bin solid angle. Smaller: more, finer links. 0.25..2; 1 by default.
    /// 0 forces every link down to element pairs (the dense solver's couplings).
    pub epsilon: f64,
    /// Smallest bounding-sphere radius (unit frame: scene diameter 1) a triangle is split down
    /// to when a near neighbour needs it finer. 0.005..0.05; 0.02 by default (0.01 split the
    /// bear's graded mesh into twice its triangles for no measurable accuracy: 5.1M links,
    /// error 6.19%; 0.02: 3.25M links, same error, same room and Cornell box errors).
    pub min_radius: f64,
    /// Most times one patch may be split in four (two rounds of longest-edge bisection). 0..6;
    /// 4 by default (256 pieces).
    pub max_split_depth: u8,
    /// How much larger than the sender's the receiver's solid angle may be: receivers evaluate a
    /// link with each element's own direction and distance, so their extent costs little
    /// accuracy. 1..8; 4 by default.
    pub receiver_factor: f64,
    /// Two leaf triangles at least `leaf_gap / epsilon` receiver diameters apart (gap between
    /// their bounding spheres) are tested with their exact solid angles instead of their
    /// bounding spheres': such pairs become cluster links (the receiver's single point
    /// integrates them well) instead of costly exact couplings. Default 1.
    pub leaf_gap: f64,
    /// Largest share of the scene's transport a link may carry and still be accepted when it
    /// is geometrically too coarse: `min(A_r * omega_s, A_s * omega_r) / (pi * A_scene)`, both
    /// solid angles bounded from above, is the link's form-factor flux `A_r F_rs` (the light
    /// it carries in a scene of uniform radiance) over the scene's area. Hierarchical
    /// radiosity's BFA rule with uniform radiance: the error of a coarse link is at most the
    /// light it carries, and small receivers (furniture, slivers, a fan of pieces) carry little.
    /// It does not depend on the triangulation: splitting a triangle splits its links' shares.
    /// 0 turns the rule off. 0..1e-4; [`FLUX_SHARE`] by default.
    pub flux_share: f64,
}

impl LinkParams {
    /// The defaults, which are also the `default` solver preset's
    /// ([`crate::solve::SolverOptions::default_preset`] takes `epsilon` and `max_split_depth`
    /// from here).
    pub const DEFAULT: LinkParams = LinkParams {
        epsilon: 1.0,
        min_radius: 0.02,
        max_split_depth: 4,
        receiver_factor: 4.0,
        leaf_gap: 1.0,
        flux_share: FLUX_SHARE,
    };
}

impl Default for LinkParams {
    fn default() -> Self {
        LinkParams::DEFAULT
    }
}

/// The default [`LinkParams::flux_share`]. Seed room (default preset, against its 256-spp
/// path-traced reference): 0 gives 0.73M links and 2.27% error; 1e-5 0.55M links, 2.27%;
/// 3e-5 0.49M, 2.31%; 1e-4 0.29M, 2.63%. The Cornell box does not change. The generated
/// classroom (fast preset): 44.5M links at 0, 27.6M at 1e-5.
pub const FLUX_SHARE: f64 = 1e-5;

// The memory estimate of the links counts this size.
const _: () = assert!(std::mem::size_of::<ClusterLink>() as u64 == budget::CLUSTER_LINK_BYTES);

/// A cluster link: sender node S sends to receiver node R as one exchange along the direction
/// from S's area-weighted centroid to R's ([`Links::point`] holds both, with S's spread).
#[derive(Clone, Copy, Debug)]
pub struct ClusterLink {
    /// Sender node.
    pub sender: u32,
    /// Receiver node.
    pub receiver: u32,
    /// Direction bin of travel (sender centroid to receiver centroid).
    pub bin: u16,
}

/// What receivers read of a node when it sends along a cluster link, and where it sits when it
/// receives: its area-weighted centroid (receivers measure their own direction and distance
/// from it; a link's direction runs from the sender's to the receiver's) and its spread (see
/// [`sender_spread`]): receivers use the disk kernel `1 / (d^2 + spread)` instead of the point
/// kernel `1 / d^2`, which overestimates the exchange with a near, extended sender (form
/// factors of a closed room summing above 1).
#[derive(Clone, Copy, Debug, Default)]
pub struct NodePoint {
    /// The node's area-weighted centroid.
    pub centroid: [f32; 3],
    /// The node's [`sender_spread`].
    pub spread: f32,
}

impl NodePoint {
    /// The centroid in f64.
    #[inline]
    pub fn centroid(&self) -> glam::DVec3 {
        glam::DVec3::new(
            self.centroid[0] as f64,
            self.centroid[1] as f64,
            self.centroid[2] as f64,
        )
    }
}

/// The refined links, grouped by receiver.
#[derive(Clone, Debug, Default)]
pub struct Links {
    /// Cluster links sorted by receiver node.
    pub cluster: Vec<ClusterLink>,
    /// For each node, its incoming cluster links: `cluster[cluster_start[i]..cluster_start[i+1]]`.
    pub cluster_start: Vec<u32>,
    /// For each node, its centroid and spread as cluster links read them.
    pub point: Vec<NodePoint>,
    /// Exact element links: sender element per link, sorted by receiver element.
    pub exact_sender: Vec<u32>,
    /// Coupling entries of each exact link: `exact_entries[exact_entry_start[l]..[l+1]]`.
    pub exact_entry_start: Vec<u32>,
    /// All coupling entries, flat.
    pub exact_entries: Vec<Entry>,
    /// For each element, its incoming exact links: `exact_start[e]..exact_start[e+1]`.
    pub exact_start: Vec<u32>,
    /// Faces of each exact link ([`EXACT_SENDER_BACK`], [`EXACT_RECEIVER_BACK`]): empty when no
    /// element is two-sided (every link then joins the sender's front to the receiver's front).
    pub exact_side: Vec<u8>,
    /// Pairs of nodes found to exchange nothing (kept only when `record_culled` was asked).
    pub culled: Vec<(u32, u32)>,
    /// What refinement did (counts and times), for reports and profiling.
    pub stats: LinkStats,
}

/// Counts and times of one refinement (the JSON report's `stats.link_stats.refinement`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct LinkStats {
    /// Node pairs culled by the plane test.
    pub culled_pairs: u64,
    /// Cluster links dropped because they carry nothing to any receiving element (front-only:
    /// the sender's centroid is behind every receiving triangle).
    pub silent_links: u64,
    /// Leaf triangles split on demand.
    pub leaf_splits: u64,
    /// Exact pairs recorded during the traversal (before expanding split leaves).
    pub exact_pairs: u64,
    /// Exact pairs after expansion (element pairs coupled).
    pub exact_element_pairs: u64,
    /// Of those, pairs whose coupling turned out empty.
    pub exact_empty: u64,
    /// Exact pairs that overlap (gap <= 0 between the bounding spheres).
    pub exact_touching: u64,
    /// Exact pairs that are apart but failed the solid-angle test.
    pub exact_apart: u64,
    /// Receivers of exact links by quadrature points per side (index q - 1, last bin q >= 8).
    pub receivers_by_quadrature: [u64; 8],
    /// Receiver points integrated over all exact couplings (a far pair counts 1).
    pub quadrature_points: u64,
    /// Seconds in the traversal.
    pub traverse_seconds: f64,
    /// Seconds computing exact couplings.
    pub couple_seconds: f64,
    /// Seconds assembling the arrays.
    pub assemble_seconds: f64,
}

/// [`Links::exact_side`] bit: the link carries the sender's back face's radiance (its entries'
/// `f_b` and `o_b`; their antiradiance weights are in the front link).
pub const EXACT_SENDER_BACK: u8 = 1;
/// [`Links::exact_side`] bit: the link lights the receiver's back face (its entries' `f_b` and
/// `f_a`; the receiver's antiradiance is gathered by its front links).
pub const EXACT_RECEIVER_BACK: u8 = 2;

impl Links {
    /// The faces exact link `l` joins: (sender's back, receiver's back).
    #[inline]
    pub fn exact_faces_of(&self, l: usize) -> (bool, bool) {
        let side = self.exact_side.get(l).copied().unwrap_or(0);
        (
            side & EXACT_SENDER_BACK != 0,
            side & EXACT_RECEIVER_BACK != 0,
        )
    }

    /// The coupling entries of exact link `l`.
    ///
    /// # Panics
    /// When `l` is not an exact link's index.
    pub fn exact_entries_of(&self, l: usize) -> &[Entry] {
        &self.exact_entries
            [self.exact_entry_start[l] as usize..self.exact_entry_start[l + 1] as usize]
    }

    /// Total number of links (cluster + exact).
    pub fn len(&self) -> usize {
        self.cluster.len() + self.exact_sender.len()
    }

    /// True when there is no link at all.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes held by the link arrays.
    pub fn bytes(&self) -> u64 {
        (self.cluster.len() * std::mem::size_of::<ClusterLink>()
            + self.cluster_start.len() * 4
            + self.point.len() * std::mem::size_of::<NodePoint>()
            + self.exact_sender.len() * 8
            + self.exact_entries.len() * std::mem::size_of::<Entry>()
            + self.exact_start.len() * 4
            + self.exact_side.len()) as u64
    }
}

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

/// What the traversal found below some node pairs (one task's share, merged in pair order).
#[derive(Default)]
struct Found {
    /// Cluster links as `receiver << 32 | sender` (the links are made once sorted).
    cluster: Vec<u64>,
    /// (sender, receiver) node pairs to couple element by element.
    exact: Vec<(u32, u32)>,
    /// Pairs that exchange nothing (kept only when `record_culled`).
    culled: Vec<(u32, u32)>,
    /// Pairs waiting for a leaf to be split: (sender, receiver, split the sender?).
    deferred: Vec<(u32, u32, bool)>,
    stats: LinkStats,
}

impl Found {
    /// The pieces' findings in order, each array concatenated once (into exact capacity),
    /// freeing each piece's array as soon as it is copied (so the peak is the result plus one
    /// piece, not twice the result: 52M cluster-link keys at 1M triangles are 0.4 GB). Their
    /// deferred pairs must have been taken (they are between rounds); the exact-pair counts are
    /// made from the final pairs.
    fn concat(mut pieces: Vec<Found>) -> Found {
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
            if small(omega_s, omega_r)
                || (leaf_pair && small(most_solid_angle(rn, sn), most_solid_angle(sn, rn)))
                || (rn.area * omega_s).min(sn.area * omega_r) <= self.flux_limit
            {
                // Receivers evaluate a cluster link at their elements' centroids with the
                // direction from the sender's centroid, and (front-only) take nothing that
                // arrives at their back: a link whose sender centroid lies behind every plane
                // below the receiver adds exactly nothing. Such links are dropped (as culled).
                if !coupling.two_sided
                    && !rn.blocks_back
                    && tree.point_behind_all(
                        sn.centroid,
                        r,
                        crate::geometry::plane_tol(sn.radius + rn.radius),
                        16,
                    )
                {
                    found.stats.silent_links += 1;
                    if self.record_culled {
                        found.culled.push((s, r));
                    }
                    return;
                }
                found.cluster.push(u64::from(r) << 32 | u64::from(s));
                return;
            }
        }
        // Too coarse: split the larger node. A leaf triangle is split (into sub-triangles) only
        // when it is much larger than its partner and than the gap between them (a coarse floor
        // under a small object), above the resolution floor, never among similar neighbours.
        let leaf_splittable = |n: &crate::hierarchy::Node, other: &crate::hierarchy::Node| {
            params.epsilon > 0.0
                && n.split_depth < params.max_split_depth
                && n.radius > params.min_radius
                && n.radius > 2.0 * other.radius
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

/// The cluster link from node `s` to node `r`.
fn cluster_link(tree: &ClusterTree, bins: &Bins, s: u32, r: u32) -> ClusterLink {
    let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
    let w = (rn.centroid - sn.centroid).normalize_or_zero();
    ClusterLink {
        sender: s,
        receiver: r,
        bin: bins.bin_of(w) as u16,
    }
}

/// The [`NodePoint`] of every node of `tree`.
fn node_points(tree: &ClusterTree) -> Vec<NodePoint> {
    tree.nodes
        .par_iter()
        .map(|n| NodePoint {
            centroid: n.centroid.as_vec3().to_array(),
            spread: sender_spread(n) as f32,
        })
        .collect()
}

/// The gap between the bounding spheres of nodes `s` and `r` (negative when they overlap).
fn sphere_gap(tree: &ClusterTree, s: u32, r: u32) -> f64 {
    let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
    (rn.center - sn.center).length() - sn.radius - rn.radius
}

/// Node pairs handed to the parallel traversal at a time, at least (the tree's top is expanded
/// breadth first until there are this many).
const PARALLEL_PAIRS: usize = 16384;

/// Refines links over the whole tree, splitting leaf triangles where needed, then finalizes the
/// tree (element numbering) and computes exact couplings in parallel.
///
/// The traversal runs in rounds: each walks its node pairs in parallel over a read-only tree,
/// deferring the pairs that need a leaf triangle split; between rounds those leaves are split
/// (in a fixed order) and the deferred pairs continue below them. At most `max_split_depth + 1`
/// rounds.
///
/// Memory: the traversal counts the cluster links and exact pairs it records, the exact pairs
/// are counted before they are coupled and the coupling entries while they are; as soon as the
/// estimate of the finished model ([`budget::HierarchicalCosts::bytes`]) exceeds `budget`, the
/// refinement stops and returns [`OverBudget`] (the tree is then left part-split: rebuild it
/// before refining again).
pub fn refine(
    tree: &mut ClusterTree,
    bins: &Bins,
    params: &LinkParams,
    coupling: &CouplingParams,
    record_culled: bool,
    budget: &LinkBudget,
) -> Result<Links, OverBudget> {
    let t_start = std::time::Instant::now();
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
            flux_limit: params.flux_share * std::f64::consts::PI * tree.nodes[0].area,
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
    let Found {
        mut cluster,
        exact: exact_pairs,
        culled: culled_pairs,
        mut stats,
        ..
    } = Found::concat(pieces);
    stats.leaf_splits = leaf_splits;
    for &(s, r) in &exact_pairs {
        if sphere_gap(tree, s, r) > 0.0 {
            stats.exact_apart += 1;
        } else {
            stats.exact_touching += 1;
        }
    }
    tree.finalize();
    stats.exact_pairs = exact_pairs.len() as u64;
    let t_traversed = std::time::Instant::now();
    stats.traverse_seconds = (t_traversed - t_start).as_secs_f64();

    // Cluster links grouped by receiver node: the 8-byte keys sorted, then the links made.
    cluster.par_sort_unstable();
    let mut cluster_start = vec![0u32; tree.nodes.len() + 1];
    for &key in &cluster {
        cluster_start[(key >> 32) as usize + 1] += 1;
    }
    for i in 0..tree.nodes.len() {
        cluster_start[i + 1] += cluster_start[i];
    }

    // A leaf recorded in an exact pair may have been split afterwards (by another pair): the pair
    // then stands for all pairs of elements below its two nodes. Pairs as (receiver element,
    // sender element), grouped by receiver; each receiver integrates all its exact senders over
    // one fixed set of points.
    let held = ModelCounts {
        nodes: tree.nodes.len() as u64,
        elements: tree.elements.len() as u64,
        cluster_links: cluster.len() as u64,
        exact_pairs: exact_pairs
            .iter()
            .map(|&(s, r)| {
                let ((s0, s1), (r0, r1)) = (
                    tree.nodes[s as usize].elements,
                    tree.nodes[r as usize].elements,
                );
                u64::from(s1 - s0) * u64::from(r1 - r0)
            })
            .sum(),
        entries: Some(0),
        ..ModelCounts::default()
    };
    budget.check(&held)?;
    let meter = Meter::new(budget, held);
    let mut exact_pairs: Vec<(u32, u32)> = exact_pairs
        .into_iter()
        .flat_map(|(s, r)| {
            let (s0, s1) = tree.nodes[s as usize].elements;
            let (r0, r1) = tree.nodes[r as usize].elements;
            (r0..r1).flat_map(move |re| (s0..s1).map(move |se| (re, se)))
        })
        .collect();
    exact_pairs.sort_unstable();
    let n_elements = tree.elements.len();
    let geoms: Vec<PatchGeom> = tree
        .elements
        .par_iter()
        .map(|&node| {
            let n = &tree.nodes[node as usize];
            PatchGeom::new(n.corners, n.plane.map(|p| p.0).unwrap_or(glam::DVec3::Z))
                .blocking_back(n.blocks_back)
        })
        .collect();
    // Receivers' ranges in `exact_pairs`.
    let mut pair_start = vec![0u32; n_elements + 1];
    for &(r, _) in &exact_pairs {
        pair_start[r as usize + 1] += 1;
    }
    for e in 0..n_elements {
        pair_start[e + 1] += pair_start[e];
    }
    /// The exact links into one receiver: senders, entry counts, entries.
    #[derive(Default)]
    struct Row {
        senders: Vec<u32>,
        sides: Vec<u8>,
        counts: Vec<u32>,
        entries: Vec<Entry>,
        empty: Vec<u32>,
        q: usize,
        points: u64,
    }
    impl Row {
        /// Appends the link from sender `s` (faces `side`) with entries `entries`, unless empty.
        fn push(&mut self, s: u32, side: u8, entries: &[Entry]) {
            if entries.is_empty() {
                return;
            }
            self.senders.push(s);
            self.sides.push(side);
            self.counts.push(entries.len() as u32);
            self.entries.extend_from_slice(entries);
        }
    }
    /// The links of the faces other than front to front, for a pair where the receiver or the
    /// sender is two-sided: the sender's back (its B seen by the receiver points behind it:
    /// `f_b`, `o_b` of the flipped sender), the receiver's back (what its back face gathers:
    /// `f_b`, `f_a` of the flipped receiver), and both backs. The antiradiance weights the front
    /// link already holds are left out of the others.
    fn faces_coupled(
        (receiver, receiver_back): (&Receiver, Option<&Receiver>),
        (s, sender, sender_two_sided): (u32, &PatchGeom, bool),
        bins: &Bins,
        coupling: &CouplingParams,
        scratch: &mut Coupling,
        row: &mut Row,
    ) {
        // The sender's back is seen only from receiver points behind its plane, and the
        // receiver's back only sees what lies behind the receiver's plane.
        let behind = |of: &PatchGeom, corners: &[glam::DVec3; 3]| {
            let tol = crate::geometry::plane_tol(of.size.max(receiver.geom.size));
            corners
                .iter()
                .any(|&c| of.normal.dot(c - of.corners[0]) < -tol)
        };
        let flipped =
            (sender_two_sided && behind(sender, &receiver.geom.corners)).then(|| sender.flipped());
        let receiver_back = receiver_back.filter(|_| behind(&receiver.geom, &sender.corners));
        let keep = |scratch: &mut Coupling, radiance_only: bool, antiradiance_out: bool| {
            for e in scratch.iter_mut() {
                if radiance_only {
                    e.f_a = 0.0;
                    e.o_a = 0.0;
                }
                if !antiradiance_out {
                    e.o_b = 0.0;
                    e.o_a = 0.0;
                }
            }
            scratch.retain(|e| e.f_b != 0.0 || e.f_a != 0.0 || e.o_b != 0.0 || e.o_a != 0.0);
        };
        if let Some(back) = &flipped {
            couple(receiver, back, bins, coupling, scratch);
            keep(scratch, true, true);
            row.push(s, EXACT_SENDER_BACK, scratch);
        }
        if let Some(r_back) = receiver_back {
            couple(r_back, sender, bins, coupling, scratch);
            keep(scratch, false, false);
            row.push(s, EXACT_RECEIVER_BACK, scratch);
            if let Some(back) = &flipped {
                couple(r_back, back, bins, coupling, scratch);
                keep(scratch, true, false);
                row.push(s, EXACT_SENDER_BACK | EXACT_RECEIVER_BACK, scratch);
            }
        }
    }
    let two_sided: Vec<bool> = tree
        .elements
        .iter()
        .map(|&node| tree.nodes[node as usize].two_sided)
        .collect();
    let any_two_sided = two_sided.iter().any(|&b| b);
    let rows: Vec<Row> = (0..n_elements)
        .into_par_iter()
        .map_init(Coupling::new, |scratch, r| {
            let pairs = &exact_pairs[pair_start[r] as usize..pair_start[r + 1] as usize];
            let mut row = Row::default();
            if pairs.is_empty() || meter.is_over() {
                return row;
            }
            let receiver = Receiver::for_senders(
                geoms[r],
                pairs.iter().map(|&(_, s)| &geoms[s as usize]),
                coupling,
            );
            row.q = receiver.quadrature();
            // A two-sided receiver's back face is integrated over the same points.
            // (It gathers radiance only: the front's coupling holds the receiver's antiradiance.)
            let receiver_back =
                two_sided[r].then(|| Receiver::new(geoms[r].flipped().blocking_back(false), row.q));
            for &(_, s) in pairs {
                row.points += receiver.points_for(&geoms[s as usize]) as u64;
                couple(&receiver, &geoms[s as usize], bins, coupling, scratch);
                if scratch.is_empty() && !two_sided[s as usize] && receiver_back.is_none() {
                    row.empty.push(s);
                    continue;
                }
                let before = row.senders.len();
                row.push(s, 0, scratch);
                if two_sided[r] || two_sided[s as usize] {
                    faces_coupled(
                        (&receiver, receiver_back.as_ref()),
                        (s, &geoms[s as usize], two_sided[s as usize]),
                        bins,
                        coupling,
                        scratch,
                        &mut row,
                    );
                }
                if row.senders.len() == before {
                    row.empty.push(s);
                }
            }
            meter.add(0, 0, pairs.len() as u64, row.entries.len() as u64);
            row
        })
        .collect();
    drop(exact_pairs);
    if meter.is_over() {
        return Err(meter.over_budget());
    }
    let t_coupled = std::time::Instant::now();
    stats.couple_seconds = (t_coupled - t_traversed).as_secs_f64();
    let cluster: Vec<ClusterLink> = cluster
        .into_par_iter()
        .map(|key| cluster_link(tree, bins, key as u32, (key >> 32) as u32))
        .collect();
    let mut links = Links {
        cluster,
        cluster_start,
        point: node_points(tree),
        exact_start: vec![0u32; n_elements + 1],
        ..Links::default()
    };
    let n_exact: usize = rows.iter().map(|r| r.senders.len()).sum();
    let n_entries: usize = rows.iter().map(|r| r.entries.len()).sum();
    links.exact_sender.reserve_exact(n_exact);
    links.exact_entry_start.reserve_exact(n_exact + 1);
    links.exact_entries.reserve_exact(n_entries);
    for (r, row) in rows.into_iter().enumerate() {
        stats.exact_element_pairs += (row.senders.len() + row.empty.len()) as u64;
        stats.exact_empty += row.empty.len() as u64;
        if row.q > 0 {
            stats.receivers_by_quadrature[(row.q - 1).min(7)] += 1;
        }
        stats.quadrature_points += row.points;
        if record_culled {
            let (rn, en) = (tree.elements[r], &tree.elements);
            links
                .culled
                .extend(row.empty.iter().map(|&s| (en[s as usize], rn)));
        }
        let mut start = links.exact_entries.len() as u32;
        for (&s, &count) in row.senders.iter().zip(&row.counts) {
            links.exact_entry_start.push(start);
            links.exact_sender.push(s);
            start += count;
        }
        if any_two_sided {
            links.exact_side.extend_from_slice(&row.sides);
        }
        links.exact_entries.extend_from_slice(&row.entries);
        links.exact_start[r + 1] = links.exact_start[r] + row.senders.len() as u32;
    }
    links
        .exact_entry_start
        .push(links.exact_entries.len() as u32);
    if record_culled {
        links.culled.extend(culled_pairs);
    }
    stats.assemble_seconds = t_coupled.elapsed().as_secs_f64();
    links.stats = stats;
    Ok(links)
}

/// Checks on a small scene that every ordered pair of distinct elements is covered exactly once
/// (by a cluster link, an exact link or a culled pair) and no element is linked to itself.
/// Needs links refined with `record_culled`. Cost O(elements^2): for tests and debug builds.
pub fn validate(tree: &ClusterTree, links: &Links) -> Result<(), String> {
    let n = tree.elements.len();
    let mut count = vec![0u8; n * n];
    let mut cover = |s: (u32, u32), r: (u32, u32)| {
        for a in s.0..s.1 {
            for b in r.0..r.1 {
                if s == r && a == b {
                    continue;
                }
                let c = &mut count[b as usize * n + a as usize];
                *c = c.saturating_add(1);
            }
        }
    };
    for l in &links.cluster {
        cover(
            tree.nodes[l.sender as usize].elements,
            tree.nodes[l.receiver as usize].elements,
        );
    }
    for &(s, r) in &links.culled {
        cover(
            tree.nodes[s as usize].elements,
            tree.nodes[r as usize].elements,
        );
    }
    for r in 0..n {
        for l in links.exact_start[r]..links.exact_start[r + 1] {
            let s = links.exact_sender[l as usize];
            cover((s, s + 1), (r as u32, r as u32 + 1));
        }
    }
    for r in 0..n {
        for s in 0..n {
            let c = count[r * n + s];
            let want = u8::from(r != s);
            if c != want {
                return Err(format!(
                    "element pair (sender {s}, receiver {r}) covered {c} times, expected {want}"
                ));
            }
        }
    }
    Ok(())
}
