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
//! - [`tiles`]: the tile grid, the tile store (tiles written once, halos assembled on read),
//!   the bucketer;
//! - [`curves`]: the output polylines and their OBJ, PLY and GeoJSON writers and readers, and the
//!   nearest curve to a point;
//! - [`preview`]: `preview.png`, the cloud and its curves from two sides;
//! - [`extract`]: the method, stage by stage, as functions of plain data (statistics,
//!   candidates, projection, smoothing, growing, completion);
//! - [`run`]: the pipeline (plan, bucket, statistics, residuals, projection, curves, write) over
//!   a run directory or memory, resumable, with `crease status`;
//! - [`eval`]: scores curves against ground truth;
//! - [`synth`]: test clouds with known curves (shapes, meshes, a large scene).
//!
//! Shared mechanics, below all of those (each imports at most [`error`] and the ones listed
//! before it): [`points`] (plain cloud data types), [`rng`] (the keyed random stream), `keys`
//! (position keys, hashing, snapping), `salts` (of the keyed random choices), `grid` (cells of a uniform grid), `sets` (union-find),
//! [`spatial`] (the k-d tree), [`spacing`], `codec` (the record format of a run directory),
//! `workspace` (a run directory or memory), [`cancel`], [`progress`], [`mem`]; and [`debug`]
//! (intermediate point sets, written with the [`curves`] writer).
#![warn(missing_docs)]

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
pub mod preview;
pub mod progress;
#[cfg(feature = "python")]
mod python;
pub mod rng;
pub mod run;
pub(crate) mod salts;
pub(crate) mod sets;
pub mod slurm;
pub mod spacing;
pub mod spatial;
pub mod synth;
pub mod tiles;
pub mod view;
pub(crate) mod workspace;

pub use error::{Error, Result};
