//! Sender groups: per node, the area sums of its elements by normal, so a cluster link pulls
//! a few group sums instead of every element.

use super::*;

/// Nodes with at most this many elements pull per element; larger ones pull per normal group.
pub(super) const PULL_PER_ELEMENT_MAX: u32 = 8;

/// Most distinct exact normals a node's groups keep; beyond it normals are grouped by cell of a
/// coarse direction grid (`GROUP_CELLS` x `GROUP_CELLS` octahedral cells, about 45 degrees wide).
pub(super) const MAX_EXACT_GROUPS: usize = 8;
pub(super) const GROUP_CELLS: usize = 4;

/// Normal groups of the large nodes (more than [`PULL_PER_ELEMENT_MAX`] elements).
///
/// A cluster link's sender sends `sum_e a_e (B_e max(0, n_e . w) - A_e[bin] max(0, -n_e . w))`;
/// for elements sharing a normal that is `max(0, n . w) sum a_e B_e - ...`, so a node needs only
/// per-group sums. Flat (architectural) scenes have few exact normals per node and the pull is
/// exact; curved ones are grouped by normal cell with the group's area-weighted mean normal.
#[derive(Clone, Debug, Default)]
pub(super) struct SenderGroups {
    /// Per node, its groups `range.0..range.1` (empty for small nodes).
    pub(super) range: Vec<(u32, u32)>,
    /// Per node, its elements (a compact copy of `Node::elements` for the pull of small
    /// nodes).
    pub(super) elements: Vec<(u32, u32)>,
    /// Per group, the area-weighted mean normal (unit for exact groups, shorter for cells).
    pub(super) normal: Vec<DVec3>,
    /// Per group, its area.
    pub(super) area: Vec<f64>,
    /// Per group: its elements block light at their back (groups never mix the two kinds).
    pub(super) both: Vec<bool>,
    /// Per group, the group of the parent node it adds into ([`NONE`] at the root).
    pub(super) parent_group: Vec<u32>,
    /// Per element, the group of its lowest large ancestor it adds into ([`NONE`] if none).
    pub(super) elem_group: Vec<u32>,
    /// Large nodes, children before parents.
    pub(super) order: Vec<u32>,
    /// (group, its parent group) for every group with a parent, children before parents.
    pub(super) child_parent: Vec<(u32, u32)>,
}

/// What feeds a group: a child's group or an element of a small child.
pub(super) enum GroupInput {
    Group(u32),
    Element(u32),
}

/// The nodes `large` selects, in post-order (children before parents) from the root; a node
/// that is not large ends its branch.
fn large_post_order(tree: &ClusterTree, large: &dyn Fn(u32) -> bool) -> Vec<u32> {
    let mut order = Vec::new();
    let mut stack = vec![(0u32, false)];
    while let Some((i, done)) = stack.pop() {
        if !large(i) {
            continue;
        }
        if done {
            order.push(i);
        } else {
            stack.push((i, true));
            let node = &tree.nodes[i as usize];
            for c in node.first_child..node.first_child + node.child_count as u32 {
                stack.push((c, false));
            }
        }
    }
    order
}

/// The group of each input (by normal and whether it blocks at its back): exact groups when
/// every input has a unit normal and there are at most [`MAX_EXACT_GROUPS`] distinct ones, else
/// cells of the coarse direction grid `cells`. Returns each input's group, each group's
/// "blocks at its back", and whether the groups are exact.
fn group_keys(
    inputs: &[(GroupInput, DVec3, f64)],
    input_back: &[bool],
    cells: &Bins,
) -> (Vec<usize>, Vec<bool>, bool) {
    // Exact groups when every input has a unit normal and there are few distinct ones;
    // else cells of a coarse direction grid.
    let mut distinct: Vec<(DVec3, bool)> = Vec::new();
    let mut key_of: Vec<usize> = Vec::with_capacity(inputs.len());
    let mut exact = true;
    for ((_, n, _), &back) in inputs.iter().zip(input_back) {
        if (n.length_squared() - 1.0).abs() > UNIT_NORMAL_SLACK {
            exact = false;
            break;
        }
        match distinct
            .iter()
            .position(|(d, b)| *b == back && 1.0 - d.dot(*n) <= SAME_NORMAL)
        {
            Some(k) => key_of.push(k),
            None if distinct.len() < MAX_EXACT_GROUPS => {
                key_of.push(distinct.len());
                distinct.push((*n, back));
            }
            None => {
                exact = false;
                break;
            }
        }
    }
    let mut group_back: Vec<bool> = distinct.iter().map(|&(_, b)| b).collect();
    if !exact {
        key_of.clear();
        group_back.clear();
        let mut cell_keys: Vec<(usize, bool)> = Vec::new();
        for ((_, n, _), &back) in inputs.iter().zip(input_back) {
            let cell = (cells.bin_of(*n), back);
            let k = cell_keys
                .iter()
                .position(|&c| c == cell)
                .unwrap_or_else(|| {
                    cell_keys.push(cell);
                    group_back.push(back);
                    cell_keys.len() - 1
                });
            key_of.push(k);
        }
    }
    (key_of, group_back, exact)
}

