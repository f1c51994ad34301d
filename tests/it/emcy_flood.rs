//! Issue 28 item 8: a node that floods EMCYs. On `canopen-emu` (our CiA 301 master against
//! emulated CiA 402 nodes on the in-process virtual CAN bus, virtual time), node 1 (axis X)
//! sends EMCY 0x2310 every millisecond while a 2 s program runs (the 1,000/s; before
//! the fix: one warning line per EMCY). The run must complete (the cycle goes on), report the
//! emergency once (900015), and sum the rest up at the end of the run (900018 with the count).

use fieldprobe::machine::{LinkChoice, Machine, RunStatus};
use fieldprobe::messages::ids;
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use fieldprobe::units::Nanos;

const PROGRAM: &str = "N10 G01 G90 X100 F3000\nN20 G01 X0 F6000\nN30 M30\n";

/// Messages as (id, text).
type Lines = Vec<(u32, String)>;

/// The run's status, its messages, and those of the end of the run (power off).
fn flooded_run(every: Nanos) -> (RunStatus, Lines, Lines) {
    let mut cfg = MachineConfig::default_machine();
    // Three CiA 402 nodes need 4 ms at 1 Mbit/s (docs/canopen.md "Bus load").
    cfg.apply_set("cycle_time_us=4000").unwrap();
    let mut m = Machine::with_link(&cfg, &LinkChoice::new("canopen-emu")).expect("canopen-emu");
    assert!(
        m.link_mut().flood_emergencies(0, 0x2310, Some(every)),
        "canopen-emu takes the flood knob"
    );
    let r = m.run_program(&parse(PROGRAM).expect("program"), &mut |_| {});
    let during = r.messages().iter().map(|m| (m.id, m.to_string())).collect();
    let end = m
        .power_off()
        .iter()
        .map(|m| (m.id, m.to_string()))
        .collect();
    (r.status, during, end)
}

#[test]
fn an_emcy_flood_gives_one_line_and_a_summary_and_the_run_completes() {
    let (status, during, end) = flooded_run(Nanos(1_000_000));
    println!("during the run: {during:?}\nat its end: {end:?}");
    assert_eq!(status, RunStatus::Completed, "{during:?}");
    // One line for the first EMCY, none per repetition.
    assert_eq!(during.len(), 1, "{during:?}");
    assert_eq!(during[0].0, ids::DRIVE_EMERGENCY);
    assert!(
        during[0].1.contains("axis X") && during[0].1.contains("0x2310"),
        "{}",
        during[0].1
    );
    // The summary counts them: ~1,000 per second of a run of more than 2 s.
    let summary: Vec<&(u32, String)> = end
        .iter()
        .filter(|(id, _)| *id == ids::DRIVE_EMERGENCY_SUMMARY)
        .collect();
    assert_eq!(summary.len(), 1, "{end:?}");
    let text = &summary[0].1;
    let n: u64 = text
        .split(" came ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no count in {text:?}"));
    assert!(n >= 2_000, "{n} EMCYs counted: {text}");
    assert!(text.contains("axis X") && text.contains("0x2310"), "{text}");
    println!("EMCY flood at 1,000/s: {n} EMCYs, 1 warning + 1 summary");
}
