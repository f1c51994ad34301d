//! EDS / DCF (CiA 306) electronic data sheets.
//!
//! [`parse`] turns the INI text of an EDS or DCF into an [`Eds`]: file and device information,
//! dummy usage, comments, the three object lists and every sub-index as an [`Entry`] keyed by
//! `(index, sub)`. Values stay as written ([`ValueText`]) and are evaluated on demand, because a
//! `$NODEID` term needs the node id the caller picks (CiA 306, key `DefaultValue`).
//!
//! **Files as vendors write them.** The reader is lenient (issue 25): one odd value, a repeated
//! key, a missing `SubNumber` or an unknown access type is a warning ([`EdsWarning`]: file,
//! line, object, the problem and what is read instead; identical problems folded into one with
//! a count), read the way CANopen tools (python-canopen, CANopenNode's editor, CANopen Magic)
//! read it — never a refusal of the whole file. The rules are in the `parse` (structure) and
//! `lenient` (values, [`ValueRole`]) submodules' documentation. [`ParseOptions::strict`]
//! refuses a file at its first problem instead. Errors carry the file, line, section and key:
//! `file:line: [section] key: problem`.
//!
//! Interpretations (CiA 306 v1.3 leaves these open or real files bend the rules):
//! - Comment lines start with `;` (CiA 306) or `#` (python-canopen's `RawConfigParser` accepts
//!   both, and `e35.eds` comments out `ParameterValue` keys with `#`). An inline comment is a `;`
//!   preceded by white space.
//! - Section and key names are compared without regard to case.
//! - `SubNumber` counts the sub-index sections present, not the highest sub-index plus one
//!   (both reference files have `[1800]` with `SubNumber=5` and subs 0, 1, 2, 3, 5).
//! - A hexadecimal literal for a signed type may be written as its two's complement
//!   (`INTEGER16` `0xFFFF` = -1); a `0x` literal for `REAL32`/`REAL64` is the IEEE bit pattern.
//! - Defects in the object lists (a listed object without a section, a section that no list
//!   names, a `SupportedObjects` count that does not match the entries) are warnings too:
//!   `e35.eds` from python-canopen has two of them.
//! - `CompactSubObj=n` (CiA 306 compact storage of sub-objects) creates sub 0 (`UNSIGNED8`, `ro`,
//!   default n, named `NrOfObjects`) and subs 1..=n typed like the object; a sub without an
//!   entry in `[xxxxName]` is named `<ParameterName><sub>`.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

// ------------------------------------------------------------------------------------------------
// Errors

/// What went wrong, for callers that match on the kind instead of the text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EdsErrorKind {
    /// The file could not be read.
    Io,
    /// A line is neither a section header, a `key=value` pair, a comment nor empty.
    Syntax,
    /// A `key=value` line before the first section header.
    KeyOutsideSection,
    /// The same section appears twice.
    DuplicateSection,
    /// The same key appears twice in one section.
    DuplicateKey,
    /// A required section is missing (`[MandatoryObjects]`, an object's own section).
    MissingSection,
    /// A required key is missing (`DataType` or `AccessType` on a VAR, `SubNumber` …).
    MissingKey,
    /// A number does not parse or does not fit.
    BadNumber,
    /// A value has the right syntax but is not allowed here.
    BadValue,
    /// `DataType` names a reserved CiA 301 data type code.
    UnknownDataType,
    /// `ObjectType` is not one of the CiA 301 object codes.
    UnknownObjectType,
    /// `AccessType` is not one of `ro`, `wo`, `rw`, `rwr`, `rww`, `const`.
    UnknownAccessType,
    /// `SubNumber` differs from the number of sub-index sections present.
    SubNumberMismatch,
    /// An object list is inconsistent with the object sections.
    ObjectList,
    /// A value outside the range of its data type.
    OutOfRange,
    /// The device type 0x1000 has no value, or names no CiA device profile.
    DeviceType,
}

/// A problem in an EDS / DCF file, with its position.
///
/// Displayed as `file:line: [section] key: problem (allowed: …)`; the parts that do not apply
/// are left out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EdsError {
    /// File name as given to [`parse`].
    pub file: String,
    /// 1-based line, `None` for problems of the whole file.
    pub line: Option<u32>,
    /// 1-based column of the value, when the problem is in a value.
    pub column: Option<u32>,
    /// Section name as written, without brackets.
    pub section: Option<String>,
    /// Key name as written.
    pub key: Option<String>,
    /// Kind of problem.
    pub kind: EdsErrorKind,
    /// Human-readable problem.
    pub message: String,
}

impl fmt::Display for EdsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        f.write_str(":")?;
        if let Some(section) = &self.section {
            write!(f, " [{section}]")?;
        }
        if let Some(key) = &self.key {
            write!(f, " {key}")?;
        }
        if self.section.is_some() || self.key.is_some() {
            f.write_str(":")?;
        }
        write!(f, " {}", self.message)
    }
}

impl std::error::Error for EdsError {}

