//! Independent EtherCAT masters from PyPI against `fieldprobe sim ethercat` over a veth pair
//! (issue 26 item 3): KickCAT (`kickcat` 2.5, the C++ master's Python bindings), SOEM (`pysoem`
//! 1.1.13) and ebpfcat (1.0.0, its plain-Python path: the XDP path needs bpf(), refused in the
//! test's user namespace, see [`check_ebpfcat`]) each drive one emulated segment holding our
//! coupler, servo and encoder terminal (`esi/`) and one CiA 402 device of every vendor ESI file
//! in `../shared/test-data/esi` that has one (the first whose default mapping a master can move
//! with, else the first). Scripts: `tests/masters/*_drive.py`. SOEM's deeper run on our own
//! segment is `tests/system/pysoem_interop.rs`.
//!
//! Per master: scan (count, identities), SDO read / write (0x1008 = the ESI default, an
//! expedited 0x6060 write read back), complete access up and down of 0x1C12 / 0x1C13 where the
//! ESI declares it, SDO Information, the image sizes, OP (with DC and SYNC0 on every drive for
//! SOEM; KickCAT 2.5's bindings and ebpfcat's plain path set up no DC), the CiA 402 enable and a
//! CSP ramp through the process image on every drive, and on every drive with a touch probe
//! 0x60B8 = 0x0011, the ramp across the probe surface, 0x60B9 bits 0/1 and 0x60BA = the
//! surface (`--probe-at POS=MM`) in increments computed here. Not moved (scan and SDO only):
//! devices whose default PDOs carry no 0x6040 / 0x607A / 0x6041 / 0x6064 (AX2000-B110, the
//! modular EJ7211 whose servo objects are 0x7010 ff., Eyou whose ESI has no default PDO
//! elements).
//!
//! What a master must find is computed here from the ESI XML with roxmltree (independently of
//! `fieldprobe::esi`): identities, default PDO assignment and mapping, the names SDO
//! Information must give, the device name 0x1008 (`DefaultString` / `DefaultData`), which
//! devices have a touch probe; the probe surfaces in increments from `--probe-at POS=MM` and
//! the `[scaling]` of `drives/cia402-generic.toml` (the drive every CiA 402 device of the
//! emulator runs, `fieldprobe sim --help`), read with toml_edit.
//!
//! Steps: `scripts/masters-venv.sh` builds the venv (a failure is a test failure: CI has PyPI);
//! the test re-executes itself in a fresh unprivileged user + network namespace
//! (`unshare -rn`), makes the veth pair v0/v1 and runs the masters on v0 one after the other,
//! each against a freshly started emulator on v1. `FIELDPROBE_MASTERS=kickcat,pysoem,ebpfcat`
//! picks masters (default: all). Only a machine without user namespaces or veth SKIPs. Every wait
//! is bounded; the emulator is killed and the pair deleted on the way out.

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::{Duration, Instant},
};

use serde_json::{json, Value};

use crate::common::esi_xml;
use crate::common::test_data;
use crate::common::veth;
use esi_xml::esi_number;
use veth::netns::{manifest_path, run_bounded};
use veth::{VethPair, EMULATOR_IF, MASTER_IF};

const INNER_ENV: &str = "FIELDPROBE_MASTERS_INNER_PYTHON";
const TEST_NAME: &str = "independent_masters_drive_emulated_segment";
const VENV_TIMEOUT: Duration = Duration::from_secs(10 * 60);
const OUTER_TIMEOUT: Duration = Duration::from_secs(150);
const SCRIPT_TIMEOUT: Duration = Duration::from_secs(60);
const EMULATOR_SECONDS: &str = "120";
/// The drive file the emulator runs behind every CiA 402 device without `--drive`.
const DRIVE: &str = "drives/cia402-generic.toml";
/// Probe surfaces (mm) and the ramp that crosses them (mm), on every touch-probe device.
const PROBE_MM: f64 = 2.3456;
const RAMP_MM: (f64, f64) = (1.0, 4.0);
/// Target step per cycle, increments (0.02 mm at 10000 increments/mm).
const STEP_INC: i64 = 200;

