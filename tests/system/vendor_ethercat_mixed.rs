//! Three vendors' CiA 402 drives on one veth segment (issue 19 "done when", EtherCAT):
//! `fieldprobe sim ethercat` plays, in ring order,
//! 0. the real Ingenia EVS-NET-01 ESI (`../shared/test-data/esi/`, no touch probe),
//! 1. a Leadshine ELP-EC400S excerpt generated from the SOEM dump of the real device (full
//!    dictionary, touch probe 0x60B8–0x60BD, default PDOs 0x1600 / 0x1A00),
//! 2. a Kollmorgen AKD excerpt generated from the real device's SII image (identity, sync
//!    managers, PDOs; the CiA 402 objects the PDOs reference; no CiA 402 touch probe),
//!
//! (`tests/common/vendor_esi.rs` writes the excerpts; each one's header names the source of
//! every fact), and on the other end of the pair:
//! 1. `fieldprobe scan` shows each identity as the source says (dump `Man:` / `ID:` / `Rev:`,
//!    SII header, the Ingenia ESI read with roxmltree) and the order string (ESI `Type`, SII
//!    General order: "AKD"; SOEM through pysoem shows the same string);
//! 2. `fieldprobe run examples/nc/hello.nc --link ethercat:v0` drives X, Y, Z (default machine,
//!    `cia402-generic`) on the three and prints what `--link sim` prints; warning 900404 (no
//!    drive latch) for X (Ingenia) and Z (AKD), none for Y (the Leadshine has a touch probe);
//! 3. `fieldprobe drive from-esi` on each of the three files, the definitions named per axis
//!    with `--set X.drive=FILE.toml …`: hello.nc prints what `--link sim` prints, no 900404
//!    (each definition maps the touch probe only where the device has one);
//! 4. SOEM through pysoem (`tests/pysoem/vendor.py`): identities, the remapping rules with
//!    their abort codes on a PDO that may change, the default mappings back (the AKD's are
//!    fixed: assigned only), OP at the expected working counter, CiA 402 enable through the
//!    process images of all three;
//! 5. error 900405: the Ingenia ESI without 0x6060 in ring position 0, the default machine's
//!    drive maps 0x6060: the start-up is refused naming the object.
//!
//! SKIP without user namespaces / veth or without the test data (FIELDPROBE_REQUIRE_TEST_DATA=1
//! makes missing data a failure). Every wait is bounded.

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::Duration,
};

use serde_json::{json, Value};

use crate::common::test_data;
use crate::common::vendor_esi;
use crate::common::vendor_spec;
use crate::common::veth;
use vendor_spec::device_spec;
use veth::netns::{manifest_path, run_bounded};
use veth::{start_emulator, VethPair, MASTER_IF};

const INNER_ENV: &str = "FIELDPROBE_VENDOR_MIXED_PYTHON";
const TEST_NAME: &str = "three_vendors_over_veth";
const VENV_TIMEOUT: Duration = Duration::from_secs(15 * 60);
const OUTER_TIMEOUT: Duration = Duration::from_secs(400);
const STEP_TIMEOUT: Duration = Duration::from_secs(90);
const EMULATOR_SECONDS: &str = "350";
const INGENIA: &str = "esi/ingenia-evs-net-ecat402-drive.xml";
const DUMP: &str = "sdo-dumps/leadshine-el7-ec400s-sdinfo.txt";
const SII: &str = "sii/kollmorgen-akd.hex";
const AXES: [&str; 3] = ["X", "Y", "Z"];

fn venv_dir() -> PathBuf {
    veth::pysoem_venv_dir()
}

fn work_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("vendor-ethercat-mixed")
}

