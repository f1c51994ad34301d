//! CiA 402 both sides over the in-memory link: [`Ds402Adapter`] (master) talks to
//! [`Ds402Model`] (drive) through [`SimLink`], one bus cycle per `cycle!`.
//!
//! Traces read like the bus: each `cycle!(rig => STATE, CW)` runs one exchange, lets the adapter
//! decode the input image and write the output image, and asserts the power state the adapter saw
//! and the controlword it wrote in that cycle.
//!
//! Bus timing (`SimLink`, as every link): at exchange k the drive takes the outputs written
//! after exchange k − 1 and steps, but the input image exchange k returns is the one the drive
//! sampled at exchange k − 1 (sampled at SYNC0, sent with the next frame); the very first
//! exchange returns an all-zero image. A controlword written after exchange k is thus processed
//! at exchange k + 1 and its effect shows in the inputs of exchange k + 2 (dead time 2 cycles).
//! So the adapter writes every command word twice: the image after its first write was sampled
//! before the drive saw it and still shows the old state.

use fieldprobe::drive::catalogue::{self, DriveDefinition};
use fieldprobe::drive::ds402::{decode_statusword, Ds402Adapter};
use fieldprobe::drive::model::ds402::{Ds402Model, ERROR_FOLLOWING_ERROR};
use fieldprobe::drive::pdo::{self, DataType, PdoEntry};
use fieldprobe::drive::{DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState};
use fieldprobe::link::sim::SimLink;
use fieldprobe::link::{Link, LinkError, ProcessImage};
use fieldprobe::units::Nanos;
use proptest::prelude::*;

use crate::common::test_data;
use test_data::test_data;

const CYCLE: Nanos = Nanos::from_micros(1000);

fn generic() -> DriveDefinition {
    catalogue::builtin("cia402-generic").expect("built-in drive")
}

/// One axis: adapter + model over a `SimLink`, with the command the axis layer would give.
struct Rig {
    link: SimLink,
    adapter: Ds402Adapter,
    images: Vec<ProcessImage>,
    now: Nanos,
    cmd: DriveCommand,
    def: DriveDefinition,
}

impl Rig {
    fn new(def: DriveDefinition) -> Rig {
        let link = SimLink::new(vec![Ds402Model::new(&def)], CYCLE);
        let adapter = Ds402Adapter::new(&def).expect("adapter");
        let images = vec![ProcessImage::new(adapter.output_len(), adapter.input_len())];
        Rig {
            link,
            adapter,
            images,
            now: Nanos::ZERO,
            cmd: DriveCommand::default(),
            def,
        }
    }

    /// One bus cycle: exchange, decode inputs, encode outputs. Returns the feedback and the
    /// controlword written.
    #[track_caller]
    fn cycle(&mut self) -> (DriveFeedback, u16) {
        self.link
            .exchange(self.now, &mut self.images)
            .expect("exchange");
        let fb = self
            .adapter
            .read_inputs(self.now, &self.images[0].inputs)
            .expect("inputs");
        self.adapter
            .write_outputs(self.now, &self.cmd, &mut self.images[0].outputs)
            .expect("outputs");
        self.now = self.now.saturating_add(CYCLE);
        (fb, self.adapter.controlword())
    }

    #[track_caller]
    fn expect(&mut self, state: PowerState, cw: u16) -> DriveFeedback {
        let (fb, written) = self.cycle();
        assert_eq!(
            (fb.state, written),
            (state, cw),
            "cycle at {}: statusword 0x{:04X}, wrote controlword 0x{written:04X}",
            self.now,
            fb.statusword
        );
        fb
    }

    fn model(&mut self) -> &mut Ds402Model {
        self.link.model_as::<Ds402Model>(0).expect("model 0")
    }

    /// Power up with the standard sequence (asserted in `power_on_to_operation_enabled`): six
    /// cycles up to the last SWITCHED ON image, plus the drive's enable delay.
    #[track_caller]
    fn enable(&mut self) {
        self.cmd.enable = true;
        for _ in 0..6 + self.def.model.enable_delay_cycles {
            self.cycle();
        }
        let fb = self.expect(PowerState::OperationEnabled, 0x0F);
        assert!(fb.operational);
    }
}

