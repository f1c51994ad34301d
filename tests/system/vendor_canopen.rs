//! Vendor CiA 402 nodes on CANopen (issue 19, the CANopen half): the real Technosoft iPOS EDS
//! (with touch probe 0x60B8–0x60BD) and python-canopen's e35.eds (without) from
//! `../shared/test-data/eds/`.
//!
//! 1. The emulated Technosoft node (`EmulatedNode::from_eds`, what `sim canopen --eds` serves)
//!    refuses PDO remaps with the CiA 301 abort codes: raw SDO frames built here, expected
//!    codes from the EDS text read here (a non-mappable object 0x06040041, an object the EDS
//!    lacks 0x06020000, an entry while sub-index 0 ≠ 0 or while the PDO exists 0x06090030, more
//!    than 64 bits 0x06040042, above `HighLimit` 0x06090031, a read-only object 0x06010002);
//!    a remap of mappable objects is taken and served after NMT start.
//! 2. Our master fits the mapping to the node: e35 nodes (no touch probe) run the default
//!    drive with warning 900504 and a definition without touch-probe objects; a Technosoft EDS
//!    whose 0x607A is not mappable refuses the start-up with error 900505 naming it.
//! 3. `drive from-eds` of the Technosoft EDS gives a definition with which `run
//!    examples/nc/hello.nc` prints on `canopen-emu` what it prints on `--link sim`; and across
//!    processes against `fieldprobe sim canopen --eds` over `canopen-udp` (in a private network
//!    namespace, as tests/system/canopen_udp_run.rs): the same output, `can scan` and `sdos --node N
//!    --eds` show the identity and dictionary the EDS gives (read here with a minimal INI
//!    lookup), and `sdo write` of a non-mappable object into RPDO1 is refused with 0x06040041.
//!
//! Without the test data: SKIP (FIELDPROBE_REQUIRE_TEST_DATA=1 makes it a failure); without
//! namespaces the cross-process part SKIPs. Every wait is bounded.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::time::Duration;

use fieldprobe::bus::can::CanFrame;
use fieldprobe::bus::canopen::eds;
use fieldprobe::bus::canopen::nmt::NmtCommand;
use fieldprobe::drive::catalogue::{self, DriveDefinition};
use fieldprobe::link::canopen::CanopenLink;
use fieldprobe::link::{Link, LinkError};
use fieldprobe::sim::canopen::EmulatedNode;
use fieldprobe::units::Nanos;

use crate::common::netns;
use crate::common::test_data;

const TECHNOSOFT: &str = "eds/technosoft-ipos-cia402.eds";
const E35: &str = "eds/python-canopen-e35.eds";

// ------------------------------------------------------------------------------------------
// The EDS as text (independent of fieldprobe's parser).

/// Sections of an INI text: name (upper case) → key → value.
fn ini(text: &str) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut out: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    let mut cur = String::new();
    for line in text.lines() {
        let l = line.trim();
        if l.starts_with(';') || l.is_empty() {
            continue;
        }
        if let Some(name) = l.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            cur = name.trim().to_ascii_uppercase();
            out.entry(cur.clone()).or_default();
        } else if let Some((k, v)) = l.split_once('=') {
            out.entry(cur.clone())
                .or_default()
                .insert(k.trim().to_string(), v.trim().to_string());
        }
    }
    out
}

fn num(s: &str) -> u64 {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).unwrap(),
        None => s.parse().unwrap(),
    }
}

/// One sub-index of the EDS: (index, sub) → (access, data type code, PDOMapping, name).
type Var = (String, u16, bool, String);

/// Every VAR of the EDS text (a VAR object is its sub-index 0).
fn vars(text: &str) -> BTreeMap<(u16, u8), Var> {
    let mut out = BTreeMap::new();
    for (name, keys) in ini(text) {
        let (index, sub) = match name.split_once("SUB") {
            Some((i, s)) => (i.to_string(), u8::from_str_radix(s, 16).ok()),
            None => (name.clone(), Some(0)),
        };
        let (Ok(index), Some(sub)) = (u16::from_str_radix(&index, 16), sub) else {
            continue;
        };
        if index == 0 || keys.get("ObjectType").map(|t| num(t)).unwrap_or(7) != 7 {
            continue;
        }
        let (Some(access), Some(ty)) = (keys.get("AccessType"), keys.get("DataType")) else {
            continue;
        };
        out.insert(
            (index, sub),
            (
                access.to_ascii_lowercase(),
                num(ty) as u16,
                keys.get("PDOMapping").is_some_and(|m| num(m) == 1),
                keys.get("ParameterName").cloned().unwrap_or_default(),
            ),
        );
    }
    out
}

