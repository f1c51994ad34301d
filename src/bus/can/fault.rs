//! [`FaultBus`]: wrap any [`CanBus`] and inject faults (in the manner of smoltcp's
//! `phy/fault_injector.rs`): lost frames in either direction, late delivery, error frames and
//! bus-off.
//!
//! Knobs (all off after [`FaultBus::new`]):
//! - [`drop_nth_sent`](FaultBus::drop_nth_sent) / [`drop_nth_received`](FaultBus::drop_nth_received):
//!   lose the n-th frame from now on (1 = the next one), once;
//! - [`drop_sent_where`](FaultBus::drop_sent_where) / [`drop_received_where`](FaultBus::drop_received_where):
//!   lose every frame a predicate selects (e.g. by COB-ID) until [`clear_faults`](FaultBus::clear_faults);
//! - [`delay_received_calls`](FaultBus::delay_received_calls) / [`delay_received_for`](FaultBus::delay_received_for):
//!   a frame the inner bus delivers during `recv` call *c* is returned at the earliest by call
//!   *c + k*, and not before `d` has passed since it arrived; order is kept;
//! - [`inject_rx`](FaultBus::inject_rx) / [`inject_error`](FaultBus::inject_error): the next
//!   `recv` returns this frame (before anything else);
//! - [`go_bus_off`](FaultBus::go_bus_off): queues a bus-off error frame; until
//!   [`recover`](FaultBus::recover) every send fails with [`CanError::BusOff`] and frames from
//!   the inner bus are discarded (a bus-off controller neither sends nor receives). `recover`
//!   queues a "controller restarted" error frame, as SocketCAN reports a restart.
//!
//! A frame lost on send is reported as sent (`Ok`): the sender cannot tell, as on a real bus
//! where the frame is lost behind the transceiver.

use std::{
    collections::VecDeque,
    time::{Duration, Instant},
};

use super::{err_class, CanBus, CanError, CanFrame};

type Predicate = Box<dyn FnMut(&CanFrame) -> bool + Send>;

/// What a [`FaultBus`] did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultStats {
    /// Frames handed to the inner bus.
    pub sent: u64,
    /// Frames lost on send (n-th or predicate).
    pub sent_dropped: u64,
    /// Sends refused because of bus-off.
    pub sent_refused_bus_off: u64,
    /// Frames returned by `recv` (injected ones included).
    pub received: u64,
    /// Frames lost on receive (n-th or predicate).
    pub received_dropped: u64,
    /// Frames from the inner bus discarded while bus-off.
    pub discarded_bus_off: u64,
}

struct Delayed {
    frame: CanFrame,
    due_call: u64,
    due_at: Instant,
}

/// A [`CanBus`] with fault knobs around another one (see the module docs).
pub struct FaultBus<B: CanBus> {
    inner: B,
    drop_sent_nth: Option<u64>,
    drop_recv_nth: Option<u64>,
    drop_sent_if: Option<Predicate>,
    drop_recv_if: Option<Predicate>,
    delay_calls: u64,
    delay_time: Duration,
    recv_calls: u64,
    delayed: VecDeque<Delayed>,
    injected: VecDeque<CanFrame>,
    bus_off: bool,
    stats: FaultStats,
}

impl<B: CanBus> std::fmt::Debug for FaultBus<B> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaultBus")
            .field("inner", &self.inner.describe())
            .field("bus_off", &self.bus_off)
            .field("stats", &self.stats)
            .finish()
    }
}

/// Count down an n-th knob; true when this is the n-th.
fn hit_nth(knob: &mut Option<u64>) -> bool {
    match knob {
        Some(1) => {
            *knob = None;
            true
        }
        Some(n) => {
            *n -= 1;
            false
        }
        None => false,
    }
}

impl<B: CanBus> FaultBus<B> {
    /// Wrap `inner` with every knob off.
    pub fn new(inner: B) -> FaultBus<B> {
        FaultBus {
            inner,
            drop_sent_nth: None,
            drop_recv_nth: None,
            drop_sent_if: None,
            drop_recv_if: None,
            delay_calls: 0,
            delay_time: Duration::ZERO,
            recv_calls: 0,
            delayed: VecDeque::new(),
            injected: VecDeque::new(),
            bus_off: false,
            stats: FaultStats::default(),
        }
    }

    /// The wrapped bus.
    pub fn inner(&self) -> &B {
        &self.inner
    }

    /// The wrapped bus, mutably (bypassing the knobs).
    pub fn inner_mut(&mut self) -> &mut B {
        &mut self.inner
    }

    /// Unwrap.
    pub fn into_inner(self) -> B {
        self.inner
    }

    /// Counters.
    pub fn stats(&self) -> FaultStats {
        self.stats
    }

    /// Lose the `n`-th frame sent from now on (1 = the next); `0` disarms.
    pub fn drop_nth_sent(&mut self, n: u64) {
        self.drop_sent_nth = (n > 0).then_some(n);
    }

    /// Lose the `n`-th frame the inner bus delivers from now on (1 = the next); `0` disarms.
    pub fn drop_nth_received(&mut self, n: u64) {
        self.drop_recv_nth = (n > 0).then_some(n);
    }

