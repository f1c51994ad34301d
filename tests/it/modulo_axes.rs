//! Modulo rotary axes (issue 27 item 6): a rotary axis with ACHSMODE_MODULO (P-AXIS-00015,
//! seed 001 §1 "rotary axes … configured as modulo axes") reads inside its modulo range
//! P-AXIS-00127 … P-AXIS-00126 (ISG axis parameters; default 0° … 360°) once it is at rest:
//! `G90 A370` ends at 10°, a long continuous jog ends inside [0°, 360°) — while the drive has
//! travelled the whole way (docs/interpretations.md M33).

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

const A: usize = 1;

fn rotary(mode: u32, extra: &str) -> Machine {
    let text = format!(
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"A\"\nkenngr.achs_typ = \"ACHSTYP_ROTATOR\"\n\
         kenngr.achs_mode = {mode}\n{extra}\n"
    );
    let cfg = MachineConfig::parse(&text, "rot.toml").unwrap_or_else(|e| panic!("{e}"));
    Machine::new(&cfg).unwrap()
}

/// Where the drive is (°): the CNC's position plus the whole ranges it was wrapped by.
fn drive_position(m: &Machine) -> f64 {
    let a = &m.channel().axes()[A];
    a.command() + a.modulo_offset()
}

#[test]
fn g90_a370_reads_10_and_the_next_block_starts_there() {
    let mut m = rotary(0x5, "");
    let r = m.run_program(
        &parse(
            "N10 G90 G01 A370 F36000\nN20 #MSG SYN[\"%f %f\", V.A.ABS.A, V.A.PROG.A]\n\
             N30 G91 A10\nN40 #MSG SYN[\"%f %f\", V.A.ABS.A, V.A.PROG.A]\n\
             N50 G90 A-30\nN60 #MSG SYN[\"%f %f\", V.A.ABS.A, V.A.PROG.A]\nN70 M30\n",
        )
        .unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert!(r.messages().is_empty(), "{:?}", r.messages());
    assert_eq!(
        r.output(),
        vec![
            "10.000000 10.000000",
            "20.000000 20.000000",
            "330.000000 330.000000"
        ]
    );
    // The drive went the programmed way: +370, +10, then from 20 to −30 (−50).
    assert!(
        (drive_position(&m) - 330.0).abs() < 1e-9,
        "{}",
        drive_position(&m)
    );
    let actual = m.channel().axes()[A].actual();
    assert!((0.0..360.0).contains(&actual), "actual {actual}");
}

#[test]
fn the_modulo_range_is_p_axis_00127_to_00126() {
    // −180° … 180° (P-AXIS-00127 = −1800000, P-AXIS-00126 = 1800000, 0.0001°).
    let mut m = rotary(0x5, "P-AXIS-00127 = -1800000\nP-AXIS-00126 = 1800000");
    let r = m.run_program(
        &parse("N10 G90 G01 A270 F36000\nN20 #MSG SYN[\"%f\", V.A.ABS.A]\nN30 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.output(), vec!["-90.000000"]);
}

#[test]
fn a_rotary_axis_without_achsmode_modulo_is_not_wrapped() {
    let mut m = rotary(0x1, "kenngr.swe_neg = -36000000\nkenngr.swe_pos = 36000000");
    let r = m.run_program(
        &parse("N10 G90 G01 A370 F36000\nN20 #MSG SYN[\"%f\", V.A.ABS.A]\nN30 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.output(), vec!["370.000000"]);
    assert_eq!(m.channel().axes()[A].modulo_offset(), 0.0);
}

#[test]
fn a_long_continuous_jog_ends_inside_the_range() {
    // Relative offset limits 0 (P-AXIS-00137 / 00138: off), as the jog had none.
    let mut m = rotary(
        0x5,
        "handbetrieb.offsetgrenze_neg = 0\nhandbetrieb.offsetgrenze_pos = 0",
    );
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    // 170 °/s for 25 s: more than 4000°; no limit on a modulo axis (SLS inactive, seed 001 §1).
    assert!(ch.jog_continuous(A, 170.0));
    let mut during = Vec::new();
    for _ in 0..25_000 {
        m.step();
        during.push(m.channel().axes()[A].command());
    }
    m.channel_mut().jog_stop(A);
    assert_eq!(m.settle(100_000), ChannelState::Idle);
    // While it moves the position runs on (no jump inside a motion) …
    assert!(
        during.windows(2).all(|w| w[1] >= w[0]),
        "monotonic while jogging"
    );
    assert!(*during.last().unwrap() > 4000.0);
    // … at rest it is the drive's position reduced into [0, 360).
    let a = m.channel().axes()[A].command();
    let drive = drive_position(&m);
    assert!(drive > 4000.0, "the drive travelled {drive}°");
    assert!((0.0..360.0).contains(&a), "reads {a}");
    let off = (a - drive).rem_euclid(360.0);
    assert!(off.min(360.0 - off) < 1e-9, "{a} vs {drive}");
}
