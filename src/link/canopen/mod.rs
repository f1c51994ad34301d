//! CANopen link: our CiA 301 master drives the axes over a [`CanBus`].
//!
//! | `--link` | bus | nodes |
//! |---|---|---|
//! | `canopen-emu` | in-process [`VirtualCan`] with a wire at the machine's bit rate ([`wire`]): the master on one endpoint, the [`CanopenSegment`] on another | one emulated CiA 402 node per axis at the node ids the machine gives (default 1, 2, …) |
//! | `canopen-udp[:GROUP:PORT]`, `socketcan:IF` | a [`CanBus`] given to [`CanopenLink::open`] | whatever answers |
//!
//! # Start-up
//!
//! The bus load of one cycle at the bus's bit rate ([`load`]): above 100 % the link refuses to
//! start before anything is sent. Then NMT reset communication → boot-up of every axis node
//! (bounded wait) → per node: SDO reads of 0x1000 and 0x1018 (identity), the objects and PDOs
//! the node offers ([`fit`]), the drive file's process data in the master's layout fitted into
//! them ([`plan_layout`] / [`crate::bus::canopen::pdo::plan_layout_in`]: ≤ 4 RPDOs / TPDOs of
//! ≤ 8 bytes and as many entries as the node's mapping parameters take, cyclic and on-change
//! PDOs) written by the CiA 301 remap procedure, the node's unused PDOs disabled, 0x6060 = 8
//! by SDO when no RPDO carries it, producer
//! heartbeat 0x1017 set, 0x1006 communication cycle period (µs = machine cycle) and 0x1007
//! synchronous window length ([`paced::sync_window`]: half the cycle, or the cycle's frames if
//! longer), the event-timer of every cyclic RPDO (sub-index 5: the node's deadline monitoring,
//! five cycles rounded up to ms, [`paced::rpdo_event_timer_ms`]; 0 for an on-change RPDO) → NMT
//! start. A node without 0x1006 / 0x1007 or
//! without the event-timer sub-index (abort 0x0602_0000 / 0x0609_0011, e.g. an EDS that lacks
//! them) is a warning; any other refusal of them is a start-up error naming node and object.
//!
//! # One exchange at `now`
//!
//! Every axis's RPDOs (an on-change one only when its data changed), then SYNC; the nodes step at
//! SYNC and answer with their TPDOs, which are copied into the input images only when every
//! expected (cyclic) TPDO came, with the last data of every on-change TPDO (kept whenever it
//! comes, [`Trigger::OnChange`]). A missing TPDO, a node whose
//! heartbeat is older than [`HEARTBEAT_TIMEOUT_FACTOR`] × its period, or a boot-up of an
//! operational node is [`LinkError::Lost`] (the channel rides through up to `max_lost_cycles`
//! of them, one more is 900012). EMCY messages are collected
//! ([`CanopenLink::take_emergencies`]).
//!
//! `canopen-emu` runs on virtual time, on the wire ([`wire`]): every frame takes its wire time
//! at the bit rate, the bus goes to the lowest identifier, the SYNC of `now` is sent at the bus
//! time epoch + `now`, the TPDOs are awaited until the synchronous window after it passed;
//! nothing waits on a wall clock. The links that leave the process (`canopen-udp`, `socketcan:IF`) run the
//! same order on the wall clock, one SYNC per machine cycle on absolute deadlines: see
//! [`paced`] (timing, synchronous window, stall rule, cycle statistics).
//!
//! # The end of a run ([`Link::release`])
//!
//! After the machine disabled the drives (controlword 0x0006 shutdown in the RPDOs, see
//! [`crate::machine::Machine::power_off`]): NMT enter pre-operational (0x80) to every axis's
//! node, one frame per node; no SYNC and no PDO follow. Each node confirms with its next
//! heartbeat (state 0x7F), awaited for [`RELEASE_HEARTBEATS`] heartbeat periods (virtual time
//! on `canopen-emu`, where the nodes run on in cycle steps; the wall clock elsewhere). A node
//! that does not confirm is an error naming it. The next exchange sends NMT start to the nodes
//! again (their PDO configuration stays).
//!
//! # Acyclic access
//!
//! SDO upload / download with our sans-IO client ([`SdoClient`]); sizes as for EtherCAT (drive
//! file, CiA 402 table, else 4 bytes). Aborts keep the CiA 301 code.

pub mod fit;
pub mod load;
pub mod paced;
pub mod pdo_map;
mod session;
mod startup;
pub mod wire;

pub use session::{CanSession, NodeInfo};

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use super::{decode_le, object_type, Link, LinkError, Peer, ProcessImage};
#[cfg(feature = "sim")]
use crate::bus::can::VirtualCan;
use crate::bus::can::{
    Bitrate, CanBus, CanError, CanFrame, CandumpWriter, SocketCanBus, UdpConfig, UdpMulticastBus,
};
use crate::bus::canopen::nmt::{self, Emcy, NmtCommand, NmtState};
use crate::bus::canopen::pdo::{plan_layout, Direction, Pdo, Trigger};
use crate::bus::canopen::sdo::{SdoClient, SdoError};
use crate::bus::capture::CaptureClock;
use crate::drive::catalogue::DriveDefinition;
#[cfg(feature = "sim")]
use crate::drive::model::DriveModel;
#[cfg(feature = "sim")]
use crate::sim::canopen::{CanopenSegment, EmulatedNode};
use crate::units::Nanos;
use load::BusLoad;
use paced::{cycle_period_us, rpdo_event_timer_ms, Pacing};
use std::sync::Arc;
use wire::Emulated;

/// [`Link::release`] waits this many heartbeat periods for the nodes to report pre-operational.
pub const RELEASE_HEARTBEATS: u64 = 3;

/// A node is lost when its last heartbeat is older than this many periods.
pub const HEARTBEAT_TIMEOUT_FACTOR: u64 = 3;
/// Producer heartbeat period the master configures (0x1017), ms.
pub const HEARTBEAT_MS: u16 = 100;
/// CiA 301 SDO abort code "object does not exist in the object dictionary".
const ABORT_NO_OBJECT: u32 = 0x0602_0000;
/// CiA 301 abort: sub-index does not exist.
const ABORT_NO_SUBINDEX: u32 = 0x0609_0011;

/// One axis's node.
#[derive(Debug)]
struct AxisNode {
    node: u8,
    def: Arc<DriveDefinition>,
    rx: Vec<Pdo>,
    tx: Vec<Pdo>,
    /// Per RPDO: the frame an on-change RPDO last went out in (`None`: send it with the next
    /// exchange).
    rx_sent: Vec<Option<CanFrame>>,
    /// Per TPDO: the frame of the last data an on-change TPDO brought (copied into every input
    /// image the link commits; `None` before the first one).
    tx_held: Vec<Option<CanFrame>>,
    sdo: SdoClient,
    last_heartbeat: Option<Nanos>,
    state: Option<NmtState>,
    /// Start-up warning of the PDO mapping ([`fit`]: touch probe left out).
    warning: Option<crate::messages::CncMessage>,
}