fn read_test_data(rel: &str, test: &str) -> Option<String> {
    let p = test_data::test_data(rel, test)?;
    Some(String::from_utf8_lossy(&std::fs::read(p).unwrap()).into_owned())
}

fn generic() -> Arc<DriveDefinition> {
    Arc::new(catalogue::load("cia402-generic").unwrap())
}

// ------------------------------------------------------------------------------------------
// 1. Remap rules of the emulated Technosoft node, by raw SDO frames.

const NODE: u8 = 5;

/// An expedited SDO download of `data` (1 … 4 bytes) to `index:sub` of `node`: `Ok` or the
/// abort code (CiA 301 §7.2.4.3.3: 0x23 | (4 − n) << 2, response 0x60, abort 0x80).
fn download(node: &mut EmulatedNode, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
    let mut req = [0u8; 8];
    req[0] = 0x23 | ((4 - data.len() as u8) << 2);
    req[1..3].copy_from_slice(&index.to_le_bytes());
    req[3] = sub;
    req[4..4 + data.len()].copy_from_slice(data);
    let f = CanFrame::new(0x600 + u16::from(NODE), &req).unwrap();
    node.handle(&f, Nanos(1_000_000));
    let out = node.take_outgoing();
    let r = out
        .iter()
        .find(|f| f.id == 0x580 + u32::from(NODE))
        .unwrap_or_else(|| panic!("no SDO answer to {index:#06x}:{sub}: {out:?}"));
    match r.data[0] {
        0x60 => Ok(()),
        0x80 => Err(u32::from_le_bytes([
            r.data[4], r.data[5], r.data[6], r.data[7],
        ])),
        c => panic!("answer {c:#04x} to {index:#06x}:{sub}"),
    }
}

fn u32le(v: u32) -> Vec<u8> {
    v.to_le_bytes().to_vec()
}

/// Mapping value of an EDS VAR (index << 16 | sub << 8 | bits of its data type).
fn mapping(index: u16, sub: u8, code: u16) -> u32 {
    let bits = match code {
        0x2 | 0x5 => 8,
        0x3 | 0x6 => 16,
        0x4 | 0x7 => 32,
        c => panic!("data type {c:#x} not used here"),
    };
    u32::from(index) << 16 | u32::from(sub) << 8 | bits
}

