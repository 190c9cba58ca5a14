//! Stages 3 to 5 on edge clouds: corner grouping, smoothing (block by block, with the edge
//! points around a block as context), the consensus filter, polyline growing and completion,
//! and the normals each curve vertex carries.

use super::complete;
use super::consensus;
use super::grow;
use super::params::Resolved;
use super::project::{self, WorldCorner, WorldEdge};
use super::smooth;
use crate::curves::{Polyline, Vertex};
use crate::debug::DebugDump;
use crate::keys::{bits_key, snap, snap_quantum};
use crate::spatial::Index;
use glam::DVec3;
use std::time::Instant;

/// Snaps an edge point's position to quantum `q` and its normals to a millionth.
pub fn snap_edge(e: &mut WorldEdge, q: f64) {
    e.p = snap(e.p, q);
    e.n = e.n.map(|n| (n * 1e6).round() / 1e6 + glam::Vec3::ZERO);
}

fn normal_key(n: &[glam::Vec3; 2]) -> [[u32; 3]; 2] {
    [n[0].to_array(), n[1].to_array()].map(|v| v.map(f32::to_bits))
}

/// Corner grouping over all corner points of the cloud, in any order; the grouped corners are
/// returned relative to `origin`.
pub fn group_corners(mut corners: Vec<WorldCorner>, origin: DVec3, r: &Resolved) -> Vec<DVec3> {
    let q = snap_quantum(r.kappa);
    for c in corners.iter_mut() {
        c.p = snap(c.p, q);
        c.w = (c.w * q).round() / q;
    }
    corners.sort_unstable_by(|a, b| bits_key(a.p).cmp(&bits_key(b.p)).then(a.w.total_cmp(&b.w)));
    let local: Vec<project::CornerPoint> = corners.iter().map(|c| project::CornerPoint { p: c.p - origin, w: c.w }).collect();
    project::group_corners(&local, r.corner_radius, 3)
}

/// Largest distance from an edge point to the edge points that move it in stage 3: a block
/// of the edge cloud is smoothed exactly as in the whole cloud if every edge point this close
/// to the block is given as context.
pub fn smoothing_reach(r: &Resolved) -> f64 {
    2.0 * r.rmls_radius
}

/// Stage 3 for a block of the (snapped) edge cloud, positions relative to `origin`: the first
/// `own` points are smoothed, the rest are the context within [`smoothing_reach`] of them.
/// The smoothed positions are snapped as the input is.
pub fn smooth_block(points: &[DVec3], own: usize, grouped: &[DVec3], r: &Resolved) -> Vec<DVec3> {
    let sp = smooth::SmoothParams { linearity: r.linearity, max_radius: smoothing_reach(r) };
    let q = snap_quantum(r.kappa);
    let mut out = smooth::smooth(points, own, grouped, &sp);
    for p in out.iter_mut() {
        *p = snap(*p, q);
    }
    out
}

/// The smoothed edge cloud (positions relative to an origin, and the normals of each point's
/// two surfaces), as stages 4 and 5 take it.
#[derive(Clone, Debug, Default)]
pub struct SmoothedEdges {
    /// Smoothed positions.
    pub points: Vec<DVec3>,
    /// The two surface normals of each.
    pub normals: Vec<[glam::Vec3; 2]>,
    /// Edge points dropped by the consensus filter.
    pub unconfirmed: u64,
}

/// Stage 3 and, on noise-limited clouds (see [`Resolved::noise_limited`]), the consensus filter
/// for a block of the edge cloud (see [`smooth_block`]; the normals are those of `points`,
/// context included): appends the smoothed positions of the first `own` points that their
/// neighbours confirm (see [`consensus`]), with their normals, to `out`, and counts those
/// dropped. (The smoothing takes every edge point as context, confirmed or not, so that the
/// block's context need reach no further.)
pub fn smooth_and_confirm(points: &[DVec3], normals: &[[glam::Vec3; 2]], own: usize, grouped: &[DVec3], r: &Resolved, out: &mut SmoothedEdges) {
    let smoothed = smooth_block(points, own, grouped, r);
    // (Without noise, edge points off a crease are rare and the filter mostly cut sparse
    // stretches into more pieces: nonuniformly sampled fandisk 34 -> 45 curves, the 5 M scene
    // 366 -> 376; so it runs where the neighbourhoods are sized by the noise.)
    let keep = if r.noise_limited() { consensus::confirmed(points, normals, own, r.step) } else { vec![true; own] };
    let before = out.points.len();
    for ((p, n), k) in smoothed.into_iter().zip(&normals[..own]).zip(keep) {
        if k {
            out.points.push(p);
            out.normals.push(*n);
        }
    }
    out.unconfirmed += (own - (out.points.len() - before)) as u64;
}

/// Curves, with what stages 4 and 5 counted and how long they took.
#[derive(Clone, Debug, Default)]
pub struct Traced {
    /// Feature curves in world coordinates.
    pub curves: Vec<Polyline>,
    /// Polylines grown (before completion).
    pub grown: u64,
    /// Seconds of stage 4.
    pub growing_seconds: f64,
    /// Seconds of stage 5.
    pub completion_seconds: f64,
}

