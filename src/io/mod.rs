//! Streaming point input: LAS/LAZ (through the `las` crate, uncompressed LAS decoded straight
//! from a memory map, COPC read through its octree when a box is asked for), PLY (ascii and
//! binary), E57 and text clouds.
//!
//! Readers hand out points in chunks of bounded size so that memory does not grow with the
//! file; [`read_header`] answers count, bounds and CRS without touching the points.
//!
//! What each format gives:
//! - LAS/LAZ 1.0-1.4, point formats 0-10. The CRS is read as LAS 1.4 asks: from any VLR or EVLR;
//!   with the header's WKT bit set the WKT rules over GeoTIFF keys (without it, the keys, unless
//!   they name no code); the EPSG code of a WKT is its root `AUTHORITY` or `ID`; the horizontal
//!   and vertical units are those the CRS names. A COPC file (`.copc.laz`) with a box
//!   (`--bounds`) decompresses only the nodes that meet it; without one it reads as the LAZ 1.4
//!   file it is.
//! - E57: every scan's pose applied, all scans of a file as one cloud; spherical scans are
//!   converted, points without a return left out. No classes (all points are class 0). The CRS
//!   comes from the file's coordinate metadata when that is a WKT, `EPSG:N` or
//!   `urn:ogc:def:crs:EPSG::N`. Each scan's pose places its scanner, which tells convex curves
//!   from concave ones.
//! - Text clouds (`.xyz`, `.pts`, `.csv`, `.txt`; values separated by spaces, tabs, commas or
//!   semicolons; CRLF and a UTF-8 BOM read right): a first line naming `x`, `y`, `z` (and
//!   `class` or `classification`) says where they are, else they are the first three values; a
//!   PTS block's count line is skipped. `--columns` and `--skip-lines` set the layout instead. A
//!   line that does not parse, or one longer than 64 KiB, is an error naming it; files of a
//!   directory with no numeric line among their first ones are passed over with a warning.
//!
//! [`write_labelled`] copies a file's points with labels added (`--label-points`).
//!
//! Files without a CRS beside files with one are taken to be in the others' CRS, with a warning;
//! files that disagree on the CRS are refused.

mod e57;
mod label;
mod labels;
mod las;
mod ply;
mod text;
mod write;

pub use label::{Label, Labeller, LABEL_CHUNK, LABEL_FIELDS};
pub use labels::{labelled_extension, write_labelled};
pub use text::TextColumns;
pub use write::{PointWriter, WriteOptions};

use crate::error::{io_input, Error, Result};
use crate::points::{Bounds, CloudHeader, FileFormat, PointChunk};
use std::path::{Path, PathBuf};

/// Default number of points per chunk.
pub const DEFAULT_CHUNK: usize = 1 << 20;

/// ASPRS class for low points (noise).
pub(crate) const CLASS_LOW_NOISE: u8 = 7;
/// ASPRS class for high noise (LAS 1.4).
pub(crate) const CLASS_HIGH_NOISE: u8 = 18;

/// Which points a reader hands out (by default: all classes, withheld and noise points dropped).
#[derive(Clone, Debug, Default)]
pub struct Filter {
    /// Keep only these classifications (all if `None`).
    pub classes: Option<Vec<u8>>,
    /// Keep withheld points and noise classes 7 and 18 (dropped by default).
    pub keep_noise: bool,
    /// Where a text cloud's columns are (detected if `None`).
    pub text: Option<TextColumns>,
    /// Keep only the points inside this box, faces included (all if `None`). A COPC file
    /// decompresses only the octree nodes that meet it.
    pub bounds: Option<Bounds>,
}

impl Filter {
    /// A filter that keeps every point.
    pub fn keep_all() -> Self {
        Filter { classes: None, keep_noise: true, text: None, bounds: None }
    }

    /// A 256-entry table: `table[class]` is true if points of that class are kept.
    /// Withheld points are handled separately (see [`Filter::keep_noise`]).
    pub(crate) fn class_table(&self) -> [bool; 256] {
        let mut t = [self.classes.is_none(); 256];
        if let Some(cs) = &self.classes {
            for &c in cs {
                t[c as usize] = true;
            }
        }
        if !self.keep_noise {
            t[CLASS_LOW_NOISE as usize] = false;
            t[CLASS_HIGH_NOISE as usize] = false;
        }
        t
    }
}

