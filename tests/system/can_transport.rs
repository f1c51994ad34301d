//! CAN transports behind `bus::can::CanBus`: in-process virtual bus semantics (order, filters,
//! error frames, threads), the fault wrapper, `candump -L` lines, the python-can
//! `udp_multicast` datagram codec (against the datagram captured from python-can in notes
//! `canopen.md` §3.1), the `udp:GROUP:PORT` spec, and SocketCAN opening.
//!
//! No network traffic here (the UDP bus itself runs in `tests/system/can_udp_interop.rs`, inside a
//! private network namespace). SocketCAN on a real `vcan0` is tested in `tests/system/socketcan.rs`
//! (on the host or in a Linux guest). Every wait is bounded.

use std::{
    sync::{Arc, Barrier},
    thread,
    time::{Duration, Instant},
};

use fieldprobe::bus::can::{
    candump::{self, CandumpRecord, CandumpWriter},
    fault::FaultBus,
    udp::UdpConfig,
    udp_wire, CanBus, CanError, CanFilter, CanFrame, SocketCanBus, VirtualCan, CAN_EFF_FLAG,
    CAN_RTR_FLAG,
};
use proptest::prelude::*;

const SHORT: Duration = Duration::from_millis(20);
const LONG: Duration = Duration::from_secs(5);

/// A frame written out field by field (independent of the constructors under test).
fn frame(id: u32, extended: bool, data: &[u8]) -> CanFrame {
    let mut d = [0u8; 8];
    d[..data.len()].copy_from_slice(data);
    CanFrame {
        id,
        extended,
        rtr: false,
        error: false,
        len: data.len() as u8,
        data: d,
    }
}

fn remote(id: u32, extended: bool, len: u8) -> CanFrame {
    CanFrame {
        id,
        extended,
        rtr: true,
        error: false,
        len,
        data: [0; 8],
    }
}

fn error(class: u32, data: [u8; 8]) -> CanFrame {
    CanFrame {
        id: class,
        extended: false,
        rtr: false,
        error: true,
        len: 8,
        data,
    }
}

fn hex(s: &str) -> Vec<u8> {
    let s: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

#[track_caller]
fn recv_all(bus: &mut impl CanBus) -> Vec<CanFrame> {
    let mut v = Vec::new();
    while let Some(f) = bus.recv(SHORT).expect("recv") {
        v.push(f);
    }
    v
}

// ---------------------------------------------------------------------------------------------
// Virtual bus

#[test]
fn virtual_bus_delivers_to_every_other_endpoint_in_send_order() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut a = hub.endpoint();
    let mut b = hub.endpoint();
    let mut c = hub.endpoint();
    let f1 = frame(0x601, false, &[0x40, 0x41, 0x10, 0x00]);
    let f2 = frame(0x581, false, &[0x43, 0x41, 0x10, 0x00, 1, 2, 3, 4]);
    let f3 = frame(0x1ABC_DE01, true, &[]);
    a.send(&f1).unwrap();
    b.send(&f2).unwrap();
    a.send(&f3).unwrap();
    assert_eq!(recv_all(&mut a), vec![f2]);
    assert_eq!(recv_all(&mut b), vec![f1, f3]);
    assert_eq!(recv_all(&mut c), vec![f1, f2, f3]);
    assert_eq!(hub.endpoints(), 3);
    drop(c);
    assert_eq!(hub.endpoints(), 2);
}

#[test]
fn virtual_bus_recv_own_msgs_and_error_frames() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut a = hub.endpoint();
    let mut b = hub.endpoint();
    a.set_recv_own_msgs(true);
    let f = frame(0x080, false, &[]);
    let e = error(0x40, [0; 8]);
    a.send(&f).unwrap();
    a.send(&e).unwrap();
    assert_eq!(recv_all(&mut a), vec![f, e]);
    let got = recv_all(&mut b);
    assert_eq!(got, vec![f, e]);
    assert!(got[1].error && got[1].id == 0x40);
    // The bus itself (all endpoints, the sender included).
    hub.broadcast(&error(0x100, [0; 8]));
    assert_eq!(recv_all(&mut a), vec![error(0x100, [0; 8])]);
    assert_eq!(recv_all(&mut b), vec![error(0x100, [0; 8])]);
    // Error mask: only bus-off errors.
    b.set_error_mask(0x40);
    a.send(&error(0x08, [0; 8])).unwrap();
    a.send(&error(0x40, [0; 8])).unwrap();
    assert_eq!(recv_all(&mut b), vec![error(0x40, [0; 8])]);
}

