//! DXF output for CAD tools: each curve as its typed pieces (see [`super::typed`]), the entity
//! a CAD user draws and snaps to: a LINE on layer `crease_lines`, an ARC on `crease_arcs`, a
//! CIRCLE on `crease_circles`, a run that no line or arc fits a cubic SPLINE on
//! `crease_splines` (its knots and control points, clamped), and a run no spline holds either
//! a 3D POLYLINE on `crease_curves`. Pieces come in curve id
//! order, each curve's in order along it; each corner is a POINT on layer `crease_corners`.
//!
//! The curves' plain polylines are not written besides: each edge would be drawn twice, and a
//! CAD user would snap to either. They stay in the OBJ, PLY, GeoJSON and GeoPackage outputs.
//!
//! An arc or a circle lies in the plane normal to its axis, which is the entity's extrusion
//! direction (group 210); its centre is given in its Object Coordinate System, found from that
//! direction by DXF's arbitrary axis algorithm, and an arc runs counterclockwise about it from
//! its start angle to its end angle (degrees, in that system), from the piece's start to its end.
//!
//! Each entity carries its curve's attributes (the GeoPackage's columns) as extended data of
//! the application `CREASE`: each a name (code 1000) followed by its value (1071 for the id,
//! 1070 for `closed`, 1040 for lengths, angles, the confidence and the radius, 1000 for text);
//! an angle that is not known is left out. Then the piece's `kind` (`line`, `arc`, `circle`,
//! `spline` or `polyline`) and, for an arc or a circle, its `radius`.

use super::typed::{self, Kind, Piece};
use super::{Curves, Polyline};
use crate::crs::Crs;
use crate::error::{Error, Result};
use dxf::entities::{Arc, Circle, Entity, EntityType, Line, ModelPoint, Polyline as DxfPolyline, Spline as DxfSpline, Vertex as DxfVertex};
use dxf::tables::{AppId, Layer};
use dxf::{Drawing, Point, Vector, XData, XDataItem};
use glam::DVec3;
use std::path::Path;

const LINES: &str = "crease_lines";
const ARCS: &str = "crease_arcs";
const CIRCLES: &str = "crease_circles";
const SPLINES: &str = "crease_splines";
const CURVES: &str = "crease_curves";
const CORNERS: &str = "crease_corners";
/// The registered application name of the curves' extended data.
pub(super) const APP: &str = "CREASE";

/// A curve's attributes as extended data: name, value, name, value, ...
fn attributes(c: &Polyline) -> XData {
    let name = |n: &str| XDataItem::Str(n.into());
    let [start, end] = c.end_kinds();
    let mut items = vec![name("id"), XDataItem::Long(c.id as i32), name("closed"), XDataItem::Integer(c.closed as i16)];
    items.extend([name("length"), XDataItem::Real(c.length()), name("confidence"), XDataItem::Real(c.confidence as f64)]);
    if let Some(a) = c.mean_dihedral_angle() {
        items.extend([name("angle"), XDataItem::Real(a)]);
    }
    items.extend([name("shape"), name(c.shape.name()), name("start"), name(start), name("end"), name(end), name("corners"), name(&c.corner_list())]);
    XData { application_name: APP.into(), items }
}

/// The x and y axes of the Object Coordinate System of an entity whose extrusion direction is
/// the unit vector `n` (DXF's arbitrary axis algorithm); its z axis is `n`.
fn ocs_axes(n: DVec3) -> (DVec3, DVec3) {
    let near_z = n.x.abs() < 1.0 / 64.0 && n.y.abs() < 1.0 / 64.0;
    let x = if near_z { DVec3::Y.cross(n) } else { DVec3::Z.cross(n) }.normalize();
    (x, n.cross(x))
}

/// `v` as the file holds it: the `dxf` crate writes reals to 12 decimals.
fn as_written(v: DVec3) -> DVec3 {
    v.to_array().map(|x| format!("{x:.12}").parse().unwrap_or(x)).into()
}

