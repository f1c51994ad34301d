//! A machine: one channel, its axes on their drives, and the link that carries the process
//! data — built from a [`MachineConfig`] and run cycle by cycle on virtual time.
//!
//! [`Machine::run_program`] is the main job of `fieldprobe run`: enable the drives, execute the
//! NC program block by block, stream `#MSG` lines and CNC messages to the caller, and stop
//! safely on errors.

use crate::axis::Axis;
use crate::channel::acyclic::AcyclicOp;
use crate::channel::{Channel, ChannelAxisConfig, ChannelConfig, ChannelState};
use crate::core::measure::source::ProbeSettings;
use crate::core::measure::timestamp::DcClock;
use crate::core::measure::{
    trigger_mode_from_text, AxisMeasConfig, ChannelMeasConfig, MeasType, SignalSource,
};
use crate::core::monitor::sls::{AxisLimitConfig, SlsBehaviour};
use crate::drive::catalogue;
use crate::drive::DriveError;
use crate::drive::ProbeEdge;
use crate::link::{Link, ProcessImage};
use crate::messages::{ids, BlockRef, CncMessage};
use crate::nc::ast::Program;
use crate::nc::exec::{Event, Executor, Step};
use crate::params::{AxisConfig, MachineConfig, ParamSet};
use crate::sim::plant::{FixedStop, ProbeSurface};
use crate::sim::plc::{
    InputEdge, ProbeInputs, ScriptedPlc, SimPlcConfig, SimPlcMode, TimestampOutput,
};
use crate::units::{param_pos_to_mm, param_vel_to_mm_s, Nanos};

/// Errors building a machine.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MachineError {
    /// A drive definition could not be loaded.
    #[error("axis {axis}: drive '{drive}': {cause}")]
    Drive {
        /// Axis name.
        axis: String,
        /// Drive name or file.
        drive: String,
        /// Cause (not a `source`: the text above already carries it).
        cause: DriveError,
    },
    /// The configuration is inconsistent.
    #[error("{0}")]
    Config(String),
}

/// How a program run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunStatus {
    /// The program ran to its end.
    Completed,
    /// A CNC error aborted it.
    Aborted,
}

/// What happened during a run, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum RunEvent {
    /// A `#MSG` line.
    Output(String),
    /// A warning or error.
    Message(CncMessage),
}

/// Where a run stands, after one interpolation cycle ([`Machine::run_program_with_progress`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunProgress {
    /// The block being executed (N number and source line).
    pub block: Option<BlockRef>,
    /// Interpolation cycles run since the program started.
    pub cycles: u64,
    /// Program time: the cycles times the interpolation cycle.
    pub time: Nanos,
}

/// Summary of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunReport {
    /// Completed or aborted.
    pub status: RunStatus,
    /// Every event in order.
    pub events: Vec<RunEvent>,
    /// Interpolation cycles run.
    pub cycles: u64,
    /// Measurement results per channel axis at the end of the run (`V.A.MESS` & co.).
    pub measurements: Vec<AxisMeasurement>,
}

/// The measurement variables of one axis at the end of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisMeasurement {
    /// `V.A.MESS` & co., `None` when the axis has no measured value.
    pub result: Option<crate::core::measure::results::AxisResult>,
    /// `V.A.MERF`.
    pub merf: bool,
    /// `V.A.MEIN`.
    pub mein: f64,
}

impl RunReport {
    /// The `#MSG` lines.
    pub fn output(&self) -> Vec<&str> {
        self.events
            .iter()
            .filter_map(|e| match e {
                RunEvent::Output(s) => Some(s.as_str()),
                RunEvent::Message(_) => None,
            })
            .collect()
    }

    /// The CNC messages.
    pub fn messages(&self) -> Vec<&CncMessage> {
        self.events
            .iter()
            .filter_map(|e| match e {
                RunEvent::Message(m) => Some(m),
                RunEvent::Output(_) => None,
            })
            .collect()
    }

    /// IDs of the CNC messages in order.
    pub fn message_ids(&self) -> Vec<u32> {
        self.messages().iter().map(|m| m.id).collect()
    }
}

/// Upper bound on the cycles of [`Machine::power_off`]'s disable (a CiA 402 drive takes 3 to 4:
/// the controlword goes out with the next exchange, takes effect at the SYNC, and the statusword
/// sampled there comes back one exchange later).
pub const POWER_OFF_CYCLES: u32 = 100;

/// Upper bound on the cycles of one run (virtual time; 1 h at 1 ms).
pub const DEFAULT_MAX_CYCLES: u64 = 3_600_000;

/// Which link carries the machine's process data.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct LinkChoice {
    /// `sim` (default), `ethercat-emu` or `ethercat:IFACE`.
    pub link: String,
    /// Capture every EtherCAT frame into this pcap file.
    pub pcap: Option<std::path::PathBuf>,
    /// Log every CAN frame into this file (candump -L format).
    pub candump: Option<std::path::PathBuf>,
    /// Write one CSV row per cycle of a paced link into this file (`--cycle-log`).
    pub cycle_log: Option<std::path::PathBuf>,
}

impl LinkChoice {
    /// The `--link` value `link`, no capture.
    pub fn new(link: &str) -> Self {
        LinkChoice {
            link: link.to_string(),
            pcap: None,
            candump: None,
            cycle_log: None,
        }
    }

    /// A CAN link (`canopen-emu`, `canopen-udp[:GROUP:PORT]`, `socketcan:IF`).
    pub fn is_can(&self) -> bool {
        let l = self.link.as_str();
        l.starts_with("canopen") || l.starts_with("socketcan:")
    }

    /// An EtherCAT link (`ethercat-emu`, `ethercat:IFACE`).
    pub fn is_ethercat(&self) -> bool {
        self.link == "ethercat-emu" || self.link.starts_with("ethercat:")
    }

    /// Refuse a capture the link cannot write, before anything is opened: `pcap` needs an
    /// EtherCAT link, `candump` a CAN link, `cycle_log` a link that leaves the process. The text names the option and the link (the CLI
    /// exits 2); an option is never silently ignored.
    pub fn check_options(&self) -> Result<(), String> {
        let link = &self.link;
        if let Some(p) = &self.pcap {
            if !self.is_ethercat() {
                return Err(format!(
                    "--pcap {}: --pcap needs an EtherCAT link (ethercat-emu or ethercat:IFACE); --link {link} is not one{}",
                    p.display(),
                    if self.is_can() { " (its CAN frames: --candump FILE.log)" } else { "" }
                ));
            }
        }
        if let Some(p) = &self.candump {
            if !self.is_can() {
                return Err(format!(
                    "--candump {}: --candump needs a CAN link (canopen-emu, canopen-udp[:GROUP:PORT] or socketcan:IF); --link {link} is not one{}",
                    p.display(),
                    if self.is_ethercat() { " (its EtherCAT frames: --pcap FILE.pcap)" } else { "" }
                ));
            }
        }
        if let Some(p) = &self.cycle_log {
            if !self.leaves_process() {
                return Err(format!(
                    "--cycle-log {}: only for links that leave the process (ethercat:IF, canopen-udp[:GROUP:PORT], socketcan:IF); --link {link} runs on virtual time",
                    p.display()
                ));
            }
        }
        Ok(())
    }

    /// The link leaves the process (`ethercat:IF`, `canopen-udp…`, `socketcan:IF`): it runs
    /// at the bus's real cycle on the wall clock; the others run on virtual time.
    pub fn leaves_process(&self) -> bool {
        let l = self.link.as_str();
        (l.starts_with("ethercat:") && l.len() > "ethercat:".len())
            || l.starts_with("canopen-udp")
            || l.starts_with("socketcan:")
    }
}

/// `--link` values fieldprobe knows, for messages ([`crate::link::LINKS`]).
pub const LINKS: &str = crate::link::LINKS;

