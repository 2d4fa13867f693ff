//! The hierarchical antiradiance solver: transport over refined links with push/pull.
//!
//! Per sweep (Jacobi, like the dense solver):
//! 1. pull: every cluster link's sender node sums the radiant intensity its elements send along
//!    the link's direction, `I = sum_e a_e (B_e max(0, n_e . w) - A_e[bin(w)] |n_e . w|)` (the
//!    antiradiance term only where it leaves the element: through its back by default);
//! 2. push/gather: every element collects from the links into itself and into each of its
//!    ancestors: irradiance `max(0, -n_e . w) I / (pi d^2)` with its own cosine, and antiradiance
//!    `I / (d^2 Omega_bin)` in the link's bin when the light arrives at its front; plus the exact
//!    couplings of its element links (the same [`crate::transport::couple`] as the dense solver);
//! 3. every element forms `B = E + rho H` and its new antiradiance bins.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::bins::Bins;
use crate::hierarchy::{ClusterTree, NONE};
use crate::links::{self, ClusterLink, LinkParams, Links};
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solution::{Solution, SolveStats};
use crate::solve::{finish, Convergence, SolverOptions};
use crate::transport::gather_entries;

/// Time spent in each stage of a hierarchical solve, seconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HierarchyTimings {
    /// Cluster tree (obvhs BVH2 and our arrays).
    pub tree: f64,
    /// Link refinement including exact couplings.
    pub links: f64,
    /// All iterations.
    pub iterate: f64,
}

/// A scene prepared for hierarchical solving: tree, links and element arrays. Build it once and
/// solve it as many times as needed (different emission: see [`Prepared::solve_with_emission`]).
pub struct Prepared {
    /// The cluster tree (finalized).
    pub tree: ClusterTree,
    /// The refined links.
    pub links: Links,
    /// The direction bins.
    pub bins: Bins,
    /// Per element: area, unit normal, albedo, emission (normalized), patch.
    elem_area: Vec<f64>,
    elem_normal: Vec<DVec3>,
    elem_center: Vec<DVec3>,
    elem_albedo: Vec<[f64; 3]>,
    elem_patch: Vec<u32>,
    /// Normal groups of the large nodes, for the pull.
    groups: SenderGroups,
    /// Solver options the links were refined for.
    pub options: SolverOptions,
    /// Build timings.
    pub timings: HierarchyTimings,
}

/// The solver's state over the elements after a solve: radiance per element and antiradiance per
/// element and bin. Pass it back to [`Prepared::solve_with_source`] to warm-start the next solve
/// of the same [`Prepared`] scene (interactive relighting).
#[derive(Clone, Debug, Default)]
pub struct ElementState {
    /// Outgoing radiance per element, RGB (normalized units).
    radiance: Vec<[f64; 3]>,
    /// Antiradiance per element and bin, RGB.
    anti: Vec<[f32; 3]>,
}

impl ElementState {
    /// Outgoing radiance per element (normalized units, element order of [`Prepared`]).
    pub fn radiance(&self) -> &[[f64; 3]] {
        &self.radiance
    }
}

/// One element (leaf triangle after on-demand subdivision) of a prepared scene, unit frame.
#[derive(Clone, Copy, Debug)]
pub struct Element {
    /// Corners, unit frame.
    pub corners: crate::geometry::Tri,
    /// Unit normal (front side).
    pub normal: DVec3,
    /// Area, unit frame.
    pub area: f64,
    /// The input patch (triangle) it is part of.
    pub patch: u32,
}

/// The link parameters implied by solver options.
pub fn link_params(options: &SolverOptions) -> LinkParams {
    LinkParams {
        epsilon: options.epsilon,
        max_split_depth: options.split_depth,
        ..LinkParams::default()
    }
}

