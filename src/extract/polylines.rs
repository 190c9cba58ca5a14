//! Stages 3 to 5 on edge clouds, a growth block at a time where they are local (see
//! [`blocks`]): corner grouping, smoothing (with the edge points around a block as context),
//! the consensus filter, polyline growing cut at the block's border, completion on the
//! stitched polylines, and the normals and evidence each curve takes from the edge cloud.

use super::blocks::{self, Blocks, Piece};
use super::complete;
use super::consensus;
use super::grow;
use super::params::Resolved;
use super::project::{self, WorldCorner, WorldEdge};
use super::smooth;
use crate::curves::{Polyline, Vertex};
use crate::keys::{bits_key, settle, snap, snap_quantum};
use crate::spatial::Index;
use glam::DVec3;
use rayon::prelude::*;

/// Snaps an edge point's position to quantum `q` and its normals to a millionth.
pub(crate) fn snap_edge(e: &mut WorldEdge, q: f64) {
    e.p = snap(e.p, q);
    e.n = e.n.map(|n| (n * 1e6).round() / 1e6 + glam::Vec3::ZERO);
}

fn normal_key(n: &[glam::Vec3; 2]) -> [[u32; 3]; 2] {
    [n[0].to_array(), n[1].to_array()].map(|v| v.map(f32::to_bits))
}

/// Groups with fewer corner points than this are taken as accidental.
const MIN_CORNER_SUPPORT: usize = 3;

/// Corner grouping (see [`project::group_corners`]) over the corner points of the whole cloud,
/// taken a part of it (a run's tile) at a time, with the groups in the order grouping all of
/// them at once gives, relative to an origin.
///
/// Grouping links only corner points within the corner radius of each other, so each linked
/// set (a component) is grouped alone as it is among all the others. A part's components with
/// no point within the radius of another part's corners are grouped with the part
/// ([`CornerGrouping::part`]); only the others are kept, to be grouped together at the end
/// ([`CornerGrouping::finish`]): the corner points near the parts' borders, not the cloud's.
pub(crate) struct CornerGrouping {
    origin: DVec3,
    q: f64,
    radius: f64,
    /// The bounds of each part's snapped corner points, relative to the origin (none if the
    /// part has none).
    boxes: Vec<Option<(DVec3, DVec3)>>,
}

/// A group of corner points: the member that stands for it (relative to the origin), and the
/// weight and position of its seed, which set its place in the order of all groups.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CornerGroup {
    at: DVec3,
    w: f64,
    key: [u64; 3],
}

/// What a part's corner points give: their groups, and the components to be grouped with
/// those of other parts.
#[derive(Debug, Default)]
pub(crate) struct PartCorners {
    groups: Vec<CornerGroup>,
    shared: Vec<WorldCorner>,
}

impl CornerGrouping {
    /// The snapped bounds of `corners` (none if empty), for [`CornerGrouping::new`].
    pub(crate) fn bounds(corners: &[WorldCorner], r: &Resolved) -> Option<(DVec3, DVec3)> {
        let q = snap_quantum(r.kappa);
        let p = corners.iter().map(|c| snap(c.p, q));
        p.clone().reduce(DVec3::min).zip(p.reduce(DVec3::max))
    }

    /// Grouping of the corner points of parts whose [`CornerGrouping::bounds`] are `bounds`,
    /// the groups relative to `origin`.
    pub(crate) fn new(bounds: &[Option<(DVec3, DVec3)>], origin: DVec3, r: &Resolved) -> CornerGrouping {
        let boxes = bounds.iter().map(|b| b.map(|(lo, hi)| (lo - origin, hi - origin))).collect();
        CornerGrouping { origin, q: snap_quantum(r.kappa), radius: r.corner_radius, boxes }
    }

