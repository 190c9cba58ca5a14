//! The statistics pass: spacing, noise and density at a sample of points, from which every
//! length default is resolved (see [`super::params::resolve`]).
//!
//! A sample is chosen by position key, so it is the same in any tiling; each sampled point's
//! spacing comes from its 16th neighbour, its noise from the RMS residual of a quadric fitted
//! within 16 of those spacings (outliers dropped) or, where that is less than five of the
//! noise's deviations, within five deviations, its density from the count in the 16-spacing
//! ball.

use super::fit::{self, Pca};
use super::neighbourhood::{Cloud, Thinned};
use crate::keys::{keep_point, position_key};
use crate::points::{Bounds, TilePoints};
use crate::tiles::within;
use glam::{DVec3, I64Vec3};
use rayon::prelude::*;

/// About this many points of a cloud are sampled (by position key).
pub(crate) const STAT_SAMPLES: f64 = 20_000.0;

/// How much wider than its first halo the statistics pass may reload a tile (see
/// [`tile_statistics`]): wide enough for the noise ball of a dense noisy cloud (5 deviations
/// of 0.02 dB noise on 10 M points of fandisk: about 230 spacings, against the first halo's
/// 24). Samples whose neighbourhood is wider still (isolated points) keep what the widest
/// halo holds.
pub(crate) const STATS_HALO_GROWTH: f64 = 16.0;
/// The widest halo, in first halos, that later tiles are first loaded with because earlier
/// ones asked for it (see [`tile_statistics`]): enough for the noise balls of 10 M points of
/// fandisk at 0.01 dB (3-3.4), and bounded so that a cloud whose sparse patches ask for the
/// widest halo does not have every tile held that wide, two at a time (the one computed and
/// the one loaded meanwhile). A tile that needs more is loaded again, as before.
pub(crate) const STATS_HALO_HINT: f64 = 4.0;

/// What one sampled point says about the cloud.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PointStats {
    /// Spacing (median nearest-neighbour distance, from the 16th neighbour).
    pub spacing: f64,
    /// Noise: RMS residual about a quadric within 16 spacings, or [`NOISE_BALL`] deviations.
    pub noise: f64,
    /// Points per unit area within 16 spacings.
    pub density: f64,
    /// True if another point lies within [`NEAR_DUPLICATE`] of this spacing: a near duplicate
    /// (see [`near_duplicate_radius`]).
    pub twin: bool,
}

/// Points closer than this share of the spacing to another are near duplicates (copies that
/// went through a transform or another scale): two independent samples of a surface come
/// that close about once in 1.4 M points (a share of ln 2 times its square), so collapsing
/// them leaves clean scans as they were, while rounded copies lie far closer than that.
pub(crate) const NEAR_DUPLICATE: f64 = 1e-3;

/// Share of the statistics samples with a near duplicate (see [`PointStats::twin`]) above
/// which the cloud's near duplicates are collapsed: a thousand times what independent samples
/// give (see [`NEAR_DUPLICATE`]), and a tenth of a percent of the samples is enough to bias
/// the spacing measured from the 16th neighbour.
pub(crate) const TWIN_SHARE: f64 = 1e-3;

/// The radius within which near duplicates are collapsed, from statistics measured with them
/// in: [`NEAR_DUPLICATE`] times the median spacing, or None if too few samples have a twin.
/// (The spacing measured over copies is short by up to the square root of their count, so
/// the radius is too; copies still lie far within it.)
pub(crate) fn near_duplicate_radius(stats: &[PointStats]) -> Option<f64> {
    let twins = stats.iter().filter(|s| s.twin).count();
    if twins < 3 || (twins as f64) < TWIN_SHARE * stats.len() as f64 {
        return None;
    }
    let mut k: Vec<f64> = stats.iter().map(|s| s.spacing).collect();
    let h = NEAR_DUPLICATE * median(&mut k);
    (h > 0.0 && h.is_finite()).then_some(h)
}

/// True if the point with key `key` is one of the statistics sample in a cloud of `total`
/// points.
pub(crate) fn stat_sample(key: u64, total: u64, seed: u64) -> bool {
    keep_point(key ^ crate::salts::STATISTICS_SAMPLE, STAT_SAMPLES / total.max(1) as f64, seed)
}

