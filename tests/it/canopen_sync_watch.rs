//! Issue 13: the emulated CANopen node watches its SYNC on its own clock, as a real CiA 301 /
//! CiA 402 device does, here driven on virtual time frame by frame (no wall clock).
//!
//! The node is configured the way a master does it, with SDO downloads written out byte by
//! byte: RPDO1 = controlword 0x6040 + target position 0x607A + modes of operation 0x6060,
//! TPDO1 = statusword 0x6041 + position actual value 0x6064 (CiA 301 remap procedure, CiA 402
//! objects), 0x1006 communication cycle period = 4000 µs, 0x1007 synchronous window = 2000 µs.
//! Expected values come from the specifications: statusword codings of CiA 402 (SWITCH ON
//! DISABLED `& 0x4F == 0x40`, READY TO SWITCH ON `& 0x6F == 0x21`, SWITCHED ON 0x23,
//! OPERATION ENABLED 0x27, FAULT `& 0x4F == 0x08`), EMCY frame layout of CiA 301 (COB-ID
//! 0x080 + node, error code LE, error register, 5 manufacturer bytes), code 0x8100
//! "communication" with error register bits 0 (generic) and 4 (communication), and the
//! documented SYNC time-out of five periods. The RPDO deadline monitoring is CiA 301's: the
//! event-timer (0x1400 sub-index 5, ms) armed by the first RPDO, EMCY 0x8250 "RPDO time-out".

use fieldprobe::bus::can::CanFrame;
use fieldprobe::drive::catalogue;
use fieldprobe::sim::canopen::{CanopenSegment, EmulatedNode};
use fieldprobe::units::Nanos;

const NODE: u8 = 1;
const PERIOD_US: u64 = 4000;

fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new(id, data).unwrap()
}

/// The node on a segment, booted (boot-up message seen) at t = 0.
fn segment(cycle_us: u64) -> CanopenSegment {
    let def = catalogue::load("cia402-generic").unwrap();
    let node = EmulatedNode::new(NODE, &def).unwrap();
    let mut seg = CanopenSegment::new(vec![node], Nanos::from_micros(cycle_us));
    let out = seg.run(&[], Nanos(0));
    // 701 [1] 00: boot-up
    assert!(out.contains(&frame(0x701, &[0])), "{out:?}");
    seg
}

/// Expedited SDO download of `value` (`n` bytes) to `index:sub`; the node must confirm (0x60).
#[track_caller]
fn download(seg: &mut CanopenSegment, index: u16, sub: u8, value: u32, n: usize) {
    let cmd = match n {
        1 => 0x2F,
        2 => 0x2B,
        _ => 0x23,
    };
    let [lo, hi] = index.to_le_bytes();
    let v = value.to_le_bytes();
    let req = [cmd, lo, hi, sub, v[0], v[1], v[2], v[3]];
    let out = seg.run(&[frame(0x600 + u16::from(NODE), &req)], Nanos(0));
    let reply = out
        .iter()
        .find(|f| f.id == 0x580 + u32::from(NODE))
        .unwrap_or_else(|| panic!("no SDO reply to {index:#06x}:{sub}: {out:?}"));
    assert_eq!(
        reply.data[..4],
        [0x60, lo, hi, sub],
        "download {index:#06x}:{sub} = {value:#x}: {reply:?}"
    );
}

