//! Manual mode (HB): continuous and incremental jog with the limits of FCT-A2 §2 and §3.3.
//!
//! On selection the channel records each axis's position; the permitted range of an axis is
//! [`SoftLimits::jog_range`](crate::core::monitor::sls::SoftLimits::jog_range) around it (active
//! SLS when referenced, relative offset limits P-AXIS-00137 / 00138, absolute offset limits
//! P-AXIS-00492 / 00493).
//!
//! - Continuous jog is planned to stop exactly at the end of the range; when it gets there the
//!   motion stops and, with P-MANU-00014, warning P-ERR-50720 is given.
//! - An incremental step that would end outside the range is not executed: warning P-ERR-150008.
//!
//! # Workspace and protection areas (FCT-C14 §5, §6.2, §6.3)
//!
//! Active control areas (`#CONTROL AREA ON`) are monitored in manual mode too, on the command
//! positions (the TCP). Whether they are is decided by P-CHAN-00442 and the control unit
//! "suppress error output from working space monitoring in manual mode"
//! ([`Channel::set_area_mon_suppress_manual_w`]); see [`Channel::manual_area_monitoring`]:
//!
//! | P-CHAN-00442 | control unit off | control unit on |
//! |---|---|---|
//! | 0 (seed case 2) | monitored; selection needs the TCP in the permitted range | not monitored |
//! | 1 (seed case 1) | not monitored | not monitored |
//! | 2 (seed case 3) | monitored; selection anywhere, moving back allowed | not monitored |
//!
//! - **Selection** ([`Channel::enter_manual`], P-CHAN-00442 = 0, control unit off): a TCP
//!   outside the workspaces gives error P-ERR-50961, inside a protection area P-ERR-50962 (text:
//!   the area and the position); the PLC datum `area_mon_violation_detected_r` is set and manual
//!   mode is *not* selected. The error stops nothing (nothing moves) and the channel stays idle:
//!   the operator recovers by setting the control unit, which allows the selection (and jogging
//!   without area limits), moves back, and clears the control unit again.
//! - **Continuous jog** is planned to stop at the nearer of the jog-range end and the first area
//!   boundary along the axis
//!   ([`AreaMonitor::free_travel`](crate::core::monitor::area_monitor::AreaMonitor::free_travel)
//!   from the command position; the 1 µm tolerance band is not used, the jog stops at the
//!   boundary itself). The trapezoid decelerates with P-AXIS-00002 so that the axis comes to rest
//!   there: the start of the deceleration lies ahead of the limit by a distance that depends on
//!   the jog velocity and the deceleration (FCT-C14 §5). At the stop only the motion stops (no
//!   error, seed "only an axis motion stop occurs"); with P-MANU-00014 warning P-ERR-900318 names
//!   the area. The PLC datum is set in the cycle the jog stops at the area (not if
//!   [`Channel::jog_stop`] brakes it before it gets there).
//! - **Incremental jog** whose path would violate an area is not executed: warning P-ERR-900318
//!   always (like P-ERR-150008), PLC datum set.
//! - **Moving back** (P-CHAN-00442 = 2, or after the control unit was cleared outside the
//!   permitted range): from a violating position a jog is allowed only in a direction in which
//!   the TCP gets back into the permitted range within the jog range; it may then run on to the
//!   next area boundary. In any other direction it is refused (continuous: warning 900318 with
//!   P-MANU-00014; incremental: warning 900318). A step that ends before the re-entry point is
//!   allowed (it approaches the permitted range). The re-entry point is found by sampling every
//!   0.05 mm and bisecting, so a permitted stretch shorter than that can be missed (a refusal,
//!   never a violation).
//! - **One axis at a time**: each jog is planned as a straight line along its own axis from the
//!   positions at its start, so while areas are monitored a second jog of a monitored axis is
//!   refused (returns false, warning 900318) as long as another monitored axis is jogging.

use super::profile::{Braking, Trapezoid};
use super::{Channel, Mode};
use crate::axis::Axis;
use crate::messages::{ids, CncMessage};

#[path = "manual_areas.rs"]
mod manual_areas;
use manual_areas::{area_name, AreaStop, AreaTravel};

