//! Emulated CANopen nodes: a CiA 402 drive model behind a CiA 301 node (NMT slave, heartbeat
//! producer, SDO server, synchronous and event-driven PDOs, EMCY producer), and
//! [`CanopenSegment`], the nodes of one bus with their [`World`] (probe surfaces, fixed stops).
//!
//! Object dictionary: the CiA 402 objects of [`ds402_objects`] (backed by the drive model), 0x1018
//! identity, 0x1017 producer heartbeat time, 0x1200 SDO server parameter, 0x1001 error register
//! and 0x1003 pre-defined error field with the EMCYs that go with them ([`errors`]: one EMCY
//! when an error becomes active, EMCY 0x0000 "error reset" when one is gone, e.g. after a
//! fault reset by controlword bit 7), and the communication / mapping parameters of 4
//! RPDOs (0x1400.. / 0x1600..) and 4 TPDOs (0x1800.. / 0x1A00..), which start with the drive
//! file's process data packed by [`pack_layout`] (transmission type 1) — or with an EDS's
//! defaults — and may be rewritten in PRE-OPERATIONAL by the CiA 301 procedure. On NMT start
//! the node reads its PDO parameters and refuses (stays pre-operational, EMCY 0x8200) a
//! mapping it cannot serve. NMT reset communication restores every writable object of the
//! communication area 0x1000 … 0x1FFF to its boot default.
//!
//! [`EmulatedNode::from_eds`] builds the object dictionary from an EDS / DCF instead; its doc
//! lists the rules.
//!
//! # The drive behind the node
//!
//! * **From power-up** the drive has passed CiA 402 transition 1: 0x6041 reads 0x0250 (SWITCH
//!   ON DISABLED, voltage enabled, remote) by SDO before any SYNC, and the first TPDOs carry
//!   the real actual values ([`crate::drive::model::DriveModel::settle`]).
//! * **SDO downloads act at once**: the model gets the value, a controlword moves the CiA 402
//!   state machine there and then (6 → READY TO SWITCH ON, 7 → SWITCHED ON, 0xF → OPERATION
//!   ENABLED, no SYNC needed). A value of the drive's RPDO image (0x6040, 0x607A, 0x60B8 …)
//!   also goes into the image, so it stays until an RPDO brings a new value; a SYNC without
//!   a new RPDO does not overwrite it.
//!
//! # PDO transmission types (CiA 301 §7.2.2, [`pdo`])
//!
//! * RPDO 0 … 240: synchronous; the data are taken over at the next SYNC (the newest before
//!   it wins), for the model step of that SYNC. RPDO 254 / 255: taken over on reception, the
//!   drive acts at once as on an SDO write.
//! * TPDO 1 … 240: every n-th SYNC since NMT start, with the values of the last model step;
//!   TPDO 0: at a SYNC when its data changed since it was last sent; TPDO 254 / 255:
//!   event-driven, checked at every [`EmulatedNode::poll`] — sent at NMT start, whenever its
//!   data differ from the last transmission but not sooner than the inhibit time (sub-index
//!   3, × 100 µs) after it, and when the event-timer (sub-index 5, ms, 0 = off) elapses since
//!   it. 252 / 253 (RTR only) stay silent: the node does not answer remote frames.
//! * A mapped object outside the drive file's process data (e.g. an EDS default mapping of
//!   0x60FF or 0x606C) is served from the object dictionary: an RPDO writes it like an SDO
//!   download, a TPDO reads it when it is sent.
//!
//! Cycle: at SYNC every node first takes over its synchronous RPDOs and sends its
//! synchronous TPDOs (the values its drive sampled at the previous SYNC), then the segment
//! steps every operational node's model once with its RPDO image (one [`World::step`], the
//! same step [`SimLink`](crate::link::sim::SimLink) makes). So a master that sends its RPDOs,
//! then SYNC, then reads the TPDOs sees the actual values one cycle after they were sampled,
//! as over `--link sim` and EtherCAT.
//!
//! # The drive's clock (issue 25)
//!
//! A real drive moves in real time, whatever its SYNC period object says. One SYNC steps the
//! drive models ([`CanopenSegment::sync_step`]):
//! * by **0x1006** communication cycle period when an operational node has it (≠ 0): the
//!   period the master wrote (fieldprobe's master writes the machine cycle);
//! * else by the **time elapsed on the nodes' own clock since the previous SYNC** — the node
//!   of an EDS without 0x1006 (maxon EPOS4, Faulhaber MCBL …), or whose master left it 0,
//!   interpolates each set-point over the real SYNC interval. Bounds: the first SYNC after
//!   NMT start has no previous one and steps by the segment's cycle (`sim canopen`: 1 ms;
//!   the drive is not enabled yet then); a gap longer than [`MAX_SYNC_STEP`] (1 s, a stalled
//!   master) steps by that. The clock is the `model_time` of [`CanopenSegment::receive`]: the
//!   wall clock in `sim canopen`, the SYNC producer's grid on `canopen-emu`, where the elapsed
//!   time is exactly the machine cycle, so that link stays deterministic.
//!
//! # SYNC timing (CiA 301 0x1006, 0x1007)
//!
//! Every node has 0x1006 communication cycle period and 0x1007 synchronous window length (µs,
//! UNSIGNED32, default 0 = not used; read-write in every NMT state; with an EDS only if the EDS
//! has them). NMT reset node / reset communication sets them back to their defaults, as CiA 301
//! says of the communication objects.
//!
//! **SYNC watch.** When 0x1006 ≠ 0, an operational node watches the SYNC on its own clock (the
//! `now` of [`EmulatedNode::poll`]), from the first SYNC after NMT start: no SYNC for longer than
//! [`SYNC_TIMEOUT_PERIODS`] × 0x1006 sends EMCY [`SYNC_TIMEOUT_EMCY`] (0x8100 "communication",
//! error register 0x11 = generic + communication; the code CANopenNode reports for its SYNC
//! time-out, CiA 301 table 21) once per outage, and the CiA 402 drive takes its reaction to the
//! loss of the master at once ("Loss of the master" below; by default FAULT with 0x603F =
//! 0x8100: it stops following its set-points, the position holds) and stays in FAULT until
//! the usual fault reset (controlword bit 7 rising edge). CANopenNode times out at 1.5 × 0x1006; five periods here match fieldprobe's
//! master, which rides through up to three missed deadlines by default (a SYNC gap under 4.5
//! periods) and reports a longer stall as error 900012 ([`crate::link::canopen::paced`]), so
//! the emulated drives stop exactly when the master gives up. On `canopen-emu` the nodes' `now`
//! is the machine's virtual time and a SYNC comes with every exchange, so the watch never fires
//! there.
//!
//! **Synchronous window.** When 0x1007 ≠ 0, RPDOs that arrive later than 0x1007 after the last
//! SYNC are counted ([`EmulatedNode::rpdos_outside_window`]) and still used (CiA 301 allows
//! discarding them; counting keeps the emulator's runs comparable).
//!
//! **RPDO deadline monitoring** (CiA 301: the event-timer, sub-index 5 of the RPDO
//! communication parameter 0x1400 + k, UNSIGNED16 ms, 0 = off). From the first reception of an
//! RPDO in OPERATIONAL, an RPDO that stays away for longer than its event-timer sends EMCY
//! [`RPDO_TIMEOUT_EMCY`] (0x8250 "RPDO time-out", error register generic + communication) once
//! per outage ([`EmulatedNode::rpdo_timeouts`]), and the drive faults like on a SYNC time-out —
//! the communication error reaction of a CiA 402 drive (0x6007 abort connection option code
//! "fault"). This is what catches a master that sends SYNC but no set-points. fieldprobe's
//! master sets the event-timer to five cycles, rounded up to whole ms
//! ([`crate::link::canopen::paced::rpdo_event_timer_ms`]). Reset communication sets it back
//! to 0, as all communication parameters.
//!
//! # Loss of the master (issue 28; CiA 402 0x6007, 0x605E)
//!
//! A SYNC time-out or an RPDO time-out is the loss of the master. The node reacts at once, on
//! its own clock — the `now` of [`EmulatedNode::poll`], which `sim canopen` calls every
//! millisecond whether or not a frame came — without waiting for a SYNC (a crashed master
//! sends none), as its **0x6007 abort connection option code** (INTEGER16, read-write,
//! default 1) says: 0 no action (the EMCY still goes out); 1 fault signal: the drive goes to
//! FAULT now ([`crate::drive::model::DriveModel::fault_now`]; 0x603F = the EMCY code); 2
//! *disable voltage*: SWITCH ON DISABLED; 3 *quick stop*: QUICK STOP ACTIVE; manufacturer
//! codes (< 0) and reserved ones fault as 1. The RPDO image gets the reaction's controlword,
//! so a late SYNC with stale data does not enable the drive again. **0x605E fault reaction
//! option code** (INTEGER16, default 2) is kept for the master to read and write; the model's
//! drive holds its position at once whatever it says (it has no ramp model). The reaction time
//! is the detection time — more than 5 × 0x1006 since the last SYNC, or more than the
//! event-timer since the last RPDO — plus at most one poll. Heartbeat consumer (0x1016) is not
//! implemented: fieldprobe's master produces no heartbeat, the SYNC and RPDO watches cover it.
//! The node also takes the 0x6007 reaction when it leaves OPERATIONAL (NMT stop, enter
//! pre-operational, reset communication) while its drive is still OPERATION ENABLED: no PDO
//! brings set-points any more (a master that dies between its NMT command and the disable, or
//! one that never disables); a master that disables first (fieldprobe's end of a run) sees no
//! reaction. (CiA 402's list of abort connection events is not quoted here: unverified.)
//!
//! # NMT reset (CiA 301 §7.3.2.2.1)
//!
//! **Reset node** restarts the application: a new drive model with its power-on values (SWITCH
//! ON DISABLED 0x0250, no fault, 0x6007 / 0x605E and every model object at their defaults, the
//! axis where it stands), the writable application objects (0x2000 …) back to their boot
//! values, the error history cleared — then reset communication. **Reset communication**
//! restores the communication area 0x1000 … 0x1FFF (PDOs, 0x1006, 0x1007, 0x1017 …), ends an
//! SDO transfer in progress and sends the boot-up message; the application (the drive's state
//! and objects) stays as it is.

