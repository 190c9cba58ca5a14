//! The pipeline: plan, bucket, statistics, residuals, projection, curves, write, over a
//! workspace that is a resumable run directory ([`run_extract`]) or memory
//! ([`extract_cloud`]). The stages' work is in [`crate::extract`]; this module only
//! orchestrates: the manifest, the plan, bucketing, the tile pass engine, the record codec of
//! the per-tile results, and status.
//!
//! 1. **Plan** from the headers: bounds, counts, CRS, a tile grid (2D for airborne-like extents,
//!    3D otherwise) sized from `--memory` (a tile holds at most [`MAX_TILE_POINTS`]).
//! 2. **Bucket**: one streaming pass over the inputs writes every point once, to its tile,
//!    zstd-compressed in spatial chunks (16 per tile edge, each headed by its bounding box), so
//!    that assembling a tile's halo decompresses only the neighbours' border chunks.
//! 3. **Tile passes** (statistics, residuals, projection), each tile with its halo: one loader
//!    thread reads the next tile while the current one is computed on all cores.
//! 4. **Curves**, a growth block of the edge cloud at a time (blocks depend on the edge cloud,
//!    not on the tiles); the blocks' pieces of polylines are read a slab at a time, stitched and
//!    completed a cluster at a time, and written a batch at a time, so that no step holds every
//!    polyline (see [`crate::extract`] for the method of each step).
//! 5. **Write** the outputs from the finished batches; the output filters apply last.
//!
//! Run directory layout:
//! - `manifest.json`: the job (inputs with size, mtime and header checksum; parameters; crease
//!   version), the plan (grid), and what is done;
//! - `tiles/`: bucketed points; `stats/`, `resid/`, `edges/`: one result file per tile and pass;
//!   `survey/`, `smoothed/`, `pieces/`: the curve stage's, one file per growth block;
//!   `finished/`: the curves a batch at a time; each file a record of the codec (see `codec.rs`:
//!   a header with the kind of record, a format number and a CRC-32, then a zstd payload);
//! - `curves.*`, `preview.png`, `report.json`: the outputs;
//! - `lock`, and `lock.<i>` for worker `i` of several sharing the run ([`run_worker`]), removed
//!   when the run ends.
//!
//! With `--work-dir`, the working data is in that directory instead, which names its run in
//! `crease-run`. The working data lets an interrupted run continue and a finished one write its
//! outputs again with other output settings; `--clean` removes it, and the run is then final.
//! A damaged per-tile or per-block result is computed again and listed in `report.json`
//! (`repaired`); a damaged tile store or manifest stops the run naming the file (exit 65).
//!
//! Every file is written to a temporary name, synced and renamed, and only then counted as
//! done, so a run killed at any moment resumes where it stopped and ends with the same curves.
//! Results do not depend on the tiling, the thread count, or how the cloud is split into files:
//! random choices are keyed by point position and neighbourhoods are ordered by coordinates;
//! whether a point lies in a ball is decided in f64 (the f32 tree is queried wide enough for its
//! coordinates' rounding); a sparse neighbourhood is widened no farther than the halo, and a
//! statistics sample whose ball reaches past the halo is recomputed with a wider one; tau is an
//! exact fixed-point sum, and spacing, noise and tau are rounded to 32 significant bits, so the
//! last bits of tile-local arithmetic cannot flip a decision.
//!
//! Workers ([`run_worker`], `--worker I/N`) share a run over a directory they all see: each
//! does what is left of its share of the first unfinished pass (tiles `t % N == I`; then a run of
//! neighbouring growth blocks) and exits 0 when it must wait for the others; worker 0 also plans,
//! buckets, and, once every block is grown, stitches, completes and writes the outputs.

pub(crate) mod bucket;
mod curves;
pub(crate) mod far;
pub mod manifest;
pub(crate) mod pass;
pub mod plan;
pub(crate) mod records;
pub mod status;

pub(crate) use bucket::Input;
pub use manifest::{common_crs, InputStamp, Job, Manifest};
pub use plan::{tile_size_for, BYTES_PER_POINT, MAX_TILE_POINTS};
pub use status::{render_status, status, Status};

use crate::cancel::Cancel;
use crate::curves::{typed, Curves, Format, Outside, Polyline, Shape};
use crate::debug::DebugDump;
use crate::error::{Error, Result};
use crate::extract::candidates::{self, ResidualSum};
use crate::extract::params::Model;
use crate::extract::polylines;
use crate::extract::statistics::{self, StatsTile};
use crate::extract::{project, Counts, Params, Resolved, Timings};
use crate::io::{self, Filter};
use crate::keys::{keep_point, key_quantum, position_key, settle};
use crate::points::{Bounds, Crs, TilePoints};
use crate::progress::Progress;
use crate::tiles::{Bucketer, Grid, Store};
use crate::workspace::Workspace;
use glam::DVec3;
use pass::{tile_pass, Loading, PassContext};
use rayon::prelude::*;
use records::{Edges, Record, Residuals, Stats};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

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
    /// Where the working data (the tile store and the per-tile results, most of a run's disk
    /// use) goes, if not in the run directory; a resumed run keeps the one it started with.
    pub work_dir: Option<PathBuf>,
    /// Removes the working data once the outputs are written: the run can then no longer be
    /// resumed, re-filtered or viewed over its points, only run again with `force`.
    pub clean: bool,
    /// Side of the curve stage's growth blocks, in polyline steps (see
    /// [`crate::extract::blocks`]). Smaller blocks cut more polylines for the stitcher to
    /// join; the default suits every input, and the option is there for tests and
    /// measurements.
    pub block_steps: f64,
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
    fn leads(w: Option<Worker>) -> bool {
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

/// What one invocation of a worker got done (see [`run_worker`]).
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
            work_dir: None,
            clean: false,
            block_steps: crate::extract::blocks::BASE_STEPS,
        }
    }
}

/// The smallest memory budget a run takes: room for a tile of a few thousand points and a
/// batch of curves (the tests' smallest fixtures run in 0.6 MB, batched).
pub const MIN_MEMORY: u64 = 512 << 10;

