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
    g.finish();
}

criterion_group!(benches, bench_stack);
criterion_main!(benches);
