//! Acceptance through `fieldprobe run`: the measurement examples of seed 004 (§2, §4, §5, §7.3)
//! in `examples/nc/seed004/` run with a simulated probe or fixed stop and print / report what the
//! seed says.
//!
//! Expected values are taken from the seed text itself (meas1 – meas4: the `-> V.A.… = …`
//! annotations are parsed out of `../shared/seeds/004_*.txt`) or computed here from the program
//! geometry (straight lines, rotations of `#CS` written out with sin / cos), never from the code
//! under test.
//!
//! Latch resolution: the drives report positions in increments of 0.1 µm (`drives/
//! cia402-generic.toml`: 10000 increments / mm), so a latched value is the true crossing
//! ± 0.05 µm; [`LATCH_TOL`] = 0.1 µm.

use crate::common::seed004;
use crate::common::test_data;
use seed004::seed_annotations;

use crate::common::cli;
use cli::{fieldprobe, stderr, stdout};
use serde_json::Value;

/// 0.1 µm in mm: one drive increment (the latch resolution).
const LATCH_TOL: f64 = 1e-4;

/// `fieldprobe run <example> <args> --json`; asserts exit code `code` and returns the report.
#[track_caller]
fn run_json(example: &str, args: &[&str], code: i32) -> Value {
    let prog = format!("examples/nc/seed004/{example}");
    let mut all = vec!["run", prog.as_str()];
    all.extend_from_slice(args);
    all.push("--json");
    let o = fieldprobe(&all);
    assert_eq!(
        o.status.code(),
        Some(code),
        "{example} {args:?}: {}",
        stderr(&o)
    );
    serde_json::from_slice(&o.stdout).expect("--json prints one JSON document")
}

/// The axis entry `name` of a `--json` report.
#[track_caller]
fn axis<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["axes"]
        .as_array()
        .expect("axes")
        .iter()
        .find(|a| a["name"] == name)
        .unwrap_or_else(|| panic!("no axis {name} in {report}"))
}

/// `measurement.<key>` of axis `name` as a number (`None` for JSON null).
#[track_caller]
fn meas(report: &Value, name: &str, key: &str) -> Option<f64> {
    axis(report, name)["measurement"][key].as_f64()
}

#[track_caller]
fn merf(report: &Value, name: &str) -> bool {
    axis(report, name)["measurement"]["merf"]
        .as_bool()
        .expect("merf is a bool")
}

#[track_caller]
fn command(report: &Value, name: &str) -> f64 {
    axis(report, name)["command"].as_f64().expect("command")
}

#[track_caller]
fn close(what: &str, actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: {actual} is not within {tol} of {expected}"
    );
}

#[track_caller]
fn completed_without_messages(r: &Value) {
    assert_eq!(r["status"], "completed", "{r}");
    assert_eq!(r["messages"], serde_json::json!([]), "{r}");
}

// ---------------------------------------------------------------------------------------------
// The seed's annotations
// ---------------------------------------------------------------------------------------------

#[test]
fn the_seed_annotations_are_parsed() {
    if !test_data::seeds_present("the_seed_annotations_are_parsed") {
        return;
    }
    // A guard for the parser above: meas1 has 9 annotated #MSG lines, the first V.A.MESS.Z = 100.
    let a = seed_annotations("meas1");
    assert_eq!(a.len(), 9, "{a:?}");
    assert_eq!(a[0], ("V.A.MESS.Z".to_string(), 100.0));
    assert_eq!(a[3], ("V.A.MOFFS.Z".to_string(), 80.0));
    assert_eq!(
        seed_annotations("meas4")[0],
        ("V.A.MESS.Z".to_string(), 20.0)
    );
}

/// meas1 – meas3 print exactly the seed's values (`%f`: 6 decimals).
#[track_caller]
fn seed_example_prints_the_seed_values(name: &str) {
    let o = fieldprobe(&[
        "run",
        &format!("examples/nc/seed004/{name}.nc"),
        "--probe-at",
        "Z=100",
    ]);
    assert_eq!(o.status.code(), Some(0), "{name}: {}", stderr(&o));
    assert_eq!(stderr(&o), "", "{name}: no warnings or errors");
    let expected: String = seed_annotations(name)
        .iter()
        .map(|(n, v)| format!("{n}={v:.6}\n"))
        .collect();
    assert_eq!(stdout(&o), expected, "{name}");
}

