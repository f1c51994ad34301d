//! Fixed-stop detection for measurement type 7 (FCT-C4 §7.3 "Measurement run to fixed stop",
//! parameters §8.2.2 P-AXIS-00774 … 00778 with the fallbacks P-AXIS-00769 … 00773 and the old
//! P-AXIS-00331 / 00332).
//!
//! Criteria (§7.3 "Parameterisation of fixed stop detection"), each optional:
//! * **lag**: |position lag| > limit (P-AXIS-00774);
//! * **velocity**: the position changes by at most the window (P-AXIS-00778) within the minimum
//!   time (P-AXIS-00775) — "an average velocity … may not be exceeded".
//!
//! "The active criteria in each case must be fulfilled for a certain period [P-AXIS-00775]
//! before the fixed stop is considered to be detected"; when a criterion is violated, "counting
//! starts from the beginning" (P-AXIS-00332). Detection is activated only after the minimum path
//! in the measuring block (P-AXIS-00776 absolute, P-AXIS-00777 per mille of the block length;
//! the smaller, minimum over the axes). On gantry systems only the master axis is monitored.
//! The measured value is the actual position when the conditions are fulfilled (§7.3.1 CNC
//! step 3).
//!
//! # Velocity criterion without history
//!
//! The window criterion is evaluated against an *anchor*: the actual position at the start of
//! the current counting period. While |actual − anchor| ≤ window the period runs on; when the
//! position leaves the window the anchor moves to the current position and counting restarts.
//! Detection therefore needs the position to stay within the window for the whole minimum time,
//! i.e. an average velocity ≤ window / min time, in O(1) memory per axis.
//!
//! # Minimum path: "parameterised" means > 0 (project interpretation)
//!
//! The seed takes "the smaller of the two values" when both the absolute distance and the per
//! mille are parameterised. The absolute distance defaults to 0 and an inactive per mille also
//! means "activate at the block start", so if 0 counted as parameterised, P-AXIS-00777 could
//! never have an effect without P-AXIS-00776 > 0, although §7.3 offers them as alternatives
//! ("as an absolute value or as a percentage"). Therefore a distance takes part in the minimum
//! only when it is > 0; when neither is, detection starts at the block start.

use thiserror::Error;

use crate::messages::CncMessage;
use crate::params::{id, ParamSet};
use crate::units::{param_pos_to_mm, Nanos};

/// FCT-C4 §8.2.2 P-AXIS-00777: per mille > 1000 at controller start (warning, value kept).
pub const PER_MILLE_WARNING_ID: u32 = 110757;
/// FCT-C4 §8.2.2 P-AXIS-00777: per mille > 1000 at the start of a measuring travel (error,
/// program aborted).
pub const PER_MILLE_ERROR_ID: u32 = 51026;
/// Largest permitted per mille (P-AXIS-00777 / 00772 data range).
pub const MAX_PER_MILLE: i64 = 1000;

/// Which parameter a value came from (for diagnostics and tests).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Origin {
    /// The measuring-travel parameter (P-AXIS-00774 … 00778).
    Measure,
    /// The general fixed-stop parameter (P-AXIS-00769 … 00773).
    FixedStop,
    /// The old parameter (P-AXIS-00331 / 00332).
    Old,
    /// None applies: the documented default (criterion off, distance 0).
    Default,
}

/// Effective fixed-stop parameters of one axis, in mm / ° and ns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedStopParams {
    /// Lag limit; `None` = lag criterion off.
    pub lag_limit: Option<f64>,
    /// Where [`lag_limit`](Self::lag_limit) came from.
    pub lag_limit_origin: Origin,
    /// Minimum time the criteria must hold.
    pub min_time: Nanos,
    /// Where [`min_time`](Self::min_time) came from.
    pub min_time_origin: Origin,
    /// Absolute minimum path before detection is activated (≥ 0).
    pub start_distance: f64,
    /// Where [`start_distance`](Self::start_distance) came from.
    pub start_distance_origin: Origin,
    /// Minimum path in per mille of the block length; `None` = inactive. Values > 1000 are kept
    /// (warning 110757 at start, error 51026 at the measuring travel).
    pub start_per_mille: Option<i64>,
    /// Where [`start_per_mille`](Self::start_per_mille) came from.
    pub start_per_mille_origin: Origin,
    /// Maximum position change within the minimum time; `None` = velocity criterion off.
    pub max_delta_window: Option<f64>,
    /// Where [`max_delta_window`](Self::max_delta_window) came from.
    pub max_delta_window_origin: Origin,
}

