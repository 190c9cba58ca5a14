//! Feature curves: the [`Polyline`] type and its readers and writers (OBJ, PLY, GeoJSON,
//! GeoPackage, DXF).
//!
//! What each output holds:
//! - `curves.obj`: `v` / `l` polylines, one `o curve_N` per curve followed by a `# confidence c`
//!   comment and a `# length L angle A shape K start S end E corners I,J` comment; corners shared
//!   by several curves are one vertex. A `# crs ...` line names the CRS.
//! - `curves.ply`: binary; vertex x, y, z (double), nx, ny, nz (the first surface's normal, which
//!   Open3D, CloudCompare and trimesh read as the normal), n2x, n2y, n2z (the second's), curve
//!   id, corner flag, the curve's confidence (float) and shape (uchar: 0 unknown, 1 convex, 2
//!   concave); edge element. A `comment crs` line names the CRS.
//! - `curves.geojson`: 3D LineStrings in the input's own coordinates (crease does not
//!   reproject). Per curve, scalar properties only (Shapefile and FlatGeobuf keep them all):
//!   `id`, `closed`, `length`, `confidence`, `angle`, `shape`, `start` and `end` (`corner`,
//!   `free` or `closed`), `corners` (indices of corner vertices, as text). The CRS is named with
//!   the `crs` member, which GDAL reads: the EPSG URN, or the WKT when the CRS has no code; the
//!   full WKT is also in `crs_wkt`, the units in `crs_units`. Without a CRS it names a local CRS of unknown unit, which GDAL reads as unknown rather than as WGS 84.
//!   Also `kind`, what the curve is as typed pieces (`typed`): `line`, `arc`, `circle`,
//!   `spline` or `polyline` where all its pieces are of that kind, `mixed` where they differ; and `radius`,
//!   where it is one arc or one circle (else null).
//! - `curves.gpkg`: an OGC GeoPackage, a `curves` table of LineString Z features with the same
//!   scalar attributes as the GeoJSON, and the CRS (code and WKT) in its spatial reference table.
//! - `curves.dxf` (AutoCAD 2000): each curve as its typed pieces, in curve id order: a LINE on
//!   layer `crease_lines`, an ARC on `crease_arcs`, a CIRCLE on `crease_circles` (an arc's or a
//!   circle's axis its extrusion direction), a run no line or arc fits a cubic SPLINE on
//!   `crease_splines` (a 3D POLYLINE on `crease_curves` where no spline holds either); each
//!   corner a POINT on layer `crease_corners`. Each entity carries its
//!   curve's attributes as extended data of the application `CREASE`: a name (group code 1000)
//!   then its value (`id` 1071, `closed` 1070, `length`, `confidence`, `angle` 1040, `shape`,
//!   `start`, `end`, `corners` 1000), then the piece's `kind` (1000) and an arc's or a circle's
//!   `radius` (1040); GDAL lists them as `RawCodeValues` with `--config
//!   DXF_INCLUDE_RAW_CODE_VALUES TRUE`. No CRS (DXF has none).
//! - `curves.json`: the typed pieces, one record each (`typed::write_pieces`).
//!
//! A curve's `angle` is the mean dihedral angle of its crease in degrees: the wedge the two
//! surfaces enclose, 90 at a cube's edge, 135 where a chamfer meets a face, towards 180 as the
//! crease flattens (a convex and a concave crease of the same opening read the same). Its
//! `shape` is `convex`, `concave` or `unknown` ([`Outside`]): a vertex reads convex if one of its
//! normals points towards the scanner (more than 10 degrees off grazing), concave if both point
//! away from it; a curve takes the reading of more than half of its vertices. Its `confidence`
//! (0 to 1) is what the edge cloud says for it: the share of its length that has edge points
//! within half a step, how well their surface normals agree, and a length term that saturates
//! over a few steps.
//!
//! Every vertex carries two normals, each pointing away from the other surface's side of the
//! crease (so the angle between them is 180 degrees minus the dihedral angle): out of the solid
//! at a convex crease, into it at a concave one. Along a curve they keep the orientation most of
//! its edge points have. Corners, and the rare vertex with no edge point near it, take those of
//! the nearest vertex along the curve that has them; a curve with none at all keeps zeros.

