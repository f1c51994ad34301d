//! What an emulated node checks in an SDO download besides access and size (the object table
//! checks those): the value range an EDS gives (`LowLimit` / `HighLimit`), and the CiA 301 PDO
//! configuration procedure (§7.5.2.35 – §7.5.2.38: destroy the PDO, set the mapping's
//! sub-index 0 to 0, write the entries, set sub-index 0 to their number, create the PDO).
//!
//! Abort codes (CiA 301 §7.2.4.3.17; the procedure's checks as CANopenNode's `CO_PDO.c`
//! answers them):
//! * a value below `LowLimit` → 0x0609_0032, above `HighLimit` → 0x0609_0031;
//! * a mapping parameter (0x1600 … 0x17FF, 0x1A00 … 0x1BFF) written while its PDO exists
//!   (COB-ID bit 31 = 0), or an entry (sub-index ≥ 1) written while sub-index 0 ≠ 0 →
//!   0x0609_0030 "invalid value for parameter";
//! * an entry naming an object the dictionary does not have → 0x0602_0000; an object that
//!   cannot be mapped into this direction, or with another bit length → 0x0604_0041. Into an
//!   RPDO / a TPDO may go: on a node built from an EDS, the objects with `PDOMapping=1` whose
//!   `AccessType` allows that direction ([`eds::Entry::pdo_directions`]); on the built-in node,
//!   the drive model's process data of that direction and every other object it may write
//!   (RPDO) / read (TPDO);
//! * sub-index 0 = n > 0 checks entries 1 … n again (0x0604_0041 / 0x0602_0000) and their
//!   total length: more than 64 bits → 0x0604_0042;
//! * a COB-ID (sub-index 1 of 0x1400 … 0x15FF, 0x1800 … 0x19FF) that keeps the PDO existing
//!   but changes its identifier (bits 0 … 29), a valid COB-ID on a restricted CAN-ID (CiA 301
//!   §7.3.5, [`crate::bus::canopen::pdo::RESTRICTED_CAN_IDS`]: 0x000, the SDO channels …) or
//!   with a 29-bit identifier, and a transmission type 241 … 251 (reserved) → 0x0609_0030.

use std::collections::BTreeMap;

use crate::bus::canopen::eds::{self, Eds};
use crate::bus::canopen::pdo::check_pdo_cob_id;
use crate::drive::pdo::PdoLayout;
use crate::sim::esc::coe::{Access, CoeServer, DataType};

/// 0x06020000: object does not exist in the object dictionary.
pub const NO_OBJECT: u32 = 0x0602_0000;
/// 0x06040041: object cannot be mapped to the PDO.
pub const NOT_MAPPABLE: u32 = 0x0604_0041;
/// 0x06040042: the number and length of the objects to be mapped would exceed the PDO length.
pub const PDO_TOO_LONG: u32 = 0x0604_0042;
/// 0x06090030: invalid value for parameter (download only).
pub const INVALID_VALUE: u32 = 0x0609_0030;
/// 0x06090031: value of parameter written too high.
pub const VALUE_TOO_HIGH: u32 = 0x0609_0031;
/// 0x06090032: value of parameter written too low.
pub const VALUE_TOO_LOW: u32 = 0x0609_0032;

/// Into which PDOs an object may be mapped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Directions {
    /// Into an RPDO (the master writes it).
    pub rx: bool,
    /// Into a TPDO (the node sends it).
    pub tx: bool,
}

/// The range of a numeric object (`LowLimit` / `HighLimit`, either may be absent).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Range {
    low: Option<i128>,
    high: Option<i128>,
}

/// The rules of one node (see the module documentation).
#[derive(Debug, Clone, Default)]
pub struct NodeRules {
    /// EDS node: the objects with `PDOMapping=1` and their directions; `None`: the built-in
    /// node (mappable = what it can serve).
    mappable: Option<BTreeMap<(u16, u8), Directions>>,
    ranges: BTreeMap<(u16, u8), Range>,
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

/// `data` as a number of type `ty` (sign-extended for the signed types); `None` for byte
/// strings or a length that is not the type's.
fn number(ty: DataType, data: &[u8]) -> Option<i128> {
    let v = ty.decode(data)?;
    Some(match ty {
        DataType::I8 | DataType::I16 | DataType::I32 | DataType::I64 => i128::from(v),
        _ => i128::from(v as u64),
    })
}

impl NodeRules {
    /// The rules of a node built from `eds` for node id `node` (`$NODEID` in limits).
    pub fn from_eds(eds: &Eds, node: u8) -> Self {
        let mut mappable = BTreeMap::new();
        let mut ranges = BTreeMap::new();
        let limit = |v: Option<eds::Value>| -> Option<i128> {
            match v? {
                eds::Value::Integer(i) => Some(i128::from(i)),
                eds::Value::Unsigned(u) => Some(i128::from(u)),
                eds::Value::Bool(b) => Some(i128::from(b)),
                _ => None,
            }
        };
        for (&key, e) in &eds.objects {
            let (rx, tx) = e.pdo_directions();
            if rx || tx {
                mappable.insert(key, Directions { rx, tx });
            }
            if !e.data_type.is_integer() {
                continue;
            }
            let range = Range {
                low: limit(e.low_limit_value(node)),
                high: limit(e.high_limit_value(node)),
            };
            if range.low.is_some() || range.high.is_some() {
                ranges.insert(key, range);
            }
        }
        NodeRules {
            mappable: Some(mappable),
            ranges,
        }
    }

