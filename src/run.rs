//! The `extract` job over a resumable run directory: plan, bucket into tiles, per-tile passes
//! (statistics, residuals, projection), then the curve stages on the gathered edge cloud.
//!
//! Run directory layout:
//! - `manifest.json`: the job (inputs with size, mtime and header checksum; parameters; crease
//!   version), the plan (grid), and what is done;
//! - `tiles/`: bucketed points; `stats/`, `resid/`, `edges/`: one result file per tile and pass;
//! - `curves.obj`, `curves.ply`, `curves.geojson`, `report.json`: the outputs.
//!
//! Every file is written to a temporary name, synced and renamed, and only then counted as
//! done, so a run killed at any moment resumes where it stopped and ends with the same curves.

use crate::cloud::{Bounds, CloudHeader, Crs, PointChunk};
use crate::curves::{write_geojson, write_obj, write_ply};
use crate::error::{Error, Result};
use crate::extract::{self, candidates::ResidualSum, cloud::Cloud, Counts, Params, Resolved, Timings, WorldCorner, WorldEdge};
use crate::io::{self, Filter, PointReader};
use crate::tiles::{within, Bucketer, Grid, Store, TilePoints};
use glam::{DVec3, I64Vec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Bytes of memory a tile point costs while processed (points, tree, per-stage arrays, the
/// halo share and the prefetched next tile).
pub const BYTES_PER_POINT: u64 = 600;

/// Most points a tile is planned to hold, whatever the memory allows. Each pass loads its
/// first tile while the cores wait, and big tiles leave little to overlap: the 20 M-point
/// scene in 2 tiles (the default budget) took 170 s; in 16 tiles, 137 s.
pub const MAX_TILE_POINTS: u64 = 2_000_000;

/// How to run a job.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Job {
    /// crease version.
    pub version: String,
    /// Input files with their stamps.
    pub inputs: Vec<InputStamp>,
    /// Method parameters as given.
    pub params: Params,
    /// Classes kept (all if None).
    pub classes: Option<Vec<u8>>,
    /// Keep withheld and noise points.
    pub keep_noise: bool,
    /// Tile edge length, if given.
    pub tile_size: Option<f64>,
    /// Memory budget in bytes.
    pub memory: u64,
}

/// What identifies an input file's content.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct InputStamp {
    /// Path as given.
    pub path: PathBuf,
    /// Size in bytes.
    pub size: u64,
    /// Modification time, nanoseconds since the epoch.
    pub mtime_ns: i128,
    /// FNV-1a hash of the first 64 KiB (header and VLRs).
    pub header_hash: String,
}

/// State of a run directory.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Manifest {
    /// The job.
    pub job: Job,
    /// Tile grid.
    pub grid: Grid,
    /// Points the headers declare.
    pub declared_points: u64,
    /// Diagonal of the inputs' union bounds.
    pub diag: f64,
    /// Bucketing finished.
    pub bucketed: bool,
    /// Points per tile after filtering.
    pub tile_points: Vec<u64>,
    /// Parameters resolved from the statistics pass.
    pub resolved: Option<Resolved>,
    /// Outputs written.
    pub finished: bool,
}

/// Options of a run beyond the method parameters.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Memory budget in bytes.
    pub memory: u64,
    /// Tile edge length override.
    pub tile_size: Option<f64>,
    /// Start over even if the directory holds a different job.
    pub force: bool,
    /// Progress output.
    pub progress: crate::progress::Mode,
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
    /// Peak resident memory of this invocation up to the end of the tile passes, bytes (the
    /// difference to `peak_rss_bytes` is what the curve stages added).
    pub peak_rss_tiles_bytes: u64,
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

/// Set by Ctrl-C / SIGTERM: passes stop after the tile in hand.
pub static STOP: AtomicBool = AtomicBool::new(false);

/// The error returned when a run was interrupted (exit code 130).
pub fn interrupted() -> Error {
    Error::Interrupted
}

fn check_stop() -> Result<()> {
    if STOP.load(Ordering::SeqCst) {
        Err(interrupted())
    } else {
        Ok(())
    }
}

/// FNV-1a, 64 bit: a stable content hash (std's hasher may change between Rust versions).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn stamp(path: &Path) -> Result<InputStamp> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| crate::error::io_input(path, e))?;
    let mtime_ns = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos() as i128);
    let mut head = vec![0u8; 65536.min(meta.len() as usize)];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)).map_err(|e| crate::error::io_input(path, e))?;
    // The path is made absolute (symbolic links kept) so that a resume from another working
    // directory, or with the same file named relatively, is recognised as the same run.
    let path = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    Ok(InputStamp { path, size: meta.len(), mtime_ns, header_hash: format!("{:016x}", fnv1a(&head)) })
}

/// Writes `bytes` to `path` atomically: temporary file, fsync, rename, fsync of the directory.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let tmp = path.with_extension("tmp");
    let r = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        if let Some(dir) = path.parent() {
            std::fs::File::open(dir)?.sync_all()?;
        }
        Ok(())
    })();
    r.map_err(|e| Error::output(path, e))
}

/// One CRS for all inputs, or an error naming the file that disagrees.
pub fn common_crs(headers: &[CloudHeader]) -> Result<Crs> {
    let known: Vec<&CloudHeader> = headers.iter().filter(|h| !h.crs.is_unknown()).collect();
    if let Some(first) = known.first() {
        for h in &known[1..] {
            if h.crs != first.crs {
                return Err(Error::input(&h.path, format!("CRS {} differs from {} in {}", h.crs.summary(), first.crs.summary(), first.path.display())));
            }
        }
        return Ok(first.crs.clone());
    }
    Ok(Crs::default())
}

