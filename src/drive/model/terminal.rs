//! Terminal drive model: an analog velocity amplifier plus a KL5101 / EL5101 encoder terminal,
//! the drive side of [`crate::drive::terminal::TerminalAdapter`] (image:
//! [`crate::drive::terminal::image`]; FCT-C4 §6.3; Beckhoff KL5101 / EL5101 documentation).
//!
//! - **Amplifier** (assumption): enabled while drive output bit 0 is set and no fault; it moves
//!   the axis at the commanded velocity (`velocity / 32767 × [terminal] full_scale_velocity`)
//!   through the shared axis physics ([`AxisPlant::drive_velocity`], CiA 402 motion module:
//!   sub-sampled trajectory, `[model] max_velocity`, fixed stop). A fault (injected) stays
//!   until a rising edge of output bit 1.
//! - **Counter**: `round(actual)` modulo 2¹⁶; SB3 / SB4 are set in a cycle in which it wrapped
//!   below 0 / above 65535; CB2 rising edge sets it to the set value (SB2 CNTSET_ACC while CB2 is
//!   set; the offset is kept in the model).
//! - **Latch**: while an enable bit is set and its *_VAL bit is 0, the first matching event
//!   stores the counter at the position interpolated at the edge time (exact to the
//!   sub-samples): CB0 the C track (zero pulse every `[model] zero_pulse_period` increments),
//!   CB1 a rising, CB3 (EL5101 only; ignored on a KL5101) a falling edge of the external latch
//!   input. Clearing the enable bit clears *_VAL but keeps the latch value (a stale value the
//!   adapter must not report). The external latch input is every digital input of the model
//!   (the terminal has one; assumption: the simulation wires the probe there whatever
//!   P-AXIS-00517 says).
//! - **Parameters**: none (`read_object` / `write_object` answer "no object").

use super::abort;
use super::axis::{clean_dt, AxisPlant};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::terminal::image::{self, Outputs};
use crate::drive::terminal::{TerminalConfig, Variant};
use crate::drive::{DriveError, PowerState};
use crate::units::Nanos;

/// Drive side of a terminal drive (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct TerminalModel {
    plant: AxisPlant,
    variant: Variant,
    full_scale_inc: f64,
    max_velocity_inc: f64,
    zero_pulse_period: f64,
    out: Outputs,
    started: bool,
    enabled: bool,
    fault: bool,
    prev_reset: bool,
    pending_fault: Option<u16>,
    error_code: u16,
    /// Counter = round(actual) + offset (mod 2¹⁶).
    counter_offset: i64,
    prev_cnt_set: bool,
    wrap: u8,
    latch_value: u16,
    latc_val: bool,
    ext_val: bool,
    input: bool,
}

impl TerminalModel {
    /// A terminal drive at increment 0 with `[model]` and `[terminal]` of `def`.
    pub fn new(def: &DriveDefinition) -> Result<Self, DriveError> {
        let cfg = TerminalConfig::from_definition(def)?;
        let inc = def.scaling.increments_per_unit.abs();
        Ok(TerminalModel {
            plant: AxisPlant::default(),
            variant: cfg.variant,
            full_scale_inc: cfg.full_scale_velocity * inc,
            max_velocity_inc: def
                .model
                .max_velocity
                .map(|v| (v * inc).abs())
                .filter(|v| v.is_finite() && *v > 0.0)
                .unwrap_or(f64::INFINITY),
            zero_pulse_period: if def.model.zero_pulse_period > 0.0 {
                def.model.zero_pulse_period
            } else {
                10_000.0
            },
            out: Outputs::default(),
            started: false,
            enabled: false,
            fault: false,
            prev_reset: false,
            pending_fault: None,
            error_code: 0,
            counter_offset: 0,
            prev_cnt_set: false,
            wrap: 0,
            latch_value: 0,
            latc_val: false,
            ext_val: false,
            input: false,
        })
    }

    /// Encoder terminal variant.
    pub fn variant(&self) -> Variant {
        self.variant
    }

    fn counter_at(&self, x: f64) -> u16 {
        let c = (x.round() as i64).wrapping_add(self.counter_offset);
        c as u16
    }

    fn counter_ext(&self, x: f64) -> i64 {
        (x.round() as i64).wrapping_add(self.counter_offset)
    }
}

impl super::DriveModel for TerminalModel {
    fn rx_len(&self) -> usize {
        image::OUTPUT_LEN
    }