/// A device of an ESI file as the file writes it (what a master must find).
#[derive(Debug, Clone)]
struct Device {
    /// `--device` argument: FILE or FILE#@N.
    arg: String,
    vendor: u32,
    product: u32,
    revision: u32,
    type_name: String,
    coe: bool,
    sdo_info: bool,
    complete_access: bool,
    device_name: Option<String>,
    /// 0x1008 / 0x1009 / 0x100A defaults (`DefaultString`, or `DefaultData` as text).
    strings: BTreeMap<String, String>,
    object_names: BTreeMap<String, String>,
    rx: Vec<(u16, u8, u32)>,
    tx: Vec<(u16, u8, u32)>,
    rx_pdos: Vec<u16>,
    tx_pdos: Vec<u16>,
    touch_probe: bool,
    /// The dictionary has 0x6072 (max torque).
    max_torque_object: bool,
    /// A process-data sync manager whose `ControlByte` has the mailbox operation mode (bits
    /// 1:0 = 10, one-buffer mode; AX2000-B110's Inputs 0x22): ebpfcat 1.0.0 tells sync managers
    /// apart by that byte alone (`Terminal.parse_sync_managers`) and takes it for a mailbox.
    one_buffer_process_data: bool,
}

impl Device {
    /// A CiA 402 drive the masters can move: controlword, target, statusword and actual
    /// position in the default mapping.
    fn drive(&self) -> bool {
        let has = |m: &[(u16, u8, u32)], i| m.iter().any(|e| e.0 == i);
        has(&self.rx, 0x6040)
            && has(&self.rx, 0x607A)
            && has(&self.tx, 0x6041)
            && has(&self.tx, 0x6064)
    }
}

fn kid<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(tag))
}

fn text<'a>(n: Option<roxmltree::Node<'a, '_>>) -> &'a str {
    n.and_then(|n| n.text()).unwrap_or("").trim()
}

fn flag(n: Option<roxmltree::Node>, attr: &str) -> bool {
    n.and_then(|n| n.attribute(attr))
        .is_some_and(|v| v == "1" || v.eq_ignore_ascii_case("true"))
}

fn hex_bytes(s: &str) -> Vec<u8> {
    let s: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    (0..s.len() / 2)
        .map(|k| u8::from_str_radix(&s[2 * k..2 * k + 2], 16).expect("hexBinary"))
        .collect()
}

/// The default PDOs of a direction (`RxPdo` / `TxPdo` with an `Sm` attribute): their indices and
/// entries (index, sub-index, bits) in order.
fn default_pdos(d: roxmltree::Node, tag: &str) -> (Vec<u16>, Vec<(u16, u8, u32)>) {
    let mut pdos = Vec::new();
    let mut entries = Vec::new();
    for p in d
        .children()
        .filter(|c| c.has_tag_name(tag) && c.attribute("Sm").is_some())
    {
        pdos.push(esi_number(text(kid(p, "Index"))) as u16);
        for e in p.children().filter(|c| c.has_tag_name("Entry")) {
            let index = esi_number(text(kid(e, "Index"))) as u16;
            let sub = kid(e, "SubIndex").map_or(0, |s| esi_number(text(Some(s))) as u8);
            entries.push((index, sub, esi_number(text(kid(e, "BitLen")))));
        }
    }
    (pdos, entries)
}

