//! The pipeline: plan, bucket, statistics, residuals, projection, curves, write, over a
//! workspace that is a resumable run directory ([`run_extract`]) or memory
//! ([`extract_cloud`]). The stages' work is in [`crate::extract`]; this module only
//! orchestrates, one step a file:
//!
//! 1. **Plan** (`plan`) from the headers (`inputs.rs`): bounds, counts, CRS, a tile grid (2D
//!    for airborne-like extents, 3D otherwise) sized from `--memory` (a tile holds at most
//!    `MAX_TILE_POINTS`; `budgets` says how the budget is shared).
//! 2. **Bucket** (`bucket.rs`): one streaming pass over the inputs writes every point once, to
//!    its tile, zstd-compressed in spatial chunks (16 per tile edge, each headed by its
//!    bounding box), so that assembling a tile's halo decompresses only the neighbours' border
//!    chunks; points far from all the others are left out (`far.rs`).
//! 3. **Tile passes** (`tile_passes.rs`, over the engine in `pass.rs`: statistics, residuals,
//!    projection), each tile with its halo: one loader thread reads the next tile while the
//!    current one is computed on all cores.
//! 4. **Curves** (`curves.rs`): the edge cloud surveyed (`survey.rs`), grown a growth block at a
//!    time (`grow.rs`; blocks depend on the edge cloud, not on the tiles), then the blocks'
//!    pieces of polylines read a slab at a time, stitched and completed a cluster at a time,
//!    and written a batch at a time (`complete.rs`), so that no step holds every polyline (see
//!    [`crate::extract`] for the method of each step).
//! 5. **Write** the outputs from the finished batches (`layout.rs`, which also says what a run
//!    directory holds); the output filters apply last; then the report.
//!
//! A run in progress is a `Run` (`state.rs`); each step comes to a `Step`, done or waiting
//! for other workers. Per-tile and per-block results are records of the codec (`records.rs`);
//! `crease status` reads them ([`status()`]).
//!
//! Run directory layout, the outputs at the top and the working data below `work/`:
//! - `curves.*`, `preview.png`, `report.json`: the outputs;
//! - `manifest.json`: the job (inputs with size, mtime and header checksum; parameters; crease
//!   version), the plan (grid), the layout, and what is done (`finished` once the outputs are
//!   in place, before `report.json` is written);
//! - `work/tiles/`: bucketed points; `work/stats/`, `work/resid/`, `work/edges/`: one result
//!   file per tile and pass; `work/survey/`, `work/smoothed/`, `work/pieces/`: the curve
//!   stage's, one file per growth block; `work/finished/`: the curves a batch at a time; each
//!   file a record of the codec (see `codec.rs`: a header with the kind of record, a format
//!   number and a CRC-32, then a zstd payload);
//! - `labels/`: the inputs' points labelled by the curves, with `--label-points` (`labels.rs`);
//! - `lock`, and `lock.<i>` for worker `i` of several sharing the run ([`run_worker`]), removed
//!   when the run ends, finished, failed or interrupted.
//!
//! With `--work-dir`, the working data is in that directory instead of `work/`, and the work
//! directory names its run in `crease-run`. A run directory of crease 0.8 or earlier (a
//! manifest without `layout`) keeps its working data at the top, and is resumed so. The working data lets an interrupted run continue and a finished one write its
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
mod budgets;
mod complete;
mod curves;
pub(crate) mod far;
mod grow;
mod inputs;
mod labels;
mod layout;
mod manifest;
pub(crate) mod pass;
mod plan;
mod recent;
pub(crate) mod records;
mod state;
mod status;
mod survey;
mod tile_passes;
mod types;

pub(crate) use bucket::Input;
pub use labels::DIR as LABELS;
pub use layout::{write_view, OUTPUTS};
pub use manifest::{InputStamp, Job, Manifest, NAME as MANIFEST};
pub use status::{render_status, status, PieceCounts, Status};
pub use types::{check_threads, Extraction, PassSeconds, ProjectionCost, Report, RunOptions, ShapeCounts, Worker, WorkerStep, MAX_THREADS_PER_CORE};

