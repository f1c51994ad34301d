//! PROFIdrive adapter (master side, sans-IO) for standard telegrams 3, 5, 102 and 105, with the
//! encoder interface probe (G1_STW / G1_ZSW / G1_XIST2) and MOMRED.
//!
//! Sources: FCT-C4 §6.5 (P0660 = 80, digital input I0.0, edge per P-AXIS-00518), §7.3 (fixed
//! stop: torque limitation, drive lag monitoring off); the PROFIdrive profile (PI order no. 3.172: G1_STW /
//! G1_ZSW bits, telegram contents, MOMRED). The telegram definition ([`Telegram`]) is shared with the
//! drive model [`crate::drive::model::profidrive::ProfidriveModel`].
//!
//! # Words (big-endian, as on PROFIBUS / PROFINET)
//!
//! | tg | set-point (master → drive) | actual (drive → master) |
//! |---|---|---|
//! | 3 | STW1, NSOLL_B(32), STW2, G1_STW | ZSW1, NIST_B(32), ZSW2, G1_ZSW, G1_XIST1(32), G1_XIST2(32) |
//! | 5 | tg 3 + XERR(32), KPC(32) | as tg 3 |
//! | 102 | STW1, NSOLL_B, STW2, MOMRED, G1_STW | ZSW1, NIST_B, ZSW2, MELDW, G1_ZSW, G1_XIST1, G1_XIST2 |
//! | 105 | tg 102 + XERR, KPC | as tg 102 |
//!
//! # Control law
//!
//! The axis layer gives a position target `T_k` per cycle; the telegrams carry a speed set-point.
//! With `x` the last G1_XIST1, sampled `d` cycles before the exchange that carried it
//! ([`DriveAdapter::set_feedback_delay`], 1 on every link: sampled at SYNC0, sent with the next
//! frame), `T_{k−1−d}` the target the axis should have reached when `x` was sampled, and `Δt`
//! the time since the previous output image:
//!
//! - feed-forward `v_ff = (T_k − T_{k−1}) / Δt` (0 in the first operational cycle),
//! - tg 3 / 102: `NSOLL_B = v_ff + kv · (T_{k−1−d} − x)`,
//! - tg 5 / 105 (DSC): `NSOLL_B = v_ff`, `XERR = T_{k−1−d} − x`, `KPC = kv` in 0.001 1/s
//!   (assumption); the drive closes `n = NSOLL_B + KPC · e` on its own fine set-point.
//!
//! An axis that follows its set-points shows no position error; kv (`[model] kv`) removes
//! residual errors. NSOLL_B / NIST_B: `0x4000_0000` = `[profidrive] reference_speed`
//! increments/s (PROFIdrive N4 normalisation against P2000; the unit is an assumption).
//!
//! # Power state (STW1 / ZSW1)
//!
//! STW1 `0x047E` (OFF1, no OFF2/OFF3, enable operation, ramp, set-point, control by PLC) then
//! `0x047F` (ON); bit 7 fault acknowledge (rising edge). ZSW1 bit 0 ready to switch on, 1 ready
//! to operate, 2 operation enabled, 3 fault, 5 no OFF3 (quick stop inactive), 6 switching on
//! inhibited → [`PowerState`] (see [`decode_zsw1`]).
//!
//! # Probe (encoder interface, flying measurement)
//!
//! Probe `p` (P-AXIS-00517 via [`ProbeRequest::probe`]) and edge (P-AXIS-00518) select function
//! `2·(p−1) + 1` (positive) or `2·(p−1) + 2` (negative) (assumption; PROFIdrive encoder interface).
//! Arming: G1_STW "abort" (command 3) for the function until G1_ZSW shows neither "function
//! active" nor "value available" (so a value of an earlier arming can never be reported), then
//! "activate" (command 1, bit 7 flying measurement) until "function active" → `Armed`. When
//! "value available" rises: "read value" (command 2); the next G1_XIST2 is the value → one
//! [`ProbeEvent`]. G1_ZSW bit 15 (error, code in G1_XIST2) → acknowledge with G1_STW bit 15 until
//! bit 15 clears, and [`ProbeState::Failed`] naming the code. Only first-event mode with the
//! probe's own input ([`ProbeTrigger::Input`]) is supported.

use super::catalogue::DriveDefinition;
use super::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger,
};
use crate::units::Nanos;
use std::collections::VecDeque;
use toml_edit::{ImDocument, Item, Value};

