//! Every EDS / DCF file in `../shared/test-data/eds/` as a new user runs it (issue 25 item 5).
//! The folder is iterated — no code per file; files added later are checked the same way.
//!
//! Per file, all files at once (each in its own network namespace, with its own multicast
//! groups and ports):
//!
//! 1. `drive from-eds FILE` writes a definition — or, for a file that is no CiA 402 drive
//!    (this test's own reader finds no 0x6040 / 0x607A / 0x6041 / 0x6064 in it), refuses with
//!    exit 2 naming each missing object. Warnings go to stderr as `warning: FILE:…`.
//! 2. With a machine of three axes X, Y, Z on that definition at a 40 ms cycle (1 Mbit/s):
//!    the reference output of `run examples/nc/hello.nc --link sim`; with a touch probe in the
//!    file also `run examples/nc/seed004/meas1.nc --probe-at Z=100 --link sim`, which must
//!    print the values of seed 004 §5 (`common/seed004.rs`).
//! 3. In a private network namespace: three `sim canopen --eds FILE` nodes (1, 2, 3) over
//!    `canopen-udp`; `can scan` shows each with the device type and vendor id of the file
//!    (0x1000 and 0x1018:01 / `[DeviceInfo] VendorNumber`, read here by a small INI reader,
//!    not fieldprobe's parser); `run hello.nc` prints exactly the reference; python-canopen's
//!    `BaseNode402` (`tests/python/canopen_cia402_walk.py`) walks every node to SWITCH ON
//!    DISABLED, READY TO SWITCH ON, SWITCHED ON and OPERATION ENABLED by SDO controlword, the
//!    statusword checked after each step against CiA 402's state coding. With a touch probe
//!    in the file, three more nodes with `--probe-at 3=100` (node 3 = Z) on another group run
//!    meas1 with the drive latch at the same time, which must print the seed's values.
//!
//! CI budget: the files run concurrently, at a 40 ms bus cycle (hello.nc is 8.8 s of machine
//! time, meas1 20 s); every command and the namespace script are bounded. Without the test
//! data: SKIP (FIELDPROBE_REQUIRE_TEST_DATA=1 makes it a failure); without namespaces only
//! steps 1 and 2 run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use crate::common::netns;
use crate::common::seed004;
use crate::common::test_data;

const TEST: &str = "every_eds_file_runs_as_a_user_runs_it";
/// The bus cycle across processes (a 2-core CI machine holds processes up for tens of ms).
const CYCLE_US: u32 = 40_000;
/// Bound of one fieldprobe call outside the namespace.
const CALL: Duration = Duration::from_secs(60);
/// Bound of one file's namespace script (meas1 is 20 s of machine time).
const SCRIPT_S: u64 = 150;

// ------------------------------------------------------------------------------------------
// The EDS as text (independent of fieldprobe's parser): sections (upper case) → keys (lower
// case) → values; the first of a repeated key counts.

type Ini = BTreeMap<String, BTreeMap<String, String>>;

fn ini(text: &str) -> Ini {
    let mut out = Ini::new();
    let mut cur = String::new();
    for line in text.lines() {
        let l = line.trim();
        if l.is_empty() || l.starts_with(';') || l.starts_with('#') {
            continue;
        }
        if let Some(name) = l.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            cur = name.trim().to_ascii_uppercase();
            out.entry(cur.clone()).or_default();
        } else if let Some((k, v)) = l.split_once('=') {
            out.entry(cur.clone())
                .or_default()
                .entry(k.trim().to_ascii_lowercase())
                .or_insert_with(|| v.trim().to_string());
        }
    }
    out
}

/// A plain number of the file (`0x` hex or decimal).
fn num(s: &str) -> Option<u64> {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

fn value(s: &Ini, section: &str, key: &str) -> Option<u64> {
    s.get(section)?.get(key).and_then(|v| num(v))
}

/// What the file says, by this reader.
struct Expect {
    /// 0x1000 `DefaultValue` (none: 0, what the node reports).
    device_type: u64,
    /// 0x1018:01 `DefaultValue`, else `[DeviceInfo] VendorNumber`.
    vendor_id: u64,
    /// Of the CiA 402 objects a CSP axis cannot do without, those without a section.
    missing: Vec<u16>,
    /// 0x60B8 and 0x60B9 mappable (`PDOMapping=1`) and an edge position 0x60BA … 0x60BD.
    touch_probe: bool,
}

fn expect(text: &str) -> Expect {
    let s = ini(text);
    let mappable = |index: &str| {
        s.get(index)
            .and_then(|k| k.get("pdomapping"))
            .and_then(|v| num(v))
            == Some(1)
    };
    Expect {
        device_type: value(&s, "1000", "defaultvalue").unwrap_or(0),
        vendor_id: value(&s, "1018SUB1", "defaultvalue")
            .or_else(|| value(&s, "DEVICEINFO", "vendornumber"))
            .unwrap_or(0),
        missing: [0x6040u16, 0x607A, 0x6041, 0x6064]
            .into_iter()
            .filter(|i| !s.contains_key(&format!("{i:04X}")))
            .collect(),
        touch_probe: mappable("60B8")
            && mappable("60B9")
            && ["60BA", "60BB", "60BC", "60BD"].iter().any(|i| mappable(i)),
    }
}

// ------------------------------------------------------------------------------------------

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_fieldprobe")
}

