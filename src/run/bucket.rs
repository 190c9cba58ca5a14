//! Bucketing: one streaming pass over the inputs writes every point once, to its tile, and
//! takes the cloud's spread along each axis, by which far points are found (see [`super::far`]).

use super::far::Spread;
use crate::cancel::Cancel;
use crate::error::{Error, Result};
use crate::io::{self, Filter, PointReader};
use crate::points::{Bounds, PointChunk};
use crate::progress::Bar;
use crate::tiles::Bucketer;
use glam::DVec3;
use std::path::PathBuf;

/// Where a run's points come from.
pub(crate) enum Input<'a> {
    /// Point files, read in order (file index `i` gives the global ids `i << 40 | record`).
    Files(&'a [PathBuf], &'a Filter),
    /// Points held in memory (global ids are their indices).
    Points(&'a [DVec3]),
}

/// Where bucketed points go: the tiles, if within the bounds kept (all, if none are set yet),
/// and the spread.
pub(crate) struct Sink<'a> {
    /// The tiles.
    pub tiles: Bucketer<'a>,
    /// The spread of the points kept.
    pub spread: Spread,
    /// Points outside these bounds are left out as far (see [`super::far`]).
    pub kept: Option<Bounds>,
    /// Points left out as far.
    pub far: u64,
    /// The bounds of the points bucketed.
    pub seen: Bounds,
}

/// Streams every point of `input` into `b`, counting the records read on `bar` (points left
/// out by the filter count too, as the bar's total is the records the inputs declare).
pub(crate) fn bucket(input: &Input, b: &mut Sink, bar: &Bar, cancel: &Cancel) -> Result<()> {
    match input {
        Input::Points(points) => {
            for (k, part) in points.chunks(io::DEFAULT_CHUNK).enumerate() {
                let first = (k * io::DEFAULT_CHUNK) as u64;
                let chunk = PointChunk { xyz: part.to_vec(), class: vec![0; part.len()], index: (first..first + part.len() as u64).collect() };
                add(b, 0, &chunk, cancel)?;
                bar.inc(chunk.len() as u64);
            }
            Ok(())
        }
        Input::Files(files, filter) => bucket_files(files, filter, b, bar, cancel),
    }
}

fn add(b: &mut Sink, fi: usize, chunk: &PointChunk, cancel: &Cancel) -> Result<()> {
    // Global ids: file index in the high bits, record index in the low 40 bits.
    let gids: Vec<u64> = chunk.index.iter().map(|&i| ((fi as u64) << 40) | i).collect();
    match &b.kept {
        Some(kept) if !chunk.xyz.iter().all(|&p| kept.contains(p)) => {
            let inside: Vec<usize> = (0..chunk.len()).filter(|&k| kept.contains(chunk.xyz[k])).collect();
            b.far += (chunk.len() - inside.len()) as u64;
            let part = PointChunk {
                xyz: inside.iter().map(|&k| chunk.xyz[k]).collect(),
                class: inside.iter().map(|&k| chunk.class[k]).collect(),
                index: inside.iter().map(|&k| chunk.index[k]).collect(),
            };
            let gids: Vec<u64> = inside.iter().map(|&k| gids[k]).collect();
            b.spread.add(&part.xyz);
            part.xyz.iter().for_each(|&p| b.seen.grow(p));
            b.tiles.add(&part, &gids)?;
        }
        _ => {
            b.spread.add(&chunk.xyz);
            chunk.xyz.iter().for_each(|&p| b.seen.grow(p));
            b.tiles.add(chunk, &gids)?;
        }
    }
    cancel.check()
}

/// The files are decoded on a thread of their own, one chunk ahead of the bucketing, so that
/// decoding overlaps the sorting, compressing and writing of the tiles.
fn bucket_files(files: &[PathBuf], filter: &Filter, b: &mut Sink, bar: &Bar, cancel: &Cancel) -> Result<()> {
    let (tx, rx) = crossbeam_channel::bounded::<Result<(usize, PointChunk, usize)>>(0);
    std::thread::scope(|s| -> Result<()> {
        // Owning the receiver here drops it on any early return, which stops the reader.
        let rx = rx;
        let reader = s.spawn(move || {
            for (fi, f) in files.iter().enumerate() {
                let mut r = match PointReader::open(f, filter) {
                    Ok(r) => r.cancelled_by(cancel),
                    Err(e) => return drop(tx.send(Err(e))),
                };
                loop {
                    let mut chunk = PointChunk::default();
                    match r.read_chunk(io::DEFAULT_CHUNK, &mut chunk) {
                        Ok(0) => break,
                        Ok(records) if tx.send(Ok((fi, chunk, records))).is_ok() => {}
                        Ok(_) => return,
                        Err(e) => return drop(tx.send(Err(e))),
                    }
                }
            }
        });
        for msg in rx.iter() {
            let (fi, chunk, records) = msg?;
            add(b, fi, &chunk, cancel)?;
            bar.inc(records as u64);
        }
        // (A reader that panicked ended the loop early: the points after it are missing.)
        reader.join().map_err(|p| Error::panic("input reader", p))
    })
}
