//! Machine file (TOML): the channel list, the manual-mode list and one `[[axis]]` table per axis,
//! plus the `--set KEY=VALUE` overrides of the command line (the command-line contract of `fieldprobe run`).
//!
//! ```toml
//! [channel]
//! cycle_time_us = 1000                 # project key: interpolation cycle, 100 ..= 100000 µs
//! in_position_timeout_ms = 1000        # project key: how long an exact stop may wait, ms
//! max_lost_cycles = 3                  # project key: lost exchanges ridden through before 900012
//! "P-CHAN-00498" = 1                   # parameters by ID …
//! range_check_prog_soft_limits = 1     # … or by name path (FCT-A2 §4.2)
//! [manual]
//! move_limit_warning = true            # P-MANU-00014 (FCT-A2 §4.4)
//! [[axis]]
//! name = "X"                           # project key, required: X Y Z A B C U V W (+ digits)
//! drive = "cia402-generic"             # project key: drives/<name>.toml
//! referenced = true                    # project key: axis referenced at start
//! node = 5                             # project key: CANopen node id 1 ..= 127 on CAN links
//!                                      # (default: axis number, i.e. 1, 2, …)
//! in_position_window = 10              # project key: exact-stop window, 0.1 µm (default 1 µm)
//! dead_time_cycles = 2                 # project key: cycles from a set-point to its position
//!                                      # read back, 1 ..= 16 (default: the link's, 2)
//! list = "x_axis.lis"                  # project key (also in [channel] / [manual]): an ISG
//!                                      # parameter-list file, relative to this file, applied
//!                                      # before the table's own keys
//! kenngr.swe_neg = -2000000            # dotted keys are flattened back to the name path
//! "P-AXIS-00178" = 2000000
//! [[terminal]]                         # an EtherCAT SubDevice that is not an axis; the [[axis]]
//!                                      # and [[terminal]] tables list the SubDevices in ring order
//! name = "ENC"                         # required: a letter, then letters, digits, '_' (≤ 32)
//! esi = "fieldprobe-el5101"            # required: a built-in ESI (esi/*.xml) or an ESI file
//!                                      # relative to this file
//! count = 4                            # optional, 1 ..= 1024: ENC1 … ENC4 in a row
//! probe_axis = "Z"                     # optional, a timestamp input (EL1252 kind) only: the
//!                                      # probe of this axis is wired to the terminal; the
//!                                      # axis's PLC and PLC_TIMESTAMP read it (seed 004 §7.5)
//! probe_channel = 1                    # optional, 1 ..= 2 (default 1): the terminal input
//! [can]
//! bitrate = 500000                     # project key: CAN bit rate, bit/s ("500k", "1M"): one of
//!                                      # the CiA 301 rates (default 1M); the CANopen links
//!                                      # check the bus load against it
//! ```
//!
//! Values are TOML integers, booleans or strings in the seeds' units; each one goes through
//! [`ParamSet::set`], so every error names the file, the line and the key.

use std::path::Path;

use toml_edit::{ImDocument, Item, Table, TableLike, Value};

use super::registry::{
    edit_distance, find, parse_int, strip_quotes, unknown_parameter, Origin, ParamError, ParamSet,
    Scope,
};

/// Default interpolation cycle in µs.
pub const DEFAULT_CYCLE_TIME_US: u32 = 1000;
/// Smallest accepted interpolation cycle in µs.
pub const MIN_CYCLE_TIME_US: u32 = 100;
/// Largest accepted interpolation cycle in µs.
pub const MAX_CYCLE_TIME_US: u32 = 100_000;
/// Default in-position window of an axis (0.1 µm units: 1 µm).
pub const DEFAULT_IN_POSITION_WINDOW: u32 = 10;
/// Default time an exact stop waits for the in-position windows, ms.
pub const DEFAULT_IN_POSITION_TIMEOUT_MS: u32 = 1000;
/// Default of `max_lost_cycles`.
pub const DEFAULT_MAX_LOST_CYCLES: u32 = 3;
/// Largest dead time (cycles) an axis may declare.
pub const MAX_DEAD_TIME_CYCLES: u32 = 16;
/// Default drive definition (`drives/cia402-generic.toml`).
pub const DEFAULT_DRIVE: &str = "cia402-generic";
/// The bit rates of CiA 301 (§7.1.1 "bit timing": 1 Mbit/s, 800, 500, 250, 125, 50, 20 and
/// 10 kbit/s), the values `[can] bitrate` accepts, bit/s.
pub const CAN_BITRATES: [u32; 8] = [
    10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000,
];
/// Default `[can] bitrate`: 1 Mbit/s.
pub const DEFAULT_CAN_BITRATE: u32 = 1_000_000;

const AXIS_LETTERS: &str = "XYZABCUVW";
const MAX_DEPTH: usize = 16;

/// One axis of the machine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AxisConfig {
    /// Axis name: one of X Y Z A B C U V W, optionally followed by digits (`X2`).
    pub name: String,
    /// Name of the drive definition in `drives/` (without `.toml`).
    pub drive: String,
    /// Whether the axis is referenced at start (software limit switches are active only on
    /// referenced axes, FCT-A2 §1).
    pub referenced: bool,
    /// CANopen node id (1 ..= 127) of the axis's drive on a CAN link; `None`: the axis number
    /// (1-based position in the file).
    pub node: Option<u8>,
    /// Cycles between sending a set-point and reading the position it produced (project key
    /// `dead_time_cycles`, 1 ..= 16); `None`: the link's (2 on every link fieldprobe has).
    pub dead_time_cycles: Option<u32>,
    /// In-position window for exact stops, 0.1 µm / 0.0001° (project key
    /// `in_position_window`, 1 ..= 10000000; default [`DEFAULT_IN_POSITION_WINDOW`] = 1 µm).
    pub in_position_window: u32,
    /// The axis parameter list (P-AXIS-*).
    pub params: ParamSet,
}

/// Tool data of one tool offset number (`D<n>`), in mm (the file keeps 0.1 µm, as the ISG
/// tool list P-TOOL-00004 `wz[i].radius` does).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ToolData {
    /// Tool radius — for a measuring probe the ball radius (FCT-C4 §5, P-CHAN-00311).
    pub radius: f64,
    /// Tool length along the tool axis (Z in G17).
    pub length: f64,
}

/// One SubDevice of the machine that is not an axis (`[[terminal]]`): an I/O terminal on the
/// EtherCAT segment, found by the identity of its ESI device in ring order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TerminalConfig {
    /// Its name (`count` > 1: the table's name with the number appended, `ENC1`).
    pub name: String,
    /// The ESI: a built-in name (`fieldprobe-el5101`) or a file, relative to the machine file.
    pub esi: String,
    /// Line of its `[[terminal]]` table.
    pub line: usize,
    /// Axes declared above it in the file: in the ring it stands after their drives (the file
    /// lists the SubDevices in ring order).
    pub after_axes: usize,
    /// `probe_axis` / `probe_channel`: the axis whose probe is wired to input channel
    /// (1 or 2) of this timestamp input terminal (seed 004 §7.5, FCT-C4 PLC_TIMESTAMP).
    pub probe: Option<TerminalProbeWiring>,
}

