//! The point spacing kappa, from which every length default is derived.

use crate::cancel::Cancel;
use crate::error::Result;
use crate::spatial::Index;
use glam::DVec3;
use rayon::prelude::*;

/// Points a tree of [`median_kth_distance`] holds at most: each is built in a few hundredths
/// of a second, and a cancel is seen between two.
const PART: usize = 1 << 18;

/// Median distance to the `k`-th nearest other point, measured at up to `samples` points spread
/// evenly through `points` (queries run against all points, so each value is exact). Returns 0
/// for too few points. Stops with [`crate::Error::Interrupted`] once `cancel` is set.
///
/// The points are indexed in parts of at most [`PART`] points, one tree each, and a sample's
/// neighbours are the nearest of each part's nearest: the same distances as one tree over all
/// (each distance is computed from the same f32 coordinates), while a tree over the whole of a
/// tile of millions of points, which no cancel can stop, took more than a second.
fn median_kth_distance(points: &[DVec3], k: usize, samples: usize, cancel: &Cancel) -> Result<f64> {
    if points.len() <= k {
        return Ok(0.0);
    }
    let origin = points[0];
    let local: Vec<[f32; 3]> = points.par_iter().map(|p| (*p - origin).as_vec3().to_array()).collect();
    cancel.check()?;
    // (Built in parallel, part by part: the whole of the fullest tile, while the pool has
    // nothing to do.)
    let parts: Vec<Option<Index>> = local.par_chunks(PART).map(|part| (!cancel.is_set()).then(|| Index::new(part))).collect();
    cancel.check()?;
    let parts: Vec<Index> = parts.into_iter().flatten().collect();
    let step = (points.len() / samples.max(1)).max(1);
    let mut d: Vec<f32> = Vec::new();
    let (mut nn, mut all) = (Vec::new(), Vec::new());
    for (n, q) in local.iter().step_by(step).enumerate() {
        if n % 256 == 0 {
            cancel.check()?;
        }
        all.clear();
        for index in &parts {
            nn.clear();
            index.nearest_n(q, k + 1, &mut nn);
            all.extend(nn.iter().map(|&(_, d2)| d2));
        }
        if all.len() > k {
            d.push(all.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1.sqrt());
        } else if let Some(&d2) = all.iter().max_by(|a, b| a.total_cmp(b)) {
            d.push(d2.sqrt());
        }
    }
    if d.is_empty() {
        return Ok(0.0);
    }
    let m = d.len() / 2;
    Ok(*d.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1 as f64)
}

/// The point spacing kappa: the median nearest-neighbour distance for evenly sampled
/// surfaces, measured through the 16th neighbour so that scan-line sampling (dense along
/// lines, sparse across) gets the spacing of its two-dimensional density rather than the
/// along-line one. For uniform random samples of a surface, the median distance to the k-th
/// neighbour is about sqrt(k / (pi rho)) and the median nearest-neighbour distance
/// sqrt(ln 2 / (pi rho)); their ratio converts one into the other.
pub fn spacing(points: &[DVec3], samples: usize) -> f64 {
    spacing_or_cancel(points, samples, &Cancel::default()).expect("not cancelled")
}

/// [`spacing`], stopped with [`crate::Error::Interrupted`] within a small part of a second of
/// `cancel` being set, however many the points (the spacing probe of a run's fullest tile).
pub(crate) fn spacing_or_cancel(points: &[DVec3], samples: usize, cancel: &Cancel) -> Result<f64> {
    const K: usize = 16;
    let k = K.min(points.len().saturating_sub(1)).max(1);
    Ok(median_kth_distance(points, k, samples, cancel)? * ((2f64).ln() / k as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn plane(n: usize) -> Vec<DVec3> {
        let mut rng = Rng::stream(61, 0);
        (0..n).map(|_| DVec3::new(3.0 * rng.f64(), 2.0 * rng.f64(), 0.01 * rng.f64())).collect()
    }

    /// Over three parts of at most [`PART`] points, the probe finds the median distance that
    /// one tree over all the points gives, to the bit.
    #[test]
    fn trees_in_parts_give_the_distance_of_one_tree() {
        let points = plane(700_000);
        let (k, samples) = (16, 2000);
        let local: Vec<[f32; 3]> = points.iter().map(|p| (*p - points[0]).as_vec3().to_array()).collect();
        let index = Index::new_parallel(&local);
        let mut d: Vec<f32> = vec![];
        let mut nn = vec![];
        for q in local.iter().step_by(points.len() / samples) {
            nn.clear();
            index.nearest_n(q, k + 1, &mut nn);
            d.push(nn[k].1.sqrt());
        }
        let m = d.len() / 2;
        let one_tree = *d.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1 as f64;
        assert_eq!(median_kth_distance(&points, k, samples, &Cancel::default()).unwrap(), one_tree);
    }

    /// A probe asked to stop builds no tree and returns the interruption.
    #[test]
    fn a_cancelled_probe_stops() {
        let cancel = Cancel::default();
        cancel.set();
        assert!(matches!(spacing_or_cancel(&plane(300_000), 2000, &cancel), Err(crate::Error::Interrupted)));
    }
}
