//! The command line as packaged: shell completions and the man page come from the same
//! definition as the parser, so they name every subcommand and option.

use std::process::Command;

fn stdout(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn completions_and_man_page_cover_the_commands() {
    for shell in ["bash", "zsh", "fish"] {
        let script = stdout(&["completions", shell]);
        // (fish names long options without their dashes.)
        for word in ["extract", "min-confidence", "a-srs", "recursive"] {
            assert!(script.contains(word), "{shell} completions lack {word}");
        }
    }
    let man = stdout(&["man"]);
    assert!(man.starts_with(".ie") && man.contains(".TH crease 1"), "{}", &man[..200.min(man.len())]);
    for word in ["extract", "status", "eval", "synth"] {
        assert!(man.contains(word), "man page lacks {word}");
    }
    // Every page the top page refers to exists: one per subcommand, with its own options.
    let extract = stdout(&["man", "extract"]);
    assert!(extract.contains(".TH crease-extract 1") && extract.contains("min\\-confidence"), "{}", &extract[..300.min(extract.len())]);
    let d = tempfile::tempdir().unwrap();
    stdout(&["man", "--dir", d.path().to_str().unwrap()]);
    for page in ["crease", "crease-extract", "crease-status", "crease-synth", "crease-eval", "crease-man"] {
        // (roff escapes the dash.)
        assert!(man.contains(&format!("{}(1)", page.replace('-', "\\-"))) || page == "crease", "the top page does not refer to {page}");
        assert!(d.path().join(format!("{page}.1")).exists(), "no {page}.1");
    }
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(["man", "nope"]).output().unwrap();
    assert_eq!(out.status.code(), Some(crease::error::exit::USAGE));
}

/// `crease view RUN` writes a page that needs nothing but itself (no network, no other file)
/// and holds the run's curves; a directory that is not a finished run is refused.
#[test]
fn view_writes_a_self_contained_page() {
    let d = tempfile::tempdir().unwrap();
    let run = d.path().join("run");
    let cube = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las");
    stdout(&["extract", cube.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"]);
    stdout(&["view", run.to_str().unwrap()]);
    let page = std::fs::read_to_string(run.join("view.html")).unwrap();
    assert!(page.contains("run: 12 curves over 20000 points"), "{}", &page[..600]);
    for outside in ["http://", "https://", " src=", "<link", "import "] {
        assert!(!page.contains(outside), "the page refers outside itself: {outside}");
    }
    // The curves' segments: 2 vertices of 3 floats each, as in curves.ply.
    let curves = crease::curves::read_ply(&run.join("curves.ply")).unwrap();
    let segments: usize = curves.iter().map(|c| c.segment_count()).sum();
    let lines = page.split("lin = dec(\"").nth(1).unwrap().split('"').next().unwrap();
    assert_eq!(lines.len().div_ceil(4) * 3 - lines.matches('=').count(), segments * 2 * 3 * 4);
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(["view", d.path().to_str().unwrap()]).output().unwrap();
    assert_eq!(out.status.code(), Some(crease::error::exit::DATA));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a crease run directory"));
}

/// Runs crease and returns its exit code and standard error.
fn run(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `--work-dir` keeps the working data out of the run directory, with the same curves; a
/// resumed run finds it without the flag, and refuses another; two runs cannot share one.
/// `--clean` removes it once the outputs are written, and a cleaned run is not run again
/// unless forced.
#[test]
fn working_data_goes_to_the_work_dir_and_clean_removes_it() {
    let d = tempfile::tempdir().unwrap();
    let p = |name: &str| d.path().join(name).to_str().unwrap().to_string();
    let cube = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las");
    let cube = cube.to_str().unwrap();
    stdout(&["extract", cube, "-o", &p("plain"), "-q"]);
    stdout(&["extract", cube, "-o", &p("run"), "-q", "--work-dir", &p("scratch")]);
    for working in ["tiles", "stats", "resid", "edges"] {
        assert!(d.path().join("scratch").join(working).is_dir() && d.path().join("plain/work").join(working).is_dir(), "{working}");
        assert!(!d.path().join("run").join(working).exists() && !d.path().join("plain").join(working).exists(), "{working}");
    }
    let curves = |run: &str| std::fs::read(d.path().join(run).join("curves.obj")).unwrap();
    assert_eq!(curves("run"), curves("plain"));
    // Resumed without the flag (other output filters: the outputs are written again from the
    // working data).
    stdout(&["extract", cube, "-o", &p("run"), "-q", "--min-confidence", "0.99"]);
    assert_ne!(curves("run"), curves("plain"));
    let (code, err) = run(&["extract", cube, "-o", &p("run"), "-q", "--work-dir", &p("other")]);
    assert_eq!(code, Some(crease::error::exit::USAGE));
    assert!(err.contains("keeps its working data in") && err.contains("scratch"), "{err}");
    assert!(!d.path().join("other").exists(), "a refused work directory was created");
    let (code, err) = run(&["extract", cube, "-o", &p("run2"), "-q", "--work-dir", &p("scratch")]);
    assert_eq!(code, Some(crease::error::exit::USAGE));
    assert!(err.contains("holds the working data of the run in"), "{err}");
    // A manifest edited to point at another run's work directory is refused as damaged.
    stdout(&["extract", cube, "-o", &p("run3"), "-q", "--work-dir", &p("scratch3")]);
    let manifest = d.path().join("run3/manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let scratch3 = std::fs::canonicalize(d.path().join("scratch3")).unwrap();
    let scratch = std::fs::canonicalize(d.path().join("scratch")).unwrap();
    std::fs::write(&manifest, text.replace(&*scratch3.to_string_lossy(), &scratch.to_string_lossy())).unwrap();
    let (code, err) = run(&["extract", cube, "-o", &p("run3"), "-q", "--min-confidence", "0.5"]);
    assert_eq!(code, Some(crease::error::exit::DATA), "{err}");
    assert!(err.contains("damaged") && err.contains("holds the working data of the run in"), "{err}");
    std::fs::write(&manifest, &text).unwrap();
    stdout(&["extract", cube, "-o", &p("run3"), "-q", "--min-confidence", "0.5"]);
    // --clean, on a finished run with a work directory and on one without.
    stdout(&["extract", cube, "-o", &p("run"), "-q", "--clean"]);
    assert!(!d.path().join("scratch").exists());
    let before = curves("plain");
    stdout(&["extract", cube, "-o", &p("plain"), "-q", "--clean"]);
    assert_eq!(curves("plain"), before);
    assert!(!d.path().join("plain/work").exists());
    assert!(stdout(&["status", &p("plain")]).contains("finished (working data removed)"));
    let (code, err) = run(&["extract", cube, "-o", &p("plain"), "-q"]);
    assert_eq!(code, Some(crease::error::exit::USAGE));
    assert!(err.contains("working data was removed (--clean)") && err.contains("--force"), "{err}");
    stdout(&["view", &p("plain")]);
    stdout(&["extract", cube, "-o", &p("plain"), "-q", "--force"]);
    assert!(d.path().join("plain/work/tiles").is_dir());
    // --force on a run with a work directory, without one: the old working data goes, the
    // new is in the run directory, and the run resumes from there.
    stdout(&["extract", cube, "-o", &p("moved"), "-q", "--work-dir", &p("scratch2")]);
    stdout(&["extract", cube, "-o", &p("moved"), "-q", "--force"]);
    assert!(!d.path().join("scratch2/tiles").exists() && d.path().join("moved/work/tiles").is_dir());
    stdout(&["extract", cube, "-o", &p("moved"), "-q", "--min-confidence", "0.3"]);
    assert!(stdout(&["status", &p("moved")]).contains("finished"));
}

/// Method lengths and `--evaluate-per-fit` that are not positive numbers are refused before
/// anything is written, with the option named.
#[test]
fn method_parameters_that_are_not_positive_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let cube = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las");
    let out = d.path().join("run");
    for (option, value) in [("--evaluate-per-fit", "0"), ("--evaluate-per-fit", "nan"), ("--kappa", "0"), ("--step", "inf")] {
        let (code, err) = run(&["extract", cube.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q", option, value]);
        assert_eq!(code, Some(crease::error::exit::USAGE), "{option} {value}: {err}");
        assert!(err.contains(&format!("{option} must be a positive number")), "{option} {value}: {err}");
        assert!(!out.exists(), "{option} {value}: the run directory was created");
    }
}

/// An EPSG code outside the EPSG dataset's range (a typing slip, or ESRI's 102100) is refused
/// before anything is written: a reader would take it for a CRS that does not exist.
#[test]
fn epsg_codes_outside_the_dataset_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let cube = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las");
    let out = d.path().join("run");
    for code in ["EPSG:99999999", "EPSG:102100", "EPSG:0"] {
        let (status, err) = run(&["extract", cube.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q", "--a-srs", code]);
        assert_eq!(status, Some(crease::error::exit::USAGE), "{code}: {err}");
        assert!(err.contains(&format!("{code} is outside the codes of the EPSG dataset")), "{code}: {err}");
        assert!(!out.exists(), "{code}: the run directory was created");
    }
}

/// A finished run directory holds its outputs, the manifest and `work/` at the top, and nothing
/// else. A run directory of the older layout (its working data at the top, a manifest without
/// `layout`) is resumed from there, not mixed with a new `work/`; `--force` starts it over in the
/// new layout.
#[test]
fn the_run_directory_shows_its_outputs_and_reads_the_older_layout() {
    let d = tempfile::tempdir().unwrap();
    let run_dir = d.path().join("run");
    let r = run_dir.to_str().unwrap();
    let cube = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las");
    let cube = cube.to_str().unwrap();
    let names = |dir: &std::path::Path| {
        let mut n: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        n.sort();
        n
    };
    stdout(&["extract", cube, "-o", r, "-q"]);
    let top = ["curves.geojson", "curves.obj", "curves.ply", "manifest.json", "preview.png", "report.json", "work"];
    assert_eq!(names(&run_dir), top);
    assert_eq!(names(&run_dir.join("work")), ["edges", "finished", "pieces", "resid", "smoothed", "stats", "survey", "tiles"]);
    let curves = std::fs::read(run_dir.join("curves.obj")).unwrap();
    // The same run in the older layout.
    for e in std::fs::read_dir(run_dir.join("work")).unwrap() {
        let e = e.unwrap();
        std::fs::rename(e.path(), run_dir.join(e.file_name())).unwrap();
    }
    std::fs::remove_dir(run_dir.join("work")).unwrap();
    let manifest = run_dir.join("manifest.json");
    let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    assert_eq!(m["layout"], 1);
    m.as_object_mut().unwrap().remove("layout");
    std::fs::write(&manifest, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    std::fs::remove_file(run_dir.join("curves.obj")).unwrap();
    stdout(&["extract", cube, "-o", r, "-q", "--min-confidence", "0.5"]);
    stdout(&["extract", cube, "-o", r, "-q"]);
    assert_eq!(std::fs::read(run_dir.join("curves.obj")).unwrap(), curves);
    assert!(!run_dir.join("work").exists() && run_dir.join("tiles").is_dir());
    assert!(stdout(&["status", r]).contains("finished"));
    stdout(&["extract", cube, "-o", r, "-q", "--force"]);
    assert_eq!(names(&run_dir), top);
    assert_eq!(std::fs::read(run_dir.join("curves.obj")).unwrap(), curves);
}
