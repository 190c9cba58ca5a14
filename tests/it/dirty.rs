//! Dirty real data: copies of points (overlapping scans, tiles merged twice) change nothing.

use glam::DVec3;
use std::path::Path;
use std::process::Command;

fn extract(input: &Path, out: &Path) -> Vec<u8> {
    let run = Command::new(env!("CARGO_BIN_EXE_crease")).args(["extract", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]).output().unwrap();
    assert!(run.status.success(), "{}: {}", input.display(), String::from_utf8_lossy(&run.stderr));
    std::fs::read(out.join("curves.obj")).unwrap()
}

fn write_ply(path: &Path, points: &[DVec3]) {
    let mut w = crease::io::PointWriter::create(path, &crease::io::WriteOptions { scale: 1e-6, offset: DVec3::ZERO, epsg: None }).unwrap();
    w.write(points, &vec![0; points.len()]).unwrap();
    w.finish().unwrap();
}

/// A 20 k-point cube, written to `dir/cube.ply` and extracted into `dir/run_plain`, which must
/// give its 12 curves: the points and the curves (OBJ bytes).
fn plain_cube(dir: &Path) -> (Vec<DVec3>, Vec<u8>) {
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
    let plain = dir.join("cube.ply");
    write_ply(&plain, &cube);
    let curves = extract(&plain, &dir.join("run_plain"));
    assert_eq!(crease::curves::read_obj(&dir.join("run_plain/curves.obj")).unwrap().len(), 12);
    (cube, curves)
}

/// A cube whose every point is written ten times, and one with 20 k copies of a single point
/// added, give the cube's 12 curves where the cube alone gives them. (Not to the byte: the
/// statistics sample is drawn at a rate set by the point count, copies included.)
#[test]
fn copies_of_points_change_nothing() {
    let d = tempfile::tempdir().unwrap();
    let (cube, _) = plain_cube(d.path());
    let tenfold: Vec<DVec3> = (0..10).flat_map(|_| cube.iter().copied()).collect();
    let one_point: Vec<DVec3> = cube.iter().copied().chain(std::iter::repeat_n(cube[17], 20_000)).collect();
    for (name, points) in [("tenfold.ply", tenfold), ("one_point.ply", one_point)] {
        let p = d.path().join(name);
        write_ply(&p, &points);
        let run = d.path().join(format!("run_{name}"));
        extract(&p, &run);
        assert_eq!(crease::curves::read_obj(&run.join("curves.obj")).unwrap().len(), 12, "{name}");
        let eval = Command::new(env!("CARGO_BIN_EXE_crease"))
            .args(["eval", "--json", "--truth", d.path().join("run_plain/curves.obj").to_str().unwrap(), "--curves", run.join("curves.obj").to_str().unwrap()])
            .output()
            .unwrap();
        let s: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
        for k in ["recall", "precision"] {
            assert!(s[k].as_f64().unwrap() > 0.99, "{name}: {k} {} against the cube's own curves", s[k]);
        }
    }
}

/// Stray points far out (a corrupt record at 1e20, a reflection a million units away) set
/// the bounds, and the grid and the point keys were planned over them: a small cube gave no
/// curve, or 21 instead of 12. They are left out with a warning that counts them, and the cube
/// gives the curves of the cube alone, to the byte, however far out and however nested (the
/// nearer ones show only once the farther are out). In memory too.
#[test]
fn stray_points_far_out_are_left_out_with_a_warning() {
    let d = tempfile::tempdir().unwrap();
    let (cube, alone) = plain_cube(d.path());
    let strays = [vec![1e20], vec![1e6], vec![1e20, 1e6, 1e3], vec![1e300]];
    for far in strays {
        let mut points = cube.clone();
        for &at in &far {
            points.extend([DVec3::splat(at), DVec3::splat(-at), DVec3::new(0.5, 0.5, at)]);
        }
        let p = d.path().join("strays.ply");
        write_ply(&p, &points);
        let run = d.path().join(format!("run_{}", far.len()));
        let _ = std::fs::remove_dir_all(&run);
        assert_eq!(extract(&p, &run), alone, "strays at {far:?}: not the cube's curves");
        let report: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("report.json")).unwrap()).unwrap();
        assert_eq!(report["counts"]["far_points"], 3 * far.len() as u64, "{far:?}");
        let warned = report["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().starts_with(&format!("{} points lie far from all the others", 3 * far.len())));
        assert!(warned, "{far:?}: {}", report["warnings"]);
        let x = crease::run::extract_cloud(&points, &crease::extract::Params::default(), &crease::run::RunOptions::default()).unwrap();
        assert_eq!((x.curves.len(), x.counts.far_points), (12, 3 * far.len() as u64), "{far:?} in memory");
    }
}

