//! The two CANopen interop cases with python-canopen 2.4.1 as the independent peer (notes
//! `canopen.md` §3, §4), on any bus python-can and fieldprobe both reach: CAN over UDP
//! multicast (`tests/system/canopen_interop.rs`, in a private network namespace) or SocketCAN
//! (`tests/system/socketcan.rs`, on vcan0 of the host or of the Linux guest).
//!
//! (a) [`python_master_drives_sim`]: python-canopen as master (`tests/python/canopen_master.py`)
//!     against `fieldprobe sim canopen`: boot-up, SDO expedited / segmented / block, abort, PDO
//!     remap, NMT start, BaseNode402 to OPERATION ENABLED, touch probe armed in an RPDO and
//!     latched while the target position ramps across a probe surface in lockstep with SYNC;
//! (b) [`rust_master_against_local_node`]: our master (library API: a [`CanBus`] + `SdoClient`
//!     + `nmt`) against a python-canopen `LocalNode` built from `python-canopen-e35.eds`
//!     (`tests/python/canopen_local_node.py`);
//! (c) [`python_sdo_drives_eds_node`]: python-canopen as master
//!     (`tests/python/canopen_sdo_drive.py`, object dictionary from the Technosoft EDS) against
//!     `fieldprobe sim canopen --eds` of the same file: 0x6041 and the EDS's PDO defaults read
//!     before any SYNC, controlword 6 / 7 / 0xF by SDO to OPERATION ENABLED, the event-driven
//!     TPDO1 after NMT start; no SYNC at all.
//!
//! Every wait is bounded. Expected values come from the test data files, read here with a
//! minimal INI / TOML lookup (not with the crate's parsers).

#![allow(dead_code)] // each test crate uses its own subset

use std::{
    io::{BufRead, BufReader, Read},
    net::Ipv4Addr,
    path::Path,
    process::{Child, Command, Stdio},
    sync::mpsc,
    thread,
    time::{Duration, Instant},
};

use fieldprobe::bus::can::{CanBus, CanFrame, SocketCanBus, UdpConfig, UdpMulticastBus};
use fieldprobe::bus::canopen::nmt::{self, NmtCommand, NmtState};
use fieldprobe::bus::canopen::sdo::{SdoClient, SdoError, TransferMode};
use fieldprobe::units::Nanos;

use super::netns::{manifest_path, run_bounded};

/// Bound of one python peer.
pub const PEER_TIMEOUT: Duration = Duration::from_secs(120);

/// The bus both sides use.
#[derive(Debug, Clone, Copy)]
pub enum PeerBus {
    /// python-can `udp_multicast` / fieldprobe `udp:GROUP:PORT`.
    Udp(Ipv4Addr, u16),
    /// A SocketCAN interface (python-can `socketcan`, fieldprobe `socketcan:IF`).
    SocketCan(&'static str),
}

impl PeerBus {
    /// `--bus` of `fieldprobe sim canopen`.
    pub fn sim_arg(&self) -> String {
        match self {
            PeerBus::Udp(g, p) => format!("udp:{g}:{p}"),
            PeerBus::SocketCan(i) => format!("socketcan:{i}"),
        }
    }

    /// The two leading arguments of the python scripts: `GROUP PORT` or `socketcan:IF 0`.
    pub fn python_args(&self) -> [String; 2] {
        match self {
            PeerBus::Udp(g, p) => [g.to_string(), p.to_string()],
            PeerBus::SocketCan(i) => [format!("socketcan:{i}"), "0".into()],
        }
    }

    /// `--interface … --channel … [--port …]` of the python scripts that take options.
    pub fn python_options(&self) -> Vec<String> {
        match self {
            PeerBus::Udp(g, p) => ["--interface", "udp_multicast", "--channel"]
                .into_iter()
                .map(String::from)
                .chain([g.to_string(), "--port".into(), p.to_string()])
                .collect(),
            PeerBus::SocketCan(i) => vec![
                "--interface".into(),
                "socketcan".into(),
                "--channel".into(),
                i.to_string(),
            ],
        }
    }