/// An axis's probe wired to a timestamp input terminal (`[[terminal]] probe_axis`,
/// `probe_channel`): the terminal's input level and latched DC timestamps of that channel feed
/// the axis's PLC interface (`probing_signal`, `timestamp`), as the PLC program of FCT-C4 §7.5
/// links "Input" and "LatchPos2".
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TerminalProbeWiring {
    /// The axis name (`Z`).
    pub axis: String,
    /// The terminal's input channel, 1 or 2.
    pub channel: u8,
    /// Line of the `probe_axis` key.
    pub line: usize,
}

/// Highest `probe_channel` (an EL1252 has two inputs).
pub const MAX_PROBE_CHANNEL: u8 = 2;

/// Most terminals a machine file may declare (counts expanded), the emulated segment's cap.
pub const MAX_TERMINALS: usize = crate::limits::MAX_SEGMENT_DEVICES;

/// A machine: channel, manual mode and axes, with their parameter lists.
#[derive(Debug, Clone, PartialEq)]
pub struct MachineConfig {
    /// Where the configuration came from (file name, or `<default>`).
    pub source: String,
    /// Interpolation cycle in µs.
    pub cycle_time_us: u32,
    /// How long an exact stop may wait for the axes to come inside their in-position windows,
    /// ms (project key `in_position_timeout_ms`, 1 ..= 600000; default
    /// [`DEFAULT_IN_POSITION_TIMEOUT_MS`]).
    pub in_position_timeout_ms: u32,
    /// Consecutive lost process-data exchanges the channel rides through before error 900012
    /// (project key `max_lost_cycles`, 0 ..= 1000; default [`DEFAULT_MAX_LOST_CYCLES`]).
    pub max_lost_cycles: u32,
    /// The CAN bus's bit rate, bit/s (`[can] bitrate`, one of `CAN_BITRATES`; default
    /// `DEFAULT_CAN_BITRATE`): the CANopen links check the bus load against it.
    pub can_bitrate: u32,
    /// Channel parameter list (P-CHAN-*).
    pub channel: ParamSet,
    /// Manual-mode parameter list (P-MANU-*).
    pub manual: ParamSet,
    /// The axes in file order.
    pub axes: Vec<AxisConfig>,
    /// The SubDevices that are not axes, in file (= ring) order, counts expanded.
    pub terminals: Vec<TerminalConfig>,
    /// Tool data by D number (`[tool.1] radius = 20000  # 0.1 µm`).
    pub tools: std::collections::BTreeMap<u32, ToolData>,
    /// Zero offsets G54 … G59 by G number, per axis name, in mm
    /// (`[zero_offset.G54] X = 1000000  # 0.1 µm`).
    pub zero_offsets: std::collections::BTreeMap<u32, Vec<(String, f64)>>,
}

impl MachineConfig {
    /// Parse a machine file. `file` is used in error messages.
    pub fn parse(text: &str, file: &str) -> Result<Self, ParamError> {
        let ctx = Ctx::new(text, file);
        let doc = ImDocument::parse(text).map_err(|e| ParamError::Toml {
            origin: ctx.origin(e.span().map(|s| s.start)),
            message: e.message().trim().to_string(),
        })?;
        let root = doc.as_table();
        let mut cfg = MachineConfig {
            source: file.to_string(),
            cycle_time_us: DEFAULT_CYCLE_TIME_US,
            in_position_timeout_ms: DEFAULT_IN_POSITION_TIMEOUT_MS,
            max_lost_cycles: DEFAULT_MAX_LOST_CYCLES,
            can_bitrate: DEFAULT_CAN_BITRATE,
            channel: ParamSet::new(Scope::Channel),
            manual: ParamSet::new(Scope::Manual),
            axes: Vec::new(),
            terminals: Vec::new(),
            tools: Default::default(),
            zero_offsets: Default::default(),
        };
        let mut axis_lines: Vec<usize> = Vec::new();
        let mut zero_items = Vec::new();
        for (name, item) in root.iter() {
            let line = ctx.key_line(root, name, item, 0);
            match name {
                "channel" | "manual" => {
                    let table = item.as_table_like().ok_or_else(|| ParamError::Config {
                        origin: ctx.at(line),
                        message: format!("'{name}' must be a table: write [{name}]"),
                    })?;
                    let mut leaves = Vec::new();
                    flatten(&ctx, table, "", line, 0, &mut leaves)?;
                    if name == "channel" {
                        cfg.parse_channel(&ctx, &leaves)?;
                    } else {
                        check_duplicate_params(&leaves, &ctx, "[manual]", &["list"])?;
                        for leaf in leaves.iter().filter(|l| l.key == "list") {
                            apply_list_leaf(&mut cfg.manual, leaf, &ctx)?;
                        }
                        for leaf in leaves.iter().filter(|l| l.key != "list") {
                            set_leaf(&mut cfg.manual, leaf, &ctx, &["list"])?;
                        }
                        cfg.manual.check_cross(&ctx.at(line))?;
                    }
                }
                "axis" => {
                    let tables = item
                        .as_array_of_tables()
                        .ok_or_else(|| ParamError::Config {
                            origin: ctx.at(line),
                            message:
                                "'axis' must be an array of tables: write [[axis]] once per axis"
                                    .to_string(),
                        })?;
                    for table in tables.iter() {
                        cfg.parse_axis(&ctx, table, line, &mut axis_lines)?;
                    }
                }
                "terminal" => {
                    let tables = item
                        .as_array_of_tables()
                        .ok_or_else(|| ParamError::Config {
                            origin: ctx.at(line),
                            message: "'terminal' must be an array of tables: write [[terminal]] once per terminal (or with count = N)"
                                .to_string(),
                        })?;
                    for table in tables.iter() {
                        cfg.parse_terminal(&ctx, table, line)?;
                    }
                }
                "tool" => cfg.parse_tools(&ctx, item, line)?,
                "can" => cfg.parse_can(&ctx, item, line)?,
                "zero_offset" => zero_items.push((item, line)),
                other => return Err(outside_error(other, item, ctx.at(line))),
            }
        }
        for (item, line) in zero_items {
            cfg.parse_zero_offsets(&ctx, item, line)?;
        }
        // Ring order: a terminal stands after the axes whose tables are above it in the file.
        for t in &mut cfg.terminals {
            t.after_axes = axis_lines.iter().filter(|&&l| l < t.line).count();
        }
        if cfg.axes.is_empty() {
            return Err(ParamError::Config {
                origin: Origin::new(file, 0),
                message: "no [[axis]] table; a machine needs at least one axis (name = \"X\")"
                    .to_string(),
            });
        }
        // A probe wired to a terminal names an axis of the machine, at most one terminal each.
        for (k, t) in cfg.terminals.iter().enumerate() {
            let Some(w) = &t.probe else { continue };
            if !cfg.axes.iter().any(|a| a.name == w.axis) {
                let names: Vec<&str> = cfg.axes.iter().map(|a| a.name.as_str()).collect();
                return Err(ParamError::Config {
                    origin: Origin::new(file, w.line),
                    message: format!(
                        "[[terminal]] {}: probe_axis = \"{}\" is not an axis of the machine; the axes are {}",
                        t.name,
                        w.axis,
                        names.join(", ")
                    ),
                });
            }
            if let Some(first) = cfg.terminals[..k]
                .iter()
                .find(|o| o.probe.as_ref().is_some_and(|p| p.axis == w.axis))
            {
                return Err(ParamError::Config {
                    origin: Origin::new(file, w.line),
                    message: format!(
                        "[[terminal]] {}: the probe of axis {} is already wired to terminal {} (line {}); an axis has one probe input",
                        t.name, w.axis, first.name, first.line
                    ),
                });
            }
        }
        Ok(cfg)
    }

