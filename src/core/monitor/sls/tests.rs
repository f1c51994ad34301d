//! Unit tests of the SLS monitor. Expected values come from FCT-A2, worked by hand.

use super::*;
use crate::core::path::Segment;

fn xy(neg: f64, pos: f64) -> SoftLimits {
    let mut s = SoftLimits::new(
        vec![
            AxisLimitConfig::linear("X", neg, pos),
            AxisLimitConfig::linear("Y", neg, pos),
        ],
        false,
    );
    s.set_referenced(0, true);
    s.set_referenced(1, true);
    s
}

fn ids_of(v: &[CncMessage]) -> Vec<u32> {
    v.iter().map(|m| m.id).collect()
}

#[test]
fn line_to_the_limit_is_allowed_beyond_is_not() {
    let s = xy(-200.0, 200.0);
    let mut out = Vec::new();
    s.check_path(
        &Segment::line(vec![0.0, 0.0], vec![200.0, 0.0]).unwrap(),
        &mut out,
    );
    assert!(out.is_empty());
    s.check_path(
        &Segment::line(vec![0.0, 0.0], vec![200.001, 0.0]).unwrap(),
        &mut out,
    );
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].side, Side::Positive);
    assert_eq!(s.path_message(&out[0]).id, 120002);
    s.check_path(
        &Segment::line(vec![0.0, 0.0], vec![0.0, -250.0]).unwrap(),
        &mut out,
    );
    assert_eq!(s.path_message(&out[0]).id, 120003);
    assert_eq!(out[0].axis, 1);
}

#[test]
fn arc_between_in_range_points_is_checked_at_its_apex() {
    // Half circle G02 from (-150, 0) to (150, 0) around (0, 0): apex Y = +150; limit 100.
    let s = xy(-100.0, 100.0);
    let mut out = Vec::new();
    let arc = Segment::arc(
        vec![-50.0, 0.0],
        vec![50.0, 0.0],
        0,
        1,
        [50.0, 0.0],
        true,
        1e-6,
    )
    .unwrap();
    s.check_path(&arc, &mut out);
    assert!(out.is_empty(), "apex at Y=50 is inside: {out:?}");
    let s = xy(-40.0, 40.0);
    let arc = Segment::arc(
        vec![-30.0, 0.0],
        vec![30.0, 0.0],
        0,
        1,
        [30.0, 0.0],
        true,
        1e-6,
    )
    .unwrap();
    s.check_path(&arc, &mut out);
    // End points ±30 inside ±40, apex Y = +30 inside; full travel fine.
    assert!(out.is_empty());
    let s = xy(-40.0, 25.0);
    s.check_path(&arc, &mut out);
    // X end point 30 > 25 and apex Y 30 > 25.
    let sides: Vec<_> = out.iter().map(|v| (v.axis, v.side)).collect();
    assert!(sides.contains(&(0, Side::Positive)));
    assert!(sides.contains(&(1, Side::Positive)));
}

#[test]
fn arc_apex_exactly_on_limit_is_allowed() {
    let s = xy(-30.0, 30.0);
    let mut out = Vec::new();
    let arc = Segment::arc(
        vec![-30.0, 0.0],
        vec![30.0, 0.0],
        0,
        1,
        [30.0, 0.0],
        true,
        1e-6,
    )
    .unwrap();
    s.check_path(&arc, &mut out);
    assert!(out.is_empty(), "{out:?}");
}

