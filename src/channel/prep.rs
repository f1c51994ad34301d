//! Block preparation: the whole command path of a block is built and checked (software limit
//! switches, drive position range) before anything moves; G98 / G99.

use super::profile::Trapezoid;
use super::{
    Channel, ChannelState, Mode, Motion, MotionKind, MotionRequest, Prepared, ARC_RADIUS_TOLERANCE,
};
use crate::axis::Axis;
use crate::core::monitor::sls::Side;
use crate::core::path::Segment;
use crate::messages::{ids, CncMessage, Severity};

impl Channel {
    // ----- block preparation -------------------------------------------------------------

    /// Block preparation of a motion block: build the path from the current command position,
    /// check it completely against the software limit switches (FCT-A2 §2: P-ERR-120002 /
    /// 120003, the block is not executed) and start it.
    pub fn start_motion(&mut self, req: &MotionRequest) -> Prepared {
        if !self.is_idle() || matches!(self.mode, Mode::Manual(_)) {
            self.push(CncMessage::error(
                ids::NC_UNSUPPORTED,
                "motion block while the channel is not ready (manual mode or still moving)",
            ));
            return Prepared::Rejected;
        }
        let n = self.axes.len();
        if req.target.len() != n || req.target.iter().any(|v| !v.is_finite()) {
            self.push(CncMessage::error(
                ids::NC_EVALUATION,
                "motion target is not a finite position for every axis",
            ));
            self.mode = Mode::Aborted;
            return Prepared::Rejected;
        }
        let start = self.command_positions();
        let mut target = req.target.clone();
        if let Err(msg) = self.couple_target(&mut target) {
            self.push(msg);
            self.mode = Mode::Aborted;
            return Prepared::Rejected;
        }
        for (i, t) in target.iter().enumerate() {
            if self.indp[i].is_some() && (t - start[i]).abs() > 1e-12 {
                let name = self.axes[i].name().to_string();
                self.push(
                    CncMessage::error(
                        ids::NC_EVALUATION,
                        format!("axis {name} is moving as an independent axis"),
                    )
                    .on_axis(&name),
                );
                self.mode = Mode::Aborted;
                return Prepared::Rejected;
            }
        }
        let segment = match &req.kind {
            MotionKind::Path(seg) => {
                let off = seg
                    .start()
                    .iter()
                    .zip(&start)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                if seg.dims() != n || off > 1e-6 {
                    self.push(CncMessage::error(
                        ids::NC_ARC_GEOMETRY,
                        "path does not start at the current position",
                    ));
                    self.mode = Mode::Aborted;
                    return Prepared::Rejected;
                }
                Ok(seg.clone())
            }
            MotionKind::Rapid | MotionKind::Linear => Segment::line(start, target.clone()),
            MotionKind::Arc {
                a1,
                a2,
                centre_offset,
                clockwise,
            } => Segment::arc(
                start,
                target.clone(),
                *a1,
                *a2,
                *centre_offset,
                *clockwise,
                ARC_RADIUS_TOLERANCE,
            ),
        };
        let segment = match segment {
            Ok(s) => s,
            Err(e) => {
                // The block is not executed and the program aborts here; the error is the one
                // message for it (no further "program aborted").
                self.push(CncMessage::error(ids::NC_ARC_GEOMETRY, e.to_string()));
                self.mode = Mode::Aborted;
                return Prepared::Rejected;
            }
        };
        if segment.is_empty() {
            return Prepared::Empty;
        }
        let mut target_len = segment.length();
        let mut limited = false;
        let segment = match &req.measure {
            Some(mreq) => match self.measuring_path(segment, mreq) {
                Ok((seg, len, lim)) => {
                    target_len = len;
                    limited = lim;
                    seg
                }
                Err(msg) => {
                    self.push(msg);
                    self.mode = Mode::Aborted;
                    return Prepared::Rejected;
                }
            },
            None => segment,
        };
        // Software limit switches: every point of the command path.
        let mut violations = std::mem::take(&mut self.violations);
        self.sls.check_path(&segment, &mut violations);
        let mut rejected = false;
        for v in &violations {
            let m = self.sls.path_message(v);
            rejected |= m.severity == Severity::Error;
            self.push(m);
        }
        self.violations = violations;
        if rejected {
            // Interpolation stops, the program is aborted at this block (FCT-A2 §2).
            self.mode = Mode::Aborted;
            return Prepared::Rejected;
        }
        // Workspace and protection areas: the whole path, exactly (FCT-C14 §2.3 "Path check").
        // A violating block is not executed; the program aborts at it.
        if let Some(m) = self.check_area_path(&segment) {
            self.push(m);
            self.mode = Mode::Aborted;
            return Prepared::Rejected;
        }
        // Every point of the path must be representable in the drive's INTEGER32 positions.
        for (i, a) in self.axes.iter().enumerate() {
            let (lo, hi) = segment.extent(i);
            let sc = a.scaling();
            if sc.to_increments(lo).is_none() || sc.to_increments(hi).is_none() {
                let name = a.name().to_string();
                self.push(
                    CncMessage::error(
                        ids::DRIVE_RANGE,
                        format!(
                            "axis {name}: the path reaches [{lo:.6}, {hi:.6}], outside the drive's position range"
                        ),
                    )
                    .on_axis(&name),
                );
                self.mode = Mode::Aborted;
                return Prepared::Rejected;
            }
        }
        let meas = match &req.measure {
            Some(mreq) => match self.prepare_measurement(mreq, &segment, target_len, false) {
                Ok(mut run) => {
                    run.limited_at_sls = limited;
                    Some(Box::new(run))
                }
                Err(msg) => {
                    self.push(msg);
                    self.mode = Mode::Aborted;
                    return Prepared::Rejected;
                }
            },
            None => None,
        };
        let profile = match &meas {
            Some(run) => self.plan_measuring(&segment, req, run.mtype()),
            None => self.plan(&segment, req),
        };
        if profile.duration() <= 0.0 {
            if let Some(run) = meas {
                self.disarm_sources(&run);
            }
            return Prepared::Empty;
        }
        self.log_path(&segment);
        self.mode = Mode::Moving(Box::new(Motion::new(segment, profile, meas, req.feed)));
        Prepared::Started
    }

