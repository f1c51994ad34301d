//! Every message ID of seed 001 (FCT-A2), produced by the situation the seed describes, through
//! the whole stack: NC program → executor → channel → CiA 402 adapter → link::sim → drive model.
//!
//! Limits are set in the seeds' unit (0.1 µm): 2000000 = 200 mm. Expected values are worked out
//! by hand from the seed text.

use fieldprobe::machine::{Machine, RunReport, RunStatus};
use fieldprobe::messages::Severity;
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const XY200: &[&str] = &[
    "X.P-AXIS-00177=-2000000",
    "X.P-AXIS-00178=2000000",
    "Y.P-AXIS-00177=-2000000",
    "Y.P-AXIS-00178=2000000",
];

fn machine(sets: &[&str]) -> Machine {
    let mut cfg = MachineConfig::default_machine();
    for s in XY200.iter().chain(sets) {
        cfg.apply_set(s).unwrap();
    }
    Machine::new(&cfg).unwrap()
}

fn run_on(m: &mut Machine, src: &str) -> RunReport {
    let program = parse(src).unwrap();
    m.run_program(&program, &mut |_| {})
}

fn run(src: &str, sets: &[&str]) -> (RunReport, Machine) {
    let mut m = machine(sets);
    let r = run_on(&mut m, src);
    (r, m)
}

fn severity_of(r: &RunReport, id: u32) -> Vec<Severity> {
    r.messages()
        .iter()
        .filter(|m| m.id == id)
        .map(|m| m.severity)
        .collect()
}

fn x(m: &Machine) -> (f64, f64) {
    let a = &m.channel().axes()[0];
    (a.command(), a.actual())
}

#[test]
fn p_err_120002_block_crossing_positive_limit_is_not_executed() {
    let (r, m) = run(
        "N10 G01 G90 X100 F6000\nN20 X250\nN30 #MSG SYN[\"reached\"]\nN40 M30\n",
        &[],
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![120002]);
    assert!(r.messages()[0].is_error());
    assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(20));
    assert!(r.output().is_empty());
    // The block was not executed: the axis stays at X100 (let the position loop settle).
    let mut m = m;
    for _ in 0..1000 {
        m.step();
    }
    assert_eq!(x(&m).0, 100.0);
    assert!((x(&m).1 - 100.0).abs() < 1e-3, "actual {}", x(&m).1);
}

#[test]
fn p_err_120003_block_crossing_negative_limit_is_not_executed() {
    let (r, m) = run("N10 G01 G90 Y-250 F6000\nN20 M30\n", &[]);
    assert_eq!(r.message_ids(), vec![120003]);
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(m.channel().axes()[1].command(), 0.0);
}

#[test]
fn p_err_120002_arc_apex_beyond_limit_between_in_range_end_points() {
    // G02 from (-150,150) to (150,150) around (0,150): apex Y = 300 > 200.
    let src = "N10 G00 G90 X-150 Y150\nN20 G02 X150 Y150 I150 J0 F3000\nN30 M30\n";
    let (r, m) = run(src, &[]);
    assert_eq!(r.message_ids(), vec![120002]);
    assert_eq!(r.messages()[0].axis.as_deref(), Some("Y"));
    assert_eq!(m.channel().axes()[1].command(), 150.0);
    // The same arc with the apex below the limit (G03 goes through Y = 0) runs.
    let src = "N10 G00 G90 X-150 Y150\nN20 G03 X150 Y150 I150 J0 F6000\nN30 M30\n";
    let (r, m) = run(src, &[]);
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(m.channel().axes()[0].command(), 150.0);
}

