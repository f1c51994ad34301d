//! Lightbus AX2000, KL5101 / EL5101 terminal drives and the EL1252 timestamp codec (seed 004
//! §6.2, §6.3, §7.5; notes cnc.md §4.1–§4.4). Byte fixtures carry a one-line decode.

use fieldprobe::drive::catalogue;
use fieldprobe::drive::catalogue::DriveDefinition;
use fieldprobe::drive::el1252::{self, Decoder, LatchMode};
use fieldprobe::drive::lightbus::{self, telegram, LightbusAdapter};
use fieldprobe::drive::model::el1252::El1252Device;
use fieldprobe::drive::model::{self, DriveModel};
use fieldprobe::drive::terminal::{self, image, CounterExtender, TerminalAdapter, Variant};
use fieldprobe::drive::{
    DriveAdapter, DriveCommand, DriveFeedback, PowerState, ProbeEdge, ProbeRequest, ProbeState,
    ProbeTrigger, TriggerSourceMode,
};
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::{MachineConfig, ParamSet};
use fieldprobe::units::Nanos;

const T: Nanos = Nanos(1_000_000);

fn req(edge: ProbeEdge, trigger: ProbeTrigger) -> ProbeRequest {
    ProbeRequest {
        probe: 1,
        edge,
        trigger,
        continuous: false,
        source_mode: TriggerSourceMode::Default,
        input: 1,
    }
}

/// Adapter + model exchanged over byte images.
struct Bench {
    a: Box<dyn DriveAdapter>,
    m: Box<dyn DriveModel>,
    now: Nanos,
    out: Vec<u8>,
    inp: Vec<u8>,
    target: i32,
    /// Fault reset bit of the drive command.
    reset: bool,
    /// Feedback of the last cycle.
    fb: Option<DriveFeedback>,
}

impl Bench {
    fn new(name: &str) -> Bench {
        Bench::with(&catalogue::load(name).unwrap())
    }
    fn with(def: &DriveDefinition) -> Bench {
        let def = def.clone();
        let mut a =
            fieldprobe::drive::adapter_for(&def, &ParamSet::new(fieldprobe::params::Scope::Axis))
                .unwrap();
        // The bench steps adapter and model in lockstep: the image read in a cycle was written
        // by the model in the same cycle (no bus in between), so no feedback delay.
        a.set_feedback_delay(0);
        let m = model::for_definition(&def).unwrap();
        Bench {
            out: vec![0; a.output_len()],
            inp: vec![0; a.input_len()],
            a,
            m,
            now: Nanos(0),
            target: 0,
            reset: false,
            fb: None,
        }
    }
    /// One cycle; `edge` = (rising, fraction of the cycle).
    fn cycle(&mut self, edge: Option<(bool, f64)>) {
        self.now = Nanos(self.now.0 + T.0);
        self.m.begin_step(self.now, 1e-3, &self.out);
        if let Some((r, f)) = edge {
            let at = Nanos(self.now.0 - T.0 + (f * T.0 as f64) as u64);
            self.m.input_edge(2, r, at);
        }
        self.m.finish_step(&mut self.inp);
        self.fb = Some(self.a.read_inputs(self.now, &self.inp).unwrap());
        let cmd = DriveCommand {
            enable: true,
            target: self.target,
            fault_reset: self.reset,
            quick_stop: false,
        };
        self.a.write_outputs(self.now, &cmd, &mut self.out).unwrap();
    }
    fn enable(&mut self) {
        for _ in 0..5 {
            self.cycle(None);
        }
    }
    fn arm(&mut self, r: ProbeRequest) {
        self.a.arm_probe(&r).unwrap();
        for _ in 0..10 {
            if self.a.probe_state() == ProbeState::Armed {
                return;
            }
            self.cycle(None);
        }
        panic!("not armed: {:?}", self.a.probe_state());
    }
}

#[test]
fn lightbus_telegram_fixture() {
    // cw 0x0001 enable | pos 1000 | vel 0 | latch ctl 0x1001 (seq 1, rising)
    let c = telegram::Command {
        control: 1,
        position: 1000,
        velocity: 0,
        latch_control: 0x1001,
    };
    let mut b = [0u8; telegram::COMMAND_LEN];
    c.encode(&mut b).unwrap();
    assert_eq!(b, [0x01, 0x00, 0xE8, 0x03, 0, 0, 0, 0, 0, 0, 0x01, 0x10]);
    assert_eq!(telegram::Command::decode(&b).unwrap(), c);
    // sw 0x0003 ready+enabled | pos 1000 | fe 0 | latch status 0x1021 (seq 1, IN2MODE 26, pos valid) | latched 500
    let f = [
        0x03, 0, 0xE8, 0x03, 0, 0, 0, 0, 0, 0, 0x21, 0x10, 0xF4, 0x01, 0, 0,
    ];
    let d = telegram::Feedback::decode(&f).unwrap();
    assert_eq!(
        (d.status, d.position, d.latch_status, d.latch_position),
        (3, 1000, 0x1021, 500)
    );
    assert!(telegram::Feedback::decode(&f[..15]).is_err());
}

#[test]
fn lightbus_latches_both_edges_and_rearms_without_stale_value() {
    let mut b = Bench::new("ax2000-lightbus");
    b.enable();
    for (edge, rising) in [(ProbeEdge::Positive, true), (ProbeEdge::Negative, false)] {
        b.arm(req(edge, ProbeTrigger::Input));
        // Move 100 increments per cycle; edge half-way through the cycle.
        for k in 0..20 {
            b.target += 100;
            b.cycle((k == 10).then_some((rising, 0.5)));
        }
        let e = b.a.take_probe_event().expect("latched");
        assert_eq!(e.edge, edge);
        assert!(b.a.take_probe_event().is_none());
        // Re-arm: the old value is not reported again.
        b.arm(req(edge, ProbeTrigger::Input));
        for _ in 0..3 {
            b.cycle(None);
        }
        assert!(b.a.take_probe_event().is_none(), "stale value reported");
        b.a.disarm_probe();
    }
}

#[test]
fn lightbus_in2mode_not_26_is_reported_and_refused() {
    assert!(lightbus::check_drive(26).is_empty());
    let p = lightbus::check_drive(3);
    assert!(p[0].contains("IN2MODE") && p[0].contains("26"), "{p:?}");
    let mut b = Bench::new("ax2000-lightbus");
    assert_eq!(b.m.read_object(lightbus::PARAM_IN2MODE, 0), Ok(26));
    b.m.write_object(lightbus::PARAM_IN2MODE, 0, 3).unwrap();
    b.enable();
    let e =
        b.a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
            .unwrap_err();
    assert!(e.to_string().contains("IN2MODE"), "{e}");
    // Error path: a telegram that is too short.
    assert!(b.a.read_inputs(b.now, &[0; 3]).is_err());
    let def = catalogue::parse(
        "[drive]\nname = \"x\"\nprofile = \"lightbus\"\n[scaling]\nincrements_per_unit = 1\n[lightbus]\nin2mode = 300\n",
        "x.toml",
    )
    .unwrap();
    let e = LightbusAdapter::new(&def).unwrap_err().to_string();
    assert!(e.starts_with("x.toml:7:") && e.contains("in2mode"), "{e}");
}

