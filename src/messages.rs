//! CNC messages (warnings and errors) with the seeds' IDs.
//!
//! The IDs are stable: tests and users match on them. Where a seed names an ID it is used as is
//! (`P-ERR-21648` → 21648). IDs the seeds do not name live in the project range 900000–999999 and
//! are listed in [`ids`].

use std::fmt;

/// Severity of a [`CncMessage`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Severity {
    /// A report at start-up (the EtherCAT segment and its wire time); nothing is wrong.
    Info,
    /// Reported; the program goes on.
    Warning,
    /// The program is aborted (the seeds' "Reset the controller").
    Error,
}

impl fmt::Display for Severity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Severity::Info => "info",
            Severity::Warning => "warning",
            Severity::Error => "error",
        })
    }
}

/// Where in the NC program a message arose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct BlockRef {
    /// The block's `N` number, if it has one.
    pub number: Option<u32>,
    /// 1-based source line of the block.
    pub line: u32,
}

impl fmt::Display for BlockRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.number {
            Some(n) => write!(f, "N{n}"),
            None => write!(f, "line {}", self.line),
        }
    }
}

/// One CNC message as the channel reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct CncMessage {
    /// Seed message ID (`P-ERR-<id>`), or a project ID from [`ids`].
    pub id: u32,
    /// Warning or error.
    pub severity: Severity,
    /// Human-readable text.
    pub text: String,
    /// The block that caused it, if any.
    pub block: Option<BlockRef>,
    /// The axis concerned, if any.
    pub axis: Option<String>,
}

impl CncMessage {
    /// A report (start-up information).
    pub fn info(id: u32, text: impl Into<String>) -> Self {
        CncMessage {
            id,
            severity: Severity::Info,
            text: text.into(),
            block: None,
            axis: None,
        }
    }

    /// A warning.
    pub fn warning(id: u32, text: impl Into<String>) -> Self {
        CncMessage {
            id,
            severity: Severity::Warning,
            text: text.into(),
            block: None,
            axis: None,
        }
    }

    /// An error.
    pub fn error(id: u32, text: impl Into<String>) -> Self {
        CncMessage {
            id,
            severity: Severity::Error,
            text: text.into(),
            block: None,
            axis: None,
        }
    }

    /// With the given severity.
    pub fn new(id: u32, severity: Severity, text: impl Into<String>) -> Self {
        CncMessage {
            id,
            severity,
            text: text.into(),
            block: None,
            axis: None,
        }
    }

    /// Attach the block reference.
    pub fn at(mut self, block: Option<BlockRef>) -> Self {
        if self.block.is_none() {
            self.block = block;
        }
        self
    }

    /// Attach the axis name.
    pub fn on_axis(mut self, axis: &str) -> Self {
        self.axis = Some(axis.to_string());
        self
    }

    /// True for errors.
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

impl fmt::Display for CncMessage {
    /// `warning <ID>: <text> (N<block>)` — the CLI's stderr contract (DESIGN.md); start-up
    /// reports are `info <ID>: <text>`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}: {}", self.severity, self.id, self.text)?;
        if let Some(b) = self.block {
            write!(f, " ({b})")?;
        }
        Ok(())
    }
}

/// Message IDs. Seed IDs carry the seed section; project IDs (9xxxxx) say so.
pub mod ids {
    /// FCT-A2 §3.1: G98 computes a negative SLS below P-AXIS-00177 (with P-CHAN-00498 = 1).
    pub const G98_BELOW_CONFIGURED: u32 = 21648;
    /// FCT-A2 §3.1: G98 computes a negative SLS ≥ the positive SLS.
    pub const G98_NOT_BELOW_POSITIVE: u32 = 21649;
    /// FCT-A2 §3.2: G99 computes a positive SLS above P-AXIS-00178 (with P-CHAN-00498 = 1).
    pub const G99_ABOVE_CONFIGURED: u32 = 21650;
    /// FCT-A2 §3.2: G99 computes a positive SLS ≤ the negative SLS.
    pub const G99_NOT_ABOVE_NEGATIVE: u32 = 21878;
    /// FCT-A2 §2: actual position beyond the positive SLS + tolerance (P-AXIS-00179).
    pub const ACTUAL_POSITIVE_SLS: u32 = 70021;
    /// FCT-A2 §2: actual position beyond the negative SLS − tolerance (P-AXIS-00179).
    pub const ACTUAL_NEGATIVE_SLS: u32 = 70022;
    /// FCT-A2 §2: a block's command path crosses the positive SLS (block not executed).
    pub const COMMAND_POSITIVE_SLS: u32 = 120002;
    /// FCT-A2 §2: a block's command path crosses the negative SLS (block not executed).
    pub const COMMAND_NEGATIVE_SLS: u32 = 120003;
    /// FCT-A2 §4.3 P-AXIS-00520/00521: the axis can no longer stop before the SLS with P-AXIS-00003.
    pub const COMMAND_STOP_DISTANCE: u32 = 70195;
    /// FCT-A2 §2: continuous jog reached an SLS / offset limit (only with P-MANU-00014).
    pub const JOG_LIMIT_REACHED: u32 = 50720;
    /// FCT-A2 §2: incremental jog step not executed, it would pass an SLS / offset limit.
    pub const JOG_STEP_REFUSED: u32 = 150008;
    /// FCT-C14 §6.2 P-CHAN-00268: measurement run stopped at the end of the motion path.
    pub const MEAS_PATH_LIMITED: u32 = 50706;

