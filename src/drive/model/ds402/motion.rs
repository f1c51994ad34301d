//! Position loop of the CiA 402 model over one cycle, with speed and torque limits and a fixed
//! stop, sampled as a trajectory.
//!
//! The loop is `ẋ = kv·(r − x)` with the set-point `r` ramping linearly from the previous target
//! to the new one over the cycle (CSP fine interpolation). Over each of [`SUBSAMPLES`] equal
//! sub-steps of length `h` the exact solution for the ramp (slope `s`) is used:
//! `e(h) = s/kv + (e₀ − s/kv)·e^(−kv·h)`, `x = r − e`. Without limits the sub-steps compose to the
//! exact solution over the whole cycle, so the sub-samples lie on the true curve.
//!
//! Limits act per sub-step on the displacement: the speed may not exceed
//! `min(max_velocity, kv · T_limit / torque_per_increment)` in the direction of motion — the
//! torque demand is `lag × torque_per_increment`, so a clipped torque is a clipped lag and, with
//! the first-order loop, a clipped speed (a viscous load). A fixed stop clips the position to
//! the wall on the side the axis came from.

/// Sub-samples per cycle recorded in the trajectory (16 per cycle: at 10 m/min and 1 ms, one
/// sub-step is 104 increments of travel; the chord error of linear interpolation between
/// sub-samples is far below one increment for the model's kv).
pub const SUBSAMPLES: usize = 16;

/// The side of a fixed stop the axis is on; it cannot pass to the other side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The axis is at or below the wall: positions are clipped to `≤ wall`.
    Below,
    /// The axis is at or above the wall: positions are clipped to `≥ wall`.
    Above,
}

/// A rigid wall in loop coordinates (increments).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// Position of the wall.
    pub at: f64,
    /// Side of the axis; `None` while the axis stands exactly at the wall and has not moved
    /// away yet (the first motion away decides).
    pub side: Option<Side>,
}

impl Wall {
    /// A wall at `at` with the side taken from the axis position `x`.
    pub fn new(at: f64, x: f64) -> Wall {
        Wall {
            at,
            side: side_of(x, at),
        }
    }

    /// `x` with the wall applied (and the side decided when it was open).
    fn clip(&mut self, x: f64) -> (f64, bool) {
        match self.side {
            None => {
                self.side = side_of(x, self.at);
                (x, false)
            }
            Some(Side::Below) if x > self.at => (self.at, true),
            Some(Side::Above) if x < self.at => (self.at, true),
            Some(_) => (x, false),
        }
    }
}

fn side_of(x: f64, at: f64) -> Option<Side> {
    if x < at {
        Some(Side::Below)
    } else if x > at {
        Some(Side::Above)
    } else {
        None
    }
}

/// One cycle of the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cycle {
    /// Position at the start (loop coordinates, increments).
    pub x0: f64,
    /// Set-point at the start of the cycle.
    pub r0: f64,
    /// Set-point at the end of the cycle (0x607A).
    pub r1: f64,
    /// Cycle length in seconds (> 0).
    pub dt: f64,
    /// Loop gain in 1/s (> 0).
    pub kv: f64,
    /// Largest speed in positive direction, increments/s (`f64::INFINITY` = none).
    pub v_pos: f64,
    /// Largest speed in negative direction (magnitude), increments/s.
    pub v_neg: f64,
}

/// What happened over the cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outcome {
    /// A speed (or torque) limit cut the displacement of some sub-step.
    pub limited: bool,
    /// The wall stopped the axis in some sub-step.
    pub contact: bool,
}

/// Integrate one cycle; `out[k]` is the position at the end of sub-step `k` (not the start).
/// Non-finite intermediate results stop the motion (the position holds), so garbage never
/// propagates.
pub fn integrate(c: &Cycle, mut wall: Option<&mut Wall>, out: &mut [f64; SUBSAMPLES]) -> Outcome {
    let mut outcome = Outcome::default();
    let h = c.dt / SUBSAMPLES as f64;
    let s = (c.r1 - c.r0) / c.dt;
    let lag = s / c.kv;
    let a = (-c.kv * h).exp();
    let mut x = c.x0;
    for (k, slot) in out.iter_mut().enumerate() {
        let ra = c.r0 + s * h * k as f64;
        let rb = if k + 1 == SUBSAMPLES {
            c.r1
        } else {
            c.r0 + s * h * (k + 1) as f64
        };
        let eb = lag + ((ra - x) - lag) * a;
        let mut d = (rb - eb) - x;
        let (lo, hi) = (-c.v_neg * h, c.v_pos * h);
        if d > hi || d < lo {
            d = d.clamp(lo.min(0.0), hi.max(0.0));
            outcome.limited = true;
        }
        let mut next = x + d;
        if let Some(w) = wall.as_deref_mut() {
            let (clipped, hit) = w.clip(next);
            next = clipped;
            outcome.contact |= hit;
        }
        if next.is_finite() {
            x = next;
        }
        *slot = x;
    }
    outcome
}

