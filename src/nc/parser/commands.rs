//! `#` control commands.
//!
//! The keyword after `#` selects the command through [`COMMANDS`]. Keywords and sub-keywords are
//! case-insensitive and separated by blanks; `<expr>` is an expression as in `[ … ]`.
//!
//! ```text
//! #MSG [SYN] ["format", <expr>, …]
//! #MEAS MODE [<expr>]            MeasMode { mode: Some }   (FCT-C4 §3; also `#MEAS MODE[2]`)
//! #MEAS MODE                     MeasMode { mode: None }   (channel default P-CHAN-00057)
//! #MEAS [TYPE=<expr>]            MeasMode { mode: Some }   (P-CHAN-00057 remark: "#MEAS [TYPE]")
//! #MEAS [AXNR=.. SIGNAL=.. INPUT=.. EDGE=..]               MeasConfig (AXNR required)
//! #MEAS PREPARE [AXNR=.. {AXNR=..}]                        MeasPrepare (at least one AXNR)
//! #CS ON [<expr>{, <expr>}]      Cs { on: Some(1 to 6 values) } (x, y, z, a, b, c)
//! #CS OFF                        Cs { on: None }
//! #TRAFO ON | #TRAFO OFF         Trafo
//! #DRIVE WR [SYN] [AX=.. KEY=.. VAL=.. [WAIT]]             Drive (AX, KEY, VAL required)
//! #DRIVE RD [SYN] [AX=.. KEY=.. P=.. [WAIT]]               Drive (AX, KEY, P required)
//! #IDENT WR [SYN] [AX=.. | AXNR=.. ID=.. VAL=.. [TYP=..] [DEC=..] [SERC | CAN]]
//! #IDENT RD [SYN] [AX=.. | AXNR=.. ID=.. P=..   [TYP=..] [DEC=..] [SERC | CAN]]
//! #SET AX LINK [<expr>, [<slave>=<master>, <kind>{, <expr>}] {, […]}]     SetAxLink
//! #ENABLE AX LINK [<expr>] | #ENABLE AX LINK                             EnableAxLink
//! #DISABLE AX LINK [<expr>] | #DISABLE AX LINK                           EnableAxLink
//! ```
//!
//! Keyword lists (`#MEAS`, `#DRIVE`, `#IDENT`) are [`KeyArg`]s separated by blanks, in any order.
//! A keyword with a value is written `KEY=value` or `KEY value` (blanks around `=` allowed); a
//! flag (`WAIT`, `SERC`, `CAN`) has no value. Only the keywords listed above are accepted, each
//! at most once (`AXNR` may repeat in `#MEAS PREPARE`). A value is
//!
//! * a bare word, an identifier that is not a parameter `P<n>` and not a function call
//!   (`SIGNAL=PLC_TIMESTAMP`, `AX=Z`, `KEY=TORQUE_LIMIT`, `EDGE=POS`) → [`Expr::Str`],
//!   upper-cased;
//! * for `ID` only: a drive parameter ident `S-0-0092`, `P-0-0270` or a CANopen object
//!   `0x6072_00` → [`Expr::Str`] (letters upper-cased, `0x` prefix kept lower-case);
//! * otherwise an expression (`VAL=4294967295`, `VAL=P1159`, `P=P10`, `AXNR=[P1+1]`).
//!
//! Without `=`, a value cannot be another keyword of the same list (`AXNR ID …` is "expected a
//! value after AXNR"). Values are not range-checked here (signal names, edge, axis numbers, the
//! target of `P=`): that is the executor's business.
//!
//! Leniency (FCT-C4 §7.3.2 lost underscores in the PDF: `KEY=TORQUE LIMIT`, `KEY=MON WINDOW`):
//! a bare-word `KEY` value may be followed by a second bare word that is not a keyword of the
//! list, not a parameter `P<n>` and not followed by `=` or `[`; the two are joined with `_`
//! (`TORQUE_LIMIT`). Only two words are joined.
//!
//! The bracket of every command above may start on the next line if the command's line ends
//! right after its keywords (see the parser module documentation).

