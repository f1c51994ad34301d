//! PROFIdrive drive model: the drive side of [`crate::drive::profidrive::ProfidriveAdapter`]
//! (telegrams 3 / 5 / 102 / 105, same [`Telegram`] definition as the adapter).
//!
//! Sources: FCT-C4 §6.5 (P0660 = 80 makes I0.0 the measuring input), §7.3 (fixed stop, torque
//! limitation, drive lag monitoring off); the PROFIdrive profile (PI order no. 3.172: STW1 / ZSW1, G1_STW /
//! G1_ZSW, telegrams, MOMRED). Sans-IO like every model: time comes in as arguments.
//!
//! # Behaviour
//!
//! - **Power state** (PROFIdrive state machine, reduced): switching on inhibited → (STW1 bit 0 =
//!   0, bits 1, 2 = 1, e.g. `0x047E`) ready to switch on → (bit 0 = 1, `0x047F`) ready to
//!   operate → (bit 3 = 1, after `[model] enable_delay_cycles`) operation enabled. Bit 0 = 0 goes
//!   back to ready to switch on, bit 1 = 0 (OFF2) to switching on inhibited, bit 2 = 0 (OFF3)
//!   holds the axis (quick stop active) until bit 0 = 0. A fault is "fault reaction" for one
//!   cycle, then fault; a rising edge of STW1 bit 7 acknowledges it.
//! - **Speed control** (telegrams 3 / 102): the speed set-point NSOLL_B (N4, `[profidrive]
//!   reference_speed`) is followed by the drive's speed loop (the shared servo of every family,
//!   [`AxisPlant::servo`] with [`Demand::Speed`]: NSOLL_B and its change as feed-forward, speed
//!   and torque clipping, fixed stop); the position loop is the master's. The torque limit is
//!   P1520 (assumption) × (1 − MOMRED / 0x4000). Without feed-forward (`[model] feed_forward =
//!   false`) NSOLL_B is integrated into an internal set-point followed by a fast first-order loop
//!   (anti wind-up at the torque limit), as before.
//! - **DSC** (telegrams 5 / 105): the drive closes the position loop itself with gain KPC
//!   (0.001 1/s, assumption) on its fine set-point, a ramp with slope NSOLL_B (also the velocity
//!   feed-forward) starting at `x_s + XERR + NSOLL_B(previous) · T`: XERR is the master's
//!   set-point minus the actual value `x_s` the drive sampled at the start of the previous cycle
//!   (the one the master received: PROFIdrive isochronous timing, assumption), so the ramp runs
//!   from the previous target to the new one, as a CiA 402 drive in CSP does
//!   ([`Demand::Ramp`]).
//! - **Following error monitoring** (assumption): |XERR| (DSC) or the distance between the
//!   integrated speed set-point and the axis (speed control) exceeding
//!   P2546 for longer than `[model] following_error_timeout_ms` faults with [`FAULT_FOLLOWING`];
//!   P2546 = 4294967295 switches it off.
//! - **Encoder interface** (G1_STW / G1_ZSW / G1_XIST1 / G1_XIST2): command 1 with bit 7
//!   (flying measurement) activates the requested functions (1/2 = probe 1 positive / negative
//!   edge on input 1 = I0.0, 3/4 = probe 2 on input 2, assumption); it is refused with encoder
//!   error [`ENCODER_ERROR_NOT_SUPPORTED`] when the probe's input is not a measuring input
//!   (P0660 for probe 1, P0661 for probe 2 (assumption), value 80) or in reference-mark mode.
//!   An edge ends an active function ("active" clears, "value available" sets). Command 2 puts
//!   the value of the lowest requested available function into G1_XIST2; command 3 aborts the
//!   requested functions and discards their values. Values stay available until aborted.
//!   G1_STW bit 15 acknowledges an encoder error (G1_ZSW bit 11 follows bit 15). G1_XIST2
//!   carries, by priority: the error code (G1_ZSW bit 15), the value read, the absolute
//!   position (bit 13), else 0.

use crate::drive::catalogue::DriveDefinition;
use crate::drive::model::axis::{AxisPlant, Demand, ServoParams};
use crate::drive::model::{abort, DriveModel};
use crate::drive::profidrive::{
    g1_stw, g1_zsw, n4_to_speed, speed_to_n4, stw1, zsw1, ProfidriveConfig, Telegram, Word,
    PNU_P0660,
};
use crate::drive::{DriveError, PowerState};
use crate::units::Nanos;

