//! ESI (ETG.2000 XML) parser: a real vendor file, the emulator's own files in `esi/` against the
//! drive files in `drives/`, malformed input, and robustness against arbitrary bytes.
//!
//! Expected values of the vendor file are read from its XML text by hand (line numbers in the
//! comments), not taken from a parser run.

use fieldprobe::esi::{self, Access, EsiError, FmmuKind, PdoMapping, Problem, SmKind};
use std::path::{Path, PathBuf};

use crate::common::test_data;
use test_data::test_data;

/// The vendor file, in `../shared/test-data/`.
const INGENIA: &str = "esi/ingenia-evs-net-ecat402-drive.xml";

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The vendor file's text; `None`: absent, `test` skips (see `common/test_data.rs`).
fn ingenia_text(test: &str) -> Option<String> {
    let path = test_data(INGENIA, test)?;
    Some(std::fs::read_to_string(path).expect("vendor ESI test file"))
}

/// The vendor file, parsed; `None` as [`ingenia_text`].
fn ingenia(test: &str) -> Option<esi::EsiFile> {
    Some(esi::load(test_data(INGENIA, test)?).expect("vendor ESI parses"))
}

// ---------------------------------------------------------------------------------------------
// Real vendor file
// ---------------------------------------------------------------------------------------------

#[test]
fn ingenia_vendor_and_identity() {
    let Some(f) = ingenia("ingenia_vendor_and_identity") else {
        return;
    };
    // <Vendor><Id>#x0000029c</Id><Name>Ingenia</Name>
    assert_eq!(f.vendor.id, 0x29C);
    assert_eq!(f.vendor.name, "Ingenia");
    // <Group><Type>Servo Drives</Type><Name LcId="1033">EtherCAT Servo Drive</Name>
    assert_eq!(f.groups.len(), 1);
    assert_eq!(f.groups[0].group_type, "Servo Drives");
    assert_eq!(f.groups[0].names[0].lcid, Some(1033));
    assert_eq!(f.groups[0].names[0].text, "EtherCAT Servo Drive");
    assert_eq!(f.devices.len(), 1);
    let d = &f.devices[0];
    // <Device Physics="YY"><Type ProductCode="61935618" RevisionNo="327685">EVS-NET-01</Type>
    assert_eq!(d.physics.as_deref(), Some("YY"));
    assert_eq!(d.product_code, 61_935_618);
    assert_eq!(d.revision_no, 327_685);
    assert_eq!(d.type_name, "EVS-NET-01");
    // <Name LcId="1031">EVS-NET-01</Name>
    assert_eq!(d.names.len(), 1);
    assert_eq!(d.names[0].lcid, Some(1031));
    assert_eq!(d.name(), "EVS-NET-01");
    assert_eq!(d.group.as_deref(), Some("Servo Drives"));
    assert!(f.device(61_935_618, 327_685).is_some());
    assert!(f.device(61_935_618, 1).is_none());
}

#[test]
fn ingenia_sync_managers_and_fmmus() {
    let Some(f) = ingenia("ingenia_sync_managers_and_fmmus") else {
        return;
    };
    let d = &f.devices[0];
    assert_eq!(
        d.fmmus,
        vec![FmmuKind::Outputs, FmmuKind::Inputs, FmmuKind::MBoxState]
    );
    assert_eq!(d.sync_managers.len(), 4);
    // <Sm MinSize="34" MaxSize="256" DefaultSize="128" StartAddress="#x1000" ControlByte="#x26" Enable="1">MBoxOut</Sm>
    let sm0 = &d.sync_managers[0];
    assert_eq!(sm0.kind, SmKind::MBoxOut);
    assert_eq!(sm0.start_address, 0x1000);
    assert_eq!(sm0.default_size, Some(128));
    assert_eq!(sm0.min_size, Some(34));
    assert_eq!(sm0.max_size, Some(256));
    assert_eq!(sm0.control_byte, 0x26);
    assert!(sm0.enable);
    assert_eq!(d.sync_managers[1].kind, SmKind::MBoxIn);
    assert_eq!(d.sync_managers[1].start_address, 0x1400);
    assert_eq!(d.sync_managers[1].control_byte, 0x22);
    // <Sm DefaultSize="11" StartAddress="#x1800" ControlByte="#x64" Enable="1">Outputs</Sm>
    let (n, out) = d.sync_manager(&SmKind::Outputs).unwrap();
    assert_eq!(n, 2);
    assert_eq!(out.start_address, 0x1800);
    assert_eq!(out.default_size, Some(11));
    assert_eq!(out.control_byte, 0x64);
    assert_eq!(out.min_size, None);
    // <Sm DefaultSize="11" StartAddress="#x1c00" ControlByte="#x20" Enable="1">Inputs</Sm>
    let (n, inp) = d.sync_manager(&SmKind::Inputs).unwrap();
    assert_eq!(n, 3);
    assert_eq!(inp.start_address, 0x1C00);
    assert_eq!(inp.control_byte, 0x20);
}

