//! Drive adapters (master side, sans-IO) and drive models (drive side).
//!
//! An adapter turns an axis command into the bytes of the drive's output process image
//! (master → drive, the RxPDO in CiA 402 terms) and decodes the input image (drive → master,
//! TxPDO) into [`DriveFeedback`]. It never does IO: the link moves the bytes.
//!
//! | family | adapter | model |
//! |---|---|---|
//! | CiA 402 (CANopen, CoE) | [`ds402::Ds402Adapter`] | [`model::ds402::Ds402Model`] |
//!
//! Drive definition files (`drives/*.toml`) are read by [`catalogue`].

pub mod catalogue;
pub mod ds402;
pub mod el1252;
pub mod lightbus;
pub mod model;
pub mod pdo;
pub mod profidrive;
pub mod sercos;
pub mod terminal;
pub mod vendor;

use crate::units::Nanos;
use std::fmt;

/// CiA 402 power state (statusword 0x6041 decode, CiA 402 §6.2; also the common state model the
/// other families map onto).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PowerState {
    /// xxxx xxxx x0xx 0000
    NotReadyToSwitchOn,
    /// xxxx xxxx x1xx 0000
    SwitchOnDisabled,
    /// xxxx xxxx x01x 0001
    ReadyToSwitchOn,
    /// xxxx xxxx x01x 0011
    SwitchedOn,
    /// xxxx xxxx x01x 0111
    OperationEnabled,
    /// xxxx xxxx x00x 0111
    QuickStopActive,
    /// xxxx xxxx x0xx 1111
    FaultReactionActive,
    /// xxxx xxxx x0xx 1000
    Fault,
    /// Any other bit pattern (kept, not rejected).
    Unknown(u16),
}

/// CiA 402 §6.2: the power stage is off in NOT READY TO SWITCH ON, SWITCH ON DISABLED, READY
/// TO SWITCH ON (where "shutdown" 0x0006 leads) and FAULT; in SWITCHED ON the amplifier is
/// switched on, in OPERATION ENABLED, QUICK STOP ACTIVE and FAULT REACTION ACTIVE it drives.
pub fn cia402_power_stage_off(state: PowerState) -> bool {
    matches!(
        state,
        PowerState::NotReadyToSwitchOn
            | PowerState::SwitchOnDisabled
            | PowerState::ReadyToSwitchOn
            | PowerState::Fault
    )
}

/// The families whose "ready" state maps onto [`PowerState::SwitchedOn`] but holds no torque
/// (SERCOS S-0-0135 bits 15/14 = 10 "ready, main power on, torque off"; the Lightbus AX2000's
/// and the encoder terminals' ready without enable): the power stage is off in every state but
/// the ones that drive the motor.
pub fn torque_off(state: PowerState) -> bool {
    !matches!(
        state,
        PowerState::OperationEnabled
            | PowerState::QuickStopActive
            | PowerState::FaultReactionActive
    )
}

/// What the axis layer asks of the drive in one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveCommand {
    /// Bring the drive to (or keep it in) *operation enabled*; `false` disables it.
    pub enable: bool,
    /// Target position in drive increments (0x607A in cyclic synchronous position mode).
    pub target: i32,
    /// Request a fault reset (the adapter produces the rising edge of controlword bit 7).
    pub fault_reset: bool,
    /// Request a quick stop.
    pub quick_stop: bool,
}

/// What the drive reported in one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveFeedback {
    /// Decoded power state.
    pub state: PowerState,
    /// Raw statusword (0x6041) or the family's equivalent.
    pub statusword: u16,
    /// Position actual value in increments (0x6064).
    pub position: i32,
    /// Following error actual value in increments (0x60F4), when mapped.
    pub following_error: Option<i32>,
    /// Modes of operation display (0x6061), when mapped.
    pub mode_display: Option<i8>,
    /// The drive follows the cyclic target: operation enabled and, where mapped, mode 8 (CSP).
    pub operational: bool,
    /// The drive is in fault or fault reaction.
    pub fault: bool,
    /// Statusword bit 13 (following error in CSP).
    pub following_error_flag: bool,
    /// Torque actual value in per mille of rated torque (0x6077), when mapped.
    pub torque: Option<i32>,
}

