//! Workspace and protection areas through the whole stack (seed 000, FCT-C14): NC program →
//! parser → executor → channel area table → block preparation path check → `link::sim`.
//!
//! Expected geometry is typed in from the seed text; expected violation points are computed here
//! with closed-form circle / line intersections, independently of `area_geom`.

use crate::common::cli;

use fieldprobe::channel::areas::AreaRefusal;
use fieldprobe::core::monitor::area_monitor::{HitKind, AREA_TOLERANCE};
use fieldprobe::core::monitor::areas::{AreaGeometry, AreaState, MonitorLevel};
use fieldprobe::machine::{Machine, RunReport, RunStatus};
use fieldprobe::messages::CncMessage;
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

fn machine() -> Machine {
    Machine::new(&MachineConfig::default_machine()).unwrap()
}

fn machine_from(toml: &str) -> Machine {
    let cfg = MachineConfig::parse(toml, "test.toml").unwrap();
    Machine::new(&cfg).unwrap()
}

fn run_on(m: &mut Machine, src: &str) -> RunReport {
    let program = parse(src).unwrap_or_else(|e| panic!("{e}\n{src}"));
    m.run_program(&program, &mut |_| {})
}

fn pos(m: &Machine) -> Vec<f64> {
    m.channel().command_positions()
}

fn polygon(m: &Machine, id: u32) -> Vec<[f64; 2]> {
    match &m.channel().areas().area(id).expect("area defined").geometry {
        AreaGeometry::Polygon { vertices } => vertices.clone(),
        other => panic!("area {id} is not a polygon: {other:?}"),
    }
}

fn refusal(m: &Machine) -> AreaRefusal {
    m.channel()
        .area_refusal()
        .cloned()
        .expect("a refused block")
}

/// The first error of an aborted run.
fn first_error(r: &RunReport) -> CncMessage {
    assert_eq!(r.status, RunStatus::Aborted, "{:?}", r.messages());
    r.messages()
        .into_iter()
        .find(|m| m.is_error())
        .cloned()
        .expect("an error")
}

/// (message ID, block number).
fn id_block(m: &CncMessage) -> (u32, Option<u32>) {
    (m.id, m.block.and_then(|b| b.number))
}

fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tol {tol})");
}

/// Seed 000 §3.1.1, verbatim.
const SEED_POLY: &str = "\
N10 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X-150 Y75 (Starting point)
N30 X-50 Y150
N40 X50 Y150
N50 X150 Y75
N60 X150 Y0
N70 X50 Y0
N80 X50 Y75
N90 X-50 Y75
N100 X-50 Y0
N120 X-150 Y0
N130 X-150 Y75 (End point identical with starting point)
N140 #CONTROL AREA END
";

/// Seed 000 §3.1.2, verbatim.
const SEED_CIRC: &str = "\
N10 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N20 G01 X0 Y0 F10000      (Start point for cyl. protection space)
N30 G02 G162 I0 J75       (Definition of the full circle)
N40 #CONTROL AREA END
";