/// Describes how two jobs differ, for the refusal message.
fn job_difference(old: &Job, new: &Job) -> String {
    if old.version != new.version {
        return format!("crease version changed ({} -> {})", old.version, new.version);
    }
    if old.inputs.len() != new.inputs.len() {
        return format!("the inputs changed ({} files -> {})", old.inputs.len(), new.inputs.len());
    }
    for (a, b) in old.inputs.iter().zip(&new.inputs) {
        if a.path != b.path {
            return format!("input {} is now {}", a.path.display(), b.path.display());
        }
        if a.size != b.size || a.header_hash != b.header_hash || a.mtime_ns != b.mtime_ns {
            return format!("input {} changed since the run started (size, time or header)", a.path.display());
        }
    }
    if old.params != new.params {
        return "the method parameters changed".to_string();
    }
    if old.classes != new.classes || old.keep_noise != new.keep_noise {
        return "the point filters changed".to_string();
    }
    if old.tile_size != new.tile_size || old.memory != new.memory {
        return "the tiling (--tile-size or --memory) changed".to_string();
    }
    "the job changed".to_string()
}

fn manifest_path(dir: &Path) -> PathBuf {
    dir.join("manifest.json")
}

/// Reads the manifest of a run directory, if there is one.
pub fn read_manifest(dir: &Path) -> Result<Option<Manifest>> {
    let p = manifest_path(dir);
    match std::fs::read(&p) {
        Ok(b) => serde_json::from_slice(&b).map(Some).map_err(|e| Error::input(&p, format!("unreadable manifest: {e}"))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::input(&p, e.to_string())),
    }
}

fn save(dir: &Path, m: &Manifest) -> Result<()> {
    write_atomic(&manifest_path(dir), serde_json::to_string_pretty(m).expect("manifest serialises").as_bytes())
}

/// Tile edge length for a budget: tiles hold about `memory / BYTES_PER_POINT` points (at most
/// [`MAX_TILE_POINTS`]), assuming the points spread evenly over the footprint (2D) or the
/// volume (3D) of the bounds.
pub fn tile_size_for(b: &Bounds, points: u64, memory: u64) -> f64 {
    let per_tile = (memory / BYTES_PER_POINT).clamp(10_000, MAX_TILE_POINTS) as f64;
    let ext = DVec3::from(b.max) - DVec3::from(b.min);
    let ext = ext.max(DVec3::splat(1e-9));
    let tiles = (points as f64 / per_tile).max(1.0);
    let flat = ext.z < 0.25 * ext.x.max(ext.y);
    let size = if flat { (ext.x * ext.y / tiles).sqrt() } else { (ext.x * ext.y * ext.z / tiles).cbrt() };
    // Never more than needed to hold everything in one tile.
    size.min(ext.max_element() * 1.001)
}

