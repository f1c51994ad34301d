//! Emulated EtherCAT servo: an [`Esc`] built from an ESI device description with a CiA 402
//! drive model ([`Ds402Model`](crate::drive::model::ds402::Ds402Model)) behind a CoE mailbox
//! server ([`CoeServer`]).
//!
//! * SII: [`sii_from_device`] of the ESI device, padded ([`sii::encode_padded`]); the ESC
//!   configuration is [`EscConfig::from_sii`].
//! * Object dictionary: [`ds402_objects`] plus 0x1018 identity (vendor, product code, revision
//!   from the ESI; serial 0 like the SII), the PDO assignment objects 0x1C12/0x1C13 (the PDOs
//!   the ESI assigns to SM2/SM3 by default) and the mapping objects (0x1600.., 0x1A00..) with the
//!   CiA 301 mapping values `index << 16 | sub << 8 | bits`. All are read-only constants, which
//!   is enough for a MainDevice that discovers the mapping by reading them (ethercrab 0.7.1
//!   reads 0x1C12/0x1C13:0.., then each PDO's :0.. with expedited uploads). All of
//!   them are ≤ 4 bytes, so the server answers them expedited.
//! * Process data: the SM2 output image is kept when the master writes it (OP only, see
//!   [`Esc`]; several writes before the next step: the last one counts). In a segment with a
//!   world ([`Segment::set_world`](super::segment::Segment::set_world)) the segment steps the
//!   model — at SYNC0, or per process-data frame (see [`super::segment::Stepping`]) — and a read
//!   of the SM3 input image returns what the last step wrote. Alone (free-running), every read
//!   of the input image is one exchange: the model runs `begin_step(now, dt, outputs)` then
//!   `finish_step(inputs)`; with a single LRW per cycle the inputs are read before that
//!   datagram's outputs are written, so the model sees the outputs of the previous cycle (like
//!   a real drive sampling at SYNC).
//! * Time when free-running: exchange `k` (counting from 1) covers the cycle ending at
//!   `now = k · cycle`, `dt = cycle`, where `cycle` is the configured cycle time
//!   ([`DEFAULT_CYCLE`] for [`emulated_servo`], or the argument of
//!   [`emulated_servo_with_cycle`]), independent of the master's wall clock.
//! * Leaving OP (the master asks for a lower state, or the sync-manager watchdog expires) puts
//!   the outputs the model acts on into their safe state
//!   ([`EscApplication::outputs_invalid`]): a CiA 402 drive gets the controlword *quick stop*
//!   (as with 0x6007 "abort connection option code" 3) and stops where it is, in QUICK STOP
//!   ACTIVE, until the master enables operation again in OP; other families get a zero output
//!   image.
//!
//! The drive definition's PDO layout must hold the same entries as the ESI's default mapping
//! (index, sub-index, bit length, gaps excluded; the order may differ) with the same image
//! lengths; otherwise [`emulated_servo`] fails with [`ServoError::PdoMismatch`]. The model keeps
//! the drive definition's layout; the bus image follows the PDO mapping objects (ESI default at
//! start, rewritten by the master in PRE-OP), and the copy plan between the two is rebuilt on
//! PRE-OP → SAFE-OP.

use std::time::Duration;

use super::app::{EscApplication, ProcessDataSizes};
use super::coe::{ds402_objects, Access, CoeServer, DataType, ObjectEntry};
use super::sdo_info::OdDescriptions;
use super::soe::{sercos_idns, SoeServer};
use super::types::{AlState, AlStatusCode};
use super::{Esc, EscConfig};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::model::DriveModel;
use crate::esi::sii::{self, SiiError};
use crate::esi::to_sii::sii_from_device;
use crate::esi::{Device, EsiFile, Pdo};
use crate::sim::world::Port;
use crate::units::Nanos;

/// Cycle time [`emulated_servo`] uses for the model's `now`/`dt` (1 ms).
pub const DEFAULT_CYCLE: Duration = Duration::from_millis(1);

/// Smallest mailbox sync manager an emulated drive accepts: the 6-byte mailbox header, the
/// 2-byte CoE header and an 8-byte SDO (ETG.1000.6 §5.6.2, the smallest SDO request).
pub const MIN_MAILBOX_SIZE: u16 = 16;

/// Largest mailbox sync manager: the data of one datagram in a maximum-size Ethernet frame
/// (1500 − 2 frame header − 10 datagram header − 2 working counter, ETG.1000.4 §5.4); a master
/// reads a mailbox in one datagram.
pub const MAX_MAILBOX_SIZE: u16 = 1486;

