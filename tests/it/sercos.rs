//! SERCOS (SoE) drive family, both sides (seed 004 §6.1, §7.3.1; notes ethercat.md §7):
//! traces of MDT / AT bytes between [`SercosAdapter`] and [`SercosModel`], the probe by
//! real-time bits for every P-AXIS-00060 value and edge, S-0-0092 / S-0-0159, error paths, the
//! commissioning check and meas1 end to end.
//!
//! Bus timing (as on every link, `SimLink`): the drive takes the MDT at the next SYNC0 and steps;
//! the AT it writes there is sampled at SYNC0 and reaches the master with the *next* frame. So
//! the AT the adapter reads in a cycle is the drive's state before it saw the MDT written in
//! that cycle, and a control word's effect shows one cycle after it was written (dead time 2
//! cycles; the very first AT is all zeros).
//!
//! Trace notation: each telegram entry in wire order (little-endian), `|` between entries.
//! Default telegram: MDT = S-0-0134 control word | S-0-0047 position command; AT = S-0-0135
//! status word | S-0-0051 position feedback | S-0-0189 following distance | S-0-0130 probe
//! value 1 positive | S-0-0179 probe status.

use fieldprobe::drive::catalogue::{self, DriveDefinition};
use fieldprobe::drive::model::{abort, sercos::SercosModel, DriveModel};
use fieldprobe::drive::sercos::{commissioning_check, SercosAdapter};
use fieldprobe::drive::{
    adapter_for, DriveAdapter, DriveCommand, DriveFeedback, PowerState, ProbeEdge, ProbeRequest,
    ProbeState, ProbeTrigger, TriggerSourceMode,
};
use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::{MachineConfig, Origin, ParamSet, Scope};
use fieldprobe::units::Nanos;

const DT_NS: u64 = 1_000_000;

fn params(pairs: &[(&str, &str)]) -> ParamSet {
    let mut p = ParamSet::new(Scope::Axis);
    for (k, v) in pairs {
        p.set(k, v, &Origin::api()).unwrap();
    }
    p
}

/// The built-in drive with its `[sercos]` lines replaced (`from` → `to`).
fn drive_with(from: &str, to: &str) -> DriveDefinition {
    let text = catalogue::load("sercos-ax5000").unwrap().source;
    assert!(text.contains(from), "{from}");
    catalogue::parse(&text.replace(from, to), "test-sercos.toml").unwrap()
}

