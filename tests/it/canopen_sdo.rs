//! SDO client and server (CiA 301 §7.2.4): byte fixtures derived by hand from the protocol
//! tables (`notes/canopen.md` §6.4 / §6.5), client ↔ server round trips in memory over a tiny
//! object dictionary, and property tests (random frames, random frame loss).
//!
//! All fixtures are node 5: requests on 0x605, responses on 0x585.

use std::collections::{BTreeMap, VecDeque};

use fieldprobe::bus::can::CanFrame;
use fieldprobe::bus::canopen::sdo::{
    ObjectAccess, SdoClient, SdoError, SdoServer, TransferMode, SDO_RX_BASE, SDO_TX_BASE,
};
use fieldprobe::units::Nanos;
use proptest::prelude::*;

const NODE: u8 = 5;
const REQ: u16 = 0x605;
const RESP: u16 = 0x585;

const fn ms(v: u64) -> Nanos {
    Nanos(v * 1_000_000)
}

/// "fieldprobe", the device name 0x1008:00 of the test dictionary (10 bytes).
const NAME: &[u8] = b"fieldprobe";

/// A tiny object dictionary: 0x1000:00 device type (read-only), 0x1008:00 device name,
/// 0x2001:00 write-only, 0x2000..0x2FFF writable; everything else does not exist.
#[derive(Default)]
struct Od {
    objs: BTreeMap<(u16, u8), Vec<u8>>,
}

impl Od {
    fn new() -> Self {
        let mut objs = BTreeMap::new();
        objs.insert((0x1000, 0), vec![0x92, 0x01, 0x02, 0x00]);
        objs.insert((0x1008, 0), NAME.to_vec());
        Od { objs }
    }
}

impl ObjectAccess for Od {
    fn read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        if index == 0x2001 {
            return Err(0x0601_0001);
        }
        self.objs.get(&(index, sub)).cloned().ok_or(0x0602_0000)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        match index {
            0x1000 => Err(0x0601_0002),
            0x2000..=0x2FFF => {
                self.objs.insert((index, sub), data.to_vec());
                Ok(())
            }
            _ => Err(0x0602_0000),
        }
    }
}

fn f(id: u16, data: [u8; 8]) -> CanFrame {
    CanFrame::new(id, &data).unwrap()
}

/// Asserts the frames (COB-ID, 8 data bytes each).
#[track_caller]
fn expect(got: Vec<CanFrame>, want: &[(u16, [u8; 8])]) {
    let got: Vec<(u32, Vec<u8>)> = got.iter().map(|f| (f.id, f.payload().to_vec())).collect();
    let want: Vec<(u32, Vec<u8>)> = want
        .iter()
        .map(|(i, d)| (u32::from(*i), d.to_vec()))
        .collect();
    assert_eq!(got, want);
}

/// Server receives a request and must answer with exactly `want`.
macro_rules! server {
    ($s:expr, $od:expr, $now:expr, [$($b:expr),*] => [$([$($r:expr),*]),*]) => {
        expect($s.handle(&f(REQ, [$($b),*]), &mut $od, $now), &[$((RESP, [$($r),*])),*])
    };
}

/// Client receives a response and must send exactly `want`.
macro_rules! client {
    ($c:expr, $now:expr, [$($b:expr),*] => [$([$($r:expr),*]),*]) => {
        expect($c.handle(&f(RESP, [$($b),*]), $now), &[$((REQ, [$($r),*])),*])
    };
}

/// Client and server in memory, frames passed directly; `drop` decides per frame (in order
/// of transmission, both directions) whether it is lost.
struct Pair {
    client: SdoClient,
    server: SdoServer,
    od: Od,
    now: Nanos,
    sent: usize,
    frames: Vec<CanFrame>,
}

impl Pair {
    fn new() -> Self {
        Pair {
            client: SdoClient::new(NODE),
            server: SdoServer::new(NODE),
            od: Od::new(),
            now: Nanos::ZERO,
            sent: 0,
            frames: Vec::new(),
        }
    }

    fn run(&mut self, first: Vec<CanFrame>) -> Result<Vec<u8>, SdoError> {
        self.run_lossy(first, &mut |_| false)
    }

    fn run_lossy(
        &mut self,
        first: Vec<CanFrame>,
        drop: &mut dyn FnMut(usize) -> bool,
    ) -> Result<Vec<u8>, SdoError> {
        let mut to_server: VecDeque<CanFrame> = VecDeque::new();
        let mut to_client: VecDeque<CanFrame> = VecDeque::new();
        let mut deliver = |q: &mut VecDeque<CanFrame>, fs: Vec<CanFrame>, p: &mut Pair| {
            for fr in fs {
                p.frames.push(fr);
                p.sent += 1;
                if !drop(p.sent - 1) {
                    q.push_back(fr);
                }
            }
        };
        deliver(&mut to_server, first, self);
        let mut result = None;
        for _ in 0..200_000 {
            if result.is_none() {
                result = self.client.take_result();
            }
            while let Some(fr) = to_server.pop_front() {
                let out = self.server.handle(&fr, &mut self.od, self.now);
                deliver(&mut to_client, out, self);
            }
            while let Some(fr) = to_client.pop_front() {
                let out = self.client.handle(&fr, self.now);
                deliver(&mut to_server, out, self);
            }
            if to_server.is_empty() && to_client.is_empty() {
                // the frames sent with the result (e.g. the block end response) are delivered
                if let Some(r) = result {
                    return r;
                }
                self.now = self.now.saturating_add(ms(1));
                let out = self.client.poll(self.now);
                deliver(&mut to_server, out, self);
                let out = self.server.poll(self.now);
                deliver(&mut to_client, out, self);
            }
        }
        panic!("transfer neither finished nor timed out");
    }

