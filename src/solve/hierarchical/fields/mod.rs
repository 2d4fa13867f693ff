//! Receiver fields: the cluster links into a node whose receiver is small seen from the
//! sender are gathered once per sweep at the node, as the field they make over it to second
//! order (value, gradient and second derivatives at the node's centroid), and each element
//! below evaluates the fields of its ancestors instead of every link into them.
//!
//! The per-element gather of a link costs its receiver's element count; a field costs one
//! term per link and one evaluation per (element, ancestor field), so a sweep costs what the
//! links cost plus the elements times the fields on their path. A link qualifies when
//!
//! - its receiver has at least [`MIN_FIELD_ELEMENTS`] elements;
//! - every element below it in one slab sees the link's sender on the same side (the
//!   receiver's elements are put in at most [`MAX_SLABS`] slabs: planes, else normals, else
//!   cells of normals, and each slab must be wholly in front or wholly behind): within a side the
//!   irradiance factor `max(0, cos) / (pi (d^2 + spread))` is the linear function
//!   `n_e . G(x_e)` of the normal, with no clamp to break the expansion, and the link's mask
//!   says which slabs see it in front;
//! - the receiver's extent (largest distance of an element's centroid from the node's
//!   centroid) is at most [`SolverOptions::field_ratio`] times the distance from the sender
//!   (with the sender's spread): the expansion's third-order remainder is then about
//!   `4 ratio^3` of the link's value at the edge of the node;
//! - for a flat sender, the receiver's extent is at most [`FIELD_TURN`] times its centroid's
//!   height above the sender's plane (the sender's cosine, which varies over the receiver, is
//!   in the field to second order).
//!
//! Everything else is gathered per element (the near field). On the seed room the fields
//! change the result by 0.020% (per-element gather of every link: `field_ratio` 0).

use super::*;

/// Terms a field link adds per unit of its intensity: irradiance, then antiradiance.
pub(super) const LINK_TERMS: usize = IRR_TERMS + ANTI_TERMS;

/// Nodes with fewer elements gather every link per element.
pub(super) const MIN_FIELD_ELEMENTS: u32 = 2;

/// Largest receiver extent, over its centroid's height above a flat sender's plane, of a link
/// gathered through a field. The sender's cosine varies linearly over the receiver by at most
/// this share of its value at the centroid, and the field holds it to second order
/// ([`crate::hierarchy::links::NodePoint::cosine_ratio`]); at 1 the linear cosine stays
/// non-negative over the receiver (no element centroid lies behind the sender's plane). The
/// rest of such links are gathered per element, with the exact ratio. Measured with the cosine
/// to first order in the fields, the 66k-triangle Cornell box (rms against its path-traced
/// references, the references' noise removed) and the element-link pairs a sweep evaluates per
/// element: 0.25 1.254%, 11.6M; 0.5 1.245%, 5.7M; 1 1.242%, 3.7M; 2 1.243%, 2.9M.
pub(super) const FIELD_TURN: f64 = 1.0;

/// A field link's key: the receiver slabs that see its sender in front (a bit mask) above
/// `MASK_SHIFT`, its bin below; [`NEAR`] for a link gathered per element.
const MASK_SHIFT: u32 = 16;
const NEAR: u32 = u32::MAX;

mod push;
mod slabs;
mod sums;

use slabs::*;
pub(super) use sums::FieldSums;
use sums::{ANTI_TERMS, IRR_TERMS};

