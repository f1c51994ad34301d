//! CiA 402 master-side adapter (CANopen and CoE over EtherCAT), sans-IO.
//!
//! [`Ds402Adapter`] drives the CiA 402 power state machine (CiA 402 §6.2) from the last
//! statusword (0x6041) it decoded and commands cyclic synchronous position mode (CSP, 0x6060 = 8)
//! with the target position 0x607A. It owns these objects of the output image: 0x6040
//! controlword, 0x607A target position, 0x6060 modes of operation (when mapped) and the objects
//! listed in `[rxpdo] defaults` of the drive file; every other mapped output byte is left as the
//! caller put it.
//!
//! # Controlword sequence (CiA 402 §6.3)
//!
//! | last state | command | controlword |
//! |---|---|---|
//! | FAULT / FAULT REACTION ACTIVE | `fault_reset` | 0x00 for one cycle, then 0x80 (rising edge of bit 7); repeated while the fault stays |
//! | FAULT / FAULT REACTION ACTIVE | no reset | 0x00 (disable voltage) |
//! | any other | `quick_stop` | 0x02 (quick stop) |
//! | QUICK STOP ACTIVE | released | 0x00 (disable voltage, transition 12 — valid for every quick stop option code) |
//! | any other | `!enable` | 0x06 (shutdown) |
//! | SWITCH ON DISABLED, NOT READY, unknown | `enable` | 0x06 (shutdown, transition 2) |
//! | READY TO SWITCH ON | `enable` | 0x07 (switch on, transition 3) |
//! | SWITCHED ON, OPERATION ENABLED | `enable` | 0x0F (enable operation, transition 4) |
//!
//! # Touch probe (CiA 402 0x60B8 / 0x60B9 / 0x60BA–0x60BD, 0x60D0, 0x60D5–0x60D8)
//!
//! When 0x60B8 is mapped the adapter owns it and writes it every cycle (0 while nothing is
//! armed). [`DriveAdapter::arm_probe`] starts a small state machine so that **no stale value is
//! ever reported as new**:
//!
//! A confirmation only counts from an input image read after the phase's word went out in an
//! output image. On a bus whose drives sample at SYNC0 (every link: the image of an exchange
//! was sampled one exchange earlier) the first such image may still be from before the drive
//! saw the word; it can then only confirm a state the drive was already in — the disabled probe
//! of *Clearing*, which the probe was in, or nothing for *Enabling* (a probe that was not
//! enabled with clear stored bits cannot show "enabled, stored bits clear" before it saw the
//! word) — so no stale value is ever reported; the sequence is only a cycle shorter.
//!
//! 1. *Clearing* — when the probe is enabled in the last 0x60B9 (bit 0 / 8), when no 0x60B9 was
//!    seen yet, when the adapter's last word for that probe was not 0, or when the drive file
//!    says `[probe] rearm_requires_zero = true`: write 0 to the probe's byte and wait until 0x60B9
//!    shows the probe disabled.
//! 2. *Enabling* — write the function byte and wait until 0x60B9 shows the probe enabled with
//!    both stored bits clear → [`ProbeState::Armed`].
//!
//! Each step gives up after `[probe] arm_timeout_cycles` images → [`ProbeState::Failed`]. A
//! fault, or leaving *operation enabled*, while arming or armed → `Failed` as well.
//!
//! Function byte ([`touch_probe_byte`]; probe 1 in the low byte, probe 2 in the high byte): bit 0
//! enable, bit 1 continuous, bits 3,2 source (`Input` 00b, `ZeroPulse` 01b, `SourceObject` 10b;
//! `CNC_DEFINED` and `DRIVE_DEFINED` (P-AXIS-00702) both select 10b), bit 4 positive edge, bit 5
//! negative edge.
//!
//! Events ([`DriveAdapter::take_probe_event`]; `sequence` counts the events of the current
//! arming):
//!
//! - **first event**: the rising of the requested edge's stored bit (0x60B9 bit 1 positive /
//!   bit 2 negative; 9 / 10 for probe 2) yields one event with 0x60BA / 0x60BB (0x60BC / 0x60BD).
//!   Later changes are not events. A stored bit that falls again without a re-arm → `Failed`.
//!   The enable bit may drop after the event (drives that end the single shot so); before it,
//!   that is `Failed`.
//! - **continuous**, edge counters 0x60D5–0x60D8 mapped (TP1 positive, TP1 negative, TP2
//!   positive, TP2 negative; `UNSIGNED16`, wrapping): a counter step of 1 is one event. A jump of
//!   k > 1 means k − 1 latches were overwritten before the master saw them: the state becomes
//!   `Failed("… lost k−1 …")`, and the value in the object is reported once as an event with
//!   `sequence` advanced by k — the counter says exactly which latch it is (the k-th since the
//!   last one reported), so a consumer sees the gap; no latch is ever reported twice.
//! - **continuous**, no counters: every change of the per-edge toggle bit — 0x60B9 bit 6
//!   positive / bit 7 negative (14 / 15 for probe 2), **vendor-specific, as Yaskawa Σ-X** — is
//!   one event. Two latches within one cycle flip the toggle twice and cannot be seen; the first
//!   latch after arming is cross-checked: a stored bit that rises without a toggle change (two
//!   latches in the first cycle, or a drive without toggle bits) → `Failed`.
//! - **`DRIVE_DEFINED`** (FCT-C4 §6.4: "a different evaluation of the latch status word"):
//!   the trigger is whatever 0x60D0 says in the drive, which may have no polarity of its own, so
//!   *either* stored bit (positive or negative) counts as the event and the value comes from the
//!   object matching the bit that rose (0x60BA for bit 1, 0x60BB for bit 2). If both rise in the
//!   same image, the edge of the request (P-AXIS-00518) is taken in first-event mode; in
//!   continuous mode both are reported, positive first. The control byte still samples only the
//!   requested edge.
//! - **`CNC_DEFINED`**: the CNC defines the source: 0x60D0 sub `probe` = the input of
//!   P-AXIS-00517. When 0x60D0:0n is mapped in the RxPDO the adapter writes it cyclically;
//!   otherwise the caller writes it acyclically before arming ([`Ds402Adapter::acyclic_probe_setup`]).
//!
//! One probe is armed at a time: arming the other probe switches the first one off (its byte
//! becomes 0). [`DriveAdapter::disarm_probe`] writes 0 to the probe's byte and drops pending
//! events.
//!
//! Residual race (documented, not handled): a drive that answers 0x60B8 several cycles late and
//! is re-armed faster than it answers may confirm an older configuration.

