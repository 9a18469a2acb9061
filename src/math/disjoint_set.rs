//! Disjoint sets (union–find) over the elements `0..n`.
//!
//! Invariant: the representative (root) of every set is its **smallest element**, so roots are
//! deterministic and do not depend on the order of the unions (callers use this to pin "the
//! smallest vertex of each connected component"). `find` uses path halving; there is no union
//! by rank (the smallest-root rule replaces it), which is fast enough for mesh-sized inputs.

/// Union–find over `0..n` whose roots are the smallest elements of their sets.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DisjointSet {
    parent: Vec<usize>,
}

impl DisjointSet {
    /// `n` singleton sets `{0}, {1}, …, {n − 1}`.
    pub fn new(n: usize) -> Self {
        DisjointSet { parent: (0..n).collect() }
    }

    /// Number of elements n.
    pub fn len(&self) -> usize {
        self.parent.len()
    }

    /// True when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.parent.is_empty()
    }

    /// The root of `x`'s set, i.e. its smallest element (path halving on the way).
    /// Panics when `x ≥ n`.
    pub fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] != x {
            self.parent[x] = self.parent[self.parent[x]];
            x = self.parent[x];
        }
        x
    }

    /// Merges the sets of `a` and `b`; the merged set's root is the smaller of the two roots.
    /// Returns `true` when they were different sets. Panics when an index is ≥ n.
    pub fn union(&mut self, a: usize, b: usize) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        self.parent[hi] = lo;
        true
    }

    /// True when `a` and `b` are in the same set.
    pub fn same(&mut self, a: usize, b: usize) -> bool {
        self.find(a) == self.find(b)
    }

    /// The root of every element, `roots()[x] = find(x)` (length n).
    pub fn roots(&mut self) -> Vec<usize> {
        (0..self.parent.len()).map(|x| self.find(x)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_are_smallest_elements_whatever_the_union_order() {
        let mut d = DisjointSet::new(8);
        assert_eq!(d.len(), 8);
        assert!(!d.is_empty());
        assert!(d.union(7, 5));
        assert!(d.union(5, 6));
        assert!(d.union(3, 1));
        assert!(!d.union(6, 7));
        assert!(d.union(6, 3));
        assert_eq!(d.roots(), vec![0, 1, 2, 1, 4, 1, 1, 1]);
        assert!(d.same(7, 1));
        assert!(!d.same(0, 2));
        assert!(DisjointSet::new(0).is_empty());
    }
}
