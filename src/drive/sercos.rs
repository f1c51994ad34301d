//! SERCOS (SoE) drive family, master side: the cyclic telegram shared with the drive model,
//! the `[sercos]` section of drive files, [`SercosAdapter`] and the [`commissioning_check`].
//!
//! # Telegram (FCT-C4 §6.1; IEC 61800-7-204, ETG.1000.6 SoE)
//!
//! Both directions start with a fixed 16-bit word that is "always mapped but not in the list"
//! (SOEM `ecx_readIDNmap`), followed by the IDNs of the file's `[sercos] mdt` / `at` lists in
//! order, little-endian (EtherCAT byte order). In a [`PdoLayout`] the entry `index` is the IDN
//! code (bit 15 P-IDN, bits 12–14 parameter set, bits 0–11 number), `sub` is 0.
//!
//! | dir | bytes | IDN | meaning |
//! |---|---|---|---|
//! | MDT | 0..2 | S-0-0134 | drive control word |
//! | MDT | 2..6 | S-0-0047 | position command value (increments) |
//! | AT | 0..2 | S-0-0135 | drive status word |
//! | AT | … | S-0-0051 | position feedback value 1 (increments) |
//! | AT | … | S-0-0189 | following distance (optional) |
//! | AT | … | S-0-0130…0133 | probe value selected by S-0-0169 |
//! | AT | … | S-0-0179 | probe status (optional) |
//!
//! # Drive control word S-0-0134 (IEC 61800-7-204; Beckhoff AX5000 documentation)
//!
//! bit 15 drive on, bit 14 drive enable, bit 13 halt/restart (1 = run: the drive follows the
//! command values, 0 = halt), bit 6 real-time control bit 1, bit 7 real-time control bit 2.
//! `0xE000` = run. The adapter writes 0 on a fault reset request; the rising edge of bit 15 then
//! clears the drive's class 1 diagnostic (assumption: real drives reset C1D with the procedure
//! command S-0-0099 over the service channel; the model accepts both).
//!
//! # Drive status word S-0-0135 (IEC 61800-7-204; Beckhoff AX5000 documentation)
//!
//! bits 15/14 ready to operate: 00 not ready, 01 ready for power-up (logic supply), 10 ready,
//! main power on, 11 drive enabled (torque on); bit 13 drive shut-down error (C1D); bit 3
//! command values are processed; bit 6 / 7 real-time status bit 1 / 2. Mapped to
//! [`PowerState`]: error → `Fault`, 00 → `NotReadyToSwitchOn`, 01 → `SwitchOnDisabled`,
//! 10 → `SwitchedOn`, 11 → `OperationEnabled` (the mapping onto the CiA 402 names is an
//! assumption). `operational` = 11, no error and bit 3.
//!
//! # Probe by real-time bits (FCT-C4 §6.1 table of P-AXIS-00060)
//!
//! | P-AXIS-00060 | enable (control) | measurement done (status) | probe activated (status) |
//! |---|---|---|---|
//! | 0 / no entry | RT control bit 1 | per P-AXIS-00106 (0x0040 = bit 1, 0x0080 = bit 2) | RT status bit 2 |
//! | 1 | RT control bit 1 | RT status bit 1 | RT status bit 2 |
//! | 2 | RT control bit 2 | RT status bit 2 | RT status bit 1 |
//!
//! The drive's S-0-0169 selects probe and edge and with them the value IDN: 1 = probe 1
//! positive → S-0-0130, 2 = probe 1 negative → S-0-0131, 4 = probe 2 positive → S-0-0132,
//! 8 = probe 2 negative → S-0-0133; that IDN must be in the AT.

use super::catalogue::{normalize_idn, DriveDefinition};
use super::pdo::{DataType, PdoLayout};
use super::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger, TriggerSourceMode,
};
use crate::params::ParamSet;
use crate::units::Nanos;
use std::collections::VecDeque;
use std::ops::Range;
use toml_edit::{ImDocument, Item, TableLike, Value};

