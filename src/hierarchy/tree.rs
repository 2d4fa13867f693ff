//! Stage 3a: the cluster tree over the patches, with on-demand subdivision of leaf triangles.
//!
//! The upper levels split the patches top down by a surface area heuristic that float noise
//! does not change (one patch per leaf, `ClusterTree::build_nodes`). Below a patch,
//! [`ClusterTree::split_leaf`] cuts a leaf triangle into pieces half as long when link
//! refinement asks for it, so a coarse input (a floor of two triangles) becomes fine exactly where
//! transport needs it. After refinement, [`ClusterTree::finalize`] numbers the leaves ("elements")
//! in depth-first order so every node covers a contiguous range of elements.

use std::time::Duration;

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::{self, tolerances, Tri};
use crate::mesh::Patches;

/// Marker for "no node / no patch".
pub const NONE: u32 = u32::MAX;

/// One node of the cluster tree: a cluster of nodes, or a leaf triangle (a patch or a piece of one).
#[derive(Clone, Debug)]
pub struct Node {
    /// Centre of the bounding sphere (unit frame).
    pub center: DVec3,
    /// Radius of the bounding sphere.
    pub radius: f64,
    /// Total area of the triangles below.
    pub area: f64,
    /// Area-weighted centroid of the triangles below.
    pub centroid: DVec3,
    /// Mean squared distance of the surface below from `centroid` (area-weighted, over every
    /// point of every triangle): the node's extent as a sender, whatever its triangulation.
    pub mean_square: f64,
    /// Unit normal and offset (n . x) when every triangle below lies in one plane facing the same
    /// way; `None` otherwise.
    pub plane: Option<(DVec3, f64)>,
    /// Axis-aligned bounds, (min, max).
    pub bounds: (DVec3, DVec3),
    /// First child; children are `first_child .. first_child + child_count`.
    pub first_child: u32,
    /// Number of children; 0 for a leaf.
    pub child_count: u8,
    /// Parent node, [`NONE`] for the root.
    pub parent: u32,
    /// For leaves: the patch this triangle is (part of); [`NONE`] for clusters.
    pub patch: u32,
    /// For leaves: how many times the patch was split to get this triangle.
    pub split_depth: u8,
    /// For leaves: the triangle's corners (counter-clockwise = front).
    pub corners: Tri,
    /// For leaves: the radius of the smallest piece [`ClusterTree::split_leaf`] would cut it
    /// into (about `radius / 2`); 0 for clusters.
    pub piece_radius: f64,
    /// Elements below this node, `elements.0 .. elements.1` (set by [`ClusterTree::finalize`]).
    pub elements: (u32, u32),
    /// Cone of the normals below: unit axis (zero when the normals cancel out).
    pub cone_axis: DVec3,
    /// Cosine of the cone's half-angle: every normal below `n` has `n . cone_axis >= cone_cos`
    /// (-1: no bound).
    pub cone_cos: f64,
    /// Some triangle below blocks light arriving at its back ([`ClusterTree::mark_back_blocking`]).
    pub blocks_back: bool,
    /// Some triangle below emits light ([`ClusterTree::mark_emitting`]): its pairs are never
    /// faint (see [`crate::hierarchy::links::LinkParams::flux_share`]).
    pub emits: bool,
    /// A leaf of a two-sided patch: both its faces emit and reflect
    /// ([`ClusterTree::mark_two_sided`]; false on clusters).
    pub two_sided: bool,
    /// How much brighter than the scene's typical surface the brightest patch below may be,
    /// from an estimate of its direct light ([`ClusterTree::mark_light`],
    /// [`crate::solve::model::light_factors`]): at least 1. The flux rule
    /// weighs a sender's links by it ([`crate::hierarchy::links::LinkParams::flux_share`]).
    pub light: f32,
    /// Largest height of `center` above the plane of any triangle below,
    /// `max_t (n_t . center - n_t . v_t)`: with the cone it bounds from above the height of any
    /// point above every triangle's plane (see [`ClusterTree::behind_all`]).
    pub height: f64,
}

impl Node {
    /// The unit normal of the node's plane, +Z for a node that is not flat (a leaf triangle
    /// always is).
    pub fn plane_normal(&self) -> DVec3 {
        self.plane.map_or(DVec3::Z, |p| p.0)
    }

    /// True for leaf triangles.
    pub fn is_leaf(&self) -> bool {
        self.child_count == 0
    }
}

/// The cluster tree over the active patches. `nodes[0]` is the root.
#[derive(Clone, Debug, Default)]
pub struct ClusterTree {
    /// All nodes; children of a node are contiguous.
    pub nodes: Vec<Node>,
    /// Leaf nodes in depth-first order (filled by [`ClusterTree::finalize`]): element i is
    /// `nodes[elements[i]]`.
    pub elements: Vec<u32>,
    /// Time spent building the tree's nodes (before refitting).
    pub bvh_time: Duration,
}

