//! EtherCAT wire codec and capture files (issue 5 groundwork): the two AKD captures in
//! `../shared/test-data/pcap/` decode, hand-walked bytes agree with the decoder, SOEM's SDO
//! uploads decode down to the SDO command, builder / in-place rewrite / pcap writer round-trip,
//! and random or truncated input never panics.

use std::collections::BTreeMap;

use fieldprobe::bus::ethercat::pcap::{
    CaptureFormat, CaptureReader, PcapError, PcapWriter, TimestampResolution,
};
use fieldprobe::bus::ethercat::wire::*;
use proptest::prelude::*;

const TWINCAT: &str = "twincat-akd-nc-mode.pcapng";
const SOEM: &str = "soem-sdinfo-akd.pcapng";

use crate::common::test_data;

/// Capture `name` of `../shared/test-data/pcap/`; `None`: absent, `test` skips (see
/// `common/test_data.rs`).
fn capture(name: &str, test: &str) -> Option<Vec<u8>> {
    let p = test_data::test_data(&format!("pcap/{name}"), test)?;
    Some(std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
}

/// Records, EtherCAT frames, non-EtherCAT EtherTypes and the command histogram of a capture.
struct Summary {
    records: usize,
    ethercat: usize,
    other: BTreeMap<u16, usize>,
    commands: BTreeMap<&'static str, usize>,
    datagrams_per_frame: BTreeMap<usize, usize>,
    /// Frames whose EtherCAT length exceeds the datagram chain, by excess.
    slack: BTreeMap<usize, usize>,
}

fn summarise(name: &str, test: &str) -> Option<Summary> {
    let bytes = capture(name, test)?;
    let reader = CaptureReader::new(&bytes).unwrap();
    assert_eq!(reader.format(), CaptureFormat::PcapNg);
    let mut s = Summary {
        records: 0,
        ethercat: 0,
        other: BTreeMap::new(),
        commands: BTreeMap::new(),
        datagrams_per_frame: BTreeMap::new(),
        slack: BTreeMap::new(),
    };
    let mut last_ts = 0;
    for (i, r) in reader.enumerate() {
        let r = r.unwrap_or_else(|e| panic!("{name} record {i}: {e}"));
        assert_eq!(r.linktype, 1);
        let ts = r.timestamp_ns.expect("EPB has a timestamp");
        assert!(ts >= last_ts, "{name} record {i}: time goes backwards");
        last_ts = ts;
        s.records += 1;
        match Frame::parse(r.data) {
            Ok(f) => {
                s.ethercat += 1;
                assert_eq!(f.frame_type(), FrameType::Datagrams);
                *s.datagrams_per_frame.entry(f.datagram_count()).or_default() += 1;
                let chain: usize = f.datagrams().map(|d| d.wire_len()).sum();
                if f.ethercat_len() > chain {
                    *s.slack.entry(f.ethercat_len() - chain).or_default() += 1;
                }
                for d in f.datagrams() {
                    *s.commands.entry(d.command.name()).or_default() += 1;
                }
            }
            Err(WireError::NotEtherCat {
                ethertype,
                offset: 12,
            }) => *s.other.entry(ethertype).or_default() += 1,
            Err(e) => panic!("{name} record {i}: {e}"),
        }
    }
    Some(s)
}

#[test]
fn twincat_capture_decodes() {
    let Some(s) = summarise(TWINCAT, "twincat_capture_decodes") else {
        return;
    };
    assert_eq!(s.records, 22_298);
    assert_eq!(s.ethercat, 18_793);
    // The rest is the Windows host's own traffic: IPv4, ARP, IPv6, LLDP and 3 frames with type 0.
    let other: BTreeMap<u16, usize> = [
        (0x0000, 3),
        (0x0800, 0xc56),
        (0x0806, 0x4f),
        (0x86dd, 0xee),
        (0x88cc, 0x1b),
    ]
    .into_iter()
    .collect();
    assert_eq!(s.other, other);
    let commands: BTreeMap<&str, usize> = [
        ("APRD", 224),
        ("APWR", 88),
        ("ARMW", 16_383),
        ("BRD", 160),
        ("BWR", 493),
        ("FPRD", 1_441),
        ("FPWR", 92),
    ]
    .into_iter()
    .collect();
    assert_eq!(s.commands, commands);
    assert_eq!(
        s.datagrams_per_frame,
        [(1, 18_713), (2, 72), (3, 8)].into_iter().collect()
    );
    // 9 frames carry one byte more EtherCAT length than their (odd-length) datagram chain
    assert_eq!(s.slack, [(1, 9)].into_iter().collect());
}

#[test]
fn soem_capture_decodes() {
    let Some(s) = summarise(SOEM, "soem_capture_decodes") else {
        return;
    };
    assert_eq!(s.records, 6_762);
    assert_eq!(s.ethercat, 6_759);
    assert_eq!(s.other, [(0x0806, 3)].into_iter().collect());
    let commands: BTreeMap<&str, usize> = [
        ("APRD", 4),
        ("APWR", 4),
        ("BRD", 5_999),
        ("BWR", 34),
        ("FPRD", 578),
        ("FPWR", 140),
    ]
    .into_iter()
    .collect();
    assert_eq!(s.commands, commands);
    assert_eq!(s.datagrams_per_frame, [(1, 6_759)].into_iter().collect());
    assert!(s.slack.is_empty());
}

/// Walk the first EtherCAT frame of a capture by hand and compare with the decoder.
fn check_first_frame_by_hand(bytes: &[u8]) {
    let rec = CaptureReader::new(bytes)
        .unwrap()
        .map(|r| r.unwrap())
        .find(|r| r.data.len() >= 14 && r.data[12..14] == [0x88, 0xA4])
        .expect("an EtherCAT frame");
    let b = rec.data;
    let f = Frame::parse(b).unwrap();
    assert_eq!(f.ethernet().dst[..], b[0..6]);
    assert_eq!(f.ethernet().src[..], b[6..12]);
    assert_eq!(f.ethernet().vlan_tci, None);
    // bytes 14-15: EtherCAT header, length bits 0..10, type bits 12..15
    let hdr = u16::from(b[14]) | u16::from(b[15]) << 8;
    assert_eq!(hdr >> 12, 1, "type 1 = datagrams");
    assert_eq!(f.ethercat_len(), usize::from(hdr & 0x7FF));
    assert_eq!(f.ethercat_header_offset(), 14);
    // byte 16 command, 17 index, 18-19 ADP, 20-21 ADO, 22-23 len|C|M, 24-25 IRQ, data, WKC
    let d = f.datagrams().next().unwrap();
    assert_eq!(d.command.code(), b[16]);
    assert_eq!(d.index, b[17]);
    assert_eq!(d.adp(), u16::from(b[18]) | u16::from(b[19]) << 8);
    assert_eq!(d.ado(), u16::from(b[20]) | u16::from(b[21]) << 8);
    let lenw = u16::from(b[22]) | u16::from(b[23]) << 8;
    let len = usize::from(lenw & 0x7FF);
    assert_eq!(d.data.len(), len);
    assert_eq!(d.circulating, lenw & 0x4000 != 0);
    assert_eq!(d.more_follows, lenw & 0x8000 != 0);
    assert_eq!(d.irq, u16::from(b[24]) | u16::from(b[25]) << 8);
    assert_eq!(d.data, &b[26..26 + len]);
    assert_eq!(d.wkc, u16::from(b[26 + len]) | u16::from(b[27 + len]) << 8);
    if !d.more_follows {
        assert_eq!(f.datagram_count(), 1);
        // TwinCAT pads an odd datagram chain to an even EtherCAT length (see twincat test)
        let slack = f.ethercat_len() - (10 + len + 2);
        assert!(slack <= 1, "{slack}");
    }
}

#[test]
fn first_frames_walked_by_hand() {
    const TEST: &str = "first_frames_walked_by_hand";
    let (Some(twincat), Some(soem)) = (capture(TWINCAT, TEST), capture(SOEM, TEST)) else {
        return;
    };
    check_first_frame_by_hand(&twincat);
    check_first_frame_by_hand(&soem);
}

#[test]
fn soem_first_frame_matches_trace() {
    let Some(bytes) = capture(SOEM, "soem_first_frame_matches_trace") else {
        return;
    };
    // trace-soem-init.txt starts "[trace] BWR   0x0103 len=1" (ecx_config_init resets DL control).
    let trace = std::fs::read_to_string(format!(
        "{}/../shared/notes/trace-soem-init.txt",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let first: Vec<&str> = trace.lines().next().unwrap().split_whitespace().collect();
    assert_eq!(first, ["[trace]", "BWR", "0x0103", "len=1"]);
    let rec = CaptureReader::new(&bytes)
        .unwrap()
        .map(|r| r.unwrap())
        .find(|r| Frame::parse(r.data).is_ok())
        .unwrap();
    let f = Frame::parse(rec.data).unwrap();
    let d = f.datagrams().next().unwrap();
    assert_eq!(d.command.name(), first[1]);
    assert_eq!(format!("{:#06x}", d.ado()), first[2]);
    assert_eq!(format!("len={}", d.data.len()), first[3]);
    assert_eq!(f.ethernet().dst, [0xFF; 6]);
}

/// Mailbox datagrams of the SOEM capture: FPWR to SM0 (0x1800) and FPRD from SM1 (0x1C00),
/// both 1024 bytes. Only answered datagrams (WKC 1) carry data that went through the slave.
#[test]
fn soem_sdo_mailboxes_decode() {
    let Some(bytes) = capture(SOEM, "soem_sdo_mailboxes_decode") else {
        return;
    };
    let mut requests = Vec::new();
    let mut responses = Vec::new();
    for r in CaptureReader::new(&bytes).unwrap() {
        let r = r.unwrap();
        let Ok(f) = Frame::parse(r.data) else {
            continue;
        };
        for d in f.datagrams() {
            let sm = match (d.command, d.ado()) {
                (Command::Fpwr, 0x1800) => SdoDirection::Request,
                (Command::Fprd, 0x1C00) => SdoDirection::Response,
                _ => continue,
            };
            assert_eq!(d.data.len(), 1024, "mailbox SM length");
            if d.wkc != 1 {
                continue;
            }
            let (mh, body) = MailboxHeader::parse(d.data).unwrap();
            assert_eq!(mh.mailbox_type, MailboxType::Coe);
            assert!((1..=7).contains(&mh.counter));
            let (coe, rest) = CoeHeader::parse(body).unwrap();
            assert_eq!(coe.number, 0);
            let sdo = SdoFrame::parse(rest, sm).unwrap();
            match sm {
                SdoDirection::Request => {
                    assert_eq!(coe.service, CoeService::SdoRequest);
                    assert_eq!(
                        sdo.command,
                        SdoCommand::InitiateUploadRequest {
                            complete_access: false
                        }
                    );
                    requests.push((mh.counter, sdo.index.unwrap(), sdo.subindex.unwrap()));
                }
                SdoDirection::Response => {
                    assert_eq!(coe.service, CoeService::SdoResponse);
                    let SdoCommand::InitiateUploadResponse {
                        expedited: true,
                        size_indicated: true,
                        unused,
                        ..
                    } = sdo.command
                    else {
                        panic!("unexpected {:?}", sdo.command)
                    };
                    let value = &sdo.data[..4 - usize::from(unused)];
                    responses.push((
                        mh.counter,
                        sdo.index.unwrap(),
                        sdo.subindex.unwrap(),
                        value.to_vec(),
                    ));
                }
            }
        }
    }
    assert_eq!(requests.len(), 35);
    assert_eq!(responses.len(), 35);
    for (q, a) in requests.iter().zip(&responses) {
        assert_eq!((q.0, q.1, q.2), (a.0, a.1, a.2), "response matches request");
    }
    // 0x1C00:0 SM communication types: 4 entries; 0x1C12:1 first RxPDO = 0x1600;
    // 0x1600:1 first mapped object 0x6040:00, 16 bits (controlword).
    assert_eq!(responses[0], (1, 0x1C00, 0, vec![4]));
    let rx1 = responses
        .iter()
        .find(|r| (r.1, r.2) == (0x1C12, 1))
        .unwrap();
    assert_eq!(rx1.3, vec![0x00, 0x16]);
    let map1 = responses
        .iter()
        .find(|r| (r.1, r.2) == (0x1600, 1))
        .unwrap();
    assert_eq!(map1.3, vec![0x10, 0x00, 0x40, 0x60]);
}

/// TwinCAT talks EoE (mailbox type 2) to the AKD through the same SM0 / SM1 areas.
#[test]
fn twincat_mailboxes_are_eoe() {
    let Some(bytes) = capture(TWINCAT, "twincat_mailboxes_are_eoe") else {
        return;
    };
    let mut eoe = 0;
    for r in CaptureReader::new(&bytes).unwrap() {
        let r = r.unwrap();
        let Ok(f) = Frame::parse(r.data) else {
            continue;
        };
        for d in f.datagrams() {
            if d.command == Command::Fpwr && d.ado() == 0x1800 {
                let (mh, _) = MailboxHeader::parse(d.data).unwrap();
                assert_eq!(mh.mailbox_type, MailboxType::Eoe);
                eoe += 1;
            }
        }
    }
    assert_eq!(eoe, 8);
}

const MASTER: [u8; 6] = [0x10, 0x10, 0x10, 0x10, 0x10, 0x10];
const BCAST: [u8; 6] = [0xFF; 6];

/// Datagrams as in trace-ethercrab-0.7.1-init.txt / trace-soem-init.txt.
fn init_datagrams(buf: &[u8]) -> Vec<Datagram<'_>> {
    let mut v = vec![
        Datagram::new(Command::Brd, 0, physical_address(0, 0x0000), &buf[..2]), // BRD 0x0000 len 2
        Datagram::new(
            Command::Apwr,
            1,
            physical_address(0u16.wrapping_sub(1), 0x0010),
            &buf[2..4],
        ), // station address
        Datagram::new(
            Command::Fprd,
            2,
            physical_address(0x1001, 0x0130),
            &buf[4..10],
        ), // AL status
        Datagram::new(
            Command::Fpwr,
            3,
            physical_address(0x1001, 0x1000),
            &buf[10..138],
        ), // mailbox SM0
        Datagram::new(Command::Lrw, 4, 0x0001_0000, &buf[138..174]),            // LRW len 36
        Datagram::new(
            Command::Frmw,
            5,
            physical_address(0x1001, 0x0910),
            &buf[174..182],
        ), // DC time
    ];
    v[2].wkc = 1;
    v[4].irq = 0x0003;
    v[5].circulating = true;
    v
}

fn pattern(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + 3) as u8).collect()
}

