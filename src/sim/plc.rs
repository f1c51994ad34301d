//! A scripted, deterministic PLC for the simulator: the machine builder's PLC glue of FCT-C4
//! §7 played on virtual time.
//!
//! One [`ScriptedPlc`] serves one axis' PLC interface ([`AxisPlc`]). It runs its own cycle
//! (`period`, `phase`: cycles at `phase + n·period`) and is stepped once per NC cycle with the
//! probe's exact edges and levels ([`ProbeInputs`]); every PLC cycle that falls into the step is
//! executed in order:
//!
//! 1. the external-latch handshake (§7.2 / §7.4): a new task is taken (`please_rw = FALSE`) and
//!    acknowledged (`done_w = TRUE`) at the first PLC cycle at least the scripted delay later
//!    ([`AckScript`]; `None` = never, for timeout tests);
//! 2. the edges that happened up to the cycle time: the `timestamp` unit is an EL1252 terminal
//!    model ([`El1252Device`], continuous mode) whose process image the PLC decodes with the
//!    master-side [`el1252::Decoder`] each cycle, taking the DC time of the last edge of the
//!    configured kind (+ terminal delay, [`TimestampOutput`]); in
//!    [`SimPlcMode::FirstEventLatch`] the first qualifying edge sets the PLC's latch; in
//!    [`SimPlcMode::ExtLatchControl`] the first qualifying edge after ENABLE makes the PLC write
//!    `probing_position` (the true crossing position) and then raise `probing_signal`;
//! 3. `probing_signal` (sampled level, latch or ext-latch event flag).
//!
//! Step the PLC before the CNC evaluates the units in the same NC cycle: a PLC cycle at exactly
//! the NC cycle time is then visible to the CNC in that cycle (a synchronous PLC). Nothing here
//! allocates per cycle (edges wait in a queue allocated once; beyond [`EDGE_QUEUE`] entries the
//! oldest are dropped and counted; the terminal image is decoded only in PLC cycles where it
//! changed, i.e. after an edge).

use crate::core::measure::plc::{AxisPlc, ExtLatchJob, ExtLatchTask};
use crate::core::measure::timestamp::DcClock;
use crate::drive::el1252::{self, LatchMode, CHANNEL_LEN};
use crate::drive::model::el1252::El1252Device;
use crate::drive::ProbeEdge;
use crate::units::Nanos;

/// Capacity of the edge queue between NC steps and PLC cycles.
pub const EDGE_QUEUE: usize = 64;
/// Smallest PLC period accepted (smaller values are raised to it).
pub const MIN_PERIOD: Nanos = Nanos(1_000);
/// A step that is more PLC cycles behind than this skips the older cycles.
const MAX_CATCH_UP: u64 = 10_000;

/// One physical edge of a probe input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct InputEdge {
    /// Probe (input) index in the plant.
    pub probe: usize,
    /// Rising (TRUE) or falling.
    pub rising: bool,
    /// Exact time of the edge.
    pub at: Nanos,
}

/// What the PLC needs from the plant (or a test): the edges of the last NC step, levels at any
/// time, and — for external measuring hardware — the true position at an edge.
pub trait ProbeInputs {
    /// Call `f` for each edge that happened in the last NC step, in time order.
    fn for_each_edge(&self, f: &mut dyn FnMut(InputEdge));
    /// Level of probe `probe` at time `at`.
    fn level(&self, probe: usize, at: Nanos) -> bool;
    /// The true axis position at an edge (for `PLC_EXT_LATCH_CONTROL`); `None` if unknown (the
    /// PLC then leaves `probing_position` disabled and the CNC uses its actual value).
    fn crossing_position(&self, _edge: &InputEdge) -> Option<f64> {
        None
    }
}