/// Every device of an ESI file (position 1-based), as [`Device`]s.
fn file_devices(path: &Path, with_selector: bool) -> Vec<(Device, Vec<u32>)> {
    let raw = std::fs::read(path).expect("read ESI");
    let all = String::from_utf8_lossy(&raw);
    let doc = roxmltree::Document::parse(all.trim_start_matches('\u{feff}')).expect("ESI XML");
    let root = doc.root_element();
    let vendor = esi_number(text(kid(root, "Vendor").and_then(|v| kid(v, "Id"))));
    let mut out = Vec::new();
    for (k, d) in root
        .descendants()
        .filter(|n| n.has_tag_name("Device") && kid(*n, "Type").is_some())
        .enumerate()
    {
        let ty = kid(d, "Type").expect("Type");
        let coe_node = kid(d, "Mailbox").and_then(|m| kid(m, "CoE"));
        let objects: Vec<roxmltree::Node> = d
            .descendants()
            .filter(|n| n.has_tag_name("Object") && kid(*n, "Index").is_some())
            .collect();
        let object = |index: u32| {
            objects
                .iter()
                .copied()
                .find(|o| esi_number(text(kid(*o, "Index"))) == index)
        };
        let string_default = |index: u32| {
            object(index).and_then(|o| {
                let info = kid(o, "Info")?;
                if let Some(s) = kid(info, "DefaultString") {
                    return Some(text(Some(s)).to_string());
                }
                kid(info, "DefaultData").map(|h| {
                    String::from_utf8_lossy(&hex_bytes(text(Some(h))))
                        .trim_end_matches('\0')
                        .to_string()
                })
            })
        };
        let mut strings = BTreeMap::new();
        for index in [0x1008u32, 0x1009, 0x100A] {
            if let Some(v) = string_default(index) {
                strings.insert(format!("{index:#06x}"), v);
            }
        }
        let device_name = object(0x1008).and_then(|o| {
            let info = kid(o, "Info")?;
            if let Some(s) = kid(info, "DefaultString") {
                return Some(text(Some(s)).to_string());
            }
            kid(info, "DefaultData").map(|h| {
                String::from_utf8_lossy(&hex_bytes(text(Some(h))))
                    .trim_end_matches('\0')
                    .to_string()
            })
        });
        let mut object_names = BTreeMap::new();
        for index in [0x1018u32, 0x6041] {
            if let Some(o) = object(index) {
                object_names.insert(format!("{index:#06x}"), text(kid(o, "Name")).to_string());
            }
        }
        let (rx_pdos, rx) = default_pdos(d, "RxPdo");
        let (tx_pdos, tx) = default_pdos(d, "TxPdo");
        let profiles: Vec<u32> = d
            .children()
            .filter(|c| c.has_tag_name("Profile"))
            .flat_map(|p| p.descendants().filter(|c| c.has_tag_name("ProfileNo")))
            .map(|n| esi_number(text(Some(n))))
            .collect();
        let arg = if with_selector {
            format!("{}#@{}", path.display(), k + 1)
        } else {
            path.display().to_string()
        };
        out.push((
            Device {
                arg,
                vendor,
                product: esi_number(ty.attribute("ProductCode").unwrap_or("0")),
                revision: ty.attribute("RevisionNo").map_or(0, esi_number),
                type_name: text(Some(ty)).to_string(),
                coe: coe_node.is_some(),
                sdo_info: flag(coe_node, "SdoInfo"),
                complete_access: flag(coe_node, "CompleteAccess"),
                device_name,
                strings,
                object_names,
                rx,
                tx,
                rx_pdos,
                tx_pdos,
                max_torque_object: object(0x6072).is_some(),
                one_buffer_process_data: d.children().any(|sm| {
                    sm.has_tag_name("Sm")
                        && matches!(text(Some(sm)), "Inputs" | "Outputs")
                        && sm
                            .attribute("ControlByte")
                            .is_some_and(|c| esi_number(c) & 0x03 == 0x02)
                }),
                touch_probe: object(0x60B8).is_some()
                    && object(0x60B9).is_some()
                    && object(0x60BA).is_some(),
            },
            profiles,
        ));
    }
    out
}