#[test]
fn virtual_bus_filters_follow_socketcan() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut tx = hub.endpoint();
    let mut sdo = hub.endpoint();
    let mut tpdo = hub.endpoint();
    let mut not_nmt = hub.endpoint();
    let mut none = hub.endpoint();
    // Exactly the standard data frame 0x585 (not extended 0x585, not RTR 0x585).
    sdo.set_filters(&[CanFilter::new(0x585, 0x7FF | CAN_EFF_FLAG | CAN_RTR_FLAG)]);
    // COB-IDs 0x180..=0x1FF, standard only: mask 0x780 keeps the function code bits.
    tpdo.set_filters(&[CanFilter::new(0x180, 0x780 | CAN_EFF_FLAG)]);
    // Everything but NMT (0x000).
    not_nmt.set_filters(&[CanFilter {
        id: 0x000,
        mask: 0x7FF | CAN_EFF_FLAG,
        inverted: true,
    }]);
    none.set_filters(&[]);
    let frames = [
        frame(0x585, false, &[0x60]),
        frame(0x585, true, &[0x61]),
        remote(0x585, false, 8),
        frame(0x185, false, &[1, 2]),
        frame(0x1FF, false, &[3]),
        frame(0x200, false, &[4]),
        frame(0x000, false, &[0x01, 0x05]),
        error(0x04, [0, 0x08, 0, 0, 0, 0, 0, 0]),
    ];
    for f in &frames {
        tx.send(f).unwrap();
    }
    let err = frames[7];
    assert_eq!(recv_all(&mut sdo), vec![frames[0], err]);
    assert_eq!(recv_all(&mut tpdo), vec![frames[3], frames[4], err]);
    assert_eq!(
        recv_all(&mut not_nmt),
        vec![frames[0], frames[1], frames[2], frames[3], frames[4], frames[5], err]
    );
    // No data frames at all, but error frames still pass (error mask, not filters).
    assert_eq!(recv_all(&mut none), vec![err]);
}

#[test]
fn virtual_bus_queue_overflow_drops_newest_and_counts() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut a = hub.endpoint();
    let mut b = hub.endpoint();
    b.set_queue_capacity(4);
    for i in 0..6u8 {
        a.send(&frame(0x100 + u32::from(i), false, &[i])).unwrap();
    }
    assert_eq!(b.pending(), 4);
    assert_eq!(b.dropped(), 2);
    let ids: Vec<u32> = recv_all(&mut b).iter().map(|f| f.id).collect();
    assert_eq!(ids, vec![0x100, 0x101, 0x102, 0x103]);
}

#[test]
fn virtual_bus_refuses_invalid_frames_and_zeroes_padding() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut a = hub.endpoint();
    let mut b = hub.endpoint();
    let mut bad = frame(0x7FF, false, &[]);
    bad.id = 0x800;
    assert!(matches!(a.send(&bad), Err(CanError::Frame(_))));
    let mut long = frame(0x100, false, &[]);
    long.len = 9;
    assert!(matches!(a.send(&long), Err(CanError::Frame(_))));
    // Garbage beyond len is not carried.
    let mut f = frame(0x100, false, &[1, 2]);
    f.data[5] = 0xEE;
    a.send(&f).unwrap();
    assert_eq!(b.recv(LONG).unwrap(), Some(frame(0x100, false, &[1, 2])));
}

#[test]
fn virtual_bus_recv_timeout_and_wakeup() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut a = hub.endpoint();
    let mut b = hub.endpoint();
    let t0 = Instant::now();
    assert_eq!(b.recv(Duration::from_millis(50)).unwrap(), None);
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_millis(50) && waited < Duration::from_secs(2),
        "{waited:?}"
    );
    assert_eq!(b.recv(Duration::ZERO).unwrap(), None);
    // A receiver blocked in recv wakes up when the frame is sent.
    let f = frame(0x181, false, &[7]);
    let rx = thread::spawn(move || {
        let t = Instant::now();
        let got = b.recv(LONG).unwrap();
        (got, t.elapsed())
    });
    thread::sleep(Duration::from_millis(50));
    a.send(&f).unwrap();
    let (got, took) = rx.join().unwrap();
    assert_eq!(got, Some(f));
    assert!(took < Duration::from_secs(2), "{took:?}");
}

