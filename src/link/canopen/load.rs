//! Bus load of a CANopen cycle, computed at start-up: the link refuses a cycle the bus cannot
//! carry and warns when little room is left (docs/canopen.md, "Bus load").
//!
//! # The figure
//!
//! ```text
//! load = B / (r · T) + n · H / (r · P) + R
//! ```
//!
//! * **B** — bit times of the frames of one cycle at worst-case bit stuffing
//!   ([`timing::worst_case_bits`]: 47 + 8 n + ⌊(34 + 8 n − 1) / 4⌋ for a base frame of n data
//!   bytes): the SYNC (0 bytes, 55 bits) and, per node, every RPDO (cyclic and on change: each
//!   can go out once per cycle), every cyclic TPDO, every on-change TPDO that carries no touch
//!   probe group, and of the on-change TPDOs of the two touch probes the larger group only — a
//!   CiA 402 adapter arms one probe at a time, so one latch changes one probe's positions
//!   (`crate::bus::canopen::pdo`, "The master's layout"). Every node may latch in the same
//!   cycle (one probe wired to every drive), so every node's group counts.
//! * **r** — the bit rate; **T** — the cycle.
//! * **n · H / (r · P)** — the heartbeats: every node sends one of 1 data byte (H = 65 bit
//!   times at worst) every P = 0x1017, the producer heartbeat time the master configures
//!   ([`super::HEARTBEAT_MS`]).
//! * **R** — a fixed reserve of [`RESERVE`] = 10 % of the bus for SDO transfers (acyclic
//!   parameter access, `#DRIVE`), EMCY and NMT.
//!
//! A load above [`MAX_LOAD`] (100 %) is refused, above [`WARN_LOAD`] (70 %) warned about
//! (message 900070). The shortest cycle that fits solves load = 100 % for T.

use crate::bus::can::timing::{self, Bitrate};
use crate::bus::canopen::pdo::{Pdo, Trigger};
use crate::units::Nanos;

/// Fixed share of the bus kept for SDO, EMCY and NMT (module documentation).
pub const RESERVE: f64 = 0.10;
/// Above this load the link warns (message 900070).
pub const WARN_LOAD: f64 = 0.70;
/// Above this load the link refuses to start.
pub const MAX_LOAD: f64 = 1.00;

/// The frames of one node in one cycle, as counted for the load.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NodeFrames {
    /// Frames counted.
    pub frames: usize,
    /// Their bit times at worst-case stuffing.
    pub bits: u64,
}

/// What a node's PDOs put on the bus in the worst cycle (module documentation, **B**).
pub fn node_frames(rx: &[Pdo], tx: &[Pdo]) -> NodeFrames {
    let bits = |p: &Pdo| u64::from(timing::worst_case_bits(p.len(), false));
    let mut n = NodeFrames::default();
    let mut add = |p: &Pdo| {
        n.frames += 1;
        n.bits += bits(p);
    };
    rx.iter().for_each(&mut add);
    tx.iter()
        .filter(|p| !matches!(p.trigger, Trigger::OnChange { probe: Some(_) }))
        .for_each(&mut add);
    // Of the touch probe groups, the one with the most bits.
    let group = |probe: u8| -> NodeFrames {
        let ps = tx
            .iter()
            .filter(|p| p.trigger == Trigger::OnChange { probe: Some(probe) });
        ps.fold(NodeFrames::default(), |a, p| NodeFrames {
            frames: a.frames + 1,
            bits: a.bits + bits(p),
        })
    };
    let (g1, g2) = (group(1), group(2));
    let g = if g2.bits > g1.bits { g2 } else { g1 };
    n.frames += g.frames;
    n.bits += g.bits;
    n
}

/// The bus load of one cycle (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct BusLoad {
    /// Bit rate.
    pub bitrate: Bitrate,
    /// The cycle (SYNC period).
    pub cycle: Nanos,
    /// Nodes.
    pub nodes: usize,
    /// Frames of one cycle: SYNC and the nodes' PDOs as counted.
    pub frames: usize,
    /// Their bit times at worst-case stuffing (**B**).
    pub bits: u64,
    /// Producer heartbeat time of every node, ms (**P**).
    pub heartbeat_ms: u16,
}

impl BusLoad {
    /// The load of SYNC plus `nodes` (their [`node_frames`]) at `bitrate` and `cycle`.
    pub fn new(nodes: &[NodeFrames], bitrate: Bitrate, cycle: Nanos, heartbeat_ms: u16) -> Self {
        let sync = u64::from(timing::worst_case_bits(0, false));
        BusLoad {
            bitrate,
            cycle,
            nodes: nodes.len(),
            frames: 1 + nodes.iter().map(|n| n.frames).sum::<usize>(),
            bits: sync + nodes.iter().map(|n| n.bits).sum::<u64>(),
            heartbeat_ms,
        }
    }

    /// Share of the bus the cyclic frames take (B / (r T)).
    pub fn cyclic(&self) -> f64 {
        let capacity = f64::from(self.bitrate.bps()) * self.cycle.as_secs_f64();
        if capacity > 0.0 {
            self.bits as f64 / capacity
        } else {
            f64::INFINITY
        }
    }

    /// Share of the bus the heartbeats take (n H / (r P)); 0 without heartbeats.
    pub fn heartbeats(&self) -> f64 {
        if self.heartbeat_ms == 0 {
            return 0.0;
        }
        let h = f64::from(timing::worst_case_bits(1, false));
        self.nodes as f64 * h
            / (f64::from(self.bitrate.bps()) * f64::from(self.heartbeat_ms) * 1e-3)
    }

