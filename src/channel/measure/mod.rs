//! Measurement runs in the channel (FCT-C4): a G100 / G210 / G310 block is a linear motion
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
//! Which axes take part (FCT-C4 §1): the measurement axes programmed in the block, with `#CS`
//! the three main axes; no other axis's probe is armed. Which of them must latch (§4): in 2.5D
//! every measurement axis the block moves; with `#CS` all three main axes. Braking uses the deceleration of the §2.1 table ("measurement
//! signal active" column) for the non-linear slope parameter set our interpolator uses.

use super::Channel;
use crate::core::measure::fixed_stop::{FixedStopAxis, FixedStopDetector, FixedStopError};
use crate::core::measure::plc::{
    BlockGate, EvaluatorConfig, ExtLatchClient, ExtLatchConfig, SignalEvaluator, SourceEvaluator,
    TimestampConfig,
};
use crate::core::measure::run::{
    contact_path_position, latched_before_target, missing_signal_error,
};
use crate::core::measure::timestamp::{DcClock, DeadTimes};
use crate::core::measure::{MeasType, MeasurementOutcome, SignalSource};
use crate::core::path::Segment;
use crate::drive::{ProbeEdge, ProbeRequest, ProbeState, ProbeTrigger, TriggerSourceMode};
use crate::messages::{ids, CncMessage};
use crate::units::Nanos;

