//! Emulated CANopen nodes: a CiA 402 drive model behind a CiA 301 node (NMT slave, heartbeat
//! producer, SDO server, synchronous PDOs, EMCY producer), and [`CanopenSegment`], the nodes of
//! one bus with their [`World`] (probe surfaces, fixed stops).
//!
//! Object dictionary: the CiA 402 objects of [`ds402_objects`] (backed by the drive model), 0x1018
//! identity, 0x1017 producer heartbeat time, and the communication / mapping parameters of 4
//! RPDOs (0x1400.. / 0x1600..) and 4 TPDOs (0x1800.. / 0x1A00..), which start with the drive
//! file's process data packed by [`pack_layout`] and may be rewritten in PRE-OPERATIONAL by the
//! CiA 301 procedure. On NMT start the node reads its PDO parameters and refuses (stays
//! pre-operational, EMCY 0x8200) a mapping its drive model cannot serve.
//!
//! Cycle: RPDOs received while operational are stored; at SYNC the segment steps every
//! operational node's model once with those outputs (one [`World::step`], the same step
//! [`SimLink`](crate::link::sim::SimLink) makes) and then every node sends its TPDOs. So a master
//! that sends its RPDOs, then SYNC, then reads the TPDOs sees the state at the end of the same
//! cycle, as over `--link sim`.

use crate::bus::can::CanFrame;
use crate::bus::canopen::nmt::{self, Emcy, NmtCommand, NmtState};
use crate::bus::canopen::pdo::{pack_layout, Direction, Mapped, Pdo, MAX_PDOS};
use crate::bus::canopen::sdo::{ObjectAccess, SdoServer, SDO_RX_BASE};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::pdo::PdoLayout;
use crate::sim::esc::coe::{ds402_objects, Access, CoeServer, DataType, ObjectEntry};
use crate::sim::world::{Port, World};
use crate::units::Nanos;

/// Vendor ID the emulated nodes report in 0x1018:1 (the EtherCAT emulator's, made up).
pub const VENDOR_ID: u32 = 0x0000_0FB0;
/// Product code the emulated CiA 402 node reports in 0x1018:2.
pub const PRODUCT_CODE: u32 = 0x0002_0402;
/// Default producer heartbeat time (0x1017), ms.
pub const DEFAULT_HEARTBEAT_MS: u16 = 100;

/// The object dictionary as the SDO server sees it: the CoE object table, PDO parameters only
/// writable in pre-operational.
struct Od<'a> {
    od: &'a mut CoeServer,
    state: NmtState,
}

impl ObjectAccess for Od<'_> {
    fn read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        self.od.read(index, sub)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        if (0x1400..0x1C00).contains(&index) && self.state == NmtState::Operational {
            // CiA 301: data cannot be transferred because of the present device state.
            return Err(0x0800_0022);
        }
        self.od.write(index, sub, data)
    }
}

/// One emulated CiA 402 node.
#[derive(Debug)]
pub struct EmulatedNode {
    id: u8,
    state: NmtState,
    od: CoeServer,
    sdo: SdoServer,
    model_rx: PdoLayout,
    model_tx: PdoLayout,
    rx: Vec<Pdo>,
    tx: Vec<Pdo>,
    outputs: Vec<u8>,
    inputs: Vec<u8>,
    last_heartbeat: Option<Nanos>,
    boot_pending: bool,
    last_error: u16,
    outgoing: Vec<CanFrame>,
    syncs: u64,
    sdo_muted: bool,
}

fn u32_entry(index: u16, sub: u8, v: u32) -> ObjectEntry {
    ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, DataType::U32, i64::from(v))
    }
}

fn u8_entry(index: u16, sub: u8, v: u8) -> ObjectEntry {
    ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, DataType::U8, i64::from(v))
    }
}

