//! The CNC channel: block preparation, the interpolator and the per-cycle monitoring.
//!
//! One [`Channel::cycle`] is one interpolation cycle, in this order:
//!
//! ```text
//! adapter.read_inputs ─► axis feedback ─► monitor (actual positions, P-AXIS-00179)
//!   ─► interpolator (next set-points) ─► monitor (stop distance, P-AXIS-00520/00521)
//!   ─► adapter.write_outputs
//! ```
//!
//! Blocks enter through [`Channel::start_motion`] (block preparation: the whole command path is
//! checked against the software limit switches before anything moves) and
//! [`Channel::program_limit`] (G98 / G99). Manual mode lives in [`manual`]. The channel does not
//! know which bus an axis is on and never reads a clock: `now` comes in with each cycle.
//!
//! Motion blocks run rest to rest (exact stop at each block end) with trapezoidal (linear slope)
//! velocity profiles; look-ahead blending is not part of this build.

pub mod acyclic;
pub mod areas;
pub mod coupling;
mod cycle;
mod independent;
pub mod manual;
pub mod measure;
mod modulo;
pub mod power_off;
mod prep;
pub mod profile;

use crate::axis::Axis;
use crate::core::frames::Frames;
use crate::core::measure::{AxisMeasConfig, ChannelMeasConfig, MeasurementOutcome};
use crate::core::monitor::sls::{AxisLimitConfig, PcsLimits, SoftLimits, Violation};
use crate::core::path::{Segment, MAX_AXES};

use crate::messages::{BlockRef, CncMessage};
use crate::units::Nanos;
pub use cycle::LINK_LOST_GIVE_UP_CYCLES;
pub use measure::{MeasureRequest, SignalOverride};
use profile::{Braking, Trapezoid};

/// Dynamics and limits of one channel axis, in mm (°), s.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelAxisConfig {
    /// Rotary axis (P-AXIS-00018).
    pub rotary: bool,
    /// The modulo range `[lower, upper)` (°) of a rotary axis with ACHSMODE_MODULO
    /// (P-AXIS-00015; P-AXIS-00127 / 00126): at rest its position is kept inside it.
    pub modulo: Option<(f64, f64)>,
    /// P-AXIS-00212 maximum axis velocity (mm/s) — also the rapid (G00) velocity.
    pub v_max: f64,
    /// P-AXIS-00001 acceleration at machining feed (mm/s²).
    pub a_feed: f64,
    /// P-AXIS-00002 deceleration at machining feed (mm/s²).
    pub d_feed: f64,
    /// P-AXIS-00004 acceleration in rapid traverse (mm/s²).
    pub a_rapid: f64,
    /// P-AXIS-00003 emergency deceleration (mm/s²): stops after errors.
    pub a_emergency: f64,
    /// Software limit switch configuration (FCT-A2).
    pub limits: AxisLimitConfig,
    /// Measurement configuration (FCT-C4).
    pub meas: AxisMeasConfig,
    /// In-position window of an exact stop (mm / °, machine key `in_position_window`): a block
    /// that ends at rest is over when |command − actual| of every moved axis is inside it.
    pub in_position: f64,
    /// Time the drive's actual position lags its set-point at constant speed (s): lag = v × this.
    /// 0 for a drive with velocity feed-forward; 1/kv for one without (drive file `[model]`).
    pub servo_lag_time: f64,
}