    /// Velocity and acceleration along the path so that no axis exceeds its own limits.
    pub(super) fn plan(&self, segment: &Segment, req: &MotionRequest) -> Trapezoid {
        let mut v = match req.kind {
            MotionKind::Rapid => f64::INFINITY,
            _ => crate::units::feed_mm_min_to_mm_s(req.feed),
        };
        let mut a_acc = f64::INFINITY;
        let mut a_dec = f64::INFINITY;
        let mut a_min_axis = f64::INFINITY;
        for (i, c) in self.cfg.axes.iter().enumerate() {
            let f = segment.axis_speed_factor(i);
            let (acc, dec) = match req.kind {
                MotionKind::Rapid => (c.a_rapid, c.a_rapid),
                _ => (c.a_feed, c.d_feed),
            };
            if f > 1e-12 {
                v = v.min(c.v_max / f);
                a_acc = a_acc.min(acc / f);
                a_dec = a_dec.min(dec / f);
                a_min_axis = a_min_axis.min(acc.min(dec));
            }
        }
        if let (Segment::Arc(arc), true) = (segment, a_min_axis.is_finite()) {
            // Centripetal acceleration v²/r must stay within the weakest plane axis.
            v = v.min((a_min_axis * arc.radius).sqrt());
        }
        let fin = |x: f64| if x.is_finite() && x > 0.0 { x } else { 1.0 };
        Trapezoid::plan(segment.length(), fin(v), fin(a_acc), fin(a_dec))
    }

