//! PLC interface of the measurement (FCT-C4 §7.1, §7.2, §7.4, §7.5, §8.2.3): the library API
//! a machine builder's PLC glue and the CNC channel use.
//!
//! * [`ControlUnit`] — the HLI control unit of FCT-C4 §8.2.3 (`command_w`, `enable_w`,
//!   `request_r`, `state_r`); [`AxisPlc`] bundles the units of one axis (`probing_signal`,
//!   `timestamp`, `probing_position`) with the axis' external-latch interface.
//! * [`ExtLatchInterface`] / [`ExtLatchClient`] — the external-latch handshake of §7.2 / §7.4
//!   (tasks PREPARE / ENABLE / DISABLE, `please_rw`, `done_w`) and the CNC-side rules around it.
//! * Signal evaluators, one per PLC source of P-AXIS-00516: [`PlcEvaluator`] (`PLC`),
//!   [`PlcFirstEventEvaluator`] (`PLC_FIRST_EVENT`), [`ExtLatchEvaluator`]
//!   (`PLC_EXT_LATCH_CONTROL`), [`TimestampEvaluator`] (`PLC_TIMESTAMP`), all behind
//!   [`SignalEvaluator`] and the dispatching [`SourceEvaluator`].
//!
//! Everything is sans-IO: time comes in as [`Nanos`]; nothing allocates per cycle.
//!
//! # Scope of the external-latch handshake: per axis
//!
//! The task carries "the required parameter number of the probing input and the relevant edge"
//! (§7.2), which are axis parameters (P-AXIS-00517 / 00518), and `#MEAS PREPARE [AXNR=..]`
//! names an axis, so one [`ExtLatchInterface`] and one [`ExtLatchClient`] exist per axis. The
//! channel-wide reset rules of §7.2 (homing / exchange of *one* prepared axis resets the
//! preparation of *all* axes; program end resets all) are applied over all clients of a channel
//! by [`reset_preparations`].
//!
//! # `PLC` versus `PLC_FIRST_EVENT` (project interpretation; the seed only names the value)
//!
//! * `PLC` ([`PlcEvaluator`]): the CNC evaluates the edge of P-AXIS-00518 on `probing_signal`
//!   as sampled in the CNC cycle (§7.1, §8.2.3 "Edge evaluation"). Every qualifying edge while
//!   armed yields an event (a bouncing probe gives several; the measurement normally keeps the
//!   first, type 3 may keep the last).
//! * `PLC_FIRST_EVENT` ([`PlcFirstEventEvaluator`]): the PLC itself catches the *first* probe
//!   event (a latching input, a fast PLC task, or edges between PLC samples) and holds
//!   `probing_signal` TRUE until the measurement ends. What reaches the CNC is therefore a
//!   *level* meaning "event occurred", not the probe's own signal: the CNC triggers on the first
//!   cycle in which the signal is TRUE after it was seen FALSE since arming (a TRUE already
//!   present at arming is a stale latch of the previous run and is ignored until the PLC clears
//!   it), **regardless of P-AXIS-00518** (the PLC already applied the probe's edge), and it
//!   **never re-triggers** until re-armed (later toggles are bounces or the PLC clearing its
//!   latch). The measured value is the actual value of that CNC cycle, as with `PLC`.
//!
//! # `PLC_EXT_LATCH_CONTROL` and the §7.4 notice
//!
//! The event is a positive edge of `probing_signal`, independent of P-AXIS-00518; the position is
//! the effective value of `probing_position`. §7.4 says that if "the probing_signal control unit
//! is not enabled when the probing event occurs, the actual value at the time the probing signal
//! occurs is used". With the control-unit rule (effective value = command when enabled, else the
//! CNC's own value) a disabled `probing_signal` can never show an edge, so the notice is
//! implemented for the unit that carries the value: when `probing_position` is not enabled, its
//! effective value is the CNC's own value, the actual position of that cycle.

use thiserror::Error;

use super::timestamp::{DcClock, DeadTimes, TimestampBuffer, TimestampError};
use super::SignalSource;
use crate::drive::ProbeEdge;
use crate::units::Nanos;

// ---------------------------------------------------------------------------------------------
// Control units (FCT-C4 §8.2.3)
// ---------------------------------------------------------------------------------------------

/// An HLI control unit (FCT-C4 §8.2.3, `MC_CONTROL_*_UNIT`): the PLC writes `command_w` and
/// `enable_w` ("redirection"); the CNC uses the command when enabled, otherwise its own value,
/// and reports its own value in `request_r` and the value in effect in `state_r`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControlUnit<T> {
    /// Value commanded by the PLC.
    pub command_w: T,
    /// The PLC's command replaces the CNC's own value.
    pub enable_w: bool,
    /// The CNC's own (requested) value, written by [`ControlUnit::publish`].
    pub request_r: T,
    /// The value in effect, written by [`ControlUnit::publish`].
    pub state_r: T,
}

impl<T: Copy> ControlUnit<T> {
    /// A unit with all values `initial`, not enabled.
    pub fn new(initial: T) -> Self {
        ControlUnit {
            command_w: initial,
            enable_w: false,
            request_r: initial,
            state_r: initial,
        }
    }

    /// PLC side: write the command and enable the redirection.
    pub fn plc_command(&mut self, value: T) {
        self.command_w = value;
        self.enable_w = true;
    }

