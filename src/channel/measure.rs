//! Measurement runs in the channel (seed 004): a G100 / G210 / G310 block is a linear motion
//! that arms the probing-signal sources of its axes, collects their latches every cycle, brakes
//! when the probing signal is complete and publishes a [`MeasurementOutcome`].
//!
//! Phases of one measuring block:
//!
//! ```text
//! arming ──(every source confirmed: drive 0x60B9 enabled, PLC acknowledged)──► measuring
//! measuring ──(all required axes latched)──► braking (type 3: goes on to the target)
//!           ──(target / overtravel end reached)──► done without signal
//! braking ──(standstill)──► done
//! ```
//!
//! Which axes must latch (seed 004 §4): in 2.5D every measurement axis the block moves; with
//! `#CS` all three main axes. Braking uses the deceleration of the §2.1 table ("measurement
//! signal active" column) for the non-linear slope parameter set our interpolator uses.

use super::Channel;
use crate::core::measure::fixed_stop::{FixedStopAxis, FixedStopDetector};
use crate::core::measure::plc::{
    BlockGate, EvaluatorConfig, ExtLatchClient, ExtLatchConfig, SignalEvaluator, SourceEvaluator,
    TimestampConfig,
};
use crate::core::measure::timestamp::{DcClock, DeadTimes};
use crate::core::measure::{MeasType, MeasurementOutcome, SignalSource};
use crate::core::path::Segment;
use crate::drive::{ProbeEdge, ProbeRequest, ProbeState, ProbeTrigger, TriggerSourceMode};
use crate::messages::{ids, CncMessage};
use crate::units::Nanos;

/// A lag below this (mm, one 0.1 µm increment) counts as none when an undetected type-7 run
/// ends (P-CHAN-00266 = 1).
const SETTLE_LAG: f64 = 1e-4;

/// Cycles a measuring block may wait for its sources to confirm the arming (1 s at 1 ms).
pub const ARMING_TIMEOUT_CYCLES: u32 = 1000;

/// The measuring part of a motion request, as the executor states it.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasureRequest {
    /// Active measurement type.
    pub mtype: MeasType,
    /// The G code of the block: 100, 210 or 310.
    pub gcode: u32,
    /// `#CS` is active: the three main axes must all latch (seed 004 §4).
    pub cs_active: bool,
    /// Per-axis signal overrides from `#MEAS [AXNR=.. SIGNAL=.. INPUT=.. EDGE=..]`.
    pub overrides: Vec<SignalOverride>,
}

/// A `#MEAS [AXNR=..]` override of one axis's signal settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalOverride {
    /// Channel axis index.
    pub axis: usize,
    /// Signal source.
    pub signal: Option<SignalSource>,
    /// Probing input.
    pub input: Option<u8>,
    /// Edge.
    pub edge: Option<ProbeEdge>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Arming { cycles: u32 },
    Measuring,
    Done,
}

#[derive(Debug, Clone)]
pub(super) struct MeasAxis {
    axis: usize,
    signal: SignalSource,
    required: bool,
    edge: ProbeEdge,
    input: u8,
    latched: Option<(f64, Nanos)>,
    /// Latched before the programmed target was reached.
    before_target: bool,
    /// Evaluator of a PLC signal source.
    eval: Option<SourceEvaluator>,
    /// The PLC's external-latch handshake gates this axis (PLC_EXT_LATCH_CONTROL,
    /// EXT_PROBE_WITH_DRIVE).
    handshake: bool,
    /// Position of the axis at the start of the block (fixed-stop start distance).
    start: f64,
    /// `CNC_DEFINED`: the 0x60D0 write that must finish before the latch is armed.
    source_sdo: Option<(u64, ProbeRequest)>,
}

/// State of one measuring block.
#[derive(Debug, Clone)]
pub(super) struct MeasRun {
    mtype: MeasType,
    phase: Phase,
    axes: Vec<MeasAxis>,
    /// Path length up to the programmed target (the segment may extend beyond: overtravel).
    pub(super) target_len: f64,
    /// The path was cut at a software limit switch (P-CHAN-00268).
    pub(super) limited_at_sls: bool,
    /// Per-axis braking deceleration (mm/s²) of the §2.1 table.
    brake: Vec<f64>,
    /// Path position where the signal became complete.
    event_s: Option<f64>,
    /// Fixed-stop detection (type 7) over the run's axes, in run-axis order.
    fixed: Option<FixedStopDetector>,
    /// Actual positions of the previous cycle while waiting for standstill at the end of an
    /// undetected type-7 run.
    settle_prev: Option<Vec<f64>>,
    /// Cycles waited for standstill.
    settle_cycles: u32,
    /// Consecutive cycles without change of the actual positions.
    settle_still: u32,
    /// Sources armed (first arming cycle done).
    armed_once: bool,
}