/// The CANopen link (see the module documentation).
pub struct CanopenLink {
    bus: Transport,
    axes: Vec<AxisNode>,
    exchanges: u64,
    lose: BTreeSet<u64>,
    emergencies: Vec<Emcy>,
    t0: Instant,
    now: Nanos,
    /// `canopen-emu`: the bus time of the machine's time 0 (the end of the start-up).
    epoch: Nanos,
    /// The machine cycle (0x1006, and the SYNC period of a paced link).
    cycle: Nanos,
    /// The synchronous window 0x1007 ([`paced::sync_window`]).
    window: Nanos,
    /// The bus load of one cycle, computed at start-up ([`load`]).
    load: BusLoad,
    /// COB-IDs of every cyclic TPDO (expected after each SYNC).
    tpdo_cobs: Vec<u32>,
    /// On-change TPDOs: COB-ID → (axis, index into its `tx`).
    on_change_cobs: Vec<(u32, usize, usize)>,
    /// The SYNC producer on the wall clock (links that leave the process); `None` on
    /// `canopen-emu`.
    pacing: Option<Pacing>,
    /// [`Link::release`] sent the nodes to pre-operational; the next exchange starts them.
    released: bool,
    /// Buffers of one exchange, kept so that a steady cycle allocates nothing
    /// (`tests/canopen_alloc.rs`): the RPDOs to send, the frames received, which cyclic
    /// TPDOs came.
    rpdo_buf: Vec<CanFrame>,
    rx_buf: Vec<CanFrame>,
    tpdo_seen: Vec<bool>,
}

impl std::fmt::Debug for CanopenLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CanopenLink")
            .field("bus", &self.bus.describe())
            .field("axes", &self.axes)
            .field("exchanges", &self.exchanges)
            .finish_non_exhaustive()
    }
}

/// Where the master's frames go: a CAN bus, and for `canopen-emu` the emulated nodes on the
/// other endpoint of the same in-process virtual bus ([`wire`]).
struct Transport {
    bus: Box<dyn CanBus>,
    emulated: Option<Emulated>,
    candump: Option<Candump>,
}

/// The `--candump` log of a transport. A write that fails (a full disk, `/dev/full`) is not
/// silent: the first error is kept, later frames are not written, and
/// [`Transport::finish_capture`] returns it at the end of the command (exit 2, after the axes
/// stopped as usual).
///
/// Timestamps are the wall-clock time of the run ([`CaptureClock`]): the wall clock when the
/// log opened plus, on `canopen-emu` (virtual time), the bus clock of the wire since then
/// ([`wire`]: a frame the master sends at the bus time it is handed to the bus, a frame it
/// receives at the end of its transmission), so the log shows the emulated bus's true SYNC
/// spacing — `run` and the commissioning commands (`can scan`, `can dump`, `sdo … --node`)
/// alike; on a bus that leaves the process the monotonic time since then.
struct Candump {
    writer: CandumpWriter<std::io::BufWriter<std::fs::File>>,
    path: std::path::PathBuf,
    failed: Option<String>,
    clock: CaptureClock,
    /// The bus clock of the wire when the log opened (`canopen-emu`).
    wire_at_open: Option<Nanos>,
}

impl Candump {
    fn fail(&mut self, e: &std::io::Error) {
        let m = format!(
            "--candump {}: writing the log failed ({e}); the log is incomplete",
            self.path.display()
        );
        tracing::warn!(target: "fieldprobe::link::canopen", "{m}");
        self.failed = Some(m);
    }
}

impl Transport {
    /// Flush the `--candump` log; the first write error, naming the option and the file.
    fn finish_capture(&mut self) -> Result<(), String> {
        let Some(c) = self.candump.as_mut() else {
            return Ok(());
        };
        if c.failed.is_none() {
            if let Err(e) = c.writer.flush() {
                c.fail(&e);
            }
        }
        c.failed.clone().map_or(Ok(()), Err)
    }

    fn describe(&self) -> String {
        match &self.emulated {
            Some(_) => format!("{} with emulated nodes", self.bus.describe()),
            None => self.bus.describe(),
        }
    }

    fn send(&mut self, f: &CanFrame) -> Result<(), LinkError> {
        self.log(f);
        self.bus
            .send(f)
            .map_err(|e| other(format!("CAN send on {}: {e}", self.bus.describe())))
    }

    /// Take every frame that arrived; `wait` bounds the wait for the first one (not waited
    /// for with emulated nodes: they have answered already).
    fn receive_all(&mut self, wait: Duration) -> Result<Vec<CanFrame>, LinkError> {
        let mut v = Vec::new();
        let mut timeout = if self.emulated.is_some() {
            Duration::ZERO
        } else {
            wait
        };
        loop {
            match self.recv(timeout)? {
                Some(f) => v.push(f),
                None => return Ok(v),
            }
            timeout = Duration::ZERO;
        }
    }

    /// One frame (at most `wait`), logged; a datagram another program got wrong is dropped
    /// with a warning, not an error of the link.
    ///
    /// The wait polls the bus (no blocking receive with a timeout) every [`RECV_POLL`]: a
    /// socket receive timeout (SO_RCVTIMEO) counts in jiffies and overshoots a sub-millisecond
    /// wait by 4–12 ms (measured here at HZ = 250), which would break the cycle's bounds.
    fn recv(&mut self, wait: Duration) -> Result<Option<CanFrame>, LinkError> {
        let end = Instant::now() + wait;
        loop {
            match self.bus.recv(Duration::ZERO) {
                Ok(Some(f)) => {
                    self.log(&f);
                    return Ok(Some(f));
                }
                Ok(None) => {
                    let now = Instant::now();
                    if now >= end {
                        return Ok(None);
                    }
                    std::thread::sleep(RECV_POLL.min(end - now));
                }
                Err(CanError::Malformed(why)) => {
                    tracing::warn!(target: "fieldprobe::link::canopen", "dropped frame: {why}");
                    if Instant::now() >= end {
                        // A flood of them does not hold the caller beyond its bound.
                        return Ok(None);
                    }
                }
                Err(e) => {
                    return Err(other(format!(
                        "CAN receive on {}: {e}",
                        self.bus.describe()
                    )))
                }
            }
        }
    }

