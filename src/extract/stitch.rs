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
pub(crate) const JOIN_STEPS: f64 = 0.5;
/// Joined end vertices this close, in steps, become one.
pub(crate) const MERGE_STEPS: f64 = 0.25;

/// A stitched polyline: its vertices, and whether it is closed.
pub(crate) type Line = (Vec<DVec3>, bool);

/// Joins `pieces` (each with the block it came from, in a fixed order) into polylines, in the
/// order of their first piece. Crossings within `reach` of each other are paired; where two
/// joined vertices lie within `merge`, they become one at their midpoint. (The curve stage
/// stitches a cluster of pieces at a time, see [`super::sweep`].)
pub(crate) fn stitch(mut pieces: Vec<(u32, Piece)>, reach: f64, merge: f64) -> Vec<Line> {
    let links = pair_crossings(&pieces, reach);
    let mut seen = vec![false; pieces.len()];
    let mut out = vec![];
    for p in 0..pieces.len() {
        if seen[p] {
            continue;
        }
        seen[p] = true;
        if pieces[p].1.closed {
            out.push((std::mem::take(&mut pieces[p].1.v), true));
            continue;
        }
        let (first, mut enter, closed) = chain_start(&links, p);
        let (mut v, mut at) = (vec![], first);
        loop {
            seen[at] = true;
            let part = std::mem::take(&mut pieces[at].1.v);
            if enter == 0 {
                join(&mut v, part.into_iter(), merge);
            } else {
                join(&mut v, part.into_iter().rev(), merge);
            }
            match links[at][1 - enter] {
                Some((q, f)) if q != first => (at, enter) = (q, f),
                _ => break,
            }
        }
        // A chain that came round to its first piece: its two ends merged where they meet.
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
        let p = &pieces[i].1;
        let end = if e == 0 { p.v.first() } else { p.v.last() };
        p.ends[e].unwrap() - end.copied().unwrap_or_default()
    };
    let mut pairs = vec![];
    for (i, (block, p)) in pieces.iter().enumerate() {
        for e in 0..2 {
            let Some(c) = p.ends[e] else { continue };
            let k = cell(c);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        for &(j, f) in grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]).map_or(&[][..], |v| &v[..]) {
                            if (j, f) <= (i, e) || pieces[j].0 == *block {
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
    fn chains_round_a_circle_stitch_in_order_whichever_way_their_pieces_come() {
        // Chains of pieces round a circle (arc length s in [0, n)), piece k in block k between
        // its crossings at s = k and k + 1, given in shuffled order and each either way round.
        // A piece has one or two vertices inside its arc and, at random, one just inside either
        // crossing: two of those across a crossing lie within the merge distance and become
        // one, other joined vertices do not. A third of the chains have no crossing at s = 0.
        let mut rng = crate::rng::Rng::new(7);
        let (merge, reach) = (0.1, 0.05);
        let (mut merged, mut closed) = (0, 0);
        for round in 0..60 {
            // (Four pieces or more: each piece turns by 90 degrees at most, so that each comes
            // at its crossings from its own side.)
            let n = 4 + round % 6;
            let radius = n as f64 / std::f64::consts::TAU;
            let along = |s: f64| DVec3::new((s / radius).cos(), (s / radius).sin(), 0.0) * radius;
            let arc = |p: DVec3| (p.y.atan2(p.x) * radius).rem_euclid(n as f64);
            let broken = round % 3 == 0;
            let (mut pieces, mut arcs) = (vec![], vec![]);
            for k in 0..n {
                let k0 = k as f64;
                let mut s: Vec<f64> = (0..1 + rng.next_u64() % 2).map(|_| k0 + rng.range(0.2, 0.8)).collect();
                for near in [k0 + 0.03, k0 + 0.97] {
                    if rng.next_u64().is_multiple_of(2) {
                        s.push(near);
                    }
                }
                s.sort_by(f64::total_cmp);
                arcs.push(s.clone());
                let mut v: Vec<DVec3> = s.into_iter().map(along).collect();
                let lift = |r: &mut crate::rng::Rng| DVec3::Z * r.range(0.0, 0.01);
                let mut ends = [(!(broken && k == 0)).then(|| along(k0) + lift(&mut rng)), Some(along(k0 + 1.0) + lift(&mut rng))];
                if rng.next_u64().is_multiple_of(2) {
                    v.reverse();
                    ends.reverse();
                }
                pieces.push((k as u32, Piece { v, ends, closed: false }));
            }
            // Expected, in arc order: every vertex, those just inside a joined crossing from
            // both sides merged (at s = 0 only if the chain closes).
            let mut want: Vec<f64> = arcs.concat();
            let crossings = if broken { 1..n } else { 1..n + 1 };
            let joined: Vec<f64> =
                crossings.filter(|&k| arcs[k - 1].last().unwrap().fract() > 0.9 && arcs[k % n][0].fract() < 0.1).map(|k| (k % n) as f64).collect();
            want.retain(|&s| !joined.iter().any(|&c| (s - c).abs() < 0.1 || (s - c - n as f64).abs() < 0.1));
            want.extend(&joined);
            want.sort_by(f64::total_cmp);
            for i in (1..pieces.len()).rev() {
                pieces.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
            }
            let lines = stitch(pieces, reach, merge);
            assert_eq!(lines.len(), 1, "round {round}");
            let (v, is_closed) = &lines[0];
            // (A closed polyline has more than two vertices.)
            assert_eq!(*is_closed, !broken && want.len() > 2, "round {round}");
            // The vertices in order round the circle, one way or the other.
            let step = |a: DVec3, b: DVec3| (arc(b) - arc(a) + n as f64 / 2.0).rem_euclid(n as f64) - n as f64 / 2.0;
            let sign = step(v[0], v[1]).signum();
            let wrap = *is_closed as usize;
            for i in 0..v.len() - 1 + wrap {
                let d = step(v[i], v[(i + 1) % v.len()]) * sign;
                assert!(d > 0.0 && d < 1.6, "round {round}: {d} between vertices {i} and the next");
            }
            // (A vertex merged across s = 0 may come out just below n.)
            let mut got: Vec<f64> = v.iter().map(|&p| arc(p)).map(|s| if n as f64 - s < 1e-9 { 0.0 } else { s }).collect();
            got.sort_by(f64::total_cmp);
            assert_eq!(got.len(), want.len(), "round {round}");
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() < 1e-9, "round {round}: vertex at {g}, expected {w}");
            }
            merged += joined.len();
            closed += *is_closed as usize;
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

    #[test]
    fn two_pieces_of_a_cut_line_are_stitched() {
        use crate::extract::blocks::Piece;
        use crate::extract::stitch::stitch;
        use glam::DVec3;

        let x = |x: f64| DVec3::new(x, 0.0, 0.0);
        let left = Piece { v: vec![x(-2.0), x(-0.5)], ends: [None, Some(x(0.0))], closed: false };
        let right = Piece { v: vec![x(0.6), x(2.0)], ends: [Some(x(0.01)), None], closed: false };
        let lines = stitch(vec![(0, left), (1, right)], 0.5, 0.1);
        assert_eq!(lines, vec![(vec![x(-2.0), x(-0.5), x(0.6), x(2.0)], false)]);
    }
}
