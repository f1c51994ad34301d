//! Acceptance: the G98 / G99 programming examples of seed 001 (§3.1, §3.2, §3.3) run through
//! `fieldprobe run` and produce the limits and messages the seed describes; the CLI contract of
//! DESIGN.md (stdout `#MSG`, stderr `warning|error <ID>: … (N<block>)`, exit codes 0 / 1 / 2).
//!
//! Expected values by hand from the seed: the default SLS are P-AXIS-00177 / 00178 =
//! ∓100000000 × 0.1 µm = ∓10000 mm; relative G98 / G99 (G91) add to those.

use crate::common::cli;
use cli::{fieldprobe, stderr, stdout};
use std::path::Path;

#[test]
fn seed_3_1_example_1_absolute_negative_sls() {
    let o = fieldprobe(&["run", "examples/nc/seed001/swe_neg_abs.nc"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o), "neg. SLS X=-100.000000 Y=-200.000000\n");
    assert_eq!(stderr(&o), "");
}

#[test]
fn seed_3_1_example_2_relative_negative_sls() {
    let o = fieldprobe(&["run", "examples/nc/seed001/swe_neg_rel.nc"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // −10000 + 10 and −10000 + 20.
    assert_eq!(stdout(&o), "neg. SLS X=-9990.000000 Y=-9980.000000\n");
}

#[test]
fn seed_3_2_example_1_absolute_positive_sls() {
    let o = fieldprobe(&["run", "examples/nc/seed001/swe_pos_abs.nc"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o), "pos. SLS X=100.000000 Y=200.000000\n");
}

#[test]
fn seed_3_2_example_2_relative_positive_sls() {
    let o = fieldprobe(&["run", "examples/nc/seed001/swe_pos_rel.nc"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o), "pos. SLS X=9990.000000 Y=9980.000000\n");
}

#[test]
fn seed_3_3_extension_with_g98_g99_and_back() {
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed001/swe_extend.nc",
        "--machine",
        "examples/machines/xy200.toml",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        stdout(&o),
        "SLS X [-200.000000, 200.000000] Y [-200.000000, 200.000000]\n\
         SLS X [-500.000000, 500.000000] Y [-500.000000, 500.000000]\n\
         at X=450.000000 Y=450.000000\n\
         SLS X [-200.000000, 200.000000] Y [-200.000000, 200.000000]\n"
    );
    assert_eq!(stderr(&o), "");
}

#[test]
fn seed_3_3_with_p_chan_00498_extension_is_refused() {
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed001/swe_extend.nc",
        "--machine",
        "examples/machines/xy200.toml",
        "--set",
        "P-CHAN-00498=1",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 6, "{err}");
    assert!(
        lines[0].starts_with("warning 21648: ") && lines[0].ends_with("(N100)"),
        "{}",
        lines[0]
    );
    assert!(lines[1].starts_with("warning 21648: ") && lines[1].ends_with("(N100)"));
    assert!(lines[2].starts_with("warning 21650: ") && lines[2].ends_with("(N200)"));
    assert!(lines[3].starts_with("warning 21650: ") && lines[3].ends_with("(N200)"));
    // N300 G01 X450 Y450 now crosses the limit in block preparation: not executed.
    assert!(
        lines[4].starts_with("error 120002: ") && lines[4].ends_with("(N300)"),
        "{}",
        lines[4]
    );
    assert!(
        lines[4].contains("axis X") && lines[5].contains("axis Y"),
        "{err}"
    );
    assert!(
        lines[5].starts_with("error 120002: ") && lines[5].ends_with("(N300)"),
        "{}",
        lines[5]
    );
    // The first #MSG still ran; the second shows the refused extension; nothing after N300.
    assert_eq!(
        stdout(&o),
        "SLS X [-200.000000, 200.000000] Y [-200.000000, 200.000000]\n\
         SLS X [-200.000000, 200.000000] Y [-200.000000, 200.000000]\n"
    );
}

