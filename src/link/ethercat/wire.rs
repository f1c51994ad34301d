//! The wire end of the EtherCAT link's PDU loop ([`WireEnd`]): where ethercrab's frames go —
//! through the in-process emulated segment (`ethercat-emu`, feature `sim`) or out of a raw
//! packet socket on a network interface (`ethercat:IFACE`, [`RawPort`]) — with the `--pcap`
//! tap, the log of the cycle's datagrams and [`drive`], which runs a master future to its end
//! on one thread while pumping the frames.

use std::future::Future;
use std::path::Path;
use std::task::Poll;
use std::time::{Duration, Instant};

use ethercrab::{MainDevice, MainDeviceConfig, PduRx, PduTx, Timeouts};

use super::datagrams::DatagramLog;
use super::retry::{GaveUp, InFlight};
use super::{EthercatSpec, Storage, Wire};
use crate::bus::capture::CaptureClock;
use crate::bus::ethercat::mailbox::MailboxError;
use crate::bus::ethercat::pcap::{PcapWriter, TimestampResolution};
use crate::bus::ethercat::raw::RawPort;
use crate::link::LinkError;
#[cfg(feature = "sim")]
use crate::sim::esc::segment::Segment;

/// Frame tap: every frame sent and received goes into a pcap file (`--pcap`). A write that
/// fails (a full disk, `/dev/full`) is not silent: the first error is kept, later frames are
/// not written, and [`Tap::finish`] returns it at the end of the run, so the command exits 2
/// after the axes stopped as usual.
///
/// Timestamps are the wall-clock time of the run ([`CaptureClock`]): on an interface the
/// monotonic time since the capture opened, on the emulated wire its bus time
/// ([`WireEnd::bus_time`]), so the capture shows the emulated cycle's true spacing.
pub(super) struct Tap {
    writer: PcapWriter<std::io::BufWriter<std::fs::File>>,
    clock: CaptureClock,
    path: std::path::PathBuf,
    failed: Option<String>,
}

impl Tap {
    /// Record `frame` at `virtual_ns` of the emulated wire's bus time, or (`None`, an
    /// interface) now.
    fn record(&mut self, frame: &[u8], virtual_ns: Option<u64>) {
        if self.failed.is_some() {
            return;
        }
        let t = match virtual_ns {
            Some(v) => self.clock.at_ns(v),
            None => self.clock.now_ns(),
        };
        if let Err(e) = self.writer.write_packet(t, frame) {
            self.fail(&e);
        }
    }

    fn fail(&mut self, e: &dyn std::fmt::Display) {
        let m = format!(
            "--pcap {}: writing the capture failed ({e}); the capture is incomplete",
            self.path.display()
        );
        tracing::warn!(target: "fieldprobe::link::ethercat", "{m}");
        self.failed = Some(m);
    }

    /// Flush the file; the first write error of the capture, naming the option and the file.
    fn finish(&mut self) -> Result<(), String> {
        if self.failed.is_none() {
            if let Err(e) = self.writer.flush() {
                self.fail(&e);
            }
        }
        self.failed.clone().map_or(Ok(()), Err)
    }
}

/// The wire end of the PDU loop: an emulated segment in-process (`ethercat-emu`, feature
/// `sim`) or a raw socket on an interface (`ethercat:IFACE`).
pub(super) struct WireEnd {
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    #[cfg(feature = "sim")]
    segment: Option<Segment>,
    tap: Option<Tap>,
    port: Option<RawPort>,
    #[cfg_attr(not(feature = "sim"), allow(dead_code))] // the emulated segment's clock
    t0: Instant,
    /// Emulated wire: a frame of the current [`drive`] call was lost (dropped by a fault knob
    /// or refused as invalid by the segment).
    lost: bool,
    /// Emulated wire: frames the current [`drive`] call has put through the segment.
    frames: u64,
    /// Emulated wire: its bus time, ns since the wire was made (the `--pcap` timestamps; see
    /// [`WireEnd::bus_time`]).
    #[cfg(feature = "sim")]
    bus_ns: u64,
    /// Emulated wire: the bus time of the machine's time 0 ([`WireEnd::start_cycles`]).
    #[cfg(feature = "sim")]
    epoch_ns: u64,
    /// The logical datagrams of the current process-data cycle, out and back.
    pub(super) log: DatagramLog,
    /// The buffer of the frame being sent.
    buf: Vec<u8>,
    /// Interface: the frames sent whose replies are not in yet, repeated and given up by
    /// [`retry`](super::retry)'s policies.
    inflight: InFlight,
    /// Interface: the frame the current [`drive`] call gave up on.
    gave_up: Option<GaveUp>,
}