/// One cycle of the servo cascade of a CSP drive with feed-forward (see [`integrate_cascade`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cascade {
    /// Position at the start (loop coordinates, increments).
    pub x0: f64,
    /// Velocity at the start, increments/s.
    pub v0: f64,
    /// Set-point at the start of the cycle (fine interpolation ramps from here).
    pub r0: f64,
    /// Set-point at the end of the cycle.
    pub r1: f64,
    /// Velocity feed-forward over the cycle, increments/s.
    pub v_ff: f64,
    /// Acceleration feed-forward over the cycle, increments/s².
    pub a_ff: f64,
    /// Cycle length in seconds (> 0).
    pub dt: f64,
    /// Position loop gain in 1/s (≥ 0; 0 = speed control, the set-point is not followed).
    pub kv: f64,
    /// Time constant of the speed loop in seconds (> 0).
    pub tv: f64,
    /// Largest speed (magnitude), increments/s (`f64::INFINITY` = none).
    pub v_max: f64,
    /// Largest acceleration in positive direction (torque limit), increments/s².
    pub a_pos: f64,
    /// Largest deceleration in negative direction (magnitude), increments/s².
    pub a_neg: f64,
}

/// Where a cascade cycle ended.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CascadeEnd {
    /// Velocity at the end, increments/s.
    pub v: f64,
    /// Acceleration the speed loop demands at the end (before the torque limit),
    /// increments/s².
    pub a_demand: f64,
    /// A speed or torque limit or the wall cut the motion.
    pub outcome: Outcome,
}

impl Cascade {
    /// Acceleration demanded at time `t` into the cycle in state `(x, v)`, before and after the
    /// limits.
    fn accel(&self, t: f64, x: f64, v: f64) -> (f64, f64) {
        let r = self.r0 + (self.r1 - self.r0) * (t / self.dt);
        let v_ref = (self.v_ff + self.kv * (r - x)).clamp(-self.v_max, self.v_max);
        let demand = (v_ref - v) / self.tv + self.a_ff;
        let mut a = demand.clamp(-self.a_neg, self.a_pos);
        // At the speed limit the drive does not accelerate further.
        if (v >= self.v_max && a > 0.0) || (v <= -self.v_max && a < 0.0) {
            a = 0.0;
        }
        (demand, a)
    }
}

/// Integrate one cycle of a CSP servo cascade with feed-forward: the drive's fine interpolator
/// ramps the set-point `r` linearly from `r0` to `r1` over the cycle; the position controller
/// commands `v_ref = v_ff + kv·(r − x)` (clipped to `v_max`); the speed loop, a first-order lag
/// with time constant `tv`, plus the acceleration feed-forward give the acceleration
/// `a = (v_ref − v)/tv + a_ff`, clipped to the torque limits (`a_pos`, `a_neg`): ẋ = v, v̇ = a.
/// With exact feed-forward (`v_ff` = the ramp's slope, `a_ff` = its change) the error
/// `e = r − x` obeys `tv·ë + ė + kv·e = 0` between the cycle boundaries, so it stays in the
/// sub-micrometre range at constant speed and along ramps.
///
/// Classic Runge-Kutta over [`SUBSAMPLES`] sub-steps (each split further so that a step is at
/// most `tv / 2`); `out[k]` is the position at the end of sub-step `k`. A wall stops the axis
/// (velocity 0). Non-finite intermediate results stop the motion.
pub fn integrate_cascade(
    c: &Cascade,
    mut wall: Option<&mut Wall>,
    out: &mut [f64; SUBSAMPLES],
) -> CascadeEnd {
    let mut end = CascadeEnd::default();
    let h = c.dt / SUBSAMPLES as f64;
    let inner = ((h / (0.5 * c.tv)).ceil().clamp(1.0, 64.0)) as usize;
    let q = h / inner as f64;
    let (mut x, mut v) = (c.x0, c.v0);
    for (k, slot) in out.iter_mut().enumerate() {
        for j in 0..inner {
            let t = h * k as f64 + q * j as f64;
            let (d1, a1) = c.accel(t, x, v);
            let (v1, x1) = (v + 0.5 * q * a1, x + 0.5 * q * v);
            let (_, a2) = c.accel(t + 0.5 * q, x1, v1);
            let (v2, x2) = (v + 0.5 * q * a2, x + 0.5 * q * v1);
            let (_, a3) = c.accel(t + 0.5 * q, x2, v2);
            let (v3, x3) = (v + q * a3, x + q * v2);
            let (_, a4) = c.accel(t + q, x3, v3);
            if d1 != a1 {
                end.outcome.limited = true;
            }
            let mut nx = x + q / 6.0 * (v + 2.0 * v1 + 2.0 * v2 + v3);
            let mut nv = v + q / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
            if nv.abs() > c.v_max {
                nv = nv.clamp(-c.v_max, c.v_max);
                end.outcome.limited = true;
            }
            if let Some(w) = wall.as_deref_mut() {
                let (clipped, hit) = w.clip(nx);
                if hit {
                    nx = clipped;
                    nv = 0.0;
                    end.outcome.contact = true;
                }
            }
            if nx.is_finite() && nv.is_finite() {
                x = nx;
                v = nv;
            } else {
                v = 0.0;
            }
        }
        *slot = x;
    }
    let (demand, a) = c.accel(c.dt, x, v);
    if demand != a {
        end.outcome.limited = true;
    }
    end.v = v;
    end.a_demand = if demand.is_finite() { demand } else { 0.0 };
    end
}