/// Fault number of a following error (SINAMICS F07452 style, assumption).
pub const FAULT_FOLLOWING: u16 = 7452;
/// Encoder error code "command not supported" in G1_XIST2 (HEIDENHAIN code 0x0F01, notes
/// `cnc.md` §3.3).
pub const ENCODER_ERROR_NOT_SUPPORTED: u32 = 0x0F01;
/// PNU of the measuring-input function of the second probe input (assumption).
pub const PNU_P0661: u16 = 661;
/// PNU P0922 telegram selection (read-only here).
pub const PNU_TELEGRAM: u16 = 922;
/// PNU P0947 last fault number (read-only).
pub const PNU_FAULT: u16 = 947;
/// PNU of the torque limit in ‰ of rated torque (P1520, assumption).
pub const PNU_TORQUE_LIMIT: u16 = 1520;
/// PNU of the following error window in increments (P2546, assumption); `u32::MAX` = off.
pub const PNU_LAG_WINDOW: u16 = 2546;
/// Digital inputs of the model (1 = I0.0 probe 1, 2 = probe 2, 3–4 spare).
const NUM_INPUTS: usize = 4;

/// Drive side of a PROFIdrive servo (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct ProfidriveModel {
    tg: Telegram,
    reference_speed: f64,
    enable_delay_cycles: u32,
    fe_timeout_ms: u16,

    state: PowerState,
    prev_ack: bool,
    enable_count: u32,
    pending_fault: Option<u16>,
    error_code: u16,

    stw1: u16,
    nsoll: i32,
    momred: u16,
    g1_stw: u16,
    xerr: i32,
    kpc: u32,

    /// Loop position, set-point (`prev_target`), disturbance, wall, trajectory of the last
    /// cycle.
    plant: AxisPlant,
    velocity: f64,
    torque: f64,
    limited: bool,
    fe_over_ns: u64,
    /// Actual position (incl. disturbance) at the start of the previous cycle: what the master
    /// saw when it computed this cycle's XERR.
    sample_prev: f64,
    /// NSOLL_B of the previous cycle, increments/s.
    nsoll_prev: f64,
    /// The speed set-point integrated (speed control): the position the axis should be at, for
    /// the following error monitoring.
    speed_ref: f64,

    inputs: [bool; NUM_INPUTS],
    active: u8,
    available: u8,
    values: [i32; 4],
    encoder_error: Option<u32>,
    sign_of_life: u16,

    p0660: i64,
    p0661: i64,
    torque_limit: u16,
    lag_window: u32,
}

impl ProfidriveModel {
    /// A drive in "not ready" at increment 0 with the telegram and PNU defaults of `def`
    /// (`[profidrive]`, `[model]`).
    pub fn new(def: &DriveDefinition) -> Result<Self, DriveError> {
        let cfg = ProfidriveConfig::parse(def)?;
        let m = &def.model;
        Ok(ProfidriveModel {
            tg: cfg.telegram,
            reference_speed: cfg.reference_speed,
            enable_delay_cycles: m.enable_delay_cycles,
            fe_timeout_ms: m.following_error_timeout_ms,
            state: PowerState::NotReadyToSwitchOn,
            prev_ack: false,
            enable_count: 0,
            pending_fault: None,
            error_code: 0,
            stw1: 0,
            nsoll: 0,
            momred: 0,
            g1_stw: 0,
            xerr: 0,
            kpc: 0,
            plant: AxisPlant::new(ServoParams::from_definition(def)),
            velocity: 0.0,
            torque: 0.0,
            limited: false,
            fe_over_ns: 0,
            sample_prev: 0.0,
            nsoll_prev: 0.0,
            speed_ref: 0.0,
            inputs: [false; NUM_INPUTS],
            active: 0,
            available: 0,
            values: [0; 4],
            encoder_error: None,
            sign_of_life: 0,
            p0660: cfg.p0660,
            p0661: crate::drive::profidrive::P0660_MEASURING_INPUT,
            torque_limit: cfg.torque_limit,
            lag_window: m.following_error_window,
        })
    }

    /// The telegram.
    pub fn telegram(&self) -> Telegram {
        self.tg
    }

    /// ZSW1 as written in the next image.
    pub fn zsw1(&self) -> u16 {
        let s = self.state;
        let mut w = zsw1::NO_OFF2 | zsw1::CONTROL_REQUESTED;
        if s != PowerState::QuickStopActive {
            w |= zsw1::NO_OFF3;
        }
        match s {
            PowerState::SwitchOnDisabled => w |= zsw1::SWITCHING_ON_INHIBITED,
            PowerState::ReadyToSwitchOn => w |= zsw1::READY_TO_SWITCH_ON,
            PowerState::SwitchedOn => w |= zsw1::READY_TO_SWITCH_ON | zsw1::READY_TO_OPERATE,
            PowerState::OperationEnabled | PowerState::QuickStopActive => {
                w |= zsw1::READY_TO_SWITCH_ON | zsw1::READY_TO_OPERATE | zsw1::OPERATION_ENABLED
            }
            PowerState::Fault | PowerState::FaultReactionActive => w |= zsw1::FAULT,
            _ => {}
        }
        w
    }