    /// FCT-C4 §8.2.2 P-AXIS-00777: per-mille start distance > 1000 at controller start.
    pub const FIXED_STOP_PER_MILLE_WARNING: u32 = 110757;
    /// FCT-C4 §8.2.2 P-AXIS-00777: per-mille start distance > 1000 at a measuring travel.
    pub const FIXED_STOP_PER_MILLE_ERROR: u32 = 51026;

    /// Project: the measuring block is not allowed as programmed (type / G code / axes /
    /// P-AXIS-00118).
    pub const MEAS_CONFIG: u32 = 900040;
    /// Project: probing signal missing (type 2; type 1 with P-CHAN-00176 = 1).
    pub const MEAS_NO_SIGNAL: u32 = 900041;
    /// Project: fixed stop not detected (type 7 with P-CHAN-00266 = 0).
    pub const MEAS_NO_FIXED_STOP: u32 = 900042;
    /// Project: a latch source failed (drive latch unit, lost event, PLC handshake, timestamp).
    pub const MEAS_LATCH: u32 = 900043;
    /// Project (warning): measuring feed reduced so that the braking distance stays inside the
    /// probe stroke P-AXIS-00086 (types 2 and 4).
    pub const MEAS_FEED_REDUCED: u32 = 900044;
    /// Project: G101 for an axis without measured value.
    pub const MEAS_NO_VALUE: u32 = 900045;
    /// Project: a measurement with a drive-latch source (DRIVE, DRIVE_TYPE_DEFAULT,
    /// EXT_PROBE_WITH_DRIVE) on an axis whose drive has no latch (a CiA 402 drive without
    /// touch probe); refused before motion, naming the sources of seed 004 §7 that remain.
    pub const MEAS_NO_DRIVE_LATCH: u32 = 900046;
    /// Project (warning, at the start of a run and in `check`): a probing-signal parameter the
    /// machine sets has no effect — an old one (P-AXIS-00113 / 00115 / 00116 / 00257 / 00269 /
    /// 00330 / 00430 / 00295) beside the new one that replaces it (P-AXIS-00516 / 00517 / 00518,
    /// seed 004 §8.2.2), or P-AXIS-00117 (no NC-kernel hardware interface here).
    pub const MEAS_PARAM_UNUSED: u32 = 900047;
    /// Project: CNC position lag monitoring (P-AXIS-00168) tripped.
    pub const LAG_LIMIT: u32 = 900014;
    /// Project: an acyclic drive access (`#DRIVE`, `#IDENT`) failed.
    pub const ACYCLIC_FAILED: u32 = 900050;
    /// Project (warning, at the start of a run on a CANopen link): the bus load of one cycle
    /// is above 70 % (docs/canopen.md "Bus load"; above 100 % the link refuses to start, exit 2).
    pub const CAN_BUS_LOAD: u32 = 900070;

