//! PDOs (CiA 301 §7.2.2): packing a drive's process image into PDOs of at most 8 bytes, the
//! communication and mapping parameters, the remap procedure, and the copy between PDO data and
//! the drive's image.
//!
//! # The master's layout ([`plan_layout`])
//!
//! A classic CAN frame costs 47 bit times plus 8 per data byte and its stuff bits
//! ([`crate::bus::can::timing`]), so the layout sends as few frames per cycle as the axis
//! needs:
//!
//! * **Cyclic** ([`Trigger::Cyclic`]): everything that changes while the axis moves or that the
//!   adapter reads every cycle (controlword, target position, touch probe function, statusword,
//!   actual position, following error, torque, modes display, touch probe status) — RPDOs sent
//!   in every exchange, TPDOs with transmission type 1 (every SYNC).
//! * **On change** ([`Trigger::OnChange`]): the objects whose value changes only on an event —
//!   the touch probe positions 0x60BA–0x60BD and edge counters 0x60D5–0x60D8 (a latch), the
//!   modes of operation 0x6060 and the touch probe source 0x60D0 (a setting). TPDOs with
//!   transmission type 0 (synchronous, acyclic: sent at a SYNC when their data changed since
//!   they were last sent, CiA 301 §7.5.2.37), grouped by touch probe so that one latch sends
//!   one frame; RPDOs the master sends only when their data changed (and after each NMT start),
//!   without deadline monitoring.
//!
//! Each class is packed first fit, largest entries first, into frames of ≤ 8 bytes. The
//! on-change TPDOs take the lowest numbers, hence the lowest COB-IDs (0x180 + 0x100 k + node):
//! a node queues every TPDO of a SYNC at once and the lower identifier wins arbitration, so by
//! the time the master has a node's cyclic TPDOs (the touch probe status 0x60B9 among them) it
//! has that SYNC's on-change TPDOs of the node too — a latch's position never arrives after the
//! status bit that announces it. Layouts that do not fit [`MAX_PDOS`] PDOs this way fall back
//! to [`pack_layout`] (everything cyclic).

use crate::bus::can::{CanFrame, FrameError};
use crate::drive::pdo::PdoLayout;

mod fit;
pub use fit::{plan_layout_in, PdoSlots, Unfit, MAX_ENTRIES};

/// Receive (master → node) or transmit (node → master) PDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// RPDO: communication 0x1400 + k, mapping 0x1600 + k, COB-ID 0x200 + 0x100 k + node.
    Rx,
    /// TPDO: communication 0x1800 + k, mapping 0x1A00 + k, COB-ID 0x180 + 0x100 k + node.
    Tx,
}

impl Direction {
    /// Communication parameter index of PDO `k` (0-based).
    pub const fn comm_index(self, k: u8) -> u16 {
        match self {
            Direction::Rx => 0x1400 + k as u16,
            Direction::Tx => 0x1800 + k as u16,
        }
    }

    /// Mapping parameter index of PDO `k`.
    pub const fn mapping_index(self, k: u8) -> u16 {
        match self {
            Direction::Rx => 0x1600 + k as u16,
            Direction::Tx => 0x1A00 + k as u16,
        }
    }

    /// Default COB-ID of PDO `k` (0 … 3) of `node` (predefined connection set).
    pub const fn default_cob(self, k: u8, node: u8) -> u16 {
        let base = match self {
            Direction::Rx => 0x200,
            Direction::Tx => 0x180,
        };
        base + 0x100 * k as u16 + node as u16
    }
}

/// PDOs per direction of the predefined connection set.
pub const MAX_PDOS: usize = 4;

/// The 11-bit CAN-IDs CiA 301 §7.3.5 restricts: no PDO (nor SDO, EMCY …) may use them,
/// because NMT, the default SDO channels, LSS, NMT error control and the reserved ranges do
/// (the same list as CANopenNode's `CO_IS_RESTRICTED_CAN_ID`). Inclusive ranges.
pub const RESTRICTED_CAN_IDS: [(u16, u16); 6] = [
    (0x000, 0x07F),
    (0x101, 0x180),
    (0x581, 0x5FF),
    (0x601, 0x67F),
    (0x6E0, 0x6FF),
    (0x701, 0x7FF),
];

