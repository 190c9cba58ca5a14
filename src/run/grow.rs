//! Stages 3 and 4 of the curve stage over the growth blocks of this process's share, a block
//! at a time: each block's edge points read from the tiles near it, sorted, smoothed and
//! confirmed (see [`crate::extract::block_edges`]), then grown (see
//! [`polylines::grow_block`]) while the next block is smoothed. Each block's smoothed core and
//! its pieces of polylines are kept in the working data, the pieces last: they mark the block
//! done.

use super::budgets;
use super::recent::Recent;
use super::records::{self, Pieces, Record, Smoothed, Survey};
use super::state::{Run, Step};
use crate::error::{Error, Result};
use crate::extract::block_edges::{self, BlockContext};
use crate::extract::polylines::{self, SmoothedEdges};
use crate::extract::{Resolved, Timings};
use crate::keys::snap_quantum;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

impl Run<'_> {
    /// The blocks this process grows: all of them, or a worker's share, a run of neighbouring
    /// blocks (which read the same tiles).
    fn block_share(&self, n: usize) -> std::ops::Range<usize> {
        match self.worker {
            None => 0..n,
            Some(w) => {
                let at = |i: u32| n * i as usize / w.count as usize;
                at(w.index)..at(w.index + 1)
            }
        }
    }

    /// True if block `b`'s pieces are kept, grown for the blocks of `survey`, and its smoothed
    /// edge points too.
    fn block_done(&self, survey: &Survey, b: u32) -> Result<bool> {
        if !self.ws.exists(&records::name(Pieces::DIR, b)) {
            return Ok(false);
        }
        if !records::read::<Pieces>(&self.ws, b)?.grown_for(&survey.blocks.list[b as usize], survey.origin) {
            return Ok(false);
        }
        records::read::<Smoothed>(&self.ws, b)?;
        Ok(true)
    }

    /// The blocks of `share` left to grow: those not done by an earlier invocation, and those
    /// whose results it left damaged (removed here, and listed in the report).
    fn blocks_to_grow(&mut self, survey: &Survey, share: std::ops::Range<usize>) -> Result<Vec<u32>> {
        let state: Vec<(u32, Result<bool>)> = share.into_par_iter().map(|b| (b as u32, self.block_done(survey, b as u32))).collect();
        let mut todo = vec![];
        for (b, done) in state {
            match done {
                Ok(true) => continue,
                Ok(false) => {}
                Err(Error::Damaged { .. }) => {
                    self.ws.remove(&records::name(Smoothed::DIR, b));
                    let name = records::name(Pieces::DIR, b);
                    self.ws.remove(&name);
                    self.repaired.push(self.ws.path(&name));
                }
                Err(e) => return Err(e),
            }
            todo.push(b);
        }
        Ok(todo)
    }

    /// Done once every block is grown; else waiting for the other workers' share.
    pub(super) fn all_grown(&self, survey: &Survey) -> Step<()> {
        let n = survey.blocks.list.len() as u32;
        let done = (0..n).filter(|&b| self.ws.exists(&records::name(Pieces::DIR, b))).count();
        if done < n as usize {
            return Step::Waiting(format!("curves: {done} of {n} blocks grown (the other workers' share)"));
        }
        Step::Done(())
    }

    /// Stages 3 and 4 for this process's share of the blocks, those not done yet, a block at a
    /// time. Each block's smoothed, confirmed core is kept in the working data for
    /// [`Run::attribute`], then its pieces, which mark it done.
    pub(super) fn grow_blocks(&mut self, survey: &Survey, r: &Resolved, seconds: &mut Timings) -> Result<()> {
        let Survey { boxes, blocks, grouped, origin, .. } = survey;
        let share = self.block_share(blocks.list.len());
        self.ws.create_dir(Smoothed::DIR)?;
        self.ws.create_dir(Pieces::DIR)?;
        let todo = self.blocks_to_grow(survey, share.clone())?;
        let q = snap_quantum(r.kappa);
        // (Only the corners within the smoothing's reach of a block can cap its neighbourhoods.)
        let cx = BlockContext::new(blocks, *origin, grouped, r);
        let (mut debug_edges, mut debug_smoothed) = (vec![], vec![]);
        let bar = self.progress.bar("curves", share.len() as u64, "blocks");
        bar.inc((share.len() - todo.len()) as u64);
        // (Neighbouring blocks read the same tiles: the last few decoded are kept.)
        let mut tiles = Recent::new(budgets::tile_edges_kept(self.opts.memory));
        // Stage 3 for block b: its smoothed, confirmed core and halo, its own edge points as
        // read (for the debug dump), and the seconds taken.
        let mut smooth = |b: u32| -> Result<(SmoothedEdges, Vec<DVec3>, Vec<DVec3>, f64)> {
            let t = Instant::now();
            let region = cx.region(b);
            let near: Vec<u32> = boxes.iter().filter(|&&(_, lo, hi)| lo.cmple(region.1).all() && hi.cmpge(region.0).all()).map(|x| x.0).collect();
            let edges = tiles.get(&near, |u| Ok(self.stored_edges(u, q)?.edges))?;
            let sorted = block_edges::sort_edges(&cx, b, edges.iter().flat_map(|e| e.iter()));
            let raw = if self.opts.debug.on() { sorted.own.points.clone() } else { vec![] };
            let (core, halo) = block_edges::smooth_core(&cx, b, sorted);
            Ok((core, halo.points, raw, t.elapsed().as_secs_f64()))
        };
        // Stage 4 for a smoothed block, and the seconds taken.
        let grow = |pending: &Option<(u32, SmoothedEdges, Vec<DVec3>)>| match pending {
            Some((b, core, halo)) => {
                let t = Instant::now();
                let grown = polylines::grow_block(&core.points, halo, blocks, *b, r, &self.opts.cancel);
                (grown, t.elapsed().as_secs_f64())
            }
            None => (vec![], 0.0),
        };
        // (Growing is serial within a block: the next block is smoothed meanwhile.)
        let mut pending: Option<(u32, SmoothedEdges, Vec<DVec3>)> = None;
        for k in 0..=todo.len() {
            let ((grown, growing), next) = rayon::join(|| grow(&pending), || todo.get(k).map(|&b| smooth(b)));
            seconds.growing += growing;
            // (A cancelled block may be grown in part: it is not kept.)
            self.opts.cancel.check()?;
            if let Some((done, core, _)) = pending.take() {
                let (block, unconfirmed) = (&blocks.list[done as usize], core.unconfirmed);
                records::write(&self.ws, done, &Smoothed(core))?;
                records::write(&self.ws, done, &Pieces { lo: block.lo, hi: block.hi, origin: *origin, unconfirmed, pieces: grown })?;
                bar.inc(1);
            }
            if let Some(next) = next {
                let (core, halo_points, raw, secs) = next?;
                seconds.smoothing += secs;
                if self.opts.debug.on() {
                    debug_edges.extend(raw);
                    debug_smoothed.extend_from_slice(&core.points);
                }
                pending = Some((todo[k], core, halo_points));
            }
        }
        bar.finish();
        self.opts.debug.points("edges.obj", &debug_edges, *origin);
        self.opts.debug.points("smoothed.obj", &debug_smoothed, *origin);
        Ok(())
    }
}