    /// Read and parse a machine file. A read error names the file.
    pub fn load(path: &Path) -> Result<Self, ParamError> {
        let file = path.display().to_string();
        let text =
            crate::limits::read_text(path, "machine file", crate::limits::MAX_MACHINE_FILE_BYTES)
                .map_err(|e| ParamError::Io {
                file: file.clone(),
                message: e.to_string(),
            })?;
        Self::parse(&text, &file)
    }

    /// The default machine: linear axes X, Y, Z, referenced, on `cia402-generic`
    /// drives, parameters at the seeds' defaults plus, per axis, `kenngr.messachse 1`,
    /// `kenngr.measure.signal DRIVE`, `kenngr.measure.input 1`, `kenngr.measure.edge POS`.
    pub fn default_machine() -> Self {
        let origin = Origin::new("<default>", 0);
        let axes = ["X", "Y", "Z"]
            .into_iter()
            .map(|name| {
                let mut params = ParamSet::new(Scope::Axis);
                params.set_label(format!("axis {name}"));
                for (key, value) in [
                    ("kenngr.messachse", "1"),
                    ("kenngr.measure.signal", "DRIVE"),
                    ("kenngr.measure.input", "1"),
                    ("kenngr.measure.edge", "POS"),
                ] {
                    let result = params.set(key, value, &origin);
                    debug_assert!(result.is_ok(), "default machine: {result:?}");
                }
                AxisConfig {
                    name: name.to_string(),
                    drive: DEFAULT_DRIVE.to_string(),
                    referenced: true,
                    node: None,
                    dead_time_cycles: None,
                    in_position_window: DEFAULT_IN_POSITION_WINDOW,
                    params,
                }
            })
            .collect();
        MachineConfig {
            source: "<default>".to_string(),
            cycle_time_us: DEFAULT_CYCLE_TIME_US,
            in_position_timeout_ms: DEFAULT_IN_POSITION_TIMEOUT_MS,
            max_lost_cycles: DEFAULT_MAX_LOST_CYCLES,
            can_bitrate: DEFAULT_CAN_BITRATE,
            channel: ParamSet::new(Scope::Channel),
            manual: ParamSet::new(Scope::Manual),
            axes,
            terminals: Vec::new(),
            // D1: the measuring probe of FCT-C4 §5 "%meas_example" (ball radius 2 mm).
            tools: [(
                1,
                ToolData {
                    radius: 2.0,
                    length: 0.0,
                },
            )]
            .into_iter()
            .collect(),
            zero_offsets: Default::default(),
        }
    }

    /// Apply one `--set KEY=VALUE`: `P-CHAN-00498=1`, `range_check_prog_soft_limits=1`,
    /// `P-MANU-00014=1`, `X.P-AXIS-00178=2000000`, `Z.kenngr.measure.signal=PLC`,
    /// `cycle_time_us=500`, `X.referenced=false`, `X.drive=NAME`. Keys without an axis prefix go
    /// to the channel or manual list by the parameter's scope; axis parameters need the prefix.
    /// The cross checks are re-run; on error nothing changes. Several assignments that only
    /// together satisfy a cross check go through [`MachineConfig::apply_sets`].
    pub fn apply_set(&mut self, assignment: &str) -> Result<(), ParamError> {
        self.apply_sets(&[assignment])
    }

    /// Apply every `--set` of a command line, then run the cross checks (e.g. P-AXIS-00177 <
    /// P-AXIS-00178, P-AXIS-00215 ≤ P-AXIS-00212) once on the result, so that the order of the
    /// assignments does not matter: `X.P-AXIS-00177=2500000 X.P-AXIS-00178=3000000` moves the
    /// whole range of X in either order. Each value is still checked against its own data range
    /// as it is applied. On error nothing changes.
    pub fn apply_sets<S: AsRef<str>>(&mut self, assignments: &[S]) -> Result<(), ParamError> {
        let mut changed = self.clone();
        for a in assignments {
            changed.assign(a.as_ref())?;
        }
        let origin = Origin::new("--set", 0);
        changed.channel.check_cross(&origin)?;
        changed.manual.check_cross(&origin)?;
        for axis in &changed.axes {
            axis.params.check_cross(&origin)?;
        }
        *self = changed;
        Ok(())
    }

    /// One assignment of [`MachineConfig::apply_sets`], without the cross checks.
    fn assign(&mut self, assignment: &str) -> Result<(), ParamError> {
        let origin = Origin::new("--set", 0);
        let Some((key, value)) = assignment
            .split_once('=')
            .filter(|(k, _)| !k.trim().is_empty())
        else {
            return Err(ParamError::Config {
                origin,
                message: format!(
                    "'{assignment}': expected KEY=VALUE, e.g. 'X.P-AXIS-00178=2000000'"
                ),
            });
        };
        let (key, value) = (key.trim(), value.trim());
        if let Some((prefix, rest)) = key.split_once('.') {
            if let Some(axis) = self
                .axes
                .iter_mut()
                .find(|a| a.name.eq_ignore_ascii_case(prefix))
            {
                return axis.apply(rest, value, &origin);
            }
        }
        if key == "cycle_time_us" {
            self.cycle_time_us = cycle_time(value, &origin)?;
            return Ok(());
        }
        if key == "can.bitrate" || key == "bitrate" {
            self.can_bitrate = can_bitrate(value, &origin)?;
            return Ok(());
        }
        if key == "in_position_timeout_ms" {
            self.in_position_timeout_ms = project_int(value, key, 1, 600_000, "ms", &origin)?;
            return Ok(());
        }
        if key == "max_lost_cycles" {
            self.max_lost_cycles = project_int(value, key, 0, 1000, "cycles", &origin)?;
            return Ok(());
        }
        if let Some(def) = find(key) {
            let set = match def.scope {
                Scope::Channel => &mut self.channel,
                Scope::Manual => &mut self.manual,
                Scope::Axis => {
                    let first = self.axes.first().map_or("X", |a| a.name.as_str());
                    return Err(ParamError::MissingAxisPrefix {
                        origin,
                        def,
                        example: format!("{first}.{key}={value}"),
                        axes: self.axis_list(),
                    });
                }
            };
            return set.set(key, value, &origin).map(|_| ());
        }
        if let Some((prefix, _)) = key.split_once('.') {
            if looks_like_axis_prefix(prefix) {
                return Err(ParamError::UnknownAxis {
                    origin,
                    axis: prefix.to_string(),
                    assignment: assignment.to_string(),
                    axes: self.axis_list(),
                });
            }
        }
        Err(unknown_parameter(key, &origin))
    }

