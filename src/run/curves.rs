//! The curve stage (stages 3-5) over the edge points of every tile, by region: the edge cloud
//! is taken a growth block at a time (see [`crate::extract::blocks`]); the blocks' pieces a
//! slab of blocks at a time, handed on in clusters that can be stitched and completed alone
//! (see [`crate::extract::sweep`]); completion takes a batch of groups of lines at a time (see
//! [`groups`]), and the finished curves go to the working data batch by batch, for the writers
//! to read back. What it holds whole is the survey: the blocks and the grouped corners.

use super::records::{self, Finished, Pieces, Record, Smoothed};
use super::{Run, Worker};
use crate::curves::{Curves, Outside, Polyline};
use crate::error::{Error, Result};
use crate::extract::blocks::{self, in_box, Blocks, Census, Layers};
use crate::extract::complete::{self, Curve};
use crate::extract::polylines::{self, CornerGrouping, Gathered, NearEdges, SmoothedEdges};
use crate::extract::stitch;
use crate::extract::sweep::{Held, Sweep};
use crate::extract::{groups, Counts, Resolved, Timings, WorldEdge};
use crate::keys::snap_quantum;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// A tile's edge points at a glance: its number and the bounds of its edge points (relative to
/// the origin).
type TileBox = (u32, DVec3, DVec3);

/// What the survey of the edge points found (see [`Run::survey`]).
pub(super) struct Survey {
    /// Side of the base blocks planned.
    pub(super) side: f64,
    /// The origin of the curve stage's positions, and of the blocks' grid.
    pub(super) origin: DVec3,
    /// The counts of stages 1 and 2.
    pub(super) counts: Counts,
    /// The tiles that hold edge points, with their bounds.
    pub(super) boxes: Vec<TileBox>,
    pub(super) blocks: Blocks,
    /// Grouped corners, relative to the origin.
    pub(super) grouped: Vec<DVec3>,
}

