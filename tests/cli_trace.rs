//! `fieldprobe run --trace FILE`: the recorded trace (latches only of axes that measured) and the
//! picture formats (SVG, PNG; other extensions refused with exit 2).

#[path = "common/cli.rs"]
mod cli;

use cli::{fieldprobe, stderr};
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;
/// 0.1 µm in mm: the latch resolution of the drive model.
const LATCH_TOL: f64 = 1e-4;

/// The default machine recording a trace, with the probe switching at `probe`, looped to the
/// digital input 1 of the axes `wired` only.
fn traced_machine(probe: (&str, f64), wired: &[usize]) -> Machine {
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let p = m.add_probe(probe.0, probe.1).unwrap();
    m.link_mut().plant_mut().unwrap().probe_surfaces_mut()[p].wired =
        wired.iter().map(|a| (*a, 1)).collect();
    m.enable_trace();
    m
}

fn latched_axes(m: &Machine) -> Vec<usize> {
    m.trace().unwrap().latches.iter().map(|l| l.1).collect()
}

#[test]
fn trace_marks_latches_only_on_axes_that_measured() {
    // G100 X10 Y10: both move, so both must latch (seed 004 §4); the probe at X = 4 is looped to
    // X only. X's drive latches, but the signal is incomplete: nothing is measured (type 1, no
    // error), so the trace has no latch.
    let mut m = traced_machine(("X", 4.0), &[X]);
    let r = m.run_program(
        &parse("N10 G100 X10 Y10 F1000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.measurements[X].result, None);
    assert_eq!(latched_axes(&m), Vec::<usize>::new(), "nothing measured");

    // G100 Z50 with the probe at Z = 30 looped to every axis: X and Y are not programmed, only Z
    // measured — one latch, on Z, at 30.
    let mut m = traced_machine(("Z", 30.0), &[X, Y, Z]);
    let r = m.run_program(
        &parse("N10 G100 Z50 F1000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(latched_axes(&m), vec![Z]);
    let (t, _, p) = m.trace().unwrap().latches[0];
    assert!((p - 30.0).abs() <= LATCH_TOL, "latched at {p}");
    // 30 mm at F1000 (16.7 mm/s) take at least 1.8 s; the mark lies within the recorded run.
    let t_end = *m.trace().unwrap().t.last().unwrap();
    assert!(
        t > 1.8 && t <= t_end,
        "latch at {t} s, run ends at {t_end} s"
    );
}
