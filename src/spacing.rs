//! The point spacing kappa, from which every length default is derived.

use crate::spatial::Index;
use glam::DVec3;

/// Median distance to the `k`-th nearest other point, measured at up to `samples` points spread
/// evenly through `points` (queries run against all points, so each value is exact). Returns 0
/// for too few points.
fn median_kth_distance(points: &[DVec3], k: usize, samples: usize) -> f64 {
    if points.len() <= k {
        return 0.0;
    }
    let origin = points[0];
    let local: Vec<[f32; 3]> = points.iter().map(|p| (*p - origin).as_vec3().to_array()).collect();
    // (Built in parallel: the whole of the fullest tile, while the pool has nothing to do.)
    let index = Index::new_parallel(&local);
    let step = (points.len() / samples.max(1)).max(1);
    let mut d: Vec<f32> = Vec::new();
    let mut nn = Vec::new();
    for q in local.iter().step_by(step) {
        nn.clear();
        index.nearest_n(q, k + 1, &mut nn);
        if let Some(&(_, d2)) = nn.last() {
            d.push(d2.sqrt());
        }
    }
    if d.is_empty() {
        return 0.0;
    }
    let m = d.len() / 2;
    *d.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1 as f64
}

/// The point spacing kappa: the median nearest-neighbour distance for evenly sampled
/// surfaces, measured through the 16th neighbour so that scan-line sampling (dense along
/// lines, sparse across) gets the spacing of its two-dimensional density rather than the
/// along-line one. For uniform random samples of a surface, the median distance to the k-th
/// neighbour is about sqrt(k / (pi rho)) and the median nearest-neighbour distance
/// sqrt(ln 2 / (pi rho)); their ratio converts one into the other.
pub fn spacing(points: &[DVec3], samples: usize) -> f64 {
    const K: usize = 16;
    let k = K.min(points.len().saturating_sub(1)).max(1);
    median_kth_distance(points, k, samples) * ((2f64).ln() / k as f64).sqrt()
}
