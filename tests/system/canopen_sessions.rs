//! One `fieldprobe sim canopen` serves session after session, and junk on the bus ends no
//! session (issue 15): CAN over UDP multicast inside a private user + network namespace with
//! multicast routed to `lo` (`tests/common/netns.rs`); nothing reaches the host network.
//!
//! 1. [`runs_and_a_python_canopen_master_against_one_sim_canopen`]: against ONE `sim canopen`
//!    (nodes 1, 2, 3 = X, Y, Z, the probe surface at Z = 100 mm): `fieldprobe run` meas1 →
//!    exit 0 and the seed's values (seed 004 §5); python-canopen as a second master
//!    (`tests/python/canopen_between_runs.py`): SDO reads of every node (0x1000 = 0x00020192,
//!    CiA 402 device type: profile 402 = 0x192, type 0x02 servo drive; 0x1018:1 / :2 the
//!    emulator's vendor ID and product code, 0x1018:4 serial number = node id as the emulator
//!    documents), NMT start (heartbeat OPERATIONAL), then a segmented upload of 0x1008 started
//!    and abandoned on every node; then `run` again → exit 0, the same values (its NMT reset
//!    communication and first SDOs meet nodes another master left operational, mid-transfer).
//!    Measured: this passes also with the node's SDO server reset on reset communication
//!    removed (a new initiate restarts the server), so it guards the sequence, not that reset;
//!    the reset itself is `src/sim/canopen/tests.rs`.
//! 2. [`a_malformed_datagram_ends_no_session`]: one datagram of the single byte 0xC1 (never
//!    valid msgpack) sent to the group during `run --link canopen-udp` (1 s after the first
//!    SYNC), during `can scan` (when its first SDO request is on the bus) and during `can dump`
//!    (after its first line): the run still prints the seed's values with exit 0, scan finds
//!    the three nodes and dump lists frames, both exit 0; each process warns that it dropped
//!    the datagram (`FIELDPROBE_LOG=fieldprobe::bus::can=warn`: the bus counts and warns,
//!    `src/bus/can/udp.rs`). Measured: without that fix the three sessions still end well (the
//!    link's receive drops `CanError::Malformed` since the first CAN link), but no bus warning
//!    comes: the assertion on it is what fails.
//!
//! Bounds (documented, generous for a loaded machine): the runs use `cycle_time_us =`
//! [`CYCLE_US`] (40 ms: meas1's motion takes ~19 s whatever the cycle, so a longer cycle costs
//! no time) and `max_lost_cycles = 4`: the master rides through a hold-up of up to 4 missed
//! SYNC deadlines (160 ms), and the emulated drives' SYNC watch (5 periods = 200 ms) stops
//! them only beyond that (at 10 ms a loaded two-core machine held the processes up for 70 ms); what is checked here are sessions and junk, not timing
//! (`tests/system/canopen_udp_run.rs`). Every process is bounded (`run` [`RUN_TIMEOUT`], the python
//! peer, the namespace child), the emulator is killed at the end, the namespace vanishes with
//! its processes. The tests run one at a time. Only a machine without user namespaces,
//! `unshare` or `ip` SKIPs; a python-canopen venv that cannot be built fails.

use std::{
    io::Read,
    net::{Ipv4Addr, UdpSocket},
    process::{Command, Stdio},
    sync::Mutex,
    thread,
    time::{Duration, Instant},
};

use fieldprobe::bus::can::{CanBus, UdpConfig, UdpMulticastBus};
use serde_json::Value;

use crate::common::netns;
use netns::{manifest_path, run_bounded, wait_bounded, SEED004_MEAS1};

use crate::common::canopen_peers;
use canopen_peers::{lines_of, wait_line, Reaped};

/// One test at a time (each keeps a cycle on the wall clock).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

const OUTER_TIMEOUT: Duration = Duration::from_secs(400);
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
/// Cycle of the runs, µs (module documentation).
const CYCLE_US: u32 = 40_000;
/// Lifetime of the emulator process (killed earlier when the test is done).
const SIM_SECONDS: &str = "380";
/// The malformed datagram: 0xC1 is the one byte msgpack never uses.
const JUNK: [u8; 1] = [0xC1];
/// The warning of a bus that dropped a malformed datagram (`src/bus/can/udp.rs`).
const DROPPED: &str = "malformed datagram (1 bytes from";

/// `fieldprobe sim canopen` on `udp:GROUP:PORT`, nodes 1 … 3, probe surface at Z = 100 mm;
/// waits (at most 10 s) until it listens. Killed when dropped.
fn start_sim(group: Ipv4Addr, port: u16) -> Reaped {
    let mut sim = Reaped(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .args(["sim", "canopen", "--bus", &format!("udp:{group}:{port}")])
            .args(["--node", "1", "--node", "2", "--node", "3"])
            .args(["--probe-at", "3=100", "--seconds", SIM_SECONDS])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn fieldprobe sim canopen"),
    );
    let lines = lines_of(sim.0.stderr.take().expect("sim stderr"));
    let (ready, seen) = wait_line(&lines, "listening on", Duration::from_secs(10));
    assert!(ready, "sim canopen not listening within 10 s: {seen:?}");
    // Keep draining its stderr so it never blocks on a full pipe.
    thread::spawn(move || for _ in lines {});
    sim
}

