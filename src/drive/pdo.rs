//! PDO layouts: which CiA 402 objects sit at which byte offset of a process image.
//!
//! A layout is built from a list of object references in the drive file
//! (`drives/*.toml`, `[rxpdo] entries` / `[txpdo] entries`), e.g.
//! `["0x6040:00", "0x607A:00", "0x6060:00"]`. The data type comes from [`OBJECTS`] (the CiA 402
//! objects this crate knows) or is given explicitly as a third field: `"0x2000:01:u32"`.
//!
//! Entries are packed back to back, little-endian, in list order (CiA 301 §7.4.8 PDO mapping:
//! "the mapped objects are concatenated in the order of the mapping entries"; EtherCAT CoE uses
//! the same byte order), least significant bit first. A `bool` entry takes one byte, as
//! fieldprobe's drive files have always laid it out; a vendor's bit fields (ETG.2000 `BOOL`
//! entries of one bit, `BIT2` …) are written `"0x7001:01:bit1"`, gaps `"0x0000:00:bit12"`
//! (mapping entry index 0), so that a fixed PDO of a device can be described bit for bit.
//!
//! A CiA 402 object may be played by another object of the device ([`Role`], a drive file's
//! `[roles]`): Beckhoff's modular device profile puts the controlword at 0x7010:01, a device
//! with fixed PDOs carries its position set-point in another object. [`PdoLayout::find`] finds
//! the role under the CiA 402 index, so the adapter and the drive model address every drive
//! the same way.
//!
//! Every accessor takes the image as a byte slice and returns `Option` / `Result`; a short slice
//! is reported, never indexed out of bounds.

use std::fmt;

/// CiA 301 basic data types used in PDOs (CiA 301 §7.1.4 / Table 44 data type indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// `BOOLEAN` (0x0001), one byte here.
    Bool,
    /// `UNSIGNED8` (0x0005).
    U8,
    /// `INTEGER8` (0x0002).
    I8,
    /// `UNSIGNED16` (0x0006).
    U16,
    /// `INTEGER16` (0x0003).
    I16,
    /// `UNSIGNED32` (0x0007).
    U32,
    /// `INTEGER32` (0x0004).
    I32,
}

impl DataType {
    /// Every data type, in the order used by error messages.
    pub const ALL: [DataType; 7] = [
        DataType::Bool,
        DataType::U8,
        DataType::I8,
        DataType::U16,
        DataType::I16,
        DataType::U32,
        DataType::I32,
    ];

    /// Size in bytes in a process image.
    pub const fn size(self) -> usize {
        match self {
            DataType::Bool | DataType::U8 | DataType::I8 => 1,
            DataType::U16 | DataType::I16 => 2,
            DataType::U32 | DataType::I32 => 4,
        }
    }

    /// Whether the type is signed.
    pub const fn is_signed(self) -> bool {
        matches!(self, DataType::I8 | DataType::I16 | DataType::I32)
    }

    /// Bit length as written into a CiA 301 mapping entry (`index << 16 | sub << 8 | bits`).
    pub const fn bits(self) -> u8 {
        match self {
            DataType::Bool => 1,
            other => (other.size() * 8) as u8,
        }
    }

