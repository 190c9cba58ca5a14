//! The tile pass engine: every tile without a result goes through `load` then `compute`, in
//! order, and its result is stored atomically; and the loading of a tile with its halo.

use super::records::{self, Dropped, Record};
use crate::cancel::Cancel;
use crate::error::{Error, Result};
use crate::extract::neighbourhood::Cloud;
use crate::extract::statistics::tile_origin;
use crate::keys::{keep_point, position_key};
use crate::points::TilePoints;
use crate::progress::Progress;
use crate::salts;
use crate::tiles::{within, Grid, Store};
use crate::workspace::Workspace;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Seconds a tile pass spent loading tiles (reading the store, building the cloud: on the
/// loader thread, overlapping compute) and computing them.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PassTime {
    /// Loading.
    pub load: f64,
    /// Computing.
    pub compute: f64,
}

/// What a pass needs besides its two steps.
pub(crate) struct PassContext<'a> {
    /// The run's files.
    pub ws: &'a Workspace,
    /// Progress output.
    pub progress: &'a Progress,
    /// Stops the pass after the tile in hand.
    pub cancel: &'a Cancel,
}

/// Runs every tile of `tiles` without an `R` result through `load` then `compute`, in order,
/// storing each result atomically. A loader thread loads the next tile while the current one
/// computes (rayon, inside `compute`) and is written, so reading and building overlap the
/// fits; the rendezvous channel keeps at most two tiles in memory. Tiles are independent, so
/// an interrupted pass resumes with the first tile that has no result.
pub(crate) fn tile_pass<T: Send, R: Record>(
    cx: &PassContext,
    name: &str,
    tiles: &[u32],
    load: impl Fn(u32, bool) -> Result<T> + Sync,
    compute: impl Fn(u32, T) -> Result<R> + Sync,
) -> Result<PassTime> {
    cx.ws.create_dir(R::DIR)?;
    let todo: Vec<u32> = tiles.iter().copied().filter(|&t| !cx.ws.exists(&records::name(R::DIR, t))).collect();
    let bar = cx.progress.bar(name, tiles.len() as u64, "tiles");
    bar.inc((tiles.len() - todo.len()) as u64);
    let (tx, rx) = crossbeam_channel::bounded::<(u32, Result<T>)>(0);
    let (load, todo, cancel) = (&load, &todo, cx.cancel);
    let mut time = PassTime::default();
    time.load = std::thread::scope(|s| -> Result<f64> {
        // Owning the receiver here drops it on any early return, which unblocks the loader
        // (its send fails) before the scope joins it.
        let rx = rx;
        let loader = s.spawn(move || {
            let mut secs = 0.0;
            for (k, &t) in todo.iter().enumerate() {
                if cancel.is_set() {
                    break;
                }
                let t0 = Instant::now();
                // (The first tile is loaded while the pool waits for it; later ones while
                // the pool computes the tile before.)
                let x = load(t, k == 0);
                secs += t0.elapsed().as_secs_f64();
                if tx.send((t, x)).is_err() {
                    break;
                }
            }
            secs
        });
        for (t, x) in rx.iter() {
            let t0 = Instant::now();
            let out = compute(t, x?)?;
            time.compute += t0.elapsed().as_secs_f64();
            // (Checked before the result is stored: a computation cancelled part way gives
            // placeholders for the work it skipped.)
            cancel.check()?;
            records::write(cx.ws, t, &out)?;
            bar.inc(1);
        }
        // (A loader that panicked ended the loop early: its tiles have no result.)
        loader.join().map_err(|p| Error::panic("tile loader", p))
    })?;
    cx.cancel.check()?;
    bar.finish();
    Ok(time)
}

