//! EtherCAT link: the `ethercrab` MainDevice drives the axes' process data, our own mailbox
//! clients carry the acyclic access (CoE SDO for object-dictionary drives, SoE for SERCOS).
//!
//! | `--link` | wire |
//! |---|---|
//! | `ethercat-emu` (feature `sim`) | in-process: frames go straight through an emulated segment (`crate::sim::esc::segment::Segment`, `emulated_segment`) built from the machine file (an EK1100-kind coupler, then one emulated drive per axis from the embedded ESI files) |
//! | `ethercat:IFACE` | a raw socket on a network interface (real devices, or `fieldprobe sim ethercat` on the other end of a veth pair) |
//!
//! # Start-up
//!
//! `init_single_group` (addresses, SII, mailbox SMs, DC delay measurement and static drift
//! compensation) → in PRE-OP, for every axis on a CoE drive, the PDO mapping of the axis's drive
//! definition (`drives/*.toml` `[rxpdo]` / `[txpdo]`) is written with the CiA 301 procedure
//! (0x1C12:0 = 0, 0x1600:0 = 0, entries, counts) through our CoE client; SERCOS drives keep the
//! telegrams of their ESI (S-0-0016 / S-0-0024 are fixed there) → DC SYNC0 with the link's cycle
//! time on every device that supports DC → SAFE-OP → OP. The process images ethercrab then
//! reports for each axis must have the drive definition's lengths, or the link refuses.
//!
//! # One exchange at `now`
//!
//! Outputs go into ethercrab's PDI and the LRW datagrams carry them to the devices and bring
//! back the inputs the devices latched at their previous SYNC0; on `ethercat-emu` the emulated
//! segment then runs SYNC0 at `now` (every drive model steps once, with the plant — probe
//! surfaces and fixed stops — exactly as [`SimLink`](super::sim::SimLink) does), filling the
//! inputs the next exchange reads. The actual values thus arrive one cycle after they were
//! sampled: the link's dead time is two cycles ([`Link::dead_time_cycles`]), as over `--link
//! sim`. On a real interface the same datagrams are sent (the devices' own SYNC0 decides when
//! they sample).
//!
//! A process image longer than a frame goes out as one LRW per frame (ethercrab 0.7.1 splits
//! it, [`cycle_plan`]); every LRW's working counter is checked on its own against the one the
//! devices' FMMU windows call for ([`datagrams`]), and a lost or miscounted one is named (its
//! number in the cycle, logical range and devices) in [`LinkError::Lost`]; the inputs are then
//! left untouched.
//!
//! # The segment
//!
//! Besides the axes' drives a machine names I/O terminals ([`terminals`]: `[[terminal]]` in the
//! machine file), found on the bus by identity in ring order, their process data reachable
//! through [`Link::terminal_inputs`] / [`Link::terminal_outputs_mut`]; every other SubDevice
//! goes to OP with its default process data and is listed at start-up
//! ([`Link::startup_report`], info 900401). Before SAFE-OP the link computes the wire time of
//! one cycle ([`cycle_plan::WireTime`]: the frames at 100 Mbit/s with their Ethernet overhead,
//! plus 1 µs per device and frame) and refuses a cycle time shorter than that (error 900403);
//! the figure is reported at start-up (info 900402).
//!
//! # Acyclic access
//!
//! [`Link::read_object`] / [`Link::write_object`] run between cycles: CoE uploads / downloads
//! (expedited, normal or segmented) whose size comes from the drive definition's function and
//! IDN tables or the CiA 402 object table (4 bytes otherwise); SoE reads / writes of the IDN
//! (index = IDN number) whose length comes from the IDN's attribute.
//!
//! # Limits
//!
//! At most [`MAX_SUBDEVICES`] SubDevices and [`MAX_PDI`] bytes of process image per link.
//! Each link leaks one ethercrab `PduStorage` (about 24 kB; ethercrab needs it `'static` and
//! lets it be split once), which is fine for a process that opens a handful of links.

pub mod cycle_plan;
pub mod datagrams;
pub mod dictionary;
#[cfg(feature = "sim")]
mod emulated;
pub mod pdo_fit;
pub mod retry;
pub mod terminals;
mod wire;

#[cfg(feature = "sim")]
pub use emulated::emulated_segment;

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ethercrab::subdevice_group::{DcConfiguration, HasDc, NoDc, Op};
use ethercrab::{DcSync, MainDevice, PduStorage, SubDeviceGroup};

use self::cycle_plan::{CyclePlan, WireTime};
use self::datagrams::{FmmuWindow, LogicalMap};
use self::terminals::{BusDevice, Role, TerminalSpec};
use self::wire::{connect, drive, WireEnd, EMULATED_TIMEOUT};
use super::{decode_le, object_type, Link, LinkError, Peer, ProcessImage};
use crate::bus::ethercat::mailbox::{CoeClient, MailboxError};
use crate::bus::ethercat::soe::SoeClient;
use crate::drive::catalogue::{DriveDefinition, Profile};
use crate::esi;
use crate::messages::{ids, CncMessage};
use crate::rt::{CycleClock, CycleRecord};
use crate::units::Nanos;

/// SubDevices a link can hold (a channel of 32 axes with their I/O terminals and couplers:
/// issue 16 runs 32 drives + 64 terminals + a coupler).
pub const MAX_SUBDEVICES: usize = 128;
/// Process data image bytes a link can hold (inputs and outputs of all devices).
pub const MAX_PDI: usize = 8192;
const MAX_FRAMES: usize = 16;
/// Datagram bytes per frame: a full Ethernet frame (1514 bytes − 14 Ethernet − 2 EtherCAT header).
pub const FRAME_DATA: usize = 1498;
/// ethercrab's storage element is a whole Ethernet frame (its `element_size(n)` is the frame of
/// one `n`-byte datagram, 28 + n): 1514 bytes, so a frame ethercrab fills (an LRW part takes the
/// rest of its frame) carries [`FRAME_DATA`] datagram bytes and never exceeds the Ethernet MTU.
const PDU_DATA: usize = crate::bus::ethercat::wire::MAX_ETHERNET_FRAME;

type Storage = PduStorage<MAX_FRAMES, PDU_DATA>;

/// ESI of the emulated CiA 402 servo (embedded).
pub const SERVO_ESI: &str = include_str!("../../../esi/fieldprobe-cia402-servo.xml");
/// ESI of the emulated SERCOS drive (embedded).
pub const SERCOS_ESI: &str = include_str!("../../../esi/fieldprobe-ax5000-sercos.xml");
/// ESI of the emulated EL5101-kind encoder terminal (embedded).
pub const EL5101_ESI: &str = include_str!("../../../esi/fieldprobe-el5101.xml");
/// ESI of the emulated coupler (embedded).
pub const COUPLER_ESI: &str = include_str!("../../../esi/fieldprobe-ek1100.xml");
/// Where the frames go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Wire {
    /// In-process emulated segment built from the machine.
    Emulated,
    /// A raw socket on this network interface.
    Interface(String),
}

impl Wire {
    /// Parse a `--link` value: `ethercat-emu` or `ethercat:IFACE`; `None` for other links.
    pub fn from_link(link: &str) -> Option<Wire> {
        if link == "ethercat-emu" {
            return Some(Wire::Emulated);
        }
        link.strip_prefix("ethercat:")
            .filter(|i| !i.is_empty())
            .map(|i| Wire::Interface(i.to_string()))
    }
}

/// What to build an EtherCAT link for: one entry per axis, in axis order.
#[derive(Debug, Clone, Default)]
pub struct EthercatSpec {
    /// Drive definition per axis.
    pub drives: Vec<Arc<DriveDefinition>>,
    /// Interpolation cycle (SYNC0 period).
    pub cycle: Nanos,
    /// Write every frame (both directions) into this pcap file.
    pub pcap: Option<std::path::PathBuf>,
    /// The SubDevices of the machine that are not axes (I/O terminals), in ring order.
    pub terminals: Vec<TerminalSpec>,
    /// `ethercat-emu` only: devices the emulated segment carries after the machine's, which the
    /// machine does not name (as a real segment carries spare terminals).
    pub emulated_extra: Vec<TerminalSpec>,
}

/// The ESI text the emulator uses for a drive, if it emulates that drive on EtherCAT: CiA 402
/// servo, SERCOS drive, EL5101 encoder terminal (not the K-bus KL5101).
pub fn esi_for(def: &DriveDefinition) -> Option<&'static str> {
    match def.profile {
        Profile::Cia402 => Some(SERVO_ESI),
        Profile::Sercos => Some(SERCOS_ESI),
        Profile::Terminal => crate::drive::terminal::TerminalConfig::from_definition(def)
            .ok()
            .filter(|c| c.variant == crate::drive::terminal::Variant::El5101)
            .map(|_| EL5101_ESI),
        _ => None,
    }
}

