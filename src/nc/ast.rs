//! Block AST of the NC language subset (DIN 66025 + the seeds' `#` commands).
//!
//! The parser ([`super::parse`]) produces a [`Program`]; the executor walks it. Every node keeps
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
    /// Blocks in source order (empty and comment-only lines are dropped).
    pub blocks: Vec<Block>,
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
    /// A `#` control command.
    Command {
        /// The command.
        command: Command,
        /// Position of the `#`.
        span: Span,
    },
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
    /// Function call: `ABS[x]`, `SQRT[x]`, `SIN[x]` (degrees), `COS[x]`, `TAN[x]`, `ATAN2[y, x]`,
    /// `INT[x]` (truncate), `ROUND[x]`.
    Call(String, Vec<Expr>, Span),
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
