//! Reader tests on the real LAS/LAZ files in `../shared/data/real` (ignored unless run with --include-ignored, as `.ci/run` does when they are there).

use crate::common;

use crease::io::{read_header, scan_bounds, Filter, PointReader};
use std::path::PathBuf;

fn real_dir() -> PathBuf {
    common::shared_data("real")
}

/// Every file: the header count equals the number of records read, and the header bounds equal
/// the min/max of a full read (to the file's coordinate resolution).
#[test]
#[ignore = "needs ../shared"]
fn header_counts_and_bounds_match_a_full_read() {
    let dir = real_dir();
    let files = crease::io::expand_inputs(&[dir], false).unwrap().files;
    assert_eq!(files.len(), 10, "expected the ten shared test files");
    for f in &files {
        let h = read_header(f).unwrap();
        let (b, n) = scan_bounds(f, &crease::io::Filter::keep_all()).unwrap();
        assert_eq!(n, h.count, "{}: point count", f.display());
        for i in 0..3 {
            // Header bounds are stored as doubles, points as scaled integers: allow one unit of
            // the coarsest scale the shared files use (0.01).
            assert!((b.min[i] - h.bounds.min[i]).abs() <= 0.01 + 1e-9, "{}: min[{i}] {} vs header {}", f.display(), b.min[i], h.bounds.min[i]);
            assert!((b.max[i] - h.bounds.max[i]).abs() <= 0.01 + 1e-9, "{}: max[{i}] {} vs header {}", f.display(), b.max[i], h.bounds.max[i]);
        }
    }
}

#[test]
#[ignore = "needs ../shared"]
fn known_point_counts() {
    let dir = real_dir();
    for (name, count, fmt) in [
        ("autzen_trim.las", 110_000, 3),
        ("autzen_trim.laz", 110_000, 3),
        ("lone-star.laz", 518_862, 1),
        ("las_with_several_extra_byte_bloc.laz", 697_721, 8),
        ("4_6_crop.las", 23_875, 3),
        ("file_with_both_wkt_and_geotiff_vlrs.las", 25_408, 6),
        ("fullwave.laz", 10_750, 10),
        ("simple1_4.las", 22_600, 7),
        ("1_4_w_evlr.laz", 1_000, 6),
        ("plane.laz", 28_185, 3),
    ] {
        let h = read_header(&dir.join(name)).unwrap();
        assert_eq!(h.count, count, "{name}");
        assert_eq!(h.point_format, Some(fmt), "{name}");
    }
}

/// LAS and LAZ copies of the same cloud decode to the same points.
#[test]
#[ignore = "needs ../shared"]
fn las_and_laz_agree() {
    let dir = real_dir();
    let a = PointReader::open(&dir.join("autzen_trim.las"), &Filter::keep_all()).unwrap().read_all().unwrap();
    let b = PointReader::open(&dir.join("autzen_trim.laz"), &Filter::keep_all()).unwrap().read_all().unwrap();
    assert_eq!(a.xyz, b.xyz);
    assert_eq!(a.class, b.class);
}

#[test]
#[ignore = "needs ../shared"]
fn crs_is_read() {
    let dir = real_dir();
    // The WKT bit is set: the WKT (US feet, no code) rules over the GeoTIFF keys' EPSG:32104
    // (metres), which a GIS would have placed the curves by.
    let h = read_header(&dir.join("file_with_both_wkt_and_geotiff_vlrs.las")).unwrap();
    assert!(h.crs.wkt.as_deref().unwrap().starts_with("PROJCS[\"NAD83_2011_Nebraska_ft\""));
    assert_eq!((h.crs.epsg, h.crs.horizontal_unit.as_deref()), (None, Some("Foot_US")));
    // Codes from the WKT's root AUTHORITY (a compound WKT1: its horizontal part's) or ID (WKT2).
    let h = read_header(&dir.join("las_with_several_extra_byte_bloc.laz")).unwrap();
    assert_eq!((h.crs.epsg, h.crs.horizontal_unit.as_deref()), (Some(2154), Some("metre")));
    let h = read_header(&dir.join("1_4_w_evlr.laz")).unwrap();
    assert_eq!((h.crs.epsg, h.crs.horizontal_unit.as_deref(), h.crs.vertical_unit.as_deref()), (Some(2903), Some("US survey foot"), Some("US survey foot")));
    let h = read_header(&dir.join("fullwave.laz")).unwrap();
    assert_eq!(h.crs.epsg, Some(32723));
    // GeoTIFF keys that name no code (user-defined) beside a WKT: the WKT.
    let h = read_header(&dir.join("autzen_trim.laz")).unwrap();
    assert_eq!((h.crs.epsg, h.crs.horizontal_unit.as_deref()), (None, Some("foot")));
    assert!(h.crs.wkt.as_deref().unwrap().contains("NAD_1983_HARN_Lambert_Conformal_Conic"));
    let h = read_header(&dir.join("plane.laz")).unwrap();
    assert!(h.crs.is_unknown());
}

/// Class filters: autzen has classes 1 and 2 only.
#[test]
#[ignore = "needs ../shared"]
fn class_filter() {
    let dir = real_dir();
    let f = dir.join("autzen_trim.las");
    let all = PointReader::open(&f, &Filter::keep_all()).unwrap().read_all().unwrap();
    let ground = PointReader::open(&f, &Filter { classes: Some(vec![2]), keep_noise: false, ..Filter::default() }).unwrap().read_all().unwrap();
    let n2 = all.class.iter().filter(|&&c| c == 2).count();
    assert!(n2 > 0 && n2 < all.len());
    assert_eq!(ground.len(), n2);
    assert!(ground.class.iter().all(|&c| c == 2));
    // The LAS 1.4 file with classes 1-6: noise classes 7/18 dropped by default; count agrees.
    let f = dir.join("las_with_several_extra_byte_bloc.laz");
    let all = PointReader::open(&f, &Filter::keep_all()).unwrap().read_all().unwrap();
    let def = PointReader::open(&f, &Filter::default()).unwrap().read_all().unwrap();
    let noise = all.class.iter().filter(|&&c| c == 7 || c == 18).count();
    assert!(def.len() <= all.len() - noise);
}

/// Curves from real scans: no open curve ends where it starts. (Completion once let both ends
/// of a piece shorter than a step take the corner it was grown from: 6 such curves on the
/// extra-bytes scan, 1 on autzen, 35 on lone-star.)
#[test]
#[ignore = "needs ../shared"]
fn no_curve_runs_out_from_a_corner_and_back() {
    for name in ["las_with_several_extra_byte_bloc.laz", "autzen_trim.laz"] {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let input = real_dir().join(name);
        let st = std::process::Command::new(env!("CARGO_BIN_EXE_crease"))
            .args(["extract", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"])
            .status()
            .unwrap();
        assert!(st.success(), "{name}");
        // (The PLY output says which curves are closed. OBJ numbers each corner once, so a
        // curve that ends at the corner it starts from reads back closed.)
        let curves = crease::curves::read_ply(&out.join("curves.ply")).unwrap();
        assert!(curves.len() >= 10, "{name}: {} curves", curves.len());
        for c in curves.iter().filter(|c| !c.closed) {
            let (first, last) = (c.vertices[0].p, c.vertices[c.vertices.len() - 1].p);
            assert_ne!(first, last, "{name}: curve {} of {} vertices ends where it starts", c.id, c.vertices.len());
        }
    }
}
