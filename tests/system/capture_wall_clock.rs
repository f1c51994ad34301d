//! Captures are stamped with the wall-clock time of the run (issue 18 item 5), emulated links
//! too: a `run --pcap` on `ethercat-emu` and a `run --candump` on `canopen-emu`.
//!
//! Expected values, computed here and not by the code under test:
//! - the first frame's time lies between the wall clock read just before the run started and
//!   just after it ended (`SystemTime`, ns since the Unix epoch; the old captures started at
//!   1970-01-01);
//! - the emulated links run on virtual time, so consecutive cycles are exactly one machine
//!   cycle apart in the capture (`--set cycle_time_us=…`): every outgoing EtherCAT frame that
//!   carries the process data (an LRW datagram, ETG.1000.4 command 12) follows the previous
//!   one by the cycle time to the ns; every CANopen SYNC (COB-ID 0x080, CiA 301) the previous
//!   one by the cycle time to the µs (candump's resolution).
//!
//! The pcap file is read twice, independently of the crate: by a byte-level parse of the
//! classic pcap format here (global header, 16-byte record headers), and by `tshark -r FILE -T
//! fields -e frame.time_epoch` (Wireshark's reader; `.ci/run` installs it, elsewhere the tshark
//! part prints `SKIP` when it is missing). The candump log is read with plain string splitting
//! (`(SECS.USECS) IFACE ID#DATA`).

use crate::common::cli;

use std::process::Command;
use std::time::{SystemTime, UNIX_EPOCH};

use cli::{fieldprobe, stderr};

fn unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

/// One record of a classic pcap file: (timestamp ns since the epoch, frame bytes).
type Record = (u64, Vec<u8>);

/// Classic pcap (libpcap format): 24-byte global header (magic 0xa1b2c3d4 µs or 0xa1b23c4d
/// ns, in the writer's byte order), then per record ts_sec, ts_frac, incl_len, orig_len and the
/// data.
fn parse_pcap(bytes: &[u8]) -> Vec<Record> {
    assert!(bytes.len() >= 24, "pcap shorter than its header");
    let magic_le = u32::from_le_bytes(bytes[0..4].try_into().unwrap());
    let magic_be = u32::from_be_bytes(bytes[0..4].try_into().unwrap());
    let (le, nanos) = match (magic_le, magic_be) {
        (0xa1b2_c3d4, _) => (true, false),
        (0xa1b2_3c4d, _) => (true, true),
        (_, 0xa1b2_c3d4) => (false, false),
        (_, 0xa1b2_3c4d) => (false, true),
        _ => panic!("not a classic pcap file: magic {magic_le:#010x}"),
    };
    let u32_at = |at: usize| {
        let b: [u8; 4] = bytes[at..at + 4].try_into().unwrap();
        if le {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        }
    };
    let mut out = Vec::new();
    let mut at = 24;
    while at < bytes.len() {
        assert!(at + 16 <= bytes.len(), "truncated record header at {at}");
        let sec = u64::from(u32_at(at));
        let frac = u64::from(u32_at(at + 4));
        let len = u32_at(at + 8) as usize;
        assert!(at + 16 + len <= bytes.len(), "truncated record at {at}");
        let ns = sec * 1_000_000_000 + if nanos { frac } else { frac * 1000 };
        out.push((ns, bytes[at + 16..at + 16 + len].to_vec()));
        at += 16 + len;
    }
    out
}

/// Does this Ethernet frame carry an EtherCAT LRW datagram (command 12)? Walks the datagrams:
/// 10-byte header (command, index, address 4, length 11 bits + "more" bit 15, IRQ 2), data,
/// working counter 2 (ETG.1000.4 §5.4).
fn has_lrw(f: &[u8]) -> bool {
    if f.len() < 16 || f[12..14] != [0x88, 0xA4] {
        return false;
    }
    let mut at = 16;
    while at + 10 <= f.len() {
        let cmd = f[at];
        let len_field = u16::from_le_bytes([f[at + 6], f[at + 7]]);
        if cmd == 12 {
            return true;
        }
        if len_field & 0x8000 == 0 {
            return false;
        }
        at += 10 + usize::from(len_field & 0x07FF) + 2;
    }
    false
}

