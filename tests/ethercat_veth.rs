//! ethercrab 0.7.1 over a real (virtual) Ethernet link: `fieldprobe sim ethercat` answers on
//! one end of a veth pair, the stock `ethercrab::std::tx_rx_task` drives the other end
//! (notes `ethercat.md` §0 point 2, §1.3).
//!
//! Isolation: the test re-executes its own binary inside a fresh unprivileged user + network
//! namespace (`unshare -rn`), where it is root and can create the veth pair without touching
//! the host. All traffic stays inside that namespace, which disappears with its processes.
//! If `unshare`, user namespaces, `ip` or veth are not available, the test prints `SKIP` and
//! passes. Every wait is bounded: the emulator runs with `--seconds` and is killed at the end,
//! the namespace child is killed after [`OUTER_TIMEOUT`].

use std::{
    io::{BufRead, BufReader, Read},
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::mpsc,
    thread,
    time::{Duration, Instant},
};

use ethercrab::{
    std::{ethercat_now, tx_rx_task},
    MainDevice, MainDeviceConfig, PduStorage, SubDeviceState, Timeouts,
};

/// Set in the re-executed test process (inside the namespace).
const INNER_ENV: &str = "FIELDPROBE_VETH_INNER";
const TEST_NAME: &str = "ethercrab_over_veth_finds_esi_devices";
const OUTER_TIMEOUT: Duration = Duration::from_secs(60);
const INNER_TIMEOUT: Duration = Duration::from_secs(30);
/// Lifetime of the emulator process (it is killed earlier when the test is done).
const EMULATOR_SECONDS: &str = "40";
const MASTER_IF: &str = "v0";
const EMULATOR_IF: &str = "v1";
const ESI_FILES: [&str; 2] = ["esi/fieldprobe-ek1100.xml", "esi/fieldprobe-el5101.xml"];

const MAX_SUBDEVICES: usize = 8;
const MAX_PDI: usize = 64;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

/// Identity and names of a device as written in its ESI file.
#[derive(Debug, Clone, PartialEq, Eq)]
struct EsiIdentity {
    vendor: u32,
    product: u32,
    revision: u32,
    type_name: String,
    name: String,
}

fn esi_number(s: &str) -> u32 {
    let t = s.trim();
    match t.strip_prefix("#x").or_else(|| t.strip_prefix("0x")) {
        Some(h) => u32::from_str_radix(h, 16).expect("hex number"),
        None => t.parse().expect("decimal number"),
    }
}

/// Read vendor ID, product code, revision, `Type` text and English name of the first device
/// straight from the XML (independently of `fieldprobe::esi`).
fn esi_identity(path: &Path) -> EsiIdentity {
    let text = std::fs::read_to_string(path).expect("read ESI");
    let doc = roxmltree::Document::parse(&text).expect("parse ESI");
    fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> roxmltree::Node<'a, 'i> {
        n.children()
            .find(|c| c.has_tag_name(tag))
            .unwrap_or_else(|| panic!("no <{tag}> in <{}>", n.tag_name().name()))
    }
    let root = doc.root_element();
    let vendor = esi_number(child(child(root, "Vendor"), "Id").text().unwrap_or(""));
    let device = child(child(child(root, "Descriptions"), "Devices"), "Device");
    let ty = child(device, "Type");
    let name = device
        .children()
        .filter(|c| c.has_tag_name("Name"))
        .find(|c| c.attribute("LcId") == Some("1033"))
        .and_then(|c| c.text())
        .unwrap_or("")
        .to_string();
    EsiIdentity {
        vendor,
        product: esi_number(ty.attribute("ProductCode").expect("ProductCode")),
        revision: esi_number(ty.attribute("RevisionNo").unwrap_or("0")),
        type_name: ty.text().unwrap_or("").trim().to_string(),
        name,
    }
}