use super::catalogue::{DriveDefinition, OutputDefault, ProbeConfig};
use super::pdo::{DataType, PdoLayout};
use super::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger, TriggerSourceMode,
};
use crate::units::Nanos;
use std::collections::VecDeque;

/// Controlword 0x6040 commands (CiA 402 §6.3 Table "command coding").
pub mod controlword {
    /// Disable voltage (transitions 7, 9, 10, 12).
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop (transitions 7, 10, 11).
    pub const QUICK_STOP: u16 = 0x0002;
    /// Shutdown (transitions 2, 6, 8).
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on / disable operation (transitions 3, 5).
    pub const SWITCH_ON: u16 = 0x0007;
    /// Enable operation (transitions 4, 16).
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Fault reset (transition 15 on the rising edge of bit 7).
    pub const FAULT_RESET: u16 = 0x0080;
}

/// Mode of operation 8: cyclic synchronous position (CiA 402 0x6060).
pub const MODE_CSP: i8 = 8;

/// Touch probe function 0x60B8, bits of one probe's byte (probe 1: low byte, probe 2: high
/// byte; CiA 402).
pub mod probe_function {
    /// Bit 0: enable the touch probe.
    pub const ENABLE: u8 = 0x01;
    /// Bit 1: continuous (0 = first event).
    pub const CONTINUOUS: u8 = 0x02;
    /// Bits 3,2 = 00b: the probe's own input.
    pub const SOURCE_INPUT: u8 = 0x00;
    /// Bits 3,2 = 01b: zero impulse of the position encoder.
    pub const SOURCE_ZERO_PULSE: u8 = 0x04;
    /// Bits 3,2 = 10b: source as defined in 0x60D0 sub 1 / 2.
    pub const SOURCE_OBJECT: u8 = 0x08;
    /// Bit 4: sample the positive edge (→ 0x60BA / 0x60BC).
    pub const POSITIVE: u8 = 0x10;
    /// Bit 5: sample the negative edge (→ 0x60BB / 0x60BD).
    pub const NEGATIVE: u8 = 0x20;
}

/// Touch probe status 0x60B9, bits of one probe's byte (probe 1: low byte, probe 2: high byte;
/// CiA 402).
pub mod probe_status {
    /// Bit 0: touch probe enabled.
    pub const ENABLED: u8 = 0x01;
    /// Bit 1: positive edge value stored.
    pub const POSITIVE_STORED: u8 = 0x02;
    /// Bit 2: negative edge value stored.
    pub const NEGATIVE_STORED: u8 = 0x04;
    /// Bit 6: toggles with every positive-edge latch in continuous mode (vendor-specific, as
    /// Yaskawa Σ-X).
    pub const POSITIVE_TOGGLE: u8 = 0x40;
    /// Bit 7: toggles with every negative-edge latch in continuous mode (vendor-specific, as
    /// Yaskawa Σ-X).
    pub const NEGATIVE_TOGGLE: u8 = 0x80;
}

