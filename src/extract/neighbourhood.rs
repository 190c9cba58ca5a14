//! The point set a stage works on: coordinates local to an f64 origin, indexed by a k-d tree
//! (built on first use) or stored by the cells of a grid.

use crate::spatial::Index;
use glam::DVec3;

/// Points of one tile (core and halo) in local coordinates, indexed for neighbour queries.
/// Points are stored in Morton (Z-curve) order, or cell by cell in a grid (see `Cells`), so
/// that consecutive points are spatial neighbours and per-point queries stay in cache; `ids`
/// maps back to the caller's order.
pub(crate) struct Cloud {
    /// World position of the local origin.
    pub origin: DVec3,
    /// Local coordinates in f64: fits use these, so results do not depend on where the
    /// origin is beyond the last bits (f32 rounding would depend on it).
    pub pos: Vec<DVec3>,
    /// For each stored point, its index in the input slice.
    pub ids: Vec<u32>,
    /// For each stored point, its global identity (stable across tilings).
    pub gid: Vec<u64>,
    /// The k-d tree over the points' f32 coordinates, built on first use (see
    /// [`Cloud::index`]): a gridded cloud's blocks of neighbourhoods never need it.
    index: std::sync::OnceLock<Index>,
    /// Whether a tree built on first use may be built on the rayon pool.
    parallel: bool,
    /// The grid the points are stored by, if gridded (see [`Cloud::gridded`]).
    cells: Option<Cells>,
    /// Each point's rank in coordinate order (x, then y, then z, then global id), if built
    /// (see [`Cloud::prepare_ordering`]): comparing two ranks is far cheaper than comparing
    /// coordinates.
    rank: std::sync::OnceLock<Vec<u32>>,
    /// How far an f32 distance between two points may be from the f64 one: each local
    /// coordinate is rounded to f32 by up to 2^-24 of the largest one.
    slack: f64,
    /// Once set, [`Cloud::map_neighbourhoods_at`] skips the blocks it has not begun (see
    /// [`Cloud::cancelled_by`]).
    cancel: Option<crate::cancel::Cancel>,
}

/// The f32 radius that surely finds every point within `r` (in f64) of a query, given the
/// coordinates' rounding `slack` (see [`Cloud`]): membership is then decided in f64. (A
/// relative margin alone missed points on the rim in tiles a few hundred metres wide, so a
/// ball held different points depending on the tile's size.)
pub(crate) fn query_radius(r: f64, slack: f64) -> f32 {
    (r * (1.0 + 1e-5) + slack) as f32 + f32::EPSILON
}

/// The rounding slack of f32 coordinates no larger than `extent` in magnitude (see [`Cloud`]):
/// both ends of a distance may be rounded, by 2^-24 of `extent` on each axis, and 2^-21 of it
/// bounds that with room to spare.
pub(crate) fn rounding_slack(extent: f64) -> f64 {
    extent * 2f64.powi(-21)
}

