//! The object descriptions an emulated CoE device gives through the SDO Information service
//! (ETG.1000.6 §5.6.3; wire layout in [`crate::bus::ethercat::sdo_info`]), and the server side
//! of that service ([`OdDescriptions::respond`]).
//!
//! Where the descriptions come from:
//! * [`OdDescriptions::from_esi`]: the device's ESI `Profile/Dictionary` (ETG.2000) — object
//!   names, data types, object codes, sub-item names, bit sizes, access (`Flags/Access` with
//!   its `WriteRestrictions`) and PDO mapping (`Flags/PdoMapping`) — for every object of the
//!   server's table the ESI declares;
//! * [`OdDescriptions::from_entries`]: the server's own table ([`ObjectEntry`]) for objects the
//!   ESI does not declare (or without an ESI): CiA 301 / CiA 402 names where fieldprobe knows
//!   them, else `Object 0x2001` / `SubIndex 001`.
//!
//! Interpretations (design log):
//! * object code: an ESI object whose type is a base type is a VAR; a data type with an
//!   `ArrayInfo` (directly, or through a sub-item whose type has one) is an ARRAY; any other
//!   data type with sub-items a RECORD. The data type of an ARRAY is its element type; of a
//!   RECORD 0x0023 (IDENTITY) for 0x1018, 0x0021 (PDO_MAPPING) for 0x1600–0x1BFF, else 0x0000
//!   (ETG.2000 record types have no standard index);
//! * access: `ro` = read in PRE-OP, SAFE-OP, OP; `rw` / `wo` write in the states
//!   `WriteRestrictions` names (`PreOP`, `SafeOP`, `OP` in the text), all three without one;
//!   `PdoMapping` `R` / `T` / `RT` set the RxPDO / TxPDO bits;
//! * strings: data type 0x0009 (VISIBLE_STRING), bit length 8 × the maximum length;
//! * Get OD List types 4 (backup) and 5 (settings) are empty lists (no object is flagged).

use std::collections::BTreeMap;

use crate::bus::ethercat::sdo_info::{
    access, data_type_of_esi_name, fragments, list_type, EntryDescription, ObjectCode,
    ObjectDescription,
};
use crate::bus::ethercat::wire::{SdoInfoHeader, SdoInfoOpcode};
use crate::esi::{Dictionary, Flags};

use super::coe::{Access, DataType, ObjectEntry};

/// Abort code of an SDO Info Error for an object that does not exist (CiA 301).
const NO_OBJECT: u32 = 0x0602_0000;
/// Abort code for a sub-index that does not exist.
const NO_SUB: u32 = 0x0609_0011;
/// Abort code for an unknown command (opcode) or a malformed request.
const UNKNOWN: u32 = 0x0504_0001;

/// Object and entry descriptions of a dictionary.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OdDescriptions {
    objects: BTreeMap<u16, ObjectDescription>,
    entries: BTreeMap<(u16, u8), EntryDescription>,
    faults: BTreeMap<u16, DescriptionFault>,
}

/// Fault knob ([`OdDescriptions::set_fault`]): how a device with broken SDO information
/// firmware answers Get Object Description of one object it lists.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DescriptionFault {
    /// An SDO Info Error with this abort code.
    Refused(u32),
    /// The description of this other object (a stale or mis-indexed answer).
    OtherObject(u16),
}

/// CiA 301 data type index of a server entry type.
pub fn data_type_index(t: DataType) -> u16 {
    match t {
        DataType::Bool => 0x0001,
        DataType::I8 => 0x0002,
        DataType::I16 => 0x0003,
        DataType::I32 => 0x0004,
        DataType::U8 => 0x0005,
        DataType::U16 => 0x0006,
        DataType::U32 => 0x0007,
        DataType::I64 => 0x0015,
        DataType::U64 => 0x001B,
        DataType::Bytes(_) => 0x0009,
    }
}

fn bits(t: DataType) -> u16 {
    match t {
        DataType::Bytes(n) => u16::try_from(n.saturating_mul(8)).unwrap_or(u16::MAX),
        t => t.size().unwrap_or(0) as u16 * 8,
    }
}