/// Channel configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelConfig {
    /// Interpolation cycle.
    pub cycle: Nanos,
    /// Per-axis configuration, in channel axis order.
    pub axes: Vec<ChannelAxisConfig>,
    /// P-CHAN-00498 `range_check_prog_soft_limits`.
    pub range_check_programmed_limits: bool,
    /// P-CHAN-00489 `display_pcs_limits`.
    pub display_pcs_limits: bool,
    /// P-MANU-00014 `move_limit_warning`.
    pub move_limit_warning: bool,
    /// P-CHAN-00442 `suppress_workspace_monitoring_manual_mode` (FCT-C14 §5, §6.2): 0 areas
    /// monitored in manual mode, selection outside the permitted range is an error (50961 /
    /// 50962); 1 not monitored in manual mode; 2 monitored, selection outside allowed.
    pub workspace_manual_mode: u16,
    /// Cycles the drives may take to reach *operation enabled*.
    pub enable_timeout_cycles: u32,
    /// Cycles an exact stop may wait for the axes to come inside their in-position windows
    /// (machine key `in_position_timeout_ms`); then error 900016.
    pub in_position_timeout_cycles: u32,
    /// Consecutive lost exchanges the channel rides through before error 900012 (machine key
    /// `max_lost_cycles`, see [`Channel::link_lost`]).
    pub max_lost_cycles: u32,
    /// Channel measurement settings (FCT-C4 §8.2.1).
    pub meas: ChannelMeasConfig,
}

/// Kind of a motion block.
#[derive(Debug, Clone, PartialEq)]
pub enum MotionKind {
    /// G00: rapid, each axis at most P-AXIS-00212, acceleration P-AXIS-00004.
    Rapid,
    /// G01 at the programmed feed.
    Linear,
    /// G02 (`clockwise`) / G03 in the plane of axes `a1`, `a2` (channel indices, in the plane's
    /// orientation) with the centre offset from the start point.
    Arc {
        /// First plane axis.
        a1: usize,
        /// Second plane axis.
        a2: usize,
        /// Centre relative to the start point, in (a1, a2).
        centre_offset: [f64; 2],
        /// G02.
        clockwise: bool,
    },
    /// A path already built by the executor (an arc in a plane tilted by a rotating `#CS`); it
    /// must start at the current command position.
    Path(Segment),
}

/// A motion block after the executor resolved it to axis coordinates (ACS).
#[derive(Debug, Clone, PartialEq)]
pub struct MotionRequest {
    /// Rapid, linear or arc.
    pub kind: MotionKind,
    /// Target position of every channel axis (ACS, mm / °).
    pub target: Vec<f64>,
    /// Feed in mm/min (ignored for G00).
    pub feed: f64,
    /// A measuring block (G100 / G210 / G310).
    pub measure: Option<measure::MeasureRequest>,
}

/// Outcome of block preparation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prepared {
    /// The block runs; step the channel until it is idle.
    Started,
    /// Nothing to move (target = current position).
    Empty,
    /// The block was refused (an error was queued); it is not executed.
    Rejected,
}

/// Operating mode of the channel (automatic program or manual block / MDI).
///
/// FCT-A2 §3.1 / §3.2: the programmed SLS (`V.A.-SWE`, `V.A.+SWE`) are pre-assigned from
/// P-AXIS-00177 / 00178 "at a reset, mode change or axis change". Selecting *jog* (manual mode,
/// [`Channel::enter_manual`]) is not such a change: §3.3 lets G98 / G99 programmed before manual
/// mode extend the manual range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OperationMode {
    /// Automatic: NC programs.
    #[default]
    Automatic,
    /// Manual block (MDI): single blocks typed in.
    ManualBlock,
}

/// CNC object index group of the GEO task axis data (FCT-A2 §4.5).
pub const CNC_OBJECT_GROUP_GEO_AXIS: u32 = 0x0012_1301;
/// Index offset of "Positive PCS limit" (FCT-A2 §4.5).
pub const CNC_OBJECT_POSITIVE_PCS_LIMIT: u32 = 0x10096;
/// Index offset of "Negative PCS limit".
pub const CNC_OBJECT_NEGATIVE_PCS_LIMIT: u32 = 0x10097;
/// Index offset of "Distance to positive PCS limit".
pub const CNC_OBJECT_DISTANCE_POSITIVE_PCS_LIMIT: u32 = 0x10098;
/// Index offset of "Distance to negative PCS limit".
pub const CNC_OBJECT_DISTANCE_NEGATIVE_PCS_LIMIT: u32 = 0x10099;