/// Why a device needing a mailbox has none usable: a mailbox sync manager with a missing or
/// impossible size (named), or no mailbox sync managers at all.
pub(super) fn mailbox_error(device: &Device) -> ServoError {
    use crate::esi::SmKind;
    let bad = device
        .sync_managers
        .iter()
        .enumerate()
        .filter_map(|(i, sm)| match sm.kind {
            SmKind::MBoxOut => Some((i, "MBoxOut", sm.default_size)),
            SmKind::MBoxIn => Some((i, "MBoxIn", sm.default_size)),
            _ => None,
        })
        .find(|(_, _, size)| {
            !size.is_some_and(|n| (MIN_MAILBOX_SIZE..=MAX_MAILBOX_SIZE).contains(&n))
        });
    match bad {
        Some((sm, kind, size)) => ServoError::MailboxSize {
            device: device.type_name.clone(),
            sm,
            kind,
            size,
        },
        None => ServoError::NoMailbox(device.type_name.clone()),
    }
}

/// CiA 402 controlword *quick stop* (bit 1 set, bit 2 clear), the outputs' safe state.
const CONTROLWORD_QUICK_STOP: u16 = 0x0002;

/// Why an emulated servo could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServoError {
    /// The SII image could not be built from the ESI device.
    #[error("SII image of the ESI device: {0}")]
    Sii(#[from] SiiError),
    /// The ESI device has no standard mailbox (no CoE possible).
    #[error("ESI device {0} has no mailbox (no MBoxOut / MBoxIn sync managers)")]
    NoMailbox(String),
    /// A mailbox sync manager's `DefaultSize` is missing or outside
    /// [`MIN_MAILBOX_SIZE`]..=[`MAX_MAILBOX_SIZE`].
    #[error(
        "ESI device {device}: mailbox sync manager SM{sm} ({kind}) has {}; a mailbox sync \
         manager needs a DefaultSize of {MIN_MAILBOX_SIZE}..={MAX_MAILBOX_SIZE} bytes",
        size.map_or("no DefaultSize".to_string(), |n| format!("DefaultSize {n}"))
    )]
    MailboxSize {
        /// Device type name.
        device: String,
        /// Sync manager index.
        sm: usize,
        /// `MBoxOut` or `MBoxIn`.
        kind: &'static str,
        /// The size found.
        size: Option<u16>,
    },
    /// The drive definition's PDO layout differs from the ESI mapping.
    #[error("{direction} PDO layout of drive '{drive}' differs from the ESI mapping: drive {drive_entries:x?} ({drive_bytes} bytes), ESI {esi_entries:x?} ({esi_bits} bits)")]
    PdoMismatch {
        /// `rx` (outputs) or `tx` (inputs).
        direction: &'static str,
        /// Drive definition name.
        drive: String,
        /// (index, sub, bits) of the drive layout.
        drive_entries: Vec<(u16, u8, u32)>,
        /// Bytes of the drive image.
        drive_bytes: usize,
        /// (index, sub, bits) of the ESI mapping (gaps excluded).
        esi_entries: Vec<(u16, u8, u32)>,
        /// Bits of the ESI mapping (gaps included).
        esi_bits: u32,
    },
    /// The drive model could not be built from the definition.
    #[error("drive model: {0}")]
    Model(String),
    /// The cycle time is zero.
    #[error("cycle time must be > 0")]
    ZeroCycle,
    /// A vendor device cannot be played as a CiA 402 drive (see [`super::vendor`]).
    #[error("{0}")]
    Vendor(String),
}

/// The mailbox server of an emulated drive: CoE for CiA 402 (and every object-dictionary
/// family), SoE for SERCOS. Either owns the drive model.
// One per emulated device, built once and never moved per cycle: the size difference between
// the CoE server and a bare model costs nothing, a box would cost an indirection per mailbox
// access.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum MailboxServer {
    /// CoE (SDO, EMCY).
    Coe(CoeServer),
    /// SoE (IDN read / write).
    Soe(SoeServer),
    /// No mailbox (a simple terminal): the model alone.
    None(Box<dyn DriveModel>),
}

impl MailboxServer {
    fn model(&self) -> &dyn DriveModel {
        match self {
            MailboxServer::Coe(c) => c.model(),
            MailboxServer::Soe(s) => s.model(),
            MailboxServer::None(m) => m.as_ref(),
        }
    }

    fn model_mut(&mut self) -> &mut dyn DriveModel {
        match self {
            MailboxServer::Coe(c) => c.model_mut(),
            MailboxServer::Soe(s) => s.model_mut(),
            MailboxServer::None(m) => m.as_mut(),
        }
    }
}

/// One mapped entry: `bits` bits at bit `bus` of the bus image are the bits at bit `model` of
/// the model's image — or, for an object outside the model's layout (`object`), the value of that
/// object in the CoE dictionary (written by an RxPDO, read for a TxPDO). Bit offsets count from
/// the least significant bit of byte 0 (PDO entries are packed LSB first, ETG.1000.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Span {
    bus: usize,
    model: usize,
    bits: usize,
    object: Option<(u16, u8)>,
}

/// A device object that plays (a part of) a CiA 402 object of the drive model (a vendor device's
/// role, [`crate::drive::vendor::plan::RoleSource`]): `object` is the model's `canonical` object
/// from its bit `at`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct RoleLink {
    pub object: (u16, u8),
    pub canonical: (u16, u8),
    pub at: u16,
}

