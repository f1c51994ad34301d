//! CiA 402 drive model: the drive side of [`crate::drive::ds402::Ds402Adapter`].
//!
//! [`Ds402Model`] plays a servo drive in cyclic synchronous position mode (CSP, 0x6060 = 8). Each
//! bus cycle the link calls [`Ds402Model::step`] with the master's output image (the drive's
//! RxPDO) and the drive's input image (TxPDO) to fill. Everything is sans-IO: time is the `dt_s`
//! argument, nothing reads a clock.
//!
//! # Methods by concern
//!
//! - cyclic: [`Ds402Model::step`], [`Ds402Model::rx_len`], [`Ds402Model::tx_len`]
//! - object dictionary (for SDO / CoE servers): [`Ds402Model::read_object`],
//!   [`Ds402Model::write_object`]
//! - plant and test knobs: [`Ds402Model::set_actual`], [`Ds402Model::actual`],
//!   [`Ds402Model::set_disturbance`], [`Ds402Model::inject_fault`]
//! - observation: [`Ds402Model::state`], [`Ds402Model::statusword`],
//!   [`Ds402Model::last_error_code`], [`Ds402Model::rx_length_errors`]
//!
//! # Behaviour
//!
//! - **Power state machine** (CiA 402 §6.2, Figure "state machine"): starts in NOT READY TO
//!   SWITCH ON and moves to SWITCH ON DISABLED by itself in the first step (transition 1).
//!   Controlword commands (CiA 402 §6.3): shutdown `xxxx x110` (2, 6, 8), switch on `xxxx 0111`
//!   (3, 5), enable operation `xxxx 1111` (4, 16; transition 4 after
//!   `enable_delay_cycles` extra cycles), disable voltage `xxxx xx0x` (7, 9, 10, 12), quick stop
//!   `xxxx x01x` (7, 10, 11). QUICK STOP ACTIVE holds the position and stays until *disable
//!   voltage* (12) or *enable operation* (16), i.e. quick stop option code 6 behaviour (0x605A).
//!   While bit 7 is set only *disable voltage* and *quick stop* are obeyed. A fault goes to
//!   FAULT REACTION ACTIVE for one cycle, then FAULT (13, 14); a rising edge of controlword bit 7
//!   in FAULT resets it to SWITCH ON DISABLED (15).
//! - **Statusword** (0x6041): state bits per CiA 402 Table "state coding", bit 4 voltage enabled
//!   (mains are always on, so set in every state after start), bit 5 quick stop (clear = quick stop
//!   active), bit 9 remote, bit 10 target reached (|0x60F4| ≤ position window 0x6067), bit 11
//!   internal limit active (the velocity limit cut the motion), bit 12 drive follows the command
//!   value (CSP), bit 13 following error.
//! - **Position loop** in OPERATION ENABLED with mode 8: a first-order lag with gain kv
//!   (`[model] kv`). For a constant set-point one cycle is exactly
//!   `actual += (target − actual) · (1 − e^(−kv·dt))`. When the set-point moves, the model
//!   interpolates it linearly over the cycle (as CSP drives interpolate their fine set-points) and
//!   uses the exact solution of `ẋ = kv·(r − x)` for that ramp, so the steady-state lag at
//!   constant velocity v is exactly v / kv (the step formula alone would give
//!   v·dt / (1 − e^(−kv·dt)), 2 % more at kv = 40/s, 1 ms). The actual position is kept as `f64`
//!   increments and reported rounded in 0x6064; 0x60F4 = 0x607A − 0x6064. `[model] max_velocity`
//!   limits the speed. In every other state the position holds (brake).
//! - **Following error monitoring** (CiA 402 0x6065 / 0x6066): when |0x60F4| exceeds the window
//!   for longer than the time out, statusword bit 13 is set and the drive faults with error code
//!   0x8611 (0x603F, EMCY "following error"). A window of 0xFFFFFFFF switches monitoring off.
//! - **Process data errors**: an RxPDO shorter than the mapping is ignored as a whole (the drive
//!   keeps the previous set-points; CiA 301 EMCY 0x8210 "PDO not processed due to length
//!   error"), counted in [`Ds402Model::rx_length_errors`]. A short TxPDO gets every entry that
//!   fits.
//!
//! # Not modelled yet (seams for the next issue)
//!
//! - Touch probe (0x60B8 / 0x60B9 / 0x60BA–0x60BD / 0x60D0): 0x60B8 and 0x60D0 are stored and
//!   read back, but nothing latches: **0x60B9 and 0x60BA–0x60BD always read 0**, in SDO reads and
//!   in the TxPDO. See `TODO(touch-probe)`.
//! - Torque limits (0x6072, 0x60E0, 0x60E1) are stored and read back but do not limit anything;
//!   0x6077 torque actual reads 0. See `TODO(torque)`.
//! - Fixed stops and probe surfaces belong to the plant; the model has no obstacle yet. See
//!   `TODO(fixed-stop)`.