/// A machine: channel, axes, and the link to their drives.
pub struct Machine {
    channel: Channel,
    link: Box<dyn Link>,
    images: Vec<ProcessImage>,
    now: Nanos,
    cycle: Nanos,
    /// Cycle budget of [`run_program`](Self::run_program).
    pub max_cycles: u64,
    tools: std::collections::BTreeMap<u32, crate::params::ToolData>,
    zero_offsets: std::collections::BTreeMap<u32, Vec<f64>>,
    /// Simulated PLC per axis (PLC-family signal sources), fed by the plant's probes.
    plcs: Vec<Option<ScriptedPlc>>,
    /// Warnings of the configuration, reported at the first run (e.g. 110757).
    startup: Vec<CncMessage>,
    /// Recorded trace (`--trace`), when enabled.
    trace: Option<Trace>,
    /// The machine's terminals by name, in `[[terminal]]` order (EtherCAT links).
    terminals: Vec<String>,
    /// Axes whose probe is wired to a timestamp input terminal (`[[terminal]] probe_axis`).
    terminal_probes: Vec<TerminalProbe>,
    /// A stop asked for from outside the run ([`Machine::set_stop_request`]).
    stop_request: Option<StopRequest>,
}

/// A stop asked for from outside a run (`fieldprobe run` on SIGINT / SIGTERM): another thread
/// [`request`](Self::request)s it with the cause; [`Machine::run_program`] sees it at its next
/// step and stops as on an error ([`ids::RUN_INTERRUPTED`] with the cause): the axes brake to
/// a stop, the program ends aborted, and the caller's [`Machine::power_off`] disables the
/// drives.
#[derive(Debug, Clone, Default)]
pub struct StopRequest(std::sync::Arc<std::sync::OnceLock<String>>);

impl StopRequest {
    /// A request not made yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Ask for the stop, `cause` in words (e.g. "SIGINT"); the first request counts.
    pub fn request(&self, cause: impl Into<String>) {
        let _ = self.0.set(cause.into());
    }

    /// The cause, once requested.
    pub fn cause(&self) -> Option<&str> {
        self.0.get().map(String::as_str)
    }
}

/// An axis's probe on an input of a timestamp input terminal (`[[terminal]] probe_axis`,
/// `probe_channel`; FCT-C4 §7.5): each cycle the terminal's process inputs are decoded
/// ([`crate::drive::el1252::Decoder`], continuous latching, the terminal's default) and the
/// channel's level and latest latched DC timestamp go to the axis's PLC interface
/// ([`crate::drive::el1252::feed_plc`]) — the PLC program of §7.5 linking "Input" and
/// "LatchPos2".
#[derive(Debug, Clone)]
struct TerminalProbe {
    /// Axis index.
    axis: usize,
    /// Terminal index (`[[terminal]]` order).
    terminal: usize,
    /// Input channel, 1-based.
    channel: u8,
    /// Decoder of the terminal's inputs (channels: what its image holds).
    decoder: crate::drive::el1252::Decoder,
}

impl std::fmt::Debug for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Machine")
            .field("channel", &self.channel)
            .field("now", &self.now)
            .field("cycle", &self.cycle)
            .field("exchanges", &self.link.exchanges())
            .finish_non_exhaustive()
    }
}

/// Most position samples a [`Trace`] holds: beyond, it keeps every second sample and records
/// every second cycle from then on, so a long run (a slow move of hours) costs at most this
/// many samples in memory and in the picture (a `--trace` SVG of a few MB), the whole run
/// still drawn. 10,000 is eight times the width of the picture in pixels.
pub const MAX_TRACE_SAMPLES: usize = 10_000;

/// Most probe edges and latched values a [`Trace`] holds; later ones are counted in
/// [`Trace::dropped_marks`] (the CLI says so) instead of growing the trace without bound.
pub const MAX_TRACE_MARKS: usize = 10_000;

/// A recorded run: positions per cycle (decimated beyond [`MAX_TRACE_SAMPLES`]), probe edges
/// and latched values (for `--trace`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    /// Axis names.
    pub axes: Vec<String>,
    /// Time of each sample in s.
    pub t: Vec<f64>,
    /// Command position per axis per sample (mm / °).
    pub command: Vec<Vec<f64>>,
    /// Actual position per axis per sample.
    pub actual: Vec<Vec<f64>>,
    /// Probe signal edges: (time s, rising).
    pub edges: Vec<(f64, bool)>,
    /// Latched values that became measurement results: (time s, axis, position). An axis that
    /// was not in a measurement, or whose latch belongs to an incomplete probing signal, has none.
    pub latches: Vec<(f64, usize, f64)>,
    /// One sample is kept every `stride` cycles (1 until the trace first reached
    /// [`MAX_TRACE_SAMPLES`], then doubled each time).
    pub stride: u64,
    /// Edges and latches beyond [`MAX_TRACE_MARKS`], not kept.
    pub dropped_marks: u64,
    /// Cycles offered since the start.
    cycles: u64,
    /// Most samples kept ([`MAX_TRACE_SAMPLES`] unless [`Machine::enable_trace_with_limit`]).
    limit: usize,
}

impl Trace {
    /// Offer the sample of one cycle; kept every [`stride`](Self::stride) cycles.
    fn push_sample(&mut self, t: f64, axes: &[crate::axis::Axis]) {
        let stride = self.stride.max(1);
        let keep = self.cycles.is_multiple_of(stride);
        self.cycles += 1;
        if !keep {
            return;
        }
        if self.t.len() >= self.limit.max(2) {
            // Keep samples 0, 2, 4, … (each a multiple of the doubled stride) and go on with it.
            let halve = |v: &mut Vec<f64>| {
                let mut k: usize = 0;
                v.retain(|_| {
                    k += 1;
                    !k.is_multiple_of(2)
                });
            };
            halve(&mut self.t);
            self.command.iter_mut().for_each(halve);
            self.actual.iter_mut().for_each(halve);
            self.stride = stride * 2;
            if !(self.cycles - 1).is_multiple_of(self.stride) {
                return;
            }
        }
        self.t.push(t);
        for (i, a) in axes.iter().enumerate() {
            if let Some(c) = self.command.get_mut(i) {
                c.push(a.command());
            }
            if let Some(c) = self.actual.get_mut(i) {
                c.push(a.actual());
            }
        }
    }

    fn push_edge(&mut self, at: f64, rising: bool) {
        if self.edges.len() < MAX_TRACE_MARKS {
            self.edges.push((at, rising));
        } else {
            self.dropped_marks += 1;
        }
    }

    fn push_latch(&mut self, at: f64, axis: usize, p: f64) {
        if self.latches.len() < MAX_TRACE_MARKS {
            self.latches.push((at, axis, p));
        } else {
            self.dropped_marks += 1;
        }
    }
}

impl Machine {
    /// Build the machine of `cfg` with drive models on the in-memory link.
    pub fn new(cfg: &MachineConfig) -> Result<Self, MachineError> {
        Machine::with_link(cfg, &LinkChoice::new("sim"))
    }