fn entry_access(a: Access) -> u16 {
    match a {
        Access::Ro => access::READ,
        Access::Rw => access::READ | access::WRITE,
        Access::Wo => access::WRITE,
    }
}

/// Names fieldprobe knows for objects outside CiA 402's table.
fn builtin_name(index: u16) -> Option<String> {
    Some(match index {
        0x1000 => "Device type".into(),
        0x1001 => "Error register".into(),
        0x1008 => "Device name".into(),
        0x1018 => "Identity".into(),
        0x1C00 => "Sync manager type".into(),
        0x1C12 => "RxPDO assign".into(),
        0x1C13 => "TxPDO assign".into(),
        0x1600..=0x17FF => format!("RxPDO {} mapping", index - 0x1600 + 1),
        0x1A00..=0x1BFF => format!("TxPDO {} mapping", index - 0x1A00 + 1),
        0x2000 => "Emulator notice".into(),
        _ => return None,
    })
}

/// `touch probe status` → `Touch probe status` (CiA 402 names as the table writes them).
fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// Access bits from ESI flags; `fallback` when the flags name no access.
fn esi_access(f: &Flags, fallback: u16) -> u16 {
    use crate::esi::Access as A;
    let write = match f.write_restrictions.as_deref() {
        None => access::WRITE,
        Some(w) => {
            let mut b = 0;
            if w.contains("PreOP") {
                b |= access::WRITE_PREOP;
            }
            if w.contains("SafeOP") {
                b |= access::WRITE_SAFEOP;
            }
            if w == "OP" || w.ends_with("_OP") {
                b |= access::WRITE_OP;
            }
            b
        }
    };
    let mut a = match f.access {
        Some(A::ReadOnly) => access::READ,
        Some(A::ReadWrite) => access::READ | write,
        Some(A::WriteOnly) => write,
        None => fallback & !(access::RXPDO | access::TXPDO),
    };
    if let Some(m) = f.pdo_mapping {
        if m.rx() {
            a |= access::RXPDO;
        }
        if m.tx() {
            a |= access::TXPDO;
        }
    }
    a
}

impl OdDescriptions {
    /// Descriptions of the server's table alone (see the module documentation).
    pub fn from_entries(entries: &[ObjectEntry]) -> Self {
        let mut by_index: BTreeMap<u16, Vec<&ObjectEntry>> = BTreeMap::new();
        for e in entries {
            by_index.entry(e.index).or_default().push(e);
        }
        let mut d = OdDescriptions::default();
        for (index, mut subs) in by_index {
            subs.sort_by_key(|e| e.sub);
            let max_sub = subs.last().map_or(0, |e| e.sub);
            let cia = |sub| crate::drive::pdo::lookup(index, sub).map(|o| capitalised(o.name));
            let name = builtin_name(index)
                .or_else(|| cia(0).filter(|_| max_sub == 0))
                .unwrap_or_else(|| match index {
                    0x60D0 => "Touch probe source".into(),
                    _ => format!("Object {index:#06x}"),
                });
            let var = max_sub == 0 && subs.len() == 1;
            let elements: Vec<DataType> = subs.iter().filter(|e| e.sub > 0).map(|e| e.ty).collect();
            let array = !var && elements.windows(2).all(|w| w[0] == w[1]) && index != 0x1018;
            let (object_code, data_type) = if var {
                (ObjectCode::Var, data_type_index(subs[0].ty))
            } else if array {
                (
                    ObjectCode::Array,
                    elements.first().map_or(0, |t| data_type_index(*t)),
                )
            } else {
                (ObjectCode::Record, record_type(index))
            };
            d.objects.insert(
                index,
                ObjectDescription {
                    index,
                    data_type,
                    max_sub,
                    object_code,
                    name: name.clone(),
                },
            );
            for e in subs {
                let ename = if var {
                    name.clone()
                } else if e.sub == 0 {
                    "Number of entries".into()
                } else {
                    cia(e.sub).unwrap_or_else(|| format!("SubIndex {:03}", e.sub))
                };
                let mut a = entry_access(e.access);
                if let Some(o) = crate::drive::pdo::lookup(index, e.sub) {
                    // CiA 402 process data objects: written ones go into RxPDOs, read-only
                    // ones into TxPDOs.
                    if crate::drive::pdo::lookup(o.index, o.sub).is_some() && index >= 0x6000 {
                        a |= if e.access == Access::Ro {
                            access::TXPDO
                        } else {
                            access::RXPDO
                        };
                    }
                }
                d.entries.insert(
                    (index, e.sub),
                    EntryDescription {
                        index,
                        sub: e.sub,
                        value_info: 0,
                        data_type: data_type_index(e.ty),
                        bit_len: bits(e.ty),
                        access: a,
                        name: ename,
                    },
                );
            }
        }
        d
    }