/// Errors of fixed-stop parameterisation and detection start. `axis` is the index of the axis in
/// the list given to [`FixedStopDetector::new`]; [`FixedStopError::cnc_message`] turns every
/// variant into a message in words that names the axis and the parameters concerned.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum FixedStopError {
    /// The NC cycle is zero (P-AXIS-00332 counts cycles).
    #[error("the NC cycle time is 0, so the minimum time of fixed-stop detection (P-AXIS-00775 / P-AXIS-00332) cannot be evaluated")]
    ZeroCycle,
    /// Effective per mille > 1000 at the start of the measuring travel (ID 51026).
    #[error("axis {axis} of the measurement: minimum distance per mille {value} exceeds 1000 (P-AXIS-00777 / P-AXIS-00772)")]
    PerMilleTooLarge {
        /// Index of the axis in the detector's list.
        axis: usize,
        /// The effective value.
        value: i64,
    },
    /// A monitored axis has neither the lag nor the velocity criterion.
    #[error("axis {axis} of the measurement: no fixed-stop criterion parameterised (position lag limit P-AXIS-00774 and position window P-AXIS-00778 both off)")]
    NoCriterion {
        /// Index of the axis in the detector's list.
        axis: usize,
    },
    /// No axis is monitored (e.g. only gantry slaves).
    #[error("no axis of the fixed-stop measurement is monitored (only gantry slaves move)")]
    NoMonitoredAxis,
    /// The block length is negative or not finite.
    #[error("the measuring block length {0} mm is not a finite distance ≥ 0")]
    InvalidBlockLength(f64),
}

impl FixedStopError {
    /// The CNC message: 51026 for [`FixedStopError::PerMilleTooLarge`]; `None` for errors the
    /// seed gives no ID (the channel reports them under its own ID, see
    /// [`cnc_message`](Self::cnc_message)).
    pub fn message(&self, axis_name: &str) -> Option<CncMessage> {
        match *self {
            FixedStopError::PerMilleTooLarge { value, .. } => {
                Some(per_mille_error(axis_name, value))
            }
            _ => None,
        }
    }

    /// Every variant as a CNC error in words: 51026 (FCT-C4 §8.2.2) for a per mille above
    /// 1000, `config_id` (the caller's ID for a measuring block that may not run) for the others.
    /// `axis_names` are the names of the detector's axes in list order; the message names the
    /// axis concerned (or, without one, every axis of the measurement) and the parameters.
    pub fn cnc_message(&self, config_id: u32, axis_names: &[&str]) -> CncMessage {
        let name = |i: usize| axis_names.get(i).copied().unwrap_or("?");
        match *self {
            FixedStopError::PerMilleTooLarge { axis, value } => per_mille_error(name(axis), value),
            FixedStopError::NoCriterion { axis } => CncMessage::error(
                config_id,
                format!(
                    "measuring travel to fixed stop: axis {} has no fixed-stop criterion: the \
                     position lag limit (P-AXIS-00774, or P-AXIS-00769 / P-AXIS-00331 when it is \
                     < 0) and the position window (P-AXIS-00778, or P-AXIS-00773 when it is < 0) \
                     are both off; set P-AXIS-00774 > 0 or P-AXIS-00778 ≥ 0 (seed 004 §7.3)",
                    name(axis)
                ),
            )
            .on_axis(name(axis)),
            FixedStopError::NoMonitoredAxis => CncMessage::error(
                config_id,
                format!(
                    "measuring travel to fixed stop: none of the axes {} is monitored for the \
                     stop (gantry slaves are not; the master axis must move, seed 004 §7.3)",
                    axis_names.join(", ")
                ),
            ),
            FixedStopError::InvalidBlockLength(len) => CncMessage::error(
                config_id,
                format!(
                    "measuring travel to fixed stop: the measuring block length {len} mm is not a \
                     finite distance ≥ 0"
                ),
            ),
            FixedStopError::ZeroCycle => CncMessage::error(
                config_id,
                "measuring travel to fixed stop: the NC cycle time is 0, so the minimum time of \
                 fixed-stop detection (P-AXIS-00775 µs, or P-AXIS-00332 cycles) cannot be evaluated",
            ),
        }
    }
}