mod prepare;
mod step;

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
    /// `#CS` is active: the three main axes must all latch (FCT-C4 §4).
    pub cs_active: bool,
    /// Per channel axis: the axis is programmed in the measuring block. Only these (and with
    /// `#CS` the three main axes) take part: "The measuring function is initialised and
    /// activated for the axes programmed in the measurement block" (FCT-C4 §1). A shorter
    /// list reads the missing axes as not programmed.
    pub programmed: Vec<bool>,
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
    /// The drive reported the event; its value may still be on the way.
    triggered: bool,
    /// Evaluator of a PLC signal source.
    eval: Option<SourceEvaluator>,
    /// The PLC's external-latch handshake gates this axis (PLC_EXT_LATCH_CONTROL,
    /// EXT_PROBE_WITH_DRIVE).
    handshake: bool,
    /// The handshake let this block go (ENABLE acknowledged).
    gate_open: bool,
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
    /// Start of the measuring line and its unit direction (per channel axis): where a latched
    /// position lies on the path.
    origin: Vec<f64>,
    dir: Vec<f64>,
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

    /// Every required axis latched or reported its event (its value may still be on the way):
    /// the probing signal is complete for the motion.
    fn signalled(&self) -> bool {
        self.axes
            .iter()
            .filter(|a| a.required)
            .all(|a| a.latched.is_some() || a.triggered)
            && self.axes.iter().any(|a| a.latched.is_some() || a.triggered)
    }

    /// An axis reported its event but its value has not arrived yet.
    pub(super) fn values_pending(&self) -> bool {
        self.axes.iter().any(|a| a.triggered && a.latched.is_none())
    }

    /// Measurement type.
    pub(super) fn mtype(&self) -> MeasType {
        self.mtype
    }

    /// Path position (distance from the start along the measuring line) of the contact the
    /// latched positions describe ([`contact_path_position`]).
    fn contact_s(&self) -> Option<f64> {
        contact_path_position(
            self.axes
                .iter()
                .filter_map(|a| a.latched.map(|(p, _)| (a.axis, p))),
            &self.origin,
            &self.dir,
        )
    }

    /// V.A.MERF per axis ([`latched_before_target`]): the contact lies on the path before the
    /// programmed target (FCT-C4 §8), judged from where the latched positions are, not from
    /// where the command was when the latch arrived (the command runs the link's dead time
    /// ahead of the axis).
    fn decide_merf(&mut self) {
        let s = self.contact_s();
        let target = self.target_len;
        for a in &mut self.axes {
            a.before_target = a.latched.is_some() && latched_before_target(s, target);
        }
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

    /// Axis `i` is in a running measurement to a fixed stop (type 7), or in the move back to
    /// its latched position that ends one.
    pub(super) fn fixed_stop_run_on(&self, i: usize) -> bool {
        let run_has = |m: &super::Motion| {
            m.meas
                .as_ref()
                .is_some_and(|r| r.mtype == MeasType::Type7 && r.has_axis(i))
                || (m.fixed_stop_return && m.moved.get(i).copied().unwrap_or(false))
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

    /// Latched values recorded since the last call: (time of the latch, axis, ACS position).
    /// Only latches that became measurement results are recorded, when the block publishes them.
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
    /// Abort the block with this error.
    Fail(CncMessage),
}

impl Channel {
    /// `#MEAS PREPARE [AXNR=..]` (FCT-C4 §7.2): ask the PLC to prepare the switchable probe of
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

    /// Program end (FCT-C4 §7.2 Notice): the preparation of all prepared axes is reset.
    pub fn program_end(&mut self) {
        for c in self.ext_latch.iter_mut().flatten() {
            c.clear_preparation();
        }
        self.prepared.iter_mut().for_each(|p| *p = false);
    }

    /// Homing of axis `i` (G74): resets the preparation of every prepared axis when `i` was
    /// prepared (FCT-C4 §7.2 Notice).
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

    /// The PLC interface of axis `i` as it was when the actual position read this cycle was
    /// sampled, and that time: the input images carry the drives' actual values
    /// `dead time − 1` cycles after they were sampled (one on every link, see
    /// [`crate::axis::Axis::lag`]), while the PLC sees its inputs at once. The PLC-family
    /// signal sources pair the signal with the position of the same instant — a PLC-sampled
    /// value lies behind the crossing by at most v·T, a DC timestamp is back-calculated on the
    /// samples' own time base — at the cost of reacting one cycle later.
    pub(in crate::channel) fn plc_view(
        &self,
        i: usize,
    ) -> (Nanos, &crate::core::measure::plc::AxisPlc) {
        let delay = self.axes[i].dead_time_cycles().saturating_sub(1) as usize;
        let seen = &self.plc_seen[i];
        let bus = self.plc_from_bus.get(i).copied().unwrap_or(false);
        match seen.get(delay.min(seen.len().saturating_sub(1))) {
            // Inputs latched at the same SYNC0 as the actual value: the current interface
            // belongs to the sample's instant.
            Some((t, _)) if bus => (*t, &self.plc[i]),
            Some((t, plc)) => (*t, plc),
            None => (self.now, &self.plc[i]),
        }
    }

    /// Axis `i`'s PLC interface is fed from inputs that cross the bus with the drives' actual
    /// values (`true`): a timestamp input terminal on the same segment latches at the same SYNC0
    /// as the drive samples its position, so what the interface shows in a cycle belongs to
    /// the instant of the actual value read in that cycle, and the evaluation pairs them
    /// without the delay a PLC that sees its inputs at once needs.
    pub fn set_plc_inputs_from_bus(&mut self, i: usize, on: bool) {
        if let Some(f) = self.plc_from_bus.get_mut(i) {
            *f = on;
        }
    }

    /// Per cycle, after the exchange: the DC system time at which the devices sampled the
    /// inputs just read ([`crate::link::Link::sample_dc_time`]). An axis whose PLC interface is
    /// fed from the bus ([`Channel::set_plc_inputs_from_bus`]) then stamps its actual values
    /// with it for PLC_TIMESTAMP, so the terminal's DC timestamps and the positions share one
    /// time base; `None`: the cycle's own time on [`DcClock::default`].
    pub fn set_sample_dc_time(&mut self, dc: Option<i64>) {
        self.sample_dc = dc;
    }

    /// The DC time base of axis `i`'s sample at cycle time `t` (see
    /// [`set_sample_dc_time`](Self::set_sample_dc_time)): `t` is DC time `sample_dc`.
    pub(in crate::channel) fn sample_dc_clock(&self, i: usize, t: Nanos) -> Option<DcClock> {
        let dc = self.sample_dc?;
        if !self.plc_from_bus.get(i).copied().unwrap_or(false) {
            return None;
        }
        let t = i64::try_from(t.0).ok()?;
        Some(DcClock::new(dc.checked_sub(t)?))
    }

    /// Per cycle, before the sources are evaluated: remember what the PLC interface showed.
    pub(super) fn record_plc_view(&mut self, now: Nanos) {
        for (i, seen) in self.plc_seen.iter_mut().enumerate() {
            let keep = self.axes[i].dead_time_cycles().max(1) as usize;
            seen.push_front((now, self.plc[i]));
            seen.truncate(keep);
        }
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
