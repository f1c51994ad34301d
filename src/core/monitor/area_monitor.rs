//! The active control areas applied to channel paths and positions (FCT-C14 §2.3 "Path check",
//! §2.4 2-path / IMCS, §4 additional axes, §5 manual mode).
//!
//! [`AreaTable`] keeps the areas in their own plane coordinates; this module ties them to channel
//! axes and checks channel [`Segment`]s (one entry per channel axis) with the exact geometry of
//! [`area_geom`](super::area_geom).
//!
//! # Which channel axes an area monitors
//!
//! | area | plane axes | excursion axis (unless `EXCUR_AX` / `EXCUR_AXNR`) |
//! |---|---|---|
//! | `MONITOR_LVL=MCS` (default), main axes | 1st / 2nd axis of the plane the area was defined in: X, Y (G17), Z, X (G18), Y, Z (G19) | 3rd: Z (G17), Y (G18), X (G19) |
//! | `MONITOR_LVL=IMCS` (seed §2.4) | U, V / W, U / V, W (secondary path, same order) | W / V / U |
//! | additional axes `X2=` / `Y2=` (seed §4) | X2, Y2 | Z2 |
//!
//! ([`plane_axis_names`](super::areas::plane_axis_names); seed 000 §3.1.1 "the first two main
//! axes of the active machining plane".) An area's own coordinates are `[1st, 2nd, excursion]`,
//! a right-handed frame for every plane, so an arc keeps its orientation in it.
//!
//! `EXCUR_AXNR=n` is the channel axis number n (1-based, the numbering of `AXNR` elsewhere).
//! Workspaces form a union per set of monitored axes (seed Fig. 7); protection areas override
//! workspaces (seed §2.3). A set of axes without any active workspace is not restricted by
//! workspaces.
//!
//! # Tolerance and segmentation
//!
//! Every check uses the boundary rule of `area_geom` with [`AREA_TOLERANCE`] (1 µm): a path
//! that comes within 1 µm of a protection area violates it; a path may run up to 1 µm outside a
//! workspace. Lines, and arcs / helices whose plane is spanned by two monitored axes in the
//! orientation of G17 / G18 / G19, are checked exactly. Anything else (an arc tilted by a
//! rotating `#CS`, an arc whose end point is off the start circle within the radius tolerance,
//! an arc with only one plane axis monitored) is replaced by chords with chordal deviation
//! `e ≤ tol / 2` (at most [`MAX_CHORDS`] chords); the chords are
//! checked against protection areas enlarged by `tol + e` and against workspaces with `tol − e`,
//! so segmentation never accepts a violating path.

use super::area_geom::{self as geo, ArcDir, PathElement, Plane, ViolationKind, MAX_CHORDS};
use super::areas::{Area, AreaAxes, AreaGeometry, AreaKind, AreaTable, ExcurAxis, MonitorLevel};
use crate::core::path::Segment;

/// Tolerance band of the area checks (mm): see the module documentation.
pub const AREA_TOLERANCE: f64 = 1e-3;

/// The names of the channel axes, to resolve which axes an area monitors.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChannelAxes {
    names: Vec<String>,
}

impl ChannelAxes {
    /// Channel axes in channel order (`X`, `Y`, `Z`, `U`, …).
    pub fn new(names: Vec<String>) -> Self {
        ChannelAxes { names }
    }

    /// Index of the axis called `name` (case-insensitive).
    pub fn find(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n.eq_ignore_ascii_case(name))
    }

    /// Name of axis `i`.
    pub fn name(&self, i: usize) -> &str {
        self.names.get(i).map(String::as_str).unwrap_or("?")
    }

    fn need(&self, name: &str, what: &str) -> Result<usize, String> {
        self.find(name).ok_or_else(|| {
            format!(
                "{what} needs a channel axis {name}; the channel has {}",
                self.names.join(", ")
            )
        })
    }

    /// Channel axis indices `[plane 1, plane 2, excursion]` that `area` monitors (module docs).
    pub fn resolve(&self, area: &Area) -> Result<[usize; 3], String> {
        let id = area.id();
        let what = |s: &str| format!("control area {id} ({s})");
        let [p0, p1, exc] = area.axis_names();
        let plane = area.plane;
        let level = match (area.header.monitor_level, area.axes) {
            (_, AreaAxes::Additional) => "additional axes".to_string(),
            (MonitorLevel::Imcs, _) => format!("MONITOR_LVL=IMCS, {plane}"),
            (MonitorLevel::Mcs, _) => format!("main axes, {plane}"),
        };
        let a = self.need(p0, &what(&level))?;
        let b = self.need(p1, &what(&level))?;
        let e = match &area.header.excur_axis {
            Some(ExcurAxis::Name(n)) => self.need(n, &what("EXCUR_AX"))?,
            Some(ExcurAxis::Number(k)) => {
                let k = *k as usize;
                if k == 0 || k > self.names.len() {
                    return Err(format!(
                        "{}: axis numbers are 1 … {} ({})",
                        what(&format!("EXCUR_AXNR={k}")),
                        self.names.len(),
                        self.names.join(", ")
                    ));
                }
                k - 1
            }
            None => self.need(exc, &what(&format!("{level}, excursion")))?,
        };
        if e == a || e == b {
            return Err(format!(
                "{}: the excursion axis {} is a plane axis of the area",
                what("EXCUR_AX"),
                self.name(e)
            ));
        }
        Ok([a, b, e])
    }
}

