//! Serve an emulated [`Segment`] on a real Linux network interface (e.g. one end of a veth
//! pair), so a stock EtherCAT master (ethercrab's `std::tx_rx_task`, SOEM) can talk to it
//! over a raw socket.
//!
//! The socket is the master's ([`RawPort`], `crate::bus::ethercat::raw`: an AF_PACKET/SOCK_RAW
//! socket bound to the interface, protocol ETH_P_ALL); frames whose EtherType is not 0x88A4 are
//! ignored, and so are our own replies, which an ETH_P_ALL socket sees again as outgoing
//! traffic: they are told apart by their bytes ([`SentFrames`], the last frames sent), not by
//! the source MAC — a real ESC processes an EtherCAT frame whatever its source MAC (a master's
//! may have the locally administered bit set: KickCAT's fixed address, every veth address) and
//! *sets* that bit in the frame it returns (ETG.1000.4; Beckhoff ESC datasheet, frame
//! processing), which is how a master tells its returned frames from its sent ones. Every other
//! frame goes through [`Segment::process_frame`] and is sent back on the same interface.
//!
//! # Time
//!
//! The segment runs on the serve loop's clock ([`Clock`]; on an interface [`MonotonicClock`],
//! CLOCK_MONOTONIC since the loop started): every frame is processed at the clock's `now`
//! (the DC system time 0x0910 of each device = that time + its 0x0920 offset), and in
//! [`Stepping::OwnClock`](super::segment::Stepping::OwnClock) the loop also wakes for the
//! devices' SYNC0 pulses and watchdog deadlines ([`Segment::poll_timeout`],
//! [`Segment::handle_timeout`]) between frames. A receiver thread hands the frames to the loop
//! through a bounded queue, so the loop can wait for "a frame or the next deadline" with
//! sub-millisecond resolution. The loop itself ([`serve_loop`]) is generic over the clock and
//! the frame transport ([`FrameIo`]), so tests run it on virtual time. Waits are at most
//! [`POLL_INTERVAL`], so `stop` / the deadline are noticed promptly.
//!
//! Needs CAP_NET_RAW (e.g. root inside an unprivileged `unshare -rn` namespace).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use super::segment::{Segment, SegmentEvent};
use crate::bus::ethercat::raw::is_ethercat;
pub use crate::bus::ethercat::raw::{RawError, RawPort, ETHERTYPE_ETHERCAT};

/// Longest wait for a frame before `stop` / the deadline is checked again (the receive timeout
/// of [`RawPort::open`]).
pub const POLL_INTERVAL: Duration = crate::bus::ethercat::raw::RECEIVE_TIMEOUT;

/// Frames the receiver thread may queue for the serve loop (then it waits: the kernel's socket
/// buffer takes the rest, and drops what does not fit, like a full NIC ring).
const FRAME_QUEUE: usize = 64;

/// A monotonic clock in ns since an arbitrary origin: the time base of [`serve_loop`].
pub trait Clock {
    /// The present, ns.
    fn now_ns(&self) -> u64;
}

/// CLOCK_MONOTONIC (`std::time::Instant`), ns since the clock was made: the emulator's own
/// clock on an interface.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock(Instant);

impl MonotonicClock {
    /// A clock reading 0 now.
    pub fn start() -> Self {
        Self(Instant::now())
    }

    /// Clock time of `instant` (0 if it lies before the origin).
    pub fn at(&self, instant: Instant) -> u64 {
        u64::try_from(instant.saturating_duration_since(self.0).as_nanos()).unwrap_or(u64::MAX)
    }
}

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        self.at(Instant::now())
    }
}

/// The frame transport of [`serve_loop`]: Ethernet frames in and out.
pub trait FrameIo {
    /// The next received Ethernet frame (any EtherType), waiting at most `timeout`; `Ok(None)`
    /// if none came.
    fn recv(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, RawError>;
    /// Send one Ethernet frame.
    fn send(&mut self, frame: &[u8]) -> Result<(), RawError>;
}

/// What [`serve`] saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServeStats {
    /// EtherCAT frames processed and answered.
    pub answered: u64,
    /// EtherCAT frames skipped because they are our own replies seen again (outgoing).
    pub skipped_processed: u64,
    /// Frames with another EtherType.
    pub skipped_other: u64,
    /// EtherCAT frames the segment rejected as invalid (dropped, like a real segment would).
    pub invalid: u64,
}

