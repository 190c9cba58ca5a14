//! DXF output for CAD tools: each curve a 3D polyline on layer `crease_curves`, in curve id
//! order, and each corner a point on layer `crease_corners`.
//!
//! The curves' attributes are not written: the `dxf` crate writes an entity's extended data
//! after all its code pairs, which for a polyline is after its vertices and SEQEND, where
//! readers (the crate's own included) attach it to the SEQEND. The GeoPackage and GeoJSON
//! carry them, for the curves in the same order.

use super::Polyline;
use crate::crs::Crs;
use crate::error::{Error, Result};
use dxf::entities::{Entity, EntityType, ModelPoint, Polyline as DxfPolyline, Vertex as DxfVertex};
use dxf::tables::Layer;
use dxf::{Drawing, Point};
use std::path::Path;

const CURVES: &str = "crease_curves";
const CORNERS: &str = "crease_corners";

/// Writes `curves` to `path` as DXF (AutoCAD 2000 format, which CAD tools and GDAL read).
pub fn write_dxf(path: &Path, curves: &[Polyline], crs: &Crs) -> Result<()> {
    let mut d = Drawing::new();
    d.header.version = dxf::enums::AcadVersion::R2000;
    // (DXF has no CRS: its summary goes in the drawing's project name.)
    d.header.project_name = crs.summary();
    for (name, colour) in [(CURVES, 1), (CORNERS, 5)] {
        d.add_layer(Layer { name: name.into(), color: dxf::Color::from_index(colour), ..Default::default() });
    }
    let mut corners = std::collections::BTreeSet::new();
    for c in curves {
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
        d.add_entity(e);
    }
    for p in corners {
        let [x, y, z] = p.map(f64::from_bits);
        let mut e = Entity::new(EntityType::ModelPoint(ModelPoint::new(Point::new(x, y, z))));
        e.common.layer = CORNERS.into();
        d.add_entity(e);
    }
    d.save_file(path).map_err(|e| Error::output(path, std::io::Error::other(e.to_string())))
}
