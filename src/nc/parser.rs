//! NC parser: DIN 66025 blocks plus the seeds' `#` control commands → [`Program`].
//!
//! Syntax (the programming examples of seed 001 §3, seed 004 §2/§4/§5 and seed 000 §3):
//!
//! ```text
//! %name                              optional program name (first line)
//! N10 G01 G90 X199 F500              N number first, then words in any order
//! N100 G98 X-500 Y-500 ;comment      ';' comment, '( … )' comment
//! N20 G01X10Y20                      blanks between words are optional
//! N60 X2 = 100 Y2=100                indexed axis names (seed 000 §4)
//! N30 X[V.A.ABS.X - 5] F=V.G.FEED    bracketed expressions, variables, '='
//! N30 #MSG SYN["V.A.MESS.Z=%f", V.A.MESS.Z]
//! ```
//!
//! Words: `N<digits>` (first word only), `G<int>`, `M<int>`, `F<value>`, `I J K <value>`, axis
//! letters `X Y Z A B C U V W` (optionally followed by digits and `=`, e.g. `X2=100`). A value is
//! a signed number, a signed `[expression]` or a signed variable, optionally after `=`. Letters
//! are case-insensitive. Lexical rules (comments, continuation lines) are in [`super::lexer`].
//!
//! Expressions: numbers, strings, variables, unary `+ -`, `+ - * /` with the usual precedence
//! (left associative), grouping with `[ ]` or `( )`, and the functions of
//! [`super::expr::FUNCTIONS`] written `ABS[x]`, `ATAN2[y, x]`. A sign directly in front of a
//! number literal is folded into the literal (`X-5` → `Expr::Num(-5.0)`). Nesting is limited to
//! [`MAX_NESTING`] levels and the tree height to [`MAX_EXPR_HEIGHT`], so no input can exhaust the
//! stack.
//!
//! `#` commands are dispatched by keyword through a table (`COMMANDS`); adding `#MEAS`, `#CS`,
//! `#CONTROL AREA` … means adding one entry and one function.

use super::ast::{BinOp, Block, Command, Expr, Item, Program, Span};
use super::expr::{function_arity, FUNCTIONS, MAX_EXPR_HEIGHT};
use super::lexer::{expression_lines, logical_lines, Cursor, LogicalLine, Token, TokenKind};

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