#[test]
fn ingenia_pdos() {
    let Some(f) = ingenia("ingenia_pdos") else {
        return;
    };
    let d = &f.devices[0];
    assert_eq!(d.rx_pdos.len(), 3);
    assert_eq!(d.tx_pdos.len(), 3);
    let idx: Vec<u16> = d.rx_pdos.iter().map(|p| p.index).collect();
    assert_eq!(idx, [0x1600, 0x1601, 0x1602]);
    let idx: Vec<u16> = d.tx_pdos.iter().map(|p| p.index).collect();
    assert_eq!(idx, [0x1A00, 0x1A01, 0x1A02]);

    // <RxPdo Fixed="0" Sm="2"> #x1600 "RPDO 1 mapping parameter", Exclude #x1601 #x1602
    let p = d.rx_pdo(0x1600).unwrap();
    assert_eq!(p.name, "RPDO 1 mapping parameter");
    assert_eq!(p.sm, Some(2));
    assert!(!p.fixed);
    assert!(!p.mandatory);
    assert_eq!(p.excludes, [0x1601, 0x1602]);
    assert_eq!(p.entries.len(), 4);
    let e = &p.entries[0];
    assert_eq!((e.index, e.subindex, e.bit_len), (0x6040, 0, 16));
    assert_eq!(e.name.as_deref(), Some("Control Word"));
    assert_eq!(e.data_type.as_deref(), Some("UINT"));
    let e = &p.entries[1];
    assert_eq!((e.index, e.subindex, e.bit_len), (0x607A, 0, 32));
    assert_eq!(e.name.as_deref(), Some("Position set-point"));
    assert_eq!(e.data_type.as_deref(), Some("DINT"));
    assert_eq!(e.mapping_value(), 0x607A_0020);
    let e = &p.entries[3];
    assert_eq!((e.index, e.bit_len), (0x6060, 8));
    assert_eq!(e.data_type.as_deref(), Some("SINT"));
    // 16 + 32 + 32 + 8 = 88 bits = the 11-byte Outputs SM
    assert_eq!(p.bit_len(), 88);
    // <RxPdo Fixed="0"> (no Sm): not assigned by default
    assert_eq!(d.rx_pdo(0x1601).unwrap().sm, None);
    assert_eq!(d.rx_pdo(0x1601).unwrap().entries.len(), 2);

    // <TxPdo Fixed="0" Sm="3"> #x1A00: 6041 (16), 6064 (32), 606c (32), 6061 (8)
    let p = d.tx_pdo(0x1A00).unwrap();
    assert_eq!(p.name, "TPDO 1 mapping parameter");
    assert_eq!(p.sm, Some(3));
    let got: Vec<(u16, u8, u16)> = p
        .entries
        .iter()
        .map(|e| (e.index, e.subindex, e.bit_len))
        .collect();
    assert_eq!(
        got,
        [
            (0x6041, 0, 16),
            (0x6064, 0, 32),
            (0x606C, 0, 32),
            (0x6061, 0, 8)
        ]
    );
    assert_eq!(p.entries[2].name.as_deref(), Some("Actual velocity"));
    assert_eq!(d.tx_pdo(0x1A02).unwrap().excludes, [0x1A00, 0x1A01]);
}

#[test]
fn ingenia_mailbox_dc_eeprom() {
    let Some(f) = ingenia("ingenia_mailbox_dc_eeprom") else {
        return;
    };
    let d = &f.devices[0];
    // <Mailbox DataLinkLayer="true"><EoE /><CoE SdoInfo="true" CompleteAccess="true"
    //  PdoAssign="true" PdoConfig="true" PdoUpload="false" SegmentedSdo="true" /><FoE />
    let m = d.mailbox.as_ref().unwrap();
    assert!(m.data_link_layer);
    assert!(m.eoe && m.foe);
    assert!(!m.soe && !m.aoe && !m.voe);
    let coe = m.coe.as_ref().unwrap();
    assert!(coe.sdo_info && coe.complete_access && coe.pdo_assign && coe.pdo_config);
    assert!(coe.segmented_sdo);
    assert!(!coe.pdo_upload);

    assert_eq!(d.dc_op_modes.len(), 2);
    // <Name>Synchron</Name><Desc>SM-Synchron</Desc><AssignActivate>#x0</AssignActivate>
    // <CycleTimeSync0 Factor="1">0</CycleTimeSync0><ShiftTimeSync0>0</ShiftTimeSync0>
    let sm = d.dc_op_mode("Synchron").unwrap();
    assert_eq!(sm.desc.as_deref(), Some("SM-Synchron"));
    assert_eq!(sm.assign_activate, 0);
    let c0 = sm.cycle_time_sync0.unwrap();
    assert_eq!((c0.value, c0.factor), (0, Some(1)));
    let s0 = sm.shift_time_sync0.unwrap();
    assert_eq!((s0.value, s0.factor), (0, None));
    // <Name>DCSync</Name><AssignActivate>#x300</AssignActivate>
    // <ShiftTimeSync0 Factor="0">-3</ShiftTimeSync0><CycleTimeSync1 Factor="0">1</CycleTimeSync1>
    let dc = d.dc_op_mode("DCSync").unwrap();
    assert_eq!(dc.desc.as_deref(), Some("DC-Synchron"));
    assert_eq!(dc.assign_activate, 0x300);
    let s0 = dc.shift_time_sync0.unwrap();
    assert_eq!((s0.value, s0.factor), (-3, Some(0)));
    let c1 = dc.cycle_time_sync1.unwrap();
    assert_eq!((c1.value, c1.factor), (1, Some(0)));
    assert!(dc.shift_time_sync1.is_none());

    // <Eeprom><ByteSize>16384</ByteSize><ConfigData>080E02EE409C0000000000000000</ConfigData>
    // <BootStrap>0010800000148000</BootStrap>
    let e = d.eeprom.as_ref().unwrap();
    assert_eq!(e.byte_size, Some(16384));
    assert_eq!(
        e.config_data.as_deref(),
        Some(&[0x08, 0x0E, 0x02, 0xEE, 0x40, 0x9C, 0, 0, 0, 0, 0, 0, 0, 0][..])
    );
    assert_eq!(
        e.boot_strap.as_deref(),
        Some(&[0x00, 0x10, 0x80, 0x00, 0x00, 0x14, 0x80, 0x00][..])
    );
}

