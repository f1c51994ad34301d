//! `--type` of `sdo read` / `sdo write`: the CiA 301 basic data types a commissioning engineer
//! reads and writes by SDO (CiA 301 §7.1.4 data type table; CoE uses the same, ETG.1000.6
//! §5.6.2), their names as fieldprobe, IgH's `ethercat upload --type`, CiA 301 / EDS and
//! IEC 61131-3 / ESI spell them, and the little-endian encoding of a value (CiA 301 §7.1.2
//! "transfer syntax": least significant byte first; REAL32 / REAL64 are IEEE 754 binary32 /
//! binary64).
//!
//! This is a CLI-side type: [`fieldprobe::drive::pdo::DataType`] stays the set of types a PDO
//! layout maps (up to 32 bits, values as `i64`); a known CiA 402 object's type converts with
//! [`ValueType::from_pdo`].

use super::number::{self, REAL_FORM};
use fieldprobe::drive::pdo::DataType;

/// A `--type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    /// BOOLEAN (0x0001), one byte, 0 or 1.
    Bool,
    /// UNSIGNED8 (0x0005).
    U8,
    /// UNSIGNED16 (0x0006).
    U16,
    /// UNSIGNED32 (0x0007).
    U32,
    /// UNSIGNED64 (0x001B).
    U64,
    /// INTEGER8 (0x0002).
    I8,
    /// INTEGER16 (0x0003).
    I16,
    /// INTEGER32 (0x0004).
    I32,
    /// INTEGER64 (0x0015).
    I64,
    /// REAL32 (0x0008), IEEE 754 binary32.
    F32,
    /// REAL64 (0x0011), IEEE 754 binary64.
    F64,
    /// VISIBLE_STRING (0x0009): the text's bytes as given.
    Str,
    /// OCTET_STRING (0x000A) / DOMAIN: bytes in the order they are sent.
    Bytes,
}

/// Every type with its names: fieldprobe's first, then IgH's, CiA 301's and IEC 61131-3's.
const NAMES: &[(ValueType, &[&str])] = &[
    (ValueType::Bool, &["bool", "boolean"]),
    (ValueType::U8, &["u8", "uint8", "unsigned8", "usint"]),
    (ValueType::U16, &["u16", "uint16", "unsigned16", "uint"]),
    (ValueType::U32, &["u32", "uint32", "unsigned32", "udint"]),
    (ValueType::U64, &["u64", "uint64", "unsigned64", "ulint"]),
    (ValueType::I8, &["i8", "int8", "integer8", "sint"]),
    (ValueType::I16, &["i16", "int16", "integer16", "int"]),
    (ValueType::I32, &["i32", "int32", "integer32", "dint"]),
    (ValueType::I64, &["i64", "int64", "integer64", "lint"]),
    (ValueType::F32, &["f32", "float", "real32", "real"]),
    (ValueType::F64, &["f64", "double", "real64", "lreal"]),
    (ValueType::Str, &["string", "visible_string"]),
    (ValueType::Bytes, &["bytes", "octet_string", "domain"]),
];

/// The allowed `--type` names, for messages and help.
pub const TYPE_NAMES: &str = "u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 bool string bytes; also \
    IgH's uint8 … uint64, int8 … int64, float, double, octet_string and CiA 301's UNSIGNED8 … \
    INTEGER64, REAL32, REAL64, VISIBLE_STRING, OCTET_STRING";

impl ValueType {
    /// Parse a `--type` name, case-insensitive.
    pub fn from_name(name: &str) -> Option<Self> {
        let n = name.trim().to_ascii_lowercase();
        NAMES
            .iter()
            .find(|(_, names)| names.contains(&n.as_str()))
            .map(|(t, _)| *t)
    }

    /// Clap value parser of `--type`.
    pub fn parse_option(name: &str) -> Result<Self, String> {
        Self::from_name(name).ok_or_else(|| format!("one of {TYPE_NAMES}"))
    }

