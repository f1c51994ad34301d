//! EDS / DCF (CiA 306) electronic data sheets.
//!
//! [`parse`] turns the INI text of an EDS or DCF into an [`Eds`]: file and device information,
//! dummy usage, comments, the three object lists and every sub-index as an [`Entry`] keyed by
//! `(index, sub)`. Values stay as written ([`ValueText`]) and are evaluated on demand, because a
//! `$NODEID` term needs the node id the caller picks (CiA 306, key `DefaultValue`).
//!
//! Errors carry the file, line, section and key: `file:line: [section] key: problem`.
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
//!   names, a `SupportedObjects` count that does not match the entries) are warnings by default
//!   and errors with [`ParseOptions::strict`]: `e35.eds` from python-canopen has two of them.
//! - `CompactSubObj=n` (CiA 306 compact storage of sub-objects) creates sub 0 (`UNSIGNED8`, `ro`,
//!   default n, named `NrOfObjects`) and subs 1..=n typed like the object; a sub without an
//!   entry in `[xxxxName]` is named `<ParameterName><sub>`.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::path::Path;

// ------------------------------------------------------------------------------------------------
// Errors

/// What went wrong, for callers that match on the kind instead of the text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
    /// An object list is inconsistent with the object sections (a warning unless strict).
    ObjectList,
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
    fn eval(&self, text: &Option<ValueText>, node_id: u8) -> Option<Value> {
        let text = text.as_ref()?;
        self.data_type.value_from_text(&text.raw, node_id).ok()
    }

    /// `DefaultValue` evaluated with `node_id` for `$NODEID`; `None` if absent.
    pub fn default_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.default, node_id)
    }

    /// `ParameterValue` evaluated with `node_id`; `None` if absent.
    pub fn parameter_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.parameter_value, node_id)
    }

    /// The configured value: `ParameterValue` if present, else `DefaultValue`.
    pub fn value(&self, node_id: u8) -> Option<Value> {
        self.parameter_value(node_id)
            .or_else(|| self.default_value(node_id))
    }

    /// `LowLimit` evaluated with `node_id`.
    pub fn low_limit_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.low_limit, node_id)
    }

    /// `HighLimit` evaluated with `node_id`.
    pub fn high_limit_value(&self, node_id: u8) -> Option<Value> {
        self.eval(&self.high_limit, node_id)
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
    /// Problems tolerated in lenient mode (see [`ParseOptions::strict`]).
    pub warnings: Vec<EdsError>,
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
// INI layer

#[derive(Debug)]
struct Key<'a> {
    name: &'a str,
    value: &'a str,
    line: usize,
    column: usize,
}

#[derive(Debug)]
struct Section<'a> {
    name: &'a str,
    line: usize,
    keys: Vec<Key<'a>>,
    /// Lower-case key name → position in `keys`.
    by_name: HashMap<String, usize>,
}

impl<'a> Section<'a> {
    fn get(&self, name: &str) -> Option<&Key<'a>> {
        self.by_name
            .get(&name.to_ascii_lowercase())
            .and_then(|&i| self.keys.get(i))
    }
}

