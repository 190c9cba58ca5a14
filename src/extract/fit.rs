//! Small, allocation-free fits: weighted PCA (planes, lines) and bivariate quadratics over a
//! plane, plus the implicit form of a fitted surface for Newton projection.

use glam::DVec3;
use nalgebra::{Matrix3, Matrix6, Vector6};

/// Principal components of a weighted point set: eigenvalues in decreasing order with their
/// unit eigenvectors.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pca {
    /// Weighted mean.
    pub mean: DVec3,
    /// Eigenvalues of the covariance, largest first.
    pub values: [f64; 3],
    /// Matching unit eigenvectors.
    pub vectors: [DVec3; 3],
}

impl Pca {
    /// PCA of `(point, weight)` pairs; None if the total weight is zero.
    pub(crate) fn of(points: impl Iterator<Item = (DVec3, f64)> + Clone) -> Option<Pca> {
        let (mut sw, mut sp) = (0.0, DVec3::ZERO);
        for (p, w) in points.clone() {
            sw += w;
            sp += p * w;
        }
        if sw <= 0.0 {
            return None;
        }
        let mean = sp / sw;
        let mut c = [0.0f64; 6];
        for (p, w) in points {
            let d = p - mean;
            c[0] += w * d.x * d.x;
            c[1] += w * d.x * d.y;
            c[2] += w * d.x * d.z;
            c[3] += w * d.y * d.y;
            c[4] += w * d.y * d.z;
            c[5] += w * d.z * d.z;
        }
        // (An iterative solver, see `symmetric_eigen3`. glamx's closed form was tried: about 10%
        // faster overall, but with it the curves depended on how a cloud was split into files,
        // even with canonical eigenvector signs, and its fallback axis broke exactly collinear
        // points.)
        Some(Pca::from_covariance(mean, c.map(|x| x / sw)))
    }

    /// As [`Pca::of`], in one pass over the points instead of two: the moments are taken
    /// about `centre`, which should lie among the points (for example the query point of a
    /// neighbourhood), so that the covariance loses no more than a few digits to cancellation.
    pub(crate) fn of_near(points: impl Iterator<Item = (DVec3, f64)>, centre: DVec3) -> Option<Pca> {
        let (mut sw, mut sd) = (0.0, DVec3::ZERO);
        let mut c = [0.0f64; 6];
        for (p, w) in points {
            let d = p - centre;
            let wd = d * w;
            sw += w;
            sd += wd;
            c[0] += wd.x * d.x;
            c[1] += wd.x * d.y;
            c[2] += wd.x * d.z;
            c[3] += wd.y * d.y;
            c[4] += wd.y * d.z;
            c[5] += wd.z * d.z;
        }
        if sw <= 0.0 {
            return None;
        }
        let m = sd / sw;
        let c = [c[0] / sw - m.x * m.x, c[1] / sw - m.x * m.y, c[2] / sw - m.x * m.z, c[3] / sw - m.y * m.y, c[4] / sw - m.y * m.z, c[5] / sw - m.z * m.z];
        Some(Pca::from_covariance(centre + m, c))
    }

    /// Eigen-decomposition of the covariance `c` (upper triangle: xx, xy, xz, yy, yz, zz).
    fn from_covariance(mean: DVec3, c: [f64; 6]) -> Pca {
        let (values, vectors) = symmetric_eigen3(c);
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
        // (Rounding can leave a zero eigenvalue slightly negative, or out of order with another.)
        let a = values[idx[0]].max(0.0);
        let b = values[idx[1]].clamp(0.0, a);
        let c = values[idx[2]].clamp(0.0, b);
        Pca { mean, values: [a, b, c], vectors: idx.map(|i| vectors[i].normalize_or_zero()) }
    }

    /// Normal of the best-fitting plane (smallest component).
    pub(crate) fn normal(&self) -> DVec3 {
        self.vectors[2]
    }

    /// Direction of the best-fitting line (largest component).
    pub(crate) fn axis(&self) -> DVec3 {
        self.vectors[0]
    }

