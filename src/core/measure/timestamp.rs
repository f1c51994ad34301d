//! DC timestamp back-calculation (FCT-C4 §7.5 "Measuring with Distributed Clocks Timestamp";
//! buffer contract as CODESYS `SMC_ETC_InterpolateAxisPosition`).
//!
//! A digital input terminal (EL1252) timestamps the probe edge on the EtherCAT distributed-clock
//! time base; the PLC hands the timestamp to the CNC through the `timestamp` control unit (seed
//! 004 §8.2.3, [`super::plc`]). The CNC keeps the actual positions of the last cycles with their
//! sample times in a [`TimestampBuffer`] and calculates the position at the event time back.
//!
//! # Time base
//!
//! DC times are 64-bit ns since 2000-01-01 (≈ 8·10¹⁷ ns today, beyond the 2⁵³ ns an `f64`
//! holds exactly). Times stay `i64` everywhere; only *differences* between a query and a sample
//! (a few ms) are converted to `f64`, i.e. the sample time is the base that is subtracted before
//! converting. Terminals with 32-bit DC times are accepted through [`TimestampBuffer::push_dc32`]
//! and [`TimestampBuffer::estimate_at_dc32`]: a 32-bit time is placed next to the newest sample by
//! the TwinCAT `T_DCTIME32` rule — the difference modulo 2³² is taken as a signed value, so it is
//! valid within ±2.147 s ([`dc32_diff`]).
//!
//! # Dead times ([`DeadTimes`])
//!
//! * The time passed to [`TimestampBuffer::push`] is the DC time of the cycle in which the CNC
//!   received the actual value (Sync0 of that cycle). The value was *acquired* earlier, at
//!   `t − input_shift − drive_delay` (DcInputShift and the drive's encoder delay).
//! * The event time passed to [`TimestampBuffer::estimate_at`] is the terminal's timestamp. The
//!   probe touched at `t_e − terminal_delay − probe_delay` (EL1252 latch delay < 1 µs, probe
//!   actuation delay, ISG P-AXIS-00487).
//!
//! Both corrections are applied to the query: the buffer compares
//! `t_e − terminal_delay − probe_delay + input_shift + drive_delay` with the stored cycle times.
//! A dead time that is wrong by Δ moves the result by v·Δ; the buffer cannot see that unless the
//! corrected time leaves the buffer ([`TimestampError::TooOld`] / [`TimestampError::TooNew`]).
//!
//! # Accuracy
//!
//! Linear interpolation between two samples a cycle `T` apart, with an acceleration `a` that is
//! constant over the interval, errs by `a/2·(t − t_k)(t_{k+1} − t)`, at most **a·T²/8**
//! (0.25 µm at 2 m/s² and 1 ms). [`Estimate::error_bound`] reports a·T²/8 with `a` estimated from
//! the second differences of the neighbouring samples. When velocities are pushed (actual
//! velocity in the PDO), cubic Hermite interpolation is used, which is exact for constant
//! acceleration; its reported bound is the same a·T²/8 with `a` from the velocity change, i.e.
//! conservative. Within one cycle after the newest sample the position is extrapolated
//! (CODESYS: "too new" only beyond one task interval) with the bound a·Δt·(Δt + T)/2 (linear
//! from the last two samples) or a·Δt²/2 (with velocity).

use thiserror::Error;

use crate::units::Nanos;

/// Smallest buffer (32–64 entries cover a 10 ms PLC at 1 ms NC).
pub const MIN_CAPACITY: usize = 32;
/// Largest buffer accepted by [`TimestampBuffer::new`] (requests above are clamped).
pub const MAX_CAPACITY: usize = 1 << 16;

/// Nanoseconds per second as `f64`.
const NS_PER_S: f64 = 1e9;

/// Difference `a − b` of two 32-bit DC times, modulo 2³², as a signed value (TwinCAT
/// `T_DCTIME32` rule): valid while the true difference lies within ±2.147 s.
#[inline]
pub fn dc32_diff(a: u32, b: u32) -> i64 {
    a.wrapping_sub(b) as i32 as i64
}

