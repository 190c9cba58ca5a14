//! The passes that run tile by tile: bucketing, then statistics, residuals (stage 1) and
//! projection (stage 2) through the tile pass engine ([`super::pass`]), each tile with its
//! halo.

use super::bucket::{self, Input};
use super::budgets;
use super::far;
use super::manifest;
use super::pass::{self, tile_pass, CloudLoading, Loading};
use super::plan::tile_size_for;
use super::records::{self, Edges, NearStats, Record, Residuals, Stats};
use super::state::{done, Run, Step};
use crate::error::{Error, Result};
use crate::extract::candidates::{self, ResidualSum};
use crate::extract::params::Model;
use crate::extract::project;
use crate::extract::statistics::{self, StatsTile};
use crate::extract::{Params, Resolved};
use crate::keys::{key_quantum, settle};
use crate::points::{Bounds, TilePoints};
use crate::tiles::{Bucketer, Grid, Store};
use glam::DVec3;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// Most bucketing rounds: each leaves out the far points that the previous grid showed.
const FAR_ROUNDS: u32 = 4;

impl Run<'_> {
    /// Bucketing, statistics, residuals and projection: the steps that run tile by tile.
    /// Done with the resolved parameters; tau is kept.
    pub(super) fn tile_passes(&mut self, input: &Input, params: &Params, first_input: &Path) -> Result<Step<Resolved>> {
        if !self.manifest.bucketed && !self.leads() {
            return Ok(Step::Waiting("bucketing (worker 0 buckets the points)".into()));
        }
        self.bucket(input)?;
        let total: u64 = self.manifest.tile_points.iter().sum();
        if total < 10 {
            return Err(Error::input(first_input, format!("only {total} points after filtering: nothing to extract")));
        }
        self.tiles = (0..self.manifest.grid.len() as u32).filter(|&t| self.manifest.tile_points[t as usize] > 0).collect();
        let r = done!(self.statistics(params)?);
        // (All points at one position, or too few apart: every length of the method is zero.)
        if !(r.kappa > 0.0 && r.kappa.is_finite() && r.fit_radius > 0.0 && r.rmls_radius > 0.0) {
            let copies = self.manifest.duplicates.iter().sum::<u64>();
            let copies = if copies > 0 { format!("; {copies} of the {total} points are copies of others") } else { String::new() };
            return Err(Error::input(first_input, format!("the points have no spread (spacing {}{copies}): nothing to extract", r.kappa)));
        }
        self.tau = done!(self.residuals(&r, params)?);
        done!(self.projection(&r)?);
        self.peak_rss_tiles = crate::mem::peak_rss();
        Ok(Step::Done(r))
    }

    /// Bucketing: all or nothing (a partial store is discarded on resume). Where the points
    /// turn out to have far points, the grid is planned again over the rest and they are
    /// bucketed again without them (a few rounds at most: a far point inside the first
    /// grid's bins of the rest shows in the next).
    fn bucket(&mut self, input: &Input) -> Result<()> {
        if self.manifest.bucketed {
            return Ok(());
        }
        let t = Instant::now();
        for round in 1.. {
            let store = Store::new(&self.ws)?.cancelled_by(&self.opts.cancel);
            store.clear()?;
            let grid = self.manifest.grid.clone();
            let tiles = Bucketer::new(&grid, store, budgets::bucket_buffer(self.opts.memory));
            let mut sink = bucket::Sink { tiles, spread: far::Spread::new(&grid.span()), kept: self.manifest.kept, far: 0, seen: Bounds::EMPTY };
            let bar = self.progress.bar("bucketing", self.manifest.declared_points, "points");
            bucket::bucket(input, &mut sink, &bar, &self.opts.cancel)?;
            bar.finish();
            match sink.spread.far_bounds() {
                Some(kept) if round < FAR_ROUNDS => {
                    drop(sink);
                    self.replan(kept)?;
                }
                _ => {
                    sink.tiles.flush()?;
                    store.sync()?;
                    self.manifest.tile_points = sink.tiles.counts.clone();
                    self.manifest.far_points = sink.far;
                    self.manifest.points_min = (!sink.seen.is_empty()).then_some(sink.seen.min);
                    break;
                }
            }
        }
        self.manifest.bucketed = true;
        manifest::save(&self.ws, &self.manifest)?;
        self.pass.bucketing = t.elapsed().as_secs_f64();
        Ok(())
    }

    /// Plans the grid again over `kept`, the bounds of the points that are not far.
    fn replan(&mut self, kept: Bounds) -> Result<()> {
        let m = &mut self.manifest;
        let size = self.opts.tile_size.unwrap_or_else(|| tile_size_for(&kept, m.declared_points, self.opts.memory));
        m.grid = Grid::new(&kept, size);
        m.diag = kept.diagonal();
        m.kept = Some(kept);
        self.kq = key_quantum(m.diag);
        manifest::save(&self.ws, &self.manifest)
    }

    /// Statistics pass: spacing, noise and density at sampled points (see
    /// [`Run::stats_pass`]); then the parameters are resolved from them. Where the samples
    /// show near duplicates (see [`statistics::near_duplicate_radius`]), they were measured
    /// over the copies, and the pass runs again with the copies collapsed, as the later
    /// passes collapse them.
    fn statistics(&mut self, params: &Params) -> Result<Step<Resolved>> {
        let t = Instant::now();
        if let Some(r) = &self.manifest.resolved {
            self.pass.statistics = t.elapsed().as_secs_f64();
            return Ok(Step::Done(r.clone()));
        }
        if self.manifest.near_radius == 0.0 {
            let first = done!(self.stats_pass::<Stats>(params, 0.0)?);
            let all: Vec<_> = first.iter().flat_map(|s| s.stats.iter().copied()).collect();
            match statistics::near_duplicate_radius(&all) {
                None => return self.resolved(params, first, 0.0, t),
                Some(near) => {
                    self.manifest.near_radius = near;
                    self.save_manifest()?;
                }
            }
        }
        let near = self.manifest.near_radius;
        let again = done!(self.stats_pass::<NearStats>(params, near)?);
        self.resolved(params, again.into_iter().map(|s| s.0).collect(), near, t)
    }

    /// The parameters resolved from the tiles' statistics `stats`, measured with near
    /// duplicates collapsed within `near`; recorded in the manifest with the copies counted.
    fn resolved(&mut self, params: &Params, stats: Vec<Stats>, near: f64, t: Instant) -> Result<Step<Resolved>> {
        self.manifest.duplicates = stats.iter().fold([0, 0], |a, s| [a[0] + s.dropped.exact, a[1] + s.dropped.near]);
        let all: Vec<_> = stats.into_iter().flat_map(|s| s.stats).collect();
        crate::extract::params::check_given_lengths(params, &all, self.manifest.diag)?;
        let mut r = crate::extract::params::resolve(params, &all);
        r.near = near;
        self.manifest.resolved = Some(r.clone());
        self.save_manifest()?;
        self.pass.statistics = t.elapsed().as_secs_f64();
        Ok(Step::Done(r))
    }

    /// One statistics pass, its records `R`, with near duplicates collapsed within `near` (0:
    /// exact copies only), with a first halo wide enough for the 16-kappa fits (kappa from a
    /// probe of the fullest tile, copies dropped; tiles whose noise fits reach farther are
    /// loaded again, wider). Returns every tile's record.
    fn stats_pass<R: Record + From<Stats> + Send>(&mut self, params: &Params, near: f64) -> Result<Step<Vec<R>>> {
        self.repair::<R>()?;
        let (store, grid) = (Store::new(&self.ws)?.cancelled_by(&self.opts.cancel), &self.manifest.grid);
        let tile_points = &self.manifest.tile_points;
        let fullest = *self.tiles.iter().max_by_key(|&&t| (tile_points[t as usize], std::cmp::Reverse(t))).expect("a tile with points");
        let mut probe = TilePoints::default();
        store.read(fullest, &mut probe, |_, _| true)?;
        // (A million copies of one point in one kd-tree bucket took a minute to query.)
        let own = 0..probe.xyz.len();
        pass::drop_duplicates(&mut probe, own);
        self.opts.cancel.check()?;
        let kappa0 = crate::spacing::spacing_or_cancel(&probe.xyz, 2000, &self.opts.cancel)?;
        drop(probe);
        let total: u64 = tile_points.iter().sum();
        let seed = params.seed.unwrap_or(crate::extract::params::DEFAULT_SEED);
        let loading =
            |halo| Loading { halo, keep: 1.0, evaluate: 1.0, seed, key_quantum: self.kq, counts: tile_points, average: 0.0, average_share: 1.0, near };
        let halo0 = 24.0 * kappa0;
        // The widest halo that the noise balls of the tiles computed so far asked for: the
        // tiles loaded after them start with it rather than loading twice. (Which tiles do
        // depends on timing; what they compute does not.)
        let asked = std::sync::atomic::AtomicU64::new(halo0.to_bits());
        let cancel = &self.opts.cancel;
        // (The pool has little to do here but wait for the next tile, so the tile is indexed
        // on the pool, not on the loader thread as in the passes below.)
        let time = tile_pass(
            &self.context(),
            "statistics",
            &self.share(),
            |t, _| {
                let halo = f64::from_bits(asked.load(std::sync::atomic::Ordering::Relaxed));
                pass::load_counted(store, grid, t, &loading(halo)).map(|first| (first, halo))
            },
            |t, ((first, dropped), loaded)| {
                let tile = StatsTile { core: grid.core(t), halo: halo0, key_quantum: self.kq, total, seed, cancel };
                let (stats, wider) = statistics::tile_statistics(first, loaded, &tile, |halo| pass::load(store, grid, t, &loading(halo)))?;
                // (The bits of positive numbers order as the numbers do.)
                asked.fetch_max(wider.to_bits(), std::sync::atomic::Ordering::Relaxed);
                Ok(R::from(Stats { stats, dropped }))
            },
        )?;
        self.pass.statistics_load += time.load;
        done!(self.all_done::<R>("statistics"));
        Ok(Step::Done(self.tiles.iter().map(|&t| records::read::<R>(&self.ws, t)).collect::<Result<_>>()?))
    }

    /// How the residual and projection passes load a tile: the same way in both, so that the
    /// residuals come back in the cloud's order.
    fn cloud_loading(&self, r: &Resolved) -> Result<CloudLoading<'_>> {
        let (halo, keep, average, average_share) = (r.halo(), r.keep, r.average, r.average_share);
        let loading = Loading {
            halo,
            keep,
            evaluate: r.evaluate,
            seed: r.seed,
            key_quantum: self.kq,
            counts: &self.manifest.tile_points,
            average,
            average_share,
            near: r.near,
        };
        Ok(CloudLoading {
            store: Store::new(&self.ws)?.cancelled_by(&self.opts.cancel),
            grid: &self.manifest.grid,
            loading,
            cell_side: r.cell_side(),
            cancel: &self.opts.cancel,
        })
    }

    /// Residual pass (stage 1); returns tau, the mean residual over all points (an exact sum:
    /// the same whatever the tiling), unless the user gave it.
    fn residuals(&mut self, r: &Resolved, params: &Params) -> Result<Step<f64>> {
        let t = Instant::now();
        self.repair::<Residuals>()?;
        let clouds = self.cloud_loading(r)?;
        let time = tile_pass(
            &self.context(),
            "residuals",
            &self.share(),
            |t, idle| clouds.load(t, idle),
            |_, (cloud, core)| Ok(Residuals(candidates::tile_residuals(&cloud, &core, r))),
        )?;
        self.pass.residuals_load = time.load;
        done!(self.all_done::<Residuals>("residuals"));
        // (Read on the pool, which is idle here.)
        let sums: Vec<ResidualSum> = self
            .tiles
            .par_iter()
            .map(|&t| Ok(ResidualSum::of(records::read::<Residuals>(&self.ws, t)?.0.residual.iter().map(|x| x.value))))
            .collect::<Result<_>>()?;
        let total = sums.into_iter().fold(ResidualSum::default(), |a, b| a + b);
        self.evaluated = total.count();
        self.pass.residuals = t.elapsed().as_secs_f64();
        Ok(Step::Done(params.tau.unwrap_or(settle(total.mean()))))
    }

    /// Projection pass (stage 2): the candidates of each tile, projected. Waiting if a
    /// worker's share is done but not every tile is.
    fn projection(&mut self, r: &Resolved) -> Result<Step<()>> {
        let t = Instant::now();
        self.repair::<Edges>()?;
        let (clouds, tau) = (self.cloud_loading(r)?, self.tau);
        let debug = &self.opts.debug;
        let time = tile_pass(
            &self.context(),
            "projection",
            &self.share(),
            |t, idle| clouds.load(t, idle),
            |t, (cloud, core)| {
                let res = records::read::<Residuals>(&self.ws, t)?.0;
                let cand = candidates::tile_candidates(&cloud, &core, &res, tau);
                if debug.on() {
                    let pts: Vec<DVec3> = cand.iter().map(|&i| cloud.at(i as usize)).collect();
                    debug.points(&format!("candidates_{t}.obj"), &pts, cloud.origin);
                }
                let band = match r.model {
                    Model::Patches => Some(self.band(t, &cloud, r.halo(), tau)?),
                    _ => None,
                };
                Ok(Edges(project::tile_edges(&cloud, &cand, band.as_deref(), r)))
            },
        )?;
        self.pass.projection_load = time.load;
        self.pass.projection = t.elapsed().as_secs_f64();
        Ok(self.all_done::<Edges>("projection"))
    }

    /// Which points of tile `t`'s `cloud`, core and halo, are candidates at `tau`: the residual
    /// records of the tiles whose cores the halo reaches (those with points; empty tiles have
    /// no records).
    fn band(&self, t: u32, cloud: &crate::extract::neighbourhood::Cloud, halo: f64, tau: f64) -> Result<Vec<bool>> {
        let around = self
            .manifest
            .grid
            .around(t, halo)
            .into_iter()
            .filter(|&u| self.manifest.tile_points[u as usize] > 0)
            .map(|u| Ok(records::read::<Residuals>(&self.ws, u)?.0))
            .collect::<Result<Vec<_>>>()?;
        Ok(candidates::band_of(cloud, &around, tau))
    }
}
