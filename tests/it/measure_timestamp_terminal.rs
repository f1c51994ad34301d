//! PLC_TIMESTAMP through a timestamp input terminal on the EtherCAT segment (issue 19 item 4;
//! seed 004 §7.5): the axes' CiA 402 drives have no touch probe, the probe is wired to input 1
//! (or 2) of an EL1252-kind terminal on the same segment (`[[terminal]] probe_axis`), and the
//! axis measures with `kenngr.measure.signal PLC_TIMESTAMP`: the terminal latches the DC time of
//! the probe edge, the CNC calculates the position at that time back from the actual values.
//!
//! On `ethercat-emu` the emulator plays the drives without touch probe (their ESI device
//! without 0x60B8 … 0x60BD) and the EL1252; `--probe-at Z=100` switches the terminal's input
//! when Z crosses 100.
//!
//! Accuracy, from the seed and physics, not from the code: meas1 (seed 004 §5) moves Z down at
//! F2000 (v = 2000/60 mm/s) through the probe at Z = 100 with a 1 ms cycle T. The position at
//! the timestamp is interpolated between the actual values of two cycles: off by at most
//! a·T²/8 (a ≤ P-AXIS-00004 = 1000 mm/s², 0 at constant speed) plus half an increment of
//! 0.1 µm in each of the two positions. A PLC that samples the input instead (seed 004 §7.1)
//! lies up to v·T = 0.033 mm behind — 150 times that bound.

use crate::common::cli;
use crate::common::seed004;
use crate::common::test_data;
use cli::{fieldprobe, stderr, stdout};

use fieldprobe::drive::el1252::{decode_image, CHANNEL_LEN};
use fieldprobe::drive::model::el1252::El1252Device;
use fieldprobe::machine::{LinkChoice, Machine, RunStatus};
use fieldprobe::params::MachineConfig;

/// meas1's measuring feed (mm/s).
const V: f64 = 2000.0 / 60.0;
/// Interpolation cycle (s).
const T: f64 = 0.001;
/// P-AXIS-00004 default acceleration (mm/s²).
const A: f64 = 1000.0;
/// One drive increment (mm).
const INC: f64 = 1e-4;
/// `%f` prints 6 decimals.
const PRINT: f64 = 0.5e-6;

/// The generic drive without its touch probe (no `[probe]`, no 0x60B8 … 0x60BD in the PDOs),
/// written to `dir`.
fn drive_without_touch_probe(dir: &tempfile::TempDir) -> String {
    let path = format!("{}/drives/cia402-generic.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::new();
    let mut in_probe = false;
    for line in text.lines() {
        if line.starts_with('[') {
            in_probe = line == "[probe]";
        }
        if !in_probe {
            out.push_str(line);
            out.push('\n');
        }
    }
    let out = out
        .replace("name = \"cia402-generic\"", "name = \"no-touch-probe\"")
        .replace(", \"0x60B8:00\"]", "]")
        .replace(
            "\"0x60B9:00\", \"0x60BA:00\", \"0x60BB:00\", \"0x60BC:00\", \"0x60BD:00\",",
            "",
        );
    for o in ["0x60B8", "0x60B9", "0x60BA", "[probe]"] {
        assert!(!out.contains(o), "{o} still in\n{out}");
    }
    let file = dir.path().join("no-touch-probe.toml");
    std::fs::write(&file, out).unwrap();
    file.to_string_lossy().into_owned()
}

/// X, Y, Z on drives without touch probe, Z measuring with PLC_TIMESTAMP, then `terminal` (the
/// `[[terminal]]` table text); the machine file in `dir`.
fn machine_file(dir: &tempfile::TempDir, terminal: &str) -> String {
    let drive = drive_without_touch_probe(dir);
    let mut text = String::new();
    for axis in ["X", "Y", "Z"] {
        text.push_str(&format!(
            "[[axis]]\nname = \"{axis}\"\ndrive = \"{drive}\"\n"
        ));
    }
    text.push_str(
        "kenngr.messachse = 1\nkenngr.measure.signal = \"PLC_TIMESTAMP\"\n\
         kenngr.measure.edge = \"POS\"\n\n",
    );
    text.push_str(terminal);
    let file = dir.path().join("machine.toml");
    std::fs::write(&file, text).unwrap();
    file.to_string_lossy().into_owned()
}

const TS_CHANNEL_1: &str =
    "[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\nprobe_axis = \"Z\"\n";
const TS_CHANNEL_2: &str = "[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\n\
                            probe_axis = \"Z\"\nprobe_channel = 2\n";

fn run_meas1(machine: &str, sets: &[&str]) -> std::process::Output {
    let mut args = vec![
        "run",
        "examples/nc/seed004/meas1.nc",
        "--machine",
        machine,
        "--link",
        "ethercat-emu",
        "--probe-at",
        "Z=100",
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    fieldprobe(&args)
}

/// The lines of stderr that are not the link's start-up report (info 900400 – 900402).
fn warnings_and_errors(o: &std::process::Output) -> Vec<String> {
    stderr(o)
        .lines()
        .filter(|l| !l.starts_with("info 9004"))
        .map(str::to_string)
        .collect()
}

/// Every printed value lies within `behind` below and `ahead` above the seed's annotation
/// (the measured value enters each annotated value that depends on it with the same sign;
/// moving down, "behind" is below the crossing). Returns the largest deviation.
#[track_caller]
fn within_seed(out: &str, behind: f64, ahead: f64) -> f64 {
    let seed = seed004::seed_annotations("meas1");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), seed.len(), "{out}");
    let mut worst: f64 = 0.0;
    for ((name, want), line) in seed.iter().zip(&lines) {
        let (n, v) = line.split_once('=').unwrap();
        assert_eq!(n, name, "{out}");
        let got: f64 = v.parse().unwrap();
        let dev = got - want;
        assert!(
            dev >= -behind - PRINT && dev <= ahead + PRINT,
            "{name} = {got}, seed {want}: off by {dev}, allowed -{behind} / +{ahead}\n{out}"
        );
        worst = worst.max(dev.abs());
    }
    worst
}