/// A value that does not fit its data type, or bytes that do not decode.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValueError {
    /// The text does not parse for the data type.
    #[error("{0}")]
    Syntax(String),
    /// The value is outside the range of the data type.
    #[error("{value} is out of range for {data_type:?}")]
    OutOfRange {
        /// The value as evaluated.
        value: String,
        /// The target data type.
        data_type: DataType,
    },
    /// The [`Value`] variant does not belong to the data type.
    #[error("a {value} value cannot be stored as {data_type:?}")]
    WrongKind {
        /// Variant name of the value.
        value: &'static str,
        /// The target data type.
        data_type: DataType,
    },
    /// A fixed-size type got the wrong number of bytes.
    #[error("{data_type:?} needs {expected} bytes, got {got}")]
    WrongLength {
        /// The data type.
        data_type: DataType,
        /// Its size.
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// No encoding is defined for this data type (complex or profile types).
    #[error("no value encoding for {0:?}")]
    Unsupported(DataType),
}

// ------------------------------------------------------------------------------------------------
// Codes

/// Object code (CiA 301 object code table; EDS key `ObjectType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ObjectType {
    /// 0x0 NULL: no data fields.
    Null,
    /// 0x2 DOMAIN: a large variable amount of data.
    Domain,
    /// 0x5 DEFTYPE: a type definition (`0x0001..0x025F`).
    DefType,
    /// 0x6 DEFSTRUCT: a record type definition.
    DefStruct,
    /// 0x7 VAR: a single value.
    Var,
    /// 0x8 ARRAY: sub-indices of one data type.
    Array,
    /// 0x9 RECORD: sub-indices of any data types.
    Record,
}

impl ObjectType {
    const ALLOWED: &'static str = "0x0 NULL, 0x2 DOMAIN, 0x5 DEFTYPE, 0x6 DEFSTRUCT, 0x7 VAR, \
                                   0x8 ARRAY, 0x9 RECORD";

    /// Decodes an object code.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0x0 => Self::Null,
            0x2 => Self::Domain,
            0x5 => Self::DefType,
            0x6 => Self::DefStruct,
            0x7 => Self::Var,
            0x8 => Self::Array,
            0x9 => Self::Record,
            _ => return None,
        })
    }

    /// The object code.
    pub fn code(self) -> u8 {
        match self {
            Self::Null => 0x0,
            Self::Domain => 0x2,
            Self::DefType => 0x5,
            Self::DefStruct => 0x6,
            Self::Var => 0x7,
            Self::Array => 0x8,
            Self::Record => 0x9,
        }
    }

    /// True for the object codes whose value lives in sub-index sections.
    pub fn has_subs(self) -> bool {
        matches!(self, Self::Array | Self::Record | Self::DefStruct)
    }
}

/// Data type (CiA 301 data type table, dictionary indices 0x0001..=0x001B; EDS key `DataType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[allow(missing_docs)] // the variant names are the CiA 301 names
pub enum DataType {
    Boolean,
    Integer8,
    Integer16,
    Integer24,
    Integer32,
    Integer40,
    Integer48,
    Integer56,
    Integer64,
    Unsigned8,
    Unsigned16,
    Unsigned24,
    Unsigned32,
    Unsigned40,
    Unsigned48,
    Unsigned56,
    Unsigned64,
    Real32,
    Real64,
    VisibleString,
    OctetString,
    UnicodeString,
    TimeOfDay,
    TimeDifference,
    Domain,
    /// A defined but unmodelled code: the CiA 301 complex types 0x20..=0x23 (PDO parameters,
    /// SDO parameter, identity), manufacturer types 0x40..=0x5F and profile types 0x60..=0x25F.
    Other(u16),
}

impl DataType {
    /// Decodes a data type code; `None` for reserved codes.
    pub fn from_code(code: u16) -> Option<Self> {
        use DataType::*;
        Some(match code {
            0x01 => Boolean,
            0x02 => Integer8,
            0x03 => Integer16,
            0x04 => Integer32,
            0x05 => Unsigned8,
            0x06 => Unsigned16,
            0x07 => Unsigned32,
            0x08 => Real32,
            0x09 => VisibleString,
            0x0A => OctetString,
            0x0B => UnicodeString,
            0x0C => TimeOfDay,
            0x0D => TimeDifference,
            0x0F => Domain,
            0x10 => Integer24,
            0x11 => Real64,
            0x12 => Integer40,
            0x13 => Integer48,
            0x14 => Integer56,
            0x15 => Integer64,
            0x16 => Unsigned24,
            0x18 => Unsigned40,
            0x19 => Unsigned48,
            0x1A => Unsigned56,
            0x1B => Unsigned64,
            0x20..=0x23 | 0x40..=0x25F => Other(code),
            _ => return None,
        })
    }

    /// The CiA 301 code.
    pub fn code(self) -> u16 {
        use DataType::*;
        match self {
            Boolean => 0x01,
            Integer8 => 0x02,
            Integer16 => 0x03,
            Integer32 => 0x04,
            Unsigned8 => 0x05,
            Unsigned16 => 0x06,
            Unsigned32 => 0x07,
            Real32 => 0x08,
            VisibleString => 0x09,
            OctetString => 0x0A,
            UnicodeString => 0x0B,
            TimeOfDay => 0x0C,
            TimeDifference => 0x0D,
            Domain => 0x0F,
            Integer24 => 0x10,
            Real64 => 0x11,
            Integer40 => 0x12,
            Integer48 => 0x13,
            Integer56 => 0x14,
            Integer64 => 0x15,
            Unsigned24 => 0x16,
            Unsigned40 => 0x18,
            Unsigned48 => 0x19,
            Unsigned56 => 0x1A,
            Unsigned64 => 0x1B,
            Other(code) => code,
        }
    }

