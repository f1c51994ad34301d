//! `fieldprobe sim`: emulate EtherCAT devices on a network interface, or CANopen CiA 402 nodes
//! on a CAN bus (`sim canopen`, see [`CanopenArgs`]).
//!
//! ```text
//! fieldprobe sim ethercat --iface IF --device FILE.xml[#SEL][:COUNT]... [--drive POS=DRIVE]...
//!                         [--probe-at POS=MM]... [--probe-input POS:CH]... [--lockstep]
//!                         [--lose-frames N|A..B|A..[,...]] [--seconds N]
//!                         [--rt-priority N] [--cpu N] [--mlock]
//! ```
//! Builds a segment from the ESI files (in the order given; `:COUNT` repeats a device; `#SEL`
//! chooses the device of a file with several and the modules of its slots, as in every command
//! ([`fieldprobe::esi::select`]; without it a file must describe one device); ring positions
//! count from 0 nearest the master), with the SII image generated from the resolved device, and
//! answers EtherCAT frames on `IF` until `--seconds` pass (default: forever) or the process is
//! killed. Needs CAP_NET_RAW (e.g. inside `unshare -rn`).
//!
//! What runs behind each device's process data:
//! * a device whose ESI `Profile/ProfileNo` is 402 (CiA 402 drive), or any device named by
//!   `--drive POS=DRIVE`, is a full emulated servo
//!   ([`emulated_servo`](fieldprobe::sim::esc::device::emulated_servo): CoE server with
//!   segmented transfers, PDO objects 0x1C12/0x1C13/0x16xx/0x1Axx, a CiA 402 drive model
//!   behind SM2/SM3). DRIVE is a built-in drive name or a drive file (`drives/*.toml`); without
//!   `--drive` a 402 device gets the built-in `cia402-generic` (= `drives/cia402-generic.toml`,
//!   whose layout is the default mapping of `esi/fieldprobe-cia402-servo.xml`). The drive's PDO
//!   layout must hold the entries of the ESI's default mapping, else the command fails with
//!   exit 2 — except for a 402 device without `--drive` whose default mapping is not the
//!   built-in drive's (a vendor's ESI): it is played as that vendor's device
//!   ([`emulated_vendor_drive`](fieldprobe::sim::esc::vendor::emulated_vendor_drive): the
//!   ESI's dictionary, default PDOs and remapping rules, the `cia402-generic` model wired by
//!   object index, no touch probe unless the ESI declares 0x60B8 / 0x60B9);
//! * a device whose ESI type name contains `EL1252` is a timestamp terminal
//!   ([`emulated_el1252`](fieldprobe::sim::esc::device::emulated_el1252): 2 channels, continuous
//!   latching); every `--probe-at` surface is also wired to its channel 1 (or, with
//!   `--probe-input POS:CH`, only to channel CH of the terminal at ring position POS), so its
//!   inputs carry the DC system time of each probe edge: the terminal's own system time (the
//!   emulator's clock + the offset 0x0920 the master wrote), on which the servos' SYNC0 runs;
//! * any other device with process data echoes its inverted outputs into its inputs;
//! * a device without process data has no application.
//!
//! The servos' drive models live in a [`World`] (probe surfaces, see [`fieldprobe::sim::plant`]).
//! The emulator keeps its own clock like real devices
//! ([`Stepping::OwnClock`](fieldprobe::sim::esc::segment::Stepping), CLOCK_MONOTONIC): each
//! device's DC system time is that clock + the offset the master wrote (0x0920); a device whose
//! master activates SYNC0 (0x0981, start time 0x0990, cycle 0x09A0) gets its pulses on that
//! clock, and the world steps once per SYNC0 with the outputs present at that instant (several
//! frames in one period: the last one counts; none: the set-points are held and the device
//! counts a sync error). While no servo has a SYNC0 (a master without DC), the world steps after
//! every frame that writes process data (LWR/LRW), the model time advancing by the servo cycle
//! (1 ms, [`DEFAULT_CYCLE`](fieldprobe::sim::esc::device::DEFAULT_CYCLE)) per step, as an
//! SM-synchronous drive does. The sync-manager watchdog (0x0400 / 0x0420, default 100 ms) drops
//! a device in OP that gets no process data to SAFE-OP with AL status code 0x001B. Every such
//! event (SYNC0 activation, a start time in the past, watchdog expiry) is printed on stderr with
//! the device's ring position and name. `--lockstep` keeps the old behaviour: the world steps
//! after every process-data frame and neither SYNC0 nor the watchdog runs on the clock.
//!
//! `--probe-at POS=MM` puts a probe surface at MM (axis units of that
//! servo's drive scaling, converted to increments with `increments_per_unit` and `offset`) on
//! the servo at ring position POS, wired to that servo's touch probe input 1: the input pulses
//! when the actual position crosses the surface (either direction), so a touch probe armed in
//! 0x60B8 latches the surface position in 0x60BA/0x60BB. The surface also switches channel 1
//! of every timestamp terminal; `--probe-input POS:CH` (repeatable) wires it to input CH (1 or
//! 2) of the timestamp terminal at ring position POS instead (exit 2 if POS is not one).
//!
//! `--rt-priority N` / `--cpu N` / `--mlock` run the serve threads with SCHED_FIFO, on one CPU,
//! with memory locked (as `run` does for the master): a real device answers in hardware, an
//! emulator that shares a loaded machine with the master answers late without them (measured
//! in docs/ethercat.md, "The paced cycle on an interface"). Refused with exit 2 where the
//! system does not permit it.
//!
//! Exit 0; 2 on bad input (the message names the file, position or interface).