/// An arc's or a circle's extrusion direction (as written), the unit normal a reader takes
/// from it, and the centre in the Object Coordinate System that normal spans.
fn plane(centre: DVec3, axis: DVec3) -> (Vector, DVec3, Point) {
    // (The normal is taken as the file will hold it, so that a reader's coordinate system is
    // the writer's: one a rounding off turns about the origin, and far from it, as georeferenced
    // coordinates are, moves the centre by more than the coordinates' own rounding.)
    let written = as_written(axis);
    let n = written.normalize();
    let (x, y) = ocs_axes(n);
    (Vector::new(written.x, written.y, written.z), n, Point::new(centre.dot(x), centre.dot(y), centre.dot(n)))
}

/// Angle of `p` about `centre` in the Object Coordinate System of normal `n`, in degrees in
/// [0, 360).
fn ocs_angle(p: DVec3, centre: DVec3, n: DVec3) -> f64 {
    let (x, y) = ocs_axes(n);
    let d = p - centre;
    d.dot(y).atan2(d.dot(x)).to_degrees().rem_euclid(360.0)
}

/// The DXF entity of piece `p` of curve `c` and its layer; None for an arc or a circle
/// without its centre, axis and radius, or a spline without its knots (which
/// [`typed::pieces`] always gives them).
fn entity(c: &Polyline, p: &Piece, d: &mut Drawing) -> Option<(EntityType, &'static str)> {
    let point = |v: DVec3| Point::new(v.x, v.y, v.z);
    Some(match p.kind {
        Kind::Line => (EntityType::Line(Line::new(point(p.start), point(p.end))), LINES),
        Kind::Arc => {
            let (centre, axis, radius) = (p.centre?, p.axis?, p.radius?);
            let (normal, n, center) = plane(centre, axis);
            let (start_angle, end_angle) = (ocs_angle(p.start, centre, n), ocs_angle(p.end, centre, n));
            (EntityType::Arc(Arc { center, radius, normal, start_angle, end_angle, ..Default::default() }), ARCS)
        }
        Kind::Circle => {
            let (normal, _, center) = plane(p.centre?, p.axis?);
            (EntityType::Circle(Circle { center, radius: p.radius?, normal, ..Default::default() }), CIRCLES)
        }
        Kind::Spline => {
            let s = p.spline.as_ref()?;
            let spline = DxfSpline {
                degree_of_curve: s.degree as i32,
                knot_values: s.knots.clone(),
                control_points: s.control_points.iter().map(|&v| point(v)).collect(),
                ..Default::default()
            };
            (EntityType::Spline(spline), SPLINES)
        }
        Kind::Polyline => {
            let n = c.vertices.len();
            // (A piece that is the whole of a closed curve is written closed, its start once.)
            let whole = c.closed && p.segments == n;
            let mut pl = DxfPolyline::default();
            pl.set_is_3d_polyline(true);
            pl.set_is_closed(whole);
            for k in 0..if whole { n } else { p.segments + 1 } {
                let mut vx = DxfVertex::new(point(c.vertices[(p.first + k) % n].p));
                vx.set_is_3d_polyline_vertex(true);
                pl.add_vertex(d, vx);
            }
            (EntityType::Polyline(pl), CURVES)
        }
    })
}

