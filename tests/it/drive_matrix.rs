//! Issue 4 "Done when": meas1–meas4 and the fixed-stop example give the same printed values with
//! the Z axis on each drive family, selected only by the machine file. The expected values are
//! the seed's (seed 004 §5 annotations; meas4 rounded by the seed, checked to 0.01 mm).
//!
//! meas4 runs in a rotated coordinate system: G100 Z moves ACS X and Z together, and the PCS
//! value depends on where X really was when Z latched. Interpolating axes with different
//! dynamics leave the programmed line (contour error; a terminal axis on Z with CiA 402 X puts
//! MESS.Z 0.03 mm off), so, as on a real machine where interpolating axes get matched loop gains,
//! meas4 runs with X, Y and Z on the same drive family. meas1–meas3 move Z alone and put only Z
//! on the family.

use fieldprobe::drive::catalogue;
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

fn machine(drive: &str, all_axes: bool) -> Machine {
    let extra = if drive == "cia402-drive-defined" {
        "\"P-AXIS-00702\" = \"DRIVE_DEFINED\"\n"
    } else {
        ""
    };
    let xy = if all_axes {
        format!("drive = \"{drive}\"\n{extra}")
    } else {
        String::new()
    };
    let toml = format!(
        "[[axis]]\nname = \"X\"\nkenngr.messachse = 1\n{xy}[[axis]]\nname = \"Y\"\nkenngr.messachse = 1\n{xy}\
         [[axis]]\nname = \"Z\"\ndrive = \"{drive}\"\nkenngr.messachse = 1\n{extra}"
    );
    let cfg = MachineConfig::parse(&toml, &format!("{drive}.toml")).unwrap();
    Machine::new(&cfg).unwrap_or_else(|e| panic!("{drive}: {e}"))
}

