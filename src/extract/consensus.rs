//! Between stages 3 and 4, on noise-limited clouds: edge points that no neighbour confirms are
//! dropped before growing.
//!
//! A crease gives every candidate near it the same two surfaces, so its edge points agree with
//! their neighbours on both normals. Edge points found where no crease is (a curved wall fitted
//! as two planes that cross, say, or a noise cluster taken for a second surface) each get their
//! own pair of surfaces, and rarely agree with anyone: joint at 0.01 dB noise, inside its bore
//! (radius about one projection radius), had edge points a few per step and mostly alone in
//! their normals, and polyline growing strung them into curves along the wall. Sparse is not
//! enough to tell them apart: the gentle feet of fandisk's fading ridge are as sparse, but their
//! edge points all agree (see the tests). This is not in Daniels et al.; it is the same kind of
//! evidence as their corner grouping's support, taken for edges.

use crate::spatial::Index;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// Two edge points agree if each normal of one is within this angle (degrees) of a normal of
/// the other (the two normals matched either way round). (30 kept more of a noisy hole's rim,
/// whose wall normal turns along it, but let more of joint's bore through: over the noisy
/// rows at seed 1, precision summed 0.11 lower.)
pub(crate) const AGREE_DEG: f64 = 20.0;
/// An edge point is kept if at least this many of its neighbours within one step agree with
/// it... (Along fandisk's ridge feet at 0.01 dB, nine of ten edge points have 3 or more; of the
/// sparse edge points off the truth in joint's bore, half have 2 or fewer and nine of ten 5 or
/// fewer. With
/// 2, pairs of them that agreed by chance still made curves there: joint 0.01 dB mean distance
/// 0.0050 dB; with 3 or 4, 0.0022-0.0023, and 4 kept it so with the crease test's extra
/// candidates.)
pub(crate) const MIN_AGREEING: usize = 4;
/// ...and they make at least this share of its neighbours. (Below a half and a third, so that
/// edge points near a corner, where two or three creases' points mix, are kept.)
pub(crate) const MIN_SHARE: f64 = 0.2;

