//! Software limit switches (FCT-A2, FCT-A2).
//!
//! [`SoftLimits`] holds, per axis, the configured limits (P-AXIS-00177 / P-AXIS-00178), the
//! active (programmed, G98 / G99) limits and the monitoring state. It answers four questions,
//! each at its point of the interpolation cycle ([`crate::channel`]):
//!
//! | question | method | seed |
//! |---|---|---|
//! | may this block's command path run? | [`SoftLimits::check_path`] | §2 P-ERR-120002 / 120003 |
//! | is the actual position beyond limit ± tolerance? | [`SoftLimits::check_actual`] | §2 P-ERR-70021 / 70022, P-AXIS-00179 |
//! | can the axis still stop before the limit? | [`SoftLimits::check_stop_distance`] | §4.3 P-AXIS-00520 / 00521, P-ERR-70195 |
//! | what does G98 / G99 set? | [`SoftLimits::program_limit`] | §3 P-ERR-21648 / 21649 / 21650 / 21878 |
//!
//! plus the manual-mode range ([`SoftLimits::jog_range`], §2 and §3.3) and the PCS display of
//! P-CHAN-00489 ([`SoftLimits::pcs_limits`], §2.1).
//!
//! Interpretations where the seed is silent are listed in `docs/interpretations.md`; the ones that
//! matter most: 120002 / 70021 are the positive side and 120003 / 70022 the negative side (the
//! seed pairs 70021 with G99 and 70022 with G98); 21649 / 21878 compare against the *active*
//! opposite limit, since §3.3 allows the opposite limit to have been moved; a block that starts
//! beyond a limit (possible after ERROR_LR / WARNING) may move back towards the valid range.
//!
//! Nothing here allocates or reads a clock in the per-cycle checks.

use crate::core::path::Segment;
use crate::messages::{ids, CncMessage, Severity};

/// Comparison slack for command positions in mm (or °): 1 nm. Command positions are checked
/// "exactly" (FCT-A2 §2); the slack only absorbs the rounding of arc extents computed in f64,
/// so that an arc whose apex lies exactly on the limit is accepted, as the seed permits moving
/// to the limit itself.
pub const COMMAND_EPSILON: f64 = 1e-6;

/// P-AXIS-00554 `kenngr.swe_behaviour`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SlsBehaviour {
    /// `ERROR`: error already in path preparation (default).
    #[default]
    Error,
    /// `ERROR_LR`: warning in path preparation, error in the position controller.
    ErrorLr,
    /// `WARNING`: only warnings, in path preparation and in the position controller.
    Warning,
}

impl SlsBehaviour {
    /// Parse the parameter text (`ERROR`, `ERROR_LR`, `WARNING`).
    pub fn from_param(text: &str) -> Option<Self> {
        match text.trim().to_ascii_uppercase().as_str() {
            "ERROR" | "" => Some(SlsBehaviour::Error),
            "ERROR_LR" => Some(SlsBehaviour::ErrorLr),
            "WARNING" => Some(SlsBehaviour::Warning),
            _ => None,
        }
    }

    /// Severity of a command-side (path preparation) violation.
    pub fn preparation_severity(self) -> Severity {
        match self {
            SlsBehaviour::Error => Severity::Error,
            SlsBehaviour::ErrorLr | SlsBehaviour::Warning => Severity::Warning,
        }
    }

    /// Severity of an actual-side (position controller) violation.
    pub fn controller_severity(self) -> Severity {
        match self {
            SlsBehaviour::Error | SlsBehaviour::ErrorLr => Severity::Error,
            SlsBehaviour::Warning => Severity::Warning,
        }
    }
}

/// Which limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// Negative SLS (P-AXIS-00177, G98).
    Negative,
    /// Positive SLS (P-AXIS-00178, G99).
    Positive,
}

impl Side {
    fn word(self) -> &'static str {
        match self {
            Side::Negative => "negative",
            Side::Positive => "positive",
        }
    }
}

