//! Command-line interface. Contract (DESIGN.md, stable):
//!
//! ```text
//! fieldprobe run PROGRAM.nc [--machine FILE.toml] [--link LINK] [--set KEY=VALUE]...
//!                           [--probe-at AXIS=POS]... [--fixed-stop-at AXIS=POS]... [--json]
//!                           [--quiet]
//! ```
//! stdout: `#MSG` lines; stderr: `warning|error <ID>: <text> (N<block>)`; exit 0 program ended,
//! 1 aborted by a CNC error, 2 bad input. Every `--set` is checked against its own data range
//! where it stands; the checks between parameters (P-AXIS-00177 < P-AXIS-00178, …) run once
//! after all of them, so their order does not matter.
//!
//! Further subcommands in the same style: `check`, `jog`, `params`, `esi`, `scan`, `sdo`, `sdos`,
//! `pdos` ([`sdos`], [`pdos`]: dictionary and PDO configuration read from a device), `idn`,
//! `can`, `sim`, `drive` (definitions from vendor ESI / EDS files), and `areas plot PROGRAM.nc
//! --out FILE.svg|FILE.png` (FCT-C14 control areas,
//! see `docs/areas.md`).
//!
//! Every number on the command line follows one grammar (decimal or `0x` hex, negative values
//! without `--`; an object index without `0x` is decimal): [`number`], docs/cli.md "Numbers on
//! the command line". `--quiet`: no progress line on a terminal ([`progress`]).

/// `println!` for the tool's results on stdout that survives a reader going away
/// (`fieldprobe run … | head`, `> /dev/full`): the first failed write is reported once on
/// stderr and later output is dropped, while the command goes on to its end (a run still stops
/// its axes and disables its drives as it would otherwise); [`main`] then exits with
/// [`EXIT_BAD_INPUT`] instead of 0 (docs/cli.md "Exit codes"). `println!` would panic instead.
/// Every write to stdout in the CLI goes through this macro.
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
pub(crate) mod canopen_od;
mod check;
mod drive;
mod esi;
mod esi_load;
mod jog;
mod number;
mod params;
mod pdos;
mod plot;
mod progress;
mod run;
mod sdo;
mod sdos;
mod sim;
mod trace;
mod value;

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
    Sdo(sdo::SdoArgs),
    /// List a device's object dictionary like IgH `ethercat sdos`: CoE SDO Information on an
    /// EtherCAT SubDevice (`--device`); the EDS (`--eds`) checked by SDO plus an SDO scan on a
    /// CANopen node (`--node`).
    Sdos(sdos::SdosArgs),
    /// The PDO configuration read from a device: sync managers, assignment 0x1C12/0x1C13 and
    /// mappings like IgH `ethercat pdos` (`--device`); RPDO/TPDO communication and mapping
    /// parameters 0x1400–0x1BFF (`--node`).
    Pdos(pdos::PdosArgs),
    /// CANopen bus: find nodes, dump frames.
    Can(bus::CanArgs),
    /// Read or write a SERCOS IDN (SoE) of an EtherCAT SubDevice.
    Idn(bus::IdnArgs),
    /// Drive definitions: write one from a vendor's ESI or EDS file.
    Drive(drive::DriveArgs),
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
            if let Err(w) = e.print() {
                eprintln!("fieldprobe: writing to stdout failed ({w})");
                return EXIT_BAD_INPUT;
            }
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
        Command::Sdo(a) => sdo::sdo(a),
        Command::Sdos(a) => sdos::run(a),
        Command::Pdos(a) => pdos::run(a),
        Command::Can(a) => bus::can(a),
        Command::Idn(a) => bus::idn(a),
        Command::Drive(a) => drive::run(a),
    };
    let code = match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fieldprobe: {}", cap_echo(&error_text(&e)));
            EXIT_BAD_INPUT
        }
    };
    exit_code_after_output(code)
}

/// An error and its causes as one line, each thing said once: a cause whose text the line
/// holds already (an error type that prints its source in its own text) is not repeated, and
/// [`said_once`] removes a part that follows itself.
pub fn error_text(e: &anyhow::Error) -> String {
    let mut text = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !text.contains(&c) {
            text.push_str(": ");
            text.push_str(&c);
        }
    }
    said_once(&text)
}

