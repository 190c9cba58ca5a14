//! Typed curves: each curve split at its corners and where its shape changes, each piece the
//! simplest of a straight line segment, a circular arc and a full circle that holds within a
//! tolerance over its whole span. What no such fit holds for more than one step is a cubic
//! B-spline ([`super::spline`]), or, where no spline holds either (a zigzag finer than the
//! tolerance), stays a polyline run. A piece starts and ends on vertices of its curve, so pieces
//! that meet share their end points exactly, corners included.

use super::spline::{self, Spline};
use super::{Curves, Polyline, Shape};
use crate::crs::Crs;
use crate::error::{Error, Result};
use glam::{DVec3, Vec3};
use serde::Serialize;
use std::f64::consts::TAU;
use std::io::{BufWriter, Write};
use std::path::Path;

/// What a piece is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum Kind {
    /// A straight segment from `start` to `end`.
    Line,
    /// A circular arc from `start` to `end`, counterclockwise about `axis`.
    Arc,
    /// A full circle (a closed curve all on one circle); `start` and `end` are one vertex.
    Circle,
    /// A cubic B-spline from `start` to `end`, where no line or arc holds for more than one step.
    Spline,
    /// The curve's own vertices, where no spline holds either.
    Polyline,
}

impl Kind {
    /// Its name in the outputs: `line`, `arc`, `circle`, `spline` or `polyline`.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Kind::Line => "line",
            Kind::Arc => "arc",
            Kind::Circle => "circle",
            Kind::Spline => "spline",
            Kind::Polyline => "polyline",
        }
    }
}

/// What a whole curve is, from its pieces (see [`pieces`]): the name of the kind they all
/// share (`polyline` for a curve without pieces), `mixed` where they differ; and the radius
/// where the curve is one arc or one circle.
pub(crate) fn curve_kind(pieces: &[Piece]) -> (&'static str, Option<f64>) {
    let Some(first) = pieces.first() else { return (Kind::Polyline.name(), None) };
    if pieces.iter().any(|p| p.kind != first.kind) {
        return ("mixed", None);
    }
    let radius = if pieces.len() == 1 { first.radius } else { None };
    (first.kind.name(), radius)
}

/// One piece of a typed curve.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct Piece {
    /// Id of the curve the piece belongs to.
    pub curve: u32,
    /// Its type.
    pub kind: Kind,
    /// Index of its first vertex in the curve's polyline.
    pub first: usize,
    /// Number of the curve's segments it spans.
    pub segments: usize,
    /// First point (a vertex of the curve).
    pub start: DVec3,
    /// Last point (a vertex of the curve).
    pub end: DVec3,
    /// Centre of an arc or circle.
    pub centre: Option<DVec3>,
    /// Unit axis of an arc or circle: the direction of travel turns counterclockwise about it.
    pub axis: Option<DVec3>,
    /// Radius of an arc or circle.
    pub radius: Option<f64>,
    /// Angle an arc sweeps, in degrees (360 for a circle).
    pub sweep_deg: Option<f64>,
    /// A spline's knots and control points.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub spline: Option<Spline>,
    /// Largest distance of a vertex of its span from it (for a spline, of a vertex or a step's
    /// middle from the spline at the same parameter).
    pub error: f64,
}

/// A circle through three points: centre, unit axis (counterclockwise from the first through
/// the second to the third) and radius; None where the points are (nearly) on one line.
fn circle_through(a: DVec3, b: DVec3, c: DVec3) -> Option<(DVec3, DVec3, f64)> {
    let (u, w) = (b - a, c - a);
    let n = u.cross(w);
    let nn = n.length_squared();
    if nn <= 1e-24 * (u.length_squared() * w.length_squared()).max(f64::MIN_POSITIVE) {
        return None;
    }
    let centre = a + (u.length_squared() * w - w.length_squared() * u).cross(n) / (2.0 * nn);
    Some((centre, n / nn.sqrt(), centre.distance(a)))
}

/// Angle of `p` about the circle (`centre`, `axis`) from `from`, in [0, 2 pi).
fn angle_about(p: DVec3, from: DVec3, centre: DVec3, axis: DVec3) -> f64 {
    let (x, y) = (from - centre, p - centre);
    let a = axis.dot(x.cross(y)).atan2(x.dot(y) - x.dot(axis) * y.dot(axis));
    if a < 0.0 {
        a + TAU
    } else {
        a
    }
}