/// The application of an emulated drive: the mailbox server (owning the drive model) plus the
/// process-data glue. See the module documentation for the time base.
#[derive(Debug)]
pub struct ServoApp {
    server: MailboxServer,
    /// Drive definition's images (the model's layout).
    model_rx: crate::drive::pdo::PdoLayout,
    model_tx: crate::drive::pdo::PdoLayout,
    /// Model-layout images.
    outputs: Vec<u8>,
    inputs: Vec<u8>,
    /// Bus images (the current PDO mapping's layout) and the copy plans between them.
    bus_rx_len: usize,
    bus_tx_len: usize,
    rx_plan: Vec<Span>,
    tx_plan: Vec<Span>,
    exchanges: u64,
    cycle_ns: u64,
    synchronized: bool,
    /// Mapped objects outside the model's layout are served from the CoE dictionary (vendor
    /// devices, [`super::vendor`]); otherwise such a mapping is refused.
    od_spans: bool,
    /// Device objects that play the model's CiA 402 objects (vendor devices).
    roles: Vec<RoleLink>,
    /// Entries of the model's RxPDO layout the current mapping does not feed (e.g. the mode of
    /// operation a master writes by SDO instead): refreshed from the model before each step,
    /// so the step does not overwrite them with the image's zeros.
    rx_unfed: Vec<crate::drive::pdo::PdoEntry>,
}

impl ServoApp {
    /// The application of a vendor device ([`super::vendor`]): `coe` owns the model, whose
    /// images have the layouts `model_rx` / `model_tx`; the bus images follow the CoE PDO
    /// objects, mapped objects outside the model's layouts come from the dictionary.
    pub(super) fn vendor(
        coe: CoeServer,
        model_rx: crate::drive::pdo::PdoLayout,
        model_tx: crate::drive::pdo::PdoLayout,
        roles: Vec<RoleLink>,
        cycle_ns: u64,
    ) -> Result<Self, AlStatusCode> {
        let (rx_len, tx_len) = (model_rx.len(), model_tx.len());
        let mut app = ServoApp {
            server: MailboxServer::Coe(coe),
            model_rx,
            model_tx,
            outputs: vec![0; rx_len],
            inputs: vec![0; tx_len],
            bus_rx_len: 0,
            bus_tx_len: 0,
            rx_plan: Vec::new(),
            tx_plan: Vec::new(),
            exchanges: 0,
            cycle_ns,
            synchronized: false,
            od_spans: true,
            roles,
            rx_unfed: Vec::new(),
        };
        app.remap()?;
        Ok(app)
    }

    /// The CoE server, if the drive speaks CoE.
    pub fn coe(&self) -> Option<&CoeServer> {
        match &self.server {
            MailboxServer::Coe(c) => Some(c),
            _ => None,
        }
    }

    /// The CoE server, mutable.
    pub fn coe_mut(&mut self) -> Option<&mut CoeServer> {
        match &mut self.server {
            MailboxServer::Coe(c) => Some(c),
            _ => None,
        }
    }

    /// Process-data steps so far (free-running: input image reads; synchronized: SYNC0 steps).
    pub fn exchanges(&self) -> u64 {
        self.exchanges
    }

    /// The last output image the master wrote, in the drive model's layout (zeros before the
    /// first write).
    pub fn outputs(&self) -> &[u8] {
        &self.outputs
    }

    /// Recompute the copy plans from the PDO mapping objects (CoE devices; SoE devices keep the
    /// ESI mapping). Errors name the first entry the model cannot map.
    fn remap(&mut self) -> Result<(), AlStatusCode> {
        let MailboxServer::Coe(coe) = &self.server else {
            return Ok(());
        };
        let (rx_len, rx_plan) =
            plan_from_objects(coe, 0x1C12, &self.model_rx, self.od_spans, &self.roles)
                .ok_or(AlStatusCode::INVALID_OUTPUT_MAPPING)?;
        let (tx_len, tx_plan) =
            plan_from_objects(coe, 0x1C13, &self.model_tx, self.od_spans, &self.roles)
                .ok_or(AlStatusCode::INVALID_INPUT_MAPPING)?;
        self.rx_unfed = self
            .model_rx
            .entries()
            .iter()
            .filter(|e| {
                let (from, to) = (e.bit, e.bit + usize::from(e.bits));
                !rx_plan
                    .iter()
                    .any(|s| s.object.is_none() && s.model < to && from < s.model + s.bits)
            })
            .copied()
            .collect();
        self.bus_rx_len = rx_len;
        self.bus_tx_len = tx_len;
        self.rx_plan = rx_plan;
        self.tx_plan = tx_plan;
        Ok(())
    }

