//! The per-tile results of the tile passes, and the curve stage's per-block results, as
//! records of the codec (see [`crate::codec`]): one file a tile (or block) and pass,
//! `<dir>/<number>.bin`, written atomically.

use crate::codec::{self, Reader, Writer};
use crate::curves::{Polyline, Shape, Vertex};
use crate::error::{Error, Result};
use crate::extract::blocks::{Block, Blocks, Piece};
use crate::extract::candidates::{Residual, TileResiduals};
use crate::extract::polylines::SmoothedEdges;
use crate::extract::statistics::PointStats;
use crate::extract::{Counts, TileEdges, WorldCorner, WorldEdge};
use crate::workspace::Workspace;
use glam::{DVec3, Vec3};
use std::path::Path;

/// A tile pass's result for one tile, as stored.
pub(crate) trait Record: Sized {
    /// The codec kind.
    const KIND: [u8; 4];
    /// The directory of the pass's results.
    const DIR: &'static str;
    /// Appends the record's fields.
    fn encode(&self, w: &mut Writer);
    /// Reads the fields back.
    fn decode(r: &mut Reader) -> Result<Self>;
}

/// The name of tile `t`'s result in directory `dir`.
pub(crate) fn name(dir: &str, t: u32) -> String {
    format!("{dir}/{t}.bin")
}

/// Stores tile `t`'s result atomically.
pub(crate) fn write<R: Record>(ws: &Workspace, t: u32, rec: &R) -> Result<()> {
    let mut w = Writer::default();
    rec.encode(&mut w);
    let name = name(R::DIR, t);
    let mut zc = zstd::bulk::Compressor::new(1).map_err(|e| Error::output(ws.path(&name), e))?;
    let bytes = codec::frame(R::KIND, &[], &w.0, &mut zc).map_err(|e| Error::output(ws.path(&name), e))?;
    ws.write_atomic(&name, &bytes)
}

/// Reads tile `t`'s result.
pub(crate) fn read<R: Record>(ws: &Workspace, t: u32) -> Result<R> {
    let name = name(R::DIR, t);
    let path = ws.path(&name);
    let bytes = ws.read(&name)?.ok_or_else(|| Error::damaged(&path, "missing"))?;
    let raw = codec::unframe(&bytes, R::KIND, &path)?;
    decode_all(&raw, &path)
}

fn decode_all<R: Record>(raw: &[u8], path: &Path) -> Result<R> {
    let mut r = Reader::new(raw, path);
    let rec = R::decode(&mut r)?;
    r.finish()?;
    Ok(rec)
}

/// How many of a tile's own points were dropped as copies of others as it was loaded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Dropped {
    /// At the very position of another.
    pub exact: u64,
    /// Within the near-duplicate radius of another (see `pass::Loading::near`).
    pub near: u64,
}

/// The statistics of a tile's sampled points, in global id order, and the copies of the tile's
/// own points that were dropped as it was loaded.
pub(crate) struct Stats {
    /// The sampled points' statistics.
    pub stats: Vec<PointStats>,
    /// The tile's own points dropped as copies.
    pub dropped: Dropped,
}

impl Record for Stats {
    const KIND: [u8; 4] = *b"STAT";
    const DIR: &'static str = "stats";

    fn encode(&self, w: &mut Writer) {
        w.u64(self.dropped.exact);
        w.u64(self.dropped.near);
        w.u64(self.stats.len() as u64);
        for s in &self.stats {
            w.f64(s.spacing);
            w.f64(s.noise);
            w.f64(s.density);
            w.u8(s.twin as u8);
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let dropped = Dropped { exact: r.u64()?, near: r.u64()? };
        let n = r.count(25)?;
        let one = |r: &mut Reader| Ok(PointStats { spacing: r.f64()?, noise: r.f64()?, density: r.f64()?, twin: r.u8()? != 0 });
        let stats = (0..n).map(|_| one(r)).collect::<Result<_>>()?;
        Ok(Stats { stats, dropped })
    }
}

/// The statistics of a tile measured again with near duplicates collapsed (see
/// [`crate::extract::statistics::near_duplicate_radius`]): kept apart from the first
/// measurement's, so that a worker still writing those cannot mix them in.
pub(crate) struct NearStats(pub(crate) Stats);

impl Record for NearStats {
    const KIND: [u8; 4] = *b"STAN";
    const DIR: &'static str = "stats_near";

    fn encode(&self, w: &mut Writer) {
        self.0.encode(w)
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        Stats::decode(r).map(NearStats)
    }
}

impl From<Stats> for NearStats {
    fn from(s: Stats) -> NearStats {
        NearStats(s)
    }
}

/// The residuals of a tile's core points.
pub(crate) struct Residuals(pub TileResiduals);

impl Record for Residuals {
    const KIND: [u8; 4] = *b"RESI";
    const DIR: &'static str = "resid";

