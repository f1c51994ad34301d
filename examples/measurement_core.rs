//! The measurement and monitoring core without NC: your interpolator, your drives, fieldprobe's
//! CNC rules.
//!
//! A drive layer that moves its axes itself plans a probing motion, feeds the actual positions
//! and the drives' latch events every cycle, and gets:
//!
//! - from [`MeasurementRun`]: when the probing signal is complete and the motion must brake
//!   (the stop request), `V.A.MERF`, and the measurement type's verdict on a missing signal
//!   (FCT-C4 Measurement);
//! - from [`results::compute`] with the [`Frames`] (zero offset, MEIN, tool length):
//!   `V.A.MESS`, `V.A.MEAS.ACS.VALUE`, `V.A.MEAS.PCS.VALUE`, `V.A.MOFFS` (FCT-C4 §5);
//! - from [`SoftLimits`]: the software limit switch verdicts on the planned path (P-ERR-120002 /
//!   120003) and on the actual positions every cycle (P-ERR-70021 / 70022), FCT-A2 Software
//!   limit switches.
//!
//! ```text
//! cargo run --example measurement_core -- [--probe-at Z_MM]
//! ```
//!
//! Needs no Cargo feature. The "drives" here are a few lines at the bottom: the actual position
//! follows the command one cycle late, and a drive latch (CiA 402 0x60BA, 10000 increments per
//! mm) switches when the actual position passes the workpiece surface at `--probe-at` (ACS Z).

use fieldprobe::core::measure::results;
use fieldprobe::core::path::Segment;
use fieldprobe::prelude::*;

/// Axes of the example machine, in channel order.
const AXES: [&str; 2] = ["X", "Z"];
const X: usize = 0;
const Z: usize = 1;
/// Interpolation cycle.
const CYCLE: Nanos = Nanos(1_000_000);
/// G54 zero offset (ACS of the workpiece zero), per axis.
const ZERO_OFFSET: [f64; 2] = [100.0, 50.0];
/// Software limit switches P-AXIS-00177 / 00178 per axis.
const LIMITS: [(f64, f64); 2] = [(-10.0, 300.0), (0.0, 200.0)];
/// Start of the probing motion (ACS) and its programmed target (PCS, as `G100 Z30`).
const START: [f64; 2] = [120.0, 150.0];
const TARGET_PCS: [f64; 2] = [20.0, 30.0];
/// Measuring feed (mm/s) and the deceleration the motion brakes with on the stop request.
const FEED: f64 = 10.0;
const BRAKE: f64 = 500.0;

type Error = Box<dyn std::error::Error + Send + Sync>;

