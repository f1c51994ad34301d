//! `#` commands other than `#MSG`: `#MEAS`, `#CS`, `#TRAFO`, `#DRIVE`, `#IDENT`, `#SET AX LINK`,
//! `#ENABLE AX LINK` (FCT-C4).

use super::{err, Decode, Executor, Fail, PendingRead};
use crate::channel::acyclic::AcyclicOp;
use crate::channel::coupling::AxisCoupling;
use crate::channel::{Channel, SignalOverride};
use crate::core::frames::CsTransform;
use crate::core::measure::{edge_from_text, MeasType, SignalSource};
use crate::messages::ids;
use crate::nc::ast::{Command, Expr, KeyArg, Span};
use crate::nc::expr::Value;

fn arg<'a>(args: &'a [KeyArg], key: &str) -> Option<&'a KeyArg> {
    args.iter().find(|a| a.key.eq_ignore_ascii_case(key))
}

fn word(e: &Expr) -> Option<String> {
    match e {
        Expr::Str(s) => Some(s.clone()),
        Expr::Var(v) => Some(v.name()),
        _ => None,
    }
}

impl Executor {
    pub(super) fn command(
        &mut self,
        command: &Command,
        span: Span,
        ch: &mut Channel,
    ) -> Result<(), Fail> {
        match command {
            Command::Msg { .. } => Ok(()),
            Command::MeasMode { mode } => {
                self.modal.meas_type = match mode {
                    None => ch.config().meas.default_type,
                    Some(e) => {
                        let v = self.num(e, span, ch)?;
                        MeasType::from_number(v as i64)
                            .filter(|_| v.fract() == 0.0)
                            .ok_or_else(|| err(ids::MEAS_CONFIG, format!("#MEAS MODE[{v}]: the measurement type must be 1 … 7 (P-CHAN-00057)")))?
                    }
                };
                Ok(())
            }
            Command::MeasConfig { args } => self.meas_config(args, span, ch),
            Command::ControlArea { command } => self.area_command(command, ch),
            Command::MeasPrepare { args } => {
                for a in args.iter().filter(|a| a.key.eq_ignore_ascii_case("AXNR")) {
                    let i = self.axnr(a, span, ch)?;
                    ch.prepare_probe(i).map_err(Fail::New)?;
                }
                Ok(())
            }
            Command::Cs { on } => {
                let cs = match on {
                    None => None,
                    Some(values) => {
                        let mut v = Vec::with_capacity(values.len());
                        for e in values {
                            v.push(self.num(e, span, ch)?);
                        }
                        Some(CsTransform::from_cs_on(&v).map_err(|e| err(ids::NC_EVALUATION, format!("#CS ON: {e}")))?)
                    }
                };
                self.frames.set_cs(cs).map_err(|e| err(ids::NC_EVALUATION, format!("#CS: {e}")))?;
                self.frames_changed(ch);
                Ok(())
            }
            Command::Trafo { .. } => Err(err(
                ids::NC_UNSUPPORTED,
                "#TRAFO (kinematic transformation) is not supported by fieldprobe; measure in 2.5D or with #CS",
            )),
            Command::Drive { write, sync, args } => self.drive(*write, *sync, args, span, ch),
            Command::Ident { write, sync, args } => self.ident(*write, *sync, args, span, ch),
            Command::SetAxLink { group, links } => {
                let g = self.num(group, span, ch)?;
                let mut out = Vec::new();
                for l in links {
                    if !l.kind.eq_ignore_ascii_case("G") {
                        return Err(err(
                            ids::NC_UNSUPPORTED,
                            format!("#SET AX LINK: coupling kind '{}' is not supported (G = gantry)", l.kind),
                        ));
                    }
                    let slave = self.axis(&l.slave).ok_or_else(|| err(ids::NC_EVALUATION, format!("#SET AX LINK: unknown axis '{}'", l.slave)))?;
                    let master = self.axis(&l.master).ok_or_else(|| err(ids::NC_EVALUATION, format!("#SET AX LINK: unknown axis '{}'", l.master)))?;
                    out.push(AxisCoupling { slave, master });
                }
                ch.define_coupling(g as i64, out).map_err(Fail::New)
            }
            Command::EnableAxLink { enable, group } => {
                let g = match group {
                    Some(e) => Some(self.num(e, span, ch)? as i64),
                    None => None,
                };
                ch.enable_coupling(g, *enable).map_err(Fail::New)
            }
        }
    }

