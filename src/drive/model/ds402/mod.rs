//! CiA 402 drive model: the drive side of [`crate::drive::ds402::Ds402Adapter`].
//!
//! [`Ds402Model`] plays a servo drive in cyclic synchronous position mode (CSP, 0x6060 = 8). Each
//! bus cycle the link runs one step with the master's output image (the drive's RxPDO) and the
//! drive's input image (TxPDO) to fill. Everything is sans-IO: time is the `now` / `dt_s`
//! arguments, nothing reads a clock.
//!
//! # Methods by concern
//!
//! - cyclic: [`Ds402Model::step`] = [`Ds402Model::begin_step`] + [`Ds402Model::finish_step`];
//!   between the two a link may deliver digital-input edges inside the cycle with
//!   [`Ds402Model::input_edge`]; [`Ds402Model::rx_len`], [`Ds402Model::tx_len`]
//! - trajectory of the last step: [`Ds402Model::trajectory`], [`Ds402Model::position_at`]
//! - object dictionary (for SDO / CoE servers): [`Ds402Model::read_object`],
//!   [`Ds402Model::write_object`]
//! - plant and test knobs: [`Ds402Model::set_actual`], [`Ds402Model::actual`],
//!   [`Ds402Model::set_disturbance`], [`Ds402Model::inject_fault`],
//!   [`Ds402Model::set_input_level`], [`Ds402Model::input_level`],
//!   [`Ds402Model::set_fixed_stop`], [`Ds402Model::fixed_stop`]
//! - observation: [`Ds402Model::state`], [`Ds402Model::statusword`],
//!   [`Ds402Model::last_error_code`], [`Ds402Model::rx_length_errors`]
//!
//! # Time
//!
//! A step covers the cycle that **ends** at `now`: `[now − dt, now]`. The input image written
//! by the step is the drive's state at `now`, and the output image it read was written by the
//! master after the previous exchange and acts over the cycle ending now. (At the very start,
//! `now < dt`, the cycle's start is clamped to time 0.)
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
//!   internal limit active (a speed or torque limit cut the motion, or the torque demand is
//!   clipped), bit 12 drive follows the command value (CSP), bit 13 following error.
//! - **Servo** in OPERATION ENABLED with mode 8: the shared servo of every family
//!   ([`AxisPlant::servo`], `[model]`): by default a CSP cascade with velocity and acceleration
//!   feed-forward from the set-point sequence (following error 0 at constant speed, sub-µm on
//!   ramps); with `feed_forward = false` a first-order lag with gain kv whose exact solution for
//!   the linearly interpolated set-point gives the lag v / kv at constant speed and
//!   `actual += (target − actual) · (1 − e^(−kv·dt))` per cycle at a constant set-point. The
//!   solution is recorded at [`motion::SUBSAMPLES`] sub-samples per cycle (the trajectory). The
//!   actual position is kept as `f64` increments and reported rounded in 0x6064; 0x60F4 =
//!   0x607A − 0x6064 (the drive's control deviation at the end of the ramp). In every other
//!   state the position holds (brake).
//! - **Speed and torque limits**: `[model] max_velocity` limits the speed. The torque demand
//!   (0x6077, ‰) is the demanded acceleration / `[model] rated_acceleration` × 1000 (without
//!   feed-forward: the lag × `[model] torque_per_increment`); the effective limit is
//!   min(0x6072, 0x60E0) for positive and min(0x6072, 0x60E1) for negative torque, and clips the
//!   acceleration (without feed-forward: the speed, a viscous load).
//! - **Fixed stop** ([`Ds402Model::set_fixed_stop`]): a rigid wall the axis cannot pass from the
//!   side it is on. Pressed against it, the actual position stays, the following error grows,
//!   the torque saturates at the limit (bit 11).
//! - **Following error monitoring** (CiA 402 0x6065 / 0x6066): when |0x60F4| exceeds the window
//!   for longer than the time out, statusword bit 13 is set and the drive faults with error code
//!   0x8611 (0x603F, EMCY "following error"). A window of 0xFFFFFFFF switches monitoring off.
//! - **Touch probes** (0x60B8, 0x60B9, 0x60BA–0x60BD, 0x60D0, 0x60D5–0x60D8): see
//!   [`touch_probe`]. Digital inputs 1–4 come from [`Ds402Model::input_edge`] (latched at the
//!   position interpolated at the edge time, so the latch is exact to the sub-sample
//!   interpolation) and [`Ds402Model::set_input_level`]; the encoder zero pulse fires when the
//!   actual position crosses a multiple of `[model] zero_pulse_period` in either direction: a
//!   positive and a negative edge at the same instant (the index pulse is one encoder line wide,
//!   below the model's resolution), latched at exactly that multiple.
//! - **Process data errors**: an RxPDO shorter than the mapping is ignored as a whole (the drive
//!   keeps the previous set-points; CiA 301 EMCY 0x8210 "PDO not processed due to length
//!   error"), counted in [`Ds402Model::rx_length_errors`]. A short TxPDO gets every entry that
//!   fits.

