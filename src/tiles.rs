//! Tiles: the grid over a cloud's bounds, and the on-disk tile store.
//!
//! Each point is written once, to the tile whose core holds it, as zstd-compressed chunks of
//! world coordinates and global point ids. A tile's halo is assembled when the tile is
//! processed, from the neighbouring tiles' stores, so the halo width can be chosen after the
//! cloud's spacing and noise are known.

use crate::cancel::Cancel;
use crate::codec;
use crate::error::{Error, Result};
pub(crate) use crate::points::TilePoints;
use crate::points::{Bounds, PointChunk};
use crate::workspace::Workspace;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::Path;

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::output(path, e)
}

/// Most tiles a grid may have. Every tile costs a little even when empty (a buffer while
/// bucketing, a file, its halo reads): a million tiles of a small cube took minutes. Grids
/// planned from `--memory` hold about one tile per 10 k-2 M points, so a billion points need
/// at most about 100 k.
pub(crate) const MAX_TILES: u64 = 1 << 18;

/// A regular grid of cubic (3D) or square-column (2D, one layer in z) tiles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Grid {
    /// Minimum corner.
    pub origin: [f64; 3],
    /// Tile edge length (x and y; z too unless the grid is 2D).
    pub size: f64,
    /// Tiles along x, y, z.
    pub dims: [u32; 3],
    /// Height of the single layer of a 2D grid (0 for 3D grids).
    pub layer: f64,
}

impl Grid {
    /// A grid over `b` with tiles of edge `size`; 2D (one layer) when the cloud is flat
    /// compared with its footprint, as airborne scans are.
    pub(crate) fn new(b: &Bounds, size: f64) -> Grid {
        let ext = DVec3::from(b.max) - DVec3::from(b.min);
        let flat = ext.z < 0.25 * ext.x.max(ext.y);
        let n = |e: f64| ((e / size).floor() as u32 + 1).max(1);
        let dims = [n(ext.x), n(ext.y), if flat { 1 } else { n(ext.z) }];
        Grid { origin: b.min, size, dims, layer: if flat { ext.z.max(1e-9) * 1.0001 + size } else { 0.0 } }
    }

    /// The box the grid's tiles span (the 2D grid's layer in z).
    pub(crate) fn span(&self) -> Bounds {
        let height = if self.dims[2] == 1 && self.layer > 0.0 { self.layer } else { self.dims[2] as f64 * self.size };
        let ext = [self.dims[0] as f64 * self.size, self.dims[1] as f64 * self.size, height];
        Bounds { min: self.origin, max: std::array::from_fn(|a| self.origin[a] + ext[a]) }
    }

    /// Number of tiles.
    pub(crate) fn len(&self) -> usize {
        self.tiles().min(usize::MAX as u64) as usize
    }

    /// Number of tiles, without overflow (a grid may be planned with more than tile ids hold:
    /// see [`MAX_TILES`]).
    pub(crate) fn tiles(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }

    fn cell(&self, v: f64, axis: usize) -> u32 {
        let c = ((v - self.origin[axis]) / self.size).floor();
        (c.max(0.0) as u32).min(self.dims[axis] - 1)
    }

    /// The tile whose core holds `p`.
    pub(crate) fn tile_of(&self, p: DVec3) -> u32 {
        let (i, j) = (self.cell(p.x, 0), self.cell(p.y, 1));
        let k = if self.dims[2] == 1 { 0 } else { self.cell(p.z, 2) };
        (k * self.dims[1] + j) * self.dims[0] + i
    }

    fn coords(&self, t: u32) -> [u32; 3] {
        [t % self.dims[0], (t / self.dims[0]) % self.dims[1], t / (self.dims[0] * self.dims[1])]
    }