    /// CANopen node id per axis: its `node` key, else its axis number (1, 2, …). Two axes
    /// with the same id, or more than 127 axes without ids, are an error naming the axes.
    pub fn node_ids(&self) -> Result<Vec<u8>, String> {
        let mut ids: Vec<u8> = Vec::with_capacity(self.axes.len());
        for (i, a) in self.axes.iter().enumerate() {
            let id = match a.node {
                Some(n) => n,
                None => u8::try_from(i + 1)
                    .ok()
                    .filter(|n| *n <= 127)
                    .ok_or_else(|| {
                        format!(
                            "axis {}: no 'node' key and axis number {} > 127",
                            a.name,
                            i + 1
                        )
                    })?,
            };
            if let Some(j) = ids.iter().position(|x| *x == id) {
                return Err(format!(
                    "axes {} and {} both have CANopen node id {id} (set 'node' in the machine file)",
                    self.axes[j].name, a.name
                ));
            }
            ids.push(id);
        }
        Ok(ids)
    }

    /// The axis with this name.
    pub fn axis(&self, name: &str) -> Option<&AxisConfig> {
        self.axes.iter().find(|a| a.name == name)
    }

    /// The axis with this name, mutable.
    pub fn axis_mut(&mut self, name: &str) -> Option<&mut AxisConfig> {
        self.axes.iter_mut().find(|a| a.name == name)
    }

