//! `sdos --node` and `pdos --node`: the CANopen side of [`super::sdos`] / [`super::pdos`].
//!
//! CiA 301 has no service that lists a node's dictionary, so `sdos --node` lists the objects
//! of the node's EDS (`--eds`), checks each by an SDO upload (the first readable sub-index the
//! EDS lists), and adds an SDO scan of the objects fieldprobe knows (the CiA 301
//! communication area objects of [`SCAN_COMMUNICATION`], the PDO parameters, and the CiA 402
//! objects of [`fieldprobe::drive::pdo::OBJECTS`]) that the EDS does not list. Lines:
//! ```text
//! SDO 0x6040, "Controlword" (EDS, on the node)
//!   0x6040:00, rw, uint16, 16 bit, "Controlword"
//! SDO 0x1001, "Error register" (EDS, on the node; upload refused: abort 0x060a0023 …)
//! SDO 0x6502, "Supported drive modes" (EDS, not on the node: abort 0x06020000 …)
//! SDO 0x60d5, "touch probe 1 positive edge counter" (scan, not in the EDS)
//! ```
//! Only abort 0x06020000 ("object does not exist", CiA 301 SDO abort codes) says an EDS object is
//! missing. Any other abort comes from an object that is there but did not give its value
//! (python-canopen's `LocalNode` answers 0x060A0023 for an entry without a value, other
//! devices 0x08000024 "no data available" or 0x08000022 "device state"); a write-only object
//! (0x06010001) is listed as on the node. The scan, which has no EDS to go by, lists only
//! objects whose upload succeeded or that are write-only.

use super::bus::{refused, Bus};
use super::EXIT_OK;
use fieldprobe::bus::canopen::eds::{self, AccessType, Eds};
use fieldprobe::bus::canopen::sdo::abort::NO_OBJECT;
use fieldprobe::bus::ethercat::sdo_info::data_type_name;
use fieldprobe::link::canopen::pdo_map::transmission_type_text;
use fieldprobe::link::LinkError;

/// CiA 301 communication objects the scan tries without an EDS (besides the PDO parameters).
pub const SCAN_COMMUNICATION: &[u16] = &[
    0x1000, 0x1001, 0x1002, 0x1003, 0x1005, 0x1006, 0x1007, 0x1008, 0x1009, 0x100A, 0x100C, 0x100D,
    0x1010, 0x1011, 0x1012, 0x1014, 0x1015, 0x1016, 0x1017, 0x1018, 0x1019, 0x1029, 0x1200, 0x1280,
];

fn access_text(a: AccessType) -> &'static str {
    match a {
        AccessType::ReadOnly => "ro",
        AccessType::WriteOnly => "wo",
        AccessType::ReadWrite => "rw",
        AccessType::ReadWriteInput => "rwr",
        AccessType::ReadWriteOutput => "rww",
        AccessType::Const => "const",
    }
}

/// CiA 301 names of the communication objects the scan tries.
fn communication_name(index: u16) -> String {
    match index {
        0x1000 => "Device type".into(),
        0x1001 => "Error register".into(),
        0x1002 => "Manufacturer status register".into(),
        0x1003 => "Pre-defined error field".into(),
        0x1005 => "COB-ID SYNC".into(),
        0x1006 => "Communication cycle period".into(),
        0x1007 => "Synchronous window length".into(),
        0x1008 => "Manufacturer device name".into(),
        0x1009 => "Manufacturer hardware version".into(),
        0x100A => "Manufacturer software version".into(),
        0x100C => "Guard time".into(),
        0x100D => "Life time factor".into(),
        0x1010 => "Store parameters".into(),
        0x1011 => "Restore default parameters".into(),
        0x1012 => "COB-ID time stamp".into(),
        0x1014 => "COB-ID EMCY".into(),
        0x1015 => "Inhibit time EMCY".into(),
        0x1016 => "Consumer heartbeat time".into(),
        0x1017 => "Producer heartbeat time".into(),
        0x1018 => "Identity object".into(),
        0x1019 => "Synchronous counter overflow value".into(),
        0x1029 => "Error behavior".into(),
        0x1200 => "SDO server parameter".into(),
        0x1280 => "SDO client parameter".into(),
        0x1400..=0x15FF => format!("RPDO {} communication parameter", index - 0x1400 + 1),
        0x1600..=0x17FF => format!("RPDO {} mapping parameter", index - 0x1600 + 1),
        0x1800..=0x19FF => format!("TPDO {} communication parameter", index - 0x1800 + 1),
        0x1A00..=0x1BFF => format!("TPDO {} mapping parameter", index - 0x1A00 + 1),
        _ => String::new(),
    }
}

/// What an upload of one object said.
enum Presence {
    /// The upload succeeded, or the object is write-only (abort 0x06010001).
    Present,
    /// The object exists but refused the upload with this abort code.
    Refused(u32),
    /// Abort 0x06020000: no such object.
    Absent(u32),
}

fn probe(
    s: &mut fieldprobe::link::canopen::CanSession,
    node: u8,
    index: u16,
    sub: u8,
) -> Result<Presence, LinkError> {
    match s.sdo_upload(node, index, sub) {
        Ok(_) => Ok(Presence::Present),
        // Write-only objects exist even though they cannot be read.
        Err(LinkError::Abort {
            code: 0x0601_0001, ..
        }) => Ok(Presence::Present),
        Err(LinkError::Abort {
            code: code @ NO_OBJECT,
            ..
        }) => Ok(Presence::Absent(code)),
        Err(LinkError::Abort { code, .. }) => Ok(Presence::Refused(code)),
        Err(e) => Err(e),
    }
}