    /// The core box of tile `t` (tiles on the grid's edge extend to infinity outwards, so
    /// every point has exactly one owner).
    pub(crate) fn core(&self, t: u32) -> Bounds {
        let c = self.coords(t);
        let mut b = Bounds { min: [0.0; 3], max: [0.0; 3] };
        for (a, &c) in c.iter().enumerate() {
            let lo = self.origin[a] + c as f64 * self.size;
            b.min[a] = if c == 0 { f64::NEG_INFINITY } else { lo };
            b.max[a] = if c + 1 == self.dims[a] { f64::INFINITY } else { lo + self.size };
        }
        b
    }

    /// Tiles whose cores come within `halo` of tile `t`'s core (including `t`).
    pub(crate) fn around(&self, t: u32, halo: f64) -> Vec<u32> {
        let c = self.coords(t);
        // (Only tiles of the grid are visited: a halo many tiles wide, or a tile size so small
        // that the ratio overflows, costs no more than the grid has tiles.)
        let r = (halo / self.size).ceil();
        let range = |a: usize| {
            let r = if r.is_finite() && r >= 0.0 { r.min(self.dims[a] as f64) as i64 } else { self.dims[a] as i64 };
            let (lo, hi) = ((c[a] as i64 - r).max(0), (c[a] as i64 + r).min(self.dims[a] as i64 - 1));
            lo as u32..=hi as u32
        };
        let mut out = vec![];
        for k in range(2) {
            for j in range(1) {
                for i in range(0) {
                    out.push((k * self.dims[1] + j) * self.dims[0] + i);
                }
            }
        }
        out
    }
}

/// True if `p` lies in `b` grown by `halo`.
pub(crate) fn within(b: &Bounds, halo: f64, p: DVec3) -> bool {
    (0..3).all(|a| p[a] >= b.min[a] - halo && p[a] < b.max[a] + halo)
}

/// The tile store: each tile's points, as frames of the record codec (see `codec.rs`)
/// appended to `tiles/<tile>.pts` in the run's workspace. A frame's metadata is its point count
/// and bounding box, so readers skip frames outside a region without decompressing them.
#[derive(Clone, Copy)]
pub(crate) struct Store<'a> {
    ws: &'a Workspace,
    /// Stops reads between frames and a bucketer's writes between tiles, once set.
    cancel: Option<&'a Cancel>,
}

/// The codec kind of tile point frames.
const KIND: [u8; 4] = *b"TPTS";
/// Bytes of a frame's metadata: point count and bounding box.
const META: usize = 4 + 48;
/// The store's directory in the workspace.
pub(crate) const DIR: &str = "tiles";

