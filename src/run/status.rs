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
        summary,
    })
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
    if let Some(w) = s.work_dir.as_ref().filter(|_| !s.cleaned) {
        out += &format!("  work dir   {}\n", w.display());
    }
    out
}
