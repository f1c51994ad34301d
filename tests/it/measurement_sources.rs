//! Probing-signal sources other than the drive latch, end to end on the simulated machine
//! (seed 004 §7.1 PLC, §7.2 EXT_PROBE_WITH_DRIVE with `#MEAS PREPARE`, §7.4
//! PLC_EXT_LATCH_CONTROL, §7.5 PLC_TIMESTAMP, §8.2.2 P-AXIS-00516 / 00518, §8.2.3 control units):
//! the simulated probe feeds the drives' inputs and a scripted PLC per axis
//! ([`fieldprobe::sim::plc::ScriptedPlc`]); the CNC evaluates the PLC interface.
//!
//! Expected values from closed-form bounds: a PLC-sampled value is the actual position of the
//! CNC cycle that sees the signal, so it lies behind the true crossing, on the far side in the
//! direction of motion, by at most v·(T + PLC period − T) (synchronous PLC: v·T); a DC timestamp
//! back-calculation is within a·T²/8 + 0.1 µm; an external latch or the drive latch gives the
//! crossing itself (0.1 µm increments).
//!
//! The trigger positions are chosen off the 0.1 mm grid of the set-points so that the crossing
//! does not coincide with a cycle boundary (where every source would read the exact value).

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunReport, RunStatus};
use fieldprobe::messages::CncMessage;
use fieldprobe::nc::exec::{Event, Executor, Step};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use fieldprobe::sim::plc::{AckScript, SimProbeState};
use fieldprobe::units::Nanos;
use std::process::Command;

/// Interpolation cycle of the default machine (s).
const T: f64 = 0.001;
/// 0.1 µm in mm: one drive increment.
const LATCH_TOL: f64 = 1e-4;
/// Half an increment: rounding of 0x6064 / the latch values.
const HALF_INC: f64 = 0.5e-4;
const Z: usize = 2;
/// Trigger position (ACS Z), off the set-point grid.
const P: f64 = 100.0371;

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

/// Latched Z of a completed run without messages.
#[track_caller]
fn latched(r: &RunReport) -> f64 {
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(r.messages().is_empty(), "{:?}", r.messages());
    assert!(r.measurements[Z].merf);
    r.measurements[Z].result.expect("Z latched").acs
}

/// `G100 Z20` from Z = 200 (moving down) at `feed` mm/min through the probe at [`P`].
fn down_program(feed: f64) -> String {
    format!("N10 G01 Z200 F6000\nN20 G100 Z20 F{feed}\nN30 M30\n")
}

/// A sampled value moving down: at or below the crossing, by at most `v·latency`.
#[track_caller]
fn behind_moving_down(what: &str, value: f64, v: f64, latency: f64) {
    assert!(
        value <= P + HALF_INC && value >= P - v * latency - HALF_INC,
        "{what}: {value} not in [{} − v·{latency}, {}] (v = {v})",
        P,
        P
    );
}

// ---------------------------------------------------------------------------------------------
// PLC (§7.1) and PLC_FIRST_EVENT
// ---------------------------------------------------------------------------------------------

#[test]
fn plc_value_is_the_actual_of_the_cycle_that_sees_the_signal() {
    // F6000 = 100 mm/s: v·T = 0.1 mm, far more than the latch resolution.
    let v = 100.0;
    let mut m = machine(&["Z.kenngr.measure.signal=PLC"]);
    m.add_probe("Z", P).unwrap();
    let value = latched(&run(&mut m, &down_program(6000.0)));
    behind_moving_down("PLC", value, v, T);
    assert!(
        (value - P).abs() > 1e-3,
        "{value}: a sampled value, not the crossing itself"
    );
}

#[test]
fn plc_with_a_slower_plc_is_behind_by_at_most_v_times_its_period() {
    // PLC period 4 ms (its cycles on the NC grid): the CNC sees the signal up to 4 ms late.
    let v = 100.0;
    let mut worst: f64 = 0.0;
    for p in [P, 100.5123, 101.2345, 99.8765] {
        let mut m = machine(&["Z.kenngr.measure.signal=PLC"]);
        m.add_probe("Z", p).unwrap();
        m.sim_plc_mut(Z).unwrap().config_mut().period = Nanos(4_000_000);
        let r = run(&mut m, &down_program(6000.0));
        let value = latched(&r);
        let behind = p - value;
        assert!(
            behind >= -HALF_INC && behind <= v * (T + 0.004) + HALF_INC,
            "probe {p}: {value}"
        );
        worst = worst.max(behind);
    }
    assert!(worst > v * T, "the 4 ms PLC shows: worst {worst}");
}

