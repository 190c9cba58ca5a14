//! Several worker processes sharing one run directory (`--worker I/N`, as job arrays on a
//! cluster run them) write the same curves as one `crease extract`, also when a worker is
//! killed part way and started again.

use std::path::Path;
use std::process::{Command, Stdio};

fn crease(args: &[impl AsRef<std::ffi::OsStr>]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap()
}

/// The arguments every run of the fandisk fixture here shares: tiles of 0.4 units, 47 tiles
/// with points, so that each worker has a share of many.
const COMMON: [&str; 5] = ["-q", "--tile-size", "0.4", "--block-steps", "16"];

/// The fandisk fixture, and the curves one `crease extract` of it writes (into `dir/plain`).
fn fandisk_and_its_curves(dir: &Path) -> (String, Vec<u8>) {
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/fandisk.las").to_str().unwrap().to_string();
    let plain = dir.join("plain");
    let out = crease(&[&["extract", &input, "-o", plain.to_str().unwrap()][..], &COMMON].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    (input, std::fs::read(plain.join("curves.obj")).unwrap())
}

#[test]
fn three_workers_write_the_curves_of_one_run_even_when_one_is_killed() {
    let d = tempfile::tempdir().unwrap();
    let (input, plain) = fandisk_and_its_curves(d.path());
    let (input, shared) = (input.as_str(), d.path().join("shared"));
    let worker = |i: u32| {
        let w = format!("{i}/3");
        let args = [&["extract", input, "-o", shared.to_str().unwrap(), "--worker", &w][..], &COMMON].concat();
        Command::new(env!("CARGO_BIN_EXE_crease")).args(args).stderr(Stdio::piped()).spawn().unwrap()
    };
    // Rounds of the three side by side, until worker 0 has written the outputs; in the second
    // round, worker 1 is killed soon after it starts.
    let mut rounds = 0;
    while !shared.join("curves.obj").exists() {
        rounds += 1;
        assert!(rounds <= 8, "not finished after 8 rounds");
        let mut running: Vec<_> = (0..3).map(worker).collect();
        if rounds == 2 {
            std::thread::sleep(std::time::Duration::from_millis(150));
            running[1].kill().unwrap();
        }
        for (i, w) in running.into_iter().enumerate() {
            let out = w.wait_with_output().unwrap();
            if !(rounds == 2 && i == 1) {
                assert!(out.status.success(), "round {rounds}, worker {i}: {}", String::from_utf8_lossy(&out.stderr));
            }
        }
    }
    assert!(rounds >= 2, "one round did it all: the workers did not share the passes");
    assert_eq!(std::fs::read(shared.join("curves.obj")).unwrap(), plain);
    let status = crease(&["status", shared.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&status.stdout).contains("finished"));
}

#[test]
fn workers_and_lone_runs_do_not_mix_and_each_index_runs_once() {
    let d = tempfile::tempdir().unwrap();
    let cube = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las");
    let run = d.path().join("run");
    let (cube, dir) = (cube.to_str().unwrap().to_string(), run.to_str().unwrap().to_string());
    let args = |extra: &[&str]| -> Vec<String> { ["extract", &cube, "-o", &dir, "-q"].iter().chain(extra).map(|s| s.to_string()).collect() };
    let refused = |extra: &[&str], why: &str| {
        let out = crease(&args(extra));
        assert_eq!(out.status.code(), Some(crease::error::exit::USAGE), "{extra:?}");
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(err.contains(why), "{extra:?}: {err}");
    };
    refused(&["--worker", "3/3"], "not below the number of workers");
    refused(&["--worker", "1"], "a worker is I/N");
    // A worker other than 0 neither plans the run nor forces it.
    let out = crease(&args(&["--worker", "1/2"]));
    assert!(out.status.success() && !run.join("manifest.json").exists());
    refused(&["--worker", "1/2", "--force"], "give it to worker 0");
    // While a worker holds the run (a shared lock, as this test takes it), a lone run is
    // refused; while worker 1 runs, another worker 1 is.
    std::fs::create_dir_all(&run).unwrap();
    let shared = std::fs::OpenOptions::new().read(true).write(true).create(true).truncate(false).open(run.join("lock")).unwrap();
    shared.try_lock_shared().unwrap();
    refused(&[], "in use by another crease run");
    let one = std::fs::OpenOptions::new().read(true).write(true).create(true).truncate(false).open(run.join("lock.1")).unwrap();
    one.try_lock().unwrap();
    refused(&["--worker", "1/2"], "in use by worker 1");
    // Worker 0 runs beside them.
    let out = crease(&args(&["--worker", "0/2"]));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(run.join("manifest.json").exists());
    // A worker of another count would share the tiles out otherwise: refused; one of the
    // planned count goes on.
    drop((shared, one));
    refused(&["--worker", "1/3"], "shared by 2 workers");
    refused(&["--worker", "0/3"], "shared by 2 workers");
    let out = crease(&args(&["--worker", "1/2"]));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// The job chain `crease slurm` writes, run by hand as Slurm would run it (each array job's
/// tasks with their `SLURM_ARRAY_TASK_ID`, the jobs in order), writes the curves of one run.
#[test]
fn the_slurm_chain_run_in_order_writes_the_curves_of_one_run() {
    let d = tempfile::tempdir().unwrap();
    let (input, plain) = fandisk_and_its_curves(d.path());
    let (input, chained) = (input.as_str(), d.path().join("chained"));
    let out = crease(&[&["slurm", input, "-o", chained.to_str().unwrap(), "--tasks", "3"][..], &COMMON, &["--", "--time=5:00"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let scripts: Vec<String> = String::from_utf8_lossy(&out.stdout).lines().map(String::from).collect();
    assert_eq!(scripts.len(), 6);
    for s in &scripts {
        let text = std::fs::read_to_string(s).unwrap();
        assert!(text.contains("#SBATCH --time=5:00") && !text.contains("--tasks"), "{text}");
        let tasks: Vec<Option<u32>> = if text.contains("#SBATCH --array=0-2") { (0..3).map(Some).collect() } else { vec![None] };
        for task in tasks {
            let mut cmd = Command::new("bash");
            cmd.arg(s);
            if let Some(i) = task {
                cmd.env("SLURM_ARRAY_TASK_ID", i.to_string());
            }
            let out = cmd.output().unwrap();
            assert!(out.status.success(), "{s} task {task:?}: {}", String::from_utf8_lossy(&out.stderr));
        }
    }
    assert_eq!(std::fs::read(chained.join("curves.obj")).unwrap(), plain);
    let submit = std::fs::read_to_string(chained.join("slurm/submit.sh")).unwrap();
    assert_eq!(submit.matches("--dependency=afterok:$prev").count(), 6);
    // Flags that would break a chain are refused, and so is an argument the scripts cannot
    // hold (not UTF-8), with a message rather than a panic.
    let out = crease(&["slurm", input, "-o", chained.to_str().unwrap(), "--force"]);
    assert_eq!(out.status.code(), Some(crease::error::exit::USAGE));
    use std::os::unix::ffi::OsStrExt;
    let odd = std::ffi::OsStr::from_bytes(b"scan\xff.las");
    let out = crease(&[std::ffi::OsStr::new("slurm"), odd, std::ffi::OsStr::new("-o"), chained.as_os_str()]);
    assert_eq!(out.status.code(), Some(crease::error::exit::USAGE));
    assert!(String::from_utf8_lossy(&out.stderr).contains("is not UTF-8"), "{}", String::from_utf8_lossy(&out.stderr));
}
