//! Feature-curve extraction after Daniels et al. 2007/2008 (see DESIGN.md section 2).
//!
//! Stages, each a function of plain data: [`candidates`] (MLS residual), [`project`] (robust
//! MLS and Newton projection, corner grouping), [`smooth`] (adaptive PCA smoothing), [`grow`]
//! (polyline growing) and [`complete`] (gaps, corners, junctions, Laplacian relaxation).
//! [`extract`] runs them all on a cloud that fits in memory.

pub mod candidates;
pub mod cloud;
pub mod complete;
pub mod consensus;
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
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
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
    /// (default 28).
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

impl Resolved {
    /// The halo a tile needs around its core for stages 1-2: the widest neighbourhood they
    /// read, with a margin. Sparse neighbourhoods are widened no farther, so that every
    /// point's neighbourhood is the same in any tiling.
    pub fn halo(&self) -> f64 {
        1.25 * self.fit_radius.max(self.rmls_radius)
    }

    /// Side of the grid cells a tile's cloud is stored by for stages 1-2 (see
    /// [`Cloud::gridded`]): the same for both, so that the two passes load a tile in the same
    /// order. 1.5 fit radii, the block size that made the fewest instructions (see
    /// `BLOCK_CELL` in `cloud.rs`) for the residual pass, whose many cheap fits feel it most.
    /// (10 M scene, two runs each: 52.9-54.1 s of CPU; 52.9-56.5 s with 1.5 times the mean of
    /// the radii, 55.1-56.4 s with 1.5 projection radii.)
    pub fn cell_side(&self) -> f64 {
        1.5 * self.fit_radius
    }

    /// True if the neighbourhoods are sized by the noise rather than by the spacing (see
    /// [`NOISE_SCALE`]): the candidates then also take the crease test (see
    /// [`candidates::CREASE_RATIO`]), and edge points the consensus filter (see [`consensus`]).
    pub fn noise_limited(&self) -> bool {
        self.scale > self.kappa
    }
}

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
            min_angle_deg: self.min_angle_deg.unwrap_or(28.0),
            corner_radius: rmls,
            reach_steps: 4.0,
            aperture_deg: 45.0,
            linearity: 0.7,
            seed: self.seed.unwrap_or(1),
        }
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
    /// Edge points dropped before growing because no neighbour agreed on their two surfaces
    /// (see [`consensus`]).
    #[serde(default)]
    pub unconfirmed: u64,
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

/// Share of points whose neighbourhoods are measured for kappa and the noise (by id hash).
pub const STAT_SAMPLES: f64 = 20_000.0;

/// The quantum of [`position_key`] for a cloud with bounding-box diagonal `diag`: a power of
/// two near a billionth of it, so that clouds whose bounds differ in the last bits agree.
pub fn key_quantum(diag: f64) -> f64 {
    2f64.powi((diag.max(1e-300) * 1e-9).log2().floor() as i32)
}

/// A point's identity from its position (rounded to `q`): the same point gets the same key
/// whichever file, tile or order it comes in, so sampling and thinning by key are independent
/// of how a cloud is split.
pub fn position_key(p: DVec3, q: f64) -> u64 {
    let w = (p / q).round();
    let mut bytes = [0u8; 24];
    for (k, v) in w.to_array().iter().enumerate() {
        bytes[8 * k..8 * k + 8].copy_from_slice(&(*v as i64).to_le_bytes());
    }
    crate::run::fnv1a(&bytes)
}

/// True if the point with key `key` is one of the statistics sample in a cloud of `total`
/// points.
pub fn stat_sample(key: u64, total: u64, seed: u64) -> bool {
    keep_point(key ^ 0x5A5A_5A5A, STAT_SAMPLES / total.max(1) as f64, seed)
}

