//! Measuring on an axis whose CiA 402 drive has no touch probe (issue 19 item 4; seed 004 §7
//! "if the drive hardware used provides no latch function, the measured value can be detected
//! in the CNC"): `check` names the sources that remain, a drive-latch source is refused before
//! motion (error 900046) with those sources in the message, and meas1 (seed 004 §5) with PLC or
//! PLC_TIMESTAMP prints the seed's values within each source's accuracy.
//!
//! The drive is the generic one without its touch probe objects (0x60B8 out, 0x60B9 …
//! 0x60BD in) and without `[probe]`, as `drive from-esi` writes it for the Ingenia ESI.
//!
//! Accuracy, from the seed and the program, not from the code: meas1 moves Z down at F2000
//! (v = 2000/60 mm/s) through the probe at Z = 100 on a machine with a 1 ms cycle T (shared by
//! the simulated PLC). §7.1 PLC: "the measured value is the actual value at the time of
//! occurrence of the probing signal" as the CNC sees it, so it lies behind the crossing by at
//! most v·T. §7.5 PLC_TIMESTAMP: the position at the terminal's timestamp is calculated back
//! from the actual positions around it; linear interpolation between two cycles is off by at
//! most a·T²/8 (a ≤ P-AXIS-00004 = 1000 mm/s², 0 at constant speed) plus half an increment of
//! 0.1 µm in each of the two positions.

use crate::common::cli;
use crate::common::seed004;
use crate::common::test_data;
use cli::{fieldprobe, stderr, stdout};

/// meas1's measuring feed (mm/s).
const V: f64 = 2000.0 / 60.0;
/// Interpolation cycle of the default machine (s).
const T: f64 = 0.001;
/// `%f` prints 6 decimals.
const PRINT: f64 = 0.5e-6;
/// One drive increment (mm).
const INC: f64 = 1e-4;

