//! The interpolation cycle (order in [`crate::channel`]) and stopping.

use super::manual;
use super::measure::MeasStep;
use super::profile::Braking;
use super::{AxisBrake, Channel, ChannelState, Mode, Motion, MotionKind, MotionRequest};
use crate::axis::Axis;
use crate::core::path::Segment;
use crate::link::{LinkError, ProcessImage};
use crate::messages::{ids, CncMessage};
use crate::units::Nanos;

/// Consecutive lost exchanges after which the channel gives up waiting for standstill
/// feedback and is aborted (100 cycles; 0.1 s at 1 ms).
pub const LINK_LOST_GIVE_UP_CYCLES: u32 = 100;

impl Channel {
    // ----- the interpolation cycle --------------------------------------------------------

    /// The link failed to exchange process data this cycle: the inputs are stale.
    ///
    /// A lost exchange is a counted event, not the end of a run: up to `max_lost_cycles`
    /// (machine key, default [`crate::params::DEFAULT_MAX_LOST_CYCLES`]) consecutive ones are counted
    /// ([`Channel::lost_cycles`]) and the channel holds — its interpolation does not advance, the
    /// drives keep the last set-point, a latch that happened meanwhile is still in the next
    /// image and is reported once. One more is error 900012 (once per outage): the axes are
    /// stopped (the drives receive braking set-points as soon as the link is back). A master
    /// that stalled ([`LinkError::Stalled`]) counts every cycle it missed. When the link stays
    /// lost for [`LINK_LOST_GIVE_UP_CYCLES`], the channel stops waiting for the axes to confirm
    /// standstill (it cannot see them) and is aborted: the drives' own watchdogs (EtherCAT SM
    /// watchdog, CANopen heartbeat consumer) stop them.
    pub fn link_lost(&mut self, err: &LinkError) {
        let missed = match err {
            LinkError::Stalled { missed, .. } => u32::try_from(*missed).unwrap_or(u32::MAX).max(1),
            _ => 1,
        };
        self.cycles += 1;
        self.lost_total = self.lost_total.saturating_add(u64::from(missed));
        let before = self.lost_streak;
        self.lost_streak = self.lost_streak.saturating_add(missed);
        let limit = self.cfg.max_lost_cycles;
        if self.lost_streak <= limit {
            tracing::debug!(target: "fieldprobe::channel", streak = self.lost_streak, limit, "exchange lost, holding: {err}");
            return;
        }
        if before <= limit {
            self.push(CncMessage::error(
                ids::LINK_LOST,
                format!(
                    "{err}; {} consecutive cycles without process data (more than {limit}, max_lost_cycles); axes stopped",
                    self.lost_streak
                ),
            ));
        } else {
            tracing::debug!(target: "fieldprobe::channel", streak = self.lost_streak, "exchange lost again: {err}");
        }
        if !matches!(self.mode, Mode::Stopping { .. } | Mode::Aborted) {
            self.begin_stop(ChannelState::Aborted);
        }
        if self.lost_streak >= LINK_LOST_GIVE_UP_CYCLES && !matches!(self.mode, Mode::Aborted) {
            self.mode = Mode::Aborted;
        }
    }

    /// Exchanges lost so far (counted ones and those beyond the limit; a stall counts every
    /// cycle it missed).
    pub fn lost_cycles(&self) -> u64 {
        self.lost_total
    }

