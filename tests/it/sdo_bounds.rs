//! Issue 28 item 1: every SDO transfer has a bound. A hostile CANopen node on the in-process
//! virtual CAN bus (1 Mbit/s, virtual time) answers our client's segmented upload in ways that
//! never end; the client must abort (the abort frame reaches the node with the CiA 301 code)
//! and report what it expected and what came, within the bound:
//!
//! - segments without data and without the end bit: the transfer's time bound (3 s of bus
//!   time), abort 0x05040000;
//! - more data than the initiate response announced: abort 0x06070012 at the first segment
//!   beyond the size;
//! - no size announced and data without end: the byte cap ([`SdoClient::set_max_size`]),
//!   abort 0x05040005.
//!
//! The EtherCAT side (our CoE mailbox client against an emulated SubDevice that answers
//! endlessly) is in [`coe`].

use fieldprobe::bus::can::{Bitrate, CanBus, CanFrame, VirtualCan};
use fieldprobe::bus::canopen::sdo::{SdoClient, SdoError, DEFAULT_TRANSFER_TIMEOUT};
use fieldprobe::units::Nanos;

#[cfg(feature = "sim")]
mod coe;

const NODE: u8 = 5;
const REQ: u32 = 0x605;
const RESP: u16 = 0x585;

/// How the hostile node answers an upload.
#[derive(Clone, Copy)]
enum Hostile {
    /// Initiate: segmented, size 100; each segment: toggle right, no data (n = 7), no end.
    EmptySegments,
    /// Initiate: segmented, size 10; each segment: 7 bytes, no end.
    MoreThanAnnounced,
    /// Initiate: segmented, no size; each segment: 7 bytes, no end.
    EndlessUnsized,
}

impl Hostile {
    /// The answer to one request (`None`: an abort or anything else, no answer).
    fn answer(self, req: &[u8; 8]) -> Option<[u8; 8]> {
        match req[0] >> 5 {
            // Initiate upload request: 010 0 00 0 s + mux + size.
            2 => {
                let (cmd, size) = match self {
                    Hostile::EmptySegments => (0x41, 100u32),
                    Hostile::MoreThanAnnounced => (0x41, 10),
                    Hostile::EndlessUnsized => (0x40, 0),
                };
                let s = size.to_le_bytes();
                Some([cmd, req[1], req[2], req[3], s[0], s[1], s[2], s[3]])
            }
            // Upload segment request 011 t 0000: 000 t nnn c.
            3 => {
                let t = req[0] & 0x10;
                match self {
                    Hostile::EmptySegments => Some([t | (7 << 1), 0, 0, 0, 0, 0, 0, 0]),
                    Hostile::MoreThanAnnounced | Hostile::EndlessUnsized => {
                        Some([t, 1, 2, 3, 4, 5, 6, 7])
                    }
                }
            }
            _ => None,
        }
    }
}

/// What one upload against the hostile node gave.
struct Outcome {
    result: Result<Vec<u8>, SdoError>,
    /// Bus time from the request to the result.
    took: Nanos,
    /// Requests the node received (the last one should be the abort).
    requests: Vec<[u8; 8]>,
}

/// Upload 0x2000:01 from the hostile node on a virtual bus, driven to the end in virtual
/// time (at most 200,000 deliveries: a broken bound fails here instead of hanging).
fn upload(hostile: Hostile, client: &mut SdoClient) -> Outcome {
    let hub = VirtualCan::with_bitrate(Bitrate::DEFAULT);
    let mut master = hub.endpoint();
    let mut node = hub.endpoint();
    let start = hub.now();
    for f in client.upload(0x2000, 1, start) {
        master.send(&f).unwrap();
    }
    let mut requests = Vec::new();
    let mut result = None;
    let mut took = Nanos::ZERO;
    for _ in 0..200_000 {
        if result.is_none() {
            if let Some(r) = client.take_result() {
                took = Nanos(hub.now().0 - start.0);
                result = Some(r);
            }
        }
        let limit = match client.next_deadline() {
            Some(d) => d,
            None if hub.queued() > 0 => Nanos(u64::MAX),
            None => break,
        };
        if hub.advance(limit).is_some() {
            while let Some((f, at)) = node.recv_timed() {
                if f.id != REQ {
                    continue;
                }
                requests.push(f.data);
                if let Some(a) = hostile.answer(&f.data) {
                    node.send_at(&CanFrame::new(RESP, &a).unwrap(), at).unwrap();
                }
            }
            while let Some((f, at)) = master.recv_timed() {
                for r in client.handle(&f, at) {
                    master.send_at(&r, at).unwrap();
                }
            }
        }
        for r in client.poll(hub.now()) {
            master.send(&r).unwrap();
        }
    }
    let result = result
        .or_else(|| client.take_result())
        .expect("the transfer never ended: no bound held");
    Outcome {
        result,
        took,
        requests,
    }
}

