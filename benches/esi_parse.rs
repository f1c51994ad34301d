#![allow(missing_docs)]
//! ESI parse time against size (issue 15: 100,000 attributes took 18 s, quadratic in the XML
//! reader's duplicate-attribute check). Two shapes, 1k / 10k / 100k attributes each, throughput
//! per attribute (a flat rate = linear):
//! - `spread`: attributes on many elements (a big vendor file), parsed in full;
//! - `one_element`: all on one element, refused by the pre-scan above
//!   `limits::MAX_ESI_ATTRIBUTES_PER_ELEMENT` before the XML reader sees them.

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fieldprobe::esi;

const COUPLER: &str = include_str!("../esi/fieldprobe-ek1100.xml");

/// `n` attributes on `n / 4` unknown elements inside the coupler's device.
fn spread(n: usize) -> String {
    let el: String = (0..n / 4)
        .map(|i| format!("<Info{} a=\"1\" b=\"2\" c=\"3\" d=\"{i}\"/>\n", i % 7))
        .collect();
    COUPLER.replace("<GroupType>", &format!("{el}<GroupType>"))
}

/// `n` attributes on the coupler's `<Device>` element.
fn one_element(n: usize) -> String {
    let attrs: String = (1..n).map(|i| format!(" a{i}=\"x\"")).collect();
    COUPLER.replace(
        "<Device Physics=\"YYE\">",
        &format!("<Device Physics=\"YYE\"{attrs}>"),
    )
}

fn bench_esi(c: &mut Criterion) {
    let mut g = c.benchmark_group("esi_parse");
    g.sample_size(10);
    for n in [1_000usize, 10_000, 100_000] {
        g.throughput(Throughput::Elements(n as u64));
        let text = spread(n);
        g.bench_with_input(BenchmarkId::new("spread", n), &text, |b, t| {
            b.iter(|| black_box(esi::parse(t, "b.xml").unwrap().devices.len()))
        });
        let text = one_element(n);
        g.bench_with_input(BenchmarkId::new("one_element", n), &text, |b, t| {
            b.iter(|| black_box(esi::parse(t, "b.xml").is_err()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench_esi);
criterion_main!(benches);
