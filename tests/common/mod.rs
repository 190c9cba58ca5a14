//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};

/// `../shared/data/<rel>` (a file or directory), or None, saying that the test is skipped,
/// where this checkout has no shared data beside it.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipping: {} not found", p.display());
        None
    }
}