fn hex(bytes: &[u8], entries: &[(usize, usize)]) -> String {
    entries
        .iter()
        .map(|&(a, b)| {
            bytes[a..b]
                .iter()
                .map(|x| format!("{x:02x}"))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect::<Vec<_>>()
        .join(" | ")
}

/// Adapter and drive model on one simulated bus with the bus's timing (module documentation;
/// the adapter keeps its default feedback delay 1).
struct Rig {
    a: SercosAdapter,
    m: SercosModel,
    now: Nanos,
    mdt: Vec<u8>,
    /// The AT the adapter read in the last cycle.
    at: Vec<u8>,
    /// The AT the drive wrote at its last step, delivered with the next frame.
    sampled: Vec<u8>,
    cmd: DriveCommand,
    /// Position the model's trajectory had at the last edge.
    edge_pos: f64,
}

impl Rig {
    fn new(def: &DriveDefinition, axis: &ParamSet) -> Rig {
        let a = SercosAdapter::new(def, axis).unwrap();
        let m = SercosModel::new(def).unwrap();
        let (mdt, at) = (vec![0; a.output_len()], vec![0; a.input_len()]);
        Rig {
            a,
            m,
            now: Nanos::ZERO,
            mdt,
            sampled: at.clone(),
            at,
            cmd: DriveCommand {
                enable: true,
                ..DriveCommand::default()
            },
            edge_pos: f64::NAN,
        }
    }

    /// One cycle: the adapter writes the MDT, the drive takes it and steps with optional input
    /// edges at `frac` of the cycle, and the adapter reads the AT of this frame — the one the
    /// drive wrote at its *previous* step.
    fn cycle(&mut self, edges: &[(u8, bool, f64)]) -> DriveFeedback {
        self.a
            .write_outputs(self.now, &self.cmd, &mut self.mdt)
            .unwrap();
        self.now = Nanos(self.now.0 + DT_NS);
        // The frame delivers what the drive sampled at the previous SYNC0.
        std::mem::swap(&mut self.at, &mut self.sampled);
        self.m.begin_step(self.now, 1e-3, &self.mdt);
        for &(input, rising, frac) in edges {
            let at = Nanos(self.now.0 - DT_NS + (DT_NS as f64 * frac) as u64);
            self.edge_pos = self.m.position_at(at).unwrap();
            self.m.input_edge(input, rising, at);
        }
        self.m.finish_step(&mut self.sampled);
        self.a.read_inputs(self.now, &self.at).unwrap()
    }

    fn mdt_hex(&self) -> String {
        let e: Vec<_> = self
            .a
            .telegram()
            .mdt
            .entries()
            .iter()
            .map(|e| (e.offset, e.end()))
            .collect();
        hex(&self.mdt, &e)
    }

    fn at_hex(&self) -> String {
        let e: Vec<_> = self
            .a
            .telegram()
            .at
            .entries()
            .iter()
            .map(|e| (e.offset, e.end()))
            .collect();
        hex(&self.at, &e)
    }

    /// Power up and run until operational: the drive follows from its third step on (ready for
    /// power-up, main power on, enabled), whose AT arrives in the fourth cycle.
    fn power_up(&mut self) {
        for _ in 0..3 {
            assert!(!self.cycle(&[]).operational);
        }
        assert!(self.cycle(&[]).operational);
    }
}

fn request(probe: u8, edge: ProbeEdge) -> ProbeRequest {
    ProbeRequest {
        probe,
        edge,
        trigger: ProbeTrigger::Input,
        continuous: false,
        source_mode: TriggerSourceMode::Default,
        input: probe,
    }
}

fn seed_axis() -> ParamSet {
    params(&[
        ("P-AXIS-00060", "1"),
        ("P-AXIS-00516", "DRIVE"),
        ("P-AXIS-00518", "POS"),
    ])
}

/// Little-endian bytes of an `i32` as in the trace notation.
fn le(v: i32) -> String {
    hex(&v.to_le_bytes(), &[(0, 4)])
}

/// The power-up trace on `def`, whose axis is at `x1` after its first following step (set-point
/// 0 → 1000) and at `x2` after the second (set-point standing at 1000).
fn power_up_trace_on(def: &DriveDefinition, x1: i32, x2: i32) {
    let mut r = Rig::new(def, &seed_axis());
    assert_eq!((r.a.output_len(), r.a.input_len()), (6, 16));
    let fb = r.cycle(&[]);
    // MDT: control word 0xE000 = drive on, enable, run | position command 0
    assert_eq!(r.mdt_hex(), "00 e0 | 00 00 00 00");
    // AT: the first frame carries nothing sampled yet: status 0 = not ready
    assert_eq!(
        r.at_hex(),
        "00 00 | 00 00 00 00 | 00 00 00 00 | 00 00 00 00 | 00 00"
    );
    assert_eq!(
        (fb.state, fb.operational),
        (PowerState::NotReadyToSwitchOn, false)
    );
    let fb = r.cycle(&[]);
    // AT of the drive's first step: status 0x4000 = ready for power-up | feedback 0 | distance 0
    // | value 0 | probe status 0
    assert_eq!(
        r.at_hex(),
        "00 40 | 00 00 00 00 | 00 00 00 00 | 00 00 00 00 | 00 00"
    );
    assert_eq!(
        (fb.state, fb.operational),
        (PowerState::SwitchOnDisabled, false)
    );
    r.cmd.target = 1000;
    let fb = r.cycle(&[]);
    // MDT: 0xE000 | position command 1000 = 0x3E8. The drive, in main power on since its second
    // step, takes drive on + enable with this MDT and follows at once (enable_delay_cycles = 0).
    assert_eq!(r.mdt_hex(), "00 e0 | e8 03 00 00");
    // AT of the second step: status 0x8000 = ready, main power on
    assert_eq!(
        r.at_hex(),
        "00 80 | 00 00 00 00 | 00 00 00 00 | 00 00 00 00 | 00 00"
    );
    assert_eq!(fb.state, PowerState::SwitchedOn);
    let fb = r.cycle(&[]);
    assert_eq!(r.mdt_hex(), "00 e0 | e8 03 00 00");
    // AT of the first following step: status 0xC008 = drive enabled, command values processed |
    // feedback x1 | distance 1000 − x1
    assert_eq!(
        r.at_hex(),
        format!(
            "08 c0 | {} | {} | 00 00 00 00 | 00 00",
            le(x1),
            le(1000 - x1)
        )
    );
    assert_eq!(
        (fb.state, fb.operational, fb.position),
        (PowerState::OperationEnabled, true, x1)
    );
    assert_eq!(fb.following_error, Some(1000 - x1));
    // Disable: control word 0.
    r.cmd.enable = false;
    let fb = r.cycle(&[]);
    assert_eq!(r.mdt_hex(), "00 00 | e8 03 00 00");
    // AT sampled before the drive saw control word 0: still following, feedback x2
    assert_eq!(
        r.at_hex(),
        format!(
            "08 c0 | {} | {} | 00 00 00 00 | 00 00",
            le(x2),
            le(1000 - x2)
        )
    );
    assert!(fb.operational);
    let fb = r.cycle(&[]);
    // AT: status 0x8000, feedback x2 held (power stage off at once), no following distance
    assert_eq!(
        r.at_hex(),
        format!("00 80 | {} | 00 00 00 00 | 00 00 00 00 | 00 00", le(x2))
    );
    assert!(!fb.operational);
}

#[test]
fn power_up_trace() {
    // The default drive (cascade with velocity and acceleration feed-forward): the set-point
    // step 0 → 1000 in one cycle demands a velocity step of 10⁶ inc/s, so the drive accelerates
    // at its torque limit S-0-0092 = 100 % = rated_acceleration 20 m/s² = 2·10⁸ inc/s² for the
    // whole cycle: x1 = a·T²/2 = 100. With the set-point standing, it brakes at the limit from
    // a·T: x2 = x1 + a·T² − a·T²/2 = 200, at rest.
    let def = catalogue::load("sercos-ax5000").unwrap();
    assert!(def.model.feed_forward);
    let a = def.model.rated_acceleration * def.scaling.increments_per_unit; // inc/s²
    let t = 1e-3;
    let x1 = a * t * t / 2.0;
    let x2 = x1 + a * t * t - a * t * t / 2.0;
    assert_eq!((x1.round(), x2.round()), (100.0, 200.0));
    power_up_trace_on(&def, x1.round() as i32, x2.round() as i32);

    // Without feed-forward (`[model] feed_forward = false`): the first-order loop
    // ẋ = kv·(r − x) with the command ramping 0 → 1000 over the cycle leaves e1 = (s/kv)·(1 −
    // e^(−kv·T)) = 980.3, x1 = 19.7; with the command standing e2 = e1·e^(−kv·T) = 941.8,
    // x2 = 58.2.
    let mut def = def;
    def.model.feed_forward = false;
    let kv = def.model.kv;
    let e1 = 1000.0 / t / kv * (1.0 - (-kv * t).exp());
    let e2 = e1 * (-kv * t).exp();
    let (x1, x2) = ((1000.0 - e1).round(), (1000.0 - e2).round());
    assert_eq!((x1, x2), (20.0, 58.0));
    power_up_trace_on(&def, x1 as i32, x2 as i32);
}

/// One configuration of the probe by real-time bits.
struct Case {
    rt: &'static str,
    p106: Option<&'static str>,
    probe: u8,
    edge: ProbeEdge,
    /// Drive IDNs (S-0-0169, 0301, 0303, 0305, 0307).
    idns: [(u16, i64); 5],
    at: &'static str,
    /// Control word mask of the enable bit, status word masks of done / activated.
    enable: u16,
    done: u16,
}

fn run_case(c: &Case) {
    let def = drive_with(
        "at = [\"S-0-0051\", \"S-0-0189\", \"S-0-0130\", \"S-0-0179\"]",
        c.at,
    );
    let mut p = vec![("P-AXIS-00060", c.rt)];
    if let Some(m) = c.p106 {
        p.push(("P-AXIS-00106", m));
    }
    let axis = params(&p);
    let mut r = Rig::new(&def, &axis);
    for (idn, v) in c.idns {
        r.m.write_object(idn, 0, v).unwrap();
    }
    r.power_up();
    r.cmd.target = 20_000;
    let input = c.probe;
    // Input level before the edge (a negative edge needs a high input).
    if c.edge == ProbeEdge::Negative {
        DriveModel::set_input_level(&mut r.m, input, true);
    }
    r.a.arm_probe(&request(c.probe, c.edge)).unwrap();
    assert_eq!(r.a.probe_state(), ProbeState::Arming);
    r.cycle(&[]);
    // Enable bit still 0 (clearing cycle); the AT shows 'done' clear (nothing latched since
    // power-up), so the next MDT sets the enable bit.
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("00 e0"));
    r.cycle(&[]);
    assert_eq!(r.a.probe_state(), ProbeState::Armed);
    let cw = u16::from_le_bytes([r.mdt[0], r.mdt[1]]);
    assert_eq!(cw, 0xE000 | c.enable, "enable bit written");
    // A wrong-edge signal first: nothing.
    let wrong = c.edge == ProbeEdge::Positive;
    if wrong {
        // Positive case: a negative edge needs the input high first; no edge from static level.
        DriveModel::set_input_level(&mut r.m, input, true);
        r.cycle(&[(input, false, 0.5)]);
        assert_eq!(r.a.take_probe_event(), None, "wrong edge latches nothing");
    }
    let rising = c.edge == ProbeEdge::Positive;
    let fb = r.cycle(&[(input, rising, 0.375)]);
    let expected = r.edge_pos.round() as i32;
    // This cycle's AT was sampled before the edge: 'done' clear, no event yet.
    assert_eq!(fb.statusword & c.done, 0, "{:04x}", fb.statusword);
    assert_eq!(r.a.take_probe_event(), None);
    // The next frame carries the latch.
    let fb = r.cycle(&[]);
    assert_ne!(
        fb.statusword & c.done,
        0,
        "done bit set: {:04x}",
        fb.statusword
    );
    let ev = r.a.take_probe_event().expect("one event");
    assert_eq!(
        (ev.probe, ev.edge, ev.position, ev.sequence),
        (c.probe, c.edge, expected, 1)
    );
    assert_ne!(
        ev.position, fb.position,
        "latched at the edge, not the cycle end"
    );
    // Second edge of the same kind: no capture until re-enabled.
    r.cycle(&[(input, !rising, 0.1)]);
    r.cycle(&[(input, rising, 0.5)]);
    assert_eq!(r.a.take_probe_event(), None);
}

#[test]
fn probe_every_rt_bit_setting_and_edge() {
    const AT_ALL: &str =
        "at = [\"S-0-0051\", \"S-0-0130\", \"S-0-0131\", \"S-0-0132\", \"S-0-0133\", \"S-0-0179\"]";
    // P-AXIS-00060 = 1, the seed's example: probe 1 positive.
    run_case(&Case {
        rt: "1",
        p106: None,
        probe: 1,
        edge: ProbeEdge::Positive,
        idns: [(169, 1), (301, 405), (303, 0), (305, 409), (307, 401)],
        at: AT_ALL,
        enable: 0x0040,
        done: 0x0040,
    });
    // P-AXIS-00060 = 1, probe 1 negative edge (S-0-0169 = 2 -> S-0-0131).
    run_case(&Case {
        rt: "1",
        p106: None,
        probe: 1,
        edge: ProbeEdge::Negative,
        idns: [(169, 2), (301, 405), (303, 0), (305, 410), (307, 401)],
        at: AT_ALL,
        enable: 0x0040,
        done: 0x0040,
    });
    // P-AXIS-00060 = 2: control bit 2, done = status bit 2, activated = status bit 1; probe 2
    // positive (S-0-0169 = 4 -> S-0-0132).
    run_case(&Case {
        rt: "2",
        p106: None,
        probe: 2,
        edge: ProbeEdge::Positive,
        idns: [(169, 4), (301, 0), (303, 406), (305, 402), (307, 411)],
        at: AT_ALL,
        enable: 0x0080,
        done: 0x0080,
    });
    // P-AXIS-00060 = 2, probe 2 negative (S-0-0169 = 8 -> S-0-0133), minimal AT.
    run_case(&Case {
        rt: "2",
        p106: None,
        probe: 2,
        edge: ProbeEdge::Negative,
        idns: [(169, 8), (301, 0), (303, 406), (305, 402), (307, 412)],
        at: "at = [\"S-0-0051\", \"S-0-0133\"]",
        enable: 0x0080,
        done: 0x0080,
    });
    // P-AXIS-00060 = 0 with P-AXIS-00106 = 0x0040 (status bit 1 = done).
    run_case(&Case {
        rt: "0",
        p106: Some("0x40"),
        probe: 1,
        edge: ProbeEdge::Positive,
        idns: [(169, 1), (301, 405), (303, 0), (305, 409), (307, 401)],
        at: AT_ALL,
        enable: 0x0040,
        done: 0x0040,
    });
}

#[test]
fn rearming_never_reports_the_stale_latch() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let mut r = Rig::new(&def, &seed_axis());
    r.power_up();
    r.cmd.target = 30_000;
    r.a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    r.cycle(&[]);
    r.cycle(&[]);
    assert_eq!(r.a.probe_state(), ProbeState::Armed);
    r.cycle(&[(1, true, 0.5)]);
    // Sampled before the edge: status 0xC008, S-0-0179 = 0.
    assert!(r.at_hex().starts_with("08 c0 |"), "{}", r.at_hex());
    assert!(r.at_hex().ends_with("| 00 00"), "{}", r.at_hex());
    assert_eq!(r.a.take_probe_event(), None);
    r.cycle(&[]);
    // AT: status 0xC0C8 = enabled, following, RT status bit 1 (S-0-0409 latched), RT status
    // bit 2 (S-0-0401 probe 1 input high) | … | S-0-0179 = 1
    assert!(r.at_hex().starts_with("c8 c0 |"), "{}", r.at_hex());
    assert!(r.at_hex().ends_with("| 01 00"), "{}", r.at_hex());
    let first = r.a.take_probe_event().unwrap();
    r.cycle(&[(1, false, 0.5)]);
    // Re-arm while the drive still shows the old latch.
    r.a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    let fb = r.cycle(&[]);
    // MDT: 0xE000, enable bit 1 cleared. The AT was sampled before the drive saw it: 'done'
    // (status bit 6) and S-0-0179 still set — the adapter keeps the bit cleared and waits.
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("00 e0"));
    assert_ne!(fb.statusword & 0x0040, 0);
    assert!(r.at_hex().ends_with("| 01 00"), "{}", r.at_hex());
    assert_eq!(r.a.take_probe_event(), None, "stale value never reported");
    let fb = r.cycle(&[]);
    // Still 0xE000; now the AT shows the drive cleared S-0-0179 on the falling enable bit.
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("00 e0"));
    assert_eq!(fb.statusword & 0x0040, 0);
    assert!(r.at_hex().ends_with("| 00 00"), "{}", r.at_hex());
    r.cycle(&[]);
    // MDT: 0xE040 = run + RT control bit 1 (probe 1 enable)
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("40 e0"));
    for _ in 0..5 {
        r.cycle(&[]);
    }
    assert_eq!(r.a.take_probe_event(), None, "stale value never reported");
    r.cycle(&[(1, true, 0.25)]);
    assert_eq!(r.a.take_probe_event(), None, "sampled before the edge");
    r.cycle(&[]);
    let second = r.a.take_probe_event().unwrap();
    assert_eq!(second.sequence, 1);
    assert_eq!(second.position, r.edge_pos.round() as i32);
    assert_ne!(first.position, second.position);
    // Disarm: enable bit 0, events dropped.
    r.a.disarm_probe();
    r.cycle(&[]);
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("00 e0"));
    assert_eq!(r.a.probe_state(), ProbeState::Idle);
}