    fn model_step(&mut self, now: Nanos) {
        self.refresh_unfed();
        let dt = self.cycle_ns as f64 * 1e-9;
        let model = self.server.model_mut();
        model.begin_step(now, dt, &self.outputs);
        model.finish_step(&mut self.inputs);
    }
}

impl ServoApp {
    /// Put the model's current values of the RxPDO entries no mapping feeds into its output
    /// image ([`ServoApp::rx_unfed`]).
    fn refresh_unfed(&mut self) {
        for e in &self.rx_unfed {
            if let Ok(v) = self.server.model().read_object(e.index, e.sub) {
                let _ = e.write(&mut self.outputs, e.ty.saturate(v));
            }
        }
    }
}

/// Bus image length (bytes) and copy plan of the PDOs assigned in `assign` (0x1C12 / 0x1C13)
/// as the CoE objects say now; `None` if an assigned PDO or a mapped object is missing. Each
/// mapped entry, bit for bit: a gap (index 0) is skipped; an object of the model's `layout` —
/// itself, or a device object that plays one of its CiA 402 objects (`roles`) — goes to the
/// model's image at that object's bits (a role's part at its bit within the word); with `od`,
/// any other object the dictionary holds is served from there (as many bits as the entry has,
/// at most the object's size); anything else fails the plan.
fn plan_from_objects(
    coe: &CoeServer,
    assign: u16,
    layout: &crate::drive::pdo::PdoLayout,
    od: bool,
    roles: &[RoleLink],
) -> Option<(usize, Vec<Span>)> {
    let value = |index: u16, sub: u8| -> Option<i64> {
        let e = coe
            .entries()
            .iter()
            .find(|e| e.index == index && e.sub == sub)?;
        e.ty.decode(e.data.as_deref()?)
    };
    let mut plan = Vec::new();
    let mut bus = 0usize;
    let n = value(assign, 0)?;
    for k in 1..=n {
        let pdo = u16::try_from(value(assign, u8::try_from(k).ok()?)?).ok()?;
        let m = value(pdo, 0)?;
        for j in 1..=m {
            let v = u32::try_from(value(pdo, u8::try_from(j).ok()?)?).ok()?;
            let (index, sub, bits) = (
                (v >> 16) as u16,
                ((v >> 8) & 0xFF) as u8,
                (v & 0xFF) as usize,
            );
            if index != 0 {
                let role = roles.iter().find(|r| r.object == (index, sub));
                let model = match role {
                    Some(r) => layout
                        .find(r.canonical.0, r.canonical.1)
                        .filter(|e| usize::from(r.at) + bits <= usize::from(e.bits))
                        .map(|e| e.bit + usize::from(r.at)),
                    None => layout
                        .find(index, sub)
                        .filter(|e| usize::from(e.bits) == bits)
                        .map(|e| e.bit),
                };
                match model {
                    Some(at) => plan.push(Span {
                        bus,
                        model: at,
                        bits,
                        object: None,
                    }),
                    None if od => {
                        let e = coe
                            .entries()
                            .iter()
                            .find(|e| e.index == index && e.sub == sub)?;
                        let size = match e.ty {
                            DataType::Bytes(n) => n,
                            ty => ty.size()?,
                        };
                        if bits > 8 * size {
                            return None;
                        }
                        plan.push(Span {
                            bus,
                            model: 0,
                            bits,
                            object: Some((index, sub)),
                        });
                    }
                    None => return None,
                }
            }
            bus += bits;
        }
    }
    Some((bus.div_ceil(8), plan))
}

