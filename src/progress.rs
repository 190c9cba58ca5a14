//! Progress reporting: indicatif bars on a terminal, a log line per stage and about every ten
//! seconds otherwise, nothing with `--quiet`. Updates are cheap (an atomic add).
//!
//! A [`Watch`] also receives every stage's counts, whatever the mode, for a caller that draws
//! its own progress from another thread: the Python binding, whose bar belongs in a notebook
//! cell rather than on the terminal that started the notebook.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The counts of a run's current stage, shared with a caller that polls them ([`Watch::get`])
/// instead of being called back from the run's threads.
#[derive(Clone, Debug, Default)]
pub struct Watch(Arc<WatchState>);

#[derive(Debug, Default)]
struct WatchState {
    /// The stage's name and unit, and its number (1 for the first stage begun).
    stage: Mutex<(String, String, u64)>,
    total: AtomicU64,
    done: AtomicU64,
}

/// What a [`Watch`] holds at one moment.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Snapshot {
    /// The stage ("bucketing", "statistics", ...), empty before the first.
    pub stage: String,
    /// What it counts ("points", "tiles", ...).
    pub unit: String,
    /// Stages begun so far: it changes when a stage begins, even one of the same name.
    pub number: u64,
    /// Units done.
    pub done: u64,
    /// Units in the stage.
    pub total: u64,
}

impl Watch {
    /// The current stage and its counts.
    pub fn get(&self) -> Snapshot {
        let s = self.0.stage.lock().unwrap_or_else(|e| e.into_inner());
        let (stage, unit, number) = s.clone();
        Snapshot { stage, unit, number, done: self.0.done.load(Ordering::Relaxed), total: self.0.total.load(Ordering::Relaxed) }
    }

    fn begin(&self, stage: &str, total: u64, unit: &str) {
        let mut s = self.0.stage.lock().unwrap_or_else(|e| e.into_inner());
        self.0.total.store(total, Ordering::Relaxed);
        self.0.done.store(0, Ordering::Relaxed);
        *s = (stage.to_string(), unit.to_string(), s.2 + 1);
    }
}

/// Where progress goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Bars on a terminal, log lines otherwise.
    Auto,
    /// Nothing.
    Quiet,
}

/// A progress reporter.
pub(crate) struct Progress {
    mode: Mode,
    terminal: bool,
    watch: Option<Watch>,
}

impl Progress {
    /// A reporter for `mode`, telling `watch` too, if given.
    pub(crate) fn new(mode: Mode, watch: Option<Watch>) -> Progress {
        Progress { mode, terminal: std::io::stderr().is_terminal(), watch }
    }

    /// A bar for one stage of `total` units.
    pub(crate) fn bar(&self, stage: &str, total: u64, unit: &str) -> Bar {
        if let Some(w) = &self.watch {
            w.begin(stage, total, unit);
        }
        let watch = self.watch.clone();
        if self.mode == Mode::Quiet {
            return Bar { pb: None, log: None, stage: stage.to_string(), unit: unit.to_string(), total, watch };
        }
        if self.terminal {
            let pb = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr_with_hz(4));
            pb.set_style(
                ProgressStyle::with_template("{prefix:>11} [{bar:30}] {human_pos}/{human_len} {msg} ({per_sec}, eta {eta})")
                    .expect("template")
                    .progress_chars("=> "),
            );
            pb.set_prefix(stage.to_string());
            pb.set_message(unit.to_string());
            Bar { pb: Some(pb), log: None, stage: stage.to_string(), unit: unit.to_string(), total, watch }
        } else {
            eprintln!("crease: {stage}: {}", counted(total, unit));
            Bar { pb: None, log: Some(Mutex::new((Instant::now(), Instant::now(), 0))), stage: stage.to_string(), unit: unit.to_string(), total, watch }
        }
    }
}

/// `total` of `unit` (a plural noun), in the singular for one: "1 tile", "3 tiles".
fn counted(total: u64, unit: &str) -> String {
    let unit = if total == 1 { unit.strip_suffix('s').unwrap_or(unit) } else { unit };
    format!("{total} {unit}")
}

/// Progress of one stage.
pub(crate) struct Bar {
    pb: Option<ProgressBar>,
    /// Off a terminal: (stage start, last line, done).
    log: Option<Mutex<(Instant, Instant, u64)>>,
    stage: String,
    unit: String,
    total: u64,
    watch: Option<Watch>,
}

impl Bar {
    /// Counts `n` more units done.
    pub(crate) fn inc(&self, n: u64) {
        if let Some(w) = &self.watch {
            w.0.done.fetch_add(n, Ordering::Relaxed);
        }
        if let Some(pb) = &self.pb {
            pb.inc(n);
        } else if let Some(log) = &self.log {
            let mut l = log.lock().unwrap();
            l.2 += n;
            if l.1.elapsed() >= Duration::from_secs(10) {
                l.1 = Instant::now();
                eprintln!("crease: {}: {}/{} {} ({:.0} s)", self.stage, l.2, self.total, self.unit, l.0.elapsed().as_secs_f64());
            }
        }
    }

    /// Ends the stage.
    pub(crate) fn finish(&self) {
        if let Some(w) = &self.watch {
            w.0.done.store(self.total, Ordering::Relaxed);
        }
        if let Some(pb) = &self.pb {
            pb.finish();
        } else if let Some(log) = &self.log {
            let l = log.lock().unwrap();
            eprintln!("crease: {}: done in {:.1} s", self.stage, l.0.elapsed().as_secs_f64());
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn one_of_a_unit_is_singular() {
        assert_eq!(super::counted(1, "slabs"), "1 slab");
        assert_eq!(super::counted(0, "tiles"), "0 tiles");
        assert_eq!(super::counted(64, "tiles"), "64 tiles");
    }

    #[test]
    fn a_watch_sees_each_stage_begin_count_and_finish() {
        let watch = super::Watch::default();
        assert_eq!(watch.get(), super::Snapshot::default());
        let p = super::Progress::new(super::Mode::Quiet, Some(watch.clone()));
        let bar = p.bar("statistics", 8, "tiles");
        bar.inc(3);
        let s = watch.get();
        assert_eq!((s.stage.as_str(), s.unit.as_str(), s.number, s.done, s.total), ("statistics", "tiles", 1, 3, 8));
        bar.finish();
        assert_eq!(watch.get().done, 8);
        let _next = p.bar("statistics", 8, "tiles");
        let s = watch.get();
        assert_eq!((s.number, s.done), (2, 0));
    }
}
