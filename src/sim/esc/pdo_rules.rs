//! PDO configuration rules of an emulated vendor device: which SDO downloads to the PDO mapping
//! objects (0x1600–0x17FF RxPDO, 0x1A00–0x1BFF TxPDO) and the PDO assignment objects
//! (0x1C12 outputs, 0x1C13 inputs) a [`CoeServer`] accepts, and the SDO
//! abort code of a refusal.
//!
//! The rules (CiA 301 §7.5.2.35 / §7.5.2.36 PDO mapping procedure, ETG.1000.6 §5.6.7.4 PDO
//! assignment, ETG.1020 "PDO configuration"):
//! * the objects are writable in PRE-OP only: elsewhere 0x0800_0022 "data cannot be
//!   transferred or stored because of the present device state";
//! * a mapping or assignment entry (sub-index ≥ 1) is written only while sub-index 0 is 0:
//!   else 0x0601_0003 "sub-index cannot be written, SI0 must be 0 for write access"
//!   (ETG.1000.6 abort code table);
//! * a mapping entry names an object the dictionary holds (else 0x0602_0000) that the device
//!   marks mappable in the PDO's direction with exactly that bit length (the SDO Information
//!   entry description: ESI `Flags/PdoMapping` R / T, `BitSize`), else 0x0604_0041 "object
//!   cannot be mapped to the PDO"; index 0 is a gap of any length;
//! * an assignment entry names 0 or an existing mapping object of its direction, else
//!   0x0609_0030 "invalid value for parameter";
//! * sub-index 0 = N is accepted when entries 1..N exist (else 0x0609_0031 "value too high")
//!   and the mapped bits fit the sync manager: a mapping object's PDO alone, an assignment's
//!   PDOs together, at most the sync manager's size limit ([`PdoRules::new`]); else
//!   0x0604_0042 "the number and length of the objects to be mapped would exceed the PDO
//!   length".
//!
//! Everything else (data type, read-only access) is the server's ordinary checking.

use super::coe::CoeServer;
use crate::bus::ethercat::sdo_info::access;

/// 0x08000022: data cannot be transferred or stored because of the present device state.
pub const STATE: u32 = 0x0800_0022;
/// 0x06010003: sub-index cannot be written, SI0 must be 0 for write access (ETG.1000.6).
pub const SI0_NOT_ZERO: u32 = 0x0601_0003;
/// 0x06020000: object does not exist in the object dictionary.
pub const NO_OBJECT: u32 = 0x0602_0000;
/// 0x06040041: object cannot be mapped to the PDO.
pub const NOT_MAPPABLE: u32 = 0x0604_0041;
/// 0x06040042: the number and length of the objects to be mapped would exceed the PDO length.
pub const PDO_TOO_LONG: u32 = 0x0604_0042;
/// 0x06090030: invalid value for parameter.
pub const INVALID_VALUE: u32 = 0x0609_0030;
/// 0x06090031: value of parameter written too high.
pub const VALUE_TOO_HIGH: u32 = 0x0609_0031;

/// The PDO configuration rules of one device (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoRules {
    /// The device is in PRE-OP (set by the application on every state change).
    editable: bool,
    /// Most bytes of the outputs (SM2) / inputs (SM3).
    max_outputs: usize,
    max_inputs: usize,
}

fn is_rx_mapping(index: u16) -> bool {
    (0x1600..=0x17FF).contains(&index)
}

fn is_tx_mapping(index: u16) -> bool {
    (0x1A00..=0x1BFF).contains(&index)
}

fn le_u32(data: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    let n = data.len().min(4);
    b[..n].copy_from_slice(&data[..n]);
    u32::from_le_bytes(b)
}

impl PdoRules {
    /// Rules for a device whose output / input sync managers hold at most `max_outputs` /
    /// `max_inputs` bytes; not editable until [`Self::set_editable`].
    pub fn new(max_outputs: usize, max_inputs: usize) -> Self {
        Self {
            editable: false,
            max_outputs,
            max_inputs,
        }
    }

    /// The device entered (`true`: PRE-OP) or left the state in which the PDO configuration
    /// may change.
    pub fn set_editable(&mut self, on: bool) {
        self.editable = on;
    }

    /// Is the PDO configuration writable now?
    pub fn editable(&self) -> bool {
        self.editable
    }

    /// Check a download of `data` to `index:sub` against the rules; `Err` is the abort code.
    /// Objects other than the PDO mapping and assignment objects pass.
    pub fn check(&self, od: &CoeServer, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        let mapping = is_rx_mapping(index) || is_tx_mapping(index);
        let assign = index == 0x1C12 || index == 0x1C13;
        if !mapping && !assign {
            return Ok(());
        }
        if !self.editable {
            return Err(STATE);
        }
        let count = |i: u16| -> Option<u8> { od.read(i, 0).ok()?.first().copied() };
        let value = |i: u16, s: u8| -> Option<u32> { od.read(i, s).ok().map(|d| le_u32(&d)) };
        let v = le_u32(data);
        if sub == 0 {
            let n = data.first().copied().unwrap_or(0);
            if n == 0 {
                return Ok(());
            }
            if (1..=n).any(|k| od.read(index, k).is_err()) {
                return Err(VALUE_TOO_HIGH);
            }
            let bits_of = |pdo: u16, n: u8| -> u64 {
                (1..=n)
                    .filter_map(|k| value(pdo, k))
                    .map(|m| u64::from(m & 0xFF))
                    .sum()
            };
            let (bits, outputs) = if mapping {
                (bits_of(index, n), is_rx_mapping(index))
            } else {
                let total = (1..=n)
                    .filter_map(|k| value(index, k))
                    .map(|pdo| pdo as u16)
                    .map(|pdo| bits_of(pdo, count(pdo).unwrap_or(0)))
                    .sum();
                (total, index == 0x1C12)
            };
            let max = if outputs {
                self.max_outputs
            } else {
                self.max_inputs
            };
            if bits > 8 * max as u64 {
                return Err(PDO_TOO_LONG);
            }
            return Ok(());
        }
        if count(index).unwrap_or(0) != 0 {
            return Err(SI0_NOT_ZERO);
        }
        if assign {
            let range = if index == 0x1C12 {
                0x1600..=0x17FF
            } else {
                0x1A00..=0x1BFF
            };
            let pdo = v as u16;
            if v != 0 && (v > 0xFFFF || !range.contains(&pdo) || count(pdo).is_none()) {
                return Err(INVALID_VALUE);
            }
            return Ok(());
        }
        let (object, object_sub, bits) = ((v >> 16) as u16, ((v >> 8) & 0xFF) as u8, v & 0xFF);
        if object == 0 {
            return Ok(());
        }
        let Some(e) = od.descriptions().entry(object, object_sub) else {
            return Err(NO_OBJECT);
        };
        let direction = if is_rx_mapping(index) {
            access::RXPDO
        } else {
            access::TXPDO
        };
        if e.access & direction == 0 || u32::from(e.bit_len) != bits {
            return Err(NOT_MAPPABLE);
        }
        Ok(())
    }
}