    /// Size in bytes on the wire; `None` for strings, domains and unmodelled types.
    pub fn size(self) -> Option<usize> {
        use DataType::*;
        Some(match self {
            Boolean | Integer8 | Unsigned8 => 1,
            Integer16 | Unsigned16 => 2,
            Integer24 | Unsigned24 => 3,
            Integer32 | Unsigned32 | Real32 => 4,
            Integer40 | Unsigned40 => 5,
            Integer48 | Unsigned48 | TimeOfDay | TimeDifference => 6,
            Integer56 | Unsigned56 => 7,
            Integer64 | Unsigned64 | Real64 => 8,
            VisibleString | OctetString | UnicodeString | Domain | Other(_) => return None,
        })
    }

    /// Length in a PDO mapping entry (CiA 301 PDO mapping parameter): 1 bit for BOOLEAN, else 8 × size.
    pub fn bit_len(self) -> Option<u8> {
        match self {
            DataType::Boolean => Some(1),
            other => other.size().and_then(|s| u8::try_from(s * 8).ok()),
        }
    }

    /// Bit width and signedness of the integer types.
    fn int_shape(self) -> Option<(u32, bool)> {
        use DataType::*;
        Some(match self {
            Boolean => (1, false),
            Integer8 => (8, true),
            Integer16 => (16, true),
            Integer24 => (24, true),
            Integer32 => (32, true),
            Integer40 => (40, true),
            Integer48 => (48, true),
            Integer56 => (56, true),
            Integer64 => (64, true),
            Unsigned8 => (8, false),
            Unsigned16 => (16, false),
            Unsigned24 => (24, false),
            Unsigned32 => (32, false),
            Unsigned40 => (40, false),
            Unsigned48 => (48, false),
            Unsigned56 => (56, false),
            Unsigned64 => (64, false),
            _ => return None,
        })
    }

    /// True for the types whose EDS values are integers (and may use `$NODEID`).
    pub fn is_integer(self) -> bool {
        self.int_shape().is_some()
    }

    /// Evaluates EDS value text for this type; `$NODEID` is replaced by `node_id`.
    ///
    /// Integers: decimal, `0x` hex, octal with a leading `0`, and sums such as `$NODEID+0x180`.
    /// Reals: decimal float or `0x` bit pattern. VISIBLE_STRING and UNICODE_STRING: the text.
    /// OCTET_STRING and DOMAIN: hex digit pairs (spaces allowed). TIME_OF_DAY / TIME_DIFFERENCE:
    /// the 48-bit raw value as an integer.
    pub fn value_from_text(self, text: &str, node_id: u8) -> Result<Value, ValueError> {
        use DataType::*;
        let text = text.trim();
        if let Some((bits, signed)) = self.int_shape() {
            let expr = IntExpr::parse(text).map_err(ValueError::Syntax)?;
            let v = expr.eval(node_id);
            return self.fit_int(v, bits, signed, expr.is_plain_hex());
        }
        match self {
            Real32 | Real64 => {
                let bits_text = text.strip_prefix("0x").or_else(|| text.strip_prefix("0X"));
                let v = match bits_text {
                    Some(hex) => {
                        let raw = u64::from_str_radix(hex, 16)
                            .map_err(|_| ValueError::Syntax(format!("bad hex number {text:?}")))?;
                        if self == Real32 {
                            let raw = u32::try_from(raw).map_err(|_| ValueError::OutOfRange {
                                value: text.to_string(),
                                data_type: self,
                            })?;
                            f64::from(f32::from_bits(raw))
                        } else {
                            f64::from_bits(raw)
                        }
                    }
                    None => text
                        .parse::<f64>()
                        .map_err(|_| ValueError::Syntax(format!("bad real number {text:?}")))?,
                };
                Ok(if self == Real32 {
                    Value::Real32(v as f32)
                } else {
                    Value::Real64(v)
                })
            }
            VisibleString => Ok(Value::Text(text.to_string())),
            UnicodeString => Ok(Value::Unicode(text.encode_utf16().collect())),
            OctetString | Domain => Ok(Value::Bytes(
                parse_hex_bytes(text).map_err(ValueError::Syntax)?,
            )),
            TimeOfDay | TimeDifference => {
                let expr = IntExpr::parse(text).map_err(ValueError::Syntax)?;
                let v = expr.eval(node_id);
                match self.fit_int(v, 48, false, false)? {
                    Value::Unsigned(raw) => Ok(Value::Time {
                        ms: (raw & 0x0FFF_FFFF) as u32,
                        days: (raw >> 32) as u16,
                    }),
                    _ => Err(ValueError::Unsupported(self)),
                }
            }
            _ => Err(ValueError::Unsupported(self)),
        }
    }

