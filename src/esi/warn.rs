//! Warnings of the ESI reader ([`EsiFile::warnings`](super::EsiFile::warnings)): a value the
//! file writes in a form ETG.2000 does not define, read the way the vendors' tools read it, or
//! left out where it has no reading.
//!
//! One warning per kind of problem and element: the first place in full (file, line, column,
//! element path, the object or PDO it belongs to) and how many more there are, the first
//! `MAX_ESI_WARNING_PLACES` of them with their line, column and text. At most
//! `MAX_ESI_WARNINGS` warnings per file ([`crate::limits`]); further kinds are counted in a last
//! [`Oddity::TooMany`] warning. Positions are worked out once after parsing, in one pass over
//! the text.

use std::collections::HashMap;
use std::fmt;

use crate::limits::{MAX_ESI_WARNINGS as MAX_WARNINGS, MAX_ESI_WARNING_PLACES as MAX_PLACES};

/// What was odd about a value, and what was read instead.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Oddity {
    /// hexBinary with an odd number of digits, read with a leading 0 nibble (`0` → `00`,
    /// `123` → `01 23`).
    OddHexBinary {
        /// The text.
        text: String,
        /// The bytes read.
        read: Vec<u8>,
    },
    /// Not hexBinary: the value is left out.
    NotHexBinary {
        /// The text.
        text: String,
    },
    /// A number in a form ETG.2000 does not define (`0x1A00`, `+5`, `16.0`).
    NumberForm {
        /// The text.
        text: String,
        /// The value read.
        read: i128,
    },
    /// A negative number in an unsigned field, read as its two's complement.
    TwosComplement {
        /// The text.
        text: String,
        /// The value read.
        read: i128,
    },
    /// An optional value that is not a number, or outside its field's range: left out.
    NumberLeftOut {
        /// The text.
        text: String,
        /// Why (`not a number`, `outside 0..=65535`).
        why: String,
    },
    /// A boolean in another form than `true` / `false` / `1` / `0`.
    Boolean {
        /// The text.
        text: String,
        /// The value read.
        read: bool,
    },
    /// An `Access` text other than `ro` / `rw` / `wo`: read as not given.
    Access {
        /// The text.
        text: String,
    },
    /// A `PdoMapping` text other than `R` / `T` / `RT` / `TR`: read as not given (not
    /// mappable).
    PdoMapping {
        /// The text.
        text: String,
    },
    /// An element that cannot be read and is left out (the reason says which and why).
    LeftOut {
        /// Why.
        why: String,
    },
    /// More kinds of problems than [`crate::limits::MAX_ESI_WARNINGS`]: this many more places, not
    /// shown.
    TooMany {
        /// Places not shown.
        count: usize,
    },
}

impl Oddity {
    fn key(&self) -> u8 {
        match self {
            Oddity::OddHexBinary { .. } => 0,
            Oddity::NotHexBinary { .. } => 1,
            Oddity::NumberForm { .. } => 2,
            Oddity::TwosComplement { .. } => 3,
            Oddity::NumberLeftOut { .. } => 4,
            Oddity::Boolean { .. } => 5,
            Oddity::Access { .. } => 6,
            Oddity::PdoMapping { .. } => 7,
            Oddity::LeftOut { .. } => 8,
            Oddity::TooMany { .. } => 9,
        }
    }

    /// The text the file has, if the oddity is about one.
    pub fn text(&self) -> Option<&str> {
        match self {
            Oddity::OddHexBinary { text, .. }
            | Oddity::NotHexBinary { text }
            | Oddity::NumberForm { text, .. }
            | Oddity::TwosComplement { text, .. }
            | Oddity::NumberLeftOut { text, .. }
            | Oddity::Boolean { text, .. }
            | Oddity::Access { text }
            | Oddity::PdoMapping { text } => Some(text),
            Oddity::LeftOut { .. } | Oddity::TooMany { .. } => None,
        }
    }
}

fn hex(bytes: &[u8]) -> String {
    let shown: Vec<String> = bytes.iter().take(16).map(|b| format!("{b:02X}")).collect();
    let more = if bytes.len() > 16 { " …" } else { "" };
    format!("{}{more}", shown.join(" "))
}