mod circle;
mod dxf;
mod geojson;
mod gpkg;
pub mod nearest;
mod obj;
mod ply;
mod shape;
pub(crate) mod spline;
pub(crate) mod typed;

pub use self::dxf::write_dxf;
pub use geojson::write_geojson;
pub use gpkg::write_gpkg;
pub use obj::{read_obj, write_obj};
pub use ply::{read_ply, write_ply};
pub use shape::{Outside, Shape};

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

/// Distance of `p` from the segment `a`-`b` (from `a` where the segment has no length).
pub(crate) fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 { ((p - a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    p.distance(a + t * ab)
}

/// The curve file formats a run can write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Wavefront OBJ polylines (`curves.obj`).
    Obj,
    /// Binary PLY with both normals per vertex (`curves.ply`).
    Ply,
    /// GeoJSON LineStrings (`curves.geojson`).
    Geojson,
    /// OGC GeoPackage (`curves.gpkg`).
    Gpkg,
    /// DXF lines, arcs, circles and splines for CAD (`curves.dxf`).
    Dxf,
    /// The curves as typed pieces, lines, arcs, circles and splines (`curves.json`).
    Json,
}

impl Format {
    /// Every format, in the order written.
    pub(crate) const ALL: [Format; 6] = [Format::Obj, Format::Ply, Format::Geojson, Format::Gpkg, Format::Dxf, Format::Json];
    /// What a run writes unless told otherwise.
    pub(crate) const DEFAULT: [Format; 3] = [Format::Obj, Format::Ply, Format::Geojson];

    /// The output's file name.
    pub fn file_name(self) -> &'static str {
        match self {
            Format::Obj => "curves.obj",
            Format::Ply => "curves.ply",
            Format::Geojson => "curves.geojson",
            Format::Gpkg => "curves.gpkg",
            Format::Dxf => "curves.dxf",
            Format::Json => "curves.json",
        }
    }

    /// Writes `curves` in this format (`tolerance`: that of the typed pieces, see
    /// `typed::tolerance`).
    pub fn write(self, path: &std::path::Path, curves: &(impl Curves + ?Sized), crs: &crate::crs::Crs, tolerance: f64) -> crate::Result<()> {
        match self {
            Format::Obj => write_obj(path, curves, crs),
            Format::Ply => write_ply(path, curves, crs),
            Format::Geojson => write_geojson(path, curves, crs, tolerance),
            Format::Gpkg => write_gpkg(path, curves, crs, tolerance),
            Format::Dxf => write_dxf(path, curves, crs, tolerance),
            Format::Json => typed::write_pieces(path, curves, crs, tolerance),
        }
    }
}

/// Curves to write, gone through once or more per output, in order: a slice of them, or a
/// run's finished curves read back a batch at a time from its working data (so that the
/// writers never need them all at once).
pub trait Curves: Sync {
    /// Calls `f` on every curve, in order, until it fails.
    fn each(&self, f: &mut dyn FnMut(&Polyline) -> crate::Result<()>) -> crate::Result<()>;
}

impl Curves for [Polyline] {
    fn each(&self, f: &mut dyn FnMut(&Polyline) -> crate::Result<()>) -> crate::Result<()> {
        self.iter().try_for_each(f)
    }
}

impl<const N: usize> Curves for [Polyline; N] {
    fn each(&self, f: &mut dyn FnMut(&Polyline) -> crate::Result<()>) -> crate::Result<()> {
        self.as_slice().each(f)
    }
}

impl Curves for Vec<Polyline> {
    fn each(&self, f: &mut dyn FnMut(&Polyline) -> crate::Result<()>) -> crate::Result<()> {
        self.as_slice().each(f)
    }
}

