//! `--label-points`: each input's points copied, in order and with all their fields, with
//! their distance to the nearest curve, that curve's id and an edge flag; LAZ 1.4 extra bytes
//! for LAS input, PLY properties for PLY input; resumable; refused, naming the file, for an
//! input gone or changed since the run. And `crease status` lists the typed pieces by kind.

use crease::curves::{read_ply, Polyline};
use glam::DVec3;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(name)
}

/// Every point of a LAS or LAZ file, in order.
fn points_of(r: &mut las::Reader) -> Vec<las::Point> {
    r.read_all().unwrap().points().map(|p| p.unwrap()).collect()
}

fn crease(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap()
}

/// Runs `crease extract` and asserts it succeeded.
fn extract(inputs: &[&Path], dir: &Path, extra: &[&str]) {
    let mut args = vec!["extract".to_string()];
    args.extend(inputs.iter().map(|p| p.to_str().unwrap().to_string()));
    args.extend(["-o", dir.to_str().unwrap(), "-q"].map(String::from));
    args.extend(extra.iter().map(|s| s.to_string()));
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(&args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// The tolerance of a run that wrote curves.json.
fn tolerance(dir: &Path) -> f64 {
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("curves.json")).unwrap()).unwrap();
    v["tolerance"].as_f64().unwrap()
}

/// Distance from `q` to the nearest curve, and that curve's id, by looking at every segment.
fn brute_nearest(curves: &[Polyline], q: DVec3) -> (f64, u32) {
    let mut best = (f64::INFINITY, u32::MAX);
    for c in curves {
        for (a, b) in c.segments() {
            let ab = b - a;
            let t = if ab.length_squared() > 0.0 { ((q - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0) } else { 0.0 };
            let d = q.distance(a + t * ab);
            if (d, c.id) < best {
                best = (d, c.id);
            }
        }
    }
    best
}

/// The three labels stored after `at` bytes of a record's extra bytes (little-endian).
fn labels_of(extra: &[u8]) -> (f64, i32, u8) {
    let n = extra.len();
    let e = &extra[n - 13..];
    (f64::from_le_bytes(e[..8].try_into().unwrap()), i32::from_le_bytes(e[8..12].try_into().unwrap()), e[12])
}

/// Checks labels against the curves: the distance is the nearest curve's, `edge` is set exactly
/// within the tolerance, `curve_id` names that curve (or -1 beyond reach, never within the
/// tolerance). Returns the number of edge points.
fn check_labels(points: &[DVec3], labels: &[(f64, i32, u8)], curves: &[Polyline], tol: f64) -> usize {
    assert!(!curves.is_empty());
    let mut edges = 0;
    for (p, &(d, id, edge)) in points.iter().zip(labels) {
        let (bd, bid) = brute_nearest(curves, *p);
        assert!((d - bd).abs() <= 1e-9 * (1.0 + bd), "{p}: distance {d}, nearest curve at {bd}");
        assert!(id == bid as i32 || (id == -1 && d > tol), "{p}: curve {id}, nearest {bid} at {bd}");
        if (bd - tol).abs() > 1e-9 {
            assert_eq!(edge == 1, bd <= tol, "{p}: edge {edge} at {bd} (tolerance {tol})");
        }
        edges += edge as usize;
    }
    edges
}

/// A labelled LAZ read back by the las crate: LAS 1.4, the input's point format, an Extra Bytes
/// VLR of three 192-byte descriptors naming the labels; every point in order with every
/// original field unchanged; labels that agree with the curves.
#[test]
fn a_labelled_laz_keeps_the_points_and_labels_them_by_the_curves() {
    let d = tempfile::tempdir().unwrap();
    let (cube, dir) = (fixture("cube.las"), d.path().join("run"));
    extract(&[&cube], &dir, &["--label-points", "--format", "ply,json"]);
    let labelled = dir.join("labels/cube.laz");
    let mut input = las::Reader::from_path(&cube).unwrap();
    let mut output = las::Reader::from_path(&labelled).unwrap();
    let (hi, ho) = (input.header().clone(), output.header().clone());
    assert_eq!(ho.version(), las::Version::new(1, 4));
    assert_eq!((ho.point_format().to_u8().unwrap(), ho.point_format().extra_bytes), (hi.point_format().to_u8().unwrap(), hi.point_format().extra_bytes + 13));
    assert_eq!(ho.number_of_points(), hi.number_of_points());
    let vlr = ho.vlrs().iter().find(|v| v.user_id == "LASF_Spec" && v.record_id == 4).expect("an Extra Bytes VLR");
    assert_eq!(vlr.data.len(), 3 * 192);
    let names: Vec<String> = vlr.data.chunks(192).map(|c| String::from_utf8_lossy(&c[4..36]).trim_end_matches('\0').to_string()).collect();
    assert_eq!(names, ["edge_distance", "curve_id", "edge"]);
    assert_eq!(vlr.data.chunks(192).map(|c| c[2]).collect::<Vec<_>>(), [10, 6, 1], "f64, i32, u8");
    let (mut points, mut labels) = (vec![], vec![]);
    for (a, mut b) in points_of(&mut input).into_iter().zip(points_of(&mut output)) {
        labels.push(labels_of(&b.extra_bytes));
        b.extra_bytes.truncate(a.extra_bytes.len());
        assert_eq!(a, b, "every field of every point, in order");
        points.push(DVec3::new(b.x, b.y, b.z));
    }
    assert_eq!(points.len() as u64, hi.number_of_points());
    let curves = read_ply(&dir.join("curves.ply")).unwrap();
    let edges = check_labels(&points, &labels, &curves, tolerance(&dir));
    // (The cube's 12 edges hold a few percent of its points.)
    assert!(edges > 100 && edges < points.len() / 4, "{edges} edge points of {}", points.len());
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["labels"][0].as_str().map(PathBuf::from), Some(labelled));
}