use crate::bus::can::CanFrame;
use std::collections::BTreeMap;

use self::pdo::{NodePdo, PdoData, Place, Slot, Transmission};
use crate::bus::canopen::eds::{self, AccessType, Eds};
use crate::bus::canopen::nmt::{self, Emcy, NmtCommand, NmtState};
use crate::bus::canopen::pdo::{
    check_pdo_cob_id, pack_layout, Direction, Mapped, Pdo, ALLOWED_PDO_CAN_IDS, MAX_PDOS,
};
use crate::bus::canopen::sdo::{ObjectAccess, SdoServer, SDO_RX_BASE};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::pdo::{is_touch_probe, PdoLayout};
use crate::sim::esc::coe::{ds402_objects, Access, CoeServer, DataType, ObjectEntry};
use crate::sim::world::{Port, PortBuffer, World};
use crate::units::Nanos;

pub mod errors;
pub mod pdo;
pub mod rules;

use self::errors::NodeErrors;
use self::rules::NodeRules;

/// Vendor ID the emulated nodes report in 0x1018:1 (the EtherCAT emulator's, made up).
pub const VENDOR_ID: u32 = 0x0000_0FB0;
/// Product code the emulated CiA 402 node reports in 0x1018:2.
pub const PRODUCT_CODE: u32 = 0x0002_0402;
/// Default producer heartbeat time (0x1017), ms.
pub const DEFAULT_HEARTBEAT_MS: u16 = 100;
/// EMCY / 0x603F code of the abort connection fault when the node leaves OPERATIONAL with its
/// drive enabled: 0x8100 "communication" (CiA 301 Table 21).
pub const LEFT_OPERATIONAL_EMCY: u16 = 0x8100;
/// Default 0x6007 abort connection option code: 1 = fault signal (CiA 402 §8.4.1 default).
pub const ABORT_CONNECTION_DEFAULT: i16 = 1;
/// Default 0x605E fault reaction option code: 2 = slow down on quick stop ramp (CiA 402
/// default). The model's drive holds its position at once whatever it says.
pub const FAULT_REACTION_DEFAULT: i16 = 2;
/// Controlword *disable voltage* (CiA 402 §6.3).
const CONTROLWORD_DISABLE_VOLTAGE: u16 = 0x0000;
/// Controlword *quick stop* (CiA 402 §6.3).
const CONTROLWORD_QUICK_STOP: u16 = 0x0002;
/// The SYNC watch fires after more than this many communication cycle periods (0x1006)
/// without a SYNC (the tolerance the master assumes too).
pub use crate::bus::canopen::nmt::SYNC_TIMEOUT_PERIODS;
/// EMCY error code of a SYNC time-out: 0x8100 "communication" (CiA 301 table 21).
pub const SYNC_TIMEOUT_EMCY: u16 = 0x8100;
/// EMCY error code of an RPDO deadline time-out (CiA 301 "RPDO time-out").
pub const RPDO_TIMEOUT_EMCY: u16 = 0x8250;
/// EMCY error code of an RPDO whose length is not its mapping's (CiA 301 table 21).
pub const PDO_LENGTH_EMCY: u16 = 0x8210;
/// EMCY error code of a refused NMT start (a PDO mapping the node cannot serve): 0x8200
/// "protocol error".
pub const START_REFUSED_EMCY: u16 = 0x8200;
/// SDO abort 0x0800_0024 "no data available": a sub-index of 0x1003 beyond the errors
/// recorded.
pub const NO_DATA: u32 = 0x0800_0024;
/// Capacity (bytes) of a VISIBLE_STRING / OCTET_STRING / UNICODE_STRING / DOMAIN object built
/// from an EDS entry whose default is shorter ([`EmulatedNode::from_eds`]).
pub const EDS_STRING_CAPACITY: usize = 256;

/// The object dictionary as the SDO server sees it: the CoE object table, PDO parameters only
/// writable in pre-operational. A write to an object of the drive model's RPDO image also goes
/// into the image, so the next SYNC step keeps it until an RPDO brings a new value.
struct Od<'a> {
    od: &'a mut CoeServer,
    state: NmtState,
    /// Objects stored as byte strings that have one fixed length (EDS types the CoE table has
    /// no numeric type for: INTEGER24, REAL32, TIME_OF_DAY …).
    fixed_len: &'a BTreeMap<(u16, u8), usize>,
    /// The drive model's RPDO layout and image, and its TPDO layout.
    rx_layout: &'a PdoLayout,
    outputs: &'a mut [u8],
    tx_layout: &'a PdoLayout,
    /// Value ranges and the PDO configuration procedure ([`rules`]).
    rules: &'a NodeRules,
    /// A download succeeded (the node refreshes its TPDO image).
    wrote: bool,
    /// The controlword 0x6040 was written (the drive acts on it at once).
    wrote_controlword: bool,
    /// 0 was written to 0x1003 sub-index 0: the node deletes its error history.
    clear_history: bool,
}

impl ObjectAccess for Od<'_> {
    fn read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        let value = self.od.read(index, sub)?;
        if index == 0x1003 && sub > 0 {
            // CiA 301 §7.5.2.3: sub-index 0 tells how many errors are recorded; a sub-index
            // of the field beyond them holds none (CANopenNode answers the same).
            let n = self.od.read_with(0x1003, 0, |b| b.first().copied())?;
            if n.is_some_and(|n| sub > n) {
                return Err(NO_DATA);
            }
        }
        Ok(value)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        if (index, sub) == (0x1003, 0) && self.od.read(0x1003, 0).is_ok() {
            // CiA 301 §7.5.2.3: writing 0 deletes the error history; any other value is
            // refused.
            return match data {
                [0] => {
                    self.clear_history = true;
                    Ok(())
                }
                [_] => Err(rules::INVALID_VALUE),
                _ => Err(0x0607_0010),
            };
        }
        if (0x1400..0x1C00).contains(&index) && self.state == NmtState::Operational {
            // CiA 301: data cannot be transferred because of the present device state.
            return Err(0x0800_0022);
        }
        if let Some(&n) = self.fixed_len.get(&(index, sub)) {
            if data.len() != n {
                // CiA 301: data type does not match, length of service parameter does not match.
                return Err(0x0607_0010);
            }
        }
        self.rules.check(
            self.od,
            (self.rx_layout, self.tx_layout),
            self.fixed_len,
            (index, sub),
            data,
        )?;
        self.od.write(index, sub, data)?;
        self.wrote = true;
        self.wrote_controlword |= (index, sub) == (0x6040, 0);
        if let Some(e) = self.rx_layout.find(index, sub) {
            if let Ok(v) = self.od.model().read_object(index, sub) {
                let _ = e.write(self.outputs, e.ty.saturate(v));
            }
        }
        Ok(())
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
    /// The valid RPDOs / TPDOs as read at NMT start.
    rx: Vec<NodePdo>,
    tx: Vec<NodePdo>,
    outputs: Vec<u8>,
    inputs: Vec<u8>,
    last_heartbeat: Option<Nanos>,
    boot_pending: bool,
    /// Active errors, the error register 0x1001 and the history 0x1003 ([`errors`]).
    errors: NodeErrors,
    /// An RPDO came with a length its mapping does not have (EMCY 0x8210), and no RPDO of
    /// the right length since.
    pdo_length_error: bool,
    /// The last NMT start was refused (EMCY 0x8200): a mapping the node cannot serve.
    start_refused: bool,
    outgoing: Vec<CanFrame>,
    syncs: u64,
    sdo_muted: bool,
    /// Fault knob [`Self::flood_emcy`]: (code, period, last sent).
    emcy_flood: Option<(u16, Nanos, Option<Nanos>)>,
    fixed_len: BTreeMap<(u16, u8), usize>,
    /// Value ranges and the PDO configuration procedure of SDO downloads ([`rules`]).
    rules: NodeRules,
    /// The drive model has a touch probe (its RPDO layout maps 0x60B8).
    touch_probe: bool,
    /// The SYNC watch: when the last SYNC came (operational, armed by the first SYNC).
    last_sync: Option<Nanos>,
    /// The watch fired and no SYNC came since.
    sync_lost: bool,
    sync_timeouts: u64,
    rpdos_outside_window: u64,
    /// RPDO deadline monitoring: when RPDO k last came (operational, armed by its first
    /// reception), and whether its time-out fired since.
    rpdo_seen: [Option<Nanos>; MAX_PDOS],
    rpdo_lost: [bool; MAX_PDOS],
    rpdo_timeouts: u64,
    /// The writable objects of the communication area 0x1000 … 0x1FFF as built (0x1006,
    /// 0x1007, 0x1017, the PDO parameters …), restored by NMT reset communication:
    /// (index, sub-index, value).
    comm_defaults: Vec<(u16, u8, Vec<u8>)>,
    /// The writable objects of the application area (0x2000 … 0xFFFF) that the drive model
    /// does not back, as built; restored with a new drive model by NMT reset node.
    app_defaults: Vec<(u16, u8, Vec<u8>)>,
    /// The drive definition, for the power-on drive model of NMT reset node.
    def: DriveDefinition,
    /// When the node last reacted to the loss of its master (SYNC or RPDO time-out).
    master_lost_at: Option<Nanos>,
}