#[test]
fn latch_never_comes_and_stuck_done_bit_fails() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let mut r = Rig::new(&def, &seed_axis());
    r.power_up();
    r.a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    for _ in 0..200 {
        r.cycle(&[]);
    }
    assert_eq!(r.a.probe_state(), ProbeState::Armed);
    assert_eq!(r.a.take_probe_event(), None);

    // A drive that keeps 'measurement done' (status bit 6) set: hand-made AT bytes.
    let mut a = SercosAdapter::new(&def, &seed_axis()).unwrap();
    let mut mdt = [0u8; 6];
    // AT: status 0xC048 | feedback 0 | distance 0 | S-0-0130 = 1234 | S-0-0179 = 1
    let at = [
        0x48, 0xC0, 0, 0, 0, 0, 0, 0, 0, 0, 0xD2, 0x04, 0, 0, 0x01, 0x00,
    ];
    a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    let cmd = DriveCommand {
        enable: true,
        ..DriveCommand::default()
    };
    for k in 0..=def.probe.arm_timeout_cycles {
        a.write_outputs(Nanos(u64::from(k)), &cmd, &mut mdt)
            .unwrap();
        // MDT: 0xE000, the enable bit stays 0 while 'done' is still set
        assert_eq!(mdt[..2], [0x00, 0xE0]);
        a.read_inputs(Nanos(u64::from(k)), &at).unwrap();
        assert_eq!(a.take_probe_event(), None, "stale 1234 never reported");
    }
    match a.probe_state() {
        ProbeState::Failed(m) => assert!(m.contains("stays set"), "{m}"),
        s => panic!("{s:?}"),
    }
    // Short AT image: an error, not a panic.
    assert!(a.read_inputs(Nanos(0), &at[..3]).is_err());
}

