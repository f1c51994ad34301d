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

#[cfg(test)]
mod tests {
    //! The rules on a small dictionary: 0x6040 (16 bits) and 0x607A (32 bits) RxPDO-mappable,
    //! 0x6041 (16 bits) TxPDO-mappable, 0x2000 (32 bits) not mappable; mapping objects 0x1600
    //! and 0x1A00 (4 entries each), assignments 0x1C12 / 0x1C13 (2 entries each). Each test
    //! states the abort code CiA 301 / ETG.1000.6 demand for the case.

    use super::*;
    use crate::bus::ethercat::sdo_info::{access as a, EntryDescription};
    use crate::drive::catalogue;
    use crate::drive::model::ds402::Ds402Model;
    use crate::sim::esc::coe::{ds402_objects, Access, DataType, ObjectEntry};
    use crate::sim::esc::sdo_info::OdDescriptions;

    fn rw(index: u16, sub: u8, ty: DataType, v: i64) -> ObjectEntry {
        ObjectEntry {
            access: Access::Rw,
            ..ObjectEntry::constant(index, sub, ty, v)
        }
    }

    fn server() -> CoeServer {
        let def = catalogue::builtin("cia402-generic").unwrap();
        let mut od = CoeServer::new(
            Box::new(Ds402Model::new(&def)),
            ds402_objects("pdo rules test"),
            128,
        );
        for pdo in [0x1600u16, 0x1A00] {
            od.insert(rw(pdo, 0, DataType::U8, 0));
            for k in 1..=4 {
                od.insert(rw(pdo, k, DataType::U32, 0));
            }
        }
        for assign in [0x1C12u16, 0x1C13] {
            od.insert(rw(assign, 0, DataType::U8, 0));
            for k in 1..=2 {
                od.insert(rw(assign, k, DataType::U16, 0));
            }
        }
        od.insert(rw(0x2000, 0, DataType::U32, 0));
        let mut d = OdDescriptions::default();
        for (index, bits, acc) in [
            (0x6040u16, 16u16, a::READ | a::WRITE | a::RXPDO),
            (0x607A, 32, a::READ | a::WRITE | a::RXPDO),
            (0x6041, 16, a::READ | a::TXPDO),
            (0x2000, 32, a::READ | a::WRITE),
        ] {
            d.insert_entry(EntryDescription {
                index,
                sub: 0,
                value_info: 0x07,
                data_type: if bits == 16 { 0x0006 } else { 0x0007 },
                bit_len: bits,
                access: acc,
                name: String::new(),
            });
        }
        od.set_descriptions(d);
        od
    }

    fn rules(max_outputs: usize, max_inputs: usize) -> PdoRules {
        let mut r = PdoRules::new(max_outputs, max_inputs);
        r.set_editable(true);
        r
    }

    /// Map `entries` into `pdo` directly (the server's own write, no rules).
    fn map(od: &mut CoeServer, pdo: u16, entries: &[u32]) {
        od.write(pdo, 0, &[0]).unwrap();
        for (k, v) in entries.iter().enumerate() {
            od.write(pdo, k as u8 + 1, &v.to_le_bytes()).unwrap();
        }
    }

    #[test]
    fn length_exceeded_is_0x06040042() {
        let mut od = server();
        // 0x6040 (16) + 0x607A (32) = 48 bits = 6 bytes.
        map(&mut od, 0x1600, &[0x6040_0010, 0x607A_0020]);
        let r = rules(5, 8);
        assert_eq!(r.check(&od, 0x1600, 0, &[2]), Err(0x0604_0042));
        assert_eq!(r.check(&od, 0x1600, 0, &[1]), Ok(()), "16 bits fit 5 bytes");
        assert_eq!(
            rules(6, 8).check(&od, 0x1600, 0, &[2]),
            Ok(()),
            "exactly 6 bytes"
        );
        // The assignment adds up its PDOs: 0x1600 with 2 entries (6 bytes) in 5 bytes.
        od.write(0x1600, 0, &[2]).unwrap();
        od.write(0x1C12, 1, &0x1600u16.to_le_bytes()).unwrap();
        assert_eq!(r.check(&od, 0x1C12, 0, &[1]), Err(PDO_TOO_LONG));
        assert_eq!(rules(6, 0).check(&od, 0x1C12, 0, &[1]), Ok(()));
        // Sub-index 0 beyond the entries the object has: 0x06090031.
        assert_eq!(rules(64, 64).check(&od, 0x1600, 0, &[5]), Err(0x0609_0031));
    }