impl MeasRun {
    /// All required axes latched.
    fn complete(&self) -> bool {
        self.axes
            .iter()
            .filter(|a| a.required)
            .all(|a| a.latched.is_some())
            && self.axes.iter().any(|a| a.latched.is_some())
    }

    /// Measurement type.
    pub(super) fn mtype(&self) -> MeasType {
        self.mtype
    }

    /// Axis `i` takes part in this run.
    fn has_axis(&self, i: usize) -> bool {
        self.axes.iter().any(|a| a.axis == i)
    }

    /// At the end of a type-7 path the block ends once the axes are at rest (detection still
    /// running); without a detected stop and with P-CHAN-00266 = 1 the CNC then goes to the actual
    /// position "to eliminate a possible position lag" (§8.2.1) — in free air the target itself.
    /// True when the block may end.
    pub(super) fn end_settled(&mut self, axes: &[crate::axis::Axis]) -> bool {
        if self.mtype != MeasType::Type7 || self.complete() {
            return true;
        }
        // Detection goes on after the path end until the axes are at rest (P-AXIS-00777 = 1000
        // activates it only there): the lag has gone (free air) or the actual positions have not
        // changed for 50 cycles (pressed against something, quantised to increments).
        let now: Vec<f64> = self.axes.iter().map(|a| axes[a.axis].actual()).collect();
        let no_lag = self
            .axes
            .iter()
            .all(|a| axes[a.axis].lag().abs() <= SETTLE_LAG);
        let unchanged = self
            .settle_prev
            .as_ref()
            .is_some_and(|p| p.iter().zip(&now).all(|(a, b)| a == b));
        self.settle_still = if unchanged { self.settle_still + 1 } else { 0 };
        self.settle_prev = Some(now);
        self.settle_cycles += 1;
        no_lag || self.settle_still >= 50 || self.settle_cycles > ARMING_TIMEOUT_CYCLES
    }

    /// The axes that still have a lag to eliminate after an undetected type-7 run.
    pub(super) fn lagging_axes(&self, axes: &[crate::axis::Axis]) -> Vec<(usize, f64)> {
        self.axes
            .iter()
            .filter(|a| axes[a.axis].lag().abs() > SETTLE_LAG)
            .map(|a| (a.axis, axes[a.axis].actual()))
            .collect()
    }

    /// Leave axis `i` to another run (an independent measuring motion of the same block): it is
    /// neither armed nor read by this one any more. Returns false when `i` must latch here.
    pub(super) fn release_axis(&mut self, i: usize) -> bool {
        if self.axes.iter().any(|a| a.axis == i && a.required) {
            return false;
        }
        self.axes.retain(|a| a.axis != i);
        true
    }
}

