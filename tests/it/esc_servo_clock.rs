//! The emulated CiA 402 servo (`esi/fieldprobe-cia402-servo.xml`, drive `cia402-generic`) on
//! the segment's own clock, driven with raw datagrams on virtual time: it is enabled and moved
//! in CSP through SYNC0 steps, then the process data stop. The sync-manager watchdog (ETG
//! defaults: (0x09C2 + 2) × 40 ns × 1000 = 100 ms) drops it to SAFE-OP with AL status code
//! 0x001B and its outputs go to their safe state: the drive performs a quick stop (CiA 402
//! statusword `x00x 0111`, QUICK STOP ACTIVE) and holds its position. The master acknowledges,
//! asks for OP and enables operation again (CiA 402 transition 16: QUICK STOP ACTIVE → OPERATION
//! ENABLED, statusword `x01x 0111`).

use fieldprobe::bus::ethercat::wire::{physical_address, Command, Frame, FrameBuilder};
use fieldprobe::drive::catalogue;
use fieldprobe::drive::PowerState;
use fieldprobe::sim::esc::device::emulated_servo;
use fieldprobe::sim::esc::segment::{Segment, Stepping};
use fieldprobe::sim::esc::{reg, AlState};
use fieldprobe::sim::plant::Plant;
use fieldprobe::sim::world::World;
use fieldprobe::units::Nanos;

const STATION: u16 = 0x1000;
const MS: u64 = 1_000_000;
/// Process-data SMs of the ESI (`<Sm>` Outputs / Inputs): start, default size, control byte.
const SM2: (u16, u16, u8) = (0x1100, 9, 0x64);
const SM3: (u16, u16, u8) = (0x1180, 31, 0x20);
/// ETG defaults: (0x09C2 + 2) × 40 ns × 1000.
const WATCHDOG_NS: u64 = (0x09C2 + 2) * 40 * 1000;
/// CiA 402 statusword state bits (mask 0x6F): CiA 402 §6.2 "state coding".
const SW_MASK: u16 = 0x6F;
const READY_TO_SWITCH_ON: u16 = 0x21;
const SWITCHED_ON: u16 = 0x23;
const OPERATION_ENABLED: u16 = 0x27;
const QUICK_STOP_ACTIVE: u16 = 0x07;
const CSP: i8 = 8;

fn exchange(seg: &mut Segment, now: u64, dgs: &[(Command, u32, Vec<u8>)]) -> Vec<(u16, Vec<u8>)> {
    let mut b = FrameBuilder::new([0xFF; 6], [0x10; 6]);
    for (i, (c, a, d)) in dgs.iter().enumerate() {
        b.push_command(*c, i as u8, *a, d).unwrap();
    }
    let mut f = b.build();
    assert!(seg.process_frame(&mut f, now).unwrap());
    Frame::parse(&f)
        .unwrap()
        .datagrams()
        .map(|d| (d.wkc, d.data.to_vec()))
        .collect()
}

fn fpwr(seg: &mut Segment, now: u64, ado: u16, data: &[u8]) {
    let r = exchange(
        seg,
        now,
        &[(Command::Fpwr, physical_address(STATION, ado), data.to_vec())],
    );
    assert_eq!(r[0].0, 1, "FPWR {ado:#06x}");
}

fn al_status(seg: &mut Segment, now: u64) -> (u16, u16) {
    let r = exchange(
        seg,
        now,
        &[(
            Command::Fprd,
            physical_address(STATION, reg::AL_STATUS),
            vec![0; 6],
        )],
    );
    let d = &r[0].1;
    (
        u16::from_le_bytes([d[0], d[1]]),
        u16::from_le_bytes([d[4], d[5]]),
    )
}

fn sm(start: u16, len: u16, control: u8) -> Vec<u8> {
    let mut v = start.to_le_bytes().to_vec();
    v.extend_from_slice(&len.to_le_bytes());
    v.extend_from_slice(&[control, 0, 1, 0]);
    v
}

