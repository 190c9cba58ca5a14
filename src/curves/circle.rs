//! Least-squares circles of a curve's vertices: a closed curve's, through its first vertex, and
//! an arc's, through both its end vertices. A circle through three vertices carries the noise of
//! those three into its centre and radius; one fitted over every vertex averages it away, so it
//! holds within the tolerance where the three-vertex one breaks. It keeps the end vertices on it
//! so that the piece, like every other, starts and ends on a vertex of its curve.

use glam::{DVec2, DVec3};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

/// Gauss-Newton steps at most; each is a pass over the vertices, and a fit started from the
/// algebraic circle settles in a handful.
const MAX_STEPS: usize = 16;

/// The circle through `pts[0]` nearest the other points in the least-squares sense (sum of
/// squared distances within the plane through `pts[0]` that they lie closest to): (centre, unit
/// axis, radius), the axis turning from `pts[0]` towards `pts[n / 3]` counterclockwise. None
/// where the points are (nearly) on one line.
pub(crate) fn fit_circle(pts: &[DVec3]) -> Option<(DVec3, DVec3, f64)> {
    let o = pts[0];
    let n = plane_through(o, pts)?;
    let (u, w) = n.any_orthonormal_pair();
    let flat: Vec<DVec2> = pts[1..].iter().map(|&p| p - o).map(|d| DVec2::new(d.dot(u), d.dot(w))).collect();
    // The circle through the origin: its centre c alone, the radius |c|.
    let mut c = kasa_through_origin(&flat)?;
    for _ in 0..MAX_STEPS {
        let r = c.length();
        // Normal equations of the residuals |q - c| - |c| in c.
        let (mut jtj, mut jtr) = (Matrix2::<f64>::zeros(), Vector2::<f64>::zeros());
        for &q in &flat {
            let d = q - c;
            let len = d.length();
            if len == 0.0 || r == 0.0 {
                return None;
            }
            let j = Vector2::new(-d.x / len - c.x / r, -d.y / len - c.y / r);
            jtj += j * j.transpose();
            jtr += j * (len - r);
        }
        let step = jtj.lu().solve(&jtr)?;
        c -= DVec2::new(step.x, step.y);
        if !c.is_finite() {
            return None;
        }
        if step.norm() <= 1e-12 * r {
            break;
        }
    }
    let centre = o + c.x * u + c.y * w;
    Some((centre, oriented(n, centre, o, pts[pts.len() / 3]), c.length()))
}

/// The circle through the end points of `pts` nearest the others in the least-squares sense
/// (within the plane through both ends that they lie closest to): (centre, unit axis, radius),
/// the axis turning from the first point towards the middle one counterclockwise. None where the
/// points are (nearly) on one line or the ends coincide.
pub(crate) fn fit_arc(pts: &[DVec3]) -> Option<(DVec3, DVec3, f64)> {
    let (a, b) = (pts[0], *pts.last()?);
    let chord = (b - a).normalize_or_zero();
    let n = plane_through(a, pts)?;
    let n = (n - n.dot(chord) * chord).normalize_or_zero();
    if chord == DVec3::ZERO || n == DVec3::ZERO {
        return None;
    }
    // In the plane, about the chord's middle: the ends at (-h, 0) and (h, 0), the centre at
    // (0, s) on the chord's bisector, the radius the hypotenuse of h and s.
    let (mid, w, h) = (0.5 * (a + b), n.cross(chord), 0.5 * a.distance(b));
    let flat: Vec<DVec2> = pts.iter().map(|&p| p - mid).map(|d| DVec2::new(d.dot(chord), d.dot(w))).collect();
    let m = flat[flat.len() / 2];
    let mut s = (m.length_squared() - h * h) / (2.0 * m.y);
    if !s.is_finite() {
        return None;
    }
    for _ in 0..MAX_STEPS {
        let r = s.hypot(h);
        // Normal equations of the residuals |q - (0, s)| - r in s.
        let (mut jtj, mut jtr) = (0.0, 0.0);
        for &q in &flat {
            let len = q.distance(DVec2::new(0.0, s));
            if len == 0.0 {
                return None;
            }
            let j = -(q.y - s) / len - s / r;
            jtj += j * j;
            jtr += j * (len - r);
        }
        let step = jtr / jtj;
        s -= step;
        if !s.is_finite() {
            return None;
        }
        if step.abs() <= 1e-12 * r {
            break;
        }
    }
    let centre = mid + s * w;
    Some((centre, oriented(n, centre, a, pts[pts.len() / 2]), s.hypot(h)))
}

