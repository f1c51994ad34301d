//! Terminal drive family: a velocity output (±10 V analog terminal) as set-point and a Beckhoff
//! KL5101 / EL5101 incremental encoder terminal as position feedback and latch unit, master side
//! (sans-IO). FCT-C4 §6.3 (probe on terminal 4 of the KL5101; P-AXIS-00518 positive edge only,
//! "measurement at negative edge is not supported by the Encoder Interface"); Beckhoff KL5101 /
//! EL5101 documentation (control / status byte bits, 16-bit counter and latch, re-arm protocol).
//!
//! # Process image (one definition, [`image`], shared with the model; assumption: the seeds give
//! the encoder bits, not the combined layout)
//!
//! Output (master → terminals, [`image::OUTPUT_LEN`] = 6 bytes, little-endian):
//!
//! | bytes | field |
//! |---|---|
//! | 0 | encoder control byte: CB0 EN_LATC (latch on C track), CB1 EN_LATCH_EXTP (rising external edge; KL5101 EN_LATEXT), CB2 CNT_SET (rising edge sets the counter), CB3 EN_LATCH_EXTN (falling external edge, EL5101 only) |
//! | 1..3 | counter set value u16 |
//! | 3..5 | velocity output i16: ±32767 = ±10 V = ±`[terminal] full_scale_velocity` (assumption) |
//! | 5 | drive digital outputs: bit 0 amplifier enable, bit 1 fault reset (assumption) |
//!
//! Input (terminals → master, [`image::INPUT_LEN`] = 6 bytes):
//!
//! | bytes | field |
//! |---|---|
//! | 0 | encoder status byte: SB0 LATC_VAL, SB1 LAT_EXT_VAL, SB2 CNTSET_ACC, SB3 UNDERFLOW, SB4 OVERFLOW, SB5 level of the external latch input |
//! | 1..3 | counter u16 |
//! | 3..5 | latch value u16 |
//! | 5 | drive digital inputs: bit 0 ready, bit 1 enabled, bit 2 fault (assumption) |
//!
//! # Position
//!
//! The 16-bit counter is extended to 64 bits with the `int16_t` delta method (Beckhoff EL5101 / KL5101 documentation,
//! linuxcnc-ethercat `lcec_el5101.c`): `ext += (counter − last) as i16`; the latch value is
//! extended relative to the counter of the same cycle: `ext + (latch − counter) as i16`. Both are
//! exact while the axis moves less than 32767 increments per cycle. The position after
//! power-up is the counter sign-extended (an incremental encoder; assumption).
//!
//! # Control law (assumption)
//!
//! Velocity output `v = (r_k − r_{k−1}) / T + kp · (r_{k−1−d} − x_k)` (set-point feed-forward
//! plus a P position loop on the error to the set-point the axis should have reached when the
//! counter value `x_k` was sampled, `d` cycles before the exchange that carried it:
//! [`DriveAdapter::set_feedback_delay`], 1 on every link). With the model's integrating
//! amplifier the error obeys `e_{k+1} = e_k − kp·T · e_{k−d}`; kp (default 200 1/s) is capped at
//! `1 / ((1 + d)·T)` so that the delayed loop stays damped at long cycles. The output is
//! `round(v / full_scale · 32767)` clipped to ±32767. Disabled: output 0.
//!
//! # Latch (re-arm protocol, Beckhoff EL5101 / KL5101 documentation)
//!
//! Arming: clear the enable bit → wait for its *_VAL = 0 → set the enable bit → armed. A *_VAL
//! bit is accepted only after it was seen 0 under this arming, so a stale latch value is never
//! reported. One edge per arming (first event; "continuous mode is not supported"). KL5101:
//! C track or rising external edge; a falling edge is refused ([`check_edge`]). EL5101: also the
//! falling external edge (CB3). The terminal has no torque limit and no lag monitoring: the
//! drive file has no `[functions]`.

use super::catalogue::DriveDefinition;
use super::lightbus::section::Section;
use super::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger,
};
use crate::units::Nanos;
use std::collections::VecDeque;

/// The terminal process image shared by [`TerminalAdapter`] and
/// [`crate::drive::model::terminal::TerminalModel`] (module documentation).
pub mod image {
    use crate::drive::DriveError;