/// `cycle!(rig => SwitchedOn, 0x0F)`: one cycle; the adapter saw `SwitchedOn` and wrote 0x0F.
macro_rules! cycle {
    ($rig:expr => $state:ident, $cw:expr) => {
        $rig.expect(PowerState::$state, $cw)
    };
}

#[test]
fn power_on_to_operation_enabled() {
    let mut rig = Rig::new(generic());
    rig.cmd.enable = true;
    // Exchange 0 returns the all-zero image (nothing sampled yet): statusword 0 decodes as NOT
    // READY TO SWITCH ON, and the adapter starts with shutdown. The drive stepped there with the
    // zeroed output image (controlword 0x0000) and left NOT READY TO SWITCH ON by itself
    // (transition 1).
    let fb = cycle!(rig => NotReadyToSwitchOn, 0x06);
    assert_eq!(fb.statusword, 0x0000);
    // Exchange 1 carries what the drive sampled at exchange 0.
    let fb = cycle!(rig => SwitchOnDisabled, 0x06); // 0x06 written twice
    assert_eq!(fb.statusword, 0x0250); // switch on disabled | voltage enabled | remote
    assert_eq!(fb.mode_display, Some(0), "sampled before 0x6060 arrived");
    // The drive took the first 0x06 at exchange 1 (transition 2); the image shows it now.
    let fb = cycle!(rig => ReadyToSwitchOn, 0x07);
    // ready to switch on | quick stop off | voltage | remote; 0x6060 = 8 arrived with the first
    // 0x06 image
    assert_eq!((fb.statusword, fb.mode_display), (0x0231, Some(8)));
    // Sampled before the drive saw 0x07: still READY TO SWITCH ON, 0x07 once more.
    let fb = cycle!(rig => ReadyToSwitchOn, 0x07);
    assert_eq!(fb.statusword, 0x0231);
    let fb = cycle!(rig => SwitchedOn, 0x0F);
    assert_eq!(fb.statusword, 0x0233);
    assert!(!fb.operational);
    let fb = cycle!(rig => SwitchedOn, 0x0F); // sampled before the drive saw 0x0F
    assert!(!fb.operational);
    let fb = cycle!(rig => OperationEnabled, 0x0F);
    // operation enabled | voltage | remote | target reached | drive follows the command value
    assert_eq!(fb.statusword, 0x1637);
    assert!(fb.operational && !fb.fault && !fb.following_error_flag);
    assert_eq!((fb.position, fb.following_error), (0, Some(0)));
}

#[test]
fn enable_delay_adds_switched_on_cycles() {
    let mut def = generic();
    def.model.enable_delay_cycles = 3;
    let mut rig = Rig::new(def);
    rig.cmd.enable = true;
    cycle!(rig => NotReadyToSwitchOn, 0x06);
    cycle!(rig => SwitchOnDisabled, 0x06);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    // The drive takes the first 0x0F at exchange 5 and needs it 1 + enable_delay_cycles = 4
    // times (exchanges 5..=8); its image of exchange 8 arrives at exchange 9. The adapter sees
    // SWITCHED ON from exchange 4 on: 2 + enable_delay_cycles images.
    for _ in 0..2 + 3 {
        cycle!(rig => SwitchedOn, 0x0F);
    }
    assert!(cycle!(rig => OperationEnabled, 0x0F).operational);
}

#[test]
fn disable_and_quick_stop() {
    let mut rig = Rig::new(generic());
    rig.enable();
    rig.cmd.quick_stop = true;
    cycle!(rig => OperationEnabled, 0x02);
    cycle!(rig => OperationEnabled, 0x02); // sampled before the drive saw 0x02
    cycle!(rig => QuickStopActive, 0x02);
    rig.cmd.quick_stop = false;
    cycle!(rig => QuickStopActive, 0x00); // disable voltage: transition 12
    cycle!(rig => QuickStopActive, 0x00);
    cycle!(rig => SwitchOnDisabled, 0x06);
    cycle!(rig => SwitchOnDisabled, 0x06);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => SwitchedOn, 0x0F);
    cycle!(rig => SwitchedOn, 0x0F);
    cycle!(rig => OperationEnabled, 0x0F);
    rig.cmd.enable = false;
    cycle!(rig => OperationEnabled, 0x06); // shutdown: transition 8
    cycle!(rig => OperationEnabled, 0x06);
    cycle!(rig => ReadyToSwitchOn, 0x06);
}

