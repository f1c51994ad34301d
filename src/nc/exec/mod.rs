//! The NC executor: walks a [`Program`] block by block, keeps the modal state (G00–G03,
//! G17–G19, G90 / G91, G161 / G162, G54–G59, F, measurement type), the frames (G92, zero
//! offsets, MEIN, tool, `#CS`) and the programmed positions, and hands motion, measurement,
//! limit changes and acyclic drive access to the [`Channel`].
//!
//! The executor runs a block only when the channel is idle, so a `#MSG SYN` line is output
//! exactly when all earlier motion has finished (main-run synchronous), and measurement results
//! of a block are available to the next one.
//!
//! Coordinates: programmed positions are PCS; `w = PCS + zero shifts + MEIN (+ tool length)` is
//! the CS frame (`V.A.ABS`); `#CS` maps `w` to the ACS ([`crate::core::frames`]). G98 / G99 values
//! are ACS (FCT-A2 §2: "The positions of the SLS are always referred to the axis coordinate
//! system").

mod areas;
mod commands;
mod motion;
mod vars;

use super::ast::{Block, Command, Item, Program, Span};
use super::expr::{eval_at, eval_num_at, Value};
use super::printf;
use crate::channel::{Channel, ChannelState, SignalOverride};
use crate::core::frames::Frames;
use crate::core::measure::results::AxisResult;
use crate::core::measure::{MeasType, MeasurementOutcome};
use crate::core::monitor::sls::Side;
use crate::messages::{ids, BlockRef, CncMessage};
use crate::params::ToolData;
use std::collections::BTreeMap;

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
    /// Active measurement type (`#MEAS MODE`, default P-CHAN-00057).
    pub meas_type: MeasType,
    /// Active zero offset G54 … G59 (`None`: G53 / none).
    pub zero_offset: Option<u32>,
}

