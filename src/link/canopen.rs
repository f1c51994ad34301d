//! CANopen link: our CiA 301 master drives the axes over a [`CanBus`].
//!
//! | `--link` | bus | nodes |
//! |---|---|---|
//! | `canopen-emu` | in-process: the master's frames go straight to a [`CanopenSegment`] | one emulated CiA 402 node per axis (node id = axis number + 1) |
//! | `canopen-udp[:GROUP:PORT]`, `socketcan:IF` | a [`CanBus`] given to [`CanopenLink::open`] | whatever answers |
//!
//! # Start-up
//!
//! NMT reset communication → boot-up of every axis node (bounded wait) → per node: SDO reads of
//! 0x1000 and 0x1018 (identity), the drive file's process data packed into ≤ 4 RPDOs / TPDOs of
//! ≤ 8 bytes ([`pack_layout`]) and written by the CiA 301 remap procedure, unused PDOs disabled,
//! producer heartbeat 0x1017 set → NMT start.
//!
//! # One exchange at `now`
//!
//! Every axis's RPDOs, then SYNC; the nodes step at SYNC and answer with their TPDOs, which are
//! copied into the input images only when every expected TPDO came. A missing TPDO, a node whose
//! heartbeat is older than [`HEARTBEAT_TIMEOUT_FACTOR`] × its period, or a boot-up of an
//! operational node is [`LinkError::Lost`] (the channel reports 900012 and stops the axes).
//! EMCY messages are collected ([`CanopenLink::take_emergencies`]).
//!
//! # Acyclic access
//!
//! SDO upload / download with our sans-IO client ([`SdoClient`]); sizes as for EtherCAT (drive
//! file, CiA 402 table, else 4 bytes). Aborts keep the CiA 301 code.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use super::{decode_le, object_type, Link, LinkError, ProcessImage};
use crate::bus::can::{CanBus, CanFrame};
use crate::bus::canopen::nmt::{self, Emcy, NmtCommand, NmtState};
use crate::bus::canopen::pdo::{pack_layout, Direction, Pdo, MAX_PDOS};
use crate::bus::canopen::sdo::{SdoClient, SdoError};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::model::DriveModel;
use crate::sim::canopen::{CanopenSegment, EmulatedNode};
use crate::sim::plant::Plant;
use crate::units::Nanos;
use std::sync::Arc;

/// A node is lost when its last heartbeat is older than this many periods.
pub const HEARTBEAT_TIMEOUT_FACTOR: u64 = 3;
/// Producer heartbeat period the master configures (0x1017), ms.
pub const HEARTBEAT_MS: u16 = 100;