    /// G1_ZSW as written in the next image.
    pub fn g1_zsw(&self) -> u16 {
        let mut w = u16::from(self.active) | (u16::from(self.available) << g1_zsw::VALUE_SHIFT);
        if self.inputs[0] {
            w |= g1_zsw::PROBE1;
        }
        if self.inputs[1] {
            w |= g1_zsw::PROBE2;
        }
        if self.g1_stw & g1_stw::ACK_ERROR != 0 {
            w |= g1_zsw::ACK_ACTIVE;
        }
        if self.encoder_error.is_some() {
            w |= g1_zsw::ERROR;
        } else if self.g1_stw & g1_stw::ABS_CYCLIC != 0 {
            w |= g1_zsw::ABS_CYCLIC;
        }
        if self.g1_stw & g1_stw::PARKING != 0 {
            w |= g1_zsw::PARKING;
        }
        w
    }

    /// Make the encoder interface report error `code` (G1_ZSW bit 15, code in G1_XIST2); active
    /// functions end.
    pub fn inject_encoder_error(&mut self, code: u32) {
        self.encoder_error = Some(code);
        self.active = 0;
    }

    /// Torque demand clipped to the effective limit, ‰ of rated torque.
    pub fn torque(&self) -> f64 {
        self.torque
    }

    /// Effective torque limit in ‰: P1520 × (1 − MOMRED / 0x4000) (assumption).
    pub fn torque_limit(&self) -> f64 {
        let red = f64::from(self.momred.min(0x4000)) / f64::from(0x4000u16);
        f64::from(self.torque_limit) * (1.0 - red)
    }

    fn read_rx(&mut self, rx: &[u8]) {
        let tg = self.tg;
        if rx.len() < tg.setpoint_len() {
            // Short image: the drive keeps the previous set-points.
            return;
        }
        let get = |w| tg.get(rx, w).unwrap_or(0);
        self.stw1 = get(Word::Stw1) as u16;
        self.nsoll = get(Word::NsollB) as i32;
        self.g1_stw = get(Word::G1Stw) as u16;
        if tg.momred() {
            self.momred = get(Word::Momred) as u16;
        }
        if tg.dsc() {
            self.xerr = get(Word::Xerr) as i32;
            self.kpc = get(Word::Kpc);
        }
    }

    fn power(&mut self) {
        let w = self.stw1;
        let ack = w & stw1::FAULT_ACK != 0;
        let ack_edge = ack && !self.prev_ack;
        self.prev_ack = ack;
        let on = w & stw1::ON != 0;
        use PowerState::*;
        self.state = match self.state {
            NotReadyToSwitchOn => SwitchOnDisabled,
            FaultReactionActive => Fault,
            Fault if ack_edge => SwitchOnDisabled,
            Fault => Fault,
            _ if w & stw1::NO_OFF2 == 0 => SwitchOnDisabled,
            SwitchOnDisabled if !on && w & stw1::NO_OFF3 != 0 => ReadyToSwitchOn,
            ReadyToSwitchOn if on => SwitchedOn,
            SwitchedOn if !on => ReadyToSwitchOn,
            SwitchedOn if w & stw1::ENABLE_OPERATION != 0 => {
                if self.enable_count >= self.enable_delay_cycles {
                    OperationEnabled
                } else {
                    self.enable_count += 1;
                    SwitchedOn
                }
            }
            OperationEnabled if !on => ReadyToSwitchOn,
            OperationEnabled if w & stw1::NO_OFF3 == 0 => QuickStopActive,
            OperationEnabled if w & stw1::ENABLE_OPERATION == 0 => SwitchedOn,
            QuickStopActive if !on => SwitchOnDisabled,
            s => s,
        };
        if self.state != SwitchedOn {
            self.enable_count = 0;
        }
        if let Some(code) = self.pending_fault.take() {
            self.enter_fault(code);
        }
    }

    fn enter_fault(&mut self, code: u16) {
        self.error_code = code;
        self.state = PowerState::FaultReactionActive;
        self.velocity = 0.0;
        self.torque = 0.0;
    }

