//! `fieldprobe drive`: drive definitions (`drives/*.toml`) from vendor files.
//!
//! ```text
//! fieldprobe drive from-esi FILE.xml[#SEL] [--device SEL] [--name NAME] [--out FILE.toml]
//! fieldprobe drive from-eds FILE.eds [--name NAME] [--out FILE.toml]
//! ```
//! Writes the definition ([`fieldprobe::drive::vendor`]) to stdout or `--out`; what was left out
//! (optional objects the device lacks, the touch probe) goes to stderr as `note:` lines. Exit 0;
//! 2 on bad input: an unreadable file, no such device, or a device that lacks objects a CiA 402
//! axis needs (the message names them and the file). SEL chooses the device of a file with
//! several and its modules ([`fieldprobe::esi::select`]); the definition is made from the
//! resolved device (module PDOs and objects included). A device that states no CiA 402 profile,
//! or whose 0x1000 default does not say 402, gets a `note:` (the file's word is a hint: the
//! device answers 0x1000 itself).

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
    /// The ESI file (EtherCATInfo XML), optionally `#SEL`: the device (TYPE[/REVISION],
    /// PRODUCT_CODE[/REVISION] or @N) and its modules (+MODULE per slot).
    #[arg(value_name = "FILE.xml[#SEL]")]
    file: String,
    /// The device, as SEL of FILE.xml#SEL: product code (`0x3B11002`, `#x3B11002`, decimal),
    /// type name (`EVS-NET-01`), TYPE/REVISION or @N; needed when the file describes several
    /// devices.
    #[arg(long, value_name = "SEL")]
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

fn from_esi(a: FromEsiArgs) -> anyhow::Result<i32> {
    let (file, device) = super::esi_load::load_device(&a.file, a.device.as_deref())?;
    if device.dictionary().is_none() {
        // Said, then the roles decide: without a dictionary only fixed PDOs could carry them.
        eprintln!(
            "note: {}: device {} has no CoE object dictionary (Profile/Dictionary){}",
            file.file,
            device.type_name,
            if device.mailbox.as_ref().is_some_and(|m| m.soe) {
                "; it speaks SoE (SERCOS over EtherCAT), not CoE"
            } else {
                ""
            }
        );
    }
    // What the file states is a hint, not a gate: the device answers 0x1000 itself.
    if !device.is_cia402() {
        let profiles: Vec<String> = device
            .profile_numbers()
            .iter()
            .map(u32::to_string)
            .collect();
        eprintln!(
            "note: {}: device {} states no CiA 402 profile (profiles: {})",
            file.file,
            device.type_name,
            if profiles.is_empty() {
                "none".to_string()
            } else {
                profiles.join(", ")
            }
        );
    }
    if let Some(t) = device.device_type().filter(|t| t & 0xFFFF != 402) {
        eprintln!(
            "note: {}: device {}: 0x1000 default 0x{t:08X} (as the file gives it) does not \
             say profile 402 in its low word",
            file.file, device.type_name
        );
    }
    let mut dev = VendorDevice::from_esi(&file, &device);
    // `[device] esi`: the file, the device's position and its modules, so that the emulator
    // plays exactly this device.
    let modules: String = device
        .plugged
        .iter()
        .flatten()
        .map(|m| format!("+#x{:X}", m.ident))
        .collect();
    dev.reference = Some(format!("{}#@{}{modules}", file.file, device.position));
    write(&dev, &a.output)
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
