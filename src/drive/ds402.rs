//! CiA 402 master-side adapter (CANopen and CoE over EtherCAT), sans-IO.
//!
//! [`Ds402Adapter`] drives the CiA 402 power state machine (CiA 402 §6.2) from the last
//! statusword (0x6041) it decoded and commands cyclic synchronous position mode (CSP, 0x6060 = 8)
//! with the target position 0x607A. It owns these objects of the output image: 0x6040
//! controlword, 0x607A target position, 0x6060 modes of operation (when mapped) and the objects
//! listed in `[rxpdo] defaults` of the drive file; every other mapped output byte is left as the
//! caller put it.
//!
//! # Controlword sequence (CiA 402 §6.3, notes/canopen.md §6.7)
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
//! Touch probe (0x60B8) is not driven yet: the adapter writes only the `[rxpdo] defaults` value
//! (or nothing) there. TODO(touch-probe): arm / read 0x60B8–0x60BD.

use super::catalogue::{DriveDefinition, OutputDefault};
use super::pdo::{DataType, PdoLayout};
use super::{DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState};
use crate::units::Nanos;

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
/// (`read_inputs`, then `write_outputs`); observation: [`Ds402Adapter::state`],
/// [`Ds402Adapter::statusword`], [`Ds402Adapter::controlword`].
#[derive(Debug, Clone)]
pub struct Ds402Adapter {
    rx: PdoLayout,
    tx: PdoLayout,
    defaults: Vec<OutputDefault>,
    statusword: u16,
    state: PowerState,
    controlword: u16,
}

impl Ds402Adapter {
    /// Adapter for the PDO mapping of `def`. Fails when the mapping lacks 0x6040 / 0x607A
    /// (outputs) or 0x6041 / 0x6064 (inputs), or maps one of the objects the adapter interprets
    /// (0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x607A, 0x60F4) with a type other than CiA 402's.
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
        let typed: [(u16, DataType); 7] = [
            (0x6040, DataType::U16),
            (0x6041, DataType::U16),
            (0x6060, DataType::I8),
            (0x6061, DataType::I8),
            (0x6064, DataType::I32),
            (0x607A, DataType::I32),
            (0x60F4, DataType::I32),
        ];
        for (index, ty) in typed {
            for (layout, dir) in [(&def.rxpdo, "rxpdo"), (&def.txpdo, "txpdo")] {
                if let Some(e) = layout.find(index, 0) {
                    if e.ty != ty {
                        return Err(fail(format!(
                            "[{dir}] entries: 0x{index:04X}:00 must be {ty} (CiA 402), mapped as {}",
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

    /// Decode 0x6041, 0x6064 and, when mapped, 0x60F4 / 0x6061. The image must hold the whole
    /// TxPDO ([`DriveError::ImageTooShort`] otherwise; nothing is updated then).
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
        self.statusword = statusword;
        self.state = state;
        let csp = mode_display.map_or(true, |m| m == MODE_CSP);
        Ok(DriveFeedback {
            state,
            statusword,
            position,
            following_error,
            mode_display,
            operational: state == PowerState::OperationEnabled && csp,
            fault: matches!(state, PowerState::Fault | PowerState::FaultReactionActive),
            following_error_flag: csp && statusword & 0x2000 != 0,
            torque: None,
        })
    }

    /// Encode controlword, target position, mode 8 (when mapped) and the `[rxpdo] defaults`.
    /// The image must hold the whole RxPDO ([`DriveError::ImageTooShort`] otherwise; nothing is
    /// written then).
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
        self.controlword = cw;
        Ok(())
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