    fn encode(&self, w: &mut Writer) {
        let t = &self.0;
        w.u64(t.gid.len() as u64);
        for (g, r) in t.gid.iter().zip(&t.residual) {
            w.u64(*g);
            w.f32(r.value);
            w.u8(r.crease as u8);
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let n = r.count(13)?;
        let mut t = TileResiduals { gid: Vec::with_capacity(n), residual: Vec::with_capacity(n) };
        for _ in 0..n {
            t.gid.push(r.u64()?);
            t.residual.push(Residual { value: r.f32()?, crease: r.u8()? != 0 });
        }
        Ok(Residuals(t))
    }
}

/// The edge and corner points of a tile's candidates.
pub(crate) struct Edges(pub TileEdges);

fn dvec3(r: &mut Reader) -> Result<DVec3> {
    Ok(DVec3::new(r.f64()?, r.f64()?, r.f64()?))
}

fn put_dvec3(w: &mut Writer, p: DVec3) {
    p.to_array().iter().for_each(|&x| w.f64(x));
}

fn vec3(r: &mut Reader) -> Result<Vec3> {
    Ok(Vec3::new(r.f32()?, r.f32()?, r.f32()?))
}

/// An edge point as stored: its position (f64) and its two normals (f32), 48 bytes.
fn put_edge(w: &mut Writer, p: DVec3, n: &[Vec3; 2]) {
    put_dvec3(w, p);
    n.iter().flat_map(|n| n.to_array()).for_each(|x| w.f32(x));
}

fn get_edge(r: &mut Reader) -> Result<(DVec3, [Vec3; 2])> {
    Ok((dvec3(r)?, [vec3(r)?, vec3(r)?]))
}

impl Record for Edges {
    const KIND: [u8; 4] = *b"EDGE";
    const DIR: &'static str = "edges";

    fn encode(&self, w: &mut Writer) {
        let t = &self.0;
        w.u64(t.candidates);
        w.u64(t.one_surface);
        w.u64(t.scattered);
        w.u64(t.edges.len() as u64);
        for e in &t.edges {
            put_edge(w, e.p, &e.n);
        }
        w.u64(t.corners.len() as u64);
        for c in &t.corners {
            put_dvec3(w, c.p);
            w.f64(c.w);
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let (candidates, one_surface, scattered) = (r.u64()?, r.u64()?, r.u64()?);
        let n = r.count(48)?;
        let edges = (0..n).map(|_| get_edge(r).map(|(p, n)| WorldEdge { p, n })).collect::<Result<_>>()?;
        let n = r.count(32)?;
        let corners = (0..n).map(|_| Ok(WorldCorner { p: dvec3(r)?, w: r.f64()? })).collect::<Result<_>>()?;
        Ok(Edges(TileEdges { edges, corners, candidates, one_surface, scattered }))
    }
}

/// A batch of the run's finished curves, numbered in order: what the curve stage hands the
/// writers, so that it need not hold every curve at once (see [`super::curves`]).
pub(crate) struct Finished(pub Vec<Polyline>);

impl Record for Finished {
    const KIND: [u8; 4] = *b"CURV";
    const DIR: &'static str = "finished";

    fn encode(&self, w: &mut Writer) {
        w.u64(self.0.len() as u64);
        for c in &self.0 {
            w.u32(c.id);
            w.u8(c.closed as u8);
            w.f32(c.confidence);
            w.u8(c.shape.code());
            w.u64(c.vertices.len() as u64);
            for v in &c.vertices {
                put_edge(w, v.p, &v.n);
                w.u8(v.corner as u8);
            }
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let n = r.count(18)?;
        let mut curves = Vec::with_capacity(n);
        for _ in 0..n {
            let (id, closed, confidence, shape) = (r.u32()?, r.u8()? != 0, r.f32()?, Shape::of_code(r.u8()?));
            let nv = r.count(49)?;
            let mut vertices = Vec::with_capacity(nv);
            for _ in 0..nv {
                let (p, n) = get_edge(r)?;
                vertices.push(Vertex { p, n, corner: r.u8()? != 0 });
            }
            curves.push(Polyline { id, closed, vertices, confidence, shape });
        }
        Ok(Finished(curves))
    }
}

/// The smoothed, confirmed edge points of a growth block's core (see
/// [`crate::extract::blocks`]), by block number rather than tile.
pub(crate) struct Smoothed(pub SmoothedEdges);

impl Record for Smoothed {
    const KIND: [u8; 4] = *b"SMTH";
    const DIR: &'static str = "smoothed";

