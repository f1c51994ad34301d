//! `fieldprobe areas plot PROGRAM.nc --out FILE.svg|FILE.png`: draw the workspace and protection
//! areas an NC program defines (FCT-C14 §3), the path it executed, and the first violation.
//!
//! The program runs on the emulated `sim` link (virtual time, as `fieldprobe run --link sim`)
//! with path recording on; the picture shows the state at the end of the run (program end or
//! abort), in one plane (`--plane`, default the plane of the first defined area, else X,Y),
//! with equal scales on both axes so circles stay round:
//!
//! - **workspaces** (`WORK`): green outline, light green fill, label `ID n WORK`;
//! - **protection areas** (`PROT`): red outline, light red fill, red 45° hatching, label
//!   `ID n PROT`;
//! - **inactive** areas (defined, not `ON`): dashed, paler outline and fill, no hatching, label
//!   suffix `(inactive)`;
//! - the **executed path**: blue polyline, each block's path (lines, arcs, helices) sampled every
//!   0.5 mm (at least 16, at most 2000 points per block);
//! - the **refused block** (the block the path check of block preparation did not execute):
//!   dashed orange;
//! - the **first violation**: black cross where the refused path starts to violate, labelled
//!   `block N230: enters protection area 4` / `leaves workspace 3` / `starts outside the
//!   workspaces`.
//!
//! Areas of other planes (e.g. additional axes X2/Y2 when plotting X,Y) are not drawn; a note on
//! stderr says so.
//!
//! SVG text is real `<text>` (the viewer's sans-serif font); the PNG draws its labels and tick
//! numbers with the built-in pixel font of [`super::plot`], so it works on a machine without any
//! font installed.
//!
//! Messages as `fieldprobe run`: `#MSG` lines on stdout, `warning|error <ID>: <text> (N<block>)`
//! on stderr. Exit code 0 program ended, 1 aborted by a CNC error (the picture is still
//! written), 2 bad input (unreadable file, parse error as `file:line:col: …`, unknown `--out`
//! extension).

use super::plot::{frame_with_ticks, label, text_width, write_picture, Format, Labels, Picture};
use super::{load_machine, load_program, EXIT_BAD_INPUT, EXIT_CNC_ERROR, EXIT_OK};
use anyhow::Context;
use fieldprobe::channel::areas::AreaRefusal;
use fieldprobe::core::monitor::area_monitor::HitKind;
use fieldprobe::core::monitor::areas::{AreaGeometry, AreaKind, AreaState};
use fieldprobe::core::path::Segment;
use fieldprobe::machine::{LinkChoice, Machine, RunEvent, RunStatus};
use fieldprobe::nc::exec::Executor;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use std::path::PathBuf;

/// Arguments of `fieldprobe areas`.
#[derive(Debug, clap::Args)]
pub struct AreasArgs {
    #[command(subcommand)]
    command: AreasCommand,
}

#[derive(Debug, clap::Subcommand)]
enum AreasCommand {
    /// Run a program on the emulated machine and draw its workspace / protection areas, the
    /// executed path and the first violation into an SVG or PNG file.
    Plot(PlotArgs),
}

/// Arguments of `fieldprobe areas plot`.
#[derive(Debug, clap::Args)]
pub struct PlotArgs {
    /// The NC program.
    program: PathBuf,
    /// The picture: `FILE.svg` or `FILE.png`.
    #[arg(long, value_name = "FILE.svg|FILE.png")]
    out: PathBuf,
    /// Machine file (TOML); default: axes X, Y, Z.
    #[arg(long)]
    machine: Option<PathBuf>,
    /// Parameter assignment in seed units, e.g. `P-CHAN-00498=1`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// The two channel axes of the picture, e.g. `X,Y`; default: the plane of the first
    /// defined area, else X,Y.
    #[arg(long, value_name = "AXIS,AXIS")]
    plane: Option<String>,
}

/// Run `fieldprobe areas …`; returns the exit code.
pub fn run(a: AreasArgs) -> anyhow::Result<i32> {
    match a.command {
        AreasCommand::Plot(p) => plot(p),
    }
}

/// Picture size in pixels.
const SIZE: (u32, u32) = (1000, 800);

