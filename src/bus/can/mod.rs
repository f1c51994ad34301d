//! CAN transports behind one seam, [`CanBus`]: SocketCAN (`socketcan` crate), an in-process
//! virtual bus with SocketCAN's delivery semantics, python-can's `udp_multicast` wire format, and
//! a fault-injecting wrapper. Classic CAN frames (≤ 8 data bytes); error frames are carried as
//! frames with [`CanFrame::error`] set.

use std::time::Duration;

pub mod candump;
pub mod fault;
pub mod socketcan_bus;
pub mod timing;
pub mod udp;
pub mod udp_wire;
pub mod virtual_bus;

pub use candump::{CandumpError, CandumpRecord, CandumpWriter};
pub use fault::FaultBus;
pub use socketcan_bus::SocketCanBus;
pub use timing::Bitrate;
pub use udp::{UdpConfig, UdpMulticastBus};
pub use virtual_bus::{Delivery, VirtualCan, VirtualEndpoint};

/// SocketCAN identifier-word flag: extended frame format (`linux/can.h` `CAN_EFF_FLAG`).
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// SocketCAN identifier-word flag: remote transmission request (`CAN_RTR_FLAG`).
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// SocketCAN identifier-word flag: error frame (`CAN_ERR_FLAG`).
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// Standard frame format identifier bits (`CAN_SFF_MASK`).
pub const CAN_SFF_MASK: u32 = 0x0000_07FF;
/// Extended frame format identifier bits (`CAN_EFF_MASK`).
pub const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;
/// Error class bits of an error frame (`CAN_ERR_MASK`).
pub const CAN_ERR_MASK: u32 = 0x1FFF_FFFF;

/// Error classes of SocketCAN error frames (`linux/can/error.h`), the bits of
/// [`CanFrame::id`] when [`CanFrame::error`] is set.
pub mod err_class {
    /// TX timeout (by netdevice driver).
    pub const TX_TIMEOUT: u32 = 0x0001;
    /// Lost arbitration (data\[0\] = bit number).
    pub const LOSTARB: u32 = 0x0002;
    /// Controller problems (data\[1\]).
    pub const CRTL: u32 = 0x0004;
    /// Protocol violations (data\[2\], data\[3\]).
    pub const PROT: u32 = 0x0008;
    /// Transceiver status (data\[4\]).
    pub const TRX: u32 = 0x0010;
    /// Received no ACK on transmission.
    pub const ACK: u32 = 0x0020;
    /// Bus off.
    pub const BUSOFF: u32 = 0x0040;
    /// Bus error (may flood).
    pub const BUSERROR: u32 = 0x0080;
    /// Controller restarted (after bus-off).
    pub const RESTARTED: u32 = 0x0100;
    /// TX / RX error counters in data\[6\], data\[7\].
    pub const CNT: u32 = 0x0200;
    /// All error classes.
    pub const ALL: u32 = super::CAN_ERR_MASK;
}

/// One classic CAN frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    /// Identifier: 11 bits (standard) or 29 bits (extended).
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Remote transmission request (no data; `len` is the requested length).
    pub rtr: bool,
    /// Error frame (SocketCAN `CAN_ERR_FLAG`; `id` holds the error class bits).
    pub error: bool,
    /// Data length (0 … 8).
    pub len: u8,
    /// Data; bytes beyond `len` are 0.
    pub data: [u8; 8],
}

/// Why a frame could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Identifier out of range.
    #[error("CAN identifier {id:#x} out of range (standard 0x000 … 0x7FF, extended 0x00000000 … 0x1FFFFFFF)")]
    Id {
        /// The identifier.
        id: u32,
    },
    /// More than 8 data bytes.
    #[error("{len} data bytes; a classic CAN frame carries 0 … 8")]
    Length {
        /// The length given.
        len: usize,
    },
}

impl CanFrame {
    /// Standard (11-bit) data frame.
    pub fn new(id: u16, data: &[u8]) -> Result<CanFrame, FrameError> {
        if id > 0x7FF {
            return Err(FrameError::Id { id: u32::from(id) });
        }
        CanFrame::build(u32::from(id), false, data)
    }

    /// Extended (29-bit) data frame.
    pub fn new_extended(id: u32, data: &[u8]) -> Result<CanFrame, FrameError> {
        if id > 0x1FFF_FFFF {
            return Err(FrameError::Id { id });
        }
        CanFrame::build(id, true, data)
    }

    fn build(id: u32, extended: bool, data: &[u8]) -> Result<CanFrame, FrameError> {
        if data.len() > 8 {
            return Err(FrameError::Length { len: data.len() });
        }
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        Ok(CanFrame {
            id,
            extended,
            rtr: false,
            error: false,
            len: data.len() as u8,
            data: d,
        })
    }

    /// Remote frame asking for `len` bytes.
    pub fn remote(id: u16, len: u8) -> Result<CanFrame, FrameError> {
        if id > 0x7FF {
            return Err(FrameError::Id { id: u32::from(id) });
        }
        if len > 8 {
            return Err(FrameError::Length {
                len: usize::from(len),
            });
        }
        Ok(CanFrame {
            id: u32::from(id),
            extended: false,
            rtr: true,
            error: false,
            len,
            data: [0; 8],
        })
    }

    /// Error frame with SocketCAN error class bits `class` (e.g. 0x40 = bus-off) and data.
    pub fn error_frame(class: u32, data: &[u8]) -> CanFrame {
        let mut d = [0u8; 8];
        let n = data.len().min(8);
        d[..n].copy_from_slice(&data[..n]);
        CanFrame {
            id: class & 0x1FFF_FFFF,
            extended: false,
            rtr: false,
            error: true,
            len: 8,
            data: d,
        }
    }

