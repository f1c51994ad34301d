//! Dynamics of measurement runs (seed 004 §2.1, §3, §8.2): the deceleration after the probing
//! signal per the non-linear slope table (P-CHAN-00296 / 00214 / 00097), the profile
//! acceleration, the probe stroke P-AXIS-00086 (types 2 and 4), the overtravel P-AXIS-00467 and
//! measuring paths at the software limit switch (P-CHAN-00268).
//!
//! The machine is driven cycle by cycle (1 ms) and the command positions are recorded, so
//! decelerations and distances are measured from the set-points, and compared with closed-form
//! values: v²/(2a), Δv = a·T per cycle, u·2T + u²/(2a) = stroke.

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
/// Z is channel axis 2.
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

/// A program run cycle by cycle (the loop of `Machine::run_program`).
struct Traced {
    exec: Executor,
    messages: Vec<CncMessage>,
    completed: bool,
    /// (command, actual) of every axis after every interpolation cycle.
    samples: Vec<Vec<(f64, f64)>>,
}

impl Traced {
    fn ids(&self) -> Vec<u32> {
        self.messages.iter().map(|m| m.id).collect()
    }

    fn command(&self, axis: usize) -> Vec<f64> {
        self.samples.iter().map(|s| s[axis].0).collect()
    }

    fn actual(&self, axis: usize) -> Vec<f64> {
        self.samples.iter().map(|s| s[axis].1).collect()
    }
}

fn run_traced(m: &mut Machine, src: &str, max_cycles: u64) -> Traced {
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
    let mut messages = Vec::new();
    let mut samples = Vec::new();
    let mut out = Vec::new();
    let mut completed = false;
    loop {
        messages.extend(m.channel_mut().take_messages());
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                let step = exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    completed = true;
                    break;
                }
            }
            _ => {
                assert!(
                    (samples.len() as u64) < max_cycles,
                    "run exceeded {max_cycles} cycles"
                );
                m.step();
                samples.push(
                    m.channel()
                        .axes()
                        .iter()
                        .map(|a| (a.command(), a.actual()))
                        .collect(),
                );
            }
        }
    }
    messages.extend(m.channel_mut().take_messages());
    Traced {
        exec,
        messages,
        completed,
        samples,
    }
}

/// Velocities between consecutive samples (mm/s).
fn velocities(c: &[f64]) -> Vec<f64> {
    c.windows(2).map(|w| (w[1] - w[0]) / T).collect()
}

/// Index of the first sample whose actual position has passed `p` moving up.
fn crossing(actual: &[f64], p: f64) -> usize {
    actual
        .iter()
        .position(|x| *x >= p)
        .expect("the axis crossed the probe")
}

// ---------------------------------------------------------------------------------------------
// §2.1 deceleration after the probing signal (non-linear slope table)
// ---------------------------------------------------------------------------------------------

/// Distinct accelerations (mm/s²): P-AXIS-00008 a_max 4000 (the others must not exceed it),
/// P-AXIS-00004 rapid 2000, P-AXIS-00053 feedhold 500, P-AXIS-00001 feed 800, P-AXIS-00002
/// feed deceleration 1200.
const A_MAX: &str = "Z.P-AXIS-00008=4000";
const A_RAPID: f64 = 2000.0;
const A_FEEDH: f64 = 500.0;
const A_FEED: f64 = 800.0;
const D_FEED: f64 = 1200.0;

fn dynamics_sets<'a>(chan: &[&'a str]) -> Vec<&'a str> {
    let mut v = vec![
        A_MAX,
        "Z.P-AXIS-00004=2000",
        "Z.P-AXIS-00053=500",
        "Z.P-AXIS-00001=800",
        "Z.P-AXIS-00002=1200",
    ];
    v.extend_from_slice(chan);
    v
}

