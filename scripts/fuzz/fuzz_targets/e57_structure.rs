//! The E57 reader on files that are valid in their page structure but lie in their XML: an E57
//! is written from the input (precision, point count, coordinates), then its XML is rewritten
//! as the writer finalises it (the declared precision swapped, the record count and the
//! cartesian bounds replaced), under fresh page checksums, which random patches never get
//! right. A file declaring single precision over a stream of doubles once decoded to 2.9e38
//! and panicked in a fit.
//!
//! Input: a flags byte (bit 0: written in single precision; 1: the other precision declared;
//! 2: the record count replaced; 3: the bounds replaced; 4: a second scan; 5: an invalid-state
//! field), two bytes of point count (at most 2047), eight of declared record count, 48 of
//! bounds (six f64), then coordinates (f64 or f32, cycled; none: a ramp).
#![no_main]
mod common;

use e57::{E57Writer, Record, RecordValue};

/// The input, read field by field (zeros once it runs out).
struct Input<'a>(&'a [u8]);

impl Input<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        let n = N.min(self.0.len());
        out[..n].copy_from_slice(&self.0[..n]);
        self.0 = &self.0[n..];
        out
    }
}

/// An E57 of `n` points in one or two scans, coordinates from `coords` (cycled), its XML
/// rewritten by `edit` (the writer pages it with fresh checksums).
fn write(single: bool, n: usize, two: bool, invalid: bool, coords: &[u8], edit: impl Fn(String) -> String) -> Option<Vec<u8>> {
    let path = common::scratch("e57-base");
    let mut w = E57Writer::from_file(&path, "fuzz").ok()?;
    let mut proto = if single {
        vec![Record::CARTESIAN_X_F32, Record::CARTESIAN_Y_F32, Record::CARTESIAN_Z_F32]
    } else {
        vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64]
    };
    if invalid {
        proto.push(Record::CARTESIAN_INVALID_STATE);
    }
    let width = if single { 4 } else { 8 };
    let value = |k: usize| -> RecordValue {
        if coords.len() < width {
            let x = (k as f64 * 0.37).sin();
            return if single { RecordValue::Single(x as f32) } else { RecordValue::Double(x) };
        }
        let at = k * width % (coords.len() - coords.len() % width);
        let b = &coords[at..at + width];
        if single {
            RecordValue::Single(f32::from_le_bytes(b.try_into().unwrap()))
        } else {
            RecordValue::Double(f64::from_le_bytes(b.try_into().unwrap()))
        }
    };
    let mut k = 0;
    for s in 0..1 + two as usize {
        let mut pc = w.add_pointcloud(&format!("scan-{s}"), proto.clone()).ok()?;
        for _ in 0..n {
            let mut p: Vec<RecordValue> = (0..3).map(|a| value(k + a)).collect();
            k += 3;
            if invalid {
                p.push(RecordValue::Integer((k % 3) as i64));
            }
            pc.add_point(p).ok()?;
        }
        pc.finalize().ok()?;
    }
    w.finalize_customized_xml(|xml| Ok(edit(xml))).ok()?;
    drop(w);
    std::fs::read(&path).ok()
}

/// Replaces the text of every `<tag ...>text</tag>` element with `value`.
fn set_element(xml: &str, tag: &str, value: &str) -> String {
    let (open, close) = (format!("<{tag} "), format!("</{tag}>"));
    let mut out = String::new();
    let mut rest = xml;
    while let Some(a) = rest.find(&open) {
        let Some(gt) = rest[a..].find('>') else { break };
        let Some(end) = rest[a..].find(&close) else { break };
        out.push_str(&rest[..a + gt + 1]);
        out.push_str(value);
        out.push_str(&close);
        rest = &rest[a + end + close.len()..];
    }
    out.push_str(rest);
    out
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let [flags] = input.take::<1>();
    let n = u16::from_le_bytes(input.take::<2>()) as usize % 2048;
    let count = u64::from_le_bytes(input.take::<8>());
    let bounds: Vec<f64> = (0..6).map(|_| f64::from_le_bytes(input.take::<8>())).collect();
    let single = flags & 1 != 0;
    let edit = |mut xml: String| {
        if flags & 2 != 0 {
            xml = if single {
                xml.replace("precision=\"single\"", "precision=\"double\"")
            } else {
                xml.replace("<cartesianX type=\"Float\"", "<cartesianX type=\"Float\" precision=\"single\"")
                    .replace("<cartesianY type=\"Float\"", "<cartesianY type=\"Float\" precision=\"single\"")
                    .replace("<cartesianZ type=\"Float\"", "<cartesianZ type=\"Float\" precision=\"single\"")
            };
        }
        if flags & 4 != 0 {
            let declared = format!("recordCount=\"{count}\"");
            let mut out = String::new();
            let mut rest = xml.as_str();
            while let Some(a) = rest.find("recordCount=\"") {
                let Some(end) = rest[a + 13..].find('"') else { break };
                out.push_str(&rest[..a]);
                out.push_str(&declared);
                rest = &rest[a + 13 + end + 1..];
            }
            out.push_str(rest);
            xml = out;
        }
        if flags & 8 != 0 {
            for (tag, v) in ["xMinimum", "xMaximum", "yMinimum", "yMaximum", "zMinimum", "zMaximum"].iter().zip(&bounds) {
                xml = set_element(&xml, tag, &v.to_string());
            }
        }
        xml
    };
    if let Some(file) = write(single, n, flags & 16 != 0, flags & 32 != 0, input.0, edit) {
        common::read_as("e57", &file);
    }
});