/// Warning 110757: per mille > 1000 at controller start (FCT-C4 §8.2.2 P-AXIS-00777; the value
/// is not corrected).
pub fn per_mille_warning(axis_name: &str, value: i64) -> CncMessage {
    CncMessage::warning(
        PER_MILLE_WARNING_ID,
        format!(
            "fixed stop detection: axis {axis_name}: minimum distance per mille {value} exceeds \
             1000 (P-AXIS-00777 / P-AXIS-00772); value not corrected"
        ),
    )
    .on_axis(axis_name)
}

/// Error 51026: per mille > 1000 at the start of a measuring travel; the program is aborted
/// (FCT-C4 §8.2.2 P-AXIS-00777).
pub fn per_mille_error(axis_name: &str, value: i64) -> CncMessage {
    CncMessage::error(
        PER_MILLE_ERROR_ID,
        format!(
            "measuring travel to fixed stop: axis {axis_name}: minimum distance per mille {value} \
             exceeds 1000 (check P-AXIS-00777 and, if it is < 0, P-AXIS-00772)"
        ),
    )
    .on_axis(axis_name)
}

impl FixedStopParams {
    /// Parameters with every criterion off (for axes that are not monitored).
    pub fn inactive() -> FixedStopParams {
        FixedStopParams {
            lag_limit: None,
            lag_limit_origin: Origin::Default,
            min_time: Nanos::ZERO,
            min_time_origin: Origin::Default,
            start_distance: 0.0,
            start_distance_origin: Origin::Default,
            start_per_mille: None,
            start_per_mille_origin: Origin::Default,
            max_delta_window: None,
            max_delta_window_origin: Origin::Default,
        }
    }

