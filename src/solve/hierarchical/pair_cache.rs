//! The pair cache: each (receiving element, cluster link) factor of the gather, kept so a
//! sweep is a stream of multiply-adds.

use super::*;

/// The geometric factors of one (receiving element, cluster link) pair
/// ([`SweepContext::pair_factor`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PairFactor {
    /// Irradiance per unit of the link's intensity.
    pub(super) irradiance: f32,
    /// Antiradiance in the link's bin per unit of the link's intensity (0 when none is created).
    pub(super) anti: f32,
}

/// The factors of every (element, cluster link) pair, per element in the order of
/// [`SweepContext::for_each_pair`]: element `e`'s pairs are `factor[start[e] .. start[e + 1]]`.
#[derive(Clone, Debug, Default)]
pub(super) struct PairCache {
    /// Bin of every cluster link (a compact copy of `ClusterLink::bin` for the stream).
    pub(super) link_bin: Vec<u16>,
    pub(super) start: Vec<u64>,
    /// Per element, the ranges of `links.cluster` into it and its ancestors that are not
    /// empty, in the order of [`SweepContext::for_each_pair`]: element `e`'s are
    /// `ranges[range_start[e] .. range_start[e + 1]]` (the sweep walks these instead of the
    /// tree).
    pub(super) ranges: Vec<(u32, u32)>,
    pub(super) range_start: Vec<u32>,
    /// Per pair, its [`PairFactor`] as `[irradiance, anti]` (an array of floats, so the
    /// allocation is zeroed lazily by the system instead of written element by element: on the
    /// room that serial fill of 80 MB took 75 ms).
    pub(super) factor: Vec<[f32; 2]>,
}

impl PairCache {
    /// The cache for `prepared` (tree, links, element arrays and `use_anti` set), or the bytes
    /// it would take when that is more than `budget`.
    pub(super) fn build(prepared: &Prepared, budget: u64) -> std::result::Result<PairCache, u64> {
        let (tree, links) = (&prepared.tree, &prepared.links);
        let n = prepared.element_count();
        let counts: Vec<usize> = (0..n)
            .into_par_iter()
            .map(|e| near_links_into_ancestors(tree, links, &prepared.fields, e))
            .collect();
        let total: usize = counts.iter().sum();
        let bytes = PairCache::factor_bytes(total as u64, n);
        if bytes > budget {
            return Err(bytes);
        }
        let start = starts_of(counts.iter().map(|&c| c as u64));
        let mut factor = vec![[0.0f32; 2]; total];
        let ctx = prepared.sweep_context();
        split_by_start(&mut factor, &start)
            .into_par_iter()
            .enumerate()
            .for_each(|(e, out)| {
                let mut k = 0;
                ctx.for_each_pair(e, links, |_, _, f| {
                    out[k] = [f.irradiance, f.anti];
                    k += 1;
                });
            });
        let link_bin = links.cluster.iter().map(|l| l.bin).collect();
        let mut ranges = Vec::new();
        let mut range_start = Vec::with_capacity(n + 1);
        range_start.push(0);
        for e in 0..n {
            let mut node = tree.elements[e];
            while node != NONE {
                let near = prepared.fields.near_links(links, node);
                if !near.is_empty() {
                    ranges.push((near.start as u32, near.end as u32));
                }
                node = tree.nodes[node as usize].parent;
            }
            range_start.push(ranges.len() as u32);
        }
        Ok(PairCache {
            link_bin,
            start,
            ranges,
            range_start,
            factor,
        })
    }

    /// Calls `f` for element `e` and each of its ancestors (element first, then up the tree,
    /// as [`SweepContext::for_each_pair`] orders them) with the node's incoming cluster links
    /// (a range of `links.cluster`) and their factors for `e`.
    #[inline]
    pub(super) fn for_each_node(
        &self,
        e: usize,
        mut f: impl FnMut(std::ops::Range<usize>, &[[f32; 2]]),
    ) {
        let mut k = self.start[e] as usize;
        let ranges = &self.ranges[self.range_start[e] as usize..self.range_start[e + 1] as usize];
        for &(a, b) in ranges {
            let range = a as usize..b as usize;
            let len = range.len();
            f(range, &self.factor[k..k + len]);
            k += len;
        }
    }

    /// Bytes of the factors of `pairs` (element, cluster link) pairs over `elements`
    /// elements, with their starts: what [`PairCache::build`] holds its budget against.
    pub(super) fn factor_bytes(pairs: u64, elements: usize) -> u64 {
        pairs * std::mem::size_of::<[f32; 2]>() as u64 + (elements as u64 + 1) * 8
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> u64 {
        (self.start.len() * 8
            + self.ranges.len() * 8
            + self.range_start.len() * 4
            + self.link_bin.len() * 2
            + self.factor.len() * std::mem::size_of::<[f32; 2]>()) as u64
    }
}