    /// Our end of the bus.
    pub fn open(&self) -> Box<dyn CanBus> {
        match *self {
            PeerBus::Udp(g, p) => {
                Box::new(UdpMulticastBus::open(UdpConfig::new(g, p)).expect("open udp bus"))
            }
            PeerBus::SocketCan(i) => Box::new(SocketCanBus::open(i).expect("open SocketCAN bus")),
        }
    }
}

/// Factor on the time windows that judge a peer's timing: 1 on a host, 4 inside the Linux
/// guest of `scripts/can-guest.sh` (software-emulated CPU, ~10–30× slower).
pub fn slack() -> u32 {
    if std::env::var_os("FIELDPROBE_IN_GUEST").is_some() {
        4
    } else {
        1
    }
}

/// Kills the child when dropped (also on panic).
pub struct Reaped(pub Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Lines of a child's stream, forwarded to a channel.
pub fn lines_of(r: impl Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        for l in BufReader::new(r).lines().map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    rx
}

/// Wait for a line containing `what`; the lines seen are returned either way.
pub fn wait_line(
    rx: &mpsc::Receiver<String>,
    what: &str,
    timeout: Duration,
) -> (bool, Vec<String>) {
    let deadline = Instant::now() + timeout;
    let mut seen = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(l) => {
                let hit = l.contains(what);
                seen.push(l);
                if hit {
                    return (true, seen);
                }
            }
            Err(_) => return (false, seen),
        }
    }
}

// ------------------------------------------------------------------------------------------
// Minimal readers of the test data (independent of the crate's EDS and drive parsers)

/// `key` of INI `[section]` (case-insensitive names), as written.
pub fn ini_value(text: &str, section: &str, key: &str) -> Option<String> {
    let mut inside = false;
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            inside = line
                .trim_matches(|c| c == '[' || c == ']')
                .eq_ignore_ascii_case(section);
        } else if inside {
            if let Some((k, v)) = line.split_once('=') {
                if k.trim().eq_ignore_ascii_case(key) {
                    return Some(v.trim().to_string());
                }
            }
        }
    }
    None
}

/// An unsigned integer literal as written in an EDS (`0x…` or decimal).
pub fn eds_uint(s: &str) -> u64 {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).expect("hex literal"),
        None => s.parse().expect("decimal literal"),
    }
}

/// `key = number` of the `[scaling]` table of a drive file.
pub fn drive_scaling(key: &str) -> f64 {
    let text = std::fs::read_to_string(manifest_path("drives/cia402-generic.toml")).unwrap();
    let v = ini_value(&text, "scaling", key).unwrap_or_else(|| panic!("[scaling] {key}"));
    v.split('#').next().unwrap().trim().parse().expect("number")
}

/// The one JSON line a python master prints last, after checking it exited 0 and said `ok`.
#[track_caller]
fn peer_report(
    status: Option<std::process::ExitStatus>,
    out: &str,
    err: &str,
) -> serde_json::Value {
    assert!(
        status.is_some_and(|s| s.success()),
        "python master: {status:?}\n{err}"
    );
    let line = out
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .expect("JSON line");
    let r: serde_json::Value = serde_json::from_str(line).expect("JSON");
    assert_eq!(r["ok"], true, "{}", r["traceback"].as_str().unwrap_or(""));
    r
}

// ------------------------------------------------------------------------------------------
// (a) python-canopen master against `fieldprobe sim canopen`

/// Probe surface of test (a), mm.
pub const SURFACE_MM: f64 = 2.5;

