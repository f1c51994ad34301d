//! The NC executor: walks a [`Program`] block by block, keeps the modal state (G00–G03,
//! G17–G19, G90 / G91, G161 / G162, F) and the programmed positions, and hands motion and
//! limit changes to the [`Channel`].
//!
//! The executor runs a block only when the channel is idle, so a `#MSG SYN` line is output
//! exactly when all earlier motion has finished (main-run synchronous).
//!
//! Coordinates: programmed positions are PCS; `acs = pcs + offset` with the G92 offsets. G98 /
//! G99 values are ACS (seed 001 §2: "The positions of the SLS are always referred to the axis
//! coordinate system").

use super::ast::{Block, Command, Expr, Item, Program, Span, VarRef};
use super::expr::{eval_at, eval_num_at, Value, VarSource};
use super::printf;
use crate::channel::{Channel, ChannelState, MotionKind, MotionRequest, Prepared};
use crate::core::monitor::sls::Side;
use crate::messages::{ids, BlockRef, CncMessage};

/// Active plane (G17 / G18 / G19).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// G17: X → Y, tool axis Z.
    G17,
    /// G18: Z → X, tool axis Y.
    G18,
    /// G19: Y → Z, tool axis X.
    G19,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MotionMode {
    G0,
    G1,
    G2,
    G3,
}

/// Modal state of the executor.
#[derive(Debug, Clone, PartialEq)]
pub struct Modal {
    motion: MotionMode,
    /// G17 / G18 / G19.
    pub plane: Plane,
    /// G90 (true) / G91.
    pub absolute: bool,
    /// G161 (true): I/J/K are absolute centre coordinates; G162 (default): relative to the start.
    pub centre_absolute: bool,
    /// Active feed in mm/min.
    pub feed: Option<f64>,
}

impl Default for Modal {
    fn default() -> Self {
        Modal {
            motion: MotionMode::G1,
            plane: Plane::G17,
            absolute: true,
            centre_absolute: false,
            feed: None,
        }
    }
}

/// What one executed block produced.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A `#MSG` line (stdout).
    Output(String),
}

/// Result of [`Executor::step`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The block was handled; step the channel until idle, then call again.
    Continue,
    /// Program end (M30 / M02 or the last block).
    End,
    /// The block raised an error (queued in the channel); the program is aborted.
    Abort,
}

/// Executes a program on a channel.
#[derive(Debug, Clone)]
pub struct Executor {
    program: Program,
    pc: usize,
    modal: Modal,
    /// Programmed (PCS) positions.
    prog: Vec<f64>,
    names: Vec<String>,
    /// Indices of the main axes X, Y, Z in the channel.
    main: [Option<usize>; 3],
    ended: bool,
}

impl Executor {
    /// An executor for `program` on a channel whose axes are named `axis_names`.
    pub fn new(program: Program, axis_names: Vec<String>) -> Self {
        let find = |n: &str| axis_names.iter().position(|a| a.eq_ignore_ascii_case(n));
        let main = [find("X"), find("Y"), find("Z")];
        let prog = vec![0.0; axis_names.len()];
        Executor {
            program,
            pc: 0,
            modal: Modal::default(),
            prog,
            names: axis_names,
            main,
            ended: false,
        }
    }

    /// Static checks before the run (exit code 2 territory): every axis word names a channel
    /// axis, every G code is supported. Returns the first problem as `(span, text)`.
    pub fn validate(&self) -> Result<(), (Span, String)> {
        for b in &self.program.blocks {
            for item in &b.items {
                match item {
                    Item::Axis { name, span, .. } if self.axis(name).is_none() => {
                        return Err((
                            *span,
                            format!(
                                "unknown axis '{name}'; the channel has {}",
                                self.names.join(", ")
                            ),
                        ));
                    }
                    Item::G { code, span } if !SUPPORTED_G.contains(code) => {
                        return Err((
                            *span,
                            format!(
                                "G{code} is not supported; supported: {}",
                                supported_g_text()
                            ),
                        ));
                    }
                    _ => {}
                }
            }
        }
        Ok(())
    }

    /// Modal state.
    pub fn modal(&self) -> &Modal {
        &self.modal
    }

    /// Programmed (PCS) position of axis `i` (`V.A.PROG`).
    pub fn programmed(&self, i: usize) -> Option<f64> {
        self.prog.get(i).copied()
    }

    /// Sync the programmed positions with the channel (at program start).
    pub fn sync(&mut self, ch: &Channel) {
        for i in 0..self.prog.len() {
            self.prog[i] = ch.axes().get(i).map(|a| a.command()).unwrap_or(0.0) - ch.pcs_offset(i);
        }
    }

