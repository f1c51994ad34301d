//! A raw packet socket on a Linux network interface: the wire of fieldprobe's `ethercat:IFACE`
//! link (the master sends its frames here) and of the emulator's `sim ethercat` (which answers
//! them, `crate::sim::esc::raw`, feature `sim`).
//!
//! The socket is an AF_PACKET/SOCK_RAW socket bound to the interface (via the safe
//! `pnet_datalink` crate, protocol ETH_P_ALL, layer 2, not promiscuous). It sees every frame on
//! the interface; [`RawPort::try_receive`] hands on the EtherCAT ones (EtherType 0x88A4,
//! ETG.1000.4 §5.2) and skips the rest.
//!
//! Needs CAP_NET_RAW (e.g. root inside an unprivileged `unshare -rn` namespace); without it
//! [`RawPort::open`] fails with [`RawError::Open`], naming the interface.

use std::time::Duration;

use pnet_datalink::{Channel, ChannelType, Config, NetworkInterface};

/// EtherType of EtherCAT frames (ETG.1000.4).
pub const ETHERTYPE_ETHERCAT: u16 = 0x88A4;

/// Receive timeout of [`RawPort::open`]: the longest a receive waits for a frame.
pub const RECEIVE_TIMEOUT: Duration = Duration::from_millis(50);

/// Failure to open or use a raw socket; every variant names the interface.
#[derive(Debug, thiserror::Error)]
pub enum RawError {
    /// No interface of that name.
    #[error("interface {iface}: no such network interface (available: {available})")]
    NoSuchInterface {
        /// Interface name asked for.
        iface: String,
        /// Names of the interfaces that exist.
        available: String,
    },
    /// Opening the raw socket failed (typically missing CAP_NET_RAW).
    #[error("interface {iface}: cannot open a raw packet socket (needs CAP_NET_RAW): {source}")]
    Open {
        /// Interface name.
        iface: String,
        /// OS error.
        source: std::io::Error,
    },
    /// The channel is not an Ethernet channel.
    #[error("interface {iface}: not an Ethernet channel")]
    NotEthernet {
        /// Interface name.
        iface: String,
    },
    /// Receiving failed.
    #[error("interface {iface}: receive failed: {source}")]
    Receive {
        /// Interface name.
        iface: String,
        /// OS error.
        source: std::io::Error,
    },
    /// Sending failed.
    #[error("interface {iface}: send failed: {source}")]
    Send {
        /// Interface name.
        iface: String,
        /// OS error.
        source: std::io::Error,
    },
}

fn find_interface(iface: &str) -> Result<NetworkInterface, RawError> {
    let all = pnet_datalink::interfaces();
    if let Some(i) = all.iter().find(|i| i.name == iface) {
        return Ok(i.clone());
    }
    let available = all
        .iter()
        .map(|i| i.name.as_str())
        .collect::<Vec<_>>()
        .join(", ");
    Err(RawError::NoSuchInterface {
        iface: iface.to_string(),
        available,
    })
}

/// An open raw socket on one interface.
pub struct RawPort {
    pub(crate) iface: String,
    pub(crate) tx: Box<dyn pnet_datalink::DataLinkSender>,
    pub(crate) rx: Box<dyn pnet_datalink::DataLinkReceiver>,
}

impl std::fmt::Debug for RawPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawPort")
            .field("iface", &self.iface)
            .finish_non_exhaustive()
    }
}

impl RawPort {
    /// Open a raw packet socket bound to `iface` (receive timeout [`RECEIVE_TIMEOUT`]).
    /// Frames that reach the interface after this returns are queued for the receives.
    pub fn open(iface: &str) -> Result<Self, RawError> {
        Self::open_with_timeout(iface, RECEIVE_TIMEOUT)
    }

    /// [`open`](Self::open) with another receive timeout (a master polls more often).
    pub fn open_with_timeout(iface: &str, read_timeout: Duration) -> Result<Self, RawError> {
        let ni = find_interface(iface)?;
        let config = Config {
            read_timeout: Some(read_timeout),
            write_timeout: Some(Duration::from_secs(1)),
            channel_type: ChannelType::Layer2,
            promiscuous: false,
            ..Config::default()
        };
        match pnet_datalink::channel(&ni, config) {
            Ok(Channel::Ethernet(tx, rx)) => Ok(Self {
                iface: iface.to_string(),
                tx,
                rx,
            }),
            Ok(_) => Err(RawError::NotEthernet {
                iface: iface.to_string(),
            }),
            Err(source) => Err(RawError::Open {
                iface: iface.to_string(),
                source,
            }),
        }
    }

    /// Interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    /// Send one Ethernet frame.
    pub fn send(&mut self, frame: &[u8]) -> Result<(), RawError> {
        match self.tx.send_to(frame, None) {
            Some(Ok(())) => Ok(()),
            Some(Err(source)) => Err(RawError::Send {
                iface: self.iface.clone(),
                source,
            }),
            None => Err(RawError::Send {
                iface: self.iface.clone(),
                source: std::io::Error::other("send_to not supported by the channel"),
            }),
        }
    }

    /// The next EtherCAT frame (EtherType 0x88A4) that arrived, waiting at most the receive
    /// timeout; `None` if none came. Frames of other types are skipped.
    pub fn try_receive(&mut self) -> Option<Vec<u8>> {
        let frame = self.rx.next().ok()?;
        is_ethercat(frame).then(|| frame.to_vec())
    }
}

/// `true` if `frame` is an EtherCAT frame (EtherType 0x88A4, no VLAN tag).
pub fn is_ethercat(frame: &[u8]) -> bool {
    frame.len() >= 14 && u16::from_be_bytes([frame[12], frame[13]]) == ETHERTYPE_ETHERCAT
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_interface_is_named() {
        let e = RawPort::open("no-such-if0").unwrap_err();
        assert!(matches!(e, RawError::NoSuchInterface { .. }), "{e}");
        assert!(e.to_string().contains("no-such-if0"), "{e}");
    }

    #[test]
    fn ethertype() {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&[0x88, 0xA4, 0, 0]);
        assert!(is_ethercat(&f));
        f[12] = 0x08;
        f[13] = 0x00;
        assert!(!is_ethercat(&f));
        assert!(!is_ethercat(&[0; 10]));
    }
}
