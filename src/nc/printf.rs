//! printf-style formatting for `#MSG ["fmt", …]` (FCT-C4 §5: `#MSG SYN["V.A.MESS.Z=%f",
//! V.A.MESS.Z]` prints `V.A.MESS.Z=100.000000`).
//!
//! Conversions follow C's `printf` for `double` arguments:
//!
//! | spec | meaning |
//! |---|---|
//! | `%f` `%F` | fixed point, default 6 decimals (`20` → `20.000000`, `-0.0` → `-0.000000`) |
//! | `%e` `%E` | exponent form, at least two exponent digits (`1.000000e+21`) |
//! | `%g` `%G` | shortest of `%e` / `%f` with trailing zeros removed (C rules) |
//! | `%d` `%i` | the number **rounded to the nearest integer** (halves away from zero), printed without exponent; precision = minimum digits |
//! | `%s` | a string; a number prints in its shortest round-trip form without exponent (`20`, `0.1`) |
//! | `%%` | a literal `%` |
//!
//! Flags `-` (left-justify), `+` (always a sign), space (blank for positive), `0` (pad with
//! zeros; ignored with `-`, for `%s`, for inf/nan and for `%d` with a precision) and `#`
//! (keep the decimal point / trailing zeros), a field width and a `.precision` are supported.
//! Length modifiers `h l L` are accepted and ignored (all numbers are `f64`). `*` widths are not
//! supported.
//!
//! Rounding is exact and round-half-even on the binary value, as glibc does: `%f` of `0.0000005`
//! (binary value slightly below 5e-7) is `0.000000`, `%.0f` of `2.5` is `2`. Infinity and NaN
//! print as `inf` / `nan` (`INF` / `NAN` for the upper-case conversions); NaN with the sign bit
//! set prints `-nan` like glibc. `%d` of a non-finite number is an error.

use super::expr::Value;

/// Largest field width or precision accepted (guards against `%999999999f`).
pub const MAX_FIELD: usize = 1024;

/// A `#MSG` format string and its arguments do not fit together.
///
/// Argument numbers are 1-based (argument 1 is the first value after the format string);
/// positions are 1-based character positions in the format string.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FormatError {
    /// The format has more conversions than there are arguments.
    #[error("'%{conv}' needs argument {index}, but only {given} argument(s) given")]
    MissingArgument {
        /// The missing argument's number.
        index: usize,
        /// The conversion character.
        conv: char,
        /// How many arguments were given.
        given: usize,
    },
    /// A string was given where a number is needed (`%f`, `%e`, `%g`, `%d`).
    #[error("argument {index} is a string, but '%{conv}' needs a number")]
    NotANumber {
        /// The argument's number.
        index: usize,
        /// The conversion character.
        conv: char,
    },
    /// `%d` / `%i` of infinity or NaN.
    #[error("argument {index} is not a finite number and cannot be printed with '%{conv}'")]
    NotFinite {
        /// The argument's number.
        index: usize,
        /// The conversion character.
        conv: char,
    },
    /// An unsupported conversion character.
    #[error("unknown conversion '%{conv}' at character {pos} of the format (expected one of d i f F e E g G s %)")]
    UnknownConversion {
        /// The conversion character.
        conv: char,
        /// Position of the `%`.
        pos: usize,
    },
    /// The format ends inside a conversion.
    #[error("incomplete conversion at character {pos} of the format: expected a conversion character after '%'")]
    Incomplete {
        /// Position of the `%`.
        pos: usize,
    },
    /// Width or precision larger than [`MAX_FIELD`].
    #[error("field width or precision larger than {MAX_FIELD} at character {pos} of the format")]
    FieldTooLarge {
        /// Position of the `%`.
        pos: usize,
    },
    /// More arguments than conversions.
    #[error("argument {index} is not used: the format has only {used} conversion(s) for {given} argument(s)")]
    TooManyArguments {
        /// Number of the first unused argument.
        index: usize,
        /// Conversions in the format.
        used: usize,
        /// Arguments given.
        given: usize,
    },
}