/// The receiver fields of a prepared scene: which links are gathered at their receiver node
/// and where their sums go.
///
/// A field's links are sorted by key (slab mask, then bin). A run of one mask is an
/// irradiance group (one `G` and Jacobian, which each element below adds to its front when
/// its slab is in the mask, else to its back face when it has one); a run of one key is an
/// antiradiance slot (one value and gradient, added to the slot's bin by the elements of the
/// mask's slabs and by those that create antiradiance from their back).
#[derive(Clone, Debug, Default)]
pub(super) struct Fields {
    /// Per node, the end of its near links: `links.cluster[cluster_start[i] .. near_end[i]]`
    /// are gathered per element, `near_end[i] .. cluster_start[i + 1]` through node i's field.
    pub(super) near_end: Vec<u32>,
    /// Per field: its node.
    pub(super) node: Vec<u32>,
    /// Per field: the expansion centre (the node's area-weighted centroid).
    pub(super) center: Vec<DVec3>,
    /// Per field: its elements' mean spread ([`crate::hierarchy::links::element_spread`]), for
    /// [`crate::hierarchy::links::receiver_spread`] when its node is flat.
    pub(super) element_spread: Vec<f32>,
    /// Per field: the nearest field of an ancestor, [`NONE`] when none.
    pub(super) parent: Vec<u32>,
    /// Per field: its irradiance groups `group_start[f] .. group_start[f + 1]`.
    pub(super) group_start: Vec<u32>,
    /// Per group: its slab mask.
    pub(super) group_mask: Vec<u16>,
    /// Per group: its slots `group_slots[g] .. group_slots[g + 1]`.
    pub(super) group_slots: Vec<u32>,
    /// Per field: its slots `slot_start[f] .. slot_start[f + 1]`.
    pub(super) slot_start: Vec<u32>,
    /// Per slot: its key (mask and bin).
    pub(super) slot_key: Vec<u32>,
    /// Per slot: the end of its links in `links.cluster` (they start where the previous slot's
    /// end, or at the node's `near_end`).
    pub(super) slot_end: Vec<u32>,
    /// Per slot: the index of its antiradiance sums, [`NONE`] when no element below the
    /// field stores its bin (its antiradiance would be dropped); see [`Fields::keep_live`].
    pub(super) slot_sum: Vec<u32>,
    /// Slots with antiradiance sums.
    pub(super) live_slots: usize,
    /// Per field: its first antiradiance sum (the sums of a field's slots are contiguous).
    pub(super) sum_start: Vec<u32>,
    /// Per element: its own or its nearest ancestor's field, [`NONE`] when none.
    pub(super) of_element: Vec<u32>,
    /// Per element, for each field on its path in order: its slab in that field's node
    /// (`elem_slab[elem_slab_start[e] ..]`).
    pub(super) elem_slab: Vec<u8>,
    pub(super) elem_slab_start: Vec<u32>,
    /// Per field link of the first fields, its terms per unit of its intensity (irradiance,
    /// then antiradiance), as many fields as fit what the pair cache's budget leaves
    /// ([`Fields::cache_terms`]); each sweep computes the other fields' terms again.
    pub(super) terms: Vec<[f32; LINK_TERMS]>,
    /// Per cached field, and one past the last: the index in `terms` of its first link.
    pub(super) term_start: Vec<u32>,
    /// Links gathered through fields.
    pub(super) links: u64,
    /// Near links replaced by links into their receivers' children ([`push`]).
    pub(super) pushed: u64,
    /// (element, field) evaluations per sweep.
    pub(super) evaluations: u64,
}

/// Bytes of cached terms for `links` field links with `starts` entries of
/// [`Fields::term_start`] (one per cached field, and one past the last).
fn terms_bytes(links: u64, starts: u64) -> u64 {
    links * (LINK_TERMS * 4) as u64 + starts * 4
}

impl Fields {
    /// No fields: every link of `links` is gathered per element.
    pub(super) fn none(links: &Links, elements: usize) -> Fields {
        Fields {
            near_end: links.cluster_start[1..].to_vec(),
            of_element: vec![NONE; elements],
            elem_slab_start: vec![0; elements + 1],
            ..Fields::default()
        }
    }