    fn fit_int(self, v: i128, bits: u32, signed: bool, twos: bool) -> Result<Value, ValueError> {
        let out = || ValueError::OutOfRange {
            value: v.to_string(),
            data_type: self,
        };
        if bits == 1 {
            return match v {
                0 => Ok(Value::Bool(false)),
                1 => Ok(Value::Bool(true)),
                _ => Err(out()),
            };
        }
        let umax: i128 = (1i128 << bits) - 1;
        if signed {
            let max = (1i128 << (bits - 1)) - 1;
            let min = -(1i128 << (bits - 1));
            let v = if twos && v > max && v <= umax {
                v - (1i128 << bits)
            } else {
                v
            };
            if v < min || v > max {
                return Err(out());
            }
            Ok(Value::Integer(v as i64))
        } else {
            if v < 0 || v > umax {
                return Err(out());
            }
            Ok(Value::Unsigned(v as u64))
        }
    }

    /// Encodes a value little-endian (CiA 301 data type encoding). Strings and domains are copied as is.
    pub fn encode(self, value: &Value) -> Result<Vec<u8>, ValueError> {
        use DataType::*;
        let wrong = || ValueError::WrongKind {
            value: value.kind_name(),
            data_type: self,
        };
        if let Some((bits, signed)) = self.int_shape() {
            let size = self.size().unwrap_or(1);
            let v: i128 = match *value {
                Value::Bool(b) => i128::from(b),
                Value::Integer(i) => i128::from(i),
                Value::Unsigned(u) => i128::from(u),
                _ => return Err(wrong()),
            };
            let fitted = self.fit_int(v, bits, signed, false)?;
            let raw: u64 = match fitted {
                Value::Bool(b) => u64::from(b),
                Value::Integer(i) => i as u64,
                Value::Unsigned(u) => u,
                _ => return Err(wrong()),
            };
            return Ok(raw.to_le_bytes()[..size].to_vec());
        }
        match (self, value) {
            (Real32, Value::Real32(f)) => Ok(f.to_le_bytes().to_vec()),
            (Real64, Value::Real64(f)) => Ok(f.to_le_bytes().to_vec()),
            (VisibleString, Value::Text(s)) => Ok(s.as_bytes().to_vec()),
            (UnicodeString, Value::Unicode(u)) => {
                Ok(u.iter().flat_map(|c| c.to_le_bytes()).collect())
            }
            (OctetString | Domain, Value::Bytes(b)) => Ok(b.clone()),
            (TimeOfDay | TimeDifference, Value::Time { ms, days }) => {
                let mut out = (ms & 0x0FFF_FFFF).to_le_bytes().to_vec();
                out.extend_from_slice(&days.to_le_bytes());
                Ok(out)
            }
            (Other(_), _) => Err(ValueError::Unsupported(self)),
            _ => Err(wrong()),
        }
    }

    /// Decodes little-endian bytes; fixed-size types need exactly [`size`](Self::size) bytes.
    pub fn decode(self, bytes: &[u8]) -> Result<Value, ValueError> {
        use DataType::*;
        if let Some(size) = self.size() {
            if bytes.len() != size {
                return Err(ValueError::WrongLength {
                    data_type: self,
                    expected: size,
                    got: bytes.len(),
                });
            }
        }
        if let Some((bits, signed)) = self.int_shape() {
            let mut buf = [0u8; 8];
            buf[..bytes.len()].copy_from_slice(bytes);
            let raw = u64::from_le_bytes(buf);
            if bits == 1 {
                return match raw {
                    0 => Ok(Value::Bool(false)),
                    1 => Ok(Value::Bool(true)),
                    _ => Err(ValueError::OutOfRange {
                        value: raw.to_string(),
                        data_type: self,
                    }),
                };
            }
            return Ok(if signed {
                let shift = 64 - bits;
                Value::Integer(((raw << shift) as i64) >> shift)
            } else {
                Value::Unsigned(raw)
            });
        }
        let fixed = |n: usize| -> [u8; 8] {
            let mut buf = [0u8; 8];
            buf[..n].copy_from_slice(&bytes[..n]);
            buf
        };
        match self {
            Real32 => {
                let b = fixed(4);
                Ok(Value::Real32(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
            }
            Real64 => Ok(Value::Real64(f64::from_le_bytes(fixed(8)))),
            VisibleString => Ok(Value::Text(bytes.iter().map(|&b| char::from(b)).collect())),
            UnicodeString => {
                if bytes.len() % 2 == 1 {
                    return Err(ValueError::Syntax(
                        "odd number of bytes in a UNICODE_STRING".into(),
                    ));
                }
                Ok(Value::Unicode(
                    bytes
                        .chunks_exact(2)
                        .map(|c| u16::from_le_bytes([c[0], c[1]]))
                        .collect(),
                ))
            }
            OctetString | Domain => Ok(Value::Bytes(bytes.to_vec())),
            TimeOfDay | TimeDifference => {
                let b = fixed(6);
                Ok(Value::Time {
                    ms: u32::from_le_bytes([b[0], b[1], b[2], b[3]]) & 0x0FFF_FFFF,
                    days: u16::from_le_bytes([b[4], b[5]]),
                })
            }
            _ => Err(ValueError::Unsupported(self)),
        }
    }
}

/// Access type (CiA 306 key `AccessType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AccessType {
    /// `ro`: read only.
    ReadOnly,
    /// `wo`: write only.
    WriteOnly,
    /// `rw`: read and write.
    ReadWrite,
    /// `rwr`: read and write, mapped into a TPDO (process input).
    ReadWriteInput,
    /// `rww`: read and write, mapped into an RPDO (process output).
    ReadWriteOutput,
    /// `const`: read only, never changes.
    Const,
}

impl AccessType {
    /// The allowed spellings, for error messages.
    pub const ALLOWED: &'static str = "ro, wo, rw, rwr, rww, const";