/// Edge of a probe signal that latches (P-AXIS-00518 `kenngr.measure.edge`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ProbeEdge {
    /// Rising edge (POS).
    Positive,
    /// Falling edge (NEG).
    Negative,
}

/// Trigger source of a touch probe (CiA 402 0x60B8 bits 2–3 / 10–11).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ProbeTrigger {
    /// 00b: the touch probe's own digital input.
    Input,
    /// 01b: zero impulse (index) of the position encoder.
    ZeroPulse,
    /// 10b: source as defined in 0x60D0 sub 1 / 2.
    SourceObject,
}

/// P-AXIS-00702 `antr.canopen.probing_trigger_source` (FCT-C4 §6.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TriggerSourceMode {
    /// `DEFAULT`: probe 1 / 2 on its own input (0x60B8 source bits 00b).
    #[default]
    Default,
    /// `CNC_DEFINED`: the CNC writes 0x60D0 with the input of P-AXIS-00517 and selects 10b.
    CncDefined,
    /// `DRIVE_DEFINED`: the drive's 0x60D0 defines the trigger; the control word selects 10b
    /// and the status word is evaluated differently (either stored bit counts).
    DriveDefined,
}

/// What the axis layer asks a drive's latch unit to do (one arming).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ProbeRequest {
    /// Touch probe 1 or 2 (P-AXIS-00517 selects it for CiA 402 drives).
    pub probe: u8,
    /// Edge to latch on (P-AXIS-00518).
    pub edge: ProbeEdge,
    /// Trigger source.
    pub trigger: ProbeTrigger,
    /// Continuous mode (every edge) instead of first event.
    pub continuous: bool,
    /// P-AXIS-00702.
    pub source_mode: TriggerSourceMode,
    /// The drive input number written to 0x60D0 with `CNC_DEFINED` (P-AXIS-00517).
    pub input: u8,
}

/// One latched value reported by a drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ProbeEvent {
    /// Touch probe 1 or 2.
    pub probe: u8,
    /// Edge that latched.
    pub edge: ProbeEdge,
    /// Latched position in increments (0x60BA … 0x60BD).
    pub position: i32,
    /// Running count of events of this arming (1 for the first), for loss detection.
    pub sequence: u32,
}

/// State of a drive's latch unit as the adapter sees it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum ProbeState {
    /// Not armed.
    #[default]
    Idle,
    /// Arming written, waiting for the drive to confirm (0x60B9 enabled, stored bits clear).
    Arming,
    /// Armed and confirmed: events are fresh.
    Armed,
    /// The drive does not behave as the profile demands (e.g. a stored bit without enable, a
    /// lost continuous-mode event); the measurement must not use this latch.
    Failed(String),
}

/// Errors of the drive layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriveError {
    /// The process image is shorter than the layout needs.
    #[error("process image too short: layout needs {expected} bytes, got {got}")]
    ImageTooShort {
        /// Bytes the layout needs.
        expected: usize,
        /// Bytes present.
        got: usize,
    },
    /// The drive or adapter does not offer the function.
    #[error("{0}")]
    Unsupported(String),
    /// A drive definition file is invalid.
    #[error("{file}:{line}: {message}")]
    Definition {
        /// File name.
        file: String,
        /// 1-based line (0 when unknown).
        line: usize,
        /// What is wrong and what is allowed.
        message: String,
    },
}

/// The set-points an adapter sent, newest first, for loops closed on the master side: the
/// actual value in an input image was sampled `delay` cycles before the exchange that carries
/// it, so it must be compared with the set-point of that time, not the last one
/// ([`DriveAdapter::set_feedback_delay`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SentSetpoints {
    buf: [i32; SentSetpoints::CAPACITY],
    len: usize,
    delay: u32,
}

impl Default for SentSetpoints {
    fn default() -> Self {
        SentSetpoints {
            buf: [0; SentSetpoints::CAPACITY],
            len: 0,
            delay: 1,
        }
    }
}

impl SentSetpoints {
    /// Set-points kept (the largest delay + 1).
    pub const CAPACITY: usize = 17;

