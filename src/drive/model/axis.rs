//! The shared axis physics of the drive models ([`AxisPlant`]): the servo of a CSP drive
//! ([`AxisPlant::servo`]), the trajectory of the last cycle, the wall and the disturbance. Every
//! axis model owns one and exposes it through [`super::DriveModel::plant`], which gives the
//! trait's default trajectory, position, wall and disturbance methods.
//!
//! # The servo ([`ServoParams`], drive file `[model]`)
//!
//! - **With feed-forward** (`feed_forward = true`, the default): the cascade of a CSP servo drive
//!   ([`motion::integrate_cascade`]). The drive's fine interpolator ramps the set-point linearly
//!   over the cycle from the previous target to the new one; the velocity feed-forward is the
//!   ramp's slope × `velocity_feed_forward`, the acceleration feed-forward the change of that
//!   slope from the previous cycle / T × `acceleration_feed_forward` (both from the set-point
//!   sequence, as the drive sees it); the position controller (gain `kv`) corrects what is left;
//!   the speed loop follows with the time constant `velocity_loop_ms`. The torque demand (‰) is
//!   the demanded acceleration / `rated_acceleration` × 1000; a torque limit caps the
//!   acceleration, a speed limit (`max_velocity`) the speed. Against a fixed stop the axis stalls:
//!   velocity 0, the position error grows with the command, the torque sits at the limit.
//!   Following error at constant speed: 0; along a ramp of a = 1 m/s² at T = 1 ms: well below
//!   1 µm (`tests` in [`motion`] and `tests/it/drive_physics.rs`).
//! - **Without feed-forward** (`feed_forward = false`): the plain first-order position loop
//!   `ẋ = kv·(r − x)` of [`motion::integrate`] (lag v / kv at constant speed, a/kv² left after a
//!   ramp, decaying with 1/kv), torque = lag × `torque_per_increment`, a torque limit capping the
//!   speed (a viscous load).

use super::ds402::motion::{self, Cascade, Cycle, Wall, SUBSAMPLES};
use crate::drive::catalogue::DriveDefinition;
use crate::units::Nanos;

/// Gain (1/s) of the speed loop of a speed-controlled drive without feed-forward (PROFIdrive
/// telegrams 3 / 102 with `feed_forward = false`): the internal set-point integrated from the
/// speed set-point is followed by a first-order loop this fast (assumption; large against any
/// position loop).
pub const LEGACY_SPEED_LOOP_GAIN: f64 = 5000.0;

/// The servo settings of a drive model, from the drive file's `[model]` (increments, seconds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoParams {
    /// Cascade with feed-forward (`true`) or the first-order loop without (`false`).
    pub feed_forward: bool,
    /// Position loop gain, 1/s.
    pub kv: f64,
    /// Velocity feed-forward gain (fraction).
    pub vff: f64,
    /// Acceleration feed-forward gain (fraction).
    pub aff: f64,
    /// Speed loop time constant, s.
    pub tv: f64,
    /// Acceleration at rated torque (1000 ‰), increments/s².
    pub rated_accel: f64,
    /// Largest speed, increments/s (`f64::INFINITY` = none).
    pub v_max: f64,
    /// Torque per increment of lag (‰), first-order loop only.
    pub torque_per_inc: f64,
}

impl Default for ServoParams {
    fn default() -> Self {
        ServoParams::from_model(&crate::drive::catalogue::ModelConfig::default(), 10_000.0)
    }
}

impl ServoParams {
    /// The servo of a drive definition (`[model]`, scaled by `[scaling]`).
    pub fn from_definition(def: &DriveDefinition) -> Self {
        ServoParams::from_model(&def.model, def.scaling.increments_per_unit)
    }

    /// The servo of a `[model]` section with `inc_per_unit` increments per axis unit. Values
    /// the drive-file parser refused cannot arrive; anything non-finite falls back to a default.
    pub fn from_model(m: &crate::drive::catalogue::ModelConfig, inc_per_unit: f64) -> Self {
        let inc = if inc_per_unit.is_finite() && inc_per_unit != 0.0 {
            inc_per_unit.abs()
        } else {
            1.0
        };
        let pos = |v: f64, d: f64| if v.is_finite() && v > 0.0 { v } else { d };
        let frac = |v: f64| {
            if v.is_finite() {
                v.clamp(0.0, 1.5)
            } else {
                1.0
            }
        };
        ServoParams {
            feed_forward: m.feed_forward,
            kv: pos(m.kv, 40.0),
            vff: frac(m.velocity_feed_forward),
            aff: frac(m.acceleration_feed_forward),
            tv: pos(m.velocity_loop_ms, 1.0) * 1e-3,
            rated_accel: pos(m.rated_acceleration * inc, 2e8),
            v_max: m
                .max_velocity
                .map(|v| (v * inc).abs())
                .filter(|v| v.is_finite() && *v > 0.0)
                .unwrap_or(f64::INFINITY),
            torque_per_inc: if m.torque_per_increment.is_finite() {
                m.torque_per_increment.max(0.0)
            } else {
                0.0
            },
        }
    }
}