/// Calls into a third-party decoder currently running: while any is, panics print nothing
/// (their message becomes the input error of [`guarded`]).
static DECODING: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Runs `f`, a call into a third-party decoder (`what`), turning a panic inside it into an
/// input error about `path`: a LAZ header that disagrees with its compressed data trips
/// assertions and capacity overflows inside the `laz` crate, on its own decoding threads. The
/// panic hook is chained, once, to stay silent while a decoder runs, so the user sees one
/// line, not a backtrace.
pub(crate) fn guarded<T>(path: &Path, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    use std::sync::atomic::Ordering;
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if DECODING.load(Ordering::SeqCst) == 0 {
                previous(info);
            }
        }));
    });
    DECODING.fetch_add(1, Ordering::SeqCst);
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    DECODING.fetch_sub(1, Ordering::SeqCst);
    r.unwrap_or_else(|p| Err(Error::input(path, format!("corrupt point data ({what} failed: {})", crate::error::panic_message(&p).replace('\n', " ")))))
}

/// Releases decoded pages of a read-only map from this process's resident set, so that reading
/// a file larger than memory keeps RSS flat (the kernel may keep them in its page cache).
pub(crate) fn release(map: &memmap2::Mmap, start: usize, end: usize) {
    const PAGE: usize = 4096;
    let (a, b) = (start / PAGE * PAGE, end / PAGE * PAGE);
    if b > a {
        // SAFETY: the map is read-only and file-backed; dropped pages are re-read from the file
        // if touched again, so no data is lost and no reference sees changed contents.
        let _ = unsafe { map.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, a, b - a) };
    }
}

/// The extensions crease reads, and their formats.
const EXTENSIONS: [(&str, FileFormat); 8] = [
    ("las", FileFormat::Las),
    ("laz", FileFormat::Laz),
    ("ply", FileFormat::Ply),
    ("e57", FileFormat::E57),
    ("xyz", FileFormat::Text),
    ("pts", FileFormat::Text),
    ("csv", FileFormat::Text),
    ("txt", FileFormat::Text),
];

/// The extensions crease reads, as a message lists them: ".las, .laz, ...".
fn extension_list() -> String {
    EXTENSIONS.iter().map(|(e, _)| format!(".{e}")).collect::<Vec<_>>().join(", ")
}

fn unknown_type(path: &Path) -> Error {
    Error::input(path, format!("unknown file type (expected {})", extension_list()))
}

/// Guesses the format of `path` from its extension.
pub(crate) fn format_of(path: &Path) -> Option<FileFormat> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    EXTENSIONS.iter().find(|(e, _)| *e == ext).map(|&(_, f)| f)
}

/// The point files the user's paths name, and what was passed over.
#[derive(Clone, Debug, Default)]
pub struct Inputs {
    /// Point files, in order.
    pub files: Vec<PathBuf>,
    /// Per directory given, the entries that are not point files (other files, subdirectories).
    pub passed_over: Vec<(PathBuf, Vec<PathBuf>)>,
}

impl Inputs {
    /// One line per directory that held entries passed over, leaving out those `expected`
    /// accepts (a run directory's own files, say).
    pub fn warnings(&self, expected: impl Fn(&Path) -> bool) -> Vec<String> {
        let mut out = vec![];
        for (dir, entries) in &self.passed_over {
            let names: Vec<String> = entries
                .iter()
                .filter(|e| !expected(e))
                .map(|e| e.strip_prefix(dir).unwrap_or(e).to_string_lossy().into_owned() + if e.is_dir() { "/" } else { "" })
                .collect();
            if !names.is_empty() {
                let shown = names.iter().take(5).cloned().collect::<Vec<_>>().join(", ");
                let more = if names.len() > 5 { format!(" and {} more", names.len() - 5) } else { String::new() };
                let entries = if names.len() == 1 { "entry that is not a point file" } else { "entries that are not point files" };
                out.push(format!("{}: passed over {} {entries} ({}): {shown}{more}", dir.display(), names.len(), extension_list()));
            }
        }
        out
    }
}

