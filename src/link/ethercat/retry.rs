//! Frames in flight on an interface (`ethercat:IFACE`) and their retries.
//!
//! A real master repeats a datagram whose frame did not come back in time: SOEM's
//! `ec_srconfirm` sends the frame again every `EC_TIMEOUTRET` until its overall timeout, IgH
//! re-queues a timed-out datagram. A device emulator on a busy machine, a noisy cable (the ESC
//! drops a frame whose CRC fails) or a switch's queue can delay or lose one frame in a
//! thousand; a start-up that gives up on the first one fails at random (`scan` did, 2 of 20
//! times against 9 emulated devices under CPU load). The wire end keeps every frame it sent
//! until its reply is in ([`InFlight`]) and sends it again, byte for byte, every
//! [`Policy::interval`] up to [`Policy::tries`] times; then it gives up and says what
//! happened ([`GaveUp`]): which datagram, to which device, how long, how many tries, and
//! whether anything on the wire had answered before.
//!
//! Process data is never repeated: a frame with a logical datagram (LRD / LWR / LRW) belongs to
//! its cycle ([`CYCLIC`]: one try); a late cycle is a lost cycle, reported as such.
//!
//! A reply is matched to its frame by the first datagram's command, index, ADO and length (the
//! ADP of auto-increment and broadcast datagrams changes on the way). A reply for no frame in
//! flight — the late answer to a frame already repeated and answered, or to one given up — is
//! not handed to the master: ethercrab reuses its indices, and a stale reply must never complete
//! a newer frame.

use std::fmt;
use std::time::{Duration, Instant};

use crate::bus::ethercat::wire::{Addressing, Command, Frame, MAX_ETHERNET_FRAME};

/// When a frame is sent again and when it is given up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Policy {
    /// Wait for the reply before the frame is sent again (or given up, after the last try).
    pub interval: Duration,
    /// Sends in all (1: never repeated).
    pub tries: u32,
}

impl Policy {
    /// Longest wait for a reply, all tries together.
    pub fn total(&self) -> Duration {
        self.interval * self.tries
    }
}

/// Frames without process data (start-up, mailbox, register access): sent again every 20 ms,
/// ten times at most (200 ms in all). A wire round trip is tens of µs, a device emulator on a
/// loaded machine answered within a few ms; SOEM repeats every 2 ms up to 20 ms for start-up
/// reads (`EC_TIMEOUTRET`, `EC_TIMEOUTSAFE`), a pace a scheduler-delayed emulator cannot keep.
pub const ACYCLIC: Policy = Policy {
    interval: Duration::from_millis(20),
    tries: 10,
};

/// Process-data frames: one try, lost after 30 ms (the link's PDU timeout before retries
/// existed; the cycle reports the loss).
pub const CYCLIC: Policy = Policy {
    interval: Duration::from_millis(30),
    tries: 1,
};

/// What identifies a frame's reply: the first datagram's command, index, ADO and length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Key {
    command: u8,
    index: u8,
    ado: u16,
    len: usize,
}

/// The first datagram of `frame`, and whether any datagram is logical (process data).
fn key_of(frame: &[u8]) -> Option<(Key, bool)> {
    let f = Frame::parse(frame).ok()?;
    let mut logical = false;
    let mut first = None;
    for d in f.datagrams() {
        logical |= d.command.addressing() == Addressing::Logical;
        if first.is_none() {
            first = Some(Key {
                command: d.command.code(),
                index: d.index,
                ado: d.ado(),
                len: d.data.len(),
            });
        }
    }
    first.map(|k| (k, logical))
}

/// The datagram a give-up names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Datagram {
    /// Command name (IgH / Wireshark: `BRD`, `FPRD`, ...).
    pub command: &'static str,
    /// ADP (position, station address or low word of a logical address).
    pub adp: u16,
    /// ADO (register, or high word of a logical address).
    pub ado: u16,
    /// Data bytes.
    pub len: usize,
    /// The ring position it addresses, where it addresses one device: a configured station
    /// address `0x1000 + n` (as ethercrab assigns them) or an auto-increment position.
    pub device: Option<u16>,
    /// Further datagrams in the frame.
    pub more: usize,
}

