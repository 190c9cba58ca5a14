//! Text clouds: XYZ, PTS, CSV and TXT, one point a line, values separated by spaces, tabs,
//! commas or semicolons.
//!
//! Without a column spec the layout is detected: a first line with names (`x`, `y`, `z`,
//! optionally `classification` or `class`; quotes and a leading `//` allowed) says where the
//! columns are; otherwise x, y and z are the first three values. A line holding a single
//! integer is a PTS block's point count and is skipped (a run warns where the counts do not add
//! up to the points the file holds). A data line that lacks a column, or
//! whose value is not a number, is an error naming the line, as is a line longer than
//! [`MAX_LINE`]. Windows line ends (CRLF) and a UTF-8 byte order mark are read as text.

use crate::error::{io_input, Error, Result};
use crate::points::{Bounds, CloudHeader, Crs, FileFormat, PointChunk, Precision};
use glam::DVec3;
use memmap2::Mmap;
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::path::{Path, PathBuf};

/// Where a text cloud's values are (0-based columns), and how many lines to skip first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TextColumns {
    /// Columns of x, y and z.
    pub xyz: [usize; 3],
    /// Column of the ASPRS class, if any.
    pub class: Option<usize>,
    /// Lines skipped before the first point (a header).
    pub skip: usize,
}

impl TextColumns {
    /// Parses `X,Y,Z[,CLASS]` (0-based column numbers).
    ///
    /// ```
    /// use crease::io::TextColumns;
    /// let c = TextColumns::parse("1,2,3,6", 1).unwrap();
    /// assert_eq!((c.xyz, c.class, c.skip), ([1, 2, 3], Some(6), 1));
    /// assert!(TextColumns::parse("x,y", 0).is_err());
    /// ```
    pub fn parse(spec: &str, skip: usize) -> std::result::Result<TextColumns, String> {
        let cols: Vec<usize> = spec
            .split(',')
            .map(|c| c.trim().parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| format!("'{spec}': expected X,Y,Z[,CLASS] column numbers from 0"))?;
        match cols[..] {
            [x, y, z] => Ok(TextColumns { xyz: [x, y, z], class: None, skip }),
            [x, y, z, c] => Ok(TextColumns { xyz: [x, y, z], class: Some(c), skip }),
            _ => Err(format!("'{spec}': expected 3 or 4 column numbers (X,Y,Z[,CLASS])")),
        }
    }
}

/// Longest line read, in bytes: a point's line holds a few dozen values at most; a longer one
/// is not a point cloud's (a binary file, or one without line ends, that would be held whole).
pub(super) const MAX_LINE: usize = 64 * 1024;

/// Points read between two looks at a reader's cancel flag (see `PointReader::cancelled_by`).
const CANCEL_LINES: usize = 1 << 16;

/// The UTF-8 byte order mark, which some Windows programs write before the first line.
const BOM: &[u8] = &[0xEF, 0xBB, 0xBF];

fn tokens(line: &str) -> impl Iterator<Item = &str> {
    line.split([' ', '\t', ',', ';', '\r']).filter(|t| !t.is_empty())
}

/// The columns a header line names, if it is one (some value is not a number).
fn from_names(line: &str) -> Option<TextColumns> {
    let names: Vec<String> = tokens(line).map(|t| t.trim_matches(['"', '\'']).trim_start_matches("//").to_ascii_lowercase()).collect();
    if names.iter().all(|n| n.parse::<f64>().is_ok()) {
        return None;
    }
    let at = |want: &[&str]| names.iter().position(|n| want.contains(&n.as_str()));
    Some(TextColumns { xyz: [at(&["x"]).unwrap_or(0), at(&["y"]).unwrap_or(1), at(&["z"]).unwrap_or(2)], class: at(&["classification", "class"]), skip: 1 })
}

/// True if `path` reads as a text cloud: one of its first lines holds at least three numbers.
/// A directory's `readme.txt` or notes do not, and are passed over rather than read as an
/// empty cloud or stopping the run on their first word.
pub(crate) fn looks_like_points(path: &Path) -> bool {
    use std::io::Read;
    let mut head = Vec::with_capacity(MAX_LINE);
    let Ok(file) = File::open(path) else { return true };
    // (Unreadable files are kept, to be refused with the reader's own message.)
    if file.take(MAX_LINE as u64).read_to_end(&mut head).is_err() {
        return true;
    }
    let text = String::from_utf8_lossy(head.strip_prefix(BOM).unwrap_or(&head)).into_owned();
    text.lines().filter(|l| !l.trim().is_empty()).take(16).any(|l| tokens(l).filter(|t| t.parse::<f64>().is_ok()).count() >= 3)
}

/// A chunked reader over one text cloud.
pub(super) struct TextReader {
    path: PathBuf,
    header: CloudHeader,
    map: Option<Mmap>,
    cols: TextColumns,
    /// Byte offset of the next line, its 1-based number, and records read.
    pos: usize,
    line: u64,
    next: u64,
    /// Points the PTS count lines read so far declare, if any were read.
    declared: Option<u64>,
}

