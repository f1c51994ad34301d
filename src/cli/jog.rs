//! `fieldprobe jog`: manual mode from the command line (FCT-A2 §2 "Manual mode").
//!
//! ```text
//! fieldprobe jog --axis X (--continuous +|- | --step DIST) [--feed MM_PER_MIN]
//!                [--program SETUP.nc] [--machine FILE.toml] [--set KEY=VALUE]...
//! ```
//! `--program` runs an NC program first (positioning, G98 / G99); then manual mode is selected
//! and the axis jogs. Prints the position where the axis stopped; warnings (50720 with
//! P-MANU-00014, 150008, 900318 at a workspace / protection area) and errors (50961 / 50962 when
//! manual mode is selected outside the permitted range) go to stderr.

use super::{load_machine, load_program, EXIT_BAD_INPUT, EXIT_CNC_ERROR, EXIT_OK};
use anyhow::Context;
use fieldprobe::channel::ChannelState;
use fieldprobe::machine::{Machine, RunStatus};
use std::path::PathBuf;

/// Largest `--step` distance (mm): the bound of every path coordinate
/// ([`fieldprobe::core::path::MAX_COORDINATE`]).
const MAX_STEP: f64 = fieldprobe::core::path::MAX_COORDINATE;

/// Arguments of `fieldprobe jog`.
#[derive(Debug, clap::Args)]
pub struct JogArgs {
    /// Axis to jog.
    #[arg(long)]
    axis: String,
    /// Continuous jog in direction `+` or `-` until the end of the permitted range.
    #[arg(long, value_parser = ["+", "-"], conflicts_with = "step")]
    continuous: Option<String>,
    /// Incremental jog by DIST (mm, signed).
    #[arg(long, value_name = "DIST", allow_hyphen_values = true)]
    step: Option<String>,
    /// Jog feed in mm/min.
    #[arg(
        long,
        value_name = "MM_PER_MIN",
        default_value = "1000",
        allow_hyphen_values = true
    )]
    feed: String,
    /// NC program to run before manual mode is selected.
    #[arg(long)]
    program: Option<PathBuf>,
    /// Machine file (TOML).
    #[arg(long)]
    machine: Option<PathBuf>,
    /// Parameter assignment in seed units.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
}

/// Run the command; returns the exit code.
pub fn run(a: JogArgs) -> anyhow::Result<i32> {
    if a.continuous.is_none() && a.step.is_none() {
        anyhow::bail!("jog: give --continuous + | - or --step DIST");
    }
    let feed = super::number::real(&a.feed).filter(|f| *f > 0.0);
    let Some(feed) = feed else {
        anyhow::bail!(
            "jog: --feed {}: expected a number > 0 (mm/min), {}",
            super::cap_echo(&a.feed),
            super::number::REAL_FORM
        );
    };
    // A step no NC program could command (path coordinates are bounded the same way) is bad
    // input, refused before the machine starts; a step inside this bound but beyond the
    // permitted range is the CNC's warning 150008.
    let step = match &a.step {
        Some(text) => Some(super::number::real_option(
            "jog: --step",
            text,
            -MAX_STEP,
            MAX_STEP,
            "a distance in mm",
        )?),
        None => None,
    };
    let cfg = load_machine(a.machine.as_deref(), &a.sets)?;
    let mut m = Machine::new(&cfg)?;
    let i = m
        .channel()
        .axis_index(&a.axis)
        .with_context(|| format!("jog: unknown axis '{}'", a.axis))?;
    if let Some(p) = &a.program {
        let Some(program) = load_program(p)? else {
            return Ok(EXIT_BAD_INPUT);
        };
        let report = m.run_program(&program, &mut |e| {
            if let fieldprobe::machine::RunEvent::Message(msg) = e {
                eprintln!("{msg}");
            }
        });
        if report.status == RunStatus::Aborted {
            return Ok(EXIT_CNC_ERROR);
        }
    } else if m.settle(10_000) != ChannelState::Idle {
        for msg in m.channel_mut().take_messages() {
            eprintln!("{msg}");
        }
        return Ok(EXIT_CNC_ERROR);
    }
    let ch = m.channel_mut();
    ch.enter_manual();
    let v = feed / 60.0;
    if let Some(dir) = &a.continuous {
        ch.jog_continuous(i, if dir == "-" { -v } else { v });
    } else if let Some(d) = step {
        ch.jog_increment(i, d, v);
    }
    // A continuous jog without any limit (non-referenced axis, offset limits 0) would run on:
    // stop it after ten minutes of virtual time.
    let ten_minutes = 600_000_000 / u64::from(cfg.cycle_time_us).max(1);
    if m.settle(ten_minutes) == ChannelState::Busy {
        eprintln!("jog: no limit reached after 10 min of jogging; stopped");
        m.channel_mut().jog_stop(i);
        m.settle(ten_minutes);
    }
    let ch = m.channel_mut();
    let failed = ch.messages().iter().any(|x| x.is_error());
    for msg in ch.take_messages() {
        eprintln!("{msg}");
    }
    let (lo, hi) = ch
        .jog_range(i)
        .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    let ax = &ch.axes()[i];
    outln!(
        "{} command {:.6} actual {:.6} range [{lo:.6}, {hi:.6}]",
        ax.name(),
        ax.command(),
        ax.actual()
    );
    Ok(if failed { EXIT_CNC_ERROR } else { EXIT_OK })
}