/// One word (or double word) of a PROFIdrive standard telegram (PROFIdrive profile).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Word {
    /// Control word 1.
    Stw1,
    /// Speed set-point B (32 bit, N4).
    NsollB,
    /// Control word 2 (master sign of life in bits 12–15).
    Stw2,
    /// Torque reduction (16 bit, 0x4000 = 100 % reduction, assumption).
    Momred,
    /// Encoder 1 control word.
    G1Stw,
    /// Position deviation for DSC (32 bit, increments).
    Xerr,
    /// Position controller gain for DSC (32 bit, 0.001 1/s, assumption).
    Kpc,
    /// Status word 1.
    Zsw1,
    /// Speed actual value B (32 bit, N4).
    NistB,
    /// Status word 2 (drive sign of life in bits 12–15).
    Zsw2,
    /// Message word (bit 1: torque limit reached, assumption).
    Meldw,
    /// Encoder 1 status word.
    G1Zsw,
    /// Encoder 1 position actual value 1 (32 bit, increments).
    G1Xist1,
    /// Encoder 1 position actual value 2 (32 bit: measured value / error code / absolute value).
    G1Xist2,
}

impl Word {
    /// Bytes on the wire (2 or 4).
    pub const fn width(self) -> usize {
        match self {
            Word::NsollB | Word::Xerr | Word::Kpc | Word::NistB | Word::G1Xist1 | Word::G1Xist2 => {
                4
            }
            _ => 2,
        }
    }

    /// PROFIdrive signal name.
    pub const fn name(self) -> &'static str {
        match self {
            Word::Stw1 => "STW1",
            Word::NsollB => "NSOLL_B",
            Word::Stw2 => "STW2",
            Word::Momred => "MOMRED",
            Word::G1Stw => "G1_STW",
            Word::Xerr => "XERR",
            Word::Kpc => "KPC",
            Word::Zsw1 => "ZSW1",
            Word::NistB => "NIST_B",
            Word::Zsw2 => "ZSW2",
            Word::Meldw => "MELDW",
            Word::G1Zsw => "G1_ZSW",
            Word::G1Xist1 => "G1_XIST1",
            Word::G1Xist2 => "G1_XIST2",
        }
    }
}

use Word::*;

const SET_3: &[Word] = &[Stw1, NsollB, Stw2, G1Stw];
const SET_5: &[Word] = &[Stw1, NsollB, Stw2, G1Stw, Xerr, Kpc];
const SET_102: &[Word] = &[Stw1, NsollB, Stw2, Momred, G1Stw];
const SET_105: &[Word] = &[Stw1, NsollB, Stw2, Momred, G1Stw, Xerr, Kpc];
const ACT_3: &[Word] = &[Zsw1, NistB, Zsw2, G1Zsw, G1Xist1, G1Xist2];
const ACT_102: &[Word] = &[Zsw1, NistB, Zsw2, Meldw, G1Zsw, G1Xist1, G1Xist2];

/// A PROFIdrive standard telegram: its set-point and actual words in wire order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Telegram {
    /// Telegram number (P0922).
    pub number: u16,
    /// Master → drive words.
    pub setpoint: &'static [Word],
    /// Drive → master words.
    pub actual: &'static [Word],
}

/// The telegram numbers supported.
pub const TELEGRAMS: [u16; 4] = [3, 5, 102, 105];

impl Telegram {
    /// Standard telegram 3, 5, 102 or 105 (PROFIdrive profile); `None` for others.
    pub fn standard(number: u16) -> Option<Telegram> {
        let (setpoint, actual) = match number {
            3 => (SET_3, ACT_3),
            5 => (SET_5, ACT_3),
            102 => (SET_102, ACT_102),
            105 => (SET_105, ACT_102),
            _ => return None,
        };
        Some(Telegram {
            number,
            setpoint,
            actual,
        })
    }

    /// Bytes of the set-point image.
    pub fn setpoint_len(&self) -> usize {
        self.setpoint.iter().map(|w| w.width()).sum()
    }

    /// Bytes of the actual-value image.
    pub fn actual_len(&self) -> usize {
        self.actual.iter().map(|w| w.width()).sum()
    }

    /// Dynamic servo control (XERR / KPC present: telegrams 5 and 105).
    pub fn dsc(&self) -> bool {
        self.setpoint.contains(&Xerr)
    }

    /// MOMRED present (telegrams 102 and 105).
    pub fn momred(&self) -> bool {
        self.setpoint.contains(&Momred)
    }