#[derive(Debug, Default, Clone, Copy)]
struct Spec {
    left: bool,
    plus: bool,
    space: bool,
    zero: bool,
    alt: bool,
    width: usize,
    precision: Option<usize>,
    conv: char,
}

/// Format `args` according to `fmt` (C printf semantics, see the module documentation).
pub fn format(fmt: &str, args: &[Value]) -> Result<String, FormatError> {
    let chars: Vec<char> = fmt.chars().collect();
    let mut out = String::new();
    let mut next_arg = 0usize;
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c != '%' {
            out.push(c);
            i += 1;
            continue;
        }
        let pos = i + 1;
        i += 1;
        if chars.get(i) == Some(&'%') {
            out.push('%');
            i += 1;
            continue;
        }
        let mut spec = Spec::default();
        while let Some(&f) = chars.get(i) {
            match f {
                '-' => spec.left = true,
                '+' => spec.plus = true,
                ' ' => spec.space = true,
                '0' => spec.zero = true,
                '#' => spec.alt = true,
                _ => break,
            }
            i += 1;
        }
        spec.width = read_num(&chars, &mut i, pos)?.unwrap_or(0);
        if chars.get(i) == Some(&'.') {
            i += 1;
            spec.precision = Some(read_num(&chars, &mut i, pos)?.unwrap_or(0));
        }
        while matches!(chars.get(i), Some('h' | 'l' | 'L')) {
            i += 1;
        }
        let Some(&conv) = chars.get(i) else {
            return Err(FormatError::Incomplete { pos });
        };
        i += 1;
        spec.conv = conv;
        if !matches!(conv, 'd' | 'i' | 'f' | 'F' | 'e' | 'E' | 'g' | 'G' | 's') {
            return Err(FormatError::UnknownConversion { conv, pos });
        }
        let index = next_arg + 1;
        let Some(arg) = args.get(next_arg) else {
            return Err(FormatError::MissingArgument {
                index,
                conv,
                given: args.len(),
            });
        };
        next_arg += 1;
        let field = match (conv, arg) {
            ('s', v) => {
                let mut s = v.to_string();
                if let Some(p) = spec.precision {
                    s = s.chars().take(p).collect();
                }
                pad(&spec, "", &s, false)
            }
            (_, Value::Str(_)) => return Err(FormatError::NotANumber { index, conv }),
            (_, Value::Num(x)) => format_number(&spec, *x, index)?,
        };
        out.push_str(&field);
    }
    if next_arg < args.len() {
        return Err(FormatError::TooManyArguments {
            index: next_arg + 1,
            used: next_arg,
            given: args.len(),
        });
    }
    Ok(out)
}

fn read_num(chars: &[char], i: &mut usize, pos: usize) -> Result<Option<usize>, FormatError> {
    let mut n: Option<usize> = None;
    while let Some(d) = chars.get(*i).and_then(|c| c.to_digit(10)) {
        let v = n.unwrap_or(0) * 10 + d as usize;
        if v > MAX_FIELD {
            return Err(FormatError::FieldTooLarge { pos });
        }
        n = Some(v);
        *i += 1;
    }
    Ok(n)
}

/// Sign prefix for a number whose sign bit is `negative`.
fn sign(spec: &Spec, negative: bool) -> &'static str {
    if negative {
        "-"
    } else if spec.plus {
        "+"
    } else if spec.space {
        " "
    } else {
        ""
    }
}

/// Justify `sign + body` in the field; `zero_ok` allows zero padding between sign and body.
fn pad(spec: &Spec, sign: &str, body: &str, zero_ok: bool) -> String {
    let len = sign.chars().count() + body.chars().count();
    let fill = spec.width.saturating_sub(len);
    if spec.left {
        format!("{sign}{body}{}", " ".repeat(fill))
    } else if spec.zero && zero_ok {
        format!("{sign}{}{body}", "0".repeat(fill))
    } else {
        format!("{}{sign}{body}", " ".repeat(fill))
    }
}