/// The generic drive without feed-forward (`[model] feed_forward = false`): the plain
/// first-order position loop `ẋ = kv·(r − x)`.
fn first_order() -> DriveDefinition {
    let mut def = generic();
    def.model.feed_forward = false;
    def
}

/// Enable, ramp the set-point at `v_mm_s` for 1000 cycles (1 s), and return the feedback of the
/// last cycle after checking that it carries the 0x60F4 the drive sampled at the exchange
/// before (the bus delivers the image one exchange late).
fn ramp_for_a_second(rig: &mut Rig, v_mm_s: f64) -> DriveFeedback {
    rig.enable();
    let scaling = rig.def.scaling;
    let mut pos_mm = 0.0;
    for k in 0..1000 {
        pos_mm += v_mm_s * CYCLE.as_secs_f64();
        rig.cmd.target = scaling.to_increments(pos_mm).unwrap();
        if k < 999 {
            rig.cycle();
        }
    }
    let sampled = rig.model().read_object(0x60F4, 0);
    let fb = rig.cycle().0;
    assert_eq!(Ok(i64::from(fb.following_error.unwrap())), sampled);
    fb
}

/// Hold the set-point for 500 cycles: the axis settles on it.
fn settles(rig: &mut Rig) {
    for _ in 0..500 {
        rig.cycle();
    }
    let target = rig.cmd.target;
    let fb = rig.cycle().0;
    assert_eq!(fb.position, target);
    assert_eq!(fb.following_error, Some(0));
    assert_ne!(fb.statusword & 0x0400, 0, "target reached");
}

/// Without feed-forward, at constant set-point velocity v the steady-state following error of
/// the first-order position loop is v / kv and the torque is that lag × torque_per_increment;
/// afterwards the position settles on the target.
#[test]
fn csp_following_error_converges_to_v_over_kv() {
    let def = first_order();
    let mut rig = Rig::new(def.clone());
    let v_mm_s = 100.0;
    let expected_lag_inc = v_mm_s * def.scaling.increments_per_unit / def.model.kv;
    let fb = ramp_for_a_second(&mut rig, v_mm_s);
    let fe = f64::from(fb.following_error.unwrap());
    assert!(
        (fe - expected_lag_inc).abs() <= 0.01 * expected_lag_inc,
        "following error {fe} inc, v/kv = {expected_lag_inc} inc"
    );
    assert!(fb.operational && !fb.following_error_flag);
    // 25000 inc × 0.004 ‰/inc = 100 ‰.
    let torque = expected_lag_inc * def.model.torque_per_increment;
    assert_eq!(fb.torque, Some(torque.round() as i32));

    // Hold the set-point: the lag decays with time constant 1/kv = 25 ms.
    settles(&mut rig);
}

/// The default drive (cascade with velocity and acceleration feed-forward): at constant
/// set-point velocity the steady-state following error is 0 and no torque is demanded. The
/// start of the ramp (a velocity step, capped by the torque limit) leaves an error that decays
/// with the slow root of `tv·s² + s + kv = 0` (≈ −41.7 1/s for kv = 40 1/s, tv = 1 ms), i.e. to
/// e^(−41.7) of itself within the second; 0x6064 is rounded to whole increments, so |0x60F4| ≤ 1
/// — against 25000 increments (v / kv) for the drive without feed-forward.
#[test]
fn csp_following_error_with_feed_forward_is_zero_at_constant_speed() {
    let def = generic();
    assert!(def.model.feed_forward, "the default drive has feed-forward");
    let mut rig = Rig::new(def);
    let fb = ramp_for_a_second(&mut rig, 100.0);
    let fe = fb.following_error.unwrap();
    assert!(fe.abs() <= 1, "following error {fe} inc");
    assert!(fb.operational && !fb.following_error_flag);
    assert_ne!(fb.statusword & 0x0400, 0, "target reached while moving");
    assert_eq!(fb.torque, Some(0), "no acceleration, no torque");
    settles(&mut rig);
}

