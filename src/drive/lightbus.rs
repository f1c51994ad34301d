//! Beckhoff Lightbus drive family (AX2000 kind), master side (sans-IO).
//!
//! FCT-C4 §6.2: digital input 2 of the drive is the probing input when the drive parameter
//! IN2MODE = 26 (probe on X3 terminal 12); the edge comes from P-AXIS-00518
//! (`kenngr.measure.edge` POS / NEG, [`ProbeRequest::edge`]). Notes cnc.md §4.2: AX2000 IN2MODE 26,
//! the EtherCAT twin (AX2000-B110) has a 2-byte latch status word with positive / negative
//! valid bits and acknowledge codes in the high nibble.
//!
//! # Telegram (one definition, [`telegram`], shared by adapter and model)
//!
//! The Lightbus telegram layout below is **(assumption)**: the seeds and notes give no byte
//! layout, so it is modelled on the AX2000-B110 latch status word (Beckhoff AX2000 documentation). Little-endian.
//!
//! Command (master → drive, [`telegram::COMMAND_LEN`] = 12 bytes):
//!
//! | bytes | field | meaning |
//! |---|---|---|
//! | 0..2 | control word u16 | bit 0 enable, bit 1 fault reset (rising edge), bit 2 quick stop |
//! | 2..6 | position set-point i32 | increments |
//! | 6..10 | velocity set-point i32 | increments/s, feed-forward (the model ignores it) |
//! | 10..12 | latch control u16 | bit 0 latch rising edge of IN2, bit 1 falling edge, bits 12..15 arming sequence 1..15 (0 = disarmed) |
//!
//! Feedback (drive → master, [`telegram::FEEDBACK_LEN`] = 16 bytes):
//!
//! | bytes | field | meaning |
//! |---|---|---|
//! | 0..2 | status word u16 | bit 0 ready, bit 1 enabled, bit 2 quick stop active, bit 3 fault, bit 4 lag error, bit 5 torque limit active |
//! | 2..6 | actual position i32 | increments |
//! | 6..10 | following error i32 | set-point − actual, increments |
//! | 10..12 | latch status u16 | bit 0 rising-edge value valid, bit 1 falling-edge value valid, bit 4 IN2 level, bit 5 IN2MODE = 26, bits 12..15 acknowledged arming sequence |
//! | 12..16 | latched position i32 | increments |
//!
//! # No stale latch
//!
//! Every arming writes a new sequence number (1..15, never the one before); the drive clears its
//! valid bits when it takes a new sequence and echoes it. The adapter accepts a valid bit only
//! with its own sequence echoed and reports one event per arming, so a value latched under an
//! earlier arming can never be reported as new.
//!
//! # Power states
//!
//! Status word → [`PowerState`]: fault → `Fault`; quick stop → `QuickStopActive`; enabled →
//! `OperationEnabled`; ready → `SwitchedOn`; else `SwitchOnDisabled` (assumption: the AX2000 has
//! no CiA 402 state machine; this is the nearest mapping).

use super::catalogue::DriveDefinition;
use super::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger,
};
use crate::units::Nanos;
use std::collections::VecDeque;

/// IN2MODE value that makes digital input 2 the probing input (FCT-C4 §6.2).
pub const IN2MODE_PROBE: i64 = 26;

/// Parameter index of IN2MODE in the model's `read_object` / `write_object` (sub 0) —
/// an index of this crate's choosing (assumption: the AX2000 has no CANopen index for it).
pub const PARAM_IN2MODE: u16 = 0x2000;
/// Parameter index of the torque limit in 0.1 % of rated torque (u16; assumption).
pub const PARAM_TORQUE_LIMIT: u16 = 0x2001;
/// Parameter index of the lag (following error) window in increments (u32; 4294967295 = lag
/// monitoring off; assumption).
pub const PARAM_LAG_WINDOW: u16 = 0x2002;
/// Parameter index of the last error code (read-only; assumption).
pub const PARAM_ERROR_CODE: u16 = 0x2003;

/// Default arming time-out in cycles.
pub const DEFAULT_ARM_TIMEOUT_CYCLES: u32 = 100;