#[test]
fn meas1_without_offsets_prints_the_seed_values() {
    if !test_data::seeds_present("meas1_without_offsets_prints_the_seed_values") {
        return;
    }
    seed_example_prints_the_seed_values("meas1");
}

#[test]
fn meas2_reference_point_offset_prints_the_seed_values() {
    if !test_data::seeds_present("meas2_reference_point_offset_prints_the_seed_values") {
        return;
    }
    seed_example_prints_the_seed_values("meas2");
}

#[test]
fn meas3_cs_offset_prints_the_seed_values() {
    if !test_data::seeds_present("meas3_cs_offset_prints_the_seed_values") {
        return;
    }
    seed_example_prints_the_seed_values("meas3");
}

#[test]
fn meas4_cs_offset_and_rotation_matches_the_seed_and_the_trigonometry() {
    if !test_data::seeds_present(
        "meas4_cs_offset_and_rotation_matches_the_seed_and_the_trigonometry",
    ) {
        return;
    }
    // #CS ON[0,0,75,0,15,0]: offset Z 75, rotation 15° about Y. The CS point (150, 0, z) is at
    // ACS z = 75 − 150·sin15° + z·cos15°, so the probe at ACS Z = 55.5 is at
    // z_cs = (55.5 − 75 + 150·sin15°) / cos15°. The seed rounds it to 20.0.
    let (s, c) = 15f64.to_radians().sin_cos();
    let z_cs = (55.5 - 75.0 + 150.0 * s) / c;
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas4.nc",
        "--probe-at",
        "Z=55.5",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let seed = seed_annotations("meas4");
    let out = stdout(&o);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), seed.len(), "{out}");
    // Own expectation per line: MESS = PCS = z_cs, ACS = 55.5, MOFFS = z_cs − (−10),
    // MEIN = 0 / MOFFS after G101 / 0 after G102, ABS after G01 Z50 = 50 + MEIN.
    let moffs = z_cs + 10.0;
    let own = [z_cs, 55.5, z_cs, moffs, 0.0, moffs, 50.0 + moffs, 0.0, 50.0];
    for ((line, (name, seed_value)), own) in lines.iter().zip(&seed).zip(own) {
        let (n, v) = line.split_once('=').expect("NAME=VALUE");
        assert_eq!(n, name);
        let v: f64 = v.parse().unwrap();
        close(&format!("{name} vs seed"), v, *seed_value, 0.01);
        // The CS value combines the latches of X and Z (each ± half an increment, 0.05 µm) with
        // sin / cos 15°, and %f rounds to 1e-6: within one increment (0.1 µm).
        close(&format!("{name} vs trigonometry"), v, own, LATCH_TOL);
    }
}

// ---------------------------------------------------------------------------------------------
// §2 Meas_run, §4 2.5D and #CS, §2 independent axes, §5 meas_example
// ---------------------------------------------------------------------------------------------

#[test]
fn meas_run_latches_both_axes_on_the_line() {
    // N30 G100 X10 Y10 from (5, 0): the line is Y = 2·(X − 5); the probe at X = 8 is crossed
    // at Y = 6, so X latches 8 and Y latches 6. N40 G01 X7 moves X on.
    // X latches where the probe is (the plant switches it on X's own trajectory): 8 to the
    // increment. Y latches where Y is at that instant: on the line up to the set-points'
    // rounding to whole increments (0x607A is an INTEGER32 of increments, so each axis follows
    // its own staircase within half an increment of the line) plus the latch's own rounding —
    // within two increments.
    let r = run_json("meas_run.nc", &["--probe-at", "X=8"], 0);
    completed_without_messages(&r);
    let on_line = 2.0 * LATCH_TOL;
    close("X latched", meas(&r, "X", "acs").unwrap(), 8.0, LATCH_TOL);
    close("Y latched", meas(&r, "Y", "acs").unwrap(), 6.0, on_line);
    close("X MESS", meas(&r, "X", "mess").unwrap(), 8.0, LATCH_TOL);
    close("Y MESS", meas(&r, "Y", "mess").unwrap(), 6.0, on_line);
    // MOFFS = measured − target (10, 10).
    close("X MOFFS", meas(&r, "X", "moffs").unwrap(), -2.0, LATCH_TOL);
    close("Y MOFFS", meas(&r, "Y", "moffs").unwrap(), -4.0, on_line);
    assert!(merf(&r, "X") && merf(&r, "Y"));
    assert_eq!(command(&r, "X"), 7.0);
    // Y stopped after the latch: beyond 6 (the command leads the actual), well before 10.
    let y = command(&r, "Y");
    assert!(y > 6.0 && y < 7.0, "Y stopped at {y}");
    // Z was not programmed: no measured value.
    assert_eq!(meas(&r, "Z", "acs"), None);
}

