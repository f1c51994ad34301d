//! `fieldprobe drive from-esi` / `drive from-eds` (issue 19 item 3) with the real vendor files
//! in `../shared/test-data` (SKIP without them, see `tests/common/test_data.rs`).
//!
//! What the definition must hold is read here from the vendor file itself, by a reader of its
//! own (string scanning of the XML `<Object>` elements and of the EDS `[xxxx]` sections), never
//! from fieldprobe's ESI / EDS parsers: an object is mapped when the file has it and marks it
//! mappable in its direction (ESI `Flags/PdoMapping` R / T / RT; EDS `PDOMapping=1` with an
//! `AccessType` of that direction), the touch probe and its `[probe]` section only when the
//! device has 0x60B8 out and 0x60B9 in, the drive functions only for objects the file has, with
//! the file's data type. The written file must then pass `fieldprobe check`.

use crate::common::cli;
use crate::common::test_data;
use cli::{fieldprobe, stderr, stdout};
use std::collections::BTreeMap;
use test_data::test_data;

/// One object as the vendor file states it.
#[derive(Debug, Clone)]
struct FileObject {
    /// Data type in drive-file spelling (`u16`), `None` if not one of those.
    ty: Option<&'static str>,
    rx: bool,
    tx: bool,
}

/// The text between `<tag>` and `</tag>` in `block`, first occurrence.
fn element<'a>(block: &'a str, tag: &str) -> Option<&'a str> {
    let open = format!("<{tag}>");
    let start = block.find(&open)? + open.len();
    let end = block[start..].find(&format!("</{tag}>"))?;
    Some(block[start..start + end].trim())
}

/// The `<Object>` elements of an ESI dictionary, by index (plain string scanning).
fn esi_objects(xml: &str) -> BTreeMap<u16, FileObject> {
    let mut out = BTreeMap::new();
    let mut rest = xml;
    while let Some(i) = rest.find("<Object>") {
        let after = &rest[i..];
        let end = after.find("</Object>").expect("</Object>");
        let block = &after[..end];
        rest = &after[end..];
        let index = element(block, "Index").expect("Index");
        let index = u16::from_str_radix(index.trim_start_matches("#x"), 16).expect("hex index");
        let ty = match element(block, "Type").expect("Type") {
            "SINT" => Some("i8"),
            "USINT" => Some("u8"),
            "INT" => Some("i16"),
            "UINT" => Some("u16"),
            "DINT" => Some("i32"),
            "UDINT" => Some("u32"),
            _ => None,
        };
        let mapping = element(block, "PdoMapping")
            .unwrap_or("")
            .to_ascii_uppercase();
        out.insert(
            index,
            FileObject {
                ty,
                rx: mapping.contains('R'),
                tx: mapping.contains('T'),
            },
        );
    }
    out
}

/// The sub-index 0 sections `[xxxx]` of an EDS, by index (plain INI scanning).
fn eds_objects(text: &str) -> BTreeMap<u16, FileObject> {
    let mut out = BTreeMap::new();
    let mut section: Option<u16> = None;
    let mut keys: BTreeMap<String, String> = BTreeMap::new();
    let mut flush = |section: Option<u16>, keys: &mut BTreeMap<String, String>| {
        if let Some(index) = section {
            let num = |k: &str| {
                keys.get(k).and_then(|v| {
                    let v = v.trim();
                    match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
                        Some(h) => u32::from_str_radix(h, 16).ok(),
                        None => v.parse().ok(),
                    }
                })
            };
            if let Some(code) = num("datatype") {
                let ty = match code {
                    2 => Some("i8"),
                    3 => Some("i16"),
                    4 => Some("i32"),
                    5 => Some("u8"),
                    6 => Some("u16"),
                    7 => Some("u32"),
                    _ => None,
                };
                let mapped = num("pdomapping") == Some(1);
                let access = keys
                    .get("accesstype")
                    .map(|a| a.trim().to_ascii_lowercase())
                    .unwrap_or_default();
                out.insert(
                    index,
                    FileObject {
                        ty,
                        rx: mapped && ["rww", "rw", "wo"].contains(&access.as_str()),
                        tx: mapped && ["ro", "rwr", "rw", "const"].contains(&access.as_str()),
                    },
                );
            }
        }
        keys.clear();
    };
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with(';') || line.is_empty() {
            continue;
        }
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            flush(section, &mut keys);
            section = (name.len() == 4)
                .then(|| u16::from_str_radix(name, 16).ok())
                .flatten();
            continue;
        }
        if let Some((k, v)) = line.split_once('=') {
            keys.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
        }
    }
    flush(section, &mut keys);
    out
}