/// Parse an NC program.
///
/// Never panics; every error names line, column and what was expected.
pub fn parse(src: &str) -> Result<Program, ParseError> {
    let lines = logical_lines(src)?;
    let mut program = Program::default();
    for (k, line) in lines.iter().enumerate() {
        if let Some((first, rest)) = line.chars.split_first().filter(|(c, _)| c.ch == '%') {
            if k != 0 {
                return Err(ParseError::at(first.span, PERCENT_MISPLACED));
            }
            let name: String = rest.iter().map(|c| c.ch).collect();
            let name = name.trim();
            program.name = (!name.is_empty()).then(|| name.to_string());
            continue;
        }
        program.blocks.push(parse_block(line)?);
    }
    Ok(program)
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
    let mut p = BlockParser {
        cur: Cursor::new(line),
    };
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

fn parse_block(line: &LogicalLine) -> PResult<Block> {
    let mut p = BlockParser {
        cur: Cursor::new(line),
    };
    let mut block = Block {
        span: line.start(),
        number: None,
        items: Vec::new(),
    };
    let mut first = true;
    loop {
        p.cur.skip_ws();
        let Some(c) = p.cur.peek() else { break };
        let span = p.cur.span();
        let letter = c.to_ascii_uppercase();
        match letter {
            'N' => {
                if !first {
                    return Err(ParseError::at(
                        span,
                        "block number 'N' must be the first word of the block",
                    ));
                }
                p.cur.bump();
                block.number = Some(p.integer('N')?);
            }
            'G' => {
                p.cur.bump();
                let code = p.integer('G')?;
                block.items.push(Item::G { code, span });
            }
            'M' => {
                p.cur.bump();
                let code = p.integer('M')?;
                block.items.push(Item::M { code, span });
            }
            'F' => {
                p.cur.bump();
                let value = p.word_value("F")?;
                block.items.push(Item::F { value, span });
            }
            'I' | 'J' | 'K' => {
                p.cur.bump();
                let value = p.word_value(&letter.to_string())?;
                block.items.push(Item::Centre {
                    letter,
                    value,
                    span,
                });
            }
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
                let value = p.word_value(&name)?;
                block.items.push(Item::Axis { name, value, span });
            }
            '#' => {
                p.cur.bump();
                let command = p.command(span)?;
                block.items.push(Item::Command { command, span });
            }
            '%' => return Err(ParseError::at(span, PERCENT_MISPLACED)),
            _ if c.is_ascii_alphabetic() => {
                return Err(ParseError::at(
                    span,
                    format!(
                        "unknown address letter '{letter}' (expected N, G, M, F, I, J, K, \
                         an axis X Y Z A B C U V W, or a # command)"
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
        }
        first = false;
    }
    Ok(block)
}

/// Signature of a `#` command parser: called after the keyword, with the span of the `#`.
type CommandFn = fn(&mut BlockParser<'_>, Span) -> PResult<Command>;

/// `#` command keyword dispatch table (keywords upper case).
const COMMANDS: &[(&str, CommandFn)] = &[("MSG", command_msg)];

/// `#MSG` entry of [`COMMANDS`].
fn command_msg(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    p.msg()
}

struct BlockParser<'a> {
    cur: Cursor<'a>,
}

impl BlockParser<'_> {
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
    /// `=`), otherwise just the letter.
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
        if self.cur.peek_at(k) != Some('=') {
            return letter.to_string();
        }
        let mut name = letter.to_string();
        name.push_str(&self.cur.scan_digits());
        name
    }

    /// Value of an address word: `[=] [+|-] (number | [expr] | variable)`.
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
                "expected a number, '[' or a variable after '{word}', found {}",
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

    /// `primary := number | string | variable | FUNC '[' args ']' | '[' expr ']' | '(' expr ')'`.
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
                if self.cur.peek_token()?.kind != TokenKind::Punct('[') {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "unknown name '{name}': expected a number, a variable V.…, a string, \
                             '[' or a function call such as ABS[…]"
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
        Ok((Expr::Call(name, args, span), h))
    }

    /// `#KEYWORD …` after the `#`: look the keyword up in [`COMMANDS`].
    fn command(&mut self, hash: Span) -> PResult<Command> {
        let Some((keyword, _)) = self.cur.scan_ident() else {
            return Err(ParseError::at(
                self.cur.span(),
                format!(
                    "expected a command name after '#', found {}",
                    self.cur.describe_next()
                ),
            ));
        };
        match COMMANDS.iter().find(|(k, _)| *k == keyword) {
            Some((_, f)) => f(self, hash),
            None => Err(ParseError::at(
                hash,
                format!("unknown control command #{keyword}"),
            )),
        }
    }

    fn expect_token(&mut self, what: &str) -> PResult<Token> {
        let t = self.cur.next_token()?;
        if t.kind == TokenKind::End {
            return Err(ParseError::at(
                t.span,
                format!("expected {what}, found end of block"),
            ));
        }
        Ok(t)
    }

    /// `#MSG [SYN] ["format", expr, …]` (seed 004 §5).
    fn msg(&mut self) -> PResult<Command> {
        let mut t = self.expect_token("'SYN' or '[' after #MSG")?;
        let mut sync = false;
        if t.kind == TokenKind::Ident("SYN".to_string()) {
            sync = true;
            t = self.expect_token("'[' after #MSG SYN")?;
        }
        if t.kind != TokenKind::Punct('[') {
            let expected = if sync { "'['" } else { "'SYN' or '['" };
            return Err(ParseError::at(
                t.span,
                format!(
                    "expected {expected} after #MSG, found {}",
                    t.kind.describe()
                ),
            ));
        }
        let t = self.expect_token("the format string \"…\"")?;
        let TokenKind::Str(format) = t.kind else {
            return Err(ParseError::at(
                t.span,
                format!(
                    "expected the format string \"…\" as the first #MSG argument, found {}",
                    t.kind.describe()
                ),
            ));
        };
        let mut args = Vec::new();
        loop {
            let t = self.expect_token("',' or ']' in #MSG")?;
            match t.kind {
                TokenKind::Punct(',') => args.push(self.expr(1)?.0),
                TokenKind::Punct(']') => break,
                other => {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "expected an operator, ',' or ']' in #MSG, found {}",
                            other.describe()
                        ),
                    ))
                }
            }
        }
        Ok(Command::Msg { sync, format, args })
    }
}