#[test]
fn meas_run_without_probe_reaches_the_target_without_error() {
    // Type 1 (default P-CHAN-00057 = 1), P-CHAN-00176 = 0: no signal is no error, MERF 0.
    let r = run_json("meas_run.nc", &[], 0);
    completed_without_messages(&r);
    assert_eq!(command(&r, "X"), 7.0);
    assert_eq!(command(&r, "Y"), 10.0);
    assert!(!merf(&r, "X") && !merf(&r, "Y"));
    assert_eq!(meas(&r, "X", "acs"), None);
}

#[test]
fn measurement_run_standard_2_5d_without_probe() {
    let r = run_json("measurement_run_standard.nc", &[], 0);
    completed_without_messages(&r);
    assert_eq!(
        (command(&r, "X"), command(&r, "Y"), command(&r, "Z")),
        (15.0, 10.0, 0.0)
    );
}

#[test]
fn measurement_run_standard_2_5d_probe_on_y() {
    // Probe at Y = 8. N30 G100 X10 (Y stands at 1): no signal, no error (type 1). N50 G100 Y10
    // from (10, 3): only Y moves and must latch → 8. N70 G100 X15 Y10 from (10, 5): the line
    // crosses Y = 8 at X = 10 + 5·(8 − 5)/5 = 13, both latch.
    let r = run_json("measurement_run_standard.nc", &["--probe-at", "Y=8"], 0);
    completed_without_messages(&r);
    close("X", meas(&r, "X", "acs").unwrap(), 13.0, LATCH_TOL);
    close("Y", meas(&r, "Y", "acs").unwrap(), 8.0, LATCH_TOL);
    assert!(merf(&r, "X") && merf(&r, "Y"));
    let (x, y) = (command(&r, "X"), command(&r, "Y"));
    assert!(
        x > 13.0 && x < 14.0 && y > 8.0 && y < 9.0,
        "stopped at ({x}, {y})"
    );
}

#[test]
fn measurement_run_standard_2_5d_probe_on_x() {
    // Probe at X = 12: N30 (X 5 → 10) does not reach it, N70 (10, 5) → (15, 10) crosses it at
    // Y = 5 + (12 − 10) = 7.
    let r = run_json("measurement_run_standard.nc", &["--probe-at", "X=12"], 0);
    completed_without_messages(&r);
    close("X", meas(&r, "X", "acs").unwrap(), 12.0, LATCH_TOL);
    close("Y", meas(&r, "Y", "acs").unwrap(), 7.0, LATCH_TOL);
    close(
        "X MOFFS",
        meas(&r, "X", "moffs").unwrap(),
        12.0 - 15.0,
        LATCH_TOL,
    );
    close(
        "Y MOFFS",
        meas(&r, "Y", "moffs").unwrap(),
        7.0 - 10.0,
        LATCH_TOL,
    );
}

/// R = Ry(b) and Rz(c) as the seed's `#CS ON[x,y,z,a,b,c]` rotations (right-handed, degrees).
fn ry(b: f64, p: [f64; 3]) -> [f64; 3] {
    let (s, c) = b.to_radians().sin_cos();
    [c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2]]
}

fn rz(g: f64, p: [f64; 3]) -> [f64; 3] {
    let (s, c) = g.to_radians().sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
}

