//! Independent-axis motions (`X[INDP_SYN G100 G90 POS100 FEED500]`, FCT-C4 §2): an axis moves
//! on its own profile, beside (or instead of) the path. With G100 it measures on its own: it arms
//! its source, latches "for each axis involved" and stops on its own signal. Measurement types
//! 1, 2 and 7 allow it (the seed table's `*`).

use super::cycle::MotionStep;
use super::measure::MeasureRequest;
use super::{Channel, ChannelState, Mode, Motion, MotionKind, MotionRequest, Prepared};
use crate::core::path::Segment;
use crate::messages::{ids, CncMessage, Severity};
use crate::units::Nanos;

/// An independent motion of one axis.
#[derive(Debug, Clone)]
pub(super) struct IndependentSlot {
    motion: Box<Motion>,
    /// `INDP_SYN`: the block waits for it at its end.
    pub(super) sync: bool,
}

impl IndependentSlot {
    pub(super) fn motion(&self) -> &Motion {
        &self.motion
    }
}

impl Channel {
    /// Start an independent motion of axis `axis` to `target` (ACS) at `feed` mm/min, measuring
    /// when `measure` is given. `sync` = `INDP_SYN`.
    pub fn start_independent(
        &mut self,
        axis: usize,
        target: f64,
        feed: f64,
        sync: bool,
        measure: Option<MeasureRequest>,
    ) -> Prepared {
        let n = self.axes.len();
        if axis >= n || !target.is_finite() {
            self.report(CncMessage::error(
                ids::NC_EVALUATION,
                "independent motion: invalid axis or target",
            ));
            return Prepared::Rejected;
        }
        let name = self.axes[axis].name().to_string();
        let path_moves_axis = match &self.mode {
            Mode::Moving(m) => {
                let (lo, hi) = m.segment.extent(axis);
                hi - lo > 1e-12
            }
            Mode::Idle | Mode::WaitAcyclic { .. } => false,
            _ => {
                self.report(CncMessage::error(
                    ids::NC_UNSUPPORTED,
                    "independent motion while the channel is not ready",
                ));
                return Prepared::Rejected;
            }
        };
        if path_moves_axis || self.indp[axis].is_some() || self.is_coupled_slave(axis) {
            self.report(
                CncMessage::error(
                    ids::NC_EVALUATION,
                    format!("axis {name} is already moving (path, independent motion or coupling)"),
                )
                .on_axis(&name),
            );
            return Prepared::Rejected;
        }
        if let Some(m) = &measure {
            if !m.mtype.allows_independent_axes() {
                self.report(CncMessage::error(
                    ids::MEAS_CONFIG,
                    format!(
                        "measurement type {} does not allow independent axes (only 1, 2 and 7)",
                        m.mtype.number()
                    ),
                ));
                return Prepared::Rejected;
            }
        }
        let start = self.command_positions();
        let mut end = start.clone();
        end[axis] = target;
        let mut segment = match Segment::line(start, end) {
            Ok(s) => s,
            Err(_) => {
                // Positions beyond the coordinate bound of every path (the only way a line of
                // finite points fails): name the axis, the position and the bound.
                let max = crate::messages::show_number(crate::core::path::MAX_COORDINATE);
                self.report(
                    CncMessage::error(
                        ids::NC_EVALUATION,
                        format!(
                            "independent motion of axis {name}: position {} mm is outside the allowed range -{max} … {max} mm",
                            crate::messages::show_number(target)
                        ),
                    )
                    .on_axis(&name),
                );
                return Prepared::Rejected;
            }
        };
        if segment.is_empty() {
            return Prepared::Empty;
        }
        let mut target_len = segment.length();
        let mut limited = false;
        if let Some(mreq) = &measure {
            match self.measuring_path_pub(segment.clone(), mreq) {
                Ok((seg, len, lim)) => {
                    segment = seg;
                    target_len = len;
                    limited = lim;
                }
                Err(msg) => {
                    self.report(msg);
                    return Prepared::Rejected;
                }
            }
        }
        let mut violations = Vec::new();
        self.sls.check_path(&segment, &mut violations);
        let mut rejected = false;
        for v in &violations {
            let m = self.sls.path_message(v);
            rejected |= m.severity == Severity::Error;
            self.push(m);
        }
        if rejected {
            self.begin_stop(ChannelState::Aborted);
            return Prepared::Rejected;
        }
        // Workspace / protection areas (FCT-C14 §2.3): the axis's own line.
        if let Some(m) = self.check_area_path(&segment) {
            self.report(m);
            return Prepared::Rejected;
        }
        if measure.is_some() {
            // A path measurement of the same block must leave this axis's latch to this run
            // (FCT-C4 §2: independent measurement "in parallel to a path motion of a G100").
            let released = match &mut self.mode {
                Mode::Moving(m) => m.meas.as_mut().is_none_or(|run| run.release_axis(axis)),
                _ => true,
            };
            if !released {
                self.report(
                    CncMessage::error(
                        ids::MEAS_CONFIG,
                        format!("axis {name} must latch for the path measurement"),
                    )
                    .on_axis(&name),
                );
                return Prepared::Rejected;
            }
        }
        let meas = match &measure {
            Some(mreq) => match self.prepare_measurement(mreq, &segment, target_len, true) {
                Ok(mut run) => {
                    run.limited_at_sls = limited;
                    Some(Box::new(run))
                }
                Err(msg) => {
                    self.report(msg);
                    return Prepared::Rejected;
                }
            },
            None => None,
        };
        let req = MotionRequest {
            kind: MotionKind::Linear,
            target: segment.end().to_vec(),
            feed,
            measure: measure.clone(),
        };
        let profile = match &meas {
            Some(run) => self.plan_measuring(&segment, &req, run.mtype()),
            None => self.plan(&segment, &req),
        };
        self.indp[axis] = Some(IndependentSlot {
            motion: Box::new(Motion::new(segment, profile, meas, feed)),
            sync,
        });
        Prepared::Started
    }

    /// Axis `axis` is moving as an independent axis (an `INDP_SYN` / `INDP_ASYN` motion is still
    /// running on it).
    pub fn moving_independently(&self, axis: usize) -> bool {
        self.indp.get(axis).is_some_and(Option::is_some)
    }

    /// Some independent motion (`INDP_SYN` or `INDP_ASYN`) is still running: the program's end
    /// waits for it.
    pub fn independent_running(&self) -> bool {
        self.indp.iter().any(Option::is_some)
    }

    /// Some `INDP_SYN` motion is still running.
    pub(super) fn independent_busy(&self) -> bool {
        self.indp.iter().flatten().any(|s| s.sync)
    }

    /// Step every independent motion by one cycle (after the path interpolation).
    pub(super) fn step_independent(&mut self, now: Nanos, dt: f64) {
        for i in 0..self.indp.len() {
            let Some(slot) = self.indp[i].take() else {
                continue;
            };
            match self.step_motion(slot.motion, now, dt, Some(i)) {
                MotionStep::Running(m) => {
                    self.indp[i] = Some(IndependentSlot {
                        motion: m,
                        sync: slot.sync,
                    })
                }
                MotionStep::Done => {}
                MotionStep::Fail | MotionStep::FailAtRest => {
                    self.begin_stop(ChannelState::Aborted);
                    return;
                }
            }
        }
    }

    /// Drop all independent motions (their measurements are disarmed) — on stops.
    pub(super) fn drop_independent(&mut self) {
        for i in 0..self.indp.len() {
            if let Some(mut slot) = self.indp[i].take() {
                if let Some(run) = slot.motion.meas.take() {
                    self.disarm_sources(&run);
                }
            }
        }
    }
}
