//! Feature-curve extraction after Daniels et al. 2007/2008 (see DESIGN.md section 2).
//!
//! Stages, each a function of plain data: [`candidates`] (MLS residual), [`project`] (robust
//! MLS and Newton projection, corner grouping), [`smooth`] (adaptive PCA smoothing), [`grow`]
//! (polyline growing) and [`complete`] (gaps, corners, junctions, Laplacian relaxation).
//! [`extract`] runs them all on a cloud that fits in memory.

pub mod candidates;
pub mod cloud;
pub mod complete;
pub mod fit;
pub mod grow;
pub mod project;
pub mod smooth;

use crate::curves::{Polyline, Vertex};
use crate::spatial::Index;
use cloud::Cloud;
use fit::Pca;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// User parameters; every length is in model units and defaults to a multiple of the point
/// spacing kappa (the median nearest-neighbour distance).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Params {
    /// Point spacing kappa (default: estimated).
    pub kappa: Option<f64>,
    /// Neighbourhood radius of the candidate fit (default 6 kappa).
    pub fit_radius: Option<f64>,
    /// Neighbourhood radius of the robust projection (default 9 kappa).
    pub rmls_radius: Option<f64>,
    /// Residual threshold tau (default: mean residual over all points).
    pub tau: Option<f64>,
    /// Polyline step s_max (default 4.5 kappa).
    pub step: Option<f64>,
    /// Largest turn while growing, degrees (default 30).
    pub max_turn_deg: Option<f64>,
    /// Creases whose surface normals differ by less than this many degrees are ignored
    /// (default 25).
    pub min_angle_deg: Option<f64>,
    /// Seed of the robust fits' random streams (default 1).
    pub seed: Option<u64>,
}

/// Parameters with every default resolved to a value.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Resolved {
    /// Point spacing (median nearest-neighbour distance).
    pub kappa: f64,
    /// Estimated noise: standard deviation of points about their local plane.
    pub noise: f64,
    /// Length unit of the defaults: max(kappa, 2 noise), so neighbourhoods outgrow the noise.
    pub scale: f64,
    /// Share of points used by the fits (1: all; less when noise makes neighbourhoods large).
    pub keep: f64,
    /// Candidate fit radius.
    pub fit_radius: f64,
    /// Robust projection radius.
    pub rmls_radius: f64,
    /// Smallest inlier threshold of the robust fits.
    pub min_threshold: f64,
    /// Polyline step.
    pub step: f64,
    /// Largest turn while growing, degrees.
    pub max_turn_deg: f64,
    /// Gentlest crease kept, degrees between the surface normals.
    pub min_angle_deg: f64,
    /// Corner grouping radius.
    pub corner_radius: f64,
    /// Completion search reach, in steps.
    pub reach_steps: f64,
    /// Completion cone half-aperture, degrees.
    pub aperture_deg: f64,
    /// Smoothing linearity target.
    pub linearity: f64,
    /// Random seed.
    pub seed: u64,
}

/// Neighbours a fit should see; denser clouds are thinned to about this many.
pub const TARGET_NEIGHBOURS: f64 = 150.0;
/// The default length unit is at least this many noise deviations.
pub const NOISE_SCALE: f64 = 1.5;

impl Params {
    /// Resolves defaults given the measured spacing `kappa` and noise `noise`.
    pub fn resolve(&self, kappa: f64, noise: f64) -> Resolved {
        let kappa = self.kappa.unwrap_or(kappa);
        let scale = kappa.max(NOISE_SCALE * noise);
        let rmls = self.rmls_radius.unwrap_or(9.0 * scale);
        let step = self.step.unwrap_or(4.5 * scale);
        Resolved {
            kappa,
            noise,
            scale,
            keep: 1.0,
            fit_radius: self.fit_radius.unwrap_or(6.0 * scale),
            rmls_radius: rmls,
            min_threshold: 0.05 * scale,
            step,
            max_turn_deg: self.max_turn_deg.unwrap_or(30.0),
            min_angle_deg: self.min_angle_deg.unwrap_or(25.0),
            corner_radius: rmls,
            reach_steps: 4.0,
            aperture_deg: 45.0,
            linearity: 0.7,
            seed: self.seed.unwrap_or(1),
        }
    }

    /// The largest neighbourhood radius any stage reads around a point of a tile's core: the
    /// halo a tile needs.
    pub fn max_radius(&self, kappa: f64, noise: f64) -> f64 {
        let r = self.resolve(kappa, noise);
        r.fit_radius.max(r.rmls_radius)
    }
}

