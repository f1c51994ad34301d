//! Values read the way CANopen tools read a vendor's EDS (issue 25): a value that does not fit
//! its data type, or a number written in an odd form, is read — never a refusal of the file.
//!
//! What is used instead (each case a warning naming the file, line and object, see
//! [`super::EdsWarning`]):
//! * **A limit** (`LowLimit` / `HighLimit`) beyond the type's range reads as the type's limit
//!   on that side (`HighLimit=65536` on an UNSIGNED16 is 65535): a limit says "no restriction
//!   beyond the type" there. python-canopen keeps such a limit as the number written; the
//!   range a node can store is the type's, so nothing above it can be written anyway.
//! * **A value** (`DefaultValue` / `ParameterValue`, `[xxxxValue]`) beyond the range: a
//!   negative number on an unsigned type that fits the signed type of the same width is its
//!   two's complement (`-1` on UNSIGNED16 is 0xFFFF, the bit pattern the writer meant), as a
//!   hexadecimal literal on a signed type already is (CiA 306 reading of `0xFFFF` on
//!   INTEGER16); a decimal number above a signed type's maximum but within the unsigned range of
//!   its width is that bit pattern too (`65535` on INTEGER16 is -1); anything else saturates at
//!   the type's limit.
//! * **Odd number forms** python-canopen (`int(text, 0)` after removing blanks) or a C compiler
//!   would still read, or a person would: blanks inside a number (`0x 1A3`), a trailing `h`
//!   (`1A3h`) or `#x` prefix (ETG.2000 style) for hexadecimal, a leading zero before a decimal
//!   number with the digits 8 or 9 (`0189`: not octal, so decimal), an integral decimal fraction
//!   (`100.0`), `TRUE` / `FALSE`, quotes or parentheses around the number, a comment after `;`
//!   without a blank before it, and `$NODEID` terms in any case, with blanks or in front of or
//!   behind the number (`0x180 + $nodeid`).
//! * A BOOLEAN value other than 0 / 1 is true when not 0 (a limit: clamped to 0 … 1).
//! * OCTET_STRING / DOMAIN hex text with an odd number of digits reads with a leading 0 digit,
//!   with a `0x` prefix without it.
//! * What still does not parse is no value (a default: the object reads 0 / empty; a limit:
//!   no limit).

use super::{DataType, IntExpr, Value, ValueError};

/// What a value text is for: limits saturate at the type's range, values keep their bit
/// pattern where one is meant (module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueRole {
    /// `DefaultValue`, `ParameterValue`, a `[xxxxValue]` entry.
    Value,
    /// `LowLimit` / `HighLimit`.
    Limit,
}

/// Type name in the words of the strict messages (`Unsigned16`).
fn type_name(t: DataType) -> String {
    format!("{t:?}")
}

impl DataType {
    /// [`value_from_text`](Self::value_from_text), reading odd values as CANopen tools do
    /// (module documentation): the value, and — when the text is not read literally — how it
    /// was read (`read as 65535, the largest Unsigned16`). An error only where nothing
    /// sensible can be read.
    pub fn value_from_text_lenient(
        self,
        text: &str,
        node_id: u8,
        role: ValueRole,
    ) -> Result<(Value, Option<String>), ValueError> {
        let strict = match self.value_from_text(text, node_id) {
            Ok(v) => return Ok((v, None)),
            Err(e) => e,
        };
        let text = text.trim();
        if let Some((bits, signed)) = self.int_shape() {
            let (expr, form) = IntExpr::parse_lenient(text).ok_or(strict)?;
            let v = expr.eval(node_id);
            let (value, fitted) = self.fit_lenient(v, bits, signed, role);
            let mut notes = Vec::new();
            if let Some(form) = form {
                notes.push(form);
            }
            if let Some(fitted) = fitted {
                notes.push(fitted);
            } else {
                notes.push(format!("read as {}", show(&value)));
            }
            return Ok((value, Some(notes.join("; "))));
        }
        match self {
            DataType::OctetString | DataType::Domain => {
                let mut digits: String = text
                    .chars()
                    .filter(|c| !c.is_whitespace())
                    .collect::<String>();
                let mut how = Vec::new();
                if let Some(rest) = digits
                    .strip_prefix("0x")
                    .or_else(|| digits.strip_prefix("0X"))
                {
                    digits = rest.to_string();
                    how.push("without its 0x prefix");
                }
                if digits.len() % 2 == 1 {
                    digits.insert(0, '0');
                    how.push("with a leading 0 digit (odd number of hex digits)");
                }
                let bytes = super::parse_hex_bytes(&digits).map_err(|_| strict)?;
                let n = bytes.len();
                Ok((
                    Value::Bytes(bytes),
                    Some(format!("read {} as {n} bytes", how.join(", "))),
                ))
            }
            DataType::TimeOfDay | DataType::TimeDifference => {
                let (expr, _) = IntExpr::parse_lenient(text).ok_or(strict)?;
                let v = expr.eval(node_id).clamp(0, (1i128 << 48) - 1);
                let value = self
                    .value_from_text(&v.to_string(), node_id)
                    .map_err(|_| ValueError::Unsupported(self))?;
                Ok((value, Some(format!("read as {v}"))))
            }
            _ => Err(strict),
        }
    }

