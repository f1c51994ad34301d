//! Measured-value detection in the CNC (seed 004 §7.1–§7.5, parameters §8.2.2 / §8.2.3): PLC
//! sampled signals, `PLC_FIRST_EVENT`, external latch control and its handshake, DC timestamp
//! back-calculation (notes cnc.md §4.4) and fixed-stop detection (§7.3).
//!
//! Expected values come from formulas written out in each test (v·T for sampled signals,
//! a·T²/8 for linear interpolation, the fallback chains as the parameter descriptions state
//! them), never from running the code under test.

use fieldprobe::core::measure::fixed_stop::{
    Detected, FixedStopAxis, FixedStopDetector, FixedStopError, FixedStopParams, Origin,
    PER_MILLE_ERROR_ID, PER_MILLE_WARNING_ID,
};
use fieldprobe::core::measure::plc::{
    reset_preparations, AxisPlc, BlockGate, ControlUnit, EvaluatorConfig, ExtLatchClient,
    ExtLatchConfig, ExtLatchError, ExtLatchEvaluator, ExtLatchStatus, ExtLatchTask, PlcEvaluator,
    PlcFirstEventEvaluator, PreparationReset, ProbeReadiness, SignalEvaluator, SourceError,
    SourceEvaluator, SourceEvent, TimestampConfig, TimestampEvaluator,
};
use fieldprobe::core::measure::timestamp::{
    dc32_diff, DcClock, DeadTimes, Interpolation, TimestampBuffer, TimestampError,
};
use fieldprobe::core::measure::SignalSource;
use fieldprobe::drive::ProbeEdge;
use fieldprobe::messages::Severity;
use fieldprobe::params::{id, ParamSet, Scope};
use fieldprobe::sim::plc::{
    AckScript, InputEdge, ScriptedInputs, ScriptedPlc, SimPlcConfig, SimPlcMode, SimProbeState,
    TimestampOutput,
};
use fieldprobe::units::Nanos;
use proptest::prelude::*;

const MS: u64 = 1_000_000;
const T_NC: u64 = MS;
/// Feeds of the sweeps, mm/min (up to 10 m/min).
const FEEDS: [f64; 6] = [60.0, 480.0, 1000.0, 3000.0, 6000.0, 10_000.0];
/// 0.1 µm in mm: the slack the notes (cnc.md §6) allow on top of the interpolation bound.
const TENTH_UM: f64 = 1e-4;

fn ns_to_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// x(t) = x0 + v·t + a·t²/2 with t in s.
#[derive(Debug, Clone, Copy)]
struct Motion {
    x0: f64,
    v: f64,
    a: f64,
}

impl Motion {
    fn at(&self, t_ns: u64) -> f64 {
        let t = ns_to_s(t_ns);
        self.x0 + self.v * t + 0.5 * self.a * t * t
    }

    fn at_signed(&self, t_ns: i64) -> f64 {
        let t = t_ns as f64 * 1e-9;
        self.x0 + self.v * t + 0.5 * self.a * t * t
    }

    fn vel(&self, t_ns: i64) -> f64 {
        self.v + self.a * t_ns as f64 * 1e-9
    }
}

/// One NC cycle: plant edges visible, PLC steps, then the CNC evaluates.
fn nc_cycle(now: Nanos, inputs: &mut ScriptedInputs, plc: &mut ScriptedPlc, axis: &mut AxisPlc) {
    inputs.advance(now);
    plc.step(now, inputs, axis);
}

fn rising(at: u64) -> InputEdge {
    InputEdge {
        probe: 0,
        rising: true,
        at: Nanos(at),
    }
}

fn falling(at: u64) -> InputEdge {
    InputEdge {
        probe: 0,
        rising: false,
        at: Nanos(at),
    }
}

// ---------------------------------------------------------------------------------------------
// Control units
// ---------------------------------------------------------------------------------------------

#[test]
fn control_unit_uses_command_only_when_enabled() {
    let mut u = ControlUnit::new(0i64);
    assert_eq!(u.effective(7), 7, "not enabled: the CNC's own value");
    u.command_w = 42;
    assert_eq!(u.effective(7), 7, "command without enable is ignored");
    u.plc_command(42);
    assert_eq!(u.publish(7), 42);
    assert_eq!((u.request_r, u.state_r), (7, 42));
    u.plc_release();
    assert_eq!(u.publish(9), 9);
    assert_eq!((u.request_r, u.state_r), (9, 9));

    let mut axis = AxisPlc::default();
    assert!(!axis.probing_signal());
    assert_eq!(axis.timestamp(), None);
    assert_eq!(axis.probing_position(12.5), 12.5);
    axis.probing_position.plc_command(3.0);
    axis.timestamp.plc_command(99);
    axis.publish(12.5);
    assert_eq!(axis.probing_position.state_r, 3.0);
    assert_eq!(axis.probing_position.request_r, 12.5);
    assert_eq!(axis.timestamp(), Some(99));
}

// ---------------------------------------------------------------------------------------------
// PLC (seed 004 §7.1): sampled in the CNC cycle
// ---------------------------------------------------------------------------------------------

/// Run a constant-feed approach through `surface` with a PLC of `period`/`phase`; returns the
/// events of a `PLC` evaluator armed at t = 0.
fn sampled_run(
    feed_mm_min: f64,
    dir: f64,
    surface_offset: f64,
    period: u64,
    phase: u64,
    latency: u64,
) -> (Vec<SourceEvent>, f64, f64) {
    let v = feed_mm_min / 60.0;
    let m = Motion {
        x0: 100.0,
        v: dir * v,
        a: 0.0,
    };
    let surface = m.x0 + dir * surface_offset;
    // Crossing at t_c = offset / v; the edge is stamped at the next whole ns (x(at) is past
    // the surface).
    let t_c = (surface_offset / v * 1e9).ceil() as u64;
    let mut inputs = ScriptedInputs::new(&[false], vec![rising(t_c)]);
    let mut cfg = SimPlcConfig::new(Nanos(period));
    cfg.phase = Nanos(phase);
    let mut plc = ScriptedPlc::new(cfg);
    let mut axis = AxisPlc::default();
    let mut ev = PlcEvaluator::new(ProbeEdge::Positive, Nanos(latency));
    let mut events = Vec::new();
    for k in 0..(t_c / T_NC + 20) {
        let now = Nanos(k * T_NC);
        nc_cycle(now, &mut inputs, &mut plc, &mut axis);
        if k == 0 {
            ev.arm(now, &axis);
        }
        if let Some(e) = ev.update(now, m.at(now.0), &axis).unwrap() {
            events.push(e);
        }
    }
    (events, surface, v)
}

#[test]
fn plc_sampled_value_lies_behind_the_crossing_by_at_most_v_t() {
    let t = ns_to_s(T_NC);
    for feed in FEEDS {
        for dir in [1.0, -1.0] {
            for frac in [0.0, 0.13, 0.5, 0.87, 0.999] {
                let v = feed / 60.0;
                let offset = v * (10.0 + frac) * t;
                let (events, surface, v) = sampled_run(feed, dir, offset, T_NC, 0, T_NC);
                assert_eq!(events.len(), 1, "feed {feed} dir {dir} frac {frac}");
                let e = events[0];
                // Bias in the direction of motion: the sample is taken at or after the edge.
                let err = (e.position - surface) * dir;
                assert!(
                    err >= -1e-9 && err <= v * t + 1e-9,
                    "feed {feed} dir {dir} frac {frac}: error {err} outside [0, v·T = {}]",
                    v * t
                );
                assert!(e.error_bound >= err - 1e-12);
                assert!((e.error_bound - v * t).abs() < 1e-9, "bound = v·T");
            }
        }
    }
}

#[test]
fn plc_sampled_with_slower_asynchronous_plc_stays_within_v_times_latency() {
    // PLC every 4 ms, first cycle at 0.7 ms; worst-case latency = PLC period + NC cycle.
    let (period, phase) = (4 * MS, 700_000);
    let latency = period + T_NC;
    for feed in FEEDS {
        for frac in [0.05, 0.4, 0.95, 2.3, 3.7] {
            let v = feed / 60.0;
            let offset = v * (10.0 + frac) * ns_to_s(T_NC);
            let (events, surface, v) = sampled_run(feed, 1.0, offset, period, phase, latency);
            assert_eq!(events.len(), 1);
            let err = events[0].position - surface;
            assert!(
                err >= -1e-9 && err <= v * ns_to_s(latency) + 1e-9,
                "feed {feed}: {err}"
            );
        }
    }
}

#[test]
fn plant_edges_feed_the_scripted_plc() {
    use fieldprobe::sim::plant::{Plant, ProbeSurface};
    // The plant is unit-agnostic (drive increments); a surface at 12.345 on device 0, crossed at
    // 8 mm/s. Sampled PLC and timestamp both from the plant's exact edges.
    let v = 480.0 / 60.0;
    let surface = 12.345;
    let mut plant = Plant::new();
    plant.add_probe_surface(ProbeSurface::new(0, surface, vec![(0, 1)]));
    let mut cfg = SimPlcConfig::new(Nanos(T_NC));
    cfg.timestamp = Some(TimestampOutput {
        clock: DcClock::default(),
        terminal_delay_ns: 0,
        edge: ProbeEdge::Positive,
    });
    let mut plc = ScriptedPlc::new(cfg);
    let mut axis = AxisPlc::default();
    let mut sampled = PlcEvaluator::new(ProbeEdge::Positive, Nanos(T_NC));
    let mut stamped = TimestampEvaluator::new(ts_config(DeadTimes::default()));
    let (mut got_sampled, mut got_stamped) = (None, None);
    for k in 0..3000u64 {
        let (start, end) = (k.saturating_sub(1) * T_NC, k * T_NC);
        let traj = [
            (Nanos(start), v * ns_to_s(start)),
            (Nanos(end), v * ns_to_s(end)),
        ];
        plant.advance(Nanos(start), Nanos(end), |_| Some(&traj[..]));
        let now = Nanos(end);
        plc.step(now, &plant, &mut axis);
        if k == 0 {
            sampled.arm(now, &axis);
            stamped.arm(now, &axis);
        }
        let actual = v * ns_to_s(end);
        got_sampled = got_sampled.or(sampled.update(now, actual, &axis).unwrap());
        got_stamped = got_stamped.or(stamped.update(now, actual, &axis).unwrap());
    }
    let e = got_sampled.expect("sampled event");
    assert!(e.position >= surface && e.position - surface <= v * ns_to_s(T_NC) + 1e-9);
    let e = got_stamped.expect("timestamp event");
    // The plant rounds the crossing to whole ns: ≤ v·1 ns.
    assert!(
        (e.position - surface).abs() <= v * 1e-9 + 1e-9,
        "{}",
        e.position
    );
}

