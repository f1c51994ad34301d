//! The one number grammar of the command line (docs/cli.md "Numbers on the command line").
//!
//! Every number a user types — `--device`, `--node`, object indices and sub-indices, SDO and
//! IDN values, positions such as `--probe-at Z=0x64`, `sim canopen --node 0x05`, `--seconds`,
//! `--cpu` — is read here:
//!
//! * an **integer** is an optional sign (`-`, `+`), then either decimal digits or `0x` / `0X`
//!   and hex digits: `4104`, `0x1008`, `-12345`, `-0x3039`. Nothing else: no blanks inside,
//!   no `_`, no octal (`010` is ten, where C's `strtoul(…, 0)` would read eight);
//! * a **real** (positions, seconds, REAL32 / REAL64 values) is an integer as above, or a
//!   decimal fraction with an optional exponent (`2.5`, `-0.125`, `1e-3`); it must be finite.
//!
//! An object index written without `0x` is decimal, as IgH's `ethercat upload` reads it
//! (`strtoul` with base 0): `4104` is object 0x1008. Because a commissioning engineer may have
//! meant hex, [`ObjectRef::notes`] gives a note for stderr whenever an index or sub-index of 10
//! or more was written in decimal.
//!
//! Errors name the option, the text as given and the allowed form and range; the caller exits 2.
//! The `value_*` functions are clap value parsers (clap adds the option and the text).

use std::fmt;

/// How an integer was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Radix {
    /// Decimal digits.
    Decimal,
    /// `0x` and hex digits.
    Hex,
}

/// An integer as written: its value and its radix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Int {
    /// The value (an `i128` holds every `u64` and `i64`; longer digit strings saturate and
    /// fall outside every range).
    pub value: i128,
    /// How it was written.
    pub radix: Radix,
}

/// Read an integer (see the module docs); `None` when `text` is not one.
pub fn integer(text: &str) -> Option<Int> {
    let (negative, body) = match text.as_bytes().first() {
        Some(b'-') => (true, &text[1..]),
        Some(b'+') => (false, &text[1..]),
        _ => (false, text),
    };
    let (digits, radix) = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        Some(h) => (h, Radix::Hex),
        None => (body, Radix::Decimal),
    };
    let valid = match radix {
        Radix::Hex => digits.bytes().all(|b| b.is_ascii_hexdigit()),
        Radix::Decimal => digits.bytes().all(|b| b.is_ascii_digit()),
    };
    if digits.is_empty() || !valid {
        return None;
    }
    let base = if radix == Radix::Hex { 16 } else { 10 };
    let magnitude = i128::from_str_radix(digits, base).unwrap_or(i128::MAX);
    Some(Int {
        value: if negative { -magnitude } else { magnitude },
        radix,
    })
}

/// Read a real number (see the module docs): finite, `None` otherwise.
pub fn real(text: &str) -> Option<f64> {
    if let Some(i) = integer(text) {
        return Some(i.value as f64).filter(|v| v.is_finite());
    }
    // Decimal fraction: [sign] digits [. digits] [e [sign] digits], at least one digit before
    // the exponent. Checked here so that `inf`, `NaN` and `0x1.8p3` are not numbers.
    let body = text.strip_prefix(['-', '+']).unwrap_or(text);
    let (mantissa, exponent) = match body.find(['e', 'E']) {
        Some(k) => (&body[..k], Some(&body[k + 1..])),
        None => (body, None),
    };
    let (int_part, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    let mantissa_ok = digits(int_part) && digits(frac) && !(int_part.is_empty() && frac.is_empty());
    let exponent_ok = exponent.is_none_or(|e| {
        let e = e.strip_prefix(['-', '+']).unwrap_or(e);
        !e.is_empty() && digits(e)
    });
    if !(mantissa_ok && exponent_ok) {
        return None;
    }
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// A number that does not fit: `{what} {text}: expected {expected}`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NumberError {
    /// The option or the part of an argument (`--device`, `object index`, `--probe-at Z=…`).
    pub what: String,
    /// The text as given.
    pub text: String,
    /// The allowed form and range.
    pub expected: String,
}

impl fmt::Display for NumberError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {}: expected {}",
            self.what,
            super::cap_echo(&self.text),
            self.expected
        )
    }
}

impl std::error::Error for NumberError {}

/// `lo … hi (decimal, or hex with 0x)`, the range part of a message.
pub fn range_text(lo: i128, hi: i128) -> String {
    format!("{lo} … {hi} (decimal, or hex with 0x)")
}

/// An integer `lo ..= hi` as written; `noun` describes it in the error (`a ring position`).
pub fn int_in(text: &str, lo: i128, hi: i128, noun: &str) -> Result<Int, String> {
    match integer(text) {
        Some(i) if (lo..=hi).contains(&i.value) => Ok(i),
        _ => Err(format!("{noun} {}", range_text(lo, hi))),
    }
}

