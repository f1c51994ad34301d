//! NC parser: DIN 66025 blocks plus the seeds' `#` control commands → [`Program`].
//!
//! Syntax (the programming examples of FCT-A2 §3, FCT-C4 §2–§7 and FCT-C14 §3):
//!
//! ```text
//! %name                              optional program name (first line)
//! N10 G01 G90 X199 F500              N number first, then words in any order
//! N100 G98 X-500 Y-500 ;comment      ';' comment, '( … )' comment
//! N20 G01X10Y20                      blanks between words are optional
//! N60 X2 = 100 Y2=100                indexed axis names (FCT-C14 §4)
//! N30 X[V.A.ABS.X - 5] F=V.G.FEED    bracketed expressions, variables, '='
//! N30 #MSG SYN["V.A.MESS.Z=%f", V.A.MESS.Z]
//! D1                                 tool offset number (probe ball radius, FCT-C4 §5)
//! N20 X[INDP_SYN G100 G90 POS100 FEED500]   independent axis (FCT-C4 §2)
//! N10 P1 = V.A.ABS.X + 2             arithmetic parameter assignment
//! ```
//!
//! Words: `N<digits>` (first word only), `G<int>`, `M<int>`, `F<value>`, `D<value>`,
//! `I J K <value>`, axis letters `X Y Z A B C U V W` (optionally followed by digits and `=`, e.g.
//! `X2=100`). A value is a signed number, a signed `[expression]`, a signed variable or a signed
//! parameter `P<n>`, optionally after `=`. Letters are case-insensitive. Lexical rules (comments,
//! continuation lines) are in [`super::lexer`].
//!
//! Independent axes: an axis letter (optionally with digits, `X2`) followed by `[` whose first
//! word is `INDP_SYN` or `INDP_ASYN` is an [`Item::Independent`]; after that first word the
//! bracket holds, in any order, `G<int>` words, exactly one `POS<value>` and at most one
//! `FEED<value>` (`POS100`, `POS=-5`, `POS[expr]`, same for `FEED`), separated by blanks. Any
//! other `X[…]` is an expression as before.
//!
//! Arithmetic parameters: `P<n> = <expr>` is an [`Item::Assign`]; the expression is written
//! without brackets and ends before the next word. An assignment is a block of its own: only the
//! `N` number and further assignments may share its block. Inside expressions (and as a word
//! value, `X=P1`) `P<n>` is [`Expr::Param`]. `P` is not an address letter otherwise.
//!
//! Expressions: numbers, strings, variables, parameters `P<n>`, unary `+ -`, `+ - * /` with the
//! usual precedence (left associative), grouping with `[ ]` or `( )`, and the functions of
//! [`super::expr::FUNCTIONS`] written `ABS[x]`, `ATAN2[y, x]`. A sign directly in front of a
//! number literal is folded into the literal (`X-5` → `Expr::Num(-5.0)`). Nesting is limited to
//! [`MAX_NESTING`] levels and the tree height to [`MAX_EXPR_HEIGHT`], so no input can exhaust the
//! stack.
//!
//! `#` commands are dispatched by keyword through a table; their syntax is documented in the
//! `commands` submodule (`#MSG`, `#MEAS`, `#CS`, `#TRAFO`, `#DRIVE`, `#IDENT`, `#SET AX LINK`,
//! `#ENABLE AX LINK`, `#DISABLE AX LINK`).
//!
//! # Leniencies for the seed texts
//!
//! The seeds are PDF extractions; these artefacts are accepted on purpose, each as narrowly as
//! possible (any other use is still an error):
//!
//! * `\#` is read as `#` at the start of a command (FCT-C4 §4: `N50 \#CS ON[0,0,0,0,0,90]`).
//! * `NO<digits>` (letter O instead of zero) is read as the block number `N<digits>` only when it
//!   is the first word and is followed by blanks and a `#` command (FCT-C4 §7.3:
//!   `NO80 #IDENT WR SYN […]`, `NO30 #DRIVE WR SYN […]`).
//! * A `#` command whose line ends right after its keywords (`N060 #IDENT RD`) takes its bracket
//!   from the next non-empty line if that line starts with `[` (FCT-C4 §7.3.1, where the
//!   bracket `[AXNR 4 ID …]` was moved to the following line). The bracket may itself continue
//!   over further lines as long as it is open (see [`super::lexer`]). Since no block can start
//!   with `[`, this never changes the meaning of an otherwise valid program.
//! * `KEY=TORQUE LIMIT` in `#DRIVE` (underscore lost) — see the `commands` submodule.
//!
//! 2-path blocks (FCT-C14 §2.4): after the block number, `:` separates the words of the
//! reference path from those of the secondary path (`N050 : G0 X200 Y0 : G0 U150 V0`). The
//! separators carry no meaning of their own here: all words form the one block, so both paths are
//! interpolated together (and an area definition takes the coordinates its `MONITOR_LVL` needs).