/// Spreads the low 21 bits of `v` to every third bit.
fn spread(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

impl Cloud {
    #[cfg(test)]
    /// Builds a cloud from world positions (global ids = their indices), with the origin at
    /// their minimum corner.
    pub(crate) fn new(world: &[DVec3]) -> Cloud {
        let origin = world.iter().copied().reduce(DVec3::min).unwrap_or(DVec3::ZERO);
        let gid: Vec<u64> = (0..world.len() as u64).collect();
        Cloud::with_origin(world, &gid, origin)
    }

    #[cfg(test)]
    /// Builds a cloud from world positions and their global ids, with a given origin.
    pub(crate) fn with_origin(world: &[DVec3], gids: &[u64], origin: DVec3) -> Cloud {
        Cloud::build(world, gids, origin, false, None)
    }

    /// As [`Cloud::with_origin`], with the sort (and the tree, once needed) built on the rayon
    /// pool (for a caller whose pool has nothing else to do meanwhile). The cloud is the same.
    pub(crate) fn with_origin_parallel(world: &[DVec3], gids: &[u64], origin: DVec3) -> Cloud {
        Cloud::build(world, gids, origin, true, None)
    }

    /// As [`Cloud::with_origin`], with the points stored cell by cell in a grid of cubes of
    /// side `side`: [`Cloud::map_neighbourhoods`] then gathers each block's points from the
    /// grid, and builds no tree. Two gridded clouds of the same points and side store them in
    /// the same order. Sorted and indexed on the rayon pool if `parallel`.
    pub(crate) fn gridded(world: &[DVec3], gids: &[u64], origin: DVec3, side: f64, parallel: bool) -> Cloud {
        Cloud::build(world, gids, origin, parallel, Some(side))
    }

    /// The points `which` (stored indices, in increasing order) as a cloud of their own, with
    /// the same local coordinates; its `ids` are their stored indices in this cloud. Its tree is
    /// built serially (see [`Thinned::new`]).
    pub(crate) fn subset(&self, which: &[u32]) -> Cloud {
        Cloud {
            origin: self.origin,
            pos: which.iter().map(|&i| self.pos[i as usize]).collect(),
            ids: which.to_vec(),
            gid: which.iter().map(|&i| self.gid[i as usize]).collect(),
            index: std::sync::OnceLock::new(),
            parallel: false,
            cells: None,
            rank: std::sync::OnceLock::new(),
            slack: self.slack,
            cancel: None,
        }
    }

    fn build(world: &[DVec3], gids: &[u64], origin: DVec3, parallel: bool, side: Option<f64>) -> Cloud {
        use rayon::prelude::*;
        let ext = world.iter().fold(0.0f64, |m, p| m.max((*p - origin).max_element()));
        let mut cells = side.map(|side| Cells::new(side, ext));
        let mut order: Vec<(u64, u32)> = match &cells {
            Some(cells) => world.iter().enumerate().map(|(i, p)| (cells.key(*p - origin), i as u32)).collect(),
            None => {
                let q = if ext > 0.0 { ((1u64 << 21) - 1) as f64 / ext } else { 0.0 };
                let code = |p: DVec3| {
                    let l = ((p - origin) * q).max(DVec3::ZERO);
                    spread(l.x as u64) | spread(l.y as u64) << 1 | spread(l.z as u64) << 2
                };
                world.iter().enumerate().map(|(i, p)| (code(*p), i as u32)).collect()
            }
        };
        if parallel {
            order.par_sort_unstable();
        } else {
            order.sort_unstable();
        }
        if let Some(c) = &mut cells {
            c.index(order.iter().map(|o| o.0));
        }
        let ids: Vec<u32> = order.iter().map(|o| o.1).collect();
        let pos: Vec<DVec3> = ids.iter().map(|&i| world[i as usize] - origin).collect();
        let gid: Vec<u64> = ids.iter().map(|&i| gids[i as usize]).collect();
        let slack = rounding_slack(pos.iter().fold(0.0f64, |m, p| m.max(p.abs().max_element())));
        Cloud { origin, pos, ids, gid, index: std::sync::OnceLock::new(), parallel, cells, rank: std::sync::OnceLock::new(), slack, cancel: None }
    }

    /// The cloud, whose neighbourhood passes stop within a block of `cancel` being set: the
    /// blocks not begun then give `T::default()`, and the caller, which sees the flag, must
    /// discard the result. (A tile's pass takes seconds; a block, milliseconds.)
    pub(crate) fn cancelled_by(mut self, cancel: &crate::cancel::Cancel) -> Cloud {
        self.cancel = Some(cancel.clone());
        self
    }

    /// The stored indices of the points that `is_core` (indexed by the caller's order, see
    /// `ids`) flags as the tile's core, in stored order. (On the pool: serial, this left one
    /// core idle for a moment of every tile.)
    pub(crate) fn core_points(&self, is_core: &[bool]) -> Vec<u32> {
        use rayon::prelude::*;
        (0..self.len() as u32).into_par_iter().filter(|&i| is_core[self.ids[i as usize] as usize]).collect()
    }

    /// The k-d tree over the points (built on first use: call it outside a parallel section
    /// to have a large tree built in parallel).
    pub(crate) fn index(&self) -> &Index {
        self.index.get_or_init(|| {
            let points: Vec<[f32; 3]> = self.pos.iter().map(|p| p.as_vec3().to_array()).collect();
            if self.parallel {
                Index::new_parallel(&points)
            } else {
                Index::new(&points)
            }
        })
    }

    /// Number of points.
    pub(crate) fn len(&self) -> usize {
        self.pos.len()
    }

    /// Local position of point `i` in f64.
    #[inline]
    pub(crate) fn at(&self, i: usize) -> DVec3 {
        self.pos[i]
    }

    /// The f32 radius around local position `q` that surely finds every point within `r`.
    fn radius32(&self, q: DVec3, r: f64) -> f32 {
        query_radius(r, self.slack.max(rounding_slack(q.abs().max_element())))
    }

    /// Number of points within `r` of local position `q` (membership decided in f64).
    pub(crate) fn count_within(&self, q: DVec3, r: f64, buf: &mut Vec<(u32, f32)>) -> usize {
        buf.clear();
        self.index().within(&q.as_vec3().to_array(), self.radius32(q, r), buf);
        buf.iter().filter(|a| self.pos[a.0 as usize].distance_squared(q) <= r * r).count()
    }

    /// Indices (and squared distances) of the points within `r` of local position `q`, or the
    /// `min` nearest where the ball holds fewer (sparse regions of unevenly sampled scans); at
    /// most about `max` of them, an even subsample of the ball when there are more.
    pub(crate) fn neighbours(&self, q: DVec3, r: f64, min: usize, max: usize, out: &mut Vec<(u32, f32)>) {
        self.neighbours_in(q, Neighbourhood { radius: r, reach: f64::INFINITY, min, max, ordered: true }, out)
    }

    /// As [`Cloud::neighbours`], for a neighbourhood `nb`: a sparse one is widened no farther
    /// than `nb.reach` (it may then hold fewer than `nb.min` points), and unless `nb.ordered`
    /// the points come in the tree's order when they need not be subsampled (for
    /// order-insensitive uses such as least-squares sums, where only the last bits can depend
    /// on it).
    pub(crate) fn neighbours_in(&self, q: DVec3, nb: Neighbourhood, out: &mut Vec<(u32, f32)>) {
        let Neighbourhood { radius: r, reach, min, max, ordered } = nb;
        out.clear();
        // Query the f32 tree a little wide, then decide membership in f64, so the ball holds
        // the same points wherever the tile's origin lies.
        self.index().within(&q.as_vec3().to_array(), self.radius32(q, r), out);
        let r2 = r * r;
        out.retain_mut(|a| {
            let d2 = self.pos[a.0 as usize].distance_squared(q);
            a.1 = d2 as f32;
            d2 <= r2
        });
        if out.len() < min {
            out.clear();
            // (A few more than `min` from the f32 tree: the f64 order of the nearest may differ.)
            self.index().nearest_n(&q.as_vec3().to_array(), min + 8, out);
            self.keep_nearest(q, r, reach, min, out);
        }
        self.order_and_thin(max, ordered, out);
    }

    /// Keeps the `min` points of `out` nearest to `q` (with their squared distances), ties
    /// broken by coordinate order. Quantised coordinates put points at exactly the same
    /// distance, and which of them a partial sort keeps depends on the order they came in,
    /// which depends on the tiling: on a 20 M-point scene, 1103 sparse points (fewer than
    /// `min` in the ball) got different neighbours, and so residuals, in 2 and in 16 tiles.
    /// Distances are compared rounded to a billionth of `r^2`, so that a tie stays a tie
    /// whatever the tile's local origin.
    fn keep_nearest(&self, q: DVec3, r: f64, reach: f64, min: usize, out: &mut Vec<(u32, f32)>) {
        let quantum = 1e-9 * r * r;
        let reach = reach.max(r);
        let mut keyed: Vec<(u64, (u32, f32))> = out
            .iter()
            .filter_map(|&(j, _)| {
                let d2 = self.pos[j as usize].distance_squared(q);
                (d2 <= reach * reach).then(|| ((d2 / quantum).round() as u64, (j, d2 as f32)))
            })
            .collect();
        let k = min.min(keyed.len());
        out.clear();
        if k == 0 {
            return;
        }
        if k == keyed.len() {
            out.extend(keyed.iter().map(|e| e.1));
            return;
        }
        // The k nearest by rounded distance; the points tied with the k-th (the only ones whose
        // choice the order could decide) are then taken in coordinate order. (Comparing
        // coordinates only for those is far cheaper than keying every point by them.)
        let cut = keyed.select_nth_unstable_by_key(k - 1, |e| e.0).1 .0;
        out.extend(keyed.iter().filter(|e| e.0 < cut).map(|e| e.1));
        let mut tied: Vec<(u32, f32)> = keyed.iter().filter(|e| e.0 == cut).map(|e| e.1).collect();
        let room = k - out.len();
        if tied.len() > room {
            tied.select_nth_unstable_by(room - 1, |a, b| self.coordinate_order(a.0, b.0));
        }
        out.extend_from_slice(&tied[..room]);
    }

    /// Builds the coordinate ranks (see `rank`) ahead of a parallel pass that orders the
    /// neighbourhoods of `queries` points, if that many pay for ranking the whole cloud; call
    /// it outside any parallel section. Without the ranks, neighbourhoods are ordered by
    /// comparing coordinates, in the same order.
    pub(crate) fn prepare_ordering(&self, queries: usize) {
        if queries * 64 >= self.len() {
            self.rank.get_or_init(|| self.ranks());
        }
    }

    fn ranks(&self) -> Vec<u32> {
        use rayon::prelude::*;
        if let Some(cells) = &self.cells {
            // A gridded cloud is stored slab by slab (cells of one x), and a point of a later
            // slab has no smaller x (the cell of x is monotone in x): sorting each slab on its
            // own gives the same order, in pieces that stay in cache.
            let slabs = cells.slabs();
            return slabs
                .par_iter()
                .flat_map_iter(|run| {
                    let mut order: Vec<(([i64; 3], u64), u32)> = run.clone().map(|i| (self.order_key(i as u32), i as u32)).collect();
                    order.sort_unstable();
                    let mut rank = vec![0u32; order.len()];
                    for (k, o) in order.iter().enumerate() {
                        rank[o.1 as usize - run.start] = (run.start + k) as u32;
                    }
                    rank
                })
                .collect();
        }
        // Sorted by value, not through the index: comparing the keys in place is several
        // times cheaper.
        let mut order: Vec<(([i64; 3], u64), u32)> = (0..self.len() as u32).into_par_iter().map(|i| (self.order_key(i), i)).collect();
        order.par_sort_unstable();
        let mut rank = vec![0u32; order.len()];
        for (k, o) in order.iter().enumerate() {
            rank[o.1 as usize] = k as u32;
        }
        rank
    }

    /// Point `i`'s key in coordinate order: x, then y, then z (as `f64::total_cmp` orders
    /// them), then global id.
    fn order_key(&self, i: u32) -> ([i64; 3], u64) {
        let key = |x: f64| {
            let b = x.to_bits() as i64;
            b ^ (((b >> 63) as u64) >> 1) as i64
        };
        (self.pos[i as usize].to_array().map(key), self.gid[i as usize])
    }

    /// Points by x, then y, then z, then global id.
    fn coordinate_order(&self, a: u32, b: u32) -> std::cmp::Ordering {
        self.order_key(a).cmp(&self.order_key(b))
    }

    /// Neighbours in coordinate order: every fit, subsample and choice over them is then the
    /// same whatever the tiling, the thread count, or how the points were split into files.
    /// With `ordered` false the order is left alone unless the set must be thinned to `max`.
    fn order_and_thin(&self, max: usize, ordered: bool, out: &mut Vec<(u32, f32)>) {
        if !ordered && out.len() <= max {
            return;
        }
        match self.rank.get() {
            Some(rank) => {
                // (Sorting packed keys, rank then position, is cheaper than comparing through
                // the rank table; ranks are distinct, so the order is the same.)
                let mut keys: Vec<u64> = out.iter().enumerate().map(|(k, a)| u64::from(rank[a.0 as usize]) << 32 | k as u64).collect();
                keys.sort_unstable();
                *out = keys.iter().map(|&k| out[(k & 0xFFFF_FFFF) as usize]).collect();
            }
            None => out.sort_unstable_by(|a, b| self.coordinate_order(a.0, b.0)),
        }
        if out.len() > max {
            let stride = out.len().div_ceil(max);
            let mut k = 0;
            out.retain(|_| {
                k += 1;
                (k - 1) % stride == 0
            });
        }
    }

    /// Sets `list` to every point within `r` of local position `c` (and a few just beyond), and
    /// `coords` to their positions, side by side once: every position of a block scans them.
    fn gather(&self, c: DVec3, r: f64, list: &mut Vec<(u32, f32)>, coords: &mut Coords) {
        list.clear();
        match &self.cells {
            Some(cells) => {
                coords.clear();
                // (A little wide: membership is decided for each position of the block.)
                let r = r * (1.0 + 1e-9) + self.slack;
                cells.runs(c, r, |run| {
                    list.extend(run.clone().map(|j| (j as u32, 0.0)));
                    coords.extend(&self.pos[run]);
                });
                coords.keep_within(c, r * r, list);
            }
            None => {
                self.index().within(&c.as_vec3().to_array(), self.radius32(c, r), list);
                coords.fill(list.iter().map(|&(j, _)| self.pos[j as usize]));
            }
        }
    }

    /// Runs `f` on the neighbourhood (as [`Cloud::neighbours_in`] gives it) of every point in
    /// `which`, in parallel, returning the results in the order of `which` (see
    /// [`Cloud::map_neighbourhoods_at`]).
    pub(crate) fn map_neighbourhoods<T: Send + Default, S>(
        &self,
        which: &[u32],
        nb: Neighbourhood,
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, u32, &[(u32, f32)]) -> T + Sync + Send,
    ) -> Vec<T> {
        let at: Vec<DVec3> = which.iter().map(|&i| self.pos[i as usize]).collect();
        self.map_neighbourhoods_at(&at, nb, init, |s, k, buf| f(s, which[k as usize], buf))
    }

    /// The positions `at` keyed by the block they fall in (see
    /// [`Cloud::map_neighbourhoods_at`]), sorted by block.
    fn block_order(&self, at: &[DVec3], r: f64) -> Vec<(u64, u32)> {
        use rayon::prelude::*;
        // Positions by block key. (A gridded cloud's own points come in key order already: then
        // nothing is sorted, and the results come out in order.)
        let mut order: Vec<(u64, u32)> = match &self.cells {
            Some(cells) => at.par_iter().enumerate().map(|(k, &q)| (cells.key(q), k as u32)).collect(),
            None => {
                let cell = |q: DVec3| crate::grid::cell(q, BLOCK_CELL * r).to_array();
                let mut by: Vec<([i64; 3], u32)> = at.iter().enumerate().map(|(k, &q)| (cell(q), k as u32)).collect();
                by.par_sort_unstable();
                let mut id = 0u64;
                by.iter()
                    .enumerate()
                    .map(|(n, o)| {
                        id += (n > 0 && o.0 != by[n - 1].0) as u64;
                        (id, o.1)
                    })
                    .collect()
            }
        };
        if !order.windows(2).all(|w| w[0] < w[1]) {
            order.par_sort_unstable();
        }
        order
    }

    /// Runs `f` on the neighbourhood (as [`Cloud::neighbours_in`] gives it) of every local
    /// position in `at`, in parallel, passing its index in `at` and returning the results in
    /// that order. The positions are taken in blocks, those in one cell of a grid (the cloud's,
    /// if gridded; else one whose cells are 1.5 ball radii wide, `BLOCK_CELL`): the points
    /// within reach of all of a block's positions are gathered once (from the grid, or by one
    /// tree query), then each position's ball is cut from that list; a sparse ball is widened
    /// from a second, wider list of the block (gathered once, for the first that needs it).
    /// This gives the same sets as a query per position at a fraction of the cost.
    pub(crate) fn map_neighbourhoods_at<T: Send + Default, S>(
        &self,
        at: &[DVec3],
        nb: Neighbourhood,
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, u32, &[(u32, f32)]) -> T + Sync + Send,
    ) -> Vec<T> {
        use rayon::prelude::*;
        let Neighbourhood { radius: r, reach: cap, min, max, ordered } = nb;
        let cap = cap.max(r);
        if ordered {
            self.prepare_ordering(at.len());
        }
        let order = self.block_order(at, r);
        let in_order = order.windows(2).all(|w| w[0].1 < w[1].1);
        let blocks = split_blocks(&order);
        let mut done: Vec<(u32, T)> = blocks
            .par_iter()
            .map_init(
                || (init(), Vec::new(), Coords::default(), Vec::new(), Vec::new(), (Vec::new(), Coords::default())),
                |(state, block, bpos, out, d2s, (wide, wpos)), chunk| {
                    if self.cancel.as_ref().is_some_and(|c| c.is_set()) {
                        return chunk.iter().map(|&(_, k)| (k, T::default())).collect::<Vec<_>>();
                    }
                    let (c, b) = centre_and_radius(chunk, at);
                    // (A grid holds every block's points; a tree query for a wide block would
                    // return too long a list.)
                    let blocked = self.cells.is_some() || b <= BLOCK_CELL * r;
                    if blocked {
                        self.gather(c, r + b, block, bpos);
                    }
                    // The wider list a sparse neighbourhood is cut from: every point within
                    // `cap` of any position of the block, gathered for the first that needs it.
                    let mut wide_ready = false;
                    chunk
                        .iter()
                        .map(|&(_, k)| {
                            let q = at[k as usize];
                            if !blocked {
                                self.neighbours_in(q, nb, out);
                                return (k, f(state, k, out));
                            }
                            // The block list holds every point within `reach` of q.
                            bpos.within(block, q, -1.0, r * r, out);
                            if out.len() < min {
                                // The nearest `min`, from the list if it surely holds them
                                // (those beyond the ball, up to `reach`, are added in the
                                // list's order, as if they had been gathered in one pass; never
                                // beyond `cap`).
                                let reach = (r + b - q.distance(c)).min(cap);
                                bpos.within(block, q, r * r, reach * reach, d2s);
                                out.append(d2s);
                                if out.len() < min && reach < cap {
                                    if !cap.is_finite() {
                                        self.neighbours_in(q, nb, out);
                                        return (k, f(state, k, out));
                                    }
                                    // (One more tree query for the block, instead of two, a
                                    // ball and the nearest, for each sparse position.)
                                    if !wide_ready {
                                        self.gather(c, b + cap, wide, wpos);
                                        wide_ready = true;
                                    }
                                    wpos.within(wide, q, -1.0, cap * cap, out);
                                }
                                self.keep_nearest(q, r, cap, min, out);
                            }
                            self.order_and_thin(max, ordered, out);
                            (k, f(state, k, out))
                        })
                        .collect::<Vec<_>>()
                },
            )
            .flatten_iter()
            .collect();
        if !in_order {
            done.par_sort_unstable_by_key(|d| d.0);
        }
        done.into_iter().map(|d| d.1).collect()
    }
}

