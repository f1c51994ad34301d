//! The `fieldprobe` command-line tool.
fn main() {}
