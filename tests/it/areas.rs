//! Workspace / protection area definitions, definition rules and states (seed 000 FCT-C14,
//! §2.4, §3, §4; syntax seed 002). Expected values are read by hand from the seed.

use fieldprobe::core::monitor::areas::*;
use fieldprobe::messages::{ids, BlockRef, Severity};

fn n(number: u32) -> BlockRef {
    BlockRef {
        number: Some(number),
        line: number / 10,
    }
}

fn g01(number: u32) -> DefBlock {
    DefBlock::new(n(number), DefMotion::G01)
}

fn parse(text: &str) -> AreaCommand {
    parse_area_command(text).unwrap_or_else(|e| panic!("{text}: {e}"))
}

fn header(text: &str) -> AreaHeader {
    match parse(text) {
        AreaCommand::Begin(h) => h,
        other => panic!("not BEGIN: {other:?}"),
    }
}

/// Run a definition through a table; the TCP locator is irrelevant for BEGIN/END.
fn define(table: &mut AreaTable, begin: &str, blocks: &[DefBlock]) -> Result<(), AreaError> {
    let mut never = |_: &Area| false;
    table.apply(&parse(begin), Some(n(10)), &mut never)?;
    for b in blocks {
        table.definition_block(b)?;
    }
    table.apply(&AreaCommand::End, Some(n(999)), &mut never)?;
    Ok(())
}

/// Seed 000 §3.1.1, "Polygonal workspace", N10–N140.
fn seed_poly_blocks() -> Vec<DefBlock> {
    vec![
        g01(20).xy(-150.0, 75.0), // N20 G01 F1000 G90 X-150 Y75 (Starting point)
        g01(30).xy(-50.0, 150.0),
        g01(40).xy(50.0, 150.0),
        g01(50).xy(150.0, 75.0),
        g01(60).xy(150.0, 0.0),
        g01(70).xy(50.0, 0.0),
        g01(80).xy(50.0, 75.0),
        g01(90).xy(-50.0, 75.0),
        g01(100).xy(-50.0, 0.0),
        g01(120).xy(-150.0, 0.0),
        g01(130).xy(-150.0, 75.0), // End point identical with starting point
    ]
}

/// Seed 000 §3.1.2, "Cylindrical protection area": N20 G01 X0 Y0 F10000, N30 G02 G162 I0 J75
/// (G162: absolute centre, so the centre is (0, 75)).
fn seed_circ_blocks() -> Vec<DefBlock> {
    vec![
        g01(20).xy(0.0, 0.0),
        DefBlock::new(n(30), DefMotion::G02).centre(0.0, 75.0),
    ]
}

const SEED_POLY: &str = "BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]";
const SEED_CIRC: &str = "BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]";

fn square(id: u32, kind: &str, half: f64) -> (String, Vec<DefBlock>) {
    (
        format!("BEGIN [ID={id} {kind} POLY MIN_EXCUR=-10 MAX_EXCUR=10]"),
        vec![
            g01(20).xy(-half, -half),
            g01(30).xy(half, -half),
            g01(40).xy(half, half),
            g01(50).xy(-half, half),
            g01(60).xy(-half, -half),
        ],
    )
}

fn at(x: f64, y: f64) -> AreaPoint {
    AreaPoint {
        plane: [x, y],
        excursion: 0.0,
    }
}

#[track_caller]
fn def_err(begin: &str, blocks: &[DefBlock]) -> AreaError {
    let mut t = AreaTable::new();
    match define(&mut t, begin, blocks) {
        Ok(()) => panic!("definition accepted"),
        Err(e) => {
            assert!(!t.is_defining(), "a failed definition is abandoned");
            e
        }
    }
}

// ---------------------------------------------------------------- geometry of the seed examples

#[test]
fn seed_poly_example_defines_the_shown_polygon() {
    let mut t = AreaTable::new();
    define(&mut t, SEED_POLY, &seed_poly_blocks()).unwrap();
    let a = t.area(3).unwrap();
    assert_eq!(a.kind(), AreaKind::Work);
    assert_eq!(a.header.shape, AreaShape::Poly);
    assert_eq!(a.axes, AreaAxes::Main);
    assert_eq!(
        a.geometry,
        AreaGeometry::Polygon {
            vertices: vec![
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
            ]
        }
    );
    let e = a.extents();
    assert_eq!(e.min, [-150.0, 0.0, -50.0]);
    assert_eq!(e.max, [150.0, 150.0, 50.0]);
    assert_eq!(t.state(3), AreaState::Defined);
    // The notch between the legs (Fig. 12) is outside, the legs and the roof inside.
    assert!(!a.contains(at(0.0, 30.0)));
    assert!(a.contains(at(100.0, 30.0)));
    assert!(a.contains(at(0.0, 100.0)));
    assert!(!a.contains(AreaPoint {
        plane: [100.0, 30.0],
        excursion: 50.1
    }));
}

