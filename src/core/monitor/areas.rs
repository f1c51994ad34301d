//! Workspace and protection areas: definition, definition rules and states (FCT-C14;
//! syntax also FCT-C14).
//!
//! This module is sans-IO. The NC layer drives it:
//!
//! | NC program | call | seed |
//! |---|---|---|
//! | text after `#CONTROL AREA` | [`parse_area_command`] → [`AreaCommand`] | 000 §3.1–§3.4, 002 |
//! | `#CONTROL AREA BEGIN/ON/OFF/CLEAR/END` | [`AreaTable::apply`] | 000 §3, Fig. 11 |
//! | a motion block between BEGIN and END | [`AreaTable::definition_block`] with a [`DefBlock`] | 000 §3.1, §3.1.1, §3.1.2, §4 |
//! | program end / controller reset | [`AreaTable::program_end`] / [`AreaTable::reset`] | 000 §3 notices |
//!
//! The geometry of one area is collected by [`AreaDefinition`] (usable on its own); the table
//! holds at most [`MAX_AREAS`] areas and their state ([`AreaState`]: cleared / defined / active).
//! Whether the TCP lies in an area is asked through [`TcpLocator`], so that the exact geometry
//! module can be plugged in; [`AreaPoint`] is a built-in locator using [`Area::contains`].
//!
//! # Coordinates
//!
//! Areas are defined in the MCS (FCT-C14 §2.3 notice, §3.1 attention): the caller passes the
//! definition points *after* G54 / G92 and the other Cartesian offsets, and *without* an active
//! `#(A)CS` (which areas ignore). `MONITOR_LVL=IMCS` areas take IMCS coordinates of the secondary
//! path (U/V/W, FCT-C14 §2.4); areas programmed with `X2=` / `Y2=` (FCT-C14 §4) are polygons in
//! the plane of those additional axes. The caller resolves arc centres (I/J/K with G161/G162) to
//! absolute coordinates before building a [`DefBlock`].
//!
//! # Machining plane
//!
//! "Normally, the surface area of the workspace or protection area is defined by the first two
//! main axes of the active machining plane" (FCT-C14 §3.1.1): a main-axes area defined under
//! G17 lies in X/Y (excursion Z), under G18 in Z/X (excursion Y), under G19 in Y/Z (excursion
//! X) — DIN 66025's 1st / 2nd / 3rd axis of each plane ([`Plane::axes`]); on the IMCS level the
//! same with U/V/W ([`plane_axis_names`]). The caller passes the plane of each block
//! ([`DefBlock::plane`]); the plane of the starting point is the area's ([`Area::plane`]), a
//! definition block in another plane is an error. The area keeps that plane afterwards, whatever
//! G17 / G18 / G19 a later block selects: "A workspace/protection area is defined by an object in
//! space" (§2.3). Additional-axes areas (`X2=` / `Y2=`, §4) always lie in X2/Y2 (excursion Z2).
//!
//! # Interpretations (where the seed is silent or ambiguous)
//!
//! - "≤ 20 blocks" for POLY (§2.3) counts the motion blocks including the starting point, so a
//!   polygon has at most 20 points, i.e. 19 distinct vertices plus the closing point.
//! - The seed's "convex" (§2.3, §3.1.1) means a simple closed chain: no two edges may cross or
//!   touch except adjacent edges at their common vertex (the seed's own example is not convex).
//! - The first definition block must program both plane coordinates (the starting point "must be
//!   specified", §4 release note); later blocks may omit a coordinate, which then keeps its value
//!   from the previous definition point (modal, as in the §4 example). Consecutive identical
//!   points are dropped (no zero-length edges) but still count as blocks.
//! - A block with neither coordinates nor a centre (e.g. only `F` / `G90`) is ignored.
//! - CIRC takes a G01 starting point and one G02/G03 block whose end point equals the start
//!   (omitted end coordinates mean "the start point"). POLY and CIRC take G01 for the start; G00
//!   is refused for MCS areas. `MONITOR_LVL=IMCS` areas also accept G00 points, because the
//!   seed's only 2-path example (§2.4) programs its polygon with `G0` (the seed contradicts its
//!   own §3.1 rule there; the issue asks for that example to be parsed and monitored). A G00
//!   block needs no F.
//! - Bare `ON` and bare `CLEAR` are syntax errors (the seed defines a bare form only for `OFF`).
//!   "The area last selected" for bare `OFF` is the set of IDs named by the last `ON` (`ON ALL`:
//!   every area defined at that moment).
//! - `ON ID=..` of an undefined ID is an error; `OFF` / `CLEAR` of an undefined ID are "nop".
//! - While a definition is open only definition blocks and `END` are accepted.
//! - Activation checks the TCP against the resulting set of active areas: workspaces form a union
//!   per monitoring space (MCS main axes, IMCS, additional axes, each per plane; Fig. 7),
//!   protection overrides workspaces (§2.3). `ON ALL` is all-or-nothing. Whether the TCP is
//!   "inside" an area is the [`TcpLocator`]'s answer: the channel passes one with the tolerance
//!   band of the path check (`area_monitor::AREA_TOLERANCE`, a TCP within the band of a
//!   protection area is inside it, one within the band outside a workspace is inside that), so
//!   that an activation that is accepted never leaves a TCP that no block could leave (§3.2 "the
//!   TCP may not incur any violation at the current position"). The built-in [`AreaPoint`]
//!   locator takes the exact boundary ([`POINT_EPSILON`]).

use std::fmt;

pub use super::area_geom::Plane;
use crate::messages::{ids, BlockRef, CncMessage};

/// FCT-C14 §2.3 / §3.1: at most 20 workspace and protection areas.
pub const MAX_AREAS: usize = 20;

/// FCT-C14 §2.3: at most 20 motion blocks define a polygon (starting point included).
pub const MAX_POLY_BLOCKS: usize = 20;

/// Length tolerance in mm (or inch) for "same point", "on the boundary" and "touching": 1 nm.
/// It only absorbs f64 rounding of the caller's offset arithmetic.
pub const POINT_EPSILON: f64 = 1e-6;

// ------------------------------------------------------------------------------------------
// Commands
// ------------------------------------------------------------------------------------------

/// `WORK` or `PROT` (FCT-C14 §3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AreaKind {
    /// `WORK`: the TCP must not leave the area.
    Work,
    /// `PROT`: the TCP must never touch the area.
    Prot,
}

/// `POLY` or `CIRC` (FCT-C14 §3.1.1 / §3.1.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AreaShape {
    /// `POLY`: closed chain of G01 blocks.
    Poly,
    /// `CIRC`: starting point and one full G02/G03 circle (a cylinder).
    Circ,
}

/// `MONITOR_LVL=` (FCT-C14 §3.1, §2.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum MonitorLevel {
    /// `MCS`: machine coordinate system (default).
    #[default]
    Mcs,
    /// `IMCS`: intermediate coordinate system (secondary path of a 2-path application).
    Imcs,
}

/// `EXCUR_AX=` / `EXCUR_AXNR=` (FCT-C14 §3.1): the axis of the third dimension.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ExcurAxis {
    /// `EXCUR_AX=<name>`: axis identifier (upper case).
    Name(String),
    /// `EXCUR_AXNR=<n>`: logical axis number.
    Number(u32),
}

/// The bracket of `#CONTROL AREA BEGIN [..]` (FCT-C14 §3.1).
#[derive(Debug, Clone, PartialEq)]
pub struct AreaHeader {
    /// `ID=..`.
    pub id: u32,
    /// `WORK` / `PROT`.
    pub kind: AreaKind,
    /// `POLY` / `CIRC`.
    pub shape: AreaShape,
    /// `MIN_EXCUR=..` in mm / inch.
    pub min_excur: f64,
    /// `MAX_EXCUR=..` in mm / inch.
    pub max_excur: f64,
    /// `EXCUR_AX=..` / `EXCUR_AXNR=..`; `None` = third main axis.
    pub excur_axis: Option<ExcurAxis>,
    /// `MONITOR_LVL=..`.
    pub monitor_level: MonitorLevel,
}