    /// Byte offset of `word` in the set-point or the actual image.
    pub fn offset(&self, word: Word) -> Option<usize> {
        for list in [self.setpoint, self.actual] {
            let mut at = 0;
            for &w in list {
                if w == word {
                    return Some(at);
                }
                at += w.width();
            }
        }
        None
    }

    /// Raw value of `word` in `image` (big-endian, unsigned); `None` when the telegram has no
    /// such word or the image is too short.
    pub fn get(&self, image: &[u8], word: Word) -> Option<u32> {
        let at = self.offset(word)?;
        let bytes = image.get(at..at + word.width())?;
        Some(bytes.iter().fold(0u32, |acc, &b| (acc << 8) | u32::from(b)))
    }

    /// Write the low bits of `value` as `word` (big-endian); `false` when the telegram has no
    /// such word or the image is too short.
    pub fn put(&self, image: &mut [u8], word: Word, value: u32) -> bool {
        let Some(at) = self.offset(word) else {
            return false;
        };
        let Some(bytes) = image.get_mut(at..at + word.width()) else {
            return false;
        };
        let n = bytes.len();
        for (i, b) in bytes.iter_mut().enumerate() {
            *b = (value >> (8 * (n - 1 - i))) as u8;
        }
        true
    }
}

/// STW1 bits (PROFIdrive profile).
pub mod stw1 {
    /// ON / OFF1.
    pub const ON: u16 = 1 << 0;
    /// No coast stop (OFF2 inactive).
    pub const NO_OFF2: u16 = 1 << 1;
    /// No quick stop (OFF3 inactive).
    pub const NO_OFF3: u16 = 1 << 2;
    /// Enable operation.
    pub const ENABLE_OPERATION: u16 = 1 << 3;
    /// Fault acknowledge (rising edge).
    pub const FAULT_ACK: u16 = 1 << 7;
    /// `0x047E`: ready (OFF1), every enable bit and control by PLC set.
    pub const READY: u16 = 0x047E;
    /// `0x047F`: switch on.
    pub const RUN: u16 = 0x047F;
}

/// ZSW1 bits.
pub mod zsw1 {
    /// Ready to switch on.
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    /// Ready to operate.
    pub const READY_TO_OPERATE: u16 = 1 << 1;
    /// Operation enabled.
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    /// Fault present.
    pub const FAULT: u16 = 1 << 3;
    /// No coast stop active.
    pub const NO_OFF2: u16 = 1 << 4;
    /// No quick stop active.
    pub const NO_OFF3: u16 = 1 << 5;
    /// Switching on inhibited.
    pub const SWITCHING_ON_INHIBITED: u16 = 1 << 6;
    /// Control requested (PLC control).
    pub const CONTROL_REQUESTED: u16 = 1 << 9;
}

/// G1_STW bits (PROFIdrive encoder interface).
pub mod g1_stw {
    /// Bits 0–3: request function 1–4.
    pub const FUNCTIONS: u16 = 0x000F;
    /// Bits 4–6: command.
    pub const COMMAND_SHIFT: u16 = 4;
    /// Command 1: activate the selected functions.
    pub const ACTIVATE: u16 = 1;
    /// Command 2: read value.
    pub const READ_VALUE: u16 = 2;
    /// Command 3: abort function.
    pub const ABORT: u16 = 3;
    /// Bit 7: mode (0 reference mark, 1 flying measurement).
    pub const FLYING: u16 = 1 << 7;
    /// Bit 13: request absolute value cyclically.
    pub const ABS_CYCLIC: u16 = 1 << 13;
    /// Bit 14: request parking encoder.
    pub const PARKING: u16 = 1 << 14;
    /// Bit 15: acknowledge encoder error.
    pub const ACK_ERROR: u16 = 1 << 15;
    /// A G1_STW word.
    pub const fn word(functions: u16, command: u16, flying: bool) -> u16 {
        (functions & FUNCTIONS) | ((command & 7) << COMMAND_SHIFT) | if flying { FLYING } else { 0 }
    }
}

/// G1_ZSW bits (PROFIdrive encoder interface).
pub mod g1_zsw {
    /// Bits 0–3: function 1–4 active.
    pub const ACTIVE: u16 = 0x000F;
    /// Bits 4–7: value 1–4 available.
    pub const VALUE_SHIFT: u16 = 4;
    /// Bit 8: probe 1 deflected.
    pub const PROBE1: u16 = 1 << 8;
    /// Bit 9: probe 2 deflected.
    pub const PROBE2: u16 = 1 << 9;
    /// Bit 11: acknowledge encoder error active.
    pub const ACK_ACTIVE: u16 = 1 << 11;
    /// Bit 13: absolute value transmitted cyclically.
    pub const ABS_CYCLIC: u16 = 1 << 13;
    /// Bit 14: parking encoder active.
    pub const PARKING: u16 = 1 << 14;
    /// Bit 15: encoder error (code in G1_XIST2).
    pub const ERROR: u16 = 1 << 15;
}