/// How many of the last frames sent [`SentFrames`] remembers: more than the frames that can be
/// in flight between a send and the socket seeing it again (one per received frame, answered
/// in order).
const SENT_REMEMBERED: usize = 16;

/// The last frames the serve loop sent, to recognise them when the ETH_P_ALL socket sees them
/// again as outgoing traffic (a packet socket's own sends come back to it; AF_PACKET's packet
/// type would tell, but the socket layer does not report it). The buffers are kept, so
/// remembering allocates nothing once they have grown.
#[derive(Debug, Default)]
pub struct SentFrames {
    frames: Vec<Vec<u8>>,
    used: [bool; SENT_REMEMBERED],
    next: usize,
}

impl SentFrames {
    /// Remember `frame` as sent.
    pub fn remember(&mut self, frame: &[u8]) {
        if self.frames.len() < SENT_REMEMBERED {
            self.frames.resize_with(SENT_REMEMBERED, Vec::new);
        }
        let b = &mut self.frames[self.next];
        b.clear();
        b.extend_from_slice(frame);
        self.used[self.next] = true;
        self.next = (self.next + 1) % SENT_REMEMBERED;
    }

    /// Is `frame` one we sent (and not yet recognised)? Each sent frame is recognised once.
    pub fn take(&mut self, frame: &[u8]) -> bool {
        for (k, b) in self.frames.iter().enumerate() {
            if self.used[k] && b.as_slice() == frame {
                self.used[k] = false;
                return true;
            }
        }
        false
    }
}

/// Serving a segment: the emulator's side of the master's [`RawPort`] (the port and its
/// receives are defined with the master, `crate::bus::ethercat::raw`; serving needs the emulated
/// [`Segment`], so it is here, with the `sim` feature).
impl RawPort {
    /// Serve `segment` until `stop` is set or `deadline` passes (whichever first); the
    /// segment's events are logged only (see [`Self::serve_with_events`]).
    pub fn serve(
        &mut self,
        segment: &mut Segment,
        stop: &AtomicBool,
        deadline: Option<Instant>,
    ) -> Result<ServeStats, RawError> {
        self.serve_with_events(segment, stop, deadline, |_| {})
    }

    /// Serve `segment` on this interface with [`serve_loop`] on a [`MonotonicClock`] started
    /// now, until `stop` is set or `deadline` passes; `on_event` gets every [`SegmentEvent`]
    /// (SYNC0 activation, watchdog expiry, …) as it is noticed.
    ///
    /// Fails if a receive or send fails for another reason than the receive timeout.
    pub fn serve_with_events(
        &mut self,
        segment: &mut Segment,
        stop: &AtomicBool,
        deadline: Option<Instant>,
        on_event: impl FnMut(&SegmentEvent),
    ) -> Result<ServeStats, RawError> {
        tracing::info!(
            iface = self.iface.as_str(),
            devices = segment.len(),
            stepping = ?segment.stepping(),
            "serving emulated EtherCAT segment"
        );
        let clock = MonotonicClock::start();
        let deadline_ns = deadline.map(|d| clock.at(d));
        let done = AtomicBool::new(false);
        let iface = self.iface.as_str();
        let rx = &mut self.rx;
        let tx = &mut self.tx;
        std::thread::scope(|scope| {
            let (frames_tx, frames_rx) = mpsc::sync_channel(FRAME_QUEUE);
            let done_ref = &done;
            scope.spawn(move || receive_frames(rx, &frames_tx, done_ref));
            let mut io = QueuedIo {
                iface,
                frames: frames_rx,
                tx,
            };
            let r = serve_loop(&mut io, &clock, segment, stop, deadline_ns, on_event);
            done.store(true, Ordering::Relaxed);
            drop(io); // the receiver thread's next hand-over fails and it ends
            r
        })
    }
}