/// Which areas `ON` / `OFF` / `CLEAR` address (FCT-C14 §3.2–§3.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Selector {
    /// `ALL`.
    All,
    /// `ID=..` (also written `ID3`).
    Id(u32),
    /// Bare `OFF`: the area(s) last selected (§3.3).
    Last,
}

/// One `#CONTROL AREA` command, parsed (FCT-C14 §3).
#[derive(Debug, Clone, PartialEq)]
pub enum AreaCommand {
    /// `BEGIN` / `START [..]`.
    Begin(AreaHeader),
    /// `END`.
    End,
    /// `ON [ALL] | [ID=..]`.
    On(Selector),
    /// `OFF [ALL] | [ID=..]` or bare `OFF`.
    Off(Selector),
    /// `CLEAR [ALL] | [ID=..]`.
    Clear(Selector),
}

/// A syntax error in the text after `#CONTROL AREA`, naming the keyword and what is allowed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AreaSyntaxError {
    /// Nothing after `#CONTROL AREA`.
    #[error("#CONTROL AREA: command missing, allowed: BEGIN | START | END | ON | OFF | CLEAR")]
    MissingCommand,
    /// Unknown command word.
    #[error(
        "#CONTROL AREA: unknown command `{found}`, allowed: BEGIN | START | END | ON | OFF | CLEAR"
    )]
    UnknownCommand {
        /// The word found.
        found: String,
    },
    /// Unknown keyword inside a command.
    #[error("#CONTROL AREA {command}: unknown keyword `{found}`, allowed: {allowed}")]
    UnknownKeyword {
        /// The command (`BEGIN`, `ON`, ..).
        command: &'static str,
        /// The word found.
        found: String,
        /// The allowed keywords.
        allowed: &'static str,
    },
    /// A keyword's value is missing or not of the allowed form.
    #[error("#CONTROL AREA: {keyword}: bad value `{found}`, allowed: {allowed}")]
    BadValue {
        /// The keyword.
        keyword: &'static str,
        /// The value found (empty if none).
        found: String,
        /// The allowed values.
        allowed: &'static str,
    },
    /// A mandatory keyword is missing.
    #[error("#CONTROL AREA {command}: {keyword} missing, allowed: {allowed}")]
    Missing {
        /// The command.
        command: &'static str,
        /// The keyword (group) missing.
        keyword: &'static str,
        /// The allowed values.
        allowed: &'static str,
    },
    /// A keyword (group) programmed twice, e.g. `WORK PROT`.
    #[error("#CONTROL AREA {command}: {keyword} programmed twice, allowed once: {allowed}")]
    Duplicate {
        /// The command.
        command: &'static str,
        /// The keyword (group).
        keyword: &'static str,
        /// The allowed values.
        allowed: &'static str,
    },
    /// Brackets or quotes do not match, or text follows the closing bracket.
    #[error("#CONTROL AREA: malformed brackets or quotes near `{found}`")]
    Malformed {
        /// The offending text.
        found: String,
    },
}

const BEGIN_KEYWORDS: &str =
    "ID=.. WORK | PROT POLY | CIRC MIN_EXCUR=.. MAX_EXCUR=.. [EXCUR_AX=.. | EXCUR_AXNR=..] [MONITOR_LVL=MCS | IMCS]";
const SELECT_KEYWORDS: &str = "ALL | ID=..";

/// One lexical item of the command text.
#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Eq,
    Open,
    Close,
}

fn tokenize(text: &str) -> Result<Vec<Tok>, AreaSyntaxError> {
    let mut out = Vec::new();
    let mut chars = text.chars().peekable();
    let mut word = String::new();
    let flush = |word: &mut String, out: &mut Vec<Tok>| {
        if !word.is_empty() {
            out.push(Tok::Word(std::mem::take(word).to_ascii_uppercase()));
        }
    };
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() => flush(&mut word, &mut out),
            '=' => {
                flush(&mut word, &mut out);
                out.push(Tok::Eq);
            }
            '[' => {
                flush(&mut word, &mut out);
                out.push(Tok::Open);
            }
            ']' => {
                flush(&mut word, &mut out);
                out.push(Tok::Close);
            }
            '"' => {
                flush(&mut word, &mut out);
                let mut quoted = String::new();
                let mut closed = false;
                for q in chars.by_ref() {
                    if q == '"' {
                        closed = true;
                        break;
                    }
                    quoted.push(q);
                }
                if !closed {
                    return Err(AreaSyntaxError::Malformed {
                        found: format!("\"{quoted}"),
                    });
                }
                out.push(Tok::Word(quoted.trim().to_ascii_uppercase()));
            }
            c => word.push(c),
        }
    }
    flush(&mut word, &mut out);
    Ok(out)
}

/// A keyword with its optional value (`ID=3`, `ID3`, `WORK`).
#[derive(Debug)]
struct Item {
    key: String,
    value: Option<String>,
}

/// Group the tokens after the command word into items; brackets are optional but must match.
fn items(toks: &[Tok]) -> Result<Vec<Item>, AreaSyntaxError> {
    let mut depth = 0usize;
    let mut seen_close = false;
    let mut out: Vec<Item> = Vec::new();
    let mut i = 0;
    while i < toks.len() {
        match &toks[i] {
            Tok::Open => {
                if depth > 0 || seen_close {
                    return Err(AreaSyntaxError::Malformed { found: "[".into() });
                }
                depth += 1;
            }
            Tok::Close => {
                if depth == 0 {
                    return Err(AreaSyntaxError::Malformed { found: "]".into() });
                }
                depth -= 1;
                seen_close = true;
            }
            Tok::Eq => {
                return Err(AreaSyntaxError::Malformed { found: "=".into() });
            }
            Tok::Word(w) => {
                if seen_close && depth == 0 {
                    return Err(AreaSyntaxError::Malformed { found: w.clone() });
                }
                let mut item = Item {
                    key: w.clone(),
                    value: None,
                };
                if matches!(toks.get(i + 1), Some(Tok::Eq)) {
                    match toks.get(i + 2) {
                        Some(Tok::Word(v)) => {
                            item.value = Some(v.clone());
                            i += 2;
                        }
                        _ => {
                            item.value = Some(String::new());
                            i += 1;
                        }
                    }
                }
                out.push(item);
            }
        }
        i += 1;
    }
    if depth != 0 {
        return Err(AreaSyntaxError::Malformed { found: "[".into() });
    }
    Ok(out)
}

/// `ID=3` or the seed's own `ID3` form.
fn id_of(item: &Item) -> Option<Result<u32, AreaSyntaxError>> {
    let bad = |found: &str| AreaSyntaxError::BadValue {
        keyword: "ID",
        found: found.to_string(),
        allowed: "a non-negative integer (ID=3 or ID3)",
    };
    if item.key == "ID" {
        let v = item.value.clone().unwrap_or_default();
        return Some(v.parse::<u32>().map_err(|_| bad(&v)));
    }
    let rest = item.key.strip_prefix("ID")?;
    if item.value.is_none() && !rest.is_empty() && rest.chars().all(|c| c.is_ascii_digit()) {
        return Some(rest.parse::<u32>().map_err(|_| bad(rest)));
    }
    None
}

fn number(keyword: &'static str, item: &Item) -> Result<f64, AreaSyntaxError> {
    let v = item.value.clone().unwrap_or_default();
    match v.parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(AreaSyntaxError::BadValue {
            keyword,
            found: v,
            allowed: "a number in mm / inch",
        }),
    }
}

