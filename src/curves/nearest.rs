//! The nearest curve to a point, exactly, for labelling a cloud's points with their distance to
//! the curves (`--label-points`).
//!
//! The curves' segments are sampled at most a spacing `h` apart and the samples indexed in a
//! k-d tree. The segment of the sample nearest to a point gives an upper bound `u` on the
//! point's distance to the curves; the segment the point is nearest to has a sample within
//! `u + h / 2` of it, so the exact distances to the segments of the samples within that radius
//! decide. Ties go to the lower curve id, then to the earlier segment, so the answer does not
//! depend on the tree.

use super::{Curves, Polyline};
use crate::error::Result;
use crate::spatial::Index;
use glam::DVec3;

/// Bytes a sample takes while the index is built: its position, its segment's number, and the
/// tree's own copy of both with the builder's scratch.
const SAMPLE_BYTES: u64 = 40;

/// A segment of a curve.
#[derive(Clone, Copy, Debug)]
struct Segment {
    a: DVec3,
    b: DVec3,
    curve: u32,
}

impl Segment {
    fn distance(&self, q: DVec3) -> f64 {
        super::segment_distance(q, self.a, self.b)
    }
}

/// The curves' segments indexed for nearest-curve queries.
pub struct NearestCurve {
    segments: Vec<Segment>,
    /// The segment of each sample in the tree.
    sample_segment: Vec<u32>,
    tree: Option<Index>,
    /// The samples' origin (the tree holds f32 offsets from it).
    origin: DVec3,
    /// Largest gap between samples along a segment.
    h: f64,
    /// Largest coordinate magnitude in the tree, for the f32 rounding allowance.
    extent: f64,
}

impl NearestCurve {
    /// Indexes `curves`, sampled about `h` apart, or more coarsely where that would take more
    /// than `bytes` of memory with the segments. (Any spacing gives the same answers: a coarser
    /// one only makes a query look at more segments.)
    ///
    /// ```
    /// use crease::curves::{nearest::NearestCurve, Polyline};
    /// use glam::DVec3;
    ///
    /// let curves = vec![Polyline::from_points(4, [DVec3::ZERO, DVec3::X])];
    /// let index = NearestCurve::new(&curves, 0.01, 1 << 20)?;
    /// let (distance, id) = index.nearest(DVec3::new(0.5, 2.0, 0.0), &mut vec![]).unwrap();
    /// assert_eq!((distance, id), (2.0, 4));
    /// # Ok::<(), crease::Error>(())
    /// ```
    pub fn new(curves: &(impl Curves + ?Sized), h: f64, bytes: u64) -> Result<NearestCurve> {
        let mut segments = vec![];
        curves.each(&mut |c: &Polyline| {
            segments.extend(c.segments().map(|(a, b)| Segment { a, b, curve: c.id }));
            // (A curve of one vertex is a segment of no length.)
            if c.vertices.len() == 1 {
                segments.push(Segment { a: c.vertices[0].p, b: c.vertices[0].p, curve: c.id });
            }
            Ok(())
        })?;
        let total: f64 = segments.iter().map(|s| s.a.distance(s.b)).sum();
        // (Each segment takes its two ends whatever the spacing; the rest of the memory goes to
        // samples between them.)
        let held = segments.len() as u64 * (std::mem::size_of::<Segment>() as u64 + 2 * SAMPLE_BYTES);
        let between = (bytes.saturating_sub(held) / SAMPLE_BYTES).max(1) as f64;
        let h = h.max(total / between).max(f64::MIN_POSITIVE);
        let origin = segments.iter().map(|s| s.a).reduce(DVec3::min).unwrap_or_default();
        let (mut samples, mut sample_segment) = (vec![], vec![]);
        for (k, s) in segments.iter().enumerate() {
            let n = (s.a.distance(s.b) / h).ceil().max(1.0) as usize;
            for i in 0..=n {
                samples.push((s.a.lerp(s.b, i as f64 / n as f64) - origin).as_vec3().to_array());
                sample_segment.push(k as u32);
            }
        }
        let extent = samples.iter().flatten().fold(0f32, |m, v| m.max(v.abs())) as f64;
        let tree = (!samples.is_empty()).then(|| Index::new_parallel(&samples));
        drop(samples);
        Ok(NearestCurve { segments, sample_segment, tree, origin, h, extent })
    }

