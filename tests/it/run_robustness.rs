//! Nothing a user writes in a program may panic the process or corrupt state: random blocks from
//! the supported vocabulary (including zero / negative / huge values, arcs with inconsistent radii,
//! bad `#MSG` formats) run to an end or to an error, within a bounded number of cycles.

use fieldprobe::machine::{Machine, RunStatus};
use fieldprobe::nc::parser::parse;
use fieldprobe::params::MachineConfig;
use proptest::prelude::*;

fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        (-400i32..=400).prop_map(|v| v.to_string()),
        (-40000i32..=40000).prop_map(|v| format!("{}", f64::from(v) / 100.0)),
        Just("0".to_string()),
        Just("99999999999".to_string()),
        Just("-0.000001".to_string()),
        Just("[1/3]".to_string()),
        Just("V.A.ABS.X".to_string()),
        Just("[V.A.+SWE.Y - 1]".to_string()),
    ]
}

fn block() -> impl Strategy<Value = String> {
    let g = prop::sample::select(vec![
        "G00", "G01", "G02", "G03", "G17", "G18", "G19", "G90", "G91", "G92", "G98", "G99", "G161",
        "G162",
    ]);
    let axis = prop::sample::select(vec!["X", "Y", "Z", "I", "J", "K", "F"]);
    let word = (axis, value()).prop_map(|(a, v)| format!("{a}{v}"));
    let msg = prop::sample::select(vec![
        "#MSG SYN[\"%f\", V.A.ABS.X]",
        "#MSG SYN[\"%d %s\", V.A.PROG.Y, \"t\"]",
        "#MSG SYN[\"%f %f\", 1]",
        "#MSG SYN[\"%q\", 1]",
        "#MSG SYN[\"%%\"]",
    ]);
    prop_oneof![
        4 => (prop::collection::vec(g, 0..3), prop::collection::vec(word, 0..4))
            .prop_map(|(g, w)| format!("{} {}", g.join(" "), w.join(" "))),
        1 => msg.prop_map(str::to_string),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, failure_persistence: None, .. ProptestConfig::default() })]

    #[test]
    fn random_programs_never_panic_and_always_end(blocks in prop::collection::vec(block(), 1..10), referenced in any::<bool>()) {
        let mut src = String::from("%fuzz\n");
        for (k, b) in blocks.iter().enumerate() {
            src.push_str(&format!("N{} {b}\n", (k + 1) * 10));
        }
        src.push_str("M30\n");
        let Ok(prog) = parse(&src) else { return Ok(()); };
        let mut cfg = MachineConfig::default_machine();
        for a in &mut cfg.axes {
            a.referenced = referenced;
        }
        let mut m = Machine::new(&cfg).unwrap();
        m.max_cycles = 50_000;
        let r = m.run_program(&prog, &mut |_| {});
        // Ended one way or the other; an aborted run carries the errors of one cause: the block
        // that aborts (an arc error is not followed by a "program aborted"). The one check that
        // names several errors for one block is the software-limit path check, one per violated
        // limit (120002 / 120003: a huge arc leaves X and Y on both sides).
        if r.status == RunStatus::Aborted {
            let errors: Vec<_> = r.messages().into_iter().filter(|x| x.is_error()).collect();
            prop_assert!(!errors.is_empty(), "{}\n{:?}", src, r.message_ids());
            if errors.len() > 1 {
                prop_assert!(
                    errors.iter().all(|e| matches!(e.id, 120002 | 120003) && e.block == errors[0].block),
                    "{}\n{:?}", src, r.message_ids()
                );
            }
        }
        for a in m.channel().axes() {
            prop_assert!(a.command().is_finite() && a.actual().is_finite());
        }
    }
}
