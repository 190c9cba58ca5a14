//! Typed curves (`--format json`): pieces that cover every curve, each within its tolerance of
//! the vertices it spans, of the right kind on shapes whose edges are known; the DXF draws
//! them as lines, arcs and circles, and the GeoJSON and GeoPackage name each curve's kind.

use crease::curves::read_obj;
use glam::DVec3;
use std::path::Path;
use std::process::Command;

/// Extracts `cloud` with `curves.json` (and the DXF, GeoJSON and GeoPackage) and returns the
/// pieces, the curves and the tolerance.
fn typed(cloud: &Path, out: &Path) -> (Vec<serde_json::Value>, Vec<crease::curves::Polyline>, f64) {
    let st = Command::new(env!("CARGO_BIN_EXE_crease"))
        .args(["extract", cloud.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q", "--format", "obj,json,dxf,geojson,gpkg"])
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
                    "spline" => {
                        let drawn = draw_spline(p);
                        assert!(drawn[0].distance(span[0]) < 1e-9 && drawn[drawn.len() - 1].distance(span[segs]) < 1e-9, "a spline through its ends");
                        drawn.windows(2).map(|w| segment_distance(*q, w[0], w[1])).fold(f64::INFINITY, f64::min)
                    }
                    _ => 0.0,
                };
                assert!(d <= tol * (1.0 + 1e-9), "a {} piece of curve {} misses a vertex by {d} (tolerance {tol})", p["kind"], c.id);
            }
        }
    }
}

