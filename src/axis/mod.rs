//! One axis: drive adapter, scaling and state (referenced, command / actual / lag).
//!
//! The axis layer is where drive increments become mm (°) and back, through
//! [`Scaling`] from the drive file. It does not know wire formats: the
//! adapter encodes and decodes the process image, the link moves it.

use crate::drive::catalogue::DriveDefinition;
use crate::drive::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, ProbeRequest, ProbeState,
};
use crate::units::{Nanos, Scaling};

/// Errors of the axis layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AxisError {
    /// The drive adapter failed (short image, bad definition).
    #[error("axis {axis}: {source}")]
    Drive {
        /// Axis name.
        axis: String,
        /// Cause.
        source: DriveError,
    },
    /// The command position does not fit the drive's INTEGER32 position range.
    #[error("axis {axis}: command position {position:.6} is outside the drive's position range")]
    OutOfRange {
        /// Axis name.
        axis: String,
        /// Offending position (mm / °).
        position: f64,
    },
}

/// Largest dead time (cycles) an axis accepts ([`Axis::set_dead_time_cycles`]).
pub const MAX_DEAD_TIME_CYCLES: u32 = 16;

/// One axis of the channel.
///
/// # Lag
///
/// The CNC's position lag ([`Axis::lag`]) compares the actual value with the command *delayed
/// by the link's dead time* (the cycles between sending a set-point and reading the position it
/// produced, [`crate::link::Link::dead_time_cycles`]): the actual value read now was produced
/// by the set-point sent that many cycles ago. A drive with feed-forward at constant speed thus
/// shows ≈ 0 lag, a stalled one its real lag — as in a production CNC's lag monitoring. The
/// drive's own following error, where its image carries one, is [`Axis::drive_lag`].
#[derive(Debug)]
pub struct Axis {
    name: String,
    adapter: Box<dyn DriveAdapter>,
    scaling: Scaling,
    referenced: bool,
    enable: bool,
    fault_reset: bool,
    /// Last command position (mm / °).
    command: f64,
    /// Last actual position (mm / °).
    actual: f64,
    /// Position lag (mm / °) as the CNC sees it: the command of [`Axis::dead_time_cycles`]
    /// cycles ago − the actual position.
    lag: f64,
    /// The drive's own following error (0x60F4, S-0-0189 …) where its image carries one.
    drive_lag: Option<f64>,
    /// Commands sent, newest first ([`Axis::dead_time_cycles`] of them are needed).
    sent: [f64; MAX_DEAD_TIME_CYCLES as usize],
    /// Cycles between sending a set-point and reading the position it produced.
    dead_time: u32,
    feedback: Option<DriveFeedback>,
    /// The command has been aligned with the actual position (before enabling).
    aligned: bool,
    /// The drive definition (function table, IDN map), when known.
    definition: Option<std::sync::Arc<DriveDefinition>>,
    /// Drive position − CNC position (mm / °): the whole modulo ranges the axis was wrapped by
    /// ([`Axis::wrap_modulo`]).
    wrap: f64,
}

impl Axis {
    /// A new axis on the given adapter.
    pub fn new(
        name: impl Into<String>,
        adapter: Box<dyn DriveAdapter>,
        scaling: Scaling,
        referenced: bool,
    ) -> Self {
        Axis {
            name: name.into(),
            adapter,
            scaling,
            referenced,
            enable: false,
            fault_reset: false,
            command: 0.0,
            actual: 0.0,
            lag: 0.0,
            drive_lag: None,
            sent: [0.0; MAX_DEAD_TIME_CYCLES as usize],
            dead_time: crate::link::DEFAULT_DEAD_TIME_CYCLES,
            feedback: None,
            aligned: false,
            definition: None,
            wrap: 0.0,
        }
    }

    /// Attach the drive definition (function table for `#DRIVE`, IDN map for `#IDENT`).
    pub fn with_definition(mut self, definition: std::sync::Arc<DriveDefinition>) -> Self {
        self.definition = Some(definition);
        self
    }