#[test]
fn measurement_run_cs_without_probe_follows_the_rotations() {
    // Start ACS (0, 1, 0). N20 #CS ON 45° about Y: CS coordinates of the start = Ryᵀ·(0, 1, 0)
    // = (0, 1, 0); N30 G100 X10 → CS (10, 1, 0) → ACS Ry(45°)·(10, 1, 0).
    let after_n30 = ry(45.0, [10.0, 1.0, 0.0]);
    // N50 #CS ON 90° about Z: CS = Rzᵀ·ACS; N60 G100 X10 sets CS x = 10.
    let mut w = rz(-90.0, after_n30);
    w[0] = 10.0;
    let after_n60 = rz(90.0, w);
    let r = run_json("measurement_run_cs.nc", &[], 0);
    completed_without_messages(&r);
    for (i, name) in ["X", "Y", "Z"].into_iter().enumerate() {
        close(name, command(&r, name), after_n60[i], 1e-9);
    }
}

#[test]
fn measurement_run_cs_all_three_main_axes_latch() {
    // Probe at ACS Y = 5. N30 (under Ry 45°) moves X and Z only: no crossing, no signal (type 1,
    // no error). N60 (under Rz 90°) moves ACS Y from 1 to 10 at ACS X = 10·cos45°,
    // Z = −10·sin45°: the crossing latches all three axes, converted with Rzᵀ into the CS.
    let acs = [
        10.0 * 45f64.to_radians().cos(),
        5.0,
        -10.0 * 45f64.to_radians().sin(),
    ];
    let cs = rz(-90.0, acs);
    let r = run_json("measurement_run_cs.nc", &["--probe-at", "Y=5"], 0);
    completed_without_messages(&r);
    for (i, name) in ["X", "Y", "Z"].into_iter().enumerate() {
        close(
            &format!("{name} ACS"),
            meas(&r, name, "acs").unwrap(),
            acs[i],
            LATCH_TOL,
        );
        close(
            &format!("{name} MESS"),
            meas(&r, name, "mess").unwrap(),
            cs[i],
            LATCH_TOL,
        );
        assert!(merf(&r, name), "{name}: MERF");
    }
}

#[test]
fn independent_measurement_path_without_probe() {
    let r = run_json("independent_measurement_path.nc", &[], 0);
    completed_without_messages(&r);
    assert_eq!((command(&r, "X"), command(&r, "Y")), (100.0, 100.0));
    assert!(!merf(&r, "X") && !merf(&r, "Y"));
}

#[test]
fn independent_measurement_path_latches_each_axis() {
    // Seed 004 §2: "The measuring point is latched for each axis involved." The probe at X = 40
    // is looped to every measurement axis (§4), so at that instant X latches 40 and Y its own
    // position; each stops on its own signal.
    let r = run_json(
        "independent_measurement_path.nc",
        &["--probe-at", "X=40"],
        0,
    );
    completed_without_messages(&r);
    close("X", meas(&r, "X", "acs").unwrap(), 40.0, LATCH_TOL);
    assert!(merf(&r, "X") && merf(&r, "Y"));
    let y = meas(&r, "Y", "acs").expect("Y latched");
    // Y (16.7 mm/s) is about twice as far as X (8.3 mm/s) when X crosses 40.
    assert!(y > 70.0 && y < 90.0, "Y latched {y}");
    assert!(command(&r, "X") < 41.0, "X stopped on its signal");
    assert!(command(&r, "Y") < 100.0, "Y stopped on its signal");
}

#[test]
fn meas_example_with_the_2_mm_ball() {
    // D1 = ball radius 2 mm (default machine). G100 Z20 from Z200 downwards, probe at Z = 100:
    // the ball centre is latched at 100 (MESS, ACS), the contact point is 2 mm further in the
    // direction of motion (PCS value 98, P-CHAN-00311 = 0); MOFFS = 100 − 20 (no tool length).
    let r = run_json("meas_example.nc", &["--probe-at", "Z=100"], 0);
    completed_without_messages(&r);
    close("MESS", meas(&r, "Z", "mess").unwrap(), 100.0, LATCH_TOL);
    close("ACS", meas(&r, "Z", "acs").unwrap(), 100.0, LATCH_TOL);
    close("PCS", meas(&r, "Z", "pcs").unwrap(), 98.0, LATCH_TOL);
    close("MOFFS", meas(&r, "Z", "moffs").unwrap(), 80.0, LATCH_TOL);
    assert!(merf(&r, "Z"));
}