#[test]
fn ingenia_dictionary() {
    let Some(f) = ingenia("ingenia_dictionary") else {
        return;
    };
    let d = &f.devices[0];
    let p = d.profile.as_ref().unwrap();
    assert_eq!(p.profile_no, Some(402));
    let dict = d.dictionary().unwrap();
    // counted in the XML text: 42 <DataType> inside <DataTypes>, 583 <Object>
    assert_eq!(dict.data_types.len(), 42);
    assert_eq!(dict.objects.len(), 583);

    // <DataType><Name>DT1018</Name><BitSize>144</BitSize> SubItems 0..4
    let t = dict.data_type("DT1018").unwrap();
    assert_eq!(t.bit_size, 144);
    assert_eq!(t.subitems.len(), 5);
    assert_eq!(t.subitems[1].subindex, Some(1));
    assert_eq!(t.subitems[1].name, "Vendor ID");
    assert_eq!(t.subitems[1].type_name, "UDINT");
    assert_eq!(t.subitems[1].bit_size, 32);
    assert_eq!(t.subitems[1].bit_offs, 16);
    assert_eq!(t.subitems[1].flags.access, Some(Access::ReadOnly));
    // <Name>DT1011ARR</Name><BaseType>UDINT</BaseType><BitSize>32</BitSize>
    // <ArrayInfo><LBound>1</LBound><Elements>1</Elements>
    let a = dict.data_type("DT1011ARR").unwrap();
    assert_eq!(a.base_type.as_deref(), Some("UDINT"));
    assert_eq!(a.bit_size, 32);
    let ai = a.array.unwrap();
    assert_eq!((ai.lbound, ai.elements), (1, 1));
    // DT1600 sub 0: <Access WriteRestrictions="PreOP">rw</Access>
    let t = dict.data_type("DT1600").unwrap();
    assert_eq!(t.bit_size, 496);
    assert_eq!(t.subitems[0].flags.access, Some(Access::ReadWrite));
    assert_eq!(
        t.subitems[0].flags.write_restrictions.as_deref(),
        Some("PreOP")
    );

    // #x1000 Device Type UDINT 32 DefaultData 92010200, ro, Category m
    let o = d.object(0x1000).unwrap();
    assert_eq!(o.name, "Device Type");
    assert_eq!(o.type_name, "UDINT");
    assert_eq!(o.bit_size, 32);
    assert_eq!(
        o.default_data.as_deref(),
        Some(&[0x92, 0x01, 0x02, 0x00][..])
    );
    assert_eq!(o.default_u64(), Some(0x0002_0192));
    assert_eq!(o.flags.access, Some(Access::ReadOnly));
    assert_eq!(o.flags.category.as_deref(), Some("m"));
    // #x6065 Position following error window UDINT DefaultData 64000000 rw PdoMapping r
    let o = d.object(0x6065).unwrap();
    assert_eq!(o.name, "Position following error window");
    assert_eq!(o.default_u64(), Some(100));
    assert_eq!(o.flags.access, Some(Access::ReadWrite));
    assert_eq!(o.flags.pdo_mapping, Some(PdoMapping::Rx));
    // #x6060 Operation mode SINT 8, rw, r
    let o = d.object(0x6060).unwrap();
    assert_eq!((o.type_name.as_str(), o.bit_size), ("SINT", 8));
    assert!(o.flags.pdo_mapping.unwrap().rx());
    // #x58ea Monitoring remove data UINT, wo, no PdoMapping
    let o = d.object(0x58EA).unwrap();
    assert_eq!(o.name, "Monitoring remove data");
    assert_eq!(o.flags.access, Some(Access::WriteOnly));
    assert_eq!(o.flags.pdo_mapping, None);
    // #x1018 Identity Object DT1018 144: SubItem "Vendor ID" DefaultData 9c020000
    let o = d.object(0x1018).unwrap();
    assert_eq!(o.type_name, "DT1018");
    assert_eq!(o.default_data, None);
    assert_eq!(o.subitems.len(), 5);
    assert_eq!(o.subitems[0].default_u64(), Some(4));
    assert_eq!(o.subitems[1].name, "Vendor ID");
    assert_eq!(o.subitems[1].default_u64(), Some(0x29C));
    // #x1600 RxPDO Map 1: element 2 = 20007a60 = 0x607A0020
    let o = d.object(0x1600).unwrap();
    assert_eq!(o.name, "RxPDO Map 1");
    assert_eq!(o.subitems[2].default_u64(), Some(0x607A_0020));
}

