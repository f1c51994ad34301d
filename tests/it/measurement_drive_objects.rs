//! Drive objects written and read by the fixed-stop examples of seed 004 §7.3 through `#DRIVE`
//! (drive function table, §7.3.2) and `#IDENT` (SERCOS IDNs, §7.3.1), observed in the simulated
//! drives' object dictionaries cycle by cycle.
//!
//! Expected wire values from the seed: TORQUE LIMIT is `LINEAR` with `scaling_factor 10.0`
//! (VAL 10 → 100, VAL 5000 → 50000), MON WINDOW is `UNSCALED` (4294967295, 1048575). The
//! SERCOS example reads S-0-0092 / S-0-0159 into P-parameters, writes 100 and 0 and restores the
//! values read at the end; on the CiA 402 drive S-0-0092 is 0x6072 and S-0-0159 is 0x6065,
//! where SERCOS 0 (monitoring off) is 0xFFFFFFFF (`drives/cia402-generic.toml` `[idn]`).

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::messages::CncMessage;
use fieldprobe::nc::exec::{Event, Executor, Step};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use std::path::Path;

/// (0x6072 max torque, 0x6065 following error window) of a drive, and the command of its axis.
type Objects = (i64, i64);

fn objects(m: &mut Machine, axis: usize) -> Objects {
    let d = m.link_mut().model_mut(axis).unwrap();
    (
        d.read_object(0x6072, 0).unwrap(),
        d.read_object(0x6065, 0).unwrap(),
    )
}

fn example(name: &str) -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("examples/nc/seed004")
            .join(name),
    )
    .unwrap()
}

/// A run cycle by cycle; after every cycle `(objects, command)` of each axis in `watch`.
struct Traced {
    exec: Executor,
    messages: Vec<CncMessage>,
    completed: bool,
    /// Per cycle, per watched axis.
    samples: Vec<Vec<(Objects, f64)>>,
    /// Before the first cycle.
    initial: Vec<Objects>,
}

fn run_traced(m: &mut Machine, src: &str, watch: &[usize]) -> Traced {
    let prog = parse(src).unwrap();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let names = m
        .channel()
        .axes()
        .iter()
        .map(|a| a.name().to_string())
        .collect();
    let mut exec = Executor::new(prog, names);
    exec.sync(m.channel());
    let initial = watch.iter().map(|&a| objects(m, a)).collect();
    let (mut messages, mut samples, mut out) = (Vec::new(), Vec::new(), Vec::new());
    let mut completed = false;
    loop {
        messages.extend(m.channel_mut().take_messages());
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                let step = exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    completed = true;
                    break;
                }
            }
            _ => {
                assert!(samples.len() < 1_000_000);
                m.step();
                let s = watch
                    .iter()
                    .map(|&a| (objects(m, a), m.channel().axes()[a].command()))
                    .collect();
                samples.push(s);
            }
        }
    }
    messages.extend(m.channel_mut().take_messages());
    Traced {
        exec,
        messages,
        completed,
        samples,
        initial,
    }
}

/// The distinct object values of watched axis `k` in the order they appeared.
fn phases(t: &Traced, k: usize) -> Vec<Objects> {
    let mut v = vec![t.initial[k]];
    for s in &t.samples {
        if *v.last().unwrap() != s[k].0 {
            v.push(s[k].0);
        }
    }
    v
}

// ---------------------------------------------------------------------------------------------
// §7.3.2 CANopen: #DRIVE
// ---------------------------------------------------------------------------------------------