#[test]
fn terminal_image_fixture_and_wraparound() {
    // SB 0x02 LAT_EXT_VAL | counter 0xFFF0 (-16) | latch 0x0010 (+16) | drive 0x03 ready+enabled
    let b = [0x02, 0xF0, 0xFF, 0x10, 0x00, 0x03];
    let i = image::Inputs::decode(&b).unwrap();
    assert_eq!(
        (i.status, i.counter, i.latch, i.drive),
        (2, 0xFFF0, 0x0010, 3)
    );
    let mut e = CounterExtender::default();
    assert_eq!(e.update(32000), 32000);
    assert_eq!(e.update(32767u16.wrapping_add(500)), 33267); // crossing +32767
    assert_eq!(e.extend(32760), 32760);
    let mut e = CounterExtender::default();
    assert_eq!(e.update(100), 100);
    assert_eq!(e.update(65000), 100 - 636); // crossing 0 downwards
}

#[test]
fn terminal_kl5101_refuses_neg_and_latches_pos_across_wrap() {
    let p = terminal::check_edge(Variant::Kl5101, ProbeEdge::Negative);
    assert!(
        p[0].contains("P-AXIS-00518") && p[0].contains("POS"),
        "{p:?}"
    );
    assert!(terminal::check_edge(Variant::El5101, ProbeEdge::Negative).is_empty());
    let mut b = Bench::new("kl5101-terminal");
    b.enable();
    assert!(b
        .a
        .arm_probe(&req(ProbeEdge::Negative, ProbeTrigger::Input))
        .is_err());
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    // 3000 inc per cycle: the 16-bit counter wraps at +32767 after 11 cycles.
    for k in 0..30 {
        b.target += 3000;
        b.cycle((k == 20).then_some((true, 0.5)));
    }
    let e = b.a.take_probe_event().expect("latched");
    let expect = b.m.trajectory().len(); // silence
    let _ = expect;
    assert!(
        e.position > 32767,
        "extended past the 16-bit range: {}",
        e.position
    );
    // Re-arm: no stale value.
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    for _ in 0..3 {
        b.cycle(None);
    }
    assert!(b.a.take_probe_event().is_none());
}

#[test]
fn terminal_el5101_ctrack_pos_neg() {
    let mut b = Bench::new("el5101-terminal");
    b.enable();
    for (edge, trig, ev) in [
        (ProbeEdge::Positive, ProbeTrigger::ZeroPulse, None),
        (ProbeEdge::Positive, ProbeTrigger::Input, Some(true)),
        (ProbeEdge::Negative, ProbeTrigger::Input, Some(false)),
    ] {
        b.arm(req(edge, trig));
        for k in 0..20 {
            b.target += 1000;
            b.cycle(ev.filter(|_| k == 5).map(|r| (r, 0.25)));
        }
        let e = b.a.take_probe_event().expect("latched");
        if trig == ProbeTrigger::ZeroPulse {
            assert_eq!(
                e.position % 10_000,
                0,
                "C track at a multiple of the period"
            );
        }
        b.a.disarm_probe();
        b.cycle(None);
    }
}

#[test]
fn kl5101_neg_axis_is_a_parameter_error() {
    let toml = "[[axis]]\nname = \"Z\"\ndrive = \"kl5101-terminal\"\nkenngr.messachse = 1\nkenngr.measure.edge = \"NEG\"\n";
    let cfg = MachineConfig::parse(toml, "neg.toml").unwrap();
    let Err(e) = Machine::new(&cfg) else {
        panic!("refused")
    };
    let e = e.to_string();
    assert!(e.contains("P-AXIS-00518") && e.contains("POS"), "{e}");
}

fn meas1(drive: &str) -> Vec<String> {
    let toml = format!(
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\ndrive = \"{drive}\"\nkenngr.messachse = 1\n"
    );
    let mut m = Machine::new(&MachineConfig::parse(&toml, "m.toml").unwrap()).unwrap();
    m.add_probe("Z", 100.0).unwrap();
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/nc/seed004/meas1.nc"
    ))
    .unwrap();
    let r = m.run_program(&parse(&src).unwrap(), &mut |_| {});
    assert_eq!(
        r.status,
        RunStatus::Completed,
        "{drive}: {:?}",
        r.messages()
    );
    r.output().iter().map(|s| s.to_string()).collect()
}

const MEAS1: [&str; 9] = [
    "V.A.MESS.Z=100.000000",
    "V.A.MEAS.ACS.VALUE.Z=100.000000",
    "V.A.MEAS.PCS.VALUE.Z=100.000000",
    "V.A.MOFFS.Z=80.000000",
    "V.A.MEIN.Z=0.000000",
    "V.A.MEIN.Z=80.000000",
    "V.A.ABS.Z=180.000000",
    "V.A.MEIN.Z=0.000000",
    "V.A.ABS.Z=100.000000",
];

#[test]
fn meas1_end_to_end_on_lightbus() {
    assert_eq!(meas1("ax2000-lightbus"), MEAS1);
}

#[test]
fn meas1_end_to_end_on_kl5101_terminal() {
    assert_eq!(meas1("kl5101-terminal"), MEAS1);
}

#[test]
fn el1252_codec_single_vs_continuous() {
    let clock = fieldprobe::core::measure::timestamp::DcClock::new(1_000);
    // Continuous: last edge wins.
    let mut d = El1252Device::new(2, LatchMode::Continuous, clock);
    let mut img = vec![0u8; d.image_len()];
    let mut dec = Decoder::new(2, LatchMode::Continuous);
    d.write_image(&mut img).unwrap();
    dec.decode(&img).unwrap();
    d.edge(2, true, Nanos(100));
    d.edge(2, false, Nanos(200));
    d.edge(2, true, Nanos(300));
    d.write_image(&mut img).unwrap();
    // channel 2 at byte 17: status 0x10 (level high) | LatchPosR 1300 | LatchNegR 1200
    assert_eq!(img[17], 0x10);
    assert_eq!(u64::from_le_bytes(img[18..26].try_into().unwrap()), 1300);
    let (levels, edges) = dec.decode(&img).unwrap();
    assert_eq!(levels, [false, true]);
    assert_eq!(
        edges
            .iter()
            .map(|e| (e.rising, e.dc_time))
            .collect::<Vec<_>>(),
        [(false, 1200), (true, 1300)]
    );
    // Single event: first change kept until read.
    let mut d = El1252Device::new(1, LatchMode::SingleEvent, clock);
    let mut img = vec![0u8; d.image_len()];
    let mut dec = Decoder::new(1, LatchMode::SingleEvent);
    d.edge(1, true, Nanos(100));
    d.edge(1, false, Nanos(150));
    d.edge(1, true, Nanos(300));
    d.write_image(&mut img).unwrap();
    // status 0x13: rising + falling seen, level high | LatchPosR 1100 | LatchNegR 1150
    assert_eq!(img[0], 0x13);
    let (_, edges) = dec.decode(&img).unwrap();
    assert_eq!(
        edges
            .iter()
            .map(|e| (e.rising, e.dc_time))
            .collect::<Vec<_>>(),
        [(true, 1100), (false, 1150)]
    );
    d.write_image(&mut img).unwrap();
    assert!(
        dec.decode(&img).unwrap().1.is_empty(),
        "read events are not reported twice"
    );
    assert!(el1252::decode_image(&img[..5], 1).is_err());
}