use super::abort;
use crate::drive::catalogue::DriveDefinition;
use crate::drive::pdo::{self, PdoLayout};
use crate::drive::PowerState;
use crate::units::Nanos;

/// EMCY / 0x603F error code of a following error (CiA 402 error code range 0x86xx).
pub const ERROR_FOLLOWING_ERROR: u16 = 0x8611;

/// Modes of operation (0x6060) the model accepts: 0 = no mode, 8 = cyclic synchronous position.
const SUPPORTED_MODES: [i8; 2] = [0, 8];
/// 0x6502 supported drive modes: bit 7 = CSP (CiA 402 §6.1.4).
const SUPPORTED_DRIVE_MODES: u32 = 1 << 7;
/// Mode 8, cyclic synchronous position.
const MODE_CSP: i8 = 8;
/// Default position window 0x6067 in increments (Leadshine EL7 factory value).
const DEFAULT_POSITION_WINDOW: u32 = 10;
/// Default max torque / torque limits in 0.1 % of rated torque (Leadshine EL7 factory value).
const DEFAULT_TORQUE_LIMIT: u16 = 3000;

/// Controlword command (CiA 402 §6.3 Table "command coding").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Command {
    Shutdown,
    SwitchOn,
    EnableOperation,
    DisableVoltage,
    QuickStop,
    /// Bit 7 set: only the fault reset edge counts.
    None,
}

fn decode_command(cw: u16) -> Command {
    if cw & 0x0002 == 0 {
        Command::DisableVoltage
    } else if cw & 0x0004 == 0 {
        Command::QuickStop
    } else if cw & 0x0080 != 0 {
        Command::None
    } else if cw & 0x0001 == 0 {
        Command::Shutdown
    } else if cw & 0x0008 == 0 {
        Command::SwitchOn
    } else {
        Command::EnableOperation
    }
}

/// Drive side of a CiA 402 servo in CSP mode (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Ds402Model {
    rx: PdoLayout,
    tx: PdoLayout,
    kv: f64,
    /// Velocity limit in increments/s.
    max_velocity_inc: Option<f64>,
    enable_delay_cycles: u32,

    state: PowerState,
    controlword: u16,
    prev_bit7: bool,
    enable_count: u32,
    mode: i8,
    target: i32,

    /// Loop position in increments (what the position loop controls).
    position: f64,
    /// Constant offset outside the loop (see [`Ds402Model::set_disturbance`]).
    disturbance: f64,
    /// Set-point of the previous cycle (start of the interpolation ramp).
    prev_target: f64,
    /// Velocity in increments/s over the last cycle.
    velocity: f64,
    /// The velocity limit cut the motion in the last cycle.
    limited: bool,

    fe_window: u32,
    fe_timeout_ms: u16,
    position_window: u32,
    fe_over_ns: u64,
    fe_flag: bool,

    max_torque: u16,
    torque_limit_pos: u16,
    torque_limit_neg: u16,
    tp_function: u16,
    tp_source: [i16; 2],

    error_code: u16,
    pending_fault: Option<u16>,
    clock_ns: u64,
    rx_length_errors: u64,
}

