//! Links bind axes to a bus: each cycle they move every axis's output image to its drive and bring
//! back the input image. [`Link`] is the seam; [`open`] builds the link a `--link` value names.
//!
//! | link | type | feature |
//! |---|---|---|
//! | `sim` | [`sim::SimLink`]: drive models in memory, images laid out as the PDO mapping | — |
//! | `ethercat:IFACE` | `ethercat::EthercatLink`: ethercrab MainDevice on a raw packet socket | `ethercat` |
//! | `ethercat-emu` | `ethercat::EthercatLink` on the emulated segment, in-process | `sim` |
//! | `canopen-udp[:GROUP:PORT]` | `canopen::CanopenLink`: fieldprobe's CiA 301 master on a CAN bus | `canopen` |
//! | `socketcan:IF` | `canopen::CanopenLink` on a Linux SocketCAN interface | `socketcan` |
//! | `canopen-emu` | `canopen::CanopenLink` with emulated nodes on an in-process virtual bus | `sim` |
//!
//! The links that leave the process need only their bus's feature, not the emulators: a drive
//! layer built with `default-features = false, features = ["ethercat"]` opens `ethercat:IFACE`
//! through [`open`], one with `features = ["socketcan"]` opens `socketcan:IF`.

#[cfg(feature = "canopen")]
pub mod canopen;
#[cfg(feature = "ethercat")]
pub mod ethercat;
pub mod sim;

use crate::drive::model::DriveModel;
use crate::sim::plant::Plant;
use crate::units::Nanos;

/// One axis's process image, as the bus carries it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ProcessImage {
    /// Master → drive (RxPDO).
    pub outputs: Vec<u8>,
    /// Drive → master (TxPDO).
    pub inputs: Vec<u8>,
}

impl ProcessImage {
    /// Zeroed image of the given sizes.
    pub fn new(output_len: usize, input_len: usize) -> Self {
        ProcessImage {
            outputs: vec![0; output_len],
            inputs: vec![0; input_len],
        }
    }
}

/// Errors of a link.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinkError {
    /// The cyclic exchange did not come back (lost frame, wrong working counter); the input images
    /// are stale and must not be used.
    #[error("process data exchange lost in cycle at {at}: {reason}")]
    Lost {
        /// When.
        at: Nanos,
        /// Why (e.g. "frame lost", "working counter 2, expected 3").
        reason: String,
    },
    /// The master did not run for `missed` cycles (stopped, overloaded): the devices went
    /// without set-points for that long and their watchdogs may have stopped them. Counts as
    /// `missed` lost exchanges (see [`crate::channel::Channel::link_lost`]).
    #[error("the master missed {missed} cycles ({ms:.1} ms without a frame)")]
    Stalled {
        /// Cycles without a frame.
        missed: u64,
        /// How long, ms.
        ms: f64,
    },
    /// The images do not match the link's devices.
    #[error("link has {devices} devices but {images} process images were given")]
    Mismatch {
        /// Devices on the link.
        devices: usize,
        /// Images given.
        images: usize,
    },
    /// An acyclic access was refused by the device (CiA 301 SDO abort code).
    #[error("{device}: access to {index:#06x}:{sub:02x} refused, abort code {code:#010x} ({})", crate::bus::abort::abort_text(*code))]
    Abort {
        /// Who refused: a device position on the link, or a CANopen node id.
        device: Peer,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// CiA 301 abort code.
        code: u32,
    },
    /// A SERCOS parameter access was refused by the drive (SoE error reply, IEC 61800-7-204
    /// error code).
    #[error("device {device} ({name}): SoE {idn_name} (drive 0): error {code:#06x} ({text})", idn_name = crate::drive::sercos::idn_name(*.idn))]
    Soe {
        /// Device position on the link.
        device: usize,
        /// Device name (ESI).
        name: String,
        /// The IDN.
        idn: u16,
        /// SERCOS error code.
        code: u16,
        /// The code in words.
        text: &'static str,
    },
    /// The device answered a mailbox request with the mailbox error reply "unsupported
    /// protocol" (ETG.1000.4 detail 0x0002): it does not speak `protocol` (an SoE access to a
    /// CoE-only device).
    #[error("device {device} ({name}): the device does not support {protocol} (it answered with the mailbox error reply {code:#06x}, unsupported protocol)")]
    Unsupported {
        /// Device position on the link.
        device: usize,
        /// Device name (ESI).
        name: String,
        /// The mailbox protocol asked for (`SoE`, `CoE`).
        protocol: &'static str,
        /// The mailbox error detail code.
        code: u16,
    },
    /// The configuration is refused with a CNC message (its ID and text, e.g. error 900403: a
    /// cycle time the EtherCAT wire cannot carry).
    #[error("{0}")]
    Refused(crate::messages::CncMessage),
    /// A frame on a network interface was not answered after every try (the wire end repeats
    /// frames, `link::ethercat::retry`): nothing on the wire answered at all
    /// (`answered_before` false: no device connected or powered), or devices that had answered
    /// stopped.
    #[error("{text}")]
    NoAnswer {
        /// What was sent, how often, for how long, and who had answered before.
        text: String,
        /// Something on the wire had answered before.
        answered_before: bool,
    },
    /// Anything else (setup, configuration).
    #[error("{0}")]
    Other(String),
}