impl WireEnd {
    /// The frames go through an in-process emulated segment (`ethercat-emu`).
    pub(super) fn is_emulated(&self) -> bool {
        #[cfg(feature = "sim")]
        return self.segment.is_some();
        #[cfg(not(feature = "sim"))]
        false
    }

    /// The emulated segment (`ethercat-emu`), if any.
    #[cfg(feature = "sim")]
    pub(super) fn segment(&self) -> Option<&Segment> {
        self.segment.as_ref()
    }

    /// The emulated segment, mutable.
    #[cfg(feature = "sim")]
    pub(super) fn segment_mut(&mut self) -> Option<&mut Segment> {
        self.segment.as_mut()
    }

    /// The emulated wire's bus time, ns since the wire was made; `None` on an interface.
    ///
    /// The in-process wire has no clock of its own (it runs on virtual time): every frame
    /// takes its wire time at 100 Mbit/s ([`frame_wire_ns`](super::cycle_plan::frame_wire_ns); the reply is stamped when the
    /// frame has passed), and the frames of the exchange at machine time `now` start at the
    /// bus time of the machine's time 0 ([`start_cycles`](Self::start_cycles)) + `now`
    /// ([`at_cycle`](Self::at_cycle)), or later if the bus is still busy. The start-up's
    /// frames thus follow each other back to back, the cycles' at the machine's cycle time.
    fn bus_time(&self) -> Option<u64> {
        #[cfg(feature = "sim")]
        if self.segment.is_some() {
            return Some(self.bus_ns);
        }
        None
    }

    /// Emulated wire: the machine's time 0 is now (the end of the start-up).
    #[cfg(feature = "sim")]
    pub(super) fn start_cycles(&mut self) {
        self.epoch_ns = self.bus_ns;
    }

    /// Emulated wire: the frames of the exchange at machine time `now` go out now (see
    /// [`bus_time`](Self::bus_time)).
    #[cfg(feature = "sim")]
    pub(super) fn at_cycle(&mut self, now: crate::units::Nanos) {
        self.bus_ns = self.bus_ns.max(self.epoch_ns.saturating_add(now.0));
    }

    /// See [`Tap::finish`]; `Ok` without `--pcap`.
    pub(super) fn finish_capture(&mut self) -> Result<(), String> {
        self.tap.as_mut().map_or(Ok(()), Tap::finish)
    }

    /// Send every queued frame; emulated: process and hand back at once; interface: send.
    fn pump(&mut self) {
        while let Some(frame) = self.tx.next_sendable_frame() {
            // The frame buffer is kept (no allocation per frame).
            let mut buf = std::mem::take(&mut self.buf);
            buf.clear();
            let sent = frame.send_blocking(|b| {
                buf.extend_from_slice(b);
                Ok(b.len())
            });
            if sent.is_err() {
                self.buf = buf;
                continue;
            }
            let at = self.bus_time();
            if let Some(tap) = self.tap.as_mut() {
                tap.record(&buf, at);
            }
            self.log.record(&buf, false);
            #[cfg(feature = "sim")]
            if let Some(seg) = self.segment.as_mut() {
                let now = self.t0.elapsed().as_nanos() as u64;
                // A dropped (fault knob) or invalid frame is lost on the wire.
                self.frames += 1;
                self.bus_ns = self
                    .bus_ns
                    .saturating_add(super::cycle_plan::frame_wire_ns(buf.len()));
                if let Ok(true) = seg.process_frame(&mut buf, now) {
                    if let Some(tap) = self.tap.as_mut() {
                        tap.record(&buf, Some(self.bus_ns));
                    }
                    self.log.record(&buf, true);
                    let _ = self.rx.receive_frame(&buf);
                } else {
                    self.lost = true;
                }
                self.buf = buf;
                continue;
            }
            if let Some(port) = self.port.as_mut() {
                self.inflight.sent(&buf, Instant::now());
                let _ = port.send(&buf);
            }
            self.buf = buf;
        }
    }