/// What the definition must map, by the rules of issue 19 item 3, from `objects`.
fn expected_pdo(objects: &BTreeMap<u16, FileObject>) -> (Vec<String>, Vec<String>, bool) {
    let rx_ok = |i: u16| objects.get(&i).is_some_and(|o| o.rx);
    let tx_ok = |i: u16| objects.get(&i).is_some_and(|o| o.tx);
    let probe = rx_ok(0x60B8) && tx_ok(0x60B9) && (0x60BA..=0x60BD).any(tx_ok);
    let mut rx: Vec<u16> = vec![0x6040, 0x607A, 0x6060];
    let mut tx: Vec<u16> = vec![0x6041, 0x6064];
    if tx_ok(0x60F4) {
        tx.push(0x60F4);
    }
    tx.push(0x6061);
    if probe {
        rx.push(0x60B8);
        tx.extend((0x60B9..=0x60BD).filter(|&i| tx_ok(i)));
    }
    if tx_ok(0x6077) {
        tx.push(0x6077);
    }
    let fmt = |v: Vec<u16>| v.into_iter().map(|i| format!("0x{i:04X}:00")).collect();
    (fmt(rx), fmt(tx), probe)
}

/// The `entries` list under `[table]` of a drive file.
fn entries(toml: &str, table: &str) -> Vec<String> {
    let at = toml
        .find(&format!("\n[{table}]\n"))
        .unwrap_or_else(|| panic!("no [{table}] in\n{toml}"));
    let line = toml[at..]
        .lines()
        .find(|l| l.starts_with("entries = ["))
        .expect("entries");
    line["entries = [".len()..line.len() - 1]
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// The `[functions]` line of `key`, if any.
fn function_line<'a>(toml: &'a str, key: &str) -> Option<&'a str> {
    toml.lines().find(|l| l.starts_with(&format!("{key} = {{")))
}

/// Compare a generated definition with the vendor file's objects.
#[track_caller]
fn assert_follows_the_file(toml: &str, objects: &BTreeMap<u16, FileObject>) -> bool {
    let (rx, tx, probe) = expected_pdo(objects);
    assert_eq!(entries(toml, "rxpdo"), rx, "{toml}");
    assert_eq!(entries(toml, "txpdo"), tx, "{toml}");
    assert_eq!(toml.contains("\n[probe]\n"), probe, "{toml}");
    for (key, index) in [
        ("TORQUE_LIMIT", 0x6072u16),
        ("TORQUE_LIMIT_POS", 0x60E0),
        ("TORQUE_LIMIT_NEG", 0x60E1),
        ("MON_WINDOW", 0x6065),
        ("MON_TIMEOUT", 0x6066),
    ] {
        match (objects.get(&index), function_line(toml, key)) {
            (None, None) => {}
            (Some(o), Some(line)) => {
                assert!(
                    line.contains(&format!("object = \"0x{index:04X}:00\"")),
                    "{line}"
                );
                let ty = o.ty.expect("a supported type");
                assert!(line.contains(&format!("type = \"{ty}\"")), "{key}: {line}");
            }
            (o, line) => panic!("{key}: object in file {:?}, line {line:?}", o.is_some()),
        }
    }
    probe
}

/// `fieldprobe check` with axis Z on `drive` (and `sets`); exit code and stdout.
fn check(drive: &str, sets: &[&str]) -> (Option<i32>, String) {
    let z = format!("Z.drive={drive}");
    let mut args = vec!["check", "--set", z.as_str()];
    for s in sets {
        args.extend(["--set", s]);
    }
    let o = fieldprobe(&args);
    (o.status.code(), format!("{}{}", stdout(&o), stderr(&o)))
}