/// Distance of `p` from the circle (`centre`, `axis`, `r`).
fn off_circle(p: DVec3, centre: DVec3, axis: DVec3, r: f64) -> f64 {
    let d = p - centre;
    let h = d.dot(axis);
    let radial = (d - h * axis).length() - r;
    (radial * radial + h * h).sqrt()
}

/// Largest distance of `pts` from the segment between their ends.
fn line_error(pts: &[DVec3]) -> f64 {
    let (a, b) = (pts[0], pts[pts.len() - 1]);
    pts.iter().map(|&p| crate::curves::segment_distance(p, a, b)).fold(0.0, f64::max)
}

/// The arc through the ends of `pts` and their middle vertex, if every vertex lies within
/// `tol` of it and they follow it in order: (centre, axis, radius, sweep in radians, error).
/// (The least-squares circle through the ends bends to take in the start of a tangent line, so
/// the pieces cut with it stray from their joints.)
fn arc_fit(pts: &[DVec3], tol: f64) -> Option<(DVec3, DVec3, f64, f64, f64)> {
    if pts.len() < 4 {
        return None;
    }
    follows(pts, circle_through(pts[0], pts[pts.len() / 2], pts[pts.len() - 1])?, tol)
}

/// The arc that [`arc_fit`] gives, or else the least-squares one through the ends, where that
/// holds: for two arcs already cut, whose joint is no tangent line's start.
fn joined_arc_fit(pts: &[DVec3], tol: f64) -> Option<(DVec3, DVec3, f64, f64, f64)> {
    arc_fit(pts, tol).or_else(|| follows(pts, super::circle::fit_arc(pts)?, tol))
}

/// `circle` (centre, axis, radius) as the arc of `pts`, if every vertex lies within `tol` of it
/// and they follow it in order from the first: with the sweep in radians and the error.
fn follows(pts: &[DVec3], circle: (DVec3, DVec3, f64), tol: f64) -> Option<(DVec3, DVec3, f64, f64, f64)> {
    let (centre, axis, r) = circle;
    let (a, b) = (pts[0], pts[pts.len() - 1]);
    let mut last = 0.0;
    let mut error = 0.0f64;
    for &p in &pts[1..] {
        let e = off_circle(p, centre, axis, r);
        let t = angle_about(p, a, centre, axis);
        // (The last vertex may sit at the start again, a whole turn on.)
        let t = if p == b && t < last { t + TAU } else { t };
        if e > tol || t < last {
            return None;
        }
        error = error.max(e);
        last = t;
    }
    Some((centre, axis, r, last, error))
}

/// A closed curve's vertices as one circle, their least-squares one, if they all lie within
/// `tol` of it and go round it once, in order.
fn circle_fit(v: &[DVec3], tol: f64) -> Option<(DVec3, DVec3, f64, f64)> {
    let n = v.len();
    if n < 6 {
        return None;
    }
    let (centre, axis, r) = super::circle::fit_circle(v)?;
    let mut last = 0.0;
    let mut error = 0.0f64;
    for &p in &v[1..] {
        let e = off_circle(p, centre, axis, r);
        let t = angle_about(p, v[0], centre, axis);
        if e > tol || t < last {
            return None;
        }
        error = error.max(e);
        last = t;
    }
    Some((centre, axis, r, error))
}

/// The pieces of curve `pl`, each within `tol` of every vertex it spans.
pub(crate) fn pieces(pl: &Polyline, tol: f64) -> Vec<Piece> {
    let v: Vec<DVec3> = pl.vertices.iter().map(|x| x.p).collect();
    let n = v.len();
    if n < 2 {
        return Vec::new();
    }
    let corners: Vec<usize> = (0..n).filter(|&i| pl.vertices[i].corner).collect();
    // (A closed curve all of whose vertices lie on one circle is that circle, whatever corners
    // completion put on it: two creases cannot meet at a corner on a smooth rim.)
    if pl.closed
        && let Some((centre, axis, r, error)) = circle_fit(&v, tol)
    {
        return vec![Piece {
            curve: pl.id,
            kind: Kind::Circle,
            first: 0,
            segments: n,
            start: v[0],
            end: v[0],
            centre: Some(centre),
            axis: Some(axis),
            radius: Some(r),
            sweep_deg: Some(360.0),
            spline: None,
            error,
        }];
    }
    // Runs between corners, as vertex indices (a closed curve's wrap round to its start).
    let mut runs: Vec<Vec<usize>> = Vec::new();
    if pl.closed {
        let start = corners.first().copied().unwrap_or_else(|| joint_of_loop(pl.id, &v, tol));
        let order: Vec<usize> = (0..=n).map(|k| (start + k) % n).collect();
        let mut run = vec![order[0]];
        for &i in &order[1..] {
            run.push(i);
            if pl.vertices[i].corner {
                runs.push(std::mem::replace(&mut run, vec![i]));
            }
        }
        if run.len() > 1 {
            runs.push(run);
        }
    } else {
        let mut run = vec![0];
        for i in 1..n {
            run.push(i);
            if pl.vertices[i].corner || i == n - 1 {
                runs.push(std::mem::replace(&mut run, vec![i]));
            }
        }
    }
    let mut out = Vec::new();
    for run in &runs {
        let from = out.len();
        type_run(pl.id, run, &v, tol, &mut out);
        one_spline_if_simpler(run, &v, tol, &mut out, from);
    }
    out
}

