//! SERCOS drive model: the drive side of [`crate::drive::sercos::SercosAdapter`] (AX5000 kind).
//!
//! Reads the MDT and writes the AT of [`crate::drive::sercos::Telegram`]; the axis physics is the
//! shared servo of every family ([`super::axis::AxisPlant::servo`]: cascade with feed-forward or
//! first-order loop per `[model]`, sub-sampled trajectory, speed and torque clipping, fixed stop).
//!
//! # Behaviour
//!
//! - **Power** (status word S-0-0135 bits 15/14, IEC 61800-7-204): 00 at start, 01 (ready
//!   for power-up) after the first step, 10 (main power on) after the second (mains are always
//!   on); control word bits 15 + 14 (drive on + enable) → 11 after `[model]
//!   enable_delay_cycles`; clearing either → 10. Bit 13 of the control word = 1 runs (the
//!   drive follows S-0-0047, status bit 3 set), 0 halts (position held).
//! - **Error** (C1D, status bit 13): S-0-0159 exceeded or `DriveModel::inject_fault`; the
//!   power stage goes off (bits 15/14 = 01). Reset: rising edge of control bit 15, or a write to
//!   S-0-0099 (assumption for the cyclic reset). S-0-0011 reads the class 1 diagnostic
//!   (bit 11 = excessive position deviation, AX2000 IDN 159).
//! - **S-0-0092** bipolar torque limit, 0.1 % of rated, start value 1000 = 100.0 %: clips the
//!   torque demand (see [`super::axis`]) in both directions, as 0x6072 in the
//!   CiA 402 model. The AX5000 caps it at 100.0 %; the model accepts the whole UNS16 range so
//!   that the seed's CANopen example (`VAL=5000`, "torque limiting off") runs (assumption).
//! - **S-0-0159** monitoring window (increments): 0 = off; values above the IDN's maximum
//!   0x7FFFFFFF also mean off (assumption, so that `MON_WINDOW VAL=4294967295` behaves as on a
//!   CiA 402 drive); |S-0-0189| beyond it → error at once (no time-out, AX2000 IDN 159 text).
//! - **Probe unit** (FCT-C4 §6.1; probe IDNs S-0-0169 … S-0-0409, IEC 61800-7-204): real-time control bit n (MDT control word bit
//!   5 + n) drives the signal S-0-0301 / 0303 allocates: 405 = probe 1 enable, 406 = probe 2
//!   enable. Enable 0 → 1 and 1 → 0 clear the probe's latched bits (values stay). While enabled,
//!   the first edge selected by S-0-0169 (bit 0 probe 1 pos, 1 probe 1 neg, 2 probe 2 pos, 3
//!   probe 2 neg) stores the position at the edge time (interpolated between the trajectory's
//!   sub-samples, exact like the CiA 402 model) in S-0-0130 … 0133 and sets S-0-0179 bit 0 … 3
//!   (= S-0-0409 … 0412); later edges are ignored until the enable is cleared and set again.
//!   Probe 1 listens to digital input 1, probe 2 to input 2 (assumption; AX5000 P-0-0251 can
//!   select others). Real-time status bit n shows the signal S-0-0305 / 0307 allocates: 409 …
//!   412 latched, 401 / 402 probe input level, 0 = none. The probing cycle command S-0-0170 is
//!   stored but the unit works without it (assumption).

use super::abort;
use super::axis::AxisPlant;
use super::axis::{Demand, ServoParams};
use super::ds402::motion::round_i32;
use crate::drive::catalogue::DriveDefinition;
use crate::drive::sercos::{self, idn, rt_mask, Telegram, CW_DRIVE_ON, CW_ENABLE, CW_RUN};
use crate::drive::{DriveError, PowerState};
use crate::units::Nanos;

/// S-0-0011 bit 11: excessive position deviation (AX2000 IDN 159 / IDN 11).
pub const C1D_POSITION_DEVIATION: u16 = 1 << 11;
/// Digital inputs of the model.
const NUM_INPUTS: usize = 4;
/// Largest S-0-0159 value that monitors (the IDN's maximum).
const WINDOW_MAX: u32 = 0x7FFF_FFFF;

/// Drive side of a SERCOS servo (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct SercosModel {
    telegram: Telegram,
    enable_delay_cycles: u32,

    /// Status word bits 15/14.
    ready: u8,
    error: bool,
    c1d: u16,
    pending_fault: Option<u16>,
    enable_count: u32,
    control: u16,
    prev_drive_on: bool,
    target: i32,

    /// Loop position, set-point ramp start, disturbance, wall, trajectory of the last cycle.
    plant: AxisPlant,
    velocity: f64,
    torque: f64,

    torque_limit: u16,
    window: u32,
    probe_control: u16,
    probing_cycle: u16,
    rtc_alloc: [u16; 2],
    rts_alloc: [u16; 2],
    /// Probe enable signals (S-0-0405 / 0406) as last applied.
    enabled: [bool; 2],
    /// S-0-0179 bits 0..3.
    latched: u16,
    /// S-0-0130 … 0133.
    values: [i32; 4],
    inputs: [bool; NUM_INPUTS],
    rx_length_errors: u64,
}