fn manifest_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// Wait for `child` at most `timeout`; kill it if it is still running. Returns the exit
/// status, or `None` if it had to be killed.
fn wait_bounded(child: &mut Child, timeout: Duration) -> Option<std::process::ExitStatus> {
    let t0 = Instant::now();
    loop {
        if let Some(s) = child.try_wait().expect("try_wait") {
            return Some(s);
        }
        if t0.elapsed() >= timeout {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        thread::sleep(Duration::from_millis(20));
    }
}

/// Can this machine create a user + network namespace with a veth pair in it?
fn namespace_probe() -> Result<(), String> {
    let mut child = Command::new("unshare")
        .args([
            "-rn",
            "sh",
            "-c",
            "ip link add v0 type veth peer name v1 && ip link set v0 up && ip link set v1 up",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run `unshare`: {e}"))?;
    let mut err = String::new();
    let status = wait_bounded(&mut child, Duration::from_secs(10));
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    match status {
        Some(s) if s.success() => Ok(()),
        Some(s) => Err(format!(
            "`unshare -rn` + `ip link add … type veth` failed ({s}): {}",
            err.trim()
        )),
        None => Err("`unshare -rn` did not finish within 10 s".into()),
    }
}

#[test]
fn ethercrab_over_veth_finds_esi_devices() {
    if std::env::var_os(INNER_ENV).is_some() {
        inner();
        return;
    }
    if let Err(why) = namespace_probe() {
        eprintln!("SKIP {TEST_NAME}: {why}");
        return;
    }
    let exe = std::env::current_exe().expect("current_exe");
    let t0 = Instant::now();
    let mut child = Command::new("unshare")
        .arg("-rn")
        .arg("--")
        .arg(&exe)
        .args([TEST_NAME, "--exact", "--nocapture", "--test-threads=1"])
        .env(INNER_ENV, "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn unshare");
    let out = child.stdout.take().expect("stdout");
    let err = child.stderr.take().expect("stderr");
    let out_reader = thread::spawn(move || {
        let mut s = String::new();
        let _ = BufReader::new(out).read_to_string(&mut s);
        s
    });
    let err_reader = thread::spawn(move || {
        let mut s = String::new();
        let _ = BufReader::new(err).read_to_string(&mut s);
        s
    });
    let status = wait_bounded(&mut child, OUTER_TIMEOUT);
    let elapsed = t0.elapsed();
    let out = out_reader.join().unwrap_or_default();
    let err = err_reader.join().unwrap_or_default();
    eprintln!("--- namespace child ({elapsed:?}) stdout:\n{out}\n--- stderr:\n{err}");
    match status {
        Some(s) => assert!(s.success(), "namespace child failed: {s}"),
        None => panic!("namespace child did not finish within {OUTER_TIMEOUT:?}"),
    }
    assert!(
        out.contains("INNER OK"),
        "inner test did not report success"
    );
}

/// Kills the emulator when dropped (also on panic).
struct Emulator(Child);

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn ip(args: &[&str]) {
    let s = Command::new("ip").args(args).status().expect("run ip");
    assert!(s.success(), "ip {args:?}: {s}");
}

/// Inside the namespace: veth pair, emulator on one end, ethercrab on the other.
fn inner() {
    let t0 = Instant::now();
    ip(&[
        "link",
        "add",
        MASTER_IF,
        "type",
        "veth",
        "peer",
        "name",
        EMULATOR_IF,
    ]);
    ip(&["link", "set", MASTER_IF, "up"]);
    ip(&["link", "set", EMULATOR_IF, "up"]);

    let expected: Vec<EsiIdentity> = ESI_FILES
        .iter()
        .map(|f| esi_identity(&manifest_path(f)))
        .collect();

    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fieldprobe"));
    cmd.args([
        "sim",
        "ethercat",
        "--iface",
        EMULATOR_IF,
        "--seconds",
        EMULATOR_SECONDS,
    ]);
    for f in ESI_FILES {
        cmd.arg("--device").arg(manifest_path(f));
    }
    let mut emu = Emulator(
        cmd.stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn fieldprobe sim ethercat"),
    );
    // Wait (bounded) until the emulator's socket is open.
    let stderr = emu.0.stderr.take().expect("emulator stderr");
    let (line_tx, line_rx) = mpsc::channel::<String>();
    let emu_log = thread::spawn(move || {
        let mut all = Vec::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = line_tx.send(line.clone());
            all.push(line);
        }
        all
    });
    let ready_deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let left = ready_deadline.saturating_duration_since(Instant::now());
        match line_rx.recv_timeout(left) {
            Ok(l) if l.contains("listening on") => break,
            Ok(_) => {}
            Err(e) => panic!("emulator not ready within 10 s: {e}"),
        }
    }
    let t_ready = t0.elapsed();

    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("split once");
    thread::spawn(move || {
        let task = tx_rx_task(MASTER_IF, tx, rx).expect("open raw socket on v0");
        let _ = futures_lite::future::block_on(task);
    });

    let (done_tx, done_rx) = mpsc::channel();
    thread::spawn(move || {
        let r = futures_lite::future::block_on(async move {
            let md = MainDevice::new(
                pdu_loop,
                Timeouts {
                    state_transition: Duration::from_secs(2),
                    ..Timeouts::default()
                },
                MainDeviceConfig {
                    dc_static_sync_iterations: 50,
                    ..MainDeviceConfig::default()
                },
            );
            let group = md
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercat_now)
                .await
                .expect("init_single_group");
            let mut found = Vec::new();
            for sd in group.iter(&md) {
                let id = sd.identity();
                let desc = sd.description().await.expect("description");
                found.push(EsiIdentity {
                    vendor: id.vendor_id,
                    product: id.product_id,
                    revision: id.revision,
                    type_name: sd.name().to_string(),
                    name: desc.map(|d| d.to_string()).unwrap_or_default(),
                });
            }
            let t_init = Instant::now();
            let group = group.into_safe_op(&md).await.expect("PRE-OP -> SAFE-OP");
            let group = group.into_op(&md).await.expect("SAFE-OP -> OP");
            let mut cycles = Vec::new();
            for _ in 0..5 {
                let resp = group.tx_rx(&md).await.expect("tx_rx");
                cycles.push((resp.working_counter, resp.subdevice_states.to_vec()));
            }
            (found, cycles, t_init.elapsed())
        });
        let _ = done_tx.send(r);
    });
    let (found, cycles, t_op) = match done_rx.recv_timeout(INNER_TIMEOUT) {
        Ok(r) => r,
        Err(e) => panic!("MainDevice side did not finish within {INNER_TIMEOUT:?}: {e}"),
    };
    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!(
        "emulator ready after {t_ready:?}; master done after {:?} (SAFE-OP/OP + 5 cycles {t_op:?})",
        t0.elapsed()
    );
    println!("emulator log: {log:?}");
    println!("found: {found:#x?}");
    println!("cycles (wkc, states): {cycles:?}");

    assert_eq!(found, expected);
    for (wkc, states) in &cycles {
        assert!(
            states.iter().all(|s| *s == SubDeviceState::Op),
            "{states:?}"
        );
        // LRW: +1 read +2 write for the terminal with process data; the coupler maps nothing.
        assert_eq!(*wkc, 3, "{cycles:?}");
    }
    println!("INNER OK");
}
