//! CAD-like shapes with analytically known sharp edges.

use super::surface::{Frame, Surface};
use glam::{DVec2, DVec3};

/// Surfaces to sample and the exact feature polylines.
#[derive(Clone, Debug, Default)]
pub struct Shape {
    /// Surface pieces, sampled by area.
    pub(crate) surfaces: Vec<Surface>,
    /// Ground-truth feature curves (closed curves repeat their first vertex).
    pub truth: Vec<Vec<DVec3>>,
}

/// Names accepted by [`shape`].
pub const SHAPES: &[&str] = &["cube", "chamfer", "holecube", "cylinder", "step", "octahedron", "fandisk", "wedge", "plate", "blade"];

/// Segments per full circle for arcs (chord error 1e-4 of the radius).
const CIRCLE_SEGMENTS: usize = 256;
/// A profile vertex turning by more than this (degrees) is a sharp edge of the prism.
const SHARP_TURN_DEG: f64 = 20.0;

/// Builds shape `name`; `angle` is the wedge's dihedral angle in degrees.
pub fn shape(name: &str, angle: f64) -> Option<Shape> {
    let sq = |a: f64, b: f64| vec![DVec2::new(a, a), DVec2::new(b, a), DVec2::new(b, b), DVec2::new(a, b)];
    Some(match name {
        "cube" => prism(&[sq(0.0, 1.0)], 1.0),
        "chamfer" => prism(&[vec![DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(1.0, 0.75), DVec2::new(0.75, 1.0), DVec2::new(0.0, 1.0)]], 1.0),
        "holecube" => prism(&[sq(0.0, 1.0), circle(DVec2::splat(0.5), 0.25)], 1.0),
        "cylinder" => prism(&[circle(DVec2::ZERO, 0.5)], 1.0),
        "step" => prism(
            &[vec![DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(1.0, 0.4), DVec2::new(0.4, 0.4), DVec2::new(0.4, 1.0), DVec2::new(0.0, 1.0)]],
            1.0,
        ),
        "octahedron" => octahedron(),
        "fandisk" => fandisk(),
        "wedge" => wedge(angle),
        "plate" => plate(),
        "blade" => blade(),
        _ => return None,
    })
}

fn circle(c: DVec2, r: f64) -> Vec<DVec2> {
    arc(c, r, 0.0, std::f64::consts::TAU, CIRCLE_SEGMENTS, false)
}

/// Points on an arc from angle a0 to a1 (radians), `n` segments; `closed_end` includes a1.
fn arc(c: DVec2, r: f64, a0: f64, a1: f64, n: usize, closed_end: bool) -> Vec<DVec2> {
    let m = if closed_end { n + 1 } else { n };
    (0..m)
        .map(|i| {
            let a = a0 + (a1 - a0) * i as f64 / n as f64;
            c + DVec2::new(a.cos(), a.sin()) * r
        })
        .collect()
}

fn sharp_vertices(l: &[DVec2]) -> Vec<bool> {
    let n = l.len();
    (0..n)
        .map(|i| {
            let a = (l[i] - l[(i + n - 1) % n]).normalize();
            let b = (l[(i + 1) % n] - l[i]).normalize();
            a.dot(b).clamp(-1.0, 1.0).acos().to_degrees() > SHARP_TURN_DEG
        })
        .collect()
}

/// A prism: profile loops in the xy plane (first outer, then holes) extruded along z from 0
/// to `len`. Sharp edges: the extrusion lines of sharp profile vertices and both cap outlines
/// (split at sharp vertices).
pub(crate) fn prism(loops: &[Vec<DVec2>], len: f64) -> Shape {
    let mut s = Shape::default();
    let lift = |p: DVec2, z: f64| DVec3::new(p.x, p.y, z);
    for cap_z in [0.0, len] {
        let frame = Frame { origin: DVec3::new(0.0, 0.0, cap_z), x: DVec3::X, y: DVec3::Y };
        s.surfaces.push(Surface::Polygon { frame, loops: loops.to_vec() });
    }
    for l in loops {
        let n = l.len();
        for i in 0..n {
            let (a, b) = (l[i], l[(i + 1) % n]);
            s.surfaces.push(Surface::Triangle([lift(a, 0.0), lift(b, 0.0), lift(b, len)]));
            s.surfaces.push(Surface::Triangle([lift(a, 0.0), lift(b, len), lift(a, len)]));
        }
        let sharp = sharp_vertices(l);
        for i in 0..n {
            if sharp[i] {
                s.truth.push(vec![lift(l[i], 0.0), lift(l[i], len)]);
            }
        }
        for z in [0.0, len] {
            s.truth.extend(split_loop(l, &sharp).into_iter().map(|pl| pl.into_iter().map(|p| lift(p, z)).collect()));
        }
    }
    s
}