#[test]
fn virtual_bus_threads_see_one_total_order() {
    let _one_module = crate::gate::enter(module_path!());
    const SENDERS: u32 = 4;
    const PER: u32 = 500;
    let hub = VirtualCan::new();
    let receivers: Vec<_> = (0..2).map(|_| hub.endpoint()).collect();
    let senders: Vec<_> = (0..SENDERS).map(|_| hub.endpoint()).collect();
    let start = Arc::new(Barrier::new(SENDERS as usize));
    let tx_threads: Vec<_> = senders
        .into_iter()
        .enumerate()
        .map(|(k, mut ep)| {
            let start = start.clone();
            thread::spawn(move || {
                start.wait();
                for seq in 0..PER {
                    let b = seq.to_le_bytes();
                    ep.send(&frame(0x180 + k as u32, false, &b)).unwrap();
                }
            })
        })
        .collect();
    let rx_threads: Vec<_> = receivers
        .into_iter()
        .map(|mut ep| {
            thread::spawn(move || {
                let mut got = Vec::new();
                while got.len() < (SENDERS * PER) as usize {
                    match ep.recv(LONG).unwrap() {
                        Some(f) => got.push(f),
                        None => break,
                    }
                }
                got
            })
        })
        .collect();
    for t in tx_threads {
        t.join().unwrap();
    }
    let seen: Vec<Vec<CanFrame>> = rx_threads.into_iter().map(|t| t.join().unwrap()).collect();
    assert_eq!(seen[0].len(), (SENDERS * PER) as usize);
    // Both receivers saw the same interleaving.
    assert_eq!(seen[0], seen[1]);
    // Per sender: 0, 1, 2, … PER-1 in order.
    for k in 0..SENDERS {
        let seqs: Vec<u32> = seen[0]
            .iter()
            .filter(|f| f.id == 0x180 + k)
            .map(|f| u32::from_le_bytes(f.data[..4].try_into().unwrap()))
            .collect();
        assert_eq!(seqs, (0..PER).collect::<Vec<_>>(), "sender {k}");
    }
}

#[test]
fn virtual_bus_cycle_cost_is_small() {
    let _one_module = crate::gate::enter(module_path!());
    // 8 nodes, each sending 2 PDOs per cycle, everybody draining its queue: 1000 cycles.
    let hub = VirtualCan::new();
    let mut nodes: Vec<_> = (0..8).map(|_| hub.endpoint()).collect();
    let t0 = Instant::now();
    let mut received = 0usize;
    for cycle in 0..1000u32 {
        for (n, ep) in nodes.iter_mut().enumerate() {
            let b = cycle.to_le_bytes();
            ep.send(&frame(0x180 + n as u32 + 1, false, &b)).unwrap();
            ep.send(&frame(0x280 + n as u32 + 1, false, &b)).unwrap();
        }
        for ep in nodes.iter_mut() {
            while let Some(_f) = ep.recv(Duration::ZERO).unwrap() {
                received += 1;
            }
        }
    }
    let took = t0.elapsed();
    assert_eq!(received, 1000 * 16 * 7);
    eprintln!(
        "virtual bus: 1000 cycles x 8 nodes x 2 PDOs in {took:?} ({:?}/cycle)",
        took / 1000
    );
    // Generous bound (debug-ish test profile, shared machine): well under the 1 ms cycle.
    assert!(took < Duration::from_secs(5), "{took:?}");
}

// ---------------------------------------------------------------------------------------------
// Fault wrapper

