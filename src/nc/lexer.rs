//! NC lexer: splits the program text into logical lines (blocks) and scans tokens.
//!
//! Two layers:
//!
//! 1. [`logical_lines`] turns the source into [`LogicalLine`]s: comments are removed, `\`
//!    continuations are joined, blank / comment-only lines are dropped. Every remaining character
//!    keeps its [`Span`] so that errors name the physical line and column.
//! 2. [`Cursor`] scans one logical line. DIN 66025 words are context dependent (`G01X10` has no
//!    separators, but `ABS[…]` and `V.A.ABS.X` are identifiers), so the parser drives the cursor
//!    with character-level primitives for address words and [`Cursor::next_token`] for
//!    expressions and `#` command keywords.
//!
//! Comment rules (FCT-A2 §3.1 `( .... )` lines, FCT-A2 §3.3 `;neg. Software limit …`):
//! `;` comments to the end of the line; `( … )` is a comment outside `[ … ]` and must close on the
//! same line; inside `[ … ]` parentheses group. Neither is recognised inside a string `"…"`.
//!
//! Continuation (FCT-C4 §2 `%Independent_measurement_path`): a `\` that is the last non-blank
//! character before a comment or the end of the line joins the next line to the block. A line that
//! ends inside an open `[` is continued as well, because the FCT-C4 §5 examples (meas1–meas4)
//! print long `#MSG SYN[…]` blocks over two lines without a `\`.
//! A `\` followed by more text on its line is not a continuation and stays in the text where it
//! is; the parser rejects it, except directly in front of `#` (FCT-C4 §4 `N50 \#CS ON[…]`).
//!
//! Length: a line, and a block joined from continued lines, may hold at most
//! [`MAX_NC_LINE_CHARS`] characters; a longer one is an error naming its line.
//!
//! Documentation placeholders: a line that consists only of `.`, `…` or `:` characters (the
//! seeds write `...` and `:` for "more blocks here", e.g. FCT-A2 §3.3, FCT-C14 §4) is skipped
//! like a blank line.

use super::ast::{Span, VarRef};
use super::parser::ParseError;
use crate::limits::MAX_NC_LINE_CHARS;

/// One source character with its position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LChar {
    /// The character.
    pub ch: char,
    /// Its position in the source (1-based line and column).
    pub span: Span,
}

/// One block's worth of source text with comments removed (comments become a single blank).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogicalLine {
    /// Characters of the block, leading and trailing blanks removed.
    pub chars: Vec<LChar>,
    /// Position just after the last character of the block (used for "found end of block").
    pub end: Span,
}

impl LogicalLine {
    /// Position of the first character (where the block starts).
    pub fn start(&self) -> Span {
        self.chars.first().map_or(self.end, |c| c.span)
    }
}

fn err(span: Span, message: impl Into<String>) -> ParseError {
    ParseError {
        line: span.line,
        col: span.col,
        message: message.into(),
    }
}

fn to_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// True for a line made only of documentation placeholders (`...`, `…`, `:`).
fn is_placeholder(chars: &[LChar]) -> bool {
    !chars.is_empty()
        && chars
            .iter()
            .all(|c| c.ch.is_whitespace() || matches!(c.ch, '.' | '…' | ':'))
}

/// Split `src` into logical lines (see the module documentation for the rules).
///
/// Errors: a `(` comment that does not close on its line, a string that does not close on its
/// line.
pub fn logical_lines(src: &str) -> Result<Vec<LogicalLine>, ParseError> {
    split(src, 0)
}

/// Like [`logical_lines`], but for a bare expression: the text is treated as if it stood inside
/// `[ … ]`, so `(` groups instead of starting a comment and all lines join into one.
pub fn expression_lines(src: &str) -> Result<Vec<LogicalLine>, ParseError> {
    split(src, 1)
}

fn split(src: &str, base_depth: usize) -> Result<Vec<LogicalLine>, ParseError> {
    let mut out = Vec::new();
    split_each(src, base_depth, &mut |line| {
        out.push(line);
        Ok(())
    })?;
    Ok(out)
}

