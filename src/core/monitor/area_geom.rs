//! Exact path-versus-area geometry for workspace and protection area monitoring
//! (FCT-C14 §2.3 "Path check", issue 7 item 4).
//!
//! Pure functions on `f64`, no I/O, no panics on any input: non-finite inputs give the
//! conservative verdict (a violation).
//!
//! # Areas
//! An [`Area`] is a prism: a planar [`Polygon`] or [`Circle`] in the area plane, extruded over
//! `[min_excur, max_excur]` on the excursion axis (seed §3.1 `MIN_EXCUR` / `MAX_EXCUR`,
//! `EXCUR_AX`). Which path coordinates (0 = X, 1 = Y, 2 = Z) are the area's plane axes and
//! which is the excursion axis is the area's [`AxisMap`]; the default is plane X/Y, excursion Z
//! (seed §2.3 "Z → 3rd main axis").
//!
//! # Boundary rule (one rule for both kinds of area)
//! Every area is monitored as the *closed, tolerance-enlarged* set
//! `A_tol = { p : dist_plane(p, shape) ≤ tol  and  min_excur − tol ≤ w(p) ≤ max_excur + tol }`.
//! - A **protection area** "must never be touched by the TCP" (seed §2.3): a path that comes
//!   within `tol` of it (touching its boundary included) **violates** it.
//! - A **workspace** is "a zone that the TCP is not permitted to exit" (seed §2.3): running along
//!   its boundary, or up to `tol` outside it, is **allowed**.
//!
//! So the tolerance band always lies on the outside of the area; a verdict can only differ from
//! the exact one for paths whose extreme distance from the area lies within about `1e-9·scale`
//! of `tol` itself, which is why `tol` should be well above f64 rounding (e.g. 1e-4 mm for
//! 0.1 µm machines). `tol = 0` is accepted, but then rounding may flip verdicts for paths that
//! graze a boundary.
//!
//! # Method
//! Along the path parameter `s ∈ [0, 1]` membership in `A_tol` can only change where the path
//! crosses the boundary of `A_tol`. That boundary is contained in (a) the two offset copies of
//! every polygon edge at distance `tol` and the circles of radius `tol` around the vertices,
//! or the circle of radius `R + tol` (circle areas), and (b) the two excursion levels. The path
//! is intersected exactly with these primitives (segment–segment, segment–circle, arc–segment,
//! arc–circle, harmonic level equations); the resulting break parameters, plus closest-approach
//! points that make tangencies robust, split `[0, 1]` into pieces on which membership is
//! constant, and one membership test per piece decides. This finds an arc whose end points are
//! outside a protection area but whose bulge enters it (the classic soft-limit bug) exactly.
//!
//! Exact cases: lines; arcs and helices whose arc plane is the area plane (a helix is trimmed by
//! the excursion levels); arcs (without helical rise) in a plane perpendicular to the area plane,
//! e.g. a G18 arc against an X/Y area, whose projection is a segment traversed harmonically.
//!
//! Segmented case: a helix whose arc plane is perpendicular to the area plane projects to a
//! non-circular curve. It is replaced by chords with chordal deviation `e = tol / 2` (larger
//! only if that would need more than [`MAX_CHORDS`] chords: then `e = r·(1 − cos(π·|sweep| /
//! (2π·MAX_CHORDS)))`); protection areas are enlarged by `e` (tolerance `tol + e`) and
//! workspaces are checked with `tol − e`, so the segmentation never accepts a violating path.

use std::f64::consts::{PI, TAU};

/// Maximum number of polygon vertices (= G01 blocks of a POLY definition, seed §2.3: "limited
/// to 20 blocks").
pub const MAX_POLYGON_VERTICES: usize = 20;

/// Upper bound on the chord count when a perpendicular helix is segmented.
pub const MAX_CHORDS: usize = 4096;

/// Why a polygon was rejected. Vertex and edge numbers are 0-based positions in the list passed
/// to [`Polygon::new`] (after dropping a repeated closing vertex); edge `i` runs from vertex `i`
/// to vertex `i + 1` (the last edge back to vertex 0).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolygonError {
    /// Fewer than 3 distinct vertices.
    #[error("polygon needs at least 3 distinct vertices, got {count}")]
    TooFewVertices {
        /// Vertices after dropping the closing duplicate.
        count: usize,
    },
    /// More than [`MAX_POLYGON_VERTICES`] vertices.
    #[error("polygon has {count} vertices, at most {MAX_POLYGON_VERTICES} allowed")]
    TooManyVertices {
        /// Vertices after dropping the closing duplicate.
        count: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("polygon vertex {vertex} is not finite")]
    NonFiniteVertex {
        /// Offending vertex.
        vertex: usize,
    },
    /// Two consecutive vertices coincide.
    #[error("polygon edge {edge} (from vertex {edge}) has zero length")]
    ZeroLengthEdge {
        /// Offending edge.
        edge: usize,
    },
    /// Two edges intersect (non-adjacent edges touch, or adjacent edges fold back).
    #[error("polygon edges {edge_a} and {edge_b} intersect")]
    SelfIntersection {
        /// First edge.
        edge_a: usize,
        /// Second edge.
        edge_b: usize,
    },
}