#[test]
fn seed_circ_example_defines_the_shown_cylinder() {
    let mut t = AreaTable::new();
    define(&mut t, SEED_CIRC, &seed_circ_blocks()).unwrap();
    let a = t.area(4).unwrap();
    assert_eq!(a.kind(), AreaKind::Prot);
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
}

#[test]
fn seed_additional_axes_example_defines_a_square_in_x2_y2() {
    // Seed 000 §4: N20 X2=100 Y2=100, N30 X2=-100, N40 Y2=-100, N50 X2=100, N60 X2=100 Y2=100.
    let blocks = vec![
        g01(20).x2(100.0).y2(100.0),
        g01(30).x2(-100.0),
        g01(40).y2(-100.0),
        g01(50).x2(100.0),
        g01(60).x2(100.0).y2(100.0),
    ];
    let mut t = AreaTable::new();
    define(
        &mut t,
        "BEGIN [ID4 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]",
        &blocks,
    )
    .unwrap();
    let a = t.area(4).unwrap();
    assert_eq!(a.axes, AreaAxes::Additional);
    assert_eq!(
        a.geometry,
        AreaGeometry::Polygon {
            vertices: vec![
                [100.0, 100.0],
                [-100.0, 100.0],
                [-100.0, -100.0],
                [100.0, -100.0]
            ]
        }
    );
}

// ---------------------------------------------------------------- syntax

#[test]
fn parses_the_seed_commands() {
    let h = header("#CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]");
    assert_eq!(
        h,
        AreaHeader {
            id: 3,
            kind: AreaKind::Work,
            shape: AreaShape::Poly,
            min_excur: -50.0,
            max_excur: 50.0,
            excur_axis: None,
            monitor_level: MonitorLevel::Mcs,
        }
    );
    let h = header(SEED_CIRC);
    assert_eq!(
        (h.id, h.kind, h.shape),
        (4, AreaKind::Prot, AreaShape::Circ)
    );
    assert_eq!((h.min_excur, h.max_excur), (-70.0, 70.0));

    assert_eq!(parse("ON [ID3]"), AreaCommand::On(Selector::Id(3)));
    assert_eq!(parse("ON ALL"), AreaCommand::On(Selector::All));
    assert_eq!(parse("ON [ALL]"), AreaCommand::On(Selector::All));
    assert_eq!(parse("ON [ID=12]"), AreaCommand::On(Selector::Id(12)));
    assert_eq!(parse("OFF [ID3]"), AreaCommand::Off(Selector::Id(3)));
    assert_eq!(parse("OFF"), AreaCommand::Off(Selector::Last));
    assert_eq!(parse("OFF ALL"), AreaCommand::Off(Selector::All));
    assert_eq!(parse("CLEAR [ID3]"), AreaCommand::Clear(Selector::Id(3)));
    assert_eq!(parse("CLEAR ALL"), AreaCommand::Clear(Selector::All));
    assert_eq!(parse("END"), AreaCommand::End);
    assert_eq!(parse("#CONTROL AREA END"), AreaCommand::End);
}

#[test]
fn parses_the_two_path_imcs_example() {
    // Seed 000 §2.4 N040, with its line break inside the bracket.
    let h =
        header("START [ID=1 WORK MONITOR_LVL = \"IMCS\" POLY MIN_EXCUR\n= -100 MAX_EXCUR = 100]");
    assert_eq!(
        h,
        AreaHeader {
            id: 1,
            kind: AreaKind::Work,
            shape: AreaShape::Poly,
            min_excur: -100.0,
            max_excur: 100.0,
            excur_axis: None,
            monitor_level: MonitorLevel::Imcs,
        }
    );
}

#[test]
fn parses_excursion_axis_options() {
    let h = header("BEGIN [ID=5 PROT POLY MIN_EXCUR=0 MAX_EXCUR=10 EXCUR_AX=Z2 MONITOR_LVL=MCS]");
    assert_eq!(h.excur_axis, Some(ExcurAxis::Name("Z2".into())));
    let h = header("begin [id=5 prot circ min_excur=0 max_excur=10 excur_axnr=7]");
    assert_eq!(h.excur_axis, Some(ExcurAxis::Number(7)));
}