/// Press the axis of `def` against a wall at 5000 (set-point 200000) with S-0-0092 = 10 %, then
/// raise S-0-0092 to 100 % for one cycle: the torque feedback S-0-0084 in both.
fn press_against_a_wall(def: &DriveDefinition) -> (i64, i64) {
    let mut r = Rig::new(def, &seed_axis());
    r.power_up();
    assert_eq!(r.m.read_object(92, 0), Ok(1000));
    r.m.write_object(92, 0, 100).unwrap();
    assert_eq!(r.m.write_object(92, 0, 65536), Err(abort::VALUE_RANGE));
    DriveModel::set_fixed_stop(&mut r.m, Some(5_000.0));
    r.cmd.target = 200_000;
    for _ in 0..50 {
        r.cycle(&[]);
    }
    // Pressed against the wall: feedback at the wall.
    assert_eq!(r.m.read_object(51, 0), Ok(5_000));
    let clipped = r.m.read_object(84, 0).unwrap();
    r.m.write_object(92, 0, 1000).unwrap();
    r.cycle(&[]);
    assert_eq!(r.m.read_object(51, 0), Ok(5_000));
    (clipped, r.m.read_object(84, 0).unwrap())
}

#[test]
fn torque_limit_s_0_0092_clips_torque() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let f = def.function("TORQUE_LIMIT").unwrap();
    assert_eq!((f.index, f.sub, f.encode(10.0)), (92, 0, Some(100)));
    assert_eq!(
        f.encode(500.0),
        Some(5000),
        "the seed's CANopen 'off' value is accepted"
    );
    // Without feed-forward (`[model] feed_forward = false`) the torque demand is the lag ×
    // torque_per_increment: at S-0-0092 = 10 % it is clipped to 100; at the full limit the
    // demand (195000 × 0.004 = 780) is below 100 %.
    let mut first_order = def.clone();
    first_order.model.feed_forward = false;
    assert_eq!(press_against_a_wall(&first_order), (100, 780));
    // With feed-forward (the default) the stalled axis makes the speed loop demand ever more
    // acceleration: the torque sits at the limit, 10 % and then 100 %.
    assert!(def.model.feed_forward);
    assert_eq!(press_against_a_wall(&def), (100, 1000));
}

