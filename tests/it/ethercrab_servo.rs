//! ethercrab 0.7.1 in-process against an emulated segment of an EK1100 coupler and a CiA 402
//! servo built from its ESI file and a drive definition
//! ([`fieldprobe::sim::esc::device::emulated_servo`]): discovery with the ESI identity, CoE
//! SDO reads answered by the drive model, PDO discovery through 0x1C12/0x1C13 and the mapping
//! objects, OP, and the CiA 402 state machine over cyclic process data. Wiring as in
//! `tests/it/ethercrab_inproc.rs`; every wait is bounded.

use std::{
    sync::{
        atomic::{AtomicBool, Ordering},
        Arc, Mutex,
    },
    time::Duration,
};

use ethercrab::{
    std::ethercat_now, MainDevice, MainDeviceConfig, PduStorage, SubDeviceState, Timeouts,
};
use fieldprobe::drive::catalogue;
use fieldprobe::drive::model::ds402::Ds402Model;
use fieldprobe::esi::{self};
use fieldprobe::sim::esc::{device::emulated_servo, segment::Segment};

use crate::common::wire;
use wire::{coupler, spawn_wire};

const TEST_TIMEOUT: Duration = Duration::from_secs(30);
const MAX_SUBDEVICES: usize = 8;
const MAX_PDI: usize = 128;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE_SERVO: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

const SERVO_XML: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/esi/fieldprobe-cia402-servo.xml"
);
const EK1100_XML: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/esi/fieldprobe-ek1100.xml");
const DRIVE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/drives/cia402-generic.toml");

/// `ProductCode="#x…"` of the first `Type` element, read from the XML text without the ESI
/// parser.
fn product_code_from_xml(path: &str) -> u32 {
    let text = std::fs::read_to_string(path).expect("read ESI");
    let at = text
        .find("ProductCode=\"#x")
        .expect("ProductCode attribute")
        + 15;
    let hex: String = text[at..]
        .chars()
        .take_while(|c| c.is_ascii_hexdigit())
        .collect();
    u32::from_str_radix(&hex, 16).expect("hex product code")
}

#[derive(Debug)]
struct Outcome {
    identities: Vec<(u32, u32, u32)>,
    statusword: u16,
    statusword_op: u16,
    device_type: u32,
    identity_1018: (u32, u32),
    sizes: Vec<(usize, usize)>,
    /// (controlword sent, statusword seen, working counter) per cycle.
    cycles: Vec<(u16, u16, u16)>,
    states_ok: bool,
}