#[test]
fn plc_first_event_value_is_the_actual_of_the_cycle_that_sees_the_signal() {
    let mut m = machine(&["Z.kenngr.measure.signal=PLC_FIRST_EVENT"]);
    m.add_probe("Z", P).unwrap();
    let value = latched(&run(&mut m, &down_program(6000.0)));
    behind_moving_down("PLC_FIRST_EVENT", value, 100.0, T);
}

#[test]
fn plc_source_through_the_cli_set_key() {
    // meas1 with `--set Z.kenngr.measure.signal=PLC`, probe at P: V.A.MESS.Z within v·T behind
    // (F2000 = 33.3 mm/s).
    let o = Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args([
            "run",
            "examples/nc/seed004/meas1.nc",
            "--probe-at",
            &format!("Z={P}"),
            "--set",
            "Z.kenngr.measure.signal=PLC",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let out = String::from_utf8_lossy(&o.stdout);
    let first = out.lines().next().unwrap();
    let value: f64 = first.strip_prefix("V.A.MESS.Z=").unwrap().parse().unwrap();
    behind_moving_down("PLC via CLI", value, 2000.0 / 60.0, T);
}

#[test]
fn negative_edge_drive_and_plc() {
    // P-AXIS-00518 NEG: the probe is wired active-low; the drive latches and the PLC evaluates
    // the falling edge at the crossing.
    let mut m = machine(&["Z.kenngr.measure.edge=NEG"]);
    m.add_probe("Z", P).unwrap();
    close(
        "DRIVE NEG",
        latched(&run(&mut m, &down_program(6000.0))),
        P,
        LATCH_TOL,
    );
    let mut m = machine(&["Z.kenngr.measure.edge=NEG", "Z.kenngr.measure.signal=PLC"]);
    m.add_probe("Z", P).unwrap();
    let value = latched(&run(&mut m, &down_program(6000.0)));
    behind_moving_down("PLC NEG", value, 100.0, T);
}

// ---------------------------------------------------------------------------------------------
// PLC_TIMESTAMP (§7.5)
// ---------------------------------------------------------------------------------------------

#[test]
fn plc_timestamp_is_within_a_t2_over_8() {
    // Crossing in the constant-velocity part: a = 0 there, bound 0.1 µm; a = 1000 mm/s²
    // (P-AXIS-00004) covers the ramps: a·T²/8 = 0.125 µm.
    let bound = 1000.0 * T * T / 8.0 + 1e-4;
    let mut m = machine(&["Z.kenngr.measure.signal=PLC_TIMESTAMP"]);
    m.add_probe("Z", P).unwrap();
    close(
        "timestamp",
        latched(&run(&mut m, &down_program(6000.0))),
        P,
        bound,
    );
}

#[test]
fn plc_timestamp_does_not_depend_on_the_plc_period() {
    // The terminal timestamps the edge; a 4 ms PLC only delays the evaluation.
    let bound = 1000.0 * T * T / 8.0 + 1e-4;
    let mut m = machine(&["Z.kenngr.measure.signal=PLC_TIMESTAMP"]);
    m.add_probe("Z", P).unwrap();
    m.sim_plc_mut(Z).unwrap().config_mut().period = Nanos(4_000_000);
    // The CNC is told the PLC's cycle: the signal-consistency window widens accordingly.
    m.channel_mut().set_plc_cycle(Some(Nanos(4_000_000)));
    close(
        "timestamp",
        latched(&run(&mut m, &down_program(6000.0))),
        P,
        bound,
    );
}

// ---------------------------------------------------------------------------------------------
// Cycle-by-cycle runs for the handshakes
// ---------------------------------------------------------------------------------------------

/// One cycle of a traced run.
#[derive(Debug, Clone, Copy)]
struct Sample {
    z: f64,
    hw: Option<SimProbeState>,
    acks: u64,
}

struct Traced {
    exec: Executor,
    messages: Vec<CncMessage>,
    completed: bool,
    samples: Vec<Sample>,
    /// Sample index at which each block was handed to the channel.
    block_at: Vec<usize>,
}

fn run_traced(m: &mut Machine, src: &str, max_cycles: usize) -> Traced {
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
    let mut t = Traced {
        exec,
        messages: Vec::new(),
        completed: false,
        samples: Vec::new(),
        block_at: Vec::new(),
    };
    let mut out = Vec::new();
    loop {
        t.messages.extend(m.channel_mut().take_messages());
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                t.block_at.push(t.samples.len());
                let step = t.exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    t.completed = true;
                    break;
                }
            }
            _ => {
                if t.samples.len() >= max_cycles {
                    break;
                }
                m.step();
                let plc = m.sim_plc_mut(Z).map(|p| (p.hardware(), p.acknowledged()));
                t.samples.push(Sample {
                    z: m.channel().axes()[Z].command(),
                    hw: plc.map(|p| p.0),
                    acks: plc.map_or(0, |p| p.1),
                });
            }
        }
    }
    t.messages.extend(m.channel_mut().take_messages());
    t
}

