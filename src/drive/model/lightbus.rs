//! Lightbus AX2000 drive model: the drive side of [`crate::drive::lightbus::LightbusAdapter`]
//! (telegram: [`crate::drive::lightbus::telegram`]; FCT-C4 §6.2; Beckhoff AX2000 documentation).
//!
//! - **Axis physics**: the shared servo of every family ([`AxisPlant::servo`], `[model]`:
//!   cascade with feed-forward or first-order loop, set-point ramped over the cycle,
//!   sub-samples, speed / torque clipping, fixed stop); the terminal drive model uses the same
//!   plant with a velocity input.
//! - **Power** (assumption, no AX2000 state machine in the seeds): ready after the first step;
//!   enabled while control word bit 0 is set and no fault; quick stop holds the position; a
//!   fault (lag error or injected) stays until a rising edge of control word bit 1.
//! - **Probe**: digital input 2 (every input number the simulation delivers maps to it;
//!   assumption) latches the position interpolated at the edge time (exact to the
//!   sub-samples) when IN2MODE = 26 and the edge is enabled by the latch control word; one value
//!   per arming (first event); a new arming sequence clears the valid bits.
//! - **Parameters** (`read_object` / `write_object`, sub 0, indices of this crate's choosing,
//!   assumption): [`PARAM_IN2MODE`] (0..=255, default `[lightbus] in2mode`),
//!   [`PARAM_TORQUE_LIMIT`] (0.1 % of rated, u16, default 3000), [`PARAM_LAG_WINDOW`]
//!   (increments, u32, 4294967295 = lag monitoring off, default `[model]
//!   following_error_window`), [`PARAM_ERROR_CODE`] (read-only).

use super::abort;
use crate::drive::catalogue::DriveDefinition;
use crate::drive::lightbus::telegram::{self, Command};
use crate::drive::lightbus::{
    LightbusConfig, IN2MODE_PROBE, PARAM_ERROR_CODE, PARAM_IN2MODE, PARAM_LAG_WINDOW,
    PARAM_TORQUE_LIMIT,
};
use crate::drive::PowerState;
use crate::units::Nanos;

/// Error code of a lag (following) error (assumption: AX2000 error F03 "following error").
pub const ERROR_LAG: u16 = 0x0003;

/// Default torque limit in 0.1 % of rated torque (assumption).
const DEFAULT_TORQUE_LIMIT: u16 = 3000;

pub use super::axis::{clean_dt, AxisPlant};
use super::axis::{Demand, ServoParams};

pub use super::ds402::motion::round_i32;

/// Drive side of a Lightbus AX2000 (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct LightbusModel {
    plant: AxisPlant,
    /// Torque actual value, ‰ of rated.
    torque: f64,
    in2mode: i64,
    torque_limit: u16,
    lag_window: u32,
    lag_timeout_ns: u64,
    lag_over_ns: u64,
    lag_flag: bool,
    started: bool,
    enabled: bool,
    quick_stop: bool,
    fault: bool,
    prev_reset: bool,
    pending_fault: Option<u16>,
    error_code: u16,
    cmd: Command,
    /// Arming sequence taken, enabled edges, valid bits.
    seq: u8,
    latch_pos_enabled: bool,
    latch_neg_enabled: bool,
    latch_valid: u16,
    latch_position: i32,
    in2: bool,
}

impl LightbusModel {
    /// A drive at increment 0 with `[model]` and `[lightbus]` of `def` (an unreadable
    /// `[lightbus]` falls back to defaults; the adapter reports it).
    pub fn new(def: &DriveDefinition) -> Self {
        let m = &def.model;
        let cfg = LightbusConfig::from_definition(def).unwrap_or_default();
        LightbusModel {
            plant: AxisPlant::new(ServoParams::from_definition(def)),
            torque: 0.0,
            in2mode: cfg.in2mode,
            torque_limit: DEFAULT_TORQUE_LIMIT,
            lag_window: m.following_error_window,
            lag_timeout_ns: u64::from(m.following_error_timeout_ms) * 1_000_000,
            lag_over_ns: 0,
            lag_flag: false,
            started: false,
            enabled: false,
            quick_stop: false,
            fault: false,
            prev_reset: false,
            pending_fault: None,
            error_code: 0,
            cmd: Command::default(),
            seq: 0,
            latch_pos_enabled: false,
            latch_neg_enabled: false,
            latch_valid: 0,
            latch_position: 0,
            in2: false,
        }
    }

    /// The axis physics.
    pub fn plant(&self) -> &AxisPlant {
        &self.plant
    }

    fn following_error(&self) -> i32 {
        if !self.enabled {
            return 0;
        }
        let fe = i64::from(self.cmd.position) - i64::from(round_i32(self.plant.actual()));
        fe.clamp(i32::MIN.into(), i32::MAX.into()) as i32
    }

    fn take_latch_control(&mut self) {
        let lc = self.cmd.latch_control;
        let seq = telegram::sequence(lc);
        if seq == 0 {
            self.seq = 0;
            self.latch_pos_enabled = false;
            self.latch_neg_enabled = false;
            self.latch_valid = 0;
            return;
        }
        if seq != self.seq {
            self.seq = seq;
            self.latch_valid = 0;
        }
        self.latch_pos_enabled = lc & telegram::LC_POS != 0;
        self.latch_neg_enabled = lc & telegram::LC_NEG != 0;
    }
}

impl super::DriveModel for LightbusModel {
    fn rx_len(&self) -> usize {
        telegram::COMMAND_LEN
    }