/// Far end used for a continuous jog on an axis without any limit (mm / °).
const UNLIMITED_TRAVEL: f64 = 1.0e9;

#[derive(Debug, Clone, Copy)]
pub(super) enum Event {
    /// Continuous jog of this axis reached the end of its range.
    LimitReached(usize),
    /// Continuous jog of this axis stopped at a workspace / protection-area boundary.
    AreaStopped(usize, AreaStop),
}

#[derive(Debug, Clone, Copy)]
struct Jog {
    origin: f64,
    sign: f64,
    profile: Trapezoid,
    k: u64,
    continuous: bool,
    /// Jog ends at a range limit (not at an unlimited far end).
    to_limit: bool,
    /// The limit is an area boundary (FCT-C14 §5).
    area: Option<AreaStop>,
    /// Braking after a jog stop: (braking, cycle it began, path position then).
    braking: Option<(Braking, u64)>,
}

/// Manual-mode state of the channel.
#[derive(Debug, Clone)]
pub struct ManualState {
    start: Vec<f64>,
    jogs: Vec<Option<Jog>>,
    /// Cycles the axes have been settling since the last jog ended (0: not settling).
    pub(super) settling: u32,
}

impl ManualState {
    /// A jog runs, or the axes are still coming to rest after one.
    pub(super) fn is_moving(&self) -> bool {
        self.jogging() || self.settling > 0
    }

    /// Axis `i` was wrapped by `shift` (a modulo axis at rest): its reference for the relative
    /// offset limits moves with it.
    pub(super) fn shift_start(&mut self, i: usize, shift: f64) {
        if let Some(s) = self.start.get_mut(i) {
            *s -= shift;
        }
    }

    /// A jog runs.
    pub(super) fn jogging(&self) -> bool {
        self.jogs.iter().any(Option::is_some)
    }

    pub(super) fn step(&mut self, dt: f64, next: &mut [f64], events: &mut Vec<Event>) {
        for (i, slot) in self.jogs.iter_mut().enumerate() {
            let Some(j) = slot else { continue };
            j.k += 1;
            let t = j.k as f64 * dt;
            let (s, done) = match j.braking {
                Some((b, k0)) => {
                    let (s, v) = b.sample((j.k - k0) as f64 * dt);
                    (s, v <= 0.0)
                }
                None => {
                    let (s, _) = j.profile.sample(t);
                    (s, t >= j.profile.duration())
                }
            };
            if let Some(n) = next.get_mut(i) {
                *n = j.origin + j.sign * s;
            }
            if done {
                if j.continuous && j.to_limit && j.braking.is_none() {
                    events.push(match j.area {
                        Some(a) => Event::AreaStopped(i, a),
                        None => Event::LimitReached(i),
                    });
                }
                *slot = None;
            }
        }
    }
}

pub(super) fn event_message(
    e: Event,
    axes: &[Axis],
    move_limit_warning: bool,
) -> Option<CncMessage> {
    match e {
        Event::LimitReached(i) => {
            let name = axes.get(i).map(Axis::name).unwrap_or("?");
            move_limit_warning.then(|| {
                CncMessage::warning(
                    ids::JOG_LIMIT_REACHED,
                    format!("continuous jog of axis {name} stopped at its limit; move back within the valid range"),
                )
                .on_axis(name)
            })
        }
        Event::AreaStopped(i, a) => {
            let name = axes.get(i).map(Axis::name).unwrap_or("?");
            move_limit_warning.then(|| {
                CncMessage::warning(
                    ids::AREA_JOG_STOPPED,
                    format!(
                        "continuous jog of axis {name} stopped at the boundary of {}; jog in the opposite direction",
                        area_name(a.kind, a.id)
                    ),
                )
                .on_axis(name)
            })
        }
    }
}

