//! Convex or concave: which side of a crease is solid.
//!
//! The points near a crease cannot tell: two half-planes meeting at 90 degrees are the edge of
//! a box or the inside corner of a room. What tells is where the scanner stood, for it saw the
//! surfaces from the air. Each vertex's normals point away from the other surface's side of the
//! crease (see stage 3), which at a convex crease is out of the solid and at a concave one
//! into it. A scanner that saw the crease sees at least one of its surfaces from the front:
//! at a convex crease, one of the normals points towards the scanner; at a concave crease,
//! whose air is the inside of the wedge, neither does. So a vertex is convex if a normal
//! points clearly towards the scanner, concave if both point away from it, and not known
//! where the scanner looks along both surfaces (a wall's corner seen from straight above).

use super::Polyline;
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Which side of a crease is solid.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// The surfaces enclose the solid (a box's edge, a roof's ridge).
    Convex,
    /// The surfaces enclose the air (a room's inside corner, where a wall meets the ground).
    Concave,
    /// Not told: no scanner position is known, or the curve's vertices do not agree.
    #[default]
    Unknown,
}

impl Shape {
    /// The name written in the outputs: `convex`, `concave` or `unknown`.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Convex => "convex",
            Shape::Concave => "concave",
            Shape::Unknown => "unknown",
        }
    }

    /// The code stored for it (in `curves.ply` and the working data): 0 unknown, 1 convex,
    /// 2 concave.
    pub fn code(self) -> u8 {
        match self {
            Shape::Unknown => 0,
            Shape::Convex => 1,
            Shape::Concave => 2,
        }
    }

    /// The shape of a stored code (unknown for any other).
    pub(crate) fn of_code(code: u8) -> Shape {
        match code {
            1 => Shape::Convex,
            2 => Shape::Concave,
            _ => Shape::Unknown,
        }
    }
}

/// Where the scanners saw the surfaces from: what tells convex from concave.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Outside {
    /// Not known: every curve is [`Shape::Unknown`].
    #[default]
    Unknown,
    /// From above, far away (airborne lidar, and terrain seen from above): +z.
    Up,
    /// From these scanner positions (E57 scan poses, or given): each vertex takes the nearest.
    /// The nearest scanner is not always one that saw the vertex; where it is not, the vertex
    /// may be read the wrong way.
    Scanners(Vec<DVec3>),
}

/// How clearly a normal must point towards the scanner (or both away from it) for a vertex to
/// count: the cosine of 80 degrees, so that a surface seen within 10 degrees of grazing, whose
/// normal noise may tip either way, does not decide.
const CLEAR: f64 = 0.17;

impl Outside {
    /// The unit direction from `p` towards the scanner, if one is known.
    fn towards_scanner(&self, p: DVec3) -> Option<DVec3> {
        match self {
            Outside::Unknown => None,
            Outside::Up => Some(DVec3::Z),
            Outside::Scanners(s) => {
                let nearest = s.iter().min_by(|a, b| a.distance_squared(p).total_cmp(&b.distance_squared(p)))?;
                (*nearest - p).try_normalize()
            }
        }
    }

    /// The shape of the crease along `curve`: the shape that more than half of its vertices
    /// with normals (corners aside) read, else unknown.
    ///
    /// ```
    /// use crease::curves::{Outside, Polyline, Shape, Vertex};
    /// use glam::{DVec3, Vec3};
    /// // A roof's ridge along x: the normals point up the two slopes' outer sides.
    /// let n = [Vec3::new(0.0, 0.6, 0.8), Vec3::new(0.0, -0.6, 0.8)];
    /// let mut ridge = Polyline::from_points(0, [DVec3::ZERO, DVec3::X]);
    /// ridge.vertices.iter_mut().for_each(|v| v.n = n);
    /// assert_eq!(Outside::Up.shape(&ridge), Shape::Convex);
    /// assert_eq!(Outside::Unknown.shape(&ridge), Shape::Unknown);
    /// ```
    pub fn shape(&self, curve: &Polyline) -> Shape {
        if *self == Outside::Unknown {
            return Shape::Unknown;
        }
        let (mut convex, mut concave, mut with_normals) = (0usize, 0usize, 0usize);
        for v in curve.vertices.iter().filter(|v| !v.corner && v.n[0] != glam::Vec3::ZERO && v.n[1] != glam::Vec3::ZERO) {
            with_normals += 1;
            let Some(s) = self.towards_scanner(v.p) else { continue };
            let [a, b] = v.n.map(|n| n.as_dvec3().dot(s));
            if a.max(b) > CLEAR {
                convex += 1;
            } else if a + b < -CLEAR {
                concave += 1;
            }
        }
        match (2 * convex > with_normals, 2 * concave > with_normals) {
            (true, _) => Shape::Convex,
            (_, true) => Shape::Concave,
            _ => Shape::Unknown,
        }
    }