    /// Linearity l0 / (l0 + l1 + l2), in [1/3, 1].
    pub(crate) fn linearity(&self) -> f64 {
        let s = self.values.iter().sum::<f64>();
        if s > 0.0 {
            self.values[0] / s
        } else {
            0.0
        }
    }

    /// Rotation-invariant line measure (l0 - l1) / (l0 + l1), in [0, 1].
    pub(crate) fn line_measure(&self) -> f64 {
        let s = self.values[0] + self.values[1];
        if s > 0.0 {
            (self.values[0] - self.values[1]) / s
        } else {
            0.0
        }
    }
}

/// Eigenvalues and unit eigenvectors of the symmetric 3x3 matrix with upper triangle `c`
/// (xx, xy, xz, yy, yz, zz), unordered, by cyclic Jacobi rotations.
///
/// Jacobi is backward stable and finds small eigenvalues to high relative accuracy, as
/// nalgebra's general QR solver does, and its results move continuously with the matrix
/// (closed forms do not: see [`Pca::of`]). Written out for 3x3, it took 7 % of the CPU samples of
/// a run where nalgebra's took 10 %: every point's fit and every seed of the projection takes a
/// PCA.
pub(crate) fn symmetric_eigen3(c: [f64; 6]) -> ([f64; 3], [DVec3; 3]) {
    let mut a = [[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]];
    // Columns of v are the eigenvectors.
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..32 {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = a[p][q];
            // Negligible against the diagonal entries (nalgebra's test): rotating would change
            // them by no more than their last bits.
            if apq.abs() <= f64::EPSILON * (a[p][p].abs() + a[q][q].abs()) || apq == 0.0 {
                a[p][q] = 0.0;
                a[q][p] = 0.0;
                continue;
            }
            rotated = true;
            // The rotation that zeroes a[p][q]: t = tan(angle), the smaller root.
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = if theta.abs() > 1e150 { 0.5 / theta } else { theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt()) };
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            a[p][p] -= t * apq;
            a[q][q] += t * apq;
            a[p][q] = 0.0;
            a[q][p] = 0.0;
            let r = 3 - p - q;
            let (arp, arq) = (a[r][p], a[r][q]);
            a[r][p] = cs * arp - sn * arq;
            a[p][r] = a[r][p];
            a[r][q] = sn * arp + cs * arq;
            a[q][r] = a[r][q];
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = cs * vp - sn * vq;
                row[q] = sn * vp + cs * vq;
            }
        }
        if !rotated {
            break;
        }
    }
    let col = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]);
    ([a[0][0], a[1][1], a[2][2]], [col(0), col(1), col(2)])
}

/// An orthonormal frame: origin, two tangent axes and a normal.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Frame {
    /// Origin.
    pub o: DVec3,
    /// First tangent axis.
    pub u: DVec3,
    /// Second tangent axis.
    pub v: DVec3,
    /// Normal.
    pub n: DVec3,
}

impl Frame {
    /// A frame at `o` with normal `n` (unit).
    pub(crate) fn new(o: DVec3, n: DVec3) -> Frame {
        let u = n.any_orthonormal_vector();
        Frame { o, u, v: n.cross(u), n }
    }

    /// Local coordinates of `p`.
    #[inline]
    pub(crate) fn local(&self, p: DVec3) -> DVec3 {
        let d = p - self.o;
        DVec3::new(d.dot(self.u), d.dot(self.v), d.dot(self.n))
    }
}

/// A height function w = a0 + a1 u + a2 v + a3 u^2 + a4 uv + a5 v^2 over a frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Quadric {
    /// The frame.
    pub frame: Frame,
    /// Coefficients.
    pub a: [f64; 6],
}

impl Quadric {
    /// The flat surface of a frame (the plane itself).
    pub(crate) fn plane(frame: Frame) -> Quadric {
        Quadric { frame, a: [0.0; 6] }
    }

    /// True if the surface is its frame's plane.
    pub(crate) fn is_plane(&self) -> bool {
        self.a == [0.0; 6]
    }

