//! Seed 000 §5 "Special features in manual mode": workspace / protection-area monitoring while
//! jogging, P-CHAN-00442 cases 1 / 2 / 3, errors 50961 / 50962, the PLC datum and the control
//! unit of §6.3, warning 900318 with P-MANU-00014.
//!
//! Geometry: workspace 3 is the seed's notched polygon; at Y50 it spans X ∈ [-150, -50] and
//! [50, 150] (the notch X ∈ [-50, 50], Y ∈ [0, 75] is outside). Protection area 4 is the seed's
//! circle, centre (0, 75), radius 75; at Y50 it spans |X| ≤ √(75² − 25²) = 70.710678.

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::messages::Severity;
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const WORK: &str = "N10 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X-150 Y75
N30 X-50 Y150
N40 X50 Y150
N50 X150 Y75
N60 X150 Y0
N70 X50 Y0
N80 X50 Y75
N90 X-50 Y75
N100 X-50 Y0
N120 X-150 Y0
N130 X-150 Y75
N140 #CONTROL AREA END
N150 G01 X-100 Y50 F5000
N160 #CONTROL AREA ON [ID3]
N170 M30
";

const PROT: &str = "N10 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N20 G01 X0 Y0 F10000
N30 G02 G162 I0 J75
N40 #CONTROL AREA END
N50 G01 G90 X-100 Y50 F5000
N60 #CONTROL AREA ON [ID4]
N70 M30
";

/// X where protection area 4 begins at Y50.
fn prot_edge() -> f64 {
    -(75.0f64 * 75.0 - 25.0 * 25.0).sqrt()
}

fn machine(program: &str, sets: &[&str]) -> Machine {
    let mut cfg = MachineConfig::default_machine();
    for s in sets {
        cfg.apply_set(s).unwrap();
    }
    let mut m = Machine::new(&cfg).unwrap();
    let r = m.run_program(&parse(program).unwrap(), &mut |_| {});
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.message_ids());
    assert_eq!(m.channel().command_positions()[..2], [-100.0, 50.0]);
    m.channel_mut().take_messages();
    m
}

fn x(m: &Machine) -> f64 {
    m.channel().axes()[0].command()
}

/// Step until idle; returns every command X seen.
fn run_jog(m: &mut Machine) -> Vec<f64> {
    let mut xs = Vec::new();
    for _ in 0..2_000_000 {
        if m.channel().state() != ChannelState::Busy {
            break;
        }
        m.step();
        xs.push(x(m));
    }
    assert_eq!(m.channel().state(), ChannelState::Idle);
    xs
}

fn ids(m: &mut Machine) -> Vec<u32> {
    m.channel_mut()
        .take_messages()
        .iter()
        .map(|x| x.id)
        .collect()
}

#[test]
fn continuous_jog_stops_at_the_workspace_boundary_with_and_without_warning() {
    for warn in [false, true] {
        let sets: &[&str] = if warn { &["P-MANU-00014=1"] } else { &[] };
        let mut m = machine(WORK, sets);
        let ch = m.channel_mut();
        assert!(ch.manual_area_monitoring());
        assert!(ch.enter_manual());
        assert!(!ch.area_mon_violation_detected_r());
        assert!(ch.jog_continuous(0, 40.0));
        // The PLC datum is set when the jog stops at the area, not when it is planned.
        assert!(!ch.area_mon_violation_detected_r());
        let xs = run_jog(&mut m);
        let stop = x(&m);
        assert!(
            (-50.01..=-50.0 + 0.001).contains(&stop),
            "stopped at {stop}"
        );
        assert!(
            xs.iter().all(|&v| v <= -50.0 + 0.001),
            "passed the boundary"
        );
        // The velocity ramps down before the limit (not an abrupt stop): the last set-point
        // before the one at the stop is short of it by less than the jog's 40 mm/s × 1 ms (the
        // set-points then stand while the axis settles in position).
        let mut moving = xs.clone();
        moving.dedup();
        let before = moving[moving.len() - 2];
        assert!(
            moving.len() > 10 && before < stop && stop - before < 0.04,
            "{before} {stop}"
        );
        let msgs = m.channel_mut().take_messages();
        assert!(msgs.iter().all(|x| !x.is_error()), "{msgs:?}");
        let w: Vec<_> = msgs.iter().filter(|x| x.id == 900318).collect();
        if warn {
            assert_eq!(w.len(), 1);
            assert_eq!(w[0].severity, Severity::Warning);
            assert!(w[0].text.contains("workspace 3"), "{}", w[0].text);
        } else {
            assert!(w.is_empty());
        }
        assert!(m.channel().area_mon_violation_detected_r());
        // Further +X: nothing moves; the way back is free.
        assert!(m.channel_mut().jog_continuous(0, 40.0));
        run_jog(&mut m);
        assert_eq!(x(&m), stop);
        assert!(m.channel_mut().jog_increment(0, -20.0, 40.0));
        run_jog(&mut m);
        assert!((x(&m) - (stop - 20.0)).abs() < 1e-9);
    }
}

