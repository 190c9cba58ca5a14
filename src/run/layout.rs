//! The run directory: the names of what it holds (the layout is described in the module docs
//! of [`crate::run`]), its work directory, the outputs written into it, and `--clean`.

use super::manifest::{self, Manifest};
use super::records::{self, Edges, Finished, Pieces, Record, Residuals, Smoothed, Stats, Survey};
use super::state::Run;
use super::types::ShapeCounts;
use crate::curves::{typed, Curves, Format, Polyline};
use crate::error::{Error, Result};
use crate::extract::Resolved;
use crate::keys::{keep_point, key_quantum, position_key};
use crate::points::{Crs, TilePoints};
use crate::salts;
use crate::tiles::Store;
use crate::workspace::Workspace;
use glam::DVec3;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The files a finished run writes into its directory.
pub const OUTPUTS: [&str; 7] = ["curves.obj", "curves.ply", "curves.geojson", "curves.gpkg", "curves.dxf", "preview.png", "report.json"];

/// Written on demand by [`write_view`].
pub(super) const VIEW: &str = "view.html";

/// The top-level names of a run's working data: the tile store and the per-tile results.
pub(super) const WORKING: [&str; 8] = [crate::tiles::DIR, Stats::DIR, Residuals::DIR, Edges::DIR, Survey::DIR, Smoothed::DIR, Pieces::DIR, Finished::DIR];

/// The subdirectory of the run directory that holds the working data, unless `--work-dir` puts
/// it elsewhere.
pub(super) const WORK: &str = "work";

/// Name of the file by which a work directory names the run directory it belongs to.
pub(super) const WORK_OWNER: &str = "crease-run";

/// Points `ws` at the working data of the run `m` describes: its `--work-dir`, else `work/`
/// in the run directory, or the top of the run directory for a run of the older layout (see
/// [`Manifest::layout`]). A cleaned run has none.
pub(super) fn use_work_dir(ws: &mut Workspace, m: &Manifest) -> Result<()> {
    match &m.work_dir {
        Some(w) => ws.set_work_dir(Some(w), &WORKING),
        None if m.layout == 0 || m.cleaned => Ok(()),
        None => {
            let work = ws.root().join(WORK);
            ws.set_work_dir(Some(&work), &WORKING)
        }
    }
}

/// Removes a run's working data, wherever `ws` has it.
pub(super) fn remove_working_data(ws: &Workspace) {
    for name in WORKING {
        ws.remove(name);
    }
}

