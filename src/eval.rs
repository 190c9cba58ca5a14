//! `crease eval`: scores extracted curves against ground-truth curves, as Daniels et al. 2007
//! do: recall and precision within a tolerance in dB (the bounding-box diagonal of the truth).
//!
//! Both curve sets are resampled at `step * dB` (default 0.001 dB, dB = the truth's bounding-box
//! diagonal unless given). Every sample carries the length it stands for, so shares are shares
//! of length. Distances are exact point-to-polyline distances.
//! - recall: share of truth length within `tol * dB` of an extracted curve;
//! - precision: share of extracted length within `tol * dB` of the truth;
//! - mean / max distance: of extracted samples to the truth;
//! - Chamfer distance: the average of the two directed mean distances; Hausdorff: the larger of
//!   the two directed maximum distances. All distances are reported in dB units;
//! - with a separation R: recall over the resolvable truth only, the truth farther than R from
//!   any other feature (see [`EvalOptions::resolvable`]), so that targets can be stated honestly
//!   where features lie closer together than the noise lets any method separate them.

use crate::curves::{segment_distance, Polyline};
use crate::points::Bounds;
use crate::spatial::Index;
use glam::DVec3;
use serde::Serialize;

/// Scoring parameters.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// The length unit dB; defaults to the truth's bounding-box diagonal.
    pub diag: Option<f64>,
    /// Distance tolerance in dB units.
    pub tol: f64,
    /// Resampling step in dB units.
    pub step: f64,
    /// Separation R in dB units: a truth sample is resolvable if every truth point within R
    /// of it is reached from it along the truth curves (through shared corners) within 2 R,
    /// so that only other, non-adjacent features count (a thin plate's opposite rims, the two
    /// sides of a slot, a knife edge's neighbours), not the curve itself or the curves meeting
    /// it at a corner.
    pub resolvable: Option<f64>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions { diag: None, tol: 0.01, step: 0.001, resolvable: None }
    }
}

/// Scores of one evaluation. Distances are in dB units.
#[derive(Clone, Debug, Serialize)]
pub struct Scores {
    /// Share of truth length matched.
    pub recall: f64,
    /// Share of extracted length matched (None if nothing was extracted).
    pub precision: Option<f64>,
    /// Mean distance of extracted samples to the truth.
    pub mean_distance: Option<f64>,
    /// Maximum distance of extracted samples to the truth.
    pub max_distance: Option<f64>,
    /// Symmetric Chamfer distance (average of the two directed means).
    pub chamfer: Option<f64>,
    /// Symmetric Hausdorff distance.
    pub hausdorff: Option<f64>,
    /// Number of extracted curves.
    pub curves: usize,
    /// Number of truth curves.
    pub truth_curves: usize,
    /// Total extracted length, in dB units.
    pub extracted_length: f64,
    /// Total truth length, in dB units.
    pub truth_length: f64,
    /// The dB used, in model units.
    pub diag: f64,
    /// The tolerance used, in dB units.
    pub tol: f64,
    /// Recall over the resolvable truth, if a separation was given.
    pub resolvable: Option<Resolvable>,
}

/// Recall over the truth that lies farther than a separation from any other feature.
#[derive(Clone, Debug, Serialize)]
pub struct Resolvable {
    /// The separation, in dB units.
    pub separation: f64,
    /// Share of the truth length that is resolvable.
    pub share: f64,
    /// Share of the resolvable truth length matched (None if none is resolvable).
    pub recall: Option<f64>,
}

/// A densely resampled curve set: points, the length each midpoint stands for, and which
/// consecutive points form segments.
struct Dense {
    /// Refined polyline vertices (segment ends).
    pts: Vec<DVec3>,
    /// `link[i]` is true if pts[i] and pts[i + 1] are joined by a segment.
    link: Vec<bool>,
    /// Sample positions (segment midpoints) and weights (segment lengths).
    samples: Vec<(DVec3, f64)>,
}

fn densify(curves: &[Polyline], step: f64) -> Dense {
    let mut d = Dense { pts: vec![], link: vec![], samples: vec![] };
    for c in curves {
        let segs: Vec<(DVec3, DVec3)> = c.segments().collect();
        if segs.is_empty() {
            continue;
        }
        d.pts.push(segs[0].0);
        for (a, b) in segs {
            let len = a.distance(b);
            let k = ((len / step).ceil() as usize).max(1);
            for i in 1..=k {
                let q = a.lerp(b, i as f64 / k as f64);
                let prev = *d.pts.last().unwrap();
                d.samples.push(((prev + q) * 0.5, len / k as f64));
                d.link.push(true);
                d.pts.push(q);
            }
        }
        d.link.push(false);
    }
    d
}

