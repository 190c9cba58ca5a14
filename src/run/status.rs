//! `crease status`: what a run directory has done and what is left.

use super::layout::use_work_dir;
use super::manifest;
use super::records::{Edges, Pieces, Record, Residuals, Stats, Survey};
use crate::error::{Error, Result};
use crate::workspace::Workspace;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What `crease status` reports.
#[derive(Clone, Debug, Serialize)]
pub struct Status {
    /// Run directory.
    pub dir: PathBuf,
    /// Inputs.
    pub inputs: Vec<PathBuf>,
    /// Tiles with points.
    pub tiles: usize,
    /// Bucketing done.
    pub bucketed: bool,
    /// Tiles done per pass: statistics, residuals, projection.
    pub passes: Vec<(String, usize)>,
    /// Growth blocks of the curve stage grown, and how many there are, once the stage has
    /// planned them.
    pub blocks: Option<(usize, usize)>,
    /// Outputs written.
    pub finished: bool,
    /// Where the working data is, if not in the run directory.
    pub work_dir: Option<PathBuf>,
    /// The working data was removed once the outputs were written.
    pub cleaned: bool,
    /// Once the outputs are written: the curves' typed pieces by kind.
    pub pieces: Option<PieceCounts>,
    /// The labelled copies of the inputs in the run directory (`--label-points`).
    pub labels: Vec<PathBuf>,
    /// One-line summary.
    pub summary: String,
}

/// Reads what a run directory has done.
///
/// ```no_run
/// let s = crease::run::status(std::path::Path::new("run"))?;
/// print!("{}", crease::run::render_status(&s));
/// # Ok::<(), crease::Error>(())
/// ```
pub fn status(dir: &Path) -> Result<Status> {
    if !dir.is_dir() {
        return Err(Error::input(dir, "not a crease run directory (no such directory)"));
    }
    let mut ws = Workspace::disk(dir)?;
    let m = manifest::read(&ws)?.ok_or_else(|| Error::input(dir, "not a crease run directory (no manifest.json)"))?;
    use_work_dir(&mut ws, &m)?;
    let tiles: Vec<u32> = (0..m.tile_points.len() as u32).filter(|&t| m.tile_points[t as usize] > 0).collect();
    let done = |dir: &str| tiles.iter().filter(|&&t| ws.exists(&super::records::name(dir, t))).count();
    let passes: Vec<(String, usize)> =
        [("statistics", Stats::DIR), ("residuals", Residuals::DIR), ("projection", Edges::DIR)].iter().map(|(n, d)| (n.to_string(), done(d))).collect();
    // (The survey is kept once the curve stage has planned its blocks; a damaged one is made
    // again by the run.)
    let blocks = super::records::read::<Survey>(&ws, 0).ok().map(|s| {
        let n = s.blocks.list.len();
        ((0..n as u32).filter(|&b| ws.exists(&super::records::name(Pieces::DIR, b))).count(), n)
    });
    let summary = if m.finished && m.cleaned {
        "finished (working data removed)".to_string()
    } else if m.finished {
        "finished".to_string()
    } else if !m.bucketed {
        "bucketing not finished (it restarts from the beginning)".to_string()
    } else {
        match (passes.iter().find(|p| p.1 < tiles.len()), blocks) {
            (Some((name, n)), _) => format!("in {name}: {n} of {} tiles done", tiles.len()),
            (None, Some((done, n))) if done < n => format!("in curves: {done} of {n} growth blocks done"),
            (None, Some(_)) => "stitching, completion and outputs left to do".to_string(),
            (None, None) => "curves and outputs left to do".to_string(),
        }
    };
    Ok(Status {
        dir: dir.to_path_buf(),
        inputs: m.job.inputs.iter().map(|i| i.path.clone()).collect(),
        tiles: tiles.len(),
        bucketed: m.bucketed,
        passes,
        blocks,
        finished: m.finished,
        work_dir: m.work_dir.clone(),
        cleaned: m.cleaned,
        pieces: if m.finished { piece_counts(dir, m.resolved.as_ref())? } else { None },
        labels: labelled_copies(dir),
        summary,
    })
}

