//! The public types of a run: its options ([`RunOptions`], checked by
//! [`RunOptions::validate`]), the worker a process is ([`Worker`]) and what an invocation got
//! done ([`WorkerStep`]), and what a run reports ([`Report`], [`Extraction`]).

use super::budgets::MIN_MEMORY;
use crate::cancel::Cancel;
use crate::curves::{Curves, Format, Outside, Polyline, Shape};
use crate::debug::DebugDump;
use crate::error::{Error, Result};
use crate::extract::{polylines, Counts, Resolved, Timings};
use crate::points::Crs;
use serde::Serialize;
use std::path::PathBuf;

/// Options of a run beyond the method parameters.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Memory budget in bytes.
    pub memory: u64,
    /// Tile edge length override.
    pub tile_size: Option<f64>,
    /// Start over, whatever the directory holds.
    pub force: bool,
    /// Progress output.
    pub progress: crate::progress::Mode,
    /// Also tells each stage's counts to this, whatever `progress` is, for a caller that draws
    /// its own progress (the Python binding).
    pub watch: Option<crate::progress::Watch>,
    /// Stops the run after the tile in hand (Ctrl-C, SIGTERM).
    pub cancel: Cancel,
    /// Where intermediate point sets are written, if anywhere.
    pub debug: DebugDump,
    /// Curves below this confidence are left out of the outputs (see
    /// [`Polyline::confidence`](crate::curves::Polyline::confidence)). An output filter: a
    /// finished run given another value writes its outputs again, without recomputing tiles.
    pub min_confidence: f64,
    /// Curves shorter than this (model units) are left out of the outputs (an output filter).
    pub min_length: f64,
    /// Called with each warning as it is found (they are also listed in the report).
    pub warn: fn(&str),
    /// The CRS of the outputs whatever the inputs say (an output setting, as `--a-srs`).
    pub assign_crs: Option<Crs>,
    /// Where the scanners saw the surfaces from, which tells convex curves from concave ones
    /// (an output setting); None takes the scanner positions the inputs give (E57), if any.
    pub outside: Option<Outside>,
    /// Input directories are searched in their subdirectories too.
    pub recursive: bool,
    /// The curve files written (an output setting).
    pub formats: Vec<Format>,
    /// Also writes a copy of each input file's points labelled by the curves (`--label-points`;
    /// an output setting): see [`crate::io::write_labelled`].
    pub label_points: bool,
    /// Where the working data (the tile store and the per-tile results, most of a run's disk
    /// use) goes, if not in the run directory; a resumed run keeps the one it started with.
    pub work_dir: Option<PathBuf>,
    /// Removes the working data once the outputs are written: the run can then no longer be
    /// resumed, re-filtered or viewed over its points, only run again with `force`.
    pub clean: bool,
    /// Side of the curve stage's growth blocks, in polyline steps (see
    /// `crate::extract::blocks`). Smaller blocks cut more polylines for the stitcher to
    /// join; the default suits every input, and the option is there for tests and
    /// measurements.
    pub block_steps: f64,
}

impl Default for RunOptions {
    /// Half of the machine's memory, tiles sized from it, quiet, not forced.
    fn default() -> Self {
        RunOptions {
            memory: (crate::mem::total_memory() / 2).max(256 << 20),
            tile_size: None,
            force: false,
            progress: crate::progress::Mode::Quiet,
            watch: None,
            cancel: Cancel::default(),
            debug: DebugDump::default(),
            min_confidence: polylines::DEFAULT_MIN_CONFIDENCE,
            min_length: 0.0,
            warn: |_| {},
            assign_crs: None,
            outside: None,
            recursive: false,
            formats: Format::DEFAULT.to_vec(),
            label_points: false,
            work_dir: None,
            clean: false,
            block_steps: crate::extract::blocks::BASE_STEPS,
        }
    }
}

