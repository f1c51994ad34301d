//! In-process CAN bus with SocketCAN's delivery semantics (the Lely approach of testing master
//! and slave on one loop-back network).
//!
//! A [`VirtualCan`] hub hands out [`VirtualEndpoint`]s. A frame sent on one endpoint is queued,
//! in one global send order, on every *other* endpoint whose filters pass it (and on the sender
//! too when it enabled `recv_own_msgs`, like `CAN_RAW_RECV_OWN_MSGS`). Error frames are
//! delivered like data frames but selected by each endpoint's error mask instead of its
//! filters. Endpoints are `Send` and may live on different threads; [`CanBus::recv`] waits on a
//! condition variable.
//!
//! Cost per frame: one mutex lock and one queue push per receiving endpoint; a waiting receiver
//! is woken only if it is actually waiting.
//!
//! # The wire ([`VirtualCan::with_bitrate`])
//!
//! Without a bit rate a frame reaches the other endpoints the moment it is sent. A bus made with
//! a bit rate has a virtual clock ([`VirtualCan::now`]) and behaves like the wire:
//!
//! * A sent frame waits for the bus ([`VirtualEndpoint::send`] at the bus clock,
//!   [`VirtualEndpoint::send_at`] at a later time: a controller told to send then).
//! * When the bus is idle, the frames waiting win it in the order of their arbitration field —
//!   the lowest identifier first ([`timing::arbitration_key`]; equal ones in send order). A
//!   frame on the wire is never interrupted: one that becomes ready meanwhile waits for the
//!   end of it, however low its identifier.
//! * A frame takes its real wire time at the bit rate — its fields with the stuff bits its bits
//!   need, the tail and the intermission ([`timing::frame_bits`]) — and reaches the receivers
//!   at the end of it, with that time ([`VirtualEndpoint::recv_timed`]).
//! * Time passes only when the owner of the bus moves it: [`VirtualCan::advance`] completes the
//!   next frame if it ends by a limit (the owner then lets the receivers answer at that time)
//!   or moves the clock to the limit. No wall clock is read; a run is the same on any machine.
//!
//! Error frames (SocketCAN's reports of a controller, not frames on the wire) take no time:
//! they reach the receivers at once, at the bus clock.

use std::{
    collections::VecDeque,
    sync::{Arc, Condvar, Mutex, MutexGuard},
    time::{Duration, Instant},
};

use super::timing::{self, Bitrate};
use super::{accepts, err_class, CanBus, CanError, CanFilter, CanFrame};
use crate::units::Nanos;

/// Default receive queue length of an endpoint (frames); further frames are dropped and counted,
/// as a full SocketCAN receive buffer drops them.
pub const DEFAULT_QUEUE_FRAMES: usize = 4096;

struct Slot {
    key: u64,
    /// Received frames with the time they were received (the end of their transmission on a
    /// bus with a bit rate, else the bus clock, 0).
    queue: VecDeque<(CanFrame, Nanos)>,
    capacity: usize,
    filters: Vec<CanFilter>,
    error_mask: u32,
    recv_own: bool,
    waiting: bool,
    dropped: u64,
    wake: Arc<Condvar>,
}

/// A frame waiting for the bus.
#[derive(Debug, Clone, Copy)]
struct Queued {
    /// From when it may start.
    ready: Nanos,
    /// Send order (ties of arbitration: equal identifiers).
    seq: u64,
    from: Option<u64>,
    frame: CanFrame,
    key: u32,
    /// Its bit times on the wire ([`timing::frame_bits`]).
    bits: u32,
}

/// The wire of a bus with a bit rate (module documentation, "The wire").
struct Wire {
    bitrate: Bitrate,
    clock: Nanos,
    /// When the last frame on the wire ended.
    idle_at: Nanos,
    pending: Vec<Queued>,
    /// The frame that won arbitration and is being sent: (start, end, frame).
    on_wire: Option<(Nanos, Nanos, Queued)>,
    next_seq: u64,
    /// Bit times of every frame sent so far (bus-load statistics).
    bits: u64,
}