/// What the PLC writes to `probing_signal`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimPlcMode {
    /// The input level sampled at each PLC cycle (`PLC`, `PLC_TIMESTAMP`).
    Signal,
    /// A PLC-side latch of the first `edge` since [`ScriptedPlc::clear_latch`] or DISABLE,
    /// held TRUE (`PLC_FIRST_EVENT`, see [`crate::core::measure::plc`]).
    FirstEventLatch {
        /// The probe's physical edge.
        edge: ProbeEdge,
    },
    /// External measuring hardware (`PLC_EXT_LATCH_CONTROL`, FCT-C4 §7.4): after ENABLE is
    /// acknowledged, the first edge of the task's edge writes `probing_position` and raises
    /// `probing_signal`, held until DISABLE.
    ExtLatchControl,
}

/// EL1252-style timestamp output (FCT-C4 §7.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TimestampOutput {
    /// Virtual time ↔ DC time (ns since 2000-01-01).
    pub clock: DcClock,
    /// Added to the true edge time (terminal latency, EL1252 < 1 µs).
    pub terminal_delay_ns: i64,
    /// Which edges are timestamped (EL1252 `LatchPosR` = rising).
    pub edge: ProbeEdge,
}

/// Acknowledge delays per task (`None`: never acknowledge).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct AckScript {
    /// HLI_EXT_LATCH_PREPARE_PROBE.
    pub prepare: Option<Nanos>,
    /// HLI_EXT_LATCH_ENABLE_PROBE.
    pub enable: Option<Nanos>,
    /// HLI_EXT_LATCH_DISABLE_PROBE.
    pub disable: Option<Nanos>,
}

impl AckScript {
    /// Acknowledge every task after `delay`.
    pub fn all(delay: Nanos) -> Self {
        AckScript {
            prepare: Some(delay),
            enable: Some(delay),
            disable: Some(delay),
        }
    }

    /// Never acknowledge anything.
    pub fn never() -> Self {
        AckScript {
            prepare: None,
            enable: None,
            disable: None,
        }
    }

    fn delay(&self, task: ExtLatchTask) -> Option<Nanos> {
        match task {
            ExtLatchTask::Prepare => self.prepare,
            ExtLatchTask::Enable => self.enable,
            ExtLatchTask::Disable => self.disable,
        }
    }
}

impl Default for AckScript {
    /// Every task acknowledged after 0 ns, i.e. in the PLC cycle that reads it.
    fn default() -> Self {
        AckScript::all(Nanos::ZERO)
    }
}

/// Configuration of a [`ScriptedPlc`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SimPlcConfig {
    /// PLC cycle (raised to [`MIN_PERIOD`]).
    pub period: Nanos,
    /// Time of the first PLC cycle.
    pub phase: Nanos,
    /// The plant's probe index that feeds this axis.
    pub probe: usize,
    /// What `probing_signal` carries.
    pub mode: SimPlcMode,
    /// Timestamp unit output, if any.
    pub timestamp: Option<TimestampOutput>,
    /// Handshake answers.
    pub ack: AckScript,
    /// Enable `probing_signal` (`enable_w`); FALSE leaves the CNC's own value (FALSE).
    pub enable_signal: bool,
}

impl SimPlcConfig {
    /// A PLC with `period`, phase 0, probe 0, sampled signal, no timestamps, immediate acks.
    pub fn new(period: Nanos) -> Self {
        SimPlcConfig {
            period,
            phase: Nanos::ZERO,
            probe: 0,
            mode: SimPlcMode::Signal,
            timestamp: None,
            ack: AckScript::default(),
            enable_signal: true,
        }
    }
}

/// The simulated probe hardware as the PLC switched it through the handshake.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SimProbeState {
    /// Off.
    #[default]
    Off,
    /// PREPARE done (probe powered).
    Prepared,
    /// ENABLE done (probe armed).
    Enabled,
}

/// A deterministic PLC on virtual time (see the module documentation).
#[derive(Debug, Clone)]
pub struct ScriptedPlc {
    config: SimPlcConfig,
    next_cycle: Nanos,
    queue: Vec<InputEdge>,
    dropped: u64,
    cycles: u64,
    task: Option<(ExtLatchJob, Option<Nanos>)>,
    hw: SimProbeState,
    enabled_at: Nanos,
    latched: bool,
    /// Last seen `measuring_r`.
    saw_measuring: bool,
    ext_event: bool,
    last_timestamp: Option<i64>,
    /// The timestamp terminal (one channel) and the PLC's decoder of its image.
    terminal: Option<Terminal>,
    acks: u64,
    /// Edge of the last task read (P-AXIS-00518 as the CNC sent it).
    task_edge: ProbeEdge,
}