// ---------------------------------------------------------------------------------------------
// Lightbus AX2000: traces
// ---------------------------------------------------------------------------------------------

/// Axis placed at `at` increments and enabled with the set-point there (stands still).
fn standing(name: &str, at: i32) -> Bench {
    let mut b = Bench::new(name);
    b.m.set_actual(f64::from(at));
    b.target = at;
    b.enable();
    b
}

#[test]
fn lightbus_arming_and_latch_trace_on_each_edge() {
    // Standing axis at 12345 increments: the latch must hold exactly that position.
    let mut b = standing("ax2000-lightbus", 12_345);
    assert_eq!(b.fb.unwrap().state, PowerState::OperationEnabled);
    assert_eq!(b.fb.unwrap().position, 12_345);
    // sw 0x0003 ready+enabled | pos 12345 (0x3039)
    assert_eq!(b.inp[..6], [0x03, 0x00, 0x39, 0x30, 0, 0]);

    // Rising edge, arming sequence 1.
    b.a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    b.cycle(None);
    assert_eq!(b.a.probe_state(), ProbeState::Arming);
    // latch ctl 0x1001: seq 1, LC_POS
    assert_eq!(b.out[10..12], [0x01, 0x10]);
    b.cycle(None);
    // latch status 0x1020: seq 1 acknowledged, IN2MODE 26, no valid bit
    assert_eq!(b.inp[10..12], [0x20, 0x10]);
    assert_eq!(b.a.probe_state(), ProbeState::Armed);
    b.cycle(Some((true, 0.5)));
    // latch status 0x1031: seq 1, IN2MODE 26, IN2 high, rising value valid | latched 12345
    assert_eq!(b.inp[10..16], [0x31, 0x10, 0x39, 0x30, 0, 0]);
    let e = b.a.take_probe_event().expect("rising edge latched");
    assert_eq!(
        (e.edge, e.position, e.probe),
        (ProbeEdge::Positive, 12_345, 1)
    );
    for _ in 0..5 {
        b.cycle(None);
    }
    assert!(b.a.take_probe_event().is_none(), "one event per arming");

    // Falling edge, arming sequence 2, axis placed elsewhere first.
    b.target = 23_456;
    for _ in 0..400 {
        b.cycle(None);
    }
    assert_eq!(b.fb.unwrap().position, 23_456);
    b.a.arm_probe(&req(ProbeEdge::Negative, ProbeTrigger::Input))
        .unwrap();
    b.cycle(None);
    // latch ctl 0x2002: seq 2, LC_NEG
    assert_eq!(b.out[10..12], [0x02, 0x20]);
    b.cycle(None);
    // latch status 0x2030: seq 2, IN2MODE 26, IN2 still high, valid bits cleared
    assert_eq!(b.inp[10..12], [0x30, 0x20]);
    assert_eq!(b.a.probe_state(), ProbeState::Armed);
    assert!(b.a.take_probe_event().is_none(), "old rising value not new");
    b.cycle(Some((false, 0.25)));
    // latch status 0x2022: seq 2, IN2MODE 26, IN2 low, falling value valid | 23456 (0x5BA0)
    assert_eq!(b.inp[10..16], [0x22, 0x20, 0xA0, 0x5B, 0, 0]);
    let e = b.a.take_probe_event().expect("falling edge latched");
    assert_eq!((e.edge, e.position), (ProbeEdge::Negative, 23_456));
}

#[test]
fn lightbus_moving_latch_lies_between_the_cycle_positions() {
    let mut b = Bench::new("ax2000-lightbus");
    b.enable();
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    let mut prev = b.fb.unwrap().position;
    let mut window = None;
    for k in 0..40 {
        b.target += 200;
        b.cycle((k == 30).then_some((true, 0.5)));
        let now = b.fb.unwrap().position;
        if k == 30 {
            window = Some((prev, now));
        }
        prev = now;
    }
    let (lo, hi) = window.unwrap();
    assert!(hi > lo, "the axis moves: {lo}..{hi}");
    let e = b.a.take_probe_event().expect("latched");
    // Half-way through the cycle: strictly inside the positions at the cycle ends.
    assert!(
        lo < e.position && e.position < hi,
        "{lo} < {} < {hi}",
        e.position
    );
}

/// Feedback telegram: status word, position, latch status, latched position.
fn lb_feedback(status: u16, position: i32, latch_status: u16, latched: i32) -> Vec<u8> {
    let mut f = vec![0u8; telegram::FEEDBACK_LEN];
    f[0..2].copy_from_slice(&status.to_le_bytes());
    f[2..6].copy_from_slice(&position.to_le_bytes());
    f[10..12].copy_from_slice(&latch_status.to_le_bytes());
    f[12..16].copy_from_slice(&latched.to_le_bytes());
    f
}

fn lightbus_def(extra: &str) -> DriveDefinition {
    catalogue::parse(
        &format!(
            "[drive]\nname = \"x\"\nprofile = \"lightbus\"\n[scaling]\nincrements_per_unit = 1\n[lightbus]\n{extra}"
        ),
        "x.toml",
    )
    .unwrap()
}

#[test]
fn lightbus_sequence_never_repeats_and_never_zero() {
    let mut a = LightbusAdapter::new(&lightbus_def("")).unwrap();
    let mut out = [0u8; telegram::COMMAND_LEN];
    let cmd = DriveCommand::default();
    let mut seen = Vec::new();
    for _ in 0..17 {
        a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
            .unwrap();
        a.write_outputs(Nanos(0), &cmd, &mut out).unwrap();
        // latch ctl: LC_POS in the low byte, sequence in the high nibble
        assert_eq!(out[10], 0x01);
        seen.push(out[11] >> 4);
    }
    assert_eq!(
        seen,
        [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 1, 2]
    );
    a.disarm_probe();
    a.write_outputs(Nanos(0), &cmd, &mut out).unwrap();
    assert_eq!(out[10..12], [0, 0], "disarmed: latch ctl 0");
}

