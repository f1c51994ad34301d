//! Control areas in the active machining plane (issue 27 item 4; seed 000 §3.1.1 "Normally, the
//! surface area of the workspace or protection area is defined by the first two main axes of the
//! active machining plane"; §2.3 "Example of X/Y basic plane (G17): X → 1st main axis, Y → 2nd
//! main axis, Z → 3rd main axis (constant due to minimum/maximum values)").
//!
//! The planes' axes are DIN 66025's: G18 Z → X (3rd axis Y), G19 Y → Z (3rd axis X). An area
//! keeps the plane it was defined in (§2.3 "A workspace/protection area is defined by an object
//! in space"). Every program runs on `sim`, `ethercat-emu` and `canopen-emu`; the expected values
//! are the seed geometry typed in here, the violation points closed-form.

use fieldprobe::channel::ChannelState;
use fieldprobe::core::monitor::area_geom::Plane;
use fieldprobe::core::monitor::area_monitor::{HitKind, AREA_TOLERANCE};
use fieldprobe::core::monitor::areas::{AreaGeometry, AreaState};
use fieldprobe::machine::{LinkChoice, Machine, RunReport, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const LINKS: [&str; 3] = ["sim", "ethercat-emu", "canopen-emu"];
const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;

fn machine(link: &str) -> Machine {
    let mut cfg = MachineConfig::default_machine();
    if link == "canopen-emu" {
        // Three CiA 402 nodes need 4 ms at 1 Mbit/s (docs/canopen.md "Bus load").
        cfg.apply_set("cycle_time_us=4000").unwrap();
    }
    Machine::with_link(&cfg, &LinkChoice::new(link)).unwrap_or_else(|e| panic!("{link}: {e}"))
}

fn run(m: &mut Machine, src: &str) -> RunReport {
    m.run_program(
        &parse(src).unwrap_or_else(|e| panic!("{e}\n{src}")),
        &mut |_| {},
    )
}

fn pos(m: &Machine) -> Vec<f64> {
    m.channel().command_positions()
}

#[track_caller]
fn completed(link: &str, r: &RunReport) {
    assert_eq!(r.status, RunStatus::Completed, "{link}: {:?}", r.messages());
    assert!(r.messages().is_empty(), "{link}: {:?}", r.messages());
}

/// The run aborted with exactly one error `id` in block `n`.
#[track_caller]
fn aborted_with(link: &str, r: &RunReport, id: u32, n: u32) {
    assert_eq!(r.status, RunStatus::Aborted, "{link}: {:?}", r.messages());
    assert_eq!(r.message_ids(), vec![id], "{link}: {:?}", r.messages());
    let msg = r.messages()[0];
    assert_eq!(msg.block.and_then(|b| b.number), Some(n), "{link}: {msg}");
}

#[track_caller]
fn close(what: &str, actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: {actual} is not within {tol} of {expected}"
    );
}

/// A protection area programmed under G18: a square Z ∈ [−10, 10], X ∈ [40, 60] in the Z/X
/// plane, excursion Y ∈ [−5, 5]. Before issue 27 N30 was refused with 900315 ("must program
/// both plane coordinates"), because X/Y was taken whatever the plane.
const G18_PROT: &str = "\
N10 G18
N20 #CONTROL AREA BEGIN [ID5 PROT POLY MIN_EXCUR=-5 MAX_EXCUR=5]
N30 G01 F1000 G90 Z-10 X40
N40 Z10
N50 X60
N60 Z-10
N70 X40
N80 #CONTROL AREA END
N90 G01 X0 Y0 Z0 F5000
N100 #CONTROL AREA ON [ID5]
";