fn program(name: &str) -> String {
    std::fs::read_to_string(format!(
        "{}/examples/nc/seed004/{name}.nc",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

fn outputs(drive: &str, prog: &str, probe: f64) -> Vec<String> {
    let mut m = machine(drive, prog == "meas4");
    m.add_probe("Z", probe).unwrap();
    let r = m.run_program(&parse(&program(prog)).unwrap(), &mut |_| {});
    assert_eq!(
        r.status,
        RunStatus::Completed,
        "{drive} {prog}: {:?}",
        r.messages()
    );
    r.output().iter().map(|s| s.to_string()).collect()
}

/// (variable, value) pairs the seed annotates, in program order.
fn seed_values(prog: &str) -> Vec<(&'static str, f64)> {
    match prog {
        "meas1" => vec![
            ("V.A.MESS.Z", 100.0),
            ("V.A.MEAS.ACS.VALUE.Z", 100.0),
            ("V.A.MEAS.PCS.VALUE.Z", 100.0),
            ("V.A.MOFFS.Z", 80.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.MEIN.Z", 80.0),
            ("V.A.ABS.Z", 180.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.ABS.Z", 100.0),
        ],
        "meas2" => vec![
            ("V.A.MESS.Z", 100.0),
            ("V.A.MEAS.ACS.VALUE.Z", 100.0),
            ("V.A.MEAS.PCS.VALUE.Z", 67.0),
            ("V.A.MOFFS.Z", 47.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.MEIN.Z", 47.0),
            ("V.A.ABS.Z", 180.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.ABS.Z", 133.0),
        ],
        "meas3" => vec![
            ("V.A.MESS.Z", 67.0),
            ("V.A.MEAS.ACS.VALUE.Z", 100.0),
            ("V.A.MEAS.PCS.VALUE.Z", 67.0),
            ("V.A.MOFFS.Z", 47.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.MEIN.Z", 47.0),
            ("V.A.ABS.Z", 147.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.ABS.Z", 100.0),
        ],
        "meas4" => vec![
            ("V.A.MESS.Z", 20.0),
            ("V.A.MEAS.ACS.VALUE.Z", 55.5),
            ("V.A.MEAS.PCS.VALUE.Z", 20.0),
            ("V.A.MOFFS.Z", 30.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.MEIN.Z", 30.0),
            ("V.A.ABS.Z", 80.0),
            ("V.A.MEIN.Z", 0.0),
            ("V.A.ABS.Z", 50.0),
        ],
        _ => unreachable!(),
    }
}

#[test]
fn meas1_to_meas4_print_the_seed_values_on_every_drive_family() {
    let drives = catalogue::builtin_names();
    assert!(drives.contains(&"cia402-generic"));
    for &drive in drives {
        for (prog, probe, tol) in [
            ("meas1", 100.0, 0.0),
            ("meas2", 100.0, 0.0),
            ("meas3", 100.0, 0.0),
            ("meas4", 55.5, 0.01),
        ] {
            let out = outputs(drive, prog, probe);
            let want = seed_values(prog);
            assert_eq!(out.len(), want.len(), "{drive} {prog}: {out:?}");
            for (line, (var, v)) in out.iter().zip(&want) {
                if tol == 0.0 {
                    assert_eq!(line, &format!("{var}={v:.6}"), "{drive} {prog}");
                } else {
                    let (name, got) = line.split_once('=').unwrap();
                    let got: f64 = got.parse().unwrap();
                    assert!(
                        name == *var && (got - v).abs() <= tol,
                        "{drive} {prog}: {line} vs {var}={v}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_canopen_fixed_stop_example_latches_the_wall_on_every_family_with_a_torque_limit() {
    for &drive in catalogue::builtin_names() {
        let def = catalogue::load(drive).unwrap();
        if def.function("TORQUE_LIMIT").is_none() || def.function("MON_WINDOW").is_none() {
            // A terminal drive has no torque limit; the example's #DRIVE blocks need both keys.
            continue;
        }
        let prog = program("meas_fixed_stop_canopen");
        // Seed 004 §7.3: Z measures with FIXED_STOP, and detection needs a criterion (the
        // parameters default to "off").
        let prog = format!(
            "%fs\n{}",
            prog.lines().skip(1).collect::<Vec<_>>().join("\n")
        );
        let mut cfg = MachineConfig::parse(
            &format!(
                "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\ndrive = \"{drive}\"\nkenngr.messachse = 1\n\
                 kenngr.measure.signal = \"FIXED_STOP\"\n\
                 kenngr.measure.fixed_stop_detect.pos_lag_limit = 10000\nkenngr.measure.fixed_stop_detect.min_time = 20000\n{}",
                if drive == "cia402-drive-defined" { "\"P-AXIS-00702\" = \"DRIVE_DEFINED\"\n" } else { "" }
            ),
            "fs.toml",
        )
        .unwrap();
        cfg.apply_set("P-CHAN-00057=1").unwrap();
        let mut m = Machine::new(&cfg).unwrap();
        m.add_fixed_stop("Z", 150.0).unwrap();
        let r = m.run_program(&parse(&prog).unwrap(), &mut |_| {});
        assert_eq!(
            r.status,
            RunStatus::Completed,
            "{drive}: {:?}",
            r.messages()
        );
        let z = r.measurements[2]
            .result
            .unwrap_or_else(|| panic!("{drive}: no result"));
        assert!((z.acs - 150.0).abs() < 1e-3, "{drive}: latched {}", z.acs);
    }
}

#[test]
fn the_sercos_gantry_fixed_stop_example_latches_the_wall_on_every_family_with_an_idn_map() {
    // Seed 004 §7.3.1: the master X and its gantry slave X2 measure against a stop; the
    // example reads / writes S-0-0092 and S-0-0159 with #IDENT, which each drive file maps to
    // its own objects ([idn]). A terminal drive has no torque limit and no map.
    let base = std::fs::read_to_string(format!(
        "{}/examples/machines/gantry.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let mut ran = Vec::new();
    for &drive in catalogue::builtin_names() {
        let def = catalogue::load(drive).unwrap();
        if def.idn("S-0-0092").is_none() || def.idn("S-0-0159").is_none() {
            continue;
        }
        if !def.model.feed_forward {
            // A drive without feed-forward lags v / kv: X at this feed (1000 mm/min along the
            // 4-axis line, X's share 900 / 1952: 7.7 mm/s) lags 0.19 mm, above the example
            // machine's 0.1 mm criterion — it would "detect" a stop in free air, as it would
            // on a real machine.
            // tests/it/drive_physics.rs runs it at the seed's §7.3.2 feed.
            continue;
        }
        let extra = if drive == "cia402-drive-defined" {
            "\"P-AXIS-00702\" = \"DRIVE_DEFINED\"\n"
        } else {
            ""
        };
        let toml = base
            .replace(
                "name = \"X\"\n",
                &format!("name = \"X\"\ndrive = \"{drive}\"\n{extra}"),
            )
            .replace(
                "name = \"X2\"\n",
                &format!("name = \"X2\"\ndrive = \"{drive}\"\n{extra}"),
            );
        let cfg = MachineConfig::parse(&toml, "gantry.toml").unwrap();
        let mut m = Machine::new(&cfg).unwrap_or_else(|e| panic!("{drive}: {e}"));
        m.add_fixed_stop("X", 300.0).unwrap();
        let r = m.run_program(
            &parse(&program("meas_fixed_stop_sercos")).unwrap(),
            &mut |_| {},
        );
        assert_eq!(
            r.status,
            RunStatus::Completed,
            "{drive}: {:?}",
            r.messages()
        );
        assert!(r.messages().is_empty(), "{drive}: {:?}", r.messages());
        let x = r.measurements[0]
            .result
            .unwrap_or_else(|| panic!("{drive}: no result"));
        assert!((x.acs - 300.0).abs() < 1e-3, "{drive}: latched {}", x.acs);
        ran.push(drive);
    }
    for family in [
        "cia402-generic",
        "sercos-ax5000",
        "profidrive-t105",
        "ax2000-lightbus",
    ] {
        assert!(ran.contains(&family), "{family} not run: {ran:?}");
    }
}

/// Nothing from a wire may panic: every family's adapter and model take random images of random
/// lengths (short, exact, long), random object accesses and arming requests without panicking.
#[test]
fn random_images_and_object_accesses_never_panic_any_family() {
    use fieldprobe::drive::{
        adapter_for, model, DriveCommand, ProbeEdge, ProbeRequest, ProbeTrigger, TriggerSourceMode,
    };
    use fieldprobe::params::{ParamSet, Scope};
    use fieldprobe::units::Nanos;
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for &drive in catalogue::builtin_names() {
        let def = catalogue::load(drive).unwrap();
        let mut a = adapter_for(&def, &ParamSet::new(Scope::Axis)).unwrap();
        let mut m = model::for_definition(&def).unwrap();
        for k in 1..2000u64 {
            let now = Nanos(k * 1_000_000);
            let len = |n: usize, r: u64| match r % 4 {
                0 => (r as usize / 4) % (n + 1),
                1 => n + (r as usize / 4) % 8,
                _ => n,
            };
            let mut rx: Vec<u8> = (0..len(a.output_len(), next()))
                .map(|_| next() as u8)
                .collect();
            let mut tx: Vec<u8> = (0..len(a.input_len(), next()))
                .map(|_| next() as u8)
                .collect();
            m.begin_step(now, 1e-3, &rx);
            if next() % 7 == 0 {
                m.input_edge((next() % 3) as u8, next() % 2 == 0, Nanos(now.0 - 500_000));
            }
            m.finish_step(&mut tx);
            if next() % 3 == 0 {
                for b in tx.iter_mut() {
                    *b = next() as u8;
                }
            }
            let _ = a.read_inputs(now, &tx);
            let cmd = DriveCommand {
                enable: next() % 2 == 0,
                target: next() as i32,
                fault_reset: next() % 5 == 0,
                quick_stop: next() % 11 == 0,
            };
            let _ = a.write_outputs(now, &cmd, &mut rx);
            let r = next();
            let _ = m.write_object(
                (r >> 16) as u16,
                (r >> 32) as u8,
                (r >> 40) as i64 - (1 << 23),
            );
            let _ = m.read_object((r >> 8) as u16, r as u8);
            if r % 13 == 0 {
                let _ = a.arm_probe(&ProbeRequest {
                    probe: (next() % 3) as u8,
                    edge: if next() % 2 == 0 {
                        ProbeEdge::Positive
                    } else {
                        ProbeEdge::Negative
                    },
                    trigger: match next() % 3 {
                        0 => ProbeTrigger::Input,
                        1 => ProbeTrigger::ZeroPulse,
                        _ => ProbeTrigger::SourceObject,
                    },
                    continuous: next() % 4 == 0,
                    source_mode: match next() % 3 {
                        0 => TriggerSourceMode::Default,
                        1 => TriggerSourceMode::CncDefined,
                        _ => TriggerSourceMode::DriveDefined,
                    },
                    input: (next() % 300) as u8,
                });
            }
            while a.take_probe_event().is_some() {}
        }
    }
}