impl SercosModel {
    /// A drive at increment 0 with the telegram and IDN start values of `def`'s `[sercos]`
    /// (defaults: FCT-C4 §6.1 example S-0-0301 = 405, 0305 = 409, 0307 = 401, 0169 = 1) and the
    /// loop of `[model]`.
    pub fn new(def: &DriveDefinition) -> Result<Self, DriveError> {
        let cfg = sercos::config(def)?;
        let m = &def.model;
        let mut model = SercosModel {
            telegram: cfg.telegram,
            enable_delay_cycles: m.enable_delay_cycles,
            ready: 0,
            error: false,
            c1d: 0,
            pending_fault: None,
            enable_count: 0,
            control: 0,
            prev_drive_on: false,
            target: 0,
            plant: AxisPlant::new(ServoParams::from_definition(def)),
            velocity: 0.0,
            torque: 0.0,
            torque_limit: 1000,
            window: m.following_error_window,
            probe_control: 1,
            probing_cycle: 0,
            rtc_alloc: [idn::PROBE_1_ENABLE, 0],
            rts_alloc: [idn::PROBE_1_POS_LATCHED, idn::PROBE_1_INPUT],
            enabled: [false; 2],
            latched: 0,
            values: [0; 4],
            inputs: [false; NUM_INPUTS],
            rx_length_errors: 0,
        };
        for (code, v) in cfg.idn_defaults {
            // Ranges were checked by the parser; a refused value keeps the default.
            let _ = model.write_object(code, 0, v);
        }
        Ok(model)
    }

    /// Bytes of the MDT.
    pub fn rx_len(&self) -> usize {
        self.telegram.mdt.len()
    }

    /// Bytes of the AT.
    pub fn tx_len(&self) -> usize {
        self.telegram.at.len()
    }

    /// Drive status word S-0-0135.
    pub fn status_word(&self) -> u16 {
        let mut s = u16::from(self.ready) << 14;
        if self.error {
            s |= sercos::SW_ERROR;
        }
        if self.following() {
            s |= sercos::SW_FOLLOWING;
        }
        for n in 1..=2u8 {
            if self.rt_status(n) {
                s |= rt_mask(n);
            }
        }
        s
    }

    fn rt_status(&self, n: u8) -> bool {
        match self.rts_alloc[usize::from(n - 1)] {
            a @ 409..=412 => self.latched & (1 << (a - 409)) != 0,
            a @ 401..=402 => self.inputs[usize::from(a - 401)],
            _ => false,
        }
    }

    fn following(&self) -> bool {
        self.ready == 3 && !self.error && self.control & CW_RUN != 0
    }

