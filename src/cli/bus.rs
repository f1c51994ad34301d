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
use fieldprobe::link::canopen::CanSession;
use fieldprobe::link::ethercat::{EthercatSpec, Session, Wire};
use fieldprobe::link::LinkError;
use std::path::PathBuf;

/// Where the bus is.
#[derive(Debug, Clone, clap::Args)]
pub struct BusArgs {
    /// `ethercat-emu` (emulated segment of the machine file), `ethercat:IFACE`, `canopen-emu`
    /// (emulated CANopen nodes of the machine file, ids 1 …), `canopen-udp[:GROUP:PORT]` or
    /// `socketcan:IF`.
    #[arg(long, value_name = "LINK", default_value = "ethercat-emu")]
    link: String,
    /// Log every CAN frame in candump -L format (CAN links; refused on EtherCAT links).
    #[arg(long, value_name = "FILE.log")]
    candump: Option<PathBuf>,
    /// Machine file whose axes the emulated devices are (ethercat-emu, canopen-emu; refused on
    /// the links to a real bus).
    #[arg(long)]
    machine: Option<PathBuf>,
    /// Parameter assignment for the machine file (e.g. `Z.drive=sercos-ax5000`; emulated links
    /// only, as `--machine`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Write every EtherCAT frame into this pcap file (EtherCAT links; refused on CAN links).
    #[arg(long, value_name = "FILE.pcap")]
    pcap: Option<PathBuf>,
}

impl BusArgs {
    fn is_can(&self) -> bool {
        self.link.starts_with("canopen") || self.link.starts_with("socketcan:")
    }

    /// Refuse the options `command` does not use on this link, naming option and link (exit
    /// 2), instead of ignoring them: `--pcap` on a CAN link, `--candump` on an EtherCAT link,
    /// `--machine` / `--set` on a link that reaches a real bus (they describe the emulated
    /// devices of `ethercat-emu` and `canopen-emu` only).
    fn check_options(&self, command: &str) -> anyhow::Result<()> {
        let link = &self.link;
        if self.is_can() {
            if let Some(p) = &self.pcap {
                anyhow::bail!(
                    "--pcap {}: `{command}` on --link {link} (a CAN link) writes no pcap capture; the CAN frames go to --candump FILE.log",
                    p.display()
                );
            }
        } else if let Some(p) = &self.candump {
            anyhow::bail!(
                "--candump {}: `{command}` on --link {link} writes no candump log (CAN links only: canopen-emu, canopen-udp[:GROUP:PORT], socketcan:IF); EtherCAT frames go to --pcap FILE.pcap",
                p.display()
            );
        }
        if link != "canopen-emu" && link != "ethercat-emu" {
            let mut given = Vec::new();
            if let Some(m) = &self.machine {
                given.push(format!("--machine {}", m.display()));
            }
            given.extend(self.sets.iter().map(|s| format!("--set {s}")));
            if !given.is_empty() {
                anyhow::bail!(
                    "{}: `{command}` on --link {link} talks to the devices on the bus; the machine file describes the emulated devices of --link ethercat-emu / canopen-emu only",
                    given.join(", ")
                );
            }
        }
        Ok(())
    }

    /// The machine's drives and CANopen node ids.
    #[allow(clippy::type_complexity)]
    fn drives(
        &self,
    ) -> anyhow::Result<(
        Vec<std::sync::Arc<fieldprobe::drive::catalogue::DriveDefinition>>,
        Vec<u8>,
    )> {
        let cfg = load_machine(self.machine.as_deref(), &self.sets)?;
        let drives = load_drives(&cfg)?;
        let ids = cfg.node_ids().map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok((drives, ids))
    }

    fn open_can(&self) -> anyhow::Result<CanSession> {
        let (drives, ids) = if self.link == "canopen-emu" {
            self.drives()?
        } else {
            (Vec::new(), Vec::new())
        };
        CanSession::open(&self.link, &drives, &ids, self.candump.as_deref())
            .map_err(|e| anyhow::anyhow!("--link {}: {e}", self.link))
    }