/// The blocks of [`Cloud::map_neighbourhoods_at`]: runs of `order` (cell, position) in one
/// cell, at most [`MAX_BLOCK`] positions each.
fn split_blocks(order: &[(u64, u32)]) -> Vec<&[(u64, u32)]> {
    let mut blocks = Vec::new();
    let mut rest = order;
    while !rest.is_empty() {
        let n = rest.iter().take(MAX_BLOCK).take_while(|o| o.0 == rest[0].0).count();
        blocks.push(&rest[..n]);
        rest = &rest[n..];
    }
    blocks
}

/// The mean of the positions of a block (numbers into `at`) and their largest distance from it.
fn centre_and_radius(block: &[(u64, u32)], at: &[DVec3]) -> (DVec3, f64) {
    let c = block.iter().map(|o| at[o.1 as usize]).sum::<DVec3>() / block.len() as f64;
    (c, block.iter().map(|o| at[o.1 as usize].distance(c)).fold(0.0, f64::max))
}

/// A grid of cubic cells over a cloud's local coordinates (which are non-negative): the
/// sorted keys of the cells that hold points, and where each one's points start, the points
/// being stored cell by cell. Cells are keyed x, then y, then z, so the cells of one column
/// (x, y) over a range of z hold one run of points.
struct Cells {
    side: f64,
    /// Largest cell coordinate on any axis (coordinates beyond are clamped to it).
    last: i64,
    keys: Vec<u64>,
    /// Index of each cell's first point, and one past the last point of the last cell.
    start: Vec<u32>,
}

