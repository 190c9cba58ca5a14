//! COPC input: a COPC file gives the curves of the same points in LAS, and `--bounds` reads only
//! the octree nodes that meet the box, keeping exactly the points a full read keeps; corrupt
//! files refused in one line.
//!
//! `fixtures/fandisk.copc.laz` holds the points of `fixtures/fandisk.las` in 55 octree nodes of
//! up to 4096 points, in another order; `scripts/copc-fixture` wrote it.

use crease::io::{Filter, PointReader, DEFAULT_CHUNK};
use crease::points::{Bounds, PointChunk};
use std::path::Path;
use std::process::Command;

const COPC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/fandisk.copc.laz");
const LAS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/fandisk.las");

fn crease(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// Records read, and the points kept (sorted by position) with their record indices, through
/// `filter`.
fn read_indexed(path: &str, filter: &Filter) -> (u64, Vec<([u64; 3], u64)>) {
    let mut r = PointReader::open(Path::new(path), filter).unwrap();
    let (mut records, mut kept) = (0, vec![]);
    let mut chunk = PointChunk::default();
    loop {
        let n = r.read_chunk(DEFAULT_CHUNK, &mut chunk).unwrap();
        if n == 0 {
            break;
        }
        records += n as u64;
        kept.extend(chunk.xyz.iter().zip(&chunk.index).map(|(p, &i)| (p.to_array().map(f64::to_bits), i)));
    }
    kept.sort_unstable();
    (records, kept)
}

/// Records read and the points kept (sorted by position), through `filter`.
fn read(path: &str, filter: &Filter) -> (u64, Vec<[u64; 3]>) {
    let (records, kept) = read_indexed(path, filter);
    (records, kept.into_iter().map(|(p, _)| p).collect())
}

/// The curves of a run, without the OBJ's comment lines (the COPC file carries a CRS).
fn curves(run: &Path) -> String {
    std::fs::read_to_string(run.join("curves.obj")).unwrap().lines().filter(|l| !l.starts_with('#')).collect::<Vec<_>>().join("\n")
}

#[test]
fn a_copc_file_gives_the_curves_of_the_same_points_in_las() {
    let d = tempfile::tempdir().unwrap();
    let (records, all) = read(COPC, &Filter::default());
    assert_eq!((records, all.clone()), read(LAS, &Filter::default()), "the same 50 000 points");
    assert_eq!(records, 50_000);
    assert_eq!(crease::io::read_header(Path::new(COPC)).unwrap().version, "1.4 (COPC)");
    assert_eq!(crease::io::read_header(Path::new(LAS)).unwrap().version, "1.2");

    // A box in a corner of the part: the octree's nodes that miss it are not decompressed,
    // and the points kept are those of a full read inside the box, whatever the format.
    let corner = Bounds { min: [-1.0, -1.0, -1.0], max: [0.5, 0.5, 0.5] };
    let boxed = Filter { bounds: Some(corner), ..Filter::default() };
    let (copc_records, copc_kept) = read(COPC, &boxed);
    let (las_records, las_kept) = read(LAS, &boxed);
    let in_box = |p: &[u64; 3]| corner.contains(glam::DVec3::from_array(p.map(f64::from_bits)));
    let inside: Vec<[u64; 3]> = all.iter().copied().filter(in_box).collect();
    assert!(!inside.is_empty() && inside.len() < all.len() / 4, "{} of {} inside", inside.len(), all.len());
    assert_eq!(copc_kept, inside);
    assert_eq!(las_kept, inside);
    assert_eq!(las_records, 50_000, "a LAS file is read whole");
    assert!(copc_records < 25_000, "the COPC file read {copc_records} records for {} points in the box", inside.len());
    // The nodes read alone give their points the record indices of a front-to-back read.
    let whole: Vec<([u64; 3], u64)> = read_indexed(COPC, &Filter::default()).1.into_iter().filter(|(p, _)| in_box(p)).collect();
    assert_eq!(read_indexed(COPC, &boxed).1, whole);

    for (name, args) in [("whole", vec![]), ("box", vec!["--bounds", "0,0,1,0.5"])] {
        let runs = [("copc", COPC), ("las", LAS)].map(|(format, input)| {
            let run = d.path().join(format!("{name}-{format}"));
            let mut a = vec!["extract", input, "-o", run.to_str().unwrap(), "-q"];
            a.extend(&args);
            let (code, err) = crease(&a);
            assert_eq!(code, 0, "{err}");
            run
        });
        assert_eq!(curves(&runs[0]), curves(&runs[1]), "{name}");
        let n = crease::curves::read_obj(&runs[0].join("curves.obj")).unwrap().len();
        assert!(if name == "whole" { n == 27 } else { (4..27).contains(&n) }, "{name}: {n} curves");
    }
}

#[test]
fn bounds_that_miss_the_cloud_or_are_malformed_are_usage_errors() {
    let d = tempfile::tempdir().unwrap();
    let run = d.path().join("run");
    for b in ["5,5,6,6", "0,0,1", "1,0,0,1", "0,0,nan,1"] {
        let (code, err) = crease(&["extract", COPC, "-o", run.to_str().unwrap(), "--bounds", b]);
        assert_eq!(code, crease::error::exit::USAGE, "{b}: {err}");
        assert!(err.contains("--bounds") && err.trim_end().lines().count() == 1, "{b}: {err}");
    }
    assert!(!run.join("curves.obj").exists());
}

#[test]
fn corrupt_copc_files_read_with_bounds_are_refused_in_one_line() {
    let d = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(COPC).unwrap();
    let header_len = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
    let mut flipped = bytes.clone();
    for k in (header_len + 2000..bytes.len()).step_by(997) {
        flipped[k] ^= 0x5a;
    }
    // The hierarchy EVLR's entries: (key 16 bytes, offset 8, byte size 4, count 4) each.
    let evlr = u64::from_le_bytes(bytes[235..243].try_into().unwrap()) as usize + 60;
    let mut offsets = bytes.clone();
    offsets[evlr + 16..evlr + 24].copy_from_slice(&(bytes.len() as u64 - 10).to_le_bytes());
    let mut counts = bytes.clone();
    counts[evlr + 28..evlr + 32].copy_from_slice(&i32::MAX.to_le_bytes());
    // The second half of every node's compressed bytes inverted: the chunk headers intact.
    let mut nodes = bytes.clone();
    for e in bytes[evlr..].chunks_exact(32).take(55) {
        let (at, size) = (u64::from_le_bytes(e[16..24].try_into().unwrap()) as usize, i32::from_le_bytes(e[24..28].try_into().unwrap()) as usize);
        for k in (at + size / 2..at + size - 8).step_by(101) {
            nodes[k] ^= 0xff;
        }
    }
    for (name, b) in [
        ("truncated.copc.laz", bytes[..bytes.len() / 2].to_vec()),
        ("flipped.copc.laz", flipped),
        ("offset.copc.laz", offsets),
        ("count.copc.laz", counts),
        ("nodes.copc.laz", nodes),
    ] {
        let p = d.path().join(name);
        std::fs::write(&p, b).unwrap();
        for cmd in ["scan", "extract"] {
            let run = d.path().join(format!("{name}.run"));
            let mut a = vec![cmd, p.to_str().unwrap(), "--bounds", "0,0,1,0.5"];
            if cmd == "extract" {
                a.extend(["-o", run.to_str().unwrap(), "-q"]);
            }
            let (code, err) = crease(&a);
            assert_eq!(code, crease::error::exit::DATA, "{name} {cmd}: {err}");
            assert!(!err.contains("panicked") && err.trim_end().lines().count() == 1 && err.contains(name), "{name} {cmd}: {err}");
        }
    }
}