impl fmt::Display for Datagram {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {:#06x}:{:#06x} ({} byte{})",
            self.command,
            self.adp,
            self.ado,
            self.len,
            if self.len == 1 { "" } else { "s" }
        )?;
        if self.more > 0 {
            write!(
                f,
                " and {} more datagram{}",
                self.more,
                if self.more == 1 { "" } else { "s" }
            )?;
        }
        Ok(())
    }
}

fn describe(frame: &[u8]) -> Option<Datagram> {
    let f = Frame::parse(frame).ok()?;
    let mut it = f.datagrams();
    let d = it.next()?;
    let more = it.count();
    let command = d.command;
    let device = match command.addressing() {
        Addressing::Node => d.adp().checked_sub(0x1000),
        Addressing::Position => Some(0u16.wrapping_sub(d.adp())),
        _ => None,
    };
    Some(Datagram {
        command: command.name(),
        adp: d.adp(),
        ado: d.ado(),
        len: d.data.len(),
        device,
        more,
    })
}

/// A frame that did not come back after every try.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GaveUp {
    /// Its first datagram (`None`: not parseable, which our own master never sends).
    pub datagram: Option<Datagram>,
    /// Sends.
    pub tries: u32,
    /// From the first send to the give-up.
    pub waited: Duration,
    /// Replies that came back on this wire before (0: nothing ever answered).
    pub replies_before: u64,
}

impl GaveUp {
    /// In words, naming the interface `iface` where known.
    pub fn text(&self, iface: Option<&str>) -> String {
        let what = self
            .datagram
            .as_ref()
            .map_or_else(|| "a frame".to_string(), ToString::to_string);
        let waited = self.waited.as_secs_f64() * 1e3;
        let tries = match self.tries {
            1 => "sent once".to_string(),
            n => format!("sent {n} times"),
        };
        let on = iface.map_or_else(String::new, |i| format!(" on {i}"));
        if self.replies_before == 0 {
            return format!(
                "no EtherCAT device answered{on}: {what}, {tries}, came back from no device within {waited:.0} ms"
            );
        }
        let who = match self.datagram.as_ref().and_then(|d| d.device) {
            Some(n) => format!("device {n}"),
            None => "the segment".to_string(),
        };
        format!(
            "{who}{on} answered before ({} frame{} came back) and then not: {what}, {tries}, no reply within {waited:.0} ms",
            self.replies_before,
            if self.replies_before == 1 { "" } else { "s" }
        )
    }
}

impl fmt::Display for GaveUp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text(None))
    }
}

/// One frame in flight.
#[derive(Debug)]
struct Slot {
    used: bool,
    key: Key,
    tries: u32,
    policy: Policy,
    first: Instant,
    last: Instant,
    frame: Vec<u8>,
}

/// The frames sent on an interface whose replies are not in yet (at most `n` at once: the PDU
/// storage's frame count; the buffers are allocated once).
#[derive(Debug)]
pub struct InFlight {
    slots: Vec<Slot>,
    /// Source MAC of the frames sent (a frame seen again with it is our own, not a reply).
    source: Option<[u8; 6]>,
    replies: u64,
}

impl InFlight {
    /// Room for `n` frames in flight.
    pub fn new(n: usize) -> Self {
        let now = Instant::now();
        InFlight {
            slots: (0..n.max(1))
                .map(|_| Slot {
                    used: false,
                    key: Key {
                        command: 0,
                        index: 0,
                        ado: 0,
                        len: 0,
                    },
                    tries: 0,
                    policy: CYCLIC,
                    first: now,
                    last: now,
                    frame: Vec::with_capacity(MAX_ETHERNET_FRAME),
                })
                .collect(),
            source: None,
            replies: 0,
        }
    }