impl Cells {
    /// Cell coordinates take 21 bits each in a key.
    const BITS: u32 = 21;

    /// An empty grid of cells of side `side` (widened if need be so that `extent` spans no
    /// more cells than a key holds).
    fn new(side: f64, extent: f64) -> Cells {
        let most = ((1i64 << Self::BITS) - 1) as f64;
        let side = side.max(extent / most).max(f64::MIN_POSITIVE);
        Cells { side, last: (1 << Self::BITS) - 1, keys: Vec::new(), start: Vec::new() }
    }

    /// Cell coordinates of local position `q`, clamped to the grid.
    fn cell(&self, q: DVec3) -> [i64; 3] {
        crate::grid::cell(q, self.side).to_array().map(|c| c.clamp(0, self.last))
    }

    fn pack(c: [i64; 3]) -> u64 {
        (c[0] as u64) << (2 * Self::BITS) | (c[1] as u64) << Self::BITS | c[2] as u64
    }

    /// Key of the cell holding local position `q`.
    fn key(&self, q: DVec3) -> u64 {
        Self::pack(self.cell(q))
    }

    /// Records the cells of points stored with these (sorted) keys.
    fn index(&mut self, sorted: impl Iterator<Item = u64>) {
        let mut n = 0u32;
        for k in sorted {
            if self.keys.last() != Some(&k) {
                self.keys.push(k);
                self.start.push(n);
            }
            n += 1;
        }
        self.start.push(n);
    }