    /// The groups of the components of part `part`'s corner points that are its alone; the
    /// other components' points are kept for [`CornerGrouping::finish`].
    pub(crate) fn part(&self, part: usize, corners: Vec<WorldCorner>) -> PartCorners {
        let Some(own) = self.boxes[part] else {
            debug_assert!(corners.is_empty(), "a part's corners out of its bounds");
            return PartCorners::default();
        };
        let (keys, points) = self.prepare(corners);
        // (Widened: a point is kept with the others on any doubt.)
        let reach = self.radius * 1.001 + 1e-9;
        let others: Vec<(DVec3, DVec3)> =
            (self.boxes.iter().enumerate()).filter_map(|(k, b)| b.filter(|_| k != part)).filter(|&(lo, hi)| box_gap((lo, hi), own) <= 2.0 * reach).collect();
        let near_other = |p: DVec3| others.iter().any(|&b| box_gap(b, (p, p)) <= reach);
        let mut out = PartCorners::default();
        for members in components(&points, self.radius) {
            if members.iter().any(|&i| near_other(points[i].p)) {
                out.shared.extend(members.iter().map(|&i| WorldCorner { p: DVec3::from_array(keys[i].map(f64::from_bits)), w: points[i].w }));
            } else {
                out.groups.extend(self.group(&members, &keys, &points));
            }
        }
        out
    }

    /// All groups: those of every part (in any order) and those of the components they share.
    pub(crate) fn finish(&self, parts: impl IntoIterator<Item = PartCorners>) -> Vec<DVec3> {
        let (mut groups, mut shared) = (vec![], vec![]);
        for p in parts {
            groups.extend(p.groups);
            shared.extend(p.shared);
        }
        let (keys, points) = self.prepare(shared);
        for members in components(&points, self.radius) {
            groups.extend(self.group(&members, &keys, &points));
        }
        // (The order of grouping all points at once: heaviest seed first, ties by position.)
        groups.sort_unstable_by(|a, b| b.w.total_cmp(&a.w).then(a.key.cmp(&b.key)));
        groups.into_iter().map(|g| g.at).collect()
    }

    /// Corner points snapped, in the order of their positions' keys (then weights), with
    /// those keys, and relative to the origin.
    fn prepare(&self, mut corners: Vec<WorldCorner>) -> (Vec<[u64; 3]>, Vec<project::CornerPoint>) {
        for c in corners.iter_mut() {
            c.p = snap(c.p, self.q);
            c.w = settle(c.w);
        }
        corners.sort_unstable_by(|a, b| bits_key(a.p).cmp(&bits_key(b.p)).then(a.w.total_cmp(&b.w)));
        let keys = corners.iter().map(|c| bits_key(c.p)).collect();
        (keys, corners.iter().map(|c| project::CornerPoint { p: c.p - self.origin, w: c.w }).collect())
    }

    /// The groups of the component `members` (in the order of `points`).
    fn group(&self, members: &[usize], keys: &[[u64; 3]], points: &[project::CornerPoint]) -> Vec<CornerGroup> {
        let set: Vec<project::CornerPoint> = members.iter().map(|&i| points[i]).collect();
        let seeded = project::seeded_groups(&set, self.radius, MIN_CORNER_SUPPORT);
        seeded.into_iter().map(|(s, at)| CornerGroup { at, w: set[s].w, key: keys[members[s]] }).collect()
    }
}

/// The gap between two boxes (0 where they meet).
fn box_gap(a: (DVec3, DVec3), b: (DVec3, DVec3)) -> f64 {
    (a.0 - b.1).max(b.0 - a.1).max(DVec3::ZERO).length()
}

/// The sets of `points` linked by distances within `radius`, each in the points' order; the
/// sets in the order of their first points.
fn components(points: &[project::CornerPoint], radius: f64) -> Vec<Vec<usize>> {
    let mut grid = crate::grid::HashGrid::new(radius);
    let mut sets = crate::sets::Sets::new(points.len());
    for (i, c) in points.iter().enumerate() {
        grid.near(c.p, radius, |j: u32| {
            if points[j as usize].p.distance(c.p) <= radius {
                sets.union(i as u32, j);
            }
        });
        grid.insert(c.p, i as u32);
    }
    sets.sets().into_iter().map(|s| s.into_iter().map(|i| i as usize).collect()).collect()
}

/// Largest distance from an edge point to the edge points that move it in stage 3: a block
/// of the edge cloud is smoothed exactly as in the whole cloud if every edge point this close
/// to the block is given as context.
pub(crate) fn smoothing_reach(r: &Resolved) -> f64 {
    2.0 * r.rmls_radius
}

/// Stage 3 for a block of the (snapped) edge cloud, positions relative to `origin`: the first
/// `own` points are smoothed, the rest are the context within [`smoothing_reach`] of them.
/// The smoothed positions are snapped as the input is.
pub(crate) fn smooth_block(points: &[DVec3], own: usize, grouped: &[DVec3], r: &Resolved) -> Vec<DVec3> {
    let sp = smooth::SmoothParams { linearity: r.linearity, max_radius: smoothing_reach(r) };
    let q = snap_quantum(r.kappa);
    let mut out = smooth::smooth(points, own, grouped, &sp);
    for p in out.iter_mut() {
        *p = snap(*p, q);
    }
    out
}