impl Prepared {
    /// Builds the tree and refines the links for `patches`.
    pub fn new(patches: &Patches, options: &SolverOptions, record_culled: bool) -> Prepared {
        let bins = Bins::new(options.bins);
        let t0 = Instant::now();
        let mut tree = ClusterTree::build(patches);
        let t1 = Instant::now();
        let links = links::refine(
            &mut tree,
            &bins,
            &link_params(options),
            &options.coupling(),
            record_culled,
        );
        let t2 = Instant::now();
        debug_assert!(tree.validate().is_ok(), "{:?}", tree.validate());
        let mut prepared = Prepared {
            elem_area: Vec::with_capacity(tree.elements.len()),
            elem_normal: Vec::with_capacity(tree.elements.len()),
            elem_center: Vec::with_capacity(tree.elements.len()),
            elem_albedo: Vec::with_capacity(tree.elements.len()),
            elem_patch: Vec::with_capacity(tree.elements.len()),
            groups: SenderGroups::default(),
            tree,
            links,
            bins,
            options: options.clone(),
            timings: HierarchyTimings {
                tree: (t1 - t0).as_secs_f64(),
                links: (t2 - t1).as_secs_f64(),
                iterate: 0.0,
            },
        };
        for &node in &prepared.tree.elements {
            let n = &prepared.tree.nodes[node as usize];
            prepared.elem_area.push(n.area);
            prepared
                .elem_normal
                .push(n.plane.map(|p| p.0).unwrap_or(DVec3::Z));
            prepared.elem_center.push(n.centroid);
            prepared.elem_albedo.push(patches.albedo[n.patch as usize]);
            prepared.elem_patch.push(n.patch);
        }
        prepared.groups =
            SenderGroups::build(&prepared.tree, &prepared.elem_area, &prepared.elem_normal);
        prepared
    }

    /// Number of elements (leaf triangles after on-demand subdivision).
    pub fn element_count(&self) -> usize {
        self.elem_area.len()
    }

    /// Bytes held by tree, links and per-sweep arrays.
    pub fn bytes(&self) -> u64 {
        let n = self.element_count() as u64;
        let nb = self.bins.len() as u64;
        self.links.bytes()
            + (self.tree.nodes.len() * std::mem::size_of::<crate::hierarchy::Node>()) as u64
            + n * (8 + 24 + 24 + 4)
            + 2 * n * (24 + nb * 12)
            + self.links.cluster.len() as u64 * 24
            + self.groups.bytes(nb)
    }