// ---------------------------------------------------------------------------------------------
// Our own files in esi/ against drives/*.toml
// ---------------------------------------------------------------------------------------------

const VENDOR: u32 = 0x0FB0;

fn own(name: &str) -> esi::EsiFile {
    let f = esi::load(root().join("esi").join(name)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.vendor.id, VENDOR, "{name}");
    assert_eq!(f.vendor.name, "fieldprobe emulated devices");
    assert_eq!(f.devices.len(), 1, "{name}");
    f
}

/// `["0x6040:00", ...]` of a `[rxpdo]` / `[txpdo]` table, read with plain string handling.
fn toml_entries(path: &Path, table: &str) -> Vec<(u16, u8)> {
    let text = std::fs::read_to_string(path).unwrap();
    let start = text.find(&format!("[{table}]")).unwrap();
    let rest = &text[start..];
    let open = rest.find("entries = [").unwrap() + "entries = [".len();
    let close = open + rest[open..].find(']').unwrap();
    rest[open..close]
        .split(',')
        .map(|s| s.trim().trim_matches('"'))
        .filter(|s| !s.is_empty())
        .map(|s| {
            let (i, sub) = s.trim_start_matches("0x").split_once(':').unwrap();
            (
                u16::from_str_radix(i, 16).unwrap(),
                u8::from_str_radix(sub, 16).unwrap(),
            )
        })
        .collect()
}

/// Bit length of the CiA 402 objects the drive file maps (CiA 402-2 data types).
fn cia402_bits(index: u16) -> u16 {
    match index {
        0x6060 | 0x6061 => 8,
        0x6040 | 0x6041 | 0x60B8 | 0x60B9 | 0x6077 => 16,
        0x607A | 0x6064 | 0x60F4 | 0x60BA..=0x60BD => 32,
        other => panic!("unexpected object {other:#06x}"),
    }
}

#[test]
fn every_file_in_esi_parses() {
    let mut n = 0;
    for entry in std::fs::read_dir(root().join("esi")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("xml") {
            continue;
        }
        let f = esi::load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(f.vendor.id, VENDOR, "{}", path.display());
        for d in &f.devices {
            // every PDO with an Sm fits that sync manager's default size
            for p in d.rx_pdos.iter().chain(&d.tx_pdos) {
                if let Some(sm) = p.sm {
                    let sm = &d.sync_managers[usize::from(sm)];
                    let bytes = u32::from(sm.default_size.unwrap());
                    assert!(
                        p.bit_len() <= bytes * 8,
                        "{}: {:#06x}",
                        path.display(),
                        p.index
                    );
                }
            }
        }
        n += 1;
    }
    assert_eq!(n, 5);
}