/// Why an area could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AreaError {
    /// The circle radius is not finite and > 0, or its centre is not finite.
    #[error("circle needs a finite centre and a finite radius > 0, got {radius}")]
    InvalidCircle {
        /// Offending radius.
        radius: f64,
    },
    /// `MIN_EXCUR < MAX_EXCUR` (both finite) is required (seed §3.1).
    #[error("MIN_EXCUR ({min}) must be finite and below MAX_EXCUR ({max})")]
    InvalidExcursion {
        /// MIN_EXCUR.
        min: f64,
        /// MAX_EXCUR.
        max: f64,
    },
    /// The axis map is not a permutation of 0, 1, 2.
    #[error("axis map {0:?} is not a permutation of 0, 1, 2")]
    InvalidAxisMap([usize; 3]),
}

/// A simple closed polygon in the area plane, at most [`MAX_POLYGON_VERTICES`] vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    v: Vec<[f64; 2]>,
    bbox: [f64; 4],
}

impl Polygon {
    /// Validates a closed vertex chain. The seed requires first point = last point; here a
    /// repeated closing vertex (bit-identical to the first) is dropped, and otherwise the
    /// closing edge from the last to the first vertex is implied. Checks: finite coordinates,
    /// 3..=20 vertices, no zero-length edge, no two edges intersecting (adjacent edges may only
    /// share their common vertex). Orientation (CW / CCW) is free.
    pub fn new(vertices: &[[f64; 2]]) -> Result<Self, PolygonError> {
        let mut v: Vec<[f64; 2]> = vertices.to_vec();
        if v.len() >= 2 && v[0] == v[v.len() - 1] {
            v.pop();
        }
        if let Some(i) = v
            .iter()
            .position(|p| !p[0].is_finite() || !p[1].is_finite())
        {
            return Err(PolygonError::NonFiniteVertex { vertex: i });
        }
        let n = v.len();
        if n > MAX_POLYGON_VERTICES {
            return Err(PolygonError::TooManyVertices { count: n });
        }
        for i in 0..n {
            if n >= 2 && v[i] == v[(i + 1) % n] {
                return Err(PolygonError::ZeroLengthEdge { edge: i });
            }
        }
        if n < 3 {
            return Err(PolygonError::TooFewVertices { count: n });
        }
        for i in 0..n {
            let (a, b) = (v[i], v[(i + 1) % n]);
            for j in (i + 1)..n {
                let (c, d) = (v[j], v[(j + 1) % n]);
                let adjacent = j == i + 1 || (i == 0 && j == n - 1);
                let bad = if adjacent {
                    // Shared vertex: fold-back means collinear and pointing back over the edge.
                    let (p, q, r) = if j == i + 1 { (a, b, d) } else { (c, a, b) };
                    let u = sub(p, q);
                    let w = sub(r, q);
                    cross(u, w) == 0.0 && dot(u, w) > 0.0
                } else {
                    segments_touch(a, b, c, d)
                };
                if bad {
                    return Err(PolygonError::SelfIntersection {
                        edge_a: i,
                        edge_b: j,
                    });
                }
            }
        }
        let mut bbox = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for p in &v {
            bbox = [
                bbox[0].min(p[0]),
                bbox[1].min(p[1]),
                bbox[2].max(p[0]),
                bbox[3].max(p[1]),
            ];
        }
        Ok(Self { v, bbox })
    }

    /// The vertices (without a repeated closing vertex).
    pub fn vertices(&self) -> &[[f64; 2]] {
        &self.v
    }
}

/// A full circle in the area plane (seed §3.1.2 CIRC).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    center: [f64; 2],
    radius: f64,
}

impl Circle {
    /// Finite centre, finite radius > 0.
    pub fn new(center: [f64; 2], radius: f64) -> Result<Self, AreaError> {
        if !(radius.is_finite() && radius > 0.0 && center[0].is_finite() && center[1].is_finite()) {
            return Err(AreaError::InvalidCircle { radius });
        }
        Ok(Self { center, radius })
    }

    /// Centre in the area plane.
    pub fn center(&self) -> [f64; 2] {
        self.center
    }

    /// Radius.
    pub fn radius(&self) -> f64 {
        self.radius
    }
}

/// The planar contour of an area.
#[derive(Debug, Clone, PartialEq)]
pub enum AreaShape {
    /// POLY area.
    Polygon(Polygon),
    /// CIRC area.
    Circle(Circle),
}

/// Which path coordinates (0 = X, 1 = Y, 2 = Z) form the area plane and the excursion axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxisMap {
    /// Path coordinate indices of the area plane's first and second axis.
    pub plane: [usize; 2],
    /// Path coordinate index of the excursion axis (seed `EXCUR_AX` / `EXCUR_AXNR`).
    pub excursion: usize,
}

impl Default for AxisMap {
    /// Plane X/Y, excursion Z (seed §2.3 default).
    fn default() -> Self {
        Self {
            plane: [0, 1],
            excursion: 2,
        }
    }
}

impl AxisMap {
    fn is_valid(&self) -> bool {
        let [a, b] = self.plane;
        let c = self.excursion;
        a < 3 && b < 3 && c < 3 && a != b && b != c && a != c
    }
}