impl LinkError {
    /// The device itself refused the access (SDO abort, SoE error, a mailbox protocol it does
    /// not support): the request reached it and
    /// was answered, as opposed to a transport, setup or input problem.
    pub fn is_refusal(&self) -> bool {
        matches!(
            self,
            LinkError::Abort { .. } | LinkError::Soe { .. } | LinkError::Unsupported { .. }
        )
    }
}

/// An emergency message of a drive (CiA 301 EMCY / CoE emergency).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriveEmergency {
    /// Device (axis) index on the link.
    pub device: usize,
    /// Error code (CiA 301 / CiA 402).
    pub code: u16,
    /// The code in words.
    pub text: &'static str,
}

/// The peer of an acyclic access, as error messages name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Peer {
    /// Device (axis) position on the link (EtherCAT, sim).
    Device(usize),
    /// CANopen node id.
    Node(u8),
}

impl std::fmt::Display for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Peer::Device(d) => write!(f, "device {d}"),
            Peer::Node(n) => write!(f, "node {n}"),
        }
    }
}

/// The transport seam: one cyclic exchange.
pub trait Link: Send {
    /// Exchange all process images once: outputs go to the drives, inputs come back.
    fn exchange(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Result<(), LinkError>;

    /// Acyclic read of object `index:sub` of device `device` (SDO upload / CoE). Links without
    /// a mailbox refuse.
    fn read_object(&mut self, device: usize, index: u16, sub: u8) -> Result<i64, LinkError> {
        let _ = (device, index, sub);
        Err(LinkError::Other(
            "this link has no acyclic (mailbox) access".into(),
        ))
    }

    /// Acyclic write of object `index:sub` of device `device` (SDO download / CoE).
    fn write_object(
        &mut self,
        device: usize,
        index: u16,
        sub: u8,
        value: i64,
    ) -> Result<(), LinkError> {
        let _ = (device, index, sub, value);
        Err(LinkError::Other(
            "this link has no acyclic (mailbox) access".into(),
        ))
    }

    /// Emergency messages the drives sent since the last call (CANopen EMCY, CoE emergency
    /// received with a mailbox answer), oldest first. Links without them return none.
    fn take_drive_emergencies(&mut self) -> Vec<DriveEmergency> {
        Vec::new()
    }

    /// The simulated plant (probe surfaces, fixed stops) behind the link, if it has one
    /// (`sim`, `ethercat-emu`; not a real bus).
    fn plant(&self) -> Option<&Plant> {
        None
    }

    /// The simulated plant, mutable.
    fn plant_mut(&mut self) -> Option<&mut Plant> {
        None
    }

    /// The drive model of device `device`, if the link hosts models.
    fn model(&self, device: usize) -> Option<&dyn DriveModel> {
        let _ = device;
        None
    }

    /// The drive model of device `device`, mutable (fault and plant knobs).
    fn model_mut(&mut self, device: usize) -> Option<&mut dyn DriveModel> {
        let _ = device;
        None
    }

    /// The world device number ([`crate::sim::world`]) of the machine's terminal `index` when
    /// the link hosts its model (`ethercat-emu`: an EL1252-kind timestamp input), so that a
    /// probe surface can be wired to its inputs; `None` otherwise.
    fn terminal_device(&self, index: usize) -> Option<usize> {
        let _ = index;
        None
    }

    /// Fault knob (issue 28 item 8): device `device` sends emergency `code` every `every` of
    /// its own time from now on, as a drive flooding EMCYs would (`None`: stop). Returns
    /// whether the link could arrange it (only links with emulated devices can).
    fn flood_emergencies(&mut self, device: usize, code: u16, every: Option<Nanos>) -> bool {
        let _ = (device, code, every);
        false
    }

    /// Fault knob: lose the `n`-th exchange (0-based). Links that cannot inject ignore it.
    fn lose_exchange_at(&mut self, n: u64) {
        let _ = n;
    }

    /// Exchanges attempted so far.
    fn exchanges(&self) -> u64 {
        0
    }

    /// The distributed-clock system time (ns since 2000-01-01) at which the devices sampled
    /// the inputs the last exchange read — their SYNC0 — on the time base an EL1252-kind
    /// timestamp input on the same segment stamps its edges with. An EtherCAT link with DC
    /// gives it each cycle (on an interface: from the reference clock's system time that
    /// cycle's frame read); `None` (default): the link has no DC time, the CNC stamps its
    /// actual values with its own cycle times.
    fn sample_dc_time(&self) -> Option<i64> {
        None
    }

    /// The drive definition device `device` runs with, when the link changed it at start-up
    /// (EtherCAT: the PDO mapping fitted to what the device offers, e.g. without the touch
    /// probe objects a device lacks); `None`: the one the link was opened with.
    fn drive_definition(
        &self,
        device: usize,
    ) -> Option<std::sync::Arc<crate::drive::catalogue::DriveDefinition>> {
        let _ = device;
        None
    }

    /// What the link reports once it is up (EtherCAT: the segment, the SubDevices the machine
    /// does not name, the wire time of a cycle; info messages). None by default.
    fn startup_report(&self) -> Vec<crate::messages::CncMessage> {
        Vec::new()
    }

    /// Inputs of the machine's terminal `index` (`[[terminal]]` order) after the last exchange;
    /// `None` on links without terminals.
    fn terminal_inputs(&self, index: usize) -> Option<&[u8]> {
        let _ = index;
        None
    }

    /// Outputs of the machine's terminal `index`, sent with the next exchange.
    fn terminal_outputs_mut(&mut self, index: usize) -> Option<&mut [u8]> {
        let _ = index;
        None
    }

    /// The link's dead time in cycles: from the exchange after which a set-point is written to
    /// the one whose input images carry the position it produced. A set-point goes out with
    /// the next exchange and is reached by the drive at the SYNC0 / SYNC that follows (one
    /// cycle); the drive samples its actual value there and sends it with the next frame (one
    /// more): 2 on every link fieldprobe has (EtherCAT with DC, CANopen synchronous PDOs, and
    /// the in-memory link, which plays the same timing). A machine file may set another value
    /// per axis for a drive with its own extra delay (`dead_time_cycles`).
    fn dead_time_cycles(&self) -> u32 {
        DEFAULT_DEAD_TIME_CYCLES
    }

    /// The statistics of the paced cycle of a link that leaves the process (`ethercat:IF`,
    /// `canopen-udp`, `socketcan:IF`); `None` on the in-process links, which run on virtual time.
    fn cycle_summary(&self) -> Option<crate::rt::CycleSummary> {
        None
    }

    /// Write one CSV row per cycle of the paced cycle to `out` (`--cycle-log FILE.csv`; `name`
    /// names it in errors).
    ///
    /// # Errors
    /// The in-process links run on virtual time and have no cycle log.
    fn set_cycle_log(
        &mut self,
        name: &str,
        out: Box<dyn std::io::Write + Send>,
    ) -> Result<(), LinkError> {
        let _ = (name, out);
        Err(LinkError::Other(
            "--cycle-log: this link runs on virtual time; the cycle log is for links that leave the process (ethercat:IF, canopen-udp, socketcan:IF)".into(),
        ))
    }

    /// Flush the per-cycle log (`--cycle-log`), if one is written.
    ///
    /// # Errors
    /// A write to the log failed, naming the file.
    fn finish_cycle_log(&mut self) -> Result<(), String> {
        Ok(())
    }

    /// Flush the frame capture (`--pcap`, `--candump`) at the end of a run; links without one:
    /// `Ok`. A capture write that failed during the run (a full disk) was not fatal to the run
    /// (the axes still stop as usual), but it is an error of the command.
    ///
    /// # Errors
    /// The first write to the capture that failed, naming the option and the file.
    fn finish_capture(&mut self) -> Result<(), String> {
        Ok(())
    }

    /// The end of a run, after the drives were disabled: bring the bus to its documented end
    /// state at `now` (CANopen: NMT enter pre-operational to every axis's node, confirmed by
    /// their heartbeats; no process data any more). The other links have no such state: `Ok`.
    /// The next [`exchange`](Link::exchange) starts the bus again (CANopen: NMT start).
    ///
    /// # Errors
    /// The end state could not be sent or was not confirmed (naming the nodes).
    fn release(&mut self, now: Nanos) -> Result<(), LinkError> {
        let _ = now;
        Ok(())
    }
}

/// `--link` values fieldprobe knows, for messages (whether this build has them: [`open`]).
pub const LINKS: &str = "sim (drive models in memory), canopen-emu (our CiA 301 master against emulated CiA 402 nodes on an in-process virtual CAN bus), canopen-udp[:GROUP:PORT] (python-can udp_multicast bus), socketcan:IF, ethercat-emu (ethercrab against emulated EtherCAT drives in-process), ethercat:IFACE (ethercrab on a network interface)";

/// What [`open`] builds a link for: one entry per axis, in axis order.
pub struct LinkRequest<'a> {
    /// The `--link` value (see [`LINKS`]).
    pub link: &'a str,
    /// Drive definition per axis.
    pub drives: &'a [std::sync::Arc<crate::drive::catalogue::DriveDefinition>],
    /// Drive model per axis (used by `sim`, which hosts them in memory).
    pub models: Vec<Box<dyn DriveModel>>,
    /// CANopen node id per axis (CAN links).
    pub node_ids: &'a [u8],
    /// Interpolation cycle.
    pub cycle: Nanos,
    /// CAN bit rate (bit/s; machine file `[can] bitrate`, CAN links).
    pub can_bitrate: u32,
    /// Capture every EtherCAT frame into this pcap file (EtherCAT links).
    pub pcap: Option<&'a std::path::Path>,
    /// Log every CAN frame into this file, candump -L format (CAN links).
    pub candump: Option<&'a std::path::Path>,
    /// EtherCAT SubDevices that are not axes (I/O terminals), in ring order after the drives.
    #[cfg(feature = "ethercat")]
    pub terminals: Vec<ethercat::terminals::TerminalSpec>,
}

