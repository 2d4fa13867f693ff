//! Pushing near links down: a cluster link that its receiver's field cannot take (the receiver
//! too large seen from the sender, beside a flat sender's plane, or on both sides of it) is
//! replaced by links from its sender into the receiver's children, and so on down, where that
//! costs the sweeps less: the smaller receivers take it through their fields where they can.
//!
//! A near link costs a pull and its receiver's element count in (element, link) pairs every
//! sweep; each pushed link costs a pull and either a field term or its own pairs. Along a
//! concave edge (a floor's clusters beside a wall) the children away from the edge take the
//! link through their fields, and only those next to it go on down: the pairs follow the
//! edge, not the receiver's area. Where the pairs are cached they cost a tenth as much, and
//! little is worth pushing.

use super::*;

/// Near links into nodes of fewer elements are gathered per element as they are.
pub(super) const PUSH_ELEMENTS: u32 = 16;

/// What a sweep spends on one (element, link) pair evaluated on the fly, the unit of the costs
/// below. Per pair, a cached factor costs [`CACHED_PAIR_COST`], a pull [`PULL_TERM_COST`]
/// per sender group it sums, and a field link [`FIELD_TERM_COST`] for its terms. Measured on
/// the 258k and 1M-triangle boxes (`perf record`, CPU time per item and sweep): about 42 ns
/// per pair on the fly, 22 ns per pull term, 88 ns per field link.
const CACHED_PAIR_COST: f64 = 0.1;
const PULL_TERM_COST: f64 = 0.5;
const FIELD_TERM_COST: f64 = 2.0;

/// A link that [`Prepared::push_near_links`] drops: pushed below its receiver, or silent.
const PUSHED: u32 = NEAR - 1;

/// Most receiver views one node's push keeps at once (about 0.8 kB each); beyond, they are
/// dropped and found again as needed.
const MAX_VIEWS: usize = 4096;

/// The receiver views one node's push has found, by node.
type Views = std::collections::HashMap<u32, ReceiverView>;

/// The fixed inputs of one push.
struct Push<'a> {
    prepared: &'a Prepared,
    ratio: f64,
    two_sided: bool,
    cells: Bins,
    /// The cost of one pair ([`CACHED_PAIR_COST`] when the pairs are cached, else 1).
    pair: f64,
    record_culled: bool,
}

impl Push<'_> {
    /// The least a sweep can spend on the link from `sender` into node `r` (`views`: the
    /// receiver views found so far): through `r`'s field, per element of `r`, or pushed into
    /// `r`'s children, whichever costs least. Appends the links that do it to `out` with their
    /// keys (a silent link with key [`PUSHED`] when culled pairs are recorded).
    fn best(
        &self,
        sender: u32,
        r: u32,
        pull: f64,
        views: &mut Views,
        out: &mut Vec<(u32, ClusterLink)>,
    ) -> f64 {
        let p = self.prepared;
        let (tree, bins) = (&p.tree, &p.bins);
        if crate::hierarchy::links::silent(tree, sender, r, self.two_sided) {
            if self.record_culled {
                let link = ClusterLink {
                    sender,
                    receiver: r,
                    bin: 0,
                };
                out.push((PUSHED, link));
            }
            return 0.0;
        }
        let node = &tree.nodes[r as usize];
        let link = crate::hierarchy::links::cluster_link(tree, bins, sender, r);
        let count = node.elements.1 - node.elements.0;
        if count >= MIN_FIELD_ELEMENTS {
            let view = views
                .entry(r)
                .or_insert_with(|| p.receiver_view(r as usize, &self.cells));
            let key = p.field_key(&link, view, self.ratio);
            if key != NEAR {
                out.push((key, link));
                return pull + FIELD_TERM_COST;
            }
        }
        let near = self.near(pull, count);
        if node.is_leaf() || count < PUSH_ELEMENTS {
            out.push((NEAR, link));
            return near;
        }
        let mark = out.len();
        let pushed = self.children(sender, r, pull, views, out);
        if pushed < near {
            return pushed;
        }
        out.truncate(mark);
        out.push((NEAR, link));
        near
    }

    /// What a sweep spends on a link gathered per element of a receiver of `count` elements,
    /// its pull costing `pull`.
    fn near(&self, pull: f64, count: u32) -> f64 {
        pull + f64::from(count) * self.pair
    }

    /// [`Push::best`] summed over the children of node `r`.
    fn children(
        &self,
        sender: u32,
        r: u32,
        pull: f64,
        views: &mut Views,
        out: &mut Vec<(u32, ClusterLink)>,
    ) -> f64 {
        let node = &self.prepared.tree.nodes[r as usize];
        (node.first_child..node.first_child + node.child_count as u32)
            .map(|c| self.best(sender, c, pull, views, out))
            .sum()
    }
}