#[test]
fn error_lr_warns_in_preparation_and_stops_on_actual_p_err_70021() {
    let (r, m) = run(
        "N10 G01 G90 X250 F6000\nN20 M30\n",
        &["X.P-AXIS-00554=ERROR_LR"],
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![120002, 70021]);
    assert_eq!(severity_of(&r, 120002), vec![Severity::Warning]);
    assert_eq!(severity_of(&r, 70021), vec![Severity::Error]);
    // Stopped with a linear deceleration after crossing 200 + 0.1 (P-AXIS-00179 = 1000).
    let (cmd, act) = x(&m);
    assert!(act > 200.1 && cmd < 250.0, "command {cmd} actual {act}");
}

#[test]
fn warning_behaviour_only_warns_and_the_program_completes() {
    let (r, m) = run(
        "N10 G01 G90 X-250 F6000\nN20 M30\n",
        &["X.P-AXIS-00554=WARNING"],
    );
    assert_eq!(r.status, RunStatus::Completed);
    assert_eq!(r.message_ids(), vec![120003, 70022]);
    assert!(r.messages().iter().all(|m| m.severity == Severity::Warning));
    assert_eq!(x(&m).0, -250.0);
}

#[test]
fn p_err_70021_and_70022_actual_beyond_newly_programmed_limit() {
    // Seed 001 §3.2: actual position greater than the new positive SLS → 70021; the new
    // position is taken over.
    let src = "N110 G00 X0 Y0 G90\nN120 G00 X20 Y30\nN130 G99 X10\nN140 M30\n";
    let (r, m) = run(src, &[]);
    assert_eq!(r.message_ids(), vec![70021]);
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(130));
    assert_eq!(
        m.channel().soft_limits().active_limits(0),
        Some((-200.0, 10.0))
    );
    // §3.1: actual smaller than the new negative SLS → 70022.
    let src = "N110 G00 X0 Y0 G90\nN120 G00 X20 Y30\nN130 G98 Y35\nN140 M30\n";
    let (r, m) = run(src, &[]);
    assert_eq!(r.message_ids(), vec![70022]);
    assert_eq!(
        m.channel().soft_limits().active_limits(1),
        Some((35.0, 200.0))
    );
}