    /// Short name used in drive files: `bool`, `u8`, `i8`, `u16`, `i16`, `u32`, `i32`.
    pub const fn name(self) -> &'static str {
        match self {
            DataType::Bool => "bool",
            DataType::U8 => "u8",
            DataType::I8 => "i8",
            DataType::U16 => "u16",
            DataType::I16 => "i16",
            DataType::U32 => "u32",
            DataType::I32 => "i32",
        }
    }

    /// Parse a short name (`u16`) or the CiA 301 name (`UNSIGNED16`), case-insensitive.
    pub fn from_name(name: &str) -> Option<DataType> {
        let n = name.trim().to_ascii_lowercase();
        DataType::ALL.into_iter().find(|t| {
            t.name() == n
                || match t {
                    DataType::Bool => n == "boolean",
                    DataType::U8 => n == "unsigned8",
                    DataType::I8 => n == "integer8",
                    DataType::U16 => n == "unsigned16",
                    DataType::I16 => n == "integer16",
                    DataType::U32 => n == "unsigned32",
                    DataType::I32 => n == "integer32",
                }
        })
    }

    /// CiA 301 data type index (object dictionary entries 0x0001–0x0007).
    pub const fn cia301_code(self) -> u16 {
        match self {
            DataType::Bool => 0x0001,
            DataType::I8 => 0x0002,
            DataType::I16 => 0x0003,
            DataType::I32 => 0x0004,
            DataType::U8 => 0x0005,
            DataType::U16 => 0x0006,
            DataType::U32 => 0x0007,
        }
    }

    /// Inverse of [`DataType::cia301_code`]; `None` for types this crate does not map.
    pub fn from_cia301_code(code: u16) -> Option<DataType> {
        DataType::ALL.into_iter().find(|t| t.cia301_code() == code)
    }

    /// Smallest and largest value of the type.
    pub const fn range(self) -> (i64, i64) {
        match self {
            DataType::Bool => (0, 1),
            DataType::U8 => (0, u8::MAX as i64),
            DataType::I8 => (i8::MIN as i64, i8::MAX as i64),
            DataType::U16 => (0, u16::MAX as i64),
            DataType::I16 => (i16::MIN as i64, i16::MAX as i64),
            DataType::U32 => (0, u32::MAX as i64),
            DataType::I32 => (i32::MIN as i64, i32::MAX as i64),
        }
    }

    /// Whether `value` fits the type.
    pub const fn contains(self, value: i64) -> bool {
        let (lo, hi) = self.range();
        value >= lo && value <= hi
    }

    /// `value` clamped into the type's range.
    pub fn saturate(self, value: i64) -> i64 {
        let (lo, hi) = self.range();
        value.clamp(lo, hi)
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One object of the CiA 402 object table ([`OBJECTS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectInfo {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Data type (CiA 402 / CiA 301).
    pub ty: DataType,
    /// Name as in CiA 402.
    pub name: &'static str,
}

const fn obj(index: u16, sub: u8, ty: DataType, name: &'static str) -> ObjectInfo {
    ObjectInfo {
        index,
        sub,
        ty,
        name,
    }
}

/// The CiA 402 (and CiA 301) objects fieldprobe maps or reads, with their data types
/// (CiA 402-2 object descriptions; cross-checked against a Leadshine EL7 SDO dump in
/// `tests/it/ds402.rs`).
pub const OBJECTS: &[ObjectInfo] = &[
    obj(0x603F, 0, DataType::U16, "error code"),
    obj(0x6040, 0, DataType::U16, "controlword"),
    obj(0x6041, 0, DataType::U16, "statusword"),
    obj(0x6060, 0, DataType::I8, "modes of operation"),
    obj(0x6061, 0, DataType::I8, "modes of operation display"),
    obj(0x6064, 0, DataType::I32, "position actual value"),
    obj(0x6065, 0, DataType::U32, "following error window"),
    obj(0x6066, 0, DataType::U16, "following error time out"),
    obj(0x6067, 0, DataType::U32, "position window"),
    obj(0x606C, 0, DataType::I32, "velocity actual value"),
    obj(0x6072, 0, DataType::U16, "max torque"),
    obj(0x6077, 0, DataType::I16, "torque actual value"),
    obj(0x607A, 0, DataType::I32, "target position"),
    obj(0x60B8, 0, DataType::U16, "touch probe function"),
    obj(0x60B9, 0, DataType::U16, "touch probe status"),
    obj(0x60BA, 0, DataType::I32, "touch probe 1 positive edge"),
    obj(0x60BB, 0, DataType::I32, "touch probe 1 negative edge"),
    obj(0x60BC, 0, DataType::I32, "touch probe 2 positive edge"),
    obj(0x60BD, 0, DataType::I32, "touch probe 2 negative edge"),
    obj(
        0x60D0,
        0,
        DataType::U8,
        "touch probe source: highest sub-index",
    ),
    obj(0x60D0, 1, DataType::I16, "touch probe 1 source"),
    obj(0x60D0, 2, DataType::I16, "touch probe 2 source"),
    obj(
        0x60D5,
        0,
        DataType::U16,
        "touch probe 1 positive edge counter",
    ),
    obj(
        0x60D6,
        0,
        DataType::U16,
        "touch probe 1 negative edge counter",
    ),
    obj(
        0x60D7,
        0,
        DataType::U16,
        "touch probe 2 positive edge counter",
    ),
    obj(
        0x60D8,
        0,
        DataType::U16,
        "touch probe 2 negative edge counter",
    ),
    obj(0x60E0, 0, DataType::U16, "positive torque limit value"),
    obj(0x60E1, 0, DataType::U16, "negative torque limit value"),
    obj(0x60F4, 0, DataType::I32, "following error actual value"),
    obj(0x6502, 0, DataType::U32, "supported drive modes"),
];

/// Look up an object of [`OBJECTS`].
pub fn lookup(index: u16, sub: u8) -> Option<&'static ObjectInfo> {
    OBJECTS.iter().find(|o| o.index == index && o.sub == sub)
}

/// Errors of PDO layouts and image access.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PdoError {
    /// An entry reference is not `0xIIII:SS` or `0xIIII:SS:type`.
    #[error("invalid PDO entry `{spec}`: {reason}")]
    Syntax {
        /// The text as written.
        spec: String,
        /// What is wrong and what is allowed.
        reason: String,
    },
    /// The object is not in [`OBJECTS`] and the entry does not give a type.
    #[error(
        "object 0x{index:04X}:{sub:02X} is not a known CiA 402 object; give its type, e.g. \
         \"0x{index:04X}:{sub:02X}:u32\""
    )]
    UnknownObject {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// The same object is mapped twice.
    #[error("object 0x{index:04X}:{sub:02X} is mapped twice")]
    Duplicate {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// The object is not part of the layout.
    #[error("object 0x{index:04X}:{sub:02X} is not mapped")]
    NotMapped {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// The image is too short for the entry.
    #[error("process image too short: entry needs bytes up to {needed}, image has {got}")]
    ImageTooShort {
        /// Bytes needed (end of the entry).
        needed: usize,
        /// Bytes present.
        got: usize,
    },
    /// A role's object does not have the bit length of the CiA 402 object it plays.
    #[error(
        "role of 0x{index:04X}:{sub:02X} ({ty}): object 0x{object:04X}:{object_sub:02X} gives {bits} bits in the image, CiA 402 has {}",
        .ty.size() * 8
    )]
    RoleSize {
        /// The CiA 402 object.
        index: u16,
        /// Its sub-index.
        sub: u8,
        /// The device's object.
        object: u16,
        /// Its sub-index.
        object_sub: u8,
        /// Bits the role would take.
        bits: u16,
        /// The CiA 402 type.
        ty: DataType,
    },
    /// The value does not fit the entry's data type.
    #[error("value {value} does not fit {ty}")]
    ValueRange {
        /// The value.
        value: i64,
        /// The entry's type.
        ty: DataType,
    },
}

impl From<PdoError> for super::DriveError {
    /// A short image becomes [`DriveError::ImageTooShort`](super::DriveError::ImageTooShort);
    /// anything else is a layout problem and becomes a
    /// [`DriveError::Definition`](super::DriveError::Definition) without a file position.
    fn from(e: PdoError) -> Self {
        match e {
            PdoError::ImageTooShort { needed, got } => super::DriveError::ImageTooShort {
                expected: needed,
                got,
            },
            other => super::DriveError::Definition {
                file: "<pdo layout>".into(),
                line: 0,
                message: other.to_string(),
            },
        }
    }
}

/// A hexadecimal `0x1600` / `#x1600` / `1600` as `u16` (PDO indices in drive files).
pub fn parse_hex_u16(s: &str) -> Option<u16> {
    let s = s.trim();
    let h = s
        .strip_prefix("0x")
        .or_else(|| s.strip_prefix("0X"))
        .or_else(|| s.strip_prefix("#x"))
        .unwrap_or(s);
    if h.is_empty() || h.len() > 4 || !h.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u16::from_str_radix(h, 16).ok()
}

/// A number `0x…` / `#x…` hexadecimal or decimal as `u32` (identities in drive files).
pub fn parse_number_u32(s: &str) -> Option<u32> {
    let s = s.trim();
    match s
        .strip_prefix("0x")
        .or_else(|| s.strip_prefix("0X"))
        .or_else(|| s.strip_prefix("#x"))
    {
        Some(h) if !h.is_empty() && h.len() <= 8 && h.bytes().all(|b| b.is_ascii_hexdigit()) => {
            u32::from_str_radix(h, 16).ok()
        }
        Some(_) => None,
        None if !s.is_empty() && s.len() <= 10 && s.bytes().all(|b| b.is_ascii_digit()) => {
            s.parse().ok()
        }
        None => None,
    }
}

/// One entry of a drive file's `[rxpdo]` / `[txpdo] entries`, parsed ([`parse_entry_spec`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EntrySpec {
    /// Object index; 0 for a gap (padding) of `bits` bits.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// How the value is read and written (for a field narrower than the type, the type of its
    /// raw unsigned value: `u8` up to 8 bits, `u16` up to 16, `u32` up to 32).
    pub ty: DataType,
    /// Bit length on the wire (the low byte of the CiA 301 mapping value).
    pub bits: u16,
}

impl EntrySpec {
    /// A whole-type entry (`bits` = the type's size; a `bool` is one byte, as fieldprobe's
    /// drive files have always laid it out).
    pub const fn whole(index: u16, sub: u8, ty: DataType) -> Self {
        EntrySpec {
            index,
            sub,
            ty,
            bits: (ty.size() * 8) as u16,
        }
    }

    /// A gap of `bits` bits (mapping entry index 0, ETG.1000.6 / CiA 301 "dummy" entry).
    pub const fn gap(bits: u16) -> Self {
        EntrySpec {
            index: 0,
            sub: 0,
            ty: DataType::U8,
            bits,
        }
    }

    /// Is this a gap?
    pub const fn is_gap(&self) -> bool {
        self.index == 0
    }
}

/// The raw unsigned type of a `bits`-bit field (`u8` up to 8 bits, `u16` up to 16, `u32`).
const fn raw_type(bits: u16) -> DataType {
    if bits <= 8 {
        DataType::U8
    } else if bits <= 16 {
        DataType::U16
    } else {
        DataType::U32
    }
}

/// Parse one entry reference: `0x6040:00`, `6040:0`, `0x2000:01:u32` (hex index and sub-index,
/// optional type name as in [`DataType::from_name`]). Only whole-type entries: a `bitN` type or
/// a gap is refused here (use [`parse_entry_spec`] for PDO entries).
pub fn parse_entry(spec: &str) -> Result<(u16, u8, DataType), PdoError> {
    let e = parse_entry_spec(spec)?;
    if e.is_gap() || u32::from(e.bits) != e.ty.size() as u32 * 8 {
        return Err(PdoError::Syntax {
            spec: spec.to_string(),
            reason: "expected a whole object such as \"0x6040:00\" or \"0x2000:01:u32\" (no gap, \
                     no bit field)"
                .into(),
        });
    }
    Ok((e.index, e.sub, e.ty))
}

/// Parse one PDO entry: `0x6040:00`, `0x2000:01:u32`, a bit field `0x7001:01:bit1` (`bit1` …
/// `bit32`: an unsigned field of that many bits, ETG.2000 `BOOL` / `BIT2` … entries), or a gap
/// `0x0000:00:bit12` (index 0: that many bits of padding, CiA 301 / ETG.1000.6 mapping entry
/// with index 0).
pub fn parse_entry_spec(spec: &str) -> Result<EntrySpec, PdoError> {
    let syntax = |reason: &str| PdoError::Syntax {
        spec: spec.to_string(),
        reason: reason.into(),
    };
    let mut parts = spec.trim().split(':');
    let (Some(index), Some(sub)) = (parts.next(), parts.next()) else {
        return Err(syntax("expected \"0xINDEX:SUB\" or \"0xINDEX:SUB:TYPE\""));
    };
    let ty = parts.next();
    if parts.next().is_some() {
        return Err(syntax("too many `:` fields; expected \"0xINDEX:SUB:TYPE\""));
    }
    let hex = |s: &str| {
        let s = s.trim();
        let s = s
            .strip_prefix("0x")
            .or_else(|| s.strip_prefix("0X"))
            .unwrap_or(s);
        if s.is_empty() || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
            None
        } else {
            u32::from_str_radix(s, 16).ok()
        }
    };
    let index = hex(index)
        .and_then(|v| u16::try_from(v).ok())
        .ok_or_else(|| syntax("index must be a hexadecimal number 0x0000..0xFFFF"))?;
    let sub = hex(sub)
        .and_then(|v| u8::try_from(v).ok())
        .ok_or_else(|| syntax("sub-index must be a hexadecimal number 0x00..0xFF"))?;
    let bit_field = ty.and_then(|t| {
        let t = t.trim().to_ascii_lowercase();
        let n = t.strip_prefix("bit")?;
        Some(n.parse::<u16>().ok().filter(|n| (1..=32).contains(n)))
    });
    if let Some(bits) = bit_field {
        let bits = bits.ok_or_else(|| syntax("bit field length must be bit1 … bit32"))?;
        if index == 0 {
            return Ok(EntrySpec::gap(bits));
        }
        return Ok(EntrySpec {
            index,
            sub,
            ty: raw_type(bits),
            bits,
        });
    }
    if index == 0 {
        return Err(syntax(
            "index 0 is a gap: give its length as a bit field, e.g. \"0x0000:00:bit8\"",
        ));
    }
    let ty = match ty {
        Some(t) => DataType::from_name(t).ok_or_else(|| {
            syntax("unknown type; allowed: bool, u8, i8, u16, i16, u32, i32, bit1 … bit32")
        })?,
        None => lookup(index, sub)
            .map(|o| o.ty)
            .ok_or(PdoError::UnknownObject { index, sub })?,
    };
    Ok(EntrySpec::whole(index, sub, ty))
}

/// The text of an entry as [`parse_entry_spec`] reads it: `"0x6040:00"` for a CiA 402 object of
/// its table type, `"0x2000:01:u32"`, `"0x7001:01:bit1"`, `"0x0000:00:bit8"`.
pub fn entry_text(e: &EntrySpec) -> String {
    if e.is_gap() {
        return format!("0x0000:00:bit{}", e.bits);
    }
    if u32::from(e.bits) != e.ty.size() as u32 * 8 {
        return format!("0x{:04X}:{:02X}:bit{}", e.index, e.sub, e.bits);
    }
    match lookup(e.index, e.sub) {
        Some(o) if o.ty == e.ty => format!("0x{:04X}:{:02X}", e.index, e.sub),
        _ => format!("0x{:04X}:{:02X}:{}", e.index, e.sub, e.ty.name()),
    }
}

/// One mapped object: where it sits in the image and how it is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PdoEntry {
    /// Object index (for a role, the CiA 402 object it stands for).
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Data type.
    pub ty: DataType,
    /// Byte offset in the image (of the entry's first bit).
    pub offset: usize,
    /// Bit offset in the image (bit 0 = least significant bit of byte 0; EtherCAT and CANopen
    /// pack PDO entries LSB first, little-endian).
    pub bit: usize,
    /// Bit length in the image.
    pub bits: u16,
}