    /// One interpolation cycle. `images[i]` is axis `i`'s process image after this cycle's
    /// exchange; the outputs written here go out with the next exchange.
    #[allow(clippy::needless_range_loop)] // axes, images and set-points are parallel arrays
    pub fn cycle(&mut self, now: Nanos, images: &mut [ProcessImage]) {
        self.cycles += 1;
        self.lost_streak = 0;
        self.now = now;
        let dt = self.cfg.cycle.as_secs_f64();
        self.poll_handshakes(now);
        self.record_plc_view(now);
        if images.len() != self.axes.len() {
            self.push(CncMessage::error(
                ids::LINK_LOST,
                format!(
                    "{} process images for {} axes",
                    images.len(),
                    self.axes.len()
                ),
            ));
            self.mode = Mode::Aborted;
            return;
        }
        // 1. Inputs.
        let enabling = matches!(self.mode, Mode::Enabling { .. });
        for i in 0..self.axes.len() {
            let res = self.axes[i]
                .read(now, &images[i].inputs)
                .map(|fb| (fb.fault, fb.operational));
            match res {
                Ok((fault, operational)) => {
                    let stopped = matches!(self.mode, Mode::Aborted | Mode::Stopping { .. });
                    if !enabling && !stopped && (fault || !operational) {
                        let name = self.axes[i].name().to_string();
                        let code = if fault {
                            "fault"
                        } else {
                            "left operation enabled"
                        };
                        self.push(
                            CncMessage::error(
                                ids::DRIVE_FAULT,
                                format!("drive of axis {name} reports {code}; axes stopped"),
                            )
                            .on_axis(&name),
                        );
                        self.begin_stop(ChannelState::Aborted);
                    }
                }
                Err(e) => {
                    self.push(CncMessage::error(ids::DRIVE_FAULT, e.to_string()));
                    self.begin_stop(ChannelState::Aborted);
                }
            }
        }
        // 2. Actual positions against the SLS + tolerance (position controller, FCT-A2 §2).
        for i in 0..self.axes.len() {
            let actual = self.axes[i].actual();
            if let Some(m) = self.sls.check_actual(i, actual) {
                let error = m.is_error();
                self.push(m);
                if error && !matches!(self.mode, Mode::Stopping { .. } | Mode::Aborted) {
                    // Interpolation stopped; the axes decelerate linearly.
                    self.begin_stop(ChannelState::Aborted);
                }
            }
        }
        // 2b. CNC position lag monitoring (P-AXIS-00168), off for the axes of a measuring run to
        //     a fixed stop (FCT-C4 §7.3.1 "Disable position lag monitoring in the position
        //     controller for all axes involved").
        if !matches!(
            self.mode,
            Mode::Stopping { .. } | Mode::Aborted | Mode::Enabling { .. }
        ) {
            for i in 0..self.axes.len() {
                let limit = self.cfg.axes[i].meas.lag_limit;
                let lag = self.axes[i].lag();
                if limit > 0.0 && lag.abs() > limit && !self.fixed_stop_run_on(i) {
                    let name = self.axes[i].name().to_string();
                    self.push(
                        CncMessage::error(
                            ids::LAG_LIMIT,
                            format!("position lag {lag:.6} of axis {name} exceeds P-AXIS-00168 ({limit:.6}); axes stopped"),
                        )
                        .on_axis(&name),
                    );
                    self.begin_stop(ChannelState::Aborted);
                    break;
                }
            }
        }
        // 3. Interpolator: next set-points.
        self.next.clear();
        self.next.extend(self.axes.iter().map(Axis::command));
        let mut finished: Option<ChannelState> = None;
        let resting = self.axes_resting();
        if matches!(self.mode, Mode::Moving(_)) {
            if let Mode::Moving(m) = std::mem::replace(&mut self.mode, Mode::Idle) {
                match self.step_motion(m, now, dt, None) {
                    MotionStep::Running(m) => self.mode = Mode::Moving(m),
                    MotionStep::Done => self.mode = Mode::Idle,
                    MotionStep::Fail => self.begin_stop(ChannelState::Aborted),
                    MotionStep::FailAtRest => {
                        self.drop_independent();
                        self.mode = Mode::Aborted;
                    }
                }
            }
        }
        if !matches!(self.mode, Mode::Stopping { .. } | Mode::Aborted) {
            self.step_independent(now, dt);
        }
        match &mut self.mode {
            Mode::Enabling { cycles } => {
                *cycles += 1;
                for a in &mut self.axes {
                    a.set_enable(true);
                    // A drive found in FAULT while enabling (left so by a master that died,
                    // issue 28 item 4) gets its fault reset, as after a program start
                    // ([`Channel::program_start`]); a drive without a fault gets none (a
                    // SERCOS drive is held off while its reset is requested).
                    if a.has_fault() {
                        a.set_fault_reset(true);
                    }
                }
                if self.axes.iter().all(Axis::is_operational) {
                    for a in &mut self.axes {
                        a.set_fault_reset(false);
                    }
                    finished = Some(ChannelState::Idle);
                } else if *cycles > self.cfg.enable_timeout_cycles {
                    let missing: Vec<&str> = self
                        .axes
                        .iter()
                        .filter(|a| !a.is_operational())
                        .map(Axis::name)
                        .collect();
                    let text = format!(
                        "drives of axes {} did not reach operation enabled within {} cycles",
                        missing.join(", "),
                        self.cfg.enable_timeout_cycles
                    );
                    self.messages
                        .push(CncMessage::error(ids::DRIVE_ENABLE_TIMEOUT, text));
                    finished = Some(ChannelState::Aborted);
                }
            }
            Mode::Idle | Mode::Aborted | Mode::WaitAcyclic { .. } => {}
            Mode::Moving(_) => {}
            Mode::Manual(state) => {
                let mut events = Vec::new();
                let was_jogging = state.jogging();
                state.step(dt, &mut self.next, &mut events);
                // After a jog the axes come to rest in position before the channel is idle
                // again (what `jog` prints are settled positions); bounded by the
                // in-position timeout.
                if was_jogging && !state.jogging() {
                    state.settling = 1;
                } else if state.settling > 0 {
                    state.settling =
                        if resting || state.settling > self.cfg.in_position_timeout_cycles {
                            0
                        } else {
                            state.settling + 1
                        };
                }
                for e in events {
                    if let manual::Event::AreaStopped(..) = e {
                        // PLC datum `area_mon_violation_detected_r` (FCT-C14 §6.3): set in the
                        // cycle the jog stops at the area.
                        self.areas.violation_detected = true;
                    }
                    let m = manual::event_message(e, &self.axes, self.cfg.move_limit_warning);
                    if let Some(m) = m {
                        self.messages.push(m.at(self.block));
                    }
                }
            }
            Mode::Stopping {
                brakes,
                k,
                then,
                settle,
            } => {
                *k += 1;
                let t = *k as f64 * dt;
                let mut done = true;
                for (i, b) in brakes.iter().enumerate() {
                    let (s, v) = b.braking.sample(t);
                    self.next[i] = b.start + b.sign * s;
                    done &= v <= 0.0;
                }
                if done {
                    // The set-points stand; the axes that still follow them come to rest (what
                    // `--json` and the messages report are settled positions). Bounded by the
                    // in-position timeout, without an error of its own: a drive that faulted
                    // does not follow.
                    *settle += 1;
                    if resting || *settle > self.cfg.in_position_timeout_cycles {
                        finished = Some(*then);
                    }
                }
            }
        }
        // 4. Command side: can every axis still stop before its SLS (P-AXIS-00520/00521)?
        if matches!(self.mode, Mode::Moving(_) | Mode::Manual(_)) {
            for i in 0..self.axes.len() {
                let v = (self.next[i] - self.axes[i].command()) / dt;
                if let Some(side) = self.sls.check_stop_distance(i, self.next[i], v) {
                    let m = self.sls.stop_distance_message(i, side);
                    self.push(m);
                    // Brake from the current state, which could still stop in time: this cycle's
                    // set-points are the first braking step.
                    self.begin_stop(ChannelState::Aborted);
                    self.next.clear();
                    self.next.extend(self.axes.iter().map(Axis::command));
                    if let Mode::Stopping { brakes, k, .. } = &mut self.mode {
                        *k = 1;
                        for (n, b) in self.next.iter_mut().zip(brakes.iter()) {
                            let (s, _) = b.braking.sample(dt);
                            *n = b.start + b.sign * s;
                        }
                    }
                    break;
                }
            }
        }
        match finished {
            Some(ChannelState::Idle) => {
                self.mode = Mode::Idle;
            }
            Some(ChannelState::Aborted) => self.mode = Mode::Aborted,
            _ => {}
        }
        // 5. Outputs.
        for i in 0..self.axes.len() {
            let next = self.next[i];
            let prev = self.axes[i].command();
            self.velocity[i] = (next - prev) / dt;
            self.axes[i].set_command(next);
            if let Err(e) = self.axes[i].write(now, &mut images[i].outputs) {
                // Keep the last valid set-point; report once and stop.
                self.axes[i].set_command(prev);
                self.velocity[i] = 0.0;
                let _ = self.axes[i].write(now, &mut images[i].outputs);
                if !matches!(self.mode, Mode::Aborted) {
                    self.push(CncMessage::error(ids::DRIVE_RANGE, e.to_string()));
                    self.mode = Mode::Aborted;
                }
            }
        }
        // 6. Modulo axes at rest back into their range (the drive targets just written stay).
        self.wrap_modulo_axes();
    }