#[test]
fn monitoring_window_s_0_0159() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let i = def.idn("S-0-159").unwrap();
    assert_eq!(
        (i.index, i.encode(0)),
        (159, Some(0)),
        "0 = off, written natively"
    );
    let mw = def.function("MON_WINDOW").unwrap();
    assert_eq!(mw.encode(4294967295.0), Some(4294967295));
    for (window, trips) in [(0i64, false), (4294967295, false), (1000, true)] {
        let mut r = Rig::new(&def, &seed_axis());
        r.power_up();
        r.m.write_object(159, 0, window).unwrap();
        assert_eq!(r.m.read_object(159, 0), Ok(window));
        DriveModel::set_disturbance(&mut r.m, 2000.0);
        // The drive monitors (and faults) at its next step; this cycle's AT was sampled before.
        assert!(!r.cycle(&[]).fault, "window {window}");
        let fb = r.cycle(&[]);
        assert_eq!(fb.fault, trips, "window {window}");
        if trips {
            // AT: status 0x6000 = error (C1D) + ready for power-up (power stage off)
            assert!(r.at_hex().starts_with("00 60 |"), "{}", r.at_hex());
            assert_eq!(r.m.read_object(11, 0), Ok(0x0800));
            assert_eq!(DriveModel::last_error_code(&r.m), 0x0800);
        }
    }
    assert_eq!(
        SercosModel::new(&def).unwrap().write_object(159, 0, -1),
        Err(abort::VALUE_RANGE)
    );
}