fn main() -> Result<(), Error> {
    let mut probe_at = 112.5;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let value = args.next().ok_or(format!("{a}: value missing"))?;
        match a.as_str() {
            "--probe-at" => probe_at = value.parse()?,
            _ => return Err(format!("unknown option {a}").into()),
        }
    }
    let drive_scaling = Scaling {
        increments_per_unit: 10_000.0,
        offset: 0.0,
    };

    // The channel's frames: X and Z are main axes; G54 active.
    let mut frames = Frames::new(AXES.len(), [Some(X), None, Some(Z)])?;
    frames.set_zero_offset(&ZERO_OFFSET)?;
    let mut limits = SoftLimits::new(
        AXES.iter()
            .zip(LIMITS)
            .map(|(name, (neg, pos))| AxisLimitConfig::linear(name, neg, pos))
            .collect(),
        false,
    );
    for i in 0..AXES.len() {
        limits.set_referenced(i, true);
    }
    println!(
        "G54 zero offset Z = {:.6}, probing G100 Z{:.6} (PCS) from ACS Z {:.6}, feed {FEED} mm/s",
        ZERO_OFFSET[Z], TARGET_PCS[Z], START[Z]
    );

    // Block preparation: the command path against the software limit switches.
    let mut target = [0.0; 2];
    frames.pcs_to_acs(&TARGET_PCS, &mut target);
    let path = Segment::line(START.to_vec(), target.to_vec())?;
    let mut violations = Vec::new();
    limits.check_path(&path, &mut violations);
    if let Some(v) = violations.first() {
        return Err(limits.path_message(v).to_string().into());
    }

    let mut run = MeasurementRun::new(
        MeasType::Type1,
        &START,
        &target,
        &[false, true],
        &[true, true],
        &ChannelMeasConfig::default(),
    )
    .map_err(|m| m.to_string())?;

    // The cycle: actual positions and latches in, stop request and limit verdicts out.
    let dir: Vec<f64> = (0..2)
        .map(|i| (target[i] - START[i]) / run.target_len())
        .collect();
    let (mut s, mut v) = (0.0, FEED);
    let mut braking = false;
    let mut command = START;
    let mut actual = START;
    let mut limit_messages = Vec::new();
    let mut cycles = 0u64;
    while cycles < 1_000_000 {
        cycles += 1;
        let now = Nanos(cycles * CYCLE.0);
        // Your drives: actual = the command of the previous cycle; the latch switches when the
        // actual position passes the surface, interpolated to the crossing, in increments.
        let previous = actual;
        actual = command;
        let mut latches = Vec::new();
        if (previous[Z] - probe_at) * (actual[Z] - probe_at) <= 0.0 && previous[Z] != actual[Z] {
            let inc = drive_scaling
                .to_increments(probe_at)
                .ok_or("probe out of range")?;
            latches.push(Latch {
                axis: Z,
                position: drive_scaling.to_units(inc),
            });
        }
        for (i, &p) in actual.iter().enumerate() {
            if let Some(m) = limits.check_actual(i, p) {
                limit_messages.push(m.to_string());
                braking = true; // an actual-position violation stops the axes as well
            }
        }
        if run.cycle(now, &latches) == RunStep::Brake {
            braking = true;
            println!(
                "stop requested in cycle {cycles}: probing signal complete, actual Z {:.6}",
                actual[Z]
            );
        }
        // Your interpolator: constant feed, braking on request, stop at the target.
        if braking {
            v = (v - BRAKE * CYCLE.as_secs_f64()).max(0.0);
        }
        s = (s + v * CYCLE.as_secs_f64()).min(run.target_len());
        for i in 0..2 {
            command[i] = START[i] + dir[i] * s;
        }
        if (v == 0.0 || s >= run.target_len()) && command == actual {
            break;
        }
    }
    let target_reached = s >= run.target_len();
    println!(
        "stopped in cycle {cycles} at ACS Z {:.6}{}",
        actual[Z],
        if target_reached { " (target)" } else { "" }
    );
    for m in &limit_messages {
        println!("software limits: {m}");
    }
    if limit_messages.is_empty() {
        println!("software limits: actual positions inside in all {cycles} cycles");
    }

    let outcome = run.finish(target_reached).map_err(|m| m.to_string())?;
    let mut start_pcs = [0.0; 2];
    frames.acs_to_pcs(&START, &mut start_pcs);
    let block = MeasuringBlock {
        target_pcs: &TARGET_PCS,
        programmed: &[false, true],
        direction_pcs: results::motion_direction(&frames, &start_pcs, &TARGET_PCS),
        ball_radius: 0.0,
        include_radius: true,
    };
    let values = results::compute(&frames, &block, &outcome.latched, &[None, None])?;
    for (i, name) in AXES.iter().enumerate() {
        match values[i] {
            Some(r) => {
                println!("V.A.MERF.{name} = {}", u8::from(outcome.merf[i]));
                println!("V.A.MESS.{name} = {:.6}", r.mess);
                println!("V.A.MEAS.ACS.VALUE.{name} = {:.6}", r.acs);
                println!("V.A.MEAS.PCS.VALUE.{name} = {:.6}", r.pcs);
                println!("V.A.MOFFS.{name} = {:.6}", r.moffs);
            }
            None if block.programmed[i] => println!("V.A.MERF.{name} = 0"),
            None => {}
        }
    }

    // The next block would move Z below its negative limit: refused before it runs.
    let beyond = Segment::line(actual.to_vec(), vec![actual[X], LIMITS[Z].0 - 5.0])?;
    limits.check_path(&beyond, &mut violations);
    for v in &violations {
        println!(
            "software limits: G01 Z{:.6} (ACS) refused: {}",
            v.position,
            limits.path_message(v)
        );
    }
    Ok(())
}
