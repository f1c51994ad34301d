//! Command-line interface. Contract (DESIGN.md, stable):
//!
//! ```text
//! fieldprobe run PROGRAM.nc [--machine FILE.toml] [--link LINK] [--set KEY=VALUE]...
//!                           [--probe-at AXIS=POS]... [--fixed-stop-at AXIS=POS]... [--json]
//! ```
//! stdout: `#MSG` lines; stderr: `warning|error <ID>: <text> (N<block>)`; exit 0 program ended,
//! 1 aborted by a CNC error, 2 bad input. Every `--set` is checked against its own data range
//! where it stands; the checks between parameters (P-AXIS-00177 < P-AXIS-00178, …) run once
//! after all of them, so their order does not matter.
//!
//! Further subcommands in the same style: `check`, `jog`, `params`, `esi`, `scan`, `sdo`, `idn`,
//! `can`, `sim`, and `areas plot PROGRAM.nc --out FILE.svg|FILE.png` (seed 000 control areas,
//! see `docs/areas.md`).

/// `println!` for the tool's results on stdout that survives a reader going away
/// (`fieldprobe run … | head`): the first failed write is reported once on stderr and later
/// output is dropped, while the command goes on to its end (a run still stops its axes and
/// disables its drives as it would otherwise). `println!` would panic instead.
macro_rules! outln {
    () => {
        $crate::cli::write_stdout(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!("{}\n", format_args!($($arg)*)))
    };
}

mod areas;
mod bus;
mod check;
mod esi;
mod jog;
mod params;
mod plot;
mod run;
mod sim;
mod trace;

use clap::{Parser, Subcommand};

/// Exit code: program ran to its end.
pub const EXIT_OK: i32 = 0;
/// Exit code: aborted by a CNC error.
pub const EXIT_CNC_ERROR: i32 = 1;
/// Exit code: bad input (program, machine file, arguments).
pub const EXIT_BAD_INPUT: i32 = 2;

#[derive(Debug, Parser)]
#[command(
    name = "fieldprobe",
    version,
    about = "Fieldbus drive-probing stack and commissioning tool"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run an NC program on the machine (default: emulated CiA 402 axes X, Y, Z).
    Run(run::RunArgs),
    /// Workspace and protection areas of an NC program: `areas plot` draws them, the executed
    /// path and the first violation into an SVG or PNG file.
    Areas(areas::AreasArgs),
    /// Manual mode: jog one axis continuously or by an increment and report where it stopped.
    Jog(jog::JogArgs),
    /// List the parameters of the seeds (ID, name path, type, default, range).
    Params(params::ParamsArgs),
    /// Commissioning check: drive settings against the axis parameters, in plain words.
    Check(check::CheckArgs),
    /// EtherCAT Slave Information (ESI XML) files: show devices, PDOs, mailbox, DC, objects.
    Esi(esi::EsiArgs),
    /// Emulate EtherCAT devices (from ESI files) on a network interface for a real master.
    Sim(sim::SimArgs),
    /// List the EtherCAT SubDevices: position, address, identity, AL state, DC, name.
    Scan(bus::ScanArgs),
    /// Read or write an object by SDO: CoE on an EtherCAT SubDevice (`--device`) or a CANopen
    /// node (`--node`).
    Sdo(bus::SdoArgs),
    /// CANopen bus: find nodes, dump frames.
    Can(bus::CanArgs),
    /// Read or write a SERCOS IDN (SoE) of an EtherCAT SubDevice.
    Idn(bus::IdnArgs),
}

/// Parse arguments, run, return the exit code.
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() {
                EXIT_BAD_INPUT
            } else {
                EXIT_OK
            };
            let _ = e.print();
            return code;
        }
    };
    let result = match cli.command {
        Command::Run(a) => run::run(a),
        Command::Jog(a) => jog::run(a),
        Command::Areas(a) => areas::run(a),
        Command::Params(a) => params::run(a),
        Command::Check(a) => check::run(a),
        Command::Esi(a) => esi::run(a),
        Command::Sim(a) => sim::run(a),
        Command::Scan(a) => bus::scan(a),
        Command::Sdo(a) => bus::sdo(a),
        Command::Can(a) => bus::can(a),
        Command::Idn(a) => bus::idn(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fieldprobe: {e:#}");
            EXIT_BAD_INPUT
        }
    }
}

