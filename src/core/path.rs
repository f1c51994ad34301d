//! Path segments (lines, circular arcs, helices) with exact axis extents.
//!
//! # Coordinates
//!
//! A point has one entry per axis, at most [`MAX_AXES`] axes, in mm (linear axes) or degrees
//! (rotary axes), as everywhere in the core (see [`crate::units`]). The path coordinate `s` runs
//! from 0 at the start point to [`Segment::length`] at the end point, in the same units.
//! [`Segment::point_at`] writes into a caller's buffer, so evaluating a path never allocates.
//!
//! # Arc planes and direction (DIN 66025, ISG kernel)
//!
//! An arc turns in the plane of two axes `(a1, a2)`, given in the plane's own orientation:
//!
//! | plane | `a1` | `a2` | centre offsets `[a1, a2]` | viewed from |
//! |-------|------|------|---------------------------|-------------|
//! | G17   | X    | Y    | `[I, J]`                  | +Z          |
//! | G18   | Z    | X    | `[K, I]`                  | +Y          |
//! | G19   | Y    | Z    | `[J, K]`                  | +X          |
//!
//! Angles are measured in the `(a1, a2)` frame from +a1 towards +a2 (`atan2(a2, a1)`). In every
//! plane `a1 × a2` is the positive third axis (X×Y = Z, Z×X = Y, Y×Z = X), so a positive sweep
//! (+a1 → +a2) is counter-clockwise when looked at from the positive third axis towards the
//! origin: that is G03. G02 is clockwise and has a negative sweep.
//!
//! Worked example, G18: from `X=0, Z=10` with `K=-10, I=0` (centre at the origin), G03 turns from
//! +Z towards +X, through `X=7.07, Z=7.07`, and a quarter circle ends at `X=10, Z=0`; G02 from the
//! same start turns towards −X and ends at `X=-10, Z=0` after a quarter.
//!
//! Any axes other than `a1` and `a2` move linearly with the angle (a helix when they move).
//!
//! # Radius mismatch
//!
//! The centre is `start + offset` and the radius is taken at the start point. The end point may
//! lie off that circle by up to the caller's radius tolerance. Such an arc is followed as the
//! circle plus a correction that grows linearly from 0 at the start to the full miss at the end,
//! so the path is continuous and ends exactly on the programmed end point. [`Segment::extent`]
//! and [`Segment::axis_speed_factor`] include the correction as a conservative bound.
//!
//! # Arcs in a general plane
//!
//! [`Segment::transformed`] maps a segment through a rigid [`AffineMap`] (a `#CS` rotation and
//! the frame offsets, FCT-C4 §4): lines stay lines, and a plane arc becomes an arc in a tilted
//! plane of the n-space, described by [`Arc::space`] (see [`space`] for the geometry and the
//! exact extents).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

pub mod space;

pub use space::{AffineMap, SpaceArc};

/// Most axes a path may have.
pub const MAX_AXES: usize = 32;

/// Largest accepted coordinate or centre offset magnitude (mm or °). Far beyond any machine; it
/// keeps every intermediate result (squares of differences, lengths) finite.
pub const MAX_COORDINATE: f64 = 1e12;

/// Smallest accepted arc radius (mm); anything shorter is a zero radius.
pub const MIN_RADIUS: f64 = 1e-9;

/// Segments shorter than this (mm) are empty: [`Segment::is_empty`].
pub const EMPTY_LENGTH: f64 = 1e-12;

/// In-plane distance, relative to `max(1, radius)`, below which an arc's start and end coincide
/// and the arc is a full circle.
const COINCIDENT: f64 = 1e-9;

/// End-point miss, relative to `max(1, radius, |centre|)`, below which the miss is rounding noise
/// and the arc is treated as an exact circle.
const ROUNDING_MISS: f64 = 1e-12;

/// Angular slack (rad) for deciding whether a cardinal angle lies in a sweep. Including a
/// cardinal point up to this far outside the sweep over-reports an extent by at most
/// `r · (1 − cos 1e-9) ≈ r · 5e-19`, which keeps extents safe against rounding of the angles.
const ANGLE_SLACK: f64 = 1e-9;