#[test]
fn following_error_window_and_timeout_fault_then_reset() {
    let mut def = generic();
    def.model.following_error_window = 1000;
    def.model.following_error_timeout_ms = 10;
    let mut rig = Rig::new(def);
    rig.enable();
    // A 5000-increment overshoot outside the loop: |0x60F4| = 5000 > 0x6065 from the drive's
    // next step on.
    rig.model().set_disturbance(5000.0);
    // This exchange's image was sampled at the step before the disturbance.
    let fb = cycle!(rig => OperationEnabled, 0x0F);
    assert_eq!(fb.following_error, Some(0));
    // Over the window for longer than 0x6066: the drive faults in its 11th over-window step of
    // 1 ms; the images of its first 10 arrive one exchange late, then FAULT REACTION ACTIVE.
    let over_cycles = 10 * 1_000_000 / CYCLE.0 + 1;
    for _ in 1..over_cycles {
        let fb = cycle!(rig => OperationEnabled, 0x0F);
        assert_eq!(fb.following_error, Some(-5000));
        assert!(!fb.following_error_flag);
    }
    let fb = cycle!(rig => FaultReactionActive, 0x00);
    assert!(fb.fault && fb.following_error_flag && !fb.operational);
    let fb = cycle!(rig => Fault, 0x00);
    assert_ne!(fb.statusword & 0x2000, 0, "statusword bit 13");
    assert_eq!(rig.model().last_error_code(), ERROR_FOLLOWING_ERROR);
    assert_eq!(rig.model().read_object(0x603F, 0), Ok(0x8611));

    // Without a reset request the adapter keeps disable voltage.
    cycle!(rig => Fault, 0x00);
    rig.model().set_disturbance(0.0);
    rig.cmd.fault_reset = true;
    // Rising edge of bit 7 after a 0x00 cycle.
    cycle!(rig => Fault, 0x80);
    // The image was sampled before the drive saw 0x80: still FAULT, so the adapter goes back to
    // 0x00 (ready for another edge) — the drive resets on the 0x80 meanwhile (transition 15).
    cycle!(rig => Fault, 0x00);
    let fb = cycle!(rig => SwitchOnDisabled, 0x06);
    assert!(!fb.following_error_flag);
    rig.cmd.fault_reset = false;
    cycle!(rig => SwitchOnDisabled, 0x06);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => SwitchedOn, 0x0F);
    cycle!(rig => SwitchedOn, 0x0F);
    let fb = cycle!(rig => OperationEnabled, 0x0F);
    assert!(fb.operational && fb.statusword & 0x2000 == 0);
    assert_eq!(
        rig.model().last_error_code(),
        0x8611,
        "0x603F keeps the last error"
    );
}

#[test]
fn window_all_ones_switches_monitoring_off() {
    let mut def = generic();
    def.model.following_error_window = u32::MAX;
    def.model.following_error_timeout_ms = 0;
    let mut rig = Rig::new(def);
    rig.enable();
    rig.model().set_disturbance(1.0e6);
    for _ in 0..50 {
        cycle!(rig => OperationEnabled, 0x0F);
    }
}