#[test]
fn seed_poly_program_defines_the_shown_polygon_without_moving() {
    let mut m = machine();
    let before = m.now();
    let r = run_on(&mut m, &format!("{SEED_POLY}N150 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(r.messages().is_empty(), "{:?}", r.messages());
    // Seed 000 §3.1.1 program: the ten distinct points in programmed order.
    let expected = [
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
    ];
    assert_eq!(polygon(&m, 3), expected);
    let a = m.channel().areas().area(3).unwrap();
    assert_eq!((a.header.min_excur, a.header.max_excur), (-50.0, 50.0));
    assert_eq!(m.channel().areas().state(3), AreaState::Defined);
    // The definition blocks did not move the axes (still at the start position 0).
    assert_eq!(pos(&m), vec![0.0; 3]);
    // Defining takes no motion time: far less than the ~1 s a 1000 mm/min move of 150 mm needs.
    assert!(m.now().as_secs_f64() - before.as_secs_f64() < 0.5);
}

#[test]
fn seed_circ_program_defines_centre_radius_and_extents() {
    let mut m = machine();
    let r = run_on(&mut m, &format!("{SEED_CIRC}N50 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let a = m.channel().areas().area(4).unwrap();
    // G162: centre = start (0, 0) + (I0, J75); radius = |start − centre| = 75.
    assert_eq!(
        a.geometry,
        AreaGeometry::Circle {
            centre: [0.0, 75.0],
            radius: 75.0
        }
    );
    let e = a.extents();
    assert_eq!(e.min, [-75.0, 0.0, -70.0]);
    assert_eq!(e.max, [75.0, 150.0, 70.0]);
    assert_eq!(pos(&m), vec![0.0; 3]);
}

const SQUARE_DEF: &str = "\
N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N20 G01 G90 F1000 X0 Y0
N30 X100
N40 Y100
N50 X0
N60 Y0
N70 #CONTROL AREA END
";

#[test]
fn definition_is_in_mcs_with_g92_and_ignores_cs() {
    // ISG G92 shifts the PCS additively (ACS = PCS + G92 value, seed 004 §5 meas2).
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!(
            "N5 G92 X10 Y20\nN6 #CS ON [0, 0, 0, 0, 0, 90]\n{SQUARE_DEF}N80 #CS OFF\nN90 M30\n"
        ),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(
        polygon(&m, 1),
        [[10.0, 20.0], [110.0, 20.0], [110.0, 120.0], [10.0, 120.0]]
    );
}

#[test]
fn definition_takes_the_g54_zero_offset() {
    let mut m = machine_from(
        r#"
[[axis]]
name = "X"
[[axis]]
name = "Y"
[[axis]]
name = "Z"
[zero_offset.G54]
X = 1000000
Y = -500000
"#,
    );
    let r = run_on(&mut m, &format!("N5 G54\n{SQUARE_DEF}N90 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    // 1000000 / -500000 in 0.1 µm = 100 / -50 mm.
    assert_eq!(
        polygon(&m, 1),
        [[100.0, -50.0], [200.0, -50.0], [200.0, 50.0], [100.0, 50.0]]
    );
}

#[test]
fn definition_errors_name_the_block() {
    let cases: &[(&str, u32, u32)] = &[
        // G91 inside the definition (seed §3.1 attention): 900301 at N30.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 F100 X0 Y0\nN30 G91 X10\nN40 #CONTROL AREA END\n",
            900301,
            30,
        ),
        // No F active (seed §3.1): 900302 at N20.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 X0 Y0\nN40 #CONTROL AREA END\n",
            900302,
            20,
        ),
        // G00 in an MCS polygon: 900303 at N30.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 F100 X0 Y0\nN30 G00 X10\nN40 #CONTROL AREA END\n",
            900303,
            30,
        ),
        // Not closed: 900305, named at the last point (N40), found at END.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 F100 X0 Y0\nN30 X10\nN40 Y10\nN60 #CONTROL AREA END\n",
            900305,
            40,
        ),
        // Bow tie: 900307, named at the block whose edge crosses an earlier one (N50).
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 F100 X0 Y0\nN30 X10 Y10\nN40 X10 Y0\nN50 X0 Y10\nN55 X0 Y0\nN60 #CONTROL AREA END\n",
            900307,
            50,
        ),
        // MIN_EXCUR >= MAX_EXCUR: 900309 at BEGIN.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=5 MAX_EXCUR=5]\nN40 #CONTROL AREA END\n",
            900309,
            10,
        ),
        // CIRC with a G01 instead of the circle: 900303 at N30.
        (
            "N10 #CONTROL AREA BEGIN [ID1 PROT CIRC MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 F100 X0 Y0\nN30 X10\nN40 #CONTROL AREA END\n",
            900303,
            30,
        ),
        // A motion that is not a straight line or arc (G100) in a definition.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1]\nN20 G01 G90 F100 X0 Y0\nN30 G100 X10\nN40 #CONTROL AREA END\n",
            900303,
            30,
        ),
        // EXCUR_AX names an axis the channel does not have: 900315 at END.
        (
            "N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=1 EXCUR_AX=B]\nN20 G01 G90 F100 X0 Y0\nN30 X10\nN35 Y10\nN37 X0 Y0\nN40 #CONTROL AREA END\n",
            900315,
            40,
        ),
    ];
    for (src, id, block) in cases {
        let mut m = machine();
        let r = run_on(&mut m, &format!("{src}N99 M30\n"));
        assert_eq!(r.status, RunStatus::Aborted, "{src}");
        let msg = r.messages().into_iter().find(|m| m.is_error()).unwrap();
        assert_eq!(msg.id, *id, "{src}: {msg}");
        assert_eq!(
            msg.block.and_then(|b| b.number),
            Some(*block),
            "{src}: {msg}"
        );
        // Nothing moved.
        assert_eq!(pos(&m), vec![0.0; 3], "{src}");
    }
}

/// Workspace square ±200 (ID1), protection circle centre (0, 60) radius 20 (ID4), both active,
/// TCP at (−50, 0).
const ARC_SETUP: &str = "\
N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N11 G01 G90 F2000 X-200 Y-200
N12 X200
N13 Y200
N14 X-200
N15 Y-200
N16 #CONTROL AREA END
N20 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N21 G01 X0 Y40
N22 G02 I0 J20
N23 #CONTROL AREA END
N30 G01 X-50 Y0 F5000
N40 #CONTROL AREA ON ALL
";