#[test]
fn drive_error_and_reset() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let mut r = Rig::new(&def, &seed_axis());
    r.power_up();
    DriveModel::inject_fault(&mut r.m, 0x0002);
    // The drive faults at its next step; this cycle's AT was sampled before.
    assert!(r.cycle(&[]).operational);
    let fb = r.cycle(&[]);
    assert!(fb.fault && !fb.operational);
    assert_eq!(fb.state, PowerState::Fault);
    // Still enabled: the error stays.
    assert!(r.cycle(&[]).fault);
    // Fault reset: control word 0 for a cycle, then the rising edge of bit 15 clears C1D.
    r.cmd.fault_reset = true;
    assert!(r.cycle(&[]).fault);
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("00 00"));
    r.cmd.fault_reset = false;
    // 0xE000 again: the drive clears C1D on the rising bit 15 and, drive on + enable set,
    // enables in the same step; this AT was sampled before it saw the edge.
    let fb = r.cycle(&[]);
    assert_eq!(r.mdt_hex().split(" | ").next(), Some("00 e0"));
    assert!(fb.fault);
    let fb = r.cycle(&[]);
    assert!(!fb.fault && fb.operational);
    assert_eq!(
        r.m.read_object(11, 0),
        Ok(2),
        "S-0-0011 keeps the last diagnostic"
    );
    // Read-only / unknown IDNs.
    assert_eq!(r.m.write_object(51, 0, 1), Err(abort::READ_ONLY));
    assert_eq!(r.m.read_object(4000, 0), Err(abort::NO_OBJECT));
    assert_eq!(r.m.read_object(51, 1), Err(abort::NO_SUB_INDEX));
    // Garbage MDT of the wrong length: ignored, no panic.
    r.m.begin_step(Nanos(1), 1e-3, &[1, 2, 3]);
    assert_eq!(r.m.rx_length_errors(), 1);
}