use super::{number, EXIT_BAD_INPUT, EXIT_OK};
use anyhow::Context;
use fieldprobe::bus::can::{CanBus, CanError};
use fieldprobe::drive::catalogue;
use fieldprobe::esi::{Device, EsiFile};
use fieldprobe::limits::MAX_SEGMENT_DEVICES;
use fieldprobe::sim::canopen::{CanopenSegment, EmulatedNode};
use fieldprobe::sim::esc::{
    device::{emulated_servo, ServoError, DEFAULT_CYCLE},
    raw,
    segment::{Segment, Stepping},
    terminal,
    vendor::emulated_vendor_drive,
    Esc,
};
use fieldprobe::sim::plant::{FixedStop, Plant, ProbeSurface};
use fieldprobe::sim::world::World;
use fieldprobe::units::{Nanos, Scaling};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
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
    /// Serve emulated CANopen CiA 402 nodes on a CAN bus (python-can udp_multicast or SocketCAN).
    Canopen(CanopenArgs),
}

/// Arguments of `fieldprobe sim ethercat`.
#[derive(Debug, clap::Args)]
struct EthercatArgs {
    /// Network interface to answer on (e.g. one end of a veth pair).
    #[arg(long, value_name = "IF")]
    iface: String,
    /// ESI file of the next device(s) in ring order, optionally `#SEL` to choose the device
    /// (TYPE[/REVISION], PRODUCT_CODE[/REVISION] or @N, then +MODULE per slot) and `:COUNT`
    /// for several. A device whose ESI profile is 402 (CiA 402) is an emulated servo with the
    /// built-in drive `cia402-generic` unless `--drive` names another one.
    #[arg(
        long = "device",
        value_name = "FILE.xml[#SEL][:COUNT]",
        required = true
    )]
    devices: Vec<String>,
    /// Emulate the device at ring position POS (0 = nearest the master) as a CiA 402 servo
    /// with drive definition DRIVE (built-in name or drives/*.toml file). Its PDO layout must
    /// hold the entries of the ESI default mapping.
    #[arg(long = "drive", value_name = "POS=DRIVE")]
    drives: Vec<String>,
    /// Put a probe surface at MM (axis units of the drive's scaling) on the servo at ring
    /// position POS, wired to its touch probe input 1 (pulses when the actual position
    /// crosses it). Repeatable.
    #[arg(long = "probe-at", value_name = "POS=MM")]
    probes: Vec<String>,
    /// The `--probe-at` surfaces switch input CH (1 or 2) of the timestamp terminal at ring
    /// position POS, instead of channel 1 of every timestamp terminal. Repeatable (one probe
    /// on several inputs).
    #[arg(long = "probe-input", value_name = "POS:CH")]
    probe_inputs: Vec<String>,
    /// Step the drive models after every frame that writes process data (model time + 1 ms
    /// each), as before the emulator had its own clock: no SYNC0 and no sync-manager watchdog
    /// on the clock. For tests whose master does not keep a cycle.
    #[arg(long)]
    lockstep: bool,
    /// Fault knob: lose the frames with these numbers (0 = the first frame received;
    /// comma-separated; `A..B` from A to before B, `A..` every frame from A on) as a noisy or
    /// pulled cable does — the frame is not processed and never comes back, so the master must
    /// send it again or report it lost.
    #[arg(long = "lose-frames", value_name = "N|A..B|A..[,...]")]
    lose_frames: Option<String>,
    /// Stop after this many seconds (default: run until killed).
    #[arg(long, value_name = "N", allow_hyphen_values = true)]
    seconds: Option<String>,
    /// Real-time options of the serve threads (a device answers in hardware: on a loaded
    /// machine an emulator without them answers late, and the master sees late frames).
    #[command(flatten)]
    rt: super::RtArgs,
}

/// Run the command; returns the exit code.
pub fn run(a: SimArgs) -> anyhow::Result<i32> {
    match a.command {
        SimCommand::Ethercat(e) => ethercat(e),
        SimCommand::Canopen(c) => canopen(c),
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
            anyhow::ensure!(
                count <= MAX_SEGMENT_DEVICES,
                "--device {spec}: count {count} is above the limit of {MAX_SEGMENT_DEVICES} \
                 devices per emulated segment (docs/limits.md)"
            );
            return Ok((PathBuf::from(file), count));
        }
    }
    Ok((PathBuf::from(spec), 1))
}