/// [`logical_lines`] one line at a time: `each` gets every logical line in order, as soon as it
/// is complete, so a caller that parses as it goes never holds the character vectors of the
/// whole program (12 bytes per source character). Stops at the first error of `each` or of the
/// lexer.
pub fn for_each_logical_line(
    src: &str,
    each: &mut dyn FnMut(LogicalLine) -> Result<(), ParseError>,
) -> Result<(), ParseError> {
    split_each(src, 0, each)
}

fn split_each(
    src: &str,
    base_depth: usize,
    out: &mut dyn FnMut(LogicalLine) -> Result<(), ParseError>,
) -> Result<(), ParseError> {
    let mut cur: Vec<LChar> = Vec::new();
    let mut cur_end = Span { line: 1, col: 1 };
    let mut depth: usize = base_depth;

    for (idx, raw) in src.split('\n').enumerate() {
        let line_no = to_u32(idx + 1);
        let raw = raw.strip_suffix('\r').unwrap_or(raw);
        // A line longer than the cap is refused before its characters are collected (a
        // character is at least one byte, so the byte length bounds the count from above).
        if raw.len() > MAX_NC_LINE_CHARS {
            let n = raw.chars().count();
            if n > MAX_NC_LINE_CHARS {
                return Err(err(
                    Span {
                        line: line_no,
                        col: 1,
                    },
                    format!(
                        "line {line_no} has {n} characters, more than the limit of \
                         {MAX_NC_LINE_CHARS} characters of one NC line (see docs/limits.md)"
                    ),
                ));
            }
        }
        let chars: Vec<char> = raw.chars().collect();
        let at = |i: usize| Span {
            line: line_no,
            col: to_u32(i + 1),
        };
        let mut line_out: Vec<LChar> = Vec::new();
        // A `\` not yet known to be a continuation: its position and where it goes in
        // `line_out` (before any blanks / comments that follow it).
        let mut pending_backslash: Option<(Span, usize)> = None;
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if c.is_whitespace() {
                line_out.push(LChar {
                    ch: ' ',
                    span: at(i),
                });
                i += 1;
                continue;
            }
            if c == ';' {
                break;
            }
            if c == '(' && depth == 0 {
                let close = chars[i + 1..].iter().position(|&d| d == ')');
                match close {
                    Some(k) => {
                        line_out.push(LChar {
                            ch: ' ',
                            span: at(i),
                        });
                        i += k + 2;
                        continue;
                    }
                    None => {
                        return Err(err(
                            at(i),
                            "comment '(' is not closed on this line: expected ')' \
                             (comments cannot span lines)",
                        ))
                    }
                }
            }
            // A real (non-blank, non-comment) character: a `\` seen before it was not a
            // continuation after all and stays in the text where it was (the parser reports it,
            // or reads `\#` as `#`).
            if let Some((span, at_index)) = pending_backslash.take() {
                line_out.insert(at_index, LChar { ch: '\\', span });
            }
            match c {
                '\\' => {
                    pending_backslash = Some((at(i), line_out.len()));
                    i += 1;
                }
                '"' => {
                    let open = i;
                    line_out.push(LChar { ch: c, span: at(i) });
                    i += 1;
                    let mut closed = false;
                    while i < chars.len() {
                        let d = chars[i];
                        line_out.push(LChar { ch: d, span: at(i) });
                        i += 1;
                        if d == '\\' && i < chars.len() {
                            line_out.push(LChar {
                                ch: chars[i],
                                span: at(i),
                            });
                            i += 1;
                        } else if d == '"' {
                            closed = true;
                            break;
                        }
                    }
                    if !closed {
                        return Err(err(
                            at(open),
                            "string is not closed on this line: expected '\"'",
                        ));
                    }
                }
                '[' => {
                    depth += 1;
                    line_out.push(LChar { ch: c, span: at(i) });
                    i += 1;
                }
                ']' => {
                    depth = depth.saturating_sub(1).max(base_depth);
                    line_out.push(LChar { ch: c, span: at(i) });
                    i += 1;
                }
                _ => {
                    line_out.push(LChar { ch: c, span: at(i) });
                    i += 1;
                }
            }
        }
        if is_placeholder(&line_out) && cur.is_empty() {
            line_out.clear();
        }
        let continued = pending_backslash.is_some() || depth > 0;
        if !line_out.is_empty() {
            if !cur.is_empty() {
                // Separate joined lines like a blank would.
                cur.push(LChar {
                    ch: ' ',
                    span: line_out[0].span,
                });
            }
            cur.append(&mut line_out);
            if cur.len() > MAX_NC_LINE_CHARS {
                let start = cur.first().map_or(at(0), |c| c.span);
                return Err(err(
                    start,
                    format!(
                        "the block starting at line {} is longer than the limit of \
                         {MAX_NC_LINE_CHARS} characters of one NC block when joined with its \
                         continuation lines up to line {line_no} (is a '[' not closed? see \
                         docs/limits.md)",
                        start.line
                    ),
                ));
            }
        }
        cur_end = at(chars.len());
        if !continued {
            flush(&mut cur, cur_end, out)?;
            depth = base_depth;
        }
    }
    flush(&mut cur, cur_end, out)
}