/// Which rule a path or position broke.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HitKind {
    /// Touches or enters a protection area.
    Protection,
    /// Leaves the union of the workspaces.
    Workspace,
    /// The path could not be evaluated (non-finite numbers): refused conservatively.
    Invalid,
}

/// A violation of the active areas.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaHit {
    /// What was violated.
    pub kind: HitKind,
    /// The protection area entered, or the workspace last left (`None` if the path starts
    /// outside every workspace or for [`HitKind::Invalid`]).
    pub id: Option<u32>,
    /// All workspaces of the monitored axes (for a workspace violation).
    pub workspaces: Vec<u32>,
    /// Channel axes `[plane 1, plane 2, excursion]` of the area(s).
    pub axes: [usize; 3],
    /// Where the violation begins, in those three coordinates.
    pub point: [f64; 3],
}

#[derive(Debug, Clone, PartialEq)]
struct Group {
    axes: [usize; 3],
    works: Vec<geo::Area>,
    work_ids: Vec<u32>,
    prots: Vec<geo::Area>,
    prot_ids: Vec<u32>,
}

/// The active areas, ready to check channel paths.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaMonitor {
    groups: Vec<Group>,
    tol: f64,
}

impl Default for AreaMonitor {
    fn default() -> Self {
        AreaMonitor {
            groups: Vec::new(),
            tol: AREA_TOLERANCE,
        }
    }
}

/// The exact-geometry body of an area.
pub fn geometry(area: &Area) -> Result<geo::Area, String> {
    let shape = match &area.geometry {
        AreaGeometry::Polygon { vertices } => geo::AreaShape::Polygon(
            geo::Polygon::new(vertices).map_err(|e| format!("control area {}: {e}", area.id()))?,
        ),
        AreaGeometry::Circle { centre, radius } => geo::AreaShape::Circle(
            geo::Circle::new(*centre, *radius)
                .map_err(|e| format!("control area {}: {e}", area.id()))?,
        ),
    };
    geo::Area::new(shape, area.header.min_excur, area.header.max_excur)
        .map_err(|e| format!("control area {}: {e}", area.id()))
}

/// Does the channel position `p` lie in `area` by the rule of the path check — the rule the
/// channel applies when an area is activated (seed 000 §3.2)? A protection area counts as
/// occupied when `p` lies inside it or within [`AREA_TOLERANCE`] of it (a zero-length path from
/// `p` would violate it); a workspace contains `p` when `p` lies inside it or at most
/// [`AREA_TOLERANCE`] outside (a zero-length path from `p` would be allowed). Non-finite
/// coordinates count as violating. `Err` if the area names axes the channel lacks.
pub fn position_inside(area: &Area, axes: &ChannelAxes, p: &[f64]) -> Result<bool, String> {
    let violated = AreaMonitor::from_areas([area], axes)?
        .check_position(p)
        .is_err();
    Ok(match area.kind() {
        AreaKind::Prot => violated,
        AreaKind::Work => !violated,
    })
}

impl AreaMonitor {
    /// The active areas of `table` on the channel axes `axes`, with [`AREA_TOLERANCE`].
    pub fn build(table: &AreaTable, axes: &ChannelAxes) -> Result<Self, String> {
        Self::from_areas(table.active(), axes)
    }