#[test]
fn a_g18_area_lies_in_z_x_with_y_as_excursion_on_every_link() {
    for link in LINKS {
        // Along X at Y0 Z0 the path meets the face X = 40 (Z = 0 lies in [−10, 10], Y = 0 in
        // the excursion [−5, 5]); it violates one tolerance band before it.
        let mut m = machine(link);
        let r = run(&mut m, &format!("{G18_PROT}N110 G01 X100\nN120 M30\n"));
        aborted_with(link, &r, 900316, 110);
        let ch = m.channel();
        let area = ch.areas().area(5).expect("area 5 defined");
        assert_eq!(area.plane, Plane::G18, "{link}");
        assert_eq!(
            area.geometry,
            AreaGeometry::Polygon {
                vertices: vec![[-10.0, 40.0], [10.0, 40.0], [10.0, 60.0], [-10.0, 60.0]]
            },
            "{link}: (Z, X) pairs as programmed"
        );
        assert_eq!(ch.areas().state(5), AreaState::Active);
        let hit = ch.area_refusal().expect("refused").hit.clone();
        assert_eq!((hit.kind, hit.id), (HitKind::Protection, Some(5)), "{link}");
        assert_eq!(hit.axes, [Z, X, Y], "{link}: plane Z/X, excursion Y");
        close("Z", hit.point[0], 0.0, 1e-9);
        close("X", hit.point[1], 40.0 - AREA_TOLERANCE, 1e-9);
        close("Y", hit.point[2], 0.0, 1e-9);
        assert_eq!(
            pos(&m),
            vec![0.0, 0.0, 0.0],
            "{link}: the block did not run"
        );

        // Y = 10 is beyond MAX_EXCUR = 5 on the excursion axis Y: the same X travel passes.
        // (Z = 10 would not help: Z is a plane axis and the square spans Z ∈ [−10, 10].)
        let mut m = machine(link);
        let r = run(
            &mut m,
            &format!("{G18_PROT}N110 G01 Y10\nN120 G01 X100\nN130 G01 X0\nN140 M30\n"),
        );
        completed(link, &r);
        let mut m = machine(link);
        let r = run(
            &mut m,
            &format!("{G18_PROT}N110 G01 Z8\nN120 G01 X100\nN130 M30\n"),
        );
        aborted_with(link, &r, 900316, 120);
        // Beside the square in Z it passes.
        let mut m = machine(link);
        let r = run(
            &mut m,
            &format!("{G18_PROT}N110 G01 Z12\nN120 G01 X100\nN130 M30\n"),
        );
        completed(link, &r);
        close("X", pos(&m)[X], 100.0, 1e-9);
    }
}

#[test]
fn an_area_keeps_its_plane_when_the_plane_changes_or_a_new_program_starts() {
    for link in LINKS {
        // G17 after the definition: the area still spans Z/X (an object in space, §2.3).
        let mut m = machine(link);
        let r = run(
            &mut m,
            &format!("{G18_PROT}N105 G17\nN110 G01 X100\nN120 M30\n"),
        );
        aborted_with(link, &r, 900316, 110);
        let hit = m.channel().area_refusal().unwrap().hit.clone();
        assert_eq!(hit.axes, [Z, X, Y], "{link}");
        close("X", hit.point[1], 40.0 - AREA_TOLERANCE, 1e-9);

        // The next program starts in G17 (the executor's default); the area stays active and
        // keeps Z/X: X travel at Y10 passes, at Y0 it is refused.
        let mut m = machine(link);
        completed(link, &run(&mut m, &format!("{G18_PROT}N110 M30\n")));
        let r = run(
            &mut m,
            "N10 G01 Y10 F5000\nN20 G01 X100\nN30 G01 X0\nN40 M30\n",
        );
        completed(link, &r);
        let r = run(&mut m, "N10 G01 Y0 F5000\nN20 G01 X100\nN30 M30\n");
        aborted_with(link, &r, 900316, 20);
        assert_eq!(m.channel().areas().area(5).unwrap().plane, Plane::G18);

        // And the other way: an area of the seed's G17 example (X/Y, excursion Z) is not turned
        // into Z/X by a later G18. Square X/Y ±10, Z ∈ [−5, 5]: X travel at Y20 passes under
        // G18, at Y0 it is refused at X = −10 − tol.
        let g17 = "\
N10 #CONTROL AREA BEGIN [ID7 PROT POLY MIN_EXCUR=-5 MAX_EXCUR=5]
N20 G01 F1000 G90 X-10 Y-10
N30 X10
N40 Y10
N50 X-10
N60 Y-10
N70 #CONTROL AREA END
N80 G01 X-50 Y20 Z0 F5000
N90 #CONTROL AREA ON [ID7]
N100 G18
N110 G01 X50
N120 G01 Y0
N130 G01 X-50
N140 M30
";
        let mut m = machine(link);
        let r = run(&mut m, g17);
        aborted_with(link, &r, 900316, 130);
        let hit = m.channel().area_refusal().unwrap().hit.clone();
        assert_eq!(hit.axes, [X, Y, Z], "{link}");
        close("X", hit.point[0], 10.0 + AREA_TOLERANCE, 1e-9);
        assert_eq!(m.channel().areas().area(7).unwrap().plane, Plane::G17);
    }
}

