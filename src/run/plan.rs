//! The plan of a run: the tile grid over the cloud's bounds, sized from the memory budget.

use crate::points::Bounds;
use glam::DVec3;

/// Bytes of memory a tile point costs while processed (points, tree, per-stage arrays, the
/// halo share and the prefetched next tile).
pub const BYTES_PER_POINT: u64 = 600;

/// Most points a tile is planned to hold, whatever the memory allows. Each pass loads its
/// first tile while the cores wait, and big tiles leave little to overlap: the 20 M-point
/// scene in 2 tiles (the default budget) took 170 s; in 16 tiles, 137 s.
pub const MAX_TILE_POINTS: u64 = 2_000_000;

/// Tile edge length for a budget: tiles hold about `memory / BYTES_PER_POINT` points (at most
/// [`MAX_TILE_POINTS`]), assuming the points spread evenly over the footprint (2D) or the
/// volume (3D) of the bounds.
pub fn tile_size_for(b: &Bounds, points: u64, memory: u64) -> f64 {
    let per_tile = (memory / BYTES_PER_POINT).clamp(10_000, MAX_TILE_POINTS) as f64;
    let ext = DVec3::from(b.max) - DVec3::from(b.min);
    let ext = ext.max(DVec3::splat(1e-9));
    let tiles = (points as f64 / per_tile).max(1.0);
    let flat = ext.z < 0.25 * ext.x.max(ext.y);
    let size = if flat { (ext.x * ext.y / tiles).sqrt() } else { (ext.x * ext.y * ext.z / tiles).cbrt() };
    // Never more than needed to hold everything in one tile.
    size.min(ext.max_element() * 1.001)
}