mod commands;

use super::ast::{BinOp, Block, Expr, IndependentMotion, Item, Program, Span};
use super::expr::{function_arity, FUNCTIONS, MAX_EXPR_HEIGHT};
use super::lexer::{self, expression_lines, Cursor, LogicalLine, TokenKind};
use crate::limits::MAX_NC_BLOCKS;

/// Deepest bracket / function / unary-sign nesting accepted in one expression.
pub const MAX_NESTING: usize = 64;

/// The program text is not valid NC syntax.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}, column {col}: {message}")]
pub struct ParseError {
    /// 1-based line.
    pub line: u32,
    /// 1-based column, in characters.
    pub col: u32,
    /// What was expected / what went wrong.
    pub message: String,
}

impl ParseError {
    /// Error at `span`.
    pub fn at(span: Span, message: impl Into<String>) -> Self {
        ParseError {
            line: span.line,
            col: span.col,
            message: message.into(),
        }
    }

    /// Position of the error.
    pub fn span(&self) -> Span {
        Span {
            line: self.line,
            col: self.col,
        }
    }
}

type PResult<T> = Result<T, ParseError>;

const PERCENT_MISPLACED: &str =
    "'%' is only allowed at the start of the first line (program name '%name')";

/// Parse an NC program. A leading UTF-8 byte-order mark (U+FEFF) is skipped.
///
/// Never panics; every error names line, column and what was expected.
pub fn parse(src: &str) -> Result<Program, ParseError> {
    // A UTF-8 byte-order mark that an editor put in front of the first line is not part of
    // the program (columns of line 1 count from after it).
    let src = src.strip_prefix('\u{feff}').unwrap_or(src);
    let mut program = ProgramBuilder::default();
    // Lines are parsed as the lexer completes them, with one line of lookahead (a following
    // line that starts with '[' may supply the bracket of a `#` command that ends this line —
    // module documentation, leniencies). `index` counts logical lines taken so far.
    let mut pending: Option<LogicalLine> = None;
    let mut index = 0usize;
    lexer::for_each_logical_line(src, &mut |line| {
        match pending.take() {
            None => pending = Some(line),
            Some(prev) => {
                let next = Some(&line).filter(|l| l.chars.first().is_some_and(|c| c.ch == '['));
                let used_next = take_line(&mut program, &prev, next, index)?;
                index += 1;
                if used_next {
                    index += 1;
                } else {
                    pending = Some(line);
                }
            }
        }
        Ok(())
    })?;
    if let Some(last) = pending {
        take_line(&mut program, &last, None, index)?;
    }
    program.blocks.shrink_to_fit();
    Ok(Program {
        name: program.name,
        blocks: std::sync::Arc::new(program.blocks),
    })
}

/// A program while it is parsed (its blocks not yet shared).
#[derive(Default)]
struct ProgramBuilder {
    name: Option<String>,
    blocks: Vec<Block>,
}