#[test]
fn fault_bus_drops_nth_and_by_predicate() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut f = FaultBus::new(hub.endpoint());
    let mut peer = hub.endpoint();
    let fs = [
        frame(0x601, false, &[1]),
        frame(0x602, false, &[2]),
        frame(0x603, false, &[3]),
    ];
    f.drop_nth_sent(2);
    for x in &fs {
        f.send(x).unwrap();
    }
    assert_eq!(recv_all(&mut peer), vec![fs[0], fs[2]]);
    assert_eq!(f.stats().sent_dropped, 1);
    assert_eq!(f.stats().sent, 2);

    f.drop_received_where(|fr| fr.id == 0x701);
    let hb = frame(0x701, false, &[0x05]);
    let pdo = frame(0x181, false, &[9]);
    peer.send(&hb).unwrap();
    peer.send(&pdo).unwrap();
    peer.send(&hb).unwrap();
    assert_eq!(recv_all(&mut f), vec![pdo]);
    assert_eq!(f.stats().received_dropped, 2);

    f.clear_faults();
    f.drop_nth_received(2);
    for x in &fs {
        peer.send(x).unwrap();
    }
    assert_eq!(recv_all(&mut f), vec![fs[0], fs[2]]);
    f.drop_sent_where(|fr| fr.id == 0x602);
    for x in &fs {
        f.send(x).unwrap();
    }
    assert_eq!(recv_all(&mut peer), vec![fs[0], fs[2]]);
}

#[test]
fn fault_bus_delays_by_calls_and_by_time() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut f = FaultBus::new(hub.endpoint());
    let mut peer = hub.endpoint();
    let a = frame(0x181, false, &[1]);
    let b = frame(0x182, false, &[2]);
    f.delay_received_calls(2);
    peer.send(&a).unwrap();
    assert_eq!(f.recv(Duration::ZERO).unwrap(), None); // call 1: a arrives
    peer.send(&b).unwrap();
    assert_eq!(f.recv(Duration::ZERO).unwrap(), None); // call 2: b arrives
    assert_eq!(f.recv(Duration::ZERO).unwrap(), Some(a)); // call 3 = 1 + 2
    assert_eq!(f.recv(Duration::ZERO).unwrap(), Some(b)); // call 4 = 2 + 2
    assert_eq!(f.recv(Duration::ZERO).unwrap(), None);

    f.clear_faults();
    f.delay_received_for(Duration::from_millis(100));
    let t0 = Instant::now();
    peer.send(&a).unwrap();
    assert_eq!(f.recv(Duration::from_millis(10)).unwrap(), None);
    assert_eq!(f.recv(LONG).unwrap(), Some(a));
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(100) && took < Duration::from_secs(2),
        "{took:?}"
    );
}

#[test]
fn fault_bus_error_frames_and_bus_off() {
    let _one_module = crate::gate::enter(module_path!());
    let hub = VirtualCan::new();
    let mut f = FaultBus::new(hub.endpoint());
    let mut peer = hub.endpoint();
    f.inject_error(0x04, &[0, 0x08]);
    assert_eq!(
        f.recv(Duration::ZERO).unwrap(),
        Some(error(0x04, [0, 0x08, 0, 0, 0, 0, 0, 0]))
    );
    f.go_bus_off();
    assert!(f.is_bus_off());
    assert!(matches!(
        f.send(&frame(0x181, false, &[1])),
        Err(CanError::BusOff)
    ));
    assert_eq!(f.recv(Duration::ZERO).unwrap(), Some(error(0x40, [0; 8])));
    peer.send(&frame(0x701, false, &[0x05])).unwrap();
    assert_eq!(
        f.recv(SHORT).unwrap(),
        None,
        "bus-off controller receives nothing"
    );
    assert_eq!(
        recv_all(&mut peer),
        vec![],
        "nothing was sent while bus-off"
    );
    f.recover();
    assert!(!f.is_bus_off());
    assert_eq!(f.recv(Duration::ZERO).unwrap(), Some(error(0x100, [0; 8])));
    f.send(&frame(0x181, false, &[1])).unwrap();
    assert_eq!(recv_all(&mut peer), vec![frame(0x181, false, &[1])]);
    let s = f.stats();
    assert_eq!(
        (s.sent_refused_bus_off, s.discarded_bus_off, s.sent),
        (1, 1, 1)
    );
}

// ---------------------------------------------------------------------------------------------
// candump -L

