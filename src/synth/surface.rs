//! Surfaces that can be sampled uniformly by area: triangles, planar polygons with holes
//! (sampled by rejection), height fields, and volumetric scatter (clutter). Curved CAD faces are fine strips of triangles.

use crate::rng::Rng;
use glam::{DVec2, DVec3};

/// A planar frame: world = origin + u * x + v * y.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Frame {
    /// Origin.
    pub origin: DVec3,
    /// First in-plane axis (unit).
    pub x: DVec3,
    /// Second in-plane axis (unit, orthogonal to `x`).
    pub y: DVec3,
}

impl Frame {
    /// Maps plane coordinates to world.
    pub(crate) fn at(&self, p: DVec2) -> DVec3 {
        self.origin + self.x * p.x + self.y * p.y
    }
}

/// A surface piece.
#[derive(Clone, Debug)]
pub(crate) enum Surface {
    /// A triangle.
    Triangle([DVec3; 3]),
    /// A planar region bounded by loops (even-odd rule, so inner loops are holes).
    Polygon {
        /// The plane.
        frame: Frame,
        /// Boundary loops in plane coordinates; the first is the outer one.
        loops: Vec<Vec<DVec2>>,
    },
    /// A height field over a rectangle of a plane, sampled by rejection on the area element.
    HeightField {
        /// The plane; heights go along `frame.x` cross `frame.y`.
        frame: Frame,
        /// Lower corner of the rectangle, in plane coordinates.
        min: DVec2,
        /// Upper corner.
        max: DVec2,
        /// The height function.
        f: fn(DVec2) -> f64,
        /// An upper bound of |grad f|.
        max_slope: f64,
    },
    /// Points scattered through the volume of an ellipsoid (a tree crown: clutter, no surface).
    /// Its "area", which sets its share of the points, is that of a sphere of its mean radius.
    Scatter {
        /// Centre.
        centre: DVec3,
        /// Semi-axes along x, y and z.
        radii: DVec3,
    },
}

fn polygon_area(loops: &[Vec<DVec2>]) -> f64 {
    // Outer loop minus holes: signed areas summed with orientation-free sign convention
    // (first loop positive, the rest negative).
    loops
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let a: f64 = (0..l.len()).map(|i| l[i].perp_dot(l[(i + 1) % l.len()])).sum::<f64>().abs() / 2.0;
            if k == 0 {
                a
            } else {
                -a
            }
        })
        .sum()
}

/// Even-odd point-in-polygon test over all loops.
pub(crate) fn inside(loops: &[Vec<DVec2>], p: DVec2) -> bool {
    let mut c = false;
    for l in loops {
        let n = l.len();
        for i in 0..n {
            let (a, b) = (l[i], l[(i + 1) % n]);
            if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
                c = !c;
            }
        }
    }
    c
}

impl Surface {
    /// Area of the piece.
    pub(crate) fn area(&self) -> f64 {
        match self {
            Surface::Triangle([a, b, c]) => (*b - *a).cross(*c - *a).length() / 2.0,
            Surface::Polygon { loops, .. } => polygon_area(loops),
            Surface::HeightField { min, max, f, .. } => {
                // Midpoint rule on a fine grid: accurate to well below a sampling percent.
                let n = 256;
                let d = (*max - *min) / n as f64;
                let mut s = 0.0;
                for i in 0..n {
                    for j in 0..n {
                        let p = *min + d * DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                        let g = grad(*f, p, d.x.min(d.y) * 0.25);
                        s += (1.0 + g.length_squared()).sqrt();
                    }
                }
                s * d.x * d.y
            }
            Surface::Scatter { radii, .. } => 4.0 * std::f64::consts::PI * (radii.element_sum() / 3.0).powi(2),
        }
    }

    /// One point uniformly distributed over the piece.
    pub(crate) fn sample(&self, rng: &mut Rng) -> DVec3 {
        match self {
            Surface::Triangle([a, b, c]) => {
                let (mut u, mut v) = (rng.f64(), rng.f64());
                if u + v > 1.0 {
                    u = 1.0 - u;
                    v = 1.0 - v;
                }
                *a + (*b - *a) * u + (*c - *a) * v
            }
            Surface::Polygon { frame, loops } => {
                let (lo, hi) = loops[0].iter().fold((DVec2::splat(f64::MAX), DVec2::splat(f64::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
                loop {
                    let p = DVec2::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y));
                    if inside(loops, p) {
                        return frame.at(p);
                    }
                }
            }
            Surface::HeightField { frame, min, max, f, max_slope } => {
                let bound = (1.0 + max_slope * max_slope).sqrt();
                loop {
                    let p = DVec2::new(rng.range(min.x, max.x), rng.range(min.y, max.y));
                    let g = grad(*f, p, 1e-6 * (*max - *min).max_element());
                    if rng.f64() * bound <= (1.0 + g.length_squared()).sqrt() {
                        return frame.at(p) + frame.x.cross(frame.y) * f(p);
                    }
                }
            }
            Surface::Scatter { centre, radii } => *centre + *radii * rng.in_ball(1.0),
        }
    }
}

fn grad(f: fn(DVec2) -> f64, p: DVec2, h: f64) -> DVec2 {
    DVec2::new((f(p + DVec2::X * h) - f(p - DVec2::X * h)) / (2.0 * h), (f(p + DVec2::Y * h) - f(p - DVec2::Y * h)) / (2.0 * h))
}

/// Picks surfaces by area: cumulative area table for sampling.
pub(crate) struct AreaTable {
    cum: Vec<f64>,
}

impl AreaTable {
    /// Builds the table for `surfaces`.
    pub(crate) fn new(surfaces: &[Surface]) -> AreaTable {
        let mut s = 0.0;
        let cum = surfaces
            .iter()
            .map(|x| {
                s += x.area();
                s
            })
            .collect();
        AreaTable { cum }
    }

    /// Total area.
    pub(crate) fn total(&self) -> f64 {
        *self.cum.last().unwrap_or(&0.0)
    }

    /// Index of a surface drawn with probability proportional to its area.
    pub(crate) fn pick(&self, rng: &mut Rng) -> usize {
        let t = rng.f64() * self.total();
        self.cum.partition_point(|&c| c <= t).min(self.cum.len() - 1)
    }
}
