//! Serve an emulated [`Segment`] on a real Linux network interface (e.g. one end of a veth
//! pair), so a stock EtherCAT master (ethercrab's `std::tx_rx_task`, SOEM) can talk to it
//! over a raw socket (notes `ethercat.md` §0 point 2, §1.3).
//!
//! The socket is an AF_PACKET/SOCK_RAW socket bound to the interface (via the safe
//! `pnet_datalink` crate, protocol ETH_P_ALL); frames whose EtherType is not 0x88A4 are
//! ignored, and so are frames whose source MAC already has the U/L bit set — our own replies,
//! which an ETH_P_ALL socket sees as outgoing traffic, or frames processed by another segment.
//! Every other frame goes through [`Segment::process_frame`] and is sent back on the same
//! interface. Receives wait at most [`POLL_INTERVAL`], so [`serve`] notices `stop` / the
//! deadline promptly.
//!
//! Needs CAP_NET_RAW (e.g. root inside an unprivileged `unshare -rn` namespace).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use pnet_datalink::{Channel, ChannelType, Config, NetworkInterface};

use super::segment::Segment;

/// EtherType of EtherCAT frames.
pub const ETHERTYPE_ETHERCAT: u16 = 0x88A4;

/// Longest wait for a frame before `stop` / the deadline is checked again.
pub const POLL_INTERVAL: Duration = Duration::from_millis(50);

/// Failure to serve on an interface; every variant names the interface.
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

/// What [`serve`] saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServeStats {
    /// EtherCAT frames processed and answered.
    pub answered: u64,
    /// EtherCAT frames skipped because the source MAC already had the U/L bit set.
    pub skipped_processed: u64,
    /// Frames with another EtherType.
    pub skipped_other: u64,
    /// EtherCAT frames the segment rejected as invalid (dropped, like a real segment would).
    pub invalid: u64,
}

/// `true` if `frame` is an EtherCAT frame (EtherType 0x88A4, no VLAN tag).
fn is_ethercat(frame: &[u8]) -> bool {
    frame.len() >= 14 && u16::from_be_bytes([frame[12], frame[13]]) == ETHERTYPE_ETHERCAT
}

/// `true` if the source MAC has the locally-administered (U/L) bit set, i.e. the frame has
/// already passed a (emulated) first device.
fn already_processed(frame: &[u8]) -> bool {
    frame.len() > 6 && frame[6] & 0x02 != 0
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

/// An open raw socket on one interface, ready to serve a segment.
pub struct RawPort {
    iface: String,
    tx: Box<dyn pnet_datalink::DataLinkSender>,
    rx: Box<dyn pnet_datalink::DataLinkReceiver>,
}

impl std::fmt::Debug for RawPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawPort")
            .field("iface", &self.iface)
            .finish_non_exhaustive()
    }
}

impl RawPort {
    /// Open a raw packet socket bound to `iface` (receive timeout [`POLL_INTERVAL`]).
    /// Frames sent to the interface after this returns are queued for [`RawPort::serve`].
    pub fn open(iface: &str) -> Result<Self, RawError> {
        Self::open_with_timeout(iface, POLL_INTERVAL)
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
        (frame.len() >= 14 && frame[12..14] == [0x88, 0xA4]).then(|| frame.to_vec())
    }

    /// Serve `segment` until `stop` is set or `deadline` passes (whichever first).
    ///
    /// Simulation time given to [`Segment::process_frame`] is the time since the call.
    /// Fails if a receive or send fails for another reason than the receive timeout.
    pub fn serve(
        &mut self,
        segment: &mut Segment,
        stop: &AtomicBool,
        deadline: Option<Instant>,
    ) -> Result<ServeStats, RawError> {
        let iface = self.iface.as_str();
        tracing::info!(
            iface,
            devices = segment.len(),
            "serving emulated EtherCAT segment"
        );
        let t0 = Instant::now();
        let mut stats = ServeStats::default();
        let mut buf = Vec::with_capacity(1600);
        loop {
            if stop.load(Ordering::Relaxed) || deadline.is_some_and(|d| Instant::now() >= d) {
                return Ok(stats);
            }
            match self.rx.next() {
                Ok(frame) => {
                    if !is_ethercat(frame) {
                        stats.skipped_other += 1;
                        continue;
                    }
                    if already_processed(frame) {
                        stats.skipped_processed += 1;
                        continue;
                    }
                    buf.clear();
                    buf.extend_from_slice(frame);
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    continue;
                }
                Err(source) => {
                    return Err(RawError::Receive {
                        iface: iface.to_string(),
                        source,
                    })
                }
            }
            let now = t0.elapsed().as_nanos() as u64;
            match segment.process_frame(&mut buf, now) {
                Ok(true) => {}
                Ok(false) => continue, // dropped on purpose (fault knob)
                Err(e) => {
                    tracing::debug!(iface, error = %e, "invalid EtherCAT frame dropped");
                    stats.invalid += 1;
                    continue;
                }
            }
            match self.tx.send_to(&buf, None) {
                Some(Ok(())) => stats.answered += 1,
                Some(Err(source)) => {
                    return Err(RawError::Send {
                        iface: iface.to_string(),
                        source,
                    })
                }
                None => {
                    return Err(RawError::Send {
                        iface: iface.to_string(),
                        source: std::io::Error::other("send_to not supported by the channel"),
                    })
                }
            }
        }
    }
}

/// Open `iface` ([`RawPort::open`]) and serve `segment` on it ([`RawPort::serve`]) until
/// `stop` is set or `deadline` passes.
pub fn serve(
    iface: &str,
    segment: &mut Segment,
    stop: &AtomicBool,
    deadline: Option<Instant>,
) -> Result<ServeStats, RawError> {
    RawPort::open(iface)?.serve(segment, stop, deadline)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_classification() {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&[0x88, 0xA4, 0, 0]);
        assert!(is_ethercat(&f));
        assert!(!already_processed(&f));
        f[6] |= 0x02;
        assert!(already_processed(&f));
        f[12] = 0x08;
        f[13] = 0x00;
        assert!(!is_ethercat(&f));
        assert!(!is_ethercat(&[0; 10]));
    }

    #[test]
    fn unknown_interface_is_named() {
        let mut seg = Segment::new(Vec::new(), 0);
        let stop = AtomicBool::new(false);
        let e = serve("no-such-if0", &mut seg, &stop, Some(Instant::now())).unwrap_err();
        assert!(e.to_string().contains("no-such-if0"), "{e}");
    }
}
