//! Stage 1: candidate feature points by MLS fit residual (Daniels 2007, section 3.2).
//!
//! A weighted plane (PCA, Gaussian weights) and a bivariate quadratic over it are fitted to a
//! neighbourhood; the residual is the largest distance of a neighbour from the quadratic along
//! the plane normal. Daniels fits around every point; here one fit serves the points of a small
//! grid cell (see [`residuals`]). Points with residual above tau are candidates.

use super::cloud::{Cloud, Neighbourhood};
use super::fit::{Frame, Pca, Quadric};
use glam::DVec3;

/// Most neighbours used by one fit (the nearest ones).
pub const MAX_FIT_NEIGHBOURS: usize = 160;
/// Fewest neighbours of a fit: sparse regions widen the neighbourhood to this many.
pub const MIN_FIT_NEIGHBOURS: usize = 20;

/// Residuals are shared by the points of one cell of a grid this many times finer than the
/// fit radius (see [`residuals`]). On the 1.6 M scene a cell holds 1.45 points on average at
/// 3 (2.17 at 2). On the 20 M scene the residual pass took 104 s of CPU at 3 and 96 s at 2,
/// against 132 s with a fit per point. Over the noisy rows of the quality table, 3 changed
/// mean recall by +0.002 / -0.002 and precision by +0.006 / -0.002 at seeds 1 / 2 (less than
/// a new seed moves them); 2 lost recall at both seeds (-0.004 each), most on fandisk 0.02 dB.
pub const CELLS_PER_RADIUS: f64 = 3.0;

/// The fit residual of every point in `which`, for neighbourhood radius `r`.
///
/// Neighbouring points' neighbourhoods overlap almost wholly, and so do their fits: one fit
/// per cell of a world-aligned grid of side `r / CELLS_PER_RADIUS`, centred in the cell, gives
/// the residual of all the cell's points. (A point's own fit would be centred up to
/// `0.87 * r / CELLS_PER_RADIUS` away; the candidate band follows the feature within that.)
/// The grid is aligned to world coordinates, so a point gets the same residual in any tile.
pub fn residuals(cloud: &Cloud, which: &[u32], r: f64) -> Vec<f32> {
    use rayon::prelude::*;
    let side = r / CELLS_PER_RADIUS;
    let cell = |i: u32| ((cloud.origin + cloud.at(i as usize)) / side).floor().as_i64vec3().to_array();
    let mut keys: Vec<([i64; 3], u32)> = which.par_iter().enumerate().map(|(k, &i)| (cell(i), k as u32)).collect();
    keys.par_sort_unstable();
    let mut centres = Vec::new();
    let mut cell_of = vec![0u32; which.len()];
    let mut last = None;
    for &(key, k) in &keys {
        if last != Some(key) {
            last = Some(key);
            centres.push((DVec3::new(key[0] as f64, key[1] as f64, key[2] as f64) + 0.5) * side - cloud.origin);
        }
        cell_of[k as usize] = centres.len() as u32 - 1;
    }
    let nb = Neighbourhood { radius: r, min: MIN_FIT_NEIGHBOURS, max: MAX_FIT_NEIGHBOURS, ordered: false };
    let res = cloud.map_neighbourhoods_at(&centres, nb, Vec::new, |pts, _, buf| residual_of(cloud, r, buf, pts));
    cell_of.iter().map(|&c| res[c as usize]).collect()
}

fn residual_of(cloud: &Cloud, r: f64, buf: &[(u32, f32)], pts: &mut Vec<(DVec3, f64)>) -> f32 {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on two half-planes meeting at a right angle along the y axis (z = 0 for x < 0,
    /// x = 0 for z < 0), on a jittered grid of spacing 0.01, shifted by `shift`.
    fn right_angle(shift: DVec3) -> Vec<DVec3> {
        let mut rng = crate::synth::rng::Rng::stream(3, 0);
        let mut world = Vec::new();
        for a in 0..60 {
            for b in 0..60 {
                let (u, y) = (-(a as f64 + rng.f64()) * 0.01, (b as f64 + rng.f64()) * 0.01);
                world.push(if (a + b) % 2 == 0 { DVec3::new(u, y, 0.0) } else { DVec3::new(0.0, y, u) } + shift);
            }
        }
        world
    }

    #[test]
    fn the_candidate_band_follows_the_crease_within_the_shared_cell() {
        let r = 0.1;
        let world = right_angle(DVec3::ZERO);
        let cloud = Cloud::new(&world);
        let all: Vec<u32> = (0..cloud.len() as u32).collect();
        let res = residuals(&cloud, &all, r);
        // Off the crease by more than a fit radius plus the reach of a cell, a fit sees one
        // plane; within a fit radius less that reach, it sees both.
        let slack = 0.87 * r / CELLS_PER_RADIUS + 1e-9;
        let (mut near, mut far) = (0, 0);
        for (&i, &x) in all.iter().zip(&res) {
            let p = cloud.at(i as usize) + cloud.origin;
            // (Points near the ends of the strip have one-sided neighbourhoods.)
            if p.y < 0.15 || p.y > 0.45 || p.x < -0.45 || p.z < -0.45 {
                continue;
            }
            let d = -(p.x + p.z);
            if d > r + slack {
                assert!(x < 1e-9, "residual {x} at {d} from the crease");
                far += 1;
            } else if d < r - slack {
                assert!(x > 1e-3, "residual {x} at {d} from the crease");
                near += 1;
            }
        }
        assert!(near > 100 && far > 100, "{near} near, {far} far");
    }

    #[test]
    fn a_point_gets_the_same_residual_whatever_the_cloud_around_it() {
        // The same points, alone and with others, and at another local origin.
        let r = 0.1;
        let world = right_angle(DVec3::new(1000.0, -3.0, 7.0));
        // (The fits of points below y = -2.8 reach no farther than y = -2.66.)
        let part: Vec<DVec3> = world.iter().copied().filter(|p| p.y < -2.6).collect();
        let residual_of = |pts: &[DVec3], shift: DVec3| -> Vec<(u64, f32)> {
            let gids: Vec<u64> = (0..pts.len() as u64).collect();
            let cloud = Cloud::with_origin(pts, &gids, DVec3::new(999.0, -3.0, 6.0) + shift);
            let which: Vec<u32> = (0..cloud.len() as u32).filter(|&i| (cloud.at(i as usize) + cloud.origin).y < -2.8).collect();
            let res = residuals(&cloud, &which, r);
            let mut out: Vec<(u64, f32)> = which.iter().zip(res).map(|(&i, x)| ((cloud.at(i as usize) + cloud.origin).y.to_bits(), x)).collect();
            out.sort_by_key(|o| o.0);
            out
        };
        let (a, b) = (residual_of(&world, DVec3::ZERO), residual_of(&part, DVec3::new(-0.123, 0.456, 0.789)));
        assert!(a.len() > 100);
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.0, y.0);
            assert!((x.1 - y.1).abs() <= 1e-6 * x.1.abs().max(1e-6), "{} against {}", x.1, y.1);
        }
    }
}