/// Runs (or resumes) extraction of `inputs` into the run directory `dir`.
pub fn run_extract(inputs: &[PathBuf], dir: &Path, params: &Params, filter: &Filter, opts: &RunOptions) -> Result<Report> {
    let t0 = Instant::now();
    let files = io::expand_inputs(inputs)?;
    let headers = files.iter().map(|f| io::read_header(f)).collect::<Result<Vec<_>>>()?;
    let crs = common_crs(&headers)?;
    let job = Job {
        version: env!("CARGO_PKG_VERSION").to_string(),
        inputs: files.iter().map(|f| stamp(f)).collect::<Result<_>>()?,
        params: params.clone(),
        classes: filter.classes.clone(),
        keep_noise: filter.keep_noise,
        tile_size: opts.tile_size,
        memory: opts.memory,
    };
    std::fs::create_dir_all(dir).map_err(|e| Error::output(dir, e))?;
    let mut resumed = false;
    let mut manifest = match read_manifest(dir)? {
        Some(m) if m.job == job => {
            resumed = true;
            m
        }
        Some(m) if !opts.force => {
            return Err(Error::Usage(format!(
                "{}: holds a different run: {}; use --force to start over",
                dir.display(),
                job_difference(&m.job, &job)
            )))
        }
        _ => {
            for sub in ["tiles", "stats", "resid", "edges"] {
                let _ = std::fs::remove_dir_all(dir.join(sub));
            }
            for f in ["curves.obj", "curves.ply", "curves.geojson", "report.json"] {
                let _ = std::fs::remove_file(dir.join(f));
            }
            let mut b = Bounds::EMPTY;
            let mut declared = 0;
            for h in &headers {
                let hb = if h.bounds.is_empty() { io::scan_bounds(&h.path)?.0 } else { h.bounds };
                b.union(&hb);
                declared += h.count;
            }
            if b.is_empty() {
                return Err(Error::input(&files[0], "no points"));
            }
            let size = opts.tile_size.unwrap_or_else(|| tile_size_for(&b, declared, opts.memory));
            let m = Manifest { job: job.clone(), grid: Grid::new(&b, size), declared_points: declared, diag: b.diagonal(), bucketed: false, tile_points: vec![], resolved: None, finished: false };
            save(dir, &m)?;
            m
        }
    };
    let progress = crate::progress::Progress::new(opts.progress);
    let mut pass = PassSeconds::default();
    let store = Store::new(&dir.join("tiles"))?;

    // Bucketing: all or nothing (a partial store is discarded on resume).
    if !manifest.bucketed {
        let t = Instant::now();
        let _ = std::fs::remove_dir_all(dir.join("tiles"));
        let store = Store::new(&dir.join("tiles"))?;
        let budget = (opts.memory / 4 / 48) as usize;
        let mut b = Bucketer::new(&manifest.grid, &store, budget);
        let bar = progress.bar("bucketing", manifest.declared_points, "points");
        let mut gids = Vec::new();
        // The inputs are decoded on a thread of their own, one chunk ahead of the bucketing,
        // so that decoding overlaps the sorting, compressing and writing of the tiles.
        let (tx, rx) = crossbeam_channel::bounded::<Result<(usize, PointChunk)>>(0);
        std::thread::scope(|s| -> Result<()> {
            // Owning the receiver here drops it on any early return, which stops the reader.
            let rx = rx;
            let files = &files;
            s.spawn(move || {
                for (fi, f) in files.iter().enumerate() {
                    let mut r = match PointReader::open(f, filter) {
                        Ok(r) => r,
                        Err(e) => return drop(tx.send(Err(e))),
                    };
                    loop {
                        let mut chunk = PointChunk::default();
                        match r.read_chunk(io::DEFAULT_CHUNK, &mut chunk) {
                            Ok(0) => break,
                            Ok(_) if tx.send(Ok((fi, chunk))).is_ok() => {}
                            Ok(_) => return,
                            Err(e) => return drop(tx.send(Err(e))),
                        }
                    }
                }
            });
            for msg in rx.iter() {
                let (fi, chunk) = msg?;
                // Global ids: file index in the high bits, record index in the low 40 bits.
                gids.clear();
                gids.extend(chunk.index.iter().map(|&i| ((fi as u64) << 40) | i));
                b.add(&chunk, &gids)?;
                bar.inc(chunk.len() as u64);
                check_stop()?;
            }
            Ok(())
        })?;
        b.flush()?;
        store.sync()?;
        bar.finish();
        manifest.tile_points = b.counts.clone();
        manifest.bucketed = true;
        save(dir, &manifest)?;
        pass.bucketing = t.elapsed().as_secs_f64();
    }
    let total: u64 = manifest.tile_points.iter().sum();
    if total < 10 {
        return Err(Error::input(&files[0], format!("only {total} points after filtering: nothing to extract")));
    }
    let grid = manifest.grid.clone();
    let kq = extract::key_quantum(manifest.diag);
    let tiles: Vec<u32> = (0..grid.len() as u32).filter(|&t| manifest.tile_points[t as usize] > 0).collect();
    let seed = params.seed.unwrap_or(1);

    // Statistics pass: spacing, noise and density at sampled points, with a halo wide enough
    // for the 16-kappa noise fit (kappa from a probe of the fullest tile).
    let t = Instant::now();
    let resolved = match &manifest.resolved {
        Some(r) => r.clone(),
        None => {
            let fullest = *tiles.iter().max_by_key(|&&t| (manifest.tile_points[t as usize], std::cmp::Reverse(t))).unwrap();
            let mut probe = TilePoints::default();
            store.read(fullest, &mut probe, |_, _| true)?;
            let kappa0 = crate::spacing::spacing(&probe.xyz, 2000);
            drop(probe);
            let halo0 = 24.0 * kappa0;
            let sdir = dir.join("stats");
            std::fs::create_dir_all(&sdir).map_err(|e| Error::output(&sdir, e))?;
            // (The pool has little to do here but wait for the next tile, so the tile is indexed
            // on the pool, not on the loader thread as in the passes below.)
            let time = tile_pass(&progress, "statistics", &tiles, &sdir, |t, _| load(&store, &grid, t, halo0, 1.0, seed, kq), |t, first| {
                let stats = tile_statistics(&store, &grid, t, first, halo0, kq, total, seed)?;
                let mut out: Vec<u8> = Vec::new();
                for s in stats {
                    for v in [s.0, s.1, s.2] {
                        out.extend_from_slice(&v.to_le_bytes());
                    }
                }
                Ok(out)
            })?;
            pass.statistics_load = time.load;
            let mut stats = vec![];
            for &t in &tiles {
                let b = read_result(&sdir, t)?;
                for c in b.chunks_exact(24) {
                    let v = |o: usize| f64::from_le_bytes(c[o..o + 8].try_into().unwrap());
                    stats.push((v(0), v(8), v(16)));
                }
            }
            let mut r = extract::resolve(params, &stats);
            if let Some(k) = params.kappa {
                r.kappa = k;
            }
            manifest.resolved = Some(r.clone());
            save(dir, &manifest)?;
            r
        }
    };
    pass.statistics = t.elapsed().as_secs_f64();
    let r = resolved;
    let halo = r.halo();

    // Residual pass.
    let t = Instant::now();
    let rdir = dir.join("resid");
    std::fs::create_dir_all(&rdir).map_err(|e| Error::output(&rdir, e))?;
    let time = tile_pass(&progress, "residuals", &tiles, &rdir, |t, idle| load_cloud(&store, &grid, t, (halo, r.cell_side()), r.keep, r.seed, kq, idle), |_, (cloud, core)| {
        // (The per-point steps around the fits run on the pool too: serial, they left one core
        // idle for a moment of every tile.)
        let which: Vec<u32> = (0..cloud.len() as u32).into_par_iter().filter(|&i| core[cloud.ids[i as usize] as usize]).collect();
        let res = extract::candidates::residuals(&cloud, &which, r.fit_radius, halo, r.noise_limited());
        // (In the cloud's order, which the projection pass's load of the tile gives again.)
        let mut out = Vec::with_capacity(which.len() * 12);
        for (&i, x) in which.iter().zip(res) {
            out.extend_from_slice(&cloud.gid[i as usize].to_le_bytes());
            out.extend_from_slice(&x.to_le_bytes());
        }
        Ok(out)
    })?;
    pass.residuals_load = time.load;
    // tau: the mean residual over all points (an exact sum: the same whatever the tiling).
    let residuals_of = |t: u32| -> Result<Vec<(u64, f32)>> {
        let b = read_result(&rdir, t)?;
        Ok(b.chunks_exact(12).map(|c| (u64::from_le_bytes(c[..8].try_into().unwrap()), f32::from_le_bytes(c[8..].try_into().unwrap()))).collect())
    };
    // (Read on the pool, which is idle here.)
    let per_tile: Vec<ResidualSum> = tiles.par_iter().map(|&t| residuals_of(t).map(|v| ResidualSum::of(v.iter().map(|p| p.1)))).collect::<Result<_>>()?;
    let total = per_tile.into_iter().fold(ResidualSum::default(), |a, b| a + b);
    let tau = params.tau.unwrap_or(extract::settle(total.mean()));
    pass.residuals = t.elapsed().as_secs_f64();

    // Projection pass.
    let t = Instant::now();
    let edir = dir.join("edges");
    std::fs::create_dir_all(&edir).map_err(|e| Error::output(&edir, e))?;
    let time = tile_pass(&progress, "projection", &tiles, &edir, |t, idle| load_cloud(&store, &grid, t, (halo, r.cell_side()), r.keep, r.seed, kq, idle), |t, (cloud, core)| {
        let mut res = residuals_of(t)?;
        // The core points' residuals, in the cloud's order as the residual pass wrote them (the
        // tile loads the same way in both passes); joined by global id if not.
        let core_pts: Vec<u32> = (0..cloud.len() as u32).into_par_iter().filter(|&i| core[cloud.ids[i as usize] as usize]).collect();
        let same_order = res.len() == core_pts.len() && res.par_iter().zip(&core_pts).all(|(r, &i)| r.0 == cloud.gid[i as usize]);
        let mut cand: Vec<u32> = Vec::new();
        if same_order {
            cand.extend(core_pts.iter().zip(&res).filter(|(_, r)| extract::candidates::is_candidate(r.1, tau)).map(|(&i, _)| i));
        } else {
            let mut core_ids: Vec<(u64, u32)> = core_pts.iter().map(|&i| (cloud.gid[i as usize], i)).collect();
            core_ids.par_sort_unstable();
            res.par_sort_unstable_by_key(|r| r.0);
            let mut k = 0;
            for (g, i) in core_ids {
                while k < res.len() && res[k].0 < g {
                    k += 1;
                }
                if k < res.len() && res[k].0 == g && extract::candidates::is_candidate(res[k].1, tau) {
                    cand.push(i);
                }
            }
            cand.par_sort_unstable();
        }
        if let Ok(d) = std::env::var("CREASE_DEBUG_DIR") {
            let pts: Vec<DVec3> = cand.iter().map(|&i| cloud.at(i as usize)).collect();
            extract::debug_dump(&d, &format!("candidates_{t}.obj"), &pts, cloud.origin);
        }
        let (edges, corners, one) = extract::project_core(&cloud, &cand, &r);
        Ok(encode_edges(&edges, &corners, cand.len() as u64, one))
    })?;
    pass.projection_load = time.load;
    pass.projection = t.elapsed().as_secs_f64();

    // Curve stages. Stage 3 (smoothing) is local: each tile's edge points are smoothed with
    // the edge points of the neighbouring tiles within the smoothing reach as context, so
    // only a few tiles' edge points are held at a time. Stages 4-5 run on the whole smoothed
    // edge cloud (positions and normals, 48 bytes a point).
    let t = Instant::now();
    let peak_rss_tiles = crate::mem::peak_rss();
    crate::mem::release_free_memory();
    let q = extract::snap_quantum(r.kappa);
    let load_edges = |t: u32| -> Result<Decoded> {
        let (mut e, c, n, one) = decode_edges(&read_result(&edir, t)?, &result_path(&edir, t))?;
        for x in e.iter_mut() {
            extract::snap_edge(x, q);
        }
        Ok((e, c, n, one))
    };
    // Bounds of each tile's edge points, and all corner points.
    let mut counts = Counts { points: total.count(), ..Default::default() };
    let mut boxes: Vec<(u32, DVec3, DVec3)> = vec![];
    let mut corners = vec![];
    for &t in &tiles {
        let (e, c, n, one) = load_edges(t)?;
        counts.candidates += n;
        counts.one_surface += one;
        counts.edge_points += e.len() as u64;
        counts.corner_points += c.len() as u64;
        corners.extend(c);
        if let Some(lo) = e.iter().map(|x| x.p).reduce(DVec3::min) {
            boxes.push((t, lo, e.iter().map(|x| x.p).reduce(DVec3::max).unwrap()));
        }
    }
    let origin = boxes.iter().map(|b| b.1).reduce(DVec3::min).unwrap_or(DVec3::ZERO);
    let grouped = extract::group_corners(corners, origin, &r);
    counts.corners = grouped.len() as u64;
    // (The margin covers the f32 rounding of the k-d tree's distances.)
    let reach = extract::smoothing_reach(&r) * 1.001 + 4.0 * q;
    let debug = std::env::var("CREASE_DEBUG_DIR").ok();
    let mut debug_edges = vec![];
    let mut points = Vec::with_capacity(counts.edge_points as usize);
    let mut normals = Vec::with_capacity(counts.edge_points as usize);
    let bar = progress.bar("smoothing", boxes.len() as u64, "tiles");
    for &(t, lo, hi) in &boxes {
        let (lo, hi) = (lo - DVec3::splat(reach), hi + DVec3::splat(reach));
        let inside = |p: DVec3| p.cmpge(lo).all() && p.cmple(hi).all();
        // (Decoded on the pool, which waits for them: the tile's edge points, and those of its
        // neighbours within reach, in order.)
        let (own, context) = rayon::join(
            || load_edges(t),
            || {
                let near: Vec<u32> = boxes.iter().filter(|&&(u, ulo, uhi)| u != t && ulo.cmple(hi).all() && uhi.cmpge(lo).all()).map(|b| b.0).collect();
                near.par_iter().map(|&u| Ok(load_edges(u)?.0.into_iter().filter(|e| inside(e.p)).collect::<Vec<_>>())).collect::<Result<Vec<_>>>()
            },
        );
        let (own, context) = (own?.0, context?);
        let size = own.len() + context.iter().map(Vec::len).sum::<usize>();
        let (mut block, mut block_normals) = (Vec::with_capacity(size), Vec::with_capacity(size));
        for e in own.iter().chain(context.iter().flatten()) {
            block.push(e.p - origin);
            block_normals.push(e.n);
        }
        if debug.is_some() {
            debug_edges.extend_from_slice(&block[..own.len()]);
        }
        counts.unconfirmed += extract::smooth_and_confirm(&block, &block_normals, own.len(), &grouped, &r, &mut points, &mut normals);
        bar.inc(1);
        check_stop()?;
    }
    bar.finish();
    if let Some(d) = &debug {
        extract::debug_dump(d, "edges.obj", &debug_edges, origin);
    }
    drop(debug_edges);
    let mut seconds = Timings { candidates: pass.residuals, projection: pass.projection, index: pass.statistics, smoothing: t.elapsed().as_secs_f64(), ..Default::default() };
    let curves = extract::curves_from_smoothed(points, normals, &grouped, origin, &r, &mut counts, &mut seconds);
    pass.curves = t.elapsed().as_secs_f64();

    let t = Instant::now();
    write_outputs(dir, &curves, &crs)?;
    manifest.finished = true;
    save(dir, &manifest)?;
    pass.writing = t.elapsed().as_secs_f64();
    let report = Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        inputs: files,
        params: r.clone(),
        tau,
        counts,
        seconds,
        pass_seconds: pass,
        total_seconds: t0.elapsed().as_secs_f64(),
        peak_rss_bytes: crate::mem::peak_rss(),
        peak_rss_tiles_bytes: peak_rss_tiles,
        threads: rayon::current_num_threads(),
        tiles: grid.len(),
        tile_size: grid.size,
        halo,
        resumed,
    };
    write_atomic(&dir.join("report.json"), serde_json::to_string_pretty(&report).expect("report serialises").as_bytes())?;
    Ok(report)
}

