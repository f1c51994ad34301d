//! [`SocketCanBus`]: a Linux SocketCAN raw socket (`socketcan` 4 crate with its tokio
//! `AsyncCanSocket`, driven by a current-thread runtime owned by the bus).
//!
//! Classic frames only. The socket receives every error class (`CAN_RAW_ERR_FILTER` = all) so
//! error frames come out as [`CanFrame`]s with [`CanFrame::error`] set, like on
//! [`super::VirtualCan`]. A bus-off error frame (class [`err_class::BUSOFF`]) marks the bus off
//! until a "restarted" one ([`err_class::RESTARTED`]); a send the kernel refuses with `ENETDOWN`
//! returns [`CanError::BusOff`].
//!
//! Opening fails with [`CanError::Unavailable`] where the kernel has no SocketCAN
//! (`EAFNOSUPPORT`) or the interface does not exist (`ENODEV`, e.g. vcan0 not set up: run
//! `scripts/vcan.sh`), on every OS other than Linux, and in a build without the `socketcan` Cargo
//! feature.

#[cfg(all(target_os = "linux", feature = "socketcan"))]
pub use linux::SocketCanBus;
#[cfg(not(all(target_os = "linux", feature = "socketcan")))]
pub use other::SocketCanBus;

#[allow(unused_imports)]
use super::{err_class, CanBus, CanError, CanFilter, CanFrame};

/// Message for a missing SocketCAN / interface.
#[cfg(all(target_os = "linux", feature = "socketcan"))]
fn unavailable(ifname: &str, detail: &str) -> CanError {
    CanError::Unavailable(format!(
        "SocketCAN interface `{ifname}` unavailable ({detail}): this system has no SocketCAN or \
         no such interface; for a virtual one load the vcan module and create it \
         (scripts/vcan.sh, needs root)"
    ))
}

#[cfg(all(target_os = "linux", feature = "socketcan"))]
mod linux {
    use std::time::Duration;

    use ::socketcan::{
        tokio::CanSocket as AsyncCanSocket, CanErrorFrame, CanFilter as RawFilter,
        CanFrame as RawFrame, EmbeddedFrame, ExtendedId, Frame, Id, SocketOptions, StandardId,
    };

    use super::{err_class, unavailable, CanBus, CanError, CanFilter, CanFrame};
    use crate::bus::can::{CAN_EFF_FLAG, CAN_ERR_FLAG, CAN_ERR_MASK, CAN_RTR_FLAG};

    /// `CAN_INV_FILTER` (`linux/can.h`): inverted filter, in the filter's id word.
    const CAN_INV_FILTER: u32 = 0x2000_0000;
    /// Longest wait for room in the transmit queue.
    const SEND_TIMEOUT: Duration = Duration::from_secs(1);

    /// A SocketCAN raw socket on one interface (see the module docs).
    pub struct SocketCanBus {
        // Field order: the socket must deregister before the runtime goes.
        socket: AsyncCanSocket,
        rt: tokio::runtime::Runtime,
        ifname: String,
        bus_off: bool,
    }