impl Ds402Model {
    /// A drive in NOT READY TO SWITCH ON at increment 0, with the PDO mapping, loop gain and
    /// monitoring defaults of `def` (`[rxpdo]`, `[txpdo]`, `[model]`).
    pub fn new(def: &DriveDefinition) -> Self {
        let m = &def.model;
        let max_velocity_inc = m
            .max_velocity
            .map(|v| (v * def.scaling.increments_per_unit).abs())
            .filter(|v| v.is_finite() && *v > 0.0);
        Ds402Model {
            rx: def.rxpdo.clone(),
            tx: def.txpdo.clone(),
            kv: if m.kv.is_finite() && m.kv > 0.0 {
                m.kv
            } else {
                40.0
            },
            max_velocity_inc,
            enable_delay_cycles: m.enable_delay_cycles,
            state: PowerState::NotReadyToSwitchOn,
            controlword: 0,
            prev_bit7: false,
            enable_count: 0,
            mode: 0,
            target: 0,
            position: 0.0,
            disturbance: 0.0,
            prev_target: 0.0,
            velocity: 0.0,
            limited: false,
            fe_window: m.following_error_window,
            fe_timeout_ms: m.following_error_timeout_ms,
            position_window: DEFAULT_POSITION_WINDOW,
            fe_over_ns: 0,
            fe_flag: false,
            max_torque: DEFAULT_TORQUE_LIMIT,
            torque_limit_pos: DEFAULT_TORQUE_LIMIT,
            torque_limit_neg: DEFAULT_TORQUE_LIMIT,
            tp_function: 0,
            tp_source: [1, 2],
            error_code: 0,
            pending_fault: None,
            clock_ns: 0,
            rx_length_errors: 0,
        }
    }

    /// Bytes of the RxPDO the model reads (master → drive).
    pub fn rx_len(&self) -> usize {
        self.rx.len()
    }

    /// Bytes of the TxPDO the model writes (drive → master).
    pub fn tx_len(&self) -> usize {
        self.tx.len()
    }

    /// One bus cycle: take the RxPDO `rx`, advance the drive by `dt_s` seconds, write the TxPDO
    /// into `tx`. `now` is the bus time of the cycle (kept for latch time stamps, see
    /// `TODO(touch-probe)`). Never panics: short images, garbage bytes and a negative or
    /// non-finite `dt_s` (treated as 0) are all handled.
    pub fn step(&mut self, now: Nanos, dt_s: f64, rx: &[u8], tx: &mut [u8]) {
        let _ = now; // TODO(touch-probe): time stamps 0x60D1..0x60D4 are taken from `now`.
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s.min(3600.0)
        } else {
            0.0
        };
        let dt_ns = (dt * 1e9).round() as u64;
        self.clock_ns = self.clock_ns.saturating_add(dt_ns);