    /// The effective parameters of one axis, with the fallback chains of FCT-C4 §8.2.2:
    /// * lag limit P-AXIS-00774: 0 = off; < 0 → P-AXIS-00769 if > 0, else P-AXIS-00331
    ///   (0 = off);
    /// * min time P-AXIS-00775 µs: 0 → P-AXIS-00770 µs if > 0, else P-AXIS-00332 × `cycle`;
    /// * start distance P-AXIS-00776: < 0 → P-AXIS-00771 if ≥ 0, else 0;
    /// * per mille P-AXIS-00777: < 0 → P-AXIS-00772 if ≥ 0, else inactive;
    /// * position window P-AXIS-00778: < 0 → P-AXIS-00773 if ≥ 0, else velocity criterion off.
    ///
    /// Positions are converted from 0.1 µm / 0.0001° to mm / °.
    pub fn from_params(p: &ParamSet, cycle: Nanos) -> Result<FixedStopParams, FixedStopError> {
        if cycle.0 == 0 {
            return Err(FixedStopError::ZeroCycle);
        }
        let (lag_limit, lag_limit_origin) = {
            let v = p.int(id::MEAS_FS_POS_LAG_LIMIT);
            if v > 0 {
                (Some(param_pos_to_mm(v)), Origin::Measure)
            } else if v == 0 {
                (None, Origin::Measure)
            } else {
                let fs = p.int(id::FS_POS_LAG_LIMIT);
                if fs > 0 {
                    (Some(param_pos_to_mm(fs)), Origin::FixedStop)
                } else {
                    let old = p.int(id::FIXED_STOP_POS_LAG_LIMIT);
                    ((old > 0).then(|| param_pos_to_mm(old)), Origin::Old)
                }
            }
        };
        let (min_time, min_time_origin) = {
            let v = p.int(id::MEAS_FS_MIN_TIME);
            let fs = p.int(id::FS_MIN_TIME);
            if v > 0 {
                (micros(v), Origin::Measure)
            } else if fs > 0 {
                (micros(fs), Origin::FixedStop)
            } else {
                let cycles = p.int(id::FIXED_STOP_NBR_CYCLES).max(0) as u64;
                (Nanos(cycles.saturating_mul(cycle.0)), Origin::Old)
            }
        };
        let (start_distance, start_distance_origin) = {
            let v = p.int(id::MEAS_FS_START_DISTANCE);
            let fs = p.int(id::FS_START_DISTANCE);
            if v >= 0 {
                (param_pos_to_mm(v), Origin::Measure)
            } else if fs >= 0 {
                (param_pos_to_mm(fs), Origin::FixedStop)
            } else {
                (0.0, Origin::Default)
            }
        };
        let (start_per_mille, start_per_mille_origin) = {
            let v = p.int(id::MEAS_FS_START_DISTANCE_PER_MILLE);
            let fs = p.int(id::FS_START_DISTANCE_PER_MILLE);
            if v >= 0 {
                (Some(v), Origin::Measure)
            } else if fs >= 0 {
                (Some(fs), Origin::FixedStop)
            } else {
                (None, Origin::Default)
            }
        };
        let (max_delta_window, max_delta_window_origin) = {
            let v = p.int(id::MEAS_FS_MAX_DELTA_POSITION_WINDOW);
            let fs = p.int(id::FS_MAX_DELTA_POSITION_WINDOW);
            if v >= 0 {
                (Some(param_pos_to_mm(v)), Origin::Measure)
            } else if fs >= 0 {
                (Some(param_pos_to_mm(fs)), Origin::FixedStop)
            } else {
                (None, Origin::Default)
            }
        };
        Ok(FixedStopParams {
            lag_limit,
            lag_limit_origin,
            min_time,
            min_time_origin,
            start_distance,
            start_distance_origin,
            start_per_mille,
            start_per_mille_origin,
            max_delta_window,
            max_delta_window_origin,
        })
    }

    /// Warning 110757 at controller start when the effective per mille exceeds 1000.
    pub fn startup_warning(&self, axis_name: &str) -> Option<CncMessage> {
        match self.start_per_mille {
            Some(v) if v > MAX_PER_MILLE => Some(per_mille_warning(axis_name, v)),
            _ => None,
        }
    }

    /// Error 51026 at the start of a measuring travel when the effective per mille exceeds 1000.
    pub fn check_measuring_start(&self, axis_name: &str) -> Result<(), CncMessage> {
        match self.start_per_mille {
            Some(v) if v > MAX_PER_MILLE => Err(per_mille_error(axis_name, v)),
            _ => Ok(()),
        }
    }

    /// At least one criterion is active.
    pub fn has_criterion(&self) -> bool {
        self.lag_limit.is_some() || self.max_delta_window.is_some()
    }

    /// Path after which detection is activated in a block of `block_length` (see the module
    /// documentation: the smaller of the distances that are > 0, else 0).
    pub fn activation_distance(&self, block_length: f64) -> f64 {
        let abs = (self.start_distance > 0.0).then_some(self.start_distance);
        let rel = match self.start_per_mille {
            Some(pm) if pm > 0 => Some(pm as f64 / 1000.0 * block_length.max(0.0)),
            _ => None,
        };
        match (abs, rel) {
            (Some(a), Some(r)) => a.min(r),
            (Some(a), None) => a,
            (None, Some(r)) => r,
            (None, None) => 0.0,
        }
    }
}

fn micros(us: i64) -> Nanos {
    Nanos((us.max(0) as u64).saturating_mul(1_000))
}

/// One axis taking part in a fixed-stop measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedStopAxis {
    /// Its effective parameters.
    pub params: FixedStopParams,
    /// Monitored: `false` for gantry slave axes (FCT-C4 §7.3: "the master axis is always used
    /// for measuring").
    pub monitored: bool,
}