/// Per-axis configuration, in mm (°) and mm/s² (°/s²), built from the axis parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisLimitConfig {
    /// Axis name (for messages).
    pub name: String,
    /// P-AXIS-00177 `kenngr.swe_neg`.
    pub neg: f64,
    /// P-AXIS-00178 `kenngr.swe_pos`.
    pub pos: f64,
    /// P-AXIS-00179 `kenngr.swe_toleranz`.
    pub tolerance: f64,
    /// P-AXIS-00554 `kenngr.swe_behaviour`.
    pub behaviour: SlsBehaviour,
    /// P-AXIS-00705 `kenngr.swe_check`: −1 by axis type / mode, 0 off, 1 on.
    pub check: i8,
    /// Rotary axis operated as modulo axis (P-AXIS-00018 / P-AXIS-00015): exempt unless
    /// P-AXIS-00705 = 1.
    pub modulo: bool,
    /// P-AXIS-00014 `kenngr.abs_pos_gueltig`: absolute measuring system, no homing needed.
    pub absolute_encoder: bool,
    /// P-AXIS-00520 `lr_param.check_pos_command_limit` (translatory axes only).
    pub check_pos_command: bool,
    /// P-AXIS-00521 `lr_param.check_neg_command_limit` (translatory axes only).
    pub check_neg_command: bool,
    /// P-AXIS-00003 `getriebe[i].dynamik.a_emergency`, the deceleration of the stop-distance check.
    pub emergency_decel: f64,
    /// P-AXIS-00137 `handbetrieb.offsetgrenze_neg` (≤ 0, relative to the position at manual mode
    /// selection).
    pub manual_rel_neg: f64,
    /// P-AXIS-00138 `handbetrieb.offsetgrenze_pos` (≥ 0).
    pub manual_rel_pos: f64,
    /// P-AXIS-00492 absolute negative offset limit in manual mode; 0 = not used.
    pub manual_abs_neg: f64,
    /// P-AXIS-00493 absolute positive offset limit in manual mode; 0 = not used.
    pub manual_abs_pos: f64,
}

impl AxisLimitConfig {
    /// A linear axis with the given limits and the seeds' defaults for the rest.
    pub fn linear(name: &str, neg: f64, pos: f64) -> Self {
        AxisLimitConfig {
            name: name.to_string(),
            neg,
            pos,
            tolerance: 0.1,
            behaviour: SlsBehaviour::Error,
            check: -1,
            modulo: false,
            absolute_encoder: false,
            check_pos_command: false,
            check_neg_command: false,
            emergency_decel: 1000.0,
            manual_rel_neg: -100.0,
            manual_rel_pos: 100.0,
            manual_abs_neg: 0.0,
            manual_abs_pos: 0.0,
        }
    }
}

/// A limit violation found by a check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Violation {
    /// Axis index in the channel.
    pub axis: usize,
    /// Which limit.
    pub side: Side,
    /// The limit that was violated (mm / °), including the tolerance where it applies.
    pub limit: f64,
    /// The offending position.
    pub position: f64,
}

#[derive(Debug, Clone)]
struct AxisLimits {
    cfg: AxisLimitConfig,
    /// Active limits (G98 / G99, V.A.-SWE / V.A.+SWE).
    neg: f64,
    pos: f64,
    referenced: bool,
    /// Actual-side violation currently latched (a warning is given once per excursion).
    actual_latched: Option<Side>,
}

/// Result of a G98 / G99 assignment.
#[derive(Debug, Clone, PartialEq)]
pub struct LimitUpdate {
    /// Messages (21648 / 21649 / 21650 / 21878 / 70021 / 70022) in order.
    pub messages: Vec<CncMessage>,
    /// Whether the new value was taken over.
    pub taken_over: bool,
}

/// Software-limit-switch state of one channel.
#[derive(Debug, Clone)]
pub struct SoftLimits {
    axes: Vec<AxisLimits>,
    /// P-CHAN-00498 `range_check_prog_soft_limits`.
    range_check_programmed: bool,
}