impl EscApplication for ServoApp {
    fn coe_mut(&mut self) -> Option<&mut CoeServer> {
        match &mut self.server {
            MailboxServer::Coe(c) => Some(c),
            _ => None,
        }
    }

    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        match &mut self.server {
            MailboxServer::Coe(c) => c.handle(data),
            MailboxServer::Soe(s) => s.handle(data),
            MailboxServer::None(_) => None,
        }
    }

    fn take_outgoing(&mut self) -> Vec<Vec<u8>> {
        match &mut self.server {
            MailboxServer::Coe(c) => c.poll(),
            MailboxServer::Soe(s) => s.take_outgoing(),
            MailboxServer::None(_) => Vec::new(),
        }
    }

    fn outputs_written(&mut self, _sm: u8, data: &[u8]) {
        for s in &self.rx_plan {
            if s.bus + s.bits > data.len() * 8 {
                continue;
            }
            if let Some((index, sub)) = s.object {
                if let MailboxServer::Coe(c) = &mut self.server {
                    // The object's bytes with the entry's bits in place (a bit field shorter
                    // than the object fills its low bits). A value the object refuses is
                    // dropped, as a drive ignores it.
                    let mut bytes = [0u8; 8];
                    let n = s.bits.div_ceil(8).min(8);
                    crate::drive::pdo::copy_bits(data, s.bus, &mut bytes, 0, s.bits.min(64));
                    let size = c
                        .read_with(index, sub, <[u8]>::len)
                        .unwrap_or(n)
                        .clamp(n, 8);
                    let _ = c.write(index, sub, &bytes[..size]);
                }
                continue;
            }
            crate::drive::pdo::copy_bits(data, s.bus, &mut self.outputs, s.model, s.bits);
        }
    }

    /// Safe state of the outputs when the device leaves OP: a CiA 402 drive gets the controlword
    /// *quick stop* (0x0002; CiA 402 0x6007 "abort connection option code" 3: OPERATION ENABLED
    /// → QUICK STOP ACTIVE, which the model holds at the actual position) and keeps its other
    /// set-points; every other drive gets an all-zero output image (SERCOS: control word 0 =
    /// drive off). The model goes on stepping with these until the master writes outputs in OP
    /// again.
    fn outputs_invalid(&mut self) {
        match self.model_rx.find(0x6040, 0).map(|e| e.offset) {
            Some(at) if at + 2 <= self.outputs.len() => {
                self.outputs[at..at + 2].copy_from_slice(&CONTROLWORD_QUICK_STOP.to_le_bytes());
            }
            _ => self.outputs.fill(0),
        }
    }

    fn mailbox_reset(&mut self) {
        match &mut self.server {
            MailboxServer::Coe(c) => c.reset_session(),
            MailboxServer::Soe(s) => s.reset_session(),
            MailboxServer::None(_) => {}
        }
    }

    fn inputs(&mut self, _sm: u8, buf: &mut [u8]) {
        if !self.synchronized {
            self.exchanges += 1;
            let now = Nanos(self.exchanges.saturating_mul(self.cycle_ns));
            self.model_step(now);
        }
        for s in &self.tx_plan {
            if s.bus + s.bits > buf.len() * 8 {
                continue;
            }
            if let Some((index, sub)) = s.object {
                if let MailboxServer::Coe(c) = &self.server {
                    let _ = c.read_with(index, sub, |v| {
                        crate::drive::pdo::copy_bits(v, 0, buf, s.bus, s.bits.min(v.len() * 8));
                    });
                }
                continue;
            }
            crate::drive::pdo::copy_bits(&self.inputs, s.model, buf, s.bus, s.bits);
        }
    }

    fn process_data_sizes(&self) -> ProcessDataSizes {
        let MailboxServer::Coe(coe) = &self.server else {
            return ProcessDataSizes {
                outputs: self.bus_rx_len as u16,
                inputs: self.bus_tx_len as u16,
            };
        };
        let len = |assign, layout| {
            plan_from_objects(coe, assign, layout, self.od_spans, &self.roles)
                .map_or(0, |(n, _)| u16::try_from(n).unwrap_or(0))
        };
        ProcessDataSizes {
            outputs: len(0x1C12, &self.model_rx),
            inputs: len(0x1C13, &self.model_tx),
        }
    }

    fn state_change(&mut self, from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        if from == AlState::PreOp && to >= AlState::SafeOp {
            self.remap()?;
        }
        if let Some(r) = self.coe_mut().and_then(|c| c.pdo_rules_mut()) {
            r.set_editable(to == AlState::PreOp);
        }
        Ok(())
    }

    fn model(&self) -> Option<&dyn DriveModel> {
        Some(self.server.model())
    }

    fn model_mut(&mut self) -> Option<&mut dyn DriveModel> {
        Some(self.server.model_mut())
    }

    fn port(&mut self) -> Option<Port<'_>> {
        self.exchanges += 1;
        self.refresh_unfed();
        Some(Port {
            model: self.server.model_mut(),
            outputs: &self.outputs,
            inputs: &mut self.inputs,
        })
    }

    fn set_synchronized(&mut self, on: bool) {
        self.synchronized = on;
    }
}

/// PDOs of `pdos` the ESI assigns to sync manager `sm` by default.
pub(super) fn assigned(pdos: &[Pdo], sm: u8) -> Vec<&Pdo> {
    pdos.iter().filter(|p| p.sm == Some(sm)).collect()
}

/// Check the drive layout against the ESI PDOs; returns the image length in bytes.
fn check_layout(
    direction: &'static str,
    def: &DriveDefinition,
    layout: &crate::drive::pdo::PdoLayout,
    pdos: &[&Pdo],
) -> Result<usize, ServoError> {
    let drive_entries: Vec<(u16, u8, u32)> = layout
        .entries()
        .iter()
        .map(|e| (e.index, e.sub, 8 * e.ty.size() as u32))
        .collect();
    let esi_entries: Vec<(u16, u8, u32)> = pdos
        .iter()
        .flat_map(|p| p.entries.iter())
        .filter(|e| e.index != 0)
        .map(|e| (e.index, e.subindex, u32::from(e.bit_len)))
        .collect();
    let esi_bits: u32 = pdos.iter().map(|p| p.bit_len()).sum();
    let drive_bytes = layout.len();
    // The same objects with the same sizes; the order may differ (the master remaps in PRE-OP).
    let sorted = |v: &[(u16, u8, u32)]| {
        let mut v = v.to_vec();
        v.sort_unstable();
        v
    };
    if sorted(&drive_entries) != sorted(&esi_entries)
        || !esi_bits.is_multiple_of(8)
        || (esi_bits / 8) as usize != drive_bytes
    {
        return Err(ServoError::PdoMismatch {
            direction,
            drive: def.name.clone(),
            drive_entries,
            drive_bytes,
            esi_entries,
            esi_bits,
        });
    }
    Ok(drive_bytes)
}

