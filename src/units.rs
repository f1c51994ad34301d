//! Units and conversions.
//!
//! Internally every position is an `f64` in mm (linear axes) or degrees (rotary axes), every
//! velocity in mm/s (°/s) and every acceleration in mm/s² (°/s²). The seeds' parameter lists keep
//! their own units: positions in 0.1 µm (linear) and 0.0001° (rotary) — both a factor 10⁴ from
//! mm / ° — velocities in µm/s (0.001°/s), accelerations in mm/s² (°/s²). Values cross into the
//! core only through the functions here.
//!
//! Time is virtual: [`Nanos`] comes in as an argument; nothing in the library reads a clock.

use std::fmt;

/// Parameter position units per mm (or per degree): 0.1 µm resp. 0.0001° (seeds' "Dimension").
pub const PARAM_POS_PER_UNIT: f64 = 10_000.0;

/// Convert a parameter position (0.1 µm / 0.0001°) to mm / °.
#[inline]
pub fn param_pos_to_mm(value: i64) -> f64 {
    value as f64 / PARAM_POS_PER_UNIT
}

/// Convert mm / ° to parameter position units (0.1 µm / 0.0001°), rounded to the nearest unit.
#[inline]
pub fn mm_to_param_pos(mm: f64) -> f64 {
    (mm * PARAM_POS_PER_UNIT).round()
}

/// Convert a parameter velocity in µm/s (0.001°/s) to mm/s (°/s).
#[inline]
pub fn param_vel_to_mm_s(value: i64) -> f64 {
    value as f64 / 1000.0
}

/// Convert a programmed feed in mm/min (°/min) to mm/s (°/s).
#[inline]
pub fn feed_mm_min_to_mm_s(feed: f64) -> f64 {
    feed / 60.0
}

/// A point in virtual time, nanoseconds since the start of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Nanos(pub u64);

impl Nanos {
    /// Zero.
    pub const ZERO: Nanos = Nanos(0);

    /// From microseconds.
    pub const fn from_micros(us: u64) -> Self {
        Nanos(us * 1_000)
    }

    /// As seconds (f64).
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// Add a duration, saturating.
    pub fn saturating_add(self, d: Nanos) -> Nanos {
        Nanos(self.0.saturating_add(d.0))
    }
}

impl fmt::Display for Nanos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.6} s", self.as_secs_f64())
    }
}

/// Linear scaling between drive increments and axis units (mm or °).
///
/// `increments_per_unit` comes from the drive file in `drives/` (CiA 402 position factor
/// 0x6093 reduced to one number). Increments are the drive's `INTEGER32` position values
/// (0x607A, 0x6064, 0x60BA…); values that do not fit are reported, never wrapped silently.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scaling {
    /// Drive increments per mm (or per degree).
    pub increments_per_unit: f64,
    /// Axis position (mm / °) at drive increment 0.
    pub offset: f64,
}

impl Scaling {
    /// Increments → mm / °.
    #[inline]
    pub fn to_units(&self, inc: i32) -> f64 {
        inc as f64 / self.increments_per_unit + self.offset
    }

    /// Increment difference (e.g. following error 0x60F4) → mm / °.
    #[inline]
    pub fn delta_to_units(&self, inc: i32) -> f64 {
        inc as f64 / self.increments_per_unit
    }

    /// mm / ° → increments, or `None` when the value does not fit an `INTEGER32`.
    #[inline]
    pub fn to_increments(&self, units: f64) -> Option<i32> {
        let v = ((units - self.offset) * self.increments_per_unit).round();
        if v.is_finite() && v >= i32::MIN as f64 && v <= i32::MAX as f64 {
            Some(v as i32)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn param_units_are_exact_for_whole_units() {
        assert_eq!(param_pos_to_mm(2_000_000), 200.0);
        assert_eq!(param_pos_to_mm(-100_000_000), -10_000.0);
        assert_eq!(param_vel_to_mm_s(16_666), 16.666);
    }

    #[test]
    fn scaling_round_trip_and_overflow() {
        let s = Scaling {
            increments_per_unit: 10_000.0,
            offset: 0.0,
        };
        assert_eq!(s.to_increments(12.3456), Some(123_456));
        assert_eq!(s.to_units(123_456), 12.3456);
        assert_eq!(s.to_increments(1.0e6), None);
    }
}