    fn axis(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|a| a.eq_ignore_ascii_case(name))
    }

    /// Execute the next block. Call only when the channel is idle.
    pub fn step(&mut self, ch: &mut Channel, events: &mut Vec<Event>) -> Step {
        if self.ended {
            return Step::End;
        }
        let Some(block) = self.program.blocks.get(self.pc).cloned() else {
            self.ended = true;
            return Step::End;
        };
        self.pc += 1;
        let bref = BlockRef {
            number: block.number,
            line: block.span.line,
        };
        ch.set_block(Some(bref));
        match self.run_block(&block, ch, events) {
            Ok(end) => {
                if end {
                    self.ended = true;
                    Step::End
                } else {
                    Step::Continue
                }
            }
            Err(Fail::New(m)) => {
                ch.report(m);
                Step::Abort
            }
            Err(Fail::Queued) => Step::Abort,
        }
    }

    fn run_block(
        &mut self,
        block: &Block,
        ch: &mut Channel,
        events: &mut Vec<Event>,
    ) -> Result<bool, Fail> {
        // 1. G codes: modal groups first, so `G00 X0 Y0 G90` uses G90.
        let mut g92 = false;
        let mut limit: Option<Side> = None;
        let mut end = false;
        for item in &block.items {
            match item {
                Item::G { code, .. } => match code {
                    0 => self.modal.motion = MotionMode::G0,
                    1 => self.modal.motion = MotionMode::G1,
                    2 => self.modal.motion = MotionMode::G2,
                    3 => self.modal.motion = MotionMode::G3,
                    17 => self.modal.plane = Plane::G17,
                    18 => self.modal.plane = Plane::G18,
                    19 => self.modal.plane = Plane::G19,
                    90 => self.modal.absolute = true,
                    91 => self.modal.absolute = false,
                    92 => g92 = true,
                    98 => limit = Some(Side::Negative),
                    99 => limit = Some(Side::Positive),
                    161 => self.modal.centre_absolute = true,
                    162 => self.modal.centre_absolute = false,
                    other => {
                        return Err(Fail::New(CncMessage::error(
                            ids::NC_UNSUPPORTED,
                            format!(
                                "G{other} is not supported; supported: {}",
                                supported_g_text()
                            ),
                        )))
                    }
                },
                Item::M { code, .. } => {
                    if matches!(code, 2 | 30) {
                        end = true;
                    }
                }
                _ => {}
            }
        }
        // 2. Words.
        let mut axes: Vec<(usize, f64)> = Vec::new();
        let mut centre: [Option<f64>; 3] = [None; 3];
        for item in &block.items {
            match item {
                Item::F { value, span } => {
                    let f = self.num(value, *span, ch)?;
                    if f.is_nan() || f <= 0.0 {
                        return Err(Fail::New(CncMessage::error(
                            ids::NC_NO_FEED,
                            format!("feed F{f} must be > 0"),
                        )));
                    }
                    self.modal.feed = Some(f);
                }
                Item::Axis { name, value, span } => {
                    let i = self.axis(name).ok_or_else(|| {
                        Fail::New(CncMessage::error(
                            ids::NC_EVALUATION,
                            format!("unknown axis '{name}'"),
                        ))
                    })?;
                    let v = self.num(value, *span, ch)?;
                    axes.push((i, v));
                }
                Item::Centre {
                    letter,
                    value,
                    span,
                } => {
                    let k = match letter.to_ascii_uppercase() {
                        'I' => 0,
                        'J' => 1,
                        _ => 2,
                    };
                    centre[k] = Some(self.num(value, *span, ch)?);
                }
                Item::Command {
                    command: Command::Msg { format, args, .. },
                    span,
                } => {
                    let mut vals = Vec::with_capacity(args.len());
                    for a in args {
                        let src = Vars { exec: self, ch };
                        vals.push(eval_at(a, &src, *span).map_err(|e| {
                            Fail::New(CncMessage::error(ids::NC_EVALUATION, e.to_string()))
                        })?);
                    }
                    let line = printf::format(format, &vals).map_err(|e| {
                        Fail::New(CncMessage::error(ids::NC_EVALUATION, format!("#MSG: {e}")))
                    })?;
                    events.push(Event::Output(line));
                }
                _ => {}
            }
        }
        // 3. Non-modal functions that take the axis words.
        if let Some(side) = limit {
            for (i, v) in axes {
                ch.program_limit(i, side, v, !self.modal.absolute);
                if !matches!(ch.state(), ChannelState::Idle) {
                    return Err(Fail::Queued);
                }
            }
            return Ok(end);
        }
        if g92 {
            // ISG G92 is a reference-point offset: the programmed values shift the PCS
            // additively (seed 004 §5 meas2: `G92 Z33` → ACS = PCS + 33). The axis does not move;
            // its programmed (PCS) position changes by the difference of the offsets.
            for (i, v) in axes {
                let old = ch.pcs_offset(i);
                ch.set_pcs_offset(i, v);
                self.prog[i] -= v - old;
            }
            return Ok(end);
        }
        // 4. Motion.
        let is_arc = matches!(self.modal.motion, MotionMode::G2 | MotionMode::G3);
        if axes.is_empty() && !(is_arc && centre.iter().any(Option::is_some)) {
            return Ok(end);
        }
        let mut prog = self.prog.clone();
        for &(i, v) in &axes {
            prog[i] = if self.modal.absolute { v } else { prog[i] + v };
        }
        let target: Vec<f64> = prog
            .iter()
            .enumerate()
            .map(|(i, p)| p + ch.pcs_offset(i))
            .collect();
        let feed = match self.modal.motion {
            MotionMode::G0 => 0.0,
            _ => self.modal.feed.ok_or_else(|| {
                Fail::New(CncMessage::error(
                    ids::NC_NO_FEED,
                    "no feed programmed (F) for a G01/G02/G03 block",
                ))
            })?,
        };
        let kind = match self.modal.motion {
            MotionMode::G0 => MotionKind::Rapid,
            MotionMode::G1 => MotionKind::Linear,
            MotionMode::G2 | MotionMode::G3 => self.arc_kind(&centre).map_err(Fail::New)?,
        };
        let req = MotionRequest { kind, target, feed, measure: None };
        match ch.start_motion(&req) {
            Prepared::Started | Prepared::Empty => {
                self.prog = prog;
                Ok(end)
            }
            Prepared::Rejected => Err(Fail::Queued),
        }
    }

    fn arc_kind(&self, centre: &[Option<f64>; 3]) -> Result<MotionKind, CncMessage> {
        // (a1, a2) and which of I/J/K belong to them, per plane (DIN 66025).
        let (a1, a2, c1, c2) = match self.modal.plane {
            Plane::G17 => (self.main[0], self.main[1], 0, 1),
            Plane::G18 => (self.main[2], self.main[0], 2, 0),
            Plane::G19 => (self.main[1], self.main[2], 1, 2),
        };
        let (Some(a1), Some(a2)) = (a1, a2) else {
            return Err(CncMessage::error(
                ids::NC_ARC_GEOMETRY,
                "G02/G03: the channel lacks a main axis of the active plane",
            ));
        };
        let o1 = centre[c1].unwrap_or(0.0);
        let o2 = centre[c2].unwrap_or(0.0);
        let centre_offset = if self.modal.centre_absolute {
            // G161: absolute PCS centre → offset from the start point.
            [o1 - self.prog[a1], o2 - self.prog[a2]]
        } else {
            [o1, o2]
        };
        Ok(MotionKind::Arc {
            a1,
            a2,
            centre_offset,
            clockwise: self.modal.motion == MotionMode::G2,
        })
    }

    fn num(&self, e: &Expr, span: Span, ch: &Channel) -> Result<f64, Fail> {
        let src = Vars { exec: self, ch };
        eval_num_at(e, &src, span)
            .map_err(|e| Fail::New(CncMessage::error(ids::NC_EVALUATION, e.to_string())))
    }
}