#[test]
fn canopen_fixed_stop_example_writes_torque_limit_and_monitoring_window() {
    let mut cfg = MachineConfig::default_machine();
    cfg.apply_set("Z.kenngr.measure.signal=FIXED_STOP").unwrap();
    cfg.apply_set("Z.P-AXIS-00774=10000").unwrap();
    cfg.apply_set("Z.P-AXIS-00775=20000").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    m.add_fixed_stop("Z", 150.0).unwrap();
    const Z: usize = 2;
    let t = run_traced(&mut m, &example("meas_fixed_stop_canopen.nc"), &[Z]);
    assert!(t.completed, "{:?}", t.messages);
    assert!(t.messages.is_empty(), "{:?}", t.messages);
    let (torque0, window0) = t.initial[0];
    // N030 TORQUE LIMIT VAL=10 → 100; N040 MON WINDOW 4294967295; N070 MON WINDOW 1048575;
    // N080 TORQUE LIMIT VAL=5000 → 50000.
    assert_eq!(
        phases(&t, 0),
        vec![
            (torque0, window0),
            (100, window0),
            (100, 0xFFFF_FFFF),
            (100, 1_048_575),
            (50_000, 1_048_575),
        ]
    );
    // The measuring run (N050, Z above 100 towards the wall) and the move back (N060) happen
    // with the torque limited and the drive's lag monitoring off.
    let above: Vec<Objects> = t
        .samples
        .iter()
        .filter(|s| s[0].1 > 100.0 + 1e-6)
        .map(|s| s[0].0)
        .collect();
    assert!(!above.is_empty());
    assert!(above.iter().all(|o| *o == (100, 0xFFFF_FFFF)), "{above:?}");
    let peak = t.samples.iter().map(|s| s[0].1).fold(f64::MIN, f64::max);
    assert!(
        peak > 150.0,
        "pressed against the wall at 150: command reached {peak}"
    );
    assert_eq!(t.samples[t.samples.len() - 1][0].1, 100.0);
    // The wall was measured.
    let z = t.exec.result(Z).expect("measured");
    assert!((z.acs - 150.0).abs() <= 1e-4, "{}", z.acs);
}

/// The keys of `[functions]` in `drives/cia402-generic.toml`.
fn drive_function_keys() -> Vec<String> {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("drives/cia402-generic.toml"),
    )
    .unwrap();
    let section = &text[text.find("[functions]").unwrap()..];
    let section = &section[..section[1..].find("\n[").map_or(section.len(), |i| i + 1)];
    section
        .lines()
        .filter_map(|l| l.split_once(" = {").map(|(k, _)| k.trim().to_string()))
        .collect()
}

#[test]
fn an_unknown_drive_key_is_an_error_naming_the_keys() {
    let keys = drive_function_keys();
    assert!(keys.contains(&"TORQUE_LIMIT".to_string()), "{keys:?}");
    assert!(keys.contains(&"MON_WINDOW".to_string()), "{keys:?}");
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let r = m.run_program(
        &parse("N10 G01 Z10 F1000\nN20 #DRIVE WR SYN [AX=Z KEY=TORQUE_LIMT VAL=10 WAIT]\nN30 G01 Z20\nN40 M30\n")
            .unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900050]);
    let e = r.messages()[0];
    assert_eq!(e.block.and_then(|b| b.number), Some(20));
    for k in &keys {
        assert!(e.text.contains(k.as_str()), "{k} not named in: {}", e.text);
    }
    // N30 was not executed (the axis did not go on towards 20; for the few 0.01 µm of the error
    // reaction see `an_error_right_after_a_block_does_not_move_the_axes`).
    assert!((m.channel().axes()[2].command() - 10.0).abs() < 1e-3);
    // The drive's torque limit is untouched.
    assert_eq!(objects(&mut m, 2).0, 3000);
}

#[test]

fn an_error_right_after_a_block_does_not_move_the_axes() {
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let r = m.run_program(
        &parse(
            "N10 G01 Z10 F1000\nN20 #DRIVE WR SYN [AX=Z KEY=TORQUE_LIMT VAL=10 WAIT]\nN30 M30\n",
        )
        .unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.message_ids(), vec![900050]);
    assert_eq!(m.channel().axes()[2].command(), 10.0);
}

