//! Commissioning commands on a bus: `scan`, `idn read|write`, `can scan|dump` here, `sdo
//! read|write` in [`super::sdo`].
//!
//! ```text
//! fieldprobe scan [--link ethercat-emu|ethercat:IFACE] [--machine FILE.toml] [--set KEY=VALUE]... [--pcap FILE]
//! fieldprobe idn read  [--link …] --device N S-0-0092
//! fieldprobe idn write [--link …] --device N S-0-0092 VALUE
//! fieldprobe can scan|dump [--link canopen-emu|canopen-udp[:GROUP:PORT]|socketcan:IF] [--candump FILE]
//! ```
//! The EtherCAT bus is brought to PRE-OP (no process data); `--device` is the ring position
//! `scan` prints. `ethercat-emu` (default) is the emulated segment of the machine file (a
//! coupler, then one drive per axis). Errors name the device and the object, with the SDO abort
//! code / SoE error in words. Exit 0; 1 when the device refuses the access; 2 on bad input or a
//! bus error.
//!
//! Each command has its own option set (docs/cli.md "Options per command"): `scan` and `idn`
//! offer the EtherCAT links and `--pcap`, `can` the CAN links and `--candump`, `sdo` both. The
//! capture option of the other bus family is not shown in a command's help; given anyway, it
//! is refused with a message that names the option, the link and where those frames go.

use super::{load_machine, number, prefixed, said_once, EXIT_BAD_INPUT, EXIT_CNC_ERROR, EXIT_OK};
use anyhow::Context;
use fieldprobe::bus::can::Bitrate;
use fieldprobe::link::canopen::CanSession;
use fieldprobe::link::ethercat::{EthercatSpec, Session, Wire};
use fieldprobe::link::LinkError;
use std::path::PathBuf;

/// A `--link` of the bus commands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusLink {
    /// `ethercat-emu`.
    EthercatEmu,
    /// `ethercat:IFACE`.
    Ethercat(String),
    /// `canopen-emu`.
    CanopenEmu,
    /// `canopen-udp[:GROUP:PORT]` (checked when opened).
    CanopenUdp,
    /// `socketcan:IF`.
    SocketCan,
}

/// The bus families a command works on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// EtherCAT only (`scan`, `idn`).
    Ethercat,
    /// CAN only (`can scan`, `can dump`).
    Can,
    /// Both (`sdo`).
    Both,
}

/// The EtherCAT links, for help and messages.
pub const ETHERCAT_LINKS: &str = "ethercat-emu (the emulated segment of the machine file) or \
                                  ethercat:IFACE (a network interface)";
/// The CAN links, for help and messages.
pub const CAN_LINKS: &str = "canopen-emu (the emulated nodes of the machine file), \
                             canopen-udp[:GROUP:PORT] or socketcan:IF";

impl Family {
    fn allowed(self) -> String {
        match self {
            Family::Ethercat => ETHERCAT_LINKS.to_string(),
            Family::Can => CAN_LINKS.to_string(),
            Family::Both => format!("{ETHERCAT_LINKS}; {CAN_LINKS}"),
        }
    }
}

impl BusLink {
    /// Parse `text`; the error says why (without the option).
    fn parse(text: &str) -> Result<BusLink, &'static str> {
        if text == "ethercat-emu" {
            return Ok(BusLink::EthercatEmu);
        }
        if text == "canopen-emu" {
            return Ok(BusLink::CanopenEmu);
        }
        if text == "canopen-udp" || text.starts_with("canopen-udp:") {
            return Ok(BusLink::CanopenUdp);
        }
        if let Some(i) = text.strip_prefix("ethercat:") {
            return match i {
                "" => Err("no interface name after `ethercat:`"),
                i => Ok(BusLink::Ethercat(i.to_string())),
            };
        }
        if let Some(i) = text.strip_prefix("socketcan:") {
            return match i {
                "" => Err("no interface name after `socketcan:`"),
                _ => Ok(BusLink::SocketCan),
            };
        }
        Err("unknown link")
    }

    /// A CAN link.
    pub fn is_can(&self) -> bool {
        matches!(
            self,
            BusLink::CanopenEmu | BusLink::CanopenUdp | BusLink::SocketCan
        )
    }

    /// A link to emulated devices (the machine file describes them).
    fn is_emulated(&self) -> bool {
        matches!(self, BusLink::EthercatEmu | BusLink::CanopenEmu)
    }
}