fn lex<'a>(text: &'a str, p: &Parser) -> Result<Vec<Section<'a>>, EdsError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut sections: Vec<Section<'a>> = Vec::new();
    let mut seen: HashMap<String, usize> = HashMap::new();
    for (i, raw_line) in text.lines().enumerate() {
        let line_no = i + 1;
        let lead = raw_line.len() - raw_line.trim_start().len();
        let line = raw_line.trim();
        if line.is_empty() || line.starts_with(';') || line.starts_with('#') {
            continue;
        }
        if let Some(rest) = line.strip_prefix('[') {
            let Some(name) = rest.strip_suffix(']') else {
                return Err(p.err(
                    EdsErrorKind::Syntax,
                    Some(line_no),
                    None,
                    None,
                    None,
                    "section header without closing `]`",
                ));
            };
            let name = name.trim();
            if name.is_empty() || name.contains(['[', ']']) {
                return Err(p.err(
                    EdsErrorKind::Syntax,
                    Some(line_no),
                    None,
                    None,
                    None,
                    format!("bad section header {line:?}"),
                ));
            }
            let lower = name.to_ascii_lowercase();
            if let Some(first) = seen.get(&lower) {
                return Err(p.err(
                    EdsErrorKind::DuplicateSection,
                    Some(line_no),
                    Some(name),
                    None,
                    None,
                    format!("duplicate section (first at line {first})"),
                ));
            }
            seen.insert(lower, line_no);
            sections.push(Section {
                name,
                line: line_no,
                keys: Vec::new(),
                by_name: HashMap::new(),
            });
            continue;
        }
        let Some((key, value)) = line.split_once('=') else {
            let section = sections.last().map(|s| s.name);
            return Err(p.err(
                EdsErrorKind::Syntax,
                Some(line_no),
                section,
                None,
                None,
                format!("expected `key=value`, got {line:?}"),
            ));
        };
        let key_name = key.trim();
        let value_start = lead + key.len() + 1;
        let mut value = value;
        // Inline comment: `;` after white space (as python-canopen's RawConfigParser).
        if let Some(pos) = value.char_indices().find_map(|(i, c)| {
            (c == ';' && i > 0 && value[..i].ends_with(char::is_whitespace)).then_some(i)
        }) {
            value = &value[..pos];
        }
        let value_lead = value.len() - value.trim_start().len();
        let value = value.trim();
        let column = raw_line
            .get(..value_start + value_lead)
            .map_or(1, |s| s.chars().count() + 1);
        let Some(section) = sections.last_mut() else {
            return Err(p.err(
                EdsErrorKind::KeyOutsideSection,
                Some(line_no),
                None,
                Some(key_name),
                None,
                "key before the first section header",
            ));
        };
        if key_name.is_empty() {
            return Err(p.err(
                EdsErrorKind::Syntax,
                Some(line_no),
                Some(section.name),
                None,
                None,
                "empty key name",
            ));
        }
        let lower = key_name.to_ascii_lowercase();
        if let Some(first) = section.get(&lower) {
            let first = first.line;
            return Err(p.err(
                EdsErrorKind::DuplicateKey,
                Some(line_no),
                Some(section.name),
                Some(key_name),
                None,
                format!("duplicate key (first at line {first})"),
            ));
        }
        section.by_name.insert(lower, section.keys.len());
        section.keys.push(Key {
            name: key_name,
            value,
            line: line_no,
            column,
        });
    }
    Ok(sections)
}

// ------------------------------------------------------------------------------------------------
// Interpretation

/// Parser settings.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ParseOptions {
    /// Treat object-list defects as errors instead of [`Eds::warnings`].
    pub strict: bool,
}

struct Parser<'f> {
    file: &'f str,
    options: ParseOptions,
    warnings: Vec<EdsError>,
}