// ---------------------------------------------------------------------------------------------
// PLC vs PLC_FIRST_EVENT
// ---------------------------------------------------------------------------------------------

/// Drive an evaluator with a level sequence (one level per CNC cycle, armed after cycle 0);
/// returns the cycle indices of the events.
fn level_events(ev: &mut dyn SignalEvaluator, levels: &[bool]) -> Vec<usize> {
    let mut axis = AxisPlc::default();
    let mut out = Vec::new();
    for (k, &level) in levels.iter().enumerate() {
        axis.probing_signal.plc_command(level);
        let now = Nanos(k as u64 * T_NC);
        if k == 0 {
            ev.arm(now, &axis);
        }
        if ev.update(now, k as f64, &axis).unwrap().is_some() {
            out.push(k);
        }
    }
    out
}

#[test]
fn plc_triggers_on_every_configured_edge_first_event_once_on_true() {
    let (f, t) = (false, true);
    // A bouncing probe.
    let bounce = [f, t, f, t, t, f, t, t];
    let mut plc_pos = PlcEvaluator::new(ProbeEdge::Positive, Nanos(T_NC));
    assert_eq!(level_events(&mut plc_pos, &bounce), vec![1, 3, 6]);
    let mut first = PlcFirstEventEvaluator::new(Nanos(T_NC));
    assert_eq!(level_events(&mut first, &bounce), vec![1]);
    assert!(first.has_fired());

    // P-AXIS-00518 = NEG: PLC takes the falling edges, FIRST_EVENT ignores the parameter.
    let mut plc_neg = PlcEvaluator::new(ProbeEdge::Negative, Nanos(T_NC));
    assert_eq!(level_events(&mut plc_neg, &bounce), vec![2, 5]);
    let cfg = EvaluatorConfig {
        edge: ProbeEdge::Negative,
        latency: Nanos(T_NC),
        hardware_bound: 0.0,
        timestamp: ts_config(DeadTimes::default()),
    };
    let mut first_neg = SourceEvaluator::for_source(SignalSource::PlcFirstEvent, &cfg).unwrap();
    assert_eq!(level_events(&mut first_neg, &bounce), vec![1]);

    // A level present at arming is no edge: TRUE at arming must drop first (stale latch).
    let stale = [t, t, t, f, f, t, f, t];
    let mut plc_pos = PlcEvaluator::new(ProbeEdge::Positive, Nanos(T_NC));
    assert_eq!(level_events(&mut plc_pos, &stale), vec![5, 7]);
    let mut first = PlcFirstEventEvaluator::new(Nanos(T_NC));
    assert_eq!(level_events(&mut first, &stale), vec![5]);
}

#[test]
fn first_event_is_one_shot_until_rearmed() {
    let mut first = PlcFirstEventEvaluator::new(Nanos(T_NC));
    let mut axis = AxisPlc::default();
    axis.probing_signal.plc_command(false);
    first.arm(Nanos(0), &axis);
    axis.probing_signal.plc_command(true);
    assert!(first.update(Nanos(T_NC), 1.0, &axis).unwrap().is_some());
    axis.probing_signal.plc_command(false);
    assert!(first.update(Nanos(2 * T_NC), 2.0, &axis).unwrap().is_none());
    axis.probing_signal.plc_command(true);
    assert!(
        first.update(Nanos(3 * T_NC), 3.0, &axis).unwrap().is_none(),
        "no re-trigger"
    );
    // Re-armed while TRUE: waits for FALSE, then fires once more.
    first.arm(Nanos(3 * T_NC), &axis);
    assert!(first.update(Nanos(4 * T_NC), 4.0, &axis).unwrap().is_none());
    axis.probing_signal.plc_command(false);
    assert!(first.update(Nanos(5 * T_NC), 5.0, &axis).unwrap().is_none());
    axis.probing_signal.plc_command(true);
    let e = first.update(Nanos(6 * T_NC), 6.0, &axis).unwrap().unwrap();
    assert_eq!((e.position, e.at), (6.0, Nanos(6 * T_NC)));
    // Disarmed: nothing.
    first.disarm();
    assert!(!first.is_armed());
}

#[test]
fn short_pulse_between_plc_samples_is_lost_for_plc_but_caught_by_first_event_latch() {
    // PLC every 4 ms; the probe pulses from 5.2 ms to 6.1 ms, between the samples at 4 and 8 ms.
    let edges = vec![rising(5_200_000), falling(6_100_000)];
    let period = 4 * MS;
    let run = |mode: SimPlcMode, ev: &mut dyn SignalEvaluator| -> Vec<u64> {
        let mut inputs = ScriptedInputs::new(&[false], edges.clone());
        let mut cfg = SimPlcConfig::new(Nanos(period));
        cfg.mode = mode;
        let mut plc = ScriptedPlc::new(cfg);
        let mut axis = AxisPlc::default();
        let mut hits = Vec::new();
        for k in 0..20 {
            let now = Nanos(k * T_NC);
            nc_cycle(now, &mut inputs, &mut plc, &mut axis);
            if k == 0 {
                ev.arm(now, &axis);
            }
            if ev.update(now, k as f64, &axis).unwrap().is_some() {
                hits.push(now.0);
            }
        }
        hits
    };
    let mut plc_ev = PlcEvaluator::new(ProbeEdge::Positive, Nanos(period + T_NC));
    assert!(run(SimPlcMode::Signal, &mut plc_ev).is_empty());
    let mut first = PlcFirstEventEvaluator::new(Nanos(period + T_NC));
    let latch = SimPlcMode::FirstEventLatch {
        edge: ProbeEdge::Positive,
    };
    assert_eq!(
        run(latch, &mut first),
        vec![8 * MS],
        "seen at the next PLC cycle"
    );
}

// ---------------------------------------------------------------------------------------------
// PLC_EXT_LATCH_CONTROL (seed 004 §7.4)
// ---------------------------------------------------------------------------------------------

fn ext_client(
    source: SignalSource,
    input: u8,
    edge: ProbeEdge,
    timeout: Option<u64>,
) -> ExtLatchClient {
    ExtLatchClient::new(ExtLatchConfig::new(source, input, edge, timeout.map(Nanos)).unwrap())
}

#[test]
fn ext_latch_takes_the_hardware_position_after_enable_independent_of_the_edge_parameter() {
    // Seed example: input 4, edge NEG. The probe's signal falls at the crossing; the PLC raises
    // probing_signal (positive edge) after writing probing_position.
    let m = Motion {
        x0: 0.0,
        v: 1000.0 / 60.0,
        a: 0.0,
    };
    let t_c = 37_654_321u64;
    for with_position in [true, false] {
        let mut inputs = ScriptedInputs::new(&[true], vec![falling(t_c)]);
        if with_position {
            inputs = inputs.with_position(move |t| m.at(t.0));
        }
        let mut cfg = SimPlcConfig::new(Nanos(T_NC));
        cfg.mode = SimPlcMode::ExtLatchControl;
        cfg.ack = AckScript::all(Nanos(2 * MS));
        let mut plc = ScriptedPlc::new(cfg);
        let mut axis = AxisPlc::default();
        let mut client = ext_client(
            SignalSource::PlcExtLatchControl,
            4,
            ProbeEdge::Negative,
            None,
        );
        let mut ev = ExtLatchEvaluator::new(0.0, Nanos(T_NC));
        let mut go_at = None;
        let mut event = None;
        for k in 0..60 {
            let now = Nanos(k * T_NC);
            nc_cycle(now, &mut inputs, &mut plc, &mut axis);
            if go_at.is_none() {
                if client.start_measuring_block(&mut axis.ext_latch, now) == BlockGate::Go {
                    go_at = Some(now);
                    ev.arm(now, &axis);
                }
                continue;
            }
            if let Some(e) = ev.update(now, m.at(now.0), &axis).unwrap() {
                assert!(event.is_none(), "one event");
                event = Some(e);
            }
        }
        // ENABLE written at 0, read at 1 ms, acknowledged 2 ms later.
        assert_eq!(go_at, Some(Nanos(3 * MS)));
        assert_eq!(axis.ext_latch.job_r.unwrap().input, 4);
        assert_eq!(axis.ext_latch.job_r.unwrap().edge, ProbeEdge::Negative);
        let e = event.expect("event");
        assert_eq!(e.at, Nanos(38 * MS), "PLC cycle after the edge");
        if with_position {
            assert_eq!(e.position, m.at(t_c), "the hardware's position, exactly");
        } else {
            // probing_position not enabled: the actual value of the cycle (§7.4 notice).
            assert_eq!(e.position, m.at(38 * MS));
            assert!(!axis.probing_position.is_enabled());
        }
    }
}

