//! Issue 15, the CLI's part: numbers from users bounded (exit 2 naming the option and its
//! range, never a panic), outputs that cannot be written (stdout, `--pcap`, `--candump`) never
//! exit 0, messages in words and of bounded size, `--trace` of a long run bounded.
//!
//! Each test is the reproducer of the issue. The expected bounds come from the contract
//! (DESIGN.md: exit 2 for bad input with the option and the allowed range) and from
//! arithmetic on the inputs, not from the code under test.

use crate::common::cli;

use cli::{fieldprobe, stderr, stdout};
use std::process::{Command, Output, Stdio};

/// Run `fieldprobe ARGS…` with `/dev/full` as its stdout (every write fails with ENOSPC).
fn with_full_stdout(args: &[&str]) -> Output {
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .expect("open /dev/full");
    Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(full)
        .stderr(Stdio::piped())
        .output()
        .expect("run fieldprobe")
}

/// Run `fieldprobe ARGS…` whose stdout reader is gone before the first line (`… | head`
/// after head exited).
fn with_closed_stdout(args: &[&str]) -> Output {
    // The reading end is closed before the child starts: closing it after the spawn raced
    // with a fast child on a busy machine (`params` had written all into the pipe buffer).
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .expect("run")
}

/// A program file in a temporary directory (kept alive by the returned guard).
fn program(src: &str) -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("prog.nc");
    std::fs::write(&p, src).unwrap();
    let s = p.to_str().unwrap().to_string();
    (dir, s)
}

/// Exit 2, no panic, and every text in `words` on stderr; stderr short (a message, not an
/// echo of a huge number).
#[track_caller]
fn refused(o: &Output, words: &[&str]) {
    let e = stderr(o);
    assert!(!e.contains("panicked"), "{e}");
    assert_eq!(o.status.code(), Some(2), "{e}");
    for w in words {
        assert!(e.contains(w), "{w:?} missing: {e}");
    }
    assert!(e.len() < 400, "a short message, got {} bytes: {e}", e.len());
}

const SEG_ESI: &str = "esi/fieldprobe-ek1100.xml";

// ---- 1. --seconds: float → Duration / Instant overflowed (exit 101) ----

#[test]
fn sim_seconds_beyond_the_clock_is_bad_input_not_a_panic() {
    // 1e19 s is beyond u64 seconds of Duration (1.8e19) on the Instant's i64 clock; 1e300 is
    // beyond Duration itself. The documented range is 0 … 1e9 s.
    for v in ["1e300", "1e19", "NaN", "inf", "1e9000"] {
        let o = fieldprobe(&[
            "sim",
            "ethercat",
            "--iface",
            "lo",
            "--device",
            SEG_ESI,
            "--seconds",
            v,
        ]);
        refused(&o, &["--seconds", "0 … 1000000000"]);
        let o = fieldprobe(&[
            "sim",
            "canopen",
            "--bus",
            "udp",
            "--node",
            "1",
            "--seconds",
            v,
        ]);
        refused(&o, &["--seconds", "0 … 1000000000"]);
    }
}

#[test]
fn can_dump_seconds_out_of_range_names_option_without_301_digits() {
    let o = fieldprobe(&["can", "dump", "--link", "canopen-emu", "--seconds", "1e300"]);
    refused(&o, &["--seconds 1e300", "0 … 86400"]);
}

// ---- 2. stdout that cannot be written ----

#[test]
fn run_to_dev_full_is_an_error_and_the_run_still_ends() {
    // The #MSG line is the run's result: lost on /dev/full, so not exit 0 (it was 0 silently).
    let (_d, p) = program("N10 G01 X10 F1000\nN20 #MSG SYN [\"x=%f\", 1.5]\nN30 M30\n");
    for extra in [&[][..], &["--json"][..]] {
        let mut args = vec!["run", p.as_str(), "--link", "sim"];
        args.extend_from_slice(extra);
        let o = with_full_stdout(&args);
        let e = stderr(&o);
        assert!(!e.contains("panicked"), "{e}");
        assert_eq!(e.matches("writing to stdout failed").count(), 1, "{e}");
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
    }
    // The same program to a pipe: the line arrives, exit 0 (the failure above is the output's).
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o), "x=1.500000\n");
}

#[test]
fn cnc_error_keeps_exit_1_when_stdout_fails_too() {
    // An aborted run (an arc whose radius does not fit: error 900022) stays a CNC error.
    let (_d, p) =
        program("N05 #MSG SYN [\"start\"]\nN10 G01 X0 Y0 F1000\nN20 G02 X10 Y0 I3 J0\nN30 M30\n");
    let o = with_full_stdout(&["run", &p, "--link", "sim"]);
    let e = stderr(&o);
    assert!(
        e.contains("writing to stdout failed") && e.contains("900022"),
        "{e}"
    );
    assert_eq!(o.status.code(), Some(1), "{e}");
}

