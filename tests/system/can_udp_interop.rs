//! `UdpMulticastBus` against python-can 4.6.1's `udp_multicast` interface (an independent
//! implementation of the wire format; notes `canopen.md` §3), both directions, plus the socket
//! options (own echoes dropped, no leaks between groups sharing a port).
//!
//! Isolation: each test re-executes its own binary inside a fresh unprivileged user + network
//! namespace (`unshare -rn`) with `lo` up, multicast on and 224.0.0.0/4 routed to `lo`, so
//! all multicast stays in that namespace (notes §3.2). Only a machine without `unshare`, user
//! namespaces or `ip` SKIPs (prints `SKIP`). The venv (`scripts/python-can-venv.sh`, pinned
//! python-can / msgpack / canopen) is built before entering the namespace; PyPI unreachable is a
//! failure, not a skip. Each test uses its own group and port. Every wait is bounded.

use std::{
    io::{BufRead, BufReader, Read},
    net::Ipv4Addr,
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::mpsc,
    thread,
    time::{Duration, Instant},
};

use fieldprobe::bus::can::{CanBus, CanFrame, UdpConfig, UdpMulticastBus};

use crate::common::netns;
use netns::{manifest_path, netns_setup, wait_bounded};

/// Set in the re-executed test process (inside the namespace); value = venv python.
const INNER_ENV: &str = "FIELDPROBE_CAN_UDP_INNER";
const OUTER_TIMEOUT: Duration = Duration::from_secs(90);
const PEER_TIMEOUT: Duration = Duration::from_secs(20);

/// Outer half: see [`netns::run_in_namespace`].
fn run_in_namespace(test_name: &str, needs_python: bool) {
    netns::run_in_namespace(test_name, INNER_ENV, OUTER_TIMEOUT, needs_python);
}

fn inner_python() -> Option<PathBuf> {
    netns::inner_python(INNER_ENV)
}

/// One test frame, written as python-can fields (the table is the expectation for both sides).
#[derive(Debug, Clone, Copy)]
struct Row {
    id: u32,
    ext: bool,
    rtr: bool,
    err: bool,
    len: u8,
    data: &'static [u8],
}

const fn row(id: u32, ext: bool, data: &'static [u8]) -> Row {
    Row {
        id,
        ext,
        rtr: false,
        err: false,
        len: data.len() as u8,
        data,
    }
}

const ROWS: [Row; 20] = [
    row(0x601, false, &[0x40, 0x41, 0x10, 0, 0, 0, 0, 0]), // SDO upload 0x1041
    row(0x000, false, &[0x01, 0x05]),                      // NMT start node 5
    row(0x080, false, &[]),                                // SYNC
    row(0x1ABC_DE01, true, &[1, 2, 3]),
    row(0x0000_0005, true, &[]), // extended with a small id
    row(0x1FFF_FFFF, true, &[0xFF; 8]),
    row(0x7FF, false, &[0xFF]),
    Row {
        id: 0x705,
        ext: false,
        rtr: true,
        err: false,
        len: 1,
        data: &[],
    },
    Row {
        id: 0x0012_3456,
        ext: true,
        rtr: true,
        err: false,
        len: 8,
        data: &[],
    },
    Row {
        id: 0x40, // CAN_ERR_BUSOFF
        ext: false,
        rtr: false,
        err: true,
        len: 8,
        data: &[0; 8],
    },
    row(0x181, false, &[]),
    row(0x182, false, &[0x11]),
    row(0x183, false, &[0x11, 0x22]),
    row(0x184, false, &[0x11, 0x22, 0x33]),
    row(0x185, false, &[0x11, 0x22, 0x33, 0x44]),
    row(0x186, false, &[0x11, 0x22, 0x33, 0x44, 0x55]),
    row(0x187, false, &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66]),
    row(0x188, false, &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77]),
    row(
        0x189,
        false,
        &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88],
    ),
    row(0x18A, false, &[0x80, 0x7F, 0, 0xFF, 0x01, 0xFE, 0x55, 0xAA]),
];

