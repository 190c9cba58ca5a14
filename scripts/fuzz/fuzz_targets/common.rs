//! What every reader target does: the input's bytes become a file of the given type, and
//! crease reads it as `crease info` and a run's bucketing pass would. Any result is fine but a
//! panic, a hang or an abort (which libFuzzer reports).

use std::path::PathBuf;

/// The input file of this process (in /dev/shm when there is one: the bytes are rewritten
/// at every execution).
fn file(ext: &str) -> PathBuf {
    scratch(&format!("in.{ext}"))
}

/// A scratch file of this process, named `name` (in /dev/shm when there is one).
#[allow(dead_code)]
pub fn scratch(name: &str) -> PathBuf {
    let base = if std::path::Path::new("/dev/shm").is_dir() { PathBuf::from("/dev/shm") } else { std::env::temp_dir() };
    base.join(format!("crease-fuzz-{}-{name}", std::process::id()))
}

pub fn read_as(ext: &str, data: &[u8]) {
    let path = file(ext);
    std::fs::write(&path, data).expect("the fuzz input file is writable");
    let _ = crease::info::file_info(&path);
    let _ = crease::io::scan(&path, &crease::io::Filter::keep_all());
}