/// A cylindrical workspace under G19: circle in Y/Z (centre from J / K), excursion X.
const G19_WORK: &str = "\
N10 G19
N20 #CONTROL AREA BEGIN [ID6 WORK CIRC MIN_EXCUR=-50 MAX_EXCUR=50]
N30 G01 F1000 G90 Y0 Z-30
N40 G02 G162 J0 K30
N50 #CONTROL AREA END
N60 G01 X0 Y0 Z0 F5000
N70 #CONTROL AREA ON [ID6]
";

#[test]
fn a_g19_cylinder_lies_in_y_z_with_x_as_excursion_on_every_link() {
    for link in LINKS {
        let mut m = machine(link);
        let r = run(
            &mut m,
            &format!("{G19_WORK}N80 G01 X45 Y20 Z20\nN90 G01 X60\nN100 M30\n"),
        );
        // (20, 20) lies at 28.28 < 30 from the axis; X = 45 is within [−50, 50]; X60 leaves
        // the cylinder through its end face X = 50.
        aborted_with(link, &r, 900317, 90);
        let ch = m.channel();
        let area = ch.areas().area(6).unwrap();
        assert_eq!(area.plane, Plane::G19);
        assert_eq!(
            area.geometry,
            AreaGeometry::Circle {
                centre: [0.0, 0.0],
                radius: 30.0
            },
            "{link}"
        );
        let hit = ch.area_refusal().unwrap().hit.clone();
        assert_eq!((hit.kind, hit.id), (HitKind::Workspace, Some(6)), "{link}");
        assert_eq!(hit.axes, [Y, Z, X], "{link}");
        close("X", hit.point[2], 50.0 + AREA_TOLERANCE, 1e-9);
        let p = pos(&m);
        close("X", p[X], 45.0, 1e-9);

        // In the Y/Z plane the circle of radius 30 is the wall: Z travel at Y0 leaves at
        // Z = 30 + tol.
        let mut m = machine(link);
        let r = run(&mut m, &format!("{G19_WORK}N80 G01 Z40\nN90 M30\n"));
        aborted_with(link, &r, 900317, 80);
        let hit = m.channel().area_refusal().unwrap().hit.clone();
        close("Z", hit.point[1], 30.0 + AREA_TOLERANCE, 1e-6);
    }
}

/// Step until the channel is idle; returns every command position seen of axis `axis`.
fn run_jog(m: &mut Machine, axis: usize) -> Vec<f64> {
    let mut seen = Vec::new();
    for _ in 0..2_000_000 {
        if m.channel().state() != ChannelState::Busy {
            break;
        }
        m.step();
        seen.push(m.channel().axes()[axis].command());
    }
    assert_eq!(m.channel().state(), ChannelState::Idle);
    seen
}

