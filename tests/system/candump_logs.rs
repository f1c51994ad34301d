//! Logs that other tools read (issue 14, item 4).
//!
//! * The interface field of every `--candump` line is a name the kernel and `canplayer` take:
//!   `canplayer` refuses a name of IFNAMSIZ (16) bytes or more and sends each line on the
//!   interface it names; the kernel's `dev_valid_name` refuses `/`, `:` and blanks. This machine
//!   has no SocketCAN, so `canplayer` (which opens a CAN socket before it reads a line) cannot
//!   run here; the tests hold the names to `^[A-Za-z0-9_-]{1,15}$`, a subset of the kernel's
//!   rule, and expect the names docs/canopen.md gives (`emu0` for canopen-emu, `udp0` for
//!   python-can's udp_multicast, the kernel's name for `socketcan:IF`).
//! * python-can 4.6.1's `can.CanutilsLogReader` (`tests/python/read_candump.py`, venv from
//!   `scripts/python-can-venv.sh`; PyPI unreachable is a failure, not a skip) is the independent
//!   reader: it reads every line of a `run --candump` log and of `can dump --plain`, and each
//!   message has the interface, identifier and data the line holds (split by this file's own
//!   small parser, not by the crate's).
//! * Logs written before the rule (`socketcan_vcan0`, `udp_239.74.163.2:43113`, `vcan-emu`)
//!   still read with the crate's reader (`can scan --candump` and the replay tests use it).

use crate::common::cli;
use crate::common::netns;

use cli::{fieldprobe, stderr, stdout};
use fieldprobe::bus::can::candump::{interface_name, is_interface_name, parse_line};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// `^[A-Za-z0-9_-]{1,15}$`: an interface name `canplayer` and the kernel take.
fn kernel_safe(name: &str) -> bool {
    (1..=15).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// One `candump -L` line split by hand: `(SECS.USECS) IFACE ID#DATA` (no error frames, no FD).
#[derive(Debug, Clone, PartialEq)]
struct Line {
    t: f64,
    iface: String,
    id: u32,
    ext: bool,
    rtr: bool,
    data: Vec<u8>,
}

fn split_line(l: &str) -> Line {
    let f: Vec<&str> = l.split_whitespace().collect();
    assert_eq!(f.len(), 3, "three fields: {l:?}");
    let t = f[0]
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("timestamp of {l:?}"));
    let (id, data) = f[2].split_once('#').unwrap_or_else(|| panic!("{l:?}"));
    let rtr = data.starts_with('R');
    let data = if rtr {
        Vec::new()
    } else {
        (0..data.len() / 2)
            .map(|i| u8::from_str_radix(&data[2 * i..2 * i + 2], 16).expect("hex data"))
            .collect()
    };
    Line {
        t,
        iface: f[1].to_string(),
        id: u32::from_str_radix(id, 16).expect("hex identifier"),
        ext: id.len() == 8,
        rtr,
        data,
    }
}

/// python-can's reading of `log`: one JSON value per message.
fn python_can_reads(log: &Path) -> Vec<serde_json::Value> {
    let python = netns::ensure_venv();
    let (status, out, err) = netns::run_bounded(
        Command::new(python)
            .arg(netns::manifest_path("tests/python/read_candump.py"))
            .arg(log),
        Duration::from_secs(120),
    );
    assert!(
        status.is_some_and(|s| s.success()),
        "python-can's CanutilsLogReader refused {}: {status:?}\n{err}",
        log.display()
    );
    let mut lines: Vec<&str> = out.lines().collect();
    let done = lines.pop().unwrap_or_default();
    let msgs: Vec<serde_json::Value> = lines
        .iter()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
        .collect();
    assert_eq!(done, format!("DONE {}", msgs.len()));
    msgs
}

/// Every line of `log` is a message python-can read back with the same fields, and its
/// interface is `iface`. Returns the number of frames.
fn assert_python_can_agrees(log: &Path, iface: &str) -> usize {
    let text = std::fs::read_to_string(log).unwrap();
    let lines: Vec<Line> = text.lines().map(split_line).collect();
    let msgs = python_can_reads(log);
    assert_eq!(
        msgs.len(),
        lines.len(),
        "python-can read {} of {} lines",
        msgs.len(),
        lines.len()
    );
    for (k, (l, m)) in lines.iter().zip(&msgs).enumerate() {
        assert_eq!(l.iface, iface, "line {k}: {l:?}");
        assert!(kernel_safe(&l.iface), "line {k}: {l:?}");
        let hex: String = l.data.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(m["channel"], l.iface.as_str(), "line {k}: {m}");
        assert_eq!(m["id"], l.id, "line {k}: {m}");
        assert_eq!(m["ext"], l.ext, "line {k}: {m}");
        assert_eq!(m["rtr"], l.rtr, "line {k}: {m}");
        assert_eq!(m["err"], false, "line {k}: {m}");
        assert_eq!(m["data"], hex.as_str(), "line {k}: {m}");
        let t = m["t"].as_f64().unwrap_or(f64::NAN);
        assert!((t - l.t).abs() < 1e-5, "line {k}: {t} vs {}", l.t);
    }
    lines.len()
}