    /// Output image bytes.
    pub const OUTPUT_LEN: usize = 6;
    /// Input image bytes.
    pub const INPUT_LEN: usize = 6;

    /// CB0 EN_LATC: latch the counter on the C track (zero pulse).
    pub const CB_EN_LATC: u8 = 1 << 0;
    /// CB1 EN_LATCH_EXTP: latch on the rising edge of the external input (KL5101 EN_LATEXT).
    pub const CB_EN_LATCH_EXTP: u8 = 1 << 1;
    /// CB2 CNT_SET: a rising edge sets the counter to the set value.
    pub const CB_CNT_SET: u8 = 1 << 2;
    /// CB3 EN_LATCH_EXTN: latch on the falling edge (EL5101 only).
    pub const CB_EN_LATCH_EXTN: u8 = 1 << 3;

    /// SB0 LATC_VAL.
    pub const SB_LATC_VAL: u8 = 1 << 0;
    /// SB1 LAT_EXT_VAL.
    pub const SB_LAT_EXT_VAL: u8 = 1 << 1;
    /// SB2 CNTSET_ACC.
    pub const SB_CNTSET_ACC: u8 = 1 << 2;
    /// SB3 UNDERFLOW.
    pub const SB_UNDERFLOW: u8 = 1 << 3;
    /// SB4 OVERFLOW.
    pub const SB_OVERFLOW: u8 = 1 << 4;
    /// SB5 level of the external latch input.
    pub const SB_LATCH_INPUT: u8 = 1 << 5;

    /// Drive output bit 0: amplifier enable.
    pub const DO_ENABLE: u8 = 1 << 0;
    /// Drive output bit 1: fault reset.
    pub const DO_RESET: u8 = 1 << 1;
    /// Drive input bit 0: ready.
    pub const DI_READY: u8 = 1 << 0;
    /// Drive input bit 1: enabled.
    pub const DI_ENABLED: u8 = 1 << 1;
    /// Drive input bit 2: fault.
    pub const DI_FAULT: u8 = 1 << 2;

    /// Output image.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct Outputs {
        /// Encoder control byte.
        pub control: u8,
        /// Counter set value.
        pub set_value: u16,
        /// Velocity output (±32767 = ±10 V).
        pub velocity: i16,
        /// Drive digital outputs.
        pub drive: u8,
    }

    /// Input image.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct Inputs {
        /// Encoder status byte.
        pub status: u8,
        /// Counter.
        pub counter: u16,
        /// Latch value.
        pub latch: u16,
        /// Drive digital inputs.
        pub drive: u8,
    }

    fn short(expected: usize, got: usize) -> DriveError {
        DriveError::ImageTooShort { expected, got }
    }

    impl Outputs {
        /// Encode into `out` (≥ [`OUTPUT_LEN`] bytes).
        pub fn encode(&self, out: &mut [u8]) -> Result<(), DriveError> {
            let got = out.len();
            let o = out
                .get_mut(..OUTPUT_LEN)
                .ok_or_else(|| short(OUTPUT_LEN, got))?;
            o[0] = self.control;
            o[1..3].copy_from_slice(&self.set_value.to_le_bytes());
            o[3..5].copy_from_slice(&self.velocity.to_le_bytes());
            o[5] = self.drive;
            Ok(())
        }

        /// Decode from `b` (≥ [`OUTPUT_LEN`] bytes).
        pub fn decode(b: &[u8]) -> Result<Self, DriveError> {
            if b.len() < OUTPUT_LEN {
                return Err(short(OUTPUT_LEN, b.len()));
            }
            Ok(Outputs {
                control: b[0],
                set_value: u16::from_le_bytes([b[1], b[2]]),
                velocity: i16::from_le_bytes([b[3], b[4]]),
                drive: b[5],
            })
        }
    }

    impl Inputs {
        /// Encode into `out` (≥ [`INPUT_LEN`] bytes).
        pub fn encode(&self, out: &mut [u8]) -> Result<(), DriveError> {
            let got = out.len();
            let o = out
                .get_mut(..INPUT_LEN)
                .ok_or_else(|| short(INPUT_LEN, got))?;
            o[0] = self.status;
            o[1..3].copy_from_slice(&self.counter.to_le_bytes());
            o[3..5].copy_from_slice(&self.latch.to_le_bytes());
            o[5] = self.drive;
            Ok(())
        }

        /// Decode from `b` (≥ [`INPUT_LEN`] bytes).
        pub fn decode(b: &[u8]) -> Result<Self, DriveError> {
            if b.len() < INPUT_LEN {
                return Err(short(INPUT_LEN, b.len()));
            }
            Ok(Inputs {
                status: b[0],
                counter: u16::from_le_bytes([b[1], b[2]]),
                latch: u16::from_le_bytes([b[3], b[4]]),
                drive: b[5],
            })
        }
    }
}