/// Open the link `req.link` names, brought up to cyclic operation.
///
/// # Errors
/// An unknown link, a link this build has no feature for (naming the feature), or the link's
/// own start-up error.
pub fn open(req: LinkRequest<'_>) -> Result<Box<dyn Link>, LinkError> {
    let link = req.link;
    if link == "sim" {
        return Ok(Box::new(sim::SimLink::from_models(req.models, req.cycle)));
    }
    let can =
        link == "canopen-emu" || link.starts_with("canopen-udp") || link.starts_with("socketcan:");
    if can {
        #[cfg(feature = "canopen")]
        {
            let bitrate = crate::bus::can::Bitrate::new(req.can_bitrate).ok_or_else(|| {
                LinkError::Other(format!("CAN bit rate {} bit/s", req.can_bitrate))
            })?;
            return Ok(Box::new(canopen::CanopenLink::on_link(
                link,
                req.drives,
                req.node_ids,
                req.cycle,
                bitrate,
                req.candump,
            )?));
        }
        #[cfg(not(feature = "canopen"))]
        return Err(LinkError::Other(format!(
            "{link}: this build of fieldprobe has no CANopen link (Cargo feature `canopen`{})",
            if link.starts_with("socketcan:") {
                ", with `socketcan` for SocketCAN"
            } else if link == "canopen-emu" {
                ", with `sim` for the emulated nodes"
            } else {
                ""
            }
        )));
    }
    if link == "ethercat-emu" || link.starts_with("ethercat:") {
        #[cfg(feature = "ethercat")]
        if let Some(wire) = ethercat::Wire::from_link(link) {
            let spec = ethercat::EthercatSpec {
                drives: req.drives.to_vec(),
                cycle: req.cycle,
                pcap: req.pcap.map(std::path::Path::to_path_buf),
                terminals: req.terminals,
                emulated_extra: Vec::new(),
            };
            return Ok(Box::new(ethercat::EthercatLink::open(&wire, &spec)?));
        }
        #[cfg(not(feature = "ethercat"))]
        return Err(LinkError::Other(format!(
            "{link}: this build of fieldprobe has no EtherCAT link (Cargo feature `ethercat`{})",
            if link == "ethercat-emu" {
                ", with `sim` for the emulated segment"
            } else {
                ""
            }
        )));
    }
    Err(LinkError::Other(format!(
        "unknown link; available: {LINKS}"
    )))
}