#[test]
fn syntax_errors_name_keyword_and_allowed_values() {
    let cases: &[(&str, &str)] = &[
        ("", "BEGIN | START | END | ON | OFF | CLEAR"),
        ("DEFINE [ID=1]", "DEFINE"),
        (
            "BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1 MONITOR_LVL=WCS]",
            "MONITOR_LVL: bad value `WCS`, allowed: MCS | IMCS",
        ),
        ("BEGIN [ID=1 WORK POLY MAX_EXCUR=1]", "MIN_EXCUR missing"),
        ("BEGIN [WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]", "ID missing"),
        (
            "BEGIN [ID=1 POLY MIN_EXCUR=0 MAX_EXCUR=1]",
            "WORK | PROT missing",
        ),
        (
            "BEGIN [ID=1 WORK PROT POLY MIN_EXCUR=0 MAX_EXCUR=1]",
            "WORK | PROT programmed twice",
        ),
        (
            "BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1 EXCUR_AX=Z EXCUR_AXNR=2]",
            "EXCUR_AX | EXCUR_AXNR programmed twice",
        ),
        (
            "BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1 EXCUR_AXNR=0]",
            "EXCUR_AXNR: bad value `0`, allowed: a logical axis number 1",
        ),
        (
            "BEGIN [ID=1 WORK POLY MIN_EXCUR=abc MAX_EXCUR=1]",
            "MIN_EXCUR: bad value `ABC`",
        ),
        (
            "BEGIN [ID=1 WORK SQUARE MIN_EXCUR=0 MAX_EXCUR=1]",
            "unknown keyword `SQUARE`",
        ),
        ("ON", "ALL | ID missing"),
        ("CLEAR", "ALL | ID missing"),
        ("ON [ID=x]", "ID: bad value `X`"),
        ("OFF [ANY]", "unknown keyword `ANY`, allowed: ALL | ID=.."),
        ("ON [ID3", "malformed"),
    ];
    for (text, expect) in cases {
        let e = parse_area_command(text).expect_err(text);
        assert!(e.to_string().contains(expect), "{text}: {e}");
        let e = AreaError {
            kind: e.into(),
            at: Some(n(40)),
        };
        assert_eq!(e.message().id, ids::AREA_SYNTAX);
    }
}

// ---------------------------------------------------------------- definition errors

#[test]
fn g91_is_refused() {
    let e = def_err(SEED_POLY, &[g01(20).xy(0.0, 0.0).absolute(false)]);
    assert_eq!(e.kind, AreaErrorKind::NotAbsolute { id: 3 });
    assert_eq!(e.at, Some(n(20)));
    assert_eq!(e.message().id, ids::AREA_NOT_ABSOLUTE);
    assert!(e.to_string().starts_with("N20: "), "{e}");
}

#[test]
fn missing_feed_is_refused() {
    let e = def_err(SEED_POLY, &[g01(20).xy(0.0, 0.0).feed_valid(false)]);
    assert_eq!(e.kind, AreaErrorKind::NoFeed { id: 3 });
    assert_eq!(e.message().id, ids::AREA_NO_FEED);
}

#[test]
fn poly_takes_g01_only() {
    for motion in [
        DefMotion::G00,
        DefMotion::G02,
        DefMotion::G03,
        DefMotion::Other,
    ] {
        let blocks = [
            g01(20).xy(0.0, 0.0),
            DefBlock::new(n(30), motion).xy(10.0, 0.0).centre(5.0, 0.0),
        ];
        let e = def_err(SEED_POLY, &blocks);
        assert!(
            matches!(e.kind, AreaErrorKind::WrongMotion { found, .. } if found == motion),
            "{e}"
        );
        assert_eq!(e.at, Some(n(30)));
        assert_eq!(e.message().id, ids::AREA_WRONG_MOTION);
    }
}

#[test]
fn poly_limit_is_20_blocks() {
    // 19 distinct points on a circle + the closing point = 20 blocks: accepted.
    let ring = |count: usize| -> Vec<DefBlock> {
        let mut v: Vec<DefBlock> = (0..count)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / count as f64;
                g01(20 + 10 * k as u32).xy(100.0 * a.cos(), 100.0 * a.sin())
            })
            .collect();
        v.push(g01(900).xy(100.0, 0.0));
        v
    };
    let mut t = AreaTable::new();
    define(&mut t, SEED_POLY, &ring(19)).unwrap();
    match &t.area(3).unwrap().geometry {
        AreaGeometry::Polygon { vertices } => assert_eq!(vertices.len(), 19),
        g => panic!("{g:?}"),
    }
    let e = def_err(SEED_POLY, &ring(20));
    assert_eq!(e.kind, AreaErrorKind::TooManyBlocks { id: 3 });
    assert_eq!(e.at, Some(n(900)));
    assert_eq!(e.message().id, ids::AREA_TOO_MANY_BLOCKS);
}

#[test]
fn poly_must_be_closed() {
    let mut blocks = seed_poly_blocks();
    blocks.pop(); // drop N130
    let e = def_err(SEED_POLY, &blocks);
    assert_eq!(
        e.kind,
        AreaErrorKind::NotClosed {
            id: 3,
            first: [-150.0, 75.0],
            last: [-150.0, 0.0]
        }
    );
    assert_eq!(e.at, Some(n(120)));
    assert_eq!(e.message().id, ids::AREA_NOT_CLOSED);
}