    /// Height of the surface above (u, v).
    #[inline]
    pub(crate) fn height(&self, u: f64, v: f64) -> f64 {
        let a = &self.a;
        a[0] + a[1] * u + a[2] * v + a[3] * u * u + a[4] * u * v + a[5] * v * v
    }

    /// Signed distance along the frame normal from the surface to `p` (the implicit function).
    #[inline]
    pub(crate) fn value(&self, p: DVec3) -> f64 {
        // (A plane's height is zero: its value is the normal coordinate alone, the same number.)
        if self.is_plane() {
            return (p - self.frame.o).dot(self.frame.n);
        }
        let l = self.frame.local(p);
        l.z - self.height(l.x, l.y)
    }

    /// Gradient of [`Quadric::value`] at `p` (not normalised).
    #[inline]
    pub(crate) fn gradient(&self, p: DVec3) -> DVec3 {
        let l = self.frame.local(p);
        let a = &self.a;
        let gu = a[1] + 2.0 * a[3] * l.x + a[4] * l.y;
        let gv = a[2] + a[4] * l.x + 2.0 * a[5] * l.y;
        self.frame.n - self.frame.u * gu - self.frame.v * gv
    }

    /// Unit surface normal at `p`.
    pub(crate) fn normal(&self, p: DVec3) -> DVec3 {
        self.gradient(p).normalize_or_zero()
    }

    /// The direction of strongest curvature, as an angle from the frame's u axis towards v:
    /// the eigenvector of the height function's Hessian with the larger |eigenvalue|.
    pub(crate) fn strongest_curvature_angle(&self) -> f64 {
        let a = &self.a;
        let (huu, huv, hvv) = (2.0 * a[3], a[4], 2.0 * a[5]);
        let phi = 0.5 * (2.0 * huv).atan2(huu - hvv);
        let root = ((huu - hvv).powi(2) + 4.0 * huv * huv).sqrt();
        let (l1, l2) = (0.5 * (huu + hvv + root), 0.5 * (huu + hvv - root));
        if l1.abs() >= l2.abs() {
            phi
        } else {
            phi + std::f64::consts::FRAC_PI_2
        }
    }

    /// Weighted least-squares fit of heights over `frame` to `(point, weight)` pairs. The
    /// curvature terms are damped by `ridge` (relative to the data's spread) so that a
    /// one-sided or sparse neighbourhood falls back smoothly towards a plane.
    pub(crate) fn fit(frame: Frame, points: impl Iterator<Item = (DVec3, f64)>, ridge: f64) -> Option<Quadric> {
        Quadric::fit_over_plane(frame, points, ridge).0
    }

