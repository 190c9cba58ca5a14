//! Stage 1: candidate feature points by MLS fit residual (Daniels 2007, section 3.2).
//!
//! For every point, a weighted plane (PCA, Gaussian weights) and a bivariate quadratic over it
//! are fitted to the neighbourhood; the residual is the largest distance of a neighbour from the
//! quadratic along the plane normal. Points with residual above tau are candidates.

use super::cloud::{Cloud, Neighbourhood};
use super::fit::{Frame, Pca, Quadric};
use glam::DVec3;

/// Most neighbours used by one fit (the nearest ones).
pub const MAX_FIT_NEIGHBOURS: usize = 160;
/// Fewest neighbours of a fit: sparse regions widen the neighbourhood to this many.
pub const MIN_FIT_NEIGHBOURS: usize = 20;

/// The fit residual of every point in `which`, for neighbourhood radius `r`.
pub fn residuals(cloud: &Cloud, which: &[u32], r: f64) -> Vec<f32> {
    let nb = Neighbourhood { radius: r, min: MIN_FIT_NEIGHBOURS, max: MAX_FIT_NEIGHBOURS, ordered: false };
    cloud.map_neighbourhoods(which, nb, Vec::new, |pts, i, buf| residual_of(cloud, i as usize, r, buf, pts))
}

fn residual_of(cloud: &Cloud, _i: usize, r: f64, buf: &[(u32, f32)], pts: &mut Vec<(DVec3, f64)>) -> f32 {
    if buf.len() < 8 {
        // Too sparse to fit a quadratic: not evidence of a feature.
        return 0.0;
    }
    // Gaussian weights on the neighbourhood's own scale (wider where it was widened).
    let reach2 = buf.iter().map(|&(_, d2)| d2 as f64).fold(r * r, f64::max);
    let h2 = reach2 / 4.0;
    pts.clear();
    pts.extend(buf.iter().map(|&(j, d2)| (cloud.at(j as usize), (-(d2 as f64) / h2).exp())));
    let Some(pca) = Pca::of(pts.iter().copied()) else { return 0.0 };
    let frame = Frame::new(pca.mean, pca.normal());
    let Some(quad) = Quadric::fit(frame, pts.iter().copied(), 1e-6) else { return 0.0 };
    pts.iter().map(|&(p, _)| quad.value(p).abs()).fold(0.0, f64::max) as f32
}