/// The 0x60B8 byte of one probe for a request (module documentation, "Touch probe").
pub fn touch_probe_byte(request: &ProbeRequest) -> u8 {
    use probe_function::*;
    let source = match request.source_mode {
        TriggerSourceMode::CncDefined | TriggerSourceMode::DriveDefined => SOURCE_OBJECT,
        TriggerSourceMode::Default => match request.trigger {
            ProbeTrigger::Input => SOURCE_INPUT,
            ProbeTrigger::ZeroPulse => SOURCE_ZERO_PULSE,
            ProbeTrigger::SourceObject => SOURCE_OBJECT,
        },
    };
    let edge = match request.edge {
        ProbeEdge::Positive => POSITIVE,
        ProbeEdge::Negative => NEGATIVE,
    };
    ENABLE | if request.continuous { CONTINUOUS } else { 0 } | source | edge
}

/// The whole 0x60B8 word for a request: [`touch_probe_byte`] in the probe's byte, `None` for a
/// probe other than 1 or 2.
pub fn touch_probe_function(request: &ProbeRequest) -> Option<u16> {
    let shift = probe_shift(request.probe)?;
    Some(u16::from(touch_probe_byte(request)) << shift)
}

/// Bit offset of a probe's byte in 0x60B8 / 0x60B9.
fn probe_shift(probe: u8) -> Option<u32> {
    match probe {
        1 => Some(0),
        2 => Some(8),
        _ => None,
    }
}

/// Value object (0x60BA…0x60BD) and counter object (0x60D5…0x60D8) of a probe's edge.
fn edge_objects(probe: u8, edge: ProbeEdge) -> (u16, u16) {
    let i = u16::from(probe.saturating_sub(1).min(1)) * 2 + u16::from(edge == ProbeEdge::Negative);
    (0x60BA + i, 0x60D5 + i)
}

/// Stored and toggle bits of an edge in a probe's 0x60B9 byte.
fn edge_bits(edge: ProbeEdge) -> (u8, u8) {
    match edge {
        ProbeEdge::Positive => (probe_status::POSITIVE_STORED, probe_status::POSITIVE_TOGGLE),
        ProbeEdge::Negative => (probe_status::NEGATIVE_STORED, probe_status::NEGATIVE_TOGGLE),
    }
}

/// Most events kept for [`DriveAdapter::take_probe_event`]; beyond that the latch fails.
const MAX_PENDING_EVENTS: usize = 256;

/// Decode a statusword (0x6041) into the power state (CiA 402 §6.2 Table "state coding"; masks
/// as python-canopen `State402.SW_MASK`). Patterns that match no state are kept as
/// [`PowerState::Unknown`].
pub fn decode_statusword(sw: u16) -> PowerState {
    match (sw & 0x004F, sw & 0x006F) {
        (0x0000, _) => PowerState::NotReadyToSwitchOn,
        (0x0040, _) => PowerState::SwitchOnDisabled,
        (_, 0x0021) => PowerState::ReadyToSwitchOn,
        (_, 0x0023) => PowerState::SwitchedOn,
        (_, 0x0027) => PowerState::OperationEnabled,
        (_, 0x0007) => PowerState::QuickStopActive,
        (0x000F, _) => PowerState::FaultReactionActive,
        (0x0008, _) => PowerState::Fault,
        _ => PowerState::Unknown(sw),
    }
}

/// Master-side CiA 402 adapter for one drive (see the module documentation).
///
/// Methods: [`Ds402Adapter::new`]; cyclic through [`DriveAdapter`]
/// (`read_inputs`, then `write_outputs`); touch probe through [`DriveAdapter`] (`arm_probe`,
/// `disarm_probe`, `probe_state`, `take_probe_event`) and [`Ds402Adapter::acyclic_probe_setup`];
/// observation: [`Ds402Adapter::state`], [`Ds402Adapter::statusword`],
/// [`Ds402Adapter::controlword`], [`Ds402Adapter::probe_function_word`].
#[derive(Debug, Clone)]
pub struct Ds402Adapter {
    rx: PdoLayout,
    tx: PdoLayout,
    defaults: Vec<OutputDefault>,
    statusword: u16,
    state: PowerState,
    controlword: u16,
    latch: Latch,
}

