//! The CANopen command line on the emulated bus of the machine file (`--link canopen-emu`, one
//! CiA 402 node per axis, ids 1 …): `can scan`, `can dump`, `sdo read|write --node`, and `run`
//! with `--candump`. Expected values: CiA 402 device type 0x0192 (profile number 402) in the
//! low word of 0x1000, the seed's meas1 values, candump -L syntax.

#[path = "common/cli.rs"]
mod cli;
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