/// Distance from every sample of `from` to the polylines of `to`.
fn distances(from: &Dense, to: &Dense, origin: DVec3) -> Vec<f64> {
    let local: Vec<[f32; 3]> = to.pts.iter().map(|p| (*p - origin).as_vec3().to_array()).collect();
    let index = Index::new(&local);
    let mut nn = Vec::new();
    from.samples
        .iter()
        .map(|(p, _)| {
            nn.clear();
            index.nearest_n(&(*p - origin).as_vec3().to_array(), 8, &mut nn);
            let mut best = f64::INFINITY;
            for &(i, _) in &nn {
                let i = i as usize;
                best = best.min(p.distance(to.pts[i]));
                if to.link[i] {
                    best = best.min(segment_distance(*p, to.pts[i], to.pts[i + 1]));
                }
                if i > 0 && to.link[i - 1] {
                    best = best.min(segment_distance(*p, to.pts[i - 1], to.pts[i]));
                }
            }
            best
        })
        .collect()
}

/// For every sample of the truth `t`: true if each truth point within `r` of it is reached
/// from it along the truth curves within `2 r` (see [`EvalOptions::resolvable`]). Curves meet
/// where their vertices coincide.
fn resolvable(t: &Dense, r: f64, origin: DVec3) -> Vec<bool> {
    use rayon::prelude::*;
    use std::collections::HashMap;
    // Graph nodes: the refined vertices, coincident ones merged.
    let mut ids: HashMap<[u64; 3], u32> = HashMap::new();
    let node: Vec<u32> = t
        .pts
        .iter()
        .map(|p| {
            let n = ids.len() as u32;
            *ids.entry(p.to_array().map(f64::to_bits)).or_insert(n)
        })
        .collect();
    let mut adj: Vec<Vec<(u32, f64)>> = vec![vec![]; ids.len()];
    // The segment of each sample (samples are the linked segments, in order).
    let mut seg = Vec::with_capacity(t.samples.len());
    for i in (0..t.link.len()).filter(|&i| t.link[i]) {
        let (a, b) = (node[i], node[i + 1]);
        let w = t.pts[i].distance(t.pts[i + 1]);
        adj[a as usize].push((b, w));
        adj[b as usize].push((a, w));
        seg.push(i);
    }
    let index = Index::new(&t.pts.iter().map(|p| (*p - origin).as_vec3().to_array()).collect::<Vec<_>>());
    t.samples
        .par_iter()
        .zip(&seg)
        .map_init(
            || (HashMap::new(), Vec::new()),
            |(reached, nn), (&(p, _), &i)| {
                // Nodes within 2 r along the curves (Dijkstra, bounded).
                reached.clear();
                let mut heap = std::collections::BinaryHeap::new();
                for j in [i, i + 1] {
                    heap.push(std::cmp::Reverse((Ordered(p.distance(t.pts[j])), node[j])));
                }
                while let Some(std::cmp::Reverse((d, n))) = heap.pop() {
                    if d.0 > 2.0 * r || reached.contains_key(&n) {
                        continue;
                    }
                    reached.insert(n, ());
                    for &(m, w) in &adj[n as usize] {
                        heap.push(std::cmp::Reverse((Ordered(d.0 + w), m)));
                    }
                }
                nn.clear();
                index.within(&(p - origin).as_vec3().to_array(), r as f32, nn);
                nn.iter().all(|&(j, _)| t.pts[j as usize].distance(p) > r || reached.contains_key(&node[j as usize]))
            },
        )
        .collect()
}