/// The 11-bit CAN-IDs a PDO may use: the complement of [`RESTRICTED_CAN_IDS`], as error
/// messages name it.
pub const ALLOWED_PDO_CAN_IDS: &str = "0x080-0x100, 0x181-0x580, 0x600, 0x680-0x6DF or 0x700";

/// Is `id` (11 bit) one of the [`RESTRICTED_CAN_IDS`]?
pub fn is_restricted_can_id(id: u16) -> bool {
    RESTRICTED_CAN_IDS
        .iter()
        .any(|&(low, high)| (low..=high).contains(&id))
}

/// Check the value of a PDO COB-ID (sub-index 1 of 0x1400 … 0x15FF / 0x1800 … 0x19FF,
/// CiA 301 §7.5.2.35 / §7.5.2.37): a PDO that is not valid (bit 31 set) may hold any
/// identifier; a valid one needs an 11-bit CAN-ID (bit 29 and bits 11 … 28 clear) outside
/// [`RESTRICTED_CAN_IDS`]. `Err` says why, for a message that adds the allowed range.
pub fn check_pdo_cob_id(value: u32) -> Result<(), String> {
    if value & 0x8000_0000 != 0 {
        return Ok(());
    }
    if value & 0x3FFF_F800 != 0 {
        return Err(format!(
            "COB-ID {value:#010x} is not an 11-bit CAN-ID (bits 11 ... 29 must be 0)"
        ));
    }
    let id = (value & 0x7FF) as u16;
    if is_restricted_can_id(id) {
        return Err(format!(
            "COB-ID {value:#x}: CAN-ID {id:#05x} is restricted (CiA 301 §7.3.5)"
        ));
    }
    Ok(())
}

/// One mapped object: `len` bytes at `pdo_offset` in the PDO's data are bytes at
/// `image_offset` of the drive's image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mapped {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Bytes.
    pub len: usize,
    /// Offset in the PDO data.
    pub pdo_offset: usize,
    /// Offset in the drive image.
    pub image_offset: usize,
}

impl Mapped {
    /// CiA 301 mapping value `index << 16 | sub << 8 | bits`.
    pub fn mapping_value(&self) -> u32 {
        (u32::from(self.index) << 16) | (u32::from(self.sub) << 8) | (8 * self.len as u32)
    }
}

/// When a PDO goes on the bus (module documentation, "The master's layout").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trigger {
    /// Every cycle: a TPDO with transmission type 1 (every SYNC); an RPDO the master sends in
    /// every exchange, watched by the node's deadline monitoring (event-timer).
    Cyclic,
    /// Only when its data changed: a TPDO with transmission type 0 (synchronous, acyclic); an
    /// RPDO the master sends when its data changed and after each NMT start.
    OnChange {
        /// The touch probe (1 or 2) whose objects it carries, if it carries only touch probe
        /// objects of one probe (CiA 402: one probe is armed at a time, so only one probe's
        /// group can change in a cycle).
        probe: Option<u8>,
    },
}

impl Trigger {
    /// The transmission type (sub-index 2 of the communication parameter) the master writes:
    /// 1 for cyclic, 0 for on change (CiA 301 §7.5.2.35 / §7.5.2.37).
    pub const fn transmission_type(self) -> u8 {
        match self {
            Trigger::Cyclic => 1,
            Trigger::OnChange { .. } => 0,
        }
    }
}

/// One PDO: its number, COB-ID and mapped objects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pdo {
    /// Direction.
    pub direction: Direction,
    /// 0-based number (PDO 1 = 0).
    pub number: u8,
    /// COB-ID.
    pub cob: u16,
    /// Mapped objects in PDO order.
    pub mapped: Vec<Mapped>,
    /// When it is sent.
    pub trigger: Trigger,
}

