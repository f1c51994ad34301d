//! The links that leave the process open through the public link API (`link::open`) with only
//! their bus's Cargo feature, without the emulators (issue 17): `.ci/run` builds and runs this
//! file with `--no-default-features --features ethercat` and with `--no-default-features
//! --features canopen,socketcan` (the default run has every feature and runs it too).
//!
//! - `ethercat:IFACE` on an interface that does not exist: the error names the link and the
//!   interface, not a missing feature.
//! - `ethercat:v0` on one end of a veth pair in a private user + network namespace (re-run of
//!   this test binary under `unshare -rn`, bounded in time): the link opens its raw socket and
//!   its master puts EtherCAT frames on the wire, which a raw socket on the other end `v1`
//!   receives; with nothing answering, the start-up fails with ethercrab's init error. Its
//!   `--pcap` capture is stamped with the wall clock of the open (issue 18). Prints `SKIP`
//!   where unprivileged namespaces or `ip` are missing.
//! - `socketcan:IF` on an interface that does not exist: the SocketCAN error names the
//!   interface, not a missing feature.
//! - Without `sim`: `ethercat-emu` and `canopen-emu` say which feature they need.

#![allow(dead_code)] // each feature set uses its own subset

use std::sync::Arc;

use fieldprobe::drive::catalogue::DriveDefinition;
use fieldprobe::link::{self, LinkError, LinkRequest};
use fieldprobe::units::Nanos;

/// `link::open(link)` with no axes, 1 ms cycle, 1 Mbit/s.
fn open(link: &str) -> Result<Box<dyn link::Link>, LinkError> {
    open_with_pcap(link, None)
}

/// [`open`], capturing the EtherCAT frames into `pcap`.
fn open_with_pcap(
    link: &str,
    pcap: Option<&std::path::Path>,
) -> Result<Box<dyn link::Link>, LinkError> {
    let drives: Vec<Arc<DriveDefinition>> = Vec::new();
    link::open(LinkRequest {
        link,
        drives: &drives,
        models: Vec::new(),
        node_ids: &[],
        cycle: Nanos::from_micros(1000),
        can_bitrate: 1_000_000,
        pcap,
        candump: None,
        #[cfg(feature = "ethercat")]
        terminals: Vec::new(),
    })
}

fn open_err(link: &str) -> String {
    open_err_with_pcap(link, None)
}

fn open_err_with_pcap(link: &str, pcap: Option<&std::path::Path>) -> String {
    match open_with_pcap(link, pcap) {
        Ok(_) => panic!("--link {link} opened"),
        Err(e) => e.to_string(),
    }
}

#[cfg(feature = "ethercat")]
#[test]
fn ethercat_iface_on_a_missing_interface_names_it() {
    let _one_module = crate::gate::enter(module_path!());
    let e = open_err("ethercat:fpno0");
    assert!(
        e.contains("ethercat:fpno0") && e.contains("no such network interface"),
        "{e}"
    );
    assert!(!e.contains("feature"), "{e}");
}

/// Inner-run marker of [`ethercat_iface_sends_frames_on_a_veth_pair`].
const INNER: &str = "FIELDPROBE_LINK_FEATURES_INNER";

