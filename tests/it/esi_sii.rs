//! ESI → SII (`esi::to_sii::sii_from_device`): every device of the repository's `esi/` files and
//! of a real vendor file is built, encoded, decoded again and compared with the values read
//! straight from the XML here (roxmltree, not the crate's ESI parser): identity, mailbox layout
//! and protocols, sync managers, PDOs and their entries, EEPROM size, DC op modes.

use fieldprobe::esi::{self, sii, to_sii};
use roxmltree::{Document, Node};
use std::path::{Path, PathBuf};

use crate::common::test_data;

/// ETG.2000 number: `#x` hex or decimal.
fn num(s: &str) -> i64 {
    let s = s.trim();
    match s.strip_prefix("#x").or_else(|| s.strip_prefix("#X")) {
        Some(h) => i64::from_str_radix(h, 16).unwrap(),
        None => s.parse().unwrap(),
    }
}

fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(name))
}

fn children<'a, 'i>(n: Node<'a, 'i>, name: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(move |c| c.has_tag_name(name))
}

fn text(n: Node) -> String {
    n.text().unwrap_or("").trim().to_string()
}

fn esi_files() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("esi");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "xml"))
        .collect();
    files.sort();
    assert!(files.len() >= 5, "esi/ has {files:?}");
    files
}

/// The vendor file in `../shared/test-data/`; `None`: absent, `test` skips (see
/// `common/test_data.rs`).
fn vendor_file(test: &str) -> Option<PathBuf> {
    test_data::test_data("esi/ingenia-evs-net-ecat402-drive.xml", test)
}