impl Parser<'_> {
    fn err(
        &self,
        kind: EdsErrorKind,
        line: Option<usize>,
        section: Option<&str>,
        key: Option<&str>,
        column: Option<usize>,
        message: impl Into<String>,
    ) -> EdsError {
        let narrow = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
        EdsError {
            file: self.file.to_string(),
            line: line.map(narrow),
            column: column.map(narrow),
            section: section.map(str::to_string),
            key: key.map(str::to_string),
            kind,
            message: message.into(),
        }
    }

    fn key_err(
        &self,
        kind: EdsErrorKind,
        s: &Section,
        k: &Key,
        message: impl Into<String>,
    ) -> EdsError {
        self.err(
            kind,
            Some(k.line),
            Some(s.name),
            Some(k.name),
            Some(k.column),
            message,
        )
    }

    /// Records a warning, or fails in strict mode.
    fn soft(&mut self, e: EdsError) -> Result<(), EdsError> {
        if self.options.strict {
            Err(e)
        } else {
            self.warnings.push(e);
            Ok(())
        }
    }

    fn number<T: TryFrom<u64>>(&self, s: &Section, k: &Key) -> Result<T, EdsError> {
        let v = parse_u64(k.value).ok_or_else(|| {
            self.key_err(
                EdsErrorKind::BadNumber,
                s,
                k,
                format!("bad number {:?}", k.value),
            )
        })?;
        T::try_from(v).map_err(|_| {
            self.key_err(
                EdsErrorKind::BadNumber,
                s,
                k,
                format!("{} is too large (max {})", k.value, type_max::<T>()),
            )
        })
    }

    fn opt_number<T: TryFrom<u64>>(&self, s: &Section, key: &str) -> Result<Option<T>, EdsError> {
        s.get(key).map(|k| self.number(s, k)).transpose()
    }

    fn flag(&self, s: &Section, key: &str) -> Result<bool, EdsError> {
        match s.get(key) {
            None => Ok(false),
            Some(k) => match parse_u64(k.value) {
                Some(0) => Ok(false),
                Some(1) => Ok(true),
                Some(_) => Err(self.key_err(
                    EdsErrorKind::BadValue,
                    s,
                    k,
                    format!("expected 0 or 1, got {:?}", k.value),
                )),
                None => Err(self.key_err(
                    EdsErrorKind::BadNumber,
                    s,
                    k,
                    format!("bad number {:?} (allowed: 0, 1)", k.value),
                )),
            },
        }
    }
}

fn type_max<T: TryFrom<u64>>() -> u64 {
    // Largest of the maxima of u8, u16, u32, u64 that converts to T, for messages.
    [u8::MAX as u64, u16::MAX as u64, u32::MAX as u64, u64::MAX]
        .into_iter()
        .take_while(|&m| T::try_from(m).is_ok())
        .last()
        .unwrap_or(0)
}

fn key_text(s: &Section, key: &str) -> Option<String> {
    s.get(key).map(|k| k.value.to_string())
}

/// The kind of an object-related section name.
enum SectionName {
    Object(u16),
    Sub(u16, u8),
    Names(u16),
    Values(u16),
    Denotations(u16),
    Other,
}

fn classify(name: &str) -> Result<SectionName, String> {
    let Some(head) = name.get(..4) else {
        return Ok(SectionName::Other);
    };
    if !head.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Ok(SectionName::Other);
    }
    let index = u16::from_str_radix(head, 16).map_err(|e| e.to_string())?;
    let tail = &name[4..];
    if tail.is_empty() {
        return Ok(SectionName::Object(index));
    }
    let lower = tail.to_ascii_lowercase();
    if let Some(sub) = lower.strip_prefix("sub") {
        if sub.is_empty() || sub.len() > 2 || !sub.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(format!(
                "bad sub-index {sub:?} (expected 1 or 2 hex digits)"
            ));
        }
        return Ok(SectionName::Sub(
            index,
            u8::from_str_radix(sub, 16).map_err(|e| e.to_string())?,
        ));
    }
    Ok(match lower.as_str() {
        "name" => SectionName::Names(index),
        "value" => SectionName::Values(index),
        "denotation" => SectionName::Denotations(index),
        _ => SectionName::Other,
    })
}

