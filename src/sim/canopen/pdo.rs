//! The emulated node's PDOs at run time (CiA 301 §7.2.2): what each RPDO / TPDO maps, where
//! the mapped bytes live on the node, and when a PDO is taken over or sent by its
//! transmission type, inhibit time and event-timer (communication parameter 0x1400 + k /
//! 0x1800 + k, sub-indices 2, 3, 5; CiA 301 §7.5.2.35 and §7.5.2.37).
//!
//! Sans-IO: every decision takes the data and `now`; the node ([`super::EmulatedNode`]) reads
//! its object dictionary, sends the frames and calls [`NodePdo::sent`].

use crate::units::Nanos;

/// Transmission type, sub-index 2 of a PDO communication parameter (CiA 301 §7.2.2.2,
/// Table 71 of CiA 301 v4.2 "description of TPDO transmission type"). Unknown (reserved)
/// codes are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transmission {
    /// 0 — synchronous, acyclic: a TPDO goes out at a SYNC only when its data changed since
    /// it was last sent; an RPDO is taken over at the next SYNC.
    SyncAcyclic,
    /// 1 … 240 — synchronous, cyclic: a TPDO goes out at every n-th SYNC; an RPDO is taken
    /// over at the next SYNC.
    SyncEvery(u8),
    /// 252 (synchronous) / 253 (event) — RTR only: sent on a remote request. The emulated
    /// node does not answer remote frames, so such a TPDO stays silent.
    RtrOnly(u8),
    /// 254 (manufacturer specific) / 255 (device profile) — event-driven: a TPDO goes out
    /// when its data change (not sooner than the inhibit time after the last one) and when
    /// the event-timer elapses; an RPDO is taken over on reception.
    Event(u8),
    /// 241 … 251 — reserved; handled like [`Transmission::Event`].
    Reserved(u8),
}

impl Transmission {
    /// The type of a sub-index 2 value.
    pub fn from_code(code: u8) -> Self {
        match code {
            0 => Transmission::SyncAcyclic,
            1..=240 => Transmission::SyncEvery(code),
            252 | 253 => Transmission::RtrOnly(code),
            254 | 255 => Transmission::Event(code),
            _ => Transmission::Reserved(code),
        }
    }

    /// The sub-index 2 value.
    pub fn code(self) -> u8 {
        match self {
            Transmission::SyncAcyclic => 0,
            Transmission::SyncEvery(n)
            | Transmission::RtrOnly(n)
            | Transmission::Event(n)
            | Transmission::Reserved(n) => n,
        }
    }

    /// Types 0 … 240: an RPDO's data take effect at the next SYNC (CiA 301 §7.2.2.2), a
    /// TPDO is sent at a SYNC.
    pub fn synchronous(self) -> bool {
        matches!(self, Transmission::SyncAcyclic | Transmission::SyncEvery(_))
    }

    /// Types 241 … 251, 254, 255: event-driven.
    pub fn event_driven(self) -> bool {
        matches!(self, Transmission::Event(_) | Transmission::Reserved(_))
    }
}

/// Where a mapped object's bytes live on the node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// At this offset of the drive model's process image (the drive file's `[rxpdo]` /
    /// `[txpdo]` layout): the model reads an RPDO's bytes at its step, a TPDO carries what
    /// the model wrote at its last step.
    Image(usize),
    /// An object outside the model's image: an RPDO writes it into the object dictionary
    /// (as an SDO download would), a TPDO reads it from there when it is sent.
    Object,
}

/// One mapped object of a PDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Bytes.
    pub len: usize,
    /// Offset in the PDO data.
    pub pdo_offset: usize,
    /// Where the bytes live.
    pub place: Place,
}

/// The data of one PDO: at most 8 bytes (a classic CAN frame; the node refuses a longer
/// mapping at NMT start), kept by value so that receiving, taking over and sending a PDO
/// allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PdoData {
    len: u8,
    bytes: [u8; 8],
}

impl PdoData {
    /// `data` if it has at most 8 bytes.
    pub fn new(data: &[u8]) -> Option<Self> {
        let mut bytes = [0u8; 8];
        bytes.get_mut(..data.len())?.copy_from_slice(data);
        Some(PdoData {
            len: data.len() as u8,
            bytes,
        })
    }

    /// `len` zero bytes (at most 8).
    pub fn zeroed(len: usize) -> Self {
        PdoData {
            len: len.min(8) as u8,
            bytes: [0; 8],
        }
    }

    /// The bytes.
    pub fn as_slice(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// The bytes, mutable.
    pub fn as_mut_slice(&mut self) -> &mut [u8] {
        &mut self.bytes[..usize::from(self.len)]
    }
}

/// One valid PDO of the node in OPERATIONAL, read from its communication and mapping
/// parameters at NMT start, with its run-time state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodePdo {
    /// 0-based number (PDO 1 = 0).
    pub number: u8,
    /// COB-ID (11 bit).
    pub cob: u16,
    /// Transmission type (sub-index 2).
    pub transmission: Transmission,
    /// Inhibit time (sub-index 3), units of 100 µs; TPDO only.
    pub inhibit_100us: u16,
    /// Event-timer (sub-index 5), ms. TPDO: the longest time between two event-driven
    /// transmissions (0 = none); an RPDO's sub-index 5 is its deadline (read by the node's
    /// RPDO monitoring, not here).
    pub event_timer_ms: u16,
    /// The mapped objects, in PDO order.
    pub slots: Vec<Slot>,
    /// RPDO, synchronous: data received since the last SYNC (the newest wins).
    pending: Option<PdoData>,
    /// TPDO, types 1 … 240: SYNCs counted since the last transmission.
    syncs: u8,
    /// TPDO: when it was last sent and what it carried.
    last_sent: Option<(Nanos, PdoData)>,
}