#[test]
fn inactive_when_not_referenced_modulo_or_switched_off() {
    let mut cfg = AxisLimitConfig::linear("A", -10.0, 10.0);
    let mut s = SoftLimits::new(vec![cfg.clone()], false);
    assert!(!s.is_active(0), "not referenced");
    s.set_referenced(0, true);
    assert!(s.is_active(0));
    cfg.modulo = true;
    let mut s = SoftLimits::new(vec![cfg.clone()], false);
    s.set_referenced(0, true);
    assert!(!s.is_active(0), "modulo rotary exempt");
    cfg.check = 1;
    let mut s = SoftLimits::new(vec![cfg.clone()], false);
    s.set_referenced(0, true);
    assert!(s.is_active(0), "P-AXIS-00705 = 1 forces it on");
    cfg.check = 0;
    cfg.modulo = false;
    let mut s = SoftLimits::new(vec![cfg.clone()], false);
    s.set_referenced(0, true);
    assert!(!s.is_active(0), "P-AXIS-00705 = 0 switches it off");
    cfg.check = -1;
    cfg.absolute_encoder = true;
    let s = SoftLimits::new(vec![cfg], false);
    assert!(s.is_active(0), "P-AXIS-00014 replaces referencing");
}

#[test]
fn actual_uses_tolerance_and_behaviour() {
    let mut s = xy(-200.0, 200.0);
    assert!(
        s.check_actual(0, 200.1).is_none(),
        "limit + tolerance 0.1 is still fine"
    );
    let m = s.check_actual(0, 200.1001).unwrap();
    assert_eq!((m.id, m.severity), (70021, Severity::Error));
    let m = s.check_actual(1, -200.2).unwrap();
    assert_eq!((m.id, m.severity), (70022, Severity::Error));

    let mut cfg = AxisLimitConfig::linear("X", -10.0, 10.0);
    cfg.behaviour = SlsBehaviour::Warning;
    let mut s = SoftLimits::new(vec![cfg], false);
    s.set_referenced(0, true);
    let m = s.check_actual(0, 11.0).unwrap();
    assert_eq!((m.id, m.severity), (70021, Severity::Warning));
    assert!(s.check_actual(0, 12.0).is_none(), "once per excursion");
    assert!(s.check_actual(0, 5.0).is_none());
    assert!(
        s.check_actual(0, 11.0).is_some(),
        "re-armed after coming back"
    );
}

#[test]
fn g98_g99_absolute_and_relative_as_seed_001_3_1_and_3_2() {
    // Configured ±10000 mm (the seeds' defaults ±100000000 × 0.1 µm).
    let mut s = xy(-10000.0, 10000.0);
    // N130 G98 X-100 Y-200
    assert!(
        s.program_limit(0, Side::Negative, -100.0, false, 20.0)
            .taken_over
    );
    assert!(
        s.program_limit(1, Side::Negative, -200.0, false, 30.0)
            .taken_over
    );
    assert_eq!(s.active_limits(0), Some((-100.0, 10000.0)));
    assert_eq!(s.active_limits(1), Some((-200.0, 10000.0)));
    s.reset();
    // N130 G98 G91 X10 Y20: relative to P-AXIS-00177.
    s.program_limit(0, Side::Negative, 10.0, true, 20.0);
    s.program_limit(1, Side::Negative, 20.0, true, 30.0);
    assert_eq!(s.active_limits(0), Some((-9990.0, 10000.0)));
    assert_eq!(s.active_limits(1), Some((-9980.0, 10000.0)));
    s.reset();
    // N130 G99 X100 Y200 / G99 G91 X-10 Y-20
    s.program_limit(0, Side::Positive, 100.0, false, 20.0);
    assert_eq!(s.active_limits(0), Some((-10000.0, 100.0)));
    s.program_limit(0, Side::Positive, -10.0, true, 20.0);
    assert_eq!(s.active_limits(0), Some((-10000.0, 9990.0)));
}