    /// Parses an EDS spelling, ignoring case.
    pub fn parse(text: &str) -> Option<Self> {
        Some(match text.trim().to_ascii_lowercase().as_str() {
            "ro" => Self::ReadOnly,
            "wo" => Self::WriteOnly,
            "rw" => Self::ReadWrite,
            "rwr" => Self::ReadWriteInput,
            "rww" => Self::ReadWriteOutput,
            "const" => Self::Const,
            _ => return None,
        })
    }

    /// True if an SDO upload is allowed.
    pub fn readable(self) -> bool {
        self != Self::WriteOnly
    }

    /// True if an SDO download is allowed.
    pub fn writable(self) -> bool {
        !matches!(self, Self::ReadOnly | Self::Const)
    }
}

/// An evaluated value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// BOOLEAN.
    Bool(bool),
    /// INTEGER8..INTEGER64.
    Integer(i64),
    /// UNSIGNED8..UNSIGNED64.
    Unsigned(u64),
    /// REAL32.
    Real32(f32),
    /// REAL64.
    Real64(f64),
    /// VISIBLE_STRING.
    Text(String),
    /// UNICODE_STRING as UTF-16 code units.
    Unicode(Vec<u16>),
    /// OCTET_STRING or DOMAIN.
    Bytes(Vec<u8>),
    /// TIME_OF_DAY / TIME_DIFFERENCE (CiA 301): ms after midnight (28 bits), days.
    Time {
        /// Milliseconds, 28 bits.
        ms: u32,
        /// Days since 1984-01-01 (TIME_OF_DAY) or a day count (TIME_DIFFERENCE).
        days: u16,
    },
}

impl Value {
    fn kind_name(&self) -> &'static str {
        match self {
            Value::Bool(_) => "Bool",
            Value::Integer(_) => "Integer",
            Value::Unsigned(_) => "Unsigned",
            Value::Real32(_) => "Real32",
            Value::Real64(_) => "Real64",
            Value::Text(_) => "Text",
            Value::Unicode(_) => "Unicode",
            Value::Bytes(_) => "Bytes",
            Value::Time { .. } => "Time",
        }
    }

    /// The value as u64 if it is a non-negative integer or a boolean.
    pub fn as_u64(&self) -> Option<u64> {
        match *self {
            Value::Bool(b) => Some(u64::from(b)),
            Value::Unsigned(u) => Some(u),
            Value::Integer(i) => u64::try_from(i).ok(),
            _ => None,
        }
    }

    /// The value as i64 if it is an integer that fits.
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            Value::Bool(b) => Some(i64::from(b)),
            Value::Unsigned(u) => i64::try_from(u).ok(),
            Value::Integer(i) => Some(i),
            _ => None,
        }
    }
}

/// Integer expression: a sum of literals and `$NODEID` terms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct IntExpr {
    constant: i128,
    node_ids: i32,
    plain_hex: bool,
}

impl IntExpr {
    fn parse(text: &str) -> Result<Self, String> {
        let text = text.trim();
        if text.is_empty() {
            return Err("empty number".into());
        }
        let mut expr = IntExpr {
            constant: 0,
            node_ids: 0,
            plain_hex: false,
        };
        let mut terms = 0;
        let mut rest = text;
        let mut negative = false;
        // Leading sign of the first term.
        if let Some(r) = rest.strip_prefix('-') {
            negative = true;
            rest = r;
        } else if let Some(r) = rest.strip_prefix('+') {
            rest = r;
        }
        loop {
            let end = rest.find(['+', '-']).unwrap_or(rest.len());
            let (term, tail) = rest.split_at(end);
            let term = term.trim();
            if term.is_empty() {
                return Err(format!("bad number {text:?}"));
            }
            terms += 1;
            if term.eq_ignore_ascii_case("$NODEID") {
                expr.node_ids += if negative { -1 } else { 1 };
            } else {
                let v = parse_literal(term).ok_or_else(|| format!("bad number {text:?}"))?;
                let v = if negative { -v } else { v };
                expr.constant = expr
                    .constant
                    .checked_add(v)
                    .ok_or_else(|| format!("number too large {text:?}"))?;
                if terms == 1
                    && !negative
                    && term.len() > 2
                    && term.get(..2).is_some_and(|h| h.eq_ignore_ascii_case("0x"))
                {
                    expr.plain_hex = true;
                }
            }
            if expr.node_ids.abs() > 16 || terms > 16 {
                return Err(format!("expression too long {text:?}"));
            }
            match tail.chars().next() {
                None => break,
                Some(c) => {
                    negative = c == '-';
                    rest = &tail[1..];
                }
            }
        }
        if terms > 1 || expr.node_ids != 0 {
            expr.plain_hex = false;
        }
        Ok(expr)
    }