    /// As [`Quadric::fit`], also returning the weighted sum of squared heights over the
    /// frame's plane (the plane's residual sum of squares, summed in the points' order), which
    /// the same pass over the points gives.
    pub(crate) fn fit_over_plane(frame: Frame, points: impl Iterator<Item = (DVec3, f64)>, ridge: f64) -> (Option<Quadric>, f64) {
        // The normal equations' entries are weighted moments of the local coordinates,
        // sum w x^a y^b (a + b <= 4, 15 of them for the 21 entries of the upper triangle),
        // and sum w z x^a y^b (a + b <= 2) on the right: about half the products of
        // accumulating `row * row^T * w` entry by entry.
        let [mut m00, mut m10, mut m01, mut m20, mut m11, mut m02] = [0.0f64; 6];
        let [mut m30, mut m21, mut m12, mut m03] = [0.0f64; 4];
        let [mut m40, mut m31, mut m22, mut m13, mut m04] = [0.0f64; 5];
        let mut b = [0.0f64; 6];
        let mut plane_rss = 0.0;
        for (p, w) in points {
            let l = frame.local(p);
            let (x, y) = (l.x, l.y);
            let (xx, xy, yy) = (x * x, x * y, y * y);
            let (wx, wy) = (w * x, w * y);
            let (wxx, wxy, wyy) = (wx * x, wx * y, wy * y);
            m00 += w;
            m10 += wx;
            m01 += wy;
            m20 += wxx;
            m11 += wxy;
            m02 += wyy;
            m30 += wxx * x;
            m21 += wxx * y;
            m12 += wxy * y;
            m03 += wyy * y;
            m40 += wxx * xx;
            m31 += wxx * xy;
            m22 += wxx * yy;
            m13 += wxy * yy;
            m04 += wyy * yy;
            let wz = w * l.z;
            plane_rss += wz * l.z;
            b[0] += wz;
            b[1] += wz * x;
            b[2] += wz * y;
            b[3] += wz * xx;
            b[4] += wz * xy;
            b[5] += wz * yy;
        }
        let sw = m00;
        if sw <= 0.0 {
            return (None, plane_rss);
        }
        let scale2 = m20 + m02;
        #[rustfmt::skip]
        let mut m = Matrix6::new(
            m00, m10, m01, m20, m11, m02,
            m10, m20, m11, m30, m21, m12,
            m01, m11, m02, m21, m12, m03,
            m20, m30, m21, m40, m31, m22,
            m11, m21, m12, m31, m22, m13,
            m02, m12, m03, m22, m13, m04,
        );
        let b = Vector6::from(b);
        let s2 = (scale2 / sw).max(1e-300);
        for i in 3..6 {
            m[(i, i)] += ridge * sw * s2 * s2;
        }
        for i in 1..3 {
            m[(i, i)] += 1e-12 * sw * s2;
        }
        let Some(x) = m.cholesky().map(|c| c.solve(&b)) else { return (None, plane_rss) };
        (Some(Quadric { frame, a: [x[0], x[1], x[2], x[3], x[4], x[5]] }), plane_rss)
    }
}

/// Newton projection of `p` onto the intersection curve of two surfaces: repeatedly moves
/// by the minimum-norm step that zeroes both linearised functions. Returns None if the
/// surfaces are (nearly) tangent there or the iteration does not settle.
pub(crate) fn project_to_intersection(p: DVec3, s1: &Quadric, s2: &Quadric, tol: f64) -> Option<DVec3> {
    let mut x = p;
    for _ in 0..12 {
        let (f1, f2) = (s1.value(x), s2.value(x));
        let (g1, g2) = (s1.gradient(x), s2.gradient(x));
        // Solve J J^T y = f with J = [g1; g2]; step = J^T y.
        let (a, b, d) = (g1.dot(g1), g1.dot(g2), g2.dot(g2));
        let det = a * d - b * b;
        if det <= 1e-12 * a * d {
            return None;
        }
        let y1 = (d * f1 - b * f2) / det;
        let y2 = (a * f2 - b * f1) / det;
        let step = g1 * y1 + g2 * y2;
        x -= step;
        if !x.is_finite() {
            return None;
        }
        if step.length() < tol {
            return Some(x);
        }
    }
    None
}

