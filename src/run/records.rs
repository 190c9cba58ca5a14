//! The per-tile results of the tile passes as records of the codec (see [`crate::codec`]):
//! one file a tile and pass, `<dir>/<tile>.bin`, written atomically.

use crate::codec::{self, Reader, Writer};
use crate::error::{Error, Result};
use crate::extract::candidates::{Residual, TileResiduals};
use crate::extract::polylines::SmoothedEdges;
use crate::extract::statistics::PointStats;
use crate::extract::{TileEdges, WorldCorner, WorldEdge};
use crate::workspace::Workspace;
use glam::{DVec3, Vec3};
use std::path::Path;

/// A tile pass's result for one tile, as stored.
pub trait Record: Sized {
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
pub fn name(dir: &str, t: u32) -> String {
    format!("{dir}/{t}.bin")
}

/// Stores tile `t`'s result atomically.
pub fn write<R: Record>(ws: &Workspace, t: u32, rec: &R) -> Result<()> {
    let mut w = Writer::default();
    rec.encode(&mut w);
    let name = name(R::DIR, t);
    let mut zc = zstd::bulk::Compressor::new(1).map_err(|e| Error::output(ws.path(&name), e))?;
    let bytes = codec::frame(R::KIND, &[], &w.0, &mut zc).map_err(|e| Error::output(ws.path(&name), e))?;
    ws.write_atomic(&name, &bytes)
}

/// Reads tile `t`'s result.
pub fn read<R: Record>(ws: &Workspace, t: u32) -> Result<R> {
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

/// The statistics of a tile's sampled points, in global id order.
pub struct Stats(pub Vec<PointStats>);

impl Record for Stats {
    const KIND: [u8; 4] = *b"STAT";
    const DIR: &'static str = "stats";

    fn encode(&self, w: &mut Writer) {
        w.u64(self.0.len() as u64);
        for s in &self.0 {
            w.f64(s.spacing);
            w.f64(s.noise);
            w.f64(s.density);
        }
    }

    fn decode(r: &mut Reader) -> Result<Self> {
        let n = r.count(24)?;
        (0..n).map(|_| Ok(PointStats { spacing: r.f64()?, noise: r.f64()?, density: r.f64()? })).collect::<Result<_>>().map(Stats)
    }
}

/// The residuals of a tile's core points.
pub struct Residuals(pub TileResiduals);

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
pub struct Edges(pub TileEdges);

fn dvec3(r: &mut Reader) -> Result<DVec3> {
    Ok(DVec3::new(r.f64()?, r.f64()?, r.f64()?))
}

fn vec3(r: &mut Reader) -> Result<Vec3> {
    Ok(Vec3::new(r.f32()?, r.f32()?, r.f32()?))
}

/// An edge point as stored: its position (f64) and its two normals (f32), 48 bytes.
fn put_edge(w: &mut Writer, p: DVec3, n: &[Vec3; 2]) {
    p.to_array().iter().for_each(|&x| w.f64(x));
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
            c.p.to_array().iter().for_each(|&x| w.f64(x));
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

/// The smoothed, confirmed edge points of a growth block's core (see
/// [`crate::extract::blocks`]), by block number rather than tile.
pub struct Smoothed(pub SmoothedEdges);

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
        // A residual record where an edge record belongs, and a missing one, are named.
        ws.write_atomic(&name(Edges::DIR, 5), &ws.read(&name(Residuals::DIR, 4)).unwrap().unwrap()).unwrap();
        let e = read::<Edges>(&ws, 5).err().unwrap().to_string();
        assert!(e.contains("edges/5.bin: damaged run directory file (holds RESI records, EDGE expected)"), "{e}");
        let e = read::<Stats>(&ws, 4).err().unwrap().to_string();
        assert!(e.contains("stats/4.bin: damaged run directory file (missing)"), "{e}");
    }
}
