//! Stage 4: polyline growing through the smoothed feature points (Daniels 2008, section 3.4,
//! after Lee 2000).
//!
//! Seeds are taken in order of neighbourhood linearity l0 / (l0 + l1 + l2), most linear first,
//! so curves start far from corners. From a vertex, the step direction is the weighted mean
//! direction to the unconsumed points ahead; the next vertex lies one step along it and is
//! re-centred onto the local principal axis. Where the step turns by more than the angle limit
//! from the running growth direction, shorter steps are tried (a bend, whose turn shrinks with
//! the step); growth stops when nothing lies ahead or when even the shortest step turns too far
//! (a corner). Points near each vertex are consumed so that no feature is traced twice.

use super::fit::Pca;
use crate::spatial::Index;
use glam::DVec3;
use rayon::prelude::*;

/// Growing parameters.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GrowParams {
    /// Step length s_max.
    pub step: f64,
    /// Largest turn between the step and the growth direction, in degrees.
    pub max_turn_deg: f64,
}

/// A grown polyline.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Grown {
    /// Vertices in order.
    pub vertices: Vec<DVec3>,
    /// True if growth came back round to its start.
    pub closed: bool,
}

/// Grows polylines through `points`, whose k-d tree is `index`, seeded from the first `seeds`
/// of them (a block's core; the rest is its halo, which polylines grow on through). Stops
/// early, with the polylines grown so far, once `cancel` is set (the caller sees the flag and
/// discards them).
pub(crate) fn grow(points: &[DVec3], seeds: usize, index: &Index, p: &GrowParams, cancel: &crate::cancel::Cancel) -> Vec<Grown> {
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
///
/// s_max is the longest step (Daniels 2008: "the maximum allowable segment length"). Where the
/// step at s_max turns too far from the growth direction, a shorter one is tried, down to
/// [`MIN_STEP_SHARE`] of it: on a bend the turn shrinks with the step, at a corner it does not.
/// (With only s_max, the running direction lags a bend of radius R by about 2 s_max / R, so any
/// rim narrower than about 4 steps broke apart; the bolt holes of a part are often 1-2 steps
/// wide.)
fn trace(points: &[DVec3], index: &Index, consumed: &mut [bool], mut x: DVec3, dir: DVec3, p: &GrowParams) -> (Vec<DVec3>, bool) {
    let start = x;
    let cos_max = p.max_turn_deg.to_radians().cos();
    let mut vg = dir;
    let mut out = vec![];
    let mut travelled = 0.0;
    let mut last: Option<DVec3> = None;
    let mut nn = Vec::new();
    for _ in 0..1_000_000 {
        nn.clear();
        index.within(&x.as_vec3().to_array(), p.step as f32, &mut nn);
        let mut h = p.step;
        let mut taken = None;
        while h >= p.step * MIN_STEP_SHARE * 0.999 {
            let Some((vc, far)) = ahead(&Around { points, consumed, nn: &nn }, x, vg, h, h < p.step) else { break };
            // (A shorter step may instead follow the last step's direction, if it turns on
            // the way the curve has been turning: a bend whose running direction lags.)
            let bend = |d: DVec3| vc.dot(d) >= cos_max && vg.cross(d).dot(d.cross(vc)) > 0.0;
            if vc.dot(vg) >= cos_max || (h < p.step && last.is_some_and(bend)) {
                taken = Some((vc, far, h));
                break;
            }
            h *= 0.5;
        }
        // Consume around this vertex before stepping on (not at the start, which the growth
        // in the other direction still needs); ahead, only as far as the step goes.
        match taken {
            _ if out.is_empty() => {}
            Some((vc, _, h)) if h < p.step => {
                for &(j, _) in &nn {
                    let d = points[j as usize] - x;
                    if d.length_squared() < (p.step * 0.999).powi(2) && d.dot(vc) <= h {
                        consumed[j as usize] = true;
                    }
                }
            }
            _ => consume(index, consumed, x, p.step * 0.999),
        }
        let Some((vc, far_along, h)) = taken else { break };
        let mut next = x + vc * h;
        // Re-centre on the local axis; at the end of the data, stop at the last point instead.
        nn.clear();
        index.within(&next.as_vec3().to_array(), (h * 0.5) as f32, &mut nn);
        if nn.len() >= 2 {
            if let Some(c) = Pca::of(nn.iter().map(|&(j, _)| (points[j as usize], 1.0))) {
                let a = if c.axis().dot(vc) < 0.0 { -c.axis() } else { c.axis() };
                next = c.mean + a * (next - c.mean).dot(a);
            }
        } else {
            if far_along > h * 0.25 {
                out.push(x + vc * far_along.min(h));
            }
            break;
        }
        vg = (vg + vc).normalize_or_zero();
        if vg == DVec3::ZERO {
            break;
        }
        if out.len() >= 3 && travelled >= 1.5 * p.step && next.distance(start) < p.step * 0.75 {
            return (out, true);
        }
        travelled += next.distance(x);
        last = Some((next - x).normalize_or_zero());
        out.push(next);
        x = next;
    }
    (out, false)
}

/// The shortest step [`trace`] tries, as a share of s_max.
const MIN_STEP_SHARE: f64 = 0.25;

/// The points around a vertex as a step from it sees them: all the points, which of them are
/// consumed, and the numbers of those within s_max of the vertex (`nn`).
struct Around<'a> {
    points: &'a [DVec3],
    consumed: &'a [bool],
    nn: &'a [(u32, f32)],
}

