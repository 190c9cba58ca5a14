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
    let cube = crease::synth::sample(&crease::synth::shapes::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
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

    // DXF: each curve a 3D polyline on its layer, carrying its attributes as extended data;
    // each corner a point on another layer.
    let (code, err) = crease(&["extract", cloud.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q", "--format", "dxf"]);
    assert_eq!(code, 0, "{err}");
    assert!(!run.join("curves.gpkg").exists());
    let drawing = dxf::Drawing::load_file(run.join("curves.dxf")).unwrap();
    let (mut lines, mut corners) = (0, 0);
    for e in drawing.entities() {
        match &e.specific {
            dxf::entities::EntityType::Polyline(p) => {
                assert!(p.is_3d_polyline() && e.common.layer == "crease_curves");
                assert!(p.vertices().count() >= 2);
                assert_eq!(e.common.x_data.len(), 1, "curve {lines}: one block of extended data, on the polyline");
                let x = &e.common.x_data[0];
                assert_eq!(x.application_name, "CREASE");
                let value = |name: &str| {
                    let k = x.items.iter().position(|i| *i == dxf::XDataItem::Str(name.into())).unwrap_or_else(|| panic!("curve {lines}: no {name}"));
                    x.items[k + 1].clone()
                };
                assert_eq!(value("id"), dxf::XDataItem::Long(lines));
                let v: Vec<glam::DVec3> = p.vertices().map(|v| glam::DVec3::new(v.location.x, v.location.y, v.location.z)).collect();
                let length: f64 = v.windows(2).map(|w| w[0].distance(w[1])).sum::<f64>() + if p.is_closed() { v[v.len() - 1].distance(v[0]) } else { 0.0 };
                let dxf::XDataItem::Real(stated) = value("length") else { panic!("curve {lines}: length is not a real") };
                assert!((stated - length).abs() < 1e-9 * length, "curve {lines}: length {stated}, vertices {length}");
                let dxf::XDataItem::Real(angle) = value("angle") else { panic!("curve {lines}: angle is not a real") };
                assert!((angle - 90.0).abs() < 5.0, "curve {lines}: a cube edge at {angle} degrees");
                // (No scanner position is known for a LAS file unless given.)
                assert_eq!(value("shape"), dxf::XDataItem::Str("unknown".into()));
                assert_eq!((value("start"), value("end")), (dxf::XDataItem::Str("corner".into()), dxf::XDataItem::Str("corner".into())));
                lines += 1;
            }
            dxf::entities::EntityType::Seqend(_) => assert!(e.common.x_data.is_empty(), "extended data left on a SEQEND"),
            dxf::entities::EntityType::ModelPoint(_) => {
                assert_eq!(e.common.layer, "crease_corners");
                corners += 1;
            }
            _ => {}
        }
    }
    assert_eq!((lines, corners), (12, 8));

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