    /// The load: cyclic frames + heartbeats + [`RESERVE`] (1.0 = 100 %).
    pub fn load(&self) -> f64 {
        self.cyclic() + self.heartbeats() + RESERVE
    }

    /// Wire time of the cycle's frames at worst case (B / r).
    pub fn wire_time(&self) -> Nanos {
        self.bitrate.time_of(self.bits)
    }

    /// The shortest cycle (whole µs) whose load is at most `limit`; `None` when the heartbeats
    /// and the reserve alone exceed it.
    pub fn shortest_cycle(&self, limit: f64) -> Option<u64> {
        let room = limit - self.heartbeats() - RESERVE;
        if room <= 0.0 {
            return None;
        }
        let us = self.bits as f64 / (f64::from(self.bitrate.bps()) * room) * 1e6;
        us.is_finite().then(|| (us - 1e-9).ceil().max(1.0) as u64)
    }

    /// One line: load, frames, wire time, cycle and bit rate.
    pub fn describe(&self) -> String {
        format!(
            "CAN bus load {:.1} % at {} and a {} µs cycle: {} frames per cycle (SYNC and the PDOs of {} node{}) take {} bit times at worst-case bit stuffing, {} µs; heartbeats {:.1} %, reserve for SDO / EMCY {:.0} %",
            100.0 * self.load(),
            self.bitrate.describe(),
            self.cycle.0 / 1000,
            self.frames,
            self.nodes,
            if self.nodes == 1 { "" } else { "s" },
            self.bits,
            self.wire_time().0.div_ceil(1000),
            100.0 * self.heartbeats(),
            100.0 * RESERVE,
        )
    }

    fn shortest(&self, limit: f64) -> String {
        match self.shortest_cycle(limit) {
            Some(us) => format!("{us} µs"),
            None => "none (the heartbeats and the reserve alone exceed it)".into(),
        }
    }

    /// `Err` (the refusal) above [`MAX_LOAD`]; `Ok(Some(warning))` above [`WARN_LOAD`];
    /// `Ok(None)` otherwise. The texts name the machine-file keys that change it.
    pub fn check(&self) -> Result<Option<String>, String> {
        let load = self.load();
        if load > MAX_LOAD {
            return Err(format!(
                "{}: the bus carries at most 100 %; the shortest cycle that fits is {} ({} below the {:.0} % warning); \
                 set cycle_time_us in [channel], a higher [can] bitrate, or fewer nodes",
                self.describe(),
                self.shortest(MAX_LOAD),
                self.shortest(WARN_LOAD),
                100.0 * WARN_LOAD,
            ));
        }
        if load > WARN_LOAD {
            return Ok(Some(format!(
                "{}: above {:.0} %, little room for SDO, heartbeat and EMCY traffic; cycles from {} stay below",
                self.describe(),
                100.0 * WARN_LOAD,
                self.shortest(WARN_LOAD),
            )));
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::canopen::pdo::{plan_layout, Direction};
    use crate::drive::pdo::PdoLayout;

    fn node(id: u8) -> NodeFrames {
        let rx = PdoLayout::parse(&["0x6040:00", "0x607A:00", "0x6060:00", "0x60B8:00"]).unwrap();
        let tx = PdoLayout::parse(&[
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
        ])
        .unwrap();
        node_frames(
            &plan_layout(&rx, Direction::Rx, id).unwrap(),
            &plan_layout(&tx, Direction::Tx, id).unwrap(),
        )
    }

    #[test]
    fn one_probe_group_counts_and_every_rpdo() {
        // RPDO 8 + 1 bytes (135 + 65), cyclic TPDOs 7 + 8 bytes (125 + 135), one probe group
        // of 8 bytes (135).
        assert_eq!(
            node(1),
            NodeFrames {
                frames: 5,
                bits: 135 + 65 + 125 + 135 + 135
            }
        );
    }

    #[test]
    fn load_refusal_warning_and_shortest_cycle() {
        let nodes = [node(1), node(2), node(3)];
        let at = |us: u64| BusLoad::new(&nodes, Bitrate::DEFAULT, Nanos::from_micros(us), 100);
        let l = at(1000);
        assert_eq!((l.frames, l.bits), (16, 55 + 3 * 595));
        assert!((l.load() - (1.840 + 3.0 * 65.0 / 100_000.0 + 0.10)).abs() < 1e-12);
        let e = l.check().unwrap_err();
        assert!(e.contains("194.2 %") && e.contains("16 frames"), "{e}");
        // 1840 / (1e6 · (1 − 0.00195 − 0.1)) s = 2048.9 µs → 2049 µs.
        assert_eq!(l.shortest_cycle(MAX_LOAD), Some(2049));
        assert!(e.contains("2049 µs"), "{e}");
        assert!(at(2049).check().is_ok());
        assert!(at(2048).check().is_err());
        // 3 ms: 71.5 % — a warning; 4 ms: 56.2 % — nothing.
        assert!(at(3000).check().unwrap().is_some());
        assert_eq!(at(4000).check(), Ok(None));
        // Heartbeats alone beyond the room: no cycle fits.
        let slow = BusLoad::new(
            &nodes,
            Bitrate::new(1000).unwrap(),
            Nanos::from_micros(1000),
            100,
        );
        assert_eq!(slow.shortest_cycle(MAX_LOAD), None);
        assert!(slow.check().unwrap_err().contains("none"));
    }
}
