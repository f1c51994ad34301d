//! Frames (`core::frames`), measurement results (`core::measure::results`) and mapped arcs
//! (`core::path::Segment::transformed`) against seed 004 §4 and §5 (meas1–meas4).
//!
//! Expected values are the seed's printed numbers or come from formulas written here (rotation
//! matrices, trigonometry), never from the code under test.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use fieldprobe::core::frames::{CsTransform, FrameError, Frames};
use fieldprobe::core::measure::results::{
    compute, g101, g102, motion_direction, AxisResult, MeasuringBlock, ResultsError,
};
use fieldprobe::core::path::{AffineMap, PathError, Segment};
use proptest::prelude::*;

const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;
const XYZ: [Option<usize>; 3] = [Some(X), Some(Y), Some(Z)];

#[track_caller]
fn close(actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{actual} differs from {expected} by more than {tol}"
    );
}

fn frames3() -> Frames {
    Frames::new(3, XYZ).unwrap()
}

/// A G100 block: target (PCS), programmed axes, motion from `start`; ideal probe (r = 0).
fn block<'a>(
    frames: &Frames,
    start: &[f64],
    target: &'a [f64],
    programmed: &'a [bool],
) -> MeasuringBlock<'a> {
    MeasuringBlock {
        target_pcs: target,
        programmed,
        direction_pcs: motion_direction(frames, start, target),
        ball_radius: 0.0,
        include_radius: true,
    }
}

fn result(results: &[Option<AxisResult>], axis: usize) -> AxisResult {
    results[axis].expect("axis has a result")
}

/// `V.A.ABS` of `axis` after `G01` to `pcs`: the CS frame coordinate `w`.
fn abs_after(frames: &Frames, pcs: &[f64], axis: usize) -> f64 {
    let mut w = vec![0.0; pcs.len()];
    frames.pcs_to_w(pcs, &mut w);
    w[axis]
}

fn acs_after(frames: &Frames, pcs: &[f64], axis: usize) -> f64 {
    let mut acs = vec![0.0; pcs.len()];
    frames.pcs_to_acs(pcs, &mut acs);
    acs[axis]
}

// ---------------------------------------------------------------------------------------------
// Rotation written out in the test: R = Rz(c)·Ry(b)·Rx(a), angles in degrees.
// ---------------------------------------------------------------------------------------------

type M3 = [[f64; 3]; 3];

fn mul(a: M3, b: M3) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn rot(a: f64, b: f64, c: f64) -> M3 {
    let (sa, ca) = a.to_radians().sin_cos();
    let (sb, cb) = b.to_radians().sin_cos();
    let (sc, cc) = c.to_radians().sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]];
    let ry = [[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]];
    let rz = [[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]];
    mul(rz, mul(ry, rx))
}

fn apply(m: M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// The test's own rigid map: rotation `r` and translation `t` on axes 0, 1, 2, identity on the
/// others.
struct TestRigid {
    r: M3,
    t: [f64; 3],
}

impl AffineMap for TestRigid {
    fn map_point(&self, p: &[f64], out: &mut [f64]) {
        self.map_vector(p, out);
        for (o, t) in out.iter_mut().zip(self.t) {
            *o += t;
        }
    }

    fn map_vector(&self, d: &[f64], out: &mut [f64]) {
        out.copy_from_slice(d);
        let v = apply(self.r, [d[0], d[1], d[2]]);
        out[..3].copy_from_slice(&v);
    }
}

// ---------------------------------------------------------------------------------------------
// Seed 004 §5 meas1 – meas4
// ---------------------------------------------------------------------------------------------

#[test]
fn meas1_no_offsets() {
    // N10 G01 G90 Z200, N20 G100 Z20, probe at ACS Z = 100.
    let mut frames = frames3();
    let target = [0.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target, &programmed);
    let res = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    let z = result(&res, Z);
    assert_eq!((z.mess, z.acs, z.pcs, z.moffs), (100.0, 100.0, 100.0, 80.0));
    assert_eq!(res[X], None);
    assert_eq!(frames.mein(Z), 0.0);
    g101(&mut frames, &res, &[(Z, 1.0)]).unwrap();
    assert_eq!(frames.mein(Z), 80.0);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 180.0);
    g102(&mut frames, &[Z]).unwrap();
    assert_eq!(frames.mein(Z), 0.0);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 100.0);
}

