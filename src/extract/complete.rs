//! Stage 5: completion of the grown polylines (Daniels 2007 section 3.6, 2008 section 3.5).
//!
//! Each free end looks ahead along its tangent (from the last four vertices) within a cone, no
//! farther than its curve is long:
//! - a corner found by the projection stage: the end is connected to it (corners joining fewer
//!   than two curves, or two curves running straight through, are not kept);
//! - the end of another curve with an opposite tangent: the gap is closed (a curve meeting its
//!   own other end becomes closed);
//! - the interior of another curve: that curve is split there and a corner created;
//! - the end of another curve at an angle: both meet at a corner where their tangents cross;
//! - nothing: a dissipating end, left alone.
//!
//! Then each corner is re-solved from the straight runs of its curves just outside the RMLS
//! radius, where the edge points are not biased by a third surface, and those runs are
//! continued straight into it (see `resolve_corners`).
//! Then short fragments with two free ends are dropped and the curves are relaxed by
//! inverse-distance Laplacian smoothing in Taubin's shrink-free form, with ends and corners fixed.

use crate::grid::HashGrid;
use glam::DVec3;

/// A curve being completed.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Curve {
    /// Vertices.
    pub v: Vec<DVec3>,
    /// Per vertex: is it a corner shared with other curves.
    pub corner: Vec<bool>,
    /// Closed loop.
    pub closed: bool,
}

impl Curve {
    /// An open curve through `v` without corners.
    pub(crate) fn new(v: Vec<DVec3>, closed: bool) -> Curve {
        let corner = vec![false; v.len()];
        Curve { v, corner, closed }
    }

    fn length(&self) -> f64 {
        self.v.windows(2).map(|w| w[0].distance(w[1])).sum()
    }

    /// How far an end of this curve may look ahead to connect: `reach`, but no farther than
    /// the curve is long. A fragment's tangent is no surer than the fragment is long, and
    /// under noise the short fragments are the spurious ones: before this rule, links made
    /// from them to corners and other curves, often longer than the fragments themselves,
    /// were most of the length off the truth (anchor at 0.005 dB: 625 of 1076 off-truth
    /// samples lay on such links).
    fn look(&self, reach: f64) -> f64 {
        reach.min(self.length())
    }

    /// Index of the vertex at end `e` (0: first vertex, 1: last).
    fn end_index(&self, e: usize) -> usize {
        if e == 0 {
            0
        } else {
            self.v.len() - 1
        }
    }

    /// The `k`-th vertex counted inwards from end `e`.
    fn inward(&self, e: usize, k: usize) -> DVec3 {
        self.v[if e == 0 { k } else { self.v.len() - 1 - k }]
    }