#[test]
fn a_drive_value_outside_the_function_range_is_an_error() {
    // TORQUE_LIMIT: wire = VAL × 10, UNSIGNED16: VAL 10000 → 100000 > 65535.
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let before = objects(&mut m, 2);
    let r = m.run_program(
        &parse("N10 #DRIVE WR SYN [AX=Z KEY=TORQUE_LIMIT VAL=10000 WAIT]\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.message_ids(), vec![900050]);
    assert_eq!(objects(&mut m, 2), before);
}

#[test]
fn drive_read_into_a_p_parameter() {
    // 0x6072 = 3000 (0.1 %) reads back through TORQUE_LIMIT (÷ 10) as 300 %.
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let raw = objects(&mut m, 2).0;
    let r = m.run_program(
        &parse("N10 #DRIVE RD [AX=Z KEY=TORQUE_LIMIT P=P10 WAIT]\nN20 #MSG SYN[\"%f\", P10]\nN30 M30\n")
            .unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
    assert_eq!(r.output(), vec![format!("{:.6}", raw as f64 / 10.0)]);
}

// ---------------------------------------------------------------------------------------------
// §7.3.1 SERCOS gantry: #IDENT
// ---------------------------------------------------------------------------------------------

#[test]
fn sercos_gantry_example_reads_limits_and_restores_them() {
    let cfg = MachineConfig::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/machines/gantry.toml"),
    )
    .unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    m.add_fixed_stop("X", 300.0).unwrap();
    // AXNR 1 = X (index 0), AXNR 4 = X2 (index 3); Y, Z, Z2 are not touched.
    let watch = [0, 3, 1, 2, 4];
    let t = run_traced(&mut m, &example("meas_fixed_stop_sercos.nc"), &watch);
    assert!(t.completed, "{:?}", t.messages);
    assert!(t.messages.is_empty(), "{:?}", t.messages);
    for k in [0, 1] {
        let (torque0, window0) = t.initial[k];
        // N080/N090 S-0-0092 = 100; N100/N110 S-0-0159 = 0 (monitoring off); N140 – N170 back
        // to the values read in N040 – N070.
        let p = phases(&t, k);
        assert_eq!(p.first(), Some(&(torque0, window0)));
        assert_eq!(p.last(), Some(&(torque0, window0)), "restored: {p:?}");
        assert!(p.contains(&(100, 0xFFFF_FFFF)), "{p:?}");
    }
    // The P-parameters hold the values read (S-0-0159 of a monitoring window ≠ 0 is the window).
    assert_eq!(t.exec.param(1092), Some(t.initial[0].0 as f64));
    assert_eq!(t.exec.param(1159), Some(t.initial[0].1 as f64));
    assert_eq!(t.exec.param(2092), Some(t.initial[1].0 as f64));
    assert_eq!(t.exec.param(2159), Some(t.initial[1].1 as f64));
    // The measuring run N120 (X above 100) and the move back happen with torque limit and
    // monitoring off on the master and its slave.
    for s in t.samples.iter().filter(|s| s[0].1 > 100.0 + 1e-6) {
        assert_eq!(s[0].0, (100, 0xFFFF_FFFF));
        assert_eq!(s[1].0, (100, 0xFFFF_FFFF));
    }
    for (k, axis) in watch.iter().enumerate().skip(2) {
        assert_eq!(phases(&t, k), vec![t.initial[k]], "axis {axis} untouched");
    }
    assert!((t.exec.result(0).unwrap().acs - 300.0).abs() <= 1e-4);
}

#[test]
fn an_unknown_idn_is_an_error() {
    let mut m = Machine::new(&MachineConfig::default_machine()).unwrap();
    let r = m.run_program(
        &parse("N10 #IDENT WR SYN [AXNR 3 ID S-0-0999 VAL=1 TYP 2 DEC 0 SERC]\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900050]);
    assert!(
        r.messages()[0].text.contains("S-0-0999"),
        "{}",
        r.messages()[0]
    );
}
