//! What a point of a labelled copy carries (`--label-points`, see `labels.rs`): the three
//! fields, their names and sizes, and the trait that gives them. The writers of each format
//! share it.

use glam::DVec3;

/// Points labelled at a time: a few tens of MB of records, labels and coordinates.
pub const LABEL_CHUNK: usize = 1 << 18;

/// The names of the three fields, in the order they are stored.
pub const LABEL_FIELDS: [&str; 3] = ["edge_distance", "curve_id", "edge"];

/// Bytes the three fields take in a record: f64, i32, u8.
pub(super) const LABEL_BYTES: u16 = 13;

/// What a point is labelled with (with no curves at all: an infinite distance, no curve, not an
/// edge).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Label {
    /// Distance to the nearest curve, model units.
    pub distance: f64,
    /// Id of that curve, or -1 when none is within reach.
    pub curve: i32,
    /// 1 if the point lies within the tolerance of a curve, else 0.
    pub edge: u8,
}

impl Label {
    /// The three fields as little- or big-endian bytes, appended to `out`.
    pub(super) fn push_bytes(&self, out: &mut Vec<u8>, big: bool) {
        if big {
            out.extend_from_slice(&self.distance.to_be_bytes());
            out.extend_from_slice(&self.curve.to_be_bytes());
        } else {
            out.extend_from_slice(&self.distance.to_le_bytes());
            out.extend_from_slice(&self.curve.to_le_bytes());
        }
        out.push(self.edge);
    }
}

/// Labels points (the caller's curves, say): `out` is replaced by one label a point.
pub trait Labeller: Sync {
    /// Labels `points`, in order.
    fn label(&self, points: &[DVec3], out: &mut Vec<Label>);
}