/// `tshark -r FILE -T fields -e frame.time_epoch`, as ns since the epoch; `None` (SKIP) when
/// tshark is not installed.
fn tshark_epochs(file: &std::path::Path) -> Option<Vec<u64>> {
    let o = match Command::new("tshark")
        .args(["-r"])
        .arg(file)
        .args(["-T", "fields", "-e", "frame.time_epoch"])
        .output()
    {
        Ok(o) => o,
        Err(e) => {
            eprintln!("SKIP tshark part: tshark not runnable ({e}; Debian package tshark)");
            return None;
        }
    };
    assert!(
        o.status.success(),
        "tshark failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = String::from_utf8(o.stdout).unwrap();
    Some(
        text.lines()
            .map(|l| {
                let (s, f) = l.trim().split_once('.').unwrap_or((l.trim(), "0"));
                let mut frac = f.to_string();
                frac.truncate(9);
                while frac.len() < 9 {
                    frac.push('0');
                }
                s.parse::<u64>().unwrap() * 1_000_000_000 + frac.parse::<u64>().unwrap()
            })
            .collect(),
    )
}

#[test]
fn ethercat_emu_pcap_is_dated_now_and_spaced_by_the_cycle() {
    let _one_module = crate::gate::enter(module_path!());
    const CYCLE_US: u64 = 2000;
    let dir = tempfile::tempdir().unwrap();
    let pcap = dir.path().join("meas1.pcap");
    let before = unix_ns();
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--link",
        "ethercat-emu",
        "--set",
        &format!("cycle_time_us={CYCLE_US}"),
        "--pcap",
        pcap.to_str().unwrap(),
    ]);
    let after = unix_ns();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let recs = parse_pcap(&std::fs::read(&pcap).unwrap());
    assert!(recs.len() > 1000, "{} frames", recs.len());
    let first = recs[0].0;
    assert!(
        (before..=after).contains(&first),
        "first frame at {first} ns, the run took place from {before} to {after} ns"
    );
    // Time never runs backwards in the capture.
    assert!(recs.windows(2).all(|w| w[0].0 <= w[1].0));
    // The process-data frames the master sent (source MAC without the U/L bit the devices
    // set), one per cycle, exactly one cycle apart.
    let cyc: Vec<u64> = recs
        .iter()
        .filter(|(_, f)| f.len() > 6 && f[6] & 0x02 == 0 && has_lrw(f))
        .map(|(t, _)| *t)
        .collect();
    assert!(cyc.len() > 100, "{} process-data frames", cyc.len());
    let gaps: Vec<u64> = cyc.windows(2).map(|w| w[1] - w[0]).collect();
    let off: Vec<(usize, u64)> = gaps
        .iter()
        .copied()
        .enumerate()
        .filter(|&(_, g)| g != CYCLE_US * 1000)
        .collect();
    assert!(
        off.is_empty(),
        "{} of {} cycle gaps are not {CYCLE_US} µs: first {:?}",
        off.len(),
        gaps.len(),
        &off[..off.len().min(5)]
    );
    // Wireshark reads the same times.
    if let Some(epochs) = tshark_epochs(&pcap) {
        assert_eq!(epochs.len(), recs.len(), "tshark frame count");
        for (k, (t, (ours, _))) in epochs.iter().zip(&recs).enumerate() {
            assert_eq!(t, ours, "frame {k}: tshark {t} ns, parsed {ours} ns");
        }
        assert!((before..=after).contains(&epochs[0]));
    }
}

#[test]
fn canopen_emu_candump_is_dated_now_and_spaced_by_the_cycle() {
    let _one_module = crate::gate::enter(module_path!());
    // The default machine's three nodes need 4 ms at 1 Mbit/s (tests/it/cli_canopen.rs).
    const CYCLE_US: u64 = 4000;
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("meas1.log");
    let before_us = unix_ns() / 1000;
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--link",
        "canopen-emu",
        "--set",
        &format!("cycle_time_us={CYCLE_US}"),
        "--candump",
        log.to_str().unwrap(),
    ]);
    let after_us = unix_ns().div_ceil(1000);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(&log).unwrap();
    // `(SECS.USECS) IFACE ID#DATA`, times in µs since the epoch.
    let lines: Vec<(u64, String)> = text
        .lines()
        .map(|l| {
            let (ts, rest) = l.split_once(' ').unwrap();
            let (s, us) = ts
                .trim_start_matches('(')
                .trim_end_matches(')')
                .split_once('.')
                .unwrap();
            assert_eq!(us.len(), 6, "{l}");
            let t = s.parse::<u64>().unwrap() * 1_000_000 + us.parse::<u64>().unwrap();
            let id = rest
                .split_whitespace()
                .nth(1)
                .unwrap()
                .split('#')
                .next()
                .unwrap();
            (t, id.to_string())
        })
        .collect();
    assert!(lines.len() > 1000, "{} lines", lines.len());
    let first = lines[0].0;
    assert!(
        (before_us..=after_us).contains(&first),
        "first frame at {first} µs, the run took place from {before_us} to {after_us} µs"
    );
    assert!(lines.windows(2).all(|w| w[0].0 <= w[1].0));
    let syncs: Vec<u64> = lines
        .iter()
        .filter(|(_, id)| id == "080")
        .map(|(t, _)| *t)
        .collect();
    assert!(syncs.len() > 100, "{} SYNCs", syncs.len());
    let gaps: Vec<u64> = syncs.windows(2).map(|w| w[1] - w[0]).collect();
    let off: Vec<(usize, u64)> = gaps
        .iter()
        .copied()
        .enumerate()
        .filter(|&(_, g)| g != CYCLE_US)
        .collect();
    assert!(
        off.is_empty(),
        "{} of {} SYNC gaps are not {CYCLE_US} µs: first {:?}",
        off.len(),
        gaps.len(),
        &off[..off.len().min(5)]
    );
}
