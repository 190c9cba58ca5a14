//! The E57 reader on damaged copies of a valid file. E57 files open with a checksummed page
//! structure and an XML section, which random bytes never reach, so the input is read as
//! patches to a small valid file written once: a first byte that truncates it (255: not at
//! all), then (offset, xor) pairs of 5 bytes each.
#![no_main]
mod common;

use std::sync::OnceLock;

fn base() -> &'static [u8] {
    static BASE: OnceLock<Vec<u8>> = OnceLock::new();
    BASE.get_or_init(|| {
        let path = std::env::temp_dir().join(format!("crease-fuzz-base-{}.e57", std::process::id()));
        let mut w = e57::E57Writer::from_file(&path, "fuzz").unwrap();
        let proto = vec![e57::Record::CARTESIAN_X_F64, e57::Record::CARTESIAN_Y_F64, e57::Record::CARTESIAN_Z_F64];
        for s in 0..2 {
            let mut pc = w.add_pointcloud(&format!("scan-{s}"), proto.clone()).unwrap();
            for i in 0..200 {
                let v = |x: f64| e57::RecordValue::Double(x);
                pc.add_point(vec![v(i as f64 * 0.01), v(s as f64), v((i % 7) as f64)]).unwrap();
            }
            pc.finalize().unwrap();
        }
        w.finalize().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        bytes
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let mut file = base().to_vec();
    if let Some((&cut, patches)) = data.split_first() {
        for p in patches.chunks_exact(5) {
            let at = u32::from_le_bytes([p[0], p[1], p[2], p[3]]) as usize % file.len();
            file[at] ^= p[4];
        }
        if cut != 255 {
            file.truncate(file.len() * cut as usize / 255);
        }
    }
    common::read_as("e57", &file);
});