    /// MDT decode, power, probe enables, motion, monitoring over the cycle ending at `now`.
    pub fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s.min(3600.0)
        } else {
            0.0
        };
        if rx.len() < self.telegram.mdt.len() {
            self.rx_length_errors += 1;
        } else {
            for e in self.telegram.mdt.entries().to_vec() {
                if let Some(v) = e.read(rx) {
                    match e.index {
                        idn::CONTROL_WORD => self.control = v as u16,
                        idn::POSITION_COMMAND => self.target = v as i32,
                        other => {
                            let _ = self.write_object(other, 0, v);
                        }
                    }
                }
            }
        }
        self.power();
        self.apply_probe_enables();
        self.move_axis(now, dt);
        self.monitor();
    }

    fn power(&mut self) {
        let drive_on = self.control & CW_DRIVE_ON != 0;
        let rising = drive_on && !self.prev_drive_on;
        self.prev_drive_on = drive_on;
        if let Some(code) = self.pending_fault.take() {
            self.enter_error(code);
        }
        if self.error {
            if rising {
                self.error = false;
                self.ready = 2;
            } else {
                return;
            }
        }
        match self.ready {
            0 => self.ready = 1,
            1 => self.ready = 2,
            2 => {
                if drive_on && self.control & CW_ENABLE != 0 {
                    if self.enable_count >= self.enable_delay_cycles {
                        self.ready = 3;
                        self.plant.prev_target = self.plant.position;
                    } else {
                        self.enable_count += 1;
                    }
                } else {
                    self.enable_count = 0;
                }
            }
            _ => {
                if !(drive_on && self.control & CW_ENABLE != 0) {
                    self.ready = 2;
                    self.enable_count = 0;
                }
            }
        }
    }

    fn enter_error(&mut self, code: u16) {
        self.error = true;
        self.c1d = code;
        self.ready = 1;
        self.enable_count = 0;
        self.velocity = 0.0;
        self.torque = 0.0;
    }

    fn apply_probe_enables(&mut self) {
        for p in 0..2 {
            let want = (1..=2u8).any(|n| {
                self.control & rt_mask(n) != 0
                    && self.rtc_alloc[usize::from(n - 1)] == idn::PROBE_1_ENABLE + p as u16
            });
            if want != self.enabled[p] {
                // Either transition resets the probe's latch status (S-0-0405).
                self.latched &= !(0b11 << (2 * p));
                self.enabled[p] = want;
            }
        }
    }

    fn move_axis(&mut self, now: Nanos, dt: f64) {
        if !self.following() || dt <= 0.0 {
            self.plant.hold(now, dt);
            self.velocity = 0.0;
            self.torque = 0.0;
            return;
        }
        let limit = f64::from(self.torque_limit);
        let c = self.plant.servo(
            now,
            dt,
            Demand::Position(f64::from(self.target)),
            limit,
            limit,
        );
        self.velocity = self.plant.velocity();
        self.torque = c.torque;
    }

    fn monitor(&mut self) {
        if !self.following() || self.window == 0 || self.window > WINDOW_MAX {
            return;
        }
        if self.following_distance().unsigned_abs() > self.window {
            self.enter_error(C1D_POSITION_DEVIATION);
        }
    }

    /// A digital-input edge at `at` inside the current cycle (see the module documentation).
    pub fn input_edge(&mut self, input: u8, rising: bool, at: Nanos) {
        let Some(i) = usize::from(input)
            .checked_sub(1)
            .filter(|i| *i < NUM_INPUTS)
        else {
            return;
        };
        if self.inputs[i] == rising {
            return;
        }
        self.inputs[i] = rising;
        if i >= 2 || !self.enabled[i] {
            return;
        }
        let slot = 2 * i + usize::from(!rising);
        if self.probe_control & (1 << slot) == 0 || self.latched & (1 << slot) != 0 {
            return;
        }
        self.values[slot] = round_i32(self.position_clamped(at));
        self.latched |= 1 << slot;
    }

    /// Write the AT.
    pub fn finish_step(&mut self, tx: &mut [u8]) {
        for e in self.telegram.at.entries() {
            let v = self.read_object(e.index, 0).unwrap_or(0);
            let _ = e.write(tx, e.ty.saturate(v));
        }
    }

    fn position_clamped(&self, t: Nanos) -> f64 {
        self.plant.position_clamped(t)
    }

    /// Position feedback S-0-0051 (rounded).
    fn feedback(&self) -> i32 {
        round_i32(self.plant.actual())
    }

    /// Following distance S-0-0189 = S-0-0047 − S-0-0051 while following, else 0.
    fn following_distance(&self) -> i32 {
        if !self.following() {
            return 0;
        }
        (i64::from(self.target) - i64::from(self.feedback()))
            .clamp(i32::MIN.into(), i32::MAX.into()) as i32
    }

    /// Acyclic read of IDN `code` (bit 15 P, bits 12–14 parameter set); `sub` must be 0.
    pub fn read_object(&self, code: u16, sub: u8) -> Result<i64, u32> {
        if sub != 0 {
            return Err(abort::NO_SUB_INDEX);
        }
        Ok(match code {
            idn::C1D => self.c1d.into(),
            idn::POSITION_COMMAND => self.target.into(),
            idn::POSITION_FEEDBACK => self.feedback().into(),
            idn::TORQUE_FEEDBACK => (self.torque.round() as i16).into(),
            idn::TORQUE_LIMIT => self.torque_limit.into(),
            130..=133 => self.values[usize::from(code - 130)].into(),
            idn::CONTROL_WORD => self.control.into(),
            idn::STATUS_WORD => self.status_word().into(),
            idn::MONITORING_WINDOW => self.window.into(),
            idn::PROBE_CONTROL => self.probe_control.into(),
            idn::PROBING_CYCLE => self.probing_cycle.into(),
            idn::PROBE_STATUS => self.latched.into(),
            idn::FOLLOWING_DISTANCE => self.following_distance().into(),
            idn::RTC_BIT_1 => self.rtc_alloc[0].into(),
            idn::RTC_BIT_2 => self.rtc_alloc[1].into(),
            idn::RTS_BIT_1 => self.rts_alloc[0].into(),
            idn::RTS_BIT_2 => self.rts_alloc[1].into(),
            401 | 402 => i64::from(self.inputs[usize::from(code - 401)]),
            405 | 406 => i64::from(self.enabled[usize::from(code - 405)]),
            409..=412 => i64::from(self.latched >> (code - 409) & 1),
            _ => return Err(abort::NO_OBJECT),
        })
    }

    /// Acyclic write of IDN `code`: S-0-0092 (UNS16), S-0-0159 (UNS32), S-0-0169 (0..=15),
    /// S-0-0170, S-0-0301 / 0303 (0, 405, 406), S-0-0305 / 0307 (0, 401, 402, 409 … 412),
    /// S-0-0099 (any value: reset C1D). Read-only IDNs abort with 0x06010002, bad values with
    /// 0x06090030.
    pub fn write_object(&mut self, code: u16, sub: u8, value: i64) -> Result<(), u32> {
        if sub != 0 {
            return Err(abort::NO_SUB_INDEX);
        }
        let range = |lo: i64, hi: i64| {
            if (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(abort::VALUE_RANGE)
            }
        };
        match code {
            idn::TORQUE_LIMIT => {
                range(0, 0xFFFF)?;
                self.torque_limit = value as u16;
            }
            idn::MONITORING_WINDOW => {
                range(0, u32::MAX.into())?;
                self.window = value as u32;
            }
            idn::PROBE_CONTROL => {
                range(0, 15)?;
                self.probe_control = value as u16;
            }
            idn::PROBING_CYCLE => {
                range(0, 0xFFFF)?;
                self.probing_cycle = value as u16;
            }
            idn::RTC_BIT_1 | idn::RTC_BIT_2 => {
                if !matches!(value, 0 | 405 | 406) {
                    return Err(abort::VALUE_RANGE);
                }
                self.rtc_alloc[usize::from(code == idn::RTC_BIT_2)] = value as u16;
            }
            idn::RTS_BIT_1 | idn::RTS_BIT_2 => {
                if !matches!(value, 0 | 401 | 402 | 409..=412) {
                    return Err(abort::VALUE_RANGE);
                }
                self.rts_alloc[usize::from(code == idn::RTS_BIT_2)] = value as u16;
            }
            idn::RESET_C1D => {
                if self.error {
                    self.error = false;
                    self.ready = 2;
                }
            }
            idn::POSITION_COMMAND => {
                range(i32::MIN.into(), i32::MAX.into())?;
                self.target = value as i32;
            }
            idn::CONTROL_WORD => {
                range(0, 0xFFFF)?;
                self.control = value as u16;
            }
            _ => {
                return Err(if self.read_object(code, 0).is_ok() {
                    abort::READ_ONLY
                } else {
                    abort::NO_OBJECT
                })
            }
        }
        Ok(())
    }

    /// Power state in the common model (same decode as the adapter).
    pub fn state(&self) -> PowerState {
        sercos::SercosAdapter::power_state(self.status_word())
    }

    /// Actual position incl. the disturbance.
    pub fn actual(&self) -> f64 {
        self.plant.actual()
    }

    /// MDTs ignored because they were shorter than the telegram.
    pub fn rx_length_errors(&self) -> u64 {
        self.rx_length_errors
    }
}

