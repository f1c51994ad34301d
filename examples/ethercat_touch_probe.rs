//! Touch probe on a CiA 402 drive over EtherCAT, with your own ethercrab `MainDevice`.
//!
//! fieldprobe's [`Ds402Adapter`] is sans-IO: it reads the drive's input image (TxPDO) and
//! writes its output image (RxPDO) — here the slices ethercrab's `SubDeviceGroup` hands out —
//! and runs the CiA 402 power state machine and the touch probe (0x60B8 / 0x60B9 / 0x60BA)
//! for you. fieldprobe's CoE client writes the torque limit 0x6072 by SDO on the same
//! `MainDevice`.
//!
//! ```text
//! cargo run --example ethercat_touch_probe -- [--probe-at MM] [--torque-limit PERCENT]
//! ```
//!
//! No hardware: the frames go through fieldprobe's emulated segment (an EK1100-kind coupler and
//! a CiA 402 servo, `sim` feature) with a probe surface at `--probe-at` mm. On a machine, replace
//! [`emulated_wire`] by ethercrab's raw socket, e.g.
//! `std::thread::spawn(move || smol::block_on(ethercrab::std::tx_rx_task("eth0", tx, rx)?))`,
//! and pace the cycle with a timer; everything else stays.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use fieldprobe::ethercrab::{
    std::ethercat_now, MainDevice, MainDeviceConfig, PduRx, PduStorage, PduTx, Timeouts,
};
use fieldprobe::link::ethercat::{emulated_segment, EthercatSpec};
use fieldprobe::prelude::*;
use fieldprobe::sim::esc::segment::{Segment, Stepping};
use fieldprobe::sim::plant::ProbeSurface;

/// The servo's position on the segment (0 is the coupler).
const SERVO: usize = 1;
/// Cycle time of the process data.
const CYCLE: Nanos = Nanos(1_000_000);
/// Feed of the probing move, mm/s.
const FEED: f64 = 20.0;
/// Travel past the probe before the move gives up, mm.
const OVERTRAVEL: f64 = 2.0;
/// Upper bound of cycles for the whole run.
const MAX_CYCLES: u64 = 20_000;

const MAX_SUBDEVICES: usize = 8;
const MAX_PDI: usize = 128;
static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

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

    // The drive definition: PDO layout, scaling (increments per mm) and drive functions.
    let drive = Arc::new(fieldprobe::drive::catalogue::load("cia402-generic")?);
    let scaling = drive.scaling;

    // --- emulator side (a real machine has cables here) ---
    let mut segment = emulated_segment(&EthercatSpec {
        drives: vec![drive.clone()],
        cycle: CYCLE,
        pcap: None,
        terminals: Vec::new(),
        emulated_extra: Vec::new(),
    })?;
    segment.set_stepping(Stepping::PerFrame);
    let surface = scaling
        .to_increments(probe_at)
        .ok_or("probe position out of range")?;
    segment
        .world_mut()
        .ok_or("the emulated segment has no world")?
        .plant_mut()
        .add_probe_surface(ProbeSurface::new(0, f64::from(surface), vec![(0, 1)]));
    let (tx, rx, pdu_loop) = PDU_STORAGE
        .try_split()
        .map_err(|()| "PDU storage split twice")?;
    let stop = Arc::new(AtomicBool::new(false));
    let wire = emulated_wire(tx, rx, Arc::new(Mutex::new(segment)), stop.clone());

    // --- your drive layer ---
    let result = futures_lite::future::block_on(probe(pdu_loop, &drive, probe_at, torque_percent));
    stop.store(true, Ordering::Relaxed);
    let _ = wire.join();
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

/// Bring the bus up, write the torque limit by SDO in PRE-OP, go to OP, enable the drive, arm
/// touch probe 1 on a rising edge and move towards the probe until it latches.
async fn probe(
    pdu_loop: fieldprobe::ethercrab::PduLoop<'static>,
    drive: &DriveDefinition,
    probe_at: f64,
    torque_percent: f64,
) -> Result<Outcome, Error> {
    let md = MainDevice::new(pdu_loop, Timeouts::default(), MainDeviceConfig::default());
    let group = md
        .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercat_now)
        .await?;

    // PRE-OP: acyclic access with fieldprobe's CoE client (segmented transfers, emergencies
    // kept). The drive file's function table says which object the torque limit is.
    let f = drive
        .function("TORQUE_LIMIT")
        .ok_or("the drive has no TORQUE_LIMIT")?;
    let raw = f
        .encode(torque_percent)
        .ok_or("torque limit out of range")?;
    let station = group.subdevice(&md, SERVO)?.configured_address();
    let mut coe = CoeClient::discover(&md, station).await?;
    coe.sdo_download(&md, f.index, f.sub, &raw.to_le_bytes()[..f.ty.size()])
        .await?;
    let back = coe.sdo_upload(&md, f.index, f.sub).await?;
    let mut le = [0u8; 8];
    le[..back.len().min(8)].copy_from_slice(&back[..back.len().min(8)]);
    let torque_raw = i64::from_le_bytes(le);

    let group = group.into_safe_op(&md).await?.into_op(&md).await?;

    let mut adapter = Ds402Adapter::new(drive)?;
    {
        let sd = group.subdevice(&md, SERVO)?;
        let io = sd.io_raw();
        if (io.outputs().len(), io.inputs().len()) != (adapter.output_len(), adapter.input_len()) {
            return Err("the servo's process data do not match the drive definition".into());
        }
    }
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
    for cycle in 0..MAX_CYCLES {
        group.tx_rx(&md).await?;
        let now = Nanos(cycle * CYCLE.0);
        let sd = group.subdevice(&md, SERVO)?;
        let feedback = adapter.read_inputs(now, &sd.inputs_raw())?;
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
            // Stop where the command is, disarm the probe and switch the drive off (shutdown,
            // 0x6040 = 6).
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
        adapter.write_outputs(now, &command, &mut sd.outputs_raw_mut())?;
    }
    let latched_increments = latched.ok_or("the probe did not latch")?;
    Ok(Outcome {
        torque_object: (f.index, f.sub),
        torque_raw,
        torque_percent: f.decode(torque_raw),
        latched_increments,
        latched_mm: scaling.to_units(latched_increments),
    })
}

/// The emulated wire: frames from ethercrab's PDU loop go through the segment and back, on a
/// thread of their own, until `stop`.
fn emulated_wire(
    mut tx: PduTx<'static>,
    mut rx: PduRx<'static>,
    segment: Arc<Mutex<Segment>>,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    struct Unpark(std::thread::Thread);
    impl std::task::Wake for Unpark {
        fn wake(self: Arc<Self>) {
            self.0.unpark();
        }
    }
    std::thread::spawn(move || {
        let waker = std::task::Waker::from(Arc::new(Unpark(std::thread::current())));
        let t0 = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            tx.replace_waker(&waker);
            while let Some(frame) = tx.next_sendable_frame() {
                let mut buf = Vec::with_capacity(1514);
                let sent = frame.send_blocking(|b| {
                    buf.extend_from_slice(b);
                    Ok(b.len())
                });
                let now = t0.elapsed().as_nanos() as u64;
                let mut seg = segment.lock().unwrap_or_else(|p| p.into_inner());
                if sent.is_ok() && matches!(seg.process_frame(&mut buf, now), Ok(true)) {
                    let _ = rx.receive_frame(&buf);
                }
            }
            std::thread::park_timeout(Duration::from_millis(1));
        }
    })
}
