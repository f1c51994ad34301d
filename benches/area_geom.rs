#![allow(missing_docs)]
//! Cost of the path check for one line block against 20 active polygon areas of 20 edges each
//! (issue 7, target median ≤ 2 µs), beside a straightforward baseline with the `geo` crate's
//! `Intersects` of a `Line` with a `Polygon` on the same data (which ignores the tolerance band
//! and the excursion range, so it does less work than the real check).
//!
//! Scenarios:
//! - `sparse`: 20 protection areas on a 5 × 4 grid, the 5 mm block passes between two of them.
//! - `dense`: 20 nested protection areas around one centre whose bounding boxes all contain the
//!   block (every area passes the box pre-filter), the block misses all of them.
//! - `dense_workspaces`: the same 20 polygons as a workspace union with the block inside it.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use fieldprobe::core::monitor::area_geom::{
    path_allowed, Area, AreaShape, Line, PathElement, Polygon,
};
use geo::Intersects;

const TOL: f64 = 1e-4;

/// 20-vertex star around `c`, radii alternating `r` and `0.8 r`.
fn star(c: [f64; 2], r: f64, phase: f64) -> Vec<[f64; 2]> {
    (0..20)
        .map(|k| {
            let a = phase + k as f64 * std::f64::consts::TAU / 20.0;
            let rr = if k % 2 == 0 { r } else { 0.8 * r };
            [c[0] + rr * a.cos(), c[1] + rr * a.sin()]
        })
        .collect()
}

fn areas(polys: &[Vec<[f64; 2]>]) -> Vec<Area> {
    polys
        .iter()
        .map(|v| Area::new(AreaShape::Polygon(Polygon::new(v).unwrap()), -100.0, 100.0).unwrap())
        .collect()
}

fn geo_polys(polys: &[Vec<[f64; 2]>]) -> Vec<geo::Polygon<f64>> {
    polys
        .iter()
        .map(|v| {
            let ring: Vec<geo::Coord<f64>> =
                v.iter().map(|p| geo::coord! {x: p[0], y: p[1]}).collect();
            geo::Polygon::new(geo::LineString::from(ring), vec![])
        })
        .collect()
}

fn bench_area_geom(c: &mut Criterion) {
    let sparse: Vec<Vec<[f64; 2]>> = (0..20)
        .map(|i| {
            star(
                [(i % 5) as f64 * 25.0, (i / 5) as f64 * 25.0],
                10.0,
                0.1 * i as f64,
            )
        })
        .collect();
    let dense: Vec<Vec<[f64; 2]>> = (0..20)
        .map(|i| star([0.0, 0.0], 10.0 + i as f64, 0.05 * i as f64))
        .collect();
    // Between grid cells (x = 12.5 is 2.5 mm from the nearest star tip), 5 mm long.
    let sparse_line = Line {
        from: [12.5, 10.0, 0.0],
        to: [12.5, 15.0, 0.0],
    };
    // In the corner of every bounding box, outside every star (|p| > 29).
    let dense_line = Line {
        from: [-27.0, -27.0, 0.0],
        to: [-22.0, -27.0, 0.0],
    };
    // Inside every star.
    let inner_line = Line {
        from: [-2.5, 0.0, 0.0],
        to: [2.5, 0.0, 0.0],
    };

    let sparse_a = areas(&sparse);
    let dense_a = areas(&dense);
    assert!(path_allowed(&sparse_line.into(), &[], &sparse_a, TOL).is_ok());
    assert!(path_allowed(&dense_line.into(), &[], &dense_a, TOL).is_ok());
    assert!(path_allowed(&inner_line.into(), &dense_a, &[], TOL).is_ok());
    let sparse_g = geo_polys(&sparse);
    let dense_g = geo_polys(&dense);
    let gl = |l: &Line| {
        geo::Line::new(
            geo::coord! {x: l.from[0], y: l.from[1]},
            geo::coord! {x: l.to[0], y: l.to[1]},
        )
    };

    let mut g = c.benchmark_group("area_check_line_20x20");
    for (name, line, ws, prot, gpolys) in [
        ("sparse", sparse_line, &[][..], &sparse_a[..], &sparse_g),
        ("dense", dense_line, &[][..], &dense_a[..], &dense_g),
        (
            "dense_workspaces",
            inner_line,
            &dense_a[..],
            &[][..],
            &dense_g,
        ),
    ] {
        let path = PathElement::Line(line);
        g.bench_function(format!("{name}/area_geom"), |b| {
            b.iter(|| path_allowed(black_box(&path), black_box(ws), black_box(prot), TOL))
        });
        let l = gl(&line);
        g.bench_function(format!("{name}/geo_intersects_baseline"), |b| {
            b.iter(|| {
                black_box(gpolys)
                    .iter()
                    .filter(|p| black_box(&l).intersects(*p))
                    .count()
            })
        });
    }
    g.finish();
}

/// The same sparse scenario through the channel's `AreaMonitor` (20 protection areas of 20
/// edges bound to channel axes X/Y/Z, the block as a channel `Segment`): what block preparation
/// pays per block. The areas are built as values: an NC definition allows at most 20 G01 blocks
/// including the starting point, i.e. 19 edges (docs/interpretations.md A2).
fn bench_area_monitor(c: &mut Criterion) {
    use fieldprobe::core::monitor::area_monitor::{AreaMonitor, ChannelAxes};
    use fieldprobe::core::monitor::areas::{
        Area as TableArea, AreaAxes, AreaGeometry, AreaHeader, AreaKind, AreaShape as Shape,
        MonitorLevel,
    };
    use fieldprobe::core::path::Segment;
    let defined: Vec<TableArea> = (0..20u32)
        .map(|i| TableArea {
            header: AreaHeader {
                id: i + 1,
                kind: AreaKind::Prot,
                shape: Shape::Poly,
                min_excur: -100.0,
                max_excur: 100.0,
                excur_axis: None,
                monitor_level: MonitorLevel::Mcs,
            },
            axes: AreaAxes::Main,
            plane: Default::default(),
            geometry: AreaGeometry::Polygon {
                vertices: star(
                    [(i % 5) as f64 * 25.0, (i / 5) as f64 * 25.0],
                    10.0,
                    0.1 * f64::from(i),
                ),
            },
            defined_at: None,
        })
        .collect();
    let axes = ChannelAxes::new(vec!["X".into(), "Y".into(), "Z".into()]);
    let monitor = AreaMonitor::from_areas(&defined, &axes).unwrap();
    let seg = Segment::line(vec![12.5, 10.0, 0.0], vec![12.5, 15.0, 0.0]).unwrap();
    assert!(monitor.check_segment(&seg).is_ok());
    c.bench_function("area_monitor_block_20x20/sparse", |b| {
        b.iter(|| black_box(&monitor).check_segment(black_box(&seg)))
    });
}

criterion_group!(benches, bench_area_geom, bench_area_monitor);
criterion_main!(benches);
