//! Faults during a run: a lost process-data exchange or a drive fault stops the axes and reports;
//! a modulo rotary axis is exempt from SLS monitoring (seed 001 §2 Notice).

use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;

fn default_machine() -> Machine {
    Machine::new(&MachineConfig::default_machine()).unwrap()
}

#[test]
fn lost_exchange_during_motion_aborts_and_brakes() {
    let mut m = default_machine();
    // Enabling takes a few exchanges; lose one well inside the motion.
    // One more than max_lost_cycles (3) in a row: the link is lost.
    for j in 0..4 {
        m.link_mut().lose_exchange_at(300 + j);
    }
    let r = m.run_program(
        &parse("N10 G01 G90 X100 F6000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900012]);
    assert_eq!(r.messages()[0].block.and_then(|b| b.number), Some(10));
    let x = &m.channel().axes()[0];
    assert!(
        x.command() < 100.0,
        "the block did not run to its end: {}",
        x.command()
    );
    // Standstill: further cycles do not move the command.
    let c = x.command();
    for _ in 0..100 {
        m.step();
    }
    assert_eq!(m.channel().axes()[0].command(), c);
}

#[test]
fn drive_fault_during_motion_aborts() {
    use fieldprobe::channel::ChannelState;
    use fieldprobe::nc::exec::Executor;
    let mut m = default_machine();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let prog = parse("N10 G01 G90 X100 F6000\nN20 M30\n").unwrap();
    let mut exec = Executor::new(prog, vec!["X".into(), "Y".into(), "Z".into()]);
    exec.sync(m.channel());
    exec.step(m.channel_mut(), &mut Vec::new());
    assert_eq!(m.channel().state(), ChannelState::Busy);
    for _ in 0..200 {
        m.step();
    }
    m.link_mut().model_mut(0).unwrap().inject_fault(0x8611);
    assert_eq!(m.settle(100_000), ChannelState::Aborted);
    let ids: Vec<u32> = m
        .channel_mut()
        .take_messages()
        .iter()
        .map(|x| x.id)
        .collect();
    assert_eq!(ids, vec![900010]);
    assert!(m.channel().axes()[0].command() < 100.0);
}

#[test]
fn following_error_window_fault_stops_the_run() {
    // A tight 0x6065 window (drive file default is wide): 1000 inc = 0.1 mm for 10 ms (0x6066).
    // An obstacle at X = 50 stalls the axis while the set-points run on at 100 mm/s: the drive's
    // following error passes 0.1 mm after 1 ms, the drive faults (0x8611), the channel stops.
    let mut m = default_machine();
    m.add_fixed_stop("X", 50.0).unwrap();
    m.link_mut()
        .model_mut(0)
        .unwrap()
        .write_object(0x6065, 0, 1000)
        .unwrap();
    let r = m.run_program(
        &parse("N10 G01 G90 X100 F6000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900010]);
    assert_eq!(m.link_mut().model_mut(0).unwrap().last_error_code(), 0x8611);
}

#[test]
fn modulo_rotary_axis_is_exempt_non_modulo_rotary_is_not() {
    let toml = |mode: u32| {
        format!(
            "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"A\"\nkenngr.achs_typ = \"ACHSTYP_ROTATOR\"\nkenngr.achs_mode = {mode}\nkenngr.swe_neg = -3600000\nkenngr.swe_pos = 3600000\n"
        )
    };
    let prog = parse("N10 G01 G90 A500 F36000\nN20 M30\n").unwrap();
    let cfg = MachineConfig::parse(&toml(0x5), "rot.toml").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = m.run_program(&prog, &mut |_| {});
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.message_ids());
    let cfg = MachineConfig::parse(&toml(0x1), "rot.toml").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = m.run_program(&prog, &mut |_| {});
    assert_eq!(r.message_ids(), vec![120002]);
    // P-AXIS-00705 = 1 switches monitoring on for the modulo axis too.
    let cfg = MachineConfig::parse(&(toml(0x5) + "kenngr.swe_check = 1\n"), "rot.toml").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
    let r = m.run_program(&prog, &mut |_| {});
    assert_eq!(r.message_ids(), vec![120002]);
}

#[test]
fn target_beyond_drive_position_range_is_refused_in_preparation() {
    // Not referenced: no SLS; 10000 inc/mm → INTEGER32 covers ±214748 mm.
    let mut cfg = MachineConfig::default_machine();
    cfg.axis_mut("X").unwrap().referenced = false;
    let mut m = Machine::new(&cfg).unwrap();
    let r = m.run_program(
        &parse("N10 G01 G90 X300000 F6000\nN20 M30\n").unwrap(),
        &mut |_| {},
    );
    assert_eq!(r.status, RunStatus::Aborted);
    assert_eq!(r.message_ids(), vec![900013]);
    assert_eq!(m.channel().axes()[0].command(), 0.0);
}

#[test]
fn after_a_drive_fault_the_next_program_start_resets_and_runs() {
    let mut m = default_machine();
    let prog = parse("N10 G01 G90 X10 F6000\nN20 M30\n").unwrap();
    // An obstacle at X = 5 and a 1 µm window (0x6065 = 10 inc): the drive faults.
    m.add_fixed_stop("X", 5.0).unwrap();
    m.link_mut()
        .model_mut(0)
        .unwrap()
        .write_object(0x6065, 0, 10)
        .unwrap();
    let r = m.run_program(&prog, &mut |_| {});
    assert_eq!(r.message_ids(), vec![900010]);
    assert_eq!(
        m.link_mut().model_mut(0).unwrap().state(),
        fieldprobe::drive::PowerState::Fault
    );
    // Clear the obstacle and open the window again; the controller reset at program start
    // sends the fault-reset edge (controlword bit 7) and re-enables.
    m.link_mut().plant_mut().unwrap().fixed_stops_mut().clear();
    m.link_mut()
        .model_mut(0)
        .unwrap()
        .write_object(0x6065, 0, 300_000)
        .unwrap();
    let r = m.run_program(&prog, &mut |_| {});
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.message_ids());
    assert_eq!(m.channel().axes()[0].command(), 10.0);
}

#[test]
fn drive_emergencies_reach_the_channel_as_warning_900015_on_canopen_and_ethercat() {
    use fieldprobe::machine::LinkChoice;
    use fieldprobe::messages::Severity;
    for link in ["canopen-emu", "ethercat-emu"] {
        let mut cfg = MachineConfig::default_machine();
        if link == "canopen-emu" {
            // Issue 16: three nodes need 4 ms at 1 Mbit/s (docs/canopen.md "Bus load").
            cfg.apply_set("cycle_time_us=4000").unwrap();
        }
        let mut m = Machine::with_link(&cfg, &LinkChoice::new(link)).unwrap();
        m.settle(10_000);
        m.channel_mut().take_messages();
        m.link_mut().model_mut(2).unwrap().inject_fault(0x8611);
        for _ in 0..5 {
            m.step();
        }
        // EtherCAT: the CoE emergency waits in the SubDevice's mailbox until the master's next
        // mailbox access collects it.
        if link == "ethercat-emu" {
            m.link_mut().read_object(2, 0x6041, 0).unwrap();
            m.step();
        }
        let msgs = m.channel_mut().take_messages();
        let e: Vec<_> = msgs.iter().filter(|x| x.id == 900015).collect();
        assert_eq!(e.len(), 1, "{link}: {msgs:?}");
        assert_eq!(e[0].severity, Severity::Warning);
        assert_eq!(
            e[0].text, "axis Z: drive emergency 0x8611 (following error (CiA 402))",
            "{link}"
        );
        assert_eq!(e[0].axis.as_deref(), Some("Z"));
    }
}