#[test]
fn arc_with_valid_end_points_whose_bulge_enters_a_protection_area_is_refused() {
    let mut m = machine();
    // G02 from (−50, 0) to (50, 0) about (0, 0): over the top through (0, 50), which lies in
    // the protection circle (distance 10 from its centre, radius 20).
    let r = run_on(
        &mut m,
        &format!("{ARC_SETUP}N50 G02 X50 Y0 I50 J0\nN60 #MSG SYN [\"not reached\"]\nN70 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert!(r.output().is_empty());
    let msg = r.messages().into_iter().find(|m| m.is_error()).unwrap();
    assert_eq!(msg.id, 900316, "{msg}");
    assert_eq!(msg.block.and_then(|b| b.number), Some(50));
    assert!(msg.text.contains("protection area 4"), "{msg}");
    // The block was not executed: still at its start point.
    let p = pos(&m);
    assert_close(p[0], -50.0, 1e-9, "X");
    assert_close(p[1], 0.0, 1e-9, "Y");
    // First point: circle r = 50 about the origin meets the circle r = 20 + tol about (0, 60);
    // x² + y² = 2500, x² + (y − 60)² = (20 + tol)² → y = (2500 − (20 + tol)² + 3600) / 120,
    // x < 0 (coming from the left).
    let rr = 20.0 + AREA_TOLERANCE;
    let y = (2500.0 - rr * rr + 3600.0) / 120.0;
    let x = -(2500.0 - y * y).sqrt();
    let hit = refusal(&m).hit;
    assert_eq!(hit.kind, HitKind::Protection);
    assert_eq!(hit.id, Some(4));
    assert_close(hit.point[0], x, 1e-6, "hit x");
    assert_close(hit.point[1], y, 1e-6, "hit y");
    assert!(m.channel().area_mon_violation_detected_r());
}

#[test]
fn the_same_arc_the_other_way_round_runs() {
    let mut m = machine();
    // G03: under the origin through (0, −50), far from the protection circle.
    let r = run_on(
        &mut m,
        &format!("{ARC_SETUP}N50 G03 X50 Y0 I50 J0\nN70 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_close(pos(&m)[0], 50.0, 1e-6, "X");
    assert!(!m.channel().area_mon_violation_detected_r());
}

#[test]
fn helix_is_trimmed_by_the_excursion_range() {
    // Protection circle centre (0, −150) radius 20, Z ∈ [−10, 10]. A G03 helix about (0, −100)
    // with radius 50 passes over (0, −150) half-way: at Z = (z0 + z1) / 2 there.
    let setup = "\
N10 #CONTROL AREA BEGIN [ID5 PROT CIRC MIN_EXCUR=-10 MAX_EXCUR=10]
N11 G01 G90 F2000 X0 Y-170
N12 G02 I0 J20
N13 #CONTROL AREA END
N20 G01 X-50 Y-100 Z60 F5000
N30 #CONTROL AREA ON [ID5]
";
    // Above: Z 60 → 20, at the crossing Z ≈ 40 > 10.
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{setup}N40 G03 X50 Y-100 Z20 I50 J0\nN50 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    // Through it: Z 60 → −60 crosses Z = 0 at the crossing.
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{setup}N40 G03 X50 Y-100 Z-60 I50 J0\nN50 M30\n"),
    );
    let msg = first_error(&r);
    assert_eq!(id_block(&msg), (900316, Some(40)));
    let hit = refusal(&m).hit;
    assert_eq!(hit.id, Some(5));
    // The helix enters where it reaches the top of the excursion range (+ tol): Z = 10.001, or
    // the cylinder wall, whichever comes later along the path; both are inside the cylinder
    // footprint enlarged by tol and at Z ≤ 10.001.
    assert!(hit.point[2] <= 10.0 + AREA_TOLERANCE + 1e-9, "{hit:?}");
    let d = (hit.point[0].powi(2) + (hit.point[1] + 150.0).powi(2)).sqrt();
    assert!(d <= 20.0 + AREA_TOLERANCE + 1e-9, "{hit:?}");
}

#[test]
fn g18_arc_dipping_into_a_protection_body_is_refused() {
    // Protection square X/Y ±10 extruded over Z ∈ [−100, −40]. G18 arcs from X−50 to X50 at
    // Y0, Z0 about (X0, Z0): G02 turns under (Z = −50, inside the body), G03 over the top.
    let setup = "\
N10 #CONTROL AREA BEGIN [ID6 PROT POLY MIN_EXCUR=-100 MAX_EXCUR=-40]
N11 G01 G90 F2000 X-10 Y-10
N12 X10
N13 Y10
N14 X-10
N15 Y-10
N16 #CONTROL AREA END
N20 G01 X-50 Y0 Z0 F5000
N30 #CONTROL AREA ON [ID6]
N35 G18
";
    let mut m = machine();
    let r = run_on(&mut m, &format!("{setup}N40 G03 X50 Z0 I50 K0\nN50 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let mut m = machine();
    let r = run_on(&mut m, &format!("{setup}N40 G02 X50 Z0 I50 K0\nN50 M30\n"));
    assert_eq!(r.status, RunStatus::Aborted);
    let hit = refusal(&m).hit;
    assert_eq!((hit.kind, hit.id), (HitKind::Protection, Some(6)));
    // The arc x² + z² = 2500 passes the level Z = −40 at X = −30, outside the footprint; it
    // reaches the side X = −10 − tol at z = −sqrt(2500 − x²) ≈ −48.99, inside [−100, −40]:
    // it enters through the side wall.
    let x = -10.0 - AREA_TOLERANCE;
    let z = -(2500.0 - x * x).sqrt();
    assert_close(hit.point[0], x, 1e-6, "x");
    assert_close(hit.point[2], z, 1e-6, "z");
}

/// Seed Fig. 7: WS1 and WS2 are connected by the small WS3.
const UNION_SETUP: &str = "\
N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N11 G01 G90 F2000 X0 Y0
N12 X100
N13 Y100
N14 X0
N15 Y0
N16 #CONTROL AREA END
N20 #CONTROL AREA BEGIN [ID2 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N21 G01 X200 Y0
N22 X300
N23 Y100
N24 X200
N25 Y0
N26 #CONTROL AREA END
N30 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N31 G01 X80 Y40
N32 X220
N33 Y60
N34 X80
N35 Y40
N36 #CONTROL AREA END
N40 G01 X50 Y50 F5000
N50 #CONTROL AREA ON ALL
";

#[test]
fn overlapping_workspaces_form_a_union() {
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}N60 G01 X250 Y50\nN70 G01 X50 Y55\nN80 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    // Outside the connection (Y = 90 at X = 100 … 200) the path leaves WS1 at X = 100 + tol.
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}N60 G01 X50 Y90\nN70 G01 X250 Y90\nN80 M30\n"),
    );
    let msg = first_error(&r);
    assert_eq!(id_block(&msg), (900317, Some(70)));
    assert!(msg.text.contains("workspace 1"), "{msg}");
    let hit = refusal(&m).hit;
    assert_eq!((hit.kind, hit.id), (HitKind::Workspace, Some(1)));
    assert_close(hit.point[0], 100.0 + AREA_TOLERANCE, 1e-9, "x");
    assert_close(pos(&m)[1], 90.0, 1e-9, "Y stayed at the block start");
}

#[test]
fn protection_inside_a_workspace_overrides_it() {
    let prot = "\
N52 #CONTROL AREA BEGIN [ID7 PROT POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N53 G01 X140 Y45
N54 X160
N55 Y55
N56 X140
N57 Y45
N58 #CONTROL AREA END
N59 #CONTROL AREA ON [ID7]
";
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}{prot}N60 G01 X250 Y50\nN80 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Aborted);
    let hit = refusal(&m).hit;
    assert_eq!((hit.kind, hit.id), (HitKind::Protection, Some(7)));
    assert_close(hit.point[0], 140.0 - AREA_TOLERANCE, 1e-9, "x");
    // Around it (Y = 42 stays in WS3 and outside ID7's tolerance band) is allowed.
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}{prot}N60 G01 X50 Y42\nN61 X250\nN80 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
}