/// Our segment (coupler, servo, encoder and timestamp terminals) and, from every vendor file
/// with one, the first CiA 402 drive the masters can move (else its first CiA 402 device).
fn segment() -> Vec<Device> {
    let mut seg: Vec<Device> = [
        "esi/fieldprobe-ek1100.xml",
        "esi/fieldprobe-cia402-servo.xml",
        "esi/fieldprobe-el5101.xml",
    ]
    .iter()
    .map(|f| file_devices(&manifest_path(f), false).remove(0).0)
    .collect();
    let dir = manifest_path("../shared/test-data/esi");
    if !dir.is_dir() {
        test_data::test_data("esi", TEST_NAME);
        return seg;
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("read the ESI folder")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml")))
        .collect();
    files.sort();
    for f in files {
        let cia: Vec<Device> = file_devices(&f, true)
            .into_iter()
            .filter(|(_, p)| p.contains(&402))
            .map(|(d, _)| d)
            .collect();
        if let Some(d) = cia.iter().find(|d| d.drive()).or(cia.first()) {
            seg.push(d.clone());
        }
    }
    seg
}

/// mm → increments with the drive file's `[scaling]` (toml_edit, independently of
/// `fieldprobe::drive`).
fn increments(mm: f64) -> i64 {
    let text = std::fs::read_to_string(manifest_path(DRIVE)).expect("read drive file");
    let doc: toml_edit::DocumentMut = text.parse().expect("parse drive file");
    let num = |key: &str| -> f64 {
        let v = &doc["scaling"][key];
        v.as_float()
            .or_else(|| v.as_integer().map(|i| i as f64))
            .expect("scaling number")
    };
    ((mm - num("offset")) * num("increments_per_unit")).round() as i64
}

fn venv() -> PathBuf {
    let dir = std::env::var_os("MASTERS_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_path("target/masters-venv"));
    veth::netns::build_venv(
        "scripts/masters-venv.sh",
        &dir,
        VENV_TIMEOUT,
        "kickcat / ebpfcat could not be installed from PyPI, this is a failure, not a skip",
    )
}

#[test]
fn independent_masters_drive_emulated_segment() {
    let _one_module = crate::gate::enter(module_path!());
    if let Some(python) = veth::inner_env(INNER_ENV) {
        inner(Path::new(&python));
        return;
    }
    veth::run_in_veth_namespace(TEST_NAME, INNER_ENV, OUTER_TIMEOUT, || {
        venv().into_os_string()
    });
}

fn step<'a>(result: &'a Value, name: &str) -> Vec<&'a Value> {
    result["steps"]
        .as_array()
        .map(|s| s.iter().filter(|s| s["step"] == name).collect())
        .unwrap_or_default()
}

/// Run `script IFACE SPEC` with the venv's python; its `PREFIX {json}` line.
fn run_master(python: &Path, script: &str, spec: &Value, prefix: &str) -> (Value, String) {
    let t0 = Instant::now();
    let (status, out, err) = run_bounded(
        Command::new(python)
            .stdin(Stdio::null())
            .arg(manifest_path(script))
            .arg(MASTER_IF)
            .arg(spec.to_string()),
        SCRIPT_TIMEOUT,
    );
    println!(
        "{script} ({:?}) stdout:\n{out}\nstderr:\n{err}",
        t0.elapsed()
    );
    let status =
        status.unwrap_or_else(|| panic!("{script} did not finish within {SCRIPT_TIMEOUT:?}"));
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("{script} printed no {prefix}line ({status}):\n{err}"));
    let v: Value = serde_json::from_str(line).expect("result JSON");
    (v, format!("{status}"))
}