impl Wire {
    /// The transmission that the bus carries next: the one on the wire, else the winner of the
    /// arbitration among the frames ready when the bus is idle.
    fn next(&self) -> Option<(Nanos, Nanos, usize)> {
        if let Some((start, end, _)) = self.on_wire {
            return Some((start, end, usize::MAX));
        }
        let first = self.pending.iter().map(|q| q.ready).min()?;
        let start = first.max(self.idle_at).max(self.clock);
        let (i, q) = self
            .pending
            .iter()
            .enumerate()
            .filter(|(_, q)| q.ready <= start)
            .min_by_key(|(_, q)| (q.key, q.seq))?;
        let end = start.saturating_add(self.bitrate.time_of(u64::from(q.bits)));
        Some((start, end, i))
    }
}

/// One frame at the end of its transmission ([`VirtualCan::advance`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Delivery {
    /// When it ended (and reached the receivers).
    pub at: Nanos,
    /// When it won the bus.
    pub start: Nanos,
    /// The frame.
    pub frame: CanFrame,
}

#[derive(Default)]
struct Hub {
    next_key: u64,
    slots: Vec<Slot>,
    wire: Option<Wire>,
}

impl Hub {
    fn slot_mut(&mut self, key: u64) -> Option<&mut Slot> {
        self.slots.iter_mut().find(|s| s.key == key)
    }

    /// The bus clock (0 without a bit rate).
    fn clock(&self) -> Nanos {
        self.wire.as_ref().map_or(Nanos::ZERO, |w| w.clock)
    }

    /// Queue `frame` on every endpoint that should see it, received at `at`; `from` is the
    /// sender (None: the bus itself, e.g. an injected error frame, goes to everyone).
    fn deliver(&mut self, from: Option<u64>, frame: &CanFrame, at: Nanos) {
        for s in &mut self.slots {
            if Some(s.key) == from && !s.recv_own {
                continue;
            }
            if !accepts(&s.filters, s.error_mask, frame) {
                continue;
            }
            if s.queue.len() >= s.capacity {
                s.dropped += 1;
                continue;
            }
            s.queue.push_back((*frame, at));
            if s.waiting {
                s.wake.notify_one();
            }
        }
    }

    /// Send `frame` from `from`: at once without a wire, else queued for the bus from `ready`
    /// (not before the bus clock).
    fn send(&mut self, from: Option<u64>, frame: &CanFrame, ready: Nanos) {
        match self.wire.as_mut() {
            Some(w) if !frame.error => {
                let seq = w.next_seq;
                w.next_seq += 1;
                w.pending.push(Queued {
                    ready: ready.max(w.clock),
                    seq,
                    from,
                    frame: *frame,
                    key: timing::arbitration_key(frame),
                    bits: timing::frame_bits(frame),
                });
            }
            _ => {
                let at = self.clock();
                self.deliver(from, frame, at);
            }
        }
    }

    /// Complete the next transmission if it ends by `limit` (`None`: whenever it ends);
    /// otherwise move the clock to `limit`, committing a transmission that started by then.
    fn advance(&mut self, limit: Option<Nanos>) -> Option<Delivery> {
        let w = self.wire.as_mut()?;
        let Some((start, end, i)) = w.next() else {
            if let Some(l) = limit {
                w.clock = w.clock.max(l);
            }
            return None;
        };
        if i != usize::MAX {
            if limit.is_some_and(|l| start > l) {
                w.clock = w.clock.max(limit.unwrap_or(w.clock));
                return None;
            }
            // Won the arbitration at `start`: on the wire from now on.
            let q = w.pending.swap_remove(i);
            w.on_wire = Some((start, end, q));
        }
        if limit.is_some_and(|l| end > l) {
            w.clock = w.clock.max(limit.unwrap_or(w.clock));
            return None;
        }
        let (_, _, q) = w.on_wire.take()?;
        w.clock = end;
        w.idle_at = end;
        w.bits += u64::from(q.bits);
        self.deliver(q.from, &q.frame, end);
        Some(Delivery {
            at: end,
            start,
            frame: q.frame,
        })
    }
}

fn lock(hub: &Mutex<Hub>) -> MutexGuard<'_, Hub> {
    // A panic while holding the lock leaves only queues behind, which stay consistent.
    hub.lock().unwrap_or_else(|p| p.into_inner())
}