/// An embedded ESI text, parsed once per process (the link needs it at start-up for the
/// emulator and again to match axes to SubDevices; there are four such texts).
fn embedded(text: &'static str, name: &str) -> Result<&'static esi::EsiFile, LinkError> {
    static CACHE: std::sync::Mutex<Vec<(usize, &'static esi::EsiFile)>> =
        std::sync::Mutex::new(Vec::new());
    let mut cache = CACHE.lock().unwrap_or_else(|p| p.into_inner());
    let key = text.as_ptr() as usize;
    if let Some((_, f)) = cache.iter().find(|(k, _)| *k == key) {
        return Ok(f);
    }
    let file = esi::parse(text, name).map_err(|e| LinkError::Other(e.to_string()))?;
    let file: &'static esi::EsiFile = Box::leak(Box::new(file));
    cache.push((key, file));
    Ok(file)
}

/// The cyclic group in OP, with or without DC.
enum Group {
    Dc(SubDeviceGroup<MAX_SUBDEVICES, MAX_PDI, ethercrab::DefaultLock, Op, HasDc>),
    NoDc(SubDeviceGroup<MAX_SUBDEVICES, MAX_PDI, ethercrab::DefaultLock, Op, NoDc>),
}

/// Mailbox client of one axis's device.
#[derive(Debug)]
enum Mailbox {
    Coe(CoeClient),
    Soe(SoeClient),
    None,
}

/// One axis on the bus.
#[derive(Debug)]
struct AxisDevice {
    /// Index of the SubDevice in the group.
    sub: usize,
    def: Arc<DriveDefinition>,
    mailbox: Mailbox,
    name: String,
    /// Start-up warnings: the PDO mapping ([`pdo_fit`]: touch probe left out), the device's
    /// identity checks, the mode of operation.
    warnings: Vec<CncMessage>,
}

/// One terminal of the machine on the bus, with its process images (copied to and from
/// ethercrab's PDI at every exchange).
#[derive(Debug)]
struct TerminalDevice {
    /// Index of the SubDevice in the group.
    sub: usize,
    name: String,
    outputs: Vec<u8>,
    inputs: Vec<u8>,
}

/// The EtherCAT link (see the module documentation).
pub struct EthercatLink {
    md: &'static MainDevice<'static>,
    group: Group,
    wire: WireEnd,
    axes: Vec<AxisDevice>,
    terminals: Vec<TerminalDevice>,
    /// Every SubDevice in ring order with its role.
    bus: Vec<BusDevice>,
    /// The frames of one cycle and their wire time.
    plan: CyclePlan,
    wire_time: WireTime,
    /// The devices' FMMU windows (per-datagram working counters).
    map: LogicalMap,
    /// Working counter of each planned LRW datagram.
    lrw_expected: Vec<u16>,
    cycle: Nanos,
    expected_wkc: u16,
    exchanges: u64,
    /// Fault knobs: (exchange, process-data datagram) to drop / to miscount.
    lose: BTreeSet<(u64, usize)>,
    miscount: BTreeSet<(u64, usize)>,
    emulated: bool,
    /// The paced cycle on a network interface (`None` in-process: virtual time).
    clock: Option<CycleClock>,
    /// Configured addresses of the DC devices (0x092C is read round-robin).
    dc_devices: Vec<u16>,
    dc_next: usize,
    /// DC system time (ns since 2000) of the SYNC0 at which the devices sampled the inputs the
    /// last exchange read ([`Link::sample_dc_time`]); `None` without DC or after a lost one.
    sample_dc: Option<i64>,
    /// The shortest sync-manager watchdog time of the devices (0x0400 / 0x0420), ns: a master
    /// that sends no frame for this long has stalled.
    watchdog_ns: u64,
}

/// Every this many cycles the link reads one DC device's system-time difference (0x092C) in an
/// extra frame (round-robin), so the watch costs next to nothing.
pub const DC_WATCH_EVERY: u64 = 100;

/// The ETG default sync-manager watchdog: (0x09C2 + 2) × 40 ns × 1000 = 100 ms.
pub const DEFAULT_WATCHDOG_NS: u64 = 100_000_000;

/// Longest wait for the devices to reach OP while the paced cycle already runs.
const OP_TIMEOUT: Duration = Duration::from_secs(5);

impl std::fmt::Debug for EthercatLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EthercatLink")
            .field("axes", &self.axes)
            .field("cycle", &self.cycle)
            .field("expected_wkc", &self.expected_wkc)
            .field("exchanges", &self.exchanges)
            .finish_non_exhaustive()
    }
}

fn mbx_err(what: String) -> impl Fn(MailboxError) -> LinkError {
    move |e| LinkError::Other(format!("{what}: {e}"))
}

fn ec_err(what: &'static str) -> impl Fn(ethercrab::error::Error) -> LinkError {
    move |e| LinkError::Other(format!("EtherCAT {what}: {e}"))
}

impl EthercatLink {
    /// Open the link on `wire` for the axes of `spec` and bring every device to OP.
    pub fn open(wire: &Wire, spec: &EthercatSpec) -> Result<Self, LinkError> {
        let (md, mut wire_end) = connect(wire, spec)?;
        let emulated = wire_end.is_emulated();
        let now = ethercrab::std::ethercat_now;
        let cycle_ns = spec.cycle.0;
        let (group, axes, terminals, bus, map, plan) = drive(&mut wire_end, async {
            let mut group = md
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(now)
                .await
                .map_err(|e| {
                    LinkError::Other(format!(
                        "EtherCAT init: {e} (the link holds at most {MAX_SUBDEVICES} SubDevices)"
                    ))
                })?;
            let (mut axes, terminals, bus) = assign_devices(md, &group, spec).await?;
            if emulated {
                // In-process: the frame budget of `drive` bounds the mailbox polls, not a clock.
                for ax in axes.iter_mut() {
                    match &mut ax.mailbox {
                        Mailbox::Coe(c) => c.timeout = EMULATED_TIMEOUT,
                        Mailbox::Soe(c) => c.timeout = EMULATED_TIMEOUT,
                        Mailbox::None => {}
                    }
                }
            }
            for ax in axes.iter_mut() {
                if let Mailbox::Coe(c) = &mut ax.mailbox {
                    ax.warnings
                        .extend(pdo_fit::check_device_type(md, c, &ax.def, &ax.name).await);
                    let fitted = pdo_fit::fit_mapping(md, c, &ax.def, &ax.name).await?;
                    write_pdo_mapping(md, c, &fitted.def, &ax.name).await?;
                    ax.def = fitted.def;
                    ax.warnings.extend(fitted.warning);
                    ax.warnings
                        .extend(write_mode(md, c, &ax.def, &ax.name).await?);
                }
            }
            let cycle = Duration::from_nanos(spec.cycle.0);
            let mut any_dc = false;
            for mut sd in group.iter_mut(md) {
                if sd.dc_support().any() {
                    sd.set_dc_sync(DcSync::Sync0);
                    any_dc = true;
                }
            }
            let pdi = group.into_pre_op_pdi(md).await.map_err(|e| {
                LinkError::Other(format!(
                    "EtherCAT PDO configuration: {e} (the link holds a process image of at most {MAX_PDI} bytes)"
                ))
            })?;
            // The process image is laid out: read the FMMU windows, plan the frames of a
            // cycle and refuse a cycle time the wire cannot carry, before any device is in
            // SAFE-OP.
            let addresses: Vec<u16> = pdi.iter(md).map(|sd| sd.configured_address()).collect();
            enable_sized_sync_managers(md, &addresses).await?;
            let pdi_len: usize = pdi
                .iter(md)
                .map(|sd| {
                    let io = sd.io_raw();
                    io.inputs().len() + io.outputs().len()
                })
                .sum();
            let map = read_logical_map(md, &addresses).await?;
            let start = map.start().unwrap_or(0);
            let plan = CyclePlan::ethercrab(start, pdi_len, addresses.len(), any_dc, FRAME_DATA);
            check_wire_time(&plan.wire_time(), cycle_ns)?;
            let mut bus = bus;
            for (b, sd) in bus.iter_mut().zip(pdi.iter(md)) {
                let io = sd.io_raw();
                b.outputs = io.outputs().len();
                b.inputs = io.inputs().len();
            }
            let group = if any_dc && !emulated {
                // As in the field: SYNC0 at the cycle period, starting well in the future (100 ms
                // after the activation is written, as ethercrab's examples, SOEM and IgH do: the
                // write reaches every device before it), the master's
                // frame half a period after SYNC0 (ethercrab aligns its cycle with
                // `CycleInfo::next_cycle_wait`); OP is requested and reached while the paced
                // process-data cycle already runs, so no sync-manager watchdog expires.
                let g = pdi
                    .configure_dc_sync(
                        md,
                        DcConfiguration {
                            start_delay: Duration::from_millis(100),
                            sync0_period: cycle,
                            sync0_shift: cycle / 2,
                        },
                    )
                    .await
                    .map_err(ec_err("DC SYNC0"))?;
                let g = g.into_safe_op(md).await.map_err(ec_err("SAFE-OP"))?;
                Group::Dc(g.request_into_op(md).await.map_err(ec_err("OP"))?)
            } else if any_dc {
                let g = pdi
                    .configure_dc_sync(
                        md,
                        DcConfiguration {
                            start_delay: Duration::from_millis(1),
                            sync0_period: cycle,
                            sync0_shift: Duration::ZERO,
                        },
                    )
                    .await
                    .map_err(ec_err("DC SYNC0"))?;
                let g = g.into_safe_op(md).await.map_err(ec_err("SAFE-OP"))?;
                Group::Dc(g.into_op(md).await.map_err(ec_err("OP"))?)
            } else {
                let g = pdi.into_safe_op(md).await.map_err(ec_err("SAFE-OP"))?;
                Group::NoDc(g.into_op(md).await.map_err(ec_err("OP"))?)
            };
            Ok::<_, LinkError>((group, axes, terminals, bus, map, plan))
        })
        .map_err(|e| wire_end.explain(e))?;
        // The DC devices whose clocks follow the reference (ethercrab takes the first DC device
        // as the reference clock; its own 0x092C is never updated by the FRMW it sources).
        let dc_devices = match &group {
            Group::Dc(g) => g
                .iter(md)
                .filter(|sd| sd.dc_support().any())
                .map(|sd| sd.configured_address())
                .skip(1)
                .collect(),
            Group::NoDc(_) => Vec::new(),
        };
        let wire_time = plan.wire_time();
        let lrw_expected = plan
            .lrw_datagrams()
            .map(|(_, a, n)| map.expected_wkc(crate::bus::ethercat::wire::Command::Lrw, a, n))
            .collect();
        let mut link = EthercatLink {
            md,
            group,
            wire: wire_end,
            axes,
            terminals,
            bus,
            plan,
            wire_time,
            map,
            lrw_expected,
            cycle: spec.cycle,
            expected_wkc: 0,
            exchanges: 0,
            lose: BTreeSet::new(),
            miscount: BTreeSet::new(),
            emulated,
            clock: (!emulated).then(|| CycleClock::new(spec.cycle)),
            dc_devices,
            dc_next: 0,
            sample_dc: None,
            watchdog_ns: DEFAULT_WATCHDOG_NS,
        };
        link.watchdog_ns = link.read_watchdog();
        link.reach_op()?;
        link.check_images()?;
        #[cfg(feature = "sim")]
        link.wire.start_cycles();
        Ok(link)
    }