/// Splits a closed loop at its sharp vertices into open polylines; a loop with no sharp vertex
/// becomes one closed polyline (first vertex repeated at the end).
fn split_loop(l: &[DVec2], sharp: &[bool]) -> Vec<Vec<DVec2>> {
    let n = l.len();
    let Some(start) = (0..n).find(|&i| sharp[i]) else {
        let mut c = l.to_vec();
        c.push(l[0]);
        return vec![c];
    };
    let mut out = vec![];
    let mut cur = vec![l[start]];
    for k in 1..=n {
        let i = (start + k) % n;
        cur.push(l[i]);
        if sharp[i] {
            out.push(std::mem::replace(&mut cur, vec![l[i]]));
        }
    }
    out
}

/// A thin plate (1 x 0.7, 0.05 thick: 0.04 of its diagonal) with a bore and two slots as
/// narrow as the plate is thick: features a few noise radii apart under noise.
fn plate() -> Shape {
    let rect = |x0: f64, y0: f64, x1: f64, y1: f64| vec![DVec2::new(x0, y0), DVec2::new(x1, y0), DVec2::new(x1, y1), DVec2::new(x0, y1)];
    prism(&[rect(0.0, 0.0, 1.0, 0.7), circle(DVec2::new(0.25, 0.35), 0.1), rect(0.5, 0.15, 0.9, 0.2), rect(0.5, 0.5, 0.9, 0.55)], 0.05)
}

/// A blade: a lens-shaped section (two circular arcs, chord 1, 0.1 thick in the middle)
/// extruded by 0.6; its two knife edges are 23 degree wedges, and towards them the two faces'
/// cap outlines converge.
fn blade() -> Shape {
    let (half, sagitta): (f64, f64) = (0.5, 0.05);
    let radius = (half * half + sagitta * sagitta) / (2.0 * sagitta);
    let beta = (half / radius).asin();
    let up = std::f64::consts::FRAC_PI_2;
    // Upper arc from (0, 0) to (1, 0), then the lower one back.
    let mut profile = arc(DVec2::new(half, sagitta - radius), radius, up + beta, up - beta, 128, false);
    profile.extend(arc(DVec2::new(half, radius - sagitta), radius, -up + beta, -up - beta, 128, false));
    prism(&[profile], 0.6)
}

fn octahedron() -> Shape {
    let v = [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y, DVec3::Z, -DVec3::Z];
    let mut s = Shape::default();
    for &(a, b) in &[(0, 2), (2, 1), (1, 3), (3, 0)] {
        s.surfaces.push(Surface::Triangle([v[a], v[b], v[4]]));
        s.surfaces.push(Surface::Triangle([v[b], v[a], v[5]]));
        s.truth.push(vec![v[a], v[b]]);
        s.truth.push(vec![v[a], v[4]]);
        s.truth.push(vec![v[a], v[5]]);
    }
    s
}

/// Two half-planes (1 x 1 squares) meeting along the z axis at dihedral angle `deg`.
fn wedge(deg: f64) -> Shape {
    let a = deg.to_radians();
    let d = DVec3::new(a.cos(), a.sin(), 0.0);
    let mut s = Shape::default();
    for dir in [DVec3::X, d] {
        s.surfaces.push(Surface::Triangle([DVec3::ZERO, dir, dir + DVec3::Z]));
        s.surfaces.push(Surface::Triangle([DVec3::ZERO, dir + DVec3::Z, DVec3::Z]));
    }
    s.truth.push(vec![DVec3::ZERO, DVec3::Z]);
    s
}

