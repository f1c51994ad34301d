//! Emulated EtherCAT servo: an [`Esc`] built from an ESI device description with a CiA 402
//! drive model ([`Ds402Model`]) behind a CoE mailbox server ([`CoeServer`]).
//!
//! * SII: [`sii_from_device`] of the ESI device, padded ([`sii::encode_padded`]); the ESC
//!   configuration is [`EscConfig::from_sii`].
//! * Object dictionary: [`ds402_objects`] plus 0x1018 identity (vendor, product code, revision
//!   from the ESI; serial 0 like the SII), the PDO assignment objects 0x1C12/0x1C13 (the PDOs
//!   the ESI assigns to SM2/SM3 by default) and the mapping objects (0x1600.., 0x1A00..) with the
//!   CiA 301 mapping values `index << 16 | sub << 8 | bits`. All are read-only constants, which
//!   is enough for a MainDevice that discovers the mapping by reading them (ethercrab 0.7.1
//!   reads 0x1C12/0x1C13:0.., then each PDO's :0.. with expedited uploads; notes §2.4). All of
//!   them are ≤ 4 bytes, so the server answers them expedited.
//! * Process data: the SM2 output image is kept when the master writes it (OP only, see
//!   [`Esc`]); every read of the SM3 input image is one exchange: the model runs
//!   `begin_step(now, dt, outputs)` then `finish_step(inputs)`. With a single LRW per cycle
//!   the inputs are read before that datagram's outputs are written, so the model sees the
//!   outputs of the previous cycle (like a real drive sampling at SYNC).
//! * Time: the emulator has no clock of its own here. Exchange `k` (counting from 1) covers the
//!   cycle ending at `now = k · cycle`, `dt = cycle`, where `cycle` is the configured cycle time
//!   ([`DEFAULT_CYCLE`] for [`emulated_servo`], or the argument of
//!   [`emulated_servo_with_cycle`]). Model time therefore advances by one cycle per process-data
//!   exchange, independent of the master's wall clock.
//!
//! The drive definition's PDO layout must equal the ESI's default mapping: the same entries
//! (index, sub-index, bit length, gaps excluded) in the same order and the same image lengths;
//! otherwise [`emulated_servo`] fails with [`ServoError::PdoMismatch`].

use std::time::Duration;

use super::app::{EscApplication, ProcessDataSizes};
use super::coe::{ds402_objects, CoeServer, DataType, ObjectEntry};
use super::{Esc, EscConfig};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::model::ds402::Ds402Model;
use crate::drive::model::DriveModel;
use crate::esi::sii::{self, SiiError};
use crate::esi::to_sii::sii_from_device;
use crate::esi::{Device, EsiFile, Pdo};
use crate::units::Nanos;

/// Cycle time [`emulated_servo`] uses for the model's `now`/`dt` (1 ms).
pub const DEFAULT_CYCLE: Duration = Duration::from_millis(1);

/// Why an emulated servo could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServoError {
    /// The SII image could not be built from the ESI device.
    #[error("SII image of the ESI device: {0}")]
    Sii(#[from] SiiError),
    /// The ESI device has no standard mailbox (no CoE possible).
    #[error("ESI device {0} has no mailbox")]
    NoMailbox(String),
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
    /// The cycle time is zero.
    #[error("cycle time must be > 0")]
    ZeroCycle,
}

/// The application of the emulated servo: CoE server (owning the drive model) plus the
/// process-data glue. See the module documentation for the time base.
#[derive(Debug)]
pub struct ServoApp {
    coe: CoeServer,
    sizes: ProcessDataSizes,
    outputs: Vec<u8>,
    exchanges: u64,
    cycle_ns: u64,
}

impl ServoApp {
    /// The CoE server (and through it the drive model).
    pub fn coe(&self) -> &CoeServer {
        &self.coe
    }

    /// The CoE server, mutable.
    pub fn coe_mut(&mut self) -> &mut CoeServer {
        &mut self.coe
    }

    /// Process-data exchanges (input image reads) so far.
    pub fn exchanges(&self) -> u64 {
        self.exchanges
    }

    /// The last output image the master wrote (zeros before the first write).
    pub fn outputs(&self) -> &[u8] {
        &self.outputs
    }
}

