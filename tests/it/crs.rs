//! CRS: read from every VLR and EVLR, named with its units in every output, and assigned with
//! `--a-srs`.

use std::path::Path;
use std::process::Command;

fn crease(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

const WKT: &str = r#"PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["European_Terrestrial_Reference_System_1989",SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],UNIT["metre",1],AXIS["Easting",EAST],AXIS["Northing",NORTH],AUTHORITY["EPSG","25832"]]"#;

/// A LAS 1.4 cube whose WKT is in its second EVLR (a COPC file puts its hierarchy first).
fn cube_with_wkt_in_a_later_evlr(path: &Path) {
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
    let mut b = las::Builder::from((1, 4));
    b.point_format = las::point::Format::new(6).unwrap();
    b.transforms = las::Vector {
        x: las::Transform { scale: 1e-5, offset: 0.0 },
        y: las::Transform { scale: 1e-5, offset: 0.0 },
        z: las::Transform { scale: 1e-5, offset: 0.0 },
    };
    b.evlrs.push(las::Vlr { user_id: "copc".into(), record_id: 1000, description: "hierarchy".into(), data: vec![0; 64] });
    b.evlrs.push(las::Vlr { user_id: "LASF_Projection".into(), record_id: 2112, description: "OGC WKT".into(), data: WKT.as_bytes().to_vec() });
    let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
    for p in &cube {
        w.write_point(las::Point { x: p.x, y: p.y, z: p.z, gps_time: Some(0.0), ..Default::default() }).unwrap();
    }
    w.close().unwrap();
    // The WKT bit of the global encoding (byte 6, bit 4), which point formats 6-10 require.
    let mut bytes = std::fs::read(path).unwrap();
    bytes[6] |= 0x10;
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn a_wkt_in_a_later_evlr_names_every_output() {
    let d = tempfile::tempdir().unwrap();
    let cloud = d.path().join("cube.las");
    cube_with_wkt_in_a_later_evlr(&cloud);
    let h = crease::io::read_header(&cloud).unwrap();
    assert_eq!((h.crs.epsg, h.crs.horizontal_unit.as_deref()), (Some(25832), Some("metre")));
    let run = d.path().join("run");
    let (code, err) = crease(&["extract", cloud.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    let summary = "EPSG:25832 (units: metre)";
    let geojson: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("curves.geojson")).unwrap()).unwrap();
    assert_eq!(geojson["crs"]["properties"]["name"], "urn:ogc:def:crs:EPSG::25832");
    assert_eq!(geojson["crs_wkt"], WKT);
    assert_eq!(geojson["crs_units"]["horizontal"], "metre");
    assert!(std::fs::read_to_string(run.join("curves.obj")).unwrap().contains(&format!("\n# crs {summary}\n")));
    let ply = std::fs::read(run.join("curves.ply")).unwrap();
    assert!(String::from_utf8_lossy(&ply[..400]).contains(&format!("\ncomment crs {summary}\n")));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("report.json")).unwrap()).unwrap();
    assert_eq!((report["crs"]["epsg"].as_u64(), report["crs"]["horizontal_unit"].as_str()), (Some(25832), Some("metre")));
    // The curves still read back.
    assert_eq!(crease::curves::read_ply(&run.join("curves.ply")).unwrap().len(), 12);
    assert_eq!(crease::curves::read_obj(&run.join("curves.obj")).unwrap().len(), 12);

    // GeoPackage: the SRS table holds the CRS (code and WKT), each curve one LineString Z row.
    let (code, err) = crease(&["extract", cloud.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q", "--format", "gpkg,obj"]);
    assert_eq!(code, 0, "{err}");
    assert!(!run.join("curves.ply").exists() && !run.join("curves.geojson").exists(), "formats not asked for are removed");
    let db = rusqlite::Connection::open(run.join("curves.gpkg")).unwrap();
    let app: i64 = db.query_row("PRAGMA application_id", [], |r| r.get(0)).unwrap();
    assert_eq!(app, 0x4750_4B47, "'GPKG'");
    let (org, def): (String, String) =
        db.query_row("SELECT organization, definition FROM gpkg_spatial_ref_sys WHERE srs_id = 25832", [], |r| Ok((r.get(0)?, r.get(1)?))).unwrap();
    assert_eq!((org.as_str(), def.as_str()), ("EPSG", WKT));
    let rows: Vec<(Vec<u8>, String)> =
        db.prepare("SELECT geom, corners FROM curves").unwrap().query_map([], |r| Ok((r.get(0)?, r.get(1)?))).unwrap().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 12);
    for (g, _) in &rows {
        assert_eq!(&g[..2], b"GP");
        assert_eq!(i32::from_le_bytes(g[4..8].try_into().unwrap()), 25832);
        assert_eq!(u32::from_le_bytes(g[57..61].try_into().unwrap()), 1002, "LineString Z");
    }
    assert!(rows.iter().any(|(_, c)| !c.is_empty()), "cube edges end at corners");

    // DXF: each cube edge a LINE on its layer between two corners, carrying its curve's
    // attributes as extended data; each corner a point on another layer.
    let (code, err) = crease(&["extract", cloud.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q", "--format", "dxf"]);
    assert_eq!(code, 0, "{err}");
    assert!(!run.join("curves.gpkg").exists());
    let drawing = dxf::Drawing::load_file(run.join("curves.dxf")).unwrap();
    let (mut lines, mut corners) = (vec![], vec![]);
    let at = |p: &dxf::Point| glam::DVec3::new(p.x, p.y, p.z);
    for e in drawing.entities() {
        match &e.specific {
            dxf::entities::EntityType::Line(l) => {
                let n = lines.len();
                assert_eq!(e.common.layer, "crease_lines");
                assert_eq!(e.common.x_data.len(), 1, "curve {n}: one block of extended data");
                let x = &e.common.x_data[0];
                assert_eq!(x.application_name, "CREASE");
                let value = |name: &str| x.items.iter().position(|i| *i == dxf::XDataItem::Str(name.into())).map(|k| x.items[k + 1].clone());
                let value = |name: &str| value(name).unwrap_or_else(|| panic!("curve {n}: no {name}"));
                assert_eq!(value("id"), dxf::XDataItem::Long(n as i32));
                assert_eq!(value("kind"), dxf::XDataItem::Str("line".into()));
                assert!(x.items.iter().all(|i| *i != dxf::XDataItem::Str("radius".into())), "curve {n}: a line has no radius");
                // The curve's length: its vertices', a little over the straight line's.
                let chord = at(&l.p1).distance(at(&l.p2));
                let dxf::XDataItem::Real(length) = value("length") else { panic!("curve {n}: length is not a real") };
                assert!(length >= chord * (1.0 - 1e-9) && length < 1.01 * chord, "curve {n}: length {length}, line {chord}");
                let dxf::XDataItem::Real(angle) = value("angle") else { panic!("curve {n}: angle is not a real") };
                assert!((angle - 90.0).abs() < 5.0, "curve {n}: a cube edge at {angle} degrees");
                // (No scanner position is known for a LAS file unless given.)
                assert_eq!(value("shape"), dxf::XDataItem::Str("unknown".into()));
                assert_eq!((value("start"), value("end")), (dxf::XDataItem::Str("corner".into()), dxf::XDataItem::Str("corner".into())));
                lines.push([at(&l.p1), at(&l.p2)]);
            }
            dxf::entities::EntityType::ModelPoint(p) => {
                assert_eq!(e.common.layer, "crease_corners");
                corners.push(at(&p.location));
            }
            other => panic!("a cube's curves are lines: {other:?}"),
        }
    }
    assert_eq!((lines.len(), corners.len()), (12, 8));
    // Every line runs between two corners.
    assert!(lines.iter().flatten().all(|p| corners.contains(p)), "{lines:?} {corners:?}");

    // --a-srs: the outputs carry the assigned CRS, and the replaced one is named in a warning.
    let (code, err) = crease(&["extract", cloud.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q", "--a-srs", "EPSG:4258"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("cube.las: its CRS EPSG:25832 (units: metre) is replaced by the one assigned, EPSG:4258"), "{err}");
    let geojson: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("curves.geojson")).unwrap()).unwrap();
    assert_eq!(geojson["crs"]["properties"]["name"], "urn:ogc:def:crs:EPSG::4258");
    let (code, err) = crease(&["extract", cloud.to_str().unwrap(), "-o", run.to_str().unwrap(), "--a-srs", "UTM 32"]);
    assert_eq!(code, crease::error::exit::USAGE);
    assert!(err.contains("neither EPSG:N nor a WKT"), "{err}");
}