    /// `frame` was sent at `now` for the first time. A frame that is not EtherCAT is not kept.
    pub fn sent(&mut self, frame: &[u8], now: Instant) {
        let Some((key, logical)) = key_of(frame) else {
            return;
        };
        if let Some(src) = frame.get(6..12) {
            let mut s = [0; 6];
            s.copy_from_slice(src);
            self.source = Some(s);
        }
        let policy = if logical { CYCLIC } else { ACYCLIC };
        // A free slot, else the oldest (cannot happen while the PDU storage has as many
        // frames as there are slots: each frame is answered, given up or dropped first).
        let k = match self.slots.iter().position(|s| !s.used) {
            Some(k) => k,
            None => {
                let mut oldest = 0;
                for (k, s) in self.slots.iter().enumerate() {
                    if s.first < self.slots[oldest].first {
                        oldest = k;
                    }
                }
                oldest
            }
        };
        let s = &mut self.slots[k];
        s.used = true;
        s.key = key;
        s.tries = 1;
        s.policy = policy;
        s.first = now;
        s.last = now;
        s.frame.clear();
        s.frame.extend_from_slice(frame);
    }

    /// `frame` came in: `true` if it is the reply to a frame in flight (which is then done) and
    /// must go to the master; `false` for our own frame seen again, a duplicate or late reply,
    /// or anything else.
    pub fn received(&mut self, frame: &[u8]) -> bool {
        if let (Some(src), Some(s)) = (frame.get(6..12), self.source) {
            if src == s {
                return false;
            }
        }
        let Some((key, _)) = key_of(frame) else {
            return false;
        };
        match self.slots.iter_mut().find(|s| s.used && s.key == key) {
            Some(s) => {
                s.used = false;
                self.replies += 1;
                true
            }
            None => false,
        }
    }

    /// The master dropped every frame it had in flight (its future ended): forget them.
    pub fn clear(&mut self) {
        for s in &mut self.slots {
            s.used = false;
        }
    }

    /// At `now`: send again (`resend`) every frame whose interval passed and which has tries
    /// left; the first frame out of tries is given up (and forgotten).
    pub fn due(&mut self, now: Instant, mut resend: impl FnMut(&[u8])) -> Option<GaveUp> {
        let mut gave_up = None;
        for s in &mut self.slots {
            if !s.used || now.saturating_duration_since(s.last) < s.policy.interval {
                continue;
            }
            if s.tries < s.policy.tries {
                s.tries += 1;
                s.last = now;
                resend(&s.frame);
            } else if gave_up.is_none() {
                s.used = false;
                gave_up = Some(GaveUp {
                    datagram: describe(&s.frame),
                    tries: s.tries,
                    waited: now.saturating_duration_since(s.first),
                    replies_before: self.replies,
                });
            }
        }
        gave_up
    }

    /// The earliest instant something is due (a resend or a give-up); `None` with nothing in
    /// flight.
    pub fn next_due(&self) -> Option<Instant> {
        self.slots
            .iter()
            .filter(|s| s.used)
            .map(|s| s.last + s.policy.interval)
            .min()
    }

    /// Replies received so far.
    pub fn replies(&self) -> u64 {
        self.replies
    }
}