#[test]
fn listings_to_dev_full_or_a_closed_pipe_exit_nonzero() {
    for args in [
        &["params"][..],
        &["esi", "show", SEG_ESI][..],
        &[
            "run",
            "examples/nc/seed004/meas1.nc",
            "--link",
            "sim",
            "--probe-at",
            "Z=100",
            "--json",
        ][..],
    ] {
        for o in [with_full_stdout(args), with_closed_stdout(args)] {
            let e = stderr(&o);
            assert!(!e.contains("panicked"), "{args:?}: {e}");
            assert!(e.contains("writing to stdout failed"), "{args:?}: {e}");
            assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        }
    }
}

#[test]
fn help_to_dev_full_is_not_exit_0() {
    let o = with_full_stdout(&["--help"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("writing to stdout failed"));
}

// ---- 3. jog --step ----

#[test]
fn jog_step_not_a_distance_is_bad_input() {
    // Bound: the coordinate bound of every path, 1e12 mm (docs/cli.md).
    for v in ["NaN", "inf", "-inf", "1e300", "-1e300", "1.5e12"] {
        let o = fieldprobe(&["jog", "--axis", "X", "--step", v]);
        refused(&o, &["--step", "-1000000000000 … 1000000000000"]);
        assert!(stdout(&o).is_empty(), "no position printed: {}", stdout(&o));
    }
    // A step inside the default machine's permitted range [-100, 100] still jogs.
    let o = fieldprobe(&["jog", "--axis", "X", "--step", "10"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).starts_with("X command 10.000000 "),
        "{}",
        stdout(&o)
    );
}

// ---- 4. capture write errors ----

#[test]
fn pcap_write_error_is_an_error_after_a_complete_run() {
    let (_d, p) = program("N10 G01 X10 F1000\nN20 #MSG SYN [\"done\"]\nN30 M30\n");
    let o = fieldprobe(&["run", &p, "--link", "ethercat-emu", "--pcap", "/dev/full"]);
    let e = stderr(&o);
    assert!(!e.contains("panicked"), "{e}");
    assert!(
        e.contains("--pcap /dev/full") && e.contains("failed"),
        "{e}"
    );
    assert_eq!(o.status.code(), Some(2), "{e}");
    // The run itself went to its end: its message was printed.
    assert_eq!(stdout(&o), "done\n", "{e}");
    // Without logging turned on (FIELDPROBE_LOG unset) the message is still there.
    let o = fieldprobe(&["scan", "--link", "ethercat-emu", "--pcap", "/dev/full"]);
    assert!(stderr(&o).contains("--pcap /dev/full"), "{}", stderr(&o));
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn candump_write_error_is_an_error() {
    let (_d, p) = program("N10 G01 X10 F1000\nN20 #MSG SYN [\"done\"]\nN30 M30\n");
    // Issue 16: the default machine's three nodes need 4 ms at 1 Mbit/s on CAN.
    let o = fieldprobe(&[
        "run",
        &p,
        "--link",
        "canopen-emu",
        "--set",
        "cycle_time_us=4000",
        "--candump",
        "/dev/full",
    ]);
    let e = stderr(&o);
    assert!(
        e.contains("--candump /dev/full") && e.contains("failed"),
        "{e}"
    );
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert_eq!(stdout(&o), "done\n", "{e}");
    for args in [
        &[
            "can",
            "dump",
            "--link",
            "canopen-emu",
            "--seconds",
            "0.2",
            "--candump",
            "/dev/full",
        ][..],
        &[
            "can",
            "scan",
            "--link",
            "canopen-emu",
            "--candump",
            "/dev/full",
        ][..],
    ] {
        let o = fieldprobe(args);
        assert!(
            stderr(&o).contains("--candump /dev/full"),
            "{args:?}: {}",
            stderr(&o)
        );
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    }
}

// ---- 5. messages ----

#[test]
fn fixed_stop_without_criterion_is_said_in_words_on_the_cli() {
    // Seed 004 §8.2.2: neither the lag limit P-AXIS-00774 nor the position window is set.
    let (_d, p) = program("N10 G100 Z50 F600\nN20 M30\n");
    let o = fieldprobe(&[
        "run",
        &p,
        "--link",
        "sim",
        "--set",
        "P-CHAN-00057=7",
        "--set",
        "Z.kenngr.measure.signal=FIXED_STOP",
    ]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("axis Z") && e.contains("P-AXIS-00774"), "{e}");
    assert!(!e.contains("NoCriterion") && !e.contains('{'), "{e}");
}

#[test]
fn independent_motion_out_of_range_names_axis_position_and_range() {
    let (_d, p) = program("N10 X[INDP_SYN G01 G90 POS10000000000000 FEED1000]\nN20 M30\n");
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.starts_with("error 900001: "), "message ID kept: {e}");
    for w in [
        "axis X",
        "10000000000000",
        "-1000000000000 … 1000000000000",
        "(N10)",
    ] {
        assert!(e.contains(w), "{w:?} missing: {e}");
    }
    assert!(!e.contains("invalid path"), "{e}");
}

#[test]
fn a_ten_million_digit_number_gives_a_short_message() {
    // A file can hold what a command line cannot (MAX_ARG_STRLEN 128 KiB): the NC program.
    let digits = "9".repeat(10_000_000);
    let (_d, p) = program(&format!("N10 G01 X{digits} F1000\nN20 M30\n"));
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{}", &e[..e.len().min(300)]);
    assert!(e.len() < 400, "{} bytes", e.len());
    // The line is refused by its length before its number is read (issue 28 item 9): the
    // message names the line, its length and the cap.
    let line_chars = "N10 G01 X".len() + digits.len() + " F1000".len();
    assert!(
        e.contains(":1:") && e.contains(&format!("{line_chars} characters")) && e.contains("65536"),
        "{e}"
    );
    // A number inside the line cap: the message abbreviates it and says how long it is.
    let digits = "9".repeat(60_000);
    let (_d, p) = program(&format!("N10 G01 X{digits} F1000\nN20 M30\n"));
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{}", &e[..e.len().min(300)]);
    assert!(e.len() < 400, "{} bytes", e.len());
    assert!(
        e.contains(":1:") && e.contains("…") && e.contains("60000 characters"),
        "{e}"
    );
    // And on the command line, the largest an argument can be (with a valid program).
    let (_d, p) = program("N10 G01 X1 F1000\nN20 M30\n");
    let digits = "9".repeat(100_000);
    for args in [
        vec![
            "run".to_string(),
            p.clone(),
            "--set".into(),
            format!("X.P-AXIS-00178={digits}"),
        ],
        vec![
            "run".to_string(),
            p.clone(),
            "--probe-at".into(),
            format!("Z={digits}"),
        ],
        vec![
            "jog".to_string(),
            "--axis".into(),
            digits.clone(),
            "--step".into(),
            "1".into(),
        ],
    ] {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = fieldprobe(&a);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{}", &e[..e.len().min(300)]);
        assert!(
            e.len() < 600,
            "{}: {} bytes",
            args[2].len().min(20),
            e.len()
        );
        assert!(e.contains("…"), "{e}");
    }
}

// ---- 6. --trace of a long run ----

#[test]
fn trace_of_a_slow_move_is_decimated_and_covers_the_run() {
    use fieldprobe::machine::{Machine, RunStatus, MAX_TRACE_SAMPLES};
    use fieldprobe::params::MachineConfig;
    // 1 mm at 1 mm/min: 60 s of travel, 60,000 cycles of 1 ms (plus the ramps).
    let cfg = MachineConfig::default_machine();
    let cycle_s = f64::from(cfg.cycle_time_us) * 1e-6;
    let mut m = Machine::new(&cfg).unwrap();
    m.enable_trace();
    let prog = fieldprobe::nc::parser::parse("N10 G01 X1 F1\nN20 M30\n").unwrap();
    let r = m.run_program(&prog, &mut |_| {});
    assert_eq!(r.status, RunStatus::Completed);
    let tr = m.trace().unwrap();
    let n = tr.t.len();
    assert!(n <= MAX_TRACE_SAMPLES, "{n} samples");
    // Stride: the smallest power of two whose samples fit, ≥ 60 s / cycle / limit = 6 → 8.
    let cycles = 60.0 / cycle_s;
    let want = (cycles / MAX_TRACE_SAMPLES as f64).ceil() as u64;
    assert_eq!(tr.stride, want.next_power_of_two(), "stride");
    assert!(
        n * 2 > MAX_TRACE_SAMPLES,
        "at least half the limit used: {n}"
    );
    // Evenly spaced over the whole run: the last sample at ≥ 60 s, X at its target.
    let dt = tr.stride as f64 * cycle_s;
    for w in tr.t.windows(2) {
        assert!((w[1] - w[0] - dt).abs() < 1e-9, "{w:?}");
    }
    assert!(*tr.t.last().unwrap() >= 60.0, "{}", tr.t.last().unwrap());
    // The last kept sample is at most one stride before the end: X within 1 mm/min · dt.
    let last = *tr.command[0].last().unwrap();
    assert!((last - 1.0).abs() <= dt / 60.0 + 1e-9, "{last}");
    assert_eq!(tr.command[0].len(), n);
    assert_eq!(tr.actual[0].len(), n);
}

#[test]
fn trace_svg_of_a_slow_move_stays_small() {
    // Before: one sample per cycle, 60,000 points per line here (and 260 MB for X1000 F1).
    let (d, p) = program("N10 G01 X1 F1\nN20 M30\n");
    let svg = d.path().join("t.svg");
    let o = fieldprobe(&["run", &p, "--link", "sim", "--trace", svg.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("one sample every 8 cycles"),
        "{}",
        stderr(&o)
    );
    let size = std::fs::metadata(&svg).unwrap().len();
    assert!(size < 1_000_000, "{size} bytes");
}
