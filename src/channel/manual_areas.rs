//! Workspace / protection-area monitoring while jogging (FCT-C14 §5, §6.2 P-CHAN-00442, §6.3).
//!
//! Everything here works on command positions (the TCP of FCT-C14 §5) and on the
//! [`AreaMonitor`](crate::core::monitor::area_monitor::AreaMonitor) of the channel; see the
//! module documentation of [`manual`](super) for the rules.

use super::super::Channel;
use crate::core::monitor::area_monitor::{AreaHit, HitKind};
use crate::messages::{ids, CncMessage};

/// Sampling step (mm) of the search for the point where a jog from a violating position
/// re-enters the permitted range. A permitted stretch shorter than this can be missed, which
/// only refuses a jog (conservative).
const MOVE_BACK_STEP: f64 = 0.05;
/// Longest stretch searched for the re-entry point (mm).
const MOVE_BACK_SEARCH: f64 = 10_000.0;
/// At most this many samples; beyond, the step grows.
const MOVE_BACK_SAMPLES: f64 = 200_000.0;

/// Why a jog is limited by an area (carried by the jog to its stop event).
///
/// Made from an [`AreaHit`] with [`AreaStop::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(in crate::channel) struct AreaStop {
    /// The protection area / workspace (None: outside every workspace).
    pub(super) id: Option<u32>,
    /// Which rule limits the jog.
    pub(super) kind: HitKind,
}

impl AreaStop {
    pub(super) fn new(hit: &AreaHit) -> Self {
        AreaStop {
            id: hit_id(hit),
            kind: hit.kind,
        }
    }
}

/// How far a jog of one axis may travel in one direction with respect to the areas.
#[derive(Debug, Clone)]
pub(super) enum AreaTravel {
    /// Not limited by any area.
    Free,
    /// May travel `dist` (mm, the tolerance band included); `hit` is what lies beyond.
    Limited { dist: f64, hit: AreaHit },
    /// The start violates and this direction does not lead back into the permitted range.
    Refused { hit: AreaHit },
}

/// The area a hit names: the protection area, the workspace left, or the only workspace of the
/// monitored axes when a position lies outside all of them.
fn hit_id(hit: &AreaHit) -> Option<u32> {
    match (hit.kind, hit.id, hit.workspaces.as_slice()) {
        (HitKind::Workspace, None, [only]) => Some(*only),
        (_, id, _) => id,
    }
}

/// Text naming the violated area(s) of a hit.
fn hit_name(hit: &AreaHit) -> String {
    match (hit.kind, hit_id(hit)) {
        (HitKind::Workspace, None) if !hit.workspaces.is_empty() => {
            let list: Vec<String> = hit.workspaces.iter().map(u32::to_string).collect();
            format!("the workspaces {}", list.join(", "))
        }
        (kind, id) => area_name(kind, id),
    }
}

/// Text naming a violated area.
pub(super) fn area_name(kind: HitKind, id: Option<u32>) -> String {
    match (kind, id) {
        (HitKind::Protection, Some(id)) => format!("protection area {id}"),
        (HitKind::Workspace, Some(id)) => format!("workspace {id}"),
        (HitKind::Workspace, None) => "the workspaces".to_string(),
        _ => "the control areas".to_string(),
    }
}

impl Channel {
    /// Are workspace / protection areas monitored for jogging right now (FCT-C14 §5)? True
    /// when an area is active, P-CHAN-00442 is not 1 and the control unit "suppress error
    /// output from working space monitoring in manual mode"
    /// ([`set_area_mon_suppress_manual_w`](Channel::set_area_mon_suppress_manual_w)) is not
    /// set. Evaluated when a jog starts.
    pub fn manual_area_monitoring(&self) -> bool {
        self.cfg.workspace_manual_mode != 1
            && !self.areas.suppress_manual
            && !self.areas.monitor.is_empty()
    }

    /// Selection of manual mode with P-CHAN-00442 = 0 (FCT-C14 §5 case 2): the TCP must be in
    /// the permitted range, else error 50961 / 50962, PLC datum set, and false.
    pub(super) fn manual_entry_allowed(&mut self) -> bool {
        if self.cfg.workspace_manual_mode == 2 || !self.manual_area_monitoring() {
            return true;
        }
        let pos = self.command_positions();
        let Err(hit) = self.areas.monitor.check_position(&pos) else {
            return true;
        };
        self.areas.violation_detected = true;
        let (id, what) = match hit.kind {
            HitKind::Protection => (ids::MANUAL_IN_PROTECTION, "inside"),
            _ => (ids::MANUAL_OUTSIDE_WORKSPACE, "outside"),
        };
        let text = format!(
            "manual mode not selected: the TCP is {what} {} at {}; set the control unit \
             'suppress area monitoring in manual mode' to move back",
            hit_name(&hit),
            self.hit_position(&hit)
        );
        self.push(CncMessage::error(id, text));
        false
    }

    fn hit_position(&self, hit: &AreaHit) -> String {
        let n = |k: usize| self.areas.axes.name(hit.axes[k]).to_string();
        format!(
            "{}={:.6} {}={:.6} {}={:.6}",
            n(0),
            hit.point[0],
            n(1),
            hit.point[1],
            n(2),
            hit.point[2]
        )
    }