/// Sub-indices each PDO mapping object offers (a master may map up to this many entries).
pub const MAPPING_CAPACITY: u8 = 16;
/// Sub-indices each PDO assignment object offers.
pub const ASSIGN_CAPACITY: u8 = 4;

/// Does the ESI declare SDO complete access for `device` (`Mailbox/CoE@CompleteAccess`)?
pub(crate) fn esi_complete_access(device: &Device) -> bool {
    device
        .mailbox
        .as_ref()
        .and_then(|m| m.coe.as_ref())
        .is_some_and(|c| c.complete_access)
}

/// Assignment object (0x1C12/0x1C13) and mapping objects of `pdos`: the CoE entries a master
/// reads to discover the PDO mapping, and writes in PRE-OP to change it (CiA 301 procedure:
/// sub 0 = 0, entries, sub 0 = count). They hold the ESI default mapping at start; the
/// application checks the mapping against the drive model on PRE-OP → SAFE-OP (AL status
/// 0x0024 / 0x0025 if an entry cannot be mapped).
pub fn pdo_objects(assign_index: u16, pdos: &[&Pdo]) -> Vec<ObjectEntry> {
    let rw = |index, sub, ty: DataType, value: i64| ObjectEntry {
        access: Access::Rw,
        ..ObjectEntry::constant(index, sub, ty, value)
    };
    let mut v = vec![rw(assign_index, 0, DataType::U8, pdos.len() as i64)];
    for k in 1..=ASSIGN_CAPACITY.max(pdos.len() as u8) {
        let pdo = pdos
            .get(usize::from(k) - 1)
            .map_or(0, |p| i64::from(p.index));
        v.push(rw(assign_index, k, DataType::U16, pdo));
    }
    for p in pdos {
        v.push(rw(p.index, 0, DataType::U8, p.entries.len() as i64));
        for j in 1..=MAPPING_CAPACITY.max(p.entries.len() as u8) {
            let m = p
                .entries
                .get(usize::from(j) - 1)
                .map_or(0, |e| i64::from(e.mapping_value()));
            v.push(rw(p.index, j, DataType::U32, m));
        }
    }
    v
}

/// Emulated CiA 402 servo with the [`DEFAULT_CYCLE`] time base. See the module documentation.
pub fn emulated_servo(
    esi: &EsiFile,
    device: &Device,
    def: &DriveDefinition,
) -> Result<Esc, ServoError> {
    emulated_drive(esi, device, def, DEFAULT_CYCLE)
}

/// Emulated CiA 402 servo whose model advances by `cycle` per process-data exchange.
pub fn emulated_servo_with_cycle(
    esi: &EsiFile,
    device: &Device,
    def: &DriveDefinition,
    cycle: Duration,
) -> Result<Esc, ServoError> {
    emulated_drive(esi, device, def, cycle)
}