#[test]
fn interface_names_follow_the_kernel_rules() {
    let _one_module = crate::gate::enter(module_path!());
    // dev_valid_name: 1 … 15 bytes, not "." / "..", no '/', ':' or blanks.
    for ok in [
        "vcan0",
        "can0",
        "emu0",
        "udp0",
        "socketcan_vcan0",
        "can0.100",
        "x",
    ] {
        assert!(is_interface_name(ok), "{ok}");
        assert_eq!(interface_name(ok), ok);
    }
    for bad in [
        "",
        ".",
        "..",
        "udp_239.74.163.2:43113",
        "udp 239.74.163.2:43113",
        "a/b",
        "sixteen_bytes_xx",
        "socketcan:vcan0",
    ] {
        assert!(!is_interface_name(bad), "{bad:?}");
        let made = interface_name(bad);
        assert!(kernel_safe(&made), "{bad:?} -> {made:?}");
    }
    assert_eq!(interface_name("udp 239.74.163.2:43113"), "udp_239_74_163_");
    assert_eq!(interface_name(""), "can0");
}

#[test]
fn logs_written_before_the_rule_still_read() {
    let _one_module = crate::gate::enter(module_path!());
    for (line, iface) in [
        (
            "(1700000000.000100) socketcan_vcan0 701#05",
            "socketcan_vcan0",
        ),
        (
            "(1700000000.000200) udp_239.74.163.2:43113 000#8000",
            "udp_239.74.163.2:43113",
        ),
        (
            "(1700000000.000300) vcan-emu 601#4000100000000000",
            "vcan-emu",
        ),
        ("(1700000000.000400) emu0 080#", "emu0"),
    ] {
        let r = parse_line(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        assert_eq!(r.interface, iface);
        let own = split_line(line);
        assert_eq!(r.frame.id, own.id);
        assert_eq!(r.frame.payload(), own.data.as_slice());
    }
}

#[test]
fn run_over_canopen_emu_logs_emu0_and_python_can_reads_every_frame() {
    let _one_module = crate::gate::enter(module_path!());
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("meas1.log");
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--link",
        "canopen-emu",
        // Issue 16: three nodes need 4 ms at 1 Mbit/s (docs/canopen.md "Bus load").
        "--set",
        "cycle_time_us=4000",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let n = assert_python_can_agrees(&log, "emu0");
    // meas1: thousands of cycles, each a SYNC, 6 cyclic TPDOs and the RPDOs.
    assert!(n > 10_000, "{n} frames");
}

#[test]
fn can_dump_plain_is_read_by_python_can_and_the_default_keeps_the_meaning() {
    let _one_module = crate::gate::enter(module_path!());
    let o = fieldprobe(&[
        "can",
        "dump",
        "--link",
        "canopen-emu",
        "--seconds",
        "0.35",
        "--plain",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(!out.contains(';'), "{out}");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("dump.log");
    std::fs::write(&file, &out).unwrap();
    // Heartbeats of nodes 1 … 3 every 100 ms: at least 2 each in 0.35 s.
    let n = assert_python_can_agrees(&file, "emu0");
    assert!(n >= 6, "{n} frames:\n{out}");
    let msgs = python_can_reads(&file);
    for node in 1..=3u32 {
        assert!(
            msgs.iter()
                .any(|m| m["id"] == 0x700 + node && m["data"] == "7f"),
            "no heartbeat of node {node}:\n{out}"
        );
    }
    // Without --plain: the meaning after `  ; `, which python-can's reader refuses (the reason
    // for --plain); the interface is the same short name.
    let o = fieldprobe(&["can", "dump", "--link", "canopen-emu", "--seconds", "0.25"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.lines()
            .any(|l| l.contains(" emu0 701#7F  ; heartbeat node 1: pre-operational")),
        "{out}"
    );
}

#[test]
fn can_dump_candump_log_names_the_interface_emu0() {
    let _one_module = crate::gate::enter(module_path!());
    // `can dump --candump FILE` writes the same plain lines into a file.
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("dump.log");
    let o = fieldprobe(&[
        "can",
        "dump",
        "--link",
        "canopen-emu",
        "--seconds",
        "0.25",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let n = assert_python_can_agrees(&log, "emu0");
    assert!(n >= 3, "{n} frames");
}