    /// PLC side: give control back to the CNC (`enable_w = FALSE`).
    pub fn plc_release(&mut self) {
        self.enable_w = false;
    }

    /// Whether the PLC's command is in effect.
    pub fn is_enabled(&self) -> bool {
        self.enable_w
    }

    /// The value in effect given the CNC's own value (no side effect).
    #[inline]
    pub fn effective(&self, own: T) -> T {
        if self.enable_w {
            self.command_w
        } else {
            own
        }
    }

    /// CNC side: write `request_r` (own value) and `state_r` (value in effect); returns the
    /// value in effect.
    pub fn publish(&mut self, own: T) -> T {
        self.request_r = own;
        self.state_r = self.effective(own);
        self.state_r
    }
}

/// The PLC-facing measurement interface of one axis (`gpAx[axis_idx]^.lr_mc_control.*`, seed
/// 004 §8.2.3) plus the axis' external-latch handshake (§7.2 / §7.4).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AxisPlc {
    /// `probing_signal` (BOOL): the probe signal for `PLC`, `PLC_FIRST_EVENT`, `PLC_TIMESTAMP`,
    /// the "event detected" signal for `PLC_EXT_LATCH_CONTROL`. The CNC's own value is FALSE.
    pub probing_signal: ControlUnit<bool>,
    /// `timestamp` (LINT, ns on the DC time base) for `PLC_TIMESTAMP`. The CNC's own value is 0.
    pub timestamp: ControlUnit<i64>,
    /// `probing_position` (mm / °) for `PLC_EXT_LATCH_CONTROL`. The CNC's own value is the
    /// actual position.
    pub probing_position: ControlUnit<f64>,
    /// External-latch handshake (`PLC_EXT_LATCH_CONTROL`, `EXT_PROBE_WITH_DRIVE`).
    pub ext_latch: ExtLatchInterface,
    /// CNC → PLC: a measuring block of this axis is armed and waiting for the probing signal
    /// (project interpretation; the seed names no such datum). A PLC that latches the first
    /// probe event itself (`PLC_FIRST_EVENT`) clears its latch on the rising edge, so an event
    /// from before the measurement is never taken as the measured one.
    pub measuring_r: bool,
}

impl AxisPlc {
    /// Effective `probing_signal` (FALSE unless the PLC enabled it).
    #[inline]
    pub fn probing_signal(&self) -> bool {
        self.probing_signal.effective(false)
    }

    /// Effective `timestamp`, `None` when the unit is not enabled (the CNC has no own value).
    #[inline]
    pub fn timestamp(&self) -> Option<i64> {
        self.timestamp.enable_w.then_some(self.timestamp.command_w)
    }

    /// Effective `probing_position` given the actual position.
    #[inline]
    pub fn probing_position(&self, actual: f64) -> f64 {
        self.probing_position.effective(actual)
    }

    /// CNC side, once per cycle: write `request_r` / `state_r` of all units.
    pub fn publish(&mut self, actual: f64) {
        self.probing_signal.publish(false);
        self.timestamp.publish(0);
        self.probing_position.publish(actual);
    }
}

// ---------------------------------------------------------------------------------------------
// External-latch handshake (FCT-C4 §7.2, §7.4)
// ---------------------------------------------------------------------------------------------

/// A task of the external-latch interface (FCT-C4 §7.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ExtLatchTask {
    /// `HLI_EXT_LATCH_PREPARE_PROBE` (`#MEAS PREPARE`): switch the probe on early.
    Prepare,
    /// `HLI_EXT_LATCH_ENABLE_PROBE`: start of the measuring block.
    Enable,
    /// `HLI_EXT_LATCH_DISABLE_PROBE`: end of the measurement run.
    Disable,
}

/// The task as written to the interface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ExtLatchJob {
    /// What to do.
    pub task: ExtLatchTask,
    /// Probing input (P-AXIS-00517).
    pub input: u8,
    /// Relevant edge (P-AXIS-00518).
    pub edge: ProbeEdge,
}

/// The shared handshake memory of one axis (HLI naming: `_r` read by the PLC, `_w` written by
/// the PLC, `_rw` both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExtLatchInterface {
    /// The task the CNC wrote (valid while or after `please_rw` was set).
    pub job_r: Option<ExtLatchJob>,
    /// Set by the CNC with a new task, cleared by the PLC when it has read it.
    pub please_rw: bool,
    /// Set by the PLC when the task is done; cleared by the CNC when it takes the
    /// acknowledgement or writes the next task.
    pub done_w: bool,
}

impl ExtLatchInterface {
    /// PLC side: take a new task (clears `please_rw`), if one is waiting.
    pub fn plc_take_task(&mut self) -> Option<ExtLatchJob> {
        if self.please_rw {
            self.please_rw = false;
            self.job_r
        } else {
            None
        }
    }

    /// PLC side: acknowledge the task (`done_w = TRUE`).
    pub fn plc_acknowledge(&mut self) {
        self.done_w = true;
    }
}

/// Status of the handshake as [`ExtLatchClient::poll`] reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ExtLatchStatus {
    /// Nothing requested since the last reset.
    Idle,
    /// A task is written and not yet acknowledged.
    Waiting {
        /// The task.
        task: ExtLatchTask,
        /// When it was written.
        since: Nanos,
    },
    /// The last task was acknowledged (`done_w`).
    Done(ExtLatchTask),
    /// The last task was not acknowledged within the configured timeout; it was withdrawn.
    Timeout(ExtLatchTask),
}