/// Linear interpolation in a time-sorted trajectory `(t, x)`; `None` outside it. Shared by the
/// drive models to read the position at a sub-cycle edge time.
pub fn interpolate(traj: &[(crate::units::Nanos, f64)], t: crate::units::Nanos) -> Option<f64> {
    let (&(t0, _), &(t1, x1)) = (traj.first()?, traj.last()?);
    if t < t0 || t > t1 {
        return None;
    }
    if t == t1 {
        return Some(x1);
    }
    // First sample after t: exists because t < t1.
    let i = traj.partition_point(|&(ti, _)| ti <= t);
    let (ta, xa) = *traj.get(i.checked_sub(1)?)?;
    let (tb, xb) = *traj.get(i)?;
    if tb <= ta {
        return Some(xb);
    }
    let f = (t.0 - ta.0) as f64 / (tb.0 - ta.0) as f64;
    Some(xa + (xb - xa) * f)
}

/// Round and saturate to `i32` (`as` saturates and maps NaN to 0).
pub fn round_i32(v: f64) -> i32 {
    v.round() as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cycle(x0: f64, r0: f64, r1: f64) -> Cycle {
        Cycle {
            x0,
            r0,
            r1,
            dt: 0.001,
            kv: 40.0,
            v_pos: f64::INFINITY,
            v_neg: f64::INFINITY,
        }
    }

    #[test]
    fn sub_steps_compose_to_the_exact_cycle_solution() {
        let c = cycle(-30.0, 0.0, 1000.0);
        let mut out = [0.0; SUBSAMPLES];
        assert_eq!(integrate(&c, None, &mut out), Outcome::default());
        let lag = 1000.0 / 0.001 / 40.0;
        for (k, x) in out.iter().enumerate() {
            let t = 0.001 * (k + 1) as f64 / SUBSAMPLES as f64;
            let e = lag + (30.0 - lag) * (-40.0 * t).exp();
            assert!((x - (1.0e6 * t - e)).abs() < 1e-6, "{k}: {x}");
        }
    }

    #[test]
    fn limits_and_wall() {
        let mut c = cycle(0.0, 0.0, 1.0e6);
        c.v_pos = 1.0e5; // 100 increments per cycle
        let mut out = [0.0; SUBSAMPLES];
        assert!(integrate(&c, None, &mut out).limited);
        assert!((out[SUBSAMPLES - 1] - 100.0).abs() < 1e-9);

        let mut wall = Wall::new(50.0, 0.0);
        let o = integrate(&c, Some(&mut wall), &mut out);
        assert!(o.limited && o.contact);
        assert_eq!(out[SUBSAMPLES - 1], 50.0);
        // From above, the other way.
        let mut wall = Wall::new(-50.0, 0.0);
        let c = Cycle {
            r1: -1.0e6,
            v_neg: 1.0e5,
            ..c
        };
        assert!(integrate(&c, Some(&mut wall), &mut out).contact);
        assert_eq!(out[SUBSAMPLES - 1], -50.0);
        // Standing at the wall: the first motion decides the side.
        let mut wall = Wall::new(0.0, 0.0);
        assert!(!integrate(&c, Some(&mut wall), &mut out).contact);
        assert_eq!(wall.side, Some(Side::Below));
    }
}