#[test]
fn ext_latch_edge_before_enable_acknowledged_is_ignored_by_the_hardware() {
    let mut inputs =
        ScriptedInputs::new(&[false], vec![rising(MS + 500_000)]).with_position(|t| t.0 as f64);
    let mut cfg = SimPlcConfig::new(Nanos(T_NC));
    cfg.mode = SimPlcMode::ExtLatchControl;
    cfg.ack = AckScript::all(Nanos(5 * MS));
    let mut plc = ScriptedPlc::new(cfg);
    let mut axis = AxisPlc::default();
    let mut client = ext_client(
        SignalSource::PlcExtLatchControl,
        1,
        ProbeEdge::Positive,
        None,
    );
    for k in 0..20 {
        let now = Nanos(k * T_NC);
        nc_cycle(now, &mut inputs, &mut plc, &mut axis);
        let _ = client.start_measuring_block(&mut axis.ext_latch, now);
    }
    assert_eq!(plc.hardware(), SimProbeState::Enabled);
    assert!(
        !axis.probing_signal(),
        "edge at 1.5 ms came before ENABLE (6 ms)"
    );
}

// ---------------------------------------------------------------------------------------------
// External-latch handshake (seed 004 §7.2)
// ---------------------------------------------------------------------------------------------

struct Rig {
    inputs: ScriptedInputs,
    plc: ScriptedPlc,
    axis: AxisPlc,
    client: ExtLatchClient,
}

impl Rig {
    fn new(ack: AckScript, timeout: Option<u64>) -> Self {
        let mut cfg = SimPlcConfig::new(Nanos(T_NC));
        cfg.ack = ack;
        Rig {
            inputs: ScriptedInputs::new(&[false], Vec::new()),
            plc: ScriptedPlc::new(cfg),
            axis: AxisPlc::default(),
            client: ext_client(
                SignalSource::ExtProbeWithDrive,
                2,
                ProbeEdge::Positive,
                timeout,
            ),
        }
    }

    /// PLC step for NC cycle `k`.
    fn plc(&mut self, k: u64) -> Nanos {
        let now = Nanos(k * T_NC);
        nc_cycle(now, &mut self.inputs, &mut self.plc, &mut self.axis);
        now
    }

    /// Run cycles from `from` calling `start_measuring_block` until Go / Failed; returns the
    /// cycle and the gate.
    fn start_block(&mut self, from: u64, max: u64) -> (u64, BlockGate) {
        for k in from..from + max {
            let now = self.plc(k);
            match self
                .client
                .start_measuring_block(&mut self.axis.ext_latch, now)
            {
                BlockGate::Wait => {}
                g => return (k, g),
            }
        }
        panic!("block did not start within {max} cycles");
    }

    fn idle(&mut self, from: u64, to: u64) {
        for k in from..to {
            let now = self.plc(k);
            self.client.poll(&mut self.axis.ext_latch, now);
        }
    }
}

#[test]
fn prepare_then_measuring_block_waits_for_prepare_and_enable_acknowledgements() {
    // Radio probe: PREPARE takes 2 s, ENABLE 10 ms, DISABLE 5 ms.
    let ack = AckScript {
        prepare: Some(Nanos(2_000 * MS)),
        enable: Some(Nanos(10 * MS)),
        disable: Some(Nanos(5 * MS)),
    };
    let mut r = Rig::new(ack, None);
    let now = r.plc(0);
    r.client.prepare(&mut r.axis.ext_latch, now).unwrap();
    assert!(r.axis.ext_latch.please_rw);
    assert_eq!(r.axis.ext_latch.job_r.unwrap().task, ExtLatchTask::Prepare);
    assert_eq!(r.axis.ext_latch.job_r.unwrap().input, 2);
    r.idle(1, 100);
    assert!(!r.axis.ext_latch.please_rw, "PLC read the task");
    assert_eq!(
        r.client.status(),
        ExtLatchStatus::Waiting {
            task: ExtLatchTask::Prepare,
            since: Nanos(0)
        }
    );
    assert!(!r.client.is_prepared());
    // The measuring block comes at 100 ms: the interpolator waits for PREPARE (read at 1 ms,
    // done at 2001 ms), then ENABLE (written 2001, read 2002, done 2012).
    let (k, gate) = r.start_block(100, 5_000);
    assert_eq!(gate, BlockGate::Go);
    assert_eq!(k, 2012);
    assert_eq!(r.client.readiness(), ProbeReadiness::Enabled);
    assert_eq!(r.plc.hardware(), SimProbeState::Enabled);

    // End of the run at 2500 ms: DISABLE read 2501, done 2506. A new run waits for it.
    let now = r.plc(2500);
    r.client
        .end_measuring_block(&mut r.axis.ext_latch, now)
        .unwrap();
    assert!(!r.client.new_run_allowed());
    let (k, gate) = r.start_block(2501, 1_000);
    assert_eq!(gate, BlockGate::Go);
    // DISABLE acknowledged at 2506, ENABLE written 2506, read 2507, done 2517.
    assert_eq!(k, 2517);
    assert!(r.client.new_run_allowed());
    assert_eq!(r.plc.acknowledged(), 4);
}

#[test]
fn measuring_block_without_prepare_enables_at_block_start() {
    let mut r = Rig::new(AckScript::all(Nanos(3 * MS)), None);
    let (k, gate) = r.start_block(0, 100);
    // ENABLE written at 0, read at 1, done at 4.
    assert_eq!((k, gate), (4, BlockGate::Go));
    assert_eq!(r.axis.ext_latch.job_r.unwrap().task, ExtLatchTask::Enable);
}

#[test]
fn unacknowledged_task_times_out() {
    let ack = AckScript {
        enable: None,
        ..AckScript::all(Nanos(MS))
    };
    let mut r = Rig::new(ack, Some(100 * MS));
    let (k, gate) = r.start_block(0, 1_000);
    assert_eq!((k, gate), (100, BlockGate::Failed(ExtLatchTask::Enable)));
    assert_eq!(
        r.client.status(),
        ExtLatchStatus::Timeout(ExtLatchTask::Enable)
    );
    assert!(!r.axis.ext_latch.please_rw, "task withdrawn");
    // Sticky until the channel resets.
    let now = r.plc(101);
    assert_eq!(
        r.client.start_measuring_block(&mut r.axis.ext_latch, now),
        BlockGate::Failed(ExtLatchTask::Enable)
    );
    r.client.cnc_reset(&mut r.axis.ext_latch);
    assert_eq!(r.client.status(), ExtLatchStatus::Idle);
    // Without a timeout the CNC waits forever (the seed's behaviour).
    let mut r = Rig::new(ack, None);
    for k in 0..3_000 {
        let now = r.plc(k);
        assert_eq!(
            r.client.start_measuring_block(&mut r.axis.ext_latch, now),
            BlockGate::Wait
        );
    }
}

#[test]
fn timed_out_disable_is_written_again_before_the_next_run() {
    let ack = AckScript {
        disable: None,
        ..AckScript::all(Nanos(MS))
    };
    let mut r = Rig::new(ack, Some(50 * MS));
    let (k, gate) = r.start_block(0, 100);
    assert_eq!(gate, BlockGate::Go);
    let now = r.plc(k + 1);
    r.client
        .end_measuring_block(&mut r.axis.ext_latch, now)
        .unwrap();
    r.idle(k + 2, k + 60);
    assert_eq!(
        r.client.status(),
        ExtLatchStatus::Timeout(ExtLatchTask::Disable)
    );
    assert!(!r.client.new_run_allowed());
    // The PLC comes back; the next measuring block first repeats DISABLE, then ENABLE.
    r.plc.config_mut().ack.disable = Some(Nanos(MS));
    let now = r.plc(k + 60);
    assert_eq!(
        r.client.start_measuring_block(&mut r.axis.ext_latch, now),
        BlockGate::Wait
    );
    assert_eq!(r.axis.ext_latch.job_r.unwrap().task, ExtLatchTask::Disable);
    let (_, gate) = r.start_block(k + 61, 100);
    assert_eq!(gate, BlockGate::Go);
    assert!(r.client.new_run_allowed());
}

#[test]
fn a_new_task_is_rejected_while_one_is_waiting() {
    let mut r = Rig::new(AckScript::never(), None);
    let now = r.plc(0);
    r.client.prepare(&mut r.axis.ext_latch, now).unwrap();
    assert_eq!(
        r.client
            .request(&mut r.axis.ext_latch, ExtLatchTask::Enable, now),
        Err(ExtLatchError::Busy(ExtLatchTask::Prepare))
    );
    assert_eq!(
        r.client.end_measuring_block(&mut r.axis.ext_latch, now),
        Err(ExtLatchError::Busy(ExtLatchTask::Prepare))
    );
}

#[test]
fn ext_latch_input_ranges_follow_the_p_axis_00517_table() {
    use SignalSource::*;
    assert!(ExtLatchConfig::new(PlcExtLatchControl, 1, ProbeEdge::Positive, None).is_ok());
    assert!(ExtLatchConfig::new(PlcExtLatchControl, 255, ProbeEdge::Positive, None).is_ok());
    assert!(matches!(
        ExtLatchConfig::new(PlcExtLatchControl, 0, ProbeEdge::Positive, None),
        Err(ExtLatchError::InputOutOfRange {
            min: 1,
            max: 255,
            ..
        })
    ));
    assert!(ExtLatchConfig::new(ExtProbeWithDrive, 2, ProbeEdge::Negative, None).is_ok());
    assert!(matches!(
        ExtLatchConfig::new(ExtProbeWithDrive, 3, ProbeEdge::Positive, None),
        Err(ExtLatchError::InputOutOfRange { min: 1, max: 2, .. })
    ));
    assert_eq!(
        ExtLatchConfig::new(Plc, 1, ProbeEdge::Positive, None),
        Err(ExtLatchError::NotExtLatchSource(Plc))
    );
}

