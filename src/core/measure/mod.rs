//! Measurement (FCT-C4, FCT-C4): measurement types, signal sources, latch handling, results.
//!
//! | part | module |
//! |---|---|
//! | types and per-axis configuration | this module |
//! | PLC interface (control units, external-latch handshake) | [`plc`] |
//! | DC timestamp back-calculation | [`timestamp`] |
//! | fixed-stop detection (type 7) | [`fixed_stop`] |
//! | a measuring motion without the NC channel (types 1–4): signal, braking, MERF, errors | [`run`] |
//! | `V.A.MESS`, `MOFFS`, `MEAS.ACS/PCS.VALUE`, G101 / G102 | [`results`] |
//! | signal source / input / edge from the new or the old parameters (§8.2.2) | [`source`] |
//!
//! Everything here is sans-IO: time comes in as [`Nanos`](crate::units::Nanos), positions in
//! mm / ° (ACS).

pub mod fixed_stop;
pub mod plc;
pub mod results;
pub mod run;
pub mod source;
pub mod timestamp;

use crate::drive::{ProbeEdge, TriggerSourceMode};

/// Measurement type (P-CHAN-00057 `messtyp`, `#MEAS MODE[n]`; FCT-C4 §3 table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeasType {
    /// 1: G100, ≥ 1 axis, feed from F.
    Type1,
    /// 2: G100, exactly one axis, feed P-AXIS-00215, error if the signal is missing.
    Type2,
    /// 3: G100, ≥ 1 axis, feed from F, continue to the target point.
    Type3,
    /// 4: G100, at most 3 main axes, feed from F.
    Type4,
    /// 5: interruptible G210, ≥ 1 axis, feed from F.
    Type5,
    /// 6: interruptible G310, ≥ 1 SERCOS axis, feed from F.
    Type6,
    /// 7: G100 to a fixed stop, ≥ 1 axis, feed from F.
    Type7,
}

impl MeasType {
    /// From the numeric value (1 … 7).
    pub fn from_number(n: i64) -> Option<Self> {
        Some(match n {
            1 => MeasType::Type1,
            2 => MeasType::Type2,
            3 => MeasType::Type3,
            4 => MeasType::Type4,
            5 => MeasType::Type5,
            6 => MeasType::Type6,
            7 => MeasType::Type7,
            _ => return None,
        })
    }

    /// The numeric value (1 … 7), `V.G.MEAS_TYPE`.
    pub fn number(self) -> u8 {
        match self {
            MeasType::Type1 => 1,
            MeasType::Type2 => 2,
            MeasType::Type3 => 3,
            MeasType::Type4 => 4,
            MeasType::Type5 => 5,
            MeasType::Type6 => 6,
            MeasType::Type7 => 7,
        }
    }

    /// Types that may run with independent axes (the table's `*`: 1, 2, 7).
    pub fn allows_independent_axes(self) -> bool {
        matches!(self, MeasType::Type1 | MeasType::Type2 | MeasType::Type7)
    }
}

/// Source of the probing signal (P-AXIS-00516 `kenngr.measure.signal`, `#MEAS [SIGNAL=..]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SignalSource {
    /// `DRIVE_TYPE_DEFAULT` (and blank): the drive type's own method — the drive latch for
    /// CiA 402 drives.
    DriveTypeDefault,
    /// `PLC`: probing_signal control unit sampled in the CNC cycle.
    Plc,
    /// `FIXED_STOP`: measurement type 7 detection.
    FixedStop,
    /// `DRIVE`: latch in the drive.
    Drive,
    /// `PLC_EXT_LATCH_CONTROL`: external measuring hardware with the please_rw / done_w handshake.
    PlcExtLatchControl,
    /// `PLC_FIRST_EVENT`: PLC signal, first event only (see [`plc`] for the interpretation).
    PlcFirstEvent,
    /// `PLC_TIMESTAMP`: probing_signal + 64-bit DC timestamp, position back-calculated.
    PlcTimestamp,
    /// `EXT_PROBE_WITH_DRIVE`: switchable probe enabled through the PLC, latch in the drive.
    ExtProbeWithDrive,
}