    #[test]
    fn bad_assignment_is_0x06090030() {
        let od = server();
        let r = rules(64, 64);
        let pdo = |i: u16| i.to_le_bytes();
        assert_eq!(
            r.check(&od, 0x1C12, 1, &pdo(0x1A00)),
            Err(0x0609_0030),
            "TxPDO on SM2"
        );
        assert_eq!(
            r.check(&od, 0x1C13, 1, &pdo(0x1600)),
            Err(0x0609_0030),
            "RxPDO on SM3"
        );
        assert_eq!(
            r.check(&od, 0x1C12, 1, &pdo(0x1601)),
            Err(0x0609_0030),
            "no such PDO"
        );
        assert_eq!(
            r.check(&od, 0x1C12, 1, &pdo(0x6040)),
            Err(0x0609_0030),
            "not a PDO"
        );
        assert_eq!(r.check(&od, 0x1C12, 1, &pdo(0x1600)), Ok(()));
        assert_eq!(r.check(&od, 0x1C13, 1, &pdo(0x1A00)), Ok(()));
        assert_eq!(r.check(&od, 0x1C12, 2, &pdo(0)), Ok(()), "0 = no PDO");
    }

    #[test]
    fn wrong_bit_length_or_direction_is_0x06040041() {
        let od = server();
        let r = rules(64, 64);
        let e = |v: u32| v.to_le_bytes();
        assert_eq!(
            r.check(&od, 0x1600, 1, &e(0x6040_0020)),
            Err(0x0604_0041),
            "32 of 16 bits"
        );
        assert_eq!(
            r.check(&od, 0x1600, 1, &e(0x607A_0010)),
            Err(0x0604_0041),
            "16 of 32 bits"
        );
        assert_eq!(r.check(&od, 0x1600, 1, &e(0x6040_0010)), Ok(()));
        assert_eq!(
            r.check(&od, 0x1600, 1, &e(0x6041_0010)),
            Err(NOT_MAPPABLE),
            "TxPDO object"
        );
        assert_eq!(r.check(&od, 0x1A00, 1, &e(0x6041_0010)), Ok(()));
        assert_eq!(
            r.check(&od, 0x1A00, 1, &e(0x6040_0010)),
            Err(NOT_MAPPABLE),
            "RxPDO object"
        );
        assert_eq!(
            r.check(&od, 0x1600, 1, &e(0x2000_0020)),
            Err(NOT_MAPPABLE),
            "not mappable"
        );
        assert_eq!(
            r.check(&od, 0x1600, 1, &e(0x5FFF_0010)),
            Err(0x0602_0000),
            "no object"
        );
        assert_eq!(r.check(&od, 0x1600, 1, &e(0x0000_0008)), Ok(()), "a gap");
    }

    #[test]
    fn state_and_sub_index_zero() {
        let mut od = server();
        let e = 0x6040_0010u32.to_le_bytes();
        let mut r = rules(64, 64);
        r.set_editable(false);
        assert_eq!(
            r.check(&od, 0x1600, 0, &[0]),
            Err(0x0800_0022),
            "not in PRE-OP"
        );
        assert_eq!(r.check(&od, 0x1C12, 0, &[0]), Err(0x0800_0022));
        assert_eq!(
            r.check(&od, 0x6040, 0, &[1, 0]),
            Ok(()),
            "other objects pass"
        );
        r.set_editable(true);
        map(&mut od, 0x1600, &[0x6040_0010]);
        od.write(0x1600, 0, &[1]).unwrap();
        assert_eq!(
            r.check(&od, 0x1600, 1, &e),
            Err(0x0601_0003),
            "sub-index 0 is 1"
        );
        od.write(0x1C12, 0, &[1]).unwrap();
        assert_eq!(
            r.check(&od, 0x1C12, 1, &0x1600u16.to_le_bytes()),
            Err(SI0_NOT_ZERO)
        );
    }
}