fn flush(
    cur: &mut Vec<LChar>,
    end: Span,
    out: &mut dyn FnMut(LogicalLine) -> Result<(), ParseError>,
) -> Result<(), ParseError> {
    let mut chars = std::mem::take(cur);
    while chars.last().is_some_and(|c| c.ch == ' ') {
        chars.pop();
    }
    let first = chars
        .iter()
        .position(|c| c.ch != ' ')
        .unwrap_or(chars.len());
    chars.drain(..first);
    if chars.is_empty() {
        return Ok(());
    }
    out(LogicalLine { chars, end })
}

/// An expression-level token (see [`Cursor::next_token`]).
#[derive(Debug, Clone, PartialEq)]
pub enum TokenKind {
    /// Unsigned number literal (`10`, `1.5`, `.5`, `5.`).
    Num(f64),
    /// String literal with `\"` and `\\` unescaped.
    Str(String),
    /// Identifier `[A-Za-z_][A-Za-z0-9_]*`, upper-cased (function names, keywords).
    Ident(String),
    /// Variable `V.…` (segments upper-cased).
    Var(VarRef),
    /// Any other single character (`[ ] ( ) , + - * / =` …).
    Punct(char),
    /// End of the logical line.
    End,
}

impl TokenKind {
    /// Short description for error messages ("found …").
    pub fn describe(&self) -> String {
        match self {
            TokenKind::Num(n) => format!("number {n}"),
            TokenKind::Str(_) => "a string".to_string(),
            TokenKind::Ident(s) => format!("'{s}'"),
            TokenKind::Var(v) => format!("variable {}", v.name()),
            TokenKind::Punct(c) => format!("'{c}'"),
            TokenKind::End => "end of block".to_string(),
        }
    }
}

/// A token with the position of its first character.
#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    /// What was scanned.
    pub kind: TokenKind,
    /// Where it starts.
    pub span: Span,
}

/// Scanner over one [`LogicalLine`].
#[derive(Debug, Clone)]
pub struct Cursor<'a> {
    chars: &'a [LChar],
    pos: usize,
    end: Span,
}

fn is_ident_start(c: char) -> bool {
    c.is_ascii_alphabetic() || c == '_'
}