    /// `v` in this integer type (`bits`, `signed`) by the rules of `role`: the value and, when
    /// it was changed, how.
    fn fit_lenient(
        self,
        v: i128,
        bits: u32,
        signed: bool,
        role: ValueRole,
    ) -> (Value, Option<String>) {
        if bits == 1 {
            let b = match role {
                ValueRole::Value => v != 0,
                ValueRole::Limit => v > 0,
            };
            let fitted = (v != i128::from(b)).then(|| format!("read as {}", u8::from(b)));
            return (Value::Bool(b), fitted);
        }
        let umax: i128 = (1i128 << bits) - 1;
        let (min, max) = if signed {
            (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
        } else {
            (0, umax)
        };
        let make = |x: i128| {
            if signed {
                Value::Integer(x as i64)
            } else {
                Value::Unsigned(x as u64)
            }
        };
        if (min..=max).contains(&v) {
            return (make(v), None);
        }
        let name = type_name(self);
        if role == ValueRole::Value {
            // The same bit pattern in the other signedness of this width.
            let half = 1i128 << (bits - 1);
            if !signed && v < 0 && v >= -half {
                let x = v + (1i128 << bits);
                return (
                    make(x),
                    Some(format!(
                        "read as its two's complement {x:#X} ({x}), the {bits}-bit pattern of {v}"
                    )),
                );
            }
            if signed && v > max && v <= umax {
                let x = v - (1i128 << bits);
                return (
                    make(x),
                    Some(format!(
                        "read as the {bits}-bit pattern {v:#X}, which is {x} in {name}"
                    )),
                );
            }
        }
        let (x, side) = if v > max {
            (max, "largest")
        } else {
            (min, "smallest")
        };
        (make(x), Some(format!("read as {x}, the {side} {name}")))
    }
}

/// A value for a message.
fn show(v: &Value) -> String {
    match v {
        Value::Unsigned(u) if *u > 9 => format!("{u} ({u:#X})"),
        Value::Unsigned(u) => u.to_string(),
        Value::Integer(i) => i.to_string(),
        Value::Bool(b) => u8::from(*b).to_string(),
        other => format!("{other:?}"),
    }
}

impl IntExpr {
    /// [`IntExpr::parse`] of the odd forms of the module documentation; the expression and, if
    /// the text was not in a CiA 306 form, what was odd about it.
    pub(super) fn parse_lenient(text: &str) -> Option<(IntExpr, Option<String>)> {
        if let Ok(e) = IntExpr::parse(text) {
            return Some((e, None));
        }
        let mut odd: Vec<&str> = Vec::new();
        let mut t = text.trim().to_string();
        if let Some(pos) = t.find(';') {
            t.truncate(pos);
            odd.push("text after `;` taken as a comment");
        }
        let stripped = t
            .trim()
            .trim_matches(|c| c == '"' || c == '\'')
            .trim_start_matches('(')
            .trim_end_matches(')')
            .to_string();
        if stripped != t.trim() {
            odd.push("quotes or parentheses around the number");
        }
        t = stripped;
        if t.chars().any(char::is_whitespace) {
            t.retain(|c| !c.is_whitespace());
            odd.push("blanks inside the number");
        }
        let mut terms: Vec<String> = Vec::new();
        let mut rest = t.as_str();
        loop {
            let end = rest
                .char_indices()
                .skip(1)
                .find(|&(_, c)| c == '+' || c == '-')
                .map_or(rest.len(), |(i, _)| i);
            let (term, tail) = rest.split_at(end);
            let (lead, body) = match term.strip_prefix(['+', '-']) {
                Some(b) => (&term[..1], b),
                None => ("", term),
            };
            let body =
                if body.eq_ignore_ascii_case("$NODEID") || body.eq_ignore_ascii_case("$NODE_ID") {
                    "$NODEID".to_string()
                } else {
                    let (lit, how) = odd_literal(body)?;
                    if let Some(how) = how {
                        odd.push(how);
                    }
                    lit
                };
            terms.push(format!("{lead}{body}"));
            if tail.is_empty() || terms.len() > 16 {
                break;
            }
            rest = tail;
        }
        let normal = terms.concat();
        let expr = IntExpr::parse(&normal).ok()?;
        odd.dedup();
        let form = if odd.is_empty() {
            None
        } else {
            Some(format!("odd number form ({})", odd.join(", ")))
        };
        Some((expr, form))
    }
}

/// One literal in an odd form, rewritten as a CiA 306 literal (decimal or `0x` hex), and what
/// was odd about it.
fn odd_literal(body: &str) -> Option<(String, Option<&'static str>)> {
    if body.is_empty() {
        return None;
    }
    if super::parse_literal(body).is_some() {
        return Some((body.to_string(), None));
    }
    if let Some(hex) = body.strip_prefix("#x").or_else(|| body.strip_prefix("#X")) {
        return hex_digits(hex).map(|h| (h, Some("`#x` hexadecimal prefix")));
    }
    if let Some(hex) = body.strip_suffix(['h', 'H']) {
        if hex.starts_with(|c: char| c.is_ascii_digit()) {
            return hex_digits(hex).map(|h| (h, Some("trailing `h` for hexadecimal")));
        }
    }
    if body.len() > 1 && body.starts_with('0') && body.bytes().all(|b| b.is_ascii_digit()) {
        // Leading zero but 8 or 9 among the digits: not octal (CiA 306), decimal.
        let d = body.trim_start_matches('0');
        let d = if d.is_empty() { "0" } else { d };
        return Some((
            d.to_string(),
            Some("leading 0 before a decimal number with 8 or 9"),
        ));
    }
    if body.eq_ignore_ascii_case("true") {
        return Some(("1".into(), Some("TRUE for 1")));
    }
    if body.eq_ignore_ascii_case("false") {
        return Some(("0".into(), Some("FALSE for 0")));
    }
    // The sign was split off with the term, so the number is not negative here.
    if let Ok(f) = body.parse::<f64>() {
        if f.is_finite() && f >= 0.0 && f.fract() == 0.0 && f < 1.8e19 {
            return Some((
                format!("{}", f as u64),
                Some("an integral decimal fraction"),
            ));
        }
    }
    None
}

fn hex_digits(h: &str) -> Option<String> {
    (!h.is_empty() && h.bytes().all(|b| b.is_ascii_hexdigit())).then(|| format!("0x{h}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ValueRole::{Limit, Value as V};

    fn read(t: DataType, text: &str, role: ValueRole) -> (Value, Option<String>) {
        t.value_from_text_lenient(text, 5, role)
            .unwrap_or_else(|e| panic!("{text:?}: {e}"))
    }

    #[test]
    fn a_limit_beyond_the_type_reads_as_the_type_limit() {
        let (v, how) = read(DataType::Unsigned16, "65536", Limit);
        assert_eq!(v, Value::Unsigned(65535));
        assert_eq!(
            how.as_deref(),
            Some("read as 65535, the largest Unsigned16")
        );
        assert_eq!(
            read(DataType::Unsigned16, "-1", Limit).0,
            Value::Unsigned(0)
        );
        assert_eq!(
            read(DataType::Integer8, "-200", Limit).0,
            Value::Integer(-128)
        );
        // Within range: as written, no note.
        assert_eq!(
            read(DataType::Unsigned16, "0x10", Limit),
            (Value::Unsigned(16), None)
        );
    }

    #[test]
    fn a_value_keeps_its_bit_pattern_else_saturates() {
        let (v, how) = read(DataType::Unsigned16, "-1", V);
        assert_eq!(v, Value::Unsigned(0xFFFF));
        assert!(how.unwrap().contains("two's complement 0xFFFF"));
        assert_eq!(read(DataType::Integer16, "65535", V).0, Value::Integer(-1));
        assert_eq!(read(DataType::Unsigned8, "300", V).0, Value::Unsigned(255));
        assert_eq!(
            read(DataType::Unsigned32, "$NODEID+0xFFFFFFFF", V).0,
            Value::Unsigned(0xFFFF_FFFF)
        );
        assert_eq!(read(DataType::Boolean, "2", V).0, Value::Bool(true));
    }

    #[test]
    fn odd_number_forms() {
        let u32_ = DataType::Unsigned32;
        for (text, want) in [
            ("0x 1A3", 0x1A3),
            ("1A3h", 0x1A3),
            ("#x1A3", 0x1A3),
            ("0189", 189),
            ("100.0", 100),
            ("\"0x10\"", 16),
            ("(0x10)", 16),
            ("0x10;note", 16),
            ("0x180 + $nodeid", 0x185),
            ("$NODE_ID+0x180", 0x185),
            ("$NodeId + 384", 0x185),
            ("TRUE", 1),
        ] {
            let (v, how) = read(u32_, text, V);
            assert_eq!(v, Value::Unsigned(want), "{text:?}");
            if !text.contains('$') {
                assert!(how.is_some(), "{text:?} is odd");
            }
        }
        // CiA 306 forms stay as they are: octal with a leading 0.
        assert_eq!(read(u32_, "017", V), (Value::Unsigned(15), None));
        for bad in ["", "0x", "abc", "1.5", "0x1G", "$NODEID*2"] {
            assert!(u32_.value_from_text_lenient(bad, 5, V).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn octet_strings_with_odd_digits() {
        let (v, how) = read(DataType::OctetString, "0", V);
        assert_eq!(v, Value::Bytes(vec![0]));
        assert!(how.unwrap().contains("leading 0"));
        assert_eq!(
            read(DataType::Domain, "0x0102", V).0,
            Value::Bytes(vec![1, 2])
        );
    }
}
