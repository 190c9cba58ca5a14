//! Far points: a few stray points far from the rest of a cloud (a reflection off a distant
//! object, a corrupt record at 1e20) would set its bounds, and with them the tile grid and the
//! quantum of the position keys; one point at 1e20 put a small part's every point in one tile
//! and under one key. They are found while the points are bucketed, left out, and the grid is
//! planned again over the rest.
//!
//! A group of points at either end of an axis is far when it is small (at most [`far_budget`]
//! points) and the gap between it and the rest along that axis is wider than the rest of the
//! cloud is wide (its largest extent once the same small number of points is set aside at
//! each end of each axis). Sparse parts of a real scene, a tower over flat ground or a wire,
//! lie closer to the rest than that, or hold too many points.

use crate::points::Bounds;
use glam::DVec3;

/// Bins per axis: fine enough that a stray point a few thousand times farther out than the
/// cloud is wide still leaves the cloud's own bins apart from it.
const BINS: usize = 4096;

/// Most points a far group may hold, for a cloud of `total` points: a 100,000th of the cloud,
/// or 64 (fewer than one fit needs), whichever is more. A real part of the scene holds more.
pub(crate) fn far_budget(total: u64) -> u64 {
    (total / 100_000).max(64)
}

/// Per-axis histograms of a cloud over a range: counts and the exact extremes in each bin.
#[derive(Clone, Debug)]
pub(crate) struct Spread {
    min: [f64; 3],
    width: [f64; 3],
    count: Vec<[u64; 3]>,
    low: Vec<[f64; 3]>,
    high: Vec<[f64; 3]>,
}

impl Spread {
    /// An empty spread over `range` (points outside it count in the end bins).
    pub(crate) fn new(range: &Bounds) -> Spread {
        // (Halved, so that a range from -1e308 to 1e308 does not overflow.)
        let width = std::array::from_fn(|a| (0.5 * range.max[a] - 0.5 * range.min[a]) / BINS as f64);
        Spread { min: range.min, width, count: vec![[0; 3]; BINS], low: vec![[f64::INFINITY; 3]; BINS], high: vec![[f64::NEG_INFINITY; 3]; BINS] }
    }

    fn bin(&self, v: f64, a: usize) -> usize {
        let b = (0.5 * v - 0.5 * self.min[a]) / self.width[a];
        if b.is_finite() {
            (b.max(0.0) as usize).min(BINS - 1)
        } else {
            0
        }
    }

    /// Counts `points`.
    pub(crate) fn add(&mut self, points: &[DVec3]) {
        for p in points {
            for a in 0..3 {
                let b = self.bin(p[a], a);
                self.count[b][a] += 1;
                self.low[b][a] = self.low[b][a].min(p[a]);
                self.high[b][a] = self.high[b][a].max(p[a]);
            }
        }
    }

    /// Points counted.
    pub(crate) fn total(&self) -> u64 {
        self.count.iter().map(|c| c[0]).sum()
    }

    /// The bounds of the cloud without its far points, or `None` if it has none.
    pub(crate) fn far_bounds(&self) -> Option<Bounds> {
        let total = self.total();
        let budget = far_budget(total);
        if total <= 2 * budget {
            return None;
        }
        // Occupied bins of each axis, in order: (count, lowest, highest).
        let occupied: [Vec<(u64, f64, f64)>; 3] =
            std::array::from_fn(|a| (0..BINS).filter(|&b| self.count[b][a] > 0).map(|b| (self.count[b][a], self.low[b][a], self.high[b][a])).collect());
        // How wide the rest is: the largest extent once `budget` points are set aside at each
        // end of each axis (bin by bin, so a little wider than exactly).
        let wide = (0..3)
            .map(|a| {
                let bins = &occupied[a];
                let (lo, hi) = (beyond(bins.iter(), budget), bins.len() - 1 - beyond(bins.iter().rev(), budget));
                bins[hi].2 - bins[lo].1
            })
            .fold(0.0, f64::max);
        let mut kept = Bounds::EMPTY;
        let mut far = false;
        for (a, bins) in occupied.iter().enumerate() {
            let lo = far_end(bins.iter(), budget, wide, |x, y| y.1 - x.2);
            let hi = bins.len() - 1 - far_end(bins.iter().rev(), budget, wide, |x, y| x.1 - y.2);
            far |= lo > 0 || hi + 1 < bins.len();
            (kept.min[a], kept.max[a]) = (bins[lo].1, bins[hi].2);
        }
        far.then_some(kept)
    }
}

/// How many bins from the start of `bins` hold the first `budget` points (the bin holding
/// point `budget + 1` is the first not counted).
fn beyond<'a>(bins: impl Iterator<Item = &'a (u64, f64, f64)>, budget: u64) -> usize {
    let mut seen = 0;
    for (k, b) in bins.enumerate() {
        seen += b.0;
        if seen > budget {
            return k;
        }
    }
    0
}

/// How many bins at the start of `bins` are far: the most whose points number at most
/// `budget` and which end in a gap (`gap(last far bin, next bin)`) wider than `wide`.
fn far_end<'a>(
    bins: impl Iterator<Item = &'a (u64, f64, f64)> + Clone,
    budget: u64,
    wide: f64,
    gap: impl Fn(&(u64, f64, f64), &(u64, f64, f64)) -> f64,
) -> usize {
    let mut far = 0;
    let mut seen = 0;
    let mut next = bins.clone().skip(1);
    for (k, b) in bins.enumerate() {
        seen += b.0;
        let Some(n) = next.next() else { break };
        if seen > budget {
            break;
        }
        if gap(b, n) > wide {
            far = k + 1;
        }
    }
    far
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, side: f64) -> Vec<DVec3> {
        (0..n * n * n).map(|k| DVec3::new((k % n) as f64, (k / n % n) as f64, (k / n / n) as f64) * side / (n - 1) as f64).collect()
    }

    fn kept(points: &[DVec3]) -> Option<Bounds> {
        let mut s = Spread::new(&Bounds::of(points.iter().copied()));
        s.add(points);
        s.far_bounds()
    }

    #[test]
    fn stray_points_far_out_are_far_and_the_rest_keeps_its_exact_bounds() {
        for at in [1e3, 1e6, 1e20, 1e150] {
            let mut pts = grid(20, 1.0);
            pts.extend([DVec3::splat(at), DVec3::splat(-at), DVec3::new(0.5, 0.5, at)]);
            let b = kept(&pts).unwrap_or_else(|| panic!("{at}: nothing far"));
            assert_eq!((b.min, b.max), ([0.0; 3], [1.0; 3]), "{at}");
        }
    }

    #[test]
    fn a_cloud_without_strays_or_with_near_ones_has_nothing_far() {
        assert!(kept(&grid(20, 1.0)).is_none());
        // A point as far out as the cloud is wide, and a sparse tower on a flat ground.
        let mut pts = grid(20, 1.0);
        pts.push(DVec3::new(0.5, 0.5, 1.9));
        assert!(kept(&pts).is_none());
        let mut ground: Vec<DVec3> = (0..10_000).map(|k| DVec3::new((k % 100) as f64, (k / 100) as f64, 0.0)).collect();
        ground.extend((0..30).map(|k| DVec3::new(50.0, 50.0, 10.0 + k as f64)));
        assert!(kept(&ground).is_none());
    }

    #[test]
    fn a_second_cloud_of_many_points_is_not_far_however_far_away() {
        let mut pts = grid(20, 1.0);
        pts.extend(grid(8, 1.0).into_iter().map(|p| p + DVec3::splat(1e6)));
        assert!(kept(&pts).is_none());
    }
}
