//! ethercrab 0.7.1's `MainDevice` driven in-process against an emulated segment
//! ([`fieldprobe::sim::esc::segment::Segment`]): no NIC, the PDU loop's frames are handed to the
//! emulated ESCs and back (notes `ethercat.md` §1.2).
//!
//! Devices: an EK1100-like coupler (no mailbox, no process data) and two I/O devices without a
//! mailbox whose SII images (identity, strings, General, FMMU, SM and PDO categories) are built
//! with `fieldprobe::esi::sii`. Every wait is bounded: the MainDevice side runs on its own thread
//! and the test fails if it does not finish within [`TEST_TIMEOUT`].

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
use fieldprobe::esi::sii::{
    self, data_type, fmmu_usage, general_flags, sm_enable, sm_type, Category, General, Pdo,
    PdoEntry, SiiContent, SiiHeader, SyncManager,
};
use fieldprobe::sim::esc::{segment::Segment, EchoApp, Esc, EscApplication, EscConfig, NullApp};

use crate::common::wire;
use wire::spawn_wire;

const TEST_TIMEOUT: Duration = Duration::from_secs(30);
const MAX_SUBDEVICES: usize = 8;
const MAX_PDI: usize = 64;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE_DISCOVER: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();
static STORAGE_OP: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();
static STORAGE_MBX: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

/// Identity and names of one emulated device.
#[derive(Debug, Clone, Copy)]
struct DeviceSpec {
    vendor: u32,
    product: u32,
    revision: u32,
    serial: u32,
    order: &'static str,
    name: &'static str,
    /// (output bytes, input bytes) of the process data; `None` = no process data (coupler).
    pd: Option<(u16, u16)>,
    /// Standard mailbox (size of each direction) with FoE as the only protocol, process data
    /// then on SM2/SM3; `None` = no mailbox, process data on SM0/SM1.
    mailbox: Option<u16>,
}

const COUPLER: DeviceSpec = DeviceSpec {
    vendor: 0x0000_0002,
    product: 0x044C_2C52,
    revision: 0x0011_0000,
    serial: 1,
    order: "EK1100",
    name: "EK1100 EtherCAT-Koppler (emulated)",
    pd: None,
    mailbox: None,
};

const IO_A: DeviceSpec = DeviceSpec {
    vendor: 0x00FF_0042,
    product: 0x0000_1001,
    revision: 0x0001_0002,
    serial: 1001,
    order: "FP-IO2",
    name: "fieldprobe emulated I/O, 2 bytes out/in",
    pd: Some((2, 2)),
    mailbox: None,
};

const IO_B: DeviceSpec = DeviceSpec {
    vendor: 0x00FF_0042,
    product: 0x0000_1002,
    revision: 0x0002_0000,
    serial: 1002,
    order: "FP-IO4",
    name: "fieldprobe emulated I/O, 4 bytes out/in",
    pd: Some((4, 4)),
    mailbox: None,
};

const IO_MBX: DeviceSpec = DeviceSpec {
    vendor: 0x00FF_0042,
    product: 0x0000_2001,
    revision: 0x0001_0000,
    serial: 2001,
    order: "FP-MBX2",
    name: "fieldprobe emulated I/O with FoE mailbox",
    pd: Some((2, 2)),
    mailbox: Some(128),
};

fn entries(index: u16, bytes: u16) -> Vec<PdoEntry> {
    (0..bytes)
        .map(|i| PdoEntry {
            index,
            sub_index: (i + 1) as u8,
            name_idx: 0,
            data_type: data_type::UINT8,
            bit_len: 8,
            flags: 0,
        })
        .collect()
}