/// Smoothed edge points (positions relative to an origin, and the normals of each point's two
/// surfaces), as stage 4 takes them.
#[derive(Clone, Debug, Default)]
pub(crate) struct SmoothedEdges {
    /// Smoothed positions.
    pub points: Vec<DVec3>,
    /// The two surface normals of each.
    pub normals: Vec<[glam::Vec3; 2]>,
    /// Edge points dropped by the consensus filter.
    pub unconfirmed: u64,
}

impl SmoothedEdges {
    /// Puts the points in the order of their positions, then normals, so that what follows
    /// does not depend on the order they came in. (Points equal in both are interchangeable.)
    pub(crate) fn sort(&mut self) {
        let (p, n) = (&self.points, &self.normals);
        let mut perm: Vec<u32> = (0..p.len() as u32).collect();
        perm.par_sort_unstable_by(|&a, &b| {
            let (a, b) = (a as usize, b as usize);
            bits_key(p[a]).cmp(&bits_key(p[b])).then(normal_key(&n[a]).cmp(&normal_key(&n[b])))
        });
        self.points = perm.iter().map(|&i| p[i as usize]).collect();
        self.normals = perm.iter().map(|&i| n[i as usize]).collect();
    }
}

/// Stage 3 and, on noise-limited clouds (see [`Resolved::noise_limited`]), the consensus filter
/// for a block of the edge cloud (see [`smooth_block`]; the normals are those of `points`,
/// context included): the smoothed positions of the first `own` points, and whether their
/// neighbours confirm each (see [`consensus`]). (The smoothing takes every edge point as
/// context, confirmed or not, so that the block's context need reach no further.)
pub(crate) fn smooth_and_confirm(points: &[DVec3], normals: &[[glam::Vec3; 2]], own: usize, grouped: &[DVec3], r: &Resolved) -> (Vec<DVec3>, Vec<bool>) {
    let smoothed = smooth_block(points, own, grouped, r);
    // (Without noise, edge points off a crease are rare and the filter mostly cut sparse
    // stretches into more pieces: nonuniformly sampled fandisk 34 -> 45 curves, the 5 M scene
    // 366 -> 376; so it runs where the neighbourhoods are sized by the noise.)
    let keep = if r.noise_limited() { consensus::confirmed(points, normals, own, r.step) } else { vec![true; own] };
    (smoothed, keep)
}

/// How far past a block's core its edge points are needed to grow, smooth and confirm its
/// core's polylines as in the whole cloud: the growing halo, and the smoothing reach beyond it.
pub(crate) fn block_context(r: &Resolved) -> (f64, f64) {
    let halo = blocks::HALO_STEPS * r.step;
    (halo, halo + smoothing_reach(r).max(r.step))
}

/// Stage 4 for a block: polylines grown from the smoothed edge points of its core (`core`, in
/// order, see [`SmoothedEdges::sort`]) on through those of its halo (`halo`, in order), cut
/// to what the block owns (see [`blocks::cut`]; `b` is its number in `blocks`). Once `cancel`
/// is set, what comes back is partial.
pub(crate) fn grow_block(core: &[DVec3], halo: &[DVec3], blocks: &Blocks, b: u32, r: &Resolved, cancel: &crate::cancel::Cancel) -> Vec<Piece> {
    let points: Vec<DVec3> = core.iter().chain(halo).copied().collect();
    if points.is_empty() {
        return vec![];
    }
    let index = Index::new(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>());
    let grown = grow::grow(&points, core.len(), &index, &grow::GrowParams { step: r.step, max_turn_deg: r.max_turn_deg }, cancel);
    let (block, halo) = (&blocks.list[b as usize], blocks::HALO_STEPS * r.step);
    grown.iter().flat_map(|g| blocks::cut(&g.vertices, g.closed, block, |p| blocks.find(p, halo) == Some(b))).collect()
}

