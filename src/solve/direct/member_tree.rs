//! A bounding-sphere tree over an emitter group's members, each node with its own rim, so that
//! a receiver's plane or quadrature visits the members near it, not all of them.
//!
//! A ceiling light of n triangles cut by a receiver's plane cost n member tests per receiver;
//! its contour, `4 sqrt(n)` edges when the light is a subdivided square. With the tree, a node
//! wholly in front of the plane adds its rim (the edges of its members not shared within the
//! node, collinear runs merged: exactly the sum of its members' contours, as shared edges
//! cancel), a node wholly behind adds nothing, and only the members near the cut are visited.

use super::*;
use std::collections::HashMap;

/// Most members of a leaf.
const LEAF_MEMBERS: usize = 4;

/// `|(b - a) x (c - b)|` at most this times `|b - a| |c - b|`: `b` counts as on the segment `a c`
/// (see [`merge_collinear`]).
const COLLINEAR: f64 = 1e-12;

/// One node: a contiguous range of [`MemberTree::order`].
#[derive(Clone, Copy, Debug)]
pub(super) struct MemberNode {
    /// Bounding sphere of the members' corners.
    pub(super) center: DVec3,
    pub(super) radius: f64,
    /// Largest member size (longest edge) in the node: the members' plane tolerances
    /// ([`plane_tol`]) grow with it.
    pub(super) size: f64,
    /// Largest member bounding radius (about its centroid) in the node.
    pub(super) member_radius: f64,
    /// Members `order[start..end]`.
    pub(super) start: u32,
    pub(super) end: u32,
    /// Children (indices into [`MemberTree::nodes`]); both 0 for a leaf.
    pub(super) children: [u32; 2],
    /// Rim edges `rims[rim_start..rim_end]`.
    pub(super) rim_start: u32,
    pub(super) rim_end: u32,
}

impl MemberNode {
    /// True for a leaf (its members are visited one by one).
    pub(super) fn is_leaf(&self) -> bool {
        self.children[0] == 0
    }

    /// True when every member's bounding sphere (about its centroid, as [`separation`] measures
    /// it) is farther than `gap` from `x`: each centroid lies in the node's sphere and each
    /// member's radius is at most `member_radius`.
    pub(super) fn farther_than(&self, x: DVec3, gap: f64) -> bool {
        (x - self.center).length() - self.radius - self.member_radius > gap
    }
}

/// The tree of one group (see the module documentation). Node 0 is the root.
pub(super) struct MemberTree {
    pub(super) nodes: Vec<MemberNode>,
    /// Member positions (indices into the group's `members`) in tree order.
    pub(super) order: Vec<u32>,
    /// Every node's rim, concatenated; valid (the node's contour) only for a manifold group.
    pub(super) rims: Vec<(DVec3, DVec3)>,
}