/// The bus: a cheap handle (clone it freely) from which endpoints are created.
#[derive(Clone, Default)]
pub struct VirtualCan {
    hub: Arc<Mutex<Hub>>,
}

impl std::fmt::Debug for VirtualCan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VirtualCan")
            .field("endpoints", &lock(&self.hub).slots.len())
            .finish()
    }
}

impl VirtualCan {
    /// A new, empty bus without a wire: a frame reaches the others the moment it is sent.
    pub fn new() -> VirtualCan {
        VirtualCan::default()
    }

    /// A new, empty bus with a wire at `bitrate` and its clock at 0 (module documentation,
    /// "The wire").
    pub fn with_bitrate(bitrate: Bitrate) -> VirtualCan {
        let bus = VirtualCan::default();
        lock(&bus.hub).wire = Some(Wire {
            bitrate,
            clock: Nanos::ZERO,
            idle_at: Nanos::ZERO,
            pending: Vec::new(),
            on_wire: None,
            next_seq: 0,
            bits: 0,
        });
        bus
    }

    /// The bit rate of the wire; `None` for a bus without one.
    pub fn bitrate(&self) -> Option<Bitrate> {
        lock(&self.hub).wire.as_ref().map(|w| w.bitrate)
    }

    /// The bus clock (always 0 on a bus without a wire).
    pub fn now(&self) -> Nanos {
        lock(&self.hub).clock()
    }

    /// Complete the next transmission if it ends by `limit`: the frame reaches the receivers
    /// at its end, the clock stands there, and the delivery is returned so that the owner can
    /// let the receivers answer at that time. Otherwise the clock moves to `limit` (a frame
    /// that won the bus by then stays on the wire) and `None` is returned. `None` at once on a
    /// bus without a wire.
    pub fn advance(&self, limit: Nanos) -> Option<Delivery> {
        lock(&self.hub).advance(Some(limit))
    }

    /// Complete the next transmission, whenever it ends; `None` (the clock unchanged) when no
    /// frame waits for the bus.
    pub fn advance_next(&self) -> Option<Delivery> {
        lock(&self.hub).advance(None)
    }

    /// Frames waiting for the bus or on the wire.
    pub fn queued(&self) -> usize {
        lock(&self.hub)
            .wire
            .as_ref()
            .map_or(0, |w| w.pending.len() + usize::from(w.on_wire.is_some()))
    }

    /// Bit times of every frame completed so far (0 without a wire).
    pub fn bits_sent(&self) -> u64 {
        lock(&self.hub).wire.as_ref().map_or(0, |w| w.bits)
    }

    /// A new endpoint: accepts every frame and every error class, does not receive its own
    /// frames, queues up to [`DEFAULT_QUEUE_FRAMES`]. It sees only frames sent after this call.
    pub fn endpoint(&self) -> VirtualEndpoint {
        let mut hub = lock(&self.hub);
        let key = hub.next_key;
        hub.next_key += 1;
        let wake = Arc::new(Condvar::new());
        hub.slots.push(Slot {
            key,
            queue: VecDeque::new(),
            capacity: DEFAULT_QUEUE_FRAMES,
            filters: vec![CanFilter::accept_all()],
            error_mask: err_class::ALL,
            recv_own: false,
            waiting: false,
            dropped: 0,
            wake: wake.clone(),
        });
        VirtualEndpoint {
            hub: self.hub.clone(),
            key,
            wake,
        }
    }

    /// Deliver `frame` to every endpoint (subject to its filters / error mask), as if the bus
    /// itself produced it: e.g. an error frame every controller on the bus reports.
    /// On a bus with a wire it reaches them at the bus clock, without taking the bus.
    pub fn broadcast(&self, frame: &CanFrame) {
        let mut hub = lock(&self.hub);
        let at = hub.clock();
        hub.deliver(None, frame, at);
    }

    /// Number of live endpoints.
    pub fn endpoints(&self) -> usize {
        lock(&self.hub).slots.len()
    }
}