#[test]
fn lightbus_stale_latch_of_an_earlier_arming_is_never_reported() {
    let mut a = LightbusAdapter::new(&lightbus_def("")).unwrap();
    let now = Nanos(0);
    // Arming 1, latched 500 under it.
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    // sw 3 | latch status 0x1020: seq 1 acknowledged, IN2MODE 26
    a.read_inputs(now, &lb_feedback(3, 0, 0x1020, 0)).unwrap();
    assert_eq!(a.probe_state(), ProbeState::Armed);
    // latch status 0x1021: seq 1, rising valid | latched 500
    a.read_inputs(now, &lb_feedback(3, 0, 0x1021, 500)).unwrap();
    assert_eq!(a.take_probe_event().map(|e| e.position), Some(500));
    // Arming 2: the drive has not taken it yet and still shows seq 1 with the 500.
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    for _ in 0..5 {
        a.read_inputs(now, &lb_feedback(3, 0, 0x1021, 500)).unwrap();
        assert_eq!(a.probe_state(), ProbeState::Arming);
        assert!(a.take_probe_event().is_none(), "stale 500 reported");
    }
    // latch status 0x2020: seq 2 acknowledged, valid bits cleared, old value still in the telegram
    a.read_inputs(now, &lb_feedback(3, 0, 0x2020, 500)).unwrap();
    assert_eq!(a.probe_state(), ProbeState::Armed);
    assert!(a.take_probe_event().is_none(), "stale 500 reported");
    // latch status 0x2021: seq 2, rising valid | latched 777
    a.read_inputs(now, &lb_feedback(3, 0, 0x2021, 777)).unwrap();
    a.read_inputs(now, &lb_feedback(3, 0, 0x2021, 777)).unwrap();
    assert_eq!(a.take_probe_event().map(|e| e.position), Some(777));
    assert!(a.take_probe_event().is_none(), "one event per arming");

    // Arming 3 acknowledged with a valid bit already set: the drive kept its latch -> failed.
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    // latch status 0x3021: seq 3 echoed, rising valid | 777
    a.read_inputs(now, &lb_feedback(3, 0, 0x3021, 777)).unwrap();
    assert!(a.take_probe_event().is_none());
    match a.probe_state() {
        ProbeState::Failed(m) => assert!(m.contains("still valid"), "{m}"),
        s => panic!("{s:?}"),
    }
}

#[test]
fn lightbus_arming_never_acknowledged_fails_after_timeout() {
    let mut a = LightbusAdapter::new(&lightbus_def("arm_timeout_cycles = 4\n")).unwrap();
    assert_eq!(a.config().arm_timeout_cycles, 4);
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    // latch status 0x0020: IN2MODE 26, sequence 0 (the drive never takes the arming)
    let fb = lb_feedback(3, 0, 0x0020, 0);
    for k in 1..=4 {
        a.read_inputs(Nanos(k), &fb).unwrap();
        assert_eq!(a.probe_state(), ProbeState::Arming, "cycle {k}");
    }
    a.read_inputs(Nanos(5), &fb).unwrap();
    match a.probe_state() {
        ProbeState::Failed(m) => {
            assert!(
                m.contains("did not acknowledge") && m.contains("4 cycles"),
                "{m}"
            )
        }
        s => panic!("{s:?}"),
    }
    assert!(a.take_probe_event().is_none());

    // Armed, but the edge never comes: stays armed, no event, no failure.
    let mut b = standing("ax2000-lightbus", 1000);
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    for _ in 0..(2 * lightbus::DEFAULT_ARM_TIMEOUT_CYCLES) {
        b.cycle(None);
    }
    assert_eq!(b.a.probe_state(), ProbeState::Armed);
    assert!(b.a.take_probe_event().is_none());

    // The drive drops the arming (acknowledge back to 0) while armed.
    let mut a = LightbusAdapter::new(&lightbus_def("")).unwrap();
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    a.read_inputs(Nanos(0), &lb_feedback(3, 0, 0x1020, 0))
        .unwrap();
    assert_eq!(a.probe_state(), ProbeState::Armed);
    a.read_inputs(Nanos(1), &lb_feedback(3, 0, 0x0020, 0))
        .unwrap();
    match a.probe_state() {
        ProbeState::Failed(m) => assert!(m.contains("dropped"), "{m}"),
        s => panic!("{s:?}"),
    }
    // IN2MODE bit gone while armed (latch status 0x1000: seq 1, no IN2MODE 26).
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    a.read_inputs(Nanos(2), &lb_feedback(3, 0, 0x2020, 0))
        .unwrap();
    a.read_inputs(Nanos(3), &lb_feedback(3, 0, 0x2000, 0))
        .unwrap();
    match a.probe_state() {
        ProbeState::Failed(m) => assert!(m.contains("IN2MODE"), "{m}"),
        s => panic!("{s:?}"),
    }
}

#[test]
fn lightbus_refuses_zero_pulse_source_object_and_continuous() {
    let mut a = LightbusAdapter::new(&lightbus_def("")).unwrap();
    for t in [ProbeTrigger::ZeroPulse, ProbeTrigger::SourceObject] {
        let e = a.arm_probe(&req(ProbeEdge::Positive, t)).unwrap_err();
        assert!(e.to_string().contains("digital input 2"), "{e}");
    }
    let mut r = req(ProbeEdge::Positive, ProbeTrigger::Input);
    r.continuous = true;
    let e = a.arm_probe(&r).unwrap_err();
    assert!(e.to_string().contains("continuous"), "{e}");
    assert_eq!(a.probe_state(), ProbeState::Idle);
}

