//! CoE SDO Information service (ETG.1000.6 §5.6.3, CoE service 8): the wire layout of its
//! requests and responses, shared by the emulated server ([`crate::sim::esc::coe`]) and the
//! client ([`super::mailbox::CoeClient::od_list`] and friends).
//!
//! Every SDO Information message is `CoE header (service 8)` + [`SdoInfoHeader`] (opcode,
//! incomplete bit, fragments left) + data:
//!
//! | opcode | message | data |
//! |---|---|---|
//! | 1 | Get OD List request | list type u16 |
//! | 2 | Get OD List response | list type u16, then one index u16 per object (type 0: five counts) |
//! | 3 | Get Object Description request | index u16 |
//! | 4 | Get Object Description response | index u16, data type u16, max sub-index u8, object code u8, name |
//! | 5 | Get Entry Description request | index u16, sub-index u8, value info u8 |
//! | 6 | Get Entry Description response | index u16, sub-index u8, value info u8, data type u16, bit length u16, object access u16, [unit, default, min, max per value info], name |
//! | 7 | SDO Info Error request | abort code u32 (CiA 301 codes) |
//!
//! A response longer than the read mailbox is sent in fragments: the response data (list type
//! and indexes, or the description) is cut into pieces, each behind its own SDO information
//! header with the incomplete bit set while more follow and `fragments left` counting down to
//! 0 on the last one; only the first fragment carries the list type (SOEM `ecx_readODlist`
//! reads the counts this way). Names are the rest of the message (no terminator).
//!
//! [`FragmentCollector`] reassembles fragments with caps on their number and total size, so a
//! device that never stops fragmenting, or announces millions of fragments, gets a clear error
//! and no unbounded memory. No function here panics on any input.

use super::wire::{SdoInfoHeader, SdoInfoOpcode};

/// Object code (ETG.1000.6 object description, CiA 301 §7.4.3 object codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectCode {
    /// 7 = VAR: a single value (sub-index 0).
    Var,
    /// 8 = ARRAY: sub 0 holds the number of entries, all entries of one type.
    Array,
    /// 9 = RECORD: sub 0 holds the number of entries, entries of different types.
    Record,
    /// Any other code, kept.
    Other(u8),
}

impl From<u8> for ObjectCode {
    fn from(v: u8) -> Self {
        match v {
            7 => ObjectCode::Var,
            8 => ObjectCode::Array,
            9 => ObjectCode::Record,
            x => ObjectCode::Other(x),
        }
    }
}

impl From<ObjectCode> for u8 {
    fn from(c: ObjectCode) -> u8 {
        match c {
            ObjectCode::Var => 7,
            ObjectCode::Array => 8,
            ObjectCode::Record => 9,
            ObjectCode::Other(x) => x,
        }
    }
}

impl ObjectCode {
    /// `VAR`, `ARRAY`, `RECORD` or `code N`.
    pub fn name(self) -> String {
        match self {
            ObjectCode::Var => "VAR".into(),
            ObjectCode::Array => "ARRAY".into(),
            ObjectCode::Record => "RECORD".into(),
            ObjectCode::Other(x) => format!("code {x}"),
        }
    }
}

/// Object access bits of an entry description (ETG.1000.6 "ObjAccess").
pub mod access {
    /// Readable in PRE-OP.
    pub const READ_PREOP: u16 = 0x0001;
    /// Readable in SAFE-OP.
    pub const READ_SAFEOP: u16 = 0x0002;
    /// Readable in OP.
    pub const READ_OP: u16 = 0x0004;
    /// Writable in PRE-OP.
    pub const WRITE_PREOP: u16 = 0x0008;
    /// Writable in SAFE-OP.
    pub const WRITE_SAFEOP: u16 = 0x0010;
    /// Writable in OP.
    pub const WRITE_OP: u16 = 0x0020;
    /// Mappable into an RxPDO.
    pub const RXPDO: u16 = 0x0040;
    /// Mappable into a TxPDO.
    pub const TXPDO: u16 = 0x0080;
    /// Used for backup.
    pub const BACKUP: u16 = 0x0100;
    /// Used for settings.
    pub const SETTINGS: u16 = 0x0200;
    /// Readable in every state.
    pub const READ: u16 = READ_PREOP | READ_SAFEOP | READ_OP;
    /// Writable in every state.
    pub const WRITE: u16 = WRITE_PREOP | WRITE_SAFEOP | WRITE_OP;

