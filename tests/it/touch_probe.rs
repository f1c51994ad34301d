//! CiA 402 touch probe end to end: [`Ds402Adapter`] (master) ↔ [`SimLink`] with
//! [`Ds402Model`]s (drives) and a [`Plant`] (probe surfaces, fixed stops).
//!
//! Expected values come from closed-form formulas in this file, not from the code under test:
//! a drive without feed-forward ([`first_order`], `[model] feed_forward = false`) at rest at
//! `xs` whose set-point then ramps with speed `v` (increments/s, exactly `vT` increments per
//! cycle) follows the first-order loop `ẋ = kv·(r − x)`:
//! `x(τ) = xs + v·τ − (v/kv)·(1 − e^(−kv·τ))`, τ = time since the ramp began. The default drive
//! (servo cascade with velocity and acceleration feed-forward) has no such closed form at the
//! start of a ramp; its latches are checked against the surface position and against the
//! drive's own trajectory at the plant's edge time, recorded as the edge happens.
//!
//! Bus timing (`SimLink`, as every link): the image an exchange returns was sampled by the drive
//! at the exchange before, so a latch (or a fault) reaches the adapter one exchange after the
//! step it happened in, and a 0x60B8 word written after exchange k shows in 0x60B9 at exchange
//! k + 2. The set-point path is not delayed: a target written after exchange k is the drive's
//! set-point for the cycle ending at exchange k + 1.

use fieldprobe::drive::catalogue::{self, DriveDefinition};
use fieldprobe::drive::ds402::{touch_probe_byte, touch_probe_function, Ds402Adapter};
use fieldprobe::drive::model::ds402::Ds402Model;
use fieldprobe::drive::pdo::PdoLayout;
use fieldprobe::drive::{
    DriveAdapter, DriveCommand, DriveFeedback, PowerState, ProbeEdge, ProbeEvent, ProbeRequest,
    ProbeState, ProbeTrigger, TriggerSourceMode,
};
use fieldprobe::link::sim::SimLink;
use fieldprobe::link::{Link, LinkError, ProcessImage};
use fieldprobe::sim::plant::{FixedStop, Plant, ProbeEdgeEvent, ProbeSurface};
use fieldprobe::units::Nanos;
use proptest::prelude::*;

const MS: u64 = 1_000_000;

fn generic() -> DriveDefinition {
    catalogue::builtin("cia402-generic").expect("built-in drive")
}

/// The generic drive without feed-forward (`[model] feed_forward = false`): the first-order
/// loop of the closed forms in this file, torque = lag × `torque_per_increment`.
fn first_order(mut def: DriveDefinition) -> DriveDefinition {
    def.model.feed_forward = false;
    def
}

