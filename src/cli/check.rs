//! `fieldprobe check`: the commissioning check — reads the drives' settings over the link and
//! reports, in plain words and per axis, every mismatch with the axis parameters (FCT-C4 §6:
//! the drive must be parameterised to match P-AXIS-00516 / 00517 / 00518 / 00060 / 00702).
//!
//! ```text
//! fieldprobe check [--machine FILE.toml] [--set KEY=VALUE]...
//! ```
//! Exit 0 when nothing was found, 1 when a finding was reported, 2 on bad input. A `note:` line
//! (a drive without touch probe on an axis that does not measure with it: the sources of
//! seed 004 §7 that remain) is not a finding, nor is a `warning 900047:` line (a probing-signal
//! parameter the axis sets without effect, as `run` reports it at its start).

use super::{load_machine, EXIT_CNC_ERROR, EXIT_OK};
use fieldprobe::machine::Machine;
use std::path::PathBuf;

/// Arguments of `fieldprobe check`.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// Machine file (TOML); default: axes X, Y, Z on emulated CiA 402 drives.
    #[arg(long)]
    machine: Option<PathBuf>,
    /// Parameter assignment in seed units.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
}

/// Run the command; returns the exit code.
pub fn run(a: CheckArgs) -> anyhow::Result<i32> {
    let cfg = load_machine(a.machine.as_deref(), &a.sets)?;
    // The drives' settings are read from the drive models (the in-memory link); the machine's
    // terminals are not needed for that, but their kinds go into the report (PLC_TIMESTAMP).
    let mut drives_only = cfg.clone();
    drives_only.terminals.clear();
    let mut machine = Machine::new(&drives_only)?;
    let report = machine.commissioning_check(&cfg);
    let mut findings = 0;
    for axis in &report {
        outln!("{} ({}, {}):", axis.axis, axis.drive, axis.profile);
        if axis.findings.is_empty() {
            outln!("  ok");
        }
        for f in &axis.findings {
            findings += 1;
            outln!("  - {f}");
        }
        for n in &axis.notes {
            outln!("  note: {n}");
        }
        // A parameter set without effect (900047): said as the run says it, not a finding.
        for w in &axis.warnings {
            outln!("  {w}");
        }
    }
    Ok(if findings == 0 {
        EXIT_OK
    } else {
        EXIT_CNC_ERROR
    })
}