fn write_out(dir: &tempfile::TempDir, name: &str, args: &[&str]) -> (String, String) {
    let out = dir.path().join(name);
    let out_s = out.to_string_lossy().into_owned();
    let mut all = args.to_vec();
    all.extend(["--out", out_s.as_str()]);
    let o = fieldprobe(&all);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
    (std::fs::read_to_string(&out).expect("written"), stderr(&o))
}

#[test]
fn ingenia_esi_gives_a_definition_without_touch_probe_that_passes_check() {
    let Some(esi) = test_data(
        "esi/ingenia-evs-net-ecat402-drive.xml",
        "ingenia_esi_gives_a_definition_without_touch_probe_that_passes_check",
    ) else {
        return;
    };
    let xml = std::fs::read_to_string(&esi).unwrap();
    let objects = esi_objects(&xml);
    // The facts about this file, read independently.
    assert!(objects.contains_key(&0x6065) && objects.contains_key(&0x6066));
    assert!(objects[&0x60F4].tx && !objects.contains_key(&0x60B8));
    let dir = tempfile::tempdir().unwrap();
    let path = esi.to_string_lossy().into_owned();
    let (toml, notes) = write_out(&dir, "ingenia.toml", &["drive", "from-esi", &path]);
    // stdout and --out carry the same text.
    let o = fieldprobe(&["drive", "from-esi", &path]);
    assert_eq!(stdout(&o).trim_end(), toml.trim_end());
    assert!(!assert_follows_the_file(&toml, &objects));
    // Header: source file, vendor, product code and revision from the file's Type element.
    let type_line = xml
        .lines()
        .find(|l| l.contains("<Type ProductCode="))
        .unwrap();
    let attr = |name: &str| -> u32 {
        let at = type_line.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        let v = &type_line[at..at + type_line[at..].find('"').unwrap()];
        match v.strip_prefix("#x") {
            Some(h) => u32::from_str_radix(h, 16).unwrap(),
            None => v.parse().unwrap(),
        }
    };
    for text in [
        "ingenia-evs-net-ecat402-drive.xml".to_string(),
        "Ingenia".to_string(),
        format!("product code 0x{:08X}", attr("ProductCode")),
        format!("revision 0x{:08X}", attr("RevisionNo")),
        "profile = \"cia402\"".to_string(),
        "TO FILL".to_string(),
    ] {
        assert!(toml.contains(&text), "{text}: {toml}");
    }
    assert!(
        notes.contains("no touch probe") && notes.contains("PLC_TIMESTAMP"),
        "{notes}"
    );
    // Z measuring through the CNC: no finding; the check names the missing touch probe.
    let file = dir.path().join("ingenia.toml");
    let file = file.to_str().unwrap();
    let (code, out) = check(file, &["Z.kenngr.measure.signal=PLC_TIMESTAMP"]);
    assert_eq!(code, Some(0), "{out}");
    assert!(
        out.contains("Z (ingenia-evs-net-01, cia402):\n  ok\n  note: "),
        "{out}"
    );
}

#[test]
fn technosoft_eds_gives_a_definition_with_touch_probe_that_passes_check() {
    let Some(eds) = test_data(
        "eds/technosoft-ipos-cia402.eds",
        "technosoft_eds_gives_a_definition_with_touch_probe_that_passes_check",
    ) else {
        return;
    };
    let text = std::fs::read_to_string(&eds).unwrap();
    let objects = eds_objects(&text);
    assert!((0x60B8..=0x60BD).all(|i| objects.contains_key(&i)));
    let dir = tempfile::tempdir().unwrap();
    let (toml, _) = write_out(
        &dir,
        "ipos.toml",
        &["drive", "from-eds", &eds.to_string_lossy()],
    );
    assert!(
        assert_follows_the_file(&toml, &objects),
        "touch probe: {toml}"
    );
    assert!(toml.contains("name = \"technosoft-ipos\""), "{toml}");
    // Measuring with the drive latch (the default machine's signal DRIVE on Z): no finding.
    let file = dir.path().join("ipos.toml");
    let (code, out) = check(file.to_str().unwrap(), &[]);
    assert_eq!(code, Some(0), "{out}");
    assert!(
        out.contains("Z (technosoft-ipos, cia402):\n  ok\n"),
        "{out}"
    );
}