#[test]
fn jog_stopped_early_leaves_the_datum_clear() {
    let mut m = machine(WORK, &[]);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    assert!(ch.jog_continuous(0, 40.0));
    for _ in 0..100 {
        m.step();
    }
    m.channel_mut().jog_stop(0);
    run_jog(&mut m);
    assert!(x(&m) < -60.0);
    assert!(!m.channel().area_mon_violation_detected_r());
}

#[test]
fn protection_area_approached_stops_before_entering() {
    let mut m = machine(PROT, &["P-MANU-00014=1"]);
    assert!(m.channel_mut().enter_manual());
    assert!(m.channel_mut().jog_continuous(0, 40.0));
    let xs = run_jog(&mut m);
    let edge = prot_edge();
    assert!(xs.iter().all(|&v| v < edge), "entered the protection area");
    assert!((x(&m) - edge).abs() < 0.01, "stopped at {}", x(&m));
    let msgs = m.channel_mut().take_messages();
    assert_eq!(msgs.iter().map(|x| x.id).collect::<Vec<_>>(), vec![900318]);
    assert!(
        msgs[0].text.contains("protection area 4"),
        "{}",
        msgs[0].text
    );
    assert!(m.channel().area_mon_violation_detected_r());
}

#[test]
fn incremental_step_into_a_protection_area_is_refused() {
    let mut m = machine(PROT, &[]);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    assert!(!ch.jog_increment(0, 40.0, 40.0));
    let msgs = ch.take_messages();
    assert_eq!(msgs.iter().map(|x| x.id).collect::<Vec<_>>(), vec![900318]);
    assert_eq!(msgs[0].severity, Severity::Warning);
    assert!(
        msgs[0].text.contains("protection area 4"),
        "{}",
        msgs[0].text
    );
    assert!(ch.area_mon_violation_detected_r());
    for _ in 0..100 {
        m.step();
    }
    assert_eq!(x(&m), -100.0, "the axis did not move");
    // A step that stays outside runs.
    assert!(m.channel_mut().jog_increment(0, 20.0, 40.0));
    run_jog(&mut m);
    assert_eq!(x(&m), -80.0);
}

#[test]
fn only_one_monitored_axis_jogs_at_a_time() {
    let mut m = machine(WORK, &[]);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    assert!(ch.jog_continuous(0, 40.0));
    assert!(!ch.jog_continuous(1, 40.0));
    assert!(!ch.jog_increment(1, 1.0, 40.0));
    assert_eq!(ids(&mut m), vec![900318, 900318]);
    run_jog(&mut m);
    // Without areas monitored two axes may jog together.
    m.channel_mut().leave_manual();
    m.channel_mut().set_area_mon_suppress_manual_w(true);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    assert!(ch.jog_increment(0, -10.0, 40.0));
    assert!(ch.jog_increment(1, -10.0, 40.0));
    run_jog(&mut m);
}

/// Jog X to -40 (inside the notch, outside workspace 3) with the control unit set.
fn move_into_notch(m: &mut Machine) {
    let ch = m.channel_mut();
    ch.set_area_mon_suppress_manual_w(true);
    assert!(ch.enter_manual());
    assert!(ch.jog_increment(0, 60.0, 40.0));
    run_jog(m);
    assert_eq!(x(m), -40.0);
    assert!(m.channel_mut().leave_manual());
}

