//! Streaming point output (LAS/LAZ through the `las` crate, binary PLY), used by `crease synth`.

use crate::error::{Error, Result};
use crate::points::FileFormat;
use glam::DVec3;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Options of a written cloud.
#[derive(Clone, Debug)]
pub struct WriteOptions {
    /// Coordinate resolution (LAS scale factor) in model units.
    pub scale: f64,
    /// Offset subtracted before scaling (LAS), usually the min corner of the data.
    pub offset: DVec3,
    /// EPSG code of a projected CRS to record as GeoTIFF keys (LAS only).
    pub epsg: Option<u16>,
}

enum Sink {
    Las(Box<las::Writer<BufWriter<File>>>),
    Ply { w: BufWriter<File>, count_at: u64, count: u64 },
}

/// A point file being written, one chunk at a time.
pub struct PointWriter {
    path: PathBuf,
    sink: Sink,
}

const PLY_COUNT_WIDTH: usize = 20;

fn geotiff_vlr(epsg: u16) -> las::Vlr {
    // GeoKeyDirectory: header (version 1, revision 1.0, 3 keys) then key entries
    // (id, location 0 = value inline, count 1, value).
    let keys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, epsg];
    las::Vlr {
        user_id: "LASF_Projection".into(),
        record_id: 34735,
        description: "GeoKeyDirectoryTag".into(),
        data: keys.iter().flat_map(|k| k.to_le_bytes()).collect(),
    }
}

impl PointWriter {
    /// Creates `path` (`.las`, `.laz` or `.ply`).
    pub fn create(path: &Path, opts: &WriteOptions) -> Result<PointWriter> {
        let out = |e: std::io::Error| Error::output(path, e);
        let sink = match crate::io::format_of(path) {
            Some(fmt @ (FileFormat::Las | FileFormat::Laz)) => {
                let mut b = las::Builder::from((1, 2));
                b.point_format = las::point::Format::new(0).expect("format 0");
                b.point_format.is_compressed = fmt == FileFormat::Laz;
                b.generating_software = format!("crease {}", env!("CARGO_PKG_VERSION"));
                let t = |o: f64| las::Transform { scale: opts.scale, offset: o };
                b.transforms = las::Vector { x: t(opts.offset.x), y: t(opts.offset.y), z: t(opts.offset.z) };
                if let Some(code) = opts.epsg {
                    b.vlrs.push(geotiff_vlr(code));
                }
                let header = b.into_header().map_err(|e| Error::output(path, std::io::Error::other(e)))?;
                let f = File::create(path).map_err(out)?;
                let w = las::Writer::new(BufWriter::with_capacity(1 << 20, f), header).map_err(|e| Error::output(path, std::io::Error::other(e)))?;
                Sink::Las(Box::new(w))
            }
            Some(FileFormat::Ply) => {
                let mut w = BufWriter::with_capacity(1 << 20, File::create(path).map_err(out)?);
                let head = "ply\nformat binary_little_endian 1.0\ncomment crease synth\nelement vertex ";
                w.write_all(head.as_bytes()).map_err(out)?;
                let count_at = head.len() as u64;
                write!(w, "{:<width$}\nproperty double x\nproperty double y\nproperty double z\nend_header\n", 0, width = PLY_COUNT_WIDTH).map_err(out)?;
                Sink::Ply { w, count_at, count: 0 }
            }
            _ => return Err(Error::Usage(format!("{}: output must end in .las, .laz or .ply", path.display()))),
        };
        Ok(PointWriter { path: path.to_path_buf(), sink })
    }

    /// Appends points (classification per point for LAS; ignored for PLY).
    pub fn write(&mut self, xyz: &[DVec3], class: &[u8]) -> Result<()> {
        match &mut self.sink {
            Sink::Las(w) => {
                for (i, p) in xyz.iter().enumerate() {
                    let point = las::Point {
                        x: p.x,
                        y: p.y,
                        z: p.z,
                        classification: las::point::Classification::new(class.get(i).copied().unwrap_or(1)).unwrap_or_default(),
                        ..Default::default()
                    };
                    w.write_point(point).map_err(|e| Error::output(&self.path, std::io::Error::other(e)))?;
                }
            }
            Sink::Ply { w, count, .. } => {
                for p in xyz {
                    for v in p.to_array() {
                        w.write_all(&v.to_le_bytes()).map_err(|e| Error::output(&self.path, e))?;
                    }
                }
                *count += xyz.len() as u64;
            }
        }
        Ok(())
    }

    /// Finishes the file (header counts and bounds).
    pub fn finish(self) -> Result<()> {
        let path = self.path;
        match self.sink {
            Sink::Las(mut w) => w.close().map_err(|e| Error::output(path, std::io::Error::other(e))),
            Sink::Ply { mut w, count_at, count } => {
                let r = (|| {
                    w.flush()?;
                    let mut f = w.into_inner().map_err(|e| e.into_error())?;
                    f.seek(SeekFrom::Start(count_at))?;
                    write!(f, "{:<width$}", count, width = PLY_COUNT_WIDTH)?;
                    f.sync_all()
                })();
                r.map_err(|e| Error::output(&path, e))
            }
        }
    }
}