    fn open(&self) -> anyhow::Result<Session> {
        let wire = Wire::from_link(&self.link).with_context(|| {
            format!(
                "--link {}: expected ethercat-emu or ethercat:IFACE",
                self.link
            )
        })?;
        let (drives, terminals) = if wire == Wire::Emulated {
            // The emulated segment of the machine: its axes' drives and its terminals.
            let cfg = load_machine(self.machine.as_deref(), &self.sets)?;
            let base = std::path::Path::new(&cfg.source).parent();
            let terminals = cfg
                .terminals
                .iter()
                .map(|t| {
                    let mut spec = fieldprobe::link::ethercat::terminals::TerminalSpec::resolve(
                        &t.name, &t.esi, base,
                    )
                    .map_err(|e| anyhow::anyhow!("{}:{}: {e}", cfg.source, t.line))?;
                    spec.after_axes = t.after_axes;
                    Ok(spec)
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            (load_drives(&cfg)?, terminals)
        } else {
            (Vec::new(), Vec::new())
        };
        let spec = EthercatSpec {
            drives,
            cycle: fieldprobe::units::Nanos::from_micros(1000),
            pcap: self.pcap.clone(),
            terminals,
            emulated_extra: Vec::new(),
        };
        Session::open(&wire, &spec).map_err(|e| anyhow::anyhow!("--link {}: {e}", self.link))
    }
}

/// The drive definition of every axis of `cfg`.
fn load_drives(
    cfg: &fieldprobe::params::MachineConfig,
) -> anyhow::Result<Vec<std::sync::Arc<fieldprobe::drive::catalogue::DriveDefinition>>> {
    cfg.axes
        .iter()
        .map(|a| {
            fieldprobe::drive::catalogue::load(&a.drive)
                .map(std::sync::Arc::new)
                .with_context(|| format!("axis {}: drive '{}'", a.name, a.drive))
        })
        .collect()
}

/// Arguments of `fieldprobe scan`.
#[derive(Debug, clap::Args)]
pub struct ScanArgs {
    #[command(flatten)]
    bus: BusArgs,
}

/// `fieldprobe scan`.
pub fn scan(a: ScanArgs) -> anyhow::Result<i32> {
    anyhow::ensure!(
        !a.bus.is_can(),
        "--link {}: `scan` lists EtherCAT SubDevices (ethercat-emu, ethercat:IFACE); CANopen nodes: `can scan`",
        a.bus.link
    );
    a.bus.check_options("scan")?;
    let mut s = a.bus.open()?;
    super::finish_capture(s.finish_capture());
    outln!("pos  address  vendor      product     revision    state    DC              name");
    for d in s.devices() {
        outln!(
            "{:<4} {:#06x}   {:#010x}  {:#010x}  {:#010x}  {:<8} {:<15} {}",
            d.position,
            d.address,
            d.vendor,
            d.product,
            d.revision,
            d.state,
            d.dc,
            d.name
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

/// The bus and the device (EtherCAT) or node (CANopen) an SDO goes to.
#[derive(Debug, clap::Args)]
struct SdoTo {
    #[command(flatten)]
    bus: BusArgs,
    /// Ring position of the SubDevice (as `scan` prints it; EtherCAT links).
    #[arg(long, required_unless_present = "node", conflicts_with = "node")]
    device: Option<usize>,
    /// CANopen node id 1 … 127 (CAN links).
    #[arg(long)]
    node: Option<u8>,
}

#[derive(Debug, clap::Args)]
struct SdoRead {
    #[command(flatten)]
    to: SdoTo,
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
    to: SdoTo,
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

/// Whom an SDO goes to.
enum Target {
    Device(usize),
    Node(u8),
}

fn target(to: &SdoTo) -> anyhow::Result<Target> {
    let bus = &to.bus;
    bus.check_options("sdo")?;
    match (bus.is_can(), to.device, to.node) {
        (false, Some(d), None) => Ok(Target::Device(d)),
        (true, None, Some(n)) if (1..=127).contains(&n) => Ok(Target::Node(n)),
        (true, None, Some(n)) => anyhow::bail!("--node {n}: allowed 1 … 127"),
        (true, _, _) => anyhow::bail!(
            "--link {}: a CAN link addresses nodes: give --node N (1 … 127), not --device",
            bus.link
        ),
        (false, _, _) => anyhow::bail!(
            "--link {}: an EtherCAT link addresses SubDevices: give --device N (ring position)",
            bus.link
        ),
    }
}

/// Exit code and message for a refused access.
fn refused(e: LinkError) -> anyhow::Result<i32> {
    eprintln!("fieldprobe: {e}");
    Ok(if e.is_refusal() {
        EXIT_CNC_ERROR
    } else {
        EXIT_BAD_INPUT
    })
}

/// `fieldprobe sdo`.
pub fn sdo(a: SdoArgs) -> anyhow::Result<i32> {
    match a.op {
        SdoOp::Read(r) => {
            let (index, sub) = parse_object(&r.object)?;
            let ty = r.ty.as_deref().map(str::to_ascii_lowercase);
            let result = match target(&r.to)? {
                Target::Device(d) => {
                    let mut s = r.to.bus.open()?;
                    let res = s.sdo_read(d, index, sub);
                    super::finish_capture(s.finish_capture());
                    res
                }
                Target::Node(n) => {
                    let mut s = r.to.bus.open_can()?;
                    let res = s.sdo_upload(n, index, sub);
                    super::finish_capture(s.finish_capture());
                    res
                }
            };
            let bytes = match result {
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
                    outln!("{index:#06x}:{sub:02x} = {v} ({raw:#x})");
                }
                Some(t) => {
                    eprintln!(
                        "fieldprobe: {} {index:#06x}:{sub:02x}: {} bytes do not fit type {}",
                        r.to.node.map_or_else(
                            || format!("device {}", r.to.device.unwrap_or(0)),
                            |n| format!("node {n}")
                        ),
                        bytes.len(),
                        t.name()
                    );
                    return Ok(EXIT_BAD_INPUT);
                }
                None if ty.as_deref() != Some("bytes")
                    && !bytes.is_empty()
                    && bytes.iter().all(|b| b.is_ascii_graphic() || *b == b' ') =>
                {
                    outln!(
                        "{index:#06x}:{sub:02x} = \"{}\" ({} bytes)",
                        String::from_utf8_lossy(&bytes),
                        bytes.len()
                    );
                }
                None => {
                    let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02x}")).collect();
                    outln!(
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
            let result = match target(&w.to)? {
                Target::Device(d) => {
                    let mut s = w.to.bus.open()?;
                    let res = s.sdo_write(d, index, sub, &data);
                    super::finish_capture(s.finish_capture());
                    res
                }
                Target::Node(n) => {
                    let mut s = w.to.bus.open_can()?;
                    let res = s.sdo_download(n, index, sub, &data);
                    super::finish_capture(s.finish_capture());
                    res
                }
            };
            match result {
                Ok(()) => {
                    outln!("{index:#06x}:{sub:02x} written ({} bytes)", data.len());
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
            anyhow::ensure!(
                !r.bus.is_can(),
                "--link {}: `idn` reaches SERCOS IDNs of EtherCAT SubDevices (SoE); expected ethercat-emu or ethercat:IFACE",
                r.bus.link
            );
            r.bus.check_options("idn")?;
            let mut s = r.bus.open()?;
            let res = s.idn_read(r.device, idn);
            super::finish_capture(s.finish_capture());
            match res {
                Ok((v, name)) => {
                    let shown = fieldprobe::drive::sercos::idn_name(idn);
                    if name.is_empty() {
                        outln!("{shown} = {v}");
                    } else {
                        outln!("{shown} = {v} ({name})");
                    }
                    Ok(EXIT_OK)
                }
                Err(e) => refused(e),
            }
        }
        IdnOp::Write(w) => {
            let idn = parse_idn(&w.idn)?;
            anyhow::ensure!(
                !w.bus.is_can(),
                "--link {}: `idn` reaches SERCOS IDNs of EtherCAT SubDevices (SoE); expected ethercat-emu or ethercat:IFACE",
                w.bus.link
            );
            w.bus.check_options("idn")?;
            let v = parse_int(&w.value)
                .with_context(|| format!("value '{}': not an integer", w.value))?;
            let mut s = w.bus.open()?;
            let res = s.idn_write(w.device, idn, v);
            super::finish_capture(s.finish_capture());
            match res {
                Ok(()) => {
                    outln!("{} written", fieldprobe::drive::sercos::idn_name(idn));
                    Ok(EXIT_OK)
                }
                Err(e) => refused(e),
            }
        }
    }
}

/// Arguments of `fieldprobe can`.
#[derive(Debug, clap::Args)]
pub struct CanArgs {
    #[command(subcommand)]
    op: CanOp,
}

#[derive(Debug, clap::Subcommand)]
enum CanOp {
    /// Find the CANopen nodes (SDO 0x1000 to every id): id, state, device type, identity, name.
    Scan(CanScan),
    /// Print the frames on the bus as `candump -L` lines, each with its CANopen meaning after
    /// `  ; ` (`--plain`: the lines alone, as candump, canplayer and python-can read them).
    Dump(CanDump),
}

#[derive(Debug, clap::Args)]
struct CanScan {
    #[command(flatten)]
    bus: BusArgs,
}

#[derive(Debug, clap::Args)]
struct CanDump {
    #[command(flatten)]
    bus: BusArgs,
    /// How long to listen, s.
    #[arg(long, default_value = "1")]
    seconds: f64,
    /// Plain `candump -L` lines without the `  ; meaning` comment, for tools that read candump
    /// logs (canplayer, log2asc, python-can's `CanutilsLogReader`).
    #[arg(long)]
    plain: bool,
}

/// `fieldprobe can`.
pub fn can(a: CanArgs) -> anyhow::Result<i32> {
    match a.op {
        CanOp::Scan(s) => {
            anyhow::ensure!(s.bus.is_can(), "--link {}: `can scan` needs a CAN link (canopen-emu, canopen-udp[:GROUP:PORT], socketcan:IF)", s.bus.link);
            s.bus.check_options("can scan")?;
            let mut session = s.bus.open_can()?;
            let nodes = session.scan().map_err(|e| anyhow::anyhow!("{e}"));
            super::finish_capture(session.finish_capture());
            let nodes = nodes?;
            outln!("node  state            device type  vendor      product     revision    name");
            let hex = |v: Option<u32>| v.map_or_else(|| "-".to_string(), |v| format!("{v:#010x}"));
            for n in nodes {
                outln!(
                    "{:<5} {:<16} {:#010x}   {:<11} {:<11} {:<11} {}",
                    n.id,
                    n.state.map_or("unknown", |s| s.name()),
                    n.device_type,
                    hex(n.identity[0]),
                    hex(n.identity[1]),
                    hex(n.identity[2]),
                    n.name.unwrap_or_default()
                );
            }
            Ok(EXIT_OK)
        }
        CanOp::Dump(d) => {
            anyhow::ensure!(
                d.bus.is_can(),
                "--link {}: `can dump` needs a CAN link",
                d.bus.link
            );
            d.bus.check_options("can dump")?;
            anyhow::ensure!(
                d.seconds.is_finite() && (0.0..=86_400.0).contains(&d.seconds),
                "--seconds {}: allowed 0 … 86400",
                super::show_number(d.seconds)
            );
            let mut session = d.bus.open_can()?;
            let iface = session.log_interface();
            let plain = d.plain;
            let heard = session.listen(std::time::Duration::from_secs_f64(d.seconds), &mut |f| {
                let t = std::time::UNIX_EPOCH.elapsed().unwrap_or_default();
                let line = fieldprobe::bus::can::candump::format_line(t, &iface, f);
                let meaning = fieldprobe::bus::canopen::describe(f);
                if plain || meaning.is_empty() {
                    outln!("{line}");
                } else {
                    outln!("{line}  ; {meaning}");
                }
            });
            super::finish_capture(session.finish_capture());
            heard.map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok(EXIT_OK)
        }
    }
}
