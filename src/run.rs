//! The `extract` job: read the inputs, extract curves, write the outputs and a report.

use crate::cloud::{Crs, CloudHeader};
use crate::curves::{write_geojson, write_obj, write_ply};
use crate::error::{Error, Result};
use crate::extract::{self, Counts, Params, Resolved, Timings};
use crate::io::{self, Filter};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `crease extract` writes to `report.json`.
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
    /// Seconds per stage (plus reading and writing).
    pub seconds: Timings,
    /// Seconds spent reading the inputs.
    pub read_seconds: f64,
    /// Seconds spent writing the outputs.
    pub write_seconds: f64,
    /// Total wall-clock seconds.
    pub total_seconds: f64,
    /// Peak resident memory in bytes.
    pub peak_rss_bytes: u64,
    /// Worker threads.
    pub threads: usize,
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

/// Runs extraction on `inputs` (files or directories) and writes everything to `out_dir`.
pub fn run_extract(inputs: &[PathBuf], out_dir: &Path, params: &Params, filter: &Filter) -> Result<Report> {
    let t0 = Instant::now();
    let files = io::expand_inputs(inputs)?;
    let headers = files.iter().map(|f| io::read_header(f)).collect::<Result<Vec<_>>>()?;
    let crs = common_crs(&headers)?;
    let cloud = io::read_all(&files, filter)?;
    if cloud.len() < 10 {
        return Err(Error::input(&files[0], format!("only {} points after filtering: nothing to extract", cloud.len())));
    }
    let read_seconds = t0.elapsed().as_secs_f64();
    let ex = extract::extract(&cloud.xyz, params);
    let t = Instant::now();
    std::fs::create_dir_all(out_dir).map_err(|e| Error::output(out_dir, e))?;
    write_obj(&out_dir.join("curves.obj"), &ex.curves)?;
    write_ply(&out_dir.join("curves.ply"), &ex.curves)?;
    write_geojson(&out_dir.join("curves.geojson"), &ex.curves, &crs)?;
    let write_seconds = t.elapsed().as_secs_f64();
    let report = Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        inputs: files,
        params: ex.params,
        tau: ex.tau,
        counts: ex.counts,
        seconds: ex.seconds,
        read_seconds,
        write_seconds,
        total_seconds: t0.elapsed().as_secs_f64(),
        peak_rss_bytes: crate::mem::peak_rss(),
        threads: rayon::current_num_threads(),
    };
    let path = out_dir.join("report.json");
    let json = serde_json::to_string_pretty(&report).expect("report serialises");
    std::fs::write(&path, json).map_err(|e| Error::output(&path, e))?;
    Ok(report)
}
