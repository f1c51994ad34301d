//! Readers of ETG.2000 value texts, strict and lenient: each returns what it read and whether the
//! text was in a form ETG.2000 does not define (the parser turns that into an
//! [`EsiWarning`](super::EsiWarning)). Pure functions on `&str`; the parser decides, per field,
//! whether a text that none of them can read is an error (identity, process data layout) or an
//! ignored optional value.
//!
//! Interpretations (also in `docs/interpretations.md`, ESI section):
//! * Numbers: `#x1A00` hex, `-12` / `42` decimal are ETG.2000's forms. Read with a warning:
//!   C hex `0x1A00`, a leading `+`, a decimal with a zero fraction (`16.0`). Leading zeros of any
//!   length are fine.
//! * A negative number in an unsigned field of n bits, within the n-bit signed range, is its
//!   two's complement (`-1` in a 16-bit field → 0xFFFF), with a warning.
//! * hexBinary with an odd number of digits is read with a leading 0 nibble (`0` → `00`,
//!   `123` → `01 23`), as TwinCAT does, with a warning.
//! * Booleans: `true` / `false` / `1` / `0`; other case (`TRUE`, `False`) and `yes` / `no` /
//!   `on` / `off` are read with a warning; anything else is not a boolean.
//! * `Access`: `ro` / `rw` / `wo` in any case; `PdoMapping`: `R` / `T` / `RT` / `TR` in any case.
//!   Other texts are not guessed at: the flag reads as not given.

use super::{Access, PdoMapping};

/// A number read from ETG.2000 text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Number {
    /// The value.
    pub value: i128,
    /// Written in a form ETG.2000 does not define (`0x1A00`, `+5`, `16.0`).
    pub odd_form: bool,
}

/// `#x1A00` → 0x1A00, `42` → 42, `-3` → -3 (strict ETG.2000 forms only). `None` on anything
/// else.
#[cfg(test)]
fn parse_number(t: &str) -> Option<i128> {
    read_number(t).filter(|n| !n.odd_form).map(|n| n.value)
}

/// A number in any form [`Number`] describes; `None` when the text is not a number.
pub(crate) fn read_number(t: &str) -> Option<Number> {
    let t = t.trim();
    let (neg, body, mut odd) = match t.as_bytes().first() {
        Some(b'-') => (true, &t[1..], false),
        Some(b'+') => (false, &t[1..], true),
        _ => (false, t, false),
    };
    let (digits, radix) = if let Some(h) = body.strip_prefix("#x").or(body.strip_prefix("#X")) {
        // `-#x10` is not an ETG.2000 form
        odd |= neg;
        (h, 16)
    } else if let Some(h) = body.strip_prefix("0x").or(body.strip_prefix("0X")) {
        odd = true;
        (h, 16)
    } else if let Some((int, frac)) = body.split_once('.') {
        if frac.is_empty() || frac.bytes().all(|b| b == b'0') {
            odd = true;
            (int, 10)
        } else {
            return None;
        }
    } else {
        (body, 10)
    };
    if digits.is_empty() {
        return None;
    }
    let digits = digits.trim_start_matches('0');
    let ok = |b: u8| {
        if radix == 16 {
            b.is_ascii_hexdigit()
        } else {
            b.is_ascii_digit()
        }
    };
    if !digits.bytes().all(ok) {
        return None;
    }
    // at most 128 bits: longer texts are not numbers of any ESI field
    if digits.len() > if radix == 16 { 32 } else { 38 } {
        return None;
    }
    let v = if digits.is_empty() {
        0
    } else {
        i128::from_str_radix(digits, radix).ok()?
    };
    Some(Number {
        value: if neg { -v } else { v },
        odd_form: odd,
    })
}

/// How a number fits an unsigned field of `bits` bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Fit {
    /// In range.
    Fits(i128),
    /// Negative within the signed range of `bits`: its two's complement.
    TwosComplement(i128),
    /// No reading in the field.
    OutOfRange,
}