#[test]
fn fault_reset_requested_before_the_fault_gives_00_then_80() {
    let mut rig = Rig::new(generic());
    rig.enable();
    rig.cmd.fault_reset = true; // harmless outside FAULT
    cycle!(rig => OperationEnabled, 0x0F);
    rig.model().inject_fault(0x7500);
    // The drive faults at its next step; this exchange's image was sampled before.
    cycle!(rig => OperationEnabled, 0x0F);
    cycle!(rig => FaultReactionActive, 0x00);
    cycle!(rig => Fault, 0x80);
    cycle!(rig => Fault, 0x00); // sampled before the drive saw 0x80
    cycle!(rig => SwitchOnDisabled, 0x06);
    cycle!(rig => SwitchOnDisabled, 0x06);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => SwitchedOn, 0x0F);
    cycle!(rig => SwitchedOn, 0x0F);
    cycle!(rig => OperationEnabled, 0x0F);
    assert_eq!(rig.model().last_error_code(), 0x7500);
}

#[test]
fn lost_exchange_leaves_inputs_and_models_alone() {
    let mut rig = Rig::new(generic());
    rig.link.lose_exchange_at(2);
    rig.cmd.enable = true;
    cycle!(rig => NotReadyToSwitchOn, 0x06);
    cycle!(rig => SwitchOnDisabled, 0x06);
    let inputs = rig.images[0].inputs.clone();
    let model = rig.link.model_ref_as::<Ds402Model>(0).unwrap().clone();
    let err = rig.link.exchange(rig.now, &mut rig.images).unwrap_err();
    assert!(
        matches!(err, LinkError::Lost { at, .. } if at == rig.now),
        "{err}"
    );
    assert_eq!(rig.images[0].inputs, inputs);
    assert_eq!(rig.link.model_ref_as::<Ds402Model>(0).unwrap(), &model);
    assert_eq!(rig.link.exchanges(), 3);
    // The next exchange goes through and the sequence continues where it was: it delivers what
    // the drive sampled at exchange 1 (where it took the first 0x06), and the drive, not
    // stepped at the lost exchange, takes the same output image (0x06) now.
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => ReadyToSwitchOn, 0x07);
    cycle!(rig => SwitchedOn, 0x0F);

    let mut two = vec![ProcessImage::new(9, 31); 2];
    assert_eq!(
        rig.link.exchange(rig.now, &mut two),
        Err(LinkError::Mismatch {
            devices: 1,
            images: 2
        })
    );
}

#[test]
fn short_images_are_errors_not_panics() {
    let def = generic();
    let mut adapter = Ds402Adapter::new(&def).unwrap();
    assert_eq!(
        adapter.read_inputs(Nanos::ZERO, &[0x37, 0x16, 0]),
        Err(DriveError::ImageTooShort {
            expected: 31,
            got: 3
        })
    );
    let mut out = [0xAAu8; 8];
    let cmd = DriveCommand {
        enable: true,
        ..Default::default()
    };
    assert_eq!(
        adapter.write_outputs(Nanos::ZERO, &cmd, &mut out),
        Err(DriveError::ImageTooShort {
            expected: 9,
            got: 8
        })
    );
    assert_eq!(out, [0xAA; 8], "nothing written");

    // The drive ignores a short RxPDO (CiA 301 EMCY 0x8210) and keeps its set-points.
    let mut m = Ds402Model::new(&def);
    let mut tx = [0u8; 5];
    m.step(Nanos::ZERO, 0.001, &[0x06, 0x00], &mut tx);
    assert_eq!(m.rx_length_errors(), 1);
    assert_eq!(m.state(), PowerState::SwitchOnDisabled);
    // 0x6041 = 0x0250 fits, 0x6064 (bytes 2..6) does not and is left out.
    assert_eq!(tx, [0x50, 0x02, 0, 0, 0]);
}

