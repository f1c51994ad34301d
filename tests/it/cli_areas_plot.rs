//! `fieldprobe areas plot`: the picture of the control areas, the executed path and the first
//! violation (SVG and PNG), exit codes and bad input.

use crate::common::cli;

use cli::{fieldprobe, stderr};

/// Output of a run and the picture path (in a temporary directory that lives as long as this).
struct Plot {
    o: std::process::Output,
    out: std::path::PathBuf,
    _dir: tempfile::TempDir,
}

/// Run `areas plot PROGRAM --out TMPDIR/NAME [EXTRA…]`.
fn plot(program: &str, name: &str, extra: &[&str]) -> Plot {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join(name);
    let out_s = out.to_str().unwrap().to_string();
    let mut args = vec!["areas", "plot", program, "--out", &out_s];
    args.extend_from_slice(extra);
    Plot {
        o: fieldprobe(&args),
        out,
        _dir: dir,
    }
}

/// The contents of the `<text>` elements of an SVG, in order.
fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let body = &t[t.find('>')? + 1..];
            Some(body[..body.find("</text>")?].trim().to_string())
        })
        .collect()
}

#[test]
fn violating_program_svg_shows_areas_path_and_violation() {
    let Plot { o, out, _dir } = plot("examples/nc/areas_poly.nc", "poly.svg", &[]);
    assert_eq!(o.status.code(), Some(1), "stderr: {}", stderr(&o));
    // The CNC error in the format of `fieldprobe run`.
    assert!(
        stderr(&o).contains("error 900316: the path enters protection area 4")
            && stderr(&o).contains("(N230)"),
        "stderr: {}",
        stderr(&o)
    );
    let svg = std::fs::read_to_string(&out).expect("SVG written although the run aborted");
    assert!(svg.contains("<svg"), "{svg}");
    assert!(svg.trim_end().ends_with("</svg>"));
    let texts = svg_texts(&svg);
    for want in [
        "ID 3 WORK",
        "ID 4 PROT",
        "block N230: enters protection area 4",
        "refused block",
        "first violation",
        "X [mm]",
        "Y [mm]",
    ] {
        assert!(texts.iter().any(|t| t == want), "{want:?} not in {texts:?}");
    }
    // Two filled areas, hatching of the protection area, the path polylines and the dashed
    // refused arc.
    let count = |tag: &str| svg.matches(tag).count();
    assert_eq!(count("<polygon"), 2, "one fill per area");
    assert!(
        count("<polyline") >= 20,
        "outlines, hatching, path: {}",
        count("<polyline")
    );
    assert!(count("<line") >= 10, "dashes and grid: {}", count("<line"));
}

#[test]
fn program_that_runs_to_its_end_exits_0_and_marks_no_violation() {
    let Plot { o, out, _dir } = plot("examples/nc/areas_ok.nc", "ok.svg", &[]);
    assert_eq!(o.status.code(), Some(0), "stderr: {}", stderr(&o));
    assert!(cli::stdout(&o).contains("areas_ok done"));
    let svg = std::fs::read_to_string(&out).unwrap();
    let texts = svg_texts(&svg);
    for want in [
        "ID 3 WORK",
        "ID 4 PROT",
        "ID 5 PROT (inactive)",
        "executed path",
    ] {
        assert!(texts.iter().any(|t| t == want), "{want:?} not in {texts:?}");
    }
    assert!(
        !texts
            .iter()
            .any(|t| t.starts_with("block ") || t == "first violation"),
        "{texts:?}"
    );
    assert_eq!(svg.matches("<polygon").count(), 3);
}