/// The Lightbus telegram, shared by [`LightbusAdapter`] and
/// [`crate::drive::model::lightbus::LightbusModel`] (layout: module documentation, assumption).
pub mod telegram {
    use crate::drive::DriveError;

    /// Bytes of the command telegram.
    pub const COMMAND_LEN: usize = 12;
    /// Bytes of the feedback telegram.
    pub const FEEDBACK_LEN: usize = 16;

    /// Control word bit 0: enable the drive.
    pub const CW_ENABLE: u16 = 1 << 0;
    /// Control word bit 1: fault reset (rising edge).
    pub const CW_RESET: u16 = 1 << 1;
    /// Control word bit 2: quick stop.
    pub const CW_QUICK_STOP: u16 = 1 << 2;

    /// Status word bit 0: ready (power on, no fault).
    pub const SW_READY: u16 = 1 << 0;
    /// Status word bit 1: enabled, following the set-point.
    pub const SW_ENABLED: u16 = 1 << 1;
    /// Status word bit 2: quick stop active.
    pub const SW_QUICK_STOP: u16 = 1 << 2;
    /// Status word bit 3: fault.
    pub const SW_FAULT: u16 = 1 << 3;
    /// Status word bit 4: lag (following) error.
    pub const SW_LAG: u16 = 1 << 4;
    /// Status word bit 5: torque limit active.
    pub const SW_LIMIT: u16 = 1 << 5;

    /// Latch control bit 0: latch on the rising edge of digital input 2.
    pub const LC_POS: u16 = 1 << 0;
    /// Latch control bit 1: latch on the falling edge of digital input 2.
    pub const LC_NEG: u16 = 1 << 1;
    /// Latch status bit 0: rising-edge value valid.
    pub const LS_POS_VALID: u16 = 1 << 0;
    /// Latch status bit 1: falling-edge value valid.
    pub const LS_NEG_VALID: u16 = 1 << 1;
    /// Latch status bit 4: level of digital input 2.
    pub const LS_IN2_LEVEL: u16 = 1 << 4;
    /// Latch status bit 5: IN2MODE = 26 (input 2 is the probing input).
    pub const LS_IN2_PROBE: u16 = 1 << 5;

    /// Arming sequence (bits 12..15) of a latch control or status word.
    pub const fn sequence(word: u16) -> u8 {
        (word >> 12) as u8
    }

    /// `word` with the arming sequence `seq` (0..=15) in bits 12..15.
    pub const fn with_sequence(word: u16, seq: u8) -> u16 {
        (word & 0x0FFF) | (((seq & 0x0F) as u16) << 12)
    }

