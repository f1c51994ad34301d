//! [`UdpMulticastBus`]: CAN over UDP/IPv4 multicast in python-can's `udp_multicast` format, so
//! a python-can or python-canopen process (`can.Bus(interface="udp_multicast",
//! channel="239.74.163.2", port=43113)`) and this crate share one virtual bus
//! (python-can documentation, "Multicast IP Interface"). The datagram codec is in [`super::udp_wire`].
//!
//! Sockets (pitfalls found interoperating with python-can 4 on Linux):
//! - receive: `SO_REUSEADDR` + `SO_REUSEPORT`, bound to `0.0.0.0:PORT`, joined to the group on
//!   any interface, `IP_MULTICAST_ALL` off (otherwise a bus on one group hears every group joined
//!   on the port by anyone on the host), `SO_RCVBUF` enlarged;
//! - send: a separate socket on an ephemeral port, TTL 1, multicast loop on. The receive socket
//!   drops datagrams whose source port is the send socket's port: those are this bus's own
//!   echoes (python-can peers all send from the group port).
//!
//! Malformed datagrams (anything [`udp_wire::decode`] refuses — junk another program sends to
//! the group, a truncated datagram) are what error frames and noise are on a real bus: the
//! receiver drops them, counts them ([`UdpMulticastBus::malformed_dropped`]) and logs a
//! `tracing` warning (the first [`MALFORMED_WARN_FIRST`], then every
//! [`MALFORMED_WARN_EVERY`]th, and the total when the bus is closed); they never end a session.
//!
//! Like python-can's transport this is unreliable under unpaced bursts (receive-buffer
//! overflow); [`UdpConfig::min_send_interval`] paces transmissions.

use std::{
    fmt,
    net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket},
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use socket2::{Domain, Protocol, Socket, Type};

use super::{udp_wire, CanBus, CanError, CanFrame};

/// python-can's `DEFAULT_GROUP_IPv4`.
pub const DEFAULT_GROUP: Ipv4Addr = Ipv4Addr::new(239, 74, 163, 2);
/// python-can's default `port`.
pub const DEFAULT_PORT: u16 = 43113;
/// Receive buffer asked for (the kernel caps it at `net.core.rmem_max`).
pub const RECV_BUFFER_BYTES: usize = 4 << 20;

/// Malformed datagrams logged one by one before the warnings thin out.
pub const MALFORMED_WARN_FIRST: u64 = 10;
/// After [`MALFORMED_WARN_FIRST`], one warning per this many malformed datagrams.
pub const MALFORMED_WARN_EVERY: u64 = 1000;

/// Where a [`UdpMulticastBus`] lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpConfig {
    /// IPv4 multicast group (224.0.0.0/4).
    pub group: Ipv4Addr,
    /// UDP port (python-can's `port`).
    pub port: u16,
    /// Multicast TTL (python-can's `hop_limit`, default 1: stays on the local link).
    pub ttl: u32,
    /// Minimum time between two transmissions (`None`: unpaced). About 135 µs matches a fully
    /// loaded 1 Mbit/s bus (measured: 20000/20000 frames arrived paced at ~7.4k frames/s).
    pub min_send_interval: Option<Duration>,
}

impl Default for UdpConfig {
    fn default() -> Self {
        UdpConfig {
            group: DEFAULT_GROUP,
            port: DEFAULT_PORT,
            ttl: 1,
            min_send_interval: None,
        }
    }
}

/// Why a `udp[:GROUP:PORT]` spec was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("bad CAN-over-UDP spec `{spec}`: {why} (allowed: `udp` for {DEFAULT_GROUP}:{DEFAULT_PORT}, or `udp:GROUP:PORT` with an IPv4 multicast GROUP in 224.0.0.0/4 and PORT 1 … 65535, e.g. `udp:239.74.163.2:43113`)")]
pub struct UdpSpecError {
    /// The spec given.
    pub spec: String,
    /// What is wrong with it.
    pub why: String,
}

impl UdpConfig {
    /// Config for `group:port` with TTL 1 and no pacing.
    pub fn new(group: Ipv4Addr, port: u16) -> UdpConfig {
        UdpConfig {
            group,
            port,
            ..UdpConfig::default()
        }
    }