/// The leaf node of triangle `corners`, piece of `patch` (a placeholder the cluster build
/// overwrites when `patch` is [`NONE`]: then no piece radius is computed).
fn leaf_node(corners: Tri, patch: u32, parent: u32, split_depth: u8) -> Node {
    let normal = geometry::normal(&corners).unwrap_or(DVec3::Z);
    let center = geometry::centroid(&corners);
    let radius = triangle_radius(&corners);
    let piece_radius = if patch == NONE {
        0.0
    } else {
        geometry::split_in_pieces(&corners)
            .iter()
            .map(triangle_radius)
            .fold(f64::INFINITY, f64::min)
    };
    let (lo, hi) = triangle_box(&corners);
    // Over a triangle, the mean of |y - centroid|^2 is the sum over its corners / 12.
    let mean_square = corners
        .iter()
        .map(|c| (*c - center).length_squared())
        .sum::<f64>()
        / 12.0;
    Node {
        center,
        radius,
        area: geometry::area(&corners),
        centroid: center,
        mean_square,
        plane: Some((normal, normal.dot(corners[0]))),
        bounds: (lo, hi),
        first_child: NONE,
        child_count: 0,
        parent,
        patch,
        split_depth,
        corners,
        piece_radius,
        elements: (0, 0),
        cone_axis: normal,
        cone_cos: 1.0,
        blocks_back: false,
        emits: false,
        two_sided: false,
        light: 1.0,
        height: 0.0,
    }
}

/// A node of the layout of [`ClusterTree::build_nodes`] before it is filled in: a leaf's by
/// its leaf, a cluster's by [`ClusterTree::refit_all`] and [`ClusterTree::compute_cones`]
/// (only `corners`, those of the first patch of its parent's range right after its split,
/// stay).
fn placeholder(corners: Tri, parent: u32) -> Node {
    Node {
        center: DVec3::ZERO,
        radius: 0.0,
        area: 0.0,
        centroid: DVec3::ZERO,
        mean_square: 0.0,
        plane: None,
        bounds: (DVec3::ZERO, DVec3::ZERO),
        first_child: NONE,
        child_count: 0,
        parent,
        patch: NONE,
        split_depth: 0,
        corners,
        piece_radius: 0.0,
        elements: (0, 0),
        cone_axis: DVec3::ZERO,
        cone_cos: 1.0,
        blocks_back: false,
        emits: false,
        two_sided: false,
        light: 1.0,
        height: 0.0,
    }
}

/// A triangle's bounding box (low and high corner).
fn triangle_box(c: &Tri) -> (DVec3, DVec3) {
    (c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2]))
}

/// The radius of a leaf's bounding sphere: the largest distance of a corner from the centroid.
fn triangle_radius(corners: &Tri) -> f64 {
    let center = geometry::centroid(corners);
    corners
        .iter()
        .map(|c| (*c - center).length())
        .fold(0.0, f64::max)
}

/// Lowest and highest signed distance of node `node` to the plane `n . x = d`: over its box's
/// corners, clamped by its sphere (exact corners for a leaf).
pub fn signed_extent(node: &Node, n: DVec3, d: f64) -> (f64, f64) {
    if node.is_leaf() {
        let h = node.corners.map(|c| n.dot(c) - d);
        return (h[0].min(h[1]).min(h[2]), h[0].max(h[1]).max(h[2]));
    }
    let (lo, hi) = node.bounds;
    let center = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo);
    let (mid, reach) = (n.dot(center) - d, n.abs().dot(half));
    let sphere = n.dot(node.center) - d;
    (
        (mid - reach).max(sphere - node.radius),
        (mid + reach).min(sphere + node.radius),
    )
}

/// Bins per axis of the cluster tree's surface-area split.
const SPLIT_BINS: usize = 16;

/// The bin (0..[`SPLIT_BINS`]) of grid position `g` in a range starting at `lo`, `span` wide.
/// (Unit-frame grid positions are at most about 1e5 apart; wider ones take the 128-bit path.)
fn split_bin(g: i64, lo: i64, span: i64) -> usize {
    match (g - lo).checked_mul(SPLIT_BINS as i64) {
        Some(scaled) => (scaled / span) as usize,
        None => ((g - lo) as i128 * SPLIT_BINS as i128 / span as i128) as usize,
    }
}

/// What the splits of [`split_range`] read of every patch, computed once.
struct SplitInput<'a> {
    corners: &'a [Tri],
    /// The centroid on the grid of [`geometry::SCENE_EPS`], per axis.
    grid: Vec<[i64; 3]>,
    /// The area.
    area: Vec<f64>,
    /// The bounding box (low and high corner).
    bounds: Vec<(DVec3, DVec3)>,
}