    /// Open a bus for `link` (`canopen-emu` with the emulated nodes of `drives` at node ids
    /// `ids`, on a wire at `bitrate` ([`wire`]); `canopen-udp[:GROUP:PORT]`; `socketcan:IF`,
    /// which run at their own bit rate).
    fn open(
        link: &str,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
        cycle: Nanos,
        bitrate: Bitrate,
        candump: Option<&std::path::Path>,
    ) -> Result<Transport, LinkError> {
        #[cfg(feature = "sim")]
        if link == "canopen-emu" {
            let nodes = drives
                .iter()
                .enumerate()
                .map(|(i, d)| {
                    if d.profile != crate::drive::catalogue::Profile::Cia402 {
                        return Err(other(format!(
                            "axis {i}: drive '{}' is a {} drive; the CANopen emulator plays CiA 402 drives only",
                            d.name,
                            d.profile.name()
                        )));
                    }
                    let id = ids.get(i).copied().unwrap_or((i + 1) as u8);
                    EmulatedNode::new(id, d)
                        .map_err(|e| other(format!("axis {i}: {e}")))
                })
                .collect::<Result<Vec<_>, _>>()?;
            let hub = VirtualCan::with_bitrate(bitrate);
            let master = hub.endpoint();
            let node_side = hub.endpoint();
            let iface = master.log_interface();
            let wire_now = Some(hub.now());
            return Ok(Transport {
                bus: Box::new(master),
                emulated: Some(Emulated::new(
                    CanopenSegment::new(nodes, cycle),
                    node_side,
                    hub,
                )),
                candump: candump
                    .map(|p| open_candump(p, &iface, wire_now))
                    .transpose()?,
            });
        }
        #[cfg(not(feature = "sim"))]
        if link == "canopen-emu" {
            let _ = (drives, ids, cycle, bitrate);
            return Err(other(
                "canopen-emu: this build of fieldprobe has no CANopen emulator (Cargo feature `sim`); canopen-udp and socketcan:IF need only `canopen` (and `socketcan`)".into(),
            ));
        }
        let bus: Box<dyn CanBus> = if let Some(ifname) = link.strip_prefix("socketcan:") {
            Box::new(SocketCanBus::open(ifname).map_err(|e| other(e.to_string()))?)
        } else if let Some(rest) = link.strip_prefix("canopen-udp") {
            let cfg = UdpConfig::parse(&format!("udp{rest}"))
                .map_err(|e| other(format!("{e} (as canopen-udp or canopen-udp:GROUP:PORT)")))?;
            Box::new(UdpMulticastBus::open(cfg).map_err(|e| other(e.to_string()))?)
        } else {
            return Err(other(format!(
                "unknown CAN link '{link}' (allowed: canopen-emu, canopen-udp[:GROUP:PORT], socketcan:IF)"
            )));
        };
        let iface = bus.log_interface();
        Ok(Transport {
            bus,
            emulated: None,
            candump: candump.map(|p| open_candump(p, &iface, None)).transpose()?,
        })
    }

    /// One SDO transfer with `client`, starting with `first`; frames that are not for the
    /// client go to `other_frames`. On `canopen-emu` on the wire and its clock
    /// ([`Transport::sdo_on_wire`]); elsewhere bounded by 4 s of wall-clock time.
    ///
    /// On a paced link (`pacing`) the SYNC keeps running on its grid while the transfer waits
    /// ([`Pacing::keep_alive`]).
    fn sdo(
        &mut self,
        client: &mut SdoClient,
        first: Vec<CanFrame>,
        t0: Instant,
        mut pacing: Option<&mut Pacing>,
        other_frames: &mut dyn FnMut(Vec<CanFrame>) -> Result<(), LinkError>,
    ) -> Result<Vec<u8>, (Option<SdoError>, String)> {
        if self.wire().is_some() {
            return self.sdo_on_wire(client, first, other_frames);
        }
        // A bus that leaves the process: the client's clock is the wall clock.
        let clock = || Nanos(t0.elapsed().as_nanos() as u64);
        for f in &first {
            self.send(f).map_err(|e| (None, e.to_string()))?;
        }
        let bound = Duration::from_secs(4);
        let deadline = Instant::now() + bound;
        loop {
            if let Some(r) = client.take_result() {
                return r.map_err(|e| {
                    let text = e.to_string();
                    (Some(e), text)
                });
            }
            if Instant::now() > deadline {
                return Err((None, "no answer".into()));
            }
            let wait = pacing
                .as_ref()
                .and_then(|p| p.until_due())
                .map_or(SDO_POLL, |ns| Duration::from_nanos(ns).min(SDO_POLL));
            let frames = self.receive_all(wait).map_err(|e| (None, e.to_string()))?;
            let mut replies = Vec::new();
            let mut rest = Vec::new();
            let response =
                u32::from(crate::bus::canopen::sdo::SDO_TX_BASE) + u32::from(client.node());
            for f in frames {
                if !f.extended && f.id == response {
                    replies.extend(client.handle(&f, clock()));
                } else {
                    rest.push(f);
                }
            }
            other_frames(rest).map_err(|e| (None, e.to_string()))?;
            replies.extend(client.poll(clock()));
            for f in &replies {
                self.send(f).map_err(|e| (None, e.to_string()))?;
            }
            if let Some(p) = pacing.as_deref_mut() {
                p.keep_alive(self).map_err(|e| (None, e.to_string()))?;
            }
        }
    }

    /// The interface name of the bus in `candump -L` lines ([`CanBus::log_interface`]).
    fn log_interface(&self) -> String {
        self.bus.log_interface()
    }

    /// Log `f` in the `--candump` file: on `canopen-emu` at the bus clock (the UNIX time of
    /// bus time 0 plus the bus time), elsewhere at the wall clock.
    fn log(&mut self, f: &CanFrame) {
        let wire = self.wire_clock();
        if let Some(c) = self.candump.as_mut().filter(|c| c.failed.is_none()) {
            let ns = match (wire, c.wire_at_open) {
                (Some(now), Some(open)) => c.clock.at_ns(now.0.saturating_sub(open.0)),
                _ => c.clock.now_ns(),
            };
            if let Err(e) = c.writer.write_frame(Duration::from_nanos(ns), f) {
                c.fail(&e);
            }
        }
    }
}

/// Sleep between two polls of the bus while waiting for a frame.
const RECV_POLL: Duration = Duration::from_micros(50);

/// Longest wait for one SDO answer poll.
const SDO_POLL: Duration = Duration::from_millis(5);

/// Open the `--candump` log `path` for a bus whose `candump -L` name is `iface`; `wire` is the
/// bus clock of the wire now (`canopen-emu`), `None` elsewhere (see [`Candump`]).
fn open_candump(
    path: &std::path::Path,
    iface: &str,
    wire: Option<Nanos>,
) -> Result<Candump, LinkError> {
    let f = std::fs::File::create(path)
        .map_err(|e| other(format!("--candump {}: {e}", path.display())))?;
    Ok(Candump {
        writer: CandumpWriter::new(std::io::BufWriter::new(f), iface),
        path: path.to_path_buf(),
        failed: None,
        clock: CaptureClock::start(),
        wire_at_open: wire,
    })
}

fn other(m: String) -> LinkError {
    LinkError::Other(m)
}

/// A failed SDO transfer as a link error: an abort keeps its CiA 301 code, anything else
/// (timeout, protocol) is described in words.
fn sdo_failure(node: u8, index: u16, sub: u8) -> impl Fn((Option<SdoError>, String)) -> LinkError {
    move |(e, text)| match e {
        Some(SdoError::Abort { code, .. }) => LinkError::Abort {
            device: Peer::Node(node),
            index,
            sub,
            code,
        },
        _ => other(format!("node {node}: SDO {index:#06x}:{sub:02x}: {text}")),
    }
}

