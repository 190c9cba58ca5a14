//! E57 input: scans with their poses read as one cloud, giving the same curves as the same
//! points in another format; corrupt files refused in one line.

use e57::{E57Writer, Quaternion, Record, RecordValue, Transform, Translation};
use glam::DVec3;
use std::path::Path;
use std::process::Command;

fn crease(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// Runs `e57` (its scanners as the file gives them) and `ply` (told they stood at `outside`)
/// into `dir`, asserts that their curve files are byte-identical, and returns the E57 run.
fn same_curves(dir: &Path, e57: &Path, ply: &Path, outside: &str) -> std::path::PathBuf {
    let outside = format!("--outside={outside}");
    let runs = [("e57", e57, None), ("ply", ply, Some(outside.as_str()))].map(|(name, input, outside)| {
        let run = dir.join(name);
        let mut args = vec!["extract", input.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"];
        args.extend(outside);
        let (code, err) = crease(&args);
        assert_eq!(code, 0, "{err}");
        run
    });
    for f in ["curves.obj", "curves.ply", "curves.geojson"] {
        assert_eq!(std::fs::read(runs[0].join(f)).unwrap(), std::fs::read(runs[1].join(f)).unwrap(), "{f}");
    }
    let [e57_run, _] = runs;
    e57_run
}

/// A 30,000-point cube written as two scans: the first half as it is, the second in a scanner
/// frame turned half a turn about z (its pose turns it back, exactly in floating point), with
/// a point without a return after every tenth point.
fn write_two_scans(path: &Path, cube: &[DVec3]) {
    let mut w = E57Writer::from_file(path, "crease-test-file").unwrap();
    let prototype = || vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64, Record::CARTESIAN_INVALID_STATE];
    let (first, second) = cube.split_at(cube.len() / 2);
    let mut scan = w.add_pointcloud("scan-1", prototype()).unwrap();
    for p in first {
        scan.add_point(vec![RecordValue::Double(p.x), RecordValue::Double(p.y), RecordValue::Double(p.z), RecordValue::Integer(0)]).unwrap();
    }
    scan.finalize().unwrap();
    let mut scan = w.add_pointcloud("scan-2", prototype()).unwrap();
    scan.set_transform(Some(Transform { rotation: Quaternion { w: 0.0, x: 0.0, y: 0.0, z: 1.0 }, translation: Translation { x: 0.0, y: 0.0, z: 0.0 } }));
    for (k, p) in second.iter().enumerate() {
        scan.add_point(vec![RecordValue::Double(-p.x), RecordValue::Double(-p.y), RecordValue::Double(p.z), RecordValue::Integer(0)]).unwrap();
        if k % 10 == 0 {
            scan.add_point(vec![RecordValue::Double(0.0), RecordValue::Double(0.0), RecordValue::Double(0.0), RecordValue::Integer(2)]).unwrap();
        }
    }
    scan.finalize().unwrap();
    w.finalize().unwrap();
}

#[test]
fn an_e57_gives_the_curves_of_the_same_points_in_ply() {
    let d = tempfile::tempdir().unwrap();
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 30_000, ..Default::default() });
    let e57 = d.path().join("cube.e57");
    write_two_scans(&e57, &cube);
    let ply = d.path().join("cube.ply");
    let mut w = crease::io::PointWriter::create(&ply, &crease::io::WriteOptions { scale: 1e-6, offset: DVec3::ZERO, epsg: None }).unwrap();
    w.write(&cube, &vec![0; cube.len()]).unwrap();
    w.finish().unwrap();

    let h = crease::io::read_header(&e57).unwrap();
    assert_eq!(h.count, 30_000 + 1_500, "records, with the points without a return");
    let read = crease::io::read_all(std::slice::from_ref(&e57), &crease::io::Filter::default()).unwrap();
    assert_eq!(read.xyz, cube, "poses applied exactly, points without a return left out");

    // (Both scans are centred on the cube's corner: their scanners stood there, as far as the
    // file says, and the PLY run is told so.)
    let run = same_curves(d.path(), &e57, &ply, "0,0,0");
    assert_eq!(crease::curves::read_obj(&run.join("curves.obj")).unwrap().len(), 12);

    // Truncated and corrupted: one line naming the file, exit 2, no panic.
    let bytes = std::fs::read(&e57).unwrap();
    let mut flipped = bytes.clone();
    for k in (2000..flipped.len()).step_by(997) {
        flipped[k] ^= 0x5a;
    }
    for (name, b) in [("truncated.e57", bytes[..bytes.len() / 2].to_vec()), ("flipped.e57", flipped), ("header.e57", bytes[..40].to_vec())] {
        let p = d.path().join(name);
        std::fs::write(&p, b).unwrap();
        for cmd in ["info", "scan"] {
            let (code, err) = crease(&[cmd, p.to_str().unwrap()]);
            assert_eq!(code, crease::error::exit::DATA, "{name} {cmd}: {err}");
            assert!(!err.contains("panicked") && err.trim_end().lines().count() == 1 && err.contains(name), "{name} {cmd}: {err}");
        }
    }
}