fn inner(python: &Path) {
    let t0 = Instant::now();
    let _pair = VethPair::create();
    let seg = segment();
    let probe_inc = increments(PROBE_MM);
    let mut emu_args: Vec<String> = vec![
        "sim".into(),
        "ethercat".into(),
        "--iface".into(),
        EMULATOR_IF.into(),
        "--seconds".into(),
        EMULATOR_SECONDS.into(),
    ];
    for (pos, d) in seg.iter().enumerate() {
        emu_args.push("--device".into());
        emu_args.push(d.arg.clone());
        if d.touch_probe && d.drive() {
            emu_args.push("--probe-at".into());
            emu_args.push(format!("{pos}={PROBE_MM}"));
        }
    }
    let spec = json!({
        "devices": seg.iter().enumerate().map(|(pos, d)| json!({
            "pos": pos, "file": d.arg, "vendor": d.vendor, "product": d.product,
            "revision": d.revision, "type": d.type_name, "coe": d.coe, "sdo_info": d.sdo_info,
            "complete_access": d.complete_access, "device_name": d.device_name,
            "strings": d.strings,
            "object_names": d.object_names,
            "rx": d.rx, "tx": d.tx, "rx_pdos": d.rx_pdos, "tx_pdos": d.tx_pdos,
            "drive": d.drive(), "touch_probe": d.touch_probe && d.drive(),
            "pdo_elements": !(d.rx_pdos.is_empty() && d.tx_pdos.is_empty()),
            "max_torque_object": d.max_torque_object,
            "one_buffer_process_data": d.one_buffer_process_data,
            "probe_inc": probe_inc, "start_inc": increments(RAMP_MM.0),
            "end_inc": increments(RAMP_MM.1),
        })).collect::<Vec<_>>(),
        "step_inc": STEP_INC,
    });
    for (pos, d) in seg.iter().enumerate() {
        println!(
            "ring {pos}: {} {:#x}/{:#x}/{:#x} drive {} touch probe {} CA {}",
            d.arg,
            d.vendor,
            d.product,
            d.revision,
            d.drive(),
            d.touch_probe,
            d.complete_access
        );
    }
    // Each master meets a freshly started segment (as after power-on): what one master left
    // configured (SYNC0, sync managers, mailbox counters) does not reach the next.
    let only = std::env::var("FIELDPROBE_MASTERS").unwrap_or_default();
    let wanted = |m: &str| only.is_empty() || only.split(',').any(|o| o == m);
    let mut times = Vec::new();

    // KickCAT. A run that failed because KickCAT gave up on a late frame (a RuntimeError from
    // its C++ core, not a failed check) is repeated once: see LINK_TIMEOUT_S in the script.
    if wanted("kickcat") {
        let t = Instant::now();
        let (emu, log) = start(&emu_args);
        let mut k = Value::Null;
        for attempt in 0..2 {
            let (r, status) = run_master(
                python,
                "tests/masters/kickcat_drive.py",
                &spec,
                "KICKCAT_RESULT ",
            );
            k = r;
            let late = k["error"]
                .as_str()
                .is_some_and(|e| e.starts_with("RuntimeError"));
            if k["ok"] == true || !late || attempt == 1 {
                assert_eq!(
                    k["ok"],
                    true,
                    "kickcat ({status}): {}\n{}",
                    k["error"],
                    k["trace"].as_str().unwrap_or("")
                );
                break;
            }
            println!(
                "KickCAT gave up on a late frame ({}), run again",
                k["error"]
            );
        }
        check_kickcat(&k, &seg, probe_inc);
        drop(emu);
        println!(
            "emulator log (KickCAT): {:#?}",
            log.join().unwrap_or_default()
        );
        times.push(format!(
            "KickCAT {:?} ({} cycles)",
            t.elapsed(),
            k["cycles"]
        ));
    }

    // SOEM (pysoem).
    if wanted("pysoem") {
        let t = Instant::now();
        let (emu, log) = start(&emu_args);
        let (p, status) = run_master(
            python,
            "tests/masters/pysoem_drive.py",
            &spec,
            "PYSOEM_RESULT ",
        );
        assert_eq!(
            p["ok"],
            true,
            "pysoem ({status}): {}\n{}",
            p["error"],
            p["trace"].as_str().unwrap_or("")
        );
        check_pysoem(&p, &seg, probe_inc);
        drop(emu);
        let log = log.join().unwrap_or_default();
        // SOEM activated SYNC0 on every drive (config_dc + dc_sync): the emulator says so.
        for (p, d) in seg.iter().enumerate().filter(|(_, d)| d.drive()) {
            assert!(
                log.iter()
                    .any(|l| l.contains(&format!("device {p} ("))
                        && l.contains("SYNC0 every 1.000 ms")),
                "no SYNC0 activation of ring {p} ({}) in the emulator log {log:#?}",
                d.arg
            );
        }
        times.push(format!("pysoem {:?} ({} cycles)", t.elapsed(), p["cycles"]));
    }

    // ebpfcat, plain-Python path (see `tests/masters/ebpfcat_drive.py` for why not XDP).
    if wanted("ebpfcat") {
        let t = Instant::now();
        let (emu, log) = start(&emu_args);
        let (e, status) = run_master(
            python,
            "tests/masters/ebpfcat_drive.py",
            &spec,
            "EBPFCAT_RESULT ",
        );
        assert_eq!(
            e["ok"],
            true,
            "ebpfcat ({status}): {}\n{}",
            e["error"],
            e["trace"].as_str().unwrap_or("")
        );
        check_ebpfcat(&e, &seg, probe_inc);
        drop(emu);
        let _ = log.join();
        times.push(format!("ebpfcat {:?}", t.elapsed()));
    }
    println!(
        "MASTERS {} devices: {}; total {:?}",
        seg.len(),
        times.join(", "),
        t0.elapsed()
    );
    println!("INNER OK");
}