    /// Command telegram.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct Command {
        /// Control word.
        pub control: u16,
        /// Position set-point, increments.
        pub position: i32,
        /// Velocity set-point (feed-forward), increments/s.
        pub velocity: i32,
        /// Latch control.
        pub latch_control: u16,
    }

    /// Feedback telegram.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct Feedback {
        /// Status word.
        pub status: u16,
        /// Actual position, increments.
        pub position: i32,
        /// Following error, increments.
        pub following_error: i32,
        /// Latch status.
        pub latch_status: u16,
        /// Latched position, increments.
        pub latch_position: i32,
    }

    fn short(expected: usize, got: usize) -> DriveError {
        DriveError::ImageTooShort { expected, got }
    }

    fn u16_at(b: &[u8], at: usize) -> u16 {
        u16::from_le_bytes([b[at], b[at + 1]])
    }

    fn i32_at(b: &[u8], at: usize) -> i32 {
        i32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
    }

    impl Command {
        /// Encode into `out` (at least [`COMMAND_LEN`] bytes).
        pub fn encode(&self, out: &mut [u8]) -> Result<(), DriveError> {
            let out = out
                .get_mut(..COMMAND_LEN)
                .ok_or_else(|| short(COMMAND_LEN, 0))?;
            out[0..2].copy_from_slice(&self.control.to_le_bytes());
            out[2..6].copy_from_slice(&self.position.to_le_bytes());
            out[6..10].copy_from_slice(&self.velocity.to_le_bytes());
            out[10..12].copy_from_slice(&self.latch_control.to_le_bytes());
            Ok(())
        }

        /// Decode from `b` (at least [`COMMAND_LEN`] bytes).
        pub fn decode(b: &[u8]) -> Result<Command, DriveError> {
            if b.len() < COMMAND_LEN {
                return Err(short(COMMAND_LEN, b.len()));
            }
            Ok(Command {
                control: u16_at(b, 0),
                position: i32_at(b, 2),
                velocity: i32_at(b, 6),
                latch_control: u16_at(b, 10),
            })
        }
    }

    impl Feedback {
        /// Encode into `out` (at least [`FEEDBACK_LEN`] bytes).
        pub fn encode(&self, out: &mut [u8]) -> Result<(), DriveError> {
            let got = out.len();
            let out = out
                .get_mut(..FEEDBACK_LEN)
                .ok_or_else(|| short(FEEDBACK_LEN, got))?;
            out[0..2].copy_from_slice(&self.status.to_le_bytes());
            out[2..6].copy_from_slice(&self.position.to_le_bytes());
            out[6..10].copy_from_slice(&self.following_error.to_le_bytes());
            out[10..12].copy_from_slice(&self.latch_status.to_le_bytes());
            out[12..16].copy_from_slice(&self.latch_position.to_le_bytes());
            Ok(())
        }

        /// Decode from `b` (at least [`FEEDBACK_LEN`] bytes).
        pub fn decode(b: &[u8]) -> Result<Feedback, DriveError> {
            if b.len() < FEEDBACK_LEN {
                return Err(short(FEEDBACK_LEN, b.len()));
            }
            Ok(Feedback {
                status: u16_at(b, 0),
                position: i32_at(b, 2),
                following_error: i32_at(b, 6),
                latch_status: u16_at(b, 10),
                latch_position: i32_at(b, 12),
            })
        }
    }
}

/// Family-section parsing shared by the Lightbus and terminal families: line-numbered errors
/// naming file, key and allowed values (toml_edit `ImDocument` spans).
pub(crate) mod section {
    use crate::drive::DriveError;
    use std::ops::Range;
    use toml_edit::{ImDocument, Item, TableLike, Value};

    /// One parsed family section.
    pub(crate) struct Section<'a> {
        file: &'a str,
        text: &'a str,
        doc: ImDocument<&'a str>,
        name: &'a str,
    }

    impl<'a> Section<'a> {
        /// Parse `text` and look at `[name]`.
        pub(crate) fn parse(
            text: &'a str,
            file: &'a str,
            name: &'a str,
        ) -> Result<Self, DriveError> {
            let doc = ImDocument::parse(text).map_err(|e| DriveError::Definition {
                file: file.to_string(),
                line: line_of(text, e.span()),
                message: format!("TOML syntax: {}", e.message().trim().replace('\n', "; ")),
            })?;
            let s = Section {
                file,
                text,
                doc,
                name,
            };
            if let Some(item) = s.doc.as_table().get(name) {
                if item.as_table_like().is_none() {
                    return Err(s.err(item.span(), format!("[{name}]: expected a table")));
                }
            }
            Ok(s)
        }

        fn table(&self) -> Option<&dyn TableLike> {
            self.doc.as_table().get(self.name)?.as_table_like()
        }

        pub(crate) fn err(&self, span: Option<Range<usize>>, message: String) -> DriveError {
            DriveError::Definition {
                file: self.file.to_string(),
                line: line_of(self.text, span),
                message,
            }
        }

        /// Unknown keys are errors.
        pub(crate) fn check_keys(&self, allowed: &[&str]) -> Result<(), DriveError> {
            let Some(t) = self.table() else {
                return Ok(());
            };
            for (k, _) in t.iter() {
                if !allowed.contains(&k) {
                    let span = t.get_key_value(k).and_then(|(key, _)| key.span());
                    return Err(self.err(
                        span,
                        format!(
                            "unknown key `{k}` in [{}]; allowed: {}",
                            self.name,
                            allowed.join(", ")
                        ),
                    ));
                }
            }
            Ok(())
        }

        fn span(&self, key: &str) -> Option<Range<usize>> {
            self.table()?.get(key)?.span()
        }

        /// An integer in `lo..=hi`.
        pub(crate) fn int(&self, key: &str, lo: i64, hi: i64) -> Result<Option<i64>, DriveError> {
            match self.table().and_then(|t| t.get(key)) {
                None => Ok(None),
                Some(Item::Value(Value::Integer(i))) if (lo..=hi).contains(i.value()) => {
                    Ok(Some(*i.value()))
                }
                Some(_) => Err(self.err(
                    self.span(key),
                    format!("[{}] {key}: expected an integer in {lo}..={hi}", self.name),
                )),
            }
        }

        /// A finite number `> 0`.
        pub(crate) fn positive(&self, key: &str) -> Result<Option<f64>, DriveError> {
            let v = match self.table().and_then(|t| t.get(key)) {
                None => return Ok(None),
                Some(Item::Value(Value::Float(f))) => *f.value(),
                Some(Item::Value(Value::Integer(i))) => *i.value() as f64,
                Some(_) => f64::NAN,
            };
            if v.is_finite() && v > 0.0 {
                Ok(Some(v))
            } else {
                Err(self.err(
                    self.span(key),
                    format!("[{}] {key}: expected a finite number > 0", self.name),
                ))
            }
        }

        /// One of `allowed` (case-insensitive); returns the index into `allowed`.
        pub(crate) fn choice(
            &self,
            key: &str,
            allowed: &[&str],
        ) -> Result<Option<usize>, DriveError> {
            let found = match self.table().and_then(|t| t.get(key)) {
                None => return Ok(None),
                Some(Item::Value(Value::String(s))) => allowed
                    .iter()
                    .position(|a| a.eq_ignore_ascii_case(s.value().trim())),
                Some(_) => None,
            };
            found.map(Some).ok_or_else(|| {
                let list: Vec<String> = allowed.iter().map(|a| format!("\"{a}\"")).collect();
                self.err(
                    self.span(key),
                    format!("[{}] {key}: allowed: {}", self.name, list.join(", ")),
                )
            })
        }
    }

    fn line_of(text: &str, span: Option<Range<usize>>) -> usize {
        span.map_or(0, |s| {
            let end = s.start.min(text.len());
            text.as_bytes()[..end]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1
        })
    }
}