/// Case (a) on `bus`; `python` is the venv's interpreter.
pub fn python_master_drives_sim(python: &Path, bus: PeerBus) {
    let t0 = Instant::now();
    let mut sim = Reaped(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .args(["sim", "canopen", "--bus"])
            .arg(bus.sim_arg())
            .args(["--node", "5", "--probe-at"])
            .arg(format!("5={SURFACE_MM}"))
            .args(["--seconds", "90"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn fieldprobe sim canopen"),
    );
    let sim_err = lines_of(sim.0.stderr.take().expect("stderr"));
    let (ready, seen) = wait_line(&sim_err, "listening", Duration::from_secs(10) * slack());
    assert!(ready, "sim canopen not listening: {seen:?}");

    // Surface in increments, from the drive file's scaling (10000 inc/mm, offset 0).
    let ipu = drive_scaling("increments_per_unit");
    let offset = drive_scaling("offset");
    let surface = ((SURFACE_MM - offset) * ipu).round() as i64;
    assert_eq!(surface, 25_000);
    let ramp_end = surface + 30_000; // 3 mm beyond the surface

    let (status, out, err) = run_bounded(
        Command::new(python)
            .arg(manifest_path("tests/python/canopen_master.py"))
            .args(bus.python_args())
            .args(["5", &ramp_end.to_string()]),
        PEER_TIMEOUT,
    );
    let elapsed = t0.elapsed();
    drop(sim);
    let sim_log: Vec<String> = sim_err.try_iter().collect();
    println!("python master ({elapsed:?}):\n{out}\n{err}\nsim: {sim_log:?}");
    let r = peer_report(status, &out, &err);

    // NMT: boot-up `705 [1] 00` after the reset, then heartbeats 0x7F (PRE-OP), 0x05 (OP).
    assert_eq!(r["bootup"], true);
    assert_eq!(r["heartbeat_preop"], 0x7F);
    assert_eq!(r["heartbeat_op"], 0x05);
    // SDO. 0x1000: CiA 402 device profile 0x0192, additional info 0x0002 (servo drive).
    assert_eq!(r["device_type"], 0x0002_0192);
    let name = r["device_name"].as_str().unwrap();
    assert!(name.contains("cia402-generic") && name.len() > 4, "{name}");
    assert_eq!(r["readback_6066"], 25);
    assert_eq!(r["readback_6065"], 123_456);
    let notice = fieldprobe::sim::esc::coe::EMULATOR_NOTICE;
    let hex: String = notice.bytes().map(|b| format!("{b:02x}")).collect();
    assert_eq!(r["block_len"], notice.len());
    assert_eq!(r["block_hex"], hex.as_str());
    assert_eq!(r["block_equals_segmented"], true);
    assert_eq!(r["abort_missing"], 0x0602_0000);
    // PDO remap read back: CiA 301 mapping entries index << 16 | sub << 8 | bits.
    let m = &r["map_readback"];
    assert_eq!(m["1600"], serde_json::json!([2, 0x6040_0010, 0x607A_0020]));
    assert_eq!(m["1601"], serde_json::json!([2, 0x60B8_0010, 0x6060_0008]));
    assert_eq!(m["1a00"], serde_json::json!([2, 0x6041_0010, 0x6064_0020]));
    assert_eq!(m["1a01"], serde_json::json!([2, 0x60B9_0010, 0x60BA_0020]));
    assert_ne!(
        m["1402_cob"].as_u64().unwrap() & 0x8000_0000,
        0,
        "RPDO3 disabled"
    );
    assert_ne!(
        m["1802_cob"].as_u64().unwrap() & 0x8000_0000,
        0,
        "TPDO3 disabled"
    );
    // CiA 402 and the touch probe.
    assert_eq!(r["state"], "OPERATION ENABLED");
    assert_eq!(
        r["tp_status_armed"].as_u64().unwrap() & 0x0001,
        1,
        "TP1 enabled"
    );
    assert_eq!(r["ramp_timeouts"], 0);
    assert!(r["latched_at_sync"].as_u64().is_some(), "no latch");
    assert!(
        r["position_last"].as_i64().unwrap() > surface,
        "moved past the surface"
    );
    for (status, latch) in [
        ("tp_status_tpdo", "tp_latch_tpdo"),
        ("tp_status_sdo", "tp_latch_sdo"),
    ] {
        assert_ne!(
            r[status].as_u64().unwrap() & 0x0002,
            0,
            "{status}: TP1 positive value stored"
        );
        let l = r[latch].as_i64().unwrap();
        assert!((l - surface).abs() <= 1, "{latch} = {l}, surface {surface}");
    }
    // CiA 301 error objects and EMCY (issue 26). Before the fault: no error, empty history.
    assert_eq!(r["err_1001_before"], 0);
    assert_eq!(r["err_1003_0_before"], 0);
    // A following error (CiA 402 EMCY 0x8611): FAULT, python-canopen's EMCY consumer has it
    // active; error register = generic (bit 0) + device profile (bit 5) = 0x21 (CiA 301
    // §7.5.2.2); 0x1003 holds one entry, the code in its low 16 bits.
    assert_eq!(r["faulted"], true, "the runaway target faulted the drive");
    let codes = |k: &str| -> Vec<u64> {
        r[k].as_array()
            .unwrap_or_else(|| panic!("{k}: {}", r[k]))
            .iter()
            .map(|c| c.as_u64().unwrap())
            .collect()
    };
    assert!(
        codes("emcy_log_in_fault").contains(&0x8611),
        "{}",
        r["emcy_log_in_fault"]
    );
    assert_eq!(codes("emcy_active_in_fault"), vec![0x8611]);
    assert_eq!(r["err_1001_in_fault"], 0x21);
    assert_eq!(r["err_1003_0_in_fault"], 1);
    assert_eq!(r["err_1003_1_in_fault"], 0x8611);
    // EMCY frames on the wire: `11 86 21 00 00 00 00 00` (0x8611, register 0x21, 5 zero
    // manufacturer bytes), and after the fault reset exactly one `00 00 00 00 00 00 00 00`
    // (error reset, register 0x00).
    let frames: Vec<&str> = r["emcy_frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(frames.contains(&"1186210000000000"), "{frames:?}");
    assert_eq!(
        r["emcy_frames_after_reset"],
        serde_json::json!(["0000000000000000"])
    );
    // After the reset: SWITCH ON DISABLED, nothing active for python-canopen, register 0, the
    // history keeps the fault until 0 is written to 0x1003:00; any other value is refused
    // (0x06090030), and an empty field has no sub-index 1 entry (0x08000024, no data).
    assert_eq!(r["statusword_after_reset"].as_u64().unwrap() & 0x4F, 0x40);
    assert_eq!(codes("emcy_active_after_reset"), Vec::<u64>::new());
    assert_eq!(r["err_1001_after_reset"], 0);
    assert_eq!(r["err_1003_0_after_reset"], 1);
    assert_eq!(r["err_1003_1_after_reset"], 0x8611);
    assert_eq!(r["err_1003_write_1"], 0x0609_0030);
    assert_eq!(r["err_1003_0_cleared"], 0);
    assert_eq!(r["err_1003_1_cleared"], 0x0800_0024);
    println!("python-canopen master against sim canopen: {elapsed:?}");
}

// ------------------------------------------------------------------------------------------
// (b) our master against a python-canopen LocalNode

/// Node id of the LocalNode (the EDS has no `[DeviceComissioning]`).
pub const LOCAL_ID: u8 = 0x20;

/// Our master: the bus, one SDO client, the clock, and every frame seen from the node.
pub struct Master {
    bus: Box<dyn CanBus>,
    sdo: SdoClient,
    t0: Instant,
    heard: Vec<CanFrame>,
}

impl Master {
    fn now(&self) -> Nanos {
        Nanos(self.t0.elapsed().as_nanos() as u64)
    }

    /// Run one SDO transfer to completion (the client's own timeouts bound it).
    fn transfer(&mut self, first: Vec<CanFrame>) -> Result<Vec<u8>, SdoError> {
        for f in &first {
            self.bus.send(f).expect("send");
        }
        let hard_stop = Instant::now() + Duration::from_secs(10) * slack();
        while self.sdo.busy() {
            assert!(Instant::now() < hard_stop, "SDO transfer did not end");
            let got = self.bus.recv(Duration::from_millis(5)).expect("recv");
            let now = self.now();
            let mut replies = Vec::new();
            if let Some(f) = got {
                self.heard.push(f);
                replies.extend(self.sdo.handle(&f, now));
            }
            replies.extend(self.sdo.poll(now));
            for r in &replies {
                self.bus.send(r).expect("send");
            }
        }
        self.sdo.take_result().expect("result")
    }

    fn upload(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoError> {
        let now = self.now();
        let f = self.sdo.upload(index, sub, now);
        self.transfer(f)
    }

    fn download(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        mode: TransferMode,
    ) -> Result<(), SdoError> {
        self.sdo.set_mode(mode);
        let now = self.now();
        let f = self.sdo.download(index, sub, data, now);
        let r = self.transfer(f).map(|_| ());
        self.sdo.set_mode(TransferMode::Auto);
        r
    }
}

/// Case (b) on `bus`; `eds_path` is `python-canopen-e35.eds` from the test data.
pub fn rust_master_against_local_node(python: &Path, eds_path: &Path, bus: PeerBus) {
    let eds = std::fs::read_to_string(eds_path).expect("read e35.eds");
    let can = bus.open();
    let t0 = Instant::now();
    let mut node = Reaped(
        Command::new(python)
            .arg(manifest_path("tests/python/canopen_local_node.py"))
            .args(bus.python_args())
            .arg(LOCAL_ID.to_string())
            .arg(eds_path)
            .arg((20 * slack()).to_string())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn LocalNode"),
    );
    let node_out = lines_of(node.0.stdout.take().expect("stdout"));
    let node_err = lines_of(node.0.stderr.take().expect("stderr"));
    // Python with canopen imports and parses the EDS first: seconds on a host, tens of seconds
    // in the emulated guest on a loaded machine.
    let (ready, seen) = wait_line(&node_out, "READY", Duration::from_secs(20) * slack());
    assert!(
        ready,
        "LocalNode not ready: {seen:?} {:?}",
        node_err.try_iter().collect::<Vec<_>>()
    );
    let mut m = Master {
        bus: can,
        sdo: SdoClient::new(LOCAL_ID),
        t0,
        heard: Vec::new(),
    };

    // Expected values: the EDS defaults, read with the minimal INI lookup above.
    let want_1000 = eds_uint(&ini_value(&eds, "1000", "DefaultValue").unwrap()) as u32;
    let want_vendor = eds_uint(&ini_value(&eds, "1018sub1", "DefaultValue").unwrap()) as u32;
    let want_1008 = ini_value(&eds, "1008", "DefaultValue").unwrap();
    let want_1009 = ini_value(&eds, "1009", "DefaultValue").unwrap();
    assert!(want_1009.len() > 4, "0x1009 must need a segmented upload");

    // Expedited uploads.
    assert_eq!(m.upload(0x1000, 0).unwrap(), want_1000.to_le_bytes());
    assert_eq!(m.upload(0x1018, 1).unwrap(), want_vendor.to_le_bytes());
    assert_eq!(m.upload(0x1008, 0).unwrap(), want_1008.as_bytes());
    // Segmented upload of a string longer than 4 bytes.
    assert_eq!(m.upload(0x1009, 0).unwrap(), want_1009.as_bytes());
    // Segmented download to the scratch string the peer adds, then read back.
    let text = b"written by fieldprobe's SDO client in 7-byte segments";
    m.download(0x2FF0, 0, text, TransferMode::Segmented)
        .unwrap();
    assert_eq!(m.upload(0x2FF0, 0).unwrap(), text);
    // Abort for a missing object.
    match m.upload(0x5FFF, 0) {
        Err(SdoError::Abort {
            index, sub, code, ..
        }) => {
            assert_eq!((index, sub, code), (0x5FFF, 0, 0x0602_0000))
        }
        other => panic!("expected abort 0x06020000, got {other:?}"),
    }

    // Heartbeat: the EDS has 0x1017 = 0, so configure 100 ms first, then NMT start.
    assert_eq!(
        eds_uint(&ini_value(&eds, "1017", "DefaultValue").unwrap()),
        0
    );
    m.download(0x1017, 0, &100u16.to_le_bytes(), TransferMode::Expedited)
        .unwrap();
    m.bus
        .send(&NmtCommand::Start.frame(LOCAL_ID))
        .expect("send NMT start");
    let t_start = Instant::now();
    let deadline = t_start + Duration::from_secs(5) * slack();
    let mut states = Vec::new();
    while Instant::now() < deadline {
        if let Some(f) = m.bus.recv(Duration::from_millis(50)).expect("recv") {
            // 0x720 [1] state
            if let Some((LOCAL_ID, s)) = nmt::parse_heartbeat(&f) {
                states.push(s);
                if s == NmtState::Operational {
                    break;
                }
            }
        }
    }
    assert_eq!(
        states.last(),
        Some(&NmtState::Operational),
        "heartbeats seen: {states:?}"
    );
    // The heartbeat period is the 100 ms written: two more within 0.35 s.
    let mut more = 0;
    let t_hb = Instant::now();
    while more < 2 && t_hb.elapsed() < Duration::from_millis(350) * slack() {
        if let Some(f) = m.bus.recv(Duration::from_millis(20)).expect("recv") {
            more +=
                usize::from(nmt::parse_heartbeat(&f) == Some((LOCAL_ID, NmtState::Operational)));
        }
    }
    assert_eq!(more, 2, "heartbeat period");
    println!(
        "our master against python-canopen LocalNode: {:?} (heartbeat states {states:?})",
        t0.elapsed()
    );
    drop(node);
}

// ------------------------------------------------------------------------------------------
// (c) python-canopen drives an EDS node by SDO alone (`tests/python/canopen_sdo_drive.py`)

/// Case (c) on `bus`; `eds_path` is `technosoft-ipos-cia402.eds` from the test data.
pub fn python_sdo_drives_eds_node(python: &Path, eds_path: &Path, bus: PeerBus) {
    let mut sim = Reaped(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .args(["sim", "canopen", "--bus"])
            .arg(bus.sim_arg())
            .args(["--node", "5", "--eds"])
            .arg(eds_path)
            .args(["--seconds", "60"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn fieldprobe sim canopen"),
    );
    let sim_err = lines_of(sim.0.stderr.take().expect("stderr"));
    let (ready, seen) = wait_line(&sim_err, "listening", Duration::from_secs(10) * slack());
    assert!(ready, "sim canopen not listening: {seen:?}");

    let (status, out, err) = run_bounded(
        Command::new(python)
            .arg(manifest_path("tests/python/canopen_sdo_drive.py"))
            .args(bus.python_options())
            .args(["--node", "5", "--eds"])
            .arg(eds_path),
        PEER_TIMEOUT,
    );
    drop(sim);
    let sim_log: Vec<String> = sim_err.try_iter().collect();
    println!("python master:\n{out}\n{err}\nsim: {sim_log:?}");
    let r = peer_report(status, &out, &err);

    // Expected values from the EDS text (minimal INI lookup) and CiA 402.
    let eds = std::fs::read(eds_path).expect("read EDS");
    let eds = String::from_utf8_lossy(&eds);
    let want = |section: &str| eds_uint(&ini_value(&eds, section, "DefaultValue").unwrap());
    // 0x6041 before any SYNC: SWITCH ON DISABLED after start-up, voltage enabled, remote.
    assert_eq!(r["statusword_before_sync"], 0x0250);
    assert_eq!(r["rpdo1_type"], want("1400sub2"));
    assert_eq!(r["tpdo1_type"], want("1800sub2"));
    assert_eq!(r["heartbeat_ms"], want("1017"));
    // Controlword 6, 7, 0xF by SDO: READY TO SWITCH ON (0x21), SWITCHED ON (0x23), OPERATION
    // ENABLED (0x27) under mask 0x6F, each seen by a statusword read.
    let steps = r["steps"].as_array().expect("steps");
    assert_eq!(steps.len(), 3, "{steps:?}");
    for (step, (cw, state)) in steps.iter().zip([(6, 0x21), (7, 0x23), (0xF, 0x27)]) {
        assert_eq!(step["controlword"], cw);
        let last = step["statusword_reads"]
            .as_array()
            .and_then(|v| v.last())
            .and_then(|v| v.as_u64())
            .expect("a statusword read");
        assert_eq!(last & 0x6F, state, "controlword {cw:#x}: {step}");
    }
    assert_eq!(r["statusword_final"].as_u64().unwrap() & 0x6F, 0x27);
    assert_eq!(r["controlword_readback"], 0x000F);
    // After NMT start the event-driven TPDO1 (type 255, 0x6041) came without a SYNC.
    let tpdo = r["tpdo1_after_start"]
        .as_str()
        .expect("TPDO1 after NMT start");
    let sw = u16::from_str_radix(&format!("{}{}", &tpdo[2..4], &tpdo[0..2]), 16).unwrap();
    assert_eq!(sw & 0x6F, 0x27, "TPDO1 {tpdo}");
}