/// ZSW1 → common power state. Fault (bit 3) wins, then switching on inhibited (6), operation
/// enabled (2; with bit 5 clear = quick stop active), ready to operate (1), ready to switch on
/// (0); nothing set = not ready.
pub fn decode_zsw1(zsw1: u16) -> PowerState {
    use zsw1::*;
    if zsw1 & FAULT != 0 {
        PowerState::Fault
    } else if zsw1 & SWITCHING_ON_INHIBITED != 0 {
        PowerState::SwitchOnDisabled
    } else if zsw1 & OPERATION_ENABLED != 0 {
        if zsw1 & NO_OFF3 == 0 {
            PowerState::QuickStopActive
        } else {
            PowerState::OperationEnabled
        }
    } else if zsw1 & READY_TO_OPERATE != 0 {
        PowerState::SwitchedOn
    } else if zsw1 & READY_TO_SWITCH_ON != 0 {
        PowerState::ReadyToSwitchOn
    } else {
        PowerState::NotReadyToSwitchOn
    }
}

/// The encoder-interface function (1..=4) for a probe (1/2) and edge (assumption, PROFIdrive
/// encoder interface: 1/2 = probe 1 positive/negative, 3/4 = probe 2 positive/negative).
pub fn function_for(probe: u8, edge: ProbeEdge) -> Option<u8> {
    if !(1..=2).contains(&probe) {
        return None;
    }
    Some(2 * (probe - 1) + if edge == ProbeEdge::Positive { 1 } else { 2 })
}

/// Value of P0660 that makes I0.0 the measuring input (FCT-C4 §6.5).
pub const P0660_MEASURING_INPUT: i64 = 80;
/// PNU of P0660.
pub const PNU_P0660: u16 = 660;

/// Drive parameter requirements of FCT-C4 §6.5, read through `read_pnu(pnu, sub)`; one
/// plain-words finding per unmet requirement (empty = all met).
pub fn check_drive(read_pnu: &dyn Fn(u16, u8) -> Option<i64>) -> Vec<String> {
    match read_pnu(PNU_P0660, 0) {
        Some(P0660_MEASURING_INPUT) => Vec::new(),
        Some(v) => vec![format!(
            "drive parameter P0660 is {v}, but must be 80 so that the fast digital input I0.0 is \
             the measuring input (seed 004 §6.5); the drive will not latch"
        )],
        None => vec![
            "drive parameter P0660 cannot be read; it must be 80 so that the fast digital input \
             I0.0 is the measuring input (seed 004 §6.5)"
                .to_string(),
        ],
    }
}

/// The `[profidrive]` section of a drive file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfidriveConfig {
    /// The telegram (P0922).
    pub telegram: Telegram,
    /// Increments/s that NSOLL_B / NIST_B `0x4000_0000` stands for (> 0).
    pub reference_speed: f64,
    /// Initial P0660 of the emulated drive (default 80).
    pub p0660: i64,
    /// Initial torque limit PNU of the emulated drive in ‰ of rated torque (default 3000,
    /// assumption).
    pub torque_limit: u16,
}

/// Default `[profidrive] reference_speed`: 2 000 000 increments/s (assumption).
pub const DEFAULT_REFERENCE_SPEED: f64 = 2_000_000.0;

