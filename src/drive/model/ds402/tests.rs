//! Unit tests of the CiA 402 drive model (module-private parts; the end-to-end behaviour is
//! tested through the adapter in `tests/it/ds402.rs` and `tests/it/touch_probe.rs`).

use super::motion::SUBSAMPLES;
use super::power::{decode_command, Command};
use super::*;
use crate::drive::catalogue;
use crate::drive::model::abort;

fn model() -> Ds402Model {
    Ds402Model::new(&catalogue::builtin("cia402-generic").unwrap())
}

/// A model in OPERATION ENABLED / CSP without going through the bus, with the first-order loop
/// without feed-forward (`[model] feed_forward = false`), whose solution is known in closed form.
fn following() -> Ds402Model {
    let mut def = catalogue::builtin("cia402-generic").unwrap();
    def.model.feed_forward = false;
    let mut m = Ds402Model::new(&def);
    m.state = PowerState::OperationEnabled;
    m.mode = MODE_CSP;
    m
}

/// Drop the speed limit.
fn no_speed_limit(m: &mut Ds402Model) {
    let mut p = *m.plant.servo_params();
    p.v_max = f64::INFINITY;
    m.plant.set_servo_params(p);
}

#[test]
fn command_decode() {
    assert_eq!(decode_command(0x06), Command::Shutdown);
    assert_eq!(decode_command(0x07), Command::SwitchOn);
    assert_eq!(decode_command(0x0F), Command::EnableOperation);
    assert_eq!(decode_command(0x00), Command::DisableVoltage);
    assert_eq!(decode_command(0x02), Command::QuickStop);
    assert_eq!(decode_command(0x80), Command::DisableVoltage);
    assert_eq!(decode_command(0x86), Command::None);
}

#[test]
fn object_access_abort_codes() {
    let mut m = model();
    assert_eq!(m.read_object(0x1000, 0), Err(abort::NO_OBJECT));
    assert_eq!(m.read_object(0x6041, 1), Err(abort::NO_SUB_INDEX));
    assert_eq!(m.write_object(0x6064, 0, 5), Err(abort::READ_ONLY));
    assert_eq!(m.write_object(0x60D0, 0, 2), Err(abort::READ_ONLY));
    assert_eq!(m.write_object(0x60D5, 0, 2), Err(abort::READ_ONLY));
    assert_eq!(m.write_object(0x60BA, 0, 2), Err(abort::READ_ONLY));
    assert_eq!(m.write_object(0x6066, 0, 70_000), Err(abort::VALUE_RANGE));
    assert_eq!(m.write_object(0x6060, 0, 1), Err(abort::VALUE_RANGE));
    assert_eq!(m.write_object(0x6065, 0, 1234), Ok(()));
    assert_eq!(m.read_object(0x6065, 0), Ok(1234));
    assert_eq!(m.write_object(0x60D0, 2, -1), Ok(()));
    assert_eq!(m.read_object(0x60D0, 2), Ok(-1));
    assert_eq!(m.read_object(0x60D0, 3), Err(abort::NO_SUB_INDEX));
    assert_eq!(m.read_object(0x60B9, 0), Ok(0));
    assert_eq!(m.write_object(0x60B8, 0, 0x0011), Ok(()));
    assert_eq!(m.read_object(0x60B8, 0), Ok(0x0011));
    assert_eq!(m.read_object(0x60B9, 0), Ok(0x0001));
    assert_eq!(m.read_object(0x60D8, 0), Ok(0));
    assert_eq!(m.read_object(0x6077, 0), Ok(0));
}

#[test]
fn first_step_leaves_not_ready() {
    let mut m = model();
    assert_eq!(m.state(), PowerState::NotReadyToSwitchOn);
    assert_eq!(m.statusword(), 0);
    assert!(m.trajectory().is_empty());
    let (rx, mut tx) = (vec![0; m.rx_len()], vec![0; m.tx_len()]);
    m.step(Nanos::ZERO, 0.001, &rx, &mut tx);
    assert_eq!(m.state(), PowerState::SwitchOnDisabled);
    // 0x0250: switch on disabled, voltage enabled, remote.
    assert_eq!(&tx[..2], &[0x50, 0x02]);
}

#[test]
fn constant_set_point_is_the_step_formula() {
    let mut m = following();
    no_speed_limit(&mut m);
    m.target = 1000;
    m.plant.prev_target = 1000.0;
    m.move_axis(Nanos(1_000_000), 0.001);
    let expect = 1000.0 * (1.0 - (-40.0f64 * 0.001).exp());
    assert!(
        (m.plant.position - expect).abs() < 1e-9,
        "{}",
        m.plant.position
    );
}