impl<'a> SplitInput<'a> {
    fn new(corners: &'a [Tri]) -> SplitInput<'a> {
        let grid = corners
            .par_iter()
            .map(|c| {
                geometry::centroid(c)
                    .to_array()
                    .map(|x| (x / geometry::SCENE_EPS).round() as i64)
            })
            .collect();
        let area = corners.par_iter().map(geometry::area).collect();
        let bounds = corners.par_iter().map(triangle_box).collect();
        SplitInput {
            corners,
            grid,
            area,
            bounds,
        }
    }
}

/// Ranges at least this long are split on their own thread ([`split_range`]).
const PARALLEL_SPLIT: usize = 4096;

/// How [`split_range`] split a range: a leaf (one patch), or two parts, the first `mid` long,
/// `head` the range's first patch right after this split.
enum Shape {
    Leaf,
    Split {
        mid: usize,
        head: u32,
        parts: Box<[Shape; 2]>,
    },
}

/// Splits `range` (of patches, at least one) recursively as [`ClusterTree::build_nodes`]
/// documents, reordering it (each part after its parent's split, first part first), and
/// returns the shape of the splits. Parts of at least [`PARALLEL_SPLIT`] patches are split in
/// parallel; the result does not depend on it.
fn split_range(range: &mut [u32], input: &SplitInput) -> Shape {
    let corners = input.corners;
    if range.len() <= 1 {
        return Shape::Leaf;
    }
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for &p in range.iter() {
        let (p_lo, p_hi) = input.bounds[p as usize];
        lo = lo.min(p_lo);
        hi = hi.max(p_hi);
    }
    let extent = (hi - lo).length();
    // The largest triangle (first by patch index among equals).
    let area = |p: u32| input.area[p as usize];
    let (big, big_area) = range.iter().enumerate().fold((0, -1.0), |best, (k, &p)| {
        let a = area(p);
        if a > best.1 || (a == best.1 && p < range[best.0]) {
            (k, a)
        } else {
            best
        }
    });
    let total: f64 = range.iter().map(|&p| area(p)).sum();
    let peel = range.len() > 2
        && big_area >= 0.5 * total
        && 2.0 * triangle_radius(&corners[range[big] as usize]) >= 0.5 * extent;
    let mid = if peel {
        range.swap(0, big);
        1
    } else {
        sah_split(range, input)
    };
    let head = range[0];
    let parallel = range.len() >= PARALLEL_SPLIT;
    let (first, second) = range.split_at_mut(mid);
    let parts = if parallel {
        rayon::join(|| split_range(first, input), || split_range(second, input))
    } else {
        (split_range(first, input), split_range(second, input))
    };
    Shape::Split {
        mid,
        head,
        parts: Box::new([parts.0, parts.1]),
    }
}

/// Splits `range` (at least two patches) in two by the surface area heuristic over
/// [`SPLIT_BINS`] centroid bins per axis, and returns the size of the first part (the range is
/// reordered, first part first, each part in its former order).
///
/// Cost of a split: each part's count times its box's surface area, the cheapest over every
/// axis and bin boundary; a wall's flat box is cheap, so walls, floor and furniture come apart
/// near the top. Robust to float noise: centroids are binned on a grid of
/// [`geometry::SCENE_EPS`] in integers, and a candidate must be cheaper by a relative 1e-6 to
/// replace an earlier one (axes x, y, z, bins in order), so a 1e-6 jitter or a translation
/// builds the same tree. When every centroid falls in one bin on every axis, the range is
/// halved in order.
fn sah_split(range: &mut [u32], input: &SplitInput) -> usize {
    let grid = |p: u32, axis: usize| input.grid[p as usize][axis];
    let area = |(lo, hi): (DVec3, DVec3)| {
        let e = (hi - lo).max(DVec3::ZERO);
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    };
    let empty = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let join = |a: (DVec3, DVec3), b: (DVec3, DVec3)| (a.0.min(b.0), a.1.max(b.1));
    // The grid's range per axis, then every axis's bins in one pass over the range.
    let (mut g_lo, mut g_hi) = ([i64::MAX; 3], [i64::MIN; 3]);
    for &p in range.iter() {
        let g = input.grid[p as usize];
        for axis in 0..3 {
            g_lo[axis] = g_lo[axis].min(g[axis]);
            g_hi[axis] = g_hi[axis].max(g[axis]);
        }
    }
    let span: [i64; 3] = std::array::from_fn(|axis| g_hi[axis] - g_lo[axis] + 1);
    let mut count = [[0usize; SPLIT_BINS]; 3];
    let mut boxes = [[empty; SPLIT_BINS]; 3];
    for &p in range.iter() {
        let (g, b) = (input.grid[p as usize], input.bounds[p as usize]);
        for axis in 0..3 {
            if span[axis] > 1 {
                let k = split_bin(g[axis], g_lo[axis], span[axis]);
                count[axis][k] += 1;
                boxes[axis][k] = join(boxes[axis][k], b);
            }
        }
    }
    // (cost, axis, last bin of the first part)
    let mut best: Option<(f64, usize, usize)> = None;
    for axis in 0..3 {
        if span[axis] == 1 {
            continue;
        }
        let (count, boxes) = (&count[axis], &boxes[axis]);
        let mut right = [(0usize, empty); SPLIT_BINS];
        let mut acc = (0usize, empty);
        for k in (0..SPLIT_BINS).rev() {
            acc = (acc.0 + count[k], join(acc.1, boxes[k]));
            right[k] = acc;
        }
        let mut left = (0usize, empty);
        for k in 0..SPLIT_BINS - 1 {
            left = (left.0 + count[k], join(left.1, boxes[k]));
            let (n_right, box_right) = right[k + 1];
            if left.0 == 0 || n_right == 0 {
                continue;
            }
            let cost = left.0 as f64 * area(left.1) + n_right as f64 * area(box_right);
            if best.is_none_or(|b| cost < b.0 * (1.0 - tolerances::SAH_IMPROVEMENT)) {
                best = Some((cost, axis, k));
            }
        }
    }
    let Some((_, axis, last)) = best else {
        return range.len() / 2;
    };
    let (lo, span) = (g_lo[axis], span[axis]);
    let (first, second): (Vec<u32>, Vec<u32>) = range
        .iter()
        .partition(|&&p| split_bin(grid(p, axis), lo, span) <= last);
    range[..first.len()].copy_from_slice(&first);
    range[first.len()..].copy_from_slice(&second);
    first.len()
}

impl ClusterTree {
    /// Builds the tree over the active patches, one patch per leaf (`build_nodes`), with the
    /// patches that emit marked ([`ClusterTree::mark_emitting`]).
    ///
    /// # Panics
    /// If no patch is active (the loader rejects such scenes).
    pub fn build(patches: &Patches) -> ClusterTree {
        let mut tree = ClusterTree::build_unmarked(patches);
        let emitting: Vec<bool> = (0..patches.len()).map(|p| patches.is_emitter(p)).collect();
        tree.mark_emitting(&emitting);
        tree
    }