    /// With areas monitored, another monitored axis is jogging: the jog of `i` is refused
    /// (warning 900318). Returns true when refused.
    pub(super) fn area_concurrent_jog(&mut self, i: usize, jogging: &[bool]) -> bool {
        if !self.manual_area_monitoring() || !self.areas.monitor.monitors_axis(i) {
            return false;
        }
        let Some(other) = (0..jogging.len())
            .find(|&j| j != i && jogging[j] && self.areas.monitor.monitors_axis(j))
        else {
            return false;
        };
        let (a, b) = (
            self.axes[i].name().to_string(),
            self.axes[other].name().to_string(),
        );
        self.push(
            CncMessage::warning(
                ids::AREA_JOG_STOPPED,
                format!(
                    "jog of axis {a} not started: axis {b} is jogging, and while workspace / \
                     protection areas are monitored only one axis may jog at a time"
                ),
            )
            .on_axis(&a),
        );
        true
    }

    /// How far axis `i` may jog in direction `sign` (at most `max`) with respect to the areas.
    pub(super) fn area_travel(&self, i: usize, sign: f64, max: f64) -> AreaTravel {
        if !self.manual_area_monitoring() || !self.areas.monitor.monitors_axis(i) {
            return AreaTravel::Free;
        }
        let mon = &self.areas.monitor;
        let p = self.command_positions();
        let (from, before) = match mon.check_position(&p) {
            Ok(()) => (p, 0.0),
            Err(hit) => match self.reentry(&p, i, sign, max) {
                Some(s0) => {
                    let mut q = p;
                    q[i] += sign * s0;
                    (q, s0)
                }
                None => return AreaTravel::Refused { hit },
            },
        };
        let rest = if max.is_finite() {
            (max - before).max(0.0)
        } else {
            super::UNLIMITED_TRAVEL
        };
        let f = mon.free_travel(&from, i, sign, rest);
        if f >= rest {
            return AreaTravel::Free;
        }
        AreaTravel::Limited {
            dist: before + f,
            hit: self.beyond(&from, i, sign, f),
        }
    }

    /// The violation just beyond `from + sign·f` along axis `i`, named at the boundary
    /// `from + sign·f` itself, as the path check of automatic mode names the first point of a
    /// violation: the area is found a little further on (10 × the tolerance), the point reported
    /// is where the permitted travel ends.
    fn beyond(&self, from: &[f64], i: usize, sign: f64, f: f64) -> AreaHit {
        let mut boundary = from.to_vec();
        boundary[i] += sign * f;
        let mut q = boundary.clone();
        q[i] += sign * 10.0 * self.areas.monitor.tolerance();
        match self.areas.monitor.check_position(&q) {
            Err(mut hit) => {
                for k in 0..3 {
                    if let Some(v) = boundary.get(hit.axes[k]) {
                        hit.point[k] = *v;
                    }
                }
                hit
            }
            Ok(()) => AreaHit {
                kind: HitKind::Workspace,
                id: None,
                workspaces: Vec::new(),
                axes: [i; 3],
                point: [boundary[i]; 3],
            },
        }
    }

    /// From the violating position `p`: the distance along axis `i` in direction `sign` (at
    /// most `max`) at which the TCP is first in the permitted range again, if any.
    fn reentry(&self, p: &[f64], i: usize, sign: f64, max: f64) -> Option<f64> {
        let mon = &self.areas.monitor;
        let len = max.min(MOVE_BACK_SEARCH);
        if len.is_nan() || len <= 0.0 {
            return None;
        }
        let n = (len / MOVE_BACK_STEP).ceil().clamp(1.0, MOVE_BACK_SAMPLES);
        let h = len / n;
        let mut q = p.to_vec();
        let mut ok = |s: f64| {
            q[i] = p[i] + sign * s;
            mon.check_position(&q).is_ok()
        };
        let mut prev = 0.0;
        for k in 1..=(n as u64) {
            let s = (k as f64 * h).min(len);
            if ok(s) {
                // Bisect between prev (violating) and s (permitted); keep the permitted side.
                let (mut lo, mut hi) = (prev, s);
                while hi - lo > 1e-7 {
                    let mid = 0.5 * (lo + hi);
                    if ok(mid) {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                return Some(hi);
            }
            prev = s;
        }
        None
    }

    /// An incremental step of axis `i` by `distance` violates an area: warning 900318, PLC datum
    /// set. Returns true when the step must not run. `range` is how far the jog range reaches
    /// in the step's direction (the re-entry search of a move back looks that far).
    pub(super) fn area_step_refused(&mut self, i: usize, distance: f64, range: f64) -> bool {
        let sign = if distance < 0.0 { -1.0 } else { 1.0 };
        let name = self.axes[i].name().to_string();
        let target = self.axes[i].command() + distance;
        let (hit, why) = match self.area_travel(i, sign, range.max(distance.abs())) {
            AreaTravel::Free => return false,
            AreaTravel::Limited { dist, .. } if distance.abs() <= dist => return false,
            AreaTravel::Limited { hit, .. } => (hit, "the path would violate"),
            AreaTravel::Refused { hit } => (
                hit,
                "the axis starts in violation and this direction does not lead back into the permitted range of",
            ),
        };
        self.areas.violation_detected = true;
        let text = format!(
            "incremental jog of axis {name} to {target:.6} not executed: {why} {} at {}",
            hit_name(&hit),
            self.hit_position(&hit)
        );
        self.push(CncMessage::warning(ids::AREA_JOG_STOPPED, text).on_axis(&name));
        true
    }
}
