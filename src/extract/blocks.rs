//! Growth blocks: the curve stage's own partition of space, so that stages 3 and 4 run a
//! block at a time in bounded memory.
//!
//! The blocks are cubes on a grid anchored at the run's origin and sized in polyline steps,
//! split in eight where they hold too many edge points. Both depend on the edge cloud alone,
//! never on the processing tiles, so the curves stay the same, to the byte, whatever the
//! tiling. Each block grows polylines from the edge points of its core, on through a halo
//! around it, and keeps the parts inside its core ([`cut`]): pieces whose ends at the core's
//! border are joined to the neighbours' by [`super::stitch`].

use glam::DVec3;
use std::collections::{BTreeMap, HashMap};

/// Side of a base block, in polyline steps. (On the 500 k-point quality clouds one or a few
/// blocks; on large scans big enough that few polylines cross a border.)
pub const BASE_STEPS: f64 = 128.0;
/// A block holding more edge points than this is split in eight...
pub(crate) const MAX_EDGE_POINTS: u64 = 250_000;
/// ...at most this many times (the smallest block is 16 steps across, twice the reach of its
/// halo and context).
pub(crate) const MAX_SPLITS: u32 = 3;
/// How far past a block's core its polylines are grown, in steps, before they are cut: the
/// growing inside the core depends only on the edge points within a step or two of it.
pub(crate) const HALO_STEPS: f64 = 4.0;

/// A block: the half-open box `[lo, hi)`, relative to the run's origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Block {
    /// Low corner (inside).
    pub lo: DVec3,
    /// High corner (outside).
    pub hi: DVec3,
    /// The census cells it covers, `[low, high)` along each axis.
    cells: [[i64; 3]; 2],
}

impl Block {
    /// True if `p` lies in the block's core.
    pub(crate) fn contains(&self, p: DVec3) -> bool {
        p.cmpge(self.lo).all() && p.cmplt(self.hi).all()
    }

    /// The block's box grown by `m` on every side, closed.
    pub(crate) fn around(&self, m: f64) -> (DVec3, DVec3) {
        (self.lo - DVec3::splat(m), self.hi + DVec3::splat(m))
    }
}

/// True if `p` lies in the closed box `b`.
pub(crate) fn in_box(b: (DVec3, DVec3), p: DVec3) -> bool {
    p.cmpge(b.0).all() && p.cmple(b.1).all()
}

/// Edge points counted per cell of the finest block size, as the plan needs them.
#[derive(Clone, Debug, Default)]
pub(crate) struct Census {
    fine: f64,
    counts: HashMap<[i64; 3], u64>,
}

impl Census {
    /// An empty census for base blocks `side` across (by default [`BASE_STEPS`] polyline
    /// steps).
    pub(crate) fn new(side: f64) -> Census {
        Census { fine: side / (1u64 << MAX_SPLITS) as f64, counts: HashMap::new() }
    }

    /// Side of the census cells (and of the smallest blocks).
    pub(crate) fn cell_side(&self) -> f64 {
        self.fine
    }

    /// Counts an edge point at `p` (relative to the origin).
    pub(crate) fn add(&mut self, p: DVec3) {
        *self.counts.entry(cell(p, self.fine)).or_default() += 1;
    }

    /// Adds another census's counts.
    pub(crate) fn merge(&mut self, other: Census) {
        for (c, n) in other.counts {
            *self.counts.entry(c).or_default() += n;
        }
    }
}

/// How the edge points lie across a census cell along each axis, a polyline step at a time, so
/// that the blocks' borders can be put where they are fewest: a crease that runs along a
/// border, within a step of it, is traced on both sides and cut into many short pieces. (CAD
/// parts put their creases in a few planes, all at round coordinates; a scan's facades and
/// curbs put many in one.)
#[derive(Clone, Debug)]
pub(crate) struct Layers {
    cell: f64,
    bins: [Vec<u64>; 3],
}