/// `POS=VALUE` → (ring position, value).
fn split_position<'a>(option: &str, spec: &'a str) -> anyhow::Result<(usize, &'a str)> {
    let (pos, value) = spec
        .split_once('=')
        .with_context(|| format!("{option} {spec}: expected POS=VALUE"))?;
    let pos = number::int_in(
        pos.trim(),
        0,
        i128::from(u16::MAX),
        "POS=VALUE with a ring position",
    )
    .map_err(|expected| number::NumberError {
        what: option.to_string(),
        text: spec.to_string(),
        expected,
    })?
    .value as usize;
    Ok((pos, value.trim()))
}

/// Does the ESI device declare CiA 402 (`ProfileNo` 402 in its profile, a `ChannelInfo` or a
/// module's profile, [`Device::is_cia402`])?
fn is_cia402(device: &Device) -> bool {
    device.is_cia402()
}

/// Does the device offer what a CiA 402 axis needs (controlword, target position, statusword,
/// position actual value), as CiA 402 objects or objects that play them
/// ([`role_sources`](fieldprobe::drive::vendor::esi_plan::role_sources))?
fn offers_cia402(device: &Device) -> bool {
    let sources = fieldprobe::drive::vendor::esi_plan::role_sources(device);
    [0x6040u16, 0x607A, 0x6041, 0x6064]
        .iter()
        .all(|i| sources.iter().any(|s| s.index == *i))
}

/// The built-in drive a CiA 402 device gets without `--drive`.
const DEFAULT_DRIVE: &str = "cia402-generic";

/// What a device hosts in the world.
#[derive(Debug, Clone, Copy)]
enum Hosted {
    /// Nothing (no process data, or the echo application).
    Nothing,
    /// A CiA 402 servo with this drive scaling.
    Servo(Scaling),
    /// An EL1252-kind timestamp terminal (2 channels, continuous latching, stamping with its
    /// ESC's DC system time).
    Timestamp,
}

/// Refuse (exit 2) drive `def`, named by `option`, when the emulator of `bus` cannot play it
/// (`serves`), naming its profile and the built-in drives it can play (`plays` says which
/// kinds).
fn refuse_unserved(
    option: &str,
    def: &catalogue::DriveDefinition,
    bus: &str,
    plays: &str,
    serves: fn(&catalogue::DriveDefinition) -> bool,
) -> anyhow::Result<()> {
    if serves(def) {
        return Ok(());
    }
    let allowed: Vec<&str> = catalogue::builtin_names()
        .iter()
        .copied()
        .filter(|n| catalogue::builtin(n).is_some_and(|d| serves(&d)))
        .collect();
    anyhow::bail!(
        "{option}: drive '{}' is a {} drive, which the {bus} emulator cannot play; it plays \
         {plays} (allowed: {}, or a drive file of such a drive)",
        def.name,
        def.profile.name(),
        allowed.join(", ")
    )
}

fn build_device(
    path: &Path,
    file: &EsiFile,
    device: &Device,
    position: usize,
    drive: Option<&str>,
) -> anyhow::Result<(Esc, Hosted)> {
    let shown = path.display();
    let given = drive.is_some();
    // A device that declares CiA 402, or offers its roles (a modular device profile servo
    // terminal), is a drive: never played as a plain terminal.
    let drive = drive.or((is_cia402(device) || offers_cia402(device)).then_some(DEFAULT_DRIVE));
    if let Some(drive) = drive {
        let def = catalogue::load(drive)
            .map_err(|e| anyhow::anyhow!("device {position} ({shown}): drive {drive}: {e}"))?;
        let esc = match emulated_servo(file, device, &def) {
            // A vendor's CiA 402 device: its own dictionary and default PDOs, the drive's
            // model wired by object index.
            Err(ServoError::PdoMismatch { .. }) if !given => {
                let vendor = emulated_vendor_drive(file, device, &def, DEFAULT_CYCLE)
                    .map_err(|e| anyhow::anyhow!("device {position} ({shown}): {e}"))?;
                for n in &vendor.notes {
                    eprintln!("fieldprobe sim ethercat: device {position}: note: {n}");
                }
                let esc = vendor.esc;
                eprintln!(
                    "fieldprobe sim ethercat: device {position}: {} (vendor CiA 402 drive: \
                     object dictionary and default PDO mapping from the ESI, drive model {})",
                    device.type_name, def.name
                );
                return Ok((esc, Hosted::Servo(def.scaling)));
            }
            r => {
                r.map_err(|e| anyhow::anyhow!("device {position} ({shown}): drive {drive}: {e}"))?
            }
        };
        eprintln!(
            "fieldprobe sim ethercat: device {position}: {} (CiA 402 servo, drive {})",
            device.type_name, def.name
        );
        return Ok((esc, Hosted::Servo(def.scaling)));
    }
    let kind = terminal::terminal_kind(device);
    let esc = terminal::emulated_terminal(file, device)
        .map_err(|e| anyhow::anyhow!("device {position} ({shown}): {e}"))?;
    if kind == terminal::TerminalKind::Timestamp {
        eprintln!(
            "fieldprobe sim ethercat: device {position}: {} (timestamp terminal, 2 channels)",
            device.type_name
        );
        return Ok((esc, Hosted::Timestamp));
    }
    eprintln!(
        "fieldprobe sim ethercat: device {position}: {}",
        device.type_name
    );
    Ok((esc, Hosted::Nothing))
}