/// Mapping between the run's virtual time ([`Nanos`]) and the DC time base (i64 ns since
/// 2000-01-01): `dc = now + epoch_offset_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DcClock {
    /// DC time at virtual time zero (ns since 2000-01-01).
    pub epoch_offset_ns: i64,
}

impl DcClock {
    /// DC time of 2026-01-01 00:00 (9497 days after 2000-01-01), a realistic magnitude that is
    /// far beyond `f64` integer precision.
    pub const YEAR_2026: i64 = 9_497 * 86_400 * 1_000_000_000;

    /// A clock with the given offset.
    pub const fn new(epoch_offset_ns: i64) -> Self {
        DcClock { epoch_offset_ns }
    }

    /// DC time of a virtual instant (saturating).
    #[inline]
    pub fn dc_time(&self, now: Nanos) -> i64 {
        let now = i64::try_from(now.0).unwrap_or(i64::MAX);
        now.saturating_add(self.epoch_offset_ns)
    }

    /// Virtual instant of a DC time (saturating at zero and `u64::MAX`).
    #[inline]
    pub fn to_nanos(&self, dc: i64) -> Nanos {
        let rel = (dc as i128) - (self.epoch_offset_ns as i128);
        Nanos(rel.clamp(0, u64::MAX as i128) as u64)
    }
}

impl Default for DcClock {
    /// [`DcClock::YEAR_2026`].
    fn default() -> Self {
        DcClock::new(DcClock::YEAR_2026)
    }
}

/// Dead times in ns (ETG.1000.4 distributed clocks; Beckhoff EL1252 documentation). All zero by default.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct DeadTimes {
    /// DcInputShift: time between acquisition and evaluation of the actual value.
    pub input_shift_ns: i64,
    /// Drive-internal encoder delay (TwinCAT "Encoder Delay in Cycles" × T + "Additional
    /// Encoder Delay").
    pub drive_delay_ns: i64,
    /// Delay between the physical edge and the terminal's timestamp (EL1252: < 1 µs).
    pub terminal_delay_ns: i64,
    /// Probe actuation delay (ISG P-AXIS-00487, given there in µs).
    pub probe_delay_ns: i64,
}

impl DeadTimes {
    /// How much earlier than its cycle time a sample was acquired.
    #[inline]
    pub fn sample_shift(&self) -> i64 {
        self.input_shift_ns.saturating_add(self.drive_delay_ns)
    }

    /// How much earlier than its timestamp the event happened.
    #[inline]
    pub fn event_shift(&self) -> i64 {
        self.terminal_delay_ns.saturating_add(self.probe_delay_ns)
    }

    /// The stored-time-base query for an event timestamp:
    /// `t_e − event_shift + sample_shift` (saturating).
    #[inline]
    pub fn query_time(&self, t_event: i64) -> i64 {
        t_event
            .saturating_sub(self.event_shift())
            .saturating_add(self.sample_shift())
    }
}

/// Why a position could not be calculated back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum TimestampError {
    /// No sample pushed yet.
    #[error("no actual values buffered yet")]
    Empty,
    /// The corrected event time lies before the oldest buffered sample (CODESYS
    /// `SMC_INVALID_TIMESTAMP`, "too old").
    #[error("timestamp too old: corrected time {query} ns before oldest sample {oldest} ns")]
    TooOld {
        /// Corrected event time on the sample time base.
        query: i64,
        /// Time of the oldest sample.
        oldest: i64,
    },
    /// The corrected event time lies more than one cycle after the newest sample ("too new").
    #[error("timestamp too new: corrected time {query} ns more than {cycle_ns} ns after newest sample {newest} ns")]
    TooNew {
        /// Corrected event time on the sample time base.
        query: i64,
        /// Time of the newest sample.
        newest: i64,
        /// The cycle time that bounds extrapolation.
        cycle_ns: i64,
    },
    /// A pushed sample is not later than the newest one (the sample is ignored).
    #[error("sample time {time} ns is not after the newest sample {newest} ns")]
    NotMonotonic {
        /// Time of the rejected sample.
        time: i64,
        /// Time of the newest sample.
        newest: i64,
    },
    /// A pushed position or velocity is NaN or infinite (the sample is ignored).
    #[error("sample value is not finite")]
    NotFinite,
}