/// Completion's parameters (stage 5) for the resolved parameters `r`.
pub(crate) fn complete_params(r: &Resolved) -> complete::CompleteParams {
    complete::CompleteParams {
        step: r.step,
        reach: r.reach_steps,
        aperture_deg: r.aperture_deg,
        min_steps: 3.0,
        smooth_passes: 2,
        corner_zone: r.corner_radius,
    }
}

/// The smoothed edge points near a curve, indexed: what a curve's vertex normals and evidence
/// are taken from, a region at a time.
pub(crate) struct NearEdges<'a> {
    index: Index,
    normals: &'a [[glam::Vec3; 2]],
    step: f64,
}

impl<'a> NearEdges<'a> {
    /// Indexes `points` (in order, see [`SmoothedEdges::sort`]) with their `normals`. Queries
    /// look half a step around them.
    pub(crate) fn new(points: &[DVec3], normals: &'a [[glam::Vec3; 2]], step: f64) -> NearEdges<'a> {
        NearEdges { index: Index::new(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>()), normals, step }
    }

    /// The normal pairs of the edge points within half a step of `p`, the first point's first,
    /// each ordered and signed to agree with the first's.
    fn pairs_at(&self, p: DVec3, nn: &mut Vec<(u32, f32)>) -> Vec<[DVec3; 2]> {
        let own = self.own_pairs_at(p, nn);
        own.first().map_or(vec![], |&f| own.iter().map(|&n| align(n, f)).collect())
    }

    /// The mean normal pair of the edge points within half a step of `p`, if any, oriented as
    /// most of those points orient theirs (see `Orientation`).
    pub(crate) fn normals_at(&self, p: DVec3) -> Option<[DVec3; 2]> {
        let own = self.own_pairs_at(p, &mut vec![]);
        let first = *own.first()?;
        let mut votes = Orientation::default();
        let sum = own.iter().fold([DVec3::ZERO; 2], |s, &n| {
            let (a, turned) = align_turned(n, first);
            votes.count(turned);
            [s[0] + a[0], s[1] + a[1]]
        });
        let mean = votes.apply([sum[0].normalize_or_zero(), sum[1].normalize_or_zero()]);
        (mean[0] != DVec3::ZERO).then_some(mean)
    }

    /// The normal pairs of the edge points within half a step of `p`, as their points have them,
    /// in point order.
    fn own_pairs_at(&self, p: DVec3, nn: &mut Vec<(u32, f32)>) -> Vec<[DVec3; 2]> {
        nn.clear();
        if !self.index.is_empty() {
            self.index.within(&p.as_vec3().to_array(), (0.5 * self.step) as f32, nn);
        }
        nn.sort_unstable_by_key(|a| a.0);
        nn.iter().map(|&(j, _)| self.normals[j as usize].map(|v| v.as_dvec3())).collect()
    }

    /// How well the normal pairs of the edge points within half a step of `p` agree with their
    /// mean (see [`Evidence::agreement`]), if there are any.
    pub(crate) fn agreement_at(&self, p: DVec3) -> Option<f64> {
        let pairs = self.pairs_at(p, &mut vec![]);
        if pairs.is_empty() {
            return None;
        }
        let sum = pairs.iter().fold([DVec3::ZERO; 2], |s, a| [s[0] + a[0], s[1] + a[1]]);
        let mean = [sum[0].normalize_or_zero(), sum[1].normalize_or_zero()];
        Some(pairs.iter().map(|&a| align(a, mean)).map(|a| a[0].dot(mean[0]).min(a[1].dot(mean[1])).max(0.0)).sum::<f64>() / pairs.len() as f64)
    }
}

/// The places, every half step along the curve through `v` (closed if `closed`), at which its
/// evidence is looked at.
pub(crate) fn places(v: &[DVec3], closed: bool, step: f64) -> Vec<DVec3> {
    let mut places = vec![];
    let n = v.len();
    let segments = if closed && n > 2 { n } else { n.saturating_sub(1) };
    for k in 0..segments {
        let (a, b) = (v[k], v[(k + 1) % n]);
        let parts = ((b - a).length() / (0.5 * step)).ceil().max(1.0) as usize;
        places.extend((0..parts).map(|i| a.lerp(b, i as f64 / parts as f64)));
    }
    if !closed || n <= 2 {
        places.extend(v.last());
    }
    places
}

/// What the smoothed edge points say along a curve, gathered region by region: the mean normal
/// pair near each vertex (zero where none is known), and over the [`places`] along it, how many
/// have edge points near and how well those agree (summed).
#[derive(Clone, Debug, Default)]
pub(crate) struct Gathered {
    /// Per vertex, the mean normal pair of the edge points within half a step.
    pub normals: Vec<[glam::Vec3; 2]>,
    /// Places with edge points near.
    pub covered: u32,
    /// Their agreement, summed.
    pub agreement: f64,
}

impl Gathered {
    /// Nothing gathered yet, for a curve of `n` vertices.
    pub(crate) fn new(n: usize) -> Gathered {
        Gathered { normals: vec![[glam::Vec3::ZERO; 2]; n], covered: 0, agreement: 0.0 }
    }
}

/// The curve `c` with what was gathered along it, made into the output polyline `id` (world
/// coordinates, from positions relative to `origin`): the normals take the orientation most
/// of its vertices have (see `Orientation`), vertices without normals take their
/// neighbours', and the evidence gives the confidence.
pub(crate) fn finish(id: u32, c: complete::Curve, g: Gathered, origin: DVec3, step: f64) -> Polyline {
    // Each normal is aligned with the one before it along the curve, so that it turns smoothly
    // round bends; the orientation is then the one most vertices have.
    let mut prev: Option<[DVec3; 2]> = None;
    let mut n: Vec<[DVec3; 2]> = vec![[DVec3::ZERO; 2]; c.v.len()];
    let mut votes = Orientation::default();
    for (i, m) in g.normals.iter().enumerate() {
        if m[0] != glam::Vec3::ZERO && !c.corner[i] {
            let m = m.map(|x| x.as_dvec3());
            let (m, turned) = prev.map_or((m, [false; 2]), |p| align_turned(m, p));
            votes.count(turned);
            n[i] = m;
            prev = Some(m);
        }
    }
    n.iter_mut().for_each(|m| *m = votes.apply(*m));
    fill_from_neighbours(&mut n);
    let length = c.v.windows(2).map(|w| w[0].distance(w[1])).sum::<f64>() + if c.closed && c.v.len() > 2 { c.v[0].distance(c.v[c.v.len() - 1]) } else { 0.0 };
    let evidence = Evidence {
        length_steps: length / step,
        coverage: g.covered as f64 / places(&c.v, c.closed, step).len().max(1) as f64,
        agreement: g.agreement / g.covered.max(1) as f64,
    };
    let vertices = c.v.iter().zip(&n).zip(&c.corner).map(|((&p, n), &corner)| Vertex { p: p + origin, n: [n[0].as_vec3(), n[1].as_vec3()], corner }).collect();
    Polyline { id, closed: c.closed, vertices, confidence: evidence.confidence() as f32, shape: crate::curves::Shape::Unknown }
}

/// Gives each vertex without normals (corners, and vertices with no edge point near) those of
/// the nearest vertex along the curve that has them, the one before it on a tie. A curve with
/// none keeps zeros.
fn fill_from_neighbours(normals: &mut [[DVec3; 2]]) {
    let known = |n: &[DVec3; 2]| n[0] != DVec3::ZERO;
    let n = normals.len();
    let (mut before, mut after) = (vec![None; n], vec![None; n]);
    for i in 0..n {
        before[i] = if known(&normals[i]) { Some(i) } else { i.checked_sub(1).and_then(|j| before[j]) };
    }
    for i in (0..n).rev() {
        after[i] = if known(&normals[i]) { Some(i) } else { after.get(i + 1).copied().flatten() };
    }
    for i in 0..n {
        let from = match (before[i], after[i]) {
            (Some(b), Some(a)) => Some(if i - b <= a - i { b } else { a }),
            (b, a) => b.or(a),
        };
        if let Some(j) = from {
            normals[i] = normals[j];
        }
    }
}

/// The length, in polyline steps, over which a curve's length term of confidence rises to 1 -
/// 1/e (see [`Evidence::confidence`]): a curve of one step has 0.39 of it, of six steps 0.95.
pub(crate) const CONFIDENT_STEPS: f64 = 2.0;
/// Agreement of the edge points' normals (mean cosine to their mean) at which confidence is
/// zero. On the noisy quality clouds, curves on the truth agree at 0.96-0.99 (quartiles), and
/// the 5 % least agreeing at 0.90; on the real aerial scan autzen, half the curves fall below
/// 0.93.
pub(crate) const AGREEMENT_FLOOR: f64 = 0.7;
/// Curves below this confidence are left out of the outputs by default (`--min-confidence`).
/// Over 90 noisy extractions of the quality clouds (nine shapes, five noise levels), 0.2 left
/// out 0.15 % of the length of curves on the truth and 1.1 % of the length of the others;
/// confidence separates curves that follow no edge from those that do, not curves placed
/// off an edge (most false length there), which it cannot see.
pub const DEFAULT_MIN_CONFIDENCE: f64 = 0.2;

/// What speaks for a curve being a feature of the surface: the edge points along it, looked
/// at every half step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Evidence {
    /// Length, in polyline steps.
    pub length_steps: f64,
    /// Share of the places looked at that have an edge point within half a step (the rest is
    /// gaps that completion bridged).
    pub coverage: f64,
    /// How well the two normals of the edge points at a place agree with their mean, on
    /// average (1: all the same; two surfaces fitted at random agree little).
    pub agreement: f64,
}