#[test]
fn builder_round_trip() {
    let buf = pattern(200);
    for vlan in [None, Some(0x6005)] {
        let dgs = init_datagrams(&buf);
        let mut b = FrameBuilder::with_vlan(BCAST, MASTER, vlan);
        for d in &dgs {
            b.push(d).unwrap();
        }
        let bytes = b.build();
        let f = Frame::parse(&bytes).unwrap();
        assert_eq!(f.ethernet().vlan_tci, vlan);
        assert_eq!(
            f.ethercat_header_offset(),
            if vlan.is_some() { 18 } else { 14 }
        );
        let got: Vec<_> = f.datagrams().collect();
        let n = dgs.len();
        let want: Vec<_> = dgs
            .iter()
            .enumerate()
            .map(|(i, d)| Datagram {
                more_follows: i + 1 < n,
                ..*d
            })
            .collect();
        assert_eq!(got, want);
        assert_eq!(
            f.ethercat_len(),
            dgs.iter().map(Datagram::wire_len).sum::<usize>()
        );
        // byte-level: FPRD of 0x0130 at station 0x1001
        let (off, d) = f.datagrams_with_offsets().nth(2).unwrap();
        assert_eq!(d.command, Command::Fprd);
        assert_eq!(&bytes[off..off + 6], &[0x04, 0x02, 0x01, 0x10, 0x30, 0x01]);
    }
    // a short frame is padded to 60 bytes; padding is ignored by the decoder
    let mut b = FrameBuilder::new(BCAST, MASTER);
    b.push_command(Command::Brd, 0, 0, &[0, 0]).unwrap();
    let bytes = b.build();
    assert_eq!(bytes.len(), 60);
    assert_eq!(Frame::parse(&bytes).unwrap().ethercat_len(), 14);
    assert_eq!(
        FrameBuilder::new(BCAST, MASTER).no_padding().build().len(),
        16
    );
}