        self.read_rx(rx);
        // Automatic transitions: 1 (self test done), 14 (fault reaction completed).
        match self.state {
            PowerState::NotReadyToSwitchOn => self.state = PowerState::SwitchOnDisabled,
            PowerState::FaultReactionActive => self.state = PowerState::Fault,
            _ => {}
        }
        if let Some(code) = self.pending_fault.take() {
            self.enter_fault(code);
        }
        self.apply_controlword();
        self.move_axis(dt);
        self.monitor_following_error(dt_ns);
        self.write_tx(tx);
    }

    fn read_rx(&mut self, rx: &[u8]) {
        if rx.len() < self.rx.len() {
            self.rx_length_errors += 1;
            return;
        }
        for i in 0..self.rx.entries().len() {
            let e = self.rx.entries()[i];
            if let Some(v) = e.read(rx) {
                // Read-only or out-of-range values in the RxPDO are ignored, as a drive that
                // keeps its previous value (e.g. an unsupported mode of operation).
                let _ = self.write_object(e.index, e.sub, v);
            }
        }
    }

    fn apply_controlword(&mut self) {
        use PowerState::*;
        let cw = self.controlword;
        let bit7 = cw & 0x0080 != 0;
        let edge = bit7 && !self.prev_bit7;
        self.prev_bit7 = bit7;
        let cmd = decode_command(cw);
        if cmd != Command::EnableOperation || self.state != SwitchedOn {
            self.enable_count = 0;
        }
        let next = match (self.state, cmd) {
            (Fault, _) if edge => {
                // Transition 15: fault reset.
                self.fe_flag = false;
                self.fe_over_ns = 0;
                SwitchOnDisabled
            }
            (SwitchOnDisabled, Command::Shutdown) => ReadyToSwitchOn,
            (ReadyToSwitchOn, Command::SwitchOn | Command::EnableOperation) => SwitchedOn,
            (ReadyToSwitchOn | SwitchedOn, Command::DisableVoltage | Command::QuickStop) => {
                SwitchOnDisabled
            }
            (SwitchedOn, Command::Shutdown) => ReadyToSwitchOn,
            (SwitchedOn, Command::EnableOperation) => {
                self.enable_count += 1;
                if self.enable_count > self.enable_delay_cycles {
                    self.enable_count = 0;
                    OperationEnabled
                } else {
                    SwitchedOn
                }
            }
            (OperationEnabled, Command::SwitchOn) => SwitchedOn,
            (OperationEnabled, Command::Shutdown) => ReadyToSwitchOn,
            (OperationEnabled | QuickStopActive, Command::DisableVoltage) => SwitchOnDisabled,
            (OperationEnabled, Command::QuickStop) => QuickStopActive,
            (QuickStopActive, Command::EnableOperation) => OperationEnabled,
            (s, _) => s,
        };
        if next == OperationEnabled && self.state != OperationEnabled {
            // Start the set-point ramp at the actual position.
            self.prev_target = self.position;
            self.fe_over_ns = 0;
        }
        self.state = next;
    }

    fn following(&self) -> bool {
        self.state == PowerState::OperationEnabled && self.mode == MODE_CSP
    }

    fn move_axis(&mut self, dt: f64) {
        self.limited = false;
        if !self.following() || dt <= 0.0 {
            // Brake: hold the position.
            // TODO(fixed-stop): the plant (obstacles, probe surfaces) acts here.
            self.velocity = 0.0;
            self.prev_target = self.position;
            return;
        }
        let r1 = f64::from(self.target);
        let r0 = self.prev_target;
        let x0 = self.position;
        let a = (-self.kv * dt).exp();
        // Exact solution of dx/dt = kv (r - x) for r ramping r0 -> r1 over dt (e = r - x):
        // e(dt) = s/kv + (e0 - s/kv) e^(-kv dt), s = (r1 - r0)/dt. With r0 == r1 this is
        // x += (r1 - x)(1 - e^(-kv dt)).
        let lag = (r1 - r0) / dt / self.kv;
        let e1 = lag + ((r0 - x0) - lag) * a;
        let mut x1 = r1 - e1;
        // TODO(torque): torque limits 0x6072/0x60E0/0x60E1 and fixed stops cut the motion here.
        if let Some(vmax) = self.max_velocity_inc {
            let d = (x1 - x0).clamp(-vmax * dt, vmax * dt);
            self.limited = d != x1 - x0;
            x1 = x0 + d;
        }
        if x1.is_finite() {
            self.velocity = (x1 - x0) / dt;
            self.position = x1;
        }
        self.prev_target = r1;
    }

    fn monitor_following_error(&mut self, dt_ns: u64) {
        if !self.following() || self.fe_window == u32::MAX {
            self.fe_over_ns = 0;
            return;
        }
        if self.following_error().unsigned_abs() > self.fe_window {
            self.fe_over_ns = self.fe_over_ns.saturating_add(dt_ns);
            if self.fe_over_ns > u64::from(self.fe_timeout_ms) * 1_000_000 {
                self.fe_flag = true;
                self.enter_fault(ERROR_FOLLOWING_ERROR);
            }
        } else {
            self.fe_over_ns = 0;
        }
    }

    fn enter_fault(&mut self, code: u16) {
        self.error_code = code;
        self.state = PowerState::FaultReactionActive;
        self.enable_count = 0;
        self.velocity = 0.0;
    }

    fn write_tx(&self, tx: &mut [u8]) {
        for e in self.tx.entries() {
            // Objects the model does not know (vendor objects) read as 0.
            let v = self.read_object(e.index, e.sub).unwrap_or(0);
            // Entries past a short image are left out; values beyond a narrower mapped type
            // saturate.
            let _ = e.write(tx, e.ty.saturate(v));
        }
    }

    /// Statusword 0x6041 as the drive reports it now.
    pub fn statusword(&self) -> u16 {
        use PowerState::*;
        let state_bits: u16 = match self.state {
            NotReadyToSwitchOn => return 0x0000,
            SwitchOnDisabled => 0x0040,
            ReadyToSwitchOn => 0x0021,
            SwitchedOn => 0x0023,
            OperationEnabled => 0x0027,
            QuickStopActive => 0x0007,
            FaultReactionActive => 0x000F,
            Fault => 0x0008,
            Unknown(sw) => sw,
        };
        let mut sw = state_bits | 0x0010 | 0x0200; // voltage enabled, remote
        if self.following() {
            sw |= 0x1000; // drive follows the command value (CSP)
            if self.following_error().unsigned_abs() <= self.position_window {
                sw |= 0x0400; // target reached
            }
            if self.limited {
                sw |= 0x0800; // internal limit active
            }
        }
        if self.fe_flag {
            sw |= 0x2000;
        }
        sw
    }

    /// Position actual value 0x6064 (rounded, saturated to `INTEGER32`).
    fn position_actual(&self) -> i32 {
        round_i32(self.position + self.disturbance)
    }

    /// Following error actual value 0x60F4 = 0x607A − 0x6064 while following, else 0.
    fn following_error(&self) -> i32 {
        if !self.following() {
            return 0;
        }
        let fe = i64::from(self.target) - i64::from(self.position_actual());
        fe.clamp(i32::MIN.into(), i32::MAX.into()) as i32
    }

    /// Read an object (SDO upload / CoE). Errors are CiA 301 abort codes ([`abort`]).
    pub fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32> {
        Ok(match (index, sub) {
            (0x603F, 0) => self.error_code.into(),
            (0x6040, 0) => self.controlword.into(),
            (0x6041, 0) => self.statusword().into(),
            (0x6060, 0) | (0x6061, 0) => self.mode.into(),
            (0x6064, 0) => self.position_actual().into(),
            (0x6065, 0) => self.fe_window.into(),
            (0x6066, 0) => self.fe_timeout_ms.into(),
            (0x6067, 0) => self.position_window.into(),
            (0x606C, 0) => round_i32(self.velocity).into(),
            (0x6072, 0) => self.max_torque.into(),
            (0x6077, 0) => 0, // TODO(torque): torque actual value.
            (0x607A, 0) => self.target.into(),
            (0x60B8, 0) => self.tp_function.into(),
            // TODO(touch-probe): latch status and edge positions; zeros until latching exists.
            (0x60B9, 0) | (0x60BA..=0x60BD, 0) => 0,
            (0x60D0, 0) => 2,
            (0x60D0, 1) => self.tp_source[0].into(),
            (0x60D0, 2) => self.tp_source[1].into(),
            (0x60E0, 0) => self.torque_limit_pos.into(),
            (0x60E1, 0) => self.torque_limit_neg.into(),
            (0x60F4, 0) => self.following_error().into(),
            (0x6502, 0) => SUPPORTED_DRIVE_MODES.into(),
            (i, _) => return Err(missing(i)),
        })
    }

    /// Write an object (SDO download / CoE). Read-only objects abort with 0x06010002, values
    /// outside the data type (or an unsupported mode of operation) with 0x06090030.
    pub fn write_object(&mut self, index: u16, sub: u8, value: i64) -> Result<(), u32> {
        let info = pdo::lookup(index, sub).ok_or_else(|| missing(index))?;
        if matches!(
            (index, sub),
            (
                0x603F | 0x6041 | 0x6061 | 0x6064 | 0x606C | 0x6077 | 0x60B9 | 0x60F4 | 0x6502,
                0
            ) | (0x60BA..=0x60BD, 0)
                | (0x60D0, 0)
        ) {
            return Err(abort::READ_ONLY);
        }
        if !info.ty.contains(value) {
            return Err(abort::VALUE_RANGE);
        }
        // In range of the object's type, so the narrowing casts below are exact.
        match (index, sub) {
            (0x6040, 0) => self.controlword = value as u16,
            (0x6060, 0) => {
                if !SUPPORTED_MODES.contains(&(value as i8)) {
                    return Err(abort::VALUE_RANGE);
                }
                self.mode = value as i8;
            }
            (0x6065, 0) => self.fe_window = value as u32,
            (0x6066, 0) => self.fe_timeout_ms = value as u16,
            (0x6067, 0) => self.position_window = value as u32,
            (0x6072, 0) => self.max_torque = value as u16,
            (0x607A, 0) => self.target = value as i32,
            // TODO(touch-probe): arming / disarming on changes of 0x60B8.
            (0x60B8, 0) => self.tp_function = value as u16,
            (0x60D0, 1) => self.tp_source[0] = value as i16,
            (0x60D0, 2) => self.tp_source[1] = value as i16,
            (0x60E0, 0) => self.torque_limit_pos = value as u16,
            (0x60E1, 0) => self.torque_limit_neg = value as u16,
            _ => return Err(abort::NO_OBJECT),
        }
        Ok(())
    }

    /// Power state now (NOT READY TO SWITCH ON until the first [`Ds402Model::step`]).
    pub fn state(&self) -> PowerState {
        self.state
    }

    /// Error code of the last fault (0x603F), kept after a fault reset; 0 before any fault.
    pub fn last_error_code(&self) -> u16 {
        self.error_code
    }

    /// RxPDOs ignored because they were shorter than the mapping.
    pub fn rx_length_errors(&self) -> u64 {
        self.rx_length_errors
    }

    /// Actual position in increments, unrounded (what 0x6064 reports rounded), including the
    /// disturbance.
    pub fn actual(&self) -> f64 {
        self.position + self.disturbance
    }

    /// Put the axis at `inc` increments (actual position including the disturbance), e.g. for a
    /// referenced start position. Non-finite values are ignored.
    pub fn set_actual(&mut self, inc: f64) {
        if inc.is_finite() {
            self.position = inc - self.disturbance;
            self.prev_target = self.position;
        }
    }

    /// Add a constant offset of `offset_inc` increments to the actual position, outside the
    /// position loop: the loop does not correct it, so it shows in 0x6064 and 0x60F4 until set
    /// back to 0 (an overshoot or a deflected axis, for monitoring tests). Non-finite values are
    /// ignored.
    pub fn set_disturbance(&mut self, offset_inc: f64) {
        if offset_inc.is_finite() {
            self.disturbance = offset_inc;
        }
    }

    /// Make the drive fault with `code` (0x603F) at the next step: FAULT REACTION ACTIVE for one
    /// cycle, then FAULT.
    pub fn inject_fault(&mut self, code: u16) {
        self.pending_fault = Some(code);
    }
}

