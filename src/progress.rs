//! Progress reporting: indicatif bars on a terminal, a log line per stage and about every ten
//! seconds otherwise, nothing with `--quiet`. Updates are cheap (an atomic add).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Where progress goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Bars on a terminal, log lines otherwise.
    Auto,
    /// Nothing.
    Quiet,
}

/// A progress reporter.
pub struct Progress {
    mode: Mode,
    terminal: bool,
}

impl Progress {
    /// A reporter for `mode`.
    pub fn new(mode: Mode) -> Progress {
        Progress { mode, terminal: std::io::stderr().is_terminal() }
    }

    /// A bar for one stage of `total` units.
    pub fn bar(&self, stage: &str, total: u64, unit: &str) -> Bar {
        if self.mode == Mode::Quiet {
            return Bar { pb: None, log: None, stage: stage.to_string(), unit: unit.to_string(), total };
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
            Bar { pb: Some(pb), log: None, stage: stage.to_string(), unit: unit.to_string(), total }
        } else {
            eprintln!("crease: {stage}: {}", counted(total, unit));
            Bar { pb: None, log: Some(Mutex::new((Instant::now(), Instant::now(), 0))), stage: stage.to_string(), unit: unit.to_string(), total }
        }
    }
}

/// `total` of `unit` (a plural noun), in the singular for one: "1 tile", "3 tiles".
fn counted(total: u64, unit: &str) -> String {
    let unit = if total == 1 { unit.strip_suffix('s').unwrap_or(unit) } else { unit };
    format!("{total} {unit}")
}

/// Progress of one stage.
pub struct Bar {
    pb: Option<ProgressBar>,
    /// Off a terminal: (stage start, last line, done).
    log: Option<Mutex<(Instant, Instant, u64)>>,
    stage: String,
    unit: String,
    total: u64,
}

impl Bar {
    /// Counts `n` more units done.
    pub fn inc(&self, n: u64) {
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
    pub fn finish(&self) {
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
}