    /// [`ClusterTree::build`] without the emitters marked.
    fn build_unmarked(patches: &Patches) -> ClusterTree {
        let active: Vec<u32> = (0..patches.len() as u32)
            .filter(|&p| patches.active[p as usize])
            .collect();
        assert!(
            !active.is_empty(),
            "a scene needs at least one non-degenerate patch"
        );
        let mut tree = ClusterTree::default();
        if active.len() == 1 {
            let p = active[0];
            tree.nodes
                .push(leaf_node(patches.corners[p as usize], p, NONE, 0));
            return tree;
        }
        let start = std::time::Instant::now();
        tree.build_nodes(patches, active);
        tree.bvh_time = start.elapsed();
        tree.refit_all();
        tree.compute_cones();
        tree
    }

    /// The cluster nodes over `active` patches, top down: a range of patches whose largest
    /// triangle holds at least half its area and reaches half its extent is split into that
    /// triangle and the rest (a wall beside furniture is not clustered with it); any other
    /// range is split at the median of its centroids along their longest axis (both on a grid of
    /// [`geometry::SCENE_EPS`], ties by patch index). Every node then
    /// has two children and the tree is balanced up to the peeled triangles.
    ///
    /// Only the order of centroids decides, so float noise (a 1e-6 jitter, a translation)
    /// changes no split beyond the exact ties it breaks, where a SAH build (obvhs) gave trees
    /// of mean leaf depth 19 or 15 for the same room, and 0.99M or 0.71M links.
    fn build_nodes(&mut self, patches: &Patches, mut active: Vec<u32>) {
        let corners = &patches.corners;
        let root_head = active[0];
        // 1. The splits, independent ranges in parallel: `active` reordered, and their shape.
        let shape = split_range(&mut active, &SplitInput::new(corners));
        // 2. The leaves, in parallel.
        let leaves: Vec<Node> = active
            .par_iter()
            .map(|&p| leaf_node(corners[p as usize], p, NONE, 0))
            .collect();
        // 3. The nodes, laid out top down with each node's two children side by side (their
        //    placeholders take the corners of the parent's first patch right after its split;
        //    `refit_all` fills in the clusters).
        self.nodes.clear();
        // A binary tree over the leaves.
        self.nodes.reserve_exact(2 * leaves.len() - 1);
        self.nodes
            .push(leaf_node(corners[root_head as usize], NONE, NONE, 0));
        // (node, first of its range, its shape)
        let mut stack = vec![(0u32, 0usize, &shape)];
        while let Some((node, first, shape)) = stack.pop() {
            let Shape::Split { mid, head, parts } = shape else {
                let parent = self.nodes[node as usize].parent;
                self.nodes[node as usize] = Node {
                    parent,
                    ..leaves[first].clone()
                };
                continue;
            };
            let child = self.nodes.len() as u32;
            for _ in 0..2 {
                self.nodes.push(placeholder(corners[*head as usize], node));
            }
            let n = &mut self.nodes[node as usize];
            n.first_child = child;
            n.child_count = 2;
            n.patch = NONE;
            stack.push((child, first, &parts[0]));
            stack.push((child + 1, first + mid, &parts[1]));
        }
    }

    /// Sets every cluster's normal cone and height from the triangles below it (the leaves are
    /// the patches: pieces split later share their patch's plane, so ancestors' bounds hold).
    fn compute_cones(&mut self) {
        // Area-weighted normal sums, bottom-up (children have larger indices than parents).
        let mut sums = vec![DVec3::ZERO; self.nodes.len()];
        for i in (0..self.nodes.len()).rev() {
            let n = &self.nodes[i];
            if n.is_leaf() {
                sums[i] = n.cone_axis * n.area;
            }
            if n.parent != NONE {
                let s = sums[i];
                sums[n.parent as usize] += s;
            }
        }
        for (i, n) in self.nodes.iter_mut().enumerate() {
            if !n.is_leaf() {
                n.cone_axis = sums[i].normalize_or_zero();
                n.cone_cos = 1.0;
                n.height = f64::NEG_INFINITY;
            }
        }
        // Every leaf widens the cones and heights of its ancestors.
        for i in 0..self.nodes.len() {
            if !self.nodes[i].is_leaf() {
                continue;
            }
            let Some((n, d)) = self.nodes[i].plane else {
                continue;
            };
            let mut a = self.nodes[i].parent;
            while a != NONE {
                let node = &mut self.nodes[a as usize];
                let cos = if node.cone_axis == DVec3::ZERO {
                    -1.0
                } else {
                    node.cone_axis.dot(n)
                };
                node.cone_cos = node.cone_cos.min(cos);
                node.height = node.height.max(n.dot(node.center) - d);
                a = node.parent;
            }
        }
    }

    /// True when every point of node `s`'s bounding sphere lies in or behind the plane of every
    /// triangle below node `r` (within `tol`): nothing leaving `s` reaches the front of anything
    /// in `r`. Conservative: false when it cannot be shown.
    pub fn behind_all(&self, s: u32, r: u32, tol: f64) -> bool {
        let sn = &self.nodes[s as usize];
        self.sphere_behind_all(sn.center, sn.radius, r, tol)
    }