/// Step of the arming sequence (module documentation, "Touch probe").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// 0 written, waiting for 0x60B9 to show the probe disabled.
    Clearing,
    /// Function byte written, waiting for "enabled, stored bits clear".
    Enabling,
    /// Confirmed; events are fresh.
    Armed,
    /// Given up; nothing more is reported until re-armed.
    Failed,
}

/// One arming of a touch probe.
#[derive(Debug, Clone)]
struct Arming {
    request: ProbeRequest,
    byte: u8,
    phase: Phase,
    /// The current phase's word went out in an output image (a confirmation must come from an
    /// image after that).
    sent: bool,
    /// Images seen in the current phase.
    cycles: u32,
    /// The probe's 0x60B9 byte of the previous image (edge detection).
    prev: u8,
    /// Last counter values (positive, negative edge) when the counters are mapped.
    counters: [Option<u16>; 2],
    /// Events reported in this arming.
    sequence: u32,
    /// First-event mode: the event was reported.
    done: bool,
}

/// The adapter's touch probe unit.
#[derive(Debug, Clone)]
struct Latch {
    config: ProbeConfig,
    /// 0x60B8 mapped (RxPDO).
    function_mapped: bool,
    /// 0x60B9 mapped (TxPDO).
    status_mapped: bool,
    arming: Option<Arming>,
    failure: Option<String>,
    /// 0x60B8 as written in the last output image.
    word: u16,
    /// 0x60B9 of the last input image.
    last_status: Option<u16>,
    events: VecDeque<ProbeEvent>,
}

impl Ds402Adapter {
    /// Adapter for the PDO mapping of `def`. Fails when the mapping lacks 0x6040 / 0x607A
    /// (outputs) or 0x6041 / 0x6064 (inputs), or maps one of the objects the adapter interprets
    /// (0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x6077, 0x607A, 0x60B8, 0x60B9, 0x60BA–0x60BD,
    /// 0x60D0:01/02, 0x60D5–0x60D8, 0x60F4) with a type other than CiA 402's.
    pub fn new(def: &DriveDefinition) -> Result<Self, DriveError> {
        let fail = |message: String| DriveError::Definition {
            file: def.file.clone(),
            line: 0,
            message,
        };
        for (layout, dir, required) in [
            (&def.rxpdo, "rxpdo", [0x6040, 0x607A]),
            (&def.txpdo, "txpdo", [0x6041, 0x6064]),
        ] {
            for index in required {
                if !layout.contains(index, 0) {
                    return Err(fail(format!(
                        "[{dir}] entries: CiA 402 adapter needs 0x{index:04X}:00 mapped"
                    )));
                }
            }
        }
        let mut typed: Vec<(u16, u8, DataType)> = vec![
            (0x6040, 0, DataType::U16),
            (0x6041, 0, DataType::U16),
            (0x6060, 0, DataType::I8),
            (0x6061, 0, DataType::I8),
            (0x6064, 0, DataType::I32),
            (0x6077, 0, DataType::I16),
            (0x607A, 0, DataType::I32),
            (0x60B8, 0, DataType::U16),
            (0x60B9, 0, DataType::U16),
            (0x60D0, 1, DataType::I16),
            (0x60D0, 2, DataType::I16),
            (0x60F4, 0, DataType::I32),
        ];
        typed.extend((0x60BA..=0x60BD).map(|i| (i, 0, DataType::I32)));
        typed.extend((0x60D5..=0x60D8).map(|i| (i, 0, DataType::U16)));
        for (index, sub, ty) in typed {
            for (layout, dir) in [(&def.rxpdo, "rxpdo"), (&def.txpdo, "txpdo")] {
                if let Some(e) = layout.find(index, sub) {
                    if e.ty != ty {
                        return Err(fail(format!(
                            "[{dir}] entries: 0x{index:04X}:{sub:02X} must be {ty} (CiA 402), mapped as {}",
                            e.ty
                        )));
                    }
                }
            }
        }
        for d in &def.rxpdo_defaults {
            let ok = def
                .rxpdo
                .find(d.index, d.sub)
                .is_some_and(|e| e.ty.contains(d.value));
            if !ok {
                return Err(fail(format!(
                    "[rxpdo] defaults: 0x{:04X}:{:02X} = {} is not a mapped output of that range",
                    d.index, d.sub, d.value
                )));
            }
        }
        Ok(Ds402Adapter {
            rx: def.rxpdo.clone(),
            tx: def.txpdo.clone(),
            defaults: def.rxpdo_defaults.clone(),
            statusword: 0,
            state: decode_statusword(0),
            controlword: controlword::DISABLE_VOLTAGE,
            latch: Latch {
                config: def.probe,
                function_mapped: def.rxpdo.contains(0x60B8, 0),
                status_mapped: def.txpdo.contains(0x60B9, 0),
                arming: None,
                failure: None,
                word: 0,
                last_status: None,
                events: VecDeque::new(),
            },
        })
    }