#[test]
fn emulated_technosoft_node_refuses_remaps_with_the_cia301_abort_codes() {
    let _one_module = crate::gate::enter(module_path!());
    let name = "emulated_technosoft_node_refuses_remaps_with_the_cia301_abort_codes";
    let Some(text) = read_test_data(TECHNOSOFT, name) else {
        return;
    };
    let vars = vars(&text);
    let sections = ini(&text);
    // From the file: a read-write CiA 402 VAR of 16 bits that is not PDO-mappable, one the
    // file marks mappable for the master (rww), a read-only mappable one (a TPDO object), a
    // CiA 402 object the file lacks, and RPDO1's mapping limits.
    let not_mappable = vars
        .iter()
        .find(|((i, s), v)| *i >= 0x6000 && *s == 0 && v.0 == "rw" && !v.2 && v.1 == 0x3)
        .map(|(k, v)| mapping(k.0, k.1, v.1))
        .expect("a non-mappable INTEGER16 rw object");
    let rww = |index: u16| {
        let v = &vars[&(index, 0)];
        assert!(v.2 && v.0 == "rww", "{index:#x}: {v:?}");
        mapping(index, 0, v.1)
    };
    let (controlword, target) = (rww(0x6040), rww(0x607A));
    let statusword = {
        let v = &vars[&(0x6041, 0)];
        assert!(v.2 && v.0 == "ro");
        mapping(0x6041, 0, v.1)
    };
    assert!(!sections.contains_key("6072"), "0x6072 is not in this EDS");
    let absent = 0x6072_0010;
    let high = num(&sections["1600SUB0"]["HighLimit"]) as u8;
    let cob = 0x200 + u32::from(NODE);

    let def = generic();
    let parsed = eds::parse(&text, "ipos.eds").unwrap();
    let mut n = EmulatedNode::from_eds(NODE, &def, &parsed).unwrap();
    n.poll(Nanos(0)); // boot-up → pre-operational
    n.take_outgoing();
    assert!(n.has_touch_probe(), "the iPOS EDS has 0x60B8 / 0x60B9");

    // The PDO exists (the EDS default: 0x1400:01 = $NODEID + 0x200): no mapping change.
    assert_eq!(download(&mut n, 0x1600, 0, &[0]), Err(0x0609_0030));
    // Destroy it; sub-index 0 is still the EDS default (1): no entry may change.
    download(&mut n, 0x1400, 1, &u32le(cob | 0x8000_0000)).unwrap();
    assert_eq!(
        download(&mut n, 0x1600, 1, &u32le(controlword)),
        Err(0x0609_0030)
    );
    download(&mut n, 0x1600, 0, &[0]).unwrap();
    // Entries: not mappable, not in the dictionary, a TPDO object into an RPDO.
    assert_eq!(
        download(&mut n, 0x1600, 1, &u32le(not_mappable)),
        Err(0x0604_0041),
        "{not_mappable:#010x}"
    );
    assert_eq!(
        download(&mut n, 0x1600, 1, &u32le(absent)),
        Err(0x0602_0000)
    );
    assert_eq!(
        download(&mut n, 0x1600, 1, &u32le(statusword)),
        Err(0x0604_0041)
    );
    // A mappable object with the wrong length.
    assert_eq!(
        download(&mut n, 0x1600, 1, &u32le(controlword & !0xFF | 32)),
        Err(0x0604_0041)
    );
    // Three 32-bit objects: 96 bits do not fit a CAN frame.
    for (k, v) in [target, target, target].iter().enumerate() {
        download(&mut n, 0x1600, k as u8 + 1, &u32le(*v)).unwrap();
    }
    assert_eq!(download(&mut n, 0x1600, 0, &[3]), Err(0x0604_0042));
    // Above the EDS's HighLimit of sub-index 0.
    assert_eq!(download(&mut n, 0x1600, 0, &[high + 1]), Err(0x0609_0031));
    // A read-only object.
    assert_eq!(download(&mut n, 0x6041, 0, &[0, 0]), Err(0x0601_0002));
    // A mapping the file allows: controlword + target position, then the PDO again; the
    // identifier of an existing PDO cannot change.
    download(&mut n, 0x1600, 1, &u32le(controlword)).unwrap();
    download(&mut n, 0x1600, 2, &u32le(target)).unwrap();
    download(&mut n, 0x1600, 0, &[2]).unwrap();
    download(&mut n, 0x1400, 2, &[1]).unwrap();
    assert_eq!(download(&mut n, 0x1400, 2, &[245]), Err(0x0609_0030));
    download(&mut n, 0x1400, 1, &u32le(cob)).unwrap();
    assert_eq!(
        download(&mut n, 0x1400, 1, &u32le(cob + 1)),
        Err(0x0609_0030)
    );
    // NMT start takes it: the node is operational.
    let start = NmtCommand::Start.frame(NODE);
    n.handle(&start, Nanos(2_000_000));
    assert_eq!(
        n.state(),
        fieldprobe::bus::canopen::nmt::NmtState::Operational,
        "{:?}",
        n.take_outgoing()
    );
}

// ------------------------------------------------------------------------------------------
// 2. The master fits the mapping to the node.

