//! Path-versus-area geometry (seed 000 FCT-C14 §2.3, issue 7 item 4). Expected values are
//! computed by hand (in the comments) or by a dense-sampling oracle written here, never by the
//! code under test.

use fieldprobe::core::monitor::area_geom::{
    intersects_interior, path_allowed, stays_inside, Arc, ArcDir, Area, AreaError, AreaShape,
    AxisMap, Circle, Helix, Line, PathElement, Plane, Polygon, PolygonError, ViolationKind,
};
use proptest::prelude::*;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

const TOL: f64 = 1e-3;

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Area {
    let p = Polygon::new(&[[x0, y0], [x1, y0], [x1, y1], [x0, y1]]).unwrap();
    Area::new(AreaShape::Polygon(p), -50.0, 50.0).unwrap()
}

fn circle(cx: f64, cy: f64, r: f64) -> Area {
    Area::new(
        AreaShape::Circle(Circle::new([cx, cy], r).unwrap()),
        -50.0,
        50.0,
    )
    .unwrap()
}

fn line(a: [f64; 3], b: [f64; 3]) -> PathElement {
    PathElement::Line(Line { from: a, to: b })
}

fn arc17(r: f64, a0: f64, a1: f64, dir: ArcDir) -> PathElement {
    PathElement::Arc(Arc {
        plane: Plane::G17,
        center: [0.0, 0.0, 0.0],
        radius: r,
        start_angle: a0,
        end_angle: a1,
        dir,
    })
}

#[track_caller]
fn close(a: [f64; 3], b: [f64; 3]) {
    for i in 0..3 {
        assert!((a[i] - b[i]).abs() < 1e-9, "{a:?} != {b:?}");
    }
}

// ---- polygon validation ---------------------------------------------------------------------

#[test]
fn seed_poly_example_is_valid() {
    // Seed 000 §3.1.1, N20..N130: 11 points, last = first.
    let pts = [
        [-150.0, 75.0],
        [-50.0, 150.0],
        [50.0, 150.0],
        [150.0, 75.0],
        [150.0, 0.0],
        [50.0, 0.0],
        [50.0, 75.0],
        [-50.0, 75.0],
        [-50.0, 0.0],
        [-150.0, 0.0],
        [-150.0, 75.0],
    ];
    let p = Polygon::new(&pts).unwrap();
    assert_eq!(p.vertices().len(), 10);
    // Implicit closure gives the same polygon.
    assert_eq!(Polygon::new(&pts[..10]).unwrap(), p);
}