#[test]
fn builder_limits() {
    let big = vec![0u8; 2048];
    let mut b = FrameBuilder::new(BCAST, MASTER);
    assert!(matches!(
        b.push_command(Command::Lrw, 0, 0, &big),
        Err(WireError::InvalidField { .. })
    ));
    b.push_command(Command::Lrw, 0, 0, &big[..1400]).unwrap();
    assert!(matches!(
        b.push_command(Command::Lrw, 1, 0, &big[..100]),
        Err(WireError::FrameTooLong { .. })
    ));
    // the failed push left the frame intact
    let bytes = b.build();
    assert_eq!(Frame::parse(&bytes).unwrap().datagram_count(), 1);
}

/// What an emulated slave does: rewrite data and WKC in place, mark the frame processed.
#[test]
fn rewrite_in_place() {
    let buf = vec![0u8; 200];
    let mut b = FrameBuilder::new(BCAST, MASTER);
    for d in init_datagrams(&buf) {
        b.push(&d).unwrap();
    }
    let mut bytes = b.build();
    let n = for_each_datagram_mut(&mut bytes, |mut d| {
        match d.command() {
            Command::Brd => d.data_mut().copy_from_slice(&[0x11, 0x05]), // ET1100 type / revision
            Command::Apwr => d.set_adp(d.adp().wrapping_add(1)),
            Command::Fprd if d.ado() == 0x0130 => d.data_mut()[0] = 0x02, // PRE-OP
            _ => {}
        }
        d.add_wkc(1);
    })
    .unwrap();
    assert_eq!(n, 6);
    assert!(mark_processed(&mut bytes));
    let f = Frame::parse(&bytes).unwrap();
    assert_eq!(f.ethernet().src[0], 0x12);
    let d: Vec<_> = f.datagrams().collect();
    assert_eq!(d[0].data, &[0x11, 0x05]);
    assert_eq!(d[0].wkc, 1);
    assert_eq!(d[1].adp(), 0);
    assert_eq!(d[2].data[0], 0x02);
    assert_eq!(d[2].wkc, 2); // was 1
    assert!(d[5].circulating);
    // an invalid frame is rejected before anything is touched
    let mut cut = bytes[..40].to_vec();
    let before = cut.clone();
    assert!(for_each_datagram_mut(&mut cut, |mut d| d.set_wkc(9)).is_err());
    assert_eq!(cut, before);
}