#[test]
fn arc_with_apex_beyond_limit_is_refused() {
    let o = fieldprobe(&[
        "run",
        "examples/nc/arc_limit.nc",
        "--machine",
        "examples/machines/xy200.toml",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).starts_with("error 120002: "), "{}", stderr(&o));
    assert!(stderr(&o).trim_end().ends_with("(N20)"));
    assert_eq!(stdout(&o), "");
}

#[test]
fn json_output_reports_limits_and_pcs_objects() {
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed001/swe_pos_abs.nc",
        "--json",
        "--set",
        "P-CHAN-00489=1",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["status"], "completed");
    assert_eq!(v["msg"][0], "pos. SLS X=100.000000 Y=200.000000");
    assert_eq!(v["axes"][0]["name"], "X");
    assert_eq!(v["axes"][0]["sls_positive"], 100.0);
    assert_eq!(v["axes"][1]["sls_positive"], 200.0);
    assert_eq!(v["axes"][0]["command"], 20.0);
    // P-CHAN-00489: no offsets, so PCS = ACS; distance to +limit 100 − 20.
    assert_eq!(v["axes"][0]["pcs_limits"]["distance_positive"], 80.0);
}

#[test]
fn json_pcs_limits_include_a_rotating_cs() {
    // Seed 001 §2.1: P-CHAN-00489 transforms the active ACS limits into the PCS, "Cartesian
    // transformations (#CS)" included. xy200: X and Y ±200 mm; G99 Y150 makes Y's positive
    // limit 150. #CS ON[10,0,0,0,0,90] (interpretation M2): ACS = (10, 0, 0) + R_z(90°)·PCS,
    // R_z(90°)·(x, y) = (−y, x), so ACS X = 10 − PCS Y and ACS Y = PCS X. `G00 X5 Y5` ends at
    // PCS (5, 5) = ACS (5, 5).
    // PCS X runs along ACS Y: PCS X = ACS Y ∈ [−200, 150].
    // PCS Y runs along −ACS X: PCS Y = 10 − ACS X ∈ [10 − 200, 10 + 200] = [−190, 210].
    // Distances from PCS 5: X 150 − 5 = 145, 5 − (−200) = 205; Y 210 − 5 = 205, 5 − (−190) = 195.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("cs.nc");
    std::fs::write(&p, "G99 Y150\n#CS ON[10,0,0,0,0,90]\nG00 X5 Y5\n").unwrap();
    let o = fieldprobe(&[
        "run",
        p.to_str().unwrap(),
        "--machine",
        "examples/machines/xy200.toml",
        "--json",
        "--set",
        "P-CHAN-00489=1",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let close = |axis: usize, key: &str, expected: f64| {
        let got = v["axes"][axis]["pcs_limits"][key]
            .as_f64()
            .unwrap_or_else(|| panic!("axis {axis} {key}: {}", v["axes"][axis]));
        assert!(
            (got - expected).abs() < 1e-9,
            "axis {axis} {key}: {got}, expected {expected}"
        );
    };
    // ACS command positions as worked out above.
    for axis in [0, 1] {
        let c = v["axes"][axis]["command"].as_f64().unwrap();
        assert!((c - 5.0).abs() < 1e-9, "ACS command {c}");
    }
    close(0, "negative", -200.0);
    close(0, "positive", 150.0);
    close(0, "distance_negative", 205.0);
    close(0, "distance_positive", 145.0);
    close(1, "negative", -190.0);
    close(1, "positive", 210.0);
    close(1, "distance_negative", 195.0);
    close(1, "distance_positive", 205.0);
    // The monitoring itself stays in the ACS (§2.1 notice).
    assert_eq!(v["axes"][1]["sls_positive"], 150.0);
}

#[test]
fn set_order_does_not_matter() {
    // The cross checks (seed 001 §4.3 P-AXIS-00177 < P-AXIS-00178) run after all --sets. On
    // xy200 (X ±200 mm), [250, 300] needs both: the old code refused one order with exit 2. With
    // the range moved, the axis at 0 lies below the negative limit: 70022 either way.
    let neg = "X.P-AXIS-00177=2500000";
    let pos = "X.P-AXIS-00178=3000000";
    let run = |first: &str, second: &str| {
        fieldprobe(&[
            "run",
            "examples/nc/hello.nc",
            "--machine",
            "examples/machines/xy200.toml",
            "--set",
            first,
            "--set",
            second,
        ])
    };
    let (a, b) = (run(neg, pos), run(pos, neg));
    assert_eq!(a.status.code(), Some(1), "{}", stderr(&a));
    assert_eq!(
        (b.status.code(), stderr(&b), stdout(&b)),
        (a.status.code(), stderr(&a), stdout(&a))
    );
    assert!(stderr(&a).starts_with("error 70022: "), "{}", stderr(&a));
    // A pair that breaks the rule after both: exit 2 naming both parameters, either order.
    let bad = "X.P-AXIS-00178=2400000";
    for (first, second) in [(neg, bad), (bad, neg)] {
        let o = run(first, second);
        assert_eq!(o.status.code(), Some(2));
        let e = stderr(&o);
        assert!(
            e.contains("--set (axis X): P-AXIS-00177 kenngr.swe_neg = 2500000 must be < P-AXIS-00178 kenngr.swe_pos = 2400000"),
            "{e}"
        );
    }
}

#[test]
fn bad_input_exits_2_naming_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.nc");
    std::fs::write(&p, "N10 G01 X10 F100\nN20 G01 Q5\n").unwrap();
    let o = fieldprobe(&["run", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("bad.nc:2:9"), "{e}");

    let o = fieldprobe(&["run", "examples/nc/hello.nc", "--set", "X.P-AXIS-00179=-5"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("P-AXIS-00179"), "{}", stderr(&o));

    let o = fieldprobe(&["run", "examples/nc/hello.nc", "--set", "X.kenngr.swe_nge=5"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("kenngr.swe_neg"),
        "closest key suggested: {}",
        stderr(&o)
    );

    let m = dir.path().join("m.toml");
    std::fs::write(
        &m,
        "[channel]\n\n[[axis]]\nname = \"X\"\nkenngr.swe_pos = \"abc\"\n",
    )
    .unwrap();
    let o = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--machine",
        m.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("m.toml:5"), "{}", stderr(&o));

    let o = fieldprobe(&["run", "examples/nc/hello.nc", "--link", "ethercat:eth0"]);
    assert_eq!(o.status.code(), Some(2));

    let o = fieldprobe(&["run", "does-not-exist.nc"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("does-not-exist.nc"));
}

#[test]
fn unknown_axis_in_program_is_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("ax.nc");
    std::fs::write(&p, "N10 G01 X10 F100\nN20 G01 B5\n").unwrap();
    let o = fieldprobe(&["run", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("ax.nc:2:9") && stderr(&o).contains("'B'"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn hello_example_runs_on_the_default_machine() {
    assert!(Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/nc/hello.nc")
        .exists());
    let o = fieldprobe(&["run", "examples/nc/hello.nc"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        stdout(&o),
        "X=0.000000 Y=0.000000 Z=0.000000\nSLS X [-10000.000000, 10000.000000]\n"
    );
}

#[test]
fn jog_subcommand_reports_limit_and_warning() {
    let o = fieldprobe(&[
        "jog",
        "--axis",
        "X",
        "--continuous",
        "+",
        "--set",
        "P-MANU-00014=1",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // Relative offset limit P-AXIS-00138 default 1000000 × 0.1 µm = 100 mm from X0.
    assert!(
        stdout(&o).starts_with("X command 100.000000"),
        "{}",
        stdout(&o)
    );
    assert!(stderr(&o).starts_with("warning 50720: "), "{}", stderr(&o));
    let o = fieldprobe(&["jog", "--axis", "X", "--step", "150"]);
    assert!(stderr(&o).starts_with("warning 150008: "), "{}", stderr(&o));
    assert!(
        stdout(&o).starts_with("X command 0.000000"),
        "{}",
        stdout(&o)
    );
}

#[test]
fn trace_svg_is_written_with_latch_marked() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("run.svg");
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--trace",
        svg.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg"), "an SVG document");
    assert!(text.contains("Z position [mm]") && text.contains("Z velocity [mm/s]"));
    // The latched value is written next to its marker.
    assert!(text.contains("100.000000"), "latched value labelled");
}