/// Writes `points` as a binary little-endian PLY with an intensity after x, y, z (float) and a
/// face element after the vertices, which the labelled copy must carry unchanged.
fn write_ply(path: &Path, points: &[DVec3]) -> Vec<u8> {
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\ncomment a test\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty ushort intensity\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        points.len()
    )
    .into_bytes();
    for (i, p) in points.iter().enumerate() {
        for v in p.to_array() {
            b.extend_from_slice(&(v as f32).to_le_bytes());
        }
        b.extend_from_slice(&(i as u16).to_le_bytes());
    }
    let face: Vec<u8> = [vec![3u8], [0i32, 1, 2].iter().flat_map(|i| i.to_le_bytes()).collect()].concat();
    b.extend_from_slice(&face);
    std::fs::write(path, &b).unwrap();
    face
}

/// A PLY input gets a PLY copy: its header with the three vertex properties added, each vertex
/// record as it was followed by its labels, the face element after them as it was.
#[test]
fn a_ply_input_gets_a_ply_with_the_label_properties() {
    let d = tempfile::tempdir().unwrap();
    let cube: Vec<DVec3> = points_of(&mut las::Reader::from_path(fixture("cube.las")).unwrap()).iter().map(|p| DVec3::new(p.x, p.y, p.z)).collect();
    let (ply, dir) = (d.path().join("cube.ply"), d.path().join("run"));
    let face = write_ply(&ply, &cube);
    extract(&[&ply], &dir, &["--label-points", "--format", "ply,json"]);
    let out = std::fs::read(dir.join("labels/cube.ply")).unwrap();
    let end = out.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&out[..end]).unwrap();
    assert!(
        header.contains("property ushort intensity\nproperty double edge_distance\nproperty int curve_id\nproperty uchar edge\nelement face 1\n"),
        "{header}"
    );
    let input = std::fs::read(&ply).unwrap();
    let body = input.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let (rin, rout) = (14, 14 + 13);
    assert_eq!(out.len() - end, cube.len() * rout + face.len());
    let (mut points, mut labels) = (vec![], vec![]);
    for (i, rec) in out[end..end + cube.len() * rout].chunks_exact(rout).enumerate() {
        assert_eq!(&rec[..rin], &input[body + i * rin..body + (i + 1) * rin], "vertex {i}");
        let f = |k: usize| f32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().unwrap()) as f64;
        points.push(DVec3::new(f(0), f(1), f(2)));
        labels.push(labels_of(rec));
    }
    assert_eq!(&out[out.len() - face.len()..], &face[..]);
    let curves = read_ply(&dir.join("curves.ply")).unwrap();
    assert!(check_labels(&points, &labels, &curves, tolerance(&dir)) > 100);
}

