//! CoE / SoE mailbox servers of the emulated ESC (`sim::esc::coe`, `sim::esc::soe`).
//!
//! Requests are built byte by byte from the spec layout (6-byte mailbox header: length u16,
//! address u16, channel/priority u8, type | counter << 4; CoE header u16 with the service in
//! bits 12..15; SDO command byte, index u16, sub u8, data) independently of the server code,
//! and the answers are checked byte by byte.

use fieldprobe::drive::catalogue;
use fieldprobe::drive::model::ds402::Ds402Model;
use fieldprobe::drive::model::sercos::SercosModel;
use fieldprobe::sim::esc::coe::{ds402_objects, Access, CoeServer, ObjectEntry};
use fieldprobe::sim::esc::soe::{sercos_idns, SoeServer};

const MBX: usize = 64;

fn ds402() -> Ds402Model {
    Ds402Model::new(&catalogue::builtin("cia402-generic").unwrap())
}

fn coe_server() -> CoeServer {
    let mut s = CoeServer::new(
        Box::new(ds402()),
        ds402_objects("fieldprobe test drive"),
        MBX,
    );
    let big: Vec<u8> = (0..300u32).map(|i| (i * 7 + 3) as u8).collect();
    s.insert(ObjectEntry::bytes(0x2000, 0, Access::Ro, &big, 0));
    s.insert(ObjectEntry::bytes(0x2001, 0, Access::Rw, b"", 200));
    s
}

/// Mailbox message: header + body, padded to the mailbox size like a master writes SM0.
fn mbx(ty: u8, counter: u8, body: &[u8]) -> Vec<u8> {
    let mut v = vec![
        body.len() as u8,
        (body.len() >> 8) as u8,
        0,
        0,
        0,
        ty | (counter << 4),
    ];
    v.extend_from_slice(body);
    v.resize(v.len().max(MBX), 0);
    v
}

/// CoE SDO request (service 2): CoE header 0x2000 LE = [0x00, 0x20].
fn sdo(counter: u8, cmd: u8, index: u16, sub: u8, data: &[u8]) -> Vec<u8> {
    let mut b = vec![0x00, 0x20, cmd, index as u8, (index >> 8) as u8, sub];
    b.extend_from_slice(data);
    if b.len() < 10 {
        b.resize(10, 0);
    }
    mbx(3, counter, &b)
}

/// Segment request (no index): CoE header, command byte, data (min. 7 bytes).
fn seg(counter: u8, cmd: u8, data: &[u8]) -> Vec<u8> {
    let mut b = vec![0x00, 0x20, cmd];
    b.extend_from_slice(data);
    if b.len() < 10 {
        b.resize(10, 0);
    }
    mbx(3, counter, &b)
}

fn len_of(reply: &[u8]) -> usize {
    usize::from(u16::from_le_bytes([reply[0], reply[1]]))
}

/// Check the mailbox header of a CoE reply and return the body (after the 6 bytes).
fn coe_body(reply: &[u8], counter: u8) -> &[u8] {
    assert_eq!(&reply[2..5], &[0, 0, 0], "address/channel");
    assert_eq!(reply[5], 0x03 | (counter << 4), "type CoE + counter");
    &reply[6..6 + len_of(reply)]
}

fn expect_abort(reply: &[u8], index: u16, sub: u8, code: u32) {
    let b = &reply[6..6 + len_of(reply)];
    assert_eq!(len_of(reply), 10);
    assert_eq!(reply[5] & 0x0F, 3);
    let mut want = vec![0x00, 0x20, 0x80, index as u8, (index >> 8) as u8, sub];
    want.extend_from_slice(&code.to_le_bytes());
    assert_eq!(b, &want[..], "abort {code:#010x}");
}