    fn upload(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoError> {
        let first = self.client.upload(index, sub, self.now);
        self.run(first)
    }

    fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<Vec<u8>, SdoError> {
        let first = self.client.download(index, sub, data, self.now);
        self.run(first)
    }
}

fn pattern(len: usize) -> Vec<u8> {
    (0..len).map(|i| (i * 7 + 3) as u8).collect()
}

/// Bit-by-bit CRC-16 (poly 0x1021, init 0, MSB first), independent of the table code.
fn crc_bitwise(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &byte in data {
        for bit in (0..8).rev() {
            let inp = (byte >> bit) & 1 == 1;
            let top = crc & 0x8000 != 0;
            crc <<= 1;
            if inp != top {
                crc ^= 0x1021;
            }
        }
    }
    crc
}

// ---------------------------------------------------------------------------------------
// Byte fixtures

#[test]
fn cob_ids() {
    assert_eq!(SDO_TX_BASE + u16::from(NODE), RESP);
    assert_eq!(SDO_RX_BASE + u16::from(NODE), REQ);
    let c = SdoClient::new(NODE);
    assert_eq!(c.node(), NODE);
}

#[test]
fn expedited_upload_fixture() {
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    // 605: 40 | 00 10 | 00  initiate upload 0x1000:00
    expect(
        c.upload(0x1000, 0, Nanos::ZERO),
        &[(REQ, [0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0])],
    );
    // 585: 43 (010 0 00 1 1: expedited, 4 bytes) | 0x1000:00 | 0x00020192
    server!(s, od, Nanos::ZERO, [0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]
        => [[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]]);
    assert!(!s.busy());
    client!(c, Nanos::ZERO, [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00] => []);
    assert!(!c.busy());
    assert_eq!(c.take_result(), Some(Ok(vec![0x92, 0x01, 0x02, 0x00])));
    assert_eq!(c.take_result(), None);
}

#[test]
fn expedited_upload_sizes_fixture() {
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    od.objs.insert((0x2000, 1), vec![0xAB]);
    od.objs.insert((0x2000, 2), vec![0x34, 0x12]);
    od.objs.insert((0x2000, 3), vec![1, 2, 3]);
    // 4F = 010 0 11 1 1: 1 byte; 4B: 2 bytes; 47: 3 bytes
    server!(s, od, Nanos::ZERO, [0x40, 0x00, 0x20, 0x01, 0, 0, 0, 0]
        => [[0x4F, 0x00, 0x20, 0x01, 0xAB, 0, 0, 0]]);
    server!(s, od, Nanos::ZERO, [0x40, 0x00, 0x20, 0x02, 0, 0, 0, 0]
        => [[0x4B, 0x00, 0x20, 0x02, 0x34, 0x12, 0, 0]]);
    server!(s, od, Nanos::ZERO, [0x40, 0x00, 0x20, 0x03, 0, 0, 0, 0]
        => [[0x47, 0x00, 0x20, 0x03, 1, 2, 3, 0]]);

    // Client side, n bytes indicated: 4B 0x6041:00 → 2 bytes
    let mut c = SdoClient::new(NODE);
    c.upload(0x6041, 0, Nanos::ZERO);
    client!(c, Nanos::ZERO, [0x4B, 0x41, 0x60, 0x00, 0x37, 0x06, 0xEE, 0xEE] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![0x37, 0x06])));
    // Without size: 42 (e = 1, s = 0): all four bytes
    c.upload(0x6041, 0, Nanos::ZERO);
    client!(c, Nanos::ZERO, [0x42, 0x41, 0x60, 0x00, 1, 2, 3, 4] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![1, 2, 3, 4])));
}

#[test]
fn expedited_download_fixture() {
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    // 2F = 001 0 11 1 1: 1 byte
    expect(
        c.download(0x2000, 1, &[0x7F], Nanos::ZERO),
        &[(REQ, [0x2F, 0x00, 0x20, 0x01, 0x7F, 0, 0, 0])],
    );
    server!(s, od, Nanos::ZERO, [0x2F, 0x00, 0x20, 0x01, 0x7F, 0, 0, 0]
        => [[0x60, 0x00, 0x20, 0x01, 0, 0, 0, 0]]);
    assert_eq!(od.objs[&(0x2000, 1)], vec![0x7F]);
    client!(c, Nanos::ZERO, [0x60, 0x00, 0x20, 0x01, 0, 0, 0, 0] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![])));

    // 2B: 2 bytes, 27: 3 bytes, 23: 4 bytes
    expect(
        c.download(0x2000, 2, &[0x0F, 0x00], Nanos::ZERO),
        &[(REQ, [0x2B, 0x00, 0x20, 0x02, 0x0F, 0x00, 0, 0])],
    );
    client!(c, Nanos::ZERO, [0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0] => []);
    expect(
        c.download(0x2000, 3, &[1, 2, 3], Nanos::ZERO),
        &[(REQ, [0x27, 0x00, 0x20, 0x03, 1, 2, 3, 0])],
    );
    client!(c, Nanos::ZERO, [0x60, 0x00, 0x20, 0x03, 0, 0, 0, 0] => []);
    // notes §6.6 capture: 605: 23 00 18 01 85 01 00 80 (COB-ID 0x80000185 to 0x1800:01)
    expect(
        c.download(0x1800, 1, &0x8000_0185u32.to_le_bytes(), Nanos::ZERO),
        &[(REQ, [0x23, 0x00, 0x18, 0x01, 0x85, 0x01, 0x00, 0x80])],
    );

    // Server, expedited without size (22 = 001 0 00 1 0): all four bytes written
    server!(s, od, Nanos::ZERO, [0x22, 0x00, 0x20, 0x04, 0x11, 0x22, 0x33, 0x44]
        => [[0x60, 0x00, 0x20, 0x04, 0, 0, 0, 0]]);
    assert_eq!(od.objs[&(0x2000, 4)], vec![0x11, 0x22, 0x33, 0x44]);
    // 2B to 0x2000:05: two bytes
    server!(s, od, Nanos::ZERO, [0x2B, 0x00, 0x20, 0x05, 0x11, 0x22, 0x33, 0x44]
        => [[0x60, 0x00, 0x20, 0x05, 0, 0, 0, 0]]);
    assert_eq!(od.objs[&(0x2000, 5)], vec![0x11, 0x22]);
}

#[test]
fn segmented_upload_fixture() {
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    c.upload(0x1008, 0, t);
    // 41 = 010 0 00 0 1: segmented, size 10
    server!(s, od, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    client!(c, t, [0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0] => [[0x60, 0, 0, 0, 0, 0, 0, 0]]);
    // 00 = 000 0 000 0: toggle 0, 7 bytes "fieldpr", more to come
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r']]);
    client!(c, t, [0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r'] => [[0x70, 0, 0, 0, 0, 0, 0, 0]]);
    // 19 = 000 1 100 1: toggle 1, n = 4 unused, last: "obe"
    server!(s, od, t, [0x70, 0, 0, 0, 0, 0, 0, 0] => [[0x19, b'o', b'b', b'e', 0, 0, 0, 0]]);
    assert!(!s.busy());
    client!(c, t, [0x19, b'o', b'b', b'e', 0, 0, 0, 0] => []);
    assert_eq!(c.take_result(), Some(Ok(NAME.to_vec())));

    // Segmented upload without size indication (40): the client follows the segments
    c.upload(0x1008, 0, t);
    client!(c, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x60, 0, 0, 0, 0, 0, 0, 0]]);
    // 0D = 000 0 110 1: one byte, last
    client!(c, t, [0x0D, 0x42, 0, 0, 0, 0, 0, 0] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![0x42])));

    // Empty object: size 0, one segment 0F = 000 0 111 1 (no data, last)
    od.objs.insert((0x2000, 9), vec![]);
    server!(s, od, t, [0x40, 0x00, 0x20, 0x09, 0, 0, 0, 0] => [[0x41, 0x00, 0x20, 0x09, 0, 0, 0, 0]]);
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x0F, 0, 0, 0, 0, 0, 0, 0]]);
}