/// The unit normal of the plane through `o` that `pts` lie closest to.
fn plane_through(o: DVec3, pts: &[DVec3]) -> Option<DVec3> {
    let mut m = Matrix3::<f64>::zeros();
    for &p in pts {
        let d = p - o;
        let d = Vector3::new(d.x, d.y, d.z);
        m += d * d.transpose();
    }
    let eigen = m.symmetric_eigen();
    let n = eigen.eigenvectors.column(eigen.eigenvalues.imin());
    let n = DVec3::new(n.x, n.y, n.z).normalize_or_zero();
    (n != DVec3::ZERO).then_some(n)
}

/// The algebraic circle through the origin of planar points (x^2 + y^2 + D x + E y = 0 in
/// least squares): its centre, the start of the geometric fit.
fn kasa_through_origin(q: &[DVec2]) -> Option<DVec2> {
    let (mut m, mut v) = (Matrix2::<f64>::zeros(), Vector2::<f64>::zeros());
    for p in q {
        let row = Vector2::new(p.x, p.y);
        m += row * row.transpose();
        v -= row * p.length_squared();
    }
    let s = m.lu().solve(&v)?;
    let c = DVec2::new(-0.5 * s.x, -0.5 * s.y);
    (c.is_finite() && c != DVec2::ZERO).then_some(c)
}

/// `n` or `-n`: the one about which `from` turns counterclockwise towards `to` round `centre`.
fn oriented(n: DVec3, centre: DVec3, from: DVec3, to: DVec3) -> DVec3 {
    if (from - centre).cross(to - centre).dot(n) >= 0.0 {
        n
    } else {
        -n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(centre: DVec3, r: f64, from: f64, to: f64, n: usize, wobble: f64) -> Vec<DVec3> {
        (0..=n)
            .map(|i| {
                let t = from + (to - from) * i as f64 / n as f64;
                // A deterministic wobble in and out of the circle, and off its plane.
                let s = wobble * if i % 2 == 0 { 1.0 } else { -1.0 };
                centre + DVec3::new((r + s) * t.cos(), (r + s) * t.sin(), 0.5 * s)
            })
            .collect()
    }

    #[test]
    fn a_wobbly_ring_gives_its_circle() {
        let c = DVec3::new(1.0, -2.0, 3.0);
        let pts = ring(c, 5.0, 0.0, 6.0, 60, 0.05);
        let (centre, axis, r) = fit_circle(&pts).unwrap();
        // (Through its first vertex, which sits 0.05 out: the circle follows it by less.)
        assert!((pts[0].distance(centre) - r).abs() < 1e-12);
        assert!(centre.distance(c) < 0.05, "{centre}");
        assert!((r - 5.0).abs() < 0.05, "{r}");
        assert!(axis.z > 0.999, "{axis}");
    }

    #[test]
    fn a_wobbly_arc_gives_its_circle_through_its_ends() {
        let c = DVec3::new(1.0, -2.0, 3.0);
        // (An even count of steps: both ends sit a wobble out, and the circle through them keeps
        // every vertex within two wobbles, where the circle through the ends and the middle
        // vertex, all three out, misses the vertices in by more.)
        for (from, to) in [(0.0, 2.0), (0.5, 5.0)] {
            let pts = ring(c, 5.0, from, to, 40, 0.05);
            let (centre, axis, r) = fit_arc(&pts).unwrap();
            assert!((pts[0].distance(centre) - r).abs() < 1e-12 && (pts[40].distance(centre) - r).abs() < 1e-12);
            let off = |centre: DVec3, r: f64| pts.iter().map(|p| (p.distance(centre) - r).abs()).fold(0.0, f64::max);
            assert!(off(centre, r) < 0.1, "{from}..{to}: {}", off(centre, r));
            assert!(axis.z > 0.99, "{axis}");
        }
    }

    #[test]
    fn collinear_points_have_no_circle() {
        let pts: Vec<DVec3> = (0..10).map(|i| DVec3::new(i as f64, 2.0 * i as f64, 0.0)).collect();
        assert!(fit_circle(&pts).is_none());
        assert!(fit_arc(&pts).is_none());
    }
}