/// The record KickCAT's script made agrees with the ESI (the script checked each value; the
/// test checks the record says so, and recomputes the latch comparison).
fn check_kickcat(k: &Value, seg: &[Device], probe_inc: i64) {
    let scan = &step(k, "scan")[0];
    assert_eq!(scan["devices"], seg.len());
    let coe = seg.iter().filter(|d| d.coe).count();
    assert_eq!(
        scan["identities"].as_array().map(Vec::len),
        Some(coe),
        "{scan}"
    );
    let sdo = step(k, "sdo");
    assert_eq!(sdo.len(), coe);
    for s in &sdo {
        let pos = s["pos"].as_u64().expect("pos") as usize;
        let d = &seg[pos];
        if let Some(n) = &d.device_name {
            assert_eq!(s["device_name"], n.as_str(), "{s}");
        }
        // Where the ESI declares no complete access the emulator refuses it (unit tests in
        // `sim::esc::coe`); KickCAT is not asked for it there.
        if d.complete_access {
            assert!(s["ca_1c12"].is_string() && s["ca_1c13"].is_string(), "{s}");
        }
    }
    let sizes = step(k, "mapping")[0]["sizes"].clone();
    for (pos, d) in seg.iter().enumerate() {
        // A device whose ESI has no default PDO elements keeps its defaults in the dictionary.
        if d.rx_pdos.is_empty() && d.tx_pdos.is_empty() {
            continue;
        }
        let want = [
            d.rx.iter().map(|e| e.2).sum::<u32>() / 8,
            d.tx.iter().map(|e| e.2).sum::<u32>() / 8,
        ];
        assert_eq!(sizes[pos], json!(want), "ring {pos} image sizes");
    }
    let drives: Vec<usize> = (0..seg.len()).filter(|&p| seg[p].drive()).collect();
    let csp = &step(k, "csp")[0]["actual"];
    for p in &drives {
        let a = csp[p.to_string()].as_i64().expect("actual");
        assert!(
            (a - increments(RAMP_MM.1)).abs() <= 1,
            "ring {p}: 0x6064 {a}"
        );
    }
    let latches = &step(k, "touch_probe")[0]["latches"];
    let probes: Vec<usize> = drives
        .iter()
        .copied()
        .filter(|&p| seg[p].touch_probe)
        .collect();
    assert!(!probes.is_empty(), "no touch-probe device in the segment");
    for p in probes {
        let l = &latches[p.to_string()];
        let got = l["tp1_pos"]
            .as_i64()
            .unwrap_or_else(|| panic!("ring {p}: no latch in {latches}"));
        // The surface in increments is a rounded conversion of PROBE_MM: ±1 increment.
        assert!(
            (got - probe_inc).abs() <= 1,
            "ring {p}: 0x60BA {got}, surface at {probe_inc} increments"
        );
        println!(
            "KICKCAT ring {p}: 0x60B9 {} 0x60BA {got} via {} (surface {probe_inc})",
            l["status"], l["via"]
        );
    }
}

/// SOEM's record: identities, SDO, image sizes, DC with SYNC0 on the drives, CSP, latches.
fn check_pysoem(r: &Value, seg: &[Device], probe_inc: i64) {
    assert_eq!(step(r, "scan")[0]["devices"], seg.len());
    let sdo = step(r, "sdo");
    assert_eq!(sdo.len(), seg.iter().filter(|d| d.coe).count());
    for s in &sdo {
        let d = &seg[s["pos"].as_u64().expect("pos") as usize];
        if let Some(n) = &d.device_name {
            assert_eq!(s["device_name"], n.as_str(), "{s}");
        }
    }
    // Our servo's ESI gives 0x1008, 0x1009 and 0x100A defaults: SOEM read all three.
    let servo = sdo.iter().find(|s| s["pos"] == 1).expect("servo SDO step");
    for idx in ["0x1008", "0x1009", "0x100a"] {
        assert_eq!(servo["strings"][idx], json!(seg[1].strings[idx]), "{servo}");
    }
    let dc = &step(r, "dc")[0];
    assert_eq!(dc["dc"], true, "SOEM found no DC device: {dc}");
    println!(
        "PYSOEM SYNC0 (1 ms) activated on ring positions {}",
        dc["sync0"]
    );
    let csp = &step(r, "csp")[0]["actual"];
    let latches = &step(r, "touch_probe")[0]["latches"];
    for (p, d) in seg.iter().enumerate() {
        if !d.drive() {
            continue;
        }
        let a = csp[p.to_string()].as_i64().expect("actual");
        assert!(
            (a - increments(RAMP_MM.1)).abs() <= 1,
            "ring {p}: 0x6064 {a}"
        );
        if d.touch_probe {
            let got = latches[p.to_string()]["tp1_pos"].as_i64().expect("latch");
            assert!(
                (got - probe_inc).abs() <= 1,
                "ring {p}: 0x60BA {got}, surface {probe_inc}"
            );
            println!("PYSOEM ring {p}: 0x60BA {got} (surface {probe_inc})");
        }
    }
}