impl Channel {
    /// Set up the measurement of a motion block (called from block preparation once the path
    /// is known). Returns an error message when the block may not run as a measurement.
    pub(super) fn prepare_measurement(
        &mut self,
        req: &MeasureRequest,
        segment: &Segment,
        target_len: f64,
        only_moved: bool,
    ) -> Result<MeasRun, CncMessage> {
        let n = self.axes.len();
        let start = segment.start();
        let end = segment.end();
        let moved: Vec<bool> = (0..n).map(|i| (end[i] - start[i]).abs() > 1e-9).collect();
        let mtype = req.mtype;
        // G code and type must belong together (seed 004 §3 table).
        let ok_gcode = match mtype {
            MeasType::Type5 => req.gcode == 210,
            MeasType::Type6 => req.gcode == 310,
            _ => req.gcode == 100,
        };
        if !ok_gcode {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                format!(
                    "G{} does not belong to measurement type {} (types 1–4 and 7 measure with G100, 5 with G210, 6 with G310)",
                    req.gcode,
                    mtype.number()
                ),
            ));
        }
        let main = self.main_axes();
        let moved_count = moved.iter().filter(|m| **m).count();
        match mtype {
            MeasType::Type2 if moved_count != 1 => {
                return Err(CncMessage::error(
                    ids::MEAS_CONFIG,
                    format!("measurement type 2 moves exactly one axis; this block moves {moved_count}"),
                ))
            }
            MeasType::Type4 => {
                if let Some(i) = (0..n).find(|i| moved[*i] && !main.contains(&Some(*i))) {
                    return Err(CncMessage::error(
                        ids::MEAS_CONFIG,
                        format!(
                            "measurement type 4 measures with at most the 3 main axes; axis {} is not one",
                            self.axes[i].name()
                        ),
                    ));
                }
            }
            MeasType::Type6 if !self.cfg.axes.iter().any(|a| a.meas.sercos) => {
                return Err(CncMessage::error(
                    ids::MEAS_CONFIG,
                    "measurement type 6 (G310) needs at least one SERCOS axis; this channel has none",
                ))
            }
            _ => {}
        }
        // Which axes take part and which must latch (seed 004 §4).
        let mut axes = Vec::new();
        for i in 0..n {
            let c = &self.cfg.axes[i].meas;
            let in_cs = req.cs_active && main.contains(&Some(i));
            // Gantry slaves move along but the master measures (seed 004 §7.3).
            let slave = self.is_coupled_slave(i);
            let required = (moved[i] || in_cs) && !slave;
            if required && !c.enabled {
                return Err(CncMessage::error(
                    ids::MEAS_CONFIG,
                    format!(
                        "axis {} is not enabled as a measurement axis (P-AXIS-00118 kenngr.messachse = 0){}",
                        self.axes[i].name(),
                        if in_cs { "; with #CS all three main axes must be" } else { "" }
                    ),
                )
                .on_axis(self.axes[i].name()));
            }
            // An independent axis measures alone: the other axes' latches belong to their own
            // runs.
            if !c.enabled || (only_moved && !required) {
                continue;
            }
            let ov = req.overrides.iter().rev().find(|o| o.axis == i);
            let mut signal = ov.and_then(|o| o.signal).unwrap_or(c.signal);
            if mtype == MeasType::Type7 {
                signal = SignalSource::FixedStop;
            }
            let edge = ov.and_then(|o| o.edge).unwrap_or(c.edge);
            let input = ov.and_then(|o| o.input).unwrap_or(c.input);
            let eval = SourceEvaluator::for_source(
                signal,
                &EvaluatorConfig {
                    edge,
                    latency: self.cfg.cycle,
                    hardware_bound: 0.0001,
                    timestamp: TimestampConfig {
                        edge,
                        cycle: self.cfg.cycle,
                        capacity: 64,
                        dead: DeadTimes::default(),
                        clock: DcClock::default(),
                        signal_window: Some(crate::units::Nanos(
                            self.cfg
                                .meas
                                .plc_cycle
                                .map_or(0, |p| p.0.saturating_sub(self.cfg.cycle.0)),
                        )),
                    },
                },
            );
            let handshake = matches!(
                signal,
                SignalSource::PlcExtLatchControl | SignalSource::ExtProbeWithDrive
            );
            if handshake {
                let cfg = ExtLatchConfig::new(signal, input, edge, None).map_err(|e| {
                    CncMessage::error(
                        ids::MEAS_CONFIG,
                        format!("axis {}: {e}", self.axes[i].name()),
                    )
                })?;
                let same = self.ext_latch[i]
                    .as_ref()
                    .is_some_and(|c| *c.config() == cfg);
                if !same {
                    self.ext_latch[i] = Some(ExtLatchClient::new(cfg));
                }
            }
            axes.push(MeasAxis {
                axis: i,
                signal,
                required,
                edge,
                input,
                latched: None,
                before_target: false,
                eval,
                handshake,
                start: start[i],
                source_sdo: None,
            });
        }
        if !axes.iter().any(|a| a.required) {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                "measuring block without a moved measurement axis",
            ));
        }
        let brake = (0..n).map(|i| self.measurement_brake_decel(i)).collect();
        let fixed = if mtype == MeasType::Type7 {
            let mut fa = Vec::with_capacity(axes.len());
            for a in &axes {
                let c = &self.cfg.axes[a.axis].meas;
                let name = self.axes[a.axis].name();
                // Only the moved axes (masters of a gantry) are watched for the stop.
                let monitored = a.required;
                let params = match (c.fixed_stop, monitored) {
                    (Some(p), _) => p,
                    (None, false) => crate::core::measure::fixed_stop::FixedStopParams::inactive(),
                    (None, true) => {
                        return Err(CncMessage::error(
                            ids::MEAS_CONFIG,
                            format!(
                                "axis {name}: fixed-stop parameters invalid (P-AXIS-00774 … 00778)"
                            ),
                        ))
                    }
                };
                if monitored {
                    params.check_measuring_start(name)?;
                }
                fa.push(FixedStopAxis { params, monitored });
            }
            Some(FixedStopDetector::new(&fa, target_len).map_err(|e| {
                e.message(self.axes[axes[0].axis].name())
                    .unwrap_or_else(|| {
                        CncMessage::error(ids::MEAS_CONFIG, format!("fixed stop: {e:?}"))
                    })
            })?)
        } else {
            None
        };
        let mut run = MeasRun {
            mtype,
            phase: Phase::Arming { cycles: 0 },
            axes,
            target_len,
            limited_at_sls: false,
            brake,
            event_s: None,
            fixed,
            armed_once: false,
            settle_prev: None,
            settle_cycles: 0,
            settle_still: 0,
        };
        self.arm_sources(&mut run)?;
        Ok(run)
    }

    /// Braking deceleration of axis `i` after the probing signal, seed 004 §2.1 table
    /// ("non-linear slope", column "measurement signal active").
    fn measurement_brake_decel(&self, i: usize) -> f64 {
        let m = &self.cfg.meas;
        let a = &self.cfg.axes[i];
        if m.std_dynamics {
            a.meas.a_feedhold
        } else if m.rapid_decel_on_signal {
            a.a_rapid
        } else if m.feedhold_param_decel {
            a.meas.a_feedhold
        } else {
            a.a_rapid
        }
    }

    /// [`measurement_brake_decel`](Self::measurement_brake_decel) for block preparation.
    pub(super) fn measurement_brake_decel_pub(&self, i: usize) -> f64 {
        self.measurement_brake_decel(i)
    }

    /// Arm every source of the run (drive latch units now; confirmation is polled per cycle).
    /// With `CNC_DEFINED` (P-AXIS-00702) the CNC first writes the probing input into 0x60D0 by
    /// SDO and arms the latch (source 10b) once the drive has confirmed the write.
    fn arm_sources(&mut self, run: &mut MeasRun) -> Result<(), CncMessage> {
        for m in &mut run.axes {
            if !m.signal.uses_drive_latch() {
                continue;
            }
            let c = &self.cfg.axes[m.axis].meas;
            let mode = c.trigger_mode;
            let probe = if mode == TriggerSourceMode::Default {
                m.input.clamp(1, 2)
            } else {
                1
            };
            let trigger = match mode {
                TriggerSourceMode::Default => ProbeTrigger::Input,
                _ => ProbeTrigger::SourceObject,
            };
            let req = ProbeRequest {
                probe,
                edge: m.edge,
                trigger,
                continuous: false,
                source_mode: mode,
                input: m.input,
            };
            let name = self.axes[m.axis].name().to_string();
            if mode == TriggerSourceMode::CncDefined {
                let what = format!(
                    "0x60D0:{probe:02} = {} (P-AXIS-00702 CNC_DEFINED, axis {name})",
                    m.input
                );
                let id = self.queue_acyclic(
                    m.axis,
                    0x60D0,
                    probe,
                    super::acyclic::AcyclicOp::Write(i64::from(m.input)),
                    false,
                    &what,
                );
                m.source_sdo = Some((id, req));
                continue;
            }
            self.axes[m.axis].arm_probe(&req).map_err(|e| {
                CncMessage::error(
                    ids::MEAS_LATCH,
                    format!("axis {name}: cannot arm the drive latch: {e}"),
                )
                .on_axis(&name)
            })?;
        }
        Ok(())
    }

    /// Disarm every source of the run; the PLC gets its DISABLE task.
    pub(super) fn disarm_sources(&mut self, run: &MeasRun) {
        let now = self.now;
        for m in &run.axes {
            if m.signal.uses_drive_latch() {
                self.axes[m.axis].disarm_probe();
            }
            self.plc[m.axis].measuring_r = false;
            if m.handshake {
                if let Some(c) = self.ext_latch[m.axis].as_mut() {
                    // A refused DISABLE (another task still waiting) is owed and written at the
                    // next block start by the client itself.
                    let _ = c.end_measuring_block(&mut self.plc[m.axis].ext_latch, now);
                }
            }
        }
    }

    /// Per cycle, before interpolation: arming progress and latch collection. `s` is the path
    /// position last commanded. Returns what the interpolator must do.
    pub(super) fn measurement_step(&mut self, run: &mut MeasRun, now: Nanos, s: f64) -> MeasStep {
        match run.phase {
            Phase::Arming { cycles } => {
                let mut all = true;
                if !run.armed_once {
                    run.armed_once = true;
                    for m in &mut run.axes {
                        if let Some(e) = m.eval.as_mut() {
                            e.arm(now, &self.plc[m.axis]);
                            self.plc[m.axis].measuring_r = true;
                        }
                    }
                }
                for m in &run.axes {
                    if m.handshake {
                        if let Some(c) = self.ext_latch[m.axis].as_mut() {
                            match c.start_measuring_block(&mut self.plc[m.axis].ext_latch, now) {
                                BlockGate::Go => {}
                                BlockGate::Wait => all = false,
                                BlockGate::Failed(task) => {
                                    return MeasStep::Fail(CncMessage::error(
                                        ids::MEAS_LATCH,
                                        format!(
                                            "axis {}: the PLC did not acknowledge {task:?}",
                                            self.axes[m.axis].name()
                                        ),
                                    ));
                                }
                            }
                        }
                    }
                }
                for m in &mut run.axes {
                    if let Some((id, req)) = m.source_sdo {
                        match self.take_acyclic_result(id) {
                            None => {
                                all = false;
                                continue;
                            }
                            Some(Ok(_)) => {
                                m.source_sdo = None;
                                let name = self.axes[m.axis].name().to_string();
                                if let Err(e) = self.axes[m.axis].arm_probe(&req) {
                                    return MeasStep::Fail(
                                        CncMessage::error(
                                            ids::MEAS_LATCH,
                                            format!("axis {name}: cannot arm the drive latch: {e}"),
                                        )
                                        .on_axis(&name),
                                    );
                                }
                                all = false;
                                continue;
                            }
                            // The channel reported the failed write already and is stopping.
                            Some(Err(e)) => {
                                return MeasStep::Fail(CncMessage::error(
                                    ids::MEAS_LATCH,
                                    format!("0x60D0 write failed: {e}"),
                                ));
                            }
                        }
                    }
                }
                for m in &run.axes {
                    if !m.signal.uses_drive_latch() {
                        continue;
                    }
                    match self.axes[m.axis].probe_state() {
                        ProbeState::Armed => {}
                        ProbeState::Failed(why) => {
                            let name = self.axes[m.axis].name().to_string();
                            return MeasStep::Fail(
                                CncMessage::error(
                                    ids::MEAS_LATCH,
                                    format!("axis {name}: drive latch failed while arming: {why}"),
                                )
                                .on_axis(&name),
                            );
                        }
                        _ => all = false,
                    }
                }
                if all {
                    run.phase = Phase::Measuring;
                    MeasStep::Go
                } else if cycles >= ARMING_TIMEOUT_CYCLES {
                    MeasStep::Fail(CncMessage::error(
                        ids::MEAS_LATCH,
                        format!("the probing-signal sources did not confirm arming within {ARMING_TIMEOUT_CYCLES} cycles"),
                    ))
                } else {
                    run.phase = Phase::Arming { cycles: cycles + 1 };
                    MeasStep::Hold
                }
            }
            Phase::Measuring => {
                let was_complete = run.complete();
                for k in 0..run.axes.len() {
                    let (axis, signal) = (run.axes[k].axis, run.axes[k].signal);
                    let event = if signal.uses_drive_latch() {
                        if let ProbeState::Failed(why) = self.axes[axis].probe_state() {
                            let name = self.axes[axis].name().to_string();
                            return MeasStep::Fail(
                                CncMessage::error(
                                    ids::MEAS_LATCH,
                                    format!("axis {name}: drive latch failed: {why}"),
                                )
                                .on_axis(&name),
                            );
                        }
                        self.axes[axis].take_latch()
                    } else if let Some(e) = run.axes[k].eval.as_mut() {
                        let actual = self.axes[axis].actual();
                        match e.update(now, actual, &self.plc[axis]) {
                            Ok(ev) => ev.map(|ev| ev.position),
                            Err(err) => {
                                let name = self.axes[axis].name().to_string();
                                return MeasStep::Fail(
                                    CncMessage::error(
                                        ids::MEAS_LATCH,
                                        format!("axis {name}: {} signal: {err}", signal.name()),
                                    )
                                    .on_axis(&name),
                                );
                            }
                        }
                    } else if signal == SignalSource::FixedStop {
                        let a = &self.axes[axis];
                        let travelled = (a.command() - run.axes[k].start).abs();
                        let detected = run
                            .fixed
                            .as_mut()
                            .and_then(|d| d.update(now, k, travelled, a.lag(), a.actual()));
                        if detected.is_some() {
                            // The measuring point is latched for each axis involved (seed 004
                            // §7.3): every axis of the run takes its actual position, and all move
                            // there at once ("reduce interpolation to measured value").
                            let mut settle = Vec::new();
                            for m in &mut run.axes {
                                let p = self.axes[m.axis].actual();
                                if let Some(log) = self.latch_log.as_mut() {
                                    log.push((now, m.axis, p));
                                }
                                m.latched = Some((p, now));
                                m.before_target = s < run.target_len - 1e-9;
                                settle.push((m.axis, p));
                            }
                            run.event_s = Some(s);
                            return MeasStep::Settle(settle);
                        }
                        None
                    } else {
                        None
                    };
                    if let Some(pos) = event {
                        let m = &mut run.axes[k];
                        if m.latched.is_none() {
                            m.latched = Some((pos, now));
                            m.before_target = s < run.target_len - 1e-9;
                            if let Some(log) = self.latch_log.as_mut() {
                                log.push((now, axis, pos));
                            }
                        }
                    }
                }
                if !was_complete && run.complete() {
                    run.event_s = Some(s);
                    if run.mtype == MeasType::Type3 {
                        MeasStep::Go
                    } else {
                        MeasStep::Brake
                    }
                } else {
                    MeasStep::Go
                }
            }
            Phase::Done => MeasStep::Go,
        }
    }

    /// Path deceleration for braking along `segment` after the signal.
    pub(super) fn path_brake_decel(&self, run: &MeasRun, segment: &Segment) -> f64 {
        let mut a = f64::INFINITY;
        for (i, &d) in run.brake.iter().enumerate() {
            let f = segment.axis_speed_factor(i);
            if f > 1e-12 {
                a = a.min(d / f);
            }
        }
        if a.is_finite() && a > 0.0 {
            a
        } else {
            1.0
        }
    }

    /// The block is over (standstill): disarm, decide about errors, publish the outcome. An
    /// error (missing signal per type) is returned; nothing is published then. Returns the
    /// positions some axes must move to at once: a type-7 run without detected stop and
    /// P-CHAN-00266 = 1 "goes to the position of the current axis actual value … to eliminate a
    /// possible position lag" (§8.2.1).
    pub(super) fn finish_measurement(
        &mut self,
        mut run: MeasRun,
        target_reached: bool,
    ) -> Result<Vec<(usize, f64)>, CncMessage> {
        run.phase = Phase::Done;
        self.disarm_sources(&run);
        let n = self.axes.len();
        let complete = run.complete();
        if !complete {
            let missing: Vec<&str> = run
                .axes
                .iter()
                .filter(|a| a.required && a.latched.is_none())
                .map(|a| self.axes[a.axis].name())
                .collect();
            let list = missing.join(", ");
            let m = &self.cfg.meas;
            let error = if run.limited_at_sls {
                Some(CncMessage::error(
                    ids::MEAS_PATH_LIMITED,
                    format!("measurement run stopped at the software limit switch without probing signal (axes {list})"),
                ))
            } else {
                match run.mtype {
                    MeasType::Type2 => Some(CncMessage::error(
                        ids::MEAS_NO_SIGNAL,
                        format!("measurement type 2: probing signal missing (axes {list})"),
                    )),
                    MeasType::Type1 if m.error_no_signal_type1 => Some(CncMessage::error(
                        ids::MEAS_NO_SIGNAL,
                        format!("probing signal missing (axes {list}; P-CHAN-00176 = 1)"),
                    )),
                    MeasType::Type7 if !m.fixed_stop_no_error => Some(CncMessage::error(
                        ids::MEAS_NO_FIXED_STOP,
                        format!("measurement type 7: fixed stop not detected (axes {list}; P-CHAN-00266 = 0)"),
                    )),
                    _ => None,
                }
            };
            if let Some(e) = error {
                return Err(e);
            }
        }
        let settle: Vec<(usize, f64)> =
            if run.mtype == MeasType::Type7 && !complete && self.cfg.meas.fixed_stop_no_error {
                run.lagging_axes(&self.axes)
            } else {
                Vec::new()
            };
        let mut latched = vec![None; n];
        let mut merf = vec![false; n];
        let mut involved = vec![false; n];
        if complete {
            for a in &run.axes {
                involved[a.axis] = true;
                if let Some((p, _)) = a.latched {
                    latched[a.axis] = Some(p);
                    merf[a.axis] = a.before_target;
                }
            }
        } else {
            for a in &run.axes {
                involved[a.axis] = a.required;
            }
        }
        let new = MeasurementOutcome {
            mtype: run.mtype,
            latched,
            merf,
            involved,
            target_reached,
        };
        // Independent axes of one block finish one by one: merge their outcomes until taken.
        self.measurement = Some(match self.measurement.take() {
            Some(old) => merge_outcomes(old, new),
            None => new,
        });
        Ok(settle)
    }

    /// The signal source axis `i` measures with in a running (armed) measurement, if any — with
    /// `#MEAS [AXNR=.. SIGNAL=..]` overrides applied.
    pub fn armed_signal(&self, i: usize) -> Option<SignalSource> {
        let of = |m: &super::Motion| {
            m.meas
                .as_ref()
                .and_then(|r| r.axes.iter().find(|a| a.axis == i).map(|a| a.signal))
        };
        let path = match &self.mode {
            super::Mode::Moving(m) => of(m),
            _ => None,
        };
        path.or_else(|| {
            self.indp
                .iter()
                .flatten()
                .find_map(|slot| of(slot.motion()))
        })
    }

    /// Axis `i` is in a running measurement to a fixed stop (type 7).
    pub(super) fn fixed_stop_run_on(&self, i: usize) -> bool {
        let run_has = |m: &super::Motion| {
            m.meas
                .as_ref()
                .is_some_and(|r| r.mtype == MeasType::Type7 && r.has_axis(i))
        };
        let path = matches!(&self.mode, super::Mode::Moving(m) if run_has(m));
        path || self
            .indp
            .iter()
            .flatten()
            .any(|slot| run_has(slot.motion()))
    }

    /// Record latched values for a trace (`--trace`).
    pub fn record_latches(&mut self, on: bool) {
        self.latch_log = on.then(Vec::new);
    }

    /// Latched values recorded since the last call: (time, axis, ACS position).
    pub fn take_latch_log(&mut self) -> Vec<(Nanos, usize, f64)> {
        self.latch_log
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }

    /// The outcome of the last measuring block, taken once.
    pub fn take_measurement(&mut self) -> Option<MeasurementOutcome> {
        self.measurement.take()
    }

    /// Indices of the main axes X, Y, Z.
    pub fn main_axes(&self) -> [Option<usize>; 3] {
        [
            self.axis_index("X"),
            self.axis_index("Y"),
            self.axis_index("Z"),
        ]
    }
}

