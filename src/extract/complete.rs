//! Stage 5: completion of the grown polylines (Daniels 2007 section 3.6, 2008 section 3.5).
//!
//! Each free end looks ahead along its tangent (from the last four vertices) within a cone:
//! - a corner found by the projection stage: the end is connected to it (corners joining fewer
//!   than two curves, or two curves running straight through, are not kept);
//! - the end of another curve with an opposite tangent: the gap is closed (a curve meeting its
//!   own other end becomes closed);
//! - the interior of another curve: that curve is split there and a corner created;
//! - the end of another curve at an angle: both meet at a corner where their tangents cross;
//! - nothing: a dissipating end, left alone.
//! Then short fragments with two free ends are dropped and the curves are relaxed by
//! inverse-distance Laplacian smoothing with ends and corners fixed.

use glam::DVec3;
use std::collections::HashMap;

/// A curve being completed.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// Vertices.
    pub v: Vec<DVec3>,
    /// Per vertex: is it a corner shared with other curves.
    pub corner: Vec<bool>,
    /// Closed loop.
    pub closed: bool,
}

impl Curve {
    /// An open curve through `v` without corners.
    pub fn new(v: Vec<DVec3>, closed: bool) -> Curve {
        let corner = vec![false; v.len()];
        Curve { v, corner, closed }
    }

    fn length(&self) -> f64 {
        self.v.windows(2).map(|w| w[0].distance(w[1])).sum()
    }

    /// Position, outward tangent and corner flag of end `e` (0: first vertex, 1: last).
    fn end(&self, e: usize) -> (DVec3, DVec3, bool) {
        let n = self.v.len();
        let (x, k) = if e == 0 { (self.v[0], 0) } else { (self.v[n - 1], n - 1) };
        let m = n.min(4);
        let inner: DVec3 = if e == 0 { self.v[..m].iter().sum::<DVec3>() } else { self.v[n - m..].iter().sum::<DVec3>() } / m as f64;
        let t = (x - inner).normalize_or_zero();
        (x, t, self.corner[k])
    }

    fn push_end(&mut self, e: usize, p: DVec3, corner: bool) {
        if e == 0 {
            self.v.insert(0, p);
            self.corner.insert(0, corner);
        } else {
            self.v.push(p);
            self.corner.push(corner);
        }
    }
}

/// Completion parameters.
#[derive(Clone, Copy, Debug)]
pub struct CompleteParams {
    /// The growing step s_max.
    pub step: f64,
    /// Search distance, in steps.
    pub reach: f64,
    /// Half-aperture of the search cone, degrees.
    pub aperture_deg: f64,
    /// Curves shorter than this many steps with two free ends are dropped.
    pub min_steps: f64,
    /// Laplacian smoothing passes.
    pub smooth_passes: usize,
}

/// Completes `curves` using the projection stage's `corners`.
pub fn complete(mut curves: Vec<Curve>, corners: &[DVec3], p: &CompleteParams) -> Vec<Curve> {
    curves.retain(|c| c.v.len() >= 2);
    attach_corners(&mut curves, corners, p);
    resolve_free_ends(&mut curves, p);
    let min_len = p.min_steps * p.step;
    curves.retain(|c| {
        let free = |k: usize| !c.corner[k];
        c.closed || c.length() >= min_len || !(free(0) && free(c.v.len() - 1))
    });
    for c in &mut curves {
        laplacian(c, p.smooth_passes);
    }
    curves
}

fn in_cone(x: DVec3, t: DVec3, q: DVec3, cos: f64, near: f64) -> bool {
    let d = q - x;
    let l = d.length();
    l <= near || d.dot(t) >= cos * l
}

/// A uniform hash grid over positions; a query visits every cell a ball touches, so the cost
/// of a lookup does not grow with the number of curves (the edge cloud of a whole scan can
/// grow thousands of them).
struct Grid<T> {
    cell: f64,
    map: HashMap<[i64; 3], Vec<T>>,
}

impl<T: Copy> Grid<T> {
    fn new(cell: f64) -> Grid<T> {
        Grid { cell: cell.max(f64::MIN_POSITIVE), map: HashMap::new() }
    }

    fn key(&self, p: DVec3) -> [i64; 3] {
        (p / self.cell).floor().to_array().map(|c| c as i64)
    }

    fn insert(&mut self, p: DVec3, t: T) {
        self.map.entry(self.key(p)).or_default().push(t);
    }

    /// Calls `f` for every item in the cells that the ball of radius `r` around `p` touches
    /// (a superset of the items within `r`; callers test the distance).
    fn near(&self, p: DVec3, r: f64, mut f: impl FnMut(T)) {
        let (lo, hi) = (self.key(p - DVec3::splat(r)), self.key(p + DVec3::splat(r)));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    if let Some(items) = self.map.get(&[x, y, z]) {
                        items.iter().for_each(|&t| f(t));
                    }
                }
            }
        }
    }
}