    /// True if there are no curves.
    pub fn is_empty(&self) -> bool {
        self.tree.is_none()
    }

    /// The distance from `q` to the nearest curve and that curve's id (None without curves).
    /// `scratch` is reused between calls.
    pub fn nearest(&self, q: DVec3, scratch: &mut Vec<(u32, f32)>) -> Option<(f64, u32)> {
        let tree = self.tree.as_ref()?;
        let local = (q - self.origin).as_vec3().to_array();
        scratch.clear();
        tree.nearest_n(&local, 1, scratch);
        let first = self.sample_segment[scratch.first()?.0 as usize];
        let upper = self.segments[first as usize].distance(q);
        // (The tree's distances are in f32: allow for the rounding of both ends.)
        let slack = 1e-6 * (self.extent + local.iter().fold(0f32, |m, v| m.max(v.abs())) as f64);
        let radius = upper + 0.5 * self.h + slack;
        scratch.clear();
        tree.within(&local, radius as f32, scratch);
        let mut best = (upper, self.segments[first as usize].curve, first);
        for &(i, _) in scratch.iter() {
            let k = self.sample_segment[i as usize];
            let s = &self.segments[k as usize];
            let d = s.distance(q);
            if (d, s.curve, k) < best {
                best = (d, s.curve, k);
            }
        }
        Some((best.0, best.1))
    }

    /// A fingerprint of the segments, `h` aside: equal for the same curves.
    pub fn fingerprint(&self) -> String {
        let mut c = crc32fast::Hasher::new();
        for s in &self.segments {
            for v in [s.a, s.b] {
                for x in v.to_array() {
                    c.update(&x.to_le_bytes());
                }
            }
            c.update(&s.curve.to_le_bytes());
        }
        format!("{}-{:08x}", self.segments.len(), c.finalize())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The index answers what a search of every segment answers, ties to the lower id, whether
    /// it may sample the curves finely or is left only their segments' ends.
    #[test]
    fn nearest_is_the_brute_force_answer() {
        for bytes in [1 << 20, 0] {
            nearest_is_the_brute_force_answer_in(bytes);
        }
    }

    fn nearest_is_the_brute_force_answer_in(bytes: u64) {
        let a = Polyline::from_points(3, [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0)]);
        let b = Polyline::from_points(7, [DVec3::new(0.0, 0.5, 0.0), DVec3::new(0.0, 0.5, 2.0)]);
        let curves = vec![a, b];
        let n = NearestCurve::new(&curves, 0.05, bytes).unwrap();
        // (The fine index holds the samples 0.05 apart, the coarse one little more than the ends.)
        assert!(if bytes > 0 { n.sample_segment.len() > 60 } else { n.sample_segment.len() <= 8 }, "{}", n.sample_segment.len());
        let mut scratch = vec![];
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64 * 6.0 - 3.0
        };
        for _ in 0..2000 {
            let q = DVec3::new(next(), next(), next());
            let brute = curves
                .iter()
                .flat_map(|c| c.segments().map(move |(a, b)| (Segment { a, b, curve: c.id }.distance(q), c.id)))
                .fold((f64::INFINITY, u32::MAX), |m, x| if x < m { x } else { m });
            assert_eq!(n.nearest(q, &mut scratch), Some(brute), "{q}");
        }
        // (Equally near both: the lower id.)
        assert_eq!(n.nearest(DVec3::new(0.0, 0.25, 0.0), &mut scratch).map(|x| x.1), Some(3));
        assert!(NearestCurve::new(&Vec::<Polyline>::new(), 0.1, 1 << 20).unwrap().nearest(q0(), &mut scratch).is_none());
    }

    fn q0() -> DVec3 {
        DVec3::ZERO
    }
}
