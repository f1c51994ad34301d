//! EtherCAT commissioning commands: `scan`, `sdo read|write`, `idn read|write`.
//!
//! ```text
//! fieldprobe scan [--link ethercat-emu|ethercat:IFACE] [--machine FILE.toml] [--set KEY=VALUE]...
//! fieldprobe sdo read  [--link …] --device N INDEX:SUB [--type T]
//! fieldprobe sdo write [--link …] --device N INDEX:SUB VALUE [--type T]
//! fieldprobe idn read  [--link …] --device N S-0-0092
//! fieldprobe idn write [--link …] --device N S-0-0092 VALUE
//! ```
//! The bus is brought to PRE-OP (no process data); `--device` is the ring position `scan`
//! prints. `ethercat-emu` (default) is the emulated segment of the machine file (a coupler, then
//! one drive per axis). Errors name the device and the object, with the SDO abort code / SoE
//! error in words. Exit 0; 1 when the device refuses the access; 2 on bad input or a bus error.

use super::{load_machine, EXIT_BAD_INPUT, EXIT_CNC_ERROR, EXIT_OK};
use anyhow::Context;
use fieldprobe::drive::pdo::DataType;
use fieldprobe::link::ethercat::{EthercatSpec, Session, Wire};
use fieldprobe::link::LinkError;
use std::path::PathBuf;

/// Where the bus is.
#[derive(Debug, Clone, clap::Args)]
pub struct BusArgs {
    /// `ethercat-emu` (emulated segment of the machine file) or `ethercat:IFACE`.
    #[arg(long, value_name = "LINK", default_value = "ethercat-emu")]
    link: String,
    /// Machine file whose axes the emulated segment carries (ethercat-emu).
    #[arg(long)]
    machine: Option<PathBuf>,
    /// Parameter assignment for the machine file (e.g. `Z.drive=sercos-ax5000`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Write every frame into this pcap file.
    #[arg(long, value_name = "FILE.pcap")]
    pcap: Option<PathBuf>,
}

impl BusArgs {
    fn open(&self) -> anyhow::Result<Session> {
        let wire = Wire::from_link(&self.link).with_context(|| {
            format!(
                "--link {}: expected ethercat-emu or ethercat:IFACE",
                self.link
            )
        })?;
        let drives = if wire == Wire::Emulated {
            let cfg = load_machine(self.machine.as_deref(), &self.sets)?;
            cfg.axes
                .iter()
                .map(|a| {
                    fieldprobe::drive::catalogue::load(&a.drive)
                        .map(std::sync::Arc::new)
                        .with_context(|| format!("axis {}: drive '{}'", a.name, a.drive))
                })
                .collect::<anyhow::Result<Vec<_>>>()?
        } else {
            Vec::new()
        };
        let spec = EthercatSpec {
            drives,
            cycle: fieldprobe::units::Nanos::from_micros(1000),
            pcap: self.pcap.clone(),
        };
        Session::open(&wire, &spec).map_err(|e| anyhow::anyhow!("--link {}: {e}", self.link))
    }
}

/// Arguments of `fieldprobe scan`.
#[derive(Debug, clap::Args)]
pub struct ScanArgs {
    #[command(flatten)]
    bus: BusArgs,
}

/// `fieldprobe scan`.
pub fn scan(a: ScanArgs) -> anyhow::Result<i32> {
    let s = a.bus.open()?;
    println!("pos  address  vendor      product     revision    state    DC              name");
    for d in s.devices() {
        println!(
            "{:<4} {:#06x}   {:#010x}  {:#010x}  {:#010x}  {:<8} {:<15} {}",
            d.position, d.address, d.vendor, d.product, d.revision, d.state, d.dc, d.name
        );
    }
    Ok(EXIT_OK)
}

/// Arguments of `fieldprobe sdo`.
#[derive(Debug, clap::Args)]
pub struct SdoArgs {
    #[command(subcommand)]
    op: SdoOp,
}

#[derive(Debug, clap::Subcommand)]
enum SdoOp {
    /// Upload (read) an object.
    Read(SdoRead),
    /// Download (write) an object.
    Write(SdoWrite),
}

#[derive(Debug, clap::Args)]
struct SdoRead {
    #[command(flatten)]
    bus: BusArgs,
    /// Ring position of the SubDevice (as `scan` prints it).
    #[arg(long)]
    device: usize,
    /// Object, e.g. `0x6041:00` or `0x1008` (sub-index 0).
    object: String,
    /// Data type (`u8` `i8` `u16` `i16` `u32` `i32`, or `string`, `bytes`); default: the CiA 402
    /// type of the object, else by length.
    #[arg(long = "type")]
    ty: Option<String>,
}