fn is_ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of `line`.
    pub fn new(line: &'a LogicalLine) -> Self {
        Cursor {
            chars: &line.chars,
            pos: 0,
            end: line.end,
        }
    }

    /// The next character, if any.
    pub fn peek(&self) -> Option<char> {
        self.peek_at(0)
    }

    /// The character `n` places ahead, if any.
    pub fn peek_at(&self, n: usize) -> Option<char> {
        self.chars.get(self.pos.saturating_add(n)).map(|c| c.ch)
    }

    /// Consume and return the next character.
    pub fn bump(&mut self) -> Option<LChar> {
        let c = self.chars.get(self.pos).copied();
        if c.is_some() {
            self.pos += 1;
        }
        c
    }

    /// Position of the next character (or the end of the block).
    pub fn span(&self) -> Span {
        self.chars.get(self.pos).map_or(self.end, |c| c.span)
    }

    /// The rest of the block as text; the cursor moves to its end.
    pub fn rest(&mut self) -> String {
        let s: String = self
            .chars
            .get(self.pos..)
            .unwrap_or_default()
            .iter()
            .map(|c| c.ch)
            .collect();
        self.pos = self.chars.len();
        s
    }

    /// Skip blanks (comments were already turned into blanks).
    pub fn skip_ws(&mut self) {
        while self.peek() == Some(' ') {
            self.pos += 1;
        }
    }

    /// Describe the next character for error messages ("found …").
    pub fn describe_next(&self) -> String {
        match self.peek() {
            None => "end of block".to_string(),
            Some(c) => format!("'{c}'"),
        }
    }

    /// Scan a run of ASCII digits (possibly empty).
    pub fn scan_digits(&mut self) -> String {
        let mut s = String::new();
        while let Some(c) = self.peek().filter(char::is_ascii_digit) {
            s.push(c);
            self.pos += 1;
        }
        s
    }

    /// True if an unsigned number literal starts here (`5`, `.5`).
    pub fn at_number(&self) -> bool {
        match self.peek() {
            Some(c) if c.is_ascii_digit() => true,
            Some('.') => self.peek_at(1).is_some_and(|c| c.is_ascii_digit()),
            _ => false,
        }
    }

    /// Scan an unsigned number literal `\d+(\.\d*)?|\.\d+`. Returns `Ok(None)` (consuming
    /// nothing) if no number starts here; errors if the value is not a finite `f64`.
    pub fn scan_number(&mut self) -> Result<Option<f64>, ParseError> {
        if !self.at_number() {
            return Ok(None);
        }
        let start = self.span();
        let mut text = self.scan_digits();
        if self.peek() == Some('.') {
            self.pos += 1;
            text.push('.');
            text.push_str(&self.scan_digits());
        }
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some(v)),
            _ => Err(err(start, format!("number {text} is out of range"))),
        }
    }

    /// Scan an identifier `[A-Za-z_][A-Za-z0-9_]*` (upper-cased) with its position.
    pub fn scan_ident(&mut self) -> Option<(String, Span)> {
        let span = self.span();
        if !self.peek().is_some_and(is_ident_start) {
            return None;
        }
        let mut s = String::new();
        while let Some(c) = self.peek().filter(|&c| is_ident_char(c)) {
            s.push(c.to_ascii_uppercase());
            self.pos += 1;
        }
        Some((s, span))
    }

    /// True if a variable `V.<segment>` starts here.
    pub fn at_var(&self) -> bool {
        matches!(self.peek(), Some('V' | 'v'))
            && self.peek_at(1) == Some('.')
            && self.segment_starts_at(2)
    }

    fn segment_starts_at(&self, n: usize) -> bool {
        match self.peek_at(n) {
            Some('+' | '-') => self.peek_at(n + 1).is_some_and(is_ident_start),
            Some(c) => is_ident_start(c),
            None => false,
        }
    }

    /// Scan a variable `V.seg.seg…` where a segment is `[+-]?[A-Za-z_][A-Za-z0-9_]*`
    /// (`V.A.-SWE.X`, FCT-A2 §3.1; `V.A.MEAS.ACS.VALUE.Z`, FCT-C4 §5). The sign is only
    /// allowed right after a dot, so `V.A.ABS.X-5` stops before `-`. Segments are upper-cased.
    pub fn scan_var(&mut self) -> Option<VarRef> {
        if !self.at_var() {
            return None;
        }
        let span = self.span();
        self.pos += 1;
        let mut segments = vec!["V".to_string()];
        while self.peek() == Some('.') && self.segment_starts_at(1) {
            self.pos += 1;
            let mut seg = String::new();
            if let Some(c @ ('+' | '-')) = self.peek() {
                seg.push(c);
                self.pos += 1;
            }
            while let Some(c) = self.peek().filter(|&c| is_ident_char(c)) {
                seg.push(c.to_ascii_uppercase());
                self.pos += 1;
            }
            segments.push(seg);
        }
        Some(VarRef { segments, span })
    }

    /// Scan a string literal starting at `"` (escapes `\"` and `\\`; any other `\x` is kept
    /// literally as the two characters).
    pub fn scan_string(&mut self) -> Result<Option<String>, ParseError> {
        if self.peek() != Some('"') {
            return Ok(None);
        }
        let start = self.span();
        self.pos += 1;
        let mut s = String::new();
        loop {
            match self.bump().map(|c| c.ch) {
                None => return Err(err(start, "string is not closed: expected '\"'")),
                Some('"') => return Ok(Some(s)),
                Some('\\') => match self.peek() {
                    Some(c @ ('"' | '\\')) => {
                        s.push(c);
                        self.pos += 1;
                    }
                    _ => s.push('\\'),
                },
                Some(c) => s.push(c),
            }
        }
    }

    /// True if the characters at the cursor spell `word` (ASCII letters compared
    /// case-insensitively). Nothing is consumed.
    pub fn at_word(&self, word: &str) -> bool {
        word.chars()
            .enumerate()
            .all(|(i, w)| self.peek_at(i).is_some_and(|c| c.eq_ignore_ascii_case(&w)))
    }

    /// Skip `n` characters (or up to the end of the block).
    pub fn advance(&mut self, n: usize) {
        self.pos = self.pos.saturating_add(n).min(self.chars.len());
    }

    /// Scan a drive parameter ident written as one word: a SERCOS IDN `S-0-0092` / `P-0-0270`
    /// (`<letter>-<digits>-<digits>`, the letter upper-cased) or a CANopen object `0x6072_00`
    /// (returned as `0x` + upper-case hex digits). The word must not run on into an identifier
    /// character. Returns `None` (consuming nothing) otherwise.
    pub fn scan_drive_ident(&mut self) -> Option<String> {
        let run = |from: usize, ok: &dyn Fn(char) -> bool| {
            let mut k = from;
            while self.peek_at(k).is_some_and(ok) {
                k += 1;
            }
            k
        };
        let ends_word = |k: usize| {
            !self
                .peek_at(k)
                .is_some_and(|c| is_ident_char(c) || c == '.')
        };
        let first = self.peek()?;
        let len = if first.is_ascii_alphabetic() && self.peek_at(1) == Some('-') {
            let a = run(2, &|c| c.is_ascii_digit());
            if a == 2 || self.peek_at(a) != Some('-') {
                return None;
            }
            let b = run(a + 1, &|c| c.is_ascii_digit());
            if b == a + 1 || !ends_word(b) {
                return None;
            }
            b
        } else if first == '0' && matches!(self.peek_at(1), Some('x' | 'X')) {
            let k = run(2, &|c| c.is_ascii_hexdigit() || c == '_');
            let digits = (2..k).any(|i| self.peek_at(i).is_some_and(|c| c.is_ascii_hexdigit()));
            if !digits || !ends_word(k) {
                return None;
            }
            k
        } else {
            return None;
        };
        let mut word: String = self.chars[self.pos..self.pos + len]
            .iter()
            .map(|c| c.ch.to_ascii_uppercase())
            .collect();
        if first == '0' {
            word.replace_range(1..2, "x");
        }
        self.pos += len;
        Some(word)
    }

    /// Scan the next expression-level token (blanks skipped).
    pub fn next_token(&mut self) -> Result<Token, ParseError> {
        self.skip_ws();
        let span = self.span();
        let kind = if let Some(v) = self.scan_var() {
            TokenKind::Var(v)
        } else if let Some(n) = self.scan_number()? {
            TokenKind::Num(n)
        } else if let Some(s) = self.scan_string()? {
            TokenKind::Str(s)
        } else if let Some((id, _)) = self.scan_ident() {
            TokenKind::Ident(id)
        } else if let Some(c) = self.bump() {
            TokenKind::Punct(c.ch)
        } else {
            TokenKind::End
        };
        Ok(Token { kind, span })
    }

    /// Look at the next token without consuming it.
    pub fn peek_token(&self) -> Result<Token, ParseError> {
        self.clone().next_token()
    }
}
