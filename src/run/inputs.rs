//! A run's input files: the paths given, expanded, with what belongs to a run (this one's
//! outputs and working data, another run's directory) passed over; their headers, the CRS of
//! the outputs, the bounds of the points, and the warnings found on the way.

use super::layout::{is_run_file, WORK_OWNER};
use super::manifest::{self, common_crs, Job};
use super::types::RunOptions;
use crate::curves::Outside;
use crate::error::{Error, Result};
use crate::extract::Params;
use crate::io::{self, Filter};
use crate::points::{Bounds, CloudHeader, Crs, Precision};
use crate::tiles::Grid;
use glam::DVec3;
use std::path::{Path, PathBuf};

/// The input files of a run, their headers and the outputs' CRS, and the warnings of the run so
/// far.
pub(super) struct InputFiles {
    /// The point files, in order.
    pub(super) files: Vec<PathBuf>,
    /// Their headers.
    pub(super) headers: Vec<CloudHeader>,
    /// The outputs' CRS: the one assigned, or the one the inputs share.
    pub(super) crs: Crs,
    /// What the run found doubtful but went on with.
    pub(super) warnings: Warnings,
}

impl InputFiles {
    /// Expands `inputs` (files or directories) and reads the headers of the point files among
    /// them, leaving out the files of the run in `dir` and of other runs.
    pub(super) fn gather(inputs: &[PathBuf], dir: &Path, opts: &RunOptions) -> Result<InputFiles> {
        // (An input directory that is also the run directory holds the run's own curves.ply: a
        // second run would read it as points.)
        let run_dir = dir.canonicalize().ok();
        // (Nor may a work directory's tile store, `.pts` files, be read as text clouds.)
        let in_work_dir = |c: &Path| c.ancestors().skip(1).any(|a| a.join(WORK_OWNER).is_file());
        let in_run_dir = |f: &Path| f.canonicalize().is_ok_and(|c| run_dir.as_deref().is_some_and(|r| is_run_file(r, &c)) || in_work_dir(&c));
        let expanded = io::expand_inputs(inputs, opts.recursive)?;
        // (Another run's directory holds its curves and tile store, not a scan.)
        let other_runs = other_run_directories(&expanded.files, run_dir.as_deref());
        let in_run_dir = |f: &Path| in_run_dir(f) || f.canonicalize().is_ok_and(|c| other_runs.iter().any(|d| c.starts_with(d)));
        let mut warnings = Warnings::new(opts.warn);
        for d in &other_runs {
            warnings.push(format!("{}: passed over: a crease run directory (its curves and working files are not a scan)", d.display()));
        }
        warnings.extend(expanded.warnings(in_run_dir));
        let in_run_dir = |f: &PathBuf| in_run_dir(f);
        let files: Vec<PathBuf> = expanded.files.into_iter().filter(|f| !in_run_dir(f)).collect();
        if files.is_empty() {
            return match inputs.first() {
                Some(dir) => Err(Error::input(dir, "holds no point files but the run's own outputs")),
                None => Err(Error::Usage("no input files".into())),
            };
        }
        let headers = files.iter().map(|f| io::read_header(f)).collect::<Result<Vec<_>>>()?;
        let crs = outputs_crs(&headers, opts, &mut warnings)?;
        for h in headers.iter().filter(|h| h.format.has_header_bounds() && !h.bounds.is_usable()) {
            warnings.push(format!("{}: the header's bounds are not usable (not finite or inverted); bounds come from the points", h.path.display()));
        }
        Ok(InputFiles { files, headers, crs, warnings })
    }

    /// The first input file, which errors about the cloud as a whole name.
    pub(super) fn first(&self) -> &Path {
        &self.files[0]
    }

    /// The job these inputs make with `params`, `filter` and the options that shape the plan.
    pub(super) fn job(&self, params: &Params, filter: &Filter, opts: &RunOptions) -> Result<Job> {
        Ok(Job {
            version: env!("CARGO_PKG_VERSION").to_string(),
            inputs: self.files.iter().map(|f| manifest::stamp(f)).collect::<Result<_>>()?,
            params: params.without_defaults(),
            classes: filter.classes.clone(),
            keep_noise: filter.keep_noise,
            text: filter.text,
            bounds: filter.bounds,
            tile_size: opts.tile_size,
            memory: opts.memory,
        })
    }

    /// The bounds of the points `filter` keeps, and the number of points the inputs declare:
    /// from the headers, or from the points where a header's bounds are missing (PLY, E57,
    /// text), not finite or inverted.
    /// Stops with [`Error::Interrupted`] once `cancel` is set.
    pub(super) fn bounds(&mut self, filter: &Filter, cancel: &crate::cancel::Cancel) -> Result<(Bounds, u64)> {
        let mut b = Bounds::EMPTY;
        let mut declared = 0;
        for h in &self.headers {
            if h.bounds.is_usable() {
                b.union(&h.bounds);
                declared += h.count;
            } else {
                let (scanned, n, said) = io::scan_bounds_declared(&h.path, filter, cancel)?;
                if let Some(said) = said.filter(|&s| s != n) {
                    self.warnings.push(format!("{}: its PTS count lines declare {said} points; it holds {n}, which are read", h.path.display()));
                }
                b.union(&scanned);
                // (Text clouds declare no count: the scan's stands in.)
                declared += if h.count > 0 { h.count } else { n };
            }
        }
        if b.is_empty() {
            return Err(Error::input(self.first(), "no points"));
        }
        if let Some(only) = &filter.bounds {
            let inside = b.intersection(only);
            if inside.is_empty() {
                return Err(Error::Usage(format!("--bounds ({}) holds none of the inputs' points ({})", only.ranges(), b.ranges())));
            }
            b = inside;
        }
        Ok((b, declared))
    }

