//! PLY point input in every encoding, and curve output round trips.

use crease::curves::{read_obj, read_ply, write_geojson, write_obj, write_ply, Polyline, Shape, Vertex};
use crease::io::{Filter, PointReader};
use crease::points::PointChunk;
use glam::{DVec3, Vec3};
use std::path::Path;

const PTS: [[f64; 3]; 4] = [[0.5, 1.25, -3.0], [1e3, -2.5, 0.125], [7.0, 8.0, 9.0], [-0.0625, 0.0, 1.5]];

fn read(path: &Path) -> PointChunk {
    PointReader::open(path, &Filter::default()).unwrap().read_all().unwrap()
}

fn binary_ply(big: bool, double: bool) -> Vec<u8> {
    let t = if double { "double" } else { "float" };
    let enc = if big { "binary_big_endian" } else { "binary_little_endian" };
    // A face element before the vertices and extra vertex properties, to check they are skipped.
    let mut b = format!(
        "ply\nformat {enc} 1.0\ncomment test\nelement face 1\nproperty list uchar int vertex_indices\n\
         element vertex 4\nproperty uchar red\nproperty {t} x\nproperty {t} y\nproperty {t} z\nproperty ushort intensity\nend_header\n"
    )
    .into_bytes();
    b.push(3);
    for i in [0i32, 1, 2] {
        b.extend(if big { i.to_be_bytes() } else { i.to_le_bytes() });
    }
    for p in PTS {
        b.push(200);
        for v in p {
            if double {
                b.extend(if big { v.to_be_bytes() } else { v.to_le_bytes() });
            } else {
                let v = v as f32;
                b.extend(if big { v.to_be_bytes() } else { v.to_le_bytes() });
            }
        }
        b.extend(if big { 7u16.to_be_bytes() } else { 7u16.to_le_bytes() });
    }
    b
}

#[test]
fn ply_all_encodings() {
    let d = tempfile::tempdir().unwrap();
    let expect: Vec<DVec3> = PTS.iter().map(|p| DVec3::from(*p)).collect();
    for big in [false, true] {
        for double in [false, true] {
            let p = d.path().join(format!("b{big}{double}.ply"));
            std::fs::write(&p, binary_ply(big, double)).unwrap();
            let c = read(&p);
            assert_eq!(c.xyz, expect, "big={big} double={double}");
        }
    }
    let p = d.path().join("a.ply");
    let mut s = String::from("ply\r\nformat ascii 1.0\r\nelement vertex 4\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nproperty list uchar int idx\r\nend_header\r\n");
    for q in PTS {
        s += &format!("{} {} {} 2 5 6\r\n", q[0], q[1], q[2]);
    }
    std::fs::write(&p, s).unwrap();
    assert_eq!(read(&p).xyz, expect);
}

#[test]
fn ply_chunks_cover_every_point() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("b.ply");
    std::fs::write(&p, binary_ply(false, true)).unwrap();
    let mut r = PointReader::open(&p, &Filter::default()).unwrap();
    let mut c = PointChunk::default();
    let mut all = vec![];
    while r.read_chunk(3, &mut c).unwrap() > 0 {
        all.extend_from_slice(&c.xyz);
    }
    assert_eq!(all.len(), 4);
    assert_eq!(all[3], DVec3::from(PTS[3]));
}

fn sample_curves() -> Vec<Polyline> {
    let n = |x: f32, y: f32, z: f32| Vec3::new(x, y, z).normalize();
    let corner = DVec3::new(1.0, 2.0, 3.0);
    vec![
        Polyline {
            id: 0,
            closed: false,
            vertices: vec![
                Vertex { p: corner, n: [n(1.0, 0.0, 0.0), n(0.0, 1.0, 0.0)], corner: true },
                Vertex { p: DVec3::new(1.1, 2.0, 3.000_000_000_1), n: [n(1.0, 0.1, 0.0), n(0.0, 1.0, 0.2)], corner: false },
                Vertex { p: DVec3::new(1.0 / 3.0, 2.0, 1e7 + 0.123), n: [n(1.0, 0.0, 0.0), n(0.0, 1.0, 0.0)], corner: false },
            ],
            confidence: 0.8125,
            shape: Shape::Convex,
        },
        Polyline {
            id: 7,
            closed: true,
            vertices: vec![
                Vertex { p: corner, n: [n(0.0, 0.0, 1.0), n(0.0, 1.0, 0.0)], corner: true },
                Vertex { p: DVec3::new(5.0, 5.0, 5.0), n: [n(0.0, 0.0, 1.0), n(0.0, 1.0, 0.0)], corner: false },
                Vertex { p: DVec3::new(-5.0, 5.0, 0.5), n: [n(0.0, 0.0, 1.0), n(0.0, 1.0, 0.0)], corner: false },
            ],
            confidence: 0.1,
            shape: Shape::Unknown,
        },
    ]
}

#[test]
fn ply_curves_round_trip_exactly() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("c.ply");
    let curves = sample_curves();
    write_ply(&p, &curves, &Default::default()).unwrap();
    assert_eq!(read_ply(&p).unwrap(), curves);
}