#[test]
fn poly_needs_three_points() {
    let e = def_err(
        SEED_POLY,
        &[
            g01(20).xy(0.0, 0.0),
            g01(30).xy(10.0, 0.0),
            g01(40).xy(0.0, 0.0),
        ],
    );
    assert_eq!(e.kind, AreaErrorKind::TooFewPoints { id: 3, vertices: 2 });
    assert_eq!(e.message().id, ids::AREA_TOO_FEW_POINTS);
    let e = def_err(SEED_POLY, &[]);
    assert_eq!(e.kind, AreaErrorKind::TooFewPoints { id: 3, vertices: 0 });
}

#[test]
fn self_intersecting_polygon_is_refused() {
    // Seed 000 Fig. 3: the bow tie.
    let e = def_err(
        SEED_POLY,
        &[
            g01(20).xy(0.0, 0.0),
            g01(30).xy(100.0, 100.0),
            g01(40).xy(100.0, 0.0),
            g01(50).xy(0.0, 100.0),
            g01(60).xy(0.0, 0.0),
        ],
    );
    assert_eq!(
        e.kind,
        AreaErrorKind::SelfIntersection {
            id: 3,
            first: n(30),
            second: n(50)
        }
    );
    assert_eq!(e.message().id, ids::AREA_SELF_INTERSECTION);
    // A spike folding back on the previous edge.
    let e = def_err(
        SEED_POLY,
        &[
            g01(20).xy(0.0, 0.0),
            g01(30).xy(100.0, 0.0),
            g01(40).xy(50.0, 0.0),
            g01(50).xy(50.0, 50.0),
            g01(60).xy(0.0, 0.0),
        ],
    );
    assert!(
        matches!(e.kind, AreaErrorKind::SelfIntersection { .. }),
        "{e}"
    );
    // A vertex touching a non-adjacent edge.
    let e = def_err(
        SEED_POLY,
        &[
            g01(20).xy(0.0, 0.0),
            g01(30).xy(100.0, 0.0),
            g01(40).xy(100.0, 100.0),
            g01(50).xy(50.0, 0.0),
            g01(60).xy(0.0, 100.0),
            g01(70).xy(0.0, 0.0),
        ],
    );
    assert!(
        matches!(e.kind, AreaErrorKind::SelfIntersection { .. }),
        "{e}"
    );
}

#[test]
fn start_point_must_be_complete_and_axes_not_mixed() {
    let e = def_err(SEED_POLY, &[g01(20).x(0.0)]);
    assert_eq!(
        e.kind,
        AreaErrorKind::StartIncomplete {
            id: 3,
            axes: "X and Y (G17)".into()
        }
    );
    assert_eq!(e.message().id, ids::AREA_AXES);
    let e = def_err(SEED_POLY, &[g01(20).xy(0.0, 0.0), g01(30).x2(5.0)]);
    assert_eq!(e.kind, AreaErrorKind::MixedAxes { id: 3 });
    let e = def_err(SEED_CIRC, &[g01(20).x2(0.0).y2(0.0)]);
    assert_eq!(e.kind, AreaErrorKind::AdditionalAxesCirc { id: 4 });
}