/// Coarse state of the channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelState {
    /// Drives are being brought to *operation enabled*.
    Enabling,
    /// Ready for the next block.
    Idle,
    /// A block (or a jog) is running.
    Busy,
    /// Stopping after an error; becomes `Aborted` at standstill.
    Stopping,
    /// Stopped after an error; needs [`Channel::reset`].
    Aborted,
}

#[derive(Debug, Clone)]
struct Motion {
    segment: Segment,
    profile: Trapezoid,
    k: u64,
    /// Braking along the path after a measurement event: (braking, cycle it began).
    braking: Option<(Braking, u64)>,
    /// The measurement of a measuring block.
    meas: Option<Box<measure::MeasRun>>,
    /// The axes this motion moves (the only ones it writes set-points for).
    moved: Vec<bool>,
    /// Feed of the block, mm/min (a follow-up move after a fixed stop uses it).
    feed: f64,
    /// Cycles waited at the end of the path for the axes to come in position.
    settle: u32,
    /// The move back to the latched positions after a fixed-stop run: still part of the
    /// measuring block, so the CNC's lag monitoring stays off for its axes.
    fixed_stop_return: bool,
}

impl Motion {
    fn new(
        segment: Segment,
        profile: Trapezoid,
        meas: Option<Box<measure::MeasRun>>,
        feed: f64,
    ) -> Self {
        let moved = (0..segment.dims())
            .map(|i| {
                let (lo, hi) = segment.extent(i);
                hi - lo > 1e-12
            })
            .collect();
        Motion {
            segment,
            profile,
            k: 0,
            braking: None,
            meas,
            moved,
            feed,
            settle: 0,
            fixed_stop_return: false,
        }
    }
}

#[derive(Debug, Clone)]
enum Mode {
    Enabling {
        cycles: u32,
    },
    Idle,
    Moving(Box<Motion>),
    Manual(manual::ManualState),
    Stopping {
        brakes: Vec<AxisBrake>,
        k: u64,
        then: ChannelState,
        /// Cycles waited after braking for the axes to come to rest.
        settle: u32,
    },
    /// Waiting for an acyclic answer (`#DRIVE … WAIT`, `#IDENT … SYN`).
    WaitAcyclic {
        id: u64,
    },
    Aborted,
}

#[derive(Debug, Clone, Copy)]
struct AxisBrake {
    start: f64,
    sign: f64,
    braking: Braking,
}

/// The CNC channel.
#[derive(Debug)]
pub struct Channel {
    /// Consecutive cycles whose exchange was lost (see [`Channel::link_lost`]).
    lost_streak: u32,
    /// Lost exchanges in all.
    lost_total: u64,
    cfg: ChannelConfig,
    axes: Vec<Axis>,
    sls: SoftLimits,
    mode: Mode,
    messages: Vec<CncMessage>,
    block: Option<BlockRef>,
    /// The executor's frames (zero shifts, MEIN, tool length, `#CS`), for the PCS limit display
    /// (P-CHAN-00489).
    frames: Frames,
    /// Command velocities of the last cycle (mm/s).
    velocity: Vec<f64>,
    /// Scratch buffers (no per-cycle allocation).
    next: Vec<f64>,
    violations: Vec<Violation>,
    cycles: u64,
    operation_mode: OperationMode,
    /// Outcome of the last measuring block, until the executor takes it.
    measurement: Option<MeasurementOutcome>,
    /// Acyclic requests (`#DRIVE`, `#IDENT`).
    acyclic: acyclic::AcyclicState,
    /// Axis couplings (gantry).
    couplings: coupling::Couplings,
    /// Independent-axis motions, per axis.
    indp: Vec<Option<independent::IndependentSlot>>,
    /// Scratch point for independent-axis interpolation.
    scratch: Vec<f64>,
    /// Axes whose switchable probe was prepared (`#MEAS PREPARE`).
    prepared: Vec<bool>,
    /// PLC interface per axis (FCT-C4 §8.2.3 control units, §7.2 / §7.4 handshake).
    plc: Vec<crate::core::measure::plc::AxisPlc>,
    /// What the PLC interface showed in the last cycles, newest first (see
    /// [`Channel::plc_view`]).
    plc_seen: Vec<std::collections::VecDeque<(Nanos, crate::core::measure::plc::AxisPlc)>>,
    /// Per axis: the PLC interface is fed from bus inputs latched with the actual values
    /// ([`Channel::set_plc_inputs_from_bus`]).
    plc_from_bus: Vec<bool>,
    /// DC system time of the samples read this cycle ([`Channel::set_sample_dc_time`]).
    sample_dc: Option<i64>,
    /// External-latch handshake clients per axis.
    ext_latch: Vec<Option<crate::core::measure::plc::ExtLatchClient>>,
    /// Time of the current cycle.
    now: Nanos,
    /// Latches recorded for a trace (`None`: not recording).
    latch_log: Option<Vec<(Nanos, usize, f64)>>,
    /// Workspace and protection areas (FCT-C14).
    areas: areas::ChannelAreas,
    /// Drive emergencies of this run by (axis, code): count and the code in words; at most
    /// [`MAX_EMERGENCY_KINDS`] kinds, the rest counted in `emergencies_other`.
    emergencies: std::collections::BTreeMap<(usize, u16), (u64, String)>,
    emergencies_other: u64,
}

