//! Plain data types describing a point cloud: its header and chunks of its points.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// An axis-aligned box in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// Smallest x, y, z.
    pub min: [f64; 3],
    /// Largest x, y, z.
    pub max: [f64; 3],
}

impl Bounds {
    /// The empty box: growing it by any point gives that point's box.
    pub(crate) const EMPTY: Bounds = Bounds { min: [f64::INFINITY; 3], max: [f64::NEG_INFINITY; 3] };

    /// The box `--bounds` gives (and the Python binding's `bounds=`): XMIN,YMIN,XMAX,YMAX (any
    /// height) or XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX.
    pub fn from_list(v: &[f64]) -> Result<Bounds, String> {
        let (min, max) = match *v {
            [x0, y0, x1, y1] => ([x0, y0, -f64::MAX], [x1, y1, f64::MAX]),
            [x0, y0, z0, x1, y1, z1] => ([x0, y0, z0], [x1, y1, z1]),
            _ => return Err(format!("takes 4 or 6 numbers (XMIN,YMIN,XMAX,YMAX or XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX), not {}", v.len())),
        };
        if v.iter().any(|x| !x.is_finite()) {
            return Err("takes finite numbers".into());
        }
        let b = Bounds { min, max };
        if (0..3).any(|a| min[a] > max[a]) {
            return Err(format!("has a minimum above its maximum ({})", b.ranges()));
        }
        Ok(b)
    }

    /// True if no point was ever added.
    pub fn is_empty(&self) -> bool {
        self.min[0] > self.max[0]
    }

    /// True if the box holds something and every bound is finite, with min <= max on each axis
    /// (a box read from a header may be none of these).
    pub(crate) fn is_usable(&self) -> bool {
        (0..3).all(|a| self.min[a].is_finite() && self.max[a].is_finite() && self.min[a] <= self.max[a])
    }

    /// Grows the box to hold `p`.
    #[inline]
    pub(crate) fn grow(&mut self, p: DVec3) {
        self.min = DVec3::from(self.min).min(p).to_array();
        self.max = DVec3::from(self.max).max(p).to_array();
    }

    /// Grows the box to hold `other`.
    pub(crate) fn union(&mut self, other: &Bounds) {
        for i in 0..3 {
            self.min[i] = self.min[i].min(other.min[i]);
            self.max[i] = self.max[i].max(other.max[i]);
        }
    }

    /// True if `p` lies in the box, its faces included.
    #[inline]
    pub fn contains(&self, p: DVec3) -> bool {
        p.cmpge(DVec3::from(self.min)).all() && p.cmple(DVec3::from(self.max)).all()
    }

    /// True if the two boxes share a point (faces included).
    pub(crate) fn meets(&self, other: &Bounds) -> bool {
        (0..3).all(|a| self.min[a] <= other.max[a] && other.min[a] <= self.max[a])
    }

    /// The part of the box inside `other` (empty if they do not meet).
    pub(crate) fn intersection(&self, other: &Bounds) -> Bounds {
        if !self.meets(other) {
            return Bounds::EMPTY;
        }
        Bounds { min: DVec3::from(self.min).max(other.min.into()).to_array(), max: DVec3::from(self.max).min(other.max.into()).to_array() }
    }

    /// The box as its three ranges, for messages: "x 0 to 2, y -0.2 to 0.9, any z" (an axis
    /// from -f64::MAX to f64::MAX is "any").
    pub(crate) fn ranges(&self) -> String {
        let axis = |a: usize, name: &str| {
            if self.min[a] <= -f64::MAX && self.max[a] >= f64::MAX {
                format!("any {name}")
            } else {
                format!("{name} {} to {}", self.min[a], self.max[a])
            }
        };
        format!("{}, {}, {}", axis(0, "x"), axis(1, "y"), axis(2, "z"))
    }

    /// Length of the diagonal (0 for an empty box).
    pub fn diagonal(&self) -> f64 {
        if self.is_empty() {
            return 0.0;
        }
        (DVec3::from(self.max) - DVec3::from(self.min)).length()
    }

    /// The box of a set of points.
    pub fn of(points: impl IntoIterator<Item = DVec3>) -> Bounds {
        let mut b = Bounds::EMPTY;
        for p in points {
            b.grow(p);
        }
        b
    }
}

pub use crate::crs::Crs;