/// Seed 000 §5: manual mode is monitored "based on the defined and activated control areas" —
/// the same Z/X square with excursion Y stops a jog of X at its face X = 40 and a jog of Y at
/// the excursion limit Y = −5.
#[test]
fn jogging_stops_at_a_g18_area_on_every_link() {
    for link in LINKS {
        let mut m = machine(link);
        completed(link, &run(&mut m, &format!("{G18_PROT}N110 M30\n")));
        m.channel_mut().take_messages();
        assert!(m.channel_mut().enter_manual(), "{link}");
        assert!(m.channel_mut().jog_continuous(X, 40.0), "{link}");
        let xs = run_jog(&mut m, X);
        let stop = pos(&m)[X];
        assert!(xs.iter().all(|&v| v < 40.0), "{link}: entered the area");
        assert!(
            (40.0 - 0.01..40.0).contains(&stop),
            "{link}: stopped at {stop}"
        );

        // From X50 Y−20 Z0 (beside the square in Y, inside it in Z/X) a jog of Y+ stops at the
        // excursion limit MIN_EXCUR = −5.
        let mut m = machine(link);
        let setup = format!(
            "{}N95 G01 Y-20\nN96 G01 X50\n{}N110 M30\n",
            &G18_PROT[..G18_PROT.find("N100").unwrap()],
            "N100 #CONTROL AREA ON [ID5]\n"
        );
        completed(link, &run(&mut m, &setup));
        assert_eq!(pos(&m), vec![50.0, -20.0, 0.0], "{link}");
        assert!(m.channel_mut().enter_manual(), "{link}");
        assert!(m.channel_mut().jog_continuous(Y, 40.0), "{link}");
        let ys = run_jog(&mut m, Y);
        let stop = pos(&m)[Y];
        assert!(ys.iter().all(|&v| v < -5.0), "{link}: entered the area");
        assert!(
            (-5.0 - 0.01..-5.0).contains(&stop),
            "{link}: stopped at {stop}"
        );
    }
}

/// The definition blocks take the coordinates of the plane; a coordinate of the plane's
/// missing axis is named in the error (900315), and a plane change inside a definition is
/// refused with the block.
#[test]
fn definition_errors_name_the_plane_axes() {
    let mut m = machine("sim");
    let r = run(
        &mut m,
        "N10 G18\nN20 #CONTROL AREA BEGIN [ID5 PROT POLY MIN_EXCUR=-5 MAX_EXCUR=5]\n\
         N30 G01 F1000 G90 X-10 Y40\nN40 #CONTROL AREA END\nN50 M30\n",
    );
    aborted_with("sim", &r, 900315, 30);
    let text = &r.messages()[0].text;
    assert!(text.contains("Z and X (G18)"), "{text}");

    let mut m = machine("sim");
    let r = run(
        &mut m,
        "N20 #CONTROL AREA BEGIN [ID5 PROT POLY MIN_EXCUR=-5 MAX_EXCUR=5]\n\
         N30 G01 F1000 G90 X-10 Y40\nN40 G19 Y10 Z10\nN50 #CONTROL AREA END\nN60 M30\n",
    );
    aborted_with("sim", &r, 900315, 40);
    let text = &r.messages()[0].text;
    assert!(text.contains("G17") && text.contains("G19"), "{text}");
    assert_eq!(m.channel().areas().state(5), AreaState::Cleared);
}

/// `MONITOR_LVL=IMCS` areas (seed §2.4, U/V/W the secondary path's main axes) follow the plane
/// the same way: under G18 the contour is W/U and V the excursion.
#[test]
fn an_imcs_area_under_g18_lies_in_w_u_with_v_as_excursion() {
    let cfg = MachineConfig::parse(
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\n\
         [[axis]]\nname = \"U\"\n[[axis]]\nname = \"V\"\n[[axis]]\nname = \"W\"\n",
        "test.toml",
    )
    .unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = run(
        &mut m,
        "N10 G18\n\
         N20 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100 MONITOR_LVL=IMCS]\n\
         N30 G01 F1000 G90 W-20 U-50\nN40 W20\nN50 U50\nN60 W-20\nN70 U-50\n\
         N80 #CONTROL AREA END\n\
         N90 #CONTROL AREA ON [ID1]\n\
         N100 G01 U40 V90 W10 F5000\nN110 W30\nN120 M30\n",
    );
    aborted_with("sim", &r, 900317, 110);
    let ch = m.channel();
    assert_eq!(ch.areas().area(1).unwrap().plane, Plane::G18);
    let hit = ch.area_refusal().unwrap().hit.clone();
    // Channel axes U = 3, V = 4, W = 5: plane W/U, excursion V.
    assert_eq!(hit.axes, [5, 3, 4]);
    close("W", hit.point[0], 20.0 + AREA_TOLERANCE, 1e-9);
    assert_eq!(pos(&m)[3..], [40.0, 90.0, 10.0]);
}