fn u32_entry(index: u16, sub: u8, v: u32) -> ObjectEntry {
    ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, DataType::U32, i64::from(v))
    }
}

fn u16_entry(index: u16, sub: u8, v: u16) -> ObjectEntry {
    ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, DataType::U16, i64::from(v))
    }
}

fn i16_entry(index: u16, sub: u8, v: i16) -> ObjectEntry {
    ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, DataType::I16, i64::from(v))
    }
}

fn u8_entry(index: u16, sub: u8, v: u8) -> ObjectEntry {
    ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, DataType::U8, i64::from(v))
    }
}

/// The error objects of CiA 301: 0x1001 error register (UNSIGNED8, read-only, mandatory) and,
/// with a `history` capacity > 0, 0x1003 pre-defined error field (sub-index 0 UNSIGNED8
/// read-write: the number of errors recorded; sub-indices 1 … `history` UNSIGNED32
/// read-only). The node keeps their values ([`EmulatedNode::poll`], [`errors`]).
fn error_objects(history: u8) -> Vec<ObjectEntry> {
    let mut v = vec![ObjectEntry::constant(0x1001, 0, DataType::U8, 0)];
    if history > 0 {
        v.push(u8_entry(0x1003, 0, 0));
        v.extend((1..=history).map(|k| ObjectEntry::constant(0x1003, k, DataType::U32, 0)));
    }
    v
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
        // Sub-indices 1 COB-ID, 2 transmission type, 3 inhibit time (100 µs), 5 event-timer
        // (ms; for an RPDO the deadline monitoring); 4 is reserved (CiA 301).
        v.push(ObjectEntry::constant(comm, 0, DataType::U8, 5));
        v.push(u32_entry(comm, 1, cob));
        v.push(u8_entry(comm, 2, 1));
        v.push(u16_entry(comm, 3, 0));
        v.push(u16_entry(comm, 5, 0));
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

/// Up to 4 little-endian bytes as a number (missing high bytes 0).
fn le_u32(b: &[u8]) -> u32 {
    let mut a = [0u8; 4];
    let n = b.len().min(4);
    a[..n].copy_from_slice(&b[..n]);
    u32::from_le_bytes(a)
}

fn check_node_id(id: u8) -> Result<(), String> {
    if (1..=127).contains(&id) {
        Ok(())
    } else {
        Err(format!("node id {id}: allowed 1 … 127"))
    }
}

/// One EDS entry as an object table entry, and its fixed length if it is stored as raw bytes
/// of one size (see [`EmulatedNode::from_eds`]).
fn eds_object(e: &eds::Entry, node: u8) -> Result<(ObjectEntry, Option<usize>), String> {
    use eds::DataType as T;
    let access = match e.access {
        AccessType::ReadOnly | AccessType::Const => Access::Ro,
        AccessType::WriteOnly => Access::Wo,
        AccessType::ReadWrite | AccessType::ReadWriteInput | AccessType::ReadWriteOutput => {
            Access::Rw
        }
    };
    // A value the lenient EDS reader could not read (it warned) is no value: zero / empty,
    // as for an entry without one.
    let value = e.value_bytes(node);
    let numeric = match e.data_type {
        T::Boolean => Some(DataType::Bool),
        T::Integer8 => Some(DataType::I8),
        T::Integer16 => Some(DataType::I16),
        T::Integer32 => Some(DataType::I32),
        T::Integer64 => Some(DataType::I64),
        T::Unsigned8 => Some(DataType::U8),
        T::Unsigned16 => Some(DataType::U16),
        T::Unsigned32 => Some(DataType::U32),
        T::Unsigned64 => Some(DataType::U64),
        _ => None,
    };
    let (ty, data, fixed) = match (numeric, e.data_type.size()) {
        (Some(ty), _) => {
            let n = ty.size().unwrap_or(1);
            (ty, value.unwrap_or_else(|| vec![0; n]), None)
        }
        (None, Some(n)) => (
            DataType::Bytes(n),
            value.unwrap_or_else(|| vec![0; n]),
            Some(n),
        ),
        (None, None) => {
            let v = value.unwrap_or_default();
            (DataType::Bytes(v.len().max(EDS_STRING_CAPACITY)), v, None)
        }
    };
    if let Some(n) = ty.size().or(fixed) {
        if data.len() != n {
            return Err(format!("value has {} bytes, the type {n}", data.len()));
        }
    }
    Ok((
        ObjectEntry {
            index: e.index,
            sub: e.sub,
            ty,
            access,
            data: Some(data),
        },
        fixed,
    ))
}

/// The drive definition a node built from `eds` runs its model with: `def` without the
/// touch-probe objects ([`is_touch_probe`]) the EDS cannot map in that direction — all of them
/// when 0x60B8 (RPDO) or 0x60B9 (TPDO) is missing, as the latch needs both. Other objects stay
/// as `def` has them (an EDS without a CiA 402 object still gets the model's value in the
/// drive file's process data; no master can map what the EDS lacks).
pub fn eds_model_definition(eds: &Eds, def: &DriveDefinition) -> DriveDefinition {
    let maps = |index: u16, sub: u8, rx: bool| {
        eds.get(index, sub).is_some_and(|e| {
            let (r, t) = e.pdo_directions();
            if rx {
                r
            } else {
                t
            }
        })
    };
    let latch = maps(0x60B8, 0, true) && maps(0x60B9, 0, false);
    let drop = |rx: bool| {
        move |index: u16, sub: u8| is_touch_probe(index) && !(latch && maps(index, sub, rx))
    };
    let mut out = def.clone();
    out.rxpdo = def.rxpdo.without(drop(true));
    out.txpdo = def.txpdo.without(drop(false));
    let rx = out.rxpdo.clone();
    out.rxpdo_defaults.retain(|d| rx.contains(d.index, d.sub));
    out
}

impl EmulatedNode {
    /// Node `id` (1 … 127) with the drive model of `def` (CiA 402), in boot-up: it sends its
    /// boot-up message and enters pre-operational at the first [`Self::poll`].
    pub fn new(id: u8, def: &DriveDefinition) -> Result<Self, String> {
        check_node_id(id)?;
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
            // CiA 301 communication cycle period and synchronous window length, µs (0 = none).
            u32_entry(0x1006, 0, 0),
            u32_entry(0x1007, 0, 0),
            // CiA 402 abort connection option code and fault reaction option code (module
            // documentation, "Loss of the master").
            i16_entry(0x6007, 0, ABORT_CONNECTION_DEFAULT),
            i16_entry(0x605E, 0, FAULT_REACTION_DEFAULT),
            // CiA 301 §7.5.2.33 SDO server parameter of the default SDO (read-only): COB-IDs
            // client → server and server → client.
            ObjectEntry::constant(0x1200, 0, DataType::U8, 2),
            ObjectEntry::constant(
                0x1200,
                1,
                DataType::U32,
                i64::from(SDO_RX_BASE) + i64::from(id),
            ),
            ObjectEntry::constant(0x1200, 2, DataType::U32, 0x580 + i64::from(id)),
        ]);
        entries.extend(error_objects(errors::DEFAULT_HISTORY));
        Self::build(id, def, entries, BTreeMap::new(), NodeRules::default())
    }

    /// Node `id` with the drive model of `def` and the object dictionary of an EDS / DCF
    /// (CiA 306), in boot-up like [`Self::new`].
    ///
    /// Rules:
    /// * Every EDS entry (every sub-index, compact storage expanded) becomes an object with the
    ///   EDS access (`ro`/`const` → read-only, `wo` → write-only, `rw`/`rwr`/`rww` →
    ///   read-write) and the EDS value evaluated for `id` (`$NODEID`): `ParameterValue` (DCF)
    ///   if present, else `DefaultValue`, else zero / empty — as the lenient EDS reader reads
    ///   it ([`eds`]: a value beyond its type saturates or keeps its bit pattern; one that
    ///   does not read at all, e.g. of a complex data type, counts as none).
    /// * Data types: BOOLEAN, INTEGER8/16/32/64 and UNSIGNED8/16/32/64 are numeric objects
    ///   (a download must have exactly the type's size, else abort 0x0607_0010). Other
    ///   fixed-size types (INTEGER24/40/48/56, UNSIGNED24/40/48/56, REAL32/64, TIME_OF_DAY,
    ///   TIME_DIFFERENCE) are stored as raw bytes of that size, with the same length check.
    ///   VISIBLE_STRING, OCTET_STRING, UNICODE_STRING, DOMAIN and the complex / manufacturer
    ///   types are byte strings holding up to max(default length, [`EDS_STRING_CAPACITY`])
    ///   bytes.
    /// * Value ranges: a download of a numeric object outside the EDS's `LowLimit` /
    ///   `HighLimit` is refused (0x0609_0032 / 0x0609_0031, [`rules`]).
    /// * PDO mapping: only objects with `PDOMapping=1` whose `AccessType` allows the
    ///   direction go into a PDO; the CiA 301 remap procedure and its abort codes are those of
    ///   [`rules`] (a non-mappable object 0x0604_0041, an object the EDS lacks 0x0602_0000, an
    ///   entry written while sub-index 0 ≠ 0 or the PDO exists 0x0609_0030, more than 64 bits
    ///   0x0604_0042).
    /// * The drive model is `def`'s with its touch probe only where the EDS has one
    ///   ([`eds_model_definition`]): without 0x60B8 mappable into an RPDO and 0x60B9 into a
    ///   TPDO the node has no touch probe, and the touch-probe objects leave the model's
    ///   process data.
    /// * Objects the drive model implements (the model-backed entries of [`ds402_objects`]:
    ///   0x6040, 0x6041, 0x6060/61, 0x6064, 0x6065/66/67, 0x606C, 0x6072, 0x6077, 0x607A,
    ///   0x60B8..=0x60BD, 0x60D0, 0x60E0/E1, 0x60F4, 0x6502, 0x603F) stay backed by the model
    ///   when the EDS has them, with the model's data type and access (the EDS default is not
    ///   written to the model); model objects the EDS lacks are not in the dictionary (SDO
    ///   abort 0x0602_0000), although the drive file's process data still carries them.
    /// * 0x1001 error register and 0x1003 pre-defined error field are the node's own
    ///   ([`errors`]): 0x1001 always (CiA 301 mandatory), 0x1003 when the EDS has it, with as
    ///   many entries as the EDS's highest sub-index of 0x1003.
    /// * 0x1018 identity from the EDS: subs 1 … 3 from [`Eds::identity`] (the sub's value,
    ///   else `[DeviceInfo]` VendorNumber / ProductNumber / RevisionNumber, else 0), sub 4
    ///   from the EDS, else the node id. Always read-only, sub 0 = 4.
    /// * 0x1000 device type: the EDS value; if the EDS lacks 0x1000 (CiA 301 mandatory), the
    ///   built-in one (0x00020192).
    /// * 0x1017 producer heartbeat time: the EDS value (often 0 = no heartbeat until the master
    ///   writes it); if the EDS lacks 0x1017, [`DEFAULT_HEARTBEAT_MS`].
    /// * PDO parameters: when the EDS has any object in 0x1400..=0x1BFF, the communication
    ///   (0x1400 + k, 0x1800 + k: COB-ID with `$NODEID`, transmission type, inhibit time,
    ///   event-timer) and mapping parameters (0x1600 + k, 0x1A00 + k) of PDOs 1 … 4 (k < 4)
    ///   are the EDS's, with the sub-indices the EDS lists (a missing inhibit time or
    ///   event-timer counts as 0, a missing transmission type as 255); PDOs 5 and up are left
    ///   out (the node serves the predefined connection set, SDO abort 0x0602_0000). An EDS
    ///   without PDO objects gets the built-in ones of [`Self::new`] (the drive file's process
    ///   data packed by [`pack_layout`], transmission type 1). A mapping whose objects the node
    ///   cannot serve is refused at NMT start, not here.
    /// * These EDS values are the node's boot defaults: NMT reset communication restores every
    ///   writable object of the communication area 0x1000 … 0x1FFF to them.
    pub fn from_eds(id: u8, def: &DriveDefinition, eds: &Eds) -> Result<Self, String> {
        check_node_id(id)?;
        let def = &eds_model_definition(eds, def);
        let builtin = ds402_objects(&format!("fieldprobe CiA 402 node ({})", def.name));
        let model_backed: BTreeMap<(u16, u8), &ObjectEntry> = builtin
            .iter()
            .filter(|e| e.data.is_none())
            .map(|e| ((e.index, e.sub), e))
            .collect();
        let mut entries = Vec::new();
        let mut fixed_len = BTreeMap::new();
        for (&(index, sub), e) in &eds.objects {
            // PDOs 5 and up (number = index & 0x1FF in each of the four parameter ranges).
            let beyond =
                (0x1400..0x1C00).contains(&index) && usize::from(index & 0x1FF) >= MAX_PDOS;
            // 0x1001 / 0x1003 are the node's own (its error state), with the EDS's size of
            // 0x1003.
            if beyond || matches!(index, 0x1018 | 0x1001 | 0x1003) {
                continue;
            }
            // A PDO COB-ID the node would send or listen on must not be a restricted CAN-ID
            // (CiA 301 §7.3.5): a TPDO on 0x000 would be an NMT command to every node.
            let comm = (0x1400..=0x15FF).contains(&index) || (0x1800..=0x19FF).contains(&index);
            if comm && sub == 1 {
                let cob = e
                    .value(id)
                    .and_then(|v| v.as_u64())
                    .and_then(|v| u32::try_from(v).ok());
                if let Some(Err(why)) = cob.map(check_pdo_cob_id) {
                    return Err(format!(
                        "EDS {}: object {index:#06x}:01 ({}, section at line {}): {why}; a \
                         valid PDO takes a CAN-ID in {ALLOWED_PDO_CAN_IDS} (bit 31 set: PDO \
                         not valid)",
                        eds.file, e.parameter_name, e.line
                    ));
                }
            }
            if let Some(m) = model_backed.get(&(index, sub)) {
                entries.push((*m).clone());
                continue;
            }
            let (entry, fixed) = eds_object(e, id).map_err(|why| {
                format!(
                    "EDS {}: object {index:#06x}:{sub:02x} ({}, section at line {}): {why}",
                    eds.file, e.parameter_name, e.line
                )
            })?;
            if let Some(n) = fixed {
                fixed_len.insert((index, sub), n);
            }
            entries.push(entry);
        }
        let has = |index: u16| {
            eds.objects
                .range((index, 0)..=(index, u8::MAX))
                .next()
                .is_some()
        };
        if !has(0x1000) {
            entries.extend(builtin.iter().filter(|e| e.index == 0x1000).cloned());
        }
        if !has(0x1017) {
            entries.push(ObjectEntry {
                access: Access::Rw,
                ..ObjectEntry::constant(0x1017, 0, DataType::U16, i64::from(DEFAULT_HEARTBEAT_MS))
            });
        }
        let history = eds
            .objects
            .range((0x1003, 1)..=(0x1003, u8::MAX))
            .map(|(&(_, sub), _)| sub)
            .max()
            .unwrap_or(0)
            .min(254);
        entries.extend(error_objects(history));
        let ident = eds.identity();
        let serial = eds
            .get(0x1018, 4)
            .and_then(|e| e.value(id))
            .and_then(|v| v.as_u64())
            .and_then(|v| u32::try_from(v).ok())
            .unwrap_or(u32::from(id));
        entries.extend([
            ObjectEntry::constant(0x1018, 0, DataType::U8, 4),
            ObjectEntry::constant(
                0x1018,
                1,
                DataType::U32,
                i64::from(ident.vendor_id.unwrap_or(0)),
            ),
            ObjectEntry::constant(
                0x1018,
                2,
                DataType::U32,
                i64::from(ident.product_code.unwrap_or(0)),
            ),
            ObjectEntry::constant(
                0x1018,
                3,
                DataType::U32,
                i64::from(ident.revision_number.unwrap_or(0)),
            ),
            ObjectEntry::constant(0x1018, 4, DataType::U32, i64::from(serial)),
        ]);
        Self::build(id, def, entries, fixed_len, NodeRules::from_eds(eds, id))
    }

    /// The node around an object table; without PDO parameters in the table, it adds the
    /// built-in ones (the drive file's process data packed by [`pack_layout`]).
    ///
    /// The drive is powered up here: it passes CiA 402 transition 1 (SWITCH ON DISABLED,
    /// statusword 0x0250), its RPDO image holds the model's values and its TPDO image the
    /// actual values, so SDO reads and the first TPDOs are valid before any SYNC.
    fn build(
        id: u8,
        def: &DriveDefinition,
        mut entries: Vec<ObjectEntry>,
        fixed_len: BTreeMap<(u16, u8), usize>,
        rules: NodeRules,
    ) -> Result<Self, String> {
        let mut model = crate::drive::model::for_definition(def).map_err(|e| e.to_string())?;
        if !entries.iter().any(|e| (0x1400..0x1C00).contains(&e.index)) {
            let rx = pack_layout(&def.rxpdo, Direction::Rx, id)?;
            let tx = pack_layout(&def.txpdo, Direction::Tx, id)?;
            entries.extend(pdo_entries(Direction::Rx, id, &rx));
            entries.extend(pdo_entries(Direction::Tx, id, &tx));
        }
        model.settle();
        let mut outputs = vec![0; model.rx_len()];
        for e in def.rxpdo.entries() {
            if let Ok(v) = model.read_object(e.index, e.sub) {
                let _ = e.write(&mut outputs, e.ty.saturate(v));
            }
        }
        let mut inputs = vec![0; model.tx_len()];
        model.finish_step(&mut inputs);
        let od = CoeServer::new(model, entries, 0);
        let history = od
            .entries()
            .iter()
            .filter(|e| e.index == 0x1003 && e.sub > 0)
            .count()
            .min(254) as u8;
        // 0x1003:00 is the error state, not a communication parameter.
        let comm_defaults = od
            .entries()
            .iter()
            .filter(|e| (0x1000..0x2000).contains(&e.index) && e.access != Access::Ro)
            .filter(|e| e.index != 0x1003)
            .filter_map(|e| Some((e.index, e.sub, e.data.clone()?)))
            .collect();
        let app_defaults = od
            .entries()
            .iter()
            .filter(|e| e.index >= 0x2000 && e.access != Access::Ro)
            .filter_map(|e| Some((e.index, e.sub, e.data.clone()?)))
            .collect();
        Ok(EmulatedNode {
            id,
            state: NmtState::BootUp,
            od,
            sdo: SdoServer::new(id),
            model_rx: def.rxpdo.clone(),
            model_tx: def.txpdo.clone(),
            rx: Vec::new(),
            tx: Vec::new(),
            outputs,
            inputs,
            last_heartbeat: None,
            boot_pending: true,
            errors: NodeErrors::new(history),
            pdo_length_error: false,
            start_refused: false,
            outgoing: Vec::new(),
            syncs: 0,
            sdo_muted: false,
            emcy_flood: None,
            fixed_len,
            rules,
            touch_probe: def.rxpdo.contains(0x60B8, 0),
            last_sync: None,
            sync_lost: false,
            sync_timeouts: 0,
            rpdos_outside_window: 0,
            rpdo_seen: [None; MAX_PDOS],
            rpdo_lost: [false; MAX_PDOS],
            rpdo_timeouts: 0,
            comm_defaults,
            app_defaults,
            def: def.clone(),
            master_lost_at: None,
        })
    }

    /// A UNSIGNED32 object of the dictionary (0 when absent or refused).
    fn read_u32(&self, index: u16) -> u32 {
        self.od.read_with(index, 0, le_u32).unwrap_or(0)
    }

    /// A UNSIGNED16 object (0 when absent or refused), read without a copy.
    fn read_u16(&self, index: u16, sub: u8) -> u16 {
        self.od
            .read_with(index, sub, |b| le_u32(b) as u16)
            .unwrap_or(0)
    }

    /// 0x1006 communication cycle period in µs, if set (≠ 0).
    pub fn cycle_period_us(&self) -> Option<u32> {
        Some(self.read_u32(0x1006)).filter(|&us| us != 0)
    }

    /// SYNC time-outs so far (each sent EMCY [`SYNC_TIMEOUT_EMCY`] and faulted the drive).
    pub fn sync_timeouts(&self) -> u64 {
        self.sync_timeouts
    }

    /// RPDO deadline time-outs so far (each sent EMCY [`RPDO_TIMEOUT_EMCY`] and faulted the
    /// drive).
    pub fn rpdo_timeouts(&self) -> u64 {
        self.rpdo_timeouts
    }

    /// RPDOs that arrived later than 0x1007 after the last SYNC (0x1007 ≠ 0).
    pub fn rpdos_outside_window(&self) -> u64 {
        self.rpdos_outside_window
    }

    /// A SYNC reached the node at `now`: the synchronous RPDOs received since the last one
    /// are taken over (CiA 301 §7.2.2.2), for the model step that follows.
    fn on_sync(&mut self, now: Nanos) {
        if self.state == NmtState::Operational {
            self.last_sync = Some(now);
            self.sync_lost = false;
            for i in 0..self.rx.len() {
                if let Some(data) = self.rx[i].take_pending() {
                    self.take_over_rpdo(i, data.as_slice(), false);
                }
            }
        }
    }

    /// The SYNC watch (module documentation), at `now`.
    fn watch_sync(&mut self, now: Nanos) {
        if self.state != NmtState::Operational || self.sync_lost {
            return;
        }
        let (Some(last), Some(us)) = (self.last_sync, self.cycle_period_us()) else {
            return;
        };
        let limit = u64::from(us) * 1000 * SYNC_TIMEOUT_PERIODS;
        if now.0.saturating_sub(last.0) <= limit {
            return;
        }
        self.sync_lost = true;
        self.sync_timeouts += 1;
        tracing::warn!(target: "fieldprobe::sim::canopen", node = self.id,
            "no SYNC for {} µs (0x1006 = {us} µs): EMCY 0x8100, drive fault",
            now.0.saturating_sub(last.0) / 1000);
        self.lose_master(SYNC_TIMEOUT_EMCY, now);
    }

    /// 0x6007 abort connection option code (INTEGER16; [`ABORT_CONNECTION_DEFAULT`] when the
    /// dictionary lacks it, e.g. an EDS without it).
    pub fn abort_connection_option(&self) -> i16 {
        self.od
            .read_with(0x6007, 0, |b| match b {
                [lo, hi, ..] => i16::from_le_bytes([*lo, *hi]),
                _ => ABORT_CONNECTION_DEFAULT,
            })
            .unwrap_or(ABORT_CONNECTION_DEFAULT)
    }

    /// When the node last reacted to the loss of its master (a SYNC or RPDO time-out, module
    /// documentation "Loss of the master"), on its own clock.
    pub fn master_lost_at(&self) -> Option<Nanos> {
        self.master_lost_at
    }

    /// The master is lost (a SYNC or RPDO time-out with `code` at `now`): the CiA 402 drive
    /// takes the reaction 0x6007 says, now, on the node's own clock — no SYNC needed (module
    /// documentation, "Loss of the master"). The RPDO image gets the controlword of that
    /// reaction too, so a late SYNC with the old image does not enable the drive again.
    fn lose_master(&mut self, code: u16, now: Nanos) {
        self.master_lost_at = Some(now);
        let option = self.abort_connection_option();
        let controlword = match option {
            0 => return,
            2 => CONTROLWORD_DISABLE_VOLTAGE,
            3 => CONTROLWORD_QUICK_STOP,
            // 1 fault signal; manufacturer-specific (< 0) and reserved codes fault too.
            _ => {
                self.od.model_mut().fault_now(code);
                CONTROLWORD_DISABLE_VOLTAGE
            }
        };
        if let Some(e) = self.model_rx.find(0x6040, 0) {
            let _ = e.write(&mut self.outputs, i64::from(controlword));
        }
        if matches!(option, 2 | 3) {
            let _ = self
                .od
                .model_mut()
                .write_object(0x6040, 0, i64::from(controlword));
        }
        self.acted(true);
    }

    /// NMT reset node, the application part (CiA 301 §7.3.2.2.1): the drive restarts with its
    /// power-on values (a new model of the drive definition, SWITCH ON DISABLED, no fault, the
    /// RPDO image of a drive just powered up); the axis stays where it is (the mechanics do
    /// not move with a reset). The application objects the model does not back go back to
    /// their boot defaults.
    fn reset_application(&mut self) {
        let actual = self.od.model().actual();
        let mut model = match crate::drive::model::for_definition(&self.def) {
            Ok(m) => m,
            Err(e) => {
                // The definition built a model at start-up, so this does not happen; if it
                // did, the old model stays rather than the node failing.
                tracing::warn!(target: "fieldprobe::sim::canopen", node = self.id, "reset node: {e}");
                return;
            }
        };
        model.set_actual(actual);
        model.settle();
        self.outputs.iter_mut().for_each(|b| *b = 0);
        for e in self.model_rx.entries() {
            if let Ok(v) = model.read_object(e.index, e.sub) {
                let _ = e.write(&mut self.outputs, e.ty.saturate(v));
            }
        }
        model.finish_step(&mut self.inputs);
        self.od.replace_model(model);
        for (index, sub, data) in self.app_defaults.clone() {
            let _ = self.od.write(index, sub, &data);
        }
        self.master_lost_at = None;
    }

    /// Read `index:sub` from the object dictionary as an SDO upload would (bytes, or the
    /// CiA 301 abort code); for tests and diagnostics.
    pub fn read_object(&self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        self.od.read(index, sub)
    }

    /// Does the drive have a touch probe (0x60B8 in its model's RPDO data; from an EDS only
    /// where the EDS has the touch-probe objects, [`eds_model_definition`])?
    pub fn has_touch_probe(&self) -> bool {
        self.touch_probe
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

    /// The producer heartbeat time 0x1017 and its default, which NMT reset communication
    /// restores (`sim canopen --heartbeat-ms`; as a fault knob 0 = no heartbeat, the master's
    /// consumer then reports the node lost).
    pub fn set_heartbeat_ms(&mut self, ms: u16) {
        let v = ms.to_le_bytes();
        if self.od.write(0x1017, 0, &v).is_ok() {
            match self
                .comm_defaults
                .iter_mut()
                .find(|d| (d.0, d.1) == (0x1017, 0))
            {
                Some(d) => d.2 = v.to_vec(),
                None => self.comm_defaults.push((0x1017, 0, v.to_vec())),
            }
        }
    }

    /// Fault knob: ignore SDO requests (the client times out).
    pub fn mute_sdo(&mut self, muted: bool) {
        self.sdo_muted = muted;
    }

    /// Fault knob: send EMCY `code` every `every` (from the next poll on; at most 64 per poll,
    /// so a late poll cannot burst without bound); `None` stops it.
    pub fn flood_emcy(&mut self, code: u16, every: Option<Nanos>) {
        self.emcy_flood = every.map(|e| (code, Nanos(e.0.max(1)), None));
    }

    /// SYNC steps made.
    pub fn syncs(&self) -> u64 {
        self.syncs
    }

    /// Read the valid PDOs of `direction` from the object dictionary (CiA 301 §7.5.2.35 –
    /// §7.5.2.38): COB-ID (bit 31 set = not valid, skipped), transmission type, inhibit time,
    /// event-timer, mapping. A mapped object is served from the drive model's image when the
    /// drive file's layout has it, else from the object dictionary when it is there with that
    /// bit length and readable (TPDO) / writable (RPDO). Anything else is an error.
    fn pdos_from_od(
        &self,
        direction: Direction,
        layout: &PdoLayout,
    ) -> Result<Vec<NodePdo>, String> {
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
            let comm = direction.comm_index(k);
            let Ok(cob) = num(comm, 1) else {
                continue; // PDO k is not in the dictionary
            };
            if cob & 0x8000_0000 != 0 {
                continue;
            }
            let transmission = Transmission::from_code(num(comm, 2).map_or(255, |v| v as u8));
            let inhibit = num(comm, 3).map_or(0, |v| v as u16);
            let event = num(comm, 5).map_or(0, |v| v as u16);
            let map = direction.mapping_index(k);
            let n = num(map, 0)?;
            let mut slots = Vec::new();
            let mut off = 0;
            for j in 1..=n.min(64) {
                let v = num(map, j as u8)?;
                let (index, sub, bits) = (
                    (v >> 16) as u16,
                    ((v >> 8) & 0xFF) as u8,
                    (v & 0xFF) as usize,
                );
                let place = self
                    .mapped_place(direction, layout, index, sub, bits)
                    .map_err(|why| {
                        format!("{map:#06x}:{j:02x}: object {index:#06x}:{sub:02x} {why}")
                    })?;
                slots.push(Slot {
                    index,
                    sub,
                    len: bits / 8,
                    pdo_offset: off,
                    place,
                });
                off += bits / 8;
            }
            if off > 8 {
                return Err(format!("{map:#06x}: {off} bytes, a PDO carries at most 8"));
            }
            out.push(NodePdo::new(
                k,
                (cob & 0x7FF) as u16,
                transmission,
                inhibit,
                event,
                slots,
            ));
        }
        Ok(out)
    }

    /// Where the node serves `index:sub` mapped with `bits` in a PDO of `direction`.
    fn mapped_place(
        &self,
        direction: Direction,
        layout: &PdoLayout,
        index: u16,
        sub: u8,
        bits: usize,
    ) -> Result<Place, String> {
        if let Some(e) = layout.find(index, sub) {
            if bits != 8 * e.ty.size() {
                return Err(format!(
                    "mapped with {bits} bits, the object has {}",
                    8 * e.ty.size()
                ));
            }
            return Ok(Place::Image(e.offset));
        }
        let e = self
            .od
            .entries()
            .iter()
            .find(|e| (e.index, e.sub) == (index, sub))
            .ok_or("is not in the object dictionary")?;
        let size =
            e.ty.size()
                .or_else(|| self.fixed_len.get(&(index, sub)).copied());
        if size.map(|n| 8 * n) != Some(bits) || bits == 0 {
            return Err(format!("is not mappable with {bits} bits"));
        }
        let allowed = match direction {
            Direction::Rx => e.access != Access::Ro,
            Direction::Tx => e.access != Access::Wo,
        };
        if !allowed {
            return Err(format!("has the wrong access for a {direction:?}PDO"));
        }
        Ok(Place::Object)
    }

    /// Current data of TPDO `p`: image bytes as the model wrote them at its last step (or
    /// its last acyclic change), other objects as the dictionary has them now.
    fn tpdo_data(&self, p: &NodePdo) -> PdoData {
        // At most 8 bytes: `pdos_from_od` refuses a longer mapping.
        let mut d = PdoData::zeroed(p.len());
        for s in &p.slots {
            let Some(dst) = d.as_mut_slice().get_mut(s.pdo_offset..s.pdo_offset + s.len) else {
                continue;
            };
            let mut copy = |src: &[u8]| {
                let n = src.len().min(s.len);
                dst[..n].copy_from_slice(&src[..n]);
            };
            match s.place {
                Place::Image(off) => {
                    if let Some(src) = self.inputs.get(off..off + s.len) {
                        copy(src);
                    }
                }
                Place::Object => {
                    let _ = self.od.read_with(s.index, s.sub, copy);
                }
            }
        }
        d
    }

    /// Take over the data of RPDO `i` (index into `self.rx`). At a SYNC (`at_once` false) the
    /// image bytes are what the model reads at its step; on reception of an event-driven RPDO
    /// (`at_once`) the model also gets them now and acts on a controlword at once. Objects
    /// outside the image are written into the dictionary either way. Values the object refuses
    /// (read-only, out of range) are left out, as the model's own step does.
    fn take_over_rpdo(&mut self, i: usize, data: &[u8], at_once: bool) {
        let Some(slots) = self.rx.get(i).map(|p| p.slots.len()) else {
            return;
        };
        let mut controlword = false;
        for j in 0..slots {
            let s = self.rx[i].slots[j];
            let Some(bytes) = data.get(s.pdo_offset..s.pdo_offset + s.len) else {
                continue;
            };
            match s.place {
                Place::Image(off) => {
                    if let Some(dst) = self.outputs.get_mut(off..off + s.len) {
                        dst.copy_from_slice(bytes);
                    }
                    if at_once {
                        if let Some(v) = self.model_rx.get(&self.outputs, s.index, s.sub) {
                            let _ = self.od.model_mut().write_object(s.index, s.sub, v);
                        }
                        controlword |= (s.index, s.sub) == (0x6040, 0);
                    }
                }
                Place::Object => {
                    let _ = self.od.write(s.index, s.sub, bytes);
                    controlword |= (s.index, s.sub) == (0x6040, 0);
                }
            }
        }
        if at_once {
            self.acted(controlword);
        }
    }

    /// After an acyclic write: the drive acts on a new controlword, the TPDO image shows the
    /// drive as it is now.
    fn acted(&mut self, controlword: bool) {
        if controlword {
            self.od.model_mut().settle();
        }
        self.od.model_mut().finish_step(&mut self.inputs);
    }

    fn nmt(&mut self, cmd: NmtCommand, now: Nanos) {
        let was_operational = self.state == NmtState::Operational;
        match cmd {
            // Already started: the PDOs (which cannot change in OPERATIONAL) keep their state.
            NmtCommand::Start if self.state == NmtState::Operational => {}
            NmtCommand::Start => {
                let rx = self.pdos_from_od(Direction::Rx, &self.model_rx.clone());
                let tx = self.pdos_from_od(Direction::Tx, &self.model_tx.clone());
                match (rx, tx) {
                    (Ok(rx), Ok(tx)) => {
                        self.rx = rx;
                        self.tx = tx;
                        self.state = NmtState::Operational;
                        self.start_refused = false;
                    }
                    (Err(e), _) | (_, Err(e)) => {
                        tracing::debug!(target: "fieldprobe::sim::canopen", node = self.id, "start refused: {e}");
                        // Reported at the next poll (EMCY 0x8200, [`Self::report_errors`]);
                        // a start that succeeds or a reset ends the error.
                        self.start_refused = true;
                    }
                }
            }
            NmtCommand::Stop => self.state = NmtState::Stopped,
            NmtCommand::EnterPreOperational => self.state = NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                if cmd == NmtCommand::ResetNode {
                    // The application restarts (the drive with its power-on values), its
                    // error history with it.
                    self.reset_application();
                    self.errors.clear_history();
                    self.refresh_error_objects();
                }
                self.start_refused = false;
                self.pdo_length_error = false;
                self.state = NmtState::BootUp;
                self.boot_pending = true;
                // The SDO server is a communication object: a transfer a client abandoned ends
                // here (CiA 301 §7.3.2.2.2), the next client does not inherit it.
                self.sdo.reset();
                for (index, sub, data) in self.comm_defaults.clone() {
                    let _ = self.od.write(index, sub, &data);
                }
            }
        }
        if self.state != NmtState::Operational {
            // Synchronous RPDO data not yet taken over are dropped with the PDOs.
            self.rx.clear();
            self.tx.clear();
        }
        // Out of OPERATIONAL with the drive still enabled: no PDO brings set-points any more,
        // the connection to the master is gone (module documentation, "Loss of the master").
        if was_operational
            && self.state != NmtState::Operational
            && self.od.model().state() == crate::drive::PowerState::OperationEnabled
        {
            tracing::warn!(target: "fieldprobe::sim::canopen", node = self.id,
                "left OPERATIONAL with the drive enabled: abort connection reaction");
            self.lose_master(LEFT_OPERATIONAL_EMCY, now);
        }
        // The SYNC watch arms again with the first SYNC in OPERATIONAL, the RPDO deadline
        // monitoring with each RPDO's first reception.
        self.last_sync = None;
        self.sync_lost = false;
        self.rpdo_seen = [None; MAX_PDOS];
        self.rpdo_lost = [false; MAX_PDOS];
    }

    fn emcy_with(&mut self, code: u16, register: u8) {
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
                    self.nmt(cmd, now);
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
                fixed_len: &self.fixed_len,
                rx_layout: &self.model_rx,
                outputs: &mut self.outputs,
                tx_layout: &self.model_tx,
                rules: &self.rules,
                wrote: false,
                wrote_controlword: false,
                clear_history: false,
            };
            let replies = self.sdo.handle(f, &mut od, now);
            let (wrote, controlword) = (od.wrote, od.wrote_controlword);
            if od.clear_history {
                self.errors.clear_history();
                self.refresh_error_objects();
            }
            self.outgoing.extend(replies);
            if wrote {
                self.acted(controlword);
            }
            return;
        }
        if self.state == NmtState::Operational {
            if let Some(i) = self.rx.iter().position(|p| p.cob == id) {
                let p = &mut self.rx[i];
                let k = usize::from(p.number);
                if f.payload().len() != p.len() {
                    self.pdo_length_error = true;
                } else {
                    self.pdo_length_error = false;
                    if k < MAX_PDOS {
                        self.rpdo_seen[k] = Some(now);
                        self.rpdo_lost[k] = false;
                    }
                    if let Some(data) = p.receive(f.payload()) {
                        self.take_over_rpdo(i, data.as_slice(), true);
                    }
                }
                let window = self.read_u32(0x1007);
                if let Some(t) = self.last_sync {
                    if window != 0 && now.0.saturating_sub(t.0) > u64::from(window) * 1000 {
                        self.rpdos_outside_window += 1;
                    }
                }
            }
        }
    }

    /// Time-driven work at `now`: boot-up message, heartbeat, SDO server timeout, EMCY for a new
    /// model fault, the SYNC watch, RPDO deadlines, event-driven TPDOs.
    pub fn poll(&mut self, now: Nanos) {
        if let Some((code, every, last)) = self.emcy_flood {
            let mut at = last.unwrap_or(Nanos(now.0.saturating_sub(every.0)));
            let mut sent = 0;
            while now.0.saturating_sub(at.0) >= every.0 && sent < 64 {
                at = Nanos(at.0 + every.0);
                sent += 1;
                self.emcy_with(code, 0x01);
            }
            if sent == 64 {
                at = now;
            }
            self.emcy_flood = Some((code, every, Some(at)));
        }
        if self.boot_pending {
            self.boot_pending = false;
            self.outgoing
                .push(nmt::heartbeat(self.id, NmtState::BootUp));
            self.state = NmtState::PreOperational;
            self.last_heartbeat = Some(now);
        }
        let period = self.read_u16(0x1017, 0);
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
        self.watch_sync(now);
        self.watch_rpdos(now);
        self.report_errors();
        self.send_event_tpdos(now);
    }

    /// The errors active now (at most one per source): the CiA 402 drive fault with its
    /// 0x603F code (FAULT REACTION ACTIVE or FAULT), a SYNC time-out, an RPDO time-out, a PDO
    /// length error, a refused NMT start.
    fn active_errors(&self) -> ([u16; 5], usize) {
        let mut a = [0u16; 5];
        let mut n = 0;
        let mut add = |code: u16| {
            if code != 0 && !a[..n].contains(&code) {
                a[n] = code;
                n += 1;
            }
        };
        let model = self.od.model();
        if matches!(
            model.state(),
            crate::drive::PowerState::Fault | crate::drive::PowerState::FaultReactionActive
        ) {
            // A fault without a code is still an error: 0x1000 generic.
            add(match model.last_error_code() {
                0 => 0x1000,
                c => c,
            });
        }
        if self.sync_lost {
            add(SYNC_TIMEOUT_EMCY);
        }
        if self.rpdo_lost.iter().any(|&l| l) {
            add(RPDO_TIMEOUT_EMCY);
        }
        if self.pdo_length_error {
            add(PDO_LENGTH_EMCY);
        }
        if self.start_refused {
            add(START_REFUSED_EMCY);
        }
        (a, n)
    }

    /// Compare the active errors with the last poll's: EMCY for every new error, EMCY 0x0000
    /// "error reset" when one is gone ([`errors`]); 0x1001 / 0x1003 follow.
    fn report_errors(&mut self) {
        let (a, n) = self.active_errors();
        if a[..n] == *self.errors.active() {
            return;
        }
        let emcys = self.errors.update(&a[..n]);
        // CiA 301 §7.3.2.2 (NMT states): no EMCY in STOPPED; the error state changes anyway.
        if matches!(self.state, NmtState::PreOperational | NmtState::Operational) {
            for (code, register) in emcys {
                self.emcy_with(code, register);
            }
        }
        self.refresh_error_objects();
    }

    /// Write the error state into 0x1001 and 0x1003 (sub-index 0 = errors recorded, 1 … n
    /// newest first, 0 beyond).
    fn refresh_error_objects(&mut self) {
        let register = self.errors.register();
        self.od.insert(ObjectEntry::constant(
            0x1001,
            0,
            DataType::U8,
            i64::from(register),
        ));
        let cap = self.errors.capacity();
        if cap == 0 {
            return;
        }
        let history = self.errors.history().to_vec();
        let _ = self.od.write(0x1003, 0, &[history.len() as u8]);
        for k in 1..=cap {
            let v = history.get(usize::from(k) - 1).copied().unwrap_or(0);
            self.od.insert(ObjectEntry::constant(
                0x1003,
                k,
                DataType::U32,
                i64::from(v),
            ));
        }
    }

    /// The error register 0x1001 now.
    pub fn error_register(&self) -> u8 {
        self.errors.register()
    }

    /// The pre-defined error field 0x1003 sub-indices 1 … n now (newest first).
    pub fn error_history(&self) -> &[u32] {
        self.errors.history()
    }

    /// Event-driven TPDOs (types 254 / 255) at `now` (operational only): sent when their data
    /// changed since their last transmission, or their event-timer elapsed, once the inhibit
    /// time is over ([`NodePdo::event_due`]); each at its NMT start (nothing sent yet).
    fn send_event_tpdos(&mut self, now: Nanos) {
        if self.state != NmtState::Operational {
            return;
        }
        for i in 0..self.tx.len() {
            if !self.tx[i].transmission.event_driven() {
                continue;
            }
            let data = self.tpdo_data(&self.tx[i]);
            if self.tx[i].event_due(now, data.as_slice()) {
                self.transmit_tpdo(i, now, data);
            }
        }
    }

    /// Send TPDO `i` (index into `self.tx`) with `data` at `now`.
    fn transmit_tpdo(&mut self, i: usize, now: Nanos, data: PdoData) {
        if let Ok(f) = CanFrame::new(self.tx[i].cob, data.as_slice()) {
            self.outgoing.push(f);
        }
        self.tx[i].sent(now, data);
    }

    /// RPDO deadline monitoring (module documentation), at `now`.
    fn watch_rpdos(&mut self, now: Nanos) {
        if self.state != NmtState::Operational {
            return;
        }
        for k in 0..MAX_PDOS {
            let Some(last) = self.rpdo_seen[k] else {
                continue;
            };
            if self.rpdo_lost[k] {
                continue;
            }
            let ms = self.read_u16(Direction::Rx.comm_index(k as u8), 5);
            if ms == 0 || now.0.saturating_sub(last.0) <= u64::from(ms) * 1_000_000 {
                continue;
            }
            self.rpdo_lost[k] = true;
            self.rpdo_timeouts += 1;
            tracing::warn!(target: "fieldprobe::sim::canopen", node = self.id,
                "RPDO {} missing for {} µs (event-timer {ms} ms): EMCY 0x8250, drive fault",
                k + 1, now.0.saturating_sub(last.0) / 1000);
            self.lose_master(RPDO_TIMEOUT_EMCY, now);
        }
    }

    /// At a SYNC (operational only), the synchronous TPDOs due ([`NodePdo::sync_due`]: type
    /// n every n-th SYNC, type 0 when the data changed), with the values of the last model step.
    fn send_tpdos(&mut self, now: Nanos) {
        if self.state != NmtState::Operational {
            return;
        }
        for i in 0..self.tx.len() {
            let data = self.tpdo_data(&self.tx[i]);
            if self.tx[i].sync_due(data.as_slice()) {
                self.transmit_tpdo(i, now, data);
            }
        }
    }

    /// Frames the node wants to send, in order.
    pub fn take_outgoing(&mut self) -> Vec<CanFrame> {
        std::mem::take(&mut self.outgoing)
    }

    /// Hand the frames the node wants to send to `send`, in order; the queue keeps its
    /// allocation (the segment's cyclic path).
    fn send_outgoing(&mut self, send: &mut dyn FnMut(CanFrame)) {
        self.outgoing.drain(..).for_each(send);
    }
}