/// Dead time of every link fieldprobe has, in cycles ([`Link::dead_time_cycles`]).
pub const DEFAULT_DEAD_TIME_CYCLES: u32 = 2;

impl<'a> dyn Link + 'a {
    /// The model of device `device` as its concrete type `T`, if it is one.
    pub fn model_as<T: 'static>(&mut self, device: usize) -> Option<&mut T> {
        self.model_mut(device)?.as_any_mut().downcast_mut::<T>()
    }
}

/// (size in bytes, signed) of object `index:sub` for drive `def`: its function / IDN tables,
/// then the CiA 402 object table, then the CiA 301 communication objects (0x1001, 0x100C,
/// 0x1017, PDO parameters); 4 bytes unsigned otherwise.
#[cfg_attr(not(any(feature = "ethercat", feature = "canopen")), allow(dead_code))] // used by the bus links
pub(crate) fn object_type(
    def: &crate::drive::catalogue::DriveDefinition,
    index: u16,
    sub: u8,
) -> (usize, bool) {
    if let Some(ty) = def.object_type(index, sub) {
        return (ty.size(), ty.is_signed());
    }
    if let Some(o) = crate::drive::pdo::lookup(index, sub) {
        return (o.ty.size(), o.ty.is_signed());
    }
    // CiA 301 communication objects.
    let size = match (index, sub) {
        (0x1001, 0) => 1,
        (0x100C, 0) | (0x1017, 0) => 2,
        (0x1400..=0x1BFF, 0) => 1,
        (0x1400..=0x15FF | 0x1800..=0x19FF, 2) => 1,
        (0x1400..=0x15FF | 0x1800..=0x19FF, 3 | 5) => 2,
        _ => 4,
    };
    (size, false)
}

/// Little-endian bytes as a number (sign-extended when `signed`).
#[cfg_attr(not(any(feature = "ethercat", feature = "canopen")), allow(dead_code))] // used by the bus links
pub(crate) fn decode_le(bytes: &[u8], signed: bool) -> i64 {
    let n = bytes.len().min(8);
    let mut b = [0u8; 8];
    b[..n].copy_from_slice(&bytes[..n]);
    let v = u64::from_le_bytes(b);
    if signed && n > 0 && n < 8 && bytes[n - 1] & 0x80 != 0 {
        (v | (!0u64 << (8 * n))) as i64
    } else {
        v as i64
    }
}