/// Hand-written log lines and what they mean.
fn candump_fixtures() -> Vec<(&'static str, CanFrame)> {
    vec![
        // SDO upload request 0x1018 sub 0 to node 1
        (
            "(1700000000.123456) can0 601#4018100000000000",
            frame(0x601, false, &[0x40, 0x18, 0x10, 0, 0, 0, 0, 0]),
        ),
        // NMT start all
        (
            "(1700000000.123456) can0 000#0100",
            frame(0x000, false, &[0x01, 0x00]),
        ),
        // SYNC, no data
        ("(1700000000.123456) can0 080#", frame(0x080, false, &[])),
        // extended id, 4 bytes
        (
            "(1700000000.123456) can0 1ABCDE01#DEADBEEF",
            frame(0x1ABC_DE01, true, &[0xDE, 0xAD, 0xBE, 0xEF]),
        ),
        // extended id below 0x800 keeps 8 digits
        (
            "(1700000000.123456) can0 00000123#11",
            frame(0x123, true, &[0x11]),
        ),
        // remote frames: length 0 and 8
        ("(1700000000.123456) can0 123#R", remote(0x123, false, 0)),
        ("(1700000000.123456) can0 705#R1", remote(0x705, false, 1)),
        (
            "(1700000000.123456) can0 12345678#R8",
            remote(0x1234_5678, true, 8),
        ),
        // error frame: CAN_ERR_FLAG | CAN_ERR_BUSOFF, 8 data bytes
        (
            "(1700000000.123456) can0 20000040#0000000000000000",
            error(0x40, [0; 8]),
        ),
        // controller problem: RX error passive (data[1] = 0x10)
        (
            "(1700000000.123456) can0 20000004#0010000000000000",
            error(0x04, [0, 0x10, 0, 0, 0, 0, 0, 0]),
        ),
    ]
}

#[test]
fn candump_lines_parse_and_format_exactly() {
    let _one_module = crate::gate::enter(module_path!());
    let ts = Duration::new(1_700_000_000, 123_456_000);
    for (line, f) in candump_fixtures() {
        let rec = candump::parse_line(line).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            rec,
            CandumpRecord {
                timestamp: ts,
                interface: "can0".into(),
                frame: f
            },
            "{line}"
        );
        assert_eq!(candump::format_line(ts, "can0", &f), line);
    }
}

#[test]
fn candump_writer_round_trip() {
    let _one_module = crate::gate::enter(module_path!());
    let fixtures = candump_fixtures();
    let mut w = CandumpWriter::new(Vec::new(), "can0");
    for (_, f) in &fixtures {
        w.write_frame(Duration::new(1_700_000_000, 123_456_789), f)
            .unwrap();
    }
    let text = String::from_utf8(w.into_inner()).unwrap();
    let expected: String = fixtures.iter().map(|(l, _)| format!("{l}\n")).collect();
    assert_eq!(text, expected);
    for (line, (_, f)) in text.lines().zip(&fixtures) {
        assert_eq!(candump::parse_line(line).unwrap().frame, *f);
    }
}

#[test]
fn candump_lenient_forms() {
    let _one_module = crate::gate::enter(module_path!());
    let p = |l: &str| candump::parse_line(l).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        p("  (0.5) vcan1 1ab#de.ad.be.ef  ").frame,
        frame(0x1AB, false, &[0xDE, 0xAD, 0xBE, 0xEF])
    );
    assert_eq!(
        p("(0.5) vcan1 1ab#00").timestamp,
        Duration::from_millis(500)
    );
    assert_eq!(p("(0.5) vcan1 1ab#00").interface, "vcan1");
    // raw DLC 0xC on an 8-byte frame; direction marker
    assert_eq!(
        p("(1.000001) can0 123#0102030405060708_C").frame,
        frame(0x123, false, &[1, 2, 3, 4, 5, 6, 7, 8])
    );
    assert_eq!(
        p("(1.000001) can0 123#01 R").timestamp,
        Duration::new(1, 1000)
    );
}

#[test]
fn candump_refuses_bad_lines() {
    let _one_module = crate::gate::enter(module_path!());
    for line in [
        "",
        "can0 123#00",
        "(1.0) can0",
        "(1.0) can0 123",
        "1.0 can0 123#00",
        "(1) can0 123#00",
        "(1.0) can0 1234#00",
        "(1.0) can0 800#00",
        "(1.0) can0 4FFFFFFF#00",
        "(1.0) can0 E0000040#00",
        "(1.0) can0 123#0",
        "(1.0) can0 123#zz",
        "(1.0) can0 123#000102030405060708",
        "(1.0) can0 123#R9",
        "(1.0) can0 123##1AA",
        "(1.0) can0 123#00 X",
        "(1.0) can0 123#00_C",
        "(x.0) can0 123#00",
    ] {
        assert!(candump::parse_line(line).is_err(), "accepted `{line}`");
    }
}