impl RunOptions {
    /// Checks the options, with the message the command line shows for each: a memory budget
    /// of at least [`MIN_MEMORY`], a positive finite tile size and block side, a confidence
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
    /// Peak resident memory during the curve stage (stages 3-5 and the outputs), bytes, as
    /// sampled every few milliseconds (see [`crate::mem::PeakSampler`]).
    pub peak_rss_curves_bytes: u64,
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
    fn of(seconds: &Timings, counts: &Counts) -> ProjectionCost {
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
    fn of(curves: &(impl Curves + ?Sized)) -> Result<ShapeCounts> {
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

/// Runs (or resumes) extraction of `inputs` (files or directories) into the run directory
/// `dir`, writing `curves.obj`, `curves.ply`, `curves.geojson` and `report.json` there.
///
/// ```no_run
/// use crease::extract::Params;
/// use crease::io::Filter;
/// use crease::run::{run_extract, RunOptions};
/// use std::path::{Path, PathBuf};
///
/// let report = run_extract(&[PathBuf::from("scan.laz")], Path::new("run"), &Params::default(), &Filter::default(), &RunOptions::default())?;
/// println!("{} curves", report.counts.curves);
/// # Ok::<(), crease::Error>(())
/// ```
pub fn run_extract(inputs: &[PathBuf], dir: &Path, params: &Params, filter: &Filter, opts: &RunOptions) -> Result<Report> {
    match run_in(inputs, dir, params, filter, opts, None)? {
        WorkerStep::Finished(report) => Ok(*report),
        // (A lone run does every tile itself: it has nothing to wait for.)
        WorkerStep::Waiting(what) => Err(Error::Usage(format!("{}: {what}", dir.display()))),
        WorkerStep::AlreadyFinished => Err(Error::Usage(format!("{}: finished by workers; a lone run would start it over", dir.display()))),
    }
}

/// [`run_extract`] as one of several processes sharing the run directory `dir` (on one
/// machine, or on a cluster's shared file system): `worker` does its share of each pass, and
/// goes on to the next pass once every worker's share of this one is done; worker 0 also
/// plans the run, buckets the points and, once all passes are done, writes the outputs. Each
/// invocation does what it can and returns: the outputs' report if it wrote them, otherwise
/// what it waits for; invoked again, a worker picks up where it stopped (a killed worker's
/// tiles are done by its next invocation). The curves are the same bytes as those of
/// [`run_extract`] on the same input.
///
/// ```no_run
/// use crease::run::{run_worker, RunOptions, Worker, WorkerStep};
/// let (inputs, dir) = (vec!["scan.laz".into()], std::path::Path::new("run"));
/// let me: Worker = "1/3".parse().unwrap();
/// match run_worker(&inputs, dir, &Default::default(), &Default::default(), &RunOptions::default(), me)? {
///     WorkerStep::Finished(report) => println!("{} curves", report.counts.curves),
///     WorkerStep::Waiting(what) => println!("waiting for {what}"),
///     WorkerStep::AlreadyFinished => println!("finished"),
/// }
/// # Ok::<(), crease::Error>(())
/// ```
pub fn run_worker(inputs: &[PathBuf], dir: &Path, params: &Params, filter: &Filter, opts: &RunOptions, worker: Worker) -> Result<WorkerStep> {
    run_in(inputs, dir, params, filter, opts, Some(worker))
}

fn run_in(inputs: &[PathBuf], dir: &Path, params: &Params, filter: &Filter, opts: &RunOptions, worker: Option<Worker>) -> Result<WorkerStep> {
    let t0 = Instant::now();
    params.validate()?;
    opts.validate()?;
    // (An input directory that is also the run directory holds the run's own curves.ply: a
    // second run would read it as points.)
    let run_dir = dir.canonicalize().ok();
    // (Nor may a work directory's tile store, `.pts` files, be read as text clouds.)
    let in_work_dir = |c: &Path| c.ancestors().skip(1).any(|a| a.join(WORK_OWNER).is_file());
    let in_run_dir = |f: &Path| f.canonicalize().is_ok_and(|c| run_dir.as_deref().is_some_and(|r| is_run_file(r, &c)) || in_work_dir(&c));
    let expanded = io::expand_inputs(inputs, opts.recursive)?;
    // (Another run's directory holds its curves and tile store, not a scan.)
    let other_runs = other_run_directories(&expanded.files, run_dir.as_deref());
    let in_run_dir = |f: &Path| in_run_dir(f) || f.canonicalize().is_ok_and(|c| other_runs.iter().any(|d| c.starts_with(d)));
    let mut warnings = Warnings::new(opts.warn);
    for d in &other_runs {
        warnings.push(format!("{}: passed over: a crease run directory (its curves and working files are not a scan)", d.display()));
    }
    warnings.extend(expanded.warnings(in_run_dir));
    let in_run_dir = |f: &PathBuf| in_run_dir(f);
    let files: Vec<PathBuf> = expanded.files.into_iter().filter(|f| !in_run_dir(f)).collect();
    let Some(first) = files.first() else {
        return match inputs.first() {
            Some(dir) => Err(Error::input(dir, "holds no point files but the run's own outputs")),
            None => Err(Error::Usage("no input files".into())),
        };
    };
    let first = first.clone();
    let headers = files.iter().map(|f| io::read_header(f)).collect::<Result<Vec<_>>>()?;
    let crs = match &opts.assign_crs {
        Some(assigned) => {
            for h in headers.iter().filter(|h| !h.crs.is_unknown() && !h.crs.agrees(assigned)) {
                warnings.push(format!("{}: its CRS {} is replaced by the one assigned, {}", h.path.display(), h.crs.summary(), assigned.summary()));
            }
            assigned.clone()
        }
        None => {
            let (crs, crs_warnings) = common_crs(&headers)?;
            warnings.extend(crs_warnings);
            crs
        }
    };
    for h in headers.iter().filter(|h| h.format.has_header_bounds() && !h.bounds.is_usable()) {
        warnings.push(format!("{}: the header's bounds are not usable (not finite or inverted); bounds come from the points", h.path.display()));
    }
    let job = Job {
        version: env!("CARGO_PKG_VERSION").to_string(),
        inputs: files.iter().map(|f| manifest::stamp(f)).collect::<Result<_>>()?,
        params: params.without_defaults(),
        classes: filter.classes.clone(),
        keep_noise: filter.keep_noise,
        text: filter.text,
        bounds: filter.bounds,
        tile_size: opts.tile_size,
        memory: opts.memory,
    };
    let mut ws = Workspace::disk(dir)?;
    ws.lock(worker.map(|w| w.index))?;
    if !Worker::leads(worker) {
        if opts.force {
            return Err(Error::Usage("--force starts a run over: give it to worker 0 (or a lone run), not to the others".into()));
        }
        if manifest::read(&ws)?.is_none() {
            return Ok(WorkerStep::Waiting("the run to be planned (worker 0 plans it and buckets the points)".into()));
        }
    }
    let bounds = || -> Result<(Bounds, u64)> {
        let mut b = Bounds::EMPTY;
        let mut declared = 0;
        for h in &headers {
            // (Header bounds that are missing (PLY, E57, text), not finite or inverted come
            // from the points.)
            if h.bounds.is_usable() {
                b.union(&h.bounds);
                declared += h.count;
            } else {
                let (scanned, n) = io::scan_bounds(&h.path, filter)?;
                b.union(&scanned);
                // (Text clouds declare no count: the scan's stands in.)
                declared += if h.count > 0 { h.count } else { n };
            }
        }
        if b.is_empty() {
            return Err(Error::input(&first, "no points"));
        }
        if let Some(only) = &filter.bounds {
            let inside = b.intersection(only);
            if inside.is_empty() {
                return Err(Error::Usage(format!("--bounds ({}) holds none of the inputs' points ({})", only.ranges(), b.ranges())));
            }
            b = inside;
        }
        Ok((b, declared))
    };
    let (manifest, resumed) = plan(&mut ws, job, bounds, opts, worker)?;
    // (Worker 0 writes the outputs, again if an output setting changed; the others had nothing
    // left to do once it finished, and were told to wait for ever.)
    if manifest.finished && !Worker::leads(worker) {
        return Ok(WorkerStep::AlreadyFinished);
    }
    let mut run = Run::new(ws, manifest, opts, worker);
    let Some(r) = run.tile_passes(&Input::Files(&files, filter), params, &first)? else {
        return Ok(WorkerStep::Waiting(run.waiting.take().unwrap_or_default()));
    };
    if let Some(kept) = run.manifest.kept.filter(|_| run.manifest.far_points > 0) {
        warnings.push(format!(
            "{} points lie far from all the others (farther out than the rest of the cloud is wide) and were left out; the rest lie within {}",
            run.manifest.far_points,
            kept.ranges()
        ));
    }
    let tau = run.tau;
    let outside = opts.outside.clone().unwrap_or_else(|| scanned_from(&headers));
    let Some((batches, counts, seconds)) = run.curves(&r, &outside)? else {
        return Ok(WorkerStep::Waiting(run.waiting.take().unwrap_or_default()));
    };
    if counts.clusters_cut > 0 {
        warnings.push(format!(
            "{} clusters of pieces of polylines held more than {} vertices and were cut where the curve stage's sweep had passed them: curves across such a cut may come out in two",
            counts.clusters_cut,
            crate::extract::sweep::MAX_CLUSTER_VERTICES
        ));
    }
    let curves = run.finished_curves(batches);
    let shapes = ShapeCounts::of(&curves)?;
    let t = Instant::now();
    write_outputs(run.ws.root(), &curves, &crs, &run.preview_sample()?, &opts.formats, typed::tolerance(r.kappa, r.noise))?;
    run.finished(t)?;
    for h in &headers {
        warnings.extend(coarse_coordinates(h, &run.manifest.grid, r.kappa));
    }
    let mut report = run.report(files, r, tau, counts, seconds, t0, resumed);
    report.warnings = warnings.into_list();
    report.crs = crs;
    report.shapes = shapes;
    report.outside = outside;
    run.ws.write_atomic("report.json", serde_json::to_string_pretty(&report).expect("report serialises").as_bytes())?;
    if opts.clean {
        run.clean()?;
    }
    Ok(WorkerStep::Finished(Box::new(report)))
}

/// Where the inputs say their scanners stood: [`Outside::Scanners`] if any file gives scan
/// positions (E57), else [`Outside::Unknown`].
fn scanned_from(headers: &[crate::points::CloudHeader]) -> Outside {
    let scanners: Vec<DVec3> = headers.iter().flat_map(|h| h.scanners.iter().copied()).collect();
    if scanners.is_empty() {
        Outside::Unknown
    } else {
        Outside::Scanners(scanners)
    }
}

/// Warnings of a run: each is passed to the run's handler as it is found, and listed in the
/// report.
struct Warnings {
    handler: fn(&str),
    list: Vec<String>,
}

impl Warnings {
    fn new(handler: fn(&str)) -> Self {
        Warnings { handler, list: vec![] }
    }

    fn push(&mut self, w: String) {
        (self.handler)(&w);
        self.list.push(w);
    }

    fn into_list(self) -> Vec<String> {
        self.list
    }
}

impl Extend<String> for Warnings {
    fn extend<I: IntoIterator<Item = String>>(&mut self, iter: I) {
        for w in iter {
            self.push(w);
        }
    }
}

/// A warning when file `h` stores coordinates in steps coarser than half the point spacing
/// `kappa`: the quantisation then acts as noise of about a third of a step (RMS), as large as a
/// scanner's, and float32 files with large coordinates (UTM, say) lose the edges.
fn coarse_coordinates(h: &crate::points::CloudHeader, grid: &Grid, kappa: f64) -> Option<String> {
    // (PLY headers hold no bounds: the grid's box, which holds every file, stands in.)
    let far = std::array::from_fn(|a| grid.origin[a] + grid.dims[a] as f64 * grid.size);
    let b = if h.bounds.is_usable() { h.bounds } else { Bounds { min: grid.origin, max: far } };
    let step = h.precision.step(&b);
    let how = match h.precision {
        crate::points::Precision::Float(23) => "float32 coordinates",
        crate::points::Precision::Float(_) => "float64 coordinates",
        crate::points::Precision::Scaled(_) => "its scale factor",
    };
    (step > 0.5 * kappa).then(|| {
        format!(
            "{}: {how} step by {step:.3e} here, {:.1} times the point spacing ({kappa:.3e}): the curves lose detail{}",
            h.path.display(),
            step / kappa,
            if matches!(h.precision, crate::points::Precision::Float(23)) { "; store double coordinates or move the origin nearer" } else { "" }
        )
    })
}

/// Extracts feature curves from `points` (world coordinates) held in memory: the same pipeline
/// as [`run_extract`], over a workspace in memory.
///
/// ```
/// use crease::extract::Params;
/// use crease::run::{extract_cloud, RunOptions};
/// use crease::synth::{sample, shapes, SynthOptions};
///
/// let cube = shapes::shape("cube", 90.0).unwrap();
/// let points = sample(&cube, &SynthOptions { n: 60_000, ..Default::default() });
/// let x = extract_cloud(&points, &Params::default(), &RunOptions::default())?;
/// assert_eq!(x.curves.len(), 12);
/// # Ok::<(), crease::Error>(())
/// ```
pub fn extract_cloud(points: &[DVec3], params: &Params, opts: &RunOptions) -> Result<Extraction> {
    params.validate()?;
    opts.validate()?;
    let here = PathBuf::from("<memory>");
    let job = Job {
        version: env!("CARGO_PKG_VERSION").to_string(),
        inputs: vec![],
        params: params.clone(),
        classes: None,
        keep_noise: true,
        text: None,
        bounds: None,
        tile_size: opts.tile_size,
        memory: opts.memory,
    };
    if let Some(p) = points.iter().find(|p| !p.is_finite()) {
        return Err(Error::input(&here, format!("a point is not finite: {p}")));
    }
    let bounds = || -> Result<(Bounds, u64)> {
        let b = Bounds::of(points.iter().copied());
        if b.is_empty() {
            return Err(Error::input(&here, "no points"));
        }
        Ok((b, points.len() as u64))
    };
    let mut ws = Workspace::memory();
    // (In memory there is no working data to put elsewhere or remove.)
    let opts = &RunOptions { work_dir: None, clean: false, ..opts.clone() };
    let (manifest, _) = plan(&mut ws, job, bounds, opts, None)?;
    let mut run = Run::new(ws, manifest, opts, None);
    // (A lone run does every tile itself: it has nothing to wait for.)
    let r = run.tile_passes(&Input::Points(points), params, &here)?.ok_or_else(|| Error::Usage(run.waiting.take().unwrap_or_default()))?;
    // (Points in memory give no scanner positions: only `outside` tells the shapes.)
    let outside = opts.outside.clone().unwrap_or_default();
    let Some((batches, counts, seconds)) = run.curves(&r, &outside)? else {
        return Err(Error::Usage(run.waiting.take().unwrap_or_default()));
    };
    let (finished, mut curves) = (run.finished_curves(batches), vec![]);
    finished.each(&mut |c| {
        curves.push(c.clone());
        Ok(())
    })?;
    Ok(Extraction { curves, params: r, tau: run.tau, counts, seconds })
}

/// The plan step: continues the job the workspace holds, or plans it anew (the tile grid over
/// `bounds()`, sized from the budget); a different job is refused, and `--force` always starts
/// over. Returns the
/// manifest and whether the run resumes.
fn plan(ws: &mut Workspace, job: Job, bounds: impl FnOnce() -> Result<(Bounds, u64)>, opts: &RunOptions, worker: Option<Worker>) -> Result<(Manifest, bool)> {
    // (With --force, whatever the directory holds, damaged or not, is replaced; so is the
    // working data of the run it held, wherever that was.)
    let held = if opts.force {
        if let Some(old) = manifest::read(ws).ok().flatten() {
            use_work_dir(ws, &old)?;
            remove_working_data(ws);
            ws.set_work_dir(None, &WORKING)?;
        }
        None
    } else {
        manifest::read(ws)?
    };
    match held {
        Some(m) if m.job == job => {
            if m.cleaned {
                return Err(Error::Usage(format!(
                    "{}: this run finished and its working data was removed (--clean), so it cannot write its outputs again; they are in the directory as they were; use --force to run it again",
                    ws.root().display()
                )));
            }
            let same = |w: &Path| m.work_dir.as_deref().is_some_and(|held| w.canonicalize().is_ok_and(|w| w == held));
            if opts.work_dir.as_deref().is_some_and(|w| !same(w)) {
                let was = m.work_dir.as_ref().map_or("the run directory".to_string(), |w| w.display().to_string());
                return Err(Error::Usage(format!(
                    "{}: this run keeps its working data in {was}: resume it with that --work-dir (or none), or use --force to start over",
                    ws.root().display()
                )));
            }
            if let (Some(n), Some(w)) = (m.workers, worker)
                && w.count != n
            {
                return Err(Error::Usage(format!(
                    "{}: this run is shared by {n} workers (--worker I/{n}), not {}: give every worker the same count, or use --force (worker 0) to start over",
                    ws.root().display(),
                    w.count
                )));
            }
            // (A manifest edited to point at another run's work directory would mix the two
            // runs' tiles and results.)
            if let Some(w) = &m.work_dir
                && let Ok(held) = std::fs::read_to_string(w.join(WORK_OWNER))
                && ws.root().canonicalize().is_ok_and(|run| held != format!("{}\n", run.display()))
            {
                return Err(Error::damaged(
                    ws.path(manifest::NAME),
                    format!("its work directory {} holds the working data of the run in {}", w.display(), held.trim()),
                ));
            }
            use_work_dir(ws, &m)?;
            // (An edited or damaged manifest must not size what the run allocates.)
            let g = &m.grid;
            let sane = g.tiles() <= crate::tiles::MAX_TILES && g.size > 0.0 && g.size.is_finite() && (!m.bucketed || m.tile_points.len() as u64 == g.tiles());
            if !sane {
                return Err(Error::damaged(ws.path(manifest::NAME), "its tile grid is not one crease planned"));
            }
            if m.resolved.as_ref().is_some_and(|r| !r.is_sane()) {
                return Err(Error::damaged(
                    ws.path(manifest::NAME),
                    "its resolved parameters are not ones the statistics pass gives (a length not positive, a share or an angle out of range)",
                ));
            }
            return Ok((m, true));
        }
        Some(m) => {
            return Err(Error::Usage(format!(
                "{}: holds a different run: {}; use --force to start over",
                ws.root().display(),
                manifest::job_difference(&m.job, &job)
            )))
        }
        _ => {}
    }
    let work_dir = match &opts.work_dir {
        Some(w) => Some(claim_work_dir(w, ws.root())?),
        None => None,
    };
    remove_working_data(ws);
    for name in [VIEW].into_iter().chain(OUTPUTS) {
        ws.remove(name);
    }
    if let Some(w) = &work_dir {
        ws.set_work_dir(Some(w), &WORKING)?;
        remove_working_data(ws);
    }
    let (b, declared) = bounds()?;
    let size = opts.tile_size.unwrap_or_else(|| tile_size_for(&b, declared, opts.memory));
    let grid = Grid::new(&b, size);
    if grid.tiles() > crate::tiles::MAX_TILES || !(size > 0.0 && size.is_finite()) {
        return Err(Error::Usage(format!(
            "tiles of size {size} over the bounds {:?} to {:?} would make {} tiles, more than the {} crease handles: use a larger --tile-size or --memory",
            b.min,
            b.max,
            grid.tiles(),
            crate::tiles::MAX_TILES
        )));
    }
    let m = Manifest {
        job,
        grid,
        declared_points: declared,
        diag: b.diagonal(),
        bucketed: false,
        tile_points: vec![],
        resolved: None,
        finished: false,
        work_dir,
        cleaned: false,
        kept: None,
        far_points: 0,
        workers: worker.map(|w| w.count),
        points_min: None,
    };
    manifest::save(ws, &m)?;
    Ok((m, false))
}

/// Most bucketing rounds: each leaves out the far points that the previous grid showed.
const FAR_ROUNDS: u32 = 4;

/// The top-level names of a run's working data: the tile store and the per-tile results.
const WORKING: [&str; 8] =
    [crate::tiles::DIR, Stats::DIR, Residuals::DIR, Edges::DIR, curves::Survey::DIR, records::Smoothed::DIR, records::Pieces::DIR, records::Finished::DIR];

/// Name of the file by which a work directory names the run directory it belongs to.
const WORK_OWNER: &str = "crease-run";

/// Points `ws` at the working data of the run `m` describes.
pub(crate) fn use_work_dir(ws: &mut Workspace, m: &Manifest) -> Result<()> {
    match &m.work_dir {
        Some(w) => ws.set_work_dir(Some(w), &WORKING),
        None => Ok(()),
    }
}

/// Removes a run's working data, wherever `ws` has it.
fn remove_working_data(ws: &Workspace) {
    for name in WORKING {
        ws.remove(name);
    }
}

/// Makes `dir` the work directory of the run in `run_dir`, returning it absolute: created if
/// need be, and refused if it is the run directory or holds another run's working data (two
/// runs there would overwrite each other's tiles).
fn claim_work_dir(dir: &Path, run_dir: &Path) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(|e| Error::output(dir, e))?;
    let (work, run) = (dir.canonicalize().map_err(|e| Error::output(dir, e))?, run_dir.canonicalize().map_err(|e| Error::output(run_dir, e))?);
    if work == run {
        return Err(Error::Usage(format!("--work-dir {}: that is the run directory; leave --work-dir out to keep the working data there", dir.display())));
    }
    let owner = work.join(WORK_OWNER);
    let mine = format!("{}\n", run.display());
    match std::fs::read_to_string(&owner) {
        Ok(held) if held != mine => {
            return Err(Error::Usage(format!(
                "--work-dir {}: holds the working data of the run in {}; give each run its own work directory",
                dir.display(),
                held.trim()
            )))
        }
        Ok(_) => {}
        Err(_) => crate::workspace::write_atomic(&owner, mine.as_bytes())?,
    }
    Ok(work)
}

/// A run in progress: its workspace, manifest and options, and what the steps found so far.
struct Run<'a> {
    ws: Workspace,
    manifest: Manifest,
    opts: &'a RunOptions,
    progress: Progress,
    pass: PassSeconds,
    /// Tiles that hold points.
    tiles: Vec<u32>,
    /// Quantum of the position keys.
    kq: f64,
    /// The residual threshold.
    tau: f64,
    /// Points whose residuals tau averages.
    evaluated: u64,
    /// Peak memory by the end of the tile passes.
    peak_rss_tiles: u64,
    /// Samples the memory of the curve stage, from its start to the report.
    curve_peak: Option<crate::mem::PeakSampler>,
    /// Damaged results removed to be computed again.
    repaired: Vec<PathBuf>,
    /// This process's share of a run that several share.
    worker: Option<Worker>,
    /// What a worker stopped for (see [`WorkerStep::Waiting`]).
    waiting: Option<String>,
}

impl<'a> Run<'a> {
    fn new(ws: Workspace, manifest: Manifest, opts: &'a RunOptions, worker: Option<Worker>) -> Run<'a> {
        let kq = key_quantum(manifest.diag);
        let progress = Progress::new(opts.progress, opts.watch.clone());
        let pass = PassSeconds::default();
        Run {
            ws,
            manifest,
            opts,
            progress,
            pass,
            tiles: vec![],
            kq,
            tau: 0.0,
            evaluated: 0,
            peak_rss_tiles: 0,
            curve_peak: None,
            repaired: vec![],
            worker,
            waiting: None,
        }
    }

    /// The tiles this process computes in a pass: all of them, or a worker's share.
    fn share(&self) -> Vec<u32> {
        self.tiles.iter().copied().filter(|&t| self.worker.is_none_or(|w| t % w.count == w.index)).collect()
    }

    /// True if every tile has its result of pass `R`; otherwise notes what a worker waits for.
    fn all_done<R: Record>(&mut self, pass: &str) -> bool {
        let done = self.tiles.iter().filter(|&&t| self.ws.exists(&records::name(R::DIR, t))).count();
        if done < self.tiles.len() {
            self.waiting = Some(format!("{pass}: {done} of {} tiles done (the other workers' share)", self.tiles.len()));
        }
        done == self.tiles.len()
    }

    /// Saves the manifest, if this process is the one that writes it (worker 0, or a lone
    /// run): workers side by side must not replace it under each other.
    fn save_manifest(&self) -> Result<()> {
        if Worker::leads(self.worker) {
            manifest::save(&self.ws, &self.manifest)?;
        }
        Ok(())
    }

    /// Checks the stored results of pass `R` (an earlier invocation's), and removes those that
    /// are damaged, so that the pass computes them again from the tiles.
    fn repair<R: Record>(&mut self) -> Result<()> {
        let mut damaged = vec![];
        for &t in &self.tiles {
            if self.ws.exists(&records::name(R::DIR, t)) {
                match records::read::<R>(&self.ws, t) {
                    Ok(_) => {}
                    Err(Error::Damaged { .. }) => damaged.push(t),
                    Err(e) => return Err(e),
                }
            }
        }
        for t in damaged {
            let name = records::name(R::DIR, t);
            self.ws.remove(&name);
            self.repaired.push(self.ws.path(&name));
        }
        Ok(())
    }

    fn context(&self) -> PassContext<'_> {
        PassContext { ws: &self.ws, progress: &self.progress, cancel: &self.opts.cancel }
    }