impl PdoEntry {
    /// A whole-byte entry of type `ty` at byte `offset`.
    pub const fn at(index: u16, sub: u8, ty: DataType, offset: usize) -> Self {
        PdoEntry {
            index,
            sub,
            ty,
            offset,
            bit: offset * 8,
            bits: (ty.size() * 8) as u16,
        }
    }

    /// First byte after the entry.
    pub const fn end(&self) -> usize {
        (self.bit + self.bits as usize).div_ceil(8)
    }

    /// The entry is whole bytes of its type's size (the fast path of read / write).
    const fn byte_aligned(&self) -> bool {
        self.bit.is_multiple_of(8) && self.bits as usize == self.ty.size() * 8
    }

    /// The CiA 301 mapping entry value (`index << 16 | sub << 8 | bit length`, objects
    /// 0x1600 / 0x1A00 sub 1..).
    pub const fn mapping_value(&self) -> u32 {
        (self.index as u32) << 16 | (self.sub as u32) << 8 | (self.bits & 0xFF) as u32
    }

    /// Read the entry from `image` (little-endian), `None` when the image is too short. A field
    /// narrower than its type reads as its unsigned bits, sign-extended for a signed type.
    pub fn read(&self, image: &[u8]) -> Option<i64> {
        if self.byte_aligned() {
            let b = image.get(self.offset..self.end())?;
            return Some(match self.ty {
                DataType::Bool => i64::from(b[0] != 0),
                DataType::U8 => i64::from(b[0]),
                DataType::I8 => i64::from(b[0] as i8),
                DataType::U16 => i64::from(u16::from_le_bytes([b[0], b[1]])),
                DataType::I16 => i64::from(i16::from_le_bytes([b[0], b[1]])),
                DataType::U32 => i64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                DataType::I32 => i64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            });
        }
        if self.end() > image.len() {
            return None;
        }
        let raw = read_bits(image, self.bit, self.bits);
        let n = u32::from(self.bits);
        Some(if self.ty.is_signed() && n < 64 && n > 0 {
            let shift = 64 - n;
            ((raw << shift) as i64) >> shift
        } else {
            raw as i64
        })
    }

