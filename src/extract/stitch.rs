//! The stitcher: joins the pieces that the growth blocks cut at their borders (see
//! [`super::blocks`]) back into polylines, each border crossing once.
//!
//! Both blocks beside a border grow a polyline that crosses it (each on into its halo), and each
//! keeps its own side: so each crossing is seen twice, once from either side, at nearly the same
//! place. Ends of pieces of different blocks whose crossings lie within the join distance, and
//! that come at the border from opposite sides, are paired, nearest pairs first. A crossing left
//! without a partner is a free end, for completion to handle like any other.

use super::blocks::Piece;
use glam::DVec3;
use std::collections::HashMap;

/// Crossings of two pieces this close, in polyline steps, may be paired. (Both sides' traces
/// follow the same smoothed edge points, so their crossings lie a small part of a step apart;
/// a parallel crease is rarely as close.)
pub const JOIN_STEPS: f64 = 0.5;
/// Joined end vertices this close, in steps, become one.
pub const MERGE_STEPS: f64 = 0.25;

/// A stitched polyline: its vertices, and whether it is closed.
pub type Line = (Vec<DVec3>, bool);

/// Joins `pieces` (each with the block it came from, in a fixed order) into polylines, in the
/// order of their first piece. Crossings within `reach` of each other are paired; where two
/// joined vertices lie within `merge`, they become one at their midpoint.
///
/// ```
/// use crease::extract::blocks::Piece;
/// use crease::extract::stitch::stitch;
/// use glam::DVec3;
///
/// let x = |x: f64| DVec3::new(x, 0.0, 0.0);
/// let left = Piece { v: vec![x(-2.0), x(-0.5)], ends: [None, Some(x(0.0))], closed: false };
/// let right = Piece { v: vec![x(0.6), x(2.0)], ends: [Some(x(0.01)), None], closed: false };
/// let lines = stitch(vec![(0, left), (1, right)], 0.5, 0.1);
/// assert_eq!(lines, vec![(vec![x(-2.0), x(-0.5), x(0.6), x(2.0)], false)]);
/// ```
pub fn stitch(mut pieces: Vec<(u32, Piece)>, reach: f64, merge: f64) -> Vec<Line> {
    let links = pair_crossings(&pieces, reach);
    // (Each piece's vertices are moved into its line, not copied: the pieces and the lines
    // are never held whole side by side.)
    let mut seen = vec![false; pieces.len()];
    let mut out = vec![];
    for p in 0..pieces.len() {
        if seen[p] {
            continue;
        }
        if pieces[p].1.closed {
            seen[p] = true;
            out.push((std::mem::take(&mut pieces[p].1.v), true));
            continue;
        }
        // Back to the chain's first piece (or round a loop to this one).
        let (mut at, mut end) = (p, 0);
        let mut closed = false;
        while let Some((q, f)) = links[at][end] {
            (at, end) = (q, 1 - f);
            if at == p {
                closed = true;
                break;
            }
        }
        let (first, mut enter) = if closed { (p, 0) } else { (at, end) };
        let mut v: Vec<DVec3> = vec![];
        let mut at = first;
        loop {
            seen[at] = true;
            let piece = std::mem::take(&mut pieces[at].1.v);
            let part: Box<dyn Iterator<Item = DVec3>> = if enter == 0 { Box::new(piece.into_iter()) } else { Box::new(piece.into_iter().rev()) };
            join(&mut v, part, merge);
            match links[at][1 - enter] {
                Some((q, f)) if q != first => (at, enter) = (q, f),
                _ => break,
            }
        }
        if closed && v.len() > 2 && v[0].distance(v[v.len() - 1]) < merge {
            let last = v.pop().unwrap();
            v[0] = v[0].lerp(last, 0.5);
        }
        if v.len() >= 2 {
            let closed = closed && v.len() > 2;
            out.push((v, closed));
        }
    }
    out
}

/// Appends `part` to `v`, its first vertex merged with `v`'s last where they lie within `merge`.
fn join(v: &mut Vec<DVec3>, mut part: impl Iterator<Item = DVec3>, merge: f64) {
    if let Some(last) = v.last_mut() {
        if let Some(first) = part.next() {
            if last.distance(first) < merge {
                *last = last.lerp(first, 0.5);
            } else {
                v.push(first);
            }
        }
    }
    v.extend(part);
}