impl SignalSource {
    /// Parse the parameter / `#MEAS` text (case-insensitive; blank = DRIVE_TYPE_DEFAULT).
    pub fn from_text(text: &str) -> Option<Self> {
        Some(match text.trim().to_ascii_uppercase().as_str() {
            "" | "DRIVE_TYPE_DEFAULT" => SignalSource::DriveTypeDefault,
            "PLC" => SignalSource::Plc,
            "FIXED_STOP" => SignalSource::FixedStop,
            "DRIVE" => SignalSource::Drive,
            "PLC_EXT_LATCH_CONTROL" => SignalSource::PlcExtLatchControl,
            "PLC_FIRST_EVENT" => SignalSource::PlcFirstEvent,
            "PLC_TIMESTAMP" => SignalSource::PlcTimestamp,
            "EXT_PROBE_WITH_DRIVE" => SignalSource::ExtProbeWithDrive,
            _ => return None,
        })
    }

    /// The parameter text.
    pub fn name(self) -> &'static str {
        match self {
            SignalSource::DriveTypeDefault => "DRIVE_TYPE_DEFAULT",
            SignalSource::Plc => "PLC",
            SignalSource::FixedStop => "FIXED_STOP",
            SignalSource::Drive => "DRIVE",
            SignalSource::PlcExtLatchControl => "PLC_EXT_LATCH_CONTROL",
            SignalSource::PlcFirstEvent => "PLC_FIRST_EVENT",
            SignalSource::PlcTimestamp => "PLC_TIMESTAMP",
            SignalSource::ExtProbeWithDrive => "EXT_PROBE_WITH_DRIVE",
        }
    }

    /// The latch is taken in the drive.
    pub fn uses_drive_latch(self) -> bool {
        matches!(
            self,
            SignalSource::DriveTypeDefault | SignalSource::Drive | SignalSource::ExtProbeWithDrive
        )
    }
}

/// The probing-signal sources of seed 004 §7 that measure without a latch in the drive, in
/// words, for the messages about an axis whose drive has none (`check`, and the refusal
/// [`crate::messages::ids::MEAS_NO_DRIVE_LATCH`]).
pub const SOURCES_WITHOUT_DRIVE_LATCH: &str = "PLC (the probe input read by the PLC, sampled \
     each cycle, seed 004 §7.1), PLC_TIMESTAMP (the probe on a timestamp input terminal such as \
     an EL1252 on the EtherCAT segment, §7.5) or PLC_EXT_LATCH_CONTROL (external measuring \
     hardware, §7.4)";

/// Parse an edge word of P-AXIS-00518 or `#MEAS [EDGE=..]` (`POS` / `NEG`). A blank
/// P-AXIS-00518 is "not specified" and takes P-AXIS-00113 ([`source::ProbeSettings`]), so it
/// is not an edge here.
pub fn edge_from_text(text: &str) -> Option<ProbeEdge> {
    match text.trim().to_ascii_uppercase().as_str() {
        "POS" => Some(ProbeEdge::Positive),
        "NEG" => Some(ProbeEdge::Negative),
        _ => None,
    }
}

/// Parse P-AXIS-00702 (`DEFAULT` / `CNC_DEFINED` / `DRIVE_DEFINED`; blank = DEFAULT).
pub fn trigger_mode_from_text(text: &str) -> Option<TriggerSourceMode> {
    match text.trim().to_ascii_uppercase().as_str() {
        "" | "DEFAULT" => Some(TriggerSourceMode::Default),
        "CNC_DEFINED" => Some(TriggerSourceMode::CncDefined),
        "DRIVE_DEFINED" => Some(TriggerSourceMode::DriveDefined),
        _ => None,
    }
}

