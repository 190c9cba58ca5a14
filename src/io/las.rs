//! LAS and LAZ input.
//!
//! Headers, VLRs and EVLRs are parsed by the `las` crate. Uncompressed point records are decoded
//! straight from a memory map (only x, y, z and the classification are needed, so this is a
//! handful of loads per point); LAZ records are decompressed by `las`/`laz` in chunks, in
//! parallel where the file has chunk tables, and decoded the same way.

use crate::error::{io_input, Error, Result};
use crate::points::{Bounds, CloudHeader, Crs, FileFormat, PointChunk, Precision};
use glam::DVec3;
use memmap2::Mmap;
use rayon::prelude::*;
use std::fs::File;
use std::io::Cursor;
use std::path::{Path, PathBuf};

/// Where the fields crease needs sit in one point record.
#[derive(Clone, Copy, Debug)]
struct Layout {
    record_len: usize,
    /// Point formats 6-10 keep the class in a byte of its own and the withheld flag elsewhere.
    extended: bool,
    scale: DVec3,
    offset: DVec3,
}

impl Layout {
    /// Decodes `n` records from `bytes` into `out`, keeping points the filter accepts.
    #[inline]
    fn decode(&self, bytes: &[u8], first: u64, out: &mut PointChunk, table: &[bool; 256], keep_withheld: bool) {
        let rl = self.record_len;
        let n = bytes.len() / rl;
        out.xyz.reserve(n);
        out.class.reserve(n);
        out.index.reserve(n);
        for (k, rec) in bytes.chunks_exact(rl).enumerate() {
            let (class, withheld) = if self.extended { (rec[16], rec[15] & 0x04 != 0) } else { (rec[15] & 0x1f, rec[15] & 0x80 != 0) };
            if !table[class as usize] || (withheld && !keep_withheld) {
                continue;
            }
            let x = i32::from_le_bytes([rec[0], rec[1], rec[2], rec[3]]);
            let y = i32::from_le_bytes([rec[4], rec[5], rec[6], rec[7]]);
            let z = i32::from_le_bytes([rec[8], rec[9], rec[10], rec[11]]);
            let p = DVec3::new(x as f64, y as f64, z as f64) * self.scale + self.offset;
            out.xyz.push(p);
            out.class.push(class);
            out.index.push(first + k as u64);
        }
    }
}

/// Maps a `las` crate error to a one-line message.
fn las_error(path: &Path, e: las::Error) -> Error {
    match e {
        las::Error::Io(io) => match io.kind() {
            std::io::ErrorKind::UnexpectedEof => Error::input(path, "truncated LAS header or VLRs"),
            _ => io_input(path, io),
        },
        las::Error::InvalidFileSignature(_) => Error::input(path, "not a LAS file (signature is not 'LASF')"),
        las::Error::LasZipError(z) => Error::input_from(path, format!("corrupt or truncated compressed point data: {z}"), z),
        other => Error::input_from(path, format!("invalid LAS file: {other}"), other),
    }
}

fn map_file(path: &Path) -> Result<Mmap> {
    let file = File::open(path).map_err(|e| io_input(path, e))?;
    let len = file.metadata().map_err(|e| io_input(path, e))?.len();
    if len == 0 {
        return Err(Error::input(path, "empty file"));
    }
    // SAFETY: the map is read-only; a file truncated underneath a running process is the one
    // case memmap2 cannot guard against, and crease never writes its inputs.
    let map = unsafe { Mmap::map(&file) }.map_err(|e| io_input(path, e))?;
    Ok(map)
}

/// The part of the raw header crease checks and uses.
struct Parsed {
    header: las::Header,
    offset_to_points: u64,
    layout: Layout,
    compressed: bool,
    crs: Crs,
}

