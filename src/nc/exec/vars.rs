//! `V.*` variables and P-parameters for expressions.
//!
//! | variable | value |
//! |---|---|
//! | `V.A.ABS.<ax>` | command position in the CS frame `w` (= ACS without `#CS`), FCT-C4 §5 |
//! | `V.A.PROG.<ax>` | programmed (PCS) position |
//! | `V.A.-SWE.<ax>` / `V.A.+SWE.<ax>` | active programmed software limit switches, FCT-A2 §3 |
//! | `V.A.MESS.<ax>` | measured value in the measuring frame, all offsets included |
//! | `V.A.MEAS.ACS.VALUE.<ax>` / `V.A.MEAS.PCS.VALUE.<ax>` | ACS / PCS measured value |
//! | `V.A.MOFFS.<ax>` | measured value − programmed target − offsets |
//! | `V.A.MERF.<ax>` | 1 when the probing signal came before the target was reached |
//! | `V.A.MEIN.<ax>` | measurement offset (G101) |
//! | `V.G.MEAS_TYPE` | active measurement type |
//!
//! An axis without a measured value reads 0 in `V.A.MESS` & co. (and `V.A.MERF` = 0).

use super::Executor;
use crate::channel::Channel;
use crate::nc::ast::VarRef;
use crate::nc::expr::{Value, VarSource};

pub(super) struct Vars<'a> {
    pub(super) exec: &'a Executor,
    pub(super) ch: &'a Channel,
}

impl VarSource for Vars<'_> {
    fn var(&self, var: &VarRef) -> Result<Value, String> {
        let s: Vec<&str> = var.segments.iter().map(String::as_str).collect();
        let axis = |n: &str| {
            self.exec
                .axis(n)
                .ok_or_else(|| format!("{}: unknown axis '{n}'", var.name()))
        };
        let result = |i: usize| self.exec.results.get(i).copied().flatten();
        let num = |v: f64| Ok(Value::Num(v));
        match s.as_slice() {
            ["V", "A", "ABS", ax] => {
                let i = axis(ax)?;
                let cmd = self.ch.command_positions();
                let mut w = vec![0.0; cmd.len()];
                self.exec.frames.acs_to_w(&cmd, &mut w);
                num(w.get(i).copied().unwrap_or(0.0))
            }
            ["V", "A", "PROG", ax] => num(self.exec.programmed(axis(ax)?).unwrap_or(0.0)),
            ["V", "A", "-SWE", ax] | ["V", "A", "+SWE", ax] => {
                let i = axis(ax)?;
                let (neg, pos) = self.ch.soft_limits().active_limits(i).unwrap_or((0.0, 0.0));
                num(if s[2] == "-SWE" { neg } else { pos })
            }
            ["V", "A", "MESS", ax] => num(result(axis(ax)?).map_or(0.0, |r| r.mess)),
            ["V", "A", "MOFFS", ax] => num(result(axis(ax)?).map_or(0.0, |r| r.moffs)),
            ["V", "A", "MERF", ax] => {
                let i = axis(ax)?;
                num(if self.exec.merf.get(i).copied().unwrap_or(false) { 1.0 } else { 0.0 })
            }
            ["V", "A", "MEIN", ax] => num(self.exec.frames.mein(axis(ax)?)),
            ["V", "A", "MEAS", "ACS", "VALUE", ax] => num(result(axis(ax)?).map_or(0.0, |r| r.acs)),
            ["V", "A", "MEAS", "PCS", "VALUE", ax] => num(result(axis(ax)?).map_or(0.0, |r| r.pcs)),
            ["V", "G", "MEAS_TYPE"] => num(f64::from(self.exec.modal.meas_type.number())),
            _ => Err(format!(
                "unknown variable {}; known: V.A.ABS / PROG / -SWE / +SWE / MESS / MERF / MOFFS / MEIN / MEAS.ACS.VALUE / MEAS.PCS.VALUE .<axis>, V.G.MEAS_TYPE",
                var.name()
            )),
        }
    }

    fn param(&self, n: u32) -> Result<f64, String> {
        self.exec
            .params
            .get(&n)
            .copied()
            .ok_or_else(|| format!("P{n} has no value"))
    }
}