#[test]
fn segmented_download_fixture() {
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    // 21 = 001 0 00 0 1: segmented, size 10 follows
    expect(
        c.download(0x2000, 2, NAME, t),
        &[(REQ, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0])],
    );
    server!(s, od, t, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0] => [[0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0]]);
    // first segment: 00 = toggle 0, n = 0, not last
    client!(c, t, [0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0] => [[0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r']]);
    server!(s, od, t, [0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r'] => [[0x20, 0, 0, 0, 0, 0, 0, 0]]);
    // 19 = 000 1 100 1
    client!(c, t, [0x20, 0, 0, 0, 0, 0, 0, 0] => [[0x19, b'o', b'b', b'e', 0, 0, 0, 0]]);
    server!(s, od, t, [0x19, b'o', b'b', b'e', 0, 0, 0, 0] => [[0x30, 0, 0, 0, 0, 0, 0, 0]]);
    client!(c, t, [0x30, 0, 0, 0, 0, 0, 0, 0] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![])));
    assert_eq!(od.objs[&(0x2000, 2)], NAME.to_vec());

    // 0 bytes: size 0, then 0F (n = 7, last)
    expect(
        c.download(0x2000, 3, &[], t),
        &[(REQ, [0x21, 0x00, 0x20, 0x03, 0, 0, 0, 0])],
    );
    client!(c, t, [0x60, 0x00, 0x20, 0x03, 0, 0, 0, 0] => [[0x0F, 0, 0, 0, 0, 0, 0, 0]]);
    // Segmented mode forces segments for 2 bytes: 21 .. size 2, then 0B (n = 5, last)
    c.set_mode(TransferMode::Segmented);
    client!(c, t, [0x20, 0, 0, 0, 0, 0, 0, 0] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![])));
    expect(
        c.download(0x2000, 3, &[0xAA, 0xBB], t),
        &[(REQ, [0x21, 0x00, 0x20, 0x03, 0x02, 0, 0, 0])],
    );
    client!(c, t, [0x60, 0x00, 0x20, 0x03, 0, 0, 0, 0] => [[0x0B, 0xAA, 0xBB, 0, 0, 0, 0, 0]]);

    // Server, segmented without size (20)
    server!(s, od, t, [0x20, 0x00, 0x20, 0x06, 0, 0, 0, 0] => [[0x60, 0x00, 0x20, 0x06, 0, 0, 0, 0]]);
    server!(s, od, t, [0x0B, 0xAA, 0xBB, 0, 0, 0, 0, 0] => [[0x20, 0, 0, 0, 0, 0, 0, 0]]);
    assert_eq!(od.objs[&(0x2000, 6)], vec![0xAA, 0xBB]);
}