    /// One cycle of a motion block (path interpolation, measurement, braking after the probing
    /// signal, the exact stop at its end). Writes the set-points of the axes the motion moves
    /// into `self.next` — only axis `only` for an independent-axis motion — and says how the
    /// motion goes on.
    ///
    /// A motion ends at rest *in position*: once the interpolation has reached the end (or
    /// braked to a stop), every moved axis's actual position must come within its in-position
    /// window of the final set-point ([`ChannelAxisConfig::in_position`](super::ChannelAxisConfig));
    /// a measurement keeps collecting latches meanwhile, so a contact that the axis reaches
    /// only while it settles still counts. Error 900016 after `in_position_timeout_cycles`.
    pub(super) fn step_motion(
        &mut self,
        mut m: Box<Motion>,
        now: Nanos,
        dt: f64,
        only: Option<usize>,
    ) -> MotionStep {
        let t_now = m.k as f64 * dt;
        let (s_now, v_now) = match m.braking {
            Some((b, k0)) => {
                let (sb, vb) = b.sample((m.k - k0) as f64 * dt);
                let (sp, vp) = m.profile.sample(t_now);
                if sp < sb {
                    (sp, vp)
                } else {
                    (sb, vb)
                }
            }
            None => m.profile.sample(t_now),
        };
        if let Some(mut run) = m.meas.take() {
            match self.measurement_step(&mut run, now, s_now) {
                MeasStep::Hold => {
                    m.meas = Some(run);
                    return MotionStep::Running(m);
                }
                MeasStep::Go => {}
                MeasStep::Brake => {
                    if m.braking.is_none() {
                        let a = self.path_brake_decel(&run, &m.segment);
                        m.braking = Some((Braking::new(s_now, v_now, a), m.k));
                    }
                }
                MeasStep::Fail(msg) => {
                    self.disarm_sources(&run);
                    self.push(msg);
                    return MotionStep::Fail;
                }
            }
            m.meas = Some(run);
        }
        m.k += 1;
        let t = m.k as f64 * dt;
        let (s, done, at_end) = match m.braking {
            Some((b, k0)) => {
                let (sb, vb) = b.sample((m.k - k0) as f64 * dt);
                let (sp, _) = m.profile.sample(t);
                let end = t >= m.profile.duration();
                (sb.min(sp), vb <= 0.0 || end, end && sp <= sb)
            }
            None => {
                let (sp, _) = m.profile.sample(t);
                let end = t >= m.profile.duration();
                (sp, end, end)
            }
        };
        // The set-points of the axes this motion moves, and no others: an independent axis
        // beside the path (or one that finished before it) keeps its own command.
        let mut p = std::mem::take(&mut self.scratch);
        p.resize(self.next.len(), 0.0);
        if at_end {
            p.copy_from_slice(m.segment.end());
        } else {
            m.segment.point_at(s, &mut p);
        }
        for (i, (&pi, &moved)) in p.iter().zip(&m.moved).enumerate() {
            if moved && only.is_none_or(|o| o == i) {
                self.next[i] = pi;
            }
        }
        self.scratch = p;
        if !done {
            return MotionStep::Running(m);
        }
        // At the end of the path: the exact stop. A fixed-stop run has its own rest criterion
        // (the axes may stand pressed against something, never in position).
        let fixed_stop_run = m
            .meas
            .as_ref()
            .is_some_and(|r| r.mtype() == crate::core::measure::MeasType::Type7);
        if let Some(run) = m.meas.as_mut() {
            if fixed_stop_run && !run.end_settled(&self.axes) {
                return MotionStep::Running(m);
            }
        }
        if !fixed_stop_run {
            match self.in_position(&mut m, only) {
                InPosition::Wait => return MotionStep::Running(m),
                InPosition::Timeout(msg) => {
                    if let Some(run) = m.meas.take() {
                        self.disarm_sources(&run);
                    }
                    self.push(msg);
                    return MotionStep::Fail;
                }
                InPosition::Reached => {}
            }
        }
        // A drive that reported its event reads the value over the following cycles
        // (PROFIdrive): wait for it, within the in-position timeout.
        if m.meas.as_ref().is_some_and(|r| r.values_pending()) {
            if m.settle <= self.cfg.in_position_timeout_cycles {
                m.settle += 1;
                return MotionStep::Running(m);
            }
            if let Some(run) = m.meas.take() {
                self.disarm_sources(&run);
            }
            self.push(CncMessage::error(
                ids::MEAS_LATCH,
                "a drive reported its probe event but the latched value did not arrive",
            ));
            return MotionStep::FailAtRest;
        }
        if let Some(run) = m.meas.take() {
            let reached = m.braking.is_none();
            match self.finish_measurement(*run, reached) {
                Ok(settle) => {
                    let settle: Vec<(usize, f64)> = settle
                        .into_iter()
                        .filter(|(i, _)| only.is_none_or(|o| o == *i))
                        .collect();
                    if let Some(back) = self.follow_up(&settle, m.feed) {
                        // "Reduce interpolation to measured value" (FCT-C4 §7.3): a move
                        // within the axes' dynamics, then the exact stop.
                        return MotionStep::Running(Box::new(back));
                    }
                }
                Err(msg) => {
                    // The block is at its end and at rest: stop here, without braking on.
                    self.push(msg);
                    return MotionStep::FailAtRest;
                }
            }
        }
        match self.in_position(&mut m, only) {
            InPosition::Wait => MotionStep::Running(m),
            InPosition::Timeout(msg) => {
                self.push(msg);
                MotionStep::Fail
            }
            InPosition::Reached => MotionStep::Done,
        }
    }