fn to_frame(r: &Row) -> CanFrame {
    let mut data = [0u8; 8];
    data[..r.data.len()].copy_from_slice(r.data);
    CanFrame {
        id: r.id,
        extended: r.ext,
        rtr: r.rtr,
        error: r.err,
        len: r.len,
        data,
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn rows_json() -> String {
    let v: Vec<serde_json::Value> = ROWS
        .iter()
        .map(|r| {
            serde_json::json!({
                "id": r.id, "ext": r.ext, "rtr": r.rtr, "err": r.err,
                "len": r.len, "data": hex(r.data),
            })
        })
        .collect();
    serde_json::Value::Array(v).to_string()
}

/// Kills the peer when dropped (also on panic).
struct Peer(Child);

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn peer(python: &Path, args: &[String]) -> Peer {
    Peer(
        Command::new(python)
            .arg(manifest_path("tests/python/can_peer.py"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn python peer"),
    )
}

/// Forward the peer's stdout lines to a channel; stderr is collected.
fn peer_lines(p: &mut Peer) -> (mpsc::Receiver<String>, thread::JoinHandle<String>) {
    let out = p.0.stdout.take().expect("stdout");
    let mut err = p.0.stderr.take().expect("stderr");
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    let e = thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    (rx, e)
}

const PY_TO_RUST: &str = "python_can_sends_rust_receives";
const RUST_TO_PY: &str = "rust_sends_python_can_receives";
const SOCKETS: &str = "udp_bus_drops_own_echoes_and_other_groups";

#[test]
fn python_can_sends_rust_receives() {
    let _one_module = crate::gate::enter(module_path!());
    let Some(python) = inner_python() else {
        return run_in_namespace(PY_TO_RUST, true);
    };
    netns_setup();
    let cfg = UdpConfig::new(Ipv4Addr::new(239, 74, 170, 1), 43201);
    let mut bus = UdpMulticastBus::open(cfg).expect("open bus");
    let t0 = Instant::now();
    let mut p = peer(
        &python,
        &[
            "send".into(),
            cfg.group.to_string(),
            cfg.port.to_string(),
            rows_json(),
        ],
    );
    let (lines, err) = peer_lines(&mut p);
    let expected: Vec<CanFrame> = ROWS.iter().map(to_frame).collect();
    let mut got = Vec::new();
    let deadline = Instant::now() + PEER_TIMEOUT;
    while got.len() < expected.len() && Instant::now() < deadline {
        if let Some(f) = bus.recv(Duration::from_millis(200)).expect("recv") {
            got.push(f);
        }
    }
    // Nothing more than what was sent.
    if let Some(extra) = bus.recv(Duration::from_millis(300)).expect("recv") {
        got.push(extra);
    }
    let status = wait_bounded(&mut p.0, PEER_TIMEOUT);
    let out: Vec<String> = lines.try_iter().collect();
    let err = err.join().unwrap_or_default();
    println!("python sender: {out:?} {err}");
    assert!(
        status.is_some_and(|s| s.success()),
        "python sender: {status:?}\n{err}"
    );
    assert!(out.contains(&format!("SENT {}", ROWS.len())), "{out:?}");
    assert_eq!(got, expected);
    println!(
        "received {} frames from python-can in {:?}",
        got.len(),
        t0.elapsed()
    );
    println!("INNER OK");
}

#[test]
fn rust_sends_python_can_receives() {
    let _one_module = crate::gate::enter(module_path!());
    let Some(python) = inner_python() else {
        return run_in_namespace(RUST_TO_PY, true);
    };
    netns_setup();
    let cfg = UdpConfig::new(Ipv4Addr::new(239, 74, 170, 2), 43202);
    let mut bus = UdpMulticastBus::open(cfg).expect("open bus");
    let t0 = Instant::now();
    let mut p = peer(
        &python,
        &[
            "recv".into(),
            cfg.group.to_string(),
            cfg.port.to_string(),
            ROWS.len().to_string(),
            "15".into(),
        ],
    );
    let (lines, err) = peer_lines(&mut p);
    let ready_deadline = Instant::now() + PEER_TIMEOUT;
    loop {
        let left = ready_deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(l) if l == "READY" => break,
            Ok(l) => println!("python: {l}"),
            Err(_) => panic!(
                "python receiver not ready within {PEER_TIMEOUT:?}: {}",
                err.join().unwrap_or_default()
            ),
        }
    }
    for r in &ROWS {
        bus.send(&to_frame(r)).expect("send");
        thread::sleep(Duration::from_millis(2));
    }
    let mut msgs = Vec::new();
    let deadline = Instant::now() + PEER_TIMEOUT;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(l) if l.starts_with("DONE") => {
                msgs.push(l);
                break;
            }
            Ok(l) => msgs.push(l),
            Err(_) => break,
        }
    }
    let status = wait_bounded(&mut p.0, PEER_TIMEOUT);
    let err = err.join().unwrap_or_default();
    assert!(
        status.is_some_and(|s| s.success()),
        "python receiver: {status:?}\n{err}"
    );
    assert_eq!(
        msgs.last().map(String::as_str),
        Some(&*format!("DONE {}", ROWS.len())),
        "{msgs:?}\n{err}"
    );
    let got: Vec<serde_json::Value> = msgs[..msgs.len() - 1]
        .iter()
        .map(|l| serde_json::from_str(l).expect("python JSON line"))
        .collect();
    assert_eq!(got.len(), ROWS.len());
    for (m, r) in got.iter().zip(&ROWS) {
        let want = serde_json::json!({
            "arbitration_id": r.id,
            "is_extended_id": r.ext,
            "is_remote_frame": r.rtr,
            "is_error_frame": r.err,
            "is_fd": false,
            "dlc": r.len,
            "data": hex(r.data),
        });
        assert_eq!(m, &want, "row {r:?}");
    }
    println!(
        "python-can received {} frames in {:?}",
        got.len(),
        t0.elapsed()
    );
    println!("INNER OK");
}

#[test]
fn udp_bus_drops_own_echoes_and_other_groups() {
    let _one_module = crate::gate::enter(module_path!());
    if inner_python().is_none() {
        return run_in_namespace(SOCKETS, false);
    }
    netns_setup();
    let g1 = Ipv4Addr::new(239, 74, 170, 3);
    let g2 = Ipv4Addr::new(239, 74, 170, 4);
    let port = 43203;
    let mut a = UdpMulticastBus::open(UdpConfig::new(g1, port)).expect("a");
    let mut b = UdpMulticastBus::open(UdpConfig::new(g1, port)).expect("b");
    let mut other_group = UdpMulticastBus::open(UdpConfig::new(g2, port)).expect("c");
    let mut other_port = UdpMulticastBus::open(UdpConfig::new(g1, port + 1)).expect("d");
    let f1 = to_frame(&ROWS[0]);
    let f2 = to_frame(&ROWS[3]);
    a.send(&f1).unwrap();
    a.send(&f2).unwrap();
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(5);
    while got.len() < 2 && Instant::now() < deadline {
        if let Some(f) = b.recv(Duration::from_millis(200)).unwrap() {
            got.push(f);
        }
    }
    assert_eq!(got, vec![f1, f2]);
    assert_eq!(
        a.recv(Duration::from_millis(300)).unwrap(),
        None,
        "own frames"
    );
    assert_eq!(a.own_echoes_dropped(), 2);
    assert_eq!(other_group.recv(Duration::from_millis(300)).unwrap(), None);
    assert_eq!(other_port.recv(Duration::ZERO).unwrap(), None);
    // b answers; a hears it.
    b.send(&f2).unwrap();
    assert_eq!(a.recv(Duration::from_secs(5)).unwrap(), Some(f2));
    // Zero-timeout polling drains without blocking.
    b.send(&f1).unwrap();
    thread::sleep(Duration::from_millis(100));
    assert_eq!(a.recv(Duration::ZERO).unwrap(), Some(f1));
    assert_eq!(a.recv(Duration::ZERO).unwrap(), None);
    println!("INNER OK");
}