impl Channel {
    /// Select manual mode (G200-like): records every axis's position as the reference of the
    /// relative offset limits. Only from idle.
    ///
    /// With active control areas, P-CHAN-00442 = 0 and the control unit
    /// [`set_area_mon_suppress_manual_w`](Channel::set_area_mon_suppress_manual_w) not set, the
    /// TCP (command positions) must be in the permitted range (FCT-C14 §5 case 2): otherwise
    /// error P-ERR-50961 (outside the workspaces) or P-ERR-50962 (inside a protection area) is
    /// queued, the PLC datum [`area_mon_violation_detected_r`] is set, the channel stays idle and
    /// false is returned. Setting the control unit allows the selection. P-CHAN-00442 = 1 or 2:
    /// no check.
    ///
    /// [`area_mon_violation_detected_r`]: Channel::area_mon_violation_detected_r
    pub fn enter_manual(&mut self) -> bool {
        if !matches!(self.mode, Mode::Idle) {
            return false;
        }
        if !self.manual_entry_allowed() {
            return false;
        }
        self.mode = Mode::Manual(ManualState {
            start: self.command_positions(),
            jogs: vec![None; self.axes.len()],
            settling: 0,
        });
        true
    }

    /// Leave manual mode; only when no axis is jogging.
    pub fn leave_manual(&mut self) -> bool {
        match &self.mode {
            Mode::Manual(m) if !m.jogging() => {
                self.mode = Mode::Idle;
                true
            }
            _ => false,
        }
    }

    /// True while manual mode is selected.
    pub fn in_manual(&self) -> bool {
        matches!(self.mode, Mode::Manual(_))
    }

    /// The manual-mode range of axis `i` (low, high), if manual mode is selected.
    pub fn jog_range(&self, i: usize) -> Option<(f64, f64)> {
        match &self.mode {
            Mode::Manual(m) => Some(self.sls.jog_range(i, *m.start.get(i)?)),
            _ => None,
        }
    }

    /// Continuous jog of axis `i` at `velocity` (signed, mm/s); runs until [`jog_stop`] or the
    /// end of the range. Returns false when not in manual mode or the axis is already jogging.
    ///
    /// While control areas are monitored ([`manual_area_monitoring`]) the jog also stops at the
    /// first area boundary (motion stop, no error; warning P-ERR-900318 with P-MANU-00014; PLC
    /// datum set), from a violating position it runs only in a direction that leads back into
    /// the permitted range, and it is refused (false, warning 900318) while another monitored
    /// axis is jogging. See the [module documentation](self).
    ///
    /// [`jog_stop`]: Channel::jog_stop
    /// [`manual_area_monitoring`]: Channel::manual_area_monitoring
    pub fn jog_continuous(&mut self, i: usize, velocity: f64) -> bool {
        let Some((lo, hi)) = self.jog_range(i) else {
            return false;
        };
        let Some(c) = self.cfg.axes.get(i) else {
            return false;
        };
        let pos = self.axes[i].command();
        let sign = if velocity < 0.0 { -1.0 } else { 1.0 };
        let end = if sign > 0.0 { hi } else { lo };
        let (mut length, mut to_limit) = if end.is_finite() {
            ((end - pos) * sign, true)
        } else {
            (UNLIMITED_TRAVEL, false)
        };
        let v = velocity.abs().min(c.v_max);
        let (a_acc, a_dec) = (c.a_feed, c.d_feed);
        let block = self.block;
        let warn = self.cfg.move_limit_warning;
        let jogging = match &self.mode {
            Mode::Manual(m) => m.jogs.iter().map(Option::is_some).collect::<Vec<_>>(),
            _ => return false,
        };
        if jogging[i] || v.is_nan() || v <= 0.0 {
            return false;
        }
        if self.area_concurrent_jog(i, &jogging) {
            return false;
        }
        // Workspace / protection areas (FCT-C14 §5).
        let range = if end.is_finite() {
            (end - pos) * sign
        } else {
            f64::INFINITY
        };
        let mut area = None;
        match self.area_travel(i, sign, range) {
            AreaTravel::Free => {}
            AreaTravel::Limited { dist, hit } => {
                let d = (dist - self.areas.monitor.tolerance()).max(0.0);
                if d < length {
                    length = d;
                    to_limit = true;
                    area = Some(AreaStop::new(&hit));
                }
            }
            AreaTravel::Refused { hit } => {
                length = 0.0;
                area = Some(AreaStop::new(&hit));
            }
        }
        if length <= 0.0 {
            if area.is_some() {
                self.areas.violation_detected = true;
            }
            // Already at (or beyond) the limit in this direction: nothing moves.
            let e = match area {
                Some(a) => Event::AreaStopped(i, a),
                None => Event::LimitReached(i),
            };
            if let Some(msg) = event_message(e, &self.axes, warn) {
                self.messages.push(msg.at(block));
            }
            return true;
        }
        let Mode::Manual(m) = &mut self.mode else {
            return false;
        };
        m.jogs[i] = Some(Jog {
            origin: pos,
            sign,
            profile: Trapezoid::plan(length, v, a_acc, a_dec),
            k: 0,
            continuous: true,
            to_limit,
            area,
            braking: None,
        });
        true
    }