/// Distinct (axis, code) pairs of drive emergencies a channel keeps apart; beyond, they are
/// only counted (a hostile device cannot grow the table).
pub const MAX_EMERGENCY_KINDS: usize = 256;

impl Channel {
    /// A channel over the given axes (same order as `cfg.axes`).
    ///
    /// # Errors
    /// When the number of axes and configurations differ.
    pub fn new(cfg: ChannelConfig, axes: Vec<Axis>) -> Result<Self, String> {
        if cfg.axes.len() != axes.len() {
            return Err(format!(
                "channel has {} axis configurations but {} axes",
                cfg.axes.len(),
                axes.len()
            ));
        }
        let mut sls = SoftLimits::new(
            cfg.axes.iter().map(|a| a.limits.clone()).collect(),
            cfg.range_check_programmed_limits,
        );
        for (i, a) in axes.iter().enumerate() {
            sls.set_referenced(i, a.is_referenced());
        }
        let n = axes.len();
        let names: Vec<String> = axes.iter().map(|a| a.name().to_string()).collect();
        let frames = initial_frames(&names);
        Ok(Channel {
            frames,
            areas: areas::ChannelAreas::new(names),
            emergencies: std::collections::BTreeMap::new(),
            emergencies_other: 0,
            cfg,
            axes,
            sls,
            mode: Mode::Enabling { cycles: 0 },
            messages: Vec::new(),
            block: None,
            velocity: vec![0.0; n],
            next: vec![0.0; n],
            violations: Vec::new(),
            cycles: 0,
            lost_streak: 0,
            lost_total: 0,
            operation_mode: OperationMode::Automatic,
            measurement: None,
            acyclic: Default::default(),
            couplings: Default::default(),
            indp: vec![None; n],
            scratch: vec![0.0; n],
            prepared: vec![false; n],
            plc: vec![Default::default(); n],
            plc_seen: vec![Default::default(); n],
            plc_from_bus: vec![false; n],
            sample_dc: None,
            ext_latch: vec![None; n],
            now: Nanos::ZERO,
            latch_log: None,
        })
    }

    /// Number of axes.
    pub fn axis_count(&self) -> usize {
        self.axes.len()
    }

    /// The axes.
    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// Index of the axis with this name.
    pub fn axis_index(&self, name: &str) -> Option<usize> {
        self.axes
            .iter()
            .position(|a| a.name().eq_ignore_ascii_case(name))
    }

    /// The software limit switch monitor.
    pub fn soft_limits(&self) -> &SoftLimits {
        &self.sls
    }

    /// Configuration.
    pub fn config(&self) -> &ChannelConfig {
        &self.cfg
    }

    /// Interpolation cycles run so far.
    pub fn cycles(&self) -> u64 {
        self.cycles
    }