fn ethercat(a: EthercatArgs) -> anyhow::Result<i32> {
    let mut drives = BTreeMap::new();
    for spec in &a.drives {
        let (pos, drive) = split_position("--drive", spec)?;
        anyhow::ensure!(
            drives.insert(pos, drive).is_none(),
            "--drive {spec}: device {pos} already has a drive"
        );
    }
    // A drive model this emulator cannot play on EtherCAT (PROFIdrive, Lightbus, the K-bus
    // KL5101) is refused before anything is built. A drive that does not load is left to
    // `build_device`, which names the device with the error.
    for (pos, drive) in &drives {
        if let Ok(def) = catalogue::load(drive) {
            refuse_unserved(
                &format!("--drive {pos}={drive}"),
                &def,
                "EtherCAT",
                "CiA 402 drives (CoE), SERCOS drives (SoE) and EL5101 encoder terminals",
                |d| fieldprobe::link::ethercat::esi_for(d).is_some(),
            )?;
        }
    }
    let mut escs = Vec::new();
    // Type name per ring position, for the event lines.
    let mut names: Vec<String> = Vec::new();
    // Devices hosting a model, in ring order (index = world device): (position, what).
    let mut hosted: Vec<(usize, Hosted)> = Vec::new();
    for spec in &a.devices {
        let (path, count) = split_count(spec)?;
        anyhow::ensure!(
            escs.len() + count <= MAX_SEGMENT_DEVICES,
            "--device {spec}: the segment would have {} devices, above the limit of \
             {MAX_SEGMENT_DEVICES} devices per emulated segment (docs/limits.md)",
            escs.len() + count
        );
        let (path, sel) = super::esi_load::split(&path.to_string_lossy());
        let (file, device) = super::esi_load::load(&path)
            .and_then(|file| {
                let sel = super::esi_load::selector(sel.as_deref(), None)?;
                let device = super::esi_load::choose(&file, sel.as_ref())?;
                Ok((file, device))
            })
            .map_err(|e| anyhow::anyhow!("--device {spec}: {e}"))?;
        for _ in 0..count {
            let pos = escs.len();
            let (esc, what) = build_device(&path, &file, &device, pos, drives.get(&pos).copied())?;
            if !matches!(what, Hosted::Nothing) {
                hosted.push((pos, what));
            }
            escs.push(esc);
            names.push(device.type_name.clone());
        }
    }
    if let Some((pos, drive)) = drives.range(escs.len()..).next() {
        anyhow::bail!(
            "--drive {pos}={drive}: there is no device {pos} (the segment has {})",
            escs.len()
        );
    }
    let deadline = match a.seconds {
        None => None,
        Some(s) => Some(super::deadline_after(
            "--seconds",
            super::seconds_option("--seconds", &s)?,
        )?),
    };
    // `--probe-input POS:CH`: (world device of the terminal, channel).
    let mut inputs: Vec<(usize, u8)> = Vec::new();
    for spec in &a.probe_inputs {
        let (pos, ch) = spec
            .split_once(':')
            .with_context(|| format!("--probe-input {spec}: expected POS:CH (e.g. 3:1)"))?;
        let pos = number::int_in(
            pos.trim(),
            0,
            i128::from(u16::MAX),
            "POS:CH with a ring position",
        )
        .map_err(|expected| number::NumberError {
            what: "--probe-input".to_string(),
            text: spec.to_string(),
            expected,
        })?
        .value as usize;
        let ch: u8 = ch
            .trim()
            .parse()
            .ok()
            .filter(|c| (1..=2).contains(c))
            .with_context(|| format!("--probe-input {spec}: CH must be 1 or 2"))?;
        let device = hosted
            .iter()
            .position(|(p, what)| *p == pos && matches!(what, Hosted::Timestamp))
            .with_context(|| {
                format!(
                    "--probe-input {spec}: device {pos} is not a timestamp terminal (EL1252 kind)"
                )
            })?;
        inputs.push((device, ch));
    }
    anyhow::ensure!(
        inputs.is_empty() || !a.probes.is_empty(),
        "--probe-input needs a --probe-at surface to switch the input"
    );
    let mut plant = Plant::new();
    for spec in &a.probes {
        let (pos, mm) = split_position("--probe-at", spec)?;
        let mm = position("--probe-at", spec, "POS=MM", mm)?;
        let (device, scaling) = hosted
            .iter()
            .enumerate()
            .find_map(|(d, (p, what))| match what {
                Hosted::Servo(s) if *p == pos => Some((d, *s)),
                _ => None,
            })
            .with_context(|| format!("--probe-at {spec}: device {pos} is not a CiA 402 servo"))?;
        let inc = scaling
            .to_increments(mm)
            .with_context(|| format!("--probe-at {spec}: {mm} mm does not fit INTEGER32"))?;
        // Wired to the servo's touch probe input 1 and to channel 1 of every timestamp terminal
        // (or to the terminal inputs `--probe-input` names).
        let mut wired = vec![(device, 1)];
        if inputs.is_empty() {
            wired.extend(
                hosted
                    .iter()
                    .enumerate()
                    .filter(|(_, (_, w))| matches!(w, Hosted::Timestamp))
                    .map(|(d, _)| (d, 1)),
            );
        } else {
            wired.extend(inputs.iter().copied());
        }
        plant.add_probe_surface(ProbeSurface::new(device, f64::from(inc), wired.clone()));
        let terminals = wired[1..]
            .iter()
            .map(|(d, ch)| format!("channel {ch} of the timestamp terminal at {}", hosted[*d].0))
            .collect::<Vec<_>>();
        eprintln!(
            "fieldprobe sim ethercat: probe surface at {mm} mm = {inc} increments of device {pos}, \
             wired to its touch probe input 1{}",
            if terminals.is_empty() {
                String::new()
            } else {
                format!(" and {}", terminals.join(", "))
            }
        );
    }
    let mut segment = Segment::new(escs, HOP_DELAY_NS);
    if !hosted.is_empty() {
        segment.set_world(World::new(plant), Nanos(DEFAULT_CYCLE.as_nanos() as u64));
    }
    segment.set_stepping(if a.lockstep {
        Stepping::PerFrame
    } else {
        Stepping::OwnClock
    });
    for item in a.lose_frames.iter().flat_map(|l| l.split(',')) {
        let frame = |n: &str| {
            number::int_in(n.trim(), 0, i128::from(u32::MAX), "a frame number")
                .map(|i| i.value as u64)
                .map_err(|expected| number::NumberError {
                    what: "--lose-frames".to_string(),
                    text: item.to_string(),
                    expected,
                })
        };
        match item.split_once("..") {
            None => segment.drop_frame_at(frame(item)?),
            Some((from, "")) => segment.drop_frames_in(frame(from)?..u64::MAX),
            Some((from, to)) => segment.drop_frames_in(frame(from)?..frame(to)?),
        }
    }
    eprintln!(
        "fieldprobe sim ethercat: {} device(s) on {}, {}",
        segment.len(),
        a.iface,
        if a.lockstep {
            "lockstep (models step after every process-data frame)"
        } else {
            "own clock (SYNC0 and sync-manager watchdogs on CLOCK_MONOTONIC)"
        }
    );
    if let Err(e) = a.rt.check_and_apply("fieldprobe sim ethercat") {
        eprintln!("fieldprobe sim ethercat: {e}");
        return Ok(EXIT_BAD_INPUT);
    }
    let mut port = raw::RawPort::open(&a.iface)?;
    eprintln!("fieldprobe sim ethercat: listening on {}", port.iface());
    let stop = AtomicBool::new(false);
    let stats = port.serve_with_events(&mut segment, &stop, deadline, |e| {
        let name = names.get(e.position).map_or("", String::as_str);
        eprintln!(
            "fieldprobe sim ethercat: {:.3} s: device {} ({name}): {}",
            e.at_ns as f64 / 1e9,
            e.position,
            e.event
        );
    })?;
    let sync_errors: Vec<String> = (0..segment.len())
        .filter_map(|p| segment.esc(p).map(|e| (p, e.sync_errors())))
        .filter(|(_, n)| *n > 0)
        .map(|(p, n)| format!("device {p}: {n}"))
        .collect();
    eprintln!(
        "fieldprobe sim ethercat: done, {stats:?}, sync errors: {}",
        if sync_errors.is_empty() {
            "none".to_string()
        } else {
            sync_errors.join(", ")
        }
    );
    Ok(EXIT_OK)
}