    /// Bucketing, statistics, residuals and projection: the steps that run tile by tile.
    /// Returns the resolved parameters; tau is kept.
    fn tile_passes(&mut self, input: &Input, params: &Params, first_input: &Path) -> Result<Option<Resolved>> {
        if !self.manifest.bucketed && !Worker::leads(self.worker) {
            self.waiting = Some("bucketing (worker 0 buckets the points)".into());
            return Ok(None);
        }
        self.bucket(input)?;
        let total: u64 = self.manifest.tile_points.iter().sum();
        if total < 10 {
            return Err(Error::input(first_input, format!("only {total} points after filtering: nothing to extract")));
        }
        self.tiles = (0..self.manifest.grid.len() as u32).filter(|&t| self.manifest.tile_points[t as usize] > 0).collect();
        let Some(r) = self.statistics(params)? else { return Ok(None) };
        // (All points at one position, or too few apart: every length of the method is zero.)
        if !(r.kappa > 0.0 && r.kappa.is_finite() && r.fit_radius > 0.0 && r.rmls_radius > 0.0) {
            return Err(Error::input(first_input, format!("the points have no spread (spacing {}): nothing to extract", r.kappa)));
        }
        let Some(tau) = self.residuals(&r, params)? else { return Ok(None) };
        self.tau = tau;
        if !self.projection(&r)? {
            return Ok(None);
        }
        self.peak_rss_tiles = crate::mem::peak_rss();
        Ok(Some(r))
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
            let store = Store::new(&self.ws)?;
            store.clear()?;
            let grid = self.manifest.grid.clone();
            let tiles = Bucketer::new(&grid, store, (self.opts.memory / 4 / 48) as usize);
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

    /// Statistics pass: spacing, noise and density at sampled points, with a first halo wide
    /// enough for the 16-kappa fits (kappa from a probe of the fullest tile; tiles whose noise
    /// fits reach farther are loaded again, wider); then the parameters are resolved from them.
    fn statistics(&mut self, params: &Params) -> Result<Option<Resolved>> {
        let t = Instant::now();
        if let Some(r) = &self.manifest.resolved {
            self.pass.statistics = t.elapsed().as_secs_f64();
            return Ok(Some(r.clone()));
        }
        self.repair::<Stats>()?;
        let (store, grid) = (Store::new(&self.ws)?, &self.manifest.grid);
        let tile_points = &self.manifest.tile_points;
        let fullest = *self.tiles.iter().max_by_key(|&&t| (tile_points[t as usize], std::cmp::Reverse(t))).expect("a tile with points");
        let mut probe = TilePoints::default();
        store.read(fullest, &mut probe, |_, _| true)?;
        let kappa0 = crate::spacing::spacing(&probe.xyz, 2000);
        drop(probe);
        let total: u64 = tile_points.iter().sum();
        let seed = params.seed.unwrap_or(crate::extract::params::DEFAULT_SEED);
        let loading = |halo| Loading { halo, keep: 1.0, evaluate: 1.0, seed, key_quantum: self.kq, counts: tile_points, average: 0.0, average_share: 1.0 };
        let halo0 = 24.0 * kappa0;
        // The widest halo that the noise balls of the tiles computed so far asked for: the
        // tiles loaded after them start with it rather than loading twice. (Which tiles do
        // depends on timing; what they compute does not.)
        let asked = std::sync::atomic::AtomicU64::new(halo0.to_bits());
        // (The pool has little to do here but wait for the next tile, so the tile is indexed
        // on the pool, not on the loader thread as in the passes below.)
        let time = tile_pass(
            &self.context(),
            "statistics",
            &self.share(),
            |t, _| {
                let halo = f64::from_bits(asked.load(std::sync::atomic::Ordering::Relaxed));
                pass::load(store, grid, t, &loading(halo)).map(|first| (first, halo))
            },
            |t, (first, loaded)| {
                let tile = StatsTile { core: grid.core(t), halo: halo0, key_quantum: self.kq, total, seed };
                let (stats, wider) = statistics::tile_statistics(first, loaded, &tile, |halo| pass::load(store, grid, t, &loading(halo)))?;
                // (The bits of positive numbers order as the numbers do.)
                asked.fetch_max(wider.to_bits(), std::sync::atomic::Ordering::Relaxed);
                Ok(Stats(stats))
            },
        )?;
        self.pass.statistics_load = time.load;
        if !self.all_done::<Stats>("statistics") {
            return Ok(None);
        }
        let mut stats = vec![];
        for &t in &self.tiles {
            stats.extend(records::read::<Stats>(&self.ws, t)?.0);
        }
        let r = crate::extract::params::resolve(params, &stats);
        self.manifest.resolved = Some(r.clone());
        self.save_manifest()?;
        self.pass.statistics = t.elapsed().as_secs_f64();
        Ok(Some(r))
    }

    /// How the residual and projection passes load a tile: the same way in both, so that the
    /// residuals come back in the cloud's order.
    fn cloud_loading(&self, r: &Resolved) -> Loading<'_> {
        let (halo, keep, average, average_share) = (r.halo(), r.keep, r.average, r.average_share);
        Loading { halo, keep, evaluate: r.evaluate, seed: r.seed, key_quantum: self.kq, counts: &self.manifest.tile_points, average, average_share }
    }