/// How an [`Estimate`] was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Interpolation {
    /// The query hit a sample time exactly.
    Exact,
    /// Linear between two samples.
    Linear,
    /// Cubic Hermite between two samples with velocities.
    Hermite,
    /// Extrapolated within one cycle after the newest sample.
    Extrapolated,
}

/// A back-calculated position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Position (mm / °) at the corrected event time.
    pub position: f64,
    /// Estimated interpolation error bound (mm / °), see the module documentation;
    /// `f64::INFINITY` when too few samples exist to estimate the acceleration.
    pub error_bound: f64,
    /// How the position was obtained.
    pub method: Interpolation,
    /// The corrected event time on the sample time base (ns).
    pub query_time: i64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    t: i64,
    pos: f64,
    vel: Option<f64>,
}

const EMPTY: Sample = Sample {
    t: 0,
    pos: 0.0,
    vel: None,
};

/// Ring buffer of (DC cycle time, actual position, optional actual velocity) with
/// back-calculation of the position at an event time (the contract of CODESYS SoftMotion's DC back-calculation).
///
/// Allocates once in [`TimestampBuffer::new`]; [`push`](Self::push) and
/// [`estimate_at`](Self::estimate_at) never allocate.
#[derive(Debug, Clone)]
pub struct TimestampBuffer {
    samples: Box<[Sample]>,
    /// Index of the oldest sample.
    start: usize,
    len: usize,
    cycle_ns: i64,
    dead: DeadTimes,
}

impl TimestampBuffer {
    /// A buffer with room for `capacity` samples, rounded up to a power of two within
    /// [`MIN_CAPACITY`] … [`MAX_CAPACITY`]. `cycle` is the NC cycle that bounds extrapolation
    /// ("too new" = more than one cycle after the newest sample).
    pub fn new(capacity: usize, cycle: Nanos, dead: DeadTimes) -> Self {
        let cap = capacity
            .clamp(MIN_CAPACITY, MAX_CAPACITY)
            .checked_next_power_of_two()
            .unwrap_or(MAX_CAPACITY)
            .min(MAX_CAPACITY);
        TimestampBuffer {
            samples: vec![EMPTY; cap].into_boxed_slice(),
            start: 0,
            len: 0,
            cycle_ns: i64::try_from(cycle.0).unwrap_or(i64::MAX),
            dead,
        }
    }

    /// Number of samples the buffer holds at most (a power of two).
    pub fn capacity(&self) -> usize {
        self.samples.len()
    }

    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True before the first push (and after [`clear`](Self::clear)).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Forget all samples.
    pub fn clear(&mut self) {
        self.start = 0;
        self.len = 0;
    }

    /// The cycle time in ns.
    pub fn cycle_ns(&self) -> i64 {
        self.cycle_ns
    }

    /// The dead times applied to queries.
    pub fn dead_times(&self) -> DeadTimes {
        self.dead
    }

    /// Replace the dead times.
    pub fn set_dead_times(&mut self, dead: DeadTimes) {
        self.dead = dead;
    }

    /// Cycle time of the oldest sample.
    pub fn oldest_time(&self) -> Option<i64> {
        (self.len > 0).then(|| self.at(0).t)
    }

    /// Cycle time of the newest sample.
    pub fn newest_time(&self) -> Option<i64> {
        (self.len > 0).then(|| self.at(self.len - 1).t)
    }

    #[inline]
    fn at(&self, i: usize) -> Sample {
        let mask = self.samples.len() - 1;
        self.samples[(self.start + i) & mask]
    }

    /// Push the actual position of one cycle. `t` is the cycle's DC time (ns since 2000).
    pub fn push(&mut self, t: i64, pos: f64) -> Result<(), TimestampError> {
        self.push_sample(Sample { t, pos, vel: None })
    }

