//! One cycle of a measuring block (arming progress, latch collection, fixed-stop detection) and
//! its end (errors per type, outcome published).

use super::*;

impl Channel {
    /// Per cycle, before interpolation: arming progress and latch collection. `s` is the path
    /// position last commanded. Returns what the interpolator must do.
    pub(in crate::channel) fn measurement_step(
        &mut self,
        run: &mut MeasRun,
        now: Nanos,
        s: f64,
    ) -> MeasStep {
        match run.phase {
            Phase::Arming { cycles } => {
                let mut all = true;
                if !run.armed_once {
                    run.armed_once = true;
                    for m in &mut run.axes {
                        if let Some(e) = m.eval.as_mut() {
                            let (t, plc) = self.plc_view(m.axis);
                            e.arm(t, plc);
                            self.plc[m.axis].measuring_r = true;
                        }
                    }
                }
                for m in &mut run.axes {
                    // Once the PLC has acknowledged the block's ENABLE the gate stays open (the
                    // drive latch may still be confirming its arming).
                    if m.handshake && !m.gate_open {
                        if let Some(c) = self.ext_latch[m.axis].as_mut() {
                            match c.start_measuring_block(&mut self.plc[m.axis].ext_latch, now) {
                                BlockGate::Go => m.gate_open = true,
                                BlockGate::Wait => all = false,
                                BlockGate::Failed(task) => {
                                    return MeasStep::Fail(CncMessage::error(
                                        ids::MEAS_LATCH,
                                        format!(
                                            "axis {}: the PLC did not acknowledge {task:?}",
                                            self.axes[m.axis].name()
                                        ),
                                    ));
                                }
                            }
                        }
                    }
                }
                for m in &mut run.axes {
                    if let Some((id, req)) = m.source_sdo {
                        match self.take_acyclic_result(id) {
                            None => {
                                all = false;
                                continue;
                            }
                            Some(Ok(_)) => {
                                m.source_sdo = None;
                                let name = self.axes[m.axis].name().to_string();
                                if let Err(e) = self.axes[m.axis].arm_probe(&req) {
                                    return MeasStep::Fail(
                                        CncMessage::error(
                                            ids::MEAS_LATCH,
                                            format!("axis {name}: cannot arm the drive latch: {e}"),
                                        )
                                        .on_axis(&name),
                                    );
                                }
                                all = false;
                                continue;
                            }
                            // The channel reported the failed write already and is stopping.
                            Some(Err(e)) => {
                                return MeasStep::Fail(CncMessage::error(
                                    ids::MEAS_LATCH,
                                    format!("0x60D0 write failed: {e}"),
                                ));
                            }
                        }
                    }
                }
                for m in &run.axes {
                    if !m.signal.uses_drive_latch() {
                        continue;
                    }
                    match self.axes[m.axis].probe_state() {
                        ProbeState::Armed => {}
                        ProbeState::Failed(why) => {
                            let name = self.axes[m.axis].name().to_string();
                            return MeasStep::Fail(
                                CncMessage::error(
                                    ids::MEAS_LATCH,
                                    format!("axis {name}: drive latch failed while arming: {why}"),
                                )
                                .on_axis(&name),
                            );
                        }
                        _ => all = false,
                    }
                }
                if all {
                    run.phase = Phase::Measuring;
                    MeasStep::Go
                } else if cycles >= ARMING_TIMEOUT_CYCLES {
                    MeasStep::Fail(CncMessage::error(
                        ids::MEAS_LATCH,
                        format!("the probing-signal sources did not confirm arming within {ARMING_TIMEOUT_CYCLES} cycles"),
                    ))
                } else {
                    run.phase = Phase::Arming { cycles: cycles + 1 };
                    MeasStep::Hold
                }
            }
            Phase::Measuring => {
                let was_signalled = run.signalled();
                for k in 0..run.axes.len() {
                    let (axis, signal) = (run.axes[k].axis, run.axes[k].signal);
                    let event = if signal.uses_drive_latch() {
                        if let ProbeState::Failed(why) = self.axes[axis].probe_state() {
                            let name = self.axes[axis].name().to_string();
                            return MeasStep::Fail(
                                CncMessage::error(
                                    ids::MEAS_LATCH,
                                    format!("axis {name}: drive latch failed: {why}"),
                                )
                                .on_axis(&name),
                            );
                        }
                        // The drive may report the event before its value (PROFIdrive: "value
                        // available", read over G1_XIST2 in the following cycles): braking
                        // starts with the report.
                        if self.axes[axis].probe_triggered() {
                            run.axes[k].triggered = true;
                        }
                        self.axes[axis].take_latch()
                    } else if let Some(e) = run.axes[k].eval.as_mut() {
                        let actual = self.axes[axis].actual();
                        let (t, plc) = self.plc_view(axis);
                        if let Some(clock) = self.sample_dc_clock(axis, t) {
                            e.set_dc_clock(clock);
                        }
                        match e.update(t, actual, plc) {
                            Ok(ev) => ev.map(|ev| ev.position),
                            Err(err) => {
                                let name = self.axes[axis].name().to_string();
                                return MeasStep::Fail(
                                    CncMessage::error(
                                        ids::MEAS_LATCH,
                                        format!("axis {name}: {} signal: {err}", signal.name()),
                                    )
                                    .on_axis(&name),
                                );
                            }
                        }
                    } else if signal == SignalSource::FixedStop {
                        let a = &self.axes[axis];
                        let travelled = (a.command() - run.axes[k].start).abs();
                        let detected = run
                            .fixed
                            .as_mut()
                            .and_then(|d| d.update(now, k, travelled, a.lag(), a.actual()));
                        if detected.is_some() {
                            // The measuring point is latched for each axis involved (FCT-C4
                            // §7.3): every axis of the run takes its actual position; the motion
                            // brakes, and at its end all axes move there ("reduce interpolation
                            // to measured value", `finish_measurement`).
                            for m in &mut run.axes {
                                let p = self.axes[m.axis].actual();
                                m.latched = Some((p, now));
                            }
                            run.event_s = Some(s);
                            return MeasStep::Brake;
                        }
                        None
                    } else {
                        None
                    };
                    if let Some(pos) = event {
                        let m = &mut run.axes[k];
                        if m.latched.is_none() {
                            m.latched = Some((pos, now));
                        }
                    }
                }
                if !was_signalled && run.signalled() {
                    run.event_s = Some(s);
                    if run.mtype == MeasType::Type3 {
                        MeasStep::Go
                    } else {
                        MeasStep::Brake
                    }
                } else {
                    MeasStep::Go
                }
            }
            Phase::Done => MeasStep::Go,
        }
    }