impl SenderGroups {
    /// Builds the groups of every large node of a finalized tree.
    pub(super) fn build(
        tree: &ClusterTree,
        elem_area: &[f64],
        elem_normal: &[DVec3],
        elem_back: &[bool],
    ) -> SenderGroups {
        let mut groups = SenderGroups {
            range: vec![(0, 0); tree.nodes.len()],
            elements: tree.nodes.iter().map(|n| n.elements).collect(),
            elem_group: vec![NONE; elem_area.len()],
            ..SenderGroups::default()
        };
        if tree.nodes.is_empty() {
            return groups;
        }
        let large = |i: u32| {
            let (e0, e1) = tree.nodes[i as usize].elements;
            e1 - e0 > PULL_PER_ELEMENT_MAX
        };
        groups.order = large_post_order(tree, &large);
        let cells = Bins::new(GROUP_CELLS);
        let order = std::mem::take(&mut groups.order);
        for &i in &order {
            // Inputs: the groups of large children, the elements of small ones.
            let node = &tree.nodes[i as usize];
            let mut inputs: Vec<(GroupInput, DVec3, f64)> = Vec::new();
            let mut input_back: Vec<bool> = Vec::new();
            for c in node.first_child..node.first_child + node.child_count as u32 {
                if large(c) {
                    let (g0, g1) = groups.range[c as usize];
                    for g in g0..g1 {
                        let (n, a) = (groups.normal[g as usize], groups.area[g as usize]);
                        inputs.push((GroupInput::Group(g), n, a));
                        input_back.push(groups.both[g as usize]);
                    }
                } else {
                    let (e0, e1) = tree.nodes[c as usize].elements;
                    for e in e0..e1 {
                        let (n, a) = (elem_normal[e as usize], elem_area[e as usize]);
                        inputs.push((GroupInput::Element(e), n, a));
                        input_back.push(elem_back[e as usize]);
                    }
                }
            }
            let (key_of, group_back, exact) = group_keys(&inputs, &input_back, &cells);
            let count = group_back.len();
            groups.both.extend_from_slice(&group_back);
            let first = groups.normal.len() as u32;
            groups.range[i as usize] = (first, first + count as u32);
            groups
                .normal
                .extend(std::iter::repeat_n(DVec3::ZERO, count));
            groups.area.extend(std::iter::repeat_n(0.0, count));
            groups.parent_group.extend(std::iter::repeat_n(NONE, count));
            // Wire the inputs; group normals are area-weighted means.
            for ((input, n, a), &k) in inputs.iter().zip(&key_of) {
                let g = first + k as u32;
                match input {
                    GroupInput::Group(child) => groups.parent_group[*child as usize] = g,
                    GroupInput::Element(e) => groups.elem_group[*e as usize] = g,
                }
                groups.normal[g as usize] += *a * *n;
                groups.area[g as usize] += *a;
            }
            for g in first as usize..first as usize + count {
                if exact {
                    groups.normal[g] = groups.normal[g].normalize_or_zero();
                } else if groups.area[g] > 0.0 {
                    groups.normal[g] /= groups.area[g];
                }
            }
        }
        for &i in &order {
            let (g0, g1) = groups.range[i as usize];
            for g in g0..g1 {
                let p = groups.parent_group[g as usize];
                if p != NONE {
                    debug_assert!(p > g, "parents' groups follow their children's");
                    groups.child_parent.push((g, p));
                }
            }
        }
        groups.order = order;
        groups
    }