    /// Residual pass (stage 1); returns tau, the mean residual over all points (an exact sum:
    /// the same whatever the tiling), unless the user gave it.
    fn residuals(&mut self, r: &Resolved, params: &Params) -> Result<Option<f64>> {
        let t = Instant::now();
        self.repair::<Residuals>()?;
        let (store, grid, loading) = (Store::new(&self.ws)?, &self.manifest.grid, self.cloud_loading(r));
        let time = tile_pass(
            &self.context(),
            "residuals",
            &self.share(),
            |t, idle| pass::load_cloud(store, grid, t, &loading, r.cell_side(), idle, &self.opts.cancel),
            |_, (cloud, core)| Ok(Residuals(candidates::tile_residuals(&cloud, &core, r))),
        )?;
        self.pass.residuals_load = time.load;
        if !self.all_done::<Residuals>("residuals") {
            return Ok(None);
        }
        // (Read on the pool, which is idle here.)
        let sums: Vec<ResidualSum> = self
            .tiles
            .par_iter()
            .map(|&t| Ok(ResidualSum::of(records::read::<Residuals>(&self.ws, t)?.0.residual.iter().map(|x| x.value))))
            .collect::<Result<_>>()?;
        let total = sums.into_iter().fold(ResidualSum::default(), |a, b| a + b);
        self.evaluated = total.count();
        self.pass.residuals = t.elapsed().as_secs_f64();
        Ok(Some(params.tau.unwrap_or(settle(total.mean()))))
    }

