//! fieldprobe's own SoE client ([`fieldprobe::bus::ethercat::soe::SoeClient`]) on ethercrab
//! 0.7.1's raw command API against emulated SERCOS drives: ESCs built from
//! `esi/fieldprobe-ax5000-sercos.xml` whose application is an `SoeServer` over a `SercosModel`
//! of `drives/sercos-ax5000.toml`. Drive 1 has the ESI's 512-byte mailboxes; drive 2 a tiny
//! write mailbox (11 bytes: one data byte per SoE write fragment) and a 24-byte read mailbox
//! (the server fragments every reply longer than 14 bytes), so both fragment directions run.
//! Wiring as in `tests/it/ethercat_mailbox_client.rs`; every wait is bounded.

use std::{
    sync::{
        atomic::{AtomicBool, Ordering},
        Arc, Mutex,
    },
    time::Duration,
};

use ethercrab::{std::ethercat_now, MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use fieldprobe::bus::ethercat::mailbox::MailboxError;
use fieldprobe::bus::ethercat::soe::{error_text, format_idn, parse_idn, Element, SoeClient};
use fieldprobe::bus::ethercat::wire::{CoeHeader, CoeService, MailboxHeader, MailboxType};
use fieldprobe::drive::catalogue;
use fieldprobe::drive::model::sercos::SercosModel;
use fieldprobe::drive::sercos;
use fieldprobe::esi::{self, sii, to_sii::sii_from_device, SmKind};
use fieldprobe::sim::esc::soe::{sercos_idns, SoeServer};
use fieldprobe::sim::esc::{segment::Segment, Esc, EscApplication, EscConfig};

use crate::common::wire;
use wire::{coupler, spawn_wire};

const TEST_TIMEOUT: Duration = Duration::from_secs(30);
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

const SERCOS_XML: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/esi/fieldprobe-ax5000-sercos.xml"
);
const DRIVE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/drives/sercos-ax5000.toml");

/// The SoE server of one drive plus test knobs, shared with the wire thread.
struct Drive {
    soe: SoeServer,
    /// Sent instead of the next reply (the reply is queued behind it).
    emcy_next: Option<Vec<u8>>,
    /// Messages for the read mailbox after the current one (fragments, delayed replies).
    queued: Vec<Vec<u8>>,
    /// SoE write requests as received: (incomplete bit, IDN field, data).
    writes: Vec<(bool, u16, Vec<u8>)>,
    /// Reply fragments queued after a first one.
    fragments_out: usize,
}

struct SharedDrive(Arc<Mutex<Drive>>);

impl EscApplication for SharedDrive {
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        let mut d = self.0.lock().unwrap();
        // SoE (mailbox type 5) write request (opcode 3): record the header and data.
        if let Ok((h, body)) = MailboxHeader::parse(data) {
            if h.mailbox_type == MailboxType::Soe && body.len() >= 4 && body[0] & 0x07 == 3 {
                let idn_field = u16::from_le_bytes([body[2], body[3]]);
                d.writes
                    .push((body[0] & 0x08 != 0, idn_field, body[4..].to_vec()));
            }
        }
        let reply = d.soe.handle(data);
        let more = d.soe.take_outgoing();
        d.fragments_out += more.len();
        match d.emcy_next.take() {
            Some(e) => {
                d.queued.extend(reply);
                d.queued.extend(more);
                Some(e)
            }
            None => {
                d.queued.extend(more);
                reply
            }
        }
    }
}

/// SERCOS drive ESC with its SM0 / SM1 lengths set to `mbx` (None = the ESI's), the server's
/// mailbox size = the SM1 length; returns the ESC, its shared server, (SM0, SM1).
#[allow(clippy::type_complexity)]
fn drive(mbx: Option<(u16, u16)>) -> (Esc, Arc<Mutex<Drive>>, (u16, u16), (u16, u16)) {
    let file = esi::load(SERCOS_XML).expect("SERCOS ESI");
    let mut device = file.devices[0].clone();
    if let Some((out, inp)) = mbx {
        for sm in &mut device.sync_managers {
            match sm.kind {
                SmKind::MBoxOut => sm.default_size = Some(out),
                SmKind::MBoxIn => sm.default_size = Some(inp),
                _ => {}
            }
        }
    }
    let def = catalogue::load(DRIVE).expect("drive definition");
    let content = sii_from_device(&file, &device).expect("SII");
    let cfg = EscConfig::from_sii(sii::encode_padded(&content).expect("encode"));
    let m = cfg.mailbox.expect("mailbox");
    let soe = SoeServer::new(
        Box::new(SercosModel::new(&def).expect("SERCOS model")),
        sercos_idns(),
        usize::from(m.tx_size),
    );
    let shared = Arc::new(Mutex::new(Drive {
        soe,
        emcy_next: None,
        queued: Vec::new(),
        writes: Vec::new(),
        fragments_out: 0,
    }));
    let esc = Esc::new(cfg, Box::new(SharedDrive(shared.clone())));
    (
        esc,
        shared,
        (m.rx_offset, m.rx_size),
        (m.tx_offset, m.tx_size),
    )
}

