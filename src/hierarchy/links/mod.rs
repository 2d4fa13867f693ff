//! Stage 3b: link refinement. Every ordered pair of elements (leaf triangles) is covered by
//! exactly one link: a cluster link between two nodes that are small as seen from each other,
//! an exact element-to-element coupling, or a culled pair that exchanges nothing.

use rayon::prelude::*;

use crate::geometry::bins::Bins;
use crate::hierarchy::cost::{self as budget, LinkBudget, Meter, ModelCounts, OverBudget};
use crate::hierarchy::ClusterTree;
use crate::transport::{CouplingParams, Entry};

mod exact;
mod traverse;

pub use traverse::{cluster_link, flat_spread, sender_spread, silent};
use traverse::{node_points, sphere_gap, Found};

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
    /// Most times one patch may be split ([`crate::hierarchy::ClusterTree::split_leaf`]: in
    /// four, a sliver in three; each split halves the pieces' length). 0..6; 4 by default (at
    /// most 256 pieces).
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
    /// solid angles bounded from above (by the nodes' bounding spheres and by their bounds, so
    /// that thin clusters such as chair legs count what they subtend), is the link's
    /// form-factor flux `A_r F_rs` (the light it carries in a scene of uniform radiance) over
    /// the scene's area. Hierarchical
    /// radiosity's BFA rule with uniform radiance: the error of a coarse link is at most the
    /// light it carries, and small receivers (furniture, slivers, a fan of pieces) carry little.
    /// It does not depend on the triangulation: splitting a triangle splits its links' shares.
    /// The share applied is this times `epsilon` (finer links carry less). 0 turns the rule
    /// off. 0..1e-4; [`FLUX_SHARE`] by default.
    ///
    /// A pair that is not accepted but whose flux is within the share even with the solid
    /// angles bounded at the gap between the nodes' bounds (a triangle of area `A` at distance
    /// `g` subtends at most `A / g^2`) and by `pi`, and that holds no emitter, is *faint*: its
    /// leaves are not split for it (its clusters are, and leaf pairs are coupled exactly as
    /// they are). Tiny triangles, and the thin faces of legs beside a floor, then cost their
    /// own elements only. Pairs with an emitter are never faint: near a light, the receiver's
    /// resolution carries the light's gradient (the generated classroom with emitters faint as
    /// well: 2.55% against its path-traced reference, bias +1.6%; with them kept, 2.34%, +0.5%).
    ///
    /// Both tests weigh the flux by the sender's [`crate::hierarchy::Node::light`], how much
    /// brighter than the scene's typical surface its direct light makes it
    /// ([`crate::solve::model::light_factors`]): the rule follows the light a link carries, not
    /// only its geometry. b90_office's desk-lamp shade, about 200 times as bright as the room,
    /// was faint to itself; weighed, b90_office 1.66% -> 1.56% from its path-traced reference
    /// (the shade -5.4% -> -3.6%), 34.4M -> 36.3M links; the generated classroom 1.425% ->
    /// 1.401%, 8.72M -> 8.93M links; the seed room 0.1% more links, the same error; the
    /// generated office (no reference) 49.3M -> 75.6M links, 3.93 -> 5.74 GB, 157 -> 191 s
    /// (104 -> 73 sweeps).
    pub flux_share: f64,
    /// A faint pair (see [`LinkParams::flux_share`]) whose bounding spheres overlap becomes one
    /// cluster link where it is first found faint, instead of being refined down to exact
    /// couplings between its elements. What is lost is the near field of small things among
    /// themselves (a chair's tessellated seat, a lamp's shade), evaluated from the sender's
    /// centroid. Off by default; on in the `fast` preset. Measured at the default preset:
    /// b90_office 31.4 s, 1.99 GiB, 1.21% (bias -0.34%) from its path-traced reference ->
    /// 12.0 s, 1.00 GiB, 2.33% (-1.76%) (32.6M -> 8.1M links; one run each). Measured on an
    /// earlier build: the generated
    /// classroom 7.1 s, 0.83 GB, 2.26% -> 6.2 s, 0.64 GB, 2.37%; in the `fast` preset
    /// b90_office 38.8 s, 2.25 GB, 5.06% -> 10.5 s, 0.76 GB, 7.66%, the classroom 5.1 s,
    /// 0.60 GB, 12.8% -> 2.8 s, 0.41 GB, 14.3%, the seed room unchanged (5.44%). The exact
    /// rows then miss the near field of small things, so damped antiradiance keeps its floor
    /// at 0 ([`crate::solve::health::Guard::close_floor`]).
    pub faint_links: bool,
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
        faint_links: false,
    };
}

