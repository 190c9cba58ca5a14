//! Cubic B-splines fitted to a run of curve vertices, as Daniels et al. 2008 (section 3.6) fit
//! their feature polylines: least squares over arc-length parameters, with knots inserted where
//! the fit misses until it holds within a tolerance.
//!
//! The spline is clamped and passes through the run's first and last vertex exactly, so that
//! pieces meeting there (a corner, or the piece before) share the point. Its error is measured
//! at every vertex and at the middle of every step (each against the spline at the same
//! parameter, which bounds the distance from the curve), so it holds within the tolerance over
//! the whole polyline it replaces, not only at the vertices.

use glam::DVec3;
use serde::Serialize;

/// Degree of every spline: cubic, as in the 2008 paper and as CAD tools draw them.
pub(crate) const DEGREE: usize = 3;

/// A clamped cubic B-spline: knot vector (each end repeated `DEGREE + 1` times, parameters from
/// 0 to 1) and control points (`knots.len() - DEGREE - 1` of them).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct Spline {
    /// Always [`DEGREE`]; written so that a reader need not know it.
    pub degree: usize,
    pub knots: Vec<f64>,
    pub control_points: Vec<DVec3>,
}

impl Spline {
    /// The point at parameter `t` in [0, 1].
    pub(crate) fn at(&self, t: f64) -> DVec3 {
        let (k, b) = basis(&self.knots, t);
        (0..=DEGREE).map(|j| b[j] * self.control_points[k - DEGREE + j]).sum()
    }
}

/// The span `k` (knots[k] <= t < knots[k + 1], the last non-empty one at t = 1) and the
/// `DEGREE + 1` basis functions that are not zero there, of control points `k - DEGREE ..= k`
/// (Cox-de Boor).
fn basis(knots: &[f64], t: f64) -> (usize, [f64; DEGREE + 1]) {
    let last = knots.len() - DEGREE - 2;
    let k = (DEGREE..=last).rfind(|&k| knots[k] <= t).unwrap_or(DEGREE).min(last);
    let mut b = [0.0; DEGREE + 1];
    b[0] = 1.0;
    let (mut left, mut right) = ([0.0; DEGREE + 1], [0.0; DEGREE + 1]);
    for j in 1..=DEGREE {
        left[j] = t - knots[k + 1 - j];
        right[j] = knots[k + j] - t;
        let mut saved = 0.0;
        for r in 0..j {
            let w = b[r] / (right[r + 1] + left[j - r]);
            b[r] = saved + right[r + 1] * w;
            saved = left[j - r] * w;
        }
        b[j] = saved;
    }
    (k, b)
}

/// Chord-length parameters of `pts`, from 0 to 1; None where the run has no length.
fn parameters(pts: &[DVec3]) -> Option<Vec<f64>> {
    let mut t = vec![0.0; pts.len()];
    for i in 1..pts.len() {
        t[i] = t[i - 1] + pts[i].distance(pts[i - 1]);
    }
    let total = *t.last()?;
    if total <= 0.0 || !total.is_finite() {
        return None;
    }
    t.iter_mut().for_each(|x| *x /= total);
    *t.last_mut()? = 1.0;
    Some(t)
}