#[test]
fn cia402_servo_matches_drive_file() {
    let f = own("fieldprobe-cia402-servo.xml");
    let d = &f.devices[0];
    let drive = root().join("drives/cia402-generic.toml");
    for (table, pdo) in [("rxpdo", d.rx_pdo(0x1600)), ("txpdo", d.tx_pdo(0x1A00))] {
        let pdo = pdo.unwrap();
        let want = toml_entries(&drive, table);
        let got: Vec<(u16, u8)> = pdo.entries.iter().map(|e| (e.index, e.subindex)).collect();
        assert_eq!(got, want, "{table}");
        let mut bits = 0u32;
        for e in &pdo.entries {
            assert_eq!(e.bit_len, cia402_bits(e.index), "{:#06x}", e.index);
            bits += u32::from(cia402_bits(e.index));
        }
        // the SM sized for the PDO
        let sm = &d.sync_managers[usize::from(pdo.sm.unwrap())];
        assert_eq!(u32::from(sm.default_size.unwrap()) * 8, bits, "{table}");
    }
    // 16 + 32 + 8 + 16 = 72 bits; 16 + 32 + 32 + 8 + 16 + 4·32 + 16 = 248 bits
    assert_eq!(d.rx_pdo(0x1600).unwrap().bit_len(), 72);
    assert_eq!(d.tx_pdo(0x1A00).unwrap().bit_len(), 248);
    assert_eq!(d.sync_managers[2].kind, SmKind::Outputs);
    assert_eq!(d.sync_managers[3].kind, SmKind::Inputs);

    let coe = d.mailbox.as_ref().unwrap().coe.as_ref().unwrap();
    assert!(coe.sdo_info && coe.segmented_sdo);
    let dc = d.dc_op_mode("DcSync").unwrap();
    assert_eq!(dc.assign_activate, 0x300);

    // dictionary: every mapped object exists, is PDO-mappable in the right direction and has
    // the size of the PDO entry
    let dict = d.dictionary().unwrap();
    for (pdo, rx) in [
        (d.rx_pdo(0x1600).unwrap(), true),
        (d.tx_pdo(0x1A00).unwrap(), false),
    ] {
        for e in &pdo.entries {
            let o = dict.object(e.index).unwrap();
            assert_eq!(o.bit_size, u32::from(e.bit_len), "{:#06x}", e.index);
            assert_eq!(Some(o.type_name.as_str()), e.data_type.as_deref());
            let m = o.flags.pdo_mapping.unwrap();
            assert!(if rx { m.rx() } else { m.tx() }, "{:#06x}", e.index);
            let access = o.flags.access.unwrap();
            if rx {
                assert_eq!(access, Access::ReadWrite);
            } else {
                assert_eq!(access, Access::ReadOnly);
            }
        }
    }
    // the mapping objects' defaults are the PDO entries (CiA 301 index·sub·length)
    for (map, pdo) in [(0x1600, d.rx_pdo(0x1600)), (0x1A00, d.tx_pdo(0x1A00))] {
        let pdo = pdo.unwrap();
        let o = dict.object(map).unwrap();
        assert_eq!(o.subitems[0].default_u64(), Some(pdo.entries.len() as u64));
        for (k, e) in pdo.entries.iter().enumerate() {
            assert_eq!(
                o.subitems[k + 1].default_u64(),
                Some(u64::from(e.mapping_value()))
            );
        }
    }
    // further objects with CiA 301 / 402 types, access and defaults from the drive file
    let check = |index: u16, ty: &str, access: Access, default: Option<u64>| {
        let o = dict.object(index).unwrap_or_else(|| panic!("{index:#06x}"));
        assert_eq!(o.type_name, ty, "{index:#06x}");
        assert_eq!(o.flags.access, Some(access), "{index:#06x}");
        if default.is_some() {
            assert_eq!(o.default_u64(), default, "{index:#06x}");
        }
    };
    check(0x1000, "UDINT", Access::ReadOnly, Some(0x0002_0192));
    check(0x6065, "UDINT", Access::ReadWrite, Some(300_000));
    check(0x6066, "UINT", Access::ReadWrite, Some(10));
    check(0x6072, "UINT", Access::ReadWrite, Some(3000));
    check(0x60E0, "UINT", Access::ReadWrite, None);
    check(0x60E1, "UINT", Access::ReadWrite, None);
    for i in 0x60D5..=0x60D8 {
        check(i, "UINT", Access::ReadOnly, Some(0));
    }
    // 0x1018 identity = the ESI identity
    let id = dict.object(0x1018).unwrap();
    assert_eq!(id.subitems[1].default_u64(), Some(u64::from(VENDOR)));
    assert_eq!(
        id.subitems[2].default_u64(),
        Some(u64::from(d.product_code))
    );
    assert_eq!(id.subitems[3].default_u64(), Some(u64::from(d.revision_no)));
    // 0x60D0 touch probe source: record USINT + 2 × INT, sources rw
    let t = dict
        .data_type(&dict.object(0x60D0).unwrap().type_name)
        .unwrap();
    let subs: Vec<(&str, Option<Access>)> = t
        .subitems
        .iter()
        .map(|s| (s.type_name.as_str(), s.flags.access))
        .collect();
    assert_eq!(
        subs,
        [
            ("USINT", Some(Access::ReadOnly)),
            ("INT", Some(Access::ReadWrite)),
            ("INT", Some(Access::ReadWrite))
        ]
    );
}