impl Layers {
    /// Empty layers across census cells of side `cell` (see [`Census::cell_side`]), in bins
    /// of about `step`.
    pub(crate) fn new(cell: f64, step: f64) -> Layers {
        let n = (cell / step).round().clamp(1.0, 1024.0) as usize;
        Layers { cell, bins: [vec![0; n], vec![0; n], vec![0; n]] }
    }

    /// Counts an edge point at `p` (relative to a fixed anchor).
    pub(crate) fn add(&mut self, p: DVec3) {
        let n = self.bins[0].len();
        for k in 0..3 {
            let b = ((p[k] / self.cell).rem_euclid(1.0) * n as f64) as usize;
            self.bins[k][b.min(n - 1)] += 1;
        }
    }

    /// Adds other layers' counts.
    pub(crate) fn merge(&mut self, other: &Layers) {
        for k in 0..3 {
            self.bins[k].iter_mut().zip(&other.bins[k]).for_each(|(a, b)| *a += b);
        }
    }

    /// Where the borders go, relative to the anchor, along each axis: the middle of the bin
    /// that has the fewest edge points within a bin of it (the first of equals), less a whole
    /// cell, so that the anchor lies inside the first cell.
    pub(crate) fn borders(&self) -> DVec3 {
        let n = self.bins[0].len();
        let w = self.cell / n as f64;
        let at = |k: usize| {
            let near = |b: usize| self.bins[k][(b + n - 1) % n] + self.bins[k][b] + if n > 1 { self.bins[k][(b + 1) % n] } else { 0 };
            let b = (0..n).min_by_key(|&b| (near(b), b)).unwrap_or(0);
            (b as f64 + 0.5) * w - self.cell
        };
        DVec3::new(at(0), at(1), at(2))
    }
}

fn cell(p: DVec3, side: f64) -> [i64; 3] {
    (p / side).floor().to_array().map(|x| x as i64)
}

/// The blocks of a run, in a fixed order, with a lookup by position.
#[derive(Clone, Debug, Default)]
pub(crate) struct Blocks {
    base: f64,
    fine: f64,
    /// The blocks, in order.
    pub list: Vec<Block>,
    by_base: HashMap<[i64; 3], Vec<u32>>,
}

/// Plans the blocks over the edge points counted in `census`: a base block for each base cell
/// that holds edge points, split in eight while it holds more than [`MAX_EDGE_POINTS`] (at most
/// [`MAX_SPLITS`] times), in the order of their cells.
pub(crate) fn plan(census: &Census) -> Blocks {
    let mut cells: BTreeMap<[i64; 3], Vec<([i64; 3], u64)>> = BTreeMap::new();
    for (&c, &n) in &census.counts {
        cells.entry(c.map(|x| x.div_euclid(1 << MAX_SPLITS))).or_default().push((c, n));
    }
    let mut spans = vec![];
    for (b, mut fine) in cells {
        fine.sort_unstable();
        split(0, b, &fine, &mut spans);
    }
    Blocks::from_cells(census.fine, spans)
}

/// Splits the cell `c` of split level `level` holding the fine cells `fine` (sorted) into
/// blocks, given by the census cells they cover.
fn split(level: u32, c: [i64; 3], fine: &[([i64; 3], u64)], out: &mut Vec<[[i64; 3]; 2]>) {
    let total: u64 = fine.iter().map(|f| f.1).sum();
    if total <= MAX_EDGE_POINTS || level == MAX_SPLITS {
        let span = 1i64 << (MAX_SPLITS - level);
        out.push([c.map(|x| x * span), c.map(|x| (x + 1) * span)]);
        return;
    }
    let shift = MAX_SPLITS - level - 1;
    let mut children: BTreeMap<[i64; 3], Vec<([i64; 3], u64)>> = BTreeMap::new();
    for &(f, n) in fine {
        children.entry(f.map(|x| x >> shift)).or_default().push((f, n));
    }
    for (child, fine) in children {
        split(level + 1, child, &fine, out);
    }
}