/// How a tile is loaded: its halo, and the thinning of noisy clouds by position key.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Loading<'a> {
    /// Halo width.
    pub halo: f64,
    /// Share of points kept (1: all).
    pub keep: f64,
    /// Share of the kept core points flagged for evaluation (1: all; see
    /// [`Resolved::evaluate`](crate::extract::Resolved::evaluate)).
    pub evaluate: f64,
    /// Seed of the thinning.
    pub seed: u64,
    /// Quantum of the position keys.
    pub key_quantum: f64,
    /// Points bucketed into each tile: a tile's store must hold them all.
    pub counts: &'a [u64],
    /// Radius over which each kept point is averaged when the cloud is thinned (0: none; see
    /// [`Resolved::average`](crate::extract::Resolved::average)).
    pub average: f64,
    /// Share of the points the averaging takes (see
    /// [`Resolved::average_share`](crate::extract::Resolved::average_share)).
    pub average_share: f64,
    /// Radius within which near duplicates are collapsed (0: exact copies only; see
    /// [`Resolved::near`](crate::extract::Resolved::near)).
    pub near: f64,
}

/// Loads tile `t`'s core and the halo around it (thinned to share `keep` by position key, each
/// point kept averaged over the share `average_share` of the points in the ball of radius
/// `average` around it if that is not 0); the flags say which points are core points to
/// evaluate (the share `evaluate` of the core's, by another draw from the position key). The
/// averaging runs on the rayon pool: on a cloud thinned to a few percent, loading a tile can
/// take as long as the fits of the tile before it.
pub(crate) fn load(store: Store, grid: &Grid, t: u32, l: &Loading) -> Result<(TilePoints, Vec<bool>)> {
    load_counted(store, grid, t, l).map(|(tile, _)| tile)
}

/// As [`load`], also counting the tile's own points dropped as copies.
pub(crate) fn load_counted(store: Store, grid: &Grid, t: u32, l: &Loading) -> Result<((TilePoints, Vec<bool>), Dropped)> {
    let core = grid.core(t);
    let (halo, keep) = (l.halo, l.keep);
    let averaged = l.average > 0.0 && keep < 1.0;
    // The points within `average` of a point of the halo are read too.
    let reach = if averaged { halo + l.average } else { halo };
    // (The store's reads stop between frames once a cancel is set; the steps after them are
    // checked between, a few hundredths of a second each on a tile of a million points.)
    let (mut tp, own) = read_tile(store, grid, t, l, reach)?;
    let before = own.len() as u64;
    let own = drop_duplicates(&mut tp, own);
    store.check()?;
    let exact = before - own.len() as u64;
    let own = if l.near > 0.0 { drop_near(&mut tp, own, l.near, |p| within(&core, reach, p)) } else { own };
    store.check()?;
    let dropped = Dropped { exact, near: before - exact - own.len() as u64 };
    let flagged = flagged(tp, own, &core, l, store);
    store.check()?;
    Ok((flagged, dropped))
}

/// Reads tile `t`'s own points and those of the tiles around within `reach` of its core
/// (and the near-duplicate radius further: whether a point is a near copy depends on the
/// points around it), as `l` thins them. Returns where the own points are.
fn read_tile(store: Store, grid: &Grid, t: u32, l: &Loading, reach: f64) -> Result<(TilePoints, std::ops::Range<usize>)> {
    let core = grid.core(t);
    let keep = l.keep;
    let averaged = l.average > 0.0 && keep < 1.0;
    let reach = reach + l.near;
    let kept = |key| keep >= 1.0 || keep_point(key, keep, l.seed);
    // (A key of its own, so that the points averaged over do not follow those kept.)
    let member = |key: u64| averaged && (l.average_share >= 1.0 || keep_point(key ^ salts::AVERAGED, l.average_share, l.seed));
    // (An unthinned cloud reads every point without hashing its position.)
    let read = |p| {
        keep >= 1.0 || {
            let key = position_key(p, l.key_quantum);
            kept(key) || member(key)
        }
    };
    let mut tp = TilePoints::default();
    let mut own = 0..0;
    for n in grid.around(t, reach) {
        let before = tp.xyz.len();
        if n == t {
            let held = store.read(n, &mut tp, |p, _| read(p))?;
            let bucketed = l.counts.get(t as usize).copied().unwrap_or(0);
            if held != bucketed {
                // (A deleted or truncated tile file once dropped its points without a word.)
                return Err(Error::damaged(store.path(t), format!("holds {held} of the {bucketed} points bucketed into it")));
            }
            own = before..tp.xyz.len();
        } else {
            store.read_near(n, Some((&core, reach)), &mut tp, |p, _| within(&core, reach, p) && read(p))?;
        }
    }
    Ok((tp, own))
}