/// The spline with `knots` that passes through the ends of `pts` and fits the rest in least
/// squares at parameters `t`; None where the fit is not determined (a span too empty).
fn least_squares(pts: &[DVec3], t: &[f64], knots: &[f64]) -> Option<Spline> {
    let n = knots.len() - DEGREE - 1;
    let (first, last) = (pts[0], pts[pts.len() - 1]);
    // Unknowns: control points 1 ..= n - 2 (the ends are the run's ends); normal equations,
    // banded: each row couples a control point with the DEGREE on either side.
    let u = n - 2;
    let mut a = vec![[0.0f64; DEGREE + 1]; u]; // a[i][d]: entry (i, i + d)
    let mut rhs = vec![DVec3::ZERO; u];
    for (&p, &ti) in pts.iter().zip(t) {
        let (k, b) = basis(knots, ti);
        let mut r = p;
        for (j, &bj) in b.iter().enumerate() {
            match k - DEGREE + j {
                0 => r -= bj * first,
                c if c == n - 1 => r -= bj * last,
                _ => {}
            }
        }
        for (j, &bj) in b.iter().enumerate() {
            let c = k - DEGREE + j;
            if c == 0 || c == n - 1 {
                continue;
            }
            rhs[c - 1] += bj * r;
            for (l, &bl) in b.iter().enumerate().skip(j) {
                let d = k - DEGREE + l;
                if d != n - 1 {
                    a[c - 1][d - c] += bj * bl;
                }
            }
        }
    }
    let inner = banded_cholesky_solve(a, rhs)?;
    let mut control_points = Vec::with_capacity(n);
    control_points.push(first);
    control_points.extend(inner);
    control_points.push(last);
    Some(Spline { degree: DEGREE, knots: knots.to_vec(), control_points })
}

/// Solves the symmetric positive definite banded system `a` x = `rhs` (a[i][d] the entry
/// (i, i + d)) by Cholesky; None where it is not positive definite to working precision.
fn banded_cholesky_solve(mut a: Vec<[f64; DEGREE + 1]>, mut rhs: Vec<DVec3>) -> Option<Vec<DVec3>> {
    let u = a.len();
    let scale = a.iter().map(|r| r[0]).fold(0.0, f64::max);
    for i in 0..u {
        for d in 0..=DEGREE {
            if i + d >= u {
                break;
            }
            let mut s = a[i][d];
            for k in (i.saturating_sub(DEGREE))..i {
                if k + DEGREE >= i + d {
                    s -= a[k][i - k] * a[k][i + d - k];
                }
            }
            if d == 0 {
                if s <= 1e-12 * scale {
                    return None;
                }
                a[i][0] = s.sqrt();
            } else {
                a[i][d] = s / a[i][0];
            }
        }
    }
    // L y = rhs, then L^T x = y (L's column i holds a[i][..]).
    for i in 0..u {
        let mut s = rhs[i];
        for k in (i.saturating_sub(DEGREE))..i {
            s -= a[k][i - k] * rhs[k];
        }
        rhs[i] = s / a[i][0];
    }
    for i in (0..u).rev() {
        let mut s = rhs[i];
        for d in 1..=DEGREE {
            if i + d < u {
                s -= a[i][d] * rhs[i + d];
            }
        }
        rhs[i] = s / a[i][0];
    }
    Some(rhs)
}