/// Measurement configuration of one axis, from its parameter list (FCT-C4 §3, §8.2.2), in
/// mm, mm/s, mm/s².
#[derive(Debug, Clone, PartialEq)]
pub struct AxisMeasConfig {
    /// P-AXIS-00118 `kenngr.messachse`: the axis may take part in measurement runs.
    pub enabled: bool,
    /// P-AXIS-00516 `kenngr.measure.signal`.
    pub signal: SignalSource,
    /// P-AXIS-00517 `kenngr.measure.input`.
    pub input: u8,
    /// P-AXIS-00518 `kenngr.measure.edge`.
    pub edge: ProbeEdge,
    /// P-AXIS-00702 `antr.canopen.probing_trigger_source`.
    pub trigger_mode: TriggerSourceMode,
    /// P-AXIS-00086 `kenngr.hub_messtaster`: probe stroke (types 2 and 4).
    pub stroke: f64,
    /// P-AXIS-00215 `kenngr.vb_messen`: measuring feed of type 2.
    pub feed_type2: f64,
    /// P-AXIS-00467 `kenngr.probing_offset`: permitted travel past the target (types 1, 2, 4–7).
    pub overtravel: f64,
    /// The permitted travel past the target in measurement type 2: P-AXIS-00467 when it is set,
    /// else the old P-AXIS-00114 `kenngr.mess_offset`, which "only has an influence on
    /// measurement travels with measurement type 2" (FCT-C4 §8.2.2, P-AXIS-00467 remarks).
    pub overtravel_type2: f64,
    /// P-AXIS-00053 `a_feedh` (0 → P-AXIS-00004): feedhold deceleration.
    pub a_feedhold: f64,
    /// P-AXIS-00168 `getriebe[i].slep_max`: CNC position lag limit; 0 = off.
    pub lag_limit: f64,
    /// The drive is a SERCOS drive (measurement type 6 needs one).
    pub sercos: bool,
    /// Fixed-stop detection parameters (P-AXIS-00774 … 00778 with their fallbacks); `None` when
    /// they are invalid.
    pub fixed_stop: Option<fixed_stop::FixedStopParams>,
}

impl Default for AxisMeasConfig {
    fn default() -> Self {
        AxisMeasConfig {
            enabled: false,
            signal: SignalSource::DriveTypeDefault,
            input: 1,
            edge: ProbeEdge::Positive,
            trigger_mode: TriggerSourceMode::Default,
            stroke: 5.0,
            feed_type2: 16.666,
            overtravel: 0.0,
            overtravel_type2: 0.0,
            a_feedhold: 1000.0,
            lag_limit: 10.0,
            sercos: false,
            fixed_stop: None,
        }
    }
}

/// Channel-wide measurement settings (FCT-C4 §8.2.1, FCT-C14 §6.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelMeasConfig {
    /// P-CHAN-00057 `messtyp`: default measurement type.
    pub default_type: MeasType,
    /// P-CHAN-00097 `use_drive_curr_limit`: feedhold uses the parameterised deceleration.
    pub feedhold_param_decel: bool,
    /// P-CHAN-00214 `meas_deceleration_mode`: brake with rapid deceleration on the signal.
    pub rapid_decel_on_signal: bool,
    /// P-CHAN-00296 `meas_use_std_dynamic`: plan the measuring block with G01 dynamics.
    pub std_dynamics: bool,
    /// P-CHAN-00176 `meas_error_no_signal`: type 1 without signal is an error.
    pub error_no_signal_type1: bool,
    /// P-CHAN-00266 `meas_fixed_stop_no_error`: type 7 without fixed stop is no error.
    pub fixed_stop_no_error: bool,
    /// P-CHAN-00268 `meas_soft_limit_move_path`: limit measuring paths at the SLS (50706).
    pub limit_at_sls: bool,
    /// P-CHAN-00311 `meas_pcs_value_no_probe_radius`: leave the ball radius out of the PCS value.
    pub pcs_without_radius: bool,
    /// Cycle of the PLC that feeds the probing signal (project setting): a PLC slower than the
    /// NC cycle widens the window a `PLC_TIMESTAMP` must lie in. `None`: the NC cycle.
    pub plc_cycle: Option<crate::units::Nanos>,
}

impl Default for ChannelMeasConfig {
    fn default() -> Self {
        ChannelMeasConfig {
            default_type: MeasType::Type1,
            feedhold_param_decel: false,
            rapid_decel_on_signal: false,
            std_dynamics: false,
            error_no_signal_type1: false,
            fixed_stop_no_error: false,
            limit_at_sls: false,
            pcs_without_radius: false,
            plc_cycle: None,
        }
    }
}

/// What a finished measuring block reports to the executor (ACS values; the executor converts
/// them with its frames into `V.A.MESS` & co.).
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementOutcome {
    /// Measurement type of the run.
    pub mtype: MeasType,
    /// Latched ACS position per channel axis; `None` where the axis did not latch.
    pub latched: Vec<Option<f64>>,
    /// Per axis: the latch arrived before the programmed target was reached (`V.A.MERF`).
    pub merf: Vec<bool>,
    /// Per axis: the axis took part in the run (values of other axes are retained).
    pub involved: Vec<bool>,
    /// The programmed target point was reached (no event, or type 3).
    pub target_reached: bool,
}