/// The loaded tile `tp` with its core flags (its own points `own`, drawn for evaluation), the
/// kept points averaged over balls if the loading averages (see [`load`]); once `store`'s
/// cancel is set, the means not taken yet are left out (the caller checks it after).
fn flagged(tp: TilePoints, own: std::ops::Range<usize>, core: &crate::points::Bounds, l: &Loading, store: Store) -> (TilePoints, Vec<bool>) {
    let (halo, keep) = (l.halo, l.keep);
    let averaged = l.average > 0.0 && keep < 1.0;
    let kept = |key| keep >= 1.0 || keep_point(key, keep, l.seed);
    let member = |key: u64| averaged && (l.average_share >= 1.0 || keep_point(key ^ salts::AVERAGED, l.average_share, l.seed));
    let is_core = |k: usize, p: DVec3| {
        // (A key of its own, so that which points are evaluated does not follow which are kept.)
        own.contains(&k) && (l.evaluate >= 1.0 || keep_point(position_key(p, l.key_quantum) ^ salts::EVALUATED, l.evaluate, l.seed))
    };
    if !averaged {
        let flags = tp.xyz.iter().enumerate().map(|(k, &p)| is_core(k, p)).collect();
        return (tp, flags);
    }
    let keys: Vec<u64> = tp.xyz.par_iter().map(|&p| position_key(p, l.key_quantum)).collect();
    let chosen: Vec<usize> = (0..tp.xyz.len()).filter(|&k| (own.contains(&k) || within(core, halo, tp.xyz[k])) && kept(keys[k])).collect();
    let members: Vec<DVec3> = tp.xyz.iter().zip(&keys).filter(|&(_, &key)| member(key)).map(|(&p, _)| p).collect();
    let balls = Balls::new(&members, l.average, l.key_quantum);
    // (Taken cell by cell, so that neighbouring balls search the same runs of cells while
    // they are in the cache.)
    let mut by_cell: Vec<(u128, usize)> = chosen.iter().enumerate().map(|(n, &k)| (Balls::key(Balls::cell(tp.xyz[k], l.average), balls.base), n)).collect();
    by_cell.par_sort_unstable();
    // (In runs of a few thousand, between which a cancel is seen: on a cloud thinned to a few
    // percent, a ball holds hundreds of points.)
    let (balls, xyz, chosen) = (&balls, &tp.xyz, &chosen);
    let means: Vec<DVec3> = by_cell
        .par_chunks(4096)
        .flat_map_iter(|run| {
            let go = !store.cancelled();
            run.iter().map(move |&(_, n)| if go { balls.mean_around(xyz[chosen[n]]) } else { DVec3::ZERO })
        })
        .collect();
    let mut xyz = vec![DVec3::ZERO; chosen.len()];
    for (&(_, n), m) in by_cell.iter().zip(means) {
        xyz[n] = m;
    }
    let out = TilePoints { xyz, gid: chosen.iter().map(|&k| tp.gid[k]).collect() };
    let flags = chosen.iter().map(|&k| is_core(k, tp.xyz[k])).collect();
    (out, flags)
}