/// Writes `curves` to `path` as DXF (AutoCAD 2000 format, which CAD tools and GDAL read), each
/// as its typed pieces within `tol` (see `typed::tolerance`).
pub fn write_dxf(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs, tol: f64) -> Result<()> {
    let mut d = Drawing::new();
    d.header.version = dxf::enums::AcadVersion::R2000;
    // (DXF has no CRS: its summary goes in the drawing's project name.)
    d.header.project_name = crs.summary();
    // (The crate stamps a drawing with the time it was made and random GUIDs; fixed ones keep the
    // same curves the same bytes, run after run and on resume.)
    let epoch = chrono::NaiveDate::from_ymd_opt(2000, 1, 1).and_then(|d| d.and_hms_opt(0, 0, 0)).expect("a valid date");
    let utc = epoch.and_utc();
    // (The local dates are written as their wall-clock time: the same in any time zone.)
    let local = chrono::TimeZone::from_local_datetime(&chrono::Local, &epoch).earliest().unwrap_or_else(|| utc.with_timezone(&chrono::Local));
    (d.header.creation_date, d.header.update_date) = (local, local);
    (d.header.creation_date_universal, d.header.update_date_universal) = (utc, utc);
    (d.header.fingerprint_guid, d.header.version_guid) = (uuid::Uuid::nil(), uuid::Uuid::nil());
    for (name, colour) in [(LINES, 7), (ARCS, 3), (CIRCLES, 4), (SPLINES, 6), (CURVES, 1), (CORNERS, 5)] {
        d.add_layer(Layer { name: name.into(), color: dxf::Color::from_index(colour), ..Default::default() });
    }
    d.add_app_id(AppId { name: APP.into(), ..Default::default() });
    let mut corners = std::collections::BTreeSet::new();
    // (The drawing is built whole, then saved: the dxf crate writes a drawing, not a stream.)
    curves.each(&mut |c| {
        let own = attributes(c);
        for p in typed::pieces(c, tol) {
            let Some((specific, layer)) = entity(c, &p, &mut d) else { continue };
            let mut x = own.clone();
            x.items.extend([XDataItem::Str("kind".into()), XDataItem::Str(p.kind.name().into())]);
            if let Some(r) = p.radius {
                x.items.extend([XDataItem::Str("radius".into()), XDataItem::Real(r)]);
            }
            let mut e = Entity::new(specific);
            e.common.layer = layer.into();
            e.common.x_data.push(x);
            d.add_entity(e);
        }
        corners.extend(c.vertices.iter().filter(|v| v.corner).map(|v| v.p.to_array().map(f64::to_bits)));
        Ok(())
    })?;
    for p in corners {
        let [x, y, z] = p.map(f64::from_bits);
        let mut e = Entity::new(EntityType::ModelPoint(ModelPoint::new(Point::new(x, y, z))));
        e.common.layer = CORNERS.into();
        d.add_entity(e);
    }
    let failed = |e: dxf::DxfError| Error::output(path, std::io::Error::other(e.to_string()));
    let mut text = vec![];
    d.save(&mut text).map_err(failed)?;
    let text = String::from_utf8(text).map_err(|e| Error::output(path, std::io::Error::other(e.to_string())))?;
    std::fs::write(path, extended_data_to_polylines(&text)).map_err(|e| Error::output(path, e))
}