/// A straight move (G00/G01) between two points.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// Start point, one entry per axis.
    pub start: Vec<f64>,
    /// End point, one entry per axis.
    pub end: Vec<f64>,
}

/// A circular or helical move (G02/G03). Build it with [`Segment::arc`], which checks the fields
/// against each other, or map one with [`Segment::transformed`]; a hand-built `Arc` with
/// inconsistent fields gives meaningless numbers but never panics.
///
/// `space` is `None` for an arc in the plane of `a1`, `a2`. When it is `Some` (an arc made by
/// [`Segment::transformed`]) the geometry is the [`SpaceArc`]: `start`, `end`, `radius`,
/// `start_angle` and `sweep` keep their meaning (the angle is measured in the `u`, `v` frame),
/// while `a1`, `a2` and `centre` describe the plane arc it was mapped from.
#[derive(Debug, Clone, PartialEq)]
pub struct Arc {
    /// Start point, one entry per axis.
    pub start: Vec<f64>,
    /// End point, one entry per axis.
    pub end: Vec<f64>,
    /// First plane axis (G17: X, G18: Z, G19: Y).
    pub a1: usize,
    /// Second plane axis (G17: Y, G18: X, G19: Z).
    pub a2: usize,
    /// Centre in the `(a1, a2)` frame.
    pub centre: [f64; 2],
    /// Radius, measured at the start point.
    pub radius: f64,
    /// Angle of the start point about the centre, `atan2` in the `(a1, a2)` frame, in [−π, π].
    pub start_angle: f64,
    /// Signed sweep: positive counter-clockwise (G03), negative clockwise (G02), magnitude in
    /// (0, 2π]; ±2π is a full circle (start and end coincide in the plane).
    pub sweep: f64,
    /// The geometry of an arc outside the plane of `a1`, `a2` (see above); `None` for a plane
    /// arc.
    pub space: Option<SpaceArc>,
}

/// One path segment.
#[derive(Debug, Clone, PartialEq)]
pub enum Segment {
    /// A straight line.
    Line(Line),
    /// A circular arc or helix.
    Arc(Arc),
}

/// Why a segment could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    /// Start and end points have different numbers of axes.
    #[error("start point has {start} axes but end point has {end}")]
    DimensionMismatch {
        /// Axes of the start point.
        start: usize,
        /// Axes of the end point.
        end: usize,
    },
    /// No axes, or more than [`MAX_AXES`].
    #[error("a path needs 1 to {max} axes, got {dims}", max = MAX_AXES)]
    UnsupportedDimension {
        /// Axes given.
        dims: usize,
    },
    /// The plane axes are equal or not axes of the points.
    #[error("arc plane axes ({a1}, {a2}) are not two different axes of a {dims}-axis path")]
    InvalidPlane {
        /// First plane axis.
        a1: usize,
        /// Second plane axis.
        a2: usize,
        /// Axes of the points.
        dims: usize,
    },
    /// A coordinate or offset is NaN or infinite.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A coordinate or offset lies beyond ±[`MAX_COORDINATE`].
    #[error("{what} {shown} is beyond ±{max}", shown = crate::messages::show_number(*value), max = MAX_COORDINATE)]
    OutOfRange {
        /// Which input.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The radius tolerance is NaN, infinite or negative.
    #[error("radius tolerance {tolerance} must be finite and not negative")]
    InvalidTolerance {
        /// The tolerance given.
        tolerance: f64,
    },
    /// The centre lies on the start point (radius below [`MIN_RADIUS`]).
    #[error("arc radius {radius} is zero (below {min})", min = MIN_RADIUS)]
    ZeroRadius {
        /// Radius at the start point.
        radius: f64,
    },
    /// Start and end point lie at different distances from the centre.
    #[error(
        "arc radius mismatch: {start_radius} at the start, {end_radius} at the end \
         (tolerance {tolerance})"
    )]
    RadiusMismatch {
        /// Radius at the start point.
        start_radius: f64,
        /// Radius at the end point.
        end_radius: f64,
        /// The tolerance that was exceeded.
        tolerance: f64,
    },
    /// [`Segment::transformed`] got a map that is not rigid (rotation plus translation).
    #[error("the map is not rigid: {what}")]
    NotRigid {
        /// What was found.
        what: &'static str,
    },
}