/// The DISABLE task written at the end of the measuring block is acknowledged by the PLC in
/// its next cycle (a few more machine cycles after the program); `acks` tasks in all.
#[track_caller]
fn assert_disabled_after_the_run(m: &mut Machine, acks: u64) {
    for _ in 0..3 {
        m.step();
    }
    let plc = m.sim_plc_mut(Z).unwrap();
    assert_eq!(plc.hardware(), SimProbeState::Off);
    assert_eq!(plc.acknowledged(), acks);
    assert_eq!(plc.current_task(), None);
}

/// First sample index ≥ `from` at which Z's command differs from its value at `from`.
fn first_motion(t: &Traced, from: usize) -> Option<usize> {
    let z0 = t.samples[from.saturating_sub(1)].z;
    (from..t.samples.len()).find(|&i| t.samples[i].z != z0)
}

// ---------------------------------------------------------------------------------------------
// PLC_EXT_LATCH_CONTROL (§7.4)
// ---------------------------------------------------------------------------------------------

#[test]
fn ext_latch_control_waits_for_enable_and_uses_the_probing_position() {
    // The PLC acknowledges ENABLE 50 ms after reading it. The measuring block must not move
    // before; the value is the external hardware's probing_position (the crossing itself),
    // while the CNC cycle's actual value would be up to v·T = 0.1 mm off at 100 mm/s.
    let mut m = machine(&["Z.kenngr.measure.signal=PLC_EXT_LATCH_CONTROL"]);
    m.add_probe("Z", P).unwrap();
    m.sim_plc_mut(Z).unwrap().config_mut().ack = AckScript {
        prepare: Some(Nanos::ZERO),
        enable: Some(Nanos(50_000_000)),
        disable: Some(Nanos::ZERO),
    };
    let t = run_traced(&mut m, &down_program(6000.0), 100_000);
    assert!(t.completed, "{:?}", t.messages);
    assert!(t.messages.is_empty(), "{:?}", t.messages);
    // Blocks: N10 (index 0), N20 G100 (index 1).
    let start = t.block_at[1];
    let moved = first_motion(&t, start).expect("the block moved");
    assert!(
        moved - start >= 50,
        "moved {} cycles after the block start, before ENABLE was acknowledged",
        moved - start
    );
    assert!(moved - start <= 53, "{} cycles", moved - start);
    assert_eq!(t.samples[moved].hw, Some(SimProbeState::Enabled));
    let z = t.exec.result(Z).expect("latched");
    close("probing_position", z.acs, P, LATCH_TOL);
    // After the block the CNC sent DISABLE; the program does not wait for it, the PLC
    // acknowledges it in its next cycle.
    assert_eq!(t.samples[t.samples.len() - 1].acks, 1, "ENABLE");
    assert_disabled_after_the_run(&mut m, 2);
}