/// The default CSP mapping of `drives/cia402-generic.toml`, byte for byte.
#[test]
fn default_pdo_layout_bytes() {
    let def = generic();
    let entry = |index, ty, offset| PdoEntry::at(index, 0, ty, offset);
    // 0x6072 is not mapped: torque limits are written acyclically (seed 004 §7.3.2).
    assert_eq!(
        def.rxpdo.entries(),
        &[
            entry(0x6040, DataType::U16, 0),
            entry(0x607A, DataType::I32, 2),
            entry(0x6060, DataType::I8, 6),
            entry(0x60B8, DataType::U16, 7),
        ]
    );
    assert_eq!(def.rxpdo.len(), 9);
    assert!(def.rxpdo_defaults.is_empty());
    assert_eq!(
        def.txpdo.entries(),
        &[
            entry(0x6041, DataType::U16, 0),
            entry(0x6064, DataType::I32, 2),
            entry(0x60F4, DataType::I32, 6),
            entry(0x6061, DataType::I8, 10),
            entry(0x60B9, DataType::U16, 11),
            entry(0x60BA, DataType::I32, 13),
            entry(0x60BB, DataType::I32, 17),
            entry(0x60BC, DataType::I32, 21),
            entry(0x60BD, DataType::I32, 25),
            entry(0x6077, DataType::I16, 29),
        ]
    );
    assert_eq!(def.txpdo.len(), 31);

    let mut adapter = Ds402Adapter::new(&def).unwrap();
    #[rustfmt::skip]
    let inputs = [
        0x37, 0x16,             // 6041 0x1637 operation enabled, target reached, following
        0x45, 0x23, 0x01, 0x00, // 6064 74565
        0xA8, 0x61, 0x00, 0x00, // 60F4 25000
        0x08,                   // 6061 8 (CSP)
        0x00, 0x00,             // 60B9 0
        0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, // 60BA..60BD 0
        0x9C, 0xFF,             // 6077 -100 (-10.0 % of rated torque)
    ];
    let fb = adapter.read_inputs(Nanos::ZERO, &inputs).unwrap();
    assert_eq!(
        (
            fb.state,
            fb.position,
            fb.following_error,
            fb.mode_display,
            fb.operational,
            fb.torque
        ),
        (
            PowerState::OperationEnabled,
            74565,
            Some(25000),
            Some(8),
            true,
            Some(-100)
        )
    );
    let mut out = [0u8; 9];
    let cmd = DriveCommand {
        enable: true,
        target: 0x0001_2345,
        ..Default::default()
    };
    adapter.write_outputs(Nanos::ZERO, &cmd, &mut out).unwrap();
    // cw 0x000F enable operation | 607A 74565 | 6060 8 (CSP) | 60B8 0 (no probe armed)
    assert_eq!(out, [0x0F, 0x00, 0x45, 0x23, 0x01, 0x00, 0x08, 0x00, 0x00]);
}

/// A drive file that maps 0x6072 cyclically still works: the adapter writes the default.
#[test]
fn max_torque_may_still_be_mapped_cyclically() {
    let def = catalogue::parse(
        "[drive]\nname = \"m\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n\
         [rxpdo]\nentries = [\"0x6040:00\", \"0x607A:00\", \"0x6072:00\"]\n\
         defaults = { \"0x6072:00\" = 1500 }\n",
        "m.toml",
    )
    .unwrap();
    let mut rig = Rig::new(def);
    rig.cycle();
    rig.cycle();
    assert_eq!(rig.model().read_object(0x6072, 0), Ok(1500));
}

