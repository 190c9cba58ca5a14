//! Converts a LAS file to COPC with the `copc-rs` writer (las-rs and laspy only read COPC, and
//! Debian has no PDAL), giving crease's COPC reader a fixture with a real octree hierarchy.
//!
//! Usage: cargo run --release -- IN.las OUT.copc.laz [MAX_NODE_POINTS]
//!
//! COPC requires a WKT CRS; a file without a CRS is given a local engineering CRS in metres.

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: crease-copc-fixture IN.las OUT.copc.laz [MAX_NODE_POINTS]");
        std::process::exit(2);
    }
    let max_node: i32 = args.get(3).map_or(4096, |s| s.parse().expect("MAX_NODE_POINTS is an integer"));
    let mut reader = las::Reader::from_path(&args[1]).expect("readable LAS");
    let mut header = reader.header().clone();
    // (copc-rs turns GeoTIFF keys into a WKT itself.)
    let has_crs = header.all_vlrs().any(|v| v.user_id == "LASF_Projection" && matches!(v.record_id, 2112 | 34735));
    if !has_crs {
        let mut b = las::Builder::from(header.clone());
        b.vlrs.push(las::Vlr {
            user_id: "LASF_Projection".into(),
            record_id: 2112,
            description: "OGC WKT".into(),
            data: b"LOCAL_CS[\"crease fixture\",LOCAL_DATUM[\"none\",0],UNIT[\"metre\",1],AXIS[\"X\",EAST],AXIS[\"Y\",NORTH]]\0".to_vec(),
        });
        header = b.into_header().expect("header with a WKT");
    }
    let mut builder = las::Builder::from(header);
    builder.point_format = las::point::Format::new(6).expect("format 6");
    builder.version = las::Version::new(1, 4);
    let header = builder.into_header().expect("LAS 1.4 header");
    // (Format 6 records carry a GPS time; the input's may not.)
    let points: Vec<las::Point> = reader.points().map(|p| las::Point { gps_time: Some(0.0), ..p.expect("readable point") }).collect();
    let n = points.len() as i32;
    let mut w = copc_rs::CopcWriter::from_path(&args[2], header, max_node / 4, max_node).expect("COPC writer");
    w.write(points, n).expect("COPC written");
    drop(w);
    eprintln!("wrote {} points to {}", n, args[2]);
}