/// The step direction v_c from `x` towards the unconsumed points ahead (along `vg`) within `h`
/// of it (those `around` it within s_max; `cut` if h is shorter), each weighted by its
/// distance along, and the farthest of them along; `None` if none lies ahead.
fn ahead(around: &Around, x: DVec3, vg: DVec3, h: f64, cut: bool) -> Option<(DVec3, f64)> {
    let Around { points, consumed, nn } = *around;
    let h2 = h * h;
    let mut vc = DVec3::ZERO;
    let mut far: Option<f64> = None;
    for &(j, _) in nn {
        let j = j as usize;
        if consumed[j] {
            continue;
        }
        let d = points[j] - x;
        let along = d.dot(vg);
        let len2 = d.length_squared();
        if along <= 0.0 || (cut && len2 > h2) {
            continue;
        }
        vc += d / len2.sqrt() * (-(along * along) / h2).exp();
        far = Some(far.map_or(along, |f: f64| f.max(along)));
    }
    let vc = vc.normalize_or_zero();
    far.map(|f| (vc, f))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cancel::Cancel;

    const P: GrowParams = GrowParams { step: 1.0, max_turn_deg: 30.0 };

    /// Points every `gap` along `f` over [0, 1), pushed sideways by up to `jitter` (a fixed
    /// pattern, so the test is the same every run).
    fn sampled(f: impl Fn(f64) -> DVec3, n: usize, jitter: f64) -> Vec<DVec3> {
        (0..n).map(|i| f(i as f64 / n as f64) + DVec3::new(0.0, 0.0, jitter * ((i * 7919 % 13) as f64 / 6.0 - 1.0))).collect()
    }

    fn grown(points: &[DVec3]) -> Vec<Grown> {
        let index = Index::new(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>());
        grow(points, points.len(), &index, &P, &Cancel::default())
    }

    #[test]
    fn a_rim_narrower_than_four_steps_is_grown_whole() {
        let r = 1.5;
        let circle = |t: f64| DVec3::new(r * (t * std::f64::consts::TAU).cos(), r * (t * std::f64::consts::TAU).sin(), 0.0);
        let points = sampled(circle, 940, 0.05);
        let lines = grown(&points);
        assert_eq!(lines.len(), 1, "{lines:?}");
        let v = &lines[0].vertices;
        assert!(lines[0].closed);
        // (A chord of a full step lies up to 0.09 inside this rim.)
        for q in v {
            assert!((q.truncate().length() - r).abs() < 0.15, "{q}");
        }
        // Every point of the rim is within a step of the polyline.
        for q in &points {
            assert!(v.iter().any(|x| x.distance(*q) < P.step), "{q} not covered");
        }
    }

    #[test]
    fn a_corner_is_not_rounded() {
        // Two arms of 6 steps meeting at a right angle at the origin.
        let mut points = sampled(|t| DVec3::new(6.0 * (1.0 - t), 0.0, 0.0), 300, 0.05);
        points.extend(sampled(|t| DVec3::new(0.0, 6.0 * t, 0.0), 300, 0.05));
        let lines = grown(&points);
        assert_eq!(lines.len(), 2, "{lines:?}");
        for l in &lines {
            // Each polyline keeps to one arm, short of the corner by at most a step.
            let on_x = l.vertices.iter().all(|q| q.y.abs() < 0.1 || q.length() < P.step);
            let on_y = l.vertices.iter().all(|q| q.x.abs() < 0.1 || q.length() < P.step);
            assert!(on_x || on_y, "{:?}", l.vertices);
        }
    }
}
