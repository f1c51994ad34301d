//! Measurement (seed 004, FCT-C4): measurement types, signal sources, latch handling, results.
//!
//! | part | module |
//! |---|---|
//! | types and per-axis configuration | this module |
//! | PLC interface (control units, external-latch handshake) | [`plc`] |
//! | DC timestamp back-calculation | [`timestamp`] |
//! | fixed-stop detection (type 7) | [`fixed_stop`] |
//!
//! Everything here is sans-IO: time comes in as [`Nanos`](crate::units::Nanos), positions in
//! mm / ° (ACS).

pub mod fixed_stop;
pub mod plc;
pub mod timestamp;

use crate::drive::{ProbeEdge, TriggerSourceMode};

/// Measurement type (P-CHAN-00057 `messtyp`, `#MEAS MODE[n]`; seed 004 §3 table).
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

/// Parse P-AXIS-00518 (`POS` / `NEG`; blank = POS).
pub fn edge_from_text(text: &str) -> Option<ProbeEdge> {
    match text.trim().to_ascii_uppercase().as_str() {
        "" | "POS" => Some(ProbeEdge::Positive),
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