/// `text` with every `: `-separated part that repeats the part before it removed: the layers
/// of a message that each name the same thing say it once. A part repeats the one before when
/// it is equal (`node 9: SDO 0x1000:00: SDO 0x1000:00: no response`) or when it is a single
/// name (no blank, not only digits) the part before ends with (`--link ethercat:lo:
/// ethercat:lo: interface lo: …`).
pub fn said_once(text: &str) -> String {
    let mut parts: Vec<&str> = Vec::new();
    for part in text.split(": ") {
        let repeats = parts.last().is_some_and(|before| {
            *before == part
                || (!part.contains(char::is_whitespace)
                    && !part.bytes().all(|b| b.is_ascii_digit())
                    && before
                        .strip_suffix(part)
                        .is_some_and(|head| head.ends_with(char::is_whitespace)))
        });
        if !repeats {
            parts.push(part);
        }
    }
    parts.join(": ")
}

/// `prefix: text`, said once ([`said_once`]): `--link ethercat:lo` + `ethercat:lo: interface
/// lo: …` is `--link ethercat:lo: interface lo: …`.
pub fn prefixed(prefix: &str, text: impl std::fmt::Display) -> String {
    said_once(&format!("{prefix}: {text}"))
}

/// A command whose stdout or capture file could not be written did not deliver its result: it
/// never exits 0. A nonzero code the command chose (1: CNC error) stays; 0 becomes
/// [`EXIT_BAD_INPUT`] — the output the caller gave us (a full disk, a closed pipe) could not
/// take the result. The failure was reported on stderr ([`write_stdout`], [`finish_capture`]).
fn exit_code_after_output(code: i32) -> i32 {
    if code == EXIT_OK && stdout_failed() {
        EXIT_BAD_INPUT
    } else {
        code
    }
}

/// Longest run of non-blank characters echoed into a message as given; a longer one (a
/// 10-million-digit number in an NC program or a machine file, a runaway argument) is cut to
/// [`ECHO_KEEP`] characters and `…`, with its length. File paths (at most 4096 bytes on Linux)
/// of ordinary length pass unchanged.
pub const ECHO_MAX: usize = 256;
/// Characters kept of a cut token.
pub const ECHO_KEEP: usize = 64;

/// `text` with every run of non-blank characters longer than [`ECHO_MAX`] characters cut (see
/// there). Applied to every error message the CLI prints from a parser or from `anyhow`.
pub fn cap_echo(text: &str) -> std::borrow::Cow<'_, str> {
    let too_long = text
        .split(char::is_whitespace)
        .any(|w| w.chars().nth(ECHO_MAX).is_some());
    if !too_long {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::new();
    let mut rest = text;
    while !rest.is_empty() {
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        let (word, tail) = rest.split_at(end);
        let n = word.chars().count();
        if n > ECHO_MAX {
            out.extend(word.chars().take(ECHO_KEEP));
            out.push_str(&format!("… ({n} characters)"));
        } else {
            out.push_str(word);
        }
        let blank = tail.len() - tail.trim_start().len();
        out.push_str(&tail[..blank]);
        rest = &tail[blank..];
    }
    std::borrow::Cow::Owned(out)
}

/// Longest time a `--seconds` option takes: about 31.7 years, far beyond any test or
/// commissioning session, and far inside what `Instant` and `Duration` hold.
pub const MAX_SECONDS: f64 = 1e9;

/// Read a `--seconds` value (`option` names it in the message): a real number
/// ([`number::real`]), 0 … [`MAX_SECONDS`]. The caller exits 2 on the error.
pub fn seconds_option(option: &str, text: &str) -> anyhow::Result<std::time::Duration> {
    let s = number::real_option(option, text, 0.0, MAX_SECONDS, "a number of seconds")?;
    Ok(std::time::Duration::from_secs_f64(s))
}