    /// IgH's six access letters: read/write in PREOP, SAFEOP, OP (`rwrwrw`, `r-r-r-`).
    pub fn letters(a: u16) -> String {
        [
            (READ_PREOP, 'r'),
            (WRITE_PREOP, 'w'),
            (READ_SAFEOP, 'r'),
            (WRITE_SAFEOP, 'w'),
            (READ_OP, 'r'),
            (WRITE_OP, 'w'),
        ]
        .iter()
        .map(|&(bit, c)| if a & bit != 0 { c } else { '-' })
        .collect()
    }
}

/// CiA 301 / ETG.1000.6 data type index (the `data type` of a description) in the words IgH's
/// `ethercat sdos` uses (`uint16`, `int32`, `string`), `type 0x0023` for others (records).
pub fn data_type_name(dt: u16) -> String {
    let s = match dt {
        0x0001 => "bool",
        0x0002 => "int8",
        0x0003 => "int16",
        0x0004 => "int32",
        0x0005 => "uint8",
        0x0006 => "uint16",
        0x0007 => "uint32",
        0x0008 => "float",
        0x0009 => "string",
        0x000A => "octet_string",
        0x000B => "unicode_string",
        0x000F => "domain",
        0x0010 => "int24",
        0x0011 => "double",
        0x0015 => "int64",
        0x0016 => "uint24",
        0x001B => "uint64",
        _ => return format!("type {dt:#06x}"),
    };
    s.to_string()
}

/// Data type index of an ETG.2000 base type name (`UINT`, `DINT`, `STRING(12)`,
/// `ARRAY [0..3] OF BYTE`), `None` for a name that is not a base type (a record type such
/// as `DT1018`).
pub fn data_type_of_esi_name(name: &str) -> Option<u16> {
    let n = name.trim();
    Some(match n {
        "BOOL" | "BIT" => 0x0001,
        "SINT" => 0x0002,
        "INT" => 0x0003,
        "DINT" => 0x0004,
        "USINT" | "BYTE" => 0x0005,
        "UINT" | "WORD" => 0x0006,
        "UDINT" | "DWORD" => 0x0007,
        "REAL" => 0x0008,
        "LREAL" => 0x0011,
        "LINT" => 0x0015,
        "ULINT" => 0x001B,
        _ if n.starts_with("STRING(") => 0x0009,
        _ if n.starts_with("ARRAY") && n.ends_with("OF BYTE") => 0x000A,
        "OCTET_STRING" => 0x000A,
        _ => return None,
    })
}

/// List types of Get OD List (ETG.1000.6).
pub mod list_type {
    /// The number of objects of each of the five lists (all, RxPDO, TxPDO, backup, settings).
    pub const COUNTS: u16 = 0;
    /// All objects.
    pub const ALL: u16 = 1;
    /// Objects mappable into an RxPDO.
    pub const RXPDO: u16 = 2;
    /// Objects mappable into a TxPDO.
    pub const TXPDO: u16 = 3;
    /// Objects to be stored for a device replacement (backup).
    pub const BACKUP: u16 = 4;
    /// Objects used as startup parameters (settings).
    pub const SETTINGS: u16 = 5;
}

/// Get Object Description response: one object.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectDescription {
    /// Index.
    pub index: u16,
    /// Data type index (a base type for VAR / ARRAY elements, a record type index otherwise).
    pub data_type: u16,
    /// Highest sub-index.
    pub max_sub: u8,
    /// Object code.
    pub object_code: ObjectCode,
    /// Name.
    pub name: String,
}

impl ObjectDescription {
    /// Response data (after the SDO information header).
    pub fn encode(&self) -> Vec<u8> {
        let mut v = self.index.to_le_bytes().to_vec();
        v.extend_from_slice(&self.data_type.to_le_bytes());
        v.push(self.max_sub);
        v.push(self.object_code.into());
        v.extend(latin1(&self.name));
        v
    }