    /// Projection pass (stage 2): the candidates of each tile, projected. False if a worker's
    /// share is done but not every tile is.
    fn projection(&mut self, r: &Resolved) -> Result<bool> {
        let t = Instant::now();
        self.repair::<Edges>()?;
        let (store, grid, loading, tau) = (Store::new(&self.ws)?, &self.manifest.grid, self.cloud_loading(r), self.tau);
        let debug = &self.opts.debug;
        let time = tile_pass(
            &self.context(),
            "projection",
            &self.share(),
            |t, idle| pass::load_cloud(store, grid, t, &loading, r.cell_side(), idle, &self.opts.cancel),
            |t, (cloud, core)| {
                let res = records::read::<Residuals>(&self.ws, t)?.0;
                let cand = candidates::tile_candidates(&cloud, &core, &res, tau);
                if debug.on() {
                    let pts: Vec<DVec3> = cand.iter().map(|&i| cloud.at(i as usize)).collect();
                    debug.points(&format!("candidates_{t}.obj"), &pts, cloud.origin);
                }
                let band = match r.model {
                    Model::Patches => {
                        // (Tiles without points have no records.)
                        let around = grid
                            .around(t, r.halo())
                            .into_iter()
                            .filter(|&u| self.manifest.tile_points[u as usize] > 0)
                            .map(|u| Ok(records::read::<Residuals>(&self.ws, u)?.0))
                            .collect::<Result<Vec<_>>>()?;
                        Some(candidates::band_of(&cloud, &around, tau))
                    }
                    _ => None,
                };
                Ok(Edges(project::tile_edges(&cloud, &cand, band.as_deref(), r)))
            },
        )?;
        self.pass.projection_load = time.load;
        self.pass.projection = t.elapsed().as_secs_f64();
        Ok(self.all_done::<Edges>("projection"))
    }