/// IDN numbers used by the family (S-0-xxxx, parameter set 0; IEC 61800-7-204).
pub mod idn {
    /// S-0-0011 class 1 diagnostic (C1D); bit 11 excessive position deviation.
    pub const C1D: u16 = 11;
    /// S-0-0047 position command value.
    pub const POSITION_COMMAND: u16 = 47;
    /// S-0-0051 position feedback value 1.
    pub const POSITION_FEEDBACK: u16 = 51;
    /// S-0-0084 torque feedback value (0.1 % of rated).
    pub const TORQUE_FEEDBACK: u16 = 84;
    /// S-0-0092 bipolar torque limit value (0.1 % of rated).
    pub const TORQUE_LIMIT: u16 = 92;
    /// S-0-0099 reset class 1 diagnostic (procedure command).
    pub const RESET_C1D: u16 = 99;
    /// S-0-0130 probe value 1 positive edge (S-0-0131 … 0133 follow).
    pub const PROBE_VALUE_1_POS: u16 = 130;
    /// S-0-0134 drive control word (MDT).
    pub const CONTROL_WORD: u16 = 134;
    /// S-0-0135 drive status word (AT).
    pub const STATUS_WORD: u16 = 135;
    /// S-0-0159 monitoring window (0 = off).
    pub const MONITORING_WINDOW: u16 = 159;
    /// S-0-0169 probe control parameter.
    pub const PROBE_CONTROL: u16 = 169;
    /// S-0-0170 probing cycle procedure command.
    pub const PROBING_CYCLE: u16 = 170;
    /// S-0-0179 probe status.
    pub const PROBE_STATUS: u16 = 179;
    /// S-0-0189 following distance.
    pub const FOLLOWING_DISTANCE: u16 = 189;
    /// S-0-0301 allocation of real-time control bit 1.
    pub const RTC_BIT_1: u16 = 301;
    /// S-0-0303 allocation of real-time control bit 2.
    pub const RTC_BIT_2: u16 = 303;
    /// S-0-0305 allocation of real-time status bit 1.
    pub const RTS_BIT_1: u16 = 305;
    /// S-0-0307 allocation of real-time status bit 2.
    pub const RTS_BIT_2: u16 = 307;
    /// S-0-0401 probe 1 (input level); S-0-0402 probe 2.
    pub const PROBE_1_INPUT: u16 = 401;
    /// S-0-0405 probe 1 enable; S-0-0406 probe 2 enable.
    pub const PROBE_1_ENABLE: u16 = 405;
    /// S-0-0409 probe 1 positive latched; 0410 negative, 0411 / 0412 probe 2.
    pub const PROBE_1_POS_LATCHED: u16 = 409;
}

/// Control word bit 15 drive on.
pub const CW_DRIVE_ON: u16 = 1 << 15;
/// Control word bit 14 drive enable.
pub const CW_ENABLE: u16 = 1 << 14;
/// Control word bit 13 halt/restart (1 = run).
pub const CW_RUN: u16 = 1 << 13;
/// Status word bit 13 drive shut-down error (C1D).
pub const SW_ERROR: u16 = 1 << 13;
/// Status word bit 3: command values are processed.
pub const SW_FOLLOWING: u16 = 1 << 3;

/// Control (status) word bit of real-time control (status) bit `n` (1 / 2): bit 6 / 7.
pub const fn rt_mask(n: u8) -> u16 {
    1 << (5 + n)
}

/// IDN code of a name like `S-0-0092` / `P-0-0010` (bit 15 P, bits 12–14 set, bits 0–11 number).
pub fn idn_code(text: &str) -> Option<u16> {
    let n = normalize_idn(text)?;
    let p = u16::from(n.starts_with('P')) << 15;
    let set: u16 = n.get(2..3)?.parse().ok()?;
    let number: u16 = n.get(4..)?.parse().ok()?;
    Some(p | set << 12 | number)
}

/// Name of an IDN code (`S-0-0092`).
pub fn idn_name(code: u16) -> String {
    let kind = if code & 0x8000 != 0 { 'P' } else { 'S' };
    format!("{kind}-{}-{:04}", (code >> 12) & 7, code & 0x0FFF)
}

/// Wire type of the cyclic IDNs the family knows, and the direction they may go.
fn cyclic_type(code: u16, mdt: bool) -> Option<DataType> {
    match (code, mdt) {
        (idn::POSITION_COMMAND, true) => Some(DataType::I32),
        (idn::TORQUE_LIMIT, true) => Some(DataType::U16),
        (idn::POSITION_FEEDBACK | idn::FOLLOWING_DISTANCE | 130..=133, false) => {
            Some(DataType::I32)
        }
        (idn::TORQUE_FEEDBACK, false) => Some(DataType::I16),
        (idn::PROBE_STATUS, false) => Some(DataType::U16),
        _ => None,
    }
}

/// The cyclic telegrams of one drive: MDT (master → drive) and AT (drive → master).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Telegram {
    /// MDT: S-0-0134 at offset 0, then the configured IDNs.
    pub mdt: PdoLayout,
    /// AT: S-0-0135 at offset 0, then the configured IDNs.
    pub at: PdoLayout,
}