    /// Push the actual position and the actual velocity (mm/s, °/s) of one cycle; with
    /// velocities on both sides of a query, cubic Hermite interpolation is used.
    pub fn push_with_velocity(&mut self, t: i64, pos: f64, vel: f64) -> Result<(), TimestampError> {
        if !vel.is_finite() {
            return Err(TimestampError::NotFinite);
        }
        self.push_sample(Sample {
            t,
            pos,
            vel: Some(vel),
        })
    }

    /// Push with a 32-bit DC time: it is unwrapped next to the newest sample ([`dc32_diff`]);
    /// the first sample defines the 64-bit time line (`t as i64`).
    pub fn push_dc32(&mut self, t: u32, pos: f64) -> Result<(), TimestampError> {
        let t64 = self.unwrap_dc32(t);
        self.push(t64, pos)
    }

    /// The 64-bit time of a 32-bit DC time placed next to the newest sample.
    pub fn unwrap_dc32(&self, t: u32) -> i64 {
        match self.newest_time() {
            Some(newest) => newest.saturating_add(dc32_diff(t, newest as u32)),
            None => t as i64,
        }
    }

    fn push_sample(&mut self, s: Sample) -> Result<(), TimestampError> {
        if !s.pos.is_finite() {
            return Err(TimestampError::NotFinite);
        }
        if let Some(newest) = self.newest_time() {
            if s.t <= newest {
                return Err(TimestampError::NotMonotonic { time: s.t, newest });
            }
        }
        let mask = self.samples.len() - 1;
        if self.len == self.samples.len() {
            self.samples[self.start] = s;
            self.start = (self.start + 1) & mask;
        } else {
            self.samples[(self.start + self.len) & mask] = s;
            self.len += 1;
        }
        Ok(())
    }

    /// The position at event time `t_event` (DC ns since 2000, before dead-time correction).
    pub fn position_at(&self, t_event: i64) -> Result<f64, TimestampError> {
        self.estimate_at(t_event).map(|e| e.position)
    }

    /// The position at a 32-bit event time (unwrapped next to the newest sample).
    pub fn position_at_dc32(&self, t_event: u32) -> Result<f64, TimestampError> {
        self.estimate_at_dc32(t_event).map(|e| e.position)
    }

    /// [`estimate_at`](Self::estimate_at) for a 32-bit event time.
    pub fn estimate_at_dc32(&self, t_event: u32) -> Result<Estimate, TimestampError> {
        if self.is_empty() {
            return Err(TimestampError::Empty);
        }
        self.estimate_at(self.unwrap_dc32(t_event))
    }