    /// Decode response data.
    pub fn parse(b: &[u8]) -> Result<Self, String> {
        if b.len() < 6 {
            return Err(format!(
                "object description of {} bytes; at least 6 expected",
                b.len()
            ));
        }
        Ok(Self {
            index: u16::from_le_bytes([b[0], b[1]]),
            data_type: u16::from_le_bytes([b[2], b[3]]),
            max_sub: b[4],
            object_code: ObjectCode::from(b[5]),
            name: text(&b[6..]),
        })
    }
}

/// Get Entry Description response: one sub-index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EntryDescription {
    /// Index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Value info of the response (which optional fields it carries; bits 3..6).
    pub value_info: u8,
    /// Data type index.
    pub data_type: u16,
    /// Length in bits.
    pub bit_len: u16,
    /// Object access bits ([`access`]).
    pub access: u16,
    /// Name (description).
    pub name: String,
}

impl EntryDescription {
    /// Response data (after the SDO information header); no unit / default / minimum / maximum
    /// (value info bits 3..6 clear).
    pub fn encode(&self) -> Vec<u8> {
        let mut v = self.index.to_le_bytes().to_vec();
        v.push(self.sub);
        v.push(self.value_info & 0x07);
        v.extend_from_slice(&self.data_type.to_le_bytes());
        v.extend_from_slice(&self.bit_len.to_le_bytes());
        v.extend_from_slice(&self.access.to_le_bytes());
        v.extend(latin1(&self.name));
        v
    }

    /// Decode response data. Optional fields announced in the value info (unit type 2 bytes,
    /// default / minimum / maximum each of the entry's byte length) are skipped.
    pub fn parse(b: &[u8]) -> Result<Self, String> {
        if b.len() < 10 {
            return Err(format!(
                "entry description of {} bytes; at least 10 expected",
                b.len()
            ));
        }
        let value_info = b[3];
        let bit_len = u16::from_le_bytes([b[6], b[7]]);
        let mut skip = 0usize;
        if value_info & 0x08 != 0 {
            skip += 2;
        }
        let n = usize::from(bit_len).div_ceil(8);
        for bit in [0x10, 0x20, 0x40] {
            if value_info & bit != 0 {
                skip += n;
            }
        }
        let name = b.get(10 + skip..).ok_or_else(|| {
            format!(
                "entry description of {} bytes is shorter than the {skip} bytes of unit/default/min/max its value info {value_info:#04x} announces",
                b.len()
            )
        })?;
        Ok(Self {
            index: u16::from_le_bytes([b[0], b[1]]),
            sub: b[2],
            value_info,
            data_type: u16::from_le_bytes([b[4], b[5]]),
            bit_len,
            access: u16::from_le_bytes([b[8], b[9]]),
            name: text(name),
        })
    }
}

/// Text as name bytes: Latin-1 (the inverse of [`text`]); a character beyond U+00FF is `?`.
fn latin1(s: &str) -> impl Iterator<Item = u8> + '_ {
    s.chars()
        .map(|c| u8::try_from(u32::from(c)).unwrap_or(b'?'))
}

/// Name bytes as text: up to the first NUL (some devices terminate), Latin-1 beyond ASCII.
fn text(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    b[..end].iter().map(|&c| char::from(c)).collect()
}

/// Request body of an SDO information service (CoE header included): `opcode` + `data`.
pub fn request(opcode: SdoInfoOpcode, data: &[u8]) -> Vec<u8> {
    let mut v = super::wire::CoeHeader {
        number: 0,
        service: super::wire::CoeService::SdoInformation,
    }
    .encode()
    .to_vec();
    v.extend_from_slice(
        &SdoInfoHeader {
            opcode,
            incomplete: false,
            fragments_left: 0,
        }
        .encode(),
    );
    v.extend_from_slice(data);
    v
}

/// The CoE bodies (CoE header included) of one response: `data` cut into fragments whose
/// data is at most `max_data` bytes (rounded down to even, so no index of an OD list is split;
/// at least 2). A response that needs more than 65 536 fragments is cut at that count (the
/// fragments-left counter is 16 bit); no dictionary comes near it.
pub fn fragments(opcode: SdoInfoOpcode, data: &[u8], max_data: usize) -> Vec<Vec<u8>> {
    let step = (max_data & !1).max(2);
    let chunks: Vec<&[u8]> = if data.is_empty() {
        vec![&[][..]]
    } else {
        data.chunks(step).take(65_536).collect()
    };
    let n = chunks.len();
    chunks
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let left = (n - 1 - i) as u16;
            let mut v = super::wire::CoeHeader {
                number: 0,
                service: super::wire::CoeService::SdoInformation,
            }
            .encode()
            .to_vec();
            v.extend_from_slice(
                &SdoInfoHeader {
                    opcode,
                    incomplete: left > 0,
                    fragments_left: left,
                }
                .encode(),
            );
            v.extend_from_slice(c);
            v
        })
        .collect()
}