impl MemberTree {
    /// The tree of `members` (indices into `emitters`) with their edge `neighbours` (positions in
    /// `members`, see [`EmitterGroup::neighbours`]).
    pub(super) fn new(emitters: &Emitters, members: &[u32], neighbours: &[[u32; 3]]) -> MemberTree {
        let mut tree = MemberTree {
            nodes: Vec::new(),
            order: (0..members.len() as u32).collect(),
            rims: Vec::new(),
        };
        if members.is_empty() {
            return tree;
        }
        // 1. Split ranges at the median along the widest axis of their centroids.
        let geom = |i: u32| &emitters.geom[members[i as usize] as usize];
        let mut stack = vec![(0usize, members.len(), usize::MAX, 0usize)];
        while let Some((start, end, parent, side)) = stack.pop() {
            let index = tree.nodes.len();
            if parent != usize::MAX {
                tree.nodes[parent].children[side] = index as u32;
            }
            let range = &mut tree.order[start..end];
            let center =
                range.iter().map(|&i| geom(i).centroid).sum::<DVec3>() / range.len() as f64;
            let radius = range
                .iter()
                .flat_map(|&i| geom(i).corners)
                .map(|c| (c - center).length())
                .fold(0.0, f64::max);
            let size = range.iter().map(|&i| geom(i).size).fold(0.0, f64::max);
            let member_radius = range.iter().map(|&i| geom(i).radius).fold(0.0, f64::max);
            tree.nodes.push(MemberNode {
                center,
                radius,
                size,
                member_radius,
                start: start as u32,
                end: end as u32,
                children: [0, 0],
                rim_start: 0,
                rim_end: 0,
            });
            if end - start <= LEAF_MEMBERS {
                continue;
            }
            let (low, high) = range.iter().fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), &i| (lo.min(geom(i).centroid), hi.max(geom(i).centroid)),
            );
            let extent = high - low;
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let middle = range.len() / 2;
            range.select_nth_unstable_by(middle, |&a, &b| {
                geom(a).centroid[axis].total_cmp(&geom(b).centroid[axis])
            });
            stack.push((start + middle, end, index, 1));
            stack.push((start, start + middle, index, 0));
        }
        // 2. Each node's rim: its members' edges whose neighbour is outside the node.
        let mut rank = vec![0u32; members.len()];
        for (r, &i) in tree.order.iter().enumerate() {
            rank[i as usize] = r as u32;
        }
        for node in 0..tree.nodes.len() {
            let (start, end) = (tree.nodes[node].start, tree.nodes[node].end);
            let mut rim = Vec::new();
            for &i in &tree.order[start as usize..end as usize] {
                let c = geom(i).corners;
                for (j, &across) in neighbours[i as usize].iter().enumerate() {
                    let inside =
                        across != NO_NEIGHBOUR && (start..end).contains(&rank[across as usize]);
                    if !inside {
                        rim.push((c[j], c[(j + 1) % 3]));
                    }
                }
            }
            let rim = merge_collinear(rim);
            tree.nodes[node].rim_start = tree.rims.len() as u32;
            tree.rims.extend(rim);
            tree.nodes[node].rim_end = tree.rims.len() as u32;
        }
        tree
    }

    /// The rim edges of `node`.
    pub(super) fn rim(&self, node: &MemberNode) -> &[(DVec3, DVec3)] {
        &self.rims[node.rim_start as usize..node.rim_end as usize]
    }

    /// The member positions (into the group's `members`) of `node`.
    pub(super) fn members(&self, node: &MemberNode) -> &[u32] {
        &self.order[node.start as usize..node.end as usize]
    }

    /// Visits the nodes below `root` top down, depth first: `visit(index, node)` is called for
    /// each node reached and returns whether to go on into its children (a leaf's members are
    /// the visitor's to take, through [`Self::members`]).
    pub(super) fn walk(&self, root: u32, mut visit: impl FnMut(u32, &MemberNode) -> bool) {
        // On the stack: a walk per receiver and emitter group, each allocating, was measurable.
        let mut stack: smallvec::SmallVec<[u32; 64]> = smallvec::smallvec![root];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if visit(n, node) && !node.is_leaf() {
                stack.extend(node.children);
            }
        }
    }
}

/// A part of a group: a node of its tree (all its members) or one member (its position in the
/// group's `members`).
#[derive(Clone, Copy, Debug)]
pub(super) enum Part {
    Node(u32),
    Member(u32),
}

/// Calls `visit` with the position of every member of `parts`.
pub(super) fn for_each_member(tree: &MemberTree, parts: &[Part], mut visit: impl FnMut(u32)) {
    for &part in parts {
        match part {
            Part::Member(i) => visit(i),
            Part::Node(n) => tree
                .members(&tree.nodes[n as usize])
                .iter()
                .for_each(|&i| visit(i)),
        }
    }
}