/// The noise is measured over a ball at least this many of its deviations wide (see
/// [`point_stats`]). Within 16 spacings alone, the ball of a dense cloud spans too little of
/// the noise, and the quadric follows part of it: the estimate then falls as the density
/// rises, and every length resolved from it with it (fandisk under uniform noise of 0.01 dB, a
/// deviation of 0.0121 across the surface: 0.0109 on 500 k points, 0.0065 on 10 M). A wider
/// ball takes in more of the surface's curvature (8 deviations: 0.0279 at 0.02 dB, whose
/// deviation is 0.0242).
pub(crate) const NOISE_BALL: f64 = 5.0;
/// Most points a noise fit takes: an even subsample of a 16-spacing ball that holds more, and
/// a uniform one of a wider ball (its points of smallest hash, see [`Thinned`]).
const NOISE_FIT_POINTS: usize = 128;

/// Neighbourhood statistics of one sampled point: its spacing (from the 16th neighbour, see
/// [`crate::spacing::spacing`]) and the RMS residual of a quadric fitted within 16 of those
/// spacings, or within [`NOISE_BALL`] deviations if the deviation so measured asks for a
/// wider ball (the noise; the ball grows up to twice), whose points `thinned()` subsamples
/// (asked for only then). Also returns the widest radius read.
pub(crate) fn point_stats<'t, 'c: 't>(cloud: &Cloud, thinned: impl Fn() -> &'t Thinned<'c>, i: usize, buf: &mut Vec<(u32, f32)>) -> Option<(PointStats, f64)> {
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
    // (Exact copies were dropped as the tile was loaded: the point itself is the one at 0.)
    let nearest = buf.iter().filter(|b| b.0 as usize != i).map(|b| cloud.at(b.0 as usize).distance_squared(q)).fold(f64::INFINITY, f64::min);
    // The K nearest neighbours (and the point) seed the surface that the noise is measured about.
    // (Points tied with the K-th, common on quantised coordinates, all belong: compared with a
    // margin far above the rounding of the tile's local coordinates, so that each tile takes
    // the same. In global id order, so that the seed plane's sums are the same in any tile.)
    let within = rk * rk * (1.0 + 1e-9);
    let mut near: Vec<(u64, DVec3)> =
        buf.iter().map(|b| (cloud.gid[b.0 as usize], cloud.at(b.0 as usize))).filter(|p| p.1.distance_squared(q) <= within).collect();
    near.sort_unstable_by_key(|p| p.0);
    let seed: Vec<DVec3> = near.into_iter().map(|p| p.1).collect();
    let kappa = rk * (2f64.ln() / K as f64).sqrt();
    // Points per unit area around this point, from the count in the 16-kappa ball.
    let density = cloud.count_within(q, 16.0 * kappa, buf) as f64 / (std::f64::consts::PI * (16.0 * kappa).powi(2));
    // A wider ball is centred on the surface fitted before, below or above the point: one
    // centred on a point that noise moved off the surface holds more of the noise on the
    // point's side than on the other, and measured 0.85 of a plane's noise at 5 deviations.
    let (mut centre, mut radius, mut reach) = (q, 16.0 * kappa, 16.0 * kappa);
    let mut noise = 0.0;
    for round in 0..3 {
        if round == 0 {
            cloud.neighbours(centre, radius, 0, NOISE_FIT_POINTS, buf);
        } else {
            thinned().neighbours(centre, radius, NOISE_FIT_POINTS, buf);
            reach = reach.max(centre.distance(q) + radius);
        }
        if buf.len() < 10 {
            break;
        }
        // (A wider ball that cannot be fitted leaves the narrower one's noise.)
        let Some((rms, foot)) = noise_within(cloud, buf, &seed, q, kappa) else {
            if round == 0 {
                return None;
            }
            break;
        };
        noise = rms;
        if NOISE_BALL * noise <= radius || round == 2 {
            break;
        }
        (centre, radius) = (foot, NOISE_BALL * noise);
    }
    let twin = nearest < (NEAR_DUPLICATE * kappa).powi(2);
    Some((PointStats { spacing: kappa, noise, density, twin }, reach))
}