#[test]
fn polygon_errors_name_the_culprit() {
    assert_eq!(
        Polygon::new(&[[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]]),
        Err(PolygonError::TooFewVertices { count: 2 })
    );
    let many: Vec<[f64; 2]> = (0..21)
        .map(|i| {
            let a = i as f64 * TAU / 21.0;
            [a.cos(), a.sin()]
        })
        .collect();
    assert_eq!(
        Polygon::new(&many),
        Err(PolygonError::TooManyVertices { count: 21 })
    );
    assert_eq!(
        Polygon::new(&[[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
        Err(PolygonError::ZeroLengthEdge { edge: 1 })
    );
    assert_eq!(
        Polygon::new(&[[0.0, 0.0], [f64::NAN, 0.0], [0.0, 1.0]]),
        Err(PolygonError::NonFiniteVertex { vertex: 1 })
    );
    // Bow tie: edge 0 (0,0)-(10,10) crosses edge 2 (10,0)-(0,10).
    assert_eq!(
        Polygon::new(&[[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]]),
        Err(PolygonError::SelfIntersection {
            edge_a: 0,
            edge_b: 2
        })
    );
    // Fold back: edge 1 (10,0)->(5,0) runs back over edge 0.
    assert_eq!(
        Polygon::new(&[[0.0, 0.0], [10.0, 0.0], [5.0, 0.0], [5.0, 5.0]]),
        Err(PolygonError::SelfIntersection {
            edge_a: 0,
            edge_b: 1
        })
    );
    // Vertex 4 touches edge 1 (a non-adjacent edge) at (10,5).
    assert_eq!(
        Polygon::new(&[
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 10.0],
            [0.0, 10.0],
            [10.0, 5.0],
            [-5.0, 5.0]
        ]),
        Err(PolygonError::SelfIntersection {
            edge_a: 1,
            edge_b: 3
        })
    );
}

#[test]
fn area_errors() {
    assert!(matches!(
        Circle::new([0.0, 0.0], 0.0),
        Err(AreaError::InvalidCircle { .. })
    ));
    let c = AreaShape::Circle(Circle::new([0.0, 0.0], 1.0).unwrap());
    assert!(matches!(
        Area::new(c.clone(), 5.0, 5.0),
        Err(AreaError::InvalidExcursion { .. })
    ));
    let a = Area::new(c, 0.0, 1.0).unwrap();
    assert!(matches!(
        a.with_axes(AxisMap {
            plane: [0, 0],
            excursion: 2
        }),
        Err(AreaError::InvalidAxisMap(_))
    ));
}

// ---- hand-computed paths --------------------------------------------------------------------

#[test]
fn line_crossing_square() {
    let sq = rect(0.0, 0.0, 10.0, 10.0);
    let l = line([-5.0, 5.0, 0.0], [15.0, 5.0, 0.0]);
    assert!(intersects_interior(&l, &sq, TOL));
    assert!(!stays_inside(&l, &sq, TOL));
    // As a protection area the violation begins at the tolerance boundary x = -tol.
    let v = path_allowed(&l, &[], std::slice::from_ref(&sq), TOL).unwrap_err();
    assert_eq!(v.kind, ViolationKind::ProtectionEntered);
    assert_eq!(v.area_index, Some(0));
    close(v.first_point, [-TOL, 5.0, 0.0]);
    // Passing 2·tol beside the square is fine, a line inside stays inside.
    let beside = line([-5.0, 10.0 + 2.0 * TOL, 0.0], [15.0, 10.0 + 2.0 * TOL, 0.0]);
    assert!(!intersects_interior(&beside, &sq, TOL));
    assert!(stays_inside(
        &line([1.0, 1.0, 0.0], [9.0, 9.0, 0.0]),
        &sq,
        TOL
    ));
    // Running exactly along the boundary: allowed in a workspace, a violation of a protection.
    let along = line([0.0, 0.0, 0.0], [10.0, 0.0, 0.0]);
    assert!(stays_inside(&along, &sq, TOL));
    assert!(intersects_interior(&along, &sq, TOL));
    // Excursion: same line at z = 50.5 misses the prism [-50, 50].
    assert!(!intersects_interior(
        &line([-5.0, 5.0, 50.5], [15.0, 5.0, 50.5]),
        &sq,
        TOL
    ));
}

#[test]
fn line_tangent_to_circle_within_tol() {
    let c = circle(0.0, 0.0, 10.0);
    let y_in = 10.0 + 0.5 * TOL;
    let y_out = 10.0 + 2.0 * TOL;
    assert!(intersects_interior(
        &line([-20.0, y_in, 0.0], [20.0, y_in, 0.0]),
        &c,
        TOL
    ));
    assert!(!intersects_interior(
        &line([-20.0, y_out, 0.0], [20.0, y_out, 0.0]),
        &c,
        TOL
    ));
    // Workspace: a radial line ending 0.5 tol outside is inside the tolerance band.
    assert!(stays_inside(
        &line([0.0, 0.0, 0.0], [y_in, 0.0, 0.0]),
        &c,
        TOL
    ));
    assert!(!stays_inside(
        &line([0.0, 0.0, 0.0], [y_out, 0.0, 0.0]),
        &c,
        TOL
    ));
}

#[test]
fn arc_bulge_enters_protection_although_end_points_are_outside() {
    // Arc r = 10 around the origin from 45° to 135° CCW: end points (±7.071, 7.071), apex (0, 10).
    let a = arc17(10.0, FRAC_PI_4, 3.0 * FRAC_PI_4, ArcDir::Ccw);
    // Protection circle (0, 12) r = 3: end points are sqrt(7.071² + 4.929²) = 8.62 away,
    // the apex only 2.
    let pc = circle(0.0, 12.0, 3.0);
    assert!(intersects_interior(&a, &pc, TOL));
    let v = path_allowed(&a, &[], std::slice::from_ref(&pc), TOL).unwrap_err();
    // Entry where |p| = 10 and |p - (0,12)| = 3 + tol: y = (100 + 144 - ρ²) / 24, x > 0.
    let rho = 3.0 + TOL;
    let y = (244.0 - rho * rho) / 24.0;
    close(v.first_point, [(100.0 - y * y).sqrt(), y, 0.0]);
    // The same end points clockwise take the long way round (through (0,-10)): no violation.
    let long = arc17(10.0, FRAC_PI_4, 3.0 * FRAC_PI_4, ArcDir::Cw);
    assert!(!intersects_interior(&long, &pc, TOL));
    // Protection square [-2,2]x[9,13]: corners (±2, 9) are inside radius 10 only by the bulge.
    let ps = rect(-2.0, 9.0, 2.0, 13.0);
    assert!(intersects_interior(&a, &ps, TOL));
    assert!(!intersects_interior(&long, &ps, TOL));
}

#[test]
fn arc_leaves_workspace_only_at_apex() {
    let a = arc17(10.0, FRAC_PI_4, 3.0 * FRAC_PI_4, ArcDir::Ccw);
    let low = rect(-10.0, -5.0, 10.0, 9.5);
    let high = rect(-10.0, -5.0, 10.0, 10.5);
    assert!(!stays_inside(&a, &low, TOL));
    assert!(stays_inside(&a, &high, TOL));
    let v = path_allowed(&a, std::slice::from_ref(&low), &[], TOL).unwrap_err();
    assert_eq!(v.kind, ViolationKind::WorkspaceLeft);
    assert_eq!(v.area_index, Some(0));
    // Exit at y = 9.5 + tol on the circle, x > 0 (CCW from 45°).
    let y: f64 = 9.5 + TOL;
    close(v.first_point, [(100.0 - y * y).sqrt(), y, 0.0]);
}

#[test]
fn union_of_overlapping_workspaces_with_l_path() {
    // R1 = [0,10]x[0,4], R2 = [6,10]x[0,20], overlap [6,10]x[0,4] (seed Fig. 7).
    let ws = [rect(0.0, 0.0, 10.0, 4.0), rect(6.0, 0.0, 10.0, 20.0)];
    let leg1 = line([1.0, 2.0, 0.0], [8.0, 2.0, 0.0]);
    let leg2 = line([8.0, 2.0, 0.0], [8.0, 18.0, 0.0]);
    assert!(!stays_inside(&leg1, &ws[1], TOL));
    assert!(!stays_inside(&leg2, &ws[0], TOL));
    assert_eq!(path_allowed(&leg1, &ws, &[], TOL), Ok(()));
    assert_eq!(path_allowed(&leg2, &ws, &[], TOL), Ok(()));
    // The diagonal shortcut leaves R1 at y = 4 + tol: s = (2 + tol)/16, x = 1 + 7 s.
    let diag = line([1.0, 2.0, 0.0], [8.0, 18.0, 0.0]);
    let v = path_allowed(&diag, &ws, &[], TOL).unwrap_err();
    assert_eq!(v.kind, ViolationKind::WorkspaceLeft);
    assert_eq!(v.area_index, Some(0));
    let s = (2.0 + TOL) / 16.0;
    close(v.first_point, [1.0 + 7.0 * s, 4.0 + TOL, 0.0]);
    // No workspace active: no workspace restriction.
    assert_eq!(path_allowed(&diag, &[], &[], TOL), Ok(()));
    // Starting outside every workspace.
    let v = path_allowed(&line([-5.0, 2.0, 0.0], [1.0, 2.0, 0.0]), &ws, &[], TOL).unwrap_err();
    assert_eq!((v.kind, v.area_index), (ViolationKind::WorkspaceLeft, None));
}

#[test]
fn protection_inside_workspace_overrides() {
    let ws = [rect(0.0, 0.0, 100.0, 100.0)];
    let pr = [circle(50.0, 50.0, 10.0)];
    let through = line([10.0, 50.0, 0.0], [90.0, 50.0, 0.0]);
    let v = path_allowed(&through, &ws, &pr, TOL).unwrap_err();
    assert_eq!(v.kind, ViolationKind::ProtectionEntered);
    assert_eq!(v.area_index, Some(0));
    close(v.first_point, [40.0 - TOL, 50.0, 0.0]);
    assert_eq!(
        path_allowed(&line([10.0, 10.0, 0.0], [90.0, 10.0, 0.0]), &ws, &pr, TOL),
        Ok(())
    );
    // Leaving the workspace before reaching the protection area reports the workspace.
    let v = path_allowed(&line([50.0, 150.0, 0.0], [50.0, 50.0, 0.0]), &ws, &pr, TOL);
    assert_eq!(v.unwrap_err().kind, ViolationKind::WorkspaceLeft);
}

#[test]
fn helix_trimmed_by_excursion() {
    // Protection [5,15]x[-5,5], excursion [0,10]. A full-turn CCW helix r = 10 from (10,0,z0).
    // Planar overlap for θ in [0°,30°] and [330°,360°] (|10 sin θ| <= 5).
    let prot = Area::new(
        AreaShape::Polygon(
            Polygon::new(&[[5.0, -5.0], [15.0, -5.0], [15.0, 5.0], [5.0, 5.0]]).unwrap(),
        ),
        0.0,
        10.0,
    )
    .unwrap();
    let helix = |z0: f64, rise: f64| {
        PathElement::Helix(Helix {
            arc: Arc {
                plane: Plane::G17,
                center: [0.0, 0.0, z0],
                radius: 10.0,
                start_angle: 0.0,
                end_angle: 0.0,
                dir: ArcDir::Ccw,
            },
            rise,
        })
    };
    // z from 20 to -20: z in [16.7, 20] and [-20, -16.7] at the overlap -> trimmed away.
    let miss = helix(20.0, -40.0);
    assert!(!intersects_interior(&miss, &prot, TOL));
    // z from 25 to 5: z in [6.7, 5] for θ in [330°, 360°] -> hit, entering at y = -(5 + tol).
    let hit = helix(25.0, -20.0);
    let v = path_allowed(&hit, &[], std::slice::from_ref(&prot), TOL).unwrap_err();
    let th = TAU - (0.5 + TOL / 10.0).asin();
    close(
        v.first_point,
        [10.0 * th.cos(), 10.0 * th.sin(), 25.0 - 20.0 * th / TAU],
    );
}

#[test]
fn g18_arc_against_xy_area() {
    // ZX arc (angle from +Z towards +X), centre origin, r = 10, from 0 to π.
    let g18 = |dir| {
        PathElement::Arc(Arc {
            plane: Plane::G18,
            center: [0.0, 0.0, 0.0],
            radius: 10.0,
            start_angle: 0.0,
            end_angle: PI,
            dir,
        })
    };
    let sq = |lo: f64, hi: f64| {
        Area::new(
            AreaShape::Polygon(
                Polygon::new(&[[8.0, -1.0], [12.0, -1.0], [12.0, 1.0], [8.0, 1.0]]).unwrap(),
            ),
            lo,
            hi,
        )
        .unwrap()
    };
    // CCW passes (x=10, z=0) at θ = 90°: inside [8,12]x[-1,1] x [-1,1].
    let ccw = g18(ArcDir::Ccw);
    let v = path_allowed(&ccw, &[], &[sq(-1.0, 1.0)], TOL).unwrap_err();
    // Entry through the top excursion level z = 1 + tol (x = 9.95 is already in [8,12]).
    let z = 1.0 + TOL;
    close(v.first_point, [(100.0 - z * z).sqrt(), 0.0, z]);
    // CW goes through x = -10: no violation.
    assert!(!intersects_interior(&g18(ArcDir::Cw), &sq(-1.0, 1.0), TOL));
    // Excursion [7,9]: cos θ in [0.7,0.9] gives x = 10 sin θ in [4.36, 7.14] < 8: miss.
    assert!(!intersects_interior(&ccw, &sq(7.0, 9.0), TOL));
    // Excursion [5,6]: x in [8.0, 8.66]: hit.
    assert!(intersects_interior(&ccw, &sq(5.0, 6.0), TOL));
    // Area in the Z/X plane with Y as excursion (axis map): the arc itself is a circle there.
    let zx = Area::new(
        AreaShape::Circle(Circle::new([0.0, 0.0], 9.0).unwrap()),
        -1.0,
        1.0,
    )
    .unwrap()
    .with_axes(AxisMap {
        plane: [2, 0],
        excursion: 1,
    })
    .unwrap();
    assert!(!intersects_interior(&ccw, &zx, TOL));
    assert!(!stays_inside(&ccw, &zx, TOL));
}

#[test]
fn perpendicular_helix_is_segmented_conservatively() {
    // G18 helix r = 10 from 0 to π CCW, rise 2 along Y: (x, y, z) = (10 sin θ, 2θ/π, 10 cos θ).
    let h = PathElement::Helix(Helix {
        arc: Arc {
            plane: Plane::G18,
            center: [0.0, 0.0, 0.0],
            radius: 10.0,
            start_angle: 0.0,
            end_angle: PI,
            dir: ArcDir::Ccw,
        },
        rise: 2.0,
    });
    let area = |y0: f64, y1: f64| {
        Area::new(
            AreaShape::Polygon(
                Polygon::new(&[[8.0, y0], [12.0, y0], [12.0, y1], [8.0, y1]]).unwrap(),
            ),
            -1.0,
            1.0,
        )
        .unwrap()
    };
    // θ = 90°: (10, 1, 0) inside [8,12]x[0.5,1.5].
    assert!(intersects_interior(&h, &area(0.5, 1.5), TOL));
    // Where z in [-1,1], θ in [84.3°, 95.7°], y in [0.94, 1.06]: misses [8,12]x[1.6,3].
    assert!(!intersects_interior(&h, &area(1.6, 3.0), TOL));
    let _ = FRAC_PI_2;
}

#[test]
fn non_finite_input_is_a_violation_not_a_panic() {
    let sq = rect(0.0, 0.0, 10.0, 10.0);
    let bad = line([f64::NAN, 0.0, 0.0], [1.0, 1.0, 0.0]);
    assert!(intersects_interior(&bad, &sq, TOL));
    assert!(!stays_inside(&bad, &sq, TOL));
    let v = path_allowed(&bad, std::slice::from_ref(&sq), &[], TOL).unwrap_err();
    assert_eq!(v.kind, ViolationKind::InvalidInput);
    let inf_arc = arc17(f64::INFINITY, 0.0, 1.0, ArcDir::Cw);
    assert_eq!(
        path_allowed(&inf_arc, &[], &[], TOL).unwrap_err().kind,
        ViolationKind::InvalidInput
    );
    assert_eq!(
        path_allowed(&line([0.0; 3], [1.0; 3]), &[], &[], f64::NAN)
            .unwrap_err()
            .kind,
        ViolationKind::InvalidInput
    );
    // Huge finite values do not panic.
    let huge = line([-1e300, 1e300, 0.0], [1e300, -1e300, 1e300]);
    let _ = path_allowed(
        &huge,
        std::slice::from_ref(&sq),
        std::slice::from_ref(&sq),
        TOL,
    );
}

// ---- dense-sampling oracle ------------------------------------------------------------------

#[derive(Debug, Clone)]
enum OShape {
    Poly(Vec<[f64; 2]>),
    Circ([f64; 2], f64),
}

#[derive(Debug, Clone)]
struct OArea {
    shape: OShape,
    lo: f64,
    hi: f64,
    axes: [usize; 3],
}

/// Point of the path at `s`, the path's length, and whether its projection is a non-circular
/// curve for an area with excursion axis `ex` (then the code segments it with chords).
fn o_point(p: &PathElement, s: f64) -> [f64; 3] {
    match p {
        PathElement::Line(l) => std::array::from_fn(|i| l.from[i] + s * (l.to[i] - l.from[i])),
        PathElement::Arc(a) => o_arc_point(a, 0.0, s),
        PathElement::Helix(h) => o_arc_point(&h.arc, h.rise, s),
    }
}

fn o_sweep(a: &Arc) -> f64 {
    let mut d = a.end_angle - a.start_angle;
    match a.dir {
        ArcDir::Ccw => {
            while d <= 0.0 {
                d += TAU;
            }
            while d > TAU {
                d -= TAU;
            }
            d
        }
        ArcDir::Cw => {
            while d >= 0.0 {
                d -= TAU;
            }
            while d < -TAU {
                d += TAU;
            }
            d
        }
    }
}

fn o_arc_point(a: &Arc, rise: f64, s: f64) -> [f64; 3] {
    let (i, j, n) = match a.plane {
        Plane::G17 => (0, 1, 2),
        Plane::G18 => (2, 0, 1),
        Plane::G19 => (1, 2, 0),
    };
    let th = a.start_angle + s * o_sweep(a);
    let mut p = a.center;
    p[i] += a.radius * th.cos();
    p[j] += a.radius * th.sin();
    p[n] += rise * s;
    p
}

fn o_length(p: &PathElement) -> f64 {
    match p {
        PathElement::Line(l) => (0..3)
            .map(|i| (l.to[i] - l.from[i]).powi(2))
            .sum::<f64>()
            .sqrt(),
        PathElement::Arc(a) => a.radius * o_sweep(a).abs(),
        PathElement::Helix(h) => (h.arc.radius * o_sweep(&h.arc)).hypot(h.rise),
    }
}

fn o_chorded(p: &PathElement, ex: usize) -> bool {
    match p {
        PathElement::Helix(h) => {
            let n = match h.arc.plane {
                Plane::G17 => 2,
                Plane::G18 => 1,
                Plane::G19 => 0,
            };
            n != ex && h.rise != 0.0
        }
        _ => false,
    }
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
    let l2 = ex * ex + ey * ey;
    let t = (((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / l2).clamp(0.0, 1.0);
    (p[0] - a[0] - t * ex).hypot(p[1] - a[1] - t * ey)
}

/// Even-odd ray casting to +x.
fn o_inside(v: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut c = false;
    for k in 0..v.len() {
        let a = v[k];
        let b = v[(k + 1) % v.len()];
        if (a[1] <= p[1] && b[1] > p[1]) || (b[1] <= p[1] && a[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if x > p[0] {
                c = !c;
            }
        }
    }
    c
}

/// 1-Lipschitz "distance" q with: p in area enlarged by tol  <=>  q(p) <= tol.
fn o_q(a: &OArea, p: [f64; 3]) -> f64 {
    let u = [p[a.axes[0]], p[a.axes[1]]];
    let w = p[a.axes[2]];
    let sd = match &a.shape {
        OShape::Circ(c, r) => (u[0] - c[0]).hypot(u[1] - c[1]) - r,
        OShape::Poly(v) => {
            let d = (0..v.len())
                .map(|k| seg_dist(u, v[k], v[(k + 1) % v.len()]))
                .fold(f64::INFINITY, f64::min);
            if o_inside(v, u) {
                -d
            } else {
                d
            }
        }
    };
    sd.max(a.lo - w).max(w - a.hi)
}

fn to_area(o: &OArea) -> Option<Area> {
    let shape = match &o.shape {
        OShape::Poly(v) => AreaShape::Polygon(Polygon::new(v).ok()?),
        OShape::Circ(c, r) => AreaShape::Circle(Circle::new(*c, *r).ok()?),
    };
    Area::new(shape, o.lo, o.hi)
        .ok()?
        .with_axes(AxisMap {
            plane: [o.axes[0], o.axes[1]],
            excursion: o.axes[2],
        })
        .ok()
}

const PERMS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [1, 0, 2],
    [2, 0, 1],
    [0, 2, 1],
    [1, 2, 0],
    [2, 1, 0],
];

fn area_strategy() -> impl Strategy<Value = OArea> {
    let poly = (
        -20.0..20.0f64,
        -20.0..20.0f64,
        prop::collection::vec((0.0..TAU, 2.0..20.0f64), 3..=20),
    )
        .prop_map(|(cx, cy, mut pts)| {
            // Star-shaped around (cx, cy): sorted angles give a simple polygon.
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            OShape::Poly(
                pts.iter()
                    .map(|(a, r)| [cx + r * a.cos(), cy + r * a.sin()])
                    .collect(),
            )
        });
    let circ = (-20.0..20.0f64, -20.0..20.0f64, 1.0..20.0f64)
        .prop_map(|(x, y, r)| OShape::Circ([x, y], r));
    (
        prop_oneof![poly, circ],
        -20.0..10.0f64,
        1.0..30.0f64,
        0..6usize,
    )
        .prop_map(|(shape, lo, h, k)| OArea {
            shape,
            lo,
            hi: lo + h,
            axes: PERMS[k],
        })
}

fn path_strategy() -> impl Strategy<Value = PathElement> {
    let p3 = || prop::array::uniform3(-35.0..35.0f64);
    let line = (p3(), p3()).prop_map(|(a, b)| PathElement::Line(Line { from: a, to: b }));
    let arc = (
        0..3usize,
        prop::array::uniform3(-25.0..25.0f64),
        0.5..30.0f64,
        -TAU..TAU,
        -TAU..TAU,
        any::<bool>(),
    )
        .prop_map(|(pl, c, r, a0, a1, ccw)| Arc {
            plane: [Plane::G17, Plane::G18, Plane::G19][pl],
            center: c,
            radius: r,
            start_angle: a0,
            end_angle: a1,
            dir: if ccw { ArcDir::Ccw } else { ArcDir::Cw },
        });
    prop_oneof![
        2 => line,
        2 => arc.clone().prop_map(PathElement::Arc),
        1 => (arc, -30.0..30.0f64).prop_map(|(arc, rise)| PathElement::Helix(Helix { arc, rise })),
    ]
}

const SAMPLES: usize = 4000;

/// (min q, max q) over the samples, and the sample spacing along the path.
fn sampled(path: &PathElement, q: impl Fn([f64; 3]) -> f64) -> (f64, f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..=SAMPLES {
        let v = q(o_point(path, k as f64 / SAMPLES as f64));
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi, o_length(path) / SAMPLES as f64 * 1.000_001)
}

const DELTA: f64 = 1e-7;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(768))]

    /// Protection rule: hit iff min over the path of q <= tol. Don't care within the band
    /// (tol - DELTA, tol + step + chord + DELTA].
    #[test]
    fn protection_matches_oracle(o in area_strategy(), path in path_strategy()) {
        let Some(area) = to_area(&o) else { return Ok(()); };
        let (minq, _, step) = sampled(&path, |p| o_q(&o, p));
        let chord = if o_chorded(&path, o.axes[2]) { TOL } else { 0.0 };
        let got = intersects_interior(&path, &area, TOL);
        if minq <= TOL - DELTA {
            prop_assert!(got, "oracle hit (min q {minq}) but exact says no");
        } else if minq > TOL + step + chord + DELTA {
            prop_assert!(!got, "oracle miss (min q {minq}, step {step}) but exact says hit");
        }
    }

    /// Workspace rule: stays iff max over the path of q <= tol.
    #[test]
    fn workspace_matches_oracle(o in area_strategy(), path in path_strategy()) {
        let Some(area) = to_area(&o) else { return Ok(()); };
        let (_, maxq, step) = sampled(&path, |p| o_q(&o, p));
        let chord = if o_chorded(&path, o.axes[2]) { TOL } else { 0.0 };
        let got = stays_inside(&path, &area, TOL);
        if maxq > TOL + DELTA {
            prop_assert!(!got, "oracle leaves (max q {maxq}) but exact says stays");
        } else if maxq < TOL - step - chord - DELTA {
            prop_assert!(got, "oracle stays (max q {maxq}) but exact says leaves");
        }
    }

    /// Union of two workspaces plus one protection area, through `path_allowed`.
    #[test]
    fn path_allowed_matches_oracle(
        w1 in area_strategy(), w2 in area_strategy(), pr in area_strategy(),
        path in path_strategy(),
    ) {
        let (Some(a1), Some(a2), Some(ap)) = (to_area(&w1), to_area(&w2), to_area(&pr)) else {
            return Ok(());
        };
        let (_, max_u, step) = sampled(&path, |p| o_q(&w1, p).min(o_q(&w2, p)));
        let (min_p, _, _) = sampled(&path, |p| o_q(&pr, p));
        let chorded = [&w1, &w2, &pr].iter().any(|o| o_chorded(&path, o.axes[2]));
        let band = step + if chorded { TOL } else { 0.0 } + DELTA;
        let got = path_allowed(&path, &[a1, a2], &[ap], TOL);
        let must_violate = max_u > TOL + DELTA || min_p <= TOL - DELTA;
        let must_pass = max_u < TOL - band && min_p > TOL + band;
        if must_violate {
            prop_assert!(got.is_err(), "oracle: violation (max_u {max_u}, min_p {min_p})");
        } else if must_pass {
            prop_assert!(got.is_ok(), "oracle: allowed, got {got:?}");
        }
    }
}
