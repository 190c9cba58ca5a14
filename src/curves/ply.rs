//! Binary PLY polylines: a `vertex` element (x, y, z as double; the two surface normals as
//! float, the first as nx, ny, nz and the second as n2x, n2y, n2z; curve id; corner flag; the
//! curve's confidence as float and its shape as uchar: 0 unknown, 1 convex, 2 concave) and an
//! `edge` element (vertex1, vertex2). Each curve's vertices are stored in order; a closed curve
//! has one more edge than an open one. (Files of crease 0.4 and earlier, without the
//! confidence, and of 0.7 and earlier, without the shape, are read too.)

use super::{Curves, Polyline, Shape, Vertex};
use crate::crs::Crs;
use crate::error::{io_input, Error, Result};
use glam::{DVec3, Vec3};
use std::io::{BufWriter, Write};
use std::path::Path;

/// The vertex properties. The first surface's normal is named nx, ny, nz, so that common
/// readers (Open3D, CloudCompare, trimesh) take it as the vertex normal.
const HEADER: &str = "property double x\nproperty double y\nproperty double z\n\
property float nx\nproperty float ny\nproperty float nz\n\
property float n2x\nproperty float n2y\nproperty float n2z\n\
property int curve\nproperty uchar corner\n";
/// The same layout as written by crease 0.5 and earlier (n1x, n1y, n1z).
const HEADER_0_5: &str = "property double x\nproperty double y\nproperty double z\n\
property float n1x\nproperty float n1y\nproperty float n1z\n\
property float n2x\nproperty float n2y\nproperty float n2z\n\
property int curve\nproperty uchar corner\n";
const CONFIDENCE: &str = "property float confidence\n";
const SHAPE: &str = "property uchar shape\n";
/// Bytes of a vertex with the confidence and the shape.
const VERTEX_BYTES: usize = 3 * 8 + 6 * 4 + 4 + 1 + 4 + 1;

/// Writes `curves` to `path` as binary little-endian PLY.
pub fn write_ply(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs) -> Result<()> {
    let f = std::fs::File::create(path).map_err(|e| Error::output(path, e))?;
    let mut w = BufWriter::new(f);
    let (mut nv, mut ne) = (0usize, 0usize);
    curves.each(&mut |c| {
        (nv, ne) = (nv + c.vertices.len(), ne + c.segment_count());
        Ok(())
    })?;
    let out = |e| Error::output(path, e);
    write!(w, "ply\nformat binary_little_endian 1.0\ncomment crease feature curves\n").map_err(out)?;
    if !crs.is_unknown() {
        // (A comment line ends at the line's end: the WKT, which may span lines, is left to
        // the GeoJSON.)
        writeln!(w, "comment crs {}", crs.summary().replace(['\n', '\r'], " ")).map_err(out)?;
    }
    write!(w, "element vertex {nv}\n{HEADER}{CONFIDENCE}{SHAPE}element edge {ne}\nproperty int vertex1\nproperty int vertex2\nend_header\n").map_err(out)?;
    curves.each(&mut |c| {
        let r = (|| -> std::io::Result<()> {
            for v in &c.vertices {
                for x in v.p.to_array() {
                    w.write_all(&x.to_le_bytes())?;
                }
                for n in v.n {
                    for x in n.to_array() {
                        w.write_all(&x.to_le_bytes())?;
                    }
                }
                w.write_all(&(c.id as i32).to_le_bytes())?;
                w.write_all(&[v.corner as u8])?;
                w.write_all(&c.confidence.to_le_bytes())?;
                w.write_all(&[c.shape.code()])?;
            }
            Ok(())
        })();
        r.map_err(out)
    })?;
    let mut base = 0i32;
    curves.each(&mut |c| {
        let n = c.vertices.len() as i32;
        for s in 0..c.segment_count() as i32 {
            w.write_all(&(base + s).to_le_bytes()).map_err(out)?;
            w.write_all(&(base + (s + 1) % n).to_le_bytes()).map_err(out)?;
        }
        base += n;
        Ok(())
    })?;
    w.flush().map_err(out)
}

/// Reads polylines written by [`write_ply`].
pub fn read_ply(path: &Path) -> Result<Vec<Polyline>> {
    let bytes = std::fs::read(path).map_err(|e| io_input(path, e))?;
    let bad = |m: &str| Error::input(path, m.to_string());
    let end = bytes.windows(11).position(|w| w == b"end_header\n").ok_or_else(|| bad("not a crease curve PLY (no end_header)"))?;
    let head = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("PLY header is not text"))?;
    let Some(properties) = [HEADER, HEADER_0_5].into_iter().find(|h| head.contains(h)) else {
        return Err(bad("not a crease curve PLY (unexpected properties)"));
    };
    if !head.contains("format binary_little_endian") {
        return Err(bad("not a crease curve PLY (not binary little-endian)"));
    }
    let count = |name: &str| -> Result<usize> {
        head.lines()
            .find_map(|l| l.strip_prefix(&format!("element {name} ")))
            .and_then(|s| s.trim().parse().ok())
            .ok_or_else(|| bad("PLY header lacks an element count"))
    };
    let (nv, ne) = (count("vertex")?, count("edge")?);
    let with_confidence = head.contains(&format!("{properties}{CONFIDENCE}"));
    let with_shape = head.contains(&format!("{properties}{CONFIDENCE}{SHAPE}"));
    let vertex_bytes = VERTEX_BYTES - if with_confidence { 0 } else { 4 } - if with_shape { 0 } else { 1 };
    let body = &bytes[end + 11..];
    if body.len() < nv * vertex_bytes + ne * 8 {
        return Err(bad("truncated PLY data"));
    }
    let f64_at = |o: usize| f64::from_le_bytes(body[o..o + 8].try_into().unwrap());
    let f32_at = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().unwrap());
    let i32_at = |o: usize| i32::from_le_bytes(body[o..o + 4].try_into().unwrap());
    let mut curves: Vec<Polyline> = Vec::new();
    let mut first_vertex: Vec<usize> = Vec::new();
    for i in 0..nv {
        let o = i * vertex_bytes;
        let p = DVec3::new(f64_at(o), f64_at(o + 8), f64_at(o + 16));
        let n1 = Vec3::new(f32_at(o + 24), f32_at(o + 28), f32_at(o + 32));
        let n2 = Vec3::new(f32_at(o + 36), f32_at(o + 40), f32_at(o + 44));
        let id = i32_at(o + 48) as u32;
        let corner = body[o + 52] != 0;
        let confidence = if with_confidence { f32_at(o + 53) } else { 1.0 };
        let shape = if with_shape { Shape::of_code(body[o + 57]) } else { Shape::Unknown };
        if curves.last().map(|c| c.id) != Some(id) {
            curves.push(Polyline { id, closed: false, vertices: vec![], confidence, shape });
            first_vertex.push(i);
        }
        curves.last_mut().unwrap().vertices.push(Vertex { p, n: [n1, n2], corner });
    }
    // A closed curve's extra edge runs from its last vertex back to its first.
    let eb = nv * vertex_bytes;
    for e in 0..ne {
        let a = i32_at(eb + e * 8) as usize;
        let b = i32_at(eb + e * 8 + 4) as usize;
        if b < a
            && let Ok(k) = first_vertex.binary_search(&b)
        {
            curves[k].closed = true;
        }
    }
    Ok(curves)
}