/// The generic drive with the edge counters 0x60D5..0x60D8 in the TxPDO.
fn with_counters(mut def: DriveDefinition) -> DriveDefinition {
    let mut entries: Vec<String> = def
        .txpdo
        .entries()
        .iter()
        .map(|e| format!("0x{:04X}:{:02X}", e.index, e.sub))
        .collect();
    entries.extend(["0x60D5:00", "0x60D6:00", "0x60D7:00", "0x60D8:00"].map(String::from));
    def.txpdo = PdoLayout::parse(&entries).unwrap();
    def
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

/// Drives on a `SimLink`, each with its adapter, cycled like the machine does: `now` advances,
/// the exchange at `now` moves the drives over `[now − cycle, now]`, the adapters decode the
/// inputs and write the targets for `now + cycle`.
struct Bench {
    link: SimLink,
    adapters: Vec<Ds402Adapter>,
    images: Vec<ProcessImage>,
    now: Nanos,
    cycle: Nanos,
    targets: Vec<i32>,
    feedback: Vec<Option<DriveFeedback>>,
    /// Plant edges of every cycle so far.
    edges: Vec<ProbeEdgeEvent>,
    /// Every plant edge with each axis's actual position at its time (read from the drive's
    /// trajectory of the cycle the edge fell in, right after that cycle).
    edge_positions: Vec<(ProbeEdgeEvent, Vec<Option<f64>>)>,
}

impl Bench {
    fn new(defs: &[DriveDefinition], cycle: Nanos, plant: Plant) -> Bench {
        let models = defs.iter().map(Ds402Model::new).collect();
        let adapters: Vec<Ds402Adapter> =
            defs.iter().map(|d| Ds402Adapter::new(d).unwrap()).collect();
        let images = adapters
            .iter()
            .map(|a| ProcessImage::new(a.output_len(), a.input_len()))
            .collect();
        Bench {
            link: SimLink::with_plant(models, cycle, plant),
            adapters,
            images,
            now: Nanos::ZERO,
            cycle,
            targets: vec![0; defs.len()],
            feedback: vec![None; defs.len()],
            edges: Vec::new(),
            edge_positions: Vec::new(),
        }
    }

    /// Put axis `i` at rest at `x` increments.
    fn place(&mut self, i: usize, x: i32) {
        self.link.model_mut(i).unwrap().set_actual(f64::from(x));
        self.targets[i] = x;
    }

    /// One cycle; `target(i, t)` is axis i's set-point for the end of the next cycle `t`.
    #[track_caller]
    fn step_with(&mut self, target: &dyn Fn(usize, Nanos) -> Option<i32>) {
        self.now = self.now.saturating_add(self.cycle);
        self.link
            .exchange(self.now, &mut self.images)
            .expect("exchange");
        self.edges.extend_from_slice(self.link.plant().last_edges());
        for &e in self.link.plant().last_edges() {
            let at: Vec<Option<f64>> = self
                .link
                .models()
                .iter()
                .map(|m| m.position_at(e.at))
                .collect();
            self.edge_positions.push((e, at));
        }
        let next = self.now.saturating_add(self.cycle);
        for i in 0..self.adapters.len() {
            let fb = self.adapters[i]
                .read_inputs(self.now, &self.images[i].inputs)
                .expect("inputs");
            self.feedback[i] = Some(fb);
            if let Some(t) = target(i, next) {
                self.targets[i] = t;
            }
            let cmd = DriveCommand {
                enable: true,
                target: self.targets[i],
                ..Default::default()
            };
            self.adapters[i]
                .write_outputs(self.now, &cmd, &mut self.images[i].outputs)
                .expect("outputs");
        }
    }

    #[track_caller]
    fn step(&mut self) {
        self.step_with(&|_, _| None);
    }

    #[track_caller]
    fn run(&mut self, cycles: usize, target: &dyn Fn(usize, Nanos) -> Option<i32>) {
        for _ in 0..cycles {
            self.step_with(target);
        }
    }

    fn fb(&self, i: usize) -> DriveFeedback {
        self.feedback[i].expect("a cycle ran")
    }

    /// Power up every drive (operation enabled, CSP).
    #[track_caller]
    fn enable(&mut self) {
        for _ in 0..10 {
            self.step();
        }
        for i in 0..self.adapters.len() {
            assert!(self.fb(i).operational, "axis {i}: {:?}", self.fb(i).state);
        }
    }

    /// Arm and cycle at rest until every listed axis confirms (from idle the adapter writes the
    /// function at once; the image after it was sampled before the drive saw it, the next one
    /// confirms: 3 cycles).
    #[track_caller]
    fn arm(&mut self, axes: &[usize], req: &ProbeRequest) {
        for &i in axes {
            self.adapters[i].arm_probe(req).expect("arm");
            assert_eq!(self.adapters[i].probe_state(), ProbeState::Arming);
        }
        for _ in 0..5 {
            self.step();
        }
        for &i in axes {
            assert_eq!(
                self.adapters[i].probe_state(),
                ProbeState::Armed,
                "axis {i}"
            );
        }
    }

    fn events(&mut self, i: usize) -> Vec<ProbeEvent> {
        std::iter::from_fn(|| self.adapters[i].take_probe_event()).collect()
    }

    fn rising_edges(&self) -> usize {
        self.edges.iter().filter(|e| e.rising).count()
    }
}

/// Closed-form position of an axis at rest at `xs` whose ramp with `v` inc/s began at `t0`.
fn ramp_position(xs: f64, v: f64, kv: f64, t0: Nanos, t: Nanos) -> f64 {
    if t <= t0 {
        return xs;
    }
    let tau = (t.0 - t0.0) as f64 * 1e-9;
    xs + v * tau - v / kv * (1.0 - (-kv * tau).exp())
}

/// Set-point of that ramp for time `t` (a cycle boundary): exact integers.
fn ramp_target(xs: i32, per_cycle: i64, cycle: Nanos, t0: Nanos, t: Nanos) -> i32 {
    let k = t.0.saturating_sub(t0.0) / cycle.0;
    (i64::from(xs) + per_cycle * k as i64) as i32
}

/// Time at which the monotonic closed-form ramp reaches `p` (bisection to 0.01 ns).
fn crossing_time(xs: f64, v: f64, kv: f64, t0: Nanos, p: f64) -> f64 {
    let x = |t: f64| {
        let tau = t - t0.0 as f64;
        xs + v * tau * 1e-9 - v / kv * (1.0 - (-kv * tau * 1e-9).exp())
    };
    let (mut lo, mut hi) = (t0.0 as f64, t0.0 as f64 + 1e12);
    let up = v > 0.0;
    while hi - lo > 0.01 {
        let mid = 0.5 * (lo + hi);
        if (x(mid) < p) == up {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Increments per cycle of a feed in mm/min at 10000 inc/mm; must be a whole number.
fn per_cycle(feed_mm_min: i64, cycle: Nanos) -> i64 {
    let num = feed_mm_min * 10_000 * cycle.0 as i64;
    let den = 60 * 1_000_000_000;
    assert_eq!(
        num % den,
        0,
        "feed {feed_mm_min} mm/min is not whole increments per cycle"
    );
    num / den
}

// ---------------------------------------------------------------------------------------------
// (a) accuracy sweep
// ---------------------------------------------------------------------------------------------

/// The probed axis latches the trigger position and a second axis moving at the same time
/// latches its own true position at the crossing time, both within 1 increment (0.1 µm), for
/// feeds up to 10 m/min and several trigger positions. On a drive without feed-forward the true
/// position and the crossing time are the closed forms; on the default drive the true position
/// is the drive's trajectory at the plant's edge time, and the probed axis's trajectory passes
/// the surface at that time.
fn latch_accuracy_sweep_on(def: &DriveDefinition) {
    let kv = def.model.kv;
    let closed_form = !def.model.feed_forward;
    let sweeps: [(Nanos, &[i64]); 2] = [
        (Nanos(MS), &[60, 600, 1200, 3000, 6000, 9996]),
        (Nanos(600_000), &[100, 2500, 10_000]),
    ];
    let mut runs = 0;
    for (cycle, feeds) in sweeps {
        for &feed in feeds {
            for (k, frac) in [(3, 0.0), (57, 0.31), (180, 0.77)] {
                let v_cyc = per_cycle(feed, cycle);
                // The second axis runs at one of three feeds, either direction.
                let feed1: i64 = [-3000, 1200, -6000][runs % 3];
                let v1_cyc = feed1.signum() * per_cycle(feed1.abs(), cycle);
                let (xs0, xs1) = (1_234, 2_000_000);
                let p = f64::from(xs0) + v_cyc as f64 * (k as f64 + frac);

                let mut plant = Plant::new();
                plant.add_probe_surface(ProbeSurface::new(0, p, vec![(0, 1), (1, 1)]));
                let mut b = Bench::new(&[def.clone(), def.clone()], cycle, plant);
                b.place(0, xs0);
                b.place(1, xs1);
                b.enable();
                b.arm(&[0, 1], &request(1, ProbeEdge::Positive));
                // The image written last still holds the rest target, so the first ramp cycle
                // is the one after the next exchange.
                let t0 = b.now.saturating_add(cycle);
                // The second axis starts one cycle later, so its position at the crossing is
                // not a whole multiple of the first axis's travel.
                let t1 = t0.saturating_add(cycle);
                let target = |i: usize, t: Nanos| {
                    Some(match i {
                        0 => ramp_target(xs0, v_cyc, cycle, t0, t),
                        _ => ramp_target(xs1, v1_cyc, cycle, t1, t),
                    })
                };
                b.run(k + 100, &target);

                let what = format!(
                    "feed-forward {} cycle {} feed {feed} p {p}",
                    def.model.feed_forward, cycle.0
                );
                let e0 = b.events(0);
                let e1 = b.events(1);
                assert_eq!(e0.len(), 1, "{what}: {e0:?}");
                assert_eq!(e1.len(), 1, "{what}: {e1:?}");
                assert_eq!(
                    (e0[0].probe, e0[0].edge, e0[0].sequence),
                    (1, ProbeEdge::Positive, 1)
                );
                assert!(
                    (f64::from(e0[0].position) - p).abs() <= 1.0,
                    "{what}: probed axis latched {} for surface {p}",
                    e0[0].position
                );
                let (edge, at) = b
                    .edge_positions
                    .iter()
                    .find(|(e, _)| e.rising)
                    .cloned()
                    .expect("contact edge");
                let (x0, x1) = (at[0].unwrap(), at[1].unwrap());
                if closed_form {
                    let v0 = v_cyc as f64 * 1e9 / cycle.0 as f64;
                    let v1 = v1_cyc as f64 * 1e9 / cycle.0 as f64;
                    let tc = crossing_time(f64::from(xs0), v0, kv, t0, p);
                    let x1 = ramp_position(f64::from(xs1), v1, kv, t1, Nanos(tc.round() as u64));
                    assert!(
                        (f64::from(e1[0].position) - x1).abs() <= 1.0,
                        "{what}: second axis latched {}, true position {x1} at {tc} ns",
                        e1[0].position
                    );
                    // The plant saw the crossing where the closed form puts it (±1 µs).
                    assert!(
                        (edge.at.0 as f64 - tc).abs() < 1_000.0,
                        "{what}: {edge:?} vs {tc}"
                    );
                } else {
                    assert!(
                        (f64::from(e1[0].position) - x1).abs() <= 1.0,
                        "{what}: second axis latched {}, its trajectory at {edge:?}: {x1}",
                        e1[0].position
                    );
                }
                // Either way the plant's edge is where the probed axis passes the surface (the
                // edge time is whole nanoseconds: below 0.002 increments at 10 m/min).
                assert!(
                    (x0 - p).abs() < 0.01,
                    "{what}: {edge:?} at {x0}, surface {p}"
                );
                runs += 1;
            }
        }
    }
    assert_eq!(runs, 27);
}

#[test]
fn latch_accuracy_sweep() {
    latch_accuracy_sweep_on(&first_order(generic()));
}

#[test]
fn latch_accuracy_sweep_with_feed_forward() {
    let def = generic();
    assert!(def.model.feed_forward);
    latch_accuracy_sweep_on(&def);
}

// ---------------------------------------------------------------------------------------------
// (b) first event vs continuous, loss detection
// ---------------------------------------------------------------------------------------------

/// Targets per cycle: rest, up to `top`, dwell, down to 0, dwell, up to `top`, dwell
/// (`step` increments per cycle): three crossings of any surface in (0, top).
fn back_and_forth(step: i32, top: i32, dwell: usize) -> Vec<i32> {
    let mut t = vec![0; dwell];
    let ramp = |t: &mut Vec<i32>, from: i32, to: i32| {
        let mut x = from;
        while x != to {
            x = if to > x {
                (x + step).min(to)
            } else {
                (x - step).max(to)
            };
            t.push(x);
        }
    };
    ramp(&mut t, 0, top);
    t.extend(std::iter::repeat_n(top, dwell));
    ramp(&mut t, top, 0);
    t.extend(std::iter::repeat_n(0, dwell));
    ramp(&mut t, 0, top);
    t.extend(std::iter::repeat_n(top, dwell));
    t
}

fn run_profile(b: &mut Bench, profile: &[i32]) {
    for &x in profile {
        b.step_with(&|_, _| Some(x));
    }
}

#[test]
fn first_event_once_continuous_every_crossing() {
    let p = 55_555.0;
    let profile = back_and_forth(500, 100_000, 200);
    for (def, continuous, expected) in [
        (generic(), false, 1),
        (generic(), true, 3),
        (with_counters(generic()), true, 3),
    ] {
        let mut plant = Plant::new();
        plant.add_probe_surface(ProbeSurface::new(0, p, vec![(0, 1)]));
        let mut b = Bench::new(&[def], Nanos(MS), plant);
        b.enable();
        b.arm(
            &[0],
            &ProbeRequest {
                continuous,
                ..request(1, ProbeEdge::Positive)
            },
        );
        run_profile(&mut b, &profile);
        // By construction the axis passes the surface three times, far apart.
        assert_eq!(b.rising_edges(), 3);
        let events = b.events(0);
        assert_eq!(
            events.len(),
            expected,
            "continuous {continuous}: {events:?}"
        );
        for (n, e) in events.iter().enumerate() {
            assert_eq!(e.sequence, n as u32 + 1, "no loss, no duplicate");
            assert!((f64::from(e.position) - p).abs() <= 1.0, "{e:?}");
        }
        assert_eq!(b.adapters[0].probe_state(), ProbeState::Armed);
    }
}

/// A drive without feed-forward with kv = 1000 1/s, no speed limit: the set-point 0 → 1000 →
/// −86 makes the axis overshoot and come back within one 1 ms cycle. With x = r − e,
/// e = s/kv + (e₀ − s/kv)e^(−kv t): cycle 1 ends at 367.9 inc (e₀ = 632.1); cycle 2
/// (s = −1.086e6 inc/s) peaks at 501.7 inc at 0.459 ms and ends at 367.9 again, so a surface at
/// 400 is crossed up at ≈ 0.055 ms and down at ≈ 0.93 ms of that cycle.
fn fast_drive(counters: bool) -> DriveDefinition {
    let mut def = first_order(generic());
    def.model.kv = 1000.0;
    def.model.max_velocity = None;
    if counters {
        with_counters(def)
    } else {
        def
    }
}

fn two_crossings_in_one_cycle(def: DriveDefinition) -> Bench {
    let mut plant = Plant::new();
    let mut s = ProbeSurface::new(0, 400.0, vec![(0, 1)]);
    s.pulse = Nanos(100_000);
    plant.add_probe_surface(s);
    let mut b = Bench::new(&[def], Nanos(MS), plant);
    b.enable();
    b.arm(
        &[0],
        &ProbeRequest {
            continuous: true,
            ..request(1, ProbeEdge::Positive)
        },
    );
    b.step_with(&|_, _| Some(1000));
    b.step_with(&|_, _| Some(-86)); // moves 0 -> 1000 (cycle 1)
    assert!(b.edges.is_empty(), "cycle 1 stays below the surface");
    b.step(); // moves 1000 -> -86 (cycle 2)
    let rising: Vec<Nanos> = b.edges.iter().filter(|e| e.rising).map(|e| e.at).collect();
    assert_eq!(rising.len(), 2, "{:?}", b.edges);
    let cycle_start = b.now.0 - MS;
    assert!(
        rising.iter().all(|t| t.0 > cycle_start && t.0 < b.now.0),
        "{rising:?}"
    );
    // The image of that cycle was sampled before the crossings: nothing yet.
    assert!(b.events(0).is_empty());
    assert_eq!(b.adapters[0].probe_state(), ProbeState::Armed);
    // The next exchange delivers the drive's image with the two latches (settling towards
    // −86 from 367.9, the axis stays below the surface).
    b.step();
    assert_eq!(b.rising_edges(), 2, "{:?}", b.edges);
    b
}

#[test]
fn two_crossings_in_one_cycle_are_a_loss_with_counters() {
    let mut b = two_crossings_in_one_cycle(fast_drive(true));
    // The counter jumped by 2: one latch lost; the value in 0x60BA is the second one, reported
    // once with the gap in `sequence`.
    let events = b.events(0);
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0].sequence, 2);
    assert!((f64::from(events[0].position) - 400.0).abs() <= 1.0);
    match b.adapters[0].probe_state() {
        ProbeState::Failed(why) => assert!(why.contains("lost 1"), "{why}"),
        other => panic!("{other:?}"),
    }
    // Nothing is reported again.
    for _ in 0..20 {
        b.step();
    }
    assert!(b.events(0).is_empty());
}

#[test]
fn two_crossings_in_the_first_cycle_without_counters_fail_on_the_toggle_check() {
    let mut b = two_crossings_in_one_cycle(fast_drive(false));
    assert!(b.events(0).is_empty());
    match b.adapters[0].probe_state() {
        ProbeState::Failed(why) => assert!(why.contains("without a toggle"), "{why}"),
        other => panic!("{other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// (c) re-arming
// ---------------------------------------------------------------------------------------------

/// After a latch, re-arming never reports the old value; the next crossing gives the new one.
fn rearm_case(def: DriveDefinition, expect_words: &[u16]) {
    let (p1, p2) = (20_000.0, 60_000.0);
    let mut plant = Plant::new();
    plant.add_probe_surface(ProbeSurface::new(0, p1, vec![(0, 1)]));
    let mut b = Bench::new(&[def], Nanos(MS), plant);
    b.enable();
    let req = request(1, ProbeEdge::Positive);
    b.arm(&[0], &req);
    // Up at 1000 inc per cycle to 40000, through p1.
    let start = b.now;
    b.run(100, &|_, t| {
        Some((((t.0 - start.0) / MS) as i32 * 1000).min(40_000))
    });
    let first = b.events(0);
    assert_eq!(first.len(), 1);
    assert!((f64::from(first[0].position) - p1).abs() <= 1.0);

    // Move the surface, then re-arm: the stored 0x60BA = p1 must not come back as an event.
    b.link.plant_mut().probe_surfaces_mut()[0].position = p2;
    b.adapters[0].arm_probe(&req).unwrap();
    let mut words = Vec::new();
    for _ in 0..6 {
        b.step();
        words.push(b.adapters[0].probe_function_word());
        assert!(
            b.events(0).is_empty(),
            "stale value reported: words {words:x?}"
        );
    }
    assert_eq!(&words[..expect_words.len()], expect_words, "{words:x?}");
    assert_eq!(b.adapters[0].probe_state(), ProbeState::Armed);
    let start = b.now;
    let from = |_: usize, t: Nanos| Some(40_000 + ((t.0 - start.0) / MS) as i32 * 1000);
    b.run(60, &from);
    let second = b.events(0);
    assert_eq!(second.len(), 1, "{second:?}");
    assert_eq!(second[0].sequence, 1);
    assert!(
        (f64::from(second[0].position) - p2).abs() <= 1.0,
        "{second:?}"
    );
}

#[test]
fn rearm_after_a_latch_never_reports_the_old_value() {
    // Enabled in 0x60B9: 0 first — twice, as the image after the first 0 was sampled before the
    // drive saw it and still shows the probe enabled with the old latch —, then the function
    // once the drive shows it disabled.
    rearm_case(generic(), &[0x0000, 0x0000, 0x0011, 0x0011]);
}

#[test]
fn drive_that_needs_zero_before_rearming() {
    let mut def = generic();
    def.probe.rearm_requires_zero = true;
    // After its single shot this drive already reports the probe disabled (0x60B9 = 0x0002),
    // so the image after the first 0 — sampled before the drive saw the 0 — shows it disabled
    // and the adapter writes the function next: the drive takes 0 for one cycle, then the
    // function (its 0 → 1 edge re-arms it). The image after the function was sampled while the
    // drive held 0, so it is confirmed one cycle later.
    rearm_case(def.clone(), &[0x0000, 0x0011, 0x0011, 0x0011]);

    // The drive side of the option: after the single shot it reports the probe disabled, and
    // writing the same word again does not re-arm it.
    let mut plant = Plant::new();
    plant.add_probe_surface(ProbeSurface::new(0, 5_000.0, vec![(0, 1)]));
    let mut b = Bench::new(&[def.clone()], Nanos(MS), plant);
    b.enable();
    // Even from idle (word 0, probe disabled) the adapter writes 0 once more and waits for an
    // image showing the probe disabled.
    b.adapters[0]
        .arm_probe(&request(1, ProbeEdge::Positive))
        .unwrap();
    b.step();
    assert_eq!(b.adapters[0].probe_function_word(), 0x0000);
    b.step();
    assert_eq!(b.adapters[0].probe_function_word(), 0x0011);
    // This image was sampled while the drive took the 0: not enabled yet.
    b.step();
    assert_eq!(b.adapters[0].probe_state(), ProbeState::Arming);
    b.step();
    assert_eq!(b.adapters[0].probe_state(), ProbeState::Armed);
    let start = b.now;
    b.run(40, &|_, t| Some(((t.0 - start.0) / MS) as i32 * 1000));
    assert_eq!(b.events(0).len(), 1);
    assert_eq!(
        b.link.read_object(0, 0x60B9, 0),
        Ok(0x0002),
        "single shot over"
    );
    assert_eq!(
        b.adapters[0].probe_state(),
        ProbeState::Armed,
        "tolerated after the event"
    );
    b.link.write_object(0, 0x60B8, 0, 0x0011).unwrap();
    assert_eq!(
        b.link.read_object(0, 0x60B9, 0),
        Ok(0x0002),
        "same word: not re-armed"
    );

    // The same drive without the option in the file: the adapter still goes through 0 because
    // its last word for the probe was not 0.
    let mut plain = generic();
    plain.probe.rearm_requires_zero = false;
    let mut b = Bench::new(&[def], Nanos(MS), Plant::new());
    b.adapters[0] = Ds402Adapter::new(&plain).unwrap();
    b.enable();
    b.arm(&[0], &request(1, ProbeEdge::Positive));
    b.link.model_mut(0).unwrap().input_edge(1, true, b.now);
    // The image of the next exchange was sampled before the edge; the one after carries it.
    b.step();
    assert!(b.events(0).is_empty());
    b.step();
    assert_eq!(b.events(0).len(), 1);
    b.adapters[0]
        .arm_probe(&request(1, ProbeEdge::Positive))
        .unwrap();
    b.step();
    assert_eq!(b.adapters[0].probe_function_word(), 0x0000);
    for _ in 0..3 {
        b.step();
    }
    assert_eq!(b.adapters[0].probe_state(), ProbeState::Armed);
    assert!(b.events(0).is_empty());
}

// ---------------------------------------------------------------------------------------------
// (d) trigger sources, negative edge, probe 2
// ---------------------------------------------------------------------------------------------

/// Axis 0 at rest at 0, then +100 inc per 1 ms cycle (10 mm/s) through the surface. Returns the
/// bench after 400 cycles and the start of the ramp.
fn one_pass(def: DriveDefinition, surface: ProbeSurface, req: &ProbeRequest) -> (Bench, Nanos) {
    let mut plant = Plant::new();
    plant.add_probe_surface(surface);
    let mut b = Bench::new(&[def], Nanos(MS), plant);
    b.enable();
    b.arm(&[0], req);
    let t0 = b.now.saturating_add(Nanos(MS));
    b.run(400, &|_, t| Some(ramp_target(0, 100, Nanos(MS), t0, t)));
    (b, t0)
}

#[test]
fn drive_defined_source_from_0x60d0() {
    // Commissioning set the drive's 0x60D0:01 to input 2; DRIVE_DEFINED selects 10b.
    let mut plant = Plant::new();
    plant.add_probe_surface(ProbeSurface::new(0, 12_000.0, vec![(0, 2)]));
    let mut b = Bench::new(&[generic()], Nanos(MS), plant);
    b.link.write_object(0, 0x60D0, 1, 2).unwrap();
    b.enable();
    let req = ProbeRequest {
        source_mode: TriggerSourceMode::DriveDefined,
        trigger: ProbeTrigger::SourceObject,
        ..request(1, ProbeEdge::Positive)
    };
    assert_eq!(touch_probe_function(&req), Some(0x0019));
    assert_eq!(b.adapters[0].acyclic_probe_setup(&req), None);
    b.arm(&[0], &req);
    let start = b.now;
    b.run(200, &|_, t| Some(((t.0 - start.0) / MS) as i32 * 100));
    let e = b.events(0);
    assert_eq!(e.len(), 1, "{e:?}");
    assert!((f64::from(e[0].position) - 12_000.0).abs() <= 1.0);
}

#[test]
fn cnc_defined_source_written_by_sdo() {
    let req = ProbeRequest {
        source_mode: TriggerSourceMode::CncDefined,
        trigger: ProbeTrigger::SourceObject,
        input: 2,
        ..request(1, ProbeEdge::Positive)
    };
    // Without the 0x60D0 write probe 1 listens to input 1 (0x60D0:01 = 1): nothing latches.
    let (mut b, _) = one_pass(
        generic(),
        ProbeSurface::new(0, 12_000.0, vec![(0, 2)]),
        &req,
    );
    assert!(b.events(0).is_empty());

    let mut plant = Plant::new();
    plant.add_probe_surface(ProbeSurface::new(0, 12_000.0, vec![(0, 2)]));
    let mut b = Bench::new(&[generic()], Nanos(MS), plant);
    b.enable();
    let (index, sub, value) = b.adapters[0]
        .acyclic_probe_setup(&req)
        .expect("0x60D0 write");
    assert_eq!((index, sub, value), (0x60D0, 1, 2));
    b.link.write_object(0, index, sub, value).unwrap();
    assert_eq!(b.link.read_object(0, 0x60D0, 1), Ok(2));
    b.arm(&[0], &req);
    let start = b.now;
    b.run(200, &|_, t| Some(((t.0 - start.0) / MS) as i32 * 100));
    let e = b.events(0);
    assert_eq!(e.len(), 1, "{e:?}");
    assert!((f64::from(e[0].position) - 12_000.0).abs() <= 1.0);
}

#[test]
fn zero_pulse_trigger_latches_the_index_positions() {
    // From 2500 at +100 inc/ms to beyond 30000: index marks at 10000, 20000, 30000.
    let base = ProbeRequest {
        trigger: ProbeTrigger::ZeroPulse,
        ..request(1, ProbeEdge::Positive)
    };
    let run = |req: ProbeRequest| {
        let mut b = Bench::new(&[generic()], Nanos(MS), Plant::new());
        b.place(0, 2_500);
        b.enable();
        b.arm(&[0], &req);
        let start = b.now;
        b.run(350, &|_, t| {
            Some(2_500 + ((t.0 - start.0) / MS) as i32 * 100)
        });
        assert!(b.fb(0).position > 30_000);
        b.events(0)
    };
    let first = run(base);
    assert_eq!(first.len(), 1);
    assert_eq!(first[0].position, 10_000);
    let all = run(ProbeRequest {
        continuous: true,
        ..base
    });
    let got: Vec<(i32, u32)> = all.iter().map(|e| (e.position, e.sequence)).collect();
    assert_eq!(got, vec![(10_000, 1), (20_000, 2), (30_000, 3)]);
    let neg = run(ProbeRequest {
        edge: ProbeEdge::Negative,
        ..base
    });
    assert_eq!(
        (neg[0].edge, neg[0].position),
        (ProbeEdge::Negative, 10_000)
    );
}

#[test]
fn negative_edge_and_probe_2() {
    // Active-high probe, negative edge: latched when the pulse ends, 5 ms after the crossing.
    // Without feed-forward the closed forms give the crossing and the position 5 ms later.
    let def = first_order(generic());
    let kv = def.model.kv;
    let p = 12_345.0;
    let (mut b, t0) = one_pass(
        def,
        ProbeSurface::new(0, p, vec![(0, 1)]),
        &request(1, ProbeEdge::Negative),
    );
    let v = 100_000.0; // inc/s
    let tc = crossing_time(0.0, v, kv, t0, p);
    let release = Nanos(tc.round() as u64 + 5 * MS);
    let expect = ramp_position(0.0, v, kv, t0, release);
    let e = b.events(0);
    assert_eq!(e.len(), 1);
    assert_eq!(e[0].edge, ProbeEdge::Negative);
    assert!(
        (f64::from(e[0].position) - expect).abs() <= 1.0,
        "{e:?} vs {expect}"
    );

    // The default drive (feed-forward): the pulse ends 5 ms after the plant's contact edge and
    // the latch is the drive's position at that time. Over 100 ms into the ramp the drive moves
    // with its set-point (what is left of the start of the ramp decays with ≈ 24 ms and is
    // below an increment), so that is p + 10 mm/s × 5 ms = p + 500 increments.
    let (mut b, _) = one_pass(
        generic(),
        ProbeSurface::new(0, p, vec![(0, 1)]),
        &request(1, ProbeEdge::Negative),
    );
    let (contact, at_contact) = b.edge_positions[0].clone();
    let (release, at_release) = b.edge_positions[1].clone();
    assert!(contact.rising && !release.rising, "{:?}", b.edge_positions);
    assert_eq!(release.at, contact.at.saturating_add(Nanos(5 * MS)));
    assert!((at_contact[0].unwrap() - p).abs() < 0.01, "{at_contact:?}");
    let e = b.events(0);
    assert_eq!(e.len(), 1);
    assert_eq!(e[0].edge, ProbeEdge::Negative);
    let x = at_release[0].unwrap();
    assert!((f64::from(e[0].position) - x).abs() <= 1.0, "{e:?} vs {x}");
    assert!(
        (f64::from(e[0].position) - (p + 500.0)).abs() <= 1.0,
        "{e:?}"
    );

    // Active-low probe: the negative edge is the contact itself.
    let mut s = ProbeSurface::new(0, p, vec![(0, 1)]);
    s.active_high = false;
    let (mut b, _) = one_pass(generic(), s, &request(1, ProbeEdge::Negative));
    let e = b.events(0);
    assert!((f64::from(e[0].position) - p).abs() <= 1.0, "{e:?}");

    // Probe 2 on input 2 → 0x60BC.
    let (mut b, _) = one_pass(
        generic(),
        ProbeSurface::new(0, p, vec![(0, 2)]),
        &request(2, ProbeEdge::Positive),
    );
    let e = b.events(0);
    assert_eq!((e.len(), e[0].probe), (1, 2));
    assert!((f64::from(e[0].position) - p).abs() <= 1.0);
    assert_eq!(
        b.link.read_object(0, 0x60BC, 0),
        Ok(i64::from(e[0].position))
    );
    assert_eq!(b.link.read_object(0, 0x60B9, 0), Ok(0x0300));
}

// ---------------------------------------------------------------------------------------------
// (e) torque limit and fixed stop
// ---------------------------------------------------------------------------------------------

/// Axis 0 of `def` at rest at 0 moves at +100 inc per 1 ms cycle against a wall at 20000 with
/// TORQUE_LIMIT 10 % (0x6072 = 100 ‰). Returns the bench after `cycles`, the first cycle
/// (1-based from the start of the motion) whose feedback showed a fault, and every feedback.
///
/// The drive's set-point at cycle n is 100 n and at the wall its following error is
/// 100 n − 20000; the feedback of cycle n carries the drive's sample of cycle n − 1.
fn press(
    def: &DriveDefinition,
    window: Option<i64>,
    cycles: usize,
) -> (Bench, Option<usize>, Vec<DriveFeedback>) {
    let mut plant = Plant::new();
    plant.add_fixed_stop(FixedStop {
        device: 0,
        position: 20_000.0,
    });
    let mut b = Bench::new(std::slice::from_ref(def), Nanos(MS), plant);
    let tl = def.function("TORQUE_LIMIT").unwrap();
    b.link
        .write_object(0, tl.index, tl.sub, tl.encode(10.0).unwrap())
        .unwrap();
    assert_eq!(b.link.read_object(0, 0x6072, 0), Ok(100));
    if let Some(w) = window {
        b.link.write_object(0, 0x6065, 0, w).unwrap();
    }
    b.enable();
    let start = b.now;
    let mut fault = None;
    let mut fbs = Vec::new();
    for n in 1..=cycles {
        b.step_with(&|_, t| Some(((t.0 - start.0) / MS) as i32 * 100));
        fbs.push(b.fb(0));
        if fault.is_none() && b.fb(0).fault {
            fault = Some(n);
        }
    }
    (b, fault, fbs)
}

/// The torque law in every operational feedback of an axis pushed against a wall at `wall`
/// with the effective torque limits `pos` / `neg` (‰), `at_wall` the limit on the wall's side
/// (signed). Without feed-forward: 0x6077 = 0x60F4 × torque_per_increment clipped to the
/// limits (±1 for the rounding of 0x6064), both clipped and unclipped cycles must occur. With
/// feed-forward: pressed against the wall (at it, the set-point beyond it) the stalled axis
/// makes the speed loop demand ever more acceleration, so 0x6077 sits at the limit.
fn check_torque_law(
    def: &DriveDefinition,
    fbs: &[DriveFeedback],
    wall: i32,
    (pos, neg): (f64, f64),
    at_wall: i32,
) {
    let (mut clipped, mut free, mut pressed) = (0, 0, 0);
    for fb in fbs.iter().filter(|fb| fb.operational) {
        let torque = fb.torque.expect("0x6077 mapped");
        let fe = fb.following_error.expect("0x60F4 mapped");
        let is_pressed = fb.position == wall && fe.signum() == at_wall.signum();
        if is_pressed {
            pressed += 1;
        }
        if def.model.feed_forward {
            if is_pressed {
                assert_eq!(torque, at_wall, "{fb:?}");
            }
        } else {
            let demand = f64::from(fe) * def.model.torque_per_increment;
            let expected = demand.clamp(-neg, pos);
            if expected != demand {
                clipped += 1;
            } else {
                free += 1;
            }
            assert!(
                (f64::from(torque) - expected).abs() <= 1.0,
                "{fb:?}: demand {demand}"
            );
        }
    }
    assert!(pressed > 0, "never at the wall");
    if !def.model.feed_forward {
        assert!(clipped > 0 && free > 0, "clipped {clipped}, free {free}");
    }
}

#[test]
fn fixed_stop_with_reduced_torque_limit_stalls_and_faults() {
    // Window 50000 inc, time out 10 ms (drive file). At the wall the drive's lag is
    // 100 n − 20000, over the window from n = 701 on, and the drive faults in its 11th cycle
    // over the window (> 10 ms), n = 711; its image reaches the adapter at n = 712.
    for def in [first_order(generic()), generic()] {
        let what = format!("feed-forward {}", def.model.feed_forward);
        let (b, fault, fbs) = press(&def, Some(50_000), 705);
        let fb = b.fb(0);
        assert!(fault.is_none() && fb.operational, "{what}");
        assert_eq!(fb.position, 20_000, "{what}: the wall holds");
        // The sample of cycle 704.
        assert_eq!(fb.following_error, Some(100 * 704 - 20_000), "{what}");
        // Without feed-forward the demand is 0.004 ‰/inc × 50400 = 201.6 ‰ > 100 ‰; with it
        // the stalled axis demands ever more. Clipped either way, internal limit active.
        assert_eq!(fb.torque, Some(100), "{what}");
        assert_ne!(fb.statusword & 0x0800, 0, "{what}: bit 11");
        check_torque_law(&def, &fbs, 20_000, (100.0, 100.0), 100);

        let (b, fault, _) = press(&def, Some(50_000), 720);
        assert_eq!(fault, Some(712), "{what}");
        assert_eq!(b.link.models()[0].last_error_code(), 0x8611, "{what}");
        assert_ne!(b.fb(0).statusword & 0x2000, 0, "{what}");
    }
}

#[test]
fn fixed_stop_with_monitoring_off_only_stalls() {
    // S-0-0159 = 0 ("monitoring off") maps to 0x6065 = 0xFFFFFFFF.
    let idn = generic().idn("S-0-0159").cloned().unwrap();
    for def in [first_order(generic()), generic()] {
        let (mut b, fault, fbs) = press(&def, idn.encode(0), 1500);
        assert_eq!(fault, None);
        let fb = b.fb(0);
        assert_eq!((fb.position, fb.torque), (20_000, Some(100)));
        // The sample of cycle 1499.
        assert_eq!(fb.following_error, Some(129_900));
        check_torque_law(&def, &fbs, 20_000, (100.0, 100.0), 100);
        assert_eq!(
            b.link.read_object(0, 0x6065, 0).map(|v| idn.decode(v)),
            Ok(0)
        );
    }
}

#[test]
fn fixed_stop_from_above_uses_the_negative_limit() {
    for def in [first_order(generic()), generic()] {
        let mut plant = Plant::new();
        plant.add_fixed_stop(FixedStop {
            device: 0,
            position: -5_000.0,
        });
        let mut b = Bench::new(std::slice::from_ref(&def), Nanos(MS), plant);
        b.link.write_object(0, 0x60E1, 0, 50).unwrap();
        b.enable();
        let start = b.now;
        let mut fbs = Vec::new();
        for _ in 0..300 {
            b.step_with(&|_, t| Some(-(((t.0 - start.0) / MS) as i32) * 100));
            fbs.push(b.fb(0));
        }
        let fb = b.fb(0);
        assert_eq!(fb.position, -5_000);
        // min(0x6072 = 3000, 0x60E1 = 50) for negative torque. Without feed-forward the
        // demand is −0.004 × 24900 = −99.6 ‰; with it the stalled axis demands ever more.
        assert_eq!(fb.torque, Some(-50));
        check_torque_law(&def, &fbs, -5_000, (3000.0, 50.0), -50);
        // Taking the stop out of the plant frees the axis.
        b.link.plant_mut().fixed_stops_mut().clear();
        b.run(5, &|_, _| None);
        assert!(b.fb(0).position < -5_000);
        assert_eq!(b.link.models()[0].fixed_stop(), None);
    }
}

// ---------------------------------------------------------------------------------------------
// (f) byte-level trace of 0x60B8
// ---------------------------------------------------------------------------------------------

/// Input image of the generic drive: statusword 0x1637 (operation enabled), CSP, 0x60B9 = `tp`,
/// 0x60BA..0x60BD = `values`.
fn image(tp: u16, values: [i32; 4]) -> Vec<u8> {
    let mut v = vec![0x37, 0x16, 0, 0, 0, 0, 0, 0, 0, 0, 0x08];
    v.extend_from_slice(&tp.to_le_bytes());
    for x in values {
        v.extend_from_slice(&x.to_le_bytes());
    }
    v.extend_from_slice(&[0, 0]); // 0x6077
    v
}

/// `recv!(adapter, 0x60B9, [60BA, 60BB, 60BC, 60BD] => state)`: decode one input image and
/// check the probe state afterwards.
macro_rules! recv {
    ($a:expr, $tp:expr, $vals:expr => $state:expr) => {{
        $a.read_inputs(Nanos::ZERO, &image($tp, $vals)).unwrap();
        assert_eq!($a.probe_state(), $state, "after 0x60B9 = 0x{:04X}", $tp);
    }};
    ($a:expr, $tp:expr => $state:expr) => {
        recv!($a, $tp, [0; 4] => $state)
    };
}

/// `send!(adapter => [lo, hi])`: encode one output image; bytes 7..9 are 0x60B8.
macro_rules! send {
    ($a:expr => $bytes:expr) => {{
        let mut out = [0u8; 9];
        let cmd = DriveCommand {
            enable: true,
            ..Default::default()
        };
        $a.write_outputs(Nanos::ZERO, &cmd, &mut out).unwrap();
        assert_eq!(out[7..9], $bytes, "0x60B8 bytes");
    }};
}

/// `event!(adapter => (edge, position, sequence))` or `event!(adapter => none)`.
macro_rules! event {
    ($a:expr => none) => {
        assert_eq!($a.take_probe_event(), None)
    };
    ($a:expr => ($probe:expr, $edge:ident, $pos:expr, $seq:expr)) => {
        assert_eq!(
            $a.take_probe_event(),
            Some(ProbeEvent {
                probe: $probe,
                edge: ProbeEdge::$edge,
                position: $pos,
                sequence: $seq
            })
        )
    };
}

#[test]
fn function_word_trace_arm_rearm_disarm() {
    use ProbeState::*;
    let mut a = Ds402Adapter::new(&generic()).unwrap();
    recv!(a, 0x0000 => Idle);
    send!(a => [0x00, 0x00]); // nothing armed: 0x60B8 = 0

    // Probe 1, first event, input 1, positive edge: 0x0011. Disabled and word 0: write at once.
    a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    assert_eq!(a.probe_state(), Arming);
    send!(a => [0x11, 0x00]);
    recv!(a, 0x0000 => Arming); // drive has not taken it yet
    send!(a => [0x11, 0x00]);
    recv!(a, 0x0001 => Armed); // enabled, stored bits clear
    event!(a => none);
    send!(a => [0x11, 0x00]);
    recv!(a, 0x0003, [1234, 0, 0, 0] => Armed); // bit 1 rose: 0x60BA = 1234
    event!(a => (1, Positive, 1234, 1));
    recv!(a, 0x0003, [1234, 0, 0, 0] => Armed);
    event!(a => none); // still stored: not new

    // Re-arm: enabled, so 0 first, and the stale stored bit / value never become an event.
    a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    send!(a => [0x00, 0x00]);
    recv!(a, 0x0003, [1234, 0, 0, 0] => Arming);
    send!(a => [0x00, 0x00]);
    recv!(a, 0x0000, [1234, 0, 0, 0] => Arming); // disabled now
    send!(a => [0x11, 0x00]);
    recv!(a, 0x0003, [1234, 0, 0, 0] => Arming); // a drive still showing the old latch: wait
    event!(a => none);
    send!(a => [0x11, 0x00]);
    recv!(a, 0x0001, [1234, 0, 0, 0] => Armed);
    event!(a => none);

    // Switch to probe 2, continuous, negative edge: 0x2300; probe 1's byte goes to 0.
    let req2 = ProbeRequest {
        continuous: true,
        ..request(2, ProbeEdge::Negative)
    };
    assert_eq!(touch_probe_byte(&req2), 0x23);
    a.arm_probe(&req2).unwrap();
    send!(a => [0x00, 0x23]);
    recv!(a, 0x0100 => Armed); // probe 2 enabled, stored clear, toggles as they are
    send!(a => [0x00, 0x23]);
    recv!(a, 0x8500, [0, 0, 0, -7] => Armed); // bit 10 stored, bit 15 toggled
    event!(a => (2, Negative, -7, 1));
    recv!(a, 0x0500, [0, 0, 0, -9] => Armed); // toggled back: a second latch
    event!(a => (2, Negative, -9, 2));
    recv!(a, 0x0500, [0, 0, 0, -9] => Armed);
    event!(a => none);

    // Disarm: 0 from the next image on, pending events dropped.
    recv!(a, 0x8500, [0, 0, 0, -11] => Armed);
    a.disarm_probe();
    event!(a => none);
    assert_eq!(a.probe_state(), Idle);
    send!(a => [0x00, 0x00]);
}

#[test]
fn drive_defined_either_stored_bit_counts() {
    let mut a = Ds402Adapter::new(&generic()).unwrap();
    let req = ProbeRequest {
        source_mode: TriggerSourceMode::DriveDefined,
        ..request(1, ProbeEdge::Positive)
    };
    recv!(a, 0x0000 => ProbeState::Idle);
    a.arm_probe(&req).unwrap();
    send!(a => [0x19, 0x00]); // enable | 10b (0x60D0) | positive edge
    recv!(a, 0x0001 => ProbeState::Armed);
    // The drive reports the latch under the negative stored bit: it counts, value 0x60BB.
    recv!(a, 0x0005, [0, 777, 0, 0] => ProbeState::Armed);
    event!(a => (1, Negative, 777, 1));
    recv!(a, 0x0007, [555, 777, 0, 0] => ProbeState::Armed);
    event!(a => none); // first event only
}

#[test]
fn refusals_and_failures() {
    let mut a = Ds402Adapter::new(&generic()).unwrap();
    assert!(a.arm_probe(&request(3, ProbeEdge::Positive)).is_err());
    let cnc0 = ProbeRequest {
        source_mode: TriggerSourceMode::CncDefined,
        input: 0,
        ..request(1, ProbeEdge::Positive)
    };
    assert!(a.arm_probe(&cnc0).is_err());
    // A drive file without 0x60B8 in the RxPDO has no latch unit for the adapter.
    let mut def = generic();
    def.rxpdo = PdoLayout::parse(&["0x6040:00", "0x607A:00"]).unwrap();
    let mut bare = Ds402Adapter::new(&def).unwrap();
    assert!(bare.arm_probe(&request(1, ProbeEdge::Positive)).is_err());

    // Timeout: the drive never confirms.
    let mut def = generic();
    def.probe.arm_timeout_cycles = 3;
    let mut a = Ds402Adapter::new(&def).unwrap();
    recv!(a, 0x0000 => ProbeState::Idle);
    a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    for _ in 0..3 {
        recv!(a, 0x0000 => ProbeState::Arming);
    }
    a.read_inputs(Nanos::ZERO, &image(0, [0; 4])).unwrap();
    assert!(matches!(a.probe_state(), ProbeState::Failed(w) if w.contains("did not confirm")));

    // A fault while armed.
    let mut a = Ds402Adapter::new(&generic()).unwrap();
    recv!(a, 0x0000 => ProbeState::Idle);
    a.arm_probe(&request(1, ProbeEdge::Positive)).unwrap();
    send!(a => [0x11, 0x00]);
    recv!(a, 0x0001 => ProbeState::Armed);
    let mut img = image(0x0003, [42, 0, 0, 0]);
    img[0] = 0x08; // statusword 0x1608: FAULT
    a.read_inputs(Nanos::ZERO, &img).unwrap();
    assert!(matches!(a.probe_state(), ProbeState::Failed(w) if w.contains("fault")));
    event!(a => none);
}

/// Leaving operation enabled through the whole stack while armed.
#[test]
fn disabling_the_drive_while_armed_fails_the_latch() {
    let mut b = Bench::new(&[generic()], Nanos(MS), Plant::new());
    b.enable();
    b.arm(&[0], &request(1, ProbeEdge::Positive));
    b.link.model_mut(0).unwrap().inject_fault(0x7500);
    // The drive faults at this exchange's step; the image was sampled before.
    b.step();
    assert_eq!(b.fb(0).state, PowerState::OperationEnabled);
    assert_eq!(b.adapters[0].probe_state(), ProbeState::Armed);
    b.step();
    assert!(matches!(b.adapters[0].probe_state(), ProbeState::Failed(_)));
    assert_eq!(
        b.link.read_object(7, 0x6041, 0),
        Err(LinkError::Other(
            "device 7: not on the link (1 devices)".into()
        ))
    );
    assert_eq!(
        b.link.write_object(0, 0x60B9, 0, 1),
        Err(LinkError::Abort {
            device: fieldprobe::link::Peer::Device(0),
            index: 0x60B9,
            sub: 0,
            code: 0x0601_0002
        })
    );
    assert_eq!(b.fb(0).state, PowerState::FaultReactionActive);
}

// ---------------------------------------------------------------------------------------------
// (g) no panics
// ---------------------------------------------------------------------------------------------

proptest! {
    /// Random RxPDO bytes, time steps and digital-input edges at random times: the model never
    /// panics, its trajectory stays ordered and finite.
    #[test]
    fn model_survives_random_rx_and_edges(
        frames in prop::collection::vec(
            (prop::collection::vec(any::<u8>(), 0..16),
             prop::collection::vec((any::<u8>(), any::<bool>(), any::<u64>()), 0..6)),
            1..30),
        dt in prop_oneof![Just(0.001), any::<f64>(), -1.0..1.0f64],
        stop in prop::option::of(-1.0e9..1.0e9f64),
    ) {
        let mut def = generic();
        def.model.zero_pulse_period = 1.0;
        let mut m = Ds402Model::new(&def);
        m.set_fixed_stop(stop);
        let mut tx = vec![0u8; m.tx_len()];
        for (i, (rx, edges)) in frames.iter().enumerate() {
            let now = Nanos(i as u64 * MS);
            m.begin_step(now, dt, rx);
            for &(input, rising, at) in edges {
                m.input_edge(input, rising, Nanos(at));
            }
            m.finish_step(&mut tx);
            prop_assert!(m.actual().is_finite());
            let t = m.trajectory();
            prop_assert!(t.windows(2).all(|w| w[0].0 <= w[1].0));
            prop_assert!(t.iter().all(|p| p.1.is_finite()));
        }
    }

    /// Random input images after arming: the adapter never panics and never reports a latch
    /// twice (sequence strictly increasing within an arming).
    #[test]
    fn adapter_survives_random_images_while_armed(
        images in prop::collection::vec(prop::collection::vec(any::<u8>(), 31..33), 1..40),
        probe in 0u8..4,
        negative in any::<bool>(),
        continuous in any::<bool>(),
        mode in 0u8..3,
        counters in any::<bool>(),
    ) {
        let def = if counters { with_counters(generic()) } else { generic() };
        let mut a = Ds402Adapter::new(&def).unwrap();
        let req = ProbeRequest {
            probe,
            edge: if negative { ProbeEdge::Negative } else { ProbeEdge::Positive },
            trigger: ProbeTrigger::Input,
            continuous,
            source_mode: [TriggerSourceMode::Default, TriggerSourceMode::CncDefined,
                TriggerSourceMode::DriveDefined][usize::from(mode)],
            input: 1,
        };
        let _ = a.arm_probe(&req);
        let mut last = 0;
        let mut out = vec![0u8; a.output_len()];
        for img in &images {
            let mut img = img.clone();
            img.resize(a.input_len(), 0);
            let _ = a.read_inputs(Nanos::ZERO, &img);
            while let Some(e) = a.take_probe_event() {
                prop_assert!(e.sequence > last, "{:?} after {}", e, last);
                last = e.sequence;
            }
            prop_assert!(a.write_outputs(Nanos::ZERO, &DriveCommand::default(), &mut out).is_ok());
        }
    }

    /// Random surfaces, pulses, fixed stops and set-points through the whole link.
    #[test]
    fn link_with_plant_survives_random_motion(
        targets in prop::collection::vec(any::<i32>(), 1..40),
        surfaces in prop::collection::vec((-1.0e6..1.0e6f64, 0u64..10_000_000, any::<u8>()), 0..4),
        stop in prop::option::of(-1.0e6..1.0e6f64),
    ) {
        let mut plant = Plant::new();
        for &(p, pulse, input) in &surfaces {
            let mut s = ProbeSurface::new(0, p, vec![(0, input), (5, 1)]);
            s.pulse = Nanos(pulse);
            plant.add_probe_surface(s);
        }
        if let Some(p) = stop {
            plant.add_fixed_stop(FixedStop { device: 0, position: p });
        }
        let mut b = Bench::new(&[generic()], Nanos(MS), plant);
        b.link.write_object(0, 0x60D0, 1, 5).unwrap();
        b.adapters[0].arm_probe(&ProbeRequest { continuous: true, ..request(1, ProbeEdge::Positive) }).unwrap();
        for &t in &targets {
            b.step_with(&|_, _| Some(t));
            let e = b.link.plant().last_edges();
            prop_assert!(e.windows(2).all(|w| w[0].at <= w[1].at));
        }
    }
}