    /// Project: an NC expression or command could not be evaluated (unknown variable, bad
    /// `#MSG` format, unknown axis).
    pub const NC_EVALUATION: u32 = 900001;
    /// Project: the drive reported a fault or left *operation enabled* during a run.
    pub const DRIVE_FAULT: u32 = 900010;
    /// Project: the drive did not reach *operation enabled* within the enable timeout.
    pub const DRIVE_ENABLE_TIMEOUT: u32 = 900011;
    /// Project: the link lost a process-data exchange (frame lost, wrong working counter).
    pub const LINK_LOST: u32 = 900012;
    /// Project: a drive sent an emergency message (CiA 301 EMCY over CANopen, CoE emergency
    /// over EtherCAT) — warning with the error code in words; the fault itself is handled by
    /// the statusword (900010).
    pub const DRIVE_EMERGENCY: u32 = 900015;
    /// Project (warning, at the end of a run): a drive sent the same emergency more than once;
    /// only the first was reported (900015), this one counts them (issue 28 item 8: a flood
    /// of EMCYs gives one line per axis and code plus this summary, and the cycle goes on).
    pub const DRIVE_EMERGENCY_SUMMARY: u32 = 900018;
    /// Project: a command position does not fit the drive's INTEGER32 position range.
    pub const DRIVE_RANGE: u32 = 900013;
    /// Project: an exact stop timed out: an axis did not come inside its in-position window
    /// (machine key `in_position_window`) within `in_position_timeout_ms`.
    pub const IN_POSITION_TIMEOUT: u32 = 900016;
    /// Project: an NC feature that is recognised but not supported in this build.
    pub const NC_UNSUPPORTED: u32 = 900020;
    /// Project: a motion block has no valid feed (F missing or zero for G01/G02/G03).
    pub const NC_NO_FEED: u32 = 900021;
    /// Project: arc geometry is inconsistent (radius at start and end differ).
    pub const NC_ARC_GEOMETRY: u32 = 900022;
    /// Project: the run exceeded its cycle budget (a block that never ends).
    pub const RUN_TIMEOUT: u32 = 900030;
    /// Project: the end of a run could not confirm its end state — a drive still reports its
    /// power stage on after the disable, or the bus did not take the end state (CANopen nodes
    /// not pre-operational). Warning; names the axes or nodes.
    pub const POWER_OFF: u32 = 900017;
    /// Project: the run was told to stop from outside (`fieldprobe run` got SIGINT or
    /// SIGTERM): the axes brake to a stop, every drive is disabled and the bus brought to its
    /// end state as at the end of any run, then the command exits 130 / 143 (128 + signal).
    pub const RUN_INTERRUPTED: u32 = 900019;

    /// FCT-C14 §3.4 notice: CLEAR of an active workspace / protection area (warning; the area
    /// stays active).
    pub const AREA_CLEAR_ACTIVE: u32 = 120499;
    /// FCT-C14 §5 case 2 (P-CHAN-00442 = 0): manual mode selected with the TCP outside the
    /// active workspace.
    pub const MANUAL_OUTSIDE_WORKSPACE: u32 = 50961;
    /// FCT-C14 §5 case 2 (P-CHAN-00442 = 0): manual mode selected with the TCP inside an active
    /// protection area.
    pub const MANUAL_IN_PROTECTION: u32 = 50962;
    /// Project (FCT-C14 §3, no ID given): `#CONTROL AREA` command text does not parse.
    pub const AREA_SYNTAX: u32 = 900300;
    /// Project (FCT-C14 §3.1 attention): area definition block not in G90.
    pub const AREA_NOT_ABSOLUTE: u32 = 900301;
    /// Project (FCT-C14 §3.1): area definition block without a valid F.
    pub const AREA_NO_FEED: u32 = 900302;
    /// Project (FCT-C14 §3.1.1 / §3.1.2): POLY takes G01 only, CIRC a G01 start and G02/G03.
    pub const AREA_WRONG_MOTION: u32 = 900303;
    /// Project (FCT-C14 §2.3): more than 20 motion blocks in a polygon.
    pub const AREA_TOO_MANY_BLOCKS: u32 = 900304;
    /// Project (FCT-C14 §3.1.1 notice): polygon first point ≠ last point.
    pub const AREA_NOT_CLOSED: u32 = 900305;
    /// Project (FCT-C14 §3.1.1): polygon with fewer than 3 distinct points.
    pub const AREA_TOO_FEW_POINTS: u32 = 900306;
    /// Project (FCT-C14 §2.3 / §3.1.1): polygon edges cross or touch.
    pub const AREA_SELF_INTERSECTION: u32 = 900307;
    /// Project (FCT-C14 §3.1.2): CIRC geometry (no centre, not a full circle, radius 0, extra
    /// or missing block).
    pub const AREA_CIRCLE: u32 = 900308;
    /// Project (FCT-C14 §3.1): MIN_EXCUR not below MAX_EXCUR.
    pub const AREA_EXCURSION: u32 = 900309;
    /// Project (FCT-C14 §2.3): a 21st control area.
    pub const AREA_TABLE_FULL: u32 = 900310;
    /// Project (FCT-C14 §3.1 "Overwrite control areas"): redefinition of an active area.
    pub const AREA_OVERWRITE_ACTIVE: u32 = 900311;
    /// Project (FCT-C14 §3.1): BEGIN / END out of sequence, command inside a definition.
    pub const AREA_SEQUENCE: u32 = 900312;
    /// Project (FCT-C14 §3.2): ON of an undefined area, bare OFF with nothing selected.
    pub const AREA_UNDEFINED: u32 = 900313;
    /// Project (FCT-C14 §3.2): TCP not in a valid position when areas are activated.
    pub const AREA_TCP_INVALID: u32 = 900314;
    /// Project (FCT-C14 §4): starting point incomplete, main and additional axes mixed, CIRC on
    /// additional axes.
    pub const AREA_AXES: u32 = 900315;
    /// Project (FCT-C14 §2.3 path check, no ID given): the programmed path of a block touches
    /// or enters an active protection area; the block is not executed, the program aborts.
    pub const AREA_PATH_PROTECTION: u32 = 900316;
    /// Project (FCT-C14 §2.3 path check, no ID given): the programmed path of a block leaves
    /// the active workspaces; the block is not executed, the program aborts.
    pub const AREA_PATH_WORKSPACE: u32 = 900317;
    /// Project (FCT-C14 §5, with P-MANU-00014): a jog stopped ahead of a workspace / protection
    /// area boundary (warning).
    pub const AREA_JOG_STOPPED: u32 = 900318;

