//! Labelled copies of input files (`--label-points`): every point of a file, in its order and
//! with all its own fields, plus three fields a [`Labeller`] gives it: `edge_distance` (f64),
//! `curve_id` (i32) and `edge` (u8).
//!
//! - LAS and LAZ inputs become LAZ 1.4 files of the same point format, each record copied byte
//!   for byte (coordinates keep their scale and offset) with the three fields appended as extra
//!   bytes, described by an Extra Bytes VLR (`LASF_Spec`, record 4; the input's own extra bytes
//!   keep their descriptors, and come first). The header's VLRs are kept, but for the laszip
//!   record (written anew) and COPC's (the copy is not a COPC file).
//! - E57 and text inputs become LAZ 1.4 files of point format 6: the points as crease reads them
//!   (x, y, z and the class; a text cloud's other columns are not carried), stored at a scale
//!   fine enough for their extent (about a billionth of it), with the CRS as a WKT if the file
//!   names one.
//! - PLY inputs become PLY files of the same encoding: the header with three vertex
//!   properties added, each vertex record copied and the three values appended, every other
//!   element copied as it was.
//!
//! Points are read, labelled and written a chunk at a time, so memory does not grow with the
//! file.

use super::label::{Labeller, LABEL_BYTES, LABEL_CHUNK, LABEL_FIELDS};
use super::{guarded, Filter, PointReader, TextColumns};
use crate::cancel::Cancel;
use crate::error::{io_input, Error, Result};
use crate::points::{Bounds, FileFormat, PointChunk};
use glam::DVec3;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// The extension of the labelled copy of `input`: `ply` for PLY, else `laz`.
pub fn labelled_extension(input: &Path) -> &'static str {
    if super::format_of(input) == Some(FileFormat::Ply) {
        "ply"
    } else {
        "laz"
    }
}

/// Writes the labelled copy of `input` (see the module docs) to `output`, synced; returns the
/// number of points written. `text` says where a text cloud's columns are, as for the run.
/// Stops between chunks when `cancel` is set.
pub fn write_labelled(input: &Path, output: &Path, text: Option<TextColumns>, labeller: &dyn Labeller, cancel: &Cancel) -> Result<u64> {
    let n = match super::format_of(input) {
        Some(FileFormat::Las | FileFormat::Laz) => label_las(input, output, labeller, cancel)?,
        Some(FileFormat::Ply) => super::ply::label_ply(input, output, labeller, cancel)?,
        Some(FileFormat::E57 | FileFormat::Text) => label_read_points(input, output, text, labeller, cancel)?,
        None => return Err(Error::input(input, "unknown file type")),
    };
    File::open(output).and_then(|f| f.sync_all()).map_err(|e| Error::output(output, e))?;
    Ok(n)
}

fn las_out(output: &Path, e: las::Error) -> Error {
    Error::output(output, std::io::Error::other(e))
}

/// Copies a LAS or LAZ file's records with their labels appended (see the module docs).
fn label_las(input: &Path, output: &Path, labeller: &dyn Labeller, cancel: &Cancel) -> Result<u64> {
    // (crease's own reader checks the header and the compressed data's tables first.)
    let declared = super::las::read_header(input)?.count;
    let file = File::open(input).map_err(|e| io_input(input, e))?;
    let mut reader = guarded(input, "the LAS reader", || {
        las::Reader::new(std::io::BufReader::with_capacity(1 << 20, file)).map_err(|e| Error::input(input, format!("invalid LAS file: {e}")))
    })?;
    let header = labelled_header(input, reader.header())?;
    let (format, transforms) = (*header.point_format(), *header.transforms());
    let out = File::create(output).map_err(|e| Error::output(output, e))?;
    let mut writer = las::Writer::new(BufWriter::with_capacity(1 << 20, out), header).map_err(|e| las_out(output, e))?;
    let mut buf = las::PointDataBuilder::new().for_header(reader.header()).build();
    let (mut xyz, mut labels, mut written) = (vec![], vec![], 0u64);
    loop {
        cancel.check()?;
        let got = guarded(input, "the LAZ decoder", || {
            reader.fill_points(LABEL_CHUNK as u64, &mut buf).map_err(|e| Error::input(input, format!("corrupt point data: {e}")))
        })?;
        if got == 0 {
            break;
        }
        let rl = buf.record_len();
        xyz.clear();
        xyz.extend(buf.raw_bytes().chunks_exact(rl).map(|r| record_xyz(r, &transforms)));
        labeller.label(&xyz, &mut labels);
        // (A labeller stopped by the cancel leaves the chunk's labels unset.)
        cancel.check()?;
        let mut bytes = Vec::with_capacity(xyz.len() * (rl + LABEL_BYTES as usize));
        for (r, l) in buf.raw_bytes().chunks_exact(rl).zip(&labels) {
            bytes.extend_from_slice(r);
            l.push_bytes(&mut bytes, false);
        }
        let slab = las::PointDataBuilder::new().with_format(format).with_transforms(transforms).build_from_bytes(bytes).map_err(|e| las_out(output, e))?;
        writer.write_points(&slab).map_err(|e| las_out(output, e))?;
        written += got;
    }
    if written != declared {
        return Err(Error::input(input, format!("header declares {declared} points but the data ends after {written}")));
    }
    writer.close().map_err(|e| las_out(output, e))?;
    Ok(written)
}