    /// Power state decoded from the last input image (NOT READY TO SWITCH ON before the first).
    pub fn state(&self) -> PowerState {
        self.state
    }

    /// Statusword 0x6041 of the last input image (0 before the first).
    pub fn statusword(&self) -> u16 {
        self.statusword
    }

    /// Controlword 0x6040 of the last output image written (0 before the first).
    pub fn controlword(&self) -> u16 {
        self.controlword
    }

    /// Touch probe function 0x60B8 of the last output image written (0 before the first).
    pub fn probe_function_word(&self) -> u16 {
        self.latch.word
    }

    /// The acyclic write (`index`, `sub`, `value`) a caller must make (SDO / CoE, e.g.
    /// [`Link::write_object`](crate::link::Link::write_object)) before arming `request`:
    /// `CNC_DEFINED` needs 0x60D0 sub `probe` = `input` (FCT-C4 §6.4) unless 0x60D0:0n is
    /// mapped in the RxPDO, where the adapter writes it cyclically. `None` when nothing is
    /// needed.
    pub fn acyclic_probe_setup(&self, request: &ProbeRequest) -> Option<(u16, u8, i64)> {
        (request.source_mode == TriggerSourceMode::CncDefined
            && !self.rx.contains(0x60D0, request.probe))
        .then_some((0x60D0, request.probe, i64::from(request.input)))
    }

    /// The controlword for this cycle (table in the module documentation).
    fn next_controlword(&self, cmd: &DriveCommand) -> u16 {
        use controlword::*;
        match self.state {
            PowerState::Fault | PowerState::FaultReactionActive => {
                if cmd.fault_reset && self.controlword == DISABLE_VOLTAGE {
                    FAULT_RESET
                } else {
                    DISABLE_VOLTAGE
                }
            }
            _ if cmd.quick_stop => QUICK_STOP,
            PowerState::QuickStopActive => DISABLE_VOLTAGE,
            _ if !cmd.enable => SHUTDOWN,
            PowerState::ReadyToSwitchOn => SWITCH_ON,
            PowerState::SwitchedOn | PowerState::OperationEnabled => ENABLE_OPERATION,
            PowerState::SwitchOnDisabled
            | PowerState::NotReadyToSwitchOn
            | PowerState::Unknown(_) => SHUTDOWN,
        }
    }

    /// Touch probe part of [`DriveAdapter::read_inputs`]: `previous` is the power state of the
    /// image before.
    fn probe_inputs(&mut self, inputs: &[u8], previous: PowerState) {
        let status = self.tx.get_u16(inputs, 0x60B9, 0);
        self.latch.last_status = status;
        let Some(a) = self.latch.arming.as_mut() else {
            return;
        };
        if a.phase == Phase::Failed {
            return;
        }
        let probe = a.request.probe;
        let fault = matches!(
            self.state,
            PowerState::Fault | PowerState::FaultReactionActive
        );
        let why = if fault {
            Some(format!(
                "touch probe {probe}: drive fault (statusword 0x{:04X})",
                self.statusword
            ))
        } else if previous == PowerState::OperationEnabled
            && self.state != PowerState::OperationEnabled
        {
            Some(format!(
                "touch probe {probe}: drive left operation enabled ({:?})",
                self.state
            ))
        } else {
            None
        };
        if let Some(why) = why {
            self.latch.fail(why);
            return;
        }
        let Some(status) = status else {
            return;
        };
        let shift = probe_shift(probe).unwrap_or(0);
        let byte = (status >> shift) as u8;
        let stored = probe_status::POSITIVE_STORED | probe_status::NEGATIVE_STORED;
        let timeout = self.latch.config.arm_timeout_cycles;
        match a.phase {
            Phase::Clearing | Phase::Enabling => {
                a.cycles += 1;
                let confirmed = a.sent
                    && match a.phase {
                        Phase::Clearing => byte & probe_status::ENABLED == 0,
                        _ => byte & probe_status::ENABLED != 0 && byte & stored == 0,
                    };
                if confirmed {
                    a.cycles = 0;
                    a.sent = false;
                    if a.phase == Phase::Clearing {
                        a.phase = Phase::Enabling;
                    } else {
                        a.phase = Phase::Armed;
                        a.prev = byte;
                        a.counters = [ProbeEdge::Positive, ProbeEdge::Negative]
                            .map(|e| self.tx.get_u16(inputs, edge_objects(probe, e).1, 0));
                        tracing::debug!(
                            target: "fieldprobe::drive::ds402",
                            probe,
                            status = format_args!("0x{status:04X}"),
                            "touch probe armed"
                        );
                    }
                } else if a.cycles > timeout {
                    let what = if a.phase == Phase::Clearing {
                        "0x60B8 = 0 (probe disabled)"
                    } else {
                        "the arming (probe enabled, stored bits clear)"
                    };
                    let why = format!(
                        "touch probe {probe}: drive did not confirm {what} within {timeout} cycles (0x60B9 = 0x{status:04X})"
                    );
                    self.latch.fail(why);
                }
            }
            Phase::Armed => {
                let result = evaluate(a, byte, &self.tx, inputs);
                for e in result.events {
                    if self.latch.events.len() >= MAX_PENDING_EVENTS {
                        self.latch.fail(format!(
                            "touch probe {probe}: more than {MAX_PENDING_EVENTS} events not taken"
                        ));
                        return;
                    }
                    self.latch.events.push_back(e);
                }
                if let Some(why) = result.failure {
                    self.latch.fail(why);
                }
            }
            Phase::Failed => {}
        }
    }
}

