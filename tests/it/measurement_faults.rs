//! Faults during measuring runs: a drive fault, a lost process-data exchange, a latch unit that
//! cannot be armed or drops its stored value, and re-arming between measuring blocks. In every
//! case the axes stop, an error is reported and no measurement result is published: `V.A.MERF`
//! stays 0, or the values of the previous measurement are retained (seed 004 §5 Notice), and a
//! latch of an earlier block is never reported as new.
//!
//! Message IDs (project range, src/messages.rs): 900010 drive fault, 900012 lost exchange,
//! 900043 latch source failed, 900041 probing signal missing (type 2).

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunReport, RunStatus};
use fieldprobe::messages::CncMessage;
use fieldprobe::nc::exec::{Event, Executor, Step};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

/// 0.1 µm in mm: one drive increment (the latch resolution).
const LATCH_TOL: f64 = 1e-4;
const Z: usize = 2;

fn config(sets: &[&str]) -> MachineConfig {
    let mut cfg = MachineConfig::default_machine();
    for s in sets {
        cfg.apply_set(s)
            .unwrap_or_else(|e| panic!("--set {s}: {e}"));
    }
    cfg
}

fn machine(sets: &[&str]) -> Machine {
    Machine::new(&config(sets)).unwrap()
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

/// A run driven cycle by cycle; `each(machine, block, cycle_in_block)` runs after every cycle,
/// with the index of the block last handed to the channel (0-based) and the cycles since.
struct Traced {
    exec: Executor,
    messages: Vec<CncMessage>,
    completed: bool,
    z: Vec<f64>,
}

impl Traced {
    fn ids(&self) -> Vec<u32> {
        self.messages.iter().map(|m| m.id).collect()
    }
}

fn run_traced(
    m: &mut Machine,
    src: &str,
    mut each: impl FnMut(&mut Machine, usize, usize),
) -> Traced {
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
    let (mut messages, mut z, mut out) = (Vec::new(), Vec::new(), Vec::new());
    let (mut block, mut since, mut completed) = (0usize, 0usize, false);
    let mut started = false;
    loop {
        messages.extend(m.channel_mut().take_messages());
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                if started {
                    block += 1;
                }
                started = true;
                since = 0;
                let step = exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    completed = true;
                    break;
                }
            }
            _ => {
                assert!(z.len() < 1_000_000);
                m.step();
                since += 1;
                z.push(m.channel().axes()[Z].command());
                each(m, block, since);
            }
        }
    }
    messages.extend(m.channel_mut().take_messages());
    Traced {
        exec,
        messages,
        completed,
        z,
    }
}

/// After an abort the axes stand still: more cycles do not change the set-points of the drives
/// that follow them (their actual positions settle onto those set-points with the loop's lag),
/// and a drive in FAULT does not move at all (its set-point tracks its actual position).
#[track_caller]
fn standstill(m: &mut Machine) {
    assert_eq!(m.channel().state(), ChannelState::Aborted);
    let before: Vec<(bool, f64, f64)> = m
        .channel()
        .axes()
        .iter()
        .map(|a| (a.is_operational(), a.command(), a.actual()))
        .collect();
    for _ in 0..200 {
        m.step();
    }
    for (a, (operational, command, actual)) in m.channel().axes().iter().zip(before) {
        if operational {
            assert_eq!(
                a.command(),
                command,
                "axis {}: the set-point moves",
                a.name()
            );
            assert!(
                (a.actual() - command).abs() <= (actual - command).abs() + 1e-9,
                "axis {}: the actual moves away from the set-point",
                a.name()
            );
        } else {
            assert_eq!(
                a.actual(),
                actual,
                "axis {}: a faulted drive moves",
                a.name()
            );
        }
    }
    assert_eq!(m.channel().state(), ChannelState::Aborted);
}

/// Two measuring blocks: N10 latches the probe at 30 (stops just past it), N20 goes on upwards
/// towards 100 where a second probe at 80 would be crossed. Block indices: N10 0, N20 1.
const TWO_BLOCKS: &str = "N10 G100 Z50 F3000\nN20 G100 Z100 F3000\nN30 M30\n";

fn two_probe_machine(cfg: &MachineConfig) -> Machine {
    let mut m = Machine::new(cfg).unwrap();
    m.add_probe("Z", 30.0).unwrap();
    m.add_probe("Z", 80.0).unwrap();
    m
}