/// [`int_in`] with the option and the text in the error.
pub fn int_option(
    what: &str,
    text: &str,
    lo: i128,
    hi: i128,
    noun: &str,
) -> Result<i128, NumberError> {
    int_in(text, lo, hi, noun)
        .map(|i| i.value)
        .map_err(|expected| NumberError {
            what: what.to_string(),
            text: text.to_string(),
            expected,
        })
}

/// What [`real`] accepts, for messages.
pub const REAL_FORM: &str = "decimal (2.5, -1e-3) or an integer in hex with 0x";

/// A real number `lo ..= hi`; `noun` describes it (`a position in mm`).
pub fn real_option(
    what: &str,
    text: &str,
    lo: f64,
    hi: f64,
    noun: &str,
) -> Result<f64, NumberError> {
    let show = fieldprobe::messages::show_number;
    match real(text) {
        Some(v) if (lo..=hi).contains(&v) => Ok(v),
        _ => Err(NumberError {
            what: what.to_string(),
            text: text.to_string(),
            expected: format!("{noun} {} … {}, {REAL_FORM}", show(lo), show(hi)),
        }),
    }
}

/// Largest position in mm any `AXIS=POS` option takes: the bound of every path coordinate.
pub const MAX_POSITION: f64 = fieldprobe::core::path::MAX_COORDINATE;

/// A position in mm (`--probe-at Z=POS`, `--fixed-stop-at`, `sim … --probe-at POS=MM`).
pub fn position(what: &str, text: &str) -> Result<f64, NumberError> {
    real_option(what, text, -MAX_POSITION, MAX_POSITION, "a position in mm")
}

/// Clap value parser: EtherCAT ring position 0 … 65535 (`--device`).
pub fn value_ring_position(text: &str) -> Result<usize, String> {
    clap_value(int_in(text, 0, i128::from(u16::MAX), "a ring position")).map(|v| v as usize)
}

/// A clap value parser's error reads `invalid value 'TEXT' for '--OPTION <N>': expected …`.
fn clap_value(r: Result<Int, String>) -> Result<i128, String> {
    r.map(|i| i.value).map_err(|e| format!("expected {e}"))
}

/// CANopen node id 1 … 127 (CiA 301 §7.5.2.1), as written.
pub fn node_id(what: &str, text: &str) -> Result<u8, NumberError> {
    int_option(what, text, 1, 127, "a CANopen node id").map(|v| v as u8)
}

/// Clap value parser: CANopen node id 1 … 127 (`--node`).
pub fn value_node_id(text: &str) -> Result<u8, String> {
    clap_value(int_in(text, 1, 127, "a CANopen node id")).map(|v| v as u8)
}

/// Clap value parser: `--rt-priority` (any `u8`; [`fieldprobe::rt::RtOptions::check`] refuses
/// what SCHED_FIFO does not take, with its own message).
pub fn value_priority(text: &str) -> Result<u8, String> {
    match integer(text).map(|i| u8::try_from(i.value)) {
        Some(Ok(v)) => Ok(v),
        _ => Err("expected a SCHED_FIFO priority 1 … 99 (decimal, or hex with 0x)".into()),
    }
}

/// Clap value parser: `--cpu` (a CPU number; whether it exists is checked when applied).
pub fn value_cpu(text: &str) -> Result<usize, String> {
    clap_value(int_in(text, 0, i128::from(u32::MAX), "a CPU number")).map(|v| v as usize)
}

/// An object `INDEX[:SUB]` as written (sdo read / write).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectRef {
    /// Object index.
    pub index: u16,
    /// Sub-index (0 when not given).
    pub sub: u8,
    /// How the index was written.
    pub index_radix: Radix,
    /// How the sub-index was written.
    pub sub_radix: Radix,
}

/// What an object reference looks like, for messages.
pub const OBJECT_FORM: &str = "INDEX[:SUB], index 0 … 65535 (0x0000 … 0xFFFF) and sub-index \
                               0 … 255 (0x00 … 0xFF), each decimal or hex with 0x (e.g. 0x6041:0, \
                               0x1018:0x02; 4104 is 0x1008)";