/// Encoder terminal variant (`[terminal] variant`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    /// KL5101 (K-bus): C track and rising external edge only.
    Kl5101,
    /// EL5101 (EtherCAT): also the falling external edge (CB3).
    El5101,
}

impl Variant {
    /// Name in drive files.
    pub const fn name(self) -> &'static str {
        match self {
            Variant::Kl5101 => "KL5101",
            Variant::El5101 => "EL5101",
        }
    }
}

/// `[terminal]` section.
///
/// ```toml
/// [terminal]
/// variant = "KL5101"            # or "EL5101"
/// full_scale_velocity = 1000.0  # units/s at +10 V (32767)
/// kp = 200.0                    # adapter position loop gain, 1/s
/// arm_timeout_cycles = 100
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerminalConfig {
    /// Encoder terminal variant (default KL5101).
    pub variant: Variant,
    /// Axis units/s at full scale of the velocity output (default 1000; assumption).
    pub full_scale_velocity: f64,
    /// Position loop gain of the adapter, 1/s (default 200; assumption).
    pub kp: f64,
    /// Cycles each re-arm step may take before the latch is reported failed (default 100).
    pub arm_timeout_cycles: u32,
}

impl Default for TerminalConfig {
    fn default() -> Self {
        TerminalConfig {
            variant: Variant::Kl5101,
            full_scale_velocity: 1000.0,
            kp: 200.0,
            arm_timeout_cycles: 100,
        }
    }
}

impl TerminalConfig {
    /// Parse `[terminal]` from `def.source` (errors name file, line, key and allowed values).
    pub fn from_definition(def: &DriveDefinition) -> Result<Self, DriveError> {
        let s = Section::parse(&def.source, &def.file, "terminal")?;
        s.check_keys(&["variant", "full_scale_velocity", "kp", "arm_timeout_cycles"])?;
        let d = TerminalConfig::default();
        let variant = match s.choice("variant", &["KL5101", "EL5101"])? {
            Some(1) => Variant::El5101,
            Some(_) => Variant::Kl5101,
            None => d.variant,
        };
        Ok(TerminalConfig {
            variant,
            full_scale_velocity: s
                .positive("full_scale_velocity")?
                .unwrap_or(d.full_scale_velocity),
            kp: s.positive("kp")?.unwrap_or(d.kp),
            arm_timeout_cycles: s
                .int("arm_timeout_cycles", 1, 1_000_000)?
                .map_or(d.arm_timeout_cycles, |v| v as u32),
        })
    }
}

/// Parameter check for a terminal axis (FCT-C4 §6.3): P-AXIS-00518 must be POS on a KL5101.
/// Returns the parameter errors in plain words (empty = fine).
pub fn check_edge(variant: Variant, edge: ProbeEdge) -> Vec<String> {
    if variant == Variant::Kl5101 && edge == ProbeEdge::Negative {
        vec![
            "P-AXIS-00518 (kenngr.measure.edge) = NEG is not allowed on a terminal drive with a \
             KL5101 encoder interface: it latches on the positive edge only; allowed value: POS \
             (seed 004 §6.3)"
                .into(),
        ]
    } else {
        Vec::new()
    }
}