#[test]
fn meas2_g92_reference_point_offset() {
    // N10 G92 Z33: additive +33.
    let mut frames = frames3();
    frames.set_g92(Z, 33.0).unwrap();
    let target = [0.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target, &programmed);
    let res = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    let z = result(&res, Z);
    assert_eq!((z.mess, z.acs, z.pcs, z.moffs), (100.0, 100.0, 67.0, 47.0));
    assert_eq!(frames.mein(Z), 0.0);
    g101(&mut frames, &res, &[(Z, 1.0)]).unwrap();
    assert_eq!(frames.mein(Z), 47.0);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 180.0);
    // Without #CS V.A.ABS is the ACS.
    assert_eq!(acs_after(&frames, &[0.0, 0.0, 100.0], Z), 180.0);
    g102(&mut frames, &[Z]).unwrap();
    assert_eq!(frames.mein(Z), 0.0);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 133.0);
}

#[test]
fn meas3_cs_offset_only() {
    // N10 #CS ON[0,0,33,0,0,0]; under #CS all three main axes latch (§4): X = Y = 0.
    let mut frames = frames3();
    frames
        .set_cs(Some(
            CsTransform::from_cs_on(&[0.0, 0.0, 33.0, 0.0, 0.0, 0.0]).unwrap(),
        ))
        .unwrap();
    let target = [0.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target, &programmed);
    let res = compute(
        &frames,
        &b,
        &[Some(0.0), Some(0.0), Some(100.0)],
        &[None; 3],
    )
    .unwrap();
    let z = result(&res, Z);
    assert_eq!((z.mess, z.acs, z.pcs, z.moffs), (67.0, 100.0, 67.0, 47.0));
    assert_eq!(frames.mein(Z), 0.0);
    g101(&mut frames, &res, &[(Z, 1.0)]).unwrap();
    assert_eq!(frames.mein(Z), 47.0);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 147.0);
    assert_eq!(acs_after(&frames, &[0.0, 0.0, 100.0], Z), 180.0);
    g102(&mut frames, &[Z]).unwrap();
    assert_eq!(frames.mein(Z), 0.0);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 100.0);
}

/// meas4's probing point: on the CS line x = 150, y = 0 where the ACS z is 55.5.
/// ACS z = 75 − 150·sin 15° + w_z·cos 15°, ACS x = 150·cos 15° + w_z·sin 15°.
fn meas4_latch() -> (f64, f64) {
    let (s, c) = 15f64.to_radians().sin_cos();
    let wz = (55.5 - 75.0 + 150.0 * s) / c;
    (wz, 150.0 * c + wz * s)
}

fn meas4_frames() -> Frames {
    let mut frames = frames3();
    frames
        .set_cs(Some(
            CsTransform::from_cs_on(&[0.0, 0.0, 75.0, 0.0, 15.0, 0.0]).unwrap(),
        ))
        .unwrap();
    frames
}

#[test]
fn meas4_cs_offset_and_rotation() {
    // N10 #CS ON[0,0,75,0,15,0], N20 G01 X150 Z100, N30 G100 Z-10, probe at ACS Z 55.5.
    let mut frames = meas4_frames();
    let (wz, acs_x) = meas4_latch();
    let target = [150.0, 0.0, -10.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[150.0, 0.0, 100.0], &target, &programmed);
    let res = compute(
        &frames,
        &b,
        &[Some(acs_x), Some(0.0), Some(55.5)],
        &[None; 3],
    )
    .unwrap();
    let z = result(&res, Z);
    // Exact values from the trigonometry above ...
    close(z.mess, wz, 1e-9);
    assert_eq!(z.acs, 55.5);
    close(z.pcs, wz, 1e-9);
    close(z.moffs, wz + 10.0, 1e-9);
    // ... and the seed's rounded numbers.
    close(z.mess, 20.0, 0.01);
    close(z.pcs, 20.0, 0.01);
    close(z.moffs, 30.0, 0.01);
    // X was not programmed but is converted jointly: the probe stood at CS x = 150.
    close(result(&res, X).mess, 150.0, 1e-9);
    close(result(&res, X).moffs, 0.0, 1e-9);
    close(result(&res, Y).mess, 0.0, 1e-12);
    assert_eq!(frames.mein(Z), 0.0);
    g101(&mut frames, &res, &[(Z, 1.0)]).unwrap();
    close(frames.mein(Z), wz + 10.0, 1e-9);
    close(frames.mein(Z), 30.0, 0.01);
    let abs = abs_after(&frames, &[150.0, 0.0, 50.0], Z);
    close(abs, 50.0 + wz + 10.0, 1e-9);
    close(abs, 80.0, 0.01);
    g102(&mut frames, &[Z]).unwrap();
    assert_eq!(frames.mein(Z), 0.0);
    close(abs_after(&frames, &[150.0, 0.0, 50.0], Z), 50.0, 1e-12);
}