fn parse_begin(items: &[Item]) -> Result<AreaHeader, AreaSyntaxError> {
    const C: &str = "BEGIN";
    let mut id = None;
    let mut kind = None;
    let mut shape = None;
    let mut min = None;
    let mut max = None;
    let mut excur = None;
    let mut level = None;
    fn set<T>(
        slot: &mut Option<T>,
        v: T,
        keyword: &'static str,
        allowed: &'static str,
    ) -> Result<(), AreaSyntaxError> {
        if slot.is_some() {
            return Err(AreaSyntaxError::Duplicate {
                command: "BEGIN",
                keyword,
                allowed,
            });
        }
        *slot = Some(v);
        Ok(())
    }
    for item in items {
        if let Some(r) = id_of(item) {
            set(&mut id, r?, "ID", "ID=..")?;
            continue;
        }
        let flag = |keyword: &'static str| -> Result<(), AreaSyntaxError> {
            match &item.value {
                None => Ok(()),
                Some(v) => Err(AreaSyntaxError::BadValue {
                    keyword,
                    found: v.clone(),
                    allowed: "no value",
                }),
            }
        };
        match item.key.as_str() {
            "WORK" => {
                flag("WORK")?;
                set(&mut kind, AreaKind::Work, "WORK | PROT", "WORK | PROT")?
            }
            "PROT" => {
                flag("PROT")?;
                set(&mut kind, AreaKind::Prot, "WORK | PROT", "WORK | PROT")?
            }
            "POLY" => {
                flag("POLY")?;
                set(&mut shape, AreaShape::Poly, "POLY | CIRC", "POLY | CIRC")?
            }
            "CIRC" => {
                flag("CIRC")?;
                set(&mut shape, AreaShape::Circ, "POLY | CIRC", "POLY | CIRC")?
            }
            "MIN_EXCUR" => set(
                &mut min,
                number("MIN_EXCUR", item)?,
                "MIN_EXCUR",
                "MIN_EXCUR=..",
            )?,
            "MAX_EXCUR" => set(
                &mut max,
                number("MAX_EXCUR", item)?,
                "MAX_EXCUR",
                "MAX_EXCUR=..",
            )?,
            "EXCUR_AX" => {
                let v = item.value.clone().unwrap_or_default();
                let ok = !v.is_empty()
                    && v.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
                    && v.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
                if !ok {
                    return Err(AreaSyntaxError::BadValue {
                        keyword: "EXCUR_AX",
                        found: v,
                        allowed: "an axis identifier (e.g. Z, Z2)",
                    });
                }
                set(
                    &mut excur,
                    ExcurAxis::Name(v),
                    "EXCUR_AX | EXCUR_AXNR",
                    "EXCUR_AX=.. | EXCUR_AXNR=..",
                )?
            }
            "EXCUR_AXNR" => {
                let v = item.value.clone().unwrap_or_default();
                let n = v.parse::<u32>().ok().filter(|n| *n >= 1).ok_or_else(|| {
                    AreaSyntaxError::BadValue {
                        keyword: "EXCUR_AXNR",
                        found: v.clone(),
                        allowed: "a logical axis number 1, 2, … (AXNR numbering)",
                    }
                })?;
                set(
                    &mut excur,
                    ExcurAxis::Number(n),
                    "EXCUR_AX | EXCUR_AXNR",
                    "EXCUR_AX=.. | EXCUR_AXNR=..",
                )?
            }
            "MONITOR_LVL" => {
                let v = item.value.clone().unwrap_or_default();
                let l = match v.as_str() {
                    "MCS" => MonitorLevel::Mcs,
                    "IMCS" => MonitorLevel::Imcs,
                    _ => {
                        return Err(AreaSyntaxError::BadValue {
                            keyword: "MONITOR_LVL",
                            found: v,
                            allowed: "MCS | IMCS",
                        })
                    }
                };
                set(&mut level, l, "MONITOR_LVL", "MONITOR_LVL=MCS | IMCS")?
            }
            _ => {
                return Err(AreaSyntaxError::UnknownKeyword {
                    command: C,
                    found: item.key.clone(),
                    allowed: BEGIN_KEYWORDS,
                })
            }
        }
    }
    let missing = |keyword: &'static str, allowed: &'static str| AreaSyntaxError::Missing {
        command: C,
        keyword,
        allowed,
    };
    Ok(AreaHeader {
        id: id.ok_or_else(|| missing("ID", "ID=.."))?,
        kind: kind.ok_or_else(|| missing("WORK | PROT", "WORK | PROT"))?,
        shape: shape.ok_or_else(|| missing("POLY | CIRC", "POLY | CIRC"))?,
        min_excur: min.ok_or_else(|| missing("MIN_EXCUR", "MIN_EXCUR=.."))?,
        max_excur: max.ok_or_else(|| missing("MAX_EXCUR", "MAX_EXCUR=.."))?,
        excur_axis: excur,
        monitor_level: level.unwrap_or_default(),
    })
}

fn parse_selector(
    command: &'static str,
    items: &[Item],
    bare: Option<Selector>,
) -> Result<Selector, AreaSyntaxError> {
    match items {
        [] => bare.ok_or(AreaSyntaxError::Missing {
            command,
            keyword: "ALL | ID",
            allowed: SELECT_KEYWORDS,
        }),
        [item] => {
            if let Some(r) = id_of(item) {
                return Ok(Selector::Id(r?));
            }
            if item.key == "ALL" && item.value.is_none() {
                return Ok(Selector::All);
            }
            Err(AreaSyntaxError::UnknownKeyword {
                command,
                found: item.key.clone(),
                allowed: SELECT_KEYWORDS,
            })
        }
        [_, second, ..] => Err(AreaSyntaxError::UnknownKeyword {
            command,
            found: second.key.clone(),
            allowed: SELECT_KEYWORDS,
        }),
    }
}

/// Parse the text after `#CONTROL AREA` (a leading `#CONTROL AREA` is accepted and skipped).
///
/// Accepts the seed's spellings: `START` for `BEGIN`, `ID3` for `ID=3`, spaces around `=`,
/// quoted values (`MONITOR_LVL = "IMCS"`, FCT-C14 §2.4), line breaks inside the bracket, and
/// `ON ALL` / `ON [ALL]`. Keywords are case-insensitive. Numbers must be literal; the NC layer
/// substitutes parameters before calling.
pub fn parse_area_command(text: &str) -> Result<AreaCommand, AreaSyntaxError> {
    let toks = tokenize(text)?;
    let mut rest: &[Tok] = &toks;
    if let [Tok::Word(a), Tok::Word(b), tail @ ..] = rest {
        if a == "#CONTROL" && b == "AREA" {
            rest = tail;
        }
    }
    let (cmd, tail) = match rest {
        [] => return Err(AreaSyntaxError::MissingCommand),
        [Tok::Word(w), tail @ ..] => (w.as_str(), tail),
        [other, ..] => {
            return Err(AreaSyntaxError::UnknownCommand {
                found: match other {
                    Tok::Eq => "=".into(),
                    Tok::Open => "[".into(),
                    _ => "]".into(),
                },
            })
        }
    };
    match cmd {
        "BEGIN" | "START" | "END" | "ON" | "OFF" | "CLEAR" => {}
        _ => {
            return Err(AreaSyntaxError::UnknownCommand {
                found: cmd.to_string(),
            })
        }
    }
    let items = items(tail)?;
    Ok(match cmd {
        "BEGIN" | "START" => AreaCommand::Begin(parse_begin(&items)?),
        "END" => {
            if let Some(item) = items.first() {
                return Err(AreaSyntaxError::UnknownKeyword {
                    command: "END",
                    found: item.key.clone(),
                    allowed: "nothing",
                });
            }
            AreaCommand::End
        }
        "ON" => AreaCommand::On(parse_selector("ON", &items, None)?),
        "OFF" => AreaCommand::Off(parse_selector("OFF", &items, Some(Selector::Last))?),
        _ => AreaCommand::Clear(parse_selector("CLEAR", &items, None)?),
    })
}

