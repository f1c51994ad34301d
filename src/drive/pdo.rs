//! PDO layouts: which CiA 402 objects sit at which byte offset of a process image.
//!
//! A layout is built from a list of object references in the drive file
//! (`drives/*.toml`, `[rxpdo] entries` / `[txpdo] entries`), e.g.
//! `["0x6040:00", "0x607A:00", "0x6060:00"]`. The data type comes from [`OBJECTS`] (the CiA 402
//! objects this crate knows) or is given explicitly as a third field: `"0x2000:01:u32"`.
//!
//! Entries are packed back to back, little-endian, in list order (CiA 301 §7.4.8 PDO mapping:
//! "the mapped objects are concatenated in the order of the mapping entries"; EtherCAT CoE uses
//! the same byte order). Offsets are whole bytes: a `BOOLEAN` takes one byte here, although
//! CiA 301 would map it as a single bit — the CiA 402 objects we use are all whole bytes.
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
/// `tests/ds402.rs`).
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

/// Parse one entry reference: `0x6040:00`, `6040:0`, `0x2000:01:u32` (hex index and sub-index,
/// optional type name as in [`DataType::from_name`]).
pub fn parse_entry(spec: &str) -> Result<(u16, u8, DataType), PdoError> {
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
    let ty = match ty {
        Some(t) => DataType::from_name(t)
            .ok_or_else(|| syntax("unknown type; allowed: bool, u8, i8, u16, i16, u32, i32"))?,
        None => lookup(index, sub)
            .map(|o| o.ty)
            .ok_or(PdoError::UnknownObject { index, sub })?,
    };
    Ok((index, sub, ty))
}

/// One mapped object: where it sits in the image and how it is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PdoEntry {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Data type.
    pub ty: DataType,
    /// Byte offset in the image.
    pub offset: usize,
}

impl PdoEntry {
    /// First byte after the entry.
    pub const fn end(&self) -> usize {
        self.offset + self.ty.size()
    }

    /// The CiA 301 mapping entry value (`index << 16 | sub << 8 | bit length`, objects
    /// 0x1600 / 0x1A00 sub 1..).
    pub const fn mapping_value(&self) -> u32 {
        (self.index as u32) << 16 | (self.sub as u32) << 8 | self.ty.bits() as u32
    }

    /// Read the entry from `image` (little-endian), `None` when the image is too short.
    pub fn read(&self, image: &[u8]) -> Option<i64> {
        let b = image.get(self.offset..self.end())?;
        Some(match self.ty {
            DataType::Bool => i64::from(b[0] != 0),
            DataType::U8 => i64::from(b[0]),
            DataType::I8 => i64::from(b[0] as i8),
            DataType::U16 => i64::from(u16::from_le_bytes([b[0], b[1]])),
            DataType::I16 => i64::from(i16::from_le_bytes([b[0], b[1]])),
            DataType::U32 => i64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            DataType::I32 => i64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        })
    }

    /// Write `value` into `image` (little-endian). Fails when the image is too short or the value
    /// does not fit the type; the image is unchanged on failure.
    pub fn write(&self, image: &mut [u8], value: i64) -> Result<(), PdoError> {
        if !self.ty.contains(value) {
            return Err(PdoError::ValueRange { value, ty: self.ty });
        }
        let got = image.len();
        let b = image
            .get_mut(self.offset..self.end())
            .ok_or(PdoError::ImageTooShort {
                needed: self.end(),
                got,
            })?;
        // In range, so the low bytes of the two's complement are the encoding.
        let le = value.to_le_bytes();
        b.copy_from_slice(&le[..self.ty.size()]);
        Ok(())
    }
}

/// Is `index` one of the optional touch-probe objects (CiA 402 0x60B8–0x60BD touch probe
/// function, status and edge positions, 0x60D0 touch probe source, 0x60D5–0x60D8 edge
/// counters)? Many CiA 402 drives have none of them (issue 19).
pub fn is_touch_probe(index: u16) -> bool {
    matches!(index, 0x60B8..=0x60BD | 0x60D0 | 0x60D5..=0x60D8)
}

/// The byte layout of one direction of a drive's process data.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoLayout {
    entries: Vec<PdoEntry>,
    len: usize,
}

impl PdoLayout {
    /// Build a layout from objects in mapping order; rejects an object mapped twice.
    pub fn from_objects(objects: &[(u16, u8, DataType)]) -> Result<PdoLayout, PdoError> {
        let mut entries: Vec<PdoEntry> = Vec::with_capacity(objects.len());
        let mut offset = 0;
        for &(index, sub, ty) in objects {
            if entries.iter().any(|e| e.index == index && e.sub == sub) {
                return Err(PdoError::Duplicate { index, sub });
            }
            entries.push(PdoEntry {
                index,
                sub,
                ty,
                offset,
            });
            offset += ty.size();
        }
        Ok(PdoLayout {
            entries,
            len: offset,
        })
    }

    /// The layout without the entries `drop` names, the rest in their order (offsets packed
    /// again).
    pub fn without(&self, mut drop: impl FnMut(u16, u8) -> bool) -> PdoLayout {
        let kept: Vec<_> = self
            .entries
            .iter()
            .filter(|e| !drop(e.index, e.sub))
            .map(|e| (e.index, e.sub, e.ty))
            .collect();
        // The entries were distinct already.
        PdoLayout::from_objects(&kept).unwrap_or_default()
    }

    /// Build a layout from entry references such as `"0x6040:00"` (see [`parse_entry`]).
    pub fn parse<S: AsRef<str>>(specs: &[S]) -> Result<PdoLayout, PdoError> {
        let objects = specs
            .iter()
            .map(|s| parse_entry(s.as_ref()))
            .collect::<Result<Vec<_>, _>>()?;
        PdoLayout::from_objects(&objects)
    }

    /// Entries in image order.
    pub fn entries(&self) -> &[PdoEntry] {
        &self.entries
    }

    /// Bytes of the image.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No entries.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The entry of an object, if mapped.
    pub fn find(&self, index: u16, sub: u8) -> Option<&PdoEntry> {
        self.entries
            .iter()
            .find(|e| e.index == index && e.sub == sub)
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
}