fn segment_distance(q: DVec3, a: DVec3, b: DVec3) -> f64 {
    let t = ((q - a).dot(b - a) / (b - a).length_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
    q.distance(a + t * (b - a))
}

/// The point at `t` of the B-spline of `degree` with `knots` and `control` points, by de Boor's
/// algorithm (written here apart from the library's basis functions, as a check of what the
/// JSON says).
fn de_boor(degree: usize, knots: &[f64], control: &[DVec3], t: f64) -> DVec3 {
    let k = (degree..control.len()).rfind(|&k| knots[k] <= t).unwrap_or(degree);
    let mut d: Vec<DVec3> = (0..=degree).map(|j| control[j + k - degree]).collect();
    for r in 1..=degree {
        for j in (r..=degree).rev() {
            let (lo, hi) = (knots[j + k - degree], knots[j + 1 + k - r]);
            let a = if hi > lo { (t - lo) / (hi - lo) } else { 0.0 };
            d[j] = (1.0 - a) * d[j - 1] + a * d[j];
        }
    }
    d[degree]
}

/// A spline piece of `curves.json` drawn at 4,001 points from its start to its end.
fn draw_spline(p: &serde_json::Value) -> Vec<DVec3> {
    let degree = p["degree"].as_u64().unwrap() as usize;
    let knots: Vec<f64> = p["knots"].as_array().unwrap().iter().map(|k| k.as_f64().unwrap()).collect();
    let control: Vec<DVec3> = p["control_points"].as_array().unwrap().iter().map(point).collect();
    assert_eq!(knots.len(), control.len() + degree + 1);
    let (a, b) = (knots[degree], knots[control.len()]);
    (0..=4000).map(|i| de_boor(degree, &knots, &control, a + (b - a) * i as f64 / 4000.0)).collect()
}

/// A DXF entity's extended data item named `name` (the one after it).
fn x_value(e: &dxf::entities::Entity, name: &str) -> Option<dxf::XDataItem> {
    let x = e.common.x_data.iter().find(|x| x.application_name == "CREASE")?;
    let k = x.items.iter().position(|i| *i == dxf::XDataItem::Str(name.into()))?;
    x.items.get(k + 1).cloned()
}

/// The world point at `degrees` about an ARC's or a CIRCLE's OCS `centre`, of `radius`, for
/// the extrusion direction `normal`: DXF's arbitrary axis algorithm, as a CAD reader applies it.
fn ocs_point(centre: &dxf::Point, radius: f64, normal: &dxf::Vector, degrees: f64) -> DVec3 {
    let n = DVec3::new(normal.x, normal.y, normal.z).normalize();
    let x = if n.x.abs() < 1.0 / 64.0 && n.y.abs() < 1.0 / 64.0 { DVec3::Y.cross(n) } else { DVec3::Z.cross(n) }.normalize();
    let y = n.cross(x);
    let t = degrees.to_radians();
    centre.x * x + centre.y * y + centre.z * n + radius * (t.cos() * x + t.sin() * y)
}

/// `curves.dxf` draws every piece, in order, as the entity of its kind on that kind's layer,
/// at the piece's points and carrying its curve's id and its kind (and an arc's or a circle's
/// radius), and each corner as a point; returns the entities' types, by layer, and the corners.
fn check_dxf(out: &Path, pieces: &[serde_json::Value], curves: &[crease::curves::Polyline]) -> (Vec<(String, &'static str)>, Vec<DVec3>) {
    use dxf::entities::EntityType;
    let drawing = dxf::Drawing::load_file(out.join("curves.dxf")).unwrap();
    let (mut drawn, mut corners) = (vec![], vec![]);
    let mut pieces = pieces.iter();
    let at = |p: &dxf::Point| DVec3::new(p.x, p.y, p.z);
    for e in drawing.entities() {
        if let EntityType::ModelPoint(p) = &e.specific {
            assert_eq!(e.common.layer, "crease_corners");
            corners.push(at(&p.location));
            continue;
        }
        if matches!(e.specific, EntityType::Seqend(_)) {
            assert!(e.common.x_data.is_empty(), "extended data left on a SEQEND");
            continue;
        }
        let p = pieces.next().expect("no more entities than pieces");
        let kind = p["kind"].as_str().unwrap();
        let (start, end) = (point(&p["start"]), point(&p["end"]));
        let scale = start.length().max(end.length()).max(1.0);
        let near = |a: DVec3, b: DVec3| a.distance(b) <= 1e-9 * scale;
        assert_eq!(x_value(e, "id"), Some(dxf::XDataItem::Long(p["curve"].as_i64().unwrap() as i32)));
        assert_eq!(x_value(e, "kind"), Some(dxf::XDataItem::Str(kind.into())));
        let radius = match x_value(e, "radius") {
            Some(dxf::XDataItem::Real(r)) => Some(r),
            None => None,
            other => panic!("radius {other:?}"),
        };
        assert_eq!(radius.is_some(), kind == "arc" || kind == "circle", "{p}");
        let what = match &e.specific {
            EntityType::Line(l) => {
                assert!(kind == "line" && near(at(&l.p1), start) && near(at(&l.p2), end), "{l:?} for {p}");
                "LINE"
            }
            EntityType::Arc(a) => {
                let r = p["radius"].as_f64().unwrap();
                assert!(kind == "arc" && (a.radius - r).abs() <= 1e-9 * r && (radius.unwrap() - r).abs() <= 1e-9 * r, "{a:?} for {p}");
                let (s, t) = (ocs_point(&a.center, a.radius, &a.normal, a.start_angle), ocs_point(&a.center, a.radius, &a.normal, a.end_angle));
                assert!(near(s, start) && near(t, end), "arc from {s} to {t} for {p}");
                // Counterclockwise about the normal from start to end: it sweeps the piece's angle.
                let sweep = (a.end_angle - a.start_angle).rem_euclid(360.0);
                assert!((sweep - p["sweep_deg"].as_f64().unwrap()).abs() < 1e-6, "sweeps {sweep} for {p}");
                "ARC"
            }
            EntityType::Circle(c) => {
                let r = p["radius"].as_f64().unwrap();
                assert!(kind == "circle" && (c.radius - r).abs() <= 1e-9 * r, "{c:?} for {p}");
                assert!(near(ocs_point(&c.center, 0.0, &c.normal, 0.0), point(&p["centre"])), "{c:?} for {p}");
                // The circle goes through the curve's start vertex.
                let n = DVec3::new(c.normal.x, c.normal.y, c.normal.z).normalize();
                let d = start - ocs_point(&c.center, 0.0, &c.normal, 0.0);
                assert!(d.dot(n).abs() <= 1e-9 * scale && ((d - d.dot(n) * n).length() - c.radius).abs() <= 1e-9 * scale, "{c:?} for {p}");
                "CIRCLE"
            }
            EntityType::Spline(s) => {
                assert!(kind == "spline" && s.degree_of_curve as u64 == p["degree"].as_u64().unwrap(), "{p}");
                let knots: Vec<f64> = p["knots"].as_array().unwrap().iter().map(|k| k.as_f64().unwrap()).collect();
                assert!(s.knot_values.len() == knots.len() && s.knot_values.iter().zip(&knots).all(|(a, b)| (a - b).abs() <= 1e-12), "{p}");
                let control: Vec<DVec3> = p["control_points"].as_array().unwrap().iter().map(point).collect();
                assert!(s.control_points.len() == control.len() && s.control_points.iter().zip(&control).all(|(a, b)| near(at(a), *b)), "{p}");
                assert!(near(control[0], start) && near(control[control.len() - 1], end), "{p}");
                "SPLINE"
            }
            EntityType::Polyline(pl) => {
                assert!(kind == "polyline" && pl.is_3d_polyline(), "{p}");
                let curve = curves.iter().find(|c| c.id as u64 == p["curve"].as_u64().unwrap()).unwrap();
                let v: Vec<DVec3> = pl.vertices().map(|v| at(&v.location)).collect();
                let (first, segs, n) = (p["first"].as_u64().unwrap() as usize, p["segments"].as_u64().unwrap() as usize, curve.vertices.len());
                let span = if pl.is_closed() { n } else { segs + 1 };
                assert!(v.len() == span && (0..span).all(|k| near(v[k], curve.vertices[(first + k) % n].p)), "{p}");
                "POLYLINE"
            }
            other => panic!("{other:?} for {p}"),
        };
        drawn.push((e.common.layer.clone(), what));
    }
    assert!(pieces.next().is_none(), "every piece drawn");
    (drawn, corners)
}

/// The GeoJSON's and the GeoPackage's `kind` and `radius` of each curve, in order.
fn curve_kinds(out: &Path) -> [Vec<(String, Option<f64>)>; 2] {
    let g: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("curves.geojson")).unwrap()).unwrap();
    let geojson =
        g["features"].as_array().unwrap().iter().map(|f| (f["properties"]["kind"].as_str().unwrap().to_string(), f["properties"]["radius"].as_f64())).collect();
    let db = rusqlite::Connection::open(out.join("curves.gpkg")).unwrap();
    let gpkg = db
        .prepare("SELECT kind, radius FROM curves ORDER BY fid")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    [geojson, gpkg]
}