/// Communication and mapping parameters of `pdos` plus disabled ones up to [`MAX_PDOS`].
fn pdo_entries(direction: Direction, node: u8, pdos: &[Pdo]) -> Vec<ObjectEntry> {
    let mut v = Vec::new();
    for k in 0..MAX_PDOS as u8 {
        let comm = direction.comm_index(k);
        let map = direction.mapping_index(k);
        let pdo = pdos.iter().find(|p| p.number == k);
        let cob =
            u32::from(direction.default_cob(k, node)) | if pdo.is_some() { 0 } else { 0x8000_0000 };
        v.push(ObjectEntry::constant(comm, 0, DataType::U8, 2));
        v.push(u32_entry(comm, 1, cob));
        v.push(u8_entry(comm, 2, 1));
        v.push(u8_entry(map, 0, pdo.map_or(0, |p| p.mapped.len() as u8)));
        for j in 0..8u8 {
            let m = pdo
                .and_then(|p| p.mapped.get(usize::from(j)))
                .map_or(0, Mapped::mapping_value);
            v.push(u32_entry(map, j + 1, m));
        }
    }
    v
}

impl EmulatedNode {
    /// Node `id` (1 … 127) with the drive model of `def` (CiA 402), in boot-up: it sends its
    /// boot-up message and enters pre-operational at the first [`Self::poll`].
    pub fn new(id: u8, def: &DriveDefinition) -> Result<Self, String> {
        if !(1..=127).contains(&id) {
            return Err(format!("node id {id}: allowed 1 … 127"));
        }
        let model = crate::drive::model::for_definition(def).map_err(|e| e.to_string())?;
        let rx = pack_layout(&def.rxpdo, Direction::Rx, id)?;
        let tx = pack_layout(&def.txpdo, Direction::Tx, id)?;
        let mut entries = ds402_objects(&format!("fieldprobe CiA 402 node ({})", def.name));
        entries.extend([
            ObjectEntry::constant(0x1018, 0, DataType::U8, 4),
            ObjectEntry::constant(0x1018, 1, DataType::U32, i64::from(VENDOR_ID)),
            ObjectEntry::constant(0x1018, 2, DataType::U32, i64::from(PRODUCT_CODE)),
            ObjectEntry::constant(0x1018, 3, DataType::U32, 0x0001_0000),
            ObjectEntry::constant(0x1018, 4, DataType::U32, i64::from(id)),
            ObjectEntry {
                access: Access::Rw,
                ..ObjectEntry::constant(0x1017, 0, DataType::U16, i64::from(DEFAULT_HEARTBEAT_MS))
            },
        ]);
        entries.extend(pdo_entries(Direction::Rx, id, &rx));
        entries.extend(pdo_entries(Direction::Tx, id, &tx));
        let (rx_len, tx_len) = (model.rx_len(), model.tx_len());
        Ok(EmulatedNode {
            id,
            state: NmtState::BootUp,
            od: CoeServer::new(model, entries, 0),
            sdo: SdoServer::new(id),
            model_rx: def.rxpdo.clone(),
            model_tx: def.txpdo.clone(),
            rx,
            tx,
            outputs: vec![0; rx_len],
            inputs: vec![0; tx_len],
            last_heartbeat: None,
            boot_pending: true,
            last_error: 0,
            outgoing: Vec::new(),
            syncs: 0,
            sdo_muted: false,
        })
    }

    /// Node id.
    pub fn id(&self) -> u8 {
        self.id
    }

    /// NMT state.
    pub fn state(&self) -> NmtState {
        self.state
    }

    /// The drive model.
    pub fn model(&self) -> &dyn crate::drive::model::DriveModel {
        self.od.model()
    }

    /// The drive model, mutable (fault and plant knobs).
    pub fn model_mut(&mut self) -> &mut dyn crate::drive::model::DriveModel {
        self.od.model_mut()
    }

    /// Fault knob: the producer heartbeat time 0x1017 (0 = no heartbeat, the master's consumer
    /// then reports the node lost).
    pub fn set_heartbeat_ms(&mut self, ms: u16) {
        let _ = self.od.write(0x1017, 0, &ms.to_le_bytes());
    }

    /// Fault knob: ignore SDO requests (the client times out).
    pub fn mute_sdo(&mut self, muted: bool) {
        self.sdo_muted = muted;
    }

    /// SYNC steps made.
    pub fn syncs(&self) -> u64 {
        self.syncs
    }