fn fieldprobe(args: &[&str]) -> (Option<i32>, String, String) {
    let (status, out, err) = netns::run_bounded(
        Command::new(bin())
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        CALL,
    );
    (status.and_then(|s| s.code()), out, err)
}

/// The machine: X, Y, Z on `drive`, measuring on the drive latch (as
/// `examples/machines/canopen_xyz.toml`), 40 ms, 1 Mbit/s, the seed's probe D1.
fn machine(dir: &Path, drive: &Path) -> PathBuf {
    let mut m = format!("[channel]\ncycle_time_us = {CYCLE_US}\n\n[can]\nbitrate = 1000000\n\n");
    for axis in ["X", "Y", "Z"] {
        m.push_str(&format!(
            "[[axis]]\nname = \"{axis}\"\ndrive = \"{}\"\n\"kenngr.messachse\" = 1\n\
             \"kenngr.measure.signal\" = \"DRIVE\"\n\"kenngr.measure.input\" = 1\n\
             \"kenngr.measure.edge\" = \"POS\"\n",
            drive.display()
        ));
    }
    m.push_str("\n[tool.1]\nradius = 20000\n");
    let p = dir.join("machine.toml");
    std::fs::write(&p, m).unwrap();
    p
}

/// CiA 402 statusword coding (CiA 402 §6.2, table "statusword"): (state, mask, value).
const STATES: [(&str, u16, u16); 4] = [
    ("SWITCH ON DISABLED", 0x4F, 0x40),
    ("READY TO SWITCH ON", 0x6F, 0x21),
    ("SWITCHED ON", 0x6F, 0x23),
    ("OPERATION ENABLED", 0x6F, 0x27),
];

/// One line of the summary: what ran for the file.
struct Outcome {
    file: String,
    what: String,
    warnings: Vec<String>,
}

