//! `fieldprobe sim`: emulate EtherCAT devices on a network interface.
//!
//! ```text
//! fieldprobe sim ethercat --iface IF --device FILE.xml[:COUNT]... [--seconds N]
//! ```
//! Builds a segment from the ESI files (in the order given; `:COUNT` repeats a device; the
//! first device of each file is used), with the SII image generated from the ESI and a simple
//! application (no process data: none; with process data: echo of the inverted outputs), and
//! answers EtherCAT frames on `IF` until `--seconds` pass (default: forever) or the process
//! is killed. Needs CAP_NET_RAW (e.g. inside `unshare -rn`). Exit 0; 2 on bad input (the
//! message names the file or interface).

use super::EXIT_OK;
use anyhow::Context;
use fieldprobe::esi::{self, sii, to_sii, Device, SmKind};
use fieldprobe::sim::esc::{
    raw, segment::Segment, EchoApp, Esc, EscApplication, EscConfig, NullApp,
};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Forwarding delay between neighbouring emulated devices.
const HOP_DELAY_NS: u64 = 500;

/// Arguments of `fieldprobe sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    #[command(subcommand)]
    command: SimCommand,
}

#[derive(Debug, clap::Subcommand)]
enum SimCommand {
    /// Serve emulated EtherCAT SubDevices on a network interface (raw socket, EtherType 0x88A4).
    Ethercat(EthercatArgs),
}

/// Arguments of `fieldprobe sim ethercat`.
#[derive(Debug, clap::Args)]
struct EthercatArgs {
    /// Network interface to answer on (e.g. one end of a veth pair).
    #[arg(long, value_name = "IF")]
    iface: String,
    /// ESI file of the next device(s) in ring order, optionally `:COUNT` for several.
    #[arg(long = "device", value_name = "FILE.xml[:COUNT]", required = true)]
    devices: Vec<String>,
    /// Stop after this many seconds (default: run until killed).
    #[arg(long, value_name = "N")]
    seconds: Option<f64>,
}

/// Run the command; returns the exit code.
pub fn run(a: SimArgs) -> anyhow::Result<i32> {
    match a.command {
        SimCommand::Ethercat(e) => ethercat(e),
    }
}

/// `FILE.xml[:COUNT]` → (file, count). A suffix that is not a number is part of the file name.
fn split_count(spec: &str) -> anyhow::Result<(PathBuf, usize)> {
    if let Some((file, n)) = spec.rsplit_once(':') {
        if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) {
            let count: usize = n
                .parse()
                .with_context(|| format!("--device {spec}: bad count {n:?}"))?;
            anyhow::ensure!(count >= 1, "--device {spec}: count must be at least 1");
            return Ok((PathBuf::from(file), count));
        }
    }
    Ok((PathBuf::from(spec), 1))
}

/// Process-data sizes (outputs, inputs) in bytes: the PDOs assigned by default.
fn pd_sizes(device: &Device) -> (u16, u16) {
    let bytes = |pdos: &[esi::Pdo], kind: SmKind| -> u16 {
        let bits: u32 = pdos
            .iter()
            .filter(|p| {
                p.sm.and_then(|n| device.sync_managers.get(usize::from(n)))
                    .is_some_and(|sm| sm.kind == kind)
            })
            .map(|p| p.bit_len())
            .sum();
        u16::try_from(bits.div_ceil(8)).unwrap_or(u16::MAX)
    };
    (
        bytes(&device.rx_pdos, SmKind::Outputs),
        bytes(&device.tx_pdos, SmKind::Inputs),
    )
}

fn build_device(path: &std::path::Path) -> anyhow::Result<Esc> {
    let shown = path.display();
    let file = esi::load(path).map_err(|e| anyhow::anyhow!("--device {shown}: {e}"))?;
    let device = file
        .devices
        .first()
        .with_context(|| format!("--device {shown}: the ESI file describes no device"))?;
    let content = to_sii::sii_from_device(&file, device)
        .with_context(|| format!("--device {shown}: cannot build the SII image"))?;
    let image = sii::encode(&content)
        .with_context(|| format!("--device {shown}: cannot encode the SII image"))?;
    let app: Box<dyn EscApplication> = match pd_sizes(device) {
        (0, 0) => Box::new(NullApp),
        (o, i) => {
            let mut app = EchoApp::new(o, i);
            app.loopback = true;
            Box::new(app)
        }
    };
    Ok(Esc::new(EscConfig::from_sii(image), app))
}

fn ethercat(a: EthercatArgs) -> anyhow::Result<i32> {
    let mut escs = Vec::new();
    for spec in &a.devices {
        let (path, count) = split_count(spec)?;
        for _ in 0..count {
            escs.push(build_device(&path)?);
        }
    }
    let deadline = match a.seconds {
        None => None,
        Some(s) if s.is_finite() && s >= 0.0 => Some(Instant::now() + Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--seconds {s}: expected a non-negative number"),
    };
    let mut segment = Segment::new(escs, HOP_DELAY_NS);
    eprintln!(
        "fieldprobe sim ethercat: {} device(s) on {}",
        segment.len(),
        a.iface
    );
    let mut port = raw::RawPort::open(&a.iface)?;
    eprintln!("fieldprobe sim ethercat: listening on {}", port.iface());
    let stop = AtomicBool::new(false);
    let stats = port.serve(&mut segment, &stop, deadline)?;
    eprintln!("fieldprobe sim ethercat: done, {stats:?}");
    Ok(EXIT_OK)
}