    /// Build the machine of `cfg` on the link `choice` (see [`LINKS`]).
    pub fn with_link(cfg: &MachineConfig, choice: &LinkChoice) -> Result<Self, MachineError> {
        if cfg.axes.is_empty() {
            return Err(MachineError::Config(format!(
                "{}: the machine has no axes",
                cfg.source
            )));
        }
        choice.check_options().map_err(MachineError::Config)?;
        if let Some(t) = cfg.terminals.first().filter(|_| !choice.is_ethercat()) {
            return Err(MachineError::Config(format!(
                "{}:{}: [[terminal]] {} is an EtherCAT SubDevice; --link {} has none (use ethercat-emu or ethercat:IFACE)",
                cfg.source, t.line, t.name, choice.link
            )));
        }
        let cycle = Nanos::from_micros(u64::from(cfg.cycle_time_us));
        let mut axes = Vec::new();
        let mut models = Vec::new();
        let mut defs = Vec::new();
        let mut images = Vec::new();
        let mut axis_cfgs = Vec::new();
        let mut param_warnings = Vec::new();
        for a in &cfg.axes {
            let def = catalogue::load(&a.drive).map_err(|source| MachineError::Drive {
                axis: a.name.clone(),
                drive: a.drive.clone(),
                cause: source,
            })?;
            // P-AXIS-00516 / 00517 / 00518 or the old parameters they replace (FCT-C4 §8.2.2).
            let probe = ProbeSettings::from_params(&a.params).map_err(|e| {
                MachineError::Config(format!("{}: axis {}: {e}", cfg.source, a.name))
            })?;
            param_warnings.extend(probe.warnings(&a.name));
            check_probing_input(a, &probe, &def)?;
            let drive_err = |source| MachineError::Drive {
                axis: a.name.clone(),
                drive: a.drive.clone(),
                cause: source,
            };
            let adapter = crate::drive::adapter_for(&def, &a.params).map_err(drive_err)?;
            let model = crate::drive::model::for_definition(&def).map_err(drive_err)?;
            let scaling = def.scaling;
            let sercos = def.profile == catalogue::Profile::Sercos;
            let def = std::sync::Arc::new(def);
            defs.push(def.clone());
            let axis =
                Axis::new(a.name.clone(), adapter, scaling, a.referenced).with_definition(def);
            images.push(ProcessImage::new(axis.output_len(), axis.input_len()));
            axes.push(axis);
            models.push(model);
            let mut axis_cfg = channel_axis_config(a, &probe, cycle);
            axis_cfg.servo_lag_time = servo_lag_time(&defs[defs.len() - 1].model);
            // Measurement type 6 needs a SERCOS axis (FCT-C4 §3 table).
            axis_cfg.meas.sercos = sercos;
            axis_cfgs.push(axis_cfg);
        }
        let ch_cfg = ChannelConfig {
            cycle,
            axes: axis_cfgs,
            range_check_programmed_limits: cfg.channel.int("P-CHAN-00498") != 0,
            display_pcs_limits: cfg.channel.int("P-CHAN-00489") != 0,
            move_limit_warning: cfg.manual.int("P-MANU-00014") != 0,
            workspace_manual_mode: u16::try_from(cfg.channel.int("P-CHAN-00442")).unwrap_or(0),
            enable_timeout_cycles: 1000,
            in_position_timeout_cycles: in_position_timeout_cycles(
                cfg.in_position_timeout_ms,
                cycle,
            ),
            max_lost_cycles: cfg.max_lost_cycles,
            meas: channel_meas_config(&cfg.channel),
        };
        // P-AXIS-00777 > 1000: warning 110757 at controller start (FCT-C4 §8.2.2).
        #[allow(unused_mut)] // the CAN bus-load warning is pushed with feature `canopen`
        let mut startup: Vec<CncMessage> = ch_cfg
            .axes
            .iter()
            .zip(&cfg.axes)
            .filter_map(|(c, a)| c.meas.fixed_stop.and_then(|f| f.startup_warning(&a.name)))
            .collect();
        // Probing-signal parameters set without effect: warning 900047 (seed 004 §8.2.2).
        startup.extend(param_warnings);
        let channel = Channel::new(ch_cfg.clone(), axes).map_err(MachineError::Config)?;
        let zero_offsets = cfg
            .zero_offsets
            .iter()
            .map(|(g, list)| {
                let mut v = vec![0.0; cfg.axes.len()];
                for (name, off) in list {
                    if let Some(i) = cfg.axes.iter().position(|a| a.name == *name) {
                        v[i] = *off;
                    }
                }
                (*g, v)
            })
            .collect();
        // CANopen node ids: the axis's `node` key, else its axis number.
        let node_ids = if choice.link.starts_with("canopen") || choice.link.starts_with("socketcan")
        {
            cfg.node_ids().map_err(MachineError::Config)?
        } else {
            Vec::new()
        };
        let is_can = choice.link == "canopen-emu"
            || choice.link.starts_with("canopen-udp")
            || choice.link.starts_with("socketcan:");
        // The bus load of the cycle (docs/canopen.md "Bus load"): the CANopen link refuses it
        // above 100 % (bad input: the message names the machine file), warning 900070 above
        // 70 %.
        #[cfg(feature = "canopen")]
        let check = if is_can {
            let bitrate = crate::bus::can::Bitrate::new(cfg.can_bitrate).ok_or_else(|| {
                MachineError::Config(format!("{}: [can] bitrate = 0", cfg.source))
            })?;
            crate::link::canopen::plan_bus_load(&defs, &node_ids, bitrate, cycle)
                .ok()
                .map(|l| l.check())
        } else {
            None
        };
        #[cfg(not(feature = "canopen"))]
        let check: Option<Result<Option<String>, String>> = {
            let _ = is_can;
            None
        };
        let link = crate::link::open(crate::link::LinkRequest {
            link: &choice.link,
            drives: &defs,
            models,
            node_ids: &node_ids,
            cycle,
            can_bitrate: cfg.can_bitrate,
            pcap: choice.pcap.as_deref(),
            candump: choice.candump.as_deref(),
            #[cfg(feature = "ethercat")]
            terminals: ethercat_terminals(cfg)?,
        })
        .map_err(|e| match &check {
            Some(Err(refusal)) if e.to_string() == *refusal => {
                MachineError::Config(format!("{}: {refusal}", cfg.source))
            }
            _ => MachineError::Config(format!("--link {}: {e}", choice.link)),
        })?;
        if let Some(Ok(Some(w))) = check {
            startup.push(CncMessage::warning(ids::CAN_BUS_LOAD, w));
        }
        // An axis whose device offers less than its drive definition maps (EtherCAT: no touch
        // probe) runs with the definition the link fitted: the channel is built again with
        // adapters and images that follow it.
        let changed = (0..defs.len()).any(|i| {
            link.drive_definition(i)
                .is_some_and(|d| !std::sync::Arc::ptr_eq(&d, &defs[i]))
        });
        let channel = if changed {
            let mut axes = Vec::new();
            for (i, a) in cfg.axes.iter().enumerate() {
                let def = link.drive_definition(i).unwrap_or_else(|| defs[i].clone());
                let adapter = crate::drive::adapter_for(&def, &a.params).map_err(|source| {
                    MachineError::Drive {
                        axis: a.name.clone(),
                        drive: a.drive.clone(),
                        cause: source,
                    }
                })?;
                let axis = Axis::new(a.name.clone(), adapter, def.scaling, a.referenced)
                    .with_definition(def);
                images[i] = ProcessImage::new(axis.output_len(), axis.input_len());
                axes.push(axis);
            }
            Channel::new(ch_cfg, axes).map_err(MachineError::Config)?
        } else {
            channel
        };
        let mut link = link;
        if let Some(path) = &choice.cycle_log {
            let file = std::fs::File::create(path).map_err(|e| {
                MachineError::Config(format!("--cycle-log {}: {e}", path.display()))
            })?;
            link.set_cycle_log(&path.display().to_string(), Box::new(file))
                .map_err(|e| MachineError::Config(e.to_string()))?;
        }
        let mut channel = channel;
        for (i, a) in cfg.axes.iter().enumerate() {
            channel.set_dead_time_cycles(i, a.dead_time_cycles.unwrap_or(link.dead_time_cycles()));
        }
        let terminal_probes = terminal_probes(cfg, link.as_ref(), &mut channel)?;
        // The in-memory link has no start-up of its own: as a bus master does in PRE-OP, write
        // the mode of operation (cyclic synchronous position) where no PDO carries it — to
        // 0x6060 or the object that plays it (`[roles]`).
        if choice.link == "sim" {
            for (i, def) in defs.iter().enumerate() {
                if def.profile == crate::drive::catalogue::Profile::Cia402
                    && !def.rxpdo.contains(0x6060, 0)
                {
                    let (index, sub) = def.object_of(0x6060, 0);
                    let _ =
                        link.write_object(i, index, sub, i64::from(crate::drive::ds402::MODE_CSP));
                }
            }
        }
        Ok(Machine {
            channel,
            link,
            images,
            now: Nanos::ZERO,
            cycle,
            max_cycles: DEFAULT_MAX_CYCLES,
            tools: cfg.tools.clone(),
            zero_offsets,
            plcs: (0..cfg.axes.len()).map(|_| None).collect(),
            startup,
            trace: None,
            terminals: cfg.terminals.iter().map(|t| t.name.clone()).collect(),
            terminal_probes,
            stop_request: None,
        })
    }