    fn encode(&self, w: &mut Writer) {
        let s = &self.0;
        w.u64(s.unconfirmed);
        w.u64(s.points.len() as u64);
        for (p, n) in s.points.iter().zip(&s.normals) {
            put_edge(w, *p, n);
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let unconfirmed = r.u64()?;
        let n = r.count(48)?;
        let mut s = SmoothedEdges { unconfirmed, points: Vec::with_capacity(n), normals: Vec::with_capacity(n) };
        for _ in 0..n {
            let (p, n) = get_edge(r)?;
            s.points.push(p);
            s.normals.push(n);
        }
        Ok(Smoothed(s))
    }
}

/// A tile's edge points at a glance: its number and the bounds of its edge points (relative to
/// the origin).
pub(crate) type TileBox = (u32, DVec3, DVec3);

/// What the curve stage's survey of the edge points found (see [`super::survey`]), kept so that
/// a resumed run, and every worker but the first, need not read every tile's edge points
/// again. One record, number 0.
pub(crate) struct Survey {
    /// Side of the base blocks planned.
    pub side: f64,
    /// The origin of the curve stage's positions, and of the blocks' grid.
    pub origin: DVec3,
    /// The counts of stages 1 and 2.
    pub counts: Counts,
    /// The tiles that hold edge points, with their bounds.
    pub boxes: Vec<TileBox>,
    /// The growth blocks.
    pub blocks: Blocks,
    /// Grouped corners, relative to the origin.
    pub grouped: Vec<DVec3>,
}

impl Record for Survey {
    const KIND: [u8; 4] = *b"SURV";
    const DIR: &'static str = "survey";

    fn encode(&self, w: &mut Writer) {
        w.f64(self.side);
        put_dvec3(w, self.origin);
        let c = &self.counts;
        [c.candidates, c.one_surface, c.scattered, c.edge_points, c.corner_points].iter().for_each(|&n| w.u64(n));
        w.u64(self.boxes.len() as u64);
        for &(t, lo, hi) in &self.boxes {
            w.u32(t);
            put_dvec3(w, lo);
            put_dvec3(w, hi);
        }
        let (fine, cells) = self.blocks.cells();
        w.f64(fine);
        w.u64(cells.len() as u64);
        cells.iter().flatten().flatten().for_each(|&x| w.u64(x as u64));
        w.u64(self.grouped.len() as u64);
        self.grouped.iter().for_each(|&p| put_dvec3(w, p));
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let (side, origin) = (r.f64()?, dvec3(r)?);
        let counts =
            Counts { candidates: r.u64()?, one_surface: r.u64()?, scattered: r.u64()?, edge_points: r.u64()?, corner_points: r.u64()?, ..Default::default() };
        let n = r.count(52)?;
        let boxes = (0..n).map(|_| Ok((r.u32()?, dvec3(r)?, dvec3(r)?))).collect::<Result<_>>()?;
        let fine = r.f64()?;
        let n = r.count(48)?;
        let mut cell = || -> Result<[i64; 3]> { Ok([r.u64()? as i64, r.u64()? as i64, r.u64()? as i64]) };
        let cells = (0..n).map(|_| Ok([cell()?, cell()?])).collect::<Result<_>>()?;
        let n = r.count(24)?;
        let grouped = (0..n).map(|_| dvec3(r)).collect::<Result<_>>()?;
        Ok(Survey { side, origin, counts, boxes, blocks: Blocks::from_cells(fine, cells), grouped })
    }
}

/// A growth block's pieces of polylines (see [`crate::extract::blocks::cut`]), by block
/// number, with what they were grown for: the block's box and the origin, so that pieces of
/// another plan of blocks are never stitched in.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Pieces {
    /// The block's box, relative to the origin.
    pub lo: DVec3,
    /// See `lo`.
    pub hi: DVec3,
    /// The curve stage's origin.
    pub origin: DVec3,
    /// The block's edge points the consensus filter dropped.
    pub unconfirmed: u64,
    /// The pieces, in the order grown.
    pub pieces: Vec<Piece>,
}

impl Pieces {
    /// True if these pieces were grown for `block` of a survey with this `origin`.
    pub(crate) fn grown_for(&self, block: &Block, origin: DVec3) -> bool {
        (self.lo, self.hi, self.origin) == (block.lo, block.hi, origin)
    }
}

impl Record for Pieces {
    const KIND: [u8; 4] = *b"PIEC";
    const DIR: &'static str = "pieces";