// ---------------------------------------------------------------------------------------------
// python-can udp_multicast datagrams

/// Captured from python-can 4.6.1 (notes `canopen.md` §3.1): SDO request
/// `0x601 [8] 40 41 10 00 00 00 00 00`, timestamp 0.0, 162 bytes.
const PYTHON_CAN_SDO_DATAGRAM: &str = "8ba974696d657374616d70cb0000000000000000ae6172626974726174696f6e5f6964cd0601ae69735f657874656e6465645f6964c2af69735f72656d6f74655f6672616d65c2ae69735f6572726f725f6672616d65c2a76368616e6e656cc0a3646c6308a464617461c4084041100000000000a569735f6664c2ae626974726174655f737769746368c2b56572726f725f73746174655f696e64696361746f72c2";

fn sdo_frame() -> CanFrame {
    frame(0x601, false, &[0x40, 0x41, 0x10, 0, 0, 0, 0, 0])
}

#[test]
fn udp_codec_matches_python_can_datagram_byte_for_byte() {
    let _one_module = crate::gate::enter(module_path!());
    let captured = hex(PYTHON_CAN_SDO_DATAGRAM);
    assert_eq!(captured.len(), 162);
    assert_eq!(udp_wire::decode(&captured).unwrap(), Some(sdo_frame()));
    let mut out = Vec::new();
    udp_wire::encode(&sdo_frame(), 0.0, &mut out).unwrap();
    assert_eq!(hex_string(&out), PYTHON_CAN_SDO_DATAGRAM);
}