/// Take logical line number `index` (0-based) into `program`: the `%name` line or one block.
/// Returns whether `next` was used. Refuses a program of more than [`MAX_NC_BLOCKS`] blocks.
fn take_line(
    program: &mut ProgramBuilder,
    line: &LogicalLine,
    next: Option<&LogicalLine>,
    index: usize,
) -> PResult<bool> {
    if let Some((first, rest)) = line.chars.split_first().filter(|(c, _)| c.ch == '%') {
        if index != 0 {
            return Err(ParseError::at(first.span, PERCENT_MISPLACED));
        }
        let name: String = rest.iter().map(|c| c.ch).collect();
        let name = name.trim();
        program.name = (!name.is_empty()).then(|| name.to_string());
        return Ok(false);
    }
    if program.blocks.len() >= MAX_NC_BLOCKS {
        return Err(ParseError::at(
            line.start(),
            format!(
                "the program has more than {MAX_NC_BLOCKS} blocks, the limit of an NC program \
                 (split it into several programs; see docs/limits.md)"
            ),
        ));
    }
    let (mut block, used_next) = parse_block(line, next)?;
    block.items.shrink_to_fit();
    program.blocks.push(block);
    Ok(used_next)
}

/// Parse a single expression as written inside `[ ]`, e.g. `"V.A.ABS.X - 5 * 2"` (so `( )`
/// group and line breaks are blanks). Positions are reported within `src`.
pub fn parse_expr(src: &str) -> Result<Expr, ParseError> {
    let lines = expression_lines(src)?;
    let [line] = lines.as_slice() else {
        let span = lines
            .get(1)
            .map_or(Span { line: 1, col: 1 }, LogicalLine::start);
        return Err(ParseError::at(span, "expected exactly one expression"));
    };
    let mut p = BlockParser::new(line, None);
    let (e, _) = p.expr(0)?;
    let t = p.cur.next_token()?;
    if t.kind != TokenKind::End {
        return Err(ParseError::at(
            t.span,
            format!(
                "expected an operator or end of expression, found {}",
                t.kind.describe()
            ),
        ));
    }
    Ok(e)
}