fn parse(path: &Path, bytes: &[u8]) -> Result<Parsed> {
    if bytes.len() < 4 || &bytes[..4] != b"LASF" {
        return Err(Error::input(path, "not a LAS file (signature is not 'LASF')"));
    }
    if bytes.len() < 227 {
        return Err(Error::input(path, format!("truncated LAS header ({} bytes, need 227)", bytes.len())));
    }
    let raw = las::raw::Header::read_from(bytes).map_err(|e| las_error(path, e))?;
    let fmt = raw.point_data_record_format & 0x3f;
    let compressed = raw.point_data_record_format & 0x80 != 0;
    if fmt > 10 {
        return Err(Error::input(path, format!("unknown LAS point format {fmt}")));
    }
    let scale = DVec3::new(raw.x_scale_factor, raw.y_scale_factor, raw.z_scale_factor);
    let offset = DVec3::new(raw.x_offset, raw.y_offset, raw.z_offset);
    if !scale.is_finite() || !offset.is_finite() || scale.cmpeq(DVec3::ZERO).any() {
        return Err(Error::input(path, format!("invalid scale {scale} or offset {offset} in the header")));
    }
    let offset_to_points = raw.offset_to_point_data as u64;
    let record_len = raw.point_data_record_length as usize;
    // (The `las` crate allocates what an EVLR declares before reading it.)
    let evlrs = evlrs(path, bytes, &raw)?;
    let header = las::Header::new(Cursor::new(bytes)).map_err(|e| las_error(path, e))?;
    let base_len = {
        let mut f = *header.point_format();
        f.extra_bytes = 0;
        f.len() as usize
    };
    if record_len < base_len {
        return Err(Error::input(path, format!("point record length {record_len} is shorter than point format {fmt} needs ({base_len})")));
    }
    let count = header.number_of_points();
    if !compressed {
        // (A LAS 1.4 count near 2^64 times the record length overflows.)
        let need = count.checked_mul(record_len as u64).and_then(|n| n.checked_add(offset_to_points));
        if need.is_none_or(|n| n > bytes.len() as u64) {
            let holds = bytes.len() as u64 - offset_to_points.min(bytes.len() as u64);
            return Err(Error::input(
                path,
                format!("header declares {count} points but the file holds only {} (truncated point data)", holds / record_len as u64),
            ));
        }
    }
    if compressed {
        check_laz(path, bytes, &header, offset_to_points, record_len)?;
    }
    let layout = Layout { record_len, extended: fmt >= 6, scale, offset };
    let records = header.vlrs().iter().map(|v| (v.user_id.as_str(), v.record_id, &v.data[..]));
    let records = records.chain(evlrs.iter().map(|(user, id, r)| (user.as_str(), *id, &bytes[r.clone()])));
    let crs = Crs::from_las_records(records, raw.global_encoding & 0x10 != 0);
    Ok(Parsed { header, offset_to_points, layout, compressed, crs })
}

/// Reads a little-endian integer of `N` bytes at `at`, if the file holds it.
fn le<const N: usize>(bytes: &[u8], at: u64) -> Option<[u8; N]> {
    let at = usize::try_from(at).ok()?;
    bytes.get(at..at.checked_add(N)?)?.try_into().ok()
}

/// Where each EVLR lies, as (user id, record id, data range), checked against the file's
/// length: a header whose EVLRs run past its end is truncated or corrupt. (The `las` crate
/// reads only the first; a COPC file puts its hierarchy there and its CRS after it.)
fn evlrs(path: &Path, bytes: &[u8], raw: &las::raw::Header) -> Result<Vec<(String, u16, std::ops::Range<usize>)>> {
    const EVLR_HEADER: u64 = 60;
    let Some(e) = raw.evlr.filter(|e| e.start_of_first_evlr > 0 && e.number_of_evlrs > 0) else {
        return Ok(vec![]);
    };
    let len = bytes.len() as u64;
    let mut at = e.start_of_first_evlr;
    let mut out = vec![];
    for k in 0..e.number_of_evlrs {
        let data = at.saturating_add(EVLR_HEADER);
        let Some(size) = le::<8>(bytes, at.saturating_add(20)).map(u64::from_le_bytes).filter(|_| data <= len) else {
            return Err(Error::input(path, format!("EVLR {} of {} starts at byte {at}, past the end of the file ({len} bytes)", k + 1, e.number_of_evlrs)));
        };
        if size > len - data {
            return Err(Error::input(
                path,
                format!("EVLR {} of {} declares {size} bytes but the file ends {} bytes after its start", k + 1, e.number_of_evlrs, len - data),
            ));
        }
        // (In bounds: the header's 60 bytes and the data lie within the file.)
        let (a, d) = (at as usize, data as usize);
        let user = String::from_utf8_lossy(&bytes[a + 2..a + 18]).trim_end_matches('\0').to_string();
        out.push((user, u16::from_le_bytes([bytes[a + 18], bytes[a + 19]]), d..d + size as usize));
        at = data + size;
    }
    Ok(out)
}