    /// The channel axis of an `AXNR` argument (1-based logical axis number = machine file order).
    fn axnr(&self, a: &KeyArg, span: Span, ch: &Channel) -> Result<usize, Fail> {
        let e = a
            .value
            .as_ref()
            .ok_or_else(|| err(ids::NC_EVALUATION, "AXNR needs a number"))?;
        let n = self.num(e, span, ch)?;
        if n.fract() != 0.0 || n < 1.0 || n as usize > self.names.len() {
            return Err(err(
                ids::NC_EVALUATION,
                format!(
                    "AXNR={n}: axis numbers are 1 … {} ({})",
                    self.names.len(),
                    self.names.join(", ")
                ),
            ));
        }
        Ok(n as usize - 1)
    }

    /// `#MEAS [AXNR=.. SIGNAL=.. INPUT=.. EDGE=..]`.
    fn meas_config(&mut self, args: &[KeyArg], span: Span, ch: &mut Channel) -> Result<(), Fail> {
        // `TYPE=n` beside the axis's signal settings: the channel's measurement type, as
        // `#MEAS MODE [n]` (P-CHAN-00057).
        if let Some(e) = arg(args, "TYPE").and_then(|a| a.value.as_ref()) {
            let v = self.num(e, span, ch)?;
            self.modal.meas_type = MeasType::from_number(v as i64)
                .filter(|_| v.fract() == 0.0)
                .ok_or_else(|| {
                    err(
                        ids::MEAS_CONFIG,
                        format!(
                            "#MEAS [TYPE={v}]: the measurement type must be 1 … 7 (P-CHAN-00057)"
                        ),
                    )
                })?;
        }
        let a = arg(args, "AXNR").ok_or_else(|| {
            err(
                ids::MEAS_CONFIG,
                "#MEAS [..]: AXNR=<axis number> is required",
            )
        })?;
        let axis = self.axnr(a, span, ch)?;
        let signal = match arg(args, "SIGNAL").and_then(|a| a.value.as_ref()).and_then(word) {
            Some(w) => Some(SignalSource::from_text(&w).ok_or_else(|| {
                err(ids::MEAS_CONFIG, format!("#MEAS SIGNAL={w}: allowed are DRIVE_TYPE_DEFAULT PLC FIXED_STOP DRIVE PLC_EXT_LATCH_CONTROL PLC_FIRST_EVENT PLC_TIMESTAMP EXT_PROBE_WITH_DRIVE (P-AXIS-00516)"))
            })?),
            None => None,
        };
        let input = match arg(args, "INPUT").and_then(|a| a.value.as_ref()) {
            Some(e) => {
                let v = self.num(e, span, ch)?;
                let max = match signal.unwrap_or(ch.config().axes[axis].meas.signal) {
                    SignalSource::PlcExtLatchControl => 255.0,
                    _ => 2.0,
                };
                if v.fract() != 0.0 || v < 1.0 || v > max {
                    return Err(err(ids::MEAS_CONFIG, format!("#MEAS INPUT={v}: allowed 1 … {max} for this signal source (P-AXIS-00517)")));
                }
                Some(v as u8)
            }
            None => None,
        };
        let edge = match arg(args, "EDGE")
            .and_then(|a| a.value.as_ref())
            .and_then(word)
        {
            Some(w) => Some(edge_from_text(&w).ok_or_else(|| {
                err(
                    ids::MEAS_CONFIG,
                    format!("#MEAS EDGE={w}: allowed POS / NEG (P-AXIS-00518)"),
                )
            })?),
            None => None,
        };
        self.overrides.push(SignalOverride {
            axis,
            signal,
            input,
            edge,
        });
        Ok(())
    }

