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

use std::{
    collections::VecDeque,
    sync::{Arc, Condvar, Mutex, MutexGuard},
    time::{Duration, Instant},
};

use super::{accepts, err_class, CanBus, CanError, CanFilter, CanFrame};

/// Default receive queue length of an endpoint (frames); further frames are dropped and counted,
/// as a full SocketCAN receive buffer drops them.
pub const DEFAULT_QUEUE_FRAMES: usize = 4096;

struct Slot {
    key: u64,
    queue: VecDeque<CanFrame>,
    capacity: usize,
    filters: Vec<CanFilter>,
    error_mask: u32,
    recv_own: bool,
    waiting: bool,
    dropped: u64,
    wake: Arc<Condvar>,
}

#[derive(Default)]
struct Hub {
    next_key: u64,
    slots: Vec<Slot>,
}

impl Hub {
    fn slot_mut(&mut self, key: u64) -> Option<&mut Slot> {
        self.slots.iter_mut().find(|s| s.key == key)
    }

    /// Queue `frame` on every endpoint that should see it; `from` is the sender (None: the bus
    /// itself, e.g. an injected error frame, goes to everyone).
    fn deliver(&mut self, from: Option<u64>, frame: &CanFrame) {
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
            s.queue.push_back(*frame);
            if s.waiting {
                s.wake.notify_one();
            }
        }
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
    /// A new, empty bus.
    pub fn new() -> VirtualCan {
        VirtualCan::default()
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
    pub fn broadcast(&self, frame: &CanFrame) {
        lock(&self.hub).deliver(None, frame);
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
}

impl CanBus for VirtualEndpoint {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        frame.validate()?;
        let frame = frame.normalized();
        lock(&self.hub).deliver(Some(self.key), &frame);
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, CanError> {
        let deadline = Instant::now().checked_add(timeout);
        let mut hub = lock(&self.hub);
        loop {
            let slot = hub
                .slot_mut(self.key)
                .expect("a live endpoint always has its slot");
            if let Some(f) = slot.queue.pop_front() {
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