/// One node's connection to a [`VirtualCan`]. Dropping it detaches it from the bus.
pub struct VirtualEndpoint {
    hub: Arc<Mutex<Hub>>,
    key: u64,
    wake: Arc<Condvar>,
}

impl std::fmt::Debug for VirtualEndpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VirtualEndpoint")
            .field("key", &self.key)
            .finish()
    }
}

impl VirtualEndpoint {
    fn with_slot<T>(&self, f: impl FnOnce(&mut Slot) -> T) -> T {
        let mut hub = lock(&self.hub);
        let slot = hub
            .slot_mut(self.key)
            .expect("a live endpoint always has its slot");
        f(slot)
    }

    /// Replace the acceptance filters (`CAN_RAW_FILTER`): a data or remote frame is queued when
    /// any filter passes it; an empty list receives no data frames.
    pub fn set_filters(&mut self, filters: &[CanFilter]) {
        self.with_slot(|s| s.filters = filters.to_vec());
    }

    /// Error classes to receive (`CAN_RAW_ERR_FILTER`; default [`err_class::ALL`], 0 = none).
    pub fn set_error_mask(&mut self, mask: u32) {
        self.with_slot(|s| s.error_mask = mask);
    }

    /// Also receive this endpoint's own transmissions (`CAN_RAW_RECV_OWN_MSGS`).
    pub fn set_recv_own_msgs(&mut self, on: bool) {
        self.with_slot(|s| s.recv_own = on);
    }

    /// Receive queue capacity in frames (at least 1).
    pub fn set_queue_capacity(&mut self, frames: usize) {
        self.with_slot(|s| s.capacity = frames.max(1));
    }

    /// Frames dropped because the receive queue was full.
    pub fn dropped(&self) -> u64 {
        self.with_slot(|s| s.dropped)
    }

    /// Frames waiting in the receive queue.
    pub fn pending(&self) -> usize {
        self.with_slot(|s| s.queue.len())
    }

    /// Send `frame` from `at` on (a bus with a wire: the frame waits for the bus from then,
    /// not before the bus clock; without one it is delivered at once).
    ///
    /// # Errors
    /// [`CanError::Frame`] for a frame out of range ([`CanFrame::validate`]).
    pub fn send_at(&mut self, frame: &CanFrame, at: Nanos) -> Result<(), CanError> {
        frame.validate()?;
        let frame = frame.normalized();
        lock(&self.hub).send(Some(self.key), &frame, at);
        Ok(())
    }

    /// The next received frame with the time it was received, without waiting.
    pub fn recv_timed(&mut self) -> Option<(CanFrame, Nanos)> {
        self.with_slot(|s| s.queue.pop_front())
    }
}