/// Emulated drive of any family with a mailbox: the drive model of `def` behind a CoE server
/// (object-dictionary families) or an SoE server (SERCOS), process data laid out as the ESI's
/// default PDOs, which must carry exactly the drive definition's entries (CiA 402) or its
/// image sizes (SERCOS, whose ESI entries are IDNs).
pub fn emulated_drive(
    esi: &EsiFile,
    device: &Device,
    def: &DriveDefinition,
    cycle: Duration,
) -> Result<Esc, ServoError> {
    let cycle_ns = u64::try_from(cycle.as_nanos()).unwrap_or(u64::MAX);
    if cycle_ns == 0 {
        return Err(ServoError::ZeroCycle);
    }
    let content = sii_from_device(esi, device)?;
    let cfg = EscConfig::from_sii(sii::encode_padded(&content)?);
    let terminal = def.profile == crate::drive::catalogue::Profile::Terminal;
    let mbx = match cfg.mailbox {
        Some(_) if !terminal && matches!(mailbox_error(device), ServoError::MailboxSize { .. }) => {
            return Err(mailbox_error(device))
        }
        Some(m) => Some(m),
        None if terminal => None,
        None => return Err(mailbox_error(device)),
    };

    let rx_pdos = assigned(&device.rx_pdos, cfg.output_sm);
    let tx_pdos = assigned(&device.tx_pdos, cfg.input_sm);
    let model =
        crate::drive::model::for_definition(def).map_err(|e| ServoError::Model(e.to_string()))?;
    let (rx_len, tx_len) = (model.rx_len(), model.tx_len());
    let sercos = def.profile == crate::drive::catalogue::Profile::Sercos;
    // SERCOS: IDNs in the ESI; terminal: the terminal's own objects (0x6000 / 0x7000 …) for the
    // drive file's combined image. Both are checked by size.
    if sercos || terminal {
        check_sizes("rx", def, rx_len, &rx_pdos)?;
        check_sizes("tx", def, tx_len, &tx_pdos)?;
    } else {
        check_layout("rx", def, &def.rxpdo, &rx_pdos)?;
        check_layout("tx", def, &def.txpdo, &tx_pdos)?;
    }
    let identity = |first: u16| {
        [
            ObjectEntry::constant(first, 0, DataType::U8, 4),
            ObjectEntry::constant(first, 1, DataType::U32, i64::from(esi.vendor.id)),
            ObjectEntry::constant(first, 2, DataType::U32, i64::from(device.product_code)),
            ObjectEntry::constant(first, 3, DataType::U32, i64::from(device.revision_no)),
            ObjectEntry::constant(first, 4, DataType::U32, 0),
        ]
    };
    let server = match mbx {
        Some(mbx) if !terminal => {
            if sercos {
                MailboxServer::Soe(SoeServer::new(
                    model,
                    sercos_idns(),
                    usize::from(mbx.tx_size),
                ))
            } else {
                let mut entries = ds402_objects(device.name());
                entries.extend(identity(0x1018));
                entries.extend(pdo_objects(0x1C12, &rx_pdos));
                entries.extend(pdo_objects(0x1C13, &tx_pdos));
                if let Some(dict) = device.dictionary() {
                    align_with_esi(&mut entries, dict, model.as_ref());
                }
                let mut coe = CoeServer::new(model, entries, usize::from(mbx.tx_size));
                coe.set_complete_access(esi_complete_access(device));
                if let Some(dict) = device.dictionary() {
                    coe.set_descriptions(OdDescriptions::from_esi(dict, coe.entries()));
                }
                MailboxServer::Coe(coe)
            }
        }
        _ => MailboxServer::None(model),
    };
    let identity_plan = |len: usize| {
        vec![Span {
            bus: 0,
            model: 0,
            bits: 8 * len,
            object: None,
        }]
    };
    let mut app = ServoApp {
        server,
        model_rx: def.rxpdo.clone(),
        model_tx: def.txpdo.clone(),
        outputs: vec![0; rx_len],
        inputs: vec![0; tx_len],
        bus_rx_len: rx_len,
        bus_tx_len: tx_len,
        rx_plan: identity_plan(rx_len),
        tx_plan: identity_plan(tx_len),
        exchanges: 0,
        cycle_ns,
        synchronized: false,
        od_spans: false,
        roles: Vec::new(),
        rx_unfed: Vec::new(),
    };
    app.remap().map_err(|_| ServoError::PdoMismatch {
        direction: "rx/tx",
        drive: def.name.clone(),
        drive_entries: Vec::new(),
        drive_bytes: rx_len + tx_len,
        esi_entries: Vec::new(),
        esi_bits: 0,
    })?;
    Ok(Esc::new(cfg, Box::new(app)))
}

