//! CiA 402 power state machine of the model (CiA 402 §6.2 / §6.3): controlword decoding, the
//! transitions, and the statusword 0x6041.

use super::{Ds402Model, MODE_CSP};
use crate::drive::PowerState;

/// Controlword command (CiA 402 §6.3 Table "command coding").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Command {
    Shutdown,
    SwitchOn,
    EnableOperation,
    DisableVoltage,
    QuickStop,
    /// Bit 7 set: only the fault reset edge counts.
    None,
}

pub(super) fn decode_command(cw: u16) -> Command {
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

impl Ds402Model {
    pub(super) fn apply_controlword(&mut self) {
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
            self.plant.prev_target = self.plant.position;
            self.fe_over_ns = 0;
        }
        self.state = next;
    }

    /// Between two cycles: the automatic start-up transition 1 (NOT READY TO SWITCH ON →
    /// SWITCH ON DISABLED once the self test is done, CiA 402 §6.2) and the transition the
    /// controlword 0x6040 commands now (CiA 402 §6.3), without moving the axis. A drive obeys a
    /// controlword written acyclically (SDO, event-driven RPDO) at once; the enable delay
    /// (`enable_delay_cycles`) still counts cycles, so with a delay the last step to OPERATION
    /// ENABLED waits for the steps.
    pub fn settle(&mut self) {
        if self.state == PowerState::NotReadyToSwitchOn {
            self.state = PowerState::SwitchOnDisabled;
        }
        self.apply_controlword();
    }

    /// The drive follows the cyclic set-point: operation enabled in CSP.
    pub(super) fn following(&self) -> bool {
        self.state == PowerState::OperationEnabled && self.mode == MODE_CSP
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
}
