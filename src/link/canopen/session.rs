//! Commissioning access to a CAN bus (`can scan`, `can dump`, `sdo … --node`): no NMT commands,
//! no PDO configuration; SDO by node id.
//!
//! On `canopen-emu` the session runs on the same bus as the link ([`super::wire`]): a wire at
//! the machine's bit rate on virtual time — every frame takes its wire time, the bus goes to
//! the lowest identifier, the nodes do their time-driven work on the bus clock, and the
//! session's times (SDO time-outs, the scan's bound, `listen`'s duration and the times it
//! reports) are bus time. Nothing waits on a wall clock there. On a bus that leaves the
//! process the session runs on the wall clock.

use std::time::{Duration, Instant};

use super::{check_ids, other, sdo_failure, Transport};
use crate::bus::can::{Bitrate, CanFrame};
use crate::bus::canopen::nmt::{self, NmtState};
use crate::bus::canopen::sdo::SdoClient;
use crate::drive::catalogue::DriveDefinition;
use crate::link::{decode_le, LinkError};
use crate::units::Nanos;
use std::sync::Arc;

/// Bus time per step of [`CanSession::listen`] on `canopen-emu`: the nodes' time-driven work
/// (heartbeats) runs at each step.
const LISTEN_STEP: Nanos = Nanos(1_000_000);
/// Bus time per step of [`CanSession::scan`] on `canopen-emu`.
const SCAN_STEP: Nanos = Nanos(1_000_000);

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
    /// The UNIX time of `t0`.
    unix0: Duration,
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
    /// Open `link` (`canopen-emu`: the emulated nodes of `drives` at node ids `ids` on a wire
    /// at `bitrate`, the machine file's `[can] bitrate`; `canopen-udp[:GROUP:PORT]`;
    /// `socketcan:IF`, which run at their own bit rate).
    pub fn open(
        link: &str,
        drives: &[Arc<DriveDefinition>],
        ids: &[u8],
        bitrate: Bitrate,
        candump: Option<&std::path::Path>,
    ) -> Result<Self, LinkError> {
        check_ids(ids)?;
        let bus = Transport::open(
            link,
            drives,
            ids,
            Nanos::from_micros(1000),
            bitrate,
            candump,
        )?;
        let mut s = CanSession {
            bus,
            t0: Instant::now(),
            unix0: std::time::UNIX_EPOCH.elapsed().unwrap_or_default(),
            states: Default::default(),
        };
        // Emulated nodes boot at once (boot-up message, pre-operational); the wire runs until
        // their boot-up messages are through (bus time: one wire time each).
        if s.bus.wire().is_some() {
            s.bus.poll_nodes();
            let frames = s.bus.run_wire(None, &mut |_, _| false)?;
            s.note(&frames);
        }
        Ok(s)
    }

    /// The UNIX time of session time 0 (the times [`Self::listen`] reports count from it; the
    /// `--candump` log uses the same on `canopen-emu`).
    pub fn unix_epoch(&self) -> Duration {
        self.bus.emulated.as_ref().map_or(self.unix0, |e| e.unix0)
    }

    /// The bit rate of the in-process bus's wire (`canopen-emu`); `None` on a bus that leaves
    /// the process.
    pub fn wire_bitrate(&self) -> Option<Bitrate> {
        self.bus.wire().and_then(|w| w.bitrate())
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

    /// The session's clock, time since it opened: the bus clock on `canopen-emu` (the bus
    /// starts with the session), else the wall clock.
    fn wall(&self) -> Nanos {
        self.bus
            .wire_clock()
            .unwrap_or_else(|| Nanos(self.t0.elapsed().as_nanos() as u64))
    }

    fn note<'a>(&mut self, frames: impl IntoIterator<Item = &'a CanFrame>) {
        for f in frames {
            if let Some((n, s)) = nmt::parse_heartbeat(f) {
                self.states.insert(n, s);
            }
        }
    }

    /// Let the bus run and take what the master received, each frame with the session time
    /// it came ([`Self::listen`]). `canopen-emu`: the nodes do their time-driven work at the
    /// bus clock, then `span` of bus time passes on the wire; a frame's time is the end of its
    /// transmission. Elsewhere: the master waits up to `wait` for a first frame and takes
    /// what came, at the wall clock.
    fn pump(&mut self, span: Nanos, wait: Duration) -> Result<Vec<(CanFrame, Nanos)>, LinkError> {
        let mut out = Vec::new();
        if let Some(now) = self.bus.wire_clock() {
            self.bus.poll_nodes();
            self.bus
                .run_wire(Some(now.saturating_add(span)), &mut |d, got| {
                    out.extend(got.iter().map(|f| (*f, d.at)));
                    false
                })?;
        } else {
            let frames = self.bus.receive_all(wait)?;
            let at = self.wall();
            out.extend(frames.into_iter().map(|f| (f, at)));
        }
        Ok(out)
    }

    /// Every frame on the bus for `duration`, in order, each with the session time it came:
    /// on `canopen-emu` `duration` of bus time (the nodes run on it; the time of a frame is
    /// the end of its transmission on the wire), elsewhere of wall-clock time.
    pub fn listen(
        &mut self,
        duration: Duration,
        each: &mut dyn FnMut(&CanFrame, Nanos),
    ) -> Result<(), LinkError> {
        if let Some(start) = self.bus.wire_clock() {
            let end = start.saturating_add(Nanos(
                u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX),
            ));
            loop {
                let now = self.wall();
                if now >= end {
                    return Ok(());
                }
                let span = Nanos(LISTEN_STEP.0.min(end.0 - now.0));
                let frames = self.pump(span, Duration::ZERO)?;
                self.note(frames.iter().map(|(f, _)| f));
                for (f, at) in &frames {
                    each(f, *at);
                }
            }
        }
        let end = Instant::now() + duration;
        while Instant::now() < end {
            let frames = self.pump(Nanos::ZERO, Duration::from_millis(10))?;
            self.note(frames.iter().map(|(f, _)| f));
            for (f, at) in &frames {
                each(f, *at);
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
        let r = self.bus.sdo(&mut client, first, t0, None, &mut |f| {
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
        // 400 ms: of bus time on `canopen-emu`, else of wall-clock time.
        let bound = Nanos::from_micros(400_000);
        let end = Instant::now() + Duration::from_millis(400);
        loop {
            let late = match self.bus.wire_clock() {
                Some(t) => t.0.saturating_sub(wall.0) >= bound.0,
                None => Instant::now() >= end,
            };
            if late || !clients.iter().any(|c| c.busy()) {
                break;
            }
            let frames = self.pump(SCAN_STEP, Duration::from_millis(10))?;
            self.note(frames.iter().map(|(f, _)| f));
            for (f, at) in &frames {
                if let Some(c) =
                    f.id.checked_sub(u32::from(crate::bus::canopen::sdo::SDO_TX_BASE))
                        .filter(|n| (1..=127).contains(n))
                        .and_then(|n| clients.get_mut(n as usize - 1))
                {
                    for r in c.handle(f, *at) {
                        self.bus.send(&r)?;
                    }
                }
            }
            let now = self.wall();
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