impl Pdo {
    /// Data length in bytes.
    pub fn len(&self) -> usize {
        self.mapped.iter().map(|m| m.len).sum()
    }

    /// `true` if nothing is mapped.
    pub fn is_empty(&self) -> bool {
        self.mapped.is_empty()
    }

    /// PDO data from the drive image.
    pub fn pack(&self, image: &[u8]) -> Vec<u8> {
        let mut d = vec![0u8; self.len()];
        self.pack_into(image, &mut d);
        d
    }

    /// The PDO as a CAN frame (COB-ID, the data packed from the drive image), built without
    /// an allocation; an error for a PDO longer than a classic CAN frame carries.
    pub fn frame(&self, image: &[u8]) -> Result<CanFrame, FrameError> {
        let n = self.len();
        let mut d = [0u8; 8];
        let Some(dst) = d.get_mut(..n) else {
            return CanFrame::new(self.cob, &self.pack(image));
        };
        self.pack_into(image, dst);
        CanFrame::new(self.cob, dst)
    }

    /// Pack the mapped objects of the drive image into `d` (the PDO's data, [`len`](Self::len)
    /// bytes).
    fn pack_into(&self, image: &[u8], d: &mut [u8]) {
        for m in &self.mapped {
            if let (Some(dst), Some(src)) = (
                d.get_mut(m.pdo_offset..m.pdo_offset + m.len),
                image.get(m.image_offset..m.image_offset + m.len),
            ) {
                dst.copy_from_slice(src);
            }
        }
    }

    /// Copy PDO data into the drive image; `false` (image untouched) if the length is wrong.
    pub fn unpack(&self, data: &[u8], image: &mut [u8]) -> bool {
        if data.len() != self.len() {
            return false;
        }
        for m in &self.mapped {
            if let (Some(dst), Some(src)) = (
                image.get_mut(m.image_offset..m.image_offset + m.len),
                data.get(m.pdo_offset..m.pdo_offset + m.len),
            ) {
                dst.copy_from_slice(src);
            }
        }
        true
    }

    /// The SDO writes of the CiA 301 remap procedure, in order: COB-ID invalid (bit 31),
    /// transmission type ([`Trigger::transmission_type`]: 1 synchronous every SYNC, 0
    /// synchronous on change), mapping count 0, the entries, mapping count, COB-ID valid. Each
    /// write: (index, sub, little-endian data).
    pub fn remap_writes(&self) -> Vec<(u16, u8, Vec<u8>)> {
        let comm = self.direction.comm_index(self.number);
        let map = self.direction.mapping_index(self.number);
        let cob = u32::from(self.cob);
        let mut w = vec![
            (comm, 1, (cob | 0x8000_0000).to_le_bytes().to_vec()),
            (comm, 2, vec![self.trigger.transmission_type()]),
            (map, 0, vec![0]),
        ];
        for (j, m) in self.mapped.iter().enumerate() {
            w.push((map, (j + 1) as u8, m.mapping_value().to_le_bytes().to_vec()));
        }
        w.push((map, 0, vec![self.mapped.len() as u8]));
        w.push((comm, 1, cob.to_le_bytes().to_vec()));
        w
    }
}

/// Pack the entries of `layout` into at most [`MAX_PDOS`] PDOs of ≤ 8 bytes for `node`: first
/// fit, largest entries first (entries are never split), PDOs then ordered by their first
/// entry's position in the layout. Errors say why it does not fit.
pub fn pack_layout(layout: &PdoLayout, direction: Direction, node: u8) -> Result<Vec<Pdo>, String> {
    let bins = first_fit(layout, (0..layout.entries().len()).collect());
    if bins.len() > MAX_PDOS {
        let total: usize = layout.entries().iter().map(|e| e.ty.size()).sum();
        return Err(format!(
            "{total} bytes of {} process data do not fit {MAX_PDOS} PDOs of 8 bytes",
            match direction {
                Direction::Rx => "output (RPDO)",
                Direction::Tx => "input (TPDO)",
            }
        ));
    }
    Ok(build(
        layout,
        direction,
        node,
        bins.into_iter().map(|b| (Trigger::Cyclic, b)).collect(),
        &[0, 1, 2, 3],
    ))
}