impl Telegram {
    /// The telegram with these IDN codes after the control / status word. Errors name the IDN
    /// and the allowed ones.
    pub fn new(mdt: &[u16], at: &[u16]) -> Result<Telegram, String> {
        let build = |word: u16, list: &[u16], is_mdt: bool| -> Result<PdoLayout, String> {
            let mut objects = vec![(word, 0u8, DataType::U16)];
            for &c in list {
                let ty = cyclic_type(c, is_mdt).ok_or_else(|| {
                    format!(
                        "{} cannot be in the {}; allowed: {}",
                        idn_name(c),
                        if is_mdt { "MDT" } else { "AT" },
                        if is_mdt {
                            "S-0-0047, S-0-0092"
                        } else {
                            "S-0-0051, S-0-0084, S-0-0130, S-0-0131, S-0-0132, S-0-0133, S-0-0179, S-0-0189"
                        }
                    )
                })?;
                objects.push((c, 0, ty));
            }
            PdoLayout::from_objects(&objects).map_err(|e| e.to_string())
        };
        let mdt_l = build(idn::CONTROL_WORD, mdt, true)?;
        if !mdt_l.contains(idn::POSITION_COMMAND, 0) {
            return Err("the MDT must carry S-0-0047 (position command value)".into());
        }
        let at_l = build(idn::STATUS_WORD, at, false)?;
        if !at_l.contains(idn::POSITION_FEEDBACK, 0) {
            return Err("the AT must carry S-0-0051 (position feedback value 1)".into());
        }
        Ok(Telegram {
            mdt: mdt_l,
            at: at_l,
        })
    }

    /// Whether the AT carries this IDN.
    pub fn at_carries(&self, code: u16) -> bool {
        self.at.contains(code, 0)
    }
}

impl Default for Telegram {
    /// S-0-0047 in the MDT; S-0-0051, S-0-0189, S-0-0130, S-0-0179 in the AT (the seed's
    /// example: probe 1 positive edge).
    fn default() -> Self {
        Telegram::new(&[47], &[51, 189, 130, 179]).unwrap_or(Telegram {
            mdt: PdoLayout::default(),
            at: PdoLayout::default(),
        })
    }
}

/// The `[sercos]` section of a drive file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SercosConfig {
    /// `mdt` / `at`.
    pub telegram: Telegram,
    /// `echtzeit_bit_nr`: P-AXIS-00060 when the axis list does not set it (default 1).
    pub echtzeit_bit_nr: u8,
    /// `idn`: drive-side start values (IDN code, value) of S-0-0092, 0159, 0169, 0301, 0303,
    /// 0305, 0307.
    pub idn_defaults: Vec<(u16, i64)>,
}

impl Default for SercosConfig {
    fn default() -> Self {
        SercosConfig {
            telegram: Telegram::default(),
            echtzeit_bit_nr: 1,
            idn_defaults: Vec::new(),
        }
    }
}

/// IDNs `[sercos] idn` may preset, with their value ranges.
const PRESET_IDNS: &[(u16, i64, i64)] = &[
    (idn::TORQUE_LIMIT, 0, 0xFFFF),
    (idn::MONITORING_WINDOW, 0, 0xFFFF_FFFF),
    (idn::PROBE_CONTROL, 0, 15),
    (idn::RTC_BIT_1, 0, 0xFFFF),
    (idn::RTC_BIT_2, 0, 0xFFFF),
    (idn::RTS_BIT_1, 0, 0xFFFF),
    (idn::RTS_BIT_2, 0, 0xFFFF),
];