/// What the CNC believes about the probe, from acknowledged tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ProbeReadiness {
    /// Off (initial, after DISABLE, after a reset).
    #[default]
    Off,
    /// PREPARE acknowledged.
    Prepared,
    /// ENABLE acknowledged: the measuring block may move.
    Enabled,
}

/// The interpolator's gate at the start of a measuring block ([`ExtLatchClient::start_measuring_block`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BlockGate {
    /// Do not move yet; call again next cycle.
    Wait,
    /// ENABLE acknowledged: the measuring block may start.
    Go,
    /// A task timed out; the channel reports an error and resets.
    Failed(ExtLatchTask),
}

/// Errors of the external-latch configuration and requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum ExtLatchError {
    /// The signal source does not use the external-latch interface.
    #[error("signal source {0:?} does not use the external-latch interface")]
    NotExtLatchSource(SignalSource),
    /// The probing input is outside the range of the source (P-AXIS-00517 table: 1–255 for
    /// `PLC_EXT_LATCH_CONTROL`, 1–2 for `EXT_PROBE_WITH_DRIVE`).
    #[error("probing input {input} out of range {min}..={max} for {signal:?}")]
    InputOutOfRange {
        /// The signal source.
        signal: SignalSource,
        /// The input.
        input: u8,
        /// Smallest valid input.
        min: u8,
        /// Largest valid input.
        max: u8,
    },
    /// A task is still waiting for its acknowledgement (a new task is rejected, not
    /// overwritten — ISG MC platform rule).
    #[error("external-latch task {0:?} still waiting for acknowledgement")]
    Busy(ExtLatchTask),
}

/// Configuration of one axis' external-latch client.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ExtLatchConfig {
    /// `PLC_EXT_LATCH_CONTROL` or `EXT_PROBE_WITH_DRIVE`.
    pub source: SignalSource,
    /// Probing input (P-AXIS-00517).
    pub input: u8,
    /// Edge (P-AXIS-00518).
    pub edge: ProbeEdge,
    /// Give up waiting for `done_w` after this long (`None`: wait forever, as the seed's
    /// interpolator does).
    pub timeout: Option<Nanos>,
}

impl ExtLatchConfig {
    /// Validate the source and the input range (FCT-C4 §8.2.2 P-AXIS-00517 table).
    pub fn new(
        source: SignalSource,
        input: u8,
        edge: ProbeEdge,
        timeout: Option<Nanos>,
    ) -> Result<Self, ExtLatchError> {
        let (min, max) = match source {
            SignalSource::PlcExtLatchControl => (1, 255),
            SignalSource::ExtProbeWithDrive => (1, 2),
            other => return Err(ExtLatchError::NotExtLatchSource(other)),
        };
        if input < min || input > max {
            return Err(ExtLatchError::InputOutOfRange {
                signal: source,
                input,
                min,
                max,
            });
        }
        Ok(ExtLatchConfig {
            source,
            input,
            edge,
            timeout,
        })
    }
}

/// Events that reset the preparation of `#MEAS PREPARE` (FCT-C4 §7.2 notice).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PreparationReset {
    /// Homing of the axis with this index (into the clients slice).
    Homing(usize),
    /// The axis with this index is exchanged from the channel.
    AxisExchange(usize),
    /// End of the NC program.
    ProgramEnd,
}

/// CNC side of one axis' external-latch handshake (FCT-C4 §7.2 / §7.4), sans-IO.
///
/// Low level: [`request`](Self::request) writes a task, [`poll`](Self::poll) watches for the
/// acknowledgement. The seed's rules are in the high-level calls:
/// * [`prepare`](Self::prepare) — `#MEAS PREPARE`.
/// * [`start_measuring_block`](Self::start_measuring_block) — call every cycle at the start of
///   the measuring block until [`BlockGate::Go`]: waits for a pending PREPARE ("the interpolator
///   does not move to the measuring block until the PLC acknowledges that probe preparation is
///   completed"), waits for an outstanding DISABLE ("before a new measurement run starts, the
///   system waits until the PLC acknowledges DISABLE"; a DISABLE that timed out is written
///   again), then writes ENABLE and waits for its acknowledgement.
/// * [`end_measuring_block`](Self::end_measuring_block) — DISABLE at the end of the run.
/// * [`cnc_reset`](Self::cnc_reset) and [`reset_preparations`] — the reset rules: a CNC reset
///   withdraws any pending task and clears the preparation, so the probe is enabled "as normal
///   at the start of the measuring block"; homing / axis exchange / program end clear the
///   preparation without touching a pending handshake.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExtLatchClient {
    config: ExtLatchConfig,
    pending: Option<(ExtLatchTask, Nanos)>,
    status: ExtLatchStatus,
    readiness: ProbeReadiness,
    /// A DISABLE was requested and not yet acknowledged.
    disable_owed: bool,
    /// The preparation was reset while PREPARE was pending: its acknowledgement does not
    /// prepare.
    ignore_prepare_ack: bool,
    /// Inside [`ExtLatchClient::start_measuring_block`] (between its first call and Go).
    starting: bool,
}

