//! `fieldprobe sdos` / `pdos` on the emulated EtherCAT segment (`ethercat-emu`, in process) and
//! on the emulated CANopen nodes (`canopen-emu`). EtherCAT: the listing must equal what the
//! servo's ESI declares (read here with roxmltree, `common/esi_dict.rs`, independently of
//! `fieldprobe::esi`); the PDO layout equals the ESI's `Sm` elements and default `RxPdo` /
//! `TxPdo` with the dictionary's names. CANopen: the RPDO / TPDO map equals the drive file's
//! process data packed into PDOs of at most 64 bits (CiA 301 frame size), read with toml_edit.

#[path = "common/cli.rs"]
mod cli;
#[path = "common/esi_dict.rs"]
mod esi_dict;
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