/// Parse one logical line; `next` is the following line if it starts with `[` (it may supply
/// the bracket of a `#` command). Returns the block and whether `next` was used.
fn parse_block<'a>(line: &'a LogicalLine, next: Option<&'a LogicalLine>) -> PResult<(Block, bool)> {
    let mut p = BlockParser::new(line, next);
    let mut block = Block {
        span: line.start(),
        number: None,
        items: Vec::new(),
    };
    // Where the block's first parameter assignment / first other word is (an assignment is a
    // block of its own).
    let mut assign_at: Option<Span> = None;
    let mut other_at: Option<Span> = None;
    let mut first = true;
    loop {
        p.cur.skip_ws();
        let Some(c) = p.cur.peek() else { break };
        let span = p.cur.span();
        let letter = c.to_ascii_uppercase();
        let item = match letter {
            'N' => {
                if !first {
                    return Err(ParseError::at(
                        span,
                        "block number 'N' must be the first word of the block",
                    ));
                }
                p.cur.bump();
                block.number = Some(p.block_number()?);
                first = false;
                continue;
            }
            'G' => {
                p.cur.bump();
                let code = p.integer('G')?;
                Item::G { code, span }
            }
            'M' => {
                p.cur.bump();
                let code = p.integer('M')?;
                Item::M { code, span }
            }
            'F' => {
                p.cur.bump();
                let value = p.word_value("F")?;
                Item::F { value, span }
            }
            'D' => {
                p.cur.bump();
                let value = p.word_value("D")?;
                Item::D { value, span }
            }
            'I' | 'J' | 'K' => {
                p.cur.bump();
                let value = p.word_value(&letter.to_string())?;
                Item::Centre {
                    letter,
                    value,
                    span,
                }
            }
            'P' => p.assignment(span)?,
            'X' | 'Y' | 'Z' | 'A' | 'B' | 'C' | 'U' | 'V' | 'W' => {
                if p.cur.at_var() {
                    return Err(ParseError::at(
                        span,
                        "expected an address letter, found a variable \
                         (assignments to variables are not supported)",
                    ));
                }
                p.cur.bump();
                let name = p.axis_name(letter);
                if let Some(sync) = p.indp_at(0) {
                    let motion = p.independent(&name, sync)?;
                    Item::Independent {
                        axis: name,
                        motion: Box::new(motion),
                        span,
                    }
                } else {
                    let value = p.word_value(&name)?;
                    Item::Axis { name, value, span }
                }
            }
            '#' => {
                p.cur.bump();
                let command = Box::new(p.command(span)?);
                Item::Command { command, span }
            }
            // FCT-C4 §4 `N50 \#CS ON[…]`: a stray '\' in front of a command (PDF extraction).
            '\\' if p.cur.peek_at(1) == Some('#') => {
                p.cur.bump();
                let span = p.cur.span();
                p.cur.bump();
                let command = Box::new(p.command(span)?);
                Item::Command { command, span }
            }
            '%' => return Err(ParseError::at(span, PERCENT_MISPLACED)),
            // FCT-C14 §2.4: `N050 : G0 X200 Y0 : G0 U150 V0` — the words of the reference path
            // and of the secondary path of a 2-path block, each after a ':'. Both paths run in
            // the one block (they are interpolated together).
            ':' if !first || block.number.is_some() => {
                p.cur.bump();
                first = false;
                continue;
            }
            _ if c.is_ascii_alphabetic() => {
                return Err(ParseError::at(
                    span,
                    format!(
                        "unknown address letter '{letter}' (expected N, G, M, F, D, I, J, K, \
                         an axis X Y Z A B C U V W, a parameter assignment P<n> = …, \
                         or a # command)"
                    ),
                ))
            }
            _ => {
                return Err(ParseError::at(
                    span,
                    format!(
                        "unexpected character '{c}': expected an address letter or a # command"
                    ),
                ))
            }
        };
        if matches!(item, Item::Assign { .. }) {
            if let Some(other) = other_at {
                return Err(ParseError::at(
                    span,
                    format!(
                        "a parameter assignment must be a block of its own, but this block \
                         already has a word at column {} (only 'N' and further assignments may \
                         share the block)",
                        other.col
                    ),
                ));
            }
            assign_at.get_or_insert(span);
        } else {
            if let Some(assign) = assign_at {
                return Err(ParseError::at(
                    span,
                    format!(
                        "a parameter assignment must be a block of its own: expected another \
                         assignment 'P<n> = …' or end of block after the assignment at column {}",
                        assign.col
                    ),
                ));
            }
            other_at.get_or_insert(span);
        }
        block.items.push(item);
        first = false;
    }
    Ok((block, p.used_next))
}

struct BlockParser<'a> {
    cur: Cursor<'a>,
    /// The next logical line if it starts with `[` and has not been taken yet.
    next_line: Option<&'a LogicalLine>,
    /// The next line was taken as the continuation of a `#` command.
    used_next: bool,
}

/// `P<digits>` as scanned by the token scanner (`P1159`): the parameter number.
fn param_number(name: &str, span: Span) -> PResult<Option<u32>> {
    let Some(digits) = name.strip_prefix('P') else {
        return Ok(None);
    };
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return Ok(None);
    }
    digits
        .parse::<u32>()
        .map(Some)
        .map_err(|_| ParseError::at(span, format!("parameter number is too large: P{digits}")))
}

impl<'a> BlockParser<'a> {
    fn new(line: &'a LogicalLine, next_line: Option<&'a LogicalLine>) -> Self {
        BlockParser {
            cur: Cursor::new(line),
            next_line,
            used_next: false,
        }
    }

    /// Where a `#` command's bracket may start: skip blanks; if the block ends here and the next
    /// line starts with `[`, continue on that line (module documentation, leniencies).
    fn continue_at_next_line_bracket(&mut self) {
        self.cur.skip_ws();
        if self.cur.peek().is_none() {
            if let Some(next) = self.next_line.take() {
                self.cur = Cursor::new(next);
                self.used_next = true;
            }
        }
    }
}