/// The world coordinates of a LAS record (x, y, z lead every point format).
fn record_xyz(r: &[u8], t: &las::Vector<las::Transform>) -> DVec3 {
    let i = |k: usize| i32::from_le_bytes([r[k], r[k + 1], r[k + 2], r[k + 3]]) as f64;
    DVec3::new(i(0) * t.x.scale + t.x.offset, i(4) * t.y.scale + t.y.offset, i(8) * t.z.scale + t.z.offset)
}

/// True for the VLRs the labelled copy does not carry over: the laszip record (written anew for
/// the new record layout), COPC's (the copy is no COPC file), and the Extra Bytes record
/// (written anew with the labels' descriptors).
fn dropped_vlr(v: &las::Vlr) -> bool {
    v.user_id == "laszip encoded" || v.user_id == "copc" || is_extra_bytes(v)
}

fn is_extra_bytes(v: &las::Vlr) -> bool {
    v.user_id == "LASF_Spec" && v.record_id == 4
}

/// The header of the labelled copy of a LAS file whose header is `input`: LAS 1.4, compressed,
/// the same point format with the labels' extra bytes after the file's own.
fn labelled_header(path: &Path, input: &las::Header) -> Result<las::Header> {
    let own = input.point_format().extra_bytes;
    let held = input.all_vlrs().find(|v| is_extra_bytes(v)).map(|v| v.data.clone()).unwrap_or_default();
    let descriptors = extra_bytes_vlr(path, &held, own)?;
    let mut b = las::Builder::from(input.clone());
    b.version = las::Version::new(1, 4);
    b.point_format.is_compressed = true;
    b.point_format.extra_bytes = own + LABEL_BYTES;
    b.vlrs.retain(|v| !dropped_vlr(v));
    b.evlrs.retain(|v| !dropped_vlr(v));
    b.vlrs.push(descriptors);
    b.point_padding.clear();
    b.generating_software = format!("crease {}", env!("CARGO_PKG_VERSION"));
    b.into_header().map_err(|e| Error::input(path, format!("cannot be copied as LAS 1.4: {e}")))
}

/// Size of an Extra Bytes descriptor.
const DESCRIPTOR: usize = 192;

/// Bytes a value of an Extra Bytes descriptor's data type takes (type 0: `options` bytes).
fn descriptor_size(d: &[u8]) -> usize {
    const SIZES: [usize; 10] = [1, 1, 2, 2, 4, 4, 8, 8, 4, 8];
    match d[2] {
        0 => d[3] as usize,
        t @ 1..=10 => SIZES[t as usize - 1],
        t @ 11..=20 => 2 * SIZES[t as usize - 11],
        t @ 21..=30 => 3 * SIZES[t as usize - 21],
        _ => 0,
    }
}

/// An Extra Bytes descriptor of a value named `name` of data type `ty` (0: `options` bytes of
/// no declared type), with `description`.
fn descriptor(ty: u8, options: u8, name: &str, description: &str) -> [u8; DESCRIPTOR] {
    let mut d = [0u8; DESCRIPTOR];
    d[2] = ty;
    d[3] = options;
    // (Both fields are 32 bytes, NUL-padded.)
    let (name, description) = (&name.as_bytes()[..name.len().min(31)], &description.as_bytes()[..description.len().min(31)]);
    d[4..4 + name.len()].copy_from_slice(name);
    d[160..160 + description.len()].copy_from_slice(description);
    d
}

/// The Extra Bytes VLR of the labelled copy: the descriptors the file `held` for its own `own`
/// extra bytes (bytes no descriptor covers described as untyped), then the labels'. A file whose
/// own extra bytes already name a label field is refused.
fn extra_bytes_vlr(path: &Path, held: &[u8], own: u16) -> Result<las::Vlr> {
    let mut data = vec![];
    let mut covered = 0usize;
    for d in held.chunks_exact(DESCRIPTOR) {
        let size = descriptor_size(d);
        if covered + size > own as usize {
            break;
        }
        let name = String::from_utf8_lossy(&d[4..36]).trim_end_matches('\0').to_string();
        if LABEL_FIELDS.contains(&name.as_str()) {
            return Err(Error::input(path, format!("already has an extra dimension named {name}, which the labelled copy would add")));
        }
        data.extend_from_slice(d);
        covered += size;
    }
    let mut left = own as usize - covered;
    while left > 0 {
        let n = left.min(255);
        data.extend_from_slice(&descriptor(0, n as u8, "", ""));
        left -= n;
    }
    data.extend_from_slice(&descriptor(10, 0, LABEL_FIELDS[0], "distance to the nearest curve"));
    data.extend_from_slice(&descriptor(6, 0, LABEL_FIELDS[1], "nearest curve's id, -1 if far"));
    data.extend_from_slice(&descriptor(1, 0, LABEL_FIELDS[2], "1 within the curve tolerance"));
    Ok(las::Vlr { user_id: "LASF_Spec".into(), record_id: 4, description: "crease labels".into(), data })
}