#[derive(Debug, clap::Args)]
struct SdoWrite {
    #[command(flatten)]
    bus: BusArgs,
    /// Ring position of the SubDevice.
    #[arg(long)]
    device: usize,
    /// Object, e.g. `0x6065:00`.
    object: String,
    /// Value (decimal or 0x hex; a string for `--type string`).
    value: String,
    /// Data type; default: the CiA 402 type of the object (required for other objects).
    #[arg(long = "type")]
    ty: Option<String>,
}

/// `INDEX[:SUB]` → (index, sub).
fn parse_object(s: &str) -> anyhow::Result<(u16, u8)> {
    let num = |t: &str, max: u32| -> Option<u32> {
        let t = t.trim();
        let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
            Some(h) => u32::from_str_radix(h, 16).ok()?,
            None => u32::from_str_radix(t, 16).ok()?,
        };
        (v <= max).then_some(v)
    };
    let (i, sub) = s.split_once(':').unwrap_or((s, "0"));
    match (num(i, 0xFFFF), num(sub, 0xFF)) {
        (Some(i), Some(sub)) => Ok((i as u16, sub as u8)),
        _ => anyhow::bail!(
            "object '{s}': expected INDEX:SUB in hex, e.g. 0x6041:00 (index 0x0000 … 0xFFFF, sub-index 0x00 … 0xFF)"
        ),
    }
}

fn parse_int(s: &str) -> Option<i64> {
    let t = s.trim();
    let (neg, t) = match t.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, t),
    };
    let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16).ok()?,
        None => t.parse().ok()?,
    };
    Some(if neg { -v } else { v })
}

/// Exit code and message for a refused access.
fn refused(e: LinkError) -> anyhow::Result<i32> {
    eprintln!("fieldprobe: {e}");
    Ok(match e {
        LinkError::Abort { .. } => EXIT_CNC_ERROR,
        LinkError::Other(m) if m.contains("SoE") => EXIT_CNC_ERROR,
        _ => EXIT_BAD_INPUT,
    })
}

/// `fieldprobe sdo`.
pub fn sdo(a: SdoArgs) -> anyhow::Result<i32> {
    match a.op {
        SdoOp::Read(r) => {
            let (index, sub) = parse_object(&r.object)?;
            let ty = r.ty.as_deref().map(str::to_ascii_lowercase);
            let mut s = r.bus.open()?;
            let bytes = match s.sdo_read(r.device, index, sub) {
                Ok(b) => b,
                Err(e) => return refused(e),
            };
            let known = fieldprobe::drive::pdo::lookup(index, sub).map(|o| o.ty);
            let numeric = match ty.as_deref() {
                Some("string") | Some("bytes") => None,
                Some(t) => Some(DataType::from_name(t).with_context(|| {
                    format!("--type {t}: expected u8, i8, u16, i16, u32, i32, string or bytes")
                })?),
                None => known.or(match bytes.len() {
                    1 => Some(DataType::U8),
                    2 => Some(DataType::U16),
                    4 => Some(DataType::U32),
                    _ => None,
                }),
            };
            match numeric {
                Some(t) if bytes.len() == t.size() => {
                    let mut b = [0u8; 8];
                    b[..bytes.len()].copy_from_slice(&bytes);
                    let raw = u64::from_le_bytes(b);
                    let v = if t.is_signed() {
                        let shift = 64 - 8 * t.size() as u32;
                        ((raw << shift) as i64) >> shift
                    } else {
                        raw as i64
                    };
                    println!("{index:#06x}:{sub:02x} = {v} ({raw:#x})");
                }
                Some(t) => {
                    eprintln!(
                        "fieldprobe: device {} {index:#06x}:{sub:02x}: {} bytes do not fit type {}",
                        r.device,
                        bytes.len(),
                        t.name()
                    );
                    return Ok(EXIT_BAD_INPUT);
                }
                None if ty.as_deref() != Some("bytes")
                    && !bytes.is_empty()
                    && bytes.iter().all(|b| b.is_ascii_graphic() || *b == b' ') =>
                {
                    println!(
                        "{index:#06x}:{sub:02x} = \"{}\" ({} bytes)",
                        String::from_utf8_lossy(&bytes),
                        bytes.len()
                    );
                }
                None => {
                    let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02x}")).collect();
                    println!(
                        "{index:#06x}:{sub:02x} = [{}] ({} bytes)",
                        hex.join(" "),
                        bytes.len()
                    );
                }
            }
            Ok(EXIT_OK)
        }
        SdoOp::Write(w) => {
            let (index, sub) = parse_object(&w.object)?;
            let data = match w.ty.as_deref().map(str::to_ascii_lowercase).as_deref() {
                Some("string") => w.value.as_bytes().to_vec(),
                t => {
                    let ty = match t {
                        Some(t) => DataType::from_name(t).with_context(|| {
                            format!("--type {t}: expected u8, i8, u16, i16, u32, i32 or string")
                        })?,
                        None => fieldprobe::drive::pdo::lookup(index, sub)
                            .map(|o| o.ty)
                            .with_context(|| {
                                format!("{index:#06x}:{sub:02x}: type unknown; give --type (u8, i8, u16, i16, u32, i32, string)")
                            })?,
                    };
                    let v = parse_int(&w.value)
                        .with_context(|| format!("value '{}': not an integer", w.value))?;
                    let bits = 8 * ty.size() as u32;
                    let (lo, hi) = if ty.is_signed() {
                        (-(1i64 << (bits - 1)), (1i64 << (bits - 1)) - 1)
                    } else {
                        (0, (1i64 << bits) - 1)
                    };
                    anyhow::ensure!(
                        (lo..=hi).contains(&v),
                        "value {v} is out of range for {} ({lo} … {hi})",
                        ty.name()
                    );
                    v.to_le_bytes()[..ty.size()].to_vec()
                }
            };
            let mut s = w.bus.open()?;
            match s.sdo_write(w.device, index, sub, &data) {
                Ok(()) => {
                    println!("{index:#06x}:{sub:02x} written ({} bytes)", data.len());
                    Ok(EXIT_OK)
                }
                Err(e) => refused(e),
            }
        }
    }
}