impl BlockParser<'_> {
    /// The block number after `N`: `<digits>`, or `O<digits>` (letter O) when followed by blanks
    /// and a `#` command (FCT-C4 §7.3 transcription artefact `NO80 #IDENT …`).
    fn block_number(&mut self) -> PResult<u32> {
        if matches!(self.cur.peek(), Some('O' | 'o')) {
            let mut k = 1;
            while self.cur.peek_at(k).is_some_and(|c| c.is_ascii_digit()) {
                k += 1;
            }
            let mut j = k;
            while self.cur.peek_at(j) == Some(' ') {
                j += 1;
            }
            let command_follows = match self.cur.peek_at(j) {
                Some('#') => true,
                Some('\\') => self.cur.peek_at(j + 1) == Some('#'),
                _ => false,
            };
            if k > 1 && j > k && command_follows {
                self.cur.bump();
                return self.integer('N');
            }
            return Err(ParseError::at(
                self.cur.span(),
                "expected an integer after 'N', found the letter 'O' \
                 ('NO<digits>' is only accepted as a block number in front of a # command)",
            ));
        }
        self.integer('N')
    }

    /// `P<n> = <expr>` starting at the `P` (at `span`).
    fn assignment(&mut self, span: Span) -> PResult<Item> {
        self.cur.bump();
        let digits_span = self.cur.span();
        let digits = self.cur.scan_digits();
        if digits.is_empty() {
            return Err(ParseError::at(
                digits_span,
                format!(
                    "expected a parameter number after 'P' (assignment 'P<n> = <expr>'), found {}",
                    self.cur.describe_next()
                ),
            ));
        }
        let param = digits.parse::<u32>().map_err(|_| {
            ParseError::at(span, format!("parameter number is too large: P{digits}"))
        })?;
        self.cur.skip_ws();
        if self.cur.peek() != Some('=') {
            return Err(ParseError::at(
                span,
                format!(
                    "'P' is not an address letter: expected '=' after P{param} (an arithmetic \
                     parameter is assigned in a block of its own, 'P{param} = <expr>', or used \
                     inside an expression), found {}",
                    self.cur.describe_next()
                ),
            ));
        }
        self.cur.bump();
        let (value, _) = self.expr(1)?;
        Ok(Item::Assign { param, value, span })
    }

    /// If the text `n` characters ahead is `[` (blanks allowed) followed by `INDP_SYN` or
    /// `INDP_ASYN` as a whole word: `Some(sync)`.
    fn indp_at(&self, n: usize) -> Option<bool> {
        let mut k = n;
        while self.cur.peek_at(k) == Some(' ') {
            k += 1;
        }
        if self.cur.peek_at(k) != Some('[') {
            return None;
        }
        k += 1;
        while self.cur.peek_at(k) == Some(' ') {
            k += 1;
        }
        let word: String = (k..)
            .map_while(|i| {
                self.cur
                    .peek_at(i)
                    .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
            })
            .take(10)
            .map(|c| c.to_ascii_uppercase())
            .collect();
        match word.as_str() {
            "INDP_SYN" => Some(true),
            "INDP_ASYN" => Some(false),
            _ => None,
        }
    }

    /// True if the keyword `kw` (upper case) starts here and is followed by its value, not by
    /// more letters (a variable `V.…` or a parameter `P<digit>` may follow directly).
    fn at_value_keyword(&self, kw: &str) -> bool {
        if !self.cur.at_word(kw) {
            return false;
        }
        let n = kw.chars().count();
        match self.cur.peek_at(n) {
            Some(c) if c.is_ascii_alphabetic() || c == '_' => match c.to_ascii_uppercase() {
                'V' => self.cur.peek_at(n + 1) == Some('.'),
                'P' => self.cur.peek_at(n + 1).is_some_and(|d| d.is_ascii_digit()),
                _ => false,
            },
            _ => true,
        }
    }

    /// The bracket of an independent-axis word, at the `[` (known to hold `INDP_SYN` /
    /// `INDP_ASYN`): `[INDP_SYN {G<int>} POS<value> [FEED<value>]]`, any order after the first
    /// word.
    fn independent(&mut self, axis: &str, sync: bool) -> PResult<IndependentMotion> {
        self.cur.skip_ws();
        let open = self.cur.span();
        self.cur.bump();
        self.cur.skip_ws();
        let kw = if sync { "INDP_SYN" } else { "INDP_ASYN" };
        self.cur.advance(kw.len());
        let mut gcodes = Vec::new();
        let mut pos: Option<Expr> = None;
        let mut feed: Option<Expr> = None;
        loop {
            self.cur.skip_ws();
            let span = self.cur.span();
            match self.cur.peek().map(|c| c.to_ascii_uppercase()) {
                Some(']') => {
                    self.cur.bump();
                    break;
                }
                None => {
                    return Err(ParseError::at(
                        span,
                        format!(
                            "expected ']' to close {axis}[{kw} … at line {}, column {}, found end \
                             of block",
                            open.line, open.col
                        ),
                    ))
                }
                Some('G')
                    if self
                        .cur
                        .peek_at(1)
                        .is_some_and(|c| c == ' ' || c.is_ascii_digit()) =>
                {
                    self.cur.bump();
                    gcodes.push(self.integer('G')?);
                }
                _ if self.at_value_keyword("POS") => {
                    if pos.is_some() {
                        return Err(ParseError::at(
                            span,
                            format!("POS is given twice in {axis}[{kw} …]"),
                        ));
                    }
                    self.cur.advance(3);
                    pos = Some(self.word_value("POS")?);
                }
                _ if self.at_value_keyword("FEED") => {
                    if feed.is_some() {
                        return Err(ParseError::at(
                            span,
                            format!("FEED is given twice in {axis}[{kw} …]"),
                        ));
                    }
                    self.cur.advance(4);
                    feed = Some(self.word_value("FEED")?);
                }
                _ => {
                    return Err(ParseError::at(
                        span,
                        format!(
                            "expected G<code>, POS<value>, FEED<value> or ']' in {axis}[{kw} …], \
                             found {}",
                            self.cur.describe_next()
                        ),
                    ))
                }
            }
        }
        let Some(pos) = pos else {
            return Err(ParseError::at(
                open,
                format!("{axis}[{kw} …] needs a target position POS<value>"),
            ));
        };
        Ok(IndependentMotion {
            sync,
            gcodes,
            pos,
            feed,
        })
    }

    /// Unsigned integer after `N`, `G` or `M` (blanks allowed after the letter).
    fn integer(&mut self, letter: char) -> PResult<u32> {
        self.cur.skip_ws();
        let span = self.cur.span();
        let digits = self.cur.scan_digits();
        if digits.is_empty() {
            return Err(ParseError::at(
                span,
                format!(
                    "expected an integer after '{letter}', found {}",
                    self.cur.describe_next()
                ),
            ));
        }
        if self.cur.peek() == Some('.') {
            return Err(ParseError::at(
                self.cur.span(),
                format!("'{letter}' takes an integer, found a decimal point"),
            ));
        }
        digits.parse::<u32>().map_err(|_| {
            ParseError::at(
                span,
                format!("number after '{letter}' is too large: {digits}"),
            )
        })
    }

    /// After an axis letter: `X2=` → `"X2"` (digits directly after the letter, then blanks and
    /// `=`, or `X2[INDP_SYN …]`), otherwise just the letter.
    fn axis_name(&mut self, letter: char) -> String {
        let mut n = 0;
        while self.cur.peek_at(n).is_some_and(|c| c.is_ascii_digit()) {
            n += 1;
        }
        if n == 0 {
            return letter.to_string();
        }
        let mut k = n;
        while self.cur.peek_at(k) == Some(' ') {
            k += 1;
        }
        if self.cur.peek_at(k) != Some('=') && self.indp_at(n).is_none() {
            return letter.to_string();
        }
        let mut name = letter.to_string();
        name.push_str(&self.cur.scan_digits());
        name
    }

    /// Value of an address word: `[=] [+|-] (number | [expr] | variable | P<n>)`.
    fn word_value(&mut self, word: &str) -> PResult<Expr> {
        self.cur.skip_ws();
        if self.cur.peek() == Some('=') {
            self.cur.bump();
            self.cur.skip_ws();
        }
        let negative = match self.cur.peek() {
            Some('-') => true,
            Some('+') => false,
            _ => return self.unsigned_word_value(word),
        };
        self.cur.bump();
        self.cur.skip_ws();
        let value = self.unsigned_word_value(word)?;
        Ok(match value {
            Expr::Num(n) if negative => Expr::Num(-n),
            v if negative => Expr::Neg(Box::new(v)),
            v => v,
        })
    }

    fn unsigned_word_value(&mut self, word: &str) -> PResult<Expr> {
        if let Some(n) = self.cur.scan_number()? {
            return Ok(Expr::Num(n));
        }
        if let Some(v) = self.cur.scan_var() {
            return Ok(Expr::Var(v));
        }
        if matches!(self.cur.peek(), Some('P' | 'p'))
            && self.cur.peek_at(1).is_some_and(|c| c.is_ascii_digit())
        {
            let span = self.cur.span();
            self.cur.bump();
            let digits = self.cur.scan_digits();
            let n = digits.parse::<u32>().map_err(|_| {
                ParseError::at(span, format!("parameter number is too large: P{digits}"))
            })?;
            return Ok(Expr::Param(n, span));
        }
        if self.cur.peek() == Some('[') {
            let open = self.cur.span();
            self.cur.bump();
            let (e, _) = self.expr(1)?;
            self.close(']', open)?;
            return Ok(e);
        }
        Err(ParseError::at(
            self.cur.span(),
            format!(
                "expected a number, '[', a variable or a parameter P<n> after '{word}', found {}",
                self.cur.describe_next()
            ),
        ))
    }

    /// Expect the closing bracket `close` of the bracket opened at `open`.
    fn close(&mut self, close: char, open: Span) -> PResult<()> {
        let t = self.cur.next_token()?;
        if t.kind == TokenKind::Punct(close) {
            return Ok(());
        }
        let what = if t.kind == TokenKind::End {
            format!(
                "expected '{close}' to close the bracket at line {}, column {}, found end of block",
                open.line, open.col
            )
        } else {
            format!(
                "expected an operator or '{close}', found {}",
                t.kind.describe()
            )
        };
        Err(ParseError::at(t.span, what))
    }

    fn enter(&self, depth: usize) -> PResult<()> {
        if depth > MAX_NESTING {
            return Err(ParseError::at(
                self.cur.span(),
                format!("expression is nested too deeply (more than {MAX_NESTING} levels)"),
            ));
        }
        Ok(())
    }

    fn grow(&self, span: Span, h: usize) -> PResult<usize> {
        if h > MAX_EXPR_HEIGHT {
            return Err(ParseError::at(
                span,
                format!("expression is too long (more than {MAX_EXPR_HEIGHT} levels of operators)"),
            ));
        }
        Ok(h)
    }

    /// `expr := term (('+' | '-') term)*`; returns the tree and its height.
    fn expr(&mut self, depth: usize) -> PResult<(Expr, usize)> {
        self.enter(depth)?;
        let (mut lhs, mut h) = self.term(depth)?;
        loop {
            let t = self.cur.peek_token()?;
            let op = match t.kind {
                TokenKind::Punct('+') => BinOp::Add,
                TokenKind::Punct('-') => BinOp::Sub,
                _ => return Ok((lhs, h)),
            };
            self.cur.next_token()?;
            let (rhs, rh) = self.term(depth)?;
            h = self.grow(t.span, 1 + h.max(rh))?;
            lhs = Expr::Bin(op, Box::new(lhs), Box::new(rhs));
        }
    }

    /// `term := unary (('*' | '/') unary)*`.
    fn term(&mut self, depth: usize) -> PResult<(Expr, usize)> {
        let (mut lhs, mut h) = self.unary(depth)?;
        loop {
            let t = self.cur.peek_token()?;
            let op = match t.kind {
                TokenKind::Punct('*') => BinOp::Mul,
                TokenKind::Punct('/') => BinOp::Div,
                _ => return Ok((lhs, h)),
            };
            self.cur.next_token()?;
            let (rhs, rh) = self.unary(depth)?;
            h = self.grow(t.span, 1 + h.max(rh))?;
            lhs = Expr::Bin(op, Box::new(lhs), Box::new(rhs));
        }
    }

    /// `unary := ('+' | '-') unary | primary`.
    fn unary(&mut self, depth: usize) -> PResult<(Expr, usize)> {
        self.enter(depth)?;
        let t = self.cur.peek_token()?;
        match t.kind {
            TokenKind::Punct('+') => {
                self.cur.next_token()?;
                self.unary(depth + 1)
            }
            TokenKind::Punct('-') => {
                self.cur.next_token()?;
                match self.unary(depth + 1)? {
                    (Expr::Num(n), h) => Ok((Expr::Num(-n), h)),
                    (e, h) => Ok((Expr::Neg(Box::new(e)), self.grow(t.span, h + 1)?)),
                }
            }
            _ => self.primary(depth),
        }
    }

    /// `primary := number | string | variable | P<n> | FUNC '[' args ']' | '[' expr ']'
    ///          | '(' expr ')'`.
    fn primary(&mut self, depth: usize) -> PResult<(Expr, usize)> {
        let t = self.cur.next_token()?;
        match t.kind {
            TokenKind::Num(n) => Ok((Expr::Num(n), 1)),
            TokenKind::Str(s) => Ok((Expr::Str(s), 1)),
            TokenKind::Var(v) => Ok((Expr::Var(v), 1)),
            TokenKind::Punct(open @ ('[' | '(')) => {
                let (e, h) = self.expr(depth + 1)?;
                self.close(if open == '[' { ']' } else { ')' }, t.span)?;
                Ok((e, h))
            }
            TokenKind::Ident(name) => {
                if let Some(n) = param_number(&name, t.span)? {
                    return Ok((Expr::Param(n, t.span), 1));
                }
                if self.cur.peek_token()?.kind != TokenKind::Punct('[') {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "unknown name '{name}': expected a number, a variable V.…, a \
                             parameter P<n>, a string, '[' or a function call such as ABS[…]"
                        ),
                    ));
                }
                self.call(name, t.span, depth)
            }
            other => Err(ParseError::at(
                t.span,
                format!(
                    "expected a number, a variable, a string, a function or '[', found {}",
                    other.describe()
                ),
            )),
        }
    }

    fn call(&mut self, name: String, span: Span, depth: usize) -> PResult<(Expr, usize)> {
        let Some(arity) = function_arity(&name) else {
            let known: Vec<&str> = FUNCTIONS.iter().map(|(n, _)| *n).collect();
            return Err(ParseError::at(
                span,
                format!("unknown function {name} (known: {})", known.join(", ")),
            ));
        };
        let open = self.cur.next_token()?.span;
        let mut args = Vec::new();
        let mut h = 0;
        if self.cur.peek_token()?.kind == TokenKind::Punct(']') {
            self.cur.next_token()?;
        } else {
            loop {
                let (e, eh) = self.expr(depth + 1)?;
                args.push(e);
                h = h.max(eh);
                let t = self.cur.next_token()?;
                match t.kind {
                    TokenKind::Punct(',') => {}
                    TokenKind::Punct(']') => break,
                    TokenKind::End => {
                        return Err(ParseError::at(
                            t.span,
                            format!(
                                "expected ',' or ']' to close {name}[ at line {}, column {}, \
                                 found end of block",
                                open.line, open.col
                            ),
                        ))
                    }
                    other => {
                        return Err(ParseError::at(
                            t.span,
                            format!(
                                "expected an operator, ',' or ']' in {name}[…], found {}",
                                other.describe()
                            ),
                        ))
                    }
                }
            }
        }
        if args.len() != arity {
            return Err(ParseError::at(
                span,
                format!(
                    "{name} takes {arity} argument{}, found {}",
                    if arity == 1 { "" } else { "s" },
                    args.len()
                ),
            ));
        }
        let h = self.grow(span, h + 1)?;
        Ok((
            Expr::Call(name.into_boxed_str(), args.into_boxed_slice(), span),
            h,
        ))
    }
}
