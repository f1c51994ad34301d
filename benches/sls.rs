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

criterion_group!(benches, bench_sls);
criterion_main!(benches);