/// The RMS residual of the points `buf` about the surface that `q` lies on, and the foot of
/// `q` on it. A second surface in the ball (a thin plate's far face, the wall beside a floor)
/// is not noise, and a quadric fitted through both measures their distance instead; so the fit
/// starts from the better of two planes by least quantile of squares, that of the whole ball
/// and that of `seed`, the points nearest to `q` (on `q`'s own surface wherever the other is
/// farther than they reach, about five spacings), and is then fitted as a quadric to the points
/// within three robust deviations of it until they no longer change.
fn noise_within(cloud: &Cloud, buf: &[(u32, f32)], seed: &[DVec3], q: DVec3, kappa: f64) -> Option<(f64, DVec3)> {
    let pts: Vec<DVec3> = buf.iter().map(|&(j, _)| cloud.at(j as usize)).collect();
    let lower_quartile = |quad: &fit::Quadric| {
        let mut r: Vec<f64> = pts.iter().map(|&p| quad.value(p).abs()).collect();
        quantile(&mut r, 0.25)
    };
    let plane = |set: &[DVec3]| Pca::of(set.iter().map(|&p| (p, 1.0))).map(|c| fit::Quadric::plane(fit::Frame::new(c.mean, c.normal())));
    let whole = plane(&pts);
    let (mut quad, quartile) = [whole, plane(seed), whole.and_then(|w| densest_band(&pts, w))]
        .into_iter()
        .flatten()
        .map(|s| (s, lower_quartile(&s)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    // (The lower quartile of |x| for a normal deviate x is 0.3186 of its deviation.)
    let mut limit = 3.0 * quartile / 0.3186;
    let mut members: Vec<DVec3> = Vec::new();
    for _ in 0..NOISE_FIT_ROUNDS {
        let next: Vec<DVec3> = pts.iter().copied().filter(|&p| quad.value(p).abs() <= limit).collect();
        if next.len() < 10 {
            return Some((0.0, q));
        }
        if next == members {
            break;
        }
        members = next;
        let pca = Pca::of(members.iter().map(|&p| (p, 1.0)))?;
        quad = fit::Quadric::fit(fit::Frame::new(pca.mean, pca.normal()), members.iter().map(|&p| (p, 1.0)), 1e-6)?;
        let mut own: Vec<f64> = members.iter().map(|&p| quad.value(p).abs()).collect();
        limit = 3.0 * 1.4826 * median(&mut own);
        // (A surface fitted to rounding, as a clean cloud's are, has no noise to narrow in on.)
        if limit < kappa * CLEAN {
            break;
        }
    }
    let rms = (members.iter().map(|&p| quad.value(p).powi(2)).sum::<f64>() / members.len() as f64).sqrt();
    Some((rms, q - quad.value(q) * quad.frame.n))
}

/// The plane parallel to `plane` through the narrowest band that holds a quarter of `pts`
/// (least quantile of squares along the plane's normal). Where a thin plate's two faces share
/// the ball, the plane of the whole ball lies between them and that of the nearest points
/// tilts with the noise; the densest band lies on one face, however close the other, as long
/// as the faces are farther apart than the band is wide.
fn densest_band(pts: &[DVec3], plane: fit::Quadric) -> Option<fit::Quadric> {
    let mut h: Vec<f64> = pts.iter().map(|&p| plane.value(p)).collect();
    h.sort_unstable_by(f64::total_cmp);
    let k = h.len() / 4;
    if k < 2 {
        return None;
    }
    let lo = (0..h.len() - k).min_by(|&a, &b| (h[a + k] - h[a]).total_cmp(&(h[b + k] - h[b])))?;
    let shift = 0.5 * (h[lo] + h[lo + k]);
    let f = plane.frame;
    Some(fit::Quadric::plane(fit::Frame::new(f.o + shift * f.n, f.n)))
}

/// Residuals below this share of the spacing are rounding, not noise: a noise fit stops there,
/// and [`super::params::resolve`] takes such a noise for 0.
pub(crate) const CLEAN: f64 = 1.0 / (1u64 << 26) as f64;

/// Most rounds of a noise fit's re-selection of its surface's points (see [`noise_within`]).
const NOISE_FIT_ROUNDS: usize = 5;

pub(crate) fn median(v: &mut [f64]) -> f64 {
    quantile(v, 0.5)
}

/// The value below which the share `q` of `v` lies (an element of `v`; 0 if empty).
pub(crate) fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let m = ((v.len() as f64 * q) as usize).min(v.len() - 1);
    *v.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1
}

/// A tile as the statistics pass sees it: the core box, the first halo, the position key
/// quantum, the cloud's point count, the seed of the sampling, and what stops it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct StatsTile<'a> {
    /// The tile's core.
    pub core: Bounds,
    /// The halo the tile was first loaded with.
    pub halo: f64,
    /// Quantum of the position keys (see `keys::key_quantum`).
    pub key_quantum: f64,
    /// Points in the whole cloud.
    pub total: u64,
    /// Sampling seed.
    pub seed: u64,
    /// Stops the tile's samples part way (a tile of a dense cloud takes seconds).
    pub cancel: &'a crate::cancel::Cancel,
}