/// One axis's node.
#[derive(Debug)]
struct AxisNode {
    node: u8,
    def: Arc<DriveDefinition>,
    rx: Vec<Pdo>,
    tx: Vec<Pdo>,
    sdo: SdoClient,
    last_heartbeat: Option<Nanos>,
    state: Option<NmtState>,
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
    /// How long to wait for TPDOs / SDO answers on an external bus.
    pub response_timeout: Duration,
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

/// Where the master's frames go.
enum Transport {
    /// In-process nodes: sending queues for them, receiving returns what they answered.
    Emulated {
        segment: CanopenSegment,
        sent: Vec<CanFrame>,
        received: std::collections::VecDeque<CanFrame>,
    },
    /// A CAN bus.
    Bus(Box<dyn CanBus>),
}

impl Transport {
    fn describe(&self) -> String {
        match self {
            Transport::Emulated { .. } => "in-process emulated nodes".into(),
            Transport::Bus(b) => b.describe(),
        }
    }
}

fn other(m: String) -> LinkError {
    LinkError::Other(m)
}

impl CanopenLink {
    /// `canopen-emu`: one emulated CiA 402 node per drive (node id = position + 1) and the
    /// master, in process; brought to operational.
    pub fn emulated(drives: &[Arc<DriveDefinition>], cycle: Nanos) -> Result<Self, LinkError> {
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
                EmulatedNode::new((i + 1) as u8, d).map_err(|e| other(format!("axis {i}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let bus = Transport::Emulated {
            segment: CanopenSegment::new(nodes, cycle),
            sent: Vec::new(),
            received: Default::default(),
        };
        let ids: Vec<u8> = (1..=drives.len() as u8).collect();
        CanopenLink::start(bus, drives, &ids)
    }

    /// A master on `bus` for nodes `ids` (one per drive), brought to operational.
    pub fn open(
        bus: Box<dyn CanBus>,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
    ) -> Result<Self, LinkError> {
        CanopenLink::start(Transport::Bus(bus), drives, ids)
    }

    fn start(
        bus: Transport,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
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
                let rx = pack_layout(&d.rxpdo, Direction::Rx, node)
                    .map_err(|e| other(format!("node {node}: {e}")))?;
                let tx = pack_layout(&d.txpdo, Direction::Tx, node)
                    .map_err(|e| other(format!("node {node}: {e}")))?;
                Ok(AxisNode {
                    node,
                    def: d.clone(),
                    rx,
                    tx,
                    sdo: SdoClient::new(node),
                    last_heartbeat: None,
                    state: None,
                })
            })
            .collect::<Result<Vec<_>, LinkError>>()?;
        let mut link = CanopenLink {
            bus,
            axes,
            exchanges: 0,
            lose: BTreeSet::new(),
            emergencies: Vec::new(),
            t0: Instant::now(),
            now: Nanos::ZERO,
            response_timeout: Duration::from_millis(500),
        };
        link.boot()?;
        Ok(link)
    }

    /// Wall-clock time since the link opened (SDO timeouts).
    fn wall(&self) -> Nanos {
        Nanos(self.t0.elapsed().as_nanos() as u64)
    }

    fn send(&mut self, f: &CanFrame) -> Result<(), LinkError> {
        match &mut self.bus {
            Transport::Emulated { sent, .. } => {
                sent.push(*f);
                Ok(())
            }
            Transport::Bus(b) => b
                .send(f)
                .map_err(|e| other(format!("CAN send on {}: {e}", b.describe()))),
        }
    }

    /// Emulated: run the nodes on what the master sent since the last run.
    fn run_nodes(&mut self, now: Nanos) {
        if let Transport::Emulated {
            segment,
            sent,
            received,
        } = &mut self.bus
        {
            let frames = std::mem::take(sent);
            received.extend(segment.run(&frames, now));
        }
    }

    /// Take every frame that arrived; `wait` bounds the wait for the first one (bus only).
    fn receive_all(&mut self, wait: Duration) -> Result<Vec<CanFrame>, LinkError> {
        match &mut self.bus {
            Transport::Emulated { received, .. } => Ok(received.drain(..).collect()),
            Transport::Bus(b) => {
                let mut v = Vec::new();
                let mut timeout = wait;
                while let Some(f) = b
                    .recv(timeout)
                    .map_err(|e| other(format!("CAN receive on {}: {e}", b.describe())))?
                {
                    v.push(f);
                    timeout = Duration::ZERO;
                }
                Ok(v)
            }
        }
    }

    /// Common handling of heartbeats and EMCY; returns the frames not consumed.
    fn note(&mut self, frames: Vec<CanFrame>, now: Nanos) -> Result<Vec<CanFrame>, LinkError> {
        let mut rest = Vec::new();
        for f in frames {
            if let Some((node, state)) = nmt::parse_heartbeat(&f) {
                if let Some(ax) = self.axes.iter_mut().find(|a| a.node == node) {
                    if state == NmtState::BootUp && ax.state == Some(NmtState::Operational) {
                        return Err(LinkError::Lost {
                            at: now,
                            reason: format!("node {node} rebooted (boot-up message)"),
                        });
                    }
                    ax.state = Some(state);
                    ax.last_heartbeat = Some(now);
                }
                continue;
            }
            if let Some(e) = Emcy::parse(&f) {
                tracing::debug!(target: "fieldprobe::link::canopen", node = e.node, code = e.code, "EMCY {}", e.text());
                self.emergencies.push(e);
                continue;
            }
            rest.push(f);
        }
        Ok(rest)
    }