    /// The shortest sync-manager watchdog of the devices with outputs: (0x0400 + 2) × 40 ns ×
    /// 0x0420 (ETG.1000.4); [`DEFAULT_WATCHDOG_NS`] where it cannot be read or is 0 (off).
    fn read_watchdog(&mut self) -> u64 {
        if self.clock.is_none() {
            return DEFAULT_WATCHDOG_NS;
        }
        let md = self.md;
        let addrs: Vec<u16> = match &self.group {
            Group::Dc(g) => g
                .iter(md)
                .filter(|sd| !sd.io_raw().outputs().is_empty())
                .map(|sd| sd.configured_address())
                .collect(),
            Group::NoDc(g) => g
                .iter(md)
                .filter(|sd| !sd.io_raw().outputs().is_empty())
                .map(|sd| sd.configured_address())
                .collect(),
        };
        let mut shortest: Option<u64> = None;
        for a in addrs {
            let div = drive(
                &mut self.wire,
                ethercrab::Command::fprd(a, 0x0400).receive::<u16>(md),
            );
            let time = drive(
                &mut self.wire,
                ethercrab::Command::fprd(a, 0x0420).receive::<u16>(md),
            );
            if let (Ok(div), Ok(time)) = (div, time) {
                let ns = (u64::from(div) + 2) * 40 * u64::from(time);
                if ns > 0 {
                    shortest = Some(shortest.map_or(ns, |s| s.min(ns)));
                }
            }
        }
        shortest.unwrap_or(DEFAULT_WATCHDOG_NS)
    }

    /// On a network interface with DC: run the paced cycle (outputs zero) until every device
    /// reports OP, at most [`OP_TIMEOUT`]; the devices' SYNC0 and watchdogs see process data
    /// from the first moment. Elsewhere nothing to do (the group is in OP already).
    fn reach_op(&mut self) -> Result<(), LinkError> {
        if self.emulated || !matches!(self.group, Group::Dc(_)) {
            return Ok(());
        }
        let start = Instant::now();
        loop {
            let wake = match self.clock.as_mut() {
                Some(c) => c.tick(),
                None => return Ok(()),
            };
            let md = self.md;
            let Group::Dc(g) = &self.group else {
                return Ok(());
            };
            let r = drive(&mut self.wire, g.tx_rx_dc(md)).map_err(ec_err("OP transition"))?;
            if let Some(c) = self.clock.as_mut() {
                c.align(
                    wake.woke
                        .saturating_add(r.extra.next_cycle_wait.as_nanos() as u64),
                );
            }
            if r.all_op() {
                return Ok(());
            }
            if start.elapsed() > OP_TIMEOUT {
                let states: Vec<String> = r
                    .subdevice_states
                    .iter()
                    .enumerate()
                    .map(|(i, s)| format!("device {i}: {s:?}"))
                    .collect();
                return Err(LinkError::Other(format!(
                    "EtherCAT OP: not every device reached OP within {} s of process data ({})",
                    OP_TIMEOUT.as_secs(),
                    states.join(", ")
                )));
            }
        }
    }

    /// Compare ethercrab's image sizes with the drive definitions; size the terminals' images;
    /// the expected working counter of a good cycle (the sum of its datagrams').
    fn check_images(&mut self) -> Result<(), LinkError> {
        for ax in &self.axes {
            let Some(b) = self.bus.get(ax.sub) else {
                continue;
            };
            let (o, i) = (b.outputs, b.inputs);
            let (want_o, want_i) = image_lengths(&ax.def);
            if (o, i) != (want_o, want_i) {
                return Err(LinkError::Other(format!(
                    "axis {}: SubDevice {} ({}) has {o} output / {i} input bytes in OP, drive '{}' needs {want_o} / {want_i}",
                    ax.name, ax.sub, b.name, ax.def.name
                )));
            }
        }
        for t in &mut self.terminals {
            if let Some(b) = self.bus.get(t.sub) {
                t.outputs = vec![0; b.outputs];
                t.inputs = vec![0; b.inputs];
            }
        }
        self.expected_wkc = self
            .lrw_expected
            .iter()
            .fold(0u16, |a, w| a.wrapping_add(*w));
        Ok(())
    }

    /// Lose the `n`-th exchange (0-based): its first frame is dropped on the wire, as a broken
    /// cable would; the exchange returns [`LinkError::Lost`]. Emulated wire only.
    pub fn lose_exchange_at(&mut self, n: u64) {
        self.lose.insert((n, 0));
    }

    /// Fault knob: the `n`-th exchange (0-based) comes back with the working counter of its
    /// first process-data datagram one short (emulated wire only); the exchange returns
    /// [`LinkError::Lost`].
    pub fn miscount_exchange_at(&mut self, n: u64) {
        self.miscount.insert((n, 0));
    }

    /// Fault knob: in the `n`-th exchange (0-based) the frame that carries process-data
    /// datagram `k` (0-based, in the order of [`Self::cycle_plan`]) is dropped on the wire
    /// (emulated wire only). ethercrab sends the frames of a cycle one after the other, so the
    /// datagrams after it are not sent either.
    pub fn lose_datagram_at(&mut self, n: u64, k: usize) {
        self.lose.insert((n, k));
    }

    /// Fault knob: in the `n`-th exchange (0-based) process-data datagram `k` comes back with a
    /// working counter one short, as if one device had not processed it (emulated wire only).
    pub fn miscount_datagram_at(&mut self, n: u64, k: usize) {
        self.miscount.insert((n, k));
    }

    /// The frames of one process-data cycle.
    pub fn cycle_plan(&self) -> &CyclePlan {
        &self.plan
    }

    /// The time one cycle takes on the wire (the start-up report, info 900402).
    pub fn wire_time(&self) -> WireTime {
        self.wire_time
    }

    /// Every SubDevice of the segment in ring order, with its role.
    pub fn bus_devices(&self) -> &[BusDevice] {
        &self.bus
    }

    /// The working counter each process-data datagram of a good cycle returns (plan order).
    pub fn datagram_wkcs(&self) -> &[u16] {
        &self.lrw_expected
    }

    /// The messages of the start-up: the segment (info 900400), every SubDevice the machine
    /// does not name (info 900401), the wire time of a cycle (info 900402).
    pub fn startup_messages(&self) -> Vec<CncMessage> {
        let unnamed: Vec<&BusDevice> = self
            .bus
            .iter()
            .filter(|b| b.role == Role::NotNamed)
            .collect();
        let mut out = vec![CncMessage::info(
            ids::ETHERCAT_SEGMENT,
            format!(
                "EtherCAT segment: {} SubDevices in OP: {} axis drive{}, {} terminal{} named in the machine, {} not named; process image {} bytes in {} LRW datagram{}",
                self.bus.len(),
                self.axes.len(),
                plural(self.axes.len()),
                self.terminals.len(),
                plural(self.terminals.len()),
                unnamed.len(),
                self.plan
                    .lrw_datagrams()
                    .map(|(_, _, n)| n)
                    .sum::<usize>(),
                self.plan.lrw_count(),
                plural(self.plan.lrw_count()),
            ),
        )];
        for b in unnamed {
            out.push(CncMessage::info(
                ids::ETHERCAT_NOT_NAMED,
                format!(
                    "EtherCAT device {} ({}, vendor {:#010x} product {:#010x}): not named in the machine file; in OP with its default process data ({} output / {} input bytes)",
                    b.position, b.name, b.vendor, b.product, b.outputs, b.inputs
                ),
            ));
        }
        out.extend(self.axes.iter().flat_map(|a| a.warnings.iter().cloned()));
        out.push(CncMessage::info(
            ids::ETHERCAT_WIRE_TIME,
            format!(
                "EtherCAT wire time per cycle {}: {:.0} % of the {} µs cycle",
                self.wire_time,
                self.wire_time.total_ns() as f64 * 100.0 / self.cycle.0.max(1) as f64,
                self.cycle.0 / 1000
            ),
        ));
        out
    }