/// What a braking after the latch looked like.
#[derive(Debug)]
struct Braking {
    /// Command velocity before the latch.
    v: f64,
    /// Velocity decrease per cycle during braking, divided by T (mm/s²), all full cycles.
    decels: Vec<f64>,
    /// Distance the command travelled from the set-point of the cycle before the latch was seen
    /// to standstill.
    distance: f64,
    /// Velocity increase per cycle / T at the start of the block (the profile acceleration).
    accel: f64,
}

/// `G100 Z100 F3000` (50 mm/s) from Z = 0 with the probe at Z = 40; the latch is seen in the
/// cycle in which the actual position passes 40 (the drive latches inside that cycle).
fn brake_after_latch(sets: &[&str]) -> Braking {
    let mut m = machine(sets);
    m.add_probe("Z", 40.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", 20_000);
    assert!(t.completed, "{:?}", t.messages);
    assert_eq!(t.ids(), Vec::<u32>::new());
    close(
        "latched",
        t.exec.result(Z).expect("Z latched").acs,
        40.0,
        LATCH_TOL,
    );
    let c = t.command(Z);
    let k = crossing(&t.actual(Z), 40.0);
    let v = velocities(&c);
    // v[j] is the velocity from sample j to j + 1. Sample k is the first braking set-point.
    let v_before = v[k - 2];
    let mut decels = Vec::new();
    let mut j = k;
    while j + 1 < v.len() && v[j + 1] > 1e-9 {
        decels.push((v[j] - v[j + 1]) / T);
        j += 1;
    }
    // The last one is a partial cycle (the stop falls between two cycles).
    decels.pop();
    let first = v.iter().position(|x| *x > 0.0).unwrap();
    let accel = (v[first + 2] - v[first + 1]) / T;
    Braking {
        v: v_before,
        decels,
        distance: c[c.len() - 1] - c[k - 1],
        accel,
    }
}

#[track_caller]
fn assert_brakes_with(b: &Braking, a: f64) {
    close("cruise velocity", b.v, 50.0, 1e-6);
    assert!(b.decels.len() > 5, "{b:?}");
    for d in &b.decels {
        close("deceleration per cycle", *d, a, 1e-6 * a);
    }
    // Stop distance v²/(2a) from the set-point the braking started at; slack: two cycles of
    // travel at v (the braking is sampled once per cycle and its first sample is the first set-
    // point after the latch was seen).
    close(
        "stop distance",
        b.distance,
        b.v * b.v / (2.0 * a),
        2.0 * b.v * T,
    );
}

#[test]
fn brake_000_rapid_deceleration_p_axis_00004() {
    let b = brake_after_latch(&dynamics_sets(&[]));
    assert_brakes_with(&b, A_RAPID);
}

#[test]
fn brake_001_feedhold_deceleration_p_axis_00053() {
    let b = brake_after_latch(&dynamics_sets(&["P-CHAN-00097=1"]));
    assert_brakes_with(&b, A_FEEDH);
}

#[test]
fn brake_010_and_011_rapid_deceleration_p_axis_00004() {
    let b = brake_after_latch(&dynamics_sets(&["P-CHAN-00214=1"]));
    assert_brakes_with(&b, A_RAPID);
    let b = brake_after_latch(&dynamics_sets(&["P-CHAN-00214=1", "P-CHAN-00097=1"]));
    assert_brakes_with(&b, A_RAPID);
}

#[test]
fn brake_1xx_feedhold_deceleration_p_axis_00053() {
    for chan in [
        &["P-CHAN-00296=1"][..],
        &["P-CHAN-00296=1", "P-CHAN-00097=1"],
        &["P-CHAN-00296=1", "P-CHAN-00214=1"],
        &["P-CHAN-00296=1", "P-CHAN-00214=1", "P-CHAN-00097=1"],
    ] {
        let b = brake_after_latch(&dynamics_sets(chan));
        assert_brakes_with(&b, A_FEEDH);
    }
}

#[test]
fn brake_feedhold_without_p_axis_00053_falls_back_to_p_axis_00004() {
    // P-CHAN-00097 §8.2.1: "If these two parameters are not set, deceleration takes place at
    // the currently valid deceleration rate (P-AXIS-00004)".
    let sets = [
        A_MAX,
        "Z.P-AXIS-00004=2000",
        "Z.P-AXIS-00053=0",
        "P-CHAN-00097=1",
    ];
    assert_brakes_with(&brake_after_latch(&sets), A_RAPID);
}

#[test]
fn brake_on_a_line_respects_every_axis() {
    // G100 X100 Z100 (45°): X may brake with 2000 mm/s² (P-AXIS-00004), Z only with 1000; the
    // path brakes so that no axis exceeds its own value: both axes decelerate with 1000.
    let sets = [
        "X.P-AXIS-00008=4000",
        "X.P-AXIS-00004=2000",
        "Z.P-AXIS-00004=1000",
    ];
    let mut m = machine(&sets);
    m.add_probe("Z", 40.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 X100 Z100 F3000\nN20 M30\n", 20_000);
    assert!(t.completed && t.messages.is_empty(), "{:?}", t.messages);
    let k = crossing(&t.actual(Z), 40.0);
    for axis in [0, Z] {
        let v = velocities(&t.command(axis));
        // Axis share of F3000 on the 45° line.
        close("axis velocity", v[k - 2], 50.0 / 2f64.sqrt(), 1e-6);
        close("axis deceleration", (v[k + 1] - v[k + 2]) / T, 1000.0, 1e-3);
    }
}

#[test]
fn profile_acceleration_rapid_unless_p_chan_00296() {
    // Column "profile dynamic (1), measurement signal inactive": G00 acceleration P-AXIS-00004
    // with P-CHAN-00296 = 0, machining acceleration P-AXIS-00001 with P-CHAN-00296 = 1.
    let b = brake_after_latch(&dynamics_sets(&[]));
    close("rapid acceleration", b.accel, A_RAPID, 1e-6 * A_RAPID);
    let b = brake_after_latch(&dynamics_sets(&["P-CHAN-00296=1"]));
    close("feed acceleration", b.accel, A_FEED, 1e-6 * A_FEED);
}

#[test]
fn profile_deceleration_at_the_target_without_signal() {
    // Without a probing signal the block decelerates into its target with the profile
    // deceleration: P-AXIS-00004 (G00 dynamics), or P-AXIS-00002 with P-CHAN-00296 = 1.
    for (chan, a) in [(&[][..], A_RAPID), (&["P-CHAN-00296=1"][..], D_FEED)] {
        let mut m = machine(&dynamics_sets(chan));
        let t = run_traced(&mut m, "N10 G100 Z20 F3000\nN20 M30\n", 20_000);
        assert!(t.completed && t.messages.is_empty(), "{:?}", t.messages);
        let c = t.command(Z);
        assert_eq!(c[c.len() - 1], 20.0);
        let v = velocities(&c);
        let last = v.iter().rposition(|x| *x > 0.0).unwrap();
        // Two full deceleration cycles before the end.
        close(
            "profile deceleration",
            (v[last - 3] - v[last - 2]) / T,
            a,
            1e-6 * a,
        );
    }
}

// ---------------------------------------------------------------------------------------------
// P-AXIS-00086 probe stroke (types 2 and 4)
// ---------------------------------------------------------------------------------------------

/// Largest axis velocity whose braking stays inside `stroke` with a dead time of two cycles:
/// u·2T + u²/(2a) = stroke.
fn stroke_velocity(stroke: f64, a: f64) -> f64 {
    a * (-2.0 * T + (4.0 * T * T + 2.0 * stroke / a).sqrt())
}

/// Run a measuring block with the given type from Z = 0 to 100 at F3000 (type 2: P-AXIS-00215
/// = 50 mm/s), probe at 40, stroke 0.5 mm; returns (trace, cruise velocity, command travel from
/// the set-point the drive followed when the probe switched to standstill).
fn stroke_run(mtype: u8) -> (Traced, f64, f64) {
    let mut m = machine(&[
        "Z.P-AXIS-00086=5000",
        "Z.P-AXIS-00215=50000",
        &format!("P-CHAN-00057={mtype}"),
    ]);
    m.add_probe("Z", 40.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", 20_000);
    let c = t.command(Z);
    let k = crossing(&t.actual(Z), 40.0);
    let v = velocities(&c);
    let cruise = v[k - 3];
    // The probe switched inside cycle k; the drive was following set-points up to c[k − 1],
    // and c[k − 2] at the start of that cycle.
    let travel = c[c.len() - 1] - c[k - 2];
    (t, cruise, travel)
}

#[test]
fn stroke_limits_the_feed_of_types_2_and_4() {
    // Braking deceleration (table row 000): P-AXIS-00004 = 1000 mm/s².
    let u = stroke_velocity(0.5, 1000.0);
    assert!(u < 50.0);
    for mtype in [2, 4] {
        let (t, cruise, travel) = stroke_run(mtype);
        assert!(t.completed, "type {mtype}: {:?}", t.messages);
        assert_eq!(t.ids(), vec![900044], "type {mtype}: warning, feed reduced");
        assert!(!t.messages[0].is_error());
        close(&format!("type {mtype} reduced feed"), cruise, u, 1e-6);
        assert!(
            travel <= 0.5 + 1e-9,
            "type {mtype}: braking travel {travel} exceeds the stroke 0.5"
        );
        close("latched", t.exec.result(Z).unwrap().acs, 40.0, LATCH_TOL);
    }
}

#[test]
fn stroke_is_not_applied_to_type_1() {
    let (t, cruise, travel) = stroke_run(1);
    assert!(t.completed && t.messages.is_empty(), "{:?}", t.messages);
    close("programmed feed", cruise, 50.0, 1e-6);
    // 50·2T + 50²/2000 = 1.35 mm > stroke: the type 1 braking is not limited.
    assert!(travel > 1.2, "{travel}");
}

#[test]
fn a_large_stroke_keeps_the_feed() {
    // Default stroke 5 mm: 50·0.002 + 50²/2000 = 1.35 mm fits, no warning.
    let mut m = machine(&["P-CHAN-00057=4"]);
    m.add_probe("Z", 40.0).unwrap();
    let t = run_traced(&mut m, "N10 G100 Z100 F3000\nN20 M30\n", 20_000);
    assert!(t.completed && t.messages.is_empty(), "{:?}", t.messages);
    let v = velocities(&t.command(Z));
    close("feed", v[v.len() / 4], 50.0, 1e-6);
}

// ---------------------------------------------------------------------------------------------
// P-AXIS-00467 overtravel
// ---------------------------------------------------------------------------------------------

/// `G100 Z50` with 2 mm overtravel (P-AXIS-00467 = 20000 × 0.1 µm), probe at `probe`.
fn overtravel_run(mtype: u8, probe: f64) -> (RunReport, Machine) {
    let mut m = machine(&["Z.P-AXIS-00467=20000", &format!("P-CHAN-00057={mtype}")]);
    m.add_probe("Z", probe).unwrap();
    let r = run(&mut m, "N10 G100 Z50 F1000\nN20 M30\n");
    (r, m)
}

#[test]
fn overtravel_finds_the_probe_past_the_target() {
    // Probe at 51: past the target 50, within the 2 mm overtravel. The value is measured; the
    // interrupt came after the target was reached, so V.A.MERF ("measurement interrupt received
    // before the target position is reached", §5) is 0.
    for mtype in [1, 2] {
        let (r, _) = overtravel_run(mtype, 51.0);
        assert_eq!(
            r.status,
            RunStatus::Completed,
            "type {mtype}: {:?}",
            r.messages()
        );
        assert!(r.messages().is_empty(), "{:?}", r.messages());
        let z = &r.measurements[Z];
        close("latched", z.result.expect("measured").acs, 51.0, LATCH_TOL);
        close("MOFFS", z.result.unwrap().moffs, 1.0, LATCH_TOL);
        assert!(!z.merf, "type {mtype}: latched after the target");
    }
}

#[test]
fn overtravel_ends_at_target_plus_overtravel() {
    // Probe at 53: beyond 50 + 2. Type 1: no value, no error; the axis went to 52 at most.
    let (r, m) = overtravel_run(1, 53.0);
    assert_eq!(r.status, RunStatus::Completed);
    assert!(r.messages().is_empty(), "{:?}", r.messages());
    assert_eq!(r.measurements[Z].result, None);
    assert!(!r.measurements[Z].merf);
    let z = m.channel().axes()[Z].command();
    close("end of the overtravel", z, 52.0, 1e-9);
    // Type 2: the missing signal is an error.
    let (r, _) = overtravel_run(2, 53.0);
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900041]);
}

#[test]
fn overtravel_is_not_used_by_type_3() {
    // §8.2.2 P-AXIS-00467: "not effective in measurement type 3".
    let (r, m) = overtravel_run(3, 51.0);
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.measurements[Z].result, None);
    assert_eq!(m.channel().axes()[Z].command(), 50.0);
}