/// Parse the `[sercos]` section of `def.source` (absent = [`SercosConfig::default`]). Errors
/// name the file, the line, the key and what is allowed.
pub fn config(def: &DriveDefinition) -> Result<SercosConfig, DriveError> {
    let text = def.source.as_str();
    let err = |span: Option<Range<usize>>, message: String| {
        let line = span.map_or(0, |s| {
            let end = s.start.min(text.len());
            text.as_bytes()[..end]
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
    let doc = ImDocument::parse(text).map_err(|e| {
        err(
            e.span(),
            format!("TOML syntax: {}", e.message().trim().replace('\n', "; ")),
        )
    })?;
    let mut cfg = SercosConfig::default();
    let Some(item) = doc.as_table().get("sercos") else {
        return Ok(cfg);
    };
    let span_of = |t: &dyn TableLike, k: &str| {
        t.get_key_value(k)
            .and_then(|(k, v)| v.span().or_else(|| k.span()))
    };
    let t = item
        .as_table_like()
        .ok_or_else(|| err(item.span(), "[sercos]: expected a table".into()))?;
    const KEYS: &[&str] = &["mdt", "at", "echtzeit_bit_nr", "idn"];
    for (k, _) in t.iter() {
        if !KEYS.contains(&k) {
            return Err(err(
                span_of(t, k),
                format!(
                    "unknown key `{k}` in [sercos]; allowed: {}",
                    KEYS.join(", ")
                ),
            ));
        }
    }
    let list = |key: &str| -> Result<Option<Vec<u16>>, DriveError> {
        let Some(item) = t.get(key) else {
            return Ok(None);
        };
        let arr = item.as_array().ok_or_else(|| {
            err(
                span_of(t, key),
                format!("[sercos] {key}: expected an array of IDNs like \"S-0-0051\""),
            )
        })?;
        let mut out = Vec::new();
        for v in arr.iter() {
            let code = v.as_str().and_then(idn_code).ok_or_else(|| {
                err(
                    v.span(),
                    format!("[sercos] {key}: expected an IDN like \"S-0-0051\" (S/P-set-number)"),
                )
            })?;
            if out.contains(&code) {
                return Err(err(
                    v.span(),
                    format!("[sercos] {key}: {} is given twice", idn_name(code)),
                ));
            }
            out.push(code);
        }
        Ok(Some(out))
    };
    let mdt = list("mdt")?;
    let at = list("at")?;
    if mdt.is_some() || at.is_some() {
        let mdt = mdt.unwrap_or_else(|| vec![idn::POSITION_COMMAND]);
        let at = at.unwrap_or_else(|| vec![idn::POSITION_FEEDBACK]);
        cfg.telegram = Telegram::new(&mdt, &at).map_err(|m| {
            err(
                span_of(t, "at").or_else(|| span_of(t, "mdt")),
                format!("[sercos] mdt / at: {m}"),
            )
        })?;
    }
    if let Some(item) = t.get("echtzeit_bit_nr") {
        match item.as_value() {
            Some(Value::Integer(i)) if (0..=2).contains(i.value()) => {
                cfg.echtzeit_bit_nr = *i.value() as u8;
            }
            _ => {
                return Err(err(
                    span_of(t, "echtzeit_bit_nr"),
                    "[sercos] echtzeit_bit_nr (P-AXIS-00060 default): expected 0, 1 or 2".into(),
                ))
            }
        }
    }
    if let Some(item) = t.get("idn") {
        let it = item.as_table_like().ok_or_else(|| {
            err(
                span_of(t, "idn"),
                "[sercos] idn: expected a table like { \"S-0-0169\" = 1 }".into(),
            )
        })?;
        for (k, v) in it.iter() {
            let span = span_of(it, k);
            let allowed = "S-0-0092, S-0-0159, S-0-0169, S-0-0301, S-0-0303, S-0-0305, S-0-0307";
            let code = idn_code(k).ok_or_else(|| {
                err(
                    span.clone(),
                    format!("[sercos] idn \"{k}\": not an IDN; allowed: {allowed}"),
                )
            })?;
            let &(_, lo, hi) =
                PRESET_IDNS
                    .iter()
                    .find(|(c, _, _)| *c == code)
                    .ok_or_else(|| {
                        err(
                            span.clone(),
                            format!("[sercos] idn \"{k}\": cannot be preset; allowed: {allowed}"),
                        )
                    })?;
            let value = match v {
                Item::Value(Value::Integer(i)) if (lo..=hi).contains(i.value()) => *i.value(),
                _ => {
                    return Err(err(
                        span,
                        format!("[sercos] idn \"{k}\": expected an integer in {lo}..={hi}"),
                    ))
                }
            };
            cfg.idn_defaults.push((code, value));
        }
    }
    Ok(cfg)
}

/// Which real-time bits carry the probe signals (FCT-C4 §6.1 table of P-AXIS-00060).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtBits {
    /// P-AXIS-00060 in effect.
    pub echtzeit_bit_nr: u8,
    /// Real-time control bit (1 / 2) that enables the measurement.
    pub enable: u8,
    /// Real-time status bit (1 / 2) that signals "measurement done".
    pub done: u8,
    /// Real-time status bit (1 / 2) that signals "measuring probe activated".
    pub activated: u8,
}

/// P-AXIS-00060 in effect: the axis list's value, else the drive file's `echtzeit_bit_nr`.
fn effective_rt(cfg: &SercosConfig, axis: &ParamSet) -> i64 {
    if axis.is_set("P-AXIS-00060") {
        axis.int("P-AXIS-00060")
    } else {
        i64::from(cfg.echtzeit_bit_nr)
    }
}

/// The real-time bit assignment of P-AXIS-00060 `rt` (with P-AXIS-00106 `mask` when `rt` = 0,
/// `None` = not set). Errors in plain words.
pub fn rt_bits(rt: i64, mask: Option<i64>) -> Result<RtBits, String> {
    match rt {
        1 => Ok(RtBits {
            echtzeit_bit_nr: 1,
            enable: 1,
            done: 1,
            activated: 2,
        }),
        2 => Ok(RtBits {
            echtzeit_bit_nr: 2,
            enable: 2,
            done: 2,
            activated: 1,
        }),
        0 => match mask {
            None => Err("P-AXIS-00060 = 0 needs P-AXIS-00106 (0x0040 = real-time status bit 1, 0x0080 = real-time status bit 2) to say which status bit signals 'measurement done', but P-AXIS-00106 is not set".into()),
            Some(0x40) => Ok(RtBits {
                echtzeit_bit_nr: 0,
                enable: 1,
                done: 1,
                activated: 2,
            }),
            Some(0x80) => Err("P-AXIS-00060 = 0 with P-AXIS-00106 = 0x0080 puts 'measurement done' on real-time status bit 2, which P-AXIS-00060 = 0 already uses for 'probe activated'; set P-AXIS-00106 = 0x0040 or P-AXIS-00060 = 1 or 2".into()),
            Some(m) => Err(format!("P-AXIS-00106 = 0x{m:04X} is not a real-time status bit; allowed: 0x0040 (bit 1), 0x0080 (bit 2)")),
        },
        other => Err(format!("P-AXIS-00060 = {other} is out of range; allowed: 0, 1, 2")),
    }
}

/// S-0-0169 value for probe `probe` (1 / 2) and edge (FCT-C4 §6.1: 1, 2, 4, 8).
pub fn probe_control_value(probe: u8, edge: ProbeEdge) -> u16 {
    1 << probe_slot(probe, edge)
}

/// 0..=3: probe 1 pos, probe 1 neg, probe 2 pos, probe 2 neg.
fn probe_slot(probe: u8, edge: ProbeEdge) -> u16 {
    2 * u16::from(probe.clamp(1, 2) - 1) + u16::from(edge == ProbeEdge::Negative)
}

/// Value IDN (S-0-0130 … 0133) of probe `probe` and edge.
pub fn probe_value_idn(probe: u8, edge: ProbeEdge) -> u16 {
    idn::PROBE_VALUE_1_POS + probe_slot(probe, edge)
}

/// Latched-signal IDN (S-0-0409 … 0412) of probe `probe` and edge.
pub fn probe_latched_idn(probe: u8, edge: ProbeEdge) -> u16 {
    idn::PROBE_1_POS_LATCHED + probe_slot(probe, edge)
}

fn edge_words(edge: ProbeEdge) -> &'static str {
    match edge {
        ProbeEdge::Positive => "positive",
        ProbeEdge::Negative => "negative",
    }
}

/// Arming progress of the latch unit.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Arm {
    Idle,
    /// Writing the enable bit 0; waiting for a status with "done" clear after such a write.
    Clearing {
        request: ProbeRequest,
        value_idn: u16,
        written_zero: bool,
        cycles: u32,
    },
    /// Confirmed clear: the next write sets the enable bit.
    Enabling {
        request: ProbeRequest,
        value_idn: u16,
    },
    /// Enable bit written 1; a rising "done" is an event.
    Armed {
        request: ProbeRequest,
        value_idn: u16,
        prev_done: bool,
        sequence: u32,
    },
    Failed(String),
}

