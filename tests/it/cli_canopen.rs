//! The CANopen command line on the emulated bus of the machine file (`--link canopen-emu`, one
//! CiA 402 node per axis, ids 1 …): `can scan`, `can dump`, `sdo read|write --node`, and `run`
//! with `--candump`. Expected values: CiA 402 device type 0x0192 (profile number 402) in the
//! low word of 0x1000, the seed's meas1 values, candump -L syntax.

use crate::common::cli;
use cli::{fieldprobe, stderr, stdout};

/// The default machine's cycle on CAN (issue 16): its three nodes need 4 ms at 1 Mbit/s (56 %
/// bus load; the default 1 ms would be 194 %, refused — docs/canopen.md "Bus load").
const CAN_CYCLE: &str = "cycle_time_us=4000";

#[test]
fn can_scan_finds_one_cia402_node_per_axis() {
    let o = fieldprobe(&["can", "scan", "--link", "canopen-emu"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    let rows: Vec<Vec<&str>> = out
        .lines()
        .skip(1)
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert_eq!(rows.len(), 3, "{out}");
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r[0], (k + 1).to_string());
        assert_eq!(r[1], "pre-operational");
        let dt = u32::from_str_radix(r[2].trim_start_matches("0x"), 16).unwrap();
        assert_eq!(dt & 0xFFFF, 402, "{out}");
    }
    // A machine of two axes has two nodes.
    let dir = tempfile::tempdir().unwrap();
    let machine = dir.path().join("xy.toml");
    std::fs::write(&machine, "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n").unwrap();
    let o = fieldprobe(&[
        "can",
        "scan",
        "--link",
        "canopen-emu",
        "--machine",
        machine.to_str().unwrap(),
    ]);
    assert_eq!(
        stdout(&o).lines().count(),
        1 + 2,
        "{}{}",
        stdout(&o),
        stderr(&o)
    );
}