// ---------------------------------------------------------------------------------------------
// P-CHAN-00268: measuring path at the software limit switch
// ---------------------------------------------------------------------------------------------

/// Positive SLS of Z at 150 mm (P-AXIS-00178 = 1500000 × 0.1 µm); `G100 Z200` from 0.
fn sls_run(chan: &str, probe: Option<f64>) -> (RunReport, Machine) {
    let mut m = machine(&["Z.P-AXIS-00178=1500000", chan]);
    if let Some(p) = probe {
        m.add_probe("Z", p).unwrap();
    }
    let r = run(&mut m, "N10 G100 Z200 F3000\nN20 M30\n");
    (r, m)
}

#[test]
fn target_beyond_the_sls_is_refused_without_p_chan_00268() {
    let (r, m) = sls_run("P-CHAN-00268=0", Some(120.0));
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![120002]);
    assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(10));
    assert_eq!(
        m.channel().axes()[Z].command(),
        0.0,
        "the block was not executed"
    );
}

#[test]
fn with_p_chan_00268_the_run_stops_at_the_sls_and_reports_50706() {
    let (r, m) = sls_run("P-CHAN-00268=1", None);
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![50706]);
    assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(10));
    assert_eq!(r.measurements[Z].result, None);
    assert!(!r.measurements[Z].merf);
    // It went all the way to the limit (within the error reaction, see the next test).
    close("at the SLS", m.channel().axes()[Z].command(), 150.0, 1e-3);
}

#[test]

fn with_p_chan_00268_the_command_never_passes_the_sls() {
    let (r, m) = sls_run("P-CHAN-00268=1", None);
    assert_eq!(r.message_ids(), vec![50706]);
    let z = m.channel().axes()[Z].command();
    assert!(z <= 150.0, "command {z} beyond the SLS 150");
}

#[test]
fn with_p_chan_00268_a_signal_before_the_sls_measures_normally() {
    let (r, m) = sls_run("P-CHAN-00268=1", Some(120.0));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(r.messages().is_empty());
    let z = &r.measurements[Z];
    close("latched", z.result.unwrap().acs, 120.0, LATCH_TOL);
    assert!(z.merf);
    assert!(m.channel().axes()[Z].command() < 150.0);
}

#[test]
fn overtravel_is_cut_silently_at_the_sls() {
    // Target 149 inside the SLS, overtravel 5 mm would reach 154: the path ends at 150 without
    // a message (type 1, no signal).
    let mut m = machine(&["Z.P-AXIS-00178=1500000", "Z.P-AXIS-00467=50000"]);
    let r = run(&mut m, "N10 G100 Z149 F3000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(r.messages().is_empty());
    assert_eq!(m.channel().axes()[Z].command(), 150.0);
}