/// `[lightbus]` section of a drive file.
///
/// ```toml
/// [lightbus]
/// in2mode = 26               # IN2MODE of the (emulated) drive, FCT-C4 §6.2
/// arm_timeout_cycles = 100   # cycles the adapter waits for the arming acknowledge
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LightbusConfig {
    /// IN2MODE the drive is configured with (default 26).
    pub in2mode: i64,
    /// Cycles the adapter waits for the drive to acknowledge an arming.
    pub arm_timeout_cycles: u32,
}

impl Default for LightbusConfig {
    fn default() -> Self {
        LightbusConfig {
            in2mode: IN2MODE_PROBE,
            arm_timeout_cycles: DEFAULT_ARM_TIMEOUT_CYCLES,
        }
    }
}

impl LightbusConfig {
    /// Parse `[lightbus]` from the drive file text (`def.source`); absent keys take defaults.
    pub fn from_definition(def: &DriveDefinition) -> Result<Self, DriveError> {
        let s = section::Section::parse(&def.source, &def.file, "lightbus")?;
        s.check_keys(&["in2mode", "arm_timeout_cycles"])?;
        let d = LightbusConfig::default();
        Ok(LightbusConfig {
            in2mode: s.int("in2mode", 0, 255)?.unwrap_or(d.in2mode),
            arm_timeout_cycles: s
                .int("arm_timeout_cycles", 1, 1_000_000)?
                .map_or(d.arm_timeout_cycles, |v| v as u32),
        })
    }
}

/// Plain-words check of the drive configuration for measuring (FCT-C4 §6.2): empty when the
/// drive can measure; otherwise one line per problem.
pub fn check_drive(in2mode: i64) -> Vec<String> {
    if in2mode == IN2MODE_PROBE {
        Vec::new()
    } else {
        vec![format!(
            "drive parameter IN2MODE is {in2mode}, but measuring needs IN2MODE = 26 \
             (digital input 2 as the probing input, probe on X3 terminal 12; seed 004 §6.2)"
        )]
    }
}

