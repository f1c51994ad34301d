#![allow(missing_docs)]
//! Full-stack cycle cost over EtherCAT (issue 5 target: ≥ 10,000 cycles/s with 8 axes on the CI
//! machine, i.e. ≤ 100 µs per cycle). One iteration = one [`Machine::step`] on `--link
//! ethercat-emu`: the channel and the SLS core, the CiA 402 adapters writing the output images,
//! ethercrab's PDI copy and one LRW frame (this cycle's outputs; the inputs the devices latched
//! at the previous SYNC0) through the PDU loop, the emulated ESCs (FMMUs, sync managers, working
//! counters) and the SYNC0 step of every drive model with the plant. The axes are enabled and in
//! position control, standing (`…_axes`) or all moving (`…_axes_moving`: continuous jogs, so
//! every drive integrates its feed-forward servo over 16 sub-samples). The same machine on
//! `--link sim` is measured alongside, so the bus share of the cost is visible.
//!
//! Issue 16: a full channel with its I/O — `examples/machines/channel32_io64.toml`, 32 axes and
//! 64 terminals (97 SubDevices with the emulator's coupler; a 2616-byte image in two LRW
//! datagrams, three frames per cycle) — and the cost per SubDevice of one step with 96 named
//! devices against that with 8 (`per_subdevice`, printed after the groups: target ≤ 1.5×).

use std::time::Instant;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{LinkChoice, Machine};
use fieldprobe::params::MachineConfig;

fn machine(axes: usize, link: &str, moving: bool) -> Machine {
    let mut toml = String::new();
    for i in 0..axes {
        // Not referenced: no limits, so a continuous jog runs for as long as the bench does.
        toml.push_str(&format!(
            "[[axis]]\nname = \"X{}\"\nreferenced = {}\n",
            i + 1,
            !moving
        ));
    }
    let cfg = MachineConfig::parse(&toml, "bench.toml").expect("machine");
    let mut m = Machine::with_link(&cfg, &LinkChoice::new(link)).expect("link");
    assert_eq!(m.settle(10_000), ChannelState::Idle, "axes enabled");
    if moving {
        let ch = m.channel_mut();
        assert!(ch.enter_manual());
        for i in 0..axes {
            assert!(ch.jog_continuous(i, 1.0 + i as f64));
        }
        // Past the acceleration ramp.
        for _ in 0..100 {
            m.step();
        }
    }
    m
}

/// The 32-axis machine with 64 terminals (`examples/machines/channel32_io64.toml`) on
/// `ethercat-emu`, axes enabled; `moving`: all 32 jogging.
fn machine_with_io(moving: bool) -> Machine {
    let path = format!(
        "{}/examples/machines/channel32_io64.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut cfg = MachineConfig::load(std::path::Path::new(&path)).expect("machine");
    if moving {
        for a in &mut cfg.axes {
            a.referenced = false;
        }
    }
    let axes = cfg.axes.len();
    let mut m = Machine::with_link(&cfg, &LinkChoice::new("ethercat-emu")).expect("link");
    assert_eq!(m.settle(10_000), ChannelState::Idle, "axes enabled");
    if moving {
        let ch = m.channel_mut();
        assert!(ch.enter_manual());
        for i in 0..axes {
            assert!(ch.jog_continuous(i, 1.0 + i as f64));
        }
        for _ in 0..100 {
            m.step();
        }
    }
    m
}

fn bench_stack(c: &mut Criterion) {
    let mut g = c.benchmark_group("full_stack_cycle");
    for axes in [1usize, 8, 32] {
        g.throughput(Throughput::Elements(1));
        for link in ["ethercat-emu", "sim"] {
            for moving in [false, true] {
                let mut m = machine(axes, link, moving);
                let name = if moving {
                    format!("{axes}_axes_moving")
                } else {
                    format!("{axes}_axes")
                };
                g.bench_with_input(BenchmarkId::new(link, name), &axes, |b, _| {
                    b.iter(|| m.step())
                });
            }
        }
    }
    for moving in [false, true] {
        let mut m = machine_with_io(moving);
        let name = if moving {
            "32_axes_64_terminals_moving"
        } else {
            "32_axes_64_terminals"
        };
        g.bench_function(BenchmarkId::new("ethercat-emu", name), |b| {
            b.iter(|| m.step())
        });
    }
    g.finish();
}

/// µs per `Machine::step` over `steps` steps (after the machine is set up).
fn step_time(m: &mut Machine, steps: u32) -> f64 {
    let t = Instant::now();
    for _ in 0..steps {
        m.step();
    }
    t.elapsed().as_secs_f64() * 1e6 / f64::from(steps)
}

/// The cost per SubDevice: 8 axes (8 named SubDevices + the emulator's coupler) against 32 axes
/// with 64 terminals (96 + the coupler), standing and moving, the best of three runs of 2000
/// steps each. Printed, not asserted (benches measure, tests decide).
fn per_subdevice(_: &mut Criterion) {
    for moving in [false, true] {
        let best = |m: &mut Machine| {
            (0..3)
                .map(|_| step_time(m, 2000))
                .fold(f64::INFINITY, f64::min)
        };
        let small = best(&mut machine(8, "ethercat-emu", moving));
        let large = best(&mut machine_with_io(moving));
        let (per8, per96) = (small / 8.0, large / 96.0);
        println!(
            "per SubDevice ({}): 8 axes {small:.1} µs/step = {per8:.2} µs per device; 32 axes + 64 terminals {large:.1} µs/step = {per96:.2} µs per device; ratio {:.2} (with the coupler: {:.2} / {:.2} µs, ratio {:.2})",
            if moving { "moving" } else { "standing" },
            per96 / per8,
            small / 9.0,
            large / 97.0,
            (large / 97.0) / (small / 9.0)
        );
    }
}

criterion_group!(benches, bench_stack, per_subdevice);
criterion_main!(benches);