    /// The drive definition, when known.
    pub fn definition(&self) -> Option<&DriveDefinition> {
        self.definition.as_deref()
    }

    /// Axis name (`X`, `Y2`, …).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Bytes of the output image the adapter needs.
    pub fn output_len(&self) -> usize {
        self.adapter.output_len()
    }

    /// Bytes of the input image the adapter needs.
    pub fn input_len(&self) -> usize {
        self.adapter.input_len()
    }

    /// Whether the axis is referenced (G74 done) — SLS monitoring depends on it.
    pub fn is_referenced(&self) -> bool {
        self.referenced
    }

    /// Set the referenced state.
    pub fn set_referenced(&mut self, referenced: bool) {
        self.referenced = referenced;
    }

    /// The drive's power stage is off in `state`, as its family's profile defines it.
    pub fn power_stage_off(&self, state: crate::drive::PowerState) -> bool {
        self.adapter.power_stage_off(state)
    }

    /// Decode this cycle's input image.
    pub fn read(&mut self, now: Nanos, inputs: &[u8]) -> Result<&DriveFeedback, AxisError> {
        let fb = self
            .adapter
            .read_inputs(now, inputs)
            .map_err(|source| AxisError::Drive {
                axis: self.name.clone(),
                source,
            })?;
        self.actual = self.scaling.to_units(fb.position) - self.wrap;
        self.drive_lag = fb.following_error.map(|fe| self.scaling.delta_to_units(fe));
        if !self.aligned || !fb.operational {
            // Cyclic synchronous position: while the drive does not follow, the target must
            // track the actual position so that enabling causes no jump (CiA 402 §8.3 CSP).
            self.command = self.actual;
            self.sent = [self.actual; MAX_DEAD_TIME_CYCLES as usize];
            self.aligned = true;
        }
        self.lag = self.delayed_command() - self.actual;
        if self.feedback.map(|f| f.state) != Some(fb.state) {
            tracing::debug!(axis = %self.name, state = ?fb.state, statusword = format_args!("{:#06x}", fb.statusword), "drive power state");
        }
        let fb = self.feedback.insert(fb);
        Ok(fb)
    }

    /// The command sent [`dead_time_cycles`](Self::dead_time_cycles) cycles ago: the one the
    /// actual position read now belongs to.
    pub fn delayed_command(&self) -> f64 {
        let d = self.dead_time.clamp(1, MAX_DEAD_TIME_CYCLES) as usize;
        self.sent[d - 1]
    }

    /// Cycles between sending a set-point and reading the position it produced (default
    /// [`crate::link::DEFAULT_DEAD_TIME_CYCLES`]).
    pub fn dead_time_cycles(&self) -> u32 {
        self.dead_time
    }

    /// Set the dead time (clamped to 1 ..= [`MAX_DEAD_TIME_CYCLES`]).
    pub fn set_dead_time_cycles(&mut self, cycles: u32) {
        self.dead_time = cycles.clamp(1, MAX_DEAD_TIME_CYCLES);
        self.adapter
            .set_feedback_delay(self.dead_time.saturating_sub(1));
    }

    /// Encode this cycle's command into the output image.
    pub fn write(&mut self, now: Nanos, outputs: &mut [u8]) -> Result<(), AxisError> {
        let target = self
            .scaling
            .to_increments(self.command + self.wrap)
            .ok_or_else(|| AxisError::OutOfRange {
                axis: self.name.clone(),
                position: self.command + self.wrap,
            })?;
        let cmd = DriveCommand {
            enable: self.enable,
            target,
            fault_reset: self.fault_reset,
            quick_stop: false,
        };
        self.adapter
            .write_outputs(now, &cmd, outputs)
            .map_err(|source| AxisError::Drive {
                axis: self.name.clone(),
                source,
            })?;
        self.sent
            .copy_within(0..MAX_DEAD_TIME_CYCLES as usize - 1, 1);
        self.sent[0] = self.command;
        Ok(())
    }

    /// Ask for *operation enabled* (`true`) or disable.
    pub fn set_enable(&mut self, enable: bool) {
        self.enable = enable;
    }

