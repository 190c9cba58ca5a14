//! A run in progress ([`Run`]): its workspace, manifest and options, what its steps found so
//! far, and the bookkeeping every step shares (a worker's share, damaged results, the
//! manifest). What a step comes to is a [`Step`]: done with its value, or waiting for other
//! workers.

use super::manifest::{self, Manifest};
use super::pass::PassContext;
use super::records::{self, Record};
use super::types::{PassSeconds, RunOptions, Worker};
use crate::error::{Error, Result};
use crate::keys::key_quantum;
use crate::progress::Progress;
use crate::workspace::Workspace;
use std::path::PathBuf;
use std::time::Instant;

/// What a step of the pipeline came to: done, with its value, or waiting for what other
/// workers sharing the run have still to do (for example "residuals: 5 of 8 tiles done (the
/// other workers' share)").
#[must_use]
pub(super) enum Step<T> {
    /// The step is done.
    Done(T),
    /// This process can go no further until other workers have done their share.
    Waiting(String),
}

impl<T> Step<T> {
    /// The value of a step that a lone run took: it does every tile and block itself, so it
    /// has nothing to wait for.
    pub(super) fn lone(self) -> Result<T> {
        match self {
            Step::Done(v) => Ok(v),
            Step::Waiting(why) => Err(Error::Usage(why)),
        }
    }
}

/// The value of a done [`Step`]; a waiting one is handed on at once, as `?` hands on an error
/// (the enclosing function returns `Result<Step<_>>`).
macro_rules! done {
    ($step:expr) => {
        match $step {
            $crate::run::state::Step::Done(v) => v,
            $crate::run::state::Step::Waiting(why) => return Ok($crate::run::state::Step::Waiting(why)),
        }
    };
}
pub(super) use done;

/// A run in progress: its workspace, manifest and options, and what the steps found so far.
pub(super) struct Run<'a> {
    pub(super) ws: Workspace,
    pub(super) manifest: Manifest,
    pub(super) opts: &'a RunOptions,
    pub(super) progress: Progress,
    pub(super) pass: PassSeconds,
    /// When this invocation started.
    pub(super) started: Instant,
    /// True if this invocation continues an interrupted run.
    pub(super) resumed: bool,
    /// Tiles that hold points.
    pub(super) tiles: Vec<u32>,
    /// Quantum of the position keys.
    pub(super) kq: f64,
    /// The residual threshold.
    pub(super) tau: f64,
    /// Points whose residuals tau averages.
    pub(super) evaluated: u64,
    /// Peak memory by the end of the tile passes.
    pub(super) peak_rss_tiles: u64,
    /// Peak memory while the outputs were written, and while the points were labelled.
    pub(super) peak_rss_outputs: u64,
    pub(super) peak_rss_labels: u64,
    /// Damaged results removed to be computed again.
    pub(super) repaired: Vec<PathBuf>,
    /// This process's share of a run that several share.
    pub(super) worker: Option<Worker>,
    /// The labelled copies of the inputs the label pass wrote or found.
    pub(super) labels: Vec<PathBuf>,
}

/// The manifest a run starts from, as the plan step left it, and whether the run resumes.
pub(super) struct Planned {
    pub(super) manifest: Manifest,
    pub(super) resumed: bool,
}

impl<'a> Run<'a> {
    /// A run of `planned` over `ws`, started at `started`.
    pub(super) fn new(ws: Workspace, planned: Planned, opts: &'a RunOptions, worker: Option<Worker>, started: Instant) -> Run<'a> {
        let Planned { manifest, resumed } = planned;
        let kq = key_quantum(manifest.diag);
        let progress = Progress::new(opts.progress, opts.watch.clone());
        let pass = PassSeconds::default();
        Run {
            ws,
            manifest,
            opts,
            progress,
            pass,
            started,
            resumed,
            tiles: vec![],
            kq,
            tau: 0.0,
            evaluated: 0,
            peak_rss_tiles: 0,
            peak_rss_outputs: 0,
            peak_rss_labels: 0,
            repaired: vec![],
            worker,
            labels: vec![],
        }
    }

    /// True for the process that plans, buckets, writes the run's shared files and the
    /// outputs: worker 0, or a lone run.
    pub(super) fn leads(&self) -> bool {
        Worker::leads(self.worker)
    }

    /// The tiles this process computes in a pass: all of them, or a worker's share.
    pub(super) fn share(&self) -> Vec<u32> {
        self.tiles.iter().copied().filter(|&t| self.worker.is_none_or(|w| t % w.count == w.index)).collect()
    }

    /// Done once every tile has its result of pass `R`; else waiting for the other workers.
    pub(super) fn all_done<R: Record>(&self, pass: &str) -> Step<()> {
        let done = self.tiles.iter().filter(|&&t| self.ws.exists(&records::name(R::DIR, t))).count();
        if done < self.tiles.len() {
            return Step::Waiting(format!("{pass}: {done} of {} tiles done (the other workers' share)", self.tiles.len()));
        }
        Step::Done(())
    }

    /// Saves the manifest, if this process is the one that writes it (worker 0, or a lone
    /// run): workers side by side must not replace it under each other.
    pub(super) fn save_manifest(&self) -> Result<()> {
        if self.leads() {
            manifest::save(&self.ws, &self.manifest)?;
        }
        Ok(())
    }

    /// Checks the stored results of pass `R` (an earlier invocation's), and removes those that
    /// are damaged, so that the pass computes them again from the tiles.
    pub(super) fn repair<R: Record>(&mut self) -> Result<()> {
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

    /// What the tile pass engine needs of the run.
    pub(super) fn context(&self) -> PassContext<'_> {
        PassContext { ws: &self.ws, progress: &self.progress, cancel: &self.opts.cancel }
    }
}