/// Node ids 1 … n.
#[cfg(feature = "sim")]
fn default_ids(n: usize) -> Result<Vec<u8>, LinkError> {
    if n > 127 {
        return Err(other(format!(
            "{n} drives: a CAN link has at most 127 nodes"
        )));
    }
    Ok((1..=n as u8).collect())
}

/// Node ids must be 1 … 127 and distinct.
fn check_ids(ids: &[u8]) -> Result<(), LinkError> {
    for (k, id) in ids.iter().enumerate() {
        if !(1..=127).contains(id) {
            return Err(other(format!("node id {id} (axis {k}): allowed 1 … 127")));
        }
        if let Some(j) = ids[..k].iter().position(|x| x == id) {
            return Err(other(format!("node id {id} is given to axes {j} and {k}")));
        }
    }
    Ok(())
}

/// The bus load of `drives` at node ids `ids` with the master's PDO layout
/// ([`plan_layout`]) at `bitrate` and `cycle` ([`load`]); an error when a drive's process data
/// do not fit its PDOs. The link checks it at start-up; a machine builder can ask before.
pub fn plan_bus_load(
    drives: &[Arc<DriveDefinition>],
    ids: &[u8],
    bitrate: Bitrate,
    cycle: Nanos,
) -> Result<BusLoad, LinkError> {
    let nodes = drives
        .iter()
        .zip(ids)
        .map(|(d, &node)| {
            let (rx, tx) = plan_node(d, node)?;
            Ok(load::node_frames(&rx, &tx))
        })
        .collect::<Result<Vec<_>, LinkError>>()?;
    Ok(BusLoad::new(&nodes, bitrate, cycle, HEARTBEAT_MS))
}

/// The master's RPDOs and TPDOs for `def` at `node`.
fn plan_node(def: &DriveDefinition, node: u8) -> Result<(Vec<Pdo>, Vec<Pdo>), LinkError> {
    let rx = plan_layout(&def.rxpdo, Direction::Rx, node)
        .map_err(|e| other(format!("node {node}: {e}")))?;
    let tx = plan_layout(&def.txpdo, Direction::Tx, node)
        .map_err(|e| other(format!("node {node}: {e}")))?;
    Ok((rx, tx))
}

impl CanopenLink {
    #[cfg(feature = "sim")]
    /// `canopen-emu`: one emulated CiA 402 node per drive (node id = position + 1) and the
    /// master, in process, on a wire at 1 Mbit/s; brought to operational.
    pub fn emulated(drives: &[Arc<DriveDefinition>], cycle: Nanos) -> Result<Self, LinkError> {
        CanopenLink::emulated_at(drives, cycle, Bitrate::DEFAULT, None)
    }

    #[cfg(feature = "sim")]
    /// [`emulated`](Self::emulated), logging every frame in candump -L format into `candump`.
    pub fn emulated_with(
        drives: &[Arc<DriveDefinition>],
        cycle: Nanos,
        candump: Option<&std::path::Path>,
    ) -> Result<Self, LinkError> {
        CanopenLink::emulated_at(drives, cycle, Bitrate::DEFAULT, candump)
    }

    #[cfg(feature = "sim")]
    /// [`emulated_with`](Self::emulated_with) on a wire at `bitrate`.
    pub fn emulated_at(
        drives: &[Arc<DriveDefinition>],
        cycle: Nanos,
        bitrate: Bitrate,
        candump: Option<&std::path::Path>,
    ) -> Result<Self, LinkError> {
        let ids = default_ids(drives.len())?;
        CanopenLink::on_link("canopen-emu", drives, &ids, cycle, bitrate, candump)
    }

    #[cfg(feature = "sim")]
    /// `canopen-emu` with the given emulated nodes (e.g. object dictionaries from an EDS,
    /// [`EmulatedNode::from_eds`]): node *i* serves `drives[i]` at its own node id; brought to
    /// operational on virtual time like [`emulated`](Self::emulated), on a wire at 1 Mbit/s.
    pub fn with_nodes(
        nodes: Vec<EmulatedNode>,
        drives: &[Arc<DriveDefinition>],
        cycle: Nanos,
    ) -> Result<Self, LinkError> {
        CanopenLink::with_nodes_at(nodes, drives, cycle, Bitrate::DEFAULT)
    }

    #[cfg(feature = "sim")]
    /// [`with_nodes`](Self::with_nodes) on a wire at `bitrate`.
    pub fn with_nodes_at(
        nodes: Vec<EmulatedNode>,
        drives: &[Arc<DriveDefinition>],
        cycle: Nanos,
        bitrate: Bitrate,
    ) -> Result<Self, LinkError> {
        let ids: Vec<u8> = nodes.iter().map(EmulatedNode::id).collect();
        check_ids(&ids)?;
        let hub = VirtualCan::with_bitrate(bitrate);
        let bus = Transport {
            bus: Box::new(hub.endpoint()),
            emulated: Some(Emulated::new(
                CanopenSegment::new(nodes, cycle),
                hub.endpoint(),
                hub,
            )),
            candump: None,
        };
        CanopenLink::start(bus, drives, &ids, cycle, bitrate)
    }

    /// A master for `drives` at node ids `ids` (one per drive, distinct, 1 … 127) on the CAN
    /// link named `link` (`canopen-emu`: emulated nodes at those ids on a wire at `bitrate`,
    /// `canopen-udp[:GROUP:PORT]`, `socketcan:IF`), brought to operational. `bitrate` is the
    /// bus's (the machine file's `[can] bitrate`): the bus load is checked against it
    /// ([`load`]).
    pub fn on_link(
        link: &str,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
        cycle: Nanos,
        bitrate: Bitrate,
        candump: Option<&std::path::Path>,
    ) -> Result<Self, LinkError> {
        check_ids(ids)?;
        let bus = Transport::open(link, drives, ids, cycle, bitrate, candump)?;
        CanopenLink::start(bus, drives, ids, cycle, bitrate)
    }

    /// A master on `bus` (running at `bitrate`) for nodes `ids` (one per drive), brought to
    /// operational; its cycle is paced on the wall clock with period `cycle` ([`paced`]).
    pub fn open(
        bus: Box<dyn CanBus>,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
        cycle: Nanos,
        bitrate: Bitrate,
        candump: Option<&std::path::Path>,
    ) -> Result<Self, LinkError> {
        let iface = bus.log_interface();
        CanopenLink::start(
            Transport {
                bus,
                emulated: None,
                candump: candump.map(|p| open_candump(p, &iface, None)).transpose()?,
            },
            drives,
            ids,
            cycle,
            bitrate,
        )
    }

