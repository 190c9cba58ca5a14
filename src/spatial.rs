//! Neighbour queries over a point set, on top of kiddo's immutable k-d tree.
//!
//! Points are kept in f32 local coordinates (relative to an f64 origin chosen by the caller,
//! e.g. the tile's corner), which is exact enough for neighbourhoods and twice as cache-friendly.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZero;

/// A static k-d tree over 3D points, answering radius and k-nearest queries by point index.
pub(crate) struct Index {
    tree: ImmutableKdTree<f32, 3>,
}

impl Index {
    /// Builds the tree over `points` (indices into this slice are what queries return).
    ///
    /// The build is serial: trees are built on the tile loader thread while the rayon pool
    /// computes the tile before, and kiddo's parallel build (the default from 262 144
    /// points) would queue behind that work instead of overlapping it.
    pub(crate) fn new(points: &[[f32; 3]]) -> Index {
        let tree = ImmutableKdTree::builder().with_serial_construction().build_from_slice(points).expect("k-d tree construction");
        Index { tree }
    }

    /// As [`Index::new`], but large trees are built in parallel on the rayon pool: for callers
    /// whose pool would otherwise wait for the tree. The tree is the same.
    pub(crate) fn new_parallel(points: &[[f32; 3]]) -> Index {
        let tree = ImmutableKdTree::builder().build_from_slice(points).expect("k-d tree construction");
        Index { tree }
    }

    /// Appends to `out` the index and squared distance of every point within `radius` of `q`,
    /// in no particular order.
    #[inline]
    pub(crate) fn within(&self, q: &[f32; 3], radius: f32, out: &mut Vec<(u32, f32)>) {
        self.tree.query(q).within::<SquaredEuclidean<f32>>(radius * radius).unsorted().visit(|r| out.push((r.item, r.distance)));
    }

    /// Index and squared distance of the `k` points nearest to `q`, nearest first.
    #[inline]
    pub(crate) fn nearest_n(&self, q: &[f32; 3], k: usize, out: &mut Vec<(u32, f32)>) {
        let Some(k) = NonZero::new(k) else { return };
        for r in self.tree.query(q).nearest_n::<SquaredEuclidean<f32>>(k).execute() {
            out.push((r.item, r.distance));
        }
    }

    /// Index and squared distance of the (at most) `k` points nearest to `q` within `radius`,
    /// nearest first. Far cheaper than [`Index::nearest_n`] where the radius prunes.
    #[inline]
    pub(crate) fn nearest_n_within(&self, q: &[f32; 3], k: usize, radius: f32, out: &mut Vec<(u32, f32)>) {
        let Some(k) = NonZero::new(k) else { return };
        for r in self.tree.query(q).nearest_n::<SquaredEuclidean<f32>>(k).within(radius * radius).execute() {
            out.push((r.item, r.distance));
        }
    }

    /// Number of points in the tree.
    pub(crate) fn len(&self) -> usize {
        self.tree.size()
    }

    /// True if the tree holds no point.
    pub(crate) fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
