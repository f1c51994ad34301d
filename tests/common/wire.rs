//! ethercrab 0.7.1 in-process against an emulated segment: the "wire" thread that takes frames
//! from ethercrab's PDU loop, runs them through the [`Segment`] and hands them back, and a
//! bounded runner for the MainDevice side (notes `ethercat.md` §1.2).

#![allow(dead_code)] // each test crate uses its own subset

use std::{
    sync::{
        atomic::{AtomicBool, Ordering},
        mpsc, Arc, Mutex,
    },
    task::{Wake, Waker},
    thread,
    time::{Duration, Instant},
};

use ethercrab::{PduRx, PduTx};
use fieldprobe::sim::esc::segment::Segment;

struct ThreadWaker(thread::Thread);

impl Wake for ThreadWaker {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }
}

/// What the wire thread saw.
#[derive(Debug, Default)]
pub struct EmuStats {
    /// Frames taken from ethercrab.
    pub frames: u64,
    /// Frames the segment refused (a real segment drops them; ethercrab times out).
    pub bad_frames: u64,
    /// Returned frames ethercrab did not take.
    pub ignored_replies: u64,
}

/// Start the wire until `stop` is set. `after_frame` runs with the segment after every
/// processed frame (e.g. to queue device-initiated mailbox messages).
pub fn spawn_wire(
    mut tx: PduTx<'static>,
    mut rx: PduRx<'static>,
    seg: Arc<Mutex<Segment>>,
    stop: Arc<AtomicBool>,
    mut after_frame: impl FnMut(&mut Segment) + Send + 'static,
) -> thread::JoinHandle<EmuStats> {
    thread::spawn(move || {
        let waker = Waker::from(Arc::new(ThreadWaker(thread::current())));
        let t0 = Instant::now();
        let mut stats = EmuStats::default();
        while !stop.load(Ordering::Relaxed) {
            tx.replace_waker(&waker);
            while let Some(frame) = tx.next_sendable_frame() {
                let mut buf = Vec::with_capacity(1514);
                frame
                    .send_blocking(|b| {
                        buf.extend_from_slice(b);
                        Ok(b.len())
                    })
                    .expect("send_blocking");
                stats.frames += 1;
                let now = t0.elapsed().as_nanos() as u64;
                {
                    let mut s = seg.lock().unwrap();
                    if s.process_frame(&mut buf, now).is_err() {
                        stats.bad_frames += 1;
                        continue;
                    }
                    after_frame(&mut s);
                }
                match rx.receive_frame(&buf) {
                    Ok(ethercrab::ReceiveAction::Processed) => {}
                    _ => stats.ignored_replies += 1,
                }
            }
            thread::park_timeout(Duration::from_millis(1));
        }
        stats
    })
}

/// Run `f` on its own thread; fail the test if it does not finish within `timeout`.
pub fn bounded<T: Send + 'static>(timeout: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (done_tx, done_rx) = mpsc::channel();
    thread::spawn(move || {
        let _ = done_tx.send(f());
    });
    done_rx
        .recv_timeout(timeout)
        .unwrap_or_else(|e| panic!("MainDevice side did not finish within {timeout:?}: {e}"))
}

/// The EK1100-kind coupler ESC of `esi/fieldprobe-ek1100.xml` (no application), first on every
/// emulated segment of the tests.
pub fn coupler() -> fieldprobe::sim::esc::Esc {
    use fieldprobe::esi::{self, sii, to_sii::sii_from_device};
    use fieldprobe::sim::esc::{Esc, EscConfig, NullApp};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/esi/fieldprobe-ek1100.xml");
    let file = esi::load(path).expect("EK1100 ESI");
    let content = sii_from_device(&file, &file.devices[0]).expect("EK1100 SII");
    let cfg = EscConfig::from_sii(sii::encode_padded(&content).expect("encode"));
    Esc::new(cfg, Box::new(NullApp))
}