/// The PDO numbered `numbers[j]` (0-based; PDO *j* where `numbers` is shorter) of `node` for
/// the *j*-th bin of entries of `layout`, packed back to back.
fn build(
    layout: &PdoLayout,
    direction: Direction,
    node: u8,
    bins: Vec<(Trigger, Vec<usize>)>,
    numbers: &[u8],
) -> Vec<Pdo> {
    bins.into_iter()
        .enumerate()
        .map(|(j, (trigger, b))| {
            let k = numbers.get(j).copied().map_or(j, usize::from);
            let mut off = 0;
            let mapped = b
                .into_iter()
                .filter_map(|i| layout.entries().get(i))
                .map(|e| {
                    let m = Mapped {
                        index: e.index,
                        sub: e.sub,
                        len: e.ty.size(),
                        pdo_offset: off,
                        image_offset: e.offset,
                    };
                    off += m.len;
                    m
                })
                .collect();
            Pdo {
                direction,
                number: k as u8,
                cob: direction.default_cob(k as u8, node),
                mapped,
                trigger,
            }
        })
        .collect()
}

/// The class of an object in the master's layout: `None` cyclic, `Some(probe)` on change
/// (module documentation).
fn on_change_class(direction: Direction, index: u16) -> Option<Option<u8>> {
    match (direction, index) {
        // Touch probe 1 positive / negative edge position and edge counters.
        (Direction::Tx, 0x60BA | 0x60BB | 0x60D5 | 0x60D6) => Some(Some(1)),
        // Touch probe 2.
        (Direction::Tx, 0x60BC | 0x60BD | 0x60D7 | 0x60D8) => Some(Some(2)),
        // Modes of operation, touch probe source: settings.
        (Direction::Rx, 0x6060 | 0x60D0) => Some(None),
        _ => None,
    }
}

/// First fit, largest first: the entries `items` of `layout` in bins of ≤ 8 bytes, each bin in
/// layout order, the bins ordered by their first entry.
fn first_fit(layout: &PdoLayout, items: Vec<usize>) -> Vec<Vec<usize>> {
    first_fit_by(layout, items, usize::MAX)
}

/// [`first_fit`] with at most `max_entries` entries a bin (a node's mapping parameter with
/// that many sub-indices, [`PdoSlots`]).
fn first_fit_by(layout: &PdoLayout, mut items: Vec<usize>, max_entries: usize) -> Vec<Vec<usize>> {
    let size = |i: usize| layout.entries().get(i).map_or(0, |e| e.ty.size());
    items.sort_by_key(|&i| std::cmp::Reverse(size(i)));
    let mut bins: Vec<Vec<usize>> = Vec::new();
    for i in items {
        match bins.iter_mut().find(|b| {
            b.len() < max_entries && b.iter().map(|&j| size(j)).sum::<usize>() + size(i) <= 8
        }) {
            Some(b) => b.push(i),
            None => bins.push(vec![i]),
        }
    }
    for b in &mut bins {
        b.sort_unstable();
    }
    bins.sort_by_key(|b| b.first().copied());
    bins
}