/// The instant `d` after now; `option` names the option in the (unlikely) error of a clock
/// that cannot reach it.
pub fn deadline_after(option: &str, d: std::time::Duration) -> anyhow::Result<std::time::Instant> {
    std::time::Instant::now()
        .checked_add(d)
        .ok_or_else(|| anyhow::anyhow!("{option}: {} s is beyond this system's clock", d.as_secs()))
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
            eprintln!("{file}:{}:{}: {}", e.line, e.col, cap_echo(&e.message));
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
    #[arg(long, value_name = "N", value_parser = number::value_priority, allow_hyphen_values = true)]
    rt_priority: Option<u8>,
    /// Pin to this CPU. `run`: links that leave the process only.
    #[arg(long, value_name = "N", value_parser = number::value_cpu, allow_hyphen_values = true)]
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

/// Set once a write to stdout failed.
static STDOUT_FAILED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Set once an output file (`--pcap`, `--candump`) could not be written.
static CAPTURE_FAILED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// A write to stdout or to a capture file failed (the command must not exit 0).
pub(crate) fn stdout_failed() -> bool {
    STDOUT_FAILED.load(std::sync::atomic::Ordering::Relaxed)
        || CAPTURE_FAILED.load(std::sync::atomic::Ordering::Relaxed)
}

/// The end of a command that wrote a frame capture: a write that failed is reported on stderr
/// (the message names the option and the file) and the command does not exit 0
/// ([`exit_code_after_output`]); its own result (an SDO value, `#MSG` lines) is still given.
pub(crate) fn finish_capture(result: Result<(), String>) {
    if let Err(e) = result {
        eprintln!("fieldprobe: {}", cap_echo(&e));
        CAPTURE_FAILED.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Write to stdout; see [`outln!`].
pub(crate) fn write_stdout(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if STDOUT_FAILED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        if !STDOUT_FAILED.swap(true, Ordering::Relaxed) {
            eprintln!("fieldprobe: writing to stdout failed ({e}); further output is dropped");
        }
    }
}

/// Erase the progress line of `run`, if one is shown (before the log writes to stderr).
pub fn clear_progress() {
    progress::clear();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn said_once_drops_a_part_that_repeats_the_one_before() {
        assert_eq!(
            said_once("node 9: SDO 0x1000:00: SDO 0x1000:00: no response"),
            "node 9: SDO 0x1000:00: no response"
        );
        assert_eq!(said_once("a: b: a: b"), "a: b: a: b");
        assert_eq!(said_once("x"), "x");
        assert_eq!(
            said_once("--link ethercat:lo: ethercat:lo: interface lo: gone"),
            "--link ethercat:lo: interface lo: gone"
        );
        // Numbers and phrases are not names: kept.
        assert_eq!(said_once("--node 5: 5: x"), "--node 5: 5: x");
        assert_eq!(said_once("axis Z: moved Z: x"), "axis Z: moved Z: x");
    }

    #[test]
    fn prefixed_does_not_repeat_the_prefix_word() {
        assert_eq!(
            prefixed("--link ethercat:lo", "ethercat:lo: interface lo: gone"),
            "--link ethercat:lo: interface lo: gone"
        );
        assert_eq!(
            prefixed("--link canopen-emu", "node id 0: allowed 1 … 127"),
            "--link canopen-emu: node id 0: allowed 1 … 127"
        );
    }

    #[derive(Debug)]
    struct Inner;
    impl std::fmt::Display for Inner {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("Operation not permitted (os error 1)")
        }
    }
    impl std::error::Error for Inner {}

    /// An error that prints its source in its own text and also returns it as `source()`.
    #[derive(Debug)]
    struct Outer(Inner);
    impl std::fmt::Display for Outer {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(
                f,
                "interface lo: cannot open a raw packet socket: {}",
                self.0
            )
        }
    }
    impl std::error::Error for Outer {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.0)
        }
    }

    #[test]
    fn error_text_says_a_cause_once() {
        let e = anyhow::Error::new(Outer(Inner));
        assert_eq!(
            error_text(&e),
            "interface lo: cannot open a raw packet socket: Operation not permitted (os error 1)"
        );
        let e = anyhow::Error::new(Inner).context("--trace t.svg");
        assert_eq!(
            error_text(&e),
            "--trace t.svg: Operation not permitted (os error 1)"
        );
    }
}