    /// Write `value` into `image` (little-endian). Fails when the image is too short or the value
    /// does not fit the type (a bit field: its bits); the image is unchanged on failure.
    pub fn write(&self, image: &mut [u8], value: i64) -> Result<(), PdoError> {
        if !self.ty.contains(value) {
            return Err(PdoError::ValueRange { value, ty: self.ty });
        }
        let got = image.len();
        if self.end() > got {
            return Err(PdoError::ImageTooShort {
                needed: self.end(),
                got,
            });
        }
        if self.byte_aligned() {
            // In range, so the low bytes of the two's complement are the encoding.
            let le = value.to_le_bytes();
            image[self.offset..self.end()].copy_from_slice(&le[..self.ty.size()]);
            return Ok(());
        }
        let n = u32::from(self.bits);
        let fits = if self.ty.is_signed() {
            n >= 64 || {
                let half = 1i64 << (n - 1);
                (-half..half).contains(&value)
            }
        } else {
            n >= 64 || (value as u64) < (1u64 << n)
        };
        if !fits {
            return Err(PdoError::ValueRange { value, ty: self.ty });
        }
        write_bits(image, self.bit, self.bits, value as u64);
        Ok(())
    }
}

/// `bits` bits of `image` from bit `at`, LSB first (the caller checked the length).
pub fn read_bits(image: &[u8], at: usize, bits: u16) -> u64 {
    let mut v = 0u64;
    for k in 0..usize::from(bits).min(64) {
        let b = at + k;
        if image[b / 8] >> (b % 8) & 1 == 1 {
            v |= 1 << k;
        }
    }
    v
}