/// The master's PDO layout of a drive's process data (module documentation, "The master's
/// layout"): cyclic and on-change classes packed apart, on-change TPDOs first; falls back to
/// everything cyclic ([`pack_layout`]) when that needs more than [`MAX_PDOS`] PDOs. Errors say
/// why it does not fit. [`plan_layout_in`] with [`PdoSlots::FULL`].
pub fn plan_layout(layout: &PdoLayout, direction: Direction, node: u8) -> Result<Vec<Pdo>, String> {
    plan_layout_in(layout, direction, node, &PdoSlots::FULL).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(specs: &[&str]) -> PdoLayout {
        PdoLayout::parse(specs).unwrap()
    }

    /// `drives/cia402-generic.toml`'s process data.
    fn generic() -> (PdoLayout, PdoLayout) {
        (
            layout(&["0x6040:00", "0x607A:00", "0x6060:00", "0x60B8:00"]),
            layout(&[
                "0x6041:00",
                "0x6064:00",
                "0x60F4:00",
                "0x6061:00",
                "0x60B9:00",
                "0x60BA:00",
                "0x60BB:00",
                "0x60BC:00",
                "0x60BD:00",
                "0x6077:00",
            ]),
        )
    }

    fn objects(p: &Pdo) -> Vec<u16> {
        p.mapped.iter().map(|m| m.index).collect()
    }

    #[test]
    fn the_master_layout_sends_touch_probe_positions_and_settings_on_change() {
        let (rx, tx) = generic();
        let r = plan_layout(&rx, Direction::Rx, 3).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(objects(&r[0]), [0x6040, 0x607A, 0x60B8]);
        assert_eq!((r[0].trigger, r[0].cob), (Trigger::Cyclic, 0x203));
        assert_eq!(objects(&r[1]), [0x6060]);
        assert_eq!(r[1].trigger, Trigger::OnChange { probe: None });
        let t = plan_layout(&tx, Direction::Tx, 3).unwrap();
        assert_eq!(t.len(), 4);
        // On-change first: lower COB-IDs than every cyclic TPDO of the node.
        assert_eq!(objects(&t[0]), [0x60BA, 0x60BB]);
        assert_eq!(
            (t[0].trigger, t[0].cob),
            (Trigger::OnChange { probe: Some(1) }, 0x183)
        );
        assert_eq!(objects(&t[1]), [0x60BC, 0x60BD]);
        assert_eq!(t[1].trigger, Trigger::OnChange { probe: Some(2) });
        assert_eq!(objects(&t[2]), [0x6041, 0x6061, 0x60B9, 0x6077]);
        assert_eq!(objects(&t[3]), [0x6064, 0x60F4]);
        assert!(t[2..]
            .iter()
            .all(|p| p.trigger == Trigger::Cyclic && p.len() <= 8));
        // The transmission types written by the remap procedure.
        assert_eq!(t[0].remap_writes()[1], (0x1800, 2, vec![0]));
        assert_eq!(t[3].remap_writes()[1], (0x1803, 2, vec![1]));
        // Every byte of the image is in exactly one PDO.
        let mut image = vec![0u8; tx.len()];
        for (k, b) in image.iter_mut().enumerate() {
            *b = k as u8 + 1;
        }
        let mut back = vec![0u8; tx.len()];
        for p in &t {
            assert!(p.unpack(&p.pack(&image), &mut back));
        }
        assert_eq!(back, image);
    }

    #[test]
    fn a_layout_that_needs_more_pdos_split_falls_back_to_all_cyclic() {
        // Cyclic 8 bytes, probe 1 and probe 2 10 bytes each: split by class 5 PDOs, packed
        // together 4.
        let tx = layout(&[
            "0x6041:00",
            "0x6064:00",
            "0x60BA:00",
            "0x60BB:00",
            "0x60BC:00",
            "0x60BD:00",
            "0x60D5:00:u16",
            "0x60D7:00:u16",
            "0x2000:01:u16",
        ]);
        let t = plan_layout(&tx, Direction::Tx, 1).unwrap();
        assert_eq!(t, pack_layout(&tx, Direction::Tx, 1).unwrap());
        assert!(t.iter().all(|p| p.trigger == Trigger::Cyclic));
        // Without anything on change the two are the same.
        let rx = layout(&["0x6040:00", "0x607A:00"]);
        assert_eq!(
            plan_layout(&rx, Direction::Rx, 1).unwrap(),
            pack_layout(&rx, Direction::Rx, 1).unwrap()
        );
    }
}