// ------------------------------------------------------------------------------------------
// Definition blocks and the definition builder
// ------------------------------------------------------------------------------------------

/// The motion G code of a definition block.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DefMotion {
    /// G00.
    G00,
    /// G01.
    G01,
    /// G02 (clockwise circle).
    G02,
    /// G03 (counter-clockwise circle).
    G03,
    /// Any other motion (spline, polynomial, G100, ..): not allowed in a definition.
    Other,
}

impl fmt::Display for DefMotion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DefMotion::G00 => "G00",
            DefMotion::G01 => "G01",
            DefMotion::G02 => "G02",
            DefMotion::G03 => "G03",
            DefMotion::Other => "a motion other than G00/G01/G02/G03",
        })
    }
}

/// One NC motion block between `#CONTROL AREA BEGIN` and `END`, as the NC layer resolved it
/// (FCT-C14 §3.1). Coordinates are MCS (offsets applied, `#(A)CS` ignored) and absolute.
#[derive(Debug, Clone, PartialEq)]
pub struct DefBlock {
    /// The block (N number, line).
    pub at: BlockRef,
    /// Modal motion G code in effect for this block.
    pub motion: DefMotion,
    /// G90 in effect (absolute dimensions).
    pub absolute: bool,
    /// A valid F (non-zero) is active.
    pub feed_valid: bool,
    /// End point in the plane of the 1st / 2nd main axis (X/Y for G17; U/V for IMCS areas);
    /// `None` = not programmed in this block.
    pub main: [Option<f64>; 2],
    /// End point of the additional axes `X2=` / `Y2=` (FCT-C14 §4).
    pub additional: [Option<f64>; 2],
    /// Absolute arc centre in the same plane as the end point (G02 / G03).
    pub centre: Option<[f64; 2]>,
    /// The machining plane active for this block (G17 / G18 / G19): `main` and `centre` are its
    /// 1st / 2nd axis (FCT-C14 §3.1.1). Not used for the additional axes.
    pub plane: Plane,
}

impl DefBlock {
    /// A block with G90 and a valid F, no coordinates yet.
    pub fn new(at: BlockRef, motion: DefMotion) -> Self {
        DefBlock {
            at,
            motion,
            absolute: true,
            feed_valid: true,
            main: [None, None],
            additional: [None, None],
            centre: None,
            plane: Plane::G17,
        }
    }

    /// Set the machining plane of the block (default G17).
    pub fn plane(mut self, plane: Plane) -> Self {
        self.plane = plane;
        self
    }

    /// Set both main-plane coordinates.
    pub fn xy(mut self, x: f64, y: f64) -> Self {
        self.main = [Some(x), Some(y)];
        self
    }

    /// Set the 1st main-plane coordinate only.
    pub fn x(mut self, x: f64) -> Self {
        self.main[0] = Some(x);
        self
    }

    /// Set the 2nd main-plane coordinate only.
    pub fn y(mut self, y: f64) -> Self {
        self.main[1] = Some(y);
        self
    }

    /// Set `X2=`.
    pub fn x2(mut self, x: f64) -> Self {
        self.additional[0] = Some(x);
        self
    }

    /// Set `Y2=`.
    pub fn y2(mut self, y: f64) -> Self {
        self.additional[1] = Some(y);
        self
    }

    /// Set the absolute arc centre.
    pub fn centre(mut self, cx: f64, cy: f64) -> Self {
        self.centre = Some([cx, cy]);
        self
    }

    /// Set G90 (true) or G91 (false).
    pub fn absolute(mut self, absolute: bool) -> Self {
        self.absolute = absolute;
        self
    }

    /// Set whether a valid F is active.
    pub fn feed_valid(mut self, valid: bool) -> Self {
        self.feed_valid = valid;
        self
    }
}

/// Which axes an area's plane is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AreaAxes {
    /// The 1st / 2nd main axis (or U/V on the IMCS level).
    Main,
    /// The additional axes `X2` / `Y2` (FCT-C14 §4; polygons only).
    Additional,
}

/// Names of the channel axes an area of this kind lies on: `[1st plane axis, 2nd plane axis,
/// default excursion axis]`.
///
/// | level / axes | G17 | G18 | G19 |
/// |---|---|---|---|
/// | MCS, main axes | X, Y, Z | Z, X, Y | Y, Z, X |
/// | IMCS (§2.4) | U, V, W | W, U, V | V, W, U |
/// | additional axes (§4) | X2, Y2, Z2 | X2, Y2, Z2 | X2, Y2, Z2 |
///
/// FCT-C14 §3.1.1 "the first two main axes of the active machining plane", §2.3 "Example of X/Y
/// basic plane (G17): X → 1st main axis, Y → 2nd main axis, Z → 3rd main axis"; the planes'
/// axis order is DIN 66025's (G18: Z → X, G19: Y → Z).
pub fn plane_axis_names(level: MonitorLevel, axes: AreaAxes, plane: Plane) -> [&'static str; 3] {
    let main = match (level, axes) {
        (_, AreaAxes::Additional) => return ["X2", "Y2", "Z2"],
        (MonitorLevel::Mcs, AreaAxes::Main) => ["X", "Y", "Z"],
        (MonitorLevel::Imcs, AreaAxes::Main) => ["U", "V", "W"],
    };
    let (a, b, c) = plane.axes();
    [main[a], main[b], main[c]]
}

/// The contour in the plane.
#[derive(Debug, Clone, PartialEq)]
pub enum AreaGeometry {
    /// Closed polygon: distinct vertices in programmed order; the closing edge from the last
    /// vertex back to the first is implicit (the programmed closing point is not repeated).
    Polygon {
        /// Vertices (≥ 3).
        vertices: Vec<[f64; 2]>,
    },
    /// Full circle (a cylinder with the excursion).
    Circle {
        /// Centre.
        centre: [f64; 2],
        /// Radius (> 0).
        radius: f64,
    },
}

/// Axis-aligned extents of an area: plane coordinates 0 / 1, excursion 2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extents {
    /// Minimum per coordinate.
    pub min: [f64; 3],
    /// Maximum per coordinate.
    pub max: [f64; 3],
}

/// A complete, validated workspace or protection area.
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    /// The BEGIN bracket.
    pub header: AreaHeader,
    /// Main or additional axes.
    pub axes: AreaAxes,
    /// The machining plane the area was defined in (main axes; G17 for additional axes): the
    /// contour lies in its 1st / 2nd axis, the excursion is its 3rd (FCT-C14 §3.1.1).
    pub plane: Plane,
    /// The contour.
    pub geometry: AreaGeometry,
    /// The BEGIN block.
    pub defined_at: Option<BlockRef>,
}

/// A point in an area's own coordinates: the plane and the excursion axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaPoint {
    /// Plane coordinates (1st / 2nd axis of the area).
    pub plane: [f64; 2],
    /// Coordinate on the excursion axis.
    pub excursion: f64,
}

impl Area {
    /// The area ID.
    pub fn id(&self) -> u32 {
        self.header.id
    }

    /// `WORK` / `PROT`.
    pub fn kind(&self) -> AreaKind {
        self.header.kind
    }

    /// The monitoring space this area belongs to; workspaces form a union per space.
    pub fn space(&self) -> (MonitorLevel, AreaAxes, Plane) {
        (self.header.monitor_level, self.axes, self.plane)
    }

    /// Axis names of the plane's 1st and 2nd axis and of the default excursion axis.
    pub fn axis_names(&self) -> [&'static str; 3] {
        plane_axis_names(self.header.monitor_level, self.axes, self.plane)
    }