fn plot(a: PlotArgs) -> anyhow::Result<i32> {
    let format = match Format::of(&a.out) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("fieldprobe: --out {e}");
            return Ok(EXIT_BAD_INPUT);
        }
    };
    let file = a.program.display().to_string();
    let Some(program) = load_program(&a.program)? else {
        return Ok(EXIT_BAD_INPUT);
    };
    let cfg = load_machine(a.machine.as_deref(), &a.sets)?;
    let mut machine = Machine::with_link(&cfg, &LinkChoice::new("sim"))?;
    let names: Vec<String> = machine
        .channel()
        .axes()
        .iter()
        .map(|x| x.name().to_string())
        .collect();
    if let Err((span, msg)) = Executor::new(program.clone(), names.clone()).validate() {
        eprintln!("{file}:{}:{}: {msg}", span.line, span.col);
        return Ok(EXIT_BAD_INPUT);
    }
    // The plane given on the command line is checked before the run.
    let given_plane = match &a.plane {
        Some(p) => match parse_plane(p, &names) {
            Ok(pl) => Some(pl),
            Err(e) => {
                eprintln!("fieldprobe: --plane {p}: {e}");
                return Ok(EXIT_BAD_INPUT);
            }
        },
        None => None,
    };
    machine.channel_mut().record_paths();
    let report = machine.run_program(&program, &mut |e| match e {
        RunEvent::Output(line) => outln!("{line}"),
        RunEvent::Message(m) => eprintln!("{m}"),
    });
    let plane = given_plane.unwrap_or_else(|| default_plane(&machine, &names));
    let scene = Scene::collect(&machine, plane, &names);
    write_picture(&scene, &a.out, format, SIZE)
        .with_context(|| format!("--out {}", a.out.display()))?;
    Ok(match report.status {
        RunStatus::Completed => EXIT_OK,
        RunStatus::Aborted => EXIT_CNC_ERROR,
    })
}

/// `X,Y` → channel axis indices.
fn parse_plane(s: &str, names: &[String]) -> Result<[usize; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 2 {
        return Err("expected two axis names, e.g. X,Y".into());
    }
    let find = |n: &str| {
        names
            .iter()
            .position(|x| x.eq_ignore_ascii_case(n))
            .ok_or_else(|| format!("no channel axis {n}; the channel has {}", names.join(", ")))
    };
    let p = [find(parts[0])?, find(parts[1])?];
    if p[0] == p[1] {
        return Err("the two axes must differ".into());
    }
    Ok(p)
}

/// The plane of the first defined area, else X,Y, else the first two axes.
fn default_plane(m: &Machine, names: &[String]) -> [usize; 2] {
    let ch = m.channel();
    if let Some([p, q, _]) = ch
        .areas()
        .areas()
        .find_map(|a| ch.area_axes().resolve(a).ok())
    {
        return [p, q];
    }
    parse_plane("X,Y", names).unwrap_or([0, 1.min(names.len().saturating_sub(1))])
}

/// One area as drawn.
struct AreaShape {
    label: String,
    prot: bool,
    active: bool,
    /// Closed outline in plane coordinates (circles as 256-gons).
    outline: Vec<(f64, f64)>,
}

/// Everything the picture shows, in plane coordinates.
struct Scene {
    axes: [String; 2],
    areas: Vec<AreaShape>,
    /// Executed path, as connected polylines.
    path: Vec<Vec<(f64, f64)>>,
    refused: Option<Vec<(f64, f64)>>,
    /// Violation point and its label.
    violation: Option<((f64, f64), String)>,
}

/// Points along a segment, projected into the plane.
fn sample(seg: &Segment, plane: [usize; 2]) -> Vec<(f64, f64)> {
    let len = seg.length();
    let n = if len.is_finite() {
        ((len / 0.5).ceil() as usize).clamp(16, 2000)
    } else {
        1
    };
    let mut buf = vec![0.0; seg.dims()];
    (0..=n)
        .map(|i| {
            seg.point_at(len * i as f64 / n as f64, &mut buf);
            (
                buf.get(plane[0]).copied().unwrap_or(0.0),
                buf.get(plane[1]).copied().unwrap_or(0.0),
            )
        })
        .collect()
}

/// Map `[a, b]` of the axes `[ia, ib]` into the plane (swapped if the plane is `[ib, ia]`).
fn to_plane(p: [f64; 2], axes: [usize; 2], plane: [usize; 2]) -> Option<(f64, f64)> {
    if axes == plane {
        Some((p[0], p[1]))
    } else if [axes[1], axes[0]] == plane {
        Some((p[1], p[0]))
    } else {
        None
    }
}

