//! `fieldprobe sdos` / `pdos` on the emulated EtherCAT segment (`ethercat-emu`, in process) and
//! on the emulated CANopen nodes (`canopen-emu`). EtherCAT: the listing must equal what the
//! servo's ESI declares (read here with roxmltree, `common/esi_dict.rs`, independently of
//! `fieldprobe::esi`); the PDO layout equals the ESI's `Sm` elements and default `RxPdo` /
//! `TxPdo` with the dictionary's names. CANopen: the RPDO / TPDO map equals the drive file's
//! process data packed into PDOs of at most 64 bits (CiA 301 frame size), read with toml_edit.

use crate::common::cli;
use crate::common::esi_dict;
use cli::{fieldprobe, stderr, stdout};

const SERVO_ESI: &str = "esi/fieldprobe-cia402-servo.xml";

fn number(s: &str) -> u32 {
    let t = s.trim();
    match t.strip_prefix("#x") {
        Some(h) => u32::from_str_radix(h, 16).unwrap(),
        None => t.parse().unwrap(),
    }
}

#[test]
fn sdos_lists_the_dictionary_the_servo_esi_declares() {
    let o = fieldprobe(&["sdos", "--device", "1"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    let expected = esi_dict::sdos_lines(&esi_dict::dictionary(SERVO_ESI));
    let got: Vec<&str> = out.lines().collect();
    assert!(expected.len() > 60, "{expected:?}");
    for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(*g, e, "line {i}");
    }
    assert_eq!(got.len(), expected.len(), "{out}");
}

#[test]
fn sdos_refuses_a_device_without_mailbox_and_an_eds_on_ethercat() {
    // Position 0 is the coupler: no mailbox, no SDO information.
    let o = fieldprobe(&["sdos", "--device", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stdout(&o));
    assert!(stderr(&o).contains("has no mailbox"), "{}", stderr(&o));
    let o = fieldprobe(&["sdos", "--device", "1", "--eds", "x.eds"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--eds x.eds"), "{}", stderr(&o));
}

#[test]
fn pdos_shows_the_esi_sync_managers_and_default_mapping() {
    let o = fieldprobe(&["pdos", "--device", "1"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));

    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(SERVO_ESI);
    let xml = std::fs::read_to_string(p).unwrap();
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let dict = esi_dict::dictionary(SERVO_ESI);
    let name_of = |index: u16, sub: u8| -> String {
        let o = dict.iter().find(|o| o.index == index).unwrap();
        o.entries
            .iter()
            .find(|e| e.sub == sub)
            .unwrap()
            .name
            .clone()
    };
    let device = doc
        .descendants()
        .find(|n| n.has_tag_name("Device"))
        .unwrap();
    let mut expected = Vec::new();
    let sms: Vec<_> = device.children().filter(|n| n.has_tag_name("Sm")).collect();
    for (k, sm) in sms.iter().enumerate() {
        expected.push(format!(
            "SM{k}: PhysAddr {:#06x}, DefaultSize {}, ControlRegister {:#04x}, Enable {}",
            number(sm.attribute("StartAddress").unwrap()),
            number(sm.attribute("DefaultSize").unwrap_or("0")),
            number(sm.attribute("ControlByte").unwrap()),
            number(sm.attribute("Enable").unwrap_or("0"))
        ));
        for tag in ["RxPdo", "TxPdo"] {
            for pdo in device
                .children()
                .filter(|n| n.has_tag_name(tag) && n.attribute("Sm").map(number) == Some(k as u32))
            {
                let text = |n: roxmltree::Node, t: &str| {
                    n.children()
                        .find(|c| c.has_tag_name(t))
                        .and_then(|c| c.text())
                        .unwrap_or("0")
                        .to_string()
                };
                let index = number(&text(pdo, "Index")) as u16;
                expected.push(format!(
                    "  {}xPDO {index:#06x} \"{}\"",
                    &tag[..1],
                    dict.iter().find(|o| o.index == index).unwrap().name
                ));
                for e in pdo.children().filter(|c| c.has_tag_name("Entry")) {
                    let i = number(&text(e, "Index")) as u16;
                    let s = number(&text(e, "SubIndex")) as u8;
                    expected.push(format!(
                        "    PDO entry {i:#06x}:{s:02x}, {} bit, \"{}\"",
                        number(&text(e, "BitLen")),
                        name_of(i, s)
                    ));
                }
            }
        }
    }
    let got: Vec<&str> = out.lines().collect();
    assert_eq!(got, expected, "{out}");
}

/// CiA 402 bit lengths of the objects the generic drive maps (CiA 402-2 data types).
fn cia402_bits(index: u16) -> u8 {
    match index {
        0x6040 | 0x6041 | 0x60B8 | 0x60B9 | 0x6077 => 16,
        0x6060 | 0x6061 => 8,
        0x607A | 0x6064 | 0x60F4 | 0x60BA..=0x60BD => 32,
        other => panic!("{other:#x} not expected"),
    }
}

#[test]
fn pdos_on_canopen_emu_shows_the_drive_file_process_data() {
    let o = fieldprobe(&["pdos", "--node", "1"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    // The drive file's entries, read with toml_edit.
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("drives/cia402-generic.toml");
    let doc: toml_edit::DocumentMut = std::fs::read_to_string(p).unwrap().parse().unwrap();
    let entries = |dir: &str| -> Vec<(u16, u8)> {
        let mut v: Vec<(u16, u8)> = doc[dir]["entries"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                let (i, s) = e.as_str().unwrap().split_once(':').unwrap();
                (
                    u16::from_str_radix(i.trim_start_matches("0x"), 16).unwrap(),
                    s.parse().unwrap(),
                )
            })
            .collect();
        v.sort_unstable();
        v
    };
    // Parse the output: PDO header lines and entry lines.
    let mut mapped: [Vec<(u16, u8)>; 2] = [Vec::new(), Vec::new()];
    let mut current: Option<(usize, u32, bool)> = None; // (rx=0 / tx=1, bits, valid)
    let mut headers = 0;
    for line in out.lines() {
        if let Some(rest) = line
            .strip_prefix("RPDO")
            .or_else(|| line.strip_prefix("TPDO"))
        {
            headers += 1;
            let rx = line.starts_with('R');
            let n: u32 = rest.split_whitespace().next().unwrap().parse().unwrap();
            // CiA 301 pre-defined connection set: RPDOn 0x200 + 0x100·(n−1) + node,
            // TPDOn 0x180 + 0x100·(n−1) + node.
            let cob = if rx { 0x200 } else { 0x180 } + 0x100 * (n - 1) + 1;
            assert!(line.contains(&format!("COB-ID {cob:#x} ")), "{line}");
            if let Some((_, bits, valid)) = current {
                assert!(
                    bits <= 64 && (bits > 0) == valid,
                    "PDO of {bits} bits, valid {valid}"
                );
            }
            current = Some((usize::from(!rx), 0, line.contains("(valid)")));
        } else if let Some(e) = line.trim_start().strip_prefix("PDO entry 0x") {
            let (i, rest) = e.split_once(':').unwrap();
            let index = u16::from_str_radix(i, 16).unwrap();
            let sub = u8::from_str_radix(&rest[..2], 16).unwrap();
            let bits: u8 = rest[4..]
                .split_whitespace()
                .next()
                .unwrap()
                .parse()
                .unwrap();
            assert_eq!(bits, cia402_bits(index), "{line}");
            let c = current.as_mut().unwrap();
            c.1 += u32::from(bits);
            mapped[c.0].push((index, sub));
        }
    }
    assert_eq!(headers, 8, "4 RPDOs and 4 TPDOs: {out}");
    for m in &mut mapped {
        m.sort_unstable();
    }
    assert_eq!(mapped[0], entries("rxpdo"), "{out}");
    assert_eq!(mapped[1], entries("txpdo"), "{out}");
}

#[test]
fn sdos_on_canopen_emu_finds_the_objects_the_node_serves() {
    let o = fieldprobe(&["sdos", "--node", "1"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    // CiA 301 mandatory objects and the drive file's process data objects are there; an
    // object the emulated node lacks (0x1010 store parameters) is not listed.
    for want in [
        "SDO 0x1000, \"Device type\" (scan)",
        "SDO 0x1018, \"Identity object\" (scan)",
        "SDO 0x6040, \"controlword\" (scan)",
        "SDO 0x60bd, \"touch probe 2 negative edge\" (scan)",
    ] {
        assert!(out.lines().any(|l| l == want), "{want}\n{out}");
    }
    assert!(!out.contains("SDO 0x1010"), "{out}");
}
