//! The emulated segment on its own clock (`Stepping::OwnClock`), on virtual time: SYNC0 from
//! 0x0990 / 0x09A0 / 0x0981 in each device's DC system time (local clock + 0x0920), one world
//! step per SYNC0 with the outputs present at that instant (the last frame of a period counts;
//! none: the same outputs again and a sync error), SM-synchronous stepping without SYNC0, a
//! start time in the past, and the sync-manager watchdog (0x0400 / 0x0420 / 0x0440 / 0x0442,
//! AL status code 0x001B) with the master's acknowledge and return to OP. The expected times
//! are computed here from the register values the test writes (ESC datasheet: system time =
//! local time + offset; watchdog = (0x0400 + 2) × 40 ns × 0x0420), not taken from the code.
//!
//! The serve loop of the raw-socket server runs here too, on a virtual clock with a scripted
//! frame transport: it wakes for every SYNC0 between frames.

use std::any::Any;
use std::cell::Cell;
use std::collections::VecDeque;
use std::rc::Rc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use fieldprobe::bus::ethercat::wire::{physical_address, Command, Frame, FrameBuilder};
use fieldprobe::drive::model::DriveModel;
use fieldprobe::drive::PowerState;
use fieldprobe::sim::esc::dc::Activation;
use fieldprobe::sim::esc::raw::{serve_loop, Clock, FrameIo, RawError};
use fieldprobe::sim::esc::segment::{SegmentEvent, Stepping};
use fieldprobe::sim::esc::{
    reg, segment::Segment, AlState, AlStatusCode, Esc, EscApplication, EscConfig, EscEvent,
    ProcessDataSizes,
};
use fieldprobe::sim::plant::Plant;
use fieldprobe::sim::world::{Port, World};
use fieldprobe::units::Nanos;

const STATION: u16 = 0x1000;
const MS: u64 = 1_000_000;
/// The segment's nominal cycle (model time per SM-synchronous step).
const SEGMENT_CYCLE: u64 = MS;

// ------------------------------------------------------------------ a drive that records

/// A drive model that records every step: (model time, dt in s, output image). Its input image
/// is the number of steps so far (u16).
#[derive(Debug, Default)]
struct Recorder {
    steps: Vec<(u64, f64, Vec<u8>)>,
}

impl DriveModel for Recorder {
    fn rx_len(&self) -> usize {
        2
    }
    fn tx_len(&self) -> usize {
        2
    }
    fn begin_step(&mut self, now: Nanos, dt_s: f64, rx: &[u8]) {
        self.steps.push((now.0, dt_s, rx.to_vec()));
    }
    fn input_edge(&mut self, _input: u8, _rising: bool, _at: Nanos) {}
    fn finish_step(&mut self, tx: &mut [u8]) {
        let n = self.steps.len() as u16;
        if tx.len() >= 2 {
            tx[..2].copy_from_slice(&n.to_le_bytes());
        }
    }
    fn set_input_level(&mut self, _input: u8, _level: bool) {}
    fn input_level(&self, _input: u8) -> Option<bool> {
        None
    }
    fn state(&self) -> PowerState {
        PowerState::OperationEnabled
    }
    fn last_error_code(&self) -> u16 {
        0
    }
    fn inject_fault(&mut self, _code: u16) {}
    fn read_object(&self, _index: u16, _sub: u8) -> Result<i64, u32> {
        Err(0x0602_0000)
    }
    fn write_object(&mut self, _index: u16, _sub: u8, _value: i64) -> Result<(), u32> {
        Err(0x0602_0000)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// Safe state of [`RecApp`]'s outputs (to see that the watchdog reached the application).
const SAFE: [u8; 2] = [0xEE, 0xEE];

/// 2 bytes of outputs (SM2) and 2 of inputs (SM3) behind a [`Recorder`].
#[derive(Debug, Default)]
struct RecApp {
    model: Recorder,
    outputs: [u8; 2],
    inputs: [u8; 2],
}

impl EscApplication for RecApp {
    fn outputs_written(&mut self, _sm: u8, data: &[u8]) {
        self.outputs.copy_from_slice(&data[..2]);
    }
    fn outputs_invalid(&mut self) {
        self.outputs = SAFE;
    }
    fn inputs(&mut self, _sm: u8, buf: &mut [u8]) {
        buf[..2].copy_from_slice(&self.inputs);
    }
    fn process_data_sizes(&self) -> ProcessDataSizes {
        ProcessDataSizes {
            outputs: 2,
            inputs: 2,
        }
    }
    fn model(&self) -> Option<&dyn DriveModel> {
        Some(&self.model)
    }
    fn model_mut(&mut self) -> Option<&mut dyn DriveModel> {
        Some(&mut self.model)
    }
    fn port(&mut self) -> Option<Port<'_>> {
        Some(Port {
            model: &mut self.model,
            outputs: &self.outputs,
            inputs: &mut self.inputs,
        })
    }
}

fn steps(seg: &Segment) -> &[(u64, f64, Vec<u8>)] {
    &seg.model(0)
        .and_then(|m| m.as_any().downcast_ref::<Recorder>())
        .expect("recorder")
        .steps
}

// ------------------------------------------------------------------ frames

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
    assert_eq!(r[0].0, 1, "FPWR {ado:#06x} {data:x?}: WKC");
}

