//! Warnings of a lenient read ([`EdsWarning`]): what was odd in the file, where, and what the
//! reader used instead; identical problems folded into one warning with a count.

use std::collections::HashMap;
use std::fmt;

use super::{EdsError, EdsErrorKind};

/// How many further places a folded warning names (the rest is a count).
pub const PLACES_SHOWN: usize = 3;

/// Another place in the file with the same problem as a folded [`EdsWarning`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Place {
    /// 1-based line.
    pub line: Option<u32>,
    /// Section name as written.
    pub section: Option<String>,
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.section, self.line) {
            (Some(s), Some(l)) => write!(f, "[{s}] line {l}"),
            (Some(s), None) => write!(f, "[{s}]"),
            (None, Some(l)) => write!(f, "line {l}"),
            (None, None) => f.write_str("the file"),
        }
    }
}

/// Something odd in an EDS / DCF that the lenient reader read anyway (CiA 306 files as vendors
/// write them): the problem with its position, what is used instead, and how many other places
/// have the same problem.
///
/// Displayed as `file:line: [section] key: problem; used (and N more like it: [s] line l, …)`
/// (the parts that do not apply are left out). With [`super::ParseOptions::strict`] the first
/// one is the parse error instead ([`EdsWarning::into_error`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EdsWarning {
    /// File name as given to the parser.
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
    /// The object (index, sub-index) the problem belongs to, if any.
    pub object: Option<(u16, u8)>,
    /// The problem, e.g. `65536 is out of range for Unsigned16`.
    pub message: String,
    /// What the reader used instead, e.g. `read as 65535, the largest Unsigned16`; `None`
    /// where nothing replaces it (an object-list defect).
    pub used: Option<String>,
    /// Further places with the same problem and the same replacement (at most
    /// [`PLACES_SHOWN`] kept; [`more`](Self::more) counts them all).
    pub others: Vec<Place>,
    /// Number of further places with the same problem.
    pub more: usize,
}

impl EdsWarning {
    /// A warning from an error-shaped problem and what is used instead.
    pub fn new(problem: EdsError, object: Option<(u16, u8)>, used: Option<String>) -> Self {
        EdsWarning {
            file: problem.file,
            line: problem.line,
            column: problem.column,
            section: problem.section,
            key: problem.key,
            kind: problem.kind,
            object,
            message: problem.message,
            used,
            others: Vec::new(),
            more: 0,
        }
    }

    /// The problem as a parse error (strict mode), without the replacement.
    pub fn into_error(self) -> EdsError {
        EdsError {
            file: self.file,
            line: self.line,
            column: self.column,
            section: self.section,
            key: self.key,
            kind: self.kind,
            message: self.message,
        }
    }

    /// Places with this problem: this one and every further one.
    pub fn count(&self) -> usize {
        1 + self.more
    }
}

impl fmt::Display for EdsWarning {
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
        write!(f, " {}", self.message)?;
        if let Some(used) = &self.used {
            write!(f, "; {used}")?;
        }
        if self.more > 0 {
            let places: Vec<String> = self.others.iter().map(ToString::to_string).collect();
            let rest = self.more - self.others.len();
            write!(
                f,
                " (and {} more like it: {}{})",
                self.more,
                places.join(", "),
                if rest > 0 {
                    format!(", … {rest} more")
                } else {
                    String::new()
                }
            )?;
        }
        Ok(())
    }
}

/// Fold warnings with the same problem, replacement and key into the first of them, keeping
/// the order of first occurrence (linear in the number of warnings: a file of many distinct
/// problems does not make this quadratic).
pub fn fold(warnings: Vec<EdsWarning>) -> Vec<EdsWarning> {
    type Key = (EdsErrorKind, Option<String>, String, Option<String>);
    let mut out: Vec<EdsWarning> = Vec::new();
    let mut first: HashMap<Key, usize> = HashMap::new();
    for w in warnings {
        let key: Key = (
            w.kind,
            w.key.as_ref().map(|k| k.to_ascii_lowercase()),
            w.message.clone(),
            w.used.clone(),
        );
        match first.get(&key) {
            Some(&i) => {
                let f = &mut out[i];
                f.more += 1;
                if f.others.len() < PLACES_SHOWN {
                    f.others.push(Place {
                        line: w.line,
                        section: w.section,
                    });
                }
            }
            None => {
                first.insert(key, out.len());
                out.push(w);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn w(line: u32, section: &str, message: &str) -> EdsWarning {
        EdsWarning::new(
            EdsError {
                file: "f.eds".into(),
                line: Some(line),
                column: Some(11),
                section: Some(section.into()),
                key: Some("HighLimit".into()),
                kind: EdsErrorKind::OutOfRange,
                message: message.into(),
            },
            None,
            Some("read as 65535".into()),
        )
    }

    #[test]
    fn identical_problems_fold_into_one_warning_with_a_count() {
        let mut all = vec![w(10, "2023", "65536 is out of range for Unsigned16")];
        for i in 0..5 {
            all.push(w(20 + i, "2025", "65536 is out of range for Unsigned16"));
        }
        all.push(w(99, "2030", "70000 is out of range for Unsigned16"));
        let folded = fold(all);
        assert_eq!(folded.len(), 2);
        assert_eq!(folded[0].count(), 6);
        assert_eq!(
            folded[0].to_string(),
            "f.eds:10: [2023] HighLimit: 65536 is out of range for Unsigned16; read as 65535 \
             (and 5 more like it: [2025] line 20, [2025] line 21, [2025] line 22, … 2 more)"
        );
        assert_eq!(
            folded[1].to_string(),
            "f.eds:99: [2030] HighLimit: 70000 is out of range for Unsigned16; read as 65535"
        );
    }
}
