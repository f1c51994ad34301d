//! fieldprobe's own CoE client ([`fieldprobe::bus::ethercat::mailbox::CoeClient`]) on
//! ethercrab 0.7.1's raw command API against an emulated CiA 402 servo (CoE server from
//! `sim::esc::coe` behind a test application that shares it with the wire thread, which pumps
//! device-initiated messages into the read mailbox between frames). Wiring as in
//! `tests/it/ethercrab_servo.rs`; every wait is bounded.

use std::{
    sync::{
        atomic::{AtomicBool, Ordering},
        Arc, Mutex,
    },
    time::Duration,
};

use ethercrab::{std::ethercat_now, MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use fieldprobe::bus::ethercat::mailbox::{CoeClient, MailboxError};
use fieldprobe::drive::catalogue;
use fieldprobe::drive::model::ds402::Ds402Model;
use fieldprobe::esi::{self, sii, to_sii::sii_from_device, Pdo};
use fieldprobe::sim::esc::coe::{ds402_objects, Access, CoeServer, ObjectEntry};
use fieldprobe::sim::esc::device::pdo_objects;
use fieldprobe::sim::esc::{segment::Segment, Esc, EscApplication, EscConfig};

use crate::common::wire;
use wire::{coupler, spawn_wire};

const TEST_TIMEOUT: Duration = Duration::from_secs(30);
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

const SERVO_XML: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/esi/fieldprobe-cia402-servo.xml"
);
const DRIVE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/drives/cia402-generic.toml");

/// Mailbox-only application sharing its CoE server with the test.
struct SharedCoe(Arc<Mutex<CoeServer>>);

impl EscApplication for SharedCoe {
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        self.0.lock().unwrap().handle(data)
    }
}

/// Servo ESC (PRE-OP capable) + its shared CoE server + (SM0, SM1) mailbox areas.
#[allow(clippy::type_complexity)]
fn servo() -> (Esc, Arc<Mutex<CoeServer>>, (u16, u16), (u16, u16)) {
    let file = esi::load(SERVO_XML).expect("servo ESI");
    let device = file.devices[0].clone();
    let def = catalogue::load(DRIVE).expect("drive definition");
    let content = sii_from_device(&file, &device).expect("SII");
    let cfg = EscConfig::from_sii(sii::encode_padded(&content).expect("encode"));
    let mbx = cfg.mailbox.expect("mailbox");
    let rx: Vec<&Pdo> = device
        .rx_pdos
        .iter()
        .filter(|p| p.sm == Some(cfg.output_sm))
        .collect();
    let tx: Vec<&Pdo> = device
        .tx_pdos
        .iter()
        .filter(|p| p.sm == Some(cfg.input_sm))
        .collect();
    let mut entries = ds402_objects(device.name());
    entries.extend(pdo_objects(0x1C12, &rx));
    entries.extend(pdo_objects(0x1C13, &tx));
    let coe = Arc::new(Mutex::new(CoeServer::new(
        Box::new(Ds402Model::new(&def)),
        entries,
        usize::from(mbx.tx_size),
    )));
    let esc = Esc::new(cfg, Box::new(SharedCoe(coe.clone())));
    (
        esc,
        coe,
        (mbx.rx_offset, mbx.rx_size),
        (mbx.tx_offset, mbx.tx_size),
    )
}

#[derive(Debug)]
struct Outcome {
    device_type: Vec<u8>,
    long_ours: Result<Vec<u8>, String>,
    long_ethercrab_is_err: bool,
    u64_readback: Result<Vec<u8>, String>,
    bytes_readback: Result<Vec<u8>, String>,
    emcy_value: Result<Vec<u8>, String>,
    emcy_codes: Vec<u16>,
    missing: Result<u32, String>,
    too_large: Result<(usize, usize), String>,
    after_too_large: Result<Vec<u8>, String>,
}

