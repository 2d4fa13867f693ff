//! The slabs of a receiver node: its elements by plane, normal or direction cell, and which
//! of them see a sender in front, for the field test.

use super::*;
use crate::geometry::tolerances::{FIELD_NORMAL_MERGE, NORMAL_ROUNDING};

/// Most distinct normals a receiver keeps as slabs of one normal each (the bits of a slab
/// mask); beyond it its slabs are the cells of a coarse direction grid (`SLAB_CELLS` x
/// `SLAB_CELLS` octahedral cells, 16 of them, about 45 degrees wide).
const MAX_SLABS: usize = 16;
pub(super) const SLAB_CELLS: usize = 4;

/// What decides the fields of one receiver node: its extent and the planes of its elements'
/// centroids.
pub(super) struct ReceiverView {
    /// Largest distance of an element's centroid below the node from the node's centroid.
    extent: f64,
    /// The elements in at most [`MAX_SLABS`] slabs: planes (normals within
    /// [`FIELD_NORMAL_MERGE`], offsets within the plane tolerance of the slab's range; each
    /// element in the first slab it fits), or when there are more, the cells of a direction
    /// grid by normal alone (`grid`). Each slab: its axis, the largest distance of a normal in
    /// it from the axis, and the range of `axis . centroid` over its elements (empty:
    /// `lo > hi`). A plane is never on both sides of a sender; a slab of parallel planes is
    /// when the sender lies between them.
    slabs: smallvec::SmallVec<[Slab; MAX_SLABS]>,
    mode: SlabMode,
}

/// How a [`ReceiverView`] puts its elements in slabs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SlabMode {
    Planes,
    Normals,
    Grid,
}

/// One slab of a [`ReceiverView`].
#[derive(Clone, Copy, Debug)]
struct Slab {
    axis: DVec3,
    deviation: f64,
    lo: f64,
    hi: f64,
}

impl ReceiverView {
    /// The slab of an element with normal `n` and centroid `x`: its direction cell, or the
    /// first plane slab of its normal whose range holds it (the one the element was put in, or
    /// an earlier one that grew over it: either bounds the element).
    pub(super) fn slab_of(&self, n: DVec3, x: DVec3, cells: &Bins) -> u8 {
        if self.mode == SlabMode::Grid {
            return cells.bin_of(n) as u8;
        }
        self.slabs
            .iter()
            .position(|s| {
                let h = s.axis.dot(x);
                1.0 - s.axis.dot(n) <= FIELD_NORMAL_MERGE
                    && (self.mode == SlabMode::Normals || (s.lo <= h && h <= s.hi))
            })
            .unwrap_or(0) as u8
    }
}

impl Prepared {
    /// The key of every cluster link, in link order: its field key when it can be gathered
    /// through its receiver's field, else [`NEAR`].
    pub(super) fn field_keys(&self, ratio: f64) -> Vec<u32> {
        let (tree, links) = (&self.tree, &self.links);
        let mut keys = vec![NEAR; links.cluster.len()];
        let cells = Bins::new(SLAB_CELLS);
        split_by_start(&mut keys, &links.cluster_start)
            .into_par_iter()
            .enumerate()
            .for_each(|(i, out)| {
                let node = &tree.nodes[i];
                if out.is_empty() || node.elements.1 - node.elements.0 < MIN_FIELD_ELEMENTS {
                    return;
                }
                let view = self.receiver_view(i, &cells);
                let start = links.cluster_start[i] as usize;
                for (k, l) in out.iter_mut().zip(&links.cluster[start..]) {
                    *k = self.field_key(l, &view, ratio);
                }
            });
        keys
    }

    /// The extent and slabs of node `i`'s elements (`cells`: the direction grid): planes when
    /// there are at most [`MAX_SLABS`], else normals, else direction cells.
    pub(super) fn receiver_view(&self, i: usize, cells: &Bins) -> ReceiverView {
        let node = &self.tree.nodes[i];
        let elements = node.elements.0 as usize..node.elements.1 as usize;
        let extent = elements
            .clone()
            .map(|e| (self.elem_center[e] - node.centroid).length())
            .fold(0.0, f64::max);
        let tol = crate::geometry::plane_tol(node.radius);
        for mode in [SlabMode::Planes, SlabMode::Normals] {
            if let Some(slabs) = self.exact_slabs(elements.clone(), mode, tol) {
                return ReceiverView {
                    extent,
                    slabs,
                    mode,
                };
            }
        }
        // One slab per cell: its mean normal as the axis.
        let empty = Slab {
            axis: DVec3::ZERO,
            deviation: 0.0,
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
        };
        let mut slabs = [empty; MAX_SLABS];
        for e in elements.clone() {
            slabs[cells.bin_of(self.elem_normal[e])].axis += self.elem_normal[e];
        }
        for s in &mut slabs {
            s.axis = s.axis.normalize_or_zero();
        }
        for e in elements {
            let (n, x) = (self.elem_normal[e], self.elem_center[e]);
            let s = &mut slabs[cells.bin_of(n)];
            let h = s.axis.dot(x);
            s.deviation = s.deviation.max((n - s.axis).length());
            s.lo = s.lo.min(h);
            s.hi = s.hi.max(h);
        }
        ReceiverView {
            extent,
            slabs: slabs.into_iter().collect(),
            mode: SlabMode::Grid,
        }
    }