/// Build, encode, decode every device of `path` and check it against the XML; returns the
/// number of devices checked.
fn check_file(path: &Path) -> usize {
    let xml = std::fs::read_to_string(path).unwrap();
    let doc = Document::parse(&xml).unwrap();
    let root = doc.root_element();
    let vendor_id = num(&text(child(child(root, "Vendor").unwrap(), "Id").unwrap())) as u32;
    let parsed = esi::load(path).unwrap();
    let devices = child(child(root, "Descriptions").unwrap(), "Devices").unwrap();
    let mut n = 0;
    for dev in children(devices, "Device") {
        n += 1;
        let who = format!("{}: device {n}", path.display());
        let ty = child(dev, "Type").unwrap();
        let product = num(ty.attribute("ProductCode").unwrap()) as u32;
        let revision = ty.attribute("RevisionNo").map_or(0, num) as u32;
        let d = parsed.device(product, revision).expect("device found");

        let content = to_sii::sii_from_device(&parsed, d).unwrap();
        let image = sii::encode(&content).unwrap();
        assert_eq!(
            sii::header_checksum(&image),
            Some(image[14]),
            "{who}: header CRC"
        );
        let back = sii::decode(&image).unwrap_or_else(|e| panic!("{who}: {e}"));
        assert_eq!(back, content, "{who}: round trip");
        let h = &back.header;

        // identity
        assert_eq!(h.vendor_id, vendor_id, "{who}");
        assert_eq!(h.product_code, product, "{who}");
        assert_eq!(h.revision, revision, "{who}");
        assert_eq!(h.serial, 0, "{who}");
        assert_eq!(h.version, 1, "{who}");

        // names
        let g = back.general().expect("General");
        assert_eq!(back.string(g.order_idx), Some(text(ty).as_str()), "{who}");
        let names: Vec<String> = children(dev, "Name").map(text).collect();
        let name = back.string(g.name_idx).unwrap().to_string();
        assert!(names.contains(&name), "{who}: {name:?} not in {names:?}");
        if let Some(gt) = child(dev, "GroupType") {
            assert_eq!(back.string(g.group_idx), Some(text(gt).as_str()), "{who}");
        }

        // EEPROM
        let eeprom = child(dev, "Eeprom");
        let bytes = eeprom
            .and_then(|e| child(e, "ByteSize"))
            .map_or(2048, |b| num(&text(b)) as usize);
        assert_eq!(h.eeprom_size_bytes(), bytes, "{who}");
        if let Some(cfg) = eeprom.and_then(|e| child(e, "ConfigData")) {
            let hex = text(cfg);
            let word0 = u16::from_str_radix(&format!("{}{}", &hex[2..4], &hex[0..2]), 16);
            assert_eq!(h.pdi_control, word0.unwrap(), "{who}: ConfigData word 0");
            let bytes: Vec<u8> = (0..hex.len() / 2)
                .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                .take(14)
                .collect();
            assert_eq!(&image[..bytes.len()], &bytes[..], "{who}: ConfigData");
        }

        // sync managers and the standard mailbox
        let sms: Vec<Node> = children(dev, "Sm").collect();
        assert_eq!(back.sync_managers().len(), sms.len(), "{who}");
        for (i, (x, s)) in sms.iter().zip(back.sync_managers()).enumerate() {
            let start = num(x.attribute("StartAddress").unwrap()) as u16;
            let size = x.attribute("DefaultSize").map_or(0, num) as u16;
            assert_eq!(s.start, start, "{who}: SM{i}");
            assert_eq!(s.length, size, "{who}: SM{i}");
            assert_eq!(
                s.control,
                num(x.attribute("ControlByte").unwrap()) as u8,
                "{who}: SM{i}"
            );
            let en = x
                .attribute("Enable")
                .is_some_and(|e| e == "1" || e == "true");
            assert_eq!(s.enable, u8::from(en), "{who}: SM{i}");
            let kind = text(*x);
            let ty = match kind.as_str() {
                "MBoxOut" => 1,
                "MBoxIn" => 2,
                "Outputs" => 3,
                "Inputs" => 4,
                _ => 0,
            };
            assert_eq!(s.sm_type, ty, "{who}: SM{i}");
            if kind == "MBoxOut" {
                assert_eq!(h.standard_mailbox.rx_offset, start, "{who}");
                assert_eq!(h.standard_mailbox.rx_size, size, "{who}");
            }
            if kind == "MBoxIn" {
                assert_eq!(h.standard_mailbox.tx_offset, start, "{who}");
                assert_eq!(h.standard_mailbox.tx_size, size, "{who}");
            }
        }

        // mailbox protocols
        let mut protos = 0u16;
        if let Some(mb) = child(dev, "Mailbox") {
            for (tag, bit) in [
                ("AoE", 0x01),
                ("EoE", 0x02),
                ("CoE", 0x04),
                ("FoE", 0x08),
                ("SoE", 0x10),
                ("VoE", 0x20),
            ] {
                if child(mb, tag).is_some() {
                    protos |= bit;
                }
            }
            if let Some(coe) = child(mb, "CoE") {
                assert_ne!(g.coe_details & 0x01, 0, "{who}: CoE SDO");
                let on = |a: &str| coe.attribute(a).is_some_and(|v| v == "true" || v == "1");
                assert_eq!(g.coe_details & 0x02 != 0, on("SdoInfo"), "{who}");
                assert_eq!(g.coe_details & 0x04 != 0, on("PdoAssign"), "{who}");
                assert_eq!(g.coe_details & 0x08 != 0, on("PdoConfig"), "{who}");
                assert_eq!(g.coe_details & 0x20 != 0, on("CompleteAccess"), "{who}");
            }
        }
        assert_eq!(h.mailbox_protocols, protos, "{who}: mailbox protocols");

        // PDOs
        for (tag, got) in [
            ("RxPdo", back.rx_pdos().collect::<Vec<_>>()),
            ("TxPdo", back.tx_pdos().collect::<Vec<_>>()),
        ] {
            let want: Vec<Node> = children(dev, tag).collect();
            assert_eq!(got.len(), want.len(), "{who}: {tag}");
            for (x, p) in want.iter().zip(got) {
                let index = num(&text(child(*x, "Index").unwrap())) as u16;
                assert_eq!(p.index, index, "{who}: {tag}");
                let sm = x.attribute("Sm").map_or(0xFF, num) as u8;
                assert_eq!(p.sync_manager, sm, "{who}: {tag} 0x{index:04X}");
                let pname = child(*x, "Name").map(text).unwrap_or_default();
                assert_eq!(
                    back.string(p.name_idx).unwrap_or(""),
                    pname,
                    "{who}: {tag} 0x{index:04X}"
                );
                let entries: Vec<Node> = children(*x, "Entry").collect();
                assert_eq!(p.entries.len(), entries.len(), "{who}: {tag} 0x{index:04X}");
                for (ex, e) in entries.iter().zip(&p.entries) {
                    let what = format!("{who}: {tag} 0x{index:04X}");
                    assert_eq!(e.index, num(&text(child(*ex, "Index").unwrap())) as u16);
                    let sub = child(*ex, "SubIndex").map_or(0, |s| num(&text(s))) as u8;
                    assert_eq!(e.sub_index, sub, "{what}");
                    let bits = num(&text(child(*ex, "BitLen").unwrap())) as u8;
                    assert_eq!(e.bit_len, bits, "{what}");
                    if let Some(n) = child(*ex, "Name") {
                        assert_eq!(back.string(e.name_idx), Some(text(n).as_str()), "{what}");
                    }
                    let dt = child(*ex, "DataType").map(text).unwrap_or_default();
                    let code = match dt.as_str() {
                        "SINT" => 2,
                        "INT" => 3,
                        "DINT" => 4,
                        "USINT" => 5,
                        "UINT" => 6,
                        "UDINT" => 7,
                        "ULINT" => 0x1B,
                        _ => e.data_type,
                    };
                    assert_eq!(e.data_type, code, "{what}: {dt}");
                }
            }
        }

        // DC op modes
        let modes: Vec<Node> = child(dev, "Dc")
            .map(|dc| children(dc, "OpMode").collect())
            .unwrap_or_default();
        assert_eq!(back.dc_op_modes().len(), modes.len(), "{who}: DC");
        for (x, m) in modes.iter().zip(back.dc_op_modes()) {
            let name = text(child(*x, "Name").unwrap());
            assert_eq!(back.string(m.name_idx), Some(name.as_str()), "{who}");
            let aa = num(&text(child(*x, "AssignActivate").unwrap())) as u16;
            assert_eq!(m.assign_activate, aa, "{who}: {name}");
            if let Some(s) = child(*x, "ShiftTimeSync0") {
                assert_eq!(m.shift_time_0 as i32 as i64, num(&text(s)), "{who}: {name}");
            }
        }

        // FMMUs
        let fmmus: Vec<u8> = children(dev, "Fmmu")
            .map(|f| match text(f).as_str() {
                "Outputs" => 1,
                "Inputs" => 2,
                "MBoxState" => 3,
                _ => 0,
            })
            .collect();
        // an odd count is padded with one unused FMMU to a whole word
        let got = back.fmmus();
        assert_eq!(&got[..fmmus.len()], &fmmus[..], "{who}: FMMU");
        assert!(
            got[fmmus.len()..].iter().all(|&u| u == 0),
            "{who}: FMMU pad"
        );
        assert!(got.len() - fmmus.len() <= 1, "{who}: FMMU pad");

        // the padded image fits the declared EEPROM
        let padded = sii::encode_padded(&content).unwrap();
        assert_eq!(padded.len(), bytes, "{who}");
    }
    n
}

