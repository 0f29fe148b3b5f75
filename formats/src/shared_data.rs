//! Locating the third-party test assets in `../shared/data` beside the checkout.
//!
//! Tests that need them call [`shared_data_dir`]: where the folder is absent (a user's clone)
//! the test skips with a message, but under `CI=true` a missing folder fails the test, so CI can
//! never pass by skipping.

use std::path::PathBuf;

/// The `shared/data` folder beside the repository, or `None` (after printing why) when it is
/// absent outside CI. Panics under `CI=true` when the folder is missing.
///
/// `SKINFIELD_SHARED_DATA` overrides the location.
#[must_use]
pub fn shared_data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("SKINFIELD_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            // formats/ → repository root → its parent → shared/data
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
        });
    if dir.is_dir() {
        return Some(dir);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "CI=true but the shared test data folder {} is missing",
            dir.display()
        );
    }
    eprintln!(
        "skipping: shared test data not found at {} (set SKINFIELD_SHARED_DATA)",
        dir.display()
    );
    None
}
