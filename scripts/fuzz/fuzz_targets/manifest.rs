//! A resumed run over a run directory whose `manifest.json` is replaced by the input: a finished
//! run of a small cube is made once, copied afresh for each execution, and resumed with the
//! edited manifest. Where the input parses as a manifest its job is set to the real one, so
//! that the run resumes with the edited grid, counts and parameters instead of being refused
//! as a different job. Any result is fine but a panic, a hang or an abort.
#![no_main]

use crease::extract::Params;
use crease::io::{Filter, PointWriter, WriteOptions};
use crease::run::{run_extract, Job, Manifest, RunOptions, MANIFEST};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

struct Setup {
    input: PathBuf,
    pristine: PathBuf,
    work: PathBuf,
    job: Job,
    opts: RunOptions,
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else if e.file_name() != "lock" {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

fn setup() -> &'static Setup {
    static SETUP: OnceLock<Setup> = OnceLock::new();
    SETUP.get_or_init(|| {
        let base = std::env::temp_dir().join(format!("crease-fuzz-manifest-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        std::fs::create_dir_all(&base).unwrap();
        let shape = crease::synth::shape("cube", 90.0).unwrap();
        let pts = crease::synth::sample(&shape, &crease::synth::SynthOptions { n: 4000, ..Default::default() });
        let input = base.join("cube.ply");
        let mut w = PointWriter::create(&input, &WriteOptions { scale: 1e-6, offset: Default::default(), epsg: None }).unwrap();
        w.write(&pts, &vec![0; pts.len()]).unwrap();
        w.finish().unwrap();
        // Several tiles, so that the grid and the per-tile counts matter.
        let opts = RunOptions { tile_size: Some(0.45), ..Default::default() };
        let pristine = base.join("pristine");
        run_extract(&[input.clone()], &pristine, &Params::default(), &Filter::keep_all(), &opts).expect("the set-up run works");
        let held: Manifest = serde_json::from_slice(&std::fs::read(pristine.join(MANIFEST)).unwrap()).unwrap();
        let job = held.job;
        Setup { input, pristine, work: base.join("work"), job, opts }
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let s = setup();
    let _ = std::fs::remove_dir_all(&s.work);
    copy_dir(&s.pristine, &s.work);
    let bytes = match serde_json::from_slice::<Manifest>(data) {
        Ok(mut m) => {
            m.job = s.job.clone();
            serde_json::to_vec(&m).unwrap()
        }
        Err(_) => data.to_vec(),
    };
    std::fs::write(s.work.join(MANIFEST), bytes).unwrap();
    let _ = run_extract(&[s.input.clone()], &s.work, &Params::default(), &Filter::keep_all(), &s.opts);
});