    /// The path of a measuring block (FCT-C4): a line, extended past the target by the
    /// permitted overtravel P-AXIS-00467 (not for type 3) and, with P-CHAN-00268 = 1 (types 1–4),
    /// cut where it reaches a software limit switch. Returns (path, length up to the programmed
    /// target, cut at an SLS).
    fn measuring_path(
        &self,
        segment: Segment,
        mreq: &super::measure::MeasureRequest,
    ) -> Result<(Segment, f64, bool), CncMessage> {
        use crate::core::measure::MeasType;
        if !matches!(segment, Segment::Line(_)) {
            return Err(CncMessage::error(
                ids::MEAS_CONFIG,
                format!(
                    "G{} measures on a straight line only (no G02/G03 in a measuring block)",
                    mreq.gcode
                ),
            ));
        }
        let start = segment.start().to_vec();
        let target = segment.end().to_vec();
        let len = segment.length();
        let dir: Vec<f64> = start
            .iter()
            .zip(&target)
            .map(|(a, b)| (b - a) / len)
            .collect();
        let n = start.len();
        // Overtravel: as far as every moved axis permits (P-AXIS-00467 is per axis; in type 2
        // the old P-AXIS-00114 when P-AXIS-00467 is not given).
        let mut ext = if mreq.mtype == MeasType::Type3 {
            0.0
        } else {
            f64::INFINITY
        };
        for (d, c) in dir.iter().zip(&self.cfg.axes) {
            if d.abs() > 1e-12 {
                let overtravel = if mreq.mtype == MeasType::Type2 {
                    c.meas.overtravel_type2
                } else {
                    c.meas.overtravel
                };
                ext = ext.min(overtravel / d.abs());
            }
        }
        if !ext.is_finite() {
            ext = 0.0;
        }
        let mut total = len + ext;
        // The software limit switches bound the path: the overtravel silently, the programmed
        // part only with P-CHAN-00268 (otherwise the normal SLS check refuses the block).
        let limit_target = self.cfg.meas.limit_at_sls
            && matches!(
                mreq.mtype,
                MeasType::Type1 | MeasType::Type2 | MeasType::Type3 | MeasType::Type4
            );
        let mut limited = false;
        for i in 0..n {
            if !self.sls.is_active(i) || dir[i].abs() <= 1e-12 {
                continue;
            }
            let Some((neg, pos)) = self.sls.active_limits(i) else {
                continue;
            };
            let bound = if dir[i] > 0.0 { pos } else { neg };
            let s_cut = ((bound - start[i]) / dir[i]).max(0.0);
            if s_cut < total && (s_cut >= len || limit_target) {
                if s_cut < len {
                    limited = true;
                }
                total = s_cut;
            }
        }
        // Workspace / protection areas bound it the same way (FCT-C14 §6.2 P-CHAN-00268: "the
        // CNC stops the movement before the software limit switch or … workspace or protection
        // area"), stopping one tolerance band ahead of the first violation; without P-CHAN-00268 a
        // programmed part that violates is refused by the area check of block preparation.
        if !self.areas.monitor.is_empty() {
            let far: Vec<f64> = (0..n).map(|i| start[i] + dir[i] * total).collect();
            if let Some(free) = self.areas.monitor.free_distance(&start, &far) {
                let s_cut = (free - self.areas.monitor.tolerance()).max(0.0);
                if s_cut < total && (s_cut >= len || limit_target) {
                    if s_cut < len {
                        limited = true;
                    }
                    total = s_cut;
                }
            }
        }
        let target_len = len.min(total);
        if total <= 1e-12 {
            return Err(CncMessage::error(
                ids::MEAS_PATH_LIMITED,
                "measurement run cannot start: the axis stands at a software limit switch or control-area boundary in the direction of measurement",
            ));
        }
        let end: Vec<f64> = (0..n).map(|i| start[i] + dir[i] * total).collect();
        let end = if (total - len).abs() < 1e-12 {
            target
        } else {
            end
        };
        let seg = Segment::line(start, end)
            .map_err(|e| CncMessage::error(ids::NC_ARC_GEOMETRY, e.to_string()))?;
        Ok((seg, target_len, limited))
    }

    /// [`measuring_path`](Self::measuring_path) for independent-axis motions.
    pub(super) fn measuring_path_pub(
        &self,
        segment: Segment,
        mreq: &super::measure::MeasureRequest,
    ) -> Result<(Segment, f64, bool), CncMessage> {
        self.measuring_path(segment, mreq)
    }