fn hex_string(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// The captured datagram with its values replaced at the same positions.
fn python_datagram(id_enc: &str, ext: bool, rtr: bool, err: bool, dlc: u8, data: &str) -> String {
    let b = |v: bool| if v { "c3" } else { "c2" };
    format!(
        "8ba974696d657374616d70cb0000000000000000ae6172626974726174696f6e5f6964{id_enc}\
         ae69735f657874656e6465645f6964{}af69735f72656d6f74655f6672616d65{}\
         ae69735f6572726f725f6672616d65{}a76368616e6e656cc0a3646c63{dlc:02x}a464617461c4{:02x}{data}\
         a569735f6664c2ae626974726174655f737769746368c2b56572726f725f73746174655f696e64696361746f72c2",
        b(ext),
        b(rtr),
        b(err),
        data.len() / 2
    )
}

#[test]
fn udp_codec_other_frame_kinds() {
    let _one_module = crate::gate::enter(module_path!());
    let cases = [
        // extended 0x1ABCDE: uint32 `ce 001abcde`, 3 bytes
        (
            frame(0x1A_BCDE, true, &[1, 2, 3]),
            python_datagram("ce001abcde", true, false, false, 3, "010203"),
        ),
        // id 0x80 needs uint8 `cc 80`; no data
        (
            frame(0x080, false, &[]),
            python_datagram("cc80", false, false, false, 0, ""),
        ),
        // id 0x7f is a positive fixint
        (
            frame(0x07F, false, &[0xFF]),
            python_datagram("7f", false, false, false, 1, "ff"),
        ),
        // remote frame: dlc = requested length, empty data
        (
            remote(0x705, false, 1),
            python_datagram("cd0705", false, true, false, 1, ""),
        ),
        // error frame bus-off
        (
            error(0x40, [0; 8]),
            python_datagram("40", false, false, true, 8, "0000000000000000"),
        ),
    ];
    for (f, dg) in cases {
        let mut out = Vec::new();
        udp_wire::encode(&f, 0.0, &mut out).unwrap();
        assert_eq!(hex_string(&out), dg, "{f:?}");
        assert_eq!(udp_wire::decode(&hex(&dg)).unwrap(), Some(f));
    }
}

#[test]
fn udp_codec_lenient_decoding() {
    let _one_module = crate::gate::enter(module_path!());
    // {"arbitration_id": 0x123, "data": b"\x01"}: python-can's default is_extended_id is True.
    let minimal = hex("82 ae6172626974726174696f6e5f6964 cd0123 a464617461 c40101");
    assert_eq!(
        udp_wire::decode(&minimal).unwrap(),
        Some(frame(0x123, true, &[1]))
    );
    // Unknown key "foo": [1, {"x": nil}] appended (map size 12): ignored.
    let mut unknown = hex(PYTHON_CAN_SDO_DATAGRAM);
    unknown[0] = 0x8c;
    unknown.extend(hex("a3666f6f 92 01 81 a178 c0"));
    assert_eq!(udp_wire::decode(&unknown).unwrap(), Some(sdo_frame()));
    // data as an int array, dlc absent, std id.
    let arr = hex(
        "83 ae6172626974726174696f6e5f6964 cd0181 ae69735f657874656e6465645f6964 c2 a464617461 93 01 cc80 ccff",
    );
    assert_eq!(
        udp_wire::decode(&arr).unwrap(),
        Some(frame(0x181, false, &[1, 0x80, 0xFF]))
    );
    // CAN FD message: well-formed, ignored by a classic bus.
    let fd = python_datagram(
        "cd0601",
        false,
        false,
        false,
        12,
        "000102030405060708090a0b",
    )
    .replace("a569735f6664c2", "a569735f6664c3");
    assert_eq!(udp_wire::decode(&hex(&fd)).unwrap(), None);
}

#[test]
fn udp_codec_refuses_what_python_can_refuses() {
    let _one_module = crate::gate::enter(module_path!());
    let bad = [
        // standard id 0x800
        python_datagram("cd0800", false, false, false, 0, ""),
        // extended id 0x20000000
        python_datagram("ce20000000", true, false, false, 0, ""),
        // dlc 2 but 1 byte
        python_datagram("01", false, false, false, 2, "00"),
        // 9 bytes classic
        python_datagram("01", false, false, false, 9, "000102030405060708"),
        // remote frame carrying data
        python_datagram("01", false, true, false, 1, "00"),
        // remote and error
        python_datagram("01", false, true, true, 0, ""),
    ];
    for dg in bad {
        assert!(
            matches!(udp_wire::decode(&hex(&dg)), Err(CanError::Malformed(_))),
            "{dg}"
        );
    }
    let captured = hex(PYTHON_CAN_SDO_DATAGRAM);
    for n in 0..captured.len() {
        assert!(
            matches!(
                udp_wire::decode(&captured[..n]),
                Err(CanError::Malformed(_))
            ),
            "prefix {n}"
        );
    }
    let mut trailing = captured.clone();
    trailing.push(0xc0);
    assert!(udp_wire::decode(&trailing).is_err());
    assert!(udp_wire::decode(&hex("93010203")).is_err()); // an array, not a map
    assert!(udp_wire::decode(&hex("81c1c0")).is_err()); // 0xc1 is never used

    // The encoder refuses frames python-can would refuse.
    let mut out = Vec::new();
    let mut std_800 = frame(0x7FF, false, &[]);
    std_800.id = 0x800;
    assert!(matches!(
        udp_wire::encode(&std_800, 0.0, &mut out),
        Err(CanError::Frame(_))
    ));
    let mut nine = frame(0x100, false, &[]);
    nine.len = 9;
    assert!(udp_wire::encode(&nine, 0.0, &mut out).is_err());
    let mut both = remote(0x100, false, 0);
    both.error = true;
    assert!(udp_wire::encode(&both, 0.0, &mut out).is_err());
    let mut big_err = error(0x40, [0; 8]);
    big_err.id = 0x800;
    assert!(udp_wire::encode(&big_err, 0.0, &mut out).is_err());
    assert!(out.is_empty());
}

fn any_frame() -> impl Strategy<Value = CanFrame> {
    (any::<u32>(), 0u8..5, 0u8..=8, any::<[u8; 8]>()).prop_map(|(id, kind, len, bytes)| {
        let data = &bytes[..usize::from(len)];
        match kind {
            0 => frame(id & 0x7FF, false, data),
            1 => frame(id & 0x1FFF_FFFF, true, data),
            2 => remote(id & 0x7FF, false, len),
            3 => remote(id & 0x1FFF_FFFF, true, len),
            _ => {
                // error class bits that fit python-can's 11-bit check
                let mut f = frame(id & 0x3FF, false, data);
                f.error = true;
                f
            }
        }
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, .. ProptestConfig::default() })]

    #[test]
    fn udp_codec_round_trips(f in any_frame(), ts in any::<f64>()) {
        let _one_module = crate::gate::enter(module_path!());
        let mut out = Vec::new();
        udp_wire::encode(&f, ts, &mut out).unwrap();
        prop_assert!(out.len() <= udp_wire::PYTHON_CAN_MAX_BUFFER);
        prop_assert_eq!(udp_wire::decode(&out).unwrap(), Some(f));
    }

    #[test]
    fn udp_decoder_never_panics_on_random_bytes(b in proptest::collection::vec(any::<u8>(), 0..300)) {
        let _one_module = crate::gate::enter(module_path!());
        let _ = udp_wire::decode(&b);
    }

    #[test]
    fn udp_decoder_never_panics_on_mutated_datagrams(
        pos in 0usize..162, val in any::<u8>(), cut in 0usize..=162,
    ) {
        let _one_module = crate::gate::enter(module_path!());
        let mut d = hex(PYTHON_CAN_SDO_DATAGRAM);
        d[pos] = val;
        d.truncate(cut);
        let _ = udp_wire::decode(&d);
    }

    #[test]
    fn candump_round_trips(f in any_frame(), secs in 0u64..4_000_000_000, us in 0u32..1_000_000) {
        let _one_module = crate::gate::enter(module_path!());
        let ts = Duration::new(secs, us * 1000);
        let line = candump::format_line(ts, "can0", &f);
        let rec = candump::parse_line(&line).unwrap();
        prop_assert_eq!(rec.timestamp, ts);
        prop_assert_eq!(rec.frame, f);
    }

    #[test]
    fn candump_parser_never_panics(s in "\\PC{0,60}") {
        let _one_module = crate::gate::enter(module_path!());
        let _ = candump::parse_line(&s);
    }

    #[test]
    fn candump_parser_never_panics_on_near_lines(s in "\\([0-9.]{0,12}\\) [a-z0-9]{1,5} [0-9A-Fa-fR#._]{0,30}( [RTX])?") {
        let _one_module = crate::gate::enter(module_path!());
        let _ = candump::parse_line(&s);
    }
}