impl Run<'_> {
    /// Stages 3-5, as the method runs them, a block at a time where they are local:
    /// 1. survey the edge points: counts, corners (grouped over the whole cloud), and the
    ///    growth blocks;
    /// 2. per block: smoothing and the consensus filter (stage 3), then growing (stage 4) from
    ///    the block's core, cut at its border; each block's pieces are kept in the working data
    ///    (a worker grows its share of the blocks);
    /// 3. a slab of blocks at a time, the stitcher joins the pieces across the borders, a
    ///    cluster of them at a time;
    /// 4. completion (stage 5) on the stitched polylines, a group of them at a time;
    /// 5. per block again: the curves' normals and evidence from the smoothed edge points, a
    ///    batch of groups at a time.
    ///
    /// Returns the number of batches of finished curves written (see [`Run::finished_curves`]),
    /// or None if this process is a worker whose share is done but whose run is not (see
    /// [`Run::waiting`]).
    pub(super) fn curves(&mut self, r: &Resolved, outside: &Outside) -> Result<Option<(u32, Counts, Timings)>> {
        let t = Instant::now();
        crate::mem::release_free_memory();
        self.curve_peak = Some(crate::mem::PeakSampler::start());
        let survey = self.survey(r)?;
        let mut seconds = Timings { candidates: self.pass.residuals, projection: self.pass.projection, index: self.pass.statistics, ..Default::default() };
        self.grow_blocks(&survey, r, &mut seconds)?;
        if !Worker::leads(self.worker) {
            self.waiting = Some("the curves and outputs (worker 0 writes them)".into());
            return Ok(None);
        }
        if !self.all_grown(&survey) {
            return Ok(None);
        }
        let Survey { counts, blocks, grouped, origin, .. } = survey;
        let mut counts = Counts {
            points: self.manifest.tile_points.iter().sum(),
            far_points: self.manifest.far_points,
            evaluated: self.evaluated,
            corners: grouped.len() as u64,
            blocks: blocks.list.len() as u64,
            ..counts
        };
        if self.opts.debug.on() {
            self.opts.debug.points("corners.obj", &grouped, origin);
        }
        let tc = Instant::now();
        let batches = self.complete(&grouped, &blocks, origin, r, outside, &mut counts)?;
        // (What the stage freed goes back to the system before the outputs are written.)
        crate::mem::release_free_memory();
        seconds.completion = tc.elapsed().as_secs_f64();
        self.pass.curves = t.elapsed().as_secs_f64();
        Ok(Some((batches, counts, seconds)))
    }

    /// The finished curves, of the `batches` batches [`Run::curves`] wrote.
    pub(super) fn finished_curves(&self, batches: u32) -> FinishedCurves<'_> {
        FinishedCurves { ws: &self.ws, batches }
    }

    /// A tile's edge points, snapped, with its corners and counts.
    fn stored_edges(&self, t: u32, q: f64) -> Result<crate::extract::TileEdges> {
        let mut e = records::read::<records::Edges>(&self.ws, t)?.0;
        for x in e.edges.iter_mut() {
            polylines::snap_edge(x, q);
        }
        Ok(e)
    }

    /// The survey of the edge points: as kept by an earlier invocation (or by worker 0), else
    /// made from the tiles (and kept, by the process that writes the run's shared files).
    fn survey(&self, r: &Resolved) -> Result<Survey> {
        let side = self.opts.block_steps * r.step;
        // (A damaged survey, or one of blocks of another side, is made again.)
        if let Ok(kept) = records::read::<Survey>(&self.ws, 0)
            && kept.side == side
        {
            return Ok(kept);
        }
        let survey = self.survey_edges(r, side)?;
        if Worker::leads(self.worker) {
            self.ws.create_dir(Survey::DIR)?;
            records::write(&self.ws, 0, &survey)?;
        }
        Ok(survey)
    }

    /// Reads every tile's edge points: the counts of stages 1-2, the corners (grouped), where
    /// the blocks' borders go (see [`Layers`]), then, relative to the origin so found, the
    /// bounds of each tile's edge points and the growth blocks of side `side`.
    fn survey_edges(&self, r: &Resolved, side: f64) -> Result<Survey> {
        let q = snap_quantum(r.kappa);
        let cell = Census::new(side).cell_side();
        // (The curves, to the bit, follow the anchor: it is the low corner of the points
        // themselves, as in memory, not the grid's origin, the corner of the bounds the inputs
        // declare, which a LAS header may round outwards. The two are one where the header is
        // exact, and where far points were left out the grid was planned over the points.)
        let m = &self.manifest;
        let anchor = DVec3::from(match (m.kept, m.points_min) {
            (None, Some(min)) => min,
            _ => m.grid.origin,
        });
        let mut counts = Counts::default();
        // (Tiles are decoded in parallel, a few at a time, and reduced to what is kept.)
        let seen = self
            .tiles
            .par_iter()
            .map(|&t| {
                let e = self.stored_edges(t, q)?;
                let mut layers = Layers::new(cell, r.step);
                e.edges.iter().for_each(|x| layers.add(x.p - anchor));
                let lo = e.edges.iter().map(|x| x.p).reduce(DVec3::min);
                let hi = e.edges.iter().map(|x| x.p).reduce(DVec3::max);
                let corners = (e.corners.len(), CornerGrouping::bounds(&e.corners, r));
                Ok((t, e.candidates, e.one_surface, e.scattered, e.edges.len(), corners, layers, lo.zip(hi)))
            })
            .collect::<Result<Vec<_>>>()?;
        let (mut boxes, mut corner_boxes, mut layers) = (vec![], vec![], Layers::new(cell, r.step));
        for (t, candidates, one_surface, scattered, edges, (corners, corner_box), l, bounds) in seen {
            counts.candidates += candidates;
            counts.one_surface += one_surface;
            counts.scattered += scattered;
            counts.edge_points += edges as u64;
            counts.corner_points += corners as u64;
            corner_boxes.push((t, corner_box));
            layers.merge(&l);
            if let Some((lo, hi)) = bounds {
                boxes.push((t, lo, hi));
            }
        }
        let origin = anchor + layers.borders();
        for b in boxes.iter_mut() {
            (b.1, b.2) = (b.1 - origin, b.2 - origin);
        }
        // (The corner points are grouped a tile at a time, as the blocks are counted.)
        let grouping = CornerGrouping::new(&corner_boxes.iter().map(|c| c.1).collect::<Vec<_>>(), origin, r);
        let has_edges = |t: u32| boxes.binary_search_by_key(&t, |b| b.0).is_ok();
        let read: Vec<(usize, u32)> = corner_boxes.iter().enumerate().filter(|(_, c)| c.1.is_some() || has_edges(c.0)).map(|(k, c)| (k, c.0)).collect();
        let (census, parts) = read
            .par_iter()
            .map(|&(k, t)| {
                let e = self.stored_edges(t, q)?;
                let mut census = Census::new(side);
                e.edges.iter().for_each(|x| census.add(x.p - origin));
                Ok((census, vec![grouping.part(k, e.corners)]))
            })
            .try_reduce(
                || (Census::new(side), vec![]),
                |mut a, b| {
                    a.0.merge(b.0);
                    a.1.extend(b.1);
                    Ok(a)
                },
            )?;
        let grouped = grouping.finish(parts);
        Ok(Survey { side, origin, counts, boxes, blocks: blocks::plan(&census), grouped })
    }

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

    /// True once every block is grown; else false, noting what it waits for (another worker's
    /// share).
    fn all_grown(&mut self, survey: &Survey) -> bool {
        let n = survey.blocks.list.len() as u32;
        let done = (0..n).filter(|&b| self.ws.exists(&records::name(Pieces::DIR, b))).count();
        if done < n as usize {
            self.waiting = Some(format!("curves: {done} of {n} blocks grown (the other workers' share)"));
        }
        done == n as usize
    }

    /// Block `b`'s pieces, and the edge points the consensus filter dropped in it, as grown for
    /// the blocks of this run.
    fn block_pieces(&self, blocks: &Blocks, origin: DVec3, b: u32) -> Result<(Vec<blocks::Piece>, u64)> {
        let k = records::read::<Pieces>(&self.ws, b)?;
        if !k.grown_for(&blocks.list[b as usize], origin) {
            let why = "grown for other blocks than this run's (by a worker given another --block-steps?)";
            return Err(Error::damaged(self.ws.path(&records::name(Pieces::DIR, b)), why));
        }
        Ok((k.pieces, k.unconfirmed))
    }

    /// Stages 3 and 4 for this process's share of the blocks, those not done yet, a block at a
    /// time. Each block's smoothed, confirmed core is kept in the working data for
    /// [`Run::attribute`], then its pieces, which mark it done.
    fn grow_blocks(&mut self, survey: &Survey, r: &Resolved, seconds: &mut Timings) -> Result<()> {
        let Survey { boxes, blocks, grouped, origin, .. } = survey;
        let origin = *origin;
        let share = self.block_share(blocks.list.len());
        self.ws.create_dir(Smoothed::DIR)?;
        self.ws.create_dir(Pieces::DIR)?;
        let todo = self.blocks_to_grow(survey, share.clone())?;
        let q = snap_quantum(r.kappa);
        let (halo, reach) = polylines::block_context(r);
        // (The margin covers the f32 rounding of the k-d tree's distances.)
        let reach = reach * 1.001 + 4.0 * q;
        let (mut debug_edges, mut debug_smoothed) = (vec![], vec![]);
        let bar = self.progress.bar("curves", share.len() as u64, "blocks");
        bar.inc((share.len() - todo.len()) as u64);
        // (Neighbouring blocks read the same tiles: the last few decoded are kept.)
        let mut tiles = Recent::new(self.opts.memory / 16 / 48);
        // (Only the corners within the smoothing's reach of a block can cap its neighbourhoods.)
        let corners = groups::Corners::new(grouped);
        // Stage 3 for block b: its smoothed, confirmed core and halo, its own edge points as
        // read (for the debug dump), and the seconds taken.
        let mut smooth = |b: usize| -> Result<(SmoothedEdges, Vec<DVec3>, Vec<DVec3>, f64)> {
            let t = Instant::now();
            let block = &blocks.list[b];
            let region = block.around(reach);
            let near: Vec<u32> = boxes.iter().filter(|&&(_, lo, hi)| lo.cmple(region.1).all() && hi.cmpge(region.0).all()).map(|x| x.0).collect();
            let edges = tiles.get(&near, |u| Ok(self.stored_edges(u, q)?.edges))?;
            let edges = edges.iter().map(|e| e.iter().filter(|e| in_box(region, e.p - origin)).copied().collect::<Vec<WorldEdge>>());
            // The block's own edge points, those of its halo, and the context of both, each in
            // the order of their positions, whatever the tiles they came from.
            let grow_box = block.around(halo);
            let (mut own, mut around, mut context) = (SmoothedEdges::default(), SmoothedEdges::default(), SmoothedEdges::default());
            for e in edges.into_iter().flatten() {
                let p = e.p - origin;
                let to = if blocks.owner(p) == Some(b as u32) {
                    &mut own
                } else if in_box(grow_box, p) {
                    &mut around
                } else {
                    &mut context
                };
                to.points.push(p);
                to.normals.push(e.n);
            }
            for s in [&mut own, &mut around, &mut context] {
                s.sort();
            }
            let (n_own, n_around) = (own.points.len(), around.points.len());
            let points: Vec<DVec3> = own.points.iter().chain(&around.points).chain(&context.points).copied().collect();
            let normals: Vec<[glam::Vec3; 2]> = own.normals.iter().chain(&around.normals).chain(&context.normals).copied().collect();
            drop(context);
            let (smoothed, keep) = polylines::smooth_and_confirm(&points, &normals, n_own + n_around, &corners.within(region.0, region.1), r);
            let (mut core, mut halo_points) = (SmoothedEdges::default(), SmoothedEdges::default());
            for (i, (&p, k)) in smoothed.iter().zip(keep).enumerate() {
                let to = if i < n_own { &mut core } else { &mut halo_points };
                if k {
                    to.points.push(p);
                    to.normals.push(normals[i]);
                } else if i < n_own {
                    to.unconfirmed += 1;
                }
            }
            core.sort();
            halo_points.sort();
            let raw = if self.opts.debug.on() { own.points } else { vec![] };
            Ok((core, halo_points.points, raw, t.elapsed().as_secs_f64()))
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
            let ((grown, growing), next) = rayon::join(|| grow(&pending), || todo.get(k).map(|&b| smooth(b as usize)));
            seconds.growing += growing;
            // (A cancelled block may be grown in part: it is not kept.)
            self.opts.cancel.check()?;
            if let Some((done, core, _)) = pending.take() {
                let (block, unconfirmed) = (&blocks.list[done as usize], core.unconfirmed);
                records::write(&self.ws, done, &Smoothed(core))?;
                records::write(&self.ws, done, &Pieces { lo: block.lo, hi: block.hi, origin, unconfirmed, pieces: grown })?;
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
        self.opts.debug.points("edges.obj", &debug_edges, origin);
        self.opts.debug.points("smoothed.obj", &debug_smoothed, origin);
        Ok(())
    }

    /// The stitcher and stage 5, by region, then each batch of curves attributed (see
    /// [`Run::attribute`]), labelled convex or concave as seen from `outside`, and those the
    /// output filters keep written to the working data as a [`Finished`] record. The blocks'
    /// pieces are read a slab at a time (see [`Blocks::slabs`]) and handed on in clusters that
    /// can be finished alone (see [`Sweep`]); each cluster is stitched and its lines grouped
    /// (see [`groups`]), and a batch of groups of about a sixteenth of the memory is completed,
    /// attributed and written before the next is gathered. The curves come in the order their
    /// clusters were handed on, a cluster's in the order of its groups' first lines. Returns the
    /// number of batches written; `counts` gets the polylines stitched, the edge points the
    /// consensus filter dropped, and the curves kept and left out.
    fn complete(&self, grouped: &[DVec3], blocks: &Blocks, origin: DVec3, r: &Resolved, outside: &Outside, counts: &mut Counts) -> Result<u32> {
        let cp = polylines::complete_params(r);
        let reach = cp.reach * cp.step;
        let (join, merge) = (stitch::JOIN_STEPS * r.step, stitch::MERGE_STEPS * r.step);
        // (A piece's vertices lie within the growth halo of its block.)
        let halo = blocks::HALO_STEPS * r.step * 1.001;
        let (axis, slabs) = blocks.slabs();
        let mut sweep = Sweep::new(axis, join, 2.0 * reach * (1.0 + 1e-9) + 2.0 * merge);
        // (A batch of about a sixteenth of the memory, at 140 bytes a vertex while completed.)
        let budget = (self.opts.memory / 16 / 140).max(256) as usize;
        let corners = groups::Corners::new(grouped);
        let mut batch = Batch { traced: 0, written: 0, groups: vec![], vertices: 0 };
        let mut debug_lines = vec![];
        (counts.grown, counts.unconfirmed, counts.curves, counts.left_out) = (0, 0, 0, 0);
        self.ws.create_dir(Finished::DIR)?;
        let bar = self.progress.bar("completion", slabs.len() as u64, "slabs");
        for (k, slab) in slabs.iter().enumerate() {
            let read = slab.par_iter().map(|&b| self.block_pieces(blocks, origin, b)).collect::<Result<Vec<_>>>()?;
            let mut held = vec![];
            for (&b, (pieces, unconfirmed)) in slab.iter().zip(read) {
                counts.unconfirmed += unconfirmed;
                held.extend(pieces.into_iter().enumerate().map(|(i, piece)| Held { id: (b as u64) << 32 | i as u64, block: b, piece }));
            }
            let beyond = slabs.get(k + 1).map_or(f64::INFINITY, |next| blocks.reach_below(next, axis, halo));
            for cluster in sweep.add(held, beyond) {
                let lines = stitch::stitch(cluster.into_iter().map(|h| (h.block, h.piece)).collect(), join, merge);
                counts.grown += lines.len() as u64;
                if self.opts.debug.on() {
                    debug_lines.extend(lines.iter().map(|l| l.0.clone()));
                }
                let groups = groups::groups(&lines, reach);
                let mut lines: Vec<Option<stitch::Line>> = lines.into_iter().map(Some).collect();
                for group in groups {
                    let curves: Vec<Curve> = group.iter().filter_map(|&i| lines[i as usize].take()).map(|(v, closed)| Curve::new(v, closed)).collect();
                    batch.vertices += curves.iter().map(|c| c.v.len()).sum::<usize>();
                    batch.groups.push(curves);
                    if batch.vertices >= budget {
                        self.finish_batch(&mut batch, &corners, &cp, blocks, origin, r, outside, counts)?;
                    }
                }
            }
            bar.inc(1);
        }
        debug_assert_eq!(sweep.held(), 0);
        counts.clusters_cut = sweep.cuts();
        if !batch.groups.is_empty() || batch.written == 0 {
            self.finish_batch(&mut batch, &corners, &cp, blocks, origin, r, outside, counts)?;
        }
        bar.finish();
        if self.opts.debug.on() {
            let pl: Vec<Polyline> = debug_lines.iter().enumerate().map(|(i, l)| Polyline::from_points(i as u32, l.iter().map(|p| *p + origin))).collect();
            self.opts.debug.polylines("grown.obj", &pl);
        }
        counts.left_out = batch.traced as u64 - counts.curves;
        counts.batches = batch.written as u64;
        // (Batches of an earlier invocation beyond this one's are stale.)
        for k in batch.written.. {
            let name = records::name(Finished::DIR, k);
            if !self.ws.exists(&name) {
                break;
            }
            self.ws.remove(&name);
        }
        Ok(batch.written)
    }

    /// Completes `batch`'s groups (each alone, with the corners within the reach of its ends),
    /// attributes the curves, and writes those the output filters keep as the next
    /// [`Finished`] record; the batch is then empty.
    #[allow(clippy::too_many_arguments)]
    fn finish_batch(
        &self,
        batch: &mut Batch,
        corners: &groups::Corners,
        cp: &complete::CompleteParams,
        blocks: &Blocks,
        origin: DVec3,
        r: &Resolved,
        outside: &Outside,
        counts: &mut Counts,
    ) -> Result<()> {
        let ends = |c: &Curve| (!c.closed).then(|| [c.v[0], c.v[c.v.len() - 1]]).into_iter().flatten();
        let (lo, hi) = batch.groups.iter().flatten().flat_map(ends).fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)));
        let near = corners.near_box(lo, hi, cp.reach * cp.step);
        let curves: Vec<Curve> = std::mem::take(&mut batch.groups)
            .into_par_iter()
            .map(|group| {
                let near = near.near(group.iter().flat_map(ends));
                complete::complete(group, &near, cp, &self.opts.cancel)
            })
            .flatten()
            .collect();
        batch.vertices = 0;
        self.opts.cancel.check()?;
        let attributed = self.attribute(curves, blocks, origin, r, batch.traced)?;
        batch.traced += attributed.len() as u32;
        let (min_confidence, min_length) = (self.opts.min_confidence, self.opts.min_length);
        let mut kept: Vec<Polyline> = attributed.into_iter().filter(|c| c.confidence as f64 >= min_confidence && c.length() >= min_length).collect();
        outside.label(&mut kept);
        counts.curves += kept.len() as u64;
        records::write(&self.ws, batch.written, &Finished(kept))?;
        batch.written += 1;
        Ok(())
    }

    /// Each curve's vertex normals and evidence, from the smoothed edge points a block at a
    /// time: each vertex and each place along a curve is looked up in the block that holds it
    /// (or, off every block, the one it is within a step of), with the smoothed edge points
    /// within a step and a half of that block.
    fn attribute(&self, curves: Vec<Curve>, blocks: &Blocks, origin: DVec3, r: &Resolved, first: u32) -> Result<Vec<Polyline>> {
        let step = r.step;
        // The curves each block may hold a vertex or place of.
        let mut meets: Vec<Vec<u32>> = vec![vec![]; blocks.list.len()];
        for (c, curve) in curves.iter().enumerate() {
            let lo = curve.v.iter().copied().reduce(DVec3::min).unwrap_or_default() - DVec3::splat(step);
            let hi = curve.v.iter().copied().reduce(DVec3::max).unwrap_or_default() + DVec3::splat(step);
            for b in blocks.meeting(lo, hi) {
                meets[b as usize].push(c as u32);
            }
        }
        let mut gathered: Vec<Gathered> = curves.iter().map(|c| Gathered::new(c.v.len())).collect();
        // (Small: it only spares neighbouring blocks decoding the records around them again.)
        let mut smoothed = Recent::new(self.opts.memory / 48 / 48);
        for (b, ids) in meets.into_iter().enumerate() {
            if ids.is_empty() {
                continue;
            }
            let region = blocks.list[b].around(1.5 * step);
            let mut near = SmoothedEdges::default();
            for s in smoothed.get(&blocks.meeting(region.0, region.1), |k| Ok(records::read::<Smoothed>(&self.ws, k)?.0))? {
                for (&p, &n) in s.points.iter().zip(&s.normals) {
                    if in_box(region, p) {
                        near.points.push(p);
                        near.normals.push(n);
                    }
                }
            }
            near.sort();
            let edges = NearEdges::new(&near.points, &near.normals, step);
            let held = blocks.list[b].around(step);
            let here = |p: DVec3| in_box(held, p) && blocks.find(p, step) == Some(b as u32);
            let found: Vec<_> = ids
                .par_iter()
                .map(|&c| {
                    let curve = &curves[c as usize];
                    let normals: Vec<(usize, [DVec3; 2])> =
                        (0..curve.v.len()).filter(|&i| !curve.corner[i] && here(curve.v[i])).filter_map(|i| Some((i, edges.normals_at(curve.v[i])?))).collect();
                    let agreement: Vec<f64> =
                        polylines::places(&curve.v, curve.closed, step).into_iter().filter(|&p| here(p)).filter_map(|p| edges.agreement_at(p)).collect();
                    (normals, agreement)
                })
                .collect();
            for (&c, (normals, agreement)) in ids.iter().zip(found) {
                let g = &mut gathered[c as usize];
                for (i, m) in normals {
                    g.normals[i] = m.map(|x| x.as_vec3());
                }
                g.covered += agreement.len() as u32;
                g.agreement += agreement.iter().sum::<f64>();
            }
            self.opts.cancel.check()?;
        }
        Ok(curves.into_iter().zip(gathered).enumerate().map(|(id, (c, g))| polylines::finish(first + id as u32, c, g, origin, step)).collect())
    }
}