/// Counts per stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Counts {
    /// Input points.
    pub points: u64,
    /// Candidates (residual above tau).
    pub candidates: u64,
    /// Candidates dropped as outliers (one surface).
    pub one_surface: u64,
    /// Edge points after projection and culling.
    pub edge_points: u64,
    /// Corner points before grouping.
    pub corner_points: u64,
    /// Corners after grouping.
    pub corners: u64,
    /// Polylines grown.
    pub grown: u64,
    /// Curves after completion.
    pub curves: u64,
}

/// Seconds per stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Timings {
    /// Spacing estimate and k-d tree.
    pub index: f64,
    /// Stage 1.
    pub candidates: f64,
    /// Stage 2.
    pub projection: f64,
    /// Stage 3.
    pub smoothing: f64,
    /// Stage 4.
    pub growing: f64,
    /// Stage 5.
    pub completion: f64,
}

/// The result of an extraction.
#[derive(Clone, Debug)]
pub struct Extraction {
    /// Feature curves in world coordinates.
    pub curves: Vec<Polyline>,
    /// Parameters used.
    pub params: Resolved,
    /// tau used.
    pub tau: f64,
    /// Counts.
    pub counts: Counts,
    /// Timings.
    pub seconds: Timings,
}

/// Extracts feature curves from `points` (world coordinates) held in memory.
pub fn extract(points: &[DVec3], params: &Params) -> Extraction {
    let t = Instant::now();
    let mut seconds = Timings::default();
    let mut counts = Counts { points: points.len() as u64, ..Default::default() };
    let full = Cloud::new(points);
    let local: Vec<DVec3> = (0..full.len()).map(|i| full.at(i)).collect();
    let kappa = params.kappa.unwrap_or_else(|| crate::spacing::spacing(&local, 20_000));
    let noise = noise_sigma(&full, kappa);
    let mut r = params.resolve(kappa, noise);
    // Noisy clouds need neighbourhoods wider than the noise; thin them (by a hash of each
    // point's identity, so the choice is the same in any tile) to keep fits affordable.
    r.keep = (TARGET_NEIGHBOURS / median_count(&full, r.fit_radius)).min(1.0);
    let cloud = if r.keep < 0.7 {
        let kept: Vec<DVec3> = (0..points.len()).filter(|&i| keep_point(i as u64, r.keep, r.seed)).map(|i| points[i]).collect();
        Cloud::with_origin(&kept, full.origin)
    } else {
        full
    };
    drop(local);
    seconds.index = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let all: Vec<u32> = (0..cloud.len() as u32).collect();
    let res = candidates::residuals(&cloud, &all, r.fit_radius);
    let tau = params.tau.unwrap_or_else(|| res.iter().map(|&x| x as f64).sum::<f64>() / res.len().max(1) as f64);
    let cand: Vec<u32> = all.iter().copied().filter(|&i| res[i as usize] as f64 > tau).collect();
    counts.candidates = cand.len() as u64;
    seconds.candidates = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let ids: Vec<u64> = cand.iter().map(|&i| cloud.ids[i as usize] as u64).collect();
    let pp = project::ProjectParams { radius: r.rmls_radius, min_threshold: r.min_threshold, min_angle_deg: r.min_angle_deg, seed: r.seed };
    let projected = project::project(&cloud, &cand, &ids, &pp);
    let edges: Vec<project::EdgePoint> = projected.iter().filter_map(|x| x.edge).collect();
    let corner_pts: Vec<project::CornerPoint> = projected.iter().filter_map(|x| x.corner).collect();
    counts.one_surface = projected.iter().filter(|x| x.surfaces == 1).count() as u64;
    counts.edge_points = edges.len() as u64;
    counts.corner_points = corner_pts.len() as u64;
    let corners = project::group_corners(&corner_pts, r.corner_radius, 3);
    counts.corners = corners.len() as u64;
    seconds.projection = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let edge_pos: Vec<DVec3> = edges.iter().map(|e| e.p).collect();
    let sp = smooth::SmoothParams { linearity: r.linearity, max_radius: 2.0 * r.rmls_radius };
    let smoothed = smooth::smooth(&edge_pos, &corners, &sp);
    seconds.smoothing = t.elapsed().as_secs_f64();

    if let Ok(dir) = std::env::var("CREASE_DEBUG_DIR") {
        let dump = |name: &str, pts: &[DVec3]| {
            let text: String = pts.iter().map(|p| { let p = *p + cloud.origin; format!("v {} {} {}\n", p.x, p.y, p.z) }).collect();
            let _ = std::fs::write(std::path::Path::new(&dir).join(name), text);
        };
        dump("edges.obj", &edge_pos);
        dump("smoothed.obj", &smoothed);
        dump("corners.obj", &corners);
    }
    let t = Instant::now();
    let grown = grow::grow(&smoothed, &grow::GrowParams { step: r.step, max_turn_deg: r.max_turn_deg });
    counts.grown = grown.len() as u64;
    seconds.growing = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let cp = complete::CompleteParams { step: r.step, reach: r.reach_steps, aperture_deg: r.aperture_deg, min_steps: 3.0, smooth_passes: 2 };
    let curves = complete::complete(grown.into_iter().map(|g| complete::Curve::new(g.vertices, g.closed)).collect(), &corners, &cp);
    let curves = to_polylines(&curves, &smoothed, &edges, cloud.origin, r.step);
    counts.curves = curves.len() as u64;
    seconds.completion = t.elapsed().as_secs_f64();
    Extraction { curves, params: r, tau, counts, seconds }
}