    /// Interface: send again what is due ([`InFlight::due`]); a frame out of tries ends the
    /// current [`drive`] call (kept in `gave_up` for the error message).
    fn retry_due(&mut self) {
        let Some(port) = self.port.as_mut() else {
            return;
        };
        let tap = &mut self.tap;
        let log = &mut self.log;
        if let Some(g) = self.inflight.due(Instant::now(), |frame| {
            tracing::debug!(target: "fieldprobe::link::ethercat", len = frame.len(),
                "no reply in time: frame sent again");
            if let Some(tap) = tap.as_mut() {
                tap.record(frame, None);
            }
            log.record(frame, false);
            let _ = port.send(frame);
        }) {
            tracing::debug!(target: "fieldprobe::link::ethercat", "{g}");
            self.gave_up = Some(g);
            self.lost = true;
        }
    }

    /// `e` from a [`drive`] call, or [`LinkError::NoAnswer`] if the call ended because the
    /// wire end gave up a frame (the root cause, whatever the master made of it).
    pub(super) fn explain(&mut self, e: LinkError) -> LinkError {
        match self.gave_up.take() {
            Some(g) => LinkError::NoAnswer {
                text: g.text(self.port.as_ref().map(RawPort::iface)),
                answered_before: g.replies_before > 0,
            },
            None => e,
        }
    }

    /// Interface: wait for the next frame (at most the port's receive timeout, [`RX_WAIT`]) and
    /// hand it to the PDU loop. One frame per call: the caller polls the master's future after
    /// each, so a reply is processed as soon as it is in, not after a further wait.
    fn receive(&mut self) {
        let Some(port) = self.port.as_mut() else {
            return;
        };
        if let Some(frame) = port.try_receive() {
            if let Some(tap) = self.tap.as_mut() {
                tap.record(&frame, None);
            }
            // Only the reply to a frame in flight goes to the master: not our own frame seen
            // again, nor the late twin of a repeated one (ethercrab reuses indices).
            if self.inflight.received(&frame) {
                self.log.record(&frame, true);
                let _ = self.rx.receive_frame(&frame);
            }
        }
    }
}

/// Longest wait of one receive on an interface. The socket is polled with it (poll(2) takes
/// whole ms: a shorter timeout would be 0, a busy loop that keeps a device emulator sharing the
/// CPU from answering — measured: wire round trip p90 1.4 ms instead of 73 µs at 1 ms). A
/// frame that arrives ends the wait at once.
const RX_WAIT: Duration = Duration::from_millis(1);

/// Frames one [`drive`] call may put through the emulated segment before it gives up (the
/// in-process wire's bound in place of ethercrab's wall-clock timeouts: a master loop that
/// polls a device which never reaches the awaited state ends here). Start-up with 100 DC
/// static-sync iterations takes a few thousand frames, an SDO transfer a few dozen.
const EMULATED_FRAMES_PER_CALL: u64 = 1_000_000;

/// ethercrab's timeouts on the in-process wire: never reached. The emulated segment answers
/// every frame synchronously inside [`WireEnd::pump`], so a reply can only be missing because
/// the segment dropped the frame, which [`drive`] sees at once and reports; a wall-clock
/// timeout there would only fire when the test machine is busy (it did, with 20 ms, under CPU
/// load: "frame lost: timeout: PDU").
pub(super) const EMULATED_TIMEOUT: Duration = Duration::from_secs(24 * 3600);