impl ScriptedPlc {
    /// A PLC whose first cycle is at `config.phase`.
    pub fn new(mut config: SimPlcConfig) -> Self {
        if config.period < MIN_PERIOD {
            config.period = MIN_PERIOD;
        }
        ScriptedPlc {
            next_cycle: config.phase,
            config,
            queue: Vec::with_capacity(EDGE_QUEUE),
            dropped: 0,
            cycles: 0,
            task: None,
            hw: SimProbeState::Off,
            enabled_at: Nanos::ZERO,
            latched: false,
            saw_measuring: false,
            ext_event: false,
            last_timestamp: None,
            terminal: config.timestamp.map(|ts| Terminal::new(ts.clock)),
            acks: 0,
            task_edge: ProbeEdge::Positive,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SimPlcConfig {
        &self.config
    }

    /// Change the configuration (e.g. the acknowledge script) between steps; the cycle grid
    /// stays.
    pub fn config_mut(&mut self) -> &mut SimPlcConfig {
        &mut self.config
    }

    /// PLC cycles executed so far.
    pub fn cycles(&self) -> u64 {
        self.cycles
    }

    /// Tasks acknowledged so far.
    pub fn acknowledged(&self) -> u64 {
        self.acks
    }

    /// Edges dropped because the queue was full.
    pub fn dropped_edges(&self) -> u64 {
        self.dropped
    }

    /// The simulated probe hardware state.
    pub fn hardware(&self) -> SimProbeState {
        self.hw
    }

    /// The task being worked on, if any.
    pub fn current_task(&self) -> Option<ExtLatchJob> {
        self.task.map(|(job, _)| job)
    }

    /// The DC time of the last timestamped edge (before terminal delay), if any.
    pub fn last_timestamp(&self) -> Option<i64> {
        self.last_timestamp
    }

    /// Clear the first-event latch and the external-latch event (the PLC glue does this when a
    /// new measurement starts).
    pub fn clear_latch(&mut self) {
        self.latched = false;
        self.ext_event = false;
    }

    /// One NC step up to `now`: queue the step's edges, run every PLC cycle ≤ `now`. A rising
    /// `measuring_r` (the CNC armed a measurement) clears the first-event latch.
    pub fn step(&mut self, now: Nanos, inputs: &dyn ProbeInputs, plc: &mut AxisPlc) {
        if plc.measuring_r && !self.saw_measuring {
            self.latched = false;
        }
        self.saw_measuring = plc.measuring_r;
        let probe = self.config.probe;
        let queue = &mut self.queue;
        let dropped = &mut self.dropped;
        inputs.for_each_edge(&mut |e: InputEdge| {
            if e.probe != probe {
                return;
            }
            if queue.len() >= EDGE_QUEUE {
                queue.remove(0);
                *dropped += 1;
            }
            queue.push(e);
        });
        // `config_mut` may have lowered the period.
        let period = self.config.period.0.max(MIN_PERIOD.0);
        if now >= self.next_cycle {
            let behind = (now.0 - self.next_cycle.0) / period;
            if behind > MAX_CATCH_UP {
                let skip = behind - MAX_CATCH_UP;
                self.next_cycle = Nanos(
                    self.next_cycle
                        .0
                        .saturating_add(skip.saturating_mul(period)),
                );
            }
        }
        while self.next_cycle <= now {
            let t = self.next_cycle;
            self.run_cycle(t, inputs, plc);
            let next = t.saturating_add(Nanos(period));
            if next == t {
                break;
            }
            self.next_cycle = next;
        }
    }

    fn run_cycle(&mut self, t: Nanos, inputs: &dyn ProbeInputs, plc: &mut AxisPlc) {
        self.cycles += 1;
        self.handshake(t, plc);

        // Edges visible at this cycle, in order.
        let mut n = 0;
        while n < self.queue.len() && self.queue[n].at <= t {
            n += 1;
        }
        for i in 0..n {
            let e = self.queue[i];
            self.on_edge(&e, inputs, plc);
        }
        self.queue.drain(..n);

        if let (Some(ts), Some(term)) = (self.config.timestamp, self.terminal.as_mut()) {
            if let Some(dc) = term.read(ts.edge) {
                self.last_timestamp = Some(dc);
            }
        }
        if let Some(ts) = self.config.timestamp {
            let value = self
                .last_timestamp
                .map_or(0, |dc| dc.saturating_add(ts.terminal_delay_ns));
            plc.timestamp.plc_command(value);
        }

        let signal = match self.config.mode {
            SimPlcMode::Signal => inputs.level(self.config.probe, t),
            SimPlcMode::FirstEventLatch { .. } => self.latched,
            SimPlcMode::ExtLatchControl => self.ext_event,
        };
        if self.config.enable_signal {
            plc.probing_signal.plc_command(signal);
        } else {
            plc.probing_signal.command_w = signal;
            plc.probing_signal.plc_release();
        }
    }

    fn handshake(&mut self, t: Nanos, plc: &mut AxisPlc) {
        if let Some(job) = plc.ext_latch.plc_take_task() {
            let due = self.config.ack.delay(job.task).map(|d| t.saturating_add(d));
            self.task_edge = job.edge;
            self.task = Some((job, due));
        }
        let Some((job, Some(due))) = self.task else {
            return;
        };
        if t < due {
            return;
        }
        plc.ext_latch.plc_acknowledge();
        self.acks += 1;
        self.task = None;
        match job.task {
            ExtLatchTask::Prepare => {
                if self.hw == SimProbeState::Off {
                    self.hw = SimProbeState::Prepared;
                }
            }
            ExtLatchTask::Enable => {
                self.hw = SimProbeState::Enabled;
                self.enabled_at = t;
                self.ext_event = false;
            }
            ExtLatchTask::Disable => {
                self.hw = SimProbeState::Off;
                self.latched = false;
                self.ext_event = false;
                plc.probing_position.plc_release();
            }
        }
    }

    fn on_edge(&mut self, e: &InputEdge, inputs: &dyn ProbeInputs, plc: &mut AxisPlc) {
        if let Some(term) = self.terminal.as_mut() {
            term.device.edge(1, e.rising, e.at);
        }
        match self.config.mode {
            SimPlcMode::Signal => {}
            SimPlcMode::FirstEventLatch { edge } => {
                if matches_edge(edge, e.rising) {
                    self.latched = true;
                }
            }
            SimPlcMode::ExtLatchControl => {
                let edge = self.task_edge;
                if self.hw == SimProbeState::Enabled
                    && !self.ext_event
                    && e.at >= self.enabled_at
                    && matches_edge(edge, e.rising)
                {
                    match inputs.crossing_position(e) {
                        Some(pos) => plc.probing_position.plc_command(pos),
                        None => plc.probing_position.plc_release(),
                    }
                    self.ext_event = true;
                }
            }
        }
    }
}

fn matches_edge(edge: ProbeEdge, rising: bool) -> bool {
    match edge {
        ProbeEdge::Positive => rising,
        ProbeEdge::Negative => !rising,
    }
}

/// The plant feeds the PLC directly: its surfaces are the probes ([`InputEdge::probe`] = surface
/// index). The plant works in drive increments and does not know the axis position in mm, so
/// [`ProbeInputs::crossing_position`] is `None` (for `PLC_EXT_LATCH_CONTROL` the CNC then uses
/// its actual value; wrap the plant to supply positions).
impl ProbeInputs for super::plant::Plant {
    fn for_each_edge(&self, f: &mut dyn FnMut(InputEdge)) {
        for e in self.last_edges() {
            f(InputEdge {
                probe: e.probe,
                rising: e.rising,
                at: e.at,
            });
        }
    }

    fn level(&self, probe: usize, at: Nanos) -> bool {
        super::plant::Plant::level(self, probe, at)
    }
}

/// Scripted probe inputs for tests: initial levels and a list of exact edges; each
/// [`advance`](Self::advance) makes the edges of the next NC step visible.
pub struct ScriptedInputs {
    initial: Vec<bool>,
    edges: Vec<InputEdge>,
    /// Visible window (from, to]; `from = None` includes everything up to `to`.
    from: Option<Nanos>,
    to: Option<Nanos>,
    position: Option<Box<dyn Fn(Nanos) -> f64>>,
}

impl ScriptedInputs {
    /// Probes with the given initial levels (missing probes start FALSE) and edges (sorted by
    /// time here).
    pub fn new(initial: &[bool], mut edges: Vec<InputEdge>) -> Self {
        edges.sort_by_key(|e| e.at);
        ScriptedInputs {
            initial: initial.to_vec(),
            edges,
            from: None,
            to: None,
            position: None,
        }
    }

    /// The true axis position as a function of time (for [`ProbeInputs::crossing_position`]).
    pub fn with_position(mut self, f: impl Fn(Nanos) -> f64 + 'static) -> Self {
        self.position = Some(Box::new(f));
        self
    }

    /// Make the edges in (previous `now`, `now`] visible (the first call: all edges ≤ `now`).
    pub fn advance(&mut self, now: Nanos) {
        self.from = self.to;
        self.to = Some(now);
    }

    /// All scripted edges.
    pub fn edges(&self) -> &[InputEdge] {
        &self.edges
    }
}

impl ProbeInputs for ScriptedInputs {
    fn for_each_edge(&self, f: &mut dyn FnMut(InputEdge)) {
        let Some(to) = self.to else {
            return;
        };
        for e in &self.edges {
            let after_from = self.from.is_none_or(|from| e.at > from);
            if after_from && e.at <= to {
                f(*e);
            }
        }
    }

    fn level(&self, probe: usize, at: Nanos) -> bool {
        let mut level = self.initial.get(probe).copied().unwrap_or(false);
        for e in self.edges.iter().take_while(|e| e.at <= at) {
            if e.probe == probe {
                level = e.rising;
            }
        }
        level
    }

    fn crossing_position(&self, edge: &InputEdge) -> Option<f64> {
        self.position.as_ref().map(|f| f(edge.at))
    }
}

impl std::fmt::Debug for ScriptedInputs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScriptedInputs")
            .field("initial", &self.initial)
            .field("edges", &self.edges)
            .field("from", &self.from)
            .field("to", &self.to)
            .field("position", &self.position.is_some())
            .finish()
    }
}