#[test]
fn circ_rules() {
    // Start point must be G01.
    let e = def_err(
        SEED_CIRC,
        &[DefBlock::new(n(20), DefMotion::G02)
            .xy(0.0, 0.0)
            .centre(0.0, 75.0)],
    );
    assert!(
        matches!(
            e.kind,
            AreaErrorKind::WrongMotion {
                found: DefMotion::G02,
                ..
            }
        ),
        "{e}"
    );
    // Second block must be G02/G03.
    let e = def_err(SEED_CIRC, &[g01(20).xy(0.0, 0.0), g01(30).xy(10.0, 0.0)]);
    assert!(
        matches!(
            e.kind,
            AreaErrorKind::WrongMotion {
                found: DefMotion::G01,
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.at, Some(n(30)));
    // No centre.
    let e = def_err(
        SEED_CIRC,
        &[
            g01(20).xy(0.0, 0.0),
            DefBlock::new(n(30), DefMotion::G03).xy(0.0, 0.0),
        ],
    );
    assert_eq!(e.kind, AreaErrorKind::NoCentre { id: 4 });
    // Not a full circle.
    let e = def_err(
        SEED_CIRC,
        &[
            g01(20).xy(0.0, 0.0),
            DefBlock::new(n(30), DefMotion::G02)
                .xy(0.0, 150.0)
                .centre(0.0, 75.0),
        ],
    );
    assert_eq!(e.kind, AreaErrorKind::NotFullCircle { id: 4 });
    // Radius zero.
    let e = def_err(
        SEED_CIRC,
        &[
            g01(20).xy(0.0, 0.0),
            DefBlock::new(n(30), DefMotion::G02).centre(0.0, 0.0),
        ],
    );
    assert_eq!(e.kind, AreaErrorKind::ZeroRadius { id: 4 });
    // A block after the circle.
    let mut blocks = seed_circ_blocks();
    blocks.push(g01(35).xy(5.0, 5.0));
    let e = def_err(SEED_CIRC, &blocks);
    assert_eq!(e.kind, AreaErrorKind::ExtraBlock { id: 4 });
    assert_eq!(e.at, Some(n(35)));
    // END without the circle.
    let e = def_err(SEED_CIRC, &[g01(20).xy(0.0, 0.0)]);
    assert_eq!(e.kind, AreaErrorKind::CircleMissing { id: 4 });
    assert_eq!(e.at, Some(n(999)));
    assert_eq!(e.message().id, ids::AREA_CIRCLE);
    // G03 is as good as G02.
    let mut t = AreaTable::new();
    define(
        &mut t,
        SEED_CIRC,
        &[
            g01(20).xy(0.0, 0.0),
            DefBlock::new(n(30), DefMotion::G03).centre(0.0, 75.0),
        ],
    )
    .unwrap();
}

#[test]
fn min_excur_must_be_below_max_excur() {
    for (min, max) in [(50.0, 50.0), (60.0, 50.0)] {
        let e = def_err(
            &format!("BEGIN [ID3 WORK POLY MIN_EXCUR={min} MAX_EXCUR={max}]"),
            &[],
        );
        assert_eq!(e.kind, AreaErrorKind::ExcursionOrder { id: 3, min, max });
        assert_eq!(e.at, Some(n(10)));
        assert_eq!(e.message().id, ids::AREA_EXCURSION);
    }
}

#[test]
fn twenty_first_area_is_refused() {
    let mut t = AreaTable::new();
    for id in 1..=20 {
        let (begin, blocks) = square(id, "WORK", 10.0);
        define(&mut t, &begin, &blocks).unwrap();
    }
    assert_eq!(t.len(), MAX_AREAS);
    let (begin, blocks) = square(21, "WORK", 10.0);
    let e = define(&mut t, &begin, &blocks).unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::TableFull { id: 21 });
    assert_eq!(e.message().id, ids::AREA_TABLE_FULL);
    assert_eq!(t.state(21), AreaState::Cleared);
    // Overwriting one of the 20 is fine; clearing one makes room.
    let (begin, blocks) = square(7, "PROT", 5.0);
    define(&mut t, &begin, &blocks).unwrap();
    assert_eq!(t.area(7).unwrap().kind(), AreaKind::Prot);
    let mut no = |_: &Area| false;
    t.apply(&parse("CLEAR [ID=7]"), None, &mut no).unwrap();
    let (begin, blocks) = square(21, "WORK", 10.0);
    define(&mut t, &begin, &blocks).unwrap();
    assert_eq!(t.state(21), AreaState::Defined);
}

#[test]
fn overwrite_of_an_active_area_is_refused() {
    let mut t = AreaTable::new();
    let (begin, blocks) = square(1, "WORK", 10.0);
    define(&mut t, &begin, &blocks).unwrap();
    t.apply(&parse("ON [ID1]"), Some(n(20)), &mut at(0.0, 0.0))
        .unwrap();
    let (begin, blocks) = square(1, "WORK", 50.0);
    let e = define(&mut t, &begin, &blocks).unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::OverwriteActive { id: 1 });
    assert_eq!(e.at, Some(n(10)));
    assert_eq!(e.message().id, ids::AREA_OVERWRITE_ACTIVE);
    assert!(!t.is_defining());
    assert_eq!(t.area(1).unwrap().extents().max[0], 10.0);
    // Inactive: overwrite allowed.
    t.apply(&parse("OFF [ID1]"), None, &mut at(0.0, 0.0))
        .unwrap();
    define(&mut t, &begin, &blocks).unwrap();
    assert_eq!(t.area(1).unwrap().extents().max[0], 50.0);
}

#[test]
fn failed_redefinition_keeps_the_old_area() {
    let mut t = AreaTable::new();
    define(&mut t, SEED_POLY, &seed_poly_blocks()).unwrap();
    let e = define(&mut t, SEED_POLY, &[g01(20).xy(0.0, 0.0).absolute(false)]).unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::NotAbsolute { id: 3 });
    assert_eq!(t.area(3).unwrap().extents().max, [150.0, 150.0, 50.0]);
}

#[test]
fn sequence_errors() {
    let mut t = AreaTable::new();
    let mut no = |_: &Area| false;
    let e = t.apply(&AreaCommand::End, Some(n(5)), &mut no).unwrap_err();
    assert!(matches!(
        e.kind,
        AreaErrorKind::Sequence { command: "END", .. }
    ));
    assert_eq!(e.message().id, ids::AREA_SEQUENCE);
    let e = t.definition_block(&g01(6).xy(0.0, 0.0)).unwrap_err();
    assert!(matches!(e.kind, AreaErrorKind::Sequence { .. }));
    t.apply(&parse(SEED_POLY), Some(n(10)), &mut no).unwrap();
    let e = t
        .apply(&parse(SEED_CIRC), Some(n(20)), &mut no)
        .unwrap_err();
    assert!(matches!(
        e.kind,
        AreaErrorKind::Sequence {
            command: "BEGIN",
            ..
        }
    ));
    let e = t.apply(&parse("ON ALL"), Some(n(20)), &mut no).unwrap_err();
    assert!(matches!(
        e.kind,
        AreaErrorKind::Sequence { command: "ON", .. }
    ));
    // Program end with an open definition: discarded and reported at the BEGIN block.
    let m = t.program_end().unwrap();
    assert_eq!((m.id, m.block), (ids::AREA_SEQUENCE, Some(n(10))));
    assert!(!t.is_defining());
    assert!(t.is_empty());
}