    /// The runs of points (ranges of stored indices) with the same x cell, in order.
    fn slabs(&self) -> Vec<std::ops::Range<usize>> {
        let mut out: Vec<std::ops::Range<usize>> = Vec::new();
        for (k, &key) in self.keys.iter().enumerate() {
            let (a, b) = (self.start[k] as usize, self.start[k + 1] as usize);
            match out.last_mut() {
                Some(last) if self.keys[k - 1] >> (2 * Self::BITS) == key >> (2 * Self::BITS) => last.end = b,
                _ => out.push(a..b),
            }
        }
        out
    }

    /// Calls `f` with each run of points (as a range of stored indices) in the cells that
    /// meet the box of half-side `r` around `c`, column by column.
    fn runs(&self, c: DVec3, r: f64, mut f: impl FnMut(std::ops::Range<usize>)) {
        let (lo, hi) = (self.cell(c - DVec3::splat(r)), self.cell(c + DVec3::splat(r)));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                let (first, end) = (Self::pack([x, y, lo[2]]), Self::pack([x, y, hi[2]]));
                let a = self.keys.partition_point(|&k| k < first);
                let mut b = a;
                while b < self.keys.len() && self.keys[b] <= end {
                    b += 1;
                }
                if b > a {
                    f(self.start[a] as usize..self.start[b] as usize);
                }
            }
        }
    }
}

/// The positions of a block's list of points, coordinate by coordinate: scanning them for
/// one ball is then a loop the compiler vectorises.
#[derive(Default)]
struct Coords {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    /// Squared distances to the current query.
    d2: Vec<f64>,
}