/// `--link TEXT` of `command`, checked against the families it works on. The messages name
/// the link and list what the command takes; a link of the other family says which command
/// serves it.
fn parse_link(command: &str, text: &str, family: Family) -> anyhow::Result<BusLink> {
    let link = BusLink::parse(text).map_err(|why| {
        anyhow::anyhow!(
            "--link {}: {why}; `{command}` takes {}",
            super::cap_echo(text),
            family.allowed()
        )
    })?;
    match (family, link.is_can()) {
        (Family::Ethercat, true) if command == "scan" => anyhow::bail!(
            "--link {text}: `scan` lists EtherCAT SubDevices ({ETHERCAT_LINKS}); CANopen nodes: `can scan`"
        ),
        (Family::Ethercat, true) => anyhow::bail!(
            "--link {text}: `{command}` reaches SERCOS IDNs of EtherCAT SubDevices (SoE); expected {ETHERCAT_LINKS}"
        ),
        (Family::Can, false) => anyhow::bail!(
            "--link {text}: `{command}` needs a CAN link ({CAN_LINKS}); EtherCAT SubDevices: `scan`"
        ),
        _ => Ok(link),
    }
}

/// `--link`, `--machine`, `--set`, `--pcap`, `--candump` of `scan` and `idn`.
#[derive(Debug, Clone, clap::Args)]
pub struct EthercatBusArgs {
    /// EtherCAT link: `ethercat-emu` (the emulated segment of the machine file: a coupler,
    /// then one drive per axis) or `ethercat:IFACE` (a network interface). CANopen nodes: see
    /// `can scan` and `sdo --node`.
    #[arg(long, value_name = "LINK", default_value = "ethercat-emu")]
    link: String,
    /// Machine file whose axes the emulated devices are (ethercat-emu only).
    #[arg(long, value_name = "FILE.toml")]
    machine: Option<PathBuf>,
    /// Parameter assignment for the machine file (e.g. `Z.drive=sercos-ax5000`; ethercat-emu
    /// only, as `--machine`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Write every EtherCAT frame (both directions) into this pcap file.
    #[arg(long, value_name = "FILE.pcap")]
    pcap: Option<PathBuf>,
    /// Not offered (CAN links only); refused with a message when given.
    #[arg(long, value_name = "FILE.log", hide = true)]
    candump: Option<PathBuf>,
}

impl EthercatBusArgs {
    /// The bus of `command`, its options checked.
    pub fn bus(&self, command: &str) -> anyhow::Result<Bus> {
        let link = parse_link(command, &self.link, Family::Ethercat)?;
        Bus::new(
            command,
            link,
            &self.link,
            &self.machine,
            &self.sets,
            &self.pcap,
            &self.candump,
        )
    }
}

/// `--link`, `--machine`, `--set`, `--candump`, `--pcap` of `can scan` and `can dump`.
#[derive(Debug, Clone, clap::Args)]
pub struct CanBusArgs {
    /// CAN link: `canopen-emu` (the emulated CiA 402 nodes of the machine file, ids 1 …),
    /// `canopen-udp[:GROUP:PORT]` (python-can udp_multicast bus) or `socketcan:IF`.
    #[arg(long, value_name = "LINK", default_value = "canopen-emu")]
    link: String,
    /// Machine file whose axes the emulated nodes are (canopen-emu only).
    #[arg(long, value_name = "FILE.toml")]
    machine: Option<PathBuf>,
    /// Parameter assignment for the machine file (canopen-emu only, as `--machine`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Log every CAN frame (both directions) in candump -L format into this file.
    #[arg(long, value_name = "FILE.log")]
    candump: Option<PathBuf>,
    /// Not offered (EtherCAT links only); refused with a message when given.
    #[arg(long, value_name = "FILE.pcap", hide = true)]
    pcap: Option<PathBuf>,
}

impl CanBusArgs {
    /// The bus of `command`, its options checked.
    pub fn bus(&self, command: &str) -> anyhow::Result<Bus> {
        let link = parse_link(command, &self.link, Family::Can)?;
        Bus::new(
            command,
            link,
            &self.link,
            &self.machine,
            &self.sets,
            &self.pcap,
            &self.candump,
        )
    }
}

/// `--link`, `--machine`, `--set`, `--pcap`, `--candump` of `sdo`, which works on both bus
/// families.
#[derive(Debug, Clone, clap::Args)]
pub struct SdoBusArgs {
    /// Link: `ethercat-emu` (default with --device; the emulated segment of the machine file),
    /// `ethercat:IFACE`, `canopen-emu` (default with --node; the emulated nodes of the machine
    /// file, ids 1 …), `canopen-udp[:GROUP:PORT]` or `socketcan:IF`.
    #[arg(long, value_name = "LINK")]
    link: Option<String>,
    /// Machine file whose axes the emulated devices are (ethercat-emu, canopen-emu).
    #[arg(long, value_name = "FILE.toml")]
    machine: Option<PathBuf>,
    /// Parameter assignment for the machine file (emulated links only, as `--machine`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Write every EtherCAT frame into this pcap file (EtherCAT links; refused on CAN links).
    #[arg(long, value_name = "FILE.pcap")]
    pcap: Option<PathBuf>,
    /// Log every CAN frame in candump -L format into this file (CAN links; refused on
    /// EtherCAT links).
    #[arg(long, value_name = "FILE.log")]
    candump: Option<PathBuf>,
}