fn violation_text(r: &AreaRefusal) -> String {
    let what = match (r.hit.kind, r.hit.id) {
        (HitKind::Protection, Some(id)) => format!("enters protection area {id}"),
        (HitKind::Workspace, Some(id)) => format!("leaves workspace {id}"),
        (HitKind::Workspace, None) => "starts outside the workspaces".to_string(),
        _ => "cannot be checked (not finite)".to_string(),
    };
    match r.block {
        Some(b) => format!("block {b}: {what}"),
        None => what,
    }
}

impl Scene {
    fn collect(m: &Machine, plane: [usize; 2], names: &[String]) -> Scene {
        let ch = m.channel();
        let table = ch.areas();
        let name = |i: usize| names.get(i).cloned().unwrap_or_else(|| "?".into());
        let mut areas = Vec::new();
        for area in table.areas() {
            let id = area.id();
            let resolved = ch.area_axes().resolve(area).ok();
            let map = |p: [f64; 2]| resolved.and_then(|[a, b, _]| to_plane(p, [a, b], plane));
            let outline: Option<Vec<(f64, f64)>> = match &area.geometry {
                AreaGeometry::Polygon { vertices } => vertices.iter().map(|v| map(*v)).collect(),
                AreaGeometry::Circle { centre, radius } => (0..256)
                    .map(|k| {
                        let t = std::f64::consts::TAU * k as f64 / 256.0;
                        map([centre[0] + radius * t.cos(), centre[1] + radius * t.sin()])
                    })
                    .collect(),
            };
            let Some(outline) = outline else {
                let on = match resolved {
                    Some([a, b, _]) => format!("the plane {},{}", name(a), name(b)),
                    None => "no channel axes".to_string(),
                };
                eprintln!(
                    "fieldprobe: area {id} lies in {on}, not in {},{}: not drawn",
                    name(plane[0]),
                    name(plane[1])
                );
                continue;
            };
            let prot = area.kind() == AreaKind::Prot;
            let active = table.state(id) == AreaState::Active;
            let mut label = format!("ID {id} {}", if prot { "PROT" } else { "WORK" });
            if !active {
                label.push_str(" (inactive)");
            }
            areas.push(AreaShape {
                label,
                prot,
                active,
                outline,
            });
        }
        let mut path: Vec<Vec<(f64, f64)>> = Vec::new();
        for (_, seg) in ch.path_log().unwrap_or(&[]) {
            let pts = sample(seg, plane);
            match path.last_mut() {
                Some(last)
                    if last
                        .last()
                        .zip(pts.first())
                        .is_some_and(|(a, b)| (a.0 - b.0).hypot(a.1 - b.1) < 1e-6) =>
                {
                    last.extend_from_slice(&pts[1..]);
                }
                _ => path.push(pts),
            }
        }
        let refusal = ch.area_refusal();
        let refused = refusal.map(|r| sample(&r.segment, plane));
        let violation = refusal.and_then(|r| {
            let h = &r.hit;
            let p = to_plane([h.point[0], h.point[1]], [h.axes[0], h.axes[1]], plane).or_else(
                || {
                    // A violation in another plane: mark where the refused path starts.
                    let mut buf = vec![0.0; r.segment.dims()];
                    r.segment.point_at(0.0, &mut buf);
                    Some((*buf.get(plane[0])?, *buf.get(plane[1])?))
                },
            )?;
            Some((p, violation_text(r)))
        });
        Scene {
            axes: [name(plane[0]), name(plane[1])],
            areas,
            path,
            refused,
            violation,
        }
    }

    /// Data ranges with some margin, widened so both axes get the same scale in a plot area of
    /// `w`×`h` pixels.
    fn ranges(&self, w: f64, h: f64) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
        let pts = self
            .areas
            .iter()
            .flat_map(|a| a.outline.iter())
            .chain(self.path.iter().flatten())
            .chain(self.refused.iter().flatten())
            .chain(self.violation.iter().map(|v| &v.0))
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for p in pts {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
        }
        let span = (x1 - x0).max(y1 - y0).max(1.0);
        let pad = span * 0.08;
        let (mut x0, mut x1, mut y0, mut y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);
        // Equal scale: mm per pixel the same on both axes.
        let sx = (x1 - x0) / w;
        let sy = (y1 - y0) / h;
        if sx > sy {
            let grow = (sx * h - (y1 - y0)) / 2.0;
            y0 -= grow;
            y1 += grow;
        } else {
            let grow = (sy * w - (x1 - x0)) / 2.0;
            x0 -= grow;
            x1 += grow;
        }
        (x0..x1, y0..y1)
    }
}