/// Checks a LAZ file's laszip record and chunk table against the file before the `laz` crate
/// sizes anything from them: its chunk table is read into a vector of the declared length
/// (4 billion chunks asked for 68 GB), and a record length that disagrees with the compressed
/// items trips an assertion.
fn check_laz(path: &Path, bytes: &[u8], header: &las::Header, data_start: u64, record_len: usize) -> Result<()> {
    let Some(vlr) = header.vlrs().iter().find(|v| v.user_id == "laszip encoded" && v.record_id == 22204) else {
        return Err(Error::input(path, "compressed points but no laszip record (VLR 'laszip encoded' 22204)"));
    };
    let d = &vlr.data;
    let field = |at: usize, n: usize| d.get(at..at + n).ok_or_else(|| Error::input(path, format!("laszip record of {} bytes is too short", d.len())));
    let chunk_size = u32::from_le_bytes(field(12, 4)?.try_into().expect("4 bytes"));
    let items = u16::from_le_bytes(field(32, 2)?.try_into().expect("2 bytes")) as usize;
    let table = field(34, 6 * items)?;
    let item_bytes: usize = table.chunks_exact(6).map(|it| u16::from_le_bytes([it[2], it[3]]) as usize).sum();
    if item_bytes != record_len {
        return Err(Error::input(path, format!("point record length {record_len} disagrees with the laszip record's items ({item_bytes} bytes)")));
    }
    if chunk_size == 0 {
        return Err(Error::input(path, "laszip record declares chunks of 0 points"));
    }
    // The chunk table's offset follows the header; a writer that could not seek back puts it
    // in the file's last 8 bytes instead (the `laz` crate looks there too).
    let len = bytes.len() as u64;
    let offset_at = |at: u64| le::<8>(bytes, at).map(i64::from_le_bytes).filter(|&o| o > data_start as i64).map(|o| o as u64);
    let Some(table_at) = offset_at(data_start).or_else(|| offset_at(len.saturating_sub(8))) else {
        return Ok(());
    };
    let Some(count) = le::<4>(bytes, table_at.saturating_add(4)).map(u32::from_le_bytes) else {
        return Err(Error::input(path, format!("the chunk table's offset {table_at} is past the end of the file ({len} bytes)")));
    };
    // Each chunk takes at least a byte between the points' start and the table.
    if count as u64 > table_at - data_start {
        return Err(Error::input(path, format!("the chunk table declares {count} chunks in {} bytes of compressed points", table_at - data_start)));
    }
    // Layered chunks (point formats 6-10) declare the size of each layer, which the decoder
    // allocates before reading it (4 GB for a flipped byte): check them against the chunk.
    let layer_words: usize = table
        .chunks_exact(6)
        .map(|it| match u16::from_le_bytes([it[0], it[1]]) {
            10 => 9, // Point14: nine layers
            11 | 13 => 1,
            12 => 2, // RGB and NIR
            14 => u16::from_le_bytes([it[2], it[3]]) as usize,
            _ => 0,
        })
        .sum();
    if layer_words > 0 {
        check_layers(path, bytes, d, data_start..table_at, record_len, layer_words)?;
    }
    Ok(())
}

