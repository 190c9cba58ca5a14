//! Feature curves: the [`Polyline`] type and its readers and writers (OBJ, PLY, GeoJSON).

mod geojson;
mod obj;
mod ply;

pub use geojson::write_geojson;
pub use obj::{read_obj, write_obj};
pub use ply::{read_ply, write_ply};

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

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
}

impl Polyline {
    /// An open polyline through `points` with unknown normals.
    pub fn from_points(id: u32, points: impl IntoIterator<Item = DVec3>) -> Polyline {
        Polyline { id, closed: false, vertices: points.into_iter().map(Vertex::at).collect(), confidence: 1.0 }
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
}