/// For each piece and end, the piece and end it is joined to.
fn pair_crossings(pieces: &[(u32, Piece)], reach: f64) -> Vec<[Option<(usize, usize)>; 2]> {
    let cell = |p: DVec3| (p / reach).floor().to_array().map(|x| x as i64);
    let mut grid: HashMap<[i64; 3], Vec<(usize, usize)>> = HashMap::new();
    for (i, (_, p)) in pieces.iter().enumerate() {
        for e in 0..2 {
            if let Some(c) = p.ends[e] {
                grid.entry(cell(c)).or_default().push((i, e));
            }
        }
    }
    // (Which way a piece comes at its crossing: from its end vertex to the crossing.)
    let outward = |i: usize, e: usize| {
        let v = &pieces[i].1.v;
        let end = if e == 0 { v[0] } else { v[v.len() - 1] };
        pieces[i].1.ends[e].unwrap() - end
    };
    let mut pairs = vec![];
    for (i, (bi, p)) in pieces.iter().enumerate() {
        for e in 0..2 {
            let Some(c) = p.ends[e] else { continue };
            let k = cell(c);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        for &(j, f) in grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]).map_or(&[][..], |v| &v[..]) {
                            if (j, f) <= (i, e) || pieces[j].0 == *bi {
                                continue;
                            }
                            let d = c.distance(pieces[j].1.ends[f].unwrap());
                            if d <= reach && outward(i, e).dot(outward(j, f)) <= 0.0 {
                                pairs.push((d, i, e, j, f));
                            }
                        }
                    }
                }
            }
        }
    }
    pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2, a.3, a.4).cmp(&(b.1, b.2, b.3, b.4))));
    let mut links = vec![[None; 2]; pieces.len()];
    for (_, i, e, j, f) in pairs {
        if links[i][e].is_none() && links[j][f].is_none() {
            links[i][e] = Some((j, f));
            links[j][f] = Some((i, e));
        }
    }
    links
}

#[cfg(test)]
mod tests {
    use super::*;

    fn piece(v: Vec<DVec3>, a: Option<DVec3>, b: Option<DVec3>) -> Piece {
        Piece { v, ends: [a, b], closed: false }
    }

    #[test]
    fn a_loop_cut_in_four_is_one_closed_polyline_again() {
        // A square loop around the corner shared by four blocks, each holding one side's
        // middle; pieces given in any direction.
        let p = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        let pieces = vec![
            (0, piece(vec![p(-1.0, -0.5), p(-0.5, -1.0)], Some(p(-1.0, 0.0)), Some(p(0.0, -1.0)))),
            (1, piece(vec![p(1.0, -0.5), p(0.5, -1.0)], Some(p(1.0, 0.0)), Some(p(0.0, -1.0)))),
            (2, piece(vec![p(1.0, 0.5), p(0.5, 1.0)], Some(p(1.0, 0.0)), Some(p(0.0, 1.0)))),
            (3, piece(vec![p(-0.5, 1.0), p(-1.0, 0.5)], Some(p(0.0, 1.0)), Some(p(-1.0, 0.0)))),
        ];
        let lines = stitch(pieces, 0.1, 0.01);
        assert_eq!(lines.len(), 1);
        assert!(lines[0].1);
        assert_eq!(lines[0].0, vec![p(-1.0, -0.5), p(-0.5, -1.0), p(0.5, -1.0), p(1.0, -0.5), p(1.0, 0.5), p(0.5, 1.0), p(-0.5, 1.0), p(-1.0, 0.5)]);
    }

    #[test]
    fn crossings_pair_nearest_first_across_blocks_only() {
        let x = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        // Two parallel curves 0.3 apart crossing the border x = 0, and a piece of the left block
        // whose crossing lies near theirs but which may not join its own block.
        let pieces = vec![
            (0, piece(vec![x(-1.0, 0.0), x(-0.4, 0.0)], None, Some(x(0.0, 0.0)))),
            (0, piece(vec![x(-1.0, 0.3), x(-0.4, 0.3)], None, Some(x(0.0, 0.3)))),
            (1, piece(vec![x(0.4, 0.28), x(1.0, 0.3)], Some(x(0.0, 0.28)), None)),
            (1, piece(vec![x(0.4, 0.02), x(1.0, 0.0)], Some(x(0.0, 0.02)), None)),
        ];
        let lines = stitch(pieces, 0.5, 0.01);
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0].0, vec![x(-1.0, 0.0), x(-0.4, 0.0), x(0.4, 0.02), x(1.0, 0.0)]);
        assert_eq!(lines[1].0, vec![x(-1.0, 0.3), x(-0.4, 0.3), x(0.4, 0.28), x(1.0, 0.3)]);
        // Pieces meeting from the same side of a border are not joined.
        let same = vec![(0, piece(vec![x(-1.0, 0.0)], None, Some(x(0.0, 0.0)))), (1, piece(vec![x(-0.5, 0.1)], None, Some(x(0.0, 0.05))))];
        assert_eq!(stitch(same, 0.5, 0.01).len(), 0, "single vertices, unjoined, are no polylines");
    }
}