    /// Coarse state.
    pub fn state(&self) -> ChannelState {
        match &self.mode {
            Mode::Enabling { .. } => ChannelState::Enabling,
            Mode::Idle if self.independent_busy() => ChannelState::Busy,
            Mode::Idle => ChannelState::Idle,
            Mode::Moving(_) => ChannelState::Busy,
            Mode::Manual(m) if m.is_moving() => ChannelState::Busy,
            Mode::Manual(_) => ChannelState::Idle,
            Mode::Stopping { .. } => ChannelState::Stopping,
            Mode::WaitAcyclic { .. } => ChannelState::Busy,
            Mode::Aborted => ChannelState::Aborted,
        }
    }

    /// Ready for the next block (enabled, nothing moving, no error).
    pub fn is_idle(&self) -> bool {
        self.state() == ChannelState::Idle
    }

    /// Take the queued messages.
    pub fn take_messages(&mut self) -> Vec<CncMessage> {
        std::mem::take(&mut self.messages)
    }

    /// Queued messages, not taken.
    pub fn messages(&self) -> &[CncMessage] {
        &self.messages
    }

    /// Set the block that subsequent messages refer to.
    pub fn set_block(&mut self, block: Option<BlockRef>) {
        self.block = block;
    }

    /// The block being executed (the one messages refer to), if any.
    pub fn block(&self) -> Option<BlockRef> {
        self.block
    }

    /// Command position of every axis (ACS).
    pub fn command_positions(&self) -> Vec<f64> {
        self.axes.iter().map(Axis::command).collect()
    }

    /// Actual position of every axis (ACS).
    pub fn actual_positions(&self) -> Vec<f64> {
        self.axes.iter().map(Axis::actual).collect()
    }

    /// Tell the channel the executor's frames (G92, zero offset, MEIN, tool length, `#CS`) for
    /// the PCS limit display (P-CHAN-00489). Frames for another number of axes are ignored.
    pub fn set_frames(&mut self, frames: &Frames) {
        if frames.axes() == self.axes.len() {
            self.frames.clone_from(frames);
        }
    }

    /// The frames last set by [`Channel::set_frames`] (all offsets 0, no `#CS` after program
    /// start).
    pub fn frames(&self) -> &Frames {
        &self.frames
    }

    /// PCS → `w` offset of axis `i` (zero shifts + MEIN + tool length; without `#CS`,
    /// `acs = pcs + offset`).
    pub fn pcs_offset(&self, i: usize) -> f64 {
        self.frames.pcs_offset(i)
    }

    /// The four PCS CNC objects of FCT-A2 §4.5 for axis `i`; `None` unless P-CHAN-00489 is
    /// set and an active software limit switch bounds the axis's PCS motion.
    ///
    /// FCT-A2 §2.1 transforms the active ACS limits into the PCS "considering all offsets …
    /// and Cartesian transformations (#CS)". With a rotating `#CS` a PCS axis may run along
    /// another ACS axis, or obliquely across several. The rule (interpretation S15): from the
    /// current PCS command position, move along PCS axis `i` alone; its PCS limits are where
    /// that line first reaches an active ACS limit of any axis, in either direction; the
    /// distances are the lengths of the two pieces. Without rotation this is the active limit of
    /// axis `i` minus its offsets; with a 90° rotation it is the limit of the ACS axis that PCS
    /// axis `i` runs along.
    pub fn pcs_limits(&self, i: usize) -> Option<PcsLimits> {
        let n = self.axes.len();
        if !self.cfg.display_pcs_limits || i >= n || n > MAX_AXES {
            return None;
        }
        let mut acs = [0.0; MAX_AXES];
        for (p, a) in acs.iter_mut().zip(&self.axes) {
            *p = a.command();
        }
        // Empty frames (a channel they cannot describe) convert nothing: PCS = ACS.
        let mut pcs = acs;
        self.frames.acs_to_pcs(&acs[..n], &mut pcs[..n]);
        let mut unit = [0.0; MAX_AXES];
        unit[i] = 1.0;
        let mut dir = unit;
        self.frames.dir_to_acs(&unit[..n], &mut dir[..n]);
        let (s_min, s_max) = self.sls.range_along(&acs[..n], &dir[..n])?;
        Some(PcsLimits {
            positive: pcs[i] + s_max,
            negative: pcs[i] + s_min,
            distance_positive: s_max,
            distance_negative: -s_min,
        })
    }