    fn encode(&self, w: &mut Writer) {
        [self.lo, self.hi, self.origin].iter().for_each(|&p| put_dvec3(w, p));
        w.u64(self.unconfirmed);
        w.u64(self.pieces.len() as u64);
        for p in &self.pieces {
            w.u64(p.v.len() as u64);
            p.v.iter().for_each(|&x| put_dvec3(w, x));
            for end in p.ends {
                w.u8(end.is_some() as u8);
                put_dvec3(w, end.unwrap_or_default());
            }
            w.u8(p.closed as u8);
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let (lo, hi, origin, unconfirmed) = (dvec3(r)?, dvec3(r)?, dvec3(r)?, r.u64()?);
        let n = r.count(59)?;
        let mut pieces = Vec::with_capacity(n);
        for _ in 0..n {
            let nv = r.count(24)?;
            let v = (0..nv).map(|_| dvec3(r)).collect::<Result<_>>()?;
            let mut end = || -> Result<Option<DVec3>> {
                let some = r.u8()? != 0;
                let p = dvec3(r)?;
                Ok(some.then_some(p))
            };
            let ends = [end()?, end()?];
            pieces.push(Piece { v, ends, closed: r.u8()? != 0 });
        }
        Ok(Pieces { lo, hi, origin, unconfirmed, pieces })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_damage_is_named() {
        let ws = Workspace::memory();
        let edges = TileEdges {
            edges: vec![WorldEdge { p: DVec3::new(1.0, 2.0, 3.0), n: [Vec3::X, Vec3::new(0.0, 0.6, 0.8)] }],
            corners: vec![WorldCorner { p: DVec3::new(-1.0, 0.5, 1e6), w: 7.5 }],
            candidates: 12,
            one_surface: 3,
            scattered: 2,
        };
        write(&ws, 4, &Edges(edges.clone())).unwrap();
        assert_eq!(read::<Edges>(&ws, 4).unwrap().0, edges);
        let res = TileResiduals { gid: vec![5, 9], residual: vec![Residual { value: 0.5, crease: true }, Residual { value: 0.25, crease: false }] };
        write(&ws, 4, &Residuals(res.clone())).unwrap();
        assert_eq!(read::<Residuals>(&ws, 4).unwrap().0, res);
        let smoothed = SmoothedEdges { points: vec![DVec3::new(0.5, -2.0, 1e7)], normals: vec![[Vec3::Z, Vec3::X]], unconfirmed: 3 };
        write(&ws, 2, &Smoothed(smoothed.clone())).unwrap();
        let back = read::<Smoothed>(&ws, 2).unwrap().0;
        assert_eq!((back.points, back.normals, back.unconfirmed), (smoothed.points, smoothed.normals, smoothed.unconfirmed));
        let piece = Piece { v: vec![DVec3::new(0.25, 1.0, -3.0), DVec3::new(0.5, 1.0, -3.0)], ends: [None, Some(DVec3::new(0.75, 1.0, -3.0))], closed: false };
        let pieces = Pieces { lo: DVec3::ZERO, hi: DVec3::splat(16.0), origin: DVec3::new(5e5, 4e6, 10.0), unconfirmed: 4, pieces: vec![piece.clone(), piece] };
        write(&ws, 3, &pieces).unwrap();
        assert_eq!(read::<Pieces>(&ws, 3).unwrap(), pieces);
        let mut census = crate::extract::blocks::Census::new(32.0);
        [DVec3::new(1.0, 2.0, 3.0), DVec3::new(-40.0, 2.0, 3.0)].into_iter().for_each(|p| census.add(p));
        let survey = Survey {
            side: 32.0,
            origin: DVec3::new(-1.5, 2.0, 7.0),
            counts: Counts { candidates: 9, one_surface: 1, scattered: 2, edge_points: 5, corner_points: 3, ..Default::default() },
            boxes: vec![(7, DVec3::ZERO, DVec3::ONE)],
            blocks: crate::extract::blocks::plan(&census),
            grouped: vec![DVec3::new(0.5, 0.5, 0.5)],
        };
        write(&ws, 0, &survey).unwrap();
        let back = read::<Survey>(&ws, 0).unwrap();
        assert_eq!((back.side, back.origin, back.boxes, back.grouped), (survey.side, survey.origin, survey.boxes, survey.grouped));
        assert_eq!((back.counts.candidates, back.counts.scattered, back.counts.corner_points), (9, 2, 3));
        assert_eq!(back.blocks.list, survey.blocks.list);
        assert_eq!(back.blocks.owner(DVec3::new(-39.0, 2.0, 3.0)), Some(0));
        // A residual record where an edge record belongs, and a missing one, are named.
        ws.write_atomic(&name(Edges::DIR, 5), &ws.read(&name(Residuals::DIR, 4)).unwrap().unwrap()).unwrap();
        let e = read::<Edges>(&ws, 5).err().unwrap().to_string();
        assert!(e.contains("edges/5.bin: damaged run directory file (holds RESI records, EDGE expected)"), "{e}");
        let e = read::<Stats>(&ws, 4).err().unwrap().to_string();
        assert!(e.contains("stats/4.bin: damaged run directory file (missing)"), "{e}");
    }
}
