//! CAN frames into emulated CANopen nodes (`sim::canopen::CanopenSegment`, as `sim canopen`
//! and the `canopen-emu` link run them): two CiA 402 nodes (IDs 1 and 2) get a script of
//! frames (NMT, SYNC, RPDOs, SDO requests, anything) and time steps on virtual time.
//! Must hold: no panic; every frame a node sends is a valid classic CAN frame from one of its
//! COB-IDs (0x080/0x180…0x580/0x700 + its ID); the output per call stays bounded.
#![no_main]
use fieldprobe::bus::can::CanFrame;
use fieldprobe::drive::catalogue;
use fieldprobe::sim::canopen::{CanopenSegment, EmulatedNode};
use fieldprobe::units::Nanos;
use fieldprobe_fuzz::Bytes;
use libfuzzer_sys::fuzz_target;

/// COB-ID function codes (CiA 301): NMT, SYNC/EMCY, TPDO1..4, RPDO1..4, SDO tx, SDO rx, NMT EC.
const BASES: [u16; 13] = [
    0x000, 0x080, 0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500, 0x580, 0x600, 0x700,
];

fuzz_target!(|data: &[u8]| {
    let def = catalogue::builtin("cia402-generic").expect("built-in drive");
    let nodes = vec![
        EmulatedNode::new(1, &def).expect("node 1"),
        EmulatedNode::new(2, &def).expect("node 2"),
    ];
    let cycle = Nanos(1_000_000);
    let mut seg = CanopenSegment::new(nodes, cycle);
    let mut now = Nanos(0);
    let mut b = Bytes::new(data);
    let mut steps = 0;
    while !b.is_empty() && steps < 4096 {
        steps += 1;
        let op = b.u8();
        let mut frames = Vec::new();
        match op % 4 {
            0 | 1 => {
                let base = BASES[usize::from(b.u8()) % BASES.len()];
                let node = u16::from(b.u8() % 4); // 0 = broadcast, 3 = nobody
                let id = if base == 0x080 && op & 0x80 != 0 {
                    0x080
                } else {
                    base + node
                };
                let payload = b.take_len8(9);
                frames.push(CanFrame::new(id, payload).expect("standard frame"));
            }
            2 => {
                // Time passes: up to ~65 ms.
                now = Nanos(now.0 + u64::from(b.u16()) * 1000);
            }
            _ => {
                let payload = b.take_len8(9);
                let f = match b.u8() % 3 {
                    0 => CanFrame::new_extended(b.u32() & 0x1FFF_FFFF, payload).expect("extended"),
                    1 => CanFrame::remote(b.u16() & 0x7FF, b.u8() % 9).expect("remote"),
                    _ => CanFrame::error_frame(b.u32(), payload),
                };
                frames.push(f);
            }
        }
        let out = seg.run(&frames, now);
        assert!(out.len() <= 64, "{} frames out for one call", out.len());
        for f in &out {
            f.validate()
                .unwrap_or_else(|e| panic!("node sent an invalid frame {f:?}: {e}"));
            assert!(!f.extended && !f.rtr && !f.error, "node sent {f:?}");
            let node = f.id & 0x7F;
            let base = f.id & !0x7F;
            assert!(
                (node == 1 || node == 2)
                    && [0x080, 0x180, 0x280, 0x380, 0x480, 0x580, 0x700].contains(&base),
                "node sent from COB-ID {:#05x}",
                f.id
            );
        }
    }
});