/// A text cloud's copy is a LAZ of point format 6 with the labels: every point, in order, at
/// its coordinates to the scale's rounding.
#[test]
fn a_text_input_gets_a_laz_of_its_points() {
    let d = tempfile::tempdir().unwrap();
    let cube: Vec<DVec3> = points_of(&mut las::Reader::from_path(fixture("cube.las")).unwrap()).iter().map(|p| DVec3::new(p.x, p.y, p.z)).collect();
    let xyz = d.path().join("cube.xyz");
    std::fs::write(&xyz, cube.iter().map(|p| format!("{} {} {}\n", p.x, p.y, p.z)).collect::<String>()).unwrap();
    let dir = d.path().join("run");
    extract(&[&xyz], &dir, &["--label-points"]);
    let mut r = las::Reader::from_path(dir.join("labels/cube.laz")).unwrap();
    assert_eq!(r.header().point_format().to_u8().unwrap(), 6);
    let scale = r.header().transforms().x.scale;
    let got = points_of(&mut r);
    assert_eq!(got.len(), cube.len());
    for (p, q) in got.iter().zip(&cube) {
        assert!(DVec3::new(p.x, p.y, p.z).distance(*q) <= scale, "{q}");
        assert_eq!(p.extra_bytes.len(), 13);
    }
}

/// Shifted copy of a LAS file (x + dx), a second input of a run.
fn shifted(from: &Path, to: &Path, dx: f64) {
    let mut r = las::Reader::from_path(from).unwrap();
    let mut w = las::Writer::from_path(to, r.header().clone()).unwrap();
    for mut p in points_of(&mut r) {
        p.x += dx;
        w.write_point(p).unwrap();
    }
    w.close().unwrap();
}

fn modified(p: &Path) -> std::time::SystemTime {
    std::fs::metadata(p).unwrap().modified().unwrap()
}

/// The label pass resumes: a finished copy is not made again (nor on a run given the same
/// command again), an unfinished one is; other output filters make other curves, and the
/// copies are made anew; a run not asked for labels removes them.
#[test]
fn a_resumed_label_pass_does_not_redo_finished_files() {
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    std::fs::copy(fixture("cube.las"), scans.join("a.las")).unwrap();
    shifted(&fixture("cube.las"), &scans.join("b.las"), 3.0);
    let dir = d.path().join("run");
    extract(&[&scans], &dir, &["--label-points"]);
    let (a, b) = (dir.join("labels/a.laz"), dir.join("labels/b.laz"));
    let (ta, tb) = (modified(&a), modified(&b));
    std::thread::sleep(std::time::Duration::from_millis(20));
    extract(&[&scans], &dir, &["--label-points"]);
    assert_eq!((modified(&a), modified(&b)), (ta, tb), "finished copies are not made again");
    // (As a run killed while writing b leaves it: a done, b under its temporary name.)
    let bytes = std::fs::read(&b).unwrap();
    std::fs::rename(&b, dir.join("labels/b.laz.tmp")).unwrap();
    extract(&[&scans], &dir, &["--label-points"]);
    assert_eq!(modified(&a), ta);
    assert_eq!(std::fs::read(&b).unwrap(), bytes, "the copy made again is the same bytes");
    assert!(!dir.join("labels/b.laz.tmp").exists());
    extract(&[&scans], &dir, &["--label-points", "--min-confidence", "1"]);
    assert_ne!(modified(&a), ta, "other curves: the copies are made anew");
    extract(&[&scans], &dir, &[]);
    assert!(!dir.join("labels").exists());
}

/// An input changed or gone since the run: `--label-points` on the finished run stops with an
/// error naming the file (not a panic), and writes no copy of it.
#[test]
fn labelling_a_changed_or_vanished_input_names_it() {
    let d = tempfile::tempdir().unwrap();
    let las = d.path().join("part.las");
    std::fs::copy(fixture("cube.las"), &las).unwrap();
    let dir = d.path().join("run");
    extract(&[&las], &dir, &[]);
    let args = ["extract", las.to_str().unwrap(), "-o", dir.to_str().unwrap(), "-q", "--label-points"];
    let mut bytes = std::fs::read(&las).unwrap();
    bytes.extend_from_slice(&[0; 20]);
    std::fs::write(&las, &bytes).unwrap();
    let out = crease(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("part.las") && err.contains("changed") && !err.contains("panicked"), "{err}");
    std::fs::remove_file(&las).unwrap();
    let out = crease(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("part.las") && !err.contains("panicked"), "{err}");
    assert!(!dir.join("labels/part.laz").exists());
}