fn fprd(seg: &mut Segment, now: u64, ado: u16, len: usize) -> Vec<u8> {
    let r = exchange(
        seg,
        now,
        &[(Command::Fprd, physical_address(STATION, ado), vec![0; len])],
    );
    assert_eq!(r[0].0, 1, "FPRD {ado:#06x}: WKC");
    r.into_iter().next().unwrap().1
}

fn u64le(b: &[u8]) -> u64 {
    u64::from_le_bytes(b[..8].try_into().unwrap())
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

/// One LRW of the process image at logical 0: 2 bytes of outputs, then 2 of inputs. Returns
/// (WKC, inputs).
fn lrw(seg: &mut Segment, now: u64, out: [u8; 2]) -> (u16, u16) {
    let mut d = out.to_vec();
    d.extend_from_slice(&[0, 0]);
    let r = exchange(seg, now, &[(Command::Lrw, 0, d)]);
    (r[0].0, u16::from_le_bytes([r[0].1[2], r[0].1[3]]))
}

fn al_status(seg: &mut Segment, now: u64) -> (u16, u16) {
    let d = fprd(seg, now, reg::AL_STATUS, 6);
    (
        u16::from_le_bytes([d[0], d[1]]),
        u16::from_le_bytes([d[4], d[5]]),
    )
}

/// One recording device on its own clock, its local clock `local_offset` ns ahead of the
/// segment's clock, brought to OP at `now` with SM2 control `sm2_control` and the DC offset
/// 0x0920 = `dc_offset`.
fn op_segment(local_offset: u64, dc_offset: u64, sm2_control: u8, now: u64) -> Segment {
    let mut esc = Esc::new(EscConfig::default(), Box::new(RecApp::default()));
    esc.set_local_clock_offset(local_offset);
    let mut seg = Segment::new(vec![esc], 0);
    seg.set_world(World::new(Plant::new()), Nanos(SEGMENT_CYCLE));
    seg.set_stepping(Stepping::OwnClock);
    let r = exchange(
        &mut seg,
        now,
        &[(
            Command::Apwr,
            physical_address(0, reg::STATION_ADDRESS),
            STATION.to_le_bytes().to_vec(),
        )],
    );
    assert_eq!(r[0].0, 1);
    fpwr(
        &mut seg,
        now,
        reg::DC_SYSTEM_TIME_OFFSET,
        &dc_offset.to_le_bytes(),
    );
    fpwr(&mut seg, now, reg::AL_CONTROL, &[0x02, 0]);
    fpwr(&mut seg, now, reg::sm(2), &sm(0x1100, 2, sm2_control));
    fpwr(&mut seg, now, reg::sm(3), &sm(0x1180, 2, 0x20));
    fpwr(&mut seg, now, reg::fmmu(0), &fmmu(0, 2, 0x1100, 2));
    fpwr(&mut seg, now, reg::fmmu(1), &fmmu(2, 2, 0x1180, 1));
    fpwr(&mut seg, now, reg::AL_CONTROL, &[0x04, 0]);
    fpwr(&mut seg, now, reg::AL_CONTROL, &[0x08, 0]);
    assert_eq!(al_status(&mut seg, now), (0x0008, 0));
    seg
}

/// Arm SYNC0 like ethercrab's `configure_dc_sync`: 0x0981 = 0, start, cycle, 0x0981 = `act`.
fn arm_sync0(seg: &mut Segment, now: u64, start: u64, cycle: u32, act: u8) {
    fpwr(seg, now, reg::DC_SYNC_ACTIVATION, &[0]);
    fpwr(seg, now, reg::DC_START_TIME, &start.to_le_bytes());
    fpwr(seg, now, reg::DC_SYNC0_CYCLE, &cycle.to_le_bytes());
    fpwr(seg, now, reg::DC_SYNC_ACTIVATION, &[act]);
}

fn sync_errors(seg: &Segment) -> u64 {
    seg.esc(0).unwrap().sync_errors()
}

// ------------------------------------------------------------------ SYNC0

#[test]
fn sync0_fires_at_start_plus_k_cycles_of_the_devices_dc_time() {
    // The device's local clock runs 7 µs ahead of the segment's clock; the master's offset
    // makes its system time 5 s ahead of that.
    const LOCAL: u64 = 7_000;
    const OFFSET: u64 = 5_000_000_000;
    let mut seg = op_segment(LOCAL, OFFSET, 0x64, 0);
    // 0x0910 = local time + 0x0920.
    let now = MS;
    assert_eq!(
        u64le(&fprd(&mut seg, now, reg::DC_SYSTEM_TIME, 8)),
        now + LOCAL + OFFSET
    );
    let start = OFFSET + 10 * MS; // system time
    let cycle = 1_000_000u32;
    arm_sync0(&mut seg, 2 * MS, start, cycle, 0x03);
    assert_eq!(
        fprd(&mut seg, 2 * MS, reg::DC_ACTIVATION_STATUS, 1)[0] & 0x01,
        0x01,
        "first SYNC0 pulse pending"
    );
    assert_eq!(seg.syncs(), 0);
    // Pulse k at system time start + k·cycle = segment time start + k·cycle − 0x0920 − local.
    let pulse = |k: u64| start + k * u64::from(cycle) - OFFSET - LOCAL;
    for k in 0..5u64 {
        let t = seg.poll_timeout(2 * MS).unwrap();
        assert_eq!(t, pulse(k), "pulse {k}");
        seg.handle_timeout(t - 1);
        assert_eq!(seg.syncs(), k, "not before its time");
        seg.handle_timeout(t);
        assert_eq!(seg.syncs(), k + 1, "one world step per SYNC0");
        // At the pulse the system time is the pulse's; 0x0990 reads the next pulse.
        assert_eq!(
            u64le(&fprd(&mut seg, t, reg::DC_SYSTEM_TIME, 8)),
            start + k * u64::from(cycle)
        );
        assert_eq!(
            u64le(&fprd(&mut seg, t, reg::DC_START_TIME, 8)),
            start + (k + 1) * u64::from(cycle)
        );
        // Keep the watchdog fed.
        assert_eq!(lrw(&mut seg, t + 1000, [k as u8, 0]).0, 3);
    }
    assert_eq!(
        fprd(&mut seg, pulse(4), reg::DC_ACTIVATION_STATUS, 1)[0] & 0x01,
        0
    );
    let s = steps(&seg);
    assert_eq!(s.len(), 5);
    for w in s.windows(2) {
        assert_eq!(
            w[1].0 - w[0].0,
            u64::from(cycle),
            "model time advances one cycle"
        );
    }
    assert!(s.iter().all(|(_, dt, _)| (*dt - 1e-3).abs() < 1e-12));
    assert_eq!(
        seg.take_events()
            .into_iter()
            .filter(|e| matches!(e.event, EscEvent::Sync0(_)))
            .map(|e| e.event)
            .collect::<Vec<_>>(),
        [EscEvent::Sync0(Activation::Scheduled {
            first: start,
            cycle: u64::from(cycle)
        })]
    );
}

#[test]
fn outputs_present_at_sync0_count_the_last_frame_wins_and_none_holds_them() {
    let mut seg = op_segment(0, 0, 0x64, 0);
    arm_sync0(&mut seg, MS, 10 * MS, 1_000_000, 0x03);
    seg.handle_timeout(10 * MS);
    assert_eq!(seg.syncs(), 1);
    // Two frames in the period (10, 11] ms: the second one's outputs are stepped at 11 ms.
    assert_eq!(lrw(&mut seg, 10 * MS + 200_000, [0x11, 0]).0, 3);
    assert_eq!(lrw(&mut seg, 10 * MS + 600_000, [0x22, 0]).0, 3);
    assert_eq!(seg.syncs(), 1, "frames do not step a device that has SYNC0");
    seg.handle_timeout(11 * MS);
    assert_eq!(steps(&seg).last().unwrap().2, [0x22, 0]);
    assert_eq!(sync_errors(&seg), 0);
    // The inputs a frame reads are those of the last SYNC0 (2 steps so far).
    assert_eq!(lrw(&mut seg, 11 * MS + 100_000, [0x22, 0]).1, 2);
    seg.handle_timeout(12 * MS);
    assert_eq!(sync_errors(&seg), 0);
    // No frame in (12, 13] ms: the outputs are held, one sync error.
    seg.handle_timeout(13 * MS);
    assert_eq!(steps(&seg).last().unwrap().2, [0x22, 0]);
    assert_eq!(sync_errors(&seg), 1);
    // A frame again: its outputs, no further error.
    assert_eq!(lrw(&mut seg, 13 * MS + 500_000, [0x33, 0]).0, 3);
    seg.handle_timeout(14 * MS);
    assert_eq!(steps(&seg).last().unwrap().2, [0x33, 0]);
    assert_eq!(sync_errors(&seg), 1);
    assert_eq!(seg.syncs(), 5);
    assert_eq!(steps(&seg).len(), 5);
}

#[test]
fn a_frame_after_a_due_sync0_comes_after_it() {
    // The serve loop may see a frame a little after a pulse fell due: the pulse comes first.
    let mut seg = op_segment(0, 0, 0x64, 0);
    arm_sync0(&mut seg, MS, 10 * MS, 1_000_000, 0x03);
    assert_eq!(lrw(&mut seg, 9 * MS, [0x01, 0]).0, 3);
    assert_eq!(lrw(&mut seg, 10 * MS + 50_000, [0x02, 0]).0, 3);
    assert_eq!(seg.syncs(), 1);
    assert_eq!(steps(&seg)[0].2, [0x01, 0]);
}

#[test]
fn without_sync0_the_world_steps_per_process_data_frame() {
    let mut seg = op_segment(0, 0, 0x64, 0);
    assert_eq!(lrw(&mut seg, MS, [1, 0]).0, 3);
    assert_eq!(lrw(&mut seg, MS + 10_000, [2, 0]).0, 3);
    // A read-only frame does not step.
    exchange(&mut seg, MS + 20_000, &[(Command::Lrd, 2, vec![0, 0])]);
    let s = steps(&seg);
    assert_eq!(s.len(), 2);
    // Model time advances by the segment's cycle per step (an SM-synchronous drive).
    assert_eq!(s[0].0, SEGMENT_CYCLE);
    assert_eq!(s[1].0, 2 * SEGMENT_CYCLE);
    assert_eq!(s[1].2, [2, 0]);
    assert_eq!(sync_errors(&seg), 0);
    // Next: the drive's own loop after ten cycles without process data (before the watchdog).
    let free_run = MS + 10_000 + 10 * SEGMENT_CYCLE;
    assert!(free_run < MS + 10_000 + 100 * MS);
    assert_eq!(seg.poll_timeout(MS + 20_000), Some(free_run));
    // From then on one step per cycle by itself, with the outputs held.
    seg.handle_timeout(free_run + 4 * SEGMENT_CYCLE);
    let s = steps(&seg);
    assert_eq!(s.len(), 2 + 5);
    assert_eq!(s[6].0, 7 * SEGMENT_CYCLE);
    assert_eq!(s[6].2, [2, 0]);
    // A frame ends the free run: the next self-step is ten cycles later again.
    let frame = free_run + 4 * SEGMENT_CYCLE + SEGMENT_CYCLE / 2;
    assert_eq!(lrw(&mut seg, frame, [3, 0]).0, 3);
    assert_eq!(steps(&seg).len(), 8);
    assert_eq!(seg.poll_timeout(frame), Some(frame + 10 * SEGMENT_CYCLE));
}

#[test]
fn sync0_start_time_in_the_past() {
    // Without the plausibility check: no SYNC0 at all, the device stays SM-synchronous.
    let mut seg = op_segment(0, 0, 0x64, 0);
    arm_sync0(&mut seg, 10 * MS, 9 * MS + 500_000, 1_000_000, 0x03);
    let events: Vec<EscEvent> = seg.take_events().into_iter().map(|e| e.event).collect();
    assert!(
        events.contains(&EscEvent::Sync0(Activation::StartMissed {
            start: 9 * MS + 500_000,
            late_ns: 500_000
        })),
        "{events:?}"
    );
    assert_eq!(fprd(&mut seg, 10 * MS, reg::DC_ACTIVATION_STATUS, 1)[0], 0);
    assert_eq!(seg.esc(0).unwrap().next_sync0(10 * MS), None);
    seg.handle_timeout(20 * MS);
    assert_eq!(seg.syncs(), 0);
    assert_eq!(lrw(&mut seg, 20 * MS, [1, 0]).0, 3);
    assert_eq!(seg.syncs(), 1, "stepped by the frame");

    // With the plausibility check (0x0981 bit 5): the pulses start at the activation.
    let mut seg = op_segment(0, 0, 0x64, 0);
    arm_sync0(&mut seg, 10 * MS, 9 * MS + 500_000, 1_000_000, 0x23);
    assert_eq!(seg.poll_timeout(10 * MS), Some(10 * MS));
    assert_eq!(seg.syncs(), 0);
    seg.handle_timeout(10 * MS);
    assert_eq!(seg.syncs(), 1);
    assert_eq!(
        fprd(&mut seg, 10 * MS, reg::DC_ACTIVATION_STATUS, 1)[0],
        0x04,
        "first pulse generated; the start time was out of the near future"
    );
    assert_eq!(seg.poll_timeout(10 * MS), Some(11 * MS));
}

// ------------------------------------------------------------------ SM watchdog

/// Default watchdog from the ETG register defaults: divider 0x09C2, SM watchdog time 1000.
const DEFAULT_WATCHDOG_NS: u64 = (0x09C2 + 2) * 40 * 1000;

#[test]
fn sm_watchdog_expires_100_ms_after_the_last_process_data() {
    assert_eq!(DEFAULT_WATCHDOG_NS, 100 * MS);
    let mut seg = op_segment(0, 0, 0x64, 0);
    assert_eq!(
        u16::from_le_bytes(fprd(&mut seg, 0, reg::WD_DIVIDER, 2).try_into().unwrap()),
        0x09C2
    );
    assert_eq!(
        u16::from_le_bytes(fprd(&mut seg, 0, reg::WD_TIME_PD, 2).try_into().unwrap()),
        1000
    );
    arm_sync0(&mut seg, MS, 10 * MS, 1_000_000, 0x03);
    // Process data every cycle for 300 ms: nothing happens.
    let mut last = 0;
    for k in 10..310u64 {
        seg.handle_timeout(k * MS);
        last = k * MS + 300_000;
        assert_eq!(lrw(&mut seg, last, [k as u8, 0]).0, 3);
    }
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
    assert_eq!(fprd(&mut seg, last, reg::WD_STATUS_PD, 1)[0] & 0x01, 0x01);
    // Then none: expiry exactly one watchdog time after the last write.
    let expiry = last + DEFAULT_WATCHDOG_NS;
    let mut t = last;
    while let Some(next) = seg.poll_timeout(t).filter(|&n| n < expiry) {
        seg.handle_timeout(next);
        t = next;
    }
    assert_eq!(seg.poll_timeout(t), Some(expiry));
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
    seg.handle_timeout(expiry);
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::SafeOp);
    assert_eq!(al_status(&mut seg, expiry), (0x0014, 0x001B));
    assert_eq!(
        seg.esc(0).unwrap().al_status_code(),
        AlStatusCode::SYNC_MANAGER_WATCHDOG
    );
    assert_eq!(fprd(&mut seg, expiry, reg::WD_STATUS_PD, 1)[0] & 0x01, 0);
    assert_eq!(fprd(&mut seg, expiry, reg::WD_COUNTER_PD, 1)[0], 1);
    let events: Vec<SegmentEvent> = seg
        .take_events()
        .into_iter()
        .filter(|e| matches!(e.event, EscEvent::WatchdogExpired { .. }))
        .collect();
    assert_eq!(
        events,
        [SegmentEvent {
            position: 0,
            at_ns: expiry,
            event: EscEvent::WatchdogExpired {
                after_ns: DEFAULT_WATCHDOG_NS
            }
        }]
    );
    let text = events[0].event.to_string();
    assert!(
        text.contains("100.0 ms") && text.contains("SAFE-OP") && text.contains("0x001B"),
        "{text}"
    );
    // The application's outputs went to their safe state; SYNC0 goes on stepping with them,
    // and a device out of OP counts no sync errors.
    let errors = sync_errors(&seg);
    seg.handle_timeout(expiry + 2 * MS);
    assert_eq!(steps(&seg).last().unwrap().2, SAFE);
    assert_eq!(sync_errors(&seg), errors);

    // The master acknowledges (SAFE-OP + error ack), then asks for OP again.
    let t = expiry + 3 * MS;
    fpwr(&mut seg, t, reg::AL_CONTROL, &[0x14, 0]);
    assert_eq!(al_status(&mut seg, t), (0x0004, 0));
    fpwr(&mut seg, t, reg::AL_CONTROL, &[0x08, 0]);
    assert_eq!(al_status(&mut seg, t), (0x0008, 0));
    assert_eq!(lrw(&mut seg, t + 100_000, [0x42, 0]).0, 3);
    assert_eq!(
        fprd(&mut seg, t + 200_000, reg::WD_STATUS_PD, 1)[0] & 0x01,
        0x01
    );
    seg.handle_timeout(t + MS);
    assert_eq!(steps(&seg).last().unwrap().2, [0x42, 0]);
}