/// Longest step one SYNC advances the drive models by when no 0x1006 is set: the time since
/// the previous SYNC, but at most this (module documentation, "The drive's clock"). 1 s covers
/// the slowest cycle a CiA 301 bus carries for a few drives (10 kbit/s: three generic drives
/// need 260 ms, eight 690 ms below 70 % load); a longer gap is a stalled master, whose last
/// set-point the drive holds.
pub const MAX_SYNC_STEP: Nanos = Nanos(1_000_000_000);

/// The emulated nodes of one bus and their world.
#[derive(Debug)]
pub struct CanopenSegment {
    nodes: Vec<EmulatedNode>,
    world: World,
    cycle: Nanos,
    /// The models' ports during a world step (kept: no allocation per SYNC).
    ports: PortBuffer,
    /// The model time of the last SYNC step, and the step it made.
    last_step: Option<(Nanos, Nanos)>,
}

impl CanopenSegment {
    /// Nodes (world device *i* = node *i*) with an empty plant, SYNC period `cycle`.
    pub fn new(nodes: Vec<EmulatedNode>, cycle: Nanos) -> Self {
        CanopenSegment {
            nodes,
            world: World::new(crate::sim::plant::Plant::new()),
            cycle,
            ports: PortBuffer::default(),
            last_step: None,
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

    /// Feed the frames the nodes received, run SYNC when one came (TPDOs, then world step),
    /// do the time-driven work at `now`, and return every frame the nodes send, in order.
    pub fn run(&mut self, received: &[CanFrame], now: Nanos) -> Vec<CanFrame> {
        let mut out = Vec::new();
        self.run_with(received, now, &mut |f| out.push(f));
        out
    }

    /// [`run`](Self::run), handing every frame to `send` as soon as a node produces it: the
    /// TPDOs of a SYNC go before the drive models step, as a device sends the values it sampled
    /// at the SYNC and computes afterwards (`fieldprobe sim canopen` on a real bus). The frames
    /// and their order are those `run` returns.
    pub fn run_with(&mut self, received: &[CanFrame], now: Nanos, send: &mut dyn FnMut(CanFrame)) {
        for f in received {
            self.receive(f, now, now, send);
        }
        self.poll(now, send);
    }

    /// One frame reaching every node at `at`: NMT, SDO and PDOs are handled at once; a SYNC
    /// makes every operational node take over its synchronous RPDOs and send its synchronous
    /// TPDOs at `at`, then the drive models step once at `model_time` — the instant on the
    /// SYNC producer's grid that the world's clock (plant, probe edges) keeps, which a bus
    /// with a wire delays by the SYNC's own wire time and any frame in progress. Whatever the
    /// nodes send goes to `send` in order.
    pub fn receive(
        &mut self,
        f: &CanFrame,
        at: Nanos,
        model_time: Nanos,
        send: &mut dyn FnMut(CanFrame),
    ) {
        if !f.extended && !f.rtr && !f.error && f.id == u32::from(nmt::SYNC_COB) {
            // The first SYNC since an operational node started (its SYNC history is reset by
            // every NMT state change).
            let first = !self
                .nodes
                .iter()
                .any(|n| n.state == NmtState::Operational && n.last_sync.is_some());
            for n in &mut self.nodes {
                n.syncs += u64::from(n.state == NmtState::Operational);
                n.on_sync(at);
                n.send_tpdos(at);
                n.send_outgoing(send);
            }
            self.step_models(model_time, first);
        } else {
            for n in &mut self.nodes {
                n.handle(f, at);
            }
        }
        for n in &mut self.nodes {
            n.send_outgoing(send);
        }
    }

    /// The time-driven work of every node at `at` ([`EmulatedNode::poll`]: boot-up, heartbeat,
    /// SDO server timeout, EMCY, SYNC watch, RPDO deadlines, event-driven TPDOs); what the
    /// nodes send goes to `send`.
    pub fn poll(&mut self, at: Nanos, send: &mut dyn FnMut(CanFrame)) {
        for n in &mut self.nodes {
            n.poll(at);
            n.send_outgoing(send);
        }
    }

    /// SYNC (after every operational node sent its TPDOs with what its drive sampled at the
    /// previous SYNC): every model steps once with the RPDOs received before this SYNC (CiA 301
    /// synchronous PDOs: received data take effect at the next SYNC, transmitted data are
    /// sampled at the SYNC). A master that sends its RPDOs, then SYNC, then reads the TPDOs
    /// thus sees the actual values one cycle after they were sampled, as on a real bus. The
    /// step is [`sync_step`](Self::sync_step)'s.
    fn step_models(&mut self, now: Nanos, first: bool) {
        let cycle = self.sync_step(now, first);
        self.last_step = Some((now, cycle));
        let ports = self.nodes.iter_mut().map(|n| Port {
            model: n.od.model_mut(),
            outputs: &n.outputs,
            inputs: &mut n.inputs,
        });
        let world = &mut self.world;
        self.ports.with(ports, |p| world.step(now, cycle, p));
    }

    /// How far a SYNC at model time `now` steps the drive models (module documentation,
    /// "The drive's clock"): 0x1006 when an operational node has it set (≠ 0); else the time
    /// since the previous SYNC on the nodes' clock, at most [`MAX_SYNC_STEP`]; the segment's
    /// cycle for the first SYNC after NMT start (`first`), when there is no previous one.
    pub fn sync_step(&self, now: Nanos, first: bool) -> Nanos {
        let configured = self
            .nodes
            .iter()
            .filter(|n| n.state == NmtState::Operational)
            .find_map(EmulatedNode::cycle_period_us);
        match (configured, self.last_step) {
            (Some(us), _) => Nanos::from_micros(u64::from(us)),
            (None, Some((prev, _))) if !first => {
                Nanos(now.0.saturating_sub(prev.0).min(MAX_SYNC_STEP.0))
            }
            _ => self.cycle,
        }
    }

    /// The step the last SYNC advanced the drive models by ([`sync_step`](Self::sync_step)).
    pub fn last_sync_step(&self) -> Option<Nanos> {
        self.last_step.map(|(_, step)| step)
    }
}

#[cfg(test)]
mod tests;