/// 45° hatching inside the closed polygon `poly` (even-odd rule): segments on the lines
/// `x + y = c`, `c` every `step`.
fn hatch(poly: &[(f64, f64)], step: f64) -> Vec<[(f64, f64); 2]> {
    let u = |p: &(f64, f64)| p.0 + p.1;
    let (lo, hi) = poly
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(u(p)), b.max(u(p)))
        });
    let mut out = Vec::new();
    if !(lo.is_finite() && hi.is_finite() && step > 0.0) {
        return out;
    }
    let mut c = (lo / step).ceil() * step;
    while c <= hi {
        // Crossings of the line with the edges, ordered along v = x − y.
        let mut xs: Vec<(f64, f64)> = Vec::new();
        for k in 0..poly.len() {
            let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
            let (ua, ub) = (u(&a), u(&b));
            if (ua <= c && c < ub) || (ub <= c && c < ua) {
                let t = (c - ua) / (ub - ua);
                xs.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
            }
        }
        xs.sort_by(|p, q| (p.0 - p.1).total_cmp(&(q.0 - q.1)));
        for pair in xs.chunks_exact(2) {
            out.push([pair[0], pair[1]]);
        }
        c += step;
    }
    out
}

const WORK_GREEN: RGBColor = RGBColor(0, 140, 60);
const PROT_RED: RGBColor = RGBColor(210, 30, 30);
const PATH_BLUE: RGBColor = RGBColor(20, 70, 220);
const REFUSED_ORANGE: RGBColor = RGBColor(240, 130, 0);