/// SII image for `spec`: optional standard mailbox on SM0/SM1 (0x1000..); process data on the
/// next two SMs (outputs 0x1400, inputs 0x1500) described by one RxPDO/TxPDO of UINT8 entries.
fn sii_image(spec: &DeviceSpec) -> Vec<u8> {
    let mut c = SiiContent {
        header: SiiHeader {
            vendor_id: spec.vendor,
            product_code: spec.product,
            revision: spec.revision,
            serial: spec.serial,
            eeprom_size: 7, // 1 KiB
            standard_mailbox: match spec.mailbox {
                Some(size) => sii::MailboxLayout {
                    rx_offset: 0x1000,
                    rx_size: size,
                    tx_offset: 0x1000 + size,
                    tx_size: size,
                },
                None => sii::MailboxLayout::default(),
            },
            mailbox_protocols: if spec.mailbox.is_some() {
                sii::mailbox_protocols::FOE
            } else {
                0
            },
            ..SiiHeader::default()
        },
        categories: Vec::new(),
    };
    let group_idx = c.add_string("fieldprobe").unwrap();
    let order_idx = c.add_string(spec.order).unwrap();
    let name_idx = c.add_string(spec.name).unwrap();
    c.categories.push(Category::General(General {
        group_idx,
        order_idx,
        name_idx,
        flags: general_flags::ENABLE_SAFEOP,
        current_on_ebus: if spec.pd.is_some() { 100 } else { -2000 },
        foe_details: u8::from(spec.mailbox.is_some()),
        physical_ports: 0x0011,
        ..General::default()
    }));
    if let Some((outputs, inputs)) = spec.pd {
        c.categories.push(Category::Fmmu(vec![
            fmmu_usage::OUTPUTS,
            fmmu_usage::INPUTS,
        ]));
        let mut sms = Vec::new();
        if let Some(size) = spec.mailbox {
            sms.push(SyncManager {
                start: 0x1000,
                length: size,
                control: 0x26,
                status: 0,
                enable: sm_enable::ENABLE,
                sm_type: sm_type::MAILBOX_OUT,
            });
            sms.push(SyncManager {
                start: 0x1000 + size,
                length: size,
                control: 0x22,
                status: 0,
                enable: sm_enable::ENABLE,
                sm_type: sm_type::MAILBOX_IN,
            });
        }
        let (out_sm, in_sm) = (sms.len() as u8, sms.len() as u8 + 1);
        sms.push(SyncManager {
            start: 0x1400,
            length: outputs,
            control: 0x64,
            status: 0,
            enable: sm_enable::ENABLE,
            sm_type: sm_type::OUTPUTS,
        });
        sms.push(SyncManager {
            start: 0x1500,
            length: inputs,
            control: 0x20,
            status: 0,
            enable: sm_enable::ENABLE,
            sm_type: sm_type::INPUTS,
        });
        c.categories.push(Category::SyncManagers(sms));
        c.categories.push(Category::RxPdos(vec![Pdo {
            index: 0x1600,
            sync_manager: out_sm,
            dc_sync: 0,
            name_idx: 0,
            flags: 0,
            entries: entries(0x7000, outputs),
        }]));
        c.categories.push(Category::TxPdos(vec![Pdo {
            index: 0x1A00,
            sync_manager: in_sm,
            dc_sync: 0,
            name_idx: 0,
            flags: 0,
            entries: entries(0x6000, inputs),
        }]));
    }
    sii::encode(&c).expect("SII image encodes")
}

fn device(spec: &DeviceSpec) -> Esc {
    let cfg = EscConfig::from_sii(sii_image(spec));
    let app: Box<dyn EscApplication> = match spec.pd {
        None => Box::new(NullApp),
        Some((o, i)) => {
            let mut app = EchoApp::new(o, i);
            app.loopback = true;
            Box::new(app)
        }
    };
    Esc::new(cfg, app)
}

fn segment(specs: &[DeviceSpec]) -> Arc<Mutex<Segment>> {
    Arc::new(Mutex::new(Segment::new(
        specs.iter().map(device).collect(),
        500,
    )))
}

fn main_device(pdu_loop: ethercrab::PduLoop<'static>) -> MainDevice<'static> {
    MainDevice::new(
        pdu_loop,
        // The in-process wire answers every frame at once: no wall-clock timeout may decide
        // here (issue 15: ethercrab's 30 ms PDU timeout fired with the CPU saturated). Every
        // wait is bounded by `wire::bounded(TEST_TIMEOUT, …)` instead.
        Timeouts {
            pdu: TEST_TIMEOUT,
            eeprom: TEST_TIMEOUT,
            mailbox_echo: TEST_TIMEOUT,
            mailbox_response: TEST_TIMEOUT,
            state_transition: TEST_TIMEOUT,
            ..Timeouts::default()
        },
        MainDeviceConfig {
            dc_static_sync_iterations: 50,
            ..MainDeviceConfig::default()
        },
    )
}

#[test]
fn init_single_group_discovers_emulated_subdevices() {
    let specs = [COUPLER, IO_A, IO_B];
    let (tx, rx, pdu_loop) = STORAGE_DISCOVER.try_split().expect("split once");
    let seg = segment(&specs);
    let stop = Arc::new(AtomicBool::new(false));
    let wire = spawn_wire(tx, rx, seg.clone(), stop.clone(), |_| {});

    let found = wire::bounded(TEST_TIMEOUT, move || {
        futures_lite::future::block_on(async move {
            let md = main_device(pdu_loop);
            let group = md
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercat_now)
                .await
                .expect("init_single_group");
            let mut found = Vec::new();
            for sd in group.iter(&md) {
                let id = sd.identity();
                let desc = sd.description().await.expect("description");
                found.push((
                    id.vendor_id,
                    id.product_id,
                    id.revision,
                    id.serial,
                    sd.name().to_string(),
                    desc.map(|d| d.to_string()),
                    sd.configured_address(),
                ));
            }
            found
        })
    });
    stop.store(true, Ordering::Relaxed);
    let stats = wire.join().expect("wire thread");
    eprintln!("emulator: {stats:?}; found {found:#x?}");

    assert_eq!(found.len(), specs.len(), "found {found:#?}");
    for (i, (f, s)) in found.iter().zip(specs.iter()).enumerate() {
        assert_eq!(
            (f.0, f.1, f.2, f.3),
            (s.vendor, s.product, s.revision, s.serial)
        );
        assert_eq!(f.4, s.order);
        assert_eq!(f.5.as_deref(), Some(s.name));
        assert_eq!(f.6, 0x1000 + i as u16);
    }
    assert_eq!(stats.bad_frames, 0, "{stats:?}");
    let seg = seg.lock().unwrap();
    for (i, esc) in seg.chain.escs.iter().enumerate() {
        assert_eq!(esc.station_address(), 0x1000 + i as u16);
        assert_eq!(
            esc.al_status() & 0x1F,
            0x02,
            "device {i} in PRE-OP without error"
        );
    }
}

