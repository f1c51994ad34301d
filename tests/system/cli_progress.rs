//! Issue 18, item 6: a progress line on stderr for long runs of `fieldprobe run` when stderr is
//! a terminal (block, program time, cycles per second on real links), redrawn in place at most
//! a few times per second and erased at the end; none in a pipe or with `--quiet`. No ANSI
//! colour in the log (`FIELDPROBE_LOG`) unless stderr is a terminal, and never with `NO_COLOR`.
//!
//! The terminal is a pty from util-linux `script -qc CMD /dev/null` (stdout and stderr of CMD
//! both go to the pty; `script` copies it to its stdout). Without `script` the pty tests print
//! `SKIP`.

use crate::common::netns;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_fieldprobe");

/// Where the progress line starts (a carriage return, then the text).
const LINE: &str = "\rfieldprobe run: ";

/// Is util-linux `script` here?
fn have_script() -> bool {
    Command::new("script")
        .args(["-qc", "true", "/dev/null"])
        .stdin(Stdio::null())
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Write `src` as an NC program in `dir`.
fn program(dir: &tempfile::TempDir, src: &str) -> String {
    let p = dir.path().join("long.nc");
    std::fs::write(&p, src).unwrap();
    let s = p.to_str().unwrap().to_string();
    assert!(!s.contains([' ', '\'', '"']), "path needs no quoting: {s}");
    s
}

/// A program that runs about three seconds of wall time on `ethercat-emu` here: measured with
/// a short run (10,000 cycles) first, then one move at F1 (1 mm = 60,000 cycles of 1 ms).
fn three_second_program(dir: &tempfile::TempDir) -> String {
    let short = program(dir, "N10 G01 X1 F6\nN20 M30\n");
    let t0 = Instant::now();
    let o = Command::new(BIN)
        .args(["run", &short, "--link", "ethercat-emu"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let per_cycle = t0.elapsed().as_secs_f64() / 10_000.0;
    // At least 1 mm, at most 50 mm (3,000,000 cycles, below the run limit of 3,600,000).
    let mm = (3.0 / per_cycle / 60_000.0).ceil().clamp(1.0, 50.0);
    program(dir, &format!("N10 G01 X{mm} F1\nN20 M30\n"))
}

/// Run `sh -c CMD` under a pty; (exit code, what the terminal got, wall time).
fn on_terminal(cmd: &str, env: &[(&str, &str)]) -> (Option<i32>, String, Duration) {
    let t0 = Instant::now();
    let mut c = Command::new("script");
    c.args(["-qec", cmd, "/dev/null"])
        .stdin(Stdio::null())
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    for (k, v) in env {
        c.env(k, v);
    }
    let (status, out, err) = netns::run_bounded(&mut c, Duration::from_secs(120));
    assert!(err.is_empty(), "script: {err}");
    (status.and_then(|s| s.code()), out, t0.elapsed())
}

#[test]
fn a_long_run_on_a_terminal_shows_progress_in_place_and_erases_it() {
    let _one_module = crate::gate::enter(module_path!());
    if !have_script() {
        eprintln!("SKIP a_long_run_on_a_terminal_shows_progress_in_place_and_erases_it: no util-linux `script`");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let prog = three_second_program(&dir);
    let (code, term, took) = on_terminal(&format!("{BIN} run {prog}"), &[]);
    assert_eq!(code, Some(0), "{term}");
    assert!(
        took > Duration::from_millis(1500),
        "the run took {took:?}: too short to show progress"
    );
    let draws = term.matches(LINE).count();
    assert!(draws >= 1, "no progress line in {took:?}: {term:?}");
    // At most four redraws a second (REDRAW = 250 ms), none in the first second.
    let bound = (took.as_secs_f64() * 4.0).ceil() as usize;
    assert!(draws <= bound, "{draws} redraws in {took:?}");
    // The current block and the program time; no cycles per second on virtual time.
    let first = term.split(LINE).nth(1).unwrap();
    assert!(
        first.starts_with("N10 (line 1), program time "),
        "{first:?}"
    );
    assert!(!term.contains("cycles/s"), "{term:?}");
    // Redrawn in place: no newline between two draws; erased at the end with blanks.
    let last_draw = term.rfind(LINE).unwrap();
    let tail = &term[last_draw + 1..];
    let line_end = tail.find('\r').expect("erased");
    assert!(!tail[..line_end].contains('\n'), "{tail:?}");
    let after = &tail[line_end..];
    assert!(after.starts_with("\r "), "not erased: {after:?}");
    let blank = after[1..]
        .find('\r')
        .expect("carriage return after the blanks");
    assert!(after[1..1 + blank].chars().all(|c| c == ' '), "{after:?}");
    // No escape sequences on the terminal from the progress line.
    assert!(!term.contains('\x1b'), "{term:?}");
}

#[test]
fn no_progress_with_quiet_or_in_a_pipe() {
    let _one_module = crate::gate::enter(module_path!());
    let dir = tempfile::tempdir().unwrap();
    let prog = three_second_program(&dir);
    if have_script() {
        let (code, term, _) = on_terminal(&format!("{BIN} run {prog} --quiet"), &[]);
        assert_eq!(code, Some(0), "{term}");
        assert!(!term.contains("fieldprobe run:"), "{term:?}");
    } else {
        eprintln!(
            "SKIP (--quiet part) no_progress_with_quiet_or_in_a_pipe: no util-linux `script`"
        );
    }
    let o = Command::new(BIN).args(["run", &prog]).output().unwrap();
    assert_eq!(o.status.code(), Some(0));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !err.contains("fieldprobe run:") && !err.contains('\r'),
        "{err:?}"
    );
}

#[test]
fn the_log_has_no_colour_in_a_file_or_with_no_color() {
    let _one_module = crate::gate::enter(module_path!());
    let dir = tempfile::tempdir().unwrap();
    let prog = program(&dir, "N10 G01 X1 F600\nN20 M30\n");
    // stderr to a file: plain text.
    let log = dir.path().join("log.txt");
    let file = std::fs::File::create(&log).unwrap();
    let o = Command::new(BIN)
        .args(["run", &prog])
        .env("FIELDPROBE_LOG", "debug")
        .env_remove("NO_COLOR")
        .stderr(file)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let text = std::fs::read(&log).unwrap();
    assert!(
        text.windows(5).any(|w| w == b"DEBUG"),
        "no debug log: {}",
        String::from_utf8_lossy(&text)
    );
    assert!(!text.contains(&0x1b), "ESC in the log file");
    if !have_script() {
        eprintln!("SKIP (terminal part) the_log_has_no_colour_in_a_file_or_with_no_color: no util-linux `script`");
        return;
    }
    // On a terminal: coloured, unless NO_COLOR is set (https://no-color.org).
    let cmd = format!("env -u NO_COLOR FIELDPROBE_LOG=debug {BIN} run {prog}");
    let (code, term, _) = on_terminal(&cmd, &[]);
    assert_eq!(code, Some(0), "{term}");
    assert!(term.contains('\x1b'), "no colour on a terminal: {term:?}");
    let cmd = format!("FIELDPROBE_LOG=debug NO_COLOR=1 {BIN} run {prog}");
    let (code, term, _) = on_terminal(&cmd, &[]);
    assert_eq!(code, Some(0), "{term}");
    assert!(term.contains("DEBUG"), "{term:?}");
    assert!(!term.contains('\x1b'), "colour despite NO_COLOR: {term:?}");
}

#[test]
fn a_real_link_shows_cycles_per_second() {
    let _one_module = crate::gate::enter(module_path!());
    // `run --link ethercat:v0` against `sim ethercat` on a veth pair, both on the wall clock
    // (1 ms cycle): a three-second program shows the rate.
    if !have_script() {
        eprintln!("SKIP a_real_link_shows_cycles_per_second: no util-linux `script`");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let prog = program(&dir, "N10 G01 X1 F20\nN20 M30\n");
    let inner = format!(
        "timeout 60 {BIN} sim ethercat --iface v1 --device esi/fieldprobe-ek1100.xml \
         --device esi/fieldprobe-cia402-servo.xml:3 --seconds 60 2>/dev/null & sleep 0.5; \
         script -qec '{BIN} run {prog} --link ethercat:v0 --set max_lost_cycles=50' /dev/null; \
         rc=$?; kill %1 2>/dev/null; exit $rc"
    );
    let probe = Command::new("scripts/netns.sh")
        .arg("true")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!("SKIP a_real_link_shows_cycles_per_second: scripts/netns.sh (unshare + veth) not available");
        return;
    }
    let (status, out, err) = netns::run_bounded(
        Command::new("scripts/netns.sh")
            .args(["sh", "-c", &inner])
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        Duration::from_secs(90),
    );
    assert_eq!(status.and_then(|s| s.code()), Some(0), "{out}{err}");
    let rates: Vec<f64> = out
        .split(LINE)
        .skip(1)
        .filter_map(|d| {
            d.split(", ")
                .find_map(|p| p.find(" cycles/s").map(|k| &p[..k]))
        })
        .filter_map(|n| n.trim().parse().ok())
        .collect();
    assert!(!rates.is_empty(), "no cycles/s: {out:?}");
    // 1 ms cycle: about 1000 per second; a loaded machine falls behind, never far ahead.
    assert!(rates.iter().all(|&r| r > 0.0 && r < 2000.0), "{rates:?}");
}