fn write_outputs(dir: &Path, curves: &[crate::curves::Polyline], crs: &Crs) -> Result<()> {
    // Each output goes to a temporary name first, then is renamed into place.
    let tmp = dir.join("out.tmp");
    std::fs::create_dir_all(&tmp).map_err(|e| Error::output(&tmp, e))?;
    write_obj(&tmp.join("curves.obj"), curves)?;
    write_ply(&tmp.join("curves.ply"), curves)?;
    write_geojson(&tmp.join("curves.geojson"), curves, crs)?;
    for f in ["curves.obj", "curves.ply", "curves.geojson"] {
        let p = tmp.join(f);
        std::fs::File::open(&p).and_then(|f| f.sync_all()).map_err(|e| Error::output(&p, e))?;
        std::fs::rename(&p, dir.join(f)).map_err(|e| Error::output(&p, e))?;
    }
    let _ = std::fs::remove_dir(&tmp);
    Ok(())
}

/// Indices of the points of `xyz` within `radius` of a point flagged in `centre` (and of some
/// a little farther), in order; None (keep every point) if that is most of them anyway, or if
/// the grid of cells this takes would be too large.
fn near(xyz: &[DVec3], centre: &[bool], radius: f64) -> Option<Vec<usize>> {
    let lo = xyz.iter().copied().reduce(DVec3::min)?;
    let hi = xyz.iter().copied().reduce(DVec3::max)?;
    // Cells a little wider than the radius, so that rounding cannot put a point within the
    // radius of a centre two cells away from it: such points lie in the centre's cell or in
    // one of the 26 around it.
    let side = radius * 1.01;
    let dims = ((hi - lo) / side).floor().as_i64vec3() + 1;
    let cells = dims.x.checked_mul(dims.y).and_then(|c| c.checked_mul(dims.z)).filter(|&c| c > 0 && c <= 1 << 28)?;
    let cell = |p: DVec3| ((p - lo) / side).floor().as_i64vec3().clamp(I64Vec3::ZERO, dims - 1);
    let index = |c: I64Vec3| (c.x + dims.x * (c.y + dims.y * c.z)) as usize;
    let mut marked = vec![false; cells as usize];
    for (&p, _) in xyz.iter().zip(centre).filter(|c| *c.1) {
        let c = cell(p);
        for d in (0..27).map(|k| I64Vec3::new(k % 3 - 1, k / 3 % 3 - 1, k / 9 - 1)) {
            let n = c + d;
            if n.cmpge(I64Vec3::ZERO).all() && n.cmplt(dims).all() {
                marked[index(n)] = true;
            }
        }
    }
    let keep: Vec<usize> = (0..xyz.len()).filter(|&i| marked[index(cell(xyz[i]))]).collect();
    (keep.len() * 4 < xyz.len() * 3).then_some(keep)
}