fn check_dims(start: &[f64], end: &[f64]) -> Result<usize, PathError> {
    if start.len() != end.len() {
        return Err(PathError::DimensionMismatch {
            start: start.len(),
            end: end.len(),
        });
    }
    if start.is_empty() || start.len() > MAX_AXES {
        return Err(PathError::UnsupportedDimension { dims: start.len() });
    }
    Ok(start.len())
}

fn check_values(values: &[f64], what: &'static str) -> Result<(), PathError> {
    for &value in values {
        if !value.is_finite() {
            return Err(PathError::NonFinite { what });
        }
        if value.abs() > MAX_COORDINATE {
            return Err(PathError::OutOfRange { what, value });
        }
    }
    Ok(())
}

/// Copies as many entries as both slices hold.
fn copy_into(out: &mut [f64], from: &[f64]) {
    let n = out.len().min(from.len());
    out[..n].copy_from_slice(&from[..n]);
}

/// Whether `phi + 2πk` lies in `[lo, hi]` (widened by [`ANGLE_SLACK`]) for some integer `k`.
/// `lo` and `hi` come from a start angle in [−π, π] and a sweep of at most 2π, so `k` in −2..=2
/// covers every case.
fn angle_in(lo: f64, hi: f64, phi: f64) -> bool {
    (-2..=2).any(|k| {
        let a = phi + TAU * f64::from(k);
        a >= lo - ANGLE_SLACK && a <= hi + ANGLE_SLACK
    })
}

impl Arc {
    fn plane_of(&self, p: &[f64]) -> [f64; 2] {
        [
            p.get(self.a1).copied().unwrap_or(0.0),
            p.get(self.a2).copied().unwrap_or(0.0),
        ]
    }

    fn end_angle(&self) -> f64 {
        self.start_angle + self.sweep
    }

    /// Angular interval covered by the sweep, low end first.
    fn angle_range(&self) -> (f64, f64) {
        let end = self.end_angle();
        (self.start_angle.min(end), self.start_angle.max(end))
    }

    /// Point of the circle at `angle`.
    fn circle_at(&self, angle: f64) -> [f64; 2] {
        let (sin, cos) = angle.sin_cos();
        [
            self.centre[0] + self.radius * cos,
            self.centre[1] + self.radius * sin,
        ]
    }

    /// How far the programmed end point misses the circle at the end angle (in-plane), zero when
    /// the miss is rounding noise. See the module docs, "Radius mismatch".
    fn end_miss(&self) -> [f64; 2] {
        let end = self.plane_of(&self.end);
        let on_circle = self.circle_at(self.end_angle());
        let miss = [end[0] - on_circle[0], end[1] - on_circle[1]];
        let scale = 1f64
            .max(self.radius.abs())
            .max(self.centre[0].abs())
            .max(self.centre[1].abs());
        if miss[0].hypot(miss[1]) <= ROUNDING_MISS * scale {
            [0.0, 0.0]
        } else {
            miss
        }
    }

    /// `k = 0` for `a1` (cos), `k = 1` for `a2` (sin).
    fn trig(k: usize, angle: f64) -> f64 {
        if k == 0 {
            angle.cos()
        } else {
            angle.sin()
        }
    }

