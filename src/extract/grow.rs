//! Stage 4: polyline growing through the smoothed feature points (Daniels 2008, section 3.4,
//! after Lee 2000).
//!
//! Seeds are taken in order of neighbourhood linearity l0 / (l0 + l1 + l2), most linear first,
//! so curves start far from corners. From a vertex, the step direction is the weighted mean
//! direction to the unconsumed points ahead; the next vertex lies one step along it and is
//! re-centred onto the local principal axis. Growth stops when nothing lies ahead or when the
//! step turns by more than the angle limit from the running growth direction. Points near each
//! vertex are consumed so that no feature is traced twice.

use super::fit::Pca;
use crate::spatial::Index;
use glam::DVec3;
use rayon::prelude::*;

/// Growing parameters.
#[derive(Clone, Copy, Debug)]
pub struct GrowParams {
    /// Step length s_max.
    pub step: f64,
    /// Largest turn between the step and the growth direction, in degrees.
    pub max_turn_deg: f64,
}

/// A grown polyline.
#[derive(Clone, Debug, PartialEq)]
pub struct Grown {
    /// Vertices in order.
    pub vertices: Vec<DVec3>,
    /// True if growth came back round to its start.
    pub closed: bool,
}

/// Grows polylines through `points`, whose k-d tree is `index`, seeded from the first `seeds`
/// of them (a block's core; the rest is its halo, which polylines grow on through). Stops
/// early, with the polylines grown so far, once `cancel` is set (the caller sees the flag and
/// discards them).
pub fn grow(points: &[DVec3], seeds: usize, index: &Index, p: &GrowParams, cancel: &crate::cancel::Cancel) -> Vec<Grown> {
    let n = points.len();
    if n < 2 {
        return vec![];
    }
    // Seed order by linearity of the step-radius neighbourhood.
    let lin: Vec<f64> = (0..seeds.min(n))
        .into_par_iter()
        .map_init(Vec::new, |nn, i| {
            nn.clear();
            index.within(&points[i].as_vec3().to_array(), p.step as f32, nn);
            if nn.len() < 3 {
                return 0.0;
            }
            Pca::of(nn.iter().map(|&(j, _)| (points[j as usize], 1.0))).map_or(0.0, |c| c.linearity())
        })
        .collect();
    let mut order: Vec<u32> = (0..lin.len() as u32).filter(|&i| lin[i as usize] > 0.0).collect();
    order.sort_unstable_by(|&a, &b| lin[b as usize].total_cmp(&lin[a as usize]).then(a.cmp(&b)));
    drop(lin);
    let mut consumed = vec![false; n];
    let mut nn = Vec::new();
    let mut out = vec![];
    for (k, &s) in order.iter().enumerate() {
        if k % 4096 == 0 && cancel.is_set() {
            break;
        }
        let s = s as usize;
        if consumed[s] {
            continue;
        }
        let x = points[s];
        nn.clear();
        index.within(&points[s].as_vec3().to_array(), p.step as f32, &mut nn);
        let Some(pca) = Pca::of(nn.iter().map(|&(j, _)| (points[j as usize], 1.0))) else { continue };
        let start = pca.mean + pca.axis() * (x - pca.mean).dot(pca.axis());
        let (fwd, closed) = trace(points, index, &mut consumed, start, pca.axis(), p);
        let bwd = if closed { vec![] } else { trace(points, index, &mut consumed, start, -pca.axis(), p).0 };
        consume(index, &mut consumed, start, p.step);
        let mut line: Vec<DVec3> = bwd.into_iter().rev().collect();
        line.push(start);
        line.extend(fwd);
        if line.len() >= 2 {
            out.push(Grown { vertices: line, closed });
        }
    }
    out
}

fn consume(index: &Index, consumed: &mut [bool], x: DVec3, r: f64) {
    let mut nn = Vec::new();
    index.within(&x.as_vec3().to_array(), r as f32, &mut nn);
    for (j, _) in nn {
        consumed[j as usize] = true;
    }
}

/// Vertices grown from `x` in direction `dir` (not including `x`), and whether growth came
/// back round to `x`.
fn trace(points: &[DVec3], index: &Index, consumed: &mut [bool], mut x: DVec3, dir: DVec3, p: &GrowParams) -> (Vec<DVec3>, bool) {
    let start = x;
    let cos_max = p.max_turn_deg.to_radians().cos();
    let mut vg = dir;
    let mut out = vec![];
    let mut nn = Vec::new();
    let s2 = p.step * p.step;
    for _ in 0..1_000_000 {
        nn.clear();
        index.within(&x.as_vec3().to_array(), p.step as f32, &mut nn);
        let mut vc = DVec3::ZERO;
        let mut far: Option<f64> = None;
        for &(j, _) in &nn {
            let j = j as usize;
            if consumed[j] {
                continue;
            }
            let d = points[j] - x;
            let along = d.dot(vg);
            if along <= 0.0 {
                continue;
            }
            let len = d.length();
            vc += d / len * (-(along * along) / s2).exp();
            far = Some(far.map_or(along, |f: f64| f.max(along)));
        }
        // Consume around this vertex before stepping on (not at the start, which the growth
        // in the other direction still needs).
        if !out.is_empty() {
            consume(index, consumed, x, p.step * 0.999);
        }
        let Some(far_along) = far else { break };
        let vc = vc.normalize_or_zero();
        if vc == DVec3::ZERO || vc.dot(vg) < cos_max {
            break;
        }
        let mut next = x + vc * p.step;
        // Re-centre on the local axis; at the end of the data, stop at the last point instead.
        nn.clear();
        index.within(&next.as_vec3().to_array(), (p.step * 0.5) as f32, &mut nn);
        if nn.len() >= 2 {
            if let Some(c) = Pca::of(nn.iter().map(|&(j, _)| (points[j as usize], 1.0))) {
                let a = if c.axis().dot(vc) < 0.0 { -c.axis() } else { c.axis() };
                next = c.mean + a * (next - c.mean).dot(a);
            }
        } else {
            if far_along > p.step * 0.25 {
                out.push(x + vc * far_along.min(p.step));
            }
            break;
        }
        vg = (vg + vc).normalize_or_zero();
        if vg == DVec3::ZERO {
            break;
        }
        if out.len() >= 3 && next.distance(start) < p.step * 0.75 {
            return (out, true);
        }
        out.push(next);
        x = next;
    }
    (out, false)
}