impl Default for Modal {
    fn default() -> Self {
        Modal {
            motion: MotionMode::G1,
            plane: Plane::G17,
            absolute: true,
            centre_absolute: false,
            feed: None,
            meas_type: MeasType::Type1,
            zero_offset: None,
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

/// A measuring block whose outcome the channel will publish.
#[derive(Debug, Clone)]
struct PendingMeasurement {
    target_pcs: Vec<f64>,
    programmed: Vec<bool>,
    direction_pcs: [f64; 3],
}

/// An acyclic read whose value goes into a P-parameter (`#IDENT RD … P=P1092`).
#[derive(Debug, Clone)]
struct PendingRead {
    id: u64,
    param: u32,
    /// Wire value → program value.
    decode: Decode,
}

#[derive(Debug, Clone)]
enum Decode {
    /// Divide by this (drive function scale, `DEC`).
    Scale(f64),
    /// SERCOS IDN mapping special value, then divide.
    Idn { zero: Option<i64>, scale: f64 },
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
    frames: Frames,
    setup_error: Option<String>,
    tools: BTreeMap<u32, ToolData>,
    zero_offsets: BTreeMap<u32, Vec<f64>>,
    tool: Option<ToolData>,
    results: Vec<Option<AxisResult>>,
    merf: Vec<bool>,
    last_meas_type: Option<MeasType>,
    overrides: Vec<SignalOverride>,
    params: BTreeMap<u32, f64>,
    pending_meas: Option<PendingMeasurement>,
    /// The PCS target of the last measuring block, per axis it programmed, until the next
    /// motion block or frame change: `V.A.PROG` after a G100 the signal interrupted reads the
    /// target point, as seed 004 §5 "MOFFS = V.A.MESS − V.A.PROG − …" reads it
    /// (docs/interpretations.md M30); [`Executor::prog`] holds where the axis stopped, the start
    /// of the next block.
    meas_target: Vec<Option<f64>>,
    pending_reads: Vec<PendingRead>,
    /// Positions moved by something other than the program (measurement stop, fixed stop):
    /// re-read the programmed positions from the channel before the next block.
    resync: bool,
    /// An area definition is open (`#CONTROL AREA BEGIN` … `END`).
    area_def: Option<areas::OpenArea>,
}

/// Why a block failed.
enum Fail {
    /// A new error to report.
    New(CncMessage),
    /// The channel already queued the error.
    Queued,
}

fn err(id: u32, text: impl Into<String>) -> Fail {
    Fail::New(CncMessage::error(id, text))
}

impl Executor {
    /// An executor for `program` on a channel whose axes are named `axis_names`.
    pub fn new(program: Program, axis_names: Vec<String>) -> Self {
        let find = |n: &str| axis_names.iter().position(|a| a.eq_ignore_ascii_case(n));
        let main = [find("X"), find("Y"), find("Z")];
        let n = axis_names.len();
        let (frames, setup_error) = match Frames::new(n, main) {
            Ok(f) => (f, None),
            Err(e) => (Frames::empty(), Some(e.to_string())),
        };
        Executor {
            program,
            pc: 0,
            modal: Modal::default(),
            prog: vec![0.0; n],
            names: axis_names,
            main,
            ended: false,
            frames,
            setup_error,
            tools: BTreeMap::new(),
            zero_offsets: BTreeMap::new(),
            tool: None,
            results: vec![None; n],
            merf: vec![false; n],
            last_meas_type: None,
            overrides: Vec::new(),
            params: BTreeMap::new(),
            pending_meas: None,
            meas_target: vec![None; n],
            pending_reads: Vec::new(),
            resync: false,
            area_def: None,
        }
    }

    /// Tool data by D number (`D1` selects tool 1's radius and length).
    pub fn set_tools(&mut self, tools: BTreeMap<u32, ToolData>) {
        self.tools = tools;
    }

    /// Zero offset table: G number (54 … 59) → offset per channel axis (mm).
    pub fn set_zero_offsets(&mut self, table: BTreeMap<u32, Vec<f64>>) {
        self.zero_offsets = table;
    }

    /// Static checks before the run (exit code 2 territory): every axis word names a channel
    /// axis, every G code is supported. Returns the first problem as `(span, text)`.
    pub fn validate(&self) -> Result<(), (Span, String)> {
        if let Some(e) = &self.setup_error {
            return Err((Span::default(), e.clone()));
        }
        for b in self.program.blocks.iter() {
            for item in &b.items {
                match item {
                    Item::Axis { name, span, .. }
                    | Item::Independent {
                        axis: name, span, ..
                    } if self.axis(name).is_none() => {
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
                    Item::Command { command, span }
                        if matches!(**command, Command::Trafo { .. }) =>
                    {
                        return Err((
                            *span,
                            "#TRAFO (kinematic transformation) is not supported by fieldprobe; measure in 2.5D or with #CS".into(),
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

    /// Programmed (PCS) position of axis `i` (`V.A.PROG`): after a measuring block, the
    /// block's target point (seed 004 §5: "Measurement offset = measuring point - target
    /// point", `MOFFS = V.A.MESS − V.A.PROG − …`) until the next motion block or frame change,
    /// also when the signal stopped the axis short of it; else where the last block took it.
    pub fn programmed(&self, i: usize) -> Option<f64> {
        match self.meas_target.get(i) {
            Some(Some(t)) => Some(*t),
            _ => self.prog.get(i).copied(),
        }
    }

    /// The frames (offsets, MEIN, `#CS`).
    pub fn frames(&self) -> &Frames {
        &self.frames
    }

    /// Measurement result of axis `i` (`V.A.MESS` & co.), if any.
    pub fn result(&self, i: usize) -> Option<AxisResult> {
        self.results.get(i).copied().flatten()
    }

    /// `V.A.MERF` of axis `i`.
    pub fn merf(&self, i: usize) -> bool {
        self.merf.get(i).copied().unwrap_or(false)
    }

    /// Arithmetic parameter `P<n>`.
    pub fn param(&self, n: u32) -> Option<f64> {
        self.params.get(&n).copied()
    }

    /// Sync with the channel at program start: measurement type default, programmed positions.
    pub fn sync(&mut self, ch: &Channel) {
        self.modal.meas_type = ch.config().meas.default_type;
        self.resync_positions(ch);
    }

    /// A modulo axis the channel wrapped at rest (P-AXIS-00015 ACHSMODE_MODULO): its
    /// programmed position follows, so the next block starts from the wrapped position.
    fn resync_modulo(&mut self, ch: &Channel) {
        let n = self.prog.len();
        if !(0..n).any(|i| ch.modulo_range(i).is_some()) {
            return;
        }
        let cmd = ch.command_positions();
        if cmd.len() != n {
            return;
        }
        let mut pcs = vec![0.0; n];
        self.frames.acs_to_pcs(&cmd, &mut pcs);
        for (i, p) in pcs.into_iter().enumerate() {
            if ch.modulo_range(i).is_some() && !ch.moving_independently(i) && p != self.prog[i] {
                self.prog[i] = p;
                self.meas_target[i] = None;
            }
        }
    }

    fn resync_positions(&mut self, ch: &Channel) {
        let cmd = ch.command_positions();
        if cmd.len() == self.prog.len() {
            self.frames.acs_to_pcs(&cmd, &mut self.prog);
        }
    }

    fn axis(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|a| a.eq_ignore_ascii_case(name))
    }

    /// Execute the next block. Call only when the channel is idle.
    pub fn step(&mut self, ch: &mut Channel, events: &mut Vec<Event>) -> Step {
        if self.ended {
            // What finished after the last block (an `INDP_ASYN` measurement the program end
            // waited for) is still taken.
            if let Err(f) = self.collect(ch) {
                if let Fail::New(m) = f {
                    ch.report(m);
                }
                return Step::Abort;
            }
            return Step::End;
        }
        if let Some(e) = self.setup_error.clone() {
            ch.report(CncMessage::error(ids::NC_EVALUATION, e));
            return Step::Abort;
        }
        if let Err(f) = self.collect(ch) {
            if let Fail::New(m) = f {
                ch.report(m);
            }
            return Step::Abort;
        }
        let Some(block) = self.program.blocks.get(self.pc).cloned() else {
            self.ended = true;
            // An area definition still open at program end is an error (FCT-C14 §3.1: "Each
            // control area must be closed by the command #CONTROL AREA END").
            if ch.area_program_end() {
                return Step::Abort;
            }
            return Step::End;
        };
        self.pc += 1;
        let bref = BlockRef {
            number: block.number,
            line: block.span.line,
        };
        tracing::trace!(block = %bref, "execute block");
        ch.set_block(Some(bref));
        match self.run_block(&block, ch, events) {
            Ok(end) => {
                if end {
                    self.ended = true;
                    if ch.area_program_end() {
                        return Step::Abort;
                    }
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

    /// Results of the previous block: measurement outcome, acyclic reads, positions moved by
    /// the channel itself.
    fn collect(&mut self, ch: &mut Channel) -> Result<(), Fail> {
        if let Some(out) = ch.take_measurement() {
            self.take_outcome(ch, out)?;
        }
        let mut still = Vec::new();
        for r in std::mem::take(&mut self.pending_reads) {
            match ch.take_acyclic_result(r.id) {
                Some(Ok(raw)) => {
                    let v = match r.decode {
                        Decode::Scale(s) => raw as f64 / s,
                        Decode::Idn { zero, scale } => {
                            (if zero == Some(raw) { 0 } else { raw }) as f64 / scale
                        }
                    };
                    self.params.insert(r.param, v);
                }
                Some(Err(_)) => {} // reported by the channel already
                None => still.push(r),
            }
        }
        self.pending_reads = still;
        if self.resync {
            self.resync = false;
            self.resync_positions(ch);
        }
        self.resync_modulo(ch);
        Ok(())
    }

    fn take_outcome(&mut self, ch: &Channel, out: MeasurementOutcome) -> Result<(), Fail> {
        self.last_meas_type = Some(out.mtype);
        let Some(pm) = self.pending_meas.take() else {
            return Ok(());
        };
        let radius = self.tool.map(|t| t.radius).unwrap_or(0.0);
        let block = crate::core::measure::results::MeasuringBlock {
            target_pcs: &pm.target_pcs,
            programmed: &pm.programmed,
            direction_pcs: pm.direction_pcs,
            ball_radius: radius,
            include_radius: !ch.config().meas.pcs_without_radius,
        };
        let results = crate::core::measure::results::compute(
            &self.frames,
            &block,
            &out.latched,
            &self.results,
        )
        .map_err(|e| err(ids::MEAS_LATCH, format!("measurement results: {e}")))?;
        self.results = results;
        for (i, inv) in out.involved.iter().enumerate() {
            if *inv || pm.programmed.get(i).copied().unwrap_or(false) {
                self.merf[i] =
                    out.merf.get(i).copied().unwrap_or(false) && self.results[i].is_some();
            }
        }
        Ok(())
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
        let mut meas_g: Option<u32> = None;
        let mut g101 = false;
        let mut g102 = false;
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
                    53..=59 => self.select_zero_offset(*code, ch)?,
                    90 => self.modal.absolute = true,
                    91 => self.modal.absolute = false,
                    92 => g92 = true,
                    98 => limit = Some(Side::Negative),
                    99 => limit = Some(Side::Positive),
                    100 | 210 | 310 => meas_g = Some(*code),
                    101 => g101 = true,
                    102 => g102 = true,
                    161 => self.modal.centre_absolute = true,
                    162 => self.modal.centre_absolute = false,
                    other => {
                        return Err(err(
                            ids::NC_UNSUPPORTED,
                            format!(
                                "G{other} is not supported; supported: {}",
                                supported_g_text()
                            ),
                        ))
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
        // 2. Words and commands in source order.
        let mut axes: Vec<(usize, f64)> = Vec::new();
        let mut centre: [Option<f64>; 3] = [None; 3];
        let mut independent = Vec::new();
        for item in &block.items {
            match item {
                Item::F { value, span } => {
                    let f = self.num(value, *span, ch)?;
                    if f.is_nan() || f <= 0.0 {
                        return Err(err(ids::NC_NO_FEED, format!("feed F{f} must be > 0")));
                    }
                    self.modal.feed = Some(f);
                }
                Item::D { value, span } => {
                    let d = self.num(value, *span, ch)?;
                    self.select_tool(d, ch)?;
                }
                Item::Axis { name, value, span } => {
                    let i = self
                        .axis(name)
                        .ok_or_else(|| err(ids::NC_EVALUATION, format!("unknown axis '{name}'")))?;
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
                Item::Independent { axis, motion, span } => {
                    independent.push((axis.clone(), (**motion).clone(), *span));
                }
                Item::Assign { param, value, span } => {
                    let v = self.num(value, *span, ch)?;
                    self.params.insert(*param, v);
                }
                Item::Command { command, span } => {
                    if let Command::Msg { format, args, .. } = &**command {
                        let mut vals = Vec::with_capacity(args.len());
                        for a in args {
                            let src = vars::Vars { exec: self, ch };
                            vals.push(
                                eval_at(a, &src, *span)
                                    .map_err(|e| err(ids::NC_EVALUATION, e.to_string()))?,
                            );
                        }
                        let line = printf::format(format, &vals)
                            .map_err(|e| err(ids::NC_EVALUATION, format!("#MSG: {e}")))?;
                        events.push(Event::Output(line));
                    } else {
                        self.command(command, *span, ch)?;
                    }
                }
                Item::G { .. } | Item::M { .. } => {}
            }
        }
        if !matches!(ch.state(), ChannelState::Idle | ChannelState::Busy) {
            return Err(Fail::Queued);
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
            // additively (FCT-C4 §5 meas2: `G92 Z33` → ACS = PCS + 33). The axis does not move.
            for (i, v) in axes {
                self.frames
                    .set_g92(i, v)
                    .map_err(|e| err(ids::NC_EVALUATION, format!("G92: {e}")))?;
            }
            self.frames_changed(ch);
            return Ok(end);
        }
        if g101 {
            let list: Vec<(usize, f64)> = axes;
            crate::core::measure::results::g101(&mut self.frames, &self.results, &list).map_err(
                |e| {
                    let axis = match e {
                        crate::core::measure::results::ResultsError::NoMeasuredValue { axis } => {
                            self.names.get(axis).cloned().unwrap_or_default()
                        }
                        _ => String::new(),
                    };
                    err(
                        if axis.is_empty() {
                            ids::NC_EVALUATION
                        } else {
                            ids::MEAS_NO_VALUE
                        },
                        if axis.is_empty() {
                            format!("{e}")
                        } else {
                            format!("G101: axis {axis} has no measured value")
                        },
                    )
                },
            )?;
            self.frames_changed(ch);
            return Ok(end);
        }
        if g102 {
            let list: Vec<usize> = axes.iter().map(|(i, _)| *i).collect();
            crate::core::measure::results::g102(&mut self.frames, &list)
                .map_err(|e| err(ids::NC_EVALUATION, format!("{e}")))?;
            self.frames_changed(ch);
            return Ok(end);
        }
        // Between #CONTROL AREA BEGIN and END a motion block defines geometry only.
        if self.defining(ch) {
            let has_motion = !axes.is_empty() || centre.iter().any(Option::is_some);
            if has_motion || !independent.is_empty() {
                let at = BlockRef {
                    number: block.number,
                    line: block.span.line,
                };
                self.area_definition_block(
                    at,
                    &axes,
                    &centre,
                    meas_g,
                    !independent.is_empty(),
                    ch,
                )?;
            }
            return Ok(end);
        }
        // 4. Motion.
        let mut measured = vec![false; self.prog.len()];
        let path_started = self.motion_block(&axes, &centre, meas_g, ch, &mut measured)?;
        for (name, motion, span) in independent {
            self.independent(&name, &motion, span, meas_g, ch, &mut measured)?;
        }
        if path_started || measured.iter().any(|m| *m) {
            self.resync = true;
        }
        Ok(end)
    }

    /// The frames changed (G92, G101/G102, zero offset, tool, #CS): the axes stay where they
    /// are, so their PCS positions change. Also tells the channel the PCS offset for the PCS
    /// limit display (P-CHAN-00489).
    fn frames_changed(&mut self, ch: &mut Channel) {
        // A target in the old PCS names no point of the new one.
        self.meas_target.iter_mut().for_each(|t| *t = None);
        ch.set_frames(&self.frames);
        self.resync_positions(ch);
    }

    fn select_zero_offset(&mut self, g: u32, ch: &mut Channel) -> Result<(), Fail> {
        let n = self.prog.len();
        let values = if g == 53 {
            vec![0.0; n]
        } else {
            self.zero_offsets
                .get(&g)
                .cloned()
                .unwrap_or_else(|| vec![0.0; n])
        };
        self.frames
            .set_zero_offset(&values)
            .map_err(|e| err(ids::NC_EVALUATION, format!("G{g}: {e}")))?;
        self.modal.zero_offset = (g != 53).then_some(g);
        self.frames_changed(ch);
        Ok(())
    }

    fn select_tool(&mut self, d: f64, ch: &mut Channel) -> Result<(), Fail> {
        if d.fract() != 0.0 || !(0.0..=32767.0).contains(&d) {
            return Err(err(
                ids::NC_EVALUATION,
                format!("D{d}: tool offset number must be 0 … 32767"),
            ));
        }
        let n = d as u32;
        self.tool = if n == 0 {
            None
        } else {
            Some(*self.tools.get(&n).ok_or_else(|| {
                err(
                    ids::NC_EVALUATION,
                    format!("D{n}: no tool data for D{n} in the machine file ([tool.{n}])"),
                )
            })?)
        };
        self.frames
            .set_tool_length(self.tool.map(|t| t.length).unwrap_or(0.0))
            .map_err(|e| err(ids::NC_EVALUATION, format!("D{n}: {e}")))?;
        self.frames_changed(ch);
        Ok(())
    }

    fn num(&self, e: &super::ast::Expr, span: Span, ch: &Channel) -> Result<f64, Fail> {
        let src = vars::Vars { exec: self, ch };
        eval_num_at(e, &src, span).map_err(|e| err(ids::NC_EVALUATION, e.to_string()))
    }

    fn value(&self, e: &super::ast::Expr, span: Span, ch: &Channel) -> Result<Value, Fail> {
        let src = vars::Vars { exec: self, ch };
        eval_at(e, &src, span).map_err(|e| err(ids::NC_EVALUATION, e.to_string()))
    }
}

/// G codes this build executes.
pub const SUPPORTED_G: &[u32] = &[
    0, 1, 2, 3, 17, 18, 19, 53, 54, 55, 56, 57, 58, 59, 90, 91, 92, 98, 99, 100, 101, 102, 161,
    162, 210, 310,
];

fn supported_g_text() -> String {
    SUPPORTED_G
        .iter()
        .map(|g| format!("G{g:02}"))
        .collect::<Vec<_>>()
        .join(" ")
}
