//! The shared axis physics of the drive models ([`AxisPlant`]): the CiA 402 position loop of
//! [`super::ds402::motion`] (first-order loop with gain kv, set-point ramped over the cycle,
//! [`SUBSAMPLES`] sub-samples, speed / torque clipping, fixed stop), the trajectory of the last
//! cycle, the wall and the disturbance. Every axis model owns one and exposes it through
//! [`super::DriveModel::plant`], which gives the trait's default trajectory, position, wall and
//! disturbance methods.

use super::ds402::motion::{self, Cycle, Wall, SUBSAMPLES};
use crate::units::Nanos;

/// The shared axis physics: loop position, trajectory of the last cycle, wall, disturbance.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisPlant {
    /// Loop position (increments, without disturbance).
    pub(super) position: f64,
    /// Set-point at the end of the previous cycle.
    pub(super) prev_target: f64,
    pub(super) disturbance: f64,
    pub(super) wall: Option<Wall>,
    pub(super) trajectory: Vec<(Nanos, f64)>,
    /// A limit cut the motion in the last cycle.
    pub limited: bool,
}

impl Default for AxisPlant {
    fn default() -> Self {
        AxisPlant {
            position: 0.0,
            prev_target: 0.0,
            disturbance: 0.0,
            wall: None,
            trajectory: Vec::with_capacity(SUBSAMPLES + 1),
            limited: false,
        }
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
    fn times(now: Nanos, dt: f64) -> impl Fn(usize) -> Nanos {
        let dt_ns = (dt * 1e9).round() as u64;
        let start = now.0.saturating_sub(dt_ns);
        move |k: usize| {
            let back = u128::from(dt_ns) * (SUBSAMPLES - k) as u128 / SUBSAMPLES as u128;
            Nanos(now.0.saturating_sub(back as u64).max(start))
        }
    }

    /// Hold the position over the cycle ending at `now` (brake).
    pub fn hold(&mut self, now: Nanos, dt_s: f64) {
        let dt = clean_dt(dt_s);
        let time = Self::times(now, dt);
        self.trajectory.clear();
        self.limited = false;
        self.prev_target = self.position;
        let x = self.position + self.disturbance;
        let n = if dt > 0.0 { SUBSAMPLES } else { 0 };
        for k in 0..=n {
            self.trajectory.push((time(k), x));
        }
    }

    /// Position loop over the cycle ending at `now`: set-point ramp from the previous target to
    /// `target` with gain `kv` and speed limits `v_pos` / `v_neg` (increments/s).
    pub fn follow(&mut self, now: Nanos, dt_s: f64, target: f64, kv: f64, v_pos: f64, v_neg: f64) {
        let dt = clean_dt(dt_s);
        if dt <= 0.0 || !target.is_finite() {
            self.hold(now, dt_s);
            return;
        }
        let c = Cycle {
            x0: self.position,
            r0: self.prev_target,
            r1: target,
            dt,
            kv,
            v_pos,
            v_neg,
        };
        self.run(now, &c);
        self.prev_target = target;
    }

    /// Pure integrator over the cycle ending at `now`: the axis moves at `velocity`
    /// (increments/s) within the speed limits (a loop with a constant lag `v/kv` that starts in
    /// steady state moves exactly at `v`).
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
        self.run(now, &c);
        self.prev_target = self.position;
    }

    fn run(&mut self, now: Nanos, c: &Cycle) {
        let time = Self::times(now, c.dt);
        self.trajectory.clear();
        let d = self.disturbance;
        self.trajectory.push((time(0), c.x0 + d));
        let mut wall = self.wall.map(|w| Wall {
            at: w.at - d,
            side: w.side,
        });
        let mut xs = [0.0; SUBSAMPLES];
        let outcome = motion::integrate(c, wall.as_mut(), &mut xs);
        if let (Some(w), Some(moved)) = (self.wall.as_mut(), wall) {
            w.side = moved.side;
        }
        for (k, x) in xs.iter().enumerate() {
            self.trajectory.push((time(k + 1), x + d));
        }
        self.position = xs[SUBSAMPLES - 1];
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

    /// Loop set-point at the end of the last cycle.
    pub fn target(&self) -> f64 {
        self.prev_target
    }

    /// Place the axis (non-finite ignored).
    pub fn set_actual(&mut self, inc: f64) {
        if inc.is_finite() {
            self.position = inc - self.disturbance;
            self.prev_target = self.position;
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