    fn is_plain_hex(&self) -> bool {
        self.plain_hex
    }

    fn uses_node_id(&self) -> bool {
        self.node_ids != 0
    }

    fn eval(&self, node_id: u8) -> i128 {
        self.constant + i128::from(self.node_ids) * i128::from(node_id)
    }
}

/// Parses one literal: `0x` hex, octal with a leading `0`, or decimal. Up to 64 bits.
fn parse_literal(term: &str) -> Option<i128> {
    let (digits, radix) =
        if let Some(h) = term.strip_prefix("0x").or_else(|| term.strip_prefix("0X")) {
            (h, 16)
        } else if term.len() > 1 && term.starts_with('0') {
            (&term[1..], 8)
        } else {
            (term, 10)
        };
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    u64::from_str_radix(digits, radix).ok().map(i128::from)
}

/// Parses an unsigned number of the header sections (no `$NODEID`).
fn parse_u64(text: &str) -> Option<u64> {
    let text = text.trim();
    let v = parse_literal(text.strip_prefix('+').unwrap_or(text))?;
    u64::try_from(v).ok()
}

fn parse_hex_bytes(text: &str) -> Result<Vec<u8>, String> {
    let digits: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if digits.len() % 2 == 1 || !digits.iter().all(u8::is_ascii_hexdigit) {
        return Err(format!("expected hex digit pairs, got {text:?}"));
    }
    Ok(digits
        .chunks_exact(2)
        .map(|p| {
            let hi = (p[0] as char).to_digit(16).unwrap_or(0);
            let lo = (p[1] as char).to_digit(16).unwrap_or(0);
            (hi * 16 + lo) as u8
        })
        .collect())
}

// ------------------------------------------------------------------------------------------------
// Model

/// A value as written in the file, with its line, evaluated on demand.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ValueText {
    /// The text after `=`, trimmed.
    pub raw: String,
    /// 1-based line of the key.
    pub line: usize,
}

impl ValueText {
    /// True if the text contains a `$NODEID` term.
    pub fn uses_node_id(&self) -> bool {
        self.raw.to_ascii_uppercase().contains("$NODEID")
    }
}

/// `[FileInfo]`. Text fields as written.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[allow(missing_docs)] // field names are the EDS key names
pub struct FileInfo {
    pub file_name: Option<String>,
    pub file_version: Option<u64>,
    pub file_revision: Option<u64>,
    pub eds_version: Option<String>,
    pub description: Option<String>,
    pub creation_time: Option<String>,
    pub creation_date: Option<String>,
    pub created_by: Option<String>,
    pub modification_time: Option<String>,
    pub modification_date: Option<String>,
    pub modified_by: Option<String>,
}

/// `[DeviceInfo]`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DeviceInfo {
    /// `VendorName`.
    pub vendor_name: Option<String>,
    /// `VendorNumber` (the 0x1018 sub 1 vendor id).
    pub vendor_number: Option<u32>,
    /// `ProductName`.
    pub product_name: Option<String>,
    /// `ProductNumber` (0x1018 sub 2).
    pub product_number: Option<u32>,
    /// `RevisionNumber` (0x1018 sub 3).
    pub revision_number: Option<u32>,
    /// `OrderCode`.
    pub order_code: Option<String>,
    /// Supported bit rates in kbit/s, from `BaudRate_<kbit/s>=1`, ascending.
    pub baud_rates: Vec<u32>,
    /// `SimpleBootUpMaster`.
    pub simple_boot_up_master: bool,
    /// `SimpleBootUpSlave`.
    pub simple_boot_up_slave: bool,
    /// `Granularity`: PDO mapping granularity in bits (0 = no mapping, 8 = byte).
    pub granularity: Option<u8>,
    /// `DynamicChannelsSupported`.
    pub dynamic_channels_supported: Option<u64>,
    /// `GroupMessaging`.
    pub group_messaging: bool,
    /// `NrOfRXPDO`.
    pub nr_of_rx_pdo: Option<u16>,
    /// `NrOfTXPDO`.
    pub nr_of_tx_pdo: Option<u16>,
    /// `LSS_Supported`.
    pub lss_supported: bool,
    /// `CompactPDO` bit field.
    pub compact_pdo: Option<u64>,
}

/// `[DeviceComissioning]` of a DCF (CiA 306 DCF; the spec spells the section with one "m", `DeviceCommissioning` is accepted too).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DeviceCommissioning {
    /// `NodeID`.
    pub node_id: Option<u8>,
    /// `NodeName`.
    pub node_name: Option<String>,
    /// `Baudrate` in kbit/s.
    pub baud_rate: Option<u32>,
    /// `NetNumber`.
    pub net_number: Option<u32>,
    /// `NetworkName`.
    pub network_name: Option<String>,
    /// `CANopenManager`.
    pub canopen_manager: bool,
    /// `LSS_SerialNumber`.
    pub lss_serial_number: Option<u32>,
}

