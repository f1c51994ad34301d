//! Our CoE mailbox client (EtherCAT) against an emulated SubDevice whose object 0x2000 answers
//! a segmented upload endlessly (a test application in front of the servo's CoE server, as
//! in `tests/it/ethercat_mailbox_client.rs`): 0x2000:01 announces 100 bytes and answers every
//! segment with no data and no end bit (the device repeats its empty answer for ever);
//! 0x2000:02 announces 10 bytes and sends 7 per segment without end. Wall clock, bounded.

use std::{
    sync::{
        atomic::{AtomicBool, Ordering},
        Arc, Mutex,
    },
    time::{Duration, Instant},
};

use ethercrab::{std::ethercat_now, MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use fieldprobe::bus::ethercat::mailbox::{CoeClient, MailboxError};
use fieldprobe::bus::ethercat::wire::{CoeHeader, CoeService, MailboxHeader, MailboxType};
use fieldprobe::drive::catalogue;
use fieldprobe::drive::model::ds402::Ds402Model;
use fieldprobe::esi::{self, sii, to_sii::sii_from_device};
use fieldprobe::sim::esc::coe::{ds402_objects, CoeServer};
use fieldprobe::sim::esc::{segment::Segment, Esc, EscApplication, EscConfig};

use crate::common::wire;
use wire::{coupler, spawn_wire};

const TEST_TIMEOUT: Duration = Duration::from_secs(60);
static STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

const SERVO_XML: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/esi/fieldprobe-cia402-servo.xml"
);
const DRIVE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/drives/cia402-generic.toml");

/// The servo's CoE server, except for 0x2000:01 / :02, which never end; aborts received
/// for 0x2000 are recorded.
struct Endless {
    coe: CoeServer,
    sm1_len: usize,
    counter: u8,
    /// Sub-index of the running hostile upload.
    running: Option<u8>,
    aborts: Arc<Mutex<Vec<(u8, u32)>>>,
}

impl Endless {
    fn reply(&mut self, sdo: [u8; 8]) -> Vec<u8> {
        self.counter = self.counter % 7 + 1;
        let mut m = MailboxHeader {
            length: 10,
            address: 0,
            channel: 0,
            priority: 0,
            mailbox_type: MailboxType::Coe,
            counter: self.counter,
        }
        .encode()
        .to_vec();
        m.extend_from_slice(
            &CoeHeader {
                number: 0,
                service: CoeService::SdoResponse,
            }
            .encode(),
        );
        m.extend_from_slice(&sdo);
        m.resize(self.sm1_len.max(m.len()), 0);
        m
    }
}

impl EscApplication for Endless {
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        let sdo = data.get(8..16).and_then(|s| <[u8; 8]>::try_from(s).ok());
        let coe = data
            .get(6..8)
            .map(|c| u16::from_le_bytes([c[0], c[1]]) >> 12);
        if let (Some(s), Some(2)) = (sdo, coe) {
            let mux = (u16::from_le_bytes([s[1], s[2]]), s[3]);
            match s[0] {
                // Initiate upload request of 0x2000:01 / :02: segmented, size 100 / 10.
                0x40 if mux.0 == 0x2000 && (1..=2).contains(&mux.1) => {
                    self.running = Some(mux.1);
                    let size: u32 = if mux.1 == 1 { 100 } else { 10 };
                    let z = size.to_le_bytes();
                    return Some(self.reply([0x41, s[1], s[2], s[3], z[0], z[1], z[2], z[3]]));
                }
                // Upload segment request 011t0000 while the hostile upload runs.
                0x60 | 0x70 if self.running.is_some() => {
                    let t = s[0] & 0x10;
                    return Some(match self.running {
                        Some(1) => self.reply([t | (7 << 1), 0, 0, 0, 0, 0, 0, 0]),
                        _ => self.reply([t, 1, 2, 3, 4, 5, 6, 7]),
                    });
                }
                0x80 if mux.0 == 0x2000 => {
                    self.running = None;
                    let code = u32::from_le_bytes([s[4], s[5], s[6], s[7]]);
                    self.aborts.lock().unwrap().push((mux.1, code));
                    return None;
                }
                _ => self.running = None,
            }
        }
        self.coe.handle(data)
    }
}