    /// Read one of the four PCS-limit CNC objects of FCT-A2 §4.5 (`REAL64`, unit 0.1 µm or
    /// 0.0001°) for axis `i`: index group [`CNC_OBJECT_GROUP_GEO_AXIS`], index offsets
    /// 0x10096 … 0x10099. `None` when the object does not exist or P-CHAN-00489 is not set.
    pub fn read_cnc_object(&self, i: usize, index_group: u32, index_offset: u32) -> Option<f64> {
        if index_group != CNC_OBJECT_GROUP_GEO_AXIS {
            return None;
        }
        let p = self.pcs_limits(i)?;
        let mm = match index_offset {
            CNC_OBJECT_POSITIVE_PCS_LIMIT => p.positive,
            CNC_OBJECT_NEGATIVE_PCS_LIMIT => p.negative,
            CNC_OBJECT_DISTANCE_POSITIVE_PCS_LIMIT => p.distance_positive,
            CNC_OBJECT_DISTANCE_NEGATIVE_PCS_LIMIT => p.distance_negative,
            _ => return None,
        };
        Some(mm * crate::units::PARAM_POS_PER_UNIT)
    }

    /// Current operating mode.
    pub fn operation_mode(&self) -> OperationMode {
        self.operation_mode
    }

    /// Change the operating mode (only when idle). A real change restores the configured SLS
    /// (FCT-A2 §3.1 / §3.2 "mode change"). Returns false when the channel is busy or in jog.
    pub fn select_operation_mode(&mut self, mode: OperationMode) -> bool {
        if !matches!(self.mode, Mode::Idle | Mode::Aborted) {
            return false;
        }
        if mode != self.operation_mode {
            self.operation_mode = mode;
            self.sls.reset();
        }
        true
    }

    /// Controller reset: restores the configured SLS (FCT-A2 §3.3), clears the error state,
    /// re-enables the drives (with fault reset) and deactivates every workspace / protection
    /// area (kept for reactivation, FCT-C14 §3 notice "Controller reset").
    pub fn reset(&mut self) {
        self.reset_areas();
        self.program_start();
    }

    /// Program start: like a controller reset ([`Channel::reset`]) except that workspace and
    /// protection areas stay active (FCT-C14 §3 notice "Program end": they "continue to be
    /// monitored at the next program start").
    pub fn program_start(&mut self) {
        self.sls.reset();
        let names: Vec<String> = self.axes.iter().map(|a| a.name().to_string()).collect();
        self.frames = initial_frames(&names);
        self.velocity.iter_mut().for_each(|v| *v = 0.0);
        self.mode = Mode::Enabling { cycles: 0 };
        for a in &mut self.axes {
            a.set_fault_reset(true);
        }
        // CNC reset: a pending PLC task is withdrawn and preparations cleared (FCT-C4 §7.2: "If
        // a reset is executed between preparation and the actual measuring block, the probe is
        // enabled as normal at the start of the measuring block").
        for (c, p) in self.ext_latch.iter_mut().zip(self.plc.iter_mut()) {
            if let Some(c) = c {
                c.cnc_reset(&mut p.ext_latch);
            }
            p.measuring_r = false;
        }
        self.prepared.iter_mut().for_each(|p| *p = false);
        self.measurement = None;
    }

    /// The dead time of axis `i` in cycles (from its link or machine file; see
    /// [`Axis::lag`]).
    pub fn set_dead_time_cycles(&mut self, i: usize, cycles: u32) {
        if let Some(a) = self.axes.get_mut(i) {
            a.set_dead_time_cycles(cycles);
        }
    }

    /// Mark axis `i` referenced or not.
    pub fn set_referenced(&mut self, i: usize, referenced: bool) {
        if let Some(a) = self.axes.get_mut(i) {
            a.set_referenced(referenced);
            self.sls.set_referenced(i, referenced);
        }
    }