/// `(file text, line, fragment of the message)`.
const BAD_FILES: &[(&str, usize, &str)] = &[
    ("[drive]\nname = \"x\"\nprofile = \"ds402\"\n", 3, "allowed: \"cia402\""),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[model]\nkvv = 3\n", 7, "unknown key `kvv` in [model]; allowed: kv,"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[model]\nkv = -1\n", 7, "kv: must be > 0"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[rxpdo]\nentries = [\n  \"0x6040:00\",\n  \"0x607A:zz\",\n]\n", 9, "sub-index must be a hexadecimal"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[rxpdo]\nentries = [\"0x6040:00\"]\n", 7, "needs 0x607A:00 mapped"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[rxpdo]\nentries = [\"0x6040:00\", \"0x607A:00\", \"0x2000:01\"]\n", 7, "give its type, e.g. \"0x2000:01:u32\""),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[model]\nkv = \n", 7, "TOML syntax"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[functions]\nX = { object = \"0x2000:01\", type = \"u64\" }\n", 7, "allowed: bool, u8, i8, u16, i16, u32, i32"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[functions]\ntorque = { object = \"0x6072:00\" }\n", 7, "upper case"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[functions]\nTL = { object = \"0x6072:00\", max = 70000 }\n", 7, "max: expected an integer in 0..=65535"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[rxpdo]\ndefaults = { \"0x6073:00\" = 1 }\n", 7, "is not in [rxpdo] entries"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n\n[scaling]\nincrements_per_unit = 0\n", 6, "non-zero"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[motor]\n", 4, "unknown key `motor` in the top level"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[probe]\nrearm_requires_zero = 1\n", 7, "rearm_requires_zero: expected true or false"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[probe]\narm_timeout_cycles = 0\n", 7, "arm_timeout_cycles: expected an integer in 1..="),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[probe]\nrearm = true\n", 7, "unknown key `rearm` in [probe]"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[model]\nzero_pulse_period = 0\n", 7, "zero_pulse_period: must be > 0"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[model]\ntorque_per_increment = -1\n", 7, "torque_per_increment: must be >= 0"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[idn]\n\"S-0-0092\" = { object = \"0x6072:00\" }\n\"X-1\" = { object = \"0x6065:00\" }\n", 8, "not a SERCOS IDN"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[idn]\n\"S-0-0092\" = { object = \"0x6072:00\" }\n\"s-0-92\" = { object = \"0x6072:00\" }\n", 8, "S-0-0092 is given twice"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[idn]\n\"S-0-0159\" = { object = \"0x6065:00\", zero = -1 }\n", 7, "zero: expected an integer in 0..=4294967295"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[idn]\n\"S-0-0159\" = { object = \"0x2000:01\" }\n", 7, "is not a known CiA 402 object; add `type`"),
    ("[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n[idn]\n\"S-0-0159\" = { object = \"0x6065:00\", scale = 2 }\n", 7, "unknown key `scale` in [idn] \"S-0-0159\""),
];

#[test]
fn drive_file_errors_name_the_line() {
    for (text, line, fragment) in BAD_FILES {
        match catalogue::parse(text, "bad.toml") {
            Err(DriveError::Definition {
                file,
                line: l,
                message,
            }) => {
                assert_eq!(file, "bad.toml");
                assert!(
                    message.contains(fragment),
                    "{message:?} lacks {fragment:?}\n{text}"
                );
                assert_eq!(l, *line, "{message}\n{text}");
            }
            other => panic!("expected a definition error for\n{text}\ngot {other:?}"),
        }
    }
}

#[test]
fn load_builtin_file_and_missing() {
    assert!(catalogue::builtin_names().contains(&"cia402-generic"));
    assert_eq!(
        catalogue::load("cia402-generic").unwrap().name,
        "cia402-generic"
    );

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mine.toml");
    std::fs::write(
        &path,
        "[drive]\nname = \"mine\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1\n",
    )
    .unwrap();
    let def = catalogue::load(path.to_str().unwrap()).unwrap();
    assert_eq!(
        (def.name.as_str(), def.file.as_str()),
        ("mine", path.to_str().unwrap())
    );

    match catalogue::load("no-such-drive") {
        Err(DriveError::Definition {
            line: 0, message, ..
        }) => {
            assert!(message.contains("cia402-generic"), "{message}")
        }
        other => panic!("{other:?}"),
    }
}

/// Decode a SOEM `slaveinfo -sdo` dump: UTF-16 (with BOM, or detected by its NUL bytes) or
/// 8-bit text.
fn decode_dump(bytes: &[u8]) -> String {
    let utf16 = |le: bool, b: &[u8]| -> String {
        let units = b.chunks_exact(2).map(|c| {
            if le {
                u16::from_le_bytes([c[0], c[1]])
            } else {
                u16::from_be_bytes([c[0], c[1]])
            }
        });
        char::decode_utf16(units)
            .map(|r| r.unwrap_or('\u{FFFD}'))
            .collect()
    };
    let nuls = bytes.iter().filter(|&&b| b == 0).count();
    match bytes {
        [0xFF, 0xFE, rest @ ..] => utf16(true, rest),
        [0xFE, 0xFF, rest @ ..] => utf16(false, rest),
        [_, 0, ..] if nuls > bytes.len() / 4 => utf16(true, bytes),
        [0, _, ..] if nuls > bytes.len() / 4 => utf16(false, bytes),
        _ => String::from_utf8_lossy(bytes).into_owned(),
    }
}

/// Our object table's types agree with a real drive's object dictionary (Leadshine EL7-EC400S,
/// SOEM SDO info dump in `../shared/test-data/`).
#[test]
fn object_types_agree_with_leadshine_dump() {
    let Some(path) = test_data(
        "sdo-dumps/leadshine-el7-ec400s-sdinfo.txt",
        "object_types_agree_with_leadshine_dump",
    ) else {
        return;
    };
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let text = decode_dump(&bytes);
    // "Index: 6040 Datatype: 0006 …" then "  Sub: 00 Datatype: 0006 Bitlength: 0010 …"
    let mut index = None;
    let mut types = Vec::new();
    for line in text.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["Index:", i, ..] => index = u16::from_str_radix(i, 16).ok(),
            ["Sub:", s, "Datatype:", t, ..] => {
                if let (Some(i), Ok(s), Ok(t)) =
                    (index, u8::from_str_radix(s, 16), u16::from_str_radix(t, 16))
                {
                    types.push(((i, s), t));
                }
            }
            _ => {}
        }
    }
    assert!(
        types.len() > 100,
        "dump not understood: {} sub-entries",
        types.len()
    );
    let checked = [
        0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x6065, 0x6066, 0x606C, 0x6072, 0x6077, 0x607A,
        0x60B8, 0x60B9, 0x60BA, 0x60BB, 0x60BC, 0x60BD, 0x60E0, 0x60E1, 0x60F4,
    ];
    for index in checked {
        let ours = pdo::lookup(index, 0).unwrap_or_else(|| panic!("0x{index:04X} not in OBJECTS"));
        let (_, code) = types
            .iter()
            .find(|(k, _)| *k == (index, 0))
            .unwrap_or_else(|| panic!("0x{index:04X}:00 not in the dump"));
        assert_eq!(
            DataType::from_cia301_code(*code),
            Some(ours.ty),
            "0x{index:04X} {}: dump data type 0x{code:04X}",
            ours.name
        );
    }
}

proptest! {
    /// Whatever the master sends, the drive model neither panics nor reports an undecodable
    /// statusword.
    #[test]
    fn model_survives_garbage_rx(
        frames in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..24), 1..40),
        dt in prop_oneof![Just(0.001), any::<f64>(), -1.0..1.0f64],
    ) {
        let mut m = Ds402Model::new(&generic());
        let mut tx = vec![0u8; m.tx_len()];
        for (i, rx) in frames.iter().enumerate() {
            m.step(Nanos(i as u64 * 1_000_000), dt, rx, &mut tx);
            let sw = u16::from_le_bytes([tx[0], tx[1]]);
            prop_assert_eq!(sw, m.statusword());
            prop_assert!(!matches!(decode_statusword(sw), PowerState::Unknown(_)), "0x{:04X}", sw);
            prop_assert!(m.actual().is_finite());
        }
    }

    /// Random input images and commands: the adapter answers with a value or an error.
    #[test]
    fn adapter_survives_garbage_inputs(
        inputs in prop::collection::vec(any::<u8>(), 0..64),
        out_len in 0usize..16,
        enable in any::<bool>(),
        fault_reset in any::<bool>(),
        quick_stop in any::<bool>(),
        target in any::<i32>(),
    ) {
        let mut a = Ds402Adapter::new(&generic()).unwrap();
        let read = a.read_inputs(Nanos::ZERO, &inputs);
        prop_assert_eq!(read.is_ok(), inputs.len() >= a.input_len());
        let mut out = vec![0u8; out_len];
        let cmd = DriveCommand { enable, target, fault_reset, quick_stop };
        let written = a.write_outputs(Nanos::ZERO, &cmd, &mut out);
        prop_assert_eq!(written.is_ok(), out_len >= a.output_len());
    }
}