pub mod motion;
mod objects;
mod power;
#[cfg(test)]
mod tests;
pub mod touch_probe;

use self::motion::round_i32;
use self::touch_probe::{Signal, TouchProbes, NUM_INPUTS};
use super::axis::{AxisPlant, Demand, ServoParams};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::pdo::PdoLayout;
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
/// At most this many encoder zero pulses are evaluated per step (a garbage set-point jump must
/// not make a step loop for long); more in one cycle are dropped.
const MAX_ZERO_PULSES_PER_STEP: usize = 1024;

/// Drive side of a CiA 402 servo in CSP mode (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Ds402Model {
    rx: PdoLayout,
    tx: PdoLayout,
    /// Whole objects of the device that play CiA 402 objects (`[roles]`): SDO access by the
    /// device's index reaches the CiA 402 object.
    roles: Vec<crate::drive::pdo::Role>,
    enable_delay_cycles: u32,
    /// Zero pulse period in increments.
    zero_pulse_period: f64,

    state: PowerState,
    controlword: u16,
    prev_bit7: bool,
    enable_count: u32,
    mode: i8,
    target: i32,

    /// Loop position in increments (what the position loop controls), set-point of the previous
    /// cycle (start of the interpolation ramp), constant offset outside the loop (see
    /// [`Ds402Model::set_disturbance`]), fixed stop in actual-position coordinates (including
    /// the disturbance) and trajectory of the last step (time, actual position incl.
    /// disturbance).
    pub(super) plant: AxisPlant,
    /// Velocity in increments/s over the last cycle.
    velocity: f64,
    /// A speed / torque limit cut the motion in the last cycle, or the torque is clipped.
    limited: bool,
    /// Torque actual value 0x6077 in ‰ (demand clipped to the limit).
    torque: f64,

    fe_window: u32,
    fe_timeout_ms: u16,
    position_window: u32,
    fe_over_ns: u64,
    fe_flag: bool,

    max_torque: u16,
    torque_limit_pos: u16,
    torque_limit_neg: u16,
    probes: TouchProbes,
    inputs: [bool; NUM_INPUTS as usize],

    error_code: u16,
    pending_fault: Option<u16>,
    clock_ns: u64,
    rx_length_errors: u64,
}