    /// Feedback delay in cycles (clamped to the capacity).
    pub fn set_delay(&mut self, cycles: u32) {
        self.delay = cycles.min(Self::CAPACITY as u32 - 1);
    }

    /// The feedback delay in cycles.
    pub fn delay(&self) -> u32 {
        self.delay
    }

    /// Forget the history (the drive stopped following).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Record the set-point just sent.
    pub fn push(&mut self, target: i32) {
        self.buf.copy_within(0..Self::CAPACITY - 1, 1);
        self.buf[0] = target;
        self.len = (self.len + 1).min(Self::CAPACITY);
    }

    /// The last set-point sent (`T_{k−1}` while `T_k` is being written).
    pub fn last(&self) -> Option<i32> {
        (self.len > 0).then(|| self.buf[0])
    }

    /// The set-point the axis should have reached when the latest actual value was sampled:
    /// `T_{k−1−delay}` (the oldest one kept while the history is shorter).
    pub fn reference(&self) -> Option<i32> {
        (self.len > 0).then(|| self.buf[(self.delay as usize).min(self.len - 1)])
    }
}

/// Master-side adapter of one drive (sans-IO).
pub trait DriveAdapter: Send + fmt::Debug {
    /// Bytes of the output image (master → drive).
    fn output_len(&self) -> usize;
    /// Bytes of the input image (drive → master).
    fn input_len(&self) -> usize;
    /// Decode the input image received in this cycle.
    fn read_inputs(&mut self, now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError>;
    /// Encode this cycle's command into the output image.
    fn write_outputs(
        &mut self,
        now: Nanos,
        command: &DriveCommand,
        outputs: &mut [u8],
    ) -> Result<(), DriveError>;

    /// Arm the latch unit (takes effect with the next [`write_outputs`](Self::write_outputs)).
    /// Drives without a latch unit refuse.
    fn arm_probe(&mut self, request: &ProbeRequest) -> Result<(), DriveError> {
        let _ = request;
        Err(DriveError::Unsupported(
            "this drive has no latch unit".into(),
        ))
    }

    /// Disarm the latch unit; pending events are dropped.
    fn disarm_probe(&mut self) {}

    /// The power stage is off in `state`, as this family's profile defines it (the end of a
    /// run disables every drive and waits for this). Default: CiA 402
    /// ([`cia402_power_stage_off`]).
    fn power_stage_off(&self, state: PowerState) -> bool {
        cia402_power_stage_off(state)
    }

    /// State of the latch unit.
    fn probe_state(&self) -> ProbeState {
        ProbeState::Idle
    }

    /// The next fresh latch event decoded by [`read_inputs`](Self::read_inputs), oldest first.
    fn take_probe_event(&mut self) -> Option<ProbeEvent> {
        None
    }

    /// The drive reported that the armed latch unit has captured its event, whose value is
    /// still being read (PROFIdrive: "value available" in G1_ZSW, the value follows in
    /// G1_XIST2 after a read request). Lets the CNC brake at once. Default: never (the value
    /// comes with the report).
    fn probe_triggered(&self) -> bool {
        false
    }

    /// Write a cyclic drive function (`commu = "CYCLIC"` in the drive file, e.g. PROFIdrive
    /// MOMRED): `value` goes into the command telegram from the next cycle on. `index:sub`
    /// names the telegram signal in the family's numbering. Families without cyclic functions
    /// refuse.
    fn write_cyclic(&mut self, index: u16, sub: u8, value: i64) -> Result<(), DriveError> {
        let _ = value;
        Err(DriveError::Unsupported(format!(
            "this drive has no cyclic function {index:#06x}:{sub:02x}"
        )))
    }

    /// Read back a cyclic drive function (the value the adapter sends).
    fn read_cyclic(&self, index: u16, sub: u8) -> Result<i64, DriveError> {
        Err(DriveError::Unsupported(format!(
            "this drive has no cyclic function {index:#06x}:{sub:02x}"
        )))
    }

    /// The actual values in an input image were sampled this many cycles before the exchange
    /// that carries them (1 on every link fieldprobe has: sampled at SYNC0, sent with the next
    /// frame; [`crate::link::Link::dead_time_cycles`] − 1). Adapters that close a loop on the
    /// master side (PROFIdrive speed control and DSC, the terminal drives' velocity output)
    /// compare the actual value with the set-point of that time. Default 1; others ignore it.
    fn set_feedback_delay(&mut self, cycles: u32) {
        let _ = cycles;
    }
}

/// The master-side adapter for a drive definition (by its profile), with the axis parameter
/// list of the axis it drives (e.g. P-AXIS-00060 / 00106 select SERCOS real-time bits).
pub fn adapter_for(
    def: &catalogue::DriveDefinition,
    axis: &crate::params::ParamSet,
) -> Result<Box<dyn DriveAdapter>, DriveError> {
    use catalogue::Profile;
    match def.profile {
        Profile::Cia402 => Ok(Box::new(ds402::Ds402Adapter::new(def)?)),
        Profile::Profidrive => Ok(Box::new(profidrive::ProfidriveAdapter::new(def)?)),
        Profile::Lightbus => Ok(Box::new(lightbus::LightbusAdapter::new(def)?)),
        Profile::Terminal => Ok(Box::new(terminal::TerminalAdapter::new(def, axis)?)),
        Profile::Sercos => Ok(Box::new(sercos::SercosAdapter::new(def, axis)?)),
    }
}

/// Family-specific commissioning checks (FCT-C4 §6): the drive's own settings, read with
/// `read(index, sub)` (acyclic access of its profile: CoE object, SERCOS IDN code, PROFIdrive
/// PNU, Lightbus parameter; `None` = cannot be read), against the axis parameters, as
/// plain-words findings. The CiA 402 PDO mapping checks need no drive access and are made by
/// the machine.
pub fn commissioning_check(
    def: &catalogue::DriveDefinition,
    axis: &crate::params::ParamSet,
    read: &dyn Fn(u16, u8) -> Option<i64>,
) -> Vec<String> {
    use catalogue::Profile;
    match def.profile {
        Profile::Cia402 => Vec::new(),
        Profile::Sercos => sercos::commissioning_check(def, axis, &|idn| read(idn, 0)),
        Profile::Profidrive => profidrive::check_drive(read),
        Profile::Lightbus => match read(lightbus::PARAM_IN2MODE, 0) {
            Some(v) => lightbus::check_drive(v),
            None => vec![format!(
                "drive parameter IN2MODE ({:#06X}) cannot be read; measuring needs IN2MODE = {} \
                 (seed 004 §6.2)",
                lightbus::PARAM_IN2MODE,
                lightbus::IN2MODE_PROBE
            )],
        },
        Profile::Terminal => match terminal::TerminalConfig::from_definition(def) {
            Ok(cfg) => terminal::check_axis_params(cfg.variant, axis),
            Err(e) => vec![e.to_string()],
        },
    }
}

#[cfg(test)]
mod power_stage_tests {
    use super::*;

    #[test]
    fn each_family_reads_its_power_stage_as_its_profile_defines() {
        // SERCOS S-0-0135 bits 15/14: 10 ready, main power on, torque off; 11 drive enabled.
        let sercos = |bits: u16| torque_off(sercos::SercosAdapter::power_state(bits << 14));
        assert!(sercos(0b00) && sercos(0b01) && sercos(0b10));
        assert!(!sercos(0b11));
        // CiA 402: SWITCHED ON has the amplifier on; shutdown leads to READY TO SWITCH ON.
        assert!(!cia402_power_stage_off(PowerState::SwitchedOn));
        assert!(cia402_power_stage_off(PowerState::ReadyToSwitchOn));
        assert!(!cia402_power_stage_off(PowerState::QuickStopActive));
        // Lightbus: ready without enable holds no torque; a quick stop still brakes.
        assert!(torque_off(lightbus::decode_status(
            lightbus::telegram::SW_READY
        )));
        assert!(!torque_off(lightbus::decode_status(
            lightbus::telegram::SW_READY | lightbus::telegram::SW_ENABLED
        )));
        assert!(!torque_off(PowerState::QuickStopActive));
    }
}