impl SdoBusArgs {
    /// The bus of `command`; without `--link`, `canopen-emu` when the target is a node
    /// (`node` true), else `ethercat-emu`.
    pub fn bus(&self, command: &str, node: bool) -> anyhow::Result<Bus> {
        let text = match &self.link {
            Some(l) => l.as_str(),
            None if node => "canopen-emu",
            None => "ethercat-emu",
        };
        let link = parse_link(command, text, Family::Both)?;
        Bus::new(
            command,
            link,
            text,
            &self.machine,
            &self.sets,
            &self.pcap,
            &self.candump,
        )
    }
}

/// A checked bus: the link and the options that apply to it.
#[derive(Debug, Clone)]
pub struct Bus {
    /// The link.
    pub link: BusLink,
    /// `--link` as given.
    pub text: String,
    machine: Option<PathBuf>,
    sets: Vec<String>,
    pcap: Option<PathBuf>,
    candump: Option<PathBuf>,
}

impl Bus {
    /// Refuse the options `command` does not use on this link, naming option and link (exit
    /// 2), instead of ignoring them: `--pcap` on a CAN link, `--candump` on an EtherCAT link,
    /// `--machine` / `--set` on a link that reaches a real bus (they describe the emulated
    /// devices of `ethercat-emu` and `canopen-emu` only).
    fn new(
        command: &str,
        link: BusLink,
        text: &str,
        machine: &Option<PathBuf>,
        sets: &[String],
        pcap: &Option<PathBuf>,
        candump: &Option<PathBuf>,
    ) -> anyhow::Result<Bus> {
        if link.is_can() {
            if let Some(p) = pcap {
                anyhow::bail!(
                    "--pcap {}: `{command}` on --link {text} (a CAN link) writes no pcap capture; the CAN frames go to --candump FILE.log",
                    p.display()
                );
            }
        } else if let Some(p) = candump {
            anyhow::bail!(
                "--candump {}: `{command}` on --link {text} writes no candump log (CAN links only: {CAN_LINKS}); EtherCAT frames go to --pcap FILE.pcap",
                p.display()
            );
        }
        if !link.is_emulated() {
            let mut given = Vec::new();
            if let Some(m) = machine {
                given.push(format!("--machine {}", m.display()));
            }
            given.extend(sets.iter().map(|s| format!("--set {s}")));
            if !given.is_empty() {
                anyhow::bail!(
                    "{}: `{command}` on --link {text} talks to the devices on the bus; the machine file describes the emulated devices of --link ethercat-emu / canopen-emu only",
                    given.join(", ")
                );
            }
        }
        Ok(Bus {
            link,
            text: text.to_string(),
            machine: machine.clone(),
            sets: sets.to_vec(),
            pcap: pcap.clone(),
            candump: candump.clone(),
        })
    }

    /// The machine's drives and CANopen node ids (the emulated devices).
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

    /// The node ids of the emulated nodes (`canopen-emu`), `None` on a real bus.
    pub fn emulated_nodes(&self) -> anyhow::Result<Option<Vec<u8>>> {
        Ok(match self.link {
            BusLink::CanopenEmu => Some(self.drives()?.1),
            _ => None,
        })
    }

    /// `--link TEXT: …` said once (a link error that starts with the link's name again).
    fn link_error(&self, e: impl std::fmt::Display) -> anyhow::Error {
        anyhow::anyhow!(prefixed(&format!("--link {}", self.text), e))
    }

    /// Open the CAN link: `canopen-emu` on a wire at the machine file's `[can] bitrate`
    /// (default 1 Mbit/s), as `run` does; a real bus at its own.
    pub fn open_can(&self) -> anyhow::Result<CanSession> {
        let (drives, ids, bitrate) = if self.link == BusLink::CanopenEmu {
            let cfg = load_machine(self.machine.as_deref(), &self.sets)?;
            let bitrate = Bitrate::new(cfg.can_bitrate)
                .ok_or_else(|| anyhow::anyhow!("{}: [can] bitrate = 0", cfg.source))?;
            let (drives, ids) = self.drives()?;
            (drives, ids, bitrate)
        } else {
            (Vec::new(), Vec::new(), Bitrate::DEFAULT)
        };
        CanSession::open(&self.text, &drives, &ids, bitrate, self.candump.as_deref())
            .map_err(|e| self.link_error(e))
    }