impl Ds402Model {
    /// A drive in NOT READY TO SWITCH ON at increment 0, with the PDO mapping, loop gain,
    /// monitoring defaults and probe behaviour of `def` (`[rxpdo]`, `[txpdo]`, `[model]`,
    /// `[probe]`).
    pub fn new(def: &DriveDefinition) -> Self {
        let m = &def.model;
        let positive_or = |v: f64, default: f64| {
            if v.is_finite() && v > 0.0 {
                v
            } else {
                default
            }
        };
        Ds402Model {
            rx: def.rxpdo.clone(),
            tx: def.txpdo.clone(),
            roles: def
                .roles
                .iter()
                .filter(|r| r.bits.is_none())
                .copied()
                .collect(),
            enable_delay_cycles: m.enable_delay_cycles,
            zero_pulse_period: positive_or(m.zero_pulse_period, 10_000.0),
            state: PowerState::NotReadyToSwitchOn,
            controlword: 0,
            prev_bit7: false,
            enable_count: 0,
            mode: 0,
            target: 0,
            plant: AxisPlant::new(ServoParams::from_definition(def)),
            velocity: 0.0,
            limited: false,
            torque: 0.0,
            fe_window: m.following_error_window,
            fe_timeout_ms: m.following_error_timeout_ms,
            position_window: DEFAULT_POSITION_WINDOW,
            fe_over_ns: 0,
            fe_flag: false,
            max_torque: DEFAULT_TORQUE_LIMIT,
            torque_limit_pos: DEFAULT_TORQUE_LIMIT,
            torque_limit_neg: DEFAULT_TORQUE_LIMIT,
            probes: TouchProbes::new(def.probe.rearm_requires_zero),
            inputs: [false; NUM_INPUTS as usize],
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

    /// One bus cycle without input edges: [`begin_step`](Self::begin_step), then
    /// [`finish_step`](Self::finish_step). Never panics: short images, garbage bytes and a
    /// negative or non-finite `dt_s` (treated as 0) are all handled.
    pub fn step(&mut self, now: Nanos, dt_s: f64, rx: &[u8], tx: &mut [u8]) {
        self.begin_step(now, dt_s, rx);
        self.finish_step(tx);
    }

    /// First phase of a bus cycle ending at `now`: decode the RxPDO `rx` (controlword, target,
    /// 0x60B8 …), run the power state machine, advance the position loop over `dt_s` seconds
    /// and record the trajectory, fire encoder zero pulses, monitor the following error.
    /// Negative or non-finite `dt_s` counts as 0 (no motion, a one-point trajectory at `now`).
    pub fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
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
        self.move_axis(now, dt);
        self.zero_pulses();
        self.monitor_following_error(dt_ns);
    }

    /// A digital-input edge inside the current cycle: `input` (1..=4) goes to the level
    /// `rising` at time `at`. Touch probes armed for that input and edge latch the position
    /// interpolated at `at` ([`position_at`](Self::position_at); `at` outside the last
    /// trajectory is clamped into it). An edge to the level the input already has is ignored,
    /// as is an unknown input.
    pub fn input_edge(&mut self, input: u8, rising: bool, at: Nanos) {
        let Some(level) = input
            .checked_sub(1)
            .and_then(|i| self.inputs.get_mut(usize::from(i)))
        else {
            return;
        };
        if *level == rising {
            return;
        }
        *level = rising;
        let pos = round_i32(self.position_clamped(at));
        self.probes.edge(Signal::Input(input), rising, pos);
    }

    /// Second phase of a bus cycle: write the TxPDO into `tx`.
    pub fn finish_step(&mut self, tx: &mut [u8]) {
        self.write_tx(tx);
    }

    /// Trajectory of the last step: `(time, actual position in increments incl. the
    /// disturbance)`, [`motion::SUBSAMPLES`] + 1 points from the start to the end of the cycle
    /// (one point for a zero-length step; empty before the first step).
    pub fn trajectory(&self) -> &[(Nanos, f64)] {
        self.plant.trajectory()
    }

    /// Actual position (increments, incl. the disturbance) at `t` within the last step,
    /// linearly interpolated between the sub-samples; `None` outside the last step.
    pub fn position_at(&self, t: Nanos) -> Option<f64> {
        self.plant.position_at(t)
    }

    /// [`position_at`](Self::position_at) with `t` clamped into the last step; the actual
    /// position when there is no trajectory yet.
    fn position_clamped(&self, t: Nanos) -> f64 {
        self.plant.position_clamped(t)
    }

    /// Set digital input `input` (1..=4) to a static level without an edge (nothing latches).
    pub fn set_input_level(&mut self, input: u8, level: bool) {
        if let Some(l) = input
            .checked_sub(1)
            .and_then(|i| self.inputs.get_mut(usize::from(i)))
        {
            *l = level;
        }
    }

    /// Level of digital input `input` (1..=4).
    pub fn input_level(&self, input: u8) -> Option<bool> {
        self.inputs.get(usize::from(input.checked_sub(1)?)).copied()
    }

    /// Put a rigid wall at `position` increments (actual position, incl. the disturbance), or
    /// remove it with `None`. The axis cannot pass it from the side it is on now (standing
    /// exactly at it, the first motion away decides). Non-finite positions are ignored.
    pub fn set_fixed_stop(&mut self, position: Option<f64>) {
        self.plant.set_fixed_stop(position)
    }

    /// The wall of [`set_fixed_stop`](Self::set_fixed_stop), in increments.
    pub fn fixed_stop(&self) -> Option<f64> {
        self.plant.fixed_stop()
    }

    fn read_rx(&mut self, rx: &[u8]) {
        if rx.len() < self.rx.len() {
            self.rx_length_errors += 1;
            return;
        }
        // The entries under their own index, then the CiA 402 objects other objects play
        // (`[roles]`: e.g. the controlword in 0x7010:01, the touch probe function in single bits).
        for i in 0..self.rx.entries().len() + self.rx.roles().len() {
            let e = match self.rx.entries().get(i) {
                Some(e) if e.is_gap() || self.rx.in_role(e) => continue,
                Some(e) => *e,
                None => self.rx.roles()[i - self.rx.entries().len()],
            };
            if let Some(v) = e.read(rx) {
                // Read-only or out-of-range values in the RxPDO are ignored, as a drive that
                // keeps its previous value (e.g. an unsupported mode of operation).
                let _ = self.write_object(e.index, e.sub, v);
            }
        }
    }

    /// Effective torque limits (‰) for positive and negative torque (CiA 402 0x6072, 0x60E0,
    /// 0x60E1).
    fn torque_limits(&self) -> (f64, f64) {
        (
            f64::from(self.max_torque.min(self.torque_limit_pos)),
            f64::from(self.max_torque.min(self.torque_limit_neg)),
        )
    }

    /// Advance the servo over the cycle `[now − dt, now]` and record the trajectory.
    fn move_axis(&mut self, now: Nanos, dt: f64) {
        if !self.following() || dt <= 0.0 {
            // Brake: hold the position.
            self.plant.hold(now, dt);
            self.velocity = 0.0;
            self.torque = 0.0;
            self.limited = false;
            return;
        }
        let (t_pos, t_neg) = self.torque_limits();
        let c = self.plant.servo(
            now,
            dt,
            Demand::Position(f64::from(self.target)),
            t_pos,
            t_neg,
        );
        self.velocity = self.plant.velocity();
        self.torque = c.torque;
        self.limited = c.limited;
    }

    /// Encoder zero pulses crossed in the last trajectory: a positive and a negative edge at
    /// each multiple of the period, latched at exactly that multiple.
    fn zero_pulses(&mut self) {
        if !self.probes.listens(Signal::ZeroPulse) {
            return;
        }
        let p = self.zero_pulse_period;
        let mut fired = 0;
        for w in self.plant.trajectory.windows(2) {
            let (xa, xb) = (w[0].1, w[1].1);
            let (na, nb) = ((xa / p).floor(), (xb / p).floor());
            if !(na.is_finite() && nb.is_finite()) || na == nb {
                continue;
            }
            // Multiples crossed, in the order the axis passes them.
            let (first, last, step) = if nb > na {
                (na + 1.0, nb, 1.0)
            } else {
                (na, nb + 1.0, -1.0)
            };
            let mut k = first;
            loop {
                if fired >= MAX_ZERO_PULSES_PER_STEP {
                    return;
                }
                fired += 1;
                let at = round_i32(k * p);
                self.probes.edge(Signal::ZeroPulse, true, at);
                self.probes.edge(Signal::ZeroPulse, false, at);
                if k == last {
                    break;
                }
                k += step;
            }
        }
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
        self.torque = 0.0;
    }

    fn write_tx(&self, tx: &mut [u8]) {
        let plain = self
            .tx
            .entries()
            .iter()
            .filter(|e| !e.is_gap() && !self.tx.in_role(e));
        for e in plain.chain(self.tx.roles()) {
            // Objects the model does not know (vendor objects) read as 0.
            let v = self.read_object(e.index, e.sub).unwrap_or(0);
            // Entries past a short image are left out; values beyond a narrower mapped type
            // saturate.
            let _ = e.write(tx, e.ty.saturate(v));
        }
    }

    /// Position actual value 0x6064 (rounded, saturated to `INTEGER32`).
    fn position_actual(&self) -> i32 {
        round_i32(self.plant.actual())
    }

    /// Following error actual value 0x60F4 = 0x607A − 0x6064 while following, else 0.
    fn following_error(&self) -> i32 {
        if !self.following() {
            return 0;
        }
        let fe = i64::from(self.target) - i64::from(self.position_actual());
        fe.clamp(i32::MIN.into(), i32::MAX.into()) as i32
    }

    /// Power state now (NOT READY TO SWITCH ON until the first step).
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
        self.plant.actual()
    }

