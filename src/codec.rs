//! The record codec of a run directory: every file but `manifest.json` is a sequence of frames,
//! each a fixed header, an optional uncompressed metadata block, and a zstd-compressed payload.
//!
//! ```text
//! magic "CRSE" | kind [4] | format u16 | meta length u16 | raw length u64 | zstd length u64
//! | crc32 of metadata and compressed payload u32                          (32 bytes, LE)
//! metadata | compressed payload
//! ```
//!
//! The kind names what a frame holds (tile points, statistics, residuals, edges), so a file put
//! in the wrong place is refused; the format number changes whenever a layout does; the
//! checksum finds a flipped byte. Payloads are written and read through [`Writer`] and
//! [`Reader`], field by field, never by offset.

use crate::error::{Error, Result};
use std::path::Path;

/// The four bytes every frame starts with.
pub(crate) const MAGIC: [u8; 4] = *b"CRSE";
/// Layout version of every kind; raised when any layout changes.
pub(crate) const FORMAT: u16 = 3;
/// Bytes of a frame header.
pub(crate) const HEADER: usize = 32;

/// The header of one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct FrameHeader {
    /// What the frame holds.
    pub kind: [u8; 4],
    /// Bytes of uncompressed metadata after the header.
    pub meta_len: usize,
    /// Bytes of the payload once decompressed.
    pub raw_len: usize,
    /// Bytes of the compressed payload.
    pub zstd_len: usize,
    /// CRC-32 of the metadata and the compressed payload.
    pub crc: u32,
}

impl FrameHeader {
    /// Parses a header, checking the magic, the kind and the format.
    pub(crate) fn parse(b: &[u8; HEADER], kind: [u8; 4], path: &Path) -> Result<FrameHeader> {
        let mut r = Reader::new(b, path);
        let (magic, k) = (r.bytes4()?, r.bytes4()?);
        if magic != MAGIC {
            return Err(Error::damaged(path, "not a crease record"));
        }
        if k != kind {
            return Err(Error::damaged(path, format!("holds {} records, {} expected", name(k), name(kind))));
        }
        let format = r.u16()?;
        if format != FORMAT {
            return Err(Error::damaged(path, format!("record format {format}, this crease reads {FORMAT}")));
        }
        let meta_len = r.u16()? as usize;
        let (raw_len, zstd_len) = (r.u64()?, r.u64()?);
        let crc = r.u32()?;
        let sane = |n: u64| usize::try_from(n).ok().filter(|&n| n <= 1 << 40);
        match (sane(raw_len), sane(zstd_len)) {
            (Some(raw_len), Some(zstd_len)) => Ok(FrameHeader { kind, meta_len, raw_len, zstd_len, crc }),
            _ => Err(Error::damaged(path, "impossible frame length")),
        }
    }

    /// Checks the metadata and compressed payload against the checksum, then decompresses
    /// with `zd` (a reader of many frames keeps one decompressor: making one per frame cost
    /// more than decompressing the small frames of a tile store).
    pub(crate) fn open(&self, meta: &[u8], zstd: &[u8], path: &Path, zd: &mut zstd::bulk::Decompressor) -> Result<Vec<u8>> {
        let mut h = crc32fast::Hasher::new();
        h.update(meta);
        h.update(zstd);
        if h.finalize() != self.crc {
            return Err(Error::damaged(path, "checksum mismatch"));
        }
        let raw = zd.decompress(zstd, self.raw_len).map_err(|e| Error::Damaged {
            path: path.to_path_buf(),
            what: "undecodable payload".into(),
            source: Some(e.into()),
        })?;
        if raw.len() != self.raw_len {
            return Err(Error::damaged(path, "payload shorter than its header says"));
        }
        Ok(raw)
    }
}

fn name(k: [u8; 4]) -> String {
    String::from_utf8_lossy(&k).into_owned()
}

/// Encodes one frame of kind `kind` with metadata `meta` and payload `raw` (compressed at
/// zstd level 1, the speed the tile passes need).
pub(crate) fn frame(kind: [u8; 4], meta: &[u8], raw: &[u8], zc: &mut zstd::bulk::Compressor) -> std::io::Result<Vec<u8>> {
    let z = zc.compress(raw)?;
    let mut h = crc32fast::Hasher::new();
    h.update(meta);
    h.update(&z);
    let mut w = Writer::default();
    w.bytes(&MAGIC);
    w.bytes(&kind);
    w.u16(FORMAT);
    w.u16(u16::try_from(meta.len()).expect("frame metadata under 64 KiB"));
    w.u64(raw.len() as u64);
    w.u64(z.len() as u64);
    w.u32(h.finalize());
    w.bytes(meta);
    w.bytes(&z);
    Ok(w.0)
}

/// Decodes a file that holds exactly one frame of kind `kind`: its payload.
pub(crate) fn unframe(bytes: &[u8], kind: [u8; 4], path: &Path) -> Result<Vec<u8>> {
    let head: &[u8; HEADER] = bytes.get(..HEADER).and_then(|h| h.try_into().ok()).ok_or_else(|| Error::damaged(path, "truncated"))?;
    let h = FrameHeader::parse(head, kind, path)?;
    if bytes.len() != HEADER + h.meta_len + h.zstd_len {
        return Err(Error::damaged(path, "length does not match its header"));
    }
    let mut zd = zstd::bulk::Decompressor::new().map_err(|e| Error::input_from(path, "cannot decompress", e))?;
    h.open(&bytes[HEADER..HEADER + h.meta_len], &bytes[HEADER + h.meta_len..], path, &mut zd)
}