/// Drops every point of `tp` at the very position of another with a smaller global id (scans
/// that overlap, tiles merged twice): a copy adds nothing to a fit but weight, and ten copies
/// of every point made the spacing, measured from the 16th neighbour, a third of the true one.
/// Every copy of a point lies in the tiles that read any of them, so each keeps the same one.
/// Returns where the tile's own points, `own` before, now are.
pub(super) fn drop_duplicates(tp: &mut TilePoints, own: std::ops::Range<usize>) -> std::ops::Range<usize> {
    // (0.0 added: -0.0 and 0.0 are the same position.)
    let bits = |p: DVec3| crate::keys::bits_key(p + DVec3::ZERO);
    // (Most clouds hold no copy: a sort of one hash a point tells, at a fraction of the cost of
    // sorting the positions. Equal hashes are then checked position by position.)
    let mut hashes: Vec<u64> = tp
        .xyz
        .par_iter()
        .map(|&p| {
            let [x, y, z] = bits(p);
            // (The golden ratio and two of xxHash64's primes: odd multipliers with well-mixed
            // bits, so that nearby positions hash far apart.)
            let h = x.wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ y.rotate_left(21).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
                ^ z.rotate_left(42).wrapping_mul(0x1656_67B1_9E37_79F9);
            h ^ (h >> 29)
        })
        .collect();
    hashes.par_sort_unstable();
    if !hashes.windows(2).any(|w| w[0] == w[1]) {
        return own;
    }
    drop(hashes);
    let mut order: Vec<([u64; 3], u64, u32)> = tp.xyz.par_iter().zip(&tp.gid).enumerate().map(|(k, (&p, &g))| (bits(p), g, k as u32)).collect();
    order.par_sort_unstable();
    let copy: Vec<u32> = order.windows(2).filter(|w| w[0].0 == w[1].0).map(|w| w[1].2).collect();
    if copy.is_empty() {
        return own;
    }
    let mut keep = vec![true; tp.xyz.len()];
    for k in copy {
        keep[k as usize] = false;
    }
    retain_kept(tp, &keep, own)
}

/// Drops every point of `tp` within `radius` of another with a smaller global id (copies
/// that went through a transform or another scale; see [`Loading::near`]), then the points
/// that are neither the tile's own (`own`) nor `inside` the loaded reach: those were read only
/// so that every point inside has all the points within `radius` of it, and is decided the
/// same way by every tile that reads it. Returns where the own points now are.
fn drop_near(tp: &mut TilePoints, own: std::ops::Range<usize>, radius: f64, inside: impl Fn(DVec3) -> bool + Sync) -> std::ops::Range<usize> {
    // (Cells of half the radius: any two points in one cell are within it, and its points
    // lie within two cells of each other along every axis.)
    let side = 0.5 * radius;
    let cell = |p: DVec3| {
        let c = (p / side).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    };
    let mut order: Vec<([i64; 3], u64, u32)> = tp.xyz.par_iter().zip(&tp.gid).enumerate().map(|(k, (&p, &g))| (cell(p), g, k as u32)).collect();
    order.par_sort_unstable();
    // Each cell's run of points, in global id order.
    let mut runs: std::collections::HashMap<[i64; 3], (usize, usize)> = std::collections::HashMap::new();
    for (n, o) in order.iter().enumerate() {
        runs.entry(o.0).or_insert((n, n)).1 = n + 1;
    }
    let (xyz, r2) = (&tp.xyz, radius * radius);
    // A cell's first point is dropped if a point of a cell around with a smaller id is near;
    // the cell's other points, by the first.
    let near_first = |&(start, _): &(usize, usize)| {
        let (c, g, k) = order[start];
        let p = xyz[k as usize];
        let around = (0..125).map(|d: i64| [c[0] + d % 5 - 2, c[1] + d / 5 % 5 - 2, c[2] + d / 25 - 2]).filter_map(|n| runs.get(&n));
        // (Runs are in id order: only their points of smaller id are looked at.)
        around.flat_map(|&(a, b)| order[a..b].iter().take_while(|o| o.1 < g)).any(|o| xyz[o.2 as usize].distance_squared(p) <= r2)
    };
    let cells: Vec<(usize, usize)> = runs.values().copied().collect();
    let dropped_first: Vec<bool> = cells.par_iter().map(near_first).collect();
    let mut keep = vec![true; xyz.len()];
    for (&(start, end), &gone) in cells.iter().zip(&dropped_first) {
        for o in &order[start + usize::from(!gone)..end] {
            keep[o.2 as usize] = false;
        }
    }
    for (k, p) in xyz.iter().enumerate() {
        keep[k] &= own.contains(&k) || inside(*p);
    }
    retain_kept(tp, &keep, own)
}