/// Arguments of `fieldprobe idn`.
#[derive(Debug, clap::Args)]
pub struct IdnArgs {
    #[command(subcommand)]
    op: IdnOp,
}

#[derive(Debug, clap::Subcommand)]
enum IdnOp {
    /// Read an IDN's value (and name) over SoE.
    Read(IdnRead),
    /// Write an IDN's value over SoE.
    Write(IdnWrite),
}

#[derive(Debug, clap::Args)]
struct IdnRead {
    #[command(flatten)]
    bus: BusArgs,
    /// Ring position of the SubDevice.
    #[arg(long)]
    device: usize,
    /// IDN, e.g. `S-0-0092` or `P-0-0010`.
    idn: String,
}

#[derive(Debug, clap::Args)]
struct IdnWrite {
    #[command(flatten)]
    bus: BusArgs,
    /// Ring position of the SubDevice.
    #[arg(long)]
    device: usize,
    /// IDN, e.g. `S-0-0092`.
    idn: String,
    /// Value (decimal or 0x hex).
    value: String,
}

fn parse_idn(s: &str) -> anyhow::Result<u16> {
    fieldprobe::drive::sercos::idn_code(s).with_context(|| {
        format!("IDN '{s}': expected S-x-nnnn or P-x-nnnn (parameter set 0 … 7, number 0 … 4095)")
    })
}

/// `fieldprobe idn`.
pub fn idn(a: IdnArgs) -> anyhow::Result<i32> {
    match a.op {
        IdnOp::Read(r) => {
            let idn = parse_idn(&r.idn)?;
            let mut s = r.bus.open()?;
            match s.idn_read(r.device, idn) {
                Ok((v, name)) => {
                    let shown = fieldprobe::drive::sercos::idn_name(idn);
                    if name.is_empty() {
                        println!("{shown} = {v}");
                    } else {
                        println!("{shown} = {v} ({name})");
                    }
                    Ok(EXIT_OK)
                }
                Err(e) => refused(e),
            }
        }
        IdnOp::Write(w) => {
            let idn = parse_idn(&w.idn)?;
            let v = parse_int(&w.value)
                .with_context(|| format!("value '{}': not an integer", w.value))?;
            let mut s = w.bus.open()?;
            match s.idn_write(w.device, idn, v) {
                Ok(()) => {
                    println!("{} written", fieldprobe::drive::sercos::idn_name(idn));
                    Ok(EXIT_OK)
                }
                Err(e) => refused(e),
            }
        }
    }
}