/// The file formats crease reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FileFormat {
    /// Uncompressed ASPRS LAS.
    Las,
    /// LASzip-compressed LAS.
    Laz,
    /// Stanford PLY (ascii or binary).
    Ply,
    /// ASTM E57 (terrestrial scans, one or more per file).
    E57,
    /// A text cloud (XYZ, PTS, CSV, TXT).
    Text,
}

impl FileFormat {
    /// True if the format's header states the points' bounds (LAS, LAZ); the others' come
    /// from reading the points.
    pub(crate) fn has_header_bounds(self) -> bool {
        matches!(self, FileFormat::Las | FileFormat::Laz)
    }
}

/// What a file's header says, read without touching the points.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CloudHeader {
    /// The file.
    pub path: PathBuf,
    /// Its format.
    pub format: FileFormat,
    /// Format version, e.g. "1.4" for LAS or "binary_little_endian 1.0" for PLY.
    pub version: String,
    /// LAS point data record format (0-10); None for PLY.
    pub point_format: Option<u8>,
    /// Number of points the header declares.
    pub count: u64,
    /// Bounds the header declares (LAS), or bounds found by reading the points (PLY).
    pub bounds: Bounds,
    /// The CRS, if the file carries one.
    pub crs: Crs,
    /// How the file stores coordinates.
    pub precision: Precision,
    /// Where the scanner stood for each scan the file holds, if it says (E57 scan poses):
    /// what tells convex creases from concave ones (see [`crate::curves::Outside`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scanners: Vec<glam::DVec3>,
}

/// How a file stores coordinates, which sets the smallest step between two positions.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Integers times a scale factor (LAS, whose largest factor this is; integer PLY
    /// properties, with a factor of 1).
    Scaled(f64),
    /// Floating point with this many mantissa bits: 23 (float32) or 52 (float64).
    Float(u32),
}

impl Precision {
    /// The step between neighbouring coordinates near the largest magnitude in `b` (0 if `b`
    /// is not usable).
    ///
    /// ```
    /// use crease::points::{Bounds, Precision};
    /// let utm = Bounds { min: [500_000.0, 5_000_000.0, 0.0], max: [501_000.0, 5_001_000.0, 50.0] };
    /// assert_eq!(Precision::Float(23).step(&utm), 0.5);
    /// assert_eq!(Precision::Scaled(0.01).step(&utm), 0.01);
    /// ```
    pub fn step(&self, b: &Bounds) -> f64 {
        match *self {
            Precision::Scaled(s) => s,
            Precision::Float(bits) => {
                let m = (0..3).map(|a| b.min[a].abs().max(b.max[a].abs())).fold(0.0, f64::max);
                if !(m > 0.0 && m.is_finite()) {
                    return 0.0;
                }
                2f64.powi(m.log2().floor() as i32 - bits as i32)
            }
        }
    }
}

/// A chunk of points in world coordinates, with their classification (0 if the format has none).
#[derive(Clone, Debug, Default)]
pub struct PointChunk {
    /// Positions in world coordinates.
    pub xyz: Vec<DVec3>,
    /// ASPRS classification codes, one per point.
    pub class: Vec<u8>,
    /// Record index of each point in its file (points dropped by filters leave gaps).
    pub index: Vec<u64>,
}

impl PointChunk {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.xyz.len()
    }

    /// True if the chunk holds no point.
    pub fn is_empty(&self) -> bool {
        self.xyz.is_empty()
    }

    /// Keeps only the points for which `keep` holds, in order.
    pub(crate) fn retain(&mut self, keep: impl Fn(DVec3) -> bool) {
        let mut k = 0;
        for i in 0..self.len() {
            if keep(self.xyz[i]) {
                self.xyz[k] = self.xyz[i];
                self.class[k] = self.class[i];
                self.index[k] = self.index[i];
                k += 1;
            }
        }
        self.xyz.truncate(k);
        self.class.truncate(k);
        self.index.truncate(k);
    }

    /// Removes every point.
    pub fn clear(&mut self) {
        self.xyz.clear();
        self.class.clear();
        self.index.clear();
    }
}

/// Points of a tile: world positions and global ids.
#[derive(Clone, Debug, Default)]
pub(crate) struct TilePoints {
    /// Positions.
    pub xyz: Vec<DVec3>,
    /// Global ids.
    pub gid: Vec<u64>,
}