/// Statistics of the sampled points in a tile's core, in global id order, given the tile
/// `first` loaded with halo `loaded`, at least `tile.halo` (with core flags); `reload(halo)`
/// loads it again with a wider halo. Also returns the widest halo that the samples' noise
/// balls asked for (at most [`STATS_HALO_HINT`] times `tile.halo`; `loaded` if none asked for
/// more), with which the next tiles may be first loaded: the statistics do not depend on the
/// halo a tile is loaded with, only the work does.
///
/// A sample's neighbourhood is 16 of its own spacings wide, or wider under noise (see
/// [`NOISE_BALL`]), so it can reach past the halo, and then it would depend on where the tile
/// borders fall. Such samples are computed again with the tile reloaded with a halo wide
/// enough for them (up to [`STATS_HALO_GROWTH`] times `tile.halo`).
pub(crate) fn tile_statistics(
    first: (TilePoints, Vec<bool>),
    loaded: f64,
    tile: &StatsTile,
    mut reload: impl FnMut(f64) -> crate::Result<(TilePoints, Vec<bool>)>,
) -> crate::Result<(Vec<PointStats>, f64)> {
    let cap = STATS_HALO_GROWTH * tile.halo;
    let (mut tp, mut is_core) = first;
    let mut halo = loaded.max(tile.halo);
    let mut asked = halo;
    // Only the points within `reach` of a sample are indexed (None: all of them). A tile holds a
    // few hundred samples at 100 M points, and their neighbourhoods a fifth of the points or
    // less. A sample whose ball turns out wider is computed again with a wider reach.
    let mut reach = Some(halo);
    let mut todo: Option<Vec<u64>> = None;
    let mut done: Vec<(u64, PointStats)> = Vec::new();
    loop {
        let round = sample_round((&tp, &is_core), todo.as_deref(), reach, tile, halo, cap);
        // (A cancelled round skipped its samples: what it says is not to be used.)
        tile.cancel.check()?;
        done.extend(round.done);
        if round.again.is_empty() {
            break;
        }
        reach = if round.need.is_finite() { reach.map(|k| (1.01 * round.need).max(2.0 * k)) } else { None };
        // (Not the halo of samples too sparse to tell how far their neighbours lie: at most a
        // few isolated points, which would have every later tile loaded with the widest halo.)
        if round.need.is_finite() {
            asked = asked.max((1.01 * round.need).min(STATS_HALO_HINT * tile.halo));
        }
        if round.wider_halo {
            halo = (1.01 * round.need).max(2.0 * halo).min(cap);
            (tp, is_core) = reload(halo)?;
        }
        todo = Some(round.again);
    }
    done.sort_unstable_by_key(|d| d.0);
    Ok((done.into_iter().map(|d| d.1).collect(), asked))
}

/// What one round of [`tile_statistics`] settled, and what it left for a wider one.
struct Round {
    /// Samples whose statistics are final, by global id.
    done: Vec<(u64, PointStats)>,
    /// Samples to compute again, in global id order.
    again: Vec<u64>,
    /// The widest ball the samples left over need.
    need: f64,
    /// True if some of them need a wider halo.
    wider_halo: bool,
}

