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

/// The fit residual of every point in `which`, for neighbourhood radius `r`; sparse
/// neighbourhoods are widened up to `reach` (see [`Neighbourhood::reach`]).
pub fn residuals(cloud: &Cloud, which: &[u32], r: f64, reach: f64) -> Vec<f32> {
    let nb = Neighbourhood { radius: r, reach, min: MIN_FIT_NEIGHBOURS, max: MAX_FIT_NEIGHBOURS, ordered: false };
    cloud.map_neighbourhoods(which, nb, Vec::new, |pts, i, buf| residual_of(cloud, i as usize, r, buf, pts))
}

fn residual_of(cloud: &Cloud, i: usize, r: f64, buf: &[(u32, f32)], pts: &mut Vec<(DVec3, f64)>) -> f32 {
    if buf.len() < 8 {
        // Too sparse to fit a quadratic: not evidence of a feature.
        return 0.0;
    }
    // Gaussian weights on the neighbourhood's own scale (wider where it was widened).
    let reach2 = buf.iter().map(|&(_, d2)| d2 as f64).fold(r * r, f64::max);
    let h2 = reach2 / 4.0;
    pts.clear();
    pts.extend(buf.iter().map(|&(j, d2)| (cloud.at(j as usize), (-(d2 as f64) / h2).exp())));
    let Some(pca) = Pca::of_near(pts.iter().copied(), cloud.at(i)) else { return 0.0 };
    let frame = Frame::new(pca.mean, pca.normal());
    let Some(quad) = Quadric::fit(frame, pts.iter().copied(), 1e-6) else { return 0.0 };
    pts.iter().map(|&(p, _)| quad.value(p).abs()).fold(0.0, f64::max) as f32
}

/// A sum of residuals that does not depend on the order of its terms: each residual is
/// rounded to a fixed quantum (2^-64 model units) and summed as an integer, so tiles may add
/// their partial sums in any grouping and tau comes out the same to the bit. (Summed in
/// floating point, the mean differed between tilings in its last digits, and a candidate on
/// the threshold could flip.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ResidualSum {
    sum: u128,
    count: u64,
}

impl std::ops::Add for ResidualSum {
    type Output = ResidualSum;

    /// Both sums together.
    fn add(self, other: ResidualSum) -> ResidualSum {
        ResidualSum { sum: self.sum + other.sum, count: self.count + other.count }
    }
}

impl ResidualSum {
    const SCALE: f64 = 18_446_744_073_709_551_616.0; // 2^64

    /// The sum of `residuals`.
    pub fn of(residuals: impl IntoIterator<Item = f32>) -> ResidualSum {
        let mut s = ResidualSum::default();
        for x in residuals {
            // (Residuals are distances: non-negative, and far below 2^64 model units.)
            s.sum += (x.max(0.0) as f64 * Self::SCALE).round() as u128;
            s.count += 1;
        }
        s
    }

    /// Number of residuals summed.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The mean residual (0 for no residuals).
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        (self.sum as f64 / Self::SCALE) / self.count as f64
    }
}

#[cfg(test)]
mod tests {
    use super::ResidualSum;

    #[test]
    fn residual_sums_do_not_depend_on_grouping_or_order() {
        // Values spread over many magnitudes, where a floating-point sum depends on its order.
        let v: Vec<f32> = (0..10_000u32).map(|i| ((i.wrapping_mul(2_654_435_761) % 100_003) as f32 * 1e-3).powi(3) * 1e-4 + 1e-7).collect();
        let whole = ResidualSum::of(v.iter().copied());
        let mut reversed = v.clone();
        reversed.reverse();
        assert_eq!(ResidualSum::of(reversed), whole);
        for parts in [2, 7, 64] {
            let grouped = v.chunks(v.len().div_ceil(parts)).rev().map(|c| ResidualSum::of(c.iter().copied())).fold(ResidualSum::default(), |a, b| a + b);
            assert_eq!(grouped, whole, "{parts} groups");
        }
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        assert!((whole.mean() - mean).abs() <= 1e-12 * mean, "{} vs {mean}", whole.mean());
        assert_eq!(whole.count(), v.len() as u64);
        assert_eq!(ResidualSum::default().mean(), 0.0);
    }
}
