//! CAN transports behind one seam, [`CanBus`]: SocketCAN (`socketcan` crate), an in-process
//! virtual bus with SocketCAN's delivery semantics, python-can's `udp_multicast` wire format, and
//! a fault-injecting wrapper. Classic CAN frames (≤ 8 data bytes); error frames are carried as
//! frames with [`CanFrame::error`] set.

use std::time::Duration;

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
}