/// Moves each polyline's extended data (codes 1000 and up) from its SEQEND back into the
/// polyline, before its first vertex. The `dxf` crate writes an entity's extended data after
/// everything else it writes for it, which for a polyline is after its vertices and SEQEND,
/// where readers (the crate's own, GDAL, CAD tools) take it for the SEQEND's.
fn extended_data_to_polylines(text: &str) -> String {
    // (ASCII DXF is a list of pairs of lines: a group code, then its value.)
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let pairs: Vec<(i32, &[&str])> = lines.chunks(2).map(|p| (p[0].trim().parse().unwrap_or(-1), p)).collect();
    let is = |k: usize, name: &str| pairs[k].0 == 0 && pairs[k].1.get(1).is_some_and(|v| v.trim() == name);
    let mut out = String::with_capacity(text.len());
    let mut k = 0;
    while k < pairs.len() {
        if !is(k, "POLYLINE") {
            out.extend(pairs[k].1.iter().copied());
            k += 1;
            continue;
        }
        // The polyline's own pairs, its vertices, the SEQEND's pairs, and what follows them.
        let vertices = (k + 1..pairs.len()).find(|&j| pairs[j].0 == 0).unwrap_or(pairs.len());
        let seqend = (vertices..pairs.len()).find(|&j| is(j, "SEQEND")).unwrap_or(pairs.len());
        let next = (seqend + 1..pairs.len()).find(|&j| pairs[j].0 == 0).unwrap_or(pairs.len());
        let (xdata, own): (Vec<_>, Vec<_>) = pairs[seqend.min(next)..next].iter().partition(|p| p.0 >= 1000);
        for p in pairs[k..vertices].iter().chain(&xdata).chain(&pairs[vertices..seqend]).chain(&own) {
            out.extend(p.1.iter().copied());
        }
        k = next;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// The extended data item named `name` (the one after it).
    fn value(e: &Entity, name: &str) -> Option<XDataItem> {
        let x = e.common.x_data.first()?;
        let k = x.items.iter().position(|i| *i == XDataItem::Str(name.into()))?;
        x.items.get(k + 1).cloned()
    }

    /// The world point at `degrees` on the circle of an ARC's or a CIRCLE's OCS `centre`,
    /// `radius` and extrusion `normal`, as a reader reconstructs it.
    fn world(centre: &Point, radius: f64, normal: &Vector, degrees: f64) -> DVec3 {
        let n = DVec3::new(normal.x, normal.y, normal.z).normalize();
        let (x, y) = ocs_axes(n);
        let o = centre.x * x + centre.y * y + centre.z * n;
        let t = degrees.to_radians();
        o + radius * (t.cos() * x + t.sin() * y)
    }

    fn load(path: &Path) -> Drawing {
        Drawing::load_file(path).unwrap()
    }

    #[test]
    fn the_arbitrary_axis_algorithm_gives_the_documented_systems() {
        // Along z the OCS is the WCS; along -z its x axis is the WCS's -x; along x its axes are
        // the WCS's y and z.
        assert_eq!(ocs_axes(DVec3::Z), (DVec3::X, DVec3::Y));
        assert_eq!(ocs_axes(-DVec3::Z), (-DVec3::X, DVec3::Y));
        assert_eq!(ocs_axes(DVec3::X), (DVec3::Y, DVec3::Z));
        // Either side of the 1/64 threshold the system is right-handed and orthonormal.
        for n in [DVec3::new(0.015, 0.0, 1.0), DVec3::new(0.016, 0.0, 1.0), DVec3::new(-0.3, 0.5, -0.2)] {
            let n = n.normalize();
            let (x, y) = ocs_axes(n);
            assert!((x.cross(y) - n).length() < 1e-15 && x.dot(n).abs() < 1e-15 && (x.length() - 1.0).abs() < 1e-15);
        }
    }

    #[test]
    fn arcs_and_circles_read_back_through_their_ocs_to_the_pieces_points() {
        // Arcs and circles about axes up, down, along x, just inside and outside the
        // algorithm's 1/64 threshold and tilted, some far from the origin as georeferenced
        // coordinates are.
        let axes = [DVec3::Z, -DVec3::Z, DVec3::X, DVec3::new(0.01, -0.005, 1.0), DVec3::new(0.02, 0.0, -1.0), DVec3::new(1.0, -2.0, 0.7)];
        let centres = [DVec3::new(1.5, -0.25, 2.0), DVec3::new(512_345.6, 5_412_345.7, 312.5)];
        let mut curves = Vec::new();
        for (k, (&axis, &centre)) in axes.iter().flat_map(|a| centres.iter().map(move |c| (a, c))).enumerate() {
            let axis = axis.normalize();
            let (u, v) = ocs_axes(axis);
            let r = 0.75 + 0.1 * k as f64;
            let at = |t: f64| centre + r * (t.cos() * u + t.sin() * v);
            // An arc from 200 degrees through 0 to 100 (turning counterclockwise about the
            // axis), and a whole circle.
            let from = 200f64.to_radians();
            curves.push(Polyline::from_points(2 * k as u32, (0..=40).map(|j| at(from + j as f64 / 40.0 * 260f64.to_radians()))));
            let mut circle = Polyline::from_points(2 * k as u32 + 1, (0..48).map(|j| at(j as f64 * TAU / 48.0)));
            circle.closed = true;
            curves.push(circle);
        }
        let tol = 1e-6;
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("c.dxf");
        write_dxf(&path, &curves, &Crs::default(), tol).unwrap();
        let drawing = load(&path);
        let entities: Vec<&Entity> = drawing.entities().collect();
        assert_eq!(entities.len(), curves.len());
        for (c, e) in curves.iter().zip(&entities) {
            let pieces = typed::pieces(c, tol);
            assert_eq!(pieces.len(), 1, "curve {}: {pieces:?}", c.id);
            let p = &pieces[0];
            let scale = p.centre.unwrap().length().max(1.0);
            // (Also within a micrometre far from the origin, where a reader's normal rounded
            // apart from the writer's would turn the centre off by more.)
            let near = |a: DVec3, b: DVec3| a.distance(b) <= 1e-9 * scale && a.distance(b) <= 1e-6;
            assert_eq!(value(e, "id"), Some(XDataItem::Long(c.id as i32)));
            // (Reals are written to 12 decimals.)
            let Some(XDataItem::Real(radius)) = value(e, "radius") else { panic!("curve {}: no radius", c.id) };
            assert!((radius - p.radius.unwrap()).abs() <= 1e-12 * scale);
            match &e.specific {
                EntityType::Arc(a) => {
                    assert_eq!((p.kind, e.common.layer.as_str()), (Kind::Arc, ARCS));
                    assert_eq!(value(e, "kind"), Some(XDataItem::Str("arc".into())));
                    let (s, t) = (world(&a.center, a.radius, &a.normal, a.start_angle), world(&a.center, a.radius, &a.normal, a.end_angle));
                    assert!(near(s, p.start) && near(t, p.end), "curve {}: arc from {s} to {t}, piece from {} to {}", c.id, p.start, p.end);
                    // Counterclockwise about the normal from start to end, the way the curve
                    // goes: the middle of the arc is the curve's middle vertex.
                    let sweep = (a.end_angle - a.start_angle).rem_euclid(360.0);
                    assert!((sweep - 260.0).abs() < 1e-6, "curve {}: sweeps {sweep}", c.id);
                    let mid = world(&a.center, a.radius, &a.normal, a.start_angle + sweep / 2.0);
                    assert!(near(mid, c.vertices[20].p), "curve {}: arc's middle {mid}, curve's {}", c.id, c.vertices[20].p);
                }
                EntityType::Circle(o) => {
                    assert_eq!((p.kind, e.common.layer.as_str()), (Kind::Circle, CIRCLES));
                    let centre = world(&o.center, 0.0, &o.normal, 0.0);
                    assert!(near(centre, p.centre.unwrap()) && (o.radius - p.radius.unwrap()).abs() <= 1e-12 * scale);
                    for v in &c.vertices {
                        let q = v.p - centre;
                        let n = DVec3::new(o.normal.x, o.normal.y, o.normal.z).normalize();
                        assert!(q.dot(n).abs() <= 1e-9 * scale && ((q - q.dot(n) * n).length() - o.radius).abs() <= 1e-9 * scale);
                    }
                }
                other => panic!("curve {}: {other:?}", c.id),
            }
        }
    }

    #[test]
    fn lines_corners_and_untyped_runs_keep_their_layers_and_attributes() {
        // A line and a zigzag meeting at a corner: a LINE, a 3D POLYLINE (with its extended
        // data on it, not on its SEQEND) and a POINT.
        let mut pl = Polyline::from_points(3, (0..=10).map(|k| DVec3::new(k as f64, 0.0, 0.0)));
        pl.vertices.extend((1..=8).map(|k| crate::curves::Vertex::at(DVec3::new(10.0 + k as f64, if k % 2 == 1 { 1.0 } else { 0.0 }, 0.5 * k as f64))));
        pl.vertices[10].corner = true;
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("c.dxf");
        write_dxf(&path, &[pl.clone()], &Crs::default(), 0.01).unwrap();
        let drawing = load(&path);
        let mut seen = Vec::new();
        for e in drawing.entities() {
            match &e.specific {
                EntityType::Line(l) => {
                    assert_eq!((&l.p1, &l.p2), (&Point::new(0.0, 0.0, 0.0), &Point::new(10.0, 0.0, 0.0)));
                    assert_eq!(value(e, "kind"), Some(XDataItem::Str("line".into())));
                    assert_eq!(value(e, "radius"), None);
                }
                EntityType::Polyline(p) => {
                    assert!(p.is_3d_polyline() && !p.is_closed());
                    let v: Vec<DVec3> = p.vertices().map(|v| DVec3::new(v.location.x, v.location.y, v.location.z)).collect();
                    assert_eq!(v, pl.vertices[10..].iter().map(|v| v.p).collect::<Vec<_>>());
                    assert_eq!(value(e, "kind"), Some(XDataItem::Str("polyline".into())));
                }
                EntityType::Seqend(_) => assert!(e.common.x_data.is_empty(), "extended data left on a SEQEND"),
                EntityType::ModelPoint(p) => assert_eq!(p.location, Point::new(10.0, 0.0, 0.0)),
                other => panic!("{other:?}"),
            }
            if !matches!(e.specific, EntityType::Seqend(_)) {
                assert_eq!(value(e, "id"), if e.common.layer == CORNERS { None } else { Some(XDataItem::Long(3)) });
                seen.push(e.common.layer.clone());
            }
        }
        assert_eq!(seen, [LINES, CURVES, CORNERS]);
        // The same curves written again, a moment later, are the same bytes.
        std::thread::sleep(std::time::Duration::from_millis(20));
        let again = d.path().join("again.dxf");
        write_dxf(&again, &[pl], &Crs::default(), 0.01).unwrap();
        assert!(std::fs::read(&path).unwrap() == std::fs::read(&again).unwrap(), "two writes of the same curves differ");
    }

    #[test]
    fn a_free_form_run_is_a_spline_of_its_pieces_knots_and_control_points() {
        // A line, a corner, then a twisted cubic: a LINE and a SPLINE that pass through the corner.
        let mut pl = Polyline::from_points(4, (0..=10).map(|k| DVec3::new(k as f64 / 10.0 - 1.0, 0.0, 0.0)));
        pl.vertices.extend((1..=200).map(|k| k as f64 / 200.0).map(|x| crate::curves::Vertex::at(DVec3::new(x, x * x * x, 0.5 * x * x))));
        pl.vertices[10].corner = true;
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("c.dxf");
        write_dxf(&path, &[pl.clone()], &Crs::default(), 1e-3).unwrap();
        let pieces = typed::pieces(&pl, 1e-3);
        let s = pieces[1].spline.as_ref().expect("a spline piece");
        let splines: Vec<_> = load(&path)
            .entities()
            .filter_map(|e| match &e.specific {
                EntityType::Spline(sp) => Some((sp.clone(), e.common.layer.clone(), value(e, "kind"))),
                _ => None,
            })
            .collect();
        assert_eq!(splines.len(), 1);
        let (sp, layer, kind) = &splines[0];
        assert_eq!((layer.as_str(), kind), (SPLINES, &Some(XDataItem::Str("spline".into()))));
        assert_eq!(sp.degree_of_curve, 3);
        assert_eq!(sp.knot_values.len(), s.knots.len());
        assert!(sp.knot_values.iter().zip(&s.knots).all(|(a, b)| (a - b).abs() < 1e-12));
        let cp: Vec<DVec3> = sp.control_points.iter().map(|p| DVec3::new(p.x, p.y, p.z)).collect();
        assert_eq!(cp.len(), s.control_points.len());
        assert!(cp.iter().zip(&s.control_points).all(|(a, b)| a.distance(*b) < 1e-12));
        assert_eq!((cp[0], cp[cp.len() - 1]), (DVec3::ZERO, DVec3::new(1.0, 1.0, 0.5)));
    }
}