impl<'a> Store<'a> {
    /// The store of workspace `ws` (its directory created if needed).
    pub(crate) fn new(ws: &'a Workspace) -> Result<Store<'a>> {
        ws.create_dir(DIR)?;
        Ok(Store { ws, cancel: None })
    }

    /// The store, whose reads stop between frames (a few hundred points each) and whose
    /// bucketer stops between tiles once `cancel` is set, with [`Error::Interrupted`]: a tile
    /// being loaded, or the fullest tile read for the spacing probe, is several hundred
    /// thousand points, a second's work on a busy machine.
    pub(crate) fn cancelled_by(self, cancel: &'a Cancel) -> Store<'a> {
        Store { cancel: Some(cancel), ..self }
    }

    /// [`Error::Interrupted`] once the store's cancel flag is set (for the loops around its
    /// reads: a loaded tile's filters and index).
    pub(crate) fn check(&self) -> Result<()> {
        self.cancel.map_or(Ok(()), Cancel::check)
    }

    /// True once the store's cancel flag is set.
    pub(crate) fn cancelled(&self) -> bool {
        self.cancel.is_some_and(Cancel::is_set)
    }

    fn name(t: u32) -> String {
        format!("{DIR}/{t}.pts")
    }

    /// The path of tile `t`'s file (for messages).
    pub(crate) fn path(&self, t: u32) -> std::path::PathBuf {
        self.ws.path(&Self::name(t))
    }

    /// Removes every tile's points.
    pub(crate) fn clear(&self) -> Result<()> {
        self.ws.remove(DIR);
        self.ws.create_dir(DIR)
    }

    /// Appends `pts` to tile `t`'s file as several frames, of the lengths in `runs`.
    pub(crate) fn append_runs(&self, t: u32, pts: &TilePoints, runs: &[usize]) -> Result<()> {
        let name = Self::name(t);
        let path = self.ws.path(&name);
        let mut zc = zstd::bulk::Compressor::new(1).map_err(io(&path))?;
        let mut out = Vec::new();
        let mut at = 0;
        for &n in runs {
            out.extend(encode_chunk(&mut zc, &pts.xyz[at..at + n], &pts.gid[at..at + n]).map_err(io(&path))?);
            at += n;
        }
        self.ws.append(&name, &out)
    }

    /// Makes every tile file durable.
    pub(crate) fn sync(&self) -> Result<()> {
        self.ws.sync_dir(DIR)
    }

    /// Streams tile `t`'s points in chunks, keeping those `keep` accepts; returns how many
    /// points the tile's file holds (kept or not).
    pub(crate) fn read(&self, t: u32, out: &mut TilePoints, keep: impl Fn(DVec3, u64) -> bool) -> Result<u64> {
        self.read_near(t, None, out, keep)
    }

    /// As [`Store::read`], but only chunks whose bounding box comes within the given distance
    /// of the given box are decompressed (a tile's halo needs only its neighbours' borders);
    /// returns how many points the chunks read hold.
    pub(crate) fn read_near(&self, t: u32, near: Option<(&Bounds, f64)>, out: &mut TilePoints, keep: impl Fn(DVec3, u64) -> bool) -> Result<u64> {
        let name = Self::name(t);
        let path = self.ws.path(&name);
        let Some(mut f) = self.ws.open(&name)? else { return Ok(0) };
        let mut read = 0u64;
        let truncated = |_| Error::damaged(&path, "truncated tile store");
        let mut head = [0u8; codec::HEADER];
        let (mut meta, mut z) = (Vec::new(), Vec::new());
        let mut zd = zstd::bulk::Decompressor::new().map_err(|e| Error::input_from(&path, "cannot decompress", e))?;
        while f.read_exact_or_end(&mut head).map_err(truncated)? {
            self.check()?;
            let h = codec::FrameHeader::parse(&head, KIND, &path)?;
            if h.meta_len != META {
                return Err(Error::damaged(&path, "tile frame metadata of the wrong size"));
            }
            meta.resize(META, 0);
            f.read_exact(&mut meta).map_err(truncated)?;
            let mut m = codec::Reader::new(&meta, &path);
            let n = m.u32()? as usize;
            let mut v = [0.0; 6];
            for x in v.iter_mut() {
                *x = m.f64()?;
            }
            let chunk = Bounds { min: [v[0], v[1], v[2]], max: [v[3], v[4], v[5]] };
            if let Some((b, d)) = near
                && (0..3).any(|a| chunk.min[a] > b.max[a] + d || chunk.max[a] < b.min[a] - d)
            {
                f.skip(h.zstd_len).map_err(truncated)?;
                continue;
            }
            z.resize(h.zstd_len, 0);
            f.read_exact(&mut z).map_err(truncated)?;
            if h.raw_len != n * 32 {
                return Err(Error::damaged(&path, "tile frame of the wrong length"));
            }
            let raw = h.open(&meta, &z, &path, &mut zd)?;
            read += n as u64;
            let f64_at = |o: usize| f64::from_le_bytes(raw[o..o + 8].try_into().unwrap());
            for i in 0..n {
                let p = DVec3::new(f64_at(8 * i), f64_at(8 * (n + i)), f64_at(8 * (2 * n + i)));
                let g = u64::from_le_bytes(raw[8 * (3 * n + i)..8 * (3 * n + i) + 8].try_into().unwrap());
                if keep(p, g) {
                    out.xyz.push(p);
                    out.gid.push(g);
                }
            }
        }
        Ok(read)
    }
}

/// One frame of points: coordinates column by column, then global ids.
fn encode_chunk(zc: &mut zstd::bulk::Compressor, xyz: &[DVec3], gid: &[u64]) -> std::io::Result<Vec<u8>> {
    let n = xyz.len();
    let bounds = Bounds::of(xyz.iter().copied());
    let mut raw = Vec::with_capacity(n * 32);
    for a in 0..3 {
        for p in xyz {
            raw.extend_from_slice(&p[a].to_le_bytes());
        }
    }
    for g in gid {
        raw.extend_from_slice(&g.to_le_bytes());
    }
    let mut meta = codec::Writer::with_capacity(META);
    meta.u32(n as u32);
    for v in bounds.min.iter().chain(&bounds.max) {
        meta.f64(*v);
    }
    codec::frame(KIND, &meta.0, &raw, zc)
}

/// Buffered points of a tile are written in chunks by sub-cell, this many per tile edge, so
/// that a neighbour's halo reads only the chunks along the border.
const SUB_CELLS: f64 = 16.0;

/// Buffers points per tile and appends them to the store when the buffers grow past a budget.
pub(crate) struct Bucketer<'a> {
    grid: &'a Grid,
    store: Store<'a>,
    /// One buffer per tile (a vector, not a map: it is looked up for every point read).
    buffers: Vec<TilePoints>,
    buffered: usize,
    budget: usize,
    /// Points bucketed per tile.
    pub counts: Vec<u64>,
}

impl<'a> Bucketer<'a> {
    /// A bucketer holding at most `budget` points in memory.
    pub(crate) fn new(grid: &'a Grid, store: Store<'a>, budget: usize) -> Self {
        Bucketer { grid, store, buffers: vec![TilePoints::default(); grid.len()], buffered: 0, budget: budget.max(1024), counts: vec![0; grid.len()] }
    }