impl TextReader {
    /// Maps the file and finds its layout (`spec`, or detected from its first line).
    pub(super) fn open(path: &Path, spec: Option<TextColumns>) -> Result<TextReader> {
        let file = File::open(path).map_err(|e| io_input(path, e))?;
        let len = file.metadata().map_err(|e| io_input(path, e))?.len();
        if len == 0 {
            return Err(Error::input(path, "empty file"));
        }
        // SAFETY: read-only map of an input crease never writes.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| io_input(path, e))?;
        #[cfg(unix)]
        let _ = map.advise(memmap2::Advice::Sequential);
        let cols = match spec {
            Some(c) => c,
            None => {
                let first = map.strip_prefix(BOM).unwrap_or(&map).split(|&b| b == b'\n').next().unwrap_or(&[]);
                if first.len() > MAX_LINE {
                    return Err(Error::input(path, format!("line 1 is longer than {MAX_LINE} bytes: not a text point cloud")));
                }
                let first = std::str::from_utf8(first).map_err(|_| Error::input(path, "line 1 is not text: not a text point cloud"))?;
                from_names(first).unwrap_or(TextColumns { xyz: [0, 1, 2], class: None, skip: 0 })
            }
        };
        let header = CloudHeader {
            path: path.to_path_buf(),
            format: FileFormat::Text,
            version: format!("columns x {} y {} z {}{}", cols.xyz[0], cols.xyz[1], cols.xyz[2], cols.class.map(|c| format!(" class {c}")).unwrap_or_default()),
            point_format: None,
            // (Unknown until read: the bounds scan counts them.)
            count: 0,
            bounds: Bounds::EMPTY,
            crs: Crs::default(),
            precision: Precision::Float(52),
            scanners: vec![],
        };
        let pos = if map.starts_with(BOM) { BOM.len() } else { 0 };
        Ok(TextReader { path: path.to_path_buf(), header, map: Some(map), cols, pos, line: 0, next: 0, declared: None })
    }

    /// The file's header (count and bounds unknown until the points are read).
    pub(super) fn header(&self) -> &CloudHeader {
        &self.header
    }

    /// The points the PTS count lines read so far declare, if any were read.
    pub(super) fn declared(&self) -> Option<u64> {
        self.declared
    }

    /// Reads up to `max` points into `out` (filtered); returns the number of records read.
    pub(super) fn read_chunk(&mut self, max: usize, out: &mut PointChunk, table: &[bool; 256], cancel: Option<&crate::cancel::Cancel>) -> Result<usize> {
        let Some(map) = &self.map else { return Ok(0) };
        let bytes: &[u8] = map;
        let need = self.cols.xyz.iter().copied().chain(self.cols.class).max().unwrap_or(2) + 1;
        let start = self.pos;
        let mut read = 0;
        while read < max && self.pos < bytes.len() {
            if read % CANCEL_LINES == 0
                && let Some(c) = cancel
            {
                c.check()?;
            }
            let scan = &bytes[self.pos..bytes.len().min(self.pos + MAX_LINE + 1)];
            let Some(end) = scan.iter().position(|&b| b == b'\n').map(|k| self.pos + k).or((scan.len() <= MAX_LINE).then_some(bytes.len())) else {
                return Err(Error::input(&self.path, format!("line {} is longer than {MAX_LINE} bytes: not a text point cloud", self.line + 1)));
            };
            let raw = &bytes[self.pos..end];
            self.pos = end + 1;
            self.line += 1;
            if self.line <= self.cols.skip as u64 {
                continue;
            }
            let text = std::str::from_utf8(raw).map_err(|_| Error::input(&self.path, format!("line {} is not text", self.line)))?.trim();
            // (A spreadsheet's export with decimal commas was read as twice the values, and
            // made a cloud of integers and digits: points on a few lines ten million long.)
            if text.contains(';') && text.contains(',') {
                return Err(Error::input(
                    &self.path,
                    format!("line {}: both ';' and ',' separate values (decimal commas?); write the numbers with decimal points", self.line),
                ));
            }
            // x, y, z and the class, by slot.
            let mut got = [0.0f64; 4];
            let mut n = 0;
            for (k, t) in tokens(text).enumerate() {
                if k >= need {
                    break;
                }
                let slots = [self.cols.xyz[0] == k, self.cols.xyz[1] == k, self.cols.xyz[2] == k, self.cols.class == Some(k)];
                if slots.contains(&true) {
                    let v = t.parse::<f64>().map_err(|_| Error::input(&self.path, format!("line {}: '{t}' in column {k} is not a number", self.line)))?;
                    for (g, hit) in got.iter_mut().zip(slots) {
                        if hit {
                            *g = v;
                        }
                    }
                }
                n = k + 1;
            }
            // (Blank lines, and a PTS block's point count: one integer alone.)
            if n == 0 {
                continue;
            }
            if n == 1
                && let Ok(count) = text.parse::<u64>()
            {
                self.declared = Some(self.declared.unwrap_or(0).saturating_add(count));
                continue;
            }
            if n < need {
                return Err(Error::input(&self.path, format!("line {} has {n} values; the columns read need {need}", self.line)));
            }
            let p = DVec3::new(got[0], got[1], got[2]);
            if !p.is_finite() {
                return Err(Error::input(&self.path, format!("line {}: coordinates are not finite", self.line)));
            }
            let class = if self.cols.class.is_some() { got[3].clamp(0.0, 255.0) as u8 } else { 0 };
            if table[class as usize] {
                out.xyz.push(p);
                out.class.push(class);
                out.index.push(self.next);
            }
            self.next += 1;
            read += 1;
        }
        super::release(map, start, self.pos.min(bytes.len()));
        Ok(read)
    }
}