    /// Dynamics of a measuring block (FCT-C4 §2.1): G00 acceleration (P-AXIS-00004) unless
    /// P-CHAN-00296 asks for G01 dynamics; the feed is F, or P-AXIS-00215 for type 2; types 2 and 4
    /// limit the feed so that braking stays inside the probe stroke P-AXIS-00086 (with a warning).
    pub(super) fn plan_measuring(
        &mut self,
        segment: &Segment,
        req: &MotionRequest,
        mtype: crate::core::measure::MeasType,
    ) -> Trapezoid {
        use crate::core::measure::MeasType;
        let std = self.cfg.meas.std_dynamics;
        let dt = self.cfg.cycle.as_secs_f64();
        let mut v = crate::units::feed_mm_min_to_mm_s(req.feed);
        let mut a_acc = f64::INFINITY;
        let mut a_dec = f64::INFINITY;
        let mut v_stroke = f64::INFINITY;
        // The feed's unit: °/min when only rotary axes move (the path is an angle), else mm/min.
        let mut only_rotary = true;
        for (i, c) in self.cfg.axes.iter().enumerate() {
            let f = segment.axis_speed_factor(i);
            if f <= 1e-12 {
                continue;
            }
            only_rotary &= c.rotary;
            if mtype == MeasType::Type2 {
                v = c.meas.feed_type2 / f;
            }
            let (acc, dec) = if std {
                (c.a_feed, c.d_feed)
            } else {
                (c.a_rapid, c.a_rapid)
            };
            v = v.min(c.v_max / f);
            a_acc = a_acc.min(acc / f);
            a_dec = a_dec.min(dec / f);
            if matches!(mtype, MeasType::Type2 | MeasType::Type4)
                && c.meas.enabled
                && c.meas.stroke > 0.0
            {
                // Axis velocity u, braking deceleration a and the time t the axis goes on at u
                // after the contact: u·t + u²/(2a) ≤ stroke (FCT-C4 P-AXIS-00086, with the
                // "distance components in the buffer" of its remark included). t = the link's
                // dead time (an edge just after a SYNC0 is latched in the cycle that follows,
                // reported one exchange later, and the first braking set-point is reached one
                // cycle after it is sent) + the drive's own lag at constant speed (1/kv without
                // feed-forward) + for a PLC-sampled signal the PLC's cycle beyond the NC cycle.
                let a = self.measurement_brake_decel_pub(i).max(1e-9);
                let plc_extra = if c.meas.signal.uses_drive_latch() {
                    0.0
                } else {
                    self.cfg
                        .meas
                        .plc_cycle
                        .map_or(0.0, |p| (p.as_secs_f64() - dt).max(0.0))
                };
                let t =
                    f64::from(self.axes[i].dead_time_cycles()) * dt + c.servo_lag_time + plc_extra;
                let h = c.meas.stroke;
                let u = a * (-t + (t * t + 2.0 * h / a).sqrt());
                v_stroke = v_stroke.min(u / f);
            }
        }
        if v > v_stroke {
            let unit = if only_rotary { "°/min" } else { "mm/min" };
            self.push(CncMessage::warning(
                ids::MEAS_FEED_REDUCED,
                format!(
                    "measuring feed reduced from {:.3} to {:.3} {unit} so that braking stays inside the probe stroke (P-AXIS-00086)",
                    v * 60.0,
                    v_stroke * 60.0
                ),
            ));
            v = v_stroke;
        }
        let fin = |x: f64| if x.is_finite() && x > 0.0 { x } else { 1.0 };
        Trapezoid::plan(segment.length(), fin(v), fin(a_acc), fin(a_dec))
    }

    /// G98 (negative) / G99 (positive) for axis `i` (FCT-A2 §3). Errors abort the channel.
    pub fn program_limit(&mut self, i: usize, side: Side, value: f64, relative: bool) {
        let actual = self.axes.get(i).map(Axis::actual).unwrap_or(0.0);
        let update = self.sls.program_limit(i, side, value, relative, actual);
        let mut error = false;
        for m in update.messages {
            error |= m.is_error();
            self.push(m);
        }
        if error {
            self.begin_stop(ChannelState::Aborted);
        }
    }
}