#[test]
fn every_repository_esi_device_round_trips_through_sii() {
    let mut devices = 0;
    for f in esi_files() {
        devices += check_file(&f);
    }
    assert!(devices >= 5, "{devices} devices");
}

#[test]
fn vendor_esi_device_round_trips_through_sii() {
    let Some(path) = vendor_file("vendor_esi_device_round_trips_through_sii") else {
        return;
    };
    assert_eq!(check_file(&path), 1);
}

#[test]
fn vendor_device_facts() {
    let Some(path) = vendor_file("vendor_device_facts") else {
        return;
    };
    // By hand from ingenia-evs-net-ecat402-drive.xml: Type ProductCode="61935618"
    // RevisionNo="327685", MBoxOut #x1000 / 128, MBoxIn #x1400 / 128, EoE + CoE + FoE,
    // ByteSize 16384, ConfigData 080E 02EE 409C, BootStrap 0010 8000 0014 8000.
    let file = esi::load(path).unwrap();
    let d = file.device_by_product(61_935_618).unwrap();
    let c = to_sii::sii_from_device(&file, d).unwrap();
    let back = sii::decode(&sii::encode(&c).unwrap()).unwrap();
    let h = &back.header;
    assert_eq!(h.vendor_id, 0x29C);
    assert_eq!(h.revision, 327_685);
    assert_eq!(
        (h.standard_mailbox.rx_offset, h.standard_mailbox.rx_size),
        (0x1000, 128)
    );
    assert_eq!(
        (h.standard_mailbox.tx_offset, h.standard_mailbox.tx_size),
        (0x1400, 128)
    );
    assert_eq!(
        h.mailbox_protocols,
        sii::mailbox_protocols::EOE | sii::mailbox_protocols::COE | sii::mailbox_protocols::FOE
    );
    assert_eq!(h.eeprom_size, 127);
    assert_eq!((h.pdi_control, h.pdi_config), (0x0E08, 0xEE02));
    assert_eq!(h.sync_impulse_len, 0x9C40);
    assert_eq!(
        h.bootstrap_mailbox,
        sii::MailboxLayout {
            rx_offset: 0x1000,
            rx_size: 0x80,
            tx_offset: 0x1400,
            tx_size: 0x80,
        }
    );
    let g = back.general().unwrap();
    assert_eq!(back.string(g.order_idx), Some("EVS-NET-01"));
    assert_eq!(g.coe_details, 0x01 | 0x02 | 0x04 | 0x08 | 0x20);
    assert_eq!((g.foe_details, g.eoe_details), (1, 1));
    assert_eq!(g.flags, sii::general_flags::MBOX_DLL);
    // DCSync: ShiftTimeSync0 -3 ns
    let dc = back.dc_op_modes();
    assert_eq!(dc.len(), 2);
    assert_eq!(dc[1].assign_activate, 0x0300);
    assert_eq!(
        dc[1].shift_time_0,
        u32::from_le_bytes((-3i32).to_le_bytes())
    );
    assert_eq!(back.string(dc[1].name_idx), Some("DCSync"));
}