    /// Sorts every node's links into near ones (first, in their order) and field ones (after,
    /// by key), and lays out the fields, for receivers of at most `ratio` times their distance
    /// from the sender (0: no fields). Reorders `links.cluster` within each node.
    pub(super) fn build(prepared: &mut Prepared, ratio: f64, record_culled: bool) -> Fields {
        let n = prepared.element_count();
        if !(ratio > 0.0) || prepared.links.cluster.is_empty() {
            return Fields::none(&prepared.links, n);
        }
        let nodes = prepared.tree.nodes.len();
        let keys = prepared.field_keys(ratio);
        let (keys, pushed) = prepared.push_near_links(keys, ratio, record_culled);
        let links = &mut prepared.links;
        let mut keyed: Vec<(u32, ClusterLink)> =
            keys.into_iter().zip(links.cluster.drain(..)).collect();
        split_by_start(&mut keyed, &links.cluster_start)
            .into_par_iter()
            .for_each(|part| part.sort_by_key(|&(k, l)| (k != NEAR, k, l.sender)));
        let mut fields = Fields {
            near_end: Vec::with_capacity(nodes),
            pushed,
            ..Fields::default()
        };
        let mut field_of = vec![NONE; nodes];
        for (i, field) in field_of.iter_mut().enumerate() {
            let (a, b) = (
                links.cluster_start[i] as usize,
                links.cluster_start[i + 1] as usize,
            );
            let near = keyed[a..b].iter().take_while(|(k, _)| *k == NEAR).count();
            fields.near_end.push((a + near) as u32);
            if a + near < b {
                *field = fields.node.len() as u32;
                let node = &prepared.tree.nodes[i];
                let count = (node.elements.1 - node.elements.0).max(1);
                let spread: f64 = (node.elements.0..node.elements.1)
                    .map(|e| crate::hierarchy::links::element_spread(&prepared.tree, e as usize))
                    .sum();
                fields.element_spread.push((spread / count as f64) as f32);
                fields.add_field(i, node.centroid, &keyed[a + near..b], a + near);
            }
        }
        fields.slot_start.push(fields.slot_key.len() as u32);
        fields.group_start.push(fields.group_mask.len() as u32);
        fields.group_slots.push(fields.slot_key.len() as u32);
        fields.slot_sum = (0..fields.slot_key.len() as u32).collect();
        fields.live_slots = fields.slot_key.len();
        fields.sum_start = fields.slot_start.clone();
        // Into a new array: collected in place, the links would keep the keyed array's 16 bytes
        // each for their 12 (31 MB of the MGF classroom's 7.8M links).
        links.cluster = keyed.iter().map(|&(_, l)| l).collect();
        drop(keyed);
        fields.link_tree(&prepared.tree, &field_of);
        fields.assign_slabs(prepared);
        fields
    }

    /// Appends the field of node `i` (centre `center`), whose links, sorted by key, are
    /// `keyed`, starting at `first` in `links.cluster`: its groups and slots.
    fn add_field(&mut self, i: usize, center: DVec3, keyed: &[(u32, ClusterLink)], first: usize) {
        self.node.push(i as u32);
        self.center.push(center);
        self.slot_start.push(self.slot_key.len() as u32);
        self.group_start.push(self.group_mask.len() as u32);
        for (j, &(k, _)) in keyed.iter().enumerate() {
            let end = (first + j + 1) as u32;
            if j > 0 && self.slot_key.last() == Some(&k) {
                if let Some(last) = self.slot_end.last_mut() {
                    *last = end;
                }
                continue;
            }
            let mask = (k >> MASK_SHIFT) as u16;
            if j == 0 || self.group_mask.last() != Some(&mask) {
                self.group_mask.push(mask);
                self.group_slots.push(self.slot_key.len() as u32);
            }
            self.slot_key.push(k);
            self.slot_end.push(end);
        }
        self.links += keyed.len() as u64;
    }

    /// Each field's nearest field ancestor and each element's nearest field, top-down from
    /// the root (`field_of`: per node, its field or [`NONE`]).
    fn link_tree(&mut self, tree: &ClusterTree, field_of: &[u32]) {
        let mut nearest = vec![NONE; tree.nodes.len()];
        let mut stack = vec![(0u32, NONE)];
        self.parent = vec![NONE; self.node.len()];
        while let Some((i, above)) = stack.pop() {
            let f = field_of[i as usize];
            if f != NONE {
                self.parent[f as usize] = above;
            }
            let here = if f != NONE { f } else { above };
            nearest[i as usize] = here;
            let node = &tree.nodes[i as usize];
            for c in node.first_child..node.first_child + node.child_count as u32 {
                stack.push((c, here));
            }
        }
        self.of_element = tree.elements.iter().map(|&i| nearest[i as usize]).collect();
    }

