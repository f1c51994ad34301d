//! Runs every cargo-fuzz target of `fuzz/` for a bounded time (issue 15 item 4).
//!
//! When `cargo fuzz` is installed, the fuzz crate is built once (libFuzzer, stable toolchain
//! with `RUSTC_BOOTSTRAP=1`, no sanitizer, debug assertions on so arithmetic overflow panics)
//! and each target listed by `cargo fuzz list` runs for `FIELDPROBE_FUZZ_SECONDS` (default 15)
//! on its seeds: `fuzz/seeds/TARGET/` (small inputs from our own runs), the repository's
//! example files, and the real vendor files in `../shared/test-data/` (never copied into the
//! repository). A crash, timeout or out-of-memory of any target fails the test, with the
//! reproducer kept in `fuzz/artifacts/TARGET/` and its path printed.
//!
//! Without cargo-fuzz the test prints `SKIP`; with `FIELDPROBE_REQUIRE_FUZZ=1` (set by
//! `.ci/run`) it fails instead. A missing `../shared/test-data` directory only drops those
//! seeds, except with `FIELDPROBE_REQUIRE_TEST_DATA=1`, where it fails.
//!
//! The targets' own directory layout and what each asserts: `fuzz/README.md`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;

/// Seconds each target runs (libFuzzer `-max_total_time`).
const DEFAULT_SECONDS: u64 = 15;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn env_is_1(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| v == "1")
}

/// `cargo fuzz …` in the repository root, on the stable toolchain with nightly features
/// unlocked, its build in `fuzz/target`.
fn cargo_fuzz(args: &[&str]) -> Command {
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.arg("fuzz")
        .args(args)
        .current_dir(root())
        .env("RUSTC_BOOTSTRAP", "1")
        // The main build's settings do not belong to the fuzz build.
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET");
    c
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The host triple (`cargo fuzz build` puts the binaries under `TARGET_DIR/TRIPLE/release`).
fn host_triple() -> String {
    let o = Command::new("rustc")
        .arg("-vV")
        .output()
        .expect("rustc -vV");
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_owned))
        .expect("host line in rustc -vV")
}

/// Seed directories of `target` besides `fuzz/seeds/TARGET`: repository files and
/// `../shared/test-data` sub-directories (relative to the repository root).
fn extra_seeds(target: &str) -> (&'static [&'static str], &'static [&'static str]) {
    match target {
        "nc_parse" => (&["examples/nc"], &[]),
        "machine_toml" | "list_file" => (&["examples/machines"], &[]),
        "drive_file" => (&["drives"], &[]),
        "esi_xml" => (&["esi"], &["esi"]),
        "eds" => (&[], &["eds"]),
        "sii" => (&[], &["sii"]),
        "pcap" => (&[], &["pcap"]),
        _ => (&[], &[]),
    }
}

/// libFuzzer `-max_len`: real ESI files and captures are large; everything else is small.
fn max_len(target: &str) -> usize {
    match target {
        "esi_xml" | "pcap" | "eds" => 1 << 20,
        _ => 1 << 14,
    }
}

/// The numbers of libFuzzer's last `#N DONE cov: … ft: … exec/s: …` line.
#[derive(Debug, Default)]
struct Stats {
    execs: u64,
    cov: u64,
    ft: u64,
    exec_per_s: u64,
}

fn stats(log: &str) -> Option<Stats> {
    let line = log
        .lines()
        .rev()
        .find(|l| l.starts_with('#') && l.split_whitespace().nth(1) == Some("DONE"))?;
    let field = |key: &str| -> Option<u64> {
        let mut it = line.split_whitespace();
        it.find(|w| *w == key)?;
        it.next()?.parse().ok()
    };
    Some(Stats {
        execs: line
            .split_whitespace()
            .next()?
            .trim_start_matches('#')
            .parse()
            .ok()?,
        cov: field("cov:")?,
        ft: field("ft:")?,
        exec_per_s: field("exec/s:")?,
    })
}