    /// Position, outward tangent and corner flag of end `e` (0: first vertex, 1: last).
    fn end(&self, e: usize) -> (DVec3, DVec3, bool) {
        let n = self.v.len();
        let k = self.end_index(e);
        let x = self.v[k];
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
pub(crate) struct CompleteParams {
    /// The growing step s_max.
    pub step: f64,
    /// Search distance, in steps.
    pub reach: f64,
    /// Half-aperture of the search cone, degrees.
    pub aperture_deg: f64,
    /// Curves shorter than this many steps with two free ends are dropped.
    pub min_steps: f64,
    /// Relaxation passes (each a Taubin pair, see `laplacian`).
    pub smooth_passes: usize,
    /// Edge points this close to a corner were projected from neighbourhoods that reach a third
    /// surface and are biased: curve vertices within it are replaced by a straight run into the
    /// corner.
    pub corner_zone: f64,
}

/// Completes `curves` using the projection stage's `corners`. Once `cancel` is set, what comes
/// back is partial (the caller sees the flag and discards it).
pub(crate) fn complete(mut curves: Vec<Curve>, corners: &[DVec3], p: &CompleteParams, cancel: &crate::cancel::Cancel) -> Vec<Curve> {
    curves.retain(|c| c.v.len() >= 2);
    attach_corners(&mut curves, corners, p);
    resolve_free_ends(&mut curves, p, cancel);
    if cancel.is_set() {
        return curves;
    }
    resolve_corners(&mut curves, p.corner_zone, corners);
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

/// The cone an end looks into: from its position `x` along its tangent `t`, `cos` the cosine
/// of its half-angle.
#[derive(Clone, Copy)]
struct Cone {
    x: DVec3,
    t: DVec3,
    cos: f64,
}

impl Cone {
    fn holds(&self, q: DVec3) -> bool {
        let d = q - self.x;
        d.dot(self.t) >= self.cos * d.length()
    }
}

/// True if end `e` of curve `c` (looking into `cone`) reaches `q`: within its cone, or within
/// `near` and not behind it (see [`behind`]).
fn reaches(c: &Curve, e: usize, cone: Cone, q: DVec3, near: f64) -> bool {
    cone.holds(q) || q.distance(cone.x) <= near && !behind(c, e, q)
}

/// True if `q` is nearer the other end of curve `c` than its end `e`. An end takes a corner or
/// a vertex within a step even outside its cone (its tangent is unsure that close), but not
/// one that is its curve's other end's: where a short curve starts at a corner, its far end
/// is within a step of the same corner, and taking it made the curve a loop there and back.
/// (A curve that overshot a corner still takes it: its other end is far.)
fn behind(c: &Curve, e: usize, q: DVec3) -> bool {
    c.v[c.end_index(1 - e)].distance_squared(q) < c.v[c.end_index(e)].distance_squared(q)
}

/// Connects ends to the corners of the projection stage.
fn attach_corners(curves: &mut [Curve], corners: &[DVec3], p: &CompleteParams) {
    let reach = p.reach * p.step;
    let cos = p.aperture_deg.to_radians().cos();
    let mut grid = HashGrid::new(reach);
    for (k, &q) in corners.iter().enumerate() {
        grid.insert(q, k);
    }
    // Which corner each end would join: the nearest in its cone (the lowest index on a tie).
    let mut claims: Vec<Vec<(usize, usize, f64)>> = vec![vec![]; corners.len()];
    for (ci, c) in curves.iter().enumerate() {
        if c.closed {
            continue;
        }
        let look = c.look(reach);
        for e in 0..2 {
            let (x, t, _) = c.end(e);
            let mut best: Option<(f64, usize)> = None;
            grid.near(x, look, |k| {
                let d = corners[k].distance(x);
                if d <= look && reaches(c, e, Cone { x, t, cos }, corners[k], p.step) && best.is_none_or(|b| (d, k) < b) {
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
/// vertices are added again; entries of older versions are skipped, and dropped once they
/// outnumber the current ones (a long curve that many ends join would otherwise fill the grid
/// with its old versions: 0.3 GB at 4 M vertices).
struct Vertices {
    cell: f64,
    grid: HashGrid<(u32, u32, u32)>,
    version: Vec<u32>,
    /// Each curve's vertices in its current version's entries.
    indexed: Vec<usize>,
    /// Entries in the grid, and those of current versions.
    entries: usize,
    current: usize,
}

impl Vertices {
    fn new(curves: &[Curve], cell: f64) -> Vertices {
        let mut v = Vertices { cell, grid: HashGrid::new(cell), version: vec![], indexed: vec![], entries: 0, current: 0 };
        for ci in 0..curves.len() {
            v.update(curves, ci);
        }
        v
    }

    /// Re-indexes curve `ci` after a change (or indexes it if new).
    fn update(&mut self, curves: &[Curve], ci: usize) {
        if ci >= self.version.len() {
            self.version.resize(ci + 1, 0);
            self.indexed.resize(ci + 1, 0);
        }
        self.version[ci] += 1;
        self.insert(curves, ci);
        let n = curves[ci].v.len();
        self.current = self.current - self.indexed[ci] + n;
        self.indexed[ci] = n;
        if self.entries > 2 * self.current + 4096 {
            self.compact(curves);
        }
    }

    fn insert(&mut self, curves: &[Curve], ci: usize) {
        let ver = self.version[ci];
        for (vi, &q) in curves[ci].v.iter().enumerate() {
            self.grid.insert(q, (ci as u32, ver, vi as u32));
        }
        self.entries += curves[ci].v.len();
    }

    /// A new grid of the indexed curves' vertices as they are now, at their current versions.
    /// (A curve changed but not yet updated gets entries that its update makes old, as before.)
    fn compact(&mut self, curves: &[Curve]) {
        (self.grid, self.entries) = (HashGrid::new(self.cell), 0);
        for ci in 0..self.version.len() {
            self.insert(curves, ci);
            self.indexed[ci] = curves[ci].v.len();
        }
        self.current = self.entries;
    }
}

/// Gives every free end its action (see the module notes), in passes over the curves until a
/// pass changes nothing. An end that acted is looked at again at once (after a join it is a
/// different end); every action removes at least one free end, so the passes end.
fn resolve_free_ends(curves: &mut Vec<Curve>, p: &CompleteParams, cancel: &crate::cancel::Cancel) {
    let reach = p.reach * p.step;
    let cos = p.aperture_deg.to_radians().cos();
    let mut index = Vertices::new(curves, reach);
    loop {
        let mut changed = false;
        let mut ci = 0;
        while ci < curves.len() {
            if ci % 1024 == 0 && cancel.is_set() {
                return;
            }
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
                let own_end = curves[ci].end_index(e);
                let look = curves[ci].look(reach);
                // Nearest vertex ahead, of any curve (the lowest curve, then vertex, on a tie);
                // on its own curve only the other end.
                let mut best: Option<(f64, usize, usize)> = None;
                index.grid.near(x, look, |(cj, ver, vi)| {
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
                    if d > look || d == 0.0 || !reaches(&curves[ci], e, Cone { x, t, cos }, q, p.step) {
                        return;
                    }
                    if best.is_none_or(|b| (d, cj, vi) < b) {
                        best = Some((d, cj, vi));
                    }
                });
                let Some((_, cj, vi)) = best else { continue };
                let before = curves.len();
                if act(curves, (ci, e), (cj, vi), cos, reach) {
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

/// Connects end `e` of curve `ci` to vertex `vi` of curve `cj`, looking as far as `reach`
/// within the cone of cosine `cos`. Returns true if curves changed.
fn act(curves: &mut Vec<Curve>, (ci, e): (usize, usize), (cj, vi): (usize, usize), cos: f64, reach: f64) -> bool {
    let (x, t, _) = curves[ci].end(e);
    let target = &curves[cj];
    let last = target.v.len() - 1;
    let is_end = !target.closed && (vi == 0 || vi == last);
    if target.corner[vi] {
        let p = target.v[vi];
        curves[ci].push_end(e, p, true);
        return true;
    }
    if is_end {
        let te = if vi == 0 { 0 } else { 1 };
        let (y, u, _) = target.end(te);
        let target_look = target.look(reach);
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
        // ahead of both and within each one's look-ahead; otherwise they are left alone.
        let Some(c) = closest_between_lines(x, t, y, u) else { return false };
        let ok = |z: DVec3, d: DVec3, look: f64| (c - z).dot(d) >= -0.25 * look && c.distance(z) <= look;
        if !ok(x, t, curves[ci].look(reach)) || !ok(y, u, target_look) {
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
            return act(curves, (ci, e), (cj, end_index), cos, reach);
        }
    }
    // Interior vertex: split there and make it a corner.
    let corner = target.v[vi];
    let mut a = std::mem::replace(&mut curves[cj], Curve::new(vec![], false));
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

fn join(curves: &mut [Curve], ci: usize, e: usize, cj: usize, f: usize) {
    let mut a = std::mem::replace(&mut curves[ci], Curve::new(vec![], false));
    let mut b = std::mem::replace(&mut curves[cj], Curve::new(vec![], false));
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

/// Farthest a line may pass from the corner re-solved from it (see `resolve_corners`), in
/// corner zones. The lines of a true corner meet to within the scatter of the curve vertices
/// they are fitted to: on the simple noisy shapes (cube, step, chamfer, octahedron, at 0.01 dB,
/// 0.02 dB and 4 kappa) within 0.01-0.10 zones. Where lines missed by more (0.23-0.44 zones on
/// fandisk at 0.02 dB), a curve that is not straight, or one joined to the wrong corner, had
/// passed as straight, and the corner moved away from the truth by up to 2.6 tolerances.
const LINE_MISS: f64 = 0.15;

/// Re-solves the corners and straightens the curves into them. Edge points within the RMLS
/// radius of a corner come from neighbourhoods that reach a third surface, and under noise
/// they, and the corners solved from them, are biased (at 0.02 dB noise on the cube, corners
/// were 0.02-0.09 dB off and curves bulged over the last radius). Where curve ends meet at a
/// corner, each end that runs straight from one to three `zone`s out gives the line it
/// follows between one and two zones out, where its edge points saw two surfaces only. With
/// two or more such lines fixing a point within `zone` of the corner, each passing within
/// [`LINE_MISS`] zones of it, the corner moves there and the straight ends drop their vertices
/// inside the zone, running straight into it. With one such line, at a corner the projection
/// stage `found` from three surfaces (a straight edge meeting the rims of a boss or a hole),
/// the corner moves onto the line, as near as it can to where it was: the line fixes it
/// across, the curved ends say nothing more. A corner completion made (where an end split a
/// curve, or two ends met) is left off the line: it is pinned by the curve it split, and moved
/// onto the line of a false curve joining that curve, it would leave it. A curved end (a small
/// hole's rim, say) neither gives a line nor is straightened, and a corner of only two curves
/// is left where it is: it is a bend, or a join that completion made, and two lines always
/// nearly meet somewhere.
fn resolve_corners(curves: &mut [Curve], zone: f64, found: &[DVec3]) {
    if zone <= 0.0 {
        return;
    }
    // The curve ends at each corner, keyed by the corner's exact position (shared vertices).
    let key = |q: DVec3| [q.x.to_bits(), q.y.to_bits(), q.z.to_bits()];
    let found: std::collections::BTreeSet<[u64; 3]> = found.iter().map(|&q| key(q)).collect();
    let mut at: std::collections::BTreeMap<[u64; 3], Vec<(usize, usize)>> = Default::default();
    for (ci, c) in curves.iter().enumerate() {
        if c.closed || c.v.len() < 2 {
            continue;
        }
        for e in 0..2 {
            let k = c.end_index(e);
            if c.corner[k] {
                at.entry(key(c.v[k])).or_default().push((ci, e));
            }
        }
    }
    for (k, ends) in at {
        let q = DVec3::new(f64::from_bits(k[0]), f64::from_bits(k[1]), f64::from_bits(k[2]));
        if ends.len() < 3 {
            continue;
        }
        // Normal equations of the point nearest to the lines: sum (I - d d^T) (x - mean) = 0.
        let (mut a, mut b) = (glam::DMat3::ZERO, DVec3::ZERO);
        let mut straight = vec![];
        for &(ci, e) in &ends {
            let Some((mean, d)) = line_out_of_zone(&curves[ci], e, q, zone) else { continue };
            let m = glam::DMat3::IDENTITY - glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
            a += m;
            b += m * mean;
            straight.push((ci, e, mean, d));
        }
        // One straight end fixes the corner across its line only: it moves onto that line.
        // (Nearly parallel lines, such as two curves running straight through, fix no point.)
        let solved = match straight[..] {
            [] => continue,
            [_] if !found.contains(&k) => continue,
            [(_, _, mean, d)] => mean + (q - mean).project_onto_normalized(d),
            _ if a.determinant().abs() <= 1e-3 => continue,
            _ => a.inverse() * b,
        };
        if !solved.is_finite() || solved.distance(q) > zone {
            continue;
        }
        if straight.iter().any(|&(_, _, mean, d)| (solved - mean).reject_from_normalized(d).length() > LINE_MISS * zone) {
            continue;
        }
        for &(ci, e) in &ends {
            let k = curves[ci].end_index(e);
            curves[ci].v[k] = solved;
        }
        for (ci, e, _, _) in straight {
            trim_zone(&mut curves[ci], e, zone);
        }
    }
}

/// The line (a point on it and its direction) that end `e` of `c`, at corner `q`, follows
/// between one and two `zone`s from the corner, if the curve runs straight from one to three
/// zones out: no vertex there farther than a tenth of the zone from the chord.
fn line_out_of_zone(c: &Curve, e: usize, q: DVec3, zone: f64) -> Option<(DVec3, DVec3)> {
    let inward = (1..c.v.len()).map(|k| c.inward(e, k));
    let run: Vec<DVec3> = inward.take_while(|v| v.distance(q) < 3.0 * zone).filter(|v| v.distance(q) >= zone).collect();
    let (&first, &last) = (run.first()?, run.last()?);
    let chord = (last - first).normalize_or_zero();
    let off = |v: &DVec3| (*v - first).reject_from_normalized(chord).length();
    if chord == DVec3::ZERO || run.iter().any(|v| off(v) > 0.1 * zone) {
        return None;
    }
    let near: Vec<DVec3> = run.into_iter().take_while(|v| v.distance(q) < 2.0 * zone).collect();
    let (&first, &last) = (near.first()?, near.last()?);
    let d = (last - first).normalize_or_zero();
    if near.len() < 2 || d == DVec3::ZERO {
        return None;
    }
    Some((near.iter().sum::<DVec3>() / near.len() as f64, d))
}

/// Removes the vertices of end `e` of `c` within `zone` of that end, up to the first one
/// outside it (or a corner, or the far end).
fn trim_zone(c: &mut Curve, e: usize, zone: f64) {
    if e == 0 {
        c.v.reverse();
        c.corner.reverse();
    }
    let n = c.v.len();
    if n > 2 {
        let q = c.v[n - 1];
        let mut k = n - 2;
        while k > 0 && !c.corner[k] && c.v[k].distance(q) < zone {
            k -= 1;
        }
        c.v.drain(k + 1..n - 1);
        c.corner.drain(k + 1..n - 1);
    }
    if e == 0 {
        c.v.reverse();
        c.corner.reverse();
    }
}

/// Inverse-distance weighted Laplacian smoothing without shrinkage (Taubin 1995): each pass
/// moves vertices half way to their neighbours' weighted mean, then back by a little more
/// (factor -0.53), which damps the vertex-to-vertex jitter but not the curve's bends. (Plain
/// Laplacian passes pull every bend inwards: on the cylinder at 0.01 dB noise the rims shrank
/// by 0.0014 dB.) Ends and corners stay fixed.
fn laplacian(c: &mut Curve, passes: usize) {
    for _ in 0..passes {
        umbrella(c, 0.5);
        umbrella(c, -0.53);
    }
}

fn umbrella(c: &mut Curve, factor: f64) {
    let n = c.v.len();
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
        c.v[i] = old[i] + (target - old[i]) * factor;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A curve from corner `q` along `dir` from the origin, vertices every 0.1 out to 3, those
    /// nearer than `bent` to the origin pushed sideways (as biased edge points are).
    fn arm(q: DVec3, dir: DVec3, side: DVec3, bent: f64) -> Curve {
        let mut v = vec![q];
        v.extend((1..=30).map(|k| {
            let d = k as f64 * 0.1;
            dir * d + side * (0.2 * (bent - d).max(0.0))
        }));
        let mut c = Curve::new(v, false);
        c.corner[0] = true;
        c
    }

    #[test]
    fn a_corner_is_resolved_from_the_curves_outside_its_zone() {
        let q = DVec3::new(0.15, 0.1, 0.05);
        let mut curves = vec![arm(q, DVec3::X, DVec3::Y, 0.5), arm(q, DVec3::Y, DVec3::Z, 0.5), arm(q, DVec3::Z, DVec3::X, 0.5)];
        resolve_corners(&mut curves, 0.5, &[]);
        for c in &curves {
            assert!(c.v[0].length() < 1e-9, "corner at {:?}", c.v[0]);
            assert!(c.corner[0] && !c.corner[1]);
            // The run into the corner starts at the first vertex outside the zone.
            assert!(c.v[1].length() >= 0.5 - 1e-9 && c.v[1].length() < 0.6 + 1e-9, "{:?}", c.v[1]);
            assert_eq!(c.v.len(), 27);
        }
    }

    #[test]
    fn a_curved_end_is_not_straightened() {
        // A rim of radius 0.5 (one zone) leaves the corner upwards and bends over; the two
        // straight arms still fix the corner.
        let q = DVec3::new(0.1, 0.1, 0.0);
        let mut rim = vec![q];
        rim.extend((1..=30).map(|k| {
            let t = k as f64 * 0.1 / 0.5;
            DVec3::new(0.5 - 0.5 * t.cos(), 0.0, 0.5 * t.sin())
        }));
        let mut rim = Curve::new(rim, false);
        rim.corner[0] = true;
        let before = rim.v[1..].to_vec();
        let mut curves = vec![arm(q, DVec3::X, DVec3::Z, 0.5), arm(q, DVec3::Y, DVec3::Z, 0.5), rim];
        resolve_corners(&mut curves, 0.5, &[]);
        assert!(curves[0].v[0].length() < 1e-9 && curves[2].v[0] == curves[0].v[0]);
        assert_eq!(curves[2].v[1..], before[..]);
        assert_eq!(curves[0].v.len(), 27);
    }

    #[test]
    fn a_found_corner_of_one_straight_end_moves_onto_its_line() {
        // A straight arm along the x axis and two rims of radius 1 (two zones) leaving along y
        // and along z and curving back over -x; the corner lies 0.2 off the arm's line. It
        // moves onto the line, keeping its place along it; the rims are not straightened.
        let q = DVec3::new(-0.05, 0.12, 0.16);
        let rim = |out: DVec3| {
            let mut v = vec![q];
            v.extend((1..=30).map(|k| {
                let t = k as f64 * 0.1;
                out * t.sin() - DVec3::X * (1.0 - t.cos())
            }));
            let mut c = Curve::new(v, false);
            c.corner[0] = true;
            c
        };
        let (ry, rz) = (rim(DVec3::Y), rim(DVec3::Z));
        let before = [ry.v[1..].to_vec(), rz.v[1..].to_vec()];
        let mut curves = vec![arm(q, DVec3::X, DVec3::Y, 0.0), ry, rz];
        // A corner completion made (not one the projection found) stays where it is.
        let mut made = curves.clone();
        resolve_corners(&mut made, 0.5, &[]);
        assert_eq!(made, curves);
        resolve_corners(&mut curves, 0.5, &[q]);
        let moved = curves[0].v[0];
        assert!(moved.distance(DVec3::new(-0.05, 0.0, 0.0)) < 1e-9, "corner at {moved:?}");
        assert!(curves.iter().all(|c| c.v[0] == moved && c.corner[0]));
        assert_eq!(curves[1].v[1..], before[0][..]);
        assert_eq!(curves[2].v[1..], before[1][..]);
        // Without the straight arm, nothing fixes the corner: it stays.
        let mut rims = vec![rim(DVec3::Y), rim(DVec3::Z), rim(-DVec3::Y)];
        resolve_corners(&mut rims, 0.5, &[q]);
        assert!(rims.iter().all(|c| c.v[0] == q));
    }

    #[test]
    fn relaxation_damps_jitter_without_shrinking_a_loop() {
        // A unit circle of 64 vertices with alternating radial jitter of 0.01.
        let radius = |k: usize| 1.0 + if k.is_multiple_of(2) { 0.01 } else { -0.01 };
        let v = (0..64).map(|k| {
            let t = k as f64 * std::f64::consts::TAU / 64.0;
            DVec3::new(t.cos(), t.sin(), 0.0) * radius(k)
        });
        let mut c = Curve::new(v.collect(), true);
        laplacian(&mut c, 2);
        let r: Vec<f64> = c.v.iter().map(|p| p.length()).collect();
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let jitter = r.iter().map(|x| (x - mean).abs()).fold(0.0, f64::max);
        assert!((mean - 1.0).abs() < 1e-3, "mean radius {mean}");
        assert!(jitter < 0.003, "jitter {jitter}");
    }

    /// A straight curve along x (vertices every 0.1 from 0 to 3) and a curve of `n` vertices
    /// coming down towards its middle, its lower end 0.3 above it.
    fn branch_towards_a_line(n: usize) -> Vec<Curve> {
        let line = Curve::new((0..=30).map(|k| DVec3::new(k as f64 * 0.1, 0.0, 0.0)).collect(), false);
        let branch = Curve::new((0..n).rev().map(|k| DVec3::new(1.5, 0.3 + k as f64 * 0.1, 0.0)).collect(), false);
        vec![line, branch]
    }

    #[test]
    fn a_fragment_reaches_no_farther_than_it_is_long() {
        // Reach is 4 steps (0.4): the line is within it of the branch's lower end.
        let p = CompleteParams { step: 0.1, reach: 4.0, aperture_deg: 45.0, min_steps: 3.0, smooth_passes: 0, corner_zone: 0.0 };
        // A branch 0.5 long meets the line: the line is split at a new shared corner.
        let mut curves = branch_towards_a_line(6);
        resolve_free_ends(&mut curves, &p, &crate::cancel::Cancel::default());
        assert_eq!(curves.len(), 3);
        let corner = DVec3::new(1.5, 0.0, 0.0);
        assert!(curves.iter().all(|c| c.v.contains(&corner)));
        // A fragment 0.1 long does not: its tangent is no surer than that.
        let mut curves = branch_towards_a_line(2);
        let before = curves.clone();
        resolve_free_ends(&mut curves, &p, &crate::cancel::Cancel::default());
        assert_eq!(curves, before);
    }

    /// Straight curves along `dirs` from 3 towards the origin, ending at `last` along each.
    fn arms_towards_the_origin(dirs: &[DVec3], last: f64) -> Vec<Curve> {
        let line = |dir: DVec3| {
            let mut v: Vec<DVec3> = (1..=30).rev().map(|k| dir * (k as f64 * 0.1)).collect();
            v.push(dir * last);
            Curve::new(v, false)
        };
        dirs.iter().map(|&d| line(d)).collect()
    }

    #[test]
    fn an_end_does_not_take_the_corner_its_curve_started_from() {
        let p = CompleteParams { step: 0.1, reach: 4.0, aperture_deg: 45.0, min_steps: 3.0, smooth_passes: 0, corner_zone: 0.0 };
        // Two arms ending a step short of a corner at the origin, and a short piece grown from
        // the corner along y, its far end within a step of it.
        let tip = DVec3::new(0.0, 0.08, 0.0);
        let mut curves = arms_towards_the_origin(&[DVec3::X, DVec3::Z], 0.1);
        curves.push(Curve::new(vec![DVec3::ZERO, tip], false));
        let done = complete(curves, &[DVec3::ZERO], &p, &crate::cancel::Cancel::default());
        // The piece's first end takes the corner; its far end, whose cone looks away from it,
        // stays free (it once took the corner too: a loop there and back).
        let piece = done.iter().find(|c| c.v.contains(&tip)).expect("the piece");
        assert_eq!((piece.v.first(), piece.corner.first()), (Some(&DVec3::ZERO), Some(&true)), "{:?}", piece.v);
        assert_eq!((piece.v.last(), piece.corner.last()), (Some(&tip), Some(&false)), "{:?}", piece.v);
        assert!(done.iter().all(|c| c.closed || c.v[0] != c.v[c.v.len() - 1]), "{done:?}");
        // The arms meet the piece there.
        assert_eq!(done.iter().filter(|c| c.v.last() == Some(&DVec3::ZERO)).count(), 2, "{done:?}");
    }

    #[test]
    fn an_end_that_overshot_a_corner_takes_it() {
        let p = CompleteParams { step: 0.1, reach: 4.0, aperture_deg: 45.0, min_steps: 3.0, smooth_passes: 0, corner_zone: 0.0 };
        // Three arms whose ends went half a step past the corner at the origin: it lies behind
        // each end, nearer the end's neighbour than the end itself.
        let mut curves = arms_towards_the_origin(&[DVec3::X, DVec3::Y, DVec3::Z], 0.03);
        for c in curves.iter_mut() {
            let past = c.v[c.v.len() - 1] * (-0.05 / 0.03);
            c.push_end(1, past, false);
        }
        let done = complete(curves, &[DVec3::ZERO], &p, &crate::cancel::Cancel::default());
        assert!(done.iter().all(|c| c.v.last() == Some(&DVec3::ZERO) && c.corner.last() == Some(&true)), "{done:?}");
    }

    #[test]
    fn a_corner_of_two_curves_or_of_lines_that_miss_stays_where_it_was() {
        // Two straight arms meeting at an angle: their lines fix a point, but only two curves
        // meet there.
        let q = DVec3::new(0.15, 0.1, 0.05);
        let mut curves = vec![arm(q, DVec3::X, DVec3::Y, 0.5), arm(q, DVec3::Y, DVec3::Z, 0.5)];
        resolve_corners(&mut curves, 0.5, &[]);
        assert!(curves.iter().all(|c| c.v[0] == q && c.v.len() == 31));
        // Three arms, one of them shifted 0.3 (0.6 zones) sideways: no point lies within 0.15
        // zones of all three lines.
        let mut curves = vec![arm(q, DVec3::X, DVec3::Y, 0.5), arm(q, DVec3::Y, DVec3::Z, 0.5), arm(q, DVec3::Z, DVec3::X, 0.5)];
        for v in curves[2].v.iter_mut().skip(1) {
            *v += DVec3::new(0.0, 0.3, 0.0);
        }
        resolve_corners(&mut curves, 0.5, &[]);
        assert!(curves.iter().all(|c| c.v[0] == q && c.v.len() == 31));
    }

    /// Short, jittered polylines scattered in a box of 100 by 100 by 1 steps of 0.1 (some
    /// closed), and corners near some of their ends: many ends within the reach of others.
    fn scattered_lines(seed: u64) -> (Vec<Curve>, Vec<DVec3>) {
        let mut rng = crate::rng::Rng::new(seed);
        let (mut curves, mut corners) = (vec![], vec![]);
        for k in 0..80 {
            let start = DVec3::new(rng.range(0.0, 10.0), rng.range(0.0, 10.0), rng.range(0.0, 0.1));
            let a = rng.range(0.0, std::f64::consts::TAU);
            let dir = DVec3::new(a.cos(), a.sin(), 0.0);
            let n = 2 + (rng.next_u64() % 8) as usize;
            let jitter = |rng: &mut crate::rng::Rng| DVec3::new(rng.range(-0.01, 0.01), rng.range(-0.01, 0.01), 0.0);
            let v: Vec<DVec3> = (0..n).map(|i| start + dir * (0.1 * i as f64) + jitter(&mut rng)).collect();
            if k % 7 == 0 {
                corners.push(v[n - 1] + dir * 0.15);
            }
            curves.push(Curve::new(v, k % 31 == 30));
        }
        (curves, corners)
    }

    /// Curves as a sorted list of their exact vertices, corner flags and closure.
    fn canonical(curves: &[Curve]) -> Vec<(Vec<[u64; 3]>, Vec<bool>, bool)> {
        let mut out: Vec<_> = curves.iter().map(|c| (c.v.iter().map(|p| p.to_array().map(f64::to_bits)).collect(), c.corner.clone(), c.closed)).collect();
        out.sort();
        out
    }

    #[test]
    fn groups_complete_as_the_whole_does() {
        let p = CompleteParams { step: 0.1, reach: 4.0, aperture_deg: 45.0, min_steps: 3.0, smooth_passes: 2, corner_zone: 0.08 };
        let reach = p.reach * p.step;
        for seed in 1..=4 {
            let (lines, corners) = scattered_lines(seed);
            let whole = complete(lines.clone(), &corners, &p, &crate::cancel::Cancel::default());
            let groups = super::super::groups::groups(&lines.iter().map(|c| (c.v.clone(), c.closed)).collect::<Vec<_>>(), reach);
            let all = super::super::groups::Corners::new(&corners);
            let mut parts = vec![];
            for g in &groups {
                let group: Vec<Curve> = g.iter().map(|&i| lines[i as usize].clone()).collect();
                // (Each group indexes only the corners near its ends' box, as a batch does.)
                let ends: Vec<DVec3> = group.iter().filter(|c| !c.closed).flat_map(|c| [c.v[0], c.v[c.v.len() - 1]]).collect();
                let (lo, hi) = ends.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)));
                let corners = all.near_box(lo, hi, reach).near(ends);
                parts.extend(complete(group, &corners, &p, &crate::cancel::Cancel::default()));
            }
            // (The lines must interact, and fall into several groups, for this to say anything.)
            eprintln!("seed {seed}: {} groups, largest {}", groups.len(), groups.iter().map(Vec::len).max().unwrap_or(0));
            assert!(groups.len() >= 5 && groups.iter().any(|g| g.len() >= 5), "seed {seed}: {} groups", groups.len());
            assert_ne!(canonical(&whole), canonical(&lines), "seed {seed}: completion changed nothing");
            assert_eq!(canonical(&parts), canonical(&whole), "seed {seed}");
        }
    }

    #[test]
    fn a_corner_the_lines_do_not_fix_stays_where_it_was() {
        // Two curves running straight through: parallel lines fix no point.
        let q = DVec3::new(0.0, 0.05, 0.0);
        let mut curves = vec![arm(q, DVec3::X, DVec3::Y, 0.0), arm(q, -DVec3::X, DVec3::Y, 0.0)];
        resolve_corners(&mut curves, 0.5, &[]);
        assert!(curves.iter().all(|c| c.v[0] == q));
    }
}