/// `fieldprobe ARGS` in the crate directory, started (stdout, stderr piped), warnings of the
/// CAN bus on.
fn spawn(args: &[&str]) -> Reaped {
    Reaped(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .env("FIELDPROBE_LOG", "fieldprobe::bus::can=warn")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("spawn fieldprobe {args:?}: {e}")),
    )
}

/// The arguments of `fieldprobe run meas1.nc` on the bus.
fn run_args(link: &str) -> Vec<String> {
    [
        "run",
        "examples/nc/seed004/meas1.nc",
        "--link",
        link,
        "--set",
        &format!("cycle_time_us={CYCLE_US}"),
        "--set",
        "max_lost_cycles=4",
    ]
    .map(String::from)
    .to_vec()
}

/// Wait for `child` (at most `timeout`): exit code, stdout, stderr.
fn finish(
    child: &mut Reaped,
    out: thread::JoinHandle<String>,
    err: thread::JoinHandle<String>,
    timeout: Duration,
) -> (Option<i32>, String, String) {
    let status = wait_bounded(&mut child.0, timeout);
    (
        status.and_then(|s| s.code()),
        out.join().unwrap_or_default(),
        err.join().unwrap_or_default(),
    )
}

/// Stdout of a child as a string (thread), its stderr as lines (channel) and a copy of them.
fn read_to_string(mut r: impl Read + Send + 'static) -> thread::JoinHandle<String> {
    thread::spawn(move || {
        let mut s = String::new();
        let _ = r.read_to_string(&mut s);
        s
    })
}

fn check_meas1(what: &str, code: Option<i32>, out: &str, err: &str) {
    assert_eq!(code, Some(0), "{what}:\n{out}{err}");
    assert_eq!(out.lines().collect::<Vec<_>>(), SEED004_MEAS1, "{what}");
}

// ------------------------------------------------------------------------------------------

const SESSIONS_ENV: &str = "FIELDPROBE_CANOPEN_SESSIONS_INNER_PYTHON";
const SESSIONS: &str = "runs_and_a_python_canopen_master_against_one_sim_canopen";
const SESSIONS_BUS: (Ipv4Addr, u16) = (Ipv4Addr::new(239, 74, 175, 1), 43751);

#[test]
fn runs_and_a_python_canopen_master_against_one_sim_canopen() {
    let _one_module = crate::gate::enter(module_path!());
    if let Some(python) = netns::inner_python(SESSIONS_ENV) {
        sessions_inner(&python);
        return;
    }
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    netns::run_in_namespace(SESSIONS, SESSIONS_ENV, OUTER_TIMEOUT, true);
}

fn sessions_inner(python: &std::path::Path) {
    netns::netns_setup();
    let (group, port) = SESSIONS_BUS;
    let _sim = start_sim(group, port);
    let link = format!("canopen-udp:{group}:{port}");
    let run = |n: usize| {
        let t0 = Instant::now();
        let (status, out, err) = run_bounded(
            Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .stdin(Stdio::null())
                .args(run_args(&link)),
            RUN_TIMEOUT,
        );
        println!("run {n} ({:?}): {status:?}\n{out}{err}", t0.elapsed());
        check_meas1(
            &format!("run {n}"),
            status.and_then(|s| s.code()),
            &out,
            &err,
        );
    };
    run(1);

    let (status, out, err) = run_bounded(
        Command::new(python)
            .stdin(Stdio::null())
            .arg(manifest_path("tests/python/canopen_between_runs.py"))
            .args([group.to_string(), port.to_string()])
            .args(["1", "2", "3"]),
        canopen_peers::PEER_TIMEOUT,
    );
    println!("canopen_between_runs.py: {status:?}\n{out}{err}");
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix("CANOPEN_RESULT "))
        .unwrap_or_else(|| panic!("no CANOPEN_RESULT line ({status:?}): {err}"));
    let r: Value = serde_json::from_str(line).expect("CANOPEN_RESULT is JSON");
    assert_eq!(r["ok"], true, "python-canopen: {}", r["error"]);
    for id in 1..=3u32 {
        let n = &r["nodes"][id.to_string()];
        assert_eq!(n["0x1000"], 0x0002_0192, "node {id}: {n}");
        assert_eq!(
            n["0x1018:1"],
            fieldprobe::sim::canopen::VENDOR_ID,
            "node {id}: {n}"
        );
        assert_eq!(
            n["0x1018:2"],
            fieldprobe::sim::canopen::PRODUCT_CODE,
            "node {id}: {n}"
        );
        assert_eq!(n["0x1018:4"], id, "node {id}: {n}");
        assert_eq!(n["state_after_start"], "OPERATIONAL", "node {id}: {n}");
        // The first 7 bytes of the device name "fieldprobe CiA 402 node (…)".
        assert_eq!(
            n["abandoned_first_segment"],
            "fieldpr"
                .bytes()
                .map(|b| format!("{b:02x}"))
                .collect::<String>(),
            "node {id}: {n}"
        );
    }

    run(2);
    println!("INNER OK");
}

