//! The curve stage's survey of the edge points: what every tile's edge points come to before
//! any block is grown (the counts of stages 1 and 2, the grouped corners, the growth blocks),
//! kept in the working data as a [`Survey`] record.

use super::records::{self, Record, Survey};
use super::state::Run;
use crate::error::Result;
use crate::extract::blocks::{self, Census, Layers};
use crate::extract::polylines::{self, CornerGrouping};
use crate::extract::{Counts, Resolved};
use crate::keys::snap_quantum;
use glam::DVec3;
use rayon::prelude::*;

impl Run<'_> {
    /// A tile's edge points, snapped, with its corners and counts.
    pub(super) fn stored_edges(&self, t: u32, q: f64) -> Result<crate::extract::TileEdges> {
        let mut e = records::read::<records::Edges>(&self.ws, t)?.0;
        for x in e.edges.iter_mut() {
            polylines::snap_edge(x, q);
        }
        Ok(e)
    }

    /// The survey of the edge points: as kept by an earlier invocation (or by worker 0), else
    /// made from the tiles (and kept, by the process that writes the run's shared files).
    pub(super) fn survey(&self, r: &Resolved) -> Result<Survey> {
        let side = self.opts.block_steps * r.step;
        // (A damaged survey, or one of blocks of another side, is made again.)
        if let Ok(kept) = records::read::<Survey>(&self.ws, 0)
            && kept.side == side
        {
            return Ok(kept);
        }
        let survey = self.survey_edges(r, side)?;
        if self.leads() {
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
        // (The curves, to the bit, follow the anchor: it is the low corner of the points
        // themselves, as in memory, not the grid's origin, the corner of the bounds the inputs
        // declare, which a LAS header may round outwards. The two are one where the header is
        // exact, and where far points were left out the grid was planned over the points.)
        let m = &self.manifest;
        let anchor = DVec3::from(match (m.kept, m.points_min) {
            (None, Some(min)) => min,
            _ => m.grid.origin,
        });
        let cell = Census::new(side).cell_side();
        let mut counts = Counts::default();
        // (Tiles are decoded in parallel, a few at a time, and reduced to what is kept.)
        let seen = self
            .tiles
            .par_iter()
            .map(|&t| {
                // (A tile's edges a time: thousands of tiles took seconds.)
                self.opts.cancel.check()?;
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
                self.opts.cancel.check()?;
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
}