    /// Removes the working data of a finished run (`--clean`), then marks it so in the
    /// manifest.
    fn clean(&mut self) -> Result<()> {
        remove_working_data(&self.ws);
        if let Some(w) = &self.manifest.work_dir {
            let _ = std::fs::remove_file(w.join(WORK_OWNER));
            let _ = std::fs::remove_dir(w);
        }
        self.manifest.cleaned = true;
        manifest::save(&self.ws, &self.manifest)
    }

    /// The end of the write step, begun at `t` once the outputs are written: the manifest
    /// marked finished.
    fn finished(&mut self, t: Instant) -> Result<()> {
        self.manifest.finished = true;
        manifest::save(&self.ws, &self.manifest)?;
        self.pass.writing = t.elapsed().as_secs_f64();
        Ok(())
    }

    /// About [`PREVIEW_POINTS`](crate::preview::PREVIEW_POINTS) of the cloud's points, chosen
    /// by position key from the tile store, in tile order.
    fn preview_sample(&self) -> Result<Vec<DVec3>> {
        sample_tiles(&self.ws, &self.manifest, &self.tiles, crate::preview::PREVIEW_POINTS)
    }

    #[allow(clippy::too_many_arguments)]
    fn report(&mut self, inputs: Vec<PathBuf>, r: Resolved, tau: f64, counts: Counts, seconds: Timings, t0: Instant, resumed: bool) -> Report {
        let grid = &self.manifest.grid;
        Report {
            version: env!("CARGO_PKG_VERSION").to_string(),
            inputs,
            halo: r.halo(),
            params: r,
            tau,
            min_confidence: self.opts.min_confidence,
            min_length: self.opts.min_length,
            projection_cost: ProjectionCost::of(&seconds, &counts),
            counts,
            seconds,
            pass_seconds: self.pass.clone(),
            total_seconds: t0.elapsed().as_secs_f64(),
            peak_rss_bytes: crate::mem::peak_rss(),
            peak_rss_tiles_bytes: self.peak_rss_tiles,
            peak_rss_curves_bytes: self.curve_peak.take().map_or(0, |s| s.finish()),
            threads: rayon::current_num_threads(),
            tiles: grid.len(),
            tile_size: grid.size,
            resumed,
            repaired: self.repaired.clone(),
            warnings: vec![],
            crs: Crs::default(),
            outside: Outside::Unknown,
            shapes: ShapeCounts::default(),
        }
    }
}

/// About `points` of the run's points, chosen by position key (so the same whatever the
/// tiling), read from the tile store.
fn sample_tiles(ws: &Workspace, manifest: &Manifest, tiles: &[u32], points: f64) -> Result<Vec<DVec3>> {
    let total: u64 = manifest.tile_points.iter().sum();
    let share = points / total.max(1) as f64;
    let kq = key_quantum(manifest.diag);
    let store = Store::new(ws)?;
    let parts: Vec<Vec<DVec3>> = tiles
        .par_iter()
        .map(|&t| {
            let mut tp = TilePoints::default();
            store.read(t, &mut tp, |p, _| keep_point(position_key(p, kq) ^ 0x9E37_79B9, share, 1))?;
            Ok(tp.xyz)
        })
        .collect::<Result<_>>()?;
    Ok(parts.concat())
}

/// Writes `view.html` into the finished run directory `dir`: its curves (from `curves.ply`)
/// over a sample of its points, to turn and zoom in a browser. Returns the page's path.
///
/// ```no_run
/// let page = crease::run::write_view(std::path::Path::new("run"))?;
/// println!("open {}", page.display());
/// # Ok::<(), crease::Error>(())
/// ```
pub fn write_view(dir: &Path) -> Result<PathBuf> {
    let mut ws = Workspace::disk(dir)?;
    let m = manifest::read(&ws)?.ok_or_else(|| Error::input(dir, "not a crease run directory (no manifest.json)"))?;
    if !m.finished {
        return Err(Error::input(dir, "the run has not finished: run crease extract on it first"));
    }
    use_work_dir(&mut ws, &m)?;
    let tiles: Vec<u32> = (0..m.tile_points.len() as u32).filter(|&t| m.tile_points[t as usize] > 0).collect();
    // (A run whose working data was removed has its curves left, not its points.)
    let points = if m.cleaned { vec![] } else { sample_tiles(&ws, &m, &tiles, crate::view::VIEW_POINTS)? };
    let curves = crate::curves::read_ply(&dir.join("curves.ply"))?;
    let crs = std::fs::read(dir.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|r| serde_json::from_value::<Crs>(r["crs"].clone()).ok())
        .unwrap_or_default();
    let title = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| dir.display().to_string());
    let page = dir.join(VIEW);
    crate::view::write_html(&page, &title, &points, &curves, &crs)?;
    Ok(page)
}