#[test]
fn inconsistent_configuration_is_refused_in_words() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let e = adapter_for(&def, &params(&[("P-AXIS-00060", "0")])).unwrap_err();
    assert!(e.to_string().contains("P-AXIS-00106 is not set"), "{e}");
    let e = adapter_for(
        &def,
        &params(&[("P-AXIS-00060", "0"), ("P-AXIS-00106", "0x80")]),
    )
    .unwrap_err();
    assert!(e.to_string().contains("already uses"), "{e}");
    // Default (no P-AXIS-00060 in the list): the file's echtzeit_bit_nr = 1.
    let mut a = adapter_for(&def, &ParamSet::new(Scope::Axis)).unwrap();
    // Negative edge needs S-0-0131, the AT carries S-0-0130 only.
    let e = a.arm_probe(&request(1, ProbeEdge::Negative)).unwrap_err();
    assert!(
        e.to_string()
            .contains("needs S-0-0169 = 2 and its value S-0-0131 in the cyclic AT"),
        "{e}"
    );
    let mut cont = request(1, ProbeEdge::Positive);
    cont.continuous = true;
    assert!(a.arm_probe(&cont).is_err());
    // Drive file errors name file, line, key and the allowed values.
    let text = def.source.replace("\"S-0-0189\",", "\"S-0-0047\",");
    let bad = catalogue::parse(&text, "bad.toml").unwrap();
    let e = SercosModel::new(&bad).unwrap_err().to_string();
    assert!(
        e.starts_with("bad.toml:") && e.contains("S-0-0047 cannot be in the AT"),
        "{e}"
    );
    let text = def
        .source
        .replace("echtzeit_bit_nr = 1", "echtzeit_bit_nr = 5");
    let e = adapter_for(
        &catalogue::parse(&text, "bad.toml").unwrap(),
        &ParamSet::new(Scope::Axis),
    )
    .unwrap_err()
    .to_string();
    let line = text
        .lines()
        .position(|l| l.starts_with("echtzeit_bit_nr"))
        .unwrap()
        + 1;
    assert!(
        e.starts_with(&format!("bad.toml:{line}: ")) && e.contains("0, 1 or 2"),
        "{e}"
    );
    let text = def
        .source
        .replace("echtzeit_bit_nr = 1", "echtzeit_bit = 1");
    let e = SercosModel::new(&catalogue::parse(&text, "bad.toml").unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown key `echtzeit_bit`") && e.contains("allowed: mdt, at"),
        "{e}"
    );
}