#[test]
fn selection_outside_the_workspace_is_error_50961_and_refused() {
    let mut m = machine(WORK, &[]);
    move_into_notch(&mut m);
    assert!(ids(&mut m).is_empty(), "control unit set: no error");
    assert!(!m.channel().area_mon_violation_detected_r());
    m.channel_mut().set_area_mon_suppress_manual_w(false);
    assert!(!m.channel_mut().enter_manual());
    assert!(!m.channel().in_manual());
    let msgs = m.channel_mut().take_messages();
    assert_eq!(msgs.iter().map(|x| x.id).collect::<Vec<_>>(), vec![50961]);
    assert!(msgs[0].is_error());
    assert!(msgs[0].text.contains("workspace 3"), "{}", msgs[0].text);
    assert!(msgs[0].text.contains("X=-40.000000"), "{}", msgs[0].text);
    assert!(m.channel().area_mon_violation_detected_r());
    assert_eq!(m.channel().state(), ChannelState::Idle);
    // Recovery: set the control unit, select, move back.
    m.channel_mut().set_area_mon_suppress_manual_w(true);
    assert!(m.channel_mut().enter_manual());
    // Control unit cleared in manual mode: monitoring is back, only moving back is allowed.
    m.channel_mut().set_area_mon_suppress_manual_w(false);
    assert!(!m.channel_mut().jog_increment(1, -5.0, 40.0));
    assert_eq!(ids(&mut m), vec![900318]);
    assert!(m.channel_mut().jog_continuous(0, -40.0));
    run_jog(&mut m);
    assert_eq!(x(&m), -140.0, "back inside, on to the jog-range end");
    // A reset clears the datum.
    m.channel_mut().leave_manual();
    m.channel_mut().reset();
    m.settle(10_000);
    assert!(!m.channel().area_mon_violation_detected_r());
}

#[test]
fn selection_inside_a_protection_area_is_error_50962() {
    let mut m = machine(PROT, &[]);
    let ch = m.channel_mut();
    ch.set_area_mon_suppress_manual_w(true);
    assert!(ch.enter_manual());
    assert!(ch.jog_increment(0, 50.0, 40.0));
    run_jog(&mut m);
    assert_eq!(x(&m), -50.0);
    let ch = m.channel_mut();
    assert!(ch.leave_manual());
    ch.set_area_mon_suppress_manual_w(false);
    assert!(!ch.enter_manual());
    let msgs = ch.take_messages();
    assert_eq!(msgs.iter().map(|x| x.id).collect::<Vec<_>>(), vec![50962]);
    assert!(
        msgs[0].text.contains("protection area 4"),
        "{}",
        msgs[0].text
    );
    assert!(ch.area_mon_violation_detected_r());
}

#[test]
fn p_chan_00442_2_selects_outside_and_allows_moving_back_only() {
    let mut m = machine(WORK, &["P-CHAN-00442=2", "P-MANU-00014=1"]);
    move_into_notch(&mut m);
    m.channel_mut().set_area_mon_suppress_manual_w(false);
    let ch = m.channel_mut();
    assert!(ch.enter_manual(), "442 = 2: no check on selection");
    assert!(ch.take_messages().is_empty());
    assert!(ch.manual_area_monitoring());
    // Jog range ±100 around X-40: [-140, 60]. -X re-enters the workspace at X-50; the next
    // area boundary lies beyond the jog range end, so the jog stops at X-140.
    assert!(ch.jog_continuous(0, -40.0));
    let xs = run_jog(&mut m);
    assert!(xs.iter().all(|v| (-140.0..=-40.0).contains(v)));
    assert_eq!(x(&m), -140.0, "stops at the end of the jog range");
    assert!(m
        .channel_mut()
        .take_messages()
        .iter()
        .all(|x| x.id == 50720));
    // Back inside: the boundary at X-50 holds again.
    assert!(m.channel_mut().jog_continuous(0, 40.0));
    let xs = run_jog(&mut m);
    assert!(xs.iter().all(|&v| v <= -50.0 + 0.001));
    assert!((x(&m) + 50.0).abs() <= 0.01);
}

#[test]
fn p_chan_00442_2_refuses_directions_that_do_not_lead_back() {
    let mut m = machine(WORK, &["P-CHAN-00442=2", "P-MANU-00014=1"]);
    move_into_notch(&mut m);
    m.channel_mut().set_area_mon_suppress_manual_w(false);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    // -Y from Y50 in the notch: the workspace has nothing below Y0 → refused, nothing moves.
    assert!(ch.jog_continuous(1, -40.0));
    assert_eq!(ids(&mut m), vec![900318]);
    assert!(m.channel().area_mon_violation_detected_r());
    run_jog(&mut m);
    assert_eq!(m.channel().command_positions()[1], 50.0);
    assert!(!m.channel_mut().jog_increment(1, -5.0, 40.0));
    assert_eq!(ids(&mut m), vec![900318]);
    // A short step towards the permitted range is allowed although it ends outside.
    assert!(m.channel_mut().jog_increment(0, -5.0, 40.0));
    run_jog(&mut m);
    assert_eq!(x(&m), -45.0);
    // +Y from the notch re-enters at Y75 and runs on to the top edge Y150 (also the jog-range end).
    assert!(m.channel_mut().jog_continuous(1, 40.0));
    run_jog(&mut m);
    let y = m.channel().command_positions()[1];
    assert!(y > 75.0 && y <= 150.0 + 0.001, "y {y}");
}