impl NodePdo {
    /// A PDO without run-time history.
    pub fn new(
        number: u8,
        cob: u16,
        transmission: Transmission,
        inhibit_100us: u16,
        event_timer_ms: u16,
        slots: Vec<Slot>,
    ) -> Self {
        NodePdo {
            number,
            cob,
            transmission,
            inhibit_100us,
            event_timer_ms,
            slots,
            pending: None,
            syncs: 0,
            last_sent: None,
        }
    }

    /// Data length in bytes.
    pub fn len(&self) -> usize {
        self.slots.iter().map(|s| s.len).sum()
    }

    /// `true` if nothing is mapped.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// RPDO `data` (of the right length, at most 8 bytes) received: `Some(data)` to take over
    /// now (types 254 / 255 and the reserved ones), `None` when it waits for the next SYNC
    /// (0 … 240) or is longer than a CAN frame carries.
    pub fn receive(&mut self, data: &[u8]) -> Option<PdoData> {
        let data = PdoData::new(data)?;
        if self.transmission.synchronous() {
            self.pending = Some(data);
            None
        } else {
            Some(data)
        }
    }

    /// RPDO at a SYNC: the data received since the previous SYNC, if any.
    pub fn take_pending(&mut self) -> Option<PdoData> {
        self.pending.take()
    }

    /// TPDO at a SYNC whose current data are `data`: `true` when it is to be sent now (type 0:
    /// the data changed since the last transmission, or it was never sent; type n: this is
    /// the n-th SYNC since the last one, counted from NMT start).
    pub fn sync_due(&mut self, data: &[u8]) -> bool {
        match self.transmission {
            Transmission::SyncAcyclic => self
                .last_sent
                .as_ref()
                .is_none_or(|(_, d)| d.as_slice() != data),
            Transmission::SyncEvery(n) => {
                self.syncs = self.syncs.saturating_add(1);
                if self.syncs >= n {
                    self.syncs = 0;
                    true
                } else {
                    false
                }
            }
            _ => false,
        }
    }

    /// Event-driven TPDO at `now` with current data `data`: `true` when it is to be sent now —
    /// the data differ from the last transmission (or there was none since NMT start) or the
    /// event-timer elapsed since it, and the inhibit time since it is over.
    pub fn event_due(&self, now: Nanos, data: &[u8]) -> bool {
        if !self.transmission.event_driven() {
            return false;
        }
        let Some((at, last)) = &self.last_sent else {
            return true;
        };
        let since = now.0.saturating_sub(at.0);
        if since < u64::from(self.inhibit_100us) * 100_000 {
            return false;
        }
        last.as_slice() != data
            || (self.event_timer_ms != 0 && since >= u64::from(self.event_timer_ms) * 1_000_000)
    }

    /// The TPDO went out at `now` carrying `data`.
    pub fn sent(&mut self, now: Nanos, data: PdoData) {
        self.last_sent = Some((now, data));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tpdo(code: u8, inhibit_100us: u16, event_timer_ms: u16) -> NodePdo {
        NodePdo::new(
            0,
            0x185,
            Transmission::from_code(code),
            inhibit_100us,
            event_timer_ms,
            Vec::new(),
        )
    }

    #[test]
    fn transmission_codes_round_trip_and_keep_reserved_ones() {
        for code in 0..=255u8 {
            assert_eq!(Transmission::from_code(code).code(), code);
        }
        assert!(Transmission::from_code(0).synchronous());
        assert!(Transmission::from_code(240).synchronous());
        assert!(!Transmission::from_code(241).synchronous());
        assert_eq!(Transmission::from_code(245), Transmission::Reserved(245));
        assert!(!Transmission::from_code(255).synchronous());
    }

    #[test]
    fn rpdo_synchronous_waits_for_sync_event_driven_is_taken_at_once() {
        let mut p = tpdo(1, 0, 0);
        assert_eq!(p.receive(&[1, 2]), None);
        assert_eq!(p.receive(&[3, 4]), None);
        // CiA 301: the newest data received before the SYNC are taken over.
        assert_eq!(p.take_pending(), PdoData::new(&[3, 4]));
        assert_eq!(p.take_pending(), None);
        let mut p = tpdo(255, 0, 0);
        assert_eq!(p.receive(&[5]), PdoData::new(&[5]));
        assert_eq!(p.take_pending(), None);
    }

    #[test]
    fn tpdo_type_3_goes_out_at_every_third_sync() {
        let mut p = tpdo(3, 0, 0);
        let due: Vec<bool> = (0..7).map(|_| p.sync_due(&[0])).collect();
        assert_eq!(due, [false, false, true, false, false, true, false]);
    }

    #[test]
    fn tpdo_event_inhibit_is_100_us_units_and_the_event_timer_ms() {
        // Inhibit 25 × 100 µs = 2.5 ms, event-timer 10 ms.
        let mut p = tpdo(255, 25, 10);
        assert!(p.event_due(Nanos(0), &[1]), "first transmission");
        p.sent(Nanos(0), PdoData::new(&[1]).unwrap());
        assert!(!p.event_due(Nanos(1_000_000), &[2]), "inhibited");
        assert!(!p.event_due(Nanos(2_499_999), &[2]), "inhibited");
        assert!(p.event_due(Nanos(2_500_000), &[2]), "inhibit over");
        assert!(!p.event_due(Nanos(9_999_999), &[1]), "unchanged");
        assert!(p.event_due(Nanos(10_000_000), &[1]), "event-timer");
        // Not at a SYNC.
        assert!(!p.sync_due(&[3]));
    }
}
