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

/// What the stitcher needs of a piece to plan the polylines: its end vertices, size, crossings
/// and block, not the vertices between (see [`plan`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PieceEnds {
    /// The block the piece was grown in.
    pub block: u32,
    /// Its first and last vertex.
    pub first: DVec3,
    /// See `first`.
    pub last: DVec3,
    /// Its number of vertices.
    pub len: u32,
    /// See [`Piece::ends`].
    pub ends: [Option<DVec3>; 2],
    /// See [`Piece::closed`].
    pub closed: bool,
}

impl PieceEnds {
    /// The ends of piece `p` of block `block`.
    pub fn of(block: u32, p: &Piece) -> PieceEnds {
        let (first, last) = (p.v.first().copied().unwrap_or_default(), p.v.last().copied().unwrap_or_default());
        PieceEnds { block, first, last, len: p.v.len() as u32, ends: p.ends, closed: p.closed }
    }
}

/// A stitched polyline before its vertices are gathered (see [`gather`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Its pieces in order, each as numbered in [`plan`]'s input and true if taken backwards.
    pub parts: Vec<(u32, bool)>,
    /// True for a closed polyline.
    pub closed: bool,
    /// True where the chain of pieces came round to its first and its two ends were merged.
    pub round: bool,
}

/// Joins `pieces` (each with the block it came from, in a fixed order) into polylines, in the
/// order of their first piece. Crossings within `reach` of each other are paired; where two
/// joined vertices lie within `merge`, they become one at their midpoint. (The curve stage
/// stitches a cluster of pieces at a time, see [`super::sweep`].)
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
pub fn stitch(pieces: Vec<(u32, Piece)>, reach: f64, merge: f64) -> Vec<Line> {
    let ends: Vec<PieceEnds> = pieces.iter().map(|(b, p)| PieceEnds::of(*b, p)).collect();
    plan(&ends, reach, merge).iter().map(|l| (gather(l, |k| &pieces[k as usize].1.v, merge), l.closed)).collect()
}

/// Plans the polylines that [`stitch`] makes of the pieces whose ends are `pieces`: which
/// pieces each joins and which way. Only the pieces' ends decide it: pieces are joined at
/// paired crossings, and only the end vertices of joined pieces are merged.
pub fn plan(pieces: &[PieceEnds], reach: f64, merge: f64) -> Vec<Plan> {
    let links = pair_crossings(pieces, reach);
    let mut seen = vec![false; pieces.len()];
    let mut out = vec![];
    for p in 0..pieces.len() {
        if seen[p] {
            continue;
        }
        if pieces[p].closed {
            seen[p] = true;
            out.push(Plan { parts: vec![(p as u32, false)], closed: true, round: false });
            continue;
        }
        let (first, mut enter, closed) = chain_start(&links, p);
        // The line's vertex count and end vertices as `gather` will join them.
        let (mut count, mut ends) = (0usize, [DVec3::ZERO; 2]);
        let mut parts = vec![];
        let mut at = first;
        loop {
            seen[at] = true;
            parts.push((at as u32, enter == 1));
            let e = &pieces[at];
            let (a, b) = if enter == 0 { (e.first, e.last) } else { (e.last, e.first) };
            let len = e.len as usize;
            if len > 0 {
                if count > 0 && ends[1].distance(a) < merge {
                    ends[1] = ends[1].lerp(a, 0.5);
                    if count == 1 {
                        ends[0] = ends[1];
                    }
                    if len > 1 {
                        ends[1] = b;
                    }
                    count += len - 1;
                } else {
                    if count == 0 {
                        ends[0] = a;
                    }
                    ends[1] = b;
                    count += len;
                }
            }
            match links[at][1 - enter] {
                Some((q, f)) if q != first => (at, enter) = (q, f),
                _ => break,
            }
        }
        let round = closed && count > 2 && ends[0].distance(ends[1]) < merge;
        count -= round as usize;
        if count >= 2 {
            let closed = closed && count > 2;
            out.push(Plan { parts, closed, round });
        }
    }
    out
}

/// Where the chain of linked pieces through piece `p` starts: its first piece and the end it
/// is entered by, back along the links; or, if the links come round to `p`, `p` itself and
/// true (a closed chain).
fn chain_start(links: &[[Option<(usize, usize)>; 2]], p: usize) -> (usize, usize, bool) {
    let (mut at, mut end) = (p, 0);
    while let Some((q, f)) = links[at][end] {
        (at, end) = (q, 1 - f);
        if at == p {
            return (p, 0, true);
        }
    }
    (at, end, false)
}

/// The vertices of the polyline `plan`, from the vertices of each piece (`piece`, by number).
pub fn gather<'a>(plan: &Plan, piece: impl Fn(u32) -> &'a [DVec3], merge: f64) -> Vec<DVec3> {
    let mut v: Vec<DVec3> = vec![];
    for &(k, backwards) in &plan.parts {
        let p = piece(k);
        if backwards {
            join(&mut v, p.iter().rev().copied(), merge);
        } else {
            join(&mut v, p.iter().copied(), merge);
        }
    }
    if plan.round {
        let last = v.pop().unwrap();
        v[0] = v[0].lerp(last, 0.5);
    }
    v
}