/// Makes `dir` the work directory of the run in `run_dir`, returning it absolute: created if
/// need be, and refused if it is the run directory or holds another run's working data (two
/// runs there would overwrite each other's tiles).
pub(super) fn claim_work_dir(dir: &Path, run_dir: &Path) -> Result<PathBuf> {
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

/// True if `f` (canonical) is a file or directory a run in `dir` (canonical) writes.
pub(super) fn is_run_file(dir: &Path, f: &Path) -> bool {
    let Ok(rel) = f.strip_prefix(dir) else {
        return false;
    };
    let top = rel.components().next().map(|c| c.as_os_str().to_string_lossy().into_owned()).unwrap_or_default();
    // (Workers' locks are `lock.<i>`.)
    // (The working data of a run of the older layout is at the top.)
    (WORKING.contains(&top.as_str()) || [WORK, "out.tmp", manifest::NAME, "lock", VIEW, super::labels::DIR].contains(&top.as_str()))
        || OUTPUTS.contains(&top.as_str())
        || top.strip_prefix("lock.").is_some_and(|i| i.parse::<u32>().is_ok())
}

/// About `points` of the run's points, chosen by position key (so the same whatever the
/// tiling), read from the tile store.
/// Stops with [`Error::Interrupted`] once `cancel` is set.
fn sample_tiles(ws: &Workspace, manifest: &Manifest, tiles: &[u32], points: f64, cancel: &crate::cancel::Cancel) -> Result<Vec<DVec3>> {
    let total: u64 = manifest.tile_points.iter().sum();
    let share = points / total.max(1) as f64;
    let kq = key_quantum(manifest.diag);
    let store = Store::new(ws)?.cancelled_by(cancel);
    let parts: Vec<Vec<DVec3>> = tiles
        .par_iter()
        .map(|&t| {
            let mut tp = TilePoints::default();
            store.read(t, &mut tp, |p, _| keep_point(position_key(p, kq) ^ salts::PREVIEW_SAMPLE, share, 1))?;
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
    let points = if m.cleaned { vec![] } else { sample_tiles(&ws, &m, &tiles, crate::view::VIEW_POINTS, &crate::cancel::Cancel::default())? };
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

impl Run<'_> {
    /// The finished curves, of the `batches` batches [`Run::curves`] wrote.
    pub(super) fn finished_curves(&self, batches: u32) -> FinishedCurves<'_> {
        FinishedCurves { ws: &self.ws, batches, cancel: &self.opts.cancel }
    }

    /// The write step: the curves of the `batches` batches the curve stage wrote go to the
    /// outputs (in the CRS `crs`), with `preview.png`; then the run is marked finished.
    /// Returns the curves written, by shape.
    pub(super) fn write(&mut self, batches: u32, crs: &Crs, r: &Resolved) -> Result<ShapeCounts> {
        let curves = self.finished_curves(batches);
        let shapes = ShapeCounts::of(&curves)?;
        let t = std::time::Instant::now();
        write_outputs(self.ws.root(), &curves, crs, &self.preview_sample()?, &self.opts.formats, typed::tolerance(r.kappa, r.noise))?;
        self.manifest.finished = true;
        manifest::save(&self.ws, &self.manifest)?;
        self.pass.writing = t.elapsed().as_secs_f64();
        Ok(shapes)
    }

    /// About [`PREVIEW_POINTS`](crate::preview::PREVIEW_POINTS) of the cloud's points, chosen
    /// by position key from the tile store, in tile order.
    fn preview_sample(&self) -> Result<Vec<DVec3>> {
        sample_tiles(&self.ws, &self.manifest, &self.tiles, crate::preview::PREVIEW_POINTS, &self.opts.cancel)
    }
}

/// A run's finished curves, kept in its working data a batch at a time (see [`Finished`]),
/// read until `cancel` is set (then [`Error::Interrupted`]: an output being written is left
/// under its temporary name, and written again when the run is resumed).
pub(super) struct FinishedCurves<'a> {
    ws: &'a Workspace,
    batches: u32,
    cancel: &'a crate::cancel::Cancel,
}

impl Curves for FinishedCurves<'_> {
    fn each(&self, f: &mut dyn FnMut(&Polyline) -> Result<()>) -> Result<()> {
        for b in 0..self.batches {
            for (k, c) in records::read::<Finished>(self.ws, b)?.0.iter().enumerate() {
                if k % 256 == 0 {
                    self.cancel.check()?;
                }
                f(c)?;
            }
        }
        self.cancel.check()
    }
}

/// Writes the curves in `formats` and `preview.png` (over the points `sample`) into `dir`, each
/// to a temporary name first; an output of a format not asked for this time is removed.
fn write_outputs(dir: &Path, curves: &(impl Curves + ?Sized), crs: &Crs, sample: &[DVec3], formats: &[Format], tolerance: f64) -> Result<()> {
    // Each output goes to a temporary name first, then is renamed into place.
    let tmp = dir.join("out.tmp");
    std::fs::create_dir_all(&tmp).map_err(|e| Error::output(&tmp, e))?;
    let (written, preview) = rayon::join(
        || formats.iter().try_for_each(|f| f.write(&tmp.join(f.file_name()), curves, crs, tolerance)),
        || crate::preview::write_png(&tmp.join("preview.png"), sample, curves, tolerance),
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

/// Removes the working data of the finished run `m` describes (`--clean`), and its work
/// directory if it has one, then marks it so in the manifest.
pub(super) fn clean(ws: &Workspace, m: &mut Manifest) -> Result<()> {
    remove_working_data(ws);
    if let Some(w) = &m.work_dir {
        let _ = std::fs::remove_file(w.join(WORK_OWNER));
        let _ = std::fs::remove_dir(w);
    } else if m.layout > 0 {
        let _ = std::fs::remove_dir(ws.root().join(WORK));
    }
    m.cleaned = true;
    manifest::save(ws, m)
}
