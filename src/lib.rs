//! crease: extracts sharp feature curves (creases, edges, corners) from laser scans.
//!
//! The crate is a library first; the `crease` binary only parses arguments and calls it.
//! See `README.md` for use, [`extract`] for the method and [`run`] for the pipeline.
//!
//! Modules, in the order data flows through a run (each imports only modules listed above it,
//! or the leaves at the end):
//! - [`io`]: reads LAS/LAZ/PLY headers and streams their points in chunks ([`points`] types),
//!   and writes the inputs' labelled copies (`--label-points`);
//! - [`info`]: `crease info`, a file's header, CRS and spacing estimate;
//! - `tiles`: the tile grid, the tile store (tiles written once, halos assembled on read),
//!   the bucketer;
//! - [`curves`]: the output polylines and their OBJ, PLY and GeoJSON writers and readers, and the
//!   nearest curve to a point;
//! - `preview`: `preview.png`, the cloud and its curves from two sides;
//! - [`extract`]: the method, stage by stage, as functions of plain data (statistics,
//!   candidates, projection, smoothing, growing, completion);
//! - [`run`]: the pipeline (plan, bucket, statistics, residuals, projection, curves, write) over
//!   a run directory or memory, resumable, with `crease status`;
//! - [`eval`]: scores curves against ground truth;
//! - [`synth`]: test clouds with known curves (shapes, meshes, a large scene).
//!
//! Shared mechanics, below all of those (each imports at most [`error`] and the ones listed
//! before it): [`points`] (plain cloud data types), `rng` (the keyed random stream), `keys`
//! (position keys, hashing, snapping), `salts` (of the keyed random choices), `grid` (cells of a uniform grid), `sets` (union-find),
//! `spatial` (the k-d tree), [`spacing`], `codec` (the record format of a run directory),
//! `workspace` (a run directory or memory), [`cancel`], [`progress`], [`mem`]; and [`debug`]
//! (intermediate point sets, written with the [`curves`] writer).
//!
//! The few types most callers need are at the crate root: an in-memory extract, in a few lines
//! ([`extract_cloud`]; [`run_extract`] is the same over files and a resumable run directory):
//!
//! ```
//! use crease::{extract_cloud, Params, RunOptions};
//!
//! let cube = crease::synth::shape("cube", 90.0).unwrap();
//! let points = crease::synth::sample(&cube, &crease::synth::SynthOptions { n: 60_000, ..Default::default() });
//! let found = extract_cloud(&points, &Params::default(), &RunOptions::default())?;
//! assert_eq!(found.curves.len(), 12);
//! for curve in &found.curves {
//!     assert!(curve.vertices.len() >= 2 && curve.confidence > 0.5);
//! }
//! # Ok::<(), crease::Error>(())
//! ```
//!
//! The command line's `clap` derives are behind the default feature `cli`; a library user can
//! leave it out (`default-features = false`).
#![warn(missing_docs)]
// (Cargo gives the binary and the tests every dependency of the library, so the lint holds for
// the library only.)
#![deny(unreachable_pub, unused_crate_dependencies)]

pub mod cancel;
pub(crate) mod codec;
pub mod crs;
pub mod curves;
pub mod debug;
pub mod error;
pub mod eval;
pub mod extract;
pub(crate) mod grid;
pub mod info;
pub mod io;
pub(crate) mod keys;
pub mod mem;
pub mod points;
pub(crate) mod preview;
pub mod progress;
#[cfg(feature = "python")]
mod python;
pub(crate) mod rng;
pub mod run;
pub(crate) mod salts;
pub(crate) mod sets;
pub mod slurm;
pub mod spacing;
pub(crate) mod spatial;
pub mod synth;
pub(crate) mod tiles;
pub(crate) mod view;
pub(crate) mod workspace;

pub use curves::{Polyline, Vertex};
pub use error::{Error, Result};
pub use extract::Params;
pub use io::Filter;
pub use run::{extract_cloud, run_extract, Extraction, Report, RunOptions};

// (The command line's crates, which the library does not use: see the `cli` feature.)
#[cfg(feature = "cli")]
use {clap_complete as _, clap_mangen as _, ctrlc as _};