#[test]
fn meas4_convention_is_the_right_handed_rotation_about_y() {
    // w = (150, 0, 20) → ACS z = 75 − 150·sin 15° + 20·cos 15° = 55.49… ≈ 55.5.
    let cs = CsTransform::from_cs_on(&[0.0, 0.0, 75.0, 0.0, 15.0, 0.0]).unwrap();
    let (s, c) = 15f64.to_radians().sin_cos();
    let acs = cs.to_acs([150.0, 0.0, 20.0]);
    close(acs[2], 75.0 - 150.0 * s + 20.0 * c, 1e-12);
    close(acs[0], 150.0 * c + 20.0 * s, 1e-12);
    close(acs[2], 55.5, 0.01);
    assert!(cs.has_rotation() && !cs.is_identity());
}

// ---------------------------------------------------------------------------------------------
// Probe ball, G101 factors, retained values
// ---------------------------------------------------------------------------------------------

#[test]
fn ball_radius_enters_the_pcs_value_only() {
    // §5 "Measuring with a measuring probe tool of 2mm radius": G0 X150 Z200, G100 Z20, D1 with
    // r = 2; probe at ACS Z = 100. Contact = centre + r·(0, 0, −1) → 98.
    let frames = frames3();
    let target = [150.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let mut b = block(&frames, &[150.0, 0.0, 200.0], &target, &programmed);
    b.ball_radius = 2.0;
    let res = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    let z = result(&res, Z);
    assert_eq!((z.mess, z.acs, z.pcs, z.moffs), (100.0, 100.0, 98.0, 80.0));
    // P-CHAN-00311 = 1: not included.
    b.include_radius = false;
    let res = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    assert_eq!(result(&res, Z).pcs, 100.0);
    // A diagonal motion in X/Z: the correction follows the unit direction (3, 0, −4)/5.
    let target = [153.0, 0.0, 196.0];
    let programmed = [true, false, true];
    let mut b = block(&frames, &[150.0, 0.0, 200.0], &target, &programmed);
    b.ball_radius = 2.0;
    let res = compute(&frames, &b, &[Some(151.5), None, Some(198.0)], &[None; 3]).unwrap();
    close(result(&res, X).pcs, 151.5 + 2.0 * 0.6, 1e-12);
    close(result(&res, Z).pcs, 198.0 - 2.0 * 0.8, 1e-12);
    // Negative or NaN radii are refused.
    b.ball_radius = -1.0;
    assert!(matches!(
        compute(&frames, &b, &[Some(151.5), None, Some(198.0)], &[None; 3]),
        Err(ResultsError::InvalidRadius { .. })
    ));
}

#[test]
fn ball_radius_under_rotated_cs_uses_the_pcs_direction() {
    // meas4 with r = 2: the measuring motion is −Z in the PCS, so the PCS value is w_z − 2.
    let frames = meas4_frames();
    let (wz, acs_x) = meas4_latch();
    let target = [150.0, 0.0, -10.0];
    let programmed = [false, false, true];
    let mut b = block(&frames, &[150.0, 0.0, 100.0], &target, &programmed);
    b.ball_radius = 2.0;
    let res = compute(
        &frames,
        &b,
        &[Some(acs_x), Some(0.0), Some(55.5)],
        &[None; 3],
    )
    .unwrap();
    close(result(&res, Z).pcs, wz - 2.0, 1e-9);
    close(result(&res, X).pcs, 150.0, 1e-9);
    close(result(&res, Z).mess, wz, 1e-9);
}

#[test]
fn g101_factor_and_errors() {
    // meas2 with G101 Z0.5: MEIN = 0.5 · 47.
    let mut frames = frames3();
    frames.set_g92(Z, 33.0).unwrap();
    let target = [0.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target, &programmed);
    let res = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    g101(&mut frames, &res, &[(Z, 0.5)]).unwrap();
    assert_eq!(frames.mein(Z), 23.5);
    assert_eq!(abs_after(&frames, &[0.0, 0.0, 100.0], Z), 156.5);
    // X has no measured value: an error, and nothing changes (Z listed first stays 23.5).
    assert_eq!(
        g101(&mut frames, &res, &[(Z, 1.0), (X, 1.0)]),
        Err(ResultsError::NoMeasuredValue { axis: X })
    );
    assert_eq!(frames.mein(Z), 23.5);
    assert!(matches!(
        g101(&mut frames, &res, &[(Z, f64::NAN)]),
        Err(ResultsError::InvalidFactor { .. })
    ));
    assert!(matches!(
        g101(&mut frames, &res, &[(7, 1.0)]),
        Err(ResultsError::Frame(FrameError::NoSuchAxis { axis: 7, .. }))
    ));
    assert!(g102(&mut frames, &[Z, 9]).is_err());
    assert_eq!(frames.mein(Z), 23.5);
}

#[test]
fn measuring_with_mein_active_keeps_g101_consistent() {
    // meas2 again, but MEIN 47 is still active when measuring a second time with the same
    // target: MOFFS includes the active MEIN (the table has no MEIN term), so G101 Z1 keeps 47.
    let mut frames = frames3();
    frames.set_g92(Z, 33.0).unwrap();
    frames.set_mein(Z, 47.0).unwrap();
    let target = [0.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target, &programmed);
    let res = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    let z = result(&res, Z);
    assert_eq!(z.moffs, 100.0 - 20.0 - 33.0);
    // The PCS value subtracts MEIN (interpretation): 100 − 33 − 47 = 20, the programmed target
    // that now maps onto the probing point.
    assert_eq!(z.pcs, 20.0);
    g101(&mut frames, &res, &[(Z, 1.0)]).unwrap();
    assert_eq!(frames.mein(Z), 47.0);
}

#[test]
fn values_are_retained_for_non_programmed_axes() {
    // §5 Notice. First run measures Z, the second X; Z keeps its values, X gets new ones.
    let frames = frames3();
    let programmed_z = [false, false, true];
    let target1 = [0.0, 0.0, 20.0];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target1, &programmed_z);
    let first = compute(&frames, &b, &[None, None, Some(100.0)], &[None; 3]).unwrap();
    let programmed_x = [true, false, false];
    let target2 = [50.0, 0.0, 100.0];
    let b = block(&frames, &[0.0, 0.0, 100.0], &target2, &programmed_x);
    // Z latches too (looped probe signal) but is not programmed: kept.
    let second = compute(&frames, &b, &[Some(30.0), None, Some(100.0)], &first).unwrap();
    assert_eq!(second[Z], first[Z]);
    assert_eq!(result(&second, X).moffs, 30.0 - 50.0);
    // Third run programs Z and the probe never switches: no measured value (MERF false).
    let b = block(&frames, &[0.0, 0.0, 100.0], &target1, &programmed_z);
    let third = compute(&frames, &b, &[None; 3], &second).unwrap();
    assert_eq!(third[Z], None);
    assert_eq!(third[X], second[X]);
}