/// What one image brought while armed.
#[derive(Debug, Default)]
struct Evaluation {
    events: Vec<ProbeEvent>,
    failure: Option<String>,
}

/// Event detection for an armed probe (module documentation, "Events"); updates `a`.
fn evaluate(a: &mut Arming, byte: u8, tx: &PdoLayout, inputs: &[u8]) -> Evaluation {
    let mut out = Evaluation::default();
    let req = a.request;
    let probe = req.probe;
    let prev = std::mem::replace(&mut a.prev, byte);
    let edges: &[ProbeEdge] = match (req.source_mode, req.edge) {
        (TriggerSourceMode::DriveDefined, ProbeEdge::Negative) => {
            &[ProbeEdge::Negative, ProbeEdge::Positive]
        }
        (TriggerSourceMode::DriveDefined, ProbeEdge::Positive) => {
            &[ProbeEdge::Positive, ProbeEdge::Negative]
        }
        (_, ProbeEdge::Positive) => &[ProbeEdge::Positive],
        (_, ProbeEdge::Negative) => &[ProbeEdge::Negative],
    };
    let value = |edge| tx.get_i32(inputs, edge_objects(probe, edge).0, 0);
    let push = |a: &mut Arming, edge, advance: u32, out: &mut Evaluation| {
        let Some(position) = value(edge) else {
            out.failure = Some(format!(
                "touch probe {probe}: value object 0x{:04X} is not in the input image",
                edge_objects(probe, edge).0
            ));
            return;
        };
        a.sequence = a.sequence.saturating_add(advance);
        out.events.push(ProbeEvent {
            probe,
            edge,
            position,
            sequence: a.sequence,
        });
    };
    if !req.continuous {
        for &edge in edges {
            let (stored, _) = edge_bits(edge);
            let rose = prev & stored == 0 && byte & stored != 0;
            let fell = prev & stored != 0 && byte & stored == 0;
            if fell {
                out.failure = Some(format!(
                    "touch probe {probe}: drive cleared the stored bit of the {edge:?} edge without a re-arm"
                ));
                return out;
            }
            if rose && !a.done {
                a.done = true;
                push(a, edge, 1, &mut out);
            }
        }
        if byte & probe_status::ENABLED == 0 && !a.done {
            out.failure = Some(format!(
                "touch probe {probe}: drive disabled the probe before it latched (0x60B9 byte 0x{byte:02X})"
            ));
        }
        return out;
    }
    if byte & probe_status::ENABLED == 0 {
        out.failure = Some(format!(
            "touch probe {probe}: drive disabled the probe (0x60B9 byte 0x{byte:02X})"
        ));
        return out;
    }
    // Positive before negative when both are evaluated.
    let mut ordered = edges.to_vec();
    ordered.sort_by_key(|e| *e == ProbeEdge::Negative);
    for edge in ordered {
        let (stored, toggle) = edge_bits(edge);
        let slot = usize::from(edge == ProbeEdge::Negative);
        let counter = tx.get_u16(inputs, edge_objects(probe, edge).1, 0);
        match (a.counters[slot], counter) {
            (Some(last), Some(now)) => {
                a.counters[slot] = Some(now);
                let k = now.wrapping_sub(last);
                if k == 1 {
                    push(a, edge, 1, &mut out);
                } else if k > 1 {
                    push(a, edge, u32::from(k), &mut out);
                    out.failure = Some(format!(
                        "touch probe {probe}: lost {} {edge:?}-edge event(s): counter 0x{:04X} jumped by {k}",
                        k - 1,
                        edge_objects(probe, edge).1
                    ));
                    return out;
                }
            }
            _ => {
                if (prev ^ byte) & toggle != 0 {
                    push(a, edge, 1, &mut out);
                } else if prev & stored == 0 && byte & stored != 0 {
                    out.failure = Some(format!(
                        "touch probe {probe}: {edge:?}-edge stored bit rose without a toggle (two latches in one cycle, or a drive without toggle bits)"
                    ));
                    return out;
                }
            }
        }
    }
    out
}

