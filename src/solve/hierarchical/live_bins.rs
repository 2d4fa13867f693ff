//! Live bins: the antiradiance bins some link both writes into an element and reads from it,
//! the only ones stored.

use super::*;

/// The antiradiance bins each element stores: those some link both writes into the element
/// (light arriving at its front, or at either side when two-sided) and reads from it (a cluster
/// link sent by one of its ancestors, or an exact coupling it sends). Every other bin of the
/// element stays 0 or is never read, so it is not stored. Element `e`'s stored bins, in
/// increasing order, are slots `start[e] .. start[e + 1]` of the antiradiance array.
#[derive(Clone, Debug, Default)]
pub(super) struct LiveBins {
    /// 64-bit words per element mask.
    pub(super) words: usize,
    /// Per element, `words` words: bit b set when bin b is stored.
    pub(super) mask: Vec<u64>,
    /// Per element, its first slot; `start[n]` is the slot count.
    pub(super) start: Vec<u32>,
}

impl LiveBins {
    /// No bin stored for any of `n` elements (no antiradiance).
    pub(super) fn empty(n: usize, nb: usize) -> LiveBins {
        let words = nb.div_ceil(64);
        LiveBins {
            words,
            mask: vec![0; n * words],
            start: vec![0; n + 1],
        }
    }

    /// The bins each element of `prepared` (tree, links, element arrays set) must store.
    pub(super) fn build(prepared: &Prepared) -> LiveBins {
        let (tree, links) = (&prepared.tree, &prepared.links);
        let n = prepared.element_count();
        let words = prepared.bins.len().div_ceil(64);
        let ctx = prepared.sweep_context();
        let set = |m: &mut [u64], bin: usize| m[bin >> 6] |= 1u64 << (bin & 63);

        // Read: bins of the cluster links each node sends (inherited by its elements) and of the
        // exact couplings each element sends that carry its antiradiance.
        let mut node_sends = vec![0u64; tree.nodes.len() * words];
        for l in &links.cluster {
            let i = l.sender as usize;
            set(&mut node_sends[i * words..(i + 1) * words], l.bin as usize);
        }
        let mut read = vec![0u64; n * words];
        for e in 0..n {
            for l in links.exact_start[e]..links.exact_start[e + 1] {
                let s = links.exact_sender[l as usize] as usize;
                for entry in links.exact_entries_of(l as usize) {
                    if entry.f_a != 0.0 || entry.o_a != 0.0 {
                        set(&mut read[s * words..(s + 1) * words], entry.bin as usize);
                    }
                }
            }
        }
        // Written, per element: its exact couplings' bins, and the bins of the cluster links
        // into it and its ancestors where the light arrives at a side that creates antiradiance;
        // then keep the read ones.
        let mut mask = vec![0u64; n * words];
        mask.par_chunks_mut(words)
            .zip(read.par_chunks(words))
            .enumerate()
            .for_each(|(e, (m, r))| {
                for l in links.exact_start[e]..links.exact_start[e + 1] {
                    for entry in links.exact_entries_of(l as usize) {
                        if entry.o_b != 0.0 || entry.o_a != 0.0 {
                            set(m, entry.bin as usize);
                        }
                    }
                }
                // The sweep's own per-pair factors (from the cache when there is one): a bin is
                // written where the pair's antiradiance factor is not 0.
                match &prepared.pairs {
                    Some(cache) => cache.for_each_node(e, |range, factors| {
                        for (f, l) in factors.iter().zip(&links.cluster[range]) {
                            if f[1] != 0.0 {
                                set(m, l.bin as usize);
                            }
                        }
                    }),
                    None => ctx.for_each_pair(e, links, |_, l, f| {
                        if f.anti != 0.0 {
                            set(m, l.bin as usize);
                        }
                    }),
                }
                // The links gathered through fields on its path.
                let back = ctx.two_sided || prepared.elem_back[e];
                prepared.fields.written_bins(e, back, |bin| set(m, bin));
                let mut reads = r.to_vec();
                let mut node = tree.elements[e];
                while node != NONE {
                    let i = node as usize;
                    for (k, word) in reads.iter_mut().enumerate() {
                        *word |= node_sends[i * words + k];
                    }
                    node = tree.nodes[i].parent;
                }
                for (word, r) in m.iter_mut().zip(&reads) {
                    *word &= r;
                }
            });
        let mut start = starts_of(
            mask.chunks(words.max(1))
                .map(|m| m.iter().map(|w| w.count_ones()).sum::<u32>()),
        );
        start.truncate(n + 1);
        LiveBins { words, mask, start }
    }

