//! The measurement types of seed 004 §3 (table, P-CHAN-00057, `#MEAS MODE`, `V.G.MEAS_TYPE`)
//! and the rules of §4 (P-AXIS-00118, 2.5D: only moved axes must latch; `#CS`: all three main
//! axes must latch), §2 (independent axes with types 1, 2 and 7) and §7.3 / §8 (type 7: fixed
//! stop, P-CHAN-00266, P-AXIS-00777 → 51026 / 110757).
//!
//! Expected values come from the seed's table and text and from closed-form geometry; message
//! IDs: the seed's where it names one (51026, 110757), the project's otherwise (900040
//! measuring block not allowed, 900041 probing signal missing, 900042 fixed stop not detected).

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunReport, RunStatus};
use fieldprobe::messages::CncMessage;
use fieldprobe::nc::exec::{Event, Executor, Step};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

/// Interpolation cycle of the default machine (s).
const T: f64 = 0.001;
/// 0.1 µm in mm: one drive increment (the latch resolution).
const LATCH_TOL: f64 = 1e-4;
const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;

fn machine(sets: &[&str]) -> Machine {
    let mut cfg = MachineConfig::default_machine();
    for s in sets {
        cfg.apply_set(s)
            .unwrap_or_else(|e| panic!("--set {s}: {e}"));
    }
    Machine::new(&cfg).unwrap()
}

fn run(m: &mut Machine, src: &str) -> RunReport {
    m.run_program(&parse(src).unwrap(), &mut |_| {})
}

#[track_caller]
fn close(what: &str, actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: {actual} is not within {tol} of {expected}"
    );
}

#[track_caller]
fn completed(r: &RunReport) {
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(r.messages().is_empty(), "{:?}", r.messages());
}

/// The run aborted with exactly one error `id` in block `n`.
#[track_caller]
fn aborted_with(r: &RunReport, id: u32, n: u32) -> &CncMessage {
    assert_eq!(r.status, RunStatus::Aborted, "{:?}", r.messages());
    assert_eq!(r.message_ids(), vec![id], "{:?}", r.messages());
    let m = r.messages()[0];
    assert!(m.is_error());
    assert_eq!(m.block.and_then(|b| b.number), Some(n), "{m}");
    m
}

fn command(m: &Machine, axis: usize) -> f64 {
    m.channel().axes()[axis].command()
}

/// Rewire probe `probe` to the digital input 1 of the given devices only.
fn wire(m: &mut Machine, probe: usize, axes: &[usize]) {
    m.link_mut().plant_mut().unwrap().probe_surfaces_mut()[probe].wired =
        axes.iter().map(|a| (*a, 1)).collect();
}

/// The commands of axis `axis` after every cycle of a run driven cycle by cycle.
fn traced_commands(m: &mut Machine, src: &str, axis: usize) -> (Vec<f64>, Vec<CncMessage>) {
    let prog = parse(src).unwrap();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let names = m
        .channel()
        .axes()
        .iter()
        .map(|a| a.name().to_string())
        .collect();
    let mut exec = Executor::new(prog, names);
    exec.sync(m.channel());
    let (mut c, mut msgs, mut out) = (Vec::new(), Vec::new(), Vec::new());
    loop {
        msgs.extend(m.channel_mut().take_messages());
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                let step = exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    break;
                }
            }
            _ => {
                assert!(c.len() < 1_000_000);
                m.step();
                c.push(m.channel().axes()[axis].command());
            }
        }
    }
    msgs.extend(m.channel_mut().take_messages());
    (c, msgs)
}

/// Largest command velocity of a trace (mm/s).
fn peak_velocity(c: &[f64]) -> f64 {
    c.windows(2)
        .map(|w| ((w[1] - w[0]) / T).abs())
        .fold(0.0, f64::max)
}

// ---------------------------------------------------------------------------------------------
// Type 1
// ---------------------------------------------------------------------------------------------

#[test]
fn type_1_without_signal_is_no_error() {
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    completed(&r);
    assert_eq!(r.measurements[Z].result, None);
    assert!(!r.measurements[Z].merf);
    assert_eq!(command(&m, Z), 50.0);
}