impl Evidence {
    /// The curve's confidence, 0 to 1: the product of its coverage, a length term that
    /// saturates over a few steps (1 - exp(-length / [`CONFIDENT_STEPS`])), and its agreement
    /// above [`AGREEMENT_FLOOR`], rescaled to 0-1.
    pub(crate) fn confidence(&self) -> f64 {
        let length = 1.0 - (-self.length_steps / CONFIDENT_STEPS).exp();
        let agreement = ((self.agreement - AGREEMENT_FLOOR) / (1.0 - AGREEMENT_FLOOR)).clamp(0.0, 1.0);
        self.coverage * length * agreement
    }
}

/// Orders the normal pair `n` to match `reference` (which surface is first).
fn order(n: [DVec3; 2], reference: [DVec3; 2]) -> [DVec3; 2] {
    let straight = n[0].dot(reference[0]).abs() + n[1].dot(reference[1]).abs();
    let crossed = n[1].dot(reference[0]).abs() + n[0].dot(reference[1]).abs();
    if crossed > straight {
        [n[1], n[0]]
    } else {
        n
    }
}

/// Orders and signs the normal pair `n` to agree with `reference`, each normal on its own (for
/// comparing pairs).
fn align(n: [DVec3; 2], reference: [DVec3; 2]) -> [DVec3; 2] {
    align_turned(n, reference).0
}