/// The first block's result is still there and nothing of the second was published.
#[track_caller]
fn first_result_retained(t: &Traced) {
    let z = t.exec.result(Z).expect("the first measurement is retained");
    close("retained value", z.acs, 30.0, LATCH_TOL);
    assert!(t.exec.merf(Z), "MERF of the first measurement");
}

// ---------------------------------------------------------------------------------------------
// Drive fault
// ---------------------------------------------------------------------------------------------

#[test]
fn drive_fault_during_a_measuring_run_publishes_nothing() {
    let mut m = machine(&[]);
    m.add_probe("Z", 80.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", |m, _, k| {
        if k == 300 {
            m.link_mut().model_mut(Z).unwrap().inject_fault(0x8611);
        }
    });
    assert!(!t.completed);
    assert_eq!(t.ids(), vec![900010], "{:?}", t.messages);
    assert_eq!(t.messages[0].block.and_then(|b| b.number), Some(10));
    assert_eq!(t.exec.result(Z), None);
    assert!(!t.exec.merf(Z));
    let z = t.z[t.z.len() - 1];
    assert!(z < 80.0, "stopped at {z}, before the probe");
    standstill(&mut m);
}

#[test]
fn drive_fault_in_a_second_measuring_block_keeps_the_first_result() {
    let mut m = two_probe_machine(&config(&[]));
    let t = run_traced(&mut m, TWO_BLOCKS, |m, block, k| {
        if block == 1 && k == 200 {
            m.link_mut().model_mut(Z).unwrap().inject_fault(0x8611);
        }
    });
    assert_eq!(t.ids(), vec![900010], "{:?}", t.messages);
    assert_eq!(t.messages[0].block.and_then(|b| b.number), Some(20));
    first_result_retained(&t);
    assert!(t.z[t.z.len() - 1] < 80.0);
    standstill(&mut m);
}

#[test]
fn drive_fault_of_another_axis_stops_the_measuring_run() {
    // X is not moved by the block but is a measurement axis of the channel.
    let mut m = machine(&[]);
    m.add_probe("Z", 80.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", |m, _, k| {
        if k == 300 {
            m.link_mut().model_mut(0).unwrap().inject_fault(0x8611);
        }
    });
    assert_eq!(t.ids(), vec![900010], "{:?}", t.messages);
    assert_eq!(t.exec.result(Z), None);
    assert!(t.z[t.z.len() - 1] < 80.0);
}

// ---------------------------------------------------------------------------------------------
// Lost exchange
// ---------------------------------------------------------------------------------------------

#[test]
fn lost_exchange_during_a_measuring_run_publishes_nothing() {
    let mut m = machine(&[]);
    m.add_probe("Z", 80.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", |m, _, k| {
        if k == 300 {
            let next = m.link_mut().exchanges();
            // One more than max_lost_cycles (3) in a row: the link is lost.
            for j in 0..4 {
                m.link_mut().lose_exchange_at(next + j);
            }
        }
    });
    assert_eq!(t.ids(), vec![900012], "{:?}", t.messages);
    assert_eq!(t.messages[0].block.and_then(|b| b.number), Some(10));
    assert_eq!(t.exec.result(Z), None);
    assert!(!t.exec.merf(Z));
    assert!(t.z[t.z.len() - 1] < 80.0);
    standstill(&mut m);
}

#[test]
fn lost_exchange_in_a_second_measuring_block_keeps_the_first_result() {
    let mut m = two_probe_machine(&config(&[]));
    let t = run_traced(&mut m, TWO_BLOCKS, |m, block, k| {
        if block == 1 && k == 200 {
            let next = m.link_mut().exchanges();
            // One more than max_lost_cycles (3) in a row: the link is lost.
            for j in 0..4 {
                m.link_mut().lose_exchange_at(next + j);
            }
        }
    });
    assert_eq!(t.ids(), vec![900012], "{:?}", t.messages);
    first_result_retained(&t);
    standstill(&mut m);
}