// ------------------------------------------------------------------------------------------

const JUNK_ENV: &str = "FIELDPROBE_CANOPEN_JUNK_INNER";
const JUNK_TEST: &str = "a_malformed_datagram_ends_no_session";
const JUNK_BUS: (Ipv4Addr, u16) = (Ipv4Addr::new(239, 74, 175, 2), 43752);

#[test]
fn a_malformed_datagram_ends_no_session() {
    let _one_module = crate::gate::enter(module_path!());
    if netns::inner_python(JUNK_ENV).is_some() {
        junk_inner();
        return;
    }
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    netns::run_in_namespace(JUNK_TEST, JUNK_ENV, OUTER_TIMEOUT, false);
}

/// Send [`JUNK`] once to the group.
fn send_junk(group: Ipv4Addr, port: u16) {
    let s = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0)).expect("bind junk sender");
    s.set_multicast_loop_v4(true).expect("IP_MULTICAST_LOOP");
    let n = s.send_to(&JUNK, (group, port)).expect("send junk");
    assert_eq!(n, 1);
}

/// Wait (at most `timeout`) until the observer hears a frame with identifier `id`.
fn heard(observer: &mut UdpMulticastBus, id: u32, timeout: Duration) -> bool {
    let end = Instant::now() + timeout;
    while Instant::now() < end {
        if let Ok(Some(f)) = observer.recv(Duration::from_millis(50)) {
            if f.id == id {
                return true;
            }
        }
    }
    false
}

fn junk_inner() {
    netns::netns_setup();
    let (group, port) = JUNK_BUS;
    let _sim = start_sim(group, port);
    let link = format!("canopen-udp:{group}:{port}");
    // An independent ear on the bus, to time the datagram into each session.
    let mut observer = UdpMulticastBus::open(UdpConfig::new(group, port)).expect("observer bus");

    // 1. During a run: 1 s after the first SYNC (0x080).
    let args = run_args(&link);
    let mut run = spawn(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let out = read_to_string(run.0.stdout.take().expect("stdout"));
    let err = read_to_string(run.0.stderr.take().expect("stderr"));
    assert!(
        heard(&mut observer, 0x080, Duration::from_secs(30)),
        "no SYNC within 30 s of the run's start"
    );
    thread::sleep(Duration::from_secs(1));
    send_junk(group, port);
    let (code, out, err) = finish(&mut run, out, err, RUN_TIMEOUT);
    println!("run with junk: {code:?}\n{out}{err}");
    check_meas1("run with a malformed datagram", code, &out, &err);
    assert!(
        err.contains(DROPPED),
        "run did not report the dropped datagram:\n{err}"
    );

    // 2. During `can scan`: when its first SDO request (to node 1, 0x601) is on the bus.
    let mut scan = spawn(&["can", "scan", "--link", &link]);
    let out = read_to_string(scan.0.stdout.take().expect("stdout"));
    let err = read_to_string(scan.0.stderr.take().expect("stderr"));
    assert!(
        heard(&mut observer, 0x601, Duration::from_secs(30)),
        "no SDO request of can scan within 30 s"
    );
    send_junk(group, port);
    let (code, out, err) = finish(&mut scan, out, err, Duration::from_secs(60));
    println!("can scan with junk: {code:?}\n{out}{err}");
    assert_eq!(code, Some(0), "can scan:\n{out}{err}");
    let found: Vec<&str> = out
        .lines()
        .skip(1)
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(found, ["1", "2", "3"], "can scan:\n{out}");
    assert!(
        err.contains(DROPPED),
        "can scan did not report the dropped datagram:\n{err}"
    );

    // 3. During `can dump`: after its first line (it is listening then).
    let mut dump = spawn(&["can", "dump", "--link", &link, "--seconds", "3"]);
    let lines = lines_of(dump.0.stdout.take().expect("stdout"));
    let err = read_to_string(dump.0.stderr.take().expect("stderr"));
    let (first, _) = wait_line(&lines, "", Duration::from_secs(30));
    assert!(first, "can dump printed nothing within 30 s");
    send_junk(group, port);
    let status = wait_bounded(&mut dump.0, Duration::from_secs(60));
    let err = err.join().unwrap_or_default();
    let rest: Vec<String> = lines.iter().collect();
    println!(
        "can dump with junk: {status:?}, {} more lines\n{err}",
        rest.len()
    );
    assert_eq!(status.and_then(|s| s.code()), Some(0), "can dump:\n{err}");
    assert!(
        rest.iter()
            .any(|l| l.contains(" 701#") || l.contains(" 703#")),
        "can dump heard no heartbeat after the datagram: {rest:?}"
    );
    assert!(
        err.contains(DROPPED),
        "can dump did not report the dropped datagram:\n{err}"
    );
    println!("INNER OK");
}