/// Parses EDS or DCF text leniently (object-list defects become [`Eds::warnings`]).
/// `file` is only used in error messages.
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
    let mut p = Parser {
        file,
        options,
        warnings: Vec::new(),
    };
    let sections = lex(text, &p)?;
    let find = |name: &str| sections.iter().find(|s| s.name.eq_ignore_ascii_case(name));

    let mut eds = Eds {
        file: file.to_string(),
        file_info: FileInfo::default(),
        device_info: DeviceInfo::default(),
        dummy_usage: BTreeMap::new(),
        comments: Vec::new(),
        object_lists: ObjectLists::default(),
        object_headers: BTreeMap::new(),
        objects: BTreeMap::new(),
        commissioning: None,
        other_sections: BTreeMap::new(),
        warnings: Vec::new(),
    };

    if let Some(s) = find("FileInfo") {
        eds.file_info = FileInfo {
            file_name: key_text(s, "FileName"),
            file_version: p.opt_number(s, "FileVersion")?,
            file_revision: p.opt_number(s, "FileRevision")?,
            eds_version: key_text(s, "EDSVersion"),
            description: key_text(s, "Description"),
            creation_time: key_text(s, "CreationTime"),
            creation_date: key_text(s, "CreationDate"),
            created_by: key_text(s, "CreatedBy"),
            modification_time: key_text(s, "ModificationTime"),
            modification_date: key_text(s, "ModificationDate"),
            modified_by: key_text(s, "ModifiedBy"),
        };
    }
    if let Some(s) = find("DeviceInfo") {
        eds.device_info = device_info(&p, s)?;
    }
    if let Some(s) = find("DummyUsage") {
        for k in &s.keys {
            let Some(n) = k
                .name
                .get(5..)
                .filter(|_| k.name[..5].eq_ignore_ascii_case("dummy"))
            else {
                continue;
            };
            let Ok(index) = u16::from_str_radix(n, 16) else {
                continue;
            };
            eds.dummy_usage.insert(index, p.flag(s, k.name)?);
        }
    }
    if let Some(s) = find("Comments") {
        let lines: u32 = p.opt_number(s, "Lines")?.unwrap_or(0);
        for i in 1..=lines.min(10_000) {
            eds.comments
                .push(key_text(s, &format!("Line{i}")).unwrap_or_default());
        }
    }
    for name in ["DeviceComissioning", "DeviceCommissioning"] {
        if let Some(s) = find(name) {
            eds.commissioning = Some(DeviceCommissioning {
                node_id: p.opt_number(s, "NodeID")?,
                node_name: key_text(s, "NodeName"),
                baud_rate: p.opt_number(s, "Baudrate")?,
                net_number: p.opt_number(s, "NetNumber")?,
                network_name: key_text(s, "NetworkName"),
                canopen_manager: p.flag(s, "CANopenManager")?,
                lss_serial_number: p.opt_number(s, "LSS_SerialNumber")?,
            });
        }
    }

    // Object lists.
    let Some(mandatory) = find("MandatoryObjects") else {
        return Err(p.err(
            EdsErrorKind::MissingSection,
            None,
            Some("MandatoryObjects"),
            None,
            None,
            "missing section",
        ));
    };
    eds.object_lists.mandatory = object_list(&mut p, mandatory)?;
    if let Some(s) = find("OptionalObjects") {
        eds.object_lists.optional = object_list(&mut p, s)?;
    }
    if let Some(s) = find("ManufacturerObjects") {
        eds.object_lists.manufacturer = object_list(&mut p, s)?;
    }

    // Object sections, then subs (a sub may come before its object in the file).
    let mut subs: Vec<(u16, u8, &Section)> = Vec::new();
    let mut extras: Vec<(SectionName, &Section)> = Vec::new();
    let mut by_index: BTreeMap<u16, &Section> = BTreeMap::new();
    for s in &sections {
        let kind = classify(s.name).map_err(|m| {
            p.err(
                EdsErrorKind::Syntax,
                Some(s.line),
                Some(s.name),
                None,
                None,
                m,
            )
        })?;
        match kind {
            SectionName::Object(index) => {
                if let Some(first) = by_index.get(&index) {
                    return Err(p.err(
                        EdsErrorKind::DuplicateSection,
                        Some(s.line),
                        Some(s.name),
                        None,
                        None,
                        format!("same object as [{}] at line {}", first.name, first.line),
                    ));
                }
                by_index.insert(index, s);
            }
            SectionName::Sub(index, sub) => subs.push((index, sub, s)),
            SectionName::Other => {
                let known = [
                    "FileInfo",
                    "DeviceInfo",
                    "DummyUsage",
                    "Comments",
                    "MandatoryObjects",
                    "OptionalObjects",
                    "ManufacturerObjects",
                    "DeviceComissioning",
                    "DeviceCommissioning",
                ];
                if !known.iter().any(|n| n.eq_ignore_ascii_case(s.name)) {
                    let keys = s
                        .keys
                        .iter()
                        .map(|k| (k.name.to_string(), k.value.to_string()))
                        .collect();
                    eds.other_sections.insert(s.name.to_string(), keys);
                }
            }
            other => extras.push((other, s)),
        }
    }
    for (&index, s) in &by_index {
        object(&p, &mut eds, index, s)?;
    }
    let mut sub_lines: BTreeMap<(u16, u8), (&str, usize)> = BTreeMap::new();
    for &(index, sub, s) in &subs {
        let Some(header) = eds.object_headers.get(&index) else {
            return Err(p.err(
                EdsErrorKind::MissingSection,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!("sub-index section without its object section [{index:04X}]"),
            ));
        };
        if !header.object_type.has_subs() || header.compact_sub_obj.is_some() {
            return Err(p.err(
                EdsErrorKind::BadValue,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!(
                    "sub-index section for an object that has none (ObjectType {:#x}{})",
                    header.object_type.code(),
                    if header.compact_sub_obj.is_some() {
                        ", CompactSubObj"
                    } else {
                        ""
                    }
                ),
            ));
        }
        if let Some((name, line)) = sub_lines.insert((index, sub), (s.name, s.line)) {
            return Err(p.err(
                EdsErrorKind::DuplicateSection,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!("same sub-index as [{name}] at line {line}"),
            ));
        }
        let entry = entry(&p, s, index, sub, None)?;
        eds.objects.insert((index, sub), entry);
    }
    // SubNumber against the subs present.
    for (&index, &s) in &by_index {
        let Some(header) = eds.object_headers.get(&index) else {
            continue;
        };
        let present = eds.subs(index).count();
        match (
            header.object_type.has_subs(),
            header.sub_number,
            header.compact_sub_obj,
        ) {
            (true, None, None) => {
                return Err(p.err(
                    EdsErrorKind::MissingKey,
                    Some(s.line),
                    Some(s.name),
                    Some("SubNumber"),
                    None,
                    "missing; required for an ARRAY or RECORD without CompactSubObj",
                ));
            }
            (true, Some(n), None) if usize::from(n) != present => {
                let Some(k) = s.get("SubNumber") else {
                    continue;
                };
                return Err(p.key_err(
                    EdsErrorKind::SubNumberMismatch,
                    s,
                    k,
                    format!(
                        "SubNumber={} but {present} sub-index sections are present",
                        k.value
                    ),
                ));
            }
            _ => {}
        }
    }
    // [xxxxName] / [xxxxValue] / [xxxxDenotation] of compact objects.
    for (kind, s) in extras {
        let (index, what) = match kind {
            SectionName::Names(i) => (i, "Name"),
            SectionName::Values(i) => (i, "Value"),
            SectionName::Denotations(i) => (i, "Denotation"),
            _ => continue,
        };
        let compact = eds
            .object_headers
            .get(&index)
            .and_then(|h| h.compact_sub_obj);
        let Some(n) = compact else {
            p.soft(p.err(
                EdsErrorKind::ObjectList,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!("[{index:04X}{what}] for an object without CompactSubObj; ignored"),
            ))?;
            continue;
        };
        for k in &s.keys {
            if k.name.eq_ignore_ascii_case("NrOfEntries") {
                p.number::<u8>(s, k)?;
                continue;
            }
            let sub: u8 = k
                .name
                .parse()
                .ok()
                .filter(|&sub| sub >= 1 && sub <= n)
                .ok_or_else(|| {
                    p.key_err(
                        EdsErrorKind::BadValue,
                        s,
                        k,
                        format!("expected a sub-index 1..={n}"),
                    )
                })?;
            let Some(e) = eds.objects.get_mut(&(index, sub)) else {
                continue;
            };
            match what {
                "Name" => e.parameter_name = k.value.to_string(),
                "Denotation" => e.denotation = Some(k.value.to_string()),
                _ => {
                    check_value(&p, s, k, e.data_type)?;
                    e.parameter_value = Some(ValueText {
                        raw: k.value.to_string(),
                        line: k.line,
                    });
                }
            }
        }
    }
    // Object lists against object sections.
    let mut listed: BTreeMap<u16, ()> = BTreeMap::new();
    for (list, name) in [
        (&eds.object_lists.mandatory, "MandatoryObjects"),
        (&eds.object_lists.optional, "OptionalObjects"),
        (&eds.object_lists.manufacturer, "ManufacturerObjects"),
    ] {
        let s = find(name);
        for (i, &index) in list.iter().enumerate() {
            listed.insert(index, ());
            if !by_index.contains_key(&index) {
                let key = (i + 1).to_string();
                let k = s.and_then(|s| s.get(&key));
                let e = p.err(
                    EdsErrorKind::MissingSection,
                    k.map(|k| k.line),
                    Some(name),
                    Some(&key),
                    k.map(|k| k.column),
                    format!("object 0x{index:04X} is listed but has no section [{index:04X}]"),
                );
                p.soft(e)?;
            }
        }
    }
    for (&index, s) in &by_index {
        if !listed.contains_key(&index) && index > 0x0FFF {
            let e = p.err(
                EdsErrorKind::ObjectList,
                Some(s.line),
                Some(s.name),
                None,
                None,
                "object is in no object list",
            );
            p.soft(e)?;
        }
    }
    eds.warnings = p.warnings;
    Ok(eds)
}