fn prepared_rigs(n: usize, prepare: &[usize]) -> (Vec<Rig>, Vec<ExtLatchClient>) {
    let mut rigs: Vec<Rig> = (0..n)
        .map(|_| Rig::new(AckScript::all(Nanos(MS)), None))
        .collect();
    for (i, r) in rigs.iter_mut().enumerate() {
        let now = r.plc(0);
        if prepare.contains(&i) {
            r.client.prepare(&mut r.axis.ext_latch, now).unwrap();
        }
        r.idle(1, 5);
    }
    let clients = rigs.iter().map(|r| r.client).collect();
    (rigs, clients)
}

#[test]
fn homing_or_exchange_of_a_prepared_axis_resets_all_preparations() {
    let (_, mut clients) = prepared_rigs(3, &[0, 1]);
    assert!(clients[0].is_prepared() && clients[1].is_prepared());
    assert!(!clients[2].is_prepared());
    // Homing an unprepared axis resets nothing.
    assert!(!reset_preparations(
        &mut clients,
        PreparationReset::Homing(2)
    ));
    assert!(clients[0].is_prepared() && clients[1].is_prepared());
    // Homing a prepared axis resets all.
    assert!(reset_preparations(
        &mut clients,
        PreparationReset::Homing(1)
    ));
    assert!(clients.iter().all(|c| !c.is_prepared()));

    let (_, mut clients) = prepared_rigs(2, &[1]);
    assert!(reset_preparations(
        &mut clients,
        PreparationReset::AxisExchange(1)
    ));
    assert!(!clients[1].is_prepared());

    let (_, mut clients) = prepared_rigs(2, &[0, 1]);
    assert!(reset_preparations(
        &mut clients,
        PreparationReset::ProgramEnd
    ));
    assert!(clients.iter().all(|c| !c.is_prepared()));
    // Out-of-range index: nothing, no panic.
    assert!(!reset_preparations(
        &mut clients,
        PreparationReset::Homing(99)
    ));
}

#[test]
fn homing_while_prepare_is_pending_means_its_acknowledgement_does_not_prepare() {
    let mut r = Rig::new(AckScript::all(Nanos(10 * MS)), None);
    let now = r.plc(0);
    r.client.prepare(&mut r.axis.ext_latch, now).unwrap();
    r.idle(1, 3);
    let mut clients = [r.client];
    assert!(reset_preparations(
        &mut clients,
        PreparationReset::Homing(0)
    ));
    r.client = clients[0];
    r.idle(3, 20);
    assert_eq!(
        r.client.status(),
        ExtLatchStatus::Done(ExtLatchTask::Prepare)
    );
    assert!(!r.client.is_prepared());
}

#[test]
fn reset_between_prepare_and_measuring_block_enables_as_normal() {
    let mut r = Rig::new(AckScript::all(Nanos(2 * MS)), None);
    let now = r.plc(0);
    r.client.prepare(&mut r.axis.ext_latch, now).unwrap();
    r.idle(1, 10);
    assert!(r.client.is_prepared());
    r.client.cnc_reset(&mut r.axis.ext_latch);
    assert!(!r.client.is_prepared());
    assert_eq!(r.client.status(), ExtLatchStatus::Idle);
    assert!(!r.axis.ext_latch.please_rw && !r.axis.ext_latch.done_w);
    let now = r.plc(10);
    assert_eq!(
        r.client.start_measuring_block(&mut r.axis.ext_latch, now),
        BlockGate::Wait
    );
    assert_eq!(r.axis.ext_latch.job_r.unwrap().task, ExtLatchTask::Enable);
    // Written 10, read 11, done 13.
    assert_eq!(r.start_block(11, 100), (13, BlockGate::Go));

    // A reset while ENABLE is pending withdraws it; the next block writes ENABLE again.
    let mut r = Rig::new(AckScript::all(Nanos(20 * MS)), None);
    let now = r.plc(0);
    assert_eq!(
        r.client.start_measuring_block(&mut r.axis.ext_latch, now),
        BlockGate::Wait
    );
    r.client.cnc_reset(&mut r.axis.ext_latch);
    assert_eq!(r.client.readiness(), ProbeReadiness::Off);
    let (_, gate) = r.start_block(1, 100);
    assert_eq!(gate, BlockGate::Go);
}

// ---------------------------------------------------------------------------------------------
// DC timestamps (seed 004 §7.5, notes cnc.md §4.4)
// ---------------------------------------------------------------------------------------------

fn ts_config(dead: DeadTimes) -> TimestampConfig {
    TimestampConfig {
        signal_window: None,
        edge: ProbeEdge::Positive,
        cycle: Nanos(T_NC),
        capacity: 32,
        dead,
        clock: DcClock::default(),
    }
}

/// End to end: plant edge → EL1252-style PLC → timestamp unit → back-calculation.
fn timestamp_run(m: Motion, t_touch: u64, dead: DeadTimes) -> SourceEvent {
    let t_edge = t_touch + dead.probe_delay_ns as u64;
    let mut inputs = ScriptedInputs::new(&[false], vec![rising(t_edge)]);
    let mut cfg = SimPlcConfig::new(Nanos(T_NC));
    cfg.timestamp = Some(TimestampOutput {
        clock: DcClock::default(),
        terminal_delay_ns: dead.terminal_delay_ns,
        edge: ProbeEdge::Positive,
    });
    let mut plc = ScriptedPlc::new(cfg);
    let mut axis = AxisPlc::default();
    let mut ev = TimestampEvaluator::new(ts_config(dead));
    let sample_shift = dead.sample_shift();
    let mut event = None;
    for k in 0..(t_edge / T_NC + 10) {
        let now = Nanos(k * T_NC);
        nc_cycle(now, &mut inputs, &mut plc, &mut axis);
        if k == 0 {
            ev.arm(now, &axis);
        }
        // The actual value reported in cycle k was acquired sample_shift earlier.
        let actual = m.at_signed(now.0 as i64 - sample_shift);
        if let Some(e) = ev.update(now, actual, &axis).unwrap() {
            assert!(event.is_none());
            event = Some(e);
        }
    }
    event.expect("timestamp event")
}

#[test]
fn timestamp_back_calculation_is_within_a_t2_over_8_over_feeds_and_accelerations() {
    let t = ns_to_s(T_NC);
    let dead = DeadTimes {
        input_shift_ns: 250_000,
        drive_delay_ns: 3 * MS as i64,
        terminal_delay_ns: 700,
        probe_delay_ns: 3_000,
    };
    for feed in FEEDS {
        for a in [0.0, 500.0, 2_000.0, -2_000.0, 5_000.0, 10_000.0] {
            for t_touch in [20_000_000u64, 20_123_457, 20_500_000, 20_999_999] {
                let m = Motion {
                    x0: 250.0,
                    v: feed / 60.0,
                    a,
                };
                let e = timestamp_run(m, t_touch, dead);
                let truth = m.at(t_touch);
                let err = (e.position - truth).abs();
                let bound = a.abs() * t * t / 8.0;
                assert!(
                    err <= bound + TENTH_UM,
                    "feed {feed} a {a} t {t_touch}: error {err} > a·T²/8 + 0.1 µm = {}",
                    bound + TENTH_UM
                );
                assert!(
                    err <= e.error_bound + 1e-9,
                    "reported bound {} < {err}",
                    e.error_bound
                );
                assert!(
                    e.error_bound <= bound * 1.000_001 + 1e-9,
                    "bound estimate ≈ a·T²/8"
                );
                assert_eq!(
                    e.at,
                    Nanos(t_touch),
                    "event time corrected by the event dead times"
                );
            }
        }
    }
}

#[test]
fn hermite_with_velocities_is_exact_for_constant_acceleration() {
    let clock = DcClock::default();
    let m = Motion {
        x0: -40.0,
        v: 10_000.0 / 60.0,
        a: 8_000.0,
    };
    let mut b = TimestampBuffer::new(32, Nanos(T_NC), DeadTimes::default());
    for k in 0..40u64 {
        let t = (k * T_NC) as i64;
        b.push_with_velocity(clock.dc_time(Nanos(k * T_NC)), m.at_signed(t), m.vel(t))
            .unwrap();
    }
    for t in [20_000_001u64, 25_500_000, 30_999_000] {
        let est = b.estimate_at(clock.dc_time(Nanos(t))).unwrap();
        assert_eq!(est.method, Interpolation::Hermite);
        assert!(
            (est.position - m.at(t)).abs() < 1e-9,
            "{} vs {}",
            est.position,
            m.at(t)
        );
        // Linear would be off by a/2·(t−t_k)(t_k+1−t).
    }
}

#[test]
fn dc_times_beyond_f64_precision_are_handled_by_base_subtraction() {
    // 2026 on the DC time base (≈ 8.2·10¹⁷ ns, f64 spacing there is 128 ns).
    let clock = DcClock::default();
    assert!(clock.dc_time(Nanos(0)) > 1 << 59);
    let v = 10_000.0 / 60.0;
    let mut b = TimestampBuffer::new(64, Nanos(T_NC), DeadTimes::default());
    for k in 0..50u64 {
        b.push(clock.dc_time(Nanos(k * T_NC)), v * ns_to_s(k * T_NC))
            .unwrap();
    }
    for t in [30_000_001u64, 30_000_063, 30_000_127, 41_234_567] {
        let p = b.position_at(clock.dc_time(Nanos(t))).unwrap();
        assert!((p - v * ns_to_s(t)).abs() < 1e-9, "t {t}: {p}");
    }
    assert_eq!(
        clock.to_nanos(clock.dc_time(Nanos(123_456_789))),
        Nanos(123_456_789)
    );
}

