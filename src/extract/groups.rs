//! Groups of stitched lines that completion (stage 5) can complete apart, so that the curve
//! stage holds one group at a time rather than every line of the cloud.
//!
//! Completion acts only at free ends, and an end looks no farther than the reach. An end never
//! moves: it is joined, attached to a corner, or left. What an end finds is a vertex within the
//! reach of it: one the line had, or one completion added, which is a corner that some other
//! end within the reach of it was attached to. So whatever an end of line A acts on lies within
//! twice the reach of an end of A or of a line A's ends interact with, and a corner of the
//! projection stage is claimed only by ends within the reach of it, so within twice the reach
//! of each other. Lines are linked where a vertex of one lies within twice the reach of an end
//! of the other; the groups are the linked sets. Completion of a group alone, with the corners
//! within the reach of its ends, then gives exactly the curves completion of all lines gives
//! for it: the actions of separate groups never touch the same curve or corner, and within a
//! group they come in the same order (lines keep their relative order; see
//! `groups_complete_as_the_whole_does` in [`super::complete`]).

use crate::grid::HashGrid;
use crate::sets::Sets;
use glam::DVec3;

/// The groups of `lines` (each its vertices, and true if closed) for completion that looks
/// `reach` ahead: each group its lines in order, the groups in the order of their first lines.
pub(crate) fn groups(lines: &[(Vec<DVec3>, bool)], reach: f64) -> Vec<Vec<u32>> {
    // (The margin covers the rounding of distances summed along two reaches.)
    let radius = 2.0 * reach * (1.0 + 1e-9);
    let mut ends = HashGrid::new(radius);
    for (i, (v, closed)) in lines.iter().enumerate() {
        if !closed && !v.is_empty() {
            ends.insert(v[0], (i as u32, v[0]));
            ends.insert(v[v.len() - 1], (i as u32, v[v.len() - 1]));
        }
    }
    let mut sets = Sets::new(lines.len());
    for (i, (v, _)) in lines.iter().enumerate() {
        for &p in v {
            ends.near(p, radius, |(other, q)| {
                if q.distance(p) <= radius {
                    sets.union(i as u32, other);
                }
            });
        }
    }
    sets.sets()
}

/// The corners of the projection stage in the order of their x, for handing each block or
/// batch of groups those near it, without indexing every corner of the cloud at once.
pub(crate) struct Corners<'a> {
    all: &'a [DVec3],
    along_x: Vec<u32>,
}

impl<'a> Corners<'a> {
    /// Sorts `all` along x.
    pub(crate) fn new(all: &'a [DVec3]) -> Corners<'a> {
        let mut along_x: Vec<u32> = (0..all.len() as u32).collect();
        along_x.sort_unstable_by(|&a, &b| all[a as usize].x.total_cmp(&all[b as usize].x).then(a.cmp(&b)));
        Corners { all, along_x }
    }

    /// The corners in the closed box `[lo, hi]`, by number, in their order.
    fn numbers_in(&self, lo: DVec3, hi: DVec3) -> Vec<u32> {
        let from = self.along_x.partition_point(|&k| self.all[k as usize].x < lo.x);
        let to = self.along_x.partition_point(|&k| self.all[k as usize].x <= hi.x).max(from);
        let p = |k: u32| self.all[k as usize];
        let mut found: Vec<u32> = self.along_x[from..to].iter().copied().filter(|&k| p(k).cmpge(lo).all() && p(k).cmple(hi).all()).collect();
        found.sort_unstable();
        found
    }

    /// The corners in the closed box `[lo, hi]`, in their order.
    pub(crate) fn within(&self, lo: DVec3, hi: DVec3) -> Vec<DVec3> {
        self.numbers_in(lo, hi).into_iter().map(|k| self.all[k as usize]).collect()
    }

    /// The corners within `reach` of the box `[lo, hi]`, indexed for handing out those within
    /// `reach` of ends in the box.
    pub(crate) fn near_box(&self, lo: DVec3, hi: DVec3, reach: f64) -> NearCorners<'a> {
        // (The margin covers the rounding of the distances.)
        let reach = reach * (1.0 + 1e-9);
        let m = DVec3::splat(reach * (1.0 + 1e-9));
        let mut grid = HashGrid::new(reach.max(f64::MIN_POSITIVE));
        for k in self.numbers_in(lo - m, hi + m) {
            grid.insert(self.all[k as usize], k);
        }
        NearCorners { all: self.all, grid, reach }
    }
}

/// Some of the corners of the projection stage, indexed (see [`Corners::near_box`]).
pub(crate) struct NearCorners<'a> {
    all: &'a [DVec3],
    grid: HashGrid<u32>,
    reach: f64,
}

impl NearCorners<'_> {
    /// The corners within the reach of any of `ends`, in their order.
    pub(crate) fn near(&self, ends: impl IntoIterator<Item = DVec3>) -> Vec<DVec3> {
        let mut found = vec![];
        for x in ends {
            self.grid.near(x, self.reach, |k| {
                if self.all[k as usize].distance(x) <= self.reach {
                    found.push(k);
                }
            });
        }
        found.sort_unstable();
        found.dedup();
        found.into_iter().map(|k| self.all[k as usize]).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_link_through_ends_within_twice_the_reach() {
        let x = |x: f64| DVec3::new(x, 0.0, 0.0);
        // Line 0 ends at 0 and 1; line 1 passes 1.9 from line 0's end (linked at reach 1);
        // line 2 lies 2.5 from every end; line 3 is closed, its vertex 0.5 from line 2's end.
        let lines = [vec![x(0.0), x(1.0)], vec![x(2.9), x(3.0)], vec![x(6.0), x(7.0)], vec![x(7.5), x(8.0), x(7.7)]];
        let lines: Vec<(Vec<DVec3>, bool)> = lines.into_iter().enumerate().map(|(i, v)| (v, i == 3)).collect();
        assert_eq!(groups(&lines, 1.0), vec![vec![0, 1], vec![2, 3]]);
    }
}
