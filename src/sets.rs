//! Disjoint sets of numbered items (union-find), for the linked sets the curve stage forms:
//! corner points within the corner radius, and polylines that completion must see together.

/// Disjoint sets over the items `0..n`; each set's root is its smallest item, so the sets
/// come out the same whatever order the links were made in.
pub(crate) struct Sets {
    parent: Vec<u32>,
}

impl Sets {
    /// `n` items, each a set of its own.
    pub(crate) fn new(n: usize) -> Sets {
        Sets { parent: (0..n as u32).collect() }
    }

    /// The root of `a`'s set (the path is halved on the way).
    fn root(&mut self, mut a: u32) -> u32 {
        while self.parent[a as usize] != a {
            let up = self.parent[self.parent[a as usize] as usize];
            self.parent[a as usize] = up;
            a = up;
        }
        a
    }

    /// Joins the sets of `a` and `b`.
    pub(crate) fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.root(a), self.root(b));
        self.parent[a.max(b) as usize] = a.min(b);
    }

    /// The sets, each its items in order, in the order of their first items.
    pub(crate) fn sets(mut self) -> Vec<Vec<u32>> {
        let n = self.parent.len();
        let mut at: Vec<u32> = vec![u32::MAX; n];
        let mut out: Vec<Vec<u32>> = vec![];
        for item in 0..n as u32 {
            let r = self.root(item) as usize;
            if at[r] == u32::MAX {
                at[r] = out.len() as u32;
                out.push(vec![]);
            }
            out[at[r] as usize].push(item);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sets_do_not_depend_on_the_order_of_links() {
        let links = [(5, 3), (3, 8), (1, 6), (8, 0), (6, 9)];
        let mut forward = Sets::new(10);
        links.iter().for_each(|&(a, b)| forward.union(a, b));
        let mut backward = Sets::new(10);
        links.iter().rev().for_each(|&(a, b)| backward.union(b, a));
        let expected = vec![vec![0, 3, 5, 8], vec![1, 6, 9], vec![2], vec![4], vec![7]];
        assert_eq!(forward.sets(), expected);
        assert_eq!(backward.sets(), expected);
    }
}