struct Outcome {
    endless: Result<Vec<u8>, MailboxError>,
    took: Duration,
    beyond: Result<Vec<u8>, MailboxError>,
    after: Result<Vec<u8>, String>,
}

#[test]
fn coe_upload_that_never_ends_is_aborted_at_the_transfer_bound() {
    let file = esi::load(SERVO_XML).expect("servo ESI");
    let device = file.devices[0].clone();
    let def = catalogue::load(DRIVE).expect("drive definition");
    let content = sii_from_device(&file, &device).expect("SII");
    let cfg = EscConfig::from_sii(sii::encode_padded(&content).expect("encode"));
    let mbx = cfg.mailbox.expect("mailbox");
    let (sm0, sm1) = ((mbx.rx_offset, mbx.rx_size), (mbx.tx_offset, mbx.tx_size));
    let aborts = Arc::new(Mutex::new(Vec::new()));
    let app = Endless {
        coe: CoeServer::new(
            Box::new(Ds402Model::new(&def)),
            ds402_objects(device.name()),
            usize::from(mbx.tx_size),
        ),
        sm1_len: usize::from(mbx.tx_size),
        counter: 0,
        running: None,
        aborts: aborts.clone(),
    };
    let servo = Esc::new(cfg, Box::new(app));
    let seg = Arc::new(Mutex::new(Segment::new(vec![coupler(), servo], 500)));
    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("split once");
    let stop = Arc::new(AtomicBool::new(false));
    let wire = spawn_wire(tx, rx, seg, stop.clone(), |_| {});
    let bound = Duration::from_millis(1500);

    let o = wire::bounded(TEST_TIMEOUT, move || {
        futures_lite::future::block_on(async move {
            let md = MainDevice::new(
                pdu_loop,
                Timeouts {
                    mailbox_response: Duration::from_secs(2),
                    ..Timeouts::default()
                },
                MainDeviceConfig::default(),
            );
            let group = md
                .init_single_group::<8, 128>(ethercat_now)
                .await
                .expect("init_single_group");
            let sd = group.subdevice(&md, 1).expect("servo subdevice");
            let mut c = CoeClient::new(sd.configured_address(), sm0, sm1);
            c.transfer_timeout = bound;
            let t = Instant::now();
            let endless = c.sdo_upload(&md, 0x2000, 1).await;
            let took = t.elapsed();
            let beyond = c.sdo_upload(&md, 0x2000, 2).await;
            let after = c
                .sdo_upload(&md, 0x1000, 0)
                .await
                .map_err(|e| e.to_string());
            Outcome {
                endless,
                took,
                beyond,
                after,
            }
        })
    });
    stop.store(true, Ordering::Relaxed);
    wire.join().expect("wire thread");

    // The endless upload: ended by the bound, abort 0x05040000 sent, the message says what
    // was expected and what came.
    let e = o.endless.expect_err("an endless upload must fail");
    println!("endless CoE upload: aborted after {:?}: {e}", o.took);
    assert!(matches!(e, MailboxError::TransferTimeout { .. }), "{e:?}");
    assert!(
        o.took >= bound && o.took < bound + Duration::from_secs(2),
        "took {:?}, bound {bound:?}",
        o.took
    );
    let text = e.to_string();
    for want in [
        "SDO 0x2000:01 upload not finished after",
        "the device kept answering",
        "0 of the 100 bytes announced",
        "sent abort 0x05040000",
    ] {
        assert!(text.contains(want), "{want:?} not in {text:?}");
    }
    // More than announced: abort 0x06070012 at the second segment.
    let e = o.beyond.expect_err("more than announced must fail");
    let text = e.to_string();
    assert!(
        text.contains("10 announced") && text.contains("0x06070012"),
        "{text}"
    );
    assert_eq!(
        *aborts.lock().unwrap(),
        vec![(1, 0x0504_0000), (2, 0x0607_0012)]
    );
    // Device and client serve the next transfer.
    assert_eq!(o.after, Ok(0x0002_0192u32.to_le_bytes().to_vec()));
}