/// Arguments of `fieldprobe sim canopen`.
///
/// ```text
/// fieldprobe sim canopen --bus udp[:GROUP:PORT]|socketcan:IF --node ID [--node ID]...
///                        [--eds FILE] [--drive DRIVE] [--probe-at ID=MM]... [--fixed-stop-at ID=MM]...
///                        [--heartbeat-ms MS] [--seconds N] [--rt-priority N] [--cpu N] [--mlock]
/// ```
/// Serves one emulated CiA 402 node per `--node` ([`EmulatedNode`]: NMT slave, boot-up and
/// heartbeat producer, SDO server with segmented and block transfers, synchronous and
/// event-driven PDOs by their transmission types, EMCY) until `--seconds` pass (default:
/// forever) or the process is killed. The drive acts on SDO writes at once (a controlword by
/// SDO moves its CiA 402 state machine without any SYNC) and its statusword is valid from
/// start-up (0x0250). With `--eds` the object dictionary, the PDO defaults and 0x1017 come from
/// the EDS / DCF ([`EmulatedNode::from_eds`] lists the rules; note that many EDS files have
/// 0x1017 = 0, i.e. no heartbeat until the master writes 0x1017 or `--heartbeat-ms` is given),
/// else it is the built-in CiA 402 table ([`EmulatedNode::new`]).
///
/// Loop: receive with a short timeout, hand the frames with `now` = wall-clock time since the
/// start to [`CanopenSegment::run`], send what it returns; `run` is also called without frames
/// at least every millisecond, so boot-up and heartbeats go out on time on a quiet bus. Every
/// SYNC steps the drive models once by the communication cycle period 0x1006 the master wrote
/// (fieldprobe's master writes the machine cycle), or — while 0x1006 is 0 or the EDS has no
/// 0x1006 — by the wall-clock time since the previous SYNC, as a real drive moves in real time
/// (the first SYNC after NMT start by [`SYNC_MODEL_CYCLE`], a gap by at most 1 s:
/// [`fieldprobe::sim::canopen`] "The drive's clock").
///
/// The nodes keep their own clock like real devices: with 0x1006 ≠ 0 a node whose SYNC stays
/// away for more than five periods sends EMCY 0x8100 and its drive faults (see
/// [`fieldprobe::sim::canopen`] "SYNC timing"); RPDOs later than 0x1007 after a SYNC are
/// counted. Both numbers are printed when the command ends (after `--seconds`, or on SIGTERM /
/// SIGINT, which end it the same way with exit 0).
///
/// `--probe-at ID=MM` puts a probe surface at MM (axis units of the drive's scaling, converted
/// with `increments_per_unit` and `offset`) wired to touch probe input 1 of node ID.
///
/// Prints `listening` on stderr when the bus is open and every node has sent its boot-up
/// message (pre-operational: it answers SDO from then on). Exit 0; 2 on bad input (the
/// message names the option and the allowed values) or when the bus cannot be opened.
#[derive(Debug, clap::Args)]
pub struct CanopenArgs {
    /// CAN bus: `udp` (python-can udp_multicast on 239.74.163.2:43113), `udp:GROUP:PORT`, or
    /// `socketcan:IF`.
    #[arg(long, value_name = "udp[:GROUP:PORT]|socketcan:IF")]
    bus: String,
    /// Node id of an emulated node (1 … 127). Repeatable; world device i = i-th `--node`.
    #[arg(long = "node", value_name = "ID", required = true)]
    nodes: Vec<String>,
    /// EDS / DCF file giving the object dictionary of every node.
    #[arg(long, value_name = "FILE")]
    eds: Option<PathBuf>,
    /// Drive definition (built-in name or drives/*.toml file) of every node.
    #[arg(long, value_name = "DRIVE", default_value = DEFAULT_DRIVE)]
    drive: String,
    /// Probe surface at MM (axis units) on node ID, wired to its touch probe input 1.
    /// Repeatable.
    #[arg(long = "probe-at", value_name = "ID=MM")]
    probes: Vec<String>,
    /// A mechanical stop at MM (axis units) in front of node ID's axis: the drive's position
    /// stays there while its torque rises to the limit (0x6072) and its following error grows,
    /// as `run --fixed-stop-at` does on the in-process links. Repeatable.
    #[arg(long = "fixed-stop-at", value_name = "ID=MM")]
    fixed_stops: Vec<String>,
    /// Producer heartbeat time 0x1017 of every node in ms (default: the EDS value, or 100
    /// without `--eds`).
    #[arg(long = "heartbeat-ms", value_name = "MS")]
    heartbeat_ms: Option<String>,
    /// Stop after this many seconds (default: run until killed).
    #[arg(long, value_name = "N", allow_hyphen_values = true)]
    seconds: Option<String>,
    /// Real-time options of the serve loop (see `sim ethercat`).
    #[command(flatten)]
    rt: super::RtArgs,
}

