//! Path geometry (`core::path`) and velocity profiles (`channel::profile`).
//!
//! Expected values are worked out by hand in the comments (closed forms), not taken from the
//! code under test.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

use fieldprobe::channel::profile::{stop_distance, Braking, Trapezoid};
use fieldprobe::core::path::{PathError, Segment};
use proptest::prelude::*;

const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;

#[track_caller]
fn close(actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{actual} differs from {expected} by more than {tol}"
    );
}

fn at(seg: &Segment, s: f64) -> Vec<f64> {
    let mut out = vec![f64::NAN; seg.dims()];
    seg.point_at(s, &mut out);
    out
}

fn arc_parts(seg: &Segment) -> &fieldprobe::core::path::Arc {
    match seg {
        Segment::Arc(a) => a,
        Segment::Line(_) => panic!("expected an arc"),
    }
}

// ---------------------------------------------------------------------------------------------
// Arcs
// ---------------------------------------------------------------------------------------------

#[test]
fn quarter_arc_g17_ccw() {
    // G17 G03 X0 Y10 I-10 J0 from X10 Y0: centre (0, 0), r = 10, a quarter turn.
    let seg = Segment::arc(
        vec![10.0, 0.0],
        vec![0.0, 10.0],
        X,
        Y,
        [-10.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    let arc = arc_parts(&seg);
    assert_eq!(arc.centre, [0.0, 0.0]);
    assert_eq!(arc.radius, 10.0);
    assert_eq!(arc.start_angle, 0.0);
    close(arc.sweep, FRAC_PI_2, 1e-15);
    close(seg.length(), 5.0 * PI, 1e-12);
    assert_eq!(seg.extent(X), (0.0, 10.0));
    assert_eq!(seg.extent(Y), (0.0, 10.0));
    let mid = at(&seg, seg.length() / 2.0);
    close(mid[X], 10.0 * FRAC_PI_4.cos(), 1e-12);
    close(mid[Y], 10.0 * FRAC_PI_4.sin(), 1e-12);
    // Ends are exact, and s is clamped.
    assert_eq!(at(&seg, 0.0), vec![10.0, 0.0]);
    assert_eq!(at(&seg, -3.0), vec![10.0, 0.0]);
    assert_eq!(at(&seg, f64::NAN), vec![10.0, 0.0]);
    assert_eq!(at(&seg, seg.length()), vec![0.0, 10.0]);
    assert_eq!(at(&seg, 1e9), vec![0.0, 10.0]);
    assert!(!seg.is_empty());
}

#[test]
fn g02_half_circle_reports_its_apex_exactly() {
    // G17 G02 from (-2, 2) to (8, 2) with I5 J0: centre (3, 2), r = 5, clockwise from the angle
    // π over π/2 to 0, so it passes the top of the circle at Y = 2 + 5.
    let seg = Segment::arc(
        vec![-2.0, 2.0],
        vec![8.0, 2.0],
        X,
        Y,
        [5.0, 0.0],
        true,
        1e-9,
    )
    .unwrap();
    close(arc_parts(&seg).sweep, -PI, 1e-15);
    assert_eq!(seg.extent(Y), (2.0, 2.0 + 5.0));
    assert_eq!(seg.extent(X), (-2.0, 8.0));
    let top = at(&seg, seg.length() / 2.0);
    close(top[X], 3.0, 1e-12);
    close(top[Y], 7.0, 1e-12);

    // The same end points with G03 go underneath: Y min = 2 − 5.
    let seg = Segment::arc(
        vec![-2.0, 2.0],
        vec![8.0, 2.0],
        X,
        Y,
        [5.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    close(arc_parts(&seg).sweep, PI, 1e-15);
    assert_eq!(seg.extent(Y), (2.0 - 5.0, 2.0));
}

#[test]
fn apex_at_an_awkward_centre_is_centre_plus_radius_exactly() {
    // Centre (0.1, 0.2); start at centre + (0.3, 0.4), end at centre + (0.3, -0.4); G02 turns
    // from +53° through 0° to −53°, so X max = centre + r. Neither end reaches it.
    let (cx, cy) = (0.1, 0.2);
    let start = vec![cx + 0.3, cy + 0.4];
    let end = vec![cx + 0.3, cy - 0.4];
    let offset = [cx - start[0], cy - start[1]];
    let seg = Segment::arc(start.clone(), end.clone(), X, Y, offset, true, 1e-9).unwrap();
    let arc = arc_parts(&seg);
    let r = (start[0] - arc.centre[0]).hypot(start[1] - arc.centre[1]);
    assert_eq!(seg.extent(X).1, arc.centre[0] + r);
    close(seg.extent(X).1, 0.6, 1e-15);
    assert_eq!(seg.extent(X).0, start[0].min(end[0]));
    assert_eq!(seg.extent(Y), (end[1], start[1]));
    // With G03 the long way round passes 90°, 180° and 270°.
    let seg = Segment::arc(start, end, X, Y, offset, false, 1e-9).unwrap();
    let arc = arc_parts(&seg);
    assert_eq!(seg.extent(X).0, arc.centre[0] - r);
    assert_eq!(seg.extent(Y), (arc.centre[1] - r, arc.centre[1] + r));
}

#[test]
fn full_circles() {
    for clockwise in [false, true] {
        // Start == end: a full circle of r = 5 about (1, -2).
        let seg = Segment::arc(
            vec![6.0, -2.0],
            vec![6.0, -2.0],
            X,
            Y,
            [-5.0, 0.0],
            clockwise,
            0.0,
        )
        .unwrap();
        let arc = arc_parts(&seg);
        assert_eq!(arc.sweep, if clockwise { -TAU } else { TAU });
        close(seg.length(), 10.0 * PI, 1e-12);
        assert_eq!(seg.extent(X), (1.0 - 5.0, 1.0 + 5.0));
        assert_eq!(seg.extent(Y), (-2.0 - 5.0, -2.0 + 5.0));
        // A quarter of the way: CCW at the top, CW at the bottom.
        let q = at(&seg, seg.length() / 4.0);
        close(q[X], 1.0, 1e-12);
        close(q[Y], if clockwise { -7.0 } else { 3.0 }, 1e-12);
        assert_eq!(at(&seg, seg.length()), vec![6.0, -2.0]);
    }
}

/// Third-axis component of `(p − c) × dp/ds` at the middle of the arc: positive means
/// counter-clockwise seen from the positive third axis.
fn turning_sense(seg: &Segment, centre: [f64; 3], third: usize) -> f64 {
    let l = seg.length();
    let (p, q) = (at(seg, l / 2.0), at(seg, l / 2.0 + 1e-6));
    let r = [p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]];
    let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
    let cross = [
        r[1] * d[2] - r[2] * d[1],
        r[2] * d[0] - r[0] * d[2],
        r[0] * d[1] - r[1] * d[0],
    ];
    cross[third]
}

#[test]
fn g18_g03_turns_from_z_to_x_counter_clockwise_seen_from_plus_y() {
    // G18 (a1 = Z, a2 = X), offsets [K, I]. From X0 Z10 with K-10 I0, centre at the origin.
    // G03 X10 Z0: a quarter turn +Z → +X; the midpoint is X = Z = 10/√2.
    let seg = Segment::arc(
        vec![0.0, 0.0, 10.0],
        vec![10.0, 0.0, 0.0],
        Z,
        X,
        [-10.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    close(arc_parts(&seg).sweep, FRAC_PI_2, 1e-15);
    let mid = at(&seg, seg.length() / 2.0);
    close(mid[X], 10.0 / 2f64.sqrt(), 1e-12);
    close(mid[Z], 10.0 / 2f64.sqrt(), 1e-12);
    assert_eq!(mid[Y], 0.0);
    assert!(turning_sense(&seg, [0.0; 3], Y) > 0.0);
    assert_eq!(seg.extent(X), (0.0, 10.0));
    assert_eq!(seg.extent(Z), (0.0, 10.0));

    // G02 to the same end goes the long way (3/4 turn) through −X and −Z.
    let seg = Segment::arc(
        vec![0.0, 0.0, 10.0],
        vec![10.0, 0.0, 0.0],
        Z,
        X,
        [-10.0, 0.0],
        true,
        1e-9,
    )
    .unwrap();
    close(arc_parts(&seg).sweep, -3.0 * FRAC_PI_2, 1e-15);
    assert!(turning_sense(&seg, [0.0; 3], Y) < 0.0);
    assert_eq!(seg.extent(X), (-10.0, 10.0));
    assert_eq!(seg.extent(Z), (-10.0, 10.0));
}

#[test]
fn g19_and_g17_orientation() {
    // G19 (a1 = Y, a2 = Z), offsets [J, K]: G03 from Y10 to Z10 about the origin, +Y → +Z.
    let seg = Segment::arc(
        vec![0.0, 10.0, 0.0],
        vec![0.0, 0.0, 10.0],
        Y,
        Z,
        [-10.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    close(arc_parts(&seg).sweep, FRAC_PI_2, 1e-15);
    assert!(turning_sense(&seg, [0.0; 3], X) > 0.0);
    // G17 G03 the same way, seen from +Z.
    let seg = Segment::arc(
        vec![10.0, 0.0, 0.0],
        vec![0.0, 10.0, 0.0],
        X,
        Y,
        [-10.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    assert!(turning_sense(&seg, [0.0; 3], Z) > 0.0);
}

#[test]
fn helix_length_extent_and_rates() {
    // G17 G03 full circle r = 5 about (0, 0) while Z rises 0 → 3 and a fourth axis 0 → −4.
    let seg = Segment::arc(
        vec![5.0, 0.0, 0.0, 0.0],
        vec![5.0, 0.0, 3.0, -4.0],
        X,
        Y,
        [-5.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    let l = ((10.0 * PI).powi(2) + 9.0 + 16.0).sqrt();
    close(seg.length(), l, 1e-12);
    assert_eq!(seg.extent(Z), (0.0, 3.0));
    assert_eq!(seg.extent(3), (-4.0, 0.0));
    assert_eq!(seg.extent(X), (-5.0, 5.0));
    let half = at(&seg, l / 2.0);
    close(half[X], -5.0, 1e-12);
    close(half[Y], 0.0, 1e-12);
    close(half[Z], 1.5, 1e-12);
    close(half[3], -2.0, 1e-12);
    close(seg.axis_speed_factor(Z), 3.0 / l, 1e-15);
    close(seg.axis_speed_factor(3), 4.0 / l, 1e-15);
    close(seg.axis_speed_factor(X), 10.0 * PI / l, 1e-15);
    close(seg.axis_speed_factor(Y), 10.0 * PI / l, 1e-15);
    assert_eq!(seg.axis_speed_factor(9), 0.0);
    assert_eq!(seg.extent(9), (0.0, 0.0));
}

#[test]
fn axis_speed_factor_of_lines_and_partial_arcs() {
    let line = Segment::line(vec![0.0, 0.0, 1.0], vec![3.0, 4.0, 1.0]).unwrap();
    close(line.axis_speed_factor(X), 0.6, 1e-15);
    close(line.axis_speed_factor(Y), 0.8, 1e-15);
    assert_eq!(line.axis_speed_factor(Z), 0.0);
    // Arc from 0° to 45° (r = 10): dX/ds = −sin θ is largest at 45°, dY/ds = cos θ at 0°.
    let c = FRAC_PI_4.cos() * 10.0;
    let seg = Segment::arc(vec![10.0, 0.0], vec![c, c], X, Y, [-10.0, 0.0], false, 1e-9).unwrap();
    close(seg.axis_speed_factor(X), FRAC_PI_4.sin(), 1e-12);
    close(seg.axis_speed_factor(Y), 1.0, 1e-12);
    // Arc from 30° to 60°: neither axis reaches full rate; X peaks at 60°, Y at 30°.
    let (s, e) = (PI / 6.0, PI / 3.0);
    let seg = Segment::arc(
        vec![10.0 * s.cos(), 10.0 * s.sin()],
        vec![10.0 * e.cos(), 10.0 * e.sin()],
        X,
        Y,
        [-10.0 * s.cos(), -10.0 * s.sin()],
        false,
        1e-9,
    )
    .unwrap();
    close(seg.axis_speed_factor(X), e.sin(), 1e-12);
    close(seg.axis_speed_factor(Y), s.cos(), 1e-12);
}

#[test]
fn radius_mismatch_and_other_errors() {
    // End radius 10.5 against start radius 10 with tolerance 0.1.
    let err = Segment::arc(
        vec![10.0, 0.0],
        vec![0.0, 10.5],
        X,
        Y,
        [-10.0, 0.0],
        false,
        0.1,
    )
    .unwrap_err();
    assert_eq!(
        err,
        PathError::RadiusMismatch {
            start_radius: 10.0,
            end_radius: 10.5,
            tolerance: 0.1
        }
    );
    assert!(err.to_string().contains("10.5"));
    let zero = Segment::arc(vec![1.0, 1.0], vec![1.0, 1.0], X, Y, [0.0, 0.0], true, 0.1);
    assert!(matches!(zero, Err(PathError::ZeroRadius { .. })));
    assert_eq!(
        Segment::line(vec![0.0; 3], vec![0.0; 2]),
        Err(PathError::DimensionMismatch { start: 3, end: 2 })
    );
    assert_eq!(
        Segment::line(vec![], vec![]),
        Err(PathError::UnsupportedDimension { dims: 0 })
    );
    assert_eq!(
        Segment::line(vec![0.0; 33], vec![0.0; 33]),
        Err(PathError::UnsupportedDimension { dims: 33 })
    );
    assert!(Segment::line(vec![0.0; 32], vec![1.0; 32]).is_ok());
    assert!(matches!(
        Segment::line(vec![f64::NAN], vec![0.0]),
        Err(PathError::NonFinite { .. })
    ));
    assert!(matches!(
        Segment::line(vec![0.0], vec![f64::INFINITY]),
        Err(PathError::NonFinite { .. })
    ));
    assert!(matches!(
        Segment::line(vec![0.0], vec![1e300]),
        Err(PathError::OutOfRange { .. })
    ));
    assert!(matches!(
        Segment::arc(
            vec![1.0, 0.0],
            vec![0.0, 1.0],
            X,
            Y,
            [f64::NAN, 0.0],
            false,
            0.1
        ),
        Err(PathError::NonFinite { .. })
    ));
    for (a1, a2) in [(0, 0), (0, 2), (5, 1)] {
        assert_eq!(
            Segment::arc(
                vec![1.0, 0.0],
                vec![0.0, 1.0],
                a1,
                a2,
                [-1.0, 0.0],
                false,
                0.1
            ),
            Err(PathError::InvalidPlane { a1, a2, dims: 2 })
        );
    }
    for tolerance in [-1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            Segment::arc(
                vec![1.0, 0.0],
                vec![0.0, 1.0],
                X,
                Y,
                [-1.0, 0.0],
                false,
                tolerance
            ),
            Err(PathError::InvalidTolerance { .. })
        ));
    }
}

#[test]
fn radius_mismatch_within_tolerance_stays_continuous_and_inside_its_extent() {
    // Start radius 10, end radius 10.05: the path ends exactly on the programmed end point
    // without a jump, and the extent still holds every point.
    let seg = Segment::arc(
        vec![10.0, 0.0],
        vec![0.0, 10.05],
        X,
        Y,
        [-10.0, 0.0],
        false,
        0.1,
    )
    .unwrap();
    let l = seg.length();
    let near_end = at(&seg, l * (1.0 - 1e-9));
    close(near_end[X], 0.0, 1e-6);
    close(near_end[Y], 10.05, 1e-6);
    let (x, y) = (seg.extent(X), seg.extent(Y));
    assert!(y.1 >= 10.05);
    for i in 0..=10_000 {
        let p = at(&seg, l * f64::from(i) / 10_000.0);
        assert!(p[X] >= x.0 && p[X] <= x.1, "{p:?} outside {x:?}");
        assert!(p[Y] >= y.0 && p[Y] <= y.1, "{p:?} outside {y:?}");
    }
}

#[test]
fn radius_miss_can_push_past_both_end_points() {
    // Start radius 10 at 0.0001 rad, end radius 10.1 at 0.3 rad (G03, tolerance 0.2). The miss
    // (0.1 radially at the end, ≈ 0.0955 in X) is added in proportion u: X peaks where
    // 10·sin θ·0.2999 = 0.0955, θ ≈ 0.0318, u ≈ 0.106, at ≈ 9.99493 + 0.0101 = 10.005 — above
    // the start (≈ 10.0) and the end (≈ 9.65).
    let (s, e) = (0.0001f64, 0.3f64);
    let start = vec![10.0 * s.cos(), 10.0 * s.sin()];
    let end = vec![10.1 * e.cos(), 10.1 * e.sin()];
    let offset = [-start[0], -start[1]];
    let seg = Segment::arc(start.clone(), end, X, Y, offset, false, 0.2).unwrap();
    let l = seg.length();
    let highest = (0..=100_000)
        .map(|i| at(&seg, l * f64::from(i) / 100_000.0)[X])
        .fold(f64::NEG_INFINITY, f64::max);
    close(highest, 10.005, 1e-3);
    assert!(seg.extent(X).1 >= highest);
}

#[test]
fn empty_segments_and_odd_buffers() {
    let line = Segment::line(vec![1.0, 2.0], vec![1.0, 2.0]).unwrap();
    assert!(line.is_empty());
    assert_eq!(line.length(), 0.0);
    assert_eq!(at(&line, 5.0), vec![1.0, 2.0]);
    assert_eq!(line.axis_speed_factor(X), 0.0);
    // A short buffer gets what fits, a long one keeps its tail.
    let line = Segment::line(vec![0.0, 0.0], vec![2.0, 4.0]).unwrap();
    let mut short = [9.0];
    line.point_at(1e9, &mut short);
    assert_eq!(short, [2.0]);
    let mut long = [9.0; 3];
    line.point_at(line.length() / 2.0, &mut long);
    assert_eq!(long, [1.0, 2.0, 9.0]);
    assert_eq!(line.extent(Y), (0.0, 4.0));
}

// ---------------------------------------------------------------------------------------------
// Profiles
// ---------------------------------------------------------------------------------------------

#[test]
fn trapezoid_closed_form() {
    // L = 100, v = 10, a = 100: t_acc = v/a = 0.1 and d_acc = v²/2a = 0.5 each way,
    // t_const = (100 − 1)/10 = 9.9, duration 10.1.
    let p = Trapezoid::plan(100.0, 10.0, 100.0, 100.0);
    close(p.accel_time(), 0.1, 1e-15);
    close(p.cruise_time(), 9.9, 1e-12);
    close(p.decel_time(), 0.1, 1e-15);
    close(p.duration(), 10.1, 1e-12);
    assert_eq!(p.peak_velocity(), 10.0);
    assert_eq!(p.length(), 100.0);
    let (s, v) = p.sample(0.05);
    close(s, 0.5 * 100.0 * 0.05 * 0.05, 1e-12);
    close(v, 5.0, 1e-12);
    let (s, v) = p.sample(5.0);
    close(s, 0.5 + 10.0 * 4.9, 1e-9);
    assert_eq!(v, 10.0);
    let (s, v) = p.sample(p.duration() - 0.05);
    close(s, 100.0 - 0.125, 1e-9);
    close(v, 5.0, 1e-9);
    assert_eq!(p.sample(p.duration()), (100.0, 0.0));
    assert_eq!(p.sample(1e6), (100.0, 0.0));
    assert_eq!(p.sample(0.0), (0.0, 0.0));
    assert_eq!(p.sample(-1.0), (0.0, 0.0));

    // Asymmetric: a_dec = 50 → t_dec = 0.2, d_dec = 1, t_const = (100 − 0.5 − 1)/10 = 9.85.
    let p = Trapezoid::plan(100.0, 10.0, 100.0, 50.0);
    close(p.decel_time(), 0.2, 1e-15);
    close(p.cruise_time(), 9.85, 1e-12);
    close(p.duration(), 10.15, 1e-12);
}

#[test]
fn trapezoid_triangle() {
    // L = 0.5, v = 10, a = 100: the ramps would need 1.0, so v_peak = sqrt(L·a) = sqrt(50).
    let p = Trapezoid::plan(0.5, 10.0, 100.0, 100.0);
    close(p.peak_velocity(), 50f64.sqrt(), 1e-12);
    assert_eq!(p.cruise_time(), 0.0);
    close(p.duration(), 2.0 * 50f64.sqrt() / 100.0, 1e-12);
    let (s, v) = p.sample(p.accel_time());
    close(s, 0.25, 1e-12);
    close(v, 50f64.sqrt(), 1e-12);
    // Asymmetric: L = 1, a_acc = 100, a_dec = 300 → v² = 2·1·100·300/400 = 150; the ramps
    // cover 150/200 = 0.75 and 150/600 = 0.25.
    let p = Trapezoid::plan(1.0, 100.0, 100.0, 300.0);
    close(p.peak_velocity(), 150f64.sqrt(), 1e-12);
    close(p.sample(p.accel_time()).0, 0.75, 1e-12);
    assert_eq!(p.sample(p.duration()), (1.0, 0.0));
    // Exactly at the threshold: L = 1 → ramps fit, no cruise.
    let p = Trapezoid::plan(1.0, 10.0, 100.0, 100.0);
    assert_eq!(p.peak_velocity(), 10.0);
    close(p.cruise_time(), 0.0, 1e-15);
}

#[test]
fn trapezoid_is_continuous_at_phase_boundaries() {
    let p = Trapezoid::plan(100.0, 10.0, 100.0, 50.0);
    let boundaries = [p.accel_time(), p.accel_time() + p.cruise_time()];
    for t in boundaries {
        let eps = 1e-9;
        let (s0, v0) = p.sample(t - eps);
        let (s1, v1) = p.sample(t + eps);
        assert!(s1 >= s0);
        close(s1 - s0, 2.0 * eps * 10.0, 1e-9);
        close(v1, v0, 100.0 * 2.0 * eps + 1e-12);
    }
}

#[test]
fn zero_length_and_invalid_inputs() {
    let p = Trapezoid::plan(0.0, 10.0, 100.0, 100.0);
    assert_eq!(p.duration(), 0.0);
    assert_eq!(p.sample(0.0), (0.0, 0.0));
    assert_eq!(p.sample(1.0), (0.0, 0.0));
    let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1.0, 0.0, 1e300];
    for &l in &[f64::NAN, -5.0, 1e300, 10.0] {
        for &v in &bad {
            for &a in &bad {
                let p = Trapezoid::plan(l, v, a, 100.0);
                let d = p.duration();
                assert!(d.is_finite() && d >= 0.0, "{p:?}");
                let (s, v) = p.sample(d / 2.0);
                assert!(s.is_finite() && v.is_finite(), "{p:?}");
                assert_eq!(p.sample(d), (p.length(), 0.0));
                assert_eq!(p.sample(f64::NAN), (0.0, 0.0));
            }
        }
    }
    assert_eq!(Trapezoid::plan(f64::NAN, 1.0, 1.0, 1.0).length(), 0.0);
    assert_eq!(Trapezoid::plan(-5.0, 1.0, 1.0, 1.0).length(), 0.0);
}

#[test]
fn interpolator_samples_at_integer_cycles() {
    // t = k·Δt, recomputed every cycle: the last sample lands exactly on the end.
    let p = Trapezoid::plan(1234.5, 250.0, 2000.0, 1500.0);
    let dt = 0.000_25;
    let mut k: u64 = 0;
    let mut last = (0.0, 0.0);
    loop {
        let t = k as f64 * dt;
        let (s, v) = p.sample(t);
        assert!(s >= last.0);
        assert!((v - last.1).abs() <= 2000.0 * dt * (1.0 + 1e-9));
        last = (s, v);
        if t >= p.duration() {
            break;
        }
        k += 1;
    }
    assert_eq!(last, (1234.5, 0.0));
    assert_eq!(k, (p.duration() / dt).ceil() as u64);
}

#[test]
fn braking() {
    assert_eq!(stop_distance(10.0, 100.0), 0.5);
    assert_eq!(stop_distance(-10.0, 100.0), 0.5);
    assert!(stop_distance(f64::NAN, 1.0).is_finite());
    assert!(stop_distance(f64::NAN, 1.0) > 1e6);
    assert!(stop_distance(1.0, 0.0).is_finite());
    // From s0 = 5 at v0 = 10 with a = 100: stops after 0.1 s at 5 + 0.5.
    let b = Braking::new(5.0, 10.0, 100.0);
    close(b.duration(), 0.1, 1e-15);
    assert_eq!(b.stop_position(), 5.5);
    assert_eq!(b.sample(0.0), (5.0, 10.0));
    let (s, v) = b.sample(0.05);
    close(s, 5.0 + 10.0 * 0.05 - 0.5 * 100.0 * 0.05 * 0.05, 1e-12);
    close(v, 5.0, 1e-12);
    assert_eq!(b.sample(0.1), (5.5, 0.0));
    assert_eq!(b.sample(7.0), (5.5, 0.0));
    // Moving backwards.
    let b = Braking::new(5.0, -10.0, 100.0);
    assert_eq!(b.stop_position(), 4.5);
    let (s, v) = b.sample(0.05);
    close(s, 5.0 - 0.375, 1e-12);
    close(v, -5.0, 1e-12);
    // Standing still, and garbage.
    assert_eq!(Braking::new(1.0, 0.0, 10.0).sample(1.0), (1.0, 0.0));
    let b = Braking::new(f64::NAN, f64::INFINITY, f64::NAN);
    assert!(b.duration().is_finite() && b.stop_position().is_finite());
}

// ---------------------------------------------------------------------------------------------
// Properties
// ---------------------------------------------------------------------------------------------

/// Plane axes (a1, a2) of G17, G18, G19 in an X, Y, Z, A space.
const PLANES: [(usize, usize); 3] = [(X, Y), (Z, X), (Y, Z)];

prop_compose! {
    /// An arc with its end exactly on the circle (up to rounding), in a 4-axis space, plus the
    /// test's own view of it: (segment, centre, r, start angle, signed sweep).
    fn arb_arc()(
        plane in 0usize..3,
        cx in -100.0..100.0f64,
        cy in -100.0..100.0f64,
        r in 0.01..100.0f64,
        start_angle in -PI..PI,
        magnitude in prop_oneof![Just(TAU), Just(PI), Just(FRAC_PI_2), 0.001..TAU],
        clockwise in any::<bool>(),
        others in prop::collection::vec(-50.0..50.0f64, 4),
    ) -> (Segment, [f64; 2], f64, f64, f64) {
        let (a1, a2) = PLANES[plane];
        let sweep = if clockwise { -magnitude } else { magnitude };
        let end_angle = start_angle + sweep;
        let mut start = vec![others[0], others[1], others[2], 0.0];
        let mut end = vec![others[2], others[3], others[1], others[3]];
        start[a1] = cx + r * start_angle.cos();
        start[a2] = cy + r * start_angle.sin();
        if magnitude == TAU {
            end[a1] = start[a1];
            end[a2] = start[a2];
        } else {
            end[a1] = cx + r * end_angle.cos();
            end[a2] = cy + r * end_angle.sin();
        }
        let offset = [cx - start[a1], cy - start[a2]];
        let seg = Segment::arc(start, end, a1, a2, offset, clockwise, 1e-9).unwrap();
        (seg, [cx, cy], r, start_angle, sweep)
    }
}

proptest! {
    #[test]
    fn arc_extent_holds_dense_samples_and_is_attained(
        (seg, centre, r, start_angle, sweep) in arb_arc()
    ) {
        let arc = arc_parts(&seg).clone();
        // The sweep the code found is the one the arc was generated with (within rounding;
        // tiny generated sweeps may round to a full turn only when the chord vanishes).
        prop_assert!((arc.sweep - sweep).abs() < 1e-6, "sweep {} vs {}", arc.sweep, sweep);
        let l = seg.length();
        // Dense samples plus the samples at the cardinal angles inside the sweep.
        let mut ss: Vec<f64> = (0..=4000).map(|i| l * f64::from(i) / 4000.0).collect();
        for quarter in -8..=8 {
            let phi = f64::from(quarter) * FRAC_PI_2;
            let u = (phi - start_angle) / sweep;
            if (0.0..=1.0).contains(&u) {
                ss.push(u * l);
            }
        }
        let points: Vec<Vec<f64>> = ss.iter().map(|&s| at(&seg, s)).collect();
        for axis in 0..4 {
            let (lo, hi) = seg.extent(axis);
            prop_assert!(lo <= hi);
            for p in &points {
                prop_assert!(p[axis] >= lo - 1e-9 && p[axis] <= hi + 1e-9,
                    "axis {axis}: {} outside ({lo}, {hi})", p[axis]);
            }
            let min = points.iter().map(|p| p[axis]).fold(f64::INFINITY, f64::min);
            let max = points.iter().map(|p| p[axis]).fold(f64::NEG_INFINITY, f64::max);
            prop_assert!((min - lo).abs() <= 1e-9, "axis {axis}: min {min} vs extent {lo}");
            prop_assert!((max - hi).abs() <= 1e-9, "axis {axis}: max {max} vs extent {hi}");
        }
        // Plane extents never beyond the circle.
        let k = |axis: usize| usize::from(axis == arc.a2);
        for axis in [arc.a1, arc.a2] {
            let (lo, hi) = seg.extent(axis);
            prop_assert!(lo >= centre[k(axis)] - r - 1e-9 && hi <= centre[k(axis)] + r + 1e-9);
        }
        prop_assert_eq!(at(&seg, l), seg.end().to_vec());
        prop_assert_eq!(at(&seg, 0.0), seg.start().to_vec());
    }

    #[test]
    fn arc_with_radius_miss_stays_inside_extent(
        (seg, _centre, _r, _start_angle, _sweep) in arb_arc(),
        miss in prop::array::uniform2(-0.05..0.05f64),
    ) {
        let arc = arc_parts(&seg);
        let mut end = arc.end.clone();
        end[arc.a1] += miss[0];
        end[arc.a2] += miss[1];
        let offset = [arc.centre[0] - arc.start[arc.a1], arc.centre[1] - arc.start[arc.a2]];
        let clockwise = arc.sweep < 0.0;
        let Ok(seg) = Segment::arc(arc.start.clone(), end, arc.a1, arc.a2, offset, clockwise, 0.1)
        else {
            return Ok(()); // a miss that lands on the start point changes the arc; skip
        };
        let l = seg.length();
        let mut previous = at(&seg, 0.0);
        for i in 0..=4000 {
            let p = at(&seg, l * f64::from(i) / 4000.0);
            for axis in 0..4 {
                let (lo, hi) = seg.extent(axis);
                prop_assert!(p[axis] >= lo - 1e-9 && p[axis] <= hi + 1e-9);
                // Continuous: no step larger than the arc length of one sample step plus the
                // share of the miss.
                prop_assert!((p[axis] - previous[axis]).abs() <= l / 4000.0 + 0.1 / 4000.0 + 1e-9);
            }
            previous = p;
        }
        prop_assert_eq!(at(&seg, l), seg.end().to_vec());
    }

    #[test]
    fn trapezoid_properties(
        length in prop_oneof![Just(0.0), 0.0..1000.0f64],
        v_max in 0.01..1000.0f64,
        a_acc in 0.1..1e4f64,
        a_dec in 0.1..1e4f64,
    ) {
        let p = Trapezoid::plan(length, v_max, a_acc, a_dec);
        let d = p.duration();
        prop_assert!(d.is_finite() && d >= 0.0);
        prop_assert_eq!(p.sample(d), (length, 0.0));
        prop_assert_eq!(p.sample(d * 2.0 + 1.0), (length, 0.0));
        let n = 3000;
        let dt = d / f64::from(n);
        let a_max = a_acc.max(a_dec);
        let mut last = p.sample(0.0);
        prop_assert_eq!(last, (0.0, 0.0));
        let mut area = 0.0;
        for i in 1..=n {
            let (s, v) = p.sample(f64::from(i) * dt);
            prop_assert!(s >= last.0, "s fell from {} to {s}", last.0);
            prop_assert!(s <= length);
            prop_assert!(v >= 0.0 && v <= v_max * (1.0 + 1e-12));
            prop_assert!((v - last.1).abs() <= a_max * dt * (1.0 + 1e-9) + 1e-12 * v_max);
            prop_assert!(s - last.0 <= v_max * dt * (1.0 + 1e-9) + 1e-12 * length);
            area += 0.5 * (v + last.1) * dt;
            last = (s, v);
        }
        // ∫v dt = length; the trapezoidal rule is exact but for the (at most four) kinks.
        prop_assert!((area - length).abs() <= 4.0 * p.peak_velocity() * dt + 1e-9 * length + 1e-12);
        // Closed form for the duration.
        let ramps = v_max * v_max / (2.0 * a_acc) + v_max * v_max / (2.0 * a_dec);
        let expected = if ramps <= length {
            v_max / a_acc + v_max / a_dec + (length - ramps) / v_max
        } else {
            let v = (2.0 * length * a_acc * a_dec / (a_acc + a_dec)).sqrt();
            v / a_acc + v / a_dec
        };
        prop_assert!((d - expected).abs() <= 1e-9 * expected.max(1.0));
    }

    #[test]
    fn braking_properties(s0 in -1e3..1e3f64, v0 in -1e3..1e3f64, a in 0.1..1e4f64) {
        let b = Braking::new(s0, v0, a);
        let stop = b.stop_position();
        prop_assert!((stop - s0 - v0 * v0.abs() / (2.0 * a)).abs() <= 1e-9 * (1.0 + stop.abs()));
        let d = b.duration();
        let mut last = b.sample(0.0);
        prop_assert_eq!(last, (s0, v0));
        for i in 1..=500 {
            let t = if i == 500 { d } else { d * f64::from(i) / 500.0 };
            let (s, v) = b.sample(t);
            prop_assert!((s - last.0) * v0.signum() >= 0.0);
            prop_assert!(v.abs() <= last.1.abs());
            last = (s, v);
        }
        prop_assert_eq!(last, (stop, 0.0));
    }
}
