//! Stage 3: smoothing of projected edge points (Daniels 2007, section 3.4).
//!
//! Each edge point moves onto the principal axis of its neighbourhood among the edge points,
//! grown adaptively (nearest first) until the neighbourhood is clearly linear, and never past
//! the nearest corner, where it would start to take in another feature. Linearity is measured
//! rotation-invariantly as (l0 - l1) / (l0 + l1) of the covariance eigenvalues (the paper's
//! correlation coefficient is zero by construction in the PCA frame).

use super::fit::Pca;
use crate::spatial::Index;
use glam::DVec3;
use rayon::prelude::*;

/// Smoothing parameters.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SmoothParams {
    /// Grow until (l0 - l1) / (l0 + l1) reaches this.
    pub linearity: f64,
    /// Largest neighbourhood radius.
    pub max_radius: f64,
}

/// Smallest and largest neighbourhood sizes tried.
const MIN_K: usize = 8;
const MAX_K: usize = 64;
/// Neighbours asked for first (one more than the neighbourhood sizes tried with them).
const FIRST_K: usize = 17;

/// Smoothed positions of the first `own` of `points`; the rest are context only (the edge
/// points around a block of the cloud, which every neighbourhood of the block may take in).
/// `corners` cap the neighbourhoods. The result depends only on the set of points within the
/// largest radius of each smoothed point, not on their order or on what lies further out, so a
/// cloud smoothed block by block gives what it gives smoothed whole.
pub(crate) fn smooth(points: &[DVec3], own: usize, corners: &[DVec3], p: &SmoothParams) -> Vec<DVec3> {
    if points.len() < MIN_K {
        return points[..own].to_vec();
    }
    // (The f32 copy is only the tree's input.)
    let index = Index::new(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>());
    let slack = super::neighbourhood::rounding_slack(points.iter().fold(0.0f64, |m, q| m.max(q.abs().max_element())));
    let corner_index = (!corners.is_empty()).then(|| Index::new(&corners.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>()));
    let key = |j: u32| points[j as usize].to_array().map(f64::to_bits);
    (0..own)
        .into_par_iter()
        .map_init(Vec::new, |nn, i| {
            let x = points[i];
            let xf = x.as_vec3().to_array();
            let cap = corner_index.as_ref().map_or(f64::INFINITY, |ci| {
                let mut c = Vec::new();
                ci.nearest_n(&xf, 1, &mut c);
                corners[c[0].0 as usize].distance(x)
            });
            let radius = p.max_radius.min(cap);
            // (Queried a little wide: whether a point is within the radius is decided below,
            // in f64.) Most neighbourhoods are linear within a few points, so the nearest
            // FIRST_K - 1 are asked for first, and the rest only if they do not suffice.
            let r32 = super::neighbourhood::query_radius(radius, slack);
            let mut best: Option<Pca> = None;
            let mut k = MIN_K;
            for want in [FIRST_K, MAX_K] {
                let want = want.min(points.len());
                nn.clear();
                index.nearest_n_within(&xf, want, r32, nn);
                // Points at equal distance come in the tree's order, which depends on what
                // else the tree holds; order them by position so the PCA sums are always the same.
                nn.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then_with(|| key(a.0).cmp(&key(b.0))));
                // All points within the radius came back, or the first want - 1 are surely
                // the nearest (the next is strictly farther), or (a tie at the cut) none are.
                let complete = nn.len() < want || want == MAX_K.min(points.len());
                let usable = if complete {
                    nn.len()
                } else if nn[want - 1].1 > nn[want - 2].1 {
                    want - 1
                } else {
                    0
                };
                let mut done = false;
                while k <= usable {
                    if (nn[k - 1].1 as f64).sqrt() > radius {
                        done = true;
                        break;
                    }
                    let pca = Pca::of(nn[..k].iter().map(|&(j, _)| (points[j as usize], 1.0)));
                    if let Some(pca) = pca {
                        best = Some(pca);
                        if pca.line_measure() >= p.linearity {
                            done = true;
                            break;
                        }
                    }
                    k += 4;
                }
                if done || complete {
                    break;
                }
            }
            match best {
                Some(pca) => pca.mean + pca.axis() * (x - pca.mean).dot(pca.axis()),
                None => x,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Noisy points along two segments meeting at a corner.
    fn polyline_cloud() -> Vec<DVec3> {
        let mut rng = Rng::new(7);
        let mut pts = vec![];
        for i in 0..400 {
            let t = i as f64 / 400.0;
            let on = if t < 0.5 { DVec3::new(t * 2.0, 0.0, 0.0) } else { DVec3::new(1.0, (t - 0.5) * 2.0, 0.2 * (t - 0.5)) };
            pts.push(on + rng.in_ball(0.01));
        }
        pts
    }

    #[test]
    fn smoothing_in_blocks_with_context_equals_smoothing_whole() {
        let pts = polyline_cloud();
        let corners = [DVec3::new(1.0, 0.0, 0.0)];
        let p = SmoothParams { linearity: 0.95, max_radius: 0.1 };
        let whole = smooth(&pts, pts.len(), &corners, &p);
        // Moved, and towards the segments.
        assert!(whole.iter().zip(&pts).filter(|(a, b)| a != b).count() > pts.len() / 2);
        // Blocks split at x = 0.7 and x = 1.0 (through the corner), each given, after its own
        // points, the others within reach of its bounds, in reverse order.
        let cuts = [f64::NEG_INFINITY, 0.7, 1.0, f64::INFINITY];
        let mut by_block = vec![DVec3::ZERO; pts.len()];
        for w in cuts.windows(2) {
            let own: Vec<usize> = (0..pts.len()).filter(|&i| pts[i].x >= w[0] && pts[i].x < w[1]).collect();
            let lo = own.iter().map(|&i| pts[i]).reduce(DVec3::min).unwrap() - DVec3::splat(p.max_radius * 1.01);
            let hi = own.iter().map(|&i| pts[i]).reduce(DVec3::max).unwrap() + DVec3::splat(p.max_radius * 1.01);
            let mut block: Vec<DVec3> = own.iter().map(|&i| pts[i]).collect();
            block.extend(
                (0..pts.len()).rev().filter(|&i| !(pts[i].x >= w[0] && pts[i].x < w[1])).map(|i| pts[i]).filter(|q| q.cmpge(lo).all() && q.cmple(hi).all()),
            );
            for (k, s) in smooth(&block, own.len(), &corners, &p).into_iter().enumerate() {
                by_block[own[k]] = s;
            }
        }
        assert_eq!(whole, by_block);
    }
}