/// Where to start the pieces of a closed curve without corners: at a joint of its shape, the
/// end of the first piece typed from vertex 0. The vertex where the curve was closed is where
/// its tracing happened to meet itself, and a piece cut there is one piece cut in two.
fn joint_of_loop(curve: u32, v: &[DVec3], tol: f64) -> usize {
    let n = v.len();
    let run: Vec<usize> = (0..=n).map(|k| k % n).collect();
    let mut first = Vec::new();
    type_run(curve, &run, v, tol, &mut first);
    if first.len() < 2 {
        return 0;
    }
    (first[0].first + first[0].segments) % n
}

/// How many numbers a piece takes to write down: a line its two ends, an arc its ends and a
/// middle point, a spline about four a control point (its point and a knot), a polyline its
/// vertices.
fn cost(p: &Piece) -> usize {
    match p.kind {
        Kind::Line => 6,
        Kind::Arc | Kind::Circle => 9,
        Kind::Spline => p.spline.as_ref().map_or(0, |s| 3 * s.control_points.len() + s.knots.len() - 2 * spline::DEGREE),
        Kind::Polyline => 3 * (p.segments + 1),
    }
}

/// Replaces the pieces `out[from..]` of `run` by one spline through the whole run where that
/// spline takes fewer numbers to write down: a free-form edge is one spline, not a chain of short
/// arcs each of which holds only because it is short; a line and an arc that meet tangentially
/// stay themselves, as no spline holds them that cheaply.
fn one_spline_if_simpler(run: &[usize], v: &[DVec3], tol: f64, out: &mut Vec<Piece>, from: usize) {
    let chain = &out[from..];
    if chain.len() < 2 {
        return;
    }
    let budget: usize = chain.iter().map(cost).sum();
    // (A spline of c control points costs about 4c numbers: only those under the budget count.)
    let max_control = (budget / 4).min(MAX_CONTROL_POINTS);
    let pts: Vec<DVec3> = run.iter().map(|&i| v[i]).collect();
    let Some((s, error)) = spline::fit(&pts, tol, max_control) else { return };
    let first = chain[0].clone();
    let spline = Piece {
        kind: Kind::Spline,
        segments: run.len() - 1,
        end: pts[pts.len() - 1],
        centre: None,
        axis: None,
        radius: None,
        sweep_deg: None,
        error,
        spline: Some(s),
        ..first
    };
    if cost(&spline) < budget {
        out.truncate(from);
        out.push(spline);
    }
}

/// Most control points a spline piece may have: DXF counts them in 16 bits, and a run that
/// needs more is no smoother than its polyline.
const MAX_CONTROL_POINTS: usize = 4096;

/// Types one run between corners: greedily, the longest line or arc from each piece's start
/// (the line where it reaches as far), then each joint between two such pieces settled (see
/// [`settle_joints`]); runs of single steps that neither holds beyond become one spline piece,
/// or a polyline piece where no spline holds.
fn type_run(curve: u32, run: &[usize], v: &[DVec3], tol: f64, out: &mut Vec<Piece>) {
    let pts: Vec<DVec3> = run.iter().map(|&i| v[i]).collect();
    let mut spans = greedy_spans(&pts, tol);
    settle_joints(&mut spans, &pts, tol);
    join_alike(&mut spans, &pts, tol);
    let piece = |kind, i: usize, j: usize| Piece {
        curve,
        kind,
        first: run[i],
        segments: j - i,
        start: pts[i],
        end: pts[j],
        centre: None,
        axis: None,
        radius: None,
        sweep_deg: None,
        spline: None,
        error: 0.0,
    };
    for &(kind, i, j) in &spans {
        match kind {
            Kind::Line => out.push(Piece { error: line_error(&pts[i..=j]), ..piece(Kind::Line, i, j) }),
            // (Every arc span was checked to hold where it was made, moved or joined.)
            Kind::Arc if let Some((centre, axis, r, sweep, error)) = joined_arc_fit(&pts[i..=j], tol) => out.push(Piece {
                centre: Some(centre),
                axis: Some(axis),
                radius: Some(r),
                sweep_deg: Some(sweep.to_degrees()),
                error,
                ..piece(Kind::Arc, i, j)
            }),
            _ if j - i == 1 => out.push(Piece { error: line_error(&pts[i..=j]), ..piece(Kind::Line, i, j) }),
            _ => match spline::fit(&pts[i..=j], tol, MAX_CONTROL_POINTS) {
                Some((s, error)) => out.push(Piece { spline: Some(s), error, ..piece(Kind::Spline, i, j) }),
                None => out.push(piece(Kind::Polyline, i, j)),
            },
        }
    }
}