#[test]
fn sm_watchdog_time_written_by_the_master() {
    // Divider 498 → (498 + 2) × 40 ns = 20 µs per tick; 250 ticks = 5 ms.
    let divider: u16 = 498;
    let ticks: u16 = 250;
    let watchdog = (u64::from(divider) + 2) * 40 * u64::from(ticks);
    assert_eq!(watchdog, 5 * MS);
    let mut seg = op_segment(0, 0, 0x64, 0);
    fpwr(&mut seg, 0, reg::WD_DIVIDER, &divider.to_le_bytes());
    fpwr(&mut seg, 0, reg::WD_TIME_PD, &ticks.to_le_bytes());
    assert_eq!(lrw(&mut seg, MS, [1, 0]).0, 3);
    assert_eq!(seg.poll_timeout(MS), Some(MS + watchdog));
    seg.handle_timeout(MS + watchdog - 1);
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
    seg.handle_timeout(MS + watchdog);
    assert_eq!(al_status(&mut seg, MS + watchdog), (0x0014, 0x001B));

    // Watchdog time 0: no watchdog.
    let mut seg = op_segment(0, 0, 0x64, 0);
    fpwr(&mut seg, 0, reg::WD_TIME_PD, &[0, 0]);
    assert_eq!(seg.poll_timeout(0), None);
    seg.handle_timeout(10_000 * MS);
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
}