impl RunOptions {
    /// Checks the options, with the message the command line shows for each: a memory budget
    /// of at least `MIN_MEMORY`, a positive finite tile size and block side, a confidence
    /// from 0 to 1, a finite length of 0 or more. Every entry point calls it.
    ///
    /// ```
    /// use crease::run::RunOptions;
    /// assert!(RunOptions::default().validate().is_ok());
    /// let bad = RunOptions { min_confidence: 2.0, ..RunOptions::default() };
    /// assert_eq!(bad.validate().unwrap_err().to_string(), "--min-confidence must be between 0 and 1");
    /// ```
    pub fn validate(&self) -> Result<()> {
        let refuse = |m: String| Err(Error::Usage(m));
        if self.memory < MIN_MEMORY {
            return refuse(format!("--memory must be at least {} KiB", MIN_MEMORY >> 10));
        }
        if let Some(t) = self.tile_size
            && !(t > 0.0 && t.is_finite())
        {
            return refuse("--tile-size must be a positive number".into());
        }
        if !(0.0..=1.0).contains(&self.min_confidence) {
            return refuse("--min-confidence must be between 0 and 1".into());
        }
        if !(self.min_length >= 0.0 && self.min_length.is_finite()) {
            return refuse("--min-length must be a length of 0 or more".into());
        }
        if !(self.block_steps > 0.0 && self.block_steps.is_finite()) {
            return refuse("--block-steps must be a positive number".into());
        }
        Ok(())
    }
}

/// One of `count` processes sharing a run: worker `index` does the tiles whose number modulo
/// `count` is `index`; worker 0 also plans, buckets, and writes the outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Worker {
    /// This worker's index, below `count`.
    pub index: u32,
    /// Number of workers.
    pub count: u32,
}

impl Worker {
    /// True for the worker that plans, buckets and writes: worker 0, or a lone run.
    pub(super) fn leads(w: Option<Worker>) -> bool {
        w.is_none_or(|w| w.index == 0)
    }
}

impl std::str::FromStr for Worker {
    type Err = String;

    /// `I/N`, as `--worker` takes it (`$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`, say).
    fn from_str(s: &str) -> std::result::Result<Worker, String> {
        let bad = || format!("{s}: a worker is I/N, its index I (from 0) of N workers");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (i.trim().parse::<u32>().map_err(|_| bad())?, n.trim().parse::<u32>().map_err(|_| bad())?);
        if index >= count {
            return Err(format!("{s}: worker index {index} is not below the number of workers {count}"));
        }
        Ok(Worker { index, count })
    }
}

/// What one invocation of a worker got done (see [`super::run_worker`]).
#[derive(Clone, Debug)]
pub enum WorkerStep {
    /// The run finished here: its outputs are written.
    Finished(Box<Report>),
    /// This worker's share is done as far as it can go; what it waits for, for example
    /// "residuals: 5 of 8 tiles done (the other workers' share)".
    Waiting(String),
    /// The run had already finished (its outputs written by worker 0): nothing is left to do.
    AlreadyFinished,
}

/// Most worker threads a core may be given: more only adds switching and memory.
pub const MAX_THREADS_PER_CORE: usize = 4;

/// Refuses a thread count above [`MAX_THREADS_PER_CORE`] a core, with the message `--threads`
/// gives (a typo such as 10000 would otherwise start that many threads).
pub fn check_threads(n: usize) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if n > MAX_THREADS_PER_CORE * cores {
        return Err(Error::Usage(format!("--threads {n}: at most {} on this machine ({MAX_THREADS_PER_CORE} a core)", MAX_THREADS_PER_CORE * cores)));
    }
    Ok(())
}