    /// Inputs of terminal `index` (machine order) after the last exchange.
    pub fn terminal_inputs(&self, index: usize) -> Option<&[u8]> {
        self.terminals.get(index).map(|t| t.inputs.as_slice())
    }

    /// Outputs of terminal `index`, sent with the next exchange.
    pub fn terminal_outputs_mut(&mut self, index: usize) -> Option<&mut [u8]> {
        self.terminals
            .get_mut(index)
            .map(|t| t.outputs.as_mut_slice())
    }

    /// Name of terminal `index`.
    pub fn terminal_name(&self, index: usize) -> Option<&str> {
        self.terminals.get(index).map(|t| t.name.as_str())
    }

    /// Exchanges attempted so far.
    pub fn exchanges(&self) -> u64 {
        self.exchanges
    }

    /// One exchange of the paced cycle on a network interface: wait for the deadline (with DC
    /// half a period after SYNC0), send, receive, record. A wait that found deadlines already
    /// passed (the process was stopped or overloaded) is [`LinkError::Stalled`] after the frame
    /// went out: the devices had no set-point for that long, the channel counts every missed
    /// cycle. The images are only updated from a good frame.
    fn paced_exchange(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Result<(), LinkError> {
        let Some(clock) = self.clock.as_mut() else {
            return Ok(());
        };
        let wake = clock.tick();
        let sent = crate::rt::monotonic_ns();
        let result = self.cycle_frame(now);
        let done = crate::rt::monotonic_ns();
        let dc_diff = if result.is_ok() {
            self.dc_watch()
        } else {
            None
        };
        if let Some(clock) = self.clock.as_mut() {
            if let Ok(Some((wait, _))) = &result {
                clock.track(sent.saturating_add(wait.as_nanos() as u64));
            }
            clock.stats_mut().record(CycleRecord {
                deadline: wake.deadline,
                sent,
                done,
                missed: wake.missed,
                lost: result.is_err(),
                dc_diff,
            });
        }
        let dc = result?;
        self.sample_dc = dc.and_then(|(_, system_time)| sample_time(system_time, self.cycle.0));
        // Periods without a frame: counted (overruns); the drives held their set-points and the
        // channel did not advance either. Only a gap as long as the devices' sync-manager
        // watchdog is a stalled master: by then they have dropped to SAFE-OP.
        let gap_ns = wake.missed.saturating_mul(self.cycle.0);
        if wake.missed > 0 && gap_ns >= self.watchdog_ns {
            return Err(LinkError::Stalled {
                missed: wake.missed,
                ms: gap_ns as f64 * 1e-6,
            });
        }
        self.copy_inputs(images)
    }

    /// Working counter a good cycle returns.
    pub fn expected_wkc(&self) -> u16 {
        self.expected_wkc
    }

    /// One LRW; returns the working counter and, with DC, the time from now to the next cycle
    /// start at its shift from SYNC0 (ethercrab's `CycleInfo::next_cycle_wait`) and the
    /// reference clock's DC system time the frame read (its FRMW of 0x0910).
    fn tx_rx(&mut self) -> Result<(u16, Option<(Duration, u64)>), ethercrab::error::Error> {
        let md = self.md;
        match &self.group {
            Group::Dc(g) => drive(&mut self.wire, g.tx_rx_dc(md)).map(|r| {
                (
                    r.working_counter,
                    Some((r.extra.next_cycle_wait, r.extra.dc_system_time)),
                )
            }),
            Group::NoDc(g) => drive(&mut self.wire, g.tx_rx(md)).map(|r| (r.working_counter, None)),
        }
    }

    /// Every [`DC_WATCH_EVERY`] cycles: one DC device's system-time difference (0x092C: bit 31
    /// sign, bits 0..30 magnitude in ns), round-robin. `None` in the other cycles or without DC.
    fn dc_watch(&mut self) -> Option<u32> {
        if self.dc_devices.is_empty() || !self.exchanges.is_multiple_of(DC_WATCH_EVERY) {
            return None;
        }
        let addr = self.dc_devices[self.dc_next % self.dc_devices.len()];
        self.dc_next = self.dc_next.wrapping_add(1);
        let md = self.md;
        let raw = drive(
            &mut self.wire,
            ethercrab::Command::fprd(addr, 0x092C).receive::<u32>(md),
        )
        .ok()?;
        Some(raw & 0x7FFF_FFFF)
    }

    /// `data` into the outputs of SubDevice `sub` in ethercrab's PDI (as many bytes as fit).
    fn put_outputs(&self, sub: usize, data: &[u8]) -> Result<(), LinkError> {
        let md = self.md;
        let put = |out: &mut [u8]| {
            let n = out.len().min(data.len());
            out[..n].copy_from_slice(&data[..n]);
        };
        match &self.group {
            Group::Dc(g) => put(&mut g
                .subdevice(md, sub)
                .map_err(ec_err("subdevice"))?
                .outputs_raw_mut()),
            Group::NoDc(g) => put(&mut g
                .subdevice(md, sub)
                .map_err(ec_err("subdevice"))?
                .outputs_raw_mut()),
        }
        Ok(())
    }

    /// The inputs of SubDevice `sub` from ethercrab's PDI into `data` (as many bytes as fit).
    fn get_inputs(&self, sub: usize, data: &mut [u8]) -> Result<(), LinkError> {
        let md = self.md;
        let mut get = |inp: &[u8]| {
            let n = inp.len().min(data.len());
            data[..n].copy_from_slice(&inp[..n]);
        };
        match &self.group {
            Group::Dc(g) => get(&g
                .subdevice(md, sub)
                .map_err(ec_err("subdevice"))?
                .inputs_raw()),
            Group::NoDc(g) => get(&g
                .subdevice(md, sub)
                .map_err(ec_err("subdevice"))?
                .inputs_raw()),
        }
        Ok(())
    }

    fn copy_outputs(&self, images: &[ProcessImage]) -> Result<(), LinkError> {
        for (ax, img) in self.axes.iter().zip(images) {
            self.put_outputs(ax.sub, &img.outputs)?;
        }
        for t in &self.terminals {
            self.put_outputs(t.sub, &t.outputs)?;
        }
        Ok(())
    }

    fn copy_inputs(&mut self, images: &mut [ProcessImage]) -> Result<(), LinkError> {
        for (ax, img) in self.axes.iter().zip(images.iter_mut()) {
            self.get_inputs(ax.sub, &mut img.inputs)?;
        }
        let mut terminals = std::mem::take(&mut self.terminals);
        let r = terminals
            .iter_mut()
            .try_for_each(|t| self.get_inputs(t.sub, &mut t.inputs));
        self.terminals = terminals;
        r
    }

    fn lost(&self, now: Nanos, reason: String) -> LinkError {
        LinkError::Lost { at: now, reason }
    }

    /// The emulated segment drops / miscounts the frames of exchange `n` the fault knobs name.
    #[cfg(feature = "sim")]
    fn arm_fault_knobs(&mut self, n: u64) {
        let Some(seg) = self.wire.segment_mut() else {
            return;
        };
        let next = seg.offered_frames();
        let frame_of = |k: usize| {
            self.plan
                .lrw_datagrams()
                .nth(k)
                .map_or(k as u64, |(f, _, _)| f as u64)
        };
        for &(_, k) in self.lose.range((n, 0)..=(n, usize::MAX)) {
            seg.drop_frame_at(next + frame_of(k));
        }
        for &(_, k) in self.miscount.range((n, 0)..=(n, usize::MAX)) {
            seg.miscount_frame_at(next + frame_of(k));
        }
    }

    /// One cycle's frames; every process-data datagram is checked on its own (module
    /// documentation). Returns, with DC, ethercrab's wait to the next cycle start and the
    /// reference clock's system time the frame read.
    fn cycle_frame(&mut self, now: Nanos) -> Result<Option<(Duration, u64)>, LinkError> {
        self.wire.log.start();
        let result = self.tx_rx();
        self.wire.log.stop();
        let map = &self.map;
        let plan = &self.plan;
        let expected = &self.lrw_expected;
        let checked = self.wire.log.check(plan.lrw_count(), |c, a, n| {
            // The planned datagram's counter; another split (not ethercrab 0.7.1's) is
            // computed from the map.
            plan.lrw_datagrams()
                .position(|(_, pa, pn)| pa == a && pn == n)
                .and_then(|k| expected.get(k).copied())
                .filter(|_| c == crate::bus::ethercat::wire::Command::Lrw)
                .unwrap_or_else(|| map.expected_wkc(c, a, n))
        });
        match (result, checked) {
            (Ok((_, next)), Ok(())) => Ok(next),
            (r, Err(mut fault)) => {
                fault.devices = self
                    .map
                    .devices_in(fault.datagram.start, fault.datagram.len);
                let tail = match r {
                    Err(e) => format!(" (ethercrab: {e})"),
                    Ok(_) => String::new(),
                };
                Err(self.lost(now, format!("{fault}{tail}")))
            }
            (Err(e), Ok(())) => Err(self.lost(
                now,
                format!(
                    "frame lost: {e} (all {} process-data datagram{} of the cycle came back: a frame of AL status checks)",
                    self.plan.lrw_count(),
                    plural(self.plan.lrw_count())
                ),
            )),
        }
    }
}

/// The SYNC0 before a frame that read the reference clock's system time `system_time`: SYNC0
/// runs at the multiples of the cycle `cycle_ns` in DC system time (ethercrab's
/// `configure_dc_sync` puts the start time on that grid; `CycleInfo::cycle_start_offset` is
/// `system_time % cycle` the same way), and the paced master's frame lands half a period after
/// it — so the inputs the frame reads are what the devices sampled at that SYNC0. `None` for a
/// zero cycle or a time beyond `i64`.
pub fn sample_time(system_time: u64, cycle_ns: u64) -> Option<i64> {
    if cycle_ns == 0 {
        return None;
    }
    i64::try_from(system_time - system_time % cycle_ns).ok()
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// The FMMU windows of the SubDevices at `addresses` (ring order): the number of FMMUs
/// (0x0004), then their registers (0x0600 + 16 n).
async fn read_logical_map(
    md: &MainDevice<'static>,
    addresses: &[u16],
) -> Result<LogicalMap, LinkError> {
    let mut windows = Vec::new();
    for (position, &a) in addresses.iter().enumerate() {
        let count = ethercrab::Command::fprd(a, 0x0004)
            .receive::<u8>(md)
            .await
            .map_err(ec_err("FMMU count"))?;
        for n in 0..u16::from(count.min(16)) {
            let regs = ethercrab::Command::fprd(a, 0x0600 + 16 * n)
                .receive::<[u8; 16]>(md)
                .await
                .map_err(ec_err("FMMU registers"))?;
            if let Some(w) = FmmuWindow::from_registers(position, &regs) {
                windows.push(w);
            }
        }
    }
    Ok(LogicalMap::new(windows))
}

/// Refuse a cycle time of `cycle_ns` the wire cannot carry (error 900403).
fn check_wire_time(w: &WireTime, cycle_ns: u64) -> Result<(), LinkError> {
    if w.total_ns() <= cycle_ns {
        return Ok(());
    }
    Err(LinkError::Refused(CncMessage::error(
        ids::ETHERCAT_CYCLE_TOO_SHORT,
        format!(
            "the EtherCAT wire needs {w} per cycle, more than the cycle time of {} µs (cycle_time_us); the shortest cycle the wire carries is {} µs",
            cycle_ns / 1000,
            w.shortest_cycle_us()
        ),
    )))
}

/// An AL state in the words IgH's `ethercat slaves` uses: `INIT`, `PREOP`, `BOOT`, `SAFEOP`,
/// `OP` (ETG.1000.6 AL control states).
pub fn igh_state(st: ethercrab::SubDeviceState) -> String {
    use ethercrab::SubDeviceState as S;
    match st {
        S::Init => "INIT".into(),
        S::PreOp => "PREOP".into(),
        S::Bootstrap => "BOOT".into(),
        S::SafeOp => "SAFEOP".into(),
        S::Op => "OP".into(),
        other => format!("{other:?}").to_uppercase(),
    }
}

/// One SubDevice as [`Session::devices`] reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SubDeviceInfo {
    /// Ring position (0 = next to the MainDevice).
    pub position: usize,
    /// Configured station address.
    pub address: u16,
    /// Vendor ID.
    pub vendor: u32,
    /// Product code.
    pub product: u32,
    /// Revision.
    pub revision: u32,
    /// Name from the SII.
    pub name: String,
    /// AL state, IgH-style ([`igh_state`]: `PREOP`, `SAFEOP`, `OP`).
    pub state: String,
    /// DC support (`none`, `32 bit`, `64 bit`).
    pub dc: String,
    /// Mailbox SMs (write SM0, read SM1) as (start, length); length 0 = no mailbox.
    pub mailbox: ((u16, u16), (u16, u16)),
}

/// A bus in PRE-OP for commissioning commands: scan, SDO and IDN access by ring position.
pub struct Session {
    md: &'static MainDevice<'static>,
    wire: WireEnd,
    devices: Vec<SubDeviceInfo>,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("devices", &self.devices)
            .finish_non_exhaustive()
    }
}

