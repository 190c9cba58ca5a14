//! The integration tests, one module per subject, built as one test binary: each test binary
//! is linked against the whole crate and its dependencies, and a dozen of them took most of
//! CI's build time.

mod common;

mod bad_input;
mod cli;
mod copc;
mod crs;
mod dirty;
mod e57;
mod extract;
mod labels;
mod ply_and_curves;
mod real_files;
mod synth;
mod text_clouds;
mod tiles;
mod typed;
mod workers;