#[test]
fn independent_axis_motion_is_checked_too() {
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}N60 X[INDP_SYN G01 G90 POS-20 FEED1000]\nN80 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Aborted, "{:?}", r.messages());
    let msg = r.messages().into_iter().find(|m| m.is_error()).unwrap();
    assert_eq!(msg.id, 900317, "{msg}");
    assert_close(pos(&m)[0], 50.0, 1e-9, "X");
}

#[test]
fn activation_needs_a_valid_tcp() {
    // TCP at (0, 0) is in the notch of the seed polygon (outside the workspace).
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{SEED_POLY}N150 #CONTROL AREA ON [ID3]\nN160 M30\n"),
    );
    let msg = first_error(&r);
    assert_eq!(id_block(&msg), (900314, Some(150)));
    assert_eq!(m.channel().areas().state(3), AreaState::Defined);
    // From inside it activates.
    let r = run_on(
        &mut m,
        "N10 G01 G90 X-100 Y50 F5000\nN20 #CONTROL AREA ON [ID3]\nN30 M30\n",
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(m.channel().areas().state(3), AreaState::Active);
}

/// A protection square X ∈ [50, 70], Y ∈ [−10, 10] (Z ∈ [−50, 50]); the TCP is put at `X{x}`
/// in front of its face X = 50, the area switched on, then a block moves away to X0.
fn prot_beside(x: f64) -> String {
    format!(
        "\
N10 #CONTROL AREA BEGIN [ID4 PROT POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X50 Y-10
N30 X70
N40 Y10
N50 X50
N60 Y-10
N70 #CONTROL AREA END
N80 G01 X{x} Y0 Z0 F5000
N90 #CONTROL AREA ON [ID4]
N100 G01 X0
N110 M30
"
    )
}