#[test]
fn python_canopen_eds_functions_follow_the_file_types() {
    let Some(eds) = test_data(
        "eds/python-canopen-e35.eds",
        "python_canopen_eds_functions_follow_the_file_types",
    ) else {
        return;
    };
    let objects = eds_objects(&std::fs::read_to_string(&eds).unwrap());
    let dir = tempfile::tempdir().unwrap();
    let (toml, notes) = write_out(
        &dir,
        "e35.toml",
        &["drive", "from-eds", &eds.to_string_lossy()],
    );
    assert!(!assert_follows_the_file(&toml, &objects));
    // 0x60E0 / 0x60E1 are INTEGER16 in this file (u16 in the generic drive).
    assert_eq!(objects[&0x60E0].ty, Some("i16"));
    assert!(notes.contains("no touch probe"), "{notes}");
    let file = dir.path().join("e35.toml");
    let (code, out) = check(file.to_str().unwrap(), &["Z.kenngr.measure.signal=PLC"]);
    assert_eq!(code, Some(0), "{out}");
}

/// The real file with the `<Object>` of 0x607A removed (a device without target position).
fn esi_without_607a(xml: &str) -> String {
    let key = xml
        .find("<Index>#x607a</Index>")
        .or_else(|| xml.find("<Index>#x607A</Index>"))
        .expect("0x607A in the file");
    let start = xml[..key].rfind("<Object>").unwrap();
    let end = key + xml[key..].find("</Object>").unwrap() + "</Object>".len();
    format!("{}{}", &xml[..start], &xml[end..])
}

#[test]
fn a_device_without_target_position_is_refused_naming_object_and_file() {
    let Some(esi) = test_data(
        "esi/ingenia-evs-net-ecat402-drive.xml",
        "a_device_without_target_position_is_refused_naming_object_and_file",
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let excerpt = esi_without_607a(&std::fs::read_to_string(&esi).unwrap());
    assert!(!esi_objects(&excerpt).contains_key(&0x607A));
    let path = dir.path().join("no-607a.xml");
    std::fs::write(&path, &excerpt).unwrap();
    let o = fieldprobe(&["drive", "from-esi", path.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stdout(&o));
    let err = stderr(&o);
    assert!(err.contains("no-607a.xml"), "{err}");
    assert!(
        err.contains("0x607A:00 target position: not in the file"),
        "{err}"
    );
    assert_eq!(stdout(&o), "", "nothing written");

    // EDS: 0x607A present but only mappable as a process input (AccessType ro).
    let Some(eds) = test_data(
        "eds/technosoft-ipos-cia402.eds",
        "a_device_without_target_position_is_refused_naming_object_and_file",
    ) else {
        return;
    };
    let text = std::fs::read_to_string(&eds).unwrap();
    let at = text.find("[607A]").expect("[607A]");
    let access = at + text[at..].find("AccessType=rww").expect("rww");
    let edited = format!(
        "{}AccessType=ro{}",
        &text[..access],
        &text[access + "AccessType=rww".len()..]
    );
    let objects = eds_objects(&edited);
    assert!(!objects[&0x607A].rx && objects[&0x607A].tx);
    let path = dir.path().join("ro-607a.eds");
    std::fs::write(&path, edited).unwrap();
    let out = dir.path().join("never.toml");
    let o = fieldprobe(&[
        "drive",
        "from-eds",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("ro-607a.eds")
            && err.contains("0x607A:00 target position: not mappable into an RxPDO"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn bad_input_is_exit_2() {
    let o = fieldprobe(&["drive", "from-esi", "no/such/file.xml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no/such/file.xml"), "{}", stderr(&o));
    let o = fieldprobe(&["drive", "from-eds", "no/such/file.eds"]);
    assert_eq!(o.status.code(), Some(2));
    // A built-in ESI without a CoE dictionary (the coupler).
    let o = fieldprobe(&["drive", "from-esi", "esi/fieldprobe-ek1100.xml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("dictionary"), "{}", stderr(&o));
    let o = fieldprobe(&[
        "drive",
        "from-esi",
        "esi/fieldprobe-cia402-servo.xml",
        "--device",
        "0x12345",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no such device"), "{}", stderr(&o));
}
