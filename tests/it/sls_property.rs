//! Property test (issue 2): for random programs and random limits, the actual position of an axis
//! with active SLS never passes limit + tolerance, and no block whose command path crosses a limit
//! is executed — while every block that stays inside is.
//!
//! The verdict "this block crosses a limit" is computed here independently of the code under
//! test: lines by their end points, arcs by sampling the circle with this file's own geometry.

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::Machine;
use fieldprobe::nc::exec::{Executor, Step};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Move {
    Line {
        x: f64,
        y: f64,
    },
    /// Half circle to the diametrically opposite point, centre offset (i, j).
    Half {
        i: f64,
        j: f64,
        cw: bool,
    },
}

/// Moves in percent of the limits: lines to −130 % … +130 % of the limit on each side (so
/// roughly one coordinate in four lies beyond), half circles with centre offsets up to 60 % of
/// the smaller half-range. Scaled to mm by [`scale`] once the limits are known.
#[derive(Debug, Clone)]
enum PctMove {
    Line(i32, i32),
    Half(i32, i32, bool),
}

fn moves() -> impl Strategy<Value = Vec<PctMove>> {
    let line = (-130i32..=130, -130i32..=130).prop_map(|(x, y)| PctMove::Line(x, y));
    let half = (-60i32..=60, -60i32..=60, any::<bool>())
        .prop_filter("non-zero radius", |(i, j, _)| *i != 0 || *j != 0)
        .prop_map(|(i, j, cw)| PctMove::Half(i, j, cw));
    prop::collection::vec(prop_oneof![3 => line, 2 => half], 1..8)
}

fn scale(m: &PctMove, nx: f64, px: f64, ny: f64, py: f64) -> Move {
    let side = |pct: i32, neg: f64, pos: f64| {
        let l = if pct < 0 { -neg } else { pos };
        (f64::from(pct) * l / 100.0 * 1000.0).round() / 1000.0
    };
    match *m {
        PctMove::Line(x, y) => Move::Line {
            x: side(x, nx, px),
            y: side(y, ny, py),
        },
        PctMove::Half(i, j, cw) => {
            let half = (px - nx).min(py - ny) / 2.0;
            let r = |p: i32| (f64::from(p) * half / 100.0 * 1000.0).round() / 1000.0;
            Move::Half {
                i: r(i),
                j: r(j),
                cw,
            }
        }
    }
}

/// Min/max of X and Y over a move from `start`, computed independently.
fn sweep_extent(start: (f64, f64), m: &Move) -> ((f64, f64), (f64, f64), (f64, f64)) {
    match *m {
        Move::Line { x, y } => (
            (start.0.min(x), start.0.max(x)),
            (start.1.min(y), start.1.max(y)),
            (x, y),
        ),
        Move::Half { i, j, cw } => {
            let c = (start.0 + i, start.1 + j);
            let r = (i * i + j * j).sqrt();
            let a0 = (start.1 - c.1).atan2(start.0 - c.0);
            let sweep = if cw {
                -std::f64::consts::PI
            } else {
                std::f64::consts::PI
            };
            let (mut xl, mut xh, mut yl, mut yh) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
            let n = 20_000;
            for k in 0..=n {
                let a = a0 + sweep * k as f64 / n as f64;
                let (px, py) = (c.0 + r * a.cos(), c.1 + r * a.sin());
                xl = xl.min(px);
                xh = xh.max(px);
                yl = yl.min(py);
                yh = yh.max(py);
            }
            ((xl, xh), (yl, yh), (start.0 + 2.0 * i, start.1 + 2.0 * j))
        }
    }
}

