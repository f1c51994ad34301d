//! Drive models: the drive side of each profile, used by the emulators and the in-memory link.
//!
//! A model is sans-IO like the adapters: it gets the output image the master sent, the time and
//! the cycle length, and writes its input image. Object access for SDO / CoE servers returns CiA
//! 301 abort codes ([`abort`]).

pub mod axis;
pub mod ds402;
pub mod el1252;
pub mod lightbus;
pub mod profidrive;
pub mod sercos;
pub mod terminal;

pub use self::axis::AxisPlant;
use super::PowerState;
use crate::units::Nanos;
use std::fmt;

/// The drive side of one profile, as the in-memory link and the emulators drive it (sans-IO).
///
/// One exchange at `now` covers the cycle `[now − dt, now]`: [`begin_step`](Self::begin_step)
/// decodes the output image and moves the axis (recording the trajectory), the plant then
/// delivers probe edges inside the cycle with [`input_edge`](Self::input_edge), and
/// [`finish_step`](Self::finish_step) writes the input image. Positions are drive increments.
/// Acyclic access (`read_object` / `write_object`) addresses the profile's parameters: CiA 402
/// objects `index:sub`; for SERCOS the IDN number in `index` (bit 15 P-/S-IDN, bits 12–14 the
/// parameter set); for PROFIdrive the PNU in `index` with `sub` as its sub-index. Refusals are
/// CiA 301 abort codes ([`abort`]).
///
/// The axis physics (trajectory, fixed stop, actual position, disturbance) lives in the model's
/// [`AxisPlant`] ([`plant`](Self::plant) / [`plant_mut`](Self::plant_mut)); the methods that
/// only delegate to it have default implementations. A model without an axis (a timestamp
/// terminal) overrides them.
pub trait DriveModel: Send + fmt::Debug {
    /// Bytes of the output image the model reads.
    fn rx_len(&self) -> usize;
    /// Bytes of the input image the model writes.
    fn tx_len(&self) -> usize;
    /// Decode the output image and advance the axis over the cycle ending at `now`.
    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]);
    /// A digital-input edge at `at` inside the current cycle (probe signal).
    fn input_edge(&mut self, input: u8, rising: bool, at: Nanos);
    /// Write the input image of this cycle.
    fn finish_step(&mut self, tx: &mut [u8]);
    /// Before a step ending at model time `now`: the DC system time (ns since 2000) of the
    /// EtherCAT device hosting the model at that instant (its SYNC0), for a model that stamps
    /// events with DC time (the EL1252 terminal: an edge at `at` is stamped
    /// `system_time − (now − at)`). Not called on a segment without a clock of its own
    /// (in-process, virtual time). Default: ignored.
    fn set_dc_time(&mut self, _now: Nanos, _system_time: u64) {}
    /// `begin_step` and `finish_step` without edges.
    fn step(&mut self, now: Nanos, dt_s: f64, rx: &[u8], tx: &mut [u8]) {
        self.begin_step(now, dt_s, rx);
        self.finish_step(tx);
    }
    /// The axis physics (position loop, trajectory of the last cycle, wall, disturbance);
    /// `None` for a device without an axis (the EL1252 input terminal).
    fn plant(&self) -> Option<&AxisPlant> {
        None
    }
    /// The axis physics, mutable.
    fn plant_mut(&mut self) -> Option<&mut AxisPlant> {
        None
    }
    /// Trajectory of the last cycle: (time, position in increments).
    fn trajectory(&self) -> &[(Nanos, f64)] {
        self.plant().map_or(&[], AxisPlant::trajectory)
    }
    /// Position (increments) at `t` within the last cycle.
    fn position_at(&self, t: Nanos) -> Option<f64> {
        self.plant()?.position_at(t)
    }
    /// Static level of a digital input.
    fn set_input_level(&mut self, input: u8, level: bool);
    /// Level of a digital input (`None`: no such input).
    fn input_level(&self, input: u8) -> Option<bool>;
    /// A mechanical wall at this position (increments), or none.
    fn set_fixed_stop(&mut self, position: Option<f64>) {
        if let Some(p) = self.plant_mut() {
            p.set_fixed_stop(position)
        }
    }
    /// The wall, if any.
    fn fixed_stop(&self) -> Option<f64> {
        self.plant()?.fixed_stop()
    }
    /// Power state in the common state model.
    fn state(&self) -> PowerState;
    /// Last error code (profile-specific; CiA 402 0x603F style).
    fn last_error_code(&self) -> u16;
    /// Actual position (increments, including the disturbance).
    fn actual(&self) -> f64 {
        self.plant().map_or(0.0, AxisPlant::actual)
    }
    /// Put the axis at this actual position (increments).
    fn set_actual(&mut self, inc: f64) {
        if let Some(p) = self.plant_mut() {
            p.set_actual(inc)
        }
    }
    /// Constant offset of the reported position (collision / overshoot emulation).
    fn set_disturbance(&mut self, offset_inc: f64) {
        if let Some(p) = self.plant_mut() {
            p.set_disturbance(offset_inc)
        }
    }
    /// Act on acyclically written commands now, between two cycles (a CiA 402 controlword
    /// written by SDO or an event-driven RPDO, and the start-up transition at power-up): the
    /// power state machine moves, the axis does not. Default: nothing (the profile acts in its
    /// cycle only).
    fn settle(&mut self) {}
    /// Force a drive fault with this error code.
    fn inject_fault(&mut self, code: u16);
    /// Force a drive fault with this error code now, between two cycles (the drive's reaction
    /// to a lost master on its own clock, when no cycle comes). Default: [`Self::inject_fault`]
    /// (the profile faults at its next cycle).
    fn fault_now(&mut self, code: u16) {
        self.inject_fault(code)
    }
    /// Acyclic read.
    fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32>;
    /// Acyclic write.
    fn write_object(&mut self, index: u16, sub: u8, value: i64) -> Result<(), u32>;
    /// The concrete model (for profile-specific test and plant knobs).
    fn as_any(&self) -> &dyn std::any::Any;
    /// The concrete model, mutable.
    fn as_any_mut(&mut self) -> &mut dyn std::any::Any;
}