/// Local origin of a loaded tile: the minimum corner of its points (fits are computed in f64,
/// so the choice only moves the last bits).
fn tile_origin(tp: &TilePoints) -> DVec3 {
    tp.xyz.iter().copied().reduce(DVec3::min).unwrap_or(DVec3::ZERO)
}

/// Statistics (spacing, noise, density: see [`extract::point_stats`]) of the sampled points in
/// tile `t`'s core, given the tile loaded with halo `halo0`, in global id order.
///
/// A sample's neighbourhood is 16 of its own spacings wide, so in a sparse region it can
/// reach past the halo, and then it would depend on where the tile borders fall. Such samples
/// are computed again with the tile reloaded with a halo wide enough for them (up to
/// [`STATS_HALO_GROWTH`] times `halo0`).
#[allow(clippy::too_many_arguments)]
fn tile_statistics(store: &Store, grid: &Grid, t: u32, first: (TilePoints, Vec<bool>), halo0: f64, kq: f64, total: u64, seed: u64) -> Result<Vec<(f64, f64, f64)>> {
    let core = grid.core(t);
    let cap = STATS_HALO_GROWTH * halo0;
    let (mut tp, mut is_core) = first;
    let mut halo = halo0;
    // Only the points within `reach` of a sample are indexed (None: all of them). A tile holds a
    // few hundred samples at 100 M points, and their neighbourhoods a fifth of the points or
    // less. A sample whose ball turns out wider is computed again with a wider reach.
    let mut reach = Some(halo0);
    let mut todo: Option<Vec<u64>> = None;
    let mut done: Vec<(u64, (f64, f64, f64))> = Vec::new();
    loop {
        // (Sampled by world position, read from the store, not rebuilt from the tile's
        // local coordinates, whose round trip may not be exact.)
        let sampled: Vec<bool> = tp
            .xyz
            .par_iter()
            .zip(&tp.gid)
            .zip(&is_core)
            .map(|((&p, g), &c)| c && extract::stat_sample(extract::position_key(p, kq), total, seed) && todo.as_ref().is_none_or(|v| v.binary_search(g).is_ok()))
            .collect();
        // (The origin is the whole tile's, so the local coordinates are the same either way.)
        let origin = tile_origin(&tp);
        let keep = reach.and_then(|r| near(&tp.xyz, &sampled, r));
        let (cloud, sampled) = match &keep {
            Some(keep) => {
                let xyz: Vec<DVec3> = keep.iter().map(|&i| tp.xyz[i]).collect();
                let gid: Vec<u64> = keep.iter().map(|&i| tp.gid[i]).collect();
                (Cloud::with_origin_parallel(&xyz, &gid, origin), keep.iter().map(|&i| sampled[i]).collect())
            }
            None => (Cloud::with_origin_parallel(&tp.xyz, &tp.gid, origin), sampled),
        };
        let kept = keep.as_ref().and(reach);
        // (The tree, on the pool, which would otherwise wait for it.)
        cloud.index();
        let sample: Vec<usize> = (0..cloud.len()).into_par_iter().filter(|&i| sampled[cloud.ids[i] as usize]).collect();
        cloud.prepare_ordering(sample.len());
        let stats: Vec<Option<(f64, f64, f64)>> = sample.par_iter().map_init(Vec::new, |buf, &i| extract::point_stats(&cloud, i, buf)).collect();
        let (mut again, mut need, mut wider_halo) = (Vec::new(), 0.0f64, false);
        for (&i, s) in sample.iter().zip(stats) {
            // The widest ball the statistics read: the 16-spacing ball, with the margin of the
            // tree query (unbounded if too few neighbours were found: more may lie farther).
            let r = s.map_or(f64::INFINITY, |s| 16.0 * s.0 * (1.0 + 1e-4));
            // Whether it holds every point of the cloud: it lies within the points kept around
            // the sample, and within the loaded halo (else, up to the widest halo).
            let in_kept = kept.is_none_or(|k| r <= k);
            let in_halo = s.is_some() && within(&core, halo - r, cloud.at(i) + cloud.origin);
            if in_kept && (in_halo || halo >= cap) {
                if let Some(s) = s {
                    done.push((cloud.gid[i], s));
                }
            } else {
                again.push(cloud.gid[i]);
                need = need.max(r);
                wider_halo |= !in_halo && halo < cap;
            }
        }
        if again.is_empty() {
            break;
        }
        again.sort_unstable();
        reach = if need.is_finite() { reach.map(|k| (1.01 * need).max(2.0 * k)) } else { None };
        if wider_halo {
            halo = (1.01 * need).max(2.0 * halo).min(cap);
            drop(cloud);
            (tp, is_core) = load(store, grid, t, halo, 1.0, seed, kq)?;
        }
        todo = Some(again);
    }
    done.sort_unstable_by_key(|d| d.0);
    Ok(done.into_iter().map(|d| d.1).collect())
}

