//! Running the `fieldprobe` binary from integration tests.

#![allow(dead_code)] // each test crate uses its own subset

use std::process::{Command, Output};

/// Run `fieldprobe ARGS…` in the crate directory and wait for it.
pub fn fieldprobe(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run fieldprobe")
}

/// Its standard output as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Its standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
