//! Disjoint sets, for grouping triangles into connected regions and objects.

use std::collections::HashMap;

/// Disjoint sets over `0..n` (path halving; a union keeps the smaller root).
pub struct UnionFind(Vec<usize>);

impl UnionFind {
    /// `n` sets of one member each.
    pub fn new(n: usize) -> UnionFind {
        UnionFind((0..n).collect())
    }
    /// The root of `x`'s set.
    pub fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    /// Joins the sets of `a` and `b`.
    pub fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb)] = ra.min(rb);
        }
    }
    /// The sets, each sorted, in order of their smallest member.
    pub fn groups(&mut self, members: impl Iterator<Item = usize>) -> Vec<Vec<usize>> {
        let mut index: HashMap<usize, usize> = HashMap::new();
        let mut groups: Vec<Vec<usize>> = Vec::new();
        for x in members {
            let r = self.find(x);
            let g = *index.entry(r).or_insert_with(|| {
                groups.push(Vec::new());
                groups.len() - 1
            });
            groups[g].push(x);
        }
        groups
    }
}