/// Computes the samples of the tile (those in `todo`, if given) with the points within `reach`
/// of a sample indexed (all of them for None), the tile being loaded with `halo`.
fn sample_round((tp, is_core): (&TilePoints, &[bool]), todo: Option<&[u64]>, reach: Option<f64>, tile: &StatsTile, halo: f64, cap: f64) -> Round {
    // (Sampled by world position, read from the store, not rebuilt from the tile's
    // local coordinates, whose round trip may not be exact.)
    let sampled: Vec<bool> = tp
        .xyz
        .par_iter()
        .zip(&tp.gid)
        .zip(is_core)
        .map(|((&p, g), &c)| c && stat_sample(position_key(p, tile.key_quantum), tile.total, tile.seed) && todo.is_none_or(|v| v.binary_search(g).is_ok()))
        .collect();
    // (The origin is the whole tile's, so the local coordinates are the same either way.)
    let origin = tile_origin(tp);
    let keep = reach.and_then(|r| near(&tp.xyz, &sampled, r));
    let (cloud, sampled) = match &keep {
        Some(keep) => {
            let xyz: Vec<DVec3> = keep.iter().map(|&i| tp.xyz[i]).collect();
            let gid: Vec<u64> = keep.iter().map(|&i| tp.gid[i]).collect();
            (Cloud::with_origin_parallel(&xyz, &gid, origin), keep.iter().map(|&i| sampled[i]).collect())
        }
        None => (Cloud::with_origin_parallel(&tp.xyz, &tp.gid, origin), sampled),
    };
    let kept = keep.as_ref().and(reach);
    // (The tree, on the pool, which would otherwise wait for it.)
    cloud.index();
    let sample: Vec<usize> = (0..cloud.len()).into_par_iter().filter(|&i| sampled[cloud.ids[i] as usize]).collect();
    cloud.prepare_ordering(sample.len());
    // (Built by the first sample whose noise ball is wider than 16 spacings: none on a clean
    // cloud. Serially, so that no rayon job runs inside the initialisation: a worker waiting
    // in it could otherwise pick up another sample that waits for the same cell.)
    let thinned = std::sync::OnceLock::new();
    let lazy = || thinned.get_or_init(|| Thinned::new(&cloud));
    let stats: Vec<Option<(PointStats, f64)>> =
        sample.par_iter().map_init(Vec::new, |buf, &i| if tile.cancel.is_set() { None } else { point_stats(&cloud, lazy, i, buf) }).collect();
    let mut round = Round { done: Vec::new(), again: Vec::new(), need: 0.0, wider_halo: false };
    for (&i, s) in sample.iter().zip(stats) {
        // The widest ball the statistics read (the 16-spacing ball, or the noise's), with the
        // margin of the tree query (unbounded if too few neighbours were found: more may lie
        // farther).
        let r = s.map_or(f64::INFINITY, |s| s.1 * (1.0 + 1e-4));
        // Whether it holds every point of the cloud: it lies within the points kept around
        // the sample, and within the loaded halo (else, up to the widest halo).
        let in_kept = kept.is_none_or(|k| r <= k);
        let in_halo = s.is_some() && within(&tile.core, halo - r, cloud.at(i) + cloud.origin);
        if in_kept && (in_halo || halo >= cap) {
            if let Some((s, _)) = s {
                round.done.push((cloud.gid[i], s));
            }
        } else {
            round.again.push(cloud.gid[i]);
            round.need = round.need.max(r);
            round.wider_halo |= !in_halo && halo < cap;
        }
    }
    round.again.sort_unstable();
    round
}

/// Local origin of a loaded tile: the minimum corner of its points (fits are computed in f64,
/// so the choice only moves the last bits).
pub(crate) fn tile_origin(tp: &TilePoints) -> DVec3 {
    tp.xyz.iter().copied().reduce(DVec3::min).unwrap_or(DVec3::ZERO)
}

/// Indices of the points of `xyz` within `radius` of a point flagged in `centre` (and of some
/// a little farther), in order; None (keep every point) if that is most of them anyway, or if
/// the grid of cells this takes would be too large.
fn near(xyz: &[DVec3], centre: &[bool], radius: f64) -> Option<Vec<usize>> {
    let lo = xyz.iter().copied().reduce(DVec3::min)?;
    let hi = xyz.iter().copied().reduce(DVec3::max)?;
    // Cells a little wider than the radius, so that rounding cannot put a point within the
    // radius of a centre two cells away from it: such points lie in the centre's cell or in
    // one of the 26 around it.
    let side = radius * 1.01;
    let dims = ((hi - lo) / side).floor().as_i64vec3() + 1;
    let cells = dims.x.checked_mul(dims.y).and_then(|c| c.checked_mul(dims.z)).filter(|&c| c > 0 && c <= 1 << 28)?;
    let cell = |p: DVec3| crate::grid::cell(p - lo, side).clamp(I64Vec3::ZERO, dims - 1);
    let index = |c: I64Vec3| (c.x + dims.x * (c.y + dims.y * c.z)) as usize;
    let mut marked = vec![false; cells as usize];
    for (&p, _) in xyz.iter().zip(centre).filter(|c| *c.1) {
        let c = cell(p);
        for d in (0..27).map(|k| I64Vec3::new(k % 3 - 1, k / 3 % 3 - 1, k / 9 - 1)) {
            let n = c + d;
            if n.cmpge(I64Vec3::ZERO).all() && n.cmplt(dims).all() {
                marked[index(n)] = true;
            }
        }
    }
    let keep: Vec<usize> = (0..xyz.len()).filter(|&i| marked[index(cell(xyz[i]))]).collect();
    (keep.len() * 4 < xyz.len() * 3).then_some(keep)
}

