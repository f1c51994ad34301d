//! Evaluation of NC expressions (`[…]` values, `#MSG` arguments).
//!
//! Numbers are `f64` (mm, degrees, as programmed); strings exist only as `#MSG` arguments and
//! literals. Arithmetic follows the usual rules; trigonometric functions take and return
//! **degrees** (ISG convention, e.g. the `#CS ON[…]` angles of FCT-C4 §4). Every error carries a
//! [`Span`] so the executor can say where the program went wrong.
//!
//! Spans: variables and function calls carry their own span in the AST. Operators and literals do
//! not, so errors raised by them (division by zero, string arithmetic, overflow) are reported at the
//! nearest enclosing function call, or else at the `fallback` span given to [`eval_at`] — the
//! executor passes the span of the word (`X`, `F`, `#MSG`) that holds the expression. [`eval`]
//! uses the first variable or call in the expression as its fallback, or [`Span::default`]
//! (line 0, column 0) for a constant expression.

use super::ast::{BinOp, Expr, Span, VarRef};

/// Deepest expression tree [`eval`] accepts (the parser never builds a deeper one).
pub const MAX_EXPR_HEIGHT: usize = 256;

/// Value of an expression.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number (mm, degrees, feed …).
    Num(f64),
    /// A string (only useful as a `#MSG` argument).
    Str(String),
}

impl std::fmt::Display for Value {
    /// Numbers in their shortest round-trip form without exponent (`20`, `0.1`), strings as-is.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Num(n) => write!(f, "{n}"),
            Value::Str(s) => f.write_str(s),
        }
    }
}

/// Where variable values come from (the executor implements this over the channel state:
/// `V.A.ABS.X`, `V.A.MESS.Z`, `V.A.-SWE.X` …).
pub trait VarSource {
    /// The value of `var`, or a message such as "unknown variable V.A.FOO.X".
    fn var(&self, var: &VarRef) -> Result<Value, String>;

    /// The value of arithmetic parameter `P<n>`, or a message. Unset parameters are an error.
    fn param(&self, n: u32) -> Result<f64, String> {
        Err(format!("P{n} has no value"))
    }
}

/// A variable source without variables (every lookup fails).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoVars;

impl VarSource for NoVars {
    fn var(&self, var: &VarRef) -> Result<Value, String> {
        Err(format!("unknown variable {}", var.name()))
    }
}

/// An expression could not be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {}, column {}: {message}", span.line, span.col)]
pub struct EvalError {
    /// Where (see the module documentation for how operator errors are located).
    pub span: Span,
    /// What went wrong.
    pub message: String,
}

/// Built-in functions and their number of arguments: `ABS SQRT SIN COS TAN ATAN2 INT ROUND`.
/// The parser checks names and arity against this table; [`eval`] checks again for hand-built
/// trees.
pub const FUNCTIONS: &[(&str, usize)] = &[
    ("ABS", 1),
    ("SQRT", 1),
    ("SIN", 1),
    ("COS", 1),
    ("TAN", 1),
    ("ATAN2", 2),
    ("INT", 1),
    ("ROUND", 1),
];

/// Number of arguments of the built-in function `name` (upper case), `None` if unknown.
pub fn function_arity(name: &str) -> Option<usize> {
    FUNCTIONS.iter().find(|(n, _)| *n == name).map(|&(_, a)| a)
}

/// Evaluate `expr`; errors without a span of their own use the first variable / call span in
/// `expr` (see the module documentation). Prefer [`eval_at`] when the enclosing word is known.
pub fn eval(expr: &Expr, vars: &dyn VarSource) -> Result<Value, EvalError> {
    eval_at(expr, vars, first_span(expr, 0).unwrap_or_default())
}

/// Evaluate `expr` to a number; a string value is an error.
pub fn eval_num(expr: &Expr, vars: &dyn VarSource) -> Result<f64, EvalError> {
    eval_num_at(expr, vars, first_span(expr, 0).unwrap_or_default())
}

/// Evaluate `expr`, reporting errors of span-less nodes at `fallback` (the span of the enclosing
/// word, e.g. [`crate::nc::ast::Item::Axis`]'s `span`).
pub fn eval_at(expr: &Expr, vars: &dyn VarSource, fallback: Span) -> Result<Value, EvalError> {
    Evaluator { vars }.eval(expr, fallback, 0)
}

/// [`eval_at`] for a numeric result.
pub fn eval_num_at(expr: &Expr, vars: &dyn VarSource, fallback: Span) -> Result<f64, EvalError> {
    match eval_at(expr, vars, fallback)? {
        Value::Num(n) => Ok(n),
        Value::Str(_) => Err(EvalError {
            span: fallback,
            message: "expected a number, found a string".to_string(),
        }),
    }
}

fn first_span(expr: &Expr, depth: usize) -> Option<Span> {
    if depth > MAX_EXPR_HEIGHT {
        return None;
    }
    match expr {
        Expr::Num(_) | Expr::Str(_) => None,
        Expr::Var(v) => Some(v.span),
        Expr::Param(_, span) => Some(*span),
        Expr::Call(_, _, span) => Some(*span),
        Expr::Neg(e) => first_span(e, depth + 1),
        Expr::Bin(_, a, b) => first_span(a, depth + 1).or_else(|| first_span(b, depth + 1)),
    }
}

