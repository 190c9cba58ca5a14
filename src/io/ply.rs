//! PLY input: ascii, binary little- and big-endian. Only x, y, z of the `vertex` element are
//! read (as float or double); every other property and element is skipped. Binary files are
//! memory-mapped.

use crate::error::{io_input, Error, Result};
use crate::points::{Bounds, CloudHeader, Crs, FileFormat, PointChunk, Precision};
use glam::DVec3;
use memmap2::Mmap;
use std::fs::File;
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// Reads one binary value as f64.
    #[inline]
    fn read(self, b: &[u8], enc: Encoding) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                (if enc == Encoding::Big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => rd!(i16, 2),
            Scalar::U16 => rd!(u16, 2),
            Scalar::I32 => rd!(i32, 4),
            Scalar::U32 => rd!(u32, 4),
            Scalar::F32 => rd!(f32, 4),
            Scalar::F64 => rd!(f64, 8),
        }
    }
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    /// For a list property, the type of its count.
    list_count: Option<Scalar>,
    ty: Scalar,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    fn fixed_size(&self) -> Option<usize> {
        self.props.iter().map(|p| if p.list_count.is_some() { None } else { Some(p.ty.size()) }).sum()
    }
}

/// A chunked reader over one PLY file.
pub(super) struct PlyReader {
    path: PathBuf,
    header: CloudHeader,
    map: Mmap,
    enc: Encoding,
    vertex: Element,
    /// Index of x, y, z among the vertex properties.
    xyz: [usize; 3],
    /// Byte position of the next vertex (binary) or of the next token (ascii).
    pos: usize,
    /// Where the data starts, after the header's last line.
    body: usize,
    next: u64,
}

fn bad(path: &Path, msg: impl Into<String>) -> Error {
    Error::input(path, msg)
}

/// The encoding, version and elements a PLY header's text declares.
fn parse_header(text: &str, path: &Path) -> Result<(Option<Encoding>, String, Vec<Element>)> {
    let mut enc = None;
    let mut version = String::new();
    let mut elements: Vec<Element> = Vec::new();
    for (lineno, line) in text.lines().enumerate().skip(1) {
        let t: Vec<&str> = line.split_whitespace().collect();
        let err = |m: &str| bad(path, format!("PLY header line {}: {m}: '{}'", lineno + 1, line.trim()));
        match t.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                enc = Some(match t.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::Little,
                    Some("binary_big_endian") => Encoding::Big,
                    _ => return Err(err("unknown format")),
                });
                version = format!("{} {}", t.get(1).unwrap_or(&""), t.get(2).unwrap_or(&""));
            }
            Some("element") => {
                let (Some(name), Some(count)) = (t.get(1), t.get(2).and_then(|c| c.parse().ok())) else {
                    return Err(err("bad element"));
                };
                elements.push(Element { name: name.to_string(), count, props: vec![] });
            }
            Some("property") => {
                let el = elements.last_mut().ok_or_else(|| err("property before any element"))?;
                let prop = if t.get(1) == Some(&"list") {
                    let (Some(c), Some(ty), Some(name)) = (t.get(2).and_then(|s| Scalar::parse(s)), t.get(3).and_then(|s| Scalar::parse(s)), t.get(4)) else {
                        return Err(err("bad list property"));
                    };
                    Property { name: name.to_string(), list_count: Some(c), ty }
                } else {
                    let (Some(ty), Some(name)) = (t.get(1).and_then(|s| Scalar::parse(s)), t.get(2)) else {
                        return Err(err("bad property"));
                    };
                    Property { name: name.to_string(), list_count: None, ty }
                };
                el.props.push(prop);
            }
            Some(_) => return Err(err("unknown keyword")),
        }
    }
    Ok((enc, version, elements))
}

/// The coarsest precision of the three coordinate properties.
fn precision(types: [Scalar; 3]) -> Precision {
    if types.contains(&Scalar::F32) {
        Precision::Float(23)
    } else if types.contains(&Scalar::F64) {
        // (With an integer coordinate beside double ones, the integers are the coarser.)
        if types.iter().all(|&t| t == Scalar::F64) {
            Precision::Float(52)
        } else {
            Precision::Scaled(1.0)
        }
    } else {
        Precision::Scaled(1.0)
    }
}