/// [`check_edge`] for an axis parameter list: the edge as the run reads it — P-AXIS-00518
/// (`POS` / `NEG`), else the old P-AXIS-00113 (1 = negative edge)
/// ([`ProbeSettings`](crate::core::measure::source::ProbeSettings)).
pub fn check_axis_params(variant: Variant, axis: &crate::params::ParamSet) -> Vec<String> {
    match crate::core::measure::source::ProbeSettings::from_params(axis) {
        Ok(p) => check_edge(variant, p.edge),
        Err(e) => vec![e],
    }
}

/// Extends a 16-bit counter to 64 bits (`int16_t` delta method).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CounterExtender {
    last: Option<u16>,
    ext: i64,
}

impl CounterExtender {
    /// Feed this cycle's counter; returns the extended position.
    pub fn update(&mut self, counter: u16) -> i64 {
        self.ext = match self.last {
            None => i64::from(counter as i16),
            Some(last) => self.ext + i64::from(counter.wrapping_sub(last) as i16),
        };
        self.last = Some(counter);
        self.ext
    }

    /// The extended value of a 16-bit `latch` taken near the last counter value.
    pub fn extend(&self, latch: u16) -> i64 {
        match self.last {
            None => i64::from(latch as i16),
            Some(last) => self.ext + i64::from(latch.wrapping_sub(last) as i16),
        }
    }

    /// Extended position of the last update.
    pub fn position(&self) -> i64 {
        self.ext
    }