/// Appends `part` to `v`, its first vertex merged with `v`'s last where they lie within `merge`.
fn join(v: &mut Vec<DVec3>, mut part: impl Iterator<Item = DVec3>, merge: f64) {
    if let Some(last) = v.last_mut()
        && let Some(first) = part.next()
    {
        if last.distance(first) < merge {
            *last = last.lerp(first, 0.5);
        } else {
            v.push(first);
        }
    }
    v.extend(part);
}

/// For each piece and end, the piece and end it is joined to.
fn pair_crossings(pieces: &[PieceEnds], reach: f64) -> Vec<[Option<(usize, usize)>; 2]> {
    let cell = |p: DVec3| (p / reach).floor().to_array().map(|x| x as i64);
    let mut grid: HashMap<[i64; 3], Vec<(usize, usize)>> = HashMap::new();
    for (i, p) in pieces.iter().enumerate() {
        for e in 0..2 {
            if let Some(c) = p.ends[e] {
                grid.entry(cell(c)).or_default().push((i, e));
            }
        }
    }
    // (Which way a piece comes at its crossing: from its end vertex to the crossing.)
    let outward = |i: usize, e: usize| {
        let end = if e == 0 { pieces[i].first } else { pieces[i].last };
        pieces[i].ends[e].unwrap() - end
    };
    let mut pairs = vec![];
    for (i, p) in pieces.iter().enumerate() {
        for e in 0..2 {
            let Some(c) = p.ends[e] else { continue };
            let k = cell(c);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        for &(j, f) in grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]).map_or(&[][..], |v| &v[..]) {
                            if (j, f) <= (i, e) || pieces[j].block == p.block {
                                continue;
                            }
                            let d = c.distance(pieces[j].ends[f].unwrap());
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

    /// Stitching as it was done on whole pieces, before it was planned from their ends: each
    /// chain's vertices joined piece by piece, a loop's ends merged, short lines dropped.
    fn stitch_whole(pieces: &[(u32, Piece)], reach: f64, merge: f64) -> Vec<Line> {
        let ends: Vec<PieceEnds> = pieces.iter().map(|(b, p)| PieceEnds::of(*b, p)).collect();
        let links = pair_crossings(&ends, reach);
        let (mut seen, mut out) = (vec![false; pieces.len()], vec![]);
        for p in 0..pieces.len() {
            if seen[p] {
                continue;
            }
            let (first, mut enter, closed) = chain_start(&links, p);
            let (mut v, mut at) = (vec![], first);
            loop {
                seen[at] = true;
                let piece = pieces[at].1.v.clone();
                if enter == 0 {
                    join(&mut v, piece.into_iter(), merge);
                } else {
                    join(&mut v, piece.into_iter().rev(), merge);
                }
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

    #[test]
    fn planned_stitching_joins_as_whole_pieces_do() {
        // Chains of pieces of one to three vertices round a circle, each piece in a block of
        // its own, crossing into the next at whole arc lengths: the vertices lie at random along
        // each piece's arc, so that some joined end vertices merge (also a lone vertex with
        // both neighbours) and some do not; a third of the chains are broken, the rest close.
        let mut rng = crate::rng::Rng::new(7);
        let (mut merged, mut closed) = (0, 0);
        for round in 0..60 {
            let n = 2 + round % 7;
            let radius = n as f64 / std::f64::consts::TAU;
            let at = |s: f64| DVec3::new(s.cos(), s.sin(), 0.0) * radius;
            let along = |s: f64| at(s / radius);
            let mut pieces = vec![];
            for k in 0..n {
                let len = 1 + (rng.next_u64() % 3) as usize;
                let mut s: Vec<f64> = (0..len).map(|_| k as f64 + rng.range(0.0, 1.0)).collect();
                s.sort_by(f64::total_cmp);
                let broken = round % 3 == 0 && k == 0;
                let ends =
                    [(!broken).then(|| along(k as f64) + DVec3::Z * rng.range(0.0, 0.01)), Some(along((k + 1) as f64) + DVec3::Z * rng.range(0.0, 0.01))];
                pieces.push((k as u32, Piece { v: s.into_iter().map(along).collect(), ends, closed: false }));
            }
            let (reach, merge) = (0.05, 0.3);
            let whole = stitch_whole(&pieces, reach, merge);
            assert_eq!(stitch(pieces.clone(), reach, merge), whole, "round {round}");
            let ends: Vec<PieceEnds> = pieces.iter().map(|(b, p)| PieceEnds::of(*b, p)).collect();
            for (plan, (v, _)) in plan(&ends, reach, merge).iter().zip(&whole) {
                merged += plan.parts.iter().map(|&(k, _)| ends[k as usize].len as usize).sum::<usize>() - v.len();
                closed += plan.closed as usize;
            }
        }
        assert!(merged > 20 && closed > 10, "{merged} vertices merged, {closed} closed");
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