/// The three object lists in file order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ObjectLists {
    /// `[MandatoryObjects]`.
    pub mandatory: Vec<u16>,
    /// `[OptionalObjects]`.
    pub optional: Vec<u16>,
    /// `[ManufacturerObjects]`.
    pub manufacturer: Vec<u16>,
}

impl ObjectLists {
    /// All listed indices: mandatory, then optional, then manufacturer.
    pub fn all(&self) -> impl Iterator<Item = u16> + '_ {
        self.mandatory
            .iter()
            .chain(&self.optional)
            .chain(&self.manufacturer)
            .copied()
    }
}

/// An object's own section `[xxxx]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectHeader {
    /// Index.
    pub index: u16,
    /// `ParameterName`.
    pub parameter_name: String,
    /// `ObjectType` (VAR when absent).
    pub object_type: ObjectType,
    /// `SubNumber`: the number of sub-index sections.
    pub sub_number: Option<u8>,
    /// `CompactSubObj`: compact storage of subs 1..=n.
    pub compact_sub_obj: Option<u8>,
    /// `ObjFlags`.
    pub obj_flags: Option<u32>,
    /// 1-based line of the section header.
    pub line: usize,
}

/// One sub-index (a VAR object is its sub 0).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    /// Index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// `ParameterName`.
    pub parameter_name: String,
    /// `ObjectType` of this section (VAR for sub-indices).
    pub object_type: ObjectType,
    /// `DataType`.
    pub data_type: DataType,
    /// `AccessType`.
    pub access: AccessType,
    /// `DefaultValue`; an empty value counts as absent.
    pub default: Option<ValueText>,
    /// `LowLimit`.
    pub low_limit: Option<ValueText>,
    /// `HighLimit`.
    pub high_limit: Option<ValueText>,
    /// `PDOMapping` (false when absent).
    pub pdo_mapping: bool,
    /// `ParameterValue` (DCF; a few EDS files carry it too).
    pub parameter_value: Option<ValueText>,
    /// `Denotation` (DCF).
    pub denotation: Option<String>,
    /// `ObjFlags`.
    pub obj_flags: Option<u32>,
    /// 1-based line of the section header (of the object, for compact subs).
    pub line: usize,
}

impl Entry {
    fn eval(&self, text: &Option<ValueText>, node_id: u8, role: ValueRole) -> Option<Value> {
        let text = text.as_ref()?;
        self.data_type
            .value_from_text_lenient(&text.raw, node_id, role)
            .ok()
            .map(|(v, _)| v)
    }

    /// `DefaultValue` evaluated with `node_id` for `$NODEID`; `None` if absent or unreadable.
    /// A value that does not fit its type is read as the `lenient` module documents (the parse
    /// warned about it).
    pub fn default_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.default, node_id, ValueRole::Value)
    }

    /// `ParameterValue` evaluated with `node_id`; `None` if absent or unreadable.
    pub fn parameter_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.parameter_value, node_id, ValueRole::Value)
    }

    /// The configured value: `ParameterValue` if present, else `DefaultValue`.
    pub fn value(&self, node_id: u8) -> Option<Value> {
        self.parameter_value(node_id)
            .or_else(|| self.default_value(node_id))
    }

    /// `LowLimit` evaluated with `node_id`; one below the type's range reads as the type's
    /// smallest value.
    pub fn low_limit_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.low_limit, node_id, ValueRole::Limit)
    }

    /// `HighLimit` evaluated with `node_id`; one above the type's range reads as the type's
    /// largest value (`HighLimit=65536` on an UNSIGNED16 is 65535).
    pub fn high_limit_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.high_limit, node_id, ValueRole::Limit)
    }

    /// [`value`](Self::value) encoded little-endian, ready for an object dictionary.
    pub fn value_bytes(&self, node_id: u8) -> Option<Vec<u8>> {
        self.data_type.encode(&self.value(node_id)?).ok()
    }

    /// Into which PDOs the entry may be mapped, (RPDO, TPDO): none without `PDOMapping=1`;
    /// with it, by `AccessType` (CiA 306 §4.6.3): `rww` / `wo` into an RPDO (process output),
    /// `ro` / `const` / `rwr` into a TPDO (process input), `rw` into either.
    pub fn pdo_directions(&self) -> (bool, bool) {
        if !self.pdo_mapping {
            return (false, false);
        }
        use AccessType as A;
        match self.access {
            A::WriteOnly | A::ReadWriteOutput => (true, false),
            A::ReadOnly | A::Const | A::ReadWriteInput => (false, true),
            A::ReadWrite => (true, true),
        }
    }

    /// PDO mapping entry `index << 16 | sub << 8 | bit length` (CiA 301 PDO mapping parameter), if mappable.
    pub fn mapping_entry(&self) -> Option<u32> {
        if !self.pdo_mapping {
            return None;
        }
        let bits = self.data_type.bit_len()?;
        Some(u32::from(self.index) << 16 | u32::from(self.sub) << 8 | u32::from(bits))
    }
}

/// Identity object 0x1018 subs 1..=4.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Identity {
    /// Sub 1, else `[DeviceInfo] VendorNumber`.
    pub vendor_id: Option<u32>,
    /// Sub 2, else `ProductNumber`.
    pub product_code: Option<u32>,
    /// Sub 3, else `RevisionNumber`.
    pub revision_number: Option<u32>,
    /// Sub 4.
    pub serial_number: Option<u32>,
}