fn device_info(p: &Parser, s: &Section) -> Result<DeviceInfo, EdsError> {
    let mut baud_rates = Vec::new();
    for k in &s.keys {
        let Some(rate) = k
            .name
            .get(9..)
            .filter(|_| k.name[..9].eq_ignore_ascii_case("BaudRate_"))
        else {
            continue;
        };
        let Ok(rate) = rate.parse::<u32>() else {
            continue;
        };
        if p.flag(s, k.name)? {
            baud_rates.push(rate);
        }
    }
    baud_rates.sort_unstable();
    Ok(DeviceInfo {
        vendor_name: key_text(s, "VendorName"),
        vendor_number: p.opt_number(s, "VendorNumber")?,
        product_name: key_text(s, "ProductName"),
        product_number: p.opt_number(s, "ProductNumber")?,
        revision_number: p.opt_number(s, "RevisionNumber")?,
        order_code: key_text(s, "OrderCode"),
        baud_rates,
        simple_boot_up_master: p.flag(s, "SimpleBootUpMaster")?,
        simple_boot_up_slave: p.flag(s, "SimpleBootUpSlave")?,
        granularity: p.opt_number(s, "Granularity")?,
        dynamic_channels_supported: p.opt_number(s, "DynamicChannelsSupported")?,
        group_messaging: p.flag(s, "GroupMessaging")?,
        nr_of_rx_pdo: p.opt_number(s, "NrOfRXPDO")?,
        nr_of_tx_pdo: p.opt_number(s, "NrOfTXPDO")?,
        lss_supported: p.flag(s, "LSS_Supported")?,
        compact_pdo: p.opt_number(s, "CompactPDO")?,
    })
}