/// Fit `v` into `[min, max]`; for an unsigned field (`min == 0`, `max == 2^n - 1`) a negative
/// value of the n-bit signed range becomes its two's complement.
pub(crate) fn fit(v: i128, min: i128, max: i128) -> Fit {
    if (min..=max).contains(&v) {
        return Fit::Fits(v);
    }
    let unsigned_field = min == 0 && max > 0 && (max + 1) & max == 0;
    if unsigned_field && v < 0 && v >= -(max + 1) / 2 {
        return Fit::TwosComplement(v + max + 1);
    }
    Fit::OutOfRange
}

/// hexBinary read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Hex {
    /// Pairs of hex digits.
    Bytes(Vec<u8>),
    /// An odd number of digits, read with a leading 0 nibble.
    Odd(Vec<u8>),
    /// Not hex digits.
    Bad,
}

/// ETG.2000 hexBinary (`92010200` → [0x92, 0x01, 0x02, 0x00]); whitespace between digits is
/// allowed. An odd number of digits is read with a leading 0 nibble (`123` → [0x01, 0x23]).
pub(crate) fn read_hex_binary(t: &str) -> Hex {
    let mut digits = Vec::with_capacity(t.len() + 1);
    for b in t.bytes().filter(|b| !b.is_ascii_whitespace()) {
        match (b as char).to_digit(16) {
            Some(d) => digits.push(d as u8),
            None => return Hex::Bad,
        }
    }
    let odd = digits.len() % 2 == 1;
    if odd {
        digits.insert(0, 0);
    }
    let bytes = digits.chunks(2).map(|p| p[0] << 4 | p[1]).collect();
    if odd {
        Hex::Odd(bytes)
    } else {
        Hex::Bytes(bytes)
    }
}

/// A boolean attribute: (value, odd form). `None`: not a boolean.
pub(crate) fn read_bool(t: &str) -> Option<(bool, bool)> {
    match t.trim() {
        "true" | "1" => Some((true, false)),
        "false" | "0" => Some((false, false)),
        other => match other.to_ascii_lowercase().as_str() {
            "true" | "yes" | "on" => Some((true, true)),
            "false" | "no" | "off" => Some((false, true)),
            _ => None,
        },
    }
}

/// `Flags/Access` text, any case. `None`: not an access text ETG.2000 defines.
pub(crate) fn read_access(t: &str) -> Option<Access> {
    match t.trim().to_ascii_lowercase().as_str() {
        "ro" => Some(Access::ReadOnly),
        "rw" => Some(Access::ReadWrite),
        "wo" => Some(Access::WriteOnly),
        _ => None,
    }
}