#[test]
fn errors_name_the_offset() {
    let mut b = FrameBuilder::new(BCAST, MASTER).no_padding();
    b.push_command(Command::Fprd, 0, physical_address(0x1001, 0x0130), &[0; 6])
        .unwrap();
    b.push_command(Command::Fprd, 1, physical_address(0x1002, 0x0130), &[0; 6])
        .unwrap();
    let bytes = b.build();
    assert_eq!(bytes.len(), 16 + 18 + 18);
    // header claims 36 bytes of datagrams but only 20 follow
    match Frame::parse(&bytes[..36]) {
        Err(WireError::Truncated {
            what: "EtherCAT payload",
            offset: 16,
            need: 36,
            have: 20,
        }) => {}
        other => panic!("{other:?}"),
    }
    // second datagram's length field says 7 instead of 6: runs past the payload
    let mut bad = bytes.clone();
    bad[34 + 6] = 7;
    match Frame::parse(&bad) {
        Err(WireError::DatagramOverrun {
            offset: 34,
            end: 53,
            limit: 52,
        }) => {}
        other => panic!("{other:?}"),
    }
    // M flag set on the last datagram
    let mut bad = bytes.clone();
    bad[34 + 7] |= 0x80;
    assert!(matches!(
        Frame::parse(&bad),
        Err(WireError::Truncated {
            what: "datagram header",
            offset: 52,
            ..
        })
    ));
    let mut ip = bytes.clone();
    ip[12..14].copy_from_slice(&[0x08, 0x00]);
    assert_eq!(
        Frame::parse(&ip).unwrap_err(),
        WireError::NotEtherCat {
            ethertype: 0x0800,
            offset: 12
        }
    );
    // other EtherCAT frame types (4 = network variables) parse with no datagrams
    let mut nv = bytes.clone();
    nv[15] = (nv[15] & 0x0F) | 0x40;
    let f = Frame::parse(&nv).unwrap();
    assert_eq!(f.frame_type(), FrameType::NetworkVariables);
    assert_eq!(f.datagrams().count(), 0);
    let e = Frame::parse(&bytes[..36]).unwrap_err().to_string();
    assert!(e.contains("byte 16"), "{e}");
}