/// Why a response could not be assembled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SdoInfoError {
    /// The device answered with an SDO Info Error (opcode 7) and this CiA 301 abort code.
    #[error("SDO information error {code:#010x} ({})", crate::bus::abort::abort_text(*.code))]
    Refused {
        /// Abort code.
        code: u32,
    },
    /// Malformed or unexpected fragment.
    #[error("SDO information response: {0}")]
    Protocol(String),
    /// More data or fragments than the client accepts.
    #[error("SDO information response larger than the {limit} bytes / {MAX_FRAGMENTS} fragments accepted ({what})")]
    TooLarge {
        /// Cap in bytes.
        limit: usize,
        /// What exceeded it.
        what: String,
    },
}

/// Most fragments of one response a client accepts (a complete OD list of 65 535 objects in
/// a 128-byte mailbox needs about 1 130).
pub const MAX_FRAGMENTS: usize = 8192;
/// Most response bytes a client collects: the largest OD list (list type + 65 535 indexes)
/// with room to spare.
pub const MAX_RESPONSE_BYTES: usize = 2 * 65_536 + 64;

/// Reassembles the fragments of one SDO information response (sans-IO: feed each CoE body
/// that arrives, see whether it is complete).
#[derive(Debug, Clone)]
pub struct FragmentCollector {
    expect: SdoInfoOpcode,
    data: Vec<u8>,
    fragments: usize,
    last_left: Option<u16>,
}

impl FragmentCollector {
    /// Collector for a response with opcode `expect`.
    pub fn new(expect: SdoInfoOpcode) -> Self {
        Self {
            expect,
            data: Vec::new(),
            fragments: 0,
            last_left: None,
        }
    }