impl ProfidriveConfig {
    /// Parse `[profidrive]` from the drive file text (`def.source`); errors name the file, the
    /// line, the key and the allowed values. A missing section means telegram 105 and defaults.
    pub fn parse(def: &DriveDefinition) -> Result<ProfidriveConfig, DriveError> {
        let text = def.source.as_str();
        let err = |span: Option<std::ops::Range<usize>>, message: String| {
            let line = span.map_or(0, |s| {
                text.as_bytes()[..s.start.min(text.len())]
                    .iter()
                    .filter(|&&b| b == b'\n')
                    .count()
                    + 1
            });
            DriveError::Definition {
                file: def.file.clone(),
                line,
                message,
            }
        };
        let doc = ImDocument::parse(text).map_err(|e| err(e.span(), format!("TOML: {e}")))?;
        let mut cfg = ProfidriveConfig {
            telegram: Telegram::standard(105).ok_or_else(|| err(None, "telegram 105".into()))?,
            reference_speed: DEFAULT_REFERENCE_SPEED,
            p0660: P0660_MEASURING_INPUT,
            torque_limit: 3000,
        };
        let Some(item) = doc.as_table().get("profidrive") else {
            return Ok(cfg);
        };
        let Some(t) = item.as_table_like() else {
            return Err(err(item.span(), "[profidrive]: expected a table".into()));
        };
        const KEYS: [&str; 4] = ["telegram", "reference_speed", "p0660", "torque_limit"];
        for (k, v) in t.iter() {
            let span = t
                .get_key_value(k)
                .and_then(|(key, _)| key.span())
                .or_else(|| v.span());
            let num = match v {
                Item::Value(Value::Integer(i)) => Some(*i.value() as f64),
                Item::Value(Value::Float(f)) => Some(*f.value()),
                _ => None,
            };
            let int = match v {
                Item::Value(Value::Integer(i)) => Some(*i.value()),
                _ => None,
            };
            match k {
                "telegram" => {
                    cfg.telegram = int
                        .and_then(|n| u16::try_from(n).ok())
                        .and_then(Telegram::standard)
                        .ok_or_else(|| {
                            err(
                                span,
                                "[profidrive] telegram: allowed values: 3, 5, 102, 105".into(),
                            )
                        })?
                }
                "reference_speed" => {
                    cfg.reference_speed =
                        num.filter(|v| v.is_finite() && *v > 0.0).ok_or_else(|| {
                            err(
                                span,
                                "[profidrive] reference_speed: allowed: a number > 0 \
                                 (increments/s)"
                                    .into(),
                            )
                        })?
                }
                "p0660" => {
                    cfg.p0660 = int.filter(|v| (0..=65535).contains(v)).ok_or_else(|| {
                        err(
                            span,
                            "[profidrive] p0660: allowed: an integer 0..=65535 (80 = measuring \
                             input I0.0)"
                                .into(),
                        )
                    })?
                }
                "torque_limit" => {
                    cfg.torque_limit = int.and_then(|v| u16::try_from(v).ok()).ok_or_else(|| {
                        err(
                            span,
                            "[profidrive] torque_limit: allowed: an integer 0..=65535 \
                                 (per mille)"
                                .into(),
                        )
                    })?
                }
                other => {
                    return Err(err(
                        span,
                        format!(
                            "unknown key `{other}` in [profidrive]; allowed: {}",
                            KEYS.join(", ")
                        ),
                    ))
                }
            }
        }
        Ok(cfg)
    }
}

/// NSOLL_B / NIST_B word for a speed in increments/s (N4: `0x4000_0000` = reference speed),
/// saturated to `i32`.
pub fn speed_to_n4(speed: f64, reference_speed: f64) -> i32 {
    let raw = (speed / reference_speed * f64::from(1u32 << 30)).round();
    if raw.is_finite() {
        raw.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    } else {
        0
    }
}

/// Speed in increments/s of an N4 word.
pub fn n4_to_speed(raw: i32, reference_speed: f64) -> f64 {
    f64::from(raw) / f64::from(1u32 << 30) * reference_speed
}

/// Steps of the probe handshake.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Abort written; waiting for "active" and "value available" to be clear.
    Clearing,
    /// Activate written; waiting for "function active".
    Activating,
    /// Function active; waiting for "value available".
    Armed,
    /// Read value written; the next G1_XIST2 is the value.
    Reading,
    /// Value taken (first event); function idle.
    Done,
    /// Error or timeout.
    Failed,
}

#[derive(Debug, Clone)]
struct Arming {
    request: ProbeRequest,
    /// Function number 1..=4.
    function: u8,
    phase: Phase,
    /// Output images written in this phase.
    writes: u32,
    /// Input images read in this phase after a write.
    waited: u32,
    sequence: u32,
}

/// Master-side PROFIdrive adapter (see the module documentation).
#[derive(Debug, Clone)]
pub struct ProfidriveAdapter {
    cfg: ProfidriveConfig,
    kv: f64,
    arm_timeout: u32,
    /// Last G1_XIST1 (increments) and whether one was read.
    position: Option<i32>,
    zsw1: u16,
    g1_zsw: u16,
    state: PowerState,
    /// Set-points sent while operational (for XERR / the speed loop's position error).
    sent: super::SentSetpoints,
    prev_now: Option<Nanos>,
    last_ack: bool,
    sign_of_life: u16,
    momred: u16,
    /// Encoder error acknowledge pending (G1_STW bit 15 written until G1_ZSW bit 15 clears).
    acking: bool,
    arming: Option<Arming>,
    /// Abort everything once more after a disarm (until the drive shows idle).
    disarming: bool,
    failure: Option<String>,
    events: VecDeque<ProbeEvent>,
}