#[test]
fn servo_from_esi_reaches_operation_enabled() {
    let file = esi::load(SERVO_XML).expect("servo ESI");
    let device = file.devices[0].clone();
    let def = catalogue::load(DRIVE).expect("drive definition");
    let servo = emulated_servo(&file, &device, &def).expect("emulated servo");
    let reference = Ds402Model::new(&def);
    let expected_statusword = reference.read_object(0x6041, 0).expect("0x6041") as u16;

    let out_bits: u32 = device.rx_pdos.iter().map(|p| p.bit_len()).sum();
    let in_bits: u32 = device.tx_pdos.iter().map(|p| p.bit_len()).sum();
    assert_eq!((out_bits / 8, in_bits / 8), (9, 31));

    let seg = Arc::new(Mutex::new(Segment::new(vec![coupler(), servo], 500)));
    let (tx, rx, pdu_loop) = STORAGE_SERVO.try_split().expect("split once");
    let stop = Arc::new(AtomicBool::new(false));
    let wire = spawn_wire(tx, rx, seg.clone(), stop.clone(), |_| {});

    let outcome = wire::bounded(TEST_TIMEOUT, move || {
        futures_lite::future::block_on(async move {
            let md = MainDevice::new(
                pdu_loop,
                Timeouts {
                    state_transition: Duration::from_secs(2),
                    mailbox_response: Duration::from_secs(2),
                    ..Timeouts::default()
                },
                MainDeviceConfig {
                    dc_static_sync_iterations: 50,
                    ..MainDeviceConfig::default()
                },
            );
            let group = md
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercat_now)
                .await
                .expect("init_single_group");
            let identities = group
                .iter(&md)
                .map(|sd| {
                    let id = sd.identity();
                    (id.vendor_id, id.product_id, id.revision)
                })
                .collect();
            let sd = group.subdevice(&md, 1).expect("servo subdevice");
            let statusword = sd.sdo_read::<u16>(0x6041, 0).await.expect("SDO 0x6041");
            let device_type = sd.sdo_read::<u32>(0x1000, 0).await.expect("SDO 0x1000");
            let vendor = sd.sdo_read::<u32>(0x1018, 1).await.expect("SDO 0x1018:1");
            let product = sd.sdo_read::<u32>(0x1018, 2).await.expect("SDO 0x1018:2");

            let group = group.into_safe_op(&md).await.expect("PRE-OP -> SAFE-OP");
            let group = group.into_op(&md).await.expect("SAFE-OP -> OP");
            let sizes = group
                .iter(&md)
                .map(|sd| {
                    let io = sd.io_raw();
                    (io.outputs().len(), io.inputs().len())
                })
                .collect();

            let mut cycles = Vec::new();
            let mut states_ok = true;
            let mut sw = 0u16;
            for _ in 0..200 {
                let cw: u16 = match sw & 0x6F {
                    0x21 => 0x07,
                    0x23 | 0x27 => 0x0F,
                    _ => 0x06,
                };
                {
                    let sd = group.subdevice(&md, 1).expect("servo");
                    let mut o = sd.outputs_raw_mut();
                    o[0..2].copy_from_slice(&cw.to_le_bytes());
                    o[6] = 8; // CSP
                }
                let resp = group.tx_rx(&md).await.expect("tx_rx");
                states_ok &= resp
                    .subdevice_states
                    .iter()
                    .all(|s| *s == SubDeviceState::Op);
                let sd = group.subdevice(&md, 1).expect("servo");
                let i = sd.inputs_raw();
                sw = u16::from_le_bytes([i[0], i[1]]);
                cycles.push((cw, sw, resp.working_counter));
                if sw & 0x6F == 0x27 && cycles.len() > 3 {
                    break;
                }
            }
            // The statusword over CoE in OP, operation enabled: the SDO path reads the live model.
            let sd = group.subdevice(&md, 1).expect("servo subdevice");
            let statusword_op = sd
                .sdo_read::<u16>(0x6041, 0)
                .await
                .expect("SDO 0x6041 in OP");
            Outcome {
                identities,
                statusword,
                statusword_op,
                device_type,
                identity_1018: (vendor, product),
                sizes,
                cycles,
                states_ok,
            }
        })
    });
    stop.store(true, Ordering::Relaxed);
    let stats = wire.join().expect("wire thread");
    eprintln!("emulator: {stats:?}; outcome {outcome:#x?}");

    let product = product_code_from_xml(SERVO_XML);
    let ek1100 = esi::load(EK1100_XML).expect("EK1100 ESI");
    assert_eq!(outcome.identities.len(), 2);
    assert_eq!(
        outcome.identities[0],
        (
            ek1100.vendor.id,
            ek1100.devices[0].product_code,
            ek1100.devices[0].revision_no
        )
    );
    assert_eq!(outcome.identities[1].0, 0x0FB0);
    assert_eq!(outcome.identities[1].1, product);
    assert_eq!(outcome.identities[1].2, device.revision_no);
    // Before the first process-data cycle the drive is "not ready to switch on" (CiA 402:
    // statusword xxxx xxxx x0xx 0000); the model agrees.
    assert_eq!(outcome.statusword & 0x4F, 0x00);
    assert_eq!(outcome.statusword, expected_statusword);
    // In OP after enabling, the SDO read shows "operation enabled" (x01x 0111).
    assert_eq!(
        outcome.statusword_op & 0x6F,
        0x27,
        "{:#x}",
        outcome.statusword_op
    );
    assert_eq!(outcome.device_type, 0x0002_0192);
    assert_eq!(outcome.identity_1018, (0x0FB0, product));
    assert_eq!(
        outcome.sizes,
        vec![(0, 0), ((out_bits / 8) as usize, (in_bits / 8) as usize)]
    );
    assert!(outcome.states_ok, "{:?}", outcome.cycles);
    let (_, last_sw, _) = *outcome.cycles.last().unwrap();
    assert_eq!(last_sw & 0x6F, 0x27, "{:x?}", outcome.cycles);
    // The state machine passed through ready to switch on and switched on.
    let seen: Vec<u16> = outcome.cycles.iter().map(|c| c.1 & 0x6F).collect();
    assert!(seen.contains(&0x21), "{seen:x?}");
    assert!(seen.contains(&0x23), "{seen:x?}");
    // LRW on the servo: +1 inputs read, +2 outputs written.
    assert!(
        outcome.cycles.iter().all(|c| c.2 == 3),
        "{:?}",
        outcome.cycles
    );
    assert_eq!(stats.bad_frames, 0, "{stats:?}");
    let seg = seg.lock().unwrap();
    assert_eq!(seg.chain.escs[1].al_status() & 0x1F, 0x08);
}
