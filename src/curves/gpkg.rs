//! GeoPackage 1.3 output (OGC 12-128r18): one `curves` feature table of LineString Z geometries
//! with the per-curve attributes as columns, and the CRS in the spatial reference table, so
//! GIS tools place the curves without a sidecar. Written with SQLite (rusqlite, bundled). Its
//! `kind` and `radius` columns say what each curve is as typed pieces (see [`super::typed`]);
//! the geometry stays the curve's own vertices.

use super::{typed, Curves, Polyline};
use crate::crs::Crs;
use crate::error::{Error, Result};
use rusqlite::{params, Connection};
use std::path::Path;

/// The SRS id of the curves' CRS in the file (EPSG code where there is one).
fn srs_id(crs: &Crs) -> i64 {
    match (crs.epsg, &crs.wkt) {
        (Some(code), _) => code as i64,
        (None, Some(_)) => 100_000,
        // (GeoPackage's own "undefined Cartesian" system.)
        (None, None) => -1,
    }
}

/// A GeoPackage geometry: the "GP" header with the SRS id and an xyz envelope, then the
/// LineString Z as little-endian WKB.
fn geometry(c: &Polyline, srs: i64) -> Vec<u8> {
    let mut pts: Vec<[f64; 3]> = c.vertices.iter().map(|v| v.p.to_array()).collect();
    if c.closed && !pts.is_empty() {
        pts.push(pts[0]);
    }
    let mut g = Vec::with_capacity(8 + 48 + 9 + 24 * pts.len());
    // Version 0; flags: little-endian (bit 0), envelope xyz (code 2 in bits 1-3).
    g.extend_from_slice(&[b'G', b'P', 0, 0b0000_0101]);
    g.extend_from_slice(&(srs as i32).to_le_bytes());
    for axis in 0..3 {
        let lo = pts.iter().map(|p| p[axis]).fold(f64::INFINITY, f64::min);
        let hi = pts.iter().map(|p| p[axis]).fold(f64::NEG_INFINITY, f64::max);
        g.extend_from_slice(&lo.to_le_bytes());
        g.extend_from_slice(&hi.to_le_bytes());
    }
    g.push(1);
    g.extend_from_slice(&1002u32.to_le_bytes()); // LineString Z
    g.extend_from_slice(&(pts.len() as u32).to_le_bytes());
    for p in &pts {
        for x in p {
            g.extend_from_slice(&x.to_le_bytes());
        }
    }
    g
}

/// Writes `curves` to `path` as a GeoPackage (replacing any file there; `tol`: the tolerance of
/// the typed pieces that name each curve's kind, see `typed::tolerance`).
pub fn write_gpkg(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs, tol: f64) -> Result<()> {
    let _ = std::fs::remove_file(path);
    let out = |e: rusqlite::Error| Error::output(path, std::io::Error::other(e.to_string()));
    let mut db = Connection::open(path).map_err(out)?;
    let srs = srs_id(crs);
    let tx = db.transaction().map_err(out)?;
    tx.execute_batch(
        "PRAGMA application_id = 1196444487; PRAGMA user_version = 10300;
         CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY, organization TEXT NOT NULL,
           organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);
         CREATE TABLE gpkg_contents (table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT UNIQUE,
           description TEXT DEFAULT '', last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
           min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER REFERENCES gpkg_spatial_ref_sys(srs_id));
         CREATE TABLE gpkg_geometry_columns (table_name TEXT NOT NULL, column_name TEXT NOT NULL, geometry_type_name TEXT NOT NULL,
           srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL, CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name));
         INSERT INTO gpkg_spatial_ref_sys VALUES ('Undefined cartesian SRS', -1, 'NONE', -1, 'undefined', 'undefined cartesian coordinate reference system');
         INSERT INTO gpkg_spatial_ref_sys VALUES ('Undefined geographic SRS', 0, 'NONE', 0, 'undefined', 'undefined geographic coordinate reference system');
         CREATE TABLE curves (fid INTEGER PRIMARY KEY AUTOINCREMENT, geom LINESTRINGZ, id INTEGER, closed BOOLEAN, length DOUBLE,
           confidence DOUBLE, angle DOUBLE, shape TEXT, start TEXT, \"end\" TEXT, corners TEXT,
           kind TEXT, radius DOUBLE);",
    )
    .map_err(out)?;
    if srs > 0 {
        // (Without a WKT, the definition names the code; GDAL resolves it from its database.)
        let definition = crs.wkt.clone().unwrap_or_else(|| "undefined".into());
        let (org, code) = match crs.epsg {
            Some(c) => ("EPSG", c as i64),
            None => ("NONE", srs),
        };
        let name = crs.summary();
        tx.execute("INSERT INTO gpkg_spatial_ref_sys VALUES (?1, ?2, ?3, ?4, ?5, ?6)", params![name, srs, org, code, definition, crs.units()]).map_err(out)?;
    }
    let mut b = crate::points::Bounds::EMPTY;
    curves.each(&mut |c| {
        c.vertices.iter().for_each(|v| b.grow(v.p));
        Ok(())
    })?;
    let (lo, hi) = if b.is_empty() { ([0.0; 3], [0.0; 3]) } else { (b.min, b.max) };
    tx.execute(
        "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, max_x, max_y, srs_id) VALUES ('curves', 'features', 'curves', 'crease feature curves', ?1, ?2, ?3, ?4, ?5)",
        params![lo[0], lo[1], hi[0], hi[1], srs],
    )
    .map_err(out)?;
    tx.execute("INSERT INTO gpkg_geometry_columns VALUES ('curves', 'geom', 'LINESTRING', ?1, 1, 0)", params![srs]).map_err(out)?;
    {
        let mut insert = tx
            .prepare("INSERT INTO curves (geom, id, closed, length, confidence, angle, shape, start, \"end\", corners, kind, radius) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)")
            .map_err(out)?;
        curves.each(&mut |c| {
            let [start, end] = c.end_kinds();
            let (kind, radius) = typed::curve_kind(&typed::pieces(c, tol));
            insert
                .execute(params![
                    geometry(c, srs),
                    c.id,
                    c.closed,
                    c.length(),
                    c.confidence as f64,
                    c.mean_dihedral_angle(),
                    c.shape.name(),
                    start,
                    end,
                    c.corner_list(),
                    kind,
                    radius
                ])
                .map_err(out)?;
            Ok(())
        })?;
    }
    tx.commit().map_err(out)?;
    db.close().map_err(|(_, e)| out(e))
}