/// Read and parse an NC program. A parse error is printed as `file:line:col: message` and gives
/// `Ok(None)` (the caller exits with [`EXIT_BAD_INPUT`]); an unreadable file is an `Err`.
fn load_program(path: &std::path::Path) -> anyhow::Result<Option<fieldprobe::nc::ast::Program>> {
    use anyhow::Context;
    let file = path.display().to_string();
    let src =
        fieldprobe::limits::read_text(path, "NC program", fieldprobe::limits::MAX_NC_PROGRAM_BYTES)
            .with_context(|| format!("cannot read {file}"))?;
    match fieldprobe::nc::parser::parse(&src) {
        Ok(p) => Ok(Some(p)),
        Err(e) => {
            eprintln!("{file}:{}:{}: {}", e.line, e.col, e.message);
            Ok(None)
        }
    }
}

/// Load the machine file (or the default machine) and apply `--set` assignments.
fn load_machine(
    machine: Option<&std::path::Path>,
    sets: &[String],
) -> anyhow::Result<fieldprobe::params::MachineConfig> {
    let mut cfg = match machine {
        Some(p) => fieldprobe::params::MachineConfig::load(p)?,
        None => fieldprobe::params::MachineConfig::default_machine(),
    };
    // All `--set`s first, then the cross checks: their order does not matter.
    cfg.apply_sets(sets)?;
    Ok(cfg)
}

/// `--link` / `--pcap` of the commands that run a machine.
#[derive(Debug, Clone, clap::Args)]
pub struct LinkArgs {
    /// Link to the drives: `sim` (drive models in memory), `ethercat-emu` (ethercrab against
    /// emulated EtherCAT drives in-process), `ethercat:IFACE` (ethercrab on a network
    /// interface), `canopen-emu` (our CANopen master against emulated CiA 402 nodes on an
    /// in-process virtual bus), `canopen-udp[:GROUP:PORT]` (python-can udp_multicast bus) or
    /// `socketcan:IF`. Default: `ethercat-emu` when every axis has a CiA 402, SERCOS or EL5101 drive (the
    /// families the EtherCAT emulator plays), else `sim`.
    #[arg(long, value_name = "LINK")]
    link: Option<String>,
    /// Write every EtherCAT frame (both directions) into this pcap file (EtherCAT links; refused
    /// on the others).
    #[arg(long, value_name = "FILE.pcap")]
    pcap: Option<std::path::PathBuf>,
    /// Log every CAN frame (both directions) in candump -L format into this file (CAN links;
    /// refused on the others). The interface field is a kernel name: `vcan0` for
    /// `socketcan:vcan0`, `udp0` for canopen-udp, `emu0` for canopen-emu.
    #[arg(long, value_name = "FILE.log")]
    candump: Option<std::path::PathBuf>,
    /// One CSV row per cycle (deadline, send time, period error, round trip, missed, lost, DC
    /// system-time difference) for links that leave the process (ethercat:IF, canopen-udp,
    /// socketcan:IF).
    #[arg(long, value_name = "FILE.csv")]
    cycle_log: Option<std::path::PathBuf>,
    /// Real-time options of the cyclic thread.
    #[command(flatten)]
    rt: RtArgs,
}

/// `--rt-priority`, `--cpu`, `--mlock`: the real-time knobs of `run` (the cyclic thread of a
/// link that leaves the process) and of `sim` (the emulator's threads on an interface or bus,
/// which play devices with their own hardware clock).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RtArgs {
    /// SCHED_FIFO at this priority (1 ..= 99; needs CAP_SYS_NICE or RLIMIT_RTPRIO). `run`:
    /// links that leave the process only.
    #[arg(long, value_name = "N")]
    rt_priority: Option<u8>,
    /// Pin to this CPU. `run`: links that leave the process only.
    #[arg(long, value_name = "N")]
    cpu: Option<usize>,
    /// Lock all memory (mlockall) so no page fault delays a cycle. `run`: links that leave the
    /// process only.
    #[arg(long)]
    mlock: bool,
}