use super::{param_number, BlockParser, PResult, ParseError};
use crate::nc::ast::{AxLink, Command, Expr, KeyArg, Span};
use crate::nc::lexer::{Token, TokenKind};

/// Signature of a `#` command parser: called after the keyword, with the span of the `#`.
type CommandFn = fn(&mut BlockParser<'_>, Span) -> PResult<Command>;

/// `#` command keyword dispatch table (keywords upper case).
const COMMANDS: &[(&str, CommandFn)] = &[
    ("MSG", command_msg),
    ("MEAS", command_meas),
    ("CS", command_cs),
    ("CONTROL", command_control),
    ("TRAFO", command_trafo),
    ("DRIVE", command_drive),
    ("IDENT", command_ident),
    ("SET", command_set),
    ("ENABLE", command_enable),
    ("DISABLE", command_disable),
];

/// What follows a keyword of a keyword list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// A bare word or an expression.
    Value,
    /// Like `Value`, but a drive parameter ident `S-0-0092` / `0x6072_00` is one word.
    Ident,
    /// Nothing (`WAIT`).
    Flag,
}

/// One keyword of a keyword list.
struct KeySpec {
    name: &'static str,
    kind: Kind,
    /// May appear more than once.
    repeat: bool,
}

const fn value(name: &'static str) -> KeySpec {
    KeySpec {
        name,
        kind: Kind::Value,
        repeat: false,
    }
}

const fn flag(name: &'static str) -> KeySpec {
    KeySpec {
        name,
        kind: Kind::Flag,
        repeat: false,
    }
}

const MEAS_CONFIG_KEYS: &[KeySpec] = &[
    value("AXNR"),
    value("SIGNAL"),
    value("INPUT"),
    value("EDGE"),
    value("TYPE"),
];

const MEAS_PREPARE_KEYS: &[KeySpec] = &[KeySpec {
    name: "AXNR",
    kind: Kind::Value,
    repeat: true,
}];

const DRIVE_KEYS: &[KeySpec] = &[
    value("AX"),
    value("KEY"),
    value("VAL"),
    value("P"),
    flag("WAIT"),
];

const IDENT_KEYS: &[KeySpec] = &[
    value("AX"),
    value("AXNR"),
    KeySpec {
        name: "ID",
        kind: Kind::Ident,
        repeat: false,
    },
    value("VAL"),
    value("P"),
    value("TYP"),
    value("DEC"),
    flag("SERC"),
    flag("CAN"),
];

fn key_names(specs: &[KeySpec]) -> String {
    specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

fn find_key<'s>(specs: &'s [KeySpec], name: &str) -> Option<&'s KeySpec> {
    specs.iter().find(|s| s.name == name)
}

fn has(args: &[KeyArg], key: &str) -> bool {
    args.iter().any(|a| a.key == key)
}

fn is_axis_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| "XYZABCUVW".contains(c)) && chars.all(|c| c.is_ascii_digit())
}

fn command_msg(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    p.msg()
}

