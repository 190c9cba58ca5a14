//! GeoJSON output: one `LineString` feature per curve, with 3D coordinates in the input's own
//! (usually projected) CRS. RFC 7946 assumes WGS 84; crease does not reproject, so it names the
//! CRS with the 2008 GeoJSON `crs` member (EPSG code, understood by GDAL/QGIS) and also keeps
//! the full WKT in a `crs_wkt` member when the input carries one, and the units in `crs_units`
//! (GDAL reads the `crs` member only: its name is the EPSG URN, or the WKT when there is no
//! code).
//!
//! Each feature also names what its curve is as typed pieces (see [`super::typed`]): its `kind`
//! and, for one arc or circle, its `radius`; the geometry stays the curve's own vertices, so
//! that a GIS reads every curve whatever its kind.

use super::typed;
use super::Curves;
use crate::error::{Error, Result};
use crate::points::Crs;
use serde_json::{json, Value};
use std::io::{BufWriter, Write};
use std::path::Path;

/// The CRS named when the input has none: a local engineering CRS of unknown unit. A GeoJSON
/// without a `crs` member is WGS 84 to GDAL and QGIS, which would put a part measured in
/// millimetres at longitude and latitude; this one they read as unknown and leave unplaced.
pub(crate) const UNKNOWN_CRS: &str = r#"LOCAL_CS["unknown",UNIT["unknown",1],AXIS["Easting",EAST],AXIS["Northing",NORTH]]"#;

/// Writes `curves` to `path` as a GeoJSON FeatureCollection (`tol`: the tolerance of the typed
/// pieces that name each curve's kind, see `typed::tolerance`).
pub fn write_geojson(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs, tol: f64) -> Result<()> {
    let f = std::fs::File::create(path).map_err(|e| Error::output(path, e))?;
    let mut w = BufWriter::new(f);
    let mut head = serde_json::Map::new();
    head.insert("type".into(), json!("FeatureCollection"));
    // GDAL reads the `crs` member's name as any CRS it accepts from a user: an EPSG URN, or a
    // WKT when the CRS has no code.
    let name = match (crs.epsg, &crs.wkt) {
        (Some(code), _) => Some(format!("urn:ogc:def:crs:EPSG::{code}")),
        (None, Some(wkt)) => Some(wkt.clone()),
        (None, None) => Some(UNKNOWN_CRS.to_string()),
    };
    if let Some(name) = name {
        head.insert("crs".into(), json!({"type": "name", "properties": {"name": name}}));
    }
    if let Some(wkt) = &crs.wkt {
        head.insert("crs_wkt".into(), json!(wkt));
    }
    if crs.horizontal_unit.is_some() || crs.vertical_unit.is_some() {
        head.insert("crs_units".into(), json!({"horizontal": crs.horizontal_unit, "vertical": crs.vertical_unit}));
    }
    // (The features are written one at a time, after the head: a tree of every coordinate
    // would take about 150 bytes a vertex, 250 MB for a 100 M-point scan's curves.)
    let head = serde_json::to_string(&Value::Object(head)).map_err(|e| Error::output(path, std::io::Error::from(e)))?;
    let io = |e: std::io::Error| Error::output(path, e);
    // (The head always has its type: it ends `"...}`, and the features go before the `}`.)
    w.write_all(&head.as_bytes()[..head.len() - 1]).map_err(io)?;
    w.write_all(b",\"features\":[").map_err(io)?;
    let mut k = 0;
    curves.each(&mut |c| {
        let mut coords: Vec<[f64; 3]> = c.vertices.iter().map(|v| v.p.to_array()).collect();
        if c.closed && !coords.is_empty() {
            coords.push(coords[0]);
        }
        let [start, end] = c.end_kinds();
        let (kind, radius) = typed::curve_kind(&typed::pieces(c, tol));
        // (Scalar properties only: Shapefile and FlatGeobuf drop or refuse lists.)
        let feature = json!({
            "type": "Feature",
            "properties": {
                "id": c.id, "closed": c.closed, "length": c.length(), "confidence": c.confidence,
                "angle": c.mean_dihedral_angle(), "shape": c.shape.name(), "start": start, "end": end, "corners": c.corner_list(),
                "kind": kind, "radius": radius,
            },
            "geometry": {"type": "LineString", "coordinates": coords},
        });
        if k > 0 {
            w.write_all(b",").map_err(io)?;
        }
        k += 1;
        serde_json::to_writer(&mut w, &feature).map_err(|e| io(std::io::Error::from(e)))
    })?;
    w.write_all(b"]}").and_then(|_| w.flush()).map_err(io)
}
