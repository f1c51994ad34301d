//! Pictures of the CLI (`areas plot --out`, `run --trace`): SVG or PNG chosen by the file's
//! extension, and text that needs no font on the machine.
//!
//! SVG text is real `<text>` (the viewer's sans-serif font). The PNG (plotters bitmap backend)
//! needs no font at all: plotters is built without its `ttf` / `ab_glyph` features (those need
//! system fonts or a bundled font), so every label and tick number of a PNG is drawn with a
//! small built-in 5×7 pixel font, upper case ([`label`] with [`Labels::Pixel`]). A picture
//! therefore draws its text only through [`label`] and its axes through [`frame_with_ticks`],
//! never through plotters' captions, axis descriptions or series labels.

use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// A picture format, by file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Format {
    /// `.svg`
    Svg,
    /// `.png`
    Png,
}

impl Format {
    /// The format of `path` by its extension (any case); an error text naming the file and the
    /// allowed extensions otherwise.
    pub(super) fn of(path: &Path) -> Result<Format, String> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("svg") => Ok(Format::Svg),
            Some("png") => Ok(Format::Png),
            _ => Err(format!(
                "{}: unknown picture format, allowed extensions: .svg, .png",
                path.display()
            )),
        }
    }
}

/// Something the CLI draws into an SVG or PNG file.
pub(super) trait Picture {
    /// Draw onto `root` (the whole picture); text only through [`label`] with `mode`.
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        mode: Labels,
    ) -> anyhow::Result<()>
    where
        DB::ErrorType: 'static;
}

/// Write `picture` into `path` as `format`, `size` pixels.
pub(super) fn write_picture(
    picture: &impl Picture,
    path: &Path,
    format: Format,
    size: (u32, u32),
) -> anyhow::Result<()> {
    match format {
        Format::Svg => {
            let root = SVGBackend::new(path, size).into_drawing_area();
            picture.draw(&root, Labels::Font)?;
            root.present()?;
        }
        Format::Png => {
            let root = BitMapBackend::new(path, size).into_drawing_area();
            picture.draw(&root, Labels::Pixel)?;
            root.present()?;
        }
    }
    Ok(())
}

/// Pixel corners of a chart's plot area: `(x0, y0)` bottom left, `(x1, y1)` top right.
#[derive(Debug, Clone, Copy)]
pub(super) struct Frame {
    pub(super) x0: i32,
    pub(super) y0: i32,
    pub(super) x1: i32,
    pub(super) y1: i32,
}

/// The black frame of a chart over `xr` × `yr` (pixel positions from `coord`, the chart's
/// coordinate spec, in the coordinates of `root`) with about `ticks` tick marks and labels per
/// axis, drawn with `mode`. Returns the frame's corners.
pub(super) fn frame_with_ticks<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    coord: &impl CoordTranslate<From = (f64, f64)>,
    xr: Range<f64>,
    yr: Range<f64>,
    ticks: (usize, usize),
    mode: Labels,
) -> anyhow::Result<Frame>
where
    DB::ErrorType: 'static,
{
    let px = |x: f64, y: f64| coord.translate(&(x, y));
    let (x0, y0) = px(xr.start, yr.start);
    let (x1, y1) = px(xr.end, yr.end);
    root.draw(&Rectangle::new([(x0, y1), (x1, y0)], BLACK.stroke_width(1)))?;
    let tick = 13;
    for x in plotters::coord::types::RangedCoordf64::from(xr.clone()).key_points(ticks.0) {
        let t = tick_text(x);
        let (cx, _) = px(x, yr.start);
        root.draw(&PathElement::new([(cx, y0), (cx, y0 + 5)], BLACK))?;
        label(
            root,
            mode,
            (cx - text_width(mode, &t, tick) / 2, y0 + 8),
            &t,
            tick,
            BLACK,
        )?;
    }
    for y in plotters::coord::types::RangedCoordf64::from(yr.clone()).key_points(ticks.1) {
        let t = tick_text(y);
        let (_, cy) = px(xr.start, y);
        root.draw(&PathElement::new([(x0 - 5, cy), (x0, cy)], BLACK))?;
        label(
            root,
            mode,
            (x0 - 8 - text_width(mode, &t, tick), cy - 7),
            &t,
            tick,
            BLACK,
        )?;
    }
    Ok(Frame { x0, y0, x1, y1 })
}

/// How text is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Labels {
    /// Through plotters' font (SVG `<text>`).
    Font,
    /// The built-in pixel font (bitmap output without a font engine).
    Pixel,
}

/// Text with its top-left corner at pixel `pos`; `size` is the font height in pixels.
pub(super) fn label<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    mode: Labels,
    pos: (i32, i32),
    text: &str,
    size: u32,
    color: RGBColor,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    match mode {
        Labels::Font => {
            let style = ("sans-serif", size).into_font().color(&color);
            root.draw(&Text::new(text.to_string(), pos, style))?;
        }
        Labels::Pixel => {
            // 5×7 glyphs and one column of spacing, scaled by a whole factor to about `size`.
            let s = (size as i32 / 7).max(1);
            let mut x = pos.0;
            for c in text.chars() {
                let rows = glyph(c.to_ascii_uppercase());
                for (r, bits) in rows.iter().enumerate() {
                    for col in 0..5 {
                        if bits & (0x10 >> col) != 0 {
                            let px = x + col * s;
                            let py = pos.1 + r as i32 * s;
                            root.draw(&Rectangle::new(
                                [(px, py), (px + s, py + s)],
                                color.filled(),
                            ))?;
                        }
                    }
                }
                x += 6 * s;
            }
        }
    }
    Ok(())
}

/// Width of `text` in pixels (estimate for the font, exact for the pixel font).
pub(super) fn text_width(mode: Labels, text: &str, size: u32) -> i32 {
    let n = text.chars().count() as i32;
    match mode {
        Labels::Font => (f64::from(size) * 0.55 * f64::from(n)) as i32,
        Labels::Pixel => 6 * (size as i32 / 7).max(1) * n,
    }
}

/// 5×7 pixel font: rows top to bottom, bit 4 = left column.
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        ' ' => [0; 7],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '-' | '−' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04],
    }
}

/// Tick label: integers without decimals, else up to 3 decimals.
fn tick_text(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("{}", v.round() as i64)
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}
