//! The run directory's manifest: the job (inputs, parameters, version), the plan (the tile
//! grid) and what is done. Re-running the same job continues it; a different job is refused.

use crate::error::{io_input, Error, Result};
use crate::extract::{Params, Resolved};
use crate::keys::fnv1a;
use crate::points::{CloudHeader, Crs};
use crate::tiles::Grid;
use crate::workspace::Workspace;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The manifest's name in a run directory.
pub const NAME: &str = "manifest.json";

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
    /// Text clouds' columns, if given.
    pub text: Option<crate::io::TextColumns>,
    /// The box points are kept in, if given (`--bounds`; absent from manifests of 0.6).
    #[serde(default)]
    pub bounds: Option<crate::points::Bounds>,
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
    pub(crate) grid: Grid,
    /// Points the headers declare.
    pub(crate) declared_points: u64,
    /// Diagonal of the inputs' union bounds.
    pub(crate) diag: f64,
    /// Bucketing finished.
    pub(crate) bucketed: bool,
    /// Points per tile after filtering.
    pub(crate) tile_points: Vec<u64>,
    /// Parameters resolved from the statistics pass.
    pub(crate) resolved: Option<Resolved>,
    /// Outputs written.
    pub(crate) finished: bool,
    /// Where the working data (tiles and per-tile results) is, if not in the run directory
    /// (`--work-dir`; absolute).
    #[serde(default)]
    pub(crate) work_dir: Option<PathBuf>,
    /// The working data was removed once the outputs were written (`--clean`).
    #[serde(default)]
    pub(crate) cleaned: bool,
    /// The bounds of the cloud without its far points, once bucketing found some (see
    /// `run/far.rs`): the grid is planned over them and the points outside are left out.
    #[serde(default)]
    pub(crate) kept: Option<crate::points::Bounds>,
    /// Points left out as far from all the others.
    #[serde(default)]
    pub(crate) far_points: u64,
    /// The radius within which near duplicates are collapsed, once the first statistics pass
    /// found them (0: none found, or not measured yet; see
    /// [`near_duplicate_radius`](crate::extract::statistics::near_duplicate_radius)).
    #[serde(default)]
    pub(crate) near_radius: f64,
    /// Points dropped as exact and as near copies of others (counted by the statistics pass).
    #[serde(default)]
    pub(crate) duplicates: [u64; 2],
    /// Number of workers sharing the run, if worker 0 planned it (`--worker 0/N`): workers of
    /// another count would share the tiles out otherwise, leaving some to no one.
    #[serde(default)]
    pub(crate) workers: Option<u32>,
    /// The low corner of the points bucketed (absent from older manifests): where the
    /// curve stage is anchored, rather than at the corner of the bounds the inputs declare.
    #[serde(default)]
    pub(crate) points_min: Option<[f64; 3]>,
    /// The run directory's layout: [`LAYOUT`] keeps the working data in `work/` (unless
    /// `work_dir` says elsewhere); 0, that of manifests without the field (crease 0.8 and
    /// earlier), keeps it at the top of the run directory, beside the outputs.
    #[serde(default)]
    pub(crate) layout: u32,
}

/// The layout of the run directories crease makes (see [`Manifest::layout`]).
pub(super) const LAYOUT: u32 = 1;

/// The stamp of input file `path`: size, modification time, hash of the first 64 KiB.
pub(super) fn stamp(path: &Path) -> Result<InputStamp> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| io_input(path, e))?;
    let mtime_ns = meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map_or(0, |d| d.as_nanos() as i128);
    let mut head = vec![0u8; 65536.min(meta.len() as usize)];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)).map_err(|e| io_input(path, e))?;
    // The path is made absolute (symbolic links kept) so that a resume from another working
    // directory, or with the same file named relatively, is recognised as the same run.
    let path = lexically_normal(&std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf()));
    Ok(InputStamp { path, size: meta.len(), mtime_ns, header_hash: format!("{:016x}", fnv1a(&head)) })
}

/// One CRS for all inputs, or an error naming the file that disagrees. Files without a CRS
/// are taken to be in the others' CRS; each such file is named in the returned warnings.
pub(crate) fn common_crs(headers: &[CloudHeader]) -> Result<(Crs, Vec<String>)> {
    let known: Vec<&CloudHeader> = headers.iter().filter(|h| !h.crs.is_unknown()).collect();
    let Some(first) = known.first() else {
        return Ok((Crs::default(), vec![]));
    };
    for h in &known[1..] {
        if !h.crs.agrees(&first.crs) {
            return Err(Error::input(&h.path, format!("CRS {} differs from {} in {}", h.crs.summary(), first.crs.summary(), first.path.display())));
        }
    }
    let warnings = headers
        .iter()
        .filter(|h| h.crs.is_unknown())
        .map(|h| format!("{}: has no CRS; taken to be in {}'s ({})", h.path.display(), first.path.display(), first.crs.summary()))
        .collect();
    Ok((first.crs.clone(), warnings))
}

/// Reads the manifest of a workspace, if there is one.
pub(super) fn read(ws: &Workspace) -> Result<Option<Manifest>> {
    match ws.read(NAME)? {
        Some(b) => {
            serde_json::from_slice(&b).map(Some).map_err(|e| Error::Damaged { path: ws.path(NAME), what: "unreadable manifest".into(), source: Some(e.into()) })
        }
        None => Ok(None),
    }
}

/// Saves the manifest atomically.
pub(super) fn save(ws: &Workspace, m: &Manifest) -> Result<()> {
    ws.write_atomic(NAME, serde_json::to_string_pretty(m).expect("manifest serialises").as_bytes())
}

/// `p` with `.` and `..` components resolved by name (`sub/../f.las` is `f.las`), so that
/// the same file named two ways is one input. (Where `sub` is a symbolic link the name may
/// point elsewhere; the stamp's size, time and header hash then tell the files apart.)
fn lexically_normal(p: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// Describes how two jobs differ, for the refusal message.
pub(super) fn job_difference(old: &Job, new: &Job) -> String {
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
    if old.classes != new.classes || old.keep_noise != new.keep_noise || old.text != new.text || old.bounds != new.bounds {
        return "the point filters changed".to_string();
    }
    if old.tile_size != new.tile_size || old.memory != new.memory {
        return "the tiling (--tile-size or --memory) changed".to_string();
    }
    "the job changed".to_string()
}