impl Session {
    /// Initialise the bus on `wire` (`ethercat-emu`: the segment of `spec`) to PRE-OP and read
    /// every SubDevice's identity, state, DC support and mailbox.
    pub fn open(wire: &Wire, spec: &EthercatSpec) -> Result<Self, LinkError> {
        let (md, mut wire_end) = connect(wire, spec)?;
        let devices = drive(&mut wire_end, async {
            let group = md
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now)
                .await
                .map_err(ec_err("init"))?;
            let mut out = Vec::new();
            for (position, sd) in group.iter(md).enumerate() {
                let id = sd.identity();
                let state = match sd.status().await {
                    Ok((st, ethercrab::AlStatusCode::NoError)) => igh_state(st),
                    Ok((st, code)) => format!("{} (AL status {code})", igh_state(st)),
                    Err(e) => format!("unknown ({e})"),
                };
                let dc = match sd.dc_support() {
                    ethercrab::DcSupport::None => "none",
                    ethercrab::DcSupport::RefOnly => "reference only",
                    ethercrab::DcSupport::Bits64 => "64 bit",
                    ethercrab::DcSupport::Bits32 => "32 bit",
                };
                let regs = ethercrab::Command::fprd(sd.configured_address(), 0x0800)
                    .receive::<[u8; 16]>(md)
                    .await
                    .map_err(ec_err("SM registers"))?;
                let sm = |o: usize| {
                    (
                        u16::from_le_bytes([regs[o], regs[o + 1]]),
                        u16::from_le_bytes([regs[o + 2], regs[o + 3]]),
                    )
                };
                out.push(SubDeviceInfo {
                    position,
                    address: sd.configured_address(),
                    vendor: id.vendor_id,
                    product: id.product_id,
                    revision: id.revision,
                    name: sd.name().to_string(),
                    state,
                    dc: dc.to_string(),
                    // Mailbox mode = control byte bits 0-1 = 10.
                    mailbox: if regs[4] & 0x03 == 0x02 && regs[12] & 0x03 == 0x02 {
                        (sm(0), sm(8))
                    } else {
                        ((0, 0), (0, 0))
                    },
                });
            }
            Ok::<_, LinkError>(out)
        })
        .map_err(|e| wire_end.explain(e))?;
        Ok(Session {
            md,
            wire: wire_end,
            devices,
        })
    }

    /// The SubDevices found, in ring order.
    pub fn devices(&self) -> &[SubDeviceInfo] {
        &self.devices
    }

    /// Flush the `--pcap` capture at the end of a command ([`Link::finish_capture`]).
    ///
    /// # Errors
    /// The first write to the capture that failed, naming the option and the file.
    pub fn finish_capture(&mut self) -> Result<(), String> {
        self.wire.finish_capture()
    }

    fn device(&self, position: usize) -> Result<&SubDeviceInfo, LinkError> {
        let d = self.devices.get(position).ok_or_else(|| {
            LinkError::Other(format!(
                "device {position}: no such SubDevice ({} found, positions 0 … {})",
                self.devices.len(),
                self.devices.len().saturating_sub(1)
            ))
        })?;
        if d.mailbox.0 .1 == 0 || d.mailbox.1 .1 == 0 {
            return Err(LinkError::Other(format!(
                "device {position} ({}): has no mailbox",
                d.name
            )));
        }
        Ok(d)
    }

    fn named(&self, position: usize, e: MailboxError) -> LinkError {
        if let MailboxError::Abort {
            index, sub, code, ..
        } = e
        {
            return LinkError::Abort {
                device: Peer::Device(position),
                index,
                sub,
                code,
            };
        }
        let name = self.devices.get(position).map_or("?", |d| d.name.as_str());
        if let MailboxError::Soe {
            idn, code, text, ..
        } = e
        {
            return LinkError::Soe {
                device: position,
                name: name.to_string(),
                idn,
                code,
                text,
            };
        }
        LinkError::Other(format!("device {position} ({name}): {e}"))
    }

    /// SDO upload of `index:sub` from the SubDevice at `position` (any size, segmented too).
    pub fn sdo_read(&mut self, position: usize, index: u16, sub: u8) -> Result<Vec<u8>, LinkError> {
        let d = self.device(position)?;
        let mut c = CoeClient::new(d.address, d.mailbox.0, d.mailbox.1);
        if self.wire.is_emulated() {
            c.timeout = EMULATED_TIMEOUT;
        }
        let md = self.md;
        drive(&mut self.wire, c.sdo_upload(md, index, sub)).map_err(|e| self.named(position, e))
    }

    /// SDO download of `data` to `index:sub` of the SubDevice at `position`.
    pub fn sdo_write(
        &mut self,
        position: usize,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), LinkError> {
        let d = self.device(position)?;
        let mut c = CoeClient::new(d.address, d.mailbox.0, d.mailbox.1);
        if self.wire.is_emulated() {
            c.timeout = EMULATED_TIMEOUT;
        }
        let md = self.md;
        drive(&mut self.wire, c.sdo_download(md, index, sub, data))
            .map_err(|e| self.named(position, e))
    }

    /// SoE read of IDN `idn` (value, with the length from its attribute) and its name.
    pub fn idn_read(&mut self, position: usize, idn: u16) -> Result<(i64, String), LinkError> {
        let d = self.device(position)?;
        let mut c = SoeClient::new(d.address, d.mailbox.0, d.mailbox.1);
        if self.wire.is_emulated() {
            c.timeout = EMULATED_TIMEOUT;
        }
        let md = self.md;
        let r = drive(&mut self.wire, async {
            let v = c.read_value(md, 0, idn).await?;
            let name = c.read_name(md, 0, idn).await.unwrap_or_default();
            Ok::<_, MailboxError>((v, name))
        });
        r.map_err(|e| self.named_soe(position, e))
    }

    /// SoE write of `value` to IDN `idn` (length from its attribute).
    pub fn idn_write(&mut self, position: usize, idn: u16, value: i64) -> Result<(), LinkError> {
        let d = self.device(position)?;
        let mut c = SoeClient::new(d.address, d.mailbox.0, d.mailbox.1);
        if self.wire.is_emulated() {
            c.timeout = EMULATED_TIMEOUT;
        }
        let md = self.md;
        drive(&mut self.wire, c.write_value(md, 0, idn, value))
            .map_err(|e| self.named_soe(position, e))
    }

    /// [`Self::named`] for an SoE access: the mailbox error reply "unsupported protocol"
    /// (0x0002) says the device has no SoE (a CoE-only device), and is said so.
    fn named_soe(&self, position: usize, e: MailboxError) -> LinkError {
        match e {
            MailboxError::MailboxErrorReply(
                code @ crate::bus::ethercat::mailbox::UNSUPPORTED_PROTOCOL,
            ) => LinkError::Unsupported {
                device: position,
                name: self
                    .devices
                    .get(position)
                    .map_or("?", |d| d.name.as_str())
                    .to_string(),
                protocol: "SoE",
                code,
            },
            e => self.named(position, e),
        }
    }
}

