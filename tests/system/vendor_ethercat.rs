//! Vendor CiA 402 devices over a real wire (issue 19): `fieldprobe sim ethercat` plays the real
//! Ingenia EVS-NET-01 ESI (`../shared/test-data/esi/`, three devices) on one end of a veth pair —
//! its own dictionary, default PDO mapping (0x6040, 0x607A, 0x60FF, 0x6060 / 0x6041, 0x6064,
//! 0x606C, 0x6061, not fieldprobe's layout) and no touch probe — and on the other end:
//! 1. `fieldprobe scan` shows each device's vendor id, product code and name as the ESI says
//!    (read here with roxmltree, not `fieldprobe::esi`);
//! 2. `fieldprobe run examples/nc/hello.nc --link ethercat:v0`: our master fits the default
//!    machine's drive (`cia402-generic`) to the devices — the touch-probe objects left out with
//!    warning 900404, the rest remapped in PRE-OP — and prints exactly what `--link sim` prints;
//! 3. SOEM through pysoem (`tests/pysoem/vendor.py`): identities, the PDO remapping rules with
//!    the CiA 301 / ETG abort codes (a non-mappable object 0x06040041, an entry written while
//!    sub-index 0 ≠ 0 0x06010003, a remap in OP 0x08000022), process data sized by the ESI's
//!    default mapping at the expected working counter, CiA 402 enable through the images.
//!
//! The venv is `scripts/pysoem-venv.sh`'s (a failed install is a failure); a machine without
//! user namespaces / veth, or without the test data, SKIPs (FIELDPROBE_REQUIRE_TEST_DATA=1 makes
//! missing data a failure). Every wait is bounded.

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::Duration,
};

use serde_json::{json, Value};

use crate::common::test_data;
use crate::common::vendor_spec;
use crate::common::veth;
use vendor_spec::device_spec;
use veth::netns::{manifest_path, run_bounded};
use veth::{start_emulator, VethPair, MASTER_IF};

const INNER_ENV: &str = "FIELDPROBE_VENDOR_ETHERCAT_PYTHON";
const TEST_NAME: &str = "vendor_devices_over_veth";
const VENV_TIMEOUT: Duration = Duration::from_secs(15 * 60);
const OUTER_TIMEOUT: Duration = Duration::from_secs(300);
const STEP_TIMEOUT: Duration = Duration::from_secs(90);
const EMULATOR_SECONDS: &str = "250";
const INGENIA: &str = "esi/ingenia-evs-net-ecat402-drive.xml";
const COUNT: usize = 3;

fn venv_dir() -> PathBuf {
    veth::pysoem_venv_dir()
}

#[test]
fn vendor_devices_over_veth() {
    let _one_module = crate::gate::enter(module_path!());
    if let Some(python) = veth::inner_env(INNER_ENV) {
        inner(Path::new(&python));
        return;
    }
    if test_data::test_data(INGENIA, TEST_NAME).is_none() {
        return;
    }
    veth::run_in_veth_namespace(TEST_NAME, INNER_ENV, OUTER_TIMEOUT, || {
        veth::netns::build_venv(
            "scripts/pysoem-venv.sh",
            &venv_dir(),
            VENV_TIMEOUT,
            "pysoem could not be installed from PyPI (registry unreachable or SOEM build failed), \
             this is a failure, not a skip",
        )
        .into_os_string()
    });
}

fn fieldprobe(args: &[&str]) -> (Option<std::process::ExitStatus>, String, String) {
    veth::fieldprobe_bounded(args, STEP_TIMEOUT)
}

fn inner(python: &Path) {
    let esi = test_data::test_data(INGENIA, TEST_NAME).expect("test data checked outside");
    let spec = device_spec(&esi);
    let _pair = VethPair::create();
    let device = format!("{}:{COUNT}", esi.display());
    let (emu, emu_log) = start_emulator(&[device.as_str()], EMULATOR_SECONDS, &[]);
    let link = format!("ethercat:{MASTER_IF}");

    // 1. scan: the vendor identity.
    let (status, scan, err) = fieldprobe(&["scan", "--link", &link]);
    assert!(
        status.is_some_and(|s| s.success()),
        "scan: {status:?}\n{scan}\n{err}"
    );
    let rows: Vec<&str> = scan.lines().skip(1).collect();
    assert_eq!(rows.len(), COUNT, "{scan}");
    for (pos, row) in rows.iter().enumerate() {
        let cols: Vec<&str> = row.split_whitespace().collect();
        let hex = |v: &Value| format!("{:#010x}", v.as_u64().unwrap());
        assert_eq!(cols[0], pos.to_string(), "{row}");
        assert_eq!(cols[2], hex(&spec["vendor"]), "vendor id: {row}");
        assert_eq!(cols[3], hex(&spec["product"]), "product code: {row}");
        assert_eq!(cols[4], hex(&spec["revision"]), "revision: {row}");
        assert!(row.ends_with(spec["name"].as_str().unwrap()), "name: {row}");
    }

    // 2. hello.nc: our master remaps and drives X, Y, Z as on the in-memory link.
    let (status, want, err) = fieldprobe(&["run", "examples/nc/hello.nc", "--link", "sim"]);
    assert!(status.is_some_and(|s| s.success()), "{want}{err}");
    let (status, out, err) = fieldprobe(&["run", "examples/nc/hello.nc", "--link", &link]);
    assert!(
        status.is_some_and(|s| s.success()),
        "run: {status:?}\n{out}\n{err}"
    );
    assert_eq!(out, want, "stdout over the vendor devices\nstderr: {err}");
    let latch_off = err
        .lines()
        .filter(|l| l.starts_with("warning 900404: ") && l.contains("0x60B8:00"))
        .count();
    assert_eq!(latch_off, COUNT, "one drive-latch warning per axis:\n{err}");

    // 3. SOEM.
    let spec_all = json!({ "devices": vec![spec.clone(); COUNT] });
    let (status, out, err) = run_bounded(
        Command::new(python)
            .stdin(Stdio::null())
            .arg(manifest_path("tests/pysoem/vendor.py"))
            .arg(MASTER_IF)
            .arg(spec_all.to_string()),
        STEP_TIMEOUT,
    );
    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!("emulator log: {log:#?}\nvendor.py stderr:\n{err}");
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix("VENDOR_RESULT "))
        .unwrap_or_else(|| panic!("vendor.py printed no VENDOR_RESULT ({status:?})\n{out}"));
    let r: Value = serde_json::from_str(line).expect("VENDOR_RESULT is JSON");
    assert_eq!(
        r["ok"], true,
        "vendor.py: {} (steps {})",
        r["error"], r["steps"]
    );
    println!("INNER OK");
}