    /// Watch `request` during runs ([`StopRequest`]).
    pub fn set_stop_request(&mut self, request: StopRequest) {
        self.stop_request = Some(request);
    }

    /// The channel.
    pub fn channel(&self) -> &Channel {
        &self.channel
    }

    /// What the link reported when it came up (EtherCAT: the segment, SubDevices the machine
    /// does not name, the wire time per cycle; info 900400 – 900402).
    pub fn startup_report(&self) -> Vec<CncMessage> {
        self.link.startup_report()
    }

    /// The names of the machine's terminals (`[[terminal]]`), in ring order.
    pub fn terminal_names(&self) -> &[String] {
        &self.terminals
    }

    /// The process inputs of terminal `name` after the last cycle (`None`: no such terminal).
    pub fn terminal_inputs(&self, name: &str) -> Option<&[u8]> {
        let i = self.terminals.iter().position(|t| t == name)?;
        self.link.terminal_inputs(i)
    }

    /// The process outputs of terminal `name`, sent with the next cycle.
    pub fn terminal_outputs_mut(&mut self, name: &str) -> Option<&mut [u8]> {
        let i = self.terminals.iter().position(|t| t == name)?;
        self.link.terminal_outputs_mut(i)
    }

    /// The statistics of the paced cycle (links that leave the process), see
    /// [`crate::rt::CycleStats`].
    pub fn cycle_summary(&self) -> Option<crate::rt::CycleSummary> {
        self.link.cycle_summary()
    }

    /// Flush the cycle log (`--cycle-log`).
    ///
    /// # Errors
    /// A write to it failed, naming the file.
    pub fn finish_cycle_log(&mut self) -> Result<(), String> {
        self.link.finish_cycle_log()
    }

    /// Flush the frame capture (`--pcap`, `--candump`) after the run ([`Link::finish_capture`]).
    ///
    /// # Errors
    /// The first write to it that failed, naming the option and the file.
    pub fn finish_capture(&mut self) -> Result<(), String> {
        self.link.finish_capture()
    }

    /// The channel, mutable (manual mode, reset, referencing).
    pub fn channel_mut(&mut self) -> &mut Channel {
        &mut self.channel
    }

    /// The link with its drive models (test, fault and plant knobs).
    pub fn link_mut(&mut self) -> &mut dyn Link {
        self.link.as_mut()
    }

    /// The link.
    pub fn link(&self) -> &dyn Link {
        self.link.as_ref()
    }

    fn plant_mut(&mut self) -> Result<&mut crate::sim::plant::Plant, MachineError> {
        self.link.plant_mut().ok_or_else(|| {
            MachineError::Config(
                "this link reaches real drives; a simulated probe or stop needs --link sim or ethercat-emu".into(),
            )
        })
    }

    /// Virtual time now.
    pub fn now(&self) -> Nanos {
        self.now
    }

    /// A simulated touch probe (`--probe-at AXIS=POS`): it switches every time `axis`'s actual
    /// (ACS) position crosses `position` (mm). Its signal is wired to input P-AXIS-00517 of every
    /// measurement axis (P-AXIS-00118), polarity per P-AXIS-00518 of `axis`, and fed to the
    /// simulated PLC of the axes that measure through the PLC. Returns the probe index.
    pub fn add_probe(&mut self, axis: &str, position: f64) -> Result<usize, MachineError> {
        let i = self.axis_index(axis)?;
        let inc = self.increments(i, position)?;
        let cfg = self.channel.config();
        let wired: Vec<(usize, u8)> = cfg
            .axes
            .iter()
            .enumerate()
            .filter(|(_, c)| c.meas.enabled)
            .map(|(j, c)| (j, c.meas.input.clamp(1, 2)))
            .collect();
        let mut surface = ProbeSurface::new(i, inc, wired);
        surface.active_high = cfg.axes[i].meas.edge == ProbeEdge::Positive;
        // The probe is also wired to every timestamp input that carries an axis's probe.
        for tp in &self.terminal_probes {
            let device = self.link.terminal_device(tp.terminal).ok_or_else(|| {
                MachineError::Config(format!(
                    "terminal {}: the link does not emulate it, so a simulated probe cannot switch its input",
                    self.terminals[tp.terminal]
                ))
            })?;
            surface.wired.push((device, tp.channel));
        }
        let signals: Vec<(SignalSource, ProbeEdge)> = cfg
            .axes
            .iter()
            .map(|c| (c.meas.signal, c.meas.edge))
            .collect();
        let probe = self.plant_mut()?.add_probe_surface(surface);
        let cycle = self.cycle;
        for (j, (signal, edge)) in signals.into_iter().enumerate() {
            // An axis whose probe is on a terminal has its PLC inputs from the terminal.
            if self.plcs[j].is_some() || self.terminal_probes.iter().any(|t| t.axis == j) {
                continue;
            }
            // Every axis gets a PLC on the first probe; its mode follows the source the axis
            // measures with (configured, or a #MEAS override while a run is armed).
            let mut pc = SimPlcConfig::new(cycle);
            pc.probe = probe;
            pc.mode = sim_plc_mode(signal, edge);
            pc.timestamp = Some(TimestampOutput {
                clock: DcClock::default(),
                terminal_delay_ns: 0,
                edge,
            });
            self.plcs[j] = Some(ScriptedPlc::new(pc));
        }
        Ok(probe)
    }

    /// A mechanical stop (`--fixed-stop-at AXIS=POS`): `axis` cannot pass ACS `position` (mm).
    pub fn add_fixed_stop(&mut self, axis: &str, position: f64) -> Result<(), MachineError> {
        let i = self.axis_index(axis)?;
        let inc = self.increments(i, position)?;
        self.plant_mut()?.add_fixed_stop(FixedStop {
            device: i,
            position: inc,
        });
        if let Some(m) = self.link.model_mut(i) {
            m.set_fixed_stop(Some(inc));
        }
        Ok(())
    }

    /// Start recording a [`Trace`]: every cycle from now on until [`MAX_TRACE_SAMPLES`] samples,
    /// then decimated (see there), so a trace of any run stays bounded.
    pub fn enable_trace(&mut self) {
        self.enable_trace_with_limit(MAX_TRACE_SAMPLES);
    }

    /// [`enable_trace`](Self::enable_trace) keeping up to `limit` samples before it
    /// decimates (at least 2): for tests that look at every cycle of a run longer than
    /// [`MAX_TRACE_SAMPLES`] cycles. Memory: 8 bytes × (1 + 2 × axes) per sample.
    pub fn enable_trace_with_limit(&mut self, limit: usize) {
        let axes: Vec<String> = self
            .channel
            .axes()
            .iter()
            .map(|a| a.name().to_string())
            .collect();
        let n = axes.len();
        self.trace = Some(Trace {
            axes,
            command: vec![Vec::new(); n],
            actual: vec![Vec::new(); n],
            stride: 1,
            limit,
            ..Trace::default()
        });
        self.channel.record_latches(true);
    }

