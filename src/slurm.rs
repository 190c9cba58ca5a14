//! `crease slurm`: an extraction as a chain of Slurm jobs over a shared run directory, one
//! array job per tile pass (see [`crate::run::run_worker`]).
//!
//! The chain, each job `afterok` the one before:
//! 1. `plan`: worker 0 plans the run and buckets the points (one task);
//! 2. `statistics`, `residuals`, `projection`: arrays of N tasks, task I running worker I/N;
//! 3. `growing`: an array of N tasks, each smoothing and growing its share of the curve
//!    stage's growth blocks;
//! 4. `curves`: worker 0 stitches the blocks' pieces, completes the curves and writes the
//!    outputs (one task).
//!
//! Every job runs the same `crease extract` command, with the same arguments, but for
//! `--worker`: each invocation does what is left of its share and goes as far as the others
//! allow, so a task that is requeued, or a chain submitted again, picks up where it stopped.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The jobs of the chain, in order: name, and whether it is an array of all the workers.
pub(crate) const JOBS: [(&str, bool); 6] =
    [("plan", false), ("statistics", true), ("residuals", true), ("projection", true), ("growing", true), ("curves", false)];

/// What the chain runs.
#[derive(Clone, Debug)]
pub struct Chain {
    /// The crease binary, the same on every node (an absolute path on the shared file system).
    pub exe: PathBuf,
    /// The directory the jobs run in (relative paths in the arguments are relative to it).
    pub workdir: PathBuf,
    /// The run directory (`-o` of the arguments).
    pub run: PathBuf,
    /// The `crease extract` arguments, without `--worker`.
    pub extract_args: Vec<String>,
    /// Number of workers (array tasks).
    pub tasks: u32,
    /// Extra `#SBATCH` options for every job (`--partition=...`, `--time=...`).
    pub sbatch_args: Vec<String>,
}

/// Writes the chain's batch scripts to `RUN/slurm/` (`1-plan.sbatch` to `6-curves.sbatch`)
/// and `submit.sh`, which submits them in order with their dependencies and prints the job
/// ids. Returns the paths of the scripts, in order.
///
/// ```
/// use crease::slurm::{write_chain, Chain};
/// let d = tempfile::tempdir()?;
/// let chain = Chain {
///     exe: "/opt/crease/bin/crease".into(),
///     workdir: d.path().into(),
///     run: d.path().join("run"),
///     extract_args: vec!["scans/".into(), "-o".into(), "run".into()],
///     tasks: 8,
///     sbatch_args: vec!["--time=2:00:00".into()],
/// };
/// let scripts = write_chain(&chain)?;
/// assert_eq!(scripts.len(), 6);
/// assert!(std::fs::read_to_string(&scripts[1])?.contains("#SBATCH --array=0-7"));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_chain(c: &Chain) -> Result<Vec<PathBuf>> {
    if c.tasks == 0 {
        return Err(Error::Usage("--tasks must be 1 or more".into()));
    }
    let dir = c.run.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
    let mut scripts = vec![];
    for (k, (name, array)) in JOBS.iter().enumerate() {
        let path = dir.join(format!("{}-{name}.sbatch", k + 1));
        std::fs::write(&path, script(c, name, *array, &dir)).map_err(|e| Error::output(&path, e))?;
        scripts.push(path);
    }
    let submit = dir.join("submit.sh");
    std::fs::write(&submit, submit_script(&scripts)).map_err(|e| Error::output(&submit, e))?;
    make_executable(&submit)?;
    Ok(scripts)
}

fn script(c: &Chain, name: &str, array: bool, logs: &Path) -> String {
    let mut s = String::from("#!/bin/bash\n");
    s += &format!("#SBATCH --job-name=crease-{name}\n");
    s += &format!("#SBATCH --chdir={}\n", quote(&c.workdir.to_string_lossy()));
    if array {
        s += &format!("#SBATCH --array=0-{}\n", c.tasks - 1);
        s += &format!("#SBATCH --output={}\n", quote(&logs.join(format!("{name}-%A_%a.log")).to_string_lossy()));
    } else {
        s += &format!("#SBATCH --output={}\n", quote(&logs.join(format!("{name}-%j.log")).to_string_lossy()));
    }
    for a in &c.sbatch_args {
        s += &format!("#SBATCH {a}\n");
    }
    let worker = if array { format!("\"$SLURM_ARRAY_TASK_ID/{}\"", c.tasks) } else { format!("0/{}", c.tasks) };
    let args: Vec<String> = c.extract_args.iter().map(|a| quote(a)).collect();
    s += &format!("exec {} extract {} --worker {worker}\n", quote(&c.exe.to_string_lossy()), args.join(" "));
    s
}

fn submit_script(scripts: &[PathBuf]) -> String {
    let mut s =
        String::from("#!/bin/bash\n# Submits the crease job chain, each job after the one before succeeded; prints the job ids.\nset -euo pipefail\nprev=\n");
    for p in scripts {
        s += &format!(
            "prev=$(sbatch --parsable ${{prev:+--dependency=afterok:$prev}} {})\necho \"$prev {}\"\n",
            quote(&p.to_string_lossy()),
            p.file_name().unwrap_or_default().to_string_lossy()
        );
    }
    s
}

/// `s` quoted for bash, unless it needs no quoting.
fn quote(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

#[cfg(unix)]
fn make_executable(p: &Path) -> Result<()> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o755)).map_err(|e| Error::output(p, e))
}

#[cfg(not(unix))]
fn make_executable(_: &Path) -> Result<()> {
    Ok(())
}

/// Submits the chain written by [`write_chain`] (`RUN/slurm/submit.sh`, which needs `sbatch`
/// on the path) and returns its output: a job id and script name per line.
pub fn submit(run: &Path) -> Result<String> {
    let script = run.join("slurm").join("submit.sh");
    let out = std::process::Command::new("bash").arg(&script).output().map_err(|e| Error::output(&script, e))?;
    if !out.status.success() {
        return Err(Error::Usage(format!("{}: submitting failed: {}", script.display(), String::from_utf8_lossy(&out.stderr).trim())));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arguments_are_quoted_for_the_shell() {
        assert_eq!(quote("scans/a.laz"), "scans/a.laz");
        assert_eq!(quote("my scans/it's.laz"), "'my scans/it'\\''s.laz'");
        assert_eq!(quote(""), "''");
    }
}