impl Default for LinkParams {
    fn default() -> Self {
        LinkParams::DEFAULT
    }
}

/// The default [`LinkParams::flux_share`] (at epsilon 1), with the flux rule's solid angles
/// bounded by the nodes' bounds as well as their spheres. Measured against path-traced
/// references (design-note error, bias; links; whole-process time of one batch), 5e-6 -> 2e-5:
///
/// | scene | 5e-6 | 2e-5 |
/// |---|---|---|
/// | seed room | 1.85% (-0.87%), 0.53M, 0.74 s | 1.87% (-0.91%), 0.33M, 0.57 s |
/// | MGF corridor | 1.58% (-0.39%), 0.82M, 0.85 s | 1.60% (-0.41%), 0.56M, 0.58 s |
/// | MGF hospital floor | 4.46% (+0.62%), 6.2M, 6.7 s | 4.54% (+0.59%), 4.3M, 4.9 s |
/// | MGF classroom | 2.40% (-0.73%), 9.6M, 10.7 s | 2.33% (-0.38%), 5.2M, 5.7 s |
/// | b90_office | 1.22% (-0.44%), 32.6M, 31.6 s | 1.21% (-0.50%), 20.8M, 22.0 s |
/// | MGF office `graz` | 2.49% (-1.10%), 41.4M, 48.0 s | 2.56% (-1.08%), 26.6M, 29.7 s |
///
/// The errors move by -0.07 to +0.08 points, about as much as they move between neighbouring
/// shares (1e-5: the classroom 2.55%, graz 2.53%); the links fall by a third to a half. At
/// 4e-5 the errors start to rise (graz 2.72%, b90_office 1.34%, the hospital 4.64%), at 1e-4
/// the seed room is 2.15% (bias -1.47%).
pub const FLUX_SHARE: f64 = 2e-5;

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
/// from it; a link's direction runs from the sender's to the receiver's), its spread (see
/// [`sender_spread`]) and, for a flat node, its plane's normal: receivers use kernels that
/// follow the sender's extent ([`NodePoint::kernel_toward`]) instead of the point kernel
/// `1 / d^2`.
#[derive(Clone, Copy, Debug, Default)]
pub struct NodePoint {
    /// The node's area-weighted centroid.
    pub centroid: [f32; 3],
    /// The node's spread: [`flat_spread`] for a flat node, else [`sender_spread`].
    pub spread: f32,
    /// The node's [`sender_spread`]: the disk kernel's, which a flat node's kernels blend into
    /// near it ([`expansion_weight`]).
    pub disk_spread: f32,
    /// The plane's unit normal of a flat node (either orientation); zero for a curved one.
    pub normal: [f32; 3],
}

/// The kernels of a cluster link's sender toward one receiving point
/// ([`NodePoint::kernel_toward`]), in the disk form `1 / (d^2 + spread)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SenderKernel {
    /// Spread of the irradiance kernel: a receiver facing the sender gets `cos_r / (d^2 +
    /// irradiance)` per unit of the link's intensity (times `1 / pi`).
    pub irradiance: f64,
    /// Spread of the antiradiance kernel `1 / (d^2 + anti)`.
    pub anti: f64,
    /// The irradiance's term in the receiver's orientation: a receiver whose normal is `n_r`
    /// adds `-n_r . tilt / (d^2 + irradiance)^2` (zero for a curved sender).
    pub tilt: glam::DVec3,
}