#[test]
fn sm_watchdog_needs_the_trigger_bit_of_the_output_sm() {
    // SM2 control 0x24: ECAT writes, no watchdog trigger (bit 6).
    let mut seg = op_segment(0, 0, 0x24, 0);
    assert_eq!(lrw(&mut seg, MS, [1, 0]).0, 3);
    // Only the drive's own loop is due (ten cycles without process data), no watchdog.
    assert_eq!(seg.poll_timeout(MS), Some(MS + 10 * SEGMENT_CYCLE));
    seg.handle_timeout(1_000 * MS);
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::Op);
    // The watchdog counts from the OP entry when no process data come at all.
    let seg = op_segment(0, 0, 0x64, 5 * MS);
    assert_eq!(seg.poll_timeout(5 * MS), Some(5 * MS + DEFAULT_WATCHDOG_NS));
}

// ------------------------------------------------------------------ serve loop on virtual time

struct VirtualClock(Rc<Cell<u64>>);

impl Clock for VirtualClock {
    fn now_ns(&self) -> u64 {
        self.0.get()
    }
}

/// Frames arriving at scripted times; a receive that times out moves the clock to its end.
struct ScriptIo {
    clock: Rc<Cell<u64>>,
    script: VecDeque<(u64, Vec<u8>)>,
    /// Clock times at which a receive timed out.
    woke: Vec<u64>,
    sent: usize,
}