/// Checks that the layers each chunk declares fit in the chunk (see [`check_laz`]), the chunks
/// lying in `points` (from the points' start to the chunk table). A chunk opens with its first
/// point, raw, the number of points, and one size per layer.
fn check_layers(path: &Path, bytes: &[u8], vlr: &[u8], points: std::ops::Range<u64>, record_len: usize, words: usize) -> Result<()> {
    let (data_start, table_at) = (points.start, points.end);
    let bad = |what: String| Error::input(path, format!("corrupt compressed point data: {what}"));
    let vlr = laz::LazVlr::from_buffer(vlr).map_err(|e| bad(format!("unreadable laszip record ({e})")))?;
    let mut src = Cursor::new(bytes);
    src.set_position(data_start);
    let chunks = laz::laszip::ChunkTable::read_from(&mut src, &vlr).map_err(|e| bad(format!("unreadable chunk table ({e})")))?;
    let mut at = data_start + 8;
    for (k, c) in chunks.as_ref().iter().enumerate() {
        let end = at.checked_add(c.byte_count).filter(|&e| e <= table_at).ok_or_else(|| bad(format!("chunk {k} runs past the chunk table")))?;
        let sizes_at = at + record_len as u64 + 4;
        let layers_at = sizes_at + 4 * words as u64;
        if c.byte_count > 0 && layers_at > end {
            return Err(bad(format!("chunk {k} ({} bytes) is shorter than its header", c.byte_count)));
        }
        if c.byte_count > 0 {
            let declared: u64 = (0..words as u64).map(|w| le::<4>(bytes, sizes_at + 4 * w).map_or(0, |b| u32::from_le_bytes(b) as u64)).sum();
            if declared > end - layers_at {
                return Err(bad(format!("chunk {k} declares {declared} bytes of layers in {}", end - layers_at)));
            }
        }
        at = end;
    }
    Ok(())
}

fn cloud_header(path: &Path, p: &Parsed) -> Result<CloudHeader> {
    let h = &p.header;
    let b = h.bounds();
    let bounds = Bounds { min: [b.min.x, b.min.y, b.min.z], max: [b.max.x, b.max.y, b.max.z] };
    let fmt = h.point_format().to_u8().map_err(|e| las_error(path, e))?;
    Ok(CloudHeader {
        path: path.to_path_buf(),
        format: if p.compressed { FileFormat::Laz } else { FileFormat::Las },
        // (A COPC file reads only the octree nodes that meet `--bounds`: worth knowing.)
        version: if h.copc_info_vlr().is_some() { format!("{} (COPC)", h.version()) } else { h.version().to_string() },
        point_format: Some(fmt),
        count: h.number_of_points(),
        bounds,
        crs: p.crs.clone(),
        precision: Precision::Scaled(p.layout.scale.max_element()),
        scanners: vec![],
    })
}

/// Reads only the header of a LAS/LAZ file.
pub(super) fn read_header(path: &Path) -> Result<CloudHeader> {
    let map = map_file(path)?;
    let parsed = parse(path, &map)?;
    cloud_header(path, &parsed)
}

enum Points {
    /// Uncompressed: records are read straight from the map.
    Mapped { map: Mmap, offset: usize },
    /// Compressed: the `las` crate decompresses into a reusable buffer.
    Compressed { reader: Box<las::Reader>, buf: las::PointData },
    /// COPC read with bounds: only the octree nodes that meet them are decompressed, several
    /// side by side, by readers of their own (opened as needed, one a thread at most), and
    /// handed on in file order.
    Copc { readers: Vec<CopcFileReader>, nodes: Vec<Node>, next: usize },
}

type CopcFileReader = las::CopcReader<'static, std::io::BufReader<File>>;

/// Nodes decompressed side by side, per thread: enough to even out nodes of different sizes.
const COPC_NODES_PER_THREAD: usize = 4;

/// A COPC octree node with points: its hierarchy entry, and the record index of its first point
/// (the nodes' points follow each other in file order, so a node read alone gives its points
/// the indices a front-to-back read gives them).
struct Node {
    entry: las::copc::Entry,
    first: u64,
}

/// The most points a COPC node may hold (COPC writers keep nodes to some 100 000).
const MAX_NODE_POINTS: i32 = 1 << 23;