    /// The axis names, comma separated (`X, Y, Z`).
    pub fn axis_list(&self) -> String {
        self.axes
            .iter()
            .map(|a| a.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    fn parse_terminal(
        &mut self,
        ctx: &Ctx<'_>,
        table: &Table,
        fallback_line: usize,
    ) -> Result<(), ParamError> {
        let header = ctx
            .line(table.span().map(|s| s.start))
            .unwrap_or(fallback_line);
        let (mut name, mut esi, mut count) = (None, None, 1usize);
        let (mut probe_axis, mut probe_channel): (Option<(String, usize)>, Option<u8>) =
            (None, None);
        for (key, item) in table.iter() {
            let origin = ctx.at(ctx.key_line(table, key, item, header));
            let text = item.as_str();
            match key {
                "name" => {
                    let n = text.filter(|n| valid_terminal_name(n)).ok_or_else(|| {
                        ParamError::Config {
                            origin: origin.clone(),
                            message: "[[terminal]] name: expected a string of a letter, then letters, digits or '_' (at most 32), e.g. name = \"ENC\"".to_string(),
                        }
                    })?;
                    name = Some(n.to_string());
                }
                "esi" => {
                    let e = text.filter(|e| !e.trim().is_empty()).ok_or_else(|| {
                        ParamError::Config {
                            origin: origin.clone(),
                            message: "[[terminal]] esi: expected a string, a built-in ESI (fieldprobe-ek1100, fieldprobe-el1252, fieldprobe-el5101) or an ESI file".to_string(),
                        }
                    })?;
                    esi = Some(e.to_string());
                }
                "count" => {
                    let raw = item.as_integer().map_or(String::new(), |i| i.to_string());
                    count =
                        project_int(&raw, "count", 1, MAX_TERMINALS as u32, "terminals", &origin)?
                            as usize;
                }
                "probe_axis" => {
                    let a = text.filter(|a| !a.trim().is_empty()).ok_or_else(|| {
                        ParamError::Config {
                            origin: origin.clone(),
                            message: "[[terminal]] probe_axis: expected the name of an axis whose probe is wired to this timestamp input, e.g. probe_axis = \"Z\"".to_string(),
                        }
                    })?;
                    probe_axis = Some((a.to_string(), origin.line));
                }
                "probe_channel" => {
                    let raw = item.as_integer().map_or(String::new(), |i| i.to_string());
                    probe_channel = Some(project_int(
                        &raw,
                        "probe_channel",
                        1,
                        u32::from(MAX_PROBE_CHANNEL),
                        "terminal input channel",
                        &origin,
                    )? as u8);
                }
                other => {
                    return Err(ParamError::Config {
                        origin,
                        message: format!(
                            "unknown key '{other}' in [[terminal]]; allowed: name, esi, count, probe_axis, probe_channel"
                        ),
                    })
                }
            }
        }
        let missing = |what: &str| {
            ParamError::Config {
            origin: ctx.at(header),
            message: format!("[[terminal]] without {what}; expected e.g. name = \"ENC\", esi = \"fieldprobe-el5101\""),
        }
        };
        let name = name.ok_or_else(|| missing("a name"))?;
        let esi = esi.ok_or_else(|| missing("an esi"))?;
        if probe_channel.is_some() && probe_axis.is_none() {
            return Err(ParamError::Config {
                origin: ctx.at(header),
                message: format!(
                    "[[terminal]] {name}: probe_channel without probe_axis; name the axis whose probe is wired to the channel, e.g. probe_axis = \"Z\""
                ),
            });
        }
        if probe_axis.is_some() && count != 1 {
            return Err(ParamError::Config {
                origin: ctx.at(header),
                message: format!(
                    "[[terminal]] {name}: probe_axis wires one terminal; write a [[terminal]] of its own (without count) for the timestamp input that carries the probe"
                ),
            });
        }
        let probe = probe_axis.map(|(axis, line)| TerminalProbeWiring {
            axis,
            channel: probe_channel.unwrap_or(1),
            line,
        });
        if self.terminals.len() + count > MAX_TERMINALS {
            return Err(ParamError::Config {
                origin: ctx.at(header),
                message: format!(
                    "[[terminal]] {name}: more than {MAX_TERMINALS} terminals in the machine"
                ),
            });
        }
        for k in 1..=count {
            let n = if count == 1 {
                name.clone()
            } else {
                format!("{name}{k}")
            };
            if let Some(t) = self.terminals.iter().find(|t| t.name == n) {
                return Err(ParamError::Config {
                    origin: ctx.at(header),
                    message: format!(
                        "duplicate terminal name '{n}' (first defined at line {})",
                        t.line
                    ),
                });
            }
            self.terminals.push(TerminalConfig {
                name: n,
                esi: esi.clone(),
                line: header,
                after_axes: 0,
                probe: probe.clone(),
            });
        }
        Ok(())
    }

    /// The terminal with this name.
    pub fn terminal(&self, name: &str) -> Option<&TerminalConfig> {
        self.terminals.iter().find(|t| t.name == name)
    }

    /// `[can]`: `bitrate` (module documentation).
    fn parse_can(&mut self, ctx: &Ctx<'_>, item: &Item, line: usize) -> Result<(), ParamError> {
        let table = item.as_table_like().ok_or_else(|| ParamError::Config {
            origin: ctx.at(line),
            message: "'can' must be a table: write [can] bitrate = 500000".to_string(),
        })?;
        for (k, v) in table.iter() {
            let kl = ctx.key_line(table, k, v, line);
            match k {
                "bitrate" => {
                    let raw = match v.as_value() {
                        Some(Value::Integer(i)) => i.value().to_string(),
                        Some(Value::String(t)) => t.value().clone(),
                        _ => String::new(),
                    };
                    self.can_bitrate = can_bitrate(&raw, &ctx.at(kl))?;
                }
                other => {
                    let hint = if edit_distance(other, "bitrate") <= 2 {
                        " (did you mean bitrate?)"
                    } else {
                        ""
                    };
                    return Err(ParamError::Config {
                        origin: ctx.at(kl),
                        message: format!("unknown key '{other}' in [can]{hint}; allowed: bitrate"),
                    });
                }
            }
        }
        Ok(())
    }

    fn parse_tools(&mut self, ctx: &Ctx<'_>, item: &Item, line: usize) -> Result<(), ParamError> {
        let table = item.as_table_like().ok_or_else(|| ParamError::Config {
            origin: ctx.at(line),
            message: "'tool' must be a table of tools: write [tool.1] radius = 20000".to_string(),
        })?;
        for (d, t) in table.iter() {
            let l = ctx.key_line(table, d, t, line);
            let number: u32 = d
                .parse()
                .ok()
                .filter(|n| (1..=32767).contains(n))
                .ok_or_else(|| ParamError::Config {
                    origin: ctx.at(l),
                    message: format!(
                        "[tool.{d}]: the tool offset number must be 1 ..= 32767 (D1 → [tool.1])"
                    ),
                })?;
            let fields = t.as_table_like().ok_or_else(|| ParamError::Config {
                origin: ctx.at(l),
                message: format!("[tool.{d}] must be a table with radius / length in 0.1 µm"),
            })?;
            let mut tool = ToolData::default();
            for (k, v) in fields.iter() {
                let kl = ctx.key_line(fields, k, v, l);
                let value = v.as_integer().ok_or_else(|| ParamError::Config {
                    origin: ctx.at(kl),
                    message: format!(
                        "tool.{d}.{k}: expected an integer in 0.1 µm (P-TOOL-00004 unit)"
                    ),
                })?;
                if !(i64::from(i32::MIN)..=i64::from(i32::MAX)).contains(&value) {
                    return Err(ParamError::Config {
                        origin: ctx.at(kl),
                        message: format!("tool.{d}.{k} = {value} is out of range: MIN(SGN32) ≤ value ≤ MAX(SGN32)"),
                    });
                }
                match k {
                    "radius" if value >= 0 => tool.radius = crate::units::param_pos_to_mm(value),
                    "radius" => {
                        return Err(ParamError::Config {
                            origin: ctx.at(kl),
                            message: format!(
                                "tool.{d}.radius = {value}: a probe ball radius must be ≥ 0"
                            ),
                        })
                    }
                    "length" => tool.length = crate::units::param_pos_to_mm(value),
                    other => {
                        return Err(ParamError::Config {
                            origin: ctx.at(kl),
                            message: format!(
                                "unknown tool field '{other}'; allowed: radius, length"
                            ),
                        })
                    }
                }
            }
            self.tools.insert(number, tool);
        }
        Ok(())
    }

    fn parse_zero_offsets(
        &mut self,
        ctx: &Ctx<'_>,
        item: &Item,
        line: usize,
    ) -> Result<(), ParamError> {
        let table = item.as_table_like().ok_or_else(|| ParamError::Config {
            origin: ctx.at(line),
            message: "'zero_offset' must be a table: write [zero_offset.G54] X = 1000000"
                .to_string(),
        })?;
        for (g, t) in table.iter() {
            let l = ctx.key_line(table, g, t, line);
            let number: u32 = g
                .strip_prefix(['G', 'g'])
                .and_then(|n| n.parse().ok())
                .filter(|n| (54..=59).contains(n))
                .ok_or_else(|| ParamError::Config {
                    origin: ctx.at(l),
                    message: format!("[zero_offset.{g}]: expected G54 … G59"),
                })?;
            let fields = t.as_table_like().ok_or_else(|| ParamError::Config {
                origin: ctx.at(l),
                message: format!("[zero_offset.{g}] must be a table of axis = offset (0.1 µm)"),
            })?;
            let mut offsets = Vec::new();
            for (ax, v) in fields.iter() {
                let kl = ctx.key_line(fields, ax, v, l);
                if self.axis(ax).is_none() {
                    return Err(ParamError::Config {
                        origin: ctx.at(kl),
                        message: format!(
                            "zero_offset.{g}.{ax}: unknown axis; the machine has {}",
                            self.axis_list()
                        ),
                    });
                }
                let value = v.as_integer().filter(|x| (i64::from(i32::MIN)..=i64::from(i32::MAX)).contains(x)).ok_or_else(|| {
                    ParamError::Config {
                        origin: ctx.at(kl),
                        message: format!("zero_offset.{g}.{ax}: expected an integer in 0.1 µm, MIN(SGN32) ≤ value ≤ MAX(SGN32)"),
                    }
                })?;
                offsets.push((ax.to_string(), crate::units::param_pos_to_mm(value)));
            }
            self.zero_offsets.insert(number, offsets);
        }
        Ok(())
    }

    fn parse_channel(&mut self, ctx: &Ctx<'_>, leaves: &[Leaf<'_>]) -> Result<(), ParamError> {
        check_duplicate_params(
            leaves,
            ctx,
            "[channel]",
            &[
                "cycle_time_us",
                "in_position_timeout_ms",
                "max_lost_cycles",
                "list",
            ],
        )?;
        for leaf in leaves.iter().filter(|l| l.key == "list") {
            apply_list_leaf(&mut self.channel, leaf, ctx)?;
        }
        for leaf in leaves {
            if leaf.key == "list" {
                continue;
            }
            if leaf.key == "cycle_time_us" {
                let origin = ctx.at(leaf.line);
                let raw = match leaf.value {
                    Value::Integer(i) => i.value().to_string(),
                    _ => {
                        return Err(ParamError::Config {
                            origin,
                            message: cycle_time_expectation(),
                        })
                    }
                };
                self.cycle_time_us = cycle_time(&raw, &origin)?;
            } else if leaf.key == "in_position_timeout_ms" {
                let raw = int_text(leaf);
                self.in_position_timeout_ms =
                    project_int(&raw, &leaf.key, 1, 600_000, "ms", &ctx.at(leaf.line))?;
            } else if leaf.key == "max_lost_cycles" {
                let raw = int_text(leaf);
                self.max_lost_cycles =
                    project_int(&raw, &leaf.key, 0, 1000, "cycles", &ctx.at(leaf.line))?;
            } else {
                set_leaf(
                    &mut self.channel,
                    leaf,
                    ctx,
                    &[
                        "cycle_time_us",
                        "in_position_timeout_ms",
                        "max_lost_cycles",
                        "list",
                    ],
                )?;
            }
        }
        self.channel.check_cross(&ctx.at(0))
    }

    fn parse_axis(
        &mut self,
        ctx: &Ctx<'_>,
        table: &Table,
        fallback_line: usize,
        axis_lines: &mut Vec<usize>,
    ) -> Result<(), ParamError> {
        let header = ctx
            .line(table.span().map(|s| s.start))
            .unwrap_or(fallback_line);
        let mut leaves = Vec::new();
        flatten(ctx, table, "", header, 0, &mut leaves)?;
        let mut name: Option<(String, usize)> = None;
        let mut drive = DEFAULT_DRIVE.to_string();
        let mut referenced = true;
        let mut node = None;
        let mut dead_time_cycles = None;
        let mut in_position_window = DEFAULT_IN_POSITION_WINDOW;
        let mut params = ParamSet::new(Scope::Axis);
        let label = leaves
            .iter()
            .find(|l| l.key == "name")
            .and_then(|l| l.value.as_str())
            .map_or_else(
                || format!("[[axis]] at line {header}"),
                |n| format!("axis {n}"),
            );
        check_duplicate_params(&leaves, ctx, &label, AXIS_PROJECT_KEYS)?;
        for leaf in leaves.iter().filter(|l| l.key == "list") {
            apply_list_leaf(&mut params, leaf, ctx)?;
        }
        for leaf in &leaves {
            let origin = ctx.at(leaf.line);
            match leaf.key.as_str() {
                "list" => {}
                "name" => {
                    let n = string_value(leaf, &origin, "an axis name such as \"X\"")?;
                    if !valid_axis_name(n) {
                        return Err(ParamError::Config {
                            origin,
                            message: format!(
                                "invalid axis name '{n}'; expected one of X Y Z A B C U V W, optionally followed by digits (e.g. \"X2\")"
                            ),
                        });
                    }
                    if let Some(i) = self.axes.iter().position(|a| a.name == n) {
                        return Err(ParamError::Config {
                            origin,
                            message: format!(
                                "duplicate axis name '{n}' (first defined at line {})",
                                axis_lines[i]
                            ),
                        });
                    }
                    name = Some((n.to_string(), leaf.line));
                }
                "drive" => {
                    let d = string_value(
                        leaf,
                        &origin,
                        "a drive definition name such as \"cia402-generic\"",
                    )?;
                    drive = valid_drive(d, &origin)?;
                }
                "referenced" => match leaf.value {
                    Value::Boolean(b) => referenced = *b.value(),
                    _ => {
                        return Err(ParamError::Config {
                            origin,
                            message: "'referenced' must be true or false".to_string(),
                        })
                    }
                },
                "node" => {
                    let text = match leaf.value {
                        Value::Integer(i) => i.value().to_string(),
                        _ => String::new(),
                    };
                    node = Some(node_id(&text, &origin)?);
                }
                "dead_time_cycles" => {
                    dead_time_cycles = Some(dead_time(&int_text(leaf), &origin)?);
                }
                "in_position_window" => {
                    in_position_window = position_window(&int_text(leaf), &origin)?;
                }
                _ => set_leaf(&mut params, leaf, ctx, AXIS_PROJECT_KEYS)?,
            }
        }
        let Some((name, line)) = name else {
            return Err(ParamError::Config {
                origin: ctx.at(header),
                message: "[[axis]] without a name; expected e.g. name = \"X\"".to_string(),
            });
        };
        params.set_label(format!("axis {name}"));
        params.check_cross(&ctx.at(header))?;
        axis_lines.push(line);
        self.axes.push(AxisConfig {
            name,
            drive,
            referenced,
            node,
            dead_time_cycles,
            in_position_window,
            params,
        });
        Ok(())
    }
}

/// A CANopen node id `1 ..= 127` (project key `node`).
fn node_id(text: &str, origin: &Origin) -> Result<u8, ParamError> {
    text.trim()
        .parse::<u8>()
        .ok()
        .filter(|n| (1..=127).contains(n))
        .ok_or_else(|| ParamError::Config {
            origin: origin.clone(),
            message: format!(
                "'node' = {}: expected a CANopen node id, an integer 1 … 127",
                if text.is_empty() {
                    "(not an integer)"
                } else {
                    text
                }
            ),
        })
}

impl AxisConfig {
    fn apply(&mut self, key: &str, value: &str, origin: &Origin) -> Result<(), ParamError> {
        match key {
            "node" => {
                self.node = Some(node_id(strip_quotes(value), origin)?);
                Ok(())
            }
            "dead_time_cycles" => {
                self.dead_time_cycles = Some(dead_time(value, origin)?);
                Ok(())
            }
            "in_position_window" => {
                self.in_position_window = position_window(value, origin)?;
                Ok(())
            }
            "name" => Err(ParamError::Config {
                origin: origin.clone(),
                message: format!(
                    "the name of axis {} cannot be changed with --set",
                    self.name
                ),
            }),
            "drive" => {
                self.drive = valid_drive(strip_quotes(value), origin)?;
                Ok(())
            }
            "referenced" => {
                let v = strip_quotes(value);
                self.referenced = if v.eq_ignore_ascii_case("true") || v == "1" {
                    true
                } else if v.eq_ignore_ascii_case("false") || v == "0" {
                    false
                } else {
                    return Err(ParamError::Config {
                        origin: origin.clone(),
                        message: format!(
                            "{}.referenced = {value}: expected true/false or 1/0",
                            self.name
                        ),
                    });
                };
                Ok(())
            }
            // Cross checks: by the caller, after all assignments (`apply_sets`).
            _ => self.params.set(key, value, origin).map(|_| ()),
        }
    }
}

/// A flattened `key = value` with the dotted path rebuilt and its 1-based line.
struct Leaf<'a> {
    key: String,
    value: &'a Value,
    line: usize,
}