#[test]
fn lightbus_torque_limit_and_lag_window_functions() {
    let def = catalogue::load("ax2000-lightbus").unwrap();
    let tl = def.function("TORQUE_LIMIT").unwrap();
    // #DRIVE VAL=10 (%) -> 100 in 0.1 % of rated torque, object 0x2001:00
    assert_eq!(
        (tl.index, tl.sub, tl.encode(10.0)),
        (lightbus::PARAM_TORQUE_LIMIT, 0, Some(100))
    );
    let mw = def.function("MON_WINDOW").unwrap();
    assert_eq!(
        (mw.index, mw.sub, mw.encode(4294967295.0)),
        (lightbus::PARAM_LAG_WINDOW, 0, Some(4294967295))
    );

    let mut b = Bench::new("ax2000-lightbus");
    b.enable();
    assert_eq!(b.m.read_object(lightbus::PARAM_TORQUE_LIMIT, 0), Ok(3000));
    assert_eq!(b.m.read_object(lightbus::PARAM_LAG_WINDOW, 0), Ok(300_000));
    b.m.write_object(lightbus::PARAM_TORQUE_LIMIT, 0, 100)
        .unwrap();
    b.m.write_object(lightbus::PARAM_LAG_WINDOW, 0, 4294967295)
        .unwrap();
    assert_eq!(b.m.read_object(lightbus::PARAM_TORQUE_LIMIT, 0), Ok(100));
    // Press against a wall at 5000 increments with the set-point running on.
    b.m.set_fixed_stop(Some(5_000.0));
    for _ in 0..200 {
        b.target += 1_000;
        b.cycle(None);
    }
    let fb = b.fb.unwrap();
    assert_eq!(fb.position, 5_000, "held at the wall");
    // Lag = set-point the drive holds (written one cycle earlier: 199 × 1000) - wall
    // (the window is off: no fault).
    assert_eq!(fb.following_error, Some(199 * 1_000 - 5_000));
    assert_eq!(fb.state, PowerState::OperationEnabled);
    assert!(!fb.following_error_flag);
    // sw 0x0023: ready, enabled, torque limit active
    assert_eq!(fb.statusword, 0x0023);

    // Window 1000: the lag exceeds it; the file's timeout is 10 ms = 10 cycles of 1 ms.
    b.m.write_object(lightbus::PARAM_LAG_WINDOW, 0, 1000)
        .unwrap();
    for k in 1..=10 {
        b.cycle(None);
        assert!(!b.fb.unwrap().fault, "cycle {k}: within the lag timeout");
    }
    b.cycle(None);
    let fb = b.fb.unwrap();
    assert_eq!(fb.state, PowerState::Fault);
    assert!(fb.fault && fb.following_error_flag && !fb.operational);
    // sw 0x0038: fault, lag error, torque limit still flagged (not ready, not enabled)
    assert_eq!(fb.statusword & 0x001F, 0x0018);
    assert_eq!(
        b.m.read_object(lightbus::PARAM_ERROR_CODE, 0),
        Ok(i64::from(fieldprobe::drive::model::lightbus::ERROR_LAG))
    );

    // Monitoring off again, set-point back to the wall, fault reset -> enabled.
    b.m.write_object(lightbus::PARAM_LAG_WINDOW, 0, 4294967295)
        .unwrap();
    b.target = 5_000;
    b.reset = true;
    b.cycle(None);
    // cw 0x0003: enable + fault reset
    assert_eq!(b.out[0..2], [0x03, 0x00]);
    b.reset = false;
    b.cycle(None);
    b.cycle(None);
    let fb = b.fb.unwrap();
    assert_eq!(fb.state, PowerState::OperationEnabled);
    assert!(!fb.following_error_flag);

    // Range, read-only and unknown-object refusals.
    use fieldprobe::drive::model::abort;
    assert_eq!(
        b.m.write_object(lightbus::PARAM_TORQUE_LIMIT, 0, 70_000),
        Err(abort::VALUE_RANGE)
    );
    assert_eq!(
        b.m.write_object(lightbus::PARAM_LAG_WINDOW, 0, -1),
        Err(abort::VALUE_RANGE)
    );
    assert_eq!(
        b.m.write_object(lightbus::PARAM_ERROR_CODE, 0, 0),
        Err(abort::READ_ONLY)
    );
    assert_eq!(
        b.m.read_object(lightbus::PARAM_TORQUE_LIMIT, 1),
        Err(abort::NO_SUB_INDEX)
    );
    assert_eq!(b.m.read_object(0x2100, 0), Err(abort::NO_OBJECT));
}

#[test]
fn lightbus_drive_fault_while_measuring_and_fault_reset() {
    let mut b = standing("ax2000-lightbus", 4_000);
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    b.m.inject_fault(0x0042);
    b.cycle(None);
    let fb = b.fb.unwrap();
    assert_eq!(fb.state, PowerState::Fault);
    assert!(fb.fault && !fb.operational);
    // sw 0x0008: fault only (not ready, not enabled)
    assert_eq!(b.inp[0..2], [0x08, 0x00]);
    assert!(b.a.take_probe_event().is_none(), "a fault is not a latch");
    // Still faulted while the command keeps enable without reset.
    b.cycle(None);
    assert_eq!(b.fb.unwrap().state, PowerState::Fault);
    // Rising edge of control word bit 1.
    b.reset = true;
    b.cycle(None);
    assert_eq!(b.out[0..2], [0x03, 0x00]);
    b.reset = false;
    b.cycle(None);
    b.cycle(None);
    assert_eq!(b.fb.unwrap().state, PowerState::OperationEnabled);
    assert_eq!(b.fb.unwrap().position, 4_000);
    assert_eq!(b.m.last_error_code(), 0x0042, "last error kept");
    assert!(b.a.take_probe_event().is_none());
}