impl NodePoint {
    /// The sender's kernels toward a receiving point at `v` from its centroid (`d2 = |v|^2 >
    /// 0`, `inv_d = 1 / |v|`), in the units of `d2`.
    ///
    /// A flat sender of spread `S` (twice its mean squared distance from its centroid: a disk
    /// of radius `a` has `S = a^2`; see [`flat_spread`]) whose normal makes angle `theta` with
    /// `v`: the second-order expansion of its form factor over its extent, `cos_s cos_r / r^2`
    /// averaged over a surface of in-plane variance `S / 4` per axis, is the point kernel times
    /// `1 - (S (2 - 3 sin^2 theta) - S cos theta (m . n_s) / cos_r) / d^2` (`m` the direction
    /// the receiver faces away from, `-n_r`);
    /// its solid angle, `cos_s / r^2` averaged, `1 - S (3/4 - 15/8 sin^2 theta) / d^2`. On
    /// the disk's axis they are `1 - S / d^2` and `1 - 3 S / (4 d^2)` (the exact disk form
    /// factor `a^2 / (d^2 + a^2)` to first order); seen obliquely a disk gives more than the
    /// point kernel, not less (its near side is nearer): at `d = 2a`, 70 degrees off its axis,
    /// the exact form factor is 1.52 times `1 / (d^2 + a^2)` and the expansion within 3%; over
    /// random orientations at `d = 2a` the disk kernel alone was 20% low (flux-weighted) and
    /// the expansion 3% high. The expansion's weight ([`expansion_weight`]) is 0 within `d2 =
    /// 4 S`, so both spreads stay above `-d2 / 4`. A curved sender keeps its [`sender_spread`]
    /// for both, without tilt. The receiving element's own extent is the same expansion with
    /// the roles swapped ([`receiver_spread`]): the disk kernel alone was low by about as much
    /// as a point receiver is high, which is why it kept a closed box's row sums near 1.
    #[inline]
    pub fn kernel_toward(&self, v: glam::DVec3, d2: f64, inv_d: f64) -> SenderKernel {
        let spread = self.spread as f64;
        let n = glam::Vec3::from_array(self.normal).as_dvec3();
        if n == glam::DVec3::ZERO {
            return SenderKernel {
                irradiance: spread,
                anti: spread,
                tilt: glam::DVec3::ZERO,
            };
        }
        let cos = n.dot(v) * inv_d;
        let sin2 = 1.0 - cos * cos;
        // The expansion holds for a receiver well outside the sender's extent; nearer (a faint
        // pair's link between overlapping nodes) it blends into the disk kernel.
        let t = expansion_weight(d2, spread);
        let disk = self.disk_spread as f64;
        let blend = |expanded: f64| disk + t * (expanded - disk);
        SenderKernel {
            irradiance: blend(spread * (2.0 - 3.0 * sin2)),
            anti: blend(spread * (0.75 - 1.875 * sin2)),
            tilt: n * (t * spread * cos),
        }
    }

    /// The plane's unit normal of a flat node, `None` for a curved one.
    #[inline]
    pub fn flat_normal(&self) -> Option<glam::DVec3> {
        let n = glam::Vec3::from_array(self.normal).as_dvec3();
        (n != glam::DVec3::ZERO).then_some(n)
    }