    /// The data bytes (`len` of them).
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }

    /// The SocketCAN identifier word: the identifier with [`CAN_EFF_FLAG`], [`CAN_RTR_FLAG`] and
    /// [`CAN_ERR_FLAG`] set as the frame says (`struct can_frame.can_id`). Filters match on it.
    pub fn id_word(&self) -> u32 {
        if self.error {
            return (self.id & CAN_ERR_MASK) | CAN_ERR_FLAG;
        }
        let mut w = if self.extended {
            (self.id & CAN_EFF_MASK) | CAN_EFF_FLAG
        } else {
            self.id & CAN_SFF_MASK
        };
        if self.rtr {
            w |= CAN_RTR_FLAG;
        }
        w
    }

    /// Check what the constructors guarantee (the fields are public): identifier in range for
    /// its format, `len` ≤ 8, not both remote and error frame.
    pub fn validate(&self) -> Result<(), FrameError> {
        let max = if self.extended || self.error {
            CAN_EFF_MASK
        } else {
            CAN_SFF_MASK
        };
        if self.id > max || (self.rtr && self.error) {
            return Err(FrameError::Id { id: self.id });
        }
        if self.len > 8 {
            return Err(FrameError::Length {
                len: usize::from(self.len),
            });
        }
        Ok(())
    }

    /// The frame with the bytes beyond `len` (and all data of a remote frame) zeroed, so that
    /// two frames that mean the same compare equal.
    pub fn normalized(&self) -> CanFrame {
        let mut f = *self;
        let n = if f.rtr { 0 } else { usize::from(f.len.min(8)) };
        for b in &mut f.data[n..] {
            *b = 0;
        }
        f
    }
}

/// A SocketCAN acceptance filter (`struct can_filter`): a frame passes when
/// `frame.id_word() & mask == id & mask` (or, if `inverted`, when it does not).
///
/// `id` and `mask` are identifier words, so they may include [`CAN_EFF_FLAG`] and
/// [`CAN_RTR_FLAG`]: `CanFilter::new(0x581, 0x7FF | CAN_EFF_FLAG | CAN_RTR_FLAG)` passes only the
/// standard data frame 0x581. Error frames are not subject to filters; an error mask selects them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFilter {
    /// Identifier word to compare with.
    pub id: u32,
    /// Bits of the identifier word that must match.
    pub mask: u32,
    /// Pass the frames that do *not* match (`CAN_INV_FILTER`).
    pub inverted: bool,
}

impl CanFilter {
    /// Filter passing frames whose identifier word matches `id` under `mask`.
    pub const fn new(id: u32, mask: u32) -> CanFilter {
        CanFilter {
            id,
            mask,
            inverted: false,
        }
    }

    /// Filter passing exactly the standard data frames with identifier `id` (e.g. one COB-ID).
    pub const fn standard(id: u16) -> CanFilter {
        CanFilter::new(
            id as u32 & CAN_SFF_MASK,
            CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
        )
    }

    /// Filter passing every frame.
    pub const fn accept_all() -> CanFilter {
        CanFilter::new(0, 0)
    }

    /// Does `frame` (a data or remote frame) pass this filter?
    pub fn matches(&self, frame: &CanFrame) -> bool {
        let hit = frame.id_word() & self.mask == self.id & self.mask;
        hit != self.inverted
    }
}

/// Does `frame` pass the filter list (SocketCAN semantics: any filter passes it; an empty list
/// passes no data frame) and the error mask (error frames pass when their class bits intersect it)?
pub fn accepts(filters: &[CanFilter], error_mask: u32, frame: &CanFrame) -> bool {
    if frame.error {
        frame.id & error_mask != 0
    } else {
        filters.iter().any(|f| f.matches(frame))
    }
}

/// Errors of a CAN transport.
#[derive(Debug, thiserror::Error)]
pub enum CanError {
    /// The transport is not available here (e.g. no SocketCAN in the kernel: ENODEV /
    /// EAFNOSUPPORT). Tests skip on this.
    #[error("{0}")]
    Unavailable(String),
    /// The bus is off (injected or reported by the controller).
    #[error("bus off")]
    BusOff,
    /// I/O error.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The cause.
        source: std::io::Error,
    },
    /// A frame that the transport cannot carry (identifier or length out of range).
    #[error("invalid frame: {0}")]
    Frame(#[from] FrameError),
    /// A received datagram / frame could not be decoded.
    #[error("malformed frame: {0}")]
    Malformed(String),
    /// Anything else.
    #[error("{0}")]
    Other(String),
}

/// A CAN transport: send frames, receive the frames of the other participants.
///
/// Blocking with a bound: [`recv`](CanBus::recv) waits at most `timeout` and returns `Ok(None)`
/// when nothing came. A bus never returns its own transmissions (SocketCAN's default without
/// `CAN_RAW_RECV_OWN_MSGS`).
pub trait CanBus: Send {
    /// Queue one frame for transmission.
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError>;
    /// The next received frame, waiting at most `timeout` (`Duration::ZERO`: poll).
    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, CanError>;
    /// Short description for messages (`virtual`, `udp 239.74.163.2:43113`, `socketcan vcan0`).
    fn describe(&self) -> String;
    /// The interface name `candump -L` logs of this bus carry: the kernel's name of a SocketCAN
    /// interface, a short stand-in for a bus that is none (see [`candump`] "Interface
    /// names"). Default: [`describe`](CanBus::describe) made to fit.
    fn log_interface(&self) -> String {
        candump::interface_name(&self.describe())
    }
    /// Received datagrams or frames this bus could not decode and dropped (junk on the wire is
    /// counted, never an error). Default 0: a transport that cannot carry junk.
    fn malformed_dropped(&self) -> u64 {
        0
    }
}