#[test]
fn e35_nodes_without_touch_probe_run_with_warning_900504_and_no_drive_latch() {
    let _one_module = crate::gate::enter(module_path!());
    let name = "e35_nodes_without_touch_probe_run_with_warning_900504_and_no_drive_latch";
    let Some(text) = read_test_data(E35, name) else {
        return;
    };
    let vars = vars(&text);
    for tp in 0x60B8..=0x60BDu16 {
        assert!(!vars.contains_key(&(tp, 0)), "e35.eds has no {tp:#x}");
    }
    let parsed = eds::parse(&text, "e35.eds").unwrap();
    let def = generic();
    let nodes: Vec<EmulatedNode> = (1..=3)
        .map(|id| EmulatedNode::from_eds(id, &def, &parsed).unwrap())
        .collect();
    assert!(nodes.iter().all(|n| !n.has_touch_probe()));
    let defs = [def.clone(), def.clone(), def.clone()];
    let link = CanopenLink::with_nodes(nodes, &defs, Nanos::from_micros(4000))
        .unwrap_or_else(|e| panic!("{e}"));
    let report = link.startup_report();
    assert_eq!(report.len(), 3, "{report:?}");
    for (k, m) in report.iter().enumerate() {
        assert_eq!(m.id, 900504);
        assert_eq!(m.severity, fieldprobe::messages::Severity::Warning);
        assert!(
            m.text
                .contains(&format!("node {} has no touch probe", k + 1)),
            "{}",
            m.text
        );
        assert!(m.text.contains("0x60B8:00"), "{}", m.text);
        assert!(m.text.contains("0x06020000"), "{}", m.text);
    }
    for device in 0..3 {
        let d = link.drive_definition(device).unwrap();
        assert!(!Arc::ptr_eq(&d, &def));
        let all: Vec<u16> = d
            .rxpdo
            .entries()
            .iter()
            .chain(d.txpdo.entries())
            .map(|e| e.index)
            .collect();
        assert!(
            all.iter().all(|i| !(0x60B8..=0x60BD).contains(i)),
            "{all:x?}"
        );
        for want in [0x6040, 0x607A, 0x6041, 0x6064] {
            assert!(all.contains(&want), "{want:#x} in {all:x?}");
        }
    }
}