/// As [`align`], and which of the two normals were turned round.
fn align_turned(n: [DVec3; 2], reference: [DVec3; 2]) -> ([DVec3; 2], [bool; 2]) {
    let [a, b] = order(n, reference);
    let turned = [a.dot(reference[0]) < 0.0, b.dot(reference[1]) < 0.0];
    ([if turned[0] { -a } else { a }, if turned[1] { -b } else { b }], turned)
}

/// The orientation of a run of normal pairs, by vote. Each pair, as its edge point or vertex
/// has it, has both normals pointing away from the other's half-surface (see stage 3). Aligned
/// normal by normal to a reference, the pairs then differ from their own orientation by one of
/// four turns: none or both (pairs oriented as the reference, or the other way round), or one
/// normal alone (a pair whose orientation noise got wrong, or a wrong reference). The turn
/// most pairs agree on, within the pattern (none or both, or one alone) most pairs share,
/// restores their orientation; a pair that noise got wrong, or a wrong reference, is outvoted.
#[derive(Clone, Copy, Debug, Default)]
struct Orientation {
    /// Pairs turned: none, both, the first alone, the second alone.
    votes: [u32; 4],
}

impl Orientation {
    fn count(&mut self, turned: [bool; 2]) {
        self.votes[match turned {
            [false, false] => 0,
            [true, true] => 1,
            [true, false] => 2,
            [false, true] => 3,
        }] += 1;
    }