/// What `report.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// crease version.
    pub version: String,
    /// Input files.
    pub inputs: Vec<PathBuf>,
    /// Parameters with defaults resolved.
    pub params: Resolved,
    /// Residual threshold used.
    pub tau: f64,
    /// Confidence below which curves were left out.
    pub min_confidence: f64,
    /// Length below which curves were left out.
    pub min_length: f64,
    /// Counts per stage.
    pub counts: Counts,
    /// Seconds per stage.
    pub seconds: Timings,
    /// Seconds per pass of this invocation (bucketing, statistics, residuals, projection,
    /// curves, writing); passes finished by an earlier invocation count 0.
    pub pass_seconds: PassSeconds,
    /// Total wall-clock seconds of this invocation.
    pub total_seconds: f64,
    /// Peak resident memory of this invocation, bytes.
    pub peak_rss_bytes: u64,
    /// Peak resident memory of this invocation up to the end of the tile passes, bytes.
    pub peak_rss_tiles_bytes: u64,
    /// Peak resident memory during the curve stage (stages 3-5), bytes, as sampled every few
    /// milliseconds (see `crate::mem::PeakSampler`).
    pub peak_rss_curves_bytes: u64,
    /// Peak resident memory while the outputs were written, bytes, sampled the same way.
    pub peak_rss_outputs_bytes: u64,
    /// Peak resident memory while the points were labelled (`--label-points`; 0 without),
    /// bytes, sampled the same way.
    pub peak_rss_labels_bytes: u64,
    /// Worker threads.
    pub threads: usize,
    /// Tiles in the grid.
    pub tiles: usize,
    /// Tile edge length.
    pub tile_size: f64,
    /// Halo width.
    pub halo: f64,
    /// True if this invocation continued an interrupted run.
    pub resumed: bool,
    /// Per-tile results of an earlier invocation that were damaged, and were computed again.
    pub repaired: Vec<PathBuf>,
    /// What the run found doubtful but went on with (files passed over, a CRS assumed, header
    /// bounds replaced, coarse coordinates).
    pub warnings: Vec<String>,
    /// The outputs' CRS, with its units (lengths in this report are in the horizontal unit).
    pub crs: Crs,
    /// Where the scanners saw the surfaces from (`--outside`, or the inputs' scan positions).
    pub outside: Outside,
    /// Curves written, by shape.
    pub shapes: ShapeCounts,
    /// The labelled copies of the inputs (`--label-points`), if asked for.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub labels: Vec<PathBuf>,
    /// What stage 2 cost per point it worked on: its seconds per candidate and per edge point
    /// found, in microseconds (the projection model's cost, whatever the cloud's size).
    pub projection_cost: ProjectionCost,
}

/// Stage 2's seconds ([`Timings::projection`]) per candidate and per edge point, in
/// microseconds (0 where there were none).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct ProjectionCost {
    /// Microseconds per candidate projected.
    pub per_candidate_us: f64,
    /// Microseconds per edge point found.
    pub per_edge_point_us: f64,
}

impl ProjectionCost {
    pub(super) fn of(seconds: &Timings, counts: &Counts) -> ProjectionCost {
        let per = |n: u64| if n > 0 { 1e6 * seconds.projection / n as f64 } else { 0.0 };
        ProjectionCost { per_candidate_us: per(counts.candidates), per_edge_point_us: per(counts.edge_points) }
    }
}

/// Curves written, by [`Shape`].
#[derive(Clone, Debug, Default, Serialize)]
pub struct ShapeCounts {
    /// Convex curves.
    pub convex: u64,
    /// Concave curves.
    pub concave: u64,
    /// Curves whose shape was not told.
    pub unknown: u64,
}

impl ShapeCounts {
    pub(super) fn of(curves: &(impl Curves + ?Sized)) -> Result<ShapeCounts> {
        let mut n = ShapeCounts::default();
        curves.each(&mut |c| {
            *match c.shape {
                Shape::Convex => &mut n.convex,
                Shape::Concave => &mut n.concave,
                Shape::Unknown => &mut n.unknown,
            } += 1;
            Ok(())
        })?;
        Ok(n)
    }
}

/// Seconds per pass.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PassSeconds {
    /// Reading and bucketing the inputs.
    pub bucketing: f64,
    /// Spacing and noise statistics.
    pub statistics: f64,
    /// Stage 1 over all tiles.
    pub residuals: f64,
    /// Stage 2 over all tiles.
    pub projection: f64,
    /// Stages 3-5 on the edge cloud.
    pub curves: f64,
    /// Of the statistics pass, seconds the loader thread spent reading tiles and building
    /// their k-d trees (overlapping the fits of the tile before).
    pub statistics_load: f64,
    /// The same for the residual pass.
    pub residuals_load: f64,
    /// The same for the projection pass.
    pub projection_load: f64,
    /// Writing outputs.
    pub writing: f64,
    /// Writing the labelled copies of the inputs (`--label-points`).
    pub labelling: f64,
}

/// The result of an in-memory extraction.
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