impl Blocks {
    /// The blocks covering the census cells (of side `fine`) `cells`, each `[low, high)` along
    /// each axis, in that order: the inverse of [`Blocks::cells`].
    pub(crate) fn from_cells(fine: f64, cells: Vec<[[i64; 3]; 2]>) -> Blocks {
        let corner = |c: [i64; 3]| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * fine;
        let mut out = Blocks { base: fine * (1u64 << MAX_SPLITS) as f64, fine, ..Default::default() };
        for (k, c) in cells.into_iter().enumerate() {
            out.by_base.entry(c[0].map(|x| x.div_euclid(1 << MAX_SPLITS))).or_default().push(k as u32);
            out.list.push(Block { lo: corner(c[0]), hi: corner(c[1]), cells: c });
        }
        out
    }

    /// The side of the census cells and the cells each block covers: what
    /// [`Blocks::from_cells`] rebuilds the same blocks from.
    pub(crate) fn cells(&self) -> (f64, Vec<[[i64; 3]; 2]>) {
        (self.fine, self.list.iter().map(|b| b.cells).collect())
    }

    /// The block that owns the edge point at `p`: the one whose census cells hold it. (Every
    /// edge point counted in the census has one, whatever the rounding of the blocks' boxes.)
    pub(crate) fn owner(&self, p: DVec3) -> Option<u32> {
        let c = cell(p, self.fine);
        let base = c.map(|x| x.div_euclid(1 << MAX_SPLITS));
        let held = |b: &Block| (0..3).all(|k| b.cells[0][k] <= c[k] && c[k] < b.cells[1][k]);
        self.by_base.get(&base)?.iter().copied().find(|&k| held(&self.list[k as usize]))
    }

