//! Lightbus AX2000, KL5101 / EL5101 terminal drives and the EL1252 timestamp codec (seed 004
//! §6.2, §6.3, §7.5; notes cnc.md §4.1–§4.4). Byte fixtures carry a one-line decode.

use fieldprobe::drive::catalogue;
use fieldprobe::drive::el1252::{self, Decoder, LatchMode};
use fieldprobe::drive::lightbus::{self, telegram, LightbusAdapter};
use fieldprobe::drive::model::el1252::El1252Device;
use fieldprobe::drive::model::{self, DriveModel};
use fieldprobe::drive::terminal::{self, image, CounterExtender, Variant};
use fieldprobe::drive::{
    DriveAdapter, DriveCommand, ProbeEdge, ProbeRequest, ProbeState, ProbeTrigger,
    TriggerSourceMode,
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
}

impl Bench {
    fn new(name: &str) -> Bench {
        let def = catalogue::load(name).unwrap();
        let a =
            fieldprobe::drive::adapter_for(&def, &ParamSet::new(fieldprobe::params::Scope::Axis))
                .unwrap();
        let m = model::for_definition(&def).unwrap();
        Bench {
            out: vec![0; a.output_len()],
            inp: vec![0; a.input_len()],
            a,
            m,
            now: Nanos(0),
            target: 0,
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
        self.a.read_inputs(self.now, &self.inp).unwrap();
        let cmd = DriveCommand {
            enable: true,
            target: self.target,
            fault_reset: false,
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
