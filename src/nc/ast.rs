//! Block AST of the NC language subset (DIN 66025 + the seeds' `#` commands).
//!
//! The parser ([`super::parser::parse`]) produces a [`Program`]; the executor walks it. Every node keeps
//! its [`Span`] so that errors name line and column.

/// 1-based line and column in the program source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Span {
    /// 1-based line.
    pub line: u32,
    /// 1-based column (in characters).
    pub col: u32,
}

/// A parsed NC program.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Program {
    /// The name after `%` on the first line, if any.
    pub name: Option<String>,
    /// Blocks in source order (empty and comment-only lines are dropped). Shared: a clone of
    /// the program (the executor's, the run's check) does not copy the blocks, so a large
    /// program is held once (issue 28 item 9).
    pub blocks: std::sync::Arc<Vec<Block>>,
}

/// One NC block (one logical line; `\` at the end of a line continues it).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Block {
    /// Where the block starts.
    pub span: Span,
    /// `N` block number.
    pub number: Option<u32>,
    /// Words and commands in source order.
    pub items: Vec<Item>,
}

/// One word or command of a block.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// `G<code>`, e.g. `G01` → 1, `G161` → 161.
    G {
        /// The G number.
        code: u32,
        /// Position of the `G`.
        span: Span,
    },
    /// `M<code>`.
    M {
        /// The M number.
        code: u32,
        /// Position of the `M`.
        span: Span,
    },
    /// `F<expr>` feed in mm/min (°/min).
    F {
        /// Feed value.
        value: Expr,
        /// Position of the `F`.
        span: Span,
    },
    /// An axis word: `X10`, `X-1.5`, `X[10+2]`, `X2=100`, `Z=V.A.ABS.Z`.
    Axis {
        /// Axis name as written (`X`, `X2`, `A`).
        name: String,
        /// The value.
        value: Expr,
        /// Position of the axis letter.
        span: Span,
    },
    /// Circle centre offset `I`, `J` or `K` (relative to the start point).
    Centre {
        /// `'I'`, `'J'` or `'K'`.
        letter: char,
        /// The value.
        value: Expr,
        /// Position of the letter.
        span: Span,
    },
    /// `D<expr>`: select tool offset number (probe ball radius, FCT-C4 §5 meas_example).
    D {
        /// Tool offset number.
        value: Expr,
        /// Position of the `D`.
        span: Span,
    },
    /// An independent-axis motion: `X[INDP_SYN G100 G90 POS100 FEED500]` (FCT-C4 §2).
    Independent {
        /// Axis name.
        axis: String,
        /// The motion (boxed: it is the largest item and rare, so every other item stays
        /// small).
        motion: Box<IndependentMotion>,
        /// Position of the axis letter.
        span: Span,
    },
    /// Arithmetic parameter assignment `P1 = <expr>` (a block of its own).
    Assign {
        /// Parameter number.
        param: u32,
        /// Value.
        value: Expr,
        /// Position of the `P`.
        span: Span,
    },
    /// A `#` control command.
    Command {
        /// The command (boxed, as [`Item::Independent`]'s motion).
        command: Box<Command>,
        /// Position of the `#`.
        span: Span,
    },
}

/// The bracket of an independent-axis word: `[INDP_SYN G100 G90 POS100 FEED500]`.
#[derive(Debug, Clone, PartialEq)]
pub struct IndependentMotion {
    /// `INDP_SYN` (true; the block waits for the motion at its end) or `INDP_ASYN`.
    pub sync: bool,
    /// G codes inside the bracket (e.g. 100, 90, 91, 0, 1).
    pub gcodes: Vec<u32>,
    /// `POS<expr>` target.
    pub pos: Expr,
    /// `FEED<expr>` feed in mm/min.
    pub feed: Option<Expr>,
}

/// One assignment of a bracketed keyword list: `AXNR=2`, `SIGNAL=PLC`, `WAIT`.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyArg {
    /// Keyword, upper-cased (`AXNR`, `SIGNAL`, `KEY`, `VAL`, `P`, `TYP`, `DEC`, `SERC`, `WAIT`).
    pub key: String,
    /// Value: an expression, a bare word (`PLC`, `TORQUE_LIMIT`, `S-0-0092`) as [`Expr::Str`],
    /// or `None` for a flag (`WAIT`, `SERC`).
    pub value: Option<Expr>,
    /// Position of the keyword.
    pub span: Span,
}