#[test]
fn coordinate_metadata_names_the_crs_when_it_is_a_code_or_a_wkt() {
    let d = tempfile::tempdir().unwrap();
    let wkt = r#"PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["European_Terrestrial_Reference_System_1989",SPHEROID["GRS 1980",6378137,298.257222101]],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],UNIT["metre",1],AUTHORITY["EPSG","25832"]]"#;
    for (k, (metadata, epsg)) in
        [("EPSG:25832", Some(25832)), ("urn:ogc:def:crs:EPSG::2056", Some(2056)), (wkt, Some(25832)), ("site grid, mm", None)].into_iter().enumerate()
    {
        let path = d.path().join(format!("{k}.e57"));
        let mut w = E57Writer::from_file(&path, "crease-test-file").unwrap();
        w.set_coordinate_metadata(Some(metadata.into()));
        let mut scan = w.add_pointcloud("scan", vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64]).unwrap();
        for i in 0..10 {
            scan.add_point(vec![RecordValue::Double(i as f64), RecordValue::Double(0.0), RecordValue::Double(0.0)]).unwrap();
        }
        scan.finalize().unwrap();
        w.finalize().unwrap();
        let crs = crease::io::read_header(&path).unwrap().crs;
        assert_eq!(crs.epsg, epsg, "{metadata}");
        assert_eq!(crs.wkt.is_some(), metadata == wkt, "{metadata}");
    }
}

/// An E57 scan's pose places its scanner, which tells convex creases from concave ones: a step
/// (an L-shaped prism) scanned from (3, 3, 3), its scan stored about the scanner and turned half
/// a turn, gives the curves, shapes included, of the same points in PLY told where the scanner
/// stood; its inside corner reads concave.
#[test]
fn an_e57_scan_pose_tells_convex_from_concave() {
    let d = tempfile::tempdir().unwrap();
    let step = crease::synth::sample(&crease::synth::shape("step", 90.0).unwrap(), &crease::synth::SynthOptions { n: 60_000, ..Default::default() });
    let at = DVec3::new(3.0, 3.0, 3.0);
    let e57 = d.path().join("step.e57");
    let mut w = E57Writer::from_file(&e57, "crease-test-file").unwrap();
    let mut scan = w.add_pointcloud("scan", vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64]).unwrap();
    scan.set_transform(Some(Transform { rotation: Quaternion { w: 0.0, x: 0.0, y: 0.0, z: 1.0 }, translation: Translation { x: at.x, y: at.y, z: at.z } }));
    for p in &step {
        let q = *p - at;
        scan.add_point(vec![RecordValue::Double(-q.x), RecordValue::Double(-q.y), RecordValue::Double(q.z)]).unwrap();
    }
    scan.finalize().unwrap();
    w.finalize().unwrap();
    assert_eq!(crease::io::read_header(&e57).unwrap().scanners, vec![at]);
    // (The points as the E57 reader gives them, pose applied, so that both runs see the same.)
    let read = crease::io::read_all(std::slice::from_ref(&e57), &crease::io::Filter::default()).unwrap();
    let ply = d.path().join("step.ply");
    let mut w = crease::io::PointWriter::create(&ply, &crease::io::WriteOptions { scale: 1e-6, offset: DVec3::ZERO, epsg: None }).unwrap();
    w.write(&read.xyz, &read.class).unwrap();
    w.finish().unwrap();

    let run = same_curves(d.path(), &e57, &ply, "3,3,3");
    let curves = crease::curves::read_obj(&run.join("curves.obj")).unwrap();
    let corner =
        curves.iter().find(|c| c.vertices.iter().all(|v| (v.p.x - 0.4).abs() < 0.05 && (v.p.y - 0.4).abs() < 0.05)).expect("the inside corner's curve");
    assert_eq!(corner.shape, crease::curves::Shape::Concave);
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["outside"]["scanners"], serde_json::json!([[3.0, 3.0, 3.0]]));
    let shapes = &report["shapes"];
    assert_eq!(shapes["convex"].as_u64().unwrap() + shapes["concave"].as_u64().unwrap() + shapes["unknown"].as_u64().unwrap(), curves.len() as u64);
    assert!(shapes["convex"].as_u64().unwrap() >= 12, "{shapes}");
}