impl ProfidriveAdapter {
    /// The adapter for a drive definition of profile `profidrive` (`[profidrive]` parsed here).
    pub fn new(def: &DriveDefinition) -> Result<Self, DriveError> {
        let cfg = ProfidriveConfig::parse(def)?;
        Ok(ProfidriveAdapter {
            cfg,
            kv: if def.model.kv.is_finite() && def.model.kv > 0.0 {
                def.model.kv
            } else {
                40.0
            },
            arm_timeout: def.probe.arm_timeout_cycles.max(1),
            position: None,
            zsw1: 0,
            g1_zsw: 0,
            state: PowerState::NotReadyToSwitchOn,
            sent: super::SentSetpoints::default(),
            prev_now: None,
            last_ack: false,
            sign_of_life: 0,
            momred: 0,
            acking: false,
            arming: None,
            disarming: false,
            failure: None,
            events: VecDeque::new(),
        })
    }

    /// The telegram in use.
    pub fn telegram(&self) -> Telegram {
        self.cfg.telegram
    }

    /// Cyclic torque reduction MOMRED in ‰ of the torque limit (0 = none, 1000 = full; written
    /// as `‰ × 0x4000 / 1000`, assumption). Refused on telegrams 3 / 5.
    pub fn set_torque_reduction(&mut self, permille: u16) -> Result<(), DriveError> {
        if !self.cfg.telegram.momred() {
            return Err(DriveError::Unsupported(format!(
                "telegram {} has no MOMRED word",
                self.cfg.telegram.number
            )));
        }
        let p = u32::from(permille.min(1000));
        self.momred = (p * 0x4000 / 1000) as u16;
        Ok(())
    }

    /// Cycles the input images run behind the output images written.
    fn sent_delay(&self) -> u32 {
        self.sent.delay()
    }

    fn fail(&mut self, why: String) {
        if let Some(a) = self.arming.as_mut() {
            a.phase = Phase::Failed;
        }
        self.failure = Some(why);
    }

    fn probe_step(&mut self, zsw: u16, xist2: u32) {
        if zsw & g1_zsw::ERROR != 0 {
            // Acknowledge in any case; a probe in use fails.
            if !self.acking && self.arming.is_some() {
                let code = xist2;
                self.fail(format!(
                    "encoder interface error: G1_ZSW bit 15 with code 0x{code:04X} in G1_XIST2"
                ));
            }
            self.acking = true;
            return;
        }
        self.acking = false;
        if self.disarming {
            if zsw & 0x00FF == 0 {
                self.disarming = false;
            }
            return;
        }
        let timeout = self.arm_timeout;
        let delay = self.sent_delay();
        let Some(a) = self.arming.as_mut() else {
            return;
        };
        if a.writes <= delay {
            // This image does not yet answer a word of this phase: the drive sampled it before
            // the word arrived (the actual values travel `delay` cycles behind, see
            // `set_feedback_delay`) — XIST2 would still hold the old content.
            return;
        }
        a.waited += 1;
        let bit = 1u16 << (a.function - 1);
        let active = zsw & bit != 0;
        let available = zsw & (bit << g1_zsw::VALUE_SHIFT) != 0;
        let next = |a: &mut Arming, p: Phase| {
            a.phase = p;
            a.writes = 0;
            a.waited = 0;
        };
        match a.phase {
            Phase::Clearing => {
                if !active && !available {
                    next(a, Phase::Activating);
                }
            }
            Phase::Activating => {
                if available {
                    // Latched at once (the edge came with the activation): fresh, read it.
                    next(a, Phase::Reading);
                } else if active {
                    next(a, Phase::Armed);
                }
            }
            Phase::Armed => {
                a.waited = 0;
                if available {
                    next(a, Phase::Reading);
                } else if !active {
                    let f = a.function;
                    self.fail(format!(
                        "function {f} of the encoder interface ended without a value"
                    ));
                }
                return;
            }
            Phase::Reading => {
                if available {
                    a.sequence += 1;
                    let ev = ProbeEvent {
                        probe: a.request.probe,
                        edge: a.request.edge,
                        position: xist2 as i32,
                        sequence: a.sequence,
                    };
                    next(a, Phase::Done);
                    self.events.push_back(ev);
                } else {
                    let f = a.function;
                    self.fail(format!(
                        "value {f} of the encoder interface vanished before it was read"
                    ));
                }
                return;
            }
            Phase::Done | Phase::Failed => return,
        }
        if let Some(a) = self.arming.as_ref() {
            if a.waited > timeout && matches!(a.phase, Phase::Clearing | Phase::Activating) {
                let (f, p) = (a.function, a.phase);
                self.fail(format!(
                    "the drive did not confirm function {f} within {timeout} cycles ({p:?})"
                ));
            }
        }
    }