impl PlyReader {
    /// Maps the file and parses its header.
    pub(super) fn open(path: &Path) -> Result<PlyReader> {
        let file = File::open(path).map_err(|e| io_input(path, e))?;
        let len = file.metadata().map_err(|e| io_input(path, e))?.len();
        if len == 0 {
            return Err(bad(path, "empty file"));
        }
        // SAFETY: read-only map of an input crease never writes.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| io_input(path, e))?;
        if !map.starts_with(b"ply") {
            return Err(bad(path, "not a PLY file (no 'ply' magic)"));
        }
        let end = find(&map, b"end_header").ok_or_else(|| bad(path, "truncated PLY header (no end_header)"))?;
        let mut body = end + b"end_header".len();
        // The header ends with one line break: "\n" or "\r\n".
        if map.get(body) == Some(&b'\r') {
            body += 1;
        }
        if map.get(body) == Some(&b'\n') {
            body += 1;
        }
        let text = std::str::from_utf8(&map[..end]).map_err(|_| bad(path, "PLY header is not text"))?;
        let (enc, version, elements) = parse_header(text, path)?;
        let enc = enc.ok_or_else(|| bad(path, "PLY header has no format line"))?;
        let vi = elements.iter().position(|e| e.name == "vertex").ok_or_else(|| bad(path, "PLY file has no vertex element"))?;
        let vertex = elements[vi].clone();
        let mut xyz = [usize::MAX; 3];
        for (k, name) in ["x", "y", "z"].iter().enumerate() {
            let i = vertex
                .props
                .iter()
                .position(|p| p.name == *name && p.list_count.is_none())
                .ok_or_else(|| bad(path, "PLY vertex element has no x/y/z properties"))?;
            xyz[k] = i;
        }
        // Skip the elements stored before the vertices.
        let mut pos = body;
        for e in &elements[..vi] {
            pos = skip_element(path, &map, enc, e, pos)?;
        }
        if enc != Encoding::Ascii
            && let Some(sz) = vertex.fixed_size()
        {
            // (A count near 2^64 times the record size overflows.)
            let need = vertex.count.checked_mul(sz as u64).and_then(|n| n.checked_add(pos as u64));
            if need.is_none_or(|n| n > map.len() as u64) {
                return Err(bad(
                    path,
                    format!("header declares {} vertices but the file holds only {} (truncated)", vertex.count, (map.len() - pos.min(map.len())) / sz),
                ));
            }
        }
        let header = CloudHeader {
            path: path.to_path_buf(),
            format: FileFormat::Ply,
            version,
            point_format: None,
            count: vertex.count,
            bounds: Bounds::EMPTY,
            crs: Crs::default(),
            precision: precision(xyz.map(|i| vertex.props[i].ty)),
            scanners: vec![],
        };
        #[cfg(unix)]
        let _ = map.advise(memmap2::Advice::Sequential);
        Ok(PlyReader { path: path.to_path_buf(), header, map, enc, vertex, xyz, pos, body, next: 0 })
    }

    /// The file's header (bounds are empty: PLY headers do not hold them).
    pub(super) fn header(&self) -> &CloudHeader {
        &self.header
    }

    /// Reads up to `max` vertices into `out`; returns how many were read.
    pub(super) fn read_chunk(&mut self, max: usize, out: &mut PointChunk, table: &[bool; 256]) -> Result<usize> {
        let n = (max as u64).min(self.header.count - self.next) as usize;
        if n == 0 {
            return Ok(0);
        }
        // PLY carries no classification: points are class 0 ("never classified").
        let keep = table[0];
        out.xyz.reserve(n);
        let mut v = [0.0f64; 3];
        for i in 0..n {
            let idx = self.next + i as u64;
            match self.enc {
                Encoding::Ascii => self.read_ascii_vertex(&mut v, idx)?,
                enc => self.read_binary_vertex(&mut v, idx, enc)?,
            }
            let p = DVec3::from(v);
            if !p.is_finite() {
                return Err(bad(&self.path, format!("vertex {idx} has a non-finite coordinate ({}, {}, {})", v[0], v[1], v[2])));
            }
            if keep {
                out.xyz.push(p);
                out.class.push(0);
                out.index.push(idx);
            }
        }
        self.next += n as u64;
        Ok(n)
    }

    fn truncated(&self, idx: u64) -> Error {
        bad(&self.path, format!("header declares {} vertices but the data ends at vertex {idx} (truncated)", self.header.count))
    }

    fn read_binary_vertex(&mut self, v: &mut [f64; 3], idx: u64, enc: Encoding) -> Result<()> {
        let map = &self.map[..];
        for (pi, p) in self.vertex.props.iter().enumerate() {
            if let Some(ct) = p.list_count {
                let b = map.get(self.pos..self.pos + ct.size()).ok_or_else(|| self.truncated(idx))?;
                let k = ct.read(b, enc) as usize;
                self.pos += ct.size() + k * p.ty.size();
            } else {
                let sz = p.ty.size();
                let b = map.get(self.pos..self.pos + sz).ok_or_else(|| self.truncated(idx))?;
                if let Some(k) = self.xyz.iter().position(|&x| x == pi) {
                    v[k] = p.ty.read(b, enc);
                }
                self.pos += sz;
            }
        }
        Ok(())
    }