    /// Every axis whose drive follows stands within its in-position window of its last
    /// set-point (a drive that does not follow — faulted, disabled — cannot settle and is not
    /// waited for).
    fn axes_resting(&self) -> bool {
        self.axes
            .iter()
            .zip(&self.cfg.axes)
            .all(|(a, c)| !a.is_operational() || (a.command() - a.actual()).abs() <= c.in_position)
    }

    /// The exact stop at the end of motion `m`: every axis it moves (only `only` for an
    /// independent axis) within its in-position window of its final set-point.
    fn in_position(&self, m: &mut Motion, only: Option<usize>) -> InPosition {
        let mut worst: Option<(usize, f64)> = None;
        for (i, &moved) in m.moved.iter().enumerate() {
            if !moved || only.is_some_and(|o| o != i) {
                continue;
            }
            let off = (self.next[i] - self.axes[i].actual()).abs();
            // NaN (a garbage position) counts as out of position.
            let inside = off <= self.cfg.axes[i].in_position;
            if !inside && worst.is_none_or(|(_, w)| off > w || off.is_nan()) {
                worst = Some((i, off));
            }
        }
        let Some((i, _)) = worst else {
            m.settle = 0;
            return InPosition::Reached;
        };
        m.settle += 1;
        if m.settle <= self.cfg.in_position_timeout_cycles {
            return InPosition::Wait;
        }
        let a = &self.axes[i];
        let name = a.name().to_string();
        let waited = self.cfg.cycle.0.saturating_mul(u64::from(m.settle)) as f64 * 1e-6;
        InPosition::Timeout(
            CncMessage::error(
                ids::IN_POSITION_TIMEOUT,
                format!(
                    "axis {name} did not come to rest within its in-position window ±{:.6} (in_position_window) after {waited:.0} ms: set-point {:.6}, actual {:.6}; axes stopped",
                    self.cfg.axes[i].in_position,
                    self.next[i],
                    a.actual()
                ),
            )
            .on_axis(&name),
        )
    }