    /// Open the EtherCAT link (PRE-OP).
    pub fn open(&self) -> anyhow::Result<Session> {
        let wire = Wire::from_link(&self.text)
            .with_context(|| format!("--link {}: expected {ETHERCAT_LINKS}", self.text))?;
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
        Session::open(&wire, &spec).map_err(|e| match (&self.link, &e) {
            // Nothing on that wire answered the bus initialisation's first frame (a broadcast
            // read every SubDevice answers), however often it was sent.
            (
                BusLink::Ethercat(iface),
                LinkError::NoAnswer {
                    answered_before: false,
                    ..
                },
            ) => anyhow::anyhow!(
                "--link {}: {e}; check that a device is connected to {iface} and powered",
                self.text
            ),
            _ => self.link_error(e),
        })
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
    bus: EthercatBusArgs,
}

/// `fieldprobe scan`.
pub fn scan(a: ScanArgs) -> anyhow::Result<i32> {
    let bus = a.bus.bus("scan")?;
    let mut s = bus.open()?;
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

/// Exit code and message for an access that failed: 1 when the device refused it, else 2.
pub fn refused(e: LinkError) -> anyhow::Result<i32> {
    eprintln!("fieldprobe: {}", said_once(&e.to_string()));
    Ok(if e.is_refusal() {
        EXIT_CNC_ERROR
    } else {
        EXIT_BAD_INPUT
    })
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
    bus: EthercatBusArgs,
    /// Ring position of the SubDevice (decimal or 0x hex).
    #[arg(long, value_name = "N", value_parser = number::value_ring_position, allow_hyphen_values = true)]
    device: usize,
    /// IDN, e.g. `S-0-0092` or `P-0-0010`.
    idn: String,
}

#[derive(Debug, clap::Args)]
struct IdnWrite {
    #[command(flatten)]
    bus: EthercatBusArgs,
    /// Ring position of the SubDevice (decimal or 0x hex).
    #[arg(long, value_name = "N", value_parser = number::value_ring_position, allow_hyphen_values = true)]
    device: usize,
    /// IDN, e.g. `S-0-0092`.
    idn: String,
    /// Value: an integer, decimal or 0x hex, negative without `--` (e.g. -100).
    #[arg(allow_hyphen_values = true)]
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
            let bus = r.bus.bus("idn")?;
            let mut s = bus.open()?;
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
            let bus = w.bus.bus("idn")?;
            let v = number::int_option(
                "value",
                &w.value,
                i64::MIN.into(),
                i64::MAX.into(),
                "an integer",
            )? as i64;
            let mut s = bus.open()?;
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
    bus: CanBusArgs,
}

#[derive(Debug, clap::Args)]
struct CanDump {
    #[command(flatten)]
    bus: CanBusArgs,
    /// How long to listen, s (0 … 86400).
    #[arg(
        long,
        value_name = "N",
        default_value = "1",
        allow_hyphen_values = true
    )]
    seconds: String,
    /// Plain `candump -L` lines without the `  ; meaning` comment, for tools that read candump
    /// logs (canplayer, log2asc, python-can's `CanutilsLogReader`).
    #[arg(long)]
    plain: bool,
}

/// `fieldprobe can`.
pub fn can(a: CanArgs) -> anyhow::Result<i32> {
    match a.op {
        CanOp::Scan(s) => {
            let bus = s.bus.bus("can scan")?;
            let mut session = bus.open_can()?;
            let nodes = session.scan().map_err(|e| bus.link_error(e));
            super::finish_capture(session.finish_capture());
            let nodes = nodes?;
            if nodes.is_empty() {
                eprintln!(
                    "fieldprobe: no CANopen node answered on --link {} (SDO upload of 0x1000 to node ids 1 … 127)",
                    bus.text
                );
            }
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
            let bus = d.bus.bus("can dump")?;
            let seconds = number::real_option(
                "--seconds",
                &d.seconds,
                0.0,
                86_400.0,
                "a number of seconds",
            )?;
            let mut session = bus.open_can()?;
            let iface = session.log_interface();
            let plain = d.plain;
            // Each frame at the time it came: on canopen-emu the end of its transmission on the
            // bus clock (virtual), elsewhere when the master took it.
            let epoch = session.unix_epoch();
            let heard =
                session.listen(std::time::Duration::from_secs_f64(seconds), &mut |f, at| {
                    let t = epoch + std::time::Duration::from_nanos(at.0);
                    let line = fieldprobe::bus::can::candump::format_line(t, &iface, f);
                    let meaning = fieldprobe::bus::canopen::describe(f);
                    if plain || meaning.is_empty() {
                        outln!("{line}");
                    } else {
                        outln!("{line}  ; {meaning}");
                    }
                });
            super::finish_capture(session.finish_capture());
            heard.map_err(|e| bus.link_error(e))?;
            Ok(EXIT_OK)
        }
    }
}