/// (output, input) image bytes of a drive definition's process data.
fn image_lengths(def: &DriveDefinition) -> (usize, usize) {
    match crate::drive::model::for_definition(def) {
        Ok(m) => (m.rx_len(), m.tx_len()),
        Err(_) => (def.rxpdo.len(), def.txpdo.len()),
    }
}

/// Match axes and terminals to SubDevices: axis `k` takes the next SubDevice (ring order) with
/// the identity of its family's ESI device, or — for drives the emulator does not describe —
/// the next SubDevice; then the terminals theirs ([`terminals::match_terminals`]). Mailbox
/// clients from the SM0 / SM1 registers the MainDevice configured. Every SubDevice in ring
/// order with its role (image sizes filled in later).
async fn assign_devices(
    md: &MainDevice<'static>,
    group: &SubDeviceGroup<
        MAX_SUBDEVICES,
        MAX_PDI,
        ethercrab::DefaultLock,
        ethercrab::subdevice_group::PreOp,
    >,
    spec: &EthercatSpec,
) -> Result<(Vec<AxisDevice>, Vec<TerminalDevice>, Vec<BusDevice>), LinkError> {
    let subs: Vec<(u16, u32, u32, String)> = group
        .iter(md)
        .map(|sd| {
            let id = sd.identity();
            (
                sd.configured_address(),
                id.vendor_id,
                id.product_id,
                sd.name().to_string(),
            )
        })
        .collect();
    let revisions: Vec<u32> = group.iter(md).map(|sd| sd.identity().revision).collect();
    // The declared SubDevices in ring order, each found by identity after the previous one: a
    // drive definition with `[device]` by that identity (as a real master finds a device:
    // vendor id and product code from the SII), a drive the emulator describes by its ESI.
    let order = terminals::ring_order(spec.drives.len(), &spec.terminals);
    let wants: Vec<Option<(u32, u32)>> = order
        .iter()
        .map(|d| match *d {
            terminals::Declared::Axis(k) => spec.drives.get(k).and_then(|def| {
                def.identity
                    .map(|i| (i.vendor_id, i.product_code))
                    .or_else(|| {
                        esi_for(def)
                            .and_then(|t| embedded(t, "embedded ESI").ok())
                            .and_then(|f| f.devices.first().map(|d| (f.vendor.id, d.product_code)))
                    })
            }),
            terminals::Declared::Terminal(k) => spec.terminals.get(k).and_then(|t| t.identity()),
        })
        .collect();
    let ids: Vec<(u32, u32)> = subs.iter().map(|(_, v, p, _)| (*v, *p)).collect();
    let mut kept: Vec<Option<CoeClient>> = Vec::new();
    let found = match terminals::match_ring(&wants, &ids) {
        Ok(found) => Ok(found),
        // A drive definition without `[device]` on a vendor's drive: take the devices whose
        // device type (0x1000) says CiA 402, else any device with a CoE mailbox (the device
        // type is then only checked, warning 900406).
        Err(e) => match embedded(SERVO_ESI, "embedded ESI")
            .ok()
            .and_then(|f| f.devices.first().map(|d| (f.vendor.id, d.product_code)))
        {
            Some(servo) => {
                let stations: Vec<u16> = subs.iter().map(|s| s.0).collect();
                let (types, clients) = pdo_fit::device_types(md, &stations, &ids, servo).await;
                kept = clients;
                let as_servo = |take: &dyn Fn(Option<u32>) -> bool| -> Vec<(u32, u32)> {
                    ids.iter()
                        .zip(&types)
                        .map(|(id, t)| if take(*t) { servo } else { *id })
                        .collect()
                };
                let cia402 = as_servo(&|t| t.is_some_and(|t| t & 0xFFFF == 402));
                let coe = as_servo(&|t| t.is_some());
                terminals::match_ring(&wants, &cia402)
                    .or_else(|_| terminals::match_ring(&wants, &coe))
                    .map_err(|_| e)
            }
            None => Err(e),
        },
    };
    let found = found.map_err(|(j, next)| {
        let what = match order.get(j) {
            Some(terminals::Declared::Axis(k)) => format!(
                "axis {k} (drive '{}')",
                spec.drives.get(*k).map_or("?", |d| d.name.as_str())
            ),
            Some(terminals::Declared::Terminal(k)) => spec.terminals.get(*k).map_or_else(
                || "?".to_string(),
                |t| {
                    let (v, p) = t.identity().unwrap_or((0, 0));
                    format!(
                        "terminal {} ({}, {} vendor {v:#010x} product {p:#010x})",
                        t.name,
                        t.source,
                        t.type_name()
                    )
                },
            ),
            None => "?".to_string(),
        };
        LinkError::Other(format!(
            "{what}: no matching SubDevice on the bus after position {next} ({} SubDevices found)",
            subs.len()
        ))
    })?;
    let mut axis_pos = vec![0usize; spec.drives.len()];
    let mut positions = vec![0usize; spec.terminals.len()];
    for (d, &p) in order.iter().zip(&found) {
        match *d {
            terminals::Declared::Axis(k) => axis_pos[k] = p,
            terminals::Declared::Terminal(k) => positions[k] = p,
        }
    }
    let mut axes = Vec::new();
    for (axis, def) in spec.drives.iter().enumerate() {
        let i = axis_pos[axis];
        let Some((station, _, _, name)) = subs.get(i) else {
            continue;
        };
        let regs = ethercrab::Command::fprd(*station, 0x0800)
            .receive::<[u8; 16]>(md)
            .await
            .map_err(ec_err("SM registers"))?;
        let sm = |o: usize| {
            (
                u16::from_le_bytes([regs[o], regs[o + 1]]),
                u16::from_le_bytes([regs[o + 2], regs[o + 3]]),
            )
        };
        // SM0 / SM1 are the mailbox only in mailbox mode (control byte bits 0-1 = 10).
        let mailbox_mode = regs[4] & 0x03 == 0x02 && regs[12] & 0x03 == 0x02;
        let (out, inp) = if mailbox_mode {
            (sm(0), sm(8))
        } else {
            ((0, 0), (0, 0))
        };
        let mailbox = if out.1 == 0 || inp.1 == 0 {
            Mailbox::None
        } else if def.profile == Profile::Sercos {
            Mailbox::Soe(SoeClient::new(*station, out, inp))
        } else {
            match kept.get_mut(i).and_then(Option::take) {
                Some(c) => Mailbox::Coe(c),
                None => Mailbox::Coe(CoeClient::new(*station, out, inp)),
            }
        };
        let mut warnings = Vec::new();
        if let (Some(want), Some(&got)) = (def.identity.and_then(|d| d.revision), revisions.get(i))
        {
            if want != got {
                warnings.push(CncMessage::warning(
                    ids::ETHERCAT_DEVICE_CHECK,
                    format!(
                        "device {axis}:{name} (position {i}) has revision {got:#010x}, drive '{}' \
                         ({}) is for revision {want:#010x}: taken by vendor id and product code",
                        def.name, def.file
                    ),
                ));
            }
        }
        axes.push(AxisDevice {
            sub: i,
            def: def.clone(),
            mailbox,
            name: format!("{axis}:{name}"),
            warnings,
        });
    }
    let terminals: Vec<TerminalDevice> = spec
        .terminals
        .iter()
        .zip(&positions)
        .map(|(t, &sub)| TerminalDevice {
            sub,
            name: t.name.clone(),
            outputs: Vec::new(),
            inputs: Vec::new(),
        })
        .collect();
    let bus = subs
        .iter()
        .enumerate()
        .map(|(position, (address, vendor, product, name))| {
            let role = if let Some(k) = axes.iter().position(|a| a.sub == position) {
                Role::Axis {
                    index: k,
                    drive: spec
                        .drives
                        .get(k)
                        .map_or_else(String::new, |d| d.name.clone()),
                }
            } else if let Some(k) = positions.iter().position(|&p| p == position) {
                Role::Terminal {
                    index: k,
                    name: spec.terminals[k].name.clone(),
                }
            } else {
                Role::NotNamed
            };
            BusDevice {
                position,
                address: *address,
                vendor: *vendor,
                product: *product,
                name: name.clone(),
                role,
                outputs: 0,
                inputs: 0,
            }
        })
        .collect();
    Ok((axes, terminals, bus))
}