/// A detected fixed stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detected {
    /// Index of the axis in the detector's list.
    pub axis: usize,
    /// Actual position when the conditions were fulfilled (the measured value).
    pub position: f64,
    /// When.
    pub at: Nanos,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct AxisState {
    axis: FixedStopAxis,
    /// Start of the current counting period and the anchor position.
    since: Option<(Nanos, f64)>,
}

/// Per-cycle fixed-stop detection over the axes of one measuring block (FCT-C4 §7.3).
/// Allocates in [`new`](Self::new) only.
#[derive(Debug, Clone, PartialEq)]
pub struct FixedStopDetector {
    axes: Vec<AxisState>,
    activation: f64,
    detected: Option<Detected>,
}

impl FixedStopDetector {
    /// Start of the measuring travel: checks every axis (per mille ≤ 1000 → else
    /// [`FixedStopError::PerMilleTooLarge`], ID 51026; a monitored axis needs a criterion) and
    /// computes the activation distance (minimum over the axes).
    pub fn new(axes: &[FixedStopAxis], block_length: f64) -> Result<Self, FixedStopError> {
        if !block_length.is_finite() || block_length < 0.0 {
            return Err(FixedStopError::InvalidBlockLength(block_length));
        }
        for (i, a) in axes.iter().enumerate().filter(|(_, a)| a.monitored) {
            if let Some(v) = a.params.start_per_mille.filter(|v| *v > MAX_PER_MILLE) {
                return Err(FixedStopError::PerMilleTooLarge { axis: i, value: v });
            }
            if !a.params.has_criterion() {
                return Err(FixedStopError::NoCriterion { axis: i });
            }
        }
        if !axes.iter().any(|a| a.monitored) {
            return Err(FixedStopError::NoMonitoredAxis);
        }
        // "When measuring with several axes, the smallest block motion path of all axes involved
        // in the measurement is used" — the axes watched for the stop (§8.2.2 P-AXIS-00776).
        let activation = axes
            .iter()
            .filter(|a| a.monitored)
            .map(|a| a.params.activation_distance(block_length))
            .fold(f64::INFINITY, f64::min);
        Ok(FixedStopDetector {
            axes: axes
                .iter()
                .map(|&axis| AxisState { axis, since: None })
                .collect(),
            activation,
            detected: None,
        })
    }

    /// Path in the block after which detection is active.
    pub fn activation_distance(&self) -> f64 {
        self.activation
    }

    /// The detection, once made.
    pub fn detected(&self) -> Option<Detected> {
        self.detected
    }

    /// One cycle of one axis: `travelled` = path travelled in the measuring block so far,
    /// `lag` = position lag (command − actual), `actual` = actual position. Returns the
    /// detection once (the first axis that fulfils the conditions ends the run); unmonitored
    /// axes, unknown indices and non-finite inputs never detect (non-finite inputs restart
    /// counting).
    pub fn update(
        &mut self,
        now: Nanos,
        axis: usize,
        travelled: f64,
        lag: f64,
        actual: f64,
    ) -> Option<Detected> {
        if self.detected.is_some() {
            return None;
        }
        let activation = self.activation;
        let st = self.axes.get_mut(axis)?;
        if !st.axis.monitored {
            return None;
        }
        if !(travelled.is_finite() && lag.is_finite() && actual.is_finite())
            || travelled < activation
        {
            st.since = None;
            return None;
        }
        let p = &st.axis.params;
        if let Some(limit) = p.lag_limit {
            if lag.abs() <= limit {
                st.since = None;
                return None;
            }
        }
        let (start, anchor) = match st.since {
            Some((t, x)) => match p.max_delta_window {
                Some(w) if (actual - x).abs() > w => (now, actual),
                _ => (t, x),
            },
            None => (now, actual),
        };
        st.since = Some((start, anchor));
        if now.0.saturating_sub(start.0) >= p.min_time.0 {
            let d = Detected {
                axis,
                position: actual,
                at: now,
            };
            self.detected = Some(d);
            return Some(d);
        }
        None
    }
}