/// Keeps the points of `tp` that `keep` flags, in order; returns where the tile's own points,
/// `own` before, now are.
fn retain_kept(tp: &mut TilePoints, keep: &[bool], own: std::ops::Range<usize>) -> std::ops::Range<usize> {
    let before = |end: usize| keep[..end].iter().filter(|&&k| k).count();
    let own = before(own.start)..before(own.end);
    let mut k = 0;
    tp.xyz.retain(|_| (keep[k], k += 1).0);
    k = 0;
    tp.gid.retain(|_| (keep[k], k += 1).0);
    own
}

/// Means of the points within a radius of a position, the same to the bit whichever tile
/// computes them: the points are found by their world positions and summed as integers (in
/// quanta of the position keys), so neither a tile's origin nor the order of its points
/// enters.
struct Balls {
    radius: f64,
    quantum: f64,
    /// The grid cell (side `radius`) of the first point, the origin of the cell keys.
    base: [i64; 3],
    /// The points' cell keys (see [`Balls::key`]) in increasing order, so that a ball's
    /// points lie in nine runs of three cells; with each point's position and its position in
    /// quanta, in the same order (read in runs: a ball takes hundreds of points when the
    /// cloud is thinned to a few percent).
    keys: Vec<u128>,
    xyz: Vec<DVec3>,
    quanta: Vec<[i64; 3]>,
}

/// Bits of a cell key per axis: cells relative to the base, offset so that every cell of a
/// tile's points and their neighbours is positive.
const KEY_BITS: u32 = 42;
const KEY_OFFSET: i64 = 1 << (KEY_BITS - 1);

impl Balls {
    fn new(xyz: &[DVec3], radius: f64, quantum: f64) -> Balls {
        let base = xyz.first().map_or([0; 3], |&p| Self::cell(p, radius));
        let mut order: Vec<(u128, u32)> = xyz.par_iter().enumerate().map(|(k, &p)| (Self::key(Self::cell(p, radius), base), k as u32)).collect();
        order.par_sort_unstable();
        let xyz: Vec<DVec3> = order.par_iter().map(|&(_, k)| xyz[k as usize]).collect();
        let quanta = xyz
            .par_iter()
            .map(|&p| {
                let v = (p / quantum).round();
                [v.x as i64, v.y as i64, v.z as i64]
            })
            .collect();
        Balls { radius, quantum, base, keys: order.into_iter().map(|(c, _)| c).collect(), xyz, quanta }
    }

    fn cell(p: DVec3, radius: f64) -> [i64; 3] {
        let c = (p / radius).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    }

    /// The sorting key of cell `c`: z, then y, then x, each relative to `base`. (A tile spans
    /// far fewer than 2^41 cells of a noise-sized radius.)
    fn key(c: [i64; 3], base: [i64; 3]) -> u128 {
        let axis = |a: usize| (c[a] - base[a] + KEY_OFFSET) as u128;
        (axis(2) << (2 * KEY_BITS)) | (axis(1) << KEY_BITS) | axis(0)
    }