/// The abort the node received last: (index, sub, code).
fn last_abort(requests: &[[u8; 8]]) -> (u16, u8, u32) {
    let a = requests.last().expect("the node received nothing");
    assert_eq!(a[0], 0x80, "last request is not an abort: {a:02x?}");
    (
        u16::from_le_bytes([a[1], a[2]]),
        a[3],
        u32::from_le_bytes([a[4], a[5], a[6], a[7]]),
    )
}

#[test]
fn empty_segments_end_at_the_transfer_bound_with_abort_05040000() {
    let mut client = SdoClient::new(NODE);
    let o = upload(Hostile::EmptySegments, &mut client);
    let e = o.result.expect_err("an endless upload must fail");
    assert!(
        matches!(
            e,
            SdoError::TransferTimeout {
                index: 0x2000,
                sub: 1,
                ..
            }
        ),
        "{e:?}"
    );
    // The bound held: 3 s of bus time, plus at most one response's round trip.
    let bound = DEFAULT_TRANSFER_TIMEOUT.0;
    assert!(
        o.took.0 >= bound && o.took.0 < bound + 5_000_000,
        "ended after {} ns (bound {bound} ns)",
        o.took.0
    );
    assert_eq!(last_abort(&o.requests), (0x2000, 1, 0x0504_0000));
    // Thousands of empty segments came before the bound (one round trip is ~0.25 ms).
    let segments = o.requests.iter().filter(|r| r[0] >> 5 == 3).count();
    assert!(segments > 5_000, "{segments} segment requests");
    let text = e.to_string();
    for want in [
        "SDO 0x2000:01",
        "an upload not finished after 3",
        "the server kept answering",
        "0 of the 100 bytes announced",
        "sent abort 0x05040000, SDO protocol timed out",
    ] {
        assert!(text.contains(want), "{want:?} not in {text:?}");
    }
    // The client is free for the next transfer.
    assert!(!client.busy());
    println!(
        "empty segments: aborted after {} ms of bus time, {segments} segments",
        o.took.0 / 1_000_000
    );
}

#[test]
fn transfer_bound_is_a_setting() {
    let mut client = SdoClient::new(NODE);
    client.set_transfer_timeout(Nanos(250_000_000));
    let o = upload(Hostile::EmptySegments, &mut client);
    assert!(matches!(o.result, Err(SdoError::TransferTimeout { .. })));
    assert!(
        o.took.0 >= 250_000_000 && o.took.0 < 255_000_000,
        "{}",
        o.took.0
    );
    assert_eq!(last_abort(&o.requests).2, 0x0504_0000);
}

#[test]
fn a_segment_beyond_the_announced_size_aborts_06070012() {
    let mut client = SdoClient::new(NODE);
    let o = upload(Hostile::MoreThanAnnounced, &mut client);
    let e = o.result.expect_err("more data than announced must fail");
    let text = e.to_string();
    assert!(text.contains("0x06070012"), "{text}");
    assert!(
        text.contains("SDO 0x2000:01") || text.contains("0x2000:01"),
        "{text}"
    );
    assert_eq!(last_abort(&o.requests), (0x2000, 1, 0x0607_0012));
    // Initiate, two segments (7 bytes, then 14 > 10), abort.
    assert_eq!(o.requests.len(), 4, "{:02x?}", o.requests);
}

#[test]
fn an_unsized_upload_stops_at_the_byte_cap_with_abort_05040005() {
    let mut client = SdoClient::new(NODE);
    client.set_max_size(700);
    client.set_transfer_timeout(Nanos(3_600_000_000_000));
    let o = upload(Hostile::EndlessUnsized, &mut client);
    let e = o.result.expect_err("an endless unsized upload must fail");
    let text = e.to_string();
    assert!(text.contains("0x05040005"), "{text}");
    assert_eq!(last_abort(&o.requests), (0x2000, 1, 0x0504_0005));
    // 100 segments of 7 bytes fit 700 bytes; the 101st is refused.
    let segments = o.requests.iter().filter(|r| r[0] >> 5 == 3).count();
    assert_eq!(segments, 101);
}