    /// Project (info, start-up): the EtherCAT segment — SubDevices in OP, how many are axis
    /// drives, named terminals and not named, the process image and its datagrams.
    pub const ETHERCAT_SEGMENT: u32 = 900400;
    /// Project (info, start-up): one SubDevice the machine file does not name, taken to OP with
    /// its default process data (position, name, identity, image sizes).
    pub const ETHERCAT_NOT_NAMED: u32 = 900401;
    /// Project (info, start-up): the wire time of one EtherCAT cycle (frames × bytes at
    /// 100 Mbit/s plus the devices' forwarding delay) and its share of the cycle time.
    pub const ETHERCAT_WIRE_TIME: u32 = 900402;
    /// Project (error, start-up): the cycle time is shorter than the EtherCAT wire needs per
    /// cycle; names the wire time and the shortest cycle the wire carries.
    pub const ETHERCAT_CYCLE_TOO_SHORT: u32 = 900403;
    /// Project (warning, start-up): the EtherCAT device of an axis lacks the touch-probe
    /// objects of its drive definition's PDO mapping (0x60B8 / 0x60B9 …); the master maps the
    /// rest and the axis has no drive latch (issue 19).
    pub const ETHERCAT_NO_DRIVE_LATCH: u32 = 900404;
    /// Project (error, start-up): the EtherCAT device of an axis does not offer objects its
    /// drive definition maps (not in its dictionary, not mappable in that direction, another
    /// bit length); names the objects, the device and the drive.
    pub const ETHERCAT_PDO_OBJECTS_MISSING: u32 = 900405;

    /// Project (warning, start-up): the EtherCAT device of an axis is not what its drive
    /// definition or the CiA 402 profile leads one to expect: its revision differs from the
    /// definition's `[device] revision`, or its device type 0x1000 does not say CiA 402 (many
    /// vendor devices report another value; the device is taken by its identity and position).
    pub const ETHERCAT_DEVICE_CHECK: u32 = 900406;

    /// Project (error, start-up): a fixed PDO of an axis's drive definition (`[rxpdo]` /
    /// `[txpdo]` with `fixed = true`) cannot be assigned, or the device maps it differently
    /// than the definition's `entries` say; names the device, the PDO and both mappings.
    pub const ETHERCAT_FIXED_PDO: u32 = 900407;

    /// Project (warning, start-up): the mode of operation (0x6060, or the object that plays it)
    /// is in no PDO and the device has no such object to write by SDO: the drive runs in the
    /// mode it is in.
    pub const ETHERCAT_NO_MODE_OBJECT: u32 = 900408;

    /// Project (warning, start-up): the CANopen node of an axis lacks the touch-probe objects
    /// of its drive definition's PDO mapping (0x60B8 / 0x60B9 …, asked by SDO upload or
    /// refused in the mapping); the master maps the rest and the axis has no drive latch
    /// (issue 19; the CANopen counterpart of 900404).
    pub const CANOPEN_NO_DRIVE_LATCH: u32 = 900504;
    /// Project (error, start-up): the CANopen node of an axis does not offer objects its
    /// drive definition maps (not in its dictionary, another length, refused in the PDO
    /// mapping); names the node, the drive and the objects (the CANopen counterpart of
    /// 900405).
    pub const CANOPEN_PDO_OBJECTS_MISSING: u32 = 900505;
    /// Project (error, start-up): the process data of an axis's drive definition do not fit
    /// the PDOs its CANopen node offers (the RPDOs / TPDOs the node has, the sub-indices of
    /// their mapping parameters, 8 bytes a frame), asked by SDO upload; names the node, the
    /// drive, what the node offers and the objects left without a PDO (issue 25).
    pub const CANOPEN_PDO_CAPACITY: u32 = 900506;
}

/// A number from a user or a file, for a message: as Rust writes it for ordinary magnitudes,
/// in exponent form beyond (`1e300`, not 301 digits; `1.5e-9`), so a message stays short
/// whatever number it echoes.
pub fn show_number(v: f64) -> String {
    if v.is_finite() && v != 0.0 && !(1e-6..1e15).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}
