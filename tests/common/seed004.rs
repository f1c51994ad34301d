//! The annotations of seed 004 §5 (`-> V.A.MESS.Z = 100.0` under each `#MSG` of the listings
//! meas1 – meas4), parsed out of `../shared/seeds/004_*.txt`: the expected values of the
//! measurement examples come from the seed text, never from the code under test. A test asks
//! [`test_data::seeds_present`](super::test_data::seeds_present) first (SKIP in a plain clone).

#![allow(dead_code)] // each test crate uses its own subset

use std::path::PathBuf;

pub fn seed_path() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/seeds");
    std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("004_"))
        })
        .expect("seed 004 in ../shared/seeds")
}

/// The `-> NAME = VALUE` (or `\rightarrow NAME = VALUE`) annotations of the program `%name` in
/// seed 004 §5, in order.
pub fn seed_annotations(name: &str) -> Vec<(String, f64)> {
    let text = std::fs::read_to_string(seed_path()).expect("read seed 004");
    let start = text
        .find(&format!("%{name}\n"))
        .unwrap_or_else(|| panic!("%{name} not in seed 004"));
    let block = &text[start..];
    let block = &block[..block.find("```").expect("end of the program listing")];
    let mut out = Vec::new();
    for line in block.lines() {
        let rest = if let Some(i) = line.find("\\rightarrow") {
            &line[i + "\\rightarrow".len()..]
        } else if let Some(i) = line.find("->") {
            &line[i + 2..]
        } else {
            continue;
        };
        let (n, v) = rest.split_once('=').expect("NAME = VALUE");
        let v: f64 = v.trim().parse().expect("a number");
        out.push((n.trim().to_string(), v));
    }
    out
}

/// What `fieldprobe run examples/nc/seed004/NAME.nc` prints on stdout by the seed: one line
/// `NAME=VALUE` per annotation, `%f` (6 decimals).
pub fn seed_stdout_lines(name: &str) -> Vec<String> {
    seed_annotations(name)
        .iter()
        .map(|(n, v)| format!("{n}={v:.6}"))
        .collect()
}
