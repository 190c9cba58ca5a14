//! The text cloud reader (XYZ, PTS, CSV) on arbitrary bytes.
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| common::read_as("csv", data));
