//! Frames end to end: a G54 zero offset from the machine file acts like meas2's `G92 Z33`
//! (seed 004 §5: "Zero Shifts"), `#TRAFO` is refused, and the CNC's position lag monitoring
//! (P-AXIS-00168) is off for the axes of a measurement to a fixed stop (§7.3.1).

use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use std::process::Command;

const Z: usize = 2;

#[test]
fn g54_zero_offset_gives_the_meas2_numbers() {
    // meas2 with `G54` (zero offset Z = 33 mm in the machine file) instead of `G92 Z33`: the
    // seed's values for meas2 apply unchanged (both are "zero shifts").
    let toml = "[[axis]]\nname = \"X\"\nkenngr.messachse = 1\n[[axis]]\nname = \"Y\"\nkenngr.messachse = 1\n\
                [[axis]]\nname = \"Z\"\nkenngr.messachse = 1\n[zero_offset.G54]\nZ = 330000\n";
    let cfg = MachineConfig::parse(toml, "g54.toml").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    m.add_probe("Z", 100.0).unwrap();
    let src = "N05 #MEAS MODE[1]\nN10 G54\nN20 G01 G90 Z200 F2000\nN30 G100 Z20 F2000\n\
               N40 #MSG SYN[\"%f %f %f %f\", V.A.MESS.Z, V.A.MEAS.ACS.VALUE.Z, V.A.MEAS.PCS.VALUE.Z, V.A.MOFFS.Z]\n\
               N70 G101 Z1\nN80 #MSG SYN[\"%f\", V.A.MEIN.Z]\nN90 G01 Z100 F1000\nN100 #MSG SYN[\"%f\", V.A.ABS.Z]\n\
               N110 G102 Z1\nN130 G01 Z100 F1000\nN140 #MSG SYN[\"%f\", V.A.ABS.Z]\nN150 M30\n";
    let r = m.run_program(&parse(src).unwrap(), &mut |_| {});
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(
        r.output(),
        vec![
            "100.000000 100.000000 67.000000 47.000000",
            "47.000000",
            "180.000000",
            "133.000000"
        ]
    );
    // G53 deselects the zero offset: Z100 is ACS 100 again.
    let r = m.run_program(
        &parse("N10 G54\nN20 G53\nN30 G01 G90 Z100 F3000\nN40 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed);
    assert_eq!(m.channel().axes()[Z].command(), 100.0);
}

#[test]
fn trafo_is_refused_as_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("trafo.nc");
    std::fs::write(&p, "N10 G01 X10 F100\nN20 #TRAFO ON\nN30 M30\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args(["run", p.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("trafo.nc:2:") && e.contains("#TRAFO"), "{e}");
}

#[test]
fn cnc_lag_monitoring_trips_but_not_for_a_fixed_stop_run() {
    // P-AXIS-00168 = 1 mm. A free G01 at 100 mm/s on a drive with feed-forward lags by far less
    // (µm), so it runs; an obstacle at Z = 50 in its way stalls the axis and the lag grows with
    // the command (100 mm/s): the monitoring trips.
    let mut cfg = MachineConfig::default_machine();
    cfg.apply_set("Z.P-AXIS-00168=10000").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = m.run_program(
        &parse("N10 G01 G90 Z100 F6000\nN20 G01 Z0\nN30 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let mut m = Machine::new(&cfg).unwrap();
    m.add_fixed_stop("Z", 50.0).unwrap();
    let r = m.run_program(
        &parse("N10 G01 G90 Z100 F6000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900014]);
    // It trips in the first cycle the lag exceeds 1 mm: the lag grows by v·T = 0.1 mm a cycle.
    let text = &r.messages()[0].text;
    let lag: f64 = text
        .split_whitespace()
        .nth(2)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!((1.0..=1.1 + 1e-9).contains(&lag), "{text}");
    // The same axis measuring to a fixed stop at the same feed: monitoring is off for it.
    for s in [
        "P-CHAN-00057=7",
        "Z.kenngr.measure.signal=FIXED_STOP",
        "Z.P-AXIS-00774=100000",
        "Z.P-AXIS-00775=20000",
    ] {
        cfg.apply_set(s).unwrap();
    }
    let mut m = Machine::new(&cfg).unwrap();
    m.add_fixed_stop("Z", 50.0).unwrap();
    m.link_mut()
        .model_mut(Z)
        .unwrap()
        .write_object(0x6065, 0, 0xFFFF_FFFF)
        .unwrap();
    let r = m.run_program(
        &parse("N10 G100 G90 Z100 F6000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    let z = r.measurements[Z].result.unwrap();
    assert!(
        (z.acs - 50.0).abs() < 1e-4,
        "latched at the wall: {}",
        z.acs
    );
}