/// What the drive follows over one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Demand {
    /// Cyclic synchronous position: the set-point at the end of the cycle (0x607A, S-0-0047,
    /// Lightbus position command); the ramp starts at the previous one.
    Position(f64),
    /// Dynamic servo control (PROFIdrive DSC): the set-point ramps from `r0` to `r1`, with the
    /// master's speed set-point `v_ff` (NSOLL_B) as velocity feed-forward.
    Ramp {
        /// Set-point at the start of the cycle.
        r0: f64,
        /// Set-point at the end.
        r1: f64,
        /// Speed set-point, increments/s.
        v_ff: f64,
        /// Position loop gain of the drive (KPC), 1/s.
        kv: f64,
    },
    /// Speed control (PROFIdrive telegrams 3 / 102): the speed set-point, increments/s; the
    /// position loop is the master's.
    Speed(f64),
}

/// What one servo cycle did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoCycle {
    /// Torque actual value, ‰ of rated (the demand clipped to the limit).
    pub torque: f64,
    /// A speed or torque limit cut the motion, or the torque is clipped.
    pub limited: bool,
    /// The axis is pressed against the wall.
    pub contact: bool,
}

/// The shared axis physics: loop position and speed, trajectory of the last cycle, wall,
/// disturbance.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisPlant {
    /// Loop position (increments, without disturbance).
    pub(super) position: f64,
    /// Actual speed, increments/s.
    pub(super) velocity: f64,
    /// Set-point at the end of the previous cycle.
    pub(super) prev_target: f64,
    /// Velocity feed-forward of the previous cycle (for the acceleration feed-forward).
    prev_v_ff: f64,
    pub(super) disturbance: f64,
    pub(super) wall: Option<Wall>,
    pub(super) trajectory: Vec<(Nanos, f64)>,
    /// A limit cut the motion in the last cycle.
    pub limited: bool,
    servo: ServoParams,
}

impl Default for AxisPlant {
    fn default() -> Self {
        AxisPlant::new(ServoParams::default())
    }
}

/// Clean a cycle length: non-finite or negative → 0, at most an hour.
pub fn clean_dt(dt_s: f64) -> f64 {
    if dt_s.is_finite() && dt_s > 0.0 {
        dt_s.min(3600.0)
    } else {
        0.0
    }
}

impl AxisPlant {
    /// An axis at increment 0, at rest, with this servo.
    pub fn new(servo: ServoParams) -> Self {
        AxisPlant {
            position: 0.0,
            velocity: 0.0,
            prev_target: 0.0,
            prev_v_ff: 0.0,
            disturbance: 0.0,
            wall: None,
            trajectory: Vec::with_capacity(SUBSAMPLES + 1),
            limited: false,
            servo,
        }
    }

    /// The servo settings.
    pub fn servo_params(&self) -> &ServoParams {
        &self.servo
    }

    /// Change the servo settings (e.g. the PROFIdrive KPC).
    pub fn set_servo_params(&mut self, servo: ServoParams) {
        self.servo = servo;
    }

    fn times(now: Nanos, dt: f64) -> impl Fn(usize) -> Nanos {
        let dt_ns = (dt * 1e9).round() as u64;
        let start = now.0.saturating_sub(dt_ns);
        move |k: usize| {
            let back = u128::from(dt_ns) * (SUBSAMPLES - k) as u128 / SUBSAMPLES as u128;
            Nanos(now.0.saturating_sub(back as u64).max(start))
        }
    }

    /// Hold the position over the cycle ending at `now` (brake): the axis stands.
    pub fn hold(&mut self, now: Nanos, dt_s: f64) {
        let dt = clean_dt(dt_s);
        let time = Self::times(now, dt);
        self.trajectory.clear();
        self.limited = false;
        self.velocity = 0.0;
        self.prev_v_ff = 0.0;
        self.prev_target = self.position;
        let x = self.position + self.disturbance;
        let n = if dt > 0.0 { SUBSAMPLES } else { 0 };
        for k in 0..=n {
            self.trajectory.push((time(k), x));
        }
    }