// ---------------------------------------------------------------------------------------------
// udp:GROUP:PORT specs

#[test]
fn udp_spec_parsing() {
    let _one_module = crate::gate::enter(module_path!());
    let d = UdpConfig::parse("udp").unwrap();
    assert_eq!(
        (d.group.octets(), d.port, d.ttl),
        ([239, 74, 163, 2], 43113, 1)
    );
    let c = UdpConfig::parse("udp:239.1.2.3:40000").unwrap();
    assert_eq!((c.group.octets(), c.port), ([239, 1, 2, 3], 40000));
    assert_eq!(c.to_string(), "udp:239.1.2.3:40000");
    for bad in [
        "",
        "tcp:239.1.2.3:40000",
        "udp:",
        "udpx",
        "udp:239.1.2.3",
        "udp:10.0.0.1:40000",
        "udp:239.1.2:40000",
        "udp:239.1.2.3:0",
        "udp:239.1.2.3:70000",
        "udp:239.1.2.3:port",
        "udp:ff15::1:40000",
    ] {
        let e = UdpConfig::parse(bad).expect_err(bad).to_string();
        assert!(
            e.contains("`udp`") && e.contains("udp:GROUP:PORT") && e.contains(bad),
            "{bad}: {e}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// SocketCAN

#[test]
fn socketcan_missing_interface_is_unavailable() {
    let _one_module = crate::gate::enter(module_path!());
    // ENODEV where SocketCAN exists, ENODEV/EAFNOSUPPORT where it does not (this machine),
    // "Linux only" elsewhere: always Unavailable, never a panic or a plain I/O error.
    match SocketCanBus::open("fpnosuch0") {
        Err(CanError::Unavailable(msg)) => {
            assert!(msg.contains("SocketCAN") && msg.contains("vcan"), "{msg}")
        }
        other => panic!("expected Unavailable, got {other:?}"),
    }
}