    /// Lose every sent frame for which `pred` is true (e.g. `|f| f.id == 0x605`).
    pub fn drop_sent_where(&mut self, pred: impl FnMut(&CanFrame) -> bool + Send + 'static) {
        self.drop_sent_if = Some(Box::new(pred));
    }

    /// Lose every received frame for which `pred` is true.
    pub fn drop_received_where(&mut self, pred: impl FnMut(&CanFrame) -> bool + Send + 'static) {
        self.drop_recv_if = Some(Box::new(pred));
    }

    /// Deliver each received frame `k` `recv` calls late (0: off).
    pub fn delay_received_calls(&mut self, k: u64) {
        self.delay_calls = k;
    }

    /// Deliver each received frame at the earliest `d` after it arrived (ZERO: off).
    pub fn delay_received_for(&mut self, d: Duration) {
        self.delay_time = d;
    }

    /// Disarm every drop and delay knob (frames already delayed are still delivered).
    pub fn clear_faults(&mut self) {
        self.drop_sent_nth = None;
        self.drop_recv_nth = None;
        self.drop_sent_if = None;
        self.drop_recv_if = None;
        self.delay_calls = 0;
        self.delay_time = Duration::ZERO;
    }

    /// The next `recv` returns `frame` (after frames injected earlier).
    pub fn inject_rx(&mut self, frame: CanFrame) {
        self.injected.push_back(frame);
    }

    /// The next `recv` returns an error frame of SocketCAN error class `class`
    /// ([`err_class`]) with `data`.
    pub fn inject_error(&mut self, class: u32, data: &[u8]) {
        self.inject_rx(CanFrame::error_frame(class, data));
    }

    /// Go bus-off: queue a bus-off error frame; sends fail until [`recover`](Self::recover).
    pub fn go_bus_off(&mut self) {
        if !self.bus_off {
            self.bus_off = true;
            self.inject_error(err_class::BUSOFF, &[]);
        }
    }

    /// Leave bus-off: queue a "controller restarted" error frame.
    pub fn recover(&mut self) {
        if self.bus_off {
            self.bus_off = false;
            self.inject_error(err_class::RESTARTED, &[]);
        }
    }

    /// Is the bus off?
    pub fn is_bus_off(&self) -> bool {
        self.bus_off
    }

    fn pop_due(&mut self, now: Instant) -> Option<CanFrame> {
        let d = self.delayed.front()?;
        if d.due_call <= self.recv_calls && d.due_at <= now {
            self.delayed.pop_front().map(|d| d.frame)
        } else {
            None
        }
    }

    fn deliver(&mut self, f: CanFrame) -> Option<CanFrame> {
        self.stats.received += 1;
        Some(f)
    }
}

impl<B: CanBus> CanBus for FaultBus<B> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        if self.bus_off {
            self.stats.sent_refused_bus_off += 1;
            return Err(CanError::BusOff);
        }
        let by_nth = hit_nth(&mut self.drop_sent_nth);
        let by_pred = self.drop_sent_if.as_mut().is_some_and(|p| p(frame));
        if by_nth || by_pred {
            self.stats.sent_dropped += 1;
            return Ok(());
        }
        self.inner.send(frame)?;
        self.stats.sent += 1;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, CanError> {
        self.recv_calls += 1;
        if let Some(f) = self.injected.pop_front() {
            return Ok(self.deliver(f));
        }
        let start = Instant::now();
        let deadline = start.checked_add(timeout);
        loop {
            let now = Instant::now();
            if let Some(f) = self.pop_due(now) {
                return Ok(self.deliver(f));
            }
            let mut wait = match deadline {
                Some(d) => d.saturating_duration_since(now),
                None => Duration::MAX,
            };
            // Wake up when the first delayed frame comes due in this call.
            if let Some(d) = self.delayed.front() {
                if d.due_call <= self.recv_calls {
                    wait = wait.min(d.due_at.saturating_duration_since(now));
                }
            }
            match self.inner.recv(wait)? {
                Some(f) => {
                    if self.bus_off {
                        self.stats.discarded_bus_off += 1;
                        continue;
                    }
                    let by_nth = hit_nth(&mut self.drop_recv_nth);
                    let by_pred = self.drop_recv_if.as_mut().is_some_and(|p| p(&f));
                    if by_nth || by_pred {
                        self.stats.received_dropped += 1;
                        continue;
                    }
                    if self.delay_calls == 0 && self.delay_time.is_zero() && self.delayed.is_empty()
                    {
                        return Ok(self.deliver(f));
                    }
                    let arrived = Instant::now();
                    self.delayed.push_back(Delayed {
                        frame: f,
                        due_call: self.recv_calls + self.delay_calls,
                        due_at: arrived + self.delay_time,
                    });
                }
                None => {
                    let now = Instant::now();
                    if deadline.is_some_and(|d| now >= d) {
                        return Ok(self.pop_due(now).and_then(|f| self.deliver(f)));
                    }
                }
            }
        }
    }

    fn describe(&self) -> String {
        format!("fault({})", self.inner.describe())
    }

    fn log_interface(&self) -> String {
        self.inner.log_interface()
    }

    fn malformed_dropped(&self) -> u64 {
        self.inner.malformed_dropped()
    }
}
