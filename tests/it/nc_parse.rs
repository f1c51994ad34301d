//! NC front end: lexer, parser, expression evaluation and `#MSG` printf formatting.
//!
//! The seed programs (seed 001 §3, seed 004 §2/§5, seed 000 §3/§4) are acceptance material: they
//! must parse to the blocks written in the documents.

use crate::common::test_data;

use std::collections::HashMap;
use std::path::Path;
use std::sync::OnceLock;

use fieldprobe::nc::ast::{
    AxLink, BinOp, Block, Command, Expr, IndependentMotion, Item, KeyArg, Program, Span, VarRef,
};
use fieldprobe::nc::expr::{eval, eval_at, eval_num, eval_num_at, EvalError, Value, VarSource};
use fieldprobe::nc::parser::{parse, parse_expr, ParseError};
use fieldprobe::nc::printf::{format, FormatError};
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// helpers

fn sp(line: u32, col: u32) -> Span {
    Span { line, col }
}

fn ok(src: &str) -> Program {
    match parse(src) {
        Ok(p) => p,
        Err(e) => panic!("parse failed: {e}\n--- source ---\n{src}"),
    }
}

fn fail(src: &str) -> ParseError {
    match parse(src) {
        Ok(p) => panic!("expected a parse error, got {p:?}\n--- source ---\n{src}"),
        Err(e) => e,
    }
}

/// Compact rendering of a block for comparisons: `N10 G1 G90 X199`.
fn show_expr(e: &Expr) -> String {
    match e {
        Expr::Num(n) => format!("{n}"),
        Expr::Str(s) => format!("{s:?}"),
        Expr::Var(v) => v.name(),
        Expr::Neg(e) => format!("-({})", show_expr(e)),
        Expr::Bin(op, a, b) => {
            let o = match op {
                BinOp::Add => '+',
                BinOp::Sub => '-',
                BinOp::Mul => '*',
                BinOp::Div => '/',
            };
            format!("({} {o} {})", show_expr(a), show_expr(b))
        }
        Expr::Call(n, args, _) => {
            let a: Vec<String> = args.iter().map(show_expr).collect();
            format!("{n}[{}]", a.join(", "))
        }
        Expr::Param(n, _) => format!("P{n}"),
    }
}

fn show_keys(args: &[KeyArg]) -> String {
    let a: Vec<String> = args
        .iter()
        .map(|k| match &k.value {
            Some(v) => format!("{}={}", k.key, show_expr(v)),
            None => k.key.clone(),
        })
        .collect();
    format!("[{}]", a.join(" "))
}

fn show_exprs(args: &[Expr]) -> String {
    let a: Vec<String> = args.iter().map(show_expr).collect();
    a.join(", ")
}

fn show_command(c: &Command) -> String {
    let syn = |s: bool| if s { " SYN" } else { "" };
    let rw = |w: bool| if w { "WR" } else { "RD" };
    match c {
        Command::Msg { sync, format, args } => format!(
            "#MSG{}[{format:?}{}{}]",
            syn(*sync),
            if args.is_empty() { "" } else { ", " },
            show_exprs(args)
        ),
        Command::MeasMode { mode: Some(m) } => format!("#MEAS MODE[{}]", show_expr(m)),
        Command::MeasMode { mode: None } => "#MEAS MODE".to_string(),
        Command::MeasConfig { args } => format!("#MEAS{}", show_keys(args)),
        Command::MeasPrepare { args } => format!("#MEAS PREPARE{}", show_keys(args)),
        Command::Cs { on: Some(v) } => format!("#CS ON[{}]", show_exprs(v)),
        Command::Cs { on: None } => "#CS OFF".to_string(),
        Command::Trafo { on } => format!("#TRAFO {}", if *on { "ON" } else { "OFF" }),
        Command::Drive { write, sync, args } => {
            format!("#DRIVE {}{}{}", rw(*write), syn(*sync), show_keys(args))
        }
        Command::Ident { write, sync, args } => {
            format!("#IDENT {}{}{}", rw(*write), syn(*sync), show_keys(args))
        }
        Command::SetAxLink { group, links } => {
            let l: Vec<String> = links
                .iter()
                .map(|l| {
                    let mut parts = vec![format!("{}={}", l.slave, l.master), l.kind.clone()];
                    parts.extend(l.params.iter().map(show_expr));
                    format!("[{}]", parts.join(", "))
                })
                .collect();
            format!("#SET AX LINK[{}, {}]", show_expr(group), l.join(", "))
        }
        Command::ControlArea { command } => format!("#CONTROL AREA {command:?}"),
        Command::EnableAxLink { enable, group } => format!(
            "#{} AX LINK{}",
            if *enable { "ENABLE" } else { "DISABLE" },
            group
                .as_ref()
                .map_or(String::new(), |g| format!("[{}]", show_expr(g)))
        ),
    }
}

fn show(b: &Block) -> String {
    let mut parts = Vec::new();
    if let Some(n) = b.number {
        parts.push(format!("N{n}"));
    }
    for it in &b.items {
        parts.push(match it {
            Item::G { code, .. } => format!("G{code}"),
            Item::M { code, .. } => format!("M{code}"),
            Item::F { value, .. } => format!("F{}", show_expr(value)),
            Item::Axis { name, value, .. } => format!("{name}{}", show_expr(value)),
            Item::Centre { letter, value, .. } => format!("{letter}{}", show_expr(value)),
            Item::D { value, .. } => format!("D{}", show_expr(value)),
            Item::Independent { axis, motion, .. } => {
                let mut parts =
                    vec![if motion.sync { "INDP_SYN" } else { "INDP_ASYN" }.to_string()];
                parts.extend(motion.gcodes.iter().map(|g| format!("G{g}")));
                parts.push(format!("POS{}", show_expr(&motion.pos)));
                if let Some(f) = &motion.feed {
                    parts.push(format!("FEED{}", show_expr(f)));
                }
                format!("{axis}[{}]", parts.join(" "))
            }
            Item::Assign { param, value, .. } => format!("P{param}={}", show_expr(value)),
            Item::Command { command, .. } => show_command(command),
        });
    }
    parts.join(" ")
}

fn shows(p: &Program) -> Vec<String> {
    p.blocks.iter().map(show).collect()
}

/// Variables from a map, keyed by the variable name as written (`V.A.ABS.X`).
struct Vars(HashMap<String, Value>);

impl Vars {
    fn new(pairs: &[(&str, f64)]) -> Self {
        Vars(
            pairs
                .iter()
                .map(|(k, v)| (k.to_string(), Value::Num(*v)))
                .collect(),
        )
    }
}

impl VarSource for Vars {
    fn var(&self, var: &VarRef) -> Result<Value, String> {
        self.0
            .get(&var.name())
            .cloned()
            .ok_or_else(|| format!("unknown variable {}", var.name()))
    }
}

fn num(src: &str) -> f64 {
    let e = parse_expr(src).unwrap_or_else(|e| panic!("{src}: {e}"));
    eval_num(&e, &Vars::new(&[])).unwrap_or_else(|e| panic!("{src}: {e}"))
}

// ---------------------------------------------------------------------------------------------
// seed programs

