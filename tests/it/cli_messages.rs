//! Messages of `fieldprobe run` on stderr: one cause gives one error (issue 12).

use crate::common::cli;

use cli::{fieldprobe, stderr};

/// Write `src` into a temporary program file and run it with `extra` arguments.
fn run_program(src: &str, extra: &[&str]) -> std::process::Output {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("prog.nc");
    std::fs::write(&p, src).unwrap();
    let mut args = vec!["run", p.to_str().unwrap()];
    args.extend_from_slice(extra);
    fieldprobe(&args)
}

#[test]
fn inconsistent_arc_gives_one_error_900022_only() {
    // Start (0, 0), end (10, 0), centre I3 J0 = (3, 0): radius 3 at the start, |(10, 0) − (3, 0)|
    // = 7 at the end — no circle through both points.
    let o = run_program("N10 G01 X0 Y0 F1000\nN20 G02 X10 Y0 I3 J0\nN30 M30\n", &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    let lines: Vec<&str> = e.lines().collect();
    assert_eq!(lines.len(), 1, "exactly one message: {e}");
    assert!(lines[0].starts_with("error 900022: "), "{e}");
    assert!(
        lines[0].contains("radius") && lines[0].ends_with("(N20)"),
        "{e}"
    );
}

/// A reader that goes away (`fieldprobe run … | head`) must not panic the tool: the failed
/// write is reported once on stderr, the run goes on to its end (axes stopped as usual), and
/// the command does not exit 0 — its result was not delivered (issue 15: exit 2).
#[test]
fn closed_stdout_is_reported_not_a_panic() {
    use std::process::{Command, Stdio};
    // The reader is gone before the child starts (closing it after the spawn would race).
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args(["run", "examples/nc/seed004/meas1.nc", "--link", "sim"])
        .args(["--probe-at", "Z=100", "--json"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        err.matches("writing to stdout failed").count(),
        1,
        "reported once: {err}"
    );
    assert_eq!(out.status.code(), Some(2), "{err}");
}
