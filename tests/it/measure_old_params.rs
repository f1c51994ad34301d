//! The probing-signal parameters of CNC builds up to V2.11.2019.14 (seed 004 §8.2.4) on a
//! machine that sets only them, on `sim`, `ethercat-emu` and `canopen-emu` (issue 27, item 1).
//!
//! Seed 004 §8.2.2: "If the parameter P-AXIS-00516 is not defined, the measurement method
//! resulting from previous parameters is used for backward compatibility reasons"; "If the
//! parameter P-AXIS-00517 is not specified, the setting in P-AXIS-00430 is used"; "If the
//! parameter P-AXIS-00518 is not specified, the setting in P-AXIS-00113 is output". §8.2.4:
//! P-AXIS-00330 "enables the measurement signal source 'Fixed stop'"; P-AXIS-00257: "the probing
//! signal is read from the HLI via the control unit … The probing value is the actual value at
//! the moment of the occurrence of the probing signal"; P-AXIS-00113 "0: Latch at positive edge
//! of pulse 1: Latch at negative edge of pulse". CiA 402 touch probe values (§6.4 table):
//! input 2 negative edge → 0x60BD.
//!
//! A parameter the machine sets that has no effect is warning 900047 naming it, at the start
//! of the run and in `fieldprobe check`.

use crate::common::cli;

use fieldprobe::machine::{LinkChoice, Machine, RunReport, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const Z: usize = 2;
/// The links the emulated drives run on.
const LINKS: [&str; 3] = ["sim", "ethercat-emu", "canopen-emu"];
/// 0.1 µm in mm: one drive increment (the latch resolution), and half of it.
const LATCH_TOL: f64 = 1e-4;
const HALF_INC: f64 = 0.5e-4;
/// Trigger position (ACS Z), off the set-point grid (as in tests/measurement_sources.rs).
const P: f64 = 100.0371;

/// The cycle on `link`: CAN carries three nodes at 4 ms (docs/canopen.md "Bus load").
fn cycle_s(link: &str) -> f64 {
    if link == "canopen-emu" {
        0.004
    } else {
        0.001
    }
}

/// A machine X, Y, Z on the generic CiA 402 drive whose Z axis list is `z` (machine-file
/// lines): no P-AXIS-00516 / 00517 / 00518 unless `z` gives them.
fn machine_on(link: &str, channel: &str, z: &str) -> Machine {
    let text = format!(
        "{channel}\n[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\n\
         kenngr.messachse = 1\n{z}\n"
    );
    let mut cfg = MachineConfig::parse(&text, "old.toml").unwrap_or_else(|e| panic!("{e}"));
    cfg.apply_set(&format!(
        "cycle_time_us={}",
        (cycle_s(link) * 1e6).round() as u32
    ))
    .unwrap();
    Machine::with_link(&cfg, &LinkChoice::new(link)).unwrap_or_else(|e| panic!("{link}: {e}"))
}

fn run(m: &mut Machine, src: &str) -> RunReport {
    m.run_program(&parse(src).unwrap(), &mut |_| {})
}

#[track_caller]
fn completed_quietly(r: &RunReport, what: &str) {
    assert_eq!(r.status, RunStatus::Completed, "{what}: {:?}", r.messages());
    assert!(r.messages().is_empty(), "{what}: {:?}", r.messages());
}

/// `G100 Z20` from Z = 200 (moving down) at 100 mm/s through the probe at [`P`].
const DOWN: &str = "N10 G01 Z200 F6000\nN20 G100 Z20 F6000\nN30 M30\n";

#[test]
fn p_axis_00330_alone_selects_the_fixed_stop_for_type_7_on_every_link() {
    // The seed's fixed-stop program (§7.3.2, CANopen) with the old parameters only: P-AXIS-00330
    // for the source, P-AXIS-00331 / 00332 ("Previous P-AXIS-00331 / 00332" of §7.3) for the
    // criterion: 0.1 mm lag for 10 cycles. The wall at 150 is latched.
    let program = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/nc/seed004/meas_fixed_stop_canopen.nc"
    ))
    .unwrap();
    for link in LINKS {
        let mut m = machine_on(
            link,
            "",
            "kenngr.meas_signal_fixed_stop = 1\nkenngr.fixed_stop_pos_lag_limit = 1000\n\
             kenngr.fixed_stop_nbr_cycles = 10",
        );
        m.add_fixed_stop("Z", 150.0).unwrap();
        let r = run(&mut m, &program);
        completed_quietly(&r, link);
        let z = r.measurements[Z].result.expect("latched").acs;
        assert!((z - 150.0).abs() <= 0.01, "{link}: latched {z}");
        assert!(r.measurements[Z].merf, "{link}");
    }
}