#[test]
fn lightbus_section_errors_name_file_line_key_and_allowed_values() {
    let head = "[drive]\nname = \"x\"\nprofile = \"lightbus\"\n[scaling]\nincrements_per_unit = 1\n[lightbus]\n";
    for (extra, want) in [
        (
            "in2mod = 26\n",
            &[
                "x.toml:7:",
                "in2mod",
                "allowed: in2mode, arm_timeout_cycles",
            ][..],
        ),
        (
            "in2mode = 26\narm_timeout_cycles = 0\n",
            &["x.toml:8:", "arm_timeout_cycles", "1..=1000000"][..],
        ),
        (
            "in2mode = \"26\"\n",
            &["x.toml:7:", "in2mode", "0..=255"][..],
        ),
    ] {
        let def = catalogue::parse(&format!("{head}{extra}"), "x.toml").unwrap();
        let e =
            fieldprobe::drive::adapter_for(&def, &ParamSet::new(fieldprobe::params::Scope::Axis))
                .unwrap_err()
                .to_string();
        for w in want {
            assert!(e.contains(w), "{extra:?}: {e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// KL5101 / EL5101 terminal drives: traces
// ---------------------------------------------------------------------------------------------

#[test]
fn terminal_arming_and_latch_trace_on_each_allowed_edge() {
    for (drive, edges) in [
        ("kl5101-terminal", &[ProbeEdge::Positive][..]),
        (
            "el5101-terminal",
            &[ProbeEdge::Positive, ProbeEdge::Negative][..],
        ),
    ] {
        let mut b = standing(drive, 12_345);
        // SB 0x00 | counter 12345 (0x3039) | latch 0 | drive 0x03 ready+enabled
        assert_eq!(b.inp, [0x00, 0x39, 0x30, 0x00, 0x00, 0x03], "{drive}");
        assert_eq!(b.fb.unwrap().position, 12_345);
        for &edge in edges {
            let (cb, rising) = match edge {
                ProbeEdge::Positive => (0x02, true),  // CB1 EN_LATCH_EXTP
                ProbeEdge::Negative => (0x08, false), // CB3 EN_LATCH_EXTN
            };
            b.a.arm_probe(&req(edge, ProbeTrigger::Input)).unwrap();
            // Re-arm protocol: enable bit 0 first, then set once *_VAL = 0 was seen.
            b.cycle(None);
            assert_eq!(b.out[0], 0x00, "{drive} {edge:?}: clear first");
            assert_eq!(b.a.probe_state(), ProbeState::Arming);
            b.cycle(None);
            assert_eq!(b.out[0], cb, "{drive} {edge:?}: enable");
            b.cycle(None);
            assert_eq!(b.a.probe_state(), ProbeState::Armed);
            assert!(b.a.take_probe_event().is_none());
            b.cycle(Some((rising, 0.5)));
            // SB LAT_EXT_VAL (+ input level when high) | counter 12345 | latch 12345 | drive 0x03
            let sb = if rising { 0x22 } else { 0x02 };
            assert_eq!(
                b.inp,
                [sb, 0x39, 0x30, 0x39, 0x30, 0x03],
                "{drive} {edge:?}"
            );
            let e = b.a.take_probe_event().expect("latched");
            assert_eq!((e.edge, e.position), (edge, 12_345), "{drive}");
            for _ in 0..3 {
                b.cycle(None);
            }
            assert!(b.a.take_probe_event().is_none(), "one event per arming");
            b.a.disarm_probe();
            b.cycle(None);
            assert_eq!(b.out[0], 0x00, "disarmed");
        }
    }
}

#[test]
fn terminal_moving_latch_across_the_wrap_lies_between_cycle_positions() {
    let mut b = standing("kl5101-terminal", 20_000);
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    let mut prev = b.fb.unwrap().position;
    let mut window = None;
    for k in 0..30 {
        b.target += 3_000;
        b.cycle((k == 10).then_some((true, 0.5)));
        let now = b.fb.unwrap().position;
        if k == 10 {
            window = Some((prev, now));
        }
        prev = now;
    }
    let (lo, hi) = window.unwrap();
    // The set-point is at 20000 + 11 × 3000 = 53000 after cycle k = 10: past the 16-bit wrap.
    assert!(hi > 32_767 && hi > lo, "{lo}..{hi}");
    let e = b.a.take_probe_event().expect("latched");
    assert!(
        lo < e.position && e.position < hi,
        "{lo} < {} < {hi}",
        e.position
    );
    // The axis follows the set-point: 20000 + 30 × 3000 within the loop lag.
    // One cycle of transport delay: in cycle k the amplifier runs at the velocity written in
    // cycle k - 1 (feed-forward to that set-point, error 0 from the standing start), so after
    // the 30th cycle the axis stands exactly at the 29th set-point: 20000 + 29 × 3000.
    assert_eq!(b.fb.unwrap().position, 20_000 + 29 * 3_000);
}

fn terminal_def(variant: &str, extra: &str) -> DriveDefinition {
    catalogue::parse(
        &format!(
            "[drive]\nname = \"t\"\nprofile = \"terminal\"\n[scaling]\nincrements_per_unit = 1\n[terminal]\nvariant = \"{variant}\"\n{extra}"
        ),
        "t.toml",
    )
    .unwrap()
}

fn terminal_adapter(def: &DriveDefinition) -> Box<dyn DriveAdapter> {
    fieldprobe::drive::adapter_for(def, &ParamSet::new(fieldprobe::params::Scope::Axis)).unwrap()
}

#[test]
fn terminal_stale_latch_is_never_reported_and_stuck_val_fails() {
    let def = terminal_def("EL5101", "arm_timeout_cycles = 5\n");
    let mut a = terminal_adapter(&def);
    let cmd = DriveCommand {
        enable: true,
        ..DriveCommand::default()
    };
    let mut out = [0u8; image::OUTPUT_LEN];
    // SB 0x02 LAT_EXT_VAL (stale) | counter 10000 (0x2710) | latch 1000 (0x03E8) | drive 0x03
    let stale = [0x02, 0x10, 0x27, 0xE8, 0x03, 0x03];
    a.read_inputs(Nanos(0), &stale).unwrap();
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    for k in 1..=5 {
        a.write_outputs(Nanos(k), &cmd, &mut out).unwrap();
        assert_eq!(out[0], 0x00, "enable stays 0 while LAT_EXT_VAL is set");
        a.read_inputs(Nanos(k), &stale).unwrap();
        assert_eq!(a.probe_state(), ProbeState::Arming, "cycle {k}");
        assert!(a.take_probe_event().is_none(), "stale 1000 reported");
    }
    a.write_outputs(Nanos(6), &cmd, &mut out).unwrap();
    a.read_inputs(Nanos(6), &stale).unwrap();
    match a.probe_state() {
        ProbeState::Failed(m) => assert!(m.contains("did not clear") && m.contains("5"), "{m}"),
        s => panic!("{s:?}"),
    }
    a.write_outputs(Nanos(7), &cmd, &mut out).unwrap();
    assert_eq!(out[0], 0x00, "failed: latch disabled");

    // Re-arm: the terminal clears the valid bit; the old latch value stays in the image.
    a.arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .unwrap();
    // SB 0x00 | counter 10000 | latch 1000 (stale value, valid bit clear) | drive 0x03
    let cleared = [0x00, 0x10, 0x27, 0xE8, 0x03, 0x03];
    a.write_outputs(Nanos(8), &cmd, &mut out).unwrap();
    a.read_inputs(Nanos(8), &cleared).unwrap();
    a.write_outputs(Nanos(9), &cmd, &mut out).unwrap();
    assert_eq!(out[0], 0x02, "CB1 EN_LATCH_EXTP");
    a.read_inputs(Nanos(9), &cleared).unwrap();
    assert_eq!(a.probe_state(), ProbeState::Armed);
    assert!(a.take_probe_event().is_none());
    // SB 0x02 | counter 10000 | latch 10240 (0x2800) | drive 0x03
    let fresh = [0x02, 0x10, 0x27, 0x00, 0x28, 0x03];
    a.read_inputs(Nanos(10), &fresh).unwrap();
    a.read_inputs(Nanos(11), &fresh).unwrap();
    assert_eq!(a.take_probe_event().map(|e| e.position), Some(10_240));
    assert!(a.take_probe_event().is_none(), "one event per arming");

    // Armed, the edge never comes: stays armed, no event.
    let mut b = standing("el5101-terminal", 500);
    b.arm(req(ProbeEdge::Negative, ProbeTrigger::Input));
    for _ in 0..250 {
        b.cycle(None);
    }
    assert_eq!(b.a.probe_state(), ProbeState::Armed);
    assert!(b.a.take_probe_event().is_none());
}

#[test]
fn terminal_refuses_source_object_and_continuous() {
    let mut a = terminal_adapter(&terminal_def("EL5101", ""));
    let e = a
        .arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::SourceObject))
        .unwrap_err();
    assert!(e.to_string().contains("no trigger source object"), "{e}");
    let mut r = req(ProbeEdge::Positive, ProbeTrigger::Input);
    r.continuous = true;
    let e = a.arm_probe(&r).unwrap_err();
    assert!(e.to_string().contains("continuous"), "{e}");
    assert_eq!(a.probe_state(), ProbeState::Idle);
}

#[test]
fn terminal_drive_fault_while_measuring_and_fault_reset() {
    let mut b = standing("el5101-terminal", 7_000);
    b.arm(req(ProbeEdge::Positive, ProbeTrigger::Input));
    b.m.inject_fault(0x0007);
    b.cycle(None);
    let fb = b.fb.unwrap();
    assert_eq!(fb.state, PowerState::Fault);
    assert!(fb.fault && !fb.operational);
    // drive inputs 0x04: fault only
    assert_eq!(b.inp[5], 0x04);
    // Velocity output 0 while the amplifier is not enabled.
    b.target = 9_000;
    b.cycle(None);
    assert_eq!(b.out[3..5], [0, 0]);
    assert_eq!(b.fb.unwrap().state, PowerState::Fault);
    assert_eq!(b.fb.unwrap().position, 7_000, "held");
    assert!(b.a.take_probe_event().is_none());
    // Fault reset: drive output bit 1.
    b.target = 7_000;
    b.reset = true;
    b.cycle(None);
    // drive outputs 0x03: enable + fault reset
    assert_eq!(b.out[5], 0x03);
    b.reset = false;
    b.cycle(None);
    b.cycle(None);
    assert_eq!(b.inp[5], 0x03, "ready + enabled");
    assert_eq!(b.fb.unwrap().state, PowerState::OperationEnabled);
    assert_eq!(b.m.last_error_code(), 0x0007);
}

#[test]
fn terminal_has_no_drive_functions_and_drive_torque_limit_is_refused() {
    for drive in ["kl5101-terminal", "el5101-terminal"] {
        let def = catalogue::load(drive).unwrap();
        assert!(def.functions.is_empty(), "{drive}");
        let m = model::for_definition(&def).unwrap();
        use fieldprobe::drive::model::abort;
        assert_eq!(m.read_object(0x2001, 0), Err(abort::NO_OBJECT));
    }
    let prog = "%t\nN10 #DRIVE WR SYN [AX=Z KEY=TORQUE LIMIT VAL=10 WAIT]\nN20 M30\n";
    let run = |drive: &str| {
        let toml = format!(
            "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n[[axis]]\nname = \"Z\"\ndrive = \"{drive}\"\n"
        );
        let mut m = Machine::new(&MachineConfig::parse(&toml, "m.toml").unwrap()).unwrap();
        m.run_program(&parse(prog).unwrap(), &mut |_| {})
    };
    let r = run("kl5101-terminal");
    assert_eq!(r.status, RunStatus::Aborted);
    let texts: Vec<&str> = r.messages().iter().map(|m| m.text.as_str()).collect();
    assert!(
        texts
            .iter()
            .any(|t| t.contains("kl5101-terminal") && t.contains("has no function TORQUE_LIMIT")),
        "{texts:?}"
    );
    // The same block on the Lightbus drive goes through.
    let r = run("ax2000-lightbus");
    assert_eq!(r.status, RunStatus::Completed, "{:?}", r.messages());
}

#[test]
fn terminal_section_errors_name_file_line_key_and_allowed_values() {
    let cases: [(&str, &str, &[&str]); 4] = [
        (
            "KL5102",
            "",
            &["t.toml:7:", "variant", "\"KL5101\", \"EL5101\""],
        ),
        (
            "EL5101",
            "kp = -1\n",
            &["t.toml:8:", "kp", "finite number > 0"],
        ),
        (
            "EL5101",
            "full_scale = 3\n",
            &[
                "t.toml:8:",
                "full_scale",
                "allowed: variant, full_scale_velocity, kp, arm_timeout_cycles",
            ],
        ),
        (
            "KL5101",
            "arm_timeout_cycles = 2000000\n",
            &["t.toml:8:", "arm_timeout_cycles", "1..=1000000"],
        ),
    ];
    for (variant, extra, want) in cases {
        let def = terminal_def(variant, extra);
        let e =
            fieldprobe::drive::adapter_for(&def, &ParamSet::new(fieldprobe::params::Scope::Axis))
                .unwrap_err()
                .to_string();
        for w in want {
            assert!(e.contains(w), "{variant} {extra:?}: {e}");
        }
        // The model reads the same section and refuses it too.
        assert!(model::for_definition(&def).is_err());
    }
}

#[test]
fn terminal_model_counter_set_cnt_set() {
    // The model's CB2 CNT_SET, driven here with hand-made output images (the adapter's side:
    // `terminal_adapter_counter_set_rebases_the_position`).
    let def = catalogue::load("el5101-terminal").unwrap();
    let mut m = model::for_definition(&def).unwrap();
    let mut tx = [0u8; image::INPUT_LEN];
    let step = |m: &mut Box<dyn DriveModel>, k: u64, rx: [u8; 6], tx: &mut [u8; 6]| {
        m.begin_step(Nanos(k * T.0), 1e-3, &rx);
        m.finish_step(tx);
    };
    m.set_actual(3_000.0);
    // CB 0x00 | set value 0 | velocity 0 | drive 0x00
    step(&mut m, 1, [0, 0, 0, 0, 0, 0], &mut tx);
    // SB 0x00 | counter 3000 (0x0BB8)
    assert_eq!(tx[0..3], [0x00, 0xB8, 0x0B]);
    // CB 0x04 CNT_SET | set value 1000 (0x03E8)
    step(&mut m, 2, [0x04, 0xE8, 0x03, 0, 0, 0], &mut tx);
    // SB 0x04 CNTSET_ACC | counter 1000
    assert_eq!(tx[0..3], [0x04, 0xE8, 0x03]);
    // CB2 held with another set value: only a rising edge sets the counter.
    step(&mut m, 3, [0x04, 0x10, 0x27, 0, 0, 0], &mut tx);
    assert_eq!(tx[0..3], [0x04, 0xE8, 0x03]);
    // The axis moves by +2500: the counter follows from the set value (1000 + 2500 = 3500).
    m.set_actual(5_500.0);
    step(&mut m, 4, [0, 0, 0, 0, 0, 0], &mut tx);
    // SB 0x00 (CNTSET_ACC gone) | counter 3500 (0x0DAC)
    assert_eq!(tx[0..3], [0x00, 0xAC, 0x0D]);
    // Set to 65530 and move +10: the counter wraps to 4 with SB4 OVERFLOW in that cycle.
    step(&mut m, 5, [0x04, 0xFA, 0xFF, 0, 0, 0], &mut tx);
    assert_eq!(tx[0..3], [0x04, 0xFA, 0xFF]);
    step(&mut m, 6, [0, 0, 0, 0, 0, 0], &mut tx);
    m.set_actual(5_510.0);
    step(&mut m, 7, [0, 0, 0, 0, 0, 0], &mut tx);
    assert_eq!(tx[0..3], [0x00, 0x04, 0x00]);
    // An external latch after the counter set is in the counter's coordinates: standing at
    // 5510 increments -> counter 4. CB1 EN_LATCH_EXTP, rising edge.
    step(&mut m, 8, [0x02, 0, 0, 0, 0, 0], &mut tx);
    m.begin_step(Nanos(9 * T.0), 1e-3, &[0x02, 0, 0, 0, 0, 0]);
    m.input_edge(1, true, Nanos(9 * T.0 - T.0 / 2));
    m.finish_step(&mut tx);
    // SB 0x22 LAT_EXT_VAL + input high | counter 4 | latch 4
    assert_eq!(tx[0..5], [0x22, 0x04, 0x00, 0x04, 0x00]);
}

// ---------------------------------------------------------------------------------------------
// EL1252: DC time of a known edge
// ---------------------------------------------------------------------------------------------

#[test]
fn el1252_dc_time_of_known_edges_per_channel_first_event_vs_continuous() {
    use fieldprobe::core::measure::timestamp::DcClock;
    // DC time counts ns from 2000-01-01; 2026-01-01 is 26 × 365 + 7 leap days (2000, 04, 08,
    // 12, 16, 20, 24) = 9497 days later.
    let days: i64 = 26 * 365 + 7;
    let epoch: i64 = days * 86_400 * 1_000_000_000;
    let clock = DcClock::default();
    let dc = |t_ns: u64| epoch + t_ns as i64;
    // Edges (channel, rising, virtual time ns) per cycle of 1 ms.
    let cycles: [&[(u8, bool, u64)]; 3] = [
        &[
            (1, true, 1_000_250),
            (2, true, 1_000_400),
            (1, false, 1_000_700),
            (1, true, 1_000_900),
        ],
        &[
            (1, false, 2_000_050),
            (2, false, 2_000_123),
            (1, true, 2_000_600),
            (1, false, 2_000_800),
        ],
        &[],
    ];
    // Continuous: the last edge of each kind wins; single event: the first is kept.
    let expect_cont: [&[(u8, bool, u64)]; 3] = [
        &[
            (2, true, 1_000_400),
            (1, false, 1_000_700),
            (1, true, 1_000_900),
        ],
        &[
            (2, false, 2_000_123),
            (1, true, 2_000_600),
            (1, false, 2_000_800),
        ],
        &[],
    ];
    let expect_single: [&[(u8, bool, u64)]; 3] = [
        &[
            (1, true, 1_000_250),
            (2, true, 1_000_400),
            (1, false, 1_000_700),
        ],
        &[
            (1, false, 2_000_050),
            (2, false, 2_000_123),
            (1, true, 2_000_600),
        ],
        &[],
    ];
    let levels = [[true, true], [false, false], [false, false]];
    for (mode, expect) in [
        (LatchMode::Continuous, expect_cont),
        (LatchMode::SingleEvent, expect_single),
    ] {
        let mut d = El1252Device::new(2, mode, clock);
        let mut img = vec![0u8; d.image_len()];
        assert_eq!(img.len(), 2 * el1252::CHANNEL_LEN);
        let mut dec = Decoder::new(2, mode);
        d.write_image(&mut img).unwrap();
        assert!(dec.decode(&img).unwrap().1.is_empty(), "reference image");
        for (k, edges) in cycles.iter().enumerate() {
            for &(ch, rising, t) in edges.iter() {
                d.edge(ch, rising, Nanos(t));
            }
            d.write_image(&mut img).unwrap();
            let (lv, got) = dec.decode(&img).unwrap();
            assert_eq!(lv, levels[k], "{mode:?} cycle {k}");
            let want: Vec<(u8, bool, i64)> =
                expect[k].iter().map(|&(c, r, t)| (c, r, dc(t))).collect();
            let got3: Vec<(u8, bool, i64)> = got
                .iter()
                .map(|e| (e.channel, e.rising, e.dc_time))
                .collect();
            assert_eq!(got3, want, "{mode:?} cycle {k}");
            // Back to the virtual edge time.
            for (e, &(_, _, t)) in got.iter().zip(expect[k].iter()) {
                assert_eq!(clock.to_nanos(e.dc_time), Nanos(t));
            }
        }
    }
    // Channel 2 image bytes after a single rising edge at 1 ms: status 0x11 (rising seen,
    // level high) | LatchPosR = epoch + 1e6 ns.
    let mut d = El1252Device::new(2, LatchMode::SingleEvent, clock);
    let mut img = vec![0u8; d.image_len()];
    d.edge(2, true, Nanos(1_000_000));
    d.write_image(&mut img).unwrap();
    assert_eq!(img[17], 0x11);
    assert_eq!(
        img[18..26],
        ((epoch + 1_000_000) as u64).to_le_bytes(),
        "LatchPosR"
    );
    assert_eq!(img[0], 0x00, "channel 1 untouched");
}

#[test]
fn terminal_adapter_counter_set_rebases_the_position() {
    // notes cnc.md §4.1 CB2 CNT_SET: the adapter writes the set value (low 16 bits of the wanted
    // position) with CNT_SET until CNTSET_ACC, then counts on from the wanted position.
    let def = catalogue::load("kl5101-terminal").unwrap();
    let mut a =
        TerminalAdapter::new(&def, &ParamSet::new(fieldprobe::params::Scope::Axis)).unwrap();
    let mut m = model::for_definition(&def).unwrap();
    let (mut out, mut inp) = ([0u8; image::OUTPUT_LEN], [0u8; image::INPUT_LEN]);
    let mut k = 0u64;
    let mut cycle = |a: &mut TerminalAdapter, m: &mut Box<dyn DriveModel>, enable: bool| {
        k += 1;
        m.begin_step(Nanos(k * T.0), 1e-3, &out);
        m.finish_step(&mut inp);
        let fb = a.read_inputs(Nanos(k * T.0), &inp).unwrap();
        let cmd = DriveCommand {
            enable,
            target: fb.position,
            fault_reset: false,
            quick_stop: false,
        };
        a.write_outputs(Nanos(k * T.0), &cmd, &mut out).unwrap();
        (fb.position, out[0], u16::from_le_bytes([out[1], out[2]]))
    };
    m.set_actual(3_000.0);
    cycle(&mut a, &mut m, false);
    assert_eq!(cycle(&mut a, &mut m, false).0, 3_000);
    // 100000 = 0x186A0: set value 0x86A0 = 34464, beyond the 16-bit counter.
    a.preset_counter(100_000).unwrap();
    assert!(a.presetting());
    // The next output image: CB 0x04 CNT_SET | set value 34464.
    let (pos, cb, set) = cycle(&mut a, &mut m, false);
    assert_eq!((pos, cb, set), (3_000, image::CB_CNT_SET, 34_464));
    // The terminal loads it and reports CNTSET_ACC: the position is 100000; CB2 dropped.
    let (pos, cb, set) = cycle(&mut a, &mut m, false);
    assert_eq!((pos, cb, set), (100_000, 0, 0));
    assert!(!a.presetting());
    // Motion after the set counts on from it (+2500), across no wrap trouble.
    m.set_actual(5_500.0);
    assert_eq!(cycle(&mut a, &mut m, false).0, 102_500);
    // A latch cannot be armed during a counter set, nor a counter set made with the amplifier on.
    a.preset_counter(0).unwrap();
    assert!(a
        .arm_probe(&req(ProbeEdge::Positive, ProbeTrigger::Input))
        .is_err());
    cycle(&mut a, &mut m, false);
    cycle(&mut a, &mut m, false);
    assert_eq!(cycle(&mut a, &mut m, false).0, 0);
    for _ in 0..5 {
        cycle(&mut a, &mut m, true);
    }
    let e = a.preset_counter(7).unwrap_err().to_string();
    assert!(e.contains("amplifier disabled"), "{e}");
}