    /// The recorded trace, if enabled.
    pub fn trace(&self) -> Option<&Trace> {
        self.trace.as_ref()
    }

    /// The simulated PLC of axis `i`, if it has one (test knobs: acknowledge script, period).
    pub fn sim_plc_mut(&mut self, i: usize) -> Option<&mut ScriptedPlc> {
        self.plcs.get_mut(i).and_then(Option::as_mut)
    }

    fn axis_index(&self, axis: &str) -> Result<usize, MachineError> {
        self.channel.axis_index(axis).ok_or_else(|| {
            let names: Vec<&str> = self.channel.axes().iter().map(|a| a.name()).collect();
            MachineError::Config(format!(
                "unknown axis '{axis}'; the machine has {}",
                names.join(", ")
            ))
        })
    }

    fn increments(&self, i: usize, position: f64) -> Result<f64, MachineError> {
        let sc = self.channel.axes()[i].scaling();
        if !position.is_finite() || sc.to_increments(position).is_none() {
            return Err(MachineError::Config(format!(
                "position {position} is outside the drive's range"
            )));
        }
        Ok((position - sc.offset) * sc.increments_per_unit)
    }

    /// One interpolation cycle: exchange the process data, run the simulated PLCs, then the
    /// channel.
    pub fn step(&mut self) {
        self.now = self.now.saturating_add(self.cycle);
        match self.link.exchange(self.now, &mut self.images) {
            Ok(()) => {
                self.feed_terminal_probes();
                self.channel.set_sample_dc_time(self.link.sample_dc_time());
                for i in 0..self.plcs.len() {
                    if let (Some(plc), Some(src)) =
                        (self.plcs[i].as_mut(), self.channel.armed_signal(i))
                    {
                        let edge = self.channel.config().axes[i].meas.edge;
                        let mode = sim_plc_mode(src, edge);
                        if plc.config().mode != mode {
                            plc.config_mut().mode = mode;
                        }
                    }
                    if let Some(plc) = self.plcs[i].as_mut() {
                        let sc = self.channel.axes()[i].scaling();
                        let inputs = AxisInputs {
                            link: self.link.as_ref(),
                            device: i,
                            scaling: sc,
                        };
                        if let Some(p) = self.channel.plc_mut(i) {
                            plc.step(self.now, &inputs, p);
                        }
                    }
                }
                self.channel.cycle(self.now, &mut self.images)
            }
            Err(e) => self.channel.link_lost(&e),
        }
        for e in self.link.take_drive_emergencies() {
            self.channel.drive_emergency(e.device, e.code, e.text);
        }
        if let Some(tr) = self.trace.as_mut() {
            tr.push_sample(self.now.as_secs_f64(), self.channel.axes());
            if let Some(plant) = self.link.plant() {
                for e in plant.last_edges() {
                    tr.push_edge(e.at.as_secs_f64(), e.rising);
                }
            }
            for (t, axis, p) in self.channel.take_latch_log() {
                tr.push_latch(t.as_secs_f64(), axis, p);
            }
        }
        // Acyclic requests (#DRIVE, #IDENT) go over the link's mailbox.
        for req in self.channel.take_acyclic_requests() {
            let result = match req.op {
                AcyclicOp::Read => self.link.read_object(req.axis, req.index, req.sub),
                AcyclicOp::Write(v) => self
                    .link
                    .write_object(req.axis, req.index, req.sub, v)
                    .map(|()| v),
            };
            self.channel
                .acyclic_done(req.id, result.map_err(|e| e.to_string()));
        }
    }

    /// The PLC glue of the axes whose probe is on a timestamp input terminal
    /// ([`TerminalProbe`]), after each exchange. The terminal's image length was checked when
    /// the machine was built, so decoding cannot fail.
    fn feed_terminal_probes(&mut self) {
        for tp in &mut self.terminal_probes {
            let Some(image) = self.link.terminal_inputs(tp.terminal) else {
                continue;
            };
            let Ok((levels, edges)) = tp.decoder.decode(image) else {
                continue;
            };
            let level = levels
                .get(usize::from(tp.channel) - 1)
                .copied()
                .unwrap_or(false);
            let edge = self.channel.config().axes[tp.axis].meas.edge;
            if let Some(plc) = self.channel.plc_mut(tp.axis) {
                crate::drive::el1252::feed_plc(plc, tp.channel, level, &edges, edge);
            }
        }
    }

    /// The end of a run: disable every drive and bring the bus to its end state.
    ///
    /// Each cycle (at most [`POWER_OFF_CYCLES`]) exchanges the process data and has every axis
    /// write "disable" ([`Channel::power_off_cycle`]: CiA 402 controlword 0x0006 shutdown →
    /// READY TO SWITCH ON), until every drive reports its power stage off; then the link's end
    /// state ([`Link::release`]: CANopen nodes to NMT pre-operational). Runs after a completed
    /// and after an aborted program alike; a lost exchange is retried within the bound.
    /// Returns warnings [`ids::POWER_OFF`] naming the axes still on or the link's failure (none:
    /// every drive off, the bus in its end state), and the emergencies that came meanwhile.
    /// A later [`run_program`](Self::run_program) enables the drives again.
    pub fn power_off(&mut self) -> Vec<CncMessage> {
        let mut on = self
            .channel
            .axes()
            .iter()
            .map(|a| a.name().to_string())
            .collect::<Vec<_>>();
        let mut lost = None;
        for _ in 0..POWER_OFF_CYCLES {
            self.now = self.now.saturating_add(self.cycle);
            match self.link.exchange(self.now, &mut self.images) {
                Ok(()) => {
                    lost = None;
                    on = self.channel.power_off_cycle(self.now, &mut self.images);
                    if on.is_empty() {
                        break;
                    }
                }
                Err(e) => lost = Some(e),
            }
        }
        for e in self.link.take_drive_emergencies() {
            self.channel.drive_emergency(e.device, e.code, e.text);
        }
        self.channel.emergency_summary();
        let mut out = self.channel.take_messages();
        if !on.is_empty() {
            out.push(CncMessage::warning(
                ids::POWER_OFF,
                format!(
                    "end of run: the drives of axes {} still report their power stage on after {POWER_OFF_CYCLES} cycles of disable{}",
                    on.join(", "),
                    lost.map(|e| format!(" (last exchange: {e})")).unwrap_or_default()
                ),
            ));
        }
        if let Err(e) = self.link.release(self.now) {
            out.push(CncMessage::warning(
                ids::POWER_OFF,
                format!("end of run: {e}"),
            ));
        }
        out
    }

    /// Step until the channel leaves `Enabling` / `Busy` / `Stopping`, at most `max` cycles.
    /// Returns the state reached.
    pub fn settle(&mut self, max: u64) -> ChannelState {
        for _ in 0..max {
            match self.channel.state() {
                ChannelState::Idle | ChannelState::Aborted => break,
                _ => self.step(),
            }
        }
        self.channel.state()
    }

    /// Run `program` to its end or to the first error. `on_event` sees every `#MSG` line and
    /// message as it happens (for streaming output).
    pub fn run_program(
        &mut self,
        program: &Program,
        on_event: &mut dyn FnMut(&RunEvent),
    ) -> RunReport {
        self.run_program_with_progress(program, on_event, &mut |_| {})
    }

