#![allow(missing_docs)]
//! Per-cycle cost of software-limit-switch monitoring (issue 2 target: < 50 ns per axis per
//! cycle on the CI machine). One iteration = one interpolation cycle's SLS work for 32 axes:
//! the actual-position check (P-AXIS-00179 tolerance band, 70021 / 70022) and the command-side
//! stop-distance check (P-AXIS-00520 / 00521, 70195). Criterion's throughput line reports the
//! rate per axis.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use fieldprobe::core::monitor::sls::{AxisLimitConfig, SoftLimits};

const AXES: usize = 32;

fn limits() -> SoftLimits {
    let cfgs = (0..AXES)
        .map(|i| {
            let mut c = AxisLimitConfig::linear(&format!("A{i}"), -200.0, 200.0);
            c.check_pos_command = true;
            c.check_neg_command = true;
            c
        })
        .collect();
    let mut s = SoftLimits::new(cfgs, false);
    for i in 0..AXES {
        s.set_referenced(i, true);
    }
    s
}

fn bench_sls(c: &mut Criterion) {
    let mut s = limits();
    let positions: Vec<f64> = (0..AXES).map(|i| -150.0 + 10.0 * i as f64).collect();
    let velocities: Vec<f64> = (0..AXES)
        .map(|i| if i % 2 == 0 { 50.0 } else { -50.0 })
        .collect();
    let mut g = c.benchmark_group("sls_cycle");
    g.throughput(Throughput::Elements(AXES as u64));
    g.bench_function("32_axes_actual_and_stop_distance", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for i in 0..AXES {
                let p = black_box(positions[i]);
                if s.check_actual(i, p).is_some() {
                    hits += 1;
                }
                if s.check_stop_distance(i, p, black_box(velocities[i]))
                    .is_some()
                {
                    hits += 1;
                }
            }
            black_box(hits)
        })
    });
    g.bench_function("32_axes_command_path_line", |b| {
        let seg =
            fieldprobe::core::path::Segment::line(vec![0.0; AXES], positions.clone()).unwrap();
        let mut out = Vec::with_capacity(AXES);
        b.iter(|| {
            s.check_path(black_box(&seg), &mut out);
            black_box(out.len())
        })
    });
    g.finish();
}

criterion_group!(benches, bench_sls, bench_machine_cycle);
criterion_main!(benches);

/// One whole interpolation cycle of a 32-axis machine on the in-memory link (exchange, adapters,
/// drive models, SLS monitoring, interpolation of a G01 through all axes) — context for the
/// monitoring share above.
fn bench_machine_cycle(c: &mut Criterion) {
    use fieldprobe::machine::Machine;
    use fieldprobe::nc::exec::Executor;
    use fieldprobe::nc::parser::parse;
    use fieldprobe::params::MachineConfig;
    let mut toml = String::from("[channel]\ncycle_time_us = 1000\n");
    let names: Vec<String> = (0..AXES)
        .map(|i| format!("{}{}", ["X", "Y", "Z", "A"][i % 4], i / 4 + 1))
        .collect();
    for n in &names {
        toml.push_str(&format!("[[axis]]\nname = \"{n}\"\n"));
    }
    let cfg = MachineConfig::parse(&toml, "bench.toml").expect("machine");
    let mut m = Machine::new(&cfg).expect("machine");
    m.settle(10_000);
    // Long back-and-forth blocks through all axes, so every measured cycle interpolates.
    let block = |v: i32| {
        names
            .iter()
            .map(|n| format!("{n}={v}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut src = String::from("N1 G01 F100000\n");
    for k in 0..1000 {
        src.push_str(&format!(
            "N{} {}\n",
            k + 2,
            block(if k % 2 == 0 { 9000 } else { -9000 })
        ));
    }
    let prog = parse(&src).expect("program");
    let mut exec = Executor::new(prog, names.clone());
    exec.sync(m.channel());
    let mut ev = Vec::new();
    let mut g = c.benchmark_group("machine_cycle");
    g.throughput(Throughput::Elements(AXES as u64));
    g.bench_function("32_axes_sim_link_g01", |b| {
        b.iter(|| {
            if m.channel().is_idle() {
                exec.step(m.channel_mut(), &mut ev);
            }
            m.step()
        })
    });
    g.finish();
}
