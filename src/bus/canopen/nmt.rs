//! NMT (CiA 301 §7.2.8): commands, node states, heartbeat and boot-up messages.

use crate::bus::can::CanFrame;

/// COB-ID of NMT commands.
pub const NMT_COB: u16 = 0x000;
/// COB-ID of SYNC.
pub const SYNC_COB: u16 = 0x080;
/// fieldprobe's tolerance for a missing SYNC, in communication cycle periods (0x1006): the
/// emulated nodes' SYNC watch fires after more than this many periods without a SYNC, and the
/// master configures its RPDO event-timers (deadline monitoring) to as many cycles. CiA 301
/// leaves the tolerance to the device.
pub const SYNC_TIMEOUT_PERIODS: u64 = 5;
/// Base COB-ID of EMCY (+ node).
pub const EMCY_BASE: u16 = 0x080;
/// Base COB-ID of heartbeat / boot-up (+ node).
pub const HEARTBEAT_BASE: u16 = 0x700;

/// NMT command specifiers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtCommand {
    /// 0x01 start remote node → operational.
    Start,
    /// 0x02 stop remote node → stopped.
    Stop,
    /// 0x80 enter pre-operational.
    EnterPreOperational,
    /// 0x81 reset node.
    ResetNode,
    /// 0x82 reset communication.
    ResetCommunication,
}

impl NmtCommand {
    /// Command specifier byte.
    pub const fn code(self) -> u8 {
        match self {
            NmtCommand::Start => 0x01,
            NmtCommand::Stop => 0x02,
            NmtCommand::EnterPreOperational => 0x80,
            NmtCommand::ResetNode => 0x81,
            NmtCommand::ResetCommunication => 0x82,
        }
    }

    /// From a command specifier byte.
    pub fn from_code(b: u8) -> Option<NmtCommand> {
        Some(match b {
            0x01 => NmtCommand::Start,
            0x02 => NmtCommand::Stop,
            0x80 => NmtCommand::EnterPreOperational,
            0x81 => NmtCommand::ResetNode,
            0x82 => NmtCommand::ResetCommunication,
            _ => return None,
        })
    }

    /// The NMT frame for `node` (0 = all nodes).
    pub fn frame(self, node: u8) -> CanFrame {
        CanFrame::new(NMT_COB, &[self.code(), node]).unwrap_or_else(|_| unreachable_frame())
    }
}

/// A frame that cannot fail to build (id 0, no data) for the `unwrap_or_else` of constant frames.
fn unreachable_frame() -> CanFrame {
    CanFrame {
        id: 0,
        extended: false,
        rtr: false,
        error: false,
        len: 0,
        data: [0; 8],
    }
}

/// NMT state as the heartbeat reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtState {
    /// 0x00 boot-up (initialisation finished).
    BootUp,
    /// 0x04 stopped.
    Stopped,
    /// 0x05 operational.
    Operational,
    /// 0x7F pre-operational.
    PreOperational,
}

impl NmtState {
    /// Heartbeat state byte.
    pub const fn code(self) -> u8 {
        match self {
            NmtState::BootUp => 0x00,
            NmtState::Stopped => 0x04,
            NmtState::Operational => 0x05,
            NmtState::PreOperational => 0x7F,
        }
    }

    /// From a heartbeat state byte (toggle bit 7 of node guarding ignored for 0x04/0x05).
    pub fn from_code(b: u8) -> Option<NmtState> {
        Some(match b {
            0x00 => NmtState::BootUp,
            0x7F => NmtState::PreOperational,
            b => match b & 0x7F {
                0x04 => NmtState::Stopped,
                0x05 => NmtState::Operational,
                _ => return None,
            },
        })
    }

    /// Name in words.
    pub const fn name(self) -> &'static str {
        match self {
            NmtState::BootUp => "boot-up",
            NmtState::Stopped => "stopped",
            NmtState::Operational => "operational",
            NmtState::PreOperational => "pre-operational",
        }
    }
}

/// Heartbeat (or boot-up) frame of `node` in `state`.
pub fn heartbeat(node: u8, state: NmtState) -> CanFrame {
    CanFrame::new(HEARTBEAT_BASE + u16::from(node & 0x7F), &[state.code()])
        .unwrap_or_else(|_| unreachable_frame())
}

/// `(node, state)` if `f` is a heartbeat / boot-up message.
pub fn parse_heartbeat(f: &CanFrame) -> Option<(u8, NmtState)> {
    if f.extended || f.rtr || f.error || f.len != 1 {
        return None;
    }
    let node = f.id.checked_sub(u32::from(HEARTBEAT_BASE))?;
    if !(1..=127).contains(&node) {
        return None;
    }
    Some((node as u8, NmtState::from_code(f.data[0])?))
}

/// The SYNC frame (no counter).
pub fn sync() -> CanFrame {
    CanFrame::new(SYNC_COB, &[]).unwrap_or_else(|_| unreachable_frame())
}

/// An emergency message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emcy {
    /// Producer node.
    pub node: u8,
    /// Error code (CiA 301 / CiA 402).
    pub code: u16,
    /// Error register (0x1001).
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub data: [u8; 5],
}

impl Emcy {
    /// The EMCY frame.
    pub fn frame(&self) -> CanFrame {
        let mut d = [0u8; 8];
        d[..2].copy_from_slice(&self.code.to_le_bytes());
        d[2] = self.register;
        d[3..].copy_from_slice(&self.data);
        CanFrame::new(EMCY_BASE + u16::from(self.node & 0x7F), &d)
            .unwrap_or_else(|_| unreachable_frame())
    }

    /// Parse an EMCY frame (COB-ID 0x081 … 0x0FF, 8 bytes).
    pub fn parse(f: &CanFrame) -> Option<Emcy> {
        if f.extended || f.rtr || f.error || f.len != 8 {
            return None;
        }
        let node = f.id.checked_sub(u32::from(EMCY_BASE))?;
        if !(1..=127).contains(&node) {
            return None;
        }
        let mut data = [0u8; 5];
        data.copy_from_slice(&f.data[3..8]);
        Some(Emcy {
            node: node as u8,
            code: u16::from_le_bytes([f.data[0], f.data[1]]),
            register: f.data[2],
            data,
        })
    }

    /// The error code in words (CiA 301 Table 21 classes, CiA 402 codes the drives use).
    pub fn text(&self) -> &'static str {
        emergency_text(self.code)
    }
}

/// An emergency error code in words; defined in [`crate::bus::abort`] (the same codes travel in
/// CoE emergencies over EtherCAT).
pub use crate::bus::abort::emergency_text;