/// A piece of a run as (kind, first vertex, last vertex): a line, an arc, or (as `Polyline`)
/// loose steps that neither holds beyond one step.
type Span = (Kind, usize, usize);

/// The greedy pass of [`type_run`]: from each piece's start, the line or arc that reaches
/// farthest; single steps that neither holds beyond gathered into loose spans.
fn greedy_spans(pts: &[DVec3], tol: f64) -> Vec<Span> {
    let m = pts.len();
    let mut spans = Vec::new();
    let mut i = 0;
    let mut loose: Option<usize> = None;
    let flush = |loose: &mut Option<usize>, to: usize, spans: &mut Vec<Span>| {
        if let Some(from) = loose.take() {
            spans.push((Kind::Polyline, from, to));
        }
    };
    while i + 1 < m {
        let jl = farthest(i + 1, m - 1, |j| line_error(&pts[i..=j]) <= tol);
        // (An arc is taken only where it reaches farther than the line: none can where the
        // line reaches the run's end.)
        let ja = if jl + 1 < m && i + 3 < m && arc_fit(&pts[i..=i + 3], tol).is_some() {
            farthest(i + 3, m - 1, |j| arc_fit(&pts[i..=j], tol).is_some())
        } else {
            i
        };
        if ja > jl && arc_holds(&pts[i..=ja], tol).is_some() {
            flush(&mut loose, i, &mut spans);
            spans.push((Kind::Arc, i, ja));
            i = ja;
        } else if jl == i + 1 && m > 2 {
            loose.get_or_insert(i);
            i = jl;
        } else {
            flush(&mut loose, i, &mut spans);
            spans.push((Kind::Line, i, jl));
            i = jl;
        }
    }
    flush(&mut loose, m - 1, &mut spans);
    spans
}

/// The sum of squared distances of `pts` from the arc through their ends and middle vertex,
/// if that arc holds within `tol` and bows out from its chord by more than twice `tol`: one
/// that bows less cannot be told from a line at that tolerance, and the line, the simpler
/// type, is taken.
fn arc_holds(pts: &[DVec3], tol: f64) -> Option<f64> {
    let arc @ (centre, axis, r, _, _) = arc_fit(pts, tol)?;
    bows(arc, tol).then(|| pts.iter().map(|&p| off_circle(p, centre, axis, r).powi(2)).sum())
}

/// True if `arc` (centre, axis, radius, sweep, error) bows out from its chord by more than twice
/// `tol` (see [`arc_holds`]).
fn bows((_, _, r, sweep, _): (DVec3, DVec3, f64, f64, f64), tol: f64) -> bool {
    r * (1.0 - (0.5 * sweep.min(std::f64::consts::PI)).cos()) > 2.0 * tol
}

/// The sum of squared distances of `pts` from the segment between their ends, if every one
/// lies within `tol` of it.
fn line_holds(pts: &[DVec3], tol: f64) -> Option<f64> {
    let (a, b) = (pts[0], pts[pts.len() - 1]);
    let mut sse = 0.0;
    for &p in pts {
        let d = crate::curves::segment_distance(p, a, b);
        if d > tol {
            return None;
        }
        sse += d * d;
    }
    Some(sse)
}

/// Joins each two neighbouring lines, or arcs, into one where that one holds over both: the
/// greedy pass ends an arc where the circle through its ends and middle stops holding, which a
/// noisy middle vertex can make happen half way round, and the next arc then goes on round
/// the same circle. (Two arcs are also one where only the least-squares circle through their
/// ends holds: that circle averages the noise of the middle vertex away.)
fn join_alike(spans: &mut Vec<Span>, pts: &[DVec3], tol: f64) {
    let mut s = 1;
    while s < spans.len() {
        let ((pk, a, _), (qk, _, b)) = (spans[s - 1], spans[s]);
        let holds = match (pk, qk) {
            (Kind::Line, Kind::Line) => line_holds(&pts[a..=b], tol).is_some(),
            (Kind::Arc, Kind::Arc) => joined_arc_fit(&pts[a..=b], tol).is_some_and(|arc| bows(arc, tol)),
            _ => false,
        };
        if holds {
            spans[s - 1].2 = b;
            spans.remove(s);
        } else {
            s += 1;
        }
    }
}