#[test]
fn toggle_errors_abort_05030000() {
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    // Server: first download segment with toggle 1 → 80 00 20 02 | 00 00 03 05
    server!(s, od, t, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0] => [[0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0]]);
    server!(s, od, t, [0x10, 1, 2, 3, 4, 5, 6, 7] => [[0x80, 0x00, 0x20, 0x02, 0x00, 0x00, 0x03, 0x05]]);
    assert!(!s.busy());
    // Server: upload segment request repeated with the same toggle
    server!(s, od, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r']]);
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x03, 0x05]]);

    // Client: upload segment with toggle 1 first
    let mut c = SdoClient::new(NODE);
    c.upload(0x1008, 0, t);
    client!(c, t, [0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0] => [[0x60, 0, 0, 0, 0, 0, 0, 0]]);
    client!(c, t, [0x10, 1, 2, 3, 4, 5, 6, 7] => [[0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x03, 0x05]]);
    let e = c.take_result().unwrap().unwrap_err();
    assert!(matches!(e, SdoError::Protocol(_)));
    assert!(e.to_string().contains("toggle bit not alternated"), "{e}");
    // Client: download segment response with the wrong toggle
    c.download(0x2000, 2, NAME, t);
    client!(c, t, [0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0] => [[0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r']]);
    client!(c, t, [0x30, 0, 0, 0, 0, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x02, 0x00, 0x00, 0x03, 0x05]]);
    assert!(c.take_result().unwrap().is_err());
}

#[test]
fn block_download_fixture() {
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    c.set_mode(TransferMode::Block);
    // C6 = 110 00 1 1 0: block download, client CRC, size 10
    expect(
        c.download(0x2000, 3, NAME, t),
        &[(REQ, [0xC6, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0])],
    );
    // A4 = 101 00 1 00: server CRC, blksize 127
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0] => [[0xA4, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]]);
    // seq 1 "fieldpr", seq 2 with c: 82 "obe"
    client!(c, t, [0xA4, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0] => [
        [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r'],
        [0x82, b'o', b'b', b'e', 0, 0, 0, 0]
    ]);
    server!(s, od, t, [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r'] => []);
    // ack: A2, ackseq 2, blksize 127
    server!(s, od, t, [0x82, b'o', b'b', b'e', 0, 0, 0, 0] => [[0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0]]);
    // end: D1 = 110 100 01 (n = 4 unused in the last segment), CRC 0x2B15 of "fieldprobe"
    client!(c, t, [0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0] => [[0xD1, 0x15, 0x2B, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xD1, 0x15, 0x2B, 0, 0, 0, 0, 0] => [[0xA1, 0, 0, 0, 0, 0, 0, 0]]);
    assert_eq!(od.objs[&(0x2000, 3)], NAME.to_vec());
    client!(c, t, [0xA1, 0, 0, 0, 0, 0, 0, 0] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![])));
    assert!(!s.busy());
}

#[test]
fn block_upload_fixture() {
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    c.set_mode(TransferMode::Block);
    // A4 = 101 00 1 00: block upload, client CRC; blksize 127, pst 0
    expect(
        c.upload(0x1008, 0, t),
        &[(REQ, [0xA4, 0x08, 0x10, 0x00, 0x7F, 0x00, 0, 0])],
    );
    // C6 = 110 00 1 1 0: server CRC, size 10
    server!(s, od, t, [0xA4, 0x08, 0x10, 0x00, 0x7F, 0x00, 0, 0] => [[0xC6, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    client!(c, t, [0xC6, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0] => [[0xA3, 0, 0, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xA3, 0, 0, 0, 0, 0, 0, 0] => [
        [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r'],
        [0x82, b'o', b'b', b'e', 0, 0, 0, 0]
    ]);
    client!(c, t, [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r'] => []);
    client!(c, t, [0x82, b'o', b'b', b'e', 0, 0, 0, 0] => [[0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0] => [[0xD1, 0x15, 0x2B, 0, 0, 0, 0, 0]]);
    client!(c, t, [0xD1, 0x15, 0x2B, 0, 0, 0, 0, 0] => [[0xA1, 0, 0, 0, 0, 0, 0, 0]]);
    assert_eq!(c.take_result(), Some(Ok(NAME.to_vec())));
    server!(s, od, t, [0xA1, 0, 0, 0, 0, 0, 0, 0] => []);
    assert!(!s.busy());
}

#[test]
fn block_download_retransmits_from_first_lost_segment() {
    // 30 bytes 00..1D = 5 segments; the server takes blocks of 4.
    let data: Vec<u8> = (0u8..30).collect();
    let mut c = SdoClient::new(NODE);
    let mut s = SdoServer::new(NODE);
    s.set_block_size(4);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    c.set_mode(TransferMode::Block);
    expect(
        c.download(0x2000, 7, &data, t),
        &[(REQ, [0xC6, 0x00, 0x20, 0x07, 0x1E, 0, 0, 0])],
    );
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x07, 0x1E, 0, 0, 0] => [[0xA4, 0x00, 0x20, 0x07, 0x04, 0, 0, 0]]);
    client!(c, t, [0xA4, 0x00, 0x20, 0x07, 0x04, 0, 0, 0] => [
        [0x01, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06],
        [0x02, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D],
        [0x03, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14],
        [0x04, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B]
    ]);
    server!(s, od, t, [0x01, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06] => []);
    // seq 2 lost; 3 is out of order; 4 = blksize closes the block: ackseq 1
    server!(s, od, t, [0x03, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14] => []);
    server!(s, od, t, [0x04, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B] => [[0xA2, 0x01, 0x04, 0, 0, 0, 0, 0]]);
    // the client starts the next block with the second segment, renumbered from 1
    client!(c, t, [0xA2, 0x01, 0x04, 0, 0, 0, 0, 0] => [
        [0x01, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D],
        [0x02, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14],
        [0x03, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B],
        [0x84, 0x1C, 0x1D, 0, 0, 0, 0, 0]
    ]);
    server!(s, od, t, [0x01, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D] => []);
    server!(s, od, t, [0x02, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14] => []);
    server!(s, od, t, [0x03, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B] => []);
    server!(s, od, t, [0x84, 0x1C, 0x1D, 0, 0, 0, 0, 0] => [[0xA2, 0x04, 0x04, 0, 0, 0, 0, 0]]);
    // end: D5 = 110 101 01 (n = 5), CRC-16 of 00..1D = 0x1F11
    client!(c, t, [0xA2, 0x04, 0x04, 0, 0, 0, 0, 0] => [[0xD5, 0x11, 0x1F, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xD5, 0x11, 0x1F, 0, 0, 0, 0, 0] => [[0xA1, 0, 0, 0, 0, 0, 0, 0]]);
    assert_eq!(od.objs[&(0x2000, 7)], data);
    assert_eq!(crc_bitwise(&data), 0x1F11);
}

#[test]
fn block_upload_retransmits_from_first_lost_segment() {
    let data: Vec<u8> = (0u8..30).collect();
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Block);
    c.set_block_size(4);
    let t = Nanos::ZERO;
    expect(
        c.upload(0x2000, 7, t),
        &[(REQ, [0xA4, 0x00, 0x20, 0x07, 0x04, 0x00, 0, 0])],
    );
    client!(c, t, [0xC6, 0x00, 0x20, 0x07, 0x1E, 0, 0, 0] => [[0xA3, 0, 0, 0, 0, 0, 0, 0]]);
    client!(c, t, [0x01, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06] => []);
    client!(c, t, [0x02, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D] => []);
    // seq 3 lost
    client!(c, t, [0x04, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B] => [[0xA2, 0x02, 0x04, 0, 0, 0, 0, 0]]);
    client!(c, t, [0x01, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14] => []);
    client!(c, t, [0x02, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B] => []);
    client!(c, t, [0x83, 0x1C, 0x1D, 0, 0, 0, 0, 0] => [[0xA2, 0x03, 0x04, 0, 0, 0, 0, 0]]);
    client!(c, t, [0xD5, 0x11, 0x1F, 0, 0, 0, 0, 0] => [[0xA1, 0, 0, 0, 0, 0, 0, 0]]);
    assert_eq!(c.take_result(), Some(Ok(data.clone())));

    // The server side of the same exchange (block size 4 from the client)
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    od.objs.insert((0x2000, 7), data);
    server!(s, od, t, [0xA4, 0x00, 0x20, 0x07, 0x04, 0x00, 0, 0] => [[0xC6, 0x00, 0x20, 0x07, 0x1E, 0, 0, 0]]);
    server!(s, od, t, [0xA3, 0, 0, 0, 0, 0, 0, 0] => [
        [0x01, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06],
        [0x02, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D],
        [0x03, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14],
        [0x04, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B]
    ]);
    server!(s, od, t, [0xA2, 0x02, 0x04, 0, 0, 0, 0, 0] => [
        [0x01, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14],
        [0x02, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1A, 0x1B],
        [0x83, 0x1C, 0x1D, 0, 0, 0, 0, 0]
    ]);
    // an ackseq beyond the block: 80 .. 03 00 04 05 (invalid sequence number)
    server!(s, od, t, [0xA2, 0x04, 0x04, 0, 0, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x07, 0x03, 0x00, 0x04, 0x05]]);
}

#[test]
fn block_crc_negotiation_and_errors() {
    let t = Nanos::ZERO;
    // Client without CRC: C2 = 110 00 0 1 0; the server still says it supports CRC (A4),
    // the end carries CRC 0 and the server does not check it.
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Block);
    c.set_crc(false);
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    expect(
        c.download(0x2000, 3, NAME, t),
        &[(REQ, [0xC2, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0])],
    );
    server!(s, od, t, [0xC2, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0] => [[0xA4, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]]);
    c.handle(&f(RESP, [0xA4, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]), t);
    client!(c, t, [0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0] => [[0xD1, 0, 0, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r'] => []);
    server!(s, od, t, [0x82, b'o', b'b', b'e', 0, 0, 0, 0] => [[0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xD1, 0, 0, 0, 0, 0, 0, 0] => [[0xA1, 0, 0, 0, 0, 0, 0, 0]]);

    // Server without CRC answers A0 / C2; the client then sends CRC 0
    let mut s = SdoServer::new(NODE);
    s.set_crc(false);
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0] => [[0xA0, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]]);
    let mut s = SdoServer::new(NODE);
    s.set_crc(false);
    server!(s, od, t, [0xA4, 0x08, 0x10, 0x00, 0x7F, 0x00, 0, 0] => [[0xC2, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Block);
    c.download(0x2000, 3, NAME, t);
    c.handle(&f(RESP, [0xA0, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]), t);
    client!(c, t, [0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0] => [[0xD1, 0, 0, 0, 0, 0, 0, 0]]);

    // CRC mismatch at the server: 80 00 20 03 | 04 00 04 05
    let mut s = SdoServer::new(NODE);
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0] => [[0xA4, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]]);
    server!(s, od, t, [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r'] => []);
    server!(s, od, t, [0x82, b'o', b'b', b'e', 0, 0, 0, 0] => [[0xA2, 0x02, 0x7F, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xD1, 0x16, 0x2B, 0, 0, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x03, 0x04, 0x00, 0x04, 0x05]]);

    // CRC mismatch at the client (block upload): abort 0x05040004, protocol error
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Block);
    c.upload(0x1008, 0, t);
    c.handle(&f(RESP, [0xC6, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]), t);
    c.handle(
        &f(RESP, [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r']),
        t,
    );
    c.handle(&f(RESP, [0x82, b'o', b'b', b'e', 0, 0, 0, 0]), t);
    client!(c, t, [0xD1, 0x00, 0x00, 0, 0, 0, 0, 0] => [[0x80, 0x08, 0x10, 0x00, 0x04, 0x00, 0x04, 0x05]]);
    let e = c.take_result().unwrap().unwrap_err();
    assert!(e.to_string().contains("CRC"), "{e}");

    // Invalid block size from the server: abort 0x05040002
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Block);
    c.download(0x2000, 3, NAME, t);
    client!(c, t, [0xA4, 0x00, 0x20, 0x03, 0x80, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x03, 0x02, 0x00, 0x04, 0x05]]);
    // ... and from the client at the server
    let mut s = SdoServer::new(NODE);
    server!(s, od, t, [0xA4, 0x08, 0x10, 0x00, 0x00, 0x00, 0, 0] => [[0x80, 0x08, 0x10, 0x00, 0x02, 0x00, 0x04, 0x05]]);
}

#[test]
fn crc_of_known_strings() {
    use fieldprobe::bus::canopen::sdo::crc16_ccitt;
    // CRC-16/XMODEM check value
    assert_eq!(crc_bitwise(b"123456789"), 0x31C3);
    assert_eq!(crc16_ccitt(b"123456789"), 0x31C3);
    assert_eq!(crc_bitwise(NAME), 0x2B15);
    for len in [0usize, 1, 7, 100, 889] {
        let d = pattern(len);
        assert_eq!(crc16_ccitt(&d), crc_bitwise(&d), "len {len}");
    }
}

// ---------------------------------------------------------------------------------------
// Aborts, errors, timeouts

#[test]
fn server_aborts_and_client_reports() {
    let mut p = Pair::new();
    // 0x6072:00 does not exist: 585: 80 72 60 00 | 00 00 02 06
    let first = p.client.upload(0x6072, 0, p.now);
    server!(p.server, p.od, p.now, [0x40, 0x72, 0x60, 0x00, 0, 0, 0, 0] => [[0x80, 0x72, 0x60, 0x00, 0x00, 0x00, 0x02, 0x06]]);
    let e = p.run(first).unwrap_err();
    assert_eq!(
        e,
        SdoError::Abort {
            index: 0x6072,
            sub: 0,
            code: 0x0602_0000,
            text: "object does not exist in the object dictionary"
        }
    );
    assert_eq!(
        e.to_string(),
        "SDO 0x6072:00 aborted by the server: 0x06020000 object does not exist in the object dictionary"
    );
    // write to a read-only object: 0x06010002
    let e = p.download(0x1000, 0, &[1, 2, 3, 4]).unwrap_err();
    assert!(matches!(
        e,
        SdoError::Abort {
            code: 0x0601_0002,
            ..
        }
    ));
    assert!(
        e.to_string()
            .contains("attempt to write a read-only object"),
        "{e}"
    );
    // read of a write-only object, every upload kind
    for mode in [TransferMode::Auto, TransferMode::Block] {
        p.client.set_mode(mode);
        let e = p.upload(0x2001, 0).unwrap_err();
        assert!(
            matches!(
                e,
                SdoError::Abort {
                    code: 0x0601_0001,
                    ..
                }
            ),
            "{e}"
        );
    }
    // segmented download refused at the end (write error after the last segment)
    p.client.set_mode(TransferMode::Segmented);
    let e = p.download(0x3000, 1, &pattern(20)).unwrap_err();
    assert!(
        matches!(
            e,
            SdoError::Abort {
                code: 0x0602_0000,
                ..
            }
        ),
        "{e}"
    );
    p.client.set_mode(TransferMode::Block);
    let e = p.download(0x3000, 1, &pattern(20)).unwrap_err();
    assert!(
        matches!(
            e,
            SdoError::Abort {
                code: 0x0602_0000,
                ..
            }
        ),
        "{e}"
    );
    assert!(!p.server.busy());
}

#[test]
fn client_abort_ends_server_transfer() {
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    server!(s, od, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    assert!(s.busy());
    // client abort 0x08000000 (general error): no answer, server idle
    server!(s, od, t, [0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x00, 0x08] => []);
    assert!(!s.busy());
    // an abort inside a block download sub-block (80 is not a segment)
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x03, 0x0A, 0, 0, 0] => [[0xA4, 0x00, 0x20, 0x03, 0x7F, 0, 0, 0]]);
    server!(s, od, t, [0x80, 0x00, 0x20, 0x03, 0x00, 0x00, 0x00, 0x08] => []);
    assert!(!s.busy());
    // a following segment is now unexpected: abort 0x05040001 (mux 0:0, segments have none)
    server!(s, od, t, [0x00, 1, 2, 3, 4, 5, 6, 7] => [[0x80, 0x00, 0x00, 0x00, 0x01, 0x00, 0x04, 0x05]]);
}

#[test]
fn unknown_command_specifier_aborts_05040001() {
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    // ccs 7: E0 → 80 00 10 00 | 01 00 04 05
    server!(s, od, t, [0xE0, 0x00, 0x10, 0x00, 0, 0, 0, 0] => [[0x80, 0x00, 0x10, 0x00, 0x01, 0x00, 0x04, 0x05]]);
    // mid-transfer: abort names the running transfer, which ends
    server!(s, od, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    server!(s, od, t, [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF] => [[0x80, 0x08, 0x10, 0x00, 0x01, 0x00, 0x04, 0x05]]);
    assert!(!s.busy());
    // upload segment request while idle
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x80, 0x00, 0x00, 0x00, 0x01, 0x00, 0x04, 0x05]]);

    // Client: scs 7 from the server → abort 0x05040001 + protocol error
    let mut c = SdoClient::new(NODE);
    c.upload(0x1000, 0, t);
    client!(c, t, [0xE0, 0x00, 0x10, 0x00, 0, 0, 0, 0] => [[0x80, 0x00, 0x10, 0x00, 0x01, 0x00, 0x04, 0x05]]);
    let e = c.take_result().unwrap().unwrap_err();
    assert!(
        e.to_string()
            .contains("command specifier not valid or unknown"),
        "{e}"
    );
}

#[test]
fn wrong_multiplexer_is_a_protocol_error() {
    let t = Nanos::ZERO;
    let mut c = SdoClient::new(NODE);
    c.upload(0x1000, 0, t);
    // response names 0x1001:00; client aborts 0x08000000 for the object it asked for
    client!(c, t, [0x4F, 0x01, 0x10, 0x00, 0x00, 0, 0, 0] => [[0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x00, 0x08]]);
    let e = c.take_result().unwrap().unwrap_err();
    assert!(
        matches!(&e, SdoError::Protocol(m) if m.contains("0x1001:00") && m.contains("0x1000:00")),
        "{e}"
    );
    // same for downloads and block initiations
    c.download(0x2000, 1, &[1], t);
    client!(c, t, [0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x01, 0x00, 0x00, 0x00, 0x08]]);
    assert!(matches!(c.take_result(), Some(Err(SdoError::Protocol(_)))));
    c.set_mode(TransferMode::Block);
    c.upload(0x1008, 0, t);
    client!(c, t, [0xC6, 0x08, 0x10, 0x01, 0x0A, 0, 0, 0] => [[0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x00, 0x08]]);
    assert!(matches!(c.take_result(), Some(Err(SdoError::Protocol(_)))));
    // an abort for another object is stale and ignored; the transfer goes on
    c.set_mode(TransferMode::Auto);
    c.upload(0x1000, 0, t);
    client!(c, t, [0x80, 0x00, 0x20, 0x01, 0x00, 0x00, 0x02, 0x06] => []);
    assert!(c.busy());
    client!(c, t, [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00] => []);
    assert_eq!(c.take_result(), Some(Ok(vec![0x92, 0x01, 0x02, 0x00])));
    // frames of other nodes are ignored
    c.upload(0x1000, 0, t);
    expect(
        c.handle(&f(0x586, [0x43, 0x00, 0x10, 0x00, 1, 2, 3, 4]), t),
        &[],
    );
    assert!(c.busy());
}

#[test]
fn client_timeout_and_per_segment_restart() {
    let mut c = SdoClient::new(NODE);
    // default 500 ms per response
    c.upload(0x1000, 0, ms(1000));
    assert_eq!(c.next_deadline(), Some(ms(1500)));
    expect(c.poll(ms(1499)), &[]);
    // 80 00 10 00 | 00 00 04 05 (SDO protocol timed out)
    expect(
        c.poll(ms(1500)),
        &[(REQ, [0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x04, 0x05])],
    );
    let e = c.take_result().unwrap().unwrap_err();
    assert_eq!(
        e,
        SdoError::Timeout {
            index: 0x1000,
            sub: 0,
            after: ms(500)
        }
    );
    assert!(e.to_string().contains("0x1000:00"), "{e}");
    assert!(!c.busy());
    expect(c.poll(ms(5000)), &[]);

    // segmented upload with 400 ms between responses: every segment restarts the timer
    c.set_timeout(ms(450));
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let mut now = Nanos::ZERO;
    let mut out = c.upload(0x1008, 0, now);
    while c.busy() {
        now = now.saturating_add(ms(400));
        expect(c.poll(now), &[]);
        let mut next = Vec::new();
        for fr in &out {
            for r in s.handle(fr, &mut od, now) {
                next.extend(c.handle(&r, now));
            }
        }
        out = next;
    }
    assert_eq!(c.take_result(), Some(Ok(NAME.to_vec())));

    // block upload: each received segment restarts the timer
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Block);
    c.set_timeout(ms(100));
    c.upload(0x1008, 0, Nanos::ZERO);
    c.handle(&f(RESP, [0xC6, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]), ms(90));
    c.handle(
        &f(RESP, [0x01, b'f', b'i', b'e', b'l', b'd', b'p', b'r']),
        ms(180),
    );
    expect(c.poll(ms(270)), &[]);
    expect(
        c.poll(ms(280)),
        &[(REQ, [0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x04, 0x05])],
    );
    assert!(
        matches!(c.take_result(), Some(Err(SdoError::Timeout { after, .. })) if after == ms(100))
    );
}

#[test]
fn server_timeout_aborts_half_done_transfer() {
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    s.handle(
        &f(REQ, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0]),
        &mut od,
        ms(10),
    );
    assert!(s.busy());
    assert_eq!(s.next_deadline(), Some(ms(1010)));
    expect(s.poll(ms(1009)), &[]);
    expect(
        s.poll(ms(1010)),
        &[(RESP, [0x80, 0x00, 0x20, 0x02, 0x00, 0x00, 0x04, 0x05])],
    );
    assert!(!s.busy());
    assert_eq!(s.next_deadline(), None);
    // a segment restarts the server timer
    s.set_timeout(ms(100));
    s.handle(
        &f(REQ, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0]),
        &mut od,
        ms(0),
    );
    s.handle(&f(REQ, [0x00, 1, 2, 3, 4, 5, 6, 7]), &mut od, ms(90));
    expect(s.poll(ms(150)), &[]);
    assert_eq!(s.poll(ms(190)).len(), 1);
}

#[test]
fn new_request_while_busy() {
    let t = Nanos::ZERO;
    // Client refuses and keeps the running transfer
    let mut c = SdoClient::new(NODE);
    c.upload(0x1008, 0, t);
    expect(c.download(0x2000, 1, &[1], t), &[]);
    expect(c.upload(0x1000, 0, t), &[]);
    let e = c.take_result().unwrap().unwrap_err();
    assert_eq!(
        e.to_string(),
        "SDO protocol error: SDO client of node 5 is busy with an upload of 0x1008:00; download of 0x2000:01 refused"
    );
    assert!(matches!(c.take_result(), Some(Err(SdoError::Protocol(_)))));
    assert_eq!(c.take_result(), None);
    assert!(c.busy());
    client!(c, t, [0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0] => [[0x60, 0, 0, 0, 0, 0, 0, 0]]);

    // Server aborts the old transfer (0x05040001 for 0x2000:02) and serves the new request
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    server!(s, od, t, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0] => [[0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0]]);
    server!(s, od, t, [0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0] => [
        [0x80, 0x00, 0x20, 0x02, 0x01, 0x00, 0x04, 0x05],
        [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    ]);
    assert!(!s.busy());
    // a retry of the same object restarts silently
    server!(s, od, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r']]);
    server!(s, od, t, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0] => [[0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]]);
    server!(s, od, t, [0x60, 0, 0, 0, 0, 0, 0, 0] => [[0x00, b'f', b'i', b'e', b'l', b'd', b'p', b'r']]);
}

#[test]
fn expedited_mode_refuses_other_sizes() {
    let mut c = SdoClient::new(NODE);
    c.set_mode(TransferMode::Expedited);
    for len in [0usize, 5, 100] {
        expect(c.download(0x2000, 1, &pattern(len), Nanos::ZERO), &[]);
        let e = c.take_result().unwrap().unwrap_err();
        assert!(
            e.to_string()
                .contains("expedited download carries 1 … 4 bytes"),
            "{e}"
        );
        assert!(!c.busy());
    }
}

#[test]
fn length_checks() {
    let t = Nanos::ZERO;
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    // size 10 indicated, segment with c after 7 bytes: 0x06070013 (too low)
    server!(s, od, t, [0x21, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0] => [[0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0]]);
    server!(s, od, t, [0x01, 1, 2, 3, 4, 5, 6, 7] => [[0x80, 0x00, 0x20, 0x02, 0x13, 0x00, 0x07, 0x06]]);
    // size 3 indicated, 7 bytes sent: 0x06070012 (too high)
    server!(s, od, t, [0x21, 0x00, 0x20, 0x02, 0x03, 0, 0, 0] => [[0x60, 0x00, 0x20, 0x02, 0, 0, 0, 0]]);
    server!(s, od, t, [0x00, 1, 2, 3, 4, 5, 6, 7] => [[0x80, 0x00, 0x20, 0x02, 0x12, 0x00, 0x07, 0x06]]);
    // size beyond the limit: 0x05040005 out of memory
    s.set_max_size(100);
    server!(s, od, t, [0x21, 0x00, 0x20, 0x02, 0x65, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x02, 0x05, 0x00, 0x04, 0x05]]);
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x02, 0xFF, 0xFF, 0xFF, 0xFF] => [[0x80, 0x00, 0x20, 0x02, 0x05, 0x00, 0x04, 0x05]]);
    // block download: size 10 indicated, end says 2 bytes (n = 5 of 7): 0x06070010
    let mut s = SdoServer::new(NODE);
    server!(s, od, t, [0xC6, 0x00, 0x20, 0x02, 0x0A, 0, 0, 0] => [[0xA4, 0x00, 0x20, 0x02, 0x7F, 0, 0, 0]]);
    server!(s, od, t, [0x81, 1, 2, 0, 0, 0, 0, 0] => [[0xA2, 0x01, 0x7F, 0, 0, 0, 0, 0]]);
    server!(s, od, t, [0xD5, 0, 0, 0, 0, 0, 0, 0] => [[0x80, 0x00, 0x20, 0x02, 0x10, 0x00, 0x07, 0x06]]);
    // client: segmented upload shorter than indicated
    let mut c = SdoClient::new(NODE);
    c.upload(0x1008, 0, t);
    c.handle(&f(RESP, [0x41, 0x08, 0x10, 0x00, 0x0A, 0, 0, 0]), t);
    client!(c, t, [0x0D, 0x42, 0, 0, 0, 0, 0, 0] => []);
    assert!(
        matches!(c.take_result(), Some(Err(SdoError::Protocol(m))) if m.contains("1 bytes, 10 indicated"))
    );
}