    fn tx_len(&self) -> usize {
        image::INPUT_LEN
    }

    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        use image::*;
        if let Ok(o) = Outputs::decode(rx) {
            self.out = o;
        }
        self.started = true;
        if let Some(code) = self.pending_fault.take() {
            self.fault = true;
            self.error_code = code;
        }
        let reset = self.out.drive & DO_RESET != 0;
        if reset && !self.prev_reset {
            self.fault = false;
        }
        self.prev_reset = reset;
        self.enabled = !self.fault && self.out.drive & DO_ENABLE != 0;
        // Latch enables: clearing an enable clears its valid bit (the value stays).
        if self.out.control & CB_EN_LATC == 0 {
            self.latc_val = false;
        }
        let ext_mask = match self.variant {
            Variant::Kl5101 => CB_EN_LATCH_EXTP,
            Variant::El5101 => CB_EN_LATCH_EXTP | CB_EN_LATCH_EXTN,
        };
        if self.out.control & ext_mask == 0 {
            self.ext_val = false;
        }
        let dt = clean_dt(dt_s);
        let c0 = self.counter_ext(self.plant.actual());
        if self.enabled {
            let v = f64::from(self.out.velocity) / 32767.0 * self.full_scale_inc;
            self.plant.drive_velocity(now, dt, v, self.max_velocity_inc);
        } else {
            self.plant.hold(now, dt);
        }
        // Counter set (CB2 rising edge).
        let cnt_set = self.out.control & CB_CNT_SET != 0;
        if cnt_set && !self.prev_cnt_set {
            let x = self.plant.actual().round() as i64;
            self.counter_offset = i64::from(self.out.set_value).wrapping_sub(x);
        }
        self.prev_cnt_set = cnt_set;
        // Under- / overflow of the 16-bit counter in this cycle.
        let c1 = self.counter_ext(self.plant.actual());
        self.wrap = 0;
        if c1.div_euclid(65536) < c0.div_euclid(65536) {
            self.wrap |= SB_UNDERFLOW;
        } else if c1.div_euclid(65536) > c0.div_euclid(65536) {
            self.wrap |= SB_OVERFLOW;
        }
        // C track.
        if self.out.control & CB_EN_LATC != 0 && !self.latc_val {
            let p = self.zero_pulse_period;
            let traj = self.plant.trajectory().to_vec();
            for w in traj.windows(2) {
                let (na, nb) = ((w[0].1 / p).floor(), (w[1].1 / p).floor());
                if na.is_finite() && nb.is_finite() && na != nb {
                    let k = if nb > na { na + 1.0 } else { na };
                    self.latch_value = self.counter_at(k * p);
                    self.latc_val = true;
                    break;
                }
            }
        }
    }

    fn input_edge(&mut self, _input: u8, rising: bool, at: Nanos) {
        use image::*;
        if self.input == rising {
            return;
        }
        self.input = rising;
        if self.ext_val {
            return;
        }
        let c = self.out.control;
        let armed = if rising {
            c & CB_EN_LATCH_EXTP != 0
        } else {
            self.variant == Variant::El5101 && c & CB_EN_LATCH_EXTN != 0
        };
        if armed {
            self.latch_value = self.counter_at(self.plant.position_clamped(at));
            self.ext_val = true;
        }
    }

    fn finish_step(&mut self, tx: &mut [u8]) {
        use image::*;
        let mut status = self.wrap;
        if self.latc_val {
            status |= SB_LATC_VAL;
        }
        if self.ext_val {
            status |= SB_LAT_EXT_VAL;
        }
        if self.out.control & CB_CNT_SET != 0 {
            status |= SB_CNTSET_ACC;
        }
        if self.input {
            status |= SB_LATCH_INPUT;
        }
        let mut drive = 0;
        if self.started && !self.fault {
            drive |= DI_READY;
        }
        if self.enabled {
            drive |= DI_ENABLED;
        }
        if self.fault {
            drive |= DI_FAULT;
        }
        let i = Inputs {
            status,
            counter: self.counter_at(self.plant.actual()),
            latch: self.latch_value,
            drive,
        };
        let _ = i.encode(tx);
    }

    fn plant(&self) -> Option<&AxisPlant> {
        Some(&self.plant)
    }

    fn plant_mut(&mut self) -> Option<&mut AxisPlant> {
        Some(&mut self.plant)
    }

    fn set_input_level(&mut self, _input: u8, level: bool) {
        self.input = level;
    }

    fn input_level(&self, input: u8) -> Option<bool> {
        (1..=4).contains(&input).then_some(self.input)
    }

    fn state(&self) -> PowerState {
        if !self.started {
            PowerState::NotReadyToSwitchOn
        } else if self.fault {
            PowerState::Fault
        } else if self.enabled {
            PowerState::OperationEnabled
        } else {
            PowerState::SwitchedOn
        }
    }

    fn last_error_code(&self) -> u16 {
        self.error_code
    }

    fn inject_fault(&mut self, code: u16) {
        self.pending_fault = Some(code);
    }

    fn read_object(&self, _index: u16, _sub: u8) -> Result<i64, u32> {
        Err(abort::NO_OBJECT)
    }

    fn write_object(&mut self, _index: u16, _sub: u8, _value: i64) -> Result<(), u32> {
        Err(abort::NO_OBJECT)
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
        self
    }
}
