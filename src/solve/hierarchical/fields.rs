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
//!   `4 ratio^3` of the link's value at the edge of the node.
//!
//! Everything else is gathered per element (the near field). On the seed room the fields
//! change the result by 0.009% (per-element gather of every link: `field_ratio` 0).

use super::*;
use crate::geometry::tolerances::FIELD_NORMAL_MERGE;

/// Nodes with fewer elements gather every link per element.
pub(super) const MIN_FIELD_ELEMENTS: u32 = 2;

/// A field link's key: the receiver slabs that see its sender in front (a bit mask) above
/// `MASK_SHIFT`, its bin below; [`NEAR`] for a link gathered per element.
const MASK_SHIFT: u32 = 16;
const NEAR: u32 = u32::MAX;

/// Most distinct normals a receiver keeps as slabs of one normal each (the bits of a slab
/// mask); beyond it its slabs are the cells of a coarse direction grid (`SLAB_CELLS` x
/// `SLAB_CELLS` octahedral cells, 16 of them, about 45 degrees wide).
const MAX_SLABS: usize = 16;
const SLAB_CELLS: usize = 4;

/// Irradiance field terms per channel: `G` at the centre (3), its symmetric Jacobian (6), and
/// its second derivatives as the vector `A` (3) and the symmetric tensor `T` (10) of
/// [`SweepContext::sum_fields`].
pub(super) const IRR_TERMS: usize = 22;

/// Antiradiance field terms per channel: the value at the centre, its gradient (3) and its
/// symmetric Hessian (6).
pub(super) const ANTI_TERMS: usize = 10;

/// The unique components of a symmetric 3-tensor, in the order of [`IRR_TERMS`]' last ten:
/// `xxx, xxy, xxz, xyy, xyz, xzz, yyy, yyz, yzz, zzz`.
const SYM3: [[usize; 3]; 10] = [
    [0, 0, 0],
    [0, 0, 1],
    [0, 0, 2],
    [0, 1, 1],
    [0, 1, 2],
    [0, 2, 2],
    [1, 1, 1],
    [1, 1, 2],
    [1, 2, 2],
    [2, 2, 2],
];