#[test]
fn ax5000_matches_drive_file() {
    let f = own("fieldprobe-ax5000-sercos.xml");
    let d = &f.devices[0];
    let m = d.mailbox.as_ref().unwrap();
    assert!(m.soe);
    assert!(m.coe.is_none());
    // IDN numbers from drives/sercos-ax5000.toml: MDT = S-0-0134 + mdt list, AT = S-0-0135 + at
    let text = std::fs::read_to_string(root().join("drives/sercos-ax5000.toml")).unwrap();
    let list = |key: &str| -> Vec<u16> {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{key} = [")))
            .unwrap();
        line.split('"')
            .filter(|s| s.starts_with("S-0-"))
            .map(|s| s[4..].parse().unwrap())
            .collect()
    };
    let mut mdt = vec![134];
    mdt.extend(list("mdt"));
    let mut at = vec![135];
    at.extend(list("at"));
    assert_eq!(mdt, [134, 47]);
    assert_eq!(at, [135, 51, 189, 130, 179]);
    // bit lengths: control / status word and S-0-0179 16 bit, the positions 32 bit
    let bits = |idn: u16| {
        if matches!(idn, 134 | 135 | 179) {
            16
        } else {
            32
        }
    };
    let rx = d.rx_pdo(0x1600).unwrap();
    let tx = d.tx_pdo(0x1A00).unwrap();
    let got: Vec<(u16, u16)> = rx.entries.iter().map(|e| (e.index, e.bit_len)).collect();
    let want: Vec<(u16, u16)> = mdt.iter().map(|&i| (i, bits(i))).collect();
    assert_eq!(got, want);
    let got: Vec<(u16, u16)> = tx.entries.iter().map(|e| (e.index, e.bit_len)).collect();
    let want: Vec<(u16, u16)> = at.iter().map(|&i| (i, bits(i))).collect();
    assert_eq!(got, want);
    // 2 + 4 = 6 bytes MDT, 2 + 4 + 4 + 4 + 2 = 16 bytes AT
    assert_eq!(d.sync_managers[2].default_size, Some(6));
    assert_eq!(d.sync_managers[3].default_size, Some(16));
    assert_eq!(rx.sm, Some(2));
    assert_eq!(tx.sm, Some(3));
}

#[test]
fn el5101_matches_terminal_image() {
    let f = own("fieldprobe-el5101.xml");
    let d = &f.devices[0];
    assert!(d.mailbox.is_none());
    // src/drive/terminal.rs: output = control u8, set value u16, velocity i16, digital outputs u8
    let rx: Vec<u16> = d.rx_pdos[0].entries.iter().map(|e| e.bit_len).collect();
    assert_eq!(rx, [8, 16, 16, 8]);
    // input = status u8, counter u16, latch u16, digital inputs u8
    let tx: Vec<u16> = d.tx_pdos[0].entries.iter().map(|e| e.bit_len).collect();
    assert_eq!(tx, [8, 16, 16, 8]);
    assert_eq!(d.rx_pdos[0].entries[2].data_type.as_deref(), Some("INT"));
    let out_len = fieldprobe::drive::terminal::image::OUTPUT_LEN;
    let in_len = fieldprobe::drive::terminal::image::INPUT_LEN;
    assert_eq!(out_len, 6);
    assert_eq!(in_len, 6);
    let (_, out) = d.sync_manager(&SmKind::Outputs).unwrap();
    let (_, inp) = d.sync_manager(&SmKind::Inputs).unwrap();
    assert_eq!(usize::from(out.default_size.unwrap()), out_len);
    assert_eq!(usize::from(inp.default_size.unwrap()), in_len);
    assert_eq!(d.rx_pdos[0].bit_len() as usize, out_len * 8);
    assert_eq!(d.tx_pdos[0].bit_len() as usize, in_len * 8);
}

#[test]
fn el1252_matches_channel_layout() {
    let f = own("fieldprobe-el1252.xml");
    let d = &f.devices[0];
    assert!(d.rx_pdos.is_empty());
    assert_eq!(d.tx_pdos.len(), 2);
    let ch = fieldprobe::drive::el1252::CHANNEL_LEN;
    assert_eq!(ch, 17);
    for p in &d.tx_pdos {
        // status u8 + LatchPosR u64 + LatchNegR u64
        let bits: Vec<u16> = p.entries.iter().map(|e| e.bit_len).collect();
        assert_eq!(bits, [8, 64, 64]);
        assert_eq!(p.bit_len() as usize, ch * 8);
    }
    let (_, inp) = d.sync_manager(&SmKind::Inputs).unwrap();
    assert_eq!(usize::from(inp.default_size.unwrap()), 2 * ch);
}

#[test]
fn ek1100_has_nothing_cyclic() {
    let f = own("fieldprobe-ek1100.xml");
    let d = &f.devices[0];
    assert!(d.mailbox.is_none());
    assert!(d.rx_pdos.is_empty() && d.tx_pdos.is_empty());
    assert!(d.sync_managers.is_empty() && d.fmmus.is_empty());
}

#[test]
fn own_product_codes_are_distinct() {
    let mut codes: Vec<u32> = [
        "fieldprobe-cia402-servo.xml",
        "fieldprobe-ax5000-sercos.xml",
        "fieldprobe-el5101.xml",
        "fieldprobe-el1252.xml",
        "fieldprobe-ek1100.xml",
    ]
    .iter()
    .map(|n| own(n).devices[0].product_code)
    .collect();
    codes.sort_unstable();
    codes.dedup();
    assert_eq!(codes.len(), 5);
}

// ---------------------------------------------------------------------------------------------
// Malformed input
// ---------------------------------------------------------------------------------------------

const MINI_HEAD: &str = "<?xml version=\"1.0\"?>\n<EtherCATInfo>\n  <Vendor>\n    <Id>#x10</Id>\n  </Vendor>\n  <Descriptions>\n    <Devices>\n";
const MINI_TAIL: &str = "    </Devices>\n  </Descriptions>\n</EtherCATInfo>\n";

fn mini(device: &str) -> String {
    format!("{MINI_HEAD}{device}{MINI_TAIL}")
}

fn invalid(e: EsiError) -> (u32, String, Problem) {
    match e {
        EsiError::Invalid {
            line,
            path,
            problem,
            ..
        } => (line, path, problem),
        other => panic!("expected Invalid, got {other:?}"),
    }
}

#[test]
fn minimal_file_parses() {
    let f = esi::parse(
        &mini("      <Device>\n        <Type ProductCode=\"7\">X</Type>\n      </Device>\n"),
        "mini.xml",
    )
    .unwrap();
    assert_eq!(f.vendor.id, 0x10);
    assert_eq!(f.devices[0].product_code, 7);
    assert_eq!(f.devices[0].revision_no, 0);
    assert_eq!(f.file, "mini.xml");
}

#[test]
fn not_xml() {
    let e = esi::parse("this is not xml", "x.xml").unwrap_err();
    assert!(matches!(e, EsiError::Xml { line: 1, .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.starts_with("x.xml:1:"), "{msg}");
    let e = esi::parse("", "empty.xml").unwrap_err();
    assert!(matches!(e, EsiError::Xml { .. }), "{e:?}");
}

#[test]
fn wrong_root() {
    let e = esi::parse("<?xml version=\"1.0\"?>\n<EtherCATModule/>", "m.xml").unwrap_err();
    let (line, path, problem) = invalid(e);
    assert_eq!(line, 2);
    assert_eq!(path, "EtherCATModule");
    assert!(matches!(problem, Problem::Unsupported(_)));
}

#[test]
fn missing_vendor() {
    let text = "<?xml version=\"1.0\"?>\n<EtherCATInfo>\n  <Descriptions/>\n</EtherCATInfo>\n";
    let e = esi::parse(text, "nv.xml").unwrap_err();
    let msg = e.to_string();
    let (line, path, problem) = invalid(e);
    assert_eq!(line, 2);
    assert_eq!(path, "EtherCATInfo");
    assert_eq!(problem, Problem::MissingElement("Vendor".into()));
    assert!(msg.contains("nv.xml:2:"), "{msg}");
    assert!(msg.contains("<Vendor>"), "{msg}");
}

#[test]
fn bad_hex_vendor_id() {
    let text = mini("").replace("#x10", "#xZZ");
    let e = esi::parse(&text, "bad.xml").unwrap_err();
    let msg = e.to_string();
    let (line, path, problem) = invalid(e);
    assert_eq!(line, 4);
    assert_eq!(path, "EtherCATInfo/Vendor/Id");
    assert_eq!(problem, Problem::BadNumber("#xZZ".into()));
    assert!(
        msg.contains("#xZZ") && msg.contains("EtherCATInfo/Vendor/Id"),
        "{msg}"
    );
}

#[test]
fn bad_hex_attribute() {
    let text =
        mini("      <Device>\n        <Type ProductCode=\"#xZZ\">X</Type>\n      </Device>\n");
    let (line, path, problem) = invalid(esi::parse(&text, "a.xml").unwrap_err());
    assert_eq!(line, 9);
    assert_eq!(path, "EtherCATInfo/Descriptions/Devices/Device/Type");
    assert_eq!(
        problem,
        Problem::BadAttribute("ProductCode".into(), "#xZZ".into())
    );
}

#[test]
fn pdo_entry_without_index() {
    let dev = "      <Device>
        <Type ProductCode=\"1\">X</Type>
        <RxPdo>
          <Index>#x1600</Index>
          <Entry>
            <Index>#x6040</Index>
            <BitLen>16</BitLen>
          </Entry>
          <Entry>
            <SubIndex>0</SubIndex>
            <BitLen>32</BitLen>
          </Entry>
        </RxPdo>
      </Device>
";
    let (line, path, problem) = invalid(esi::parse(&mini(dev), "e.xml").unwrap_err());
    // MINI_HEAD has 7 lines; the second <Entry> is line 7 + 9
    assert_eq!(line, 16);
    assert_eq!(
        path,
        "EtherCATInfo/Descriptions/Devices/Device/RxPdo/Entry[2]"
    );
    assert_eq!(problem, Problem::MissingElement("Index".into()));
}

#[test]
fn out_of_range_and_bad_values() {
    let dev = "      <Device>\n        <Type ProductCode=\"1\">X</Type>\n        <Sm StartAddress=\"#x10000\">Outputs</Sm>\n      </Device>\n";
    let (line, path, problem) = invalid(esi::parse(&mini(dev), "r.xml").unwrap_err());
    assert_eq!(line, 10);
    assert_eq!(path, "EtherCATInfo/Descriptions/Devices/Device/Sm");
    assert_eq!(
        problem,
        Problem::BadAttribute("StartAddress".into(), "#x10000".into())
    );

    let dev = "      <Device>\n        <Type ProductCode=\"1\">X</Type>\n        <Mailbox>\n          <CoE SdoInfo=\"maybe\"/>\n        </Mailbox>\n      </Device>\n";
    let (line, path, _) = invalid(esi::parse(&mini(dev), "b.xml").unwrap_err());
    assert_eq!(line, 11);
    assert_eq!(path, "EtherCATInfo/Descriptions/Devices/Device/Mailbox/CoE");

    let dev = "      <Device>\n        <Type ProductCode=\"1\">X</Type>\n        <TxPdo>\n          <Index>#x1A00</Index>\n          <Entry><Index>#x6041</Index><BitLen>70000</BitLen></Entry>\n        </TxPdo>\n      </Device>\n";
    let (line, path, problem) = invalid(esi::parse(&mini(dev), "o.xml").unwrap_err());
    assert_eq!(line, 12);
    assert_eq!(
        path,
        "EtherCATInfo/Descriptions/Devices/Device/TxPdo/Entry/BitLen"
    );
    assert_eq!(problem, Problem::OutOfRange("70000".into()));
}

#[test]
fn bad_access_in_vendor_file_names_line() {
    // corrupt one Access of the real file: line 3751 is #x6065's <Access>rw</Access>. An Access
    // text ETG.2000 does not define is no longer a refusal of the file (issue 25): the file
    // parses, the object reads as having no Access, and a warning names the line and path.
    let Some(text) = ingenia_text("bad_access_in_vendor_file_names_line") else {
        return;
    };
    let mut lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[3750].trim(), "<Access>rw</Access>");
    lines[3750] = "                  <Access>rx</Access>";
    let text = lines.join("\n");
    let f = esi::parse(&text, "i.xml").expect("an odd Access is a warning");
    assert_eq!(f.warnings.len(), 1, "{:?}", f.warnings);
    let w = &f.warnings[0];
    assert_eq!(w.line, 3751);
    assert!(
        w.path.starts_with(
            "EtherCATInfo/Descriptions/Devices/Device/Profile/Dictionary/Objects/Object["
        ),
        "{}",
        w.path
    );
    assert!(w.path.ends_with("]/Flags/Access"), "{}", w.path);
    assert_eq!(w.oddity, esi::Oddity::Access { text: "rx".into() });
    assert_eq!(
        w.subject.as_deref(),
        Some("device EVS-NET-01, object #x6065")
    );
    assert_eq!(f.devices[0].object(0x6065).unwrap().flags.access, None);
    let shown = w.to_string();
    assert!(shown.starts_with("i.xml:3751:"), "{shown}");
    assert!(shown.contains("Access \"rx\""), "{shown}");
}

#[test]
fn truncated_vendor_file() {
    let Some(text) = ingenia_text("truncated_vendor_file") else {
        return;
    };
    let cut = &text[..text.len() / 2];
    let e = esi::parse(cut, "t.xml").unwrap_err();
    // the error points at the end of what is there
    let last_line = cut.lines().count() as u32;
    assert_eq!(e.line(), Some(last_line), "{e}");
    assert!(matches!(e, EsiError::Xml { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("t.xml:{last_line}:")), "{msg}");
    // and names the elements open at the cut
    assert!(
        msg.contains("file ends inside EtherCATInfo/Descriptions/Devices/Device/Profile/Dictionary/Objects/Object"),
        "{msg}"
    );
}

#[test]
fn io_error_names_file() {
    let e = esi::load("/nonexistent/dir/x.xml").unwrap_err();
    assert!(matches!(e, EsiError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/dir/x.xml"));
}

#[test]
fn latin1_declared_file() {
    let bytes = b"<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>\n<EtherCATInfo><Vendor><Id>1</Id><Name>M\xFCller</Name></Vendor><Descriptions><Devices/></Descriptions></EtherCATInfo>".to_vec();
    let f = esi::parse_bytes(&bytes, "l.xml").unwrap();
    assert_eq!(f.vendor.name, "Müller");
    // undeclared non-UTF-8 is an encoding error
    let e = esi::parse_bytes(b"<a>\xFF</a>", "u.xml").unwrap_err();
    assert!(matches!(e, EsiError::Encoding { offset: 3, .. }), "{e:?}");
}

// ---------------------------------------------------------------------------------------------
// Robustness: no panics on arbitrary input
// ---------------------------------------------------------------------------------------------

#[test]
fn prefixes_of_vendor_file_never_panic() {
    let Some(text) = ingenia_text("prefixes_of_vendor_file_never_panic") else {
        return;
    };
    let n = 400;
    for k in 0..n {
        let mut cut = text.len() * k / n;
        while !text.is_char_boundary(cut) {
            cut -= 1;
        }
        let r = esi::parse(&text[..cut], "cut.xml");
        assert!(r.is_err(), "prefix {cut} parsed");
    }
    assert!(esi::parse(&text, "full.xml").is_ok());
}

#[test]
fn element_removals_never_panic() {
    // drop one line at a few hundred places: well-formed or not, never a panic
    let Some(text) = ingenia_text("element_removals_never_panic") else {
        return;
    };
    let lines: Vec<&str> = text.lines().collect();
    for k in (0..lines.len()).step_by(lines.len() / 300) {
        let mut l = lines.clone();
        l.remove(k);
        let _ = esi::parse(&l.join("\n"), "drop.xml");
    }
}

#[test]
fn random_bytes_never_panic() {
    // xorshift: deterministic pseudo-random input
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let alphabet = b"<>/=\"#x0123456789ABZ EtherCATInfoVendorIdDeviceTypeRxPdoEntryIndex\n-";
    for _ in 0..500 {
        let len = (next() % 300) as usize;
        let raw: Vec<u8> = (0..len).map(|_| next() as u8).collect();
        let _ = esi::parse_bytes(&raw, "rnd.bin");
        let text: String = (0..len)
            .map(|_| char::from(alphabet[(next() % alphabet.len() as u64) as usize]))
            .collect();
        let _ = esi::parse(&text, "rnd.xml");
        let _ = esi::parse(&mini(&text), "rnd-dev.xml");
    }
}