/// `#MEAS MODE …`, `#MEAS PREPARE […]`, `#MEAS […]`.
fn command_meas(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    p.continue_at_next_line_bracket();
    if p.cur.peek() == Some('[') {
        let (open, mut args) = p.key_list("#MEAS", MEAS_CONFIG_KEYS)?;
        // `#MEAS [TYPE=n]`: the measurement type, as #MEAS MODE [n] (P-CHAN-00057: "can be
        // changed at any time in the NC program with #MEAS MODE or #MEAS [TYPE]").
        if has(&args, "TYPE") && !has(&args, "AXNR") {
            if let Some(other) = args.iter().find(|a| a.key != "TYPE") {
                return Err(ParseError::at(
                    other.span,
                    format!(
                        "#MEAS [{} ...] needs the axis number AXNR=<expr>; TYPE=<expr> alone sets the measurement type",
                        other.key
                    ),
                ));
            }
            let t = args.remove(0);
            return match t.value {
                Some(mode) if !matches!(mode, Expr::Str(_)) => {
                    Ok(Command::MeasMode { mode: Some(mode) })
                }
                _ => Err(ParseError::at(
                    t.span,
                    "#MEAS [TYPE=<expr>]: the measurement type is a number 1 … 7 (P-CHAN-00057)",
                )),
            };
        }
        if !has(&args, "AXNR") {
            return Err(ParseError::at(
                open,
                "#MEAS [...] needs the axis number AXNR=<expr>",
            ));
        }
        return Ok(Command::MeasConfig { args });
    }
    let t = p.expect_token("MODE, PREPARE or '[' after #MEAS")?;
    match &t.kind {
        TokenKind::Ident(k) if k == "MODE" => {
            p.continue_at_next_line_bracket();
            if p.cur.peek() != Some('[') {
                return Ok(Command::MeasMode { mode: None });
            }
            let open = p.cur.span();
            p.cur.bump();
            if p.cur.peek_token()?.kind == TokenKind::Punct(']') {
                return Err(ParseError::at(
                    p.cur.peek_token()?.span,
                    "expected the measurement type in #MEAS MODE [...], found ']' \
                     (write #MEAS MODE without brackets for the channel default)",
                ));
            }
            let (mode, _) = p.expr(1)?;
            p.close(']', open)?;
            Ok(Command::MeasMode { mode: Some(mode) })
        }
        TokenKind::Ident(k) if k == "PREPARE" => {
            let (open, args) = p.key_list("#MEAS PREPARE", MEAS_PREPARE_KEYS)?;
            if args.is_empty() {
                return Err(ParseError::at(
                    open,
                    "#MEAS PREPARE [...] needs at least one axis number AXNR=<expr>",
                ));
            }
            Ok(Command::MeasPrepare { args })
        }
        other => Err(ParseError::at(
            t.span,
            format!(
                "expected MODE, PREPARE or '[' after #MEAS, found {}",
                other.describe()
            ),
        )),
    }
}

/// `#CS ON [x, y, z, a, b, c]` / `#CS OFF`.
fn command_cs(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    if !p.on_off("#CS")? {
        return Ok(Command::Cs { on: None });
    }
    p.continue_at_next_line_bracket();
    let t = p.expect_token("'[' with the offsets after #CS ON")?;
    if t.kind != TokenKind::Punct('[') {
        return Err(ParseError::at(
            t.span,
            format!(
                "expected '[' with the offsets after #CS ON, found {}",
                t.kind.describe()
            ),
        ));
    }
    let values = p.expr_list("#CS ON", t.span)?;
    if values.is_empty() || values.len() > 6 {
        return Err(ParseError::at(
            t.span,
            format!(
                "#CS ON [...] takes 1 to 6 values (x, y, z, a, b, c), found {}",
                values.len()
            ),
        ));
    }
    Ok(Command::Cs { on: Some(values) })
}

/// `#TRAFO ON` / `#TRAFO OFF`.
fn command_trafo(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    Ok(Command::Trafo {
        on: p.on_off("#TRAFO")?,
    })
}

/// `#CONTROL AREA …` (FCT-C14 §3): the rest of the block is the area command text.
fn command_control(p: &mut BlockParser<'_>, hash: Span) -> PResult<Command> {
    let t = p.expect_token("AREA after #CONTROL")?;
    match &t.kind {
        TokenKind::Ident(w) if w == "AREA" => {}
        other => {
            return Err(ParseError::at(
                t.span,
                format!("expected AREA after #CONTROL, found {}", other.describe()),
            ))
        }
    }
    p.cur.skip_ws();
    let mut text = p.cur.rest();
    if !text.contains('[') {
        p.continue_at_next_line_bracket();
        let more = p.cur.rest();
        if !more.is_empty() {
            text.push(' ');
            text.push_str(&more);
        }
    }
    let command = crate::core::monitor::areas::parse_area_command(&text)
        .map_err(|e| ParseError::at(hash, e.to_string()))?;
    Ok(Command::ControlArea { command })
}