#[test]
fn own_coe_client_fixes_ethercrab_defects() {
    let (servo, coe, sm0, sm1) = servo();
    let long: Vec<u8> = (0..300u32).map(|i| (i * 7 + 3) as u8).collect();
    {
        let mut c = coe.lock().unwrap();
        c.insert(ObjectEntry::bytes(0x2000, 0, Access::Rw, &long, 512));
        c.insert(ObjectEntry::bytes(0x2001, 0, Access::Rw, &[0; 8], 8));
        c.insert(ObjectEntry::bytes(0x2002, 0, Access::Rw, b"", 400));
        // One byte more than the client accepts (1 MiB, limits::MAX_MAILBOX_OBJECT_BYTES).
        let huge = vec![0xA5; (1 << 20) + 1];
        c.insert(ObjectEntry::bytes(0x2003, 0, Access::Ro, &huge, huge.len()));
    }
    let seg = Arc::new(Mutex::new(Segment::new(vec![coupler(), servo], 500)));
    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("split once");
    let stop = Arc::new(AtomicBool::new(false));
    let queued = coe.clone();
    // Device-initiated / queued messages go to the read mailbox between frames.
    let wire = spawn_wire(tx, rx, seg.clone(), stop.clone(), move |s| {
        let out = queued.lock().unwrap().take_outgoing();
        for m in out {
            s.esc_mut(1).expect("servo").push_mailbox(m);
        }
    });
    let coe2 = coe.clone();
    let long2 = long.clone();
    let big: Vec<u8> = (0..250u32).map(|i| (i ^ 0x5A) as u8).collect();
    let big2 = big.clone();

    let outcome = wire::bounded(TEST_TIMEOUT, move || {
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
            let s = |r: Result<Vec<u8>, MailboxError>| r.map_err(|e| e.to_string());
            let device_type = c.sdo_upload(&md, 0x1000, 0).await.expect("0x1000");
            let long_ours = s(c.sdo_upload(&md, 0x2000, 0).await);
            let long_ethercrab_is_err = sd.sdo_read::<[u8; 300]>(0x2000, 0).await.is_err();
            let u64v = 0x1122_3344_5566_7788u64.to_le_bytes();
            let u64_readback = match c.sdo_download(&md, 0x2001, 0, &u64v).await {
                Ok(()) => s(c.sdo_upload(&md, 0x2001, 0).await),
                Err(e) => Err(e.to_string()),
            };
            let bytes_readback = match c.sdo_download(&md, 0x2002, 0, &big2).await {
                Ok(()) => s(c.sdo_upload(&md, 0x2002, 0).await),
                Err(e) => Err(e.to_string()),
            };
            coe2.lock().unwrap().faults.emcy_before_next_sdo = Some((0x3220, 0x04));
            let emcy_value = s(c.sdo_upload(&md, 0x1000, 0).await);
            let emcy_codes = c.take_emergencies().iter().map(|e| e.code).collect();
            let missing = match c.sdo_upload(&md, 0x2FFF, 0).await {
                Err(MailboxError::Abort { code, .. }) => Ok(code),
                other => Err(format!("{other:?}")),
            };
            let too_large = match c.sdo_upload(&md, 0x2003, 0).await {
                Err(MailboxError::ObjectTooLarge { size, limit }) => Ok((size, limit)),
                other => Err(format!("{:?}", other.map(|v| v.len()))),
            };
            // The client aborted the transfer: the server serves the next request.
            let after_too_large = s(c.sdo_upload(&md, 0x1000, 0).await);
            Outcome {
                too_large,
                after_too_large,
                device_type,
                long_ours,
                long_ethercrab_is_err,
                u64_readback,
                bytes_readback,
                emcy_value,
                emcy_codes,
                missing,
            }
        })
    });
    stop.store(true, Ordering::Relaxed);
    wire.join().expect("wire thread");
    eprintln!("{outcome:#x?}");

    assert_eq!(outcome.device_type, 0x0002_0192u32.to_le_bytes().to_vec());
    // Defect 1: ethercrab's own segmented upload fails; ours returns the exact bytes.
    assert!(outcome.long_ethercrab_is_err);
    assert_eq!(outcome.long_ours.as_deref(), Ok(long2.as_slice()));
    // Defect 3: downloads > 4 bytes (normal and segmented).
    assert_eq!(
        outcome.u64_readback,
        Ok(0x1122_3344_5566_7788u64.to_le_bytes().to_vec())
    );
    assert_eq!(outcome.bytes_readback, Ok(big));
    // Defect 2: EMCY before the SDO answer (ethercrab's sdo_read panics here, not called).
    assert_eq!(
        outcome.emcy_value,
        Ok(0x0002_0192u32.to_le_bytes().to_vec())
    );
    assert_eq!(outcome.emcy_codes, vec![0x3220]);
    // A missing object: the server's abort (CoE service 2, command 0x80) comes back as
    // MailboxError::Abort with CiA 301 0x06020000 "object does not exist".
    assert_eq!(outcome.missing, Ok(0x0602_0000));
    // A hostile or broken device announcing more than 1 MiB: refused before any segment.
    assert_eq!(outcome.too_large, Ok(((1 << 20) + 1, 1 << 20)));
    assert_eq!(
        outcome.after_too_large,
        Ok(0x0002_0192u32.to_le_bytes().to_vec())
    );
}