#[test]
fn meas_example_pcs_without_ball_radius() {
    // P-CHAN-00311 = 1: the ball radius is not included in the PCS value.
    let r = run_json(
        "meas_example.nc",
        &["--probe-at", "Z=100", "--set", "P-CHAN-00311=1"],
        0,
    );
    close("PCS", meas(&r, "Z", "pcs").unwrap(), 100.0, LATCH_TOL);
}

// ---------------------------------------------------------------------------------------------
// §7.3 fixed stop
// ---------------------------------------------------------------------------------------------

#[test]
fn fixed_stop_canopen_example() {
    // Wall at Z = 150; lag limit 1 mm (P-AXIS-00774 = 10000 × 0.1 µm) for 20 ms (P-AXIS-00775).
    // N050 G100 Z1000 F100 latches the wall; N060 G01 Z100 moves back.
    let r = run_json(
        "meas_fixed_stop_canopen.nc",
        &[
            "--fixed-stop-at",
            "Z=150",
            "--set",
            "Z.kenngr.measure.signal=FIXED_STOP",
            "--set",
            "Z.P-AXIS-00774=10000",
            "--set",
            "Z.P-AXIS-00775=20000",
        ],
        0,
    );
    completed_without_messages(&r);
    close("Z latched", meas(&r, "Z", "acs").unwrap(), 150.0, LATCH_TOL);
    close(
        "Z MOFFS",
        meas(&r, "Z", "moffs").unwrap(),
        150.0 - 1000.0,
        LATCH_TOL,
    );
    assert!(merf(&r, "Z"));
    assert_eq!(command(&r, "Z"), 100.0);
}

#[test]
fn fixed_stop_sercos_gantry_example() {
    // examples/machines/gantry.toml: messtyp 7, lag limit 0.1 mm for 10 ms on X, Y, Z, Z2; X2 is
    // the gantry slave of X. Wall at X = 300: X latches the wall; N130 G01 X100 moves back.
    let r = run_json(
        "meas_fixed_stop_sercos.nc",
        &[
            "--machine",
            "examples/machines/gantry.toml",
            "--fixed-stop-at",
            "X=300",
        ],
        0,
    );
    completed_without_messages(&r);
    close("X latched", meas(&r, "X", "acs").unwrap(), 300.0, LATCH_TOL);
    assert!(merf(&r, "X"));
    assert_eq!(command(&r, "X"), 100.0);
    // The slave followed X back: it started at 0 with X at 100.
    assert_eq!(command(&r, "X2"), 0.0);
    // Y, Z, Z2 moved along the block's line (start (100, 0, 0, 0), target 1000 each) and were
    // latched where they were when the stop was detected; they stay at the latched value.
    let y = meas(&r, "Y", "acs").unwrap();
    for name in ["Z", "Z2"] {
        close(name, meas(&r, name, "acs").unwrap(), y, 2.0 * LATCH_TOL);
    }
    // X reached the wall after 200 mm, Y had done 200·1000/900 then; detection follows.
    assert!(y > 200.0 * 1000.0 / 900.0 && y < 240.0, "Y latched {y}");
    close("Y rests at its latch", command(&r, "Y"), y, LATCH_TOL);
}

#[test]
fn cli_reports_the_measurement_errors_on_stderr() {
    // Type 2 (P-CHAN-00057 = 2) without a probe: error 900041 in the measuring block, exit 1,
    // stderr `error <ID>: <text> (N<block>)`.
    let dir = tempfile::tempdir().unwrap();
    let prog = dir.path().join("t2.nc");
    std::fs::write(&prog, "N10 G01 G90 Z200 F2000\nN20 G100 Z20\nN30 M30\n").unwrap();
    let o = fieldprobe(&["run", prog.to_str().unwrap(), "--set", "P-CHAN-00057=2"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.starts_with("error 900041: "), "{err}");
    assert!(err.trim_end().ends_with("(N20)"), "{err}");
}