fn format_number(spec: &Spec, x: f64, index: usize) -> Result<String, FormatError> {
    let upper = spec.conv.is_ascii_uppercase();
    if !x.is_finite() {
        if matches!(spec.conv, 'd' | 'i') {
            return Err(FormatError::NotFinite {
                index,
                conv: spec.conv,
            });
        }
        let body = match (x.is_nan(), upper) {
            (true, false) => "nan",
            (true, true) => "NAN",
            (false, false) => "inf",
            (false, true) => "INF",
        };
        return Ok(pad(spec, sign(spec, x.is_sign_negative()), body, false));
    }
    let (negative, body, zero_ok) = match spec.conv {
        'd' | 'i' => {
            let r = x.round();
            let mut digits = format!("{:.0}", r.abs());
            match spec.precision {
                Some(0) if r == 0.0 => digits.clear(),
                Some(p) if digits.len() < p => {
                    digits = format!("{}{digits}", "0".repeat(p - digits.len()));
                }
                _ => {}
            }
            (r < 0.0, digits, spec.precision.is_none())
        }
        'f' | 'F' => {
            let p = spec.precision.unwrap_or(6);
            let mut s = format!("{:.*}", p, x.abs());
            if spec.alt && p == 0 {
                s.push('.');
            }
            (x.is_sign_negative(), s, true)
        }
        'e' | 'E' => {
            let p = spec.precision.unwrap_or(6);
            (
                x.is_sign_negative(),
                exp_form(x.abs(), p, spec.alt, upper),
                true,
            )
        }
        _ => (
            x.is_sign_negative(),
            general_form(x.abs(), spec, upper),
            true,
        ),
    };
    Ok(pad(spec, sign(spec, negative), &body, zero_ok))
}

/// Split Rust's `{:.p$e}` output (`1.234568e8`) into mantissa and exponent.
fn rust_exp(x: f64, p: usize) -> (String, i32) {
    let s = format!("{:.*e}", p, x);
    match s.split_once('e') {
        Some((m, e)) => (m.to_string(), e.parse().unwrap_or(0)),
        None => (s, 0),
    }
}

/// C `%e` body for a non-negative finite `x`.
fn exp_form(x: f64, p: usize, alt: bool, upper: bool) -> String {
    let (mut mant, exp) = rust_exp(x, p);
    if alt && p == 0 {
        mant.push('.');
    }
    let e = if upper { 'E' } else { 'e' };
    let esign = if exp < 0 { '-' } else { '+' };
    format!("{mant}{e}{esign}{:02}", exp.unsigned_abs())
}

/// C `%g` body for a non-negative finite `x`.
fn general_form(x: f64, spec: &Spec, upper: bool) -> String {
    let p = match spec.precision {
        None => 6,
        Some(0) => 1,
        Some(p) => p,
    };
    let exp = if x == 0.0 { 0 } else { rust_exp(x, p - 1).1 };
    let p_i = i64::try_from(p).unwrap_or(i64::MAX);
    let exp_i = i64::from(exp);
    let s = if exp_i < p_i && exp_i >= -4 {
        let decimals = usize::try_from(p_i - 1 - exp_i).unwrap_or(0);
        let mut s = format!("{:.*}", decimals, x);
        if spec.alt && !s.contains('.') {
            s.push('.');
        }
        s
    } else {
        exp_form(x, p - 1, spec.alt, upper)
    };
    if spec.alt {
        return s;
    }
    // Remove trailing zeros of the fraction (and a bare '.').
    let (mant, tail) = match s.find(['e', 'E']) {
        Some(k) => (&s[..k], &s[k..]),
        None => (s.as_str(), ""),
    };
    let mant = if mant.contains('.') {
        mant.trim_end_matches('0').trim_end_matches('.')
    } else {
        mant
    };
    format!("{mant}{tail}")
}
