//! `crease synth`: point clouds with exactly known feature curves, for tests and benchmarks.
//!
//! - `shapes`: CAD-like solids and Weber's two-plane wedge, with analytic edges;
//! - `mesh`: area-weighted sampling of a triangle mesh, truth = edges above a dihedral angle;
//! - `scene`: a large outdoor scene streamed to disk with constant memory.
//!
//! Noise follows Daniels et al.: each point moves by a uniform random vector of length at most
//! `noise * dB`, with dB the bounding-box diagonal of the clean cloud.

pub(crate) mod mesh;
pub(crate) mod scene;
pub(crate) mod shapes;
pub(crate) mod surface;

pub use mesh::{read_mesh, Mesh};
pub use scene::{write_scene, SceneOptions, EPSG};
pub use shapes::{shape, Shape, SHAPES};

use crate::curves::{write_obj, Polyline};
use crate::error::{Error, Result};
use crate::io::{PointWriter, WriteOptions};
use crate::points::Bounds;
use crate::rng::Rng;
use glam::DVec3;
use std::path::{Path, PathBuf};
use surface::AreaTable;

/// How points are spread over the surfaces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampling {
    /// Uniform by area.
    Uniform,
    /// Along parallel scan lines: `anisotropy` times denser along the lines than across them.
    ScanLines {
        /// Ratio of line separation to along-line spacing.
        anisotropy: f64,
    },
    /// Density varying smoothly fivefold across the object.
    NonUniform,
}

/// What to generate.
#[derive(Clone, Debug)]
pub struct SynthOptions {
    /// Number of points.
    pub n: usize,
    /// Noise level in units of the bounding-box diagonal.
    pub noise: f64,
    /// Noise level in units of the clean cloud's point spacing kappa (used instead of `noise`
    /// when positive): scanner-like noise, whose size follows the sampling, not the part.
    pub noise_spacing: f64,
    /// Share of points replaced by outliers uniform in the (5% enlarged) bounding box.
    pub outliers: f64,
    /// Sampling pattern.
    pub sampling: Sampling,
    /// Random seed.
    pub seed: u64,
}

impl Default for SynthOptions {
    /// 500 k points, uniform, no noise or outliers, seed 1 (as `crease synth`).
    fn default() -> Self {
        SynthOptions { n: 500_000, noise: 0.0, noise_spacing: 0.0, outliers: 0.0, sampling: Sampling::Uniform, seed: 1 }
    }
}

/// Samples `opts.n` points of `shape` (noise and outliers applied).
pub fn sample(shape: &Shape, opts: &SynthOptions) -> Vec<DVec3> {
    let table = AreaTable::new(&shape.surfaces);
    let mut rng = Rng::new(opts.seed);
    let draw = |rng: &mut Rng| shape.surfaces[table.pick(rng)].sample(rng);
    let mut pts = Vec::with_capacity(opts.n);
    match opts.sampling {
        Sampling::Uniform => {
            while pts.len() < opts.n {
                pts.push(draw(&mut rng));
            }
        }
        Sampling::ScanLines { anisotropy } => {
            // Lines are the intersections of the surface with thin slabs across direction u;
            // separation chosen so that n points give the requested anisotropy.
            let u = DVec3::new(0.31, 0.17, 0.935).normalize();
            let sep = (table.total() * anisotropy / opts.n as f64).sqrt();
            let thickness = sep / 32.0;
            while pts.len() < opts.n {
                let p = draw(&mut rng);
                if (p.dot(u) / sep).rem_euclid(1.0) * sep < thickness {
                    pts.push(p);
                }
            }
        }
        Sampling::NonUniform => {
            let mut r = Rng::stream(opts.seed, 1);
            let b = Bounds::of((0..4096).map(|_| draw(&mut r)));
            let (x0, x1) = (b.min[0], b.max[0].max(b.min[0] + 1e-12));
            while pts.len() < opts.n {
                let p = draw(&mut rng);
                let t = ((p.x - x0) / (x1 - x0)).clamp(0.0, 1.0);
                let keep = 0.2 + 0.8 * (0.5 - 0.5 * (std::f64::consts::PI * t).cos());
                if rng.f64() < keep {
                    pts.push(p);
                }
            }
        }
    }
    let radius = if opts.noise_spacing > 0.0 {
        opts.noise_spacing * crate::spacing::spacing(&pts, 2000)
    } else {
        opts.noise * Bounds::of(pts.iter().copied()).diagonal()
    };
    perturb(&mut pts, radius, opts.outliers, &mut Rng::stream(opts.seed, 2));
    pts
}

/// Applies Daniels' noise (uniform in a ball of radius `radius`) and replaces a share
/// `outliers` of the points by uniform points in the (clean) bounding box, enlarged by 5 %.
pub(crate) fn perturb(pts: &mut [DVec3], radius: f64, outliers: f64, rng: &mut Rng) {
    let b = Bounds::of(pts.iter().copied());
    let r = radius;
    if r > 0.0 {
        for p in pts.iter_mut() {
            *p += rng.in_ball(r);
        }
    }
    if outliers > 0.0 {
        let (lo, hi) = (DVec3::from(b.min), DVec3::from(b.max));
        let pad = (hi - lo) * 0.05;
        for p in pts.iter_mut() {
            if rng.f64() < outliers {
                *p = DVec3::new(rng.range(lo.x - pad.x, hi.x + pad.x), rng.range(lo.y - pad.y, hi.y + pad.y), rng.range(lo.z - pad.z, hi.z + pad.z));
            }
        }
    }
}

/// The truth file written next to `out`: `cube.las` -> `cube.truth.obj`.
pub fn truth_path(out: &Path) -> PathBuf {
    out.with_extension("truth.obj")
}

/// Converts truth polylines (closed ones repeat their first vertex) to [`Polyline`]s.
pub fn truth_polylines(truth: &[Vec<DVec3>]) -> Vec<Polyline> {
    truth
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let closed = t.len() > 2 && t[0] == t[t.len() - 1];
            let pts = if closed { &t[..t.len() - 1] } else { &t[..] };
            Polyline { closed, ..Polyline::from_points(i as u32, pts.iter().copied()) }
        })
        .collect()
}

/// A LAS scale fine enough for `diag`-sized data (1e-6 of it, rounded down to a power of ten).
pub(crate) fn scale_for(diag: f64) -> f64 {
    10f64.powf((diag.max(1e-300) * 1e-6).log10().floor())
}

/// Samples `shape` and writes the cloud to `out` and its truth to [`truth_path`]`(out)`.
///
/// ```no_run
/// use crease::synth::{shape, write_sampled, SynthOptions};
///
/// let fandisk = shape("fandisk", 90.0).unwrap();
/// write_sampled(&fandisk, &SynthOptions { noise: 0.005, ..Default::default() }, std::path::Path::new("fandisk.las"))?;
/// # Ok::<(), crease::Error>(())
/// ```
pub fn write_sampled(shape: &Shape, opts: &SynthOptions, out: &Path) -> Result<usize> {
    if opts.n == 0 {
        return Err(Error::Usage("-n must be at least 1".into()));
    }
    let pts = sample(shape, opts);
    let b = Bounds::of(pts.iter().copied());
    let wopts = WriteOptions { scale: scale_for(b.diagonal()), offset: DVec3::from(b.min).floor(), epsg: None };
    let mut w = PointWriter::create(out, &wopts)?;
    w.write(&pts, &vec![1u8; pts.len()])?;
    w.finish()?;
    write_obj(&truth_path(out), &truth_polylines(&shape.truth), &Default::default())?;
    Ok(pts.len())
}
