//! Cells of a uniform grid: the one cell function every gridded structure uses (the tile
//! store's sub-cells, the statistics pass's sample cells, a tile cloud's blocks), and a hash
//! grid for sparse sets (the completion stage's ends and vertices).

use glam::{DVec3, I64Vec3};
use std::collections::HashMap;

/// The cell of side `side` holding position `p` (cells are half-open, `[k side, (k+1) side)`).
#[inline]
pub(crate) fn cell(p: DVec3, side: f64) -> I64Vec3 {
    (p / side).floor().as_i64vec3()
}

/// A uniform hash grid over positions: a query visits every cell a ball touches, so the cost
/// of a lookup does not grow with the number of items.
pub(crate) struct HashGrid<T> {
    side: f64,
    /// Each cell's last item added, as an index into `items`.
    heads: HashMap<I64Vec3, u32>,
    /// The items, each with the index of the one added before it to its cell ([`NONE`] for
    /// the first). (Chained in one vector rather than a vector per cell: completion's grid of
    /// a few curve vertices per cell took twice the memory that way.)
    items: Vec<(T, u32)>,
}

/// The end of a cell's chain of items.
const NONE: u32 = u32::MAX;

impl<T: Copy> HashGrid<T> {
    /// An empty grid of cells of side `side`.
    pub(crate) fn new(side: f64) -> HashGrid<T> {
        HashGrid { side: side.max(f64::MIN_POSITIVE), heads: HashMap::new(), items: vec![] }
    }

    /// Adds item `t` at `p`.
    pub(crate) fn insert(&mut self, p: DVec3, t: T) {
        let before = self.heads.insert(cell(p, self.side), self.items.len() as u32).unwrap_or(NONE);
        self.items.push((t, before));
    }

    /// Calls `f` for every item in the cells that the ball of radius `r` around `p` touches
    /// (a superset of the items within `r`; callers test the distance), each cell's from the
    /// last added (callers that pick one item break ties by a total order).
    pub(crate) fn near(&self, p: DVec3, r: f64, mut f: impl FnMut(T)) {
        let (lo, hi) = (cell(p - DVec3::splat(r), self.side), cell(p + DVec3::splat(r), self.side));
        for x in lo.x..=hi.x {
            for y in lo.y..=hi.y {
                for z in lo.z..=hi.z {
                    let mut at = self.heads.get(&I64Vec3::new(x, y, z)).copied().unwrap_or(NONE);
                    while at != NONE {
                        let (t, before) = self.items[at as usize];
                        f(t);
                        at = before;
                    }
                }
            }
        }
    }
}