/// The generic drive without touch probe, written to `dir`.
fn drive_without_touch_probe(dir: &tempfile::TempDir) -> String {
    let path = format!("{}/drives/cia402-generic.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::new();
    let mut in_probe = false;
    for line in text.lines() {
        if line.starts_with('[') {
            in_probe = line == "[probe]";
        }
        if in_probe {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    let out = out
        .replace("name = \"cia402-generic\"", "name = \"no-touch-probe\"")
        .replace(", \"0x60B8:00\"]", "]")
        .replace(
            "\"0x60B9:00\", \"0x60BA:00\", \"0x60BB:00\", \"0x60BC:00\", \"0x60BD:00\",",
            "",
        );
    for o in ["\"0x60B8:00\"", "\"0x60B9:00\"", "[probe]"] {
        assert!(!out.contains(o), "{o} still in\n{out}");
    }
    let file = dir.path().join("no-touch-probe.toml");
    std::fs::write(&file, out).unwrap();
    file.to_string_lossy().into_owned()
}

/// The three sources of seed 004 §7 named in `text`.
#[track_caller]
fn names_the_remaining_sources(text: &str) {
    for s in [
        "PLC (",
        "PLC_TIMESTAMP (",
        "PLC_EXT_LATCH_CONTROL (",
        "EL1252",
    ] {
        assert!(text.contains(s), "{s} not in: {text}");
    }
}

fn run(drive: &str, program: &str, sets: &[&str], json: bool) -> std::process::Output {
    let z = format!("Z.drive={drive}");
    let mut args = vec![
        "run",
        program,
        "--link",
        "sim",
        "--probe-at",
        "Z=100",
        "--set",
        z.as_str(),
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    if json {
        args.push("--json");
    }
    fieldprobe(&args)
}

#[test]
fn signal_drive_is_refused_before_motion_with_the_alternatives() {
    let dir = tempfile::tempdir().unwrap();
    let drive = drive_without_touch_probe(&dir);
    for signal in ["DRIVE", "DRIVE_TYPE_DEFAULT", "EXT_PROBE_WITH_DRIVE"] {
        let set = format!("Z.kenngr.measure.signal={signal}");
        let o = run(&drive, "examples/nc/seed004/meas1.nc", &[&set], false);
        assert_eq!(o.status.code(), Some(1), "{signal}: {}", stderr(&o));
        assert_eq!(
            stdout(&o),
            "",
            "{signal}: no #MSG line: the run stopped at N20"
        );
        let err = stderr(&o);
        assert!(
            err.starts_with("error 900046: axis Z: drive 'no-touch-probe' has no touch probe"),
            "{err}"
        );
        assert!(err.contains(&format!("signal {signal} ")), "{err}");
        assert!(err.trim_end().ends_with("(N20)"), "{err}");
        names_the_remaining_sources(&err);
    }
    // Before motion: Z stands where N10 put it (200), the measuring travel towards 20 never
    // started, and nothing was measured.
    let o = run(&drive, "examples/nc/seed004/meas1.nc", &[], true);
    assert_eq!(o.status.code(), Some(1));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("--json report");
    let axis = report["axes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "Z")
        .expect("axis Z in the report");
    assert_eq!(axis["command"].as_f64(), Some(200.0), "{axis}");
    assert!(
        (axis["actual"].as_f64().unwrap() - 200.0).abs() < 0.01,
        "{axis}"
    );
    assert_eq!(axis["measurement"]["merf"], false, "{axis}");
    assert!(axis["measurement"]["mess"].is_null(), "{axis}");
}

#[test]
fn meas_signal_drive_in_the_program_is_refused_too() {
    // Configured for PLC, switched to the drive latch by #MEAS in the program.
    let dir = tempfile::tempdir().unwrap();
    let drive = drive_without_touch_probe(&dir);
    let prog = dir.path().join("p.nc");
    std::fs::write(
        &prog,
        "N05 #MEAS [AXNR=3 SIGNAL=DRIVE]\nN10 G01 Z200 F6000\nN20 G100 Z20 F2000\nN30 M30\n",
    )
    .unwrap();
    let o = run(
        &drive,
        prog.to_str().unwrap(),
        &["Z.kenngr.measure.signal=PLC"],
        false,
    );
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.starts_with("error 900046: "), "{err}");
    assert!(err.contains("signal DRIVE (#MEAS SIGNAL)"), "{err}");
    names_the_remaining_sources(&err);
}

#[test]
fn check_names_the_sources_that_remain() {
    let dir = tempfile::tempdir().unwrap();
    let drive = drive_without_touch_probe(&dir);
    // Default machine: Z measures with DRIVE -> one finding, exit 1.
    let o = fieldprobe(&["check", "--set", &format!("Z.drive={drive}")]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let out = stdout(&o);
    let z = &out[out.find("Z (no-touch-probe, cia402):\n").expect("Z")..];
    assert_eq!(
        z.matches("\n  - ").count(),
        1,
        "one finding, not one per object: {z}"
    );
    assert!(
        z.contains("has no touch probe") && z.contains("signal DRIVE cannot latch"),
        "{z}"
    );
    names_the_remaining_sources(z);
    assert!(z.contains("names no timestamp input terminal"), "{z}");

    // A machine file with an EL1252-kind terminal and Z on PLC_TIMESTAMP: no finding, a note
    // naming the terminal.
    let machine = dir.path().join("m.toml");
    std::fs::write(
        &machine,
        format!(
            "[[axis]]\nname = \"X\"\n\n[[axis]]\nname = \"Z\"\ndrive = \"{drive}\"\n\
             kenngr.messachse = 1\nkenngr.measure.signal = \"PLC_TIMESTAMP\"\n\n\
             [[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\n\n\
             [[terminal]]\nname = \"ENC\"\nesi = \"fieldprobe-el5101\"\n"
        ),
    )
    .unwrap();
    let o = fieldprobe(&["check", "--machine", machine.to_str().unwrap()]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    assert!(
        out.contains("Z (no-touch-probe, cia402):\n  ok\n  note: "),
        "{out}"
    );
    assert!(
        out.contains("measures through the CNC with PLC_TIMESTAMP"),
        "{out}"
    );
    assert!(out.contains("TS (fieldprobe-el1252)"), "{out}");
    assert!(
        !out.contains("ENC ("),
        "the EL5101 is no timestamp input: {out}"
    );
    // The same machine with Z on DRIVE: the finding names the terminal for PLC_TIMESTAMP.
    let o = fieldprobe(&[
        "check",
        "--machine",
        machine.to_str().unwrap(),
        "--set",
        "Z.kenngr.measure.signal=DRIVE",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let out = stdout(&o);
    names_the_remaining_sources(&out);
    assert!(out.contains("TS (fieldprobe-el1252)"), "{out}");
}

/// meas1 on the drive without touch probe with `signal`: every printed value lies within
/// `behind_at_most` behind (below) and `ahead_at_most` ahead of the seed's annotation.
fn meas1_within(signal: &str, behind_at_most: f64, ahead_at_most: f64) {
    let dir = tempfile::tempdir().unwrap();
    let drive = drive_without_touch_probe(&dir);
    let set = format!("Z.kenngr.measure.signal={signal}");
    let o = run(&drive, "examples/nc/seed004/meas1.nc", &[&set], false);
    assert_eq!(o.status.code(), Some(0), "{signal}: {}", stderr(&o));
    assert_eq!(stderr(&o), "", "{signal}: no warnings");
    let seed = seed004::seed_annotations("meas1");
    let out = stdout(&o);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), seed.len(), "{out}");
    // The measured value m enters every annotated value that depends on it with the same sign
    // (V.A.MESS, ACS, PCS = m; MOFFS = m − 20; MEIN after G101 = MOFFS; ABS after G101 =
    // 100 + MOFFS); the others are exact. Moving down, "behind" means below the crossing.
    let mut worst: f64 = 0.0;
    for ((name, want), line) in seed.iter().zip(&lines) {
        let (n, v) = line.split_once('=').unwrap();
        assert_eq!(n, name);
        let got: f64 = v.parse().unwrap();
        let dev = got - want;
        assert!(
            dev >= -behind_at_most - PRINT && dev <= ahead_at_most + PRINT,
            "{signal}: {name} = {got}, seed {want}: off by {dev}, allowed -{behind_at_most} / +{ahead_at_most}"
        );
        worst = worst.max(dev.abs());
    }
    eprintln!("{signal}: largest deviation from the seed {worst:.6} mm");
}

#[test]
fn meas1_with_plc_prints_the_seed_values_within_v_times_t() {
    if !test_data::seeds_present("meas1_with_plc_prints_the_seed_values_within_v_times_t") {
        return;
    }
    // Sampled once per cycle: at or behind the crossing (below it, moving down) by ≤ v·T.
    meas1_within("PLC", V * T + INC / 2.0, INC / 2.0);
}

#[test]
fn meas1_with_plc_timestamp_prints_the_seed_values_within_a_t2_over_8() {
    if !test_data::seeds_present(
        "meas1_with_plc_timestamp_prints_the_seed_values_within_a_t2_over_8",
    ) {
        return;
    }
    let bound = 1000.0 * T * T / 8.0 + INC;
    meas1_within("PLC_TIMESTAMP", bound, bound);
}
