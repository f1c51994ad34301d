//! Real vendor files in `../shared/test-data/` (next to the crate directory, never in the
//! repository).
//!
//! A test that reads one asks [`test_data`] for it first. Where the file is absent (a plain clone
//! without `../shared/test-data`) the test prints `SKIP` with the reason and returns; with
//! `FIELDPROBE_REQUIRE_TEST_DATA=1` (set by `.ci/run`) it fails instead.
//! `src/sim/canopen/tests.rs` repeats this logic in its unit tests (the library cannot use
//! `tests/common`).

#![allow(dead_code)] // each test crate uses its own subset

use std::path::{Path, PathBuf};

/// `1`: a missing test-data file is a test failure, not a skip.
pub const REQUIRE_ENV: &str = "FIELDPROBE_REQUIRE_TEST_DATA";

/// `../shared/test-data/REL` when the file exists. Otherwise: panics if
/// `FIELDPROBE_REQUIRE_TEST_DATA=1`, else prints `SKIP TEST_NAME: …` to stderr and returns `None`
/// (the test then returns without checking anything).
pub fn test_data(rel: &str, test_name: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/test-data")
        .join(rel);
    if path.is_file() {
        return Some(path);
    }
    let why = format!(
        "{} not present (a plain clone without ../shared/test-data)",
        path.display()
    );
    if std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1") {
        panic!("{test_name}: {why}; {REQUIRE_ENV}=1 requires the test data");
    }
    eprintln!("SKIP {test_name}: {why}");
    None
}

/// Is `../shared/seeds` (the ISG kernel documents the seed tests read) present? Same rule as
/// [`test_data`]: absent in a plain clone → `SKIP TEST_NAME: …` and `false`; with
/// `FIELDPROBE_REQUIRE_TEST_DATA=1` → panic.
pub fn seeds_present(test_name: &str) -> bool {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/seeds");
    if dir.is_dir() {
        return true;
    }
    let why = format!(
        "{} not present (a plain clone without ../shared/seeds)",
        dir.display()
    );
    if std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1") {
        panic!("{test_name}: {why}; {REQUIRE_ENV}=1 requires the seeds");
    }
    eprintln!("SKIP {test_name}: {why}");
    false
}

/// `../shared/test-data/REL` when the folder exists; otherwise as [`test_data`] (SKIP, or a
/// failure with `FIELDPROBE_REQUIRE_TEST_DATA=1`).
pub fn test_data_dir(rel: &str, test_name: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/test-data")
        .join(rel);
    if path.is_dir() {
        return Some(path);
    }
    let why = format!(
        "{} not present (a plain clone without ../shared/test-data)",
        path.display()
    );
    if std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1") {
        panic!("{test_name}: {why}; {REQUIRE_ENV}=1 requires the test data");
    }
    eprintln!("SKIP {test_name}: {why}");
    None
}