    /// The factor that turns a cluster link's intensity, which a flat sender (normal `n_s`)
    /// sends along `w` (unit, from its centroid to the receiver node's: the direction of
    /// [`ClusterLink`]), into what it sends along `v` (unit, toward one receiving point): the
    /// ratio of the sender's cosines `(n_s . v) / (n_s . w)`, or 0 when the two differ in sign
    /// or `n_s . w` is 0 (the point lies on the other side of the sender's plane, which sends
    /// what the link does not carry). 1 for a curved sender.
    ///
    /// Every term of a flat sender's intensity, radiance and antiradiance alike, is its area
    /// times `|n_s . w|`, so the ratio is exact for it; evaluated at the receiver node's
    /// centroid instead, every element of a large receiver took the cosine of its centre.
    /// Near a concave edge that is the larger one (the centre is farther from the sender's
    /// plane): a closed box's row sums were 1.055 on the triangles along its edges, the
    /// 66k-triangle Cornell box 3.95% too bright there.
    #[inline]
    pub fn cosine_ratio(&self, w: glam::DVec3, v: glam::DVec3) -> f64 {
        self.flat_normal()
            .map_or(1.0, |n| cosine_ratio(n.dot(w), n.dot(v)))
    }

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

/// [`NodePoint::cosine_ratio`] from a flat sender's cosines along the link (`c_link`) and
/// toward the point (`c_point`): their ratio, 0 when they differ in sign or `c_link` is 0.
#[inline]
pub fn cosine_ratio(c_link: f64, c_point: f64) -> f64 {
    if c_link * c_point > 0.0 {
        c_point / c_link
    } else {
        0.0
    }
}

/// Weight of the second-order kernels ([`NodePoint::kernel_toward`],
/// [`receiver_spread`]) at squared distance `d2` from a surface of spread `spread`: 0 (the disk
/// kernel alone) within `d2 = 4 spread` (for a disk of radius `a`, closer than `2a`), 1 beyond
/// `8 spread`, linear between. The expansion is in `spread / d2`: at `d = 2a` it is within 3%
/// of a disk's exact form factor, and an overlapping pair (a faint link, `LinkParams::faint_links`)
/// would take up to twice the point kernel from it.
#[inline]
pub fn expansion_weight(d2: f64, spread: f64) -> f64 {
    if !(spread > 0.0) || d2 >= 8.0 * spread {
        return 1.0;
    }
    ((d2 / spread - 4.0) / 4.0).clamp(0.0, 1.0)
}

/// The receiving elements' own extent in the irradiance kernel's spread, at squared distance
/// `d2` from a sender: `s_e (2 - 3 sin^2 theta_e)` for elements of spread `s_e`
/// ([`element_spread`]) whose normal makes angle `theta_e` with the direction to the sender
/// (`cos_e` its cosine, either sign), blended into 0 near the sender ([`expansion_weight`]),
/// so at least `-d2 / 4`. The receiver's half of the second-order expansion whose sender half
/// is [`NodePoint::kernel_toward`]; its term in the sender's normal, which needs the sender's
/// cosine toward the element, is added by the gather for flat senders
/// ([`NodePoint::cosine_ratio`]).
#[inline]
pub fn receiver_spread(s_e: f64, cos_e: f64, d2: f64) -> f64 {
    expansion_weight(d2, s_e) * s_e * (3.0 * cos_e * cos_e - 1.0)
}

/// Element `e`'s spread as a receiver: [`flat_spread`] of its triangle (its leaf in `tree`).
pub fn element_spread(tree: &ClusterTree, e: usize) -> f64 {
    flat_spread(&tree.nodes[tree.elements[e] as usize])
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
    /// Exact pairs (of `exact_pairs`) that are faint: they carry at most the flux rule's share
    /// whatever their geometry, so their leaves were not split for them
    /// ([`LinkParams::flux_share`]).
    pub faint_exact: u64,
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
    let (pieces, leaf_splits) =
        traverse::rounds(tree, bins, params, coupling, record_culled, budget)?;
    let Found {
        mut cluster,
        exact: exact_pairs,
        culled: culled_pairs,
        mut stats,
        ..
    } = Found::concat(pieces);
    stats.leaf_splits = leaf_splits;
    let limit = traverse::flux_limit(params, tree);
    // Which exact pairs are faint: counted here, coupled with fewer points below.
    let mut faint = Vec::with_capacity(exact_pairs.len());
    for &(s, r) in &exact_pairs {
        let (sn, rn) = (&tree.nodes[s as usize], &tree.nodes[r as usize]);
        let is_faint = traverse::faint(sn, rn, params, limit);
        faint.push(is_faint);
        if is_faint {
            stats.faint_exact += 1;
        }
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
    let cluster_start = receiver_starts(&cluster, tree.nodes.len());

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
    let any_two_sided = (tree.elements.iter()).any(|&node| tree.nodes[node as usize].two_sided);
    let rows = exact::couple_exact(tree, exact_pairs, &faint, bins, coupling, &meter);
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
        exact_start: vec![0u32; tree.elements.len() + 1],
        ..Links::default()
    };
    append_exact_rows(
        &mut links,
        rows,
        tree,
        any_two_sided,
        record_culled,
        &mut stats,
    );
    if record_culled {
        links.culled.extend(culled_pairs);
    }
    stats.assemble_seconds = t_coupled.elapsed().as_secs_f64();
    links.stats = stats;
    Ok(links)
}

/// Per node, where its incoming links start in `sorted` (cluster-link keys `receiver << 32 |
/// sender`, sorted), with one entry more for the end.
fn receiver_starts(sorted: &[u64], nodes: usize) -> Vec<u32> {
    let mut start = vec![0u32; nodes + 1];
    for &key in sorted {
        start[(key >> 32) as usize + 1] += 1;
    }
    for i in 0..nodes {
        start[i + 1] += start[i];
    }
    start
}

/// Appends the coupled exact rows (one per receiver element, in element order) to `links`:
/// senders, entry ranges, faces (when some element is two-sided) and the per-element starts,
/// counting what they hold in `stats`; with `record_culled`, the element pairs found to
/// exchange nothing as culled pairs.
fn append_exact_rows(
    links: &mut Links,
    rows: Vec<exact::Row>,
    tree: &ClusterTree,
    any_two_sided: bool,
    record_culled: bool,
    stats: &mut LinkStats,
) {
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

#[cfg(test)]
mod kernel_tests {
    use super::*;
    use glam::DVec3;

    /// Irradiance at `x` (normal `n_r`) from a unit disk in the plane z = 0 (normal +z) of
    /// unit radiance, per unit of its intensity toward `x` (`area cos_s`): the exact value,
    /// integrated over the disk on a fine polar grid.
    fn disk_exact(x: DVec3, n_r: DVec3) -> f64 {
        let (rings, sectors) = (200, 400);
        let mut sum = 0.0;
        for i in 0..rings {
            let r = (i as f64 + 0.5) / rings as f64;
            let ring_area = std::f64::consts::PI * (((i + 1) * (i + 1) - i * i) as f64)
                / (rings * rings) as f64;
            for j in 0..sectors {
                let phi = std::f64::consts::TAU * (j as f64 + 0.5) / sectors as f64;
                let y = DVec3::new(r * phi.cos(), r * phi.sin(), 0.0);
                let u = x - y;
                let l2 = u.length_squared();
                let (cos_s, cos_r) = (u.z / l2.sqrt(), -n_r.dot(u) / l2.sqrt());
                if cos_s > 0.0 && cos_r > 0.0 {
                    sum += ring_area / sectors as f64 * cos_s * cos_r / l2;
                }
            }
        }
        let cos_link = x.z / x.length();
        sum / (std::f64::consts::PI * cos_link)
    }

    /// A flat unit disk at the origin with normal `normal`: spread `a^2` = 1 (twice its mean
    /// square 1/2).
    fn unit_disk(normal: [f32; 3]) -> NodePoint {
        NodePoint {
            centroid: [0.0; 3],
            spread: 1.0,
            disk_spread: 1.0,
            normal,
        }
    }

    /// The solver's value for the same pair: `cos_r / (d^2 + s) - n_r . tilt / (d^2 + s)^2`.
    fn kernel_value(x: DVec3, n_r: DVec3, disk: &NodePoint) -> f64 {
        let d2 = x.length_squared();
        let k = disk.kernel_toward(x, d2, 1.0 / d2.sqrt());
        let g = 1.0 / (d2 + k.irradiance);
        let cos_r = -n_r.dot(x) / d2.sqrt();
        cos_r * g - n_r.dot(k.tilt) * g * g
    }

    #[test]
    fn an_oblique_disk_sends_what_its_form_factor_says() {
        let disk = unit_disk([0.0, 0.0, 1.0]);
        for degrees in [0.0f64, 40.0, 70.0] {
            let t = degrees.to_radians();
            let x = DVec3::new(t.sin(), 0.0, t.cos()) * 3.0;
            // Facing the disk's centre, and tilted toward the disk's normal.
            for n_r in [
                -x.normalize(),
                (-x.normalize() - DVec3::Z * 0.5).normalize(),
            ] {
                let exact = disk_exact(x, n_r);
                let model = kernel_value(x, n_r, &disk);
                let disk_kernel = (-n_r.dot(x) / 3.0) / (9.0 + 1.0);
                assert!(
                    (model / exact - 1.0).abs() < 0.02,
                    "{degrees} degrees, n_r {n_r}: model {model}, exact {exact}"
                );
                if degrees == 70.0 {
                    assert!(
                        disk_kernel < 0.9 * exact,
                        "the disk kernel alone is low seen obliquely: {disk_kernel} / {exact}"
                    );
                }
            }
        }
    }

    #[test]
    fn near_a_sender_the_kernel_is_the_disk_kernel() {
        assert_eq!(expansion_weight(3.0, 1.0), 0.0);
        assert_eq!(expansion_weight(6.0, 1.0), 0.5);
        assert_eq!(expansion_weight(9.0, 1.0), 1.0);
        let disk = unit_disk([0.0, 0.0, 1.0]);
        // Grazing and within twice its radius: no negative spread, no tilt.
        let x = DVec3::new(1.5, 0.0, 0.1);
        let k = disk.kernel_toward(x, x.length_squared(), 1.0 / x.length());
        assert_eq!((k.irradiance, k.anti, k.tilt), (1.0, 1.0, DVec3::ZERO));
    }

    #[test]
    fn a_flat_senders_light_is_turned_to_each_points_own_cosine() {
        let flat = unit_disk([0.0, 0.0, -1.0]);
        let curved = NodePoint {
            normal: [0.0; 3],
            ..flat
        };
        let w = DVec3::new(1.0, 0.0, 1.0).normalize();
        let v = DVec3::new(3.0, 0.0, 1.0).normalize();
        // Either orientation of the plane's normal gives the same ratio of cosines.
        let ratio = flat.cosine_ratio(w, v);
        assert!((ratio - v.z / w.z).abs() < 1e-6, "{ratio}");
        assert!(
            ratio < 1.0,
            "a point nearer the sender's plane sees it more obliquely"
        );
        assert_eq!(curved.cosine_ratio(w, v), 1.0);
        // A point on the other side of the sender's plane, or in it, gets nothing of the link.
        assert_eq!(
            flat.cosine_ratio(w, DVec3::new(1.0, 0.0, -0.1).normalize()),
            0.0
        );
        assert_eq!(flat.cosine_ratio(w, DVec3::X), 0.0);
        assert_eq!(flat.cosine_ratio(DVec3::X, v), 0.0);
    }
}