#[test]
fn a_plc_that_never_acknowledges_keeps_the_block_waiting() {
    // §7.2 "The interpolator does not move to the measuring block until the PLC acknowledges".
    let mut m = machine(&["Z.kenngr.measure.signal=PLC_EXT_LATCH_CONTROL"]);
    m.add_probe("Z", P).unwrap();
    m.sim_plc_mut(Z).unwrap().config_mut().ack = AckScript::never();
    let t = run_traced(&mut m, &down_program(6000.0), 5_000);
    let start = t.block_at[1];
    // Bounded look: 900 cycles (0.9 s) after the block start nothing has moved.
    assert!(t.samples.len() >= start + 900);
    for s in &t.samples[start..start + 900] {
        assert_eq!(s.z, 200.0, "the axis moved without the acknowledgement");
    }
    // It never completes. Either it is still waiting (no message) or the channel gave up with
    // an error (the project bounds the wait, `channel::measure::ARMING_TIMEOUT_CYCLES`), still
    // without motion and without publishing anything.
    assert!(!t.completed);
    assert!(t.samples[start..].iter().all(|s| s.z == 200.0));
    assert_eq!(t.exec.result(Z), None);
    let ids: Vec<u32> = t.messages.iter().map(|m| m.id).collect();
    assert!(ids.is_empty() || ids == [900043], "{:?}", t.messages);
    assert_eq!(m.sim_plc_mut(Z).unwrap().acknowledged(), 0);
}

// ---------------------------------------------------------------------------------------------
// EXT_PROBE_WITH_DRIVE with #MEAS PREPARE (§7.2)
// ---------------------------------------------------------------------------------------------

#[test]
fn ext_probe_with_drive_prepared_early_latches_in_the_drive() {
    // PREPARE is acknowledged 300 ms after it is read, during the 1.8 s positioning block N20;
    // when N30 starts the probe is prepared, ENABLE is acknowledged at once, the block moves
    // without waiting and the drive latches the crossing exactly (100 mm/s: a sampled value
    // would be up to 0.1 mm off).
    let mut m = machine(&["Z.kenngr.measure.signal=EXT_PROBE_WITH_DRIVE"]);
    m.add_probe("Z", P).unwrap();
    m.sim_plc_mut(Z).unwrap().config_mut().ack = AckScript {
        prepare: Some(Nanos(300_000_000)),
        enable: Some(Nanos::ZERO),
        disable: Some(Nanos::ZERO),
    };
    let t = run_traced(
        &mut m,
        "N10 #MEAS PREPARE [AXNR=3]\nN20 G01 Z200 F6000\nN30 G100 Z20 F6000\nN40 M30\n",
        100_000,
    );
    assert!(t.completed, "{:?}", t.messages);
    assert!(t.messages.is_empty(), "{:?}", t.messages);
    // Block indices: N10 0, N20 1, N30 2.
    let (n20, n30) = (t.block_at[1], t.block_at[2]);
    assert_eq!(
        t.samples[n20].hw,
        Some(SimProbeState::Off),
        "PREPARE not yet acknowledged"
    );
    assert_eq!(t.samples[n30 - 1].hw, Some(SimProbeState::Prepared));
    assert_eq!(t.samples[n30 - 1].acks, 1, "PREPARE acknowledged early");
    let moved = first_motion(&t, n30).expect("N30 moved");
    assert!(moved - n30 <= 5, "N30 waited {} cycles", moved - n30);
    assert_eq!(t.samples[moved].hw, Some(SimProbeState::Enabled));
    close(
        "drive latch",
        t.exec.result(Z).expect("latched").acs,
        P,
        LATCH_TOL,
    );
    // DISABLE after the block.
    assert_disabled_after_the_run(&mut m, 3);
}

#[test]
fn ext_probe_with_drive_without_prepare_enables_at_the_block_start() {
    let mut m = machine(&["Z.kenngr.measure.signal=EXT_PROBE_WITH_DRIVE"]);
    m.add_probe("Z", P).unwrap();
    m.sim_plc_mut(Z).unwrap().config_mut().ack = AckScript {
        prepare: Some(Nanos::ZERO),
        enable: Some(Nanos(20_000_000)),
        disable: Some(Nanos::ZERO),
    };
    let t = run_traced(&mut m, &down_program(6000.0), 100_000);
    assert!(t.completed && t.messages.is_empty(), "{:?}", t.messages);
    let start = t.block_at[1];
    let moved = first_motion(&t, start).unwrap();
    assert!(moved - start >= 20, "moved before ENABLE was acknowledged");
    close("drive latch", t.exec.result(Z).unwrap().acs, P, LATCH_TOL);
}

// ---------------------------------------------------------------------------------------------
// #MEAS [AXNR=.. SIGNAL=..]
// ---------------------------------------------------------------------------------------------