fn fail<T>(span: Span, message: impl Into<String>) -> Result<T, EvalError> {
    Err(EvalError {
        span,
        message: message.into(),
    })
}

fn op_symbol(op: BinOp) -> char {
    match op {
        BinOp::Add => '+',
        BinOp::Sub => '-',
        BinOp::Mul => '*',
        BinOp::Div => '/',
    }
}

fn finite(v: f64, span: Span, what: impl FnOnce() -> String) -> Result<Value, EvalError> {
    if v.is_finite() {
        Ok(Value::Num(v))
    } else {
        fail(span, format!("{} is not a finite number", what()))
    }
}

/// `sin` in degrees, exact at multiples of 90°.
fn sin_deg(x: f64) -> f64 {
    let r = x.rem_euclid(360.0);
    match r {
        0.0 | 180.0 | 360.0 => 0.0,
        90.0 => 1.0,
        270.0 => -1.0,
        _ => r.to_radians().sin(),
    }
}

/// `cos` in degrees, exact at multiples of 90°.
fn cos_deg(x: f64) -> f64 {
    sin_deg(x + 90.0)
}

struct Evaluator<'v> {
    vars: &'v dyn VarSource,
}

impl Evaluator<'_> {
    fn num(&self, e: &Expr, at: Span, depth: usize, what: &str) -> Result<f64, EvalError> {
        match self.eval(e, at, depth)? {
            Value::Num(n) => Ok(n),
            Value::Str(_) => fail(at, format!("{what} needs a number, found a string")),
        }
    }

    fn eval(&self, expr: &Expr, at: Span, depth: usize) -> Result<Value, EvalError> {
        if depth > MAX_EXPR_HEIGHT {
            return fail(
                at,
                format!("expression is nested deeper than {MAX_EXPR_HEIGHT} levels"),
            );
        }
        match expr {
            Expr::Num(n) => finite(*n, at, || "number literal".to_string()),
            Expr::Str(s) => Ok(Value::Str(s.clone())),
            Expr::Var(v) => match self.vars.var(v) {
                Ok(Value::Num(n)) => finite(n, v.span, || format!("variable {}", v.name())),
                Ok(s @ Value::Str(_)) => Ok(s),
                Err(message) => fail(v.span, message),
            },
            Expr::Param(n, span) => match self.vars.param(*n) {
                Ok(x) => finite(x, *span, || format!("P{n}")),
                Err(message) => fail(*span, message),
            },
            Expr::Neg(e) => {
                let n = self.num(e, at, depth + 1, "unary '-'")?;
                Ok(Value::Num(-n))
            }
            Expr::Bin(op, a, b) => {
                let sym = op_symbol(*op);
                let what = format!("operator '{sym}'");
                let x = self.num(a, at, depth + 1, &what)?;
                let y = self.num(b, at, depth + 1, &what)?;
                let r = match op {
                    BinOp::Add => x + y,
                    BinOp::Sub => x - y,
                    BinOp::Mul => x * y,
                    BinOp::Div => {
                        if y == 0.0 {
                            return fail(at, format!("division by zero ({x} / 0)"));
                        }
                        x / y
                    }
                };
                finite(r, at, || format!("result of {x} {sym} {y}"))
            }
            Expr::Call(name, args, span) => self.call(name, args, *span, depth),
        }
    }

    fn call(
        &self,
        name: &str,
        args: &[Expr],
        span: Span,
        depth: usize,
    ) -> Result<Value, EvalError> {
        let upper = name.to_ascii_uppercase();
        let Some(arity) = function_arity(&upper) else {
            return fail(span, format!("unknown function {name}"));
        };
        if args.len() != arity {
            return fail(
                span,
                format!(
                    "{upper} takes {arity} argument{}, found {}",
                    if arity == 1 { "" } else { "s" },
                    args.len()
                ),
            );
        }
        let what = format!("function {upper}");
        let mut v = Vec::with_capacity(args.len());
        for a in args {
            v.push(self.num(a, span, depth + 1, &what)?);
        }
        let x = v[0];
        let r = match upper.as_str() {
            "ABS" => x.abs(),
            "SQRT" => {
                if x < 0.0 {
                    return fail(span, format!("SQRT of a negative number ({x})"));
                }
                x.sqrt()
            }
            "SIN" => sin_deg(x),
            "COS" => cos_deg(x),
            "TAN" => {
                let c = cos_deg(x);
                if c == 0.0 {
                    return fail(span, format!("TAN of {x}° is undefined"));
                }
                sin_deg(x) / c
            }
            "ATAN2" => x.atan2(v[1]).to_degrees(),
            "INT" => x.trunc(),
            "ROUND" => x.round(),
            _ => return fail(span, format!("unknown function {name}")),
        };
        finite(r, span, || format!("result of {upper}"))
    }
}