#[test]
fn obj_curves_round_trip_positions_ids_and_shared_corners() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("c.obj");
    let curves = sample_curves();
    write_obj(&p, &curves, &Default::default()).unwrap();
    let back = read_obj(&p).unwrap();
    assert_eq!(back.len(), curves.len());
    for (a, b) in curves.iter().zip(&back) {
        assert_eq!(a.id, b.id);
        assert_eq!(a.closed, b.closed);
        assert_eq!(a.confidence, b.confidence, "the confidence comment round-trips");
        assert_eq!(a.shape, b.shape, "the shape comment round-trips");
        let pa: Vec<DVec3> = a.vertices.iter().map(|v| v.p).collect();
        let pb: Vec<DVec3> = b.vertices.iter().map(|v| v.p).collect();
        assert_eq!(pa, pb, "positions must round-trip bit for bit");
        let ca: Vec<bool> = a.vertices.iter().map(|v| v.corner).collect();
        let cb: Vec<bool> = b.vertices.iter().map(|v| v.corner).collect();
        assert_eq!(ca, cb, "the shared corner is written once and read back as a corner");
    }
    // The corner shared by both curves is one OBJ vertex: 6 curve vertices, 5 'v' lines.
    let text = std::fs::read_to_string(&p).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 5);
}

#[test]
fn geojson_carries_crs_and_coordinates() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("c.geojson");
    let crs = crease::points::Crs { wkt: Some("PROJCS[\"x\"]".into()), epsg: Some(2154), ..Default::default() };
    write_geojson(&p, &sample_curves(), &crs, 1e-6).unwrap();
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    assert_eq!(v["crs"]["properties"]["name"], "urn:ogc:def:crs:EPSG::2154");
    assert_eq!(v["features"].as_array().unwrap().len(), 2);
    let ring = v["features"][1]["geometry"]["coordinates"].as_array().unwrap();
    assert_eq!(ring.len(), 4, "closed curve repeats its first vertex");
    assert_eq!(ring[0], ring[3]);
    assert_eq!(v["features"][0]["geometry"]["coordinates"][2][2], 1e7 + 0.123);
    assert_eq!(v["features"][0]["properties"]["confidence"], 0.8125);
    // Scalar attributes only (Shapefile and FlatGeobuf refuse lists): corners as text.
    let (a, b) = (&v["features"][0]["properties"], &v["features"][1]["properties"]);
    assert_eq!((a["corners"].as_str(), a["start"].as_str(), a["end"].as_str()), (Some("0"), Some("corner"), Some("free")));
    assert_eq!((b["start"].as_str(), b["end"].as_str()), (Some("closed"), Some("closed")));
    assert!((b["angle"].as_f64().unwrap() - 90.0).abs() < 1e-4, "{b}");
    assert_eq!((a["shape"].as_str(), b["shape"].as_str()), (Some("convex"), Some("unknown")));
    // Neither curve has a step that a line or an arc reaches beyond.
    assert_eq!((a["kind"].as_str(), b["kind"].as_str()), (Some("polyline"), Some("polyline")));
    assert!(a["radius"].is_null() && b["radius"].is_null());
    for f in v["features"].as_array().unwrap() {
        assert!(f["properties"].as_object().unwrap().values().all(|p| !p.is_array() && !p.is_object()), "{f}");
    }
    // Without an EPSG code, the `crs` member's name is the WKT, which GDAL reads as the CRS.
    let wkt_only = crease::points::Crs { wkt: Some("PROJCS[\"NAD83_2011_Nebraska_ft\"]".into()), ..Default::default() };
    write_geojson(&p, &sample_curves(), &wkt_only, 1e-6).unwrap();
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    assert_eq!(v["crs"]["properties"]["name"], "PROJCS[\"NAD83_2011_Nebraska_ft\"]");
    // Without any CRS, a local one of unknown unit: a GeoJSON that names none is WGS 84 to GDAL.
    write_geojson(&p, &sample_curves(), &crease::points::Crs::default(), 1e-6).unwrap();
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    let name = v["crs"]["properties"]["name"].as_str().unwrap();
    assert!(name.starts_with("LOCAL_CS[\"unknown\"") && name.contains("UNIT[\"unknown\",1]"), "{name}");
}

/// Curve PLYs of older layouts still read: without the shape (crease 0.7), each curve's shape
/// unknown; without the confidence either (crease 0.4, whose first normal was n1x, n1y, n1z),
/// each curve at confidence 1.
#[test]
fn ply_of_older_layouts_still_reads() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("c.ply");
    let curves = sample_curves();
    write_ply(&p, &curves, &Default::default()).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let head = String::from_utf8(bytes[..end].to_vec()).unwrap();
    // The first normal is nx, ny, nz (Open3D, CloudCompare and trimesh read it as the normal);
    // crease 0.5 and earlier named it n1x, n1y, n1z.
    assert!(head.contains("property float nx\nproperty float ny\nproperty float nz\nproperty float n2x\n"), "{head}");
    assert!(head.contains("property float confidence\nproperty uchar shape\n"), "{head}");
    let nv: usize = curves.iter().map(|c| c.vertices.len()).sum();
    // (A vertex is 58 bytes: the confidence is bytes 53-56, the shape byte 57.)
    for with_confidence in [true, false] {
        let mut head = head.replace("property uchar shape\n", "");
        let kept = if with_confidence { 57 } else { 53 };
        if !with_confidence {
            head = head
                .replace("property float confidence\n", "")
                .replace("float nx\n", "float n1x\n")
                .replace("float ny\n", "float n1y\n")
                .replace("float nz\n", "float n1z\n");
        }
        let mut old = head.into_bytes();
        for v in 0..nv {
            old.extend_from_slice(&bytes[end + v * 58..end + v * 58 + kept]);
        }
        old.extend_from_slice(&bytes[end + nv * 58..]);
        std::fs::write(&p, old).unwrap();
        let back = read_ply(&p).unwrap();
        assert_eq!(back.len(), 2);
        for (a, b) in curves.iter().zip(&back) {
            assert_eq!((a.id, a.closed, &a.vertices), (b.id, b.closed, &b.vertices));
            assert_eq!(b.confidence, if with_confidence { a.confidence } else { 1.0 });
            assert_eq!(b.shape, Shape::Unknown);
        }
    }
}