/// `#` control commands.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `#MSG ["fmt", expr, …]` or `#MSG SYN ["fmt", expr, …]`.
    Msg {
        /// `SYN`: output synchronous with block execution (all prior motion done).
        sync: bool,
        /// The printf-style format string.
        format: String,
        /// Arguments.
        args: Vec<Expr>,
    },
    /// `#MEAS MODE [expr]` / `#MEAS MODE` (back to P-CHAN-00057).
    MeasMode {
        /// The type, or `None` for the channel default.
        mode: Option<Expr>,
    },
    /// `#MEAS [AXNR=.. SIGNAL=.. INPUT=.. EDGE=..]`: per-axis signal source override (P-AXIS-00516
    /// / 00517 / 00518 for the program).
    MeasConfig {
        /// The keyword list as written.
        args: Vec<KeyArg>,
    },
    /// `#MEAS PREPARE [AXNR=.. {AXNR=..}]` (FCT-C4 §7.2).
    MeasPrepare {
        /// The keyword list as written.
        args: Vec<KeyArg>,
    },
    /// `#CS ON [x, y, z, a, b, c]` (missing values are 0) / `#CS OFF`.
    Cs {
        /// `None` for OFF.
        on: Option<Vec<Expr>>,
    },
    /// `#TRAFO ON` / `#TRAFO OFF` — recognised so that it can be refused clearly.
    Trafo {
        /// ON.
        on: bool,
    },
    /// `#DRIVE WR [SYN] [AX=.. KEY=.. VAL=.. WAIT]` / `#DRIVE RD [SYN] [AX=.. KEY=.. P=Pn]`.
    Drive {
        /// WR (true) or RD.
        write: bool,
        /// SYN.
        sync: bool,
        /// The keyword list as written.
        args: Vec<KeyArg>,
    },
    /// `#IDENT WR|RD [SYN] [AXNR .. ID .. VAL=|P= TYP .. DEC .. SERC]` (FCT-C4 §7.3.1). Keywords
    /// may be written with or without `=` (`AXNR 1`, `AXNR=1`).
    Ident {
        /// WR (true) or RD.
        write: bool,
        /// SYN.
        sync: bool,
        /// The keyword list as written.
        args: Vec<KeyArg>,
    },
    /// `#SET AX LINK [group, [slave=master, G, p1, p2] …]` (gantry coupling, FCT-C4 §7.3.1).
    SetAxLink {
        /// Link group number.
        group: Expr,
        /// Couplings.
        links: Vec<AxLink>,
    },
    /// `#CONTROL AREA BEGIN|START [..]`, `END`, `ON`, `OFF`, `CLEAR` (FCT-C14 §3).
    ControlArea {
        /// The parsed area command.
        command: crate::core::monitor::areas::AreaCommand,
    },
    /// `#ENABLE AX LINK [group]` / `#DISABLE AX LINK [group]`.
    EnableAxLink {
        /// Enable (true) or disable.
        enable: bool,
        /// Link group number (`None` = all).
        group: Option<Expr>,
    },
}

/// One coupling of `#SET AX LINK`: `[X2=X, G, 15, 20]` — slave X2 follows master X as a gantry
/// (`G`), with the two monitoring parameters as written.
#[derive(Debug, Clone, PartialEq)]
pub struct AxLink {
    /// Slave axis name.
    pub slave: String,
    /// Master axis name.
    pub master: String,
    /// Coupling kind as written (`G` = gantry).
    pub kind: String,
    /// Further parameters as written.
    pub params: Vec<Expr>,
}

/// Expression (inside `[...]`, after an address letter, or as a `#MSG` argument).
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// Numeric literal.
    Num(f64),
    /// String literal `"..."`.
    Str(String),
    /// Variable such as `V.A.ABS.X` or `V.A.-SWE.X`.
    Var(VarRef),
    /// Unary minus / plus.
    Neg(Box<Expr>),
    /// Binary arithmetic.
    Bin(BinOp, Box<Expr>, Box<Expr>),
    /// Arithmetic parameter `P<n>`.
    Param(u32, Span),
    /// Function call: `ABS[x]`, `SQRT[x]`, `SIN[x]` (degrees), `COS[x]`, `TAN[x]`, `ATAN2[y, x]`,
    /// `INT[x]` (truncate), `ROUND[x]`.
    ///
    /// Name and arguments are boxed slices (16 bytes each instead of 24), which keeps every
    /// [`Expr`], and so every axis word, 16 bytes smaller.
    Call(Box<str>, Box<[Expr]>, Span),
}

/// Binary operators (`+ - * /`), usual precedence, left associative.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
}

/// A variable reference, split at `.`: `V.A.-SWE.X` → `["V", "A", "-SWE", "X"]`.
/// Segments are upper-cased by the parser.
#[derive(Debug, Clone, PartialEq)]
pub struct VarRef {
    /// Dot-separated segments.
    pub segments: Vec<String>,
    /// Position of the `V`.
    pub span: Span,
}

impl VarRef {
    /// The variable as written (`V.A.ABS.X`).
    pub fn name(&self) -> String {
        self.segments.join(".")
    }
}