/// Moves each joint between two lines or arcs to the vertex where both still hold and leave
/// the least sum of squared distances (the fit that noise of equal spread on every vertex makes
/// likeliest). The greedy pass ends a piece where it stops holding, which at a tangent joint is
/// past the joint by as far as the tolerance lets one shape pass for the other: an arc that runs
/// on along a line, or a line that cuts into an arc. A joint moves at most the shorter piece's
/// length, each piece keeping the vertices its kind needs.
fn settle_joints(spans: &mut [Span], pts: &[DVec3], tol: f64) {
    let holds = |kind: Kind, i: usize, j: usize| match kind {
        Kind::Line if j > i => line_holds(&pts[i..=j], tol),
        Kind::Arc if j >= i + 3 => arc_holds(&pts[i..=j], tol),
        _ => None,
    };
    let fitted = |kind: Kind| matches!(kind, Kind::Line | Kind::Arc);
    for s in 1..spans.len() {
        let ((pk, a, k), (qk, _, b)) = (spans[s - 1], spans[s]);
        if !fitted(pk) || !fitted(qk) {
            continue;
        }
        let reach = (k - a).min(b - k);
        let cost = |k: usize| Some(holds(pk, a, k)? + holds(qk, k, b)?);
        let Some(mut best) = cost(k) else { continue };
        let mut at = k;
        for j in k.saturating_sub(reach).max(a + 1)..=(k + reach).min(b - 1) {
            if let Some(c) = cost(j)
                && c < best
            {
                (best, at) = (c, j);
            }
        }
        spans[s - 1].2 = at;
        spans[s].1 = at;
    }
}

/// The largest `j` in `lo..=hi` for which `ok(j)` holds, given that it holds at `lo`: found by
/// steps that double until one fails, then halve (a piece grown a vertex at a time took time
/// quadratic in its length). Where a fit fails
/// at one vertex and holds again farther on, the piece may reach past that vertex: it still
/// holds within the tolerance over all it spans, as that is what `ok` checks.
fn farthest(lo: usize, hi: usize, ok: impl Fn(usize) -> bool) -> usize {
    let (mut good, mut bad, mut step) = (lo, hi + 1, 1);
    while good + step < bad {
        if ok(good + step) {
            good += step;
            step *= 2;
        } else {
            bad = good + step;
        }
    }
    while bad - good > 1 {
        let mid = good + (bad - good) / 2;
        if ok(mid) {
            good = mid;
        } else {
            bad = mid;
        }
    }
    good
}

/// The tolerance of the typed pieces of a run: three noise deviations, or half the spacing on a
/// clean cloud. A curve's vertices stray from its edge by about a deviation (on a machined part
/// at 2 spacings of noise, 99 % of them within two), and the largest stray of the hundred or so
/// vertices of an edge is about three (sqrt(2 ln 100) = 3.03 for normal strays): a tighter
/// piece breaks where one vertex strays.
pub(crate) fn tolerance(kappa: f64, noise: f64) -> f64 {
    (3.0 * noise).max(0.5 * kappa)
}

/// Writes `curves.json`: the pieces of every curve within `tol` (see [`pieces`]), one JSON
/// record a piece with its curve's confidence and shape and the two surface normals at its
/// ends. A record holds the fields of [`Piece`]: `kind`, `start`, `end` and `error` for every
/// piece, `centre`, `axis`, `radius` and `sweep_deg` for an arc or a circle (null otherwise),
/// and for a spline its `degree` (3), `knots` (clamped, from 0 to 1) and `control_points`.
pub(crate) fn write_pieces(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs, tol: f64) -> Result<()> {
    let f = std::fs::File::create(path).map_err(|e| Error::output(path, e))?;
    let mut w = BufWriter::new(f);
    let out = |e| Error::output(path, e);
    let crs = serde_json::to_string(&crs.summary()).expect("a string");
    write!(w, "{{\"tolerance\":{tol},\"crs\":{crs},\"pieces\":[").map_err(out)?;
    let mut first = true;
    curves.each(&mut |c| {
        for p in pieces(c, tol) {
            let n = c.vertices.len();
            let at = |k: usize| c.vertices[k % n].n;
            let record = Record { piece: &p, confidence: c.confidence, shape: c.shape, normals_start: at(p.first), normals_end: at(p.first + p.segments) };
            let record = serde_json::to_string(&record).expect("plain data");
            write!(w, "{}\n{record}", if first { "" } else { "," }).map_err(out)?;
            first = false;
        }
        Ok(())
    })?;
    writeln!(w, "\n]}}").map_err(out)?;
    w.flush().map_err(out)
}