#[test]
fn p_chan_00442_1_does_not_monitor_areas_in_manual_mode() {
    let mut m = machine(WORK, &["P-CHAN-00442=1"]);
    let ch = m.channel_mut();
    assert!(!ch.manual_area_monitoring());
    assert!(ch.enter_manual());
    assert!(ch.jog_continuous(0, 40.0));
    run_jog(&mut m);
    assert_eq!(x(&m), 0.0, "jog range end (relative offset limit +100)");
    assert!(!m.channel().area_mon_violation_detected_r());
    assert!(m
        .channel_mut()
        .take_messages()
        .iter()
        .all(|x| !x.is_error()));
}

#[test]
fn control_unit_set_means_no_limit_and_no_error() {
    let mut m = machine(WORK, &[]);
    let ch = m.channel_mut();
    ch.set_area_mon_suppress_manual_w(true);
    assert!(ch.enter_manual());
    assert!(!ch.manual_area_monitoring());
    assert!(ch.jog_continuous(0, 40.0));
    run_jog(&mut m);
    assert_eq!(x(&m), 0.0);
    assert!(ids(&mut m).is_empty());
    assert!(!m.channel().area_mon_violation_detected_r());
}

#[test]
fn a_refused_incremental_step_names_the_boundary_as_automatic_mode_does() {
    // Issue 27 item 6: the point named is where protection area 4 begins on the step's line —
    // X = −√(75² − 25²) at Y50 (seed 000 §3.1 circle, centre (0, 75), radius 75) — not a
    // point 10 tolerances inside it.
    let point_x = |text: &str| -> f64 {
        let at = text
            .find(" at X=")
            .unwrap_or_else(|| panic!("no point: {text}"))
            + 6;
        let end = text[at..].find(' ').map_or(text.len(), |e| at + e);
        text[at..end].parse().unwrap()
    };
    let mut m = machine(PROT, &[]);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    assert!(!ch.jog_increment(0, 40.0, 40.0));
    let msgs = ch.take_messages();
    assert_eq!(msgs.iter().map(|x| x.id).collect::<Vec<_>>(), vec![900318]);
    // On the near side of the edge, within the 1 µm band both modes keep from a protection
    // area (docs/interpretations.md A6) and the 0.1 µm the search resolves.
    let edge = prot_edge();
    let near_edge = |x: f64| x <= edge && x >= edge - 1.1e-3;
    let jog = point_x(&msgs[0].text);
    assert!(
        near_edge(jog),
        "jog names {jog}, edge {edge}: {}",
        msgs[0].text
    );
    // Automatic mode, the same line: 900316 names the same point.
    let mut m = machine(PROT, &[]);
    let r = m.run_program(
        &parse("N10 G01 X-60 F1000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.message_ids(), vec![900316], "{:?}", r.messages());
    let auto = point_x(&r.messages()[0].text);
    assert!(
        near_edge(auto),
        "automatic names {auto}: {}",
        r.messages()[0].text
    );
    assert!(
        (jog - auto).abs() <= 1e-4,
        "jog {jog}, automatic {auto}: {}",
        r.messages()[0].text
    );
}

/// Seed 000 §2.3 "a protection area must never be touched by the TCP" and §3.2 (issue 27 item
/// 3): a jog stopped in front of a protection area leaves the TCP where automatic mode may go
/// on. Back in automatic mode, a block moving away from the area runs (the path check's 1 µm
/// band does not hold the stop point), and one moving towards the area is refused (900316).
#[test]
fn after_a_jog_stopped_at_a_protection_area_automatic_mode_moves_away() {
    let mut m = machine(PROT, &["P-MANU-00014=1"]);
    assert!(m.channel_mut().enter_manual());
    assert!(m.channel_mut().jog_continuous(0, 40.0));
    run_jog(&mut m);
    let stop = x(&m);
    let edge = prot_edge();
    assert!(stop < edge, "stopped at {stop}, area from {edge}");
    m.channel_mut().take_messages();
    assert!(m.channel_mut().leave_manual());

    let away = parse("N10 G01 G90 X-100 Y50 F5000\nN20 M30\n").unwrap();
    let r = m.run_program(&away, &mut |_| {});
    assert_eq!(
        r.status,
        RunStatus::Completed,
        "moving away from {stop}: {:?}",
        r.message_ids()
    );
    assert_eq!(m.channel().command_positions()[..2], [-100.0, 50.0]);

    let toward = parse("N10 G01 G90 X0 Y50 F5000\nN20 M30\n").unwrap();
    let r = m.run_program(&toward, &mut |_| {});
    assert_ne!(r.status, RunStatus::Completed);
    assert!(r.message_ids().contains(&900316), "{:?}", r.message_ids());
}
