//! The Rust examples under `examples/` run as a user runs them (`cargo run --example NAME`) and
//! print what their README paths promise; each test checks the printed values against values
//! it computes itself from what it asked for (probe position, torque limit) and the drive
//! file's scaling, read from the TOML text here, not through fieldprobe.
//!
//! The example is built with the cargo that runs the tests, in the profile and with the
//! features of this test build (a no-op when `cargo test` built it already), then its binary
//! runs with a bounded time.

#![allow(dead_code)] // each feature set uses its own subset

use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Longest run of one example.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// The features of this test build, for building the example the same way.
fn features() -> Vec<&'static str> {
    let mut f = Vec::new();
    if cfg!(feature = "ethercat") {
        f.push("ethercat");
    }
    if cfg!(feature = "canopen") {
        f.push("canopen");
    }
    if cfg!(feature = "socketcan") {
        f.push("socketcan");
    }
    if cfg!(feature = "sim") {
        f.push("sim");
    }
    if cfg!(feature = "cli") {
        f.push("cli");
    }
    f
}

/// Build example `name` and return its binary: `<target>/<profile dir>/examples/<name>`, next
/// to the `deps/` directory this test binary runs from.
fn build(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test binary in <target>/<profile>/deps")
        .to_path_buf();
    // `debug` holds the dev and test profiles; this test build's profile is `test` there.
    let profile = match profile_dir.file_name().and_then(|n| n.to_str()) {
        Some("release") => "release",
        _ => "test",
    };
    let mut cmd = Command::new(env!("CARGO"));
    cmd.args(["build", "--offline", "--quiet", "--example", name])
        .args(["--profile", profile])
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    // The same feature set as this build (the `default` feature is part of the fingerprint, so
    // it is kept when it is on), or cargo would build the library a second time.
    if !cfg!(feature = "default") {
        cmd.arg("--no-default-features");
        let f = features();
        if !f.is_empty() {
            cmd.args(["--features", &f.join(",")]);
        }
    }
    let out = cmd.output().expect("run cargo build");
    assert!(
        out.status.success(),
        "cargo build --example {name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bin = profile_dir
        .join("examples")
        .join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(bin.is_file(), "{} was not built", bin.display());
    bin
}

/// Run example `name` with `args`; its standard output. Fails the test on a non-zero exit or
/// when it runs longer than [`RUN_TIMEOUT`].
fn run(name: &str, args: &[&str]) -> String {
    let bin = build(name);
    let mut child = Command::new(&bin)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("run {}: {e}", bin.display()));
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait for the example") {
            break s;
        }
        if start.elapsed() > RUN_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("example {name} ran longer than {RUN_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stdout = String::new();
    let mut stderr = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert!(
        status.success(),
        "example {name} {args:?} failed ({status}):\n{stdout}\n{stderr}"
    );
    eprintln!("example {name} {args:?}:\n{stdout}");
    stdout
}

/// `increments_per_unit` of a drive file, read from its TOML text.
fn increments_per_mm(drive: &str) -> f64 {
    let path = format!("{}/drives/{drive}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("drive file");
    text.lines()
        .find_map(|l| {
            let (k, v) = l.split_once('=')?;
            (k.trim() == "increments_per_unit").then(|| v.trim().parse::<f64>().ok())?
        })
        .unwrap_or_else(|| panic!("{path}: no increments_per_unit"))
}

/// The number after `key` in `line` (up to the next blank or parenthesis).
fn number_after(line: &str, key: &str) -> f64 {
    let at = line
        .find(key)
        .unwrap_or_else(|| panic!("{key:?} not in {line:?}"))
        + key.len();
    let text: String = line[at..]
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == '-')
        .collect();
    text.parse()
        .unwrap_or_else(|_| panic!("no number after {key:?} in {line:?}"))
}

/// The one line of `out` that starts with `prefix`.
fn line<'a>(out: &'a str, prefix: &str) -> &'a str {
    let mut lines = out.lines().filter(|l| l.starts_with(prefix));
    let l = lines
        .next()
        .unwrap_or_else(|| panic!("no line {prefix:?} in\n{out}"));
    assert!(lines.next().is_none(), "two lines {prefix:?} in\n{out}");
    l
}

/// A latch line `… latched at MM mm (INC increments) …` against a probe at `probe_mm` on a drive
/// of `per_mm` increments per mm: the increments are the surface's (± 1 for the rounding of
/// the edge position) and the millimetres are those increments scaled back.
fn check_latch(l: &str, probe_mm: f64, per_mm: f64) {
    let mm = number_after(l, "latched at");
    let inc = number_after(l, "mm (");
    let expected = (probe_mm * per_mm).round();
    assert!(
        (inc - expected).abs() <= 1.0,
        "latched {inc} increments, the probe surface is at {expected}: {l}"
    );
    assert!(
        (mm - inc / per_mm).abs() < 0.5e-4,
        "{mm} mm is not {inc} increments / {per_mm}: {l}"
    );
}