/// The server's table as the ESI dictionary declares the device (ETG.2000 `Profile/Dictionary`):
/// * sub-indices of an object the ESI declares with sub-items that the ESI does not list are
///   dropped (e.g. the assignment and mapping objects offer as many entries as their ESI data
///   type has, not [`ASSIGN_CAPACITY`] / [`MAPPING_CAPACITY`]) — unless the object's default
///   content needs them;
/// * a single-value object the ESI declares and the table lacks is added: backed by the drive
///   model when the model answers it (e.g. the touch-probe edge counters 0x60D5–0x60D8), else
///   a constant with the ESI `DefaultData`; an object with neither is left out;
/// * a VISIBLE_STRING object with a default in the ESI (0x1008, 0x1009, 0x100A) serves that
///   text (it replaces the device name the table starts with).
fn align_with_esi(
    entries: &mut Vec<ObjectEntry>,
    dict: &crate::esi::Dictionary,
    model: &dyn DriveModel,
) {
    use crate::bus::ethercat::sdo_info::data_type_of_esi_name;
    for o in &dict.objects {
        let declared: Option<Vec<u8>> = dict
            .data_type(&o.type_name)
            .filter(|t| !t.subitems.is_empty() && t.subitems.iter().all(|s| s.subindex.is_some()))
            .map(|t| t.subitems.iter().filter_map(|s| s.subindex).collect());
        if let Some(subs) = declared {
            let used = entries
                .iter()
                .filter(|e| e.index == o.index && e.sub == 0)
                .find_map(|e| e.data.as_ref().and_then(|d| d.first().copied()))
                .unwrap_or(0);
            entries.retain(|e| e.index != o.index || subs.contains(&e.sub) || e.sub <= used);
            continue;
        }
        if data_type_of_esi_name(&o.type_name) == Some(0x0009) {
            // A VISIBLE_STRING with a default (0x1008 device name, 0x1009 hardware version,
            // 0x100A software version): the device serves the ESI's text, so a configurator
            // shows what the file says (ETG.2000 `DefaultString` / `DefaultData`).
            if let Some(d) = &o.default_data {
                let len = usize::try_from(o.bit_size / 8).unwrap_or(usize::MAX);
                let text: Vec<u8> = d.iter().copied().take(len).collect();
                entries.retain(|e| e.index != o.index);
                entries.push(ObjectEntry::bytes(o.index, 0, Access::Ro, &text, len));
            }
            continue;
        }
        if entries.iter().any(|e| e.index == o.index) {
            continue;
        }
        let ty = match (data_type_of_esi_name(&o.type_name), o.bit_size) {
            (Some(0x0001 | 0x0005), 8) => DataType::U8,
            (Some(0x0002), 8) => DataType::I8,
            (Some(0x0003), 16) => DataType::I16,
            (Some(0x0006), 16) => DataType::U16,
            (Some(0x0004), 32) => DataType::I32,
            (Some(0x0007), 32) => DataType::U32,
            (Some(0x0015), 64) => DataType::I64,
            (Some(0x001B), 64) => DataType::U64,
            _ => continue,
        };
        let access = match o.flags.access {
            Some(crate::esi::Access::ReadWrite) => Access::Rw,
            Some(crate::esi::Access::WriteOnly) => Access::Wo,
            _ => Access::Ro,
        };
        if model.read_object(o.index, 0).is_ok() {
            entries.push(ObjectEntry::model(o.index, 0, ty, access));
        } else if let Some(d) = &o.default_data {
            if d.len() == ty.size().unwrap_or(0) {
                entries.push(ObjectEntry {
                    access,
                    data: Some(d.clone()),
                    ..ObjectEntry::constant(o.index, 0, ty, 0)
                });
            }
        }
    }
}

/// SERCOS: the ESI telegram sizes must equal the model's image sizes.
fn check_sizes(
    direction: &'static str,
    def: &DriveDefinition,
    model_bytes: usize,
    pdos: &[&Pdo],
) -> Result<(), ServoError> {
    let esi_bits: u32 = pdos.iter().map(|p| p.bit_len()).sum();
    if !esi_bits.is_multiple_of(8) || (esi_bits / 8) as usize != model_bytes {
        return Err(ServoError::PdoMismatch {
            direction,
            drive: def.name.clone(),
            drive_entries: Vec::new(),
            drive_bytes: model_bytes,
            esi_entries: pdos
                .iter()
                .flat_map(|p| p.entries.iter())
                .map(|e| (e.index, e.subindex, u32::from(e.bit_len)))
                .collect(),
            esi_bits,
        });
    }
    Ok(())
}

/// Emulated EL1252-kind timestamp terminal: the ESI device's SII, no mailbox, inputs = the
/// terminal image of [`El1252Device`](crate::drive::model::el1252::El1252Device) (`channels`
/// channels stamping with `clock`). Hosted in a segment's world, a probe surface wired to
/// `(its world index, channel)` stamps its edges.
pub fn emulated_el1252(
    esi: &EsiFile,
    device: &Device,
    channels: usize,
    mode: crate::drive::el1252::LatchMode,
    clock: crate::core::measure::timestamp::DcClock,
) -> Result<Esc, ServoError> {
    let content = sii_from_device(esi, device)?;
    let cfg = EscConfig::from_sii(sii::encode_padded(&content)?);
    let model = crate::drive::model::el1252::El1252Device::new(channels, mode, clock);
    let tx_len = model.image_len();
    // Inputs only: every TxPDO the ESI assigns to a sync manager.
    let esi_bits: u32 = device
        .tx_pdos
        .iter()
        .filter(|p| p.sm.is_some())
        .map(|p| p.bit_len())
        .sum();
    if esi_bits != 8 * tx_len as u32 {
        return Err(ServoError::PdoMismatch {
            direction: "tx",
            drive: "el1252".into(),
            drive_entries: Vec::new(),
            drive_bytes: tx_len,
            esi_entries: Vec::new(),
            esi_bits,
        });
    }
    let empty = crate::drive::pdo::PdoLayout::default();
    let app = ServoApp {
        server: MailboxServer::None(Box::new(model)),
        model_rx: empty.clone(),
        model_tx: empty,
        outputs: Vec::new(),
        inputs: vec![0; tx_len],
        bus_rx_len: 0,
        bus_tx_len: tx_len,
        rx_plan: Vec::new(),
        tx_plan: vec![Span {
            bus: 0,
            model: 0,
            bits: 8 * tx_len,
            object: None,
        }],
        exchanges: 0,
        cycle_ns: DEFAULT_CYCLE.as_nanos() as u64,
        synchronized: false,
        od_spans: false,
        roles: Vec::new(),
        rx_unfed: Vec::new(),
    };
    Ok(Esc::new(cfg, Box::new(app)))
}
