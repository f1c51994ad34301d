//! `fieldprobe run --trace FILE`: the recorded trace (latches only of axes that measured) and the
//! picture formats (SVG, PNG; other extensions refused with exit 2).

use crate::common::cli;

use cli::{fieldprobe, stderr};
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;
/// 0.1 µm in mm: the latch resolution of the drive model.
const LATCH_TOL: f64 = 1e-4;

/// The default machine recording a trace, with the probe switching at `probe`, looped to the
/// digital input 1 of the axes `wired` only.
fn traced_machine(probe: (&str, f64), wired: &[usize]) -> Machine {
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let p = m.add_probe(probe.0, probe.1).unwrap();
    m.link_mut().plant_mut().unwrap().probe_surfaces_mut()[p].wired =
        wired.iter().map(|a| (*a, 1)).collect();
    m.enable_trace();
    m
}

fn latched_axes(m: &Machine) -> Vec<usize> {
    m.trace().unwrap().latches.iter().map(|l| l.1).collect()
}

#[test]
fn trace_marks_latches_only_on_axes_that_measured() {
    // G100 X10 Y10: both move, so both must latch (seed 004 §4); the probe at X = 4 is looped to
    // X only. X's drive latches, but the signal is incomplete: nothing is measured (type 1, no
    // error), so the trace has no latch.
    let mut m = traced_machine(("X", 4.0), &[X]);
    let r = m.run_program(
        &parse("N10 G100 X10 Y10 F1000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.measurements[X].result, None);
    assert_eq!(latched_axes(&m), Vec::<usize>::new(), "nothing measured");

    // G100 Z50 with the probe at Z = 30 looped to every axis: X and Y are not programmed, only Z
    // measured — one latch, on Z, at 30.
    let mut m = traced_machine(("Z", 30.0), &[X, Y, Z]);
    let r = m.run_program(
        &parse("N10 G100 Z50 F1000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(latched_axes(&m), vec![Z]);
    let (t, _, p) = m.trace().unwrap().latches[0];
    assert!((p - 30.0).abs() <= LATCH_TOL, "latched at {p}");
    // 30 mm at F1000 (16.7 mm/s) take at least 1.8 s; the mark lies within the recorded run.
    let t_end = *m.trace().unwrap().t.last().unwrap();
    assert!(
        t > 1.8 && t <= t_end,
        "latch at {t} s, run ends at {t_end} s"
    );
}

/// Run `meas1` (probe at ACS Z = 100) with `--trace DIR/NAME`; returns the output and the path.
fn traced_cli_run(
    program: &str,
    probe: &str,
    name: &str,
) -> (std::process::Output, std::path::PathBuf, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join(name);
    let o = fieldprobe(&[
        "run",
        program,
        "--probe-at",
        probe,
        "--link",
        "sim",
        "--trace",
        out.to_str().unwrap(),
    ]);
    (o, out, dir)
}

/// Width and height from a PNG's IHDR chunk, after checking the signature.
fn png_size(png: &[u8]) -> (u32, u32) {
    assert!(png.len() > 24, "too short for a PNG: {} bytes", png.len());
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&png[12..16], b"IHDR");
    (
        u32::from_be_bytes(png[16..20].try_into().unwrap()),
        u32::from_be_bytes(png[20..24].try_into().unwrap()),
    )
}

#[test]
fn trace_png_is_a_png_with_one_row_per_axis_that_moved() {
    // meas1 moves Z only: one row of 1200 × 320 pixels.
    let (o, out, _dir) = traced_cli_run("examples/nc/seed004/meas1.nc", "Z=100", "meas1.png");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let png = std::fs::read(&out).expect("PNG written");
    assert_eq!(png_size(&png), (1200, 320));
    // A white page of this size compresses to a few hundred bytes; curves, grid and the
    // pixel-font labels make tens of kilobytes.
    assert!(
        png.len() > 10_000,
        "a picture, not an empty page: {}",
        png.len()
    );
    // meas4 moves X and Z under #CS, where all three main axes latch (seed 004 §4): Y stands
    // still but measured, so it has a row too — three rows. The extension is read in any case.
    let (o, out, _dir) = traced_cli_run("examples/nc/seed004/meas4.nc", "Z=55.5", "meas4.PNG");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(png_size(&std::fs::read(&out).unwrap()), (1200, 3 * 320));
}

#[test]
fn trace_svg_still_works() {
    let (o, out, _dir) = traced_cli_run("examples/nc/seed004/meas1.nc", "Z=100", "meas1.svg");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    for text in [
        "Z position [mm]",
        "Z velocity [mm/s]",
        "100.000000",
        "latch",
    ] {
        assert!(svg.contains(text), "{text:?} missing");
    }
}

#[test]
fn trace_with_another_extension_is_refused_before_the_run() {
    for name in ["meas1.jpg", "meas1"] {
        let (o, out, _dir) = traced_cli_run("examples/nc/seed004/meas1.nc", "Z=100", name);
        assert_eq!(o.status.code(), Some(2), "{name}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(
            e.contains(out.to_str().unwrap()) && e.contains(".svg") && e.contains(".png"),
            "names the file and the allowed extensions: {e}"
        );
        assert!(!out.exists(), "nothing written");
        assert_eq!(cli::stdout(&o), "", "the program did not run");
    }
}
