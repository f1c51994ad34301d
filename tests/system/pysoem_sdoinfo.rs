//! SDO Information over a real wire: `fieldprobe sim ethercat` (coupler + CiA 402 servo) on one
//! end of a veth pair, and on the other end
//! 1. `fieldprobe sdos --link ethercat:v0 --device 1` and `pdos` (our CoE client through
//!    ethercrab on a raw socket), and
//! 2. SOEM through pysoem (`tests/pysoem/od.py`, `slave.od`: ecx_readODlist,
//!    ecx_readODdescription, ecx_readOE), an independent master's SDO Information client.
//!
//! Both must find exactly the dictionary the servo's ESI declares, read here with roxmltree
//! (`common/esi_dict.rs`, independently of `fieldprobe::esi`): object list, names, object codes
//! (VAR / RECORD), data types, bit lengths and access bits incl. PDO mapping.
//!
//! The venv is `scripts/pysoem-venv.sh`'s (as `tests/system/pysoem_interop.rs`; a failed install is a
//! failure); only a machine without user namespaces / veth SKIPs. Every wait is bounded.

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::Duration,
};

use serde_json::Value;

use crate::common::esi_dict;
use crate::common::veth;
use veth::netns::{manifest_path, run_bounded};
use veth::{start_emulator, VethPair, MASTER_IF};

const INNER_ENV: &str = "FIELDPROBE_PYSOEM_SDOINFO_PYTHON";
const TEST_NAME: &str = "sdo_information_over_veth_matches_the_esi";
const VENV_TIMEOUT: Duration = Duration::from_secs(15 * 60);
const OUTER_TIMEOUT: Duration = Duration::from_secs(240);
const STEP_TIMEOUT: Duration = Duration::from_secs(90);
const EMULATOR_SECONDS: &str = "200";
const ESI_FILES: [&str; 2] = [
    "esi/fieldprobe-ek1100.xml",
    "esi/fieldprobe-cia402-servo.xml",
];
const SERVO: usize = 1;
/// SOEM keeps at most this many characters of a name (EC_MAXNAME).
const SOEM_MAXNAME: usize = 40;

fn venv_dir() -> PathBuf {
    veth::pysoem_venv_dir()
}

#[test]
fn sdo_information_over_veth_matches_the_esi() {
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
            "pysoem could not be installed from PyPI (registry unreachable or SOEM build failed), \
             this is a failure, not a skip",
        )
        .into_os_string()
    });
}

fn fieldprobe_out(args: &[&str]) -> String {
    let (status, out, err) = run_bounded(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .stdin(Stdio::null())
            .args(args),
        STEP_TIMEOUT,
    );
    let status = status.unwrap_or_else(|| panic!("fieldprobe {args:?} did not finish"));
    assert!(
        status.success(),
        "fieldprobe {args:?}: {status}\n{out}\n{err}"
    );
    out
}

fn inner(python: &Path) {
    let _pair = VethPair::create();
    let dict = esi_dict::dictionary(ESI_FILES[SERVO]);
    let (emu, emu_log) = start_emulator(&ESI_FILES, EMULATOR_SECONDS, &[]);
    let link = format!("ethercat:{MASTER_IF}");

    // 1. Our client through ethercrab on the raw socket.
    let sdos = fieldprobe_out(&["sdos", "--link", &link, "--device", "1"]);
    let want = esi_dict::sdos_lines(&dict);
    assert_eq!(sdos.lines().collect::<Vec<_>>(), want, "{sdos}");
    let pdos = fieldprobe_out(&["pdos", "--link", &link, "--device", "1"]);
    assert!(
        pdos.contains("SM2: PhysAddr 0x1100, DefaultSize 9, ControlRegister 0x64, Enable 1\n  RxPDO 0x1600 \"RxPDO 1 mapping\"\n    PDO entry 0x6040:00, 16 bit, \"Controlword\""),
        "{pdos}"
    );

    // 2. SOEM.
    let (status, out, err) = run_bounded(
        Command::new(python)
            .stdin(Stdio::null())
            .arg(manifest_path("tests/pysoem/od.py"))
            .arg(MASTER_IF)
            .arg(SERVO.to_string()),
        STEP_TIMEOUT,
    );
    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!("emulator log: {log:#?}\nod.py stderr:\n{err}");
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix("OD_RESULT "))
        .unwrap_or_else(|| panic!("od.py printed no OD_RESULT ({status:?})\n{out}"));
    let r: Value = serde_json::from_str(line).expect("OD_RESULT is JSON");
    assert_eq!(r["ok"], true, "od.py: {}", r["error"]);
    let objects = r["objects"].as_array().expect("objects");
    let indexes: Vec<u64> = objects
        .iter()
        .map(|o| o["index"].as_u64().unwrap())
        .collect();
    let want_idx: Vec<u64> = dict.iter().map(|o| u64::from(o.index)).collect();
    assert_eq!(indexes, want_idx, "SOEM's OD list");
    let cut = |s: &str| s.chars().take(SOEM_MAXNAME).collect::<String>();
    for (o, e) in objects.iter().zip(&dict) {
        let at = format!("{:#06x}", e.index);
        assert_eq!(o["name"], cut(&e.name), "{at} name");
        assert_eq!(o["object_code"], e.object_code, "{at} object code");
        if e.object_code == 7 {
            let x = &e.entries[0];
            let entry = o["entries"].as_array().and_then(|v| v.first());
            let (bits, acc) = match entry {
                Some(en) => (&en["bit_length"], &en["obj_access"]),
                None => (&o["bit_length"], &o["obj_access"]),
            };
            assert_eq!(o["data_type"], x.data_type, "{at} data type");
            assert_eq!(*bits, x.bits, "{at} bit length");
            assert_eq!(*acc, x.access, "{at} access");
        } else {
            let entries = o["entries"].as_array().expect("entries");
            assert_eq!(entries.len(), e.entries.len(), "{at} entries: {o}");
            for (g, x) in entries.iter().zip(&e.entries) {
                let at = format!("{at}:{:02x}", x.sub);
                assert_eq!(g["name"], cut(&x.name), "{at} name");
                assert_eq!(g["data_type"], x.data_type, "{at} data type");
                assert_eq!(g["bit_length"], x.bits, "{at} bit length");
                assert_eq!(g["obj_access"], x.access, "{at} access");
            }
        }
    }
    println!("SOEM read {} objects; INNER OK", objects.len());
}
