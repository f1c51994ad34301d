//! PLC_TIMESTAMP through a timestamp input on a vendor segment over a real wire (issue 19 "done
//! when": "meas1 with PLC_TIMESTAMP through an emulated timestamp input works on that segment").
//!
//! `fieldprobe sim ethercat` plays, on one end of a veth pair, three devices from the real
//! Ingenia EVS-NET-01 ESI (`../shared/test-data/esi/`; no touch probe) and an EL1252-kind
//! timestamp input (`esi/fieldprobe-el1252.xml`) behind them, on its own clock: DC system time
//! = its monotonic clock + the offset the master wrote (0x0920), the drives sampling their
//! position at SYNC0, the terminal stamping the edge of its input 1 with its system time.
//! `--probe-at 2=100 --probe-input 3:2` puts the probe at Z = 100 mm on the drive at ring
//! position 2 (Z), wired to input 2 of the terminal (ring position 3). On the other end
//! `fieldprobe run examples/nc/seed004/meas1.nc --link ethercat:v0` with a machine whose Z
//! measures with `PLC_TIMESTAMP`, the probe on channel 2 of the terminal (`[[terminal]]
//! probe_axis = "Z"`, `probe_channel = 2`; the same machine with channel 1, which nothing
//! switches, measures nothing, error 900045):
//! the master relates the terminal's DC timestamps to Z's actual values through the reference
//! clock's system time each cycle's frame reads (the SYNC0 at which the drives sampled).
//!
//! Accuracy over this wire, from the seed and physics, not from the code: meas1 moves Z down at
//! F2000 (v = 2000/60 mm/s) through the probe with a 1 ms cycle T. The value is off by
//! * the terminal's timestamp resolution, 1 ns (EL1252: 1 ns; the emulator stamps whole ns):
//!   v · 1 ns = 0.00000003 mm;
//! * the interpolation between two actual values a cycle apart: at most a·T²/8 (a ≤
//!   P-AXIS-00004 = 1000 mm/s², 0 at constant speed) = 0.000125 mm, plus half an increment
//!   (0.1 µm) in each of the two positions = 0.0001 mm;
//! * the DC sync error between the terminal and the drive (their system times disagree by δ:
//!   the edge moves by v·δ). On the emulator all devices share one clock; the offsets the
//!   master writes come from receive times 500 ns apart per device (its delay model) and the
//!   clock is not slewed, so the terminal three positions behind the reference clock runs at
//!   most 3 × 500 ns = 1.5 µs from the drives: v · 1.5 µs = 0.00005 mm.
//!
//! Bound: 0.000225 + 0.00005 + 0.00000003 ≈ 0.000275 mm. A relation off by one cycle (the
//! samples stamped a SYNC0 early or late) moves the value by v·T = 0.033 mm, 120 times that
//! (seen: error 900043, the timestamp outside its signal's window); the frame's own time taken
//! for the samples' (half a period late) by 0.0175 mm (seen: fails the bound).
//! DRIVE on the same axis is refused before motion (error 900046).
//!
//! SKIP without user namespaces / veth or without the test data or seeds
//! (FIELDPROBE_REQUIRE_TEST_DATA=1 makes missing data a failure). Every wait is bounded.

use std::{
    ffi::OsString,
    process::{Command, Stdio},
    time::Duration,
};

use crate::common::seed004;
use crate::common::test_data;
use crate::common::veth;
use veth::netns::run_bounded;
use veth::{start_emulator, VethPair, MASTER_IF};

const INNER_ENV: &str = "FIELDPROBE_VENDOR_TIMESTAMP_VETH";
const TEST_NAME: &str = "meas1_with_plc_timestamp_on_a_vendor_segment_over_veth";
const OUTER_TIMEOUT: Duration = Duration::from_secs(300);
const STEP_TIMEOUT: Duration = Duration::from_secs(90);
const EMULATOR_SECONDS: &str = "250";
const INGENIA: &str = "esi/ingenia-evs-net-ecat402-drive.xml";

/// meas1's measuring feed (mm/s).
const V: f64 = 2000.0 / 60.0;
/// Interpolation cycle (s).
const T: f64 = 0.001;
/// P-AXIS-00004 default acceleration (mm/s²).
const A: f64 = 1000.0;
/// One drive increment (mm).
const INC: f64 = 1e-4;
/// The terminal's timestamp resolution (s).
const STAMP_RESOLUTION: f64 = 1e-9;
/// DC sync error between the terminal and the drives on the emulator (s): 500 ns per device
/// between the reference clock (ring position 0) and the terminal (ring position 3).
const DC_SYNC_ERROR: f64 = 3.0 * 500e-9;
/// `%f` prints 6 decimals.
const PRINT: f64 = 0.5e-6;

/// Z measures with PLC_TIMESTAMP, its probe on input 1 of the EL1252 behind the three drives
/// (the drives: the default `cia402-generic`, fitted by the master to what the Ingenia offers).
const MACHINE_CH2: &str =
    "[[axis]]\nname = \"X\"\n\n[[axis]]\nname = \"Y\"\n\n[[axis]]\nname = \"Z\"\n\
kenngr.messachse = 1\nkenngr.measure.signal = \"PLC_TIMESTAMP\"\nkenngr.measure.edge = \"POS\"\n\n\
[[terminal]]\nname = \"TS\"\nesi = \"fieldprobe-el1252\"\nprobe_axis = \"Z\"\nprobe_channel = 2\n";