#[test]
fn sdo_by_node_id_with_aborts_in_words() {
    let o = fieldprobe(&[
        "sdo",
        "read",
        "--link",
        "canopen-emu",
        "--node",
        "2",
        "0x1008",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).starts_with("0x1008:00 = \"fieldprobe CiA 402 node"),
        "{}",
        stdout(&o)
    );
    let o = fieldprobe(&[
        "sdo",
        "read",
        "--link",
        "canopen-emu",
        "--node",
        "1",
        "0x6065",
    ]);
    // drives/cia402-generic.toml: following_error_window = 300000.
    assert_eq!(stdout(&o).trim(), "0x6065:00 = 300000 (0x493e0)");
    let o = fieldprobe(&[
        "sdo",
        "write",
        "--link",
        "canopen-emu",
        "--node",
        "3",
        "0x6072",
        "500",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o).trim(), "0x6072:00 written (2 bytes)");
    let o = fieldprobe(&[
        "sdo",
        "read",
        "--link",
        "canopen-emu",
        "--node",
        "2",
        "0x5000",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("node 2")
            && stderr(&o).contains("0x5000:00")
            && stderr(&o).contains("abort code 0x06020000 (object does not exist"),
        "{}",
        stderr(&o)
    );
    let o = fieldprobe(&[
        "sdo",
        "read",
        "--link",
        "canopen-emu",
        "--device",
        "1",
        "0x1000",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("give --node N"), "{}", stderr(&o));
    let o = fieldprobe(&[
        "sdo",
        "read",
        "--link",
        "canopen-emu",
        "--node",
        "0",
        "0x1000",
    ]);
    assert_eq!(o.status.code(), Some(2));
    // The argument parser refuses it (docs/cli.md "Numbers on the command line"), naming the
    // option, the text and the range.
    let e = stderr(&o);
    assert!(
        e.contains("'0'") && e.contains("--node") && e.contains("1 … 127"),
        "{e}"
    );
}

#[test]
fn can_dump_prints_heartbeats_with_their_meaning() {
    let o = fieldprobe(&["can", "dump", "--link", "canopen-emu", "--seconds", "0.35"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    // Heartbeat every 100 ms (0x1017 default) from nodes 1 … 3, in pre-operational (0x7F).
    for node in 1..=3 {
        let n = out
            .lines()
            .filter(|l| {
                l.contains(&format!(
                    " 70{node}#7F  ; heartbeat node {node}: pre-operational"
                ))
            })
            .count();
        assert!(
            (2..=5).contains(&n),
            "node {node}: {n} heartbeats in 0.35 s\n{out}"
        );
    }
}

#[test]
fn run_over_canopen_with_a_candump_log() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("meas1.log");
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--link",
        "canopen-emu",
        "--set",
        CAN_CYCLE,
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("V.A.MEAS.ACS.VALUE.Z=100.000000"));
    let text = std::fs::read_to_string(&log).unwrap();
    let frames: Vec<_> = text
        .lines()
        .map(|l| {
            fieldprobe::bus::can::candump::parse_line(l).unwrap_or_else(|e| panic!("{l}: {e:?}"))
        })
        .collect();
    let id = |r: &fieldprobe::bus::can::CandumpRecord| r.frame.id;
    // NMT reset communication of all nodes first, boot-ups, then NMT start (0x01, all nodes).
    assert_eq!(frames[0].frame.payload(), &[0x82, 0x00]);
    assert!(frames
        .iter()
        .any(|r| id(r) == 0 && r.frame.payload() == [0x01, 0x00]));
    // One SYNC per cycle and every one answered by the 2 cyclic TPDOs (3 and 4) of each of the
    // 3 nodes; the touch probe positions (TPDOs 1 and 2, on change: issue 16) only at the
    // first SYNC and when a latch changed them — Z's probe 1 (0x183) at least once more.
    let syncs = frames.iter().filter(|r| id(r) == 0x080).count();
    let tpdo = |lo: u32, hi: u32| {
        frames
            .iter()
            .filter(|r| (lo..=hi).contains(&id(r)) && id(r) & 0x80 != 0)
            .count()
    };
    assert!(syncs > 1000, "{syncs} SYNCs");
    assert_eq!(tpdo(0x381, 0x4FF), 6 * syncs);
    let on_change = tpdo(0x181, 0x2FF);
    assert!((6..=20).contains(&on_change), "{on_change} on-change TPDOs");
    assert!(frames.iter().filter(|r| id(r) == 0x183).count() >= 2);
    // --candump needs a CAN link.
    let o = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--link",
        "sim",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn node_ids_from_the_machine_configuration() {
    // Z at node 42: the scan finds it there, and meas1 runs over it with the seed's value.
    let o = fieldprobe(&["can", "scan", "--link", "canopen-emu", "--set", "Z.node=42"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    let nodes: Vec<&str> = out
        .lines()
        .skip(1)
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(nodes, ["1", "2", "42"]);
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("node42.log");
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--link",
        "canopen-emu",
        "--set",
        CAN_CYCLE,
        "--set",
        "Z.node=42",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("V.A.MEAS.ACS.VALUE.Z=100.000000"));
    // Node 42's heartbeat (0x700 + 42 = 0x72A) is on the bus; nothing answers as node 3.
    let log = std::fs::read_to_string(&log).unwrap();
    assert!(log.contains(" 72A#"), "{log}");
    assert!(!log.contains(" 703#"), "{log}");
    // Two axes on one id: bad input, naming the axes.
    let o = fieldprobe(&["can", "scan", "--link", "canopen-emu", "--set", "Z.node=1"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("axes X and Z both have CANopen node id 1"),
        "{}",
        stderr(&o)
    );
}

// ---------------------------------------------------------------------------------------------
// The commissioning commands on the wire (issue 16): `can dump`, `can scan` and `sdo --node` on
// `canopen-emu` run on the same timed virtual bus as `run`, at the machine's bit rate.
// ---------------------------------------------------------------------------------------------

/// Bit times of a base-format data frame with `n` data bytes (ISO 11898-1: SOF 1, identifier
/// 11, RTR / IDE / r0 3, DLC 4, data 8 n, CRC 15, CRC delimiter 1, ACK 2, EOF 7, intermission
/// 3 = 47 + 8 n) without stuff bits, and with the most stuff bits the 34 + 8 n stuffed bits
/// (SOF … CRC) can need, one per 4 after the first.
fn wire_bits(n: u64) -> (u64, u64) {
    let plain = 47 + 8 * n;
    (plain, plain + (34 + 8 * n - 1) / 4)
}

/// The frames of candump -L lines (`--plain` output or a `--candump` log) with their times, µs.
fn frames(text: &str) -> Vec<(u64, fieldprobe::bus::can::CanFrame)> {
    text.lines()
        .map(|l| {
            let r = fieldprobe::bus::can::candump::parse_line(l)
                .unwrap_or_else(|e| panic!("{l}: {e:?}"));
            (r.timestamp.as_micros() as u64, r.frame)
        })
        .collect()
}

/// `t` µs lies within the wire time of `bits` = (fewest, most) bit times at `bps`, allowing
/// 1 µs for the µs resolution of the two timestamps.
fn within(t: u64, bits: (u64, u64), bps: u64) -> bool {
    let us = |b: u64| b * 1_000_000 / bps;
    t + 1 >= us(bits.0) && t <= us(bits.1) + 1
}

#[test]
fn can_dump_on_canopen_emu_takes_each_frames_wire_time_at_the_machines_bit_rate() {
    for (set, bps) in [(None, 1_000_000u64), (Some("can.bitrate=10k"), 10_000)] {
        let mut args = vec!["can", "dump", "--plain", "--link", "canopen-emu"];
        args.extend(["--seconds", "0.35"]);
        if let Some(s) = set {
            args.extend(["--set", s]);
        }
        let o = fieldprobe(&args);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let out = stdout(&o);
        let f = frames(&out);
        // Heartbeats of nodes 1 … 3 every 100 ms (in 0.35 s of bus time: 3 rounds).
        assert_eq!(f.len(), 9, "{bps} bit/s:\n{out}");
        for (k, w) in f.windows(2).enumerate() {
            let ((t0, a), (t1, b)) = (w[0], w[1]);
            let dt = t1 - t0;
            // The next frame reaches the master one wire time after the previous one at the
            // earliest (it cannot use the bus before the previous one left it).
            let bits = wire_bits(u64::from(b.len));
            assert!(
                dt + 1 >= bits.0 * 1_000_000 / bps,
                "{bps} bit/s, line {k}: {dt} µs after the previous frame, a {}-byte frame \
                 takes {} µs at least\n{out}",
                b.len,
                bits.0 * 1_000_000 / bps
            );
            // The three heartbeats of one round are sent together: they go in the order of
            // their identifiers (arbitration), back to back.
            if a.id + 1 == b.id {
                assert!(
                    within(dt, bits, bps),
                    "{bps} bit/s, line {k}: heartbeat {:#x} {dt} µs after {:#x}, its wire time \
                     is {:?} bit times\n{out}",
                    b.id,
                    a.id,
                    bits
                );
            }
        }
        for round in f.chunks(3) {
            let ids: Vec<u32> = round.iter().map(|(_, f)| f.id).collect();
            assert_eq!(ids, [0x701, 0x702, 0x703], "{bps} bit/s:\n{out}");
        }
    }
}

#[test]
fn can_scan_and_sdo_on_canopen_emu_run_on_the_wire() {
    let dir = tempfile::tempdir().unwrap();
    // sdo read at 10 kbit/s: the request (8 bytes) leaves the master onto an idle bus, the node
    // answers when it has received it, the answer (8 bytes) takes its own wire time — 22.2 to
    // 27 ms after the request, in the log.
    let log = dir.path().join("sdo.log");
    let o = fieldprobe(&[
        "sdo",
        "read",
        "--link",
        "canopen-emu",
        "--set",
        "can.bitrate=10k",
        "--node",
        "2",
        "0x6065",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o).trim(), "0x6065:00 = 300000 (0x493e0)");
    let text = std::fs::read_to_string(&log).unwrap();
    let f = frames(&text);
    let req = f.iter().find(|(_, f)| f.id == 0x602).expect("request");
    let resp = f.iter().find(|(_, f)| f.id == 0x582).expect("answer");
    let (lo, hi) = (wire_bits(8), wire_bits(8));
    assert!(
        within(resp.0 - req.0, (lo.0 + hi.0, lo.1 + hi.1), 10_000),
        "answer {} µs after the request\n{text}",
        resp.0 - req.0
    );
    // can scan at 1 Mbit/s: 127 SDO requests queued at once; the frames the nodes send
    // reach the master one after another, each a wire time after the one before.
    let log = dir.path().join("scan.log");
    let o = fieldprobe(&[
        "can",
        "scan",
        "--link",
        "canopen-emu",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 1 + 3, "{}", stdout(&o));
    let text = std::fs::read_to_string(&log).unwrap();
    let from_nodes: Vec<_> = frames(&text)
        .into_iter()
        .filter(|(_, f)| (0x581..=0x583).contains(&f.id) || (0x701..=0x703).contains(&f.id))
        .collect();
    assert!(from_nodes.len() >= 3 * 5, "{text}");
    for w in from_nodes.windows(2) {
        let ((t0, _), (t1, b)) = (w[0], w[1]);
        let least = wire_bits(u64::from(b.len)).0;
        assert!(
            t1 - t0 + 1 >= least,
            "{:#x} {} µs after the node frame before it (at least {least} µs)\n{text}",
            b.id,
            t1 - t0
        );
    }
}