/// The crease run directories (canonical) that hold some of `files`, other than `this_run`: a
/// directory whose manifest is a run's (a job and a tile grid).
fn other_run_directories(files: &[PathBuf], this_run: Option<&Path>) -> Vec<PathBuf> {
    let mut seen: std::collections::HashMap<PathBuf, bool> = std::collections::HashMap::new();
    let mut runs = vec![];
    for f in files {
        let Ok(c) = f.canonicalize() else { continue };
        for a in c.ancestors().skip(1) {
            if Some(a) == this_run {
                continue;
            }
            let is_run = *seen.entry(a.to_path_buf()).or_insert_with(|| {
                let m = a.join(manifest::NAME);
                m.is_file()
                    && std::fs::read(&m)
                        .ok()
                        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
                        .is_some_and(|v| v.get("job").is_some() && v.get("grid").is_some())
            });
            if is_run && !runs.iter().any(|r: &PathBuf| r == a) {
                runs.push(a.to_path_buf());
            }
        }
    }
    runs
}

/// True if `f` (canonical) is a file or directory a run in `dir` (canonical) writes.
fn is_run_file(dir: &Path, f: &Path) -> bool {
    let Ok(rel) = f.strip_prefix(dir) else {
        return false;
    };
    let top = rel.components().next().map(|c| c.as_os_str().to_string_lossy().into_owned()).unwrap_or_default();
    // (Workers' locks are `lock.<i>`.)
    (WORKING.contains(&top.as_str()) || ["out.tmp", manifest::NAME, "lock", VIEW].contains(&top.as_str()))
        || OUTPUTS.contains(&top.as_str())
        || top.strip_prefix("lock.").is_some_and(|i| i.parse::<u32>().is_ok())
}