/// A record being encoded: fields appended in little-endian order.
#[derive(Default)]
pub(crate) struct Writer(pub Vec<u8>);

impl Writer {
    /// An empty record with room for `n` bytes.
    pub(crate) fn with_capacity(n: usize) -> Writer {
        Writer(Vec::with_capacity(n))
    }

    /// Appends raw bytes.
    pub(crate) fn bytes(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }

    /// Appends a u8.
    pub(crate) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }

    /// Appends a u16.
    pub(crate) fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }

    /// Appends a u32.
    pub(crate) fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }

    /// Appends a u64.
    pub(crate) fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }

    /// Appends an f32.
    pub(crate) fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }

    /// Appends an f64.
    pub(crate) fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
}

/// A record being decoded: fields taken in order; running past the end is a damaged file.
pub(crate) struct Reader<'a> {
    b: &'a [u8],
    path: &'a Path,
}

impl<'a> Reader<'a> {
    /// A reader over `b`, which came from `path` (named in errors).
    pub(crate) fn new(b: &'a [u8], path: &'a Path) -> Reader<'a> {
        Reader { b, path }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N]> {
        let (head, rest) = self.b.split_first_chunk::<N>().ok_or_else(|| Error::damaged(self.path, "record ends early"))?;
        self.b = rest;
        Ok(*head)
    }

    /// Four raw bytes.
    pub(crate) fn bytes4(&mut self) -> Result<[u8; 4]> {
        self.take()
    }

    /// A u8.
    pub(crate) fn u8(&mut self) -> Result<u8> {
        Ok(self.take::<1>()?[0])
    }

    /// A u16.
    pub(crate) fn u16(&mut self) -> Result<u16> {
        self.take().map(u16::from_le_bytes)
    }

    /// A u32.
    pub(crate) fn u32(&mut self) -> Result<u32> {
        self.take().map(u32::from_le_bytes)
    }

    /// A u64.
    pub(crate) fn u64(&mut self) -> Result<u64> {
        self.take().map(u64::from_le_bytes)
    }

    /// A count of items of `size` bytes each that must fit in what is left.
    pub(crate) fn count(&mut self, size: usize) -> Result<usize> {
        let n = self.u64()?;
        match usize::try_from(n).ok().filter(|&n| n.checked_mul(size).is_some_and(|b| b <= self.b.len())) {
            Some(n) => Ok(n),
            None => Err(Error::damaged(self.path, "count larger than the record")),
        }
    }

    /// An f32.
    pub(crate) fn f32(&mut self) -> Result<f32> {
        self.take().map(f32::from_le_bytes)
    }

    /// An f64.
    pub(crate) fn f64(&mut self) -> Result<f64> {
        self.take().map(f64::from_le_bytes)
    }

    /// Checks that the whole record was read.
    pub(crate) fn finish(self) -> Result<()> {
        if self.b.is_empty() {
            Ok(())
        } else {
            Err(Error::damaged(self.path, "record longer than its contents"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_damage_is_named() {
        let path = Path::new("edges/3.bin");
        let mut zc = zstd::bulk::Compressor::new(1).unwrap();
        let raw: Vec<u8> = (0..1000u32).flat_map(|i| (i * 7).to_le_bytes()).collect();
        let f = frame(*b"EDGE", b"meta", &raw, &mut zc).unwrap();
        assert_eq!(&f[HEADER..HEADER + 4], b"meta");
        assert_eq!(unframe(&f, *b"EDGE", path).unwrap(), raw);
        let err = |bytes: &[u8], kind: [u8; 4]| unframe(bytes, kind, path).unwrap_err().to_string();
        assert!(err(&f, *b"RESI").contains("holds EDGE records, RESI expected"));
        for at in [0, 9, HEADER + 1, f.len() - 1] {
            let mut bad = f.clone();
            bad[at] ^= 0x10;
            let e = err(&bad, *b"EDGE");
            assert!(e.starts_with("edges/3.bin: damaged run directory file"), "byte {at}: {e}");
        }
        assert!(err(&f[..f.len() - 1], *b"EDGE").contains("length does not match"));
        assert!(err(&f[..10], *b"EDGE").contains("truncated"));
    }

    #[test]
    fn readers_refuse_counts_past_the_end() {
        let mut w = Writer::default();
        w.u64(3);
        w.f64(1.0);
        let path = Path::new("x");
        let mut r = Reader::new(&w.0, path);
        assert!(r.count(8).is_err());
        let mut w = Writer::default();
        w.u64(1);
        w.f64(2.5);
        let mut r = Reader::new(&w.0, path);
        assert_eq!(r.count(8).unwrap(), 1);
        assert_eq!(r.f64().unwrap(), 2.5);
        r.finish().unwrap();
    }
}