    /// Feed one CoE body (CoE header included). `Ok(Some(data))` when the response is complete,
    /// `Ok(None)` when more fragments follow. An SDO Info Error ends it with
    /// [`SdoInfoError::Refused`]; a fragment out of order, of another opcode or beyond the caps
    /// with another error.
    pub fn push(&mut self, coe_body: &[u8]) -> Result<Option<Vec<u8>>, SdoInfoError> {
        let proto = |s: String| SdoInfoError::Protocol(s);
        let (coe, rest) = super::wire::CoeHeader::parse(coe_body)
            .map_err(|e| proto(format!("CoE header: {e}")))?;
        if coe.service != super::wire::CoeService::SdoInformation {
            return Err(proto(format!(
                "CoE service {:?} instead of SDO information",
                coe.service
            )));
        }
        let (h, data) = SdoInfoHeader::parse(rest)
            .map_err(|e| proto(format!("SDO information header: {e}")))?;
        if h.opcode == SdoInfoOpcode::ErrorRequest {
            let code = data
                .get(..4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .ok_or_else(|| proto(format!("SDO Info Error of {} bytes", data.len())))?;
            return Err(SdoInfoError::Refused { code });
        }
        if h.opcode != self.expect {
            return Err(proto(format!(
                "opcode {:?} while waiting for {:?}",
                h.opcode, self.expect
            )));
        }
        if let Some(prev) = self.last_left {
            if prev == 0 || h.fragments_left != prev - 1 {
                return Err(proto(format!(
                    "fragment with {} fragments left after one with {prev} left",
                    h.fragments_left
                )));
            }
        } else if usize::from(h.fragments_left) >= MAX_FRAGMENTS {
            return Err(SdoInfoError::TooLarge {
                limit: MAX_RESPONSE_BYTES,
                what: format!("{} fragments announced", usize::from(h.fragments_left) + 1),
            });
        }
        self.fragments += 1;
        if self.data.len() + data.len() > MAX_RESPONSE_BYTES {
            return Err(SdoInfoError::TooLarge {
                limit: MAX_RESPONSE_BYTES,
                what: format!("{} bytes received", self.data.len() + data.len()),
            });
        }
        self.data.extend_from_slice(data);
        self.last_left = Some(h.fragments_left);
        if h.fragments_left == 0 {
            Ok(Some(std::mem::take(&mut self.data)))
        } else {
            Ok(None)
        }
    }
}

/// Decode the data of a complete Get OD List response for list type `list`: the indexes (or,
/// for [`list_type::COUNTS`], the five counts).
pub fn parse_od_list(list: u16, data: &[u8]) -> Result<Vec<u16>, SdoInfoError> {
    let proto = |s: String| SdoInfoError::Protocol(s);
    let got = data
        .get(..2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .ok_or_else(|| proto("OD list response without list type".into()))?;
    if got != list {
        return Err(proto(format!(
            "OD list response for list type {got}, {list} requested"
        )));
    }
    let rest = &data[2..];
    if !rest.len().is_multiple_of(2) {
        return Err(proto(format!(
            "OD list of {} bytes (an odd number; indexes are 2 bytes)",
            rest.len()
        )));
    }
    Ok(rest
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fragments_reassemble_at_every_size() {
        let data: Vec<u8> = (0..=255u8).cycle().take(1001).collect();
        for max in 1..60 {
            let frags = fragments(SdoInfoOpcode::GetOdListResponse, &data, max);
            let mut c = FragmentCollector::new(SdoInfoOpcode::GetOdListResponse);
            let mut out = None;
            for (i, f) in frags.iter().enumerate() {
                let r = c.push(f).unwrap();
                assert_eq!(r.is_some(), i + 1 == frags.len());
                out = r;
            }
            assert_eq!(out.unwrap(), data, "max {max}");
        }
    }

    #[test]
    fn collector_refuses_gaps_and_floods() {
        let frags = fragments(SdoInfoOpcode::GetOdListResponse, &[0; 40], 10);
        let mut c = FragmentCollector::new(SdoInfoOpcode::GetOdListResponse);
        c.push(&frags[0]).unwrap();
        assert!(matches!(c.push(&frags[2]), Err(SdoInfoError::Protocol(_))));
        // 60 000 fragments announced: refused at once.
        let mut f = frags[0].clone();
        f[4..6].copy_from_slice(&60_000u16.to_le_bytes());
        let mut c = FragmentCollector::new(SdoInfoOpcode::GetOdListResponse);
        assert!(matches!(c.push(&f), Err(SdoInfoError::TooLarge { .. })));
        // An SDO Info Error carries its abort code.
        let mut e = request(SdoInfoOpcode::ErrorRequest, &0x0602_0000u32.to_le_bytes());
        let mut c = FragmentCollector::new(SdoInfoOpcode::GetObjectDescriptionResponse);
        assert_eq!(c.push(&e), Err(SdoInfoError::Refused { code: 0x0602_0000 }));
        e.truncate(8);
        assert!(matches!(c.push(&e), Err(SdoInfoError::Protocol(_))));
    }

    #[test]
    fn descriptions_round_trip_and_short_input_is_an_error() {
        let o = ObjectDescription {
            index: 0x1018,
            data_type: 0x0023,
            max_sub: 4,
            object_code: ObjectCode::Record,
            name: "Identity".into(),
        };
        assert_eq!(ObjectDescription::parse(&o.encode()).unwrap(), o);
        let e = EntryDescription {
            index: 0x6040,
            sub: 0,
            value_info: 7,
            data_type: 6,
            bit_len: 16,
            access: access::READ | access::WRITE | access::RXPDO,
            name: "Controlword".into(),
        };
        assert_eq!(EntryDescription::parse(&e.encode()).unwrap(), e);
        assert_eq!(access::letters(e.access), "rwrwrw");
        assert_eq!(access::letters(access::READ), "r-r-r-");
        for n in 0..10 {
            assert!(EntryDescription::parse(&e.encode()[..n]).is_err());
            assert!(ObjectDescription::parse(&o.encode()[..n.min(5)]).is_err());
        }
        // Default value announced (bit 4) but missing: an error, not a panic.
        let mut b = e.encode();
        b[3] = 0x10;
        b.truncate(11);
        assert!(EntryDescription::parse(&b).is_err());
    }
}