#[test]
fn group_reaches_op_and_exchanges_process_data() {
    run_to_op(&STORAGE_OP, &[COUPLER, IO_A, IO_B]);
}

#[test]
fn mailbox_device_without_coe_reaches_op() {
    run_to_op(&STORAGE_MBX, &[COUPLER, IO_MBX, IO_B]);
}

/// Init, SAFE-OP, OP, then five `tx_rx` cycles checking WKC, states and the echoed inputs.
fn run_to_op(storage: &'static PduStorage<MAX_FRAMES, MAX_PDU_DATA>, specs: &[DeviceSpec]) {
    let (tx, rx, pdu_loop) = storage.try_split().expect("split once");
    let seg = segment(specs);
    let stop = Arc::new(AtomicBool::new(false));
    let wire = spawn_wire(tx, rx, seg.clone(), stop.clone(), |_| {});

    let result = wire::bounded(TEST_TIMEOUT, move || {
        futures_lite::future::block_on(async move {
            let md = main_device(pdu_loop);
            let group = md
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercat_now)
                .await
                .expect("init_single_group");
            let group = group.into_safe_op(&md).await.expect("PRE-OP -> SAFE-OP");
            let group = group.into_op(&md).await.expect("SAFE-OP -> OP");
            let sizes: Vec<(usize, usize)> = group
                .iter(&md)
                .map(|sd| {
                    let io = sd.io_raw();
                    (io.outputs().len(), io.inputs().len())
                })
                .collect();
            let mut log = Vec::new();
            for cycle in 0u8..5 {
                for (k, sd) in group.iter(&md).enumerate() {
                    let mut o = sd.outputs_raw_mut();
                    for (j, b) in o.iter_mut().enumerate() {
                        *b = cycle.wrapping_mul(16).wrapping_add((k * 4 + j) as u8);
                    }
                }
                let resp = group.tx_rx(&md).await.expect("tx_rx");
                let io: Vec<(Vec<u8>, Vec<u8>)> = group
                    .iter(&md)
                    .map(|sd| {
                        let io = sd.io_raw();
                        (io.outputs().to_vec(), io.inputs().to_vec())
                    })
                    .collect();
                log.push((resp.working_counter, resp.subdevice_states.to_vec(), io));
            }
            (sizes, log)
        })
    });
    stop.store(true, Ordering::Relaxed);
    let stats = wire.join().expect("wire thread");
    let (sizes, log) = result;
    eprintln!("emulator: {stats:?}; PD sizes {sizes:?}; cycles {log:02x?}");

    let expected_sizes: Vec<(usize, usize)> = specs
        .iter()
        .map(|s| {
            s.pd.map_or((0, 0), |(o, i)| (usize::from(o), usize::from(i)))
        })
        .collect();
    assert_eq!(sizes, expected_sizes);
    let io_devices = specs.iter().filter(|s| s.pd.is_some()).count() as u16;
    assert_eq!(stats.bad_frames, 0, "{stats:?}");
    for (cycle, (wkc, states, io)) in log.iter().enumerate() {
        // LRW: +1 (inputs read) +2 (outputs written) per I/O device; the coupler maps nothing.
        assert_eq!(*wkc, 3 * io_devices, "cycle {cycle}");
        assert!(
            states.iter().all(|s| *s == SubDeviceState::Op),
            "{states:?}"
        );
        // LRW reads the inputs before it writes the outputs, so the inputs are the inverted
        // outputs of the previous cycle (all outputs 0 before the first one).
        for (o, i) in io.iter().skip(1) {
            let expected: Vec<u8> = o
                .iter()
                .map(|b| {
                    if cycle == 0 {
                        0xFF
                    } else {
                        !b.wrapping_sub(16)
                    }
                })
                .collect();
            assert_eq!(*i, expected, "cycle {cycle}: outputs {o:02x?}");
        }
    }
    let seg = seg.lock().unwrap();
    for (i, esc) in seg.chain.escs.iter().enumerate() {
        assert_eq!(
            esc.al_status() & 0x1F,
            0x08,
            "device {i} in OP without error"
        );
    }
}