#[test]
fn meas_signal_override_to_drive() {
    // Configured PLC, switched to the drive latch in the program: the exact crossing.
    let mut m = machine(&["Z.kenngr.measure.signal=PLC"]);
    m.add_probe("Z", P).unwrap();
    let r = run(
        &mut m,
        &format!("N05 #MEAS [AXNR=3 SIGNAL=DRIVE]\n{}", down_program(6000.0)),
    );
    close("drive latch", latched(&r), P, LATCH_TOL);
}

#[test]
fn meas_signal_override_to_plc_sources() {
    for signal in ["PLC", "PLC_FIRST_EVENT"] {
        let mut m = machine(&[]);
        m.add_probe("Z", P).unwrap();
        let r = run(
            &mut m,
            &format!(
                "N05 #MEAS [AXNR=3 SIGNAL={signal}]\n{}",
                down_program(6000.0)
            ),
        );
        let value = latched(&r);
        behind_moving_down(signal, value, 100.0, T);
    }
    let mut m = machine(&[]);
    m.add_probe("Z", P).unwrap();
    let r = run(
        &mut m,
        &format!(
            "N05 #MEAS [AXNR=3 SIGNAL=PLC_TIMESTAMP]\n{}",
            down_program(6000.0)
        ),
    );
    close("timestamp", latched(&r), P, 1000.0 * T * T / 8.0 + 1e-4);
    let mut m = machine(&[]);
    m.add_probe("Z", P).unwrap();
    let r = run(
        &mut m,
        &format!(
            "N05 #MEAS [AXNR=3 SIGNAL=PLC_EXT_LATCH_CONTROL]\n{}",
            down_program(6000.0)
        ),
    );
    close("external latch", latched(&r), P, LATCH_TOL);
}

// ---------------------------------------------------------------------------------------------
// Drive latch settings: P-AXIS-00517 input, P-AXIS-00702 trigger source (§6.4)
// ---------------------------------------------------------------------------------------------

#[test]
fn probing_input_2_latches_with_touch_probe_2() {
    // P-AXIS-00517 = 2: the probe is wired to input 2, touch probe 2 latches it.
    let mut m = machine(&["Z.kenngr.measure.input=2"]);
    m.add_probe("Z", P).unwrap();
    close(
        "input 2",
        latched(&run(&mut m, &down_program(6000.0))),
        P,
        LATCH_TOL,
    );
    assert_ne!(
        m.link_mut().model_mut(Z).unwrap().read_object(0x60BC, 0),
        Ok(0),
        "touch probe 2 positive edge value 0x60BC"
    );
}

#[test]
fn a_probe_on_another_input_is_not_seen() {
    // Wired to input 1, measured on input 2 (#MEAS INPUT=2): no signal (type 1, no error).
    let mut m = machine(&[]);
    m.add_probe("Z", P).unwrap();
    let r = run(
        &mut m,
        &format!("N05 #MEAS [AXNR=3 INPUT=2]\n{}", down_program(6000.0)),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.measurements[Z].result, None);
    assert_eq!(m.channel().axes()[Z].command(), 20.0);
}

#[test]
fn trigger_source_cnc_and_drive_defined() {
    // P-AXIS-00702 CNC_DEFINED: the CNC writes the input (P-AXIS-00517 = 2) into 0x60D0:01 and
    // arms touch probe 1 on that source; DRIVE_DEFINED uses the drive's own 0x60D0 (default:
    // probe 1 ← input 1).
    let mut m = machine(&["Z.P-AXIS-00702=CNC_DEFINED", "Z.kenngr.measure.input=2"]);
    m.add_probe("Z", P).unwrap();
    close(
        "CNC_DEFINED",
        latched(&run(&mut m, &down_program(6000.0))),
        P,
        LATCH_TOL,
    );
    assert_eq!(
        m.link_mut().model_mut(Z).unwrap().read_object(0x60D0, 1),
        Ok(2)
    );
    let mut m = machine(&["Z.P-AXIS-00702=DRIVE_DEFINED"]);
    m.add_probe("Z", P).unwrap();
    close(
        "DRIVE_DEFINED",
        latched(&run(&mut m, &down_program(6000.0))),
        P,
        LATCH_TOL,
    );
}