// ---------------------------------------------------------------------------------------------
// §4 #CS examples
// ---------------------------------------------------------------------------------------------

#[test]
fn section4_cs_45_degrees_about_y() {
    // N10 G00 X0 Y1 Z0, N20 #CS ON[0,0,0,0,45], N30 G100 X10: the CS start is (0, 1, 0) and the
    // motion runs along the CS x axis, i.e. along (cos 45°, 0, −sin 45°) in the ACS, so X and Z
    // move while all three axes must latch. Probe at CS x = 6.
    let mut frames = frames3();
    let cs = CsTransform::from_cs_on(&[0.0, 0.0, 0.0, 0.0, 45.0]).unwrap();
    assert_eq!(cs.values(), [0.0, 0.0, 0.0, 0.0, 45.0, 0.0]);
    frames.set_cs(Some(cs)).unwrap();
    let (s, c) = 45f64.to_radians().sin_cos();
    let latch = [6.0 * c, 1.0, -6.0 * s];
    let target = [10.0, 1.0, 0.0];
    let programmed = [true, false, false];
    let b = block(&frames, &[0.0, 1.0, 0.0], &target, &programmed);
    let old = Some(AxisResult {
        mess: 9.0,
        acs: 9.0,
        pcs: 9.0,
        moffs: 9.0,
    });
    let latched = latch.map(Some);
    let res = compute(&frames, &b, &latched, &[old; 3]).unwrap();
    for (axis, (mess, moffs)) in [(6.0, -4.0), (1.0, 0.0), (0.0, 0.0)]
        .into_iter()
        .enumerate()
    {
        let r = result(&res, axis);
        close(r.mess, mess, 1e-12);
        close(r.pcs, mess, 1e-12);
        close(r.moffs, moffs, 1e-12);
        assert_eq!(r.acs, latch[axis]);
    }
    // A main axis without a latch under #CS is an error (§4: looped to all measurement axes) ...
    assert_eq!(
        compute(&frames, &b, &[latched[0], None, latched[2]], &[None; 3]),
        Err(ResultsError::IncompleteCsLatch { axis: Y })
    );
    // ... none at all is a run without a probing signal: the programmed X has no value, Y and Z
    // keep theirs.
    let res = compute(&frames, &b, &[None; 3], &[old; 3]).unwrap();
    assert_eq!(res, vec![None, old, old]);
}