/// The point nearest to `p` on which three surfaces meet (Newton on the 3x3 system).
pub(crate) fn project_to_corner(p: DVec3, s: [&Quadric; 3], tol: f64) -> Option<DVec3> {
    let mut x = p;
    for _ in 0..12 {
        let f = DVec3::new(s[0].value(x), s[1].value(x), s[2].value(x));
        let g = s.map(|q| q.gradient(x));
        let m = Matrix3::new(g[0].x, g[0].y, g[0].z, g[1].x, g[1].y, g[1].z, g[2].x, g[2].y, g[2].z);
        // Reject near-singular systems: the three normals must span space.
        if m.determinant().abs() < 0.05 * g[0].length() * g[1].length() * g[2].length() {
            return None;
        }
        let step = m.lu().solve(&nalgebra::Vector3::new(f.x, f.y, f.z))?;
        let step = DVec3::new(step[0], step[1], step[2]);
        x -= step;
        if step.length() < tol {
            return Some(x);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pca_of_a_line() {
        let pts: Vec<(DVec3, f64)> = (0..10).map(|i| (DVec3::new(i as f64, 2.0 * i as f64, 0.0), 1.0)).collect();
        let p = Pca::of(pts.iter().copied()).unwrap();
        assert!((p.axis().dot(DVec3::new(1.0, 2.0, 0.0).normalize()).abs() - 1.0).abs() < 1e-9);
        assert!(p.linearity() > 0.999);
    }

    #[test]
    fn pca_is_an_eigen_decomposition_at_any_scale_and_shape() {
        // Planes, lines and blobs, at scales from micrometres to kilometres.
        let mut rng = crate::rng::Rng::stream(7, 0);
        for case in 0..600 {
            let scale = 10f64.powi(case % 10 - 6);
            // (Exact lines and planes, axis-aligned in every third case, have double or
            // zero eigenvalues.)
            let spread = [DVec3::new(1.0, 1.0, 0.01), DVec3::new(1.0, 0.01, 0.01), DVec3::ONE, DVec3::new(1.0, 1.0, 1e-6), DVec3::X, DVec3::new(1.0, 1.0, 0.0)]
                [case as usize % 6];
            let n = if case % 3 == 0 { DVec3::Z } else { DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5).normalize() };
            let axes = Frame::new(DVec3::ZERO, n);
            let pts: Vec<(DVec3, f64)> = (0..40)
                .map(|_| {
                    let l = DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5) * spread * scale;
                    (axes.u * l.x + axes.v * l.y + axes.n * l.z + DVec3::splat(3.0 * scale), 1.0)
                })
                .collect();
            // (One pass about a point of the set, as the candidate fits take it, or two.)
            for p in [Pca::of(pts.iter().copied()).unwrap(), Pca::of_near(pts.iter().copied(), pts[7].0).unwrap()] {
                let cov = |v: DVec3| pts.iter().map(|&(q, _)| (q - p.mean) * (q - p.mean).dot(v)).sum::<DVec3>() / pts.len() as f64;
                let total: f64 = p.values.iter().sum();
                assert!(p.values[0] >= p.values[1] && p.values[1] >= p.values[2], "{:?}", p.values);
                for k in 0..3 {
                    let v = p.vectors[k];
                    assert!((v.length() - 1.0).abs() < 1e-9);
                    // Vectors to 1e-9; values (closed form) to 1e-7, as a double root of the
                    // characteristic cubic is only found to about the square root of the precision.
                    let rayleigh = v.dot(cov(v));
                    assert!((cov(v) - v * rayleigh).length() <= 1e-9 * total, "case {case}: component {k}");
                    assert!((rayleigh - p.values[k]).abs() <= 1e-7 * total, "case {case}: value {k}");
                    assert!(v.dot(p.vectors[(k + 1) % 3]).abs() < 1e-6, "case {case}: not orthogonal");
                }
            }
        }
    }

    #[test]
    fn quadric_fits_a_paraboloid_and_newton_meets_two_planes() {
        let f = Frame::new(DVec3::ZERO, DVec3::Z);
        let pts: Vec<(DVec3, f64)> = (0..100)
            .map(|i| {
                let (u, v) = ((i % 10) as f64 * 0.1 - 0.5, (i / 10) as f64 * 0.1 - 0.5);
                let l = f.u * u + f.v * v;
                (l + f.n * (0.3 * u * u - 0.2 * u * v + 0.1), 1.0)
            })
            .collect();
        let q = Quadric::fit(f, pts.iter().copied(), 0.0).unwrap();
        for &(p, _) in &pts {
            assert!(q.value(p).abs() < 1e-9);
        }
        let a = Quadric::plane(Frame::new(DVec3::ZERO, DVec3::X));
        let b = Quadric::plane(Frame::new(DVec3::ZERO, DVec3::Y));
        let e = project_to_intersection(DVec3::new(0.3, -0.2, 0.7), &a, &b, 1e-12).unwrap();
        assert!((e - DVec3::new(0.0, 0.0, 0.7)).length() < 1e-9);
        let c = Quadric::plane(Frame::new(DVec3::new(0.0, 0.0, 0.25), DVec3::Z));
        let k = project_to_corner(DVec3::new(0.1, 0.1, 0.1), [&a, &b, &c], 1e-12).unwrap();
        assert!((k - DVec3::new(0.0, 0.0, 0.25)).length() < 1e-9);
    }
}