/// Noise estimate: median, over a sample of points, of the RMS residual of their
/// neighbourhood (radius 16 kappa) about its best-fitting quadric (a plane would mistake the
/// curvature of small parts for noise; the quadric's six coefficients absorb little noise from
/// the hundred-odd points).
pub fn noise_sigma(cloud: &Cloud, kappa: f64) -> f64 {
    let step = (cloud.len() / 2000).max(1);
    let mut buf = Vec::new();
    let mut s: Vec<f64> = (0..cloud.len())
        .step_by(step)
        .filter_map(|i| {
            cloud.neighbours(cloud.at(i), 16.0 * kappa, 0, 128, &mut buf);
            if buf.len() < 10 {
                return None;
            }
            let pts = || buf.iter().map(|&(j, _)| (cloud.at(j as usize), 1.0));
            let pca = Pca::of(pts())?;
            let q = fit::Quadric::fit(fit::Frame::new(pca.mean, pca.normal()), pts(), 1e-6)?;
            Some((pts().map(|(p, _)| q.value(p).powi(2)).sum::<f64>() / buf.len() as f64).sqrt())
        })
        .collect();
    if s.is_empty() {
        return 0.0;
    }
    let m = s.len() / 2;
    *s.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1
}

/// Median number of points within `r` of a sample of points.
fn median_count(cloud: &Cloud, r: f64) -> f64 {
    let step = (cloud.len() / 1000).max(1);
    let mut buf = Vec::new();
    let mut c: Vec<usize> = (0..cloud.len())
        .step_by(step)
        .map(|i| {
            buf.clear();
            cloud.index.within(&cloud.points[i], r as f32, &mut buf);
            buf.len()
        })
        .collect();
    if c.is_empty() {
        return 1.0;
    }
    let m = c.len() / 2;
    (*c.select_nth_unstable(m).1).max(1) as f64
}

/// True if point `id` belongs to the thinned cloud keeping share `keep`.
pub fn keep_point(id: u64, keep: f64, seed: u64) -> bool {
    let mut r = crate::synth::rng::Rng::stream(seed ^ 0x7417, id);
    r.f64() < keep
}

/// Attaches normals (from the nearest edge points, orientation carried along each curve) and
/// converts to world coordinates.
fn to_polylines(curves: &[complete::Curve], smoothed: &[DVec3], edges: &[project::EdgePoint], origin: DVec3, step: f64) -> Vec<Polyline> {
    let f32s: Vec<[f32; 3]> = smoothed.iter().map(|q| q.as_vec3().to_array()).collect();
    let index = (!f32s.is_empty()).then(|| Index::new(&f32s));
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
                if let Some(ix) = &index {
                    ix.within(&p.as_vec3().to_array(), (0.5 * step) as f32, &mut nn);
                    if nn.is_empty() {
                        ix.nearest_n(&p.as_vec3().to_array(), 1, &mut nn);
                    }
                }
                nn.sort_unstable_by_key(|a| a.0);
                let mut acc = [DVec3::ZERO; 2];
                for &(j, _) in &nn {
                    let n = edges[j as usize].n;
                    let reference = prev.unwrap_or(edges[nn[0].0 as usize].n);
                    acc[0] += align(n, reference)[0];
                    acc[1] += align(n, reference)[1];
                }
                let pair = [acc[0].normalize_or_zero(), acc[1].normalize_or_zero()];
                if pair[0] != DVec3::ZERO {
                    normals[i] = pair;
                    prev = Some(pair);
                }
            }
            // Corners take the normals of their neighbour on the curve.
            for i in 0..c.v.len() {
                if c.corner[i] {
                    let j = if i == 0 { 1.min(c.v.len() - 1) } else { i - 1 };
                    normals[i] = normals[j];
                }
            }
            Polyline {
                id: id as u32,
                closed: c.closed,
                vertices: c
                    .v
                    .iter()
                    .zip(&normals)
                    .zip(&c.corner)
                    .map(|((&p, n), &corner)| Vertex { p: p + origin, n: [n[0].as_vec3(), n[1].as_vec3()], corner })
                    .collect(),
            }
        })
        .collect()
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