#[test]
fn mailbox_headers_round_trip() {
    // ethercrab-style SDO upload request for 0x1C12:00 in a 128-byte SM0 at 0x1000
    let mh = MailboxHeader {
        length: 10,
        address: 0,
        channel: 0,
        priority: 0,
        mailbox_type: MailboxType::Coe,
        counter: 3,
    };
    let coe = CoeHeader {
        number: 0,
        service: CoeService::SdoRequest,
    };
    let mut mbx = Vec::new();
    mbx.extend_from_slice(&mh.encode());
    mbx.extend_from_slice(&coe.encode());
    mbx.extend_from_slice(&[
        SdoCommand::InitiateUploadRequest {
            complete_access: false,
        }
        .encode(),
        0x12,
        0x1C,
        0x00,
    ]);
    mbx.extend_from_slice(&[0; 4]);
    mbx.resize(128, 0);
    assert_eq!(&mbx[..8], &[10, 0, 0, 0, 0, 0x33, 0x00, 0x20]);
    let (h, body) = MailboxHeader::parse(&mbx).unwrap();
    assert_eq!(h, mh);
    assert_eq!(body.len(), 10);
    let (c, rest) = CoeHeader::parse(body).unwrap();
    assert_eq!(c, coe);
    let sdo = SdoFrame::parse(rest, SdoDirection::Request).unwrap();
    assert_eq!((sdo.index, sdo.subindex), (Some(0x1C12), Some(0)));

    // abort: command 0x80, index, sub, code 0x06020000 (object does not exist)
    let abort = [0x80, 0x00, 0x20, 0x01, 0x00, 0x00, 0x02, 0x06];
    let a = SdoFrame::parse(&abort, SdoDirection::Response).unwrap();
    assert_eq!(a.command, SdoCommand::Abort);
    assert_eq!(a.abort_code, Some(0x0602_0000));
    assert!(matches!(
        SdoFrame::parse(&abort[..6], SdoDirection::Response),
        Err(WireError::Truncated {
            what: "SDO abort code",
            offset: 4,
            ..
        })
    ));
    // segment toggles
    assert_eq!(
        SdoCommand::decode(0x70, SdoDirection::Request),
        SdoCommand::UploadSegmentRequest { toggle: true }
    );
    assert_eq!(
        SdoCommand::decode(0x1B, SdoDirection::Response),
        SdoCommand::UploadSegmentResponse {
            toggle: true,
            unused: 5,
            last: true
        }
    );
    let seg = SdoFrame::parse(&[0x00, 1, 2, 3, 4, 5, 6, 7], SdoDirection::Response).unwrap();
    assert_eq!(seg.index, None);
    assert_eq!(seg.data, &[1, 2, 3, 4, 5, 6, 7]);

    // SDO information: get OD list request, list type 1 (all objects)
    let info = SdoInfoHeader {
        opcode: SdoInfoOpcode::GetOdListRequest,
        incomplete: false,
        fragments_left: 0,
    };
    let (i, rest) = SdoInfoHeader::parse(&[0x01, 0x00, 0x00, 0x00, 0x01, 0x00]).unwrap();
    assert_eq!(i, info);
    assert_eq!(rest, &[1, 0]);
    let frag = SdoInfoHeader {
        opcode: SdoInfoOpcode::GetOdListResponse,
        incomplete: true,
        fragments_left: 2,
    };
    assert_eq!(SdoInfoHeader::parse(&frag.encode()).unwrap().0, frag);
    assert_eq!(
        CoeHeader::parse(&[0x00, 0x80]).unwrap().0.service,
        CoeService::SdoInformation
    );

    // SoE read request of S-0-0169 (probe control) value, drive 0; and a 2-fragment reply
    let soe = SoeHeader {
        opcode: SoeOpcode::ReadRequest,
        incomplete: false,
        error: false,
        drive_no: 0,
        elements: 0x40,
        idn: 0x00A9,
    };
    assert_eq!(soe.encode(), [0x01, 0x40, 0xA9, 0x00]);
    let (s, _) = SoeHeader::parse(&[0xAA, 0x04, 0x0A, 0x80]).unwrap();
    assert_eq!(
        s,
        SoeHeader {
            opcode: SoeOpcode::ReadResponse,
            incomplete: true,
            error: false,
            drive_no: 5,
            elements: 0x04,
            idn: 0x800A
        }
    );
    assert_eq!(SoeHeader::parse(&s.encode()).unwrap().0, s);
    let soe_mbx = MailboxHeader {
        mailbox_type: MailboxType::Soe,
        ..mh
    };
    assert_eq!(soe_mbx.encode()[5] & 0x0F, 5);
    // mailbox header claiming more data than the buffer holds
    assert!(matches!(
        MailboxHeader::parse(&[20, 0, 0, 0, 0, 3, 1, 2]),
        Err(WireError::Truncated {
            what: "mailbox service data",
            offset: 6,
            need: 20,
            have: 2
        })
    ));
}