    /// `#DRIVE WR|RD [SYN] [AX=.. KEY=.. VAL=.. | P=Pn WAIT]` through the drive function table.
    fn drive(
        &mut self,
        write: bool,
        sync: bool,
        args: &[KeyArg],
        span: Span,
        ch: &mut Channel,
    ) -> Result<(), Fail> {
        let ax = arg(args, "AX")
            .and_then(|a| a.value.as_ref())
            .and_then(word)
            .ok_or_else(|| err(ids::NC_EVALUATION, "#DRIVE: AX=<axis name> is required"))?;
        let axis = self
            .axis(&ax)
            .ok_or_else(|| err(ids::NC_EVALUATION, format!("#DRIVE: unknown axis '{ax}'")))?;
        let key = arg(args, "KEY")
            .and_then(|a| a.value.as_ref())
            .and_then(word)
            .ok_or_else(|| err(ids::NC_EVALUATION, "#DRIVE: KEY=<function> is required"))?;
        let key = key.to_ascii_uppercase().replace(' ', "_");
        let def = ch.axes()[axis].definition().ok_or_else(|| {
            err(
                ids::ACYCLIC_FAILED,
                format!("#DRIVE: axis {ax} has no drive definition"),
            )
        })?;
        let f = def
            .function(&key)
            .ok_or_else(|| {
                let keys: Vec<&str> = def.functions.iter().map(|f| f.key.as_str()).collect();
                // A definition without a function table (an encoder terminal) has none at all:
                // say so rather than list nothing (issue 28 item 10).
                let has = if keys.is_empty() {
                    "its definition has no drive functions".to_owned()
                } else {
                    format!("it has {}", keys.join(", "))
                };
                err(
                    ids::ACYCLIC_FAILED,
                    format!(
                        "#DRIVE: drive '{}' of axis {ax} has no function {key}; {has}",
                        def.name
                    ),
                )
            })?
            .clone();
        let wait = sync || arg(args, "WAIT").is_some();
        let what = format!(
            "#DRIVE {} KEY={key} (axis {ax}, object {:#06x}:{:02x})",
            if write { "WR" } else { "RD" },
            f.index,
            f.sub
        );
        if write {
            let e = arg(args, "VAL")
                .and_then(|a| a.value.as_ref())
                .ok_or_else(|| err(ids::NC_EVALUATION, "#DRIVE WR: VAL=<value> is required"))?;
            let v = self.num(e, span, ch)?;
            let raw = f.encode(v).ok_or_else(|| {
                err(ids::ACYCLIC_FAILED, format!("#DRIVE WR KEY={key} VAL={v}: outside the function's range {} … {} (wire value = VAL × {})", f.min, f.max, f.scale))
            })?;
            if f.cyclic {
                ch.cyclic_function(axis, f.index, f.sub, AcyclicOp::Write(raw), &what);
            } else {
                ch.queue_acyclic(axis, f.index, f.sub, AcyclicOp::Write(raw), wait, &what);
            }
        } else {
            let param = self.target_param(args)?;
            let id = if f.cyclic {
                ch.cyclic_function(axis, f.index, f.sub, AcyclicOp::Read, &what)
            } else {
                ch.queue_acyclic(axis, f.index, f.sub, AcyclicOp::Read, true, &what)
            };
            if let Some(p) = param {
                self.pending_reads.push(PendingRead {
                    id,
                    param: p,
                    decode: Decode::Scale(if f.scale != 0.0 { f.scale } else { 1.0 }),
                });
            }
        }
        Ok(())
    }

