//! Issue 16 item 3: no allocation per steady-state cycle on the EtherCAT hot path. A counting
//! global allocator (`stats_alloc`, which needs no `unsafe` here) counts every allocation of
//! the process while machines run `Machine::step`. The file runs without the libtest harness
//! (`harness = false`): the counter sees every thread, and the harness's own thread allocates
//! now and then while a test runs (seen in `tests/canopen_alloc.rs`: 4 allocations in 1 run of
//! 20), so the one check runs on the main thread alone.
//!
//! Steady state: the axes enabled and all moving (continuous jogs, so every drive model
//! integrates and every image changes), after a settling phase in which buffers reach their
//! size. Counted over 500 cycles of the whole `Machine::step` — on `ethercat-emu` the channel,
//! the adapters, the link (outputs into ethercrab's image, the frames through the emulated
//! segment, each datagram checked, SYNC0 step of every model with the plant, inputs back) — with
//! 8 axes and with 32 axes + 64 terminals: nothing may be allocated; `sim` alike. Not covered:
//! a network interface (a received frame is copied into a new buffer) and `--pcap`.

use std::alloc::System;

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{LinkChoice, Machine};
use fieldprobe::params::MachineConfig;
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

const CYCLES: u64 = 500;

/// `axes` linear axes, not referenced (a jog runs as long as it is asked to), jogging.
fn moving_machine(cfg: MachineConfig, link: &str) -> Machine {
    let axes = cfg.axes.len();
    let mut m = Machine::with_link(&cfg, &LinkChoice::new(link)).unwrap();
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let ch = m.channel_mut();
    assert!(ch.enter_manual());
    for i in 0..axes {
        assert!(ch.jog_continuous(i, 1.0 + i as f64));
    }
    for _ in 0..500 {
        m.step();
    }
    m
}

fn axes(n: usize) -> MachineConfig {
    let mut toml = String::new();
    for i in 0..n {
        toml.push_str(&format!(
            "[[axis]]\nname = \"X{}\"\nreferenced = false\n",
            i + 1
        ));
    }
    MachineConfig::parse(&toml, "alloc.toml").unwrap()
}

fn with_io() -> MachineConfig {
    let path = format!(
        "{}/examples/machines/channel32_io64.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut cfg = MachineConfig::load(std::path::Path::new(&path)).unwrap();
    for a in &mut cfg.axes {
        a.referenced = false;
    }
    cfg
}

/// Allocations during [`CYCLES`] steps of `m`.
fn allocations(m: &mut Machine) -> usize {
    let reg = Region::new(GLOBAL);
    for _ in 0..CYCLES {
        m.step();
    }
    let s = reg.change();
    s.allocations + s.reallocations
}

fn main() {
    a_steady_ethercat_cycle_allocates_nothing();
    println!("test a_steady_ethercat_cycle_allocates_nothing ... ok");
}

fn a_steady_ethercat_cycle_allocates_nothing() {
    let mut report = Vec::new();
    for (name, cfg) in [("8 axes", axes(8)), ("32 axes + 64 terminals", with_io())] {
        // The in-memory link has no terminals.
        let mut axes_only = cfg.clone();
        axes_only.terminals.clear();
        let sim = allocations(&mut moving_machine(axes_only, "sim"));
        let emu = allocations(&mut moving_machine(cfg, "ethercat-emu"));
        report.push(format!(
            "{name}: ethercat-emu {emu} allocations in {CYCLES} cycles, sim {sim}"
        ));
        // Before: 3 per cycle on ethercat-emu (a frame buffer per frame, the world step's port
        // list), 1 on sim (its port list).
        assert_eq!((emu, sim), (0, 0), "{}", report.join("; "));
    }
    eprintln!("{}", report.join("\n"));
}