/// File name and line index of the text being parsed.
struct Ctx<'a> {
    file: &'a str,
    line_starts: Vec<usize>,
}

impl<'a> Ctx<'a> {
    fn new(text: &str, file: &'a str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(
            text.bytes()
                .enumerate()
                .filter(|(_, b)| *b == b'\n')
                .map(|(i, _)| i + 1),
        );
        Ctx { file, line_starts }
    }

    /// 1-based line of a byte offset.
    fn line(&self, offset: Option<usize>) -> Option<usize> {
        let offset = offset?;
        Some(match self.line_starts.binary_search(&offset) {
            Ok(i) => i + 1,
            Err(i) => i,
        })
    }

    fn at(&self, line: usize) -> Origin {
        Origin::new(self.file, line)
    }

    fn origin(&self, offset: Option<usize>) -> Origin {
        self.at(self.line(offset).unwrap_or(0))
    }

    fn key_line(&self, table: &dyn TableLike, key: &str, item: &Item, fallback: usize) -> usize {
        let span = table
            .get_key_value(key)
            .and_then(|(k, _)| k.span())
            .or_else(|| item.span());
        self.line(span.map(|s| s.start)).unwrap_or(fallback)
    }
}

/// Flatten nested tables (dotted keys, `[axis.kenngr]` sub-tables, inline tables) into leaves
/// whose keys are the ISG name paths.
fn flatten<'a>(
    ctx: &Ctx<'_>,
    table: &'a dyn TableLike,
    prefix: &str,
    fallback_line: usize,
    depth: usize,
    out: &mut Vec<Leaf<'a>>,
) -> Result<(), ParamError> {
    for (key, item) in table.iter() {
        let line = ctx.key_line(table, key, item, fallback_line);
        let full = if prefix.is_empty() {
            key.to_string()
        } else {
            format!("{prefix}.{key}")
        };
        if depth >= MAX_DEPTH {
            return Err(ParamError::Config {
                origin: ctx.at(line),
                message: format!("'{full}' is nested too deeply to be a parameter path"),
            });
        }
        match item {
            Item::Value(Value::InlineTable(t)) => flatten(ctx, t, &full, line, depth + 1, out)?,
            Item::Value(value) => out.push(Leaf {
                key: full,
                value,
                line,
            }),
            Item::Table(t) => flatten(ctx, t, &full, line, depth + 1, out)?,
            Item::ArrayOfTables(_) => {
                return Err(ParamError::Config {
                    origin: ctx.at(line),
                    message: format!(
                        "'{full}' is an array of tables; only [[axis]] and [[terminal]] may be one"
                    ),
                })
            }
            Item::None => {}
        }
    }
    Ok(())
}

