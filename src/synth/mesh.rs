//! Triangle meshes (OFF, OBJ): area-weighted sampling and sharp edges as ground truth.

use super::shapes::Shape;
use super::surface::Surface;
use crate::error::{io_input, Error, Result};
use glam::DVec3;
use std::collections::HashMap;
use std::path::Path;

/// A triangle mesh.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub vertices: Vec<DVec3>,
    /// Triangles (polygons are fanned).
    pub triangles: Vec<[u32; 3]>,
}

/// Reads an OFF or OBJ mesh (faces with more than three vertices are fanned into triangles).
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    let text = std::fs::read_to_string(path).map_err(|e| io_input(path, e))?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let mesh = match ext.as_str() {
        "off" => parse_off(&text).map_err(|m| Error::input(path, m))?,
        "obj" => parse_obj(&text).map_err(|m| Error::input(path, m))?,
        _ => return Err(Error::input(path, "unknown mesh type (expected .off or .obj)")),
    };
    if mesh.triangles.is_empty() {
        return Err(Error::input(path, "mesh has no faces"));
    }
    Ok(mesh)
}

fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    for i in 1..poly.len().saturating_sub(1) {
        out.push([poly[0], poly[i], poly[i + 1]]);
    }
}

fn parse_off(text: &str) -> std::result::Result<Mesh, String> {
    // Tokens without comments; the header may share a line with the counts ("OFF3 ...").
    let mut tok = text.lines().map(|l| l.split('#').next().unwrap_or("")).flat_map(|l| l.split_whitespace());
    let magic = tok.next().ok_or("empty file")?;
    if !magic.ends_with("OFF") {
        return Err("not an OFF file".into());
    }
    let mut num = |what: &str| -> std::result::Result<f64, String> {
        tok.next().ok_or(format!("truncated OFF ({what})"))?.parse::<f64>().map_err(|_| format!("bad number in OFF ({what})"))
    };
    let (nv, nf) = (num("counts")? as usize, num("counts")? as usize);
    num("counts")?;
    let mut m = Mesh::default();
    for _ in 0..nv {
        let p = DVec3::new(num("vertex")?, num("vertex")?, num("vertex")?);
        if !p.is_finite() {
            return Err("non-finite vertex".into());
        }
        m.vertices.push(p);
    }
    let mut poly = vec![];
    for _ in 0..nf {
        let k = num("face")? as usize;
        poly.clear();
        for _ in 0..k {
            let i = num("face")? as usize;
            if i >= nv {
                return Err(format!("face refers to vertex {i} of {nv}"));
            }
            poly.push(i as u32);
        }
        fan(&poly, &mut m.triangles);
    }
    Ok(m)
}

fn parse_obj(text: &str) -> std::result::Result<Mesh, String> {
    let mut m = Mesh::default();
    let mut poly = vec![];
    for (no, line) in text.lines().enumerate() {
        let mut t = line.split_whitespace();
        match t.next() {
            Some("v") => {
                let c: Vec<f64> = t.take(3).filter_map(|s| s.parse().ok()).collect();
                if c.len() != 3 {
                    return Err(format!("line {}: bad vertex", no + 1));
                }
                m.vertices.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                poly.clear();
                for s in t {
                    let i: i64 = s.split('/').next().unwrap_or("").parse().map_err(|_| format!("line {}: bad face", no + 1))?;
                    let i = if i < 0 { m.vertices.len() as i64 + i } else { i - 1 };
                    if i < 0 || i as usize >= m.vertices.len() {
                        return Err(format!("line {}: face index out of range", no + 1));
                    }
                    poly.push(i as u32);
                }
                fan(&poly, &mut m.triangles);
            }
            _ => {}
        }
    }
    Ok(m)
}

impl Mesh {
    /// Unit normal of triangle `t` (zero for a degenerate triangle).
    pub fn normal(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.triangles[t].map(|i| self.vertices[i as usize]);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// Edges whose two faces' normals differ by more than `angle_deg` (boundary and
    /// non-manifold edges are not counted), as sorted vertex pairs.
    pub(crate) fn sharp_edges(&self, angle_deg: f64) -> Vec<[u32; 2]> {
        let mut faces: HashMap<[u32; 2], Vec<usize>> = HashMap::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                faces.entry([a.min(b), a.max(b)]).or_default().push(t);
            }
        }
        let cos = angle_deg.to_radians().cos();
        let mut out: Vec<[u32; 2]> =
            faces.into_iter().filter(|(_, f)| f.len() == 2 && self.normal(f[0]).dot(self.normal(f[1])) < cos).map(|(e, _)| e).collect();
        out.sort_unstable();
        out
    }

    /// The mesh as sampleable surfaces with its sharp edges (chained) as truth.
    pub fn to_shape(&self, angle_deg: f64) -> Shape {
        let surfaces = self.triangles.iter().map(|t| Surface::Triangle(t.map(|i| self.vertices[i as usize]))).collect();
        let truth = chain(&self.sharp_edges(angle_deg)).into_iter().map(|c| c.into_iter().map(|i| self.vertices[i as usize]).collect()).collect();
        Shape { surfaces, truth }
    }
}

/// Chains edges into polylines that break at vertices where other than two edges meet. Loops
/// repeat their first vertex at the end.
pub(crate) fn chain(edges: &[[u32; 2]]) -> Vec<Vec<u32>> {
    let mut adj: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, e) in edges.iter().enumerate() {
        adj.entry(e[0]).or_default().push(k);
        adj.entry(e[1]).or_default().push(k);
    }
    let mut used = vec![false; edges.len()];
    let mut out = vec![];
    let other = |e: [u32; 2], v: u32| if e[0] == v { e[1] } else { e[0] };
    let walk = |start: u32, first: usize, used: &mut Vec<bool>| {
        let mut line = vec![start];
        let (mut v, mut k) = (start, first);
        loop {
            used[k] = true;
            v = other(edges[k], v);
            line.push(v);
            let a = &adj[&v];
            if a.len() != 2 {
                break;
            }
            match a.iter().find(|&&j| !used[j]) {
                Some(&j) => k = j,
                None => break,
            }
        }
        line
    };
    // Start at chain ends and junctions first, in a fixed order, then close the loops.
    let mut verts: Vec<u32> = adj.keys().copied().collect();
    verts.sort_unstable();
    for &v in &verts {
        if adj[&v].len() != 2 {
            for &k in &adj[&v].clone() {
                if !used[k] {
                    out.push(walk(v, k, &mut used));
                }
            }
        }
    }
    for k in 0..edges.len() {
        if !used[k] {
            out.push(walk(edges[k][0], k, &mut used));
        }
    }
    out
}