    /// Read the PDO parameters of `direction` from the object dictionary.
    fn pdos_from_od(&self, direction: Direction, layout: &PdoLayout) -> Result<Vec<Pdo>, String> {
        let num = |index: u16, sub: u8| -> Result<u32, String> {
            let b = self
                .od
                .read(index, sub)
                .map_err(|c| format!("{index:#06x}:{sub:02x} abort {c:#010x}"))?;
            let mut a = [0u8; 4];
            let n = b.len().min(4);
            a[..n].copy_from_slice(&b[..n]);
            Ok(u32::from_le_bytes(a))
        };
        let mut out = Vec::new();
        for k in 0..MAX_PDOS as u8 {
            let cob = num(direction.comm_index(k), 1)?;
            if cob & 0x8000_0000 != 0 {
                continue;
            }
            let map = direction.mapping_index(k);
            let n = num(map, 0)?;
            let mut mapped = Vec::new();
            let mut off = 0;
            for j in 1..=n.min(8) {
                let v = num(map, j as u8)?;
                let (index, sub, bits) = (
                    (v >> 16) as u16,
                    ((v >> 8) & 0xFF) as u8,
                    (v & 0xFF) as usize,
                );
                let e = layout.find(index, sub).ok_or_else(|| {
                    format!(
                        "{map:#06x}:{j:02x}: object {index:#06x}:{sub:02x} is not mappable here"
                    )
                })?;
                if bits != 8 * e.ty.size() {
                    return Err(format!(
                        "{map:#06x}:{j:02x}: {bits} bits, the object has {}",
                        8 * e.ty.size()
                    ));
                }
                mapped.push(Mapped {
                    index,
                    sub,
                    len: bits / 8,
                    pdo_offset: off,
                    image_offset: e.offset,
                });
                off += bits / 8;
            }
            if off > 8 {
                return Err(format!("{map:#06x}: {off} bytes, a PDO carries at most 8"));
            }
            out.push(Pdo {
                direction,
                number: k,
                cob: (cob & 0x7FF) as u16,
                mapped,
            });
        }
        Ok(out)
    }

    fn nmt(&mut self, cmd: NmtCommand) {
        match cmd {
            NmtCommand::Start => {
                let rx = self.pdos_from_od(Direction::Rx, &self.model_rx.clone());
                let tx = self.pdos_from_od(Direction::Tx, &self.model_tx.clone());
                match (rx, tx) {
                    (Ok(rx), Ok(tx)) => {
                        self.rx = rx;
                        self.tx = tx;
                        self.state = NmtState::Operational;
                    }
                    (Err(e), _) | (_, Err(e)) => {
                        tracing::debug!(target: "fieldprobe::sim::canopen", node = self.id, "start refused: {e}");
                        self.emcy(0x8200);
                    }
                }
            }
            NmtCommand::Stop => self.state = NmtState::Stopped,
            NmtCommand::EnterPreOperational => self.state = NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                self.state = NmtState::BootUp;
                self.boot_pending = true;
            }
        }
    }

    fn emcy(&mut self, code: u16) {
        let register = if code == 0 { 0 } else { 0x01 };
        self.outgoing.push(
            Emcy {
                node: self.id,
                code,
                register,
                data: [0; 5],
            }
            .frame(),
        );
    }

    /// Handle one received frame (NMT, SDO, RPDO). Replies are queued for [`Self::take_outgoing`].
    pub fn handle(&mut self, f: &CanFrame, now: Nanos) {
        if f.extended || f.error || f.rtr {
            return;
        }
        let id = f.id as u16;
        if id == nmt::NMT_COB {
            if f.len == 2 && (f.data[1] == 0 || f.data[1] == self.id) {
                if let Some(cmd) = NmtCommand::from_code(f.data[0]) {
                    self.nmt(cmd);
                }
            }
            return;
        }
        if id == SDO_RX_BASE + u16::from(self.id) {
            if self.sdo_muted || self.state == NmtState::Stopped || self.state == NmtState::BootUp {
                return;
            }
            let mut od = Od {
                od: &mut self.od,
                state: self.state,
            };
            let replies = self.sdo.handle(f, &mut od, now);
            self.outgoing.extend(replies);
            return;
        }
        if self.state == NmtState::Operational {
            if let Some(p) = self.rx.iter().find(|p| p.cob == id) {
                if !p.unpack(f.payload(), &mut self.outputs) {
                    self.emcy(0x8210); // PDO not processed due to length error
                }
            }
        }
    }

    /// Time-driven work at `now`: boot-up message, heartbeat, SDO server timeout, EMCY for a new
    /// model fault.
    pub fn poll(&mut self, now: Nanos) {
        if self.boot_pending {
            self.boot_pending = false;
            self.outgoing
                .push(nmt::heartbeat(self.id, NmtState::BootUp));
            self.state = NmtState::PreOperational;
            self.last_heartbeat = Some(now);
        }
        let period = self
            .od
            .read(0x1017, 0)
            .ok()
            .and_then(|b| b.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]])))
            .unwrap_or(0);
        if period > 0 {
            let due = self
                .last_heartbeat
                .is_none_or(|t| now.0.saturating_sub(t.0) >= u64::from(period) * 1_000_000);
            if due {
                self.outgoing.push(nmt::heartbeat(self.id, self.state));
                self.last_heartbeat = Some(now);
            }
        }
        self.outgoing.extend(self.sdo.poll(now));
        let e = self.od.model().last_error_code();
        if e != self.last_error {
            self.last_error = e;
            self.emcy(e);
        }
    }

    /// The TPDOs of the last SYNC step (operational only).
    fn send_tpdos(&mut self) {
        if self.state != NmtState::Operational {
            return;
        }
        for p in &self.tx {
            let data = p.pack(&self.inputs);
            if let Ok(f) = CanFrame::new(p.cob, &data) {
                self.outgoing.push(f);
            }
        }
    }

    /// Frames the node wants to send, in order.
    pub fn take_outgoing(&mut self) -> Vec<CanFrame> {
        std::mem::take(&mut self.outgoing)
    }
}