/// Read `INDEX[:SUB]`; `what` names the argument in the error.
pub fn object(what: &str, text: &str) -> Result<ObjectRef, NumberError> {
    let err = |detail: &str| NumberError {
        what: what.to_string(),
        text: text.to_string(),
        expected: format!("{OBJECT_FORM}{detail}"),
    };
    let (i, s) = match text.split_once(':') {
        Some((i, s)) => (i, Some(s)),
        None => (text, None),
    };
    let index = integer(i).ok_or_else(|| err("; the index is not a number"))?;
    let index_value = u16::try_from(index.value).map_err(|_| err("; the index is out of range"))?;
    let sub = match s {
        None => Int {
            value: 0,
            radix: Radix::Hex,
        },
        Some(s) => integer(s).ok_or_else(|| err("; the sub-index is not a number"))?,
    };
    let sub_value = u8::try_from(sub.value).map_err(|_| err("; the sub-index is out of range"))?;
    Ok(ObjectRef {
        index: index_value,
        sub: sub_value,
        index_radix: index.radix,
        sub_radix: sub.radix,
    })
}

impl ObjectRef {
    /// Notes for stderr: an index or sub-index of 10 or more written in decimal (where hex was
    /// perhaps meant), e.g. `object index 4104 (decimal) = 0x1008`.
    pub fn notes(&self) -> Vec<String> {
        let mut v = Vec::new();
        if self.index_radix == Radix::Decimal && self.index >= 10 {
            v.push(format!(
                "object index {} (decimal) = {:#06x}; write 0x{} for hex",
                self.index, self.index, self.index
            ));
        }
        if self.sub_radix == Radix::Decimal && self.sub >= 10 {
            v.push(format!(
                "sub-index {} (decimal) = {:#04x}; write 0x{} for hex",
                self.sub, self.sub, self.sub
            ));
        }
        v
    }
}

/// An object as the CLI prints it, so that the text reads back as the same object: the index
/// in hex with `0x`, the sub-index as two digits below 10 (the same in both radixes) and with
/// `0x` from 10 on (`0x6041:00`, `0x1a00:0x10`).
pub fn show_object(index: u16, sub: u8) -> String {
    if sub < 10 {
        format!("{index:#06x}:{sub:02}")
    } else {
        format!("{index:#06x}:{sub:#04x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers() {
        let v = |t: &str| integer(t).map(|i| i.value);
        assert_eq!(v("4104"), Some(4104));
        assert_eq!(v("0x1008"), Some(0x1008));
        assert_eq!(v("0X1008"), Some(0x1008));
        assert_eq!(v("-12345"), Some(-12345));
        assert_eq!(v("+7"), Some(7));
        assert_eq!(v("-0x10"), Some(-16));
        assert_eq!(v("010"), Some(10));
        assert_eq!(v("18446744073709551615"), Some(u64::MAX as i128));
        for bad in [
            "", "-", "0x", "1_000", " 1", "1 ", "0b1", "12a", "--1", "0x-1", "1.0",
        ] {
            assert_eq!(integer(bad), None, "{bad:?}");
        }
        assert_eq!(integer("4104").unwrap().radix, Radix::Decimal);
        assert_eq!(integer("0x4104").unwrap().radix, Radix::Hex);
    }

    #[test]
    fn reals() {
        assert_eq!(real("2.5"), Some(2.5));
        assert_eq!(real("-1e-3"), Some(-0.001));
        assert_eq!(real(".5"), Some(0.5));
        assert_eq!(real("5."), Some(5.0));
        assert_eq!(real("0x64"), Some(100.0));
        assert_eq!(real("-0x64"), Some(-100.0));
        for bad in [
            "", ".", "e3", "1e", "inf", "-inf", "NaN", "1e400", "0x1.8p3", "1,5", "1e+",
        ] {
            assert_eq!(real(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn objects_and_notes() {
        let o = object("object", "4104").unwrap();
        assert_eq!((o.index, o.sub), (0x1008, 0));
        assert_eq!(
            o.notes(),
            ["object index 4104 (decimal) = 0x1008; write 0x4104 for hex"]
        );
        let o = object("object", "0x1A00:16").unwrap();
        assert_eq!((o.index, o.sub), (0x1A00, 16));
        assert_eq!(
            o.notes(),
            ["sub-index 16 (decimal) = 0x10; write 0x16 for hex"]
        );
        assert!(object("object", "0x6041:00").unwrap().notes().is_empty());
        assert!(object("object", "7:1").unwrap().notes().is_empty());
        for bad in [
            "",
            "0x10000",
            "65536",
            "0x1000:256",
            "0x1000:",
            "x1000",
            "0x1000:0:0",
            "-1",
        ] {
            assert!(object("object", bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn shown_objects_read_back() {
        for (i, s) in [
            (0x1008u16, 0u8),
            (0x1A00, 9),
            (0x1A00, 10),
            (0x1A00, 0x10),
            (0, 255),
        ] {
            let o = object("object", &show_object(i, s)).unwrap();
            assert_eq!((o.index, o.sub), (i, s));
        }
    }
}