#[test]
fn commissioning_check_on_the_seed_example_and_wrong_settings() {
    let def = catalogue::load("sercos-ax5000").unwrap();
    let mut m = SercosModel::new(&def).unwrap();
    let axis = seed_axis();
    let check = |m: &SercosModel, axis: &ParamSet| {
        commissioning_check(&def, axis, &|i| m.read_object(i, 0).ok())
    };
    assert_eq!(check(&m, &axis), Vec::<String>::new());
    m.write_object(305, 0, 410).unwrap();
    assert_eq!(
        check(&m, &axis),
        vec!["P-AXIS-00060 = 1 expects real-time status bit 1 to signal 'probe 1 positive edge latched' (S-0-0305 = 409), but the drive has S-0-0305 = 410".to_string()]
    );
    m.write_object(305, 0, 409).unwrap();
    // Negative edge in the axis: S-0-0169, S-0-0305 and the AT value all disagree.
    let neg = params(&[
        ("P-AXIS-00060", "1"),
        ("P-AXIS-00516", "DRIVE"),
        ("P-AXIS-00518", "NEG"),
    ]);
    let f = check(&m, &neg);
    assert_eq!(f.len(), 3, "{f:#?}");
    assert!(f[0].contains("(S-0-0305 = 410), but the drive has S-0-0305 = 409"));
    assert!(
        f[1].contains("need S-0-0169 = 2 (probe 1 negative edge), but the drive has S-0-0169 = 1")
    );
    assert!(f[2].contains("S-0-0131, but the cyclic AT"));
    // P-AXIS-00060 = 2 against the seed's drive settings (bit 1 allocations).
    let f = check(
        &m,
        &params(&[("P-AXIS-00060", "2"), ("P-AXIS-00516", "DRIVE")]),
    );
    assert_eq!(f.len(), 3, "{f:#?}");
    assert!(f[0].starts_with("P-AXIS-00060 = 2 expects real-time control bit 2 to signal 'probe 1 enable' (S-0-0303 = 405), but the drive has S-0-0303 = 0"));
    // Wrong measuring method and unreadable IDNs.
    let f = commissioning_check(&def, &params(&[("P-AXIS-00516", "PLC")]), &|_| None);
    assert!(f[0].starts_with("P-AXIS-00516 = PLC"), "{f:#?}");
    assert!(f.iter().any(|s| s.contains("S-0-0169 cannot be read")));
}

const SEED_MEAS1: [&str; 9] = [
    "V.A.MESS.Z=100.000000",
    "V.A.MEAS.ACS.VALUE.Z=100.000000",
    "V.A.MEAS.PCS.VALUE.Z=100.000000",
    "V.A.MOFFS.Z=80.000000",
    "V.A.MEIN.Z=1.000000",
    "V.A.MEIN.Z=1.000000",
    "V.A.ABS.Z=180.000000",
    "V.A.MEIN.Z=1.000000",
    "V.A.ABS.Z=100.000000",
];

fn meas1(drive: &str) -> Vec<String> {
    let toml = format!(
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\n\
         [[axis]]\nname = \"Z\"\ndrive = \"{drive}\"\nkenngr.messachse = 1\n"
    );
    let cfg = MachineConfig::parse(&toml, "sercos-machine.toml").unwrap();
    let mut m = Machine::new(&cfg).unwrap();
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
    r.output().into_iter().map(String::from).collect()
}

#[test]
fn meas1_end_to_end_matches_the_cia402_default() {
    let cia = meas1("cia402-generic");
    let sercos = meas1("sercos-ax5000");
    assert_eq!(sercos, cia);
    assert_eq!(sercos[0], SEED_MEAS1[0]);
    assert_eq!(sercos[3], SEED_MEAS1[3]);
    assert_eq!(sercos[6], SEED_MEAS1[6]);
    assert_eq!(sercos.len(), SEED_MEAS1.len(), "{sercos:#?}");
}