    /// Reads vertex `idx` from its own line: a line with fewer or more values than the
    /// header's properties is an error naming it (one extra value once shifted every later
    /// vertex, and the run went on with 0 curves).
    fn read_ascii_vertex(&mut self, v: &mut [f64; 3], idx: u64) -> Result<()> {
        let map: &[u8] = &self.map;
        let mut pos = self.pos;
        while pos < map.len() && map[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if pos >= map.len() {
            return Err(self.truncated(idx));
        }
        let start = pos;
        let eol = map[pos..].iter().position(|&b| b == b'\n').map_or(map.len(), |k| pos + k);
        let line = &map[..eol];
        let wrong = |what: &str| {
            let lineno = map[..start].iter().filter(|&&b| b == b'\n').count() + 1;
            bad(&self.path, format!("vertex {idx} (line {lineno}): {what} values than the header's vertex properties"))
        };
        for (pi, p) in self.vertex.props.iter().enumerate() {
            let tok = next_token(line, &mut pos).ok_or_else(|| wrong("fewer"))?;
            if p.list_count.is_some() {
                let k: usize = parse_tok(tok).ok_or_else(|| bad(&self.path, format!("vertex {idx}: bad list count")))? as usize;
                for _ in 0..k {
                    next_token(line, &mut pos).ok_or_else(|| wrong("fewer"))?;
                }
            } else if let Some(k) = self.xyz.iter().position(|&x| x == pi) {
                v[k] = parse_tok(tok).ok_or_else(|| bad(&self.path, format!("vertex {idx}: '{}' is not a number", String::from_utf8_lossy(tok))))?;
            }
        }
        if next_token(line, &mut pos).is_some() {
            return Err(wrong("more"));
        }
        self.pos = pos;
        Ok(())
    }
}

fn parse_tok(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse::<f64>().ok()
}

fn next_token<'a>(map: &'a [u8], pos: &mut usize) -> Option<&'a [u8]> {
    while *pos < map.len() && map[*pos].is_ascii_whitespace() {
        *pos += 1;
    }
    let start = *pos;
    while *pos < map.len() && !map[*pos].is_ascii_whitespace() {
        *pos += 1;
    }
    (*pos > start).then(|| &map[start..*pos])
}

fn skip_element(path: &Path, map: &[u8], enc: Encoding, e: &Element, mut pos: usize) -> Result<usize> {
    let trunc = || bad(path, format!("truncated PLY data in element '{}'", e.name));
    if e.props.is_empty() {
        // (Nothing is stored, however many there are: counting them out would never end.)
        return Ok(pos);
    }
    if enc == Encoding::Ascii {
        for _ in 0..e.count {
            for p in &e.props {
                let tok = next_token(map, &mut pos).ok_or_else(trunc)?;
                if p.list_count.is_some() {
                    let k = parse_tok(tok).ok_or_else(trunc)? as usize;
                    for _ in 0..k {
                        next_token(map, &mut pos).ok_or_else(trunc)?;
                    }
                }
            }
        }
        return Ok(pos);
    }
    if let Some(sz) = e.fixed_size() {
        let end = e.count.checked_mul(sz as u64).and_then(|n| n.checked_add(pos as u64)).filter(|&end| end <= map.len() as u64);
        return end.map(|end| end as usize).ok_or_else(trunc);
    }
    for _ in 0..e.count {
        for p in &e.props {
            match p.list_count {
                Some(ct) => {
                    let b = map.get(pos..pos + ct.size()).ok_or_else(trunc)?;
                    pos += ct.size() + ct.read(b, enc) as usize * p.ty.size();
                }
                None => pos += p.ty.size(),
            }
        }
    }
    Ok(pos)
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    // The header is short; search only its first 64 KiB.
    let hay = &hay[..hay.len().min(1 << 16)];
    hay.windows(needle.len()).position(|w| w == needle)
}

impl PlyReader {
    /// Reads up to `max` vertices into `xyz` (replaced), with the bytes of each one's record in
    /// `spans` (ascii: from its first value to its last); returns how many were read.
    fn read_spans(&mut self, max: usize, xyz: &mut Vec<DVec3>, spans: &mut Vec<std::ops::Range<usize>>) -> Result<usize> {
        xyz.clear();
        spans.clear();
        let n = (max as u64).min(self.header.count - self.next) as usize;
        let mut v = [0.0f64; 3];
        for i in 0..n {
            let idx = self.next + i as u64;
            let start = match self.enc {
                Encoding::Ascii => skip_space(&self.map, self.pos),
                _ => self.pos,
            };
            match self.enc {
                Encoding::Ascii => self.read_ascii_vertex(&mut v, idx)?,
                enc => self.read_binary_vertex(&mut v, idx, enc)?,
            }
            xyz.push(DVec3::from(v));
            spans.push(start..self.pos);
        }
        self.next += n as u64;
        Ok(n)
    }

