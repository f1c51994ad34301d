//! ethercrab 0.7.1 over a real (virtual) Ethernet link: `fieldprobe sim ethercat` answers on
//! one end of a veth pair, the stock `ethercrab::std::tx_rx_task` drives the other end
//! (notes `ethercat.md` §0 point 2, §1.3).
//!
//! Isolation: the test re-executes its own binary inside a fresh unprivileged user + network
//! namespace (`unshare -rn`), where it is root and can create the veth pair without touching
//! the host. All traffic stays inside that namespace, which disappears with its processes.
//! If `unshare`, user namespaces, `ip` or veth are not available, the test prints `SKIP` and
//! passes. Every wait is bounded: the emulator runs with `--seconds` and is killed at the end,
//! the namespace child is killed after [`OUTER_TIMEOUT`]. Harness: `tests/common/veth.rs`.

use std::{
    ffi::OsString,
    sync::mpsc,
    thread,
    time::{Duration, Instant},
};

use ethercrab::{
    std::{ethercat_now, tx_rx_task},
    MainDevice, MainDeviceConfig, PduStorage, SubDeviceState, Timeouts,
};

/// Set in the re-executed test process (inside the namespace).
const INNER_ENV: &str = "FIELDPROBE_VETH_INNER";
const TEST_NAME: &str = "ethercrab_over_veth_finds_esi_devices";
const OUTER_TIMEOUT: Duration = Duration::from_secs(60);
const INNER_TIMEOUT: Duration = Duration::from_secs(30);
/// Lifetime of the emulator process (it is killed earlier when the test is done).
const EMULATOR_SECONDS: &str = "40";
const ESI_FILES: [&str; 2] = ["esi/fieldprobe-ek1100.xml", "esi/fieldprobe-el5101.xml"];

const MAX_SUBDEVICES: usize = 8;
const MAX_PDI: usize = 64;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

use crate::common::esi_xml;
use crate::common::veth;
use esi_xml::{esi_identities, EsiIdentity};
use veth::{start_emulator, VethPair, MASTER_IF};

#[test]
fn ethercrab_over_veth_finds_esi_devices() {
    let _one_module = crate::gate::enter(module_path!());
    if veth::inner_env(INNER_ENV).is_some() {
        inner();
        return;
    }
    veth::run_in_veth_namespace(TEST_NAME, INNER_ENV, OUTER_TIMEOUT, || OsString::from("1"));
}

/// Inside the namespace: veth pair, emulator on one end, ethercrab on the other.
fn inner() {
    let t0 = Instant::now();
    let _pair = VethPair::create();

    let expected: Vec<EsiIdentity> = esi_identities(&ESI_FILES);

    let (emu, emu_log) = start_emulator(&ESI_FILES, EMULATOR_SECONDS, &[]);
    let t_ready = t0.elapsed();

    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("split once");
    thread::spawn(move || {
        let task = tx_rx_task(MASTER_IF, tx, rx).expect("open raw socket on v0");
        let _ = futures_lite::future::block_on(task);
    });

    let (done_tx, done_rx) = mpsc::channel();
    thread::spawn(move || {
        let r = futures_lite::future::block_on(async move {
            let md = MainDevice::new(
                pdu_loop,
                // Generous bounds: the frames cross a real interface to an emulator in another
                // process, and a loaded CI machine delayed a reply past ethercrab's default
                // 30 ms PDU timeout ("init_single_group: Timeout(Pdu)" in a saturated run).
                Timeouts {
                    state_transition: Duration::from_secs(2),
                    pdu: Duration::from_millis(500),
                    eeprom: Duration::from_millis(500),
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
            let mut found = Vec::new();
            for sd in group.iter(&md) {
                let id = sd.identity();
                let desc = sd.description().await.expect("description");
                found.push(EsiIdentity {
                    vendor: id.vendor_id,
                    product: id.product_id,
                    revision: id.revision,
                    type_name: sd.name().to_string(),
                    name: desc.map(|d| d.to_string()).unwrap_or_default(),
                });
            }
            let t_init = Instant::now();
            let group = group.into_safe_op(&md).await.expect("PRE-OP -> SAFE-OP");
            let group = group.into_op(&md).await.expect("SAFE-OP -> OP");
            let mut cycles = Vec::new();
            for _ in 0..5 {
                let resp = group.tx_rx(&md).await.expect("tx_rx");
                cycles.push((resp.working_counter, resp.subdevice_states.to_vec()));
            }
            (found, cycles, t_init.elapsed())
        });
        let _ = done_tx.send(r);
    });
    let (found, cycles, t_op) = match done_rx.recv_timeout(INNER_TIMEOUT) {
        Ok(r) => r,
        Err(e) => panic!("MainDevice side did not finish within {INNER_TIMEOUT:?}: {e}"),
    };
    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!(
        "emulator ready after {t_ready:?}; master done after {:?} (SAFE-OP/OP + 5 cycles {t_op:?})",
        t0.elapsed()
    );
    println!("emulator log: {log:?}");
    println!("found: {found:#x?}");
    println!("cycles (wkc, states): {cycles:?}");

    assert_eq!(found, expected);
    for (wkc, states) in &cycles {
        assert!(
            states.iter().all(|s| *s == SubDeviceState::Op),
            "{states:?}"
        );
        // LRW: +1 read +2 write for the terminal with process data; the coupler maps nothing.
        assert_eq!(*wkc, 3, "{cycles:?}");
    }
    println!("INNER OK");
}