/// An f64 that orders totally (for the heap).
#[derive(Clone, Copy, PartialEq)]
struct Ordered(f64);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// Scores `curves` against `truth`.
///
/// ```
/// use crease::curves::Polyline;
/// use crease::eval::{evaluate, EvalOptions};
/// use glam::DVec3;
///
/// let truth = vec![Polyline::from_points(0, [DVec3::ZERO, DVec3::X])];
/// let found = vec![Polyline::from_points(0, [DVec3::new(0.0, 0.001, 0.0), DVec3::new(0.5, 0.001, 0.0)])];
/// let s = evaluate(&truth, &found, &EvalOptions::default());
/// assert!((s.recall - 0.5).abs() < 0.02 && s.precision == Some(1.0));
/// ```
pub fn evaluate(truth: &[Polyline], curves: &[Polyline], opts: &EvalOptions) -> Scores {
    let tb = Bounds::of(truth.iter().flat_map(|c| c.vertices.iter().map(|v| v.p)));
    let diag = opts.diag.unwrap_or_else(|| tb.diagonal()).max(f64::MIN_POSITIVE);
    let origin = if tb.is_empty() { DVec3::ZERO } else { DVec3::from(tb.min) };
    let step = opts.step * diag;
    let (t, e) = (densify(truth, step), densify(curves, step));
    let tol = opts.tol * diag;
    let total = |d: &Dense| d.samples.iter().map(|s| s.1).sum::<f64>();
    let (tl, el) = (total(&t), total(&e));
    let mut s = Scores {
        recall: 0.0,
        precision: None,
        mean_distance: None,
        max_distance: None,
        chamfer: None,
        hausdorff: None,
        curves: curves.len(),
        truth_curves: truth.len(),
        extracted_length: el / diag,
        truth_length: tl / diag,
        diag,
        tol: opts.tol,
        resolvable: None,
    };
    if t.samples.is_empty() {
        return s;
    }
    // (Nothing extracted: every truth sample is infinitely far.)
    let dt = if e.samples.is_empty() { vec![f64::INFINITY; t.samples.len()] } else { distances(&t, &e, origin) };
    if let Some(r) = opts.resolvable {
        let ok = resolvable(&t, r * diag, origin);
        // (+ 0.0: an empty float sum is -0.0.)
        let length = |want: Option<f64>| {
            t.samples.iter().zip(&ok).zip(&dt).filter(|&((_, &o), &x)| o && want.is_none_or(|tol| x <= tol)).map(|((s, _), _)| s.1).sum::<f64>() + 0.0
        };
        let share = length(None);
        s.resolvable = Some(Resolvable { separation: r, share: share / tl, recall: (share > 0.0).then(|| length(Some(tol)) / share) });
    }
    if e.samples.is_empty() {
        return s;
    }
    let de = distances(&e, &t, origin);
    let matched = |d: &Dense, dist: &[f64]| d.samples.iter().zip(dist).filter(|&(_, &x)| x <= tol).map(|(s, _)| s.1).sum::<f64>();
    let mean = |d: &Dense, dist: &[f64]| d.samples.iter().zip(dist).map(|(s, x)| s.1 * x).sum::<f64>() / total(d);
    let max = |dist: &[f64]| dist.iter().copied().fold(0.0, f64::max);
    s.recall = matched(&t, &dt) / tl;
    s.precision = Some(matched(&e, &de) / el);
    s.mean_distance = Some(mean(&e, &de) / diag);
    s.max_distance = Some(max(&de) / diag);
    s.chamfer = Some((mean(&e, &de) + mean(&t, &dt)) / 2.0 / diag);
    s.hausdorff = Some(max(&de).max(max(&dt)) / diag);
    s
}