    /// Stored slots in all.
    pub(super) fn slots(&self) -> usize {
        self.start.last().map_or(0, |&s| s as usize)
    }

    /// Bytes of the masks and offsets.
    pub(super) fn bytes(&self) -> u64 {
        (self.mask.len() * 8 + self.start.len() * 4) as u64
    }

    /// The slot of element `e`'s bin `bin`, or `None` when it is not stored.
    #[inline]
    pub(super) fn slot(&self, e: usize, bin: usize) -> Option<usize> {
        let m = &self.mask[e * self.words..(e + 1) * self.words];
        let (w, bit) = (bin >> 6, bin & 63);
        if (m[w] >> bit) & 1 == 0 {
            return None;
        }
        let below: u32 = m[..w].iter().map(|x| x.count_ones()).sum();
        Some(self.start[e] as usize + (below + (m[w] & ((1u64 << bit) - 1)).count_ones()) as usize)
    }

    /// Calls `visit(bin, slot)` for each of element `e`'s stored bins in `bins`, increasing.
    #[inline]
    pub(super) fn for_each_slot_in(
        &self,
        e: usize,
        bins: std::ops::Range<usize>,
        mut visit: impl FnMut(usize, usize),
    ) {
        let mut slot = self.start[e] as usize;
        for (k, &word) in self.mask[e * self.words..(e + 1) * self.words]
            .iter()
            .enumerate()
        {
            let (low, high) = (k * 64, k * 64 + 64);
            if bins.end <= low {
                break;
            }
            if bins.start >= high {
                slot += word.count_ones() as usize;
                continue;
            }
            // The bits of this word from `bins.start` on; those below count as slots before.
            let from = bins.start.saturating_sub(low);
            let below = if from == 0 {
                0
            } else {
                word & ((1u64 << from) - 1)
            };
            slot += below.count_ones() as usize;
            let mut w = word & !below;
            while w != 0 {
                let bit = w.trailing_zeros() as usize;
                if low + bit >= bins.end {
                    return;
                }
                visit(low + bit, slot);
                slot += 1;
                w &= w - 1;
            }
        }
    }

    /// Element `e`'s stored bins, increasing (the order of its slots).
    pub(super) fn bins_of(&self, e: usize) -> impl Iterator<Item = usize> + '_ {
        self.mask[e * self.words..(e + 1) * self.words]
            .iter()
            .enumerate()
            .flat_map(|(k, &word)| {
                let mut w = word;
                std::iter::from_fn(move || {
                    if w == 0 {
                        return None;
                    }
                    let b = w.trailing_zeros() as usize;
                    w &= w - 1;
                    Some(k * 64 + b)
                })
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every block of bins visits exactly the element's stored bins in it, with the slots
    /// `slot` gives them, across word boundaries (144 bins: three words per element).
    #[test]
    fn slots_in_a_block_of_bins_are_those_of_the_whole_mask() {
        let nb = 144;
        let mut live = LiveBins::empty(3, nb);
        let words = live.words;
        let mut rng = crate::geometry::sampling::Rng::new(7, 0);
        for m in live.mask.iter_mut() {
            *m = rng.below(u64::MAX) & rng.below(u64::MAX);
        }
        live.mask[words] = 0; // an element with no bins
        live.start = starts_of(
            live.mask
                .chunks(words)
                .map(|m| m.iter().map(|w| w.count_ones()).sum::<u32>()),
        );
        for e in 0..3 {
            for (from, to) in [
                (0, nb),
                (0, 1),
                (5, 70),
                (63, 65),
                (64, 128),
                (100, nb),
                (70, 70),
            ] {
                let mut seen = Vec::new();
                live.for_each_slot_in(e, from..to, |bin, slot| seen.push((bin, slot)));
                let expected: Vec<(usize, usize)> = live
                    .bins_of(e)
                    .filter(|b| (from..to).contains(b))
                    .map(|b| (b, live.slot(e, b).expect("stored")))
                    .collect();
                assert_eq!(seen, expected, "element {e}, bins {from}..{to}");
            }
        }
    }
}