    /// Parse `udp` (python-can's defaults) or `udp:GROUP:PORT`.
    pub fn parse(spec: &str) -> Result<UdpConfig, UdpSpecError> {
        let err = |why: String| UdpSpecError {
            spec: spec.to_string(),
            why,
        };
        let s = spec.trim();
        let rest = match s.strip_prefix("udp") {
            Some("") => return Ok(UdpConfig::default()),
            Some(r) => match r.strip_prefix(':') {
                Some(r) => r,
                None => return Err(err("expected `:` after `udp`".into())),
            },
            None => return Err(err("does not start with `udp`".into())),
        };
        let (group, port) = rest
            .rsplit_once(':')
            .ok_or_else(|| err("missing `:PORT`".into()))?;
        let group: Ipv4Addr = group
            .parse()
            .map_err(|_| err(format!("`{group}` is not an IPv4 address")))?;
        if !group.is_multicast() {
            return Err(err(format!("{group} is not a multicast address")));
        }
        let port: u16 = port
            .parse()
            .map_err(|_| err(format!("`{port}` is not a port number")))?;
        if port == 0 {
            return Err(err("port 0".into()));
        }
        Ok(UdpConfig::new(group, port))
    }
}

impl fmt::Display for UdpConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "udp:{}:{}", self.group, self.port)
    }
}

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> CanError {
    let what = what.into();
    move |source| CanError::Io { what, source }
}

/// A python-can compatible CAN-over-UDP-multicast bus (see the module docs).
pub struct UdpMulticastBus {
    config: UdpConfig,
    rx: UdpSocket,
    tx: UdpSocket,
    tx_port: u16,
    dest: SocketAddr,
    rx_buf: Vec<u8>,
    tx_buf: Vec<u8>,
    /// Read timeout currently set on `rx` (`Some(ZERO)` stands for non-blocking).
    rx_timeout: Option<Duration>,
    last_send: Option<Instant>,
    own_echoes: u64,
    malformed: u64,
}

impl fmt::Debug for UdpMulticastBus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("UdpMulticastBus")
            .field("config", &self.config)
            .field("tx_port", &self.tx_port)
            .finish()
    }
}

impl UdpMulticastBus {
    /// Open the receive and send sockets and join the group.
    pub fn open(config: UdpConfig) -> Result<UdpMulticastBus, CanError> {
        if !config.group.is_multicast() {
            return Err(CanError::Other(format!(
                "{} is not an IPv4 multicast group",
                config.group
            )));
        }
        let what = format!("udp {}:{}", config.group, config.port);
        let rx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
            .map_err(io(format!("{what}: receive socket")))?;
        rx.set_reuse_address(true)
            .map_err(io(format!("{what}: SO_REUSEADDR")))?;
        #[cfg(unix)]
        rx.set_reuse_port(true)
            .map_err(io(format!("{what}: SO_REUSEPORT")))?;
        // Best effort: the kernel silently caps the size at net.core.rmem_max.
        let _ = rx.set_recv_buffer_size(RECV_BUFFER_BYTES);
        let bind = SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, config.port);
        rx.bind(&bind.into())
            .map_err(io(format!("{what}: bind {bind}")))?;
        rx.join_multicast_v4(&config.group, &Ipv4Addr::UNSPECIFIED)
            .map_err(io(format!(
                "{what}: join {} (no multicast-capable interface or route? In a bare network \
                 namespace: `ip link set lo up; ip link set lo multicast on; ip route add \
                 224.0.0.0/4 dev lo`)",
                config.group
            )))?;
        #[cfg(target_os = "linux")]
        rx.set_multicast_all_v4(false)
            .map_err(io(format!("{what}: IP_MULTICAST_ALL")))?;