impl fmt::Display for Oddity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Oddity::OddHexBinary { text, read } => write!(
                f,
                "odd-length hexBinary {text:?}: read with a leading 0 nibble as bytes {}",
                hex(read)
            ),
            Oddity::NotHexBinary { text } => write!(f, "not hexBinary {text:?}: left out"),
            Oddity::NumberForm { text, read } => {
                write!(
                    f,
                    "number {text:?} is not #x hex or decimal: read as {read}"
                )
            }
            Oddity::TwosComplement { text, read } => write!(
                f,
                "negative {text:?} in an unsigned field: read as its two's complement {read:#X}"
            ),
            Oddity::NumberLeftOut { text, why } => write!(f, "{text:?} {why}: left out"),
            Oddity::Boolean { text, read } => {
                write!(f, "boolean {text:?} is not true/false/1/0: read as {read}")
            }
            Oddity::Access { text } => write!(
                f,
                "Access {text:?} is not ro/rw/wo: read as not given (the reader's default applies)"
            ),
            Oddity::PdoMapping { text } => write!(
                f,
                "PdoMapping {text:?} is not R/T/RT/TR: read as not given (not PDO-mappable)"
            ),
            Oddity::LeftOut { why } => write!(f, "{why}"),
            Oddity::TooMany { count } => write!(
                f,
                "{count} more odd values of other kinds not listed (at most {MAX_WARNINGS} \
                 warnings per file)"
            ),
        }
    }
}

/// One further place of the same problem.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Place {
    /// 1-based line.
    pub line: u32,
    /// 1-based column (characters).
    pub column: u32,
    /// The object / PDO / device it belongs to, if any (see [`EsiWarning::subject`]).
    pub subject: Option<String>,
    /// The text found there, if the problem is about a text.
    pub text: Option<String>,
}

/// A value read another way than written, or left out (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EsiWarning {
    /// File name.
    pub file: String,
    /// 1-based line of the first place.
    pub line: u32,
    /// 1-based column (characters).
    pub column: u32,
    /// Element path of the first place (`…/Object[24]/Info/SubItem[2]/Info/DefaultData`); an
    /// attribute ends in `/@Name`.
    pub path: String,
    /// What the value belongs to: device, object (`object #x2001 SubItem[2]`) or PDO, as
    /// written in the file.
    pub subject: Option<String>,
    /// What was odd and what was read.
    pub oddity: Oddity,
    /// Further places of the same kind of problem in the same element (at most
    /// [`crate::limits::MAX_ESI_WARNING_PLACES`]).
    pub more: Vec<Place>,
    /// How many further places there are in all (≥ `more.len()`).
    pub more_count: usize,
}

impl fmt::Display for EsiWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: {}: ",
            self.file, self.line, self.column, self.path
        )?;
        if let Some(s) = &self.subject {
            write!(f, "{s}: ")?;
        }
        write!(f, "{}", self.oddity)?;
        if self.more_count > 0 {
            let places: Vec<String> = self
                .more
                .iter()
                .map(|p| {
                    let mut s = format!("{}:{}", p.line, p.column);
                    let what: Vec<String> = p
                        .subject
                        .iter()
                        .cloned()
                        .chain(p.text.iter().map(|t| format!("{t:?}")))
                        .collect();
                    if !what.is_empty() {
                        s.push_str(&format!(" ({})", what.join(" ")));
                    }
                    s
                })
                .collect();
            let rest = self.more_count - self.more.len();
            write!(
                f,
                "; {} more like it at {}{}",
                self.more_count,
                places.join(", "),
                if rest > 0 {
                    format!(" and {rest} more")
                } else {
                    String::new()
                }
            )?;
        }
        Ok(())
    }
}

/// The warnings of one parse, before their positions are known (byte offsets).
#[derive(Debug, Default)]
pub(crate) struct Collector {
    warnings: Vec<Pending>,
    by_key: HashMap<(u8, String), usize>,
    not_listed: usize,
}

#[derive(Debug)]
struct Pending {
    offset: usize,
    path: String,
    subject: Option<String>,
    oddity: Oddity,
    more: Vec<(usize, Option<String>, Option<String>)>,
    more_count: usize,
}

/// What [`Collector::add`] needs from the place, computed only when kept.
pub(crate) struct Where<'a> {
    /// Byte offset in the text.
    pub offset: usize,
    /// Element (or `@attribute`) name: problems of one kind in one element name are grouped.
    pub name: &'a str,
    /// Element path, computed on demand.
    pub path: &'a dyn Fn() -> String,
    /// Subject, computed on demand.
    pub subject: &'a dyn Fn() -> Option<String>,
}