/// A run's finished curves, kept in its working data a batch at a time (see [`Finished`]).
pub(super) struct FinishedCurves<'a> {
    ws: &'a crate::workspace::Workspace,
    batches: u32,
}

impl Curves for FinishedCurves<'_> {
    fn each(&self, f: &mut dyn FnMut(&Polyline) -> Result<()>) -> Result<()> {
        for b in 0..self.batches {
            records::read::<Finished>(self.ws, b)?.0.iter().try_for_each(&mut *f)?;
        }
        Ok(())
    }
}

/// Groups of lines waiting to be completed, and what the batches so far came to.
struct Batch {
    /// Curves traced in the batches written.
    traced: u32,
    /// Batches written.
    written: u32,
    /// The groups waiting, and their vertices in all.
    groups: Vec<Vec<Curve>>,
    vertices: usize,
}

/// The last few records read (tiles' edge points, blocks' smoothed edge points), up to a number
/// of points in all, so that neighbouring blocks do not decode the same records again.
struct Recent<T> {
    cap: u64,
    held: u64,
    items: std::collections::VecDeque<(u32, std::sync::Arc<T>, u64)>,
}

/// A record's size, in points.
trait Points {
    fn points(&self) -> u64;
}

impl Points for Vec<WorldEdge> {
    fn points(&self) -> u64 {
        self.len() as u64
    }
}