    fn start(
        bus: Transport,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
        cycle: Nanos,
        bitrate: Bitrate,
    ) -> Result<Self, LinkError> {
        if drives.len() != ids.len() {
            return Err(other(format!(
                "{} drives but {} node ids",
                drives.len(),
                ids.len()
            )));
        }
        let axes = drives
            .iter()
            .zip(ids)
            .map(|(d, &node)| {
                let (rx, tx) = plan_node(d, node)?;
                Ok(AxisNode {
                    node,
                    def: d.clone(),
                    rx_sent: vec![None; rx.len()],
                    tx_held: vec![None; tx.len()],
                    rx,
                    tx,
                    sdo: SdoClient::new(node),
                    last_heartbeat: None,
                    state: None,
                    warning: None,
                })
            })
            .collect::<Result<Vec<_>, LinkError>>()?;
        let nodes: Vec<load::NodeFrames> = axes
            .iter()
            .map(|a| load::node_frames(&a.rx, &a.tx))
            .collect();
        let bus_load = BusLoad::new(&nodes, bitrate, cycle, HEARTBEAT_MS);
        if let Err(refused) = bus_load.check() {
            return Err(LinkError::Other(refused));
        }
        tracing::info!(target: "fieldprobe::link::canopen", "{}", bus_load.describe());
        let window = paced::sync_window(cycle, bus_load.wire_time());
        let mut link = CanopenLink {
            bus,
            axes,
            exchanges: 0,
            lose: BTreeSet::new(),
            emergencies: Vec::new(),
            t0: Instant::now(),
            now: Nanos::ZERO,
            epoch: Nanos::ZERO,
            cycle,
            window,
            load: bus_load,
            tpdo_cobs: Vec::new(),
            on_change_cobs: Vec::new(),
            pacing: None,
            released: false,
            rpdo_buf: Vec::new(),
            rx_buf: Vec::new(),
            tpdo_seen: Vec::new(),
        };
        if link.bus.emulated.is_none() {
            link.pacing = Some(Pacing::new(cycle, window));
        }
        link.boot()?;
        // The TPDOs as mapped (the start-up may have fitted a definition, [`fit`]).
        for (i, a) in link.axes.iter().enumerate() {
            for (k, p) in a.tx.iter().enumerate() {
                match p.trigger {
                    Trigger::Cyclic => link.tpdo_cobs.push(u32::from(p.cob)),
                    Trigger::OnChange { .. } => {
                        link.on_change_cobs.push((u32::from(p.cob), i, k));
                    }
                }
            }
        }
        let nodes: Vec<load::NodeFrames> = link
            .axes
            .iter()
            .map(|a| load::node_frames(&a.rx, &a.tx))
            .collect();
        link.load = BusLoad::new(&nodes, bitrate, cycle, HEARTBEAT_MS);
        // The layout fitted into the nodes' PDOs may need more frames than planned (fewer
        // entries a PDO): the same limit, before any SYNC or PDO.
        if let Err(refused) = link.load.check() {
            return Err(LinkError::Other(format!(
                "{refused} (with the PDOs fitted into what the nodes offer)"
            )));
        }
        link.epoch = link.bus.wire_clock().unwrap_or(Nanos::ZERO);
        Ok(link)
    }

    /// The bus load of one cycle as computed at start-up ([`load`]).
    pub fn bus_load(&self) -> &BusLoad {
        &self.load
    }

    /// The synchronous window 0x1007 the master configured.
    pub fn sync_window(&self) -> Nanos {
        self.window
    }

    /// `canopen-emu`: the bus clock (virtual) and the bus time of the machine's time 0 (the
    /// end of the start-up); `None` on a bus that leaves the process.
    pub fn bus_clock(&self) -> Option<(Nanos, Nanos)> {
        self.bus.wire_clock().map(|c| (c, self.epoch))
    }

    /// The link's clock for SDO time-outs and the heartbeat consumer: the bus clock on
    /// `canopen-emu` ([`wire`]; the emulated nodes produce their heartbeats on it), else the
    /// wall clock since the link opened (the nodes on a real bus produce on theirs).
    fn wall(&self) -> Nanos {
        self.bus
            .wire_clock()
            .unwrap_or_else(|| Nanos(self.t0.elapsed().as_nanos() as u64))
    }

    fn send(&mut self, f: &CanFrame) -> Result<(), LinkError> {
        self.bus.send(f)
    }

    fn receive_all(&mut self, wait: Duration) -> Result<Vec<CanFrame>, LinkError> {
        self.bus.receive_all(wait)
    }

    /// Common handling of heartbeats, EMCY and on-change TPDOs (kept for the next input image
    /// the link commits, whenever they come); returns the frames not consumed.
    fn note(&mut self, mut frames: Vec<CanFrame>, now: Nanos) -> Result<Vec<CanFrame>, LinkError> {
        self.note_from(&mut frames, 0, now)?;
        Ok(frames)
    }

    /// [`note`](Self::note) on `frames[from..]` in place: the frames not consumed stay there,
    /// in order.
    fn note_from(
        &mut self,
        frames: &mut Vec<CanFrame>,
        from: usize,
        now: Nanos,
    ) -> Result<(), LinkError> {
        let hb_now = self.wall();
        let mut keep = from;
        for i in from..frames.len() {
            let f = frames[i];
            if !self.note_one(&f, now, hb_now)? {
                frames[keep] = f;
                keep += 1;
            }
        }
        frames.truncate(keep);
        Ok(())
    }

    /// One frame for [`note`](Self::note), heartbeats taken at `hb_now`: `true` when it was
    /// consumed.
    fn note_one(&mut self, f: &CanFrame, now: Nanos, hb_now: Nanos) -> Result<bool, LinkError> {
        if !f.extended && !f.rtr && !f.error {
            if let Some(&(_, i, k)) = self.on_change_cobs.iter().find(|c| c.0 == f.id) {
                if let Some(slot) = self.axes.get_mut(i).and_then(|a| a.tx_held.get_mut(k)) {
                    *slot = Some(*f);
                }
                return Ok(true);
            }
        }
        if let Some((node, state)) = nmt::parse_heartbeat(f) {
            if let Some(ax) = self.axes.iter_mut().find(|a| a.node == node) {
                if state == NmtState::BootUp && ax.state == Some(NmtState::Operational) {
                    return Err(LinkError::Lost {
                        at: now,
                        reason: format!("node {node} rebooted (boot-up message)"),
                    });
                }
                ax.state = Some(state);
                ax.last_heartbeat = Some(hb_now);
            }
            return Ok(true);
        }
        if let Some(e) = Emcy::parse(f) {
            tracing::debug!(target: "fieldprobe::link::canopen", node = e.node, code = e.code, "EMCY {}", e.text());
            self.emergencies.push(e);
            return Ok(true);
        }
        Ok(false)
    }

    /// Let the bus run a little and take what came: on `canopen-emu` the nodes do their
    /// time-driven work and 1 ms of bus time passes ([`wire`]); elsewhere the master waits up
    /// to `wait` for a first frame.
    fn settle(&mut self, wait: Duration) -> Result<Vec<CanFrame>, LinkError> {
        if self.bus.wire().is_some() {
            self.bus.wait_wire(Nanos::from_micros(1000))
        } else {
            self.receive_all(wait)
        }
    }

