//! `fieldprobe sim ethercat` keeps its own clock on a real (virtual) interface: a stock
//! ethercrab 0.7.1 master on the other end of a veth pair configures DC SYNC0 (start 100 ms
//! ahead, 1 ms cycle), goes to OP and exchanges process data every millisecond with
//! `tx_rx_dc` (FRMW of 0x0910 + LRW), then stops for 400 ms — as a master that was stopped
//! (SIGSTOP) would. The emulated servo's sync-manager watchdog (ETG defaults: 100 ms) drops it
//! to SAFE-OP with AL status code 0x001B, which the master reads (0x0130 / 0x0134) and the
//! emulator logs; the master acknowledges the error (0x0120 = 0x0014), brings the group back to
//! OP and exchanges data again.
//!
//! Isolation, SKIP and bounds as in `tests/system/ethercat_veth.rs` (harness `tests/common/veth.rs`).

use std::{
    ffi::OsString,
    sync::mpsc,
    thread,
    time::{Duration, Instant},
};

use ethercrab::{
    std::{ethercat_now, tx_rx_task},
    subdevice_group::{DcConfiguration, HasDc, Op},
    DcSync, MainDevice, MainDeviceConfig, PduStorage, SubDeviceGroup, SubDeviceState, Timeouts,
};

/// Set in the re-executed test process (inside the namespace).
const INNER_ENV: &str = "FIELDPROBE_VETH_WATCHDOG_INNER";
const TEST_NAME: &str = "stopped_master_trips_the_sm_watchdog_and_recovers";
const OUTER_TIMEOUT: Duration = Duration::from_secs(90);
const INNER_TIMEOUT: Duration = Duration::from_secs(45);
/// Lifetime of the emulator process (it is killed earlier when the test is done).
const EMULATOR_SECONDS: &str = "60";
const ESI_FILES: [&str; 2] = [
    "esi/fieldprobe-ek1100.xml",
    "esi/fieldprobe-cia402-servo.xml",
];
/// How long the master stays silent (the watchdog needs 100 ms).
const PAUSE: Duration = Duration::from_millis(400);

const MAX_SUBDEVICES: usize = 4;
const MAX_PDI: usize = 64;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

use crate::common::veth;
use veth::{start_emulator, VethPair, MASTER_IF};

#[test]
fn stopped_master_trips_the_sm_watchdog_and_recovers() {
    let _one_module = crate::gate::enter(module_path!());
    if veth::inner_env(INNER_ENV).is_some() {
        inner();
        return;
    }
    veth::run_in_veth_namespace(TEST_NAME, INNER_ENV, OUTER_TIMEOUT, || OsString::from("1"));
}

/// What the master saw.
#[derive(Debug)]
struct Seen {
    /// (AL status, AL status code) of the servo after the pause.
    after_pause: (u16, u16),
    /// Group states and working counter before the pause, and after the recovery.
    before: (Vec<SubDeviceState>, u16),
    after: (Vec<SubDeviceState>, u16),
}

fn inner() {
    let _pair = VethPair::create();
    let (emu, emu_log) = start_emulator(&ESI_FILES, EMULATOR_SECONDS, &[]);
    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("split once");
    thread::spawn(move || {
        let task = tx_rx_task(MASTER_IF, tx, rx).expect("open raw socket on v0");
        let _ = futures_lite::future::block_on(task);
    });
    let (done_tx, done_rx) = mpsc::channel();
    thread::spawn(move || {
        let r = futures_lite::future::block_on(master(pdu_loop));
        let _ = done_tx.send(r);
    });
    let seen = match done_rx.recv_timeout(INNER_TIMEOUT) {
        Ok(Ok(s)) => s,
        Ok(Err(e)) => panic!("master failed: {e}"),
        Err(e) => panic!("master did not finish within {INNER_TIMEOUT:?}: {e}"),
    };
    drop(emu);
    let log = emu_log.join().unwrap_or_default();
    println!("emulator log: {log:#?}");
    println!("master saw: {seen:?}");

    assert_eq!(seen.before, (vec![SubDeviceState::Op; 2], 3));
    // SAFE-OP with the error indication, AL status code 0x001B "sync manager watchdog".
    assert_eq!(seen.after_pause, (0x0014, 0x001B));
    assert_eq!(seen.after, (vec![SubDeviceState::Op; 2], 3));
    let sync0 = log
        .iter()
        .filter(|l| l.contains("device 1 (FP-CIA402-SERVO): SYNC0 every 1.000 ms"))
        .count();
    assert_eq!(sync0, 1, "the servo's SYNC0 was not started once: {log:#?}");
    let watchdog: Vec<&String> = log
        .iter()
        .filter(|l| l.contains("watchdog expired"))
        .collect();
    assert_eq!(watchdog.len(), 1, "{log:#?}");
    assert!(
        watchdog[0].contains(
            "device 1 (FP-CIA402-SERVO): sync-manager watchdog expired after 100.0 ms without \
             process data \u{2192} SAFE-OP, AL status 0x001B"
        ),
        "{}",
        watchdog[0]
    );
    println!("INNER OK");
}

async fn master(pdu_loop: ethercrab::PduLoop<'static>) -> Result<Seen, ethercrab::error::Error> {
    let md = MainDevice::new(
        pdu_loop,
        Timeouts {
            state_transition: Duration::from_secs(5),
            ..Timeouts::default()
        },
        MainDeviceConfig {
            dc_static_sync_iterations: 100,
            ..MainDeviceConfig::default()
        },
    );
    let mut group = md
        .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercat_now)
        .await?;
    for mut sd in group.iter_mut(&md) {
        if sd.dc_support().any() {
            sd.set_dc_sync(DcSync::Sync0);
        }
    }
    let group = group
        .into_pre_op_pdi(&md)
        .await?
        .configure_dc_sync(
            &md,
            DcConfiguration {
                start_delay: Duration::from_millis(100),
                sync0_period: Duration::from_millis(1),
                sync0_shift: Duration::ZERO,
            },
        )
        .await?
        .into_safe_op(&md)
        .await?
        .into_op(&md)
        .await?;
    let before = cycles(&md, &group, 300).await?;
    // The master stops.
    let t = Instant::now();
    thread::sleep(PAUSE);
    assert!(t.elapsed() >= PAUSE);
    let servo = group.iter(&md).nth(1).expect("servo");
    let al: u16 = servo.register_read(0x0130u16).await?;
    let code: u16 = servo.register_read(0x0134u16).await?;
    // Acknowledge the error (SAFE-OP + ack), then the usual way back to OP.
    servo.register_write(0x0120u16, 0x0014u16).await?;
    let group = group.into_safe_op(&md).await?.into_op(&md).await?;
    let after = cycles(&md, &group, 50).await?;
    Ok(Seen {
        after_pause: (al, code),
        before,
        after,
    })
}

/// `n` cycles of `tx_rx_dc`, one per millisecond; the states and working counter of the last.
async fn cycles(
    md: &MainDevice<'_>,
    group: &SubDeviceGroup<MAX_SUBDEVICES, MAX_PDI, ethercrab::DefaultLock, Op, HasDc>,
    n: usize,
) -> Result<(Vec<SubDeviceState>, u16), ethercrab::error::Error> {
    let mut last = (Vec::new(), 0);
    for _ in 0..n {
        let r = group.tx_rx_dc(md).await?;
        last = (r.subdevice_states.to_vec(), r.working_counter);
        thread::sleep(Duration::from_millis(1));
    }
    Ok(last)
}