impl Points for SmoothedEdges {
    fn points(&self) -> u64 {
        self.points.len() as u64
    }
}

impl<T: Points + Send + Sync> Recent<T> {
    fn new(cap: u64) -> Recent<T> {
        Recent { cap, held: 0, items: Default::default() }
    }

    /// The records `ids`, those not held read by `read` (in parallel), in the order asked.
    fn get(&mut self, ids: &[u32], read: impl Fn(u32) -> Result<T> + Sync) -> Result<Vec<std::sync::Arc<T>>> {
        let missing: Vec<u32> = ids.iter().copied().filter(|&k| !self.items.iter().any(|x| x.0 == k)).collect();
        let read = missing.par_iter().map(|&k| Ok((k, std::sync::Arc::new(read(k)?)))).collect::<Result<Vec<_>>>()?;
        let out: Vec<std::sync::Arc<T>> = ids
            .iter()
            .map(|&k| read.iter().find(|x| x.0 == k).map(|x| x.1.clone()).unwrap_or_else(|| self.items.iter().find(|x| x.0 == k).unwrap().1.clone()))
            .collect();
        for (k, item) in read {
            let n = item.points();
            self.items.push_back((k, item, n));
            self.held += n;
        }
        while self.held > self.cap {
            let Some((_, _, n)) = self.items.pop_front() else { break };
            self.held -= n;
        }
        Ok(out)
    }
}
