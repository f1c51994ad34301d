#![allow(missing_docs)]
//! NC parse cost per block (issue 15: ~1 KB per block before, 1e6 blocks → 1.2 GB; the block
//! count is capped at `limits::MAX_NC_BLOCKS`). Criterion times the parse of 1k / 10k / 100k
//! typical blocks (throughput per block, so linear growth shows as a flat rate); before the
//! timing, the resident memory held by a parsed 200k-block program is printed per block
//! (`/proc/self/statm`, Linux; the source text is excluded).

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fieldprobe::nc::parser::parse;

/// `n` blocks in the style of the seed examples: motion words, a measurement, a message.
fn program(n: usize) -> String {
    let mut s = String::from("%bench\n");
    for i in 0..n {
        let line = match i % 4 {
            0 => format!("N{i} G01 X{}.5 Y-20 Z3 F1000\n", i % 100),
            1 => format!("N{i} G100 Z[V.A.ABS.Z - 5] F500\n"),
            2 => format!("N{i} #MSG SYN[\"Z=%f\", V.A.MESS.Z]\n"),
            _ => format!("N{i} P1 = P1 + 0.25\n"),
        };
        s.push_str(&line);
    }
    s
}

/// Resident set size in bytes (Linux), `None` elsewhere.
fn rss() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

fn report_memory() {
    const N: usize = 200_000;
    let src = program(N);
    let before = rss();
    let p = parse(&src).unwrap();
    let after = rss();
    if let (Some(b), Some(a)) = (before, after) {
        eprintln!(
            "nc_parse memory: {N} blocks, {:.0} bytes per parsed block held ({} source bytes per block)",
            a.saturating_sub(b) as f64 / N as f64,
            src.len() / N
        );
    }
    black_box(p);
}

fn bench_nc_parse(c: &mut Criterion) {
    report_memory();
    let mut g = c.benchmark_group("nc_parse");
    g.sample_size(10);
    for n in [1_000usize, 10_000, 100_000] {
        let src = program(n);
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::from_parameter(n), &src, |b, src| {
            b.iter(|| black_box(parse(src).unwrap().blocks.len()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench_nc_parse);
criterion_main!(benches);
