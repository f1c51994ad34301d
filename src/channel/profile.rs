//! Velocity profiles along a path coordinate `s`: linear velocity slopes (trapezoid / triangle)
//! and braking to a stop.
//!
//! Units: `s` in mm (or °), velocities in mm/s, accelerations in mm/s², time in seconds (see
//! [`crate::units`]).
//!
//! # Sampling in the interpolator
//!
//! A profile is a pure function of time since its start. The interpolator samples it at
//! `t = k · Δt` with an integer cycle counter `k` and the cycle time `Δt`, computing `t` afresh
//! every cycle instead of adding `Δt` to a running float, so no time error accumulates over long
//! moves. It is finished once `t >= duration()`; that sample is exactly `(length, 0)`.
//!
//! ```
//! use fieldprobe::channel::profile::Trapezoid;
//! let profile = Trapezoid::plan(100.0, 10.0, 100.0, 100.0);
//! let dt = 0.001;
//! let mut k: u64 = 0;
//! loop {
//!     let t = k as f64 * dt;
//!     let (s, v) = profile.sample(t);
//!     // ... hand s to Segment::point_at, v to the monitors ...
//!     if t >= profile.duration() {
//!         assert_eq!((s, v), (100.0, 0.0));
//!         break;
//!     }
//!     k += 1;
//! }
//! ```
//!
//! # Invalid inputs
//!
//! Nothing here panics or returns NaN. A velocity or acceleration that is NaN, infinite or below
//! its minimum ([`MIN_VELOCITY`], [`MIN_ACCELERATION`]) is raised to that minimum, so a broken
//! parameter gives a very slow move rather than an unbounded one; finite values above
//! [`MAX_DYNAMIC`] are lowered to it. A length or position that is NaN counts as 0, a negative
//! length as 0, and magnitudes are capped at [`MAX_LENGTH`].

/// Smallest velocity a profile uses (mm/s); lower, non-finite or negative limits are raised to it.
pub const MIN_VELOCITY: f64 = 1e-6;

/// Smallest acceleration a profile uses (mm/s²); lower, non-finite or negative limits are raised
/// to it.
pub const MIN_ACCELERATION: f64 = 1e-6;

/// Largest velocity (mm/s) or acceleration (mm/s²) a profile uses.
pub const MAX_DYNAMIC: f64 = 1e9;

/// Largest length or position magnitude (mm) a profile uses.
pub const MAX_LENGTH: f64 = 1e12;

fn velocity_limit(v: f64) -> f64 {
    if v.is_finite() && v > MIN_VELOCITY {
        v.min(MAX_DYNAMIC)
    } else {
        MIN_VELOCITY
    }
}

fn acceleration_limit(a: f64) -> f64 {
    if a.is_finite() && a > MIN_ACCELERATION {
        a.min(MAX_DYNAMIC)
    } else {
        MIN_ACCELERATION
    }
}

/// A length: NaN or negative → 0, capped at [`MAX_LENGTH`].
fn length_value(l: f64) -> f64 {
    if l > 0.0 {
        l.min(MAX_LENGTH)
    } else {
        0.0
    }
}

/// A position: NaN → 0, capped at ±[`MAX_LENGTH`].
fn position_value(s: f64) -> f64 {
    if s.is_nan() {
        0.0
    } else {
        s.clamp(-MAX_LENGTH, MAX_LENGTH)
    }
}

/// Distance to stop from speed `v` at deceleration `a`: `v² / (2a)`.
///
/// `v` is taken by magnitude; a NaN or infinite speed counts as [`MAX_DYNAMIC`] and an invalid
/// deceleration as [`MIN_ACCELERATION`], so a limit check built on this errs on the safe side
/// (longer distance).
pub fn stop_distance(v: f64, a: f64) -> f64 {
    let v = if v.is_finite() {
        v.abs().min(MAX_DYNAMIC)
    } else {
        MAX_DYNAMIC
    };
    let a = acceleration_limit(a);
    v * v / (2.0 * a)
}

/// A rest-to-rest move over a length with linear velocity slopes: accelerate at `a_acc` to
/// `v_peak`, cruise, decelerate at `a_dec` to rest. When the length is too short to reach the
/// velocity limit the cruise phase vanishes and the peak is lower (triangle).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trapezoid {
    length: f64,
    v_peak: f64,
    a_acc: f64,
    a_dec: f64,
    t_acc: f64,
    t_const: f64,
    t_dec: f64,
    /// Position at the end of the acceleration phase.
    s_acc: f64,
    /// Position at the start of the deceleration phase (`>= s_acc`).
    s_dec: f64,
}