    /// `#IDENT WR|RD [SYN] [AXNR n ID S-0-0092 VAL=.. | P=Pn TYP t DEC d SERC]`: a SERCOS IDN,
    /// carried to a CoE drive through the drive file's `[idn]` map.
    fn ident(
        &mut self,
        write: bool,
        sync: bool,
        args: &[KeyArg],
        span: Span,
        ch: &mut Channel,
    ) -> Result<(), Fail> {
        let a = arg(args, "AXNR")
            .ok_or_else(|| err(ids::NC_EVALUATION, "#IDENT: AXNR <axis number> is required"))?;
        let axis = self.axnr(a, span, ch)?;
        let id = arg(args, "ID")
            .and_then(|a| a.value.as_ref())
            .and_then(word)
            .ok_or_else(|| err(ids::NC_EVALUATION, "#IDENT: ID <IDN> is required"))?;
        let dec = match arg(args, "DEC").and_then(|a| a.value.as_ref()) {
            Some(e) => self.num(e, span, ch)?,
            None => 0.0,
        };
        if dec.fract() != 0.0 || !(0.0..=9.0).contains(&dec) {
            return Err(err(
                ids::NC_EVALUATION,
                format!("#IDENT DEC {dec}: decimal places 0 … 9"),
            ));
        }
        let scale = 10f64.powi(dec as i32);
        let name = ch.axes()[axis].name().to_string();
        let def = ch.axes()[axis].definition().ok_or_else(|| {
            err(
                ids::ACYCLIC_FAILED,
                format!("#IDENT: axis {name} has no drive definition"),
            )
        })?;
        let m = def.idn(&id).ok_or_else(|| {
            err(ids::ACYCLIC_FAILED, format!("#IDENT ID {id}: drive '{}' of axis {name} has no mapping for this IDN ([idn] in its drive file)", def.name))
        })?.clone();
        let wait = sync;
        let what = format!(
            "#IDENT {} ID {id} (axis {name}, object {:#06x}:{:02x})",
            if write { "WR" } else { "RD" },
            m.index,
            m.sub
        );
        if write {
            let e = arg(args, "VAL")
                .and_then(|a| a.value.as_ref())
                .ok_or_else(|| err(ids::NC_EVALUATION, "#IDENT WR: VAL=<value> is required"))?;
            let v = self.num(e, span, ch)?;
            let scaled = (v * scale).round();
            let raw = (scaled.is_finite() && scaled.abs() < 9.0e15)
                .then_some(scaled as i64)
                .and_then(|x| m.encode(x))
                .ok_or_else(|| {
                    err(
                        ids::ACYCLIC_FAILED,
                        format!(
                            "#IDENT WR ID {id} VAL={v}: does not fit the drive object ({})",
                            m.ty.name()
                        ),
                    )
                })?;
            ch.queue_acyclic(axis, m.index, m.sub, AcyclicOp::Write(raw), wait, &what);
        } else {
            let param = self.target_param(args)?;
            let rid = ch.queue_acyclic(axis, m.index, m.sub, AcyclicOp::Read, true, &what);
            if let Some(p) = param {
                self.pending_reads.push(PendingRead {
                    id: rid,
                    param: p,
                    decode: Decode::Idn {
                        zero: m.zero,
                        scale,
                    },
                });
            }
        }
        Ok(())
    }

    /// `P=P1092` of a read command.
    fn target_param(&self, args: &[KeyArg]) -> Result<Option<u32>, Fail> {
        match arg(args, "P").and_then(|a| a.value.as_ref()) {
            Some(Expr::Param(n, _)) => Ok(Some(*n)),
            Some(other) => Err(err(
                ids::NC_EVALUATION,
                format!("P= must name a parameter such as P1092, got {other:?}"),
            )),
            None => Ok(None),
        }
    }

    #[allow(dead_code)]
    fn text_value(&self, e: &Expr, span: Span, ch: &Channel) -> Result<String, Fail> {
        Ok(match self.value(e, span, ch)? {
            Value::Str(s) => s,
            Value::Num(n) => n.to_string(),
        })
    }
}