/// Master-side adapter of a SERCOS drive (sans-IO; see the module documentation).
#[derive(Debug, Clone)]
pub struct SercosAdapter {
    telegram: Telegram,
    bits: RtBits,
    arm_timeout: u32,
    arm: Arm,
    events: VecDeque<ProbeEvent>,
    /// Last "probe activated" status bit (S-0-0401 / 0402 as allocated).
    probe_active: bool,
    last_status: u16,
}

impl SercosAdapter {
    /// The adapter of `def` for the axis with parameter list `axis` (P-AXIS-00060, P-AXIS-00106).
    /// Inconsistent configuration is a [`DriveError::Unsupported`] in plain words.
    pub fn new(def: &DriveDefinition, axis: &ParamSet) -> Result<Self, DriveError> {
        let cfg = config(def)?;
        let rt = effective_rt(&cfg, axis);
        let mask = axis
            .is_set("P-AXIS-00106")
            .then(|| axis.int("P-AXIS-00106"));
        let bits = rt_bits(rt, mask)
            .map_err(|m| DriveError::Unsupported(format!("drive '{}': {m}", def.name)))?;
        Ok(SercosAdapter {
            telegram: cfg.telegram,
            bits,
            arm_timeout: def.probe.arm_timeout_cycles.max(1),
            arm: Arm::Idle,
            events: VecDeque::new(),
            probe_active: false,
            last_status: 0,
        })
    }