    fn encoder(&mut self) {
        let w = self.g1_stw;
        if w & g1_stw::ACK_ERROR != 0 && self.encoder_error.is_some() {
            self.encoder_error = None;
            self.active = 0;
        }
        if self.encoder_error.is_some() {
            return;
        }
        let mask = (w & g1_stw::FUNCTIONS) as u8;
        match (w >> g1_stw::COMMAND_SHIFT) & 7 {
            g1_stw::ACTIVATE => {
                if w & g1_stw::FLYING == 0 {
                    // Reference-mark search is not modelled.
                    self.encoder_error = Some(ENCODER_ERROR_NOT_SUPPORTED);
                    return;
                }
                for f in 0..4u8 {
                    let bit = 1u8 << f;
                    if mask & bit == 0 || (self.active | self.available) & bit != 0 {
                        continue;
                    }
                    let param = if f < 2 { self.p0660 } else { self.p0661 };
                    if param != crate::drive::profidrive::P0660_MEASURING_INPUT {
                        self.encoder_error = Some(ENCODER_ERROR_NOT_SUPPORTED);
                        self.active = 0;
                        return;
                    }
                    self.active |= bit;
                }
            }
            g1_stw::ABORT => {
                self.active &= !mask;
                self.available &= !mask;
            }
            _ => {}
        }
    }

    fn move_axis(&mut self, now: Nanos, dt: f64) {
        // The actual value the master's XERR refers to: the one sampled at the start of the
        // previous cycle (delivered one exchange later, as every link does; PROFIdrive
        // isochronous mode: Ti / To, assumption).
        let sample = self.sample_prev;
        self.sample_prev = self.plant.actual();
        if self.state != PowerState::OperationEnabled || dt <= 0.0 {
            self.plant.hold(now, dt);
            self.velocity = 0.0;
            self.torque = 0.0;
            self.limited = false;
            self.nsoll_prev = 0.0;
            self.speed_ref = self.plant.position;
            return;
        }
        let speed = n4_to_speed(self.nsoll, self.reference_speed);
        let speed = if speed.is_finite() { speed } else { 0.0 };
        let limit = self.torque_limit();
        let dsc_kv = f64::from(self.kpc) * 1e-3;
        let demand = if self.tg.dsc() && dsc_kv > 0.0 {
            // DSC: XERR = the master's set-point at the time of `sample` − `sample`; the
            // set-point ramp of this cycle starts one NSOLL_B step after that set-point.
            let r0 = sample - self.plant.disturbance + f64::from(self.xerr) + self.nsoll_prev * dt;
            Demand::Ramp {
                r0,
                r1: r0 + speed * dt,
                v_ff: speed,
                kv: dsc_kv,
            }
        } else {
            Demand::Speed(speed)
        };
        let v_max = self.plant.servo_params().v_max;
        self.speed_ref += speed.clamp(-v_max, v_max) * dt;
        self.nsoll_prev = speed;
        let c = self.plant.servo(now, dt, demand, limit, limit);
        self.velocity = self.plant.velocity();
        self.torque = c.torque;
        self.limited = c.limited;
        if c.limited && matches!(demand, Demand::Speed(_)) {
            // Anti wind-up: the reference does not run away from an axis held at a limit by
            // more than the lag that limit allows.
            let lag = self.speed_ref - self.plant.position;
            let cap = f64::from(self.lag_window.min(u32::MAX - 1)).max(1.0) * 2.0;
            if lag.abs() > cap {
                self.speed_ref = self.plant.position + cap.copysign(lag);
            }
        }
    }

    fn monitor(&mut self, dt: f64) {
        if self.state != PowerState::OperationEnabled || self.lag_window == u32::MAX {
            self.fe_over_ns = 0;
            return;
        }
        let dev = if self.tg.dsc() {
            f64::from(self.xerr).abs()
        } else {
            (self.speed_ref - self.plant.position).abs()
        };
        if dev > f64::from(self.lag_window) {
            self.fe_over_ns = self.fe_over_ns.saturating_add((dt * 1e9) as u64);
            if self.fe_over_ns > u64::from(self.fe_timeout_ms) * 1_000_000 {
                self.fe_over_ns = 0;
                self.enter_fault(FAULT_FOLLOWING);
            }
        } else {
            self.fe_over_ns = 0;
        }
    }

    fn position_clamped(&self, t: Nanos) -> f64 {
        self.plant.position_clamped(t)
    }

    fn actual_pos(&self) -> f64 {
        self.plant.actual()
    }