#[test]
fn section4_cs_90_degrees_about_z() {
    // N50 #CS ON[0,0,0,0,0,90]: CS x runs along ACS +Y, CS y along ACS −X.
    let cs = CsTransform::from_cs_on(&[0.0, 0.0, 0.0, 0.0, 0.0, 90.0]).unwrap();
    let acs = cs.to_acs([6.0, 1.0, 0.0]);
    close(acs[0], -1.0, 1e-12);
    close(acs[1], 6.0, 1e-12);
    close(acs[2], 0.0, 1e-12);
    let mut frames = frames3();
    frames.set_cs(Some(cs)).unwrap();
    let target = [10.0, 1.0, 0.0];
    let programmed = [true, false, false];
    let b = block(&frames, &[0.0, 1.0, 0.0], &target, &programmed);
    let res = compute(&frames, &b, &acs.map(Some), &[None; 3]).unwrap();
    close(result(&res, X).mess, 6.0, 1e-12);
    close(result(&res, X).moffs, -4.0, 1e-12);
    close(result(&res, Y).mess, 1.0, 1e-12);
}

#[test]
fn cs_two_rotations_round_trip_and_match_rz_ry_rx() {
    let values = [10.0, -20.0, 30.0, 25.0, -40.0, 70.0];
    let cs = CsTransform::from_cs_on(&values).unwrap();
    let r = rot(25.0, -40.0, 70.0);
    for w in [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [-150.0, 33.3, 71.0]] {
        let rw = apply(r, w);
        let expected = [rw[0] + 10.0, rw[1] - 20.0, rw[2] + 30.0];
        let acs = cs.to_acs(w);
        for k in 0..3 {
            close(acs[k], expected[k], 1e-12);
        }
        let back = cs.to_acs(cs.to_cs(acs));
        for k in 0..3 {
            close(back[k], acs[k], 1e-12);
        }
    }
    let m = cs.rotation_matrix();
    for i in 0..3 {
        for j in 0..3 {
            close(m[i][j], r[i][j], 1e-15);
        }
    }
    // Two rotations only (b and c), through Frames with every offset set, on 5 axes.
    let mut frames = Frames::new(5, [Some(0), Some(2), Some(3)]).unwrap();
    frames
        .set_cs(Some(
            CsTransform::from_cs_on(&[5.0, 6.0, 7.0, 0.0, 30.0, -60.0]).unwrap(),
        ))
        .unwrap();
    frames.set_g92(0, 1.5).unwrap();
    frames
        .set_zero_offset(&[10.0, 20.0, 30.0, 40.0, 50.0])
        .unwrap();
    frames.set_mein(3, -2.0).unwrap();
    frames.set_tool_length(100.0).unwrap();
    assert_eq!(frames.shifts(0), 11.5);
    assert_eq!(frames.tool_length(3), 100.0);
    assert_eq!(frames.tool_length(2), 0.0);
    let acs = [12.0, -3.0, 44.0, 250.0, 9.0];
    let mut w = [0.0; 5];
    let mut again = [0.0; 5];
    frames.acs_to_w(&acs, &mut w);
    frames.w_to_acs(&w, &mut again);
    for k in 0..5 {
        close(again[k], acs[k], 1e-12);
    }
    // Non-main axes pass through unchanged.
    assert_eq!((w[1], w[4]), (-3.0, 9.0));
    let mut pcs = [0.0; 5];
    frames.acs_to_pcs(&acs, &mut pcs);
    frames.pcs_to_acs(&pcs, &mut again);
    for k in 0..5 {
        close(again[k], acs[k], 1e-12);
    }
    // PCS = w − shifts − MEIN − tool length, written out: main axis Z is channel axis 3.
    close(pcs[3], w[3] - 40.0 + 2.0 - 100.0, 1e-12);
    // The ACS from the test's own matrix: w on (0, 2, 3) rotated by Rz(−60)·Ry(30).
    let r = rot(0.0, 30.0, -60.0);
    let rw = apply(r, [w[0], w[2], w[3]]);
    close(acs[0], rw[0] + 5.0, 1e-9);
    close(acs[2], rw[1] + 6.0, 1e-9);
    close(acs[3], rw[2] + 7.0, 1e-9);
}