#[test]
fn expedited_upload_of_statusword() {
    let mut s = coe_server();
    let want = s.model().read_object(0x6041, 0).unwrap() as u16;
    let r = s.handle(&sdo(1, 0x40, 0x6041, 0, &[])).unwrap();
    assert_eq!(len_of(&r), 10);
    let b = coe_body(&r, 1);
    // SDO response (0x3000), expedited, size indicated, 2 unused bytes: 0x4B
    assert_eq!(&b[..6], &[0x00, 0x30, 0x4B, 0x41, 0x60, 0x00]);
    assert_eq!(u16::from_le_bytes([b[6], b[7]]), want);
    assert_eq!(&b[8..10], &[0, 0]);
    // Compare with the model directly (same model type, fresh instance).
    assert_eq!(i64::from(want), ds402().read_object(0x6041, 0).unwrap());

    // 4-byte object 0x1000 (constant) expedited with 0 unused: 0x43.
    let r = s.handle(&sdo(2, 0x40, 0x1000, 0, &[])).unwrap();
    let b = coe_body(&r, 2);
    assert_eq!(
        &b[..10],
        &[0x00, 0x30, 0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );

    // I8 object 0x6061: 3 unused bytes: 0x4F
    let r = s.handle(&sdo(3, 0x40, 0x6061, 0, &[])).unwrap();
    assert_eq!(coe_body(&r, 3)[2], 0x4F);
}

#[test]
fn normal_upload_of_device_name() {
    let mut s = coe_server();
    let r = s.handle(&sdo(1, 0x40, 0x1008, 0, &[])).unwrap();
    let name = b"fieldprobe test drive";
    assert_eq!(len_of(&r), 10 + name.len());
    let b = coe_body(&r, 1);
    assert_eq!(&b[..6], &[0x00, 0x30, 0x41, 0x08, 0x10, 0x00]);
    assert_eq!(
        u32::from_le_bytes([b[6], b[7], b[8], b[9]]) as usize,
        name.len()
    );
    assert_eq!(&b[10..], name);
}

#[test]
fn segmented_upload_toggles_and_last_flag() {
    let mut s = coe_server();
    let big: Vec<u8> = (0..300u32).map(|i| (i * 7 + 3) as u8).collect();
    let r = s.handle(&sdo(1, 0x40, 0x2000, 0, &[])).unwrap();
    assert_eq!(len_of(&r), 10, "initiate response carries the size only");
    let b = coe_body(&r, 1);
    assert_eq!(&b[..6], &[0x00, 0x30, 0x41, 0x00, 0x20, 0x00]);
    assert_eq!(u32::from_le_bytes([b[6], b[7], b[8], b[9]]), 300);

    let mut got = Vec::new();
    let mut toggle = 0u8;
    let mut counter = 1u8;
    let mut segments = 0;
    loop {
        counter = counter % 7 + 1;
        let r = s.handle(&seg(counter, 0x60 | (toggle << 4), &[])).unwrap();
        assert!(r.len() <= MBX, "segment fits the mailbox");
        let b = coe_body(&r, counter);
        assert_eq!(&b[..2], &[0x00, 0x30]);
        let cmd = b[2];
        assert_eq!(cmd >> 5, 0, "scs 0 (upload segment response)");
        assert_eq!((cmd >> 4) & 1, toggle, "toggle echoed");
        let unused = usize::from((cmd >> 1) & 7);
        let data = &b[3..];
        got.extend_from_slice(&data[..data.len() - unused]);
        segments += 1;
        if cmd & 1 == 1 {
            break;
        }
        assert!(segments < 20);
        toggle ^= 1;
    }
    // 64-byte mailbox: 64 - 6 - 2 - 1 = 55 bytes per segment → 5 full + 1 of 25
    assert_eq!(segments, 6);
    assert_eq!(got, big);

    // A segment request after the end: unknown command.
    let r = s.handle(&seg(5, 0x60, &[])).unwrap();
    expect_abort(&r, 0, 0, 0x0504_0001);
}

#[test]
fn segmented_upload_wrong_toggle_aborts() {
    let mut s = coe_server();
    s.handle(&sdo(1, 0x40, 0x2000, 0, &[])).unwrap();
    let r = s.handle(&seg(2, 0x70, &[])).unwrap(); // first toggle must be 0
    expect_abort(&r, 0x2000, 0, 0x0503_0000);
}

#[test]
fn short_last_segment_has_unused_count() {
    let mut s = coe_server();
    s.insert(ObjectEntry::bytes(0x2002, 0, Access::Ro, &[9; 58], 0));
    // normal would need 16 + 58 > 64: segmented, 55 + 3
    let r = s.handle(&sdo(1, 0x40, 0x2002, 0, &[])).unwrap();
    assert_eq!(len_of(&r), 10);
    let r = s.handle(&seg(2, 0x60, &[])).unwrap();
    assert_eq!(coe_body(&r, 2)[2], 0x00);
    assert_eq!(len_of(&r), 3 + 55);
    let r = s.handle(&seg(3, 0x70, &[])).unwrap();
    let b = coe_body(&r, 3);
    // toggle 1, 4 unused (3 data bytes padded to 7), last
    assert_eq!(b[2], 0x10 | (4 << 1) | 1);
    assert_eq!(&b[3..], &[9, 9, 9, 0, 0, 0, 0]);
}

#[test]
fn expedited_and_normal_download() {
    let mut s = coe_server();
    // expedited 2 bytes: 0x2B
    let r = s.handle(&sdo(1, 0x2B, 0x6040, 0, &[0x06, 0x00])).unwrap();
    assert_eq!(len_of(&r), 10);
    assert_eq!(
        coe_body(&r, 1),
        &[0x00, 0x30, 0x60, 0x40, 0x60, 0x00, 0, 0, 0, 0]
    );
    assert_eq!(s.model().read_object(0x6040, 0), Ok(6));
    // expedited 4 bytes: 0x23 to 0x607A (I32)
    let r = s
        .handle(&sdo(2, 0x23, 0x607A, 0, &(-5i32).to_le_bytes()))
        .unwrap();
    assert_eq!(coe_body(&r, 2)[2], 0x60);
    assert_eq!(s.model().read_object(0x607A, 0), Ok(-5));
    // normal download into a byte string: 0x21, size 5, data
    let mut d = 5u32.to_le_bytes().to_vec();
    d.extend_from_slice(b"hello");
    let r = s.handle(&sdo(3, 0x21, 0x2001, 0, &d)).unwrap();
    assert_eq!(coe_body(&r, 3)[2], 0x60);
    let r = s.handle(&sdo(4, 0x40, 0x2001, 0, &[])).unwrap();
    let b = coe_body(&r, 4);
    assert_eq!(b[2], 0x41);
    assert_eq!(&b[10..], b"hello");
}

#[test]
fn segmented_download() {
    let mut s = coe_server();
    let payload: Vec<u8> = (0..100u8).collect();
    let r = s
        .handle(&sdo(1, 0x21, 0x2001, 0, &100u32.to_le_bytes()))
        .unwrap();
    assert_eq!(
        coe_body(&r, 1),
        &[0x00, 0x30, 0x60, 0x01, 0x20, 0x00, 0, 0, 0, 0]
    );
    let parts = [
        (&payload[..40], 0u8, false),
        (&payload[40..80], 1, false),
        (&payload[80..], 0, true),
    ];
    for (k, (p, t, last)) in parts.iter().enumerate() {
        let c = k as u8 + 2;
        let cmd = (t << 4) | u8::from(*last);
        let r = s.handle(&seg(c, cmd, p)).unwrap();
        assert_eq!(len_of(&r), 10);
        // download segment response: scs 1, toggle echoed, 7 reserved bytes
        assert_eq!(
            coe_body(&r, c),
            &[0x00, 0x30, 0x20 | (t << 4), 0, 0, 0, 0, 0, 0, 0]
        );
    }
    let e = s.entries().iter().find(|e| e.index == 0x2001).unwrap();
    assert_eq!(e.data.as_deref(), Some(&payload[..]));

    // short last segment with the unused count: 3 bytes in a 7-byte segment (n = 4)
    s.handle(&sdo(5, 0x21, 0x2001, 0, &3u32.to_le_bytes()))
        .unwrap();
    let r = s
        .handle(&seg(6, (4 << 1) | 1, &[7, 8, 9, 0, 0, 0, 0]))
        .unwrap();
    assert_eq!(coe_body(&r, 6)[2], 0x20);
    let e = s.entries().iter().find(|e| e.index == 0x2001).unwrap();
    assert_eq!(e.data.as_deref(), Some(&[7u8, 8, 9][..]));

    // toggle error in the download
    s.handle(&sdo(7, 0x21, 0x2001, 0, &20u32.to_le_bytes()))
        .unwrap();
    let r = s.handle(&seg(1, 0x10, &[0; 10])).unwrap();
    expect_abort(&r, 0x2001, 0, 0x0503_0000);
    // wrong total length
    s.handle(&sdo(2, 0x21, 0x2001, 0, &20u32.to_le_bytes()))
        .unwrap();
    let r = s.handle(&seg(3, 0x01, &[0; 10])).unwrap();
    expect_abort(&r, 0x2001, 0, 0x0607_0010);
}

#[test]
fn abort_codes() {
    let mut s = coe_server();
    let r = s.handle(&sdo(1, 0x40, 0x1234, 0, &[])).unwrap();
    expect_abort(&r, 0x1234, 0, 0x0602_0000);
    let r = s.handle(&sdo(2, 0x40, 0x6041, 1, &[])).unwrap();
    expect_abort(&r, 0x6041, 1, 0x0609_0011);
    let r = s.handle(&sdo(3, 0x2B, 0x6041, 0, &[1, 0])).unwrap();
    expect_abort(&r, 0x6041, 0, 0x0601_0002);
    let r = s.handle(&sdo(4, 0x23, 0x6040, 0, &[1, 0, 0, 0])).unwrap();
    expect_abort(&r, 0x6040, 0, 0x0607_0010);
    let r = s.handle(&sdo(5, 0x2F, 0x6060, 0, &[99])).unwrap();
    expect_abort(&r, 0x6060, 0, 0x0609_0030);
    let r = s.handle(&sdo(6, 0xE0, 0x6041, 0, &[])).unwrap();
    expect_abort(&r, 0x6041, 0, 0x0504_0001);
    let r = s.handle(&seg(7, 0x60, &[])).unwrap();
    expect_abort(&r, 0, 0, 0x0504_0001);
    // an abort from the master gets no answer
    let mut body = vec![0x00, 0x20, 0x80, 0x00, 0x20, 0x00];
    body.extend_from_slice(&0x0800_0000u32.to_le_bytes());
    assert!(s.handle(&mbx(3, 1, &body)).is_none());
    // other mailbox type: mailbox error reply (type 0, service 1, detail 2)
    let r = s.handle(&mbx(4, 2, &[0; 8])).unwrap();
    assert_eq!(&r[..10], &[4, 0, 0, 0, 0, r[5] & 0x70, 1, 0, 2, 0]);
}

#[test]
fn complete_access_upload_and_download() {
    let mut s = coe_server();
    // 0x60D0: sub 0 = 2 (padded to 16 bits) + 2 × INT16
    let r = s.handle(&sdo(1, 0x50, 0x60D0, 0, &[])).unwrap();
    let b = coe_body(&r, 1);
    assert_eq!(b[2], 0x51, "normal upload with CA");
    assert_eq!(u32::from_le_bytes([b[6], b[7], b[8], b[9]]), 6);
    assert_eq!(&b[10..12], &[2, 0]);
    let src1 = s.model().read_object(0x60D0, 1).unwrap() as i16;
    assert_eq!(i16::from_le_bytes([b[12], b[13]]), src1);
    // CA download from sub 1 (ethercrab style): 4 bytes expedited 0x33
    let r = s.handle(&sdo(2, 0x33, 0x60D0, 1, &[1, 0, 2, 0])).unwrap();
    let b = coe_body(&r, 2);
    assert_eq!(b[2], 0x60, "{:x?}", b);
    assert_eq!(s.model().read_object(0x60D0, 1), Ok(1));
    assert_eq!(s.model().read_object(0x60D0, 2), Ok(2));
}

#[test]
fn emergency_during_sdo_and_on_demand() {
    let mut s = coe_server();
    s.faults.emcy_before_next_sdo = Some((0x3220, 0x04));
    let r = s.handle(&sdo(1, 0x40, 0x6041, 0, &[])).unwrap();
    // EMCY: CoE service 1 (0x1000), error code, error register, 5 manufacturer bytes
    assert_eq!(len_of(&r), 10);
    assert_eq!(
        coe_body(&r, 1),
        &[0x00, 0x10, 0x20, 0x32, 0x04, 0, 0, 0, 0, 0]
    );
    let rest = s.take_outgoing();
    assert_eq!(rest.len(), 1);
    let b = coe_body(&rest[0], 2);
    assert_eq!(&b[..3], &[0x00, 0x30, 0x4B]);

    s.emergency(0x8611, 0x80);
    let out = s.poll();
    assert_eq!(out.len(), 1);
    assert_eq!(
        coe_body(&out[0], 3),
        &[0x00, 0x10, 0x11, 0x86, 0x80, 0, 0, 0, 0, 0]
    );

    // a model fault produces an EMCY with the model's error code on the next poll
    s.model_mut().inject_fault(0x7500);
    let m = s.model_mut();
    let (rx, mut tx) = (vec![0u8; m.rx_len()], vec![0u8; m.tx_len()]);
    m.step(fieldprobe::units::Nanos(1_000_000), 0.001, &rx, &mut tx);
    let code = s.model().last_error_code();
    let out = s.poll();
    assert_eq!(out.len(), 1);
    let b = coe_body(&out[0], 4);
    assert_eq!(&b[..2], &[0x00, 0x10]);
    assert_eq!(u16::from_le_bytes([b[2], b[3]]), code);
    assert!(s.poll().is_empty());
}

#[test]
fn delayed_answer_and_counter() {
    let mut s = coe_server();
    s.faults.delay_polls = 2;
    assert!(s.handle(&sdo(1, 0x40, 0x6041, 0, &[])).is_none());
    assert!(s.poll().is_empty());
    let out = s.poll();
    assert_eq!(out.len(), 1);
    assert_eq!(coe_body(&out[0], 1)[2], 0x4B);
    s.faults.delay_polls = 0;
    // repeated counter = retry: ignored
    assert!(s.handle(&sdo(1, 0x40, 0x6041, 0, &[])).is_none());
    // reply counter runs 2..7 then wraps to 1
    let mut seen = Vec::new();
    for k in 0..8u8 {
        let r = s.handle(&sdo(k % 7 + 2, 0x40, 0x6041, 0, &[])).unwrap();
        seen.push(r[5] >> 4);
    }
    assert_eq!(seen, vec![2, 3, 4, 5, 6, 7, 1, 2]);
}

fn sercos() -> SercosModel {
    SercosModel::new(&catalogue::builtin("sercos-ax5000").unwrap()).unwrap()
}

/// SoE message: mailbox type 5, SoE header (opcode | flags, elements, IDN), data.
fn soe(counter: u8, b0: u8, elements: u8, idn: u16, data: &[u8]) -> Vec<u8> {
    let mut b = vec![b0, elements, idn as u8, (idn >> 8) as u8];
    b.extend_from_slice(data);
    mbx(5, counter, &b)
}

#[test]
fn soe_read_and_write() {
    let mut s = SoeServer::new(Box::new(sercos()), sercos_idns(), MBX);
    // read S-0-0169 value: opcode 1, element 0x40
    let r = s.handle(&soe(1, 0x01, 0x40, 169, &[])).unwrap();
    assert_eq!(&r[..6], &[6, 0, 0, 0, 0, 0x15]);
    assert_eq!(&r[6..12], &[0x02, 0x40, 0xA9, 0x00, 0x01, 0x00]);
    assert_eq!(sercos().read_object(169, 0), Ok(1));

    // write S-0-0092 = 500: opcode 3 → 4
    let r = s
        .handle(&soe(2, 0x03, 0x40, 92, &500u16.to_le_bytes()))
        .unwrap();
    assert_eq!(&r[..10], &[4, 0, 0, 0, 0, 0x25, 0x04, 0x40, 0x5C, 0x00]);
    assert_eq!(s.model().read_object(92, 0), Ok(500));

    // unknown IDN: error bit, code 0x1001
    let r = s.handle(&soe(3, 0x01, 0x40, 0x0FFF, &[])).unwrap();
    assert_eq!(&r[6..12], &[0x12, 0x40, 0xFF, 0x0F, 0x01, 0x10]);
    // write a read-only IDN (S-0-0051): 0x7004
    let r = s.handle(&soe(4, 0x03, 0x40, 51, &[0; 4])).unwrap();
    assert_eq!(&r[6..12], &[0x14, 0x40, 0x33, 0x00, 0x04, 0x70]);
    // value out of range (S-0-0169 = 99): invalid data 0x7008
    let r = s.handle(&soe(5, 0x03, 0x40, 169, &[99, 0])).unwrap();
    assert_eq!(&r[10..12], &[0x08, 0x70]);
    // wrong length: too short 0x7002
    let r = s.handle(&soe(6, 0x03, 0x40, 169, &[1])).unwrap();
    assert_eq!(&r[10..12], &[0x02, 0x70]);

    // name + attribute + value in one request
    let r = s.handle(&soe(7, 0x01, 0x46, 169, &[])).unwrap();
    let name = b"Probe control parameter";
    let n = name.len();
    let d = &r[10..6 + len_of(&r)];
    assert_eq!(&d[..4], &[n as u8, 0, n as u8, 0]);
    assert_eq!(&d[4..4 + n], name);
    let attr = u32::from_le_bytes(d[4 + n..8 + n].try_into().unwrap());
    assert_eq!((attr >> 16) & 3, 1, "2-byte length code");
    assert_eq!(&d[8 + n..], &[1, 0]);
}

#[test]
fn soe_fragmented_read() {
    let mut s = SoeServer::new(Box::new(sercos()), sercos_idns(), 24);
    // name of S-0-0301 is 37 characters + 4 → 41 bytes, 24 - 10 = 14 per fragment → 3
    let r = s.handle(&soe(1, 0x01, 0x02, 301, &[])).unwrap();
    let rest = s.take_outgoing();
    assert_eq!(rest.len(), 2);
    assert_eq!(r[6], 0x02 | 0x08, "incomplete");
    assert_eq!(u16::from_le_bytes([r[8], r[9]]), 2, "fragments left");
    assert_eq!(rest[0][6], 0x0A);
    assert_eq!(u16::from_le_bytes([rest[0][8], rest[0][9]]), 1);
    assert_eq!(rest[1][6], 0x02);
    assert_eq!(u16::from_le_bytes([rest[1][8], rest[1][9]]), 301);
    let mut all = Vec::new();
    for m in std::iter::once(&r).chain(rest.iter()) {
        all.extend_from_slice(&m[10..6 + len_of(m)]);
    }
    assert_eq!(&all[4..], b"Allocation of real-time control bit 1");
}

#[test]
fn random_mailbox_bytes_never_panic() {
    let mut coe = coe_server();
    let mut soe_s = SoeServer::new(Box::new(sercos()), sercos_idns(), MBX);
    let mut x: u64 = 0x1234_5678_9ABC_DEF0;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for i in 0..20_000 {
        let n = (rnd() % 80) as usize;
        let mut m: Vec<u8> = (0..n).map(|_| rnd() as u8).collect();
        if i % 2 == 0 && m.len() >= 8 {
            // plausible header: length within the buffer, type CoE/SoE
            let l = (m.len() - 6) as u8;
            m[0] = l;
            m[1] = 0;
            m[5] = (m[5] & 0x70) | if i % 4 == 0 { 3 } else { 5 };
            if i % 8 == 0 && m.len() >= 8 {
                m[6] = 0x00;
                m[7] = 0x20;
            }
        }
        let _ = coe.handle(&m);
        let _ = coe.poll();
        let _ = soe_s.handle(&m);
        let _ = soe_s.take_outgoing();
    }
}

/// End to end through an emulated ESC: SM0/SM1 mailbox configured, PRE-OP, SDO request written
/// into SM0 (full length), the answer read from SM1.
#[test]
fn coe_server_behind_an_esc() {
    use fieldprobe::sim::esc::{reg, sii_crc8, Address, Command, Esc, EscChain, EscConfig};
    const OUT: u16 = 0x1000;
    const IN: u16 = 0x1080;
    let mut w = [0u16; 0x40];
    w[0x18] = OUT;
    w[0x19] = MBX as u16;
    w[0x1A] = IN;
    w[0x1B] = MBX as u16;
    w[0x1C] = 0x0004;
    let mut sii: Vec<u8> = w.iter().flat_map(|x| x.to_le_bytes()).collect();
    sii[14] = sii_crc8(&sii[..14]);
    sii.resize(256, 0xFF);
    let esc = Esc::new(EscConfig::from_sii(sii), Box::new(coe_server()));
    let mut c = EscChain::new(vec![esc], 100);
    let mut dg = |cmd: Command, ado: u16, data: &[u8]| {
        let mut d = data.to_vec();
        let (wkc, _) = c.process(cmd, Address::station(0, ado), &mut d, 0);
        (wkc, d)
    };
    let sm = |start: u16, ctrl: u8| {
        let mut v = start.to_le_bytes().to_vec();
        v.extend_from_slice(&(MBX as u16).to_le_bytes());
        v.extend_from_slice(&[ctrl, 0, 1, 0]);
        v
    };
    assert_eq!(dg(Command::Fpwr, reg::sm(0), &sm(OUT, 0x26)).0, 1);
    assert_eq!(dg(Command::Fpwr, reg::sm(1), &sm(IN, 0x22)).0, 1);
    dg(Command::Fpwr, reg::AL_CONTROL, &[0x02, 0]);
    let (_, st) = dg(Command::Fprd, reg::AL_STATUS, &[0; 2]);
    assert_eq!(st[0], 0x02, "PRE-OP");
    let (wkc, _) = dg(Command::Fpwr, OUT, &sdo(1, 0x40, 0x1000, 0, &[]));
    assert_eq!(wkc, 1);
    let (wkc, r) = dg(Command::Fprd, IN, &[0; MBX]);
    assert_eq!(wkc, 1);
    assert_eq!(
        &r[..16],
        &[10, 0, 0, 0, 0, 0x13, 0x00, 0x30, 0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );
}