/// Everything for one file (module documentation); panics on the first thing that is wrong.
fn check_file(k: usize, path: &Path, python: Option<&Path>, seed: Option<&[String]>) -> Outcome {
    let file = path.file_name().unwrap().to_string_lossy().into_owned();
    let text = String::from_utf8_lossy(&std::fs::read(path).unwrap()).into_owned();
    let want = expect(&text);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let drive = dir.join("drive.toml");
    let p = path.display().to_string();

    // 1. drive from-eds.
    let (code, _, err) = fieldprobe(&[
        "drive",
        "from-eds",
        &p,
        "--out",
        &drive.display().to_string(),
    ]);
    let warnings: Vec<String> = err
        .lines()
        .filter(|l| l.starts_with("warning: "))
        .map(str::to_string)
        .collect();
    for w in &warnings {
        assert!(w.contains(&p), "{file}: a warning names the file: {w}");
    }
    if !want.missing.is_empty() {
        assert_eq!(code, Some(2), "{file}: not a CiA 402 drive, refused: {err}");
        assert!(err.contains("cannot run a CiA 402 axis"), "{file}: {err}");
        for index in &want.missing {
            assert!(
                err.contains(&format!("0x{index:04X}:00")),
                "{file}: the refusal names 0x{index:04X}: {err}"
            );
        }
        return Outcome {
            file,
            what: format!(
                "refused, not CiA 402 (device type {:#010x}; no {})",
                want.device_type,
                want.missing
                    .iter()
                    .map(|i| format!("0x{i:04X}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            warnings,
        };
    }
    assert_eq!(code, Some(0), "{file}: drive from-eds: {err}");
    assert!(drive.is_file(), "{file}: no definition written");
    let toml = std::fs::read_to_string(&drive).unwrap();
    assert_eq!(
        toml.contains("\"0x60B8:00\""),
        want.touch_probe,
        "{file}: touch probe in the definition as in the file:\n{toml}"
    );

    // 2. The reference on --link sim.
    let m = machine(dir, &drive).display().to_string();
    let (code, hello_ref, err) = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--machine",
        &m,
        "--link",
        "sim",
    ]);
    assert_eq!(code, Some(0), "{file}: hello.nc on sim: {err}");
    assert!(!hello_ref.is_empty(), "{file}: hello.nc prints");
    let meas1 = "examples/nc/seed004/meas1.nc";
    if want.touch_probe {
        let (code, out, err) = fieldprobe(&[
            "run",
            meas1,
            "--probe-at",
            "Z=100",
            "--machine",
            &m,
            "--link",
            "sim",
        ]);
        assert_eq!(code, Some(0), "{file}: meas1 on sim: {err}");
        if let Some(seed) = seed {
            assert_eq!(
                out.lines().collect::<Vec<_>>(),
                seed,
                "{file}: meas1 on sim"
            );
        }
    }
    let Some(python) = python else {
        return Outcome {
            file,
            what: "definition; hello.nc on sim (no namespaces: not across processes)".into(),
            warnings,
        };
    };

    // 3. Across processes.
    let link = format!("239.74.164.{}:{}", 10 + k, 43400 + k);
    let probe_link = format!("239.74.165.{}:{}", 10 + k, 43500 + k);
    let d = dir.display();
    let b = bin();
    let sims = format!(
        "timeout {SCRIPT_S} {b} sim canopen --bus udp:{link} --node 1 --node 2 --node 3 --eds '{p}' \
           --seconds {SCRIPT_S} 2>{d}/sim.err & SIM=$!; {}",
        if want.touch_probe {
            format!(
                "timeout {SCRIPT_S} {b} sim canopen --bus udp:{probe_link} --node 1 --node 2 \
                   --node 3 --probe-at 3=100 --eds '{p}' --seconds {SCRIPT_S} 2>{d}/simp.err & \
                 SIMP=$!;"
            )
        } else {
            "SIMP=;".into()
        }
    );
    let wait_listening = |f: &str| {
        format!(
            "i=0; while ! grep -q listening {d}/{f} 2>/dev/null && [ $i -lt 400 ]; do sleep 0.05; \
             i=$((i+1)); done;"
        )
    };
    let meas = if want.touch_probe {
        format!(
            "{} (timeout 60 {b} run {meas1} --machine {m} --link canopen-udp:{probe_link} \
               >{d}/meas1.out 2>{d}/meas1.err; echo $? >{d}/meas1.rc) & MEAS=$!;",
            wait_listening("simp.err")
        )
    } else {
        "MEAS=;".into()
    };
    let script = format!(
        "{setup}; {sims} {wait} {meas} \
         timeout 20 {b} can scan --link canopen-udp:{link} >{d}/scan.out 2>{d}/scan.err; \
         timeout 60 {b} run examples/nc/hello.nc --machine {m} --link canopen-udp:{link} \
           >{d}/hello.out 2>{d}/hello.err; echo $? >{d}/hello.rc; \
         timeout 60 {py} tests/python/canopen_cia402_walk.py {g} {port} 1 2 3 \
           >{d}/walk.out 2>{d}/walk.err; echo $? >{d}/walk.rc; \
         [ -n \"$MEAS\" ] && wait $MEAS; kill $SIM $SIMP 2>/dev/null; wait; exit 0",
        setup = netns::NETNS_SETUP,
        wait = wait_listening("sim.err"),
        py = python.display(),
        g = link.split(':').next().unwrap(),
        port = link.split(':').nth(1).unwrap(),
    );
    let t0 = Instant::now();
    let (status, out, err) = netns::run_bounded(
        Command::new("timeout")
            .args([
                &(SCRIPT_S + 20).to_string(),
                "unshare",
                "-rn",
                "sh",
                "-c",
                &script,
            ])
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        Duration::from_secs(SCRIPT_S + 30),
    );
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    assert!(
        status.is_some_and(|s| s.success()),
        "{file}: namespace script {status:?}\n{out}\n{err}\nsim: {}",
        read("sim.err")
    );
    let took = t0.elapsed();
    // sim canopen --eds read the same file: each of its warnings once on stderr.
    let sim_err = read("sim.err");
    for w in &warnings {
        assert_eq!(
            sim_err.matches(w.as_str()).count(),
            1,
            "{file}: {w:?} once in sim canopen's stderr:\n{sim_err}"
        );
    }

    // can scan: nodes 1 … 3 with the file's device type and vendor id.
    let scan = read("scan.out");
    for node in 1..=3 {
        let line = scan
            .lines()
            .find(|l| l.starts_with(&format!("{node} ")))
            .unwrap_or_else(|| {
                panic!(
                    "{file}: node {node} in can scan:\n{scan}{}",
                    read("scan.err")
                )
            });
        assert!(
            line.contains(&format!("{:#010x}", want.device_type)),
            "{file}: device type {:#010x} in {line}",
            want.device_type
        );
        assert!(
            line.contains(&format!("{:#010x}", want.vendor_id)),
            "{file}: vendor id {:#010x} in {line}",
            want.vendor_id
        );
    }
    // hello.nc across processes: what --link sim prints.
    assert_eq!(
        read("hello.rc").trim(),
        "0",
        "{file}: hello.nc over canopen-udp: {}\nsim: {}",
        read("hello.err"),
        read("sim.err")
    );
    assert_eq!(
        read("hello.out"),
        hello_ref,
        "{file}: hello.nc canopen-udp vs sim: {}",
        read("hello.err")
    );
    // No CNC error and no start-up message of the PDO fit (900504 … 900506) on the way.
    let hello_err = read("hello.err");
    assert!(
        !hello_err
            .lines()
            .any(|l| l.starts_with("error ") || l.starts_with("warning 9005")),
        "{file}: {hello_err}"
    );
    // python-canopen walked every node through the CiA 402 state machine.
    assert_eq!(
        read("walk.rc").trim(),
        "0",
        "{file}: walk: {}",
        read("walk.err")
    );
    let walk: serde_json::Value =
        serde_json::from_str(read("walk.out").trim()).unwrap_or_else(|e| {
            panic!(
                "{file}: walk output {e}: {}{}",
                read("walk.out"),
                read("walk.err")
            )
        });
    for node in ["1", "2", "3"] {
        let n = &walk["nodes"][node];
        assert_eq!(n["ok"], true, "{file}: node {node}: {n}");
        let steps = n["steps"].as_array().unwrap();
        assert_eq!(steps.len(), STATES.len(), "{file}: node {node}: {n}");
        for (s, (state, mask, bits)) in steps.iter().zip(STATES) {
            assert_eq!(s["target"], state, "{file}: node {node}");
            let sw = s["statusword"].as_u64().unwrap() as u16;
            assert_eq!(
                sw & mask,
                bits,
                "{file}: node {node} {state}: statusword {sw:#06x}"
            );
        }
    }
    let mut what = format!(
        "definition; can scan; hello.nc over canopen-udp as on sim; CiA 402 walk by python-canopen ({:.1} s)",
        took.as_secs_f64()
    );
    if want.touch_probe {
        assert_eq!(
            read("meas1.rc").trim(),
            "0",
            "{file}: meas1: {}",
            read("meas1.err")
        );
        if let Some(seed) = seed {
            assert_eq!(
                read("meas1.out").lines().collect::<Vec<_>>(),
                seed,
                "{file}: meas1 over canopen-udp: {}",
                read("meas1.err")
            );
        }
        what.push_str("; meas1 with the drive latch as the seed");
    }
    Outcome {
        file,
        what,
        warnings,
    }
}

#[test]
fn every_eds_file_runs_as_a_user_runs_it() {
    let _one_module = crate::gate::enter(module_path!());
    let Some(dir) = test_data::test_data_dir("eds", TEST) else {
        return;
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.extension()
                .is_some_and(|x| x.eq_ignore_ascii_case("eds") || x.eq_ignore_ascii_case("dcf"))
        })
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no EDS file in {}", dir.display());
    assert!(
        files.len() < 200,
        "group / port numbers per file: at most 200 files"
    );
    let seed = test_data::seeds_present(TEST).then(|| seed004::seed_stdout_lines("meas1"));
    let python = match netns::namespace_probe() {
        Ok(()) => Some(netns::ensure_venv()),
        Err(why) => {
            eprintln!("SKIP {TEST} (across processes): {why}");
            None
        }
    };
    let t0 = Instant::now();
    let handles: Vec<_> = files
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let (f, python, seed) = (f.clone(), python.clone(), seed.clone());
            std::thread::spawn(move || check_file(k, &f, python.as_deref(), seed.as_deref()))
        })
        .collect();
    let mut failed = Vec::new();
    for (h, f) in handles.into_iter().zip(&files) {
        match h.join() {
            Ok(o) => {
                eprintln!("{}: {}", o.file, o.what);
                for w in &o.warnings {
                    eprintln!("    {w}");
                }
            }
            Err(e) => {
                let why = e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                failed.push(format!("{}: {why}", f.display()));
            }
        }
    }
    eprintln!(
        "{} files in {:.1} s",
        files.len(),
        t0.elapsed().as_secs_f64()
    );
    assert!(failed.is_empty(), "{}", failed.join("\n\n"));
}
