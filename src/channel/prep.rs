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
    /// check it completely against the software limit switches (seed 001 §2: P-ERR-120002 /
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
            return Prepared::Rejected;
        }
        let start = self.command_positions();
        let segment = match req.kind {
            MotionKind::Rapid | MotionKind::Linear => Segment::line(start, req.target.clone()),
            MotionKind::Arc {
                a1,
                a2,
                centre_offset,
                clockwise,
            } => Segment::arc(
                start,
                req.target.clone(),
                a1,
                a2,
                centre_offset,
                clockwise,
                ARC_RADIUS_TOLERANCE,
            ),
        };
        let segment = match segment {
            Ok(s) => s,
            Err(e) => {
                self.push(CncMessage::error(ids::NC_ARC_GEOMETRY, e.to_string()));
                return Prepared::Rejected;
            }
        };
        if segment.is_empty() {
            return Prepared::Empty;
        }
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
            // Interpolation stops, the program is aborted at this block (seed 001 §2).
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
        let profile = self.plan(&segment, req);
        if profile.duration() <= 0.0 {
            return Prepared::Empty;
        }
        self.mode = Mode::Moving(Box::new(Motion {
            segment,
            profile,
            k: 0,
        }));
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

    /// G98 (negative) / G99 (positive) for axis `i` (seed 001 §3). Errors abort the channel.
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