/// Write the low `bits` bits of `value` into `image` from bit `at`, LSB first (the caller
/// checked the length).
pub fn write_bits(image: &mut [u8], at: usize, bits: u16, value: u64) {
    for k in 0..usize::from(bits).min(64) {
        let b = at + k;
        let mask = 1u8 << (b % 8);
        if value >> k & 1 == 1 {
            image[b / 8] |= mask;
        } else {
            image[b / 8] &= !mask;
        }
    }
}

/// Copy `bits` bits from `src` at bit `from` to `dst` at bit `to` (LSB first); whole bytes at
/// byte boundaries are copied as bytes. Bits outside either slice are left alone.
pub fn copy_bits(src: &[u8], from: usize, dst: &mut [u8], to: usize, bits: usize) {
    if bits == 0 || from + bits > src.len() * 8 || to + bits > dst.len() * 8 {
        return;
    }
    if from.is_multiple_of(8) && to.is_multiple_of(8) && bits.is_multiple_of(8) {
        dst[to / 8..(to + bits) / 8].copy_from_slice(&src[from / 8..(from + bits) / 8]);
        return;
    }
    for k in 0..bits {
        let (s, d) = (from + k, to + k);
        let mask = 1u8 << (d % 8);
        if src[s / 8] >> (s % 8) & 1 == 1 {
            dst[d / 8] |= mask;
        } else {
            dst[d / 8] &= !mask;
        }
    }
}

/// Is `index` one of the optional touch-probe objects (CiA 402 0x60B8–0x60BD touch probe
/// function, status and edge positions, 0x60D0 touch probe source, 0x60D5–0x60D8 edge
/// counters)? Many CiA 402 drives have none of them (issue 19).
pub fn is_touch_probe(index: u16) -> bool {
    matches!(index, 0x60B8..=0x60BD | 0x60D0 | 0x60D5..=0x60D8)
}

/// A CiA 402 object played by another object of the device (a drive definition's `[roles]`):
/// the CiA 402 object `index:sub` is the device's object `object:object_sub` — or, with
/// `bits`, the `bits`-bit word whose first bit is that object's first bit in the image (a
/// device that splits a CiA 402 word into single-bit objects, such as Beckhoff's modular device
/// profile touch probe control 0x7001:01 … 0x7001:0E, laid out bit for bit as 0x60B8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Role {
    /// The CiA 402 object (e.g. 0x6040:00).
    pub index: u16,
    /// Its sub-index.
    pub sub: u8,
    /// The device's object that plays it (e.g. 0x7010:01).
    pub object: u16,
    /// Its sub-index.
    pub object_sub: u8,
    /// A word of this many bits from the object's first bit; `None`: the object itself.
    pub bits: Option<u16>,
}

/// The CiA 402 objects a drive file's `[roles]` may give to other objects of the device, by
/// their role name (the key in `[roles]`), with the direction they travel (`true`: master →
/// drive). Objects that are not process data (the mode of operation written once by SDO) are
/// roles too: the master writes the role's object.
pub const ROLE_NAMES: &[(&str, u16, u8, bool)] = &[
    ("controlword", 0x6040, 0, true),
    ("modes_of_operation", 0x6060, 0, true),
    ("target_position", 0x607A, 0, true),
    ("touch_probe_function", 0x60B8, 0, true),
    ("statusword", 0x6041, 0, false),
    ("modes_of_operation_display", 0x6061, 0, false),
    ("position_actual_value", 0x6064, 0, false),
    ("following_error_actual_value", 0x60F4, 0, false),
    ("torque_actual_value", 0x6077, 0, false),
    ("touch_probe_status", 0x60B9, 0, false),
    ("touch_probe_1_positive_edge", 0x60BA, 0, false),
    ("touch_probe_1_negative_edge", 0x60BB, 0, false),
    ("touch_probe_2_positive_edge", 0x60BC, 0, false),
    ("touch_probe_2_negative_edge", 0x60BD, 0, false),
];

/// The role name of a CiA 402 object ([`ROLE_NAMES`]).
pub fn role_name(index: u16, sub: u8) -> Option<&'static str> {
    ROLE_NAMES
        .iter()
        .find(|r| r.1 == index && r.2 == sub)
        .map(|r| r.0)
}

/// The byte layout of one direction of a drive's process data.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoLayout {
    entries: Vec<PdoEntry>,
    /// CiA 402 objects played by other entries (found by [`Self::find`] under the CiA 402
    /// index), in [`Role`] order.
    roles: Vec<PdoEntry>,
    len: usize,
}

impl PdoLayout {
    /// Build a layout from objects in mapping order; rejects an object mapped twice.
    pub fn from_objects(objects: &[(u16, u8, DataType)]) -> Result<PdoLayout, PdoError> {
        let specs: Vec<EntrySpec> = objects
            .iter()
            .map(|&(index, sub, ty)| EntrySpec::whole(index, sub, ty))
            .collect();
        PdoLayout::from_specs(&specs)
    }

    /// Build a layout from entries (bit fields and gaps allowed) in mapping order; rejects an
    /// object mapped twice.
    pub fn from_specs(specs: &[EntrySpec]) -> Result<PdoLayout, PdoError> {
        let mut entries: Vec<PdoEntry> = Vec::with_capacity(specs.len());
        let mut bit = 0usize;
        for s in specs {
            if !s.is_gap() {
                if entries.iter().any(|e| e.index == s.index && e.sub == s.sub) {
                    return Err(PdoError::Duplicate {
                        index: s.index,
                        sub: s.sub,
                    });
                }
                entries.push(PdoEntry {
                    index: s.index,
                    sub: s.sub,
                    ty: s.ty,
                    offset: bit / 8,
                    bit,
                    bits: s.bits,
                });
            } else {
                entries.push(PdoEntry {
                    index: 0,
                    sub: 0,
                    ty: s.ty,
                    offset: bit / 8,
                    bit,
                    bits: s.bits,
                });
            }
            bit += usize::from(s.bits);
        }
        Ok(PdoLayout {
            entries,
            roles: Vec::new(),
            len: bit.div_ceil(8),
        })
    }