    /// The header of the labelled copy: the vertex element's properties followed by the
    /// labels'. Refused if the vertices already have a property of a label's name.
    fn labelled_header(&self) -> Result<Vec<u8>> {
        if let Some(p) = self.vertex.props.iter().find(|p| super::label::LABEL_FIELDS.contains(&p.name.as_str())) {
            return Err(bad(&self.path, format!("already has a vertex property named {}, which the labelled copy would add", p.name)));
        }
        let text = std::str::from_utf8(&self.map[..self.body]).map_err(|_| bad(&self.path, "PLY header is not text"))?;
        let (mut out, mut in_vertex) = (String::with_capacity(text.len() + 128), false);
        for line in text.split_inclusive('\n') {
            let first = line.split_whitespace().next();
            if in_vertex && matches!(first, Some("element" | "end_header")) {
                let eol = if line.ends_with("\r\n") { "\r\n" } else { "\n" };
                for p in ["double edge_distance", "int curve_id", "uchar edge"] {
                    out += &format!("property {p}{eol}");
                }
                in_vertex = false;
            }
            if first == Some("element") && line.split_whitespace().nth(1) == Some("vertex") {
                in_vertex = true;
            }
            out += line;
        }
        Ok(out.into_bytes())
    }
}

/// The first position at or after `pos` that is not white space.
fn skip_space(map: &[u8], mut pos: usize) -> usize {
    while pos < map.len() && map[pos].is_ascii_whitespace() {
        pos += 1;
    }
    pos
}

/// Writes the labelled copy of the PLY file `input` to `output` (see [`super::labels`]): its
/// header with the label properties added to the vertex element, then its data, each vertex
/// followed by its labels (in binary, in the file's byte order; in ascii, as three more values
/// on its line). Returns the number of vertices.
pub(super) fn label_ply(input: &Path, output: &Path, labeller: &dyn super::label::Labeller, cancel: &crate::cancel::Cancel) -> Result<u64> {
    use std::io::Write;
    let mut r = PlyReader::open(input)?;
    let out = |e| Error::output(output, e);
    let mut w = std::io::BufWriter::with_capacity(1 << 20, File::create(output).map_err(out)?);
    w.write_all(&r.labelled_header()?).map_err(out)?;
    let ascii = r.enc == Encoding::Ascii;
    let count = r.header.count;
    // (In ascii, what lies between the elements before the vertices and the first vertex's
    // values is its line break: kept.)
    let first = if ascii && count > 0 { skip_space(&r.map, r.pos) } else { r.pos };
    w.write_all(&r.map[r.body..first]).map_err(out)?;
    // (An ascii vertex line ends as the header's lines do.)
    let eol = if r.map[..r.body].ends_with(b"\r\n") { "\r\n" } else { "\n" };
    let (mut xyz, mut spans, mut labels, mut bytes) = (vec![], vec![], vec![], vec![]);
    while r.read_spans(super::label::LABEL_CHUNK, &mut xyz, &mut spans)? > 0 {
        cancel.check()?;
        labeller.label(&xyz, &mut labels);
        // (A labeller stopped by the cancel leaves the chunk's labels unset.)
        cancel.check()?;
        bytes.clear();
        for (s, l) in spans.iter().zip(&labels) {
            if ascii {
                // (The span runs on over the white space after the line's last value.)
                let values = r.map[s.clone()].trim_ascii_end();
                bytes.extend_from_slice(values);
                bytes.extend_from_slice(format!(" {} {} {}{eol}", l.distance, l.curve, l.edge).as_bytes());
            } else {
                bytes.extend_from_slice(&r.map[s.clone()]);
                l.push_bytes(&mut bytes, r.enc == Encoding::Big);
            }
        }
        w.write_all(&bytes).map_err(out)?;
    }
    // (In ascii the last vertex's line break was written with it.)
    let mut rest = r.pos;
    if ascii && count > 0 {
        while rest < r.map.len() && matches!(r.map[rest], b' ' | b'\t' | b'\r') {
            rest += 1;
        }
        rest += (r.map.get(rest) == Some(&b'\n')) as usize;
    }
    w.write_all(&r.map[rest..]).map_err(out)?;
    w.flush().map_err(out)?;
    Ok(count)
}
