//! One `fieldprobe sim ethercat` serves session after session (issue 15 "Done when"): two
//! `fieldprobe run --link ethercat:v0` of meas1, an SDO read by another master (SOEM through
//! pysoem, `tests/pysoem/sdo_read.py`), then a third `run`, all against ONE emulator process
//! on the other end of a veth pair (`tests/common/veth.rs`), in a private user + network
//! namespace that vanishes with its processes.
//!
//! What each step must give:
//! - every `run`: exit 0 and the seed's meas1 values (seed 004 §5, the probe surface of the
//!   emulated world at Z = 100 mm, `--probe-at 3=100`);
//! - the SOEM session: four devices; the Z servo's 0x1000 device type = the ESI's
//!   `DefaultData` of object 0x1000, 0x1018:1..3 = the ESI's vendor ID / product code /
//!   revision, 0x1008 = the ESI's English device name (all read here from the XML with
//!   roxmltree, not with `fieldprobe::esi`); 0x6041 not OPERATION ENABLED (the previous master
//!   left: CiA 402 drive with no valid outputs).
//!
//! What it guards: the emulator keeps serving new masters. Each master starts its mailbox
//! counter at 1 after INIT (ETG.1000.4 mailbox repeat rule; SOEM and ethercrab both do). The
//! SOEM session below makes exactly 8 mailbox requests (8 SDO uploads; 0x1008, 44 bytes, fits
//! one mailbox as a normal upload), counters 1 … 7, 1, so it ends on counter 1: an emulator
//! that kept the counter across INIT drops the third run's first SDO as a repeat. Checked:
//! without the ESC's `mailbox_reset` on INIT the third run fails with "PDO mapping 0x1c12:00 =
//! 0: mailbox timeout after 2s (SDO response)", exit 2.
//!
//! Bounds: every child process is bounded (`run` 120 s, SOEM 60 s, the namespace child
//! [`OUTER_TIMEOUT`]); the emulator lives at most [`EMULATOR_SECONDS`] and is killed at the end.
//! The runs use the link's real-interface timeouts and `max_lost_cycles = 50` (50 ms at the
//! default 1 ms cycle): a busy machine may lose a frame now and then (counted in the cycle
//! summary), what is checked here are sessions, not timing (that is `tests/system/ethercat_rt.rs`).
//! The emulator runs `--lockstep` (its drives step per process-data cycle, no sync-manager
//! watchdog): on its own clock, a loaded two-core machine (load average 6) held the processes
//! up beyond the devices' 100 ms watchdog and the drives faulted; the own clock and the
//! watchdogs are covered by `tests/system/ethercat_iface_run.rs` and `tests/system/ethercat_veth_watchdog.rs`.
//! Only a machine without user namespaces, `unshare`, `ip` or veth SKIPs; a pysoem venv that
//! cannot be built fails (as `tests/system/pysoem_interop.rs`).

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::{Duration, Instant},
};

use serde_json::Value;

use crate::common::esi_xml;
use crate::common::veth;
use veth::netns::{manifest_path, run_bounded, SEED004_MEAS1};
use veth::{start_emulator, VethPair, MASTER_IF};

/// Set in the re-executed test process (inside the namespace); value = venv python.
const INNER_ENV: &str = "FIELDPROBE_SESSIONS_INNER_PYTHON";
const TEST_NAME: &str = "runs_and_a_soem_session_against_one_sim_ethercat";
/// First venv build may compile SOEM.
const VENV_TIMEOUT: Duration = Duration::from_secs(15 * 60);
/// Three runs of ~20 s of motion each, start-up, SOEM; generous for a loaded machine.
const OUTER_TIMEOUT: Duration = Duration::from_secs(420);
const RUN_TIMEOUT: Duration = Duration::from_secs(120);
const SOEM_TIMEOUT: Duration = Duration::from_secs(60);
/// Lifetime of the emulator process (it is killed earlier when the test is done).
const EMULATOR_SECONDS: &str = "400";
const COUPLER: &str = "esi/fieldprobe-ek1100.xml";
const SERVO: &str = "esi/fieldprobe-cia402-servo.xml";
/// Ring position of the Z servo (coupler at 0, the X, Y, Z servos at 1, 2, 3).
const Z: usize = 3;

fn venv_dir() -> PathBuf {
    match std::env::var_os("PYSOEM_VENV") {
        Some(v) => PathBuf::from(v),
        None => manifest_path("target/pysoem-venv"),
    }
}

#[test]
fn runs_and_a_soem_session_against_one_sim_ethercat() {
    let _one_module = crate::gate::enter(module_path!());
    if let Some(python) = veth::inner_env(INNER_ENV) {
        inner(Path::new(&python));
        return;
    }
    veth::run_in_veth_namespace(TEST_NAME, INNER_ENV, OUTER_TIMEOUT, || {
        veth::netns::build_venv(
            "scripts/pysoem-venv.sh",
            &venv_dir(),
            VENV_TIMEOUT,
            "pysoem could not be installed from PyPI (registry unreachable or SOEM build \
             failed), this is a failure, not a skip",
        )
        .into_os_string()
    });
}