    /// The layout with `roles`: each role whose device object is mapped here becomes findable
    /// under its CiA 402 index ([`Self::find`]), with the CiA 402 type ([`lookup`]); roles of
    /// objects not mapped here are skipped. A role whose object has another bit length than
    /// the CiA 402 type (or, with `bits`, whose word runs past the image) is an error.
    pub fn with_roles(mut self, roles: &[Role]) -> Result<PdoLayout, PdoError> {
        self.roles.clear();
        for r in roles {
            let Some(e) = self
                .entries
                .iter()
                .find(|e| e.index == r.object && e.sub == r.object_sub && e.index != 0)
            else {
                continue;
            };
            let ty = lookup(r.index, r.sub)
                .map(|o| o.ty)
                .ok_or(PdoError::UnknownObject {
                    index: r.index,
                    sub: r.sub,
                })?;
            let bits = r.bits.unwrap_or(e.bits);
            if usize::from(bits) != ty.size() * 8 || e.bit + usize::from(bits) > self.len * 8 {
                return Err(PdoError::RoleSize {
                    index: r.index,
                    sub: r.sub,
                    object: r.object,
                    object_sub: r.object_sub,
                    bits,
                    ty,
                });
            }
            self.roles.push(PdoEntry {
                index: r.index,
                sub: r.sub,
                ty,
                offset: e.bit / 8,
                bit: e.bit,
                bits,
            });
        }
        Ok(self)
    }

    /// The layout without the entries `drop` names, the rest in their order (offsets packed
    /// again; gaps kept). Roles are dropped; apply them again with [`Self::with_roles`].
    pub fn without(&self, mut drop: impl FnMut(u16, u8) -> bool) -> PdoLayout {
        let kept: Vec<EntrySpec> = self
            .entries
            .iter()
            .filter(|e| e.index == 0 || !drop(e.index, e.sub))
            .map(PdoEntry::spec)
            .collect();
        // The entries were distinct already.
        PdoLayout::from_specs(&kept).unwrap_or_default()
    }

    /// Build a layout from entry references such as `"0x6040:00"` (see [`parse_entry_spec`]).
    pub fn parse<S: AsRef<str>>(specs: &[S]) -> Result<PdoLayout, PdoError> {
        let objects = specs
            .iter()
            .map(|s| parse_entry_spec(s.as_ref()))
            .collect::<Result<Vec<_>, _>>()?;
        PdoLayout::from_specs(&objects)
    }

    /// Entries in image order (the device's objects as mapped, gaps included with index 0).
    pub fn entries(&self) -> &[PdoEntry] {
        &self.entries
    }

    /// The entries as specifications (for building a new layout from this one).
    pub fn specs(&self) -> Vec<EntrySpec> {
        self.entries.iter().map(PdoEntry::spec).collect()
    }

    /// The CiA 402 objects played by other entries ([`Self::with_roles`]).
    pub fn roles(&self) -> &[PdoEntry] {
        &self.roles
    }

    /// Does a role ([`Self::roles`]) cover bits of entry `e`? Such an entry is read and written
    /// through the role (the CiA 402 object), not under its own index.
    pub fn in_role(&self, e: &PdoEntry) -> bool {
        self.roles
            .iter()
            .any(|r| r.bit < e.bit + usize::from(e.bits) && e.bit < r.bit + usize::from(r.bits))
    }

    /// Bytes of the image.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No entries.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The entry of an object, if mapped: a role's CiA 402 object first
    /// ([`Self::with_roles`]), then the entries (gaps are never found).
    pub fn find(&self, index: u16, sub: u8) -> Option<&PdoEntry> {
        self.roles
            .iter()
            .find(|e| e.index == index && e.sub == sub)
            .or_else(|| {
                self.entries
                    .iter()
                    .find(|e| e.index == index && e.sub == sub && e.index != 0)
            })
    }

    /// Whether an object is mapped.
    pub fn contains(&self, index: u16, sub: u8) -> bool {
        self.find(index, sub).is_some()
    }

    /// Read an object; `None` when not mapped or the image is too short.
    pub fn get(&self, image: &[u8], index: u16, sub: u8) -> Option<i64> {
        self.find(index, sub)?.read(image)
    }

    /// Write an object; fails when not mapped, the image is too short or the value does not fit.
    pub fn set(&self, image: &mut [u8], index: u16, sub: u8, value: i64) -> Result<(), PdoError> {
        self.find(index, sub)
            .ok_or(PdoError::NotMapped { index, sub })?
            .write(image, value)
    }

    /// Read an `UNSIGNED8`-compatible object (`None` also when the value does not fit `u8`).
    pub fn get_u8(&self, image: &[u8], index: u16, sub: u8) -> Option<u8> {
        self.get(image, index, sub)
            .and_then(|v| u8::try_from(v).ok())
    }

    /// Read an `INTEGER8`-compatible object.
    pub fn get_i8(&self, image: &[u8], index: u16, sub: u8) -> Option<i8> {
        self.get(image, index, sub)
            .and_then(|v| i8::try_from(v).ok())
    }

    /// Read an `UNSIGNED16`-compatible object.
    pub fn get_u16(&self, image: &[u8], index: u16, sub: u8) -> Option<u16> {
        self.get(image, index, sub)
            .and_then(|v| u16::try_from(v).ok())
    }

    /// Read an `INTEGER16`-compatible object.
    pub fn get_i16(&self, image: &[u8], index: u16, sub: u8) -> Option<i16> {
        self.get(image, index, sub)
            .and_then(|v| i16::try_from(v).ok())
    }

