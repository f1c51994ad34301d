//! Issue 18, item 4: every message said once, naming the real cause, and help that offers
//! only what the command takes.
//!
//! The cases of the issue, each reproduced the way a user meets it: a raw socket without
//! CAP_NET_RAW (`unshare -r`: root of a user namespace, no capability over the host's
//! network), an SDO to a CANopen node that is not there (CAN over UDP multicast in a private
//! namespace with nothing else on it), `--link ethercat:lo` without the capability, an unknown
//! link, `scan` on a wire with nothing on it (one end of a veth pair in a private namespace).
//! Where a namespace cannot be made the test prints `SKIP` and passes.

use crate::common::cli;
use crate::common::netns;

use cli::{fieldprobe, stderr};
use std::process::Command;
use std::time::Duration;

/// `count` occurrences of `needle` in `text`.
#[track_caller]
fn occurs(text: &str, needle: &str, count: usize) {
    assert_eq!(
        text.matches(needle).count(),
        count,
        "{needle:?} should occur {count}×: {text}"
    );
}

/// `sh -c SCRIPT` in the crate directory under `wrap` (e.g. `unshare -r`), at most 60 s:
/// (exit code, stdout, stderr). `None` when `wrap` cannot run here (SKIP).
fn wrapped(wrap: &[&str], script: &str) -> Option<(Option<i32>, String, String)> {
    let probe = Command::new(wrap[0])
        .args(&wrap[1..])
        .arg("true")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()?;
    if !probe.status.success() {
        return None;
    }
    let (status, out, err) = netns::run_bounded(
        Command::new(wrap[0])
            .args(&wrap[1..])
            .args(["sh", "-c", script])
            .env("FIELDPROBE", env!("CARGO_BIN_EXE_fieldprobe"))
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        Duration::from_secs(60),
    );
    Some((status.and_then(|s| s.code()), out, err))
}

#[test]
fn a_refused_raw_socket_is_said_once() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `… (needs CAP_NET_RAW): Operation not permitted (os error 1): Operation not
    // permitted (os error 1)` from `sim ethercat`, and `--link ethercat:lo: ethercat:lo: …`.
    let Some((code, _, err)) = wrapped(
        &["unshare", "-r"],
        "\"$FIELDPROBE\" sim ethercat --iface lo --device esi/fieldprobe-cia402-servo.xml --seconds 0; \
         \"$FIELDPROBE\" run examples/nc/hello.nc --link ethercat:lo; \
         \"$FIELDPROBE\" scan --link ethercat:lo",
    ) else {
        eprintln!("SKIP a_refused_raw_socket_is_said_once: `unshare -r` not available");
        return;
    };
    assert_eq!(code, Some(2), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("CAP_NET_RAW")).collect();
    assert_eq!(lines.len(), 3, "{err}");
    for l in &lines {
        occurs(l, "Operation not permitted", 1);
        occurs(l, "interface lo", 1);
    }
    for l in &lines[1..] {
        assert!(
            l.starts_with("fieldprobe: --link ethercat:lo: interface lo:"),
            "{err}"
        );
    }
    occurs(&err, "ethercat:lo", 2);
}

#[test]
fn a_missing_interface_is_said_once() {
    let _one_module = crate::gate::enter(module_path!());
    // No namespace needed: an interface that does not exist, for `run` (the machine's link)
    // and `scan` (a session).
    for args in [
        &[
            "run",
            "examples/nc/hello.nc",
            "--link",
            "ethercat:fp-no-such0",
        ][..],
        &["scan", "--link", "ethercat:fp-no-such0"],
    ] {
        let o = fieldprobe(args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{e}");
        assert!(
            e.starts_with("fieldprobe: --link ethercat:fp-no-such0: interface fp-no-such0: no such network interface"),
            "{args:?}: {e}"
        );
        occurs(&e, "ethercat:fp-no-such0", 1);
    }
}

#[test]
fn a_node_that_does_not_answer_is_said_once() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `SDO 0x1000:00: SDO 0x1000:00: no response`. Nothing on this bus answers.
    let Some((code, out, err)) = wrapped(
        &["unshare", "-rn"],
        &format!(
            "{} && \"$FIELDPROBE\" sdo read --link canopen-udp:239.74.163.19:43119 --node 5 0x1000; \
             echo rc=$?; \"$FIELDPROBE\" can scan --link canopen-udp:239.74.163.19:43119",
            netns::NETNS_SETUP
        ),
    ) else {
        eprintln!("SKIP a_node_that_does_not_answer_is_said_once: `unshare -rn` not available");
        return;
    };
    assert!(out.contains("rc=2"), "{out}{err}");
    let line = err
        .lines()
        .find(|l| l.contains("no response"))
        .unwrap_or_else(|| panic!("no time-out message: {err}"));
    occurs(line, "SDO 0x1000:00", 1);
    assert!(
        line.starts_with("fieldprobe: node 5: SDO 0x1000:00: no response"),
        "{line}"
    );
    // `can scan` on the silent bus: exit 0, and it says that nobody answered.
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("no CANopen node answered on --link canopen-udp:239.74.163.19:43119"),
        "{err}"
    );
}