    /// The telegram layout.
    pub fn telegram(&self) -> &Telegram {
        &self.telegram
    }

    /// The real-time bits in use.
    pub fn rt_bits(&self) -> RtBits {
        self.bits
    }

    /// The "measuring probe activated" status bit of the last AT.
    pub fn probe_activated(&self) -> bool {
        self.probe_active
    }

    fn enable_bit(&self) -> bool {
        matches!(self.arm, Arm::Armed { .. })
    }

    /// Decode the drive status word into the common power state.
    pub fn power_state(status: u16) -> PowerState {
        if status & SW_ERROR != 0 {
            return PowerState::Fault;
        }
        match status >> 14 {
            0 => PowerState::NotReadyToSwitchOn,
            1 => PowerState::SwitchOnDisabled,
            2 => PowerState::SwitchedOn,
            _ => PowerState::OperationEnabled,
        }
    }
}

impl DriveAdapter for SercosAdapter {
    fn power_stage_off(&self, state: PowerState) -> bool {
        super::torque_off(state)
    }

    fn output_len(&self) -> usize {
        self.telegram.mdt.len()
    }

    fn input_len(&self) -> usize {
        self.telegram.at.len()
    }

    fn read_inputs(&mut self, _now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError> {
        let at = &self.telegram.at;
        if inputs.len() < at.len() {
            return Err(DriveError::ImageTooShort {
                expected: at.len(),
                got: inputs.len(),
            });
        }
        let status = at.get_u16(inputs, idn::STATUS_WORD, 0).unwrap_or(0);
        self.last_status = status;
        let position = at.get_i32(inputs, idn::POSITION_FEEDBACK, 0).unwrap_or(0);
        let done = status & rt_mask(self.bits.done) != 0;
        self.probe_active = status & rt_mask(self.bits.activated) != 0;
        let state = Self::power_state(status);
        let fault = state == PowerState::Fault;
        let operational = state == PowerState::OperationEnabled && status & SW_FOLLOWING != 0;
        let timeout = self.arm_timeout;
        match &mut self.arm {
            Arm::Clearing {
                written_zero,
                cycles,
                request,
                value_idn,
            } => {
                if *written_zero && !done {
                    self.arm = Arm::Enabling {
                        request: *request,
                        value_idn: *value_idn,
                    };
                } else {
                    *cycles += 1;
                    if *cycles > timeout {
                        self.arm = Arm::Failed(format!(
                            "real-time status bit {} ('measurement done') stays set although the enable bit (real-time control bit {}) was cleared for {timeout} cycles; the drive does not reset its latch",
                            self.bits.done, self.bits.enable
                        ));
                    }
                }
            }
            Arm::Armed {
                request,
                value_idn,
                prev_done,
                sequence,
            } => {
                if done && !*prev_done {
                    *sequence += 1;
                    let value = at.get_i32(inputs, *value_idn, 0).unwrap_or(0);
                    self.events.push_back(ProbeEvent {
                        probe: request.probe,
                        edge: request.edge,
                        position: value,
                        sequence: *sequence,
                    });
                }
                *prev_done = done;
            }
            Arm::Idle | Arm::Enabling { .. } | Arm::Failed(_) => {}
        }
        Ok(DriveFeedback {
            state,
            statusword: status,
            position,
            following_error: at.get_i32(inputs, idn::FOLLOWING_DISTANCE, 0),
            mode_display: None,
            operational,
            fault,
            following_error_flag: false,
            torque: at.get_i16(inputs, idn::TORQUE_FEEDBACK, 0).map(i32::from),
        })
    }

    fn write_outputs(
        &mut self,
        _now: Nanos,
        command: &DriveCommand,
        outputs: &mut [u8],
    ) -> Result<(), DriveError> {
        let mdt = &self.telegram.mdt;
        if outputs.len() < mdt.len() {
            return Err(DriveError::ImageTooShort {
                expected: mdt.len(),
                got: outputs.len(),
            });
        }
        // Enabling -> Armed: this write sets the enable bit.
        if let Arm::Enabling { request, value_idn } = self.arm {
            self.arm = Arm::Armed {
                request,
                value_idn,
                prev_done: false,
                sequence: 0,
            };
        }
        if let Arm::Clearing { written_zero, .. } = &mut self.arm {
            *written_zero = true;
        }
        let mut cw = if command.fault_reset {
            0
        } else if command.enable {
            let run = if command.quick_stop { 0 } else { CW_RUN };
            CW_DRIVE_ON | CW_ENABLE | run
        } else {
            0
        };
        if self.enable_bit() {
            cw |= rt_mask(self.bits.enable);
        }
        let map = |e: super::pdo::PdoError| DriveError::Unsupported(e.to_string());
        mdt.set_u16(outputs, idn::CONTROL_WORD, 0, cw)
            .map_err(map)?;
        mdt.set_i32(outputs, idn::POSITION_COMMAND, 0, command.target)
            .map_err(map)?;
        Ok(())
    }

    fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        if request.continuous {
            return Err(DriveError::Unsupported("SERCOS probe by real-time bits latches once per enable; continuous mode is not offered (assumption)".into()));
        }
        if request.trigger != ProbeTrigger::Input
            || request.source_mode != TriggerSourceMode::Default
        {
            return Err(DriveError::Unsupported("SERCOS probe: only the probe's own input is selectable (the drive's S-0-0169 / P-0-0251 choose the signal); set P-AXIS-00702 = DEFAULT".into()));
        }
        if !(1..=2).contains(&request.probe) {
            return Err(DriveError::Unsupported(format!(
                "SERCOS probe {} does not exist; allowed: 1, 2",
                request.probe
            )));
        }
        let value_idn = probe_value_idn(request.probe, request.edge);
        if !self.telegram.at_carries(value_idn) {
            return Err(DriveError::Unsupported(format!(
                "probe {} {} edge needs S-0-0169 = {} and its value {} in the cyclic AT, but the AT carries only {}",
                request.probe,
                edge_words(request.edge),
                probe_control_value(request.probe, request.edge),
                idn_name(value_idn),
                self.telegram
                    .at
                    .entries()
                    .iter()
                    .map(|e| idn_name(e.index))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        self.events.clear();
        self.arm = Arm::Clearing {
            request: *request,
            value_idn,
            written_zero: false,
            cycles: 0,
        };
        Ok(())
    }

    fn disarm_probe(&mut self) {
        self.arm = Arm::Idle;
        self.events.clear();
    }

    fn probe_state(&self) -> ProbeState {
        match &self.arm {
            Arm::Idle => ProbeState::Idle,
            Arm::Clearing { .. } | Arm::Enabling { .. } => ProbeState::Arming,
            Arm::Armed { .. } => ProbeState::Armed,
            Arm::Failed(m) => ProbeState::Failed(m.clone()),
        }
    }

    fn take_probe_event(&mut self) -> Option<ProbeEvent> {
        self.events.pop_front()
    }
}

/// Commissioning check (FCT-C4 §6.1, flowcharts Fig. 12 / 13 inferred): every mismatch
/// between the drive's IDN settings (`drive_idns` answers an IDN code, `None` = cannot be read)
/// and the axis parameters, in plain words; empty when all fits.
///
/// Checked: P-AXIS-00516 is DRIVE (or the drive-type default); P-AXIS-00060 (or 0 with
/// P-AXIS-00106) is consistent; the enable control bit is allocated to the probe enable of the
/// probe P-AXIS-00517 selects (S-0-0301 / 0303 = 405 / 406); the "done" status bit to that
/// probe's latched signal of the P-AXIS-00518 edge (S-0-0305 / 0307 = 409 … 412); the
/// "activated" status bit to that probe's input (401 / 402); S-0-0169 selects exactly that probe
/// and edge; its value IDN S-0-0130 … 0133 is in the AT.
pub fn commissioning_check(
    def: &DriveDefinition,
    axis: &ParamSet,
    drive_idns: &dyn Fn(u16) -> Option<i64>,
) -> Vec<String> {
    let mut out = Vec::new();
    let cfg = match config(def) {
        Ok(c) => c,
        Err(e) => return vec![e.to_string()],
    };
    // P-AXIS-00516 / 00517 / 00518, else the old parameters (FCT-C4 §8.2.2): as the run reads
    // them.
    let probe = match crate::core::measure::source::ProbeSettings::from_params(axis) {
        Ok(p) => p,
        Err(e) => return vec![e],
    };
    let signal = probe.signal;
    if !signal.uses_drive_latch() || signal == crate::core::measure::SignalSource::ExtProbeWithDrive
    {
        out.push(format!(
            "{} = {}: a SERCOS drive measures with P-AXIS-00516 = DRIVE (seed 004 §6.1); the drive's probe settings are not used",
            probe.signal_origin.id_or("P-AXIS-00516"),
            signal.name()
        ));
    }
    let rt = effective_rt(&cfg, axis);
    let mask = axis
        .is_set("P-AXIS-00106")
        .then(|| axis.int("P-AXIS-00106"));
    let bits = match rt_bits(rt, mask) {
        Ok(b) => b,
        Err(m) => {
            out.push(m);
            return out;
        }
    };
    let edge = probe.edge;
    let input_id = probe.input_origin.id_or("P-AXIS-00517");
    let edge_id = probe.edge_origin.id_or("P-AXIS-00518");
    let probe = probe.input.clamp(1, 2);
    let what = format!(
        "P-AXIS-00060 = {}{}",
        bits.echtzeit_bit_nr,
        if bits.echtzeit_bit_nr == 0 {
            format!(" with P-AXIS-00106 = 0x{:04X}", mask.unwrap_or(0))
        } else {
            String::new()
        }
    );
    let mut expect = |alloc: u16, kind: &str, bit: u8, meaning: String, want: u16| {
        match drive_idns(alloc) {
            None => out.push(format!(
                "{what} expects real-time {kind} bit {bit} to signal '{meaning}' ({} = {want}), but the drive's {} cannot be read",
                idn_name(alloc),
                idn_name(alloc)
            )),
            Some(v) if v != i64::from(want) => out.push(format!(
                "{what} expects real-time {kind} bit {bit} to signal '{meaning}' ({} = {want}), but the drive has {} = {v}",
                idn_name(alloc),
                idn_name(alloc)
            )),
            Some(_) => {}
        }
    };
    let ctl_alloc = |b: u8| {
        if b == 1 {
            idn::RTC_BIT_1
        } else {
            idn::RTC_BIT_2
        }
    };
    let st_alloc = |b: u8| {
        if b == 1 {
            idn::RTS_BIT_1
        } else {
            idn::RTS_BIT_2
        }
    };
    expect(
        ctl_alloc(bits.enable),
        "control",
        bits.enable,
        format!("probe {probe} enable"),
        idn::PROBE_1_ENABLE + u16::from(probe - 1),
    );
    expect(
        st_alloc(bits.done),
        "status",
        bits.done,
        format!("probe {probe} {} edge latched", edge_words(edge)),
        probe_latched_idn(probe, edge),
    );
    expect(
        st_alloc(bits.activated),
        "status",
        bits.activated,
        format!("probe {probe} input"),
        idn::PROBE_1_INPUT + u16::from(probe - 1),
    );
    let want169 = probe_control_value(probe, edge);
    let edge_param = format!(
        "{input_id} = {} (probe {probe}) and {edge_id} = {}",
        axis.int(input_id),
        match (edge_id, edge) {
            ("P-AXIS-00113", _) => axis.int(edge_id).to_string(),
            (_, ProbeEdge::Positive) => "POS".into(),
            (_, ProbeEdge::Negative) => "NEG".into(),
        }
    );
    match drive_idns(idn::PROBE_CONTROL) {
        None => out.push(format!(
            "{edge_param} need S-0-0169 = {want169}, but the drive's S-0-0169 cannot be read"
        )),
        Some(v) if v != i64::from(want169) => out.push(format!(
            "{edge_param} need S-0-0169 = {want169} (probe {probe} {} edge), but the drive has S-0-0169 = {v}",
            edge_words(edge)
        )),
        Some(_) => {}
    }
    let value_idn = probe_value_idn(probe, edge);
    if !cfg.telegram.at_carries(value_idn) {
        out.push(format!(
            "S-0-0169 = {want169} stores the measured value in {}, but the cyclic AT of drive '{}' does not carry it ([sercos] at)",
            idn_name(value_idn),
            def.name
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idn_codes() {
        assert_eq!(idn_code("S-0-0169"), Some(0x00A9));
        assert_eq!(idn_code("P-0-0010"), Some(0x800A));
        assert_eq!(idn_code("S-1-0092"), Some(0x105C));
        assert_eq!(idn_name(0x800A), "P-0-0010");
        assert_eq!(idn_code("X-0-1"), None);
    }

    #[test]
    fn rt_bit_table() {
        assert_eq!(
            rt_bits(2, None).map(|b| (b.enable, b.done, b.activated)),
            Ok((2, 2, 1))
        );
        assert!(rt_bits(0, None).is_err());
        assert!(rt_bits(0, Some(0x80)).is_err());
        assert_eq!(rt_bits(0, Some(0x40)).map(|b| b.done), Ok(1));
        assert!(rt_bits(3, None).is_err());
    }
}