impl ExtLatchClient {
    /// A client in the idle state.
    pub fn new(config: ExtLatchConfig) -> Self {
        ExtLatchClient {
            config,
            pending: None,
            status: ExtLatchStatus::Idle,
            readiness: ProbeReadiness::Off,
            disable_owed: false,
            ignore_prepare_ack: false,
            starting: false,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ExtLatchConfig {
        &self.config
    }

    /// The last status (as the last [`poll`](Self::poll) / request left it).
    pub fn status(&self) -> ExtLatchStatus {
        self.status
    }

    /// What the acknowledged tasks say about the probe.
    pub fn readiness(&self) -> ProbeReadiness {
        self.readiness
    }

    /// `#MEAS PREPARE` was acknowledged and not reset since.
    pub fn is_prepared(&self) -> bool {
        self.readiness == ProbeReadiness::Prepared
    }

    /// No DISABLE is outstanding, so a new measurement run may start.
    pub fn new_run_allowed(&self) -> bool {
        !self.disable_owed
    }

    /// Write `task` with the configured input and edge and set `please_rw`. Rejected while a
    /// task is waiting.
    pub fn request(
        &mut self,
        iface: &mut ExtLatchInterface,
        task: ExtLatchTask,
        now: Nanos,
    ) -> Result<(), ExtLatchError> {
        if let Some((pending, _)) = self.pending {
            return Err(ExtLatchError::Busy(pending));
        }
        iface.done_w = false;
        iface.job_r = Some(ExtLatchJob {
            task,
            input: self.config.input,
            edge: self.config.edge,
        });
        iface.please_rw = true;
        self.pending = Some((task, now));
        self.status = ExtLatchStatus::Waiting { task, since: now };
        if task == ExtLatchTask::Disable {
            self.disable_owed = true;
        }
        if task == ExtLatchTask::Prepare {
            self.ignore_prepare_ack = false;
        }
        Ok(())
    }

    /// Watch for the acknowledgement of the pending task (takes `done_w`) and for the timeout.
    pub fn poll(&mut self, iface: &mut ExtLatchInterface, now: Nanos) -> ExtLatchStatus {
        let Some((task, since)) = self.pending else {
            return self.status;
        };
        if iface.done_w {
            iface.done_w = false;
            iface.please_rw = false;
            self.pending = None;
            self.status = ExtLatchStatus::Done(task);
            match task {
                ExtLatchTask::Prepare => {
                    if !self.ignore_prepare_ack && self.readiness == ProbeReadiness::Off {
                        self.readiness = ProbeReadiness::Prepared;
                    }
                    self.ignore_prepare_ack = false;
                }
                ExtLatchTask::Enable => self.readiness = ProbeReadiness::Enabled,
                ExtLatchTask::Disable => {
                    self.readiness = ProbeReadiness::Off;
                    self.disable_owed = false;
                }
            }
        } else if let Some(limit) = self.config.timeout {
            if now.0.saturating_sub(since.0) >= limit.0 {
                iface.please_rw = false;
                self.pending = None;
                self.status = ExtLatchStatus::Timeout(task);
                if task == ExtLatchTask::Prepare {
                    self.ignore_prepare_ack = false;
                }
            }
        }
        self.status
    }

    /// `#MEAS PREPARE [AXNR=..]`: write PREPARE. Rejected while a task is waiting.
    pub fn prepare(
        &mut self,
        iface: &mut ExtLatchInterface,
        now: Nanos,
    ) -> Result<(), ExtLatchError> {
        self.request(iface, ExtLatchTask::Prepare, now)
    }

    /// Start of the measuring block; call every cycle until [`BlockGate::Go`] (see the type
    /// documentation for the rules). Every measuring block writes its own ENABLE; a status left
    /// over from before the block (an old acknowledgement or timeout) does not count.
    pub fn start_measuring_block(
        &mut self,
        iface: &mut ExtLatchInterface,
        now: Nanos,
    ) -> BlockGate {
        let status = self.poll(iface, now);
        if let ExtLatchStatus::Waiting { .. } = status {
            self.starting = true;
            return BlockGate::Wait;
        }
        if self.starting {
            match status {
                ExtLatchStatus::Timeout(task) => return BlockGate::Failed(task),
                ExtLatchStatus::Done(ExtLatchTask::Enable)
                    if self.readiness == ProbeReadiness::Enabled =>
                {
                    self.starting = false;
                    return BlockGate::Go;
                }
                _ => {}
            }
        }
        self.starting = true;
        let task = if self.disable_owed {
            ExtLatchTask::Disable
        } else {
            ExtLatchTask::Enable
        };
        // Cannot be busy: poll() above reported nothing waiting.
        let _ = self.request(iface, task, now);
        BlockGate::Wait
    }

    /// End of the measurement run (probe latched or run aborted): write DISABLE. Rejected while
    /// a task is waiting.
    pub fn end_measuring_block(
        &mut self,
        iface: &mut ExtLatchInterface,
        now: Nanos,
    ) -> Result<(), ExtLatchError> {
        self.starting = false;
        self.request(iface, ExtLatchTask::Disable, now)
    }

    /// CNC reset: withdraw a pending task (`please_rw = done_w = FALSE`), forget the
    /// preparation and any enable; the status returns to [`ExtLatchStatus::Idle`]. A following
    /// measuring block enables the probe as normal (FCT-C4 §7.2 "Basics").
    pub fn cnc_reset(&mut self, iface: &mut ExtLatchInterface) {
        iface.please_rw = false;
        iface.done_w = false;
        self.pending = None;
        self.status = ExtLatchStatus::Idle;
        self.readiness = ProbeReadiness::Off;
        self.disable_owed = false;
        self.ignore_prepare_ack = false;
        self.starting = false;
    }

    /// Clear the preparation (homing, axis exchange, program end). A pending PREPARE still
    /// has to be acknowledged but no longer prepares.
    pub fn clear_preparation(&mut self) {
        if self.readiness == ProbeReadiness::Prepared {
            self.readiness = ProbeReadiness::Off;
        }
        if matches!(self.pending, Some((ExtLatchTask::Prepare, _))) {
            self.ignore_prepare_ack = true;
        }
    }

    fn preparation_involved(&self) -> bool {
        self.is_prepared() || matches!(self.pending, Some((ExtLatchTask::Prepare, _)))
    }
}

/// Apply a preparation reset of FCT-C4 §7.2 to all clients of a channel (indexed like the
/// channel's axes): homing or exchange of a *prepared* axis (or one with PREPARE pending) resets
/// the preparation of all axes; program end resets all. Returns whether anything was reset.
pub fn reset_preparations(clients: &mut [ExtLatchClient], event: PreparationReset) -> bool {
    let trigger = match event {
        PreparationReset::Homing(axis) | PreparationReset::AxisExchange(axis) => clients
            .get(axis)
            .is_some_and(ExtLatchClient::preparation_involved),
        PreparationReset::ProgramEnd => true,
    };
    if trigger {
        for c in clients.iter_mut() {
            c.clear_preparation();
        }
    }
    trigger
}

// ---------------------------------------------------------------------------------------------
// Signal evaluators (FCT-C4 §7.1, §7.4, §7.5)
// ---------------------------------------------------------------------------------------------

/// A probing event found by an evaluator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceEvent {
    /// Measured position (mm / °, ACS).
    pub position: f64,
    /// When the event happened (the CNC cycle for sampled sources, the back-calculated event
    /// time for `PLC_TIMESTAMP`).
    pub at: Nanos,
    /// Bound of the position error (mm / °): |v|·latency for sampled sources, the
    /// interpolation bound for timestamps, the configured hardware bound for the external
    /// latch; `f64::INFINITY` when unknown.
    pub error_bound: f64,
}

/// Why an evaluator could not produce a position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SourceError {
    /// `PLC_TIMESTAMP`: the `timestamp` control unit is not enabled at the signal edge.
    #[error("PLC_TIMESTAMP: timestamp control unit not enabled at the probing signal")]
    TimestampNotEnabled,
    /// `PLC_TIMESTAMP`: the timestamp did not change within two cycles after the edge.
    #[error("PLC_TIMESTAMP: timestamp unchanged since the previous event")]
    StaleTimestamp,
    /// `PLC_TIMESTAMP`: back-calculation failed.
    #[error("PLC_TIMESTAMP: {0}")]
    Timestamp(TimestampError),
    /// `PLC_TIMESTAMP`: the timestamp lies outside the window in which the probing signal
    /// changed (DC ns): the timestamp is off (wrong dead time, stale or future value).
    #[error("PLC_TIMESTAMP: timestamp {edge} ns is outside the window ({low}, {high}] ns in which the probing signal changed")]
    InconsistentTimestamp {
        /// Event time from the timestamp (dead times removed).
        edge: i64,
        /// Last DC time the signal was seen inactive (less the slack).
        low: i64,
        /// DC time the signal was first seen active.
        high: i64,
    },
}