impl super::DriveModel for SercosModel {
    fn rx_len(&self) -> usize {
        SercosModel::rx_len(self)
    }
    fn tx_len(&self) -> usize {
        SercosModel::tx_len(self)
    }
    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        SercosModel::begin_step(self, now, dt_s, rx)
    }
    fn input_edge(&mut self, input: u8, rising: bool, at: Nanos) {
        SercosModel::input_edge(self, input, rising, at)
    }
    fn finish_step(&mut self, tx: &mut [u8]) {
        SercosModel::finish_step(self, tx)
    }
    fn plant(&self) -> Option<&AxisPlant> {
        Some(&self.plant)
    }
    fn plant_mut(&mut self) -> Option<&mut AxisPlant> {
        Some(&mut self.plant)
    }
    fn set_input_level(&mut self, input: u8, level: bool) {
        if let Some(l) = usize::from(input)
            .checked_sub(1)
            .and_then(|i| self.inputs.get_mut(i))
        {
            *l = level;
        }
    }
    fn input_level(&self, input: u8) -> Option<bool> {
        self.inputs.get(usize::from(input).checked_sub(1)?).copied()
    }
    fn state(&self) -> PowerState {
        SercosModel::state(self)
    }
    fn last_error_code(&self) -> u16 {
        self.c1d
    }
    fn inject_fault(&mut self, code: u16) {
        self.pending_fault = Some(code);
    }
    fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32> {
        SercosModel::read_object(self, index, sub)
    }
    fn write_object(&mut self, index: u16, sub: u8, value: i64) -> Result<(), u32> {
        SercosModel::write_object(self, index, sub, value)
    }
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
        self
    }
}
