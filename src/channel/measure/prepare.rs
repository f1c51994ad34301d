//! Preparing a measuring block: which axes take part and must latch, the braking deceleration
//! of the FCT-C4 §2.1 table, arming the sources (drive latch, CNC_DEFINED 0x60D0, PLC).

use super::*;

impl Channel {
    /// Set up the measurement of a motion block (called from block preparation once the path
    /// is known). Returns an error message when the block may not run as a measurement.
    pub(in crate::channel) fn prepare_measurement(
        &mut self,
        req: &MeasureRequest,
        segment: &Segment,
        target_len: f64,
        only_moved: bool,
    ) -> Result<MeasRun, CncMessage> {
        let n = self.axes.len();
        let start = segment.start();
        let end = segment.end();
        let moved: Vec<bool> = (0..n).map(|i| (end[i] - start[i]).abs() > 1e-9).collect();
        let mtype = req.mtype;
        // G code and type must belong together (FCT-C4 §3 table).
        let ok_gcode = match mtype {
            MeasType::Type5 => req.gcode == 210,
            MeasType::Type6 => req.gcode == 310,
            _ => req.gcode == 100,
        };
        if !ok_gcode {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                format!(
                    "G{} does not belong to measurement type {} (types 1–4 and 7 measure with G100, 5 with G210, 6 with G310)",
                    req.gcode,
                    mtype.number()
                ),
            ));
        }
        let main = self.main_axes();
        let moved_count = moved.iter().filter(|m| **m).count();
        match mtype {
            MeasType::Type2 if moved_count != 1 => {
                return Err(CncMessage::error(
                    ids::MEAS_CONFIG,
                    format!("measurement type 2 moves exactly one axis; this block moves {moved_count}"),
                ))
            }
            MeasType::Type4 => {
                if let Some(i) = (0..n).find(|i| moved[*i] && !main.contains(&Some(*i))) {
                    return Err(CncMessage::error(
                        ids::MEAS_CONFIG,
                        format!(
                            "measurement type 4 measures with at most the 3 main axes; axis {} is not one",
                            self.axes[i].name()
                        ),
                    ));
                }
            }
            MeasType::Type6 if !self.cfg.axes.iter().any(|a| a.meas.sercos) => {
                return Err(CncMessage::error(
                    ids::MEAS_CONFIG,
                    "measurement type 6 (G310) needs at least one SERCOS axis; this channel has none",
                ))
            }
            _ => {}
        }
        // Which axes take part (FCT-C4 §1: "initialised and activated for the axes programmed
        // in the measurement block") and which must latch (§4).
        let mut axes = Vec::new();
        for i in 0..n {
            let c = &self.cfg.axes[i].meas;
            let in_cs = req.cs_active && main.contains(&Some(i));
            let programmed = req.programmed.get(i).copied().unwrap_or(false);
            // Gantry slaves move along but the master measures (FCT-C4 §7.3).
            let slave = self.is_coupled_slave(i);
            let required = (moved[i] || in_cs) && !slave;
            if required && !c.enabled {
                return Err(CncMessage::error(
                    ids::MEAS_CONFIG,
                    format!(
                        "axis {} is not enabled as a measurement axis (P-AXIS-00118 kenngr.messachse = 0){}",
                        self.axes[i].name(),
                        if in_cs { "; with #CS all three main axes must be" } else { "" }
                    ),
                )
                .on_axis(self.axes[i].name()));
            }
            // Only programmed axes (and the #CS main axes) are armed: an axis the block does not
            // name keeps its probe for other uses and its previous results. An independent axis
            // measures alone: the other axes' latches belong to their own runs.
            if !c.enabled || !(required || programmed) || (only_moved && !required) {
                continue;
            }
            let ov = req.overrides.iter().rev().find(|o| o.axis == i);
            let mut signal = ov.and_then(|o| o.signal).unwrap_or(c.signal);
            if mtype == MeasType::Type7 {
                // FCT-C4 §7.3 "The following entries must be assigned in the axis parameter
                // lists: P-AXIS-00516 … FIXED_STOP" (P-AXIS-00330: "All other measurement signal
                // sources … must be deselected"): an axis watched for the stop that is set up
                // for another source is refused before anything moves. The other axes of the
                // run only take their actual position when the stop is detected.
                if required && signal != SignalSource::FixedStop {
                    let name = self.axes[i].name();
                    return Err(CncMessage::error(
                        ids::MEAS_CONFIG,
                        format!(
                            "measurement type 7 (moving to a fixed stop) needs P-AXIS-00516 \
                             kenngr.measure.signal = FIXED_STOP on axis {name}, which measures \
                             with {}{}; set FIXED_STOP in its axis parameters or select it with \
                             #MEAS [AXNR={} SIGNAL=FIXED_STOP] (seed 004 §7.3)",
                            signal.name(),
                            if ov.and_then(|o| o.signal).is_some() {
                                " (#MEAS SIGNAL)"
                            } else {
                                ""
                            },
                            i + 1
                        ),
                    )
                    .on_axis(name));
                }
                signal = SignalSource::FixedStop;
            }
            // Seed 004 §7: "if the drive hardware used provides no latch function, the
            // measured value can be detected in the CNC" — a drive-latch source on a drive
            // without one is refused before anything moves, naming what remains.
            if signal.uses_drive_latch() {
                if let Some(def) = self.axes[i].definition().filter(|d| !d.has_drive_latch()) {
                    let name = self.axes[i].name();
                    return Err(CncMessage::error(
                        ids::MEAS_NO_DRIVE_LATCH,
                        format!(
                            "axis {name}: drive '{}' has no touch probe (0x60B8 / 0x60B9 are not \
                             in its PDO mapping), so measurement signal {}{} cannot latch; \
                             select a source the CNC evaluates with kenngr.measure.signal or \
                             #MEAS [AXNR={} SIGNAL=…]: {}",
                            def.name,
                            signal.name(),
                            if ov.and_then(|o| o.signal).is_some() {
                                " (#MEAS SIGNAL)"
                            } else {
                                ""
                            },
                            i + 1,
                            crate::core::measure::SOURCES_WITHOUT_DRIVE_LATCH
                        ),
                    )
                    .on_axis(name));
                }
            }
            let edge = ov.and_then(|o| o.edge).unwrap_or(c.edge);
            let input = ov.and_then(|o| o.input).unwrap_or(c.input);
            let eval = SourceEvaluator::for_source(
                signal,
                &EvaluatorConfig {
                    edge,
                    latency: self.cfg.cycle,
                    hardware_bound: 0.0001,
                    timestamp: TimestampConfig {
                        edge,
                        cycle: self.cfg.cycle,
                        capacity: 64,
                        dead: DeadTimes::default(),
                        clock: DcClock::default(),
                        signal_window: Some(crate::units::Nanos(
                            self.cfg
                                .meas
                                .plc_cycle
                                .map_or(0, |p| p.0.saturating_sub(self.cfg.cycle.0)),
                        )),
                    },
                },
            );
            let handshake = matches!(
                signal,
                SignalSource::PlcExtLatchControl | SignalSource::ExtProbeWithDrive
            );
            if handshake {
                let cfg = ExtLatchConfig::new(signal, input, edge, None).map_err(|e| {
                    CncMessage::error(
                        ids::MEAS_CONFIG,
                        format!("axis {}: {e}", self.axes[i].name()),
                    )
                })?;
                let same = self.ext_latch[i]
                    .as_ref()
                    .is_some_and(|c| *c.config() == cfg);
                if !same {
                    self.ext_latch[i] = Some(ExtLatchClient::new(cfg));
                }
            }
            axes.push(MeasAxis {
                axis: i,
                signal,
                required,
                edge,
                input,
                latched: None,
                before_target: false,
                triggered: false,
                eval,
                handshake,
                gate_open: false,
                start: start[i],
                source_sdo: None,
            });
        }
        if !axes.iter().any(|a| a.required) {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                "measuring block without a moved measurement axis",
            ));
        }
        let brake = (0..n).map(|i| self.measurement_brake_decel(i)).collect();
        let fixed = if mtype == MeasType::Type7 {
            let mut fa = Vec::with_capacity(axes.len());
            for a in &axes {
                let c = &self.cfg.axes[a.axis].meas;
                let name = self.axes[a.axis].name();
                // Only the moved axes (masters of a gantry) are watched for the stop.
                let monitored = a.required;
                let params = match (c.fixed_stop, monitored) {
                    (Some(p), _) => p,
                    (None, false) => crate::core::measure::fixed_stop::FixedStopParams::inactive(),
                    // `from_params` refuses only a cycle time of 0.
                    (None, true) => {
                        return Err(FixedStopError::ZeroCycle
                            .cnc_message(ids::MEAS_CONFIG, &[name])
                            .on_axis(name))
                    }
                };
                if monitored {
                    params.check_measuring_start(name)?;
                }
                fa.push(FixedStopAxis { params, monitored });
            }
            Some(FixedStopDetector::new(&fa, target_len).map_err(|e| {
                let names: Vec<&str> = axes.iter().map(|a| self.axes[a.axis].name()).collect();
                e.cnc_message(ids::MEAS_CONFIG, &names)
            })?)
        } else {
            None
        };
        let mut run = MeasRun {
            mtype,
            phase: Phase::Arming { cycles: 0 },
            axes,
            target_len,
            limited_at_sls: false,
            brake,
            event_s: None,
            origin: start.to_vec(),
            dir: {
                let len = segment.length();
                (0..n)
                    .map(|i| {
                        if len > 0.0 {
                            (end[i] - start[i]) / len
                        } else {
                            0.0
                        }
                    })
                    .collect()
            },
            fixed,
            armed_once: false,
            settle_prev: None,
            settle_cycles: 0,
            settle_still: 0,
        };
        self.arm_sources(&mut run)?;
        Ok(run)
    }

    /// Braking deceleration of axis `i` after the probing signal, FCT-C4 §2.1 table
    /// ("non-linear slope", column "measurement signal active").
    fn measurement_brake_decel(&self, i: usize) -> f64 {
        let m = &self.cfg.meas;
        let a = &self.cfg.axes[i];
        if m.std_dynamics {
            a.meas.a_feedhold
        } else if m.rapid_decel_on_signal {
            a.a_rapid
        } else if m.feedhold_param_decel {
            a.meas.a_feedhold
        } else {
            a.a_rapid
        }
    }

    /// [`measurement_brake_decel`](Self::measurement_brake_decel) for block preparation.
    pub(in crate::channel) fn measurement_brake_decel_pub(&self, i: usize) -> f64 {
        self.measurement_brake_decel(i)
    }

    /// Arm every source of the run (drive latch units now; confirmation is polled per cycle).
    /// With `CNC_DEFINED` (P-AXIS-00702) the CNC first writes the probing input into 0x60D0 by
    /// SDO and arms the latch (source 10b) once the drive has confirmed the write.
    fn arm_sources(&mut self, run: &mut MeasRun) -> Result<(), CncMessage> {
        for m in &mut run.axes {
            if !m.signal.uses_drive_latch() {
                continue;
            }
            let c = &self.cfg.axes[m.axis].meas;
            let mode = c.trigger_mode;
            let probe = if mode == TriggerSourceMode::Default {
                m.input.clamp(1, 2)
            } else {
                1
            };
            let trigger = match mode {
                TriggerSourceMode::Default => ProbeTrigger::Input,
                _ => ProbeTrigger::SourceObject,
            };
            let req = ProbeRequest {
                probe,
                edge: m.edge,
                trigger,
                continuous: false,
                source_mode: mode,
                input: m.input,
            };
            let name = self.axes[m.axis].name().to_string();
            if mode == TriggerSourceMode::CncDefined {
                let what = format!(
                    "0x60D0:{probe:02} = {} (P-AXIS-00702 CNC_DEFINED, axis {name})",
                    m.input
                );
                let id = self.queue_acyclic(
                    m.axis,
                    0x60D0,
                    probe,
                    crate::channel::acyclic::AcyclicOp::Write(i64::from(m.input)),
                    false,
                    &what,
                );
                m.source_sdo = Some((id, req));
                continue;
            }
            self.axes[m.axis].arm_probe(&req).map_err(|e| {
                CncMessage::error(
                    ids::MEAS_LATCH,
                    format!("axis {name}: cannot arm the drive latch: {e}"),
                )
                .on_axis(&name)
            })?;
        }
        Ok(())
    }

    /// Disarm every source of the run; the PLC gets its DISABLE task.
    pub(in crate::channel) fn disarm_sources(&mut self, run: &MeasRun) {
        let now = self.now;
        for m in &run.axes {
            if m.signal.uses_drive_latch() {
                self.axes[m.axis].disarm_probe();
            }
            self.plc[m.axis].measuring_r = false;
            if m.handshake {
                if let Some(c) = self.ext_latch[m.axis].as_mut() {
                    // A refused DISABLE (another task still waiting) is owed and written at the
                    // next block start by the client itself.
                    let _ = c.end_measuring_block(&mut self.plc[m.axis].ext_latch, now);
                }
            }
        }
    }

    /// Path deceleration for braking along `segment` after the signal.
    pub(in crate::channel) fn path_brake_decel(&self, run: &MeasRun, segment: &Segment) -> f64 {
        let mut a = f64::INFINITY;
        for (i, &d) in run.brake.iter().enumerate() {
            let f = segment.axis_speed_factor(i);
            if f > 1e-12 {
                a = a.min(d / f);
            }
        }
        if a.is_finite() && a > 0.0 {
            a
        } else {
            1.0
        }
    }
}
