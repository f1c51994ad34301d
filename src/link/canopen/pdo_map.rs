//! The PDO configuration of a CANopen node read back by SDO (`fieldprobe pdos --node`): the
//! communication parameters (CiA 301 §7.5.2.35 / .37: RPDO 0x1400–0x15FF, TPDO 0x1800–0x19FF;
//! sub 1 COB-ID with bit 31 "not valid", sub 2 transmission type, sub 3 inhibit time ×100 µs,
//! sub 5 event timer ms) and the mapping parameters (0x1600–0x17FF / 0x1A00–0x1BFF; sub 0 the
//! number of entries, subs 1.. `index << 16 | sub << 8 | bits`).

use super::session::CanSession;
use crate::link::LinkError;

/// Abort code "object does not exist" (CiA 301): the end of the PDO numbers.
const NO_OBJECT: u32 = 0x0602_0000;
/// Most PDOs per direction (CiA 301: 512).
pub const MAX_PDOS: u16 = 512;

/// One PDO of a node.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanPdoInfo {
    /// RPDO (received by the node) or TPDO.
    pub rpdo: bool,
    /// PDO number, 1-based (RPDO1 = 0x1400 / 0x1600).
    pub number: u16,
    /// COB-ID (sub 1) as read, bit 31 included.
    pub cob_id: u32,
    /// Transmission type (sub 2).
    pub transmission_type: u8,
    /// Inhibit time (sub 3, ×100 µs), if the node has it.
    pub inhibit_time: Option<u16>,
    /// Event timer (sub 5, ms), if the node has it.
    pub event_timer: Option<u16>,
    /// Mapped entries (index, sub-index, bits).
    pub entries: Vec<(u16, u8, u8)>,
}

impl CanPdoInfo {
    /// COB-ID bit 31 clear: the PDO exists (is used).
    pub fn valid(&self) -> bool {
        self.cob_id & 0x8000_0000 == 0
    }

    /// The communication parameter index.
    pub fn comm_index(&self) -> u16 {
        (if self.rpdo { 0x1400 } else { 0x1800 }) + self.number - 1
    }

    /// The mapping parameter index.
    pub fn mapping_index(&self) -> u16 {
        self.comm_index() + 0x0200
    }
}

/// CiA 301 transmission type in words.
pub fn transmission_type_text(t: u8) -> String {
    match t {
        0 => "synchronous, acyclic".into(),
        1 => "synchronous, every SYNC".into(),
        2..=240 => format!("synchronous, every {t}th SYNC"),
        241..=251 => "reserved".into(),
        252 => "RTR only, synchronous".into(),
        253 => "RTR only, event-driven".into(),
        254 => "event-driven (manufacturer-specific)".into(),
        255 => "event-driven (device profile)".into(),
    }
}

fn le(v: &[u8]) -> u32 {
    v.iter()
        .take(4)
        .rev()
        .fold(0u32, |acc, &b| acc << 8 | u32::from(b))
}

impl CanSession {
    /// Optional sub-index: `None` when the node aborts the upload.
    fn optional(&mut self, node: u8, index: u16, sub: u8) -> Result<Option<u32>, LinkError> {
        match self.sdo_upload(node, index, sub) {
            Ok(v) => Ok(Some(le(&v))),
            Err(LinkError::Abort { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// The RPDOs then the TPDOs of `node`. Each direction is read from PDO 1 up to the first
    /// communication parameter the node does not have (abort 0x06020000; at most [`MAX_PDOS`]);
    /// a mapping parameter the node lacks gives an empty mapping.
    pub fn pdo_map(&mut self, node: u8) -> Result<Vec<CanPdoInfo>, LinkError> {
        let mut out = Vec::new();
        for rpdo in [true, false] {
            let base = if rpdo { 0x1400u16 } else { 0x1800 };
            for k in 0..MAX_PDOS {
                let comm = base + k;
                let cob_id = match self.sdo_upload(node, comm, 1) {
                    Ok(v) => le(&v),
                    Err(LinkError::Abort {
                        code: NO_OBJECT, ..
                    }) => break,
                    Err(LinkError::Abort { .. }) => continue,
                    Err(e) => return Err(e),
                };
                let tt = self.optional(node, comm, 2)?.unwrap_or(0) as u8;
                let (inhibit_time, event_timer) = if rpdo {
                    (None, self.optional(node, comm, 5)?.map(|v| v as u16))
                } else {
                    (
                        self.optional(node, comm, 3)?.map(|v| v as u16),
                        self.optional(node, comm, 5)?.map(|v| v as u16),
                    )
                };
                let map = comm + 0x0200;
                let mut entries = Vec::new();
                let n = self.optional(node, map, 0)?.unwrap_or(0).min(64) as u8;
                for j in 1..=n {
                    let m = le(&self.sdo_upload(node, map, j)?);
                    entries.push(((m >> 16) as u16, (m >> 8) as u8, m as u8));
                }
                out.push(CanPdoInfo {
                    rpdo,
                    number: k + 1,
                    cob_id,
                    transmission_type: tt,
                    inhibit_time,
                    event_timer,
                    entries,
                });
            }
        }
        Ok(out)
    }
}