    /// Read an `UNSIGNED32`-compatible object.
    pub fn get_u32(&self, image: &[u8], index: u16, sub: u8) -> Option<u32> {
        self.get(image, index, sub)
            .and_then(|v| u32::try_from(v).ok())
    }

    /// Read an `INTEGER32`-compatible object.
    pub fn get_i32(&self, image: &[u8], index: u16, sub: u8) -> Option<i32> {
        self.get(image, index, sub)
            .and_then(|v| i32::try_from(v).ok())
    }

    /// Write a `u8` value (checked against the entry's type).
    pub fn set_u8(&self, image: &mut [u8], index: u16, sub: u8, v: u8) -> Result<(), PdoError> {
        self.set(image, index, sub, i64::from(v))
    }

    /// Write an `i8` value (checked against the entry's type).
    pub fn set_i8(&self, image: &mut [u8], index: u16, sub: u8, v: i8) -> Result<(), PdoError> {
        self.set(image, index, sub, i64::from(v))
    }

    /// Write a `u16` value (checked against the entry's type).
    pub fn set_u16(&self, image: &mut [u8], index: u16, sub: u8, v: u16) -> Result<(), PdoError> {
        self.set(image, index, sub, i64::from(v))
    }

    /// Write an `i16` value (checked against the entry's type).
    pub fn set_i16(&self, image: &mut [u8], index: u16, sub: u8, v: i16) -> Result<(), PdoError> {
        self.set(image, index, sub, i64::from(v))
    }

    /// Write a `u32` value (checked against the entry's type).
    pub fn set_u32(&self, image: &mut [u8], index: u16, sub: u8, v: u32) -> Result<(), PdoError> {
        self.set(image, index, sub, i64::from(v))
    }

    /// Write an `i32` value (checked against the entry's type).
    pub fn set_i32(&self, image: &mut [u8], index: u16, sub: u8, v: i32) -> Result<(), PdoError> {
        self.set(image, index, sub, i64::from(v))
    }
}

impl PdoEntry {
    /// The entry as a specification (index, sub-index, type, bit length).
    pub const fn spec(&self) -> EntrySpec {
        EntrySpec {
            index: self.index,
            sub: self.sub,
            ty: self.ty,
            bits: self.bits,
        }
    }

    /// Is this a gap (index 0)?
    pub const fn is_gap(&self) -> bool {
        self.index == 0
    }
}

/// Default CSP RxPDO (master → drive): controlword, target position, modes of operation, touch
/// probe function (CiA 402-3 / ETG.6010 "CSP" example mapping plus 0x60B8).
///
/// 0x6072 max torque is deliberately not mapped: torque limits are written acyclically (FCT-C4
/// §7.3.2, `antr.function[1].commu ACYCLIC`), and a cyclic mapping would overwrite every SDO write
/// in the next cycle. Drive files may still map it.
pub const DEFAULT_RXPDO: &[&str] = &["0x6040:00", "0x607A:00", "0x6060:00", "0x60B8:00"];