fn object_list(p: &mut Parser, s: &Section) -> Result<Vec<u16>, EdsError> {
    let count = match s.get("SupportedObjects") {
        Some(k) => p.number::<u16>(s, k)?,
        None => {
            return Err(p.err(
                EdsErrorKind::MissingKey,
                Some(s.line),
                Some(s.name),
                Some("SupportedObjects"),
                None,
                "missing",
            ));
        }
    };
    let mut out = Vec::new();
    for i in 1..=count {
        match s.get(&i.to_string()) {
            Some(k) => out.push(p.number::<u16>(s, k)?),
            None => {
                let e = p.err(
                    EdsErrorKind::ObjectList,
                    Some(s.line),
                    Some(s.name),
                    Some(&i.to_string()),
                    None,
                    format!("missing; SupportedObjects={count}"),
                );
                p.soft(e)?;
            }
        }
    }
    for k in &s.keys {
        let in_range = k.name.parse::<u16>().is_ok_and(|n| n >= 1 && n <= count);
        if !in_range && !k.name.eq_ignore_ascii_case("SupportedObjects") {
            let e = p.key_err(
                EdsErrorKind::ObjectList,
                s,
                k,
                format!("unexpected key; SupportedObjects={count}"),
            );
            p.soft(e)?;
        }
    }
    Ok(out)
}