#[test]
fn lost_exchange_through_run_program() {
    // The same with the machine's own loop: exchange 500 is inside the 2 s measuring block.
    let mut m = machine(&[]);
    m.add_probe("Z", 80.0).unwrap();
    // One more than max_lost_cycles (3) in a row: the link is lost.
    for j in 0..4 {
        m.link_mut().lose_exchange_at(500 + j);
    }
    let r = run(&mut m, "N10 G100 Z100 F3000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900012]);
    assert_eq!(r.measurements[Z].result, None);
    assert!(!r.measurements[Z].merf);
    assert!(m.channel().axes()[Z].command() < 80.0);
}

// ---------------------------------------------------------------------------------------------
// Latch unit failures
// ---------------------------------------------------------------------------------------------

/// The generic drive file with `edit` applied, written to a temporary file.
fn drive_file(dir: &tempfile::TempDir, name: &str, edit: &dyn Fn(&str) -> String) -> String {
    let base = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("drives/cia402-generic.toml"),
    )
    .unwrap();
    let text = edit(&base);
    assert_ne!(text, base, "the edit changed the drive file");
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn a_latch_unit_that_cannot_be_armed_is_an_error() {
    // A drive whose TxPDO lacks the touch probe 1 positive-edge value 0x60BA.
    let dir = tempfile::tempdir().unwrap();
    let drive = drive_file(&dir, "no60ba.toml", &|t| t.replace("\"0x60BA:00\", ", ""));
    let mut cfg = config(&[]);
    cfg.axis_mut("Z").unwrap().drive = drive;
    let mut m = two_probe_machine(&cfg);
    let r = run(&mut m, "N10 G100 Z50 F3000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900043], "{:?}", r.messages());
    assert!(
        r.messages()[0].text.contains("0x60BA"),
        "{}",
        r.messages()[0]
    );
    assert_eq!(m.channel().axes()[Z].command(), 0.0, "nothing moved");
    assert_eq!(r.measurements[Z].result, None);
}

#[test]
fn a_latch_unit_that_drops_its_value_during_the_run_is_an_error() {
    // Right after the latch (the actual has just passed 30) the drive re-arms its probe on its
    // own (0x60B8 written to 0 behind the master's back; the next RxPDO enables it again, which
    // clears the stored bit). The master sees the stored bit fall without a re-arm: the latch
    // unit failed; the block aborts and publishes nothing — also not the value latched before.
    let mut m = machine(&[]);
    m.add_probe("Z", 30.0).unwrap();
    let mut glitched = false;
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", |m, _, _| {
        if !glitched && m.channel().axes()[Z].actual() > 30.0 {
            glitched = true;
            m.link_mut()
                .model_mut(Z)
                .unwrap()
                .write_object(0x60B8, 0, 0)
                .unwrap();
        }
    });
    assert!(glitched);
    assert_eq!(t.ids(), vec![900043], "{:?}", t.messages);
    assert_eq!(t.exec.result(Z), None);
    assert!(!t.exec.merf(Z));
    // Latched at 30 with the command v/kv = 1.25 mm ahead, braking v²/(2a) = 1.25 mm.
    assert!(
        t.z[t.z.len() - 1] < 33.0,
        "stopped at {}",
        t.z[t.z.len() - 1]
    );
    standstill(&mut m);
}

// ---------------------------------------------------------------------------------------------
// Re-arming: no stale latch
// ---------------------------------------------------------------------------------------------

/// The generic drive, and a drive that re-arms only on 0x60B8 = 0 → enable (`[probe]
/// rearm_requires_zero = true`); both must give fresh latches.
fn both_drives(dir: &tempfile::TempDir) -> Vec<(&'static str, MachineConfig)> {
    let quirk = drive_file(dir, "rearm0.toml", &|t| {
        t.replace("rearm_requires_zero = false", "rearm_requires_zero = true")
    });
    let mut q = config(&[]);
    q.axis_mut("Z").unwrap().drive = quirk;
    vec![("generic", config(&[])), ("rearm_requires_zero", q)]
}

#[test]
fn each_measuring_block_reports_its_own_latch() {
    // Probes at 30 and 40. N10 crosses 30 and stops just past it; N20 goes on and crosses 40.
    let dir = tempfile::tempdir().unwrap();
    for (name, cfg) in both_drives(&dir) {
        let mut m = Machine::new(&cfg).unwrap();
        m.add_probe("Z", 30.0).unwrap();
        m.add_probe("Z", 40.0).unwrap();
        let r = run(
            &mut m,
            "N10 G100 Z50 F3000\n\
             N20 #MSG SYN[\"%f\", V.A.MESS.Z]\n\
             N30 G100 Z50 F3000\n\
             N40 #MSG SYN[\"%f\", V.A.MESS.Z]\n\
             N50 M30\n",
        );
        assert_eq!(r.status, RunStatus::Completed, "{name}: {:?}", r.messages());
        assert_eq!(r.output(), vec!["30.000000", "40.000000"], "{name}");
    }
}

