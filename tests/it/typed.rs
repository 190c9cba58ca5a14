//! Typed curves (`--format json`): pieces that cover every curve, each within its tolerance of
//! the vertices it spans, of the right kind on shapes whose edges are known.

use crease::curves::read_obj;
use glam::DVec3;
use std::path::Path;
use std::process::Command;

/// Extracts `cloud` with `curves.json` and returns the pieces, the curves and the tolerance.
fn typed(cloud: &Path, out: &Path) -> (Vec<serde_json::Value>, Vec<crease::curves::Polyline>, f64) {
    let st = Command::new(env!("CARGO_BIN_EXE_crease"))
        .args(["extract", cloud.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q", "--format", "obj,json"])
        .status()
        .unwrap();
    assert!(st.success());
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("curves.json")).unwrap()).unwrap();
    let curves = read_obj(&out.join("curves.obj")).unwrap();
    (v["pieces"].as_array().unwrap().clone(), curves, v["tolerance"].as_f64().unwrap())
}

fn point(v: &serde_json::Value) -> DVec3 {
    DVec3::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap())
}

/// Each curve's pieces follow each other over all its segments, start and end on its vertices,
/// and lie within the tolerance of every vertex they span.
fn check_cover(pieces: &[serde_json::Value], curves: &[crease::curves::Polyline], tol: f64) {
    for c in curves {
        let own: Vec<&serde_json::Value> = pieces.iter().filter(|p| p["curve"].as_u64() == Some(c.id as u64)).collect();
        let n = c.vertices.len();
        assert_eq!(own.iter().map(|p| p["segments"].as_u64().unwrap() as usize).sum::<usize>(), c.segment_count(), "curve {}", c.id);
        for p in own {
            let (first, segs) = (p["first"].as_u64().unwrap() as usize, p["segments"].as_u64().unwrap() as usize);
            let span: Vec<DVec3> = (0..=segs).map(|k| c.vertices[(first + k) % n].p).collect();
            // (Written through OBJ's decimal text and JSON's: equal to their last digits.)
            assert!(point(&p["start"]).distance(span[0]) < 1e-9 && point(&p["end"]).distance(span[segs]) < 1e-9);
            for q in &span {
                let d = match p["kind"].as_str().unwrap() {
                    "line" => {
                        let (a, b) = (point(&p["start"]), point(&p["end"]));
                        let t = ((*q - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
                        q.distance(a + t * (b - a))
                    }
                    "arc" | "circle" => {
                        let (o, ax, r) = (point(&p["centre"]), point(&p["axis"]), p["radius"].as_f64().unwrap());
                        let d = *q - o;
                        let h = d.dot(ax);
                        ((d - h * ax).length() - r).hypot(h)
                    }
                    _ => 0.0,
                };
                assert!(d <= tol * (1.0 + 1e-9), "a {} piece of curve {} misses a vertex by {d} (tolerance {tol})", p["kind"], c.id);
            }
        }
    }
}

#[test]
fn a_cubes_edges_are_twelve_lines_between_its_corners() {
    let d = tempfile::tempdir().unwrap();
    let (pieces, curves, tol) = typed(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cube.las"), d.path());
    check_cover(&pieces, &curves, tol);
    assert_eq!(pieces.len(), 12, "{pieces:?}");
    assert!(pieces.iter().all(|p| p["kind"] == "line"));
    // Each corner of the cube is the end of three lines.
    let mut ends: Vec<DVec3> = pieces.iter().flat_map(|p| [point(&p["start"]), point(&p["end"])]).collect();
    ends.sort_by(|a, b| a.to_array().partial_cmp(&b.to_array()).unwrap());
    ends.dedup_by(|a, b| a.distance(*b) < 1e-9);
    assert_eq!(ends.len(), 8);
}

#[test]
fn a_holed_cubes_edges_are_twelve_lines_and_its_bore_rims_two_circles() {
    let d = tempfile::tempdir().unwrap();
    let (pieces, curves, tol) = typed(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/holecube.las"), d.path());
    check_cover(&pieces, &curves, tol);
    let circles: Vec<&serde_json::Value> = pieces.iter().filter(|p| p["kind"] == "circle").collect();
    let lines = pieces.iter().filter(|p| p["kind"] == "line").count();
    assert_eq!((circles.len(), lines, pieces.len()), (2, 12, 14), "{pieces:?}");
    // The rims are the bore's, of radius 0.25.
    for c in circles {
        assert!((c["radius"].as_f64().unwrap() - 0.25).abs() < 0.0025, "{c:?}");
    }
}