        let tx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
            .map_err(io(format!("{what}: send socket")))?;
        tx.set_multicast_ttl_v4(config.ttl)
            .map_err(io(format!("{what}: IP_MULTICAST_TTL")))?;
        tx.set_multicast_loop_v4(true)
            .map_err(io(format!("{what}: IP_MULTICAST_LOOP")))?;
        tx.bind(&SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, 0).into())
            .map_err(io(format!("{what}: bind send socket")))?;
        let tx: UdpSocket = tx.into();
        let tx_port = tx
            .local_addr()
            .map_err(io(format!("{what}: send socket address")))?
            .port();
        Ok(UdpMulticastBus {
            config,
            rx: rx.into(),
            tx,
            tx_port,
            dest: SocketAddrV4::new(config.group, config.port).into(),
            rx_buf: vec![0; 65536],
            tx_buf: Vec::with_capacity(192),
            rx_timeout: None,
            last_send: None,
            own_echoes: 0,
            malformed: 0,
        })
    }

    /// The configuration this bus was opened with.
    pub fn config(&self) -> &UdpConfig {
        &self.config
    }

    /// Local port of the send socket (the source port of this bus's datagrams).
    pub fn send_port(&self) -> u16 {
        self.tx_port
    }

    /// Own transmissions received back and dropped so far.
    pub fn own_echoes_dropped(&self) -> u64 {
        self.own_echoes
    }

    /// Malformed datagrams received and dropped so far (see the module docs).
    pub fn malformed_dropped(&self) -> u64 {
        self.malformed
    }

    /// Count and log one malformed datagram from `from`.
    fn malformed_datagram(&mut self, from: SocketAddr, len: usize, why: &CanError) {
        self.malformed += 1;
        let n = self.malformed;
        if n <= MALFORMED_WARN_FIRST || n.is_multiple_of(MALFORMED_WARN_EVERY) {
            tracing::warn!(
                target: "fieldprobe::bus::can",
                bus = %self.config,
                "malformed datagram ({len} bytes from {from}) dropped: {why} ({n} dropped so far)"
            );
        }
    }

    fn set_rx_timeout(&mut self, t: Duration) -> Result<(), CanError> {
        if self.rx_timeout == Some(t) {
            return Ok(());
        }
        let was_nonblocking = self.rx_timeout == Some(Duration::ZERO);
        if t.is_zero() {
            self.rx
                .set_nonblocking(true)
                .map_err(io("udp: set non-blocking"))?;
        } else {
            if was_nonblocking {
                self.rx
                    .set_nonblocking(false)
                    .map_err(io("udp: set blocking"))?;
            }
            self.rx
                .set_read_timeout(Some(t))
                .map_err(io("udp: set read timeout"))?;
        }
        self.rx_timeout = Some(t);
        Ok(())
    }
}

impl CanBus for UdpMulticastBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        self.tx_buf.clear();
        let stamp = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0);
        udp_wire::encode(frame, stamp, &mut self.tx_buf)?;
        if let (Some(min), Some(last)) = (self.config.min_send_interval, self.last_send) {
            let since = last.elapsed();
            if since < min {
                std::thread::sleep(min - since);
            }
        }
        self.tx
            .send_to(&self.tx_buf, self.dest)
            .map_err(io(format!("udp send to {}", self.dest)))?;
        self.last_send = Some(Instant::now());
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, CanError> {
        let deadline = Instant::now().checked_add(timeout);
        loop {
            let left = match deadline {
                Some(d) => d.saturating_duration_since(Instant::now()),
                None => Duration::from_secs(3600),
            };
            // A blocking wait needs a non-zero timeout; round sub-microsecond rests up.
            let wait = if timeout.is_zero() {
                Duration::ZERO
            } else if left.is_zero() {
                return Ok(None);
            } else {
                left.max(Duration::from_micros(1))
            };
            self.set_rx_timeout(wait)?;
            let (n, from) = match self.rx.recv_from(&mut self.rx_buf) {
                Ok(x) => x,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    if timeout.is_zero() {
                        return Ok(None);
                    }
                    continue;
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    return Err(CanError::Io {
                        what: format!("udp receive on {}", self.config),
                        source: e,
                    })
                }
            };
            if from.port() == self.tx_port {
                self.own_echoes += 1;
                continue;
            }
            match udp_wire::decode(&self.rx_buf[..n]) {
                Ok(Some(f)) => return Ok(Some(f)),
                Ok(None) => tracing::debug!(bus = %self.config, "CAN FD datagram ignored"),
                Err(e) => self.malformed_datagram(from, n, &e),
            }
        }
    }

    fn describe(&self) -> String {
        format!("udp {}:{}", self.config.group, self.config.port)
    }

    fn log_interface(&self) -> String {
        super::candump::UDP_INTERFACE.to_string()
    }

    fn malformed_dropped(&self) -> u64 {
        self.malformed
    }
}

impl Drop for UdpMulticastBus {
    fn drop(&mut self) {
        if self.malformed > 0 {
            tracing::warn!(
                target: "fieldprobe::bus::can",
                bus = %self.config,
                "{} malformed datagrams dropped in total",
                self.malformed
            );
        }
    }
}