    /// Put the axis at `inc` increments (actual position including the disturbance), e.g. for a
    /// referenced start position. A fixed stop takes the side of the new position. Non-finite
    /// values are ignored.
    pub fn set_actual(&mut self, inc: f64) {
        self.plant.set_actual(inc)
    }

    /// Add a constant offset of `offset_inc` increments to the actual position, outside the
    /// position loop: the loop does not correct it, so it shows in 0x6064 and 0x60F4 until set
    /// back to 0 (an overshoot or a deflected axis, for monitoring tests). The torque follows
    /// the loop's own lag and does not see it. Non-finite values are ignored.
    pub fn set_disturbance(&mut self, offset_inc: f64) {
        self.plant.set_disturbance(offset_inc)
    }

    /// Make the drive fault with `code` (0x603F) at the next step: FAULT REACTION ACTIVE for one
    /// cycle, then FAULT.
    pub fn inject_fault(&mut self, code: u16) {
        self.pending_fault = Some(code);
    }

    /// Make the drive fault with `code` (0x603F) now, between two cycles, on the drive's own
    /// clock (a CiA 402 drive's communication fault reaction, 0x6007 abort connection option
    /// code 1): FAULT REACTION ACTIVE and, since the model's fault reaction has nothing left to
    /// do (speed and torque are zero at once, the brake holds the position in every state but
    /// OPERATION ENABLED, whatever 0x605E fault reaction option code says), FAULT (transitions
    /// 13, 14). No step is needed, so it happens when no SYNC comes at all. A fault pending
    /// from [`Self::inject_fault`] is replaced.
    pub fn fault_now(&mut self, code: u16) {
        self.pending_fault = None;
        self.enter_fault(code);
        self.state = PowerState::Fault;
    }
}