#[test]
fn p_err_70021_from_the_drive_overshooting() {
    // A disturbance in the drive (e.g. a collision pushing the axis) moves the actual position
    // past limit + tolerance while the command stays inside.
    let mut m = machine(&[]);
    let r = run_on(&mut m, "N10 G01 G90 X199.95 F6000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed);
    // Let the position loop settle at 199.95, then push the axis by 0.2 mm (2000 increments at
    // 10000 inc/mm): 200.15 > 200 + 0.1.
    for _ in 0..2000 {
        m.step();
    }
    assert!((x(&m).1 - 199.95).abs() < 1e-3);
    m.link_mut().model_mut(0).unwrap().set_disturbance(2000.0);
    // The drive samples the pushed position at the next SYNC0; the frame after that carries it.
    m.step();
    let r = run_on(&mut m, "N10 #MSG SYN[\"not reached\"]\nN20 M30\n");
    assert_eq!(r.message_ids(), vec![70021]);
    assert_eq!(r.status, RunStatus::Aborted);
    assert!(r.output().is_empty());
}

#[test]
fn p_err_21649_and_21878_limits_must_stay_ordered() {
    let (r, _) = run("N10 G98 X200\nN20 M30\n", &[]);
    assert_eq!(r.message_ids(), vec![21649]);
    assert_eq!(r.status, RunStatus::Aborted);
    let (r, m) = run("N10 G99 X-250\nN20 M30\n", &[]);
    assert_eq!(r.message_ids(), vec![21878]);
    assert_eq!(
        m.channel().soft_limits().active_limits(0),
        Some((-200.0, 200.0))
    );
}

#[test]
fn p_err_21648_and_21650_with_range_check_p_chan_00498() {
    let src = "N100 G98 X-500 Y-500\nN200 G99 X500 Y500\nN210 #MSG SYN[\"%f %f\", V.A.-SWE.X, V.A.+SWE.X]\nN220 M30\n";
    let (r, _) = run(src, &["P-CHAN-00498=1"]);
    assert_eq!(r.status, RunStatus::Completed);
    assert_eq!(r.message_ids(), vec![21648, 21648, 21650, 21650]);
    assert!(r.messages().iter().all(|m| m.severity == Severity::Warning));
    assert_eq!(r.output(), vec!["-200.000000 200.000000"]);
    // Without P-CHAN-00498 the range is extended (seed 001 §3.3).
    let (r, _) = run(src, &[]);
    assert_eq!(r.message_ids(), Vec::<u32>::new());
    assert_eq!(r.output(), vec!["-500.000000 500.000000"]);
}

#[test]
fn p_err_70195_stop_distance_with_p_axis_00520() {
    // a_emergency 10 mm/s² (P-AXIS-00003) is far below the profile's deceleration: at 100 mm/s
    // the axis could not stop before 200 → 70195, braking in time.
    let sets = ["X.P-AXIS-00520=1", "X.P-AXIS-00003=10"];
    let (r, m) = run("N10 G01 G90 X199 F6000\nN20 M30\n", &sets);
    assert_eq!(r.message_ids(), vec![70195]);
    assert_eq!(r.status, RunStatus::Aborted);
    let (cmd, act) = x(&m);
    assert!(
        cmd <= 200.0 + 1e-9 && act <= 200.0 + 1e-9,
        "stopped before the limit: {cmd} {act}"
    );
    // Without the parameter the same move completes.
    let (r, _) = run("N10 G01 G90 X199 F6000\nN20 M30\n", &["X.P-AXIS-00003=10"]);
    assert_eq!(r.status, RunStatus::Completed);
    // Negative side needs P-AXIS-00521.
    let (r, _) = run("N10 G01 G90 X-199 F6000\nN20 M30\n", &sets);
    assert_eq!(r.status, RunStatus::Completed);
    let (r, _) = run(
        "N10 G01 G90 X-199 F6000\nN20 M30\n",
        &["X.P-AXIS-00521=1", "X.P-AXIS-00003=10"],
    );
    assert_eq!(r.message_ids(), vec![70195]);
}

#[test]
fn monitoring_needs_referencing_and_skips_modulo_axes() {
    let mut cfg = MachineConfig::default_machine();
    for s in XY200 {
        cfg.apply_set(s).unwrap();
    }
    cfg.axis_mut("X").unwrap().referenced = false;
    let mut m = Machine::new(&cfg).unwrap();
    let r = run_on(&mut m, "N10 G01 G90 X250 F6000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "not referenced: no SLS");
    // P-AXIS-00014 absolute encoder replaces referencing.
    cfg.apply_set("X.P-AXIS-00014=1").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = run_on(&mut m, "N10 G01 G90 X250 F6000\nN20 M30\n");
    assert_eq!(r.message_ids(), vec![120002]);
    // P-AXIS-00705 = 0 switches it off.
    let (r, _) = run("N10 G01 G90 X250 F6000\nN20 M30\n", &["X.P-AXIS-00705=0"]);
    assert_eq!(r.status, RunStatus::Completed);
}

#[test]
fn limits_are_restored_at_the_next_program_start() {
    let mut m = machine(&[]);
    let r = run_on(&mut m, "N10 G99 X50\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed);
    assert_eq!(
        m.channel().soft_limits().active_limits(0),
        Some((-200.0, 50.0))
    );
    let r = run_on(&mut m, "N10 #MSG SYN[\"%f\", V.A.+SWE.X]\nN20 M30\n");
    assert_eq!(r.output(), vec!["200.000000"]);
}

#[test]
fn manual_mode_p_err_50720_and_150008() {
    for warn in [false, true] {
        let sets: Vec<&str> = if warn { vec!["P-MANU-00014=1"] } else { vec![] };
        let mut m = machine(&sets);
        assert_eq!(m.settle(10_000), fieldprobe::channel::ChannelState::Idle);
        let ch = m.channel_mut();
        assert!(ch.enter_manual());
        // Relative offset limits ±100 mm (P-AXIS-00137/00138 defaults) around X0, SLS ±200.
        assert_eq!(ch.jog_range(0), Some((-100.0, 100.0)));
        assert!(ch.jog_continuous(0, 50.0));
        m.settle(1_000_000);
        let ch = m.channel_mut();
        assert_eq!(
            ch.axes()[0].command(),
            100.0,
            "stops exactly at the offset limit"
        );
        let ids: Vec<u32> = ch.take_messages().iter().map(|m| m.id).collect();
        assert_eq!(ids, if warn { vec![50720] } else { vec![] });
        // Incremental step beyond: not executed, warning 150008 regardless of P-MANU-00014.
        assert!(!ch.jog_increment(0, 0.5, 50.0));
        let msgs = ch.take_messages();
        assert_eq!(msgs.iter().map(|m| m.id).collect::<Vec<_>>(), vec![150008]);
        assert_eq!(msgs[0].severity, Severity::Warning);
        assert!(ch.jog_increment(0, -30.0, 50.0));
        m.settle(1_000_000);
        assert_eq!(m.channel().axes()[0].command(), 70.0);
    }
}

#[test]
fn manual_mode_absolute_offset_limits_hold_when_g99_extends() {
    // §3.3: P-AXIS-00493 set to the configured 200 keeps manual mode inside it after G99 X500.
    let mut m = machine(&[
        "X.P-AXIS-00493=2000000",
        "X.P-AXIS-00137=0",
        "X.P-AXIS-00138=0",
    ]);
    let r = run_on(&mut m, "N10 G99 X500\nN20 G01 X150 F6000\nN30 M30\n");
    assert_eq!(r.status, RunStatus::Completed);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    assert_eq!(ch.jog_range(0), Some((-200.0, 200.0)));
    assert!(ch.jog_continuous(0, 50.0));
    m.settle(1_000_000);
    assert_eq!(m.channel().axes()[0].command(), 200.0);
}

#[test]
fn pcs_limits_objects_with_p_chan_00489() {
    let src = "N10 G92 X50\nN20 G01 G90 X10 F3000\nN40 M30\n";
    let (r, m) = run(src, &["P-CHAN-00489=1"]);
    assert_eq!(r.status, RunStatus::Completed);
    let p = m.channel().pcs_limits(0).unwrap();
    // G92 X50: ACS = PCS + 50 (ISG reference-point offset); ACS limits ±200 → PCS 150 / −250;
    // PCS position 10.
    assert_eq!((p.positive, p.negative), (150.0, -250.0));
    assert_eq!((p.distance_positive, p.distance_negative), (140.0, 260.0));
    let (_, m) = run(src, &[]);
    assert!(
        m.channel().pcs_limits(0).is_none(),
        "display off by default"
    );
}

#[test]
fn pcs_limits_with_an_oblique_cs_follow_the_pcs_axis_to_the_first_acs_limit() {
    // X, Y ±200 mm; G99 Y150. #CS ON[0,0,0,0,0,30] (M2: ACS = R_z(30°)·PCS) at PCS (0, 0): PCS X
    // runs along (cos 30°, sin 30°) = (√3/2, 1/2) in the ACS. Going +: ACS X reaches 200 after
    // 200/(√3/2) = 400/√3 ≈ 230.94, ACS Y reaches 150 after 150/(1/2) = 300: the limit is 400/√3.
    // Going −: ACS X −200 after 400/√3, ACS Y −200 after 400: −400/√3.
    // PCS Y runs along (−1/2, √3/2): + reaches ACS Y 150 after 150/(√3/2) = 300/√3 (ACS X −200
    // only after 400); − reaches ACS Y −200 after 400/√3 (ACS X 200 after 400).
    let (r, m) = run(
        "N10 G99 Y150\nN20 #CS ON[0,0,0,0,0,30]\nN30 G01 X0 Y0 F1000\nN40 M30\n",
        &["P-CHAN-00489=1"],
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let s3 = 3f64.sqrt();
    let close = |what: &str, got: f64, expected: f64| {
        assert!(
            (got - expected).abs() < 1e-9,
            "{what}: {got}, expected {expected}"
        );
    };
    let px = m.channel().pcs_limits(0).unwrap();
    close("X +", px.positive, 400.0 / s3);
    close("X −", px.negative, -400.0 / s3);
    close("X to +", px.distance_positive, 400.0 / s3);
    close("X to −", px.distance_negative, 400.0 / s3);
    let py = m.channel().pcs_limits(1).unwrap();
    close("Y +", py.positive, 300.0 / s3);
    close("Y −", py.negative, -400.0 / s3);
    // The CNC objects carry the same in 0.1 µm (seed 001 §4.5, index group 0x121301).
    let obj = |offset| m.channel().read_cnc_object(1, 0x121301, offset).unwrap();
    close("0x10096", obj(0x10096), 300.0 / s3 * 1e4);
    close("0x10099", obj(0x10099), 400.0 / s3 * 1e4);
}

#[test]
fn pcs_limits_with_g92_and_a_rotating_cs() {
    // G92 X50 (ISG reference-point offset, N7): w = PCS + (50, 0, 0); #CS ON[0,0,0,0,0,90]:
    // ACS X = −w_y, ACS Y = w_x. PCS X runs along ACS Y: w_x = PCS X + 50 ∈ [−200, 200] →
    // PCS X ∈ [−250, 150]. PCS Y runs along −ACS X: ACS X = −PCS Y ∈ [−200, 200] → PCS Y ∈
    // [−200, 200]. At PCS (10, 20): distances X 140 / 260, Y 180 / 220.
    let (r, m) = run(
        "N10 G92 X50\nN20 #CS ON[0,0,0,0,0,90]\nN30 G01 X10 Y20 F1000\nN40 M30\n",
        &["P-CHAN-00489=1"],
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let close = |what: &str, got: f64, expected: f64| {
        assert!(
            (got - expected).abs() < 1e-9,
            "{what}: {got}, expected {expected}"
        );
    };
    let px = m.channel().pcs_limits(0).unwrap();
    close("X +", px.positive, 150.0);
    close("X −", px.negative, -250.0);
    close("X to +", px.distance_positive, 140.0);
    close("X to −", px.distance_negative, 260.0);
    let py = m.channel().pcs_limits(1).unwrap();
    close("Y +", py.positive, 200.0);
    close("Y −", py.negative, -200.0);
    close("Y to +", py.distance_positive, 180.0);
    close("Y to −", py.distance_negative, 220.0);
}

#[test]
fn limits_are_restored_at_reset_and_mode_change_but_kept_into_jog() {
    use fieldprobe::channel::OperationMode;
    let mut m = machine(&[]);
    run_on(&mut m, "N10 G99 X50\nN20 M30\n");
    // Selecting jog keeps the programmed limit (§3.3).
    assert!(m.channel_mut().enter_manual());
    assert_eq!(m.channel().jog_range(0), Some((-100.0, 50.0)));
    assert!(m.channel_mut().leave_manual());
    // A mode change (automatic → MDI) pre-assigns P-AXIS-00178 again (§3.2 Notice).
    assert!(m
        .channel_mut()
        .select_operation_mode(OperationMode::ManualBlock));
    assert_eq!(
        m.channel().soft_limits().active_limits(0),
        Some((-200.0, 200.0))
    );
    run_on(&mut m, "N10 G98 X-50\nN20 M30\n");
    assert_eq!(
        m.channel().soft_limits().active_limits(0),
        Some((-50.0, 200.0))
    );
    // Controller reset does too.
    m.channel_mut().reset();
    assert_eq!(
        m.channel().soft_limits().active_limits(0),
        Some((-200.0, 200.0))
    );
}