/// One evaluator per PLC signal source. Call [`update`](Self::update) every CNC cycle, armed or
/// not (levels and, for timestamps, actual values are tracked while disarmed), after the PLC's
/// outputs of that cycle are in place.
pub trait SignalEvaluator {
    /// Start looking for an event. The levels present now are the reference: a level already
    /// present at arming is not an edge.
    fn arm(&mut self, now: Nanos, plc: &AxisPlc);
    /// Stop looking for events.
    fn disarm(&mut self);
    /// Whether armed.
    fn is_armed(&self) -> bool;
    /// One CNC cycle with the axis' actual position (mm / °) of this cycle.
    fn update(
        &mut self,
        now: Nanos,
        actual: f64,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError>;
}

/// Speed tracking for the |v|·latency error bound of sampled sources.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Speed {
    last: Option<(Nanos, f64)>,
    speed: f64,
}

impl Speed {
    fn update(&mut self, now: Nanos, actual: f64) {
        if let Some((t, x)) = self.last {
            let dt = now.0.saturating_sub(t.0);
            if dt > 0 {
                let v = (actual - x).abs() / (dt as f64 * 1e-9);
                self.speed = if v.is_finite() { v } else { f64::INFINITY };
            }
        }
        if actual.is_finite() {
            self.last = Some((now, actual));
        }
    }

    fn bound(&self, latency: Nanos) -> f64 {
        if self.last.is_none() {
            return f64::INFINITY;
        }
        self.speed * latency.as_secs_f64()
    }
}