    /// The blocks whose box meets the closed box `[lo, hi]`, in order.
    pub(crate) fn meeting(&self, lo: DVec3, hi: DVec3) -> Vec<u32> {
        let (a, b) = (cell(lo, self.base), cell(hi, self.base));
        let mut out = vec![];
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    for &k in self.by_base.get(&[x, y, z]).map_or(&[][..], |v| &v[..]) {
                        let k_box = &self.list[k as usize];
                        if k_box.lo.cmple(hi).all() && k_box.hi.cmpge(lo).all() {
                            out.push(k);
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// The blocks in slabs, one layer of base cells each, across the axis along which they
    /// spread over the most base cells (the first of equals): the axis, and the slabs in order
    /// along it, each its blocks in order.
    pub(crate) fn slabs(&self) -> (usize, Vec<Vec<u32>>) {
        let layer = |b: &Block, k: usize| b.cells[0][k].div_euclid(1 << MAX_SPLITS);
        let spread = |k: usize| self.list.iter().map(|b| layer(b, k)).collect::<std::collections::BTreeSet<_>>().len();
        let axis = (0..3).max_by_key(|&k| (spread(k), std::cmp::Reverse(k))).unwrap_or(0);
        let mut slabs: BTreeMap<i64, Vec<u32>> = BTreeMap::new();
        for (k, b) in self.list.iter().enumerate() {
            slabs.entry(layer(b, axis)).or_default().push(k as u32);
        }
        (axis, slabs.into_values().collect())
    }

    /// The least that any piece grown in the blocks `slab` (see [`Blocks::slabs`]) may hold
    /// along `axis`: their lowest side less the growth halo `halo` (infinity for no blocks).
    pub(crate) fn reach_below(&self, slab: &[u32], axis: usize, halo: f64) -> f64 {
        slab.iter().map(|&b| self.list[b as usize].lo[axis]).fold(f64::INFINITY, f64::min) - halo
    }

    /// The block whose core holds `p`, else the first whose box grown by `m` holds it. (Smoothed
    /// edge points, and polylines through them, may lie a little outside every block's core,
    /// at the edge cloud's fringes.)
    pub(crate) fn find(&self, p: DVec3, m: f64) -> Option<u32> {
        let near = self.meeting(p - DVec3::splat(m), p + DVec3::splat(m));
        near.iter().copied().find(|&k| self.list[k as usize].contains(p)).or_else(|| near.first().copied())
    }
}

/// A part of a grown polyline inside one block's core.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Piece {
    /// Vertices, all inside the core.
    pub v: Vec<DVec3>,
    /// Where the polyline crossed the core's border at each end, if it did (else the end is
    /// an end of the polyline).
    pub ends: [Option<DVec3>; 2],
    /// A closed polyline wholly inside the core.
    pub closed: bool,
}

/// The parts of the polyline through `v` (closed if `closed`) that `block` owns (`owns`: its
/// core, and near it whatever lies in no block's core, see [`Blocks::find`]).
pub(crate) fn cut(v: &[DVec3], closed: bool, block: &Block, owns: impl Fn(DVec3) -> bool) -> Vec<Piece> {
    let inside: Vec<bool> = v.iter().map(|&p| owns(p)).collect();
    if inside.iter().all(|&x| x) {
        return vec![Piece { v: v.to_vec(), ends: [None, None], closed }];
    }
    // A closed polyline is cut open at a vertex outside, which then ends it on both sides.
    let v: Vec<DVec3> = match (closed, inside.iter().position(|&x| !x)) {
        (true, Some(k)) => v[k..].iter().chain(&v[..=k]).copied().collect(),
        _ => v.to_vec(),
    };
    let inside: Vec<bool> = v.iter().map(|&p| owns(p)).collect();
    let mut out = vec![];
    let mut i = 0;
    while i < v.len() {
        if !inside[i] {
            i += 1;
            continue;
        }
        let start = i;
        while i < v.len() && inside[i] {
            i += 1;
        }
        let ends = [(start > 0).then(|| crossing(v[start], v[start - 1], block)), (i < v.len()).then(|| crossing(v[i - 1], v[i], block))];
        out.push(Piece { v: v[start..i].to_vec(), ends, closed: false });
    }
    out
}

/// Where the segment from `a` (inside the block) to `b` (outside) leaves the block's box.
fn crossing(a: DVec3, b: DVec3, block: &Block) -> DVec3 {
    let d = b - a;
    let mut t = 1.0f64;
    for k in 0..3 {
        if d[k] > 0.0 {
            t = t.min((block.hi[k] - a[k]) / d[k]);
        } else if d[k] < 0.0 {
            t = t.min((block.lo[k] - a[k]) / d[k]);
        }
    }
    a + d * t.clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> Block {
        Block { lo: DVec3::ZERO, hi: DVec3::ONE, cells: [[0; 3], [1; 3]] }
    }

    #[test]
    fn a_polyline_is_cut_at_the_core_border_with_its_crossings() {
        let x = |x: f64| DVec3::new(x, 0.5, 0.5);
        let pieces = cut(&[x(-0.5), x(0.25), x(0.75), x(1.5), x(2.0)], false, &unit(), |p| unit().contains(p));
        assert_eq!(pieces.len(), 1);
        assert_eq!(pieces[0].v, vec![x(0.25), x(0.75)]);
        assert_eq!(pieces[0].ends, [Some(x(0.0)), Some(x(1.0))]);
        // Out and back in: two pieces; a polyline inside keeps its free ends.
        let y = |x: f64, y: f64| DVec3::new(x, y, 0.5);
        let pieces = cut(&[y(0.5, 0.5), y(0.5, 1.5), y(0.7, 0.5)], false, &unit(), |p| unit().contains(p));
        assert_eq!(pieces.iter().map(|p| p.ends).collect::<Vec<_>>(), vec![[None, Some(y(0.5, 1.0))], [Some(y(0.6, 1.0)), None]]);
        assert_eq!(cut(&[x(0.2), x(0.4)], false, &unit(), |p| unit().contains(p))[0].ends, [None, None]);
    }

    #[test]
    fn a_closed_polyline_leaving_the_core_is_cut_open_outside() {
        let p = |x: f64, y: f64| DVec3::new(x, y, 0.5);
        // A square loop whose right side lies outside the block.
        let pieces = cut(&[p(0.2, 0.2), p(1.2, 0.2), p(1.2, 0.8), p(0.2, 0.8)], true, &unit(), |p| unit().contains(p));
        assert_eq!(pieces.len(), 1);
        assert_eq!(pieces[0].v, vec![p(0.2, 0.8), p(0.2, 0.2)]);
        assert_eq!(pieces[0].ends, [Some(p(1.0, 0.8)), Some(p(1.0, 0.2))]);
        assert!(!pieces[0].closed);
    }

    #[test]
    fn borders_go_where_edge_points_are_fewest() {
        let mut layers = Layers::new(16.0, 1.0);
        // Creases in the planes x = 0 and x = 40 (bins 0 and 8); along y and z everywhere.
        for i in 0..1000 {
            let t = i as f64 * 0.16;
            layers.add(DVec3::new(if i % 2 == 0 { 0.2 } else { 40.3 }, t, t));
        }
        let b = layers.borders();
        assert_eq!(b.x, 2.5 - 16.0, "the middle of the first bin a bin away from both planes");
        assert!(b.y > -16.0 && b.y < 0.0);
    }

    #[test]
    fn crowded_blocks_are_split_and_found_by_position() {
        let mut census = Census::new(128.0);
        // Base blocks of 128, census cells of 16; one crowded corner.
        for i in 0..(MAX_EDGE_POINTS + 1) {
            census.add(DVec3::new(1.0 + (i % 7) as f64 * 0.1, 1.0, 1.0));
        }
        census.add(DVec3::new(100.0, 100.0, 100.0));
        let blocks = plan(&census);
        assert_eq!(blocks.list.len(), 2, "{:?}", blocks.list);
        // The crowded eighth is split down to the smallest block; its empty siblings are none.
        assert_eq!((blocks.list[0].lo, blocks.list[0].hi), (DVec3::ZERO, DVec3::splat(16.0)));
        assert_eq!((blocks.list[1].lo, blocks.list[1].hi), (DVec3::splat(64.0), DVec3::splat(128.0)));
        assert_eq!(blocks.owner(DVec3::new(1.5, 1.0, 1.0)), Some(0));
        assert_eq!(blocks.owner(DVec3::splat(127.0)), Some(1));
        assert_eq!(blocks.owner(DVec3::splat(20.0)), None);
        assert_eq!(blocks.find(DVec3::splat(70.0), 0.0), Some(1));
        assert_eq!(blocks.find(DVec3::new(17.0, 10.0, 10.0), 0.0), None);
        assert_eq!(blocks.find(DVec3::new(17.0, 10.0, 10.0), 1.5), Some(0));
        assert_eq!(blocks.meeting(DVec3::splat(10.0), DVec3::splat(65.0)), vec![0, 1]);
    }

    #[test]
    fn far_edge_points_make_two_blocks() {
        use crate::extract::blocks::{plan, Census};
        use glam::DVec3;

        let mut census = Census::new(128.0);
        census.add(DVec3::new(1.0, 2.0, 3.0));
        census.add(DVec3::new(200.0, 2.0, 3.0));
        let blocks = plan(&census);
        assert_eq!(blocks.list.len(), 2);
        assert!(blocks.list[0].contains(DVec3::new(1.0, 2.0, 3.0)));
    }

    #[test]
    fn slabs_go_across_the_widest_spread() {
        use crate::extract::blocks::{plan, Census};
        use glam::DVec3;

        let mut census = Census::new(1.0);
        for (y, z) in [(0.5, 0.5), (0.5, 1.5), (3.5, 0.5)] {
            census.add(DVec3::new(0.5, y, z));
        }
        let (axis, slabs) = plan(&census).slabs();
        assert_eq!(axis, 1);
        assert_eq!(slabs, vec![vec![0, 1], vec![2]]);
    }
}