/// Stages 4 and 5 on the whole smoothed edge cloud (positions relative to `origin`), in any
/// order: polyline growing and completion. Once `cancel` is set, what comes back is partial.
pub fn grow_and_complete(edges: SmoothedEdges, grouped: &[DVec3], origin: DVec3, r: &Resolved, debug: &DebugDump, cancel: &crate::cancel::Cancel) -> Traced {
    // Sorted first, so the result does not depend on the order the points arrive in. (The
    // edge cloud is the one part of a run that grows with the whole input, not with a tile:
    // it is reordered through a permutation rather than as records, so that at most one
    // extra copy of one of its columns exists at a time.)
    use rayon::prelude::*;
    let SmoothedEdges { points, normals, .. } = edges;
    let mut perm: Vec<u32> = (0..points.len() as u32).collect();
    // (Points equal in position and normals are interchangeable: the unstable order of
    // such ties changes nothing.)
    perm.par_sort_unstable_by(|&a, &b| {
        let (a, b) = (a as usize, b as usize);
        bits_key(points[a]).cmp(&bits_key(points[b])).then(normal_key(&normals[a]).cmp(&normal_key(&normals[b])))
    });
    let points = permute(points, &perm);
    let normals = permute(normals, &perm);
    drop(perm);
    debug.points("smoothed.obj", &points, origin);
    debug.points("corners.obj", grouped, origin);
    let t = Instant::now();
    let index = (!points.is_empty()).then(|| Index::new_parallel(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>()));
    let grown = index.as_ref().map_or(vec![], |ix| grow::grow(&points, ix, &grow::GrowParams { step: r.step, max_turn_deg: r.max_turn_deg }, cancel));
    if debug.on() {
        let pl: Vec<Polyline> = grown.iter().enumerate().map(|(i, g)| Polyline::from_points(i as u32, g.vertices.iter().map(|p| *p + origin))).collect();
        debug.polylines("grown.obj", &pl);
    }
    let mut traced = Traced { grown: grown.len() as u64, growing_seconds: t.elapsed().as_secs_f64(), ..Default::default() };
    if cancel.is_set() {
        return traced;
    }
    let t = Instant::now();
    let cp = complete::CompleteParams {
        step: r.step,
        reach: r.reach_steps,
        aperture_deg: r.aperture_deg,
        min_steps: 3.0,
        smooth_passes: 2,
        corner_zone: r.corner_radius,
    };
    let curves = complete::complete(grown.into_iter().map(|g| complete::Curve::new(g.vertices, g.closed)).collect(), grouped, &cp, cancel);
    if cancel.is_set() {
        return traced;
    }
    traced.curves = to_polylines(&curves, index.as_ref(), &normals, origin, r.step);
    traced.completion_seconds = t.elapsed().as_secs_f64();
    traced
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

/// `v` reordered by `perm` (consumed, so that the unordered copy is freed at once).
fn permute<T: Copy>(v: Vec<T>, perm: &[u32]) -> Vec<T> {
    perm.iter().map(|&i| v[i as usize]).collect()
}

/// Attaches normals (from the nearest edge points, orientation carried along each curve) and
/// the evidence for each curve (see [`Evidence`]), and converts to world coordinates.
fn to_polylines(curves: &[complete::Curve], index: Option<&Index>, edge_normals: &[[glam::Vec3; 2]], origin: DVec3, step: f64) -> Vec<Polyline> {
    let mut nn = Vec::new();
    curves
        .iter()
        .enumerate()
        .map(|(id, c)| {
            let mut prev: Option<[DVec3; 2]> = None;
            let mut normals = vec![[DVec3::ZERO; 2]; c.v.len()];
            for (i, &p) in c.v.iter().enumerate() {
                if c.corner[i] {
                    continue;
                }
                nn.clear();
                if let Some(ix) = index {
                    ix.within(&p.as_vec3().to_array(), (0.5 * step) as f32, &mut nn);
                    if nn.is_empty() {
                        ix.nearest_n(&p.as_vec3().to_array(), 1, &mut nn);
                    }
                }
                if nn.is_empty() {
                    continue;
                }
                nn.sort_unstable_by_key(|a| a.0);
                let mut acc = [DVec3::ZERO; 2];
                let pair = |j: u32| edge_normals[j as usize].map(|v| v.as_dvec3());
                let reference = prev.unwrap_or(pair(nn[0].0));
                for &(j, _) in &nn {
                    let n = align(pair(j), reference);
                    acc[0] += n[0];
                    acc[1] += n[1];
                }
                let mean = [acc[0].normalize_or_zero(), acc[1].normalize_or_zero()];
                if mean[0] != DVec3::ZERO {
                    normals[i] = mean;
                    prev = Some(mean);
                }
            }
            fill_from_neighbours(&mut normals);
            let vertices: Vec<Vertex> =
                c.v.iter()
                    .zip(&normals)
                    .zip(&c.corner)
                    .map(|((&p, n), &corner)| Vertex { p: p + origin, n: [n[0].as_vec3(), n[1].as_vec3()], corner })
                    .collect();
            let mut line = Polyline { id: id as u32, closed: c.closed, vertices, confidence: 0.0 };
            line.confidence = index.map_or(0.0, |ix| Evidence::along(&c.v, c.closed, ix, edge_normals, step).confidence() as f32);
            line
        })
        .collect()
}

/// The length, in polyline steps, over which a curve's length term of confidence rises to 1 -
/// 1/e (see [`Evidence::confidence`]): a curve of one step has 0.39 of it, of six steps 0.95.
pub const CONFIDENT_STEPS: f64 = 2.0;
/// Agreement of the edge points' normals (mean cosine to their mean) at which confidence is
/// zero. On the noisy quality clouds, curves on the truth agree at 0.96-0.99 (quartiles), and
/// the 5 % least agreeing at 0.90; on the real aerial scan autzen, half the curves fall below
/// 0.93.
pub const AGREEMENT_FLOOR: f64 = 0.7;
/// Curves below this confidence are left out of the outputs by default (`--min-confidence`).
/// Over 90 noisy extractions of the quality clouds (nine shapes, five noise levels), 0.2 left
/// out 0.15 % of the length of curves on the truth and 1.1 % of the length of the others;
/// confidence separates curves that follow no edge from those that do, not curves placed
/// off an edge (most false length there), which it cannot see.
pub const DEFAULT_MIN_CONFIDENCE: f64 = 0.2;

/// What speaks for a curve being a feature of the surface: the edge points along it, looked
/// at every half step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Evidence {
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
    /// The evidence along the curve through `v` (closed if `closed`), from the edge cloud
    /// indexed by `index` with the normals `normals`, for polyline step `step`.
    fn along(v: &[DVec3], closed: bool, index: &Index, normals: &[[glam::Vec3; 2]], step: f64) -> Evidence {
        let mut places = vec![];
        let n = v.len();
        let segments = if closed && n > 2 { n } else { n.saturating_sub(1) };
        let mut length = 0.0;
        for k in 0..segments {
            let (a, b) = (v[k], v[(k + 1) % n]);
            let parts = ((b - a).length() / (0.5 * step)).ceil().max(1.0) as usize;
            places.extend((0..parts).map(|i| a.lerp(b, i as f64 / parts as f64)));
            length += (b - a).length();
        }
        if !closed || n <= 2 {
            places.extend(v.last());
        }
        let (mut covered, mut agreement) = (0usize, 0.0);
        let mut near = vec![];
        for p in &places {
            near.clear();
            index.within(&p.as_vec3().to_array(), (0.5 * step) as f32, &mut near);
            if near.is_empty() {
                continue;
            }
            near.sort_unstable_by_key(|a| a.0);
            let pair = |j: u32| normals[j as usize].map(|x| x.as_dvec3());
            let reference = pair(near[0].0);
            let sum = near.iter().fold([DVec3::ZERO; 2], |s, &(j, _)| {
                let a = align(pair(j), reference);
                [s[0] + a[0], s[1] + a[1]]
            });
            let mean = [sum[0].normalize_or_zero(), sum[1].normalize_or_zero()];
            covered += 1;
            agreement +=
                near.iter().map(|&(j, _)| align(pair(j), mean)).map(|a| a[0].dot(mean[0]).min(a[1].dot(mean[1])).max(0.0)).sum::<f64>() / near.len() as f64;
        }
        let seen = covered.max(1) as f64;
        Evidence { length_steps: length / step, coverage: covered as f64 / places.len().max(1) as f64, agreement: agreement / seen }
    }

    /// The curve's confidence, 0 to 1: the product of its coverage, a length term that
    /// saturates over a few steps (1 - exp(-length / [`CONFIDENT_STEPS`])), and its agreement
    /// above [`AGREEMENT_FLOOR`], rescaled to 0-1.
    pub fn confidence(&self) -> f64 {
        let length = 1.0 - (-self.length_steps / CONFIDENT_STEPS).exp();
        let agreement = ((self.agreement - AGREEMENT_FLOOR) / (1.0 - AGREEMENT_FLOOR)).clamp(0.0, 1.0);
        self.coverage * length * agreement
    }
}

/// Orders and signs the normal pair `n` to agree with `reference`.
fn align(n: [DVec3; 2], reference: [DVec3; 2]) -> [DVec3; 2] {
    let straight = n[0].dot(reference[0]).abs() + n[1].dot(reference[1]).abs();
    let crossed = n[1].dot(reference[0]).abs() + n[0].dot(reference[1]).abs();
    let [a, b] = if crossed > straight { [n[1], n[0]] } else { n };
    let a = if a.dot(reference[0]) < 0.0 { -a } else { a };
    let b = if b.dot(reference[1]) < 0.0 { -b } else { b };
    [a, b]
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