    /// Exact extent of plane coordinate `k` (0: `a1`, 1: `a2`).
    fn plane_extent(&self, k: usize) -> (f64, f64) {
        let (s, e) = (self.plane_of(&self.start)[k], self.plane_of(&self.end)[k]);
        let (mut lo, mut hi) = (s.min(e), s.max(e));
        let (c, r, miss) = (self.centre[k], self.radius, self.end_miss()[k]);
        // Where the coordinate is largest / smallest on the circle.
        let (max_phi, min_phi) = if k == 0 {
            (0.0, PI)
        } else {
            (FRAC_PI_2, 3.0 * FRAC_PI_2)
        };
        let (a_lo, a_hi) = self.angle_range();
        let at_ends = [
            Self::trig(k, self.start_angle),
            Self::trig(k, self.end_angle()),
        ];
        // u·miss (u in [0, 1]) adds at most max(0, miss) and at least min(0, miss).
        if angle_in(a_lo, a_hi, max_phi) {
            hi = hi.max(c + r + miss.max(0.0));
        } else if miss != 0.0 {
            hi = hi.max(c + r * at_ends[0].max(at_ends[1]) + miss.max(0.0));
        }
        if angle_in(a_lo, a_hi, min_phi) {
            lo = lo.min(c - r + miss.min(0.0));
        } else if miss != 0.0 {
            lo = lo.min(c + r * at_ends[0].min(at_ends[1]) + miss.min(0.0));
        }
        (lo, hi)
    }

    /// Largest `|d coordinate k / ds|` on the circle part, times the length.
    fn plane_rate(&self, k: usize) -> f64 {
        // d/dθ of cos is −sin, of sin is cos: |derivative| is 1 where the *other* function is 0.
        let (p, q) = if k == 0 {
            (FRAC_PI_2, 3.0 * FRAC_PI_2)
        } else {
            (0.0, PI)
        };
        let (a_lo, a_hi) = self.angle_range();
        let other = 1 - k;
        let m = if angle_in(a_lo, a_hi, p) || angle_in(a_lo, a_hi, q) {
            1.0
        } else {
            Self::trig(other, self.start_angle)
                .abs()
                .max(Self::trig(other, self.end_angle()).abs())
        };
        self.radius * self.sweep.abs() * m
    }

    /// Plane coordinates at fraction `u` of the sweep, written into `out`.
    fn write_plane(&self, u: f64, out: &mut [f64]) {
        let p = self.circle_at(self.start_angle + self.sweep * u);
        let miss = self.end_miss();
        if let Some(o) = out.get_mut(self.a1) {
            *o = p[0] + u * miss[0];
        }
        if let Some(o) = out.get_mut(self.a2) {
            *o = p[1] + u * miss[1];
        }
    }

    fn is_plane_axis(&self, axis: usize) -> bool {
        axis == self.a1 || axis == self.a2
    }
}

impl Segment {
    /// A straight move from `start` to `end`.
    ///
    /// Errors: different or unsupported numbers of axes, non-finite or out-of-range coordinates.
    pub fn line(start: Vec<f64>, end: Vec<f64>) -> Result<Segment, PathError> {
        check_dims(&start, &end)?;
        check_values(&start, "start point")?;
        check_values(&end, "end point")?;
        Ok(Segment::Line(Line { start, end }))
    }

