//! The mean point spacing kappa, from which every length default is derived.

use crate::spatial::Index;
use glam::DVec3;

/// Median nearest-neighbour distance of a point set, measured at up to `samples` points spread
/// evenly through it (queries run against all points, so the value is exact for the sample).
/// Duplicate points (distance 0) are skipped. Returns 0 for fewer than two distinct points.
pub fn median_nn_distance(points: &[DVec3], samples: usize) -> f64 {
    if points.len() < 2 {
        return 0.0;
    }
    let origin = points[0];
    let local: Vec<[f32; 3]> = points.iter().map(|p| (*p - origin).as_vec3().to_array()).collect();
    let index = Index::new(&local);
    let step = (points.len() / samples.max(1)).max(1);
    let mut d: Vec<f32> = Vec::new();
    let mut nn = Vec::new();
    for q in local.iter().step_by(step) {
        nn.clear();
        index.nearest_n(q, 4, &mut nn);
        if let Some(&(_, d2)) = nn.iter().find(|(_, d2)| *d2 > 0.0) {
            d.push(d2.sqrt());
        }
    }
    median(&mut d) as f64
}

/// The point spacing kappa: the median nearest-neighbour distance for evenly sampled
/// surfaces, measured through the 16th neighbour so that scan-line sampling (dense along
/// lines, sparse across) gets the spacing of its two-dimensional density rather than the
/// along-line one. For uniform random samples of a surface, the median distance to the k-th
/// neighbour is about sqrt(k / (pi rho)) and the median nearest-neighbour distance
/// sqrt(ln 2 / (pi rho)); their ratio converts one into the other.
pub fn spacing(points: &[DVec3], samples: usize) -> f64 {
    const K: usize = 16;
    if points.len() <= K {
        return median_nn_distance(points, samples);
    }
    let origin = points[0];
    let local: Vec<[f32; 3]> = points.iter().map(|p| (*p - origin).as_vec3().to_array()).collect();
    let index = Index::new(&local);
    let step = (points.len() / samples.max(1)).max(1);
    let mut d: Vec<f32> = Vec::new();
    let mut nn = Vec::new();
    for q in local.iter().step_by(step) {
        nn.clear();
        index.nearest_n(q, K + 1, &mut nn);
        if let Some(&(_, d2)) = nn.last() {
            d.push(d2.sqrt());
        }
    }
    let rk = median(&mut d) as f64;
    rk * ((2f64).ln() / K as f64).sqrt()
}

/// Spacing estimate from a random-like subsample of a surface: the median nearest-neighbour
/// distance within the sample, scaled by sqrt(sample / total) since on a surface spacing goes
/// as one over the square root of density.
pub fn spacing_from_subsample(sample: &[DVec3], total: u64) -> f64 {
    let d = median_nn_distance(sample, 20_000);
    if total == 0 || sample.is_empty() {
        return d;
    }
    d * (sample.len() as f64 / total as f64).min(1.0).sqrt()
}

fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1
}