#[cfg(test)]
mod tests {
    use super::{median, near, point_stats, tile_statistics, StatsTile, NOISE_BALL};
    use crate::extract::neighbourhood::{Cloud, Thinned};
    use glam::DVec3;

    /// The median noise measured at points near the middle of a unit square of `n` points, each
    /// moved by noise uniform in a ball of radius `radius`, and the widest ball read.
    fn measured_noise(n: usize, radius: f64) -> (f64, f64) {
        let mut rng = crate::rng::Rng::stream(11, n as u64);
        let pts: Vec<DVec3> = (0..n).map(|_| DVec3::new(rng.f64(), rng.f64(), 0.0) + rng.in_ball(radius)).collect();
        let cloud = Cloud::new(&pts);
        let thinned = Thinned::new(&cloud);
        let mut buf = Vec::new();
        let middle: Vec<usize> = (0..cloud.len()).filter(|&i| (cloud.at(i) + cloud.origin - DVec3::new(0.5, 0.5, 0.0)).length() < 0.1).take(60).collect();
        let stats: Vec<(f64, f64)> = middle.iter().filter_map(|&i| point_stats(&cloud, || &thinned, i, &mut buf)).map(|(s, r)| (s.noise, r)).collect();
        let mut noise: Vec<f64> = stats.iter().map(|s| s.0).collect();
        (median(&mut noise), stats.iter().map(|s| s.1).fold(0.0, f64::max))
    }

    /// The noise measured on a sparse and on a dense sampling of the same noisy plane agree,
    /// and both come near the noise's deviation across the plane (radius / sqrt 5 for noise
    /// uniform in a ball): on the dense one, 16 spacings span about 1.6 deviations, and a
    /// quadric fitted within them followed the noise and measured about 0.6 of it.
    #[test]
    fn the_noise_measured_does_not_depend_on_the_density() {
        let radius = 0.05;
        let deviation = radius / 5f64.sqrt();
        let (sparse, _) = measured_noise(8_000, radius);
        let (dense, dense_reach) = measured_noise(160_000, radius);
        eprintln!("sparse {sparse}, dense {dense} (reach {dense_reach}), deviation {deviation}");
        for (name, noise) in [("sparse", sparse), ("dense", dense)] {
            assert!(noise > 0.85 * deviation && noise < 1.1 * deviation, "{name}: {noise} against a deviation of {deviation}");
        }
        assert!((dense - sparse).abs() < 0.1 * sparse, "dense {dense}, sparse {sparse}");
        // The dense cloud's ball was widened to the noise's, and the reach says so.
        assert!(dense_reach >= 0.9 * NOISE_BALL * deviation, "read {dense_reach}");
    }

    /// A thin plate's two faces within one noise ball: the noise measured is the faces' own,
    /// not half the plate's thickness (which, read as noise, widened every neighbourhood of a
    /// clean 1 mm plate until no edge was found), clean and with the faces' noise bands a
    /// little over a noise radius apart.
    #[test]
    fn a_second_surface_in_the_ball_is_not_noise() {
        // (A unit square's two faces 0.02 apart, about 8 spacings at 20 k points a face.)
        let (thickness, n) = (0.02, 20_000);
        for radius in [0.0, 0.002, 0.006] {
            let mut rng = crate::rng::Rng::stream(5, n as u64);
            let pts: Vec<DVec3> =
                (0..2 * n).map(|k| DVec3::new(rng.f64(), rng.f64(), if k % 2 == 0 { 0.0 } else { thickness }) + rng.in_ball(radius)).collect();
            let cloud = Cloud::new(&pts);
            let thinned = Thinned::new(&cloud);
            let mut buf = Vec::new();
            let middle: Vec<usize> =
                (0..cloud.len()).filter(|&i| ((cloud.at(i) + cloud.origin).truncate() - glam::DVec2::splat(0.5)).length() < 0.1).take(60).collect();
            let mut noise: Vec<f64> = middle.iter().filter_map(|&i| point_stats(&cloud, || &thinned, i, &mut buf)).map(|(s, _)| s.noise).collect();
            let measured = median(&mut noise);
            let deviation = radius / 5f64.sqrt();
            assert!(
                measured <= 1.1 * deviation + 1e-9 && measured >= 0.85 * deviation,
                "noise radius {radius}: measured {measured} against a deviation of {deviation}"
            );
        }
    }