#[test]
fn pcap_write_read_back() {
    let buf = pattern(200);
    let frames: Vec<Vec<u8>> = (0..5)
        .map(|i| {
            let mut b = FrameBuilder::new(BCAST, MASTER);
            for d in init_datagrams(&buf).into_iter().take(i + 1) {
                b.push(&d).unwrap();
            }
            b.build()
        })
        .collect();
    let t0 = 1_763_722_800_123_456_789u64;
    for res in [TimestampResolution::Nano, TimestampResolution::Micro] {
        let mut w = PcapWriter::new(Vec::new(), res).unwrap();
        for (i, f) in frames.iter().enumerate() {
            w.write_packet(t0 + i as u64 * 1_000_500, f).unwrap();
        }
        let bytes = w.into_inner().unwrap();
        let magic = match res {
            TimestampResolution::Nano => [0x4D, 0x3C, 0xB2, 0xA1],
            TimestampResolution::Micro => [0xD4, 0xC3, 0xB2, 0xA1],
        };
        assert_eq!(bytes[..4], magic);
        assert_eq!(bytes[20..24], [1, 0, 0, 0], "LINKTYPE_ETHERNET");
        let r = CaptureReader::new(&bytes).unwrap();
        assert_eq!(r.format(), CaptureFormat::Pcap);
        let recs: Vec<_> = r.map(|r| r.unwrap()).collect();
        assert_eq!(recs.len(), frames.len());
        for (i, (rec, f)) in recs.iter().zip(&frames).enumerate() {
            let t = t0 + i as u64 * 1_000_500;
            let want = if res == TimestampResolution::Micro {
                t / 1000 * 1000
            } else {
                t
            };
            assert_eq!(rec.timestamp_ns, Some(want));
            assert_eq!(rec.data, &f[..]);
            assert_eq!(rec.original_len as usize, f.len());
            assert_eq!(Frame::parse(rec.data).unwrap().datagram_count(), i + 1);
        }
    }
    // through a file, as `--pcap FILE` will
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.pcap");
    let mut w = PcapWriter::new(
        std::fs::File::create(&path).unwrap(),
        TimestampResolution::Micro,
    )
    .unwrap();
    w.write_packet(1_000, &frames[0]).unwrap();
    w.flush().unwrap();
    drop(w);
    let recs = fieldprobe::bus::ethercat::pcap::read_file(&path).unwrap();
    assert_eq!(recs.len(), 1);
    assert_eq!(recs[0].data, frames[0]);
    // seconds beyond u32 are refused
    let mut w = PcapWriter::new(Vec::new(), TimestampResolution::Nano).unwrap();
    assert!(w.write_packet(u64::MAX, &frames[0]).is_err());
}