    fn boot(&mut self) -> Result<(), LinkError> {
        self.send(&NmtCommand::ResetCommunication.frame(0))?;
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            self.run_nodes(self.now);
            let frames = self.receive_all(Duration::from_millis(20))?;
            self.note(frames, self.now)?;
            if self.axes.iter().all(|a| {
                a.state == Some(NmtState::PreOperational) || a.state == Some(NmtState::BootUp)
            }) {
                break;
            }
            if Instant::now() > deadline {
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
            let mut writes = Vec::new();
            for dir in [Direction::Rx, Direction::Tx] {
                let pdos = match dir {
                    Direction::Rx => self.axes[i].rx.clone(),
                    Direction::Tx => self.axes[i].tx.clone(),
                };
                for p in &pdos {
                    writes.extend(p.remap_writes());
                }
                for k in pdos.len()..MAX_PDOS {
                    let cob = u32::from(dir.default_cob(k as u8, node)) | 0x8000_0000;
                    writes.push((dir.comm_index(k as u8), 1, cob.to_le_bytes().to_vec()));
                }
            }
            writes.push((0x1017, 0, HEARTBEAT_MS.to_le_bytes().to_vec()));
            for (index, sub, data) in writes {
                self.sdo_transfer(i, index, sub, Some(&data))?;
            }
        }
        self.send(&NmtCommand::Start.frame(0))?;
        self.run_nodes(self.now);
        let frames = self.receive_all(Duration::from_millis(20))?;
        self.note(frames, self.now)?;
        for a in &mut self.axes {
            a.state = Some(NmtState::Operational);
            a.last_heartbeat = Some(self.now);
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
        let first = match data {
            None => self.axes[i].sdo.upload(index, sub, wall),
            Some(d) => self.axes[i].sdo.download(index, sub, d, wall),
        };
        for f in &first {
            self.send(f)?;
        }
        let deadline = Instant::now() + self.response_timeout * 4;
        loop {
            if let Some(r) = self.axes[i].sdo.take_result() {
                return r.map_err(|e| match e {
                    SdoError::Abort { code, .. } => LinkError::Abort {
                        device: i,
                        index,
                        sub,
                        code,
                    },
                    other_err => other(format!(
                        "node {node}: SDO {index:#06x}:{sub:02x}: {other_err}"
                    )),
                });
            }
            if Instant::now() > deadline {
                return Err(other(format!(
                    "node {node}: SDO {index:#06x}:{sub:02x}: no answer"
                )));
            }
            self.run_nodes(self.now);
            let frames = self.receive_all(Duration::from_millis(5))?;
            let frames = self.note(frames, self.now)?;
            let wall = self.wall();
            let mut replies = Vec::new();
            for f in &frames {
                replies.extend(self.axes[i].sdo.handle(f, wall));
            }
            replies.extend(self.axes[i].sdo.poll(wall));
            for f in &replies {
                self.send(f)?;
            }
        }
    }

    /// Fault knob: the TPDOs of the `n`-th exchange (0-based) are lost on the bus.
    pub fn lose_exchange_at(&mut self, n: u64) {
        self.lose.insert(n);
    }

    /// Emergencies received so far (drains).
    pub fn take_emergencies(&mut self) -> Vec<Emcy> {
        std::mem::take(&mut self.emergencies)
    }

    /// The emulated nodes (`canopen-emu`).
    pub fn segment(&self) -> Option<&CanopenSegment> {
        match &self.bus {
            Transport::Emulated { segment, .. } => Some(segment),
            Transport::Bus(_) => None,
        }
    }

    /// The emulated nodes, mutable (fault knobs: a node's 0x1017, model faults).
    pub fn segment_mut(&mut self) -> Option<&mut CanopenSegment> {
        match &mut self.bus {
            Transport::Emulated { segment, .. } => Some(segment),
            Transport::Bus(_) => None,
        }
    }
}

impl Link for CanopenLink {
    fn exchange(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Result<(), LinkError> {
        if images.len() != self.axes.len() {
            return Err(LinkError::Mismatch {
                devices: self.axes.len(),
                images: images.len(),
            });
        }
        self.now = now;
        let n = self.exchanges;
        self.exchanges += 1;
        for (ax, img) in self.axes.iter().zip(images.iter()) {
            for p in &ax.rx {
                let data = p.pack(&img.outputs);
                let f = CanFrame::new(p.cob, &data)
                    .map_err(|e| other(format!("node {}: RPDO {}: {e}", ax.node, p.number + 1)))?;
                match &mut self.bus {
                    Transport::Emulated { sent, .. } => sent.push(f),
                    Transport::Bus(b) => b
                        .send(&f)
                        .map_err(|e| other(format!("CAN send on {}: {e}", b.describe())))?,
                }
            }
        }
        self.send(&nmt::sync())?;
        self.run_nodes(now);
        // TPDOs of this SYNC: all of them, or the cycle is lost.
        let expected: usize = self.axes.iter().map(|a| a.tx.len()).sum();
        let mut got: Vec<CanFrame> = Vec::new();
        let deadline = Instant::now() + self.response_timeout;
        loop {
            let frames = self.receive_all(Duration::from_millis(2))?;
            let frames = self.note(frames, now)?;
            got.extend(frames);
            let tpdos = got
                .iter()
                .filter(|f| {
                    self.axes
                        .iter()
                        .any(|a| a.tx.iter().any(|p| u32::from(p.cob) == f.id))
                })
                .count();
            if tpdos >= expected || matches!(self.bus, Transport::Emulated { .. }) {
                break;
            }
            if Instant::now() > deadline {
                break;
            }
        }
        if self.lose.contains(&n) {
            return Err(LinkError::Lost {
                at: now,
                reason: format!("TPDOs lost on the bus (injected at exchange {n})"),
            });
        }
        // Heartbeat consumer.
        for ax in &self.axes {
            let limit = u64::from(HEARTBEAT_MS) * 1_000_000 * HEARTBEAT_TIMEOUT_FACTOR;
            if let Some(t) = ax.last_heartbeat {
                if now.0.saturating_sub(t.0) > limit {
                    return Err(LinkError::Lost {
                        at: now,
                        reason: format!(
                            "node {} heartbeat lost (none for {} ms, period {HEARTBEAT_MS} ms)",
                            ax.node,
                            now.0.saturating_sub(t.0) / 1_000_000
                        ),
                    });
                }
            }
        }
        let mut staged: Vec<Vec<u8>> = images.iter().map(|i| i.inputs.clone()).collect();
        for (ax, inputs) in self.axes.iter().zip(staged.iter_mut()) {
            for p in &ax.tx {
                let f = got
                    .iter()
                    .rev()
                    .find(|f| !f.extended && !f.rtr && f.id == u32::from(p.cob));
                match f {
                    Some(f) if p.unpack(f.payload(), inputs) => {}
                    Some(f) => {
                        return Err(LinkError::Lost {
                            at: now,
                            reason: format!(
                                "node {}: TPDO {} has {} bytes, expected {}",
                                ax.node,
                                p.number + 1,
                                f.len,
                                p.len()
                            ),
                        })
                    }
                    None => {
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
        for (img, inputs) in images.iter_mut().zip(staged) {
            img.inputs = inputs;
        }
        Ok(())
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

    fn plant(&self) -> Option<&Plant> {
        self.segment().map(|s| s.world().plant())
    }

    fn plant_mut(&mut self) -> Option<&mut Plant> {
        self.segment_mut().map(|s| s.world_mut().plant_mut())
    }

    fn model(&self, device: usize) -> Option<&dyn DriveModel> {
        self.segment()?.nodes().get(device).map(|n| n.model())
    }

    fn model_mut(&mut self, device: usize) -> Option<&mut dyn DriveModel> {
        self.segment_mut()?
            .nodes_mut()
            .get_mut(device)
            .map(|n| n.model_mut())
    }

    fn lose_exchange_at(&mut self, n: u64) {
        CanopenLink::lose_exchange_at(self, n);
    }

    fn exchanges(&self) -> u64 {
        self.exchanges
    }
}