    fn g1_stw(&mut self) -> u16 {
        let ack = if self.acking { g1_stw::ACK_ERROR } else { 0 };
        if self.disarming {
            return g1_stw::word(g1_stw::FUNCTIONS, g1_stw::ABORT, true) | ack;
        }
        let Some(a) = self.arming.as_mut() else {
            return ack;
        };
        a.writes = a.writes.saturating_add(1);
        let bit = 1u16 << (a.function - 1);
        let word = match a.phase {
            Phase::Clearing => g1_stw::word(bit, g1_stw::ABORT, true),
            Phase::Activating | Phase::Armed => g1_stw::word(bit, g1_stw::ACTIVATE, true),
            Phase::Reading => g1_stw::word(bit, g1_stw::READ_VALUE, true),
            Phase::Done | Phase::Failed => g1_stw::word(bit, 0, true),
        };
        word | ack
    }
}

impl DriveAdapter for ProfidriveAdapter {
    fn output_len(&self) -> usize {
        self.cfg.telegram.setpoint_len()
    }

    fn input_len(&self) -> usize {
        self.cfg.telegram.actual_len()
    }

    fn read_inputs(&mut self, now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError> {
        let _ = now;
        let tg = self.cfg.telegram;
        if inputs.len() < tg.actual_len() {
            return Err(DriveError::ImageTooShort {
                expected: tg.actual_len(),
                got: inputs.len(),
            });
        }
        let word = |w| tg.get(inputs, w).unwrap_or(0);
        self.zsw1 = word(Zsw1) as u16;
        self.g1_zsw = word(G1Zsw) as u16;
        let position = word(G1Xist1) as i32;
        self.position = Some(position);
        self.state = decode_zsw1(self.zsw1);
        let xist2 = word(G1Xist2);
        self.probe_step(self.g1_zsw, xist2);
        let operational = self.state == PowerState::OperationEnabled;
        let fault = self.state == PowerState::Fault;
        Ok(DriveFeedback {
            state: self.state,
            statusword: self.zsw1,
            position,
            following_error: None,
            mode_display: None,
            operational,
            fault,
            following_error_flag: false,
            torque: None,
        })
    }

    fn write_outputs(
        &mut self,
        now: Nanos,
        command: &DriveCommand,
        outputs: &mut [u8],
    ) -> Result<(), DriveError> {
        let tg = self.cfg.telegram;
        if outputs.len() < tg.setpoint_len() {
            return Err(DriveError::ImageTooShort {
                expected: tg.setpoint_len(),
                got: outputs.len(),
            });
        }
        // STW1: fault acknowledge as a rising edge, else the enable sequence.
        let mut stw = match self.state {
            PowerState::Fault => {
                let ack = command.fault_reset && !self.last_ack;
                self.last_ack = ack;
                stw1::READY | if ack { stw1::FAULT_ACK } else { 0 }
            }
            PowerState::SwitchOnDisabled | PowerState::NotReadyToSwitchOn => {
                self.last_ack = false;
                stw1::READY
            }
            _ => {
                self.last_ack = false;
                if command.enable {
                    stw1::RUN
                } else {
                    stw1::READY
                }
            }
        };
        if command.quick_stop {
            stw &= !stw1::NO_OFF3;
        }
        // Speed set-point (control law in the module documentation).
        let operational = self.state == PowerState::OperationEnabled && command.enable;
        let dt = match self.prev_now {
            Some(p) if now.0 > p.0 => (now.0 - p.0) as f64 * 1e-9,
            _ => 0.0,
        };
        self.prev_now = Some(now);
        let (mut nsoll, mut xerr) = (0.0, 0.0);
        match (
            operational,
            self.sent.last(),
            self.sent.reference(),
            self.position,
        ) {
            (true, Some(prev), Some(reference), Some(x)) if dt > 0.0 => {
                let v_ff = (f64::from(command.target) - f64::from(prev)) / dt;
                xerr = f64::from(reference) - f64::from(x);
                nsoll = if tg.dsc() {
                    v_ff
                } else {
                    v_ff + self.kv * xerr
                };
            }
            _ => {}
        }
        if operational {
            self.sent.push(command.target);
        } else {
            self.sent.clear();
        }
        self.sign_of_life = (self.sign_of_life + 1) & 0xF;
        let g1 = self.g1_stw();
        tg.put(outputs, Stw1, u32::from(stw));
        tg.put(
            outputs,
            NsollB,
            speed_to_n4(nsoll, self.cfg.reference_speed) as u32,
        );
        tg.put(outputs, Stw2, u32::from(self.sign_of_life << 12));
        tg.put(outputs, Momred, u32::from(self.momred));
        tg.put(outputs, G1Stw, u32::from(g1));
        let xerr = xerr.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        tg.put(outputs, Xerr, xerr as u32);
        tg.put(
            outputs,
            Kpc,
            (self.kv * 1000.0).round().clamp(0.0, 4e9) as u32,
        );
        Ok(())
    }

    fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        let function = function_for(request.probe, request.edge).ok_or_else(|| {
            DriveError::Unsupported(format!(
                "PROFIdrive has measuring probes 1 and 2, not {}",
                request.probe
            ))
        })?;
        if request.trigger != ProbeTrigger::Input {
            return Err(DriveError::Unsupported(
                "PROFIdrive flying measurement latches on the probe input only".into(),
            ));
        }
        if request.continuous {
            return Err(DriveError::Unsupported(
                "PROFIdrive flying measurement is first-event only (assumption)".into(),
            ));
        }
        self.disarming = false;
        self.failure = None;
        self.events.clear();
        self.arming = Some(Arming {
            request: *request,
            function,
            phase: Phase::Clearing,
            writes: 0,
            waited: 0,
            sequence: 0,
        });
        Ok(())
    }