    /// Monitor exactly `areas` (active or not), e.g. to plot or to test.
    pub fn from_areas<'a>(
        areas: impl IntoIterator<Item = &'a Area>,
        axes: &ChannelAxes,
    ) -> Result<Self, String> {
        let mut groups: Vec<Group> = Vec::new();
        for a in areas {
            let ax = axes.resolve(a)?;
            let g = geometry(a)?;
            let k = match groups.iter().position(|g| g.axes == ax) {
                Some(k) => k,
                None => {
                    groups.push(Group {
                        axes: ax,
                        works: Vec::new(),
                        work_ids: Vec::new(),
                        prots: Vec::new(),
                        prot_ids: Vec::new(),
                    });
                    groups.len() - 1
                }
            };
            let gr = &mut groups[k];
            match a.kind() {
                AreaKind::Work => {
                    gr.works.push(g);
                    gr.work_ids.push(a.id());
                }
                AreaKind::Prot => {
                    gr.prots.push(g);
                    gr.prot_ids.push(a.id());
                }
            }
        }
        Ok(AreaMonitor {
            groups,
            tol: AREA_TOLERANCE,
        })
    }

    /// No area is monitored.
    pub fn is_empty(&self) -> bool {
        self.groups.is_empty()
    }

    /// The tolerance band (mm).
    pub fn tolerance(&self) -> f64 {
        self.tol
    }

    /// Does this monitor restrict channel axis `i` at all?
    pub fn monitors_axis(&self, i: usize) -> bool {
        self.groups.iter().any(|g| g.axes.contains(&i))
    }

    /// Check the whole path of a block (seed §2.3 "Path check"). On several violations the
    /// first in the order of the monitored axis sets is reported.
    pub fn check_segment(&self, seg: &Segment) -> Result<(), AreaHit> {
        for g in &self.groups {
            self.check_group(g, seg)?;
        }
        Ok(())
    }

    /// Check a position (one entry per channel axis): inside the workspaces and outside every
    /// protection area, with the tolerance band.
    pub fn check_position(&self, p: &[f64]) -> Result<(), AreaHit> {
        for g in &self.groups {
            let q = local(p, g.axes);
            let el = PathElement::Line(geo::Line { from: q, to: q });
            self.verdict(g, &el, self.tol, self.tol)?;
        }
        Ok(())
    }

    /// How far axis `axis` may travel from `from` in direction `dir` (sign), at most `max`,
    /// before the position would violate an area (0 if `from` itself violates). Axes not
    /// monitored travel `max`.
    pub fn free_travel(&self, from: &[f64], axis: usize, dir: f64, max: f64) -> f64 {
        let max = max.max(0.0);
        let mut to = from.to_vec();
        if let Some(t) = to.get_mut(axis) {
            *t += dir.signum() * max;
        }
        self.free_distance(from, &to).unwrap_or(max)
    }

    /// Distance along the straight line `from` → `to` (channel coordinates, the line's own
    /// length) to the point where it starts to violate an area; `None` if it never does.
    pub fn free_distance(&self, from: &[f64], to: &[f64]) -> Option<f64> {
        let total = from
            .iter()
            .zip(to)
            .map(|(a, b)| (b - a) * (b - a))
            .sum::<f64>()
            .sqrt();
        let mut best: Option<f64> = None;
        for g in &self.groups {
            let a = local(from, g.axes);
            let b = local(to, g.axes);
            let el = PathElement::Line(geo::Line { from: a, to: b });
            let Err(h) = self.verdict(g, &el, self.tol, self.tol) else {
                continue;
            };
            let ab: f64 = (0..3).map(|k| (b[k] - a[k]) * (b[k] - a[k])).sum();
            let s = if ab > 0.0 && h.point.iter().all(|v| v.is_finite()) {
                ((0..3)
                    .map(|k| (h.point[k] - a[k]) * (b[k] - a[k]))
                    .sum::<f64>()
                    / ab)
                    .clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = s * total;
            best = Some(best.map_or(d, |x: f64| x.min(d)));
        }
        best
    }

    fn check_group(&self, g: &Group, seg: &Segment) -> Result<(), AreaHit> {
        match local_path(seg, g.axes) {
            Local::Exact(el) => self.verdict(g, &el, self.tol, self.tol),
            Local::Curve { radius, sweep } => {
                let (n, e) = chords(radius, sweep, self.tol);
                let len = seg.length();
                let dims = seg.dims();
                let mut p = vec![0.0; dims];
                seg.point_at(0.0, &mut p);
                let mut a = local(&p, g.axes);
                for k in 1..=n {
                    seg.point_at(len * k as f64 / n as f64, &mut p);
                    let b = local(&p, g.axes);
                    let el = PathElement::Line(geo::Line { from: a, to: b });
                    self.verdict(g, &el, self.tol + e, (self.tol - e).max(0.0))?;
                    a = b;
                }
                Ok(())
            }
        }
    }

    fn verdict(
        &self,
        g: &Group,
        el: &PathElement,
        tol_prot: f64,
        tol_work: f64,
    ) -> Result<(), AreaHit> {
        let hit = |v: geo::AreaViolation, ids: &[u32]| {
            let kind = match v.kind {
                ViolationKind::ProtectionEntered => HitKind::Protection,
                ViolationKind::WorkspaceLeft => HitKind::Workspace,
                ViolationKind::InvalidInput => HitKind::Invalid,
            };
            AreaHit {
                kind,
                id: v.area_index.and_then(|i| ids.get(i).copied()),
                workspaces: if kind == HitKind::Workspace {
                    g.work_ids.clone()
                } else {
                    Vec::new()
                },
                axes: g.axes,
                point: v.first_point,
            }
        };
        let p = geo::path_allowed(el, &[], &g.prots, tol_prot).map_err(|v| hit(v, &g.prot_ids));
        let w = geo::path_allowed(el, &g.works, &[], tol_work).map_err(|v| hit(v, &g.work_ids));
        match (p, w) {
            (Ok(()), Ok(())) => Ok(()),
            (Err(h), Ok(())) | (Ok(()), Err(h)) => Err(h),
            // Both: the one that begins first along the path (protection wins a tie).
            (Err(hp), Err(hw)) => {
                let from = el.point_at(0.0);
                let d = |q: [f64; 3]| (0..3).map(|k| (q[k] - from[k]).powi(2)).sum::<f64>().sqrt();
                if d(hw.point) < d(hp.point) {
                    Err(hw)
                } else {
                    Err(hp)
                }
            }
        }
    }
}