#[cfg(feature = "ethercat")]
#[test]
fn ethercat_iface_sends_frames_on_a_veth_pair() {
    let _one_module = crate::gate::enter(module_path!());
    use std::process::Command;
    use std::time::{Duration, Instant};

    const NAME: &str = "ethercat_iface_sends_frames_on_a_veth_pair";
    if std::env::var_os(INNER).is_none() {
        // Outer half: re-run this test in a namespace with a veth pair, at most 60 s.
        let probe = Command::new("unshare")
            .args(["-rn", "sh", "-c", "ip link add v0 type veth peer name v1"])
            .output();
        match probe {
            Ok(o) if o.status.success() => {}
            Ok(o) => {
                eprintln!(
                    "SKIP {NAME}: `unshare -rn` + veth failed: {}",
                    String::from_utf8_lossy(&o.stderr).trim()
                );
                return;
            }
            Err(e) => {
                eprintln!("SKIP {NAME}: unshare: {e}");
                return;
            }
        }
        let exe = std::env::current_exe().expect("current_exe");
        let mut child = Command::new("timeout")
            .args(["60", "unshare", "-rn", "--"])
            .arg(&exe)
            .args([
                crate::common::full_test_name(NAME).as_str(),
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(INNER, "1")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("spawn the namespace run");
        let t0 = Instant::now();
        let out = loop {
            if child.try_wait().expect("wait").is_some() || t0.elapsed() > Duration::from_secs(90) {
                let _ = child.kill();
                break child.wait_with_output().expect("output");
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        let (so, se) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        eprintln!("--- {NAME} in the namespace:\n{so}\n{se}");
        assert!(out.status.success(), "namespace run failed:\n{so}\n{se}");
        assert!(so.contains("INNER OK"), "no INNER OK:\n{so}\n{se}");
        return;
    }
    // Inner half: in the namespace, as its root (CAP_NET_RAW).
    let sh = |c: &str| {
        let s = Command::new("sh").args(["-c", c]).status().expect("sh");
        assert!(s.success(), "{c}: {s}");
    };
    sh("ip link add v0 type veth peer name v1 && ip link set v0 up && ip link set v1 up");
    let mut peer = fieldprobe::bus::ethercat::raw::RawPort::open("v1").expect("raw socket on v1");
    let dir = tempfile::tempdir().unwrap();
    let pcap = dir.path().join("v0.pcap");
    let unix_ns = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64
    };
    let before = unix_ns();
    let e = open_err_with_pcap("ethercat:v0", Some(&pcap));
    let after = unix_ns();
    // Nobody answers: the master's start-up (ethercrab init_single_group) fails on the wire,
    // after the socket opened and its first frame was sent ten times (issue 26).
    assert!(e.contains("no EtherCAT device answered on v0"), "{e}");
    assert!(!e.contains("feature") && !e.contains("no such"), "{e}");
    let mut frames = 0;
    // `try_receive` gives `None` for a frame of another type too (the kernel's IPv6 neighbour
    // discovery on a new veth): read what came within a bounded time.
    let until = std::time::Instant::now() + std::time::Duration::from_secs(2);
    while std::time::Instant::now() < until && frames < 10 {
        let Some(f) = peer.try_receive() else {
            continue;
        };
        // EtherType 0x88A4, EtherCAT header type 1 (datagrams), ETG.1000.4 §5.2.
        assert_eq!(&f[12..14], &[0x88, 0xA4]);
        assert_eq!(f[15] >> 4, 1, "EtherCAT header {:02x}{:02x}", f[14], f[15]);
        frames += 1;
    }
    assert!(
        frames >= 10,
        "{frames} EtherCAT frames reached v1, not its ten tries ({e})"
    );
    // The `--pcap` capture of a real link is stamped with the wall clock (issue 18): the
    // first record of the classic pcap file (ns magic 0xa1b23c4d, little-endian; record
    // header ts_sec, ts_nsec after the 24-byte global header) lies within the open.
    let b = std::fs::read(&pcap).unwrap();
    assert!(b.len() > 40, "empty capture");
    let u32_at = |at: usize| u64::from(u32::from_le_bytes(b[at..at + 4].try_into().unwrap()));
    assert_eq!(u32_at(0), 0xa1b2_3c4d);
    let first = u32_at(24) * 1_000_000_000 + u32_at(28);
    assert!(
        (before..=after).contains(&first),
        "first frame at {first} ns, the open ran from {before} to {after} ns"
    );
    println!("{frames} EtherCAT frames from ethercat:v0 reached v1; open failed with: {e}");
    println!("INNER OK");
}

#[cfg(feature = "socketcan")]
#[test]
fn socketcan_on_a_missing_interface_names_it() {
    let _one_module = crate::gate::enter(module_path!());
    let e = open_err("socketcan:fpno0");
    // The SocketCAN open itself failed (this kernel may have no CAN at all).
    assert!(e.contains("SocketCAN interface `fpno0` unavailable"), "{e}");
    assert!(!e.contains("feature"), "{e}");
}

#[cfg(all(feature = "ethercat", not(feature = "sim")))]
#[test]
fn ethercat_emu_without_sim_names_the_feature() {
    let _one_module = crate::gate::enter(module_path!());
    let e = open_err("ethercat-emu");
    assert!(e.contains("ethercat-emu") && e.contains("`sim`"), "{e}");
}

#[cfg(all(feature = "canopen", not(feature = "sim")))]
#[test]
fn canopen_emu_without_sim_names_the_feature() {
    let _one_module = crate::gate::enter(module_path!());
    let e = open_err("canopen-emu");
    assert!(e.contains("canopen-emu") && e.contains("`sim`"), "{e}");
}