/// The EL1252 of a PLC timestamp unit: the terminal model on the input side, the image the
/// PLC reads, and its decoder.
#[derive(Debug, Clone)]
struct Terminal {
    device: El1252Device,
    decoder: el1252::Decoder,
    image: [u8; CHANNEL_LEN],
    last_image: [u8; CHANNEL_LEN],
}

impl Terminal {
    fn new(clock: DcClock) -> Self {
        let mut t = Terminal {
            device: El1252Device::new(1, LatchMode::Continuous, clock),
            decoder: el1252::Decoder::new(1, LatchMode::Continuous),
            image: [0; CHANNEL_LEN],
            last_image: [0; CHANNEL_LEN],
        };
        // The first image is the decoder's reference: give it the idle terminal.
        if t.device.write_image(&mut t.image).is_ok() && t.decoder.decode(&t.image).is_ok() {
            t.last_image = t.image;
        }
        t
    }

    /// One PLC cycle: read the terminal's image; the DC time of the latest new edge of `edge`'s
    /// kind, if any.
    fn read(&mut self, edge: ProbeEdge) -> Option<i64> {
        self.device.write_image(&mut self.image).ok()?;
        if self.image == self.last_image {
            return None;
        }
        self.last_image = self.image;
        let (_, edges) = self.decoder.decode(&self.image).ok()?;
        edges
            .iter()
            .rev()
            .find(|e| matches_edge(edge, e.rising))
            .map(|e| e.dc_time)
    }
}