/// Connects ends to the corners of the projection stage.
fn attach_corners(curves: &mut [Curve], corners: &[DVec3], p: &CompleteParams) {
    let reach = p.reach * p.step;
    let cos = p.aperture_deg.to_radians().cos();
    let mut grid = Grid::new(reach);
    for (k, &q) in corners.iter().enumerate() {
        grid.insert(q, k);
    }
    // Which corner each end would join: the nearest in its cone (the lowest index on a tie).
    let mut claims: Vec<Vec<(usize, usize, f64)>> = vec![vec![]; corners.len()];
    for (ci, c) in curves.iter().enumerate() {
        if c.closed {
            continue;
        }
        for e in 0..2 {
            let (x, t, _) = c.end(e);
            let mut best: Option<(f64, usize)> = None;
            grid.near(x, reach, |k| {
                let d = corners[k].distance(x);
                if d <= reach && in_cone(x, t, corners[k], cos, p.step) && best.map_or(true, |b| (d, k) < b) {
                    best = Some((d, k));
                }
            });
            if let Some((d, k)) = best {
                claims[k].push((ci, e, d));
            }
        }
    }
    for (k, cl) in claims.iter().enumerate() {
        if cl.len() < 2 {
            continue;
        }
        if cl.len() == 2 {
            // Two curves running straight through a "corner": not a corner.
            let (a, b) = (curves[cl[0].0].end(cl[0].1).1, curves[cl[1].0].end(cl[1].1).1);
            if a.dot(b) < -(20f64.to_radians().cos()) {
                continue;
            }
        }
        for &(ci, e, _) in cl {
            curves[ci].push_end(e, corners[k], true);
        }
    }
}

/// The vertices of all curves in a grid. A curve that changes gets a new version and its
/// vertices are added again; entries of older versions are skipped.
struct Vertices {
    grid: Grid<(u32, u32, u32)>,
    version: Vec<u32>,
}

impl Vertices {
    fn new(curves: &[Curve], cell: f64) -> Vertices {
        let mut v = Vertices { grid: Grid::new(cell), version: vec![] };
        for ci in 0..curves.len() {
            v.update(curves, ci);
        }
        v
    }

    /// Re-indexes curve `ci` after a change (or indexes it if new).
    fn update(&mut self, curves: &[Curve], ci: usize) {
        if ci >= self.version.len() {
            self.version.resize(ci + 1, 0);
        }
        self.version[ci] += 1;
        let ver = self.version[ci];
        for (vi, &q) in curves[ci].v.iter().enumerate() {
            self.grid.insert(q, (ci as u32, ver, vi as u32));
        }
    }
}

/// Gives every free end its action (see the module notes), in passes over the curves until a
/// pass changes nothing. An end that acted is looked at again at once (after a join it is a
/// different end); every action removes at least one free end, so the passes end.
fn resolve_free_ends(curves: &mut Vec<Curve>, p: &CompleteParams) {
    let reach = p.reach * p.step;
    let cos = p.aperture_deg.to_radians().cos();
    let mut index = Vertices::new(curves, reach);
    loop {
        let mut changed = false;
        let mut ci = 0;
        while ci < curves.len() {
            let mut again = false;
            for e in 0..2 {
                // (Curves joined into another are left empty until the end.)
                if curves[ci].closed || curves[ci].v.len() < 2 {
                    break;
                }
                let (x, t, attached) = curves[ci].end(e);
                if attached || t == DVec3::ZERO {
                    continue;
                }
                let own_end = if e == 0 { 0 } else { curves[ci].v.len() - 1 };
                // Nearest vertex ahead, of any curve (the lowest curve, then vertex, on a tie);
                // on its own curve only the other end.
                let mut best: Option<(f64, usize, usize)> = None;
                index.grid.near(x, reach, |(cj, ver, vi)| {
                    let (cj, vi) = (cj as usize, vi as usize);
                    if ver != index.version[cj] {
                        return;
                    }
                    let c = &curves[cj];
                    if cj == ci && (vi != c.v.len() - 1 - own_end || c.v.len() < 4) {
                        return;
                    }
                    let q = c.v[vi];
                    let d = q.distance(x);
                    if d > reach || d == 0.0 || !in_cone(x, t, q, cos, p.step) {
                        return;
                    }
                    if best.map_or(true, |b| (d, cj, vi) < b) {
                        best = Some((d, cj, vi));
                    }
                });
                let Some((_, cj, vi)) = best else { continue };
                let before = curves.len();
                if act(curves, ci, e, cj, vi, cos, reach) {
                    for k in [ci, cj].into_iter().chain(before..curves.len()) {
                        index.update(curves, k);
                    }
                    changed = true;
                    again = true;
                    break;
                }
            }
            if !again {
                ci += 1;
            }
        }
        if !changed {
            break;
        }
    }
    curves.retain(|c| !c.v.is_empty());
}