#[test]
fn technosoft_nodes_keep_the_touch_probe_and_no_warning() {
    let _one_module = crate::gate::enter(module_path!());
    let name = "technosoft_nodes_keep_the_touch_probe_and_no_warning";
    let Some(text) = read_test_data(TECHNOSOFT, name) else {
        return;
    };
    let parsed = eds::parse(&text, "ipos.eds").unwrap();
    let def = generic();
    let node = EmulatedNode::from_eds(1, &def, &parsed).unwrap();
    let link = CanopenLink::with_nodes(
        vec![node],
        std::slice::from_ref(&def),
        Nanos::from_micros(4000),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(link.startup_report().is_empty());
    assert!(Arc::ptr_eq(&link.drive_definition(0).unwrap(), &def));
}

#[test]
fn a_target_position_the_node_cannot_map_is_start_up_error_900505() {
    let _one_module = crate::gate::enter(module_path!());
    let name = "a_target_position_the_node_cannot_map_is_start_up_error_900505";
    let Some(text) = read_test_data(TECHNOSOFT, name) else {
        return;
    };
    // The same EDS with [607A] PDOMapping=0.
    let start = text.find("[607A]").expect("[607A]");
    let end = start + text[start..].find("\n[").expect("next section");
    let section = text[start..end].replace("PDOMapping=1", "PDOMapping=0");
    assert_ne!(section, &text[start..end]);
    let edited = format!("{}{}{}", &text[..start], section, &text[end..]);
    let parsed = eds::parse(&edited, "ipos-607a.eds").unwrap();
    let def = generic();
    let node = EmulatedNode::from_eds(4, &def, &parsed).unwrap();
    match CanopenLink::with_nodes(vec![node], &[def], Nanos::from_micros(4000)) {
        Err(LinkError::Refused(m)) => {
            assert_eq!(m.id, 900505);
            for want in [
                "node 4",
                "'cia402-generic'",
                "0x607A:00 (not mappable into an RPDO (SDO abort 0x06040041))",
            ] {
                assert!(m.text.contains(want), "{want:?} in {}", m.text);
            }
        }
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("a node that cannot map 0x607A started"),
    }
}

// ------------------------------------------------------------------------------------------
// 3. drive from-eds, hello.nc on sim / canopen-emu / sim canopen --eds in another process.

fn fieldprobe(args: &[&str]) -> (Option<i32>, String, String) {
    let (status, out, err) = netns::run_bounded(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        Duration::from_secs(120),
    );
    (status.and_then(|s| s.code()), out, err)
}

/// A machine with X, Y, Z on `drive`, 4 ms cycle at 1 Mbit/s (the bus load of the generated
/// layout: 2 RPDOs + 4 TPDOs per node).
fn machine(dir: &Path, drive: &Path) -> std::path::PathBuf {
    let mut m = String::from("[channel]\ncycle_time_us = 4000\n[can]\nbitrate = 1000000\n");
    for axis in ["X", "Y", "Z"] {
        m.push_str(&format!(
            "[[axis]]\nname = \"{axis}\"\ndrive = \"{}\"\n",
            drive.display()
        ));
    }
    let p = dir.join("machine.toml");
    std::fs::write(&p, m).unwrap();
    p
}

#[test]
fn hello_with_the_technosoft_definition_prints_what_sim_prints_on_emu_and_across_processes() {
    let _one_module = crate::gate::enter(module_path!());
    let name =
        "hello_with_the_technosoft_definition_prints_what_sim_prints_on_emu_and_across_processes";
    let Some(eds_path) = test_data::test_data(TECHNOSOFT, name) else {
        return;
    };
    let text = String::from_utf8_lossy(&std::fs::read(&eds_path).unwrap()).into_owned();
    let dir = tempfile::tempdir().unwrap();
    let drive = dir.path().join("technosoft.toml");
    let (code, _, err) = fieldprobe(&[
        "drive",
        "from-eds",
        &eds_path.display().to_string(),
        "--out",
        &drive.display().to_string(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let toml = std::fs::read_to_string(&drive).unwrap();
    assert!(
        toml.contains("\"0x60B8:00\""),
        "the iPOS has a touch probe:\n{toml}"
    );
    let machine = machine(dir.path(), &drive);
    let m = machine.display().to_string();
    let run = |link: &str| {
        fieldprobe(&[
            "run",
            "examples/nc/hello.nc",
            "--machine",
            &m,
            "--link",
            link,
        ])
    };
    let (code, sim_out, err) = run("sim");
    assert_eq!(code, Some(0), "{err}");
    // hello.nc ends where it started (X0 Y0 after the square and the full circle).
    assert!(
        sim_out.starts_with("X=0.000000 Y=0.000000 Z=0.000000\n"),
        "{sim_out}"
    );
    let (code, emu_out, err) = run("canopen-emu");
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(emu_out, sim_out, "canopen-emu vs sim; stderr {err}");
    assert!(!err.contains("warning 9005"), "{err}");

    // Across processes.
    if let Err(why) = netns::namespace_probe() {
        eprintln!("SKIP {name} (cross-process part): {why}");
        return;
    }
    let rt = netns::try_run_bounded(
        Command::new("unshare").args(["-n", "chrt", "-f", "1", "true"]),
        Duration::from_secs(10),
    )
    .is_ok_and(|(s, _, _)| s.is_some_and(|s| s.success()));
    let (unshare, master_rt, sim_rt) = if rt {
        ("-n", "chrt -f 50 ", "chrt -f 49 ")
    } else {
        ("-rn", "", "")
    };
    let d = dir.path().display();
    let bin = env!("CARGO_BIN_EXE_fieldprobe");
    let eds_arg = eds_path.display();
    let link = "canopen-udp:239.74.163.21:43121";
    // Across processes the run uses a 40 ms cycle, as tests/system/canopen_sessions.rs does: on a
    // loaded two-core machine even SCHED_FIFO processes are held up for 35 ms now and then (seen:
    // "the master missed 8 cycles (34.8 ms without a frame)" at 4 ms), which the master and the
    // nodes' SYNC watch rightly treat as a lost bus; hello.nc's output does not depend on the
    // cycle time.
    // Node 4 is asked by can scan, sdos and sdo write first (pre-operational after boot-up);
    // then nodes 1-3 run hello.nc (the master's NMT reset communication to all nodes restores
    // node 4's PDO parameters too).
    let script = format!(
        "{setup}; \
         timeout 150 {sim_rt}{bin} sim canopen --bus udp:239.74.163.21:43121 --node 1 --node 2 \
           --node 3 --node 4 --eds {eds_arg} --seconds 140 2>{d}/sim.err & SIM=$!; \
         i=0; while ! grep -q listening {d}/sim.err 2>/dev/null && [ $i -lt 400 ]; do sleep 0.05; i=$((i+1)); done; \
         timeout 30 {bin} can scan --link {link} >{d}/scan.out 2>{d}/scan.err; \
         timeout 60 {bin} sdos --node 4 --eds {eds_arg} --link {link} >{d}/sdos.out 2>{d}/sdos.err; \
         echo $? >{d}/sdos.rc; \
         timeout 20 {bin} sdo write 0x1400:01 0x80000204 --type u32 --node 4 --link {link} 2>{d}/w1.err; \
         timeout 20 {bin} sdo write 0x1600:00 0 --type u8 --node 4 --link {link} 2>{d}/w2.err; \
         timeout 20 {bin} sdo write 0x1600:01 0x605A0010 --type u32 --node 4 --link {link} \
           >{d}/w3.out 2>{d}/w3.err; echo $? >{d}/w3.rc; \
         timeout 60 {master_rt}{bin} run examples/nc/hello.nc --machine {m} --link {link} \
           --set cycle_time_us=40000 >{d}/run.out 2>{d}/run.err; echo $? >{d}/run.rc; \
         kill $SIM 2>/dev/null; wait $SIM; exit 0",
        setup = netns::NETNS_SETUP,
    );
    let (status, out, err) = netns::run_bounded(
        Command::new("timeout")
            .args(["200", "unshare", unshare, "sh", "-c", &script])
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        Duration::from_secs(210),
    );
    let read = |f: &str| std::fs::read_to_string(dir.path().join(f)).unwrap_or_default();
    assert!(
        status.is_some_and(|s| s.success()),
        "namespace script: {status:?}\n{out}\n{err}\nsim: {}",
        read("sim.err")
    );
    eprintln!(
        "{name} ({}):\nrun stderr: {}\nsim: {}",
        if rt { "SCHED_FIFO" } else { "normal priority" },
        read("run.err"),
        read("sim.err")
    );
    assert_eq!(read("run.rc").trim(), "0", "run: {}", read("run.err"));
    assert_eq!(
        read("run.out"),
        sim_out,
        "canopen-udp vs sim: {}",
        read("run.err")
    );
    assert!(
        !read("run.err").contains("warning 9005"),
        "{}",
        read("run.err")
    );

    // can scan: node 4 with the EDS's device type and vendor (lower-case hex, 8 digits).
    let s = ini(&text);
    let device_type = num(&s["1000"]["DefaultValue"]);
    let vendor = num(&s["DEVICEINFO"]["VendorNumber"]);
    let scan = read("scan.out");
    let line = scan
        .lines()
        .find(|l| l.starts_with("4 "))
        .unwrap_or_else(|| panic!("node 4 in can scan:\n{scan}{}", read("scan.err")));
    assert!(line.contains(&format!("{device_type:#010x}")), "{line}");
    assert!(line.contains(&format!("{vendor:#010x}")), "{line}");

    // sdos: every object section of the EDS, on the node, each VAR with the EDS's access and
    // bit length.
    assert_eq!(read("sdos.rc").trim(), "0", "{}", read("sdos.err"));
    let sdos = read("sdos.out");
    let objects: std::collections::BTreeSet<u16> = vars(&text).keys().map(|k| k.0).collect();
    for index in &objects {
        let head = format!("SDO {index:#06x}, ");
        let l = sdos
            .lines()
            .find(|l| l.starts_with(&head))
            .unwrap_or_else(|| panic!("{head} in sdos"));
        assert!(l.ends_with("(EDS, on the node)"), "{l}");
    }
    for ((index, sub), (access, code, _, _)) in vars(&text) {
        let bits = match code {
            0x1 | 0x2 | 0x5 => Some(8),
            0x3 | 0x6 => Some(16),
            0x4 | 0x7 => Some(32),
            _ => None,
        };
        let Some(bits) = bits else { continue };
        let want = format!("  {index:#06x}:{sub:02x}, {access}, ");
        let l = sdos
            .lines()
            .find(|l| l.starts_with(&want))
            .unwrap_or_else(|| panic!("{want:?} in sdos:\n{sdos}"));
        assert!(l.contains(&format!(", {bits} bit, ")), "{l}");
    }

    // sdo write: RPDO1 destroyed, its mapping emptied, then 0x605A (PDOMapping=0 in the EDS)
    // refused with 0x06040041, exit 1.
    assert!(
        !vars(&text)[&(0x605A, 0)].2,
        "0x605A is not mappable in the EDS"
    );
    assert_eq!(read("w1.err"), "", "destroy RPDO1");
    assert_eq!(read("w2.err"), "", "empty its mapping");
    assert_eq!(read("w3.rc").trim(), "1", "{}", read("w3.err"));
    assert!(read("w3.err").contains("0x06040041"), "{}", read("w3.err"));
}