#[test]
fn three_vendors_over_veth() {
    let _one_module = crate::gate::enter(module_path!());
    if let Some(python) = veth::inner_env(INNER_ENV) {
        inner(Path::new(&python));
        return;
    }
    for f in [INGENIA, DUMP, SII] {
        if test_data::test_data(f, TEST_NAME).is_none() {
            return;
        }
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

/// The three devices' specs in ring order, the identities checked against the sources.
fn specs(ingenia: &Path, leadshine: &Path, akd: &Path) -> Vec<Value> {
    let dump = vendor_esi::read_sdo_dump(
        &std::fs::read(test_data::test_data(DUMP, TEST_NAME).unwrap()).unwrap(),
    );
    let sii = vendor_esi::read_sii(
        &std::fs::read(test_data::test_data(SII, TEST_NAME).unwrap()).unwrap(),
    );
    let out = vec![
        device_spec(ingenia),
        device_spec(leadshine),
        device_spec(akd),
    ];
    let identity = |v: &Value| {
        (
            v["vendor"].as_u64().unwrap(),
            v["product"].as_u64().unwrap(),
            v["revision"].as_u64().unwrap(),
            v["name"].as_str().unwrap().to_string(),
        )
    };
    // The dump: "Man: 00004321 ID: 000010b2 Rev: 00000001", "Name:ELP-EC400S" (SOEM's name:
    // the SII General order string, as on the AKD below).
    assert_eq!(
        identity(&out[1]),
        (
            u64::from(dump.vendor),
            u64::from(dump.product),
            u64::from(dump.revision),
            dump.name.clone()
        )
    );
    assert_eq!(out[1]["type"], dump.name.as_str());
    assert_eq!((dump.vendor, dump.product), (0x4321, 0x10B2));
    // The SII: header words 0x08..0x0D, General name string.
    assert_eq!(
        identity(&out[2]),
        (
            u64::from(sii.vendor),
            u64::from(sii.product),
            u64::from(sii.revision),
            sii.name()
        )
    );
    assert_eq!(sii.order(), "AKD");
    assert_eq!(
        out[2]["type"],
        sii.order().as_str(),
        "SII General order string"
    );
    assert_eq!((sii.vendor, sii.product), (0x6A, 0x0041_4B44));
    out
}

fn run_ok(args: &[&str]) -> (String, String) {
    let (status, out, err) = fieldprobe(args);
    assert!(
        status.is_some_and(|s| s.success()),
        "fieldprobe {args:?}: {status:?}\n{out}\n{err}"
    );
    (out, err)
}

fn inner(python: &Path) {
    let ingenia = test_data::test_data(INGENIA, TEST_NAME).expect("checked outside");
    let dir = work_dir();
    let (leadshine, akd) = vendor_esi::write_excerpts(&dir, TEST_NAME).expect("checked outside");
    let spec = specs(&ingenia, &leadshine, &akd);
    let files = [ingenia.clone(), leadshine.clone(), akd.clone()];
    let _pair = VethPair::create();
    let devices: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    let devices: Vec<&str> = devices.iter().map(String::as_str).collect();
    let (emu, emu_log) = start_emulator(&devices, EMULATOR_SECONDS, &[]);
    let link = format!("ethercat:{MASTER_IF}");

    // 1. scan: the three identities.
    let (scan, _) = run_ok(&["scan", "--link", &link]);
    let rows: Vec<&str> = scan.lines().skip(1).collect();
    assert_eq!(rows.len(), 3, "{scan}");
    for (pos, (row, s)) in rows.iter().zip(&spec).enumerate() {
        let cols: Vec<&str> = row.split_whitespace().collect();
        let hex = |v: &Value| format!("{:#010x}", v.as_u64().unwrap());
        assert_eq!(cols[0], pos.to_string(), "{row}");
        assert_eq!(cols[2], hex(&s["vendor"]), "vendor id: {row}");
        assert_eq!(cols[3], hex(&s["product"]), "product code: {row}");
        assert_eq!(cols[4], hex(&s["revision"]), "revision: {row}");
        // ethercrab's name is the SII General order string (ESI `Type`).
        assert!(row.ends_with(s["type"].as_str().unwrap()), "type: {row}");
    }

    // 2. hello.nc on the default machine's drive, fitted to each device.
    let (want, _) = run_ok(&["run", "examples/nc/hello.nc", "--link", "sim"]);
    let (out, err) = run_ok(&["run", "examples/nc/hello.nc", "--link", &link]);
    assert_eq!(out, want, "stdout over the three vendors\nstderr: {err}");
    // "warning 900404: device 0:EVS-NET-01 has no touch probe …" (ring position: order string)
    let latch_off = |pos: usize| {
        err.lines()
            .filter(|l| l.starts_with(&format!("warning 900404: device {pos}:")))
            .count()
    };
    assert_eq!(
        [latch_off(0), latch_off(1), latch_off(2)],
        [1, 0, 1],
        "drive latch off for Ingenia (X) and AKD (Z), not for the Leadshine (Y):\n{err}"
    );

    // 3. drive from-esi per device, named per axis.
    let mut sets = Vec::new();
    for (axis, file) in AXES.iter().zip(&files) {
        let toml = dir.join(format!("{axis}-from-esi.toml"));
        let (_, notes) = run_ok(&[
            "drive",
            "from-esi",
            &file.display().to_string(),
            "--out",
            &toml.display().to_string(),
        ]);
        println!("drive from-esi {}: {notes}", file.display());
        sets.push(format!("{axis}.drive={}", toml.display()));
    }
    let mut args = vec!["run", "examples/nc/hello.nc", "--link", "sim"];
    for s in &sets {
        args.extend(["--set", s.as_str()]);
    }
    let (want_defs, _) = run_ok(&args);
    assert_eq!(want_defs, want, "the vendor definitions on --link sim");
    args[3] = &link;
    let (out, err) = run_ok(&args);
    assert_eq!(
        out, want,
        "stdout with the from-esi definitions\nstderr: {err}"
    );
    assert!(
        !err.contains("900404"),
        "the from-esi definitions map a touch probe only where the device has one:\n{err}"
    );

    // 4. SOEM.
    let (status, out, err) = run_bounded(
        Command::new(python)
            .stdin(Stdio::null())
            .arg(manifest_path("tests/pysoem/vendor.py"))
            .arg(MASTER_IF)
            .arg(json!({ "devices": spec }).to_string()),
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
    println!("vendor.py steps: {}", r["steps"]);

    // 5. A required object the device lacks: an Ingenia ESI copy without 0x6060 (its dictionary
    //    object and its entry in the default RxPDO). The emulator plays it (its model runs
    //    without modes of operation), our master refuses to start: error 900405 names the
    //    object, nothing runs.
    let text = std::fs::read_to_string(&ingenia).unwrap();
    let cut = without_object(&text, 0x6060);
    assert!(
        cut.len() < text.len() && !cut.contains(">#x6060<"),
        "0x6060 removed"
    );
    let no6060 = dir.join("ingenia-without-6060.xml");
    std::fs::write(&no6060, cut).unwrap();
    let devices = [
        no6060.display().to_string(),
        leadshine.display().to_string(),
        akd.display().to_string(),
    ];
    let devices: Vec<&str> = devices.iter().map(String::as_str).collect();
    let (emu, _log) = start_emulator(&devices, "60", &[]);
    let (status, out, err) = fieldprobe(&["run", "examples/nc/hello.nc", "--link", &link]);
    drop(emu);
    assert!(
        status.is_some_and(|s| !s.success()),
        "{status:?}\n{out}\n{err}"
    );
    assert_eq!(out, "", "nothing ran:\n{err}");
    let line = err
        .lines()
        .find(|l| l.contains("error 900405: "))
        .unwrap_or_else(|| panic!("error 900405 expected:\n{err}"));
    assert!(
        line.contains("device 0:EVS-NET-01")
            && line.contains("0x6060:00 (not in its object dictionary)")
            && !line.contains("0x60B8"),
        "{line}"
    );
    println!("INNER OK");
}

/// `xml` without the `<Object>` of `index` and without the PDO `<Entry>`s that map it.
fn without_object(xml: &str, index: u16) -> String {
    let tag = format!(">#x{index:04x}<");
    let mut out = String::new();
    let mut rest = xml;
    loop {
        let next = ["<Object>", "<Entry>"]
            .iter()
            .filter_map(|t| rest.find(t).map(|i| (i, *t)))
            .min();
        let Some((i, open)) = next else {
            out.push_str(rest);
            return out;
        };
        let close = open.replace('<', "</");
        let end = i + rest[i..].find(&close).expect("closing tag") + close.len();
        let block = &rest[i..end];
        let own_index = block
            .split("</Index>")
            .next()
            .is_some_and(|h| h.to_ascii_lowercase().ends_with(&tag[..tag.len() - 1]));
        out.push_str(&rest[..i]);
        if !own_index {
            out.push_str(block);
        }
        rest = &rest[end..];
    }
}

/// Without a network: the two excerpts parse (`fieldprobe esi show`), and `drive from-esi`
/// maps the touch probe for the Leadshine (0x60B8 RxPDO-, 0x60B9/0x60BA TxPDO-mappable in the
/// dump: access 0x007F / 0x0087) and not for the AKD (no CiA 402 touch probe in its PDOs).
#[test]
fn vendor_excerpts_parse_and_define_drives() {
    let _one_module = crate::gate::enter(module_path!());
    let dir = work_dir().join("offline");
    let Some((leadshine, akd)) = vendor_esi::write_excerpts(&dir, "vendor_excerpts") else {
        return;
    };
    let dump = vendor_esi::read_sdo_dump(
        &std::fs::read(test_data::test_data(DUMP, "vendor_excerpts").unwrap()).unwrap(),
    );
    let access = |i: u16| dump.object(i).unwrap().entries[0].access;
    assert_eq!(
        access(0x60B8) & 0x40,
        0x40,
        "0x60B8 RxPDO-mappable in the dump"
    );
    assert_eq!(
        access(0x60B9) & 0x80,
        0x80,
        "0x60B9 TxPDO-mappable in the dump"
    );
    for (file, probe) in [(&leadshine, true), (&akd, false)] {
        let f = file.display().to_string();
        let (show, _) = run_ok(&["esi", "show", &f, "--objects"]);
        assert!(
            show.contains("0x60B8") == probe || show.contains("60B8") == probe,
            "{show}"
        );
        let (def, notes) = run_ok(&["drive", "from-esi", &f]);
        assert_eq!(def.contains("0x60B8:00"), probe, "{f}:\n{def}\n{notes}");
        assert_eq!(def.contains("[probe]"), probe, "{f}:\n{def}");
    }
}