impl FrameIo for ScriptIo {
    fn recv(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, RawError> {
        let now = self.clock.get();
        let until = now + u64::try_from(timeout.as_nanos()).unwrap();
        if self.script.front().is_some_and(|(at, _)| *at <= until) {
            let (at, frame) = self.script.pop_front().unwrap();
            self.clock.set(now.max(at));
            return Ok(Some(frame));
        }
        self.clock.set(until);
        self.woke.push(until);
        Ok(None)
    }

    fn send(&mut self, _frame: &[u8]) -> Result<(), RawError> {
        self.sent += 1;
        Ok(())
    }
}

fn lrw_frame(out: [u8; 2]) -> Vec<u8> {
    let mut b = FrameBuilder::new([0xFF; 6], [0x10; 6]);
    b.push_command(Command::Lrw, 0, 0, &[out[0], out[1], 0, 0])
        .unwrap();
    b.build()
}

#[test]
fn serve_loop_wakes_for_every_sync0_between_frames() {
    let mut seg = op_segment(0, 0, 0x64, 0);
    arm_sync0(&mut seg, MS, 50 * MS, 1_000_000, 0x03);
    let before = steps(&seg).len();
    assert_eq!(before, 0);
    let clock = Rc::new(Cell::new(49 * MS));
    let mut io = ScriptIo {
        clock: clock.clone(),
        script: VecDeque::from([
            (50 * MS + 300_000, lrw_frame([0x01, 0])),
            (52 * MS + 600_000, lrw_frame([0x02, 0])),
        ]),
        woke: Vec::new(),
        sent: 0,
    };
    let stop = AtomicBool::new(false);
    let mut events = Vec::new();
    let stats = serve_loop(
        &mut io,
        &VirtualClock(clock.clone()),
        &mut seg,
        &stop,
        Some(200 * MS),
        |e| events.push(*e),
    )
    .unwrap();
    assert_eq!(stats.answered, 2);
    assert_eq!(io.sent, 2);
    // The loop woke at every pulse 50 … 199 ms (no frame needed), and at nothing else but the
    // watchdog expiry and the deadline.
    for k in 50..200u64 {
        assert!(
            io.woke.contains(&(k * MS)),
            "did not wake for the SYNC0 at {k} ms"
        );
    }
    let s = steps(&seg);
    assert_eq!(s.len(), 150, "pulses at 50 … 199 ms");
    assert_eq!(s[1].2, [0x01, 0], "51 ms: the frame of 50.3 ms");
    assert_eq!(s[2].2, [0x01, 0], "52 ms: held");
    assert_eq!(s[3].2, [0x02, 0], "53 ms: the frame of 52.6 ms");
    // Sync errors: 52 ms, then 54 ms until the watchdog dropped the device at 152.6 ms.
    let expiry = 52 * MS + 600_000 + DEFAULT_WATCHDOG_NS;
    assert!(io.woke.contains(&expiry), "did not wake for the watchdog");
    assert_eq!(sync_errors(&seg), 1 + (152 - 54 + 1));
    assert_eq!(
        events
            .iter()
            .filter(|e| matches!(e.event, EscEvent::WatchdogExpired { .. }))
            .map(|e| (e.position, e.at_ns))
            .collect::<Vec<_>>(),
        [(0, expiry)]
    );
    assert_eq!(seg.esc(0).unwrap().al_state(), AlState::SafeOp);
    assert_eq!(clock.get(), 200 * MS);
}

// ------------------------------------------------------------------ robustness

/// Random register writes (SYNC0 activation with any start and cycle time, any watchdog
/// divider and time, offsets, AL requests) and process data at random times, with the loop's
/// calls in between: nothing panics, and every `handle_timeout` call stays bounded.
#[test]
fn random_timing_registers_never_panic_or_run_away() {
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let mut pulses = 0;
    for round in 0..20 {
        let mut seg = op_segment(next() % 1_000_000, next(), 0x64, 0);
        let mut now = 0u64;
        for _ in 0..400 {
            let r = next();
            // Mostly small steps, sometimes a long silence.
            now = now.saturating_add(match r % 8 {
                0 => (r >> 8) % 10_000_000_000,
                _ => (r >> 8) % 3_000_000,
            });
            let ado = [
                reg::DC_SYNC_ACTIVATION,
                reg::DC_START_TIME,
                reg::DC_SYNC0_CYCLE,
                reg::DC_SYSTEM_TIME_OFFSET,
                reg::WD_DIVIDER,
                reg::WD_TIME_PD,
                reg::AL_CONTROL,
                reg::DC_SYSTEM_TIME,
            ][((r >> 40) % 8) as usize];
            let mut data = next().to_le_bytes();
            let len = [1usize, 2, 4, 8][((r >> 50) % 4) as usize];
            // Bias towards SYNC0 that runs: activation with SYNC0 (often with the plausibility
            // check), short cycle times.
            if ado == reg::DC_SYNC_ACTIVATION && r & 0x7 != 0 {
                data[0] = 0x03 | (data[0] & 0x20);
            }
            if ado == reg::DC_SYNC0_CYCLE && r & 0x7 != 0 {
                data[..4].copy_from_slice(&(40_000 + (r >> 20) % 2_000_000).to_le_bytes()[..4]);
            }
            let cmd = if r & 0x8000 != 0 {
                Command::Frmw
            } else {
                Command::Fpwr
            };
            let mut b = FrameBuilder::new([0xFF; 6], [0x10; 6]);
            b.push_command(cmd, 0, physical_address(STATION, ado), &data[..len])
                .unwrap();
            b.push_command(Command::Lrw, 1, 0, &[r as u8, 0, 0, 0])
                .unwrap();
            let mut f = b.build();
            seg.process_frame(&mut f, now).unwrap();
            let steps_before = seg.syncs();
            seg.handle_timeout(now);
            // At most the SYNC0 backlog per call (one device).
            assert!(seg.syncs() - steps_before <= 1001, "round {round}");
            pulses += seg.syncs() - steps_before;
            if let Some(t) = seg.poll_timeout(now) {
                if t <= now.saturating_add(5_000_000) {
                    seg.handle_timeout(t);
                    now = now.max(t);
                }
            }
        }
        let _ = seg.take_events();
    }
    println!("{pulses} SYNC0 world steps");
    assert!(pulses > 1000, "SYNC0 ran: {pulses} steps");
}