#[test]
fn big_endian_classic_pcap() {
    let frame = {
        let mut b = FrameBuilder::new(BCAST, MASTER);
        b.push_command(Command::Brd, 0, 0, &[0, 0]).unwrap();
        b.build()
    };
    let mut f = Vec::new();
    f.extend_from_slice(&0xA1B2_C3D4u32.to_be_bytes());
    f.extend_from_slice(&2u16.to_be_bytes());
    f.extend_from_slice(&4u16.to_be_bytes());
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&65535u32.to_be_bytes());
    f.extend_from_slice(&1u32.to_be_bytes());
    f.extend_from_slice(&7u32.to_be_bytes());
    f.extend_from_slice(&250_000u32.to_be_bytes());
    f.extend_from_slice(&(frame.len() as u32).to_be_bytes());
    f.extend_from_slice(&(frame.len() as u32).to_be_bytes());
    f.extend_from_slice(&frame);
    let recs: Vec<_> = CaptureReader::new(&f)
        .unwrap()
        .map(|r| r.unwrap())
        .collect();
    assert_eq!(recs.len(), 1);
    assert_eq!(recs[0].timestamp_ns, Some(7_250_000_000));
    assert_eq!(recs[0].data, &frame[..]);
    // truncated record names its offset
    let cut = &f[..f.len() - 1];
    let errs: Vec<_> = CaptureReader::new(cut)
        .unwrap()
        .filter_map(Result::err)
        .collect();
    assert!(
        matches!(
            errs[..],
            [PcapError::Truncated {
                what: "pcap record data",
                offset: 40,
                ..
            }]
        ),
        "{errs:?}"
    );
}

/// pcapng block: type, total length, body padded to 4, total length.
fn block(be: bool, btype: u32, body: &[u8]) -> Vec<u8> {
    let w32 = |v: u32| if be { v.to_be_bytes() } else { v.to_le_bytes() };
    let mut body = body.to_vec();
    while !body.len().is_multiple_of(4) {
        body.push(0);
    }
    let total = 12 + body.len() as u32;
    let mut v = Vec::new();
    v.extend_from_slice(&w32(btype));
    v.extend_from_slice(&w32(total));
    v.extend_from_slice(&body);
    v.extend_from_slice(&w32(total));
    v
}

fn pcapng(be: bool, frame: &[u8]) -> Vec<u8> {
    let w16 = |v: u16| if be { v.to_be_bytes() } else { v.to_le_bytes() };
    let w32 = |v: u32| if be { v.to_be_bytes() } else { v.to_le_bytes() };
    let mut shb = Vec::new();
    shb.extend_from_slice(&w32(0x1A2B_3C4D));
    shb.extend_from_slice(&w16(1));
    shb.extend_from_slice(&w16(0));
    shb.extend_from_slice(&[0xFF; 8]);
    let mut idb = Vec::new();
    idb.extend_from_slice(&w16(1));
    idb.extend_from_slice(&w16(0));
    idb.extend_from_slice(&w32(0));
    idb.extend_from_slice(&w16(9)); // if_tsresol = 10^-9
    idb.extend_from_slice(&w16(1));
    idb.extend_from_slice(&[9, 0, 0, 0]);
    idb.extend_from_slice(&[0; 4]); // opt_endofopt
    let mut epb = Vec::new();
    let ts: u64 = 1_763_722_800_000_000_042;
    epb.extend_from_slice(&w32(0));
    epb.extend_from_slice(&w32((ts >> 32) as u32));
    epb.extend_from_slice(&w32(ts as u32));
    epb.extend_from_slice(&w32(frame.len() as u32));
    epb.extend_from_slice(&w32(frame.len() as u32));
    epb.extend_from_slice(frame);
    let mut spb = Vec::new();
    spb.extend_from_slice(&w32(frame.len() as u32));
    spb.extend_from_slice(frame);
    let mut out = block(be, 0x0A0D_0D0A, &shb);
    out.extend(block(be, 1, &idb));
    out.extend(block(be, 5, &[0; 20])); // interface statistics: skipped
    out.extend(block(be, 0x4000_0BAD, &[1, 2, 3])); // custom / unknown: skipped
    out.extend(block(be, 6, &epb));
    out.extend(block(be, 3, &spb));
    out
}

#[test]
fn pcapng_both_byte_orders() {
    let mut b = FrameBuilder::new(BCAST, MASTER).no_padding();
    b.push_command(Command::Fprd, 7, physical_address(0x1001, 0x0130), &[0; 5])
        .unwrap(); // 35 bytes: odd length
    let frame = b.build();
    for be in [false, true] {
        let file = pcapng(be, &frame);
        let recs: Vec<_> = CaptureReader::new(&file)
            .unwrap()
            .map(|r| r.unwrap())
            .collect();
        assert_eq!(recs.len(), 2, "be={be}");
        assert_eq!(recs[0].timestamp_ns, Some(1_763_722_800_000_000_042));
        assert_eq!(recs[1].timestamp_ns, None);
        for r in &recs {
            assert_eq!(r.data, &frame[..]);
            assert_eq!(
                Frame::parse(r.data)
                    .unwrap()
                    .datagrams()
                    .next()
                    .unwrap()
                    .index,
                7
            );
        }
        // EPB naming an interface that was never described
        let mut bad = file.clone();
        let epb_at =
            file.len() - block(be, 3, &[0; 4 + 35]).len() - block(be, 6, &[0; 20 + 35]).len();
        bad[epb_at + 8..epb_at + 12].copy_from_slice(&[0, 0, 0, 3]);
        let err = CaptureReader::new(&bad)
            .unwrap()
            .find_map(Result::err)
            .unwrap();
        assert!(
            matches!(err, PcapError::UnknownInterface { offset, .. } if offset == epb_at),
            "{err}"
        );
        // trailing length mismatch
        let mut bad = file.clone();
        let n = bad.len();
        bad[n - 1] ^= 0x40;
        bad[n - 4] ^= 0x40;
        let err = CaptureReader::new(&bad)
            .unwrap()
            .find_map(Result::err)
            .unwrap();
        assert!(err.to_string().contains("simple packet block"), "{err}");
    }
}