/// A workspace or protection area: planar shape × excursion range, with its axis map.
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    shape: AreaShape,
    min_excur: f64,
    max_excur: f64,
    axes: AxisMap,
}

impl Area {
    /// `MIN_EXCUR < MAX_EXCUR`, both finite; default axis map (X/Y plane, Z excursion).
    pub fn new(shape: AreaShape, min_excur: f64, max_excur: f64) -> Result<Self, AreaError> {
        if !(min_excur.is_finite() && max_excur.is_finite() && min_excur < max_excur) {
            return Err(AreaError::InvalidExcursion {
                min: min_excur,
                max: max_excur,
            });
        }
        Ok(Self {
            shape,
            min_excur,
            max_excur,
            axes: AxisMap::default(),
        })
    }

    /// Replaces the axis map; it must be a permutation of 0, 1, 2.
    pub fn with_axes(mut self, axes: AxisMap) -> Result<Self, AreaError> {
        if !axes.is_valid() {
            return Err(AreaError::InvalidAxisMap([
                axes.plane[0],
                axes.plane[1],
                axes.excursion,
            ]));
        }
        self.axes = axes;
        Ok(self)
    }

    /// The planar contour.
    pub fn shape(&self) -> &AreaShape {
        &self.shape
    }

    /// `[MIN_EXCUR, MAX_EXCUR]`.
    pub fn excursion(&self) -> [f64; 2] {
        [self.min_excur, self.max_excur]
    }

    /// The axis map.
    pub fn axes(&self) -> AxisMap {
        self.axes
    }
}

/// Circular interpolation plane, also the machining plane of a control area (DIN 66025;
/// FCT-C14 §3.1.1 "the first two main axes of the active machining plane").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Plane {
    /// X/Y plane, angle from +X towards +Y, helix axis Z.
    #[default]
    G17,
    /// Z/X plane, angle from +Z towards +X, helix axis Y.
    G18,
    /// Y/Z plane, angle from +Y towards +Z, helix axis X.
    G19,
}

impl Plane {
    /// (first axis, second axis, normal axis) as coordinate indices (0 = X, 1 = Y, 2 = Z, or
    /// the 1st / 2nd / 3rd main axis): G17 (0, 1, 2), G18 (2, 0, 1), G19 (1, 2, 0).
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Plane::G17 => (0, 1, 2),
            Plane::G18 => (2, 0, 1),
            Plane::G19 => (1, 2, 0),
        }
    }
}

impl std::fmt::Display for Plane {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Plane::G17 => "G17",
            Plane::G18 => "G18",
            Plane::G19 => "G19",
        })
    }
}

/// Direction of an arc, viewed from the positive normal axis of its plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArcDir {
    /// G02: decreasing angle.
    Cw,
    /// G03: increasing angle.
    Ccw,
}

/// A straight path element (G00 / G01).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// Start point (X, Y, Z).
    pub from: [f64; 3],
    /// End point (X, Y, Z).
    pub to: [f64; 3],
}

/// A circular arc (G02 / G03) in `plane`. Angles in radians, measured in the plane from its
/// first axis towards its second (see [`Plane`]). If `end_angle ≡ start_angle` (mod 2π, within
/// 1e-12 rad) the arc is a full circle. The point at angle `a` is
/// `center + radius·(cos a·e1 + sin a·e2)`; the centre's normal-axis coordinate is the arc's
/// height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arc {
    /// Plane of the arc.
    pub plane: Plane,
    /// Centre (X, Y, Z).
    pub center: [f64; 3],
    /// Radius, > 0.
    pub radius: f64,
    /// Start angle \[rad\].
    pub start_angle: f64,
    /// End angle \[rad\].
    pub end_angle: f64,
    /// Direction.
    pub dir: ArcDir,
}

/// A helix: `arc` plus linear motion of `rise` along the arc plane's normal axis, starting at
/// the centre's normal-axis coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Helix {
    /// The arc in its plane.
    pub arc: Arc,
    /// Displacement along the normal axis over the whole arc.
    pub rise: f64,
}

/// One motion block's path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PathElement {
    /// Straight line.
    Line(Line),
    /// Arc.
    Arc(Arc),
    /// Helix.
    Helix(Helix),
}

impl From<Line> for PathElement {
    fn from(l: Line) -> Self {
        PathElement::Line(l)
    }
}
impl From<Arc> for PathElement {
    fn from(a: Arc) -> Self {
        PathElement::Arc(a)
    }
}
impl From<Helix> for PathElement {
    fn from(h: Helix) -> Self {
        PathElement::Helix(h)
    }
}

impl PathElement {
    /// The point at parameter `s ∈ [0, 1]` (0 = start, 1 = end; arcs at constant angular rate).
    pub fn point_at(&self, s: f64) -> [f64; 3] {
        match Curve::of(self) {
            Some(c) => c.eval(s),
            None => [f64::NAN; 3],
        }
    }
}

/// What a violation is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViolationKind {
    /// The path touches or enters a protection area (within `tol`).
    ProtectionEntered,
    /// The path leaves the union of the active workspaces (by more than `tol`).
    WorkspaceLeft,
    /// A path or tolerance value is NaN / infinite, or an arc radius is not > 0.
    InvalidInput,
}