/// SIGTERM / SIGINT, taken through a signalfd (no handler, no unsafe code): the loop polls it
/// and ends like `--seconds` does.
#[cfg(target_os = "linux")]
struct StopSignals(nix::sys::signalfd::SignalFd);

#[cfg(target_os = "linux")]
impl StopSignals {
    /// Block SIGTERM and SIGINT in this thread (threads started later inherit it) and open a
    /// signalfd for them; `None` (the signals keep their default action) if that fails.
    fn new() -> Option<Self> {
        use nix::sys::signal::{SigSet, Signal};
        use nix::sys::signalfd::{SfdFlags, SignalFd};
        let mut mask = SigSet::empty();
        mask.add(Signal::SIGTERM);
        mask.add(Signal::SIGINT);
        let fd =
            SignalFd::with_flags(&mask, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC).ok()?;
        mask.thread_block().ok()?;
        Some(StopSignals(fd))
    }

    /// One of them arrived.
    fn received(&self) -> bool {
        matches!(self.0.read_signal(), Ok(Some(_)))
    }
}

#[cfg(not(target_os = "linux"))]
struct StopSignals;

#[cfg(not(target_os = "linux"))]
impl StopSignals {
    fn new() -> Option<Self> {
        None
    }
    fn received(&self) -> bool {
        false
    }
}

/// Model time the first SYNC after NMT start advances the drive models by when 0x1006 is not
/// set (the EtherCAT emulator's servo cycle); later SYNCs step by the time since the previous
/// one.
pub const SYNC_MODEL_CYCLE: Duration = DEFAULT_CYCLE;

/// Longest wait in one receive, so `run` is called at least this often.
const CAN_POLL: Duration = Duration::from_millis(1);

/// Frames handed to one `run` call at most (the rest wait for the next call).
const CAN_BATCH: usize = 64;