    /// The elements, in the order of [`ElementState`] and of `elem_source` in
    /// [`Prepared::solve_with_source`].
    pub fn elements(&self) -> impl ExactSizeIterator<Item = Element> + '_ {
        self.tree
            .elements
            .iter()
            .enumerate()
            .map(|(e, &node)| Element {
                corners: self.tree.nodes[node as usize].corners,
                normal: self.elem_normal[e],
                area: self.elem_area[e],
                patch: self.elem_patch[e],
            })
    }

    /// Solves with the patches' own emission.
    pub fn solve(&mut self, patches: &Patches, progress: &Progress) -> (Solution, ElementState) {
        self.solve_with_emission(patches, &patches.emission, None, progress)
    }

    /// Solves for a given per-patch emission (normalized units, as in `Patches::emission`),
    /// optionally warm-starting from a previous [`ElementState`] of this scene.
    /// Returns the solution and the final element state for the next warm start.
    ///
    /// # Panics
    /// When `patch_emission.len() != patches.len()`.
    pub fn solve_with_emission(
        &mut self,
        patches: &Patches,
        patch_emission: &[[f64; 3]],
        warm: Option<&ElementState>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        assert_eq!(patch_emission.len(), patches.len());
        let source: Vec<[f64; 3]> = self
            .elem_patch
            .iter()
            .map(|&p| patch_emission[p as usize])
            .collect();
        // Patches the tree does not hold (inactive: zero area, duplicates) are settled by
        // `Solution::from_normalized` from their own emission or their twin.
        self.solve_with_source(patches, &source, warm, progress)
    }

    /// Solves `B_e = source_e + rho_e H_e(B)` for a per-element source radiance (normalized
    /// units, element order of [`Prepared::elements`]). With the emission as the source this is
    /// the usual solve; with the reflected direct light as the source it gives the indirect
    /// part on top of exact direct lighting. Warm-starts from `warm` when it belongs to this
    /// scene (same element and bin count), else starts from the source.
    ///
    /// # Panics
    /// When `elem_source.len() != self.element_count()`.
    pub fn solve_with_source(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        let t0 = Instant::now();
        let options = &self.options;
        let nb = self.bins.len();
        let n = self.element_count();
        assert_eq!(elem_source.len(), n);
        let two_sided = options.two_sided;
        let use_anti = options.antiradiance;
        let emission = elem_source;
        let (mut radiance, mut anti) = match warm {
            Some(w) if w.radiance.len() == n && w.anti.len() == n * nb => {
                (w.radiance.clone(), w.anti.clone())
            }
            _ => (emission.to_vec(), vec![[0.0f32; 3]; n * nb]),
        };
        let mut next_radiance = radiance.clone();
        let mut next_anti = anti.clone();
        let mut intensity = vec![[0.0f64; 3]; self.links.cluster.len()];
        let mut stats = SolveStats {
            links: self.links.len() as u64,
            solver_bytes: self.bytes(),
            ..SolveStats::default()
        };
        let mut convergence = Convergence::default();
        let tree = &self.tree;
        let links = &self.links;
        let bins = &self.bins;
        let (elem_area, elem_normal, elem_albedo, elem_center) = (
            &self.elem_area,
            &self.elem_normal,
            &self.elem_albedo,
            &self.elem_center,
        );

        let inv_pi = 1.0 / std::f64::consts::PI;
        let groups = &self.groups;
        let mut group_b = vec![[0.0f64; 3]; groups.normal.len()];
        let mut group_a = vec![[0.0f64; 3]; groups.normal.len() * nb];
        let ctx = SweepContext {
            tree,
            bins,
            elem_area,
            elem_normal,
            use_anti,
            two_sided,
        };

        for iteration in 1..=options.max_iterations {
            // 1. Sender summaries: per normal group of every large node, the area-weighted sums of
            //    B and of each antiradiance bin (bottom-up, children before parents).
            groups.accumulate(&radiance, &anti, elem_area, nb, &mut group_b, &mut group_a);

            // 2. Pull: the radiant intensity every cluster link's sender sends along the link.
            intensity
                .par_iter_mut()
                .zip(links.cluster.par_iter())
                .for_each(|(out, l)| {
                    *out = ctx.pull(l, groups, &group_b, &group_a, &radiance, &anti);
                });

            // 3. Gather per element: exact links, then the cluster links into it and its ancestors,
            //    each with the element's own direction and distance from the link's sender (the
            //    antiradiance goes to the link's bin, the one its sender reads when it passes it on).
            let change_parts: Vec<(f64, f64, f64)> = next_radiance
                .par_iter_mut()
                .zip(next_anti.par_chunks_mut(nb))
                .enumerate()
                .map(|(e, (b_out, a_out))| {
                    let mut h = [0.0f64; 3];
                    let mut a_acc = vec![[0.0f64; 3]; nb];
                    let mut row = 0.0;
                    for l in links.exact_start[e]..links.exact_start[e + 1] {
                        let s = links.exact_sender[l as usize] as usize;
                        let entries = &links.exact_entries[links.exact_entry_start[l as usize]
                            as usize
                            ..links.exact_entry_start[l as usize + 1] as usize];
                        row += gather_entries(
                            entries,
                            radiance[s],
                            &anti[s * nb..(s + 1) * nb],
                            use_anti,
                            two_sided,
                            &mut h,
                            &mut a_acc,
                        );
                    }
                    let n_e = elem_normal[e];
                    let x_e = elem_center[e];
                    let mut node = tree.elements[e];
                    while node != NONE {
                        let range = links.cluster_start[node as usize] as usize
                            ..links.cluster_start[node as usize + 1] as usize;
                        for (l, i) in links.cluster[range.clone()].iter().zip(&intensity[range]) {
                            // This element's own direction and distance from the sender.
                            let v = x_e
                                - DVec3::new(
                                    l.origin[0] as f64,
                                    l.origin[1] as f64,
                                    l.origin[2] as f64,
                                );
                            let d2 = v.length_squared();
                            if !(d2 > 0.0) {
                                continue;
                            }
                            let w = v / d2.sqrt();
                            let cos = -n_e.dot(w);
                            let g = 1.0 / (d2 + l.spread as f64);
                            if cos > 0.0 {
                                let k = cos * g * inv_pi;
                                for c in 0..3 {
                                    h[c] += k * i[c];
                                }
                            }
                            if use_anti && (cos > 0.0 || two_sided) {
                                let bin = l.bin as usize;
                                let k = g / bins.solid_angle[bin];
                                for c in 0..3 {
                                    a_acc[bin][c] += k * i[c];
                                }
                            }
                        }
                        node = tree.nodes[node as usize].parent;
                    }
                    for c in 0..3 {
                        b_out[c] = emission[e][c] + elem_albedo[e][c] * h[c];
                    }
                    for (dst, src) in a_out.iter_mut().zip(&a_acc) {
                        *dst = src.map(|x| x as f32);
                    }
                    let a = elem_area[e];
                    let num: f64 = (0..3).map(|c| a * (b_out[c] - radiance[e][c]).abs()).sum();
                    let den: f64 = (0..3).map(|c| a * b_out[c].abs()).sum();
                    (num, den, row)
                })
                .collect();

            let sums = change_parts.iter().fold(SweepSums::default(), |acc, p| {
                acc.add(SweepSums {
                    num: p.0,
                    den: p.1,
                    max_row: p.2,
                })
            });
            if iteration == 1 {
                stats.max_row_sum = sums.max_row;
            }
            let change = if sums.den > 0.0 {
                sums.num / sums.den
            } else {
                0.0
            };
            std::mem::swap(&mut radiance, &mut next_radiance);
            std::mem::swap(&mut anti, &mut next_anti);
            stats.iterations = iteration;
            progress.inc(1);
            progress.message(format!("residual {change:.2e}"));
            if convergence.sweep_done(iteration, change, options.tol) {
                stats.converged = true;
                break;
            }
            // Once the sweeps contract at a steady ratio, jump over the geometric tail.
            if let Some(k) = convergence.extrapolation_factor() {
                extrapolate(&mut radiance, &next_radiance, k);
                extrapolate(&mut anti, &next_anti, k);
                stats.extrapolations += 1;
            }
        }
        stats.residual = convergence.residual;

        // Elements -> patches (area-weighted mean); patches without elements (inactive) get 0
        // here and their emission from `solve_with_emission`.
        let mut patch_sum = vec![[0.0f64; 3]; patches.len()];
        let mut patch_area = vec![0.0f64; patches.len()];
        for e in 0..n {
            let p = self.elem_patch[e] as usize;
            patch_area[p] += elem_area[e];
            for c in 0..3 {
                patch_sum[p][c] += elem_area[e] * radiance[e][c];
            }
        }
        let patch_radiance: Vec<[f64; 3]> = (0..patches.len())
            .map(|p| {
                if patch_area[p] > 0.0 {
                    patch_sum[p].map(|x| x / patch_area[p])
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        self.timings.iterate = t0.elapsed().as_secs_f64();
        let solution = finish(patches, patch_radiance, stats, options.clamp_negative);
        (solution, ElementState { radiance, anti })
    }
}

/// Solves the scene with the hierarchical solver. Preconditions: `options.validate()` passed.
pub fn solve_hierarchical(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Solution {
    let mut prepared = Prepared::new(patches, options, false);
    prepared.solve(patches, progress).0
}

/// Nodes with at most this many elements pull per element; larger ones pull per normal group.
const PULL_PER_ELEMENT_MAX: u32 = 8;

/// Most distinct exact normals a node's groups keep; beyond it normals are grouped by cell of a
/// coarse direction grid (`GROUP_CELLS` x `GROUP_CELLS` octahedral cells, about 45 degrees wide).
const MAX_EXACT_GROUPS: usize = 8;
const GROUP_CELLS: usize = 4;

/// Two unit normals closer than this (1 - cos) are the same group.
const SAME_NORMAL: f64 = 1e-9;

/// Normal groups of the large nodes (more than [`PULL_PER_ELEMENT_MAX`] elements).
///
/// A cluster link's sender sends `sum_e a_e (B_e max(0, n_e . w) - A_e[bin] max(0, -n_e . w))`;
/// for elements sharing a normal that is `max(0, n . w) sum a_e B_e - ...`, so a node needs only
/// per-group sums. Flat (architectural) scenes have few exact normals per node and the pull is
/// exact; curved ones are grouped by normal cell with the group's area-weighted mean normal.
#[derive(Clone, Debug, Default)]
struct SenderGroups {
    /// Per node, its groups `range.0..range.1` (empty for small nodes).
    range: Vec<(u32, u32)>,
    /// Per group, the area-weighted mean normal (unit for exact groups, shorter for cells).
    normal: Vec<DVec3>,
    /// Per group, its area.
    area: Vec<f64>,
    /// Per group, the group of the parent node it adds into ([`NONE`] at the root).
    parent_group: Vec<u32>,
    /// Per element, the group of its lowest large ancestor it adds into ([`NONE`] if none).
    elem_group: Vec<u32>,
    /// Large nodes, children before parents.
    order: Vec<u32>,
}

/// What feeds a group: a child's group or an element of a small child.
enum GroupInput {
    Group(u32),
    Element(u32),
}

impl SenderGroups {
    /// Builds the groups of every large node of a finalized tree.
    fn build(tree: &ClusterTree, elem_area: &[f64], elem_normal: &[DVec3]) -> SenderGroups {
        let mut groups = SenderGroups {
            range: vec![(0, 0); tree.nodes.len()],
            elem_group: vec![NONE; elem_area.len()],
            ..SenderGroups::default()
        };
        if tree.nodes.is_empty() {
            return groups;
        }
        let maxe: u32 = std::env::var("AR_PULLMAX")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(PULL_PER_ELEMENT_MAX);
        let large = |i: u32| {
            let (e0, e1) = tree.nodes[i as usize].elements;
            e1 - e0 > maxe
        };
        // Post-order over the large nodes.
        let mut stack = vec![(0u32, false)];
        while let Some((i, done)) = stack.pop() {
            if !large(i) {
                continue;
            }
            if done {
                groups.order.push(i);
            } else {
                stack.push((i, true));
                let node = &tree.nodes[i as usize];
                for c in node.first_child..node.first_child + node.child_count as u32 {
                    stack.push((c, false));
                }
            }
        }
        let cells = Bins::new(GROUP_CELLS);
        let order = std::mem::take(&mut groups.order);
        for &i in &order {
            // Inputs: the groups of large children, the elements of small ones.
            let node = &tree.nodes[i as usize];
            let mut inputs: Vec<(GroupInput, DVec3, f64)> = Vec::new();
            for c in node.first_child..node.first_child + node.child_count as u32 {
                if large(c) {
                    let (g0, g1) = groups.range[c as usize];
                    for g in g0..g1 {
                        let (n, a) = (groups.normal[g as usize], groups.area[g as usize]);
                        inputs.push((GroupInput::Group(g), n, a));
                    }
                } else {
                    let (e0, e1) = tree.nodes[c as usize].elements;
                    for e in e0..e1 {
                        let (n, a) = (elem_normal[e as usize], elem_area[e as usize]);
                        inputs.push((GroupInput::Element(e), n, a));
                    }
                }
            }
            // Exact groups when every input has a unit normal and there are few distinct ones;
            // else cells of a coarse direction grid.
            let mut distinct: Vec<DVec3> = Vec::new();
            let mut key_of: Vec<usize> = Vec::with_capacity(inputs.len());
            let mut exact = true;
            for (_, n, _) in &inputs {
                if (n.length_squared() - 1.0).abs() > 1e-9 {
                    exact = false;
                    break;
                }
                match distinct.iter().position(|d| 1.0 - d.dot(*n) <= SAME_NORMAL) {
                    Some(k) => key_of.push(k),
                    None if distinct.len() < MAX_EXACT_GROUPS => {
                        key_of.push(distinct.len());
                        distinct.push(*n);
                    }
                    None => {
                        exact = false;
                        break;
                    }
                }
            }
            let count = if exact {
                distinct.len()
            } else {
                key_of.clear();
                let mut cell_keys: Vec<usize> = Vec::new();
                for (_, n, _) in &inputs {
                    let cell = cells.bin_of(*n);
                    let k = cell_keys
                        .iter()
                        .position(|&c| c == cell)
                        .unwrap_or_else(|| {
                            cell_keys.push(cell);
                            cell_keys.len() - 1
                        });
                    key_of.push(k);
                }
                cell_keys.len()
            };
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
        groups.order = order;
        groups
    }

    /// True when node `i` pulls per group.
    fn is_grouped(&self, i: u32) -> bool {
        let (g0, g1) = self.range[i as usize];
        g1 > g0
    }

    /// Bytes of the per-sweep group sums.
    fn bytes(&self, bins: u64) -> u64 {
        self.normal.len() as u64 * (24 + 8 + 4 + 24 * (1 + bins))
    }

    /// Area-weighted sums of B (`group_b`) and of every antiradiance bin (`group_a`) per group:
    /// elements into their lowest large ancestor's groups, then groups into their parents'.
    fn accumulate(
        &self,
        radiance: &[[f64; 3]],
        anti: &[[f32; 3]],
        elem_area: &[f64],
        nb: usize,
        group_b: &mut [[f64; 3]],
        group_a: &mut [[f64; 3]],
    ) {
        group_b.fill([0.0; 3]);
        group_a.fill([0.0; 3]);
        for (e, &g) in self.elem_group.iter().enumerate() {
            if g == NONE {
                continue;
            }
            let (g, a) = (g as usize, elem_area[e]);
            for c in 0..3 {
                group_b[g][c] += a * radiance[e][c];
            }
            let dst = &mut group_a[g * nb..(g + 1) * nb];
            for (d, s) in dst.iter_mut().zip(&anti[e * nb..(e + 1) * nb]) {
                for c in 0..3 {
                    d[c] += a * s[c] as f64;
                }
            }
        }
        for &i in &self.order {
            let (g0, g1) = self.range[i as usize];
            for g in g0 as usize..g1 as usize {
                let p = self.parent_group[g];
                if p == NONE {
                    continue;
                }
                let p = p as usize;
                for c in 0..3 {
                    group_b[p][c] += group_b[g][c];
                }
                // Parents' groups are allocated after their children's (post-order).
                debug_assert!(p > g);
                let (lo, hi) = group_a.split_at_mut(p * nb);
                let (src, dst) = (&lo[g * nb..(g + 1) * nb], &mut hi[..nb]);
                for (d, s) in dst.iter_mut().zip(src) {
                    for c in 0..3 {
                        d[c] += s[c];
                    }
                }
            }
        }
    }
}

/// Sums over a sweep's elements: relative change numerator and denominator, largest row sum.
#[derive(Clone, Copy, Debug, Default)]
struct SweepSums {
    num: f64,
    den: f64,
    max_row: f64,
}

impl SweepSums {
    fn add(self, o: SweepSums) -> SweepSums {
        SweepSums {
            num: self.num + o.num,
            den: self.den + o.den,
            max_row: self.max_row.max(o.max_row),
        }
    }
}

/// Everything a sweep reads that does not change between sweeps.
struct SweepContext<'a> {
    tree: &'a ClusterTree,
    bins: &'a Bins,
    elem_area: &'a [f64],
    elem_normal: &'a [DVec3],
    use_anti: bool,
    two_sided: bool,
}

impl SweepContext<'_> {
    /// The radiant intensity a cluster link's sender sends along the link: B through the front of
    /// every element, minus antiradiance through the back (both sides when two-sided).
    fn pull(
        &self,
        l: &ClusterLink,
        groups: &SenderGroups,
        group_b: &[[f64; 3]],
        group_a: &[[f64; 3]],
        radiance: &[[f64; 3]],
        anti: &[[f32; 3]],
    ) -> [f64; 3] {
        let nb = self.bins.len();
        let w = DVec3::new(l.w[0] as f64, l.w[1] as f64, l.w[2] as f64);
        let bin = l.bin as usize;
        let mut acc = [0.0f64; 3];
        let mut add = |cos: f64, b: [f64; 3], a: [f64; 3]| {
            if cos > 0.0 {
                for c in 0..3 {
                    acc[c] += cos * b[c];
                }
            }
            if self.use_anti && (self.two_sided || cos < 0.0) {
                let k = cos.abs();
                for c in 0..3 {
                    acc[c] -= k * a[c];
                }
            }
        };
        if groups.is_grouped(l.sender) {
            let (g0, g1) = groups.range[l.sender as usize];
            for g in g0 as usize..g1 as usize {
                add(groups.normal[g].dot(w), group_b[g], group_a[g * nb + bin]);
            }
        } else {
            let (e0, e1) = self.tree.nodes[l.sender as usize].elements;
            for e in e0 as usize..e1 as usize {
                let a = self.elem_area[e];
                let a_e = anti[e * nb + bin];
                add(
                    self.elem_normal[e].dot(w),
                    radiance[e].map(|x| a * x),
                    [a * a_e[0] as f64, a * a_e[1] as f64, a * a_e[2] as f64],
                );
            }
        }
        acc
    }
}

/// `x += k (x - x_previous)`, element-wise.
fn extrapolate<const C: usize, T>(x: &mut [[T; C]], x_previous: &[[T; C]], k: f64)
where
    T: Copy + Into<f64> + FromF64 + Send + Sync,
{
    x.par_iter_mut()
        .zip(x_previous.par_iter())
        .for_each(|(a, b)| {
            for c in 0..C {
                let (v, p): (f64, f64) = (a[c].into(), b[c].into());
                a[c] = T::from_f64(v + k * (v - p));
            }
        });
}

/// Conversion back from f64 for [`extrapolate`].
trait FromF64 {
    fn from_f64(x: f64) -> Self;
}

impl FromF64 for f64 {
    fn from_f64(x: f64) -> Self {
        x
    }
}

impl FromF64 for f32 {
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}
