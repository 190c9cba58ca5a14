//! The stitcher, stage 5 and the curves' attributes, by region: the blocks' pieces read a slab
//! at a time (see [`Blocks::slabs`]) and handed on in clusters that can be finished alone
//! (see [`Sweep`]); each cluster stitched and its lines grouped (see [`groups`]); a batch of
//! groups completed, attributed, labelled and written to the working data as a [`Finished`]
//! record before the next is gathered.

use super::budgets;
use super::recent::Recent;
use super::records::{self, Finished, Pieces, Record, Smoothed};
use super::state::Run;
use crate::curves::{Outside, Polyline};
use crate::error::{Error, Result};
use crate::extract::blocks::{self, in_box, Blocks};
use crate::extract::complete::{self, Curve};
use crate::extract::polylines::{self, Gathered, NearEdges, SmoothedEdges};
use crate::extract::stitch;
use crate::extract::sweep::{Held, Sweep};
use crate::extract::{groups, Counts, Resolved};
use glam::DVec3;
use rayon::prelude::*;

/// What completing the curves takes besides the curves: the grouped corners, completion's
/// parameters, the blocks and their origin, the resolved parameters, and where the surfaces
/// were seen from (which labels the curves convex or concave).
pub(super) struct Completion<'a> {
    corners: groups::Corners<'a>,
    cp: complete::CompleteParams,
    blocks: &'a Blocks,
    origin: DVec3,
    r: &'a Resolved,
    outside: &'a Outside,
}

impl<'a> Completion<'a> {
    /// The completion of the curves grown in `blocks` about `origin`, with the corners
    /// `grouped` (relative to the origin).
    pub(super) fn new(grouped: &'a [DVec3], blocks: &'a Blocks, origin: DVec3, r: &'a Resolved, outside: &'a Outside) -> Completion<'a> {
        Completion { corners: groups::Corners::new(grouped), cp: polylines::complete_params(r), blocks, origin, r, outside }
    }
}

impl Run<'_> {
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

    /// The stitcher and stage 5, by region, then each batch of curves attributed (see
    /// [`Run::attribute`]), labelled convex or concave as seen from `cx.outside`, and those the
    /// output filters keep written to the working data as a [`Finished`] record. The blocks'
    /// pieces are read a slab at a time (see [`Blocks::slabs`]) and handed on in clusters that
    /// can be finished alone (see [`Sweep`]); each cluster is stitched and its lines grouped
    /// (see [`groups`]), and a batch of groups of about a sixteenth of the memory is completed,
    /// attributed and written before the next is gathered. The curves come in the order their
    /// clusters were handed on, a cluster's in the order of its groups' first lines. Returns the
    /// number of batches written; `counts` gets the polylines stitched, the edge points the
    /// consensus filter dropped, and the curves kept and left out.
    pub(super) fn complete(&self, cx: &Completion, counts: &mut Counts) -> Result<u32> {
        let (blocks, r) = (cx.blocks, cx.r);
        let reach = cx.cp.reach * cx.cp.step;
        let (join, merge) = (stitch::JOIN_STEPS * r.step, stitch::MERGE_STEPS * r.step);
        // (A piece's vertices lie within the growth halo of its block.)
        let halo = blocks::HALO_STEPS * r.step * 1.001;
        let (axis, slabs) = blocks.slabs();
        let mut sweep = Sweep::new(axis, join, 2.0 * reach * (1.0 + 1e-9) + 2.0 * merge);
        let budget = budgets::completion_batch(self.opts.memory);
        let mut batch = Batch { traced: 0, written: 0, groups: vec![], vertices: 0 };
        let mut debug_lines = vec![];
        (counts.grown, counts.unconfirmed, counts.curves, counts.left_out) = (0, 0, 0, 0);
        self.ws.create_dir(Finished::DIR)?;
        let bar = self.progress.bar("completion", slabs.len() as u64, "slabs");
        for (k, slab) in slabs.iter().enumerate() {
            let read = slab.par_iter().map(|&b| self.block_pieces(blocks, cx.origin, b)).collect::<Result<Vec<_>>>()?;
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
                        self.finish_batch(cx, &mut batch, counts)?;
                    }
                }
            }
            bar.inc(1);
        }
        debug_assert_eq!(sweep.held(), 0);
        counts.clusters_cut = sweep.cuts();
        if !batch.groups.is_empty() || batch.written == 0 {
            self.finish_batch(cx, &mut batch, counts)?;
        }
        bar.finish();
        if self.opts.debug.on() {
            let pl: Vec<Polyline> = debug_lines.iter().enumerate().map(|(i, l)| Polyline::from_points(i as u32, l.iter().map(|p| *p + cx.origin))).collect();
            self.opts.debug.polylines("grown.obj", &pl);
        }
        counts.left_out = batch.traced as u64 - counts.curves;
        counts.batches = batch.written as u64;
        self.remove_stale_batches(batch.written);
        Ok(batch.written)
    }

    /// Removes the batches of finished curves from number `from` on: an earlier invocation's,
    /// beyond this one's.
    fn remove_stale_batches(&self, from: u32) {
        for k in from.. {
            let name = records::name(Finished::DIR, k);
            if !self.ws.exists(&name) {
                break;
            }
            self.ws.remove(&name);
        }
    }

    /// Completes `batch`'s groups (each alone, with the corners within the reach of its ends),
    /// attributes the curves, and writes those the output filters keep as the next
    /// [`Finished`] record; the batch is then empty.
    fn finish_batch(&self, cx: &Completion, batch: &mut Batch, counts: &mut Counts) -> Result<()> {
        let ends = |c: &Curve| (!c.closed).then(|| [c.v[0], c.v[c.v.len() - 1]]).into_iter().flatten();
        let (lo, hi) = batch.groups.iter().flatten().flat_map(ends).fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)));
        let near = cx.corners.near_box(lo, hi, cx.cp.reach * cx.cp.step);
        let curves: Vec<Curve> = std::mem::take(&mut batch.groups)
            .into_par_iter()
            .map(|group| {
                let near = near.near(group.iter().flat_map(ends));
                complete::complete(group, &near, &cx.cp, &self.opts.cancel)
            })
            .flatten()
            .collect();
        batch.vertices = 0;
        self.opts.cancel.check()?;
        let attributed = self.attribute(cx, curves, batch.traced)?;
        batch.traced += attributed.len() as u32;
        let (min_confidence, min_length) = (self.opts.min_confidence, self.opts.min_length);
        let mut kept: Vec<Polyline> = attributed.into_iter().filter(|c| c.confidence as f64 >= min_confidence && c.length() >= min_length).collect();
        cx.outside.label(&mut kept);
        counts.curves += kept.len() as u64;
        records::write(&self.ws, batch.written, &Finished(kept))?;
        batch.written += 1;
        Ok(())
    }

    /// Each curve's vertex normals and evidence, from the smoothed edge points a block at a
    /// time: each vertex and each place along a curve is looked up in the block that holds it
    /// (or, off every block, the one it is within a step of), with the smoothed edge points
    /// within a step and a half of that block.
    fn attribute(&self, cx: &Completion, curves: Vec<Curve>, first: u32) -> Result<Vec<Polyline>> {
        let (blocks, step) = (cx.blocks, cx.r.step);
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
        let mut smoothed = Recent::new(budgets::smoothed_kept(self.opts.memory));
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
        Ok(curves.into_iter().zip(gathered).enumerate().map(|(id, (c, g))| polylines::finish(first + id as u32, c, g, cx.origin, step)).collect())
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