fn missing(index: u16) -> u32 {
    if pdo::OBJECTS.iter().any(|o| o.index == index) {
        abort::NO_SUB_INDEX
    } else {
        abort::NO_OBJECT
    }
}

fn round_i32(v: f64) -> i32 {
    // `as` saturates and maps NaN to 0.
    v.round() as i32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::catalogue;

    fn model() -> Ds402Model {
        Ds402Model::new(&catalogue::builtin("cia402-generic").unwrap())
    }

    #[test]
    fn command_decode() {
        assert_eq!(decode_command(0x06), Command::Shutdown);
        assert_eq!(decode_command(0x07), Command::SwitchOn);
        assert_eq!(decode_command(0x0F), Command::EnableOperation);
        assert_eq!(decode_command(0x00), Command::DisableVoltage);
        assert_eq!(decode_command(0x02), Command::QuickStop);
        assert_eq!(decode_command(0x80), Command::DisableVoltage);
        assert_eq!(decode_command(0x86), Command::None);
    }

    #[test]
    fn object_access_abort_codes() {
        let mut m = model();
        assert_eq!(m.read_object(0x1000, 0), Err(abort::NO_OBJECT));
        assert_eq!(m.read_object(0x6041, 1), Err(abort::NO_SUB_INDEX));
        assert_eq!(m.write_object(0x6064, 0, 5), Err(abort::READ_ONLY));
        assert_eq!(m.write_object(0x60D0, 0, 2), Err(abort::READ_ONLY));
        assert_eq!(m.write_object(0x6066, 0, 70_000), Err(abort::VALUE_RANGE));
        assert_eq!(m.write_object(0x6060, 0, 1), Err(abort::VALUE_RANGE));
        assert_eq!(m.write_object(0x6065, 0, 1234), Ok(()));
        assert_eq!(m.read_object(0x6065, 0), Ok(1234));
        assert_eq!(m.write_object(0x60D0, 2, -1), Ok(()));
        assert_eq!(m.read_object(0x60D0, 2), Ok(-1));
        assert_eq!(m.read_object(0x60B9, 0), Ok(0));
    }

    #[test]
    fn first_step_leaves_not_ready() {
        let mut m = model();
        assert_eq!(m.state(), PowerState::NotReadyToSwitchOn);
        assert_eq!(m.statusword(), 0);
        let (rx, mut tx) = (vec![0; m.rx_len()], vec![0; m.tx_len()]);
        m.step(Nanos::ZERO, 0.001, &rx, &mut tx);
        assert_eq!(m.state(), PowerState::SwitchOnDisabled);
        // 0x0250: switch on disabled, voltage enabled, remote.
        assert_eq!(&tx[..2], &[0x50, 0x02]);
    }

    #[test]
    fn constant_set_point_is_the_step_formula() {
        let mut m = model();
        m.state = PowerState::OperationEnabled;
        m.mode = MODE_CSP;
        m.max_velocity_inc = None;
        m.target = 1000;
        m.prev_target = 1000.0;
        m.move_axis(0.001);
        let expect = 1000.0 * (1.0 - (-40.0f64 * 0.001).exp());
        assert!((m.position - expect).abs() < 1e-9, "{}", m.position);
    }
}