/// A rejected path (seed §2.3 path check).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaViolation {
    /// Index into the `protections` slice (ProtectionEntered) or the `workspaces` slice
    /// (WorkspaceLeft: the workspace the path was in just before leaving the union; `None` if
    /// the path starts outside every workspace). `None` for InvalidInput.
    pub area_index: Option<usize>,
    /// Kind.
    pub kind: ViolationKind,
    /// The first point of the path where the violation begins (on the tolerance boundary);
    /// NaN for InvalidInput.
    pub first_point: [f64; 3],
}

/// `true` if the path touches or enters `area` enlarged by `tol` (the protection-area rule;
/// see the module docs). Non-finite input or negative `tol` gives `true` (conservative).
pub fn intersects_interior(path: &PathElement, area: &Area, tol: f64) -> bool {
    if !(tol.is_finite() && tol >= 0.0) {
        return true;
    }
    match Curve::of(path) {
        Some(c) => first_hit(&c, area, tol).is_some(),
        None => true,
    }
}

/// `true` if every point of the path lies in `area` enlarged by `tol` (the workspace rule; see
/// the module docs). Non-finite input or negative `tol` gives `false` (conservative).
pub fn stays_inside(path: &PathElement, area: &Area, tol: f64) -> bool {
    if !(tol.is_finite() && tol >= 0.0) {
        return false;
    }
    match Curve::of(path) {
        Some(c) => first_exit(&c, &[area], tol).is_none(),
        None => false,
    }
}

/// The seed's monitoring semantics for one block: the path must not touch any protection area
/// (protection overrides workspace) and, if at least one workspace is given, must stay inside
/// the *union* of the workspaces (seed Fig. 7: overlapping workspaces let the path move from one
/// to the next). No workspaces = no workspace restriction. On several violations the one that
/// begins first along the path is reported (a protection area wins a tie).
pub fn path_allowed(
    path: &PathElement,
    workspaces: &[Area],
    protections: &[Area],
    tol: f64,
) -> Result<(), AreaViolation> {
    let invalid = AreaViolation {
        area_index: None,
        kind: ViolationKind::InvalidInput,
        first_point: [f64::NAN; 3],
    };
    if !(tol.is_finite() && tol >= 0.0) {
        return Err(invalid);
    }
    let Some(c) = Curve::of(path) else {
        return Err(invalid);
    };
    let mut best: Option<(f64, AreaViolation)> = None;
    for (i, a) in protections.iter().enumerate() {
        if let Some(s) = first_hit(&c, a, tol) {
            if best.as_ref().is_none_or(|(b, _)| s < *b) {
                best = Some((
                    s,
                    AreaViolation {
                        area_index: Some(i),
                        kind: ViolationKind::ProtectionEntered,
                        first_point: c.eval(s),
                    },
                ));
            }
        }
    }
    if !workspaces.is_empty() {
        let refs: Vec<&Area> = workspaces.iter().collect();
        if let Some((s, idx)) = first_exit(&c, &refs, tol) {
            if best.as_ref().is_none_or(|(b, _)| s < *b) {
                best = Some((
                    s,
                    AreaViolation {
                        area_index: idx,
                        kind: ViolationKind::WorkspaceLeft,
                        first_point: c.eval(s),
                    },
                ));
            }
        }
    }
    match best {
        Some((_, v)) => Err(v),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// Internals.

type P2 = [f64; 2];

fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}
fn dot(a: P2, b: P2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn orient(a: P2, b: P2, c: P2) -> f64 {
    cross(sub(b, a), sub(c, a))
}

/// Closed segments [a,b] and [c,d] share a point (used for polygon validation only).
fn segments_touch(a: P2, b: P2, c: P2, d: P2) -> bool {
    let o1 = orient(a, b, c);
    let o2 = orient(a, b, d);
    let o3 = orient(c, d, a);
    let o4 = orient(c, d, b);
    let on = |p: P2, q: P2, r: P2| {
        r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0))
        && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0))
    {
        return true;
    }
    (o1 == 0.0 && on(a, b, c))
        || (o2 == 0.0 && on(a, b, d))
        || (o3 == 0.0 && on(c, d, a))
        || (o4 == 0.0 && on(c, d, b))
}