/// A parsed `--bus`.
enum CanBusSpec {
    Udp(fieldprobe::bus::can::UdpConfig),
    SocketCan(String),
}

/// Check `--bus` (before anything is built, so bad input fails fast).
fn parse_can_bus(spec: &str) -> anyhow::Result<CanBusSpec> {
    const ALLOWED: &str =
        "allowed: `udp`, `udp:GROUP:PORT` (IPv4 multicast group, port 1 … 65535) \
                           or `socketcan:IF`";
    let s = spec.trim();
    if s.starts_with("udp") {
        let cfg = fieldprobe::bus::can::UdpConfig::parse(s)
            .map_err(|e| anyhow::anyhow!("--bus {spec}: {e}"))?;
        return Ok(CanBusSpec::Udp(cfg));
    }
    if let Some(ifname) = s.strip_prefix("socketcan:") {
        anyhow::ensure!(
            !ifname.is_empty(),
            "--bus {spec}: no interface name ({ALLOWED})"
        );
        return Ok(CanBusSpec::SocketCan(ifname.to_string()));
    }
    anyhow::bail!("--bus {spec}: unknown bus ({ALLOWED})")
}

/// Open the bus `--bus` named.
fn open_can_bus(spec: &str, bus: CanBusSpec) -> anyhow::Result<Box<dyn CanBus>> {
    use fieldprobe::bus::can::{SocketCanBus, UdpMulticastBus};
    Ok(match bus {
        CanBusSpec::Udp(cfg) => Box::new(
            UdpMulticastBus::open(cfg)
                .map_err(|e| anyhow::anyhow!("--bus {spec}: cannot open {cfg}: {e}"))?,
        ),
        CanBusSpec::SocketCan(ifname) => {
            Box::new(SocketCanBus::open(&ifname).map_err(|e| {
                anyhow::anyhow!("--bus {spec}: cannot open SocketCAN {ifname}: {e}")
            })?)
        }
    })
}

/// The node id `id` in the argument `spec` of `option` (`--node 0x05`, `--probe-at 5=10`):
/// 1 … 127, decimal or 0x hex.
fn parse_node_id(option: &str, spec: &str, id: &str) -> anyhow::Result<u8> {
    let mut e = match number::node_id(option, id.trim()) {
        Ok(n) => return Ok(n),
        Err(e) => e,
    };
    if spec != id {
        e.text = spec.to_string();
        e.expected = format!("ID=MM with {}", e.expected);
    }
    Err(e.into())
}

/// The position MM (mm) in the argument `spec` (of the form `form`, e.g. `ID=MM`) of `option`.
fn position(option: &str, spec: &str, form: &str, mm: &str) -> anyhow::Result<f64> {
    number::position(option, mm).map_err(|e| {
        anyhow::anyhow!(number::NumberError {
            text: spec.to_string(),
            expected: format!("{form} with {}", e.expected),
            ..e
        })
    })
}