fn object_type(p: &Parser, s: &Section) -> Result<ObjectType, EdsError> {
    let Some(k) = s.get("ObjectType") else {
        return Ok(ObjectType::Var);
    };
    let code: u8 = p.number(s, k)?;
    ObjectType::from_code(code).ok_or_else(|| {
        p.key_err(
            EdsErrorKind::UnknownObjectType,
            s,
            k,
            format!(
                "unknown object type {} (allowed: {})",
                k.value,
                ObjectType::ALLOWED
            ),
        )
    })
}

fn object(p: &Parser, eds: &mut Eds, index: u16, s: &Section) -> Result<(), EdsError> {
    let object_type = object_type(p, s)?;
    let sub_number: Option<u8> = p.opt_number(s, "SubNumber")?;
    let compact_sub_obj: Option<u8> = p.opt_number(s, "CompactSubObj")?;
    let header = ObjectHeader {
        index,
        parameter_name: key_text(s, "ParameterName").unwrap_or_default(),
        object_type,
        sub_number,
        compact_sub_obj,
        obj_flags: p.opt_number(s, "ObjFlags")?,
        line: s.line,
    };
    if let (Some(n), Some(k)) = (compact_sub_obj, s.get("CompactSubObj")) {
        if object_type != ObjectType::Array {
            return Err(p.key_err(
                EdsErrorKind::BadValue,
                s,
                k,
                "CompactSubObj is only allowed on an ARRAY (ObjectType=0x8)",
            ));
        }
        if let Some(sn) = s.get("SubNumber") {
            return Err(p.key_err(
                EdsErrorKind::BadValue,
                s,
                sn,
                "SubNumber and CompactSubObj exclude each other",
            ));
        }
        let count = Entry {
            index,
            sub: 0,
            parameter_name: "NrOfObjects".into(),
            object_type: ObjectType::Var,
            data_type: DataType::Unsigned8,
            access: AccessType::ReadOnly,
            default: Some(ValueText {
                raw: n.to_string(),
                line: k.line,
            }),
            low_limit: None,
            high_limit: None,
            pdo_mapping: false,
            parameter_value: None,
            denotation: None,
            obj_flags: None,
            line: s.line,
        };
        eds.objects.insert((index, 0), count);
        for sub in 1..=n {
            let name = format!("{}{sub}", header.parameter_name);
            let e = entry(p, s, index, sub, Some(name))?;
            eds.objects.insert((index, sub), e);
        }
    } else if matches!(
        object_type,
        ObjectType::Var | ObjectType::DefType | ObjectType::Domain
    ) {
        let e = entry(p, s, index, 0, None)?;
        eds.objects.insert((index, 0), e);
    }
    eds.object_headers.insert(index, header);
    Ok(())
}

fn check_value(p: &Parser, s: &Section, k: &Key, data_type: DataType) -> Result<(), EdsError> {
    if matches!(data_type, DataType::Other(_)) {
        return Ok(());
    }
    // $NODEID expressions must fit for every node id 1..=127.
    for node in [1u8, 127] {
        if let Err(e) = data_type.value_from_text(k.value, node) {
            let kind = match e {
                ValueError::Syntax(_)
                    if data_type.is_integer()
                        || matches!(data_type, DataType::Real32 | DataType::Real64) =>
                {
                    EdsErrorKind::BadNumber
                }
                _ => EdsErrorKind::BadValue,
            };
            let mut message = e.to_string();
            if let Ok(expr) = IntExpr::parse(k.value) {
                if expr.uses_node_id() {
                    message = format!("{message} (with $NODEID={node})");
                }
            }
            return Err(p.key_err(kind, s, k, message));
        }
    }
    Ok(())
}

