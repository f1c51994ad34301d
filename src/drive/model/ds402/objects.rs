//! Object dictionary of the model (SDO / CoE access and the PDO path): CiA 402 objects with
//! CiA 301 abort codes.

use super::{round_i32, Ds402Model, SUPPORTED_DRIVE_MODES, SUPPORTED_MODES};
use crate::drive::model::abort;
use crate::drive::pdo;

impl Ds402Model {
    /// The CiA 402 object a device object plays (`[roles]`), else the object itself.
    fn canonical(&self, index: u16, sub: u8) -> (u16, u8) {
        self.roles
            .iter()
            .find(|r| (r.object, r.object_sub) == (index, sub))
            .map_or((index, sub), |r| (r.index, r.sub))
    }

    /// Read an object (SDO upload / CoE). Errors are CiA 301 abort codes ([`abort`]).
    pub fn read_object(&self, index: u16, sub: u8) -> Result<i64, u32> {
        let (index, sub) = self.canonical(index, sub);
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
            (0x6077, 0) => (self.torque.round() as i16).into(),
            (0x607A, 0) => self.target.into(),
            (0x60B8, 0) => self.probes.function().into(),
            (0x60B9, 0) => self.probes.status().into(),
            (0x60BA..=0x60BD, 0) => self
                .probes
                .value(usize::from(index - 0x60BA))
                .unwrap_or(0)
                .into(),
            (0x60D0, 0) => 2,
            (0x60D0, 1 | 2) => self.probes.source(sub).unwrap_or(0).into(),
            (0x60D5..=0x60D8, 0) => self
                .probes
                .counter(usize::from(index - 0x60D5))
                .unwrap_or(0)
                .into(),
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
        let (index, sub) = self.canonical(index, sub);
        let info = pdo::lookup(index, sub).ok_or_else(|| missing(index))?;
        if matches!(
            (index, sub),
            (
                0x603F | 0x6041 | 0x6061 | 0x6064 | 0x606C | 0x6077 | 0x60B9 | 0x60F4 | 0x6502,
                0
            ) | (0x60BA..=0x60BD, 0)
                | (0x60D5..=0x60D8, 0)
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
            (0x60B8, 0) => self.probes.write_function(value as u16),
            (0x60D0, 1 | 2) => self.probes.set_source(sub, value as i16),
            (0x60E0, 0) => self.torque_limit_pos = value as u16,
            (0x60E1, 0) => self.torque_limit_neg = value as u16,
            _ => return Err(abort::NO_OBJECT),
        }
        Ok(())
    }
}

fn missing(index: u16) -> u32 {
    if pdo::OBJECTS.iter().any(|o| o.index == index) {
        abort::NO_SUB_INDEX
    } else {
        abort::NO_OBJECT
    }
}