#[test]
fn short_frames_are_padded() {
    // Some devices send 4-byte acks / aborts: 80 00 10 00 → code 0 fills with zeros.
    let mut c = SdoClient::new(NODE);
    c.upload(0x1000, 0, Nanos::ZERO);
    let out = c.handle(
        &CanFrame::new(RESP, &[0x80, 0x00, 0x10, 0x00]).unwrap(),
        Nanos::ZERO,
    );
    assert!(out.is_empty());
    assert!(matches!(
        c.take_result(),
        Some(Err(SdoError::Abort { code: 0, .. }))
    ));
    // an empty frame, an RTR and an extended frame on the COB-ID are not SDO frames
    let mut s = SdoServer::new(NODE);
    let mut od = Od::new();
    let t = Nanos::ZERO;
    assert!(s
        .handle(&CanFrame::new(REQ, &[]).unwrap(), &mut od, t)
        .is_empty());
    assert!(s
        .handle(&CanFrame::remote(REQ, 8).unwrap(), &mut od, t)
        .is_empty());
    assert!(s
        .handle(
            &CanFrame::new_extended(u32::from(REQ), &[0x40, 0, 0x10, 0]).unwrap(),
            &mut od,
            t
        )
        .is_empty());
}

// ---------------------------------------------------------------------------------------
// Round trips