    impl std::fmt::Debug for SocketCanBus {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.debug_struct("SocketCanBus")
                .field("ifname", &self.ifname)
                .field("bus_off", &self.bus_off)
                .finish()
        }
    }

    fn io(what: String) -> impl FnOnce(std::io::Error) -> CanError {
        move |source| CanError::Io { what, source }
    }

    impl SocketCanBus {
        /// Open a raw CAN socket on `ifname` (e.g. `vcan0`, `can0`): all frames, all error
        /// classes, own frames not received.
        pub fn open(ifname: &str) -> Result<SocketCanBus, CanError> {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_io()
                .enable_time()
                .build()
                .map_err(io(format!("socketcan {ifname}: tokio runtime")))?;
            let socket = {
                let _guard = rt.enter();
                AsyncCanSocket::open(ifname)
            };
            let socket = match socket {
                Ok(s) => s,
                Err(e) if matches!(e.raw_os_error(), Some(libc::ENODEV | libc::EAFNOSUPPORT)) => {
                    return Err(unavailable(ifname, &e.to_string()))
                }
                Err(e) => return Err(io(format!("socketcan {ifname}: open"))(e)),
            };
            socket
                .set_error_filter(CAN_ERR_MASK)
                .map_err(io(format!("socketcan {ifname}: CAN_RAW_ERR_FILTER")))?;
            Ok(SocketCanBus {
                socket,
                rt,
                ifname: ifname.to_string(),
                bus_off: false,
            })
        }

        /// Interface name.
        pub fn ifname(&self) -> &str {
            &self.ifname
        }

        /// Has the controller reported bus-off (and not "restarted" since)?
        pub fn is_bus_off(&self) -> bool {
            self.bus_off
        }

        /// Replace the acceptance filters (`CAN_RAW_FILTER`); an empty list receives no data
        /// frames.
        pub fn set_filters(&mut self, filters: &[CanFilter]) -> Result<(), CanError> {
            let what = format!("socketcan {}: CAN_RAW_FILTER", self.ifname);
            if filters.is_empty() {
                return self.socket.set_filter_drop_all().map_err(io(what));
            }
            let raw: Vec<RawFilter> = filters
                .iter()
                .map(|f| {
                    let id = if f.inverted {
                        f.id | CAN_INV_FILTER
                    } else {
                        f.id & !CAN_INV_FILTER
                    };
                    RawFilter::new(id, f.mask)
                })
                .collect();
            self.socket.set_filters(&raw).map_err(io(what))
        }

        /// Error classes to receive (`CAN_RAW_ERR_FILTER`; default all).
        pub fn set_error_mask(&mut self, mask: u32) -> Result<(), CanError> {
            self.socket
                .set_error_filter(mask & CAN_ERR_MASK)
                .map_err(io(format!("socketcan {}: CAN_RAW_ERR_FILTER", self.ifname)))
        }

        /// Also receive own transmissions (`CAN_RAW_RECV_OWN_MSGS`).
        pub fn set_recv_own_msgs(&mut self, on: bool) -> Result<(), CanError> {
            self.socket.set_recv_own_msgs(on).map_err(io(format!(
                "socketcan {}: CAN_RAW_RECV_OWN_MSGS",
                self.ifname
            )))
        }

        fn convert_received(&mut self, f: &RawFrame) -> CanFrame {
            let word = f.id_word();
            let data = EmbeddedFrame::data(f);
            if word & CAN_ERR_FLAG != 0 {
                let class = word & CAN_ERR_MASK;
                if class & err_class::BUSOFF != 0 {
                    self.bus_off = true;
                }
                if class & err_class::RESTARTED != 0 {
                    self.bus_off = false;
                }
                return CanFrame::error_frame(class, data);
            }
            let extended = word & CAN_EFF_FLAG != 0;
            let id = if extended {
                word & crate::bus::can::CAN_EFF_MASK
            } else {
                word & crate::bus::can::CAN_SFF_MASK
            };
            let mut out = CanFrame {
                id,
                extended,
                rtr: word & CAN_RTR_FLAG != 0,
                error: false,
                len: 0,
                data: [0; 8],
            };
            if out.rtr {
                out.len = EmbeddedFrame::dlc(f).min(8) as u8;
            } else {
                let n = data.len().min(8);
                out.data[..n].copy_from_slice(&data[..n]);
                out.len = n as u8;
            }
            out
        }
    }

    fn to_raw(frame: &CanFrame) -> Result<RawFrame, CanError> {
        frame.validate()?;
        let bad = || CanError::Frame(crate::bus::can::FrameError::Id { id: frame.id });
        if frame.error {
            return CanErrorFrame::new_error(frame.id, frame.payload())
                .map(RawFrame::Error)
                .map_err(|e| CanError::Other(format!("error frame: {e}")));
        }
        let id: Id = if frame.extended {
            ExtendedId::new(frame.id).ok_or_else(bad)?.into()
        } else {
            StandardId::new(frame.id as u16).ok_or_else(bad)?.into()
        };
        let f = if frame.rtr {
            RawFrame::new_remote(id, usize::from(frame.len))
        } else {
            RawFrame::new(id, frame.payload())
        };
        f.ok_or_else(bad)
    }

    impl CanBus for SocketCanBus {
        fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
            let raw = to_raw(frame)?;
            let r = self.rt.block_on(async {
                tokio::time::timeout(SEND_TIMEOUT, self.socket.write_frame(raw)).await
            });
            match r {
                Ok(Ok(())) => Ok(()),
                Ok(Err(e)) if e.raw_os_error() == Some(libc::ENETDOWN) => {
                    self.bus_off = true;
                    Err(CanError::BusOff)
                }
                Ok(Err(e)) => Err(CanError::Io {
                    what: format!("socketcan {}: send", self.ifname),
                    source: e,
                }),
                Err(_) => Err(CanError::Io {
                    what: format!("socketcan {}: send", self.ifname),
                    source: std::io::Error::new(
                        std::io::ErrorKind::TimedOut,
                        format!("transmit queue still full after {SEND_TIMEOUT:?}"),
                    ),
                }),
            }
        }

        fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, CanError> {
            let r = if timeout.is_zero() {
                match self.socket.try_read_frame() {
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(None),
                    r => r,
                }
            } else {
                match self.rt.block_on(async {
                    tokio::time::timeout(timeout, self.socket.read_frame()).await
                }) {
                    Err(_elapsed) => return Ok(None),
                    Ok(r) => r,
                }
            };
            match r {
                Ok(f) => Ok(Some(self.convert_received(&f))),
                Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => {
                    self.bus_off = true;
                    Err(CanError::BusOff)
                }
                Err(e) => Err(CanError::Io {
                    what: format!("socketcan {}: receive", self.ifname),
                    source: e,
                }),
            }
        }

        fn describe(&self) -> String {
            format!("socketcan {}", self.ifname)
        }

        fn log_interface(&self) -> String {
            crate::bus::can::candump::interface_name(&self.ifname)
        }
    }
}