#[test]
fn too_old_too_new_and_empty() {
    let mut b = TimestampBuffer::new(32, Nanos(T_NC), DeadTimes::default());
    assert_eq!(b.position_at(0), Err(TimestampError::Empty));
    let base = DcClock::YEAR_2026;
    for k in 0..100i64 {
        b.push(base + k * T_NC as i64, k as f64).unwrap();
    }
    // 32 samples: 68 … 99 ms.
    let oldest = base + 68 * T_NC as i64;
    let newest = base + 99 * T_NC as i64;
    assert_eq!(b.oldest_time(), Some(oldest));
    assert_eq!(b.position_at(oldest), Ok(68.0));
    assert!(matches!(
        b.position_at(oldest - 1),
        Err(TimestampError::TooOld { .. })
    ));
    // Up to one cycle after the newest sample: extrapolated.
    let est = b.estimate_at(newest + T_NC as i64).unwrap();
    assert_eq!(est.method, Interpolation::Extrapolated);
    assert!((est.position - 100.0).abs() < 1e-12);
    assert!(matches!(
        b.position_at(newest + T_NC as i64 + 1),
        Err(TimestampError::TooNew { .. })
    ));
    // Pushing back in time is refused and changes nothing.
    assert!(matches!(
        b.push(newest, 0.0),
        Err(TimestampError::NotMonotonic { .. })
    ));
    assert_eq!(b.push(newest + 1, f64::NAN), Err(TimestampError::NotFinite));
    assert_eq!(b.newest_time(), Some(newest));
}

/// Wrong dead time by one cycle: inside the buffer it is *not* detectable and shows up as a
/// position error of v·T (at constant feed, exactly); where the corrected time leaves the
/// buffer it is reported as TooNew (shift too large at the newest end) or TooOld (at the oldest
/// end).
#[test]
fn dead_time_one_cycle_off_is_an_error_of_v_t_or_too_new_too_old() {
    let t = ns_to_s(T_NC);
    let v = 480.0 / 60.0;
    let m = Motion {
        x0: 10.0,
        v,
        a: 0.0,
    };
    let base = DcClock::YEAR_2026;
    let true_delay = T_NC as i64;
    let fill = |dead: DeadTimes| {
        let mut b = TimestampBuffer::new(32, Nanos(T_NC), dead);
        for k in 0..40i64 {
            let tk = k * T_NC as i64;
            b.push(base + tk, m.at_signed(tk - true_delay)).unwrap();
        }
        b
    };
    let right = fill(DeadTimes {
        drive_delay_ns: true_delay,
        ..DeadTimes::default()
    });
    let wrong = fill(DeadTimes::default());
    let t_e = 30_400_000i64;
    let ok = right.position_at(base + t_e).unwrap();
    assert!((ok - m.at_signed(t_e)).abs() < 1e-9);
    let bad = wrong.position_at(base + t_e).unwrap();
    let err = (bad - m.at_signed(t_e)).abs();
    assert!((err - v * t).abs() < 1e-9, "error {err} = v·T = {}", v * t);
    // a = 0 here, so the interpolation bound is 0.1 µm: the error is far beyond it.
    assert!(err > TENTH_UM);

    // At the newest end: an event half a cycle after the newest sample is fine with the right
    // dead time; one cycle too much sample shift makes it TooNew.
    let newest = base + 39 * T_NC as i64;
    let t_new = newest + (T_NC / 2) as i64;
    assert!(fill(DeadTimes::default()).position_at(t_new).is_ok());
    let too_much = fill(DeadTimes {
        drive_delay_ns: T_NC as i64,
        ..DeadTimes::default()
    });
    assert!(matches!(
        too_much.position_at(t_new),
        Err(TimestampError::TooNew { .. })
    ));
    // At the oldest end: one cycle too much event delay makes it TooOld.
    let oldest = base + 8 * T_NC as i64;
    let t_old = oldest + (T_NC / 2) as i64;
    assert!(fill(DeadTimes::default()).position_at(t_old).is_ok());
    let late = fill(DeadTimes {
        terminal_delay_ns: T_NC as i64,
        ..DeadTimes::default()
    });
    assert!(matches!(
        late.position_at(t_old),
        Err(TimestampError::TooOld { .. })
    ));
}

#[test]
fn thirty_two_bit_dc_times_wrap_around() {
    assert_eq!(dc32_diff(3, u32::MAX), 4);
    assert_eq!(dc32_diff(u32::MAX, 3), -4);
    assert_eq!(dc32_diff(2_000_000_000, 0), 2_000_000_000);
    let v = 3000.0 / 60.0;
    // Start 10 ms before the 32-bit wrap; the same times in 64 bit for comparison.
    let start64: i64 = (5i64 << 32) - 10 * T_NC as i64;
    let mut b32 = TimestampBuffer::new(32, Nanos(T_NC), DeadTimes::default());
    let mut b64 = TimestampBuffer::new(32, Nanos(T_NC), DeadTimes::default());
    for k in 0..25i64 {
        let t = start64 + k * T_NC as i64;
        let x = v * (k as f64 * 1e-3);
        b32.push_dc32(t as u32, x).unwrap();
        b64.push(t, x).unwrap();
    }
    for dk in [3_500_000i64, 9_999_999, 10_000_001, 12_250_000] {
        let t = start64 + dk;
        let p32 = b32.position_at_dc32(t as u32).unwrap();
        let p64 = b64.position_at(t).unwrap();
        assert!((p32 - p64).abs() < 1e-12, "{dk}: {p32} vs {p64}");
        assert!((p64 - v * dk as f64 * 1e-9).abs() < 1e-9);
    }
    // A 32-bit time before the buffer is TooOld, not a wrapped-around future time.
    let old = (start64 - 50 * T_NC as i64) as u32;
    assert!(matches!(
        b32.position_at_dc32(old),
        Err(TimestampError::TooOld { .. })
    ));
}

#[test]
fn timestamp_evaluator_errors() {
    let mut ev = TimestampEvaluator::new(ts_config(DeadTimes::default()));
    let mut axis = AxisPlc::default();
    ev.arm(Nanos(0), &axis);
    for k in 0..5 {
        ev.update(Nanos(k * T_NC), 0.0, &axis).unwrap();
    }
    // Signal without timestamp unit.
    axis.probing_signal.plc_command(true);
    assert_eq!(
        ev.update(Nanos(5 * T_NC), 0.0, &axis),
        Err(SourceError::TimestampNotEnabled)
    );
    // A timestamp that never changes after arming: stale after the wait.
    let mut ev = TimestampEvaluator::new(ts_config(DeadTimes::default()));
    let mut axis = AxisPlc::default();
    axis.timestamp
        .plc_command(DcClock::default().dc_time(Nanos(0)));
    ev.arm(Nanos(0), &axis);
    axis.probing_signal.plc_command(true);
    let mut result = Ok(None);
    for k in 1..10 {
        result = ev.update(Nanos(k * T_NC), 0.0, &axis);
        if result != Ok(None) {
            break;
        }
    }
    assert_eq!(result, Err(SourceError::StaleTimestamp));
    // A timestamp far in the past: TooOld.
    let mut ev = TimestampEvaluator::new(ts_config(DeadTimes::default()));
    let mut axis = AxisPlc::default();
    ev.arm(Nanos(0), &axis);
    for k in 0..50 {
        ev.update(Nanos(k * T_NC), 0.0, &axis).unwrap();
    }
    axis.timestamp
        .plc_command(DcClock::default().dc_time(Nanos(T_NC)));
    axis.probing_signal.plc_command(true);
    assert!(matches!(
        ev.update(Nanos(50 * T_NC), 0.0, &axis),
        Err(SourceError::Timestamp(TimestampError::TooOld { .. }))
    ));
}

// ---------------------------------------------------------------------------------------------
// Fixed stop (seed 004 §7.3, §8.2.2)
// ---------------------------------------------------------------------------------------------

fn axis_params(values: &[(&str, i64)]) -> ParamSet {
    let mut p = ParamSet::new(Scope::Axis);
    for (id, v) in values {
        p.set_int(id, *v)
            .unwrap_or_else(|e| panic!("{id} = {v}: {e}"));
    }
    p
}

fn fs(values: &[(&str, i64)]) -> FixedStopParams {
    FixedStopParams::from_params(&axis_params(values), Nanos(T_NC)).unwrap()
}

#[test]
fn lag_limit_fallback_chain() {
    use id::*;
    // 00774 > 0: used (0.1 µm → mm).
    let p = fs(&[(MEAS_FS_POS_LAG_LIMIT, 5_000), (FS_POS_LAG_LIMIT, 7_000)]);
    assert_eq!(
        (p.lag_limit, p.lag_limit_origin),
        (Some(0.5), Origin::Measure)
    );
    // 00774 = 0: lag criterion off, whatever the others say.
    let p = fs(&[
        (MEAS_FS_POS_LAG_LIMIT, 0),
        (FS_POS_LAG_LIMIT, 7_000),
        (FIXED_STOP_POS_LAG_LIMIT, 9),
    ]);
    assert_eq!((p.lag_limit, p.lag_limit_origin), (None, Origin::Measure));
    // 00774 < 0 (default) and 00769 > 0: 00769.
    let p = fs(&[(FS_POS_LAG_LIMIT, 7_000), (FIXED_STOP_POS_LAG_LIMIT, 9_000)]);
    assert_eq!(
        (p.lag_limit, p.lag_limit_origin),
        (Some(0.7), Origin::FixedStop)
    );
    // 00769 < 0 (default): 00331.
    let p = fs(&[(FIXED_STOP_POS_LAG_LIMIT, 9_000)]);
    assert_eq!((p.lag_limit, p.lag_limit_origin), (Some(0.9), Origin::Old));
    // 00769 = 0 is not > 0: 00331 as well.
    let p = fs(&[(FS_POS_LAG_LIMIT, 0), (FIXED_STOP_POS_LAG_LIMIT, 9_000)]);
    assert_eq!((p.lag_limit, p.lag_limit_origin), (Some(0.9), Origin::Old));
    // 00331 = 0 (default): off.
    let p = fs(&[]);
    assert_eq!((p.lag_limit, p.lag_limit_origin), (None, Origin::Old));
}