/// A parsed EDS or DCF.
#[derive(Debug, Clone, PartialEq)]
pub struct Eds {
    /// File name as given to [`parse`].
    pub file: String,
    /// `[FileInfo]`.
    pub file_info: FileInfo,
    /// `[DeviceInfo]`.
    pub device_info: DeviceInfo,
    /// `[DummyUsage]`: data type index (1..=7) → may be mapped as a dummy.
    pub dummy_usage: BTreeMap<u16, bool>,
    /// `[Comments]` lines in order.
    pub comments: Vec<String>,
    /// The object lists in file order.
    pub object_lists: ObjectLists,
    /// Object sections `[xxxx]`.
    pub object_headers: BTreeMap<u16, ObjectHeader>,
    /// Every sub-index, including compact-storage subs.
    pub objects: BTreeMap<(u16, u8), Entry>,
    /// `[DeviceComissioning]` of a DCF.
    pub commissioning: Option<DeviceCommissioning>,
    /// Sections this parser does not interpret (`[Tools]`, modular devices …), keys in order.
    pub other_sections: BTreeMap<String, Vec<(String, String)>>,
    /// What the lenient reader read in its own way (see [`ParseOptions::strict`]), identical
    /// problems folded; the commands that load an EDS print each once on stderr.
    pub warnings: Vec<EdsWarning>,
}

impl Eds {
    /// The entry at `(index, sub)`.
    pub fn get(&self, index: u16, sub: u8) -> Option<&Entry> {
        self.objects.get(&(index, sub))
    }

    /// All entries of one index, by sub-index.
    pub fn subs(&self, index: u16) -> impl Iterator<Item = &Entry> + '_ {
        self.objects
            .range((index, 0)..=(index, u8::MAX))
            .map(|(_, e)| e)
    }

    /// Node id of a DCF (`[DeviceComissioning] NodeID`).
    pub fn node_id(&self) -> Option<u8> {
        self.commissioning.as_ref().and_then(|c| c.node_id)
    }

    /// Identity 0x1018 from the sub-index defaults, falling back to `[DeviceInfo]`.
    pub fn identity(&self) -> Identity {
        let node = self.node_id().unwrap_or(0);
        let sub = |s: u8| {
            self.get(0x1018, s)
                .and_then(|e| e.value(node))
                .and_then(|v| v.as_u64())
                .and_then(|v| u32::try_from(v).ok())
        };
        Identity {
            vendor_id: sub(1).or(self.device_info.vendor_number),
            product_code: sub(2).or(self.device_info.product_number),
            revision_number: sub(3).or(self.device_info.revision_number),
            serial_number: sub(4),
        }
    }

    /// True if `(index, sub)` may be mapped into a PDO: `PDOMapping=1`, or a dummy data type
    /// object 0x0001..=0x0007 sub 0 enabled in `[DummyUsage]`.
    pub fn pdo_mappable(&self, index: u16, sub: u8) -> bool {
        if (1..=7).contains(&index) && sub == 0 && self.dummy_usage.get(&index) == Some(&true) {
            return true;
        }
        self.get(index, sub).is_some_and(|e| e.pdo_mapping)
    }
}

// ------------------------------------------------------------------------------------------------
// Reading

mod ini;
mod lenient;
mod parse;
mod warning;

pub use lenient::ValueRole;
pub use warning::{EdsWarning, Place, PLACES_SHOWN};

/// Parser settings.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ParseOptions {
    /// Refuse the file at its first problem instead of reading it with [`Eds::warnings`]
    /// (validating a file one writes; the commands read leniently).
    pub strict: bool,
}

/// Parses EDS or DCF text leniently: whatever a vendor's file gets wrong is read the way
/// CANopen tools read it and becomes one of the [`Eds::warnings`] (the `parse` module lists
/// what is read instead); only text with no object section at all is refused. `file` is only
/// used in messages.
pub fn parse(text: &str, file: &str) -> Result<Eds, EdsError> {
    parse_with(text, file, ParseOptions::default())
}

/// Reads and parses a file. Bytes that are not UTF-8 are read as ISO 8859-1.
pub fn load(path: impl AsRef<Path>) -> Result<Eds, EdsError> {
    load_with(path, ParseOptions::default())
}

/// [`load`] with options.
pub fn load_with(path: impl AsRef<Path>, options: ParseOptions) -> Result<Eds, EdsError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let bytes = crate::limits::read_file(path, "EDS file", crate::limits::MAX_EDS_FILE_BYTES)
        .map_err(|e| EdsError {
            file: file.clone(),
            line: None,
            column: None,
            section: None,
            key: None,
            kind: EdsErrorKind::Io,
            message: e.to_string(),
        })?;
    let text = match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => e.into_bytes().iter().map(|&b| char::from(b)).collect(),
    };
    parse_with(&text, &file, options)
}

/// [`parse`] with options.
pub fn parse_with(text: &str, file: &str, options: ParseOptions) -> Result<Eds, EdsError> {
    parse::run(text, file, options)
}