impl Trapezoid {
    /// Plans a rest-to-rest move over `length` with cruise velocity at most `v_max`, acceleration
    /// `a_acc` and deceleration `a_dec` (all > 0; see the module docs for invalid values).
    ///
    /// Trapezoid when `v_max²/(2 a_acc) + v_max²/(2 a_dec) <= length`: `t_acc = v_max / a_acc`,
    /// `t_dec = v_max / a_dec`, cruise for the rest. Otherwise a triangle with
    /// `v_peak = sqrt(2 · length · a_acc · a_dec / (a_acc + a_dec))`. Length 0 gives duration 0.
    pub fn plan(length: f64, v_max: f64, a_acc: f64, a_dec: f64) -> Trapezoid {
        let length = length_value(length);
        let v_max = velocity_limit(v_max);
        let a_acc = acceleration_limit(a_acc);
        let a_dec = acceleration_limit(a_dec);
        let ramps = stop_distance(v_max, a_acc) + stop_distance(v_max, a_dec);
        let (v_peak, t_const) = if ramps <= length {
            (v_max, (length - ramps) / v_max)
        } else {
            let v = (2.0 * length * a_acc * a_dec / (a_acc + a_dec)).sqrt();
            (v.min(v_max), 0.0)
        };
        let t_acc = v_peak / a_acc;
        let t_dec = v_peak / a_dec;
        let s_acc = (0.5 * a_acc * t_acc * t_acc).min(length);
        let s_dec = (length - 0.5 * a_dec * t_dec * t_dec).clamp(s_acc, length);
        let plan = Trapezoid {
            length,
            v_peak,
            a_acc,
            a_dec,
            t_acc,
            t_const,
            t_dec,
            s_acc,
            s_dec,
        };
        debug_assert!(
            [t_acc, t_const, t_dec, v_peak]
                .iter()
                .all(|x| x.is_finite() && *x >= 0.0),
            "trapezoid planned from sanitised inputs must be finite: {plan:?}"
        );
        plan
    }

    /// Total time: acceleration + cruise + deceleration.
    pub fn duration(&self) -> f64 {
        self.t_acc + self.t_const + self.t_dec
    }

    /// `(s, v)` at time `t` since the start, `t` clamped to `[0, duration]` (NaN counts as 0).
    ///
    /// `s` never decreases with `t`, `v <= v_peak`, and `sample(t)` for `t >= duration()` is
    /// exactly `(length, 0.0)`. The deceleration phase is computed from the remaining time, so
    /// the end is exact and not the sum of rounded phases.
    pub fn sample(&self, t: f64) -> (f64, f64) {
        if t.is_nan() || t <= 0.0 {
            return (0.0, 0.0);
        }
        let duration = self.duration();
        if t >= duration {
            return (self.length, 0.0);
        }
        if t < self.t_acc {
            let s = (0.5 * self.a_acc * t * t).min(self.s_acc);
            return (s, (self.a_acc * t).min(self.v_peak));
        }
        if t < self.t_acc + self.t_const {
            let s = self.s_acc + self.v_peak * (t - self.t_acc);
            return (s.clamp(self.s_acc, self.s_dec), self.v_peak);
        }
        let remaining = duration - t;
        let s = self.length - 0.5 * self.a_dec * remaining * remaining;
        let v = (self.a_dec * remaining).min(self.v_peak);
        (s.clamp(self.s_dec, self.length), v)
    }

    /// Length of the move.
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Highest velocity reached (the cruise velocity, or the triangle's peak).
    pub fn peak_velocity(&self) -> f64 {
        self.v_peak
    }

    /// Acceleration used (after validation).
    pub fn acceleration(&self) -> f64 {
        self.a_acc
    }

    /// Deceleration used (after validation).
    pub fn deceleration(&self) -> f64 {
        self.a_dec
    }

    /// Duration of the acceleration phase.
    pub fn accel_time(&self) -> f64 {
        self.t_acc
    }

    /// Duration of the cruise phase (0 for a triangle).
    pub fn cruise_time(&self) -> f64 {
        self.t_const
    }

    /// Duration of the deceleration phase.
    pub fn decel_time(&self) -> f64 {
        self.t_dec
    }
}

/// Braking from position `s0` and velocity `v0` to rest at constant deceleration `a`.
///
/// `v0` may be negative (moving towards smaller `s`); the stop position is
/// `s0 + sign(v0) · v0² / (2a)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Braking {
    s0: f64,
    v0: f64,
    a: f64,
}

impl Braking {
    /// Starts braking at `s0` with velocity `v0` and deceleration `a` (> 0). A NaN `s0` or `v0`
    /// counts as 0, an infinite `v0` as ±[`MAX_DYNAMIC`]; `a` as in the module docs.
    pub fn new(s0: f64, v0: f64, a: f64) -> Braking {
        let v0 = if v0.is_nan() {
            0.0
        } else {
            v0.clamp(-MAX_DYNAMIC, MAX_DYNAMIC)
        };
        Braking {
            s0: position_value(s0),
            v0,
            a: acceleration_limit(a),
        }
    }

    /// Time to stop: `|v0| / a`.
    pub fn duration(&self) -> f64 {
        self.v0.abs() / self.a
    }

    /// Where the axis comes to rest.
    pub fn stop_position(&self) -> f64 {
        self.s0 + self.v0.signum() * stop_distance(self.v0, self.a)
    }

    /// `(s, v)` at time `t` since braking began, `t` clamped to `[0, duration]` (NaN counts as 0):
    /// exactly `(s0, v0)` at 0 and `(stop_position, 0.0)` from `duration` on; `s` moves
    /// monotonically from `s0` to the stop position.
    pub fn sample(&self, t: f64) -> (f64, f64) {
        if t.is_nan() || t <= 0.0 {
            return (self.s0, self.v0);
        }
        let duration = self.duration();
        let stop = self.stop_position();
        if t >= duration {
            return (stop, 0.0);
        }
        let sign = self.v0.signum();
        let remaining = duration - t;
        let s = stop - sign * 0.5 * self.a * remaining * remaining;
        let s = s.clamp(self.s0.min(stop), self.s0.max(stop));
        let v = sign * (self.a * remaining).min(self.v0.abs());
        (s, v)
    }
}