/// Set one leaf in a parameter list; `project_keys` are the section's non-parameter keys, used
/// for "did you mean" on typos.
/// `list = "FILE"`: apply an ISG parameter-list file (path relative to the machine file's
/// directory) to `set`. Errors in the list name the list file and its line.
fn apply_list_leaf(set: &mut ParamSet, leaf: &Leaf<'_>, ctx: &Ctx<'_>) -> Result<(), ParamError> {
    let origin = ctx.at(leaf.line);
    let rel = string_value(
        leaf,
        &origin,
        "a parameter-list file name such as \"x_axis.lis\"",
    )?;
    let base = std::path::Path::new(ctx.file)
        .parent()
        .unwrap_or(std::path::Path::new(""));
    let path = base.join(rel);
    let text = crate::limits::read_text(
        &path,
        "parameter list file",
        crate::limits::MAX_LIST_FILE_BYTES,
    )
    .map_err(|e| ParamError::Config {
        origin: origin.clone(),
        message: format!("list = \"{rel}\": cannot read {}: {e}", path.display()),
    })?;
    crate::params::listfile::apply_list(set, &text, &path.display().to_string())
}

/// One parameter set twice in one table through different keys (its ID and its name path, or
/// `[0]` and `[i]`): TOML itself refuses a repeated key, but both spellings would otherwise
/// reach the same parameter and the later one would silently win.
fn check_duplicate_params(
    leaves: &[Leaf<'_>],
    ctx: &Ctx<'_>,
    table: &str,
    project_keys: &[&str],
) -> Result<(), ParamError> {
    let mut seen: std::collections::HashMap<&str, &Leaf<'_>> = std::collections::HashMap::new();
    for leaf in leaves
        .iter()
        .filter(|l| !project_keys.contains(&l.key.as_str()))
    {
        let Some(def) = find(&leaf.key) else { continue };
        if let Some(first) = seen.insert(def.id, leaf) {
            return Err(ParamError::Config {
                origin: ctx.at(leaf.line),
                message: format!(
                    "{table}: parameter {} ({}) is set twice, as '{}' (line {}) and as '{}' \
                     (line {}); keep one",
                    def.id, def.path, first.key, first.line, leaf.key, leaf.line
                ),
            });
        }
    }
    Ok(())
}

fn set_leaf(
    set: &mut ParamSet,
    leaf: &Leaf<'_>,
    ctx: &Ctx<'_>,
    project_keys: &[&str],
) -> Result<(), ParamError> {
    let origin = ctx.at(leaf.line);
    if find(&leaf.key).is_none() {
        if let Some(k) = project_keys
            .iter()
            .find(|k| edit_distance(&leaf.key, k) <= 2)
        {
            return Err(ParamError::UnknownParameter {
                origin,
                key: leaf.key.clone(),
                suggestion: Some(format!("'{k}'")),
            });
        }
        return Err(unknown_parameter(&leaf.key, &origin));
    }
    let raw = match leaf.value {
        Value::Integer(i) => i.value().to_string(),
        Value::Boolean(b) => b.value().to_string(),
        Value::String(s) => s.value().clone(),
        Value::Float(f) => format!("{:?}", f.value()),
        Value::Datetime(d) => d.value().to_string(),
        Value::Array(_) | Value::InlineTable(_) => {
            return Err(ParamError::Config {
                origin,
                message: format!("{}: expected an integer, boolean or string", leaf.key),
            })
        }
    };
    set.set(&leaf.key, &raw, &origin).map(|_| ())
}

fn string_value<'a>(
    leaf: &Leaf<'a>,
    origin: &Origin,
    expected: &str,
) -> Result<&'a str, ParamError> {
    match leaf.value {
        Value::String(s) => Ok(s.value().as_str()),
        _ => Err(ParamError::Config {
            origin: origin.clone(),
            message: format!("'{}' must be a string: {expected}", leaf.key),
        }),
    }
}

fn outside_error(name: &str, item: &Item, origin: Origin) -> ParamError {
    let allowed = "allowed tables are [channel], [manual], [[axis]], [[terminal]], [tool.<D>], [zero_offset.G54…G59] and [can]";
    let message = if item.is_value() {
        let hint = if name == "cycle_time_us" {
            "; cycle_time_us belongs in [channel]".to_string()
        } else if name == "bitrate" {
            "; bitrate belongs in [can]".to_string()
        } else if let Some(def) = find(name) {
            format!("; {} belongs in {}", def.id, def.scope.section())
        } else {
            String::new()
        };
        format!("'{name}' is outside any table; {allowed}{hint}")
    } else {
        format!("unknown table [{name}]; {allowed}")
    };
    ParamError::Config { origin, message }
}