impl Latch {
    fn fail(&mut self, why: String) {
        tracing::debug!(target: "fieldprobe::drive::ds402", "{why}");
        if let Some(a) = self.arming.as_mut() {
            a.phase = Phase::Failed;
        }
        self.failure = Some(why);
    }

    /// The 0x60B8 word for this cycle.
    fn word(&self) -> u16 {
        match &self.arming {
            None => 0,
            Some(a) => {
                let byte = if a.phase == Phase::Clearing {
                    0
                } else {
                    a.byte
                };
                u16::from(byte) << probe_shift(a.request.probe).unwrap_or(0)
            }
        }
    }
}

/// Little-endian read of a mapped entry the caller checked to fit.
fn get(layout: &PdoLayout, image: &[u8], index: u16) -> Option<i64> {
    layout.get(image, index, 0)
}

impl DriveAdapter for Ds402Adapter {
    fn output_len(&self) -> usize {
        self.rx.len()
    }

    fn input_len(&self) -> usize {
        self.tx.len()
    }

    /// Decode 0x6041, 0x6064 and, when mapped, 0x60F4 / 0x6061 / 0x6077, and run the touch
    /// probe state machine on 0x60B9. The image must hold the whole TxPDO
    /// ([`DriveError::ImageTooShort`] otherwise; nothing is updated then).
    fn read_inputs(&mut self, _now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError> {
        if inputs.len() < self.tx.len() {
            return Err(DriveError::ImageTooShort {
                expected: self.tx.len(),
                got: inputs.len(),
            });
        }
        let short = || DriveError::ImageTooShort {
            expected: self.tx.len(),
            got: inputs.len(),
        };
        // Types are checked in `new`, so the narrowing casts are exact.
        let statusword = get(&self.tx, inputs, 0x6041).ok_or_else(short)? as u16;
        let position = get(&self.tx, inputs, 0x6064).ok_or_else(short)? as i32;
        let following_error = get(&self.tx, inputs, 0x60F4).map(|v| v as i32);
        let mode_display = get(&self.tx, inputs, 0x6061).map(|v| v as i8);
        let torque = get(&self.tx, inputs, 0x6077).map(|v| v as i32);
        let state = decode_statusword(statusword);
        if state != self.state {
            tracing::trace!(
                target: "fieldprobe::drive::ds402",
                statusword = format_args!("0x{statusword:04X}"),
                "power state {:?} -> {:?}",
                self.state,
                state
            );
        }
        let previous = self.state;
        self.statusword = statusword;
        self.state = state;
        self.probe_inputs(inputs, previous);
        let csp = mode_display.is_none_or(|m| m == MODE_CSP);
        Ok(DriveFeedback {
            state,
            statusword,
            position,
            following_error,
            mode_display,
            operational: state == PowerState::OperationEnabled && csp,
            fault: matches!(state, PowerState::Fault | PowerState::FaultReactionActive),
            following_error_flag: csp && statusword & 0x2000 != 0,
            torque,
        })
    }

    /// Encode controlword, target position, mode 8 (when mapped), the `[rxpdo] defaults`, the
    /// touch probe function 0x60B8 (when mapped; it overrides a default) and, for
    /// `CNC_DEFINED` with 0x60D0:0n mapped, the touch probe source. The image must hold the
    /// whole RxPDO ([`DriveError::ImageTooShort`] otherwise; nothing is written then).
    fn write_outputs(
        &mut self,
        _now: Nanos,
        command: &DriveCommand,
        outputs: &mut [u8],
    ) -> Result<(), DriveError> {
        if outputs.len() < self.rx.len() {
            return Err(DriveError::ImageTooShort {
                expected: self.rx.len(),
                got: outputs.len(),
            });
        }
        let cw = self.next_controlword(command);
        for d in &self.defaults {
            self.rx.set(outputs, d.index, d.sub, d.value)?;
        }
        self.rx.set_u16(outputs, 0x6040, 0, cw)?;
        self.rx.set_i32(outputs, 0x607A, 0, command.target)?;
        if self.rx.contains(0x6060, 0) {
            self.rx.set_i8(outputs, 0x6060, 0, MODE_CSP)?;
        }
        let word = self.latch.word();
        if self.latch.function_mapped {
            self.rx.set_u16(outputs, 0x60B8, 0, word)?;
        }
        if let Some(a) = self.latch.arming.as_mut() {
            a.sent = true;
            let r = a.request;
            if r.source_mode == TriggerSourceMode::CncDefined && self.rx.contains(0x60D0, r.probe) {
                self.rx
                    .set_i16(outputs, 0x60D0, r.probe, i16::from(r.input))?;
            }
        }
        if word != self.latch.word {
            tracing::debug!(
                target: "fieldprobe::drive::ds402",
                "0x60B8 0x{:04X} -> 0x{word:04X}",
                self.latch.word
            );
        }
        self.latch.word = word;
        self.controlword = cw;
        Ok(())
    }

    /// Start arming (module documentation, "Touch probe"). Refused when the probe is not 1 or
    /// 2, when 0x60B8 / 0x60B9 or the value objects the request needs are not mapped, or when
    /// `CNC_DEFINED` names input 0.
    fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        let probe = request.probe;
        let shift = probe_shift(probe).ok_or_else(|| {
            DriveError::Unsupported(format!(
                "touch probe {probe}: CiA 402 drives have touch probes 1 and 2"
            ))
        })?;
        if !self.latch.function_mapped || !self.latch.status_mapped {
            return Err(DriveError::Unsupported(
                "touch probe: needs 0x60B8 in [rxpdo] entries and 0x60B9 in [txpdo] entries".into(),
            ));
        }
        let edges: &[ProbeEdge] = if request.source_mode == TriggerSourceMode::DriveDefined {
            &[ProbeEdge::Positive, ProbeEdge::Negative]
        } else {
            std::slice::from_ref(&request.edge)
        };
        for &edge in edges {
            let (value, _) = edge_objects(probe, edge);
            if !self.tx.contains(value, 0) {
                return Err(DriveError::Unsupported(format!(
                    "touch probe {probe}: the {edge:?}-edge value 0x{value:04X} is not in [txpdo] entries"
                )));
            }
        }
        if request.source_mode == TriggerSourceMode::CncDefined && request.input == 0 {
            return Err(DriveError::Unsupported(format!(
                "touch probe {probe}: CNC_DEFINED needs the drive input (P-AXIS-00517) 1 or more, got 0"
            )));
        }
        let enabled = self
            .latch
            .last_status
            .is_none_or(|s| (s >> shift) as u8 & probe_status::ENABLED != 0);
        let written = (self.latch.word >> shift) as u8 != 0;
        let phase = if enabled || written || self.latch.config.rearm_requires_zero {
            Phase::Clearing
        } else {
            Phase::Enabling
        };
        self.latch.arming = Some(Arming {
            request: *request,
            byte: touch_probe_byte(request),
            phase,
            sent: false,
            cycles: 0,
            prev: 0,
            counters: [None; 2],
            sequence: 0,
            done: false,
        });
        self.latch.failure = None;
        self.latch.events.clear();
        Ok(())
    }

