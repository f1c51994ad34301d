//! `canopen-emu` on the wire: the master and the emulated nodes on a [`VirtualCan`] with a bit
//! rate, driven on virtual time (`crate::bus::can::virtual_bus`, "The wire").
//!
//! The link owns the bus clock and moves it (`Transport::run_wire`): each frame ends its
//! transmission at the time its bits take, after the frames that won arbitration before it;
//! the nodes take every frame at its end and answer at once (their answers wait for the bus
//! like any frame); the master takes its frames after each one. Nothing here reads a wall
//! clock: SDO time-outs, the boot-up wait and the heartbeat consumer run on the bus clock too,
//! so a run is the same on a loaded machine as on an idle one.
//!
//! Bus time and machine time: start-up (NMT, the SDO configuration) takes bus time before the
//! machine's cycle 0; the link keeps the offset ([`super::CanopenLink`]'s epoch) and sends the
//! SYNC of the machine's `now` at epoch + `now` on the bus. The drive models step at `now`
//! itself (the SYNC producer's grid, [`CanopenSegment::receive`]), so the world — probe
//! surfaces, fixed stops, the PLC's timestamps — keeps the machine's clock.

use std::collections::VecDeque;
use std::time::Duration;

use super::Transport;
#[cfg(feature = "sim")]
use crate::bus::can::CanBus;
use crate::bus::can::{CanFrame, Delivery, VirtualCan, VirtualEndpoint};
use crate::bus::canopen::nmt;
use crate::bus::canopen::sdo::{SdoClient, SdoError, SDO_TX_BASE};
use crate::link::LinkError;
#[cfg(feature = "sim")]
use crate::sim::canopen::CanopenSegment;
use crate::units::Nanos;

/// A virtual SDO transfer that has not ended after this much bus time is given up ("no
/// answer"), as a real one is after 4 s of wall-clock time.
pub const SDO_BOUND: Nanos = Nanos(4_000_000_000);

/// The emulated nodes of `canopen-emu` on the other endpoint of the in-process bus. Only a
/// build with the emulators (feature `sim`) makes one; without it the transport's `emulated` is
/// always `None` and the wire's functions here have nothing to run.
#[cfg_attr(not(feature = "sim"), allow(dead_code))]
pub(super) struct Emulated {
    #[cfg(feature = "sim")]
    pub(super) segment: CanopenSegment,
    pub(super) endpoint: VirtualEndpoint,
    /// The bus with its wire: every frame takes its wire time on virtual time — the link's
    /// and the commissioning session's (`can scan`, `can dump`, `sdo … --node`) alike.
    pub(super) wire: VirtualCan,
    /// Model times of the SYNCs sent and not yet delivered to the nodes.
    pub(super) sync_times: VecDeque<Nanos>,
    /// Every frame the wire completed, while recorded
    /// ([`super::CanopenLink::trace_bus`]).
    pub(super) trace: Option<Vec<Delivery>>,
    /// The UNIX time that bus time 0 stands for in `--candump` logs and `can dump` lines
    /// (when the bus was made): a label only, nothing runs on it.
    pub(super) unix0: Duration,
}

#[cfg(feature = "sim")]
impl Emulated {
    pub(super) fn new(
        segment: CanopenSegment,
        endpoint: VirtualEndpoint,
        wire: VirtualCan,
    ) -> Emulated {
        Emulated {
            segment,
            endpoint,
            wire,
            sync_times: VecDeque::new(),
            trace: None,
            unix0: std::time::UNIX_EPOCH.elapsed().unwrap_or_default(),
        }
    }
}

impl Transport {
    /// The bus clock of the in-process bus (`canopen-emu`); `None` on a bus that leaves the
    /// process.
    pub(super) fn wire_clock(&self) -> Option<Nanos> {
        self.wire().map(VirtualCan::now)
    }

    /// The in-process bus with its wire (`canopen-emu`), if this is one.
    pub(super) fn wire(&self) -> Option<&VirtualCan> {
        self.emulated.as_ref().map(|e| &e.wire)
    }

    /// Run the wire: complete frames that end by `until` (`None`: until the bus has nothing to
    /// send), the nodes taking each at its end and answering at once; the frames the master
    /// receives are returned in order. After each delivery `stop` sees it and the frames the
    /// master got with it, and may end the run there (the clock then stands at that delivery).
    /// Without `stop` ending it and with `until`, the clock stands at `until` afterwards.
    pub(super) fn run_wire(
        &mut self,
        until: Option<Nanos>,
        stop: &mut dyn FnMut(&Delivery, &[CanFrame]) -> bool,
    ) -> Result<Vec<CanFrame>, LinkError> {
        let mut got = Vec::new();
        self.run_wire_into(until, stop, &mut got)?;
        Ok(got)
    }