/// How much wider than its first halo the statistics pass may reload a tile (see
/// [`tile_statistics`]). Samples whose neighbourhood is wider still (isolated points) keep
/// what the widest halo holds.
const STATS_HALO_GROWTH: f64 = 4.0;

/// Loads tile `t` with its halo (see [`load`]) and stores it by grid cells of side `side`, on
/// the rayon pool if `idle` says that the pool has nothing else to do (the same cloud either
/// way).
#[allow(clippy::too_many_arguments)]
fn load_cloud(store: &Store, grid: &Grid, t: u32, (halo, side): (f64, f64), keep: f64, seed: u64, kq: f64, idle: bool) -> Result<(Cloud, Vec<bool>)> {
    let (tp, core) = load(store, grid, t, halo, keep, seed, kq)?;
    let origin = tile_origin(&tp);
    Ok((Cloud::gridded(&tp.xyz, &tp.gid, origin, side, idle), core))
}

/// Loads tile `t`'s core and the halo around it (thinned to share `keep` by id hash); the
/// flags say which points are core.
fn load(store: &Store, grid: &Grid, t: u32, halo: f64, keep: f64, seed: u64, kq: f64) -> Result<(TilePoints, Vec<bool>)> {
    let core = grid.core(t);
    let mut tp = TilePoints::default();
    let mut is_core = vec![];
    for n in grid.around(t, halo) {
        let before = tp.xyz.len();
        if n == t {
            store.read(n, &mut tp, |p, _| keep >= 1.0 || extract::keep_point(extract::position_key(p, kq), keep, seed))?;
        } else {
            store.read_near(n, Some((&core, halo)), &mut tp, |p, _| within(&core, halo, p) && (keep >= 1.0 || extract::keep_point(extract::position_key(p, kq), keep, seed)))?;
        }
        is_core.extend(std::iter::repeat(n == t).take(tp.xyz.len() - before));
    }
    Ok((tp, is_core))
}