    /// [`Machine::run_program`], with `on_cycle` called after every interpolation cycle with
    /// where the run stands (for a progress display; it must be cheap).
    pub fn run_program_with_progress(
        &mut self,
        program: &Program,
        on_event: &mut dyn FnMut(&RunEvent),
        on_cycle: &mut dyn FnMut(&RunProgress),
    ) -> RunReport {
        let mut events = Vec::new();
        let mut emit = |e: RunEvent, events: &mut Vec<RunEvent>| {
            on_event(&e);
            events.push(e);
        };
        let start_cycles = self.channel.cycles();
        let start_time = self.now;
        for m in std::mem::take(&mut self.startup) {
            emit(RunEvent::Message(m), &mut events);
        }
        // Program start: configured SLS again (FCT-A2 §3.3), drives enabled.
        if self.channel.state() != ChannelState::Enabling {
            self.channel.program_start();
        }
        self.settle(u64::from(self.channel.config().enable_timeout_cycles) + 2);
        let names = self
            .channel
            .axes()
            .iter()
            .map(|a| a.name().to_string())
            .collect();
        let mut exec = Executor::new(program.clone(), names);
        exec.set_tools(self.tools.clone());
        exec.set_zero_offsets(self.zero_offsets.clone());
        exec.sync(&self.channel);
        let mut out = Vec::new();
        let mut ended = false;
        let mut waited_for_independent = false;
        let mut stop_reported = false;
        let status = loop {
            if !stop_reported {
                if let Some(cause) = self.stop_request.as_ref().and_then(StopRequest::cause) {
                    stop_reported = true;
                    self.channel.report(CncMessage::error(
                        ids::RUN_INTERRUPTED,
                        format!(
                            "stop requested ({cause}): the axes brake to a stop, then every \
                             drive is disabled"
                        ),
                    ));
                }
            }
            for m in self.channel.take_messages() {
                emit(RunEvent::Message(m), &mut events);
            }
            if self.channel.cycles() - start_cycles > self.max_cycles {
                let m = CncMessage::error(
                    ids::RUN_TIMEOUT,
                    format!(
                        "run exceeded {} interpolation cycles; stopped",
                        self.max_cycles
                    ),
                );
                self.channel.report(m);
                self.settle(1_000_000);
                for m in self.channel.take_messages() {
                    emit(RunEvent::Message(m), &mut events);
                }
                break RunStatus::Aborted;
            }
            match self.channel.state() {
                ChannelState::Aborted => {
                    self.channel.area_program_end();
                    for m in self.channel.take_messages() {
                        emit(RunEvent::Message(m), &mut events);
                    }
                    break RunStatus::Aborted;
                }
                // The program's end waits for independent motions still running
                // (`INDP_ASYN`), then takes what they measured.
                ChannelState::Idle if ended && self.channel.independent_running() => {
                    waited_for_independent = true;
                    self.step();
                    on_cycle(&RunProgress {
                        block: self.channel.block(),
                        cycles: self.channel.cycles() - start_cycles,
                        time: Nanos(self.now.0.saturating_sub(start_time.0)),
                    });
                }
                ChannelState::Idle if ended && waited_for_independent => {
                    waited_for_independent = false;
                    if exec.step(&mut self.channel, &mut out) == Step::Abort
                        && self.channel.state() == ChannelState::Idle
                    {
                        self.channel.abort_reported();
                    }
                }
                ChannelState::Idle if ended => {
                    self.channel.program_end();
                    for m in self.channel.take_messages() {
                        emit(RunEvent::Message(m), &mut events);
                    }
                    break RunStatus::Completed;
                }
                ChannelState::Idle => {
                    let step = exec.step(&mut self.channel, &mut out);
                    for Event::Output(line) in out.drain(..) {
                        emit(RunEvent::Output(line), &mut events);
                    }
                    match step {
                        Step::Continue => {}
                        Step::End => ended = true,
                        Step::Abort => {
                            if self.channel.state() == ChannelState::Idle {
                                // Defensive: an aborting block always stops the channel. Its
                                // error, when queued already, is the only message (one cause,
                                // one error).
                                if self.channel.messages().iter().any(CncMessage::is_error) {
                                    self.channel.abort_reported();
                                } else {
                                    self.channel.report(CncMessage::error(
                                        ids::NC_EVALUATION,
                                        "program aborted",
                                    ));
                                }
                            }
                        }
                    }
                }
                _ => {
                    self.step();
                    on_cycle(&RunProgress {
                        block: self.channel.block(),
                        cycles: self.channel.cycles() - start_cycles,
                        time: Nanos(self.now.0.saturating_sub(start_time.0)),
                    });
                }
            }
        };
        let measurements = (0..self.channel.axis_count())
            .map(|i| AxisMeasurement {
                result: exec.result(i),
                merf: exec.merf(i),
                mein: exec.frames().mein(i),
            })
            .collect();
        RunReport {
            status,
            events,
            cycles: self.channel.cycles() - start_cycles,
            measurements,
        }
    }
}

/// The channel's view of one axis's parameters (seed units → mm, mm/s, mm/s²); `probe` is the
/// axis's probing signal settings resolved from the same list ([`ProbeSettings::from_params`]).
pub fn channel_axis_config(
    a: &AxisConfig,
    probe: &ProbeSettings,
    cycle: Nanos,
) -> ChannelAxisConfig {
    let p = &a.params;
    let rotary = is_rotary(p);
    let mm_s2 = |id: &str| p.int(id) as f64;
    // P-AXIS-00003 a_emergency: 0 means P-AXIS-00008 a_max is used (ISG axis parameter docs).
    let a_emergency = match p.int("P-AXIS-00003") {
        0 => mm_s2("P-AXIS-00008"),
        v => v as f64,
    };
    let limits = AxisLimitConfig {
        name: a.name.clone(),
        neg: param_pos_to_mm(p.int("P-AXIS-00177")),
        pos: param_pos_to_mm(p.int("P-AXIS-00178")),
        tolerance: param_pos_to_mm(p.int("P-AXIS-00179")),
        behaviour: SlsBehaviour::from_param(p.text("P-AXIS-00554")).unwrap_or_default(),
        check: p.int("P-AXIS-00705").clamp(-1, 1) as i8,
        modulo: rotary && is_modulo(p),
        absolute_encoder: p.int("P-AXIS-00014") != 0,
        // FCT-A2 §4.3: axis types T only.
        check_pos_command: !rotary && p.int("P-AXIS-00520") != 0,
        check_neg_command: !rotary && p.int("P-AXIS-00521") != 0,
        emergency_decel: a_emergency,
        manual_rel_neg: param_pos_to_mm(p.int("P-AXIS-00137")),
        manual_rel_pos: param_pos_to_mm(p.int("P-AXIS-00138")),
        manual_abs_neg: param_pos_to_mm(p.int("P-AXIS-00492")),
        manual_abs_pos: param_pos_to_mm(p.int("P-AXIS-00493")),
    };
    let a_rapid = mm_s2("P-AXIS-00004");
    let meas = AxisMeasConfig {
        enabled: p.int("P-AXIS-00118") != 0,
        signal: probe.signal,
        input: probe.input,
        edge: probe.edge,
        trigger_mode: trigger_mode_from_text(p.text("P-AXIS-00702")).unwrap_or_default(),
        stroke: param_pos_to_mm(p.int("P-AXIS-00086")),
        feed_type2: param_vel_to_mm_s(p.int("P-AXIS-00215")),
        overtravel: param_pos_to_mm(p.int("P-AXIS-00467")),
        // P-AXIS-00467 replaces P-AXIS-00114, which stays available for type 2 only (FCT-C4
        // §8.2.2): the old value applies when the new parameter is not given.
        overtravel_type2: param_pos_to_mm(if p.is_set("P-AXIS-00467") {
            p.int("P-AXIS-00467")
        } else {
            p.int("P-AXIS-00114")
        }),
        // P-AXIS-00053 a_feedh: 0 means P-AXIS-00004 (ISG axis parameter docs).
        a_feedhold: match p.int("P-AXIS-00053") {
            0 => a_rapid,
            v => v as f64,
        },
        lag_limit: param_pos_to_mm(p.int("P-AXIS-00168")),
        sercos: false,
        fixed_stop: crate::core::measure::fixed_stop::FixedStopParams::from_params(p, cycle).ok(),
    };
    ChannelAxisConfig {
        rotary,
        // P-AXIS-00127 modulou … P-AXIS-00126 moduloo (0.0001°), for a modulo rotary axis.
        modulo: (rotary && is_modulo(p)).then(|| {
            (
                param_pos_to_mm(p.int("P-AXIS-00127")),
                param_pos_to_mm(p.int("P-AXIS-00126")),
            )
        }),
        v_max: param_vel_to_mm_s(p.int("P-AXIS-00212")),
        a_feed: mm_s2("P-AXIS-00001"),
        d_feed: mm_s2("P-AXIS-00002"),
        a_rapid: mm_s2("P-AXIS-00004"),
        a_emergency,
        limits,
        meas,
        in_position: param_pos_to_mm(i64::from(a.in_position_window)),
        servo_lag_time: 0.0,
    }
}