#[test]
fn min_time_fallback_chain() {
    use id::*;
    let p = fs(&[
        (MEAS_FS_MIN_TIME, 2_500),
        (FS_MIN_TIME, 4_000),
        (FIXED_STOP_NBR_CYCLES, 7),
    ]);
    assert_eq!(
        (p.min_time, p.min_time_origin),
        (Nanos(2_500_000), Origin::Measure)
    );
    let p = fs(&[(FS_MIN_TIME, 4_000), (FIXED_STOP_NBR_CYCLES, 7)]);
    assert_eq!(
        (p.min_time, p.min_time_origin),
        (Nanos(4_000_000), Origin::FixedStop)
    );
    let p = fs(&[(FIXED_STOP_NBR_CYCLES, 7)]);
    assert_eq!(
        (p.min_time, p.min_time_origin),
        (Nanos(7 * T_NC), Origin::Old)
    );
    // Cycles scale with the NC cycle.
    let p =
        FixedStopParams::from_params(&axis_params(&[(FIXED_STOP_NBR_CYCLES, 7)]), Nanos(250_000))
            .unwrap();
    assert_eq!(p.min_time, Nanos(1_750_000));
    assert_eq!(
        FixedStopParams::from_params(&axis_params(&[]), Nanos(0)),
        Err(FixedStopError::ZeroCycle)
    );
}

#[test]
fn start_distance_fallback_chain() {
    use id::*;
    // 00776 ≥ 0 (default 0) is used as is.
    let p = fs(&[(FS_START_DISTANCE, 30_000)]);
    assert_eq!(
        (p.start_distance, p.start_distance_origin),
        (0.0, Origin::Measure)
    );
    let p = fs(&[
        (MEAS_FS_START_DISTANCE, 20_000),
        (FS_START_DISTANCE, 30_000),
    ]);
    assert_eq!(
        (p.start_distance, p.start_distance_origin),
        (2.0, Origin::Measure)
    );
    // 00776 < 0: 00771 if ≥ 0 …
    let p = fs(&[(MEAS_FS_START_DISTANCE, -1), (FS_START_DISTANCE, 30_000)]);
    assert_eq!(
        (p.start_distance, p.start_distance_origin),
        (3.0, Origin::FixedStop)
    );
    let p = fs(&[(MEAS_FS_START_DISTANCE, -1), (FS_START_DISTANCE, 0)]);
    assert_eq!(
        (p.start_distance, p.start_distance_origin),
        (0.0, Origin::FixedStop)
    );
    // … else 0 (00771 default is -1).
    let p = fs(&[(MEAS_FS_START_DISTANCE, -1)]);
    assert_eq!(
        (p.start_distance, p.start_distance_origin),
        (0.0, Origin::Default)
    );
}

#[test]
fn per_mille_fallback_chain() {
    use id::*;
    let p = fs(&[]);
    assert_eq!(
        (p.start_per_mille, p.start_per_mille_origin),
        (None, Origin::Default)
    );
    let p = fs(&[
        (MEAS_FS_START_DISTANCE_PER_MILLE, 250),
        (FS_START_DISTANCE_PER_MILLE, 400),
    ]);
    assert_eq!(
        (p.start_per_mille, p.start_per_mille_origin),
        (Some(250), Origin::Measure)
    );
    let p = fs(&[
        (MEAS_FS_START_DISTANCE_PER_MILLE, 0),
        (FS_START_DISTANCE_PER_MILLE, 400),
    ]);
    assert_eq!(
        (p.start_per_mille, p.start_per_mille_origin),
        (Some(0), Origin::Measure)
    );
    let p = fs(&[(FS_START_DISTANCE_PER_MILLE, 400)]);
    assert_eq!(
        (p.start_per_mille, p.start_per_mille_origin),
        (Some(400), Origin::FixedStop)
    );
    let p = fs(&[(FS_START_DISTANCE_PER_MILLE, 0)]);
    assert_eq!(
        (p.start_per_mille, p.start_per_mille_origin),
        (Some(0), Origin::FixedStop)
    );
}

#[test]
fn position_window_fallback_chain() {
    use id::*;
    let p = fs(&[]);
    assert_eq!(
        (p.max_delta_window, p.max_delta_window_origin),
        (None, Origin::Default)
    );
    let p = fs(&[
        (MEAS_FS_MAX_DELTA_POSITION_WINDOW, 0),
        (FS_MAX_DELTA_POSITION_WINDOW, 50),
    ]);
    assert_eq!(
        (p.max_delta_window, p.max_delta_window_origin),
        (Some(0.0), Origin::Measure)
    );
    let p = fs(&[(MEAS_FS_MAX_DELTA_POSITION_WINDOW, 150)]);
    assert_eq!(
        (p.max_delta_window, p.max_delta_window_origin),
        (Some(0.015), Origin::Measure)
    );
    let p = fs(&[(FS_MAX_DELTA_POSITION_WINDOW, 50)]);
    assert_eq!(
        (p.max_delta_window, p.max_delta_window_origin),
        (Some(0.005), Origin::FixedStop)
    );
}

#[test]
fn per_mille_above_1000_warns_at_start_and_errors_at_the_measuring_travel() {
    use id::*;
    for values in [
        vec![
            (MEAS_FS_START_DISTANCE_PER_MILLE, 1500),
            (MEAS_FS_POS_LAG_LIMIT, 100),
        ],
        vec![
            (FS_START_DISTANCE_PER_MILLE, 1001),
            (MEAS_FS_POS_LAG_LIMIT, 100),
        ],
    ] {
        let p = fs(&values);
        let w = p.startup_warning("Z").expect("warning 110757");
        assert_eq!(
            (w.id, w.severity),
            (PER_MILLE_WARNING_ID, Severity::Warning)
        );
        assert_eq!(w.id, 110757);
        assert_eq!(w.axis.as_deref(), Some("Z"));
        let e = p.check_measuring_start("Z").unwrap_err();
        assert_eq!((e.id, e.severity), (PER_MILLE_ERROR_ID, Severity::Error));
        assert_eq!(e.id, 51026);
        let axes = [FixedStopAxis {
            params: p,
            monitored: true,
        }];
        let err = FixedStopDetector::new(&axes, 100.0).unwrap_err();
        assert!(matches!(
            err,
            FixedStopError::PerMilleTooLarge { axis: 0, .. }
        ));
        assert_eq!(err.message("Z").unwrap().id, 51026);
    }
    let p = fs(&[
        (MEAS_FS_START_DISTANCE_PER_MILLE, 1000),
        (MEAS_FS_POS_LAG_LIMIT, 100),
    ]);
    assert!(p.startup_warning("Z").is_none());
    assert!(p.check_measuring_start("Z").is_ok());
}

/// A stall at `t_stall`: the command runs on at `v`, the actual stays; lag = v·(t − t_stall).
fn stall_run(det: &mut FixedStopDetector, v: f64, t_stall: u64, cycles: u64) -> Option<Detected> {
    for k in 0..cycles {
        let now = k * T_NC;
        let cmd = v * ns_to_s(now);
        let act = v * ns_to_s(now.min(t_stall));
        if let Some(d) = det.update(Nanos(now), 0, cmd, cmd - act, act) {
            return Some(d);
        }
    }
    None
}

fn one_axis(p: FixedStopParams) -> Vec<FixedStopAxis> {
    vec![FixedStopAxis {
        params: p,
        monitored: true,
    }]
}

#[test]
fn lag_criterion_detects_exactly_after_the_minimum_time() {
    use id::*;
    let v = 10.0; // mm/s
    let t_stall = 50_300_000u64;
    let limit = 0.02; // 200 × 0.1 µm
                      // First cycle with v·(t − t_stall) > limit.
    let k0 = (0..)
        .find(|k| v * (ns_to_s(k * T_NC) - ns_to_s(t_stall)) > limit)
        .unwrap();
    assert_eq!(k0, 53);
    // Old parameters: 5 cycles.
    let p = fs(&[(FIXED_STOP_POS_LAG_LIMIT, 200), (FIXED_STOP_NBR_CYCLES, 5)]);
    let mut det = FixedStopDetector::new(&one_axis(p), 100.0).unwrap();
    let d = stall_run(&mut det, v, t_stall, 200).unwrap();
    assert_eq!(d.at, Nanos((k0 + 5) * T_NC));
    assert_eq!(
        d.position,
        v * ns_to_s(t_stall),
        "the actual (stalled) position"
    );
    assert_eq!(d.axis, 0);
    assert_eq!(det.detected(), Some(d));
    assert_eq!(
        det.update(Nanos(999 * T_NC), 0, 1e9, 1e9, 0.0),
        None,
        "reported once"
    );
    // 3.5 ms minimum time at 1 ms cycles: the first cycle 3.5 ms after k0, i.e. k0 + 4.
    let p = fs(&[(MEAS_FS_POS_LAG_LIMIT, 200), (MEAS_FS_MIN_TIME, 3_500)]);
    let mut det = FixedStopDetector::new(&one_axis(p), 100.0).unwrap();
    assert_eq!(
        stall_run(&mut det, v, t_stall, 200).unwrap().at,
        Nanos((k0 + 4) * T_NC)
    );
    // Minimum time 0: the first cycle above the limit.
    let p = fs(&[(MEAS_FS_POS_LAG_LIMIT, 200)]);
    let mut det = FixedStopDetector::new(&one_axis(p), 100.0).unwrap();
    assert_eq!(
        stall_run(&mut det, v, t_stall, 200).unwrap().at,
        Nanos(k0 * T_NC)
    );
}

#[test]
fn violation_restarts_counting() {
    use id::*;
    let p = fs(&[(MEAS_FS_POS_LAG_LIMIT, 1_000), (MEAS_FS_MIN_TIME, 5_000)]);
    let mut det = FixedStopDetector::new(&one_axis(p), 100.0).unwrap();
    // Lag (mm) per cycle: above 0.1 from k = 10, dips at k = 13, above again from k = 14.
    let lag = |k: u64| if k >= 10 && k != 13 { 0.2 } else { 0.05 };
    let mut hit = None;
    for k in 0..100 {
        if let Some(d) = det.update(Nanos(k * T_NC), 0, 50.0, lag(k), 7.0) {
            hit = Some(d);
            break;
        }
    }
    assert_eq!(hit.unwrap().at, Nanos((14 + 5) * T_NC));
}

