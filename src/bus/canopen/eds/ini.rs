//! The INI layer of an EDS / DCF (CiA 306 §4): sections, `key=value` lines, comments, read
//! leniently — a line that is not INI, a key before the first section, a section header
//! without `]`, a repeated section or key is a warning ([`Parser::soft`]) and the rest of the
//! file is read.
//!
//! Repeated sections and keys: the first counts (a later repeat is ignored), as the Windows
//! profile API (`GetPrivateProfileString`) reads an INI file; python-canopen's
//! `RawConfigParser` refuses the file instead.

use std::collections::HashMap;

use super::parse::Parser;
use super::{EdsError, EdsErrorKind};

#[derive(Debug)]
pub(super) struct Key<'a> {
    pub name: &'a str,
    pub value: &'a str,
    pub line: usize,
    pub column: usize,
}

#[derive(Debug)]
pub(super) struct Section<'a> {
    pub name: &'a str,
    pub line: usize,
    pub keys: Vec<Key<'a>>,
    /// Lower-case key name → position in `keys`.
    by_name: HashMap<String, usize>,
}

impl<'a> Section<'a> {
    pub fn get(&self, name: &str) -> Option<&Key<'a>> {
        self.by_name
            .get(&name.to_ascii_lowercase())
            .and_then(|&i| self.keys.get(i))
    }
}

/// Sections of `text` in file order (a leading byte-order mark is skipped).
pub(super) fn lex<'a>(text: &'a str, p: &mut Parser) -> Result<Vec<Section<'a>>, EdsError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut sections: Vec<Section<'a>> = Vec::new();
    let mut seen: HashMap<String, usize> = HashMap::new();
    // Keys go to the last section unless it is ignored (a repeated or unreadable header).
    let mut ignoring = false;
    for (i, raw_line) in text.lines().enumerate() {
        let line_no = i + 1;
        let lead = raw_line.len() - raw_line.trim_start().len();
        let line = raw_line.trim();
        if line.is_empty() || line.starts_with(';') || line.starts_with('#') {
            continue;
        }
        if let Some(rest) = line.strip_prefix('[') {
            let name = match rest.strip_suffix(']') {
                Some(name) => name.trim(),
                None => {
                    let name = rest.trim();
                    p.soft(
                        p.err(
                            EdsErrorKind::Syntax,
                            Some(line_no),
                            None,
                            None,
                            None,
                            "section header without closing `]`",
                        ),
                        None,
                        Some(format!("read as [{name}]")),
                    )?;
                    name
                }
            };
            if name.is_empty() || name.contains(['[', ']']) {
                p.soft(
                    p.err(
                        EdsErrorKind::Syntax,
                        Some(line_no),
                        None,
                        None,
                        None,
                        format!("bad section header {line:?}"),
                    ),
                    None,
                    Some("the section and its keys are ignored".into()),
                )?;
                ignoring = true;
                continue;
            }
            let lower = name.to_ascii_lowercase();
            if let Some(first) = seen.get(&lower) {
                p.soft(
                    p.err(
                        EdsErrorKind::DuplicateSection,
                        Some(line_no),
                        Some(name),
                        None,
                        None,
                        format!("duplicate section (first at line {first})"),
                    ),
                    None,
                    Some("this one is ignored, the first counts".into()),
                )?;
                ignoring = true;
                continue;
            }
            ignoring = false;
            seen.insert(lower, line_no);
            sections.push(Section {
                name,
                line: line_no,
                keys: Vec::new(),
                by_name: HashMap::new(),
            });
            continue;
        }
        if ignoring {
            continue;
        }
        let Some((key, value)) = line.split_once('=') else {
            let section = sections.last().map(|s| s.name);
            p.soft(
                p.err(
                    EdsErrorKind::Syntax,
                    Some(line_no),
                    section,
                    None,
                    None,
                    format!("expected `key=value`, got {line:?}"),
                ),
                None,
                Some("the line is ignored".into()),
            )?;
            continue;
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
            p.soft(
                p.err(
                    EdsErrorKind::KeyOutsideSection,
                    Some(line_no),
                    None,
                    Some(key_name),
                    None,
                    "key before the first section header",
                ),
                None,
                Some("ignored".into()),
            )?;
            continue;
        };
        if key_name.is_empty() {
            let e = p.err(
                EdsErrorKind::Syntax,
                Some(line_no),
                Some(section.name),
                None,
                None,
                "empty key name",
            );
            p.soft(e, None, Some("the line is ignored".into()))?;
            continue;
        }
        let lower = key_name.to_ascii_lowercase();
        if let Some(first) = section.get(&lower) {
            let e = p.err(
                EdsErrorKind::DuplicateKey,
                Some(line_no),
                Some(section.name),
                Some(key_name),
                None,
                format!("duplicate key (first at line {})", first.line),
            );
            p.soft(
                e,
                None,
                Some("this value is ignored, the first counts".into()),
            )?;
            continue;
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