/// Time a drive's actual position lags its set-point at constant speed, s (lag = v × this):
/// `(1 − velocity_feed_forward) / kv`, i.e. 0 with full velocity feed-forward and 1/kv for a
/// drive without feed-forward.
pub fn servo_lag_time(m: &crate::drive::catalogue::ModelConfig) -> f64 {
    let kv = if m.kv.is_finite() && m.kv > 0.0 {
        m.kv
    } else {
        40.0
    };
    let vff = if m.feed_forward {
        m.velocity_feed_forward.clamp(0.0, 1.0)
    } else {
        0.0
    };
    (1.0 - vff) / kv
}

/// `in_position_timeout_ms` in interpolation cycles (at least 1).
fn in_position_timeout_cycles(ms: u32, cycle: Nanos) -> u32 {
    let c = cycle.0.max(1);
    let n = (u64::from(ms) * 1_000_000).div_ceil(c);
    u32::try_from(n).unwrap_or(u32::MAX).max(1)
}

/// The channel's measurement settings from its parameter list (FCT-C4 §8.2.1, FCT-C14 §6.2).
pub fn channel_meas_config(p: &ParamSet) -> ChannelMeasConfig {
    ChannelMeasConfig {
        default_type: MeasType::from_number(p.int("P-CHAN-00057")).unwrap_or(MeasType::Type1),
        feedhold_param_decel: p.int("P-CHAN-00097") != 0,
        rapid_decel_on_signal: p.int("P-CHAN-00214") != 0,
        std_dynamics: p.int("P-CHAN-00296") != 0,
        error_no_signal_type1: p.int("P-CHAN-00176") != 0,
        fixed_stop_no_error: p.int("P-CHAN-00266") != 0,
        limit_at_sls: p.int("P-CHAN-00268") != 0,
        pcs_without_radius: p.int("P-CHAN-00311") != 0,
        plc_cycle: None,
    }
}

/// P-AXIS-00018 `kenngr.achs_typ`: rotary axis (`ACHSTYP_ROTATOR`, 0x0002).
fn is_rotary(p: &ParamSet) -> bool {
    let t = p.text("P-AXIS-00018");
    t.eq_ignore_ascii_case(AXIS_TYPE_ROTARY) || t == "2" || t.eq_ignore_ascii_case("0x0002")
}

/// P-AXIS-00015 `kenngr.achs_mode`: bit ACHSMODE_MODULO.
fn is_modulo(p: &ParamSet) -> bool {
    p.int("P-AXIS-00015") & ACHSMODE_MODULO != 0
}

/// P-AXIS-00018 value of a rotary axis (ISG: ACHSTYP_TRANSLATOR 0x1, ACHSTYP_ROTATOR 0x2,
/// ACHSTYP_SPINDEL 0x4).
pub const AXIS_TYPE_ROTARY: &str = "ACHSTYP_ROTATOR";
/// P-AXIS-00015 bit ACHSMODE_MODULO (ISG axis parameter docs: 0x00000004).
pub const ACHSMODE_MODULO: i64 = 0x4;

/// The plant's probe signals as one axis's simulated PLC sees them; the "true" crossing
/// position it reports for external measuring hardware is that axis's own position at the edge.
struct AxisInputs<'a> {
    link: &'a dyn Link,
    device: usize,
    scaling: crate::units::Scaling,
}

impl ProbeInputs for AxisInputs<'_> {
    fn for_each_edge(&self, f: &mut dyn FnMut(InputEdge)) {
        if let Some(p) = self.link.plant() {
            p.for_each_edge(f);
        }
    }

    fn level(&self, probe: usize, at: Nanos) -> bool {
        self.link.plant().is_some_and(|p| p.level(probe, at))
    }

    fn crossing_position(&self, edge: &InputEdge) -> Option<f64> {
        let inc = self.link.model(self.device)?.position_at(edge.at)?;
        Some(inc / self.scaling.increments_per_unit + self.scaling.offset)
    }
}

/// What the simulated PLC puts on `probing_signal` for a signal source.
fn sim_plc_mode(signal: SignalSource, edge: ProbeEdge) -> SimPlcMode {
    match signal {
        SignalSource::PlcFirstEvent => SimPlcMode::FirstEventLatch { edge },
        SignalSource::PlcExtLatchControl => SimPlcMode::ExtLatchControl,
        _ => SimPlcMode::Signal,
    }
}

/// The commissioning findings of one axis.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisCheck {
    /// Axis name.
    pub axis: String,
    /// Drive definition name.
    pub drive: String,
    /// Drive family.
    pub profile: &'static str,
    /// Mismatches in plain words (empty: consistent).
    pub findings: Vec<String>,
    /// What the user should know that is not a mismatch (a drive without touch probe on an
    /// axis that measures through the CNC), in plain words.
    pub notes: Vec<String>,
    /// Parameters the axis sets without effect (warning 900047), as the run reports them.
    pub warnings: Vec<CncMessage>,
}

/// The timestamp input terminals (EL1252 kind) the machine names, in words for `check`: where
/// PLC_TIMESTAMP gets its timestamps (seed 004 §7.5).
fn timestamp_inputs_text(cfg: &MachineConfig) -> String {
    let names: Vec<String> = cfg
        .terminals
        .iter()
        .filter(|t| is_timestamp_terminal(cfg, t))
        .map(|t| format!("{} ({})", t.name, t.esi))
        .collect();
    if names.is_empty() {
        "the machine names no timestamp input terminal (EL1252 kind) for PLC_TIMESTAMP: add a \
         [[terminal]] with esi = \"fieldprobe-el1252\" or your EL1252's ESI"
            .into()
    } else {
        format!(
            "timestamp input terminals on the segment for PLC_TIMESTAMP: {}",
            names.join(", ")
        )
    }
}

/// Is `[[terminal]]` `t` an EL1252-kind timestamp input (the type name of its ESI device)?
#[cfg(feature = "sim")]
fn is_timestamp_terminal(cfg: &MachineConfig, t: &crate::params::TerminalConfig) -> bool {
    let base = std::path::Path::new(&cfg.source).parent();
    crate::link::ethercat::terminals::TerminalSpec::resolve(&t.name, &t.esi, base)
        .ok()
        .and_then(|s| {
            s.esi
                .devices
                .first()
                .map(crate::sim::esc::terminal::is_el1252)
        })
        .unwrap_or(false)
}

/// Is `[[terminal]]` `t` an EL1252-kind timestamp input (without the emulator: by its ESI
/// reference's name)?
#[cfg(not(feature = "sim"))]
fn is_timestamp_terminal(_cfg: &MachineConfig, t: &crate::params::TerminalConfig) -> bool {
    t.esi.to_ascii_uppercase().contains("EL1252")
}