#[test]
fn p_axis_00257_alone_samples_the_probe_through_the_plc_on_every_link() {
    for link in LINKS {
        let t = cycle_s(link);
        let v = 100.0;
        // The old parameter: the actual value of the cycle that sees the signal — behind the
        // crossing by at most v·T, not the crossing itself.
        let mut m = machine_on(link, "", "kenngr.probing_signal_via_plc = 1");
        m.add_probe("Z", P).unwrap();
        let r = run(&mut m, DOWN);
        completed_quietly(&r, link);
        let value = r.measurements[Z].result.expect("latched").acs;
        assert!(
            value <= P + HALF_INC && value >= P - v * t - HALF_INC,
            "{link}: PLC sample {value} not in [{P} − v·T, {P}]"
        );
        assert!(
            (value - P).abs() > 1e-3,
            "{link}: {value} is the crossing itself (the drive latch), not a PLC sample"
        );
        // Without it the same machine latches in the drive: the crossing within 0.1 µm.
        let mut m = machine_on(link, "", "");
        m.add_probe("Z", P).unwrap();
        let r = run(&mut m, DOWN);
        completed_quietly(&r, link);
        let value = r.measurements[Z].result.expect("latched").acs;
        assert!(
            (value - P).abs() <= LATCH_TOL,
            "{link}: drive latch {value}"
        );
    }
}

#[test]
fn p_axis_00430_and_00113_select_probe_input_2_and_the_negative_edge_on_every_link() {
    for link in LINKS {
        let mut m = machine_on(
            link,
            "",
            "antr.probing_input_nbr = 2\nkenngr.mess_neg_flanke = 1",
        );
        // The simulated probe follows the axis settings: wired to input 2, active low.
        m.add_probe("Z", P).unwrap();
        let r = run(&mut m, DOWN);
        completed_quietly(&r, link);
        let value = r.measurements[Z].result.expect("latched").acs;
        assert!((value - P).abs() <= LATCH_TOL, "{link}: latched {value}");
        // Touch probe 2, negative edge: 0x60BD holds the value; the other three were not used.
        let read = |m: &mut Machine, index: u16| m.link_mut().read_object(Z, index, 0).unwrap();
        assert_ne!(read(&mut m, 0x60BD), 0, "{link}: 0x60BD");
        for index in [0x60BA, 0x60BB, 0x60BC] {
            assert_eq!(read(&mut m, index), 0, "{link}: {index:#06X}");
        }
    }
}

#[test]
fn new_parameters_win_and_each_old_one_beside_them_is_a_warning_naming_it() {
    for link in LINKS {
        // P-AXIS-00516 DRIVE, 00517 1, 00518 POS given: P-AXIS-00330, 00430, 00113 have no
        // effect — the drive latch on input 1, positive edge — and each is named once.
        let mut m = machine_on(
            link,
            "",
            "kenngr.measure.signal = \"DRIVE\"\nkenngr.measure.input = 1\n\
             kenngr.measure.edge = \"POS\"\nkenngr.meas_signal_fixed_stop = 1\n\
             antr.probing_input_nbr = 2\nkenngr.mess_neg_flanke = 1",
        );
        m.add_probe("Z", P).unwrap();
        let r = run(&mut m, DOWN);
        assert_eq!(r.status, RunStatus::Completed, "{link}: {:?}", r.messages());
        assert_eq!(
            r.message_ids(),
            vec![900047, 900047, 900047],
            "{link}: {:?}",
            r.messages()
        );
        for (msg, (old, new)) in r.messages().iter().zip([
            ("P-AXIS-00330", "P-AXIS-00516"),
            ("P-AXIS-00430", "P-AXIS-00517"),
            ("P-AXIS-00113", "P-AXIS-00518"),
        ]) {
            assert!(!msg.is_error(), "{link}: {msg}");
            assert!(
                msg.text.contains(old) && msg.text.contains(new) && msg.text.contains("axis Z"),
                "{link}: {msg}"
            );
        }
        let value = r.measurements[Z].result.expect("latched").acs;
        assert!((value - P).abs() <= LATCH_TOL, "{link}: latched {value}");
        assert_ne!(m.link_mut().read_object(Z, 0x60BA, 0).unwrap(), 0, "{link}");
    }
}

