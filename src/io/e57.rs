//! E57 input, the terrestrial scanners' exchange format, through the `e57` crate: every scan of
//! a file, each with its pose applied, read as one cloud. Spherical scans are converted to
//! Cartesian coordinates; points without a valid position (no return) are counted as records
//! but not kept.
//!
//! The crate's point iterator borrows its file reader, so the scans are decoded on a thread of
//! their own that hands chunks over a bounded channel: memory stays at two chunks whatever the
//! file's size, and the reader can be held by a [`crate::io::PointReader`].

use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::points::{Bounds, CloudHeader, FileFormat, PointChunk, Precision};
use crossbeam_channel::{bounded, Receiver};
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Records decoded per chunk handed over.
const CHUNK: usize = 1 << 16;

fn e57_error(path: &Path, e: e57::Error) -> Error {
    Error::input(path, format!("invalid E57 file: {}", e.to_string().replace('\n', " ")))
}

/// Where the scanner of scan `c` stood, in the file's coordinates, if the file tells. A scan's
/// own coordinates are centred on its scanner, and its pose's translation places that centre:
/// by definition for a scan stored in spherical coordinates; for one in Cartesian coordinates
/// unless its bounds lie more than ten times their size from the centre (a scan exported in a
/// map's coordinates without a pose, whose origin is no scanner), or, without bounds, if it
/// has a pose.
fn scanner(c: &e57::PointCloud) -> Option<DVec3> {
    let bounds = c.cartesian_bounds.as_ref().and_then(|b| {
        let lo = DVec3::new(b.x_min?, b.y_min?, b.z_min?);
        let hi = DVec3::new(b.x_max?, b.y_max?, b.z_max?);
        Some((lo, hi))
    });
    let centred = c.has_spherical()
        || match bounds {
            Some((lo, hi)) => DVec3::ZERO.max(lo).min(hi).length() <= 10.0 * lo.distance(hi),
            None => c.transform.is_some(),
        };
    centred.then(|| c.transform.as_ref().map_or(DVec3::ZERO, |t| DVec3::new(t.translation.x, t.translation.y, t.translation.z)))
}

/// A chunk of decoded points and the records it came from.
type Decoded = Result<(PointChunk, u64)>;

/// A chunked reader over one E57 file.
pub(super) struct E57Reader {
    path: PathBuf,
    header: CloudHeader,
    /// Started at the first read.
    decoded: Option<Receiver<Decoded>>,
    /// Points decoded but not yet returned, from `at` on, and their records.
    pending: PointChunk,
    at: usize,
    /// Records read so far, and up to the end of the pending chunk.
    next: u64,
    chunk_end: u64,
}

impl E57Reader {
    /// Opens `path` and reads its XML section (scans, record counts, coordinate metadata).
    pub(super) fn open(path: &Path) -> Result<E57Reader> {
        let meta = std::fs::metadata(path).map_err(|e| crate::error::io_input(path, e))?;
        if meta.len() == 0 {
            return Err(Error::input(path, "empty file"));
        }
        let reader = super::guarded(path, "the E57 decoder", || e57::E57Reader::from_file(path).map_err(|e| e57_error(path, e)))?;
        let clouds = reader.pointclouds();
        let count = clouds.iter().map(|c| c.records).try_fold(0u64, u64::checked_add).ok_or_else(|| Error::input(path, "scan record counts overflow"))?;
        // (E57's coordinate metadata is free text: a WKT or a code is taken, anything else left.)
        let crs = reader.coordinate_metadata().and_then(Crs::from_metadata).unwrap_or_default();
        let h = reader.header();
        let header = CloudHeader {
            path: path.to_path_buf(),
            format: FileFormat::E57,
            version: format!("{}.{} ({} scans)", h.major, h.minor, clouds.len()),
            point_format: None,
            count,
            bounds: Bounds::EMPTY,
            crs,
            // (Poses are applied in double precision.)
            precision: Precision::Float(52),
            scanners: clouds.iter().filter_map(scanner).collect(),
        };
        Ok(E57Reader { path: path.to_path_buf(), header, decoded: None, pending: PointChunk::default(), at: 0, next: 0, chunk_end: 0 })
    }