/// One vertex of a feature curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Vertex {
    /// Position in world coordinates.
    pub p: DVec3,
    /// Unit normals of the two surfaces that meet here (zero if unknown).
    pub n: [Vec3; 2],
    /// True if the vertex is a corner where three or more surfaces meet.
    pub corner: bool,
}

impl Vertex {
    /// A vertex with unknown normals.
    pub fn at(p: DVec3) -> Vertex {
        Vertex { p, n: [Vec3::ZERO; 2], corner: false }
    }
}

/// A feature curve: an ordered run of vertices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Polyline {
    /// Identifier, unique within a result.
    pub id: u32,
    /// True if the last vertex connects back to the first.
    pub closed: bool,
    /// The vertices, in order.
    pub vertices: Vec<Vertex>,
    /// How sure crease is that the curve is a feature of the surface, 0 to 1 (1 for curves
    /// not extracted by crease).
    pub confidence: f32,
    /// Convex or concave, where the scanners' positions tell (see [`Outside::shape`]).
    #[serde(default)]
    pub shape: Shape,
}

impl Polyline {
    /// An open polyline through `points` with unknown normals.
    pub fn from_points(id: u32, points: impl IntoIterator<Item = DVec3>) -> Polyline {
        Polyline { id, closed: false, vertices: points.into_iter().map(Vertex::at).collect(), confidence: 1.0, shape: Shape::Unknown }
    }

    /// Number of segments (closing segment included).
    pub fn segment_count(&self) -> usize {
        let n = self.vertices.len();
        match (n, self.closed) {
            (0 | 1, _) => 0,
            (_, true) => n,
            (_, false) => n - 1,
        }
    }

    /// The segments as pairs of positions (closing segment included).
    pub fn segments(&self) -> impl Iterator<Item = (DVec3, DVec3)> + '_ {
        let n = self.vertices.len();
        (0..self.segment_count()).map(move |i| (self.vertices[i].p, self.vertices[(i + 1) % n].p))
    }

    /// Total length.
    pub fn length(&self) -> f64 {
        self.segments().map(|(a, b)| a.distance(b)).sum()
    }

    /// Mean dihedral angle, in degrees: the angle of the wedge that the two surfaces enclose at
    /// the crease (90 at a cube's edge, 135 where a chamfer meets a face, towards 180 as the
    /// crease flattens), over the vertices whose normals are known; None if none are. The
    /// normals point away from each other's half-surface (see the edge points of stage 3), so
    /// the angle is 180 minus the angle between them. A convex and a concave crease of the same
    /// opening read the same (see [`Polyline::shape`]).
    pub fn mean_dihedral_angle(&self) -> Option<f64> {
        let angles: Vec<f64> = self
            .vertices
            .iter()
            .filter(|v| v.n[0] != Vec3::ZERO && v.n[1] != Vec3::ZERO)
            .map(|v| 180.0 - (v.n[0].dot(v.n[1]).clamp(-1.0, 1.0) as f64).acos().to_degrees())
            .collect();
        (!angles.is_empty()).then(|| angles.iter().sum::<f64>() / angles.len() as f64)
    }

    /// How the curve ends at its first and last vertex: "corner" (three or more surfaces
    /// meet), "free" (it fades out or meets a border of the cloud), or "closed" for a loop.
    pub(crate) fn end_kinds(&self) -> [&'static str; 2] {
        if self.closed {
            return ["closed"; 2];
        }
        let kind = |v: Option<&Vertex>| if v.is_some_and(|v| v.corner) { "corner" } else { "free" };
        [kind(self.vertices.first()), kind(self.vertices.last())]
    }

    /// Indices of the corner vertices, as text ("0,17"): a list field that every GIS format
    /// carries.
    pub(crate) fn corner_list(&self) -> String {
        self.vertices.iter().enumerate().filter(|(_, v)| v.corner).map(|(i, _)| i.to_string()).collect::<Vec<_>>().join(",")
    }
}