fn canopen(a: CanopenArgs) -> anyhow::Result<i32> {
    let bus_spec = parse_can_bus(&a.bus)?;
    let deadline = match a.seconds {
        None => None,
        Some(s) => Some(super::deadline_after(
            "--seconds",
            super::seconds_option("--seconds", &s)?,
        )?),
    };
    let heartbeat = a
        .heartbeat_ms
        .as_deref()
        .map(|ms| {
            number::int_option(
                "--heartbeat-ms",
                ms.trim(),
                0,
                i128::from(u16::MAX),
                "a time in ms (0 = no heartbeat)",
            )
            .map(|v| v as u16)
        })
        .transpose()?;
    let mut ids = Vec::new();
    for spec in &a.nodes {
        let id = parse_node_id("--node", spec, spec)?;
        anyhow::ensure!(!ids.contains(&id), "--node {spec}: node {id} given twice");
        ids.push(id);
    }
    let def = catalogue::load(&a.drive).map_err(|e| {
        anyhow::anyhow!(
            "--drive {}: {e} (allowed: a built-in drive name such as {DEFAULT_DRIVE}, or a \
             drive file drives/*.toml)",
            a.drive
        )
    })?;
    refuse_unserved(
        &format!("--drive {}", a.drive),
        &def,
        "CANopen",
        "CiA 402 drives",
        |d| d.profile == catalogue::Profile::Cia402,
    )?;
    let eds = match &a.eds {
        None => None,
        Some(p) => Some(super::canopen_od::load_eds(Some("--eds"), p)?),
    };
    let mut nodes = Vec::new();
    for &id in &ids {
        let mut node = match &eds {
            None => EmulatedNode::new(id, &def),
            Some(e) => EmulatedNode::from_eds(id, &def, e),
        }
        .map_err(|e| anyhow::anyhow!("--node {id}: {e}"))?;
        if let Some(ms) = heartbeat {
            node.set_heartbeat_ms(ms);
        }
        eprintln!(
            "fieldprobe sim canopen: node {id}: CiA 402 drive {}, object dictionary {}",
            def.name,
            a.eds
                .as_ref()
                .map_or("built in".to_string(), |p| p.display().to_string())
        );
        nodes.push(node);
    }
    let mut segment = CanopenSegment::new(nodes, Nanos(SYNC_MODEL_CYCLE.as_nanos() as u64));
    // `--probe-at` / `--fixed-stop-at ID=MM`: (node id, device index, mm, increments).
    let node_position = |option: &str, spec: &str| -> anyhow::Result<(u8, usize, f64, i32)> {
        let (id, mm) = spec
            .split_once('=')
            .with_context(|| format!("{option} {spec}: expected ID=MM"))?;
        let id = parse_node_id(option, spec, id)?;
        let device = ids.iter().position(|&n| n == id).with_context(|| {
            format!("{option} {spec}: node {id} is not emulated (nodes: {ids:?})")
        })?;
        let mm = position(option, spec, "ID=MM", mm.trim())?;
        let inc = def
            .scaling
            .to_increments(mm)
            .with_context(|| format!("{option} {spec}: {mm} mm does not fit INTEGER32"))?;
        Ok((id, device, mm, inc))
    };
    for spec in &a.fixed_stops {
        let (id, device, mm, inc) = node_position("--fixed-stop-at", spec)?;
        segment.world_mut().plant_mut().add_fixed_stop(FixedStop {
            device,
            position: f64::from(inc),
        });
        eprintln!("fieldprobe sim canopen: fixed stop at {mm} mm = {inc} increments of node {id}");
    }
    for spec in &a.probes {
        let (id, device, mm, inc) = node_position("--probe-at", spec)?;
        segment
            .world_mut()
            .plant_mut()
            .add_probe_surface(ProbeSurface::new(device, f64::from(inc), vec![(device, 1)]));
        eprintln!(
            "fieldprobe sim canopen: probe surface at {mm} mm = {inc} increments of node {id}, \
             wired to its touch probe input 1"
        );
    }
    if let Err(e) = a.rt.check_and_apply("fieldprobe sim canopen") {
        eprintln!("fieldprobe sim canopen: {e}");
        return Ok(EXIT_BAD_INPUT);
    }
    let stop = StopSignals::new();
    let mut bus = open_can_bus(&a.bus, bus_spec)?;
    let t0 = Instant::now();
    let (mut received, mut sent) = (0u64, 0u64);
    // Boot the nodes before saying `listening`: each sends its boot-up message and is
    // pre-operational, so a master that starts on that line is answered at once (a node in
    // boot-up (NMT initialisation) ignores SDO requests, and a request that came before the
    // first poll would wait for the master's SDO timeout).
    let mut boot = Vec::new();
    segment.run_with(&[], Nanos(0), &mut |f| boot.push(f));
    for f in &boot {
        bus.send(f)
            .map_err(|e| anyhow::anyhow!("bus {}: send {f:?}: {e}", bus.describe()))?;
        sent += 1;
    }
    eprintln!("fieldprobe sim canopen: listening on {}", bus.describe());
    let mut frames = Vec::with_capacity(CAN_BATCH);
    while deadline.is_none_or(|d| Instant::now() < d)
        && !stop.as_ref().is_some_and(|s| s.received())
    {
        frames.clear();
        let mut wait = CAN_POLL;
        while frames.len() < CAN_BATCH {
            match bus.recv(wait) {
                Ok(Some(f)) => frames.push(f),
                Ok(None) => break,
                // A datagram another program got wrong: say so and go on.
                Err(CanError::Malformed(why)) => {
                    tracing::warn!(target: "fieldprobe::sim::canopen", "dropped frame: {why}");
                }
                Err(e) => anyhow::bail!("bus {}: {e}", bus.describe()),
            }
            wait = Duration::ZERO;
        }
        received += frames.len() as u64;
        let now = Nanos(t0.elapsed().as_nanos() as u64);
        // TPDOs leave at the SYNC, before the models step (`run_with`).
        let busy = Instant::now();
        let mut failed = None;
        segment.run_with(&frames, now, &mut |f| {
            if failed.is_some() {
                return;
            }
            match bus.send(&f) {
                Ok(()) => sent += 1,
                Err(e) => failed = Some(format!("bus {}: send {f:?}: {e}", bus.describe())),
            }
        });
        if let Some(e) = failed {
            anyhow::bail!(e);
        }
        let busy = busy.elapsed();
        if busy > Duration::from_millis(1) {
            tracing::debug!(target: "fieldprobe::sim::canopen", "{} frames took {} µs", frames.len(), busy.as_micros());
        }
    }
    let timeouts: u64 = segment.nodes().iter().map(|n| n.sync_timeouts()).sum();
    let rpdo_timeouts: u64 = segment.nodes().iter().map(|n| n.rpdo_timeouts()).sum();
    let late: u64 = segment
        .nodes()
        .iter()
        .map(|n| n.rpdos_outside_window())
        .sum();
    eprintln!(
        "fieldprobe sim canopen: done, {received} frames received, {sent} sent, {timeouts} SYNC \
         time-outs, {rpdo_timeouts} RPDO time-outs, {late} RPDOs outside the synchronous window"
    );
    Ok(EXIT_OK)
}