/// RPDO1 / TPDO1 as described in the module documentation, the other PDOs off, SYNC timing,
/// then NMT start.
fn configure(seg: &mut CanopenSegment, period_us: u32, window_us: u32) {
    for k in 0..4u16 {
        // COB-ID invalid (bit 31) while remapping; PDOs 2..4 stay invalid.
        download(
            seg,
            0x1400 + k,
            1,
            0x8000_0000 | u32::from(0x200 + 0x100 * k + 1),
            4,
        );
        download(
            seg,
            0x1800 + k,
            1,
            0x8000_0000 | u32::from(0x180 + 0x100 * k + 1),
            4,
        );
    }
    download(seg, 0x1400, 2, 1, 1); // synchronous, every SYNC
    download(seg, 0x1600, 0, 0, 1);
    download(seg, 0x1600, 1, 0x6040_0010, 4);
    download(seg, 0x1600, 2, 0x607A_0020, 4);
    download(seg, 0x1600, 3, 0x6060_0008, 4);
    download(seg, 0x1600, 0, 3, 1);
    download(seg, 0x1400, 1, 0x201, 4);
    download(seg, 0x1800, 2, 1, 1);
    download(seg, 0x1A00, 0, 0, 1);
    download(seg, 0x1A00, 1, 0x6041_0010, 4);
    download(seg, 0x1A00, 2, 0x6064_0020, 4);
    download(seg, 0x1A00, 0, 2, 1);
    download(seg, 0x1800, 1, 0x181, 4);
    download(seg, 0x1006, 0, period_us, 4);
    download(seg, 0x1007, 0, window_us, 4);
    // 000 [2] 01 01: NMT start node 1
    seg.run(&[frame(0x000, &[0x01, NODE])], Nanos(0));
}

/// What the node sent in reply to one cycle.
#[derive(Debug, Default)]
struct Reply {
    /// (statusword, position actual value) of TPDO1, if it came.
    tpdo: Option<(u16, i32)>,
    /// EMCY (code, error register) frames.
    emcy: Vec<(u16, u8)>,
}

fn decode(out: &[CanFrame]) -> Reply {
    let mut r = Reply::default();
    for f in out {
        if f.id == 0x180 + u32::from(NODE) {
            let d = f.data;
            r.tpdo = Some((
                u16::from_le_bytes([d[0], d[1]]),
                i32::from_le_bytes([d[2], d[3], d[4], d[5]]),
            ));
        } else if f.id == 0x080 + u32::from(NODE) {
            r.emcy
                .push((u16::from_le_bytes([f.data[0], f.data[1]]), f.data[2]));
        }
    }
    r
}

/// One cycle at `t`: RPDO1 (controlword, target, mode 8 = CSP) at `t`, then SYNC at `t`.
fn cycle(seg: &mut CanopenSegment, t: Nanos, controlword: u16, target: i32) -> Reply {
    let mut d = [0u8; 7];
    d[..2].copy_from_slice(&controlword.to_le_bytes());
    d[2..6].copy_from_slice(&target.to_le_bytes());
    d[6] = 8;
    decode(&seg.run(&[frame(0x201, &d), frame(0x080, &[])], t))
}

/// Drive the node through the enable sequence on the SYNC grid starting at cycle `*k`;
/// returns the last (statusword, position).
fn enable(seg: &mut CanopenSegment, k: &mut u64, target: i32) -> (u16, i32) {
    let mut last = (0, 0);
    // (controlword, statusword mask, expected state) of CiA 402 transitions 2, 3, 4.
    for (cw, mask, want) in [(0x06, 0x6F, 0x21), (0x07, 0x6F, 0x23), (0x0F, 0x6F, 0x27)] {
        let mut reached = false;
        for _ in 0..50 {
            *k += 1;
            if let Some(tp) = cycle(seg, Nanos::from_micros(*k * PERIOD_US), cw, target).tpdo {
                last = tp;
                if tp.0 & mask == want {
                    reached = true;
                    break;
                }
            }
        }
        assert!(reached, "controlword {cw:#04x}: statusword {:#06x}", last.0);
    }
    last
}