/// What the interpolator does after [`Channel::measurement_step`].
#[derive(Debug, Clone, PartialEq)]
pub(super) enum MeasStep {
    /// Hold the set-points (arming).
    Hold,
    /// Interpolate as planned.
    Go,
    /// The probing signal is complete: brake along the path.
    Brake,
    /// Fixed stop detected (type 7): set the axes to these positions and end the block.
    Settle(Vec<(usize, f64)>),
    /// Abort the block with this error.
    Fail(CncMessage),
}

/// Combine two outcomes of the same block (independent axes): per axis the one that involved it.
fn merge_outcomes(old: MeasurementOutcome, new: MeasurementOutcome) -> MeasurementOutcome {
    let n = old.latched.len().max(new.latched.len());
    let pick = |i: usize| new.involved.get(i).copied().unwrap_or(false);
    MeasurementOutcome {
        mtype: new.mtype,
        latched: (0..n)
            .map(|i| {
                if pick(i) {
                    new.latched.get(i).copied().flatten()
                } else {
                    old.latched.get(i).copied().flatten()
                }
            })
            .collect(),
        merf: (0..n)
            .map(|i| {
                if pick(i) {
                    new.merf.get(i).copied().unwrap_or(false)
                } else {
                    old.merf.get(i).copied().unwrap_or(false)
                }
            })
            .collect(),
        involved: (0..n)
            .map(|i| pick(i) || old.involved.get(i).copied().unwrap_or(false))
            .collect(),
        target_reached: old.target_reached && new.target_reached,
    }
}