/// `edges` (directed) with each run of collinear edges joined end to start merged into one edge
/// from the run's first start to its last end: the same Lambert contour sum (an edge's term is
/// an integral along it, so a straight edge split at a point on it gives the same sum), for
/// the cost of the run's straight pieces. A subdivided square light's rim of `4 k` edges becomes
/// its 4 sides. Points join when bit-identical; a point counts as on the segment when the turn
/// there is below [`COLLINEAR`] (relative), so the sum moves by rounding only.
pub(super) fn merge_collinear(edges: Vec<(DVec3, DVec3)>) -> Vec<(DVec3, DVec3)> {
    if edges.len() < 2 {
        return edges;
    }
    let mut leaving: HashMap<[u64; 3], Vec<u32>> = HashMap::new();
    for (i, &(a, _)) in edges.iter().enumerate() {
        leaving.entry(point_key(a)).or_default().push(i as u32);
    }
    let straight_on = |a: DVec3, b: DVec3, c: DVec3| {
        let (u, v) = (b - a, c - b);
        u.dot(v) > 0.0 && u.cross(v).length() <= COLLINEAR * u.length() * v.length()
    };
    // An edge is taken into the run of the edge before it when it continues it straight on.
    let mut absorbed = vec![false; edges.len()];
    let mut next: Vec<Option<u32>> = vec![None; edges.len()];
    for (i, &(a, b)) in edges.iter().enumerate() {
        let Some(candidates) = leaving.get(&point_key(b)) else {
            continue;
        };
        if let Some(&j) = candidates.iter().find(|&&j| {
            j as usize != i && !absorbed[j as usize] && straight_on(a, b, edges[j as usize].1)
        }) {
            absorbed[j as usize] = true;
            next[i] = Some(j);
        }
    }
    let mut merged = Vec::with_capacity(edges.len());
    let mut visited = vec![false; edges.len()];
    // Runs start at edges no other edge continues into; what is left is closed loops of
    // collinear edges (impossible for a real contour, kept edge by edge).
    let mut push_run = |start: usize, visited: &mut Vec<bool>| {
        let (a, mut b) = edges[start];
        visited[start] = true;
        let mut at = start;
        while let Some(j) = next[at] {
            let j = j as usize;
            if visited[j] {
                break;
            }
            visited[j] = true;
            b = edges[j].1;
            at = j;
        }
        merged.push((a, b));
    };
    for (start, _) in absorbed.iter().enumerate().filter(|(_, &a)| !a) {
        push_run(start, &mut visited);
    }
    for (edge, _) in edges.iter().zip(&visited).filter(|(_, &v)| !v) {
        merged.push(*edge);
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn collinear_runs_merge_and_keep_the_contour_sum() {
        let v = DVec3::new;
        // A square's rim, each side split in 3 (one split point moved off its line).
        let corners = [
            v(0.0, 0.0, 0.0),
            v(1.0, 0.0, 0.0),
            v(1.0, 1.0, 0.0),
            v(0.0, 1.0, 0.0),
        ];
        let mut edges = Vec::new();
        for s in 0..4 {
            let (a, b) = (corners[s], corners[(s + 1) % 4]);
            let p = |t: f64| a + (b - a) * t;
            let mut mid = p(2.0 / 3.0);
            if s == 2 {
                mid.z += 1e-3;
            }
            edges.extend([(a, p(1.0 / 3.0)), (p(1.0 / 3.0), mid), (mid, b)]);
        }
        let merged = merge_collinear(edges.clone());
        assert_eq!(
            merged.len(),
            4 + 2,
            "three straight sides, one bent side in 3 pieces"
        );
        let x = v(0.3, 0.4, 0.8);
        let n = v(0.1, -0.2, -1.0).normalize();
        let sum = |e: &[(DVec3, DVec3)]| -> f64 {
            e.iter()
                .map(|&(a, b)| geometry::lambert_edge(a - x, b - x, n))
                .sum()
        };
        assert!((sum(&merged) - sum(&edges)).abs() < 1e-14);
    }
}