#[test]
fn meas1_with_plc_timestamp_on_a_vendor_segment_over_veth() {
    let _one_module = crate::gate::enter(module_path!());
    if veth::inner_env(INNER_ENV).is_some() {
        inner();
        return;
    }
    if test_data::test_data(INGENIA, TEST_NAME).is_none() || !test_data::seeds_present(TEST_NAME) {
        return;
    }
    veth::run_in_veth_namespace(TEST_NAME, INNER_ENV, OUTER_TIMEOUT, || OsString::from("1"));
}

fn fieldprobe(args: &[&str]) -> (Option<std::process::ExitStatus>, String, String) {
    run_bounded(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .stdin(Stdio::null())
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(args),
        STEP_TIMEOUT,
    )
}

/// Every printed value lies within `bound` of the seed's annotation (seed 004 §5, parsed from
/// the seed text). Returns the largest deviation.
#[track_caller]
fn within_seed(out: &str, bound: f64) -> f64 {
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
            dev.abs() <= bound + PRINT,
            "{name} = {got}, seed {want}: off by {dev}, allowed ±{bound}\n{out}"
        );
        worst = worst.max(dev.abs());
    }
    worst
}

fn inner() {
    let esi = test_data::test_data(INGENIA, TEST_NAME).expect("test data checked outside");
    let dir = std::env::temp_dir().join(format!("fieldprobe-{TEST_NAME}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let machine = dir.join("machine.toml");
    std::fs::write(&machine, MACHINE_CH2).unwrap();
    let machine = machine.to_string_lossy().into_owned();
    let machine_ch1 = dir.join("machine-ch1.toml");
    std::fs::write(
        &machine_ch1,
        MACHINE_CH2.replace("probe_channel = 2", "probe_channel = 1"),
    )
    .unwrap();
    let machine_ch1 = machine_ch1.to_string_lossy().into_owned();

    let bound = STAMP_RESOLUTION * V + A * T * T / 8.0 + INC + DC_SYNC_ERROR * V;
    assert!(bound < 0.00028 && V * T / bound > 100.0, "{bound}");

    let _pair = VethPair::create();
    let drives = format!("{}:3", esi.display());
    let (emu, emu_log) = start_emulator(
        &[drives.as_str(), "esi/fieldprobe-el1252.xml"],
        EMULATOR_SECONDS,
        &[
            "--probe-at".into(),
            "2=100".into(),
            "--probe-input".into(),
            "3:2".into(),
        ],
    );
    let link = format!("ethercat:{MASTER_IF}");
    let meas1_on = |machine: &str, extra: &[&str]| {
        let mut args = vec![
            "run",
            "examples/nc/seed004/meas1.nc",
            "--machine",
            machine,
            "--link",
            &link,
        ];
        args.extend_from_slice(extra);
        fieldprobe(&args)
    };
    let meas1 = |extra: &[&str]| meas1_on(&machine, extra);

    // 1. PLC_TIMESTAMP: the seed's values within the bound.
    let (status, out, err) = meas1(&[]);
    assert!(
        status.is_some_and(|s| s.success()),
        "meas1 PLC_TIMESTAMP: {status:?}\n{out}\n{err}"
    );
    assert!(
        err.contains("3 axis drives, 1 terminal named in the machine"),
        "the segment: {err}"
    );
    let worst = within_seed(&out, bound);
    println!(
        "PLC_TIMESTAMP over veth: largest deviation from the seed {worst:.6} mm (bound {bound:.6})"
    );

    // 2. DRIVE on that axis: refused before motion (no #MSG line), naming what remains.
    let (status, out, err) = meas1(&["--set", "Z.kenngr.measure.signal=DRIVE"]);
    assert_eq!(
        status.and_then(|s| s.code()),
        Some(1),
        "meas1 DRIVE: {status:?}\n{out}\n{err}"
    );
    assert_eq!(out, "", "no #MSG line: the run stopped at N20\n{err}");
    let refusal = err
        .lines()
        .find(|l| l.starts_with("error 900046: axis Z: "))
        .unwrap_or_else(|| panic!("no error 900046 for Z:\n{err}"));
    for s in [
        "has no touch probe",
        "signal DRIVE ",
        "PLC_TIMESTAMP (",
        "EL1252",
        "(N20)",
    ] {
        assert!(refusal.contains(s), "{s:?} not in {refusal}");
    }

    // 3. The probe is on input 2 only: Z wired to input 1 sees no edge and measures nothing.
    // MODE[1] runs to its end point without an edge: no value (0), G101 then refuses.
    let (status, out, err) = meas1_on(&machine_ch1, &[]);
    assert!(
        status.and_then(|s| s.code()) == Some(1)
            && out.lines().next() == Some("V.A.MESS.Z=0.000000")
            && err.contains("error 900045: G101: axis Z has no measured value"),
        "meas1 with the probe on the other input: {status:?}\n{out}\n{err}"
    );

    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!("emulator log: {log:#?}");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        log.iter().any(|l| l.contains(
            "wired to its touch probe input 1 and channel 2 of the timestamp terminal at 3"
        )),
        "the probe surface is wired to the terminal: {log:#?}"
    );
    println!("INNER OK");
}
