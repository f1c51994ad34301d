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