    /// The mean of the points within the radius of `p` (`p` if there are none).
    fn mean_around(&self, p: DVec3) -> DVec3 {
        let c = Self::cell(p, self.radius);
        let r2 = self.radius * self.radius;
        let (mut sum, mut count) = ([0i128; 3], 0i128);
        for dz in -1..=1 {
            for dy in -1..=1 {
                let row = |dx: i64| Self::key([c[0] + dx, c[1] + dy, c[2] + dz], self.base);
                let lo = self.keys.partition_point(|&k| k < row(-1));
                let hi = lo + self.keys[lo..].partition_point(|&k| k <= row(1));
                for (o, v) in self.xyz[lo..hi].iter().zip(&self.quanta[lo..hi]) {
                    if o.distance_squared(p) <= r2 {
                        sum[0] += v[0] as i128;
                        sum[1] += v[1] as i128;
                        sum[2] += v[2] as i128;
                        count += 1;
                    }
                }
            }
        }
        if count == 0 {
            return p;
        }
        let mean = |s: i128| (s.div_euclid(count) as f64 + s.rem_euclid(count) as f64 / count as f64) * self.quantum;
        DVec3::new(mean(sum[0]), mean(sum[1]), mean(sum[2]))
    }
}

/// How the residual and projection passes load a tile as a cloud: from `store` over `grid`,
/// as `loading` says, gridded in cells of side `cell_side`, its queries stopped by `cancel`.
pub(crate) struct CloudLoading<'a> {
    /// The tile store.
    pub store: Store<'a>,
    /// The tile grid.
    pub grid: &'a Grid,
    /// The halo and thinning.
    pub loading: Loading<'a>,
    /// Side of the cloud's grid cells.
    pub cell_side: f64,
    /// Stops the cloud's queries.
    pub cancel: &'a Cancel,
}

impl CloudLoading<'_> {
    /// Loads tile `t` with its halo (see [`load`]) and stores it by grid cells, on the rayon
    /// pool if `idle` says that the pool has nothing else to do (the same cloud either way).
    pub(crate) fn load(&self, t: u32, idle: bool) -> Result<(Cloud, Vec<bool>)> {
        let (tp, core) = load(self.store, self.grid, t, &self.loading)?;
        let origin = tile_origin(&tp);
        let cloud = Cloud::gridded(&tp.xyz, &tp.gid, origin, self.cell_side, idle).cancelled_by(self.cancel);
        self.cancel.check()?;
        Ok((cloud, core))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A noisy plane's points averaged over balls of twice the noise deviation lie closer to
    /// the plane than the points do (less so than the count of points in a ball would say: a
    /// ball narrower than the noise's spread leans towards its own point's side), and each
    /// mean is the same to the bit whatever the order of the points.
    #[test]
    fn ball_means_narrow_the_noise_and_ignore_the_order() {
        let mut rng = Rng::stream(5, 0);
        let sigma = 0.05;
        let mut xyz: Vec<DVec3> = (0..40_000).map(|_| DVec3::new(4.0 * rng.f64(), 4.0 * rng.f64(), sigma * 3f64.sqrt() * (2.0 * rng.f64() - 1.0))).collect();
        let balls = Balls::new(&xyz, 2.0 * sigma, 1e-9);
        let at: Vec<DVec3> = xyz.iter().copied().filter(|p| p.x > 1.0 && p.x < 3.0 && p.y > 1.0 && p.y < 3.0).take(500).collect();
        let means: Vec<DVec3> = at.iter().map(|&p| balls.mean_around(p)).collect();
        let rms = |v: &[DVec3]| (v.iter().map(|p| p.z * p.z).sum::<f64>() / v.len() as f64).sqrt();
        assert!(rms(&means) < 0.75 * rms(&at), "{} vs {}", rms(&means), rms(&at));
        xyz.reverse();
        let reversed = Balls::new(&xyz, 2.0 * sigma, 1e-9);
        for (&p, &m) in at.iter().zip(&means) {
            assert_eq!(reversed.mean_around(p), m);
        }
    }
}