#[test]
fn png_is_written_with_the_requested_size() {
    let Plot { o, out, _dir } = plot("examples/nc/areas_poly.nc", "poly.png", &[]);
    assert_eq!(o.status.code(), Some(1), "stderr: {}", stderr(&o));
    let png = std::fs::read(&out).expect("PNG written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    // IHDR: length, "IHDR", width, height (big endian).
    assert_eq!(&png[12..16], b"IHDR");
    let w = u32::from_be_bytes(png[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(png[20..24].try_into().unwrap());
    assert_eq!((w, h), (1000, 800));
    assert!(
        png.len() > 10_000,
        "a picture, not an empty image: {}",
        png.len()
    );
}

#[test]
fn plane_option_swaps_the_axes_and_rejects_unknown_axes() {
    let Plot { o, out, _dir } = plot("examples/nc/areas_ok.nc", "yx.svg", &["--plane", "Y,X"]);
    assert_eq!(o.status.code(), Some(0), "stderr: {}", stderr(&o));
    let texts = svg_texts(&std::fs::read_to_string(&out).unwrap());
    assert!(
        texts.iter().any(|t| t == "Control areas in the YX plane"),
        "{texts:?}"
    );
    assert!(texts.iter().any(|t| t == "ID 3 WORK"), "{texts:?}");

    let Plot { o, out, _dir } = plot("examples/nc/areas_ok.nc", "bad.svg", &["--plane", "X,Q"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--plane X,Q: no channel axis Q"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

#[test]
fn unknown_extension_is_bad_input_naming_the_allowed_ones() {
    let Plot { o, out, _dir } = plot("examples/nc/areas_poly.nc", "poly.jpg", &[]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("poly.jpg") && e.contains(".svg") && e.contains(".png"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn missing_program_is_bad_input_naming_the_file() {
    let Plot { o, _dir, .. } = plot("examples/nc/no_such_program.nc", "x.svg", &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("examples/nc/no_such_program.nc"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn parse_error_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let prog = dir.path().join("bad.nc");
    std::fs::write(&prog, "N10 G01 X0 Y0 F1000\nN20 G01 X=]\n").unwrap();
    let Plot { o, out, _dir } = plot(prog.to_str().unwrap(), "bad.svg", &[]);
    assert_eq!(o.status.code(), Some(2), "stderr: {}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("{}:2:", prog.display())),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

/// Issue 27 item 4: an area defined under G18 lies in Z/X (seed 000 §3.1.1 "the first two main
/// axes of the active machining plane"); the default picture plane is that of the first area,
/// Z,X, and the violation is drawn where the path meets its face X = 40.
#[test]
fn a_g18_area_is_drawn_in_the_z_x_plane() {
    let dir = tempfile::tempdir().unwrap();
    let prog = dir.path().join("g18.nc");
    std::fs::write(
        &prog,
        "N10 G18\n\
         N20 #CONTROL AREA BEGIN [ID5 PROT POLY MIN_EXCUR=-5 MAX_EXCUR=5]\n\
         N30 G01 F1000 G90 Z-10 X40\nN40 Z10\nN50 X60\nN60 Z-10\nN70 X40\n\
         N80 #CONTROL AREA END\n\
         N90 G01 X0 Y0 Z0 F5000\nN100 #CONTROL AREA ON [ID5]\n\
         N110 G01 X100\nN120 M30\n",
    )
    .unwrap();
    let Plot { o, out, _dir } = plot(prog.to_str().unwrap(), "g18.svg", &[]);
    assert_eq!(o.status.code(), Some(1), "stderr: {}", stderr(&o));
    assert!(
        stderr(&o).contains("error 900316: the path enters protection area 5")
            && stderr(&o).contains("(N110)"),
        "stderr: {}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("not drawn"), "{}", stderr(&o));
    let texts = svg_texts(&std::fs::read_to_string(&out).unwrap());
    for want in [
        "Control areas in the ZX plane",
        "Z [mm]",
        "X [mm]",
        "ID 5 PROT",
        "block N110: enters protection area 5",
    ] {
        assert!(texts.iter().any(|t| t == want), "{want:?} not in {texts:?}");
    }
    // In the X,Y plane the Z/X square is not drawn, and the note says which plane it lies in.
    let Plot { o, out, _dir } = plot(prog.to_str().unwrap(), "xy.svg", &["--plane", "X,Y"]);
    assert_eq!(o.status.code(), Some(1), "stderr: {}", stderr(&o));
    assert!(
        stderr(&o).contains("area 5 lies in the plane Z,X, not in X,Y: not drawn"),
        "{}",
        stderr(&o)
    );
    assert!(out.exists());
}