/// CoE emergency (mailbox type 3, CoE service 1): error code, register, 5 bytes.
fn coe_emergency(code: u16) -> Vec<u8> {
    let mut body = CoeHeader {
        number: 0,
        service: CoeService::Emergency,
    }
    .encode()
    .to_vec();
    body.extend_from_slice(&code.to_le_bytes());
    body.extend_from_slice(&[0x04, 0, 0, 0, 0, 0]);
    let mut m = MailboxHeader {
        length: body.len() as u16,
        address: 0,
        channel: 0,
        priority: 0,
        mailbox_type: MailboxType::Coe,
        counter: 1,
    }
    .encode()
    .to_vec();
    m.extend_from_slice(&body);
    m
}

type R<T> = Result<T, String>;

#[derive(Debug)]
struct Outcome {
    value_92: R<i64>,
    value_159: R<i64>,
    raw_92: R<Vec<u8>>,
    name_92: R<String>,
    after_write_92: R<i64>,
    out_of_range_92: R<()>,
    signed_47: R<i64>,
    read_only_51: Result<(), MailboxError>,
    missing: Result<i64, MailboxError>,
    emcy_value_159: R<i64>,
    emcy_codes: Vec<u16>,
    // drive 2 (small mailboxes)
    frag_name_301: R<String>,
    frag_write_159: R<i64>,
}