    /// Adds a chunk of points; `gid0` is the global id of the chunk's first point.
    pub(crate) fn add(&mut self, chunk: &PointChunk, gids: &[u64]) -> Result<()> {
        for (p, &g) in chunk.xyz.iter().zip(gids) {
            let t = self.grid.tile_of(*p);
            let b = &mut self.buffers[t as usize];
            b.xyz.push(*p);
            b.gid.push(g);
            self.counts[t as usize] += 1;
        }
        self.buffered += chunk.len();
        if self.buffered >= self.budget {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes every buffer out.
    pub(crate) fn flush(&mut self) -> Result<()> {
        use rayon::prelude::*;
        let tiles: Vec<(u32, TilePoints)> =
            self.buffers.iter_mut().enumerate().filter(|(_, b)| !b.xyz.is_empty()).map(|(t, b)| (t as u32, std::mem::take(b))).collect();
        let sub = self.grid.size / SUB_CELLS;
        let o = DVec3::from(self.grid.origin);
        // Tiles are separate files: they are sorted, compressed and written in parallel.
        tiles.into_par_iter().try_for_each(|(t, b)| {
            // (Bucketing is all or nothing: an interrupted one starts over.)
            self.store.check()?;
            let mut order: Vec<([i64; 3], u32)> = b.xyz.iter().enumerate().map(|(i, &p)| (crate::grid::cell(p - o, sub).to_array(), i as u32)).collect();
            order.sort_unstable();
            let sorted = TilePoints { xyz: order.iter().map(|r| b.xyz[r.1 as usize]).collect(), gid: order.iter().map(|r| b.gid[r.1 as usize]).collect() };
            drop(b);
            let runs: Vec<usize> = order.chunk_by(|a, b| a.0 == b.0).map(|r| r.len()).collect();
            self.store.append_runs(t, &sorted, &runs)
        })?;
        self.buffered = 0;
        Ok(())
    }
}
