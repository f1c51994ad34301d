//! `--trace FILE.svg|FILE.png`: position and velocity per axis over time, probe edges and latched
//! values marked — what a commissioning engineer looks at to see where and when the probe
//! switched. The format follows the extension ([`Format::of`]); text goes through the shared
//! labels of [`super::plot`], so the PNG needs no font on the machine.

use super::plot::{frame_with_ticks, label, text_width, write_picture, Format, Labels, Picture};
use fieldprobe::machine::Trace;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// Width of the picture and height of one axis row, in pixels.
const WIDTH: u32 = 1200;
const ROW_HEIGHT: u32 = 320;

const COMMAND_GREY: RGBColor = RGBColor(150, 150, 150);
const EDGE_FALLING: RGBColor = RGBColor(255, 170, 170);
const VELOCITY_GREEN: RGBColor = RGBColor(0, 150, 60);

/// Render `trace` into `path` as `format`: per axis that moved or measured one row with position
/// (command grey, actual blue) and velocity (command, from the set-points); probe edges as
/// vertical red lines (falling ones pale), latched values as black circles with their value.
pub fn write(trace: &Trace, path: &Path, format: Format) -> anyhow::Result<()> {
    let rows = TracePicture::rows(trace).len().max(1) as u32;
    write_picture(
        &TracePicture { trace },
        path,
        format,
        (WIDTH, ROW_HEIGHT * rows),
    )
}

struct TracePicture<'a> {
    trace: &'a Trace,
}

/// Smallest and largest finite value.
fn extent<'a>(values: impl IntoIterator<Item = &'a f64>) -> (f64, f64) {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// `lo..hi` with 5 % (at least 0.1) room on both sides; `-1..1` when empty.
fn padded(lo: f64, hi: f64) -> Range<f64> {
    if !(lo.is_finite() && hi.is_finite()) {
        return -1.0..1.0;
    }
    let pad = ((hi - lo) * 0.05).max(0.1);
    (lo - pad)..(hi + pad)
}

impl TracePicture<'_> {
    /// The axes drawn: those whose command moved or that have a latch.
    fn rows(trace: &Trace) -> Vec<usize> {
        (0..trace.axes.len())
            .filter(|&i| {
                let (lo, hi) = extent(&trace.command[i]);
                hi - lo > 1e-9 || trace.latches.iter().any(|l| l.1 == i)
            })
            .collect()
    }

    /// One panel: caption, frame with ticks, `t [s]`; returns the chart to draw into.
    #[allow(clippy::type_complexity)]
    fn panel<'b, DB: DrawingBackend>(
        root: &DrawingArea<DB, Shift>,
        area: &'b DrawingArea<DB, Shift>,
        mode: Labels,
        caption: &str,
        xr: Range<f64>,
        yr: Range<f64>,
    ) -> anyhow::Result<ChartContext<'b, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>>
    where
        DB::ErrorType: 'static,
    {
        let (px, py) = area.get_pixel_range();
        label(
            root,
            mode,
            (px.start + 10, py.start + 8),
            caption,
            18,
            BLACK,
        )?;
        let inner = area.margin(34, 40, 75, 15);
        let mut chart = ChartBuilder::on(&inner).build_cartesian_2d(xr.clone(), yr.clone())?;
        chart
            .configure_mesh()
            .x_labels(8)
            .y_labels(6)
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(215, 215, 215))
            .draw()?;
        let f = frame_with_ticks(root, chart.as_coord_spec(), xr, yr, (8, 6), mode)?;
        let t = "t [s]";
        label(
            root,
            mode,
            (f.x1 - text_width(mode, t, 14), f.y0 + 22),
            t,
            14,
            BLACK,
        )?;
        Ok(chart)
    }
}