/// `#DRIVE WR|RD [SYN] [AX=.. KEY=.. VAL=..|P=.. [WAIT]]`.
fn command_drive(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    let (write, sync) = p.wr_rd_syn("#DRIVE")?;
    let what = if write { "#DRIVE WR" } else { "#DRIVE RD" };
    let (open, args) = p.key_list(what, DRIVE_KEYS)?;
    for key in ["AX", "KEY"] {
        if !has(&args, key) {
            return Err(ParseError::at(
                open,
                format!("{what} [...] needs {key}=<value>"),
            ));
        }
    }
    check_direction(what, write, open, &args)?;
    Ok(Command::Drive { write, sync, args })
}

/// `#IDENT WR|RD [SYN] [AX=..|AXNR=.. ID=.. VAL=..|P=.. TYP=.. DEC=.. SERC|CAN]`.
fn command_ident(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    let (write, sync) = p.wr_rd_syn("#IDENT")?;
    let what = if write { "#IDENT WR" } else { "#IDENT RD" };
    let (open, args) = p.key_list(what, IDENT_KEYS)?;
    match (has(&args, "AX"), has(&args, "AXNR")) {
        (false, false) => {
            return Err(ParseError::at(
                open,
                format!("{what} [...] needs the axis: AX <name> or AXNR <number>"),
            ))
        }
        (true, true) => {
            let second = args
                .iter()
                .filter(|a| a.key == "AX" || a.key == "AXNR")
                .nth(1)
                .map_or(open, |a| a.span);
            return Err(ParseError::at(
                second,
                format!("{what} [...] takes either AX or AXNR, not both"),
            ));
        }
        _ => {}
    }
    if !has(&args, "ID") {
        return Err(ParseError::at(
            open,
            format!("{what} [...] needs the parameter ident ID, e.g. ID S-0-0092"),
        ));
    }
    if let Some(second) = args
        .iter()
        .filter(|a| a.key == "SERC" || a.key == "CAN")
        .nth(1)
    {
        return Err(ParseError::at(
            second.span,
            format!("{what} [...] takes one drive type (SERC or CAN)"),
        ));
    }
    check_direction(what, write, open, &args)?;
    Ok(Command::Ident { write, sync, args })
}

/// WR needs `VAL` and refuses `P`; RD needs `P` (where the value goes) and refuses `VAL`.
fn check_direction(what: &str, write: bool, open: Span, args: &[KeyArg]) -> PResult<()> {
    let (needed, refused, hint) = if write {
        ("VAL", "P", "VAL=<value to write>")
    } else {
        (
            "P",
            "VAL",
            "P=<parameter that receives the value>, e.g. P=P10",
        )
    };
    if let Some(a) = args.iter().find(|a| a.key == refused) {
        return Err(ParseError::at(
            a.span,
            format!("{what} [...] does not take {refused} (it needs {hint})"),
        ));
    }
    if !has(args, needed) {
        return Err(ParseError::at(open, format!("{what} [...] needs {hint}")));
    }
    Ok(())
}

/// `#SET AX LINK [group, [slave=master, kind, p…] …]`.
fn command_set(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    p.ax_link("#SET")?;
    p.continue_at_next_line_bracket();
    let t = p.expect_token("'[' after #SET AX LINK")?;
    if t.kind != TokenKind::Punct('[') {
        return Err(ParseError::at(
            t.span,
            format!(
                "expected '[' after #SET AX LINK, found {}",
                t.kind.describe()
            ),
        ));
    }
    let open = t.span;
    let (group, _) = p.expr(1)?;
    let mut links = Vec::new();
    loop {
        let t = p.cur.next_token()?;
        match t.kind {
            TokenKind::Punct(',') => links.push(p.link()?),
            TokenKind::Punct(']') if !links.is_empty() => break,
            TokenKind::End => {
                return Err(ParseError::at(
                    t.span,
                    format!(
                        "expected ',' or ']' to close #SET AX LINK[ at line {}, column {}, found \
                         end of block",
                        open.line, open.col
                    ),
                ))
            }
            other => {
                let expected = if links.is_empty() {
                    "an operator or ',' and a coupling [<slave>=<master>, <kind>, …]"
                } else {
                    "',' or ']'"
                };
                return Err(ParseError::at(
                    t.span,
                    format!(
                        "expected {expected} in #SET AX LINK[…], found {}",
                        other.describe()
                    ),
                ));
            }
        }
    }
    Ok(Command::SetAxLink { group, links })
}