#[test]
fn sync_missing_for_five_periods_is_emcy_8100_and_a_drive_fault_until_fault_reset() {
    let mut seg = segment(PERIOD_US);
    configure(&mut seg, PERIOD_US as u32, PERIOD_US as u32 / 2);
    let mut k = 0u64;
    let (sw, pos) = enable(&mut seg, &mut k, 0);
    assert_eq!(sw & 0x6F, 0x27, "operation enabled");
    // It follows a target (CSP): 1000 increments, reached within 50 cycles.
    let mut p = pos;
    for _ in 0..50 {
        k += 1;
        p = cycle(&mut seg, Nanos::from_micros(k * PERIOD_US), 0x0F, 1000)
            .tpdo
            .unwrap()
            .1;
    }
    assert_eq!(p, 1000, "follows the target before the SYNC stops");

    // The SYNC stops after cycle k (last SYNC at t_last). Time goes on in 1 ms steps; no
    // frames. The node may not complain at 5 periods = 20 ms, must at the first poll after.
    let t_last = k * PERIOD_US;
    let mut emcy_at = None;
    let mut emcys = Vec::new();
    for ms in 1..=40u64 {
        let t = Nanos::from_micros(t_last + ms * 1000);
        let r = decode(&seg.run(&[], t));
        if !r.emcy.is_empty() && emcy_at.is_none() {
            emcy_at = Some(ms);
        }
        emcys.extend(r.emcy);
    }
    // 081 [8] 00 81 11 00 00 00 00 00: EMCY 0x8100 communication, register generic + comm.
    assert_eq!(emcys, vec![(0x8100, 0x11)], "exactly one EMCY per outage");
    assert_eq!(emcy_at, Some(21), "first poll with a gap over 20 ms");
    assert_eq!(seg.nodes()[0].sync_timeouts(), 1);

    // The SYNC comes back: the drive reports FAULT and does not follow a new target.
    let mut k = t_last / PERIOD_US + 10; // 40 ms after the last SYNC
    let mut last = (0, 0);
    for _ in 0..5 {
        k += 1;
        let r = cycle(&mut seg, Nanos::from_micros(k * PERIOD_US), 0x0F, 5000);
        assert!(
            r.emcy.iter().all(|&(c, _)| c != 0x8100),
            "no second EMCY 0x8100 when the fault takes effect: {:?}",
            r.emcy
        );
        last = r.tpdo.unwrap();
    }
    assert_eq!(last.0 & 0x4F, 0x08, "FAULT: statusword {:#06x}", last.0);
    assert_eq!(
        last.1, 1000,
        "stopped following: still at the last position"
    );
    // 0x603F error code: the SYNC time-out.
    assert_eq!(
        seg.nodes()[0].read_object(0x603F, 0).unwrap()[..2],
        0x8100u16.to_le_bytes()
    );

    // Fault reset (rising edge of controlword bit 7) → SWITCH ON DISABLED, then enable again:
    // it follows once more.
    let mut state = 0;
    for cw in [0x00, 0x80, 0x80, 0x80] {
        k += 1;
        state = cycle(&mut seg, Nanos::from_micros(k * PERIOD_US), cw, 1000)
            .tpdo
            .unwrap()
            .0;
    }
    assert_eq!(state & 0x4F, 0x40, "switch on disabled: {state:#06x}");
    enable(&mut seg, &mut k, 1000);
    let mut p = 0;
    for _ in 0..50 {
        k += 1;
        p = cycle(&mut seg, Nanos::from_micros(k * PERIOD_US), 0x0F, 3000)
            .tpdo
            .unwrap()
            .1;
    }
    assert_eq!(p, 3000, "runs again after the fault reset");
    assert_eq!(seg.nodes()[0].sync_timeouts(), 1);
}

#[test]
fn no_watch_without_a_cycle_period_or_before_the_first_sync() {
    // 0x1006 = 0: SYNC not monitored, however long it stays away.
    let mut seg = segment(PERIOD_US);
    configure(&mut seg, 0, 0);
    let mut k = 0;
    enable(&mut seg, &mut k, 0);
    for ms in 1..=200u64 {
        let r = decode(&seg.run(&[], Nanos::from_micros(k * PERIOD_US + ms * 1000)));
        assert!(r.emcy.is_empty(), "{:?}", r.emcy);
    }
    // 0x1006 set, operational, but no SYNC yet: not armed.
    let mut seg = segment(PERIOD_US);
    configure(&mut seg, PERIOD_US as u32, 2000);
    for ms in 1..=200u64 {
        let r = decode(&seg.run(&[], Nanos::from_micros(ms * 1000)));
        assert!(r.emcy.is_empty(), "{:?}", r.emcy);
    }
    assert_eq!(seg.nodes()[0].sync_timeouts(), 0);
}