fn result_path(dir: &Path, t: u32) -> PathBuf {
    dir.join(format!("{t}.bin"))
}

fn read_result(dir: &Path, t: u32) -> Result<Vec<u8>> {
    let p = result_path(dir, t);
    let z = std::fs::read(&p).map_err(|e| Error::input(&p, e.to_string()))?;
    zstd::decode_all(&z[..]).map_err(|e| Error::input(&p, format!("corrupt tile result: {e}")))
}

/// Seconds a tile pass spent loading tiles (reading the store, building the k-d tree: on the
/// loader thread, overlapping compute) and computing them.
#[derive(Clone, Copy, Debug, Default)]
struct PassTime {
    load: f64,
    compute: f64,
}

/// Runs every tile without a result in `dir` through `load` then `compute`, in order, storing
/// each result atomically. A loader thread loads the next tile while the current one computes
/// (rayon, inside `compute`) and is written, so reading and building overlap the fits; the
/// rendezvous channel keeps at most two tiles in memory. Tiles are independent, so an
/// interrupted pass resumes with the first tile that has no result.
fn tile_pass<T: Send>(
    progress: &crate::progress::Progress,
    name: &str,
    tiles: &[u32],
    dir: &Path,
    load: impl Fn(u32, bool) -> Result<T> + Sync,
    compute: impl Fn(u32, T) -> Result<Vec<u8>> + Sync,
) -> Result<PassTime> {
    let todo: Vec<u32> = tiles.iter().copied().filter(|&t| !result_path(dir, t).exists()).collect();
    let bar = progress.bar(name, tiles.len() as u64, "tiles");
    bar.inc((tiles.len() - todo.len()) as u64);
    let (tx, rx) = crossbeam_channel::bounded::<(u32, Result<T>)>(0);
    let load = &load;
    let todo = &todo;
    let mut time = PassTime::default();
    let load_time = std::thread::scope(|s| -> Result<f64> {
        // Owning the receiver here drops it on any early return, which unblocks the loader
        // (its send fails) before the scope joins it.
        let rx = rx;
        let loader = s.spawn(move || {
            let mut secs = 0.0;
            for (k, &t) in todo.iter().enumerate() {
                if STOP.load(Ordering::SeqCst) {
                    break;
                }
                let t0 = Instant::now();
                // (The first tile is loaded while the pool waits for it; later ones while
                // the pool computes the tile before.)
                let x = load(t, k == 0);
                secs += t0.elapsed().as_secs_f64();
                if tx.send((t, x)).is_err() {
                    break;
                }
            }
            secs
        });
        for (t, x) in rx.iter() {
            let t0 = Instant::now();
            let out = compute(t, x?)?;
            time.compute += t0.elapsed().as_secs_f64();
            let z = zstd::encode_all(&out[..], 1).map_err(|e| Error::output(dir, e))?;
            write_atomic(&result_path(dir, t), &z)?;
            bar.inc(1);
            check_stop()?;
        }
        Ok(loader.join().unwrap_or(0.0))
    })?;
    time.load = load_time;
    check_stop()?;
    bar.finish();
    Ok(time)
}