    /// True when point `p` lies strictly behind the plane of every triangle below node `r`, by
    /// more than `tol`: the normal-cone bound first, then, for nodes of at most `max_leaves`
    /// leaves, each leaf's plane. Conservative: false when it cannot be shown.
    pub fn point_behind_all(&self, p: DVec3, r: u32, tol: f64, max_leaves: usize) -> bool {
        if self.sphere_behind_all(p, 0.0, r, -tol) {
            return true;
        }
        let rn = &self.nodes[r as usize];
        if rn.plane.is_some() || rn.cone_cos >= 1.0 {
            // One normal below r: the bound is already the largest height over the planes.
            return false;
        }
        let mut stack: smallvec::SmallVec<[u32; 16]> = smallvec::smallvec![r];
        let mut leaves = 0;
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i as usize];
            if n.is_leaf() {
                leaves += 1;
                if leaves > max_leaves {
                    return false;
                }
                match n.plane {
                    Some((normal, d)) if normal.dot(p) - d < -tol => {}
                    _ => return false,
                }
            } else {
                stack.extend(n.first_child..n.first_child + n.child_count as u32);
            }
        }
        true
    }

    /// [`Self::behind_all`] for a sphere given by centre and radius.
    fn sphere_behind_all(&self, center: DVec3, radius: f64, r: u32, tol: f64) -> bool {
        let rn = &self.nodes[r as usize];
        if rn.cone_cos <= -1.0 {
            return false;
        }
        // For a triangle t below r with normal n_t and a point y of the sphere (c_s, r_s):
        // n_t . y - d_t = n_t . (c_s - c_r) + n_t . (y - c_s) + (n_t . c_r - d_t)
        //              <= max over the cone of n . D   +   r_s   +   height(r).
        let dv = center - rn.center;
        // The cone's axis lies in the cone, so the bound is at least axis . D: most pairs
        // are decided by that alone, without a square root.
        let axis_dot = rn.cone_axis.dot(dv);
        if axis_dot + radius + rn.height > tol {
            return false;
        }
        let len = dv.length();
        let max_dot = if len > 0.0 {
            // cos(max(0, theta - alpha)), theta the angle between the axis and D, alpha the
            // cone's half-angle: 1 when D is inside the cone, else cos(theta - alpha).
            let cos_theta = (axis_dot / len).clamp(-1.0, 1.0);
            let cos_alpha = rn.cone_cos.clamp(-1.0, 1.0);
            if cos_theta >= cos_alpha {
                len
            } else {
                let sin_theta = (1.0 - cos_theta * cos_theta).sqrt();
                let sin_alpha = (1.0 - cos_alpha * cos_alpha).sqrt();
                // Safety margin for rounding.
                len * ((cos_theta * cos_alpha + sin_theta * sin_alpha) + tolerances::CONE_COS_SLACK)
                    .min(1.0)
            }
        } else {
            0.0
        };
        max_dot + radius + rn.height <= tol
    }

    /// Recomputes every cluster's bounds, sphere, area and plane from its children (bottom-up).
    fn refit_all(&mut self) {
        // Children always have larger indices than their parent, so a reverse sweep is bottom-up.
        for i in (0..self.nodes.len()).rev() {
            if !self.nodes[i].is_leaf() {
                self.refit(i);
            }
        }
    }

    fn refit(&mut self, i: usize) {
        let (first, count) = (
            self.nodes[i].first_child as usize,
            self.nodes[i].child_count as usize,
        );
        let children = &self.nodes[first..first + count];
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut area = 0.0;
        let mut moment = DVec3::ZERO;
        for c in children {
            lo = lo.min(c.bounds.0);
            hi = hi.max(c.bounds.1);
            area += c.area;
            moment += c.centroid * c.area;
        }
        let centroid = if area > 0.0 {
            moment / area
        } else {
            (lo + hi) * 0.5
        };
        // Parallel-axis sum of the children's second moments about the new centroid.
        let mean_square = if area > 0.0 {
            children
                .iter()
                .map(|c| c.area * (c.mean_square + (c.centroid - centroid).length_squared()))
                .sum::<f64>()
                / area
        } else {
            0.0
        };
        let center = (lo + hi) * 0.5;
        let radius = children
            .iter()
            .map(|c| (c.center - center).length() + c.radius)
            .fold(0.0, f64::max);
        // Flat when every child is flat, faces the same way, and lies within the plane
        // tolerance of the first child's plane (its box, clamped by its sphere).
        let size = (hi - lo).length().max(f64::MIN_POSITIVE);
        let tol = geometry::plane_tol(size);
        let plane = children[0].plane.filter(|&(n, d)| {
            children.iter().all(|c| {
                c.plane.is_some_and(|(n2, _)| {
                    let (low, high) = signed_extent(c, n, d);
                    n.dot(n2) > 0.0 && low >= -tol && high <= tol
                })
            })
        });
        let node = &mut self.nodes[i];
        node.bounds = (lo, hi);
        node.center = center;
        node.radius = radius;
        node.area = area;
        node.centroid = centroid;
        node.mean_square = mean_square;
        node.plane = plane;
    }

    /// Splits leaf `i` into the pieces [`geometry::split_in_pieces`] gives (new leaves, same
    /// patch, same orientation, each at most half as long) and returns the first child.
    /// Ancestors' bounds do not change (the pieces cover the same triangle).
    ///
    /// A well-shaped triangle is split in four by two rounds of longest-edge bisection (four
    /// pieces per split: with two, on-demand splits stopped at half the elements, Cornell box
    /// 184 -> 96 elements, error 1.70% -> 2.20%). Bisection keeps a sliver's shape, so a sliver
    /// is cut across its two long edges instead, in three pieces half as long, those beside its
    /// short edge about as wide, so that repeated splits end in well-shaped pieces (the
    /// generated classroom, whose polygons are fanned into slivers: 66,894 elements and 18.7M
    /// links with bisection, 47,154 and 13.4M cut across, the same error against its 16,384-spp
    /// path-traced reference, 2.31%).
    pub fn split_leaf(&mut self, i: u32) -> u32 {
        let node = &self.nodes[i as usize];
        debug_assert!(node.is_leaf());
        let (patch, depth, corners) = (node.patch, node.split_depth, node.corners);
        let (blocks_back, emits, two_sided) = (node.blocks_back, node.emits, node.two_sided);
        let light = node.light;
        let first = self.nodes.len() as u32;
        let pieces = geometry::split_in_pieces(&corners);
        for &piece in &pieces {
            let mut leaf = leaf_node(piece, patch, i, depth + 1);
            leaf.blocks_back = blocks_back;
            leaf.emits = emits;
            leaf.two_sided = two_sided;
            leaf.light = light;
            self.nodes.push(leaf);
        }
        let node = &mut self.nodes[i as usize];
        node.first_child = first;
        node.child_count = pieces.len() as u8;
        first
    }

    /// Undoes every [`ClusterTree::split_leaf`] made since the tree had `len` nodes: the pieces
    /// are removed and the leaves they came from are leaves again (the element order is
    /// cleared; [`ClusterTree::finalize`] sets it again). `len` must be a node count the tree
    /// had before those splits, with no split made before it undone since.
    pub fn unsplit(&mut self, len: usize) {
        if len >= self.nodes.len() {
            return;
        }
        let first_piece = len as u32;
        self.nodes.truncate(len);
        for node in &mut self.nodes {
            if node.child_count > 0 && node.first_child >= first_piece {
                node.first_child = NONE;
                node.child_count = 0;
            }
        }
        self.elements.clear();
    }

    /// Splits every leaf whose radius exceeds `ratio` times its distance from one of `points`
    /// (point and spot lights, unit frame) that lies in front of it (either side of a two-sided
    /// leaf), and its pieces in turn, while above `min_radius` and under `max_depth` splits: a
    /// point light's irradiance varies over a triangle by about its size over its distance, and
    /// each piece is then given its own direct light. Call before refinement. Returns the
    /// number of leaves split.
    pub fn split_toward_points(
        &mut self,
        points: &[DVec3],
        ratio: f64,
        max_depth: u8,
        min_radius: f64,
    ) -> usize {
        if points.is_empty() {
            return 0;
        }
        // A leaf is one triangle: its plane is always set.
        let near = |n: &Node| {
            let Some((normal, d)) = n.plane else {
                return false;
            };
            points.iter().any(|&x| {
                let height = normal.dot(x) - d;
                (height > 0.0 || n.two_sided) && n.radius > ratio * (x - n.center).length()
            })
        };
        let mut todo: Vec<u32> = (0..self.nodes.len() as u32)
            .filter(|&i| self.nodes[i as usize].is_leaf())
            .collect();
        let mut splits = 0;
        while let Some(i) = todo.pop() {
            let n = &self.nodes[i as usize];
            if n.split_depth >= max_depth || n.radius <= min_radius || !near(n) {
                continue;
            }
            let first = self.split_leaf(i);
            splits += 1;
            let count = self.nodes[i as usize].child_count as u32;
            todo.extend(first..first + count);
        }
        splits
    }

    /// Marks the leaves of patches with `per_patch[p]` as blocking light at their back, and
    /// every ancestor of such a leaf. Call before refinement (pieces split later inherit it).
    ///
    /// # Panics
    /// When `per_patch` is shorter than a leaf's patch index.
    pub fn mark_back_blocking(&mut self, per_patch: &[bool]) {
        self.mark_with_ancestors(per_patch, |n| &mut n.blocks_back);
    }

    /// Marks the leaves of patches with `per_patch[p]` as emitting, and every ancestor of such
    /// a leaf. Call before refinement (pieces split later inherit it).
    ///
    /// # Panics
    /// When `per_patch` is shorter than a leaf's patch index.
    pub fn mark_emitting(&mut self, per_patch: &[bool]) {
        self.mark_with_ancestors(per_patch, |n| &mut n.emits);
    }

    /// Sets `flag` on the leaves of patches with `per_patch[p]` and on their ancestors, and
    /// clears it everywhere else.
    fn mark_with_ancestors(&mut self, per_patch: &[bool], flag: fn(&mut Node) -> &mut bool) {
        for n in &mut self.nodes {
            *flag(n) = false;
        }
        for i in 0..self.nodes.len() {
            let n = &self.nodes[i];
            if !n.is_leaf() || !per_patch[n.patch as usize] {
                continue;
            }
            // Up to the first ancestor already marked (its own ancestors are).
            let mut a = i as u32;
            loop {
                *flag(&mut self.nodes[a as usize]) = true;
                a = self.nodes[a as usize].parent;
                if a == NONE || *flag(&mut self.nodes[a as usize]) {
                    break;
                }
            }
        }
    }

    /// Sets every node's [`Node::light`]: a leaf's from `per_patch[p]`, its patch's brightness
    /// over the scene's typical surface's (values below 1, NaN and missing ones count 1), a
    /// cluster's the largest of its leaves'.
    pub fn mark_light(&mut self, per_patch: &[f32]) {
        for n in &mut self.nodes {
            let light = if n.is_leaf() {
                per_patch.get(n.patch as usize).copied().unwrap_or(1.0)
            } else {
                1.0
            };
            n.light = if light > 1.0 { light } else { 1.0 };
        }
        for i in 0..self.nodes.len() {
            let n = &self.nodes[i];
            if !n.is_leaf() || n.light <= 1.0 {
                continue;
            }
            let (light, mut a) = (n.light, n.parent);
            while a != NONE && self.nodes[a as usize].light < light {
                self.nodes[a as usize].light = light;
                a = self.nodes[a as usize].parent;
            }
        }
    }

    /// Marks the leaves of patches with `per_patch[p]` (missing entries: false) as two-sided.
    /// Call before refinement (pieces split later inherit it); two-sided patches must block
    /// light at their back as well ([`ClusterTree::mark_back_blocking`]).
    pub fn mark_two_sided(&mut self, per_patch: &[bool]) {
        for n in &mut self.nodes {
            n.two_sided = n.is_leaf() && per_patch.get(n.patch as usize).copied().unwrap_or(false);
        }
    }

    /// Numbers the leaves in depth-first order and sets every node's element range.
    pub fn finalize(&mut self) {
        self.elements.clear();
        // Iterative post-order: ranges are known once all children are done.
        let mut stack = vec![(0u32, false)];
        while let Some((i, done)) = stack.pop() {
            let node = &self.nodes[i as usize];
            if node.is_leaf() {
                let e = self.elements.len() as u32;
                self.elements.push(i);
                self.nodes[i as usize].elements = (e, e + 1);
            } else if done {
                let first = node.first_child as usize;
                let last = first + node.child_count as usize - 1;
                let range = (self.nodes[first].elements.0, self.nodes[last].elements.1);
                self.nodes[i as usize].elements = range;
            } else {
                stack.push((i, true));
                for c in (node.first_child..node.first_child + node.child_count as u32).rev() {
                    stack.push((c, false));
                }
            }
        }
    }

    /// Checks the tree's invariants: parents and children agree, every cluster's sphere contains
    /// its children's and every split triangle's the corners of its pieces, areas add up,
    /// element ranges nest. Returns the first violation found.
    pub fn validate(&self) -> Result<(), String> {
        for (i, n) in self.nodes.iter().enumerate() {
            if n.is_leaf() {
                if n.patch == NONE {
                    return Err(format!("leaf {i} has no patch"));
                }
                continue;
            }
            let mut area = 0.0;
            for c in n.first_child..n.first_child + n.child_count as u32 {
                let child = &self.nodes[c as usize];
                if child.parent != i as u32 {
                    return Err(format!("node {c}'s parent is {} not {i}", child.parent));
                }
                // A cluster's sphere contains its children's; a split leaf's contains its
                // pieces' corners (a half's own sphere, about its centroid, may reach out of it).
                let reach = if n.patch != NONE && child.is_leaf() {
                    (child.corners.iter().map(|c| (*c - n.center).length())).fold(0.0, f64::max)
                } else {
                    (child.center - n.center).length() + child.radius
                };
                if reach
                    > n.radius * (1.0 + tolerances::TREE_CHECK_RELATIVE)
                        + tolerances::TREE_CHECK_ABSOLUTE
                {
                    return Err(format!("node {i}'s sphere does not contain child {c}"));
                }
                if !self.elements.is_empty()
                    && (child.elements.0 < n.elements.0 || child.elements.1 > n.elements.1)
                {
                    return Err(format!("node {c}'s elements are outside its parent's"));
                }
                area += child.area;
            }
            if (area - n.area).abs() > tolerances::TREE_CHECK_RELATIVE * n.area.max(1e-300) {
                return Err(format!("node {i}'s area {} != children's {area}", n.area));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::build_patches;
    use crate::scene::Scene;

    /// A UV sphere with outward normals (a curved, closed mesh) and a few flat quads.
    fn curved_scene() -> Scene {
        let (nu, nv) = (12, 8);
        let p = |i: usize, j: usize| {
            let (u, v) = (
                i as f64 / nu as f64 * std::f64::consts::TAU,
                j as f64 / nv as f64 * std::f64::consts::PI,
            );
            DVec3::new(v.sin() * u.cos(), v.cos(), v.sin() * u.sin())
        };
        let mut tris = Vec::new();
        for i in 0..nu {
            for j in 0..nv {
                let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
                for t in [[a, b, c], [a, c, d]] {
                    if geometry::area(&t) > 1e-9 {
                        tris.push(t);
                    }
                }
            }
        }
        // A floor under the sphere, facing up.
        let f = |x: f64, z: f64| DVec3::new(x, -1.5, z);
        tris.push([f(-2.0, -2.0), f(-2.0, 2.0), f(2.0, 2.0)]);
        tris.push([f(-2.0, -2.0), f(2.0, 2.0), f(2.0, -2.0)]);
        let n = tris.len();
        Scene::from_triangles(&tris, &vec![[0.5; 3]; n], &vec![[0.0; 3]; n])
    }

    /// A floor of two triangles with a point above one corner: the leaves near it are split
    /// until each is small beside its distance (or at the depth limit), those far from it keep
    /// their size, and a point below the floor (behind it) splits nothing.
    #[test]
    fn leaves_split_toward_a_point_in_front_only() {
        let f = |x: f64, z: f64| DVec3::new(x, 0.0, z);
        let tris = [
            [f(0.0, 0.0), f(0.0, 1.0), f(1.0, 1.0)],
            [f(0.0, 0.0), f(1.0, 1.0), f(1.0, 0.0)],
        ];
        let scene = Scene::from_triangles(&tris, &[[0.5; 3]; 2], &[[0.0; 3]; 2]);
        let patches = build_patches(&scene, None);
        let build = || ClusterTree::build(&patches);
        // Unit frame: the floor's corner (0, 0, 0) and a point 0.05 above it, scene units.
        let unit = |x: DVec3| patches.frame.unit_from_world(x);
        let light = unit(DVec3::new(0.0, 0.05, 0.0));
        let mut tree = build();
        let splits = tree.split_toward_points(&[light], 0.5, 4, 0.0);
        tree.finalize();
        tree.validate().unwrap();
        assert!(splits > 0);
        let leaves: Vec<&Node> = tree.nodes.iter().filter(|n| n.is_leaf()).collect();
        for n in &leaves {
            let near = n.radius > 0.5 * (light - n.center).length();
            assert!(!near || n.split_depth == 4, "{n:?}");
        }
        let depths: Vec<u8> = leaves.iter().map(|n| n.split_depth).collect();
        assert!(
            depths.contains(&4) && depths.iter().any(|&d| d < 2),
            "{depths:?}"
        );
        let mut behind = build();
        let below = unit(DVec3::new(0.0, -0.05, 0.0));
        assert_eq!(behind.split_toward_points(&[below], 0.5, 4, 0.0), 0);
    }

    /// Splits undone give back the tree they were made on, and splitting it again gives the
    /// same tree as splitting a fresh one (the attempts of a coarsened solve share one tree).
    #[test]
    fn unsplit_restores_the_tree() {
        let patches = build_patches(&curved_scene(), None);
        let mut fresh = ClusterTree::build(&patches);
        let len = fresh.nodes.len();
        let mut tree = fresh.clone();
        let leaves: Vec<u32> = (0..len as u32)
            .filter(|&i| tree.nodes[i as usize].is_leaf())
            .collect();
        for &leaf in leaves.iter().step_by(3) {
            let first = tree.split_leaf(leaf);
            tree.split_leaf(first);
        }
        assert!(tree.nodes.len() > len + leaves.len());
        tree.unsplit(len);
        let key = |t: &ClusterTree| {
            t.nodes
                .iter()
                .map(|n| {
                    (
                        n.first_child,
                        n.child_count,
                        n.parent,
                        n.patch,
                        n.split_depth,
                    )
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(key(&tree), key(&fresh));
        for t in [&mut tree, &mut fresh] {
            t.split_leaf(leaves[1]);
            t.finalize();
        }
        assert_eq!(key(&tree), key(&fresh));
        assert_eq!(tree.elements, fresh.elements);
        let valid = tree.validate();
        assert!(valid.is_ok(), "{valid:?}");
    }

    #[test]
    fn behind_all_is_conservative() {
        let patches = build_patches(&curved_scene(), None);
        let mut tree = ClusterTree::build(&patches);
        tree.finalize();
        tree.validate().unwrap();
        let leaves: Vec<u32> = tree.elements.clone();

        let mut culled = 0;
        for r in 0..tree.nodes.len() as u32 {
            for s in 0..tree.nodes.len() as u32 {
                if s == r || !tree.behind_all(s, r, 0.0) {
                    continue;
                }
                culled += 1;
                let (r0, r1) = tree.nodes[r as usize].elements;
                let (s0, s1) = tree.nodes[s as usize].elements;
                for &re in &leaves[r0 as usize..r1 as usize] {
                    let (n, d) = tree.nodes[re as usize].plane.unwrap();
                    for &se in &leaves[s0 as usize..s1 as usize] {
                        for c in tree.nodes[se as usize].corners {
                            assert!(n.dot(c) - d <= 1e-12, "node {s} is not behind node {r}");
                        }
                    }
                }
            }
        }
        // The test is useful: on a sphere, far sides are behind each other.
        assert!(culled > 1000, "{culled}");
    }

    #[test]
    fn a_cluster_is_as_bright_as_its_brightest_leaf_and_pieces_keep_their_patchs_light() {
        let patches = build_patches(&curved_scene(), None);
        let mut tree = ClusterTree::build(&patches);
        let mut per_patch = vec![1.0f32; patches.len()];
        per_patch[3] = 5.0;
        per_patch[4] = f32::NAN;
        per_patch[5] = 0.5;
        tree.mark_light(&per_patch);
        let leaf_of = |tree: &ClusterTree, p: u32| {
            (0..tree.nodes.len()).find(|&i| tree.nodes[i].is_leaf() && tree.nodes[i].patch == p)
        };
        let bright = leaf_of(&tree, 3).expect("patch 3 has a leaf");
        assert_eq!(tree.nodes[bright].light, 5.0);
        assert_eq!(tree.nodes[0].light, 5.0, "the root holds patch 3");
        for p in [4, 5, 6] {
            let leaf = leaf_of(&tree, p).expect("a leaf");
            assert_eq!(tree.nodes[leaf].light, 1.0, "patch {p}");
        }
        // Every cluster: the largest of its children's, and at least 1.
        for n in tree.nodes.iter().filter(|n| !n.is_leaf()) {
            let children = n.first_child as usize..n.first_child as usize + n.child_count as usize;
            let most = children.map(|c| tree.nodes[c].light).fold(1.0f32, f32::max);
            assert_eq!(n.light, most);
        }
        let first = tree.split_leaf(bright as u32) as usize;
        let count = tree.nodes[bright].child_count as usize;
        assert!(count >= 3);
        assert!(tree.nodes[first..first + count]
            .iter()
            .all(|n| n.light == 5.0));
    }
}