    /// The block is over (standstill): disarm, decide about errors, publish the outcome. An
    /// error (missing signal per type) is returned; nothing is published then. Returns the
    /// positions some axes must move to at once: a type-7 run without detected stop and
    /// P-CHAN-00266 = 1 "goes to the position of the current axis actual value … to eliminate a
    /// possible position lag" (§8.2.1).
    pub(in crate::channel) fn finish_measurement(
        &mut self,
        mut run: MeasRun,
        target_reached: bool,
    ) -> Result<Vec<(usize, f64)>, CncMessage> {
        run.phase = Phase::Done;
        self.disarm_sources(&run);
        let n = self.axes.len();
        let complete = run.complete();
        if !complete {
            let missing: Vec<&str> = run
                .axes
                .iter()
                .filter(|a| a.required && a.latched.is_none())
                .map(|a| self.axes[a.axis].name())
                .collect();
            let list = missing.join(", ");
            let error = missing_signal_error(run.mtype, &self.cfg.meas, run.limited_at_sls, &list);
            if let Some(e) = error {
                return Err(e);
            }
        }
        run.decide_merf();
        let settle: Vec<(usize, f64)> = match run.mtype {
            // Detected: every axis of the run goes to its latched position (FCT-C4 §7.3).
            MeasType::Type7 if complete => run
                .axes
                .iter()
                .filter_map(|a| a.latched.map(|(p, _)| (a.axis, p)))
                .collect(),
            MeasType::Type7 if self.cfg.meas.fixed_stop_no_error => run.lagging_axes(&self.axes),
            _ => Vec::new(),
        };
        let mut latched = vec![None; n];
        let mut merf = vec![false; n];
        let mut involved = vec![false; n];
        if complete {
            for a in &run.axes {
                involved[a.axis] = true;
                if let Some((p, t)) = a.latched {
                    latched[a.axis] = Some(p);
                    merf[a.axis] = a.before_target;
                    // The trace marks the latches that became results: an axis whose latch
                    // belongs to an incomplete signal did not measure.
                    if let Some(log) = self.latch_log.as_mut() {
                        log.push((t, a.axis, p));
                    }
                }
            }
        } else {
            for a in &run.axes {
                involved[a.axis] = a.required;
            }
        }
        let new = MeasurementOutcome {
            mtype: run.mtype,
            latched,
            merf,
            involved,
            target_reached,
        };
        // Independent axes of one block finish one by one: merge their outcomes until taken.
        self.measurement = Some(match self.measurement.take() {
            Some(old) => merge_outcomes(old, new),
            None => new,
        });
        Ok(settle)
    }
}

/// Combine two outcomes of the same block (independent axes): per axis the one that involved it.
fn merge_outcomes(old: MeasurementOutcome, new: MeasurementOutcome) -> MeasurementOutcome {
    let n = old.latched.len().max(new.latched.len());
    let pick = |i: usize| new.involved.get(i).copied().unwrap_or(false);
    MeasurementOutcome {
        mtype: new.mtype,
        latched: (0..n)
            .map(|i| {
                if pick(i) {
                    new.latched.get(i).copied().flatten()
                } else {
                    old.latched.get(i).copied().flatten()
                }
            })
            .collect(),
        merf: (0..n)
            .map(|i| {
                if pick(i) {
                    new.merf.get(i).copied().unwrap_or(false)
                } else {
                    old.merf.get(i).copied().unwrap_or(false)
                }
            })
            .collect(),
        involved: (0..n)
            .map(|i| pick(i) || old.involved.get(i).copied().unwrap_or(false))
            .collect(),
        target_reached: old.target_reached && new.target_reached,
    }
}