    #[test]
    fn near_keeps_every_point_within_the_radius_of_a_centre_and_drops_far_ones() {
        let mut rng = crate::rng::Rng::stream(3, 0);
        // Points on a tilted plane 1 km from the origin, a few of them centres.
        let pts: Vec<DVec3> = (0..200_000)
            .map(|_| DVec3::new(1000.0 + 50.0 * rng.f64(), -700.0 + 50.0 * rng.f64(), 0.0))
            .map(|p| DVec3::new(p.x, p.y, 0.3 * p.x - 0.2 * p.y))
            .collect();
        let centre: Vec<bool> = (0..pts.len()).map(|i| i % 5000 == 17).collect();
        let radius = 0.7;
        let keep = near(&pts, &centre, radius).expect("a few centres keep a small share");
        assert!(keep.windows(2).all(|w| w[0] < w[1]), "in order");
        let centres: Vec<DVec3> = (0..pts.len()).filter(|&i| centre[i]).map(|i| pts[i]).collect();
        let dist = |p: DVec3| centres.iter().map(|c| c.distance(p)).fold(f64::INFINITY, f64::min);
        let kept: std::collections::HashSet<usize> = keep.iter().copied().collect();
        for (i, &p) in pts.iter().enumerate() {
            let d = dist(p);
            if d <= radius {
                assert!(kept.contains(&i), "point {i} at {d} from a centre was dropped");
            }
            // (Kept points lie in a centre's cell or a neighbouring one.)
            if kept.contains(&i) {
                assert!(d <= 2.0 * 1.01 * radius * 3f64.sqrt() + 1e-9, "point {i} at {d} was kept");
            }
        }
        assert!(keep.len() < pts.len() / 10);
        // Most of the points near: keep them all.
        let all: Vec<bool> = (0..pts.len()).map(|i| i % 50 == 0).collect();
        assert_eq!(near(&pts, &all, radius), None);
    }

    /// A cancel while a tile's samples are computed ends the tile within a small share of its
    /// time (the samples check the flag; the tile took as long as all of them before): here a
    /// noisy plane whose every statistics sample lies in one tile.
    #[test]
    fn a_cancel_during_a_tiles_statistics_returns_promptly() {
        let n = 300_000;
        let mut rng = crate::rng::Rng::stream(7, 0);
        let xyz: Vec<DVec3> = (0..n).map(|_| DVec3::new(rng.f64(), rng.f64(), 0.0) + rng.in_ball(0.01)).collect();
        let tp = crate::points::TilePoints { gid: (0..n as u64).collect(), xyz };
        let core = crate::points::Bounds { min: [-1.0; 3], max: [2.0; 3] };
        let cancel = crate::cancel::Cancel::default();
        let tile = StatsTile { core, halo: 0.05, key_quantum: 1e-9, total: n as u64, seed: 1, cancel: &cancel };
        let first = || (tp.clone(), vec![true; n]);
        let t = std::time::Instant::now();
        let (stats, _) = tile_statistics(first(), 0.05, &tile, |_| Ok(first())).unwrap();
        let whole = t.elapsed();
        assert!(stats.len() > 10_000, "{} samples", stats.len());
        let at = whole / 4;
        let took = std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(at);
                cancel.set();
            });
            let t = std::time::Instant::now();
            let out = tile_statistics(first(), 0.05, &tile, |_| Ok(first()));
            assert!(matches!(out, Err(crate::Error::Interrupted)), "not interrupted: {:?}", out.map(|s| s.0.len()));
            t.elapsed()
        });
        eprintln!("whole tile {whole:?}, cancelled at {at:?}, returned after {took:?}");
        assert!(took < at + whole / 4, "cancelled at {at:?}, returned after {took:?} (the whole tile takes {whole:?})");
    }
}