    /// The move of the listed axes from their set-points to the given positions after a
    /// fixed-stop run, with the rapid dynamics (P-AXIS-00212 / 00004), or `None` when they are
    /// there.
    fn follow_up(&self, to: &[(usize, f64)], feed: f64) -> Option<Motion> {
        if to.is_empty() {
            return None;
        }
        let start = self.next.clone();
        let mut target = start.clone();
        for &(i, p) in to {
            if let Some(t) = target.get_mut(i) {
                *t = p;
            }
        }
        let segment = Segment::line(start, target.clone()).ok()?;
        if segment.is_empty() {
            return None;
        }
        // A repositioning move: rapid dynamics.
        let req = MotionRequest {
            kind: MotionKind::Rapid,
            target,
            feed,
            measure: None,
        };
        let profile = self.plan(&segment, &req);
        let mut m = Motion::new(segment, profile, None, feed);
        m.fixed_stop_return = true;
        Some(m)
    }

    /// Stop all axes: each decelerates linearly from its current command velocity with
    /// P-AXIS-00003 (FCT-A2 §2: "decelerated by a linear velocity profile"; the contour may be
    /// left when several axes move).
    pub(super) fn begin_stop(&mut self, then: ChannelState) {
        if matches!(self.mode, Mode::Stopping { .. }) {
            return;
        }
        // A running measurement is abandoned: its sources are disarmed and nothing is published.
        let mut abandoned = None;
        if let Mode::Moving(m) = &mut self.mode {
            abandoned = m.meas.take();
        }
        if let Some(run) = abandoned {
            self.disarm_sources(&run);
        }
        let moving = matches!(
            self.mode,
            Mode::Moving(_) | Mode::Manual(_) | Mode::Stopping { .. }
        ) || self.indp.iter().any(Option::is_some);
        if !moving {
            // At rest (e.g. an error right after a block ended): the velocity of the block's last
            // set-point must not carry the axes on.
            self.velocity.iter_mut().for_each(|v| *v = 0.0);
        }
        self.drop_independent();
        let brakes = self
            .axes
            .iter()
            .zip(&self.velocity)
            .zip(&self.cfg.axes)
            .map(|((a, &v), c)| AxisBrake {
                start: a.command(),
                sign: if v < 0.0 { -1.0 } else { 1.0 },
                braking: Braking::new(0.0, v.abs(), c.a_emergency.max(1e-6)),
            })
            .collect();
        self.mode = Mode::Stopping {
            brakes,
            k: 0,
            then,
            settle: 0,
        };
    }
}

/// Where the exact stop at the end of a motion stands.
enum InPosition {
    /// Every moved axis is inside its window.
    Reached,
    /// Not yet.
    Wait,
    /// Waited too long: error 900016.
    Timeout(CncMessage),
}

/// How a motion goes on after one cycle.
pub(super) enum MotionStep {
    /// Still moving.
    Running(Box<Motion>),
    /// Finished (at standstill).
    Done,
    /// Aborted with an error (already queued); brake from the current motion.
    Fail,
    /// Ended at rest with an error (already queued): no braking needed.
    FailAtRest,
}