    /// [`run_wire`](Self::run_wire) appending the master's frames to `got` (the cyclic
    /// exchange keeps that buffer: nothing here allocates once the buffers have their size).
    /// `stop` sees the frames of each delivery only.
    pub(super) fn run_wire_into(
        &mut self,
        until: Option<Nanos>,
        stop: &mut dyn FnMut(&Delivery, &[CanFrame]) -> bool,
        got: &mut Vec<CanFrame>,
    ) -> Result<(), LinkError> {
        loop {
            let Some(em) = self.emulated.as_mut() else {
                return Ok(());
            };
            let wire = &em.wire;
            let delivery = match until {
                Some(t) => wire.advance(t),
                None => wire.advance_next(),
            };
            let Some(d) = delivery else {
                return Ok(());
            };
            if let Some(t) = em.trace.as_mut() {
                t.push(d);
            }
            #[cfg(feature = "sim")]
            let (segment, endpoint, syncs) =
                (&mut em.segment, &mut em.endpoint, &mut em.sync_times);
            #[cfg(feature = "sim")]
            while let Some((f, at)) = endpoint.recv_timed() {
                let model_time = if is_sync(&f) {
                    syncs.pop_front().unwrap_or(at)
                } else {
                    at
                };
                // The answers wait for the bus like any frame (queued, not delivered, here).
                segment.receive(&f, at, model_time, &mut |a| node_send(endpoint, &a));
            }
            let first = got.len();
            while let Some(f) = self.poll_master()? {
                got.push(f);
            }
            if stop(&d, &got[first..]) {
                return Ok(());
            }
        }
    }

    /// The next frame the master received, logged, without waiting (and without reading a
    /// clock).
    fn poll_master(&mut self) -> Result<Option<CanFrame>, LinkError> {
        match self.bus.recv(Duration::ZERO) {
            Ok(Some(f)) => {
                self.log(&f);
                Ok(Some(f))
            }
            Ok(None) => Ok(None),
            Err(e) => Err(LinkError::Other(format!(
                "CAN receive on {}: {e}",
                self.bus.describe()
            ))),
        }
    }

    /// The nodes' time-driven work (heartbeat, boot-up, SDO server timeout, EMCY, SYNC and
    /// RPDO watch) at the bus clock; what they send waits for the bus.
    pub(super) fn poll_nodes(&mut self) {
        let Some(em) = self.emulated.as_mut() else {
            return;
        };
        #[cfg(feature = "sim")]
        {
            let now = em.wire.now();
            let endpoint = &mut em.endpoint;
            em.segment.poll(now, &mut |f| node_send(endpoint, &f));
        }
        #[cfg(not(feature = "sim"))]
        let _ = em; // no emulated nodes in this build
    }

    /// Let `span` of bus time pass: the nodes do their time-driven work now, the wire runs to
    /// now + `span`; the master's frames are returned.
    pub(super) fn wait_wire(&mut self, span: Nanos) -> Result<Vec<CanFrame>, LinkError> {
        let Some(now) = self.wire_clock() else {
            return Ok(Vec::new());
        };
        self.poll_nodes();
        self.run_wire(Some(now.saturating_add(span)), &mut |_, _| false)
    }

    /// Send the SYNC whose drive-model step belongs at `model_time` (machine time).
    pub(super) fn send_sync(&mut self, model_time: Nanos) -> Result<(), LinkError> {
        if let Some(em) = self.emulated.as_mut() {
            em.sync_times.push_back(model_time);
        }
        self.send(&nmt::sync())
    }

    /// One SDO transfer on the wire (see [`Transport::sdo`]): the client's time-outs run on
    /// the bus clock; a transfer is given up after [`SDO_BOUND`] of bus time.
    pub(super) fn sdo_on_wire(
        &mut self,
        client: &mut SdoClient,
        first: Vec<CanFrame>,
        other_frames: &mut dyn FnMut(Vec<CanFrame>) -> Result<(), LinkError>,
    ) -> Result<Vec<u8>, (Option<SdoError>, String)> {
        let failed = |e: LinkError| (None, e.to_string());
        let start = self.wire_clock().unwrap_or(Nanos::ZERO);
        for f in &first {
            self.send(f).map_err(failed)?;
        }
        let response = u32::from(SDO_TX_BASE) + u32::from(client.node());
        loop {
            if let Some(r) = client.take_result() {
                return r.map_err(|e| {
                    let text = e.to_string();
                    (Some(e), text)
                });
            }
            let now = self.wire_clock().unwrap_or(Nanos::ZERO);
            if now.0.saturating_sub(start.0) > SDO_BOUND.0 {
                return Err((None, "no answer".into()));
            }
            // Until the client's deadline (or the bound), or until its answer came.
            let until = client
                .next_deadline()
                .unwrap_or(start.saturating_add(SDO_BOUND))
                .max(now);
            self.poll_nodes();
            let frames = self
                .run_wire(Some(until), &mut |_, got| {
                    got.iter().any(|f| !f.extended && f.id == response)
                })
                .map_err(failed)?;
            let now = self.wire_clock().unwrap_or(now);
            let mut replies = Vec::new();
            let mut rest = Vec::new();
            for f in frames {
                if !f.extended && f.id == response {
                    replies.extend(client.handle(&f, now));
                } else {
                    rest.push(f);
                }
            }
            other_frames(rest).map_err(failed)?;
            replies.extend(client.poll(now));
            for f in &replies {
                self.send(f).map_err(failed)?;
            }
        }
    }
}

/// An emulated node's frame onto its endpoint (a frame out of range is a warning: the node
/// built it, nothing from outside).
#[cfg(feature = "sim")]
fn node_send(endpoint: &mut VirtualEndpoint, f: &CanFrame) {
    if endpoint.send(f).is_err() {
        tracing::warn!(target: "fieldprobe::link::canopen", "emulated node frame refused: {f:?}");
    }
}

/// The SYNC (COB-ID 0x080, CiA 301).
#[cfg(feature = "sim")]
fn is_sync(f: &CanFrame) -> bool {
    !f.extended && !f.rtr && !f.error && f.id == u32::from(nmt::SYNC_COB)
}