/// Enable every process-data sync manager that has a length but is not enabled. ethercrab
/// 0.7.1 enables a sync manager only where the SII says `Enable` (`write_sm_config`); an ESI
/// may declare its process-data sync managers disabled with size 0 for the configurator to size
/// and enable once PDOs are assigned (Bohign CL86EC: `Sm DefaultSize="0" Enable="0"`), as
/// TwinCAT and SOEM do — left disabled, such a device refuses SAFE-OP (invalid output / input
/// configuration). Mailbox sync managers (mode bits 10b) are left as they are.
async fn enable_sized_sync_managers(
    md: &MainDevice<'static>,
    addresses: &[u16],
) -> Result<(), LinkError> {
    for &a in addresses {
        let regs = ethercrab::Command::fprd(a, 0x0800)
            .receive::<[u8; 64]>(md)
            .await
            .map_err(ec_err("SM registers"))?;
        for n in 0..8usize {
            let r = &regs[8 * n..8 * n + 8];
            let len = u16::from_le_bytes([r[2], r[3]]);
            let mailbox = r[4] & 0x03 == 0x02;
            if len > 0 && !mailbox && r[6] & 0x01 == 0 {
                ethercrab::Command::fpwr(a, 0x0806 + 8 * n as u16)
                    .send(md, r[6] | 0x01)
                    .await
                    .map_err(ec_err("SM enable"))?;
            }
        }
    }
    Ok(())
}

/// Configure the PDOs of an axis in PRE-OP (CiA 301 / ETG.1000.6 §5.6.7.4 procedure):
/// * a direction whose definition names fixed PDOs (`fixed = true`): assign them (0x1C12 /
///   0x1C13: sub-index 0 = 0, the PDOs, sub-index 0 = their number — only when the device's
///   assignment differs) and read their mapping back: it must be the definition's entries,
///   object for object and bit for bit (error [`ids::ETHERCAT_FIXED_PDO`] otherwise); the
///   mapping itself is never written;
/// * otherwise write the entries into the definition's PDO (`pdos`, default 0x1600 / 0x1A00)
///   and assign it alone.
async fn write_pdo_mapping(
    md: &MainDevice<'static>,
    c: &mut CoeClient,
    def: &DriveDefinition,
    who: &str,
) -> Result<(), LinkError> {
    for (assign, default_pdo, layout, a) in [
        (0x1C12u16, 0x1600u16, &def.rxpdo, &def.rx_assign),
        (0x1C13, 0x1A00, &def.txpdo, &def.tx_assign),
    ] {
        if a.fixed {
            assign_fixed(md, c, assign, &a.pdos, who).await?;
            check_fixed(md, c, &a.pdos, layout, def, who).await?;
            continue;
        }
        let pdo = a.pdos.first().copied().unwrap_or(default_pdo);
        // A device that refuses the mapping often has fixed PDOs (or fewer entries): say where
        // a definition that takes them as they are comes from.
        let what = |s: &str| {
            format!(
                "device {who}: PDO mapping {s} (drive '{}' maps its entries into {pdo:#06x}; for \
                 a device whose PDOs are fixed or smaller, `fieldprobe drive from-esi \
                 VENDOR.xml` writes a definition with the PDOs its ESI offers)",
                def.name
            )
        };
        c.sdo_download(md, assign, 0, &[0])
            .await
            .map_err(mbx_err(what(&format!("{assign:#06x}:00 = 0"))))?;
        c.sdo_download(md, pdo, 0, &[0])
            .await
            .map_err(mbx_err(what(&format!("{pdo:#06x}:00 = 0"))))?;
        for (k, e) in layout.entries().iter().enumerate() {
            let v = e.mapping_value();
            c.sdo_download(md, pdo, (k + 1) as u8, &v.to_le_bytes())
                .await
                .map_err(mbx_err(what(&format!("{pdo:#06x}:{:02x}", k + 1))))?;
        }
        let n = layout.entries().len() as u8;
        c.sdo_download(md, pdo, 0, &[n])
            .await
            .map_err(mbx_err(what(&format!("{pdo:#06x}:00 = {n}"))))?;
        c.sdo_download(md, assign, 1, &pdo.to_le_bytes())
            .await
            .map_err(mbx_err(what(&format!("{assign:#06x}:01"))))?;
        c.sdo_download(md, assign, 0, &[1])
            .await
            .map_err(mbx_err(what(&format!("{assign:#06x}:00 = 1"))))?;
    }
    Ok(())
}

/// The first byte of an SDO upload (sub-index 0 counts), or the error named.
async fn upload_u8(
    md: &MainDevice<'static>,
    c: &mut CoeClient,
    index: u16,
    sub: u8,
    who: &str,
) -> Result<u8, LinkError> {
    let v = c.sdo_upload(md, index, sub).await.map_err(mbx_err(format!(
        "device {who}: reading {index:#06x}:{sub:02x}"
    )))?;
    Ok(v.first().copied().unwrap_or(0))
}

/// A little-endian number of up to 4 bytes from an SDO upload.
async fn upload_u32(
    md: &MainDevice<'static>,
    c: &mut CoeClient,
    index: u16,
    sub: u8,
    who: &str,
) -> Result<u32, LinkError> {
    let v = c.sdo_upload(md, index, sub).await.map_err(mbx_err(format!(
        "device {who}: reading {index:#06x}:{sub:02x}"
    )))?;
    let mut b = [0u8; 4];
    let n = v.len().min(4);
    b[..n].copy_from_slice(&v[..n]);
    Ok(u32::from_le_bytes(b))
}

/// Assign the fixed PDOs `pdos` to `assign` unless the device has exactly them assigned.
async fn assign_fixed(
    md: &MainDevice<'static>,
    c: &mut CoeClient,
    assign: u16,
    pdos: &[u16],
    who: &str,
) -> Result<(), LinkError> {
    let n = upload_u8(md, c, assign, 0, who).await?;
    let mut current = Vec::new();
    for k in 1..=n {
        current.push(upload_u32(md, c, assign, k, who).await? as u16);
    }
    if current == pdos {
        return Ok(());
    }
    let refused = |e: MailboxError| {
        LinkError::Refused(CncMessage::error(
            ids::ETHERCAT_FIXED_PDO,
            format!(
                "device {who}: assigning the fixed PDOs {} to {assign:#06X} (the device has {}): {e}",
                hex_list(pdos),
                hex_list(&current)
            ),
        ))
    };
    c.sdo_download(md, assign, 0, &[0]).await.map_err(refused)?;
    for (k, p) in pdos.iter().enumerate() {
        c.sdo_download(md, assign, (k + 1) as u8, &p.to_le_bytes())
            .await
            .map_err(refused)?;
    }
    c.sdo_download(md, assign, 0, &[pdos.len() as u8])
        .await
        .map_err(refused)?;
    Ok(())
}