/// `DefaultData` of object `index` in the ESI at `path` (hexBinary, little-endian), as u32.
fn esi_default_u32(path: &Path, index: u16) -> u32 {
    let text = std::fs::read_to_string(path).expect("read ESI");
    let doc = roxmltree::Document::parse(&text).expect("parse ESI");
    let want = format!("#x{index:04x}");
    let object = doc
        .descendants()
        .filter(|n| n.has_tag_name("Object"))
        .find(|o| {
            o.children().any(|c| {
                c.has_tag_name("Index") && c.text().is_some_and(|t| t.eq_ignore_ascii_case(&want))
            })
        })
        .unwrap_or_else(|| panic!("no object {want} in {}", path.display()));
    let hex = object
        .descendants()
        .find(|n| n.has_tag_name("DefaultData"))
        .and_then(|n| n.text())
        .unwrap_or_else(|| panic!("object {want} has no DefaultData"));
    let bytes: Vec<u8> = (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hexBinary"))
        .collect();
    bytes.iter().rev().fold(0, |v, b| (v << 8) | u32::from(*b))
}

/// One `fieldprobe run meas1.nc --link ethercat:v0`: exit code, stdout, stderr.
fn run_meas1(n: usize) -> (Option<i32>, String, String) {
    let t0 = Instant::now();
    let (status, out, err) = run_bounded(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdin(Stdio::null())
            .args([
                "run",
                "examples/nc/seed004/meas1.nc",
                "--link",
                &format!("ethercat:{MASTER_IF}"),
                "--set",
                "max_lost_cycles=50",
            ]),
        RUN_TIMEOUT,
    );
    println!("run {n} ({:?}): {status:?}\n{out}{err}", t0.elapsed(),);
    (status.and_then(|s| s.code()), out, err)
}

/// Inside the namespace.
fn inner(python: &Path) {
    let _pair = VethPair::create();
    let (emu, emu_log) = start_emulator(
        &[COUPLER, &format!("{SERVO}:3")],
        EMULATOR_SECONDS,
        // Lockstep: the drives step once per process-data cycle of the master instead of at
        // SYNC0 on the emulator's own clock (bounds in the module documentation).
        &["--probe-at".into(), format!("{Z}=100"), "--lockstep".into()],
    );
    let check_run = |n: usize| {
        let (code, out, err) = run_meas1(n);
        assert_eq!(code, Some(0), "run {n}: {out}{err}");
        assert_eq!(out.lines().collect::<Vec<_>>(), SEED004_MEAS1, "run {n}");
    };
    check_run(1);
    check_run(2);

    // Another master: SOEM scans the segment and reads objects of the Z servo by SDO.
    let reads = [
        "0x1000:0",
        "0x1018:1",
        "0x1018:2",
        "0x1018:3",
        "0x1008:0:s",
        "0x6041:0",
        "0x1018:0",
        "0x1C12:0",
    ];
    let (status, out, err) = run_bounded(
        Command::new(python)
            .stdin(Stdio::null())
            .arg(manifest_path("tests/pysoem/sdo_read.py"))
            .arg(MASTER_IF)
            .arg(Z.to_string())
            .args(reads),
        SOEM_TIMEOUT,
    );
    println!("sdo_read.py: {status:?}\n{out}{err}");
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix("SDO_RESULT "))
        .unwrap_or_else(|| panic!("sdo_read.py printed no SDO_RESULT ({status:?}): {err}"));
    let r: Value = serde_json::from_str(line).expect("SDO_RESULT is JSON");
    assert_eq!(r["ok"], true, "SOEM: {}", r["error"]);
    assert_eq!(r["devices"], 4, "{r}");
    let servo = esi_xml::esi_identity(&manifest_path(SERVO));
    let v = &r["values"];
    assert_eq!(
        v["0x1000:0"],
        esi_default_u32(&manifest_path(SERVO), 0x1000),
        "{r}"
    );
    assert_eq!(v["0x1018:1"], servo.vendor, "{r}");
    assert_eq!(v["0x1018:2"], servo.product, "{r}");
    assert_eq!(v["0x1018:3"], servo.revision, "{r}");
    assert_eq!(v["0x1008:0"], servo.name.as_str(), "{r}");
    let sw = v["0x6041:0"].as_u64().expect("0x6041");
    // CiA 402 state coding under mask 0x6F: 0x27 = OPERATION ENABLED.
    assert_ne!(sw & 0x6F, 0x27, "statusword {sw:#06x} with no master in OP");

    check_run(3);
    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!("emulator log: {log:#?}");
    println!("INNER OK");
}