/// `true` if `command` is one of the logical (process-data) commands.
pub fn is_logical(command: Command) -> bool {
    command.addressing() == Addressing::Logical
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::ethercat::wire::{Datagram as Dg, FrameBuilder};

    const MASTER: [u8; 6] = [0x10; 6];
    const DEVICE: [u8; 6] = [0x12, 0x10, 0x10, 0x10, 0x10, 0x10];

    fn frame(cmd: Command, index: u8, adp: u16, ado: u16, len: usize, src: [u8; 6]) -> Vec<u8> {
        let data = vec![0u8; len];
        let address = u32::from(adp) | (u32::from(ado) << 16);
        FrameBuilder::new([0xff; 6], src)
            .push(&Dg::new(cmd, index, address, &data))
            .expect("datagram")
            .build()
    }

    #[test]
    fn a_reply_completes_its_frame_once() {
        let t0 = Instant::now();
        let mut f = InFlight::new(4);
        let out = frame(Command::Fprd, 7, 0x1002, 0x0130, 2, MASTER);
        f.sent(&out, t0);
        // Our own frame seen again on the socket is no reply.
        assert!(!f.received(&out));
        let back = frame(Command::Fprd, 7, 0x1002, 0x0130, 2, DEVICE);
        assert!(f.received(&back));
        // The same reply again (the answer to a repeat): not handed on.
        assert!(!f.received(&back));
        assert_eq!(f.replies(), 1);
        assert_eq!(f.next_due(), None);
    }

    #[test]
    fn a_lost_frame_is_sent_again_then_given_up() {
        let t0 = Instant::now();
        let mut f = InFlight::new(4);
        let out = frame(Command::Fprd, 3, 0x1004, 0x0130, 2, MASTER);
        f.sent(&out, t0);
        let mut resent = Vec::new();
        // Not yet due.
        assert_eq!(
            f.due(t0 + ACYCLIC.interval / 2, |b| resent.push(b.to_vec())),
            None
        );
        assert!(resent.is_empty());
        let mut t = t0;
        for k in 1..ACYCLIC.tries {
            t += ACYCLIC.interval;
            assert_eq!(f.due(t, |b| resent.push(b.to_vec())), None, "try {k}");
        }
        assert_eq!(resent.len() as u32, ACYCLIC.tries - 1);
        assert!(resent.iter().all(|b| *b == out), "repeated byte for byte");
        t += ACYCLIC.interval;
        let g = f.due(t, |_| panic!("no try left")).expect("given up");
        assert_eq!(g.tries, ACYCLIC.tries);
        assert_eq!(g.waited, ACYCLIC.total());
        assert_eq!(g.replies_before, 0);
        let d = g.datagram.as_ref().expect("datagram");
        assert_eq!(
            (d.command, d.adp, d.ado, d.len, d.device),
            ("FPRD", 0x1004, 0x0130, 2, Some(4))
        );
        assert!(
            g.text(Some("eth1"))
                .starts_with("no EtherCAT device answered on eth1: FPRD 0x1004:0x0130 (2 bytes), sent 10 times, came back from no device within 200 ms"),
            "{g}"
        );
        // The late reply to a given-up frame is not handed on.
        assert!(!f.received(&frame(Command::Fprd, 3, 0x1004, 0x0130, 2, DEVICE)));
    }

    #[test]
    fn a_device_that_answered_before_is_named() {
        let t0 = Instant::now();
        let mut f = InFlight::new(4);
        f.sent(&frame(Command::Brd, 0, 0, 0x0000, 1, MASTER), t0);
        assert!(f.received(&frame(Command::Brd, 0, 3, 0x0000, 1, DEVICE)));
        // Auto-increment read of the device at position 2 (ADP = -2).
        let out = frame(Command::Aprd, 1, 0xfffe, 0x0000, 1, MASTER);
        f.sent(&out, t0);
        let mut t = t0;
        let mut gave_up = None;
        for _ in 0..ACYCLIC.tries {
            t += ACYCLIC.interval;
            gave_up = f.due(t, |_| {});
        }
        let g = gave_up.expect("given up after the last try");
        assert_eq!(g.replies_before, 1);
        assert_eq!(g.datagram.as_ref().and_then(|d| d.device), Some(2));
        let text = g.to_string();
        assert!(
            text.starts_with("device 2 answered before (1 frame came back) and then not: APRD 0xfffe:0x0000 (1 byte), sent 10 times, no reply within 200 ms"),
            "{text}"
        );
    }

    #[test]
    fn process_data_is_never_repeated() {
        let t0 = Instant::now();
        let mut f = InFlight::new(2);
        f.sent(&frame(Command::Lrw, 9, 0, 0, 8, MASTER), t0);
        let g = f
            .due(t0 + CYCLIC.interval, |_| panic!("process data repeated"))
            .expect("lost");
        assert_eq!(g.tries, 1);
        assert!(is_logical(Command::Lrw) && !is_logical(Command::Fprd));
    }
}
