#![allow(missing_docs)]
//! Full-stack cycle cost over CANopen (issues 6 and 16): one [`Machine::step`] on `--link
//! canopen-emu` with the axes enabled — the channel, the CiA 402 adapters, every node's RPDOs
//! and the SYNC on the virtual CAN bus with its wire at 1 Mbit/s (every frame's wire time,
//! arbitration by identifier, on virtual time), the emulated nodes (PDO copy, the SYNC step of
//! every drive model), their cyclic TPDOs back (2 per node; the touch probe positions only on
//! change) and the heartbeat consumer — for 1, 4 and 8 nodes, beside the same machine on `--link
//! sim`. Each machine runs at the shortest whole-millisecond cycle whose bus load stays below
//! the 70 % warning (docs/canopen.md "Bus load": 2 ms, 5 ms, 9 ms); the cost per cycle hardly
//! depends on the cycle, the wire does not wait on the wall clock.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fieldprobe::bus::can::Bitrate;
use fieldprobe::channel::ChannelState;
use fieldprobe::link::canopen::{load::WARN_LOAD, plan_bus_load};
use fieldprobe::machine::{LinkChoice, Machine};
use fieldprobe::params::MachineConfig;
use fieldprobe::units::Nanos;
use std::sync::Arc;

/// The shortest whole-ms cycle at which `nodes` default drives load a 1 Mbit/s bus below the
/// warning threshold.
fn cycle_us(nodes: usize) -> u64 {
    let def = Arc::new(fieldprobe::drive::catalogue::load("cia402-generic").expect("drive"));
    let ids: Vec<u8> = (1..=nodes as u8).collect();
    let load = plan_bus_load(
        &vec![def; nodes],
        &ids,
        Bitrate::DEFAULT,
        Nanos::from_micros(1000),
    )
    .expect("layout");
    let us = load.shortest_cycle(WARN_LOAD).expect("a cycle fits");
    us.div_ceil(1000) * 1000
}

fn machine(axes: usize, link: &str, cycle_us: u64) -> Machine {
    let mut toml = format!("[channel]\ncycle_time_us = {cycle_us}\n");
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
    for nodes in [1usize, 4, 8] {
        let cycle = cycle_us(nodes);
        for link in ["canopen-emu", "sim"] {
            let mut m = machine(nodes, link, cycle);
            g.bench_with_input(
                BenchmarkId::new(link, format!("{nodes}_nodes_{}ms", cycle / 1000)),
                &nodes,
                |b, _| b.iter(|| m.step()),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench_pdo);
criterion_main!(benches);