impl Collector {
    /// Record one occurrence.
    pub(crate) fn add(&mut self, at: Where, oddity: Oddity) {
        let key = (oddity.key(), at.name.to_string());
        if let Some(&i) = self.by_key.get(&key) {
            let w = &mut self.warnings[i];
            w.more_count += 1;
            if w.more.len() < MAX_PLACES {
                let text = oddity.text().map(str::to_string);
                w.more.push((at.offset, (at.subject)(), text));
            }
            return;
        }
        if self.warnings.len() >= MAX_WARNINGS {
            self.not_listed += 1;
            return;
        }
        self.by_key.insert(key, self.warnings.len());
        self.warnings.push(Pending {
            offset: at.offset,
            path: (at.path)(),
            subject: (at.subject)(),
            oddity,
            more: Vec::new(),
            more_count: 0,
        });
    }

    /// The warnings with their positions in `text` (one pass over it).
    pub(crate) fn finish(self, text: &str, file: &str) -> Vec<EsiWarning> {
        let mut offsets: Vec<usize> = self
            .warnings
            .iter()
            .flat_map(|w| std::iter::once(w.offset).chain(w.more.iter().map(|m| m.0)))
            .collect();
        offsets.sort_unstable();
        offsets.dedup();
        let positions = positions(text, &offsets);
        let pos = |o: usize| {
            offsets
                .binary_search(&o)
                .map(|i| positions[i])
                .unwrap_or((0, 0))
        };
        let mut out: Vec<EsiWarning> = self
            .warnings
            .into_iter()
            .map(|w| {
                let (line, column) = pos(w.offset);
                EsiWarning {
                    file: file.to_string(),
                    line,
                    column,
                    path: w.path,
                    subject: w.subject,
                    oddity: w.oddity,
                    more: w
                        .more
                        .into_iter()
                        .map(|(o, subject, text)| {
                            let (line, column) = pos(o);
                            Place {
                                line,
                                column,
                                subject,
                                text,
                            }
                        })
                        .collect(),
                    more_count: w.more_count,
                }
            })
            .collect();
        if self.not_listed > 0 {
            out.push(EsiWarning {
                file: file.to_string(),
                line: 1,
                column: 1,
                path: "EtherCATInfo".to_string(),
                subject: None,
                oddity: Oddity::TooMany {
                    count: self.not_listed,
                },
                more: Vec::new(),
                more_count: 0,
            });
        }
        out
    }
}

/// 1-based (line, column in characters) of each of the sorted byte `offsets` in `text`.
fn positions(text: &str, offsets: &[usize]) -> Vec<(u32, u32)> {
    let mut out = Vec::with_capacity(offsets.len());
    let (mut line, mut col) = (1u32, 1u32);
    let mut chars = text.char_indices().peekable();
    for &o in offsets {
        while let Some(&(i, c)) = chars.peek() {
            if i >= o {
                break;
            }
            if c == '\n' {
                line = line.saturating_add(1);
                col = 1;
            } else {
                col = col.saturating_add(1);
            }
            chars.next();
        }
        out.push((line, col));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_in_one_pass() {
        let t = "ab\ncdé\nf";
        // offsets: 0 'a', 3 'c', 5 'é' (2 bytes), 7 '\n', 8 'f'
        assert_eq!(
            positions(t, &[0, 3, 5, 8]),
            vec![(1, 1), (2, 1), (2, 3), (3, 1)]
        );
    }

    #[test]
    fn grouping_and_bounds() {
        let mut c = Collector::default();
        let path = || "A/B".to_string();
        let subject = || Some("object #x1".to_string());
        for i in 0..20 {
            c.add(
                Where {
                    offset: i,
                    name: "DefaultData",
                    path: &path,
                    subject: &subject,
                },
                Oddity::OddHexBinary {
                    text: "0".into(),
                    read: vec![0],
                },
            );
        }
        for i in 0..(MAX_WARNINGS + 3) {
            let name = format!("E{i}");
            c.add(
                Where {
                    offset: 0,
                    name: &name,
                    path: &path,
                    subject: &subject,
                },
                Oddity::Access { text: "x".into() },
            );
        }
        let text = "x".repeat(30);
        let w = c.finish(&text, "f.xml");
        assert_eq!(w.len(), MAX_WARNINGS + 1);
        assert_eq!(w[0].more_count, 19);
        assert_eq!(w[0].more.len(), MAX_PLACES);
        assert_eq!((w[0].more[0].line, w[0].more[0].column), (1, 2));
        assert_eq!(w[MAX_WARNINGS].oddity, Oddity::TooMany { count: 4 });
        let s = w[0].to_string();
        assert!(
            s.starts_with("f.xml:1:1: A/B: object #x1: odd-length hexBinary \"0\""),
            "{s}"
        );
        assert!(
            s.contains("; 19 more like it at 1:2 (object #x1 \"0\")"),
            "{s}"
        );
        assert!(s.ends_with(" and 11 more"), "{s}");
    }
}