impl Coords {
    fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
    }

    fn extend(&mut self, pos: &[DVec3]) {
        self.x.extend(pos.iter().map(|p| p.x));
        self.y.extend(pos.iter().map(|p| p.y));
        self.z.extend(pos.iter().map(|p| p.z));
    }

    /// Squared distances from `q` of every position, into `d2`.
    fn distances(&mut self, q: DVec3) {
        self.d2.clear();
        self.d2.extend(self.x.iter().zip(&self.y).zip(&self.z).map(|((&x, &y), &z)| {
            let (dx, dy, dz) = (x - q.x, y - q.y, z - q.z);
            dx * dx + dy * dy + dz * dz
        }));
    }

    /// Keeps the positions (and the entries of `list`, whose positions they are) at squared
    /// distance at most `r2` from `q`, in order.
    fn keep_within(&mut self, q: DVec3, r2: f64, list: &mut Vec<(u32, f32)>) {
        self.distances(q);
        // (Branch-free, as in `within`.)
        let mut len = 0;
        for k in 0..self.d2.len() {
            let d2 = self.d2[k];
            (self.x[len], self.y[len], self.z[len]) = (self.x[k], self.y[k], self.z[k]);
            list[len] = (list[k].0, d2 as f32);
            len += (d2 <= r2) as usize;
        }
        for v in [&mut self.x, &mut self.y, &mut self.z] {
            v.truncate(len);
        }
        list.truncate(len);
    }

    fn fill(&mut self, pos: impl Iterator<Item = DVec3>) {
        self.clear();
        for p in pos {
            self.x.push(p.x);
            self.y.push(p.y);
            self.z.push(p.z);
        }
    }

    /// Sets `out` to the entries of `list` (whose positions these are) at squared distance
    /// from `q` above `lo2` (negative for none) and at most `hi2`, in list order.
    fn within(&mut self, list: &[(u32, f32)], q: DVec3, lo2: f64, hi2: f64, out: &mut Vec<(u32, f32)>) {
        let n = self.x.len();
        self.distances(q);
        // Branch-free compaction: every entry is written, and kept by advancing past it.
        out.clear();
        out.resize(n, (0, 0.0));
        let mut len = 0;
        for (&(j, _), &d2) in list[..n].iter().zip(&self.d2) {
            out[len] = (j, d2 as f32);
            len += (d2 > lo2 && d2 <= hi2) as usize;
        }
        out.truncate(len);
    }
}

/// Side of the grid cells whose points are gathered together, in ball radii. Larger cells take
/// fewer tree queries and longer lists to cut each ball from. (callgrind, 1.6 M scene, 1
/// thread: 0.5 -> 91.9 G instructions, 1 -> 81.2 G, 1.25 -> 80.0 G, 1.5 -> 79.6 G,
/// 2 -> 80.2 G, 2.5 -> 81.7 G; the curves are the same.)
const BLOCK_CELL: f64 = 1.5;

/// Most points taken together by [`Cloud::map_neighbourhoods`] (a dense cell is split).
const MAX_BLOCK: usize = 64;

/// What [`Cloud::map_neighbourhoods`] gathers around each point.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Neighbourhood {
    /// Ball radius.
    pub radius: f64,
    /// Widest a sparse neighbourhood is widened to (never narrower than the ball). A tile holds every point within its halo
    /// of its core, so a neighbourhood no wider than the halo is the same in every tiling;
    /// wider, it could reach past the halo and depend on where the tile borders fall.
    pub reach: f64,
    /// Fewest points: the nearest this many within `reach` where the ball holds fewer.
    pub min: usize,
    /// Most points: an even subsample of the ball where it holds more.
    pub max: usize,
    /// Points in coordinate order (otherwise in no particular order unless thinned).
    pub ordered: bool,
}

/// A cloud with its points thinned by a hash of their global ids to an eighth, a 64th, and
/// so on, for subsamples of balls far wider than the subsample (see
/// [`Thinned::neighbours`]): the same points in any tiling, found by querying a level that
/// holds a few times as many of the ball's points as are wanted, not the whole ball.
pub(crate) struct Thinned<'a> {
    cloud: &'a Cloud,
    /// Level k holds the points whose hash is below 2^64 / 8^(k+1) (densest first).
    levels: Vec<Cloud>,
}

/// The hash of a point's global id by which [`Thinned`] thins a cloud.
fn thinning_hash(gid: u64) -> u64 {
    crate::rng::Rng::new(gid ^ crate::salts::THINNED_LEVEL).next_u64()
}

/// Fewest points a level of [`Thinned`] holds.
const LEVEL_MIN: usize = 1024;