/// Connects end `e` of curve `ci` to vertex `vi` of curve `cj`. Returns true if curves changed.
fn act(curves: &mut Vec<Curve>, ci: usize, e: usize, cj: usize, vi: usize, cos: f64, reach: f64) -> bool {
    let (x, t, _) = curves[ci].end(e);
    let target = curves[cj].clone();
    let last = target.v.len() - 1;
    let is_end = !target.closed && (vi == 0 || vi == last);
    if target.corner[vi] {
        curves[ci].push_end(e, target.v[vi], true);
        return true;
    }
    if is_end {
        let te = if vi == 0 { 0 } else { 1 };
        let (y, u, _) = target.end(te);
        if t.dot(u) <= -cos {
            // Opposite tangents: a gap.
            if ci == cj {
                curves[ci].closed = true;
            } else {
                join(curves, ci, e, cj, te);
            }
            return true;
        }
        // Two ends at an angle: they meet where their tangent lines pass closest, if that is
        // ahead of both and within reach; otherwise they are left alone.
        let Some(c) = closest_between_lines(x, t, y, u) else { return false };
        let ok = |z: DVec3, d: DVec3| (c - z).dot(d) >= -0.25 * reach && c.distance(z) <= reach;
        if !ok(x, t) || !ok(y, u) {
            return false;
        }
        curves[ci].push_end(e, c, true);
        curves[cj].push_end(te, c, true);
        return true;
    }
    // An interior vertex near a free end of a curve running the same way is that curve's
    // overlapping end, not a junction: treat it as the end.
    if !target.closed {
        let dir = (target.v[(vi + 1).min(last)] - target.v[vi.saturating_sub(1)]).normalize_or_zero();
        let parallel = dir.dot(t).abs() > 30f64.to_radians().cos();
        let near_end = target.v[vi].distance(target.v[0]).min(target.v[vi].distance(target.v[last])) <= 2.0 * reach;
        if parallel && near_end {
            let te = if target.v[vi].distance(target.v[0]) <= target.v[vi].distance(target.v[last]) { 0 } else { 1 };
            let end_index = if te == 0 { 0 } else { last };
            if target.corner[end_index] || (ci == cj && te == e) {
                return false;
            }
            return act(curves, ci, e, cj, end_index, cos, reach);
        }
    }
    // Interior vertex: split there and make it a corner.
    let corner = target.v[vi];
    let mut a = curves[cj].clone();
    if a.closed {
        // Re-open the loop at the corner.
        a.v.rotate_left(vi);
        a.corner.rotate_left(vi);
        a.v.push(corner);
        a.corner.push(true);
        a.corner[0] = true;
        a.closed = false;
        curves[cj] = a;
    } else {
        let mut b = Curve { v: a.v.split_off(vi), corner: a.corner.split_off(vi), closed: false };
        a.v.push(corner);
        a.corner.push(true);
        b.corner[0] = true;
        curves[cj] = a;
        curves.push(b);
    }
    curves[ci].push_end(e, corner, true);
    true
}

fn join(curves: &mut Vec<Curve>, ci: usize, e: usize, cj: usize, f: usize) {
    let mut a = curves[ci].clone();
    let mut b = curves[cj].clone();
    if e == 0 {
        a.v.reverse();
        a.corner.reverse();
    }
    if f == 1 {
        b.v.reverse();
        b.corner.reverse();
    }
    a.v.extend(b.v);
    a.corner.extend(b.corner);
    curves[ci] = a;
    // (Left empty, not removed, so that the other curves keep their places while ends are
    // being resolved.)
    curves[cj] = Curve::new(vec![], false);
}

/// Midpoint of the closest points of lines x + s t and y + r u, if they are not parallel.
fn closest_between_lines(x: DVec3, t: DVec3, y: DVec3, u: DVec3) -> Option<DVec3> {
    let w = x - y;
    let (a, b, c, d, e) = (t.dot(t), t.dot(u), u.dot(u), t.dot(w), u.dot(w));
    let den = a * c - b * b;
    if den < 1e-6 {
        return None;
    }
    let s = (b * e - c * d) / den;
    let r = (a * e - b * d) / den;
    Some((x + t * s + y + u * r) * 0.5)
}

/// Inverse-distance weighted Laplacian smoothing; ends and corners stay fixed.
fn laplacian(c: &mut Curve, passes: usize) {
    let n = c.v.len();
    for _ in 0..passes {
        let old = c.v.clone();
        for i in 0..n {
            let (prev, next) = if c.closed {
                ((i + n - 1) % n, (i + 1) % n)
            } else if i == 0 || i == n - 1 {
                continue;
            } else {
                (i - 1, i + 1)
            };
            if c.corner[i] {
                continue;
            }
            let (wa, wb) = (1.0 / old[i].distance(old[prev]).max(1e-12), 1.0 / old[i].distance(old[next]).max(1e-12));
            let target = (old[prev] * wa + old[next] * wb) / (wa + wb);
            c.v[i] = old[i] + (target - old[i]) * 0.5;
        }
    }
}