fn local(p: &[f64], axes: [usize; 3]) -> [f64; 3] {
    axes.map(|a| p.get(a).copied().unwrap_or(f64::NAN))
}

enum Local {
    Exact(PathElement),
    /// Needs chords: an arc of this radius and sweep (rad).
    Curve {
        radius: f64,
        sweep: f64,
    },
}

/// The segment in the three monitored coordinates (module docs).
fn local_path(seg: &Segment, axes: [usize; 3]) -> Local {
    match seg {
        Segment::Line(l) => Local::Exact(PathElement::Line(geo::Line {
            from: local(&l.start, axes),
            to: local(&l.end, axes),
        })),
        Segment::Arc(arc) => {
            let curve = Local::Curve {
                radius: arc.radius,
                sweep: arc.sweep,
            };
            if arc.space.is_some() {
                return curve;
            }
            let sp = arc.to_space();
            let miss = sp.miss.iter().map(|m| m * m).sum::<f64>().sqrt();
            if miss > 1e-9 * arc.radius.max(1.0) {
                return curve;
            }
            let la1 = axes.iter().position(|&a| a == arc.a1);
            let la2 = axes.iter().position(|&a| a == arc.a2);
            let (la1, la2) = match (la1, la2) {
                (None, None) => {
                    // Only axes moving linearly with the angle are monitored: a straight line.
                    return Local::Exact(PathElement::Line(geo::Line {
                        from: local(&arc.start, axes),
                        to: local(&arc.end, axes),
                    }));
                }
                (Some(a), Some(b)) => (a, b),
                _ => return curve,
            };
            let (plane, normal) = match (la1, la2) {
                (0, 1) => (Plane::G17, 2),
                (2, 0) => (Plane::G18, 1),
                (1, 2) => (Plane::G19, 0),
                _ => return curve,
            };
            let start = local(&arc.start, axes);
            let end = local(&arc.end, axes);
            let mut center = [0.0; 3];
            center[la1] = arc.centre[0];
            center[la2] = arc.centre[1];
            center[normal] = start[normal];
            let a = geo::Arc {
                plane,
                center,
                radius: arc.radius,
                start_angle: arc.start_angle,
                end_angle: arc.start_angle + arc.sweep,
                dir: if arc.sweep >= 0.0 {
                    ArcDir::Ccw
                } else {
                    ArcDir::Cw
                },
            };
            let rise = end[normal] - start[normal];
            if rise != 0.0 {
                Local::Exact(PathElement::Helix(geo::Helix { arc: a, rise }))
            } else {
                Local::Exact(PathElement::Arc(a))
            }
        }
    }
}

/// Chord count and chordal deviation for an arc of `radius` and `sweep`.
fn chords(radius: f64, sweep: f64, tol: f64) -> (usize, f64) {
    let r = radius.abs();
    let w = sweep.abs();
    let want = tol / 2.0;
    let n = if !(r.is_finite() && w.is_finite()) || r <= want {
        1
    } else {
        let step = 2.0 * (1.0 - want / r).acos();
        let n = (w / step).ceil();
        if n.is_finite() {
            (n as usize).clamp(1, MAX_CHORDS)
        } else {
            MAX_CHORDS
        }
    };
    let e = if r.is_finite() {
        r * (1.0 - (w / (2.0 * n as f64)).min(std::f64::consts::PI).cos())
    } else {
        f64::INFINITY
    };
    (n, e.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chord_deviation_is_within_half_the_tolerance_for_ordinary_radii() {
        for r in [0.5, 10.0, 250.0, 1000.0] {
            let (n, e) = chords(r, std::f64::consts::TAU, AREA_TOLERANCE);
            assert!(e <= AREA_TOLERANCE / 2.0 + 1e-15, "r {r}: e {e}, n {n}");
        }
    }
}
