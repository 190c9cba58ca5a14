//! DXF output for CAD tools: each curve a 3D polyline on layer `crease_curves`, in curve id
//! order, carrying the curve's attributes as extended data, and each corner a point on layer
//! `crease_corners`.
//!
//! The attributes are the GeoPackage's columns, as extended data of the application `CREASE`:
//! each a name (code 1000) followed by its value (1071 for the id, 1070 for `closed`, 1040 for
//! lengths, angles and the confidence, 1000 for text); an angle that is not known is left out.

use super::{Curves, Polyline};
use crate::crs::Crs;
use crate::error::{Error, Result};
use dxf::entities::{Entity, EntityType, ModelPoint, Polyline as DxfPolyline, Vertex as DxfVertex};
use dxf::tables::{AppId, Layer};
use dxf::{Drawing, Point, XData, XDataItem};
use std::path::Path;

const CURVES: &str = "crease_curves";
const CORNERS: &str = "crease_corners";
/// The registered application name of the curves' extended data.
pub const APP: &str = "CREASE";

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

/// Writes `curves` to `path` as DXF (AutoCAD 2000 format, which CAD tools and GDAL read).
pub fn write_dxf(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs) -> Result<()> {
    let mut d = Drawing::new();
    d.header.version = dxf::enums::AcadVersion::R2000;
    // (DXF has no CRS: its summary goes in the drawing's project name.)
    d.header.project_name = crs.summary();
    for (name, colour) in [(CURVES, 1), (CORNERS, 5)] {
        d.add_layer(Layer { name: name.into(), color: dxf::Color::from_index(colour), ..Default::default() });
    }
    d.add_app_id(AppId { name: APP.into(), ..Default::default() });
    let mut corners = std::collections::BTreeSet::new();
    // (The drawing is built whole, then saved: the dxf crate writes a drawing, not a stream.)
    curves.each(&mut |c| {
        let mut pl = DxfPolyline::default();
        pl.set_is_3d_polyline(true);
        pl.set_is_closed(c.closed);
        for v in &c.vertices {
            let mut vx = DxfVertex::new(Point::new(v.p.x, v.p.y, v.p.z));
            vx.set_is_3d_polyline_vertex(true);
            pl.add_vertex(&mut d, vx);
            if v.corner {
                corners.insert(v.p.to_array().map(f64::to_bits));
            }
        }
        let mut e = Entity::new(EntityType::Polyline(pl));
        e.common.layer = CURVES.into();
        e.common.x_data.push(attributes(c));
        d.add_entity(e);
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