/// `[can] bitrate` / `--set can.bitrate=…`: bit/s as an integer or with a k / M suffix
/// (`500000`, `"500k"`, `"1M"`), one of [`CAN_BITRATES`]; the error names the key, the value
/// and the allowed rates.
fn can_bitrate(raw: &str, origin: &Origin) -> Result<u32, ParamError> {
    let text = strip_quotes(raw.trim()).trim();
    let (digits, factor) = match text.char_indices().last() {
        Some((i, 'k' | 'K')) => (&text[..i], 1_000u64),
        Some((i, 'M' | 'm')) => (&text[..i], 1_000_000),
        _ => (text, 1),
    };
    let bps = digits
        .trim()
        .parse::<u64>()
        .ok()
        .and_then(|v| v.checked_mul(factor))
        .and_then(|v| u32::try_from(v).ok());
    match bps {
        Some(v) if CAN_BITRATES.contains(&v) => Ok(v),
        _ => Err(ParamError::Config {
            origin: origin.clone(),
            message: format!(
                "bitrate = {}: not a CAN bit rate of CiA 301; allowed: 10k, 20k, 50k, 125k, 250k, 500k, 800k, 1M (bit/s, e.g. bitrate = 500000 or \"500k\" in [can])",
                if raw.trim().is_empty() { "(not a number)" } else { raw.trim() }
            ),
        }),
    }
}

/// Project keys of an `[[axis]]` table (not parameters).
const AXIS_PROJECT_KEYS: &[&str] = &[
    "name",
    "drive",
    "referenced",
    "node",
    "list",
    "dead_time_cycles",
    "in_position_window",
];

/// The text of an integer leaf (empty for other types, which the range check then refuses).
fn int_text(leaf: &Leaf<'_>) -> String {
    match leaf.value {
        Value::Integer(i) => i.value().to_string(),
        _ => String::new(),
    }
}

/// An integer project key in `lo ..= hi`; the error names the key, the value and the range.
fn project_int(
    raw: &str,
    key: &str,
    lo: u32,
    hi: u32,
    unit: &str,
    origin: &Origin,
) -> Result<u32, ParamError> {
    match parse_int(strip_quotes(raw)) {
        Some(v) if (i128::from(lo)..=i128::from(hi)).contains(&v) => {
            Ok(u32::try_from(v).unwrap_or(lo))
        }
        _ => Err(ParamError::Config {
            origin: origin.clone(),
            message: format!(
                "{key} = {}: expected an integer {lo} ..= {hi} ({unit})",
                if raw.is_empty() {
                    "(not an integer)"
                } else {
                    raw
                }
            ),
        }),
    }
}

fn dead_time(raw: &str, origin: &Origin) -> Result<u32, ParamError> {
    project_int(
        raw,
        "dead_time_cycles",
        1,
        MAX_DEAD_TIME_CYCLES,
        "cycles from sending a set-point to reading the position it produced",
        origin,
    )
}

fn position_window(raw: &str, origin: &Origin) -> Result<u32, ParamError> {
    project_int(
        raw,
        "in_position_window",
        1,
        10_000_000,
        "0.1 µm / 0.0001°",
        origin,
    )
}

fn cycle_time_expectation() -> String {
    format!("cycle_time_us must be an integer number of µs, {MIN_CYCLE_TIME_US} ..= {MAX_CYCLE_TIME_US}")
}

fn cycle_time(raw: &str, origin: &Origin) -> Result<u32, ParamError> {
    match parse_int(strip_quotes(raw)) {
        Some(v) if (i128::from(MIN_CYCLE_TIME_US)..=i128::from(MAX_CYCLE_TIME_US)).contains(&v) => {
            Ok(u32::try_from(v).unwrap_or(DEFAULT_CYCLE_TIME_US))
        }
        _ => Err(ParamError::Config {
            origin: origin.clone(),
            message: format!("cycle_time_us = {raw}: {}", cycle_time_expectation()),
        }),
    }
}

/// X Y Z A B C U V W, optionally followed by digits.
/// A terminal name: an ASCII letter, then letters, digits or '_', at most 32 characters.
fn valid_terminal_name(name: &str) -> bool {
    let mut b = name.bytes();
    name.len() <= 32
        && b.next().is_some_and(|c| c.is_ascii_alphabetic())
        && b.all(|c| c.is_ascii_alphanumeric() || c == b'_')
}

fn valid_axis_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| AXIS_LETTERS.contains(c)) && chars.all(|c| c.is_ascii_digit())
}

/// A letter followed by digits: meant as an axis prefix in `--set`.
fn looks_like_axis_prefix(prefix: &str) -> bool {
    let mut chars = prefix.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic()) && chars.all(|c| c.is_ascii_digit())
}

/// A drive value: a built-in / `drives/<name>.toml` name (letters, digits, '-', '_'), or the
/// path of a user drive definition ending in `.toml`. A relative path in a machine file is
/// taken relative to that file's directory; from `--set`, relative to the working directory.
fn valid_drive(name: &str, origin: &Origin) -> Result<String, ParamError> {
    let is_name = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if is_name {
        return Ok(name.to_string());
    }
    if name.len() > ".toml".len() && name.ends_with(".toml") {
        let path = std::path::Path::new(name);
        let base = std::path::Path::new(&origin.file).parent();
        let from_file = origin.line > 0 && path.is_relative();
        return Ok(match base {
            Some(dir) if from_file && !dir.as_os_str().is_empty() => {
                dir.join(path).to_string_lossy().into_owned()
            }
            _ => name.to_string(),
        });
    }
    Err(ParamError::Config {
        origin: origin.clone(),
        message: format!(
            "invalid drive '{name}'; expected the name of a drives/<name>.toml definition (letters, digits, '-', '_') or the path of a drive file ending in .toml"
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_index() {
        let ctx = Ctx::new("a\nbb\n\nc", "f");
        assert_eq!(ctx.line(Some(0)), Some(1));
        assert_eq!(ctx.line(Some(1)), Some(1));
        assert_eq!(ctx.line(Some(2)), Some(2));
        assert_eq!(ctx.line(Some(5)), Some(3));
        assert_eq!(ctx.line(Some(6)), Some(4));
        assert_eq!(ctx.line(Some(100)), Some(4));
    }

    #[test]
    fn axis_names() {
        for ok in ["X", "Y", "Z", "A", "W", "X2", "C10"] {
            assert!(valid_axis_name(ok), "{ok}");
        }
        for bad in ["", "x", "Q", "XX", "X-1", "2X"] {
            assert!(!valid_axis_name(bad), "{bad}");
        }
    }

    #[test]
    fn cycle_time_bounds() {
        let o = Origin::new("f", 1);
        assert_eq!(cycle_time("100", &o), Ok(100));
        assert_eq!(cycle_time("100000", &o), Ok(100_000));
        assert!(cycle_time("99", &o).is_err());
        assert!(cycle_time("100001", &o).is_err());
        assert!(cycle_time("abc", &o).is_err());
    }
}