#[test]
fn velocity_criterion_is_an_average_velocity_limit_over_the_minimum_time() {
    use id::*;
    // Window 5 µm in 5 ms: 1 mm/s average.
    let p = fs(&[
        (MEAS_FS_MAX_DELTA_POSITION_WINDOW, 50),
        (MEAS_FS_MIN_TIME, 5_000),
    ]);
    assert_eq!(p.lag_limit, None);
    for (creep, detect) in [(2.0, false), (0.5, true)] {
        let mut det = FixedStopDetector::new(&one_axis(p), 100.0).unwrap();
        let mut hit = None;
        for k in 0..200u64 {
            let x = creep * ns_to_s(k * T_NC);
            if let Some(d) = det.update(Nanos(k * T_NC), 0, 50.0, 0.0, x) {
                hit = Some(d);
                break;
            }
        }
        assert_eq!(hit.is_some(), detect, "creep {creep} mm/s");
        if let Some(d) = hit {
            assert_eq!(d.at, Nanos(5 * T_NC));
        }
    }
}

#[test]
fn activation_distance_is_the_smaller_parameterised_distance_minimum_over_axes() {
    use id::*;
    let lag = (MEAS_FS_POS_LAG_LIMIT, 100);
    // 10 mm absolute, 10 % of 50 mm = 5 mm: 5 mm.
    let both = fs(&[
        lag,
        (MEAS_FS_START_DISTANCE, 100_000),
        (MEAS_FS_START_DISTANCE_PER_MILLE, 100),
    ]);
    assert_eq!(both.activation_distance(50.0), 5.0);
    assert_eq!(both.activation_distance(200.0), 10.0);
    // Only per mille (00776 = 0 default): 10 % of the block.
    let rel = fs(&[lag, (MEAS_FS_START_DISTANCE_PER_MILLE, 100)]);
    assert_eq!(rel.activation_distance(50.0), 5.0);
    // Only absolute.
    let abs = fs(&[lag, (MEAS_FS_START_DISTANCE, 30_000)]);
    assert_eq!(abs.activation_distance(50.0), 3.0);
    // Neither: at the block start.
    assert_eq!(fs(&[lag]).activation_distance(50.0), 0.0);

    // Two axes: the minimum.
    let axes = [
        FixedStopAxis {
            params: both,
            monitored: true,
        },
        FixedStopAxis {
            params: abs,
            monitored: true,
        },
    ];
    let mut det = FixedStopDetector::new(&axes, 50.0).unwrap();
    assert_eq!(det.activation_distance(), 3.0);
    // Criterion fulfilled (lag 1 mm > 0.01 mm, min time 0) but not yet activated.
    assert_eq!(det.update(Nanos(0), 0, 2.999, 1.0, 0.0), None);
    assert_eq!(det.update(Nanos(T_NC), 1, 2.999, 1.0, 0.0), None);
    let d = det.update(Nanos(2 * T_NC), 1, 3.0, 1.0, 4.2).unwrap();
    assert_eq!((d.axis, d.position, d.at), (1, 4.2, Nanos(2 * T_NC)));
}

#[test]
fn gantry_slaves_are_not_monitored() {
    use id::*;
    let p = fs(&[(MEAS_FS_POS_LAG_LIMIT, 100), (MEAS_FS_MIN_TIME, 2_000)]);
    let axes = [
        FixedStopAxis {
            params: p,
            monitored: true,
        },
        FixedStopAxis {
            params: fs(&[]),
            monitored: false,
        }, // slave, no criterion needed
    ];
    let mut det = FixedStopDetector::new(&axes, 10.0).unwrap();
    for k in 0..10 {
        assert_eq!(
            det.update(Nanos(k * T_NC), 1, 5.0, 100.0, 1.0),
            None,
            "slave ignored"
        );
    }
    let mut hit = None;
    for k in 10..20 {
        hit = hit.or(det.update(Nanos(k * T_NC), 0, 5.0, 0.5, 2.0));
    }
    assert_eq!(hit.unwrap().at, Nanos(12 * T_NC));
    assert_eq!(
        det.update(Nanos(0), 7, 5.0, 0.5, 2.0),
        None,
        "unknown axis index"
    );

    let slaves = [FixedStopAxis {
        params: p,
        monitored: false,
    }];
    assert_eq!(
        FixedStopDetector::new(&slaves, 10.0),
        Err(FixedStopError::NoMonitoredAxis)
    );
    let none = [FixedStopAxis {
        params: fs(&[]),
        monitored: true,
    }];
    assert_eq!(
        FixedStopDetector::new(&none, 10.0),
        Err(FixedStopError::NoCriterion { axis: 0 })
    );
    assert!(matches!(
        FixedStopDetector::new(&one_axis(p), f64::NAN),
        Err(FixedStopError::InvalidBlockLength(_))
    ));
}

#[test]
fn every_fixed_stop_error_reads_in_words_naming_axis_and_parameter() {
    // The detector's axes in list order: X2 (index 0), Z (index 1).
    let names = ["X2", "Z"];
    let cases = [
        (
            FixedStopError::NoCriterion { axis: 1 },
            900040,
            &["axis Z", "P-AXIS-00774", "P-AXIS-00778"][..],
        ),
        (
            FixedStopError::PerMilleTooLarge {
                axis: 1,
                value: 1500,
            },
            51026,
            &["axis Z", "1500", "P-AXIS-00777"][..],
        ),
        (
            FixedStopError::NoMonitoredAxis,
            900040,
            &["X2, Z", "monitored"][..],
        ),
        (
            FixedStopError::InvalidBlockLength(-1.0),
            900040,
            &["block length -1"][..],
        ),
        (
            FixedStopError::ZeroCycle,
            900040,
            &["cycle time is 0", "P-AXIS-00775", "P-AXIS-00332"][..],
        ),
    ];
    for (e, id, words) in cases {
        let m = e.cnc_message(900040, &names);
        assert_eq!((m.id, m.severity), (id, Severity::Error), "{e:?}");
        for w in words {
            assert!(m.text.contains(w), "{w:?} missing in {:?}", m.text);
        }
        // No Rust debug output: no variant names, no braces.
        let debug = format!("{e:?}");
        let variant = debug.split([' ', '(', '{']).next().unwrap();
        assert!(!m.text.contains(variant), "{:?}", m.text);
        assert!(
            !m.text.contains('{') && !m.text.contains('}'),
            "{:?}",
            m.text
        );
        // The Display text of the error reads in words, too.
        assert!(!e.to_string().contains(variant), "{e}");
    }
    let m = FixedStopError::NoCriterion { axis: 1 }.cnc_message(900040, &names);
    assert_eq!(m.axis.as_deref(), Some("Z"));
}

#[test]
fn scripted_plc_clamps_its_period_and_bounds_far_jumps() {
    let mut plc = ScriptedPlc::new(SimPlcConfig::new(Nanos(0)));
    assert_eq!(plc.config().period, Nanos(1_000));
    let inputs = ScriptedInputs::new(&[true], Vec::new());
    let mut axis = AxisPlc::default();
    plc.step(Nanos(5_500), &inputs, &mut axis);
    assert_eq!(plc.cycles(), 6, "cycles at 0, 1, … 5 µs");
    assert!(axis.probing_signal());
    plc.config_mut().period = Nanos(0);
    plc.step(Nanos(9_500), &inputs, &mut axis);
    assert_eq!(plc.cycles(), 10, "a zero period set later runs as 1 µs");
    plc.step(Nanos(u64::MAX), &inputs, &mut axis);
    assert!(plc.cycles() < 20_000, "older cycles skipped");
    plc.step(Nanos(u64::MAX), &inputs, &mut axis);
}

// ---------------------------------------------------------------------------------------------
// Property tests: no panic on any input
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone)]
enum BufOp {
    Push(i64, f64),
    PushV(i64, f64, f64),
    Push32(u32, f64),
    Query(i64),
    Query32(u32),
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::num::f64::ANY,
        -1e6f64..1e6,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(0.0)
    ]
}

fn buf_op() -> impl Strategy<Value = BufOp> {
    prop_oneof![
        (any::<i64>(), any_f64()).prop_map(|(t, x)| BufOp::Push(t, x)),
        (0i64..1_000_000_000, any_f64()).prop_map(|(t, x)| BufOp::Push(t, x)),
        (any::<i64>(), any_f64(), any_f64()).prop_map(|(t, x, v)| BufOp::PushV(t, x, v)),
        (any::<u32>(), any_f64()).prop_map(|(t, x)| BufOp::Push32(t, x)),
        any::<i64>().prop_map(BufOp::Query),
        (0i64..1_000_000_000).prop_map(BufOp::Query),
        any::<u32>().prop_map(BufOp::Query32),
    ]
}

fn any_dead() -> impl Strategy<Value = DeadTimes> {
    (any::<i64>(), any::<i64>(), any::<i64>(), any::<i64>()).prop_map(|(a, b, c, d)| DeadTimes {
        input_shift_ns: a,
        drive_delay_ns: b,
        terminal_delay_ns: c,
        probe_delay_ns: d,
    })
}