/// G codes this build executes.
pub const SUPPORTED_G: &[u32] = &[0, 1, 2, 3, 17, 18, 19, 90, 91, 92, 98, 99, 161, 162];

fn supported_g_text() -> String {
    SUPPORTED_G
        .iter()
        .map(|g| format!("G{g:02}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Why a block failed.
enum Fail {
    /// A new error to report.
    New(CncMessage),
    /// The channel already queued the error.
    Queued,
}

struct Vars<'a> {
    exec: &'a Executor,
    ch: &'a Channel,
}

impl VarSource for Vars<'_> {
    /// `V.A.ABS.<ax>` (ACS command position), `V.A.PROG.<ax>` (programmed PCS position),
    /// `V.A.-SWE.<ax>` / `V.A.+SWE.<ax>` (active programmed SLS, seed 001 §3).
    fn var(&self, var: &VarRef) -> Result<Value, String> {
        let s: Vec<&str> = var.segments.iter().map(String::as_str).collect();
        let axis = |n: &str| {
            self.exec
                .axis(n)
                .ok_or_else(|| format!("{}: unknown axis '{n}'", var.name()))
        };
        match s.as_slice() {
            ["V", "A", "ABS", ax] => {
                let i = axis(ax)?;
                Ok(Value::Num(self.ch.axes()[i].command()))
            }
            ["V", "A", "PROG", ax] => Ok(Value::Num(self.exec.prog[axis(ax)?])),
            ["V", "A", "-SWE", ax] | ["V", "A", "+SWE", ax] => {
                let i = axis(ax)?;
                let (neg, pos) = self.ch.soft_limits().active_limits(i).unwrap_or((0.0, 0.0));
                Ok(Value::Num(if s[2] == "-SWE" { neg } else { pos }))
            }
            _ => Err(format!(
                "unknown variable {}; known: V.A.ABS.<axis>, V.A.PROG.<axis>, V.A.-SWE.<axis>, V.A.+SWE.<axis>",
                var.name()
            )),
        }
    }
}