/// `crease status` lists a finished run's typed pieces by kind: those of curves.json, and the
/// same counts from curves.ply when the run wrote no curves.json.
#[test]
fn status_lists_the_typed_pieces_by_kind() {
    let d = tempfile::tempdir().unwrap();
    let (cube, dir) = (fixture("cube.las"), d.path().join("run"));
    extract(&[&cube], &dir, &["--format", "ply,json"]);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("curves.json")).unwrap()).unwrap();
    let count = |k: &str| v["pieces"].as_array().unwrap().iter().filter(|p| p["kind"] == k).count() as u64;
    let status = |dir: &Path| -> serde_json::Value { serde_json::from_slice(&crease(&["status", dir.to_str().unwrap(), "--json"]).stdout).unwrap() };
    let s = status(&dir);
    let p = &s["pieces"];
    assert_eq!(
        [&p["lines"], &p["arcs"], &p["circles"], &p["splines"], &p["polylines"]].map(|x| x.as_u64().unwrap()),
        ["line", "arc", "circle", "spline", "polyline"].map(count)
    );
    assert_eq!(p["curves"].as_u64(), Some(12));
    assert!(p["lines"].as_u64().unwrap() >= 12, "a cube's edges are lines: {p}");
    std::fs::remove_file(dir.join("curves.json")).unwrap();
    assert_eq!(&status(&dir)["pieces"], p);
    let text = String::from_utf8_lossy(&crease(&["status", dir.to_str().unwrap()]).stdout).into_owned();
    assert!(text.contains(&format!("pieces     {} lines", count("line"))), "{text}");
}

/// An ascii PLY (CRLF line ends) gets an ascii copy: each vertex line with its values as they
/// were and the three labels after them, the lines after the vertices as they were.
#[test]
fn an_ascii_ply_gets_its_lines_with_the_labels_after_them() {
    let d = tempfile::tempdir().unwrap();
    let cube: Vec<DVec3> = points_of(&mut las::Reader::from_path(fixture("cube.las")).unwrap()).iter().map(|p| DVec3::new(p.x, p.y, p.z)).collect();
    let (ply, dir) = (d.path().join("cube.ply"), d.path().join("run"));
    let head = format!("ply\r\nformat ascii 1.0\r\nelement vertex {}\r\nproperty double x\r\nproperty double y\r\nproperty double z\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n", cube.len());
    let lines: Vec<String> = cube.iter().map(|p| format!("{} {} {}", p.x, p.y, p.z)).collect();
    std::fs::write(&ply, format!("{head}{}\r\n3 0 1 2\r\n", lines.join("\r\n"))).unwrap();
    extract(&[&ply], &dir, &["--label-points", "--format", "ply,json"]);
    let out = std::fs::read_to_string(dir.join("labels/cube.ply")).unwrap();
    let (header, body) = out.split_once("end_header\r\n").unwrap();
    assert!(header.ends_with("property double z\r\nproperty double edge_distance\r\nproperty int curve_id\r\nproperty uchar edge\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\n"), "{header}");
    let got: Vec<&str> = body.split("\r\n").collect();
    assert_eq!(got.len(), cube.len() + 2);
    assert_eq!(&got[cube.len()..], ["3 0 1 2", ""]);
    let mut labels = vec![];
    for (line, want) in got.iter().zip(&lines) {
        let (values, rest) = line.split_at(want.len());
        assert_eq!(values, want);
        let l: Vec<&str> = rest.split_whitespace().collect();
        labels.push((l[0].parse().unwrap(), l[1].parse().unwrap(), l[2].parse().unwrap()));
    }
    let curves = read_ply(&dir.join("curves.ply")).unwrap();
    assert!(check_labels(&cube, &labels, &curves, tolerance(&dir)) > 100);
}