/// The receiver thread: every frame from `rx` into `frames` until `done` is set or the loop
/// went away; a receive error is handed over and ends the thread.
fn receive_frames(
    rx: &mut Box<dyn pnet_datalink::DataLinkReceiver>,
    frames: &mpsc::SyncSender<std::io::Result<Vec<u8>>>,
    done: &AtomicBool,
) {
    while !done.load(Ordering::Relaxed) {
        match rx.next() {
            Ok(frame) => {
                if frames.send(Ok(frame.to_vec())).is_err() {
                    return;
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::Interrupted
                ) => {}
            Err(e) => {
                let _ = frames.send(Err(e));
                return;
            }
        }
    }
}

/// [`FrameIo`] of an interface: frames from the receiver thread's queue, sent directly.
struct QueuedIo<'a> {
    iface: &'a str,
    frames: mpsc::Receiver<std::io::Result<Vec<u8>>>,
    tx: &'a mut Box<dyn pnet_datalink::DataLinkSender>,
}

impl FrameIo for QueuedIo<'_> {
    fn recv(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, RawError> {
        match self.frames.recv_timeout(timeout) {
            Ok(Ok(frame)) => Ok(Some(frame)),
            Ok(Err(source)) => Err(RawError::Receive {
                iface: self.iface.to_string(),
                source,
            }),
            Err(mpsc::RecvTimeoutError::Timeout) => Ok(None),
            Err(mpsc::RecvTimeoutError::Disconnected) => Err(RawError::Receive {
                iface: self.iface.to_string(),
                source: std::io::Error::other("the receiver thread ended"),
            }),
        }
    }

    fn send(&mut self, frame: &[u8]) -> Result<(), RawError> {
        let error = |source| RawError::Send {
            iface: self.iface.to_string(),
            source,
        };
        match self.tx.send_to(frame, None) {
            Some(Ok(())) => Ok(()),
            Some(Err(source)) => Err(error(source)),
            None => Err(error(std::io::Error::other(
                "send_to not supported by the channel",
            ))),
        }
    }
}

/// Serve `segment` over `io` on `clock` until `stop` is set or the clock reaches
/// `deadline_ns`: wait for a frame or the segment's next deadline
/// ([`Segment::poll_timeout`], at most [`POLL_INTERVAL`]), run what is due
/// ([`Segment::handle_timeout`]), process an EtherCAT frame at the clock's `now` and send it
/// back. Frames of other EtherTypes, our own replies seen again ([`SentFrames`]) and frames the
/// segment rejects are not answered (counted in [`ServeStats`]). `on_event` gets the segment's
/// events.
pub fn serve_loop(
    io: &mut impl FrameIo,
    clock: &impl Clock,
    segment: &mut Segment,
    stop: &AtomicBool,
    deadline_ns: Option<u64>,
    mut on_event: impl FnMut(&SegmentEvent),
) -> Result<ServeStats, RawError> {
    let poll_ns = u64::try_from(POLL_INTERVAL.as_nanos()).unwrap_or(u64::MAX);
    let mut stats = ServeStats::default();
    let mut sent = SentFrames::default();
    loop {
        let now = clock.now_ns();
        if stop.load(Ordering::Relaxed) || deadline_ns.is_some_and(|d| now >= d) {
            return Ok(stats);
        }
        segment.handle_timeout(now);
        for e in segment.take_events() {
            on_event(&e);
        }
        let mut wait = poll_ns;
        if let Some(t) = segment.poll_timeout(now) {
            wait = wait.min(t.saturating_sub(now));
        }
        if let Some(d) = deadline_ns {
            wait = wait.min(d.saturating_sub(now));
        }
        let Some(mut frame) = io.recv(Duration::from_nanos(wait))? else {
            continue;
        };
        if !is_ethercat(&frame) {
            stats.skipped_other += 1;
            continue;
        }
        if sent.take(&frame) {
            stats.skipped_processed += 1;
            continue;
        }
        match segment.process_frame(&mut frame, clock.now_ns()) {
            Ok(true) => {}
            Ok(false) => continue, // dropped on purpose (fault knob)
            Err(e) => {
                tracing::debug!(error = %e, "invalid EtherCAT frame dropped");
                stats.invalid += 1;
                continue;
            }
        }
        sent.remember(&frame);
        io.send(&frame)?;
        stats.answered += 1;
        for e in segment.take_events() {
            on_event(&e);
        }
    }
}