/// `Flags/PdoMapping` text, any case: `Ok(None)` for an empty text, `Err(())` for a text
/// ETG.2000 does not define.
pub(crate) fn read_pdo_mapping(t: &str) -> Result<Option<PdoMapping>, ()> {
    match t.trim().to_ascii_uppercase().as_str() {
        "R" => Ok(Some(PdoMapping::Rx)),
        "T" => Ok(Some(PdoMapping::Tx)),
        "RT" | "TR" => Ok(Some(PdoMapping::RxTx)),
        "" => Ok(None),
        _ => Err(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn n(v: i128, odd_form: bool) -> Option<Number> {
        Some(Number { value: v, odd_form })
    }

    #[test]
    fn strict_numbers() {
        assert_eq!(parse_number("#x1A00"), Some(0x1A00));
        assert_eq!(parse_number("#x1a00"), Some(0x1A00));
        assert_eq!(parse_number("#X1A00"), Some(0x1A00));
        assert_eq!(parse_number("42"), Some(42));
        assert_eq!(parse_number(" -3 "), Some(-3));
        assert_eq!(parse_number("0"), Some(0));
        assert_eq!(parse_number("#x0"), Some(0));
        assert_eq!(
            parse_number("#x00000000000000000000000000000000001"),
            Some(1)
        );
        assert_eq!(parse_number("#xZZ"), None);
        assert_eq!(parse_number("#x"), None);
        assert_eq!(parse_number("0x10"), None);
        assert_eq!(parse_number(""), None);
        assert_eq!(parse_number("-"), None);
        assert_eq!(parse_number("1e3"), None);
        assert_eq!(parse_number("#x111122223333444455556666777788889"), None);
    }

    #[test]
    fn odd_number_forms() {
        assert_eq!(read_number("0x1A00"), n(0x1A00, true));
        assert_eq!(read_number("0X1a"), n(0x1A, true));
        assert_eq!(read_number("+5"), n(5, true));
        assert_eq!(read_number("16.0"), n(16, true));
        assert_eq!(read_number("16."), n(16, true));
        assert_eq!(read_number("-#x10"), n(-16, true));
        assert_eq!(read_number("16.5"), None);
        assert_eq!(read_number("0x"), None);
        assert_eq!(read_number("+"), None);
        assert_eq!(read_number("."), None);
        assert_eq!(read_number("#x 10"), None);
    }

    #[test]
    fn fit_unsigned_and_signed() {
        let u16max = i128::from(u16::MAX);
        assert_eq!(fit(5, 0, u16max), Fit::Fits(5));
        assert_eq!(fit(-1, 0, u16max), Fit::TwosComplement(0xFFFF));
        assert_eq!(fit(-32768, 0, u16max), Fit::TwosComplement(0x8000));
        assert_eq!(fit(-32769, 0, u16max), Fit::OutOfRange);
        assert_eq!(fit(65536, 0, u16max), Fit::OutOfRange);
        // not an unsigned n-bit field: no two's complement reading
        assert_eq!(fit(-1, 0, 100), Fit::OutOfRange);
        assert_eq!(fit(-5, -10, 10), Fit::Fits(-5));
    }

    #[test]
    fn hex_binary() {
        assert_eq!(read_hex_binary("92010200"), Hex::Bytes(vec![0x92, 1, 2, 0]));
        assert_eq!(
            read_hex_binary("92 01\n0200"),
            Hex::Bytes(vec![0x92, 1, 2, 0])
        );
        assert_eq!(read_hex_binary(""), Hex::Bytes(vec![]));
        assert_eq!(read_hex_binary("0"), Hex::Odd(vec![0x00]));
        assert_eq!(read_hex_binary("7"), Hex::Odd(vec![0x07]));
        assert_eq!(read_hex_binary("123"), Hex::Odd(vec![0x01, 0x23]));
        assert_eq!(read_hex_binary("800"), Hex::Odd(vec![0x08, 0x00]));
        assert_eq!(read_hex_binary("zz"), Hex::Bad);
        assert_eq!(read_hex_binary("#x12"), Hex::Bad);
    }

    #[test]
    fn booleans() {
        assert_eq!(read_bool("true"), Some((true, false)));
        assert_eq!(read_bool("0"), Some((false, false)));
        assert_eq!(read_bool("TRUE"), Some((true, true)));
        assert_eq!(read_bool("False"), Some((false, true)));
        assert_eq!(read_bool("yes"), Some((true, true)));
        assert_eq!(read_bool("maybe"), None);
        assert_eq!(read_bool("2"), None);
    }

    #[test]
    fn access_and_mapping() {
        assert_eq!(read_access("rw"), Some(Access::ReadWrite));
        assert_eq!(read_access("RO"), Some(Access::ReadOnly));
        assert_eq!(read_access("Wo"), Some(Access::WriteOnly));
        assert_eq!(read_access("rx"), None);
        assert_eq!(read_access("const"), None);
        assert_eq!(read_pdo_mapping("t"), Ok(Some(PdoMapping::Tx)));
        assert_eq!(read_pdo_mapping("Tr"), Ok(Some(PdoMapping::RxTx)));
        assert_eq!(read_pdo_mapping(""), Ok(None));
        assert_eq!(read_pdo_mapping("no"), Err(()));
    }
}