impl Picture for Scene {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        mode: Labels,
    ) -> anyhow::Result<()>
    where
        DB::ErrorType: 'static,
    {
        draw(root, self, mode)
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    scene: &Scene,
    mode: Labels,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (w, h) = root.dim_in_pixel();
    // Plot area: left margin for the Y tick labels, bottom for the X ones, top for the title.
    let (left, right, top, bottom) = (70u32, 20u32, 50u32, 50u32);
    let inner = root.margin(top, bottom, left, right);
    let (pw, ph) = (w - left - right, h - top - bottom);
    let (xr, yr) = scene.ranges(f64::from(pw), f64::from(ph));
    let mut chart = ChartBuilder::on(&inner).build_cartesian_2d(xr.clone(), yr.clone())?;
    chart
        .configure_mesh()
        .x_labels(10)
        .y_labels(10)
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    // Frame and tick labels (drawn here so that the PNG needs no font engine).
    let coord = chart.as_coord_spec().clone();
    let px = |x: f64, y: f64| coord.translate(&(x, y));
    let f = frame_with_ticks(root, &coord, xr.clone(), yr.clone(), (10, 10), mode)?;
    let (x0, y0, x1, y1) = (f.x0, f.y0, f.x1, f.y1);
    let xdesc = format!("{} [mm]", scene.axes[0]);
    let xdesc_at = (x1 - text_width(mode, &xdesc, 15), y0 + 28);
    label(root, mode, xdesc_at, &xdesc, 15, BLACK)?;
    label(
        root,
        mode,
        (8, y1 - 18),
        &format!("{} [mm]", scene.axes[1]),
        15,
        BLACK,
    )?;
    label(
        root,
        mode,
        (x0, 12),
        &format!(
            "Control areas in the {}{} plane",
            scene.axes[0], scene.axes[1]
        ),
        20,
        BLACK,
    )?;

    // Areas: fills first (workspaces under protection areas), then outlines and hatching.
    let order = |prot: bool| scene.areas.iter().filter(move |a| a.prot == prot);
    for a in order(false).chain(order(true)) {
        let base = if a.prot { PROT_RED } else { WORK_GREEN };
        let alpha = match (a.prot, a.active) {
            (false, true) => 0.18,
            (true, true) => 0.22,
            (_, false) => 0.07,
        };
        chart.draw_series(std::iter::once(Polygon::new(
            a.outline.clone(),
            base.mix(alpha).filled(),
        )))?;
    }
    let step = (xr.end - xr.start) / 90.0;
    for a in order(false).chain(order(true)) {
        let base = if a.prot { PROT_RED } else { WORK_GREEN };
        let mut closed = a.outline.clone();
        closed.extend(a.outline.first().copied());
        if a.active {
            if a.prot {
                chart.draw_series(
                    hatch(&a.outline, step)
                        .into_iter()
                        .map(|s| PathElement::new(s.to_vec(), base.mix(0.6).stroke_width(1))),
                )?;
            }
            chart.draw_series(std::iter::once(PathElement::new(
                closed,
                base.stroke_width(2),
            )))?;
        } else {
            chart.draw_series(DashedLineSeries::new(
                closed,
                8,
                6,
                base.mix(0.55).stroke_width(2),
            ))?;
        }
    }
    // Path and refused block.
    for line in &scene.path {
        chart.draw_series(std::iter::once(PathElement::new(
            line.clone(),
            PATH_BLUE.stroke_width(2),
        )))?;
    }
    if let Some(r) = &scene.refused {
        chart.draw_series(DashedLineSeries::new(
            r.clone(),
            7,
            5,
            REFUSED_ORANGE.stroke_width(3),
        ))?;
    }
    // Area labels above the top-left corner of each area's bounding box.
    for a in &scene.areas {
        let (bx, by) = a
            .outline
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(x, y), p| {
                (x.min(p.0), y.max(p.1))
            });
        let (lx, ly) = px(bx, by);
        let base = if a.prot { PROT_RED } else { WORK_GREEN };
        label(root, mode, (lx + 2, ly - 18), &a.label, 15, base)?;
    }
    // The violation.
    if let Some((p, text)) = &scene.violation {
        let (vx, vy) = px(p.0, p.1);
        let d = 9;
        for s in [
            [(vx - d, vy - d), (vx + d, vy + d)],
            [(vx - d, vy + d), (vx + d, vy - d)],
        ] {
            root.draw(&PathElement::new(s.to_vec(), BLACK.stroke_width(3)))?;
        }
        let tw = text_width(mode, text, 15);
        // Right of the cross, or left if it would leave the picture.
        let lx = if vx + 14 + tw < w as i32 - 4 {
            vx + 14
        } else {
            vx - 14 - tw
        };
        root.draw(&Rectangle::new(
            [(lx - 3, vy + 8), (lx + tw + 3, vy + 28)],
            WHITE.mix(0.85).filled(),
        ))?;
        label(root, mode, (lx, vy + 11), text, 15, BLACK)?;
    }
    // Legend, bottom right inside the plot.
    let mut entries: Vec<(&str, RGBColor, bool)> = vec![
        ("workspace", WORK_GREEN, false),
        ("protection area", PROT_RED, false),
        ("executed path", PATH_BLUE, false),
    ];
    if scene.refused.is_some() {
        entries.push(("refused block", REFUSED_ORANGE, true));
    }
    if scene.violation.is_some() {
        entries.push(("first violation", BLACK, false));
    }
    let lw = 34
        + entries
            .iter()
            .map(|e| text_width(mode, e.0, 14))
            .max()
            .unwrap_or(0)
        + 8;
    let (lx, ly) = (x1 - lw - 10, y0 - 10 - 20 * entries.len() as i32);
    root.draw(&Rectangle::new(
        [(lx - 6, ly - 6), (lx + lw, y0 - 8)],
        WHITE.mix(0.85).filled(),
    ))?;
    root.draw(&Rectangle::new(
        [(lx - 6, ly - 6), (lx + lw, y0 - 8)],
        BLACK,
    ))?;
    for (k, (text, color, dashed)) in entries.iter().enumerate() {
        let y = ly + 20 * k as i32 + 6;
        if *dashed {
            root.draw(&PathElement::new(
                [(lx, y), (lx + 10, y)],
                color.stroke_width(3),
            ))?;
            root.draw(&PathElement::new(
                [(lx + 16, y), (lx + 26, y)],
                color.stroke_width(3),
            ))?;
        } else if k < 2 {
            root.draw(&Rectangle::new(
                [(lx, y - 6), (lx + 26, y + 6)],
                color.mix(0.2).filled(),
            ))?;
            root.draw(&Rectangle::new(
                [(lx, y - 6), (lx + 26, y + 6)],
                color.stroke_width(2),
            ))?;
        } else if *color == BLACK {
            root.draw(&PathElement::new(
                [(lx + 8, y - 5), (lx + 18, y + 5)],
                color.stroke_width(2),
            ))?;
            root.draw(&PathElement::new(
                [(lx + 8, y + 5), (lx + 18, y - 5)],
                color.stroke_width(2),
            ))?;
        } else {
            root.draw(&PathElement::new(
                [(lx, y), (lx + 26, y)],
                color.stroke_width(2),
            ))?;
        }
        label(root, mode, (lx + 34, y - 7), text, 14, BLACK)?;
    }
    Ok(())
}