    /// fieldprobe's name (`u16`, `f32`, `string`).
    pub fn name(self) -> &'static str {
        NAMES
            .iter()
            .find(|(t, _)| *t == self)
            .map_or("?", |(_, names)| names[0])
    }

    /// The type of a known CiA 402 object.
    pub fn from_pdo(t: DataType) -> Self {
        match t {
            DataType::Bool => ValueType::Bool,
            DataType::U8 => ValueType::U8,
            DataType::I8 => ValueType::I8,
            DataType::U16 => ValueType::U16,
            DataType::I16 => ValueType::I16,
            DataType::U32 => ValueType::U32,
            DataType::I32 => ValueType::I32,
        }
    }

    /// Size in bytes (CiA 301 §7.1.4); `None` for strings and bytes.
    pub fn size(self) -> Option<usize> {
        use ValueType::*;
        match self {
            Bool | U8 | I8 => Some(1),
            U16 | I16 => Some(2),
            U32 | I32 | F32 => Some(4),
            U64 | I64 | F64 => Some(8),
            Str | Bytes => None,
        }
    }

    /// Value range of an integer type; `None` for the others.
    pub fn int_range(self) -> Option<(i128, i128)> {
        use ValueType::*;
        Some(match self {
            Bool => (0, 1),
            U8 => (0, u8::MAX.into()),
            U16 => (0, u16::MAX.into()),
            U32 => (0, u32::MAX.into()),
            U64 => (0, u64::MAX.into()),
            I8 => (i8::MIN.into(), i8::MAX.into()),
            I16 => (i16::MIN.into(), i16::MAX.into()),
            I32 => (i32::MIN.into(), i32::MAX.into()),
            I64 => (i64::MIN.into(), i64::MAX.into()),
            F32 | F64 | Str | Bytes => return None,
        })
    }

    /// Encode `text` (the VALUE argument) as the bytes an SDO download carries. The error says
    /// what is allowed (the caller adds the value and exits 2).
    pub fn encode(self, text: &str) -> Result<Vec<u8>, String> {
        if let (Some((lo, hi)), Some(size)) = (self.int_range(), self.size()) {
            let v = number::int_in(text, lo, hi, "an integer")?.value;
            // In range, so the low bytes of the two's complement are the encoding.
            return Ok(v.to_le_bytes()[..size].to_vec());
        }
        match self {
            ValueType::F32 => {
                // Rounded to the nearest binary32; beyond ±f32::MAX (after rounding) it is
                // infinite and refused.
                let v = number::real(text)
                    .map(|v| v as f32)
                    .filter(|v| v.is_finite());
                let v = v.ok_or_else(|| {
                    format!(
                        "a number -3.4028235e38 … 3.4028235e38 (rounded to the nearest REAL32), {REAL_FORM}"
                    )
                })?;
                Ok(v.to_le_bytes().to_vec())
            }
            ValueType::F64 => number::real(text)
                .map(|v| v.to_le_bytes().to_vec())
                .ok_or_else(|| format!("a finite number, {REAL_FORM}")),
            ValueType::Str => Ok(text.as_bytes().to_vec()),
            ValueType::Bytes => hex_bytes(text).ok_or_else(|| {
                "bytes in hex in the order they are sent, two digits each, optionally \
                 separated by blanks or `:` (e.g. `01 02 0a` or `01020a`)"
                    .to_string()
            }),
            _ => Err("a value of this type".to_string()),
        }
    }

    /// The value of `bytes` as the CLI prints it: `300000 (0x493e0)`, `-1.5 (0xbfc00000)`,
    /// `"text" (4 bytes)`, `[01 02] (2 bytes)`. `None` when the length does not fit the type.
    pub fn show(self, bytes: &[u8]) -> Option<String> {
        if let Some(size) = self.size() {
            if bytes.len() != size {
                return None;
            }
        }
        let mut le = [0u8; 8];
        le[..bytes.len().min(8)].copy_from_slice(&bytes[..bytes.len().min(8)]);
        let raw = u64::from_le_bytes(le);
        Some(match self {
            ValueType::F32 => {
                let bits = raw as u32;
                format!("{} ({bits:#010x})", show_real(f32::from_bits(bits)))
            }
            ValueType::F64 => format!("{} ({raw:#018x})", show_real(f64::from_bits(raw))),
            ValueType::Str => show_string(bytes),
            ValueType::Bytes => show_bytes(bytes),
            t => {
                let size = t.size().unwrap_or(8);
                let signed = t.int_range().is_some_and(|(lo, _)| lo < 0);
                let value = if signed {
                    // Sign-extend the `size` bytes.
                    let shift = 64 - 8 * size as u32;
                    i128::from(((raw << shift) as i64) >> shift)
                } else {
                    i128::from(raw)
                };
                format!("{value} ({raw:#x})")
            }
        })
    }
}