    /// Descriptions of the server's table `entries`, taken from the ESI dictionary `dict` for
    /// every object it declares (see the module documentation); the others as
    /// [`Self::from_entries`]. Only objects and sub-indices the table holds are described
    /// (the server answers what it can read).
    pub fn from_esi(dict: &Dictionary, entries: &[ObjectEntry]) -> Self {
        let mut d = Self::from_entries(entries);
        for o in &dict.objects {
            let Some(base) = d.objects.get(&o.index).cloned() else {
                continue;
            };
            let obj_flags = esi_access(&o.flags, 0);
            if let Some(dt) = data_type_of_esi_name(&o.type_name) {
                d.objects.insert(
                    o.index,
                    ObjectDescription {
                        data_type: dt,
                        object_code: ObjectCode::Var,
                        name: o.name.clone(),
                        ..base
                    },
                );
                if let Some(e) = d.entries.get_mut(&(o.index, 0)) {
                    e.name = o.name.clone();
                    e.data_type = dt;
                    e.bit_len = u16::try_from(o.bit_size).unwrap_or(e.bit_len);
                    e.access = esi_access(&o.flags, e.access);
                }
                continue;
            }
            let Some(t) = dict.data_type(&o.type_name) else {
                if let Some(x) = d.objects.get_mut(&o.index) {
                    x.name = o.name.clone();
                }
                continue;
            };
            let array_type = |name: &str| dict.data_type(name).and_then(|x| x.array.map(|_| x));
            let elements = t
                .subitems
                .iter()
                .find_map(|s| array_type(&s.type_name))
                .or(t.array.map(|_| t));
            let (object_code, data_type) = match elements {
                Some(a) => (
                    ObjectCode::Array,
                    a.base_type
                        .as_deref()
                        .and_then(data_type_of_esi_name)
                        .unwrap_or(0),
                ),
                None => (ObjectCode::Record, record_type(o.index)),
            };
            d.objects.insert(
                o.index,
                ObjectDescription {
                    data_type,
                    object_code,
                    name: o.name.clone(),
                    ..base
                },
            );
            for s in &t.subitems {
                let Some(sub) = s.subindex else { continue };
                let Some(e) = d.entries.get_mut(&(o.index, sub)) else {
                    continue;
                };
                e.name = s.name.clone();
                if let Some(dt) = data_type_of_esi_name(&s.type_name) {
                    e.data_type = dt;
                }
                e.bit_len = u16::try_from(s.bit_size).unwrap_or(e.bit_len);
                let fallback = if s.flags.access.is_some() {
                    e.access
                } else {
                    obj_flags
                };
                e.access = esi_access(&s.flags, fallback);
            }
        }
        d
    }

    /// Description of object `index`.
    pub fn object(&self, index: u16) -> Option<&ObjectDescription> {
        self.objects.get(&index)
    }

    /// Description of entry `index:sub`.
    pub fn entry(&self, index: u16, sub: u8) -> Option<&EntryDescription> {
        self.entries.get(&(index, sub))
    }

    /// Insert or replace an object description (e.g. from a vendor's dump).
    pub fn insert_object(&mut self, o: ObjectDescription) {
        self.objects.insert(o.index, o);
    }

    /// Insert or replace an entry description.
    pub fn insert_entry(&mut self, e: EntryDescription) {
        self.entries.insert((e.index, e.sub), e);
    }

