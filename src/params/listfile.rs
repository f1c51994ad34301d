//! ISG parameter-list text: one assignment per line, `key value` (the form of the seeds'
//! parameterisation examples, e.g. FCT-C4 §3 `kenngr.measure.signal PLC`, FCT-C4 §8.2.1
//! `meas_error_no_signal 1`); `key = value` is tolerated.
//!
//! Keys are IDs or name paths. Comments: lines starting with `#`, `;` or `(`, and trailing
//! `# …`, `; …` or `( … )` outside quotes. Blank lines are ignored. After the last line the
//! cross-parameter ranges are checked ([`ParamSet::check_cross`]).

use super::registry::{
    find, suggestion_text, unknown_parameter, Origin, ParamError, ParamSet, Scope,
};

/// Parse a parameter list of the given scope into a new set.
pub fn parse_list(text: &str, file: &str, scope: Scope) -> Result<ParamSet, ParamError> {
    let mut set = ParamSet::new(scope);
    apply_list(&mut set, text, file)?;
    Ok(set)
}

/// Apply a parameter list to an existing set (later lines override earlier values), then run
/// the cross checks. Errors name `file`, the 1-based line and the key.
pub fn apply_list(set: &mut ParamSet, text: &str, file: &str) -> Result<(), ParamError> {
    for (index, line) in text.lines().enumerate() {
        let origin = Origin::new(file, index + 1);
        let Some((key, value)) = split_line(line) else {
            continue;
        };
        if value.is_empty() {
            return Err(ParamError::Config {
                origin,
                message: format!("'{key}' has no value; expected '{key} <value>'"),
            });
        }
        if find(key).is_none() {
            return Err(unknown_key(key, value, &origin));
        }
        set.set(key, value, &origin)?;
    }
    set.check_cross(&Origin::new(file, 0))
}

/// Split a line into key and value; `None` for blank and comment lines.
fn split_line(line: &str) -> Option<(&str, &str)> {
    let line = strip_comment(line).trim();
    if line.is_empty() {
        return None;
    }
    let end = line
        .find(|c: char| c.is_whitespace() || c == '=')
        .unwrap_or(line.len());
    let (key, rest) = line.split_at(end);
    let rest = rest.trim_start();
    let rest = rest.strip_prefix('=').unwrap_or(rest).trim();
    Some((key, rest))
}

/// Cut the line at the first `#`, `;` or `(` that is not inside quotes.
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (Some(q), _) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '#' | ';' | '(') => return &line[..i],
            _ => {}
        }
    }
    line
}

/// Unknown key. If the value has several words and `key_word` is known (the seeds' PDF text lost
/// underscores: `kenngr.hub messtaster 100000`), suggest that; else the closest known key.
fn unknown_key(key: &str, value: &str, origin: &Origin) -> ParamError {
    if let Some(first) = value
        .split_whitespace()
        .next()
        .filter(|_| value.split_whitespace().nth(1).is_some())
    {
        let joined = format!("{key}_{first}");
        if let Some(def) = find(&joined) {
            return ParamError::UnknownParameter {
                origin: origin.clone(),
                key: key.to_string(),
                suggestion: Some(suggestion_text(&joined, def)),
            };
        }
    }
    unknown_parameter(key, origin)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_forms() {
        assert_eq!(
            split_line("kenngr.swe_neg  -5"),
            Some(("kenngr.swe_neg", "-5"))
        );
        assert_eq!(
            split_line("kenngr.swe_neg = -5 # c"),
            Some(("kenngr.swe_neg", "-5"))
        );
        assert_eq!(
            split_line("kenngr.swe_neg=-5"),
            Some(("kenngr.swe_neg", "-5"))
        );
        assert_eq!(split_line("messtyp\t3 ( comment )"), Some(("messtyp", "3")));
        assert_eq!(split_line("  # only a comment"), None);
        assert_eq!(split_line("; also"), None);
        assert_eq!(split_line("(and this)"), None);
        assert_eq!(split_line(""), None);
        assert_eq!(
            split_line("kenngr.measure.signal \"PLC;x\" ; c"),
            Some(("kenngr.measure.signal", "\"PLC;x\""))
        );
    }
}