#[test]
fn two_old_sources_that_disagree_are_refused_naming_both() {
    let text = "[[axis]]\nname = \"Z\"\nkenngr.meas_signal_fixed_stop = 1\n\
                kenngr.probing_signal_via_plc = 1\n";
    let cfg = MachineConfig::parse(text, "two.toml").unwrap();
    let e = match Machine::new(&cfg) {
        Ok(_) => panic!("two disagreeing old sources were accepted"),
        Err(e) => e.to_string(),
    };
    for w in [
        "two.toml",
        "axis Z",
        "P-AXIS-00330",
        "P-AXIS-00257",
        "P-AXIS-00516",
    ] {
        assert!(e.contains(w), "{w:?} missing: {e}");
    }
}

/// A machine file in a temporary directory.
fn machine_file(text: &str) -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.toml");
    std::fs::write(&path, text).unwrap();
    let p = path.display().to_string();
    (dir, p)
}

#[test]
fn check_and_run_read_the_old_sercos_edge_alike() {
    // SERCOS §6.1 "P-AXIS-00518 (old: P-AXIS-00113)": with only P-AXIS-00113 = 1 the run arms
    // the negative edge and `check` expects it (S-0-0169 = 2 for probe 1 negative edge) — one
    // reading for both. The emulated AX5000 is set up for probe 1 positive edge (S-0-0169 = 1),
    // so `check` reports exactly that mismatch, naming P-AXIS-00113.
    let (_dir, file) = machine_file(
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\n\
         drive = \"sercos-ax5000\"\nkenngr.messachse = 1\nkenngr.mess_neg_flanke = 1\n",
    );
    let o = cli::fieldprobe(&["check", "--machine", &file]);
    let out = cli::stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}{}", cli::stderr(&o));
    assert!(
        out.contains("P-AXIS-00113 = 1") && out.contains("S-0-0169 = 2"),
        "{out}"
    );
    // The run reads the same edge: its channel arms the negative edge, which is what the
    // check compares the drive's S-0-0169 with.
    let cfg = MachineConfig::load(std::path::Path::new(&file)).unwrap();
    let m = Machine::new(&cfg).unwrap();
    let z = &m.channel().config().axes[Z].meas;
    assert_eq!(z.edge, fieldprobe::drive::ProbeEdge::Negative);
    // With P-AXIS-00518 = POS the machine file's P-AXIS-00113 has no effect: no edge
    // finding, and the check names it as a warning.
    let (_dir2, file) = machine_file(
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\n\
         drive = \"sercos-ax5000\"\nkenngr.messachse = 1\nkenngr.mess_neg_flanke = 1\n\
         kenngr.measure.edge = \"POS\"\n",
    );
    let o = cli::fieldprobe(&["check", "--machine", &file]);
    let out = cli::stdout(&o);
    assert!(
        out.contains("warning 900047: axis Z: P-AXIS-00113"),
        "{out}{}",
        cli::stderr(&o)
    );
    assert!(!out.contains("S-0-0169 = 2"), "{out}");
}

#[test]
fn run_on_the_command_line_warns_once_per_unused_parameter() {
    // Through the CLI on the default machine (P-AXIS-00516 DRIVE given): --set of the old
    // P-AXIS-00257 is named on stderr and the run goes on with the drive latch.
    let (_dir, prog) = machine_file(DOWN);
    let o = cli::fieldprobe(&[
        "run",
        &prog,
        "--set",
        "Z.P-AXIS-00257=1",
        "--probe-at",
        &format!("Z={P}"),
    ]);
    let err = cli::stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert_eq!(
        err.matches("warning 900047: axis Z: P-AXIS-00257").count(),
        1,
        "{err}"
    );
}