impl SoftLimits {
    /// New monitor. `range_check_programmed` is P-CHAN-00498.
    pub fn new(configs: Vec<AxisLimitConfig>, range_check_programmed: bool) -> Self {
        let axes = configs
            .into_iter()
            .map(|cfg| AxisLimits {
                neg: cfg.neg,
                pos: cfg.pos,
                referenced: false,
                actual_latched: None,
                cfg,
            })
            .collect();
        SoftLimits {
            axes,
            range_check_programmed,
        }
    }

    /// Number of axes.
    pub fn len(&self) -> usize {
        self.axes.len()
    }

    /// True when there are no axes.
    pub fn is_empty(&self) -> bool {
        self.axes.is_empty()
    }

    /// Configuration of axis `i`.
    pub fn config(&self, i: usize) -> Option<&AxisLimitConfig> {
        self.axes.get(i).map(|a| &a.cfg)
    }

    /// Mark axis `i` referenced (G74 done) or not.
    pub fn set_referenced(&mut self, i: usize, referenced: bool) {
        if let Some(a) = self.axes.get_mut(i) {
            a.referenced = referenced;
        }
    }

    /// Whether SLS monitoring is effective for axis `i` (FCT-A2 §1, §2 "Activation",
    /// P-AXIS-00705): referenced or absolute encoder, and not a modulo axis unless forced on.
    pub fn is_active(&self, i: usize) -> bool {
        self.axes.get(i).is_some_and(axis_active)
    }

    /// Active (programmed) limits of axis `i`: (negative, positive). These are the values of
    /// `V.A.-SWE.<ax>` and `V.A.+SWE.<ax>`.
    pub fn active_limits(&self, i: usize) -> Option<(f64, f64)> {
        self.axes.get(i).map(|a| (a.neg, a.pos))
    }

    /// Restore the configured limits (reset, mode change, program start; FCT-A2 §3.3) and clear
    /// latched violations.
    pub fn reset(&mut self) {
        for a in &mut self.axes {
            a.neg = a.cfg.neg;
            a.pos = a.cfg.pos;
            a.actual_latched = None;
        }
    }

    /// Block preparation: check a block's command path against the active limits (FCT-A2 §2,
    /// "Command positions are checked for exact compliance with the SLS").
    ///
    /// Every point of the path counts, including the extremes of arcs between in-range end points
    /// ([`Segment::extent`]). A path that starts beyond a limit may move back towards the valid
    /// range; it violates only if it goes further out than its start. Violations are written into
    /// `out` (cleared first); the caller turns them into messages by the axis's behaviour.
    pub fn check_path(&self, path: &Segment, out: &mut Vec<Violation>) {
        out.clear();
        let start = path.start();
        for (i, a) in self.axes.iter().enumerate() {
            if i >= path.dims() || !axis_active(a) {
                continue;
            }
            let (lo, hi) = path.extent(i);
            let s = start[i];
            if hi > a.pos.max(s) + COMMAND_EPSILON {
                out.push(Violation {
                    axis: i,
                    side: Side::Positive,
                    limit: a.pos,
                    position: hi,
                });
            }
            if lo < a.neg.min(s) - COMMAND_EPSILON {
                out.push(Violation {
                    axis: i,
                    side: Side::Negative,
                    limit: a.neg,
                    position: lo,
                });
            }
        }
    }

    /// Check a single command point (e.g. a jog target) against the active limits.
    pub fn check_point(&self, i: usize, position: f64) -> Option<Violation> {
        let a = self.axes.get(i)?;
        if !axis_active(a) {
            return None;
        }
        if position > a.pos + COMMAND_EPSILON {
            Some(Violation {
                axis: i,
                side: Side::Positive,
                limit: a.pos,
                position,
            })
        } else if position < a.neg - COMMAND_EPSILON {
            Some(Violation {
                axis: i,
                side: Side::Negative,
                limit: a.neg,
                position,
            })
        } else {
            None
        }
    }

