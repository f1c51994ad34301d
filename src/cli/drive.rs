//! `fieldprobe drive`: drive definitions (`drives/*.toml`) from vendor files.
//!
//! ```text
//! fieldprobe drive from-esi FILE.xml [--device PRODUCT] [--name NAME] [--out FILE.toml]
//! fieldprobe drive from-eds FILE.eds [--name NAME] [--out FILE.toml]
//! ```
//! Writes the definition ([`fieldprobe::drive::vendor`]) to stdout or `--out`; what was left out
//! (optional objects the device lacks, the touch probe) goes to stderr as `note:` lines. Exit 0;
//! 2 on bad input: an unreadable file, no such device, or a device that lacks objects a CiA 402
//! axis needs (the message names them and the file).

use super::EXIT_OK;
use anyhow::Context;
use fieldprobe::drive::vendor::{self, VendorDevice};
use std::path::PathBuf;

/// Arguments of `fieldprobe drive`.
#[derive(Debug, clap::Args)]
pub struct DriveArgs {
    #[command(subcommand)]
    command: DriveCommand,
}

#[derive(Debug, clap::Subcommand)]
enum DriveCommand {
    /// Write a drive definition from an EtherCAT ESI file (the device's CoE dictionary).
    FromEsi(FromEsiArgs),
    /// Write a drive definition from a CANopen EDS file.
    FromEds(FromEdsArgs),
}

/// Where the definition goes and what it is called.
#[derive(Debug, clap::Args)]
struct Output {
    /// `[drive] name` (default: from vendor and product, e.g. `ingenia-evs-net-01`).
    #[arg(long)]
    name: Option<String>,
    /// Write the definition into this file instead of stdout.
    #[arg(long, short = 'o', value_name = "FILE.toml")]
    out: Option<PathBuf>,
}

/// Arguments of `fieldprobe drive from-esi`.
#[derive(Debug, clap::Args)]
struct FromEsiArgs {
    /// The ESI file (EtherCATInfo XML).
    file: PathBuf,
    /// The device: product code (`0x3B11002`, `#x3B11002`, decimal) or type name
    /// (`EVS-NET-01`); needed when the file describes several devices.
    #[arg(long, value_name = "PRODUCT")]
    device: Option<String>,
    #[command(flatten)]
    output: Output,
}

/// Arguments of `fieldprobe drive from-eds`.
#[derive(Debug, clap::Args)]
struct FromEdsArgs {
    /// The EDS (or DCF) file.
    file: PathBuf,
    #[command(flatten)]
    output: Output,
}

/// Run the command; returns the exit code.
pub fn run(a: DriveArgs) -> anyhow::Result<i32> {
    match a.command {
        DriveCommand::FromEsi(a) => from_esi(a),
        DriveCommand::FromEds(a) => from_eds(a),
    }
}

/// `0x…` / `#x…` hexadecimal or decimal.
fn number(s: &str) -> Option<u32> {
    let t = s.trim();
    match t
        .strip_prefix("0x")
        .or_else(|| t.strip_prefix("0X"))
        .or_else(|| t.strip_prefix("#x"))
    {
        Some(h) => u32::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}

fn from_esi(a: FromEsiArgs) -> anyhow::Result<i32> {
    let file = fieldprobe::esi::load(&a.file)?;
    let list = || {
        file.devices
            .iter()
            .map(|d| format!("{} (product code 0x{:08X})", d.type_name, d.product_code))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let device = match a.device.as_deref() {
        Some(want) => {
            let code = number(want);
            file.devices
                .iter()
                .find(|d| {
                    code == Some(d.product_code)
                        || d.type_name.eq_ignore_ascii_case(want.trim())
                        || d.name().eq_ignore_ascii_case(want.trim())
                })
                .with_context(|| {
                    format!(
                        "{}: --device {want}: no such device; the file has: {}",
                        file.file,
                        list()
                    )
                })?
        }
        None => match file.devices.as_slice() {
            [one] => one,
            [] => anyhow::bail!("{}: the file describes no device", file.file),
            _ => anyhow::bail!(
                "{}: the file describes {} devices; pick one with --device: {}",
                file.file,
                file.devices.len(),
                list()
            ),
        },
    };
    if device.dictionary().is_none() {
        anyhow::bail!(
            "{}: device {} has no CoE object dictionary (Profile/Dictionary); a CiA 402 drive \
             definition needs one",
            file.file,
            device.type_name
        );
    }
    write(&VendorDevice::from_esi(&file, device), &a.output)
}

fn from_eds(a: FromEdsArgs) -> anyhow::Result<i32> {
    let eds = super::canopen_od::load_eds(None, &a.file)?;
    let dev = VendorDevice::from_eds(&eds);
    let pdos = vendor::PdoCapacity::from_eds(&eds);
    match vendor::generate_in(&dev, a.output.name.as_deref(), Some(&pdos)) {
        // Not a CiA 402 drive at all: say what its device type names (CiA 301 0x1000, bits
        // 0 … 15 the device profile number).
        Err(e @ vendor::VendorError::MissingObjects { .. }) => {
            let profile = eds
                .get(0x1000, 0)
                .and_then(|d| d.value(eds.node_id().unwrap_or(0)))
                .and_then(|v| v.as_u64());
            match profile {
                Some(t) if t & 0xFFFF != 402 => anyhow::bail!(
                    "{e}; its device type 0x{t:08X} (0x1000) names device profile {} (bits \
                     0 … 15), not CiA 402 (drives and motion control)",
                    t & 0xFFFF
                ),
                _ => Err(e.into()),
            }
        }
        Err(e) => Err(e.into()),
        Ok(g) => write_generated(&dev, g, &a.output),
    }
}

fn write(dev: &VendorDevice, out: &Output) -> anyhow::Result<i32> {
    let g = vendor::generate(dev, out.name.as_deref())?;
    write_generated(dev, g, out)
}

fn write_generated(dev: &VendorDevice, g: vendor::Generated, out: &Output) -> anyhow::Result<i32> {
    for n in &g.notes {
        eprintln!("note: {}: {n}", dev.file);
    }
    match &out.out {
        Some(path) => {
            std::fs::write(path, &g.toml)
                .with_context(|| format!("--out {}: cannot write", path.display()))?;
            eprintln!("wrote {}", path.display());
        }
        None => outln!("{}", g.toml.trim_end()),
    }
    Ok(EXIT_OK)
}
