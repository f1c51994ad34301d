//! The SDO client (`bus::canopen::sdo::SdoClient`, CiA 301) fed hostile server replies: one
//! upload or download in any transfer mode, then a script of frames (mostly on the server's
//! COB-ID 0x580 + node) and time steps.
//! Must hold: no panic; the client only sends valid frames on 0x600 + node; an upload result is
//! never longer than the configured maximum; a download result is `Ok` only for the data given;
//! after its timeout the client is idle with a result (it cannot hang).
#![no_main]
use fieldprobe::bus::can::CanFrame;
use fieldprobe::bus::canopen::sdo::{SdoClient, TransferMode, SDO_RX_BASE, SDO_TX_BASE};
use fieldprobe::units::Nanos;
use fieldprobe_fuzz::Bytes;
use libfuzzer_sys::fuzz_target;

const NODE: u8 = 5;
const TIMEOUT: Nanos = Nanos(500_000_000);

fn check_out(frames: &[CanFrame]) {
    for f in frames {
        f.validate()
            .unwrap_or_else(|e| panic!("client sent an invalid frame {f:?}: {e}"));
        assert_eq!(
            f.id,
            u32::from(SDO_RX_BASE) + u32::from(NODE),
            "client sent {f:?}"
        );
        assert!(!f.extended && !f.rtr && !f.error, "client sent {f:?}");
    }
    assert!(frames.len() <= 128, "{} frames at once", frames.len());
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes::new(data);
    let mut c = SdoClient::new(NODE);
    c.set_timeout(TIMEOUT);
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
    let index = b.u16();
    let sub = b.u8();
    let mut now = Nanos(0);
    let upload = cfg & 8 == 0;
    let sent: Vec<u8> = if upload {
        Vec::new()
    } else {
        b.take_len16(2048).to_vec()
    };
    let out = if upload {
        c.upload(index, sub, now)
    } else {
        c.download(index, sub, &sent, now)
    };
    check_out(&out);
    let mut results = 0u32;
    let mut steps = 0;
    while !b.is_empty() && steps < 8192 {
        steps += 1;
        let op = b.u8();
        let out = if op < 0xF0 {
            let id = if op & 0x40 == 0 {
                SDO_TX_BASE + u16::from(NODE)
            } else {
                b.u16() & 0x7FF
            };
            let payload = b.take_len8(9);
            let f = CanFrame::new(id, payload).expect("standard frame");
            c.handle(&f, now)
        } else {
            now = Nanos(now.0 + u64::from(b.u16()) * 10_000);
            c.poll(now)
        };
        check_out(&out);
        if let Some(r) = c.take_result() {
            results += 1;
            if let Ok(d) = &r {
                if upload {
                    assert!(
                        d.len() <= max.max(4),
                        "upload of {} bytes, max {max}",
                        d.len()
                    );
                } else {
                    assert!(d.is_empty(), "download returned data");
                }
            }
            // Start another transfer on the same client: stale replies must not break it.
            let out = if upload {
                c.upload(index, sub, now)
            } else {
                c.download(index, sub, &sent, now)
            };
            check_out(&out);
        }
    }
    // Bounded: past the deadline the client gives up.
    if c.busy() {
        let deadline = c.next_deadline().expect("a busy client has a deadline");
        assert!(
            deadline.0 <= now.0 + TIMEOUT.0,
            "deadline {deadline:?} beyond now + timeout"
        );
        let out = c.poll(Nanos(deadline.0 + 1));
        check_out(&out);
        assert!(!c.busy(), "client still busy after its timeout");
        assert!(
            c.take_result().is_some(),
            "timed-out transfer without a result"
        );
    }
    let _ = results;
});
