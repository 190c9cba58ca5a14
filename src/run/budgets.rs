//! How a run shares its memory budget (`--memory`): the tiles of the tile passes take most of
//! it; bucketing and the curve stage keep buffers of a fixed share each, counted in the items
//! they hold at what one item costs there. A share is a divisor of the budget, so that the
//! buffers together stay well inside it beside the tile or block being worked on.

/// The smallest memory budget a run takes: room for a tile of a few thousand points and a
/// batch of curves.
pub(crate) const MIN_MEMORY: u64 = 512 << 10;

/// Bytes of memory a tile point costs while processed (points, tree, per-stage arrays, the
/// halo share and the prefetched next tile).
pub(crate) const BYTES_PER_POINT: u64 = 600;

/// Most points a tile is planned to hold, whatever the memory allows: each pass loads its
/// first tile while the cores wait, and big tiles leave little loading to overlap.
pub(crate) const MAX_TILE_POINTS: u64 = 2_000_000;

/// Fewest points a tile is planned to hold, however small the budget: smaller tiles would be
/// mostly halo.
pub(super) const MIN_TILE_POINTS: u64 = 10_000;

/// Bytes of a point in the bucketer's buffers: its position and global id, and its place in
/// the sort by chunk when the buffer is written.
const BUCKETED_POINT_BYTES: u64 = 48;

/// Bytes of an edge point as the curve stage holds it: a position (f64) and the normals of its
/// two surfaces (f32).
const EDGE_POINT_BYTES: u64 = 48;

/// Bytes of a curve vertex while its batch is completed (positions, tangents, corner flags,
/// the index of the ends and the copies completion makes).
const COMPLETED_VERTEX_BYTES: u64 = 140;

/// Bytes the label pass's index of the curves may take (see
/// [`crate::curves::nearest::NearestCurve`]): half the budget, the other half holding a chunk of
/// points in flight and the compressor.
pub(super) fn label_index(memory: u64) -> u64 {
    memory / 2
}

/// Points the bucketer buffers before it appends them to the tile store: a quarter of the
/// budget, the rest being the readers' and the compressors'.
pub(super) fn bucket_buffer(memory: u64) -> usize {
    (memory / 4 / BUCKETED_POINT_BYTES) as usize
}

/// Edge points of the tiles the curve stage read last, kept for the neighbouring blocks that
/// read the same tiles: a sixteenth of the budget.
pub(super) fn tile_edges_kept(memory: u64) -> u64 {
    memory / 16 / EDGE_POINT_BYTES
}

/// Smoothed edge points of the blocks that attribution read last: a 48th of the budget (small:
/// it only spares neighbouring blocks decoding the records around them again).
pub(super) fn smoothed_kept(memory: u64) -> u64 {
    memory / 48 / EDGE_POINT_BYTES
}

/// Vertices of a batch of curves completed, attributed and written at once: a sixteenth of the
/// budget, and at least 256 (so that a tiny budget still makes batches of a few curves).
pub(super) fn completion_batch(memory: u64) -> usize {
    (memory / 16 / COMPLETED_VERTEX_BYTES).max(256) as usize
}