fn presence_text(p: &Presence) -> String {
    match p {
        Presence::Present => "EDS, on the node".into(),
        Presence::Refused(c) => format!(
            "EDS, on the node; upload refused: abort {c:#010x} {}",
            fieldprobe::bus::abort::abort_text(*c)
        ),
        Presence::Absent(c) => format!(
            "EDS, not on the node: abort {c:#010x} {}",
            fieldprobe::bus::abort::abort_text(*c)
        ),
    }
}

/// Load the EDS / DCF of option `option` (`--eds`; `None` for an argument) leniently and print
/// what the reader read in its own way on stderr, once each, as `warning: FILE:LINE: [SECTION]
/// KEY: problem; what is read instead` ([`eds::EdsWarning`]; identical problems folded with a
/// count).
pub fn load_eds(option: Option<&str>, path: &std::path::Path) -> anyhow::Result<Eds> {
    let eds = eds::load(path).map_err(|e| match option {
        Some(o) => anyhow::anyhow!("{o} {}: {e}", path.display()),
        None => anyhow::anyhow!("{e}"),
    })?;
    for w in &eds.warnings {
        eprintln!("warning: {w}");
    }
    Ok(eds)
}

/// `fieldprobe sdos --node N`.
pub fn sdos(bus: &Bus, node: u8, eds_path: Option<&std::path::Path>) -> anyhow::Result<i32> {
    let eds: Option<Eds> = match eds_path {
        Some(p) => Some(load_eds(Some("--eds"), p)?),
        None => None,
    };
    let mut s = bus.open_can()?;
    let res = list(&mut s, node, eds.as_ref());
    super::finish_capture(s.finish_capture());
    match res {
        Ok(()) => Ok(EXIT_OK),
        Err(e) => refused(e),
    }
}

fn list(
    s: &mut fieldprobe::link::canopen::CanSession,
    node: u8,
    eds: Option<&Eds>,
) -> Result<(), LinkError> {
    let mut listed = std::collections::BTreeSet::new();
    if let Some(eds) = eds {
        for (&index, h) in &eds.object_headers {
            listed.insert(index);
            let first = eds.subs(index).map(|e| e.sub).next().unwrap_or(0);
            // A record's sub 0 may be absent; probe the first listed readable sub.
            let sub = eds
                .subs(index)
                .find(|e| e.access.readable())
                .map_or(first, |e| e.sub);
            let p = probe(s, node, index, sub)?;
            outln!(
                "SDO {index:#06x}, \"{}\" ({})",
                h.parameter_name,
                presence_text(&p)
            );
            for e in eds.subs(index) {
                let bits = e
                    .data_type
                    .bit_len()
                    .map_or_else(|| "?".to_string(), |b| b.to_string());
                outln!(
                    "  {:#06x}:{:02x}, {}, {}, {} bit, \"{}\"",
                    e.index,
                    e.sub,
                    access_text(e.access),
                    data_type_name(e.data_type.code()),
                    bits,
                    e.parameter_name
                );
            }
        }
    }
    let mut scan: Vec<u16> = SCAN_COMMUNICATION.to_vec();
    for base in [0x1400u16, 0x1600, 0x1800, 0x1A00] {
        scan.extend(base..base + 4);
    }
    scan.extend(fieldprobe::drive::pdo::OBJECTS.iter().map(|o| o.index));
    scan.sort_unstable();
    scan.dedup();
    for index in scan.into_iter().filter(|i| !listed.contains(i)) {
        let first = fieldprobe::drive::pdo::OBJECTS
            .iter()
            .find(|o| o.index == index)
            .copied();
        let sub = first.map_or(0, |o| o.sub);
        let p = probe(s, node, index, sub)?;
        if !matches!(p, Presence::Present) {
            continue;
        }
        let name = first.map_or_else(|| communication_name(index), |o| o.name.to_string());
        let origin = if eds.is_some() {
            "scan, not in the EDS"
        } else {
            "scan"
        };
        outln!("SDO {index:#06x}, \"{name}\" ({origin})");
    }
    Ok(())
}

/// `fieldprobe pdos --node N`.
pub fn pdos(bus: &Bus, node: u8) -> anyhow::Result<i32> {
    let mut s = bus.open_can()?;
    let res = s.pdo_map(node);
    super::finish_capture(s.finish_capture());
    let pdos = match res {
        Ok(p) => p,
        Err(e) => return refused(e),
    };
    for p in pdos {
        let mut line = format!(
            "{}PDO{} (0x{:04x} / 0x{:04x}): COB-ID {:#x} ({}), transmission type {} ({})",
            if p.rpdo { "R" } else { "T" },
            p.number,
            p.comm_index(),
            p.mapping_index(),
            p.cob_id & 0x1FFF_FFFF,
            if p.valid() { "valid" } else { "not valid" },
            p.transmission_type,
            transmission_type_text(p.transmission_type)
        );
        if let Some(t) = p.inhibit_time {
            line.push_str(&format!(", inhibit {t} x 100 us"));
        }
        if let Some(t) = p.event_timer {
            line.push_str(&format!(", event timer {t} ms"));
        }
        outln!("{line}");
        for (index, sub, bits) in &p.entries {
            let name = fieldprobe::drive::pdo::lookup(*index, *sub).map_or("", |o| o.name);
            outln!("    PDO entry {index:#06x}:{sub:02x}, {bits} bit, \"{name}\"");
        }
    }
    Ok(EXIT_OK)
}