    /// Into which PDOs `index:sub` may be mapped by this node's description: the EDS's
    /// `PDOMapping` and access; `None` on the built-in node (no description beyond what it
    /// serves).
    pub fn directions(&self, index: u16, sub: u8) -> Option<Directions> {
        self.mappable
            .as_ref()
            .map(|m| m.get(&(index, sub)).copied().unwrap_or_default())
    }

    /// Check a download of `data` to `index:sub` of `od` (the model's process data `layouts`
    /// = (RPDO, TPDO) layout; `fixed_len` the byte strings of one length); `Err` is the abort
    /// code. Objects that do not exist or are read-only pass: the object table refuses them
    /// with its own code.
    pub fn check(
        &self,
        od: &CoeServer,
        layouts: (&PdoLayout, &PdoLayout),
        fixed_len: &BTreeMap<(u16, u8), usize>,
        (index, sub): (u16, u8),
        data: &[u8],
    ) -> Result<(), u32> {
        let Some(entry) = od
            .entries()
            .iter()
            .find(|e| (e.index, e.sub) == (index, sub))
        else {
            return Ok(());
        };
        if entry.access == Access::Ro {
            return Ok(());
        }
        if let (Some(r), Some(v)) = (self.ranges.get(&(index, sub)), number(entry.ty, data)) {
            if r.low.is_some_and(|low| v < low) {
                return Err(VALUE_TOO_LOW);
            }
            if r.high.is_some_and(|high| v > high) {
                return Err(VALUE_TOO_HIGH);
            }
        }
        let read = |i: u16, s: u8| od.read(i, s).ok().map(|d| le_u32(&d));
        let comm = (0x1400..=0x15FF).contains(&index) || (0x1800..=0x19FF).contains(&index);
        if comm {
            let v = le_u32(data);
            if sub == 1 {
                // A valid PDO on a restricted CAN-ID (the NMT id 0x000, the SDO channels …,
                // CiA 301 §7.3.5) or on a 29-bit id the node does not serve.
                if check_pdo_cob_id(v).is_err() {
                    return Err(INVALID_VALUE);
                }
                let old = read(index, 1).unwrap_or(0x8000_0000);
                let exists = |c: u32| c & 0x8000_0000 == 0;
                if exists(v) && exists(old) && (v & 0x3FFF_FFFF) != (old & 0x3FFF_FFFF) {
                    return Err(INVALID_VALUE);
                }
            }
            if sub == 2 && (241..=251).contains(&v) {
                return Err(INVALID_VALUE);
            }
            return Ok(());
        }
        let rx = is_rx_mapping(index);
        if !rx && !is_tx_mapping(index) {
            return Ok(());
        }
        // The PDO must not exist while its mapping changes.
        if read(index - 0x200, 1).is_some_and(|cob| cob & 0x8000_0000 == 0) {
            return Err(INVALID_VALUE);
        }
        let layout = if rx { layouts.0 } else { layouts.1 };
        let mapping = |v: u32| self.mapping_ok(od, layout, fixed_len, rx, v);
        if sub == 0 {
            let n = data.first().copied().unwrap_or(0);
            let mut bits = 0u32;
            for k in 1..=n {
                let v = read(index, k).ok_or(VALUE_TOO_HIGH)?;
                mapping(v)?;
                bits += v & 0xFF;
            }
            if bits > 64 {
                return Err(PDO_TOO_LONG);
            }
            return Ok(());
        }
        if read(index, 0).unwrap_or(0) != 0 {
            return Err(INVALID_VALUE);
        }
        let v = le_u32(data);
        if v == 0 {
            return Ok(());
        }
        mapping(v)
    }

    /// May the mapping entry `v` (index << 16 | sub << 8 | bits) go into an RPDO (`rx`) / a
    /// TPDO of this node?
    fn mapping_ok(
        &self,
        od: &CoeServer,
        layout: &PdoLayout,
        fixed_len: &BTreeMap<(u16, u8), usize>,
        rx: bool,
        v: u32,
    ) -> Result<(), u32> {
        let (index, sub, bits) = ((v >> 16) as u16, (v >> 8) as u8, (v & 0xFF) as usize);
        let Some(e) = od
            .entries()
            .iter()
            .find(|e| (e.index, e.sub) == (index, sub))
        else {
            return Err(NO_OBJECT);
        };
        let size =
            e.ty.size()
                .or_else(|| fixed_len.get(&(index, sub)).copied());
        if bits == 0 || size.map(|n| 8 * n) != Some(bits) {
            return Err(NOT_MAPPABLE);
        }
        let allowed = match &self.mappable {
            Some(m) => m
                .get(&(index, sub))
                .is_some_and(|d| if rx { d.rx } else { d.tx }),
            None => {
                layout.contains(index, sub)
                    || if rx {
                        e.access != Access::Ro
                    } else {
                        e.access != Access::Wo
                    }
            }
        };
        if allowed {
            Ok(())
        } else {
            Err(NOT_MAPPABLE)
        }
    }
}