    /// Every element's slab in each field on its path (the slabs of
    /// [`Prepared::receiver_view`], found again by the element's normal).
    fn assign_slabs(&mut self, prepared: &Prepared) {
        let n = prepared.element_count();
        let cells = Bins::new(SLAB_CELLS);
        let views: Vec<ReceiverView> = self
            .node
            .par_iter()
            .map(|&i| prepared.receiver_view(i as usize, &cells))
            .collect();
        let counts: Vec<u32> = (0..n)
            .into_par_iter()
            .map(|e| self.path(e).count() as u32)
            .collect();
        let start = starts_of(counts.into_iter());
        self.evaluations = start.last().map_or(0, |&total| total as u64);
        let mut slab = vec![0u8; self.evaluations as usize];
        split_by_start(&mut slab, &start)
            .into_par_iter()
            .enumerate()
            .for_each(|(e, out)| {
                let (normal, x) = (prepared.elem_normal[e], prepared.elem_center[e]);
                for (k, f) in out.iter_mut().zip(self.path(e)) {
                    *k = views[f].slab_of(normal, x, &cells);
                }
            });
        self.elem_slab = slab;
        self.elem_slab_start = start;
    }

    /// The cluster links into `node` gathered per element (the rest go through its field).
    pub(super) fn near_links(&self, links: &Links, node: u32) -> std::ops::Range<usize> {
        links.cluster_start[node as usize] as usize..self.near_end[node as usize] as usize
    }