/// Neighbourhood statistics of one sampled point: its spacing (from the 16th neighbour, see
/// [`crate::spacing::spacing`]) and the RMS residual of a quadric fitted within 16 of those
/// spacings (the noise).
pub fn point_stats(cloud: &Cloud, i: usize, buf: &mut Vec<(u32, f32)>) -> Option<(f64, f64, f64)> {
    const K: usize = 16;
    buf.clear();
    // (A few more than K + 1 from the f32 tree, whose distances depend on the tile's origin in
    // their last bits; the K-th neighbour's distance is then taken in f64, from the f64
    // positions, so it is the same in every tile.)
    cloud.index().nearest_n(&cloud.at(i).as_vec3().to_array(), K + 1 + 8, buf);
    if buf.len() < K + 1 {
        return None;
    }
    let q = cloud.at(i);
    let mut d2: Vec<f64> = buf.iter().map(|b| cloud.at(b.0 as usize).distance_squared(q)).collect();
    let rk = d2.select_nth_unstable_by(K, f64::total_cmp).1.sqrt();
    let kappa = rk * (2f64.ln() / K as f64).sqrt();
    // Points per unit area around this point, from the count in the 16-kappa ball.
    let density = cloud.count_within(q, 16.0 * kappa, buf) as f64 / (std::f64::consts::PI * (16.0 * kappa).powi(2));
    cloud.neighbours(q, 16.0 * kappa, 0, 128, buf);
    if buf.len() < 10 {
        return Some((kappa, 0.0, density));
    }
    // Fit, drop points beyond three robust deviations (outliers), fit again; the noise is the
    // RMS residual of what remains.
    let mut pts: Vec<DVec3> = buf.iter().map(|&(j, _)| cloud.at(j as usize)).collect();
    let mut rms = 0.0;
    for round in 0..2 {
        let pca = Pca::of(pts.iter().map(|&p| (p, 1.0)))?;
        let q = fit::Quadric::fit(fit::Frame::new(pca.mean, pca.normal()), pts.iter().map(|&p| (p, 1.0)), 1e-6)?;
        let mut res: Vec<f64> = pts.iter().map(|&p| q.value(p).abs()).collect();
        if round == 1 {
            rms = (res.iter().map(|r| r * r).sum::<f64>() / res.len() as f64).sqrt();
            break;
        }
        let limit = 3.0 * 1.4826 * median(&mut res.clone());
        pts.retain(|&p| q.value(p).abs() <= limit);
        if pts.len() < 10 {
            return Some((kappa, 0.0, density));
        }
        let _ = &mut res;
    }
    Some((kappa, rms, density))
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1
}

/// `x` rounded to 32 significant bits. The global quantities (spacing, noise, tau) are
/// statistics of fits made in each tile's local coordinates, and their last bits depend on
/// where a tile's origin lies; rounded, they come out the same in any tiling (unless two
/// values straddle a rounding boundary, a chance of about one in a billion), so that no
/// candidate or projection decides differently because of the tiling.
pub fn settle(x: f64) -> f64 {
    if !x.is_finite() {
        return x;
    }
    const DROP: u32 = 52 - 31;
    let b = x.to_bits();
    f64::from_bits((b + (1 << (DROP - 1))) & !((1u64 << DROP) - 1))
}

/// Resolves the parameters from the sampled statistics (spacing, noise, points per unit
/// area): spacing and noise are their medians; `keep` thins the cloud so that a fit sees about
/// [`TARGET_NEIGHBOURS`] points.
pub fn resolve(params: &Params, stats: &[(f64, f64, f64)]) -> Resolved {
    let mut k: Vec<f64> = stats.iter().map(|s| s.0).collect();
    let mut n: Vec<f64> = stats.iter().map(|s| s.1).collect();
    let mut d: Vec<f64> = stats.iter().map(|s| s.2).collect();
    let mut r = params.resolve(settle(median(&mut k)), settle(median(&mut n)));
    let count = median(&mut d) * std::f64::consts::PI * r.fit_radius.powi(2);
    r.keep = if count > 0.0 { (TARGET_NEIGHBOURS / count).min(1.0) } else { 1.0 };
    if r.keep >= 0.7 {
        r.keep = 1.0;
    }
    r
}

/// A point of the edge cloud in world coordinates, with the normals of its two surfaces.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldEdge {
    /// Position.
    pub p: DVec3,
    /// Surface normals.
    pub n: [glam::Vec3; 2],
}

/// A corner point in world coordinates with its grouping weight.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldCorner {
    /// Position.
    pub p: DVec3,
    /// Weight 1 / |corner - edge point|.
    pub w: f64,
}