const SIZES: [usize; 9] = [0, 1, 4, 5, 7, 8, 100, 889, 1000];

#[test]
fn round_trip_every_kind_and_size() {
    for mode in [
        TransferMode::Auto,
        TransferMode::Expedited,
        TransferMode::Segmented,
        TransferMode::Block,
    ] {
        for &len in &SIZES {
            let mut p = Pair::new();
            p.client.set_mode(mode);
            let data = pattern(len);
            let r = p.download(0x2000, 0x10, &data);
            if mode == TransferMode::Expedited && !(1..=4).contains(&len) {
                assert!(matches!(r, Err(SdoError::Protocol(_))), "{mode:?} {len}");
                continue;
            }
            assert_eq!(r, Ok(vec![]), "download {mode:?} {len}");
            assert_eq!(p.od.objs[&(0x2000, 0x10)], data, "download {mode:?} {len}");
            assert!(!p.server.busy());
            let r = p.upload(0x2000, 0x10);
            assert_eq!(r, Ok(data.clone()), "upload {mode:?} {len}");
            assert!(!p.server.busy(), "upload {mode:?} {len}");
            // first frame kinds: expedited iff 1..=4 bytes in the normal protocols
            let first_dl = p.frames[0].data[0];
            match mode {
                TransferMode::Block => assert_eq!(first_dl, 0xC6),
                TransferMode::Segmented => assert_eq!(first_dl, 0x21),
                _ if (1..=4).contains(&len) => assert_eq!(first_dl & 0x03, 0x03),
                _ => assert_eq!(first_dl, 0x21),
            }
        }
    }
}