#[test]
fn every_fuzz_target_runs_without_crash() {
    let _one_module = crate::gate::enter(module_path!());
    let require = env_is_1("FIELDPROBE_REQUIRE_FUZZ");
    match cargo_fuzz(&["--version"]).output() {
        Ok(o) if o.status.success() => {}
        other => {
            let why = match other {
                Ok(o) => format!("`cargo fuzz --version` failed: {}", text(&o).trim()),
                Err(e) => format!("`cargo fuzz` not runnable: {e}"),
            };
            assert!(
                !require,
                "{why}; FIELDPROBE_REQUIRE_FUZZ=1 (install: cargo install cargo-fuzz --locked)"
            );
            eprintln!("SKIP every_fuzz_target_runs_without_crash: {why} (cargo install cargo-fuzz --locked)");
            return;
        }
    }
    let seconds: u64 = std::env::var("FIELDPROBE_FUZZ_SECONDS")
        .ok()
        .map(|s| s.parse().expect("FIELDPROBE_FUZZ_SECONDS: whole seconds"))
        .unwrap_or(DEFAULT_SECONDS);
    let root = root();
    let fuzz_dir = root.join("fuzz");
    let target_dir = fuzz_dir.join("target");
    let t0 = Instant::now();

    // Every file in fuzz_targets/ must be a listed target (none silently left out).
    let o = cargo_fuzz(&["list"]).output().expect("cargo fuzz list");
    assert!(o.status.success(), "cargo fuzz list: {}", text(&o));
    let targets: Vec<String> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| l.trim().to_owned())
        .filter(|l| !l.is_empty())
        .collect();
    let mut files: Vec<String> = std::fs::read_dir(fuzz_dir.join("fuzz_targets"))
        .expect("fuzz/fuzz_targets")
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "rs").then(|| p.file_stem().unwrap().to_string_lossy().into_owned())
        })
        .collect();
    files.sort();
    let mut listed = targets.clone();
    listed.sort();
    assert_eq!(
        listed, files,
        "fuzz targets in Cargo.toml vs files in fuzz/fuzz_targets"
    );

    // One build of all targets.
    let o = cargo_fuzz(&[
        "build",
        "--sanitizer",
        "none",
        "--debug-assertions",
        "--target-dir",
        target_dir.to_str().expect("UTF-8 path"),
    ])
    .output()
    .expect("cargo fuzz build");
    assert!(o.status.success(), "cargo fuzz build failed:\n{}", text(&o));
    let build_time = t0.elapsed();
    eprintln!("fuzz build: {:.0} s", build_time.as_secs_f64());
    let bin_dir = target_dir.join(host_triple()).join("release");

    let shared = root.join("../shared/test-data");
    let require_data = env_is_1("FIELDPROBE_REQUIRE_TEST_DATA");
    let mut failures = Vec::new();
    let mut table = Vec::new();
    // Two targets at a time (this test runs alone on a two-core CI machine): every target
    // still gets its full `-max_total_time`.
    let mut prepared = Vec::new();
    for t in &targets {
        let corpus = fuzz_dir.join("corpus").join(t);
        let artifacts = fuzz_dir.join("artifacts").join(t);
        std::fs::create_dir_all(&corpus).expect("corpus dir");
        std::fs::create_dir_all(&artifacts).expect("artifacts dir");
        let mut dirs: Vec<PathBuf> = vec![corpus];
        let own = fuzz_dir.join("seeds").join(t);
        if own.is_dir() {
            dirs.push(own);
        }
        let (repo, data) = extra_seeds(t);
        dirs.extend(repo.iter().map(|d| root.join(d)));
        for d in data {
            let p = shared.join(d);
            if p.is_dir() {
                dirs.push(p);
            } else {
                assert!(
                    !require_data,
                    "{} missing; FIELDPROBE_REQUIRE_TEST_DATA=1",
                    p.display()
                );
                eprintln!("note: {t}: seeds {} absent (plain clone)", p.display());
            }
        }
        prepared.push((t, dirs, artifacts));
    }
    let mut runs = Vec::new();
    for pair in prepared.chunks(2) {
        let children: Vec<_> = pair
            .iter()
            .map(|(t, dirs, artifacts)| {
                let before: Vec<PathBuf> = list(artifacts);
                let started = Instant::now();
                let child = Command::new(bin_dir.join(t))
                    .args(dirs)
                    .arg(format!("-max_total_time={seconds}"))
                    .arg(format!("-max_len={}", max_len(t)))
                    .arg("-timeout=10")
                    .arg("-rss_limit_mb=2048")
                    .arg(format!("-artifact_prefix={}/", artifacts.display()))
                    .current_dir(&root)
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap_or_else(|e| panic!("run {t}: {e}"));
                (t, artifacts, before, started, child)
            })
            .collect();
        for (t, artifacts, before, started, child) in children {
            let o = child
                .wait_with_output()
                .unwrap_or_else(|e| panic!("run {t}: {e}"));
            runs.push((t, artifacts, before, started.elapsed(), o));
        }
    }
    for (t, artifacts, before, took, o) in runs {
        let artifacts = &artifacts;
        let log = text(&o);
        let took = took.as_secs_f64();
        let new: Vec<PathBuf> = list(artifacts)
            .into_iter()
            .filter(|p| !before.contains(p))
            .collect();
        match stats(&log) {
            Some(s) if o.status.success() && new.is_empty() => {
                eprintln!(
                    "{t:18} {:>10} execs {:>7} exec/s  cov {:>5}  ft {:>6}  ({took:.0} s)",
                    s.execs, s.exec_per_s, s.cov, s.ft
                );
                table.push(((*t).clone(), s));
            }
            _ => {
                let tail: Vec<&str> = log.lines().rev().take(40).collect();
                let tail: Vec<&str> = tail.into_iter().rev().collect();
                let repro = new
                    .iter()
                    .map(|p| {
                        format!(
                            "  reproducer kept: {}\n  replay: RUSTC_BOOTSTRAP=1 cargo fuzz run -s none -a {t} {}",
                            p.display(),
                            p.display()
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n");
                eprintln!(
                    "FAIL {t}: {} after {took:.0} s\n{repro}\n--- libFuzzer output (tail) ---\n{}",
                    o.status,
                    tail.join("\n")
                );
                failures.push(format!(
                    "{t} ({}){}",
                    o.status,
                    if new.is_empty() {
                        String::new()
                    } else {
                        format!(
                            ": {}",
                            new.iter()
                                .map(|p| p.display().to_string())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    }
                ));
            }
        }
    }
    eprintln!(
        "fuzz total: {:.0} s ({} targets × {seconds} s, build {:.0} s)",
        t0.elapsed().as_secs_f64(),
        targets.len(),
        build_time.as_secs_f64()
    );
    assert!(
        failures.is_empty(),
        "fuzz targets failed (reproducers kept):\n{}",
        failures.join("\n")
    );
    assert_eq!(table.len(), targets.len());
    for (t, s) in &table {
        assert!(s.execs > 0, "{t} ran no input");
    }
}

/// Files in `dir` (sorted).
fn list(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.sort();
    v
}
