//! Manual mode (HB): continuous and incremental jog with the limits of seed 001 §2 and §3.3.
//!
//! On selection the channel records each axis's position; the permitted range of an axis is
//! [`SoftLimits::jog_range`](crate::core::monitor::sls::SoftLimits::jog_range) around it (active
//! SLS when referenced, relative offset limits P-AXIS-00137 / 00138, absolute offset limits
//! P-AXIS-00492 / 00493).
//!
//! - Continuous jog is planned to stop exactly at the end of the range; when it gets there the
//!   motion stops and, with P-MANU-00014, warning P-ERR-50720 is given.
//! - An incremental step that would end outside the range is not executed: warning P-ERR-150008.

use super::profile::{Braking, Trapezoid};
use super::{Channel, Mode};
use crate::axis::Axis;
use crate::messages::{ids, CncMessage};

/// Far end used for a continuous jog on an axis without any limit (mm / °).
const UNLIMITED_TRAVEL: f64 = 1.0e9;

#[derive(Debug, Clone, Copy)]
pub(super) enum Event {
    /// Continuous jog of this axis reached the end of its range.
    LimitReached(usize),
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
    /// Braking after a jog stop: (braking, cycle it began, path position then).
    braking: Option<(Braking, u64)>,
}

/// Manual-mode state of the channel.
#[derive(Debug, Clone)]
pub struct ManualState {
    start: Vec<f64>,
    jogs: Vec<Option<Jog>>,
}

impl ManualState {
    pub(super) fn is_moving(&self) -> bool {
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
                    events.push(Event::LimitReached(i));
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
    }
}

impl Channel {
    /// Select manual mode (G200-like): records every axis's position as the reference of the
    /// relative offset limits. Only from idle.
    pub fn enter_manual(&mut self) -> bool {
        if !matches!(self.mode, Mode::Idle) {
            return false;
        }
        self.mode = Mode::Manual(ManualState {
            start: self.command_positions(),
            jogs: vec![None; self.axes.len()],
        });
        true
    }

    /// Leave manual mode; only when no axis is jogging.
    pub fn leave_manual(&mut self) -> bool {
        match &self.mode {
            Mode::Manual(m) if !m.is_moving() => {
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
    /// [`jog_stop`]: Channel::jog_stop
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
        let (length, to_limit) = if end.is_finite() {
            ((end - pos) * sign, true)
        } else {
            (UNLIMITED_TRAVEL, false)
        };
        let v = velocity.abs().min(c.v_max);
        let (a_acc, a_dec) = (c.a_feed, c.d_feed);
        let block = self.block;
        let warn = self.cfg.move_limit_warning;
        let Mode::Manual(m) = &mut self.mode else {
            return false;
        };
        if m.jogs[i].is_some() || v.is_nan() || v <= 0.0 {
            return false;
        }
        if length <= 0.0 {
            // Already at (or beyond) the limit in this direction: nothing moves.
            if let Some(msg) = event_message(Event::LimitReached(i), &self.axes, warn) {
                self.messages.push(msg.at(block));
            }
            return true;
        }
        m.jogs[i] = Some(Jog {
            origin: pos,
            sign,
            profile: Trapezoid::plan(length, v, a_acc, a_dec),
            k: 0,
            continuous: true,
            to_limit,
            braking: None,
        });
        true
    }

    /// Stop a continuous jog of axis `i`: brake with P-AXIS-00002 (or stop an increment).
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
                    }
                }
            }
        }
    }

    /// Incremental jog of axis `i` by `distance` (signed) at `velocity`. A step that would end
    /// outside the range is not executed and gives warning P-ERR-150008 (seed 001 §2).
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
        let Mode::Manual(m) = &mut self.mode else {
            return false;
        };
        if m.jogs[i].is_some() || v.is_nan() || v <= 0.0 || distance == 0.0 {
            return false;
        }
        m.jogs[i] = Some(Jog {
            origin: pos,
            sign: if distance < 0.0 { -1.0 } else { 1.0 },
            profile: Trapezoid::plan(distance.abs(), v, a_acc, a_dec),
            k: 0,
            continuous: false,
            to_limit: false,
            braking: None,
        });
        true
    }
}