impl RtArgs {
    /// The options given.
    pub fn options(&self) -> fieldprobe::rt::RtOptions {
        fieldprobe::rt::RtOptions {
            priority: self.rt_priority,
            cpu: self.cpu,
            lock_memory: self.mlock,
        }
    }

    /// Check and apply them to the calling thread and the process (threads spawned later
    /// inherit the scheduling policy and the affinity); `who` prefixes the messages. The
    /// error text names the option and the reason (the caller exits 2).
    pub fn check_and_apply(&self, who: &str) -> Result<(), String> {
        let rt = self.options();
        rt.check().map_err(|e| e.to_string())?;
        for what in rt.apply().map_err(|e| e.to_string())? {
            eprintln!("{who}: real-time: {what}");
        }
        Ok(())
    }
}

impl LinkArgs {
    /// The link for `cfg`.
    pub fn choice(
        &self,
        cfg: &fieldprobe::params::MachineConfig,
    ) -> fieldprobe::machine::LinkChoice {
        let link = match &self.link {
            Some(l) => l.clone(),
            None => default_link(cfg).to_string(),
        };
        fieldprobe::machine::LinkChoice {
            link,
            pcap: self.pcap.clone(),
            candump: self.candump.clone(),
            cycle_log: self.cycle_log.clone(),
        }
    }

    /// The real-time options given (`--rt-priority`, `--cpu`, `--mlock`).
    pub fn rt(&self) -> fieldprobe::rt::RtOptions {
        self.rt.options()
    }

    /// Refuse the real-time options and the cycle log on a link that runs on virtual time, and
    /// options no system could take (priority out of 1 ..= 99, a CPU that does not exist).
    /// Errors name the option and the reason; the caller exits 2. The options are applied once
    /// the link is open ([`fieldprobe::rt::RtOptions::apply`]).
    pub fn check_rt(&self, choice: &fieldprobe::machine::LinkChoice) -> Result<(), String> {
        let rt = self.rt();
        let wants = !rt.is_empty() || self.cycle_log.is_some();
        if wants && !choice.leaves_process() {
            let mut given = Vec::new();
            if let Some(p) = rt.priority {
                given.push(format!("--rt-priority {p}"));
            }
            if let Some(c) = rt.cpu {
                given.push(format!("--cpu {c}"));
            }
            if rt.lock_memory {
                given.push("--mlock".into());
            }
            if let Some(p) = &self.cycle_log {
                given.push(format!("--cycle-log {}", p.display()));
            }
            return Err(format!(
                "{}: only for links that leave the process (ethercat:IF, canopen-udp[:GROUP:PORT], socketcan:IF); --link {} runs on virtual time",
                given.join(", "),
                choice.link
            ));
        }
        rt.check().map_err(|e| e.to_string())
    }
}

/// `ethercat-emu` when every axis's drive is one the EtherCAT emulator plays, else `sim`.
fn default_link(cfg: &fieldprobe::params::MachineConfig) -> &'static str {
    use fieldprobe::drive::catalogue;
    let emulated = cfg.axes.iter().all(|a| {
        catalogue::load(&a.drive).is_ok_and(|d| fieldprobe::link::ethercat::esi_for(&d).is_some())
    });
    if emulated {
        "ethercat-emu"
    } else {
        "sim"
    }
}

/// Write to stdout; see [`outln!`].
pub(crate) fn write_stdout(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};
    static FAILED: AtomicBool = AtomicBool::new(false);
    if FAILED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        if !FAILED.swap(true, Ordering::Relaxed) {
            eprintln!("fieldprobe: writing to stdout failed ({e}); further output is dropped");
        }
    }
}