    /// The fields element `e` evaluates, each with the element's slab in it: its own node's
    /// or nearest ancestor's first, then up the tree.
    pub(super) fn path_slabs(&self, e: usize) -> impl Iterator<Item = (usize, u8)> + '_ {
        let slabs = self
            .elem_slab
            .get(self.elem_slab_start[e] as usize..self.elem_slab_start[e + 1] as usize)
            .unwrap_or(&[]);
        self.path(e).zip(slabs.iter().copied())
    }

    /// The fields element `e` evaluates: its own node's or nearest ancestor's, then up.
    fn path(&self, e: usize) -> impl Iterator<Item = usize> + '_ {
        let mut f = self.of_element.get(e).copied().unwrap_or(NONE);
        std::iter::from_fn(move || {
            if f == NONE {
                return None;
            }
            let here = f as usize;
            f = self.parent[here];
            Some(here)
        })
    }

    /// The links of slot `s` of field `f`.
    fn slot_links(&self, f: usize, s: usize) -> std::ops::Range<usize> {
        let start = if s == self.slot_start[f] as usize {
            self.near_end[self.node[f] as usize] as usize
        } else {
            self.slot_end[s - 1] as usize
        };
        start..self.slot_end[s] as usize
    }

    /// A slot's bin and slab mask.
    fn slot_bin(&self, s: usize) -> (usize, u16) {
        let k = self.slot_key[s];
        (
            (k & ((1 << MASK_SHIFT) - 1)) as usize,
            (k >> MASK_SHIFT) as u16,
        )
    }

    /// Bytes held (without the per-sweep sums, [`Fields::sweep_bytes`]).
    pub(super) fn bytes(&self) -> u64 {
        (self.near_end.len() * 4
            + self.node.len() * (4 + 24 + 4 + 4 + 4)
            + self.group_mask.len() * (2 + 4)
            + self.slot_key.len() * (4 + 4 + 4)
            + self.of_element.len() * 8
            + self.elem_slab.len()) as u64
            + self.cached_terms_bytes()
    }

    /// Bytes the cached terms take ([`Fields::cache_terms`]).
    pub(super) fn cached_terms_bytes(&self) -> u64 {
        terms_bytes(self.terms.len() as u64, self.term_start.len() as u64)
    }

    /// Computes and keeps the terms of every field link of the first fields whose terms fit
    /// `budget` bytes (all of them when they fit; `ctx` the sweep context of the prepared scene
    /// whose fields these are): a sweep then sums those fields' links as a stream of
    /// multiply-adds instead of their geometry, and computes the rest as before. Call after
    /// [`Fields::keep_live`] (a slot without antiradiance sums caches none).
    pub(super) fn cache_terms(&mut self, ctx: &SweepContext, links: &Links, budget: u64) {
        let mut start = Vec::with_capacity(self.node.len() + 1);
        let mut total = 0u32;
        for f in 0..self.node.len() {
            let node = self.node[f] as usize;
            let count = links.cluster_start[node + 1] - self.near_end[node];
            // Fields 0..=f cached: their links' terms and f + 2 starts.
            if terms_bytes(u64::from(total + count), f as u64 + 2) > budget {
                break;
            }
            start.push(total);
            total += count;
        }
        if start.is_empty() {
            return;
        }
        start.push(total);
        let mut terms = vec![[0.0f32; LINK_TERMS]; total as usize];
        split_by_start(&mut terms, &start)
            .into_par_iter()
            .enumerate()
            .for_each(|(f, out)| {
                let first = self.near_end[self.node[f] as usize] as usize;
                for s in self.slot_start[f] as usize..self.slot_start[f + 1] as usize {
                    let with_anti = ctx.use_anti && self.slot_sum[s] != NONE;
                    for j in self.slot_links(f, s) {
                        let (t, a) = ctx.link_terms(self, links, (f, s, j), with_anti);
                        let dst = &mut out[j - first];
                        for (d, x) in dst.iter_mut().zip(t.iter().chain(&a)) {
                            *d = *x as f32;
                        }
                    }
                }
            });
        self.terms = terms;
        self.term_start = start;
    }

    /// Bytes of the per-sweep sums in `channels` channels.
    pub(super) fn sweep_bytes(&self, channels: usize) -> u64 {
        ((self.group_mask.len() * IRR_TERMS + self.live_slots * ANTI_TERMS) * channels * 4) as u64
    }

    /// Keeps antiradiance sums only for the slots whose bin some element below their field
    /// stores (`live`); every slot keeps them until this is called.
    pub(super) fn keep_live(&mut self, tree: &ClusterTree, live: &LiveBins) {
        let words = live.words;
        let mut next = 0u32;
        self.sum_start.clear();
        for f in 0..self.node.len() {
            self.sum_start.push(next);
            let node = &tree.nodes[self.node[f] as usize];
            let mut union = vec![0u64; words];
            for e in node.elements.0 as usize..node.elements.1 as usize {
                for (u, m) in union.iter_mut().zip(&live.mask[e * words..(e + 1) * words]) {
                    *u |= m;
                }
            }
            for s in self.slot_start[f] as usize..self.slot_start[f + 1] as usize {
                let (bin, _) = self.slot_bin(s);
                self.slot_sum[s] = if (union[bin >> 6] >> (bin & 63)) & 1 != 0 {
                    next += 1;
                    next - 1
                } else {
                    NONE
                };
            }
        }
        self.sum_start.push(next);
        self.live_slots = next as usize;
    }

    /// Calls `set` with the bin of every field slot on element `e`'s path that gives it
    /// antiradiance: those whose mask holds its slab, and every one when it creates
    /// antiradiance from its back (`back`).
    pub(super) fn written_bins(&self, e: usize, back: bool, mut set: impl FnMut(usize)) {
        for (f, k) in self.path_slabs(e) {
            for s in self.slot_start[f] as usize..self.slot_start[f + 1] as usize {
                let (bin, mask) = self.slot_bin(s);
                if back || mask & (1 << k) != 0 {
                    set(bin);
                }
            }
        }
    }
}