/// A run's curves as typed pieces (`curves::typed`), counted by kind.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PieceCounts {
    /// Curves.
    pub curves: u64,
    /// Line segments.
    pub lines: u64,
    /// Circular arcs.
    pub arcs: u64,
    /// Whole circles.
    pub circles: u64,
    /// Cubic B-splines, where no line or arc fits within the tolerance.
    pub splines: u64,
    /// Runs of the polyline no spline holds either.
    pub polylines: u64,
}

impl PieceCounts {
    fn add(&mut self, kind: &str) {
        match kind {
            "line" => self.lines += 1,
            "arc" => self.arcs += 1,
            "circle" => self.circles += 1,
            "spline" => self.splines += 1,
            _ => self.polylines += 1,
        }
    }
}

/// The typed pieces of a finished run's curves, by kind: those of `curves.json` if it was
/// written, else those of the curves in `curves.ply` (or `curves.obj`) at the run's tolerance;
/// None if the run wrote none of these.
fn piece_counts(dir: &Path, r: Option<&crate::extract::Resolved>) -> Result<Option<PieceCounts>> {
    use crate::curves::typed;
    let mut n = PieceCounts::default();
    let json = dir.join("curves.json");
    if let Ok(bytes) = std::fs::read(&json) {
        let v: serde_json::Value = serde_json::from_slice(&bytes).map_err(|e| Error::input(&json, format!("unreadable curves.json: {e}")))?;
        let pieces = v["pieces"].as_array().map_or(&[][..], |a| &a[..]);
        let mut curves = std::collections::BTreeSet::new();
        for p in pieces {
            n.add(p["kind"].as_str().unwrap_or(""));
            curves.insert(p["curve"].as_u64());
        }
        n.curves = curves.len() as u64;
        return Ok(Some(n));
    }
    let Some(r) = r else { return Ok(None) };
    let curves = if dir.join("curves.ply").is_file() {
        crate::curves::read_ply(&dir.join("curves.ply"))?
    } else if dir.join("curves.obj").is_file() {
        crate::curves::read_obj(&dir.join("curves.obj"))?
    } else {
        return Ok(None);
    };
    let tol = typed::tolerance(r.kappa, r.noise);
    for c in &curves {
        typed::pieces(c, tol).iter().for_each(|p| n.add(p.kind.name()));
    }
    n.curves = curves.len() as u64;
    Ok(Some(n))
}

/// The labelled copies in a run directory, by name.
fn labelled_copies(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir.join(super::labels::DIR))
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "laz" || x == "ply"))
        .collect();
    files.sort();
    files
}

/// Formats a status for humans.
pub fn render_status(s: &Status) -> String {
    let mut out = format!(
        "{}: {}\n  inputs     {}\n  tiles      {}\n  bucketed   {}\n",
        s.dir.display(),
        s.summary,
        s.inputs.len(),
        s.tiles,
        if s.bucketed { "yes" } else { "no" }
    );
    for (name, n) in s.passes.iter().filter(|_| !s.cleaned) {
        out += &format!("  {name:<10} {n}/{}\n", s.tiles);
    }
    if let Some((done, n)) = s.blocks.filter(|_| !s.cleaned) {
        out += &format!("  curves     {done}/{n} growth blocks\n");
    }
    out += &format!("  outputs    {}\n", if s.finished { "written" } else { "not yet" });
    if let Some(p) = &s.pieces {
        out += &format!(
            "  pieces     {} lines, {} arcs, {} circles, {} splines, {} polyline runs (of {} curves)\n",
            p.lines, p.arcs, p.circles, p.splines, p.polylines, p.curves
        );
    }
    if !s.labels.is_empty() {
        let copies = if s.labels.len() == 1 { "copy" } else { "copies" };
        out += &format!("  labels     {} labelled {copies} in {}/\n", s.labels.len(), super::labels::DIR);
    }
    if let Some(w) = s.work_dir.as_ref().filter(|_| !s.cleaned) {
        out += &format!("  work dir   {}\n", w.display());
    }
    out
}
