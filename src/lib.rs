//! crease: extracts sharp feature curves (creases, edges, corners) from laser scans.
//!
//! The crate is a library first; the `crease` binary only parses arguments and calls it.
//! See `README.md` for use and `../shared/DESIGN.md` for the method and architecture.
#![warn(missing_docs)]

pub mod cloud;
pub mod curves;
pub mod error;
pub mod eval;
pub mod extract;
pub mod info;
pub mod io;
pub mod mem;
pub mod progress;
pub mod run;
pub mod spacing;
pub mod spatial;
pub mod synth;
pub mod tiles;

pub use error::{Error, Result};