/// The nodes of a COPC file's octree that meet `bounds`, in file order, checked against the
/// header and the file: `None` if the file is not COPC.
fn copc_nodes(path: &Path, bytes: &[u8], header: &las::Header, bounds: &Bounds, scale: DVec3) -> Result<Option<Vec<Node>>> {
    let Some(info) = header.copc_info_vlr() else {
        return Ok(None);
    };
    let bad = |what: String| Error::input(path, format!("invalid COPC hierarchy: {what}"));
    let hierarchy = header.copc_hierarchy_evlr().ok_or_else(|| bad("no hierarchy EVLR".into()))?;
    let entries = super::guarded(path, "the COPC hierarchy", || hierarchy.iter_entries().collect::<las::Result<Vec<_>>>().map_err(|e| bad(e.to_string())))?;
    let mut with_points: Vec<las::copc::Entry> = entries.into_iter().filter(|e| e.point_count > 0).copied().collect();
    with_points.sort_by_key(|e| e.offset);
    let (count, len) = (header.number_of_points(), bytes.len() as u64);
    let (mut first, mut nodes) = (0u64, vec![]);
    for e in with_points {
        let k = e.key;
        if !(0..=30).contains(&k.l) || [k.x, k.y, k.z].iter().any(|&c| c < 0 || (c as i64) >> k.l != 0) {
            return Err(bad(format!("node key {}-{}-{}-{} is outside the octree", k.l, k.x, k.y, k.z)));
        }
        if e.byte_size <= 0 || e.offset.checked_add(e.byte_size as u64).is_none_or(|end| end > len) {
            return Err(bad(format!("node {}-{}-{}-{} lies past the end of the file ({len} bytes)", k.l, k.x, k.y, k.z)));
        }
        // (A node is decompressed whole: its declared count sizes the buffer.)
        if e.point_count > MAX_NODE_POINTS {
            return Err(bad(format!(
                "node {}-{}-{}-{} declares {} points, more than crease reads in one node ({MAX_NODE_POINTS})",
                k.l, k.x, k.y, k.z, e.point_count
            )));
        }
        let b = k.bounds(&info);
        // (A point is stored in the node its scaled coordinates fall in: allow one unit of the
        // scale either side.)
        let node = Bounds { min: (DVec3::new(b.min.x, b.min.y, b.min.z) - scale).to_array(), max: (DVec3::new(b.max.x, b.max.y, b.max.z) + scale).to_array() };
        if node.meets(bounds) {
            nodes.push(Node { entry: e, first });
        }
        first += e.point_count as u64;
    }
    if first != count {
        return Err(bad(format!("its nodes hold {first} points but the header declares {count}")));
    }
    Ok(Some(nodes))
}

/// Opens a reader of the COPC file `path`.
fn open_copc(path: &Path) -> Result<CopcFileReader> {
    super::guarded(path, "the COPC reader", || las::CopcReader::from_path(path).map_err(|e| las_error(path, e)))
}

/// Decompresses the points of COPC node `node` of `path`.
fn read_node(path: &Path, reader: &mut CopcFileReader, node: &Node) -> Result<las::PointData> {
    let k = node.entry.key;
    let corrupt = |e: las::Error| Error::input(path, format!("corrupt compressed point data in COPC node {}-{}-{}-{}: {e}", k.l, k.x, k.y, k.z));
    super::guarded(path, "the COPC decoder", || reader.read_entry(&node.entry).map_err(corrupt))
}

/// A chunked reader over one LAS or LAZ file.
pub(super) struct LasReader {
    path: PathBuf,
    header: CloudHeader,
    layout: Layout,
    points: Points,
    next: u64,
}