    /// The message for a command-side violation (P-ERR-120002 / 120003) with the axis's
    /// behaviour (P-AXIS-00554).
    pub fn path_message(&self, v: &Violation) -> CncMessage {
        let (name, severity) = match self.axes.get(v.axis) {
            Some(a) => (a.cfg.name.as_str(), a.cfg.behaviour.preparation_severity()),
            None => ("?", Severity::Error),
        };
        let id = match v.side {
            Side::Positive => ids::COMMAND_POSITIVE_SLS,
            Side::Negative => ids::COMMAND_NEGATIVE_SLS,
        };
        CncMessage::new(
            id,
            severity,
            format!(
                "command position of axis {name} reaches {:.6}, beyond the {} software limit switch {:.6}",
                v.position,
                v.side.word(),
                v.limit
            ),
        )
        .on_axis(name)
    }

    /// Position controller, every cycle: the actual position against limit ± P-AXIS-00179
    /// (FCT-A2 §2, P-ERR-70021 / 70022).
    ///
    /// Returns the message when a violation begins. For ERROR and ERROR_LR the message is an
    /// error (the caller stops interpolation and decelerates); for WARNING a warning, given once
    /// per excursion and re-armed when the axis is back inside.
    #[inline]
    pub fn check_actual(&mut self, i: usize, actual: f64) -> Option<CncMessage> {
        let a = self.axes.get_mut(i)?;
        if !axis_active(a) {
            return None;
        }
        let side = if actual > a.pos + a.cfg.tolerance {
            Side::Positive
        } else if actual < a.neg - a.cfg.tolerance {
            Side::Negative
        } else {
            a.actual_latched = None;
            return None;
        };
        if a.actual_latched == Some(side) {
            return None;
        }
        a.actual_latched = Some(side);
        Some(actual_message(a, side, actual))
    }

    /// Fast form of [`check_actual`](Self::check_actual) for benchmarks and the per-cycle loop:
    /// returns only whether axis `i` is currently beyond its tolerance band.
    #[inline]
    pub fn actual_outside(&self, i: usize, actual: f64) -> bool {
        match self.axes.get(i) {
            Some(a) if axis_active(a) => {
                actual > a.pos + a.cfg.tolerance || actual < a.neg - a.cfg.tolerance
            }
            _ => false,
        }
    }

    /// Command-side stop-distance check (P-AXIS-00520 / 00521, FCT-A2 §4.3): can axis `i`,
    /// at command position `position` moving with `velocity`, still stop before the active limit
    /// (without tolerance) when decelerating with P-AXIS-00003? Returns the side that can no
    /// longer be kept, if that side's check is enabled and monitoring is active.
    #[inline]
    pub fn check_stop_distance(&self, i: usize, position: f64, velocity: f64) -> Option<Side> {
        let a = self.axes.get(i)?;
        if !axis_active(a) || !(a.cfg.check_pos_command || a.cfg.check_neg_command) {
            return None;
        }
        let decel = a.cfg.emergency_decel.max(1e-9);
        let stop = velocity * velocity / (2.0 * decel);
        if a.cfg.check_pos_command && velocity > 0.0 && position + stop > a.pos + COMMAND_EPSILON {
            return Some(Side::Positive);
        }
        if a.cfg.check_neg_command && velocity < 0.0 && position - stop < a.neg - COMMAND_EPSILON {
            return Some(Side::Negative);
        }
        None
    }

    /// The P-ERR-70195 message for a stop-distance violation.
    pub fn stop_distance_message(&self, i: usize, side: Side) -> CncMessage {
        let (name, limit) = match self.axes.get(i) {
            Some(a) => (
                a.cfg.name.as_str(),
                if side == Side::Positive { a.pos } else { a.neg },
            ),
            None => ("?", 0.0),
        };
        CncMessage::error(
            ids::COMMAND_STOP_DISTANCE,
            format!(
                "axis {name} cannot stop before the {} software limit switch {limit:.6} with the emergency deceleration (P-AXIS-00003); axis stopped",
                side.word()
            ),
        )
        .on_axis(name)
    }