impl Prepared {
    /// Pushes each near link (key [`NEAR`] in `keys`, in link order) into a node of at least
    /// [`PUSH_ELEMENTS`] elements down into the node's children when that costs the sweeps
    /// less ([`Push::best`]; `ratio`: [`SolverOptions::field_ratio`]). A pushed link that
    /// would add exactly nothing is dropped ([`crate::hierarchy::links::silent`]; kept in
    /// `links.culled` when `record_culled`). The pairs are taken as cached when they fit the
    /// pair cache's own budget ([`SolverOptions::pair_cache_mb`]). Rewrites `links.cluster`
    /// and `links.cluster_start` and returns the keys of the new links, with the number of
    /// links pushed. Needs the sender groups.
    pub(super) fn push_near_links(
        &mut self,
        mut keys: Vec<u32>,
        ratio: f64,
        record_culled: bool,
    ) -> (Vec<u32>, u64) {
        let (tree, links) = (&self.tree, &self.links);
        let near_pairs: u64 = split_by_start(&mut keys, &links.cluster_start)
            .into_par_iter()
            .enumerate()
            .map(|(i, out)| {
                let (e0, e1) = tree.nodes[i].elements;
                out.iter().filter(|&&k| k == NEAR).count() as u64 * u64::from(e1 - e0)
            })
            .sum();
        let cached = PairCache::factor_bytes(near_pairs, self.element_count())
            <= self.options.pair_cache_mb as u64 * 1_000_000;
        let push = Push {
            prepared: self,
            ratio,
            two_sided: self.options.coupling().two_sided,
            cells: Bins::new(SLAB_CELLS),
            pair: if cached { CACHED_PAIR_COST } else { 1.0 },
            record_culled,
        };
        // Per receiver node, in node order: the links that replace its pushed ones.
        let pushed: Vec<(u32, ClusterLink)> = split_by_start(&mut keys, &links.cluster_start)
            .into_par_iter()
            .enumerate()
            .flat_map_iter(|(i, out)| {
                let node = &tree.nodes[i];
                let mut found = Vec::new();
                let count = node.elements.1 - node.elements.0;
                if node.is_leaf() || count < PUSH_ELEMENTS {
                    return found.into_iter();
                }
                // The views of the nodes below, which every near link into the node visits.
                let mut views = Views::new();
                let start = links.cluster_start[i] as usize;
                for (k, l) in out.iter_mut().zip(&links.cluster[start..]) {
                    if *k != NEAR {
                        continue;
                    }
                    let pull = PULL_TERM_COST * push.prepared.pull_terms(l.sender) as f64;
                    if views.len() > MAX_VIEWS {
                        views.clear();
                    }
                    let mark = found.len();
                    let pushed = push.children(l.sender, i as u32, pull, &mut views, &mut found);
                    if pushed < push.near(pull, count) {
                        *k = PUSHED;
                    } else {
                        found.truncate(mark);
                    }
                }
                found.into_iter()
            })
            .collect();
        let moved = keys.iter().filter(|&&k| k == PUSHED).count() as u64;
        if moved == 0 {
            return (keys, 0);
        }
        let links = &mut self.links;
        let mut added = Vec::with_capacity(pushed.len());
        for (k, l) in pushed {
            if k == PUSHED {
                links.culled.push((l.sender, l.receiver));
            } else {
                added.push((k, l));
            }
        }
        added.par_sort_by_key(|&(_, l)| l.receiver);
        // Per receiver node in node order: the links that stay, then the pushed ones.
        let nodes = links.cluster_start.len() - 1;
        let total = keys.len() - moved as usize + added.len();
        let mut start = Vec::with_capacity(nodes + 1);
        let mut new_keys = Vec::with_capacity(total);
        let mut new_links = Vec::with_capacity(total);
        let mut next = added.into_iter().peekable();
        for i in 0..nodes {
            start.push(new_links.len() as u32);
            let (a, b) = (
                links.cluster_start[i] as usize,
                links.cluster_start[i + 1] as usize,
            );
            for (&k, &l) in keys[a..b].iter().zip(&links.cluster[a..b]) {
                if k != PUSHED {
                    new_keys.push(k);
                    new_links.push(l);
                }
            }
            while let Some((k, l)) = next.next_if(|(_, l)| l.receiver as usize == i) {
                new_keys.push(k);
                new_links.push(l);
            }
        }
        start.push(new_links.len() as u32);
        links.cluster = new_links;
        links.cluster_start = start;
        (new_keys, moved)
    }
}
