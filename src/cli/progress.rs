//! The progress line of `fieldprobe run` on a terminal (docs/cli.md "Progress of a long run").
//!
//! When stderr is a terminal and `--quiet` is not given, a run that lasts longer than
//! [`FIRST_DRAW`] gets one status line on stderr — the block being executed, the program time
//! and, on a link that runs on the wall clock, the interpolation cycles per second —, redrawn in
//! place (carriage return, no escape sequences) at most every [`REDRAW`], and erased at the end
//! of the run. Anything else written to the terminal during the run (`#MSG` lines, warnings,
//! `FIELDPROBE_LOG` output) erases the line first ([`clear`]); the next redraw puts it back
//! below. Nothing is drawn when stderr is a pipe or a file.

use fieldprobe::machine::RunProgress;
use std::io::Write;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// No line for a run shorter than this (wall-clock time).
pub const FIRST_DRAW: Duration = Duration::from_secs(1);
/// Shortest time between two redraws.
pub const REDRAW: Duration = Duration::from_millis(250);

/// Characters of the line now on the terminal (0: none). The lock also keeps a redraw and a
/// clear from other threads (the tracing writer) apart.
static SHOWN: Mutex<usize> = Mutex::new(0);

/// Erase the progress line, if one is shown, so that the next write to the terminal starts on
/// a clean line.
pub fn clear() {
    let mut shown = SHOWN.lock().unwrap_or_else(|p| p.into_inner());
    if *shown > 0 {
        let blank = format!("\r{}\r", " ".repeat(*shown));
        // A terminal that cannot take the line is no reason to stop the run.
        let _ = std::io::stderr().write_all(blank.as_bytes());
        *shown = 0;
    }
}

/// Draw `line` in place of the one shown.
fn draw(line: &str) {
    let mut shown = SHOWN.lock().unwrap_or_else(|p| p.into_inner());
    let width = line.chars().count();
    let pad = " ".repeat(shown.saturating_sub(width));
    let _ = std::io::stderr().write_all(format!("\r{line}{pad}").as_bytes());
    *shown = width.max(1);
}

/// The progress display of one run.
#[derive(Debug)]
pub struct Progress {
    enabled: bool,
    /// Show cycles per second (a link on the wall clock).
    rate: bool,
    next_draw: Instant,
    /// (when, cycles) at the previous draw, for the rate.
    last: Option<(Instant, u64)>,
}

impl Progress {
    /// A display that draws when `enabled`; `rate`: show the cycles per second.
    pub fn new(enabled: bool, rate: bool) -> Self {
        Progress {
            enabled,
            rate,
            next_draw: Instant::now() + FIRST_DRAW,
            last: None,
        }
    }

    /// After one interpolation cycle: redraw when it is time.
    pub fn tick(&mut self, p: &RunProgress) {
        if !self.enabled {
            return;
        }
        let now = Instant::now();
        if now < self.next_draw {
            return;
        }
        self.next_draw = now + REDRAW;
        let mut line = format!("fieldprobe run: {}", progress_text(p));
        if self.rate {
            if let Some((t, c)) = self.last {
                let dt = now.duration_since(t).as_secs_f64();
                if dt > 0.0 {
                    let per_s = p.cycles.saturating_sub(c) as f64 / dt;
                    line.push_str(&format!(", {per_s:.0} cycles/s"));
                }
            }
            self.last = Some((now, p.cycles));
        }
        draw(&line);
    }

    /// The run ended: erase the line.
    pub fn finish(&mut self) {
        if self.enabled {
            clear();
        }
    }
}

/// `N20 (line 3), program time 12.345 s, cycle 12345`.
pub fn progress_text(p: &RunProgress) -> String {
    let block = match p.block {
        Some(b) => match b.number {
            Some(n) => format!("N{n} (line {})", b.line),
            None => format!("line {}", b.line),
        },
        None => "no block yet".to_string(),
    };
    format!(
        "{block}, program time {:.3} s, cycle {}",
        p.time.as_secs_f64(),
        p.cycles
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use fieldprobe::messages::BlockRef;
    use fieldprobe::units::Nanos;

    #[test]
    fn text() {
        let p = RunProgress {
            block: Some(BlockRef {
                number: Some(20),
                line: 3,
            }),
            cycles: 12_345,
            time: Nanos(12_345_000_000),
        };
        assert_eq!(
            progress_text(&p),
            "N20 (line 3), program time 12.345 s, cycle 12345"
        );
    }
}