    /// Write 0 to the armed probe's byte from the next output image on; pending events go.
    fn disarm_probe(&mut self) {
        self.latch.arming = None;
        self.latch.failure = None;
        self.latch.events.clear();
    }

    fn probe_state(&self) -> ProbeState {
        match &self.latch.arming {
            None => ProbeState::Idle,
            Some(a) => match a.phase {
                Phase::Clearing | Phase::Enabling => ProbeState::Arming,
                Phase::Armed => ProbeState::Armed,
                Phase::Failed => ProbeState::Failed(
                    self.latch
                        .failure
                        .clone()
                        .unwrap_or_else(|| "touch probe failed".into()),
                ),
            },
        }
    }

    fn take_probe_event(&mut self) -> Option<ProbeEvent> {
        self.latch.events.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statusword_decode_table() {
        for (sw, state) in [
            (0x0000, PowerState::NotReadyToSwitchOn),
            (0x0250, PowerState::SwitchOnDisabled),
            (0x0231, PowerState::ReadyToSwitchOn),
            (0x0233, PowerState::SwitchedOn),
            (0x1637, PowerState::OperationEnabled),
            (0x0217, PowerState::QuickStopActive),
            (0x021F, PowerState::FaultReactionActive),
            (0x0418, PowerState::Fault), // Leadshine EL7 0x6041 in its SDO dump
            (0x0001, PowerState::Unknown(0x0001)),
        ] {
            assert_eq!(decode_statusword(sw), state, "0x{sw:04X}");
        }
    }
}