#[test]
fn not_a_capture() {
    assert!(matches!(
        CaptureReader::new(b"GIF89a.."),
        Err(PcapError::BadMagic { .. })
    ));
    assert!(matches!(
        CaptureReader::new(b"ab"),
        Err(PcapError::Truncated { .. })
    ));
}

/// xorshift64*: deterministic pseudo-random bytes without a dependency.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

fn poke_everything(bytes: &[u8]) {
    if let Ok(f) = Frame::parse(bytes) {
        for d in f.datagrams() {
            let _ = (d.adp(), d.ado(), d.wire_len());
        }
    }
    let mut m = bytes.to_vec();
    let _ = for_each_datagram_mut(&mut m, |mut d| {
        d.add_wkc(1);
        let _ = d.as_datagram();
        if let Some(b) = d.data_mut().first_mut() {
            *b = 0;
        }
    });
    if let Ok((_, body)) = MailboxHeader::parse(bytes) {
        if let Ok((c, rest)) = CoeHeader::parse(body) {
            let _ = SdoFrame::parse(rest, SdoDirection::Request);
            let _ = SdoFrame::parse(rest, SdoDirection::Response);
            let _ = SdoInfoHeader::parse(rest);
            let _ = c.encode();
        }
        let _ = SoeHeader::parse(body);
    }
    if let Ok(r) = CaptureReader::new(bytes) {
        for rec in r.take(1000).flatten() {
            let _ = Frame::parse(rec.data);
        }
    }
}

#[test]
fn random_bytes_never_panic() {
    let mut rng = Rng(0x5EED_CAFE);
    for _ in 0..20_000 {
        let n = (rng.next() % 200) as usize;
        let mut b = rng.bytes(n);
        // steer half the inputs past the EtherType / magic checks
        if n >= 16 && rng.next().is_multiple_of(2) {
            b[12..14].copy_from_slice(&[0x88, 0xA4]);
            b[15] = (b[15] & 0x0F) | 0x10;
        }
        if n >= 4 && rng.next().is_multiple_of(4) {
            b[..4].copy_from_slice(&[0x0A, 0x0D, 0x0D, 0x0A]);
        }
        poke_everything(&b);
    }
}

#[test]
fn truncations_never_panic() {
    let Some(cap) = capture(SOEM, "truncations_never_panic") else {
        return;
    };
    // every prefix of a multi-datagram frame: only the full frame parses
    let buf = pattern(200);
    let mut b = FrameBuilder::with_vlan(BCAST, MASTER, Some(1)).no_padding();
    for d in init_datagrams(&buf) {
        b.push(&d).unwrap();
    }
    let frame = b.build();
    for n in 0..frame.len() {
        assert!(Frame::parse(&frame[..n]).is_err(), "prefix {n}");
        poke_everything(&frame[..n]);
    }
    // every prefix of the first 6 KiB of a real capture, and single-byte corruptions
    for n in 0..6144 {
        poke_everything(&cap[..n]);
    }
    let mut rng = Rng(42);
    for _ in 0..300 {
        let mut c = cap[..8192].to_vec();
        let i = (rng.next() % 8192) as usize;
        c[i] = rng.next() as u8;
        poke_everything(&c);
    }
}

proptest! {
    #[test]
    fn prop_frame_round_trip(
        dgs in prop::collection::vec(
            (0u8..=16, any::<u8>(), any::<u32>(), prop::collection::vec(any::<u8>(), 0..64), any::<bool>(), any::<u16>(), any::<u16>()),
            1..8,
        ),
        vlan in prop::option::of(any::<u16>()),
    ) {
        let mut b = FrameBuilder::with_vlan(BCAST, MASTER, vlan);
        let want: Vec<Datagram<'_>> = dgs
            .iter()
            .enumerate()
            .map(|(i, (c, idx, addr, data, circ, irq, wkc))| Datagram {
                command: Command::from(*c),
                index: *idx,
                address: *addr,
                circulating: *circ,
                more_follows: i + 1 < dgs.len(),
                irq: *irq,
                data,
                wkc: *wkc,
            })
            .collect();
        for d in &want {
            b.push(d).unwrap();
        }
        let bytes = b.build();
        let f = Frame::parse(&bytes).unwrap();
        prop_assert_eq!(f.datagrams().collect::<Vec<_>>(), want);
        let mut copy = bytes.clone();
        prop_assert_eq!(for_each_datagram_mut(&mut copy, |_| {}).unwrap(), dgs.len());
        prop_assert_eq!(copy, bytes);
    }
}