/// Which of the first `own` edge points (positions `points`, normals `normals`) are confirmed
/// by their neighbours within `radius`; the rest of `points` are context (the edge points
/// around a block, at least `radius` beyond it). Whether a point is within the radius is
/// decided in f64, so the result depends only on the set of points within the radius of each
/// point, not on their order or on how the cloud was cut into blocks.
pub(crate) fn confirmed(points: &[DVec3], normals: &[[Vec3; 2]], own: usize, radius: f64) -> Vec<bool> {
    assert_eq!(points.len(), normals.len(), "one pair of normals per edge point");
    if points.is_empty() {
        return vec![];
    }
    let index = Index::new(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>());
    let slack = super::neighbourhood::rounding_slack(points.iter().fold(0.0f64, |m, q| m.max(q.abs().max_element())));
    let r32 = super::neighbourhood::query_radius(radius, slack);
    let cos = AGREE_DEG.to_radians().cos() as f32;
    let agree = |a: &[Vec3; 2], b: &[Vec3; 2]| {
        let close = |u: Vec3, v: Vec3| u.dot(v).abs() >= cos;
        (close(a[0], b[0]) && close(a[1], b[1])) || (close(a[0], b[1]) && close(a[1], b[0]))
    };
    (0..own)
        .into_par_iter()
        .map_init(Vec::new, |nn, i| {
            let x = points[i];
            nn.clear();
            index.within(&x.as_vec3().to_array(), r32, nn);
            let (mut near, mut agreeing) = (0usize, 0usize);
            for &(j, _) in nn.iter() {
                let j = j as usize;
                if j == i || points[j].distance(x) > radius {
                    continue;
                }
                near += 1;
                agreeing += agree(&normals[i], &normals[j]) as usize;
            }
            agreeing >= MIN_AGREEING && agreeing as f64 >= MIN_SHARE * near as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Normals of a crease along x between planes tilted by +-`half` degrees about x.
    fn crease_normals(half: f64) -> [Vec3; 2] {
        let h = half.to_radians();
        [Vec3::new(0.0, h.sin() as f32, h.cos() as f32), Vec3::new(0.0, -h.sin() as f32, h.cos() as f32)]
    }

    #[test]
    fn sparse_agreeing_edge_points_are_kept_and_lone_ones_dropped() {
        let mut rng = Rng::stream(3, 0);
        // A sparse crease (six neighbours within the radius, as along fandisk's ridge feet under
        // noise, against a hundred or more on most edges), its normals a few degrees apart;
        // beside it, as sparse, points with random normal pairs.
        let mut points = vec![];
        let mut normals = vec![];
        for k in 0..40 {
            points.push(DVec3::new(k as f64 * 0.16, rng.range(-0.02, 0.02), 0.0));
            normals.push(crease_normals(20.0 + rng.range(-4.0, 4.0)));
        }
        let crease = points.len();
        for k in 0..40 {
            points.push(DVec3::new(k as f64 * 0.16, 3.0 + rng.range(-0.02, 0.02), 0.0));
            let mut random = || Vec3::new(rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32).normalize();
            let (a, b) = (random(), random());
            normals.push([a, b]);
        }
        let keep = confirmed(&points, &normals, points.len(), 0.5);
        let kept_crease = keep[..crease].iter().filter(|&&k| k).count();
        let kept_lone = keep[crease..].iter().filter(|&&k| k).count();
        assert!(kept_crease >= crease - 2, "{kept_crease} of {crease} crease points kept");
        assert!(kept_lone <= 4, "{kept_lone} of 40 lone points kept");
    }

    #[test]
    fn edge_points_near_a_corner_are_kept() {
        // Three creases meet at the origin (a cube's corner): near it each point's neighbours are
        // a third its own crease's.
        let axes = [DVec3::X, DVec3::Y, DVec3::Z];
        let n = |a: usize| {
            let (u, v) = (axes[(a + 1) % 3].as_vec3(), axes[(a + 2) % 3].as_vec3());
            [u, v]
        };
        let mut points = vec![];
        let mut normals = vec![];
        for (a, &axis) in axes.iter().enumerate() {
            for k in 1..=30 {
                points.push(axis * k as f64 * 0.02);
                normals.push(n(a));
            }
        }
        let keep = confirmed(&points, &normals, points.len(), 0.1);
        assert!(keep.iter().all(|&k| k), "{} of {} dropped", keep.iter().filter(|&&k| !k).count(), keep.len());
    }

    #[test]
    fn the_result_does_not_depend_on_blocks_or_order() {
        let mut rng = Rng::stream(5, 0);
        let points: Vec<DVec3> = (0..2000).map(|_| DVec3::new(rng.range(0.0, 4.0), rng.range(0.0, 1.0), rng.range(0.0, 0.1))).collect();
        let normals: Vec<[Vec3; 2]> = points.iter().map(|p| crease_normals(if p.y < 0.5 { 20.0 } else { 20.0 + rng.range(-40.0, 40.0) })).collect();
        let radius = 0.1;
        let whole = confirmed(&points, &normals, points.len(), radius);
        // The block x < 2 with its context (x < 2 + radius), in reverse order.
        let own: Vec<usize> = (0..points.len()).rev().filter(|&i| points[i].x < 2.0).collect();
        let ctx: Vec<usize> = (0..points.len()).filter(|&i| points[i].x >= 2.0 && points[i].x < 2.0 + 1.01 * radius).collect();
        let order: Vec<usize> = own.iter().chain(&ctx).copied().collect();
        let p: Vec<DVec3> = order.iter().map(|&i| points[i]).collect();
        let n: Vec<[Vec3; 2]> = order.iter().map(|&i| normals[i]).collect();
        let block = confirmed(&p, &n, own.len(), radius);
        for (k, &i) in own.iter().enumerate() {
            assert_eq!(block[k], whole[i], "point {i}");
        }
        assert!(whole.iter().any(|&k| !k) && whole.iter().any(|&k| k));
    }
}