use crate::curves::{Curves, Outside};
use crate::error::{Error, Result};
use crate::extract::{Counts, Params, Resolved};
use crate::io::Filter;
use crate::points::Bounds;
use crate::workspace::Workspace;
use curves::CurveStage;
use glam::DVec3;
use inputs::InputFiles;
use plan::plan;
use state::{done, Run, Step};
use std::path::{Path, PathBuf};
use std::time::Instant;

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

/// The run over files, in its steps: the inputs gathered, the job planned (or resumed), then
/// the steps of [`extract_files`]. A worker other than worker 0 waits for the plan, and has
/// nothing to do once the run is finished.
fn run_in(inputs: &[PathBuf], dir: &Path, params: &Params, filter: &Filter, opts: &RunOptions, worker: Option<Worker>) -> Result<WorkerStep> {
    let started = Instant::now();
    params.validate()?;
    opts.validate()?;
    let mut found = InputFiles::gather(inputs, dir, opts)?;
    let job = found.job(params, filter, opts)?;
    let mut ws = Workspace::disk(dir)?;
    ws.lock(worker.map(|w| w.index))?;
    if let Step::Waiting(why) = wait_for_plan(&ws, opts, worker)? {
        return Ok(WorkerStep::Waiting(why));
    }
    let planned = plan(&mut ws, job, || found.bounds(filter, &opts.cancel), opts, worker)?;
    // (Worker 0 writes the outputs, again if an output setting changed; the others had nothing
    // left to do once it finished, and were told to wait for ever.)
    if planned.manifest.finished && !Worker::leads(worker) {
        return Ok(WorkerStep::AlreadyFinished);
    }
    let run = Run::new(ws, planned, opts, worker, started);
    Ok(match extract_files(run, found, params, filter)? {
        Step::Done(report) => WorkerStep::Finished(Box::new(report)),
        Step::Waiting(why) => WorkerStep::Waiting(why),
    })
}

/// A worker other than worker 0 neither starts a run over nor plans it: it waits until worker
/// 0 has planned the run.
fn wait_for_plan(ws: &Workspace, opts: &RunOptions, worker: Option<Worker>) -> Result<Step<()>> {
    if Worker::leads(worker) {
        return Ok(Step::Done(()));
    }
    if opts.force {
        return Err(Error::Usage("--force starts a run over: give it to worker 0 (or a lone run), not to the others".into()));
    }
    if manifest::read(ws)?.is_none() {
        return Ok(Step::Waiting("the run to be planned (worker 0 plans it and buckets the points)".into()));
    }
    Ok(Step::Done(()))
}

/// The steps of a planned run over files: the tile passes, the curve stage, the outputs, the
/// report (written last, as `report.json`), and `--clean`.
fn extract_files(mut run: Run, mut found: InputFiles, params: &Params, filter: &Filter) -> Result<Step<Report>> {
    let r = done!(run.tile_passes(&Input::Files(&found.files, filter), params, found.first())?);
    found.warnings.extend(far_points_warning(&run.manifest));
    let outside = found.outside(run.opts);
    let stage = done!(run.curves(&r, &outside)?);
    found.warnings.extend(clusters_cut_warning(&stage.counts));
    let (shapes, peak) = crate::mem::sampled(|| run.write(stage.batches, &found.crs, &r));
    run.peak_rss_outputs = peak;
    let shapes = shapes?;
    let (labels, peak) = crate::mem::sampled(|| run.label_points(stage.batches, &r, &found.files, filter.text));
    (run.peak_rss_labels, run.labels) = (peak, labels?);
    found.warn_coarse_coordinates(&run.manifest.grid, r.kappa);
    let report = report(&mut run, found, r, stage, outside, shapes);
    run.ws.write_atomic("report.json", serde_json::to_string_pretty(&report).expect("report serialises").as_bytes())?;
    if run.opts.clean {
        layout::clean(&run.ws, &mut run.manifest)?;
    }
    Ok(Step::Done(report))
}