fn program(moves: &[Move]) -> String {
    let mut s = String::from("%prop\nN1 G90 F12000\n");
    for (k, m) in moves.iter().enumerate() {
        let n = (k + 2) * 10;
        match m {
            Move::Line { x, y } => s.push_str(&format!("N{n} G01 X{x} Y{y}\n")),
            Move::Half { i, j, cw } => {
                // End point = start + 2·(I, J): written relative with G91 so it is exact.
                let g = if *cw { 2 } else { 3 };
                s.push_str(&format!(
                    "N{n} G91 G0{g} X{} Y{} I{i} J{j}\nN{n}5 G90\n",
                    2.0 * i,
                    2.0 * j
                ));
            }
        }
    }
    s.push_str("N999 M30\n");
    s
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, .. ProptestConfig::default() })]

    #[test]
    fn sls_is_never_passed_and_crossing_blocks_never_run(
        neg_x in 50i64..=250, pos_x in 50i64..=250, neg_y in 50i64..=250, pos_y in 50i64..=250,
        pct_moves in moves(),
    ) {
        let (nx, px, ny, py) = (-(neg_x as f64), pos_x as f64, -(neg_y as f64), pos_y as f64);
        let moves: Vec<Move> = pct_moves.iter().map(|m| scale(m, nx, px, ny, py)).collect();
        let tol = 0.1; // P-AXIS-00179 default 1000 × 0.1 µm
        let mut cfg = MachineConfig::default_machine();
        for s in [
            format!("X.P-AXIS-00177={}", -neg_x * 10_000), format!("X.P-AXIS-00178={}", pos_x * 10_000),
            format!("Y.P-AXIS-00177={}", -neg_y * 10_000), format!("Y.P-AXIS-00178={}", pos_y * 10_000),
        ] {
            cfg.apply_set(&s).unwrap();
        }
        let mut m = Machine::new(&cfg).unwrap();
        prop_assert_eq!(m.settle(10_000), ChannelState::Idle);
        let src = program(&moves);
        let prog = parse(&src).unwrap();
        let names = m.channel().axes().iter().map(|a| a.name().to_string()).collect();
        let mut exec = Executor::new(prog, names);
        exec.sync(m.channel());
        let mut events = Vec::new();
        let mut pos = (0.0, 0.0);
        let mut move_iter = moves.iter();
        let mut cycles = 0u64;
        loop {
            let a = m.channel().actual_positions();
            prop_assert!(a[0] <= px + tol && a[0] >= nx - tol, "X actual {} outside [{nx}, {px}] ± {tol}", a[0]);
            prop_assert!(a[1] <= py + tol && a[1] >= ny - tol, "Y actual {} outside [{ny}, {py}] ± {tol}", a[1]);
            match m.channel().state() {
                ChannelState::Idle => {
                    // Is the next block a move of ours? Peek by comparing programmed text order.
                    let before = m.channel().command_positions();
                    let step = exec.step(m.channel_mut(), &mut events);
                    let after_state = m.channel().state();
                    let started = after_state == ChannelState::Busy;
                    let rejected = m.channel().messages().iter().any(|x| x.id == 120002 || x.id == 120003);
                    if started || rejected {
                        let mv = move_iter.next().expect("a motion block belongs to a generated move");
                        prop_assert_eq!((before[0], before[1]), pos);
                        let ((xl, xh), (yl, yh), end) = sweep_extent(pos, mv);
                        let inside = xl >= nx - 1e-6 && xh <= px + 1e-6 && yl >= ny - 1e-6 && yh <= py + 1e-6;
                        let clearly_out = xl < nx - 1e-3 || xh > px + 1e-3 || yl < ny - 1e-3 || yh > py + 1e-3;
                        if started {
                            prop_assert!(inside, "block {mv:?} from {pos:?} crosses a limit but was started");
                            pos = end;
                        } else {
                            prop_assert!(clearly_out || !inside, "block {mv:?} from {pos:?} stays inside but was refused");
                            break;
                        }
                    } else if step == Step::Continue {
                        // Modal-only block (G90) or a zero-length move.
                        if let Some(Move::Line { x, y }) = peek_zero(&moves, &mut move_iter, pos) {
                            pos = (x, y);
                        }
                    }
                    match step {
                        Step::End => break,
                        Step::Abort => { m.settle(1_000_000); break; }
                        Step::Continue => {}
                    }
                }
                ChannelState::Aborted => break,
                _ => m.step(),
            }
            cycles += 1;
            prop_assert!(cycles < 5_000_000, "run did not end");
        }
        // Settle to standstill and check once more.
        m.settle(1_000_000);
        let a = m.channel().actual_positions();
        prop_assert!(a[0] <= px + tol && a[0] >= nx - tol);
        prop_assert!(a[1] <= py + tol && a[1] >= ny - tol);
    }
}

/// A generated line to the current position starts nothing (zero length): consume it.
fn peek_zero<'a>(
    _all: &[Move],
    it: &mut std::slice::Iter<'a, Move>,
    pos: (f64, f64),
) -> Option<Move> {
    let mut probe = it.clone();
    match probe.next() {
        Some(Move::Line { x, y }) if (*x, *y) == pos => {
            it.next();
            Some(Move::Line { x: *x, y: *y })
        }
        _ => None,
    }
}
