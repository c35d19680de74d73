//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub(crate) mod mesh_checks;
pub(crate) mod rig;

use std::path::{Path, PathBuf};

/// `rel` below the shared data folder (`../shared/data` beside the checkout), or `None` with a
/// note on stderr when it is not there (the test then skips).
pub(crate) fn shared_data(rel: &str) -> Option<PathBuf> {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")).join(rel);
    if path.exists() {
        Some(path)
    } else {
        eprintln!(
            "skipping: {} not found (shared data sets absent)",
            path.display()
        );
        None
    }
}