/// Issue 27 item 3. Seed 000 §3.2: "when a protection area is activated, the TCP may not incur
/// any violation at the current position"; §2.3: "a protection area must never be touched by the
/// TCP". The path check counts a TCP within the tolerance band (1 µm) of a protection area as
/// touching it; activation applies the same rule, so a TCP 0.5 µm in front of the area is
/// refused at `ON` (900314) instead of being accepted and then refusing every block (900316).
#[test]
fn activation_beside_a_protection_area_uses_the_path_check_band() {
    let mut m = machine();
    let r = run_on(&mut m, &prot_beside(50.0 - 0.0005));
    let msg = first_error(&r);
    assert_eq!(id_block(&msg), (900314, Some(90)), "{msg}");
    assert!(msg.text.contains("[4]"), "{msg}");
    assert_eq!(m.channel().areas().state(4), AreaState::Defined);
    assert!(m.channel().area_mon_violation_detected_r());
    assert_close(
        pos(&m)[0],
        50.0 - 0.0005,
        1e-12,
        "X stayed in front of the area",
    );
    // Just inside the band: refused too; just outside it: accepted, and the block moving away
    // runs — the band of the activation is the band of the path check.
    let mut m = machine();
    let r = run_on(&mut m, &prot_beside(50.0 - 0.999 * AREA_TOLERANCE));
    assert_eq!(id_block(&first_error(&r)), (900314, Some(90)));
    let mut m = machine();
    let r = run_on(&mut m, &prot_beside(50.0 - 1.001 * AREA_TOLERANCE));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(m.channel().areas().state(4), AreaState::Active);
    assert_close(pos(&m)[0], 0.0, 1e-12, "the move away ran");
    // From there, a block towards the area that ends inside the band is refused by the path
    // check at once: the same 1 µm.
    let r = run_on(
        &mut m,
        &format!(
            "N10 G01 X{} F5000\nN20 M30\n",
            50.0 - 0.999 * AREA_TOLERANCE
        ),
    );
    assert_eq!(id_block(&first_error(&r)), (900316, Some(10)));
    let r = run_on(
        &mut m,
        &format!(
            "N10 G01 X{} F5000\nN20 G01 X0\nN30 M30\n",
            50.0 - 1.001 * AREA_TOLERANCE
        ),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
}

/// The same rule on the workspace side (seed 000 §3.2 "When workspaces are activated, the TCP
/// must already be located in the valid workspace"): a path may run up to 1 µm outside a
/// workspace, so a TCP 0.5 µm outside may switch it on and move in; 1.5 µm outside it may not.
#[test]
fn activation_beside_a_workspace_uses_the_path_check_band() {
    let work = |x: f64| {
        format!(
            "\
N10 #CONTROL AREA BEGIN [ID2 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X-10 Y-10
N30 X10
N40 Y10
N50 X-10
N60 Y-10
N70 #CONTROL AREA END
N80 G01 X{x} Y0 Z0 F5000
N90 #CONTROL AREA ON [ID2]
N100 G01 X0
N110 M30
"
        )
    };
    let mut m = machine();
    let r = run_on(&mut m, &work(10.0 + 0.5 * AREA_TOLERANCE));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_close(pos(&m)[0], 0.0, 1e-12, "moved into the workspace");
    let mut m = machine();
    let r = run_on(&mut m, &work(10.0 + 1.5 * AREA_TOLERANCE));
    assert_eq!(id_block(&first_error(&r)), (900314, Some(90)));
    assert_eq!(m.channel().areas().state(2), AreaState::Defined);
}

#[test]
fn areas_survive_program_end_and_reset_deactivates_them() {
    let mut m = machine();
    let r = run_on(&mut m, &format!("{UNION_SETUP}N60 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    // Next program: still monitored (seed §3 notice "Program end").
    let r = run_on(&mut m, "N10 G01 G90 X50 Y150 F5000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900317]);
    // Controller reset: deactivated, kept (seed §3 notice "Controller reset").
    m.channel_mut().reset();
    assert!(!m.channel().area_mon_violation_detected_r());
    for id in [1, 2, 3] {
        assert_eq!(m.channel().areas().state(id), AreaState::Defined);
    }
    let r = run_on(&mut m, "N10 G01 G90 X50 Y150 F5000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    // Reactivation by ID needs a valid TCP again: (50, 150) is outside.
    let r = run_on(&mut m, "N10 #CONTROL AREA ON [ID1]\nN20 M30\n");
    assert_eq!(r.message_ids(), vec![900314]);
    let r = run_on(
        &mut m,
        "N10 G01 X50 Y50 F5000\nN20 #CONTROL AREA ON [ID1]\nN30 M30\n",
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(m.channel().areas().state(1), AreaState::Active);
}

#[test]
fn clear_of_an_active_area_warns_120499_and_keeps_it() {
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}N60 #CONTROL AREA CLEAR [ID2]\nN70 #CONTROL AREA OFF [ID2]\nN80 #CONTROL AREA CLEAR [ID2]\nN90 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let w: Vec<_> = r
        .messages()
        .into_iter()
        .filter(|m| m.id == 120499)
        .collect();
    assert_eq!(w.len(), 1);
    assert!(!w[0].is_error());
    assert_eq!(w[0].block.and_then(|b| b.number), Some(60));
    assert_eq!(m.channel().areas().state(2), AreaState::Cleared);
    assert_eq!(m.channel().areas().state(1), AreaState::Active);
}

#[test]
fn bare_off_deactivates_the_last_selected_areas() {
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{UNION_SETUP}N60 #CONTROL AREA OFF\nN70 G01 X50 Y150\nN80 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    for id in [1, 2, 3] {
        assert_eq!(m.channel().areas().state(id), AreaState::Defined);
    }
}

const TWO_PATH_MACHINE: &str = r#"
[[axis]]
name = "X"
[[axis]]
name = "Y"
[[axis]]
name = "Z"
[[axis]]
name = "U"
[[axis]]
name = "V"
[[axis]]
name = "W"
"#;

/// Seed 000 §2.4, verbatim (the BEGIN bracket continues on the next line).
const SEED_TWO_PATH: &str = "\
N040 #CONTROL AREA START [ID=1 WORK MONITOR_LVL = \"IMCS\" POLY MIN_EXCUR
= -100 MAX_EXCUR = 100]
N050 : G0 X200 Y0 : G0 U150 V0
N060 : G0 X200 Y200 : G0 U150 V150
N070 : G0 X-200 Y200 : G0 U-150 V150
N080 : G0 X-200 Y-200 : G0 U-150 V-150
N090 : G0 X200 Y-200 : G0 U150 V-150
N100 : G0 X200 Y0 : G0 U150 V0
N110 #CONTROL AREA END
";

#[test]
fn seed_two_path_example_defines_an_imcs_area_on_u_v_and_is_monitored() {
    let mut m = machine_from(TWO_PATH_MACHINE);
    let r = run_on(&mut m, &format!("{SEED_TWO_PATH}N120 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let a = m.channel().areas().area(1).unwrap();
    assert_eq!(a.header.monitor_level, MonitorLevel::Imcs);
    assert_eq!((a.header.min_excur, a.header.max_excur), (-100.0, 100.0));
    // The U/V chain of the example (the X/Y words are the reference path).
    assert_eq!(
        polygon(&m, 1),
        [
            [150.0, 0.0],
            [150.0, 150.0],
            [-150.0, 150.0],
            [-150.0, -150.0],
            [150.0, -150.0]
        ]
    );
    assert_eq!(pos(&m), vec![0.0; 6]);
    // Monitored: U/V inside ±150, W inside ±100; X/Y/Z are not restricted by this area.
    let r = run_on(
        &mut m,
        "N10 #CONTROL AREA ON [ID=1]\nN20 G01 G90 U100 V100 W50 F5000\nN30 X500 Y-500\nN40 U200\nN50 M30\n",
    );
    let msg = first_error(&r);
    assert_eq!(id_block(&msg), (900317, Some(40)));
    assert!(msg.text.contains("U=150.001"), "{msg}");
    let p = pos(&m);
    assert_close(p[0], 500.0, 1e-9, "X moved freely");
    assert_close(p[3], 100.0, 1e-9, "U did not move");
    // W beyond MAX_EXCUR leaves it too.
    let r = run_on(&mut m, "N10 G01 W150 F5000\nN20 M30\n");
    assert_eq!(r.message_ids(), vec![900317]);
}

#[test]
fn additional_axes_define_their_own_polygon() {
    let mut m = machine_from(
        r#"
[[axis]]
name = "X"
[[axis]]
name = "Y"
[[axis]]
name = "Z"
[[axis]]
name = "X2"
[[axis]]
name = "Y2"
[[axis]]
name = "Z2"
"#,
    );
    // Seed 000 §4, verbatim apart from the placeholders.
    let src = "\
N10 #CONTROL AREA BEGIN [ID4 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X2=100 Y2=100 ;Starting point
N30 X2=-100
N40 Y2=-100
N50 X2=100
N60 X2 = 100 Y2= 100 ; End point identical with starting point
N70 #CONTROL AREA END
N500 #CONTROL AREA ON ALL
N600 G01 X2=50 Y2=50 X300 F5000
N700 G01 X2=150
N1000 M30
";
    let r = run_on(&mut m, src);
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(
        polygon(&m, 4),
        [
            [100.0, 100.0],
            [-100.0, 100.0],
            [-100.0, -100.0],
            [100.0, -100.0]
        ]
    );
    let msg = r.messages().into_iter().find(|m| m.is_error()).unwrap();
    assert_eq!(
        (msg.id, msg.block.and_then(|b| b.number)),
        (900317, Some(700))
    );
    assert!(msg.text.contains("X2=100.001"), "{msg}");
    assert_close(pos(&m)[0], 300.0, 1e-9, "X is not monitored by this area");
}

#[test]
fn cli_run_reports_the_area_and_block_and_exits_1() {
    let dir = std::env::temp_dir().join(format!("fieldprobe-areas-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("bulge.nc");
    std::fs::write(
        &file,
        format!("{ARC_SETUP}N50 G02 X50 Y0 I50 J0\nN70 M30\n"),
    )
    .unwrap();
    let o = cli::fieldprobe(&["run", file.to_str().unwrap()]);
    let err = cli::stderr(&o);
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(o.status.code(), Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("error 900316"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(line.contains("protection area 4"), "{line}");
    assert!(line.ends_with("(N50)"), "{line}");
}

#[test]
fn arc_under_a_rotating_cs_is_checked_in_machine_coordinates() {
    // #CS rotates 90° about Z: ACS = R·PCS with R(x, y) = (−y, x). The TCP at ACS (−50, 0) is
    // PCS (0, 50). G02 about the PCS origin to PCS (0, −50) passes PCS (50, 0) = ACS (0, 50),
    // inside the protection circle; G03 passes ACS (0, −50). The tilted-frame arc is checked by
    // chords (deviation ≤ tol / 2, protection enlarged by it).
    let cs = "N45 #CS ON [0, 0, 0, 0, 0, 90]\n";
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{ARC_SETUP}{cs}N50 G03 X0 Y-50 I0 J-50\nN60 #CS OFF\nN70 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let mut m = machine();
    let r = run_on(
        &mut m,
        &format!("{ARC_SETUP}{cs}N50 G02 X0 Y-50 I0 J-50\nN60 #CS OFF\nN70 M30\n"),
    );
    assert_eq!(r.status, RunStatus::Aborted);
    let hit = refusal(&m).hit;
    assert_eq!((hit.kind, hit.id), (HitKind::Protection, Some(4)));
    let rr = 20.0 + AREA_TOLERANCE;
    let y = (2500.0 - rr * rr + 3600.0) / 120.0;
    let x = -(2500.0 - y * y).sqrt();
    // Chords lie inside the circle by at most e ≤ tol / 2 and are tested with tol + e.
    assert_close(hit.point[0], x, 2e-3, "hit x");
    assert_close(hit.point[1], y, 2e-3, "hit y");
}

#[test]
fn definition_left_open_at_program_end_is_an_error_and_discarded() {
    let mut m = machine();
    let r = run_on(
        &mut m,
        "N10 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]\nN20 G01 G90 X0 Y0 F100\nN30 M30\n",
    );
    let msg = first_error(&r);
    assert_eq!(id_block(&msg), (900312, Some(10)));
    assert_eq!(m.channel().areas().state(3), AreaState::Cleared);
    assert!(!m.channel().area_defining());
    // The next program starts clean: motion blocks move again.
    let r = run_on(&mut m, "N10 G01 G90 X10 F5000\nN20 M30\n");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_close(pos(&m)[0], 10.0, 1e-9, "X");
}

mod robustness {
    //! Mutated area programs, run end to end on the emulated machine: never a panic, and the
    //! table stays consistent (≤ 20 areas, no definition left open after the run, every active
    //! area leaves the TCP in a valid position).
    use super::*;
    use proptest::prelude::*;

    const PROGRAMS: &[&str] = &[SEED_POLY, SEED_CIRC, ARC_SETUP, UNION_SETUP, SQUARE_DEF];
    const ALPHABET: &[char] = &[
        'X', 'Y', 'Z', 'I', 'J', 'G', '0', '1', '2', '3', '4', '5', '7', '9', '-', '.', ' ',
    ];

    fn mutate(src: &str, edits: Vec<(prop::sample::Index, u8, char)>) -> String {
        let mut v: Vec<char> = src.chars().collect();
        for (at, op, c) in edits {
            if v.is_empty() {
                v.push(c);
                continue;
            }
            let k = at.index(v.len());
            match op {
                0 => v[k] = c,
                1 => v.insert(k, c),
                _ => {
                    v.remove(k);
                }
            }
        }
        v.into_iter().collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn mutated_area_programs_never_panic(
            which in 0..PROGRAMS.len(),
            edits in proptest::collection::vec(
                (any::<prop::sample::Index>(), 0u8..3, proptest::sample::select(ALPHABET)), 1..6),
            tail in proptest::sample::select(&[
                "N900 G01 X20 Y20 F3000\n",
                "N900 G02 X60 Y0 I30 J0 F3000\n",
                "N900 #CONTROL AREA CLEAR ALL\n",
                "N900 #CONTROL AREA OFF\n",
            ][..]),
        ) {
            let src = format!("{}{tail}N999 M30\n", mutate(PROGRAMS[which], edits));
            let Ok(program) = parse(&src) else { return Ok(()) };
            run_and_check(&src, &program)?;
        }

        /// Only numbers change (so most programs still parse and run): coordinates, IDs,
        /// excursions, G codes.
        #[test]
        fn programs_with_mutated_numbers_run_consistently(
            which in 0..PROGRAMS.len(),
            edits in proptest::collection::vec(
                (any::<prop::sample::Index>(), 0u8..3, proptest::sample::select(&['0', '1', '2', '3', '5', '7', '9'][..])), 1..5),
        ) {
            let mut v: Vec<char> = PROGRAMS[which].chars().collect();
            for (at, op, c) in edits {
                let digits: Vec<usize> = (0..v.len()).filter(|&k| v[k].is_ascii_digit()).collect();
                let k = digits[at.index(digits.len())];
                match op {
                    0 => v[k] = c,
                    1 => v.insert(k, '-'),
                    _ => v.insert(k, c),
                }
            }
            let src = format!("{}N900 G01 X20 Y20 F3000\nN999 M30\n", v.into_iter().collect::<String>());
            let Ok(program) = parse(&src) else { return Ok(()) };
            run_and_check(&src, &program)?;
        }
    }

    fn run_and_check(
        src: &str,
        program: &fieldprobe::nc::ast::Program,
    ) -> Result<(), TestCaseError> {
        {
            let mut m = machine();
            let _ = m.run_program(program, &mut |_| {});
            let ch = m.channel();
            prop_assert!(ch.areas().len() <= 20);
            prop_assert!(!ch.area_defining());
            let p = ch.command_positions();
            prop_assert!(ch.area_monitor().check_position(&p).is_ok(), "{src}");
        }
        Ok(())
    }
}

/// A workspace box X/Y ±200, Z ∈ [−100, 100], active; TCP at the origin.
const BOX: &str = "\
N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
N11 G01 G90 F2000 X-200 Y-200
N12 X200
N13 Y200
N14 X-200
N15 Y-200
N16 #CONTROL AREA END
N20 #CONTROL AREA ON [ID1]
";

fn z(m: &Machine) -> f64 {
    pos(m)[2]
}

#[test]
fn measuring_block_beyond_the_workspace_is_refused_or_limited_with_p_chan_00268() {
    // P-CHAN-00268 = 0: the programmed target Z−150 lies outside: refused, nothing moves.
    let mut m = machine();
    let r = run_on(&mut m, &format!("{BOX}N30 G100 Z-150 F1000\nN40 M30\n"));
    assert_eq!(id_block(&first_error(&r)), (900317, Some(30)));
    assert_close(z(&m), 0.0, 1e-9, "Z");
    // P-CHAN-00268 = 1, no probe: the run stops one tolerance band ahead of the first
    // violation (Z = −100 − tol + tol = −100), error 50706.
    let mut cfg = MachineConfig::default_machine();
    cfg.apply_set("P-CHAN-00268=1").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = run_on(&mut m, &format!("{BOX}N30 G100 Z-150 F1000\nN40 M30\n"));
    assert_eq!(id_block(&first_error(&r)), (50706, Some(30)));
    assert!(
        (-100.0 - 1e-6..=-100.0 + 1e-6).contains(&z(&m)),
        "stopped at Z = {}",
        z(&m)
    );
    // … and with a probe surface at Z = −50 it measures there.
    let mut m = Machine::new(&cfg).unwrap();
    m.add_probe("Z", -50.0).unwrap();
    let r = run_on(
        &mut m,
        &format!(
            "{BOX}N30 G100 Z-150 F1000\nN40 #MSG SYN [\"%f\", V.A.MEAS.ACS.VALUE.Z]\nN50 M30\n"
        ),
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.output(), vec!["-50.000000"]);
}

#[test]
fn measuring_overtravel_stops_at_the_workspace_instead_of_refusing_the_block() {
    // Target Z−95 is inside; the overtravel of 20 mm past it (P-AXIS-00467 = 200000 × 0.1 µm,
    // no probe) would leave the workspace at Z = −100: it is cut there silently, as at a
    // software limit switch, and the axis travels beyond the target up to the boundary.
    let mut cfg = MachineConfig::default_machine();
    cfg.apply_set("Z.P-AXIS-00467=200000").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = run_on(&mut m, &format!("{BOX}N30 G100 Z-95 F1000\nN40 M30\n"));
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(
        r.messages().iter().all(|x| x.id != 900317),
        "{:?}",
        r.messages()
    );
    assert!(z(&m) >= -100.0 - 1e-6, "Z = {}", z(&m));
    assert!(
        z(&m) < -95.0 - 1.0,
        "the overtravel ran past the target: Z = {}",
        z(&m)
    );
}