    /// `n`, aligned as the pairs counted were, turned back to the orientation most had.
    fn apply(&self, n: [DVec3; 2]) -> [DVec3; 2] {
        let v = self.votes;
        let same = v[0] + v[1] >= v[2] + v[3];
        let turn = match (same, if same { v[1] > v[0] } else { v[3] > v[2] }) {
            (true, false) => [false, false],
            (true, true) => [true, true],
            (false, false) => [true, false],
            (false, true) => [false, true],
        };
        [if turn[0] { -n[0] } else { n[0] }, if turn[1] { -n[1] } else { n[1] }]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_grouped_a_part_at_a_time_are_those_grouped_at_once() {
        let r = super::super::Params::default().resolve(0.01, 0.0);
        let radius = r.corner_radius;
        let world = DVec3::new(5e5, 5.4e6, 100.0);
        let mut rng = crate::rng::Rng::new(7);
        let mut all = vec![];
        // Tight clusters, loose ones (two or three groups each), and chains a few parts long;
        // weights from a few values, so that ties are broken by position.
        for k in 0..400 {
            let c = world + DVec3::new(rng.range(0.0, 16.0), rng.range(0.0, 3.0), rng.range(0.0, 1.5));
            let (n, spread) = [(8, 0.3), (12, 1.5), (12, 0.0)][k % 3];
            let dir = DVec3::new(1.0, rng.range(-0.3, 0.3), 0.0).normalize();
            for i in 0..n {
                let along = if spread == 0.0 { dir * (i as f64 * 0.8 * radius) } else { DVec3::ZERO };
                let p = c + along + rng.in_ball(spread * radius);
                all.push(WorldCorner { p, w: 1.0 + (rng.f64() * 4.0).floor() });
            }
        }
        // Parts are slabs along x whose corner points stray a little past their borders.
        let part_of = |c: &WorldCorner, jitter: f64| (((c.p.x - world.x + jitter) / 2.0).floor().clamp(0.0, 7.0)) as usize;
        let mut parts: Vec<Vec<WorldCorner>> = vec![vec![]; 8];
        for c in &all {
            parts[part_of(c, rng.range(-0.05, 0.05))].push(*c);
        }
        let origin = world + DVec3::new(1.0, 0.5, 0.25);
        let bounds: Vec<_> = parts.iter().map(|p| CornerGrouping::bounds(p, &r)).collect();
        let grouping = CornerGrouping::new(&bounds, origin, &r);
        let done: Vec<PartCorners> = parts.into_iter().enumerate().rev().map(|(k, p)| grouping.part(k, p)).collect();
        let (alone, shared) = (done.iter().map(|p| p.groups.len()).sum::<usize>(), done.iter().map(|p| p.shared.len()).sum::<usize>());
        let by_parts = grouping.finish(done);
        let (_, points) = grouping.prepare(all.clone());
        let at_once = project::group_corners(&points, radius, MIN_CORNER_SUPPORT);
        assert!(at_once.len() > 300, "{} groups", at_once.len());
        assert!(alone > 100 && shared > 100 && shared < all.len() / 2, "{alone} groups alone, {shared} corner points shared");
        assert_eq!(by_parts, at_once);
    }

    #[test]
    fn vertices_without_normals_take_the_nearest_along_the_curve() {
        let (a, b) = ([DVec3::X, DVec3::Y], [DVec3::Y, DVec3::Z]);
        let z = [DVec3::ZERO; 2];
        // Two corners at the ends (a curve between two corners), a gap in the middle.
        let mut n = vec![z, a, z, z, z, b, z];
        fill_from_neighbours(&mut n);
        assert_eq!(n, vec![a, a, a, a, b, b, b]);
        let mut none = vec![z, z];
        fill_from_neighbours(&mut none);
        assert_eq!(none, vec![z, z]);
    }

    #[test]
    fn a_curve_takes_the_orientation_most_of_its_vertices_have() {
        // A crease along x between the faces of a 135 degree wedge: normals (0, 0, 1) and
        // (0, 0.71, 0.71) point away from each other's half-surface. Noise got the first vertex's
        // second normal wrong, and turned a later vertex's pair round whole; with the first
        // vertex as the reference, both stay so, and the first reads a 45 degree crease.
        let (a, b) = (glam::Vec3::Z, glam::Vec3::new(0.0, 1.0, 1.0).normalize());
        let mut own = vec![[a, b]; 6];
        own[0] = [a, -b];
        own[3] = [-a, -b];
        let c = complete::Curve::new((0..6).map(|i| DVec3::X * i as f64).collect(), false);
        let g = Gathered { normals: own, covered: 6, agreement: 6.0 };
        let line = finish(0, c, g, DVec3::ZERO, 1.0);
        for v in &line.vertices {
            assert!(v.n[0].abs_diff_eq(a, 1e-6) && v.n[1].abs_diff_eq(b, 1e-6), "{:?}", v.n);
        }
        assert!((line.mean_dihedral_angle().unwrap() - 135.0).abs() < 1e-3);
    }
}