    /// A G02 (`clockwise`) or G03 arc from `start` to `end` in the plane `(a1, a2)`.
    ///
    /// `centre_offset` is the centre relative to the start point in the `(a1, a2)` frame: `[I, J]`
    /// for G17, `[K, I]` for G18, `[J, K]` for G19 (see the module docs for the orientation).
    /// The radius is taken at the start point; the end point's radius may differ by at most
    /// `radius_tolerance`. Axes other than `a1`, `a2` move linearly (helix). When start and end
    /// coincide in the plane (within 1e-9 · max(1, r)) the arc is a full circle.
    ///
    /// Errors: as [`Segment::line`], plus an invalid plane, a non-finite offset, an invalid
    /// tolerance, a zero radius or a radius mismatch.
    pub fn arc(
        start: Vec<f64>,
        end: Vec<f64>,
        a1: usize,
        a2: usize,
        centre_offset: [f64; 2],
        clockwise: bool,
        radius_tolerance: f64,
    ) -> Result<Segment, PathError> {
        let dims = check_dims(&start, &end)?;
        check_values(&start, "start point")?;
        check_values(&end, "end point")?;
        check_values(&centre_offset, "centre offset")?;
        if !(radius_tolerance.is_finite() && radius_tolerance >= 0.0) {
            return Err(PathError::InvalidTolerance {
                tolerance: radius_tolerance,
            });
        }
        if a1 >= dims || a2 >= dims || a1 == a2 {
            return Err(PathError::InvalidPlane { a1, a2, dims });
        }
        let centre = [start[a1] + centre_offset[0], start[a2] + centre_offset[1]];
        let rel_start = [start[a1] - centre[0], start[a2] - centre[1]];
        let rel_end = [end[a1] - centre[0], end[a2] - centre[1]];
        let radius = rel_start[0].hypot(rel_start[1]);
        if radius.is_nan() || radius < MIN_RADIUS {
            return Err(PathError::ZeroRadius { radius });
        }
        let end_radius = rel_end[0].hypot(rel_end[1]);
        if (radius - end_radius).abs() > radius_tolerance {
            return Err(PathError::RadiusMismatch {
                start_radius: radius,
                end_radius,
                tolerance: radius_tolerance,
            });
        }
        let start_angle = rel_start[1].atan2(rel_start[0]);
        let chord = (end[a1] - start[a1]).hypot(end[a2] - start[a2]);
        let magnitude = if chord <= COINCIDENT * radius.max(1.0) {
            TAU
        } else {
            let end_angle = rel_end[1].atan2(rel_end[0]);
            let raw = if clockwise {
                start_angle - end_angle
            } else {
                end_angle - start_angle
            };
            // Into (0, 2π]: the way round in the programmed direction.
            let turned = if raw <= 0.0 { raw + TAU } else { raw };
            if turned > 0.0 && turned <= TAU {
                turned
            } else {
                TAU
            }
        };
        Ok(Segment::Arc(Arc {
            start,
            end,
            a1,
            a2,
            centre,
            radius,
            start_angle,
            sweep: if clockwise { -magnitude } else { magnitude },
            space: None,
        }))
    }

    /// Number of axes.
    pub fn dims(&self) -> usize {
        self.start().len()
    }

    /// Start point.
    pub fn start(&self) -> &[f64] {
        match self {
            Segment::Line(l) => &l.start,
            Segment::Arc(a) => &a.start,
        }
    }

    /// End point.
    pub fn end(&self) -> &[f64] {
        match self {
            Segment::Line(l) => &l.end,
            Segment::Arc(a) => &a.end,
        }
    }

    /// Path length: the Euclidean distance for a line; `sqrt((r·|sweep|)² + Σ Δ²)` over the
    /// linearly moving axes for an arc or helix (`Σ helix²` for a mapped arc).
    pub fn length(&self) -> f64 {
        match self {
            Segment::Line(l) => l
                .start
                .iter()
                .zip(&l.end)
                .map(|(a, b)| (b - a) * (b - a))
                .sum::<f64>()
                .sqrt(),
            Segment::Arc(arc) => {
                if let Some(space) = &arc.space {
                    return arc.space_length(space);
                }
                let turn = arc.radius * arc.sweep.abs();
                let linear: f64 = arc
                    .start
                    .iter()
                    .zip(&arc.end)
                    .enumerate()
                    .filter(|(i, _)| !arc.is_plane_axis(*i))
                    .map(|(_, (a, b))| (b - a) * (b - a))
                    .sum();
                (turn * turn + linear).sqrt()
            }
        }
    }