/// Formats scores for humans.
pub fn render_text(s: &Scores) -> String {
    let o = |x: Option<f64>| x.map(|v| format!("{v:.6}")).unwrap_or_else(|| "n/a".into());
    format!(
        "recall      {:.4}\nprecision   {}\nmean dist   {} dB\nmax dist    {} dB\nchamfer     {} dB\nhausdorff   {} dB\ncurves      {} (truth {})\nlength      {:.4} dB (truth {:.4} dB)\ndB          {}\ntolerance   {} dB\n{}",
        s.recall,
        s.precision.map(|v| format!("{v:.4}")).unwrap_or_else(|| "n/a".into()),
        o(s.mean_distance),
        o(s.max_distance),
        o(s.chamfer),
        o(s.hausdorff),
        s.curves,
        s.truth_curves,
        s.extracted_length,
        s.truth_length,
        s.diag,
        s.tol,
        s.resolvable.as_ref().map_or(String::new(), |r| format!(
            "resolvable  recall {} over {:.1} % of the truth (features farther apart than {} dB)\n",
            r.recall.map_or("n/a".into(), |x| format!("{x:.4}")),
            100.0 * r.share,
            r.separation
        ))
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(id: u32, a: [f64; 3], b: [f64; 3]) -> Polyline {
        Polyline::from_points(id, [DVec3::from(a), DVec3::from(b)])
    }

    /// Truth: three unit edges of a cube, diagonal fixed to 1 for easy numbers.
    fn truth() -> Vec<Polyline> {
        vec![line(0, [0.0; 3], [1.0, 0.0, 0.0]), line(1, [0.0; 3], [0.0, 1.0, 0.0]), line(2, [0.0; 3], [0.0, 0.0, 2.0])]
    }

    fn opts() -> EvalOptions {
        EvalOptions { diag: Some(1.0), ..Default::default() }
    }

    #[test]
    fn identical_sets_score_perfectly() {
        let s = evaluate(&truth(), &truth(), &opts());
        assert!((s.recall - 1.0).abs() < 1e-12);
        assert!((s.precision.unwrap() - 1.0).abs() < 1e-12);
        assert!(s.mean_distance.unwrap() < 1e-12 && s.max_distance.unwrap() < 1e-12);
        assert!(s.chamfer.unwrap() < 1e-12 && s.hausdorff.unwrap() < 1e-12);
        assert_eq!((s.curves, s.truth_curves), (3, 3));
    }

    #[test]
    fn shifted_curve_scores_its_shift() {
        let t = vec![line(0, [0.0; 3], [1.0, 0.0, 0.0])];
        let e = vec![line(0, [0.0, 0.005, 0.0], [1.0, 0.005, 0.0])];
        let s = evaluate(&t, &e, &opts());
        assert!((s.mean_distance.unwrap() - 0.005).abs() < 1e-9, "{:?}", s.mean_distance);
        assert!((s.max_distance.unwrap() - 0.005).abs() < 1e-9);
        assert!((s.recall - 1.0).abs() < 1e-12, "within the 0.01 tolerance");
        // Beyond the tolerance nothing matches.
        let e = vec![line(0, [0.0, 0.02, 0.0], [1.0, 0.02, 0.0])];
        let s = evaluate(&t, &e, &opts());
        assert_eq!(s.recall, 0.0);
        assert_eq!(s.precision, Some(0.0));
    }

    #[test]
    fn missing_curve_lowers_recall_by_its_length_share() {
        let mut e = truth();
        e.pop(); // the length-2 edge: half of the total length 4
        let s = evaluate(&truth(), &e, &opts());
        // Samples near the shared corner are within tolerance of the other edges: allow that.
        assert!((s.recall - 0.5).abs() < 0.006, "{}", s.recall);
        assert!((s.precision.unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn extra_curve_lowers_precision_by_its_length_share() {
        let mut e = truth();
        e.push(line(9, [5.0, 5.0, 5.0], [5.0, 5.0, 9.0])); // length 4, far away
        let s = evaluate(&truth(), &e, &opts());
        assert!((s.recall - 1.0).abs() < 1e-12);
        assert!((s.precision.unwrap() - 0.5).abs() < 1e-9, "{:?}", s.precision);
        assert_eq!(s.curves, 4);
    }

    #[test]
    fn resolvable_recall_leaves_out_features_closer_than_the_separation() {
        // A square loop (corners shared) and, 0.004 from the middle of its bottom side, a short
        // parallel curve: a thin plate's other rim. At a separation of 0.01 the parts of both
        // that face each other are not resolvable; the square's corners and the rest are.
        let sq = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]];
        let square = Polyline::from_points(0, sq.map(DVec3::from));
        let rim = line(1, [0.3, -0.004, 0.0], [0.7, -0.004, 0.0]);
        let truth = vec![square.clone(), rim.clone()];
        // Found: the square only.
        let o = EvalOptions { diag: Some(1.0), tol: 0.002, resolvable: Some(0.01), ..Default::default() };
        let s = evaluate(&truth, std::slice::from_ref(&square), &o);
        let r = s.resolvable.unwrap();
        // Unresolvable: the rim (0.4) and the square's side beside it (0.4 + about 0.01 each
        // end), of 4.4.
        assert!((r.share - (4.4 - 0.82) / 4.4).abs() < 0.005, "share {}", r.share);
        assert!((r.recall.unwrap() - 1.0).abs() < 1e-9, "the missed rim is not resolvable");
        assert!((s.recall - 4.0 / 4.4).abs() < 0.005, "plain recall {}", s.recall);
        // Apart by more than the separation, everything is resolvable.
        let far = line(1, [0.3, -0.05, 0.0], [0.7, -0.05, 0.0]);
        let s = evaluate(&[square, far], &[rim], &o);
        assert!((s.resolvable.unwrap().share - 1.0).abs() < 1e-9);
    }

    #[test]
    fn nothing_extracted() {
        let s = evaluate(&truth(), &[], &EvalOptions { resolvable: Some(0.01), ..opts() });
        assert_eq!(s.recall, 0.0);
        assert!(s.precision.is_none());
        let r = s.resolvable.unwrap();
        assert_eq!((r.share, r.recall), (1.0, Some(0.0)));
    }
}
