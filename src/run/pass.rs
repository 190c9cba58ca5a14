//! The tile pass engine: every tile without a result goes through `load` then `compute`, in
//! order, and its result is stored atomically; and the loading of a tile with its halo.

use super::records::{self, Record};
use crate::cancel::Cancel;
use crate::error::{Error, Result};
use crate::extract::neighbourhood::Cloud;
use crate::extract::statistics::tile_origin;
use crate::keys::{keep_point, position_key};
use crate::points::TilePoints;
use crate::progress::Progress;
use crate::tiles::{within, Grid, Store};
use crate::workspace::Workspace;
use std::time::Instant;

/// Seconds a tile pass spent loading tiles (reading the store, building the cloud: on the
/// loader thread, overlapping compute) and computing them.
#[derive(Clone, Copy, Debug, Default)]
pub struct PassTime {
    /// Loading.
    pub load: f64,
    /// Computing.
    pub compute: f64,
}

/// What a pass needs besides its two steps.
pub struct PassContext<'a> {
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
pub fn tile_pass<T: Send, R: Record>(
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
pub struct Loading<'a> {
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
}

/// Loads tile `t`'s core and the halo around it (thinned to share `keep` by position key); the
/// flags say which points are core points to evaluate (the share `evaluate` of the core's,
/// by another draw from the position key).
pub fn load(store: Store, grid: &Grid, t: u32, l: &Loading) -> Result<(TilePoints, Vec<bool>)> {
    let core = grid.core(t);
    let (halo, keep) = (l.halo, l.keep);
    let kept = |p| keep >= 1.0 || keep_point(position_key(p, l.key_quantum), keep, l.seed);
    // (A key of its own, so that which points are evaluated does not follow which are kept.)
    let evaluated = |p| l.evaluate >= 1.0 || keep_point(position_key(p, l.key_quantum) ^ 0xE7A1_0A7E, l.evaluate, l.seed);
    let mut tp = TilePoints::default();
    let mut is_core = vec![];
    for n in grid.around(t, halo) {
        let before = tp.xyz.len();
        if n == t {
            let held = store.read(n, &mut tp, |p, _| kept(p))?;
            let bucketed = l.counts.get(t as usize).copied().unwrap_or(0);
            if held != bucketed {
                // (A deleted or truncated tile file once dropped its points without a word.)
                return Err(Error::damaged(store.path(t), format!("holds {held} of the {bucketed} points bucketed into it")));
            }
        } else {
            store.read_near(n, Some((&core, halo)), &mut tp, |p, _| within(&core, halo, p) && kept(p))?;
        }
        let own = n == t;
        is_core.extend(tp.xyz[before..].iter().map(|&p| own && evaluated(p)));
    }
    Ok((tp, is_core))
}

/// Loads tile `t` with its halo (see [`load`]) and stores it by grid cells of side `side`, on
/// the rayon pool if `idle` says that the pool has nothing else to do (the same cloud either
/// way).
pub fn load_cloud(store: Store, grid: &Grid, t: u32, l: &Loading, side: f64, idle: bool, cancel: &Cancel) -> Result<(Cloud, Vec<bool>)> {
    let (tp, core) = load(store, grid, t, l)?;
    let origin = tile_origin(&tp);
    Ok((Cloud::gridded(&tp.xyz, &tp.gid, origin, side, idle).cancelled_by(cancel), core))
}
