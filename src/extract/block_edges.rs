//! Stage 3 for one growth block (see [`super::blocks`]): the edge points near the block sorted into
//! its own, those of its growing halo ("around") and the smoothing's context beyond, then
//! smoothed and confirmed (see [`polylines::smooth_and_confirm`]) and split into the block's
//! core, which it grows from, and its halo, which it grows on through. Positions are relative
//! to the curve stage's origin; the run reads the edge points ([`BlockContext::region`] says
//! which) and stores what comes out.

use super::blocks::{in_box, Blocks};
use super::groups::Corners;
use super::params::Resolved;
use super::polylines::{self, SmoothedEdges};
use super::project::WorldEdge;
use crate::keys::snap_quantum;
use glam::DVec3;

/// What sorting and smoothing a block's edge points takes: the blocks, their origin, the
/// grouped corners (which cap the smoothing's neighbourhoods), and how far the growing halo
/// and the smoothing's context reach past a block.
pub(crate) struct BlockContext<'a> {
    blocks: &'a Blocks,
    origin: DVec3,
    corners: Corners<'a>,
    r: &'a Resolved,
    /// The growing halo's width.
    halo: f64,
    /// How far past a block its edge points are needed (the halo, and the smoothing reach
    /// beyond it).
    reach: f64,
}

/// A block's edge points, sorted (see [`sort_edges`]), each set in the order of its positions.
#[derive(Default)]
pub(crate) struct BlockEdges {
    /// The points the block owns.
    pub own: SmoothedEdges,
    /// The points of its growing halo.
    pub around: SmoothedEdges,
    /// The points beyond, within the smoothing's reach: context only.
    pub context: SmoothedEdges,
}

impl<'a> BlockContext<'a> {
    /// The context of the blocks `blocks` about `origin`, with the grouped corners `grouped`
    /// (relative to the origin).
    pub(crate) fn new(blocks: &'a Blocks, origin: DVec3, grouped: &'a [DVec3], r: &'a Resolved) -> BlockContext<'a> {
        let q = snap_quantum(r.kappa);
        let (halo, reach) = polylines::block_context(r);
        // (The margin covers the f32 rounding of the k-d tree's distances.)
        let reach = reach * 1.001 + 4.0 * q;
        BlockContext { blocks, origin, corners: Corners::new(grouped), r, halo, reach }
    }

    /// The box (relative to the origin) whose edge points block `b` needs.
    pub(crate) fn region(&self, b: u32) -> (DVec3, DVec3) {
        self.blocks.list[b as usize].around(self.reach)
    }
}

/// Sorts `edges` (world positions; those outside block `b`'s region are passed over) into the
/// block's own, those of its halo and the context of both, each put in the order of its
/// positions, whatever the tiles the points came from.
pub(crate) fn sort_edges<'e>(cx: &BlockContext, b: u32, edges: impl IntoIterator<Item = &'e WorldEdge>) -> BlockEdges {
    let region = cx.region(b);
    let grow_box = cx.blocks.list[b as usize].around(cx.halo);
    let mut sorted = BlockEdges::default();
    for e in edges.into_iter().filter(|e| in_box(region, e.p - cx.origin)) {
        let p = e.p - cx.origin;
        let to = if cx.blocks.owner(p) == Some(b) {
            &mut sorted.own
        } else if in_box(grow_box, p) {
            &mut sorted.around
        } else {
            &mut sorted.context
        };
        to.points.push(p);
        to.normals.push(e.n);
    }
    for s in [&mut sorted.own, &mut sorted.around, &mut sorted.context] {
        s.sort();
    }
    sorted
}

/// Stage 3 for block `b`'s sorted edge points: the own and halo points smoothed (with the
/// context) and confirmed, then split into the block's core (its own points that were
/// confirmed, with the count of those that were not) and its halo (the halo's confirmed
/// points), each in the order of its positions.
pub(crate) fn smooth_core(cx: &BlockContext, b: u32, edges: BlockEdges) -> (SmoothedEdges, SmoothedEdges) {
    let BlockEdges { own, around, context } = edges;
    let (n_own, n_around) = (own.points.len(), around.points.len());
    let points: Vec<DVec3> = own.points.iter().chain(&around.points).chain(&context.points).copied().collect();
    let normals: Vec<[glam::Vec3; 2]> = own.normals.iter().chain(&around.normals).chain(&context.normals).copied().collect();
    drop((own, around, context));
    let region = cx.region(b);
    let (smoothed, keep) = polylines::smooth_and_confirm(&points, &normals, n_own + n_around, &cx.corners.within(region.0, region.1), cx.r);
    let (mut core, mut halo) = (SmoothedEdges::default(), SmoothedEdges::default());
    for (i, (&p, k)) in smoothed.iter().zip(keep).enumerate() {
        let to = if i < n_own { &mut core } else { &mut halo };
        if k {
            to.points.push(p);
            to.normals.push(normals[i]);
        } else if i < n_own {
            to.unconfirmed += 1;
        }
    }
    core.sort();
    halo.sort();
    (core, halo)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::blocks::{plan, Census, BASE_STEPS};
    use crate::extract::params::Params;
    use glam::Vec3;

    /// Edge points along a line through two blocks: block 0 owns those in its box, its halo
    /// takes those within the growing halo past its border, the context those beyond it within
    /// the reach, and points farther are passed over; smoothed, a clean line keeps every point,
    /// its core points in the block and its halo points past it, on the line.
    #[test]
    fn a_blocks_edge_points_are_sorted_by_how_far_past_it_they_lie() {
        let r = Params::default().resolve(1.0, 0.0);
        let side = BASE_STEPS * r.step;
        let mut census = Census::new(side);
        let (y, z) = (0.5 * side, 0.5 * side);
        [DVec3::new(1.0, y, z), DVec3::new(side + 1.0, y, z)].into_iter().for_each(|p| census.add(p));
        let blocks = plan(&census);
        assert_eq!(blocks.list.len(), 2);
        let grouped = vec![];
        let origin = DVec3::new(1e5, -2e5, 30.0);
        let cx = BlockContext::new(&blocks, origin, &grouped, &r);
        let edges: Vec<WorldEdge> =
            (0..(4.0 * side / r.kappa) as usize).map(|k| WorldEdge { p: origin + DVec3::new(k as f64 * r.kappa, y, z), n: [Vec3::Y, Vec3::Z] }).collect();
        let sorted = sort_edges(&cx, 0, edges.iter().rev());
        let (halo, reach) = (cx.halo, cx.reach);
        let count = |f: &dyn Fn(f64) -> bool| edges.iter().filter(|e| f(e.p.x - origin.x)).count();
        assert_eq!(sorted.own.points.len(), count(&|x| x < side));
        assert_eq!(sorted.around.points.len(), count(&|x| x >= side && x <= side + halo));
        assert_eq!(sorted.context.points.len(), count(&|x| x > side + halo && x <= side + reach));
        assert!(sorted.own.points.windows(2).all(|w| w[0].x < w[1].x), "in the order of their positions");
        let (n_own, n_around) = (sorted.own.points.len(), sorted.around.points.len());
        let (core, halo_points) = smooth_core(&cx, 0, sorted);
        assert_eq!((core.points.len(), halo_points.points.len(), core.unconfirmed), (n_own, n_around, 0));
        assert!(core.points.iter().chain(&halo_points.points).all(|p| (p.y - y).abs() < 1e-6 && (p.z - z).abs() < 1e-6));
        assert!(core.points.iter().all(|p| p.x < side) && halo_points.points.iter().all(|p| p.x >= side));
    }
}