#[test]
fn own_soe_client_reads_and_writes_idns() {
    let (d1_esc, d1, d1_sm0, d1_sm1) = drive(None);
    let (d2_esc, d2, d2_sm0, d2_sm1) = drive(Some((11, 24)));
    assert_eq!((d2_sm0.1, d2_sm1.1), (11, 24));
    let seg = Arc::new(Mutex::new(Segment::new(
        vec![coupler(), d1_esc, d2_esc],
        500,
    )));
    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("split once");
    let stop = Arc::new(AtomicBool::new(false));
    // Queued drive messages (ring position, drive) go to the read mailbox between frames.
    let drives = vec![(1, d1.clone()), (2, d2.clone())];
    let wire = spawn_wire(tx, rx, seg.clone(), stop.clone(), move |s| {
        for (pos, d) in &drives {
            let out = std::mem::take(&mut d.lock().unwrap().queued);
            for m in out {
                s.esc_mut(*pos).expect("drive ESC").push_mailbox(m);
            }
        }
    });
    let d1c = d1.clone();

    let outcome = wire::bounded(TEST_TIMEOUT, move || {
        futures_lite::future::block_on(async move {
            let md = MainDevice::new(pdu_loop, Timeouts::default(), MainDeviceConfig::default());
            let group = md
                .init_single_group::<8, 128>(ethercat_now)
                .await
                .expect("init_single_group");
            let a1 = group
                .subdevice(&md, 1)
                .expect("drive 1")
                .configured_address();
            let a2 = group
                .subdevice(&md, 2)
                .expect("drive 2")
                .configured_address();
            let mut c = SoeClient::new(a1, d1_sm0, d1_sm1);
            let s = |e: MailboxError| e.to_string();
            let idn = |t: &str| parse_idn(t).expect("IDN");

            let value_92 = c.read_value(&md, 0, idn("S-0-0092")).await.map_err(s);
            let value_159 = c.read_value(&md, 0, idn("S-0-0159")).await.map_err(s);
            let raw_92 = c
                .read_idn(&md, 0, idn("S-0-0092"), Element::Value)
                .await
                .map_err(s);
            let name_92 = c.read_name(&md, 0, idn("S-0-0092")).await.map_err(s);
            let after_write_92 = match c.write_value(&md, 0, idn("S-0-0092"), 500).await {
                Ok(()) => c.read_value(&md, 0, idn("S-0-0092")).await.map_err(s),
                Err(e) => Err(e.to_string()),
            };
            let out_of_range_92 = c
                .write_value(&md, 0, idn("S-0-0092"), 70_000)
                .await
                .map_err(s);
            let signed_47 = match c.write_value(&md, 0, idn("S-0-0047"), -1234).await {
                Ok(()) => c.read_value(&md, 0, idn("S-0-0047")).await.map_err(s),
                Err(e) => Err(e.to_string()),
            };
            let read_only_51 = c.write_value(&md, 0, idn("S-0-0051"), 1).await;
            let missing = c.read_value(&md, 0, idn("S-0-4095")).await;
            d1c.lock().unwrap().emcy_next = Some(coe_emergency(0x3220));
            let emcy_value_159 = c.read_value(&md, 0, idn("S-0-0159")).await.map_err(s);
            let emcy_codes = c.take_emergencies().iter().map(|e| e.code).collect();

            let mut c2 = SoeClient::new(a2, d2_sm0, d2_sm1);
            let frag_name_301 = c2.read_name(&md, 0, idn("S-0-0301")).await.map_err(s);
            let frag_write_159 = match c2.write_value(&md, 0, idn("S-0-0159"), 123_456).await {
                Ok(()) => c2.read_value(&md, 0, idn("S-0-0159")).await.map_err(s),
                Err(e) => Err(e.to_string()),
            };
            Outcome {
                value_92,
                value_159,
                raw_92,
                name_92,
                after_write_92,
                out_of_range_92,
                signed_47,
                read_only_51,
                missing,
                emcy_value_159,
                emcy_codes,
                frag_name_301,
                frag_write_159,
            }
        })
    });
    stop.store(true, Ordering::Relaxed);
    wire.join().expect("wire thread");
    eprintln!("{outcome:#?}");

    // Expectations from the drive definition and a fresh model, not from the client.
    let def = catalogue::load(DRIVE).expect("drive definition");
    let idn_defaults = sercos::config(&def).expect("[sercos]").idn_defaults;
    let toml_92 = idn_defaults
        .iter()
        .find(|(c, _)| *c == 92)
        .map(|(_, v)| *v)
        .expect("[sercos] idn S-0-0092");
    assert_eq!(toml_92, 1000);
    let fresh = SercosModel::new(&def).expect("model");
    assert_eq!(fresh.read_object(92, 0), Ok(toml_92));
    assert_eq!(
        fresh.read_object(159, 0),
        Ok(i64::from(def.model.following_error_window))
    );
    assert_eq!(outcome.value_92, Ok(toml_92));
    assert_eq!(
        outcome.value_159,
        Ok(i64::from(def.model.following_error_window))
    );
    // S-0-0092 is 2 bytes unsigned in the server's table: the raw value element.
    assert_eq!(outcome.raw_92, Ok((toml_92 as u16).to_le_bytes().to_vec()));
    let table = sercos_idns();
    let name_of = |n: u16| table.iter().find(|e| e.idn == n).expect("IDN").name.clone();
    assert_eq!(outcome.name_92, Ok(name_of(92)));

    // Write then read back; the model holds the value.
    assert_eq!(outcome.after_write_92, Ok(500));
    assert_eq!(d1.lock().unwrap().soe.model().read_object(92, 0), Ok(500));
    // 70000 does not fit u16: refused before sending, the value stays 500.
    assert_eq!(
        outcome.out_of_range_92,
        Err("value 70000 does not fit 2 byte(s) unsigned".into())
    );
    // Signed 4-byte IDN: sign extension on read.
    assert_eq!(outcome.signed_47, Ok(-1234));

    // SoE error replies: code and words.
    match &outcome.read_only_51 {
        Err(MailboxError::Soe {
            idn, code, text, ..
        }) => {
            assert_eq!((*idn, *code), (51, 0x7004));
            assert_eq!(*text, error_text(0x7004));
            assert_eq!(*text, "data cannot be changed (read only)");
        }
        other => panic!("write to read-only S-0-0051: {other:?}"),
    }
    match &outcome.missing {
        Err(
            e @ MailboxError::Soe {
                idn, code, text, ..
            },
        ) => {
            assert_eq!((*idn, *code, *text), (0x0FFF, 0x1001, "IDN does not exist"));
            assert_eq!(
                e.to_string(),
                "SoE S-0-4095 (drive 0): error 0x1001 (IDN does not exist)"
            );
        }
        other => panic!("read of missing S-0-4095: {other:?}"),
    }
    assert_eq!(format_idn(0x0FFF), "S-0-4095");

    // A CoE emergency in front of the SoE reply is collected, the SoE call succeeds.
    assert_eq!(
        outcome.emcy_value_159,
        Ok(i64::from(def.model.following_error_window))
    );
    assert_eq!(outcome.emcy_codes, vec![0x3220]);
    // Drive 1's writes (S-0-0092, S-0-0047, S-0-0051) each went out whole.
    let w1: Vec<(bool, u16)> = d1
        .lock()
        .unwrap()
        .writes
        .iter()
        .map(|w| (w.0, w.1))
        .collect();
    assert_eq!(w1, vec![(false, 92), (false, 47), (false, 51)]);

    // Drive 2: the 37-character name (41 bytes with the string lengths) comes in 3 fragments
    // of ≤ 14 bytes (24-byte read mailbox), joined by the client.
    assert_eq!(outcome.frag_name_301, Ok(name_of(301)));
    let d2 = d2.lock().unwrap();
    assert_eq!(d2.fragments_out, 2, "fragments after the first reply");
    // The 4-byte write of S-0-0159 = 123456 goes out in 4 fragments of 1 byte (11-byte write
    // mailbox): incomplete bit with the fragments left 3, 2, 1 in the IDN field, then the last
    // fragment with the IDN (notes §7.3, SOEM ecx_SoEwrite).
    let want: Vec<(bool, u16, Vec<u8>)> = 123_456u32
        .to_le_bytes()
        .iter()
        .zip([(true, 3u16), (true, 2), (true, 1), (false, 159)])
        .map(|(b, (inc, f))| (inc, f, vec![*b]))
        .collect();
    assert_eq!(d2.writes, want);
    // The server takes the IDN from the last fragment (the others carry the fragments left).
    assert_eq!(outcome.frag_write_159, Ok(123_456));
    assert_eq!(d2.soe.model().read_object(159, 0), Ok(123_456));
}