    fn tx_len(&self) -> usize {
        telegram::FEEDBACK_LEN
    }

    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        // A short telegram is ignored as a whole (the drive keeps the previous set-points).
        if let Ok(c) = Command::decode(rx) {
            self.cmd = c;
        }
        self.started = true;
        if let Some(code) = self.pending_fault.take() {
            self.fault = true;
            self.error_code = code;
        }
        let reset = self.cmd.control & telegram::CW_RESET != 0;
        if reset && !self.prev_reset && self.fault {
            self.fault = false;
            self.lag_flag = false;
        }
        self.prev_reset = reset;
        let was_enabled = self.enabled;
        self.enabled = !self.fault && self.cmd.control & telegram::CW_ENABLE != 0;
        self.quick_stop = self.enabled && self.cmd.control & telegram::CW_QUICK_STOP != 0;
        self.take_latch_control();
        let dt = clean_dt(dt_s);
        if self.enabled && !self.quick_stop {
            if !was_enabled {
                // Enabling takes the actual position as the start of the ramp (no jump).
                let a = self.plant.actual();
                self.plant.set_actual(a);
            }
            let limit = f64::from(self.torque_limit);
            let c = self.plant.servo(
                now,
                dt,
                Demand::Position(f64::from(self.cmd.position)),
                limit,
                limit,
            );
            self.torque = c.torque;
        } else {
            self.plant.hold(now, dt);
            self.torque = 0.0;
        }
        // Lag monitoring.
        if self.enabled && self.lag_window != u32::MAX {
            if self.following_error().unsigned_abs() > self.lag_window {
                self.lag_over_ns = self.lag_over_ns.saturating_add((dt * 1e9) as u64);
                if self.lag_over_ns > self.lag_timeout_ns {
                    self.lag_flag = true;
                    self.fault = true;
                    self.enabled = false;
                    self.error_code = ERROR_LAG;
                }
            } else {
                self.lag_over_ns = 0;
            }
        } else {
            self.lag_over_ns = 0;
        }
    }

    fn input_edge(&mut self, _input: u8, rising: bool, at: Nanos) {
        // The drive has one probing input, digital input 2; the simulation's probe is wired to
        // it whatever P-AXIS-00517 says (assumption).
        if self.in2 == rising {
            return;
        }
        self.in2 = rising;
        if self.in2mode != IN2MODE_PROBE || self.seq == 0 || self.latch_valid != 0 {
            return;
        }
        let armed = if rising {
            self.latch_pos_enabled
        } else {
            self.latch_neg_enabled
        };
        if armed {
            self.latch_position = round_i32(self.plant.position_clamped(at));
            self.latch_valid = if rising {
                telegram::LS_POS_VALID
            } else {
                telegram::LS_NEG_VALID
            };
        }
    }

    fn finish_step(&mut self, tx: &mut [u8]) {
        use telegram::*;
        let status = self.status_word();
        let mut ls = with_sequence(self.latch_valid, self.seq);
        if self.in2 {
            ls |= LS_IN2_LEVEL;
        }
        if self.in2mode == IN2MODE_PROBE {
            ls |= LS_IN2_PROBE;
        }
        let fb = Feedback {
            status,
            position: round_i32(self.plant.actual()),
            following_error: self.following_error(),
            latch_status: ls,
            latch_position: self.latch_position,
        };
        // A short image gets nothing (the master reports the length).
        let _ = fb.encode(tx);
    }

    fn plant(&self) -> Option<&AxisPlant> {
        Some(&self.plant)
    }

    fn plant_mut(&mut self) -> Option<&mut AxisPlant> {
        Some(&mut self.plant)
    }

    fn set_input_level(&mut self, _input: u8, level: bool) {
        self.in2 = level;
    }

    fn input_level(&self, input: u8) -> Option<bool> {
        (1..=4).contains(&input).then_some(self.in2)
    }

    fn state(&self) -> PowerState {
        if !self.started {
            return PowerState::NotReadyToSwitchOn;
        }
        crate::drive::lightbus::decode_status(self.status_word())
    }

    fn last_error_code(&self) -> u16 {
        self.error_code
    }

    fn inject_fault(&mut self, code: u16) {
        self.pending_fault = Some(code);
    }

    fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32> {
        let v = match index {
            PARAM_IN2MODE => self.in2mode,
            PARAM_TORQUE_LIMIT => i64::from(self.torque_limit),
            PARAM_LAG_WINDOW => i64::from(self.lag_window),
            PARAM_ERROR_CODE => i64::from(self.error_code),
            _ => return Err(abort::NO_OBJECT),
        };
        if sub != 0 {
            return Err(abort::NO_SUB_INDEX);
        }
        Ok(v)
    }

    fn write_object(&mut self, index: u16, sub: u8, value: i64) -> Result<(), u32> {
        self.read_object(index, sub)?;
        match index {
            PARAM_IN2MODE => {
                self.in2mode = (0..=255)
                    .contains(&value)
                    .then_some(value)
                    .ok_or(abort::VALUE_RANGE)?
            }
            PARAM_TORQUE_LIMIT => {
                self.torque_limit = u16::try_from(value).map_err(|_| abort::VALUE_RANGE)?
            }
            PARAM_LAG_WINDOW => {
                self.lag_window = u32::try_from(value).map_err(|_| abort::VALUE_RANGE)?
            }
            _ => return Err(abort::READ_ONLY),
        }
        Ok(())
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
        self
    }
}

impl LightbusModel {
    /// Status word of the feedback telegram.
    fn status_word(&self) -> u16 {
        use telegram::*;
        let mut status = 0;
        if self.started && !self.fault {
            status |= SW_READY;
        }
        if self.enabled {
            status |= SW_ENABLED;
        }
        if self.quick_stop {
            status |= SW_QUICK_STOP;
        }
        if self.fault {
            status |= SW_FAULT;
        }
        if self.lag_flag {
            status |= SW_LAG;
        }
        if self.plant.limited {
            status |= SW_LIMIT;
        }
        status
    }
}