    /// Re-base after a counter set: the terminal loaded `set_value` and now shows `counter`
    /// (set value plus the motion since); the extended position becomes `value` plus that motion.
    pub fn rebase(&mut self, value: i64, set_value: u16, counter: u16) {
        self.ext = value.saturating_add(i64::from(counter.wrapping_sub(set_value) as i16));
        self.last = Some(counter);
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Enable bit written 0 (`written`), waiting for *_VAL = 0.
    Clearing { written: bool },
    /// Enable bit written 1 (`written`), waiting for the next input image.
    Enabling { written: bool },
    /// Armed; `reported` once the event was taken.
    Armed { reported: bool },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Arming {
    request: ProbeRequest,
    enable: u8,
    valid: u8,
    phase: Phase,
    waited: u32,
}

/// Master-side adapter of a terminal drive (module documentation).
#[derive(Debug)]
pub struct TerminalAdapter {
    config: TerminalConfig,
    /// Increments per axis unit (for the velocity output scaling).
    inc_per_unit: f64,
    counter: CounterExtender,
    arming: Option<Arming>,
    failure: Option<String>,
    events: VecDeque<ProbeEvent>,
    /// Time of the previous write.
    prev: Option<Nanos>,
    /// Set-points sent (the position while disabled), newest first.
    sent: super::SentSetpoints,
    /// Extended position of the last read.
    position: i64,
    enabled_in: bool,
    /// Counter set in progress: the extended position wanted and the cycles waited.
    preset: Option<(i64, u32)>,
    /// Cycles between sampling the counter and reading it ([`DriveAdapter::set_feedback_delay`]).
    delay: u32,
}

impl TerminalAdapter {
    /// The adapter for `def` (reads `[terminal]`); refuses a KL5101 axis whose P-AXIS-00518 is
    /// NEG (FCT-C4 §6.3) with the parameter error.
    pub fn new(def: &DriveDefinition, axis: &crate::params::ParamSet) -> Result<Self, DriveError> {
        let config = TerminalConfig::from_definition(def)?;
        let problems = check_axis_params(config.variant, axis);
        if !problems.is_empty() {
            return Err(DriveError::Unsupported(problems.join("; ")));
        }
        Ok(TerminalAdapter {
            config,
            inc_per_unit: def.scaling.increments_per_unit.abs(),
            counter: CounterExtender::default(),
            arming: None,
            failure: None,
            events: VecDeque::new(),
            prev: None,
            sent: super::SentSetpoints::default(),
            position: 0,
            enabled_in: false,
            preset: None,
            delay: 1,
        })
    }

    /// Set the axis position (increments) by the terminal's counter set (CB2 CNT_SET; notes
    /// cnc.md §4.1), e.g. when referencing: CNT_SET with the set value `value mod 2^16` is
    /// written until the terminal reports CNTSET_ACC, then the extended position continues from
    /// `value`. Refused while the amplifier is enabled (the position would jump under the
    /// position loop) or a latch is armed (its value would be on the old count).
    pub fn preset_counter(&mut self, value: i64) -> Result<(), DriveError> {
        if self.enabled_in {
            return Err(DriveError::Unsupported(
                "encoder terminal: the counter can only be set with the amplifier disabled".into(),
            ));
        }
        if self.arming.is_some() {
            return Err(DriveError::Unsupported(
                "encoder terminal: the counter cannot be set while a latch is armed".into(),
            ));
        }
        self.preset = Some((value, 0));
        Ok(())
    }

    /// A counter set is in progress.
    pub fn presetting(&self) -> bool {
        self.preset.is_some()
    }

    /// The `[terminal]` configuration.
    pub fn config(&self) -> &TerminalConfig {
        &self.config
    }

    fn control_byte(&self) -> u8 {
        match self.arming {
            Some(Arming {
                enable,
                phase: Phase::Enabling { .. } | Phase::Armed { .. },
                ..
            }) => enable,
            _ => 0,
        }
    }

    fn fail(&mut self, why: String) {
        self.failure = Some(why);
        self.arming = None;
    }
}

impl DriveAdapter for TerminalAdapter {
    fn power_stage_off(&self, state: PowerState) -> bool {
        super::torque_off(state)
    }

    fn set_feedback_delay(&mut self, cycles: u32) {
        self.delay = cycles;
        self.sent.set_delay(cycles);
    }

    fn output_len(&self) -> usize {
        image::OUTPUT_LEN
    }

    fn input_len(&self) -> usize {
        image::INPUT_LEN
    }

    fn read_inputs(&mut self, _now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError> {
        use image::*;
        let i = Inputs::decode(inputs)?;
        let timeout = self.config.arm_timeout_cycles;
        match self.preset {
            Some((value, _)) if i.status & SB_CNTSET_ACC != 0 => {
                self.counter.rebase(value, value as u16, i.counter);
                self.position = self.counter.position();
                self.preset = None;
            }
            Some((value, waited)) => {
                self.position = self.counter.update(i.counter);
                if waited >= timeout {
                    self.preset = None;
                    return Err(DriveError::Unsupported(format!(
                        "encoder terminal: counter set not acknowledged (CNTSET_ACC) within \
                         {timeout} cycles"
                    )));
                }
                self.preset = Some((value, waited + 1));
            }
            None => self.position = self.counter.update(i.counter),
        }
        if let Some(mut a) = self.arming {
            let val = i.status & a.valid != 0;
            match a.phase {
                Phase::Clearing { written } => {
                    if written && !val {
                        a.phase = Phase::Enabling { written: false };
                        a.waited = 0;
                    } else {
                        a.waited += 1;
                    }
                }
                Phase::Enabling { written } => {
                    if written {
                        a.phase = Phase::Armed { reported: false };
                    }
                }
                Phase::Armed { .. } => {}
            }
            if let Phase::Armed { reported: false } = a.phase {
                if val {
                    a.phase = Phase::Armed { reported: true };
                    let pos = self.counter.extend(i.latch);
                    self.events.push_back(ProbeEvent {
                        probe: a.request.probe,
                        edge: a.request.edge,
                        position: pos.clamp(i32::MIN.into(), i32::MAX.into()) as i32,
                        sequence: 1,
                    });
                }
            }
            self.arming = Some(a);
            if a.waited > timeout {
                self.fail(format!(
                    "the encoder terminal did not clear its latch valid bit within {timeout} \
                     cycles (re-arm protocol: clear enable, wait for *_VAL = 0)"
                ));
            }
        }
        let fault = i.drive & DI_FAULT != 0;
        let ready = i.drive & DI_READY != 0;
        self.enabled_in = i.drive & DI_ENABLED != 0;
        let state = if fault {
            PowerState::Fault
        } else if self.enabled_in {
            PowerState::OperationEnabled
        } else if ready {
            PowerState::SwitchedOn
        } else {
            PowerState::SwitchOnDisabled
        };
        Ok(DriveFeedback {
            state,
            statusword: u16::from(i.status) | (u16::from(i.drive) << 8),
            position: self.position.clamp(i32::MIN.into(), i32::MAX.into()) as i32,
            following_error: None,
            mode_display: None,
            operational: state == PowerState::OperationEnabled,
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
        use image::*;
        if outputs.len() < OUTPUT_LEN {
            return Err(DriveError::ImageTooShort {
                expected: OUTPUT_LEN,
                got: outputs.len(),
            });
        }
        let target = f64::from(command.target);
        let x = self.position as f64;
        let following = command.enable && self.enabled_in;
        let velocity = match (self.prev, self.sent.last(), self.sent.reference()) {
            (Some(t), Some(r_prev), Some(r_ref)) if following && now > t => {
                let dt = (now.0 - t.0) as f64 * 1e-9;
                // The actual value was sampled `delay` cycles back: compare it with the
                // set-point of that time; the gain is capped so that the delayed loop stays
                // well damped (kp·T ≤ 1 / (1 + delay)).
                let kp = self
                    .config
                    .kp
                    .min(1.0 / ((1.0 + f64::from(self.delay)) * dt));
                let v = (target - f64::from(r_prev)) / dt + kp * (f64::from(r_ref) - x);
                let full = self.config.full_scale_velocity * self.inc_per_unit;
                let raw = (v / full * 32767.0).round();
                if raw.is_finite() {
                    raw.clamp(-32767.0, 32767.0) as i16
                } else {
                    0
                }
            }
            _ => 0,
        };
        self.prev = Some(now);
        if !following {
            self.sent.clear();
        }
        self.sent.push(if following {
            command.target
        } else {
            x.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
        });
        let mut drive = 0;
        if command.enable {
            drive |= DO_ENABLE;
        }
        if command.fault_reset {
            drive |= DO_RESET;
        }
        let control = self.control_byte();
        if let Some(a) = self.arming.as_mut() {
            match &mut a.phase {
                Phase::Clearing { written } | Phase::Enabling { written } => *written = true,
                Phase::Armed { .. } => {}
            }
        }
        let (control, set_value) = match self.preset {
            Some((value, _)) => (control | CB_CNT_SET, value as u16),
            None => (control, 0),
        };
        Outputs {
            control,
            set_value,
            velocity,
            drive,
        }
        .encode(outputs)
    }

    fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        use image::*;
        if self.preset.is_some() {
            return Err(DriveError::Unsupported(
                "encoder terminal: a counter set is in progress".into(),
            ));
        }
        let (enable, valid) = match request.trigger {
            ProbeTrigger::ZeroPulse => (CB_EN_LATC, SB_LATC_VAL),
            ProbeTrigger::Input => {
                let problems = check_edge(self.config.variant, request.edge);
                if !problems.is_empty() {
                    return Err(DriveError::Unsupported(problems.join("; ")));
                }
                match request.edge {
                    ProbeEdge::Positive => (CB_EN_LATCH_EXTP, SB_LAT_EXT_VAL),
                    ProbeEdge::Negative => (CB_EN_LATCH_EXTN, SB_LAT_EXT_VAL),
                }
            }
            ProbeTrigger::SourceObject => {
                return Err(DriveError::Unsupported(
                    "encoder terminal: no trigger source object; latch on the C track or the \
                     external latch input"
                        .into(),
                ))
            }
        };
        if request.continuous {
            return Err(DriveError::Unsupported(
                "encoder terminal: one edge per arming; continuous mode is not supported \
                 (Beckhoff EL5101 / KL5101 documentation)"
                    .into(),
            ));
        }
        self.events.clear();
        self.failure = None;
        self.arming = Some(Arming {
            request: *request,
            enable,
            valid,
            phase: Phase::Clearing { written: false },
            waited: 0,
        });
        Ok(())
    }

    fn disarm_probe(&mut self) {
        self.arming = None;
        self.failure = None;
        self.events.clear();
    }

    fn probe_state(&self) -> ProbeState {
        if let Some(f) = &self.failure {
            return ProbeState::Failed(f.clone());
        }
        match self.arming.map(|a| a.phase) {
            None => ProbeState::Idle,
            Some(Phase::Armed { .. }) => ProbeState::Armed,
            Some(_) => ProbeState::Arming,
        }
    }

    fn take_probe_event(&mut self) -> Option<ProbeEvent> {
        self.events.pop_front()
    }
}