/// A piece as `curves.json` holds it.
#[derive(Serialize)]
struct Record<'a> {
    #[serde(flatten)]
    piece: &'a Piece,
    confidence: f32,
    shape: Shape,
    normals_start: [Vec3; 2],
    normals_end: [Vec3; 2],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curves::Vertex;

    fn polyline(pts: impl IntoIterator<Item = DVec3>, closed: bool) -> Polyline {
        let mut pl = Polyline::from_points(1, pts);
        pl.closed = closed;
        pl
    }

    /// Every piece lies within the tolerance of every vertex it spans, and consecutive pieces
    /// share their ends.
    fn check(pl: &Polyline, pieces: &[Piece], tol: f64) {
        let n = pl.vertices.len();
        let mut next = pieces[0].first;
        for p in pieces {
            assert_eq!(p.first, next % n, "pieces follow each other");
            let span: Vec<DVec3> = (0..=p.segments).map(|k| pl.vertices[(p.first + k) % n].p).collect();
            assert_eq!(p.start, span[0]);
            assert_eq!(p.end, span[p.segments]);
            for &q in &span {
                let d = match p.kind {
                    Kind::Line => crate::curves::segment_distance(q, p.start, p.end),
                    Kind::Arc | Kind::Circle => off_circle(q, p.centre.unwrap(), p.axis.unwrap(), p.radius.unwrap()),
                    Kind::Spline => {
                        // (Distance from the spline drawn finely, not at the vertex's own parameter.)
                        let s = p.spline.as_ref().unwrap();
                        let drawn: Vec<DVec3> = (0..=4000).map(|k| s.at(k as f64 / 4000.0)).collect();
                        drawn.windows(2).map(|w| crate::curves::segment_distance(q, w[0], w[1])).fold(f64::INFINITY, f64::min)
                    }
                    Kind::Polyline => 0.0,
                };
                assert!(d <= tol, "{:?} misses a vertex by {d}", p.kind);
            }
            next = p.first + p.segments;
        }
        assert_eq!(pieces.iter().map(|p| p.segments).sum::<usize>(), pl.segment_count());
    }

    #[test]
    fn a_noisy_circle_is_one_circle_of_its_radius() {
        let mut rng = crate::rng::Rng::stream(2, 0);
        let (c, r) = (DVec3::new(3.0, -2.0, 1.0), 2.5);
        let pts: Vec<DVec3> =
            (0..200).map(|k| k as f64 * TAU / 200.0).map(|t| c + DVec3::new(r * t.cos(), 0.0, r * t.sin()) + 0.002 * (rng.in_ball(1.0))).collect();
        let pl = polyline(pts, true);
        let pieces = pieces(&pl, 0.01);
        assert_eq!(pieces.len(), 1);
        assert_eq!(pieces[0].kind, Kind::Circle);
        assert!((pieces[0].radius.unwrap() - r).abs() < 0.01);
        assert!(pieces[0].axis.unwrap().y.abs() > 0.999);
        check(&pl, &pieces, 0.01);
    }

    #[test]
    fn a_rim_with_a_corner_put_on_it_is_still_one_circle() {
        let pts: Vec<DVec3> = (0..60).map(|k| k as f64 * TAU / 60.0).map(|t| DVec3::new(t.cos(), t.sin(), 0.5)).collect();
        let mut pl = polyline(pts, true);
        pl.vertices[17].corner = true;
        let pieces = pieces(&pl, 1e-6);
        assert_eq!(pieces.iter().map(|p| p.kind).collect::<Vec<_>>(), [Kind::Circle]);
        check(&pl, &pieces, 1e-6);
    }

    /// A stadium: two straight sides 4 long, two half circles of radius 1, as one closed curve
    /// without corners (the sides meet the arcs tangentially), steps of 0.1.
    fn stadium() -> Vec<DVec3> {
        let mut pts = Vec::new();
        for k in 0..40 {
            pts.push(DVec3::new(-2.0 + 0.1 * k as f64, -1.0, 0.0));
        }
        for k in 0..30 {
            let t = -TAU / 4.0 + k as f64 * (TAU / 2.0) / 30.0;
            pts.push(DVec3::new(2.0 + t.cos(), t.sin(), 0.0));
        }
        for k in 0..40 {
            pts.push(DVec3::new(2.0 - 0.1 * k as f64, 1.0, 0.0));
        }
        for k in 0..30 {
            let t = TAU / 4.0 + k as f64 * (TAU / 2.0) / 30.0;
            pts.push(DVec3::new(-2.0 + t.cos(), t.sin(), 0.0));
        }
        pts
    }

    fn two_lines_and_two_half_circles(pieces: &[Piece]) {
        let kinds: Vec<Kind> = pieces.iter().map(|p| p.kind).collect();
        assert_eq!(kinds.iter().filter(|&&k| k == Kind::Line).count(), 2, "{kinds:?}");
        assert_eq!(kinds.iter().filter(|&&k| k == Kind::Arc).count(), 2, "{kinds:?}");
        for p in pieces.iter().filter(|p| p.kind == Kind::Arc) {
            assert!((p.radius.unwrap() - 1.0).abs() < 1e-6, "{}", p.radius.unwrap());
            assert!((p.sweep_deg.unwrap() - 180.0).abs() < 7.0, "{}", p.sweep_deg.unwrap());
        }
    }

    #[test]
    fn a_slot_outline_is_two_lines_and_two_arcs() {
        let pl = polyline(stadium(), true);
        let pieces = pieces(&pl, 1e-3);
        two_lines_and_two_half_circles(&pieces);
        check(&pl, &pieces, 1e-3);
    }

    #[test]
    fn a_slot_outline_closed_half_way_round_an_arc_still_has_two_arcs() {
        let mut pts = stadium();
        pts.rotate_left(55);
        let pl = polyline(pts, true);
        let pieces = pieces(&pl, 1e-3);
        two_lines_and_two_half_circles(&pieces);
        check(&pl, &pieces, 1e-3);
    }

    #[test]
    fn an_arc_ends_where_its_tangent_line_begins_however_loose_the_tolerance() {
        // A quarter circle of radius 1 in steps of 6 degrees, then its tangent line in steps of
        // 0.1. At a tolerance of 0.03 the arc drawn on from its start takes in the line's first
        // steps too; the joint is settled back to the tangent point, where both fit exactly.
        let mut pts: Vec<DVec3> = (0..=15).map(|k| k as f64 * TAU / 60.0).map(|t| DVec3::new(t.sin(), 1.0 - t.cos(), 0.0)).collect();
        pts.extend((1..=20).map(|k| DVec3::new(1.0, 1.0 + 0.1 * k as f64, 0.0)));
        let pl = polyline(pts, false);
        let pieces = pieces(&pl, 0.03);
        let kinds: Vec<Kind> = pieces.iter().map(|p| p.kind).collect();
        assert_eq!(kinds, [Kind::Arc, Kind::Line]);
        assert_eq!(pieces[0].segments, 15, "the arc ends {} steps from the tangent point", pieces[0].segments as i64 - 15);
        assert!((pieces[0].sweep_deg.unwrap() - 90.0).abs() < 1e-9 && (pieces[0].radius.unwrap() - 1.0).abs() < 1e-9);
        check(&pl, &pieces, 0.03);
    }

    #[test]
    fn corners_split_pieces_and_are_shared() {
        // A square's outline with its four corners flagged.
        let mut pts = Vec::new();
        let sq = [DVec3::ZERO, DVec3::X, DVec3::X + DVec3::Y, DVec3::Y];
        for s in 0..4 {
            for k in 0..10 {
                pts.push(sq[s].lerp(sq[(s + 1) % 4], k as f64 / 10.0));
            }
        }
        let mut pl = polyline(pts, true);
        for k in [0, 10, 20, 30] {
            pl.vertices[k].corner = true;
        }
        let pieces = pieces(&pl, 1e-9);
        assert_eq!(pieces.len(), 4);
        for (p, q) in pieces.iter().zip(pieces.iter().cycle().skip(1)) {
            assert_eq!(p.kind, Kind::Line);
            assert_eq!(p.end, q.start);
            assert!(sq.contains(&p.start));
        }
        check(&pl, &pieces, 1e-9);
    }

    #[test]
    fn a_curve_is_of_the_kind_its_pieces_share_with_the_radius_of_its_one_arc_or_circle() {
        let rim: Vec<DVec3> = (0..60).map(|k| k as f64 * TAU / 60.0).map(|t| DVec3::new(2.0 * t.cos(), 2.0 * t.sin(), 0.0)).collect();
        let (kind, r) = curve_kind(&pieces(&polyline(rim.clone(), true), 1e-6));
        assert_eq!(kind, "circle");
        assert!((r.unwrap() - 2.0).abs() < 1e-12);
        let (kind, r) = curve_kind(&pieces(&polyline(rim[..20].to_vec(), false), 1e-6));
        assert_eq!(kind, "arc");
        assert!((r.unwrap() - 2.0).abs() < 1e-12);
        // A square's four sides: all lines, so a line curve, but not one radius.
        let sq = [DVec3::ZERO, DVec3::X, DVec3::X + DVec3::Y, DVec3::Y];
        let mut square = polyline((0..40).map(|k| sq[k / 10].lerp(sq[(k / 10 + 1) % 4], (k % 10) as f64 / 10.0)), true);
        for k in [0, 10, 20, 30] {
            square.vertices[k].corner = true;
        }
        assert_eq!(curve_kind(&pieces(&square, 1e-9)), ("line", None));
        // A side and a quarter circle meeting at a corner: mixed.
        let mut bend = polyline((0..=10).map(|k| DVec3::new(k as f64 / 10.0 - 1.0, 0.0, 0.0)), false);
        bend.vertices.extend((1..=15).map(|k| k as f64 * TAU / 60.0).map(|t| Vertex::at(DVec3::new(t.sin(), 1.0 - t.cos(), 0.0))));
        bend.vertices[10].corner = true;
        let p = pieces(&bend, 1e-6);
        assert_eq!(p.iter().map(|p| p.kind).collect::<Vec<_>>(), [Kind::Line, Kind::Arc]);
        assert_eq!(curve_kind(&p), ("mixed", None));
        assert_eq!(curve_kind(&[]), ("polyline", None));
    }

    #[test]
    fn a_wiggle_stays_a_polyline_and_pieces_cover_the_curve() {
        // A zigzag whose every step turns: nothing longer than a step fits.
        let pts: Vec<DVec3> = (0..12).map(|k| DVec3::new(k as f64, if k % 2 == 0 { 0.0 } else { 1.0 }, 0.0)).collect();
        let mut pl = polyline(pts, false);
        pl.vertices.push(Vertex::at(DVec3::new(12.0, 0.0, 0.0)));
        let pieces = pieces(&pl, 0.01);
        assert_eq!(pieces.len(), 1, "{pieces:?}");
        assert_eq!(pieces[0].kind, Kind::Polyline);
        check(&pl, &pieces, 0.01);
    }

    #[test]
    fn a_free_form_run_is_one_spline_that_shares_its_corner() {
        // A straight side, a corner, then a twisted cubic: no arc holds it whole, and the short
        // arcs that would each hold a stretch take more numbers than one spline.
        let mut pl = polyline((0..=20).map(|k| DVec3::new(k as f64 / 20.0 - 1.0, 0.0, 0.0)), false);
        pl.vertices.extend((1..=200).map(|k| k as f64 / 200.0).map(|x| Vertex::at(DVec3::new(x, x * x * x, 0.5 * x * x))));
        pl.vertices[20].corner = true;
        for tol in [1e-4, 1e-3] {
            let p = pieces(&pl, tol);
            assert_eq!(p.iter().map(|p| p.kind).collect::<Vec<_>>(), [Kind::Line, Kind::Spline], "{tol}");
            assert_eq!((p[0].end, p[1].start), (DVec3::ZERO, DVec3::ZERO));
            assert!(p[1].spline.as_ref().unwrap().control_points.len() < 20);
            check(&pl, &p, tol);
        }
    }

    #[test]
    fn two_runs_meeting_at_a_corner_are_two_lines() {
        use crate::curves::{typed, Polyline};
        use glam::DVec3;
        // Two straight runs meeting at a corner, sampled every 0.1.
        let mut pl = Polyline::from_points(
            7,
            (0..=20).map(|k| {
                let t = k as f64 / 10.0;
                if t <= 1.0 {
                    DVec3::new(t, 0.0, 0.0)
                } else {
                    DVec3::new(1.0, t - 1.0, 0.0)
                }
            }),
        );
        pl.vertices[10].corner = true;
        let pieces = typed::pieces(&pl, 1e-6);
        assert_eq!(pieces.len(), 2);
        assert!(pieces.iter().all(|p| p.kind == typed::Kind::Line));
        assert_eq!(pieces[0].end, pieces[1].start);
    }
}