#[test]
fn meas1_with_plc_timestamp_on_the_terminal_prints_the_seed_values() {
    if !test_data::seeds_present("meas1_with_plc_timestamp_on_the_terminal_prints_the_seed_values")
    {
        return;
    }
    let bound = A * T * T / 8.0 + INC;
    assert!(bound < 0.00023 && V * T / bound > 100.0);
    let dir = tempfile::tempdir().unwrap();
    for terminal in [TS_CHANNEL_1, TS_CHANNEL_2] {
        let machine = machine_file(&dir, terminal);
        let o = run_meas1(&machine, &[]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert_eq!(warnings_and_errors(&o), Vec::<String>::new());
        // The segment: three drives and the terminal the machine names.
        assert!(
            stderr(&o).contains("3 axis drives, 1 terminal named in the machine"),
            "{}",
            stderr(&o)
        );
        let worst = within_seed(&stdout(&o), bound, bound);
        eprintln!("PLC_TIMESTAMP on the terminal: largest deviation from the seed {worst:.6} mm");
    }
}

#[test]
fn meas1_with_plc_on_the_terminal_lies_behind_by_at_most_v_times_t() {
    if !test_data::seeds_present("meas1_with_plc_on_the_terminal_lies_behind_by_at_most_v_times_t")
    {
        return;
    }
    // The terminal's input level as the PLC's probing signal, sampled once per cycle.
    let dir = tempfile::tempdir().unwrap();
    let machine = machine_file(&dir, TS_CHANNEL_1);
    let o = run_meas1(&machine, &["Z.kenngr.measure.signal=PLC"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let worst = within_seed(&stdout(&o), V * T + INC / 2.0, INC / 2.0);
    eprintln!("PLC on the terminal: largest deviation from the seed {worst:.6} mm");
}

#[test]
fn signal_drive_is_refused_before_motion_on_that_segment() {
    let dir = tempfile::tempdir().unwrap();
    let machine = machine_file(&dir, TS_CHANNEL_1);
    for signal in ["DRIVE", "DRIVE_TYPE_DEFAULT"] {
        let set = format!("Z.kenngr.measure.signal={signal}");
        let o = run_meas1(&machine, &[&set]);
        assert_eq!(o.status.code(), Some(1), "{signal}: {}", stderr(&o));
        assert_eq!(
            stdout(&o),
            "",
            "{signal}: no #MSG line: the run stopped at N20"
        );
        let errors = warnings_and_errors(&o);
        assert_eq!(errors.len(), 1, "{errors:?}");
        let err = &errors[0];
        assert!(
            err.starts_with("error 900046: axis Z: drive 'no-touch-probe' has no touch probe"),
            "{err}"
        );
        assert!(err.contains(&format!("signal {signal} ")), "{err}");
        for s in ["PLC (", "PLC_TIMESTAMP (", "EL1252"] {
            assert!(err.contains(s), "{s} not in {err}");
        }
        assert!(err.ends_with("(N20)"), "{err}");
    }
}

/// meas1 on `ethercat-emu` through the library, the terminal's timestamps shifted by
/// `offset_ns` (the emulated EL1252's fault knob): V.A.MESS.Z, and the terminal's two input
/// channels after the run.
fn meas1_via_library(
    terminal: &str,
    offset_ns: i64,
) -> (f64, [fieldprobe::drive::el1252::Channel; 2]) {
    let dir = tempfile::tempdir().unwrap();
    let file = machine_file(&dir, terminal);
    let cfg = MachineConfig::load(std::path::Path::new(&file)).unwrap();
    let mut m = Machine::with_link(&cfg, &LinkChoice::new("ethercat-emu")).unwrap();
    let ts = m
        .link()
        .terminal_device(0)
        .expect("the EL1252 hosts a model");
    m.link_mut()
        .model_mut(ts)
        .and_then(|d| d.as_any_mut().downcast_mut::<El1252Device>())
        .expect("the emulated EL1252")
        .set_stamp_offset_ns(offset_ns);
    m.add_probe("Z", 100.0).unwrap();
    let text = std::fs::read_to_string("examples/nc/seed004/meas1.nc").unwrap();
    let program = fieldprobe::nc::parser::parse(&text).unwrap();
    let report = m.run_program(&program, &mut |_| {});
    assert_eq!(report.status, RunStatus::Completed, "{:?}", report.events);
    let mess = report
        .output()
        .iter()
        .find_map(|l| l.strip_prefix("V.A.MESS.Z="))
        .expect("V.A.MESS.Z printed")
        .parse()
        .unwrap();
    let image = m.terminal_inputs("TS").expect("terminal TS");
    assert_eq!(image.len(), 2 * CHANNEL_LEN);
    let ch = decode_image(image, 2).unwrap();
    (mess, [ch[0], ch[1]])
}

#[test]
fn the_measured_value_follows_the_terminals_timestamps() {
    // Z crosses 100 at constant speed v; a terminal that stamps the edge Δ early reports the
    // crossing where Z was Δ·v higher. A result from anything but these timestamps (the PLC's
    // own sampling, a timestamp of its own) would not move.
    let (m0, ch) = meas1_via_library(TS_CHANNEL_1, 0);
    assert!(
        (m0 - 100.0).abs() <= A * T * T / 8.0 + INC + PRINT,
        "V.A.MESS.Z = {m0}"
    );
    assert_ne!(ch[0].latch_pos, 0, "channel 1 stamped the rising edge");
    assert_eq!(ch[1].latch_pos, 0, "nothing on channel 2: {ch:?}");
    let delta_ns: i64 = 20_000;
    let (m1, _) = meas1_via_library(TS_CHANNEL_1, -delta_ns);
    let shift = V * delta_ns as f64 * 1e-9;
    // Both values are linear interpolations on the same constant-speed stretch: each exact to
    // half an increment in each of its two samples.
    assert!(
        ((m1 - m0) - shift).abs() <= 2.0 * INC + 2.0 * PRINT,
        "stamped {delta_ns} ns early: {m1} − {m0} = {}, physics {shift}",
        m1 - m0
    );
    // The probe on channel 2: that channel carries the stamp, channel 1 none.
    let (m2, ch) = meas1_via_library(TS_CHANNEL_2, 0);
    assert_eq!(ch[0].latch_pos, 0, "{ch:?}");
    assert_ne!(ch[1].latch_pos, 0, "{ch:?}");
    assert!((m2 - m0).abs() <= PRINT, "{m2} vs {m0}");
}

#[test]
fn the_wiring_is_checked_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    // The axis tables take lines 1 – 13, the first [[terminal]] starts at line 14.
    let cases: [(&str, &[&str]); 5] = [
        (
            "[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\nprobe_axis = \"Q\"\n",
            &["machine.toml:17:", "probe_axis = \"Q\" is not an axis", "X, Y, Z"],
        ),
        (
            "[[terminal]]\nname = \"ENC\"\nesi = \"fieldprobe-el5101\"\nprobe_axis = \"Z\"\n",
            &["machine.toml:17:", "no timestamp input (EL1252 kind"],
        ),
        (
            "[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\nprobe_axis = \"Z\"\nprobe_channel = 3\n",
            &["machine.toml:18:", "probe_channel = 3", "1 ..= 2"],
        ),
        (
            "[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\ncount = 2\nprobe_axis = \"Z\"\n",
            &["machine.toml:14:", "probe_axis wires one terminal"],
        ),
        (
            "[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\nprobe_axis = \"Z\"\n\n\
             [[terminal]]\nname = \"TS2\"\nesi = \"fieldprobe-el1252\"\nprobe_axis = \"Z\"\n",
            &["machine.toml:22:", "already wired to terminal TS (line 14)"],
        ),
    ];
    for (terminal, wants) in cases {
        let machine = machine_file(&dir, terminal);
        let o = run_meas1(&machine, &[]);
        assert_eq!(o.status.code(), Some(2), "{terminal}: {}", stderr(&o));
        assert_eq!(stdout(&o), "");
        let err = stderr(&o);
        assert!(err.contains("machine.toml"), "names the file: {err}");
        for w in wants {
            assert!(err.contains(w), "{w} not in: {err}");
        }
    }
}