/// Expands the user's paths: files are kept as given, directories are replaced by the
/// point files (see `format_of`) inside them (`recursive`: in their subdirectories too),
/// sorted by path. Other entries of a directory are passed over, and named in a warning, as are
/// its text files that hold no line of coordinates.
pub fn expand_inputs(paths: &[PathBuf], recursive: bool) -> Result<Inputs> {
    let mut out = Inputs::default();
    for p in paths {
        let meta = std::fs::metadata(p).map_err(|e| io_input(p, e))?;
        if meta.is_dir() {
            let (mut files, mut other) = (vec![], vec![]);
            let mut dirs = vec![p.clone()];
            while let Some(dir) = dirs.pop() {
                for e in std::fs::read_dir(&dir).map_err(|e| io_input(&dir, e))? {
                    let e = e.map_err(|e| io_input(&dir, e))?;
                    let f = e.path();
                    // (A symbolic link to a directory is not followed: it may lead back up.)
                    if recursive && e.file_type().is_ok_and(|t| t.is_dir()) {
                        dirs.push(f);
                    } else if f.is_file() && format_of(&f).is_some_and(|k| k != FileFormat::Text || text::looks_like_points(&f)) {
                        files.push(f);
                    } else {
                        other.push(f);
                    }
                }
            }
            if files.is_empty() {
                let where_ = if recursive { "directory tree" } else { "directory" };
                return Err(Error::input(p, format!("{where_} holds no point files ({})", extension_list())));
            }
            files.sort();
            out.files.extend(files);
            if !other.is_empty() {
                other.sort();
                out.passed_over.push((p.clone(), other));
            }
        } else {
            if format_of(p).is_none() {
                return Err(unknown_type(p));
            }
            // (A FIFO or a device would block or never end.)
            if !meta.is_file() {
                return Err(Error::input(p, "not a regular file"));
            }
            out.files.push(p.clone());
        }
    }
    Ok(out)
}

/// Reads only the header of a point file. For PLY, whose header holds no bounds, the bounds
/// are left empty; use [`scan_bounds`] to get them.
///
/// ```no_run
/// let h = crease::io::read_header(std::path::Path::new("scan.laz"))?;
/// println!("{} points, CRS {}", h.count, h.crs.summary());
/// # Ok::<(), crease::Error>(())
/// ```
pub fn read_header(path: &Path) -> Result<CloudHeader> {
    match format_of(path) {
        Some(FileFormat::Las) | Some(FileFormat::Laz) => las::read_header(path),
        Some(FileFormat::Ply) => Ok(ply::PlyReader::open(path)?.header().clone()),
        Some(FileFormat::E57) => Ok(e57::E57Reader::open(path)?.header().clone()),
        Some(FileFormat::Text) => Ok(text::TextReader::open(path, None)?.header().clone()),
        None => Err(unknown_type(path)),
    }
}

/// Reads every point of `path` (without class filtering; text columns as `filter` says) to
/// find its true bounds and count.
pub fn scan_bounds(path: &Path, filter: &Filter) -> Result<(Bounds, u64)> {
    scan_bounds_or_cancel(path, filter, &crate::cancel::Cancel::default())
}

/// [`scan_bounds`], stopped between chunks with [`crate::Error::Interrupted`] once `cancel` is
/// set (a text cloud of millions of points takes seconds to read).
pub(crate) fn scan_bounds_or_cancel(path: &Path, filter: &Filter, cancel: &crate::cancel::Cancel) -> Result<(Bounds, u64)> {
    scan_bounds_declared(path, filter, cancel).map(|(b, n, _)| (b, n))
}

/// [`scan_bounds_or_cancel`], with the count a text cloud's PTS count lines declare, if it has
/// any (to be checked against the points it holds).
pub(crate) fn scan_bounds_declared(path: &Path, filter: &Filter, cancel: &crate::cancel::Cancel) -> Result<(Bounds, u64, Option<u64>)> {
    let mut reader = PointReader::open(path, &Filter { text: filter.text, ..Filter::keep_all() })?.cancelled_by(cancel);
    let mut chunk = PointChunk::default();
    let mut b = Bounds::EMPTY;
    let mut n = 0u64;
    while reader.read_chunk(DEFAULT_CHUNK, &mut chunk)? > 0 {
        cancel.check()?;
        for &p in &chunk.xyz {
            b.grow(p);
        }
        n += chunk.len() as u64;
    }
    let declared = if let Inner::Text(t) = &reader.inner { t.declared() } else { None };
    Ok((b, n, declared))
}

enum Inner {
    Las(las::LasReader),
    Ply(ply::PlyReader),
    E57(Box<e57::E57Reader>),
    Text(text::TextReader),
}

/// A streaming reader over one point file.
pub struct PointReader {
    inner: Inner,
    table: [bool; 256],
    keep_withheld: bool,
    bounds: Option<Bounds>,
    /// Stops a text file's chunk between lines (see [`PointReader::cancelled_by`]).
    cancel: Option<crate::cancel::Cancel>,
}