    /// Position, error bound and method at event time `t_event` (DC ns since 2000, before
    /// dead-time correction).
    pub fn estimate_at(&self, t_event: i64) -> Result<Estimate, TimestampError> {
        if self.len == 0 {
            return Err(TimestampError::Empty);
        }
        let q = self.dead.query_time(t_event);
        let oldest = self.at(0).t;
        let last = self.len - 1;
        let newest = self.at(last).t;
        if q < oldest {
            return Err(TimestampError::TooOld { query: q, oldest });
        }
        if q > newest.saturating_add(self.cycle_ns) {
            return Err(TimestampError::TooNew {
                query: q,
                newest,
                cycle_ns: self.cycle_ns,
            });
        }
        // Largest k with t_k <= q (exists: q >= oldest).
        let (mut lo, mut hi) = (0usize, last);
        while lo < hi {
            let mid = lo + (hi - lo).div_ceil(2);
            if self.at(mid).t <= q {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        let k = lo;
        let s0 = self.at(k);
        if s0.t == q {
            return Ok(Estimate {
                position: s0.pos,
                error_bound: 0.0,
                method: Interpolation::Exact,
                query_time: q,
            });
        }
        if k == last {
            return Ok(self.extrapolate(k, q));
        }
        let s1 = self.at(k + 1);
        let h = secs(s1.t, s0.t);
        let x = secs(q, s0.t);
        let est = match (s0.vel, s1.vel) {
            (Some(v0), Some(v1)) if h > 0.0 => {
                let s = x / h;
                let s2 = s * s;
                let s3 = s2 * s;
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = s3 - 2.0 * s2 + s;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = s3 - s2;
                let a = ((v1 - v0) / h).abs();
                Estimate {
                    position: h00 * s0.pos + h10 * h * v0 + h01 * s1.pos + h11 * h * v1,
                    error_bound: a * h * h / 8.0,
                    method: Interpolation::Hermite,
                    query_time: q,
                }
            }
            _ => {
                let frac = if h > 0.0 { x / h } else { 0.0 };
                let a = self.local_accel(k);
                Estimate {
                    position: s0.pos + (s1.pos - s0.pos) * frac,
                    error_bound: a * h * h / 8.0,
                    method: Interpolation::Linear,
                    query_time: q,
                }
            }
        };
        Ok(est)
    }

    /// Extrapolate from sample `k` (the newest) to `q`, at most one cycle later.
    fn extrapolate(&self, k: usize, q: i64) -> Estimate {
        let sn = self.at(k);
        let dt = secs(q, sn.t);
        let a = if k >= 2 {
            self.second_difference(k - 1)
        } else {
            f64::INFINITY
        };
        let (position, error_bound) = match sn.vel {
            Some(v) => (sn.pos + v * dt, a * dt * dt / 2.0),
            None if k >= 1 => {
                let sp = self.at(k - 1);
                let h = secs(sn.t, sp.t);
                let slope = if h > 0.0 { (sn.pos - sp.pos) / h } else { 0.0 };
                (sn.pos + slope * dt, a * dt * (dt + h) / 2.0)
            }
            None => (sn.pos, f64::INFINITY),
        };
        Estimate {
            position,
            error_bound,
            method: Interpolation::Extrapolated,
            query_time: q,
        }
    }

    /// |acceleration| estimated around the interval (k, k+1): the larger of the second
    /// differences centred on k and k+1 that exist; infinite when none exists.
    fn local_accel(&self, k: usize) -> f64 {
        let mut a = f64::NEG_INFINITY;
        if k >= 1 {
            a = a.max(self.second_difference(k));
        }
        if k + 2 < self.len {
            a = a.max(self.second_difference(k + 1));
        }
        if a == f64::NEG_INFINITY {
            f64::INFINITY
        } else {
            a
        }
    }

    /// |second difference| centred on sample i (needs i−1 and i+1), in units/s².
    fn second_difference(&self, i: usize) -> f64 {
        let (a, b, c) = (self.at(i - 1), self.at(i), self.at(i + 1));
        let h0 = secs(b.t, a.t);
        let h1 = secs(c.t, b.t);
        if h0 <= 0.0 || h1 <= 0.0 {
            return f64::INFINITY;
        }
        let acc = 2.0 * ((c.pos - b.pos) / h1 - (b.pos - a.pos) / h0) / (h0 + h1);
        acc.abs()
    }
}

/// `(a − b)` in seconds, computed in i128 so that no DC time difference overflows.
#[inline]
fn secs(a: i64, b: i64) -> f64 {
    ((a as i128) - (b as i128)) as f64 / NS_PER_S
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capacity_is_power_of_two_and_at_least_32() {
        assert_eq!(
            TimestampBuffer::new(0, Nanos(1), DeadTimes::default()).capacity(),
            32
        );
        assert_eq!(
            TimestampBuffer::new(33, Nanos(1), DeadTimes::default()).capacity(),
            64
        );
        assert_eq!(
            TimestampBuffer::new(usize::MAX, Nanos(1), DeadTimes::default()).capacity(),
            MAX_CAPACITY
        );
    }

    #[test]
    fn ring_keeps_newest_samples() {
        let mut b = TimestampBuffer::new(32, Nanos(1_000), DeadTimes::default());
        for k in 0..100i64 {
            b.push(k * 1_000, k as f64).unwrap();
        }
        assert_eq!(b.len(), 32);
        assert_eq!(b.oldest_time(), Some(68_000));
        assert_eq!(b.position_at(70_500), Ok(70.5));
    }

    #[test]
    fn dc32_rule() {
        assert_eq!(dc32_diff(5, u32::MAX - 4), 10);
        assert_eq!(dc32_diff(u32::MAX - 4, 5), -10);
    }
}
