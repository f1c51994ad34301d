//! Touch probe on a CiA 402 drive over CANopen, with fieldprobe's CiA 301 master on a CAN bus
//! you open.
//!
//! [`CanopenLink::open`] takes any [`CanBus`]: it boots the node (NMT reset communication, boot-up,
//! identity 0x1018), maps the drive file's process data into RPDOs / TPDOs with the CiA 301
//! remap procedure, sets heartbeat, 0x1006 / 0x1007 and the RPDO deadline monitoring, starts the
//! node and from then on runs one SYNC per cycle on the wall clock. You move the drive's
//! process images ([`ProcessImage`], in the drive file's layout) with [`Link::exchange`] and
//! let fieldprobe's sans-IO [`Ds402Adapter`] read and write them; SDO access goes through
//! [`Link::write_object`] / [`Link::read_object`].
//!
//! ```text
//! cargo run --example canopen_touch_probe -- [--probe-at MM] [--torque-limit PERCENT]
//! ```
//!
//! No hardware: the bus is fieldprobe's in-process [`VirtualCan`] and the drive an emulated
//! CiA 402 node (`sim` feature) on a thread of its own, with a probe surface at `--probe-at` mm.
//! On a machine, open SocketCAN instead (`socketcan` feature, Linux):
//!
//! ```text
//! let bus = fieldprobe::bus::can::SocketCanBus::open("can0")?;
//! let mut link = CanopenLink::open(Box::new(bus), &[drive.clone()], &[NODE], CYCLE, None)?;
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use fieldprobe::bus::can::VirtualEndpoint;
use fieldprobe::prelude::*;
use fieldprobe::sim::canopen::{CanopenSegment, EmulatedNode};
use fieldprobe::sim::plant::ProbeSurface;

/// The drive's CANopen node id.
const NODE: u8 = 1;
/// SYNC period.
const CYCLE: Nanos = Nanos(10_000_000);
/// Feed of the probing move, mm/s.
const FEED: f64 = 20.0;
/// Travel past the probe before the move gives up, mm.
const OVERTRAVEL: f64 = 2.0;
/// Upper bound of cycles for the whole run.
const MAX_CYCLES: u64 = 3_000;
/// Exchanges without fresh inputs (lost TPDOs, a stalled master) the run rides through.
const MAX_LOST: u32 = 50;

type Error = Box<dyn std::error::Error + Send + Sync>;

fn main() -> Result<(), Error> {
    let mut probe_at = 12.5;
    let mut torque_percent = 40.0;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let value = args.next().ok_or(format!("{a}: value missing"))?;
        match a.as_str() {
            "--probe-at" => probe_at = value.parse()?,
            "--torque-limit" => torque_percent = value.parse()?,
            _ => return Err(format!("unknown option {a}").into()),
        }
    }
    let drive = Arc::new(fieldprobe::drive::catalogue::load("cia402-generic")?);

    // --- emulator side (a real machine has a cable and a drive here) ---
    let hub = VirtualCan::new();
    let mut segment = CanopenSegment::new(vec![EmulatedNode::new(NODE, &drive)?], CYCLE);
    let surface = drive
        .scaling
        .to_increments(probe_at)
        .ok_or("probe position out of range")?;
    segment
        .world_mut()
        .plant_mut()
        .add_probe_surface(ProbeSurface::new(0, f64::from(surface), vec![(0, 1)]));
    let stop = Arc::new(AtomicBool::new(false));
    let node = emulated_node(hub.endpoint(), segment, stop.clone());

    // --- your drive layer ---
    let result = probe(Box::new(hub.endpoint()), &drive, probe_at, torque_percent);
    stop.store(true, Ordering::Relaxed);
    let _ = node.join();
    let r = result?;
    println!(
        "torque limit {:#06x}:{:02x} = {} ({} % of rated torque), read back by SDO",
        r.torque_object.0, r.torque_object.1, r.torque_raw, r.torque_percent
    );
    println!(
        "touch probe 1 latched at {:.4} mm ({} increments), probe surface at {probe_at} mm",
        r.latched_mm, r.latched_increments
    );
    Ok(())
}

/// What the run found.
struct Outcome {
    torque_object: (u16, u8),
    torque_raw: i64,
    torque_percent: f64,
    latched_increments: i32,
    latched_mm: f64,
}