fn point_segment_dist2(p: P2, a: P2, b: P2) -> f64 {
    let e = sub(b, a);
    let w = sub(p, a);
    let l2 = dot(e, e);
    let t = if l2 > 0.0 {
        (dot(w, e) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + t * e[0] - p[0], a[1] + t * e[1] - p[1]];
    dot(q, q)
}

/// Crossing-number point-in-polygon (boundary points may go either way; the tolerance band
/// makes that irrelevant).
fn pip(v: &[P2], p: P2) -> bool {
    let mut inside = false;
    let n = v.len();
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (v[i], v[j]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// Membership of a planar point in the shape enlarged by `t` (shrunk if `t < 0`).
fn planar_member(shape: &AreaShape, p: P2, t: f64) -> bool {
    match shape {
        AreaShape::Circle(c) => {
            let r = c.radius + t;
            if r < 0.0 {
                return false;
            }
            let d = sub(p, c.center);
            dot(d, d) <= r * r
        }
        AreaShape::Polygon(poly) => {
            let v = &poly.v;
            let n = v.len();
            let inside = pip(v, p);
            if t >= 0.0 {
                if inside {
                    return true;
                }
                let t2 = t * t;
                (0..n).any(|i| point_segment_dist2(p, v[i], v[(i + 1) % n]) <= t2)
            } else {
                if !inside {
                    return false;
                }
                let t2 = t * t;
                (0..n).all(|i| point_segment_dist2(p, v[i], v[(i + 1) % n]) >= t2)
            }
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Coord {
    /// `a + b·s`
    Lin { a: f64, b: f64 },
    /// `a + c·cos θ(s) + d·sin θ(s)`
    Harm { a: f64, c: f64, d: f64 },
}

/// A path element as three coordinate functions of `s ∈ [0, 1]`, `θ(s) = th0 + s·sweep`.
#[derive(Clone, Copy, Debug)]
struct Curve {
    k: [Coord; 3],
    th0: f64,
    sweep: f64,
    radius: f64,
}

impl Curve {
    fn of(path: &PathElement) -> Option<Curve> {
        let fin3 = |p: &[f64; 3]| p.iter().all(|x| x.is_finite());
        match path {
            PathElement::Line(l) => {
                if !(fin3(&l.from) && fin3(&l.to)) {
                    return None;
                }
                let k = std::array::from_fn(|i| Coord::Lin {
                    a: l.from[i],
                    b: l.to[i] - l.from[i],
                });
                Some(Curve {
                    k,
                    th0: 0.0,
                    sweep: 0.0,
                    radius: 0.0,
                })
            }
            PathElement::Arc(a) => Self::arc(a, 0.0),
            PathElement::Helix(h) => Self::arc(&h.arc, h.rise),
        }
    }

    fn arc(a: &Arc, rise: f64) -> Option<Curve> {
        if !(a.center.iter().all(|x| x.is_finite())
            && a.radius.is_finite()
            && a.radius > 0.0
            && a.start_angle.is_finite()
            && a.end_angle.is_finite()
            && rise.is_finite())
        {
            return None;
        }
        let (e1, e2, n) = a.plane.axes();
        let mut sweep = match a.dir {
            ArcDir::Ccw => (a.end_angle - a.start_angle).rem_euclid(TAU),
            ArcDir::Cw => -(a.start_angle - a.end_angle).rem_euclid(TAU),
        };
        if sweep.abs() < 1e-12 || sweep.abs() > TAU - 1e-12 {
            sweep = if a.dir == ArcDir::Ccw { TAU } else { -TAU };
        }
        let mut k = [Coord::Lin { a: 0.0, b: 0.0 }; 3];
        k[e1] = Coord::Harm {
            a: a.center[e1],
            c: a.radius,
            d: 0.0,
        };
        k[e2] = Coord::Harm {
            a: a.center[e2],
            c: 0.0,
            d: a.radius,
        };
        k[n] = Coord::Lin {
            a: a.center[n],
            b: rise,
        };
        Some(Curve {
            k,
            th0: a.start_angle,
            sweep,
            radius: a.radius,
        })
    }

    fn coord(&self, i: usize, s: f64) -> f64 {
        match self.k[i] {
            Coord::Lin { a, b } => a + b * s,
            Coord::Harm { a, c, d } => {
                let th = self.th0 + s * self.sweep;
                a + c * th.cos() + d * th.sin()
            }
        }
    }

    fn eval(&self, s: f64) -> [f64; 3] {
        [self.coord(0, s), self.coord(1, s), self.coord(2, s)]
    }

    /// Angle → parameter on this curve's `θ` (None if outside the sweep).
    fn theta_to_s(&self, th: f64) -> Option<f64> {
        angle_to_s(th, self.th0, self.sweep)
    }
}

fn angle_to_s(ang: f64, a0: f64, sweep: f64) -> Option<f64> {
    if !ang.is_finite() || sweep == 0.0 {
        return None;
    }
    let d = if sweep > 0.0 {
        (ang - a0).rem_euclid(TAU)
    } else {
        (a0 - ang).rem_euclid(TAU)
    };
    let s = d / sweep.abs();
    if s <= 1.0 {
        Some(s)
    } else if d > TAU - 1e-12 {
        Some(0.0)
    } else {
        None
    }
}

/// Planar projection of a curve for one area.
enum Planar {
    /// `p + s·d`
    Seg { p: P2, d: P2 },
    /// `c + r·(cos φ, sin φ)`, `φ = phi0 + s·sweep`
    Circ {
        c: P2,
        r: f64,
        phi0: f64,
        sweep: f64,
    },
    /// Coordinate `h` is `a + c cos θ + d sin θ` (θ of the curve), the other is constant `f`.
    Harm1 {
        h: usize,
        f: f64,
        a: f64,
        c: f64,
        d: f64,
    },
    /// Non-circular projection (perpendicular helix): needs chords.
    Curved,
}

fn planar_of(cv: &Curve, axes: AxisMap) -> Planar {
    let ku = cv.k[axes.plane[0]];
    let kv = cv.k[axes.plane[1]];
    match (ku, kv) {
        (Coord::Lin { a: au, b: bu }, Coord::Lin { a: av, b: bv }) => Planar::Seg {
            p: [au, av],
            d: [bu, bv],
        },
        (
            Coord::Harm {
                a: au,
                c: cu,
                d: du,
            },
            Coord::Harm {
                a: av,
                c: cv2,
                d: dv,
            },
        ) => {
            let c = [au, av];
            let sig = if cu * dv - du * cv2 >= 0.0 { 1.0 } else { -1.0 };
            let p0 = [
                cu * cv.th0.cos() + du * cv.th0.sin(),
                cv2 * cv.th0.cos() + dv * cv.th0.sin(),
            ];
            Planar::Circ {
                c,
                r: cv.radius,
                phi0: p0[1].atan2(p0[0]),
                sweep: sig * cv.sweep,
            }
        }
        (Coord::Harm { a, c, d }, Coord::Lin { a: f, b: 0.0 }) => {
            Planar::Harm1 { h: 0, f, a, c, d }
        }
        (Coord::Lin { a: f, b: 0.0 }, Coord::Harm { a, c, d }) => {
            Planar::Harm1 { h: 1, f, a, c, d }
        }
        _ => Planar::Curved,
    }
}

/// Parameters `s` where `a + c cos θ(s) + d sin θ(s) = val`, plus the extremes.
fn harmonic_roots(cv: &Curve, a: f64, c: f64, d: f64, val: f64, out: &mut Vec<f64>) {
    let r = c.hypot(d);
    if r == 0.0 {
        return;
    }
    let al = d.atan2(c);
    let x = (val - a) / r;
    if x.abs() <= 1.0 + 1e-12 {
        let ac = x.clamp(-1.0, 1.0).acos();
        for th in [al + ac, al - ac] {
            if let Some(s) = cv.theta_to_s(th) {
                out.push(s);
            }
        }
    }
}

fn harmonic_extremes(cv: &Curve, c: f64, d: f64, out: &mut Vec<f64>) {
    let al = d.atan2(c);
    for th in [al, al + PI] {
        if let Some(s) = cv.theta_to_s(th) {
            out.push(s);
        }
    }
}

/// A boundary primitive of an enlarged area.
#[derive(Clone, Copy)]
enum Prim {
    Seg(P2, P2),
    Circ(P2, f64),
}

const T_SLACK: f64 = 1e-9;

/// Breaks of the segment `p + s d` (local parameter, not filtered) with a primitive.
fn seg_prim_breaks(p: P2, d: P2, prim: Prim, out: &mut Vec<f64>) {
    let dd = dot(d, d);
    if dd == 0.0 {
        return;
    }
    match prim {
        Prim::Seg(a, b) => {
            let e = sub(b, a);
            let w = sub(a, p);
            let den = cross(d, e);
            let ee = dot(e, e);
            if den.abs() > 1e-9 * (dd * ee).sqrt() {
                let s = cross(w, e) / den;
                let t = cross(w, d) / den;
                if (-T_SLACK..=1.0 + T_SLACK).contains(&t) {
                    out.push(s);
                }
            } else {
                out.push(dot(w, d) / dd);
                out.push(dot(sub(b, p), d) / dd);
            }
        }
        Prim::Circ(c, rho) => {
            let f = sub(p, c);
            let b = dot(f, d);
            let cc = dot(f, f) - rho * rho;
            let disc = b * b - dd * cc;
            if disc >= 0.0 {
                let q = disc.sqrt();
                out.push((-b - q) / dd);
                out.push((-b + q) / dd);
            }
            out.push(-b / dd);
        }
    }
}

/// Breaks (as angles) of the circle `c, r` with a primitive.
fn circ_prim_angles(c: P2, r: f64, prim: Prim, out: &mut Vec<f64>) {
    match prim {
        Prim::Seg(a, b) => {
            let e = sub(b, a);
            let ee = dot(e, e);
            if ee == 0.0 {
                return;
            }
            let tf = dot(sub(c, a), e) / ee;
            let foot = [a[0] + tf * e[0], a[1] + tf * e[1]];
            let hv = sub(foot, c);
            let h2 = dot(hv, hv);
            let in_t = |t: f64| (-T_SLACK..=1.0 + T_SLACK).contains(&t);
            if h2 <= r * r {
                let half = (r * r - h2).sqrt() / ee.sqrt();
                for t in [tf - half, tf + half] {
                    if in_t(t) {
                        let x = [a[0] + t * e[0] - c[0], a[1] + t * e[1] - c[1]];
                        out.push(x[1].atan2(x[0]));
                    }
                }
            }
            if h2 > 0.0 && in_t(tf) {
                out.push(hv[1].atan2(hv[0]));
            }
        }
        Prim::Circ(cc, rho) => {
            let dv = sub(cc, c);
            let dist = dot(dv, dv).sqrt();
            if dist == 0.0 {
                return;
            }
            let base = dv[1].atan2(dv[0]);
            let x = (r * r + dist * dist - rho * rho) / (2.0 * r * dist);
            if x.abs() <= 1.0 {
                let ac = x.acos();
                out.push(base + ac);
                out.push(base - ac);
            }
            out.push(base);
        }
    }
}

/// Breaks in `s` of the planar projection with one primitive (unfiltered `s`).
fn planar_breaks(cv: &Curve, pl: &Planar, prim: Prim, out: &mut Vec<f64>) {
    match *pl {
        Planar::Seg { p, d } => seg_prim_breaks(p, d, prim, out),
        Planar::Circ { c, r, phi0, sweep } => {
            let start = out.len();
            circ_prim_angles(c, r, prim, out);
            let mut w = start;
            for i in start..out.len() {
                if let Some(s) = angle_to_s(out[i], phi0, sweep) {
                    out[w] = s;
                    w += 1;
                }
            }
            out.truncate(w);
        }
        Planar::Harm1 { h, f, a, c, d } => {
            let r = c.hypot(d);
            let mut p = [0.0; 2];
            p[h] = a - r;
            p[1 - h] = f;
            let mut dir = [0.0; 2];
            dir[h] = 2.0 * r;
            let mut ts = Vec::with_capacity(4);
            seg_prim_breaks(p, dir, prim, &mut ts);
            for t in ts {
                if (-T_SLACK..=1.0 + T_SLACK).contains(&t) {
                    harmonic_roots(cv, a, c, d, a - r + 2.0 * r * t, out);
                }
            }
        }
        Planar::Curved => {}
    }
}

/// Conservative planar bounding box of the projection.
fn planar_bbox(pl: &Planar) -> [f64; 4] {
    match *pl {
        Planar::Seg { p, d } => {
            let q = [p[0] + d[0], p[1] + d[1]];
            [
                p[0].min(q[0]),
                p[1].min(q[1]),
                p[0].max(q[0]),
                p[1].max(q[1]),
            ]
        }
        Planar::Circ { c, r, .. } => [c[0] - r, c[1] - r, c[0] + r, c[1] + r],
        Planar::Harm1 { h, f, a, c, d } => {
            let r = c.hypot(d);
            let mut b = [0.0; 4];
            b[h] = a - r;
            b[h + 2] = a + r;
            b[1 - h] = f;
            b[3 - h] = f;
            b
        }
        Planar::Curved => [
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::INFINITY,
        ],
    }
}

fn boxes_overlap(a: &[f64; 4], b: &[f64; 4], grow: f64) -> bool {
    a[0] <= b[2] + grow && b[0] <= a[2] + grow && a[1] <= b[3] + grow && b[1] <= a[3] + grow
}

/// Collects the break parameters of the curve against area `ar` enlarged by `t` (unsorted,
/// filtered to (0, 1)). Returns false if the planar bounding boxes do not even overlap (then
/// the curve is outside the enlarged area everywhere).
fn area_breaks(cv: &Curve, pl: &Planar, ar: &Area, t: f64, out: &mut Vec<f64>) -> bool {
    let pb = planar_bbox(pl);
    let at = t.abs();
    let start = out.len();
    match &ar.shape {
        AreaShape::Circle(c) => {
            let rr = c.radius + t;
            if rr <= 0.0 {
                return false;
            }
            let cb = [
                c.center[0] - rr,
                c.center[1] - rr,
                c.center[0] + rr,
                c.center[1] + rr,
            ];
            if !boxes_overlap(&pb, &cb, 0.0) {
                return false;
            }
            planar_breaks(cv, pl, Prim::Circ(c.center, rr), out);
        }
        AreaShape::Polygon(poly) => {
            if !boxes_overlap(&pb, &poly.bbox, at) {
                return false;
            }
            let v = &poly.v;
            let n = v.len();
            for i in 0..n {
                let (a, b) = (v[i], v[(i + 1) % n]);
                let eb = [
                    a[0].min(b[0]),
                    a[1].min(b[1]),
                    a[0].max(b[0]),
                    a[1].max(b[1]),
                ];
                if !boxes_overlap(&pb, &eb, at) {
                    continue;
                }
                if at == 0.0 {
                    planar_breaks(cv, pl, Prim::Seg(a, b), out);
                    continue;
                }
                let e = sub(b, a);
                let l = dot(e, e).sqrt();
                let nrm = [-e[1] / l * at, e[0] / l * at];
                for sg in [1.0, -1.0] {
                    let o = [sg * nrm[0], sg * nrm[1]];
                    planar_breaks(
                        cv,
                        pl,
                        Prim::Seg([a[0] + o[0], a[1] + o[1]], [b[0] + o[0], b[1] + o[1]]),
                        out,
                    );
                }
                planar_breaks(cv, pl, Prim::Circ(a, at), out);
                planar_breaks(cv, pl, Prim::Circ(b, at), out);
            }
        }
    }
    // Excursion levels.
    let w = ar.axes.excursion;
    for lvl in [ar.min_excur - t, ar.max_excur + t] {
        match cv.k[w] {
            Coord::Lin { a, b } => {
                if b != 0.0 {
                    out.push((lvl - a) / b);
                }
            }
            Coord::Harm { a, c, d } => {
                harmonic_roots(cv, a, c, d, lvl, out);
                harmonic_extremes(cv, c, d, out);
            }
        }
    }
    let mut wr = start;
    for i in start..out.len() {
        let s = out[i];
        if s > 0.0 && s < 1.0 {
            out[wr] = s;
            wr += 1;
        }
    }
    out.truncate(wr);
    true
}

fn member(cv: &Curve, ar: &Area, t: f64, s: f64) -> bool {
    let p = cv.eval(s);
    let w = p[ar.axes.excursion];
    if !(w >= ar.min_excur - t && w <= ar.max_excur + t) {
        return false;
    }
    planar_member(&ar.shape, [p[ar.axes.plane[0]], p[ar.axes.plane[1]]], t)
}

/// Chord count and chordal deviation for a curve that needs segmentation.
fn chords(cv: &Curve, tol: f64) -> (usize, f64) {
    let r = cv.radius;
    let e_want = tol / 2.0;
    let n_needed = if e_want > 0.0 && e_want < r {
        let step = 2.0 * (1.0 - e_want / r).acos();
        (cv.sweep.abs() / step).ceil()
    } else if e_want >= r {
        1.0
    } else {
        f64::INFINITY
    };
    let n = if n_needed.is_finite() {
        (n_needed as usize).clamp(1, MAX_CHORDS)
    } else {
        MAX_CHORDS
    };
    let e = r * (1.0 - (cv.sweep.abs() / (2.0 * n as f64)).cos());
    (n, e.max(e_want.min(r)))
}

fn chord(cv: &Curve, n: usize, k: usize) -> Curve {
    let s0 = k as f64 / n as f64;
    let s1 = (k + 1) as f64 / n as f64;
    let (a, b) = (cv.eval(s0), cv.eval(s1));
    Curve {
        k: std::array::from_fn(|i| Coord::Lin {
            a: a[i],
            b: b[i] - a[i],
        }),
        th0: 0.0,
        sweep: 0.0,
        radius: 0.0,
    }
}

fn sort_dedup(v: &mut Vec<f64>) {
    v.sort_unstable_by(|a, b| a.total_cmp(b));
    v.dedup();
}

/// First parameter where the curve is in `ar` enlarged by `t`.
fn first_hit(cv: &Curve, ar: &Area, t: f64) -> Option<f64> {
    if let Planar::Curved = planar_of(cv, ar.axes) {
        let (n, e) = chords(cv, t);
        for k in 0..n {
            let ch = chord(cv, n, k);
            if let Some(s) = first_hit(&ch, ar, t + e) {
                return Some((k as f64 + s) / n as f64);
            }
        }
        return None;
    }
    let pl = planar_of(cv, ar.axes);
    let mut br = Vec::new();
    if !area_breaks(cv, &pl, ar, t, &mut br) {
        return None;
    }
    sort_dedup(&mut br);
    let mut prev = 0.0;
    if member(cv, ar, t, 0.0) {
        return Some(0.0);
    }
    for &b in br.iter().chain(std::iter::once(&1.0)) {
        if member(cv, ar, t, 0.5 * (prev + b)) {
            return Some(prev);
        }
        if member(cv, ar, t, b) {
            return Some(b);
        }
        prev = b;
    }
    None
}

/// First parameter where the curve leaves the union of `areas` enlarged by `t`, with the index
/// of the area it was in just before.
fn first_exit(cv: &Curve, areas: &[&Area], t: f64) -> Option<(f64, Option<usize>)> {
    if areas
        .iter()
        .any(|a| matches!(planar_of(cv, a.axes), Planar::Curved))
    {
        let (n, e) = chords(cv, t);
        let mut last = None;
        for k in 0..n {
            let ch = chord(cv, n, k);
            match first_exit_exact(&ch, areas, t - e, last) {
                Ok(l) => last = l,
                Err((s, idx)) => return Some(((k as f64 + s) / n as f64, idx)),
            }
        }
        return None;
    }
    first_exit_exact(cv, areas, t, None).err()
}

/// Ok(index of the area containing the end) or Err((exit parameter, area before)).
#[allow(clippy::type_complexity)]
fn first_exit_exact(
    cv: &Curve,
    areas: &[&Area],
    t: f64,
    mut last: Option<usize>,
) -> Result<Option<usize>, (f64, Option<usize>)> {
    let mut br = Vec::new();
    let mut near: Vec<usize> = Vec::with_capacity(areas.len());
    for (i, a) in areas.iter().enumerate() {
        if matches!(planar_of(cv, a.axes), Planar::Curved) {
            // Only reachable for chords, which are lines: cannot happen.
            near.push(i);
            continue;
        }
        let pl = planar_of(cv, a.axes);
        if area_breaks(cv, &pl, a, t, &mut br) {
            near.push(i);
        }
    }
    sort_dedup(&mut br);
    let mut prev = 0.0;
    for &b in br.iter().chain(std::iter::once(&1.0)) {
        let m = 0.5 * (prev + b);
        // Prefer the area we are already in, so the reported index is stable.
        let hit = last
            .filter(|&l| near.contains(&l) && member(cv, areas[l], t, m))
            .or_else(|| near.iter().copied().find(|&i| member(cv, areas[i], t, m)));
        match hit {
            Some(i) => last = Some(i),
            None => return Err((prev, last)),
        }
        prev = b;
    }
    Ok(last)
}
