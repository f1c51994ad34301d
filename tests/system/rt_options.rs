//! Issue 13: the real-time options of `fieldprobe run` take effect or are a clear error (exit 2)
//! naming the option and the reason — never a silent fallback; and they, like `--cycle-log`, are
//! refused on the links that run on virtual time.

use std::process::Command;

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", "examples/nc/hello.nc"])
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn real_time_options_are_refused_on_virtual_time_links() {
    let _one_module = crate::gate::enter(module_path!());
    for link in ["sim", "ethercat-emu", "canopen-emu"] {
        for opt in [
            vec!["--rt-priority", "50"],
            vec!["--cpu", "0"],
            vec!["--mlock"],
            vec!["--cycle-log", "/tmp/fieldprobe-never-written.csv"],
        ] {
            let mut args = vec!["--link", link];
            args.extend(&opt);
            let (code, err) = run(&args);
            assert_eq!(code, Some(2), "{link} {opt:?}: {err}");
            assert!(
                err.contains(opt[0])
                    && err.contains("only for links that leave the process")
                    && err.contains(&format!("--link {link} runs on virtual time")),
                "{link} {opt:?}: {err}"
            );
        }
    }
    assert!(!std::path::Path::new("/tmp/fieldprobe-never-written.csv").exists());
}

#[test]
fn impossible_real_time_options_name_the_reason() {
    let _one_module = crate::gate::enter(module_path!());
    // On a link that leaves the process the options are applied before it opens: a CPU that
    // does not exist and a priority outside SCHED_FIFO's range are errors with the reason.
    let (code, err) = run(&["--link", "ethercat:fp-no-such-if", "--cpu", "100000"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--cpu 100000: no such CPU"), "{err}");
    let (code, err) = run(&["--link", "ethercat:fp-no-such-if", "--rt-priority", "0"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--rt-priority 0: SCHED_FIFO priorities are 1 ..= 99"),
        "{err}"
    );
    // A permitted set of options gets past them to the link, which then names the interface.
    let (code, err) = run(&["--link", "ethercat:fp-no-such-if", "--cpu", "0"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("fp-no-such-if") && !err.contains("--cpu"),
        "{err}"
    );
}

use crate::common::veth;

#[test]
fn refused_by_the_system_says_what_would_permit_it() {
    let _one_module = crate::gate::enter(module_path!());
    // The options are applied once the link is open (the start-up runs without them). In an
    // unprivileged user namespace (`scripts/netns.sh`: veth pair, `fieldprobe sim ethercat` on
    // v1) the process has no CAP_SYS_NICE / CAP_IPC_LOCK on the host: SCHED_FIFO, and mlockall
    // with a 0 memlock limit, are refused — with the reason, exit 2, before any cycle runs.
    for (opt, prelude, want) in [
        (
            "--rt-priority 50",
            "",
            "--rt-priority 50: not permitted: SCHED_FIFO needs CAP_SYS_NICE",
        ),
        (
            "--mlock",
            "ulimit -l 0; ",
            "--mlock: Operation not permitted (needs CAP_IPC_LOCK",
        ),
    ] {
        let Some((code, stdout, stderr)) = veth::netns::meas1_against_sim(
            "refused_by_the_system_says_what_would_permit_it",
            veth::veth_probe,
            &["scripts/netns.sh"],
            prelude,
            "ethercat --iface v1 --device esi/fieldprobe-ek1100.xml \
             --device esi/fieldprobe-cia402-servo.xml:3",
            &format!("ethercat:v0 {opt}"),
        ) else {
            return;
        };
        assert_eq!(code, Some(2), "{opt}: {stdout}{stderr}");
        assert!(stderr.contains(want), "{opt}: {stderr}");
        assert!(stdout.is_empty(), "{opt}: no cycle ran: {stdout}");
    }
}

#[test]
fn the_emulators_take_the_same_options_and_refuse_impossible_ones() {
    let _one_module = crate::gate::enter(module_path!());
    // `sim ethercat` / `sim canopen` play devices with their own hardware clock; on a shared
    // machine their serve threads get the same knobs as the master. An impossible value is
    // refused before any interface or bus is opened (the interface here does not exist), with
    // the option and the reason, exit 2.
    for (sub, args) in [
        (
            "ethercat",
            &[
                "--iface",
                "fp-no-such-if",
                "--device",
                "esi/fieldprobe-cia402-servo.xml",
            ][..],
        ),
        (
            "canopen",
            &["--bus", "socketcan:fp-no-such-if", "--node", "1"][..],
        ),
    ] {
        for (opt, want) in [
            (
                &["--rt-priority", "100"][..],
                "--rt-priority 100: SCHED_FIFO priorities are 1 ..= 99",
            ),
            (&["--cpu", "100000"][..], "--cpu 100000: no such CPU"),
        ] {
            let o = Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .args(["sim", sub])
                .args(args)
                .args(opt)
                .args(["--seconds", "1"])
                .output()
                .expect("fieldprobe runs");
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "sim {sub} {opt:?}: {err}");
            assert!(err.contains(want), "sim {sub} {opt:?}: {err}");
            assert!(!err.contains("listening"), "sim {sub} {opt:?}: {err}");
        }
    }
}