impl PointReader {
    /// Opens `path` and reads its header; points are read on demand.
    ///
    /// ```no_run
    /// use crease::io::{Filter, PointReader, DEFAULT_CHUNK};
    /// use crease::points::PointChunk;
    ///
    /// let mut r = PointReader::open(std::path::Path::new("scan.las"), &Filter::default())?;
    /// let mut chunk = PointChunk::default();
    /// while r.read_chunk(DEFAULT_CHUNK, &mut chunk)? > 0 {
    ///     println!("{} points", chunk.len());
    ///     chunk.clear();
    /// }
    /// # Ok::<(), crease::Error>(())
    /// ```
    pub fn open(path: &Path, filter: &Filter) -> Result<PointReader> {
        let inner = match format_of(path) {
            Some(FileFormat::Las) | Some(FileFormat::Laz) => Inner::Las(las::LasReader::open(path, filter.bounds.as_ref())?),
            Some(FileFormat::Ply) => Inner::Ply(ply::PlyReader::open(path)?),
            Some(FileFormat::E57) => Inner::E57(Box::new(e57::E57Reader::open(path)?)),
            Some(FileFormat::Text) => Inner::Text(text::TextReader::open(path, filter.text)?),
            None => return Err(unknown_type(path)),
        };
        Ok(PointReader { inner, table: filter.class_table(), keep_withheld: filter.keep_noise, bounds: filter.bounds, cancel: None })
    }

    /// The reader, whose reads of a text file stop with [`crate::Error::Interrupted`] within
    /// 65,536 points once `cancel` is set: a chunk of a million lines takes
    /// seconds to parse on a busy machine. (The other formats decode a chunk in a small part
    /// of a second.)
    pub(crate) fn cancelled_by(mut self, cancel: &crate::cancel::Cancel) -> PointReader {
        self.cancel = Some(cancel.clone());
        self
    }

    /// The file's header.
    pub fn header(&self) -> &CloudHeader {
        match &self.inner {
            Inner::Las(r) => r.header(),
            Inner::Ply(r) => r.header(),
            Inner::E57(r) => r.header(),
            Inner::Text(r) => r.header(),
        }
    }

    /// Replaces `out` with the next points: reads up to `max` records from the file (a COPC
    /// file read with bounds: whole octree nodes, at least one) and keeps those the filter
    /// accepts. Returns the
    /// number of records read (0 at the end of the file); `out` may hold fewer points than that.
    pub fn read_chunk(&mut self, max: usize, out: &mut PointChunk) -> Result<usize> {
        out.clear();
        let n = match &mut self.inner {
            Inner::Las(r) => r.read_chunk(max, out, &self.table, self.keep_withheld),
            Inner::Ply(r) => r.read_chunk(max, out, &self.table),
            Inner::E57(r) => r.read_chunk(max, out, &self.table),
            Inner::Text(r) => r.read_chunk(max, out, &self.table, self.cancel.as_ref()),
        }?;
        if let Some(b) = &self.bounds {
            out.retain(|p| b.contains(p));
        }
        Ok(n)
    }

    /// Reads every remaining point into one chunk (for clouds known to fit in memory).
    pub fn read_all(&mut self) -> Result<PointChunk> {
        let mut all = PointChunk::default();
        let mut chunk = PointChunk::default();
        while self.read_chunk(DEFAULT_CHUNK, &mut chunk)? > 0 {
            all.xyz.extend_from_slice(&chunk.xyz);
            all.class.extend_from_slice(&chunk.class);
            all.index.extend_from_slice(&chunk.index);
        }
        Ok(all)
    }
}

/// Reads all points of all `paths` (filtered) into one chunk.
pub fn read_all(paths: &[PathBuf], filter: &Filter) -> Result<PointChunk> {
    let mut all = PointChunk::default();
    for p in paths {
        let c = PointReader::open(p, filter)?.read_all()?;
        all.xyz.extend_from_slice(&c.xyz);
        all.class.extend_from_slice(&c.class);
    }
    Ok(all)
}

/// What a full read of one file found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScanResult {
    /// The file.
    pub path: PathBuf,
    /// Records read.
    pub records: u64,
    /// Points the filter kept.
    pub kept: u64,
    /// Bounds of the kept points.
    pub bounds: Bounds,
}

/// Reads every point of `path` through `filter`, in chunks.
pub fn scan(path: &Path, filter: &Filter) -> Result<ScanResult> {
    let mut reader = PointReader::open(path, filter)?;
    let mut chunk = PointChunk::default();
    let mut b = Bounds::EMPTY;
    let (mut records, mut kept) = (0u64, 0u64);
    loop {
        let n = reader.read_chunk(DEFAULT_CHUNK, &mut chunk)?;
        if n == 0 {
            break;
        }
        records += n as u64;
        kept += chunk.len() as u64;
        for &p in &chunk.xyz {
            b.grow(p);
        }
    }
    Ok(ScanResult { path: path.to_path_buf(), records, kept, bounds: b })
}