#[test]
fn an_unknown_link_is_called_unknown() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `sdo read --link bogus --node 1` said "give --device N".
    let o = fieldprobe(&["sdo", "read", "--link", "bogus", "--node", "1", "0x1000"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--link bogus: unknown link"), "{e}");
    for form in [
        "ethercat-emu",
        "ethercat:IFACE",
        "canopen-emu",
        "canopen-udp[:GROUP:PORT]",
        "socketcan:IF",
    ] {
        assert!(e.contains(form), "{form} not listed: {e}");
    }
    assert!(!e.contains("give --device"), "{e}");
    // Each command lists the links it takes.
    let o = fieldprobe(&["scan", "--link", "bogus"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        e.contains("unknown link") && e.contains("ethercat:IFACE"),
        "{e}"
    );
    assert!(!e.contains("socketcan"), "{e}");
    let o = fieldprobe(&["can", "dump", "--link", "bogus"]);
    let e = stderr(&o);
    assert!(
        e.contains("unknown link") && e.contains("socketcan:IF"),
        "{e}"
    );
    assert!(!e.contains("ethercat:IFACE"), "{e}");
    // An interface name is missing: said so.
    let o = fieldprobe(&["scan", "--link", "ethercat:"]);
    assert!(stderr(&o).contains("no interface name"), "{}", stderr(&o));
}

#[test]
fn a_node_the_emulator_does_not_have_is_named() {
    let _one_module = crate::gate::enter(module_path!());
    // canopen-emu emulates one node per axis of the machine file (default X, Y, Z: 1, 2, 3).
    let o = fieldprobe(&["sdo", "read", "--node", "9", "0x1000"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("--node 9: --link canopen-emu emulates node(s) 1, 2, 3"),
        "{e}"
    );
    // Without --link, --node means the emulated CANopen nodes, --device the emulated segment.
    let o = fieldprobe(&["sdo", "read", "--node", "1", "0x1000"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn scan_on_a_wire_with_nothing_says_no_device_answered() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `scan` on a wire with nothing said only `EtherCAT init: timeout: PDU`. One end
    // of a veth pair whose other end nobody serves.
    let Some((code, _, err)) = wrapped(
        &["scripts/netns.sh"],
        "\"$FIELDPROBE\" scan --link ethercat:v0",
    ) else {
        eprintln!(
            "SKIP scan_on_a_wire_with_nothing_says_no_device_answered: scripts/netns.sh (unshare + veth) not available"
        );
        return;
    };
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--link ethercat:v0: no EtherCAT device answered on v0"),
        "{err}"
    );
    // Issue 26: what was tried, and how long (the first frame of the start-up, a broadcast
    // read, sent ten times 20 ms apart: SOEM and IgH repeat a datagram too).
    assert!(
        err.contains(": BRD 0x0000:0x0000 (")
            && err.contains("sent 10 times, came back from no device within 2"),
        "{err}"
    );
    occurs(&err, "ethercat:v0", 1);
}

/// `sim ethercat` (a coupler and eight servos) on v1 losing the frames `lose`
/// (`--lose-frames`), then `scan` on v0: (exit code of scan, stdout, stderr).
fn scan_with_lost_frames(lose: &str) -> Option<(Option<i32>, String, String)> {
    wrapped(
        &["scripts/netns.sh"],
        &format!(
            "log=$(mktemp); \
             \"$FIELDPROBE\" sim ethercat --iface v1 --device esi/fieldprobe-ek1100.xml \
               --device esi/fieldprobe-cia402-servo.xml:8 --lose-frames {lose} --seconds 50 2>$log & \
             n=0; until grep -q 'listening on' $log; do sleep 0.05; n=$((n+1)); \
               [ $n -lt 400 ] || {{ cat $log >&2; exit 9; }}; done; \
             \"$FIELDPROBE\" scan --link ethercat:v0; code=$?; kill $! 2>/dev/null; exit $code"
        ),
    )
}

#[test]
fn scan_repeats_a_frame_the_wire_lost() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 26: `scan` failed 2 of 20 times against 9 emulated devices on a loaded machine
    // ("no EtherCAT device answered … check that a device is connected"): one late or lost
    // frame ended the start-up. A real master sends it again. The emulator loses the first
    // frame three times over (frames 0, 1, 2 are the first broadcast read and its first two
    // repeats) and four frames later in the start-up.
    let Some((code, out, err)) = scan_with_lost_frames("0,1,2,5,9,20,40") else {
        eprintln!("SKIP scan_repeats_a_frame_the_wire_lost: scripts/netns.sh (unshare + veth) not available");
        return;
    };
    assert_eq!(code, Some(0), "{out}{err}");
    let devices = out.lines().filter(|l| l.contains("0x00000fb0")).count();
    assert_eq!(devices, 9, "{out}");
    assert_eq!(out.matches("FP-CIA402-SERVO").count(), 8, "{out}");
}

#[test]
fn a_segment_that_stops_answering_is_told_from_an_empty_wire() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 26: "device N answered before and then not within T after K tries" apart from "no
    // device on this interface". The emulator answers the first 30 frames and no more (a
    // pulled cable); the broadcast datagram ethercrab sends next is named, with its tries and
    // the time, and the 30 replies that came before.
    let Some((code, out, err)) = scan_with_lost_frames("30..") else {
        eprintln!("SKIP a_segment_that_stops_answering_is_told_from_an_empty_wire: scripts/netns.sh (unshare + veth) not available");
        return;
    };
    assert_eq!(code, Some(2), "{out}{err}");
    assert!(
        err.contains("--link ethercat:v0: ")
            && err.contains(" on v0 answered before (30 frames came back) and then not: ")
            && err.contains(", sent 10 times, no reply within 2"),
        "{err}"
    );
    assert!(!err.contains("no EtherCAT device answered"), "{err}");
    assert!(!err.contains("check that a device is connected"), "{err}");
    occurs(&err, "ethercat:v0", 1);
}

/// The `--link` help text of `args --help` (the lines from `--link` to the next option).
fn link_help(args: &[&str]) -> String {
    let o = fieldprobe(&[args, &["--help"]].concat());
    assert_eq!(o.status.code(), Some(0));
    let text = cli::stdout(&o);
    let start = text.find("--link").expect("--link in help");
    let rest = &text[start..];
    let end = rest[6..].find("\n      --").map_or(rest.len(), |k| k + 6);
    rest[..end].to_string()
}

#[test]
fn help_offers_what_the_command_takes() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: one shared `--link` text offered CAN links to `scan` / `idn`, which refused
    // them; `--pcap` on `can` commands and `--candump` on EtherCAT commands were offered.
    for cmd in [&["scan"][..], &["idn", "read"], &["idn", "write"]] {
        let h = link_help(cmd);
        assert!(
            h.contains("ethercat-emu") && h.contains("ethercat:IFACE"),
            "{h}"
        );
        for can in ["canopen-emu", "canopen-udp", "socketcan"] {
            assert!(!h.contains(can), "{cmd:?} --link offers {can}: {h}");
        }
        let all = cli::stdout(&fieldprobe(&[cmd, &["--help"]].concat()));
        assert!(
            all.contains("--pcap") && !all.contains("--candump"),
            "{all}"
        );
    }
    for cmd in [&["can", "scan"][..], &["can", "dump"]] {
        let h = link_help(cmd);
        assert!(
            h.contains("canopen-emu") && h.contains("socketcan:IF"),
            "{h}"
        );
        assert!(
            !h.contains("ethercat"),
            "{cmd:?} --link offers EtherCAT: {h}"
        );
        let all = cli::stdout(&fieldprobe(&[cmd, &["--help"]].concat()));
        assert!(
            all.contains("--candump") && !all.contains("--pcap"),
            "{all}"
        );
    }
    // `sdo` takes both families: both offered, each capture with the links it is for.
    let all = cli::stdout(&fieldprobe(&["sdo", "read", "--help"]));
    for form in [
        "ethercat:IFACE",
        "canopen-emu",
        "socketcan:IF",
        "--pcap",
        "--candump",
    ] {
        assert!(all.contains(form), "{form}: {all}");
    }
    // What the help offers is taken: every command's default link works.
    for args in [
        &["scan"][..],
        &["can", "scan"],
        &["can", "dump", "--seconds", "0"],
    ] {
        let o = fieldprobe(args);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
    }
}