/// Seed 001 §3.1, example 1 (absolute negative SLS).
#[test]
fn seed_001_3_1_swe_abs() {
    let src = "%swe_abs.nc  \nN110 G00 X0 Y0 G90  \nN120 G00 X20 Y30  \n  \n\
               (Sets neg. SLS in X to -100 and Y to -200)  \nN130 G98 X-100 Y-200  \n  \n( .... )\n";
    let p = ok(src);
    assert_eq!(p.name.as_deref(), Some("swe_abs.nc"));
    assert_eq!(
        shows(&p),
        [
            "N110 G0 X0 Y0 G90",
            "N120 G0 X20 Y30",
            "N130 G98 X-100 Y-200"
        ]
    );
    assert_eq!(p.blocks[2].span, sp(6, 1));
    // Spans of the words of N130.
    let spans: Vec<Span> = p.blocks[2]
        .items
        .iter()
        .map(|i| match i {
            Item::G { span, .. } | Item::Axis { span, .. } => *span,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(spans, [sp(6, 6), sp(6, 10), sp(6, 16)]);
}

/// Seed 001 §3.1 example 2 and §3.2 examples (relative SLS, positive SLS, `(....)` lines).
#[test]
fn seed_001_3_1_and_3_2_relative_and_positive() {
    let p = ok("%swe_rel.nc\nN110 G00 X0 Y0 G90\nN120 G00 X20 Y30\n\n\
                (Offsets neg. SLS in X by 10 and Y by 20)\nN130 G98 G91 X10 Y20\n\n( .... )\n");
    assert_eq!(p.name.as_deref(), Some("swe_rel.nc"));
    assert_eq!(shows(&p)[2], "N130 G98 G91 X10 Y20");

    let p = ok("%swe_abs.nc\nN110 G00 X0 Y0 G90\nN120 G00 X20 Y30\n\
                (Sets pos. SLS in X to 100 and Y to 200)\nN130 G99 X100 Y200\n(....)\n");
    assert_eq!(shows(&p)[2], "N130 G99 X100 Y200");
    let p = ok("%swe_rel.nc\nN130 G99 G91 X-10 Y-20\n(....)\n");
    assert_eq!(shows(&p), ["N130 G99 G91 X-10 Y-20"]);
}

/// Seed 001 §3.3: extended limits with G98 / G99, `;` comments and `...` placeholder lines.
#[test]
fn seed_001_3_3_extensions_to_g98_g99() {
    let src = ";Assuming: Software limit switches are configured to +- 200 in X, Y  \n\
N10 G01 G90 X199  \n\
...  \n\
N100 G98 X-500 Y-500 ;neg. Software limit switches X and Y -> -500  \n\
N200 G99 X500 Y500 ;pos. Software limit switches X and Y -> +500  \n\
N300 G01 X450 Y450 ;Move within extended section  \n\
...  \n\
N400 G01 X100 Y100 ;Back to limited section  \n\
N500 G98 X-200 Y-200 ;neg. Software limit switches X and Y -> -200  \n\
N600 G99 X200 Y200 ;pos. Software limit switches X and Y -> 200  \n\
...\n";
    let p = ok(src);
    assert_eq!(p.name, None);
    assert_eq!(
        shows(&p),
        [
            "N10 G1 G90 X199",
            "N100 G98 X-500 Y-500",
            "N200 G99 X500 Y500",
            "N300 G1 X450 Y450",
            "N400 G1 X100 Y100",
            "N500 G98 X-200 Y-200",
            "N600 G99 X200 Y200",
        ]
    );
    assert_eq!(p.blocks[0].span, sp(2, 1));
    assert_eq!(p.blocks[1].span, sp(4, 1));
    // Exact AST of N100.
    assert_eq!(
        p.blocks[1],
        Block {
            span: sp(4, 1),
            number: Some(100),
            items: vec![
                Item::G {
                    code: 98,
                    span: sp(4, 6)
                },
                Item::Axis {
                    name: "X".into(),
                    value: Expr::Num(-500.0),
                    span: sp(4, 10)
                },
                Item::Axis {
                    name: "Y".into(),
                    value: Expr::Num(-500.0),
                    span: sp(4, 16)
                },
            ],
        }
    );
}

/// Seed 004 §2: measurement with G100.
#[test]
fn seed_004_2_meas_run() {
    let p = ok("%Meas_run\nN10 G00 X0 Y0 Z0\nN20 X5\nN30 G100 X10 Y10 F500\nN40 G01 X7\nN50 M30\n");
    assert_eq!(p.name.as_deref(), Some("Meas_run"));
    assert_eq!(
        shows(&p),
        [
            "N10 G0 X0 Y0 Z0",
            "N20 X5",
            "N30 G100 X10 Y10 F500",
            "N40 G1 X7",
            "N50 M30"
        ]
    );
}

/// Seed 004 §4: 2.5D example program (names with blanks, indented comment lines).
#[test]
fn seed_004_4_measurement_run_standard() {
    let src = "%Measurement run standard\nN10 G00 X0 Y1 Z0\nN20 X5\nN30 G100 X10 F500\n\
               ;Wait for probing signal from X\nN40 G01 Y3\n                        \
               ;Wait for probing signal from Y\nN50 G100 Y10 F500\nN60 G01 X10 Y5\n\
               N70 G100 X15 Y10 F500\n                        ;Wait for probing signal from X & Y\n\
               N100 M30\n";
    let p = ok(src);
    assert_eq!(p.name.as_deref(), Some("Measurement run standard"));
    assert_eq!(p.blocks.len(), 8);
    assert_eq!(shows(&p)[6], "N70 G100 X15 Y10 F500");
}

/// Seed 004 §5 meas1 (the `-> …` result annotations of the document removed; `#MEAS MODE` is
/// not part of this front end yet). `#MSG SYN[` blocks printed over two lines join because the
/// `[` is still open.
#[test]
fn seed_004_5_meas1_messages() {
    let src = "%meas1\n\
N10 G01 G90 Z200 F2000\n\
N20 G100 Z20 F2000\n\
N30 #MSG SYN[\"V.A.MESS.Z=%f\", V.A.MESS.Z]\n\
N31 #MSG SYN[\"V.A.MEAS.ACS.VALUE.Z=%f\",\n                                 V.A.MEAS.ACS.VALUE.Z]\n\
N32 #MSG SYN[\"V.A.MEAS.PCS.VALUE.Z=%f\",\n                                 V.A.MEAS.PCS.VALUE.Z]\n\
N40 #MSG SYN[\"V.A.MOFFS.Z=%f\", V.A.MOFFS.Z]\n\
N50 #MSG SYN[\"V.A.MEIN.Z=%f\", V.A.MEIN.Z]\n\
N60 G101 Z1\n\
N80 G01 Z100 F1000\n\
N100 G102 Z1\n\
N140 M30\n";
    let p = ok(src);
    assert_eq!(
        shows(&p),
        [
            "N10 G1 G90 Z200 F2000",
            "N20 G100 Z20 F2000",
            "N30 #MSG SYN[\"V.A.MESS.Z=%f\", V.A.MESS.Z]",
            "N31 #MSG SYN[\"V.A.MEAS.ACS.VALUE.Z=%f\", V.A.MEAS.ACS.VALUE.Z]",
            "N32 #MSG SYN[\"V.A.MEAS.PCS.VALUE.Z=%f\", V.A.MEAS.PCS.VALUE.Z]",
            "N40 #MSG SYN[\"V.A.MOFFS.Z=%f\", V.A.MOFFS.Z]",
            "N50 #MSG SYN[\"V.A.MEIN.Z=%f\", V.A.MEIN.Z]",
            "N60 G101 Z1",
            "N80 G1 Z100 F1000",
            "N100 G102 Z1",
            "N140 M30",
        ]
    );
    // The variable on the continuation line keeps its own position.
    let Item::Command { command, span } = &p.blocks[3].items[0] else {
        panic!()
    };
    let Command::Msg { args, .. } = &**command else {
        panic!()
    };
    assert_eq!(*span, sp(5, 5));
    let Expr::Var(v) = &args[0] else { panic!() };
    assert_eq!(v.span, sp(6, 34));
    assert_eq!(v.segments, ["V", "A", "MEAS", "ACS", "VALUE", "Z"]);
}

/// Seed 000 §3.1 POLY and CIRC geometry blocks (between `#CONTROL AREA BEGIN/END`).
#[test]
fn seed_000_3_1_area_geometry_blocks() {
    let p = ok(
        "N20 G01 F1000 G90 X-150 Y75 (Starting point)\nN30 X-50 Y150\n\
                N130 X-150 Y75 (End point identical with starting point)\n\
                N20 G01 X0 Y0 F10000      (Start point for cyl. protection space)\n\
                N30 G02 G162 I0 J75       (Definition of the full circle)\n",
    );
    assert_eq!(
        shows(&p),
        [
            "N20 G1 F1000 G90 X-150 Y75",
            "N30 X-50 Y150",
            "N130 X-150 Y75",
            "N20 G1 X0 Y0 F10000",
            "N30 G2 G162 I0 J75"
        ]
    );
}

/// Seed 000 §4: indexed axis names `X2=100`, also with blanks around `=`, `:` placeholders.
#[test]
fn seed_000_4_indexed_axes() {
    let p = ok(
        ":\nN20 G01 F1000 G90 X2=100 Y2=100 ;Starting point\nN30 X2=-100\nN40 Y2=-100\n\
                N50 X2=100\nN60 X2 = 100 Y2= 100 ; End point identical with starting point\n:\n\
                N1000 M30\n",
    );
    assert_eq!(
        shows(&p),
        [
            "N20 G1 F1000 G90 X2100 Y2100",
            "N30 X2-100",
            "N40 Y2-100",
            "N50 X2100",
            "N60 X2100 Y2100",
            "N1000 M30"
        ]
    );
    let Item::Axis { name, value, span } = &p.blocks[4].items[0] else {
        panic!()
    };
    assert_eq!(
        (name.as_str(), value, *span),
        ("X2", &Expr::Num(100.0), sp(6, 5))
    );
}

// ---------------------------------------------------------------------------------------------
// seed 004 programs, read verbatim from the seed document

/// The text of seed 004 (read once).
fn seed_004() -> &'static str {
    static TEXT: OnceLock<String> = OnceLock::new();
    TEXT.get_or_init(|| {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/seeds/004_7eddc17f286cb1c8.txt");
        std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read seed 004 at {}: {e}", path.display()))
    })
}

/// The `nth` (from 0) program of seed 004 whose first line is `%<name>`, up to the closing code
/// fence, with the seed's lines unchanged.
fn seed_program(name: &str, nth: usize) -> String {
    let header = format!("%{name}");
    let lines: Vec<&str> = seed_004().lines().collect();
    let start = lines
        .iter()
        .enumerate()
        .filter(|(_, l)| l.trim() == header)
        .map(|(i, _)| i)
        .nth(nth)
        .unwrap_or_else(|| panic!("program {header} #{nth} not found in seed 004"));
    let len = lines[start..]
        .iter()
        .position(|l| l.trim_start().starts_with("```"))
        .unwrap_or_else(|| panic!("program {header} has no closing code fence"));
    let mut text = lines[start..start + len].join("\n");
    text.push('\n');
    text
}

/// Drop the document's result annotations (`-> V.A.MESS.Z = 100.0`, `\rightarrow …`) of the
/// seed 004 §5 examples.
fn without_annotations(src: &str) -> String {
    src.lines()
        .filter(|l| {
            let t = l.trim_start();
            !(t.starts_with("->") || t.starts_with("\\rightarrow"))
        })
        .map(|l| format!("{l}\n"))
        .collect()
}

fn command_of(item: &Item) -> &Command {
    match item {
        Item::Command { command, .. } => command,
        other => panic!("expected a command, found {other:?}"),
    }
}

fn key(k: &str, value: Option<Expr>, span: Span) -> KeyArg {
    KeyArg {
        key: k.to_string(),
        value,
        span,
    }
}

fn word(s: &str) -> Option<Expr> {
    Some(Expr::Str(s.to_string()))
}

fn n(x: f64) -> Option<Expr> {
    Some(Expr::Num(x))
}

/// Seed 004 §2: measurement with G100, read from the seed.
#[test]
fn seed_004_2_meas_run_from_seed() {
    if !test_data::seeds_present("seed_004_2_meas_run_from_seed") {
        return;
    }
    let p = ok(&seed_program("Meas_run", 0));
    assert_eq!(p.name.as_deref(), Some("Meas_run"));
    assert_eq!(
        shows(&p),
        [
            "N10 G0 X0 Y0 Z0",
            "N20 X5",
            "N30 G100 X10 Y10 F500",
            "N40 G1 X7",
            "N50 M30"
        ]
    );
}

/// Seed 004 §2: independent axes, two independent words of one block joined by `\`.
#[test]
fn seed_004_2_independent_measurement_path() {
    if !test_data::seeds_present("seed_004_2_independent_measurement_path") {
        return;
    }
    let src = seed_program("Independent_measurement_path", 0);
    assert!(src.contains("FEED500] \\\n"), "{src}");
    let p = ok(&src);
    assert_eq!(p.name.as_deref(), Some("Independent_measurement_path"));
    assert_eq!(
        shows(&p),
        [
            "N10 G0 X0 Y0",
            "N20 X[INDP_SYN G100 G90 POS100 FEED500] Y[INDP_SYN G100 G90 POS100 FEED1000]",
            "N30 M30"
        ]
    );
    assert_eq!(
        p.blocks[1].items,
        [
            Item::Independent {
                axis: "X".into(),
                motion: Box::new(IndependentMotion {
                    sync: true,
                    gcodes: vec![100, 90],
                    pos: Expr::Num(100.0),
                    feed: Some(Expr::Num(500.0)),
                }),
                span: sp(3, 5),
            },
            Item::Independent {
                axis: "Y".into(),
                motion: Box::new(IndependentMotion {
                    sync: true,
                    gcodes: vec![100, 90],
                    pos: Expr::Num(100.0),
                    feed: Some(Expr::Num(1000.0)),
                }),
                span: sp(4, 9),
            },
        ]
    );
}

/// Seed 004 §4: the 2.5D example, only the NC program (not the `kopf.achs nr …` lines).
#[test]
fn seed_004_4_measurement_run_standard_from_seed() {
    if !test_data::seeds_present("seed_004_4_measurement_run_standard_from_seed") {
        return;
    }
    let p = ok(&seed_program("Measurement run standard", 0));
    assert_eq!(p.name.as_deref(), Some("Measurement run standard"));
    assert_eq!(
        shows(&p),
        [
            "N10 G0 X0 Y1 Z0",
            "N20 X5",
            "N30 G100 X10 F500",
            "N40 G1 Y3",
            "N50 G100 Y10 F500",
            "N60 G1 X10 Y5",
            "N70 G100 X15 Y10 F500",
            "N100 M30"
        ]
    );
}

/// Seed 004 §4: measurement with `#CS`, including the stray `\` of `N50 \#CS ON[…]`.
#[test]
fn seed_004_4_measurement_run_cs() {
    if !test_data::seeds_present("seed_004_4_measurement_run_cs") {
        return;
    }
    let src = seed_program("Measurement run CS", 0);
    assert!(src.contains("N50 \\#CS ON[0,0,0,0,0,90]"), "{src}");
    let p = ok(&src);
    assert_eq!(
        shows(&p),
        [
            "N10 G0 X0 Y1 Z0",
            "N20 #CS ON[0, 0, 0, 0, 45]",
            "N30 G100 X10 F500",
            "N40 #CS OFF",
            "N50 #CS ON[0, 0, 0, 0, 0, 90]",
            "N60 G100 X10 F500",
            "N70 #CS OFF",
            "N100 M30"
        ]
    );
    // The command's position is the '#', not the stray '\'.
    let Item::Command { span, .. } = &p.blocks[4].items[0] else {
        panic!()
    };
    assert_eq!(*span, sp(6, 6));
    assert_eq!(
        *command_of(&p.blocks[1].items[0]),
        Command::Cs {
            on: Some(vec![
                Expr::Num(0.0),
                Expr::Num(0.0),
                Expr::Num(0.0),
                Expr::Num(0.0),
                Expr::Num(45.0)
            ])
        }
    );
}

/// Seed 004 §5 meas1 from the seed (annotation lines removed).
#[test]
fn seed_004_5_meas1_from_seed() {
    if !test_data::seeds_present("seed_004_5_meas1_from_seed") {
        return;
    }
    let p = ok(&without_annotations(&seed_program("meas1", 0)));
    assert_eq!(
        shows(&p),
        [
            "N5 #MEAS MODE[1]",
            "N10 G1 G90 Z200 F2000",
            "N20 G100 Z20 F2000",
            "N30 #MSG SYN[\"V.A.MESS.Z=%f\", V.A.MESS.Z]",
            "N31 #MSG SYN[\"V.A.MEAS.ACS.VALUE.Z=%f\", V.A.MEAS.ACS.VALUE.Z]",
            "N32 #MSG SYN[\"V.A.MEAS.PCS.VALUE.Z=%f\", V.A.MEAS.PCS.VALUE.Z]",
            "N40 #MSG SYN[\"V.A.MOFFS.Z=%f\", V.A.MOFFS.Z]",
            "N50 #MSG SYN[\"V.A.MEIN.Z=%f\", V.A.MEIN.Z]",
            "N60 G101 Z1",
            "N70 #MSG SYN[\"V.A.MEIN.Z=%f\", V.A.MEIN.Z]",
            "N80 G1 Z100 F1000",
            "N90 #MSG SYN[\"V.A.ABS.Z=%f\", V.A.ABS.Z]",
            "N100 G102 Z1",
            "N110 #MSG SYN[\"V.A.MEIN.Z=%f\", V.A.MEIN.Z]",
            "N120 G1 Z100 F1000",
            "N130 #MSG SYN[\"V.A.ABS.Z=%f\", V.A.ABS.Z]",
            "N140 M30",
        ]
    );
    assert_eq!(
        p.blocks[0].items,
        [Item::Command {
            command: Box::new(Command::MeasMode {
                mode: Some(Expr::Num(1.0))
            }),
            span: sp(2, 5)
        }]
    );
}

/// Seed 004 §5 meas2 (G92) and meas3 / meas4 (`#CS ON[…]`, `#CS OFF`) from the seed.
#[test]
fn seed_004_5_meas2_to_meas4_from_seed() {
    if !test_data::seeds_present("seed_004_5_meas2_to_meas4_from_seed") {
        return;
    }
    let p = ok(&without_annotations(&seed_program("meas2", 0)));
    let s = shows(&p);
    assert_eq!(s.len(), 18, "{s:#?}");
    assert_eq!(s[0], "N5 #MEAS MODE[1]");
    assert_eq!(s[1], "N10 G92 Z33");
    // N50 is printed over two lines in the seed.
    assert_eq!(s[7], "N50 #MSG SYN[\"V.A.MOFFS.Z=%f\", V.A.MOFFS.Z]");
    assert_eq!(s[17], "N150 M30");

    let p = ok(&without_annotations(&seed_program("meas3", 0)));
    let s = shows(&p);
    assert_eq!(s.len(), 19, "{s:#?}");
    assert_eq!(
        &s[..4],
        [
            "N5 #MEAS MODE[1]",
            "N10 #CS ON[0, 0, 33, 0, 0, 0]",
            "N20 G1 G90 Z200 F2000",
            "N30 G100 Z20 F2000"
        ]
    );
    assert_eq!(&s[17..], ["N150 #CS OFF", "N160 M30"]);

    let p = ok(&without_annotations(&seed_program("meas4", 0)));
    let s = shows(&p);
    assert_eq!(s.len(), 19, "{s:#?}");
    assert_eq!(
        &s[..4],
        [
            "N5 #MEAS MODE[1]",
            "N10 #CS ON[0, 0, 75, 0, 15, 0]",
            "N20 G1 G90 X150 Z100 F2000",
            "N30 G100 Z-10 F1000"
        ]
    );
    assert_eq!(s[13], "N110 G102 Z1");
    assert_eq!(&s[17..], ["N150 #CS OFF", "N160 M30"]);
}

/// Seed 004 §5 %meas_example: `:` placeholder lines, comments and `D1`.
#[test]
fn seed_004_5_meas_example_from_seed() {
    if !test_data::seeds_present("seed_004_5_meas_example_from_seed") {
        return;
    }
    let p = ok(&seed_program("meas_example", 0));
    assert_eq!(shows(&p), ["D1", "G0 X150 Z200", "G100 Z20", "M30"]);
    assert_eq!(
        p.blocks[0].items,
        [Item::D {
            value: Expr::Num(1.0),
            span: sp(5, 1)
        }]
    );
}

/// Seed 004 §7.3.1 (SERCOS fixed stop with Soft Gantry). The PDF extraction displaced three
/// lines: the command text of N040, N050 and N100 was printed after the first line of its own
/// bracket. Verbatim, the first displaced bracket is a clear error; after swapping each of those
/// command lines with the line above it (nothing else changed), the program parses — N040/N060
/// with the bracket on the next line(s), `NO80` as block 80.
#[test]
fn seed_004_7_3_1_fixed_stop_sercos() {
    if !test_data::seeds_present("seed_004_7_3_1_fixed_stop_sercos") {
        return;
    }
    let verbatim = seed_program("Meas fixed stop", 0);
    let e = fail(&verbatim);
    assert_eq!((e.line, e.col), (7, 20), "{e}");
    assert!(e.message.contains("unexpected character '['"), "{e}");

    let mut lines: Vec<&str> = verbatim.lines().collect();
    for (command, displaced) in [
        ("N040 #IDENT RD", "[AXNR 1 ID S-0-0092 P=P1092"),
        (
            "N050 #IDENT RD",
            "[AXNR 1 ID S-0-0159 P=P1159 TYP 4 DEC 0 SERC]",
        ),
        (
            "N100 #IDENT WR SYN [AXNR 1 ID S-0-0159 VAL=0",
            "TYP 4 DEC 0 SERC]",
        ),
    ] {
        let i = lines
            .iter()
            .position(|l| l.trim() == command)
            .unwrap_or_else(|| panic!("{command} not found"));
        assert_eq!(lines[i - 1].trim(), displaced);
        lines.swap(i - 1, i);
    }
    let repaired: String = lines.iter().map(|l| format!("{l}\n")).collect();
    let p = ok(&repaired);
    assert_eq!(p.name.as_deref(), Some("Meas fixed stop"));
    let ident = |n: u32, rw: &str, p: u32, id: &str, val: &str, typ: u32| {
        format!("N{n} #IDENT {rw}[AXNR={p} ID=\"{id}\" {val} TYP={typ} DEC=0 SERC]")
    };
    assert_eq!(
        shows(&p),
        [
            "N10 G0 X100 X20".to_string(),
            "N20 #SET AX LINK[1, [X2=X, G, 15, 20]]".to_string(),
            "N30 #ENABLE AX LINK[1]".to_string(),
            ident(40, "RD", 1, "S-0-0092", "P=P1092", 2),
            ident(50, "RD", 1, "S-0-0159", "P=P1159", 4),
            ident(60, "RD", 4, "S-0-0092", "P=P2092", 2),
            ident(70, "RD", 4, "S-0-0159", "P=P2159", 4),
            ident(80, "WR SYN", 1, "S-0-0092", "VAL=100", 2),
            ident(90, "WR SYN", 4, "S-0-0092", "VAL=100", 2),
            ident(100, "WR SYN", 1, "S-0-0159", "VAL=0", 4),
            ident(110, "WR SYN", 4, "S-0-0159", "VAL=0", 4),
            "N120 G100 X1000 Y1000 Z1000 Z21000 F1000".to_string(),
            "N130 G1 X100 F1000".to_string(),
            ident(140, "WR SYN", 1, "S-0-0159", "VAL=P1159", 4),
            ident(150, "WR SYN", 4, "S-0-0159", "VAL=P2159", 4),
            ident(160, "WR SYN", 1, "S-0-0092", "VAL=P1092", 2),
            ident(170, "WR SYN", 4, "S-0-0092", "VAL=P2092", 2),
            "N180 M30".to_string(),
        ]
    );
    // Exact ASTs of the gantry coupling and of N060, whose bracket starts on the next line and
    // continues on the line after it.
    assert_eq!(
        *command_of(&p.blocks[1].items[0]),
        Command::SetAxLink {
            group: Expr::Num(1.0),
            links: vec![AxLink {
                slave: "X2".into(),
                master: "X".into(),
                kind: "G".into(),
                params: vec![Expr::Num(15.0), Expr::Num(20.0)],
            }],
        }
    );
    assert_eq!(
        *command_of(&p.blocks[2].items[0]),
        Command::EnableAxLink {
            enable: true,
            group: Some(Expr::Num(1.0))
        }
    );
    let n060 = &p.blocks[5];
    assert_eq!((n060.number, n060.span), (Some(60), sp(12, 1)));
    assert_eq!(
        *command_of(&n060.items[0]),
        Command::Ident {
            write: false,
            sync: false,
            args: vec![
                key("AXNR", n(4.0), sp(13, 20)),
                key("ID", word("S-0-0092"), sp(13, 27)),
                key("P", Some(Expr::Param(2092, sp(13, 41))), sp(13, 39)),
                key("TYP", n(2.0), sp(14, 49)),
                key("DEC", n(0.0), sp(14, 55)),
                key("SERC", None, sp(14, 61)),
            ],
        }
    );
    // NO80: the letter O of the seed is read as a block number.
    assert_eq!(p.blocks[7].number, Some(80));
}

/// Seed 004 §7.3.2 (CANopen fixed stop with `#DRIVE`): `NO30`/`NO40`/`NO80` and the lost
/// underscores of `KEY=TORQUE LIMIT` / `KEY=MON WINDOW`.
#[test]
fn seed_004_7_3_2_fixed_stop_canopen() {
    if !test_data::seeds_present("seed_004_7_3_2_fixed_stop_canopen") {
        return;
    }
    let src = seed_program("Meas fixed stop", 1);
    assert!(src.contains("NO30 #DRIVE WR SYN [AX=Z KEY=TORQUE LIMIT VAL=10 WAIT]"));
    let p = ok(&src);
    assert_eq!(
        shows(&p),
        [
            "N10 #MEAS MODE[7]",
            "N20 G0 Z100",
            "N30 #DRIVE WR SYN[AX=\"Z\" KEY=\"TORQUE_LIMIT\" VAL=10 WAIT]",
            "N40 #DRIVE WR SYN[AX=\"Z\" KEY=\"MON_WINDOW\" VAL=4294967295 WAIT]",
            "N50 G100 Z1000 F100",
            "N60 G1 Z100 F1000",
            "N70 #DRIVE WR SYN[AX=\"Z\" KEY=\"MON_WINDOW\" VAL=1048575 WAIT]",
            "N80 #DRIVE WR SYN[AX=\"Z\" KEY=\"TORQUE_LIMIT\" VAL=5000 WAIT]",
            "N90 M30",
        ]
    );
    assert_eq!(
        p.blocks[2].items,
        [Item::Command {
            command: Box::new(Command::Drive {
                write: true,
                sync: true,
                args: vec![
                    key("AX", word("Z"), sp(5, 21)),
                    key("KEY", word("TORQUE_LIMIT"), sp(5, 26)),
                    key("VAL", n(10.0), sp(5, 43)),
                    key("WAIT", None, sp(5, 50)),
                ],
            }),
            span: sp(5, 6),
        }]
    );
}

// ---------------------------------------------------------------------------------------------
// measurement syntax, one construct at a time

#[test]
fn meas_commands() {
    assert_eq!(
        shows(&ok(
            "#MEAS MODE [2]\n#MEAS MODE[2]\n#meas mode\n#MEAS MODE [P1+1]"
        )),
        [
            "#MEAS MODE[2]",
            "#MEAS MODE[2]",
            "#MEAS MODE",
            "#MEAS MODE[(P1 + 1)]"
        ]
    );
    let p = ok("N10 #MEAS [AXNR=2 SIGNAL=PLC_TIMESTAMP]");
    assert_eq!(
        *command_of(&p.blocks[0].items[0]),
        Command::MeasConfig {
            args: vec![
                key("AXNR", n(2.0), sp(1, 12)),
                key("SIGNAL", word("PLC_TIMESTAMP"), sp(1, 19)),
            ]
        }
    );
    assert_eq!(
        shows(&ok("#MEAS [ AXNR = 1 INPUT=2 EDGE=neg SIGNAL DRIVE]")),
        ["#MEAS[AXNR=1 INPUT=2 EDGE=\"NEG\" SIGNAL=\"DRIVE\"]"]
    );
    assert_eq!(
        shows(&ok("#MEAS PREPARE [AXNR=1]\n#MEAS PREPARE [AXNR=1 AXNR=2]")),
        ["#MEAS PREPARE[AXNR=1]", "#MEAS PREPARE[AXNR=1 AXNR=2]"]
    );
}

#[test]
fn cs_and_trafo_commands() {
    assert_eq!(
        shows(&ok(
            "#CS ON [0,0,33,0,0,0]\n#CS ON[0,0,0,0,45]\n#cs on[1]\n#CS OFF\n#TRAFO ON\n#TRAFO OFF"
        )),
        [
            "#CS ON[0, 0, 33, 0, 0, 0]",
            "#CS ON[0, 0, 0, 0, 45]",
            "#CS ON[1]",
            "#CS OFF",
            "#TRAFO ON",
            "#TRAFO OFF"
        ]
    );
    assert_eq!(
        shows(&ok("#CS ON[V.A.ABS.X, -P2, 2*3]")),
        ["#CS ON[V.A.ABS.X, -(P2), (2 * 3)]"]
    );
}

#[test]
fn drive_and_ident_commands() {
    assert_eq!(
        shows(&ok("#DRIVE WR SYN [AX=Z KEY=TORQUE_LIMIT VAL=10 WAIT]\n\
             #DRIVE WR [AX=Z KEY=MON_WINDOW VAL=4294967295]\n\
             #DRIVE RD SYN [AX=Z KEY=MON_WINDOW P=P10]\n\
             #drive rd [ax x key mon_window p p11 wait]")),
        [
            "#DRIVE WR SYN[AX=\"Z\" KEY=\"TORQUE_LIMIT\" VAL=10 WAIT]",
            "#DRIVE WR[AX=\"Z\" KEY=\"MON_WINDOW\" VAL=4294967295]",
            "#DRIVE RD SYN[AX=\"Z\" KEY=\"MON_WINDOW\" P=P10]",
            "#DRIVE RD[AX=\"X\" KEY=\"MON_WINDOW\" P=P11 WAIT]",
        ]
    );
    // The two-word KEY leniency joins only a second word that is not a keyword.
    assert_eq!(
        shows(&ok("#DRIVE WR [KEY=TORQUE LIMIT AX=Z VAL=1]")),
        ["#DRIVE WR[KEY=\"TORQUE_LIMIT\" AX=\"Z\" VAL=1]"]
    );
    assert_eq!(
        shows(&ok("#DRIVE WR [AX=Z KEY=TORQUE WAIT VAL=1]")),
        ["#DRIVE WR[AX=\"Z\" KEY=\"TORQUE\" WAIT VAL=1]"]
    );
    assert_eq!(
        shows(&ok(
            "#IDENT RD [AXNR 1 ID S-0-0092 P=P1092 TYP 2 DEC 0 SERC]\n\
             #IDENT WR SYN [AXNR 4 ID S-0-0159 VAL=0 TYP 4 DEC 0 SERC]\n\
             #IDENT WR SYN [AXNR=1 ID=P-0-0270 VAL=P1159 TYP=4 DEC=0 SERC]\n\
             #IDENT WR [AX X ID s-0-0104 VAL 655.35 TYP 4 DEC 2 SERC]\n\
             #IDENT RD [AX X ID 0x6072_00 P=P1 TYP 4 DEC 2 CAN]"
        )),
        [
            "#IDENT RD[AXNR=1 ID=\"S-0-0092\" P=P1092 TYP=2 DEC=0 SERC]",
            "#IDENT WR SYN[AXNR=4 ID=\"S-0-0159\" VAL=0 TYP=4 DEC=0 SERC]",
            "#IDENT WR SYN[AXNR=1 ID=\"P-0-0270\" VAL=P1159 TYP=4 DEC=0 SERC]",
            "#IDENT WR[AX=\"X\" ID=\"S-0-0104\" VAL=655.35 TYP=4 DEC=2 SERC]",
            "#IDENT RD[AX=\"X\" ID=\"0x6072_00\" P=P1 TYP=4 DEC=2 CAN]",
        ]
    );
}

#[test]
fn ax_link_commands() {
    assert_eq!(
        shows(&ok(
            "#SET AX LINK[1, [X2=X,G,15,20]]\n#SET AX LINK [2, [Y2=Y, G], [Z2 = Z, G, 1+1]]\n\
             #ENABLE AX LINK[1]\n#ENABLE AX LINK\n#DISABLE AX LINK[1]\n#disable ax link"
        )),
        [
            "#SET AX LINK[1, [X2=X, G, 15, 20]]",
            "#SET AX LINK[2, [Y2=Y, G], [Z2=Z, G, (1 + 1)]]",
            "#ENABLE AX LINK[1]",
            "#ENABLE AX LINK",
            "#DISABLE AX LINK[1]",
            "#DISABLE AX LINK",
        ]
    );
}

#[test]
fn independent_axes() {
    assert_eq!(
        shows(&ok("N20 Y[INDP_ASYN G01 G91 POS=-5 FEED=1000]")),
        ["N20 Y[INDP_ASYN G1 G91 POS-5 FEED1000]"]
    );
    assert_eq!(
        shows(&ok(
            "X2[ INDP_SYN POS[10+2] ]\nx[indp_syn feed = 5 pos V.A.ABS.X g90]\nZ[INDP_SYN POSP1]"
        )),
        [
            "X2[INDP_SYN POS(10 + 2)]",
            "X[INDP_SYN G90 POSV.A.ABS.X FEED5]",
            "Z[INDP_SYN POSP1]"
        ]
    );
    // Independent words mix with path words; a plain bracket is still an expression.
    assert_eq!(
        shows(&ok("N10 G100 Z10 F500 X[INDP_SYN G100 POS100] Y[10]")),
        ["N10 G100 Z10 F500 X[INDP_SYN G100 POS100] Y10"]
    );
    err_at(
        "X[INDP_SYN G90 FEED5]",
        1,
        2,
        "X[INDP_SYN …] needs a target position POS<value>",
    );
    err_at("X[INDP_SYN POS1 POS2]", 1, 17, "POS is given twice");
    err_at(
        "X[INDP_SYN POS1 Q]",
        1,
        17,
        "expected G<code>, POS<value>, FEED<value> or ']' in X[INDP_SYN …], found 'Q'",
    );
    err_at("X[INDP_SYN POSITION1]", 1, 12, "found 'P'");
    err_at(
        "X[INDP_ASYN POS1",
        1,
        17,
        "expected ']' to close X[INDP_ASYN … at line 1, column 2",
    );
    err_at("X[INDP_SYNC POS1]", 1, 3, "unknown name 'INDP_SYNC'");
}

#[test]
fn parameters() {
    let p = ok("N10 P1 = 5\nP2=V.A.ABS.X + P1 * 2 P3 = -1\nX=P1 Y[P2/2] ZP3\n#MSG[\"%f\", P1]");
    assert_eq!(
        shows(&p),
        [
            "N10 P1=5",
            "P2=(V.A.ABS.X + (P1 * 2)) P3=-1",
            "XP1 Y(P2 / 2) ZP3",
            "#MSG[\"%f\", P1]"
        ]
    );
    assert_eq!(
        p.blocks[0].items,
        [Item::Assign {
            param: 1,
            value: Expr::Num(5.0),
            span: sp(1, 5)
        }]
    );
    let Item::Axis { value, .. } = &p.blocks[2].items[0] else {
        panic!()
    };
    assert_eq!(*value, Expr::Param(1, sp(3, 3)));
    assert_eq!(
        parse_expr("p7 + 1").unwrap(),
        Expr::Bin(
            BinOp::Add,
            Box::new(Expr::Param(7, sp(1, 1))),
            Box::new(Expr::Num(1.0))
        )
    );

    // Evaluation goes through VarSource::param; the default has no parameters.
    struct Params;
    impl VarSource for Params {
        fn var(&self, var: &VarRef) -> Result<Value, String> {
            Err(format!("unknown variable {}", var.name()))
        }
        fn param(&self, n: u32) -> Result<f64, String> {
            if n == 7 {
                Ok(2.5)
            } else {
                Err(format!("P{n} has no value"))
            }
        }
    }
    assert_eq!(eval_num(&parse_expr("P7 * 2").unwrap(), &Params), Ok(5.0));
    let e = eval(&parse_expr("1 + P8").unwrap(), &Params).unwrap_err();
    assert_eq!((e.span, e.message.as_str()), (sp(1, 5), "P8 has no value"));
    let e = eval(&parse_expr("P7").unwrap(), &Vars::new(&[])).unwrap_err();
    assert_eq!(e.message, "P7 has no value");

    err_at(
        "N10 G04 P5",
        1,
        9,
        "'P' is not an address letter: expected '=' after P5",
    );
    err_at("N10 P=5", 1, 6, "expected a parameter number after 'P'");
    err_at(
        "N10 X10 P1=2",
        1,
        9,
        "a parameter assignment must be a block of its own",
    );
    err_at(
        "N10 P1=2 X10",
        1,
        10,
        "a parameter assignment must be a block of its own",
    );
    err_at("N10 P1=", 1, 8, "found end of block");
    err_at("P99999999999=1", 1, 1, "parameter number is too large");
    err_at("X[P99999999999]", 1, 3, "parameter number is too large");
}

#[test]
fn seed_leniencies() {
    // NO<digits> only as the first word in front of a # command.
    assert_eq!(shows(&ok("NO80 #CS OFF")), ["N80 #CS OFF"]);
    assert_eq!(shows(&ok("no30 \\#TRAFO OFF")), ["N30 #TRAFO OFF"]);
    err_at("NO80 X1", 1, 2, "found the letter 'O'");
    err_at("NO80#CS OFF", 1, 2, "found the letter 'O'");
    err_at("NO #CS OFF", 1, 2, "found the letter 'O'");
    // '\#' only directly in front of a command.
    assert_eq!(shows(&ok("N50 \\#CS OFF")), ["N50 #CS OFF"]);
    err_at("N50 \\ #CS OFF", 1, 5, "unexpected character '\\'");
    err_at("N50 \\X1", 1, 5, "unexpected character '\\'");
    // A bracket on the next line(s) when the command line ends after the keywords.
    let p = ok("N10 #MEAS PREPARE\n   [AXNR=1\n    AXNR=2]\nN20 #ENABLE AX LINK\n\n  [2]\nN30 M30");
    assert_eq!(
        shows(&p),
        [
            "N10 #MEAS PREPARE[AXNR=1 AXNR=2]",
            "N20 #ENABLE AX LINK[2]",
            "N30 M30"
        ]
    );
    assert_eq!(p.blocks[2].span, sp(7, 1));
    assert_eq!(shows(&ok("#MSG SYN\n[\"a\"]")), ["#MSG SYN[\"a\"]"]);
    // Not after a complete command, and not after other words.
    err_at("N10 #CS OFF\n[1]", 2, 1, "unexpected character '['");
    err_at("N10 #CS ON[1]\n[1]", 2, 1, "unexpected character '['");
    err_at("N10 X1\n[1]", 2, 1, "unexpected character '['");
    err_at(
        "N10 #IDENT RD X\n[AXNR 1]",
        1,
        15,
        "expected '[' with the keywords",
    );
    // The KEY leniency joins at most two words.
    err_at(
        "#DRIVE WR [AX=Z KEY=TORQUE LIMIT VALUE VAL=1]",
        1,
        34,
        "unknown keyword VALUE in #DRIVE WR",
    );
}

#[test]
fn measurement_syntax_errors() {
    err_at(
        "N10 #MEAS",
        1,
        10,
        "expected MODE, PREPARE or '[' after #MEAS, found end of block",
    );
    err_at(
        "N10 #MEAS FOO",
        1,
        11,
        "expected MODE, PREPARE or '[' after #MEAS, found 'FOO'",
    );
    err_at("N10 #MEAS MODE []", 1, 17, "expected the measurement type");
    err_at(
        "N10 #MEAS MODE [1",
        1,
        18,
        "expected ']' to close the bracket at line 1, column 16",
    );
    err_at(
        "N10 #MEAS [SIGNAL=PLC]",
        1,
        11,
        "#MEAS [...] needs the axis number AXNR",
    );
    err_at(
        "N10 #MEAS [AXNR=1 FOO=2]",
        1,
        19,
        "unknown keyword FOO in #MEAS [...] (expected one of AXNR, SIGNAL, INPUT, EDGE, TYPE)",
    );
    err_at("N10 #MEAS [AXNR=1 AXNR=2]", 1, 19, "AXNR is given twice");
    err_at(
        "N10 #MEAS [AXNR=1",
        1,
        18,
        "expected ']' to close #MEAS [ at line 1, column 11",
    );
    err_at(
        "N10 #MEAS [AXNR=]",
        1,
        17,
        "expected a value after AXNR in #MEAS [...], found ']'",
    );
    err_at(
        "N10 #MEAS [AXNR=1, SIGNAL=PLC]",
        1,
        18,
        "expected a keyword (AXNR, SIGNAL, INPUT, EDGE, TYPE) or ']'",
    );
    err_at(
        "N10 #MEAS PREPARE []",
        1,
        19,
        "needs at least one axis number AXNR",
    );
    err_at(
        "N10 #MEAS PREPARE",
        1,
        18,
        "expected '[' with the keywords (AXNR) after #MEAS PREPARE",
    );
    err_at(
        "N10 #CS",
        1,
        8,
        "expected ON or OFF after #CS, found end of block",
    );
    err_at(
        "N10 #CS ON",
        1,
        11,
        "expected '[' with the offsets after #CS ON, found end of block",
    );
    err_at(
        "N10 #CS ON[]",
        1,
        11,
        "#CS ON [...] takes 1 to 6 values (x, y, z, a, b, c), found 0",
    );
    err_at("N10 #CS ON[1,2,3,4,5,6,7]", 1, 11, "found 7");
    err_at(
        "N10 #CS ON[1 2]",
        1,
        14,
        "expected an operator, ',' or ']' in #CS ON[…], found number 2",
    );
    err_at("N10 #TRAFO", 1, 11, "expected ON or OFF after #TRAFO");
    err_at(
        "N10 #TRAFO 1",
        1,
        12,
        "expected ON or OFF after #TRAFO, found number 1",
    );
    err_at(
        "N10 #DRIVE SYN [AX=Z]",
        1,
        12,
        "expected WR or RD after #DRIVE, found 'SYN'",
    );
    err_at(
        "N10 #DRIVE WR [AX=Z VAL=1]",
        1,
        15,
        "#DRIVE WR [...] needs KEY=<value>",
    );
    err_at(
        "N10 #DRIVE WR [AX=Z KEY=K]",
        1,
        15,
        "#DRIVE WR [...] needs VAL=<value to write>",
    );
    err_at(
        "N10 #DRIVE RD [AX=Z KEY=K VAL=1]",
        1,
        27,
        "#DRIVE RD [...] does not take VAL",
    );
    err_at(
        "N10 #DRIVE WR [AX=Z KEY=K VAL=1 P=P1]",
        1,
        33,
        "#DRIVE WR [...] does not take P",
    );
    err_at(
        "N10 #DRIVE WR [AX=Z KEY=K VAL=1 WAIT=1]",
        1,
        37,
        "WAIT is a flag in #DRIVE WR [...] and takes no value",
    );
    err_at(
        "N10 #DRIVE WR [AX=Z KEY=K VAL=1 AXNR=1]",
        1,
        33,
        "unknown keyword AXNR in #DRIVE WR",
    );
    err_at(
        "N10 #IDENT RD [ID S-0-0092 P=P1]",
        1,
        15,
        "needs the axis: AX <name> or AXNR <number>",
    );
    err_at(
        "N10 #IDENT RD [AX X AXNR 1 ID S-0-0092 P=P1]",
        1,
        21,
        "either AX or AXNR, not both",
    );
    err_at(
        "N10 #IDENT RD [AXNR 1 P=P1]",
        1,
        15,
        "needs the parameter ident ID",
    );
    err_at(
        "N10 #IDENT RD [AXNR ID S-0-0092 P=P1]",
        1,
        21,
        "expected a value after AXNR in #IDENT RD [...], found the keyword ID",
    );
    err_at(
        "N10 #IDENT RD [AXNR 1 ID S-0-0092 P=P1 SERC CAN]",
        1,
        45,
        "one drive type (SERC or CAN)",
    );
    err_at(
        "N10 #IDENT RD [AXNR 1 ID S-0-0092]",
        1,
        15,
        "#IDENT RD [...] needs P=<parameter that receives the value>",
    );
    err_at(
        "N10 #IDENT WR [AXNR 1 ID S-0-0092 SERC]",
        1,
        15,
        "#IDENT WR [...] needs VAL=",
    );
    err_at(
        "N10 #IDENT RD [AXNR 1 ID S-0-0092 P=P1 TYP 4 DEC 0 SERC",
        1,
        56,
        "expected ']' to close #IDENT RD [ at line 1, column 15",
    );
    err_at(
        "N10 #SET AX [1, [X2=X, G]]",
        1,
        13,
        "expected 'AX LINK' after #SET, found '['",
    );
    err_at(
        "N10 #SET FOO",
        1,
        10,
        "expected 'AX LINK' after #SET, found 'FOO'",
    );
    err_at(
        "N10 #SET AX LINK[1]",
        1,
        19,
        "expected an operator or ',' and a coupling",
    );
    err_at(
        "N10 #SET AX LINK[1, [X2, G]]",
        1,
        24,
        "expected '=' after the slave axis X2",
    );
    err_at(
        "N10 #SET AX LINK[1, [X2=Q, G]]",
        1,
        25,
        "expected the master axis name",
    );
    err_at(
        "N10 #SET AX LINK[1, [X2=X G]]",
        1,
        27,
        "expected ',' and the coupling kind",
    );
    err_at(
        "N10 #SET AX LINK[1, [X2=X, 5]]",
        1,
        28,
        "expected the coupling kind (e.g. G)",
    );
    err_at(
        "N10 #SET AX LINK[1, [X2=X, G, 1]",
        1,
        33,
        "expected ',' or ']' to close #SET AX LINK[ at line 1, column 17",
    );
    err_at(
        "N10 #ENABLE AX LINK[1",
        1,
        22,
        "expected ']' to close the bracket at line 1, column 20",
    );
    err_at(
        "N10 #ENABLE LINK",
        1,
        13,
        "expected 'AX LINK' after #ENABLE",
    );
    err_at("N10 D", 1, 6, "after 'D'");
}

// ---------------------------------------------------------------------------------------------
// words and lexical rules

#[test]
fn words_case_blanks_and_values() {
    assert_eq!(shows(&ok("g01x10y20")), ["G1 X10 Y20"]);
    assert_eq!(shows(&ok("G01X10Y20Z-3.5F500")), ["G1 X10 Y20 Z-3.5 F500"]);
    assert_eq!(shows(&ok("N5 X 10 Y = 20 Z=-1")), ["N5 X10 Y20 Z-1"]);
    assert_eq!(shows(&ok("X.5 Y5. Z+3 A-0.25")), ["X0.5 Y5 Z3 A-0.25"]);
    assert_eq!(
        shows(&ok("A1 B2 C3 U4 V5 W6 I7 J8 K9")),
        ["A1 B2 C3 U4 V5 W6 I7 J8 K9"]
    );
    assert_eq!(shows(&ok("G17 G161 M3 M05")), ["G17 G161 M3 M5"]);
    assert_eq!(shows(&ok("N010")), ["N10"]);
    // X2 without '=' is axis X with value 2.
    assert_eq!(shows(&ok("X2 Y3")), ["X2 Y3"]);
    // Values: bracketed expressions and (signed) variables.
    assert_eq!(
        shows(&ok("X[10+2] Y-[1] Z=V.A.ABS.Z F-V.G.FEED")),
        ["X(10 + 2) Y-1 ZV.A.ABS.Z F-(V.G.FEED)"]
    );
    assert_eq!(shows(&ok("XV.A.ABS.X")), ["XV.A.ABS.X"]);
    assert_eq!(shows(&ok("x=v.a.abs.x")), ["XV.A.ABS.X"]);
}

#[test]
fn comments_blank_lines_and_placeholders() {
    let p = ok(
        "\n   \n(only a comment)\n;only a comment\nN10 (a) G01 (b) X1 ; tail (not closed\n...\n…\n",
    );
    assert_eq!(shows(&p), ["N10 G1 X1"]);
    assert_eq!(p.blocks[0].span, sp(5, 1));
    // Indented block: the span is the first character.
    assert_eq!(ok("   N7 X1").blocks[0].span, sp(1, 4));
    // Windows line ends.
    assert_eq!(shows(&ok("N1 X1\r\nN2 X2\r\n")), ["N1 X1", "N2 X2"]);
    // A comment separates like a blank: X1(c)0 is X1 followed by a stray 0.
    assert_eq!(fail("X1(c)0").col, 6);
    // Parentheses inside [ ] are grouping, ';' inside a string is text.
    assert_eq!(shows(&ok("X[(1+2)*3]")), ["X((1 + 2) * 3)"]);
    assert_eq!(
        shows(&ok("#MSG[\"a;(b)\\\"c\\\\\"] ; comment")),
        ["#MSG[\"a;(b)\\\"c\\\\\"]"]
    );
}

#[test]
fn continuation_lines() {
    let p = ok("N10 G01 X1 \\\n    Y2\nN20 X[1+ \\ ; comment\n 2] Y3 \\ (comment)\n Z4\nN30 X5\n");
    assert_eq!(shows(&p), ["N10 G1 X1 Y2", "N20 X(1 + 2) Y3 Z4", "N30 X5"]);
    let Item::Axis { span, .. } = &p.blocks[0].items[2] else {
        panic!()
    };
    assert_eq!(*span, sp(2, 5));
    assert_eq!(p.blocks[2].span, sp(6, 1));
    // A '\' followed by more text is not a continuation.
    let e = fail("N10 X1 \\ Y2");
    assert_eq!((e.line, e.col), (1, 8));
    // '\' at the end of the file simply ends the block.
    assert_eq!(shows(&ok("N10 X1 \\")), ["N10 X1"]);
}

#[test]
fn program_name() {
    assert_eq!(ok("%abc").name.as_deref(), Some("abc"));
    assert_eq!(
        ok("(header)\n%abc ; comment\nN1 X1").name.as_deref(),
        Some("abc")
    );
    assert_eq!(ok("%\nN1 X1").name, None);
    let e = fail("N1 X1\n%late");
    assert_eq!((e.line, e.col), (2, 1));
    assert!(e.message.contains("first line"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// variables and expressions

#[test]
fn variables() {
    let seg = |s: &str| match parse_expr(s).unwrap() {
        Expr::Var(v) => v.segments,
        other => panic!("{other:?}"),
    };
    assert_eq!(seg("V.A.-SWE.X"), ["V", "A", "-SWE", "X"]);
    assert_eq!(seg("V.A.+SWE.X"), ["V", "A", "+SWE", "X"]);
    assert_eq!(seg("v.a.abs.x"), ["V", "A", "ABS", "X"]);
    assert_eq!(
        seg("V.A.MEAS.ACS.VALUE.X"),
        ["V", "A", "MEAS", "ACS", "VALUE", "X"]
    );
    assert_eq!(seg("V.G.MEAS_TYPE"), ["V", "G", "MEAS_TYPE"]);
    assert_eq!(seg("V.A.ABS.X2"), ["V", "A", "ABS", "X2"]);
    // The sign is only part of a segment right after a dot.
    assert_eq!(
        show_expr(&parse_expr("V.A.ABS.X-5").unwrap()),
        "(V.A.ABS.X - 5)"
    );
    assert_eq!(
        show_expr(&parse_expr("V.A.ABS.X - -5").unwrap()),
        "(V.A.ABS.X - -5)"
    );
    assert_eq!(
        show_expr(&parse_expr("-V.A.-SWE.X").unwrap()),
        "-(V.A.-SWE.X)"
    );
    assert_eq!(
        show_expr(&parse_expr("V.A.+SWE.X+V.A.-SWE.X").unwrap()),
        "(V.A.+SWE.X + V.A.-SWE.X)"
    );
    // Spans point at the V.
    let Expr::Bin(_, a, b) = parse_expr("  V.A.X *  V.A.Y").unwrap() else {
        panic!()
    };
    let (Expr::Var(a), Expr::Var(b)) = (*a, *b) else {
        panic!()
    };
    assert_eq!((a.span, b.span), (sp(1, 3), sp(1, 12)));
}

#[test]
fn expression_precedence_and_shape() {
    let s = |src: &str| show_expr(&parse_expr(src).unwrap());
    assert_eq!(s("1+2*3"), "(1 + (2 * 3))");
    assert_eq!(s("[1+2]*3"), "((1 + 2) * 3)");
    assert_eq!(s("(1+2)*3"), "((1 + 2) * 3)");
    assert_eq!(s("10-4-3"), "((10 - 4) - 3)");
    assert_eq!(s("8/4/2"), "((8 / 4) / 2)");
    assert_eq!(s("-2*3"), "(-2 * 3)");
    assert_eq!(s("2*-3"), "(2 * -3)");
    assert_eq!(s("--2"), "2");
    assert_eq!(s("+2"), "2");
    assert_eq!(s("-[1+2]"), "-((1 + 2))");
    assert_eq!(
        s("abs[-1] + atan2[1, 2*3]"),
        "(ABS[-1] + ATAN2[1, (2 * 3)])"
    );
    assert_eq!(s("\"text\""), "\"text\"");
}

#[test]
fn expression_evaluation() {
    assert_eq!(num("1+2*3"), 7.0);
    assert_eq!(num("[1+2]*3"), 9.0);
    assert_eq!(num("10-4-3"), 3.0);
    assert_eq!(num("8/4/2"), 1.0);
    assert_eq!(num("-2*-3"), 6.0);
    assert_eq!(num("ABS[-2.5]"), 2.5);
    assert_eq!(num("SQRT[16]"), 4.0);
    assert!((num("SIN[30]") - 0.5).abs() < 1e-15);
    assert_eq!(num("SIN[90]"), 1.0);
    assert_eq!(num("SIN[180]"), 0.0);
    assert_eq!(num("COS[90]"), 0.0);
    assert_eq!(num("COS[-180]"), -1.0);
    assert!((num("COS[60]") - 0.5).abs() < 1e-15);
    assert!((num("TAN[45]") - 1.0).abs() < 1e-15);
    assert_eq!(num("ATAN2[1, 1]"), 45.0);
    assert_eq!(num("ATAN2[0, -1]"), 180.0);
    assert_eq!(num("INT[-2.7]"), -2.0);
    assert_eq!(num("INT[2.7]"), 2.0);
    assert_eq!(num("ROUND[2.5]"), 3.0);
    assert_eq!(num("ROUND[-2.5]"), -3.0);
    assert_eq!(num("ROUND[2.4999]"), 2.0);

    let vars = Vars::new(&[("V.A.ABS.X", 12.5), ("V.A.-SWE.X", -200.0)]);
    let e = parse_expr("V.A.ABS.X-5").unwrap();
    assert_eq!(eval(&e, &vars), Ok(Value::Num(7.5)));
    let e = parse_expr("v.a.-swe.x / 4").unwrap();
    assert_eq!(eval_num(&e, &vars), Ok(-50.0));
    assert_eq!(
        eval(&parse_expr("\"abc\"").unwrap(), &vars),
        Ok(Value::Str("abc".into()))
    );
}

#[test]
fn evaluation_errors_carry_spans() {
    let vars = Vars::new(&[("V.A.ABS.X", 1.0)]);
    let at = sp(7, 3);
    let err =
        |src: &str| -> EvalError { eval_at(&parse_expr(src).unwrap(), &vars, at).unwrap_err() };

    let e = err("1/0");
    assert_eq!(e.span, at);
    assert!(e.message.contains("division by zero"), "{e}");
    assert_eq!(e.to_string(), format!("line 7, column 3: {}", e.message));

    let e = err("1 + V.A.ABS.Y");
    assert_eq!(e.span, sp(1, 5));
    assert_eq!(e.message, "unknown variable V.A.ABS.Y");

    let e = err("2 * SQRT[-1]");
    assert_eq!(e.span, sp(1, 5));
    assert!(e.message.contains("SQRT"), "{e}");

    // Errors of operators inside a call are reported at the call.
    let e = err("ABS[1/[V.A.ABS.X-1]]");
    assert_eq!(
        (e.span, e.message.contains("division by zero")),
        (sp(1, 1), true)
    );

    let e = err("\"a\" + 1");
    assert_eq!(e.span, at);
    assert!(e.message.contains("string"), "{e}");
    let e = err("-\"a\"");
    assert!(e.message.contains("string"), "{e}");

    let e = err("TAN[90]");
    assert!(e.message.contains("TAN"), "{e}");

    // Overflow to infinity.
    let big = format!("1{}", "0".repeat(300));
    let e = err(&format!("{big} * {big}"));
    assert!(e.message.contains("not a finite number"), "{e}");

    // A string where a number is needed.
    let e = eval_num_at(&parse_expr("\"a\"").unwrap(), &vars, at).unwrap_err();
    assert_eq!(e.span, at);

    // Hand-built trees: unknown function and wrong arity.
    let call =
        |name: &str, n: usize| Expr::Call(name.into(), vec![Expr::Num(1.0); n].into(), sp(2, 9));
    let e = eval(&call("FOO", 1), &vars).unwrap_err();
    assert_eq!(
        (e.span, e.message.as_str()),
        (sp(2, 9), "unknown function FOO")
    );
    let e = eval(&call("ATAN2", 1), &vars).unwrap_err();
    assert_eq!(e.span, sp(2, 9));
    assert!(e.message.contains("takes 2 arguments"), "{e}");
    // A deeper tree than the parser can build is an error, not a stack overflow.
    let mut deep = Expr::Num(1.0);
    for _ in 0..300 {
        deep = Expr::Neg(Box::new(deep));
    }
    assert!(eval(&deep, &vars).is_err());
    // Without a fallback, eval locates operator errors at the first variable / call.
    let e = eval(&parse_expr("V.A.ABS.X / 0").unwrap(), &vars).unwrap_err();
    assert_eq!(e.span, sp(1, 1));
}

// ---------------------------------------------------------------------------------------------
// #MSG

#[test]
fn msg_command() {
    let p = ok("N10 #MSG SYN[\"X=%f Y=%f\", V.A.ABS.X, V.A.ABS.Y]");
    let Item::Command { command, span } = &p.blocks[0].items[0] else {
        panic!()
    };
    assert_eq!(*span, sp(1, 5));
    let Command::Msg {
        sync,
        format: f,
        args,
    } = &**command
    else {
        panic!("{command:?}")
    };
    assert!(*sync);
    assert_eq!(f, "X=%f Y=%f");
    assert_eq!(args.len(), 2);
    let Expr::Var(v) = &args[1] else { panic!() };
    assert_eq!((v.name(), v.span), ("V.A.ABS.Y".to_string(), sp(1, 38)));

    let vars = Vars::new(&[("V.A.ABS.X", 20.0), ("V.A.ABS.Y", -0.5)]);
    let values: Vec<Value> = args.iter().map(|a| eval(a, &vars).unwrap()).collect();
    assert_eq!(format(f, &values).unwrap(), "X=20.000000 Y=-0.500000");

    assert_eq!(shows(&ok("#msg syn [\"a\"]")), ["#MSG SYN[\"a\"]"]);
    assert_eq!(
        shows(&ok("#MSG[\"n=%d\", 1+2]")),
        ["#MSG[\"n=%d\", (1 + 2)]"]
    );
    assert_eq!(
        shows(&ok("#MSG [\"s=%s\", \"x\"]")),
        ["#MSG[\"s=%s\", \"x\"]"]
    );
    // A command may be followed by more words.
    assert_eq!(shows(&ok("N1 #MSG[\"a\"] X1")), ["N1 #MSG[\"a\"] X1"]);
}

// ---------------------------------------------------------------------------------------------
// errors: exact positions and messages

fn err_at(src: &str, line: u32, col: u32, needle: &str) {
    let e = fail(src);
    assert_eq!((e.line, e.col), (line, col), "{src:?}: {e}");
    assert!(e.message.contains(needle), "{src:?}: {e}");
    assert_eq!(
        e.to_string(),
        format!("line {line}, column {col}: {}", e.message)
    );
}

#[test]
fn error_positions_and_messages() {
    err_at("N10 Q5", 1, 5, "unknown address letter 'Q'");
    err_at("N10 G01\nN20 q5", 2, 5, "unknown address letter 'Q'");
    err_at(
        "N10 X",
        1,
        6,
        "expected a number, '[', a variable or a parameter P<n> after 'X', found end of block",
    );
    err_at("N10 X2=", 1, 8, "after 'X2'");
    err_at("N10 X Y1", 1, 7, "after 'X', found 'Y'");
    err_at("N10 F", 1, 6, "after 'F'");
    err_at("N10 X--5", 1, 7, "after 'X', found '-'");
    err_at("N10 (comment", 1, 5, "comment '(' is not closed");
    err_at("N10 #XYZ", 1, 5, "unknown control command #XYZ");
    err_at("N10 #xyz[1]", 1, 5, "unknown control command #XYZ");
    err_at("N10 # MSG", 1, 6, "expected a command name after '#'");
    err_at("N10 G01 N20", 1, 9, "must be the first word");
    err_at("N10 G", 1, 6, "expected an integer after 'G'");
    err_at("N10 G1.5", 1, 7, "integer");
    err_at("N10 G99999999999", 1, 6, "too large");
    err_at("N10 X[1+]", 1, 9, "found ']'");
    err_at(
        "N10 X[1 2]",
        1,
        9,
        "expected an operator or ']', found number 2",
    );
    err_at(
        "N10 X[1+2",
        1,
        10,
        "expected ']' to close the bracket at line 1, column 6",
    );
    err_at(
        "N10 X[1+2\nN20 X1",
        2,
        1,
        "expected an operator or ']', found 'N20'",
    );
    err_at("N10 X[FOO[1]]", 1, 7, "unknown function FOO");
    err_at("N10 X[FOO]", 1, 7, "unknown name 'FOO'");
    err_at("N10 X[ABS[1,2]]", 1, 7, "ABS takes 1 argument, found 2");
    err_at("N10 X[ATAN2[1]]", 1, 7, "ATAN2 takes 2 arguments, found 1");
    err_at("N10 X[ABS[1]", 1, 13, "expected ']'");
    err_at("N10 X[1)]", 1, 8, "found ')'");
    err_at("N10 #MSG SYN[\"x", 1, 14, "string is not closed");
    err_at("N10 #MSG SYN[1]", 1, 14, "expected the format string");
    err_at(
        "N10 #MSG SYN",
        1,
        13,
        "expected '[' after #MSG SYN, found end of block",
    );
    err_at(
        "N10 #MSG FOO[\"x\"]",
        1,
        10,
        "expected 'SYN' or '[' after #MSG, found 'FOO'",
    );
    err_at(
        "N10 #MSG[\"x\" 1]",
        1,
        14,
        "expected an operator, ',' or ']' in #MSG",
    );
    err_at("N10 #MSG[\"x\", ]", 1, 15, "found ']'");
    err_at("N10 V.A.X=1", 1, 5, "variable");
    err_at("N10 X1 $", 1, 8, "unexpected character '$'");
    err_at("N10 X1 ]", 1, 8, "unexpected character ']'");
    err_at("N10 X1e5", 1, 7, "unknown address letter 'E'");
    // Columns count characters, not bytes.
    err_at("(äöü) Q1", 1, 7, "'Q'");
    // Lines are counted through comments and blank lines.
    err_at("%p\n\n(c)\n;c\nN10 X1\nN20 Y", 6, 6, "after 'Y'");
}

#[test]
fn nesting_and_length_limits() {
    // Deep nesting is an error, not a stack overflow.
    let deep = format!("X{}1{}", "[".repeat(200), "]".repeat(200));
    let e = fail(&deep);
    assert!(e.message.contains("nested too deeply"), "{e}");
    let e = fail(&format!("X[{}1]", "-".repeat(200)));
    assert!(e.message.contains("nested too deeply"), "{e}");
    let e = fail(&format!("X[{}1{}]", "ABS[".repeat(100), "]".repeat(100)));
    assert!(e.message.contains("nested too deeply"), "{e}");
    // Very long operator chains are limited too.
    let e = fail(&format!("X[1{}]", "+1".repeat(1000)));
    assert!(e.message.contains("too long"), "{e}");
    // Moderate sizes are fine.
    let p = ok(&format!("X{}1{}", "[".repeat(30), "]".repeat(30)));
    assert_eq!(show(&p.blocks[0]), "X1");
    assert_eq!(num(&format!("1{}", "+1".repeat(100))), 101.0);
}

// ---------------------------------------------------------------------------------------------
// printf

fn f1(fmt: &str, x: f64) -> String {
    format(fmt, &[Value::Num(x)]).unwrap_or_else(|e| panic!("{fmt}: {e}"))
}

#[test]
fn printf_fixed_matches_c() {
    // Values checked against glibc printf("%f") on doubles.
    assert_eq!(f1("%f", 20.0), "20.000000");
    assert_eq!(f1("%f", -0.5), "-0.500000");
    assert_eq!(f1("%f", 100.0), "100.000000");
    assert_eq!(f1("%f", 55.5), "55.500000");
    assert_eq!(f1("%f", -0.0), "-0.000000");
    assert_eq!(f1("%f", 0.0000005), "0.000000"); // binary value is 4.99999…e-7
    assert_eq!(f1("%f", 2.5e-7), "0.000000");
    assert_eq!(f1("%f", 0.0000015), "0.000002");
    assert_eq!(f1("%f", 0.0000025), "0.000003"); // binary value is 2.5000000000000002e-6
    assert_eq!(f1("%f", 1.0000005), "1.000001");
    assert_eq!(f1("%f", 1e21), "1000000000000000000000.000000");
    assert_eq!(f1("%.0f", 0.5), "0");
    assert_eq!(f1("%.0f", 1.5), "2");
    assert_eq!(f1("%.0f", 2.5), "2");
    assert_eq!(f1("%.2f", 0.125), "0.12");
    assert_eq!(f1("%.2f", 2.675), "2.67");
    assert_eq!(f1("%.3f", 2.675), "2.675");
    assert_eq!(f1("%#.0f", 3.0), "3.");
    assert_eq!(f1("%5.1f", 3.14259), "  3.1");
    assert_eq!(f1("%-8.2f|", 3.14259), "3.14    |");
    assert_eq!(f1("%+08.2f", -3.14259), "-0003.14");
    assert_eq!(f1("%+.1f", 2.0), "+2.0");
    assert_eq!(f1("% .1f", 2.0), " 2.0");
    assert_eq!(f1("%010.3f", 1.5), "000001.500");
    assert_eq!(f1("%-010.3f|", 1.5), "1.500     |");
    assert_eq!(f1("%lf", 1.0), "1.000000");
    assert_eq!(f1("%F", 1.0), "1.000000");
}

#[test]
fn printf_exp_general_int_string() {
    assert_eq!(f1("%e", 1e21), "1.000000e+21");
    assert_eq!(f1("%e", 0.0000005), "5.000000e-07");
    assert_eq!(f1("%e", -0.0), "-0.000000e+00");
    assert_eq!(f1("%e", 123456789.0), "1.234568e+08");
    assert_eq!(f1("%.0e", 2.5), "2e+00");
    assert_eq!(f1("%.1e", 0.125), "1.2e-01");
    assert_eq!(f1("%E", 5e-324), "4.940656E-324");
    assert_eq!(f1("%08.2e", 12345.678), "1.23e+04");
    assert_eq!(f1("%#.0e", 3.0), "3.e+00");

    assert_eq!(f1("%g", 0.5), "0.5");
    assert_eq!(f1("%g", 100000.0), "100000");
    assert_eq!(f1("%g", 1e21), "1e+21");
    assert_eq!(f1("%g", 123456789.0), "1.23457e+08");
    assert_eq!(f1("%g", 0.0001), "0.0001");
    assert_eq!(f1("%g", 0.00001234), "1.234e-05");
    assert_eq!(f1("%g", 0.0), "0");
    assert_eq!(f1("%g", -0.0), "-0");
    assert_eq!(f1("%.3g", 2.675), "2.67");
    assert_eq!(f1("%#g", 100000.0), "100000.");
    assert_eq!(f1("%#g", 0.5), "0.500000");
    assert_eq!(f1("%G", 0.00001234), "1.234E-05");

    assert_eq!(f1("%d", 42.0), "42");
    assert_eq!(f1("[%5d]", 42.0), "[   42]");
    assert_eq!(f1("[%-5d]", 42.0), "[42   ]");
    assert_eq!(f1("[%05d]", 42.0), "[00042]");
    assert_eq!(f1("[%05d]", -42.0), "[-0042]");
    assert_eq!(f1("%+d", 42.0), "+42");
    assert_eq!(f1("% d", 42.0), " 42");
    assert_eq!(f1("%.3d", 7.0), "007");
    assert_eq!(f1("[%05.3d]", 7.0), "[  007]");
    assert_eq!(f1("[%.0d]", 0.0), "[]");
    assert_eq!(f1("%d", 2.5), "3"); // rounded to nearest, halves away from zero
    assert_eq!(f1("%d", -2.5), "-3");
    assert_eq!(f1("%i", 99.4), "99");
    assert_eq!(f1("%d", -0.4), "0");
    assert_eq!(f1("%d", 1e21), "1000000000000000000000");

    let s = |fmt: &str, v: Value| format(fmt, &[v]).unwrap();
    assert_eq!(s("%s", Value::Str("ab".into())), "ab");
    assert_eq!(s("[%5s]", Value::Str("ab".into())), "[   ab]");
    assert_eq!(s("[%-5s]", Value::Str("ab".into())), "[ab   ]");
    assert_eq!(s("[%05s]", Value::Str("ab".into())), "[   ab]");
    assert_eq!(s("%.2s", Value::Str("abc".into())), "ab");
    assert_eq!(s("%s", Value::Num(20.0)), "20");
    assert_eq!(s("%s", Value::Num(0.1)), "0.1");
    assert_eq!(s("%s", Value::Num(-1.25)), "-1.25");

    assert_eq!(format("100%% done", &[]).unwrap(), "100% done");
    assert_eq!(format("", &[]).unwrap(), "");
    assert_eq!(format("ä%fö", &[Value::Num(1.0)]).unwrap(), "ä1.000000ö");

    assert_eq!(f1("%f", f64::INFINITY), "inf");
    assert_eq!(f1("%e", f64::NEG_INFINITY), "-inf");
    assert_eq!(f1("%5.1f", f64::INFINITY), "  inf");
    assert_eq!(f1("%05f", f64::NEG_INFINITY), " -inf");
    assert_eq!(f1("%F", f64::INFINITY), "INF");
    assert_eq!(f1("%g", f64::NAN), "nan");
}

#[test]
fn printf_errors_name_the_argument() {
    let n = Value::Num(1.0);
    let s = Value::Str("x".into());
    assert_eq!(
        format("%f %f", std::slice::from_ref(&n)),
        Err(FormatError::MissingArgument {
            index: 2,
            conv: 'f',
            given: 1
        })
    );
    assert_eq!(
        format("%f", std::slice::from_ref(&s)),
        Err(FormatError::NotANumber {
            index: 1,
            conv: 'f'
        })
    );
    assert_eq!(
        format("%s %d", &[s.clone(), s.clone()]),
        Err(FormatError::NotANumber {
            index: 2,
            conv: 'd'
        })
    );
    assert_eq!(
        format("%f", &[n.clone(), n.clone()]),
        Err(FormatError::TooManyArguments {
            index: 2,
            used: 1,
            given: 2
        })
    );
    assert_eq!(
        format("ab%q", std::slice::from_ref(&n)),
        Err(FormatError::UnknownConversion { conv: 'q', pos: 3 })
    );
    assert_eq!(format("%5", &[]), Err(FormatError::Incomplete { pos: 1 }));
    assert_eq!(
        format("%99999f", std::slice::from_ref(&n)),
        Err(FormatError::FieldTooLarge { pos: 1 })
    );
    assert_eq!(
        format("%d", &[Value::Num(f64::NAN)]),
        Err(FormatError::NotFinite {
            index: 1,
            conv: 'd'
        })
    );
    let msg = format("%f", std::slice::from_ref(&s))
        .unwrap_err()
        .to_string();
    assert_eq!(msg, "argument 1 is a string, but '%f' needs a number");
    let msg = format("%f %f", std::slice::from_ref(&n))
        .unwrap_err()
        .to_string();
    assert_eq!(msg, "'%f' needs argument 2, but only 1 argument(s) given");
}

// ---------------------------------------------------------------------------------------------
// trace: parse + evaluate + format, as the executor does for #MSG SYN

/// Run every `#MSG` of `src` against fixed variable values and collect the output lines.
fn msg_trace(src: &str, vars: &Vars) -> Vec<String> {
    let program = ok(src);
    let mut out = Vec::new();
    for block in program.blocks.iter() {
        for item in &block.items {
            if let Item::Command { command, span } = item {
                let Command::Msg {
                    format: f, args, ..
                } = &**command
                else {
                    continue;
                };
                let values: Vec<Value> = args
                    .iter()
                    .map(|a| eval_at(a, vars, *span).unwrap())
                    .collect();
                out.push(format(f, &values).unwrap());
            }
        }
    }
    out
}

/// Seed 004 §5 meas1/meas4 message lines with the documented values (probe at Z=100 / 55.5).
#[test]
fn trace_seed_004_5_messages() {
    let vars = Vars::new(&[
        ("V.A.MESS.Z", 100.0),
        ("V.A.MEAS.ACS.VALUE.Z", 100.0),
        ("V.A.MOFFS.Z", 80.0),
        ("V.A.MEIN.Z", 0.0),
    ]);
    let src = "%meas1\nN30 #MSG SYN[\"V.A.MESS.Z=%f\", V.A.MESS.Z]\n\
               N31 #MSG SYN[\"V.A.MEAS.ACS.VALUE.Z=%f\",\n        V.A.MEAS.ACS.VALUE.Z]\n\
               N40 #MSG SYN[\"V.A.MOFFS.Z=%f\", V.A.MOFFS.Z]\n\
               N50 #MSG SYN[\"V.A.MEIN.Z=%f\", V.A.MEIN.Z]\n";
    assert_eq!(
        msg_trace(src, &vars),
        [
            "V.A.MESS.Z=100.000000",
            "V.A.MEAS.ACS.VALUE.Z=100.000000",
            "V.A.MOFFS.Z=80.000000",
            "V.A.MEIN.Z=0.000000"
        ]
    );
    let vars = Vars::new(&[("V.A.MEAS.ACS.VALUE.Z", 55.5), ("V.A.ABS.X", 150.0)]);
    assert_eq!(
        msg_trace(
            "N41 #MSG SYN[\"Z=%f X=%.1f d=%d\", V.A.MEAS.ACS.VALUE.Z, V.A.ABS.X, \
             V.A.ABS.X/7]",
            &vars
        ),
        ["Z=55.500000 X=150.0 d=21"]
    );
}

// ---------------------------------------------------------------------------------------------
// robustness: never panic

const VALID: &[&str] = &[
    "%swe_abs.nc\nN110 G00 X0 Y0 G90\nN120 G00 X20 Y30\n(Sets neg. SLS)\nN130 G98 X-100 Y-200\n( .... )\n",
    "N10 G01 G90 X199\n...\nN100 G98 X-500 Y-500 ;neg.\nN200 G99 X500 Y500\n",
    "%Meas_run\nN10 G00 X0 Y0 Z0\nN20 X5\nN30 G100 X10 Y10 F500\nN40 G01 X7\nN50 M30\n",
    "N30 #MSG SYN[\"V.A.MESS.Z=%f\", V.A.MESS.Z]\nN31 #MSG SYN[\"x=%f\",\n V.A.MEAS.ACS.VALUE.Z]\n",
    "N20 X[ABS[-1]*SIN[30]+ATAN2[1,2]/[V.A.-SWE.X-2]] \\\n Y2=100 F=V.G.F\n",
    "N20 X[INDP_SYN G100 G90 POS100 FEED500] \\\n Y[INDP_ASYN G01 G91 POS=-5 FEED=1000]\nD1\n",
    "N10 P1 = 5\nP2=V.A.ABS.X + P1 * 2\nX=P1 Y[P2/2]\n#MEAS MODE [2]\n#MEAS MODE\n",
    "#MEAS [AXNR=2 SIGNAL=PLC_TIMESTAMP EDGE=POS]\n#MEAS PREPARE [AXNR=1 AXNR=2]\n#CS ON[0,0,0,0,45]\n\\#CS OFF\n#TRAFO ON\n",
    "NO30 #DRIVE WR SYN [AX=Z KEY=TORQUE LIMIT VAL=10 WAIT]\n#DRIVE RD [AX=Z KEY=MON_WINDOW P=P10]\n",
    "N060 #IDENT RD\n  [AXNR 4 ID S-0-0092 P=P2092\n    TYP 2 DEC 0 SERC]\nN070 #IDENT WR SYN [AX X ID 0x6072_00 VAL=P1 CAN]\n",
    "N020 #SET AX LINK[1, [X2=X,G,15,20]]\nN030 #ENABLE AX LINK[1]\n#DISABLE AX LINK\n",
];

const ALPHABET: &[char] = &[
    'N', 'G', 'X', 'Y', 'V', '.', 'A', '-', '+', '[', ']', '(', ')', ';', '"', '\\', '\n', ' ',
    '1', '0', '5', '=', '#', 'M', 'S', 'Y', '%', ',', '*', '/', 'ä', '\r', '\t', 'Q', 'E', 'P',
    'D', 'O', 'I', '_', 'K', 'R', 'W', 'C', 'L', 'x',
];

/// Programs of seed 004 as the seed tests parse them (annotations removed).
fn seed_004_programs() -> &'static [String] {
    static PROGRAMS: OnceLock<Vec<String>> = OnceLock::new();
    PROGRAMS.get_or_init(|| {
        [
            ("Meas_run", 0),
            ("Independent_measurement_path", 0),
            ("Measurement run standard", 0),
            ("Measurement run CS", 0),
            ("meas1", 0),
            ("meas2", 0),
            ("meas3", 0),
            ("meas4", 0),
            ("meas_example", 0),
            ("Meas fixed stop", 0),
            ("Meas fixed stop", 1),
        ]
        .iter()
        .map(|&(name, nth)| without_annotations(&seed_program(name, nth)))
        .collect()
    })
}

fn mutate(text: &str, edits: Vec<(prop::sample::Index, u8, char)>) -> String {
    let mut chars: Vec<char> = text.chars().collect();
    for (idx, kind, c) in edits {
        let i = if chars.is_empty() {
            0
        } else {
            idx.index(chars.len())
        };
        match kind {
            0 if !chars.is_empty() => {
                chars.remove(i);
            }
            1 => chars.insert(i, c),
            _ if !chars.is_empty() => chars[i] = c,
            _ => chars.push(c),
        }
    }
    chars.into_iter().collect()
}

/// Parse `s`; if it parses, evaluate every expression in it (against no variables) so that the
/// evaluator sees every shape the parser can produce. Errors must carry a position.
fn parse_and_eval(s: &str) -> Result<(), TestCaseError> {
    match parse(s) {
        Ok(p) => {
            let vars = Vars::new(&[]);
            let mut exprs: Vec<&Expr> = Vec::new();
            for b in p.blocks.iter() {
                for it in &b.items {
                    match it {
                        Item::Axis { value, .. }
                        | Item::F { value, .. }
                        | Item::D { value, .. }
                        | Item::Centre { value, .. }
                        | Item::Assign { value, .. } => exprs.push(value),
                        Item::Independent { motion, .. } => {
                            exprs.push(&motion.pos);
                            exprs.extend(motion.feed.iter());
                        }
                        Item::Command { command, .. } => match &**command {
                            Command::Msg { args, .. } => exprs.extend(args),
                            Command::MeasConfig { args }
                            | Command::MeasPrepare { args }
                            | Command::Drive { args, .. }
                            | Command::Ident { args, .. } => {
                                exprs.extend(args.iter().filter_map(|a| a.value.as_ref()))
                            }
                            Command::Cs { on: Some(v) } => exprs.extend(v),
                            Command::MeasMode { mode: Some(e) }
                            | Command::EnableAxLink { group: Some(e), .. } => exprs.push(e),
                            Command::SetAxLink { group, links } => {
                                exprs.push(group);
                                exprs.extend(links.iter().flat_map(|l| &l.params));
                            }
                            _ => {}
                        },
                        Item::G { .. } | Item::M { .. } => {}
                    }
                }
            }
            for e in exprs {
                let _ = eval(e, &vars);
            }
        }
        Err(e) => {
            prop_assert!(e.line >= 1 && e.col >= 1, "{e}");
            prop_assert!(!e.message.is_empty());
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_strings_never_panic(s in "\\PC{0,200}") {
        let _ = parse(&s);
        let _ = parse_expr(&s);
    }

    #[test]
    fn random_nc_like_strings_never_panic(
        v in proptest::collection::vec(proptest::sample::select(ALPHABET), 0..200)
    ) {
        let s: String = v.into_iter().collect();
        parse_and_eval(&s)?;
    }

    #[test]
    fn mutated_valid_programs_never_panic(
        which in 0..VALID.len(),
        edits in proptest::collection::vec(
            (any::<prop::sample::Index>(), 0u8..3, proptest::sample::select(ALPHABET)), 1..8)
    ) {
        parse_and_eval(&mutate(VALID[which], edits))?;
    }

    #[test]
    fn mutated_seed_004_programs_never_panic(
        which in any::<prop::sample::Index>(),
        edits in proptest::collection::vec(
            (any::<prop::sample::Index>(), 0u8..3, proptest::sample::select(ALPHABET)), 1..12)
    ) {
        if !test_data::seeds_present("mutated_seed_004_programs_never_panic") {
            return Ok(());
        }
        let programs = seed_004_programs();
        parse_and_eval(&mutate(&programs[which.index(programs.len())], edits))?;
    }

    #[test]
    fn printf_never_panics(fmt in "\\PC{0,40}", a in any::<f64>(), b in "\\PC{0,5}") {
        let _ = format(&fmt, &[Value::Num(a), Value::Str(b)]);
        let _ = format(&fmt, &[]);
    }

    #[test]
    fn printf_f_matches_rust_exact_rounding(x in -1e9f64..1e9, p in 0usize..12) {
        let got = format(&format!("%.{p}f"), &[Value::Num(x)]).unwrap();
        prop_assert_eq!(got, std::format!("{:.*}", p, x));
    }

    #[test]
    fn integers_parse_back(n in 0u32..1_000_000, x in -1e6f64..1e6) {
        let x = (x * 1000.0).round() / 1000.0;
        let p = parse(&std::format!("N{n} X{x}")).unwrap();
        prop_assert_eq!(p.blocks[0].number, Some(n));
        let Item::Axis { value, .. } = &p.blocks[0].items[0] else { panic!() };
        prop_assert_eq!(value, &Expr::Num(x));
    }
}