/// Map a Lightbus status word to the common power state (module docs; assumption).
pub fn decode_status(status: u16) -> PowerState {
    use telegram::*;
    if status & SW_FAULT != 0 {
        PowerState::Fault
    } else if status & SW_QUICK_STOP != 0 {
        PowerState::QuickStopActive
    } else if status & SW_ENABLED != 0 {
        PowerState::OperationEnabled
    } else if status & SW_READY != 0 {
        PowerState::SwitchedOn
    } else {
        PowerState::SwitchOnDisabled
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Latch {
    Idle,
    Arming {
        probe: u8,
        edge: ProbeEdge,
        seq: u8,
        waited: u32,
    },
    Armed {
        probe: u8,
        edge: ProbeEdge,
        seq: u8,
        reported: bool,
    },
    Failed(String),
}

/// Master-side adapter of a Lightbus AX2000 drive (module documentation).
#[derive(Debug)]
pub struct LightbusAdapter {
    config: LightbusConfig,
    latch: Latch,
    last_seq: u8,
    events: VecDeque<ProbeEvent>,
    /// IN2MODE = 26 as the last feedback showed it (`None` before the first feedback).
    in2_probe: Option<bool>,
    prev_target: Option<(Nanos, i32)>,
}

impl LightbusAdapter {
    /// The adapter for `def` (reads `[lightbus]`).
    pub fn new(def: &DriveDefinition) -> Result<Self, DriveError> {
        Ok(LightbusAdapter {
            config: LightbusConfig::from_definition(def)?,
            latch: Latch::Idle,
            last_seq: 0,
            events: VecDeque::new(),
            in2_probe: None,
            prev_target: None,
        })
    }

    /// The `[lightbus]` configuration.
    pub fn config(&self) -> &LightbusConfig {
        &self.config
    }

    /// [`check_drive`] for the configured IN2MODE and, once the drive has reported, its
    /// IN2MODE status bit.
    pub fn check(&self) -> Vec<String> {
        let mut out = check_drive(self.config.in2mode);
        if out.is_empty() && self.in2_probe == Some(false) {
            out.push(
                "the drive reports IN2MODE ≠ 26: digital input 2 is not the probing input \
                 (set IN2MODE = 26; seed 004 §6.2)"
                    .into(),
            );
        }
        out
    }

    fn latch_control(&self) -> u16 {
        use telegram::*;
        match self.latch {
            Latch::Arming { edge, seq, .. } | Latch::Armed { edge, seq, .. } => {
                let bit = if edge == ProbeEdge::Positive {
                    LC_POS
                } else {
                    LC_NEG
                };
                with_sequence(bit, seq)
            }
            Latch::Idle | Latch::Failed(_) => 0,
        }
    }
}

impl DriveAdapter for LightbusAdapter {
    fn power_stage_off(&self, state: PowerState) -> bool {
        super::torque_off(state)
    }

    fn output_len(&self) -> usize {
        telegram::COMMAND_LEN
    }

    fn input_len(&self) -> usize {
        telegram::FEEDBACK_LEN
    }

    fn read_inputs(&mut self, _now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError> {
        use telegram::*;
        let fb = Feedback::decode(inputs)?;
        let probe_ok = fb.latch_status & LS_IN2_PROBE != 0;
        self.in2_probe = Some(probe_ok);
        let ack = sequence(fb.latch_status);
        let timeout = self.config.arm_timeout_cycles;
        let valid_bit = |edge: ProbeEdge| {
            if edge == ProbeEdge::Positive {
                LS_POS_VALID
            } else {
                LS_NEG_VALID
            }
        };
        match &mut self.latch {
            Latch::Arming {
                probe,
                edge,
                seq,
                waited,
            } => {
                if !probe_ok {
                    self.latch = Latch::Failed(check_drive_status());
                } else if ack == *seq && fb.latch_status & (LS_POS_VALID | LS_NEG_VALID) == 0 {
                    self.latch = Latch::Armed {
                        probe: *probe,
                        edge: *edge,
                        seq: *seq,
                        reported: false,
                    };
                } else if ack == *seq {
                    // A valid bit together with our fresh sequence before the confirmation:
                    // the drive did not clear its latch on re-arming.
                    self.latch = Latch::Failed(
                        "the drive acknowledged the arming with a latch value still valid".into(),
                    );
                } else {
                    *waited += 1;
                    if *waited > timeout {
                        self.latch = Latch::Failed(format!(
                            "the drive did not acknowledge the arming (sequence {seq}) within \
                             {timeout} cycles"
                        ));
                    }
                }
            }
            Latch::Armed {
                probe,
                edge,
                seq,
                reported,
            } => {
                if !probe_ok {
                    self.latch = Latch::Failed(check_drive_status());
                } else if ack != *seq {
                    self.latch = Latch::Failed(format!(
                        "the drive dropped the arming (acknowledge {ack}, expected {seq})"
                    ));
                } else if !*reported && fb.latch_status & valid_bit(*edge) != 0 {
                    *reported = true;
                    self.events.push_back(ProbeEvent {
                        probe: *probe,
                        edge: *edge,
                        position: fb.latch_position,
                        sequence: 1,
                    });
                }
            }
            Latch::Idle | Latch::Failed(_) => {}
        }
        let state = decode_status(fb.status);
        Ok(DriveFeedback {
            state,
            statusword: fb.status,
            position: fb.position,
            following_error: Some(fb.following_error),
            mode_display: None,
            operational: state == PowerState::OperationEnabled,
            fault: state == PowerState::Fault,
            following_error_flag: fb.status & SW_LAG != 0,
            torque: None,
        })
    }

    fn write_outputs(
        &mut self,
        now: Nanos,
        command: &DriveCommand,
        outputs: &mut [u8],
    ) -> Result<(), DriveError> {
        use telegram::*;
        if outputs.len() < COMMAND_LEN {
            return Err(DriveError::ImageTooShort {
                expected: COMMAND_LEN,
                got: outputs.len(),
            });
        }
        let mut control = 0;
        if command.enable {
            control |= CW_ENABLE;
        }
        if command.fault_reset {
            control |= CW_RESET;
        }
        if command.quick_stop {
            control |= CW_QUICK_STOP;
        }
        // Velocity feed-forward: set-point difference over the time since the last write.
        let velocity = match self.prev_target {
            Some((t, p)) if now > t => {
                let dt = (now.0 - t.0) as f64 * 1e-9;
                let v = (f64::from(command.target) - f64::from(p)) / dt;
                v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
            }
            _ => 0,
        };
        self.prev_target = Some((now, command.target));
        Command {
            control,
            position: command.target,
            velocity,
            latch_control: self.latch_control(),
        }
        .encode(outputs)
    }

    fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        let problems = self.check();
        if !problems.is_empty() {
            return Err(DriveError::Unsupported(problems.join("; ")));
        }
        if request.trigger != ProbeTrigger::Input {
            return Err(DriveError::Unsupported(
                "Lightbus drive: the probe latches on digital input 2 only (no zero-pulse or \
                 source-object trigger)"
                    .into(),
            ));
        }
        if request.continuous {
            return Err(DriveError::Unsupported(
                "Lightbus drive: the latch keeps the first edge of an arming; continuous mode \
                 is not supported (assumption)"
                    .into(),
            ));
        }
        // A new sequence number, never the previous one, never 0.
        let seq = self.last_seq % 15 + 1;
        self.last_seq = seq;
        self.events.clear();
        self.latch = Latch::Arming {
            probe: request.probe,
            edge: request.edge,
            seq,
            waited: 0,
        };
        Ok(())
    }

    fn disarm_probe(&mut self) {
        self.latch = Latch::Idle;
        self.events.clear();
    }

    fn probe_state(&self) -> ProbeState {
        match &self.latch {
            Latch::Idle => ProbeState::Idle,
            Latch::Arming { .. } => ProbeState::Arming,
            Latch::Armed { .. } => ProbeState::Armed,
            Latch::Failed(why) => ProbeState::Failed(why.clone()),
        }
    }

    fn take_probe_event(&mut self) -> Option<ProbeEvent> {
        self.events.pop_front()
    }
}

fn check_drive_status() -> String {
    "the drive reports IN2MODE ≠ 26: digital input 2 is not the probing input (set IN2MODE = \
     26; seed 004 §6.2)"
        .into()
}