/// Start the node, write the torque limit by SDO, enable the drive, arm touch probe 1 on a
/// rising edge and move towards the probe until it latches.
fn probe(
    bus: Box<dyn CanBus>,
    drive: &Arc<DriveDefinition>,
    probe_at: f64,
    torque_percent: f64,
) -> Result<Outcome, Error> {
    let mut link = CanopenLink::open(
        bus,
        std::slice::from_ref(drive),
        &[NODE],
        CYCLE,
        fieldprobe::bus::can::Bitrate::DEFAULT,
        None,
    )?;

    // SDO: the drive file's function table says which object the torque limit is.
    let f = drive
        .function("TORQUE_LIMIT")
        .ok_or("the drive has no TORQUE_LIMIT")?;
    let raw = f
        .encode(torque_percent)
        .ok_or("torque limit out of range")?;
    link.write_object(0, f.index, f.sub, raw)?;
    let torque_raw = link.read_object(0, f.index, f.sub)?;

    let mut adapter = Ds402Adapter::new(drive)?;
    let mut images = vec![ProcessImage::new(adapter.output_len(), adapter.input_len())];
    let scaling = drive.scaling;
    let request = ProbeRequest {
        probe: 1,
        edge: ProbeEdge::Positive,
        trigger: ProbeTrigger::Input,
        continuous: false,
        source_mode: TriggerSourceMode::Default,
        input: 1,
    };
    let end = scaling
        .to_increments(probe_at + OVERTRAVEL)
        .ok_or("end of the move out of range")?;
    let step = (FEED * CYCLE.as_secs_f64() * scaling.increments_per_unit).round() as i32;
    let mut target: Option<i32> = None;
    let mut armed = false;
    let mut latched = None;
    let mut enable = true;
    let mut lost = 0;
    let mut now = Nanos::ZERO;
    for cycle in 0..MAX_CYCLES {
        now = Nanos(cycle * CYCLE.0);
        match link.exchange(now, &mut images) {
            Ok(()) => {}
            // No fresh inputs this cycle (a TPDO missing, the master held up): the outputs
            // stay as they are; a drive whose SYNC watch fired reports a fault below.
            Err(LinkError::Lost { .. } | LinkError::Stalled { .. }) if lost < MAX_LOST => {
                lost += 1;
                continue;
            }
            Err(e) => return Err(e.into()),
        }
        let feedback = adapter.read_inputs(now, &images[0].inputs)?;
        if feedback.fault {
            return Err(format!("drive fault, statusword {:#06x}", feedback.statusword).into());
        }
        if let Some(event) = adapter.take_probe_event() {
            latched = Some(event.position);
        }
        // CSP: hold the actual position until enabled, then move once the probe is armed.
        let t = *target.get_or_insert(feedback.position);
        if feedback.operational && !armed {
            adapter.arm_probe(&request)?;
            armed = true;
        }
        match adapter.probe_state() {
            ProbeState::Failed(why) if enable => return Err(format!("touch probe: {why}").into()),
            ProbeState::Armed if latched.is_none() && t < end => {
                target = Some((t + step).min(end));
            }
            _ => {}
        }
        if enable && (latched.is_some() || t >= end) {
            // Stop where the command is, disarm the probe and switch the drive off.
            adapter.disarm_probe();
            enable = false;
        } else if !enable && !feedback.operational {
            break;
        }
        let command = DriveCommand {
            enable,
            target: target.unwrap_or(t),
            ..DriveCommand::default()
        };
        adapter.write_outputs(now, &command, &mut images[0].outputs)?;
    }
    // NMT enter pre-operational, confirmed by the node's heartbeat.
    link.release(now)?;
    let latched_increments = latched.ok_or("the probe did not latch")?;
    Ok(Outcome {
        torque_object: (f.index, f.sub),
        torque_raw,
        torque_percent: f.decode(torque_raw),
        latched_increments,
        latched_mm: scaling.to_units(latched_increments),
    })
}

/// The emulated node on its own thread and clock: take what arrived (waiting at most 1 ms),
/// run the node, send its answers; until `stop`.
fn emulated_node(
    mut endpoint: VirtualEndpoint,
    mut segment: CanopenSegment,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let t0 = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            let mut frames = Vec::new();
            let mut wait = Duration::from_millis(1);
            while let Ok(Some(f)) = endpoint.recv(wait) {
                frames.push(f);
                wait = Duration::ZERO;
            }
            for f in segment.run(&frames, Nanos(t0.elapsed().as_nanos() as u64)) {
                let _ = endpoint.send(&f);
            }
        }
    })
}