    /// Extents of the body (plane bounding box and `MIN_EXCUR` / `MAX_EXCUR`).
    pub fn extents(&self) -> Extents {
        let (lo, hi) = match &self.geometry {
            AreaGeometry::Polygon { vertices } => {
                let mut lo = [f64::INFINITY; 2];
                let mut hi = [f64::NEG_INFINITY; 2];
                for v in vertices {
                    for k in 0..2 {
                        lo[k] = lo[k].min(v[k]);
                        hi[k] = hi[k].max(v[k]);
                    }
                }
                (lo, hi)
            }
            AreaGeometry::Circle { centre, radius } => (
                [centre[0] - radius, centre[1] - radius],
                [centre[0] + radius, centre[1] + radius],
            ),
        };
        Extents {
            min: [lo[0], lo[1], self.header.min_excur],
            max: [hi[0], hi[1], self.header.max_excur],
        }
    }

    /// Is `p` inside the body (boundary included within [`POINT_EPSILON`])?
    ///
    /// The simple built-in test (crossing number for polygons); the exact path checks live in the
    /// geometry module.
    pub fn contains(&self, p: AreaPoint) -> bool {
        if p.excursion < self.header.min_excur - POINT_EPSILON
            || p.excursion > self.header.max_excur + POINT_EPSILON
        {
            return false;
        }
        match &self.geometry {
            AreaGeometry::Circle { centre, radius } => {
                dist(p.plane, *centre) <= radius + POINT_EPSILON
            }
            AreaGeometry::Polygon { vertices } => point_in_polygon(p.plane, vertices),
        }
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Distance of `p` from the segment `a`–`b`.
fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let l2 = d[0] * d[0] + d[1] * d[1];
    if l2 == 0.0 {
        return dist(p, a);
    }
    let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / l2).clamp(0.0, 1.0);
    dist(p, [a[0] + t * d[0], a[1] + t * d[1]])
}

fn point_in_polygon(p: [f64; 2], v: &[[f64; 2]]) -> bool {
    let n = v.len();
    if (0..n).any(|i| seg_dist(p, v[i], v[(i + 1) % n]) <= POINT_EPSILON) {
        return true;
    }
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (v[i], v[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// Do the closed segments `a`–`b` and `c`–`d` intersect or touch (within [`POINT_EPSILON`])?
fn segments_touch(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    if seg_dist(a, c, d) <= POINT_EPSILON
        || seg_dist(b, c, d) <= POINT_EPSILON
        || seg_dist(c, a, b) <= POINT_EPSILON
        || seg_dist(d, a, b) <= POINT_EPSILON
    {
        return true;
    }
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// Which rule of FCT-C14 §3 a definition or a command violated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AreaErrorKind {
    /// The command text does not parse.
    #[error(transparent)]
    Syntax(#[from] AreaSyntaxError),
    /// §3.1 attention: definition blocks must be absolute (G90).
    #[error("control area {id}: G90 required in the definition (G91 active)")]
    NotAbsolute {
        /// Area ID.
        id: u32,
    },
    /// §3.1: a valid F must be active.
    #[error("control area {id}: no valid feed (F) active in the definition")]
    NoFeed {
        /// Area ID.
        id: u32,
    },
    /// §3.1 / §3.1.1 / §3.1.2: POLY takes G01, CIRC a G01 start and G02/G03.
    #[error("control area {id}: {shape:?} expects {expected} here, found {found}")]
    WrongMotion {
        /// Area ID.
        id: u32,
        /// The area shape.
        shape: AreaShape,
        /// The motion found.
        found: DefMotion,
        /// What was expected.
        expected: &'static str,
    },
    /// §2.3: more than [`MAX_POLY_BLOCKS`] blocks define the polygon.
    #[error("control area {id}: more than {max} motion blocks in the polygon", max = MAX_POLY_BLOCKS)]
    TooManyBlocks {
        /// Area ID.
        id: u32,
    },
    /// §4: the starting point must program both coordinates.
    #[error("control area {id}: the starting point must program both plane coordinates ({axes})")]
    StartIncomplete {
        /// Area ID.
        id: u32,
        /// The two coordinates expected, e.g. `Z and X (G18)`.
        axes: String,
    },
    /// §3.1.1: the plane of the definition (that of its starting point) changed within it.
    #[error("control area {id}: defined in the {plane} plane, a block in {found} found; the machining plane must not change within a definition")]
    PlaneChanged {
        /// Area ID.
        id: u32,
        /// The plane of the starting point.
        plane: Plane,
        /// The plane of the offending block.
        found: Plane,
    },
    /// §4: main and additional axes mixed in one area.
    #[error("control area {id}: main axes and additional axes (X2/Y2) mixed in one definition")]
    MixedAxes {
        /// Area ID.
        id: u32,
    },
    /// §4: areas of additional axes are polygons only.
    #[error("control area {id}: additional axes (X2/Y2) allow POLY areas only")]
    AdditionalAxesCirc {
        /// Area ID.
        id: u32,
    },
    /// §3.1.1 notice: first point and last point differ.
    #[error("control area {id}: polygon not closed, last point ({:.4}, {:.4}) differs from the first ({:.4}, {:.4})", last[0], last[1], first[0], first[1])]
    NotClosed {
        /// Area ID.
        id: u32,
        /// First point.
        first: [f64; 2],
        /// Last point.
        last: [f64; 2],
    },
    /// §3.1.1: fewer than 3 distinct vertices.
    #[error("control area {id}: polygon needs at least 3 distinct points, has {vertices}")]
    TooFewPoints {
        /// Area ID.
        id: u32,
        /// Distinct vertices found.
        vertices: usize,
    },
    /// §2.3 / §3.1.1: two edges of the polygon cross or touch.
    #[error("control area {id}: polygon intersects itself: the edge ending in {first} meets the edge ending in {second}")]
    SelfIntersection {
        /// Area ID.
        id: u32,
        /// Block of the first edge.
        first: BlockRef,
        /// Block of the second edge.
        second: BlockRef,
    },
    /// §3.1.2: a G02/G03 without a centre.
    #[error("control area {id}: circle without centre")]
    NoCentre {
        /// Area ID.
        id: u32,
    },
    /// §3.1.2: the circle is not a full circle (end ≠ start).
    #[error(
        "control area {id}: CIRC needs a full circle, the end point differs from the start point"
    )]
    NotFullCircle {
        /// Area ID.
        id: u32,
    },
    /// §3.1.2: radius zero.
    #[error("control area {id}: circle radius is zero")]
    ZeroRadius {
        /// Area ID.
        id: u32,
    },
    /// §3.1.2: a block after the full circle.
    #[error("control area {id}: CIRC takes one full circle, further motion block found")]
    ExtraBlock {
        /// Area ID.
        id: u32,
    },
    /// §3.1.2: END before the starting point and the circle were programmed.
    #[error("control area {id}: CIRC needs a starting point and a full G02/G03 circle")]
    CircleMissing {
        /// Area ID.
        id: u32,
    },
    /// §3.1: `MIN_EXCUR` must be below `MAX_EXCUR`.
    #[error("control area {id}: MIN_EXCUR={min} must be less than MAX_EXCUR={max}")]
    ExcursionOrder {
        /// Area ID.
        id: u32,
        /// MIN_EXCUR.
        min: f64,
        /// MAX_EXCUR.
        max: f64,
    },
    /// §2.3 / §3.1: a 21st area.
    #[error("control area {id}: no more than {max} control areas can be defined", max = MAX_AREAS)]
    TableFull {
        /// Area ID.
        id: u32,
    },
    /// §3.1 "Overwrite control areas": the ID is active.
    #[error("control area {id} is active and cannot be overwritten")]
    OverwriteActive {
        /// Area ID.
        id: u32,
    },
    /// §3.1: BEGIN while a definition is open, END without BEGIN, ON/OFF/CLEAR inside a
    /// definition, END missing at program end.
    #[error("#CONTROL AREA {command}: {reason}")]
    Sequence {
        /// The command.
        command: &'static str,
        /// What is wrong.
        reason: &'static str,
    },
    /// `ON ID=..` of an undefined area, or bare `OFF` with nothing selected before.
    #[error("control area {id}: not defined")]
    Undefined {
        /// Area ID (0 for bare OFF without a previous ON).
        id: u32,
    },
    /// §3.2: the TCP is not in a valid position for the areas to be activated.
    #[error("control areas {ids:?}: the TCP is not in a valid position, activation refused")]
    TcpInvalid {
        /// The areas that make the position invalid.
        ids: Vec<u32>,
    },
}

impl AreaErrorKind {
    /// The message ID (project IDs, FCT-C14 gives none for these errors).
    pub fn message_id(&self) -> u32 {
        use AreaErrorKind::*;
        match self {
            Syntax(_) => ids::AREA_SYNTAX,
            NotAbsolute { .. } => ids::AREA_NOT_ABSOLUTE,
            NoFeed { .. } => ids::AREA_NO_FEED,
            WrongMotion { .. } => ids::AREA_WRONG_MOTION,
            TooManyBlocks { .. } => ids::AREA_TOO_MANY_BLOCKS,
            StartIncomplete { .. }
            | PlaneChanged { .. }
            | MixedAxes { .. }
            | AdditionalAxesCirc { .. } => ids::AREA_AXES,
            NotClosed { .. } => ids::AREA_NOT_CLOSED,
            TooFewPoints { .. } => ids::AREA_TOO_FEW_POINTS,
            SelfIntersection { .. } => ids::AREA_SELF_INTERSECTION,
            NoCentre { .. }
            | NotFullCircle { .. }
            | ZeroRadius { .. }
            | ExtraBlock { .. }
            | CircleMissing { .. } => ids::AREA_CIRCLE,
            ExcursionOrder { .. } => ids::AREA_EXCURSION,
            TableFull { .. } => ids::AREA_TABLE_FULL,
            OverwriteActive { .. } => ids::AREA_OVERWRITE_ACTIVE,
            Sequence { .. } => ids::AREA_SEQUENCE,
            Undefined { .. } => ids::AREA_UNDEFINED,
            TcpInvalid { .. } => ids::AREA_TCP_INVALID,
        }
    }
}

/// An [`AreaErrorKind`] with the block that caused it.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaError {
    /// The rule violated.
    pub kind: AreaErrorKind,
    /// The block (definition block, BEGIN, END or command).
    pub at: Option<BlockRef>,
}

impl fmt::Display for AreaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.at {
            Some(b) => write!(f, "{b}: {}", self.kind),
            None => write!(f, "{}", self.kind),
        }
    }
}