#[test]
fn a_second_block_without_crossing_has_no_signal() {
    // N10 latches 30; N20 goes further up without crossing a probe: the first latch must not be
    // reported again. Type 1: no value, MERF 0; type 2: error 900041.
    let dir = tempfile::tempdir().unwrap();
    for (name, cfg) in both_drives(&dir) {
        let mut m = Machine::new(&cfg).unwrap();
        m.add_probe("Z", 30.0).unwrap();
        let r = run(
            &mut m,
            "N10 G100 Z50 F3000\n\
             N20 #MSG SYN[\"%f %d\", V.A.MESS.Z, V.A.MERF.Z]\n\
             N30 G100 Z60 F3000\n\
             N40 #MSG SYN[\"%d\", V.A.MERF.Z]\n\
             N50 M30\n",
        );
        assert_eq!(r.status, RunStatus::Completed, "{name}: {:?}", r.messages());
        assert_eq!(r.output(), vec!["30.000000 1", "0"], "{name}");
        assert_eq!(
            m.channel().axes()[Z].command(),
            60.0,
            "{name}: no braking in N30"
        );
        assert_eq!(r.measurements[Z].result, None, "{name}");

        let mut cfg2 = cfg.clone();
        cfg2.apply_set("P-CHAN-00057=2").unwrap();
        let mut m = Machine::new(&cfg2).unwrap();
        m.add_probe("Z", 30.0).unwrap();
        let r = run(&mut m, "N10 G100 Z50 F3000\nN20 G100 Z60 F3000\nN30 M30\n");
        assert_eq!(r.status, RunStatus::Aborted, "{name}");
        assert_eq!(r.message_ids(), vec![900041], "{name}: {:?}", r.messages());
        assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(20));
    }
}

#[test]
fn a_crossing_between_measuring_blocks_is_not_taken() {
    // The probe at 30 is crossed by a plain G01 (no measurement armed); the following G100 must
    // not report it.
    let mut m = machine(&[]);
    m.add_probe("Z", 30.0).unwrap();
    let r = run(&mut m, "N10 G01 Z40 F3000\nN20 G100 Z60 F3000\nN30 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.measurements[Z].result, None);
    assert_eq!(m.channel().axes()[Z].command(), 60.0);
}

// ---------------------------------------------------------------------------------------------
// Every drive family: a fault or a lost exchange while measuring stops the axis and reports
// ---------------------------------------------------------------------------------------------

/// Each built-in drive family on Z: a drive fault, then a lost exchange, in the middle of a
/// measuring block (before the probe at 80) end the run with the seed's error, publish no
/// latch, and leave the axes standing.
#[test]
fn every_drive_family_stops_safely_on_a_fault_or_lost_exchange() {
    for &drive in fieldprobe::drive::catalogue::builtin_names() {
        let mut sets = vec![format!("Z.drive={drive}")];
        if drive == "cia402-drive-defined" {
            sets.push("Z.P-AXIS-00702=DRIVE_DEFINED".into());
        }
        let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
        for (what, id) in [("fault", 900010), ("lost exchange", 900012)] {
            let mut m = machine(&sets);
            m.add_probe("Z", 80.0).unwrap();
            let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", |m, _, k| {
                if k == 300 {
                    if id == 900010 {
                        m.link_mut().model_mut(Z).unwrap().inject_fault(0x8611);
                    } else {
                        let next = m.link_mut().exchanges();
                        // One more than max_lost_cycles (3) in a row: the link is lost.
                        for j in 0..4 {
                            m.link_mut().lose_exchange_at(next + j);
                        }
                    }
                }
            });
            assert!(!t.completed, "{drive} {what}");
            assert_eq!(t.ids(), vec![id], "{drive} {what}: {:?}", t.messages);
            assert_eq!(t.exec.result(Z), None, "{drive} {what}");
            assert!(!t.exec.merf(Z), "{drive} {what}");
            let z = t.z[t.z.len() - 1];
            assert!(z < 80.0, "{drive} {what}: stopped at {z}, before the probe");
            standstill(&mut m);
        }
    }
}