/// Default CSP TxPDO (drive → master): statusword, position actual, following error actual,
/// modes display, touch probe status, the four touch probe edge positions and torque actual
/// value (0x6077, appended last so the offsets of the other entries stay put).
pub const DEFAULT_TXPDO: &[&str] = &[
    "0x6041:00",
    "0x6064:00",
    "0x60F4:00",
    "0x6061:00",
    "0x60B9:00",
    "0x60BA:00",
    "0x60BB:00",
    "0x60BC:00",
    "0x60BD:00",
    "0x6077:00",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entry_syntax() {
        assert_eq!(parse_entry("0x6040:00"), Ok((0x6040, 0, DataType::U16)));
        assert_eq!(parse_entry("60d0:2"), Ok((0x60D0, 2, DataType::I16)));
        assert_eq!(
            parse_entry("0x2000:01:UNSIGNED32"),
            Ok((0x2000, 1, DataType::U32))
        );
        assert_eq!(
            parse_entry("0x2000:01"),
            Err(PdoError::UnknownObject {
                index: 0x2000,
                sub: 1
            })
        );
        for bad in [
            "",
            "0x6040",
            "0x6040:00:u64",
            "0x16040:00",
            "0x6040:100",
            "0x6040:00:u8:x",
            "0x:00",
        ] {
            assert!(
                matches!(parse_entry(bad), Err(PdoError::Syntax { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn round_trip_every_type_and_short_images() {
        for ty in DataType::ALL {
            let l = PdoLayout::from_objects(&[(0x6040, 0, DataType::U8), (0x2000, 1, ty)]).unwrap();
            let (lo, hi) = ty.range();
            let mut img = vec![0u8; l.len()];
            for v in [lo, hi, (lo + hi) / 2] {
                l.set(&mut img, 0x2000, 1, v).unwrap();
                assert_eq!(l.get(&img, 0x2000, 1), Some(v), "{ty}");
            }
            assert_eq!(l.get(&img[..l.len() - 1], 0x2000, 1), None);
            assert!(l.set(&mut img, 0x2000, 1, hi + 1).is_err());
            assert!(matches!(
                l.set(&mut img[..1], 0x2000, 1, lo),
                Err(PdoError::ImageTooShort { .. })
            ));
        }
    }

    #[test]
    fn duplicates_rejected_and_mapping_value() {
        assert_eq!(
            PdoLayout::parse(&["0x6040:00", "0x6040:0"]),
            Err(PdoError::Duplicate {
                index: 0x6040,
                sub: 0
            })
        );
        let l = PdoLayout::parse(&["0x6041:00", "0x60BA:00"]).unwrap();
        assert_eq!(l.entries()[1].mapping_value(), 0x60BA_0020);
        assert_eq!(l.entries()[0].mapping_value(), 0x6041_0010);
    }

    /// Beckhoff EJ7211-0010 "FB Touch probe control" (ESI RxPdo 0x1607): bits 0x7001:01, :02,
    /// a 2-bit :03, :05, :06, a 2-bit gap, the same for TP2, a 2-bit gap — 16 bits laid out as
    /// CiA 402 0x60B8. With the role, 0x60B8 reads and writes the whole word.
    #[test]
    fn bit_fields_gaps_and_a_role_word() {
        let l = PdoLayout::parse(&[
            "0x7010:01:u16",
            "0x7001:01:bit1",
            "0x7001:02:bit1",
            "0x7001:03:bit2",
            "0x7001:05:bit1",
            "0x7001:06:bit1",
            "0x0000:00:bit2",
            "0x7001:09:bit1",
            "0x7001:0A:bit1",
            "0x7001:0B:bit2",
            "0x7001:0D:bit1",
            "0x7001:0E:bit1",
            "0x0000:00:bit2",
            "0x7010:05:u32",
        ])
        .unwrap();
        assert_eq!(l.len(), 2 + 2 + 4);
        let e = l.find(0x7001, 0x0D).unwrap();
        assert_eq!((e.bit, e.bits, e.offset), (16 + 12, 1, 3));
        assert_eq!(l.find(0x7010, 5).unwrap().offset, 4);
        assert_eq!(l.entries()[6].mapping_value(), 0x0000_0002);
        assert_eq!(l.entries()[3].mapping_value(), 0x7001_0302);
        let l = l
            .with_roles(&[
                Role {
                    index: 0x60B8,
                    sub: 0,
                    object: 0x7001,
                    object_sub: 1,
                    bits: Some(16),
                },
                Role {
                    index: 0x6040,
                    sub: 0,
                    object: 0x7010,
                    object_sub: 1,
                    bits: None,
                },
                Role {
                    index: 0x607A,
                    sub: 0,
                    object: 0x7010,
                    object_sub: 5,
                    bits: None,
                },
            ])
            .unwrap();
        let mut img = vec![0u8; l.len()];
        // TP1 enable + positive edge (bits 0, 4), TP2 enable (bit 8): 0x0111.
        l.set(&mut img, 0x60B8, 0, 0x0111).unwrap();
        assert_eq!(img[2..4], [0x11, 0x01]);
        assert_eq!(l.get(&img, 0x7001, 5), Some(1));
        assert_eq!(l.get(&img, 0x7001, 9), Some(1));
        assert_eq!(l.get(&img, 0x7001, 2), Some(0));
        l.set(&mut img, 0x7001, 3, 2).unwrap();
        assert_eq!(l.get(&img, 0x60B8, 0), Some(0x0119));
        assert!(l.set(&mut img, 0x7001, 3, 4).is_err(), "2 bits hold 0..=3");
        // The UDINT target position plays the INTEGER32 0x607A: signed through the role.
        l.set(&mut img, 0x607A, 0, -5).unwrap();
        assert_eq!(l.get(&img, 0x607A, 0), Some(-5));
        assert_eq!(l.get(&img, 0x7010, 5), Some(0xFFFF_FFFB));
        l.set(&mut img, 0x6040, 0, 0x000F).unwrap();
        assert_eq!(img[..2], [0x0F, 0x00]);
        // A role of the wrong width is refused, one whose object is not mapped skipped.
        let bad = PdoLayout::parse(&["0x7010:01:u32"])
            .unwrap()
            .with_roles(&[Role {
                index: 0x6040,
                sub: 0,
                object: 0x7010,
                object_sub: 1,
                bits: None,
            }]);
        assert!(matches!(bad, Err(PdoError::RoleSize { bits: 32, .. })));
        let skipped = PdoLayout::parse(&["0x6041:00"])
            .unwrap()
            .with_roles(&[Role {
                index: 0x6040,
                sub: 0,
                object: 0x7010,
                object_sub: 1,
                bits: None,
            }]);
        assert!(!skipped.unwrap().contains(0x6040, 0));
    }

    #[test]
    fn entry_specs_and_their_text() {
        for (text, want) in [
            ("0x6040:00", EntrySpec::whole(0x6040, 0, DataType::U16)),
            ("0x5FF1:00:u8", EntrySpec::whole(0x5FF1, 0, DataType::U8)),
            ("0x0000:00:bit12", EntrySpec::gap(12)),
            (
                "0x6000:0F:bit2",
                EntrySpec {
                    index: 0x6000,
                    sub: 0x0F,
                    ty: DataType::U8,
                    bits: 2,
                },
            ),
            (
                "0x6000:11:bit32",
                EntrySpec {
                    index: 0x6000,
                    sub: 0x11,
                    ty: DataType::U32,
                    bits: 32,
                },
            ),
        ] {
            assert_eq!(parse_entry_spec(text), Ok(want), "{text}");
        }
        assert_eq!(entry_text(&EntrySpec::gap(8)), "0x0000:00:bit8");
        assert_eq!(
            entry_text(&EntrySpec::whole(0x6064, 0, DataType::U32)),
            "0x6064:00:u32"
        );
        assert_eq!(
            entry_text(&EntrySpec::whole(0x6064, 0, DataType::I32)),
            "0x6064:00"
        );
        for bad in [
            "0x0000:00",
            "0x0000:00:u8",
            "0x7001:01:bit0",
            "0x7001:01:bit33",
        ] {
            assert!(
                matches!(parse_entry_spec(bad), Err(PdoError::Syntax { .. })),
                "{bad}"
            );
        }
        assert!(parse_entry("0x7001:01:bit1").is_err(), "not a whole object");
        // Gaps may repeat; objects may not.
        assert!(PdoLayout::parse(&["0x0000:00:bit8", "0x0000:00:bit8"]).is_ok());
    }
}