    /// The point at path coordinate `s` (clamped to `[0, length]`; NaN counts as 0), written into
    /// `out` (one entry per axis; a shorter or longer buffer gets as many entries as both hold).
    ///
    /// On an arc the angle is `start_angle + sweep · s / length` and the linear axes move by the
    /// same fraction. `s <= 0` gives exactly the start point and `s >= length` exactly the end
    /// point, without rounding drift. Never allocates.
    pub fn point_at(&self, s: f64, out: &mut [f64]) {
        let (start, end) = (self.start(), self.end());
        let length = self.length();
        if s.is_nan() || s <= 0.0 {
            copy_into(out, start);
            return;
        }
        if s >= length {
            copy_into(out, end);
            return;
        }
        let u = s / length;
        if let Segment::Arc(arc) = self {
            if let Some(space) = &arc.space {
                let n = out.len().min(start.len());
                arc.space_point(space, u, &mut out[..n]);
                return;
            }
        }
        for ((o, a), b) in out.iter_mut().zip(start).zip(end) {
            *o = a + u * (b - a);
        }
        if let Segment::Arc(arc) = self {
            arc.write_plane(u, out);
        }
    }

    /// Smallest and largest value of `axis` over the whole segment, exactly (no sampling).
    ///
    /// Lines and the linear axes of a helix: the end points. Arc plane axes: the end points plus
    /// `centre ± r` for every cardinal angle (0, π/2, π, 3π/2 + k·2π) inside the sweep, so an
    /// arc that bulges past both end points reports its apex. The extent is never smaller than
    /// the path (a radius mismatch widens it by at most the miss). An axis the segment does not
    /// have gives `(0.0, 0.0)`.
    ///
    /// A mapped arc ([`Arc::space`]): the end points plus every angle inside the sweep where the
    /// axis has a stationary point, including the helix part (exact, see [`space`]).
    pub fn extent(&self, axis: usize) -> (f64, f64) {
        if let Segment::Arc(arc) = self {
            if let Some(space) = &arc.space {
                if axis >= arc.start.len() {
                    return (0.0, 0.0);
                }
                return arc.space_extent(space, axis);
            }
            if axis == arc.a1 {
                return arc.plane_extent(0);
            }
            if axis == arc.a2 {
                return arc.plane_extent(1);
            }
        }
        match (self.start().get(axis), self.end().get(axis)) {
            (Some(&a), Some(&b)) => (a.min(b), a.max(b)),
            _ => (0.0, 0.0),
        }
    }

    /// Largest `|d axis / ds|` over the segment, normally in [0, 1]; 0 for an axis that does not
    /// move, an empty segment or an axis the segment does not have.
    ///
    /// Line and linear axes of a helix: `|Δ| / length`. Arc plane axes: `r·|sweep| / length` if
    /// the axis reaches its largest rate inside the sweep (where the other plane axis is at a
    /// cardinal angle), else the larger rate at the two ends; a radius mismatch adds
    /// `|miss| / length` and may then exceed 1. A mapped arc ([`Arc::space`]): the exact largest
    /// rate of the axis's wave plus helix part over the sweep. Limit the path so that
    /// `v_path · factor <= v_axis` and `a_path · factor <= a_axis` for every axis.
    pub fn axis_speed_factor(&self, axis: usize) -> f64 {
        let length = self.length();
        if length.is_nan() || length < EMPTY_LENGTH {
            return 0.0;
        }
        if let Segment::Arc(arc) = self {
            if let Some(space) = &arc.space {
                if axis >= arc.start.len() {
                    return 0.0;
                }
                return arc.space_rate(space, axis, length);
            }
            if arc.is_plane_axis(axis) {
                let k = usize::from(axis != arc.a1);
                let miss = arc.end_miss()[k].abs();
                let rate = (arc.plane_rate(k) + miss) / length;
                return if miss == 0.0 { rate.min(1.0) } else { rate };
            }
        }
        match (self.start().get(axis), self.end().get(axis)) {
            (Some(&a), Some(&b)) => ((b - a).abs() / length).min(1.0),
            _ => 0.0,
        }
    }

    /// Whether the segment is shorter than [`EMPTY_LENGTH`].
    pub fn is_empty(&self) -> bool {
        let length = self.length();
        length.is_nan() || length < EMPTY_LENGTH
    }
}
