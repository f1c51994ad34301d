//! Issue 16 item 3 on CANopen: no allocation per steady-state cycle on the `canopen-emu` hot
//! path. A counting global allocator (`stats_alloc`) counts every allocation of the process
//! while a machine runs `Machine::step`. It is a `harness = false` test (Cargo.toml): `main`
//! runs it on the process's only thread, so nothing else allocates during a counted window.
//!
//! What one counted cycle covers on `canopen-emu`: the channel and the adapters, our CiA 301
//! master (RPDOs packed and sent, SYNC, the TPDOs awaited and copied into the input images,
//! the heartbeat consumer), the in-process bus with its wire (each frame queued, arbitrated,
//! timed and delivered at the bit rate), and the emulated CiA 402 nodes (RPDO take-over,
//! synchronous TPDOs, heartbeats, the SYNC / RPDO watches, the drive models and the plant).
//!
//! Steady state, after a settling phase in which every buffer reached its size:
//! * the default three-axis machine (at a cycle the bus carries, 4 ms at 1 Mbit/s) with every
//!   axis jogging at constant velocity; the count covers at least one producer heartbeat of
//!   every node (100 ms) so the heartbeat path is in it;
//! * the same machine in a G100 measuring move of Z towards a probe it does not reach within
//!   the counted cycles: the touch probe armed, Z at its constant feed.
//!
//! Not covered: SDO transfers (acyclic, allocate their data), `--candump`, a bus that leaves
//! the process (`canopen-udp`, `socketcan:IF`), start-up.

use std::alloc::System;

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{LinkChoice, Machine};
use fieldprobe::nc::exec::{Event, Executor, Step};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Counted cycles: 1 s of machine time at 4 ms, ten heartbeat periods of every node.
const CYCLES: u64 = 250;

/// The default machine at a cycle its bus carries (see tests/it/canopen_link.rs: 56 % at 4 ms).
fn machine(link: &str) -> Machine {
    let mut cfg = MachineConfig::default_machine();
    cfg.apply_set("cycle_time_us=4000").unwrap();
    for a in &mut cfg.axes {
        a.referenced = false;
    }
    Machine::with_link(&cfg, &LinkChoice::new(link)).unwrap()
}

/// Allocations (and reallocations) while `f` runs.
fn counted(f: impl FnOnce()) -> usize {
    let reg = Region::new(GLOBAL);
    f();
    let s = reg.change();
    s.allocations + s.reallocations
}

/// Every axis jogging; allocations during [`CYCLES`] steps after 500 settling ones.
fn jogging(link: &str) -> usize {
    let mut m = machine(link);
    let axes = m.channel().axis_count();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    for i in 0..axes {
        assert!(ch.jog_continuous(i, 1.0 + i as f64));
    }
    for _ in 0..500 {
        m.step();
    }
    let before = m.channel().actual_positions();
    let n = counted(|| {
        for _ in 0..CYCLES {
            m.step();
        }
    });
    // The axes did move over the counted cycles.
    let after = m.channel().actual_positions();
    for (i, (a, b)) in before.iter().zip(&after).enumerate() {
        assert!(b - a > 0.5, "axis {i} at {a} then {b}: not moving");
    }
    assert_eq!(m.channel().state(), ChannelState::Busy, "{link}");
    n
}

/// A G100 measuring move of Z towards a probe at 1000 mm (not reached); allocations during
/// [`CYCLES`] steps once Z moves at its feed.
fn measuring(link: &str) -> usize {
    let mut m = machine(link);
    m.add_probe("Z", 1000.0).unwrap();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let names = m
        .channel()
        .axes()
        .iter()
        .map(|a| a.name().to_string())
        .collect();
    let mut exec = Executor::new(parse("N10 G100 Z900 F3000\nN20 M30\n").unwrap(), names);
    exec.sync(m.channel());
    let mut out = Vec::new();
    while m.channel().state() == ChannelState::Idle {
        let step = exec.step(m.channel_mut(), &mut out);
        for Event::Output(_) in out.drain(..) {}
        assert_ne!(step, Step::End, "the measuring block did not start");
    }
    // Acceleration to F3000 (50 mm/s) is over well within 1 s.
    for _ in 0..250 {
        m.step();
    }
    let z0 = m.channel().actual_positions()[2];
    let busy = m.channel().state();
    let n = counted(|| {
        for _ in 0..CYCLES {
            m.step();
        }
    });
    let z1 = m.channel().actual_positions()[2];
    // 50 mm/s over 1 s, at constant feed, still short of the probe.
    assert!(
        (z1 - z0 - 50.0).abs() < 0.5,
        "{link}: Z {z0} → {z1}, not at its feed"
    );
    assert_eq!(m.channel().state(), busy, "{link}: the move ended");
    n
}

fn main() {
    a_steady_canopen_cycle_allocates_nothing();
    println!("canopen_alloc: a steady CANopen cycle allocates nothing: ok");
}

fn a_steady_canopen_cycle_allocates_nothing() {
    let jog_sim = jogging("sim");
    let jog_can = jogging("canopen-emu");
    let meas_sim = measuring("sim");
    let meas_can = measuring("canopen-emu");
    let report = format!(
        "jogging: canopen-emu {jog_can} allocations in {CYCLES} cycles, sim {jog_sim}; \
         G100 with the probe armed: canopen-emu {meas_can}, sim {meas_sim}"
    );
    eprintln!("{report}");
    assert_eq!(
        (jog_can, jog_sim, meas_can, meas_sim),
        (0, 0, 0, 0),
        "{report}"
    );
}