    /// The file's header (bounds are empty: poses move the scans' own bounds).
    pub(super) fn header(&self) -> &CloudHeader {
        &self.header
    }

    /// Reads up to `max` records into `out` (filtered by class 0, as E57 has no classes);
    /// returns the number of records read (0 at the end).
    pub(super) fn read_chunk(&mut self, max: usize, out: &mut PointChunk, table: &[bool; 256]) -> Result<usize> {
        if self.at == self.pending.len() {
            self.at = 0;
            self.pending.clear();
            let rx = self.decoded.get_or_insert_with(|| decode(self.path.clone()));
            match rx.recv() {
                Ok(Ok((chunk, records))) => {
                    self.pending = chunk;
                    self.chunk_end = self.next + records;
                    if self.pending.is_empty() {
                        self.next += records;
                        return Ok(records as usize);
                    }
                }
                Ok(Err(e)) => return Err(e),
                Err(_) => {
                    if self.next != self.header.count {
                        return Err(Error::input(&self.path, format!("the scans declare {} points but hold {}", self.header.count, self.next)));
                    }
                    return Ok(0);
                }
            }
        }
        let end = (self.at + max.max(1)).min(self.pending.len());
        // (Records without a position count with the point after them, or the chunk's end.)
        let upto = if end == self.pending.len() { self.chunk_end } else { self.pending.index[end] };
        let records = upto - self.next;
        for k in self.at..end {
            if table[0] {
                out.xyz.push(self.pending.xyz[k]);
                out.class.push(0);
                out.index.push(self.pending.index[k]);
            }
        }
        self.at = end;
        self.next += records;
        Ok(records as usize)
    }
}

/// Largest coordinate magnitude taken for a point (1e12 metres is beyond any scan): a float
/// stream decoded at the wrong precision gives values up to 3e38, which would otherwise make
/// bounds that no tiling can cover.
const MAX_COORDINATE: f64 = 1e12;

/// Starts decoding every scan of `path` on a thread of its own.
fn decode(path: PathBuf) -> Receiver<Decoded> {
    let (tx, rx) = bounded::<Decoded>(2);
    std::thread::spawn(move || {
        let sent = super::guarded(&path, "the E57 decoder", || {
            let mut reader = e57::E57Reader::from_file(&path).map_err(|e| e57_error(&path, e))?;
            let mut index = 0u64;
            let mut chunk = PointChunk::default();
            let mut records = 0u64;
            for (scan, pc) in reader.pointclouds().into_iter().enumerate() {
                let points = reader.pointcloud_simple(&pc).map_err(|e| e57_error(&path, e))?;
                for p in points {
                    let p = p.map_err(|e| e57_error(&path, e))?;
                    if let e57::CartesianCoordinate::Valid { x, y, z } = p.cartesian {
                        let xyz = DVec3::new(x, y, z);
                        if !xyz.is_finite() || xyz.abs().max_element() > MAX_COORDINATE {
                            return Err(Error::input(
                                &path,
                                format!("scan {}, record {index}: the point ({x}, {y}, {z}) is not finite or lies beyond {MAX_COORDINATE:e} (a stream read at the wrong precision?)", scan + 1),
                            ));
                        }
                        chunk.xyz.push(xyz);
                        chunk.class.push(0);
                        chunk.index.push(index);
                    }
                    index += 1;
                    records += 1;
                    if records as usize == CHUNK {
                        if tx.send(Ok((std::mem::take(&mut chunk), records))).is_err() {
                            return Ok(()); // (The reader was dropped.)
                        }
                        records = 0;
                    }
                }
            }
            if records > 0 {
                let _ = tx.send(Ok((chunk, records)));
            }
            Ok(())
        });
        if let Err(e) = sent {
            let _ = tx.send(Err(e));
        }
    });
    rx
}