/// Fits a spline to the run `pts` (at least two vertices): one span first, then a knot in the
/// middle of every span where the fit misses by more than `tol`, until it holds; at most
/// `max_control` control points. Returns the spline and its error (the largest miss at a vertex
/// or a step's middle); None where no spline of that size holds (a zigzag finer than the
/// tolerance), or a span to be split holds too few vertices to fit on both sides.
pub(crate) fn fit(pts: &[DVec3], tol: f64, max_control: usize) -> Option<(Spline, f64)> {
    let t = parameters(pts)?;
    let clamp = |interior: &[f64]| -> Vec<f64> {
        let mut k = vec![0.0; DEGREE + 1];
        k.extend_from_slice(interior);
        k.extend([1.0; DEGREE + 1]);
        k
    };
    let mut interior: Vec<f64> = Vec::new();
    loop {
        let knots = clamp(&interior);
        let spline = least_squares(pts, &t, &knots)?;
        // Misses by span: at each vertex and at each step's middle.
        let mut miss = vec![0.0f64; interior.len() + 1];
        let span_of = |x: f64| interior.partition_point(|&k| k <= x).min(interior.len());
        for i in 0..pts.len() {
            miss[span_of(t[i])] = miss[span_of(t[i])].max(spline.at(t[i]).distance(pts[i]));
            if i + 1 < pts.len() {
                let tm = 0.5 * (t[i] + t[i + 1]);
                let e = spline.at(tm).distance(0.5 * (pts[i] + pts[i + 1]));
                miss[span_of(tm)] = miss[span_of(tm)].max(e);
            }
        }
        let error = miss.iter().copied().fold(0.0, f64::max);
        if error <= tol {
            return Some((spline, error));
        }
        // (Each new span must hold at least two vertices, so that every control point is
        // pinned by data and the normal equations stay positive definite.)
        let bounds = clamp(&interior);
        let mut added = Vec::new();
        for (s, &m) in miss.iter().enumerate() {
            let (lo, hi) = (bounds[DEGREE + s], bounds[DEGREE + s + 1]);
            let mid = 0.5 * (lo + hi);
            let count = |a: f64, b: f64| t.iter().filter(|&&x| x >= a && x < b).count();
            if m > tol && count(lo, mid) >= 2 && count(mid, hi) >= 2 {
                added.push(mid);
            }
        }
        if added.is_empty() || interior.len() + added.len() + DEGREE + 1 > max_control {
            return None;
        }
        interior.extend(added);
        interior.sort_by(f64::total_cmp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn the_basis_sums_to_one_and_the_ends_are_the_end_control_points() {
        let knots = vec![0.0, 0.0, 0.0, 0.0, 0.3, 0.5, 1.0, 1.0, 1.0, 1.0];
        for k in 0..=20 {
            let t = k as f64 / 20.0;
            let (_, b) = basis(&knots, t);
            assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{t}: {b:?}");
            assert!(b.iter().all(|&x| x >= -1e-15));
        }
        let s = Spline { degree: DEGREE, knots, control_points: (0..6).map(|i| DVec3::new(i as f64, (i * i) as f64, 0.0)).collect() };
        assert_eq!(s.at(0.0), s.control_points[0]);
        assert!(s.at(1.0).distance(s.control_points[5]) < 1e-12);
    }

    #[test]
    fn a_helix_turn_is_a_few_spans_within_the_tolerance_through_its_ends() {
        let pts: Vec<DVec3> = (0..=300).map(|k| k as f64 / 300.0 * TAU).map(|a| DVec3::new(a.cos(), a.sin(), 0.3 * a)).collect();
        let (s, error) = fit(&pts, 1e-3, 1000).expect("a smooth run fits");
        assert!(error <= 1e-3);
        assert!(s.control_points.len() < 20, "{} control points", s.control_points.len());
        assert_eq!(s.control_points[0], pts[0]);
        assert_eq!(*s.control_points.last().unwrap(), pts[300]);
        assert_eq!(s.at(0.0), pts[0]);
        assert!(s.at(1.0).distance(pts[300]) < 1e-12);
        // Between the vertices too: the fitted curve follows the helix, not only its samples.
        for k in 0..3000 {
            let p = s.at(k as f64 / 3000.0);
            let a = p.z / 0.3;
            assert!(p.distance(DVec3::new(a.cos(), a.sin(), p.z)) < 2e-3, "{k}");
        }
    }

    #[test]
    fn noise_within_the_tolerance_is_smoothed_not_followed() {
        let mut rng = crate::rng::Rng::stream(9, 0);
        let pts: Vec<DVec3> = (0..=400).map(|k| k as f64 / 100.0).map(|x| DVec3::new(x, (x * 1.3).sin(), 0.0) + 0.01 * rng.in_ball(1.0)).collect();
        let (s, error) = fit(&pts, 0.04, 1000).expect("fits");
        assert!(error <= 0.04);
        assert!(s.control_points.len() <= 12, "{} control points follow the noise", s.control_points.len());
    }

    #[test]
    fn a_zigzag_finer_than_the_tolerance_allows_has_no_spline() {
        let pts: Vec<DVec3> = (0..40).map(|k| DVec3::new(k as f64, (k % 2) as f64, 0.0)).collect();
        assert!(fit(&pts, 0.01, 1000).is_none());
        // With room to be its own polyline's shape, it still cannot bend at every vertex.
        assert!(fit(&pts, 0.01, 8).is_none());
    }
}