/// What a curve's kind and radius are from its pieces in `curves.json`.
fn kind_from_pieces(pieces: &[serde_json::Value], id: u32) -> (String, Option<f64>) {
    let own: Vec<&serde_json::Value> = pieces.iter().filter(|p| p["curve"].as_u64() == Some(id as u64)).collect();
    let kinds: std::collections::BTreeSet<&str> = own.iter().map(|p| p["kind"].as_str().unwrap()).collect();
    match (kinds.len(), own.len()) {
        (0, _) => ("polyline".into(), None),
        (1, 1) => (own[0]["kind"].as_str().unwrap().into(), own[0]["radius"].as_f64()),
        (1, _) => (own[0]["kind"].as_str().unwrap().into(), None),
        _ => ("mixed".into(), None),
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
    // The DXF draws them as twelve LINEs and the eight corners as POINTs; the GeoJSON and the
    // GeoPackage call each curve a line.
    let (drawn, corners) = check_dxf(d.path(), &pieces, &curves);
    assert_eq!(drawn, vec![("crease_lines".to_string(), "LINE"); 12]);
    assert_eq!(corners.len(), 8);
    assert!(corners.iter().all(|c| ends.iter().any(|e| e.distance(*c) < 1e-9)), "{corners:?}");
    for kinds in curve_kinds(d.path()) {
        assert_eq!(kinds, vec![("line".to_string(), None); 12]);
    }
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
    // The DXF draws them as twelve LINEs and two CIRCLEs; the GeoJSON and the GeoPackage call
    // twelve curves lines and two circles of the bore's radius.
    let (drawn, corners) = check_dxf(d.path(), &pieces, &curves);
    let count = |layer: &str, what: &str| drawn.iter().filter(|(l, w)| l == layer && *w == what).count();
    assert_eq!((count("crease_lines", "LINE"), count("crease_circles", "CIRCLE"), drawn.len(), corners.len()), (12, 2, 14, 8), "{drawn:?}");
    for kinds in curve_kinds(d.path()) {
        assert_eq!(kinds.len(), curves.len());
        assert_eq!(kinds.iter().filter(|(k, r)| k == "line" && r.is_none()).count(), 12, "{kinds:?}");
        let circles: Vec<f64> = kinds.iter().filter(|(k, _)| k == "circle").map(|(_, r)| r.unwrap()).collect();
        assert_eq!(circles.len(), 2, "{kinds:?}");
        assert!(circles.iter().all(|r| (r - 0.25).abs() < 0.0025), "{circles:?}");
    }
}

#[test]
fn the_fandisks_arcs_read_back_from_the_dxf_to_their_pieces_ends() {
    let d = tempfile::tempdir().unwrap();
    let (pieces, curves, _) = typed(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/fandisk.las"), d.path());
    let (drawn, _) = check_dxf(d.path(), &pieces, &curves);
    assert!(drawn.iter().any(|(l, w)| l == "crease_arcs" && *w == "ARC"), "the fandisk's rounded creases give arcs: {drawn:?}");
    // Each curve's kind and radius in the GeoJSON and the GeoPackage are its pieces'.
    let expected: Vec<(String, Option<f64>)> = curves.iter().map(|c| kind_from_pieces(&pieces, c.id)).collect();
    assert!(expected.iter().any(|(k, _)| k == "mixed"), "{expected:?}");
    for kinds in curve_kinds(d.path()) {
        assert_eq!(kinds.len(), expected.len());
        for (got, want) in kinds.iter().zip(&expected) {
            assert_eq!(got.0, want.0);
            assert_eq!(got.1.is_some(), want.1.is_some(), "{got:?} {want:?}");
            if let (Some(a), Some(b)) = (got.1, want.1) {
                assert!((a - b).abs() <= 1e-9 * b, "{got:?} {want:?}");
            }
        }
    }
}

/// Under noise, runs of the fandisk that no line or arc holds are cubic splines: within the
/// tolerance of every vertex they replace, through their ends, drawn in the DXF as SPLINEs of
/// the same knots and control points on their own layer.
#[test]
fn a_noisy_fandisks_free_runs_are_splines_in_the_dxf() {
    let d = tempfile::tempdir().unwrap();
    let cloud = d.path().join("fandisk.las");
    let st = Command::new(env!("CARGO_BIN_EXE_crease"))
        .args(["synth", "shape", "fandisk", "-n", "200000", "--noise", "0.005", "-o", cloud.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(st.status.success());
    let out = d.path().join("run");
    let (pieces, curves, tol) = typed(&cloud, &out);
    check_cover(&pieces, &curves, tol);
    assert!(pieces.iter().any(|p| p["kind"] == "spline"), "{pieces:?}");
    let (drawn, _) = check_dxf(&out, &pieces, &curves);
    assert!(drawn.iter().any(|(l, w)| l == "crease_splines" && *w == "SPLINE"), "{drawn:?}");
}