/// A REAL32 / REAL64 in the shortest text that reads back to the same value, in exponent form
/// for magnitudes below 1e-6 and from 1e15 on (`4.2039e-40`, not 45 digits).
fn show_real<T: std::fmt::Display + std::fmt::LowerExp + Into<f64> + Copy>(v: T) -> String {
    let x: f64 = v.into();
    if x.is_finite() && x != 0.0 && !(1e-6..1e15).contains(&x.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `"text" (N bytes)`; characters that would not print are escaped.
pub fn show_string(bytes: &[u8]) -> String {
    format!(
        "\"{}\" ({})",
        String::from_utf8_lossy(bytes).escape_debug(),
        count_bytes(bytes.len())
    )
}

/// `1 byte`, `4 bytes`.
pub fn count_bytes(n: usize) -> String {
    if n == 1 {
        "1 byte".to_string()
    } else {
        format!("{n} bytes")
    }
}

/// `[01 02 0a] (3 bytes)`.
pub fn show_bytes(bytes: &[u8]) -> String {
    let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02x}")).collect();
    format!("[{}] ({})", hex.join(" "), count_bytes(bytes.len()))
}

/// `01 02 0a`, `01:02:0a`, `01020a` → bytes; `None` on anything else.
fn hex_bytes(text: &str) -> Option<Vec<u8>> {
    let digits: Vec<u8> = text
        .bytes()
        .filter(|b| !matches!(b, b' ' | b':' | b'\t'))
        .collect();
    if !digits.len().is_multiple_of(2) || !digits.iter().all(u8::is_ascii_hexdigit) {
        return None;
    }
    digits
        .chunks(2)
        .map(|p| u8::from_str_radix(std::str::from_utf8(p).ok()?, 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_sizes() {
        for (name, t, size) in [
            ("uint8", ValueType::U8, 1),
            ("UNSIGNED16", ValueType::U16, 2),
            ("int32", ValueType::I32, 4),
            ("uint64", ValueType::U64, 8),
            ("Integer64", ValueType::I64, 8),
            ("float", ValueType::F32, 4),
            ("REAL64", ValueType::F64, 8),
            ("double", ValueType::F64, 8),
        ] {
            assert_eq!(ValueType::from_name(name), Some(t), "{name}");
            assert_eq!(t.size(), Some(size), "{name}");
        }
        assert_eq!(ValueType::from_name("octet_string"), Some(ValueType::Bytes));
        assert_eq!(ValueType::from_name("u128"), None);
    }

    #[test]
    fn encodings() {
        assert_eq!(
            ValueType::I32.encode("-12345").unwrap(),
            (-12345i32).to_le_bytes()
        );
        assert_eq!(ValueType::U16.encode("0xBEEF").unwrap(), [0xEF, 0xBE]);
        assert_eq!(
            ValueType::U64.encode("18446744073709551615").unwrap(),
            [0xFF; 8]
        );
        assert!(ValueType::U64.encode("18446744073709551616").is_err());
        assert!(ValueType::I8.encode("128").is_err());
        assert!(ValueType::U8.encode("-1").is_err());
        assert_eq!(ValueType::F32.encode("1.5").unwrap(), 1.5f32.to_le_bytes());
        assert!(ValueType::F32.encode("1e39").is_err());
        assert!(ValueType::F32.encode("3.4028236e38").is_err());
        assert_eq!(
            ValueType::F32.encode("3.4028235e38").unwrap(),
            f32::MAX.to_le_bytes()
        );
        assert_eq!(
            ValueType::Bytes.encode("de ad:be ef").unwrap(),
            [0xDE, 0xAD, 0xBE, 0xEF]
        );
        assert!(ValueType::Bytes.encode("abc").is_err());
    }

    #[test]
    fn shown_values() {
        assert_eq!(
            ValueType::I16.show(&(-2i16).to_le_bytes()).unwrap(),
            "-2 (0xfffe)"
        );
        assert_eq!(
            ValueType::F64.show(&(-0.5f64).to_le_bytes()).unwrap(),
            "-0.5 (0xbfe0000000000000)"
        );
        assert_eq!(ValueType::U32.show(&[1, 2]), None);
    }
}