// ---------------------------------------------------------------- states (Fig. 11)

#[test]
fn no_area_is_predefined_at_start_up() {
    let t = AreaTable::new();
    assert!(t.is_empty());
    assert_eq!(t.state(1), AreaState::Cleared);
    assert_eq!(t.active().count(), 0);
}

#[test]
fn fig11_transitions() {
    let mut t = AreaTable::new();
    let mut inside_ws = at(0.0, 0.0);
    // cleared → defined (BEGIN .. END)
    let (begin, blocks) = square(1, "WORK", 10.0);
    define(&mut t, &begin, &blocks).unwrap();
    assert_eq!(t.state(1), AreaState::Defined);
    // defined → defined (OFF: nop)
    assert!(t
        .apply(&parse("OFF [ID1]"), None, &mut inside_ws)
        .unwrap()
        .is_empty());
    assert_eq!(t.state(1), AreaState::Defined);
    // defined → defined (BEGIN .. END: overwrite)
    define(&mut t, &begin, &blocks).unwrap();
    assert_eq!(t.state(1), AreaState::Defined);
    // defined → active (ON)
    t.apply(&parse("ON [ID1]"), None, &mut inside_ws).unwrap();
    assert_eq!(t.state(1), AreaState::Active);
    assert_eq!(t.active().map(Area::id).collect::<Vec<_>>(), vec![1]);
    // active → active (ON: nop)
    t.apply(&parse("ON [ID1]"), None, &mut inside_ws).unwrap();
    assert_eq!(t.state(1), AreaState::Active);
    // active → active (CLEAR: warning 120499)
    let w = t
        .apply(&parse("CLEAR [ID1]"), Some(n(70)), &mut inside_ws)
        .unwrap();
    assert_eq!(w.len(), 1);
    assert_eq!(w[0].id, 120499);
    assert_eq!(w[0].severity, Severity::Warning);
    assert_eq!(w[0].block, Some(n(70)));
    assert_eq!(t.state(1), AreaState::Active);
    // active → active (BEGIN: refused)
    assert!(define(&mut t, &begin, &blocks).is_err());
    assert_eq!(t.state(1), AreaState::Active);
    // active → defined (OFF)
    t.apply(&parse("OFF [ID1]"), None, &mut inside_ws).unwrap();
    assert_eq!(t.state(1), AreaState::Defined);
    // defined → cleared (CLEAR)
    assert!(t
        .apply(&parse("CLEAR [ID1]"), None, &mut inside_ws)
        .unwrap()
        .is_empty());
    assert_eq!(t.state(1), AreaState::Cleared);
    assert!(t.area(1).is_none());
    // cleared → cleared (OFF, CLEAR: nop; ON: error)
    assert!(t
        .apply(&parse("OFF [ID1]"), None, &mut inside_ws)
        .unwrap()
        .is_empty());
    assert!(t
        .apply(&parse("CLEAR [ID1]"), None, &mut inside_ws)
        .unwrap()
        .is_empty());
    let e = t
        .apply(&parse("ON [ID1]"), Some(n(90)), &mut inside_ws)
        .unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::Undefined { id: 1 });
    assert_eq!(e.message().id, ids::AREA_UNDEFINED);
    assert_eq!(t.state(1), AreaState::Cleared);
}

#[test]
fn clear_all_clears_inactive_and_warns_for_active() {
    let mut t = AreaTable::new();
    let mut tcp = at(0.0, 0.0);
    for id in 1..=3 {
        let (begin, blocks) = square(id, "WORK", 10.0 * id as f64);
        define(&mut t, &begin, &blocks).unwrap();
    }
    t.apply(&parse("ON [ID2]"), None, &mut tcp).unwrap();
    let w = t.apply(&parse("CLEAR ALL"), Some(n(50)), &mut tcp).unwrap();
    assert_eq!(
        w.iter().map(|m| m.id).collect::<Vec<_>>(),
        vec![ids::AREA_CLEAR_ACTIVE]
    );
    assert!(w[0].text.contains('2'));
    assert_eq!(t.areas().map(Area::id).collect::<Vec<_>>(), vec![2]);
}

