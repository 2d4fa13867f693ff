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
use crate::links::{self, LinkParams, Links};
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
    }

    /// The elements, in the order of [`ElementState`] and of `elem_source` in
    /// [`Prepared::solve_with_source`].
    pub fn elements(&self) -> impl ExactSizeIterator<Item = Element> + '_ {
        self.tree.elements.iter().enumerate().map(|(e, &node)| Element {
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
        let (mut solution, state) = self.solve_with_source(patches, &source, warm, progress);
        // Patches the tree does not hold (inactive) keep their emission.
        for p in 0..patches.len() {
            if !patches.active[p] {
                solution.patch_radiance[p] = patch_emission[p];
            }
        }
        (solution, state)
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

        for iteration in 1..=options.max_iterations {
            // 1. Pull: sender intensity along every cluster link.
            intensity
                .par_iter_mut()
                .zip(links.cluster.par_iter())
                .for_each(|(out, l)| {
                    let w = DVec3::new(l.w[0] as f64, l.w[1] as f64, l.w[2] as f64);
                    let (e0, e1) = tree.nodes[l.sender as usize].elements;
                    let mut acc = [0.0f64; 3];
                    for e in e0 as usize..e1 as usize {
                        let cos = elem_normal[e].dot(w);
                        let a = elem_area[e];
                        if cos > 0.0 {
                            for c in 0..3 {
                                acc[c] += a * cos * radiance[e][c];
                            }
                        }
                        if use_anti && (two_sided || cos < 0.0) {
                            let anti_e = anti[e * nb + l.bin as usize];
                            let k = a * cos.abs();
                            for c in 0..3 {
                                acc[c] -= k * anti_e[c] as f64;
                            }
                        }
                    }
                    *out = acc;
                });

            // 2-3. Gather per element: exact links, then cluster links into it and its ancestors.
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
                            let g = 1.0 / d2;
                            if cos > 0.0 {
                                let k = cos * g * inv_pi;
                                for c in 0..3 {
                                    h[c] += k * i[c];
                                }
                            }
                            if use_anti && (cos > 0.0 || two_sided) {
                                let bin = bins.bin_of(w);
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
            let (num, den) = change_parts
                .iter()
                .fold((0.0, 0.0), |acc, p| (acc.0 + p.0, acc.1 + p.1));
            if iteration == 1 {
                stats.max_row_sum = change_parts.iter().map(|p| p.2).fold(0.0, f64::max);
            }
            let change = if den > 0.0 { num / den } else { 0.0 };
            std::mem::swap(&mut radiance, &mut next_radiance);
            std::mem::swap(&mut anti, &mut next_anti);
            stats.iterations = iteration;
            progress.inc(1);
            progress.message(format!("residual {change:.2e}"));
            if convergence.update(change, options.tol) && iteration >= 3 {
                stats.converged = true;
                break;
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