/// Record length of point format 6.
const FORMAT6_LEN: usize = 30;

/// Writes an E57 or text cloud's points, as crease reads them, as a LAZ 1.4 file of point format
/// 6 with the labels (see the module docs). The file is read twice: once for its bounds, which
/// set the scale and offset.
fn label_read_points(input: &Path, output: &Path, text: Option<TextColumns>, labeller: &dyn Labeller, cancel: &Cancel) -> Result<u64> {
    let filter = Filter { text, ..Filter::keep_all() };
    let mut reader = PointReader::open(input, &filter)?.cancelled_by(cancel);
    let crs = reader.header().crs.clone();
    let (bounds, _) = super::scan_bounds_or_cancel(input, &filter, cancel)?;
    let header = generated_header(&bounds, crs.wkt.as_deref())?;
    let transforms = *header.transforms();
    let format = *header.point_format();
    let out = File::create(output).map_err(|e| Error::output(output, e))?;
    let mut writer = las::Writer::new(BufWriter::with_capacity(1 << 20, out), header).map_err(|e| las_out(output, e))?;
    let (mut chunk, mut labels, mut written) = (PointChunk::default(), vec![], 0u64);
    loop {
        cancel.check()?;
        if reader.read_chunk(LABEL_CHUNK, &mut chunk)? == 0 {
            break;
        }
        labeller.label(&chunk.xyz, &mut labels);
        cancel.check()?;
        let mut bytes = Vec::with_capacity(chunk.len() * (FORMAT6_LEN + LABEL_BYTES as usize));
        for ((p, &class), l) in chunk.xyz.iter().zip(&chunk.class).zip(&labels) {
            push_format6(&mut bytes, *p, class, &transforms);
            l.push_bytes(&mut bytes, false);
        }
        let slab = las::PointDataBuilder::new().with_format(format).with_transforms(transforms).build_from_bytes(bytes).map_err(|e| las_out(output, e))?;
        writer.write_points(&slab).map_err(|e| las_out(output, e))?;
        written += chunk.len() as u64;
    }
    writer.close().map_err(|e| las_out(output, e))?;
    Ok(written)
}

/// Appends a point format 6 record of `p` and its class: one return of one, nothing else set.
fn push_format6(out: &mut Vec<u8>, p: DVec3, class: u8, t: &las::Vector<las::Transform>) {
    let q = |v: f64, t: &las::Transform| ((v - t.offset) / t.scale).round() as i32;
    for (v, t) in [(p.x, &t.x), (p.y, &t.y), (p.z, &t.z)] {
        out.extend_from_slice(&q(v, t).to_le_bytes());
    }
    // intensity, returns (1 of 1), flags, class, user data, scan angle, source id, GPS time.
    out.extend_from_slice(&[0, 0, 0x11, 0, class, 0, 0, 0, 0, 0]);
    out.extend_from_slice(&0f64.to_le_bytes());
}

/// The header of a labelled copy of points without a LAS header of their own: LAS 1.4, point
/// format 6 with the labels' extra bytes, offset at the low corner of `bounds` and a scale of a
/// power of ten near a billionth of their extent (so every coordinate fits in 31 bits), and the
/// CRS `wkt`, if any.
fn generated_header(bounds: &Bounds, wkt: Option<&str>) -> Result<las::Header> {
    let (lo, hi) = if bounds.is_empty() { (DVec3::ZERO, DVec3::ONE) } else { (DVec3::from(bounds.min), DVec3::from(bounds.max)) };
    let extent = (hi - lo).max_element().max(1e-9);
    let scale = 10f64.powf((extent / 1e9).log10().ceil());
    let mut b = las::Builder::from((1, 4));
    b.point_format = las::point::Format::new(6).expect("format 6");
    b.point_format.is_compressed = true;
    b.point_format.extra_bytes = LABEL_BYTES;
    let t = |o: f64| las::Transform { scale, offset: o };
    b.transforms = las::Vector { x: t(lo.x), y: t(lo.y), z: t(lo.z) };
    b.generating_software = format!("crease {}", env!("CARGO_PKG_VERSION"));
    b.vlrs.push(extra_bytes_vlr(Path::new(""), &[], 0)?);
    if let Some(w) = wkt {
        let mut data = w.as_bytes().to_vec();
        data.push(0);
        b.vlrs.push(las::Vlr { user_id: "LASF_Projection".into(), record_id: 2112, description: "OGC WKT".into(), data });
    }
    b.into_header().map_err(|e| Error::Usage(format!("a labelled copy's header: {e}")))
}