#[cfg(feature = "sim")]
#[test]
fn ethercat_touch_probe_latches_the_surface_and_writes_the_torque_limit() {
    let _one_module = crate::gate::enter(module_path!());
    let probe = 7.3456;
    let out = run(
        "ethercat_touch_probe",
        &["--probe-at", "7.3456", "--torque-limit", "37.5"],
    );
    check_latch(
        line(&out, "touch probe 1 latched"),
        probe,
        increments_per_mm("cia402-generic"),
    );
    // CiA 402 0x6072 max torque is in per mille of the rated torque: 37.5 % = 375.
    let t = line(&out, "torque limit 0x6072:00 =");
    assert_eq!(number_after(t, "0x6072:00 ="), 375.0, "{t}");
}

#[cfg(feature = "sim")]
#[test]
fn canopen_touch_probe_latches_the_surface_and_writes_the_torque_limit() {
    let _one_module = crate::gate::enter(module_path!());
    let probe = 4.0321;
    let out = run(
        "canopen_touch_probe",
        &["--probe-at", "4.0321", "--torque-limit", "55"],
    );
    check_latch(
        line(&out, "touch probe 1 latched"),
        probe,
        increments_per_mm("cia402-generic"),
    );
    // CiA 402 0x6072 max torque is in per mille of the rated torque: 55 % = 550.
    let t = line(&out, "torque limit 0x6072:00 =");
    assert_eq!(number_after(t, "0x6072:00 ="), 550.0, "{t}");
}

/// The value of `NAME = VALUE` in `out`.
fn value(out: &str, name: &str) -> f64 {
    number_after(line(out, &format!("{name} =")), "=")
}

#[test]
fn measurement_core_reports_the_results_the_stop_and_the_limits() {
    let _one_module = crate::gate::enter(module_path!());
    let probe = 98.76543;
    let out = run("measurement_core", &["--probe-at", "98.76543"]);
    let setup = line(&out, "G54 zero offset Z =");
    let offset = number_after(setup, "Z =");
    let target_pcs = number_after(setup, "G100 Z");
    let start = number_after(setup, "from ACS Z");
    // The example's drive latches in increments of 0.1 µm.
    let latched = (probe * 10_000.0_f64).round() / 10_000.0;
    let near = |name: &str, want: f64| {
        let got = value(&out, name);
        assert!(
            (got - want).abs() < 1e-6,
            "{name} = {got}, want {want}\n{out}"
        );
    };
    // FCT-C4 §5, 2.5D: MESS and the ACS value are the latched ACS position; the PCS value is
    // it without the zero shift; MOFFS = MESS − programmed target − zero shifts.
    near("V.A.MESS.Z", latched);
    near("V.A.MEAS.ACS.VALUE.Z", latched);
    near("V.A.MEAS.PCS.VALUE.Z", latched - offset);
    near("V.A.MOFFS.Z", latched - target_pcs - offset);
    near("V.A.MERF.Z", 1.0);
    // The stop request came with the latch; the axis stopped past the surface, short of the
    // target.
    let stop = line(&out, "stop requested in cycle");
    assert!(number_after(stop, "actual Z") <= probe, "{stop}");
    let stopped = number_after(line(&out, "stopped in cycle"), "ACS Z");
    assert!(stopped < probe && stopped > target_pcs + offset, "{out}");
    assert!(start > probe);
    assert!(
        out.contains("software limits: actual positions inside"),
        "{out}"
    );
    // FCT-A2: a command path below the negative limit switch is P-ERR-120003.
    let refused = line(&out, "software limits: G01 Z");
    assert!(refused.contains("error 120003"), "{refused}");

    // A surface beyond the target: the motion reaches the target without a signal; type 1
    // accepts that (P-CHAN-00176 = 0) and Z gets no result (MERF 0).
    let out = run(
        "measurement_core",
        &["--probe-at", &format!("{}", offset + target_pcs - 5.0)],
    );
    assert_eq!(value(&out, "V.A.MERF.Z"), 0.0, "{out}");
    assert!(!out.contains("V.A.MESS.Z"), "{out}");
    assert!(!out.contains("stop requested"), "{out}");
    assert!(
        line(&out, "stopped in cycle").ends_with("(target)"),
        "{out}"
    );
}