fn encode_edges(edges: &[WorldEdge], corners: &[WorldCorner], candidates: u64, one: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(32 + edges.len() * 48 + corners.len() * 32);
    for v in [edges.len() as u64, corners.len() as u64, candidates, one] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for e in edges {
        for x in e.p.to_array() {
            out.extend_from_slice(&x.to_le_bytes());
        }
        for n in e.n {
            for x in n.to_array() {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    for c in corners {
        for x in c.p.to_array() {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&c.w.to_le_bytes());
    }
    out
}

type Decoded = (Vec<WorldEdge>, Vec<WorldCorner>, u64, u64);

fn decode_edges(b: &[u8], path: &Path) -> Result<Decoded> {
    let bad = || Error::input(path, "corrupt tile result");
    if b.len() < 32 {
        return Err(bad());
    }
    let u = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    let (ne, nc) = (u(0) as usize, u(8) as usize);
    if b.len() != 32 + ne * 48 + nc * 32 {
        return Err(bad());
    }
    let f = |o: usize| f64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    let g = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let mut edges = Vec::with_capacity(ne);
    for i in 0..ne {
        let o = 32 + i * 48;
        edges.push(WorldEdge {
            p: DVec3::new(f(o), f(o + 8), f(o + 16)),
            n: [Vec3::new(g(o + 24), g(o + 28), g(o + 32)), Vec3::new(g(o + 36), g(o + 40), g(o + 44))],
        });
    }
    let mut corners = Vec::with_capacity(nc);
    for i in 0..nc {
        let o = 32 + ne * 48 + i * 32;
        corners.push(WorldCorner { p: DVec3::new(f(o), f(o + 8), f(o + 16)), w: f(o + 24) });
    }
    Ok((edges, corners, u(16), u(24)))
}

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
    /// Outputs written.
    pub finished: bool,
    /// One-line summary.
    pub summary: String,
}

/// Reads what a run directory has done.
pub fn status(dir: &Path) -> Result<Status> {
    let m = read_manifest(dir)?.ok_or_else(|| Error::input(dir, "not a crease run directory (no manifest.json)"))?;
    let tiles: Vec<u32> = (0..m.tile_points.len() as u32).filter(|&t| m.tile_points[t as usize] > 0).collect();
    let done = |sub: &str| tiles.iter().filter(|&&t| result_path(&dir.join(sub), t).exists()).count();
    let passes: Vec<(String, usize)> = [("statistics", "stats"), ("residuals", "resid"), ("projection", "edges")].iter().map(|(n, d)| (n.to_string(), done(d))).collect();
    let summary = if m.finished {
        "finished".to_string()
    } else if !m.bucketed {
        "bucketing not finished (it restarts from the beginning)".to_string()
    } else {
        match passes.iter().find(|p| p.1 < tiles.len()) {
            Some((name, n)) => format!("in {name}: {n} of {} tiles done", tiles.len()),
            None => "curves and outputs left to do".to_string(),
        }
    };
    Ok(Status { dir: dir.to_path_buf(), inputs: m.job.inputs.iter().map(|i| i.path.clone()).collect(), tiles: tiles.len(), bucketed: m.bucketed, passes, finished: m.finished, summary })
}

/// Formats a status for humans.
pub fn render_status(s: &Status) -> String {
    let mut out = format!("{}: {}\n  inputs     {}\n  tiles      {}\n  bucketed   {}\n", s.dir.display(), s.summary, s.inputs.len(), s.tiles, if s.bucketed { "yes" } else { "no" });
    for (name, n) in &s.passes {
        out += &format!("  {name:<10} {n}/{}\n", s.tiles);
    }
    out += &format!("  outputs    {}\n", if s.finished { "written" } else { "not yet" });
    out
}

#[cfg(test)]
mod tests {
    use super::near;
    use glam::DVec3;

    #[test]
    fn near_keeps_every_point_within_the_radius_of_a_centre_and_drops_far_ones() {
        let mut rng = crate::synth::rng::Rng::stream(3, 0);
        // Points on a tilted plane 1 km from the origin, a few of them centres.
        let pts: Vec<DVec3> = (0..200_000).map(|_| DVec3::new(1000.0 + 50.0 * rng.f64(), -700.0 + 50.0 * rng.f64(), 0.0)).map(|p| DVec3::new(p.x, p.y, 0.3 * p.x - 0.2 * p.y)).collect();
        let centre: Vec<bool> = (0..pts.len()).map(|i| i % 5000 == 17).collect();
        let radius = 0.7;
        let keep = near(&pts, &centre, radius).expect("a few centres keep a small share");
        assert!(keep.windows(2).all(|w| w[0] < w[1]), "in order");
        let centres: Vec<DVec3> = (0..pts.len()).filter(|&i| centre[i]).map(|i| pts[i]).collect();
        let dist = |p: DVec3| centres.iter().map(|c| c.distance(p)).fold(f64::INFINITY, f64::min);
        let kept: std::collections::HashSet<usize> = keep.iter().copied().collect();
        for (i, &p) in pts.iter().enumerate() {
            let d = dist(p);
            if d <= radius {
                assert!(kept.contains(&i), "point {i} at {d} from a centre was dropped");
            }
            // (Kept points lie in a centre's cell or a neighbouring one.)
            if kept.contains(&i) {
                assert!(d <= 2.0 * 1.01 * radius * 3f64.sqrt() + 1e-9, "point {i} at {d} was kept");
            }
        }
        assert!(keep.len() < pts.len() / 10);
        // Most of the points near: keep them all.
        let all: Vec<bool> = (0..pts.len()).map(|i| i % 50 == 0).collect();
        assert_eq!(near(&pts, &all, radius), None);
    }
}