/// Open `iface` ([`RawPort::open`]) and serve `segment` on it ([`RawPort::serve`]) until
/// `stop` is set or `deadline` passes.
pub fn serve(
    iface: &str,
    segment: &mut Segment,
    stop: &AtomicBool,
    deadline: Option<Instant>,
) -> Result<ServeStats, RawError> {
    RawPort::open(iface)?.serve(segment, stop, deadline)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_classification() {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&[0x88, 0xA4, 0, 0]);
        assert!(is_ethercat(&f));
        // A master's frame with the locally administered bit set is an EtherCAT frame like any.
        f[6] |= 0x02;
        assert!(is_ethercat(&f));
        let mut sent = SentFrames::default();
        assert!(!sent.take(&f));
        sent.remember(&f);
        assert!(sent.take(&f), "our own frame, seen again");
        assert!(!sent.take(&f), "recognised once");
        f[12] = 0x08;
        f[13] = 0x00;
        assert!(!is_ethercat(&f));
        assert!(!is_ethercat(&[0; 10]));
    }

    /// Frames in from a list, frames out into a list; the clock stands still.
    struct ListIo {
        incoming: Vec<Vec<u8>>,
        sent: Vec<Vec<u8>>,
    }

    impl FrameIo for ListIo {
        fn recv(&mut self, _timeout: Duration) -> Result<Option<Vec<u8>>, RawError> {
            Ok(if self.incoming.is_empty() {
                None
            } else {
                Some(self.incoming.remove(0))
            })
        }
        fn send(&mut self, frame: &[u8]) -> Result<(), RawError> {
            self.sent.push(frame.to_vec());
            Ok(())
        }
    }

    /// A clock that advances 1 µs every time it is read, so the loop reaches its deadline.
    struct Ticking(std::cell::Cell<u64>);
    impl Clock for Ticking {
        fn now_ns(&self) -> u64 {
            let t = self.0.get() + 1_000;
            self.0.set(t);
            t
        }
    }

    /// A master's frame (one BRD of register 0x0000, 1 byte): Ethernet II to broadcast from
    /// `src`, EtherCAT header (length 13, type 1), datagram header, data, working counter.
    fn brd_frame(src: [u8; 6]) -> Vec<u8> {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&src);
        f.extend_from_slice(&[0x88, 0xA4]);
        f.extend_from_slice(&(13u16 | (1 << 12)).to_le_bytes());
        f.extend_from_slice(&[0x07, 0x00, 0, 0, 0, 0, 1, 0, 0, 0, 0x00, 0, 0]);
        f.resize(60, 0);
        f
    }

    #[test]
    fn returned_frames_have_the_locally_administered_bit_set() {
        // ETG.1000.4 / Beckhoff ESC datasheet (frame processing): the ESC sets bit 1 of the
        // first source-MAC byte in every frame it processes; a master's own address (ethercrab
        // 10:10:10:10:10:10) comes back as 12:10:10:10:10:10, one that has the bit already
        // (KickCAT, any veth address) keeps it.
        let mut seg = Segment::new(Vec::new(), 0);
        let stop = AtomicBool::new(false);
        let mut io = ListIo {
            incoming: vec![brd_frame([0x10; 6]), brd_frame([0x02, 0, 0, 0, 0, 0x01])],
            sent: Vec::new(),
        };
        let clock = Ticking(std::cell::Cell::new(0));
        let stats =
            serve_loop(&mut io, &clock, &mut seg, &stop, Some(1_000_000), |_| {}).expect("serve");
        assert_eq!(stats.answered, 2);
        assert_eq!(io.sent.len(), 2, "both frames answered");
        assert_eq!(&io.sent[0][6..12], &[0x12, 0x10, 0x10, 0x10, 0x10, 0x10]);
        assert_eq!(&io.sent[1][6..12], &[0x02, 0, 0, 0, 0, 0x01]);
        // Everything else but the source MAC is the frame as processed (no device: BRD WKC 0).
        assert_eq!(&io.sent[0][12..], &brd_frame([0x10; 6])[12..]);
    }

    #[test]
    fn unknown_interface_is_named() {
        let mut seg = Segment::new(Vec::new(), 0);
        let stop = AtomicBool::new(false);
        let e = serve("no-such-if0", &mut seg, &stop, Some(Instant::now())).unwrap_err();
        assert!(e.to_string().contains("no-such-if0"), "{e}");
    }
}