/// `PLC` (FCT-C4 §7.1): edge of P-AXIS-00518 on `probing_signal` sampled in the CNC cycle;
/// the measured value is the actual value of that cycle. Every qualifying edge while armed is an
/// event.
///
/// The value lags the physical crossing by the sampling delay, so it lies *behind* the true
/// crossing in the direction of motion by 0 … |v|·latency ( uniform in
/// [0, v·T]). `latency` is the worst-case delay from the physical edge to the CNC cycle that
/// sees it: the CNC cycle when the PLC runs synchronously with it, PLC period + CNC cycle
/// otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlcEvaluator {
    edge: ProbeEdge,
    latency: Nanos,
    armed: bool,
    prev: bool,
    speed: Speed,
}

impl PlcEvaluator {
    /// An evaluator for the given edge (P-AXIS-00518) and worst-case sampling latency.
    pub fn new(edge: ProbeEdge, latency: Nanos) -> Self {
        PlcEvaluator {
            edge,
            latency,
            armed: false,
            prev: false,
            speed: Speed::default(),
        }
    }
}

#[inline]
fn is_edge(edge: ProbeEdge, prev: bool, now: bool) -> bool {
    match edge {
        ProbeEdge::Positive => !prev && now,
        ProbeEdge::Negative => prev && !now,
    }
}

impl SignalEvaluator for PlcEvaluator {
    fn arm(&mut self, _now: Nanos, plc: &AxisPlc) {
        self.armed = true;
        self.prev = plc.probing_signal();
    }

    fn disarm(&mut self) {
        self.armed = false;
    }

    fn is_armed(&self) -> bool {
        self.armed
    }

    fn update(
        &mut self,
        now: Nanos,
        actual: f64,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError> {
        self.speed.update(now, actual);
        let level = plc.probing_signal();
        let edge = is_edge(self.edge, self.prev, level);
        self.prev = level;
        Ok((self.armed && edge).then(|| SourceEvent {
            position: actual,
            at: now,
            error_bound: self.speed.bound(self.latency),
        }))
    }
}

/// `PLC_FIRST_EVENT` (project interpretation, see the module documentation): the first cycle
/// with `probing_signal` TRUE after it was seen FALSE since arming, regardless of P-AXIS-00518;
/// one event per arming. Value and error bound as [`PlcEvaluator`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlcFirstEventEvaluator {
    latency: Nanos,
    armed: bool,
    seen_clear: bool,
    fired: bool,
    speed: Speed,
}

impl PlcFirstEventEvaluator {
    /// An evaluator with the given worst-case sampling latency.
    pub fn new(latency: Nanos) -> Self {
        PlcFirstEventEvaluator {
            latency,
            armed: false,
            seen_clear: false,
            fired: false,
            speed: Speed::default(),
        }
    }

    /// Whether the event of this arming has been reported.
    pub fn has_fired(&self) -> bool {
        self.fired
    }
}

impl SignalEvaluator for PlcFirstEventEvaluator {
    fn arm(&mut self, _now: Nanos, plc: &AxisPlc) {
        self.armed = true;
        self.fired = false;
        self.seen_clear = !plc.probing_signal();
    }

    fn disarm(&mut self) {
        self.armed = false;
    }

    fn is_armed(&self) -> bool {
        self.armed
    }

    fn update(
        &mut self,
        now: Nanos,
        actual: f64,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError> {
        self.speed.update(now, actual);
        if !self.armed || self.fired {
            return Ok(None);
        }
        if !plc.probing_signal() {
            self.seen_clear = true;
            return Ok(None);
        }
        if !self.seen_clear {
            return Ok(None);
        }
        self.fired = true;
        Ok(Some(SourceEvent {
            position: actual,
            at: now,
            error_bound: self.speed.bound(self.latency),
        }))
    }
}

/// `PLC_EXT_LATCH_CONTROL` (FCT-C4 §7.4): positive edge of `probing_signal` (independent of
/// P-AXIS-00518); position = effective `probing_position` (the external hardware's value when
/// enabled, else the actual value of the cycle). Every positive edge while armed is an event.
/// Arm it once ENABLE is acknowledged ([`ExtLatchClient`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtLatchEvaluator {
    hardware_bound: f64,
    latency: Nanos,
    armed: bool,
    prev: bool,
    speed: Speed,
}

impl ExtLatchEvaluator {
    /// `hardware_bound`: error bound (mm / °) reported for positions from the external
    /// hardware; `latency`: sampling latency for the fallback to the actual value.
    pub fn new(hardware_bound: f64, latency: Nanos) -> Self {
        ExtLatchEvaluator {
            hardware_bound,
            latency,
            armed: false,
            prev: false,
            speed: Speed::default(),
        }
    }
}

impl SignalEvaluator for ExtLatchEvaluator {
    fn arm(&mut self, _now: Nanos, plc: &AxisPlc) {
        self.armed = true;
        self.prev = plc.probing_signal();
    }

    fn disarm(&mut self) {
        self.armed = false;
    }

    fn is_armed(&self) -> bool {
        self.armed
    }