    /// Request (or stop requesting) a fault reset.
    pub fn set_fault_reset(&mut self, reset: bool) {
        self.fault_reset = reset;
    }

    /// Set the command position (mm / °) for the next write.
    #[inline]
    pub fn set_command(&mut self, position: f64) {
        self.command = position;
    }

    /// Last command position (mm / °).
    #[inline]
    pub fn command(&self) -> f64 {
        self.command
    }

    /// Last actual position (mm / °).
    #[inline]
    pub fn actual(&self) -> f64 {
        self.actual
    }

    /// Position lag (mm / °): the command sent [`dead_time_cycles`](Self::dead_time_cycles)
    /// ago − the actual position (see the type's documentation).
    #[inline]
    pub fn lag(&self) -> f64 {
        self.lag
    }

    /// The drive's own following error (mm / °), where its image carries one (0x60F4,
    /// S-0-0189, XERR …).
    #[inline]
    pub fn drive_lag(&self) -> Option<f64> {
        self.drive_lag
    }

    /// Last feedback, if any arrived.
    pub fn feedback(&self) -> Option<&DriveFeedback> {
        self.feedback.as_ref()
    }

    /// The drive follows the cyclic command.
    pub fn is_operational(&self) -> bool {
        self.feedback.is_some_and(|f| f.operational)
    }

    /// The drive reports a fault.
    pub fn has_fault(&self) -> bool {
        self.feedback.is_some_and(|f| f.fault)
    }

    /// Arm the drive's latch unit (FCT-C4 §6).
    pub fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        self.adapter.arm_probe(request)
    }

    /// Disarm the drive's latch unit.
    pub fn disarm_probe(&mut self) {
        self.adapter.disarm_probe();
    }

    /// Write a cyclic drive function (telegram signal `index:sub`, see
    /// [`DriveAdapter::write_cyclic`]).
    pub fn write_cyclic(&mut self, index: u16, sub: u8, value: i64) -> Result<(), DriveError> {
        self.adapter.write_cyclic(index, sub, value)
    }

    /// Read back a cyclic drive function.
    pub fn read_cyclic(&self, index: u16, sub: u8) -> Result<i64, DriveError> {
        self.adapter.read_cyclic(index, sub)
    }

    /// State of the drive's latch unit.
    pub fn probe_state(&self) -> ProbeState {
        self.adapter.probe_state()
    }

    /// The drive reported its latch event; the value is still being read
    /// ([`DriveAdapter::probe_triggered`]).
    pub fn probe_triggered(&self) -> bool {
        self.adapter.probe_triggered()
    }

    /// The next fresh latched position (mm / °) decoded this cycle.
    pub fn take_latch(&mut self) -> Option<f64> {
        self.adapter
            .take_probe_event()
            .map(|e| self.scaling.to_units(e.position) - self.wrap)
    }

    /// A modulo axis at rest: bring its position into `[lower, upper)` by a whole number of
    /// ranges — command, actual and the commands in flight move together, the drive's own
    /// position does not (the difference is kept, see [`Axis::modulo_offset`]). Returns the
    /// shift subtracted (0: already inside, or an empty range).
    pub fn wrap_modulo(&mut self, lower: f64, upper: f64) -> f64 {
        let range = upper - lower;
        if !(range.is_finite() && range > 0.0 && self.command.is_finite()) {
            return 0.0;
        }
        let k = ((self.command - lower) / range).floor();
        if k == 0.0 || !k.is_finite() {
            return 0.0;
        }
        let shift = k * range;
        self.command -= shift;
        self.actual -= shift;
        for s in &mut self.sent {
            *s -= shift;
        }
        self.wrap += shift;
        shift
    }

    /// The drive's position − the CNC's (mm / °): the whole ranges a modulo axis was wrapped
    /// by ([`Axis::wrap_modulo`]); 0 for every other axis.
    pub fn modulo_offset(&self) -> f64 {
        self.wrap
    }

    /// Scaling of this axis.
    pub fn scaling(&self) -> Scaling {
        self.scaling
    }
}