fn command_enable(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    p.enable_ax_link(true)
}

fn command_disable(p: &mut BlockParser<'_>, _hash: Span) -> PResult<Command> {
    p.enable_ax_link(false)
}

impl BlockParser<'_> {
    /// `#KEYWORD …` after the `#`: look the keyword up in [`COMMANDS`].
    pub(super) fn command(&mut self, hash: Span) -> PResult<Command> {
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

    /// Expect the identifier `word` (upper case) as the next token.
    fn expect_word(&mut self, word: &str, what: &str) -> PResult<()> {
        let t = self.expect_token(what)?;
        match &t.kind {
            TokenKind::Ident(w) if w == word => Ok(()),
            other => Err(ParseError::at(
                t.span,
                format!("expected {what}, found {}", other.describe()),
            )),
        }
    }

    /// `ON` (true) or `OFF` after `#CS` / `#TRAFO`.
    fn on_off(&mut self, command: &str) -> PResult<bool> {
        let what = format!("ON or OFF after {command}");
        let t = self.expect_token(&what)?;
        match &t.kind {
            TokenKind::Ident(w) if w == "ON" => Ok(true),
            TokenKind::Ident(w) if w == "OFF" => Ok(false),
            other => Err(ParseError::at(
                t.span,
                format!("expected {what}, found {}", other.describe()),
            )),
        }
    }

    /// `WR|RD [SYN]` after `#DRIVE` / `#IDENT`: (write, sync).
    fn wr_rd_syn(&mut self, command: &str) -> PResult<(bool, bool)> {
        let what = format!("WR or RD after {command}");
        let t = self.expect_token(&what)?;
        let write = match &t.kind {
            TokenKind::Ident(w) if w == "WR" => true,
            TokenKind::Ident(w) if w == "RD" => false,
            other => {
                return Err(ParseError::at(
                    t.span,
                    format!("expected {what}, found {}", other.describe()),
                ))
            }
        };
        let sync = self.cur.peek_token()?.kind == TokenKind::Ident("SYN".to_string());
        if sync {
            self.cur.next_token()?;
        }
        Ok((write, sync))
    }

    /// `AX LINK` after `#SET` / `#ENABLE` / `#DISABLE`.
    fn ax_link(&mut self, command: &str) -> PResult<()> {
        let what = format!("'AX LINK' after {command}");
        self.expect_word("AX", &what)?;
        self.expect_word("LINK", &what)
    }

    /// `#ENABLE AX LINK [group]` / `#DISABLE AX LINK [group]` (bracket optional).
    fn enable_ax_link(&mut self, enable: bool) -> PResult<Command> {
        let command = if enable { "#ENABLE" } else { "#DISABLE" };
        self.ax_link(command)?;
        self.continue_at_next_line_bracket();
        if self.cur.peek() != Some('[') {
            return Ok(Command::EnableAxLink {
                enable,
                group: None,
            });
        }
        let open = self.cur.span();
        self.cur.bump();
        let (group, _) = self.expr(1)?;
        self.close(']', open)?;
        Ok(Command::EnableAxLink {
            enable,
            group: Some(group),
        })
    }

    /// An axis name token of `#SET AX LINK` (`X`, `X2`).
    fn link_axis(&mut self, role: &str) -> PResult<String> {
        let t = self.expect_token(&format!("the {role} axis name"))?;
        match t.kind {
            TokenKind::Ident(name) if is_axis_name(&name) => Ok(name),
            other => Err(ParseError::at(
                t.span,
                format!(
                    "expected the {role} axis name (X Y Z A B C U V W, optionally with digits \
                     such as X2) in #SET AX LINK, found {}",
                    other.describe()
                ),
            )),
        }
    }

    /// One coupling `[<slave>=<master>, <kind>{, <expr>}]` of `#SET AX LINK`.
    fn link(&mut self) -> PResult<AxLink> {
        let t = self.expect_token("'[' with a coupling [<slave>=<master>, <kind>, …]")?;
        if t.kind != TokenKind::Punct('[') {
            return Err(ParseError::at(
                t.span,
                format!(
                    "expected '[' with a coupling [<slave>=<master>, <kind>, …] in #SET AX \
                     LINK, found {}",
                    t.kind.describe()
                ),
            ));
        }
        let open = t.span;
        let slave = self.link_axis("slave")?;
        let t = self.expect_token("'=' after the slave axis")?;
        if t.kind != TokenKind::Punct('=') {
            return Err(ParseError::at(
                t.span,
                format!(
                    "expected '=' after the slave axis {slave} in #SET AX LINK, found {}",
                    t.kind.describe()
                ),
            ));
        }
        let master = self.link_axis("master")?;
        let t = self.expect_token("',' and the coupling kind")?;
        if t.kind != TokenKind::Punct(',') {
            return Err(ParseError::at(
                t.span,
                format!(
                    "expected ',' and the coupling kind (e.g. G) after {slave}={master}, found {}",
                    t.kind.describe()
                ),
            ));
        }
        let t = self.expect_token("the coupling kind (e.g. G)")?;
        let TokenKind::Ident(kind) = t.kind else {
            return Err(ParseError::at(
                t.span,
                format!(
                    "expected the coupling kind (e.g. G) in #SET AX LINK, found {}",
                    t.kind.describe()
                ),
            ));
        };
        let mut params = Vec::new();
        loop {
            let t = self.cur.next_token()?;
            match t.kind {
                TokenKind::Punct(',') => params.push(self.expr(1)?.0),
                TokenKind::Punct(']') => break,
                TokenKind::End => {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "expected ',' or ']' to close the coupling at line {}, column {}, \
                             found end of block",
                            open.line, open.col
                        ),
                    ))
                }
                other => {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "expected an operator, ',' or ']' in the coupling [{slave}={master}, \
                             …], found {}",
                            other.describe()
                        ),
                    ))
                }
            }
        }
        Ok(AxLink {
            slave,
            master,
            kind,
            params,
        })
    }

    /// After the `[` at `open`: `[<expr> {, <expr>}]` (possibly empty) up to and including `]`.
    fn expr_list(&mut self, what: &str, open: Span) -> PResult<Vec<Expr>> {
        let mut values = Vec::new();
        if self.cur.peek_token()?.kind == TokenKind::Punct(']') {
            self.cur.next_token()?;
            return Ok(values);
        }
        loop {
            values.push(self.expr(1)?.0);
            let t = self.cur.next_token()?;
            match t.kind {
                TokenKind::Punct(',') => {}
                TokenKind::Punct(']') => return Ok(values),
                TokenKind::End => {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "expected ',' or ']' to close {what}[ at line {}, column {}, found \
                             end of block",
                            open.line, open.col
                        ),
                    ))
                }
                other => {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "expected an operator, ',' or ']' in {what}[…], found {}",
                            other.describe()
                        ),
                    ))
                }
            }
        }
    }

    /// A bracketed keyword list `[KEY=value KEY value FLAG …]` (see the module documentation).
    /// Returns the position of the `[` and the arguments.
    fn key_list(&mut self, what: &str, specs: &[KeySpec]) -> PResult<(Span, Vec<KeyArg>)> {
        self.continue_at_next_line_bracket();
        let open = self.cur.span();
        if self.cur.peek() != Some('[') {
            return Err(ParseError::at(
                open,
                format!(
                    "expected '[' with the keywords ({}) after {what}, found {}",
                    key_names(specs),
                    self.cur.describe_next()
                ),
            ));
        }
        self.cur.bump();
        let mut args: Vec<KeyArg> = Vec::new();
        loop {
            self.cur.skip_ws();
            let span = self.cur.span();
            match self.cur.peek() {
                Some(']') => {
                    self.cur.bump();
                    break;
                }
                None => {
                    return Err(ParseError::at(
                        span,
                        format!(
                            "expected ']' to close {what} [ at line {}, column {}, found end of \
                             block",
                            open.line, open.col
                        ),
                    ))
                }
                Some(_) => {}
            }
            let Some((key, _)) = self.cur.scan_ident() else {
                return Err(ParseError::at(
                    span,
                    format!(
                        "expected a keyword ({}) or ']' in {what} [...], found {}",
                        key_names(specs),
                        self.cur.describe_next()
                    ),
                ));
            };
            let Some(spec) = find_key(specs, &key) else {
                return Err(ParseError::at(
                    span,
                    format!(
                        "unknown keyword {key} in {what} [...] (expected one of {})",
                        key_names(specs)
                    ),
                ));
            };
            if !spec.repeat && has(&args, &key) {
                return Err(ParseError::at(
                    span,
                    format!("{key} is given twice in {what} [...]"),
                ));
            }
            let value = match spec.kind {
                Kind::Flag => {
                    self.cur.skip_ws();
                    if self.cur.peek() == Some('=') {
                        return Err(ParseError::at(
                            self.cur.span(),
                            format!("{key} is a flag in {what} [...] and takes no value"),
                        ));
                    }
                    None
                }
                kind => Some(self.key_value(what, &key, kind, specs)?),
            };
            args.push(KeyArg { key, value, span });
        }
        Ok((open, args))
    }

    /// The value of keyword `key` (see the module documentation).
    fn key_value(&mut self, what: &str, key: &str, kind: Kind, specs: &[KeySpec]) -> PResult<Expr> {
        self.cur.skip_ws();
        let explicit = self.cur.peek() == Some('=');
        if explicit {
            self.cur.bump();
            self.cur.skip_ws();
        }
        if kind == Kind::Ident {
            if let Some(word) = self.cur.scan_drive_ident() {
                return Ok(Expr::Str(word));
            }
        }
        let t = self.cur.peek_token()?;
        match &t.kind {
            TokenKind::End | TokenKind::Punct(']') => {
                return Err(ParseError::at(
                    t.span,
                    format!(
                        "expected a value after {key} in {what} [...], found {}",
                        t.kind.describe()
                    ),
                ))
            }
            TokenKind::Ident(name) if self.is_bare_word(name, t.span)? => {
                if !explicit && find_key(specs, name).is_some() {
                    return Err(ParseError::at(
                        t.span,
                        format!(
                            "expected a value after {key} in {what} [...], found the keyword \
                             {name}"
                        ),
                    ));
                }
                let mut word = name.clone();
                self.cur.next_token()?;
                if key == "KEY" {
                    if let Some(second) = self.second_key_word(specs)? {
                        word.push('_');
                        word.push_str(&second);
                    }
                }
                return Ok(Expr::Str(word));
            }
            _ => {}
        }
        Ok(self.expr(1)?.0)
    }

    /// An identifier token `name` (already peeked, not consumed) is a bare word: not a
    /// parameter `P<n>` and not followed by `[` (a function call).
    fn is_bare_word(&self, name: &str, span: Span) -> PResult<bool> {
        if param_number(name, span)?.is_some() {
            return Ok(false);
        }
        let mut look = self.cur.clone();
        look.next_token()?;
        Ok(look.peek_token()?.kind != TokenKind::Punct('['))
    }

    /// The `KEY=TORQUE LIMIT` leniency: the next token, consumed, if it is a second bare word
    /// that is not a keyword of `specs` and not followed by `=` or `[`.
    fn second_key_word(&mut self, specs: &[KeySpec]) -> PResult<Option<String>> {
        let t = self.cur.peek_token()?;
        let TokenKind::Ident(name) = t.kind else {
            return Ok(None);
        };
        if find_key(specs, &name).is_some() || param_number(&name, t.span)?.is_some() {
            return Ok(None);
        }
        let mut look = self.cur.clone();
        look.next_token()?;
        if matches!(look.peek_token()?.kind, TokenKind::Punct('=' | '[')) {
            return Ok(None);
        }
        self.cur = look;
        Ok(Some(name))
    }

    /// `#MSG [SYN] ["format", expr, …]` (FCT-C4 §5).
    fn msg(&mut self) -> PResult<Command> {
        self.continue_at_next_line_bracket();
        let mut t = self.expect_token("'SYN' or '[' after #MSG")?;
        let mut sync = false;
        if t.kind == TokenKind::Ident("SYN".to_string()) {
            sync = true;
            self.continue_at_next_line_bracket();
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