    /// One servo cycle ending at `now` following `demand`, with the torque limits `torque_pos`
    /// / `torque_neg` (‰ of rated, magnitudes). See the module documentation.
    pub fn servo(
        &mut self,
        now: Nanos,
        dt_s: f64,
        demand: Demand,
        torque_pos: f64,
        torque_neg: f64,
    ) -> ServoCycle {
        let dt = clean_dt(dt_s);
        let finite = match demand {
            Demand::Position(r) => r.is_finite(),
            Demand::Ramp { r0, r1, v_ff, kv } => {
                r0.is_finite() && r1.is_finite() && v_ff.is_finite() && kv.is_finite()
            }
            Demand::Speed(v) => v.is_finite(),
        };
        if dt <= 0.0 || !finite {
            self.hold(now, dt_s);
            return ServoCycle::default();
        }
        let (t_pos, t_neg) = (clean_limit(torque_pos), clean_limit(torque_neg));
        if self.servo.feed_forward {
            self.cascade(now, dt, demand, t_pos, t_neg)
        } else {
            self.first_order(now, dt, demand, t_pos, t_neg)
        }
    }

    fn cascade(
        &mut self,
        now: Nanos,
        dt: f64,
        demand: Demand,
        t_pos: f64,
        t_neg: f64,
    ) -> ServoCycle {
        let s = self.servo;
        let (r0, r1, v_ff, kv) = match demand {
            Demand::Position(r) => {
                let r0 = self.prev_target;
                (r0, r, s.vff * (r - r0) / dt, s.kv)
            }
            Demand::Ramp { r0, r1, v_ff, kv } => (r0, r1, s.vff * v_ff, kv.max(0.0)),
            Demand::Speed(v) => (self.position, self.position, v, 0.0),
        };
        let a_ff = s.aff * (v_ff - self.prev_v_ff) / dt;
        let c = Cascade {
            x0: self.position,
            v0: self.velocity,
            r0,
            r1,
            v_ff,
            a_ff,
            dt,
            kv,
            tv: s.tv,
            v_max: s.v_max,
            a_pos: s.rated_accel * t_pos / 1000.0,
            a_neg: s.rated_accel * t_neg / 1000.0,
        };
        let mut xs = [0.0; SUBSAMPLES];
        let end = self.with_wall(|wall| motion::integrate_cascade(&c, wall, &mut xs));
        self.record(now, dt, &xs);
        self.velocity = end.v;
        self.prev_v_ff = if v_ff.is_finite() { v_ff } else { 0.0 };
        self.prev_target = match demand {
            Demand::Speed(_) => self.position,
            _ => r1,
        };
        let demand_torque = end.a_demand / s.rated_accel * 1000.0;
        let torque = demand_torque.clamp(-t_neg, t_pos);
        let torque = if torque.is_finite() { torque } else { 0.0 };
        self.limited = end.outcome.limited || torque != demand_torque;
        ServoCycle {
            torque,
            limited: self.limited,
            contact: end.outcome.contact,
        }
    }

    fn first_order(
        &mut self,
        now: Nanos,
        dt: f64,
        demand: Demand,
        t_pos: f64,
        t_neg: f64,
    ) -> ServoCycle {
        let s = self.servo;
        let torque_speed = |kv: f64, limit: f64| {
            if s.torque_per_inc > 0.0 {
                kv * limit / s.torque_per_inc
            } else {
                f64::INFINITY
            }
        };
        let (r0, r1, kv) = match demand {
            Demand::Position(r) => (self.prev_target, r, s.kv),
            Demand::Ramp { r0, r1, kv, .. } => (r0, r1, kv.max(1e-9)),
            Demand::Speed(v) => {
                // The speed set-point integrated into an internal set-point, followed fast.
                let v = v.clamp(-s.v_max, s.v_max);
                (
                    self.prev_target,
                    self.prev_target + v * dt,
                    LEGACY_SPEED_LOOP_GAIN,
                )
            }
        };
        let c = Cycle {
            x0: self.position,
            r0,
            r1,
            dt,
            kv,
            v_pos: s.v_max.min(torque_speed(kv, t_pos)),
            v_neg: s.v_max.min(torque_speed(kv, t_neg)),
        };
        let mut xs = [0.0; SUBSAMPLES];
        let outcome = self.with_wall(|wall| motion::integrate(&c, wall, &mut xs));
        let x0 = self.position;
        self.record(now, dt, &xs);
        self.velocity = (self.position - x0) / dt;
        let demand_torque = (r1 - self.position) * s.torque_per_inc;
        let torque = demand_torque.clamp(-t_neg, t_pos);
        let mut target = r1;
        if matches!(demand, Demand::Speed(_)) && s.torque_per_inc > 0.0 && torque != demand_torque {
            // Anti wind-up: the speed controller's integral stays at the torque limit.
            target = self.position + torque / s.torque_per_inc;
        }
        self.prev_target = if target.is_finite() {
            target
        } else {
            self.position
        };
        self.prev_v_ff = 0.0;
        let torque = if torque.is_finite() { torque } else { 0.0 };
        self.limited = outcome.limited || torque != demand_torque;
        ServoCycle {
            torque,
            limited: self.limited,
            contact: outcome.contact,
        }
    }