#[test]
fn type_1_without_signal_with_p_chan_00176_is_an_error() {
    let mut m = machine(&["P-CHAN-00176=1"]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    let e = aborted_with(&r, 900041, 10);
    assert!(e.text.contains('Z'), "{e}");
    assert_eq!(r.measurements[Z].result, None);
}

#[test]
fn type_1_measures_and_stops() {
    let mut m = machine(&[]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    completed(&r);
    let z = r.measurements[Z];
    close("latched", z.result.unwrap().acs, 30.0, LATCH_TOL);
    close("MOFFS = 30 − 50", z.result.unwrap().moffs, -20.0, LATCH_TOL);
    assert!(z.merf);
    // The command leads the actual by v/kv = (1000/60)/40 mm and brakes with 1000 mm/s².
    let z = command(&m, Z);
    assert!(z > 30.0 && z < 31.0, "{z}");
}

// ---------------------------------------------------------------------------------------------
// Type 2
// ---------------------------------------------------------------------------------------------

#[test]
fn type_2_moves_exactly_one_axis() {
    let mut m = machine(&["P-CHAN-00057=2"]);
    m.add_probe("Z", 5.0).unwrap();
    let r = run(&mut m, "N10 G100 X10 Z10 F1000\nN20 M30\n");
    aborted_with(&r, 900040, 10);
    assert_eq!(
        (command(&m, X), command(&m, Z)),
        (0.0, 0.0),
        "nothing moved"
    );
}

#[test]
fn type_2_feed_is_p_axis_00215_not_f() {
    // P-AXIS-00215 = 20000 µm/s = 20 mm/s; F100 would be 1.67 mm/s.
    let mut m = machine(&["P-CHAN-00057=2", "Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let (c, msgs) = traced_commands(&mut m, "N10 G100 Z50 F100\nN20 M30\n", Z);
    assert!(msgs.is_empty(), "{msgs:?}");
    close("type 2 feed", peak_velocity(&c), 20.0, 1e-6);
    // Type 1 with the same block uses F.
    let mut m = machine(&["Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let (c1, _) = traced_commands(&mut m, "N10 G100 Z50 F100\nN20 M30\n", Z);
    close("type 1 feed", peak_velocity(&c1), 100.0 / 60.0, 1e-6);
    // Duration to the probe: 30 mm at 20 mm/s is 1.5 s (+ ramps and the lag of the actual).
    assert!(c.len() < 1_700, "type 2 took {} cycles", c.len());
    assert!(c1.len() > 18_000, "type 1 took {} cycles", c1.len());
}

#[test]
fn type_2_needs_no_f_word() {
    // Seed 004 §3: type 2 "Measurement feed is specified in the axis data list" (§8.2.2
    // P-AXIS-00215 kenngr.vb_messen). A program without any F measures at P-AXIS-00215 =
    // 20000 µm/s = 20 mm/s.
    let prog = "N10 #MEAS MODE[2]\nN20 G100 Z50\nN30 M30\n";
    let mut m = machine(&["Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let (c, msgs) = traced_commands(&mut m, prog, Z);
    assert!(msgs.is_empty(), "{msgs:?}");
    close("type 2 feed", peak_velocity(&c), 20.0, 1e-6);
    let mut m = machine(&["Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, prog);
    completed(&r);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        30.0,
        LATCH_TOL,
    );
    // The measuring block does not make up an F for later blocks: a G01 still needs one.
    let mut m = machine(&[]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(
        &mut m,
        "N10 #MEAS MODE[2]\nN20 G100 Z50\nN30 G01 Z0\nN40 M30\n",
    );
    aborted_with(&r, 900021, 30);
    // Type 1 measures with F: without one, the G100 is refused (900021).
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 G100 Z50\nN20 M30\n");
    aborted_with(&r, 900021, 10);
    // An independent axis under type 2 needs no FEED either.
    let mut m = machine(&["P-CHAN-00057=2", "X.P-AXIS-00215=20000"]);
    m.add_probe("X", 30.0).unwrap();
    let (c, msgs) = traced_commands(&mut m, "N10 X[INDP_SYN G100 G90 POS100]\nN20 M30\n", X);
    assert!(msgs.is_empty(), "{msgs:?}");
    close("independent type 2 feed", peak_velocity(&c), 20.0, 1e-6);
}

#[test]
fn old_p_axis_00114_is_the_type_2_overtravel_unless_p_axis_00467_is_set() {
    // Seed 004 §8.2.2, P-AXIS-00467 remarks: it "replaces the parameter P-AXIS-00114 … [which]
    // continues to be available … [and] only has an influence on measurement travels with
    // measurement type 2". P-AXIS-00114 = 20000 × 0.1 µm = 2 mm; probe at Z = 51.5, 1.5 mm past
    // the target 50.
    let probe_run = |sets: &[&str]| {
        let mut m = machine(sets);
        m.add_probe("Z", 51.5).unwrap();
        let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
        (r, command(&m, Z))
    };
    // Type 2: the old overtravel lets the run find the probe past the target (MERF 0: after it).
    let (r, _) = probe_run(&["P-CHAN-00057=2", "Z.P-AXIS-00114=20000"]);
    completed(&r);
    close(
        "latched in the overtravel",
        r.measurements[Z].result.unwrap().acs,
        51.5,
        LATCH_TOL,
    );
    assert!(!r.measurements[Z].merf);
    // Type 1: P-AXIS-00114 has no influence: the run ends at the target without a value.
    let (r, z) = probe_run(&["Z.P-AXIS-00114=20000"]);
    completed(&r);
    assert_eq!(r.measurements[Z].result, None);
    assert_eq!(z, 50.0);
    // Type 2 with P-AXIS-00467 given (1 mm): the new parameter replaces the old one; the run
    // ends at 51 without the signal (error 900041 of type 2).
    let (r, z) = probe_run(&[
        "P-CHAN-00057=2",
        "Z.P-AXIS-00114=20000",
        "Z.P-AXIS-00467=10000",
    ]);
    aborted_with(&r, 900041, 10);
    close("end of the P-AXIS-00467 overtravel", z, 51.0, 1e-9);
    // … also when it is given as 0.
    let (r, z) = probe_run(&["P-CHAN-00057=2", "Z.P-AXIS-00114=20000", "Z.P-AXIS-00467=0"]);
    aborted_with(&r, 900041, 10);
    close("at the target", z, 50.0, 1e-9);
}

#[test]
fn type_2_without_signal_is_an_error() {
    let mut m = machine(&["P-CHAN-00057=2"]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    aborted_with(&r, 900041, 10);
    assert_eq!(r.measurements[Z].result, None);
    close("at the target", command(&m, Z), 50.0, 1e-3);
}

#[test]

fn type_2_without_signal_stops_at_the_target() {
    let mut m = machine(&["P-CHAN-00057=2"]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    assert_eq!(r.message_ids(), vec![900041]);
    let z = command(&m, Z);
    assert!(z <= 50.0, "command {z} beyond the target 50");
}

#[test]
fn type_2_measures() {
    let mut m = machine(&["P-CHAN-00057=2"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    completed(&r);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        30.0,
        LATCH_TOL,
    );
    assert!(r.measurements[Z].merf);
}

// ---------------------------------------------------------------------------------------------
// Type 3
// ---------------------------------------------------------------------------------------------

#[test]
fn type_3_continues_to_the_target() {
    let mut m = machine(&["P-CHAN-00057=3"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    completed(&r);
    assert_eq!(command(&m, Z), 50.0, "went on to the target");
    let z = r.measurements[Z];
    close("latched", z.result.unwrap().acs, 30.0, LATCH_TOL);
    assert!(z.merf, "the signal came before the target");
}

#[test]
fn type_3_without_signal_is_no_error() {
    let mut m = machine(&["P-CHAN-00057=3"]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    completed(&r);
    assert!(!r.measurements[Z].merf);
}

// ---------------------------------------------------------------------------------------------
// Type 4
// ---------------------------------------------------------------------------------------------

/// X, Y, Z and a fourth linear axis U, all measurement axes on the drive latch.
fn four_axes(mtype: u8) -> Machine {
    let mut toml = format!("[channel]\nmesstyp = {mtype}\n");
    for a in ["X", "Y", "Z", "U"] {
        toml += &format!(
            "[[axis]]\nname = \"{a}\"\nkenngr.messachse = 1\nkenngr.measure.signal = \"DRIVE\"\nkenngr.measure.input = 1\nkenngr.measure.edge = \"POS\"\n"
        );
    }
    Machine::new(&MachineConfig::parse(&toml, "four.toml").unwrap()).unwrap()
}

#[test]
fn type_4_measures_with_the_main_axes_only() {
    let mut m = four_axes(4);
    let r = run(&mut m, "N10 G100 U10 F1000\nN20 M30\n");
    let e = aborted_with(&r, 900040, 10);
    assert!(e.text.contains('U'), "{e}");
    assert_eq!(command(&m, 3), 0.0);
    // X, Y, Z together are fine; so is U with type 1.
    let mut m = four_axes(4);
    m.add_probe("X", 5.0).unwrap();
    let r = run(&mut m, "N10 G100 X10 Y10 Z10 F1000\nN20 M30\n");
    completed(&r);
    for a in [X, Y, Z] {
        close(
            "on the diagonal",
            r.measurements[a].result.unwrap().acs,
            5.0,
            LATCH_TOL,
        );
    }
    let mut m = four_axes(1);
    let r = run(&mut m, "N10 G100 U10 F1000\nN20 M30\n");
    completed(&r);
}

// ---------------------------------------------------------------------------------------------
// Types 5 and 6: G210 / G310
// ---------------------------------------------------------------------------------------------

#[test]
fn type_5_measures_with_g210_only() {
    let mut m = machine(&["P-CHAN-00057=5"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G210 Z50 F1000\nN20 M30\n");
    completed(&r);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        30.0,
        LATCH_TOL,
    );
    let mut m = machine(&["P-CHAN-00057=5"]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    aborted_with(&r, 900040, 10);
    assert_eq!(command(&m, Z), 0.0);
    // And G210 does not belong to type 1.
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 G210 Z50 F1000\nN20 M30\n");
    aborted_with(&r, 900040, 10);
}

#[test]
fn type_6_needs_a_sercos_axis() {
    // The default machine has CiA 402 drives only.
    let mut m = machine(&["P-CHAN-00057=6"]);
    let r = run(&mut m, "N10 G310 Z50 F1000\nN20 M30\n");
    let e = aborted_with(&r, 900040, 10);
    assert!(e.text.contains("SERCOS"), "{e}");
    assert_eq!(command(&m, Z), 0.0);
    let mut m = machine(&["P-CHAN-00057=6"]);
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    aborted_with(&r, 900040, 10);
}

#[test]
fn type_6_measures_with_g310_when_z_is_on_a_sercos_drive() {
    let mut m = machine(&["P-CHAN-00057=6", "Z.drive=sercos-ax5000"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G310 Z50 F1000\nN20 M30\n");
    completed(&r);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        30.0,
        LATCH_TOL,
    );
}

// ---------------------------------------------------------------------------------------------
// #MEAS MODE, P-CHAN-00057, V.G.MEAS_TYPE
// ---------------------------------------------------------------------------------------------

#[test]
fn meas_mode_switches_and_returns_to_the_channel_default() {
    let mut m = machine(&["P-CHAN-00057=2"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(
        &mut m,
        "N05 F1000\n\
         N10 #MSG SYN[\"%d\", V.G.MEAS_TYPE]\n\
         N20 #MEAS MODE[3]\n\
         N30 #MSG SYN[\"%d\", V.G.MEAS_TYPE]\n\
         N40 G100 Z50\n\
         N50 #MSG SYN[\"%f\", V.A.ABS.Z]\n\
         N60 #MEAS MODE\n\
         N70 #MSG SYN[\"%d\", V.G.MEAS_TYPE]\n\
         N80 M30\n",
    );
    completed(&r);
    // Type 3 went on to the target 50 after latching 30.
    assert_eq!(r.output(), vec!["2", "3", "50.000000", "2"]);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        30.0,
        LATCH_TOL,
    );
}

#[test]
fn meas_mode_out_of_range_is_an_error() {
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 #MEAS MODE[8]\nN20 M30\n");
    aborted_with(&r, 900040, 10);
}

// ---------------------------------------------------------------------------------------------
// §4 P-AXIS-00118, 2.5D and #CS
// ---------------------------------------------------------------------------------------------

#[test]
fn a_moved_axis_must_be_a_measurement_axis() {
    let mut m = machine(&["X.P-AXIS-00118=0"]);
    let r = run(&mut m, "N10 G100 X10 Z10 F1000\nN20 M30\n");
    let e = aborted_with(&r, 900040, 10);
    assert_eq!(e.axis.as_deref(), Some("X"), "{e}");
    assert_eq!(command(&m, Z), 0.0);
    // An axis that is not moved need not be one.
    let mut m = machine(&["X.P-AXIS-00118=0"]);
    m.add_probe("Z", 5.0).unwrap();
    let r = run(&mut m, "N10 G100 Z10 F1000\nN20 M30\n");
    completed(&r);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        5.0,
        LATCH_TOL,
    );
}

#[test]
fn in_2_5d_only_the_moved_axes_must_latch() {
    // The probe is looped to X only. A block moving X alone is complete with X's latch.
    let mut m = machine(&[]);
    let p = m.add_probe("X", 4.0).unwrap();
    wire(&mut m, p, &[X]);
    let r = run(&mut m, "N10 G100 X10 F1000\nN20 M30\n");
    completed(&r);
    close("X", r.measurements[X].result.unwrap().acs, 4.0, LATCH_TOL);
    assert!(command(&m, X) < 5.0, "braked after the latch");
    // Moving X and Y, Y must latch as well: without its latch the signal is incomplete, the
    // block runs to its target and nothing is measured (type 1: no error) …
    let mut m = machine(&[]);
    let p = m.add_probe("X", 4.0).unwrap();
    wire(&mut m, p, &[X]);
    let r = run(&mut m, "N10 G100 X10 Y10 F1000\nN20 M30\n");
    completed(&r);
    assert_eq!((command(&m, X), command(&m, Y)), (10.0, 10.0));
    assert_eq!(r.measurements[X].result, None);
    assert!(!r.measurements[X].merf && !r.measurements[Y].merf);
    // … and with P-CHAN-00176 = 1 the missing Y is an error naming Y.
    let mut m = machine(&["P-CHAN-00176=1"]);
    let p = m.add_probe("X", 4.0).unwrap();
    wire(&mut m, p, &[X]);
    let r = run(&mut m, "N10 G100 X10 Y10 F1000\nN20 M30\n");
    let e = aborted_with(&r, 900041, 10);
    assert!(e.text.contains('Y'), "{e}");
}

/// Run `src` cycle by cycle; `watch` sees the machine after every interpolation cycle. Returns
/// the messages of the run.
fn run_watched(m: &mut Machine, src: &str, mut watch: impl FnMut(&mut Machine)) -> Vec<CncMessage> {
    let prog = parse(src).unwrap();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let names = m
        .channel()
        .axes()
        .iter()
        .map(|a| a.name().to_string())
        .collect();
    let mut exec = Executor::new(prog, names);
    exec.sync(m.channel());
    let (mut msgs, mut out, mut cycles) = (Vec::new(), Vec::new(), 0u32);
    loop {
        msgs.extend(m.channel_mut().take_messages());
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                let step = exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    break;
                }
            }
            _ => {
                cycles += 1;
                assert!(cycles < 1_000_000);
                m.step();
                watch(m);
            }
        }
    }
    msgs.extend(m.channel_mut().take_messages());
    msgs
}

#[test]
fn only_the_programmed_axes_arm_their_probes() {
    // Seed 004 §1: "The measuring function is initialised and activated for the axes programmed
    // in the measurement block". X, Y and Z are measurement axes (P-AXIS-00118 = 1) with the
    // probe looped to all three. `G100 X0 Z50` from X = 0 programs X (not moved) and Z; Y is not
    // programmed: its drive's touch-probe function 0x60B8 never gets an enable bit (bit 0 probe
    // 1, bit 8 probe 2, CiA 402) and its axis latch is never armed.
    use fieldprobe::drive::ProbeState;
    let mut m = machine(&[]);
    m.add_probe("Z", 30.0).unwrap();
    let mut enabled = [false; 3];
    let mut armed = [false; 3];
    let msgs = run_watched(&mut m, "N10 G100 X0 Z50 F1000\nN20 M30\n", |m| {
        for a in [X, Y, Z] {
            let function = m.link_mut().read_object(a, 0x60B8, 0).unwrap();
            enabled[a] |= function & 0x0101 != 0;
            armed[a] |= m.channel().axes()[a].probe_state() == ProbeState::Armed;
        }
    });
    assert!(msgs.is_empty(), "{msgs:?}");
    assert!(enabled[Z] && armed[Z], "the moved axis Z is armed");
    assert!(
        enabled[X] && armed[X],
        "X is programmed (not moved): armed as well"
    );
    assert!(
        !enabled[Y] && !armed[Y],
        "Y is not programmed: never armed (0x60B8 enabled: {}, armed: {})",
        enabled[Y],
        armed[Y]
    );
}

#[test]
fn with_cs_all_three_main_axes_must_latch() {
    // #CS ON with an offset only; G100 X10 moves X alone, but Y and Z must latch as well (§4
    // "irrespective of whether the axis was actually moved or not").
    let prog = "N10 #CS ON[0,0,5,0,0,0]\nN20 G100 X10 F1000\nN30 #CS OFF\nN40 M30\n";
    let mut m = machine(&[]);
    let p = m.add_probe("X", 4.0).unwrap();
    wire(&mut m, p, &[X, Y]);
    let r = run(&mut m, prog);
    completed(&r);
    assert_eq!(command(&m, X), 10.0, "no complete latch: no braking");
    assert!(!r.measurements[X].merf);
    // Looped to all three: complete, every main axis gets a value (Z in the CS: 0 − 5).
    let mut m = machine(&[]);
    m.add_probe("X", 4.0).unwrap();
    let r = run(&mut m, prog);
    completed(&r);
    assert!(command(&m, X) < 5.0);
    close("X", r.measurements[X].result.unwrap().mess, 4.0, LATCH_TOL);
    close("Y", r.measurements[Y].result.unwrap().mess, 0.0, LATCH_TOL);
    close("Z", r.measurements[Z].result.unwrap().mess, -5.0, LATCH_TOL);
    close(
        "Z ACS",
        r.measurements[Z].result.unwrap().acs,
        0.0,
        LATCH_TOL,
    );
    assert!(r.measurements[X].merf);
}

#[test]
fn with_cs_an_unmoved_main_axis_must_be_a_measurement_axis() {
    let mut m = machine(&["Z.P-AXIS-00118=0"]);
    let r = run(
        &mut m,
        "N10 #CS ON[0,0,5,0,0,0]\nN20 G100 X10 F1000\nN30 M30\n",
    );
    let e = aborted_with(&r, 900040, 20);
    assert_eq!(e.axis.as_deref(), Some("Z"), "{e}");
    // Without #CS the same block is fine.
    let mut m = machine(&["Z.P-AXIS-00118=0"]);
    completed(&run(&mut m, "N20 G100 X10 F1000\nN30 M30\n"));
}

// ---------------------------------------------------------------------------------------------
// Type 7: fixed stop
// ---------------------------------------------------------------------------------------------

/// Type 7 with fixed-stop detection on Z (P-AXIS-00516 FIXED_STOP, seed 004 §7.3): lag above
/// 1 mm (P-AXIS-00774 = 10000 × 0.1 µm) for 20 ms (P-AXIS-00775 = 20000 µs).
fn type_7(extra: &[&str]) -> Machine {
    let mut sets = vec![
        "P-CHAN-00057=7",
        "Z.kenngr.measure.signal=FIXED_STOP",
        "Z.P-AXIS-00774=10000",
        "Z.P-AXIS-00775=20000",
    ];
    sets.extend_from_slice(extra);
    machine(&sets)
}

#[test]
fn type_7_latches_the_wall_and_returns_to_it() {
    let mut m = type_7(&[]);
    m.add_fixed_stop("Z", 150.0).unwrap();
    let r = run(
        &mut m,
        "N10 G01 Z100 F3000\nN20 G100 Z200 F600\nN30 #MSG SYN[\"%f\", V.A.ABS.Z]\nN40 M30\n",
    );
    completed(&r);
    let z = r.measurements[Z];
    // The actual position pressed against the wall is the wall; it reads in 0.1 µm increments.
    close("latched", z.result.unwrap().acs, 150.0, LATCH_TOL);
    assert!(z.merf);
    // After detection the command goes back to the latched position (§7.3 "Process").
    let abs: f64 = r.output()[0].parse().unwrap();
    close("command after the block", abs, 150.0, LATCH_TOL);
    close("command now", command(&m, Z), 150.0, LATCH_TOL);
}

#[test]
fn type_7_without_a_stop_is_an_error_unless_p_chan_00266() {
    let mut m = type_7(&[]);
    let r = run(&mut m, "N10 G100 Z50 F600\nN20 M30\n");
    aborted_with(&r, 900042, 10);
    assert_eq!(r.measurements[Z].result, None);
    let mut m = type_7(&["P-CHAN-00266=1"]);
    let r = run(&mut m, "N10 G100 Z50 F600\nN20 M30\n");
    completed(&r);
    assert_eq!(r.measurements[Z].result, None);
    assert!(!r.measurements[Z].merf);
    assert_eq!(command(&m, Z), 50.0);
}

#[test]
fn type_7_needs_fixed_stop_as_the_signal_source_of_the_moved_axes() {
    // Seed 004 §7.3: for a measurement run to a fixed stop "the following entries must be
    // assigned in the axis parameter lists: P-AXIS-00516 … kenngr.measure.signal FIXED_STOP".
    // The default machine measures with DRIVE: the block is refused before anything moves, with
    // a message naming the axis, the parameter, its value and the way out.
    let sets = [
        "P-CHAN-00057=7",
        "Z.P-AXIS-00774=10000",
        "Z.P-AXIS-00775=20000",
    ];
    let mut m = machine(&sets);
    m.add_fixed_stop("Z", 150.0).unwrap();
    let r = run(&mut m, "N10 G100 Z200 F600\nN20 M30\n");
    let e = aborted_with(&r, 900040, 10);
    for w in [
        "axis Z",
        "P-AXIS-00516",
        "FIXED_STOP",
        "with DRIVE",
        "#MEAS [AXNR=3",
    ] {
        assert!(e.text.contains(w), "{w:?} missing: {e}");
    }
    assert_eq!(e.axis.as_deref(), Some("Z"));
    assert_eq!(command(&m, Z), 0.0, "nothing moved");

    // The program may select the source itself (#MEAS, §8.2.2 P-AXIS-00516). X is programmed
    // but not moved: it is not watched for the stop, so its DRIVE source does not matter; it
    // takes its actual position (0) when Z's stop is detected.
    let mut m = machine(&sets);
    m.add_fixed_stop("Z", 150.0).unwrap();
    let r = run(
        &mut m,
        "N05 #MEAS [AXNR=3 SIGNAL=FIXED_STOP]\nN10 G100 X0 Z200 F600\nN20 M30\n",
    );
    completed(&r);
    close(
        "Z at the wall",
        r.measurements[Z].result.unwrap().acs,
        150.0,
        LATCH_TOL,
    );
    close(
        "X where it stood",
        r.measurements[X].result.unwrap().acs,
        0.0,
        LATCH_TOL,
    );

    // A #MEAS override to another source is refused the same way and says where it came from.
    let mut m = machine(&[&sets[..], &["Z.kenngr.measure.signal=FIXED_STOP"]].concat());
    let r = run(
        &mut m,
        "N05 #MEAS [AXNR=3 SIGNAL=PLC]\nN10 G100 Z200 F600\nN20 M30\n",
    );
    let e = aborted_with(&r, 900040, 10);
    assert!(e.text.contains("with PLC (#MEAS SIGNAL)"), "{e}");
}

#[test]
fn type_7_without_a_criterion_names_axis_and_parameters_in_words() {
    // Defaults: P-AXIS-00774 = 0 (lag criterion off), P-AXIS-00778 < 0 → P-AXIS-00773 < 0
    // (position window off): Z has no fixed-stop criterion (seed 004 §8.2.2).
    let mut m = machine(&["P-CHAN-00057=7", "Z.kenngr.measure.signal=FIXED_STOP"]);
    let r = run(&mut m, "N10 G100 Z50 F600\nN20 M30\n");
    let e = aborted_with(&r, 900040, 10);
    for w in ["axis Z", "P-AXIS-00774", "P-AXIS-00778"] {
        assert!(e.text.contains(w), "{w:?} missing: {e}");
    }
    assert!(
        !e.text.contains("NoCriterion") && !e.text.contains('{'),
        "words, not debug output: {e}"
    );
    assert_eq!(e.axis.as_deref(), Some("Z"));
    assert_eq!(command(&m, Z), 0.0, "nothing moved");
}

#[test]

fn type_7_undetected_stop_goes_to_the_actual_position() {
    // §8.2.1 P-CHAN-00266: "If no error message is output when the fixed stop is not found, the
    // CNC still goes to the position of the current axis actual value at the end of the
    // measurement travel in order to eliminate a possible position lag (e.g. if the specified
    // position lag is not reached completely)". Wall at 150, target 158, lag limit 20 mm: the
    // axis is pressed against the wall with an 8 mm lag that never reaches the limit.
    let mut m = type_7(&["P-CHAN-00266=1", "Z.P-AXIS-00774=200000"]);
    m.add_fixed_stop("Z", 150.0).unwrap();
    let r = run(&mut m, "N10 G01 Z140 F3000\nN20 G100 Z158 F600\nN30 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.measurements[Z].result, None);
    close(
        "command at the actual position",
        command(&m, Z),
        150.0,
        LATCH_TOL,
    );
}

#[test]
fn p_axis_00777_above_1000_warns_at_start_and_aborts_the_measuring_travel() {
    let mut m = type_7(&["Z.P-AXIS-00777=1500"]);
    m.add_fixed_stop("Z", 150.0).unwrap();
    let r = run(&mut m, "N10 G01 Z100 F3000\nN20 G100 Z200 F600\nN30 M30\n");
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![110757, 51026], "{:?}", r.messages());
    let (w, e) = (r.messages()[0], r.messages()[1]);
    assert!(!w.is_error() && w.axis.as_deref() == Some("Z"), "{w}");
    assert!(
        e.is_error() && e.block.and_then(|b| b.number) == Some(20),
        "{e}"
    );
    assert_eq!(command(&m, Z), 100.0, "the measuring travel did not start");
    // 110757 is a controller-start warning: not repeated by the next program.
    let r = run(&mut m, "N10 G100 Z200 F600\nN20 M30\n");
    assert_eq!(r.message_ids(), vec![51026]);
    // 1000 is allowed. Detection then starts only at the end of the block, so the lag reaches
    // 50 mm: the drive's following-error window must be open, as a fixed-stop program does.
    let mut m = type_7(&["Z.P-AXIS-00777=1000"]);
    m.add_fixed_stop("Z", 150.0).unwrap();
    m.link_mut()
        .model_mut(Z)
        .unwrap()
        .write_object(0x6065, 0, 0xFFFF_FFFF)
        .unwrap();
    let r = run(&mut m, "N10 G01 Z100 F3000\nN20 G100 Z200 F600\nN30 M30\n");
    assert_eq!(r.message_ids(), Vec::<u32>::new());
}

/// Type 7, wall at Z = 120, `G100 Z200` from Z = 100: the wall is reached after 20 mm. With
/// 300 ‰ of the 100 mm block detection is active only after 30 mm: the command goes on to
/// (at least) 130 while the actual stays at the wall, then the stop is detected at the wall.
/// Returns the largest command before the end and the final command.
fn per_mille_run(sets: &[&str]) -> (f64, f64) {
    let mut m = type_7(sets);
    m.add_fixed_stop("Z", 120.0).unwrap();
    let (c, msgs) = traced_commands(
        &mut m,
        "N10 G01 Z100 F3000\nN20 G100 Z200 F600\nN30 M30\n",
        Z,
    );
    assert!(msgs.is_empty(), "{msgs:?}");
    let peak = c.iter().cloned().fold(f64::MIN, f64::max);
    (peak, c[c.len() - 1])
}

#[test]
fn p_axis_00777_delays_the_detection() {
    // Every measurement axis of the channel with 300 ‰.
    let (peak, end) = per_mille_run(&[
        "X.P-AXIS-00777=300",
        "Y.P-AXIS-00777=300",
        "Z.P-AXIS-00777=300",
    ]);
    assert!(
        peak >= 130.0,
        "command reached only {peak} before detection"
    );
    close("back at the wall", end, 120.0, LATCH_TOL);
    // Without it the stop is detected right after the lag exceeds 1 mm for 20 ms.
    let (peak, end) = per_mille_run(&[]);
    assert!(peak < 122.0, "{peak}");
    close("back at the wall", end, 120.0, LATCH_TOL);
}

#[test]

fn p_axis_00777_of_the_moved_axis_delays_the_detection() {
    // Seed 004 §8.2.2 P-AXIS-00776 / 00777: "the smallest block motion path of all axes
    // involved in the measurement". Only Z moves (and is monitored); X and Y are not involved.
    let (peak, end) = per_mille_run(&["Z.P-AXIS-00777=300"]);
    assert!(
        peak >= 130.0,
        "command reached only {peak} before detection"
    );
    close("back at the wall", end, 120.0, LATCH_TOL);
}

// ---------------------------------------------------------------------------------------------
// Independent axes (§2, types 1, 2, 7)
// ---------------------------------------------------------------------------------------------

#[test]
fn independent_axis_type_1_latches_and_stops() {
    let mut m = machine(&[]);
    m.add_probe("X", 30.0).unwrap();
    let r = run(&mut m, "N10 X[INDP_SYN G100 G90 POS100 FEED500]\nN20 M30\n");
    completed(&r);
    close("X", r.measurements[X].result.unwrap().acs, 30.0, LATCH_TOL);
    assert!(r.measurements[X].merf);
    let x = command(&m, X);
    assert!(x > 30.0 && x < 31.0, "{x}");
}

#[test]
fn independent_axes_latch_and_stop_each_on_its_own() {
    // Two probes, each looped to one axis only: X's at X = 30, Y's at Y = 80. Each axis must
    // latch its own probe and stop on its own signal.
    let mut m = machine(&[]);
    let px = m.add_probe("X", 30.0).unwrap();
    let py = m.add_probe("Y", 80.0).unwrap();
    wire(&mut m, px, &[X]);
    wire(&mut m, py, &[Y]);
    let r = run(
        &mut m,
        "N10 X[INDP_SYN G100 G90 POS100 FEED500] Y[INDP_SYN G100 G90 POS100 FEED1000]\nN20 M30\n",
    );
    completed(&r);
    let x = r.measurements[X].result.expect("X latched");
    let y = r.measurements[Y].result.expect("Y latched");
    close("X", x.acs, 30.0, LATCH_TOL);
    close("Y", y.acs, 80.0, LATCH_TOL);
    assert!(r.measurements[X].merf && r.measurements[Y].merf);
    assert!(command(&m, X) < 31.0 && command(&m, Y) < 81.0);
}

#[test]

fn independent_measurement_beside_a_path_measurement() {
    // §2: "An independent measurement run is also possible in parallel to a path motion of a
    // G100 measurement run." Z measures on the path (probe at Z = 20, looped to Z only), X as an
    // independent axis (probe at X = 30, looped to X only).
    let mut m = machine(&[]);
    let pz = m.add_probe("Z", 20.0).unwrap();
    let px = m.add_probe("X", 30.0).unwrap();
    wire(&mut m, pz, &[Z]);
    wire(&mut m, px, &[X]);
    let r = run(
        &mut m,
        "N10 G100 Z50 F1000 X[INDP_SYN G100 G90 POS100 FEED500]\nN20 M30\n",
    );
    completed(&r);
    close(
        "Z",
        r.measurements[Z].result.expect("Z").acs,
        20.0,
        LATCH_TOL,
    );
    close(
        "X",
        r.measurements[X].result.expect("X").acs,
        30.0,
        LATCH_TOL,
    );
}

#[test]
fn independent_axis_type_2_uses_p_axis_00215_and_needs_the_signal() {
    // FEED500 would be 8.3 mm/s; P-AXIS-00215 = 20 mm/s.
    let mut m = machine(&["P-CHAN-00057=2", "X.P-AXIS-00215=20000"]);
    m.add_probe("X", 30.0).unwrap();
    let (c, msgs) = traced_commands(
        &mut m,
        "N10 X[INDP_SYN G100 G90 POS100 FEED500]\nN20 M30\n",
        X,
    );
    assert!(msgs.is_empty(), "{msgs:?}");
    close("type 2 feed", peak_velocity(&c), 20.0, 1e-6);
    let mut m = machine(&["P-CHAN-00057=2"]);
    let r = run(&mut m, "N10 X[INDP_SYN G100 G90 POS10 FEED500]\nN20 M30\n");
    aborted_with(&r, 900041, 10);
}

#[test]
fn independent_axis_type_7_latches_the_wall() {
    let mut m = machine(&[
        "P-CHAN-00057=7",
        "X.kenngr.measure.signal=FIXED_STOP",
        "X.P-AXIS-00774=10000",
        "X.P-AXIS-00775=20000",
    ]);
    m.add_fixed_stop("X", 150.0).unwrap();
    let r = run(
        &mut m,
        "N10 G01 X100 F3000\nN20 X[INDP_SYN G100 G90 POS200 FEED600]\nN30 M30\n",
    );
    completed(&r);
    close("X", r.measurements[X].result.unwrap().acs, 150.0, LATCH_TOL);
    close("back at the wall", command(&m, X), 150.0, LATCH_TOL);
}

#[test]
fn independent_axes_are_refused_for_type_3() {
    let mut m = machine(&["P-CHAN-00057=3"]);
    let r = run(&mut m, "N10 X[INDP_SYN G100 G90 POS100 FEED500]\nN20 M30\n");
    aborted_with(&r, 900040, 10);
    assert_eq!(command(&m, X), 0.0);
}

// ---------------------------------------------------------------------------------------------
// §5 results across blocks, G101 without a measured value
// ---------------------------------------------------------------------------------------------

#[test]
fn values_of_non_programmed_axes_are_retained() {
    // §5 Notice: "the values from the previous measurement are retained for non-programmed
    // axes". Probe A at X = 4 (N10 on the diagonal latches X = Y = 4), probe B at Y = 20 (N30
    // moves Y alone and latches Y = 20; X is not programmed and keeps 4).
    let mut m = machine(&[]);
    m.add_probe("X", 4.0).unwrap();
    m.add_probe("Y", 20.0).unwrap();
    let r = run(
        &mut m,
        "N10 G100 X10 Y10 F1000\n\
         N20 #MSG SYN[\"%f %d %f %d\", V.A.MESS.X, V.A.MERF.X, V.A.MESS.Y, V.A.MERF.Y]\n\
         N30 G100 Y30 F1000\n\
         N40 #MSG SYN[\"%f %d %f %d\", V.A.MESS.X, V.A.MERF.X, V.A.MESS.Y, V.A.MERF.Y]\n\
         N50 M30\n",
    );
    completed(&r);
    assert_eq!(
        r.output(),
        vec!["4.000000 1 4.000000 1", "4.000000 1 20.000000 1",]
    );
}

#[test]
fn g101_without_a_measured_value_is_an_error() {
    // §5: "An error message is output if no measured values were detected beforehand."
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 G101 Z1\nN20 M30\n");
    let e = aborted_with(&r, 900045, 10);
    assert!(e.text.contains('Z'), "{e}");
    // After a measuring block without signal (type 1, no error) there is no value either.
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 G100 Z10 F1000\nN20 G101 Z1\nN30 M30\n");
    aborted_with(&r, 900045, 20);
}

#[test]
fn meas_type_keyword_sets_the_type_as_meas_mode_does() {
    // Seed 004 §8.2.1, P-CHAN-00057 remarks: "This measurement type can be changed at any time
    // in the NC program with #MEAS MODE or #MEAS [TYPE]." `#MEAS [TYPE=2]` is type 2: no F
    // needed, the measuring feed of P-AXIS-00215 (20000 µm/s = 20 mm/s), V.G.MEAS_TYPE = 2.
    let prog = "N10 #MEAS [TYPE=2]\nN20 G100 Z50\nN30 M30\n";
    let mut m = machine(&["Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let (c, msgs) = traced_commands(&mut m, prog, Z);
    assert!(msgs.is_empty(), "{msgs:?}");
    close("type 2 feed", peak_velocity(&c), 20.0, 1e-6);
    let mut m = machine(&["Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(
        &mut m,
        // An expression; type 2 measures without F (type 1 would refuse the G100, 900021).
        "N10 #MEAS [TYPE=1+1]\nN20 G100 Z50\nN30 M30\n",
    );
    completed(&r);
    close(
        "latched",
        r.measurements[Z].result.unwrap().acs,
        30.0,
        LATCH_TOL,
    );
    // Beside an axis's signal settings, TYPE sets the channel's type too.
    let mut m = machine(&["Z.P-AXIS-00215=20000"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(
        &mut m,
        "N10 #MEAS [AXNR=3 EDGE=POS TYPE=2]\nN20 G100 Z50\nN30 M30\n",
    );
    completed(&r);
    // Out of range, and a signal setting without an axis: refused.
    let mut m = machine(&[]);
    let r = run(&mut m, "N10 #MEAS [TYPE=8]\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Aborted, "{:?}", r.messages());
    assert!(parse("#MEAS [TYPE=2 EDGE=POS]\n").is_err());
    assert!(parse("#MEAS [TYPE=PLC]\n").is_err());
}

// ---------------------------------------------------------------------------------------------
// Issue 27 item 6: V.A.PROG after an interrupted G100, INDP_ASYN beside the path, 900044 units
// ---------------------------------------------------------------------------------------------

#[test]
fn v_a_prog_after_an_interrupted_g100_is_the_target_point_of_the_moffs_identity() {
    // Seed 004 §5, meas1: probe at Z = 100, `G100 Z20` → "V.A.MOFFS.Z = 80.0", and the table's
    // identity "MOFFS.X = V.A.MESS.X - V.A.PROG.X - Zero Shifts - Tool Offset" (no shifts, no
    // tool): V.A.PROG.Z reads the target point 20 although the axis stopped near 100. The next
    // incremental block starts where the axis stopped; after it V.A.PROG is that block's end.
    let mut m = machine(&[]);
    m.add_probe("Z", 100.0).unwrap();
    let r = run(
        &mut m,
        "N05 #MEAS MODE[1]\nN10 G01 G90 Z200 F2000\nN20 G100 Z20 F2000\n\
         N30 #MSG SYN[\"%f %f %f\", V.A.MESS.Z, V.A.PROG.Z, V.A.MOFFS.Z]\n\
         N35 #MSG SYN[\"%f\", V.A.ABS.Z]\n\
         N40 G91 G01 Z10 F1000\nN50 #MSG SYN[\"%f %f\", V.A.ABS.Z, V.A.PROG.Z]\nN60 M30\n",
    );
    completed(&r);
    let out = r.output();
    assert_eq!(out[0], "100.000000 20.000000 80.000000");
    let stop: f64 = out[1].parse().unwrap();
    assert!(stop < 100.0 && stop > 99.0, "stopped at {stop}");
    let after: Vec<f64> = out[2].split(' ').map(|v| v.parse().unwrap()).collect();
    close(
        "G91 Z10 from the stop position",
        after[0],
        stop + 10.0,
        1e-6,
    );
    close("V.A.PROG after the next block", after[1], stop + 10.0, 1e-6);
}

#[test]
fn an_indp_asyn_axis_goes_on_beside_a_following_path_block() {
    // Seed 004 §2: "An independent measurement run is also possible in parallel to a path motion
    // of a G100 measurement run"; P-CHAN-00057: "a measurement travel is also possible with
    // independent axes". X measures independently (probe at X = 60, looped to X only) while
    // N20 moves Y on the path: N20 runs and ends while X is still travelling, X latches 60.
    let mut m = machine(&[]);
    let px = m.add_probe("X", 60.0).unwrap();
    wire(&mut m, px, &[X]);
    let r = run(
        &mut m,
        "N10 X[INDP_ASYN G100 G90 POS100 FEED600]\nN20 G01 Y50 F6000\n\
         N30 #MSG SYN[\"%f %f\", V.A.ABS.X, V.A.ABS.Y]\nN40 M30\n",
    );
    completed(&r);
    let at_n30: Vec<f64> = r.output()[0]
        .split(' ')
        .map(|v| v.parse().unwrap())
        .collect();
    // Y at its end (50 mm at 100 mm/s: ~0.5 s), X still on its way (10 mm/s: 6 s to X = 60).
    close("Y after N20", at_n30[1], 50.0, 1e-9);
    assert!(
        at_n30[0] > 0.0 && at_n30[0] < 60.0,
        "X at N30: {}",
        at_n30[0]
    );
    close(
        "X latched beside the path",
        r.measurements[X].result.expect("X latched").acs,
        60.0,
        LATCH_TOL,
    );
    // A path block that programs the moving axis is still refused.
    let mut m = machine(&[]);
    let r = run(
        &mut m,
        "N10 X[INDP_ASYN G90 POS100 FEED600]\nN20 G01 X50 F6000\nN30 M30\n",
    );
    let e = aborted_with(&r, 900001, 20);
    assert!(e.text.contains("independent"), "{e}");
}

#[test]
fn feed_reduction_warning_on_a_rotary_axis_is_in_degrees_per_minute() {
    // Type 2 on rotary axis A: the feed is P-AXIS-00215 (seed 004 §8.2.2 dimension "R,S:
    // 0.001°/s"; default 16666 → 999.96 °/min) and the stroke P-AXIS-00086 ("R: 0.0001°"):
    // 0.01° cannot hold it, so it is reduced with 900044 — in °/min.
    let toml = "[channel]\nmesstyp = 2\n[[axis]]\nname = \"X\"\n[[axis]]\nname = \"A\"\n\
                kenngr.achs_typ = \"ACHSTYP_ROTATOR\"\nkenngr.messachse = 1\n\
                kenngr.hub_messtaster = 100\n";
    let cfg = MachineConfig::parse(toml, "rot.toml").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    m.add_probe("A", 30.0).unwrap();
    let r = run(&mut m, "N10 G100 A50\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let w: Vec<_> = r
        .messages()
        .into_iter()
        .filter(|x| x.id == 900044)
        .collect();
    assert_eq!(w.len(), 1, "{:?}", r.messages());
    assert!(
        w[0].text.contains("from 999.960 to") && w[0].text.contains("°/min"),
        "{}",
        w[0].text
    );
    assert!(!w[0].text.contains("mm/min"), "{}", w[0].text);
    // A linear axis keeps mm/min.
    let mut m = machine(&["P-CHAN-00057=2", "Z.P-AXIS-00086=100"]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G100 Z50\nN20 M30\n");
    let w: Vec<_> = r
        .messages()
        .into_iter()
        .filter(|x| x.id == 900044)
        .collect();
    assert_eq!(w.len(), 1, "{:?}", r.messages());
    assert!(w[0].text.contains("mm/min"), "{}", w[0].text);
}