impl LasReader {
    /// Maps the file and parses its header. With `bounds`, a COPC file is read through its
    /// octree: only the nodes that meet the box are decompressed (the caller still drops the
    /// points outside it).
    pub(super) fn open(path: &Path, bounds: Option<&Bounds>) -> Result<LasReader> {
        let map = map_file(path)?;
        let parsed = parse(path, &map)?;
        let header = cloud_header(path, &parsed)?;
        let layout = parsed.layout;
        let copc = match bounds {
            Some(b) if parsed.compressed => copc_nodes(path, &map, &parsed.header, b, layout.scale)?,
            _ => None,
        };
        let points = if let Some(nodes) = copc {
            drop(map);
            Points::Copc { readers: vec![open_copc(path)?], nodes, next: 0 }
        } else if parsed.compressed {
            // Decompression reads the file once, front to back: a buffered reader keeps resident
            // memory bounded, where a map would keep every page touched.
            drop(map);
            let file = File::open(path).map_err(|e| io_input(path, e))?;
            let reader =
                super::guarded(path, "the LAZ decoder", || las::Reader::new(std::io::BufReader::with_capacity(1 << 20, file)).map_err(|e| las_error(path, e)))?;
            let buf = las::PointDataBuilder::new().for_header(reader.header()).build();
            Points::Compressed { reader: Box::new(reader), buf }
        } else {
            #[cfg(unix)]
            let _ = map.advise(memmap2::Advice::Sequential);
            Points::Mapped { map, offset: parsed.offset_to_points as usize }
        };
        Ok(LasReader { path: path.to_path_buf(), header, layout, points, next: 0 })
    }

    /// The file's header.
    pub(super) fn header(&self) -> &CloudHeader {
        &self.header
    }

    /// Reads up to `max` records into `out` (filtered); returns the number of records read.
    pub(super) fn read_chunk(&mut self, max: usize, out: &mut PointChunk, table: &[bool; 256], keep_withheld: bool) -> Result<usize> {
        let left = self.header.count - self.next;
        let n = (max as u64).min(left) as usize;
        if n == 0 {
            return Ok(0);
        }
        let rl = self.layout.record_len;
        match &mut self.points {
            Points::Mapped { map, offset } => {
                let start = *offset + self.next as usize * rl;
                self.layout.decode(&map[start..start + n * rl], self.next, out, table, keep_withheld);
                super::release(map, start, start + n * rl);
            }
            Points::Compressed { reader, buf } => {
                let path = &self.path;
                let got = super::guarded(path, "the LAZ decoder", || reader.fill_points(n as u64, buf).map_err(|e| las_error(path, e)))?;
                if got as usize != n {
                    return Err(Error::input(&self.path, format!("header declares {} points but the data ends after {}", self.header.count, self.next + got)));
                }
                let layout = Layout { record_len: buf.record_len(), ..self.layout };
                layout.decode(buf.raw_bytes(), self.next, out, table, keep_withheld);
            }
            Points::Copc { readers, nodes, next } => {
                if *next == nodes.len() {
                    return Ok(0);
                }
                // The next nodes, up to `max` points (at least one node), a few a thread.
                let threads = rayon::current_num_threads().max(1);
                let mut end = *next + 1;
                let mut records = nodes[*next].entry.point_count as u64;
                while end < nodes.len() && end - *next < COPC_NODES_PER_THREAD * threads && records + nodes[end].entry.point_count as u64 <= max as u64 {
                    records += nodes[end].entry.point_count as u64;
                    end += 1;
                }
                let batch = &nodes[*next..end];
                while readers.len() < threads.min(batch.len()) {
                    readers.push(open_copc(&self.path)?);
                }
                // (Reader k takes nodes k, k + R, k + 2R, ... of the batch.)
                let path = &self.path;
                let r = readers.len();
                let decoded: Vec<Vec<Result<las::PointData>>> = readers
                    .par_iter_mut()
                    .enumerate()
                    .map(|(k, reader)| batch.iter().skip(k).step_by(r).map(|node| read_node(path, reader, node)).collect())
                    .collect();
                let mut decoded: Vec<std::vec::IntoIter<Result<las::PointData>>> = decoded.into_iter().map(Vec::into_iter).collect();
                for (i, node) in batch.iter().enumerate() {
                    let data = decoded[i % r].next().expect("a node's points")?;
                    let layout = Layout { record_len: data.record_len(), ..self.layout };
                    layout.decode(data.raw_bytes(), node.first, out, table, keep_withheld);
                }
                *next = end;
                return Ok(records as usize);
            }
        }
        self.next += n as u64;
        Ok(n)
    }
}