impl Picture for TracePicture<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        mode: Labels,
    ) -> anyhow::Result<()>
    where
        DB::ErrorType: 'static,
    {
        let trace = self.trace;
        root.fill(&WHITE)?;
        let rows = Self::rows(trace);
        let t_end = trace.t.last().copied().unwrap_or(1.0).max(1e-3);
        let panels = root.split_evenly((rows.len().max(1), 2));
        for (row, &i) in rows.iter().enumerate() {
            let name = &trace.axes[i];
            let cmd = &trace.command[i];
            let act = &trace.actual[i];
            let (lo, hi) = extent(cmd.iter().chain(act));
            let yr = padded(lo, hi);
            let mut pos = Self::panel(
                root,
                &panels[row * 2],
                mode,
                &format!("{name} position [mm]"),
                0.0..t_end,
                yr.clone(),
            )?;
            pos.draw_series(LineSeries::new(
                trace.t.iter().copied().zip(cmd.iter().copied()),
                &COMMAND_GREY,
            ))?;
            pos.draw_series(LineSeries::new(
                trace.t.iter().copied().zip(act.iter().copied()),
                &BLUE,
            ))?;
            // Falling edges first, so that a rising edge a pulse earlier stays visible on top.
            for rising in [false, true] {
                for &(t, _) in trace.edges.iter().filter(|e| e.1 == rising) {
                    let style = if rising { RED } else { EDGE_FALLING };
                    pos.draw_series(LineSeries::new([(t, yr.start), (t, yr.end)], &style))?;
                }
            }
            let coord = pos.as_coord_spec().clone();
            for &(t, _, p) in trace.latches.iter().filter(|l| l.1 == i) {
                pos.draw_series(std::iter::once(Circle::new((t, p), 5, BLACK)))?;
                let (x, y) = plotters::coord::CoordTranslate::translate(&coord, &(t, p));
                label(root, mode, (x + 8, y - 20), &format!("{p:.6}"), 14, BLACK)?;
            }
            legend(root, &panels[row * 2], mode, trace, i)?;
            // Velocity of the command set-points.
            let vel: Vec<(f64, f64)> = trace
                .t
                .windows(2)
                .zip(cmd.windows(2))
                .map(|(t, c)| (t[1], (c[1] - c[0]) / (t[1] - t[0]).max(1e-12)))
                .collect();
            let (vlo, vhi) = extent(vel.iter().map(|v| &v.1));
            let vr = padded(vlo.min(0.0), vhi.max(0.0));
            let mut v = Self::panel(
                root,
                &panels[row * 2 + 1],
                mode,
                &format!("{name} velocity [mm/s]"),
                0.0..t_end,
                vr.clone(),
            )?;
            v.draw_series(LineSeries::new(vel, &VELOCITY_GREEN))?;
            for &(t, _) in trace.edges.iter().filter(|e| e.1) {
                v.draw_series(LineSeries::new([(t, vr.start), (t, vr.end)], &RED))?;
            }
        }
        Ok(())
    }
}

/// The legend of a position panel, in one line right of the caption (above the plot, so that
/// it hides no data): command, actual, probe edge and, where the axis has one, latch.
fn legend<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    mode: Labels,
    trace: &Trace,
    axis: usize,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let mut entries = vec![("command", COMMAND_GREY), ("actual", BLUE)];
    if !trace.edges.is_empty() {
        entries.push(("probe edge", RED));
    }
    if trace.latches.iter().any(|l| l.1 == axis) {
        entries.push(("latch", BLACK));
    }
    let size = 13;
    let width = |text: &str| 30 + text_width(mode, text, size) + 14;
    let (px, py) = area.get_pixel_range();
    let mut x = px.end - 15 - entries.iter().map(|e| width(e.0)).sum::<i32>();
    let y = py.start + 14;
    for (text, color) in entries {
        if text == "latch" {
            root.draw(&Circle::new((x + 12, y), 4, color))?;
        } else {
            root.draw(&PathElement::new(
                [(x, y), (x + 24, y)],
                color.stroke_width(2),
            ))?;
        }
        label(root, mode, (x + 30, y - 6), text, size, BLACK)?;
        x += width(text);
    }
    Ok(())
}