/// ethercrab's timeouts on the in-process wire ([`EMULATED_TIMEOUT`]'s reason): `Duration::MAX`,
/// which ethercrab's std timer (`async_io::Timer::after`) turns into a timer that never fires
/// and is never registered with the async-io reactor — a 24 h timer would be, once per frame
/// (a syscall to wake the reactor thread, and its bookkeeping, per frame).
const EMULATED_ETHERCRAB_TIMEOUT: Duration = Duration::MAX;

/// The value a master future gives when [`drive`] ends it because the emulated wire lost one
/// of its frames (or it exceeded [`EMULATED_FRAMES_PER_CALL`]), the in-process, virtual-time
/// counterpart of ethercrab's PDU timeout.
pub(super) trait LostOnWire {
    /// `gave_up`: on an interface, the frame given up after its tries; `None`: the emulated
    /// wire lost it.
    fn lost_on_wire(gave_up: Option<&GaveUp>) -> Self;
}

impl<T> LostOnWire for Result<T, ethercrab::error::Error> {
    fn lost_on_wire(gave_up: Option<&GaveUp>) -> Self {
        Err(match gave_up {
            // As ethercrab's own PDU timeout said before the wire end repeated frames.
            Some(_) => ethercrab::error::Error::Timeout(ethercrab::error::TimeoutError::Pdu),
            None => ethercrab::error::Error::ReceiveFrame,
        })
    }
}

impl<T> LostOnWire for Result<T, MailboxError> {
    fn lost_on_wire(gave_up: Option<&GaveUp>) -> Self {
        Err(MailboxError::Datagram(match gave_up {
            Some(g) => g.to_string(),
            None => "frame lost on the emulated wire".into(),
        }))
    }
}

impl<T> LostOnWire for Result<T, LinkError> {
    fn lost_on_wire(gave_up: Option<&GaveUp>) -> Self {
        Err(LinkError::Other(match gave_up {
            Some(g) => format!("EtherCAT: {g}"),
            None => "EtherCAT: a frame was lost on the emulated wire".into(),
        }))
    }
}

/// Run `fut` to completion while pumping frames through `wire` (single thread): send what the
/// master queued, then wait for one frame, then poll the master again. On the emulated wire a
/// frame the segment drops ends `fut` at once with [`LostOnWire`] (ethercrab releases the
/// frame when its future is dropped); no clock decides.
pub(super) fn drive<T: LostOnWire>(wire: &mut WireEnd, fut: impl Future<Output = T>) -> T {
    wire.lost = false;
    wire.frames = 0;
    wire.gave_up = None;
    let pump = std::future::poll_fn(|cx| {
        wire.tx.replace_waker(cx.waker());
        wire.pump();
        if wire.lost || wire.frames > EMULATED_FRAMES_PER_CALL {
            tracing::debug!(target: "fieldprobe::link::ethercat", frames = wire.frames,
                "frame lost or no progress; the master operation ends");
            return Poll::Ready(T::lost_on_wire(wire.gave_up.as_ref()));
        }
        wire.receive();
        wire.retry_due();
        if wire.lost {
            return Poll::Ready(T::lost_on_wire(wire.gave_up.as_ref()));
        }
        if wire.port.is_some() {
            // Nothing wakes us when a frame arrives on the socket: the receive above waited
            // for it; poll the master again.
            cx.waker().wake_by_ref();
        }
        Poll::<T>::Pending
    });
    let out = futures_lite::future::block_on(futures_lite::future::or(fut, pump));
    // Whatever the master still had in flight ended with its future.
    wire.inflight.clear();
    out
}