impl<'a> Thinned<'a> {
    /// The levels of `cloud`, their trees built, on the calling thread (no rayon job: see
    /// `statistics::sample_round`).
    pub(crate) fn new(cloud: &'a Cloud) -> Thinned<'a> {
        let mut levels = Vec::new();
        let below = |i: u32, k: u32| thinning_hash(cloud.gid[i as usize]) < u64::MAX >> (3 * k);
        let mut which: Vec<u32> = (0..cloud.len() as u32).filter(|&i| below(i, 1)).collect();
        for k in 2..=21 {
            if which.len() < LEVEL_MIN {
                break;
            }
            let level = cloud.subset(&which);
            level.index();
            levels.push(level);
            which.retain(|&i| below(i, k));
        }
        Thinned { cloud, levels }
    }

    /// The `max` points within `r` of local position `q` whose hashes are smallest (every
    /// point of the ball if it holds fewer), in coordinate order, as indices of the cloud with
    /// their squared distances: a uniform subsample, the same whichever level gave it.
    pub(crate) fn neighbours(&self, q: DVec3, r: f64, max: usize, out: &mut Vec<(u32, f32)>) {
        let nb = Neighbourhood { radius: r, reach: f64::INFINITY, min: 0, max: usize::MAX, ordered: false };
        // (From the sparsest level up: a level whose ball holds at least `max` points holds
        // every point of the ball with a smaller hash than its `max`th.)
        let mut found = false;
        for level in self.levels.iter().rev() {
            level.neighbours_in(q, nb, out);
            if out.len() >= max {
                for a in out.iter_mut() {
                    a.0 = level.ids[a.0 as usize];
                }
                found = true;
                break;
            }
        }
        if !found {
            self.cloud.neighbours_in(q, nb, out);
        }
        if out.len() > max {
            // (Each point's hash once: the selection compares each several times.)
            let mut keyed: Vec<(u64, u64, (u32, f32))> = out
                .iter()
                .map(|&a| {
                    let g = self.cloud.gid[a.0 as usize];
                    (thinning_hash(g), g, a)
                })
                .collect();
            keyed.select_nth_unstable_by_key(max - 1, |k| (k.0, k.1));
            out.clear();
            out.extend(keyed[..max].iter().map(|k| k.2));
        }
        self.cloud.order_and_thin(max, true, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The points as a tree-indexed cloud, and gridded with cells far narrower than, about as
    /// wide as, and far wider than a ball of radius `r`.
    fn clouds(world: &[DVec3], gids: &[u64], origin: DVec3, r: f64) -> Vec<Cloud> {
        let mut v = vec![Cloud::with_origin(world, gids, origin)];
        v.extend([0.3, 1.5, 4.0].map(|s| Cloud::gridded(world, gids, origin, s * r, false)));
        v
    }

    #[test]
    fn ordered_neighbourhoods_are_the_same_with_and_without_the_coordinate_ranks() {
        // A jittered grid with repeated coordinates (ties broken by global id), and a cell
        // dense enough that the ball must be thinned.
        let mut rng = crate::rng::Rng::stream(3, 0);
        let mut world: Vec<DVec3> = (0..4000).map(|_| DVec3::new(rng.f64(), rng.f64(), 0.01 * rng.f64()) * 10.0).collect();
        for k in 0..500 {
            world.push(world[k * 3]);
        }
        let gids: Vec<u64> = (0..world.len() as u64).rev().collect();
        for cloud in clouds(&world, &gids, DVec3::new(-1.0, -1.0, -1.0), 0.6) {
            let which: Vec<u32> = (0..cloud.len() as u32).step_by(7).collect();
            let plain: Vec<Vec<(u32, f32)>> = which
                .iter()
                .map(|&i| {
                    let mut out = Vec::new();
                    cloud.neighbours(cloud.at(i as usize), 0.6, 10, 40, &mut out);
                    out
                })
                .collect();
            assert!(cloud.rank.get().is_none());
            assert!(plain.iter().any(|b| b.len() == 40), "no ball was thinned");
            // map_neighbourhoods builds the ranks; the per-point queries above compared coordinates.
            let nb = Neighbourhood { radius: 0.6, reach: f64::INFINITY, min: 10, max: 40, ordered: true };
            let ranked = cloud.map_neighbourhoods(&which, nb, || (), |_, _, buf| buf.to_vec());
            assert!(cloud.rank.get().is_some());
            let ids = |v: &Vec<Vec<(u32, f32)>>| v.iter().map(|b| b.iter().map(|a| a.0).collect::<Vec<_>>()).collect::<Vec<_>>();
            assert_eq!(ids(&plain), ids(&ranked));
            for b in &plain {
                assert!(b.windows(2).all(|w| cloud.coordinate_order(w[0].0, w[1].0).is_lt()));
                // (The order itself, spelled out with total_cmp.)
                let by_cmp = |i: u32, j: u32| {
                    let (p, q) = (cloud.pos[i as usize], cloud.pos[j as usize]);
                    p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)).then(p.z.total_cmp(&q.z)).then(cloud.gid[i as usize].cmp(&cloud.gid[j as usize]))
                };
                assert!(b.windows(2).all(|w| by_cmp(w[0].0, w[1].0).is_lt()));
            }
        }
    }

    #[test]
    fn the_nearest_of_a_sparse_neighbourhood_do_not_depend_on_point_order_or_origin() {
        // Points on a unit grid (every distance ties with others), too sparse for the ball:
        // the nearest `min` are chosen among exactly tied candidates.
        let mut world = Vec::new();
        for x in 0..12 {
            for y in 0..12 {
                world.push(DVec3::new(500_000.0 + x as f64, 5_400_000.0 + y as f64, 100.0));
            }
        }
        let (r, min) = (1.5, 20);
        // (An unbounded reach widens each sparse ball on its own; a bounded one, as in a tile,
        // from one wider list per block.)
        for reach in [f64::INFINITY, 4.0] {
            let nearest = |pts: &[DVec3], origin: DVec3| -> Vec<Vec<[i64; 3]>> {
                let gids: Vec<u64> = pts.iter().map(|p| (p.x as u64) << 20 | (p.y as u64 & 0xFFFFF)).collect();
                let mut per_cloud = Vec::new();
                for cloud in clouds(pts, &gids, origin, r) {
                    let at: Vec<DVec3> =
                        (3..9).flat_map(|x| (3..9).map(move |y| DVec3::new(500_000.0 + x as f64 + 0.5, 5_400_000.0 + y as f64, 100.0))).collect();
                    let local: Vec<DVec3> = at.iter().map(|&q| q - origin).collect();
                    let key = |j: u32| (cloud.at(j as usize) + cloud.origin).round().as_i64vec3().to_array();
                    let nb = Neighbourhood { radius: r, reach, min, max: 100, ordered: true };
                    let mut blocked = cloud.map_neighbourhoods_at(&local, nb, || (), |_, _, buf| buf.iter().map(|a| key(a.0)).collect::<Vec<_>>());
                    for (q, b) in local.iter().zip(&mut blocked) {
                        let mut one = Vec::new();
                        cloud.neighbours_in(*q, nb, &mut one);
                        assert_eq!(one.iter().map(|a| key(a.0)).collect::<Vec<_>>(), *b, "query by query");
                        b.sort();
                    }
                    per_cloud.push(blocked);
                }
                assert!(per_cloud.iter().all(|b| *b == per_cloud[0]), "tree-indexed and gridded clouds differ");
                per_cloud.swap_remove(0)
            };
            let a = nearest(&world, DVec3::new(499_990.0, 5_399_990.0, 90.0));
            world.reverse();
            world.rotate_left(37);
            let b = nearest(&world, DVec3::new(499_999.25, 5_399_993.5, 99.75));
            assert!(a.iter().all(|v| v.len() == min));
            let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
            assert_eq!(differ, 0, "reach {reach}: {differ} of {} neighbourhoods differ", a.len());
        }
    }

    #[test]
    fn balls_hold_their_rim_points_far_from_the_origin() {
        // Points just inside (and just outside) a small ball a kilometre from the cloud's
        // origin, where f32 coordinates are rounded by far more than the ball's relative
        // margin: membership must still follow the f64 distances.
        let mut rng = crate::rng::Rng::stream(3, 0);
        let r = 0.1;
        let centres: Vec<DVec3> = (0..20).map(|k| DVec3::new(1000.0 + k as f64 * 0.731, 700.0 + k as f64 * 0.377, 50.0)).collect();
        let mut world = vec![DVec3::ZERO];
        for &c in &centres {
            for k in 0..200 {
                let d = rng.in_ball(1.0).normalize_or(DVec3::X);
                world.push(c + d * r * if k % 2 == 0 { 1.0 - 1e-9 } else { 1.0 + 1e-9 });
            }
        }
        let cloud = Cloud::new(&world);
        let mut buf = Vec::new();
        for &c in &centres {
            let q = c - cloud.origin;
            let truth = (0..cloud.len()).filter(|&i| cloud.at(i).distance_squared(q) <= r * r).count();
            assert_eq!(cloud.count_within(q, r, &mut buf), truth);
            cloud.neighbours(q, r, 0, usize::MAX, &mut buf);
            assert_eq!(buf.len(), truth);
        }
    }

    #[test]
    fn sparse_neighbourhoods_are_widened_no_farther_than_their_reach() {
        // A unit grid: a ball of radius 1.5 holds 9 points, the 20 nearest reach out to
        // sqrt(5), and within reach 2 there are 13 (the ring at distance 2 included). A reach
        // below the radius does not shrink the ball.
        let world: Vec<DVec3> = (0..144).map(|k| DVec3::new((k % 12) as f64, (k / 12) as f64, 0.0)).collect();
        let gids: Vec<u64> = (0..world.len() as u64).collect();
        for cloud in clouds(&world, &gids, DVec3::ZERO, 1.5) {
            let at: Vec<DVec3> = (4..8).flat_map(|x| (4..8).map(move |y| DVec3::new(x as f64, y as f64, 0.0))).collect();
            for (reach, count) in [(f64::INFINITY, 20), (2.0, 13), (1.0, 9)] {
                let nb = Neighbourhood { radius: 1.5, reach, min: 20, max: 100, ordered: true };
                let blocked = cloud.map_neighbourhoods_at(&at, nb, || (), |_, _, buf| buf.to_vec());
                for (q, b) in at.iter().zip(&blocked) {
                    let mut one = Vec::new();
                    cloud.neighbours_in(*q, nb, &mut one);
                    assert_eq!(&one, b, "reach {reach}: query by query and by blocks");
                    assert_eq!(b.len(), count, "reach {reach} at {q}");
                    assert!(b.iter().all(|a| (a.1 as f64) <= reach.max(1.5).powi(2) + 1e-9), "reach {reach} at {q}");
                }
            }
        }
    }

    /// A wide ball's thinned neighbours are the points of the ball with the smallest hashes,
    /// whichever level served them: the same as taken from the whole ball, and the same in a
    /// cloud holding only part of the points around (another tile), as long as it holds the
    /// ball.
    #[test]
    fn thinned_balls_take_the_smallest_hashes_whatever_level_serves_them() {
        let mut rng = crate::rng::Rng::stream(7, 0);
        let world: Vec<DVec3> = (0..120_000).map(|_| DVec3::new(rng.f64(), rng.f64(), 0.01 * rng.f64())).collect();
        let gids: Vec<u64> = (0..world.len() as u64).map(|g| g * 7 + 3).collect();
        let cloud = Cloud::with_origin(&world, &gids, DVec3::ZERO);
        let thinned = Thinned::new(&cloud);
        assert!(thinned.levels.len() >= 2, "{} levels", thinned.levels.len());
        // The left half of the points only, with another origin.
        let part: Vec<usize> = (0..world.len()).filter(|&k| world[k].x < 0.5).collect();
        let (pw, pg): (Vec<DVec3>, Vec<u64>) = part.iter().map(|&k| (world[k], gids[k])).unzip();
        let other = Cloud::with_origin(&pw, &pg, DVec3::new(-0.5, 0.25, -1.0));
        let other_thinned = Thinned::new(&other);
        let max = 128;
        let (mut out, mut all, mut theirs) = (Vec::new(), Vec::new(), Vec::new());
        let mut levels_used = std::collections::BTreeSet::new();
        let mut in_other = 0;
        for (k, r) in [(11, 0.02), (503, 0.05), (1999, 0.1), (7001, 0.2), (40_000, 0.12)] {
            let q = cloud.at(k);
            thinned.neighbours(q, r, max, &mut out);
            cloud.neighbours_in(q, Neighbourhood { radius: r, reach: f64::INFINITY, min: 0, max: usize::MAX, ordered: false }, &mut all);
            let mut expected: Vec<u64> = all.iter().map(|a| cloud.gid[a.0 as usize]).collect();
            expected.sort_unstable_by_key(|&g| (thinning_hash(g), g));
            expected.truncate(max);
            expected.sort_unstable();
            let mut got: Vec<u64> = out.iter().map(|a| cloud.gid[a.0 as usize]).collect();
            assert!(out.windows(2).all(|w| cloud.coordinate_order(w[0].0, w[1].0).is_lt()));
            got.sort_unstable();
            assert_eq!(got, expected, "ball {k} of radius {r}");
            levels_used.insert((all.len() / 8 >= max) as u8 + (all.len() / 64 >= max) as u8);
            let world_q = q + cloud.origin;
            if world_q.x + r < 0.5 {
                other_thinned.neighbours(world_q - other.origin, r, max, &mut theirs);
                let mut g: Vec<u64> = theirs.iter().map(|a| other.gid[a.0 as usize]).collect();
                g.sort_unstable();
                assert_eq!(g, got, "ball {k} in the other cloud");
                in_other += 1;
            }
        }
        assert!(levels_used.len() >= 3, "levels used: {levels_used:?}");
        assert!(in_other >= 1, "no ball lay in the other cloud");
    }
}
