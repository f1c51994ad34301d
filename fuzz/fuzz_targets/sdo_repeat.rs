//! Issue 28 item 1: a device that repeats its last answer for ever. The SDO client
//! (`bus::canopen::sdo::SdoClient`, CiA 301) starts an upload or download; the hostile server
//! answers each request with the next frame of the script, and once the script is spent it
//! repeats its last answer for ever (with the toggle bit put right if the input says so, the
//! case that kept `sdo read` busy: segments without data and without the end bit). Every
//! answer comes a fuzzed gap after the request, inside the response timeout, so only the
//! bound of the whole transfer can end it.
//! Must hold: no panic; the transfer ends with a result within the client's transfer bound
//! (plus one gap), after at most bound / gap + 1 answers; the client sends only valid frames
//! on 0x600 + node; an upload result never exceeds the configured maximum.
#![no_main]
use fieldprobe::bus::can::CanFrame;
use fieldprobe::bus::canopen::sdo::{SdoClient, TransferMode, SDO_RX_BASE, SDO_TX_BASE};
use fieldprobe::units::Nanos;
use fieldprobe_fuzz::Bytes;
use libfuzzer_sys::fuzz_target;

const NODE: u8 = 5;
const TIMEOUT: Nanos = Nanos(500_000_000);
/// The whole-transfer bound under test (small, so that one input stays fast).
const BOUND: Nanos = Nanos(20_000_000);
/// Shortest gap between a request and its answer: 20 µs (a CAN frame at 1 Mbit/s takes
/// ~100 µs), so at most 1,000 answers fit the bound.
const MIN_GAP: u64 = 20_000;

fn check_out(frames: &[CanFrame]) {
    for f in frames {
        f.validate()
            .unwrap_or_else(|e| panic!("client sent an invalid frame {f:?}: {e}"));
        assert_eq!(
            f.id,
            u32::from(SDO_RX_BASE) + u32::from(NODE),
            "client sent {f:?}"
        );
    }
    assert!(frames.len() <= 128, "{} frames at once", frames.len());
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes::new(data);
    let mut c = SdoClient::new(NODE);
    c.set_timeout(TIMEOUT);
    c.set_transfer_timeout(BOUND);
    let cfg = b.u8();
    c.set_mode(match cfg & 3 {
        0 => TransferMode::Auto,
        1 => TransferMode::Expedited,
        2 => TransferMode::Segmented,
        _ => TransferMode::Block,
    });
    c.set_block_size(b.u8());
    c.set_crc(cfg & 4 != 0);
    let max = usize::from(b.u16());
    c.set_max_size(max);
    let fix_toggle = cfg & 0x10 != 0;
    let upload = cfg & 8 == 0;
    let gap = MIN_GAP + u64::from(b.u16()) * 1_000;
    let gap = gap.min(TIMEOUT.0 - 1);
    let index = b.u16();
    let sub = b.u8();
    let sent: Vec<u8> = if upload {
        Vec::new()
    } else {
        b.take_len16(512).to_vec()
    };
    let mut now = Nanos(0);
    let mut out = if upload {
        c.upload(index, sub, now)
    } else {
        c.download(index, sub, &sent, now)
    };
    check_out(&out);
    let mut last = [0x00u8; 8];
    let mut answers = 0u64;
    let most = BOUND.0 / gap + 2;
    while c.busy() {
        answers += 1;
        assert!(
            answers <= most,
            "{answers} answers and still busy at {now:?}: the transfer bound did not hold"
        );
        now = Nanos(now.0 + gap);
        // The answer: the next scripted frame, else the last one again.
        if !b.is_empty() {
            let p = b.take_len8(8);
            last = [0; 8];
            last[..p.len()].copy_from_slice(p);
        } else if fix_toggle {
            // Put the toggle right for the request just sent (segment protocols).
            if let Some(req) = out.last() {
                last[0] = (last[0] & !0x10) | (req.data[0] & 0x10);
            }
        }
        let f = CanFrame::new(SDO_TX_BASE + u16::from(NODE), &last).expect("frame");
        out = c.handle(&f, now);
        check_out(&out);
        if c.busy() {
            let p = c.poll(now);
            check_out(&p);
            if !p.is_empty() {
                out = p;
            }
        }
        if out.is_empty() && c.busy() {
            // Nothing requested (a block in progress): time passes to the next deadline.
            let d = c.next_deadline().expect("a busy client has a deadline");
            assert!(d.0 <= BOUND.0.max(now.0 + TIMEOUT.0), "deadline {d:?}");
            now = Nanos(d.0.max(now.0));
            out = c.poll(now);
            check_out(&out);
        }
    }
    assert!(
        now.0 <= BOUND.0 + gap,
        "transfer ended at {now:?}, bound {BOUND:?} + gap {gap} ns"
    );
    let r = c.take_result().expect("an ended transfer has a result");
    if let Ok(d) = &r {
        if upload {
            assert!(d.len() <= max.max(4), "upload of {} bytes, max {max}", d.len());
        }
    }
});