#[test]
fn frame_errors_and_odd_inputs() {
    assert!(matches!(
        Frames::new(40, XYZ),
        Err(FrameError::TooManyAxes { axes: 40 })
    ));
    assert!(matches!(
        Frames::new(2, XYZ),
        Err(FrameError::NoSuchAxis { axis: 2, axes: 2 })
    ));
    assert!(matches!(
        Frames::new(3, [Some(0), Some(0), None]),
        Err(FrameError::DuplicateMainAxis { axis: 0 })
    ));
    assert!(matches!(
        CsTransform::from_cs_on(&[0.0; 7]),
        Err(FrameError::CsArity { got: 7 })
    ));
    assert!(matches!(
        CsTransform::from_cs_on(&[0.0, f64::NAN]),
        Err(FrameError::NonFinite { .. })
    ));
    assert!(CsTransform::from_cs_on(&[]).unwrap().is_identity());
    assert!(!CsTransform::from_cs_on(&[0.0, 0.0, 0.0, 360.0, -720.0])
        .unwrap()
        .has_rotation());
    let mut f = frames3();
    assert!(f.set_g92(3, 1.0).is_err());
    assert!(f.set_mein(Z, f64::INFINITY).is_err());
    assert!(f.set_zero_offset(&[1.0; 4]).is_err());
    assert!(f.set_zero_offset(&[1.0, f64::NAN]).is_err());
    assert_eq!(f.zero_offset(0), 0.0, "a refused table changes nothing");
    // A rotating #CS needs X, Y and Z; a pure offset does not.
    let mut xz = Frames::new(2, [Some(0), None, Some(1)]).unwrap();
    assert!(matches!(
        xz.set_cs(Some(
            CsTransform::from_cs_on(&[0.0, 0.0, 0.0, 0.0, 15.0]).unwrap()
        )),
        Err(FrameError::CsNeedsMainAxes { axis: 'Y' })
    ));
    xz.set_cs(Some(CsTransform::from_cs_on(&[1.0, 2.0, 3.0]).unwrap()))
        .unwrap();
    let mut acs = [0.0; 2];
    xz.w_to_acs(&[10.0, 20.0], &mut acs);
    assert_eq!(acs, [11.0, 23.0]);
    // Short and long buffers: as many entries as all hold.
    let mut short = [7.0; 1];
    f.pcs_to_acs(&[1.0, 2.0, 3.0], &mut short);
    assert_eq!(short, [1.0]);
    let mut long = [7.0; 5];
    f.pcs_to_acs(&[1.0, 2.0], &mut long);
    assert_eq!(long, [1.0, 2.0, 7.0, 7.0, 7.0]);
}