/// The index in [`SYM3`] of component `(i, j, k)` (any order), at `9 i + 3 j + k`.
const SYM3_INDEX: [usize; 27] = [
    0, 1, 2, 1, 3, 4, 2, 4, 5, 1, 3, 4, 3, 6, 7, 4, 7, 8, 2, 4, 5, 4, 7, 8, 5, 8, 9,
];

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
    /// Per element: its own or its nearest ancestor's field, [`NONE`] when none.
    pub(super) of_element: Vec<u32>,
    /// Per element, for each field on its path in order: its slab in that field's node
    /// (`elem_slab[elem_slab_start[e] ..]`).
    pub(super) elem_slab: Vec<u8>,
    pub(super) elem_slab_start: Vec<u32>,
    /// Links gathered through fields.
    pub(super) links: u64,
    /// (element, field) evaluations per sweep.
    pub(super) evaluations: u64,
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
    pub(super) fn build(prepared: &mut Prepared, ratio: f64) -> Fields {
        let n = prepared.element_count();
        if !(ratio > 0.0) || prepared.links.cluster.is_empty() {
            return Fields::none(&prepared.links, n);
        }
        let nodes = prepared.tree.nodes.len();
        let keys = prepared.field_keys(ratio);
        let links = &mut prepared.links;
        let mut keyed: Vec<(u32, ClusterLink)> =
            keys.into_iter().zip(links.cluster.drain(..)).collect();
        split_by_start(&mut keyed, &links.cluster_start)
            .into_par_iter()
            .for_each(|part| part.sort_by_key(|&(k, l)| (k != NEAR, k, l.sender)));
        let mut fields = Fields {
            near_end: Vec::with_capacity(nodes),
            ..Fields::default()
        };
        let mut field_of = vec![NONE; nodes];
        for i in 0..nodes {
            let (a, b) = (
                links.cluster_start[i] as usize,
                links.cluster_start[i + 1] as usize,
            );
            let near = keyed[a..b].iter().take_while(|(k, _)| *k == NEAR).count();
            fields.near_end.push((a + near) as u32);
            if a + near < b {
                field_of[i] = fields.node.len() as u32;
                fields.add_field(
                    i,
                    prepared.tree.nodes[i].centroid,
                    &keyed[a + near..b],
                    a + near,
                );
            }
        }
        fields.slot_start.push(fields.slot_key.len() as u32);
        fields.group_start.push(fields.group_mask.len() as u32);
        fields.group_slots.push(fields.slot_key.len() as u32);
        links.cluster = keyed.into_iter().map(|(_, l)| l).collect();
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
                *self.slot_end.last_mut().expect("pushed") = end;
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
        let mut start = Vec::with_capacity(n + 1);
        start.push(0u32);
        for c in &counts {
            start.push(start.last().expect("pushed") + c);
        }
        self.evaluations = *start.last().expect("pushed") as u64;
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

    /// Slots of all fields.
    fn slots(&self) -> usize {
        self.slot_key.len()
    }

    /// Bytes held (without the per-sweep sums, [`Fields::sweep_bytes`]).
    pub(super) fn bytes(&self) -> u64 {
        (self.near_end.len() * 4
            + self.node.len() * (4 + 24 + 4 + 4 + 4)
            + self.group_mask.len() * (2 + 4)
            + self.slot_key.len() * (4 + 4)
            + self.of_element.len() * 8
            + self.elem_slab.len()) as u64
    }

    /// Bytes of the per-sweep sums in `channels` channels.
    pub(super) fn sweep_bytes(&self, channels: usize) -> u64 {
        ((self.group_mask.len() * IRR_TERMS + self.slots() * ANTI_TERMS) * channels * 4) as u64
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

/// What decides the fields of one receiver node: its extent and the planes of its elements'
/// centroids.
struct ReceiverView {
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
    fn slab_of(&self, n: DVec3, x: DVec3, cells: &Bins) -> u8 {
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
    fn field_keys(&self, ratio: f64) -> Vec<u32> {
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
    fn receiver_view(&self, i: usize, cells: &Bins) -> ReceiverView {
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
        let mut view = ReceiverView {
            extent,
            slabs: smallvec::SmallVec::new(),
            mode: SlabMode::Grid,
        };
        {
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
            view.slabs = slabs.into_iter().collect();
        }
        view
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
                    slab.deviation = slab.deviation.max((n - slab.axis).length() + 1e-12);
                }
                None if slabs.len() < MAX_SLABS => {
                    let h = n.dot(x);
                    slabs.push(Slab {
                        axis: n,
                        deviation: 1e-12,
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
    fn field_key(&self, l: &ClusterLink, view: &ReceiverView, ratio: f64) -> u32 {
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
            // A sender in the slab's plane (within the margin of its whole range) lights its
            // elements at grazing incidence: nothing, as behind them (the per-element gather's
            // cosine is then 0 up to rounding).
            if (h - slab.lo).abs() <= margin && (h - slab.hi).abs() <= margin {
                continue;
            }
            if side(h - slab.hi, h - slab.lo, margin)? {
                mask |= 1 << k;
            }
        }
        Some(mask)
    }
}

/// One sweep's field sums: per irradiance group, `G`, its Jacobian's upper triangle
/// (`xx, xy, xz, yy, yz, zz`), `A` and `T` per channel; per slot, the antiradiance, its
/// gradient and its Hessian's upper triangle.
pub(super) struct FieldSums<const C: usize> {
    pub(super) irr: Vec<[[f32; C]; IRR_TERMS]>,
    pub(super) anti: Vec<[[f32; C]; ANTI_TERMS]>,
}

impl<const C: usize> FieldSums<C> {
    /// Zeroed sums for `fields`.
    pub(super) fn new(fields: &Fields) -> Self {
        FieldSums {
            irr: vec![[[0.0; C]; IRR_TERMS]; fields.group_mask.len()],
            anti: vec![[[0.0; C]; ANTI_TERMS]; fields.slots()],
        }
    }
}

impl SweepContext<'_> {
    /// Sums every field's links (intensities `intensity`) into `sums`. Per link with sender
    /// point `c_s`, spread `s`, and `v = c_r - c_s` from it to the field's centre (`r = |v|`,
    /// `D = r^2 + s`, `h = 1 / (r D)`, `q = h' / r`, `k = -1 / pi`):
    ///
    /// - the irradiance field `G = k h v`, its Jacobian `k (h I + q v v^T)` and its second
    ///   derivatives `k (q (d_ij v_k + d_ik v_j + d_jk v_i) + (q' / r) v_i v_j v_k)`, kept as
    ///   `A = k q v` and `T = k (q' / r) v v v`: an element at `c_r + x` with normal `n` gets
    ///   `n . G + n . J x + (2 (n . x)(A . x) + |x|^2 (n . A) + T(n, x, x)) / 2`;
    /// - the antiradiance `1 / (D Omega)`, its gradient `-2 v / (D^2 Omega)` and Hessian
    ///   `(-2 I / D^2 + 8 v v^T / D^3) / Omega`.
    ///
    /// A first-order expansion was tried: the kernels are convex, so it is low everywhere but
    /// at the centre (the room 0.17% darker), and its remainder limited the fields to
    /// receivers of 0.15-0.2 of the distance.
    pub(super) fn sum_fields<const C: usize>(
        &self,
        fields: &Fields,
        links: &Links,
        intensity: &[[f32; C]],
        sums: &mut FieldSums<C>,
    ) {
        let anti_parts = split_by_start(&mut sums.anti, &fields.slot_start);
        let irr_parts = split_by_start(&mut sums.irr, &fields.group_start);
        anti_parts
            .into_par_iter()
            .zip(irr_parts.into_par_iter())
            .enumerate()
            .for_each(|(f, (anti, irr))| {
                let (g0, s0) = (
                    fields.group_start[f] as usize,
                    fields.slot_start[f] as usize,
                );
                for (g, irr) in irr.iter_mut().enumerate() {
                    let mut acc = [[0.0f64; C]; IRR_TERMS];
                    let slots = fields.group_slots[g0 + g] as usize
                        ..fields.group_slots[g0 + g + 1] as usize;
                    for s in slots {
                        anti[s - s0] = self.sum_slot(fields, links, intensity, (f, s), &mut acc);
                    }
                    *irr = acc.map(|x| x.map(|y| y as f32));
                }
            });
    }

    /// The links of slot `s` of field `f`: adds their irradiance terms to `irr` and returns
    /// their antiradiance terms.
    fn sum_slot<const C: usize>(
        &self,
        fields: &Fields,
        links: &Links,
        intensity: &[[f32; C]],
        (f, s): (usize, usize),
        irr: &mut [[f64; C]; IRR_TERMS],
    ) -> [[f32; C]; ANTI_TERMS] {
        let center = fields.center[f];
        let (bin, _) = fields.slot_bin(s);
        let omega = self.bins.solid_angle[bin];
        let mut a = [[0.0f64; C]; ANTI_TERMS];
        let k = -std::f64::consts::FRAC_1_PI;
        for j in fields.slot_links(f, s) {
            let sender = &self.points[links.cluster[j].sender as usize];
            let spread = sender.spread as f64;
            let v = center - sender.centroid();
            let r2 = v.length_squared();
            if !(r2 > 0.0) {
                continue;
            }
            let (r, big_d) = (r2.sqrt(), r2 + spread);
            let i = intensity[j].map(f64::from);
            let vv = [v.x, v.y, v.z];
            if self.use_anti {
                let phi = 1.0 / (big_d * omega);
                let grad = v * (-2.0 * phi / big_d);
                let hess = |p: usize, q: usize| {
                    phi * ((if p == q { -2.0 } else { 0.0 }) + 8.0 * vv[p] * vv[q] / big_d) / big_d
                };
                let t = [
                    phi,
                    grad.x,
                    grad.y,
                    grad.z,
                    hess(0, 0),
                    hess(0, 1),
                    hess(0, 2),
                    hess(1, 1),
                    hess(1, 2),
                    hess(2, 2),
                ];
                for (a, t) in a.iter_mut().zip(t) {
                    for c in 0..C {
                        a[c] += t * i[c];
                    }
                }
            }
            let r3 = r2 * r;
            let h = 1.0 / (r * big_d);
            let q = -(3.0 * r2 + spread) / (r3 * big_d * big_d);
            let dq_over_r = -(6.0 / (r3 * big_d * big_d)
                - 3.0 * (3.0 * r2 + spread) / (r3 * r2 * big_d * big_d)
                - 4.0 * (3.0 * r2 + spread) / (r3 * big_d * big_d * big_d));
            let jac = |p: usize, s: usize| k * ((if p == s { h } else { 0.0 }) + q * vv[p] * vv[s]);
            let mut t = [0.0f64; IRR_TERMS];
            t[..3].copy_from_slice(&[k * h * v.x, k * h * v.y, k * h * v.z]);
            t[3..9].copy_from_slice(&[
                jac(0, 0),
                jac(0, 1),
                jac(0, 2),
                jac(1, 1),
                jac(1, 2),
                jac(2, 2),
            ]);
            t[9..12].copy_from_slice(&[k * q * v.x, k * q * v.y, k * q * v.z]);
            for (u, [p, s, w]) in SYM3.iter().enumerate() {
                t[12 + u] = k * dq_over_r * vv[*p] * vv[*s] * vv[*w];
            }
            for (acc, t) in irr.iter_mut().zip(t) {
                for c in 0..C {
                    acc[c] += t * i[c];
                }
            }
        }
        a.map(|x| x.map(|y| y as f32))
    }

    /// Adds the fields on element `e`'s path to its front irradiance `h`, its back face's
    /// `h_back` (two-sided elements) and its antiradiance bins `a_acc`.
    #[allow(clippy::needless_range_loop)]
    pub(super) fn gather_fields<const C: usize>(
        &self,
        e: usize,
        (fields, sums): (&Fields, &FieldSums<C>),
        a_acc: &mut [[f64; C]],
        (h, h_back): (&mut [f64; C], &mut [f64; C]),
    ) {
        let n = self.elem_normal[e];
        let x = self.elem_center[e];
        let back = self.two_sided || self.elem_back[e];
        let two = self.elem_two.get(e).copied().unwrap_or(false);
        for (f, k) in fields.path_slabs(e) {
            let bit = 1u16 << k;
            let dx = x - fields.center[f];
            let w = irradiance_weights(n, dx);
            for g in fields.group_start[f] as usize..fields.group_start[f + 1] as usize {
                let front = fields.group_mask[g] & bit != 0;
                if !front && !two {
                    continue;
                }
                let t = &sums.irr[g];
                let mut value = [0.0f64; C];
                for k in 0..IRR_TERMS {
                    for c in 0..C {
                        value[c] += w[k] * t[k][c] as f64;
                    }
                }
                // Behind: n . G is the (negative) irradiance of the back face.
                let (out, sign) = if front {
                    (&mut *h, 1.0)
                } else {
                    (&mut *h_back, -1.0)
                };
                for c in 0..C {
                    out[c] += sign * value[c];
                }
            }
            if self.use_anti {
                let wa = [
                    1.0,
                    dx.x,
                    dx.y,
                    dx.z,
                    0.5 * dx.x * dx.x,
                    dx.x * dx.y,
                    dx.x * dx.z,
                    0.5 * dx.y * dx.y,
                    dx.y * dx.z,
                    0.5 * dx.z * dx.z,
                ];
                for s in fields.slot_start[f] as usize..fields.slot_start[f + 1] as usize {
                    let (bin, mask) = fields.slot_bin(s);
                    if !back && mask & bit == 0 {
                        continue;
                    }
                    let t = &sums.anti[s];
                    for k in 0..ANTI_TERMS {
                        for c in 0..C {
                            a_acc[bin][c] += wa[k] * t[k][c] as f64;
                        }
                    }
                }
            }
        }
    }
}

/// The weights of an irradiance group's terms ([`SweepContext::sum_fields`]) for an element
/// with normal `n` at `dx` from the field's centre: `n . G + n . J dx + (2 (n . dx)(A . dx) +
/// |dx|^2 (n . A) + T(n, dx, dx)) / 2`, with `J` and `T` symmetric.
fn irradiance_weights(n: DVec3, dx: DVec3) -> [f64; IRR_TERMS] {
    let (nn, xx) = ([n.x, n.y, n.z], [dx.x, dx.y, dx.z]);
    let mut w = [0.0f64; IRR_TERMS];
    w[..3].copy_from_slice(&nn);
    // J's upper triangle: n_p x_s + n_s x_p off the diagonal.
    let pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
    for (u, &(p, s)) in pairs.iter().enumerate() {
        w[3 + u] = if p == s {
            nn[p] * xx[p]
        } else {
            nn[p] * xx[s] + nn[s] * xx[p]
        };
    }
    let (n_dx, dx2) = (n.dot(dx), dx.length_squared());
    for p in 0..3 {
        w[9 + p] = n_dx * xx[p] + 0.5 * dx2 * nn[p];
    }
    for i in 0..3 {
        for j in 0..3 {
            for l in 0..3 {
                w[12 + SYM3_INDEX[9 * i + 3 * j + l]] += 0.5 * nn[i] * xx[j] * xx[l];
            }
        }
    }
    w
}
