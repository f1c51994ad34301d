//! Accuracy of the latched values over feeds up to 10 m/min and several trigger positions, per
//! source (seed 004 §6 drive latch, §7.1 PLC, §7.5 DC timestamp; goals of notes cnc.md §0 / §6):
//!
//! | source | bound (probed axis) |
//! |---|---|
//! | drive latch (`DRIVE`) | the crossing within 0.1 µm (one increment) |
//! | `PLC`, synchronous PLC | behind the crossing by 0 … v·T, on the far side in the direction of motion |
//! | `PLC_TIMESTAMP` | within a·T²/8 + 0.1 µm |
//!
//! The block is the straight line `G100 X50 Z100` from the origin with the probe on Z, so at any
//! moment X = Z / 2: a second moving axis must read its own position at the same moment, i.e.
//! X = p / 2 for the latches of the crossing, and half the sampled Z for a sampled source.
//! Both axes start at rest with the same loop, so their actual positions stay on the line.
//!
//! A timestamp shifted by one cycle (an uncompensated dead time in the terminal) is not
//! visible to the CNC inside its buffer of actual values: it shows up as a value off by v·T
//! (ahead for a later timestamp, behind for an earlier one). A shift that leaves the buffer is
//! an error (900043) and nothing is published.

use fieldprobe::machine::{Machine, RunReport, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use fieldprobe::units::Nanos;

/// Interpolation cycle (s).
const T: f64 = 0.001;
/// One drive increment (mm).
const INC: f64 = 1e-4;
/// Half an increment: rounding of 0x6064 and of the drive latch.
const HALF_INC: f64 = 0.5e-4;
const X: usize = 0;
const Z: usize = 2;
/// Path feeds (mm/min), up to 10 m/min.
const FEEDS: [f64; 5] = [200.0, 1000.0, 3000.0, 6000.0, 10000.0];
/// Trigger positions on Z (mm), off the set-point grid; the first lies in the acceleration
/// ramp at the higher feeds.
const TRIGGERS: [f64; 3] = [6.54321, 61.0009, 87.77777];
/// Z's share of the path velocity on the line (50, 100): 100 / √(50² + 100²).
fn z_share() -> f64 {
    100.0 / (50f64 * 50.0 + 100.0 * 100.0).sqrt()
}
/// Z acceleration bound: P-AXIS-00004 = 1000 mm/s² (measuring blocks use G00 dynamics).
const A_Z: f64 = 1000.0;

fn timestamp_bound() -> f64 {
    A_Z * T * T / 8.0 + 1e-4
}

/// `G100 X50 Z100 F<feed>` from the origin with the probe at Z = `p`, both axes measuring with
/// `signal`; `knob` adjusts the machine (e.g. the simulated PLC) after the probe is added.
fn sweep_run(signal: &str, feed: f64, p: f64, knob: &dyn Fn(&mut Machine)) -> RunReport {
    let mut cfg = MachineConfig::default_machine();
    for s in [
        format!("X.kenngr.measure.signal={signal}"),
        format!("Z.kenngr.measure.signal={signal}"),
    ] {
        cfg.apply_set(&s).unwrap();
    }
    let mut m = Machine::new(&cfg).unwrap();
    m.add_probe("Z", p).unwrap();
    knob(&mut m);
    m.run_program(
        &parse(&format!("N10 G100 X50 Z100 F{feed}\nN20 M30\n")).unwrap(),
        &mut |_| {},
    )
}

/// (X, Z) latched by a completed run without messages.
#[track_caller]
fn latched(r: &RunReport, what: &str) -> (f64, f64) {
    assert_eq!(r.status, RunStatus::Completed, "{what}: {:?}", r.messages());
    assert!(r.messages().is_empty(), "{what}: {:?}", r.messages());
    let x = r.measurements[X]
        .result
        .unwrap_or_else(|| panic!("{what}: X"));
    let z = r.measurements[Z]
        .result
        .unwrap_or_else(|| panic!("{what}: Z"));
    assert!(r.measurements[X].merf && r.measurements[Z].merf, "{what}");
    (x.acs, z.acs)
}

#[track_caller]
fn within(what: &str, actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: {actual} is not within {tol} of {expected} (off by {})",
        actual - expected
    );
}

#[test]
fn drive_latch_is_the_crossing_within_an_increment() {
    for feed in FEEDS {
        for p in TRIGGERS {
            let what = format!("DRIVE F{feed} p {p}");
            let (x, z) = latched(&sweep_run("DRIVE", feed, p, &|_| {}), &what);
            within(&format!("{what} Z"), z, p, INC);
            within(&format!("{what} X on the line"), x, p / 2.0, INC);
        }
    }
}