/// Stages 1 and 2 for the points `core` of a tile's cloud (indices into `cloud`), with the
/// residual threshold `tau` (computed by the caller). Returns edge and corner points in world
/// coordinates, and the number of candidates and of candidates lying on one surface only.
pub fn project_core(cloud: &Cloud, candidates: &[u32], r: &Resolved) -> (Vec<WorldEdge>, Vec<WorldCorner>, u64) {
    // Each candidate's random stream is keyed by its position (on a grid far finer than the
    // spacing), not by its id, so the same point gets the same stream in any file layout.
    let q = r.kappa / 4096.0;
    let ids: Vec<u64> = candidates.iter().map(|&i| position_key(cloud.at(i as usize) + cloud.origin, q)).collect();
    let pp = project::ProjectParams { radius: r.rmls_radius, reach: r.halo(), min_threshold: r.min_threshold, min_angle_deg: r.min_angle_deg, seed: r.seed, noise: r.noise };
    let projected = project::project(cloud, candidates, &ids, &pp);
    let one = projected.iter().filter(|x| x.surfaces == 1).count() as u64;
    let o = cloud.origin;
    let edges = projected.iter().filter_map(|x| x.edge).map(|e| WorldEdge { p: e.p + o, n: [e.n[0].as_vec3(), e.n[1].as_vec3()] }).collect();
    let corners = projected.iter().filter_map(|x| x.corner).map(|c| WorldCorner { p: c.p + o, w: c.w }).collect();
    (edges, corners, one)
}

/// The grid the curve stages snap positions to, far finer than the spacing: positions
/// computed in differently placed tiles differ in their last bits, and the curve stages are
/// discrete (seed order, cone tests); snapping makes their input, and so the curves, the same
/// for any tiling.
pub fn snap_quantum(kappa: f64) -> f64 {
    kappa / 4096.0
}

/// `p` on the snapping grid of quantum `q`.
pub fn snap(p: DVec3, q: f64) -> DVec3 {
    // (+ 0.0 turns a negative zero, whose sign is rounding noise, into zero.)
    (p / q).round() * q + DVec3::ZERO
}

/// Snaps an edge point's position to quantum `q` and its normals to a millionth.
pub fn snap_edge(e: &mut WorldEdge, q: f64) {
    e.p = snap(e.p, q);
    e.n = e.n.map(|n| (n * 1e6).round() / 1e6 + glam::Vec3::ZERO);
}

