//! SDO Information with a real device's dictionary: the SOEM `slaveinfo -sdo` dump of a
//! Leadshine EL7-EC400S (`../shared/test-data/sdo-dumps/`, 639 objects, 64-byte mailbox) is
//! served by the emulator's SDO Information server and read back by the client's reassembly
//! and parsers: the OD list (fragmented into 52-byte pieces, as that device's mailbox forces),
//! every object description and every entry description must come back as the dump says.
//! (The AKD capture `pcap/soem-sdinfo-akd.pcapng` holds no SDO Information frames despite its
//! name — only 35 SDO uploads — so it cannot serve here.)

use fieldprobe::bus::ethercat::sdo_info::{
    list_type, parse_od_list, request, EntryDescription, FragmentCollector, ObjectCode,
    ObjectDescription,
};
use fieldprobe::bus::ethercat::wire::SdoInfoOpcode;
use fieldprobe::sim::esc::sdo_info::OdDescriptions;

use crate::common::test_data;
use crate::common::vendor_esi;

/// Mailbox 64 − 6 mailbox header − 2 CoE header − 4 SDO information header.
const MAX_DATA: usize = 52;

/// (object, entries) from the dump, read by the shared reader of `tests/common/vendor_esi.rs`
/// (`Index:` / `Sub:` lines).
fn read_dump(bytes: &[u8]) -> Vec<(ObjectDescription, Vec<EntryDescription>)> {
    vendor_esi::read_sdo_dump(bytes)
        .objects
        .into_iter()
        .map(|o| {
            let entries: Vec<EntryDescription> = o
                .entries
                .iter()
                .map(|e| EntryDescription {
                    index: o.index,
                    sub: e.sub,
                    value_info: 0x07,
                    data_type: e.data_type,
                    bit_len: e.bit_len,
                    access: e.access,
                    name: e.name.clone(),
                })
                .collect();
            let description = ObjectDescription {
                index: o.index,
                data_type: o.data_type,
                max_sub: o.entries.iter().map(|e| e.sub).max().unwrap_or(0),
                object_code: ObjectCode::from(o.object_code),
                name: o.name,
            };
            (description, entries)
        })
        .collect()
}

fn ask(
    server: &OdDescriptions,
    op: SdoInfoOpcode,
    data: &[u8],
    expect: SdoInfoOpcode,
) -> (Vec<u8>, usize) {
    let req = request(op, data);
    let bodies = server.respond(&req[2..], MAX_DATA);
    let mut c = FragmentCollector::new(expect);
    for (i, b) in bodies.iter().enumerate() {
        assert!(b.len() <= 64 - 6, "fragment of {} bytes", b.len());
        if let Some(d) = c.push(b).unwrap() {
            assert_eq!(i + 1, bodies.len());
            return (d, bodies.len());
        }
    }
    panic!("response incomplete");
}

#[test]
fn leadshine_dictionary_round_trips_through_sdo_information() {
    let Some(p) = test_data::test_data(
        "sdo-dumps/leadshine-el7-ec400s-sdinfo.txt",
        "leadshine_dictionary_round_trips_through_sdo_information",
    ) else {
        return;
    };
    // Names as Latin-1, as they travel on the wire (some of the dump's names are raw bytes).
    let dump = read_dump(&std::fs::read(p).unwrap());
    assert_eq!(dump.len(), 639, "the dump says: 639 entries");
    let mut server = OdDescriptions::default();
    for (o, es) in &dump {
        server.insert_object(o.clone());
        for e in es {
            server.insert_entry(e.clone());
        }
    }
    let (d, n) = ask(
        &server,
        SdoInfoOpcode::GetOdListRequest,
        &list_type::ALL.to_le_bytes(),
        SdoInfoOpcode::GetOdListResponse,
    );
    // 2 + 639·2 bytes in 52-byte fragments.
    assert_eq!(n, (2 + 639 * 2usize).div_ceil(MAX_DATA));
    let list = parse_od_list(list_type::ALL, &d).unwrap();
    let mut want: Vec<u16> = dump.iter().map(|(o, _)| o.index).collect();
    want.sort_unstable();
    assert_eq!(list, want);
    for (o, es) in &dump {
        let (d, _) = ask(
            &server,
            SdoInfoOpcode::GetObjectDescriptionRequest,
            &o.index.to_le_bytes(),
            SdoInfoOpcode::GetObjectDescriptionResponse,
        );
        assert_eq!(&ObjectDescription::parse(&d).unwrap(), o);
        for e in es {
            let i = e.index.to_le_bytes();
            let (d, _) = ask(
                &server,
                SdoInfoOpcode::GetEntryDescriptionRequest,
                &[i[0], i[1], e.sub, 0x07],
                SdoInfoOpcode::GetEntryDescriptionResponse,
            );
            assert_eq!(&EntryDescription::parse(&d).unwrap(), e);
        }
    }
    // 0x1018 Identity Object: RECORD of data type 0x0023, Vendor ID 32 bit read-only.
    let (id, subs) = dump.iter().find(|(o, _)| o.index == 0x1018).unwrap();
    assert_eq!((id.object_code, id.data_type), (ObjectCode::Record, 0x0023));
    assert_eq!(
        (subs[1].bit_len, subs[1].access, subs[1].name.as_str()),
        (32, 0x0007, "Vendor ID")
    );
    // An unknown object gets an SDO Info Error with 0x06020000.
    let req = request(
        SdoInfoOpcode::GetObjectDescriptionRequest,
        &0x5FFFu16.to_le_bytes(),
    );
    let mut c = FragmentCollector::new(SdoInfoOpcode::GetObjectDescriptionResponse);
    let r = c.push(&server.respond(&req[2..], MAX_DATA)[0]);
    assert_eq!(
        r,
        Err(fieldprobe::bus::ethercat::sdo_info::SdoInfoError::Refused { code: 0x0602_0000 })
    );
}
