//! The label pass (`--label-points`, an output setting): a copy of each input file's points,
//! labelled with their distance to the nearest output curve, that curve's id, and whether they
//! lie within the typed curves' tolerance of it (see [`crate::io::write_labelled`]), written to
//! `labels/<input file stem>.laz` (`.ply` for a PLY input) in the run directory.
//!
//! Like every pass it resumes: each copy is written to a temporary name and renamed once
//! complete, and a copy already there is not made again, as long as `labels/curves.key` says it
//! was made from the same curves (other output filters make other curves, and the copies are
//! then made anew). A run not asked for labels this time removes them, as it removes the curve
//! files of formats not asked for: they would no longer match its outputs.

use super::state::Run;
use crate::curves::nearest::NearestCurve;
use crate::curves::typed;
use crate::error::{Error, Result};
use crate::extract::Resolved;
use crate::io::{self, Label, Labeller, TextColumns};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The directory of the labelled copies in a run directory (`--label-points`).
pub const DIR: &str = "labels";

/// Names the curves and tolerances the copies in [`DIR`] were labelled with.
const KEY: &str = "curves.key";

/// Labels points by the nearest of the curves: `edge` within `tolerance`, a curve id within
/// `reach` (else -1). Once `cancel` is set, the points not labelled yet are given the label
/// of no curve (a chunk of a quarter million points took seconds; the writer checks the flag
/// before it writes the chunk).
struct ByNearest {
    nearest: NearestCurve,
    tolerance: f64,
    reach: f64,
    cancel: crate::cancel::Cancel,
}

impl Labeller for ByNearest {
    fn label(&self, points: &[glam::DVec3], out: &mut Vec<Label>) {
        points
            .par_iter()
            .map_init(Vec::new, |scratch, &p| match (!self.cancel.is_set()).then(|| self.nearest.nearest(p, scratch)).flatten() {
                Some((d, id)) => Label { distance: d, curve: if d <= self.reach { id as i32 } else { -1 }, edge: (d <= self.tolerance) as u8 },
                None => Label { distance: f64::INFINITY, curve: -1, edge: 0 },
            })
            .collect_into_vec(out);
    }
}

impl Run<'_> {
    /// The label pass over the input `files` (in the job's order; `text` their columns, as the
    /// run read them) with the curves of the `batches` batches written: the copies it made or
    /// found made, or none, and `labels/` removed, if labels are not asked for.
    pub(super) fn label_points(&mut self, batches: u32, r: &Resolved, files: &[PathBuf], text: Option<TextColumns>) -> Result<Vec<PathBuf>> {
        let dir = self.ws.root().join(DIR);
        if !self.opts.label_points {
            let _ = std::fs::remove_dir_all(&dir);
            return Ok(vec![]);
        }
        let t = std::time::Instant::now();
        let tolerance = typed::tolerance(r.kappa, r.noise);
        let nearest = NearestCurve::new(&self.finished_curves(batches), tolerance, super::budgets::label_index(self.opts.memory))?;
        let reach = r.halo().max(tolerance);
        let key = format!("{} {tolerance:e} {reach:e}\n", nearest.fingerprint());
        prepare_dir(&dir, &key)?;
        let labeller = ByNearest { nearest, tolerance, reach, cancel: self.opts.cancel.clone() };
        let names = labelled_names(files);
        let bar = self.progress.bar("labels", files.len() as u64, "files");
        let mut made = vec![];
        for ((file, name), stamp) in files.iter().zip(names).zip(&self.manifest.job.inputs) {
            let out = dir.join(&name);
            if !out.is_file() {
                unchanged(file, stamp)?;
                let tmp = dir.join(format!("{name}.tmp"));
                io::write_labelled(file, &tmp, text, &labeller, &self.opts.cancel)?;
                std::fs::rename(&tmp, &out).map_err(|e| Error::output(&tmp, e))?;
            }
            made.push(out);
            bar.inc(1);
        }
        bar.finish();
        sync_dir(&dir);
        self.pass.labelling = t.elapsed().as_secs_f64();
        Ok(made)
    }
}

/// Makes `dir` hold copies labelled as `key` says: kept if its key is that one, else emptied and
/// given that key. Unfinished copies (temporary names) are removed either way.
fn prepare_dir(dir: &Path, key: &str) -> Result<()> {
    if std::fs::read_to_string(dir.join(KEY)).ok().as_deref() != Some(key) {
        let _ = std::fs::remove_dir_all(dir);
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::output(dir, e))?;
    for e in std::fs::read_dir(dir).map_err(|e| Error::output(dir, e))?.flatten() {
        if e.path().extension().is_some_and(|x| x == "tmp") {
            let _ = std::fs::remove_file(e.path());
        }
    }
    if !dir.join(KEY).is_file() {
        crate::workspace::write_atomic(&dir.join(KEY), key.as_bytes())?;
    }
    Ok(())
}

/// The names of the labelled copies of `files`: each file's stem and the copy's extension, with
/// `-2`, `-3`, ... after a stem an earlier file took (files of the same stem in different
/// directories, or `a.las` beside `a.ply`).
fn labelled_names(files: &[PathBuf]) -> Vec<String> {
    let mut taken = std::collections::HashSet::new();
    files
        .iter()
        .map(|f| {
            let stem = f.file_stem().map_or("points".into(), |s| s.to_string_lossy().into_owned());
            let ext = io::labelled_extension(f);
            let name =
                (1..).map(|k| if k == 1 { format!("{stem}.{ext}") } else { format!("{stem}-{k}.{ext}") }).find(|n| !taken.contains(n)).expect("a free name");
            taken.insert(name.clone());
            name
        })
        .collect()
}

/// Refuses an input that is gone or changed since the run read it: its copy would label other
/// points than the curves were found in.
fn unchanged(file: &Path, stamp: &super::InputStamp) -> Result<()> {
    if !file.exists() {
        return Err(Error::input(file, "no longer there: the labelled copy is made from the file the run read"));
    }
    let now = super::manifest::stamp(file)?;
    if (now.size, now.mtime_ns, &now.header_hash) != (stamp.size, stamp.mtime_ns, &stamp.header_hash) {
        return Err(Error::input(file, "changed since the run read it (size, time or header): run it again with --force to label this file"));
    }
    Ok(())
}

/// Syncs a directory's entries (the renames into it), where the platform allows.
fn sync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}