/// Sorting key of a position: its bits (positions are snapped, so equal means identical).
fn pos_key(p: DVec3) -> [u64; 3] {
    p.to_array().map(f64::to_bits)
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
    corners.sort_unstable_by(|a, b| pos_key(a.p).cmp(&pos_key(b.p)).then(a.w.total_cmp(&b.w)));
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

/// Stage 3 and, on noise-limited clouds (see [`Resolved::noise_limited`]), the consensus filter
/// for a block of the edge cloud (see [`smooth_block`]; the normals are those of `points`,
/// context included): appends the smoothed positions of the first `own` points that their
/// neighbours confirm (see [`consensus`]), with their normals, to
/// `points_out` and `normals_out`, and returns how many were dropped. (The smoothing takes every
/// edge point as context, confirmed or not, so that the block's context need reach no further.)
pub fn smooth_and_confirm(points: &[DVec3], normals: &[[glam::Vec3; 2]], own: usize, grouped: &[DVec3], r: &Resolved, points_out: &mut Vec<DVec3>, normals_out: &mut Vec<[glam::Vec3; 2]>) -> u64 {
    let smoothed = smooth_block(points, own, grouped, r);
    // (Without noise, edge points off a crease are rare and the filter mostly cut sparse
    // stretches into more pieces: nonuniformly sampled fandisk 34 -> 45 curves, the 5 M scene
    // 366 -> 376; so it runs where the neighbourhoods are sized by the noise.)
    let keep = if r.noise_limited() { consensus::confirmed(points, normals, own, r.step) } else { vec![true; own] };
    let before = points_out.len();
    for ((p, n), k) in smoothed.into_iter().zip(&normals[..own]).zip(keep) {
        if k {
            points_out.push(p);
            normals_out.push(*n);
        }
    }
    (own - (points_out.len() - before)) as u64
}

/// Stages 4 and 5 on the whole smoothed edge cloud (positions relative to `origin`, with the
/// normals of each point's two surfaces), in any order: polyline growing and completion.
pub fn curves_from_smoothed(points: Vec<DVec3>, normals: Vec<[glam::Vec3; 2]>, grouped: &[DVec3], origin: DVec3, r: &Resolved, counts: &mut Counts, seconds: &mut Timings) -> Vec<Polyline> {
    // Sorted first, so the result does not depend on the order the points arrive in. (The
    // edge cloud is the one part of a run that grows with the whole input, not with a tile:
    // it is reordered through a permutation rather than as records, so that at most one
    // extra copy of one of its columns exists at a time.)
    use rayon::prelude::*;
    let mut perm: Vec<u32> = (0..points.len() as u32).collect();
    // (Points equal in position and normals are interchangeable: the unstable order of
    // such ties changes nothing.)
    perm.par_sort_unstable_by(|&a, &b| {
        let (a, b) = (a as usize, b as usize);
        pos_key(points[a]).cmp(&pos_key(points[b])).then(normal_key(&normals[a]).cmp(&normal_key(&normals[b])))
    });
    let points = permute(points, &perm);
    let normals = permute(normals, &perm);
    drop(perm);
    if let Ok(dir) = std::env::var("CREASE_DEBUG_DIR") {
        debug_dump(&dir, "smoothed.obj", &points, origin);
        debug_dump(&dir, "corners.obj", grouped, origin);
    }
    let t = Instant::now();
    let index = (!points.is_empty()).then(|| Index::new_parallel(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>()));
    let grown = index.as_ref().map_or(vec![], |ix| grow::grow(&points, ix, &grow::GrowParams { step: r.step, max_turn_deg: r.max_turn_deg }));
    counts.grown = grown.len() as u64;
    if let Ok(dir) = std::env::var("CREASE_DEBUG_DIR") {
        let pl: Vec<Polyline> = grown.iter().enumerate().map(|(i, g)| Polyline::from_points(i as u32, g.vertices.iter().map(|p| *p + origin))).collect();
        let _ = crate::curves::write_obj(&std::path::Path::new(&dir).join("grown.obj"), &pl);
    }
    seconds.growing = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let cp = complete::CompleteParams { step: r.step, reach: r.reach_steps, aperture_deg: r.aperture_deg, min_steps: 3.0, smooth_passes: 2, corner_zone: r.corner_radius };
    let curves = complete::complete(grown.into_iter().map(|g| complete::Curve::new(g.vertices, g.closed)).collect(), grouped, &cp);
    let curves = to_polylines(&curves, index.as_ref(), &normals, origin, r.step);
    counts.curves = curves.len() as u64;
    seconds.completion = t.elapsed().as_secs_f64();
    curves
}

/// `v` reordered by `perm` (consumed, so that the unordered copy is freed at once).
fn permute<T: Copy>(v: Vec<T>, perm: &[u32]) -> Vec<T> {
    perm.iter().map(|&i| v[i as usize]).collect()
}

/// With CREASE_DEBUG_DIR set, the curve stages write their intermediate point sets there as
/// OBJ files (candidates per tile, edge cloud, smoothed cloud, corners, grown polylines).
pub fn debug_dump(dir: &str, name: &str, pts: &[DVec3], origin: DVec3) {
    let text: String = pts.iter().map(|p| {
        let p = *p + origin;
        format!("v {} {} {}\n", p.x, p.y, p.z)
    }).collect();
    let _ = std::fs::write(std::path::Path::new(dir).join(name), text);
}

/// Stages 3 to 5 on a whole edge cloud held in memory, in any order.
pub fn curves_from_edges(mut edges: Vec<WorldEdge>, corners: Vec<WorldCorner>, r: &Resolved, counts: &mut Counts, seconds: &mut Timings) -> Vec<Polyline> {
    let q = snap_quantum(r.kappa);
    for e in edges.iter_mut() {
        snap_edge(e, q);
    }
    counts.edge_points = edges.len() as u64;
    counts.corner_points = corners.len() as u64;
    let origin = edges.iter().map(|e| e.p).reduce(DVec3::min).unwrap_or(DVec3::ZERO);
    let t = Instant::now();
    let grouped = group_corners(corners, origin, r);
    counts.corners = grouped.len() as u64;
    let normals: Vec<[glam::Vec3; 2]> = edges.iter().map(|e| e.n).collect();
    let local: Vec<DVec3> = edges.into_iter().map(|e| e.p - origin).collect();
    if let Ok(dir) = std::env::var("CREASE_DEBUG_DIR") {
        debug_dump(&dir, "edges.obj", &local, origin);
    }
    let (mut smoothed, mut kept_normals) = (Vec::new(), Vec::new());
    counts.unconfirmed = smooth_and_confirm(&local, &normals, local.len(), &grouped, r, &mut smoothed, &mut kept_normals);
    drop(local);
    seconds.smoothing = t.elapsed().as_secs_f64();
    curves_from_smoothed(smoothed, kept_normals, &grouped, origin, r, counts, seconds)
}

/// Extracts feature curves from `points` (world coordinates) held in memory: the whole cloud
/// is one tile.
pub fn extract(points: &[DVec3], params: &Params) -> Extraction {
    let t = Instant::now();
    let mut seconds = Timings::default();
    let mut counts = Counts { points: points.len() as u64, ..Default::default() };
    let gids: Vec<u64> = (0..points.len() as u64).collect();
    let full = Cloud::new(points);
    let seed = params.seed.unwrap_or(1);
    let kq = key_quantum(crate::cloud::Bounds::of(points.iter().copied()).diagonal());
    let mut buf = Vec::new();
    let stats: Vec<(f64, f64, f64)> = (0..full.len())
        .filter(|&i| stat_sample(position_key(full.at(i) + full.origin, kq), points.len() as u64, seed))
        .filter_map(|i| point_stats(&full, i, &mut buf))
        .collect();
    let mut r = resolve(params, &stats);
    if let Some(k) = params.kappa {
        r.kappa = k;
    }
    // Noisy clouds need neighbourhoods wider than the noise; thin them (by a hash of each
    // point's identity, so the choice is the same in any tile) to keep fits affordable.
    let cloud = if r.keep < 1.0 {
        let keep: Vec<usize> = (0..points.len()).filter(|&i| keep_point(position_key(points[i], kq), r.keep, r.seed)).collect();
        let kept: Vec<DVec3> = keep.iter().map(|&i| points[i]).collect();
        let kept_ids: Vec<u64> = keep.iter().map(|&i| gids[i]).collect();
        Cloud::gridded(&kept, &kept_ids, full.origin, r.cell_side(), true)
    } else {
        Cloud::gridded(points, &gids, full.origin, r.cell_side(), true)
    };
    // (The statistics' cloud, in Morton order with its tree, is not needed past here.)
    drop(full);
    seconds.index = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let all: Vec<u32> = (0..cloud.len() as u32).collect();
    let res = candidates::residuals(&cloud, &all, r.fit_radius, r.halo(), r.noise_limited());
    let tau = params.tau.unwrap_or_else(|| settle(candidates::ResidualSum::of(res.iter().copied()).mean()));
    let cand: Vec<u32> = all.iter().copied().filter(|&i| candidates::is_candidate(res[i as usize], tau)).collect();
    counts.candidates = cand.len() as u64;
    seconds.candidates = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let (edges, corners, one) = project_core(&cloud, &cand, &r);
    counts.one_surface = one;
    seconds.projection = t.elapsed().as_secs_f64();
    let curves = curves_from_edges(edges, corners, &r, &mut counts, &mut seconds);
    Extraction { curves, params: r, tau, counts, seconds }
}

/// True if point `id` belongs to the thinned cloud keeping share `keep`.
pub fn keep_point(id: u64, keep: f64, seed: u64) -> bool {
    if keep >= 1.0 {
        return true;
    }
    let mut r = crate::synth::rng::Rng::stream(seed ^ 0x7417, id);
    r.f64() < keep
}

/// Attaches normals (from the nearest edge points, orientation carried along each curve) and
/// converts to world coordinates.
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
                nn.sort_unstable_by_key(|a| a.0);
                let mut acc = [DVec3::ZERO; 2];
                let pair = |j: u32| edge_normals[j as usize].map(|v| v.as_dvec3());
                for &(j, _) in &nn {
                    let n = pair(j);
                    let reference = prev.unwrap_or(pair(nn[0].0));
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

#[cfg(test)]
mod tests {
    use super::settle;

    #[test]
    fn settled_values_forget_their_last_bits() {
        for x in [1.0f64, 0.007509334601371811, 0.0022075607504528335, 123456.789] {
            let up = f64::from_bits(x.to_bits() + 3);
            let down = f64::from_bits(x.to_bits() - 3);
            assert_eq!(settle(up), settle(x));
            assert_eq!(settle(down), settle(x));
            assert!((settle(x) - x).abs() <= x * 2f64.powi(-31));
        }
        assert_eq!(settle(0.0), 0.0);
    }
}