    /// Stop a continuous jog of axis `i`: brake with P-AXIS-00002 (or stop an increment).
    /// A jog that was to stop at an area boundary and now stops short of it is no area stop
    /// (the PLC datum `area_mon_violation_detected_r` is set only when a jog stops at an area).
    pub fn jog_stop(&mut self, i: usize) {
        let Some(c) = self.cfg.axes.get(i) else {
            return;
        };
        let d = c.d_feed;
        let dt = self.cfg.cycle.as_secs_f64();
        if let Mode::Manual(m) = &mut self.mode {
            if let Some(Some(j)) = m.jogs.get_mut(i) {
                if j.braking.is_none() {
                    let (s, v) = j.profile.sample(j.k as f64 * dt);
                    // Never brake past the planned end (the range limit).
                    let b = Braking::new(s, v, d.max(1e-6));
                    if b.stop_position() <= j.profile.length() {
                        j.braking = Some((b, j.k));
                        // Stopped short of the area: no area stop (and no PLC datum).
                        j.area = None;
                    }
                }
            }
        }
    }

    /// Incremental jog of axis `i` by `distance` (signed) at `velocity`. A step that would end
    /// outside the range is not executed and gives warning P-ERR-150008 (FCT-A2 §2).
    ///
    /// While control areas are monitored ([`manual_area_monitoring`]) a step whose path would
    /// violate an area (or, from a violating position, one in a direction that does not lead
    /// back into the permitted range) is not executed: warning P-ERR-900318, PLC datum set,
    /// false. A step while another monitored axis is jogging is refused as well (false,
    /// warning 900318).
    ///
    /// [`manual_area_monitoring`]: Channel::manual_area_monitoring
    pub fn jog_increment(&mut self, i: usize, distance: f64, velocity: f64) -> bool {
        let Some((lo, hi)) = self.jog_range(i) else {
            return false;
        };
        let Some(c) = self.cfg.axes.get(i) else {
            return false;
        };
        let pos = self.axes[i].command();
        let target = pos + distance;
        let name = self.axes[i].name().to_string();
        let eps = crate::core::monitor::sls::COMMAND_EPSILON;
        if !target.is_finite() || target > hi + eps || target < lo - eps {
            self.push(
                CncMessage::warning(
                    ids::JOG_STEP_REFUSED,
                    format!(
                        "incremental jog of axis {name} to {target:.6} not executed: beyond the permitted range [{lo:.6}, {hi:.6}]"
                    ),
                )
                .on_axis(&name),
            );
            return false;
        }
        let v = velocity.abs().min(c.v_max);
        let (a_acc, a_dec) = (c.a_feed, c.d_feed);
        let jogging = match &self.mode {
            Mode::Manual(m) => m.jogs.iter().map(Option::is_some).collect::<Vec<_>>(),
            _ => return false,
        };
        if jogging[i] || v.is_nan() || v <= 0.0 || distance == 0.0 {
            return false;
        }
        if self.area_concurrent_jog(i, &jogging) {
            return false;
        }
        let range = if distance > 0.0 { hi - pos } else { pos - lo };
        if self.area_step_refused(i, distance, range) {
            return false;
        }
        let Mode::Manual(m) = &mut self.mode else {
            return false;
        };
        m.jogs[i] = Some(Jog {
            origin: pos,
            sign: if distance < 0.0 { -1.0 } else { 1.0 },
            profile: Trapezoid::plan(distance.abs(), v, a_acc, a_dec),
            k: 0,
            continuous: false,
            to_limit: false,
            area: None,
            braking: None,
        });
        true
    }
}
