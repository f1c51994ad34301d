//! SII EEPROM images: decode the real Kollmorgen AKD dump, round-trip a CiA 402 servo, never
//! panic on damaged images, Intel HEX / hex dump readers.
//!
//! Expected values for the AKD image were read by hand from `xxd` of the dump (offsets noted next
//! to each assertion) and are re-checked against the raw bytes here, independently of the decoder.

use fieldprobe::esi::sii::{
    self, coe_details, data_type, fmmu_usage, general_flags, mailbox_protocols, sm_enable, sm_type,
    Category, DcOpMode, General, MailboxLayout, Pdo, PdoEntry, SiiContent, SiiError, SiiHeader,
    SyncManager,
};

use crate::common::test_data;
use test_data::test_data;

/// The AKD dump as stored; `None`: absent, `test` skips (see `common/test_data.rs`).
fn akd_raw(test: &str) -> Option<Vec<u8>> {
    let path = test_data("sii/kollmorgen-akd.hex", test)?;
    Some(std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
}

/// The AKD image, loaded; `None` as [`akd_raw`].
fn akd(test: &str) -> Option<Vec<u8>> {
    Some(sii::load_image(&akd_raw(test)?).expect("load AKD image"))
}

fn raw16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn raw32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// Offset of the End marker, found by walking the category chain by hand (independent of the
/// decoder), plus the category types met on the way.
fn walk_chain(b: &[u8]) -> (Vec<(usize, u16)>, usize) {
    let mut at = 0x80;
    let mut seen = Vec::new();
    while raw16(b, at) != 0xFFFF {
        seen.push((at, raw16(b, at)));
        at += 4 + 2 * usize::from(raw16(b, at + 2));
    }
    (seen, at)
}

#[test]
fn akd_file_is_raw_binary_and_loads_unchanged() {
    let Some(raw) = akd_raw("akd_file_is_raw_binary_and_loads_unchanged") else {
        return;
    };
    assert_eq!(raw.len(), 2048);
    assert_eq!(sii::load_image(&raw).expect("load AKD image"), raw);
}

#[test]
fn akd_header_identity_from_raw_bytes() {
    let Some(b) = akd("akd_header_identity_from_raw_bytes") else {
        return;
    };
    let c = sii::decode(&b).expect("decode AKD");
    let h = &c.header;
    // Hand-read: 0x10 "6a00 0000", 0x14 "444b 4100" ("DKA"), 0x18 "0200 0000", 0x1C "9300 8399".
    assert_eq!(raw32(&b, 0x10), 0x0000_006A);
    assert_eq!(raw32(&b, 0x14), 0x0041_4B44);
    assert_eq!(raw32(&b, 0x18), 2);
    assert_eq!(raw32(&b, 0x1C), 0x9983_0093);
    assert_eq!(h.vendor_id, raw32(&b, 0x10));
    assert_eq!(h.product_code, raw32(&b, 0x14));
    assert_eq!(h.revision, raw32(&b, 0x18));
    assert_eq!(h.serial, raw32(&b, 0x1C));
    assert_eq!(h.vendor_id, 0x6A);
    assert_eq!(h.product_code, 0x0041_4B44);
    assert_eq!(h.revision, 2);
    // PDI control 0x0009, PDI config 0x0800 (bytes 0..4 "0900 0008").
    assert_eq!(h.pdi_control, 0x0009);
    assert_eq!(h.pdi_config, 0x0800);
    // Bootstrap mailbox words 0x14..0x18 (bytes 0x28..0x30), standard 0x18..0x1C (0x30..0x38):
    // both "0018 0004 001c 0004".
    let mb = MailboxLayout {
        rx_offset: 0x1800,
        rx_size: 0x0400,
        tx_offset: 0x1C00,
        tx_size: 0x0400,
    };
    assert_eq!(h.bootstrap_mailbox, mb);
    assert_eq!(h.standard_mailbox, mb);
    assert_eq!(raw16(&b, 0x30), 0x1800);
    assert_eq!(raw16(&b, 0x36), 0x0400);
    // Protocols word 0x1C (byte 0x38) = 0x000E: EoE | CoE | FoE.
    assert_eq!(raw16(&b, 0x38), 0x000E);
    assert_eq!(
        h.mailbox_protocols,
        mailbox_protocols::EOE | mailbox_protocols::COE | mailbox_protocols::FOE
    );
    // Size word 0x3E (byte 0x7C) = 0x000F → 16 * 128 = 2048 bytes; version word 0x3F = 1.
    assert_eq!(h.eeprom_size, 0x000F);
    assert_eq!(h.eeprom_size_bytes(), 2048);
    assert_eq!(h.version, 1);
}

#[test]
fn akd_header_crc_matches_crc8() {
    let Some(b) = akd("akd_header_crc_matches_crc8") else {
        return;
    };
    // Stored checksum: low byte of word 7 (byte 14) = 0x10, high byte 0.
    assert_eq!(b[14], 0x10);
    assert_eq!(b[15], 0x00);
    assert_eq!(sii::crc8(&b[..14]), b[14]);
    assert_eq!(sii::header_checksum(&b), Some(0x10));
    // And the encoder writes the same checksum for the decoded header.
    let c = sii::decode(&b).unwrap();
    let enc = sii::encode(&c).unwrap();
    assert_eq!(&enc[..16], &b[..16]);
}

#[test]
fn akd_category_chain_and_strings() {
    let Some(b) = akd("akd_category_chain_and_strings") else {
        return;
    };
    let c = sii::decode(&b).unwrap();
    let (chain, end) = walk_chain(&b);
    // Hand-read: 0x80 vendor 0x0800 (10 words), 0x98 vendor 0x0801 (6 words), 0xA8 Strings
    // (0xEF words), 0x28A General, 0x2AE FMMU, 0x2B6 SM, 0x2DA SyncUnit(43), 0x2E0 TxPDO,
    // 0x4EC RxPDO, 0x660 DC, End at 0x694.
    let types: Vec<u16> = chain.iter().map(|&(_, t)| t).collect();
    assert_eq!(types, [0x0800, 0x0801, 10, 30, 40, 41, 43, 50, 51, 60]);
    let offsets: Vec<usize> = chain.iter().map(|&(o, _)| o).collect();
    assert_eq!(
        offsets,
        [0x80, 0x98, 0xA8, 0x28A, 0x2AE, 0x2B6, 0x2DA, 0x2E0, 0x4EC, 0x660]
    );
    assert_eq!(end, 0x694);
    let decoded_types: Vec<u16> = c.categories.iter().map(Category::type_code).collect();
    assert_eq!(decoded_types, types);

    // Vendor-specific categories are kept raw: order code and firmware version text.
    assert_eq!(&b[0x84..0x98], b"AKD-P00606-NBCC-E000");
    assert_eq!(
        c.categories[0],
        Category::Unknown {
            category_type: 0x0800,
            data: b"AKD-P00606-NBCC-E000".to_vec()
        }
    );
    assert_eq!(
        c.categories[1],
        Category::Unknown {
            category_type: 0x0801,
            data: b"01-20-00-003".to_vec()
        }
    );
    assert_eq!(
        c.categories[6],
        Category::Unknown {
            category_type: 43,
            data: vec![0xF0, 0xFF]
        }
    );

    // Strings: count byte 0x21 at 0xAC; "AKD" at 0xAE (len 3 at 0xAD); string 4 (len 0x18 at
    // 0xBE) "AKD EtherCAT Drive (CoE)" at 0xBF.
    assert_eq!(b[0xAC], 0x21);
    assert_eq!(b[0xAD], 3);
    assert_eq!(&b[0xAE..0xB1], b"AKD");
    assert_eq!(b[0xBE], 0x18);
    assert_eq!(&b[0xBF..0xBF + 0x18], b"AKD EtherCAT Drive (CoE)");
    assert_eq!(c.strings().len(), 0x21);
    assert_eq!(c.string(1), Some("AKD"));
    assert_eq!(c.string(2), Some("Drive"));
    assert_eq!(c.string(3), Some("Drives"));
    assert_eq!(c.string(4), Some("AKD EtherCAT Drive (CoE)"));
    assert_eq!(c.string(9), Some("Statusword"));
    assert_eq!(c.string(24), Some("Controlword"));
    assert_eq!(c.string(0), None);
    assert_eq!(c.string(0x22), None);
}

#[test]
fn akd_general_fmmu_sm() {
    let Some(b) = akd("akd_general_fmmu_sm") else {
        return;
    };
    let c = sii::decode(&b).unwrap();
    // General data at 0x28E: "0205 0104 010d 0103 0001 0005 0000 0300 1100".
    let g = c.general().expect("General");
    assert_eq!(
        &b[0x28E..0x2A0],
        &[
            0x02, 0x05, 0x01, 0x04, 0x01, 0x0D, 0x01, 0x03, 0x00, 0x01, 0x00, 0x05, 0x00, 0x00,
            0x03, 0x00, 0x11, 0x00
        ]
    );
    assert_eq!(g.group_idx, 2);
    assert_eq!(g.order_idx, 1);
    assert_eq!(g.name_idx, 4);
    assert_eq!(c.string(g.order_idx), Some("AKD"));
    assert_eq!(c.string(g.name_idx), Some("AKD EtherCAT Drive (CoE)"));
    assert_eq!(
        g.coe_details,
        coe_details::SDO | coe_details::PDO_ASSIGN | coe_details::PDO_CONFIG
    );
    assert_eq!(g.foe_details, 1);
    assert_eq!(g.eoe_details, 3);
    assert_eq!(g.ds402_channels, 1);
    assert_eq!(
        g.flags,
        general_flags::ENABLE_SAFEOP | general_flags::MBOX_DLL
    );
    assert_eq!(g.current_on_ebus, 0);
    assert_eq!(g.physical_ports, 0x0011); // two MII ports

    // FMMU at 0x2AE: "2800 0200 0102 03ff".
    assert_eq!(c.fmmus(), &[0x01, 0x02, 0x03, 0xFF]);
    assert_eq!(c.fmmus(), &b[0x2B2..0x2B6]);

    // SyncManagers at 0x2BA (header "2900 1000" at 0x2B6), 8 bytes each.
    let sm = |start, length, control, ty| SyncManager {
        start,
        length,
        control,
        status: 0,
        enable: sm_enable::ENABLE,
        sm_type: ty,
    };
    assert_eq!(
        c.sync_managers(),
        &[
            sm(0x1800, 0x0400, 0x26, sm_type::MAILBOX_OUT),
            sm(0x1C00, 0x0400, 0x22, sm_type::MAILBOX_IN),
            sm(0x1100, 0, 0x24, sm_type::OUTPUTS),
            sm(0x1140, 0, 0x20, sm_type::INPUTS),
        ]
    );
    assert_eq!(raw16(&b, 0x2BA), 0x1800);
    assert_eq!(raw16(&b, 0x2D2), 0x1140);
}

#[test]
fn akd_pdos_and_dc() {
    let Some(b) = akd("akd_pdos_and_dc") else {
        return;
    };
    let c = sii::decode(&b).unwrap();
    // TxPDO data at 0x2E4: "001a 01ff 0008 0000" + entry "4160 0009 0610 0000".
    assert_eq!(raw16(&b, 0x2E4), 0x1A00);
    assert_eq!(raw16(&b, 0x2EC), 0x6041);
    let tx: Vec<&Pdo> = c.tx_pdos().collect();
    assert_eq!(
        *tx[0],
        Pdo {
            index: 0x1A00,
            sync_manager: 0xFF,
            dc_sync: 0,
            name_idx: 8,
            flags: 0,
            entries: vec![PdoEntry {
                index: 0x6041,
                sub_index: 0,
                name_idx: 9,
                data_type: data_type::UINT16,
                bit_len: 16,
                flags: 0
            }]
        }
    );
    assert_eq!(c.string(tx[0].name_idx), Some("Inputs"));
    assert_eq!(c.string(tx[0].entries[0].name_idx), Some("Statusword"));
    // Then 0x1A01..0x1A03 without entries, 0x1B01 with 2 entries on SM3, flags 0x0010
    // (0x30C: "011b 0203 0008 1000"), first entry 0x6063 INT32 "Position actual internal value".
    let idx: Vec<(u16, usize)> = tx
        .iter()
        .take(5)
        .map(|p| (p.index, p.entries.len()))
        .collect();
    assert_eq!(
        idx,
        [
            (0x1A00, 1),
            (0x1A01, 0),
            (0x1A02, 0),
            (0x1A03, 0),
            (0x1B01, 2)
        ]
    );
    assert_eq!(tx[4].sync_manager, 3);
    assert_eq!(tx[4].flags, 0x0010);
    assert_eq!(tx[4].entries[0].index, 0x6063);
    assert_eq!(tx[4].entries[0].data_type, data_type::INT32);
    assert_eq!(tx[4].entries[0].bit_len, 32);
    assert_eq!(
        c.string(tx[4].entries[0].name_idx),
        Some("Position actual internal value")
    );

    // RxPDO data at 0x4F0: "0016 01ff 0017 0000 4060 0018 0610 0000".
    assert_eq!(raw16(&b, 0x4F0), 0x1600);
    assert_eq!(raw16(&b, 0x4F8), 0x6040);
    let rx0 = c.rx_pdos().next().unwrap();
    assert_eq!(rx0.index, 0x1600);
    assert_eq!(c.string(rx0.name_idx), Some("Outputs"));
    assert_eq!(rx0.entries.len(), 1);
    assert_eq!(rx0.entries[0].index, 0x6040);
    assert_eq!(c.string(rx0.entries[0].name_idx), Some("Controlword"));
    // The last RxPDO entry before DC (0x658: "7260 001e 0610 0000"): 0x6072 "Max torque".
    let last = c.rx_pdos().last().unwrap();
    let e = last.entries.last().unwrap();
    assert_eq!(
        (e.index, e.data_type, e.bit_len),
        (0x6072, data_type::UINT16, 16)
    );
    assert_eq!(c.string(e.name_idx), Some("Max torque"));

    // DC at 0x664: two 24-byte op modes; AssignActivate 0x0300 at 0x672, SYNC0 factor 1 at
    // 0x674, name "DcSync" (6) at 0x676; second: AssignActivate 0, name "DcOff" (7) at 0x68E.
    assert_eq!(raw16(&b, 0x672), 0x0300);
    let dc = c.dc_op_modes();
    assert_eq!(dc.len(), 2);
    assert_eq!(
        dc[0],
        DcOpMode {
            assign_activate: 0x0300,
            sync0_cycle_factor: 1,
            name_idx: 6,
            ..DcOpMode::default()
        }
    );
    assert_eq!(c.string(dc[0].name_idx), Some("DcSync"));
    assert_eq!(dc[1].assign_activate, 0);
    assert_eq!(c.string(dc[1].name_idx), Some("DcOff"));
}

#[test]
fn akd_reencodes_byte_exact() {
    let Some(b) = akd("akd_reencodes_byte_exact") else {
        return;
    };
    let c = sii::decode(&b).unwrap();
    let enc = sii::encode(&c).unwrap();
    // Everything up to and including the End marker at 0x694.
    assert_eq!(enc.len(), 0x696);
    assert_eq!(enc, &b[..0x696]);
    let padded = sii::encode_padded(&c).unwrap();
    assert_eq!(padded.len(), 2048);
    // The AKD image is 0xFF-filled after the End marker.
    assert_eq!(padded, b);
    assert_eq!(sii::decode(&enc).unwrap(), c);
}

fn servo() -> SiiContent {
    let e = |index, data_type, bit_len| PdoEntry {
        index,
        sub_index: 0,
        name_idx: 0,
        data_type,
        bit_len,
        flags: 0,
    };
    use data_type::*;
    SiiContent {
        header: SiiHeader {
            pdi_control: 0x0080,
            pdi_config: 0x0000,
            station_alias: 0x0000,
            vendor_id: 0x0000_0F1E,
            product_code: 0x0402_0001,
            revision: 0x0001_0000,
            serial: 42,
            bootstrap_mailbox: MailboxLayout::default(),
            standard_mailbox: MailboxLayout {
                rx_offset: 0x1000,
                rx_size: 128,
                tx_offset: 0x1080,
                tx_size: 128,
            },
            mailbox_protocols: mailbox_protocols::COE,
            eeprom_size: 0x000F,
            version: 1,
            ..SiiHeader::default()
        },
        categories: vec![
            Category::Strings(
                ["FP402", "Drives", "FP402 servo", "RxPDO", "TxPDO"]
                    .map(String::from)
                    .to_vec(),
            ),
            Category::General(General {
                group_idx: 2,
                order_idx: 1,
                name_idx: 3,
                group_idx2: 2,
                coe_details: coe_details::SDO
                    | coe_details::SDO_INFO
                    | coe_details::PDO_ASSIGN
                    | coe_details::PDO_CONFIG
                    | coe_details::COMPLETE_ACCESS,
                ds402_channels: 1,
                flags: general_flags::ENABLE_SAFEOP,
                current_on_ebus: 0,
                physical_ports: 0x0011,
                ..General::default()
            }),
            Category::Fmmu(vec![
                fmmu_usage::OUTPUTS,
                fmmu_usage::INPUTS,
                fmmu_usage::SM_STATUS,
                fmmu_usage::UNUSED,
            ]),
            Category::SyncManagers(vec![
                SyncManager {
                    start: 0x1000,
                    length: 128,
                    control: 0x26,
                    status: 0,
                    enable: sm_enable::ENABLE,
                    sm_type: sm_type::MAILBOX_OUT,
                },
                SyncManager {
                    start: 0x1080,
                    length: 128,
                    control: 0x22,
                    status: 0,
                    enable: sm_enable::ENABLE,
                    sm_type: sm_type::MAILBOX_IN,
                },
                SyncManager {
                    start: 0x1100,
                    length: 0,
                    control: 0x64,
                    status: 0,
                    enable: sm_enable::ENABLE,
                    sm_type: sm_type::OUTPUTS,
                },
                SyncManager {
                    start: 0x1400,
                    length: 0,
                    control: 0x20,
                    status: 0,
                    enable: sm_enable::ENABLE,
                    sm_type: sm_type::INPUTS,
                },
            ]),
            Category::RxPdos(vec![Pdo {
                index: 0x1600,
                sync_manager: 2,
                dc_sync: 0,
                name_idx: 4,
                flags: 0,
                entries: vec![
                    e(0x6040, UINT16, 16),
                    e(0x607A, INT32, 32),
                    e(0x6060, INT8, 8),
                    e(0x60B8, UINT16, 16),
                ],
            }]),
            Category::TxPdos(vec![Pdo {
                index: 0x1A00,
                sync_manager: 3,
                dc_sync: 0,
                name_idx: 5,
                flags: 0,
                entries: vec![
                    e(0x6041, UINT16, 16),
                    e(0x6064, INT32, 32),
                    e(0x60F4, INT32, 32),
                    e(0x6061, INT8, 8),
                    e(0x60B9, UINT16, 16),
                    e(0x60BA, INT32, 32),
                    e(0x60BB, INT32, 32),
                    e(0x60BC, INT32, 32),
                    e(0x60BD, INT32, 32),
                    e(0x6077, INT16, 16),
                ],
            }]),
            Category::Dc(vec![DcOpMode {
                assign_activate: 0x0300,
                sync0_cycle_factor: 1,
                ..DcOpMode::default()
            }]),
        ],
    }
}

#[test]
fn servo_round_trip_and_layout() {
    let c = servo();
    let b = sii::encode(&c).unwrap();
    assert_eq!(sii::decode(&b).unwrap(), c);

    // Layout computed by hand from ETG.1000.6 Table 16 / ETG.2010:
    // header: alias word 4 at 0x08, checksum at 0x0E, vendor at 0x10, product at 0x14,
    // standard mailbox at 0x30, protocols at 0x38, size at 0x7C, version at 0x7E.
    assert_eq!(&b[0..2], &[0x80, 0x00]);
    assert_eq!(b[14], sii::crc8(&b[..14]));
    assert_eq!(&b[0x10..0x14], &[0x1E, 0x0F, 0x00, 0x00]);
    assert_eq!(&b[0x14..0x18], &[0x01, 0x00, 0x02, 0x04]);
    assert_eq!(
        &b[0x30..0x38],
        &[0x00, 0x10, 0x80, 0x00, 0x80, 0x10, 0x80, 0x00]
    );
    assert_eq!(&b[0x38..0x3A], &[0x04, 0x00]);
    assert_eq!(&b[0x7C..0x80], &[0x0F, 0x00, 0x01, 0x00]);
    // Strings at 0x80: 1 + (1+5) + (1+6) + (1+11) + (1+5) + (1+5) = 38 bytes = 19 words.
    assert_eq!(&b[0x80..0x84], &[10, 0, 19, 0]);
    assert_eq!(&b[0x84..0x8B], &[5, 5, b'F', b'P', b'4', b'0', b'2']);
    // General at 0x84 + 38 = 0xAA, 16 words; CoE details byte 5 at 0xB3, flags byte 11 at 0xB9.
    assert_eq!(&b[0xAA..0xAE], &[30, 0, 16, 0]);
    assert_eq!(&b[0xAE..0xB2], &[2, 0, 1, 3]);
    assert_eq!(b[0xB3], 0x2F);
    assert_eq!(b[0xB7], 1); // DS402 channels
    assert_eq!(b[0xB9], 0x01);
    // FMMU at 0xCE (2 words), SM at 0xD6 (16 words, data 0xDA..0xFA).
    assert_eq!(&b[0xCE..0xD6], &[40, 0, 2, 0, 1, 2, 3, 0]);
    assert_eq!(&b[0xD6..0xDA], &[41, 0, 16, 0]);
    assert_eq!(
        &b[0xDA..0xE2],
        &[0x00, 0x10, 0x80, 0x00, 0x26, 0x00, 0x01, 0x01]
    );
    assert_eq!(
        &b[0xF2..0xFA],
        &[0x00, 0x14, 0x00, 0x00, 0x20, 0x00, 0x01, 0x04]
    );
    // RxPDO at 0xFA: 8 + 4*8 = 40 bytes = 20 words; header then entry 0x6040 UINT16/16.
    assert_eq!(&b[0xFA..0xFE], &[51, 0, 20, 0]);
    assert_eq!(&b[0xFE..0x106], &[0x00, 0x16, 4, 2, 0, 4, 0, 0]);
    assert_eq!(&b[0x106..0x10E], &[0x40, 0x60, 0, 0, 0x06, 16, 0, 0]);
    // 0x607A INT32/32 at 0x10E, 0x60B8 at 0x11E.
    assert_eq!(&b[0x10E..0x114], &[0x7A, 0x60, 0, 0, 0x04, 32]);
    assert_eq!(&b[0x11E..0x120], &[0xB8, 0x60]);
    // TxPDO at 0x126: 8 + 10*8 = 88 bytes = 44 words.
    assert_eq!(&b[0x126..0x12A], &[50, 0, 44, 0]);
    assert_eq!(&b[0x12A..0x132], &[0x00, 0x1A, 10, 3, 0, 5, 0, 0]);
    // Last entry 0x6077 INT16 at 0x12A + 8 + 9*8 = 0x17A.
    assert_eq!(&b[0x17A..0x180], &[0x77, 0x60, 0, 0, 0x03, 16]);
    // DC at 0x182 (12 words), AssignActivate at data + 14 = 0x194; End at 0x19E.
    assert_eq!(&b[0x182..0x186], &[60, 0, 12, 0]);
    assert_eq!(&b[0x194..0x198], &[0x00, 0x03, 0x01, 0x00]);
    assert_eq!(&b[0x19E..], &[0xFF, 0xFF]);

    let padded = sii::encode_padded(&c).unwrap();
    assert_eq!(padded.len(), 2048);
    assert!(padded[0x1A0..].iter().all(|&x| x == 0xFF));
    assert_eq!(sii::decode(&padded).unwrap(), c);
}

#[test]
fn encode_rejects_undefined_flag_bits_and_oversize() {
    let mut c = servo();
    c.header.mailbox_protocols = 0x0104;
    assert!(matches!(sii::encode(&c), Err(SiiError::Encode(_))));

    for bad in [0x20u8, 0x80] {
        let mut c = servo();
        if let Category::General(g) = &mut c.categories[1] {
            g.flags = bad;
        }
        assert!(sii::encode(&c).is_err(), "flags 0x{bad:02X}");
    }
    let mut c = servo();
    if let Category::General(g) = &mut c.categories[1] {
        g.coe_details = 0x40;
    }
    assert!(sii::encode(&c).is_err());
    let mut c = servo();
    if let Category::SyncManagers(s) = &mut c.categories[3] {
        s[0].sm_type = 5;
    }
    assert!(sii::encode(&c).is_err());
    let mut c = servo();
    if let Category::SyncManagers(s) = &mut c.categories[3] {
        s[0].enable = 0x10;
    }
    assert!(sii::encode(&c).is_err());
    let mut c = servo();
    c.categories[2] = Category::Fmmu(vec![4]);
    assert!(sii::encode(&c).is_err());

    let mut c = servo();
    c.categories[0] = Category::Strings(vec!["x".repeat(256)]);
    assert!(sii::encode(&c).is_err());
    let mut c = servo();
    c.categories[0] = Category::Strings(vec!["Ω".into()]);
    assert!(sii::encode(&c).is_err());
    let mut c = servo();
    c.header.eeprom_size = 0; // 128 bytes: header only
    assert!(sii::encode(&c).is_ok());
    assert!(sii::encode_padded(&c).is_err());
}

#[test]
fn decode_errors_name_offset_and_category() {
    let Some(b) = akd("decode_errors_name_offset_and_category") else {
        return;
    };
    assert_eq!(sii::decode(&b[..100]), Err(SiiError::TooShort { len: 100 }));

    let mut bad_crc = b.clone();
    bad_crc[8] ^= 1; // station alias
    match sii::decode(&bad_crc) {
        Err(SiiError::HeaderChecksum { stored, computed }) => {
            assert_eq!(stored, 0x10);
            assert_eq!(computed, sii::crc8(&bad_crc[..14]));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        sii::decode_ignoring_checksum(&bad_crc)
            .unwrap()
            .header
            .station_alias,
        1
    );

    // Strings length word at 0xAA → 0x7FFF words: runs past the image.
    let mut over = b.clone();
    over[0xAA..0xAC].copy_from_slice(&0x7FFFu16.to_le_bytes());
    let err = sii::decode(&over).unwrap_err();
    assert_eq!(
        err,
        SiiError::CategoryOverrun {
            name: "Strings",
            category_type: 10,
            offset: 0xA8,
            words: 0x7FFF,
            len: 2048
        }
    );
    assert!(err.to_string().contains("0x00A8"), "{err}");

    // SM category length 16 → 15 words (30 bytes, not a multiple of 8).
    let mut sm = b.clone();
    sm[0x2B8] = 15;
    match sii::decode(&sm) {
        Err(SiiError::BadCategory { name, offset, .. }) => {
            assert_eq!(name, "SyncManager");
            assert_eq!(offset, 0x2BA);
        }
        other => panic!("{other:?}"),
    }

    // First TxPDO claims 0x41 entries.
    let mut pdo = b.clone();
    pdo[0x2E6] = 0x41; // 8 + 65 * 8 = 528 bytes > 520 in the category
    match sii::decode(&pdo) {
        Err(SiiError::BadCategory {
            name,
            offset,
            reason,
            ..
        }) => {
            assert_eq!(name, "TxPDO");
            assert_eq!(offset, 0x2E4);
            assert!(reason.contains("0x1A00"), "{reason}");
        }
        other => panic!("{other:?}"),
    }

    // Strings: first string length 0xFF at 0xAD overruns the category → offset of the length.
    let mut s = b.clone();
    s[0xAD] = 0xFF;
    s[0xAC] = 1;
    assert!(matches!(
        sii::decode(&s),
        Ok(_) | Err(SiiError::BadCategory { .. })
    ));
    s[0xAC] = 0x21;
    match sii::decode(&s) {
        Err(SiiError::BadCategory { name, .. }) => assert_eq!(name, "Strings"),
        other => panic!("{other:?}"),
    }

    // Cut right before the End marker: no End.
    assert!(matches!(
        sii::decode(&b[..0x694]),
        Err(SiiError::TruncatedCategoryHeader { offset: 0x694, .. })
    ));
}

#[test]
fn truncations_never_panic() {
    let Some(b) = akd("truncations_never_panic") else {
        return;
    };
    for len in 0..=b.len() {
        let r1 = sii::decode(&b[..len]);
        let r2 = sii::decode_ignoring_checksum(&b[..len]);
        if len < 0x696 {
            assert!(r1.is_err() && r2.is_err(), "len {len}");
        } else {
            assert!(r1.is_ok() && r2.is_ok(), "len {len}");
        }
    }
}

#[test]
fn random_corruptions_never_panic() {
    let Some(b) = akd("random_corruptions_never_panic") else {
        return;
    };
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut ok = 0;
    for _ in 0..3000 {
        let mut img = b.clone();
        let n = 1 + next() % 8;
        for _ in 0..n {
            let at = (next() % 0x6A0) as usize;
            img[at] = next() as u8;
        }
        let cut = if next() % 4 == 0 {
            (next() % 2048) as usize
        } else {
            2048
        };
        let img = &img[..cut];
        let _ = sii::decode(img);
        if let Ok(c) = sii::decode_ignoring_checksum(img) {
            ok += 1;
            // Whatever decoded must re-encode (or be refused cleanly) and decode again.
            if let Ok(enc) = sii::encode(&c) {
                assert_eq!(sii::decode(&enc).unwrap(), c);
            }
        }
        let _ = sii::load_image(img);
    }
    assert!(ok > 0);
}

fn to_intel_hex(b: &[u8]) -> String {
    let mut s = String::new();
    for (i, chunk) in b.chunks(16).enumerate() {
        let addr = (i * 16) as u16;
        let mut rec = vec![chunk.len() as u8, (addr >> 8) as u8, addr as u8, 0];
        rec.extend_from_slice(chunk);
        let sum = rec.iter().fold(0u8, |a, &x| a.wrapping_add(x));
        rec.push(sum.wrapping_neg());
        s.push(':');
        for x in rec {
            s.push_str(&format!("{x:02X}"));
        }
        s.push('\n');
    }
    s.push_str(":00000001FF\n");
    s
}

#[test]
fn intel_hex_and_hex_dump_readers() {
    let Some(b) = akd("intel_hex_and_hex_dump_readers") else {
        return;
    };
    let ihex = to_intel_hex(&b);
    assert_eq!(sii::parse_intel_hex(&ihex).unwrap(), b);
    assert_eq!(sii::load_image(ihex.as_bytes()).unwrap(), b);

    // A known record from the Intel HEX spec example.
    let one = ":0300300002337A1E\n:00000001FF\n";
    let img = sii::parse_intel_hex(one).unwrap();
    assert_eq!(img.len(), 0x33);
    assert_eq!(&img[0x30..], &[0x02, 0x33, 0x7A]);
    assert!(img[..0x30].iter().all(|&x| x == 0xFF));

    // Malformed records report their line.
    let mut lines: Vec<String> = ihex.lines().map(String::from).collect();
    assert_eq!(&lines[2][9..11], "00");
    lines[2].replace_range(9..11, "01"); // data byte changed → checksum mismatch on line 3
    let broken = lines.join("\n");
    match sii::parse_intel_hex(&broken) {
        Err(SiiError::Hex { line, reason }) => {
            assert_eq!(line, 3);
            assert!(reason.contains("checksum"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    for (text, line) in [
        (":00000001FF\n", None),
        ("\n:0G00000001\n:00000001FF", Some(2)),
        (":10000000\n", Some(1)),
        (":020000000102FB\n0102\n", Some(2)),
        (":0100000000FF\n", Some(1)), // no EOF record
        (":0100000700F8\n", Some(1)), // unknown record type 07
    ] {
        let r = sii::parse_intel_hex(text);
        match line {
            None => assert_eq!(r, Ok(vec![])),
            Some(l) => match r {
                Err(SiiError::Hex { line, .. }) => assert_eq!(line, l, "{text:?}"),
                other => panic!("{text:?}: {other:?}"),
            },
        }
    }

    let dump = "09 00 00 08\n0000 0000 # comment\n\nFF\n";
    assert_eq!(
        sii::parse_hex_dump(dump).unwrap(),
        [0x09, 0x00, 0x00, 0x08, 0, 0, 0, 0, 0xFF]
    );
    // With a comment the text is not a pure hex dump: load_image treats it as raw binary.
    assert_eq!(sii::load_image(dump.as_bytes()).unwrap(), dump.as_bytes());
    let pure = "09 00 00 08\n0000 0000\nFF\n";
    assert_eq!(sii::load_image(pure.as_bytes()).unwrap().len(), 9);
    match sii::parse_hex_dump("00 11\n22 3\n") {
        Err(SiiError::Hex { line, .. }) => assert_eq!(line, 2),
        other => panic!("{other:?}"),
    }
}

#[test]
fn add_string_interns() {
    let mut c = SiiContent::default();
    assert_eq!(c.add_string(""), Ok(0));
    assert_eq!(c.add_string("Inputs"), Ok(1));
    assert_eq!(c.add_string("Outputs"), Ok(2));
    assert_eq!(c.add_string("Inputs"), Ok(1));
    assert_eq!(c.string(2), Some("Outputs"));
    for i in 0..253 {
        c.add_string(&format!("s{i}")).unwrap();
    }
    assert_eq!(c.strings().len(), 255);
    assert!(c.add_string("one too many").is_err());
    let b = sii::encode(&c).unwrap();
    assert_eq!(sii::decode(&b).unwrap(), c);
}

/// The AKD header followed by arbitrary category bytes (skips as a whole without the dump).
#[test]
fn arbitrary_category_bytes_never_panic() {
    let Some(b) = akd("arbitrary_category_bytes_never_panic") else {
        return;
    };
    let header = &b[..0x80];
    proptest::proptest!(|(tail in proptest::collection::vec(proptest::num::u8::ANY, 0..600))| {
        let mut img = header.to_vec();
        img.extend_from_slice(&tail);
        if let Ok(c) = sii::decode(&img) {
            if let Ok(enc) = sii::encode(&c) {
                proptest::prop_assert_eq!(sii::decode(&enc).unwrap(), c);
            }
        }
    });
}

proptest::proptest! {
    #[test]
    fn arbitrary_text_never_panics_hex_readers(text in "[:0-9A-Fa-f \\n]{0,200}") {
        let _ = sii::parse_intel_hex(&text);
        let _ = sii::parse_hex_dump(&text);
        let _ = sii::load_image(text.as_bytes());
    }
}

#[test]
fn add_string_beyond_255_is_an_error_not_a_panic() {
    use fieldprobe::esi::sii::{Category, SiiContent};
    let mut c = SiiContent::default();
    let names: Vec<String> = (0..300).map(|i| format!("s{i}")).collect();
    c.categories.push(Category::Strings(names));
    // Number 1 and 255 still have an index; number 256 and a new 301st do not.
    assert_eq!(c.add_string("s0").unwrap(), 1);
    assert_eq!(c.add_string("s254").unwrap(), 255);
    assert!(c.add_string("s255").is_err());
    assert!(c.add_string("new").is_err());
}