/// Communication objects whose data type CiA 301 fixes (§7.5.2): a master and the emulated
/// node read them with that type, so an EDS declaring another type is refused.
const FIXED_TYPES: &[(u16, u8, DataType, &str)] = &[
    (0x1000, 0, DataType::Unsigned32, "device type"),
    (0x1001, 0, DataType::Unsigned8, "error register"),
    (0x1017, 0, DataType::Unsigned16, "producer heartbeat time"),
];

/// Builds the entry of a VAR section, a sub-index section or (with `compact_name`) a compact sub.
fn entry(
    p: &Parser,
    s: &Section,
    index: u16,
    sub: u8,
    compact_name: Option<String>,
) -> Result<Entry, EdsError> {
    let object_type = if compact_name.is_some() {
        ObjectType::Var
    } else {
        object_type(p, s)?
    };
    let kind_word = if sub == 0 && compact_name.is_none() {
        "a VAR"
    } else {
        "a sub-index"
    };
    let data_type = match s.get("DataType") {
        Some(k) => {
            let code: u16 = p.number(s, k)?;
            DataType::from_code(code).ok_or_else(|| {
                p.key_err(
                    EdsErrorKind::UnknownDataType,
                    s,
                    k,
                    format!(
                        "unknown data type code {} (CiA 301 data type table)",
                        k.value
                    ),
                )
            })?
        }
        None if object_type == ObjectType::Domain => DataType::Domain,
        None => {
            return Err(p.err(
                EdsErrorKind::MissingKey,
                Some(s.line),
                Some(s.name),
                Some("DataType"),
                None,
                format!("missing; required for {kind_word}"),
            ));
        }
    };
    if let Some(&(_, _, expected, what)) = FIXED_TYPES
        .iter()
        .find(|(i, j, _, _)| (*i, *j) == (index, sub))
    {
        if data_type != expected {
            let found = format!("{:#06x} ({data_type:?})", data_type.code());
            let message = format!(
                "object {index:#06x}:{sub:02x} ({what}) must have data type {:#06x} \
                 ({expected:?}, CiA 301), found {found}",
                expected.code()
            );
            return Err(match s.get("DataType") {
                Some(k) => p.key_err(EdsErrorKind::BadValue, s, k, message),
                None => p.err(
                    EdsErrorKind::BadValue,
                    Some(s.line),
                    Some(s.name),
                    Some("DataType"),
                    None,
                    message,
                ),
            });
        }
    }
    let access = match s.get("AccessType") {
        Some(k) => AccessType::parse(k.value).ok_or_else(|| {
            p.key_err(
                EdsErrorKind::UnknownAccessType,
                s,
                k,
                format!(
                    "unknown access type {:?} (allowed: {})",
                    k.value,
                    AccessType::ALLOWED
                ),
            )
        })?,
        None => {
            return Err(p.err(
                EdsErrorKind::MissingKey,
                Some(s.line),
                Some(s.name),
                Some("AccessType"),
                None,
                format!(
                    "missing; required for {kind_word} (allowed: {})",
                    AccessType::ALLOWED
                ),
            ));
        }
    };
    let value = |key: &str| -> Result<Option<ValueText>, EdsError> {
        match s.get(key) {
            Some(k) if !k.value.is_empty() => {
                check_value(p, s, k, data_type)?;
                Ok(Some(ValueText {
                    raw: k.value.to_string(),
                    line: k.line,
                }))
            }
            _ => Ok(None),
        }
    };
    Ok(Entry {
        index,
        sub,
        parameter_name: compact_name
            .unwrap_or_else(|| key_text(s, "ParameterName").unwrap_or_default()),
        object_type,
        data_type,
        access,
        default: value("DefaultValue")?,
        low_limit: value("LowLimit")?,
        high_limit: value("HighLimit")?,
        pdo_mapping: p.flag(s, "PDOMapping")?,
        parameter_value: value("ParameterValue")?,
        denotation: key_text(s, "Denotation"),
        obj_flags: p.opt_number(s, "ObjFlags")?,
        line: s.line,
    })
}