/// Leak a PDU storage and a MainDevice for `wire` (emulated segment per `spec`).
pub(super) fn connect(
    wire: &Wire,
    spec: &EthercatSpec,
) -> Result<(&'static MainDevice<'static>, WireEnd), LinkError> {
    #[cfg(feature = "sim")]
    let segment = match wire {
        Wire::Emulated => Some(super::emulated::emulated_segment(spec)?),
        Wire::Interface(_) => None,
    };
    let port = match wire {
        Wire::Interface(i) => Some(
            RawPort::open_with_timeout(i, RX_WAIT)
                .map_err(|e| LinkError::Other(format!("ethercat:{i}: {e}")))?,
        ),
        #[cfg(feature = "sim")]
        Wire::Emulated => None,
        #[cfg(not(feature = "sim"))]
        Wire::Emulated => {
            return Err(LinkError::Other(
                "ethercat-emu: this build of fieldprobe has no EtherCAT emulator (Cargo feature `sim`); ethercat:IFACE needs only `ethercat`".into(),
            ))
        }
    };
    let tap = match &spec.pcap {
        None => None,
        Some(p) => Some(open_tap(p)?),
    };
    let emulated = port.is_none();
    let storage: &'static Storage = Box::leak(Box::new(Storage::new()));
    let (tx, rx, pdu_loop) = storage
        .try_split()
        .map_err(|()| LinkError::Other("EtherCAT PDU storage already in use".into()))?;
    let wire_end = WireEnd {
        tx,
        rx,
        #[cfg(feature = "sim")]
        segment,
        tap,
        port,
        t0: Instant::now(),
        lost: false,
        frames: 0,
        #[cfg(feature = "sim")]
        bus_ns: 0,
        #[cfg(feature = "sim")]
        epoch_ns: 0,
        log: DatagramLog::default(),
        buf: Vec::with_capacity(crate::bus::ethercat::wire::MAX_ETHERNET_FRAME),
        inflight: InFlight::new(super::MAX_FRAMES),
        gave_up: None,
    };
    let timeouts = if emulated {
        Timeouts {
            pdu: EMULATED_ETHERCRAB_TIMEOUT,
            state_transition: EMULATED_ETHERCRAB_TIMEOUT,
            mailbox_echo: EMULATED_ETHERCRAB_TIMEOUT,
            mailbox_response: EMULATED_ETHERCRAB_TIMEOUT,
            eeprom: EMULATED_ETHERCRAB_TIMEOUT,
            ..Timeouts::default()
        }
    } else {
        Timeouts {
            // A backstop only: the wire end repeats and gives up a frame itself
            // ([`super::retry`]: 30 ms for process data, 10 × 20 ms for the rest).
            pdu: Duration::from_secs(1),
            state_transition: Duration::from_secs(5),
            mailbox_response: Duration::from_secs(2),
            // One SII (EEPROM) word read, busy bit polled over the wire: ethercrab's 10 ms is
            // shorter than a raw-socket round trip to a busy emulator (or a long segment) can
            // take; it only matters at start-up.
            eeprom: Duration::from_millis(100),
            ..Timeouts::default()
        }
    };
    let md: &'static MainDevice<'static> = Box::leak(Box::new(MainDevice::new(
        pdu_loop,
        timeouts,
        MainDeviceConfig {
            dc_static_sync_iterations: if emulated { 100 } else { 10_000 },
            ..MainDeviceConfig::default()
        },
    )));
    Ok((md, wire_end))
}

pub(super) fn open_tap(path: &Path) -> Result<Tap, LinkError> {
    let f = std::fs::File::create(path)
        .map_err(|e| LinkError::Other(format!("--pcap {}: {e}", path.display())))?;
    let writer = PcapWriter::new(std::io::BufWriter::new(f), TimestampResolution::Nano)
        .map_err(|e| LinkError::Other(format!("--pcap {}: {e}", path.display())))?;
    Ok(Tap {
        writer,
        clock: CaptureClock::start(),
        path: path.to_path_buf(),
        failed: None,
    })
}