    /// Normal groups per element of `tree` as it stands, its leaves as the elements (the tree
    /// is finalized for it): what the memory estimate assumes before the links are refined.
    pub(super) fn share(tree: &mut ClusterTree) -> f64 {
        tree.finalize();
        let leaves = || tree.elements.iter().map(|&i| &tree.nodes[i as usize]);
        let area: Vec<f64> = leaves().map(|n| n.area).collect();
        let normal: Vec<DVec3> = leaves().map(|n| n.plane_normal()).collect();
        let back: Vec<bool> = leaves().map(|n| n.blocks_back).collect();
        let groups = SenderGroups::build(tree, &area, &normal, &back);
        groups.normal.len() as f64 / area.len().max(1) as f64
    }

    /// True when node `i` pulls per group.
    pub(super) fn is_grouped(&self, i: u32) -> bool {
        let (g0, g1) = self.range[i as usize];
        g1 > g0
    }

    /// Bytes of the per-sweep group sums.
    pub(super) fn bytes(&self, bins: u64) -> u64 {
        self.normal.len() as u64 * (24 + 8 + 4 + 24 * (1 + bins)) + self.elements.len() as u64 * 8
    }

    /// Area-weighted sums of B (`group_b`) and of every antiradiance bin (`group_a`) per group:
    /// elements into their lowest large ancestor's groups, then groups into their parents'.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn accumulate<const C: usize>(
        &self,
        (radiance, radiance_back): (&[[f64; C]], &[[f64; C]]),
        anti: &[[f32; C]],
        live: &LiveBins,
        elem_area: &[f64],
        nb: usize,
        (group_b, group_b_back): (&mut [[f64; C]], &mut [[f64; C]]),
        group_a: &mut [[f64; C]],
    ) {
        // group_a is bin-major: bin b of group g at b * ng + g, so the groups of one node in
        // one bin (what a link's pull reads) are side by side. Its bins are summed in parallel,
        // a block of rows per task (each task reads every element's mask and takes the bins in
        // its block); every sum is formed in the same order as one pass would, so the result
        // does not depend on the thread count.
        let ng = self.normal.len();
        debug_assert_eq!(group_a.len(), ng * nb);
        let mut radiance_sums = || {
            group_b.fill([0.0; C]);
            group_b_back.fill([0.0; C]);
            for (e, &g) in self.elem_group.iter().enumerate() {
                if g == NONE {
                    continue;
                }
                let (g, a) = (g as usize, elem_area[e]);
                for c in 0..C {
                    group_b[g][c] += a * radiance[e][c];
                }
                if let (Some(dst), Some(b)) = (group_b_back.get_mut(g), radiance_back.get(e)) {
                    for c in 0..C {
                        dst[c] += a * b[c];
                    }
                }
            }
            // Children into parents; parents' groups come after their children's (post-order),
            // so one pass in group order sums whole subtrees.
            for &(g, p) in &self.child_parent {
                let child = group_b[g as usize];
                for (d, s) in group_b[p as usize].iter_mut().zip(child) {
                    *d += s;
                }
                if let Some(&child) = group_b_back.get(g as usize) {
                    for (d, s) in group_b_back[p as usize].iter_mut().zip(child) {
                        *d += s;
                    }
                }
            }
        };
        if ng == 0 || nb == 0 {
            radiance_sums();
            return;
        }
        let tasks = (2 * rayon::current_num_threads()).clamp(1, nb);
        let rows_per_task = nb.div_ceil(tasks);
        let anti_sums = || {
            group_a
                .par_chunks_mut(ng * rows_per_task)
                .enumerate()
                .for_each(|(task, rows)| {
                    rows.fill([0.0; C]);
                    let first_bin = task * rows_per_task;
                    let end_bin = first_bin + rows.len() / ng;
                    for (e, &g) in self.elem_group.iter().enumerate() {
                        if g == NONE {
                            continue;
                        }
                        let (g, a) = (g as usize, elem_area[e]);
                        live.for_each_slot_in(e, first_bin..end_bin, |bin, slot| {
                            let dst = &mut rows[(bin - first_bin) * ng + g];
                            for c in 0..C {
                                dst[c] += a * anti[slot][c] as f64;
                            }
                        });
                    }
                    for row in rows.chunks_mut(ng) {
                        for &(g, p) in &self.child_parent {
                            let child = row[g as usize];
                            for (d, s) in row[p as usize].iter_mut().zip(child) {
                                *d += s;
                            }
                        }
                    }
                });
        };
        rayon::join(radiance_sums, anti_sums);
    }
}