impl std::error::Error for AreaError {}

impl AreaError {
    fn new(kind: AreaErrorKind, at: Option<BlockRef>) -> Self {
        AreaError { kind, at }
    }

    /// The CNC error message (severity error, block attached).
    pub fn message(&self) -> CncMessage {
        CncMessage::error(self.kind.message_id(), self.kind.to_string()).at(self.at)
    }
}

impl From<AreaError> for CncMessage {
    fn from(e: AreaError) -> Self {
        e.message()
    }
}

/// One collected definition point.
#[derive(Debug, Clone, Copy)]
struct DefPoint {
    p: [f64; 2],
    at: BlockRef,
}

/// Collects the geometry of one area between `BEGIN` and `END` and enforces the definition
/// rules of FCT-C14 §3.1 (lifecycle: [`AreaDefinition::begin`] → [`AreaDefinition::block`]* →
/// [`AreaDefinition::end`]).
#[derive(Debug, Clone)]
pub struct AreaDefinition {
    header: AreaHeader,
    begin_at: Option<BlockRef>,
    axes: Option<AreaAxes>,
    /// The plane of the starting point (main axes).
    plane: Option<Plane>,
    blocks: usize,
    points: Vec<DefPoint>,
    circle: Option<([f64; 2], f64)>,
}

impl AreaDefinition {
    /// Open a definition; checks `MIN_EXCUR < MAX_EXCUR`.
    pub fn begin(header: AreaHeader, at: Option<BlockRef>) -> Result<Self, AreaError> {
        if header.min_excur.is_nan()
            || header.max_excur.is_nan()
            || header.min_excur >= header.max_excur
        {
            return Err(AreaError::new(
                AreaErrorKind::ExcursionOrder {
                    id: header.id,
                    min: header.min_excur,
                    max: header.max_excur,
                },
                at,
            ));
        }
        Ok(AreaDefinition {
            header,
            begin_at: at,
            axes: None,
            plane: None,
            blocks: 0,
            points: Vec::new(),
            circle: None,
        })
    }

    /// The BEGIN bracket.
    pub fn header(&self) -> &AreaHeader {
        &self.header
    }

    /// Feed one definition block.
    pub fn block(&mut self, b: &DefBlock) -> Result<(), AreaError> {
        let id = self.header.id;
        let err = |kind| Err(AreaError::new(kind, Some(b.at)));
        let has_main = b.main.iter().any(Option::is_some);
        let has_add = b.additional.iter().any(Option::is_some);
        if !has_main && !has_add && b.centre.is_none() {
            return Ok(()); // a purely modal block (F, G90 ..) defines nothing
        }
        if !b.absolute {
            return err(AreaErrorKind::NotAbsolute { id });
        }
        if !b.feed_valid {
            return err(AreaErrorKind::NoFeed { id });
        }
        if has_main && has_add {
            return err(AreaErrorKind::MixedAxes { id });
        }
        let axes = if has_add {
            AreaAxes::Additional
        } else if has_main {
            AreaAxes::Main
        } else {
            self.axes.unwrap_or(AreaAxes::Main)
        };
        if self.axes.is_some_and(|a| a != axes) {
            return err(AreaErrorKind::MixedAxes { id });
        }
        if axes == AreaAxes::Additional && self.header.shape == AreaShape::Circ {
            return err(AreaErrorKind::AdditionalAxesCirc { id });
        }
        let plane = match axes {
            AreaAxes::Main => b.plane,
            AreaAxes::Additional => Plane::G17,
        };
        if let Some(first) = self.plane.filter(|p| *p != plane) {
            return err(AreaErrorKind::PlaneChanged {
                id,
                plane: first,
                found: plane,
            });
        }
        let coords = match axes {
            AreaAxes::Main => b.main,
            AreaAxes::Additional => b.additional,
        };
        let prev = self.points.last().map(|p| p.p);
        let end = match prev {
            None => match coords {
                [Some(x), Some(y)] => [x, y],
                _ => {
                    let [p, q, _] = plane_axis_names(self.header.monitor_level, axes, plane);
                    let axes = match axes {
                        AreaAxes::Main => format!("{p} and {q} ({plane})"),
                        AreaAxes::Additional => format!("{p} and {q}"),
                    };
                    return err(AreaErrorKind::StartIncomplete { id, axes });
                }
            },
            Some(p) => [coords[0].unwrap_or(p[0]), coords[1].unwrap_or(p[1])],
        };
        if !(end[0].is_finite() && end[1].is_finite()) {
            return err(AreaErrorKind::StartIncomplete {
                id,
                axes: "finite numbers".to_string(),
            });
        }
        // FCT-C14 §2.4: the 2-path (IMCS) example programs its polygon with G0 blocks.
        let imcs_rapid = self.header.monitor_level == MonitorLevel::Imcs;
        match self.header.shape {
            AreaShape::Poly => {
                if b.motion != DefMotion::G01 && !(b.motion == DefMotion::G00 && imcs_rapid) {
                    return err(AreaErrorKind::WrongMotion {
                        id,
                        shape: AreaShape::Poly,
                        found: b.motion,
                        expected: "G01",
                    });
                }
                if self.blocks >= MAX_POLY_BLOCKS {
                    return err(AreaErrorKind::TooManyBlocks { id });
                }
            }
            AreaShape::Circ => match (self.points.len(), self.circle) {
                (_, Some(_)) => return err(AreaErrorKind::ExtraBlock { id }),
                (0, None) => {
                    if b.motion != DefMotion::G01 && !(b.motion == DefMotion::G00 && imcs_rapid) {
                        return err(AreaErrorKind::WrongMotion {
                            id,
                            shape: AreaShape::Circ,
                            found: b.motion,
                            expected: "G01 (starting point)",
                        });
                    }
                }
                (_, None) => {
                    if !matches!(b.motion, DefMotion::G02 | DefMotion::G03) {
                        return err(AreaErrorKind::WrongMotion {
                            id,
                            shape: AreaShape::Circ,
                            found: b.motion,
                            expected: "G02 | G03 (full circle)",
                        });
                    }
                    let start = prev.unwrap_or(end);
                    let Some(c) = b.centre else {
                        return err(AreaErrorKind::NoCentre { id });
                    };
                    if !(c[0].is_finite() && c[1].is_finite()) {
                        return err(AreaErrorKind::NoCentre { id });
                    }
                    if dist(start, end) > POINT_EPSILON {
                        return err(AreaErrorKind::NotFullCircle { id });
                    }
                    let r = dist(start, c);
                    if r <= POINT_EPSILON {
                        return err(AreaErrorKind::ZeroRadius { id });
                    }
                    self.blocks += 1;
                    self.circle = Some((c, r));
                    self.axes = Some(axes);
                    self.plane = Some(plane);
                    return Ok(());
                }
            },
        }
        self.blocks += 1;
        self.axes = Some(axes);
        self.plane = Some(plane);
        if prev.is_none_or(|p| dist(p, end) > POINT_EPSILON) {
            self.points.push(DefPoint { p: end, at: b.at });
        }
        Ok(())
    }