#[test]
fn sync_timing_objects_are_writable_in_operational_and_reset_by_nmt_reset_communication() {
    let mut seg = segment(PERIOD_US);
    configure(&mut seg, 4000, 2000);
    // CiA 301 puts no NMT-state restriction on 0x1006 / 0x1007 (unlike the PDO parameters).
    download(&mut seg, 0x1006, 0, 2000, 4);
    download(&mut seg, 0x1007, 0, 1000, 4);
    assert_eq!(seg.nodes()[0].cycle_period_us(), Some(2000));
    // 000 [2] 82 01: reset communication → communication objects back to their defaults (0).
    seg.run(&[frame(0x000, &[0x82, NODE])], Nanos(0));
    assert_eq!(seg.nodes()[0].read_object(0x1006, 0), Ok(vec![0, 0, 0, 0]));
    assert_eq!(seg.nodes()[0].read_object(0x1007, 0), Ok(vec![0, 0, 0, 0]));
}

/// Velocity actual value 0x606C (INTEGER32, increments/s) of the node, by SDO upload.
fn velocity(seg: &mut CanopenSegment) -> i32 {
    // 40 6C 60 00: upload 0x606C:00
    let out = seg.run(
        &[frame(
            0x600 + u16::from(NODE),
            &[0x40, 0x6C, 0x60, 0, 0, 0, 0, 0],
        )],
        Nanos(0),
    );
    let r = out
        .iter()
        .find(|f| f.id == 0x580 + u32::from(NODE))
        .unwrap();
    assert_eq!(r.data[..4], [0x43, 0x6C, 0x60, 0], "{r:?}");
    i32::from_le_bytes([r.data[4], r.data[5], r.data[6], r.data[7]])
}

/// A steady ramp of 400 increments per SYNC, 100 SYNCs; returns the velocity the drive
/// reports then.
fn ramp_velocity(seg: &mut CanopenSegment) -> i32 {
    let mut k = 0;
    enable(seg, &mut k, 0);
    let mut target = 0;
    for _ in 0..100 {
        k += 1;
        target += 400;
        cycle(seg, Nanos::from_micros(k * PERIOD_US), 0x0F, target);
    }
    velocity(seg)
}

#[test]
fn a_drive_step_covers_the_configured_cycle_period() {
    // The segment's own cycle is 1 ms. With 0x1006 = 4000 µs a step covers 4 ms, so 400
    // increments per SYNC are 400 / 0.004 s = 100 000 increments/s. Without 0x1006 the drive
    // keeps real time (issue 25): a step covers the time since the previous SYNC, which comes
    // 4 ms later on the node's clock here — the same 100 000 increments/s (before issue 25 it
    // took the segment's 1 ms: 400 000).
    let mut seg = segment(1000);
    configure(&mut seg, PERIOD_US as u32, 2000);
    let v = ramp_velocity(&mut seg);
    assert!((v - 100_000).abs() <= 1_000, "velocity {v} increments/s");
    let mut seg = segment(1000);
    configure(&mut seg, 0, 0);
    let v = ramp_velocity(&mut seg);
    assert!((v - 100_000).abs() <= 1_000, "velocity {v} increments/s");
}

/// One cycle with SYNC only (the master lost its set-points, or never sends them).
fn sync_only(seg: &mut CanopenSegment, t: Nanos) -> Reply {
    decode(&seg.run(&[frame(0x080, &[])], t))
}

