//! A G100 measuring run stepped cycle by cycle, with a hook after every cycle (fault
//! injection), for the link tests.

#![allow(dead_code)] // each test crate uses its own subset

use fieldprobe::channel::ChannelState;
use fieldprobe::machine::Machine;
use fieldprobe::nc::exec::{Event, Executor, Step};
use fieldprobe::nc::parser::parse;

/// Run `N10 G100 Z100 F3000` on `m`; `each(machine, cycle)` after every cycle. Returns the
/// message IDs in order and the executor (for the results).
pub fn measuring_run(
    m: &mut Machine,
    mut each: impl FnMut(&mut Machine, usize),
) -> (Vec<u32>, Executor) {
    assert_eq!(m.settle(10_000), ChannelState::Idle);
    let names = m
        .channel()
        .axes()
        .iter()
        .map(|a| a.name().to_string())
        .collect();
    let mut exec = Executor::new(parse("N10 G100 Z100 F3000\nN20 M30\n").unwrap(), names);
    exec.sync(m.channel());
    let (mut ids, mut out, mut k) = (Vec::new(), Vec::new(), 0usize);
    loop {
        ids.extend(m.channel_mut().take_messages().iter().map(|x| x.id));
        match m.channel().state() {
            ChannelState::Aborted => break,
            ChannelState::Idle => {
                let step = exec.step(m.channel_mut(), &mut out);
                for Event::Output(_) in out.drain(..) {}
                if step == Step::End {
                    break;
                }
            }
            _ => {
                assert!(k < 100_000);
                m.step();
                k += 1;
                each(m, k);
            }
        }
    }
    ids.extend(m.channel_mut().take_messages().iter().map(|x| x.id));
    (ids, exec)
}
