//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};

/// `../shared/data/<rel>` (a file or directory). Tests that call it are marked
/// `#[ignore = "needs ../shared"]`, and `.ci/run` includes them when `../shared` is there; run
/// without it, they fail here rather than pass having tested nothing.
pub fn shared_data(rel: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    assert!(p.exists(), "{} not found: this test needs ../shared beside the checkout", p.display());
    p
}