fn fmmu(logical: u32, len: u16, physical: u16, ty: u8) -> Vec<u8> {
    let mut f = logical.to_le_bytes().to_vec();
    f.extend_from_slice(&len.to_le_bytes());
    f.extend_from_slice(&[0, 7]);
    f.extend_from_slice(&physical.to_le_bytes());
    f.extend_from_slice(&[0, ty, 1, 0, 0, 0]);
    f
}

/// Outputs (ESI default RxPDO): 0x6040 u16, 0x607A i32, 0x6060 i8, 0x60B8 u16.
fn outputs(cw: u16, target: i32) -> Vec<u8> {
    let mut v = cw.to_le_bytes().to_vec();
    v.extend_from_slice(&target.to_le_bytes());
    v.push(CSP as u8);
    v.extend_from_slice(&[0, 0]);
    v
}

/// LRW of outputs (logical 0..9) and inputs (9..40); returns (WKC, statusword 0x6041, position
/// 0x6064).
fn cycle(seg: &mut Segment, now: u64, cw: u16, target: i32) -> (u16, u16, i32) {
    let mut d = outputs(cw, target);
    d.extend_from_slice(&[0; 31]);
    let r = exchange(seg, now, &[(Command::Lrw, 0, d)]);
    let i = &r[0].1[9..];
    (
        r[0].0,
        u16::from_le_bytes([i[0], i[1]]),
        i32::from_le_bytes([i[2], i[3], i[4], i[5]]),
    )
}

/// LRD of the inputs only.
fn inputs(seg: &mut Segment, now: u64) -> (u16, i32) {
    let r = exchange(seg, now, &[(Command::Lrd, 9, vec![0; 31])]);
    let i = &r[0].1;
    (
        u16::from_le_bytes([i[0], i[1]]),
        i32::from_le_bytes([i[2], i[3], i[4], i[5]]),
    )
}

/// The emulated servo alone on a segment on its own clock (world cycle 1 ms), taken through
/// PRE-OP to SAFE-OP with the ESI's mailbox and process-data SMs and the FMMUs of [`cycle`].
fn servo_in_safe_op() -> Segment {
    let esi = fieldprobe::esi::load("esi/fieldprobe-cia402-servo.xml").unwrap();
    let def = catalogue::load("cia402-generic").unwrap();
    let esc = emulated_servo(&esi, &esi.devices[0], &def).unwrap();
    let mbx = esc.config().mailbox.expect("the servo has a mailbox");
    let mut seg = Segment::new(vec![esc], 0);
    seg.set_world(World::new(Plant::new()), Nanos(MS));
    seg.set_stepping(Stepping::OwnClock);
    let r = exchange(
        &mut seg,
        0,
        &[(
            Command::Apwr,
            physical_address(0, reg::STATION_ADDRESS),
            STATION.to_le_bytes().to_vec(),
        )],
    );
    assert_eq!(r[0].0, 1);
    fpwr(
        &mut seg,
        0,
        reg::sm(0),
        &sm(mbx.rx_offset, mbx.rx_size, 0x26),
    );
    fpwr(
        &mut seg,
        0,
        reg::sm(1),
        &sm(mbx.tx_offset, mbx.tx_size, 0x22),
    );
    fpwr(&mut seg, 0, reg::AL_CONTROL, &[0x02, 0]);
    fpwr(&mut seg, 0, reg::sm(2), &sm(SM2.0, SM2.1, SM2.2));
    fpwr(&mut seg, 0, reg::sm(3), &sm(SM3.0, SM3.1, SM3.2));
    fpwr(&mut seg, 0, reg::fmmu(0), &fmmu(0, SM2.1, SM2.0, 2));
    fpwr(&mut seg, 0, reg::fmmu(1), &fmmu(9, SM3.1, SM3.0, 1));
    fpwr(&mut seg, 0, reg::AL_CONTROL, &[0x04, 0]);
    assert_eq!(al_status(&mut seg, 0), (0x0004, 0));
    seg
}