    /// G98 (`side` = Negative) or G99 (Positive) for axis `i` (FCT-A2 §3.1–3.3).
    ///
    /// `value` is the programmed value; with `relative` (G91) it is added to the configured
    /// limit P-AXIS-00177 / 00178, as the seed says. `actual` is the axis's current actual
    /// position, checked against the new limit ± tolerance (70021 / 70022: the new limit is taken
    /// over and the error raised).
    pub fn program_limit(
        &mut self,
        i: usize,
        side: Side,
        value: f64,
        relative: bool,
        actual: f64,
    ) -> LimitUpdate {
        let range_check = self.range_check_programmed;
        let Some(a) = self.axes.get_mut(i) else {
            return LimitUpdate {
                messages: Vec::new(),
                taken_over: false,
            };
        };
        let name = a.cfg.name.clone();
        let mut messages = Vec::new();
        let configured = match side {
            Side::Negative => a.cfg.neg,
            Side::Positive => a.cfg.pos,
        };
        let new = if relative { configured + value } else { value };
        let taken_over = match side {
            Side::Negative => {
                if new >= a.pos {
                    messages.push(
                        CncMessage::error(
                            ids::G98_NOT_BELOW_POSITIVE,
                            format!(
                                "G98: negative software limit switch {new:.6} of axis {name} is not below the positive software limit switch {:.6}; not taken over",
                                a.pos
                            ),
                        )
                        .on_axis(&name),
                    );
                    false
                } else if range_check && new < a.cfg.neg {
                    messages.push(
                        CncMessage::warning(
                            ids::G98_BELOW_CONFIGURED,
                            format!(
                                "G98: negative software limit switch {new:.6} of axis {name} is below P-AXIS-00177 {:.6}; P-AXIS-00177 stays in force",
                                a.cfg.neg
                            ),
                        )
                        .on_axis(&name),
                    );
                    a.neg = a.cfg.neg;
                    false
                } else {
                    a.neg = new;
                    true
                }
            }
            Side::Positive => {
                if new <= a.neg {
                    messages.push(
                        CncMessage::error(
                            ids::G99_NOT_ABOVE_NEGATIVE,
                            format!(
                                "G99: positive software limit switch {new:.6} of axis {name} is not above the negative software limit switch {:.6}; not taken over",
                                a.neg
                            ),
                        )
                        .on_axis(&name),
                    );
                    false
                } else if range_check && new > a.cfg.pos {
                    messages.push(
                        CncMessage::warning(
                            ids::G99_ABOVE_CONFIGURED,
                            format!(
                                "G99: positive software limit switch {new:.6} of axis {name} is above P-AXIS-00178 {:.6}; P-AXIS-00178 stays in force",
                                a.cfg.pos
                            ),
                        )
                        .on_axis(&name),
                    );
                    a.pos = a.cfg.pos;
                    false
                } else {
                    a.pos = new;
                    true
                }
            }
        };
        if taken_over {
            if let Some(a) = self.axes.get_mut(i) {
                a.actual_latched = None;
            }
            if let Some(m) = self.check_actual(i, actual) {
                messages.push(m);
            }
        }
        LimitUpdate {
            messages,
            taken_over,
        }
    }

    /// Manual-mode range of axis `i` (FCT-A2 §2 "Manual mode", §3.3): referenced axes are
    /// limited by the active SLS; in addition the relative offset limits P-AXIS-00137 / 00138
    /// around `start` (the position when manual mode was selected; inactive when both are 0)
    /// and the absolute offset limits P-AXIS-00492 / 00493 (each only when ≠ 0) apply. A
    /// non-referenced axis is limited by the offset limits only. Returns (low, high); infinite
    /// where nothing limits.
    pub fn jog_range(&self, i: usize, start: f64) -> (f64, f64) {
        let Some(a) = self.axes.get(i) else {
            return (f64::NEG_INFINITY, f64::INFINITY);
        };
        let (mut lo, mut hi) = if axis_active(a) {
            (a.neg, a.pos)
        } else {
            (f64::NEG_INFINITY, f64::INFINITY)
        };
        if a.cfg.manual_rel_neg != 0.0 || a.cfg.manual_rel_pos != 0.0 {
            lo = lo.max(start + a.cfg.manual_rel_neg);
            hi = hi.min(start + a.cfg.manual_rel_pos);
        }
        if a.cfg.manual_abs_neg != 0.0 {
            lo = lo.max(a.cfg.manual_abs_neg);
        }
        if a.cfg.manual_abs_pos != 0.0 {
            hi = hi.min(a.cfg.manual_abs_pos);
        }
        (lo, hi)
    }