    /// Labels every curve of `curves` with its [`Outside::shape`].
    pub(crate) fn label(&self, curves: &mut [Polyline]) {
        use rayon::prelude::*;
        curves.par_iter_mut().for_each(|c| c.shape = self.shape(c));
    }

    /// The outside as `--outside` takes it: `up`, `unknown`, or scanner positions `X,Y,Z`
    /// separated by `;`.
    pub fn parse(s: &str) -> Result<Outside, String> {
        match s.trim() {
            "up" => return Ok(Outside::Up),
            "unknown" | "none" => return Ok(Outside::Unknown),
            _ => {}
        }
        let position = |p: &str| -> Result<DVec3, String> {
            let c: Vec<f64> = p.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| format!("{p}: not a number"))?;
            match c[..] {
                [x, y, z] if c.iter().all(|v| v.is_finite()) => Ok(DVec3::new(x, y, z)),
                _ => Err(format!("{p}: a scanner position is X,Y,Z (three finite numbers)")),
            }
        };
        let scanners: Vec<DVec3> = s.split(';').filter(|p| !p.trim().is_empty()).map(position).collect::<Result<_, _>>()?;
        if scanners.is_empty() {
            return Err("give up, unknown, or scanner positions X,Y,Z separated by ;".into());
        }
        Ok(Outside::Scanners(scanners))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curves::Vertex;
    use glam::Vec3;

    /// A straight crease along y through `at` whose normals (oriented away from each other's
    /// half-surface) are `n`.
    fn crease(at: DVec3, n: [Vec3; 2]) -> Polyline {
        let vertices = (0..5).map(|i| Vertex { p: at + DVec3::Y * i as f64 * 0.1, n, corner: false }).collect();
        Polyline { vertices, ..Polyline::from_points(0, []) }
    }

    #[test]
    fn a_box_edge_is_convex_and_an_inside_corner_concave() {
        // The edge of a box [0,1]^3 at x = 1, z = 1, seen from a scanner at (3, 0.2, 3): top and
        // side, normals out of the solid.
        let edge = crease(DVec3::new(1.0, 0.0, 1.0), [Vec3::Z, Vec3::X]);
        // The inside corner of an L whose floor is z = 0 (x > 1) and wall x = 1 (z > 0): the
        // normals point away from the other half-surface, into the solid.
        let corner = crease(DVec3::new(1.0, 0.0, 0.0), [-Vec3::Z, -Vec3::X]);
        let scanner = Outside::Scanners(vec![DVec3::new(3.0, 0.2, 3.0)]);
        assert_eq!(scanner.shape(&edge), Shape::Convex);
        assert_eq!(scanner.shape(&corner), Shape::Concave);
        // Seen from above, both read the same; a scanner that sees only the box's top does too.
        assert_eq!(Outside::Up.shape(&edge), Shape::Convex);
        assert_eq!(Outside::Up.shape(&corner), Shape::Concave);
        assert_eq!(Outside::Scanners(vec![DVec3::new(-3.0, 0.2, 3.0)]).shape(&edge), Shape::Convex);
    }

    #[test]
    fn a_vertical_crease_seen_from_above_is_not_told() {
        // A building's corner: both normals horizontal.
        let corner = crease(DVec3::ZERO, [Vec3::X, Vec3::Y]);
        assert_eq!(Outside::Up.shape(&corner), Shape::Unknown);
        // Without normals, nothing is told either.
        assert_eq!(Outside::Up.shape(&crease(DVec3::ZERO, [Vec3::ZERO; 2])), Shape::Unknown);
    }

    #[test]
    fn each_vertex_takes_the_nearest_scanner() {
        let edge = crease(DVec3::new(1.0, 0.0, 1.0), [Vec3::Z, Vec3::X]);
        // The near scanner sees the box's top and side; the far one, under the box on the
        // other side, sees neither, and would read the edge as concave.
        let scanners = vec![DVec3::new(-20.0, 0.0, -20.0), DVec3::new(3.0, 0.0, 3.0)];
        assert_eq!(Outside::Scanners(scanners).shape(&edge), Shape::Convex);
        assert_eq!(Outside::Scanners(vec![DVec3::new(-20.0, 0.0, -20.0)]).shape(&edge), Shape::Concave);
    }

    #[test]
    fn outside_parses_up_and_scanner_positions() {
        assert_eq!(Outside::parse("up"), Ok(Outside::Up));
        assert_eq!(Outside::parse("1,2,3; 4,5,6"), Ok(Outside::Scanners(vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 5.0, 6.0)])));
        for bad in ["1,2", "1,2,x", "", ";", "1,2,inf"] {
            assert!(Outside::parse(bad).is_err(), "{bad}");
        }
    }
}
