//! `crease info`: what each input file holds, from its header plus a small sample of points.

use crate::error::Result;
use crate::io::{Filter, PointReader};
use crate::points::{Bounds, CloudHeader, FileFormat, PointChunk};
use glam::DVec3;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// Points read from each file to estimate the spacing.
pub(crate) const SPACING_SAMPLE: usize = 100_000;

/// What `crease info` reports about one file.
#[derive(Clone, Debug, Serialize)]
pub struct FileInfo {
    /// Header fields.
    #[serde(flatten)]
    pub header: CloudHeader,
    /// Estimated mean point spacing (median nearest-neighbour distance), in file units.
    pub spacing: f64,
    /// How many points the spacing estimate is based on.
    pub spacing_sample: usize,
    /// How many of those points are at the very position of another of them: a count over
    /// the block read, not an estimate for the file (copies cluster where scans overlap, and
    /// a file written twice over holds none in its first block). `crease extract` counts
    /// every copy, exact and near, in `report.json`.
    pub sample_copies: usize,
}

/// Reads the header of `path` and estimates its point spacing from the first
/// `SPACING_SAMPLE` points. For PLY files the bounds come from a full read, since PLY headers
/// do not store them.
///
/// ```no_run
/// let infos = crease::info::file_info(std::path::Path::new("scan.laz"))?;
/// print!("{}", crease::info::render_text(&[infos]));
/// # Ok::<(), crease::Error>(())
/// ```
pub fn file_info(path: &Path) -> Result<FileInfo> {
    let mut reader = PointReader::open(path, &Filter::keep_all())?;
    let mut header = reader.header().clone();
    let mut sample = PointChunk::default();
    reader.read_chunk(SPACING_SAMPLE, &mut sample)?;
    if !header.format.has_header_bounds() {
        let (bounds, n) = crate::io::scan_bounds(path, &Filter::keep_all())?;
        header.bounds = bounds;
        // (Text clouds declare no count.)
        if header.count == 0 {
            header.count = n;
        }
    }
    let (spacing, distinct) = estimate_spacing(&sample.xyz, header.count, &header.bounds);
    Ok(FileInfo { header, spacing, spacing_sample: sample.len(), sample_copies: sample.len() - distinct })
}

/// Spacing from a contiguous block of a file's points. Scanner files are written in scan order,
/// so a block is a dense patch; synthetic or shuffled files give a thinned random subsample.
/// Both are handled by comparing the block's share of the points with its share of the area
/// (areas from the two largest extents of the bounding boxes), assuming even density. Also
/// returns how many distinct positions the block holds.
pub(crate) fn estimate_spacing(block: &[DVec3], total: u64, bounds: &Bounds) -> (f64, usize) {
    // (Copies of a point are measured once: 100 k copies of one point in one kd-tree bucket
    // took seconds to query, and copies shorten the spacing.)
    let mut distinct: Vec<[u64; 3]> = block.iter().map(|&p| crate::keys::bits_key(p + DVec3::ZERO)).collect();
    distinct.sort_unstable();
    distinct.dedup();
    let d = if distinct.len() == block.len() {
        crate::spacing::spacing(block, 20_000)
    } else {
        crate::spacing::spacing(&distinct.iter().map(|b| DVec3::from_array(b.map(f64::from_bits))).collect::<Vec<_>>(), 20_000)
    };
    let n = distinct.len();
    if block.len() < 2 || total == 0 || bounds.is_empty() {
        return (d, n);
    }
    let area = |b: &Bounds| {
        let mut e: Vec<f64> = (0..3).map(|i| (b.max[i] - b.min[i]).max(0.0)).collect();
        e.sort_by(|a, b| b.total_cmp(a));
        e[0] * e[1]
    };
    let (a_block, a_all) = (area(&Bounds::of(block.iter().copied())), area(bounds));
    if a_block <= 0.0 || a_all <= 0.0 {
        return (d, n);
    }
    let expected = total as f64 * (a_block / a_all).min(1.0);
    let thinning = (block.len() as f64 / expected).min(1.0);
    (d * thinning.sqrt(), n)
}

/// Formats infos as human-readable text.
pub fn render_text(infos: &[FileInfo]) -> String {
    let mut s = String::new();
    for i in infos {
        let h = &i.header;
        let fmt = match h.format {
            FileFormat::Las => "LAS",
            FileFormat::Laz => "LAZ",
            FileFormat::Ply => "PLY",
            FileFormat::E57 => "E57",
            FileFormat::Text => "text",
        };
        let _ = writeln!(s, "{}", h.path.display());
        let pf = h.point_format.map(|f| format!(", point format {f}")).unwrap_or_default();
        let _ = writeln!(s, "  format   {fmt} {}{pf}", h.version);
        let _ = writeln!(s, "  points   {}", h.count);
        let b = &h.bounds;
        let _ = writeln!(s, "  min      {:.3} {:.3} {:.3}", b.min[0], b.min[1], b.min[2]);
        let _ = writeln!(s, "  max      {:.3} {:.3} {:.3}", b.max[0], b.max[1], b.max[2]);
        let _ = writeln!(s, "  crs      {}", h.crs.summary());
        if let Some(first) = h.scanners.first() {
            let more = if h.scanners.len() > 1 { format!(" and {} more", h.scanners.len() - 1) } else { String::new() };
            let _ = writeln!(s, "  scanners at {:.3} {:.3} {:.3}{more}", first.x, first.y, first.z);
        }
        let _ = writeln!(s, "  spacing  {:.4} (from {} points)", i.spacing, i.spacing_sample);
        if i.sample_copies > 0 {
            // (Counted over the block read, not estimated for the file: see FileInfo.)
            let _ = writeln!(
                s,
                "  copies   {} of those {} points repeat the position of another of them (`extract` counts all)",
                i.sample_copies, i.spacing_sample
            );
        }
    }
    s
}
