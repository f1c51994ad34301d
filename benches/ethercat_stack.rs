#![allow(missing_docs)]
//! Full-stack cycle cost over EtherCAT (issue 5 target: ≥ 10,000 cycles/s with 8 axes on the CI
//! machine, i.e. ≤ 100 µs per cycle). One iteration = one [`Machine::step`] on `--link
//! ethercat-emu`: the channel and the SLS core, the CiA 402 adapters writing the output images,
//! ethercrab's PDI copy and two LRW frames (outputs; inputs after SYNC0) through the PDU loop,
//! the emulated ESCs (FMMUs, sync managers, working counters) and the SYNC0 step of every drive
//! model with the plant. The axes are enabled and in position control. The same machine on
//! `--link sim` is measured alongside, so the bus share of the cost is visible.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{LinkChoice, Machine};
use fieldprobe::params::MachineConfig;

fn machine(axes: usize, link: &str) -> Machine {
    let mut toml = String::new();
    for i in 0..axes {
        toml.push_str(&format!("[[axis]]\nname = \"X{}\"\n", i + 1));
    }
    let cfg = MachineConfig::parse(&toml, "bench.toml").expect("machine");
    let mut m = Machine::with_link(&cfg, &LinkChoice::new(link)).expect("link");
    assert_eq!(m.settle(10_000), ChannelState::Idle, "axes enabled");
    m
}

fn bench_stack(c: &mut Criterion) {
    let mut g = c.benchmark_group("full_stack_cycle");
    for axes in [1usize, 8, 32] {
        g.throughput(Throughput::Elements(1));
        for link in ["ethercat-emu", "sim"] {
            let mut m = machine(axes, link);
            g.bench_with_input(
                BenchmarkId::new(link, format!("{axes}_axes")),
                &axes,
                |b, _| b.iter(|| m.step()),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench_stack);
criterion_main!(benches);