/// `[0x1600, 0x1A00]` as `0x1600, 0x1A00` (`none` when empty).
fn hex_list(v: &[u16]) -> String {
    if v.is_empty() {
        return "none".into();
    }
    v.iter()
        .map(|p| format!("{p:#06X}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Read the mapping of the fixed PDOs back and compare it with the definition's entries.
async fn check_fixed(
    md: &MainDevice<'static>,
    c: &mut CoeClient,
    pdos: &[u16],
    layout: &crate::drive::pdo::PdoLayout,
    def: &DriveDefinition,
    who: &str,
) -> Result<(), LinkError> {
    let mut got: Vec<u32> = Vec::new();
    for &p in pdos {
        let n = upload_u8(md, c, p, 0, who).await?;
        for k in 1..=n {
            got.push(upload_u32(md, c, p, k, who).await?);
        }
    }
    let want: Vec<u32> = layout
        .entries()
        .iter()
        .map(crate::drive::pdo::PdoEntry::mapping_value)
        .collect();
    if got == want {
        return Ok(());
    }
    let show = |v: &[u32]| {
        v.iter()
            .map(|m| format!("{:04X}:{:02X}/{}", m >> 16, (m >> 8) & 0xFF, m & 0xFF))
            .collect::<Vec<_>>()
            .join(" ")
    };
    Err(LinkError::Refused(CncMessage::error(
        ids::ETHERCAT_FIXED_PDO,
        format!(
            "device {who}: the fixed PDOs {} map [{}] (index:sub/bits), drive '{}' ({}) expects \
             [{}]",
            hex_list(pdos),
            show(&got),
            def.name,
            def.file,
            show(&want)
        ),
    )))
}

/// Cyclic synchronous position needs the mode of operation 8 (CiA 402 0x6060). When no PDO
/// carries it, write it once by SDO in PRE-OP — to 0x6060, or the object that plays it
/// (`[roles] modes_of_operation`, e.g. 0x7010:03 of a Beckhoff MDP 742 terminal). A device
/// without that object gets warning [`ids::ETHERCAT_NO_MODE_OBJECT`] and runs in its own mode.
async fn write_mode(
    md: &MainDevice<'static>,
    c: &mut CoeClient,
    def: &DriveDefinition,
    who: &str,
) -> Result<Option<CncMessage>, LinkError> {
    if def.profile != Profile::Cia402 || def.rxpdo.contains(0x6060, 0) {
        return Ok(None);
    }
    let (index, sub) = def.object_of(0x6060, 0);
    let mode = crate::drive::ds402::MODE_CSP as u8;
    match c.sdo_download(md, index, sub, &[mode]).await {
        Ok(()) => Ok(None),
        Err(MailboxError::Abort { code, .. }) if code == 0x0602_0000 || code == 0x0609_0011 => {
            Ok(Some(CncMessage::warning(
                ids::ETHERCAT_NO_MODE_OBJECT,
                format!(
                    "device {who}: the mode of operation is in no PDO and the device has no \
                     {index:#06X}:{sub:02X} to write it (abort {code:#010x}): the drive runs in \
                     the mode it is in"
                ),
            )))
        }
        Err(e) => Err(mbx_err(format!(
            "device {who}: writing the mode of operation {index:#06x}:{sub:02x} = 8 (cyclic \
             synchronous position)"
        ))(e)),
    }
}

/// A mailbox failure of an acyclic access as a link error (aborts keep their CiA 301 code).
fn mailbox_error(device: usize, index: u16, sub: u8) -> impl Fn(MailboxError) -> LinkError {
    move |e| match e {
        MailboxError::Abort { code, .. } => LinkError::Abort {
            device: Peer::Device(device),
            index,
            sub,
            code,
        },
        other => LinkError::Other(format!("device {device}: {index:#06x}:{sub:02x}: {other}")),
    }
}

impl Link for EthercatLink {
    fn take_drive_emergencies(&mut self) -> Vec<super::DriveEmergency> {
        let mut out = Vec::new();
        for (device, ax) in self.axes.iter_mut().enumerate() {
            let list = match &mut ax.mailbox {
                Mailbox::Coe(c) => c.take_emergencies(),
                Mailbox::Soe(s) => s.take_emergencies(),
                Mailbox::None => Vec::new(),
            };
            out.extend(list.into_iter().map(|e| super::DriveEmergency {
                device,
                code: e.code,
                text: crate::bus::abort::emergency_text(e.code),
            }));
        }
        out
    }

    fn exchange(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Result<(), LinkError> {
        if images.len() != self.axes.len() {
            return Err(LinkError::Mismatch {
                devices: self.axes.len(),
                images: images.len(),
            });
        }
        #[cfg(feature = "sim")]
        self.arm_fault_knobs(self.exchanges);
        self.exchanges += 1;
        // The frames of one cycle, as on the bus: they carry this cycle's set-points and read
        // the inputs the devices latched at the previous SYNC0; the emulated segment's SYNC0
        // follows (a network interface's emulator steps by itself). The actual values thus
        // arrive one exchange after they were sampled (dead time: docs/ethercat.md).
        self.copy_outputs(images)?;
        self.sample_dc = None;
        if self.clock.is_some() {
            return self.paced_exchange(now, images);
        }
        #[cfg(feature = "sim")]
        self.wire.at_cycle(now);
        self.cycle_frame(now)?;
        // In-process the inputs were sampled at the segment's SYNC0 of the previous exchange,
        // at machine time now − cycle, on the DC time base the emulated EL1252 stamps with in
        // virtual time (`DcClock::default()`; the ESC registers follow the wall clock there).
        #[cfg(feature = "sim")]
        if self.wire.segment().is_some() && now.0 >= self.cycle.0 {
            self.sample_dc = Some(
                crate::core::measure::timestamp::DcClock::default()
                    .dc_time(Nanos(now.0 - self.cycle.0)),
            );
        }
        #[cfg(feature = "sim")]
        if let Some(seg) = self.wire.segment_mut() {
            seg.sync0(now);
        }
        self.copy_inputs(images)
    }

    fn read_object(&mut self, device: usize, index: u16, sub: u8) -> Result<i64, LinkError> {
        let md = self.md;
        let ax = self
            .axes
            .get_mut(device)
            .ok_or_else(|| LinkError::Other(format!("device {device}: not on the link")))?;
        let (_, signed) = object_type(&ax.def, index, sub);
        let abort = mailbox_error(device, index, sub);
        match &mut ax.mailbox {
            Mailbox::Coe(c) => {
                let bytes = drive(&mut self.wire, c.sdo_upload(md, index, sub)).map_err(abort)?;
                Ok(decode_le(&bytes, signed))
            }
            Mailbox::Soe(s) => drive(&mut self.wire, s.read_value(md, 0, index)).map_err(abort),
            Mailbox::None => Err(LinkError::Other(format!(
                "device {device}: the SubDevice has no mailbox"
            ))),
        }
    }

    fn write_object(
        &mut self,
        device: usize,
        index: u16,
        sub: u8,
        value: i64,
    ) -> Result<(), LinkError> {
        let md = self.md;
        let ax = self
            .axes
            .get_mut(device)
            .ok_or_else(|| LinkError::Other(format!("device {device}: not on the link")))?;
        let (size, _) = object_type(&ax.def, index, sub);
        let abort = mailbox_error(device, index, sub);
        match &mut ax.mailbox {
            Mailbox::Coe(c) => {
                let bytes = value.to_le_bytes();
                drive(
                    &mut self.wire,
                    c.sdo_download(md, index, sub, &bytes[..size.min(8)]),
                )
                .map_err(abort)
            }
            Mailbox::Soe(s) => {
                drive(&mut self.wire, s.write_value(md, 0, index, value)).map_err(abort)
            }
            Mailbox::None => Err(LinkError::Other(format!(
                "device {device}: the SubDevice has no mailbox"
            ))),
        }
    }

    #[cfg(feature = "sim")]
    fn plant(&self) -> Option<&crate::sim::plant::Plant> {
        self.wire
            .segment()?
            .world()
            .map(crate::sim::world::World::plant)
    }

    #[cfg(feature = "sim")]
    fn plant_mut(&mut self) -> Option<&mut crate::sim::plant::Plant> {
        self.wire
            .segment_mut()?
            .world_mut()
            .map(crate::sim::world::World::plant_mut)
    }

    #[cfg(feature = "sim")]
    fn model(&self, device: usize) -> Option<&dyn crate::drive::model::DriveModel> {
        self.wire.segment()?.model(device)
    }

    #[cfg(feature = "sim")]
    fn model_mut(&mut self, device: usize) -> Option<&mut dyn crate::drive::model::DriveModel> {
        self.wire.segment_mut()?.model_mut(device)
    }

    #[cfg(feature = "sim")]
    fn terminal_device(&self, index: usize) -> Option<usize> {
        let sub = self.terminals.get(index)?.sub;
        self.wire.segment()?.world_device_at(sub)
    }

    fn lose_exchange_at(&mut self, n: u64) {
        EthercatLink::lose_exchange_at(self, n);
    }

    fn exchanges(&self) -> u64 {
        self.exchanges
    }

    fn sample_dc_time(&self) -> Option<i64> {
        self.sample_dc
    }

    fn startup_report(&self) -> Vec<CncMessage> {
        self.startup_messages()
    }

    fn drive_definition(&self, device: usize) -> Option<Arc<DriveDefinition>> {
        self.axes.get(device).map(|a| a.def.clone())
    }

    fn terminal_inputs(&self, index: usize) -> Option<&[u8]> {
        EthercatLink::terminal_inputs(self, index)
    }

    fn terminal_outputs_mut(&mut self, index: usize) -> Option<&mut [u8]> {
        EthercatLink::terminal_outputs_mut(self, index)
    }

    fn cycle_summary(&self) -> Option<crate::rt::CycleSummary> {
        self.clock.as_ref().map(|c| c.stats().summary())
    }

    fn finish_capture(&mut self) -> Result<(), String> {
        self.wire.finish_capture()
    }

    fn finish_cycle_log(&mut self) -> Result<(), String> {
        match self.clock.as_mut() {
            Some(c) => c.stats_mut().finish_log(),
            None => Ok(()),
        }
    }

    fn set_cycle_log(
        &mut self,
        name: &str,
        out: Box<dyn std::io::Write + Send>,
    ) -> Result<(), LinkError> {
        match self.clock.as_mut() {
            Some(c) => {
                c.stats_mut().log_to(name, out);
                Ok(())
            }
            None => Err(LinkError::Other(
                "--cycle-log: ethercat-emu runs on virtual time; the cycle log is for links that leave the process (ethercat:IF, canopen-udp, socketcan:IF)".into(),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::sample_time;

    #[test]
    fn the_sample_is_the_sync0_before_the_frame() {
        // SYNC0 on the multiples of 1 ms; the frame half a period after it.
        assert_eq!(
            sample_time(40_796_201_500_000, 1_000_000),
            Some(40_796_201_000_000)
        );
        // A frame at a SYNC0 reads what that SYNC0 sampled.
        assert_eq!(
            sample_time(40_796_201_000_000, 1_000_000),
            Some(40_796_201_000_000)
        );
        assert_eq!(
            sample_time(40_796_201_999_999, 1_000_000),
            Some(40_796_201_000_000)
        );
        assert_eq!(sample_time(123, 0), None);
        assert_eq!(sample_time(u64::MAX, 1_000_000), None);
    }
}