/// The files a finished run writes into its directory.
pub const OUTPUTS: [&str; 7] = ["curves.obj", "curves.ply", "curves.geojson", "curves.gpkg", "curves.dxf", "preview.png", "report.json"];

/// Written on demand by [`write_view`].
const VIEW: &str = "view.html";

fn write_outputs(dir: &Path, curves: &(impl Curves + ?Sized), crs: &Crs, sample: &[DVec3], formats: &[Format], tolerance: f64) -> Result<()> {
    // Each output goes to a temporary name first, then is renamed into place.
    let tmp = dir.join("out.tmp");
    std::fs::create_dir_all(&tmp).map_err(|e| Error::output(&tmp, e))?;
    let (written, preview) = rayon::join(
        || formats.iter().try_for_each(|f| f.write(&tmp.join(f.file_name()), curves, crs, tolerance)),
        || crate::preview::write_png(&tmp.join("preview.png"), sample, curves),
    );
    written.and(preview)?;
    for f in formats.iter().map(|f| f.file_name()).chain(["preview.png"]) {
        let p = tmp.join(f);
        std::fs::File::open(&p).and_then(|f| f.sync_all()).map_err(|e| Error::output(&p, e))?;
        std::fs::rename(&p, dir.join(f)).map_err(|e| Error::output(&p, e))?;
    }
    // (An output of a format not asked for this time would be stale.)
    for f in Format::ALL.iter().filter(|f| !formats.contains(f)) {
        let _ = std::fs::remove_file(dir.join(f.file_name()));
    }
    let _ = std::fs::remove_dir(&tmp);
    Ok(())
}