    /// Where the scanners saw the surfaces from: `--outside` if given, else
    /// [`Outside::Scanners`] if any file gives scan positions (E57), else [`Outside::Unknown`].
    pub(super) fn outside(&self, opts: &RunOptions) -> Outside {
        if let Some(o) = &opts.outside {
            return o.clone();
        }
        let scanners: Vec<DVec3> = self.headers.iter().flat_map(|h| h.scanners.iter().copied()).collect();
        if scanners.is_empty() {
            Outside::Unknown
        } else {
            Outside::Scanners(scanners)
        }
    }

    /// Warns of every input whose coordinates are coarse for the point spacing `kappa` (see
    /// [`coarse_coordinates`]).
    pub(super) fn warn_coarse_coordinates(&mut self, grid: &Grid, kappa: f64) {
        for h in &self.headers {
            if let Some(w) = coarse_coordinates(h, grid, kappa) {
                self.warnings.push(w);
            }
        }
    }
}

/// The outputs' CRS: the one assigned (warning of each input it replaces), or the one the
/// inputs share.
fn outputs_crs(headers: &[CloudHeader], opts: &RunOptions, warnings: &mut Warnings) -> Result<Crs> {
    match &opts.assign_crs {
        Some(assigned) => {
            for h in headers.iter().filter(|h| !h.crs.is_unknown() && !h.crs.agrees(assigned)) {
                warnings.push(format!("{}: its CRS {} is replaced by the one assigned, {}", h.path.display(), h.crs.summary(), assigned.summary()));
            }
            Ok(assigned.clone())
        }
        None => {
            let (crs, crs_warnings) = common_crs(headers)?;
            warnings.extend(crs_warnings);
            Ok(crs)
        }
    }
}

/// Warnings of a run: each is passed to the run's handler as it is found, and listed in the
/// report.
pub(super) struct Warnings {
    handler: fn(&str),
    list: Vec<String>,
}

impl Warnings {
    fn new(handler: fn(&str)) -> Self {
        Warnings { handler, list: vec![] }
    }

    pub(super) fn push(&mut self, w: String) {
        (self.handler)(&w);
        self.list.push(w);
    }

    pub(super) fn into_list(self) -> Vec<String> {
        self.list
    }
}

impl Extend<String> for Warnings {
    fn extend<I: IntoIterator<Item = String>>(&mut self, iter: I) {
        for w in iter {
            self.push(w);
        }
    }
}

/// A warning when file `h` stores coordinates in steps coarser than half the point spacing
/// `kappa`: the quantisation then acts as noise of about a third of a step (RMS), as large as a
/// scanner's, and float32 files with large coordinates (UTM, say) lose the edges.
fn coarse_coordinates(h: &CloudHeader, grid: &Grid, kappa: f64) -> Option<String> {
    // (PLY headers hold no bounds: the grid's box, which holds every file, stands in.)
    let far = std::array::from_fn(|a| grid.origin[a] + grid.dims[a] as f64 * grid.size);
    let b = if h.bounds.is_usable() { h.bounds } else { Bounds { min: grid.origin, max: far } };
    let step = h.precision.step(&b);
    let how = match h.precision {
        Precision::Float(23) => "float32 coordinates",
        Precision::Float(_) => "float64 coordinates",
        Precision::Scaled(_) => "its scale factor",
    };
    (step > 0.5 * kappa).then(|| {
        format!(
            "{}: {how} step by {step:.3e} here, {:.1} times the point spacing ({kappa:.3e}): the curves lose detail{}",
            h.path.display(),
            step / kappa,
            if matches!(h.precision, Precision::Float(23)) { "; store double coordinates or move the origin nearer" } else { "" }
        )
    })
}

/// The crease run directories (canonical) that hold some of `files`, other than `this_run`: a
/// directory whose manifest is a run's (a job and a tile grid).
fn other_run_directories(files: &[PathBuf], this_run: Option<&Path>) -> Vec<PathBuf> {
    let mut seen: std::collections::HashMap<PathBuf, bool> = std::collections::HashMap::new();
    let mut runs = vec![];
    for f in files {
        let Ok(c) = f.canonicalize() else { continue };
        for a in c.ancestors().skip(1) {
            if Some(a) == this_run {
                continue;
            }
            let is_run = *seen.entry(a.to_path_buf()).or_insert_with(|| {
                let m = a.join(manifest::NAME);
                m.is_file()
                    && std::fs::read(&m)
                        .ok()
                        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
                        .is_some_and(|v| v.get("job").is_some() && v.get("grid").is_some())
            });
            if is_run && !runs.iter().any(|r: &PathBuf| r == a) {
                runs.push(a.to_path_buf());
            }
        }
    }
    runs
}