/// A warning of the points left out as far from all the others, if any were.
fn far_points_warning(m: &Manifest) -> Option<String> {
    let kept = m.kept.filter(|_| m.far_points > 0)?;
    Some(format!(
        "{} points lie far from all the others (farther out than the rest of the cloud is wide) and were left out; the rest lie within {}",
        m.far_points,
        kept.ranges()
    ))
}

/// A warning of the clusters of pieces of polylines the curve stage cut, if it cut any.
fn clusters_cut_warning(counts: &Counts) -> Option<String> {
    (counts.clusters_cut > 0).then(|| {
        format!(
            "{} clusters of pieces of polylines held more than {} vertices and were cut where the curve stage's sweep had passed them: curves across such a cut may come out in two",
            counts.clusters_cut,
            crate::extract::sweep::MAX_CLUSTER_VERTICES
        )
    })
}

/// The report of a finished run, from what its steps found.
fn report(run: &mut Run, found: InputFiles, r: Resolved, stage: CurveStage, outside: Outside, shapes: ShapeCounts) -> Report {
    let CurveStage { counts, seconds, peak_rss, .. } = stage;
    let grid = &run.manifest.grid;
    Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        inputs: found.files,
        halo: r.halo(),
        params: r,
        tau: run.tau,
        min_confidence: run.opts.min_confidence,
        min_length: run.opts.min_length,
        projection_cost: ProjectionCost::of(&seconds, &counts),
        counts,
        seconds,
        pass_seconds: run.pass.clone(),
        total_seconds: run.started.elapsed().as_secs_f64(),
        peak_rss_bytes: crate::mem::peak_rss(),
        peak_rss_tiles_bytes: run.peak_rss_tiles,
        peak_rss_curves_bytes: peak_rss,
        peak_rss_outputs_bytes: run.peak_rss_outputs,
        peak_rss_labels_bytes: run.peak_rss_labels,
        threads: rayon::current_num_threads(),
        tiles: grid.len(),
        tile_size: grid.size,
        resumed: run.resumed,
        repaired: run.repaired.clone(),
        warnings: found.warnings.into_list(),
        crs: found.crs,
        outside,
        shapes,
        labels: std::mem::take(&mut run.labels),
    }
}

/// Extracts feature curves from `points` (world coordinates) held in memory: the same pipeline
/// as [`run_extract`], over a workspace in memory.
///
/// ```
/// use crease::extract::Params;
/// use crease::run::{extract_cloud, RunOptions};
/// use crease::synth::{sample, shape, SynthOptions};
///
/// let cube = shape("cube", 90.0).unwrap();
/// let points = sample(&cube, &SynthOptions { n: 60_000, ..Default::default() });
/// let x = extract_cloud(&points, &Params::default(), &RunOptions::default())?;
/// assert_eq!(x.curves.len(), 12);
/// # Ok::<(), crease::Error>(())
/// ```
pub fn extract_cloud(points: &[DVec3], params: &Params, opts: &RunOptions) -> Result<Extraction> {
    let started = Instant::now();
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
    let planned = plan(&mut ws, job, bounds, opts, None)?;
    let mut run = Run::new(ws, planned, opts, None, started);
    let r = run.tile_passes(&Input::Points(points), params, &here)?.lone()?;
    // (Points in memory give no scanner positions: only `outside` tells the shapes.)
    let outside = opts.outside.clone().unwrap_or_default();
    let CurveStage { batches, counts, seconds, .. } = run.curves(&r, &outside)?.lone()?;
    let (finished, mut curves) = (run.finished_curves(batches), vec![]);
    finished.each(&mut |c| {
        curves.push(c.clone());
        Ok(())
    })?;
    Ok(Extraction { curves, params: r, tau: run.tau, counts, seconds })
}