#[test]
fn result_input_errors() {
    let frames = frames3();
    let target = [0.0, 0.0, 20.0];
    let programmed = [false, false, true];
    let b = block(&frames, &[0.0, 0.0, 200.0], &target, &programmed);
    assert!(matches!(
        compute(&frames, &b, &[None, Some(1.0)], &[None; 3]),
        Err(ResultsError::Length { .. })
    ));
    assert!(matches!(
        compute(&frames, &b, &[None, None, Some(f64::NAN)], &[None; 3]),
        Err(ResultsError::NonFinite { axis: Z, .. })
    ));
    let bad_target = [0.0, f64::INFINITY, 0.0];
    let b = block(&frames, &[0.0; 3], &bad_target, &programmed);
    assert!(matches!(
        compute(&frames, &b, &[None; 3], &[None; 3]),
        Err(ResultsError::NonFinite { axis: Y, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Mapped arcs (core::path)
// ---------------------------------------------------------------------------------------------

fn at(seg: &Segment, s: f64) -> Vec<f64> {
    let mut out = vec![f64::NAN; seg.dims()];
    seg.point_at(s, &mut out);
    out
}

fn mapped(map: &dyn AffineMap, p: &[f64]) -> Vec<f64> {
    let mut out = vec![f64::NAN; p.len()];
    map.map_point(p, &mut out);
    out
}

/// Largest value of `g` over `[a, b]` by ternary search (g unimodal there).
fn refine_max(g: &dyn Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    for _ in 0..200 {
        let m1 = a + (b - a) / 3.0;
        let m2 = b - (b - a) / 3.0;
        if g(m1) < g(m2) {
            a = m1;
        } else {
            b = m2;
        }
    }
    g(a).max(g(b))
}

/// Largest value of `g` on `[0, l]`: dense samples, then every local peak refined.
fn true_max(g: &dyn Fn(f64) -> f64, l: f64) -> f64 {
    const N: usize = 3000;
    let s = |i: usize| l * i as f64 / N as f64;
    let v: Vec<f64> = (0..=N).map(|i| g(s(i))).collect();
    let mut best = v[0].max(v[N]);
    for i in 0..=N {
        let left = if i == 0 { f64::NEG_INFINITY } else { v[i - 1] };
        let right = if i == N { f64::NEG_INFINITY } else { v[i + 1] };
        if v[i] >= left && v[i] >= right {
            best = best.max(refine_max(g, s(i.saturating_sub(1)), s((i + 1).min(N))));
        }
    }
    best
}

/// Plane axes (a1, a2) of G17, G18, G19 in an X, Y, Z, A space.
const PLANES: [(usize, usize); 3] = [(X, Y), (Z, X), (Y, Z)];

prop_compose! {
    /// A plane arc (optionally with a radius miss at the end) in X, Y, Z, A.
    fn arb_plane_arc()(
        plane in 0usize..3,
        cx in -100.0..100.0f64,
        cy in -100.0..100.0f64,
        r in 0.5..100.0f64,
        start_angle in -PI..PI,
        magnitude in prop_oneof![Just(TAU), Just(PI), Just(FRAC_PI_2), 0.01..TAU],
        clockwise in any::<bool>(),
        others in prop::collection::vec(-50.0..50.0f64, 4),
        miss in prop_oneof![Just([0.0, 0.0]), prop::array::uniform2(-0.05..0.05f64)],
    ) -> Segment {
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
            end[a1] = cx + r * end_angle.cos() + miss[0];
            end[a2] = cy + r * end_angle.sin() + miss[1];
        }
        let offset = [cx - start[a1], cy - start[a2]];
        Segment::arc(start, end, a1, a2, offset, clockwise, 0.1)
            .or_else(|_| Segment::line(vec![0.0; 4], vec![1.0; 4]))
            .unwrap()
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    #[test]
    fn mapped_arc_matches_the_mapped_samples_and_its_extents_are_exact(
        seg in arb_plane_arc(),
        angles in prop::array::uniform3(-180.0..180.0f64),
        t in prop::array::uniform3(-100.0..100.0f64),
    ) {
        let map = TestRigid { r: rot(angles[0], angles[1], angles[2]), t };
        let moved = seg.transformed(&map).unwrap();
        let l = seg.length();
        prop_assert!((moved.length() - l).abs() <= 1e-9);
        prop_assert_eq!(moved.start().to_vec(), mapped(&map, seg.start()));
        prop_assert_eq!(moved.end().to_vec(), mapped(&map, seg.end()));
        let n = 4000;
        for i in 0..=n {
            let s = l * f64::from(i) / f64::from(n);
            let want = mapped(&map, &at(&seg, s));
            let got = at(&moved, s);
            for k in 0..4 {
                prop_assert!((got[k] - want[k]).abs() <= 1e-9,
                    "s = {s}, axis {k}: {} vs {}", got[k], want[k]);
            }
        }
        for k in 0..4 {
            let (lo, hi) = moved.extent(k);
            // The extremes of the mapped original, found by the test's own search.
            let hi_true = true_max(&|s| mapped(&map, &at(&seg, s))[k], l);
            let lo_true = -true_max(&|s| -mapped(&map, &at(&seg, s))[k], l);
            prop_assert!((hi - hi_true).abs() <= 1e-9, "axis {k}: max {hi} vs {hi_true}");
            prop_assert!((lo - lo_true).abs() <= 1e-9, "axis {k}: min {lo} vs {lo_true}");
            // Speed factor: a bound of every finite-difference rate, and nearly attained.
            let f = moved.axis_speed_factor(k);
            let h = l / f64::from(n);
            let mut worst: f64 = 0.0;
            for i in 0..n {
                let s = h * f64::from(i);
                let d = (at(&moved, s + h)[k] - at(&moved, s)[k]).abs() / h;
                worst = worst.max(d);
            }
            prop_assert!(worst <= f + 1e-6, "axis {k}: rate {worst} above factor {f}");
            prop_assert!(f - worst <= 1e-3 * (1.0 + f), "axis {k}: factor {f} vs {worst}");
        }
    }

    #[test]
    fn lines_stay_lines(
        start in prop::collection::vec(-100.0..100.0f64, 4),
        end in prop::collection::vec(-100.0..100.0f64, 4),
        angles in prop::array::uniform3(-180.0..180.0f64),
    ) {
        let map = TestRigid { r: rot(angles[0], angles[1], angles[2]), t: [1.0, -2.0, 3.0] };
        let line = Segment::line(start.clone(), end.clone()).unwrap();
        let moved = line.transformed(&map).unwrap();
        prop_assert!(matches!(moved, Segment::Line(_)));
        prop_assert_eq!(moved.start().to_vec(), mapped(&map, &start));
        prop_assert_eq!(moved.end().to_vec(), mapped(&map, &end));
        prop_assert!((moved.length() - line.length()).abs() <= 1e-9);
    }

    #[test]
    fn results_never_panic(
        values in prop::collection::vec(prop::num::f64::ANY, 12),
        latched in prop::collection::vec(prop::option::of(prop::num::f64::ANY), 0..5),
        programmed in prop::collection::vec(any::<bool>(), 3),
        cs in prop::collection::vec(-1e13..1e13f64, 0..8),
        factor in prop::num::f64::ANY,
    ) {
        let mut frames = frames3();
        let _ = frames.set_g92(Z, values[0]);
        let _ = frames.set_mein(X, values[1]);
        let _ = frames.set_tool_length(values[2]);
        let _ = frames.set_zero_offset(&values[3..6]);
        if let Ok(t) = CsTransform::from_cs_on(&cs) {
            let _ = frames.set_cs(Some(t));
        }
        let target = &values[6..9];
        let block = MeasuringBlock {
            target_pcs: target,
            programmed: &programmed,
            direction_pcs: [values[9], values[10], values[11]],
            ball_radius: values[11].abs(),
            include_radius: true,
        };
        if let Ok(res) = compute(&frames, &block, &latched, &[None; 3]) {
            let _ = g101(&mut frames, &res, &[(Z, factor), (X, factor)]);
        }
        let mut out = [0.0; 3];
        frames.pcs_to_acs(&values[..latched.len().min(12)], &mut out);
        frames.acs_to_pcs(&values[..2], &mut out);
    }
}

#[test]
fn g17_arc_under_meas4_cs_is_a_tilted_circle() {
    // G17 G02 full circle r = 10 about (150, 0) at CS z = 20, under #CS ON[0,0,75,0,15,0]: in the
    // ACS a circle in a plane tilted by 15° about Y. Written out: x' = x·cos b + z·sin b,
    // z' = 75 − x·sin b + z·cos b, with x in [140, 160] at z = 20.
    let frames = meas4_frames();
    let arc = Segment::arc(
        vec![160.0, 0.0, 20.0],
        vec![160.0, 0.0, 20.0],
        X,
        Y,
        [-10.0, 0.0],
        true,
        1e-9,
    )
    .unwrap();
    let moved = arc.transformed(&frames.w_to_acs_map()).unwrap();
    let (s, c) = 15f64.to_radians().sin_cos();
    let (xlo, xhi) = moved.extent(X);
    close(xlo, 140.0 * c + 20.0 * s, 1e-9);
    close(xhi, 160.0 * c + 20.0 * s, 1e-9);
    let (zlo, zhi) = moved.extent(Z);
    close(zlo, 75.0 - 160.0 * s + 20.0 * c, 1e-9);
    close(zhi, 75.0 - 140.0 * s + 20.0 * c, 1e-9);
    assert_eq!(moved.extent(Y), (-10.0, 10.0));
    close(moved.length(), 20.0 * PI, 1e-9);
    // Quarter way round clockwise from (160, 0): CS point (150, −10, 20).
    let p = at(&moved, moved.length() / 4.0);
    close(p[X], 150.0 * c + 20.0 * s, 1e-9);
    close(p[Y], -10.0, 1e-9);
    close(p[Z], 75.0 - 150.0 * s + 20.0 * c, 1e-9);
    // The X rate peaks at cos 15° (where the circle runs along CS x), Y at 1.
    close(moved.axis_speed_factor(X), c, 1e-12);
    close(moved.axis_speed_factor(Y), 1.0, 1e-12);
    close(moved.axis_speed_factor(Z), s, 1e-12);
    // A second map composes: mapped arcs map again.
    let back = TestRigid {
        r: rot(0.0, -15.0, 0.0),
        t: [0.0; 3],
    };
    let twice = moved.transformed(&back).unwrap();
    let q = at(&twice, twice.length() / 4.0);
    let expected = apply(rot(0.0, -15.0, 0.0), [p[X], p[Y], p[Z]]);
    for k in 0..3 {
        close(q[k], expected[k], 1e-9);
    }
}

#[test]
fn non_rigid_maps_are_refused() {
    struct Scale;
    impl AffineMap for Scale {
        fn map_point(&self, p: &[f64], out: &mut [f64]) {
            self.map_vector(p, out);
        }
        fn map_vector(&self, d: &[f64], out: &mut [f64]) {
            for (o, x) in out.iter_mut().zip(d) {
                *o = 2.0 * x;
            }
        }
    }
    struct Nan;
    impl AffineMap for Nan {
        fn map_point(&self, _: &[f64], _: &mut [f64]) {}
        fn map_vector(&self, _: &[f64], _: &mut [f64]) {}
    }
    let arc = Segment::arc(
        vec![10.0, 0.0],
        vec![0.0, 10.0],
        X,
        Y,
        [-10.0, 0.0],
        false,
        1e-9,
    )
    .unwrap();
    assert!(matches!(
        arc.transformed(&Scale),
        Err(PathError::NotRigid { .. })
    ));
    assert!(matches!(
        arc.transformed(&Nan),
        Err(PathError::NonFinite { .. })
    ));
    // A line under a scaling is still a line (affine), so it is accepted.
    let line = Segment::line(vec![0.0, 0.0], vec![1.0, 1.0]).unwrap();
    assert_eq!(line.transformed(&Scale).unwrap().end(), &[2.0, 2.0]);
}