#[cfg(not(all(target_os = "linux", feature = "socketcan")))]
mod other {
    use std::time::Duration;

    use super::{CanBus, CanError, CanFilter, CanFrame};

    /// Why there is no SocketCAN here.
    #[cfg(not(target_os = "linux"))]
    const WHY: &str = "SocketCAN exists only on Linux";
    /// Why there is no SocketCAN here.
    #[cfg(target_os = "linux")]
    const WHY: &str = "this build of fieldprobe has no SocketCAN (Cargo feature `socketcan`)";

    fn unavailable(ifname: &str) -> CanError {
        CanError::Unavailable(format!("SocketCAN interface `{ifname}` unavailable: {WHY}"))
    }

    /// SocketCAN exists only on Linux, with the `socketcan` feature: every operation returns
    /// [`CanError::Unavailable`].
    #[derive(Debug)]
    pub struct SocketCanBus {
        ifname: String,
    }

    impl SocketCanBus {
        /// Always [`CanError::Unavailable`] here.
        pub fn open(ifname: &str) -> Result<SocketCanBus, CanError> {
            Err(unavailable(ifname))
        }

        /// Interface name.
        pub fn ifname(&self) -> &str {
            &self.ifname
        }

        /// Never bus-off (never open).
        pub fn is_bus_off(&self) -> bool {
            false
        }

        /// Unavailable here.
        pub fn set_filters(&mut self, _filters: &[CanFilter]) -> Result<(), CanError> {
            Err(unavailable(&self.ifname))
        }

        /// Unavailable here.
        pub fn set_error_mask(&mut self, _mask: u32) -> Result<(), CanError> {
            Err(unavailable(&self.ifname))
        }

        /// Unavailable here.
        pub fn set_recv_own_msgs(&mut self, _on: bool) -> Result<(), CanError> {
            Err(unavailable(&self.ifname))
        }
    }

    impl CanBus for SocketCanBus {
        fn send(&mut self, _frame: &CanFrame) -> Result<(), CanError> {
            Err(unavailable(&self.ifname))
        }

        fn recv(&mut self, _timeout: Duration) -> Result<Option<CanFrame>, CanError> {
            Err(unavailable(&self.ifname))
        }

        fn describe(&self) -> String {
            format!("socketcan {} (unavailable)", self.ifname)
        }

        fn log_interface(&self) -> String {
            crate::bus::can::candump::interface_name(&self.ifname)
        }
    }
}