/// The emulated nodes of one bus and their world.
#[derive(Debug)]
pub struct CanopenSegment {
    nodes: Vec<EmulatedNode>,
    world: World,
    cycle: Nanos,
}

impl CanopenSegment {
    /// Nodes (world device *i* = node *i*) with an empty plant, SYNC period `cycle`.
    pub fn new(nodes: Vec<EmulatedNode>, cycle: Nanos) -> Self {
        CanopenSegment {
            nodes,
            world: World::new(crate::sim::plant::Plant::new()),
            cycle,
        }
    }

    /// The nodes.
    pub fn nodes(&self) -> &[EmulatedNode] {
        &self.nodes
    }

    /// The nodes, mutable.
    pub fn nodes_mut(&mut self) -> &mut [EmulatedNode] {
        &mut self.nodes
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, mutable.
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// Feed the frames the nodes received, run SYNC when one came (world step, then TPDOs),
    /// do the time-driven work at `now`, and return every frame the nodes send, in order.
    pub fn run(&mut self, received: &[CanFrame], now: Nanos) -> Vec<CanFrame> {
        let mut out = Vec::new();
        for f in received {
            if !f.extended && !f.rtr && !f.error && f.id == u32::from(nmt::SYNC_COB) {
                self.sync(now);
            } else {
                for n in &mut self.nodes {
                    n.handle(f, now);
                }
            }
            for n in &mut self.nodes {
                out.extend(n.take_outgoing());
            }
        }
        for n in &mut self.nodes {
            n.poll(now);
            out.extend(n.take_outgoing());
        }
        out
    }

    /// SYNC: step every operational node's model once, then queue the TPDOs.
    fn sync(&mut self, now: Nanos) {
        let mut ports: Vec<Port<'_>> = self
            .nodes
            .iter_mut()
            .map(|n| {
                n.syncs += u64::from(n.state == NmtState::Operational);
                Port {
                    model: n.od.model_mut(),
                    outputs: &n.outputs,
                    inputs: &mut n.inputs,
                }
            })
            .collect();
        self.world.step(now, self.cycle, &mut ports);
        drop(ports);
        for n in &mut self.nodes {
            n.send_tpdos();
        }
    }
}