#[test]
fn trajectory_times_and_interpolation() {
    let mut m = following();
    no_speed_limit(&mut m);
    m.set_disturbance(0.5);
    m.target = 1600;
    m.plant.prev_target = 0.0;
    m.move_axis(Nanos(5_000_000), 0.001);
    let traj = m.trajectory().to_vec();
    assert_eq!(traj.len(), SUBSAMPLES + 1);
    assert_eq!(traj[0], (Nanos(4_000_000), 0.5));
    assert_eq!(traj[SUBSAMPLES].0, Nanos(5_000_000));
    assert_eq!(traj[SUBSAMPLES].1, m.actual());
    assert_eq!(traj[1].0, Nanos(4_062_500));
    let mid = m.position_at(Nanos(4_031_250)).unwrap();
    assert!((mid - (traj[0].1 + traj[1].1) / 2.0).abs() < 1e-12);
    assert_eq!(m.position_at(Nanos(3_999_999)), None);
    assert_eq!(m.position_at(Nanos(5_000_001)), None);
    // Zero-length step: one point.
    m.move_axis(Nanos(7), 0.0);
    assert_eq!(m.trajectory(), &[(Nanos(7), m.actual())]);
    assert_eq!(m.position_at(Nanos(7)), Some(m.actual()));
    // Start of time: the cycle start is clamped to 0.
    m.move_axis(Nanos(300_000), 0.001);
    assert_eq!(m.trajectory()[0].0, Nanos::ZERO);
    assert!(m.trajectory().windows(2).all(|w| w[0].0 <= w[1].0));
}

#[test]
fn input_edge_latches_interpolated_position() {
    let mut m = following();
    no_speed_limit(&mut m);
    m.write_object(0x60B8, 0, 0x0031).unwrap(); // TP1 first event, both edges
    m.target = 1600;
    m.move_axis(Nanos(1_000_000), 0.001);
    let at = Nanos(400_000);
    let expect = m.position_at(at).unwrap();
    m.input_edge(1, true, at);
    m.input_edge(1, true, Nanos(500_000)); // already high: no edge
    assert_eq!(m.read_object(0x60BA, 0), Ok(expect.round() as i64));
    assert_eq!(m.read_object(0x60B9, 0), Ok(0x0003));
    // Out of the cycle: clamped to its end.
    m.input_edge(1, false, Nanos(9_000_000));
    assert_eq!(m.read_object(0x60BB, 0), Ok(m.actual().round() as i64));
    m.input_edge(0, true, at);
    m.input_edge(9, true, at);
    m.set_input_level(2, true);
    assert_eq!((m.input_level(2), m.input_level(5)), (Some(true), None));
    assert_eq!(m.read_object(0x60B9, 0), Ok(0x0007));
}

#[test]
fn zero_pulses_latch_exact_multiples() {
    let mut m = following();
    no_speed_limit(&mut m);
    m.set_actual(9_990.0);
    m.write_object(0x60B8, 0, 0x0017).unwrap(); // TP1 continuous, zero pulse, positive edge
    m.target = 30_010;
    m.move_axis(Nanos(1_000_000), 0.001);
    m.zero_pulses();
    // Crosses 10000 only (lag): one pulse at exactly 10000.
    let end = m.actual();
    let crossed = ((end / 10_000.0).floor() - 0.0) as u16;
    assert_eq!(m.read_object(0x60D5, 0), Ok(i64::from(crossed)));
    assert_eq!(m.read_object(0x60BA, 0), Ok(10_000 * i64::from(crossed)));
}

#[test]
fn torque_limit_and_wall() {
    let mut m = following();
    m.write_object(0x6072, 0, 100).unwrap();
    m.write_object(0x60E0, 0, 50).unwrap();
    m.set_fixed_stop(Some(100.0));
    assert_eq!(m.fixed_stop(), Some(100.0));
    m.target = 50_000;
    m.plant.prev_target = 50_000.0;
    m.move_axis(Nanos(1_000_000), 0.001);
    assert_eq!(m.actual(), 100.0);
    // Demand 0.004 * 49900 = 199.6 per mille, limit min(100, 50) = 50.
    assert_eq!(m.read_object(0x6077, 0), Ok(50));
    assert_ne!(m.statusword() & 0x0800, 0);
    // Negative side: min(6072, 60E1 = 3000) = 100.
    m.set_fixed_stop(None);
    m.target = -50_000;
    m.plant.prev_target = -50_000.0;
    m.set_fixed_stop(Some(0.0));
    m.move_axis(Nanos(2_000_000), 0.001);
    assert_eq!(m.actual(), 0.0);
    assert_eq!(m.read_object(0x6077, 0), Ok(-100));
}