    fn update(
        &mut self,
        now: Nanos,
        actual: f64,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError> {
        self.speed.update(now, actual);
        let level = plc.probing_signal();
        let rising = !self.prev && level;
        self.prev = level;
        if !(self.armed && rising) {
            return Ok(None);
        }
        let (position, error_bound) = if plc.probing_position.is_enabled() {
            (plc.probing_position.command_w, self.hardware_bound)
        } else {
            (actual, self.speed.bound(self.latency))
        };
        Ok(Some(SourceEvent {
            position,
            at: now,
            error_bound,
        }))
    }
}

/// Configuration of a [`TimestampEvaluator`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TimestampConfig {
    /// Edge of `probing_signal` (P-AXIS-00518, FCT-C4 §8.2.3 "Edge evaluation").
    pub edge: ProbeEdge,
    /// NC cycle.
    pub cycle: Nanos,
    /// Samples kept (rounded up to a power of two ≥ 32).
    pub capacity: usize,
    /// Dead times.
    pub dead: DeadTimes,
    /// Virtual time ↔ DC time.
    pub clock: DcClock,
    /// Check the timestamp against the probing signal: the edge must lie after the last cycle
    /// in which the signal was seen inactive (less this slack — the PLC period beyond the NC
    /// cycle when the PLC samples asynchronously) and not after the cycle in which it was first
    /// seen active. A timestamp that contradicts its own signal (e.g. one cycle off) is
    /// [`SourceError::InconsistentTimestamp`]. `None`: no check.
    pub signal_window: Option<Nanos>,
}

/// Cycles an edge may wait for a fresh timestamp (beyond the wait for the bracketing sample).
const STALE_WAIT_CYCLES: u32 = 2;

/// `PLC_TIMESTAMP` (FCT-C4 §7.5): edge of P-AXIS-00518 on `probing_signal`; the event time is
/// the `timestamp` control unit (DC ns); the position is calculated back from the buffered
/// actual values ([`TimestampBuffer`]).
///
/// Every [`update`](SignalEvaluator::update) pushes the cycle's actual value at the cycle's DC
/// time ([`DcClock::dc_time`] of `now`; [`TimestampEvaluator::update_dc`] takes an explicit DC
/// time and velocity). Because actual values arrive late by the sample dead times, the corrected
/// event time may lie after the newest sample when the edge is seen; the evaluation then waits
/// for the sample after it (at most ⌈(input shift + drive delay) / cycle⌉ + 2 cycles), so that it
/// interpolates instead of extrapolating. A timestamp equal to the one consumed last (or present
/// at arming) is waited for within the same limit, then [`SourceError::StaleTimestamp`]. When
/// the wait ends without a bracketing sample the buffer extrapolates within one cycle or reports
/// [`TimestampError::TooNew`].
#[derive(Debug, Clone)]
pub struct TimestampEvaluator {
    config: TimestampConfig,
    buffer: TimestampBuffer,
    armed: bool,
    prev: bool,
    last_ts: Option<i64>,
    pending: Option<u32>,
    max_wait: u32,
    /// DC time of the last cycle with the signal at its inactive level.
    last_inactive: Option<i64>,
    /// Window (low, high] of the pending edge.
    window: Option<(i64, i64)>,
}

impl TimestampEvaluator {
    /// Allocates the buffer once.
    pub fn new(config: TimestampConfig) -> Self {
        let cycle = config.cycle.0.max(1);
        let shift = config.dead.sample_shift().max(0) as u64;
        let bracket = shift.div_ceil(cycle).min(u32::MAX as u64 / 2) as u32;
        TimestampEvaluator {
            buffer: TimestampBuffer::new(config.capacity, config.cycle, config.dead),
            config,
            armed: false,
            prev: false,
            last_ts: None,
            pending: None,
            max_wait: bracket + STALE_WAIT_CYCLES,
            last_inactive: None,
            window: None,
        }
    }

    /// The buffer of actual values.
    pub fn buffer(&self) -> &TimestampBuffer {
        &self.buffer
    }

    /// The configuration.
    pub fn config(&self) -> &TimestampConfig {
        &self.config
    }

    /// The relation of the run's time to DC time from now on: a link that reads the DC system
    /// time of each cycle's samples (`Link::sample_dc_time`) sets it per cycle, so that
    /// [`update`](SignalEvaluator::update) at the sample's cycle time pushes the sample at its
    /// DC time, on the time base the timestamps come from.
    pub fn set_dc_clock(&mut self, clock: DcClock) {
        self.config.clock = clock;
    }