#[test]
fn plc_sampled_value_is_behind_by_at_most_v_t() {
    for feed in FEEDS {
        let v_z = feed / 60.0 * z_share();
        for p in TRIGGERS {
            let what = format!("PLC F{feed} p {p}");
            let (x, z) = latched(&sweep_run("PLC", feed, p, &|_| {}), &what);
            // Moving up: the sampled value is at or beyond the crossing.
            let behind = z - p;
            assert!(
                behind >= -HALF_INC && behind <= v_z * T + HALF_INC,
                "{what}: Z {z} is {behind} past the crossing, v·T = {}",
                v_z * T
            );
            // X was sampled in the same cycle: half of Z (each rounded to an increment).
            within(&format!("{what} X"), x, z / 2.0, INC);
        }
    }
}

#[test]
fn plc_timestamp_is_within_a_t2_over_8() {
    for feed in FEEDS {
        for p in TRIGGERS {
            let what = format!("PLC_TIMESTAMP F{feed} p {p}");
            let (x, z) = latched(&sweep_run("PLC_TIMESTAMP", feed, p, &|_| {}), &what);
            within(&format!("{what} Z"), z, p, timestamp_bound());
            within(&format!("{what} X"), x, p / 2.0, timestamp_bound());
        }
    }
}

/// The Z terminal's timestamps are `shift_ns` late (negative: early) — a dead time the CNC
/// does not know of.
fn shifted(shift_ns: i64) -> impl Fn(&mut Machine) {
    move |m: &mut Machine| {
        let plc = m.sim_plc_mut(Z).unwrap().config_mut();
        plc.timestamp.as_mut().unwrap().terminal_delay_ns = shift_ns;
    }
}

#[test]
fn a_timestamp_one_cycle_off_is_detected() {
    // A terminal whose timestamps are one NC cycle late or early (a dead time the CNC does not
    // know of) contradicts its own probing signal: the edge would lie after the cycle in which
    // the signal was first seen active, or before the last cycle it was seen inactive. The
    // measuring block fails with 900043 and publishes nothing, instead of a value off by v·T.
    for feed in [1000.0, 3000.0, 6000.0, 10000.0] {
        for p in [45.0123, 61.0009] {
            for shift in [1_000_000, -1_000_000] {
                let what = format!("F{feed} p {p} shift {shift}");
                let r = sweep_run("PLC_TIMESTAMP", feed, p, &shifted(shift));
                assert_eq!(r.status, RunStatus::Aborted, "{what}");
                assert_eq!(r.message_ids(), vec![900043], "{what}: {:?}", r.messages());
                assert!(
                    r.messages()[0].text.contains("outside the window"),
                    "{what}"
                );
                assert_eq!(r.measurements[Z].result, None, "{what}");
            }
            // Within the signal's window (a sub-cycle terminal delay) it is accepted.
            let r = sweep_run("PLC_TIMESTAMP", feed, p, &shifted(500));
            let (_, z) = latched(&r, &format!("F{feed} p {p} 0.5 µs"));
            let v_z = feed / 60.0 * z_share();
            within("0.5 µs late", z, p + v_z * 500e-9, timestamp_bound());
        }
    }
}

#[test]
fn a_timestamp_outside_the_buffer_is_an_error() {
    // 5 cycles late: after the newest actual value by more than a cycle ("too new"); 100 cycles
    // early: older than the buffered actual values ("too old"). Error 900043 in the measuring
    // block, nothing published, Z does not go on to the target.
    for shift in [5_000_000, -100_000_000] {
        let r = sweep_run("PLC_TIMESTAMP", 3000.0, 61.0009, &shifted(shift));
        assert_eq!(r.status, RunStatus::Aborted, "shift {shift}");
        assert_eq!(
            r.message_ids(),
            vec![900043],
            "shift {shift}: {:?}",
            r.messages()
        );
        assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(10));
        assert_eq!(r.measurements[Z].result, None);
        assert!(!r.measurements[Z].merf);
    }
}

#[test]
fn timestamp_beats_sampling_by_orders_of_magnitude_at_speed() {
    // The same crossing at 10 m/min: the PLC-sampled value may be up to v·T ≈ 0.15 mm off,
    // the timestamp within a·T²/8 + 0.1 µm, the drive latch within 0.1 µm.
    let p = 87.77777;
    let v_z = 10000.0 / 60.0 * z_share();
    let (_, plc) = latched(&sweep_run("PLC", 10000.0, p, &|_| {}), "PLC");
    let (_, ts) = latched(&sweep_run("PLC_TIMESTAMP", 10000.0, p, &|_| {}), "TS");
    let (_, drv) = latched(&sweep_run("DRIVE", 10000.0, p, &|_| {}), "DRIVE");
    assert!(plc - p > 1e-3 && plc - p <= v_z * T + HALF_INC, "{plc}");
    within("timestamp", ts, p, timestamp_bound());
    within("drive", drv, p, INC);
    // The PLC period shows in the sampled value, not in the timestamp.
    let slow = |m: &mut Machine| {
        m.sim_plc_mut(Z).unwrap().config_mut().period = Nanos(4_000_000);
        m.channel_mut().set_plc_cycle(Some(Nanos(4_000_000)));
    };
    let (_, ts4) = latched(&sweep_run("PLC_TIMESTAMP", 10000.0, p, &slow), "TS 4 ms");
    within("timestamp with a 4 ms PLC", ts4, p, timestamp_bound());
}