/// CiA 402 enable through the state machine (controlword 0x06, 0x07, 0x0F), one process-data
/// cycle per `cycle_with(controlword)` (which returns the statusword), at most 50 per step.
fn enable(mut cycle_with: impl FnMut(u16) -> u16) {
    let mut sw = 0;
    for (cw, want) in [
        (0x06, READY_TO_SWITCH_ON),
        (0x07, SWITCHED_ON),
        (0x0F, OPERATION_ENABLED),
    ] {
        let mut n = 0;
        while sw & SW_MASK != want {
            sw = cycle_with(cw);
            n += 1;
            assert!(n < 50, "controlword {cw:#x}: statusword {sw:#06x}");
        }
    }
}

#[test]
fn watchdog_expiry_quick_stops_the_drive_and_the_master_brings_it_back() {
    // INIT → PRE-OP → SAFE-OP with the ESI's SMs, SYNC0 every 1 ms from 10 ms, OP.
    let mut seg = servo_in_safe_op();
    fpwr(&mut seg, MS, reg::DC_SYNC_ACTIVATION, &[0]);
    fpwr(&mut seg, MS, reg::DC_START_TIME, &(10 * MS).to_le_bytes());
    fpwr(
        &mut seg,
        MS,
        reg::DC_SYNC0_CYCLE,
        &1_000_000u32.to_le_bytes(),
    );
    fpwr(&mut seg, MS, reg::DC_SYNC_ACTIVATION, &[0x03]);
    fpwr(&mut seg, 2 * MS, reg::AL_CONTROL, &[0x08, 0]);
    assert_eq!(al_status(&mut seg, 2 * MS), (0x0008, 0));

    // One frame per SYNC0 period, 300 µs after the pulse.
    let mut k = 10u64;
    let mut run = |seg: &mut Segment, cw: u16, target: i32| {
        seg.handle_timeout(k * MS);
        let r = cycle(seg, k * MS + 300_000, cw, target);
        k += 1;
        assert_eq!(r.0, 3, "LRW working counter");
        (r.1, r.2, k * MS)
    };
    enable(|cw| run(&mut seg, cw, 0).0);
    // A ramp of 100 increments per cycle, then hold the end.
    let mut target = 0;
    for _ in 0..50 {
        target += 100;
        run(&mut seg, 0x0F, target);
    }
    let mut last_frame = 0;
    let (mut sw, mut pos) = (0, 0);
    for _ in 0..20 {
        let r = run(&mut seg, 0x0F, target);
        (sw, pos) = (r.0, r.1);
        last_frame = r.2 - MS + 300_000;
    }
    assert_eq!(sw & SW_MASK, OPERATION_ENABLED);
    assert!((pos - target).abs() <= 2, "position {pos}, target {target}");
    assert_eq!(seg.model(0).unwrap().state(), PowerState::OperationEnabled);

    // The frames stop. Until the watchdog expires the drive holds its set-point (sync errors).
    let expiry = last_frame + WATCHDOG_NS;
    let errors_before = seg.esc(0).unwrap().sync_errors();
    seg.handle_timeout(expiry - 1);
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
    assert_eq!(
        seg.esc(0).unwrap().sync_errors() - errors_before,
        // Pulses after the last frame's period, up to the expiry.
        (expiry - 1) / MS - last_frame / MS - 1,
        "one sync error per SYNC0 without process data"
    );
    seg.handle_timeout(expiry);
    assert_eq!(al_status(&mut seg, expiry), (0x0014, 0x001B));
    // The next SYNC0 steps the drive with the safe outputs: quick stop, position held.
    seg.handle_timeout(expiry + 5 * MS);
    let (sw, held) = inputs(&mut seg, expiry + 5 * MS);
    assert_eq!(sw & SW_MASK, QUICK_STOP_ACTIVE, "statusword {sw:#06x}");
    assert_eq!(seg.model(0).unwrap().state(), PowerState::QuickStopActive);
    assert!(
        (held - target).abs() <= 2,
        "position {held}, target {target}"
    );
    seg.handle_timeout(expiry + 50 * MS);
    assert_eq!(inputs(&mut seg, expiry + 50 * MS), (sw, held));

    // Acknowledge, OP, enable operation again.
    let t = expiry + 51 * MS;
    fpwr(&mut seg, t, reg::AL_CONTROL, &[0x14, 0]);
    assert_eq!(al_status(&mut seg, t), (0x0004, 0));
    fpwr(&mut seg, t, reg::AL_CONTROL, &[0x08, 0]);
    assert_eq!(al_status(&mut seg, t), (0x0008, 0));
    let mut sw = 0;
    for k in t / MS + 1..t / MS + 11 {
        seg.handle_timeout(k * MS);
        let r = cycle(&mut seg, k * MS + 300_000, 0x0F, held);
        assert_eq!(r.0, 3);
        sw = r.1;
        if sw & SW_MASK == OPERATION_ENABLED {
            break;
        }
    }
    assert_eq!(sw & SW_MASK, OPERATION_ENABLED, "statusword {sw:#06x}");
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
}

