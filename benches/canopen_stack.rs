#![allow(missing_docs)]
//! Per-cycle cost of CANopen process data (issue 6): one [`Machine::step`] on `--link
//! canopen-emu` with the axes enabled — the channel, the CiA 402 adapters, every node's RPDOs
//! and SYNC over the in-process virtual CAN bus, the emulated nodes (PDO copy, the SYNC step of
//! every drive model), the TPDOs back (4 per node) and the heartbeat consumer — for 1 and 8
//! nodes, beside the same machine on `--link sim`.

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

fn bench_pdo(c: &mut Criterion) {
    let mut g = c.benchmark_group("canopen_pdo_cycle");
    g.throughput(Throughput::Elements(1));
    for nodes in [1usize, 8] {
        for link in ["canopen-emu", "sim"] {
            let mut m = machine(nodes, link);
            g.bench_with_input(
                BenchmarkId::new(link, format!("{nodes}_nodes")),
                &nodes,
                |b, _| b.iter(|| m.step()),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench_pdo);
criterion_main!(benches);