/// Which scans place a scanner: a spherical scan always (at its pose's translation); a
/// Cartesian scan stored about its scanner; not a Cartesian scan in a map's coordinates, whose
/// origin lies far from its points, with an identity pose or none.
#[test]
fn scanner_positions_come_from_scans_stored_about_their_scanner() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("scans.e57");
    let mut w = E57Writer::from_file(&path, "crease-test-file").unwrap();
    let spherical = vec![Record::SPHERICAL_AZIMUTH_F32, Record::SPHERICAL_ELEVATION_F32, Record::SPHERICAL_RANGE_F32];
    let mut scan = w.add_pointcloud("spherical", spherical).unwrap();
    scan.set_transform(Some(Transform { rotation: Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }, translation: Translation { x: 10.0, y: 20.0, z: 1.5 } }));
    for i in 0..10 {
        scan.add_point(vec![RecordValue::Single(0.1 * i as f32), RecordValue::Single(-0.2), RecordValue::Single(5.0)]).unwrap();
    }
    scan.finalize().unwrap();
    let cartesian = || vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64];
    let mut scan = w.add_pointcloud("about its scanner", cartesian()).unwrap();
    scan.set_transform(Some(Transform { rotation: Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }, translation: Translation { x: -4.0, y: 0.0, z: 2.0 } }));
    for i in 0..10 {
        scan.add_point(vec![RecordValue::Double(3.0 + i as f64), RecordValue::Double(1.0), RecordValue::Double(-2.0)]).unwrap();
    }
    scan.finalize().unwrap();
    // (With or without a pose: an identity pose is what some exports write.)
    for pose in [None, Some(Transform { rotation: Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }, translation: Translation { x: 0.0, y: 0.0, z: 0.0 } })] {
        let mut scan = w.add_pointcloud("map coordinates", cartesian()).unwrap();
        scan.set_transform(pose);
        for i in 0..10 {
            scan.add_point(vec![RecordValue::Double(500_000.0 + i as f64), RecordValue::Double(5_400_000.0), RecordValue::Double(100.0)]).unwrap();
        }
        scan.finalize().unwrap();
    }
    w.finalize().unwrap();
    let h = crease::io::read_header(&path).unwrap();
    assert_eq!(h.scanners, vec![DVec3::new(10.0, 20.0, 1.5), DVec3::new(-4.0, 0.0, 2.0)]);
}

/// A point that is not finite, or far beyond any scan (as a float stream decoded at the wrong
/// precision gives), is refused in one line naming the file, by `info` and by `extract`.
#[test]
fn an_e57_point_not_finite_or_beyond_any_scan_is_refused() {
    let d = tempfile::tempdir().unwrap();
    for (name, bad) in [("nan", f64::NAN), ("inf", f64::INFINITY), ("huge", 2.9e38)] {
        let path = d.path().join(format!("{name}.e57"));
        let mut w = E57Writer::from_file(&path, "crease-test-file").unwrap();
        let mut scan = w.add_pointcloud("scan-1", vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64]).unwrap();
        for k in 0..100 {
            let x = if k == 57 { bad } else { k as f64 };
            scan.add_point(vec![RecordValue::Double(x), RecordValue::Double(1.0), RecordValue::Double(2.0)]).unwrap();
        }
        scan.finalize().unwrap();
        w.finalize().unwrap();
        let run = d.path().join(format!("run-{name}"));
        for args in [vec!["info", path.to_str().unwrap()], vec!["extract", path.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"]] {
            let (code, err) = crease(&args);
            assert_eq!(code, crease::error::exit::DATA, "{name} {args:?}: {err}");
            assert!(err.contains(path.to_str().unwrap()) && err.contains("record 57") && err.lines().count() == 1, "{name} {args:?}: {err}");
        }
        assert!(!run.join("curves.obj").exists());
    }
}