/// A master without DC (SM-synchronous: the drive steps per process-data frame) moves the axis,
/// then asks for INIT and sends nothing more. Leaving OP puts the controlword into its safe
/// state (quick stop); the drive's own control loop carries it out although no frame and no
/// SYNC0 comes any more: QUICK STOP ACTIVE, standing still where the quick stop ended.
#[test]
fn a_master_that_leaves_for_init_finds_the_drive_quick_stopped_not_frozen_enabled() {
    let mut seg = servo_in_safe_op();
    fpwr(&mut seg, MS, reg::AL_CONTROL, &[0x08, 0]);
    assert_eq!(al_status(&mut seg, MS), (0x0008, 0));

    // One frame per millisecond, no SYNC0: enable, then a ramp of 200 increments per cycle.
    let mut k = 2u64;
    let mut run = |seg: &mut Segment, cw: u16, target: i32| {
        seg.handle_timeout(k * MS);
        let r = cycle(seg, k * MS, cw, target);
        k += 1;
        assert_eq!(r.0, 3, "LRW working counter");
        (r.1, r.2, k)
    };
    enable(|cw| run(&mut seg, cw, 0).0);
    let mut target = 0;
    let mut last = 0;
    for _ in 0..40 {
        target += 200;
        last = run(&mut seg, 0x0F, target).2;
    }
    assert_eq!(seg.model(0).unwrap().state(), PowerState::OperationEnabled);
    let steps_before = seg.syncs();

    // INIT, then silence.
    let t = last * MS;
    fpwr(&mut seg, t, reg::AL_CONTROL, &[0x01, 0]);
    assert_eq!(al_status(&mut seg, t).0 & 0x0F, 0x01);
    seg.handle_timeout(t + 100 * MS);
    assert!(
        seg.syncs() >= steps_before + 80,
        "the drive's loop ran on its own clock: {} steps in 100 ms",
        seg.syncs() - steps_before
    );
    assert_eq!(seg.model(0).unwrap().state(), PowerState::QuickStopActive);
    // The ESC is in INIT (its process-data SMs are off): the model shows where the drive is.
    let stopped = seg.model(0).unwrap().actual();
    assert!(
        stopped > f64::from(target) - 2000.0,
        "the quick stop keeps the axis near where the frames stopped: {stopped} vs {target}"
    );
    // It stands still: another 100 ms on its own clock do not move it.
    seg.handle_timeout(t + 200 * MS);
    let later = seg.model(0).unwrap().actual();
    assert!((later - stopped).abs() < 0.5, "{stopped} → {later}");
    assert_eq!(seg.model(0).unwrap().state(), PowerState::QuickStopActive);
}