impl CanBus for VirtualEndpoint {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        frame.validate()?;
        let frame = frame.normalized();
        let mut hub = lock(&self.hub);
        let now = hub.clock();
        hub.send(Some(self.key), &frame, now);
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, CanError> {
        if timeout.is_zero() {
            // A poll: no clock to read.
            return Ok(self.recv_timed().map(|(f, _)| f));
        }
        let deadline = Instant::now().checked_add(timeout);
        let mut hub = lock(&self.hub);
        loop {
            let slot = hub
                .slot_mut(self.key)
                .expect("a live endpoint always has its slot");
            if let Some((f, _)) = slot.queue.pop_front() {
                slot.waiting = false;
                return Ok(Some(f));
            }
            let left = match deadline {
                Some(d) => d.saturating_duration_since(Instant::now()),
                None => Duration::MAX,
            };
            if left.is_zero() {
                slot.waiting = false;
                return Ok(None);
            }
            slot.waiting = true;
            hub = self
                .wake
                .wait_timeout(hub, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }

    fn describe(&self) -> String {
        format!("virtual #{}", self.key)
    }

    fn log_interface(&self) -> String {
        super::candump::EMU_INTERFACE.to_string()
    }
}

impl Drop for VirtualEndpoint {
    fn drop(&mut self) {
        let key = self.key;
        lock(&self.hub).slots.retain(|s| s.key != key);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::can::timing::wire_time;

    fn bus() -> (
        VirtualCan,
        VirtualEndpoint,
        VirtualEndpoint,
        VirtualEndpoint,
    ) {
        let hub = VirtualCan::with_bitrate(Bitrate::new(500_000).unwrap());
        let (a, b, rx) = (hub.endpoint(), hub.endpoint(), hub.endpoint());
        (hub, a, b, rx)
    }

    #[test]
    fn frames_pending_together_go_lowest_identifier_first_each_taking_its_wire_time() {
        let (hub, mut a, mut b, mut rx) = bus();
        let high = CanFrame::new(0x281, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        let low = CanFrame::new(0x181, &[9; 8]).unwrap();
        a.send(&high).unwrap();
        b.send(&low).unwrap();
        assert_eq!(rx.recv_timed(), None, "nothing before the bus moved");
        let first = hub.advance_next().unwrap();
        let second = hub.advance_next().unwrap();
        assert_eq!(hub.advance_next(), None);
        let t_low = wire_time(&low, Bitrate::new(500_000).unwrap());
        let t_high = wire_time(&high, Bitrate::new(500_000).unwrap());
        assert_eq!((first.frame, first.at), (low, t_low));
        assert_eq!(
            (second.frame, second.start, second.at),
            (high, t_low, Nanos(t_low.0 + t_high.0))
        );
        assert_eq!(rx.recv_timed(), Some((low, t_low)));
        assert_eq!(rx.recv_timed(), Some((high, second.at)));
        // The senders do not see their own frames, each sees the other's.
        assert_eq!(a.recv_timed().map(|x| x.0), Some(low));
        assert_eq!(b.recv_timed().map(|x| x.0), Some(high));
        assert_eq!(hub.now(), second.at);
    }

    #[test]
    fn a_frame_on_the_wire_is_not_interrupted_by_a_lower_identifier() {
        let (hub, mut a, mut b, _rx) = bus();
        let hb = CanFrame::new(0x701, &[5]).unwrap();
        a.send(&hb).unwrap();
        // Half way through the heartbeat the SYNC becomes ready: it waits for the end.
        let half = Nanos(wire_time(&hb, hub.bitrate().unwrap()).0 / 2);
        assert_eq!(hub.advance(half), None);
        assert_eq!(hub.now(), half);
        b.send(&CanFrame::new(0x080, &[]).unwrap()).unwrap();
        let d = hub.advance_next().unwrap();
        assert_eq!(d.frame.id, 0x701);
        let s = hub.advance_next().unwrap();
        assert_eq!((s.frame.id, s.start), (0x080, d.at));
    }

    #[test]
    fn send_at_waits_until_then_and_the_clock_moves_only_on_advance() {
        let (hub, mut a, _b, mut rx) = bus();
        let sync = CanFrame::new(0x080, &[]).unwrap();
        a.send_at(&sync, Nanos(1_000_000)).unwrap();
        assert_eq!(hub.queued(), 1);
        assert_eq!(hub.advance(Nanos(999_999)), None);
        assert_eq!(hub.now(), Nanos(999_999));
        let d = hub.advance(Nanos(2_000_000)).unwrap();
        assert_eq!(d.start, Nanos(1_000_000));
        assert_eq!(rx.recv_timed(), Some((sync, d.at)));
        // Nothing queued: the clock goes to the limit, never beyond it.
        assert_eq!(hub.advance(Nanos(3_000_000)), None);
        assert_eq!(hub.now(), Nanos(3_000_000));
        assert_eq!(hub.advance_next(), None);
        assert_eq!(hub.now(), Nanos(3_000_000));
        assert_eq!(hub.bits_sent(), u64::from(timing::frame_bits(&sync)));
    }

    #[test]
    fn without_a_wire_frames_arrive_at_once() {
        let hub = VirtualCan::new();
        let (mut a, mut rx) = (hub.endpoint(), hub.endpoint());
        a.send_at(&CanFrame::new(0x181, &[1]).unwrap(), Nanos(5))
            .unwrap();
        assert_eq!(rx.recv_timed().map(|x| x.1), Some(Nanos::ZERO));
        assert_eq!(hub.advance(Nanos(10)), None);
        assert_eq!(hub.now(), Nanos::ZERO);
        assert_eq!(hub.bitrate(), None);
    }
}