/// A finished run inside an input directory tree (its curves.ply, its tile store's files) is
/// passed over with a warning naming it, not read as a scan: the curves are the scan's alone.
#[test]
fn a_run_directory_among_the_inputs_is_not_a_scan() {
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las"), scans.join("cube.las")).unwrap();
    let alone = extract(&scans.join("cube.las"), &scans.join("old_run"));
    let run = Command::new(env!("CARGO_BIN_EXE_crease"))
        .args(["extract", "-r", scans.to_str().unwrap(), "-o", d.path().join("again").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("old_run: passed over: a crease run directory"), "{err}");
    assert!(!err.contains("old_run/"), "the run's own files listed one by one: {err}");
    assert!(std::fs::read(d.path().join("again/curves.obj")).unwrap() == alone, "other curves than the scan's");
}

/// A directory's notes with a point cloud's extension (`readme.txt`) are passed over with a
/// warning: one line of prose was read as a header over an empty cloud, two stopped the run on
/// their first word. A text cloud with a header and a PTS count is still read.
#[test]
fn notes_among_the_scans_are_passed_over() {
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
    let (half, rest) = cube.split_at(10_000);
    write_ply(&scans.join("a.ply"), half);
    let pts: String = std::iter::once(format!("{}\n", rest.len())).chain(rest.iter().map(|p| format!("{} {} {}\n", p.x, p.y, p.z))).collect();
    std::fs::write(scans.join("b.pts"), pts).unwrap();
    std::fs::write(scans.join("readme.txt"), "Scans of the 2026 survey\nSee the report for the set-up, 3 stations\n").unwrap();
    std::fs::write(scans.join("todo.txt"), "check the east wall\n").unwrap();
    let run =
        Command::new(env!("CARGO_BIN_EXE_crease")).args(["extract", scans.to_str().unwrap(), "-o", d.path().join("run").to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("passed over 2 entries that are not point files") && err.contains("readme.txt, todo.txt"), "{err}");
    assert!(err.contains("12 curves from 20000 points"), "{err}");
}

/// A cube whose every point is written twice, the copy moved by a ten-thousandth of the
/// spacing (a copy that went through a transform, not bit-identical): the copies are
/// collapsed as near duplicates and counted, and the curves are the cube's 12, the same to
/// the byte in tiles as in one (which copy is kept is decided the same way in every tile).
/// Before, the spacing was measured over the copies and the cube gave 14 curves.
#[test]
fn near_copies_are_collapsed_and_counted() {
    let d = tempfile::tempdir().unwrap();
    let (cube, _) = plain_cube(d.path());
    let spacing = (6.0 / cube.len() as f64).sqrt();
    // (A splitmix64 stream: any spread of signs and sizes within the bound will do.)
    let mut state = 3u64;
    let mut jitter = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        let unit = (z ^ (z >> 31)) as f64 / u64::MAX as f64;
        1e-4 * spacing * (2.0 * unit - 1.0)
    };
    let twice: Vec<DVec3> = cube.iter().copied().chain(cube.iter().map(|&p| p + DVec3::new(jitter(), jitter(), jitter()))).collect();
    let p = d.path().join("twice.ply");
    let mut w = crease::io::PointWriter::create(&p, &crease::io::WriteOptions { scale: 1e-12, offset: DVec3::ZERO, epsg: None }).unwrap();
    w.write(&twice, &vec![0; twice.len()]).unwrap();
    w.finish().unwrap();
    let one = extract(&p, &d.path().join("run_one"));
    assert_eq!(crease::curves::read_obj(&d.path().join("run_one/curves.obj")).unwrap().len(), 12);
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(d.path().join("run_one/report.json")).unwrap()).unwrap();
    assert_eq!((report["counts"]["exact_duplicates"].as_u64(), report["counts"]["near_duplicates"].as_u64()), (Some(0), Some(cube.len() as u64)));
    let tiled = d.path().join("run_tiled");
    let run = Command::new(env!("CARGO_BIN_EXE_crease"))
        .args(["extract", p.to_str().unwrap(), "-o", tiled.to_str().unwrap(), "-q", "--tile-size", "0.3"])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    assert!(std::fs::read(tiled.join("curves.obj")).unwrap() == one, "other curves in tiles of 0.3");
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(tiled.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["counts"]["near_duplicates"].as_u64(), Some(cube.len() as u64), "in tiles");
}

/// A cloud far longer than it is wide (a corridor, or points on a few lines) was tiled in
/// squares as wide as its footprint's area asked for: 30 k points on a strip 10,000 long and 1
/// wide made 100 tiles of 300 points (3,163 of 10 on one 1e7 long), and minutes of per-tile
/// work. It is one tile across, and its tiles are sized along its length.
#[test]
fn a_long_thin_cloud_is_tiled_along_its_length() {
    let d = tempfile::tempdir().unwrap();
    let mut s = 61u64;
    let mut r = || {
        s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let strip: Vec<DVec3> = (0..30_000).map(|_| DVec3::new(10_000.0 * r(), r(), 0.01 * r())).collect();
    let p = d.path().join("strip.ply");
    write_ply(&p, &strip);
    let run = d.path().join("run");
    let t = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(["extract", p.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("report.json")).unwrap()).unwrap();
    assert!(report["tiles"].as_u64().unwrap() <= 2, "{} tiles for 30 k points", report["tiles"]);
    assert!(t.elapsed().as_secs() < 20, "{:?}", t.elapsed());
}

/// `crease info` reads one block of a file; the copies among the points of that block are
/// counted and said to be of the block, not guessed for the file.
#[test]
fn info_counts_the_copies_in_the_block_it_reads() {
    let d = tempfile::tempdir().unwrap();
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
    let twice: Vec<DVec3> = cube.iter().chain(&cube[..5_000]).copied().collect();
    for (name, points, copies) in [("plain.ply", &cube, 0), ("twice.ply", &twice, 5_000)] {
        let p = d.path().join(name);
        write_ply(&p, points);
        let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(["info", "--json", p.to_str().unwrap()]).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v[0]["sample_copies"].as_u64(), Some(copies), "{name}");
        let text = Command::new(env!("CARGO_BIN_EXE_crease")).args(["info", p.to_str().unwrap()]).output().unwrap();
        let text = String::from_utf8_lossy(&text.stdout);
        assert_eq!(text.contains(&format!("copies   {copies} of those 25000 points")), copies > 0, "{text}");
    }
}