    /// Close the definition (`#CONTROL AREA END`): checks closure, vertex count and
    /// self-intersection for POLY, the full circle for CIRC.
    pub fn end(self, at: Option<BlockRef>) -> Result<Area, AreaError> {
        let id = self.header.id;
        let geometry = match self.header.shape {
            AreaShape::Circ => match self.circle {
                Some((centre, radius)) => AreaGeometry::Circle { centre, radius },
                None => {
                    return Err(AreaError::new(AreaErrorKind::CircleMissing { id }, at));
                }
            },
            AreaShape::Poly => {
                let pts = &self.points;
                let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
                    return Err(AreaError::new(
                        AreaErrorKind::TooFewPoints { id, vertices: 0 },
                        at,
                    ));
                };
                if pts.len() < 2 || dist(first.p, last.p) > POINT_EPSILON {
                    return Err(AreaError::new(
                        AreaErrorKind::NotClosed {
                            id,
                            first: first.p,
                            last: last.p,
                        },
                        Some(last.at),
                    ));
                }
                // pts[i] → pts[i+1] is edge i, programmed in block pts[i+1].at.
                let n = pts.len() - 1;
                if n < 3 {
                    return Err(AreaError::new(
                        AreaErrorKind::TooFewPoints { id, vertices: n },
                        at,
                    ));
                }
                for i in 0..n {
                    for j in i + 1..n {
                        let adjacent = j == i + 1 || (i == 0 && j == n - 1);
                        let (a, b) = (pts[i].p, pts[i + 1].p);
                        let (c, d) = (pts[j].p, pts[j + 1].p);
                        let hit = if adjacent {
                            // Adjacent edges share one vertex; they must not fold back onto
                            // each other (the far end of one lying on the other).
                            let (far_i, far_j) = if j == i + 1 { (a, d) } else { (b, c) };
                            seg_dist(far_i, c, d) <= POINT_EPSILON
                                || seg_dist(far_j, a, b) <= POINT_EPSILON
                        } else {
                            segments_touch(a, b, c, d)
                        };
                        if hit {
                            return Err(AreaError::new(
                                AreaErrorKind::SelfIntersection {
                                    id,
                                    first: pts[i + 1].at,
                                    second: pts[j + 1].at,
                                },
                                Some(pts[j + 1].at),
                            ));
                        }
                    }
                }
                AreaGeometry::Polygon {
                    vertices: pts[..n].iter().map(|p| p.p).collect(),
                }
            }
        };
        Ok(Area {
            header: self.header,
            axes: self.axes.unwrap_or(AreaAxes::Main),
            plane: self.plane.unwrap_or_default(),
            geometry,
            defined_at: self.begin_at,
        })
    }
}

// ------------------------------------------------------------------------------------------
// The table and its state machine
// ------------------------------------------------------------------------------------------

/// State of one area ID (FCT-C14 Fig. 11).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AreaState {
    /// Not defined (never defined, or cleared).
    Cleared,
    /// Defined and inactive.
    Defined,
    /// Defined and monitored.
    Active,
}

/// Answers "is the current TCP inside this area?" (boundary included). Plug the exact geometry
/// module in here; closures `FnMut(&Area) -> bool` implement it, and [`AreaPoint`] is the
/// built-in for a TCP already expressed in the areas' coordinates.
pub trait TcpLocator {
    /// True if the TCP lies inside `area` or on its boundary.
    fn inside(&mut self, area: &Area) -> bool;
}

impl<F: FnMut(&Area) -> bool> TcpLocator for F {
    fn inside(&mut self, area: &Area) -> bool {
        self(area)
    }
}

impl TcpLocator for AreaPoint {
    fn inside(&mut self, area: &Area) -> bool {
        area.contains(*self)
    }
}

#[derive(Debug, Clone)]
struct Slot {
    area: Area,
    active: bool,
}

/// The control areas of one channel and their states (FCT-C14 §3, Fig. 11).
///
/// - Start-up: [`AreaTable::new`] is empty — no area is predefined (§3.1 "Time of definition").
/// - Commands: [`AreaTable::apply`] for BEGIN / END / ON / OFF / CLEAR, and
///   [`AreaTable::definition_block`] for each motion block between BEGIN and END.
/// - Lifecycle events: [`AreaTable::program_end`] (areas stay active), [`AreaTable::reset`]
///   (areas deactivated, kept).
/// - Queries: [`AreaTable::state`], [`AreaTable::area`], [`AreaTable::active`],
///   [`AreaTable::is_defining`].
///
/// Methods return the messages to report; `Err` is an error that aborts the program, `Ok`
/// carries warnings (120499).
#[derive(Debug, Clone, Default)]
pub struct AreaTable {
    slots: Vec<Slot>,
    open: Option<AreaDefinition>,
    last_selected: Vec<u32>,
}

impl AreaTable {
    /// An empty table (no predefined areas).
    pub fn new() -> Self {
        Self::default()
    }

    fn index(&self, id: u32) -> Option<usize> {
        self.slots.iter().position(|s| s.area.id() == id)
    }

    /// State of `id`.
    pub fn state(&self, id: u32) -> AreaState {
        match self.index(id) {
            None => AreaState::Cleared,
            Some(i) if self.slots[i].active => AreaState::Active,
            Some(_) => AreaState::Defined,
        }
    }

    /// The area `id`, if defined.
    pub fn area(&self, id: u32) -> Option<&Area> {
        self.index(id).map(|i| &self.slots[i].area)
    }

    /// All defined areas in definition order.
    pub fn areas(&self) -> impl Iterator<Item = &Area> {
        self.slots.iter().map(|s| &s.area)
    }

    /// The active areas in definition order.
    pub fn active(&self) -> impl Iterator<Item = &Area> {
        self.slots.iter().filter(|s| s.active).map(|s| &s.area)
    }