impl Machine {
    /// Commissioning check (FCT-C4 §6): read each drive's settings over the link and compare
    /// them with the axis parameters of `cfg`; every mismatch in plain words.
    pub fn commissioning_check(&mut self, cfg: &MachineConfig) -> Vec<AxisCheck> {
        let mut out = Vec::new();
        for (i, a) in cfg.axes.iter().enumerate() {
            let Some(def) = self.channel.axes()[i].definition().cloned() else {
                continue;
            };
            let mut findings = Vec::new();
            let p = &a.params;
            // The same resolution as the run's (FCT-C4 §8.2.2: new parameter, else the old).
            let probe = match ProbeSettings::from_params(p) {
                Ok(s) => s,
                Err(e) => {
                    out.push(AxisCheck {
                        axis: a.name.clone(),
                        drive: def.name.clone(),
                        profile: def.profile.name(),
                        findings: vec![e],
                        notes: Vec::new(),
                        warnings: Vec::new(),
                    });
                    continue;
                }
            };
            let signal = probe.signal;
            let measures = p.int("P-AXIS-00118") != 0;
            let link = std::cell::RefCell::new(self.link.as_mut());
            let read = |index: u16, sub: u8| link.borrow_mut().read_object(i, index, sub).ok();
            findings.extend(crate::drive::commissioning_check(&def, p, &read));
            let mut notes = Vec::new();
            if !def.has_drive_latch() {
                // Seed 004 §7: without a latch in the drive the CNC detects the value.
                let sources = crate::core::measure::SOURCES_WITHOUT_DRIVE_LATCH;
                let terminals = timestamp_inputs_text(cfg);
                if measures && signal.uses_drive_latch() {
                    findings.push(format!(
                        "drive '{}' has no touch probe (0x60B8 / 0x60B9 are not in its PDO \
                         mapping): P-AXIS-00516 kenngr.measure.signal {} cannot latch; the \
                         sources that remain (seed 004 §7): {sources}; {terminals}",
                        def.name,
                        signal.name()
                    ));
                } else if measures {
                    notes.push(format!(
                        "drive '{}' has no touch probe; the axis measures through the CNC with \
                         {} (seed 004 §7){}",
                        def.name,
                        signal.name(),
                        if signal == SignalSource::PlcTimestamp {
                            format!("; {terminals}")
                        } else {
                            String::new()
                        }
                    ));
                } else {
                    notes.push(format!(
                        "drive '{}' has no touch probe: should the axis measure (P-AXIS-00118), \
                         the sources are (seed 004 §7): {sources}",
                        def.name
                    ));
                }
            } else if measures
                && signal.uses_drive_latch()
                && def.profile == crate::drive::catalogue::Profile::Cia402
            {
                let mapped = |index: u16| def.txpdo.contains(index, 0);
                if !mapped(0x60B9) {
                    findings.push("the touch probe status 0x60B9 is not in the TxPDO; the drive latch cannot be read (seed 004 §6.4)".into());
                }
                let probe2 = probe.input == 2;
                let edge_neg = probe.edge == ProbeEdge::Negative;
                let value = match (probe2, edge_neg) {
                    (false, false) => 0x60BA,
                    (false, true) => 0x60BB,
                    (true, false) => 0x60BC,
                    (true, true) => 0x60BD,
                };
                if !mapped(value) {
                    findings.push(format!(
                        "P-AXIS-00517 / 00518 select the latch value {value:#06X}, which is not in the TxPDO (seed 004 §6.4 table)"
                    ));
                }
                if !def.rxpdo.contains(0x60B8, 0) {
                    findings.push(
                        "the touch probe function 0x60B8 is not in the RxPDO (seed 004 §6.4)"
                            .into(),
                    );
                }
            }
            out.push(AxisCheck {
                axis: a.name.clone(),
                drive: def.name.clone(),
                profile: def.profile.name(),
                findings,
                notes,
                warnings: probe.warnings(&a.name),
            });
        }
        out
    }
}

/// P-AXIS-00517 per the seed's table (FCT-C4 §8.2.2): PLC_EXT_LATCH_CONTROL 1 … 255,
/// EXT_PROBE_WITH_DRIVE 1 … 2, DRIVE on SERCOS / CANopen / PROFIDRIVE 1 … 2, DRIVE on the other
/// drive types (Lightbus, terminal) 1. 0 = not given (input 1).
fn check_probing_input(
    a: &AxisConfig,
    probe: &ProbeSettings,
    def: &crate::drive::catalogue::DriveDefinition,
) -> Result<(), MachineError> {
    use crate::drive::catalogue::Profile;
    let input = i64::from(probe.input);
    let signal = probe.signal;
    let max = match signal {
        SignalSource::PlcExtLatchControl => 255,
        SignalSource::ExtProbeWithDrive => 2,
        SignalSource::Drive | SignalSource::DriveTypeDefault => match def.profile {
            Profile::Cia402 | Profile::Sercos | Profile::Profidrive => 2,
            Profile::Lightbus | Profile::Terminal => 1,
        },
        _ => return Ok(()),
    };
    if (1..=max).contains(&input) {
        return Ok(());
    }
    Err(MachineError::Config(format!(
        "axis {}: {} = {input} is not allowed for measurement method {} on a {} drive ('{}'); allowed 1 … {max} (seed 004 §8.2.2)",
        a.name,
        probe.input_origin.words(),
        signal.name(),
        def.profile.name(),
        def.name
    )))
}

/// The axes whose probe a `[[terminal]]` wires to a timestamp input (`probe_axis`,
/// `probe_channel`): the terminal must be an EL1252-kind timestamp input whose process inputs
/// hold the channel; the channel then reads the axis's PLC interface with the actual values
/// latched at the same SYNC0 ([`Channel::set_plc_inputs_from_bus`]).
fn terminal_probes(
    cfg: &MachineConfig,
    link: &dyn Link,
    channel: &mut Channel,
) -> Result<Vec<TerminalProbe>, MachineError> {
    use crate::drive::el1252::{Decoder, LatchMode, CHANNEL_LEN};
    let mut out = Vec::new();
    for (k, t) in cfg.terminals.iter().enumerate() {
        let Some(w) = &t.probe else { continue };
        let at = format!(
            "{}:{}: [[terminal]] {} probe_axis = \"{}\"",
            cfg.source, w.line, t.name, w.axis
        );
        if !is_timestamp_terminal(cfg, t) {
            return Err(MachineError::Config(format!(
                "{at}: esi \"{}\" is no timestamp input (EL1252 kind, e.g. fieldprobe-el1252); a probe for PLC_TIMESTAMP is wired to one (seed 004 §7.5)",
                t.esi
            )));
        }
        let axis = cfg
            .axes
            .iter()
            .position(|a| a.name == w.axis)
            .ok_or_else(|| MachineError::Config(format!("{at}: no such axis")))?;
        let channels = link.terminal_inputs(k).map_or(0, |i| i.len() / CHANNEL_LEN);
        if channels < usize::from(w.channel) {
            return Err(MachineError::Config(format!(
                "{at}: probe_channel = {}: the terminal's process inputs hold {channels} timestamp channel{} of {CHANNEL_LEN} bytes",
                w.channel,
                if channels == 1 { "" } else { "s" }
            )));
        }
        channel.set_plc_inputs_from_bus(axis, true);
        out.push(TerminalProbe {
            axis,
            terminal: k,
            channel: w.channel,
            decoder: Decoder::new(channels, LatchMode::Continuous),
        });
    }
    Ok(out)
}

/// The machine's `[[terminal]]` tables with their ESI files loaded (relative paths from the
/// machine file's directory).
#[cfg(feature = "ethercat")]
fn ethercat_terminals(
    cfg: &MachineConfig,
) -> Result<Vec<crate::link::ethercat::terminals::TerminalSpec>, MachineError> {
    let base = std::path::Path::new(&cfg.source).parent();
    cfg.terminals
        .iter()
        .map(|t| {
            let mut spec =
                crate::link::ethercat::terminals::TerminalSpec::resolve(&t.name, &t.esi, base)
                    .map_err(|e| MachineError::Config(format!("{}:{}: {e}", cfg.source, t.line)))?;
            spec.after_axes = t.after_axes;
            Ok(spec)
        })
        .collect()
}