    fn disarm_probe(&mut self) {
        if self.arming.take().is_some() {
            self.disarming = true;
        }
        self.failure = None;
        self.events.clear();
    }

    fn probe_state(&self) -> ProbeState {
        match &self.arming {
            None => ProbeState::Idle,
            Some(a) => match a.phase {
                Phase::Clearing | Phase::Activating => ProbeState::Arming,
                Phase::Armed | Phase::Reading | Phase::Done => ProbeState::Armed,
                Phase::Failed => ProbeState::Failed(
                    self.failure
                        .clone()
                        .unwrap_or_else(|| "encoder interface failed".into()),
                ),
            },
        }
    }

    fn probe_triggered(&self) -> bool {
        self.arming
            .as_ref()
            .is_some_and(|a| matches!(a.phase, Phase::Reading))
    }

    fn take_probe_event(&mut self) -> Option<ProbeEvent> {
        self.events.pop_front()
    }

    /// Signal [`SIGNAL_MOMRED`] sub 0: the torque reduction in ‰ (0 … 1000).
    fn write_cyclic(&mut self, index: u16, sub: u8, value: i64) -> Result<(), DriveError> {
        if (index, sub) != (SIGNAL_MOMRED, 0) {
            return Err(DriveError::Unsupported(format!(
                "PROFIdrive: no cyclic function {index:#06x}:{sub:02x}; signal {SIGNAL_MOMRED} \
                 (0x0065:00) MOMRED is"
            )));
        }
        let permille = u16::try_from(value)
            .ok()
            .filter(|v| *v <= 1000)
            .ok_or_else(|| {
                DriveError::Unsupported(format!(
                    "PROFIdrive MOMRED: {value} is outside 0 … 1000 per mille"
                ))
            })?;
        self.set_torque_reduction(permille)
    }

    fn read_cyclic(&self, index: u16, sub: u8) -> Result<i64, DriveError> {
        if (index, sub) != (SIGNAL_MOMRED, 0) {
            return Err(DriveError::Unsupported(format!(
                "PROFIdrive: no cyclic function {index:#06x}:{sub:02x}"
            )));
        }
        // Back to per mille, rounded (the word is ‰ × 0x4000 / 1000, truncated).
        Ok((i64::from(self.momred) * 1000 + 0x2000) / 0x4000)
    }

    fn set_feedback_delay(&mut self, cycles: u32) {
        self.sent.set_delay(cycles);
    }
}

/// PROFIdrive signal number of MOMRED (torque reduction): the `index` of the cyclic drive
/// function `object = "0x0065:00"`, `commu = "CYCLIC"` (assumption: the profile's signal
/// numbering, 101 = MOMRED).
pub const SIGNAL_MOMRED: u16 = 101;