    /// The slabs of `elements` by plane (normal and offset) or by normal alone, or `None`
    /// when there are more than [`MAX_SLABS`].
    fn exact_slabs(
        &self,
        elements: std::ops::Range<usize>,
        mode: SlabMode,
        tol: f64,
    ) -> Option<smallvec::SmallVec<[Slab; MAX_SLABS]>> {
        let mut slabs: smallvec::SmallVec<[Slab; MAX_SLABS]> = smallvec::SmallVec::new();
        for e in elements {
            let (n, x) = (self.elem_normal[e], self.elem_center[e]);
            let fits = |s: &Slab| {
                let h = s.axis.dot(x);
                1.0 - s.axis.dot(n) <= FIELD_NORMAL_MERGE
                    && (mode == SlabMode::Normals || (s.lo - tol <= h && h <= s.hi + tol))
            };
            match slabs.iter().position(fits) {
                Some(k) => {
                    let slab = &mut slabs[k];
                    let h = slab.axis.dot(x);
                    slab.lo = slab.lo.min(h);
                    slab.hi = slab.hi.max(h);
                    // The normals' own distance from the axis (at most sqrt(2 x merge)),
                    // with a little for its rounding.
                    slab.deviation = slab
                        .deviation
                        .max((n - slab.axis).length() + NORMAL_ROUNDING);
                }
                None if slabs.len() < MAX_SLABS => {
                    let h = n.dot(x);
                    slabs.push(Slab {
                        axis: n,
                        deviation: NORMAL_ROUNDING,
                        lo: h,
                        hi: h,
                    });
                }
                None => return None,
            }
        }
        Some(slabs)
    }

    /// The key of cluster link `l` when it can be gathered through its receiver's field
    /// (`view`: extent at most `ratio` times its distance from the sender, the sender on one
    /// side of every element of each slab), or [`NEAR`].
    pub(super) fn field_key(&self, l: &ClusterLink, view: &ReceiverView, ratio: f64) -> u32 {
        let rn = &self.tree.nodes[l.receiver as usize];
        if view.extent <= 0.0 {
            return NEAR;
        }
        let sender = &self.links.point[l.sender as usize];
        let p = sender.centroid();
        let d2 = (rn.centroid - p).length_squared() + sender.spread as f64;
        if !(view.extent * view.extent <= ratio * ratio * d2) {
            return NEAR;
        }
        // A flat sender's cosine varies over the receiver by up to its extent over its height
        // above the sender's plane; the field holds it to second order (`FIELD_TURN`).
        if let Some(n_s) = sender.flat_normal() {
            if !(view.extent <= FIELD_TURN * n_s.dot(rn.centroid - p).abs()) {
                return NEAR;
            }
        }
        match self.front_slabs(l.receiver, p, view) {
            Some(mask) => u32::from(mask) << MASK_SHIFT | u32::from(l.bin),
            None => NEAR,
        }
    }

    /// Which slabs of node `r` (`view`) see point `p` in front of every element (at its
    /// centroid, as the gather evaluates it), as a mask, when every other slab sees it behind
    /// every element; `None` when a slab is mixed or too close to a plane to tell: by each
    /// slab's range of heights, within a margin for the spread of its normals.
    fn front_slabs(&self, r: u32, p: DVec3, view: &ReceiverView) -> Option<u16> {
        let rn = &self.tree.nodes[r as usize];
        let d = (rn.centroid - p).length();
        let tol = crate::geometry::plane_tol(d);
        // In front of the whole range of heights, behind it, or neither.
        let side = |lo: f64, hi: f64, margin: f64| -> Option<bool> {
            if lo > margin {
                Some(true)
            } else if hi < -margin {
                Some(false)
            } else {
                None
            }
        };
        let mut mask = 0u16;
        for (k, slab) in view.slabs.iter().enumerate() {
            if slab.lo > slab.hi {
                continue;
            }
            // |n_e - axis| |p - x_e| bounds how far each element's height differs from the
            // axis's.
            let margin = tol + slab.deviation * (d + view.extent);
            let h = slab.axis.dot(p);
            // A sender in the plane of a plane slab (within the margin of its whole range)
            // lights its elements at grazing incidence: nothing, as behind them (the
            // per-element gather's cosine is then 0 up to rounding). Not for slabs of a normal
            // or a cell: their margin also holds senders clearly in front of some elements.
            if view.mode == SlabMode::Planes
                && (h - slab.lo).abs() <= margin
                && (h - slab.hi).abs() <= margin
            {
                continue;
            }
            if side(h - slab.hi, h - slab.lo, margin)? {
                mask |= 1 << k;
            }
        }
        Some(mask)
    }
}