    /// One CNC cycle with an explicit DC time of the cycle and optional actual velocity.
    /// Samples that are not later than the newest one or not finite are skipped.
    pub fn update_dc(
        &mut self,
        dc_time: i64,
        actual: f64,
        velocity: Option<f64>,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError> {
        let _ = match velocity {
            Some(v) => self.buffer.push_with_velocity(dc_time, actual, v),
            None => self.buffer.push(dc_time, actual),
        };
        let level = plc.probing_signal();
        let edge = is_edge(self.config.edge, self.prev, level);
        self.prev = level;
        let active_level = self.config.edge == ProbeEdge::Positive;
        let last_inactive = self.last_inactive;
        if level != active_level {
            self.last_inactive = Some(dc_time);
        }
        if !self.armed {
            return Ok(None);
        }
        if edge && self.pending.is_none() {
            self.pending = Some(0);
            self.window = Some((last_inactive.unwrap_or(i64::MIN), dc_time));
        }
        let Some(waited) = self.pending else {
            return Ok(None);
        };
        let Some(ts) = plc.timestamp() else {
            self.pending = None;
            return Err(SourceError::TimestampNotEnabled);
        };
        let can_wait = waited < self.max_wait;
        if Some(ts) == self.last_ts {
            if !can_wait {
                self.pending = None;
                return Err(SourceError::StaleTimestamp);
            }
            self.pending = Some(waited + 1);
            return Ok(None);
        }
        let query = self.buffer.dead_times().query_time(ts);
        if can_wait && self.buffer.newest_time().is_some_and(|n| query > n) {
            self.pending = Some(waited + 1);
            return Ok(None);
        }
        self.pending = None;
        self.last_ts = Some(ts);
        let event_time = ts.saturating_sub(self.buffer.dead_times().event_shift());
        if let (Some(slack), Some((low, high))) = (self.config.signal_window, self.window.take()) {
            let low = low.saturating_sub(i64::try_from(slack.0).unwrap_or(i64::MAX));
            if event_time <= low || event_time > high {
                return Err(SourceError::InconsistentTimestamp {
                    edge: event_time,
                    low,
                    high,
                });
            }
        }
        let est = self
            .buffer
            .estimate_at(ts)
            .map_err(SourceError::Timestamp)?;
        Ok(Some(SourceEvent {
            position: est.position,
            at: self.config.clock.to_nanos(event_time),
            error_bound: est.error_bound,
        }))
    }
}

impl SignalEvaluator for TimestampEvaluator {
    fn arm(&mut self, _now: Nanos, plc: &AxisPlc) {
        self.armed = true;
        self.prev = plc.probing_signal();
        self.last_ts = plc.timestamp();
        self.pending = None;
    }

    fn disarm(&mut self) {
        self.armed = false;
        self.pending = None;
    }

    fn is_armed(&self) -> bool {
        self.armed
    }

    fn update(
        &mut self,
        now: Nanos,
        actual: f64,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError> {
        let dc = self.config.clock.dc_time(now);
        self.update_dc(dc, actual, None, plc)
    }
}

/// Settings from which [`SourceEvaluator::for_source`] builds an evaluator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvaluatorConfig {
    /// P-AXIS-00518.
    pub edge: ProbeEdge,
    /// Worst-case sampling latency of the PLC path (CNC cycle, + PLC period if asynchronous).
    pub latency: Nanos,
    /// Error bound of the external measuring hardware (`PLC_EXT_LATCH_CONTROL`).
    pub hardware_bound: f64,
    /// `PLC_TIMESTAMP` settings.
    pub timestamp: TimestampConfig,
}

/// The evaluator for a PLC signal source of P-AXIS-00516.
#[derive(Debug, Clone)]
pub enum SourceEvaluator {
    /// `PLC`.
    Plc(PlcEvaluator),
    /// `PLC_FIRST_EVENT`.
    FirstEvent(PlcFirstEventEvaluator),
    /// `PLC_EXT_LATCH_CONTROL`.
    ExtLatch(ExtLatchEvaluator),
    /// `PLC_TIMESTAMP`.
    Timestamp(Box<TimestampEvaluator>),
}

impl SourceEvaluator {
    /// The evaluator for `source`, or `None` for sources not evaluated from the PLC interface
    /// (drive latches, fixed stop).
    pub fn for_source(source: SignalSource, config: &EvaluatorConfig) -> Option<Self> {
        Some(match source {
            SignalSource::Plc => {
                SourceEvaluator::Plc(PlcEvaluator::new(config.edge, config.latency))
            }
            SignalSource::PlcFirstEvent => {
                SourceEvaluator::FirstEvent(PlcFirstEventEvaluator::new(config.latency))
            }
            SignalSource::PlcExtLatchControl => SourceEvaluator::ExtLatch(ExtLatchEvaluator::new(
                config.hardware_bound,
                config.latency,
            )),
            SignalSource::PlcTimestamp => {
                SourceEvaluator::Timestamp(Box::new(TimestampEvaluator::new(config.timestamp)))
            }
            _ => return None,
        })
    }

    /// `PLC_TIMESTAMP`: see [`TimestampEvaluator::set_dc_clock`]; the other sources have no
    /// DC time.
    pub fn set_dc_clock(&mut self, clock: DcClock) {
        if let SourceEvaluator::Timestamp(t) = self {
            t.set_dc_clock(clock);
        }
    }

    fn inner(&mut self) -> &mut dyn SignalEvaluator {
        match self {
            SourceEvaluator::Plc(e) => e,
            SourceEvaluator::FirstEvent(e) => e,
            SourceEvaluator::ExtLatch(e) => e,
            SourceEvaluator::Timestamp(e) => e.as_mut(),
        }
    }
}

impl SignalEvaluator for SourceEvaluator {
    fn arm(&mut self, now: Nanos, plc: &AxisPlc) {
        self.inner().arm(now, plc)
    }

    fn disarm(&mut self) {
        self.inner().disarm()
    }

    fn is_armed(&self) -> bool {
        match self {
            SourceEvaluator::Plc(e) => e.is_armed(),
            SourceEvaluator::FirstEvent(e) => e.is_armed(),
            SourceEvaluator::ExtLatch(e) => e.is_armed(),
            SourceEvaluator::Timestamp(e) => e.is_armed(),
        }
    }

    fn update(
        &mut self,
        now: Nanos,
        actual: f64,
        plc: &AxisPlc,
    ) -> Result<Option<SourceEvent>, SourceError> {
        self.inner().update(now, actual, plc)
    }
}
