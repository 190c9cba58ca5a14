//! Wavefront OBJ polylines: `v x y z` vertices and `l i j k ...` lines, one `o` per curve, with
//! the curve's confidence in a `# confidence c` comment after it, and its other attributes
//! (length, mean dihedral angle, shape, end kinds, corner vertices) in a `# length ...` comment (other
//! readers skip both).
//! Corner vertices shared by several curves are written once and referenced by each.

use super::{Curves, Polyline, Shape, Vertex};
use crate::crs::Crs;
use crate::error::{io_input, Error, Result};
use glam::DVec3;
use std::collections::HashMap;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;

/// Writes `curves` to `path` as OBJ.
///
/// ```
/// use crease::curves::{read_obj, write_obj, Polyline};
/// use glam::DVec3;
///
/// let path = std::env::temp_dir().join("crease-doc-curves.obj");
/// write_obj(&path, &[Polyline::from_points(0, [DVec3::ZERO, DVec3::X, DVec3::ONE])], &Default::default())?;
/// assert_eq!(read_obj(&path)?[0].vertices.len(), 3);
/// # Ok::<(), crease::Error>(())
/// ```
pub fn write_obj(path: &Path, curves: &(impl Curves + ?Sized), crs: &Crs) -> Result<()> {
    let f = std::fs::File::create(path).map_err(|e| Error::output(path, e))?;
    let mut w = BufWriter::new(f);
    let out = |e| Error::output(path, e);
    let mut count = 0;
    curves.each(&mut |_| {
        count += 1;
        Ok(())
    })?;
    writeln!(w, "# crease feature curves: {count} polylines").map_err(out)?;
    if !crs.is_unknown() {
        writeln!(w, "# crs {}", crs.summary().replace(['\n', '\r'], " ")).map_err(out)?;
    }
    // The vertex table, then the lines, which number the vertices again the same way.
    let mut table = VertexTable::default();
    curves.each(&mut |c| {
        for v in &c.vertices {
            if table.number(v).1 {
                writeln!(w, "v {} {} {}", v.p.x, v.p.y, v.p.z).map_err(out)?;
            }
        }
        Ok(())
    })?;
    let mut table = VertexTable::default();
    curves.each(&mut |c| write_line(&mut w, c, &mut table).map_err(out))?;
    w.flush().map_err(out)
}

/// Numbers the vertices as written, from 1; corners with identical positions are shared.
#[derive(Default)]
struct VertexTable {
    corners: HashMap<[u64; 3], usize>,
    next: usize,
}

impl VertexTable {
    /// The number of vertex `v`, and true if it is new (to be written).
    fn number(&mut self, v: &Vertex) -> (usize, bool) {
        if v.corner
            && let Some(&i) = self.corners.get(&v.p.to_array().map(f64::to_bits))
        {
            return (i, false);
        }
        self.next += 1;
        if v.corner {
            self.corners.insert(v.p.to_array().map(f64::to_bits), self.next);
        }
        (self.next, true)
    }
}

/// Curve `c`'s object name, attributes and line.
fn write_line(w: &mut impl Write, c: &Polyline, table: &mut VertexTable) -> std::io::Result<()> {
    let mut idx: Vec<usize> = c.vertices.iter().map(|v| table.number(v).0).collect();
    if c.closed && !idx.is_empty() {
        idx.push(idx[0]);
    }
    writeln!(w, "o curve_{}", c.id)?;
    writeln!(w, "# confidence {}", c.confidence)?;
    let [start, end] = c.end_kinds();
    let angle = c.mean_dihedral_angle().map_or("unknown".to_string(), |a| format!("{a:.1}"));
    let corners = c.corner_list();
    writeln!(
        w,
        "# length {} angle {angle} shape {} start {start} end {end} corners {}",
        c.length(),
        c.shape.name(),
        if corners.is_empty() { "none" } else { &corners }
    )?;
    write!(w, "l")?;
    for i in idx {
        write!(w, " {i}")?;
    }
    writeln!(w)
}

/// Reads the polylines of an OBJ file (`l` elements; `f` faces are ignored). A line whose
/// last index repeats its first is closed. Curve ids come from `o curve_N` names when present,
/// else from the order of the lines. Vertices used by two or more lines are marked as corners.
pub fn read_obj(path: &Path) -> Result<Vec<Polyline>> {
    let f = std::fs::File::open(path).map_err(|e| io_input(path, e))?;
    let mut verts: Vec<DVec3> = Vec::new();
    let mut lines: Vec<(Option<u32>, f32, Shape, Vec<usize>)> = Vec::new();
    let mut pending_id: Option<u32> = None;
    let mut pending_confidence = 1.0;
    let mut pending_shape = Shape::Unknown;
    for (no, line) in BufReader::new(f).lines().enumerate() {
        let line = line.map_err(|e| io_input(path, e))?;
        let mut t = line.split_whitespace();
        let bad = |m: &str| Error::input(path, format!("line {}: {m}", no + 1));
        match t.next() {
            Some("v") => {
                let c: Vec<f64> = t.take(3).map(|s| s.parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad("bad vertex"))?;
                if c.len() != 3 || c.iter().any(|x| !x.is_finite()) {
                    return Err(bad("bad vertex"));
                }
                verts.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("o") | Some("g") => {
                pending_id = t.next().and_then(|n| n.strip_prefix("curve_")).and_then(|s| s.parse().ok());
            }
            Some("#") => match t.next() {
                Some("confidence") => {
                    pending_confidence = t.next().and_then(|s| s.parse().ok()).filter(|c: &f32| c.is_finite()).ok_or_else(|| bad("bad confidence"))?;
                }
                // (`# length L angle A shape S ...`: the shape is the word after `shape`.)
                Some("length") => {
                    pending_shape = match t.skip_while(|w| *w != "shape").nth(1) {
                        Some("convex") => Shape::Convex,
                        Some("concave") => Shape::Concave,
                        _ => Shape::Unknown,
                    };
                }
                _ => {}
            },
            Some("l") => {
                let mut idx = Vec::new();
                for s in t {
                    // "l" entries may be "v/vt"; only the vertex index matters.
                    let first = s.split('/').next().unwrap_or("");
                    let i: i64 = first.parse().map_err(|_| bad("bad line index"))?;
                    let i = if i < 0 { verts.len() as i64 + i } else { i - 1 };
                    if i < 0 {
                        return Err(bad("line index out of range"));
                    }
                    idx.push(i as usize);
                }
                lines.push((pending_id.take(), std::mem::replace(&mut pending_confidence, 1.0), std::mem::take(&mut pending_shape), idx));
            }
            _ => {}
        }
    }
    let mut uses = vec![0u32; verts.len()];
    for (_, _, _, idx) in &lines {
        let n = idx.len();
        let closed = n > 2 && idx[0] == idx[n - 1];
        let end = if closed { n - 1 } else { n };
        for &i in &idx[..end] {
            if i >= verts.len() {
                return Err(Error::input(path, format!("line refers to vertex {} of {}", i + 1, verts.len())));
            }
            uses[i] += 1;
        }
    }
    let mut out = Vec::with_capacity(lines.len());
    for (k, (id, confidence, shape, mut idx)) in lines.into_iter().enumerate() {
        let closed = idx.len() > 2 && idx[0] == idx[idx.len() - 1];
        if closed {
            idx.pop();
        }
        let vertices = idx.iter().map(|&i| Vertex { corner: uses[i] > 1, ..Vertex::at(verts[i]) }).collect();
        out.push(Polyline { id: id.unwrap_or(k as u32), closed, vertices, confidence, shape });
    }
    Ok(out)
}