    /// Number of defined areas.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// No area defined.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// A definition (BEGIN without END yet) is open.
    pub fn is_defining(&self) -> bool {
        self.open.is_some()
    }

    /// The IDs a bare `OFF` would deactivate.
    pub fn last_selected(&self) -> &[u32] {
        &self.last_selected
    }

    /// Execute one `#CONTROL AREA` command at block `at`; `tcp` locates the current TCP (used
    /// by `ON` only).
    pub fn apply(
        &mut self,
        cmd: &AreaCommand,
        at: Option<BlockRef>,
        tcp: &mut impl TcpLocator,
    ) -> Result<Vec<CncMessage>, AreaError> {
        let name = match cmd {
            AreaCommand::Begin(_) => "BEGIN",
            AreaCommand::End => "END",
            AreaCommand::On(_) => "ON",
            AreaCommand::Off(_) => "OFF",
            AreaCommand::Clear(_) => "CLEAR",
        };
        let seq = |reason| {
            AreaError::new(
                AreaErrorKind::Sequence {
                    command: name,
                    reason,
                },
                at,
            )
        };
        match (cmd, self.open.is_some()) {
            (AreaCommand::End, false) => Err(seq("END without BEGIN")),
            (AreaCommand::End, true) => self.end(at).map(|()| Vec::new()),
            (AreaCommand::Begin(_), true) => {
                Err(seq("the previous definition is not closed by END"))
            }
            (_, true) => Err(seq("not allowed inside a definition, END expected")),
            (AreaCommand::Begin(h), false) => self.begin(h, at).map(|()| Vec::new()),
            (AreaCommand::On(sel), false) => self.on(*sel, at, tcp).map(|()| Vec::new()),
            (AreaCommand::Off(sel), false) => self.off(*sel, at).map(|()| Vec::new()),
            (AreaCommand::Clear(sel), false) => Ok(self.clear(*sel, at)),
        }
    }

    fn begin(&mut self, h: &AreaHeader, at: Option<BlockRef>) -> Result<(), AreaError> {
        self.admissible(h.id, at)?;
        self.open = Some(AreaDefinition::begin(h.clone(), at)?);
        Ok(())
    }

    /// May `id` be (re)defined now? (overwrite only while inactive; ≤ 20 areas)
    fn admissible(&self, id: u32, at: Option<BlockRef>) -> Result<(), AreaError> {
        match self.state(id) {
            AreaState::Active => Err(AreaError::new(AreaErrorKind::OverwriteActive { id }, at)),
            AreaState::Defined => Ok(()),
            AreaState::Cleared if self.slots.len() >= MAX_AREAS => {
                Err(AreaError::new(AreaErrorKind::TableFull { id }, at))
            }
            AreaState::Cleared => Ok(()),
        }
    }

    /// Feed one motion block of an open definition. On error the definition is abandoned (an
    /// area of the same ID defined earlier stays as it was).
    pub fn definition_block(&mut self, block: &DefBlock) -> Result<(), AreaError> {
        let Some(def) = self.open.as_mut() else {
            return Err(AreaError::new(
                AreaErrorKind::Sequence {
                    command: "BEGIN",
                    reason: "definition block without an open definition",
                },
                Some(block.at),
            ));
        };
        let r = def.block(block);
        if r.is_err() {
            self.open = None;
        }
        r
    }

    fn end(&mut self, at: Option<BlockRef>) -> Result<(), AreaError> {
        let Some(def) = self.open.take() else {
            return Err(AreaError::new(
                AreaErrorKind::Sequence {
                    command: "END",
                    reason: "END without BEGIN",
                },
                at,
            ));
        };
        let area = def.end(at)?;
        self.admissible(area.id(), at)?;
        match self.index(area.id()) {
            Some(i) => self.slots[i].area = area,
            None => self.slots.push(Slot {
                area,
                active: false,
            }),
        }
        Ok(())
    }

    fn on(
        &mut self,
        sel: Selector,
        at: Option<BlockRef>,
        tcp: &mut impl TcpLocator,
    ) -> Result<(), AreaError> {
        let targets: Vec<u32> = match sel {
            Selector::All => self.slots.iter().map(|s| s.area.id()).collect(),
            Selector::Id(id) => {
                if self.index(id).is_none() {
                    return Err(AreaError::new(AreaErrorKind::Undefined { id }, at));
                }
                vec![id]
            }
            Selector::Last => self.last_selected.clone(),
        };
        let newly: Vec<usize> = targets
            .iter()
            .filter_map(|&id| self.index(id))
            .filter(|&i| !self.slots[i].active)
            .collect();
        // Validity of the TCP against the resulting active set.
        let resulting: Vec<usize> = (0..self.slots.len())
            .filter(|i| self.slots[*i].active || newly.contains(i))
            .collect();
        let mut inside = vec![false; self.slots.len()];
        for &i in &resulting {
            inside[i] = tcp.inside(&self.slots[i].area);
        }
        let mut bad = Vec::new();
        for &i in &newly {
            let a = &self.slots[i].area;
            let wrong = match a.kind() {
                AreaKind::Prot => inside[i],
                AreaKind::Work => !resulting.iter().any(|&k| {
                    let b = &self.slots[k].area;
                    b.kind() == AreaKind::Work && b.space() == a.space() && inside[k]
                }),
            };
            if wrong {
                bad.push(a.id());
            }
        }
        if !bad.is_empty() {
            return Err(AreaError::new(AreaErrorKind::TcpInvalid { ids: bad }, at));
        }
        for i in newly {
            self.slots[i].active = true;
        }
        self.last_selected = targets;
        Ok(())
    }

    fn off(&mut self, sel: Selector, at: Option<BlockRef>) -> Result<(), AreaError> {
        match sel {
            Selector::All => self.slots.iter_mut().for_each(|s| s.active = false),
            Selector::Id(id) => {
                if let Some(i) = self.index(id) {
                    self.slots[i].active = false;
                }
            }
            Selector::Last => {
                if self.last_selected.is_empty() {
                    return Err(AreaError::new(AreaErrorKind::Undefined { id: 0 }, at));
                }
                for id in self.last_selected.clone() {
                    if let Some(i) = self.index(id) {
                        self.slots[i].active = false;
                    }
                }
            }
        }
        Ok(())
    }

    fn clear(&mut self, sel: Selector, at: Option<BlockRef>) -> Vec<CncMessage> {
        let targets: Vec<u32> = match sel {
            Selector::All => self.slots.iter().map(|s| s.area.id()).collect(),
            Selector::Id(id) => vec![id],
            Selector::Last => self.last_selected.clone(),
        };
        let mut warnings = Vec::new();
        for id in targets {
            match self.index(id) {
                None => {}
                Some(i) if self.slots[i].active => warnings.push(
                    CncMessage::warning(
                        ids::AREA_CLEAR_ACTIVE,
                        format!("control area {id} is active and cannot be cleared"),
                    )
                    .at(at),
                ),
                Some(i) => {
                    self.slots.remove(i);
                    self.last_selected.retain(|&x| x != id);
                }
            }
        }
        warnings
    }

    /// Program end (M30 / M02): areas stay defined and active (§3 notice "Program end"). A
    /// definition still open is discarded and reported.
    pub fn program_end(&mut self) -> Option<CncMessage> {
        self.open.take().map(|d| {
            AreaError::new(
                AreaErrorKind::Sequence {
                    command: "END",
                    reason: "missing at program end, definition discarded",
                },
                d.begin_at,
            )
            .message()
        })
    }

    /// Controller reset: every area is deactivated but kept (§2.1, §3 notice "Controller
    /// reset"); an open definition is discarded.
    pub fn reset(&mut self) {
        self.open = None;
        self.last_selected.clear();
        self.slots.iter_mut().for_each(|s| s.active = false);
    }
}
