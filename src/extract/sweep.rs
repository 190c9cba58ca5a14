//! The stitched set by region: the growth blocks' pieces taken a slab of blocks at a time (see
//! [`super::blocks::Blocks::slabs`]) and handed on in clusters that the rest of the curve stage
//! can finish alone, so that it never holds every piece of the cloud.
//!
//! Stitching pairs crossings within the join distance, and each crossing's rivals for a
//! partner lie within that distance of it. Grouping links lines where a vertex of one lies
//! within twice completion's reach of an end of the other (see [`super::groups`]); a line's
//! vertices and ends are its pieces' vertices and end vertices, or midpoints of two of them
//! within the merge distance. So pieces are clustered by a superset of both links: crossings
//! within the join distance, and a vertex within the link distance (twice the reach plus twice
//! the merge distance) of another piece's end vertex. A cluster is a union of whole lines and
//! whole groups, with every rival of its crossings inside it: stitching it alone, then
//! grouping and completing its lines, gives the curves that doing so for all pieces gives for
//! it. A cluster is handed on once the sweep is past it, when every piece yet to come lies
//! farther than both distances from every piece of it.
//!
//! Clusters are as large as the links make them, and where edge pieces lie thick everywhere
//! (tree crowns of a wooded aerial scan) they percolate: one cluster can reach across the
//! whole scan. So a cluster is bounded: once its pieces hold more than
//! [`MAX_CLUSTER_VERTICES`], those the sweep is past are handed on as a cluster of their own
//! and the rest go on. That cut is the one place where the curves can differ from finishing
//! all pieces at once: a line across it comes out in two, and completion does not look across
//! it. It depends only on the pieces and the blocks (world-aligned, sized in the spacing), so
//! the curves still do not depend on the tiling, the thread count or `--memory`; the curve
//! stage counts the cuts and warns of them.

use super::blocks::Piece;
use crate::grid::HashGrid;
use crate::sets::Sets;
use glam::DVec3;

/// A piece in the sweep: its number (pieces are numbered in a fixed order, whatever the
/// slabs), the block it was grown in, and the piece.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Held {
    /// The piece's number.
    pub id: u64,
    /// Its block.
    pub block: u32,
    /// The piece.
    pub piece: Piece,
}

impl Held {
    /// The piece's end vertices, if it has ends (a closed piece has none).
    fn end_vertices(&self) -> impl Iterator<Item = DVec3> + '_ {
        let v = &self.piece.v;
        let open = !self.piece.closed && !v.is_empty();
        open.then(|| [v[0], v[v.len() - 1]]).into_iter().flatten()
    }

    /// The farthest the piece reaches along `axis`: its vertices' and crossings'.
    fn reach_along(&self, axis: usize) -> f64 {
        self.piece.v.iter().chain(self.piece.ends.iter().flatten()).map(|p| p[axis]).fold(f64::NEG_INFINITY, f64::max)
    }
}

/// Most vertices a cluster's pieces may hold before the pieces the sweep is past are cut off
/// and handed on (see the module notes): about 40 MB while the cluster is stitched and
/// completed, and some hundred times the largest cluster we have seen (in a wooded aerial scan).
pub(crate) const MAX_CLUSTER_VERTICES: usize = 1 << 18;

/// The sweep: the pieces whose clusters may still grow.
pub(crate) struct Sweep {
    axis: usize,
    join: f64,
    link: f64,
    /// Most vertices of a cluster (see [`MAX_CLUSTER_VERTICES`]).
    most: usize,
    /// Clusters cut so far.
    cuts: u64,
    /// The pieces held, in order, each with its cluster's number (as numbered when last
    /// handed back).
    front: Vec<(Held, u32)>,
}

impl Sweep {
    /// A sweep along `axis` that clusters pieces whose crossings lie within `join`, or a vertex
    /// of one within `link` of an end vertex of the other.
    pub(crate) fn new(axis: usize, join: f64, link: f64) -> Sweep {
        Sweep { axis, join, link, most: MAX_CLUSTER_VERTICES, cuts: 0, front: vec![] }
    }

    #[cfg(test)]
    /// The same sweep with clusters cut once they hold more than `most` vertices.
    pub(crate) fn bounded(self, most: usize) -> Sweep {
        Sweep { most, ..self }
    }

    /// The number of times a cluster was cut because it outgrew the bound.
    pub(crate) fn cuts(&self) -> u64 {
        self.cuts
    }

    /// The number of pieces held, waiting for their clusters to be complete.
    pub(crate) fn held(&self) -> usize {
        self.front.len()
    }