    fn boot(&mut self) -> Result<(), LinkError> {
        self.send(&NmtCommand::ResetCommunication.frame(0))?;
        let deadline = Instant::now() + Duration::from_secs(2);
        let bus_deadline = self.wall().saturating_add(Nanos(2_000_000_000));
        loop {
            let frames = self.settle(Duration::from_millis(20))?;
            self.note(frames, self.now)?;
            if self.axes.iter().all(|a| {
                a.state == Some(NmtState::PreOperational) || a.state == Some(NmtState::BootUp)
            }) {
                break;
            }
            let late = match self.bus.wire_clock() {
                Some(t) => t > bus_deadline,
                None => Instant::now() > deadline,
            };
            if late {
                let missing: Vec<String> = self
                    .axes
                    .iter()
                    .filter(|a| a.state.is_none())
                    .map(|a| a.node.to_string())
                    .collect();
                return Err(other(format!(
                    "no boot-up from node(s) {} within 2 s on {}",
                    missing.join(", "),
                    self.bus.describe()
                )));
            }
        }
        for i in 0..self.axes.len() {
            let node = self.axes[i].node;
            let device_type = self.sdo_transfer(i, 0x1000, 0, None)?;
            let device_type = decode_le(&device_type, false) as u32;
            if device_type & 0xFFFF != 402 {
                tracing::warn!(target: "fieldprobe::link::canopen", node, "device type {device_type:#010x} is not a CiA 402 drive");
            }
            self.fit_and_map(i)?;
            self.sdo_transfer(i, 0x1017, 0, Some(&HEARTBEAT_MS.to_le_bytes()))?;
            self.write_sync_timing(i)?;
        }
        self.send(&NmtCommand::Start.frame(0))?;
        let frames = self.settle(Duration::from_millis(20))?;
        self.note(frames, self.now)?;
        let hb_start = self.wall();
        for a in &mut self.axes {
            a.state = Some(NmtState::Operational);
            a.last_heartbeat = Some(hb_start);
        }
        Ok(())
    }