    fn xist2(&self) -> u32 {
        if let Some(code) = self.encoder_error {
            return code;
        }
        let mask = (self.g1_stw & g1_stw::FUNCTIONS) as u8;
        if (self.g1_stw >> g1_stw::COMMAND_SHIFT) & 7 == g1_stw::READ_VALUE {
            if let Some(f) = (0..4).find(|f| mask & self.available & (1 << f) != 0) {
                return self.values[f] as u32;
            }
        }
        if self.g1_stw & g1_stw::ABS_CYCLIC != 0 {
            return wrap_u32(self.actual_pos());
        }
        0
    }
}

fn wrap_u32(x: f64) -> u32 {
    let r = x.round();
    if r.is_finite() {
        (r as i64) as u32
    } else {
        0
    }
}

impl DriveModel for ProfidriveModel {
    fn rx_len(&self) -> usize {
        self.tg.setpoint_len()
    }

    fn tx_len(&self) -> usize {
        self.tg.actual_len()
    }

    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s.min(3600.0)
        } else {
            0.0
        };
        self.read_rx(rx);
        self.power();
        self.encoder();
        self.move_axis(now, dt);
        self.monitor(dt);
        self.sign_of_life = (self.sign_of_life + 1) & 0xF;
    }

    fn input_edge(&mut self, input: u8, rising: bool, at: Nanos) {
        let Some(i) = input.checked_sub(1).map(usize::from) else {
            return;
        };
        let Some(level) = self.inputs.get_mut(i) else {
            return;
        };
        if *level == rising {
            return;
        }
        *level = rising;
        if i >= 2 || self.encoder_error.is_some() {
            return;
        }
        let f = 2 * i + usize::from(!rising);
        let bit = 1u8 << f;
        if self.active & bit != 0 {
            let pos = self.position_clamped(at).round();
            self.values[f] = if pos.is_finite() {
                pos as i64 as i32
            } else {
                0
            };
            self.active &= !bit;
            self.available |= bit;
        }
    }

    fn finish_step(&mut self, tx: &mut [u8]) {
        let tg = self.tg;
        tg.put(tx, Word::Zsw1, u32::from(self.zsw1()));
        tg.put(
            tx,
            Word::NistB,
            speed_to_n4(self.velocity, self.reference_speed) as u32,
        );
        tg.put(tx, Word::Zsw2, u32::from(self.sign_of_life << 12));
        tg.put(tx, Word::Meldw, if self.limited { 1 << 1 } else { 0 });
        tg.put(tx, Word::G1Zsw, u32::from(self.g1_zsw()));
        tg.put(tx, Word::G1Xist1, wrap_u32(self.actual_pos()));
        tg.put(tx, Word::G1Xist2, self.xist2());
    }

    fn plant(&self) -> Option<&AxisPlant> {
        Some(&self.plant)
    }

    fn plant_mut(&mut self) -> Option<&mut AxisPlant> {
        Some(&mut self.plant)
    }

    fn set_input_level(&mut self, input: u8, level: bool) {
        if let Some(l) = input
            .checked_sub(1)
            .and_then(|i| self.inputs.get_mut(usize::from(i)))
        {
            *l = level;
        }
    }

    fn input_level(&self, input: u8) -> Option<bool> {
        self.inputs.get(usize::from(input.checked_sub(1)?)).copied()
    }

    fn state(&self) -> PowerState {
        self.state
    }

    fn last_error_code(&self) -> u16 {
        self.error_code
    }

    fn inject_fault(&mut self, code: u16) {
        self.pending_fault = Some(code);
    }

    fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32> {
        let v = match index {
            PNU_P0660 => self.p0660,
            PNU_P0661 => self.p0661,
            PNU_TELEGRAM => i64::from(self.tg.number),
            PNU_FAULT => i64::from(self.error_code),
            PNU_TORQUE_LIMIT => i64::from(self.torque_limit),
            PNU_LAG_WINDOW => i64::from(self.lag_window),
            _ => return Err(abort::NO_OBJECT),
        };
        if sub != 0 {
            return Err(abort::NO_SUB_INDEX);
        }
        Ok(v)
    }

    fn write_object(&mut self, index: u16, sub: u8, value: i64) -> Result<(), u32> {
        self.read_object(index, sub)?;
        let range = |lo: i64, hi: i64| {
            if (lo..=hi).contains(&value) {
                Ok(value)
            } else {
                Err(abort::VALUE_RANGE)
            }
        };
        match index {
            PNU_P0660 => self.p0660 = range(0, 65535)?,
            PNU_P0661 => self.p0661 = range(0, 65535)?,
            PNU_TORQUE_LIMIT => self.torque_limit = range(0, 65535)? as u16,
            PNU_LAG_WINDOW => self.lag_window = range(0, u32::MAX.into())? as u32,
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