#[test]
fn areas_survive_program_end_and_reset_deactivates_them() {
    let mut t = AreaTable::new();
    let mut tcp = at(0.0, 0.0);
    let (begin, blocks) = square(1, "WORK", 10.0);
    define(&mut t, &begin, &blocks).unwrap();
    t.apply(&parse("ON ALL"), None, &mut tcp).unwrap();
    assert_eq!(t.program_end(), None);
    assert_eq!(t.state(1), AreaState::Active);
    t.reset();
    assert_eq!(t.state(1), AreaState::Defined);
    // Reactivated by its ID at any time.
    t.apply(&parse("ON [ID1]"), None, &mut tcp).unwrap();
    assert_eq!(t.state(1), AreaState::Active);
}

#[test]
fn bare_off_deactivates_the_area_last_selected() {
    let mut t = AreaTable::new();
    let mut tcp = at(0.0, 0.0);
    for id in [1, 2] {
        let (begin, blocks) = square(id, "WORK", 10.0);
        define(&mut t, &begin, &blocks).unwrap();
    }
    // Nothing selected yet.
    let e = t.apply(&parse("OFF"), Some(n(5)), &mut tcp).unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::Undefined { id: 0 });
    t.apply(&parse("ON [ID1]"), None, &mut tcp).unwrap();
    t.apply(&parse("ON [ID2]"), None, &mut tcp).unwrap();
    assert_eq!(t.last_selected(), &[2]);
    t.apply(&parse("#CONTROL AREA OFF"), None, &mut tcp)
        .unwrap();
    assert_eq!(t.state(2), AreaState::Defined);
    assert_eq!(t.state(1), AreaState::Active);
    t.apply(&parse("ON ALL"), None, &mut tcp).unwrap();
    t.apply(&parse("OFF"), None, &mut tcp).unwrap();
    assert_eq!(t.active().count(), 0);
    // OFF ALL from several active.
    t.apply(&parse("ON ALL"), None, &mut tcp).unwrap();
    t.apply(&parse("OFF ALL"), None, &mut tcp).unwrap();
    assert_eq!(t.active().count(), 0);
}

#[test]
fn activation_requires_a_valid_tcp() {
    let mut t = AreaTable::new();
    let (begin, blocks) = square(1, "WORK", 100.0);
    define(&mut t, &begin, &blocks).unwrap();
    let (begin, blocks) = square(2, "PROT", 10.0);
    define(&mut t, &begin, &blocks).unwrap();

    // Outside the workspace: refused.
    let e = t
        .apply(&parse("ON [ID1]"), Some(n(40)), &mut at(150.0, 0.0))
        .unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::TcpInvalid { ids: vec![1] });
    assert_eq!(e.message().id, ids::AREA_TCP_INVALID);
    assert_eq!(e.at, Some(n(40)));
    assert_eq!(t.state(1), AreaState::Defined);
    // Inside the protection area: refused; ON ALL is all-or-nothing.
    let e = t
        .apply(&parse("ON ALL"), None, &mut at(0.0, 0.0))
        .unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::TcpInvalid { ids: vec![2] });
    assert_eq!(t.active().count(), 0);
    // On the protection boundary: refused; on the workspace boundary: fine.
    assert!(t
        .apply(&parse("ON [ID2]"), None, &mut at(10.0, 0.0))
        .is_err());
    t.apply(&parse("ON ALL"), None, &mut at(100.0, 50.0))
        .unwrap();
    assert_eq!(t.active().count(), 2);
    // Excursion: above MAX_EXCUR of the protection area is outside it.
    t.reset();
    let mut above = AreaPoint {
        plane: [0.0, 0.0],
        excursion: 10.5,
    };
    assert!(t.apply(&parse("ON [ID1]"), None, &mut above).is_err()); // and outside the workspace
    t.apply(&parse("ON [ID2]"), None, &mut above).unwrap();
}

#[test]
fn workspaces_form_a_union_when_activated() {
    // Seed 000 Fig. 7: the TCP in workspace 1 may activate workspace 2 it is not in.
    let mut t = AreaTable::new();
    let (begin, blocks) = square(1, "WORK", 10.0);
    define(&mut t, &begin, &blocks).unwrap();
    let mut far = vec![
        g01(20).xy(100.0, 100.0),
        g01(30).xy(120.0, 100.0),
        g01(40).xy(120.0, 120.0),
        g01(50).xy(100.0, 120.0),
        g01(60).xy(100.0, 100.0),
    ];
    define(
        &mut t,
        "BEGIN [ID=2 WORK POLY MIN_EXCUR=-10 MAX_EXCUR=10]",
        &far,
    )
    .unwrap();
    t.apply(&parse("ON [ID1]"), None, &mut at(0.0, 0.0))
        .unwrap();
    t.apply(&parse("ON [ID2]"), None, &mut at(0.0, 0.0))
        .unwrap();
    // An IMCS workspace is a separate monitoring space: the MCS ones do not count for it.
    far[0] = g01(20).xy(100.0, 100.0);
    define(
        &mut t,
        "BEGIN [ID=3 WORK POLY MIN_EXCUR=-10 MAX_EXCUR=10 MONITOR_LVL=IMCS]",
        &far,
    )
    .unwrap();
    let e = t
        .apply(&parse("ON [ID3]"), None, &mut at(0.0, 0.0))
        .unwrap_err();
    assert_eq!(e.kind, AreaErrorKind::TcpInvalid { ids: vec![3] });
}

