//! `--trace FILE.svg`: position and velocity per axis over time, probe edges and latched values
//! marked — what a commissioning engineer looks at to see where and when the probe switched.

use fieldprobe::machine::Trace;
use plotters::prelude::*;
use std::path::Path;

/// Render `trace` to an SVG file: per moving axis one row with position (command dashed grey,
/// actual blue) and velocity (command, from the set-points); probe edges as vertical red lines,
/// latched values as black circles with their value.
pub fn write_svg(trace: &Trace, path: &Path) -> anyhow::Result<()> {
    let moving: Vec<usize> = (0..trace.axes.len())
        .filter(|&i| {
            let c = &trace.command[i];
            let (lo, hi) = c
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            hi - lo > 1e-9 || trace.latches.iter().any(|l| l.1 == i)
        })
        .collect();
    let rows = moving.len().max(1);
    let root = SVGBackend::new(path, (1200, 320 * rows as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let t_end = trace.t.last().copied().unwrap_or(1.0).max(1e-3);
    let panels = root.split_evenly((rows, 2));
    for (row, &i) in moving.iter().enumerate() {
        let name = &trace.axes[i];
        let cmd = &trace.command[i];
        let act = &trace.actual[i];
        let (lo, hi) = cmd
            .iter()
            .chain(act)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let pad = ((hi - lo) * 0.05).max(0.1);
        let mut pos = ChartBuilder::on(&panels[row * 2])
            .caption(format!("{name} position [mm]"), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))?;
        pos.configure_mesh().x_desc("t [s]").draw()?;
        pos.draw_series(LineSeries::new(
            trace.t.iter().copied().zip(cmd.iter().copied()),
            &RGBColor(150, 150, 150),
        ))?
        .label("command")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], RGBColor(150, 150, 150)));
        pos.draw_series(LineSeries::new(
            trace.t.iter().copied().zip(act.iter().copied()),
            &BLUE,
        ))?
        .label("actual")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], BLUE));
        for &(t, rising) in &trace.edges {
            let style = if rising { RED } else { RGBColor(255, 170, 170) };
            pos.draw_series(LineSeries::new([(t, lo - pad), (t, hi + pad)], &style))?;
        }
        for &(t, _, p) in trace.latches.iter().filter(|l| l.1 == i) {
            pos.draw_series(PointSeries::of_element([(t, p)], 5, &BLACK, &|c, s, st| {
                EmptyElement::at(c)
                    + Circle::new((0, 0), s, st)
                    + Text::new(format!("{p:.6}"), (8, -12), ("sans-serif", 14))
            }))?;
        }
        pos.configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        // Velocity of the command set-points.
        let vel: Vec<(f64, f64)> = trace
            .t
            .windows(2)
            .zip(cmd.windows(2))
            .map(|(t, c)| (t[1], (c[1] - c[0]) / (t[1] - t[0]).max(1e-12)))
            .collect();
        let (vlo, vhi) = vel
            .iter()
            .fold((0.0f64, 0.0f64), |(a, b), &(_, v)| (a.min(v), b.max(v)));
        let vpad = ((vhi - vlo) * 0.05).max(0.1);
        let mut v = ChartBuilder::on(&panels[row * 2 + 1])
            .caption(format!("{name} velocity [mm/s]"), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, (vlo - vpad)..(vhi + vpad))?;
        v.configure_mesh().x_desc("t [s]").draw()?;
        v.draw_series(LineSeries::new(vel, &GREEN))?;
        for &(t, rising) in trace.edges.iter().filter(|e| e.1) {
            let _ = rising;
            v.draw_series(LineSeries::new([(t, vlo - vpad), (t, vhi + vpad)], &RED))?;
        }
    }
    root.present()?;
    Ok(())
}