proptest! {
    #[test]
    fn timestamp_buffer_never_panics(
        cap in any::<usize>(),
        cycle in any::<u64>(),
        dead in prop_oneof![any_dead(), Just(DeadTimes::default())],
        ops in prop::collection::vec(buf_op(), 0..80),
    ) {
        let mut b = TimestampBuffer::new(cap % 5000, Nanos(cycle), dead);
        for op in ops {
            match op {
                BufOp::Push(t, x) => { let _ = b.push(t, x); }
                BufOp::PushV(t, x, v) => { let _ = b.push_with_velocity(t, x, v); }
                BufOp::Push32(t, x) => { let _ = b.push_dc32(t, x); }
                BufOp::Query(t) => { let _ = b.estimate_at(t); }
                BufOp::Query32(t) => { let _ = b.estimate_at_dc32(t); }
            }
            prop_assert!(b.len() <= b.capacity());
            prop_assert!(b.capacity().is_power_of_two() && b.capacity() >= 32);
        }
    }

    #[test]
    fn fixed_stop_never_panics(
        values in prop::collection::vec((0usize..11, any::<i64>()), 0..12),
        cycle in any::<u64>(),
        block in any_f64(),
        monitored in any::<bool>(),
        steps in prop::collection::vec((any::<u64>(), 0usize..3, any_f64(), any_f64(), any_f64()), 0..60),
    ) {
        let ids = [
            id::MEAS_FS_POS_LAG_LIMIT, id::FS_POS_LAG_LIMIT, id::FIXED_STOP_POS_LAG_LIMIT,
            id::MEAS_FS_MIN_TIME, id::FS_MIN_TIME, id::FIXED_STOP_NBR_CYCLES,
            id::MEAS_FS_START_DISTANCE, id::FS_START_DISTANCE,
            id::MEAS_FS_START_DISTANCE_PER_MILLE, id::FS_START_DISTANCE_PER_MILLE,
            id::MEAS_FS_MAX_DELTA_POSITION_WINDOW,
        ];
        let mut p = ParamSet::new(Scope::Axis);
        for (i, v) in values {
            let _ = p.set_int(ids[i], v);
            let _ = p.set_int(ids[i], v % 100_000);
        }
        if let Ok(params) = FixedStopParams::from_params(&p, Nanos(cycle)) {
            let _ = params.startup_warning("X");
            let _ = params.check_measuring_start("X");
            let _ = params.activation_distance(block);
            let axes = [FixedStopAxis { params, monitored }, FixedStopAxis { params, monitored: true }];
            if let Ok(mut det) = FixedStopDetector::new(&axes, block) {
                for (t, axis, travelled, lag, actual) in steps {
                    let _ = det.update(Nanos(t), axis, travelled, lag, actual);
                }
            }
        }
    }

    #[test]
    fn ext_latch_client_never_panics(
        timeout in prop::option::of(any::<u64>()),
        ops in prop::collection::vec((0u8..12, any::<u64>()), 0..100),
    ) {
        let mut c = ext_client(SignalSource::PlcExtLatchControl, 7, ProbeEdge::Negative, timeout);
        let mut others = [ext_client(SignalSource::ExtProbeWithDrive, 1, ProbeEdge::Positive, None); 2];
        let mut iface = AxisPlc::default().ext_latch;
        for (op, t) in ops {
            let now = Nanos(t);
            match op {
                0 => { let _ = c.prepare(&mut iface, now); }
                1 => { let _ = c.start_measuring_block(&mut iface, now); }
                2 => { let _ = c.end_measuring_block(&mut iface, now); }
                3 => { let _ = c.poll(&mut iface, now); }
                4 => { let _ = iface.plc_take_task(); }
                5 => iface.plc_acknowledge(),
                6 => c.cnc_reset(&mut iface),
                7 => c.clear_preparation(),
                8 => { others[0] = c; let _ = reset_preparations(&mut others, PreparationReset::Homing((t % 4) as usize)); c = others[0]; }
                9 => { let _ = reset_preparations(&mut others, PreparationReset::ProgramEnd); }
                10 => iface.please_rw = !iface.please_rw,
                _ => iface.done_w = !iface.done_w,
            }
        }
    }

    #[test]
    fn evaluators_never_panic(
        edge in any::<bool>(),
        latency in any::<u64>(),
        cycle in any::<u64>(),
        capacity in 0usize..300,
        dead in prop_oneof![any_dead(), Just(DeadTimes::default())],
        offset in any::<i64>(),
        steps in prop::collection::vec(
            (any::<u64>(), any_f64(), any::<bool>(), any::<bool>(), any::<i64>(), any::<bool>(), any_f64(), any::<bool>(), 0u8..4),
            0..80),
    ) {
        let cfg = EvaluatorConfig {
            edge: if edge { ProbeEdge::Positive } else { ProbeEdge::Negative },
            latency: Nanos(latency),
            hardware_bound: 0.001,
            timestamp: TimestampConfig {
                edge: ProbeEdge::Positive,
                cycle: Nanos(cycle),
                capacity,
                dead,
                clock: DcClock::new(offset),
                signal_window: Some(Nanos(0)),
            },
        };
        let mut evs: Vec<SourceEvaluator> = [
            SignalSource::Plc, SignalSource::PlcFirstEvent,
            SignalSource::PlcExtLatchControl, SignalSource::PlcTimestamp,
        ].iter().map(|s| SourceEvaluator::for_source(*s, &cfg).unwrap()).collect();
        prop_assert!(SourceEvaluator::for_source(SignalSource::Drive, &cfg).is_none());
        let mut axis = AxisPlc::default();
        for (t, actual, sig, sig_en, ts, ts_en, pos, pos_en, action) in steps {
            axis.probing_signal.command_w = sig;
            axis.probing_signal.enable_w = sig_en;
            axis.timestamp.command_w = ts;
            axis.timestamp.enable_w = ts_en;
            axis.probing_position.command_w = pos;
            axis.probing_position.enable_w = pos_en;
            axis.publish(actual);
            for ev in evs.iter_mut() {
                match action {
                    0 => ev.arm(Nanos(t), &axis),
                    1 => ev.disarm(),
                    _ => {}
                }
                let _ = ev.update(Nanos(t), actual, &axis);
            }
        }
    }

    #[test]
    fn scripted_plc_never_panics(
        period in any::<u64>(),
        phase in any::<u64>(),
        mode in 0u8..3,
        delays in (prop::option::of(any::<u64>()), prop::option::of(0u64..10_000_000)),
        ts_offset in any::<i64>(),
        ts_delay in any::<i64>(),
        edges in prop::collection::vec((0usize..3, any::<bool>(), 0u64..100_000_000), 0..40),
        steps in prop::collection::vec((0u64..3_000_000, 0u8..4), 1..60),
    ) {
        let mut cfg = SimPlcConfig::new(Nanos(100_000 + period % 20_000_000));
        cfg.phase = Nanos(phase % 50_000_000);
        cfg.mode = match mode {
            0 => SimPlcMode::Signal,
            1 => SimPlcMode::FirstEventLatch { edge: ProbeEdge::Negative },
            _ => SimPlcMode::ExtLatchControl,
        };
        cfg.ack = AckScript { prepare: delays.0.map(Nanos), enable: delays.1.map(Nanos), disable: Some(Nanos(0)) };
        cfg.timestamp = Some(TimestampOutput {
            clock: DcClock::new(ts_offset),
            terminal_delay_ns: ts_delay,
            edge: ProbeEdge::Positive,
        });
        let edges = edges.into_iter().map(|(probe, rising, at)| InputEdge { probe, rising, at: Nanos(at) }).collect();
        let mut inputs = ScriptedInputs::new(&[true], edges).with_position(|t| t.0 as f64 * 1e-6);
        let mut plc = ScriptedPlc::new(cfg);
        let mut axis = AxisPlc::default();
        let mut client = ext_client(SignalSource::PlcExtLatchControl, 3, ProbeEdge::Positive, Some(5 * MS));
        let mut now = 0u64;
        for (dt, action) in steps {
            now += dt;
            inputs.advance(Nanos(now));
            plc.step(Nanos(now), &inputs, &mut axis);
            match action {
                0 => { let _ = client.start_measuring_block(&mut axis.ext_latch, Nanos(now)); }
                1 => { let _ = client.end_measuring_block(&mut axis.ext_latch, Nanos(now)); }
                2 => plc.clear_latch(),
                _ => { let _ = client.prepare(&mut axis.ext_latch, Nanos(now)); }
            }
        }
    }
}

#[test]
fn timestamp_outside_the_signal_window_is_inconsistent() {
    use fieldprobe::core::measure::plc::{
        AxisPlc, SignalEvaluator, SourceError, TimestampEvaluator,
    };
    // NC cycle 1 ms, synchronous PLC (no slack). The signal is inactive at 10 ms and seen active
    // at 11 ms: the edge must lie in (10 ms, 11 ms].
    let clock = DcClock::new(0);
    let cfg = TimestampConfig {
        signal_window: Some(Nanos(0)),
        ..ts_config(DeadTimes::default())
    };
    for (edge_ns, ok) in [
        (10_500_000i64, true),
        (11_000_000, true),
        (9_500_000, false),
        (11_500_000, false),
    ] {
        let mut ev = TimestampEvaluator::new(TimestampConfig { clock, ..cfg });
        let mut plc = AxisPlc::default();
        plc.probing_signal.plc_command(false);
        plc.timestamp.plc_command(0);
        let mut result = None;
        for k in 0..=14u64 {
            let now = Nanos(k * 1_000_000);
            if k == 0 {
                ev.arm(now, &plc);
            }
            if k == 11 {
                plc.probing_signal.plc_command(true);
                plc.timestamp
                    .plc_command(clock.dc_time(Nanos(edge_ns as u64)));
            }
            let pos = k as f64; // 1 mm per ms
            if let Some(r) = ev.update(now, pos, &plc).transpose() {
                result = Some(r);
                break;
            }
        }
        match (ok, result) {
            (true, Some(Ok(e))) => assert!(
                (e.position - edge_ns as f64 / 1e6).abs() < 1e-9,
                "{edge_ns}: {}",
                e.position
            ),
            (false, Some(Err(SourceError::InconsistentTimestamp { .. }))) => {}
            (ok, r) => panic!("edge {edge_ns} (ok {ok}): {r:?}"),
        }
    }
}