impl DriveModel for ds402::Ds402Model {
    fn rx_len(&self) -> usize {
        ds402::Ds402Model::rx_len(self)
    }
    fn tx_len(&self) -> usize {
        ds402::Ds402Model::tx_len(self)
    }
    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        ds402::Ds402Model::begin_step(self, now, dt_s, rx)
    }
    fn input_edge(&mut self, input: u8, rising: bool, at: Nanos) {
        ds402::Ds402Model::input_edge(self, input, rising, at)
    }
    fn finish_step(&mut self, tx: &mut [u8]) {
        ds402::Ds402Model::finish_step(self, tx)
    }
    fn plant(&self) -> Option<&AxisPlant> {
        Some(&self.plant)
    }
    fn plant_mut(&mut self) -> Option<&mut AxisPlant> {
        Some(&mut self.plant)
    }
    fn set_input_level(&mut self, input: u8, level: bool) {
        ds402::Ds402Model::set_input_level(self, input, level)
    }
    fn input_level(&self, input: u8) -> Option<bool> {
        ds402::Ds402Model::input_level(self, input)
    }
    fn state(&self) -> PowerState {
        ds402::Ds402Model::state(self)
    }
    fn last_error_code(&self) -> u16 {
        ds402::Ds402Model::last_error_code(self)
    }
    fn settle(&mut self) {
        ds402::Ds402Model::settle(self)
    }
    fn inject_fault(&mut self, code: u16) {
        ds402::Ds402Model::inject_fault(self, code)
    }
    fn fault_now(&mut self, code: u16) {
        ds402::Ds402Model::fault_now(self, code)
    }
    fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32> {
        ds402::Ds402Model::read_object(self, index, sub)
    }
    fn write_object(&mut self, index: u16, sub: u8, value: i64) -> Result<(), u32> {
        ds402::Ds402Model::write_object(self, index, sub, value)
    }
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
        self
    }
}

/// The drive model for a drive definition (by its profile).
pub fn for_definition(
    def: &super::catalogue::DriveDefinition,
) -> Result<Box<dyn DriveModel>, super::DriveError> {
    use super::catalogue::Profile;
    match def.profile {
        Profile::Cia402 => Ok(Box::new(ds402::Ds402Model::new(def))),
        Profile::Profidrive => Ok(Box::new(profidrive::ProfidriveModel::new(def)?)),
        Profile::Lightbus => Ok(Box::new(lightbus::LightbusModel::new(def))),
        Profile::Terminal => Ok(Box::new(terminal::TerminalModel::new(def)?)),
        Profile::Sercos => Ok(Box::new(sercos::SercosModel::new(def)?)),
    }
}

/// CiA 301 SDO abort codes (CiA 301 §7.2.4.3.17, Table 22) returned by model object access.
pub mod abort {
    /// 0x06010002 — attempt to write a read-only object.
    pub const READ_ONLY: u32 = 0x0601_0002;
    /// 0x06020000 — object does not exist in the object dictionary.
    pub const NO_OBJECT: u32 = 0x0602_0000;
    /// 0x06090011 — sub-index does not exist.
    pub const NO_SUB_INDEX: u32 = 0x0609_0011;
    /// 0x06090030 — invalid value for parameter (value range exceeded).
    pub const VALUE_RANGE: u32 = 0x0609_0030;
}