impl EscApplication for ServoApp {
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        self.coe.handle(data)
    }

    fn outputs_written(&mut self, _sm: u8, data: &[u8]) {
        let n = data.len().min(self.outputs.len());
        self.outputs[..n].copy_from_slice(&data[..n]);
    }

    fn inputs(&mut self, _sm: u8, buf: &mut [u8]) {
        self.exchanges += 1;
        let now = Nanos(self.exchanges.saturating_mul(self.cycle_ns));
        let dt = self.cycle_ns as f64 * 1e-9;
        let model = self.coe.model_mut();
        model.begin_step(now, dt, &self.outputs);
        let mut tx = vec![0u8; model.tx_len()];
        model.finish_step(&mut tx);
        let n = buf.len().min(tx.len());
        buf[..n].copy_from_slice(&tx[..n]);
    }

    fn process_data_sizes(&self) -> ProcessDataSizes {
        self.sizes
    }
}

/// PDOs of `pdos` the ESI assigns to sync manager `sm` by default.
fn assigned(pdos: &[Pdo], sm: u8) -> Vec<&Pdo> {
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
    if drive_entries != esi_entries || esi_bits % 8 != 0 || (esi_bits / 8) as usize != drive_bytes {
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

/// Assignment object (0x1C12/0x1C13) and mapping objects of `pdos`: the CoE entries a master
/// reads to discover the PDO mapping.
pub fn pdo_objects(assign_index: u16, pdos: &[&Pdo]) -> Vec<ObjectEntry> {
    let mut v = vec![ObjectEntry::constant(
        assign_index,
        0,
        DataType::U8,
        pdos.len() as i64,
    )];
    for (i, p) in pdos.iter().enumerate() {
        v.push(ObjectEntry::constant(
            assign_index,
            (i + 1) as u8,
            DataType::U16,
            i64::from(p.index),
        ));
        v.push(ObjectEntry::constant(
            p.index,
            0,
            DataType::U8,
            p.entries.len() as i64,
        ));
        for (j, e) in p.entries.iter().enumerate() {
            v.push(ObjectEntry::constant(
                p.index,
                (j + 1) as u8,
                DataType::U32,
                i64::from(e.mapping_value()),
            ));
        }
    }
    v
}

/// Emulated servo with the [`DEFAULT_CYCLE`] time base. See the module documentation.
pub fn emulated_servo(
    esi: &EsiFile,
    device: &Device,
    def: &DriveDefinition,
) -> Result<Esc, ServoError> {
    emulated_servo_with_cycle(esi, device, def, DEFAULT_CYCLE)
}

/// Emulated servo whose model advances by `cycle` per process-data exchange.
pub fn emulated_servo_with_cycle(
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
    let mbx = cfg
        .mailbox
        .ok_or_else(|| ServoError::NoMailbox(device.type_name.clone()))?;

    let rx_pdos = assigned(&device.rx_pdos, cfg.output_sm);
    let tx_pdos = assigned(&device.tx_pdos, cfg.input_sm);
    let rx_len = check_layout("rx", def, &def.rxpdo, &rx_pdos)?;
    let tx_len = check_layout("tx", def, &def.txpdo, &tx_pdos)?;

    let model = Ds402Model::new(def);
    debug_assert_eq!(DriveModel::rx_len(&model), rx_len);
    debug_assert_eq!(DriveModel::tx_len(&model), tx_len);

    let mut entries = ds402_objects(device.name());
    entries.extend([
        ObjectEntry::constant(0x1018, 0, DataType::U8, 4),
        ObjectEntry::constant(0x1018, 1, DataType::U32, i64::from(esi.vendor.id)),
        ObjectEntry::constant(0x1018, 2, DataType::U32, i64::from(device.product_code)),
        ObjectEntry::constant(0x1018, 3, DataType::U32, i64::from(device.revision_no)),
        ObjectEntry::constant(0x1018, 4, DataType::U32, 0),
    ]);
    entries.extend(pdo_objects(0x1C12, &rx_pdos));
    entries.extend(pdo_objects(0x1C13, &tx_pdos));

    let coe = CoeServer::new(Box::new(model), entries, usize::from(mbx.tx_size));
    let app = ServoApp {
        coe,
        sizes: ProcessDataSizes {
            outputs: rx_len as u16,
            inputs: tx_len as u16,
        },
        outputs: vec![0; rx_len],
        exchanges: 0,
        cycle_ns,
    };
    Ok(Esc::new(cfg, Box::new(app)))
}