/// ebpfcat's record: the scan, SDO on every CoE device, the CSP ramp and the latches.
fn check_ebpfcat(e: &Value, seg: &[Device], probe_inc: i64) {
    assert_eq!(step(e, "scan")[0]["devices"], seg.len());
    // ebpfcat's XDP path (FastEtherCat / FastSyncGroup) loads an eBPF program: bpf() needs
    // CAP_BPF / CAP_SYS_ADMIN in the initial user namespace, which a process in the test's
    // unprivileged user namespace lacks (EPERM = 1; `kernel.unprivileged_bpf_disabled` is 2 on
    // the CI machine). The plain-Python path above ran; the XDP path is skipped for that reason.
    match e["bpf_errno"].as_i64() {
        Some(1) => println!(
            "SKIP ebpfcat XDP path (FastEtherCat/FastSyncGroup): bpf(BPF_MAP_CREATE) = EPERM in \
             the unprivileged user namespace (needs CAP_BPF in the initial namespace)"
        ),
        other => println!("ebpfcat: bpf() allowed here (errno {other:?}); XDP path not exercised"),
    }
    let sdo = step(e, "sdo");
    let reachable = seg
        .iter()
        .filter(|d| d.coe && !d.one_buffer_process_data)
        .count();
    assert_eq!(sdo.len(), reachable);
    for (p, d) in seg.iter().enumerate() {
        if d.coe && d.one_buffer_process_data {
            println!("EBPFCAT ring {p}: mailbox not used (one-buffer process-data SM, see Device)");
        }
    }
    for s in &sdo {
        let d = &seg[s["pos"].as_u64().expect("pos") as usize];
        assert_eq!(
            s["identity"],
            json!([d.vendor, d.product, d.revision]),
            "{s}"
        );
        if let Some(n) = &d.device_name {
            assert_eq!(s["device_name"], n.as_str(), "{s}");
        }
    }
    let csp = &step(e, "csp")[0]["actual"];
    for (p, d) in seg.iter().enumerate() {
        if d.drive() {
            let a = csp[p.to_string()].as_i64().expect("actual");
            assert!(
                (a - increments(RAMP_MM.1)).abs() <= 1,
                "ring {p}: 0x6064 {a}"
            );
        }
    }
    let latches = &step(e, "touch_probe")[0]["latches"];
    for (p, d) in seg.iter().enumerate() {
        if d.drive() && d.touch_probe {
            let got = latches[p.to_string()]["tp1_pos"].as_i64().expect("latch");
            assert!(
                (got - probe_inc).abs() <= 1,
                "ring {p}: 0x60BA {got}, surface {probe_inc}"
            );
            println!("EBPFCAT ring {p}: 0x60BA {got} (surface {probe_inc})");
        }
    }
}

/// Start the emulator with `args`; waits (10 s at most) for its "listening on" line.
fn start(args: &[String]) -> (veth::Emulator, std::thread::JoinHandle<Vec<String>>) {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn fieldprobe sim ethercat");
    let stderr = child.stderr.take().expect("stderr");
    let emu = veth::Emulator(child);
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let log = std::thread::spawn(move || {
        let mut all = Vec::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line.clone());
            all.push(line);
        }
        all
    });
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            Ok(l) if l.contains("listening on") => break,
            Ok(_) => {}
            Err(e) => {
                drop(emu);
                panic!("emulator not ready within 10 s: {e}; log {:?}", log.join());
            }
        }
    }
    (emu, log)
}