#[test]
fn block_round_trip_small_blocks() {
    for blksize in [1u8, 2, 3, 127] {
        for &len in &SIZES {
            let mut p = Pair::new();
            p.client.set_mode(TransferMode::Block);
            p.client.set_block_size(blksize);
            p.server.set_block_size(blksize);
            let data = pattern(len);
            assert_eq!(p.download(0x2000, 1, &data), Ok(vec![]));
            assert_eq!(p.upload(0x2000, 1), Ok(data));
        }
    }
}

// ---------------------------------------------------------------------------------------
// Properties

fn any_frame() -> impl Strategy<Value = CanFrame> {
    (
        prop_oneof![Just(REQ), Just(RESP), 0u16..0x800],
        0usize..=8,
        any::<[u8; 8]>(),
        prop_oneof![
            Just(0u8),
            Just(0x40),
            Just(0x60),
            Just(0xA0),
            Just(0xC0),
            any::<u8>()
        ],
    )
        .prop_map(|(id, len, mut data, b0)| {
            if b0 != 0 {
                data[0] = (data[0] & 0x1F) | (b0 & 0xE0);
            }
            CanFrame::new(id, &data[..len]).unwrap()
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// The server never panics, answers only on its COB-ID with 8 bytes, and ends idle
    /// after its timeout whatever it was fed.
    #[test]
    fn server_survives_random_frames(frames in proptest::collection::vec(any_frame(), 0..60)) {
        let mut s = SdoServer::new(NODE);
        s.set_block_size(3);
        let mut od = Od::new();
        od.objs.insert((0x2000, 1), pattern(40));
        let mut now = Nanos::ZERO;
        for fr in &frames {
            now = now.saturating_add(ms(1));
            for out in s.handle(fr, &mut od, now).into_iter().chain(s.poll(now)) {
                prop_assert_eq!(out.id, u32::from(RESP));
                prop_assert_eq!(out.len, 8);
            }
        }
        s.poll(now.saturating_add(ms(2000)));
        prop_assert!(!s.busy());
    }

    /// The client never panics on random answers to any kind of request and finishes with
    /// one result (or stays busy until its timeout).
    #[test]
    fn client_survives_random_frames(
        mode in 0usize..4,
        download in any::<bool>(),
        frames in proptest::collection::vec(any_frame(), 0..40),
    ) {
        let modes = [TransferMode::Auto, TransferMode::Expedited, TransferMode::Segmented, TransferMode::Block];
        let mut c = SdoClient::new(NODE);
        c.set_mode(modes[mode]);
        c.set_block_size(3);
        let mut now = Nanos::ZERO;
        if download { c.download(0x2000, 1, &pattern(30), now); } else { c.upload(0x2000, 1, now); }
        for fr in &frames {
            now = now.saturating_add(ms(1));
            for out in c.handle(fr, now) {
                prop_assert_eq!(out.id, u32::from(REQ));
            }
        }
        c.poll(now.saturating_add(ms(1000)));
        prop_assert!(!c.busy());
        prop_assert!(c.take_result().is_some());
        prop_assert!(c.take_result().is_none());
    }

    /// Client ↔ server with random frame loss: always a result (correct data if Ok) or a
    /// timeout / abort, never a hang; the server ends idle.
    #[test]
    fn lossy_link_ends_in_result_or_timeout(
        mode in 0usize..4,
        download in any::<bool>(),
        len in 0usize..300,
        blksize in 1u8..=8,
        drops in proptest::collection::vec(proptest::bool::weighted(0.1), 0..200),
    ) {
        let modes = [TransferMode::Auto, TransferMode::Expedited, TransferMode::Segmented, TransferMode::Block];
        let mut p = Pair::new();
        p.client.set_mode(modes[mode]);
        p.client.set_block_size(blksize);
        p.server.set_block_size(blksize);
        let data = pattern(len);
        p.od.objs.insert((0x2000, 1), data.clone());
        let first = if download {
            p.client.download(0x2000, 2, &data, p.now)
        } else {
            p.client.upload(0x2000, 1, p.now)
        };
        let r = p.run_lossy(first, &mut |i| drops.get(i).copied().unwrap_or(false));
        match r {
            Ok(v) if download => {
                prop_assert!(v.is_empty());
                prop_assert_eq!(&p.od.objs[&(0x2000, 2)], &data);
            }
            Ok(v) => prop_assert_eq!(v, data),
            Err(SdoError::Timeout { .. } | SdoError::TransferTimeout { .. }) | Err(SdoError::Abort { .. }) => {}
            Err(SdoError::Protocol(m)) => {
                // loss alone never looks like a protocol violation; only the refused
                // expedited sizes end this way
                prop_assert!(m.contains("expedited download carries"), "{}", m);
            }
        }
        p.server.poll(p.now.saturating_add(ms(5000)));
        prop_assert!(!p.server.busy());
        prop_assert!(!p.client.busy());
    }

    /// Segmented and block transfers for every length around segment and block borders.
    #[test]
    fn round_trip_any_length(len in 0usize..1200, blksize in 1u8..=127, block in any::<bool>()) {
        let mut p = Pair::new();
        p.client.set_mode(if block { TransferMode::Block } else { TransferMode::Segmented });
        p.client.set_block_size(blksize);
        p.server.set_block_size(blksize);
        let data = pattern(len);
        prop_assert_eq!(p.download(0x2000, 3, &data), Ok(vec![]));
        prop_assert_eq!(p.upload(0x2000, 3), Ok(data));
    }
}

#[test]
fn lossy_block_transfers_recover_by_retransmission() {
    // frames: 0 initiate, 1 response, 2.. segments (download); drop the third segment
    let data = pattern(100);
    let mut p = Pair::new();
    p.client.set_mode(TransferMode::Block);
    let first = p.client.download(0x2000, 1, &data, p.now);
    assert_eq!(p.run_lossy(first, &mut |i| i == 4), Ok(vec![]));
    assert_eq!(p.od.objs[&(0x2000, 1)], data);
    // the ack after the loss: ackseq 2 of 15 segments, blksize 127
    assert!(p
        .frames
        .iter()
        .any(|f| f.id == u32::from(RESP) && f.data[..3] == [0xA2, 0x02, 0x7F]));
    // upload: 0 initiate, 1 response, 2 start, 3.. segments; drop the fifth segment
    let mut p = Pair::new();
    p.od.objs.insert((0x2000, 1), data.clone());
    p.client.set_mode(TransferMode::Block);
    let first = p.client.upload(0x2000, 1, p.now);
    assert_eq!(p.run_lossy(first, &mut |i| i == 7), Ok(data));
    assert!(p
        .frames
        .iter()
        .any(|f| f.id == u32::from(REQ) && f.data[..3] == [0xA2, 0x04, 0x7F]));
}