    /// Queue a message from outside the channel (e.g. the executor), tagged with the current
    /// block. An error aborts the channel.
    pub fn report(&mut self, m: CncMessage) {
        let error = m.is_error();
        self.push(m);
        if error && !matches!(self.mode, Mode::Stopping { .. } | Mode::Aborted) {
            self.begin_stop(ChannelState::Aborted);
        }
    }

    /// Abort the program for an error that is already queued (one cause, one error): the
    /// channel stops as after [`Channel::report`] of that error, without a message of its own.
    pub fn abort_reported(&mut self) {
        if !matches!(self.mode, Mode::Stopping { .. } | Mode::Aborted) {
            self.begin_stop(ChannelState::Aborted);
        }
    }

    /// A drive's emergency message (EMCY / CoE emergency): warning 900015 naming the axis and
    /// the code in words, once per axis and code in a run; repetitions are counted and
    /// summed up by [`emergency_summary`](Self::emergency_summary) (a device flooding EMCYs
    /// gives one line, not one per message, and costs the cycle no more than a count). Code
    /// 0x0000 ("error reset or no error") is not reported.
    pub fn drive_emergency(&mut self, axis: usize, code: u16, text: &str) {
        if code == 0 {
            return;
        }
        let kinds = self.emergencies.len();
        match self.emergencies.get_mut(&(axis, code)) {
            Some(e) => {
                e.0 = e.0.saturating_add(1);
                return;
            }
            None if kinds >= MAX_EMERGENCY_KINDS => {
                self.emergencies_other = self.emergencies_other.saturating_add(1);
                return;
            }
            None => {
                self.emergencies.insert((axis, code), (1, text.to_string()));
            }
        }
        let name = self.axes.get(axis).map_or("?", |a| a.name()).to_string();
        self.push(
            CncMessage::warning(
                crate::messages::ids::DRIVE_EMERGENCY,
                format!("axis {name}: drive emergency {code:#06x} ({text})"),
            )
            .on_axis(&name),
        );
    }

    /// Warnings 900018 for the emergencies that came more than once since the last summary
    /// (axis, code, how many in all), then the count starts again.
    pub fn emergency_summary(&mut self) {
        let counts = std::mem::take(&mut self.emergencies);
        for ((axis, code), (n, text)) in counts {
            if n < 2 {
                continue;
            }
            let name = self.axes.get(axis).map_or("?", |a| a.name()).to_string();
            self.push(
                CncMessage::warning(
                    crate::messages::ids::DRIVE_EMERGENCY_SUMMARY,
                    format!(
                        "axis {name}: drive emergency {code:#06x} ({text}) came {n} times in this run; only the first was reported"
                    ),
                )
                .on_axis(&name),
            );
        }
        let other = std::mem::take(&mut self.emergencies_other);
        if other > 0 {
            self.push(CncMessage::warning(
                crate::messages::ids::DRIVE_EMERGENCY_SUMMARY,
                format!(
                    "{other} more drive emergencies of further codes in this run (beyond {MAX_EMERGENCY_KINDS} kinds, not reported one by one)"
                ),
            ));
        }
    }

    pub(super) fn push(&mut self, m: CncMessage) {
        let m = m.at(self.block);
        tracing::debug!(id = m.id, "{m}");
        self.messages.push(m);
    }
}

/// Permitted difference between start and end radius of a G02 / G03 (mm).
pub const ARC_RADIUS_TOLERANCE: f64 = 1e-3;

/// The frames of a program start: no offsets, no `#CS`, main axes X, Y, Z by name (as the
/// executor builds them). A channel the frames cannot describe gets empty frames, which leave
/// the PCS limit display without offsets.
fn initial_frames(names: &[String]) -> Frames {
    let main = ["X", "Y", "Z"].map(|m| names.iter().position(|n| n.eq_ignore_ascii_case(m)));
    Frames::new(names.len(), main).unwrap_or_else(|_| Frames::empty())
}