#[test]
fn a_closure_can_locate_the_tcp() {
    let mut t = AreaTable::new();
    define(&mut t, SEED_CIRC, &seed_circ_blocks()).unwrap();
    let mut asked = Vec::new();
    let mut locator = |a: &Area| {
        asked.push(a.id());
        false
    };
    t.apply(&parse("ON [ID4]"), None, &mut locator).unwrap();
    assert_eq!(asked, vec![4]);
    assert_eq!(t.state(4), AreaState::Active);
}

/// Seed 000 §3.1.1: "Normally, the surface area of the workspace or protection area is defined
/// by the first two main axes of the active machining plane." Under G18 the block's 1st / 2nd
/// coordinates are Z / X (DIN 66025), the area records the plane of its starting point.
#[test]
fn an_area_keeps_the_plane_of_its_starting_point() {
    let mut t = AreaTable::new();
    // G18: (Z, X) = (-10, 40) … a 20 × 20 square.
    let blocks: Vec<DefBlock> = [(-10.0, 40.0), (10.0, 40.0), (10.0, 60.0), (-10.0, 60.0)]
        .iter()
        .chain([(-10.0, 40.0)].iter())
        .enumerate()
        .map(|(i, &(z, x))| g01(20 + 10 * i as u32).xy(z, x).plane(Plane::G18))
        .collect();
    define(
        &mut t,
        "BEGIN [ID5 PROT POLY MIN_EXCUR=-5 MAX_EXCUR=5]",
        &blocks,
    )
    .unwrap();
    let a = t.area(5).unwrap();
    assert_eq!(a.plane, Plane::G18);
    assert_eq!(a.axis_names(), ["Z", "X", "Y"]);
    assert_eq!(
        a.geometry,
        AreaGeometry::Polygon {
            vertices: vec![[-10.0, 40.0], [10.0, 40.0], [10.0, 60.0], [-10.0, 60.0]]
        }
    );
    // G19: Y / Z, excursion X; IMCS: the same order with U / V / W.
    assert_eq!(
        plane_axis_names(MonitorLevel::Mcs, AreaAxes::Main, Plane::G19),
        ["Y", "Z", "X"]
    );
    assert_eq!(
        plane_axis_names(MonitorLevel::Imcs, AreaAxes::Main, Plane::G18),
        ["W", "U", "V"]
    );
    // The additional axes of §4 are X2 / Y2 / Z2 in every plane.
    let mut t = AreaTable::new();
    let add: Vec<DefBlock> = [
        (100.0, 100.0),
        (-100.0, 100.0),
        (-100.0, -100.0),
        (100.0, 100.0),
    ]
    .iter()
    .enumerate()
    .map(|(i, &(x, y))| g01(20 + 10 * i as u32).x2(x).y2(y).plane(Plane::G19))
    .collect();
    define(&mut t, SEED_POLY, &add).unwrap();
    assert_eq!(t.area(3).unwrap().axis_names(), ["X2", "Y2", "Z2"]);
}

#[test]
fn the_plane_must_not_change_within_a_definition() {
    let e = def_err(
        SEED_POLY,
        &[
            g01(20).xy(0.0, 0.0).plane(Plane::G18),
            g01(30).xy(10.0, 0.0).plane(Plane::G17),
        ],
    );
    assert_eq!(
        e.kind,
        AreaErrorKind::PlaneChanged {
            id: 3,
            plane: Plane::G18,
            found: Plane::G17
        }
    );
    assert_eq!(e.message().id, ids::AREA_AXES);
    assert_eq!(e.at.and_then(|b| b.number), Some(30));
    // The starting point names the coordinates of its plane when one is missing.
    let e = def_err(SEED_POLY, &[g01(20).x(0.0).plane(Plane::G19)]);
    assert_eq!(
        e.kind,
        AreaErrorKind::StartIncomplete {
            id: 3,
            axes: "Y and Z (G19)".into()
        }
    );
    // A block without coordinates (e.g. `G17` alone) defines nothing and changes nothing.
    let mut t = AreaTable::new();
    let mut blocks = seed_poly_blocks();
    for b in blocks.iter_mut() {
        b.plane = Plane::G18;
    }
    blocks.insert(3, DefBlock::new(n(45), DefMotion::G01));
    define(&mut t, SEED_POLY, &blocks).unwrap();
    assert_eq!(t.area(3).unwrap().plane, Plane::G18);
}