#[test]
fn g98_g99_errors_and_warnings() {
    let mut s = xy(-200.0, 200.0);
    let u = s.program_limit(0, Side::Negative, 200.0, false, 0.0);
    assert_eq!((ids_of(&u.messages), u.taken_over), (vec![21649], false));
    assert!(u.messages[0].is_error());
    let u = s.program_limit(0, Side::Positive, -200.0, false, 0.0);
    assert_eq!((ids_of(&u.messages), u.taken_over), (vec![21878], false));
    // Actual position beyond the new limit: taken over, error 70021 / 70022.
    let u = s.program_limit(0, Side::Positive, 10.0, false, 20.0);
    assert_eq!((ids_of(&u.messages), u.taken_over), (vec![70021], true));
    assert_eq!(s.active_limits(0), Some((-200.0, 10.0)));
    let u = s.program_limit(1, Side::Negative, 35.0, false, 30.0);
    assert_eq!((ids_of(&u.messages), u.taken_over), (vec![70022], true));

    // P-CHAN-00498 = 1: extension refused with warnings, configured value stays.
    let mut s = SoftLimits::new(vec![AxisLimitConfig::linear("X", -200.0, 200.0)], true);
    s.set_referenced(0, true);
    let u = s.program_limit(0, Side::Negative, -500.0, false, 0.0);
    assert_eq!((ids_of(&u.messages), u.taken_over), (vec![21648], false));
    assert!(!u.messages[0].is_error());
    let u = s.program_limit(0, Side::Positive, 500.0, false, 0.0);
    assert_eq!((ids_of(&u.messages), u.taken_over), (vec![21650], false));
    assert_eq!(s.active_limits(0), Some((-200.0, 200.0)));
    // Without it (default) the extension of §3.3 is allowed.
    let mut s = xy(-200.0, 200.0);
    assert!(
        s.program_limit(0, Side::Negative, -500.0, false, 199.0)
            .taken_over
    );
    assert!(
        s.program_limit(0, Side::Positive, 500.0, false, 199.0)
            .taken_over
    );
    assert_eq!(s.active_limits(0), Some((-500.0, 500.0)));
}

#[test]
fn stop_distance_check() {
    let mut cfg = AxisLimitConfig::linear("X", -100.0, 100.0);
    cfg.check_pos_command = true;
    cfg.emergency_decel = 100.0;
    let mut s = SoftLimits::new(vec![cfg], false);
    s.set_referenced(0, true);
    // v = 10 mm/s: stop distance 0.5 mm.
    assert_eq!(s.check_stop_distance(0, 99.5, 10.0), None);
    assert_eq!(s.check_stop_distance(0, 99.6, 10.0), Some(Side::Positive));
    assert_eq!(
        s.check_stop_distance(0, -99.9, -10.0),
        None,
        "negative check not enabled"
    );
    assert_eq!(s.stop_distance_message(0, Side::Positive).id, 70195);
}

#[test]
fn jog_range_combines_sls_and_offset_limits() {
    let mut cfg = AxisLimitConfig::linear("X", -200.0, 200.0);
    cfg.manual_rel_neg = -100.0;
    cfg.manual_rel_pos = 100.0;
    let mut s = SoftLimits::new(vec![cfg.clone()], false);
    s.set_referenced(0, true);
    assert_eq!(s.jog_range(0, 150.0), (50.0, 200.0));
    s.set_referenced(0, false);
    assert_eq!(
        s.jog_range(0, 150.0),
        (50.0, 250.0),
        "not referenced: offset limits only"
    );
    cfg.manual_rel_neg = 0.0;
    cfg.manual_rel_pos = 0.0;
    cfg.manual_abs_pos = 180.0;
    let mut s = SoftLimits::new(vec![cfg], false);
    s.set_referenced(0, true);
    s.program_limit(0, Side::Positive, 500.0, false, 0.0);
    assert_eq!(
        s.jog_range(0, 0.0),
        (-200.0, 180.0),
        "absolute limit holds even when G99 extends"
    );
}

#[test]
fn pcs_limits_follow_offset() {
    let s = xy(-200.0, 200.0);
    // G92 made PCS 0 at ACS 50: offset 50.
    let p = s.pcs_limits(0, 50.0, 10.0).unwrap();
    assert_eq!((p.positive, p.negative), (150.0, -250.0));
    assert_eq!((p.distance_positive, p.distance_negative), (140.0, 260.0));
}