    /// Run `f` with the wall in loop coordinates (the wall is kept in actual coordinates; the
    /// loop runs without the disturbance) and keep the side it decided.
    fn with_wall<R>(&mut self, f: impl FnOnce(Option<&mut Wall>) -> R) -> R {
        let d = self.disturbance;
        let mut wall = self.wall.map(|w| Wall {
            at: w.at - d,
            side: w.side,
        });
        let r = f(wall.as_mut());
        if let (Some(w), Some(moved)) = (self.wall.as_mut(), wall) {
            w.side = moved.side;
        }
        r
    }

    /// Record the trajectory of the cycle ending at `now` from the sub-sample positions.
    fn record(&mut self, now: Nanos, dt: f64, xs: &[f64; SUBSAMPLES]) {
        let time = Self::times(now, dt);
        let d = self.disturbance;
        self.trajectory.clear();
        self.trajectory.push((time(0), self.position + d));
        for (k, x) in xs.iter().enumerate() {
            self.trajectory.push((time(k + 1), x + d));
        }
        self.position = xs[SUBSAMPLES - 1];
    }

    /// Pure integrator over the cycle ending at `now`: the axis moves at `velocity`
    /// (increments/s) within the speed limits (a loop with a constant lag `v/kv` that starts in
    /// steady state moves exactly at `v`). The analog amplifier of the terminal drives.
    pub fn drive_velocity(&mut self, now: Nanos, dt_s: f64, velocity: f64, v_max: f64) {
        let dt = clean_dt(dt_s);
        if dt <= 0.0 || !velocity.is_finite() {
            self.hold(now, dt_s);
            return;
        }
        const KV: f64 = 1000.0;
        let lag = velocity / KV;
        let c = Cycle {
            x0: self.position,
            r0: self.position + lag,
            r1: self.position + lag + velocity * dt,
            dt,
            kv: KV,
            v_pos: v_max,
            v_neg: v_max,
        };
        let mut xs = [0.0; SUBSAMPLES];
        let outcome = self.with_wall(|wall| motion::integrate(&c, wall, &mut xs));
        let x0 = self.position;
        self.record(now, dt, &xs);
        self.velocity = (self.position - x0) / dt;
        self.prev_target = self.position;
        self.limited = outcome.limited;
    }

    /// Trajectory of the last cycle (time, actual position incl. disturbance).
    pub fn trajectory(&self) -> &[(Nanos, f64)] {
        &self.trajectory
    }

    /// Position at `t` inside the last cycle (linear between sub-samples).
    pub fn position_at(&self, t: Nanos) -> Option<f64> {
        super::ds402::motion::interpolate(&self.trajectory, t)
    }

    /// Position at `t` clamped into the last cycle; the actual position without trajectory.
    pub fn position_clamped(&self, t: Nanos) -> f64 {
        match (self.trajectory.first(), self.trajectory.last()) {
            (Some(&(t0, _)), Some(&(t1, _))) => self
                .position_at(t.clamp(t0, t1))
                .unwrap_or_else(|| self.actual()),
            _ => self.actual(),
        }
    }

    /// Actual position incl. disturbance.
    pub fn actual(&self) -> f64 {
        self.position + self.disturbance
    }

    /// Actual speed (increments/s) at the end of the last cycle.
    pub fn velocity(&self) -> f64 {
        self.velocity
    }

    /// Loop set-point at the end of the last cycle.
    pub fn target(&self) -> f64 {
        self.prev_target
    }

    /// Place the axis at rest (non-finite ignored).
    pub fn set_actual(&mut self, inc: f64) {
        if inc.is_finite() {
            self.position = inc - self.disturbance;
            self.prev_target = self.position;
            self.velocity = 0.0;
            self.prev_v_ff = 0.0;
            if let Some(w) = self.wall {
                self.wall = Some(Wall::new(w.at, inc));
            }
        }
    }

    /// Constant offset outside the loop (non-finite ignored).
    pub fn set_disturbance(&mut self, d: f64) {
        if d.is_finite() {
            self.disturbance = d;
        }
    }

    /// Wall at `position` (actual coordinates) or none; non-finite ignored.
    pub fn set_fixed_stop(&mut self, position: Option<f64>) {
        match position {
            None => self.wall = None,
            Some(p) if p.is_finite() => self.wall = Some(Wall::new(p, self.actual())),
            Some(_) => {}
        }
    }

    /// The wall.
    pub fn fixed_stop(&self) -> Option<f64> {
        self.wall.map(|w| w.at)
    }
}

/// A torque limit as a magnitude (NaN → 0).
fn clean_limit(l: f64) -> f64 {
    if l.is_nan() {
        0.0
    } else {
        l.abs()
    }
}