    /// How far the point `acs` may move along the direction `dir` (ACS, one entry per axis; a
    /// unit vector when `s` is to be a distance) before an active limit is reached: the interval
    /// `(s_min, s_max)` of all `s` with `neg ≤ acs + s·dir ≤ pos` on every axis whose monitoring
    /// is active and whose share of `dir` is not zero (|share| > 1e-12: the 6e-17 of cos 90° is
    /// none). `None` when no active limit lies on the line. For P-CHAN-00489 with `#CS`, where a
    /// PCS axis may run along another ACS axis or obliquely (FCT-A2 §2.1). `s_min > s_max`
    /// when the point lies outside the range on an axis the line crosses.
    pub fn range_along(&self, acs: &[f64], dir: &[f64]) -> Option<(f64, f64)> {
        let mut range: Option<(f64, f64)> = None;
        for ((a, &p), &d) in self.axes.iter().zip(acs).zip(dir) {
            if d.abs() <= 1e-12 || !axis_active(a) {
                continue;
            }
            let (s1, s2) = ((a.neg - p) / d, (a.pos - p) / d);
            let (lo, hi) = (s1.min(s2), s1.max(s2));
            range = Some(match range {
                Some((l, h)) => (l.max(lo), h.min(hi)),
                None => (lo, hi),
            });
        }
        range
    }

    /// P-CHAN-00489 in 2.5D: the active limits of axis `i` in the programming coordinate system,
    /// given the PCS → ACS offset of the axis (`acs = pcs + offset`, G92 / G54) and the current
    /// PCS position. `None` when monitoring is not active for the axis (no limit to display).
    /// With `#CS` the channel uses [`SoftLimits::range_along`] (`Channel::pcs_limits`).
    pub fn pcs_limits(&self, i: usize, offset: f64, pcs_position: f64) -> Option<PcsLimits> {
        let a = self.axes.get(i)?;
        if !axis_active(a) {
            return None;
        }
        let positive = a.pos - offset;
        let negative = a.neg - offset;
        Some(PcsLimits {
            positive,
            negative,
            distance_positive: positive - pcs_position,
            distance_negative: pcs_position - negative,
        })
    }
}

/// The four CNC objects of FCT-A2 §4.5 (positive / negative PCS limit, distance to each),
/// in mm / °. The CNC objects themselves are in 0.1 µm / 0.0001° (multiply by 10⁴).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcsLimits {
    /// Positive PCS limit (index offset 0x10096).
    pub positive: f64,
    /// Negative PCS limit (0x10097).
    pub negative: f64,
    /// Distance to the positive PCS limit (0x10098).
    pub distance_positive: f64,
    /// Distance to the negative PCS limit (0x10099).
    pub distance_negative: f64,
}

#[inline]
fn axis_active(a: &AxisLimits) -> bool {
    let homed = a.referenced || a.cfg.absolute_encoder;
    match a.cfg.check {
        0 => false,
        1 => homed,
        _ => homed && !a.cfg.modulo,
    }
}

fn actual_message(a: &AxisLimits, side: Side, actual: f64) -> CncMessage {
    let (id, limit) = match side {
        Side::Positive => (ids::ACTUAL_POSITIVE_SLS, a.pos + a.cfg.tolerance),
        Side::Negative => (ids::ACTUAL_NEGATIVE_SLS, a.neg - a.cfg.tolerance),
    };
    CncMessage::new(
        id,
        a.cfg.behaviour.controller_severity(),
        format!(
            "actual position {actual:.6} of axis {} is beyond the {} software limit switch including tolerance ({limit:.6})",
            a.cfg.name,
            side.word()
        ),
    )
    .on_axis(&a.cfg.name)
}

#[cfg(test)]
mod tests;