    /// Start-up: 0x1006 communication cycle period and 0x1007 synchronous window length
    /// (CiA 301; [`paced::sync_window`]) of axis `i`'s node, and the event-timer (deadline
    /// monitoring) of each of its RPDOs — 0 (off) for an on-change RPDO, which does not come
    /// every cycle. A node without the object or sub-index (abort 0x0602_0000 / 0x0609_0011)
    /// runs without it: a warning. Any other refusal is an error naming node and object.
    fn write_sync_timing(&mut self, i: usize) -> Result<(), LinkError> {
        let node = self.axes[i].node;
        let event_ms = rpdo_event_timer_ms(self.cycle);
        let window_us = u32::try_from(self.window.0 / 1000).unwrap_or(u32::MAX);
        let mut objects = vec![
            (
                0x1006u16,
                0u8,
                "communication cycle period".to_string(),
                cycle_period_us(self.cycle).to_le_bytes().to_vec(),
                format!("{} µs", cycle_period_us(self.cycle)),
            ),
            (
                0x1007,
                0,
                "synchronous window length".to_string(),
                window_us.to_le_bytes().to_vec(),
                format!("{window_us} µs"),
            ),
        ];
        for p in &self.axes[i].rx {
            let ms = match p.trigger {
                Trigger::Cyclic => event_ms,
                Trigger::OnChange { .. } => 0,
            };
            objects.push((
                Direction::Rx.comm_index(p.number),
                5,
                format!("RPDO {} event-timer", p.number + 1),
                ms.to_le_bytes().to_vec(),
                format!("{ms} ms"),
            ));
        }
        for (index, sub, what, data, value) in objects {
            match self.sdo_transfer(i, index, sub, Some(&data)) {
                Ok(_) => {
                    tracing::debug!(target: "fieldprobe::link::canopen", node, "{index:#06x}:{sub:02x} {what} = {value}");
                }
                Err(LinkError::Abort { code, .. })
                    if code == ABORT_NO_OBJECT || code == ABORT_NO_SUBINDEX =>
                {
                    tracing::warn!(target: "fieldprobe::link::canopen", node,
                        "node {node} has no {index:#06x}:{sub:02x} {what} (SDO abort {code:#010x}); it runs without it");
                }
                Err(LinkError::Abort { code, .. }) => {
                    return Err(other(format!(
                        "node {node}: start-up: writing {index:#06x}:{sub:02x} {what} = {value} refused, \
                         abort code {code:#010x} ({})",
                        crate::bus::abort::abort_text(code)
                    )))
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// One SDO transfer with axis `i`'s node: upload (`data` None) or download.
    fn sdo_transfer(
        &mut self,
        i: usize,
        index: u16,
        sub: u8,
        data: Option<&[u8]>,
    ) -> Result<Vec<u8>, LinkError> {
        let node = self.axes[i].node;
        let wall = self.wall();
        let mut client = std::mem::replace(&mut self.axes[i].sdo, SdoClient::new(node));
        let first = match data {
            None => client.upload(index, sub, wall),
            Some(d) => client.download(index, sub, d, wall),
        };
        let now = self.now;
        let t0 = self.t0;
        let mut seen = Vec::new();
        let r = self.bus.sdo(
            &mut client,
            first,
            t0,
            self.pacing.as_mut(),
            &mut |frames| {
                seen.extend(frames);
                Ok(())
            },
        );
        self.axes[i].sdo = client;
        self.note(seen, now)?;
        r.map_err(sdo_failure(node, index, sub))
    }

    /// The end of an exchange: the fault knob, the heartbeat consumer, and the TPDOs (`got`,
    /// the frames after SYNC) copied into the input images when every expected (cyclic) one
    /// came, with the last data of every on-change TPDO ([`Trigger::OnChange`], taken by
    /// [`Self::note`] whenever it came).
    fn finish_exchange(
        &mut self,
        n: u64,
        now: Nanos,
        got: &mut Vec<CanFrame>,
        images: &mut [ProcessImage],
    ) -> Result<(), LinkError> {
        if self.lose.contains(&n) {
            // Fault knob: this cycle's cyclic TPDOs come too late for it.
            got.retain(|f| !self.tpdo_cobs.contains(&f.id));
        }
        // Heartbeat consumer.
        let hb_now = self.wall();
        for ax in &self.axes {
            let limit = u64::from(HEARTBEAT_MS) * 1_000_000 * HEARTBEAT_TIMEOUT_FACTOR;
            if let Some(t) = ax.last_heartbeat {
                if hb_now.0.saturating_sub(t.0) > limit {
                    return Err(LinkError::Lost {
                        at: now,
                        reason: format!(
                            "node {} heartbeat lost (none for {} ms, period {HEARTBEAT_MS} ms)",
                            ax.node,
                            hb_now.0.saturating_sub(t.0) / 1_000_000
                        ),
                    });
                }
            }
        }
        // Every expected TPDO first, with its length; only then the input images change (all
        // or none of them).
        /// TPDO `p`'s data: `None` for an on-change one that has not come yet, `Some(None)`
        /// for a missing cyclic one.
        fn data<'a>(
            got: &'a [CanFrame],
            p: &Pdo,
            held: &'a Option<CanFrame>,
        ) -> Option<Option<&'a [u8]>> {
            match p.trigger {
                Trigger::Cyclic => Some(
                    got.iter()
                        .rev()
                        .find(|f| !f.extended && !f.rtr && f.id == u32::from(p.cob))
                        .map(CanFrame::payload),
                ),
                Trigger::OnChange { .. } => held.as_ref().map(|f| Some(f.payload())),
            }
        }
        let got = &got[..];
        for ax in &self.axes {
            for (p, held) in ax.tx.iter().zip(&ax.tx_held) {
                match data(got, p, held) {
                    // An on-change TPDO that has not come yet: nothing to copy.
                    None => {}
                    Some(Some(d)) if d.len() == p.len() => {}
                    Some(Some(d)) => {
                        return Err(LinkError::Lost {
                            at: now,
                            reason: format!(
                                "node {}: TPDO {} has {} bytes, expected {}",
                                ax.node,
                                p.number + 1,
                                d.len(),
                                p.len()
                            ),
                        })
                    }
                    Some(None) => {
                        return Err(LinkError::Lost {
                            at: now,
                            reason: format!(
                                "node {}: TPDO {} missing after SYNC",
                                ax.node,
                                p.number + 1
                            ),
                        })
                    }
                }
            }
        }
        for (ax, img) in self.axes.iter().zip(images.iter_mut()) {
            for (p, held) in ax.tx.iter().zip(&ax.tx_held) {
                if let Some(Some(d)) = data(got, p, held) {
                    p.unpack(d, &mut img.inputs);
                }
            }
        }
        Ok(())
    }

    /// After [`Link::release`]: NMT start to every axis's node (their PDO configuration is
    /// kept in pre-operational), as at the end of the start-up.
    fn restart(&mut self) -> Result<(), LinkError> {
        self.released = false;
        let nodes: Vec<u8> = self.axes.iter().map(|a| a.node).collect();
        for node in nodes {
            self.send(&NmtCommand::Start.frame(node))?;
        }
        let hb = self.wall();
        for a in &mut self.axes {
            a.state = Some(NmtState::Operational);
            a.last_heartbeat = Some(hb);
            // The on-change RPDOs go out again with the next exchange.
            a.rx_sent.iter_mut().for_each(|d| *d = None);
        }
        Ok(())
    }

    /// Fault knob: the cyclic TPDOs of the `n`-th exchange (0-based) do not reach the master in
    /// time (dropped before it sees them; the exchange then reports the missing TPDO). On CAN
    /// a frame is not lost silently — the controllers acknowledge and repeat it — so what a
    /// master misses is a frame that came too late; the on-change TPDOs of that SYNC, which
    /// come before the cyclic ones ([`crate::bus::canopen::pdo`]), are taken as always.
    pub fn lose_exchange_at(&mut self, n: u64) {
        self.lose.insert(n);
    }

    /// Emergencies received so far (drains).
    pub fn take_emergencies(&mut self) -> Vec<Emcy> {
        std::mem::take(&mut self.emergencies)
    }

    #[cfg(feature = "sim")]
    /// The emulated nodes (`canopen-emu`).
    pub fn segment(&self) -> Option<&CanopenSegment> {
        self.bus.emulated.as_ref().map(|e| &e.segment)
    }

    #[cfg(feature = "sim")]
    /// The emulated nodes, mutable (fault knobs: a node's 0x1017, model faults).
    pub fn segment_mut(&mut self) -> Option<&mut CanopenSegment> {
        self.bus.emulated.as_mut().map(|e| &mut e.segment)
    }

    /// `canopen-emu`: record every frame the wire completes from now on (`false`: stop and
    /// forget), for [`take_bus_trace`](Self::take_bus_trace).
    pub fn trace_bus(&mut self, on: bool) {
        if let Some(e) = self.bus.emulated.as_mut() {
            e.trace = on.then(Vec::new);
        }
    }

    /// The frames the wire completed since the last call (with [`trace_bus`](Self::trace_bus)
    /// on), in order: when each won the bus and when it ended.
    pub fn take_bus_trace(&mut self) -> Vec<crate::bus::can::Delivery> {
        self.bus
            .emulated
            .as_mut()
            .and_then(|e| e.trace.as_mut())
            .map(std::mem::take)
            .unwrap_or_default()
    }

    /// One exchange on `canopen-emu` ([`wire`]): the RPDOs (sent already, at the bus clock:
    /// right after the previous exchange's TPDOs) travel while the wire runs to the SYNC's
    /// time epoch + `now`; the nodes do their time-driven work; SYNC (late, at the bus clock,
    /// when the bus ran past its time); the wire runs until every cyclic TPDO came or the
    /// synchronous window after the SYNC passed.
    fn exchange_on_wire(
        &mut self,
        n: u64,
        now: Nanos,
        images: &mut [ProcessImage],
    ) -> Result<(), LinkError> {
        let t_sync = self.epoch.saturating_add(now);
        let mut frames = std::mem::take(&mut self.rx_buf);
        frames.clear();
        self.bus
            .run_wire_into(Some(t_sync), &mut |_, _| false, &mut frames)?;
        // Heartbeats, EMCY and on-change TPDOs count; a cyclic TPDO before this SYNC belongs
        // to an earlier one and is dropped.
        self.note_from(&mut frames, 0, now)?;
        frames.clear();
        self.bus.poll_nodes();
        let sent = self.bus.wire_clock().unwrap_or(t_sync);
        self.bus.send_sync(now)?;
        let deadline = sent.saturating_add(self.window);
        let cobs = &self.tpdo_cobs;
        let seen = &mut self.tpdo_seen;
        seen.clear();
        seen.resize(cobs.len(), false);
        let mut missing = cobs.len();
        let mut synced = false;
        let mut before = 0;
        self.bus.run_wire_into(
            Some(deadline),
            &mut |d, got| {
                if !synced {
                    synced = d.frame.id == u32::from(nmt::SYNC_COB) && !d.frame.extended;
                    before += got.len();
                    return false;
                }
                for f in got.iter().filter(|f| !f.extended && !f.rtr && !f.error) {
                    if let Some(k) = cobs.iter().position(|&c| c == f.id) {
                        if !seen[k] {
                            seen[k] = true;
                            missing -= 1;
                        }
                    }
                }
                missing == 0
            },
            &mut frames,
        )?;
        // The frames up to the SYNC: noted, the rest dropped (as before the SYNC above); the
        // frames after it: the TPDOs of this SYNC.
        let before = before.min(frames.len());
        let hb_now = self.wall();
        for f in frames.drain(..before) {
            self.note_one(&f, now, hb_now)?;
        }
        self.note_from(&mut frames, 0, now)?;
        let r = self.finish_exchange(n, now, &mut frames, images);
        self.rx_buf = frames;
        r
    }
}

impl Link for CanopenLink {
    fn take_drive_emergencies(&mut self) -> Vec<super::DriveEmergency> {
        let axes = &self.axes;
        std::mem::take(&mut self.emergencies)
            .into_iter()
            .filter_map(|e| {
                let device = axes.iter().position(|a| a.node == e.node)?;
                Some(super::DriveEmergency {
                    device,
                    code: e.code,
                    text: e.text(),
                })
            })
            .collect()
    }

    fn exchange(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Result<(), LinkError> {
        if images.len() != self.axes.len() {
            return Err(LinkError::Mismatch {
                devices: self.axes.len(),
                images: images.len(),
            });
        }
        self.now = now;
        if self.released {
            self.restart()?;
        }
        let n = self.exchanges;
        self.exchanges += 1;
        let mut rpdos = std::mem::take(&mut self.rpdo_buf);
        rpdos.clear();
        for (ax, img) in self.axes.iter_mut().zip(images.iter()) {
            for (p, sent) in ax.rx.iter().zip(ax.rx_sent.iter_mut()) {
                let f = p
                    .frame(&img.outputs)
                    .map_err(|e| other(format!("node {}: RPDO {}: {e}", ax.node, p.number + 1)))?;
                if p.trigger != Trigger::Cyclic {
                    // On change: only new data go out.
                    if sent.as_ref().map(CanFrame::payload) == Some(f.payload()) {
                        continue;
                    }
                    *sent = Some(f);
                }
                rpdos.push(f);
            }
        }
        // The set-points computed from the previous exchange go out at once: inside the
        // synchronous window that followed the previous SYNC.
        for f in &rpdos {
            self.send(f)?;
        }
        self.rpdo_buf = rpdos;
        match self.pacing.take() {
            Some(mut pacing) => {
                let r = self.paced_cycle(&mut pacing, n, now, images);
                self.pacing = Some(pacing);
                r
            }
            None => self.exchange_on_wire(n, now, images),
        }
    }

    fn release(&mut self, now: Nanos) -> Result<(), LinkError> {
        self.now = now;
        self.released = true;
        let nodes: Vec<u8> = self.axes.iter().map(|a| a.node).collect();
        for &node in &nodes {
            self.send(&NmtCommand::EnterPreOperational.frame(node))?;
        }
        // Only heartbeats after the command count.
        for a in &mut self.axes {
            a.state = None;
        }
        let bound = u64::from(HEARTBEAT_MS) * 1_000_000 * RELEASE_HEARTBEATS;
        let confirmed = |axes: &[AxisNode]| {
            axes.iter()
                .all(|a| a.state == Some(NmtState::PreOperational))
        };
        if self.bus.wire().is_some() {
            // Virtual time: the wire and the nodes run on in cycle steps until their
            // heartbeats came. The machine's time is not moved (nothing else runs): its next
            // SYNC, after a restart, follows on a grid that starts here.
            let start = self.wall();
            loop {
                let frames = self.bus.wait_wire(Nanos(self.cycle.0.max(1)))?;
                self.note(frames, now)?;
                if confirmed(&self.axes) || self.wall().0.saturating_sub(start.0) >= bound {
                    break;
                }
            }
            self.epoch = Nanos(self.wall().0.saturating_sub(now.0));
        } else {
            let end = Instant::now() + Duration::from_nanos(bound);
            while !confirmed(&self.axes) && Instant::now() < end {
                let frames = self.receive_all(Duration::from_millis(10))?;
                self.note(frames, now)?;
            }
        }
        let missing: Vec<String> = self
            .axes
            .iter()
            .filter(|a| a.state != Some(NmtState::PreOperational))
            .map(|a| match a.state {
                Some(s) => format!("node {} ({})", a.node, s.name()),
                None => format!("node {} (no heartbeat)", a.node),
            })
            .collect();
        if missing.is_empty() {
            Ok(())
        } else {
            Err(other(format!(
                "NMT enter pre-operational: {} not confirmed by a heartbeat within {} ms on {}",
                missing.join(", "),
                bound / 1_000_000,
                self.bus.describe()
            )))
        }
    }

    fn read_object(&mut self, device: usize, index: u16, sub: u8) -> Result<i64, LinkError> {
        let ax = self
            .axes
            .get(device)
            .ok_or_else(|| other(format!("device {device}: not on the link")))?;
        let (_, signed) = object_type(&ax.def, index, sub);
        let bytes = self.sdo_transfer(device, index, sub, None)?;
        Ok(decode_le(&bytes, signed))
    }

    fn write_object(
        &mut self,
        device: usize,
        index: u16,
        sub: u8,
        value: i64,
    ) -> Result<(), LinkError> {
        let ax = self
            .axes
            .get(device)
            .ok_or_else(|| other(format!("device {device}: not on the link")))?;
        let (size, _) = object_type(&ax.def, index, sub);
        let bytes = value.to_le_bytes();
        self.sdo_transfer(device, index, sub, Some(&bytes[..size.min(8)]))
            .map(|_| ())
    }

    #[cfg(feature = "sim")]
    fn plant(&self) -> Option<&crate::sim::plant::Plant> {
        self.segment().map(|s| s.world().plant())
    }

    #[cfg(feature = "sim")]
    fn plant_mut(&mut self) -> Option<&mut crate::sim::plant::Plant> {
        self.segment_mut().map(|s| s.world_mut().plant_mut())
    }

    #[cfg(feature = "sim")]
    fn flood_emergencies(&mut self, device: usize, code: u16, every: Option<Nanos>) -> bool {
        self.segment_mut()
            .and_then(|s| s.nodes_mut().get_mut(device))
            .map(|n| n.flood_emcy(code, every))
            .is_some()
    }

    #[cfg(feature = "sim")]
    fn model(&self, device: usize) -> Option<&dyn DriveModel> {
        self.segment()?.nodes().get(device).map(|n| n.model())
    }

    #[cfg(feature = "sim")]
    fn model_mut(&mut self, device: usize) -> Option<&mut dyn DriveModel> {
        self.segment_mut()?
            .nodes_mut()
            .get_mut(device)
            .map(|n| n.model_mut())
    }

    fn lose_exchange_at(&mut self, n: u64) {
        CanopenLink::lose_exchange_at(self, n);
    }

    fn drive_definition(&self, device: usize) -> Option<Arc<DriveDefinition>> {
        self.axes.get(device).map(|a| a.def.clone())
    }

    fn startup_report(&self) -> Vec<crate::messages::CncMessage> {
        self.axes.iter().filter_map(|a| a.warning.clone()).collect()
    }

    fn exchanges(&self) -> u64 {
        self.exchanges
    }

    fn cycle_summary(&self) -> Option<crate::rt::CycleSummary> {
        self.pacing.as_ref().map(|p| p.stats().summary())
    }

    fn finish_capture(&mut self) -> Result<(), String> {
        self.bus.finish_capture()
    }

    fn finish_cycle_log(&mut self) -> Result<(), String> {
        match self.pacing.as_mut() {
            Some(p) => p.stats_mut().finish_log(),
            None => Ok(()),
        }
    }

    fn set_cycle_log(
        &mut self,
        name: &str,
        out: Box<dyn std::io::Write + Send>,
    ) -> Result<(), LinkError> {
        match self.pacing.as_mut() {
            Some(p) => {
                p.log_to(name, out);
                Ok(())
            }
            None => Err(LinkError::Other(paced::NO_CYCLE_LOG.into())),
        }
    }
}
