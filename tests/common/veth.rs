//! The veth-pair harness of the EtherCAT raw-socket tests: `fieldprobe sim ethercat` on one end
//! of a veth pair [`MASTER_IF`] ↔ [`EMULATOR_IF`], a master on the other, all inside a fresh
//! unprivileged user + network namespace (`unshare -rn`) in which the test is root; nothing on
//! the host changes and the namespace vanishes with its processes.
//!
//! Outer half: [`run_in_veth_namespace`] checks that a veth pair can be made in a new
//! namespace (else prints `SKIP` and returns), then re-executes the test binary for the test
//! inside one (see [`netns::rerun_in_namespace`]). Inner half ([`inner_env`] is set): make the
//! pair with [`VethPair::create`] (deleted on drop), start the emulator with
//! [`start_emulator`] (killed on drop). Every wait is bounded.

#![allow(dead_code)] // each test crate uses its own subset

use std::ffi::OsString;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

pub use super::netns;
use netns::manifest_path;

/// The master's end of the pair.
pub const MASTER_IF: &str = "v0";
/// The emulator's end of the pair.
pub const EMULATOR_IF: &str = "v1";
/// Shell form of [`VethPair::create`], for [`veth_probe`].
pub const VETH_SETUP: &str =
    "ip link add v0 type veth peer name v1 && ip link set v0 up && ip link set v1 up";

/// Can this machine create a user + network namespace with a veth pair in it?
pub fn veth_probe() -> Result<(), String> {
    netns::namespace_probe_with(VETH_SETUP, "`ip link add … type veth`")
}

/// Outer half of a test: `SKIP` (return) unless [`veth_probe`] succeeds; else re-run
/// `test_name` in a new namespace with `inner_env` = `inner_value()` (called only when not
/// skipping, e.g. to build a venv), at most `timeout`; it must print `INNER OK`.
pub fn run_in_veth_namespace(
    test_name: &str,
    inner_env: &str,
    timeout: Duration,
    inner_value: impl FnOnce() -> OsString,
) {
    if let Err(why) = veth_probe() {
        eprintln!("SKIP {test_name}: {why}");
        return;
    }
    let value = inner_value();
    netns::rerun_in_namespace(test_name, inner_env, &value, timeout);
}

/// Inside the namespace: the value the outer half gave `name` (`None`: this is the outer
/// process).
pub fn inner_env(name: &str) -> Option<OsString> {
    std::env::var_os(name)
}

fn ip(args: &[&str]) {
    let s = Command::new("ip").args(args).status().expect("run ip");
    assert!(s.success(), "ip {args:?}: {s}");
}

/// Inside the namespace: the pair [`MASTER_IF`] ↔ [`EMULATOR_IF`], both up. Deleted when
/// dropped (also on panic); the namespace would take it along anyway.
pub struct VethPair(());

impl VethPair {
    pub fn create() -> VethPair {
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
        let pair = VethPair(());
        ip(&["link", "set", MASTER_IF, "up"]);
        ip(&["link", "set", EMULATOR_IF, "up"]);
        pair
    }
}

impl Drop for VethPair {
    fn drop(&mut self) {
        let _ = Command::new("ip")
            .args(["link", "del", MASTER_IF])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

/// Kills the emulator when dropped (also on panic).
pub struct Emulator(pub Child);

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start `fieldprobe sim ethercat` on [`EMULATOR_IF`] with a `--device` per ESI file (relative
/// to the crate), living at most `seconds`, plus `extra` arguments, and wait (at most 10 s)
/// until its socket is open. Returns the process and a thread collecting its stderr lines.
pub fn start_emulator(
    esi_files: &[&str],
    seconds: &str,
    extra: &[String],
) -> (Emulator, thread::JoinHandle<Vec<String>>) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fieldprobe"));
    cmd.args([
        "sim",
        "ethercat",
        "--iface",
        EMULATOR_IF,
        "--seconds",
        seconds,
    ]);
    for f in esi_files {
        cmd.arg("--device").arg(manifest_path(f));
    }
    cmd.args(extra);
    let mut emu = Emulator(
        cmd.stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn fieldprobe sim ethercat"),
    );
    let stderr = emu.0.stderr.take().expect("emulator stderr");
    let (line_tx, line_rx) = mpsc::channel::<String>();
    let log = thread::spawn(move || {
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
    (emu, log)
}

/// The pysoem venv of `scripts/pysoem-venv.sh`: `$PYSOEM_VENV`, else `target/pysoem-venv`.
pub fn pysoem_venv_dir() -> std::path::PathBuf {
    match std::env::var_os("PYSOEM_VENV") {
        Some(v) => std::path::PathBuf::from(v),
        None => netns::manifest_path("target/pysoem-venv"),
    }
}

/// `fieldprobe ARGS…` from the crate root, stdin closed, at most `limit`: (status, stdout,
/// stderr).
pub fn fieldprobe_bounded(
    args: &[&str],
    limit: Duration,
) -> (Option<std::process::ExitStatus>, String, String) {
    netns::run_bounded(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .stdin(Stdio::null())
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(args),
        limit,
    )
}
