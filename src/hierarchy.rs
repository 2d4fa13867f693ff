//! Stage 3a: the cluster tree over the patches, with on-demand subdivision of leaf triangles.
//!
//! The upper levels come from an obvhs BVH2 over the patches (one patch per leaf). Below a patch,
//! [`ClusterTree::split_leaf`] cuts a leaf triangle into its four midpoint sub-triangles when link
//! refinement asks for it, so a coarse input (a floor of two triangles) becomes fine exactly where
//! transport needs it. After refinement, [`ClusterTree::finalize`] numbers the leaves ("elements")
//! in depth-first order so every node covers a contiguous range of elements.

use std::time::Duration;

use glam::{DVec3, Vec3A};

use crate::geometry::{self, Tri, PLANE_EPS};
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
    /// Elements below this node, `elements.0 .. elements.1` (set by [`ClusterTree::finalize`]).
    pub elements: (u32, u32),
    /// Cone of the normals below: unit axis (zero when the normals cancel out).
    pub cone_axis: DVec3,
    /// Cosine of the cone's half-angle: every normal below `n` has `n . cone_axis >= cone_cos`
    /// (-1: no bound).
    pub cone_cos: f64,
    /// Largest height of `center` above the plane of any triangle below,
    /// `max_t (n_t . center - n_t . v_t)`: with the cone it bounds from above the height of any
    /// point above every triangle's plane (see [`ClusterTree::behind_all`]).
    pub height: f64,
}

impl Node {
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
    /// Time spent in the obvhs build.
    pub bvh_time: Duration,
}

fn leaf_node(corners: Tri, patch: u32, parent: u32, split_depth: u8) -> Node {
    let normal = geometry::normal(&corners).unwrap_or(DVec3::Z);
    let center = geometry::centroid(&corners);
    let radius = corners
        .iter()
        .map(|c| (*c - center).length())
        .fold(0.0, f64::max);
    let lo = corners[0].min(corners[1]).min(corners[2]);
    let hi = corners[0].max(corners[1]).max(corners[2]);
    Node {
        center,
        radius,
        area: geometry::area(&corners),
        centroid: center,
        plane: Some((normal, normal.dot(corners[0]))),
        bounds: (lo, hi),
        first_child: NONE,
        child_count: 0,
        parent,
        patch,
        split_depth,
        corners,
        elements: (0, 0),
        cone_axis: normal,
        cone_cos: 1.0,
        height: 0.0,
    }
}

impl ClusterTree {
    /// Builds the tree over the active patches (an obvhs BVH2 with one patch per leaf).
    ///
    /// # Panics
    /// If no patch is active (the loader rejects such scenes).
    pub fn build(patches: &Patches) -> ClusterTree {
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
        let tris: Vec<obvhs::triangle::Triangle> = active
            .iter()
            .map(|&p| {
                let c = patches.corners[p as usize];
                let v = |x: DVec3| Vec3A::new(x.x as f32, x.y as f32, x.z as f32);
                obvhs::triangle::Triangle {
                    v0: v(c[0]),
                    v1: v(c[1]),
                    v2: v(c[2]),
                }
            })
            .collect();
        let mut params = obvhs::BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 1;
        let mut bvh_time = Duration::ZERO;
        let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(&tris, params, &mut bvh_time);
        tree.bvh_time = bvh_time;

        // Copy the BVH into our own arrays: children contiguous, leaves are patches.
        tree.nodes.push(leaf_node(
            patches.corners[active[0] as usize],
            NONE,
            NONE,
            0,
        ));
        let mut stack = vec![(0usize, 0u32)]; // (bvh node, our node)
        while let Some((b, ours)) = stack.pop() {
            let node = &bvh.nodes[b];
            if node.prim_count > 0 {
                let prims: Vec<u32> = (0..node.prim_count)
                    .map(|k| {
                        active[bvh.primitive_indices[(node.first_index + k) as usize] as usize]
                    })
                    .collect();
                if prims.len() == 1 {
                    let parent = tree.nodes[ours as usize].parent;
                    tree.nodes[ours as usize] =
                        leaf_node(patches.corners[prims[0] as usize], prims[0], parent, 0);
                } else {
                    let first = tree.nodes.len() as u32;
                    for &p in &prims {
                        tree.nodes
                            .push(leaf_node(patches.corners[p as usize], p, ours, 0));
                    }
                    let n = &mut tree.nodes[ours as usize];
                    n.first_child = first;
                    n.child_count = prims.len() as u8;
                    n.patch = NONE;
                }
            } else {
                let first = tree.nodes.len() as u32;
                for k in 0..2 {
                    let mut child = leaf_node(patches.corners[active[0] as usize], NONE, ours, 0);
                    child.patch = NONE;
                    tree.nodes.push(child);
                    stack.push((node.first_index as usize + k, first + k as u32));
                }
                let n = &mut tree.nodes[ours as usize];
                n.first_child = first;
                n.child_count = 2;
                n.patch = NONE;
            }
        }
        tree.refit_all();
        tree.compute_cones();
        tree
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
                len * ((cos_theta * cos_alpha + sin_theta * sin_alpha) + 1e-9).min(1.0)
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
        let center = (lo + hi) * 0.5;
        let radius = children
            .iter()
            .map(|c| (c.center - center).length() + c.radius)
            .fold(0.0, f64::max);
        let size = (hi - lo).length().max(f64::MIN_POSITIVE);
        let plane = children[0].plane.filter(|&(n, d)| {
            children.iter().all(|c| {
                c.plane.is_some_and(|(n2, d2)| {
                    n.dot(n2) > 1.0 - 1e-9 && (d - d2).abs() <= PLANE_EPS * size
                })
            })
        });
        let node = &mut self.nodes[i];
        node.bounds = (lo, hi);
        node.center = center;
        node.radius = radius;
        node.area = area;
        node.centroid = centroid;
        node.plane = plane;
    }

    /// Splits leaf `i` into its four midpoint sub-triangles (new leaves, same patch) and returns
    /// the first child. Ancestors' bounds do not change (the pieces cover the same triangle).
    pub fn split_leaf(&mut self, i: u32) -> u32 {
        let node = &self.nodes[i as usize];
        debug_assert!(node.is_leaf());
        let (patch, depth, corners) = (node.patch, node.split_depth, node.corners);
        let first = self.nodes.len() as u32;
        for piece in geometry::subdivide(&corners, 2) {
            self.nodes.push(leaf_node(piece, patch, i, depth + 1));
        }
        let node = &mut self.nodes[i as usize];
        node.first_child = first;
        node.child_count = 4;
        first
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

    /// Checks the tree's invariants: parents and children agree, every node's sphere contains its
    /// children's, areas add up, element ranges nest. Returns the first violation found.
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
                let reach = (child.center - n.center).length() + child.radius;
                if reach > n.radius * (1.0 + 1e-9) + 1e-12 {
                    return Err(format!("node {i}'s sphere does not contain child {c}"));
                }
                if !self.elements.is_empty()
                    && (child.elements.0 < n.elements.0 || child.elements.1 > n.elements.1)
                {
                    return Err(format!("node {c}'s elements are outside its parent's"));
                }
                area += child.area;
            }
            if (area - n.area).abs() > 1e-9 * n.area.max(1e-300) {
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
}
