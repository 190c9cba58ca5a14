//! The curve stage (stages 3-5) over the edge points of every tile, by region: the edge cloud
//! is surveyed ([`super::survey`]) and taken a growth block at a time (see
//! [`crate::extract::blocks`] and [`super::grow`]); the blocks' pieces a slab of blocks at a
//! time, handed on in clusters that can be stitched and completed alone (see
//! [`super::complete`]); completion takes a batch of groups of lines at a time, and the
//! finished curves go to the working data batch by batch, for the writers to read back. What
//! it holds whole is the survey: the blocks and the grouped corners.

use super::complete::Completion;
use super::records::Survey;
use super::state::{done, Run, Step};
use crate::curves::Outside;
use crate::error::Result;
use crate::extract::{Counts, Resolved, Timings};
use std::time::Instant;

/// What the curve stage hands on: the number of batches of finished curves it wrote (see
/// `Run::finished_curves`), the counts of every stage, the seconds of each, and its peak
/// resident memory (bytes).
pub(super) struct CurveStage {
    pub(super) batches: u32,
    pub(super) counts: Counts,
    pub(super) seconds: Timings,
    pub(super) peak_rss: u64,
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
    /// Done with what the stage wrote, or waiting if this process is a worker whose share is
    /// done but whose run is not.
    pub(super) fn curves(&mut self, r: &Resolved, outside: &Outside) -> Result<Step<CurveStage>> {
        let t = Instant::now();
        crate::mem::release_free_memory();
        let peak = crate::mem::PeakSampler::start();
        let survey = self.survey(r)?;
        let mut seconds = Timings { candidates: self.pass.residuals, projection: self.pass.projection, index: self.pass.statistics, ..Default::default() };
        self.grow_blocks(&survey, r, &mut seconds)?;
        if !self.leads() {
            return Ok(Step::Waiting("the curves and outputs (worker 0 writes them)".into()));
        }
        done!(self.all_grown(&survey));
        let Survey { counts, blocks, grouped, origin, .. } = survey;
        let mut counts = Counts {
            points: self.manifest.tile_points.iter().sum(),
            far_points: self.manifest.far_points,
            exact_duplicates: self.manifest.duplicates[0],
            near_duplicates: self.manifest.duplicates[1],
            evaluated: self.evaluated,
            corners: grouped.len() as u64,
            blocks: blocks.list.len() as u64,
            ..counts
        };
        if self.opts.debug.on() {
            self.opts.debug.points("corners.obj", &grouped, origin);
        }
        let tc = Instant::now();
        let batches = self.complete(&Completion::new(&grouped, &blocks, origin, r, outside), &mut counts)?;
        // (What the stage freed goes back to the system before the outputs are written.)
        crate::mem::release_free_memory();
        seconds.completion = tc.elapsed().as_secs_f64();
        self.pass.curves = t.elapsed().as_secs_f64();
        Ok(Step::Done(CurveStage { batches, counts, seconds, peak_rss: peak.finish() }))
    }
}