    /// Adds `slab`'s pieces, numbered after every piece added before, and returns the clusters
    /// that no piece yet to come can join, given that every such piece lies at `beyond` or
    /// farther along the axis (infinity after the last slab): each cluster its pieces in order,
    /// the clusters in the order of their first pieces. (A cluster cut for its size, see
    /// [`MAX_CLUSTER_VERTICES`], comes where the whole would have.)
    pub(crate) fn add(&mut self, slab: Vec<Held>, beyond: f64) -> Vec<Vec<Held>> {
        let mut items: Vec<(Held, Option<u32>)> =
            std::mem::take(&mut self.front).into_iter().map(|(h, c)| (h, Some(c))).chain(slab.into_iter().map(|h| (h, None))).collect();
        items.sort_by_key(|(h, _)| h.id);
        let mut sets = Sets::new(items.len());
        // (Pieces of one cluster stay together: they were linked when they were added.)
        let mut first_of = std::collections::HashMap::new();
        for (i, (_, c)) in items.iter().enumerate() {
            if let Some(c) = c {
                sets.union(*first_of.entry(*c).or_insert(i as u32), i as u32);
            }
        }
        // Each new piece against all pieces, and the pieces held before against the new ones:
        // every pair is tested when the later of the two is added, never again.
        let mut crossings = HashGrid::new(self.join);
        let mut ends = HashGrid::new(self.link);
        for (i, (h, _)) in items.iter().enumerate() {
            h.piece.ends.iter().flatten().for_each(|&c| crossings.insert(c, (i as u32, c)));
            h.end_vertices().for_each(|e| ends.insert(e, (i as u32, e)));
        }
        for (i, (h, held)) in items.iter().enumerate() {
            let wanted = |j: u32| held.is_none() || items[j as usize].1.is_none();
            let mut linked = vec![];
            for &c in h.piece.ends.iter().flatten() {
                crossings.near(c, self.join, |(j, d)| {
                    if wanted(j) && c.distance(d) <= self.join {
                        linked.push(j);
                    }
                });
            }
            for &p in &h.piece.v {
                ends.near(p, self.link, |(j, e)| {
                    if wanted(j) && p.distance(e) <= self.link {
                        linked.push(j);
                    }
                });
            }
            linked.into_iter().for_each(|j| sets.union(i as u32, j));
        }
        let reach = self.join.max(self.link);
        let mut slots: Vec<Option<Held>> = items.into_iter().map(|(h, _)| Some(h)).collect();
        let (mut done, mut waiting) = (vec![], 0);
        let past = |h: &Held| h.reach_along(self.axis) + reach < beyond;
        for cluster in sets.sets() {
            let mut pieces: Vec<Held> = cluster.iter().filter_map(|&i| slots[i as usize].take()).collect();
            if pieces.iter().all(past) {
                done.push(pieces);
                continue;
            }
            if pieces.iter().map(|h| h.piece.v.len()).sum::<usize>() > self.most {
                let (behind, ahead): (Vec<Held>, Vec<Held>) = pieces.into_iter().partition(past);
                if !behind.is_empty() {
                    done.push(behind);
                    self.cuts += 1;
                }
                pieces = ahead;
            }
            self.front.extend(pieces.into_iter().map(|h| (h, waiting)));
            waiting += 1;
        }
        self.front.sort_by_key(|(h, _)| h.id);
        done
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::blocks::{cut, Blocks, HALO_STEPS};
    use crate::extract::{groups, stitch};

    /// Lines as grouping sees them, each group a list of its lines' exact vertices and closure,
    /// the groups sorted.
    fn canonical(lines: Vec<stitch::Line>, reach: f64) -> Vec<Vec<(Vec<[u64; 3]>, bool)>> {
        let mut out: Vec<Vec<(Vec<[u64; 3]>, bool)>> = groups::groups(&lines, reach)
            .into_iter()
            .map(|g| g.iter().map(|&i| (lines[i as usize].0.iter().map(|p| p.to_array().map(f64::to_bits)).collect(), lines[i as usize].1)).collect())
            .collect();
        out.sort();
        out
    }

    #[test]
    fn clusters_stitch_and_group_as_all_pieces_do() {
        // Random smooth walks (some closed loops) through 16 x 2 blocks of 8 units, cut at the
        // blocks' borders as growing does; ends of many walks lie near other walks.
        let step = 0.3;
        let (join, merge, reach) = (stitch::JOIN_STEPS * step, stitch::MERGE_STEPS * step, 4.0 * step);
        let cells: Vec<[[i64; 3]; 2]> = (0..16).flat_map(|x| (0..2).map(move |y| [[x * 8, y * 8, 0], [x * 8 + 8, y * 8 + 8, 8]])).collect();
        let blocks = Blocks::from_cells(1.0, cells);
        let halo = HALO_STEPS * step;
        for seed in 1..=6 {
            let mut rng = crate::rng::Rng::new(seed);
            let mut walks: Vec<(Vec<DVec3>, bool)> = vec![];
            for k in 0..60 {
                let mut p = DVec3::new(rng.range(1.0, 127.0), rng.range(1.0, 15.0), rng.range(1.0, 7.0));
                if k % 6 == 1 {
                    // Start near a vertex of an earlier walk.
                    let w = &walks[(rng.next_u64() % walks.len() as u64) as usize].0;
                    p = w[(rng.next_u64() % w.len() as u64) as usize] + DVec3::new(rng.range(-0.8, 0.8), rng.range(-0.8, 0.8), 0.0);
                }
                if k % 10 == 9 {
                    let r = rng.range(0.5, 3.0);
                    let n = (std::f64::consts::TAU * r / step) as usize;
                    let at = |i: usize| i as f64 / n as f64 * std::f64::consts::TAU;
                    let v = (0..n).map(|i| p + DVec3::new(at(i).cos(), at(i).sin(), 0.0) * r).collect();
                    walks.push((v, true));
                    continue;
                }
                let mut a = rng.range(0.0, std::f64::consts::TAU);
                let n = 5 + (rng.next_u64() % 40) as usize;
                let mut v = vec![p];
                for _ in 1..n {
                    a += rng.range(-0.2, 0.2);
                    p += DVec3::new(a.cos(), a.sin(), rng.range(-0.1, 0.1)) * step;
                    v.push(p);
                }
                walks.push((v, false));
            }
            // At each border across the slabs, a line ending 2.2 before it, and in the next slab
            // one passing 2.3 from that end: one group, which only the full margin keeps whole.
            for x in (8..128).step_by(8) {
                let (x, y) = (x as f64, 2.0 + rng.range(0.0, 12.0));
                walks.push(((0..8).map(|i| DVec3::new(x - 4.3 + 0.3 * i as f64, y, 4.0)).collect(), false));
                walks.push(((0..8).map(|i| DVec3::new(x + 0.1, y - 1.0 + 0.3 * i as f64, 4.0)).collect(), false));
            }
            let mut pieces = vec![];
            for (b, block) in blocks.list.iter().enumerate() {
                let mut k = 0u64;
                for (v, closed) in &walks {
                    for piece in cut(v, *closed, block, |p| blocks.find(p, halo) == Some(b as u32)) {
                        pieces.push(Held { id: (b as u64) << 32 | k, block: b as u32, piece });
                        k += 1;
                    }
                }
            }
            let all = stitch::stitch(pieces.iter().map(|h| (h.block, h.piece.clone())).collect(), join, merge);
            let whole = canonical(all, reach);

            let (axis, slabs) = blocks.slabs();
            let mut sweep = Sweep::new(axis, join, 2.0 * reach * (1.0 + 1e-9) + 2.0 * merge);
            let (mut parts, mut early, mut most) = (vec![], 0, 0);
            for (k, slab) in slabs.iter().enumerate() {
                let held: Vec<Held> = pieces.iter().filter(|h| slab.contains(&h.block)).cloned().collect();
                let beyond = slabs.get(k + 1).map_or(f64::INFINITY, |next| blocks.reach_below(next, axis, halo));
                let done = sweep.add(held, beyond);
                most = most.max(sweep.held());
                if k + 1 < slabs.len() {
                    early += done.len();
                }
                for cluster in done {
                    let lines = stitch::stitch(cluster.into_iter().map(|h| (h.block, h.piece)).collect(), join, merge);
                    parts.extend(canonical(lines, reach));
                }
            }
            parts.sort();
            eprintln!("seed {seed}: {early} clusters early, at most {most} of {} pieces held, {} groups", pieces.len(), whole.len());
            // (The sweep must have handed clusters on before its end, and held less than all,
            // for this to say anything.)
            assert!(early >= 5 && most < pieces.len() * 2 / 3, "seed {seed}: {early} clusters early, at most {most} of {} pieces held", pieces.len());
            assert!(whole.len() > 10 && whole.iter().any(|g| g.len() > 2), "seed {seed}: {} groups", whole.len());
            assert_eq!(parts, whole, "seed {seed}");
        }
    }

    #[test]
    fn a_cluster_reaching_across_the_scan_is_cut_where_the_sweep_is_past_it() {
        // A thicket: short pieces scattered along a band through 16 blocks, each within the
        // link distance of the next, so that all of them are one cluster.
        let step = 0.3;
        let (join, merge, reach) = (stitch::JOIN_STEPS * step, stitch::MERGE_STEPS * step, 4.0 * step);
        let link = 2.0 * reach * (1.0 + 1e-9) + 2.0 * merge;
        let cells: Vec<[[i64; 3]; 2]> = (0..16).map(|x| [[x * 8, 0, 0], [x * 8 + 8, 8, 8]]).collect();
        let blocks = Blocks::from_cells(1.0, cells);
        let halo = HALO_STEPS * step;
        let mut rng = crate::rng::Rng::new(7);
        let mut pieces = vec![];
        let mut x = 0.5;
        while x < 127.0 {
            let (y, z) = (rng.range(3.0, 4.0), rng.range(3.0, 4.0));
            let v: Vec<DVec3> = (0..4).map(|i| DVec3::new(x + step * i as f64, y, z)).collect();
            for (b, block) in blocks.list.iter().enumerate() {
                for piece in cut(&v, false, block, |p| blocks.find(p, halo) == Some(b as u32)) {
                    pieces.push(Held { id: pieces.len() as u64, block: b as u32, piece });
                }
            }
            x += 1.2;
        }
        let (axis, slabs) = blocks.slabs();
        let sweep_all = |mut sweep: Sweep| {
            let (mut clusters, mut most) = (vec![], 0);
            for (k, slab) in slabs.iter().enumerate() {
                let held: Vec<Held> = pieces.iter().filter(|h| slab.contains(&h.block)).cloned().collect();
                let beyond = slabs.get(k + 1).map_or(f64::INFINITY, |next| blocks.reach_below(next, axis, halo));
                clusters.extend(sweep.add(held, beyond));
                most = most.max(sweep.front.iter().map(|(h, _)| h.piece.v.len()).sum::<usize>());
            }
            (clusters, most, sweep.cuts())
        };
        let vertices = |c: &[Held]| c.iter().map(|h| h.piece.v.len()).sum::<usize>();
        let all = vertices(&pieces);
        let (whole, most_whole, cuts) = sweep_all(Sweep::new(axis, join, link));
        assert_eq!((whole.len(), cuts), (1, 0), "the thicket must be one cluster for this to say anything");
        assert!(most_whole > all * 3 / 4, "held {most_whole} of {all} vertices");

        let bound = 60;
        let (parts, most, cuts) = sweep_all(Sweep::new(axis, join, link).bounded(bound));
        // (A slab of this thicket holds about 30 vertices: the bound, and what came since the
        // last cut, stay held.)
        let slab_vertices = pieces.iter().filter(|h| slabs[1].contains(&h.block)).map(|h| h.piece.v.len()).sum::<usize>();
        eprintln!("{cuts} cuts, at most {most} vertices held of {all}, a slab {slab_vertices}");
        assert!(cuts >= 5 && parts.len() as u64 == cuts + 1, "{cuts} cuts, {} clusters", parts.len());
        assert!(most <= bound + 2 * slab_vertices, "held {most} vertices of {all}, bound {bound}");
        assert!(parts.iter().all(|c| vertices(c) <= bound + 2 * slab_vertices));
        let mut ids: Vec<u64> = parts.iter().flatten().map(|h| h.id).collect();
        ids.sort();
        assert_eq!(ids, (0..pieces.len() as u64).collect::<Vec<_>>(), "every piece handed on once");
    }

    #[test]
    fn a_cut_line_waits_for_the_next_slab() {
        use crate::extract::blocks::Piece;
        use crate::extract::sweep::{Held, Sweep};
        use glam::DVec3;

        let x = |x: f64| DVec3::new(x, 0.0, 0.0);
        let held = |id, block, v: Vec<DVec3>, ends| Held { id, block, piece: Piece { v, ends, closed: false } };
        let mut sweep = Sweep::new(0, 0.5, 2.0);
        // A line cut at x = 10 by the first slab's block: it may go on in the next slab.
        let first = vec![held(0, 0, vec![x(1.0), x(2.0)], [None, None]), held(1, 0, vec![x(8.0), x(9.5)], [None, Some(x(10.0))])];
        let done = sweep.add(first, 6.0);
        assert_eq!(done.len(), 1);
        assert_eq!(done[0][0].id, 0);
        let done = sweep.add(vec![held(2, 1, vec![x(10.5), x(12.0)], [Some(x(10.0)), None])], f64::INFINITY);
        assert_eq!(done.iter().map(|c| c.iter().map(|h| h.id).collect()).collect::<Vec<Vec<u64>>>(), vec![vec![1, 2]]);
    }
}