#[test]
fn servo_device_facts() {
    // By hand from esi/fieldprobe-cia402-servo.xml.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("esi/fieldprobe-cia402-servo.xml");
    let file = esi::load(path).unwrap();
    let d = file.device_by_product(0x0001_0402).unwrap();
    let c = to_sii::sii_from_device(&file, d).unwrap();
    let back = sii::decode(&sii::encode(&c).unwrap()).unwrap();
    assert_eq!(back.header.vendor_id, 0xFB0);
    assert_eq!(back.header.mailbox_protocols, sii::mailbox_protocols::COE);
    let sms = back.sync_managers();
    assert_eq!(
        sms.iter().map(|s| s.sm_type).collect::<Vec<_>>(),
        [1, 2, 3, 4]
    );
    assert_eq!(
        (sms[2].start, sms[2].length, sms[2].control),
        (0x1100, 9, 0x64)
    );
    let rx: Vec<_> = back.rx_pdos().collect();
    assert_eq!(rx[0].index, 0x1600);
    assert_eq!(rx[0].sync_manager, 2);
    assert_eq!(
        rx[0]
            .entries
            .iter()
            .map(|e| (e.index, e.bit_len))
            .collect::<Vec<_>>(),
        [(0x6040, 16), (0x607A, 32), (0x6060, 8), (0x60B8, 16)]
    );
    let tx: Vec<_> = back.tx_pdos().collect();
    assert_eq!(
        tx[0]
            .entries
            .iter()
            .map(|e| u32::from(e.bit_len))
            .sum::<u32>(),
        31 * 8
    );
    assert_eq!(back.general().unwrap().ds402_channels, 1);
}
