//! Commissioning access to a CAN bus (`can scan`, `can dump`, `sdo … --node`): no NMT commands,
//! no PDO configuration; SDO by node id.

use std::time::{Duration, Instant};

use super::{check_ids, other, sdo_failure, Transport};
use crate::bus::can::CanFrame;
use crate::bus::canopen::nmt::{self, NmtState};
use crate::bus::canopen::sdo::SdoClient;
use crate::drive::catalogue::DriveDefinition;
use crate::link::{decode_le, LinkError};
use crate::units::Nanos;
use std::sync::Arc;

/// One node as [`CanSession::scan`] finds it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeInfo {
    /// Node id.
    pub id: u8,
    /// State from its last heartbeat / boot-up, if one was seen.
    pub state: Option<NmtState>,
    /// 0x1000 device type.
    pub device_type: u32,
    /// 0x1018:1 … 3 vendor, product code, revision (None where the node refused).
    pub identity: [Option<u32>; 3],
    /// 0x1008 device name, if the node has one.
    pub name: Option<String>,
}

/// A CAN bus for commissioning commands (`can scan`, `can dump`, `sdo … --node`): no NMT
/// commands, no PDO configuration; SDO by node id.
pub struct CanSession {
    bus: Transport,
    t0: Instant,
    states: std::collections::BTreeMap<u8, NmtState>,
}

impl std::fmt::Debug for CanSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CanSession")
            .field("bus", &self.bus.describe())
            .finish_non_exhaustive()
    }
}

impl CanSession {
    /// Open `link` (`canopen-emu`: the emulated nodes of `drives` at node ids `ids`;
    /// `canopen-udp[:GROUP:PORT]`; `socketcan:IF`).
    pub fn open(
        link: &str,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
        candump: Option<&std::path::Path>,
    ) -> Result<Self, LinkError> {
        check_ids(ids)?;
        let bus = Transport::open(link, drives, ids, Nanos::from_micros(1000), None, candump)?;
        let mut s = CanSession {
            bus,
            t0: Instant::now(),
            states: Default::default(),
        };
        // Emulated nodes boot at once (boot-up message, pre-operational).
        s.bus.run_nodes(Nanos::ZERO);
        let frames = s.bus.receive_all(Duration::ZERO)?;
        s.note(&frames);
        Ok(s)
    }

    /// The interface name `candump -L` lines of this bus carry (`vcan0` for `socketcan:vcan0`,
    /// `udp0`, `emu0`; [`crate::bus::can::candump`] "Interface names").
    pub fn log_interface(&self) -> String {
        self.bus.log_interface()
    }

    /// Flush the `--candump` log at the end of a command.
    ///
    /// # Errors
    /// The first write to the log that failed, naming the option and the file.
    pub fn finish_capture(&mut self) -> Result<(), String> {
        self.bus.finish_capture()
    }

    fn wall(&self) -> Nanos {
        Nanos(self.t0.elapsed().as_nanos() as u64)
    }

    fn note(&mut self, frames: &[CanFrame]) {
        for f in frames {
            if let Some((n, s)) = nmt::parse_heartbeat(f) {
                self.states.insert(n, s);
            }
        }
    }

    /// Every frame on the bus for `duration` (emulated nodes run meanwhile), in order.
    pub fn listen(
        &mut self,
        duration: Duration,
        each: &mut dyn FnMut(&CanFrame),
    ) -> Result<(), LinkError> {
        let end = Instant::now() + duration;
        while Instant::now() < end {
            let now = self.wall();
            self.bus.run_nodes(now);
            let frames = self.bus.receive_all(Duration::from_millis(10))?;
            self.note(&frames);
            for f in &frames {
                each(f);
            }
            if self.bus.emulated.is_some() {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        Ok(())
    }

    /// SDO upload from `node`.
    pub fn sdo_upload(&mut self, node: u8, index: u16, sub: u8) -> Result<Vec<u8>, LinkError> {
        self.transfer(node, index, sub, None)
    }

    /// SDO download to `node`.
    pub fn sdo_download(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), LinkError> {
        self.transfer(node, index, sub, Some(data)).map(|_| ())
    }

    fn transfer(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        data: Option<&[u8]>,
    ) -> Result<Vec<u8>, LinkError> {
        if !(1..=127).contains(&node) {
            return Err(other(format!("node {node}: allowed 1 … 127")));
        }
        let mut client = SdoClient::new(node);
        let wall = self.wall();
        let first = match data {
            None => client.upload(index, sub, wall),
            Some(d) => client.download(index, sub, d, wall),
        };
        let t0 = self.t0;
        let mut seen = Vec::new();
        let r = self.bus.sdo(&mut client, first, t0, wall, None, &mut |f| {
            seen.extend(f);
            Ok(())
        });
        self.note(&seen);
        r.map_err(sdo_failure(node, index, sub))
    }

    /// Find the nodes: an SDO upload of 0x1000 to every node id 1 … 127 at once (nodes in
    /// pre-operational or operational answer), then 0x1018:1 … 3 and 0x1008 from each.
    pub fn scan(&mut self) -> Result<Vec<NodeInfo>, LinkError> {
        let wall = self.wall();
        let mut clients: Vec<SdoClient> = (1..=127u8).map(SdoClient::new).collect();
        for c in &mut clients {
            c.set_timeout(Nanos::from_micros(300_000));
            for f in c.upload(0x1000, 0, wall) {
                self.bus.send(&f)?;
            }
        }
        let end = Instant::now() + Duration::from_millis(400);
        while Instant::now() < end && clients.iter().any(|c| c.busy()) {
            let now = self.wall();
            self.bus.run_nodes(now);
            let frames = self.bus.receive_all(Duration::from_millis(10))?;
            self.note(&frames);
            for f in &frames {
                if let Some(c) =
                    f.id.checked_sub(u32::from(crate::bus::canopen::sdo::SDO_TX_BASE))
                        .filter(|n| (1..=127).contains(n))
                        .and_then(|n| clients.get_mut(n as usize - 1))
                {
                    for r in c.handle(f, now) {
                        self.bus.send(&r)?;
                    }
                }
            }
            for c in &mut clients {
                for r in c.poll(now) {
                    self.bus.send(&r)?;
                }
            }
        }
        let found: Vec<(u8, u32)> = clients
            .iter_mut()
            .filter_map(|c| match c.take_result() {
                Some(Ok(b)) => Some((c.node(), decode_le(&b, false) as u32)),
                _ => None,
            })
            .collect();
        let mut out = Vec::new();
        for (id, device_type) in found {
            let mut identity = [None; 3];
            for (k, slot) in identity.iter_mut().enumerate() {
                *slot = self
                    .sdo_upload(id, 0x1018, (k + 1) as u8)
                    .ok()
                    .map(|b| decode_le(&b, false) as u32);
            }
            let name = self.sdo_upload(id, 0x1008, 0).ok().map(|b| {
                String::from_utf8_lossy(&b)
                    .trim_end_matches('\0')
                    .to_string()
            });
            out.push(NodeInfo {
                id,
                state: self.states.get(&id).copied(),
                device_type,
                identity,
                name,
            });
        }
        Ok(out)
    }
}