impl Channel {
    /// `#MEAS PREPARE [AXNR=..]` (seed 004 §7.2): ask the PLC to prepare the switchable probe of
    /// axis `axis` ahead of the measuring block.
    pub fn prepare_probe(&mut self, axis: usize) -> Result<(), CncMessage> {
        if axis >= self.axes.len() {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                "#MEAS PREPARE: no such axis",
            ));
        }
        let c = &self.cfg.axes[axis].meas;
        let (signal, input, edge) = (c.signal, c.input, c.edge);
        if !matches!(
            signal,
            SignalSource::ExtProbeWithDrive | SignalSource::PlcExtLatchControl
        ) {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                format!(
                    "#MEAS PREPARE: axis {} measures with {}; PREPARE needs EXT_PROBE_WITH_DRIVE or PLC_EXT_LATCH_CONTROL (P-AXIS-00516)",
                    self.axes[axis].name(),
                    signal.name()
                ),
            ));
        }
        let cfg = ExtLatchConfig::new(signal, input, edge, None)
            .map_err(|e| CncMessage::error(ids::MEAS_CONFIG, format!("#MEAS PREPARE: {e}")))?;
        let now = self.now;
        let client = self.ext_latch[axis].get_or_insert_with(|| ExtLatchClient::new(cfg));
        client
            .prepare(&mut self.plc[axis].ext_latch, now)
            .map_err(|e| CncMessage::error(ids::MEAS_LATCH, format!("#MEAS PREPARE: {e}")))?;
        self.prepared[axis] = true;
        Ok(())
    }

    /// The cycle of the PLC that delivers the probing signal (`None`: the NC cycle). A PLC
    /// slower than the NC cycle widens the window in which a `PLC_TIMESTAMP` must lie.
    pub fn set_plc_cycle(&mut self, cycle: Option<Nanos>) {
        self.cfg.meas.plc_cycle = cycle;
    }

    /// Program end (seed 004 §7.2 Notice): the preparation of all prepared axes is reset.
    pub fn program_end(&mut self) {
        for c in self.ext_latch.iter_mut().flatten() {
            c.clear_preparation();
        }
        self.prepared.iter_mut().for_each(|p| *p = false);
    }

    /// Homing of axis `i` (G74): resets the preparation of every prepared axis when `i` was
    /// prepared (seed 004 §7.2 Notice).
    pub fn homing(&mut self, i: usize) {
        if self.prepared.get(i).copied().unwrap_or(false) {
            self.program_end();
        }
        self.set_referenced(i, true);
    }

    /// The PLC interface of axis `i` (control units and the external-latch handshake) — what a
    /// machine builder's PLC glue reads and writes between cycles.
    pub fn plc(&self, i: usize) -> Option<&crate::core::measure::plc::AxisPlc> {
        self.plc.get(i)
    }

    /// The PLC interface of axis `i`, mutable.
    pub fn plc_mut(&mut self, i: usize) -> Option<&mut crate::core::measure::plc::AxisPlc> {
        self.plc.get_mut(i)
    }

    /// Per cycle: let the external-latch clients see the PLC's acknowledgements.
    pub(super) fn poll_handshakes(&mut self, now: Nanos) {
        for (c, p) in self.ext_latch.iter_mut().zip(self.plc.iter_mut()) {
            if let Some(c) = c {
                c.poll(&mut p.ext_latch, now);
            }
        }
    }
}