    /// The indexes of Get OD List type `list` (type 0: the five counts).
    pub fn list(&self, list: u16) -> Option<Vec<u16>> {
        let mappable = |bit: u16| -> Vec<u16> {
            self.objects
                .keys()
                .copied()
                .filter(|&i| {
                    self.entries
                        .range((i, 0)..=(i, u8::MAX))
                        .any(|(_, e)| e.access & bit != 0)
                })
                .collect()
        };
        Some(match list {
            list_type::ALL => self.objects.keys().copied().collect(),
            list_type::RXPDO => mappable(access::RXPDO),
            list_type::TXPDO => mappable(access::TXPDO),
            list_type::BACKUP => mappable(access::BACKUP),
            list_type::SETTINGS => mappable(access::SETTINGS),
            list_type::COUNTS => (1..=5)
                .map(|l| self.list(l).map_or(0, |v| v.len() as u16))
                .collect(),
            _ => return None,
        })
    }

    /// Fault knob: answer Get Object Description of `index` as `fault` says (the object stays
    /// in the OD list).
    pub fn set_fault(&mut self, index: u16, fault: DescriptionFault) {
        self.faults.insert(index, fault);
    }

    /// Answer one SDO information request (`req`: the bytes after the CoE header) with the CoE
    /// bodies of the response, fragmented so each fragment's data is at most `max_data` bytes
    /// (read mailbox − mailbox header − CoE header − SDO information header). Unknown opcodes,
    /// short requests and unknown objects get an SDO Info Error.
    pub fn respond(&self, req: &[u8], max_data: usize) -> Vec<Vec<u8>> {
        let error = |code: u32| fragments(SdoInfoOpcode::ErrorRequest, &code.to_le_bytes(), 4);
        let Ok((h, data)) = SdoInfoHeader::parse(req) else {
            return error(UNKNOWN);
        };
        let u16_at = |o: usize| data.get(o..o + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
        match h.opcode {
            SdoInfoOpcode::GetOdListRequest => {
                let Some(list) = u16_at(0) else {
                    return error(UNKNOWN);
                };
                let Some(ids) = self.list(list) else {
                    return error(crate::sim::esc::coe::abort::VALUE_RANGE);
                };
                let mut v = list.to_le_bytes().to_vec();
                for i in ids {
                    v.extend_from_slice(&i.to_le_bytes());
                }
                fragments(SdoInfoOpcode::GetOdListResponse, &v, max_data)
            }
            SdoInfoOpcode::GetObjectDescriptionRequest => {
                let Some(index) = u16_at(0) else {
                    return error(UNKNOWN);
                };
                let shown = match self.faults.get(&index) {
                    Some(DescriptionFault::Refused(code)) => return error(*code),
                    Some(DescriptionFault::OtherObject(other)) => *other,
                    None => index,
                };
                match self.objects.get(&shown) {
                    Some(o) => fragments(
                        SdoInfoOpcode::GetObjectDescriptionResponse,
                        &o.encode(),
                        max_data,
                    ),
                    None => error(NO_OBJECT),
                }
            }
            SdoInfoOpcode::GetEntryDescriptionRequest => {
                let (Some(index), Some(&sub), Some(&vi)) = (u16_at(0), data.get(2), data.get(3))
                else {
                    return error(UNKNOWN);
                };
                match self.entries.get(&(index, sub)) {
                    Some(e) => {
                        let e = EntryDescription {
                            value_info: vi & 0x07,
                            ..e.clone()
                        };
                        fragments(
                            SdoInfoOpcode::GetEntryDescriptionResponse,
                            &e.encode(),
                            max_data,
                        )
                    }
                    None if self.objects.contains_key(&index) => error(NO_SUB),
                    None => error(NO_OBJECT),
                }
            }
            _ => error(UNKNOWN),
        }
    }
}

/// Data type index of a RECORD object (see the module documentation).
fn record_type(index: u16) -> u16 {
    match index {
        0x1018 => 0x0023,
        0x1600..=0x1BFF => 0x0021,
        _ => 0x0000,
    }
}