// Fandisk-like part: a prism whose profile mixes lines, a smooth (tangent) fillet and a
// cylindrical boss, with a ridge on its bottom face whose sharpness fades to nothing.
const RIDGE_ZC: f64 = 0.6;
const RIDGE_HALF_WIDTH: f64 = 0.2;
const RIDGE_SLOPE: f64 = 1.0;
const RIDGE_LEN: f64 = 2.0;

fn ridge(p: DVec2) -> f64 {
    let a = RIDGE_SLOPE * (1.0 - p.x / RIDGE_LEN).max(0.0);
    a * (RIDGE_HALF_WIDTH - (p.y - RIDGE_ZC).abs()).max(0.0)
}

fn fandisk() -> Shape {
    use std::f64::consts::{FRAC_PI_2, PI};
    let mut profile = vec![DVec2::new(0.0, 0.0), DVec2::new(2.0, 0.0)];
    // Tangent fillet (no feature), then a flat, then a half-cylinder boss (two concave edges).
    profile.extend(arc(DVec2::new(1.8, 0.3), 0.2, 0.0, FRAC_PI_2, 32, true));
    profile.insert(2, DVec2::new(2.0, 0.3));
    profile.dedup_by(|a, b| a.distance(*b) < 1e-12);
    profile.extend(arc(DVec2::new(1.0, 0.5), 0.4, 0.0, PI, 128, true));
    profile.dedup_by(|a, b| a.distance(*b) < 1e-12);
    profile.extend([DVec2::new(0.3, 0.5), DVec2::new(0.3, 0.9), DVec2::new(0.0, 0.9)]);
    let len = 1.2;
    let mut s = prism(&[profile], len);
    // Replace the bottom face (the extrusion of the first profile segment: the first two
    // triangles after the two caps) by a height field carrying the fading ridge.
    s.surfaces.drain(2..4);
    let frame = Frame { origin: DVec3::ZERO, x: DVec3::X, y: DVec3::Z };
    let normal = frame.x.cross(frame.y); // -Y: the ridge stands out of the part
    s.surfaces.push(Surface::HeightField { frame, min: DVec2::ZERO, max: DVec2::new(2.0, len), f: ridge, max_slope: RIDGE_SLOPE * 1.01 });
    // The ridge's end at the x = 0 wall is a vertical triangle.
    let top = DVec3::new(0.0, 0.0, RIDGE_ZC) + normal * (RIDGE_SLOPE * RIDGE_HALF_WIDTH);
    let (l, r) = (DVec3::new(0.0, 0.0, RIDGE_ZC - RIDGE_HALF_WIDTH), DVec3::new(0.0, 0.0, RIDGE_ZC + RIDGE_HALF_WIDTH));
    s.surfaces.push(Surface::Triangle([l, r, top]));
    // Truth: the x = 0 bottom edge detours around the ridge's end.
    s.truth.retain(|t| !(t.len() == 2 && t[0] == DVec3::ZERO && t[1] == DVec3::new(0.0, 0.0, len)));
    s.truth.push(vec![DVec3::ZERO, l, top, r, DVec3::new(0.0, 0.0, len)]);
    // The ridge crest is sharp (normals turn by 2 atan(a) >= 30 deg) while a >= tan 15 deg;
    // its two feet (turn atan(a) >= 30 deg) while a >= tan 30 deg.
    let x_at = |a_min: f64| RIDGE_LEN * (1.0 - a_min / RIDGE_SLOPE);
    let xc = x_at(15f64.to_radians().tan());
    let xf = x_at(30f64.to_radians().tan());
    let crest = |x: f64| DVec3::new(x, 0.0, RIDGE_ZC) + normal * ridge(DVec2::new(x, RIDGE_ZC));
    s.truth.push((0..=64).map(|i| crest(xc * i as f64 / 64.0)).collect());
    for zf in [RIDGE_ZC - RIDGE_HALF_WIDTH, RIDGE_ZC + RIDGE_HALF_WIDTH] {
        s.truth.push(vec![DVec3::new(0.0, 0.0, zf), DVec3::new(xf, 0.0, zf)]);
    }
    s
}