#[test]
fn rpdo_missing_beyond_its_event_timer_is_emcy_8250_and_a_drive_fault() {
    let mut seg = segment(PERIOD_US);
    configure(&mut seg, PERIOD_US as u32, PERIOD_US as u32 / 2);
    // RPDO1 deadline monitoring: 20 ms (a PDO parameter: written in pre-operational).
    seg.run(&[frame(0x000, &[0x80, NODE])], Nanos(0));
    download(&mut seg, 0x1400, 5, 20, 2);
    seg.run(&[frame(0x000, &[0x01, NODE])], Nanos(0));
    let mut k = 0u64;
    enable(&mut seg, &mut k, 0);
    let mut p = 0;
    for _ in 0..20 {
        k += 1;
        p = cycle(&mut seg, Nanos::from_micros(k * PERIOD_US), 0x0F, 800)
            .tpdo
            .unwrap()
            .1;
    }
    assert_eq!(p, 800);
    // From here the SYNC keeps coming every 4 ms, the RPDO does not. Time in 1 ms steps: no
    // EMCY while the gap is ≤ 20 ms, one at the first step beyond.
    let t_last = k * PERIOD_US;
    let mut emcys = Vec::new();
    let mut emcy_at = None;
    let mut last = (0, 0);
    for ms in 1..=60u64 {
        let t = Nanos::from_micros(t_last + ms * 1000);
        let r = if ms % 4 == 0 {
            sync_only(&mut seg, t)
        } else {
            decode(&seg.run(&[], t))
        };
        if !r.emcy.is_empty() && emcy_at.is_none() {
            emcy_at = Some(ms);
        }
        emcys.extend(r.emcy);
        if let Some(tp) = r.tpdo {
            last = tp;
        }
    }
    // 081 [8] 50 82 11 …: EMCY 0x8250 RPDO time-out, error register generic + communication;
    // exactly one per outage, and not 0x8100: the SYNC never stopped.
    assert_eq!(emcys, vec![(0x8250, 0x11)]);
    assert_eq!(emcy_at, Some(21), "first step with a gap over 20 ms");
    assert_eq!(seg.nodes()[0].rpdo_timeouts(), 1);
    assert_eq!(seg.nodes()[0].sync_timeouts(), 0);
    assert_eq!(last.0 & 0x4F, 0x08, "FAULT: statusword {:#06x}", last.0);
    assert_eq!(
        seg.nodes()[0].read_object(0x603F, 0).unwrap()[..2],
        0x8250u16.to_le_bytes()
    );
    // The RPDO comes back: the drive stays in FAULT (no new target followed) until a fault
    // reset; no second EMCY for the same outage.
    let mut k = (t_last + 60_000) / PERIOD_US;
    for _ in 0..5 {
        k += 1;
        let r = cycle(&mut seg, Nanos::from_micros(k * PERIOD_US), 0x0F, 5000);
        assert!(r.emcy.iter().all(|&(c, _)| c != 0x8250), "{:?}", r.emcy);
        last = r.tpdo.unwrap();
    }
    assert_eq!(last.0 & 0x4F, 0x08, "still FAULT: {:#06x}", last.0);
    assert_eq!(last.1, 800, "does not follow while faulted");
}

#[test]
fn no_rpdo_monitoring_with_event_timer_0_and_reset_communication_restores_0() {
    let mut seg = segment(PERIOD_US);
    configure(&mut seg, PERIOD_US as u32, PERIOD_US as u32 / 2);
    let mut k = 0u64;
    enable(&mut seg, &mut k, 0);
    // Event-timer 0 (the default): SYNC only for 200 ms, no RPDO time-out.
    for ms in 1..=200u64 {
        let t = Nanos::from_micros(k * PERIOD_US + ms * 1000);
        let r = if ms % 4 == 0 {
            sync_only(&mut seg, t)
        } else {
            decode(&seg.run(&[], t))
        };
        assert!(r.emcy.is_empty(), "{:?}", r.emcy);
    }
    assert_eq!(seg.nodes()[0].rpdo_timeouts(), 0);
    // Set, then reset communication: back to 0 (CiA 301: the communication parameters).
    seg.run(&[frame(0x000, &[0x80, NODE])], Nanos(0));
    download(&mut seg, 0x1400, 5, 20, 2);
    assert_eq!(seg.nodes()[0].read_object(0x1400, 5), Ok(vec![20, 0]));
    seg.run(&[frame(0x000, &[0x82, NODE])], Nanos(0));
    assert_eq!(seg.nodes()[0].read_object(0x1400, 5), Ok(vec![0, 0]));
}
