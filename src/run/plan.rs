//! The plan step: a run continues the job its directory holds, or plans it anew, a tile grid
//! over the cloud's bounds sized from the memory budget.

use super::budgets::{BYTES_PER_POINT, MAX_TILE_POINTS, MIN_TILE_POINTS};
use super::layout::{claim_work_dir, remove_working_data, use_work_dir, OUTPUTS, VIEW, WORK, WORKING, WORK_OWNER};
use super::manifest::{self, Job, Manifest};
use super::state::Planned;
use super::types::{RunOptions, Worker};
use crate::error::{Error, Result};
use crate::points::Bounds;
use crate::tiles::Grid;
use crate::workspace::Workspace;
use glam::DVec3;
use std::path::Path;

/// Tile edge length for a budget: tiles hold about `memory / BYTES_PER_POINT` points (at most
/// [`MAX_TILE_POINTS`], at least [`MIN_TILE_POINTS`]), assuming the points spread evenly over the footprint (2D) or the
/// volume (3D) of the bounds. An extent narrower than a quarter of the tiles so sized is one
/// tile across, and the tiles are sized over the others: a corridor's grid of square tiles as
/// wide as the footprint's area asks for has a tile every few metres along it, each holding a
/// sliver of the points, and a run pays the halo and the overhead of every one of them.
pub(crate) fn tile_size_for(b: &Bounds, points: u64, memory: u64) -> f64 {
    let per_tile = (memory / BYTES_PER_POINT).clamp(MIN_TILE_POINTS, MAX_TILE_POINTS) as f64;
    let ext = DVec3::from(b.max) - DVec3::from(b.min);
    let ext = ext.max(DVec3::splat(1e-9));
    let tiles = (points as f64 / per_tile).max(1.0);
    let flat = ext.z < 0.25 * ext.x.max(ext.y);
    let mut size = if flat { (ext.x * ext.y / tiles).sqrt() } else { (ext.x * ext.y * ext.z / tiles).cbrt() };
    let mut sides = if flat { vec![ext.x, ext.y] } else { vec![ext.x, ext.y, ext.z] };
    sides.sort_by(f64::total_cmp);
    while sides.len() > 1 && sides[0] < 0.25 * size {
        sides.remove(0);
        size = if sides.len() == 2 { (sides[0] * sides[1] / tiles).sqrt() } else { sides[0] / tiles };
    }
    // Never more than needed to hold everything in one tile.
    size.min(ext.max_element() * 1.001)
}

/// The plan step: continues the job the workspace holds, or plans it anew (the tile grid over
/// `bounds()`, sized from the budget); a different job is refused, and `--force` always starts
/// over.
pub(super) fn plan(ws: &mut Workspace, job: Job, bounds: impl FnOnce() -> Result<(Bounds, u64)>, opts: &RunOptions, worker: Option<Worker>) -> Result<Planned> {
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
            refuse_resuming(ws, &m, opts, worker)?;
            use_work_dir(ws, &m)?;
            refuse_damaged(ws, &m)?;
            Ok(Planned { manifest: m, resumed: true })
        }
        Some(m) => {
            Err(Error::Usage(format!("{}: holds a different run: {}; use --force to start over", ws.root().display(), manifest::job_difference(&m.job, &job))))
        }
        None => plan_anew(ws, job, bounds, opts, worker),
    }
}

/// Refuses to resume the run `m` describes as this invocation would: its working data was
/// removed, it is asked to keep it elsewhere, it is shared by another number of workers, or its
/// work directory belongs to another run.
fn refuse_resuming(ws: &Workspace, m: &Manifest, opts: &RunOptions, worker: Option<Worker>) -> Result<()> {
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
    Ok(())
}

/// Refuses a manifest whose plan crease did not make: an edited or damaged manifest must not
/// size what the run allocates.
fn refuse_damaged(ws: &Workspace, m: &Manifest) -> Result<()> {
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
    Ok(())
}

/// Plans `job` anew over an emptied run directory and work directory (`work/` in the run
/// directory unless the options give one): the tile grid over `bounds()`, sized from the memory
/// budget unless a tile size is given; the manifest is saved.
fn plan_anew(ws: &mut Workspace, job: Job, bounds: impl FnOnce() -> Result<(Bounds, u64)>, opts: &RunOptions, worker: Option<Worker>) -> Result<Planned> {
    let work_dir = match &opts.work_dir {
        Some(w) => Some(claim_work_dir(w, ws.root())?),
        None => None,
    };
    // (Working data at the top is that of a run of the older layout.)
    remove_working_data(ws);
    for name in [VIEW, super::labels::DIR].into_iter().chain(OUTPUTS) {
        ws.remove(name);
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
    // (Only now: a run refused before it is planned leaves no work directory behind.)
    let work = work_dir.clone().unwrap_or_else(|| ws.root().join(WORK));
    ws.set_work_dir(Some(&work), &WORKING)?;
    remove_working_data(ws);
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
        near_radius: 0.0,
        duplicates: [0, 0],
        points_min: None,
        workers: worker.map(|w| w.count),
        layout: manifest::LAYOUT,
    };
    manifest::save(ws, &m)?;
    Ok(Planned { manifest: m, resumed: false })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cube's tiles are sized as before (no extent is narrow); a strip far longer than wide
    /// is one tile across, and its tiles hold the points the budget asks for.
    #[test]
    fn a_narrow_extent_is_one_tile_across() {
        let b = |max: [f64; 3]| Bounds { min: [0.0; 3], max };
        let memory = 256 << 20;
        let per_tile = (memory / BYTES_PER_POINT) as f64;
        let cube = tile_size_for(&b([1.0, 1.0, 1.0]), 4_000_000, memory);
        assert_eq!(cube, (1.0 * 1.0 * 1.0 / (4e6 / per_tile)).cbrt());
        let strip = tile_size_for(&b([10_000.0, 1.0, 0.01]), 30_000, memory);
        assert!(strip >= 10_000.0, "{strip}");
        let long = tile_size_for(&b([10_000.0, 1.0, 0.01]), 4_000_000, memory);
        assert!((long / (10_000.0 / (4e6 / per_tile)) - 1.0).abs() < 1e-12, "{long}");
        assert_eq!(Grid::new(&b([10_000.0, 1.0, 0.01]), long).len(), (4e6 / per_tile).floor() as usize + 1);
    }
}
