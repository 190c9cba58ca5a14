//! The point set a stage works on: f32 coordinates local to an f64 origin, with a k-d tree.

use crate::spatial::Index;
use glam::{DVec3, Vec3};

/// Points of one tile (core and halo) in local coordinates, indexed for neighbour queries.
pub struct Cloud {
    /// World position of the local origin.
    pub origin: DVec3,
    /// Local coordinates.
    pub points: Vec<[f32; 3]>,
    /// Neighbour index over `points`.
    pub index: Index,
}

impl Cloud {
    /// Builds a cloud from world positions, with the origin at their minimum corner.
    pub fn new(world: &[DVec3]) -> Cloud {
        let origin = world.iter().copied().reduce(DVec3::min).unwrap_or(DVec3::ZERO);
        Cloud::with_origin(world, origin)
    }

    /// Builds a cloud from world positions with a given origin.
    pub fn with_origin(world: &[DVec3], origin: DVec3) -> Cloud {
        let points: Vec<[f32; 3]> = world.iter().map(|p| (*p - origin).as_vec3().to_array()).collect();
        let index = Index::new(&points);
        Cloud { origin, points, index }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True if there is no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Local position of point `i` in f64.
    #[inline]
    pub fn at(&self, i: usize) -> DVec3 {
        Vec3::from(self.points[i]).as_dvec3()
    }

    /// Indices (and squared distances) of the points within `r` of local position `q`; at most
    /// `max` of them, chosen deterministically (nearest first) when there are more.
    pub fn neighbours(&self, q: DVec3, r: f64, max: usize, out: &mut Vec<(u32, f32)>) {
        out.clear();
        self.index.within(&q.as_vec3().to_array(), r as f32, out);
        if out.len() > max {
            out.select_nth_unstable_by(max, |a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            out.truncate(max);
        }
        // A fixed order makes every fit independent of the tree's traversal order.
        out.sort_unstable_by_key(|a| a.0);
    }
}
