//! An option a subcommand does not support for the chosen link is refused — exit 2, a message
//! naming the option and the link — never accepted and silently ignored (issue 14, item 4:
//! `can scan --pcap`, `scan --candump` and `run --link canopen-emu --pcap` exited 0 and wrote
//! nothing). Every refused file must not have been created.

use crate::common::cli;

use cli::{fieldprobe, stderr};

/// `args` (with `FILE` replaced by a path in a fresh directory) exits 2, its message names
/// `option` and `link`, and FILE does not exist afterwards.
#[track_caller]
fn refused(args: &[&str], option: &str, link: &str) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("capture.out");
    let f = file.to_str().unwrap();
    let args: Vec<&str> = args
        .iter()
        .map(|a| if *a == "FILE" { f } else { a })
        .collect();
    let o = fieldprobe(&args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert!(
        err.contains(option),
        "{args:?}: message does not name {option}: {err}"
    );
    assert!(
        err.contains(link),
        "{args:?}: message does not name {link}: {err}"
    );
    assert!(!file.exists(), "{args:?}: {f} was written");
}

#[test]
fn pcap_on_can_links_is_refused() {
    let _one_module = crate::gate::enter(module_path!());
    refused(
        &["can", "scan", "--link", "canopen-emu", "--pcap", "FILE"],
        "--pcap",
        "canopen-emu",
    );
    refused(
        &[
            "can",
            "dump",
            "--link",
            "canopen-emu",
            "--seconds",
            "0",
            "--pcap",
            "FILE",
        ],
        "--pcap",
        "canopen-emu",
    );
    refused(
        &[
            "sdo",
            "read",
            "--link",
            "canopen-emu",
            "--node",
            "1",
            "0x1000",
            "--pcap",
            "FILE",
        ],
        "--pcap",
        "canopen-emu",
    );
    refused(
        &[
            "run",
            "examples/nc/hello.nc",
            "--link",
            "canopen-emu",
            "--pcap",
            "FILE",
        ],
        "--pcap",
        "canopen-emu",
    );
    refused(
        &[
            "run",
            "examples/nc/hello.nc",
            "--link",
            "sim",
            "--pcap",
            "FILE",
        ],
        "--pcap",
        "sim",
    );
}

#[test]
fn candump_on_ethercat_links_is_refused() {
    let _one_module = crate::gate::enter(module_path!());
    refused(&["scan", "--candump", "FILE"], "--candump", "ethercat-emu");
    refused(
        &[
            "sdo",
            "read",
            "--device",
            "1",
            "0x1000",
            "--candump",
            "FILE",
        ],
        "--candump",
        "ethercat-emu",
    );
    refused(
        &[
            "idn",
            "read",
            "--device",
            "3",
            "S-0-0092",
            "--set",
            "Z.drive=sercos-ax5000",
            "--candump",
            "FILE",
        ],
        "--candump",
        "ethercat-emu",
    );
    refused(
        &[
            "run",
            "examples/nc/hello.nc",
            "--link",
            "ethercat-emu",
            "--candump",
            "FILE",
        ],
        "--candump",
        "ethercat-emu",
    );
    refused(
        &[
            "run",
            "examples/nc/hello.nc",
            "--link",
            "sim",
            "--candump",
            "FILE",
        ],
        "--candump",
        "sim",
    );
}

#[test]
fn cycle_log_and_real_time_options_on_virtual_time_links_are_refused() {
    let _one_module = crate::gate::enter(module_path!());
    for link in ["sim", "canopen-emu", "ethercat-emu"] {
        refused(
            &[
                "run",
                "examples/nc/hello.nc",
                "--link",
                link,
                "--cycle-log",
                "FILE",
            ],
            "--cycle-log",
            link,
        );
        refused(
            &[
                "run",
                "examples/nc/hello.nc",
                "--link",
                link,
                "--rt-priority",
                "10",
            ],
            "--rt-priority",
            link,
        );
    }
}

#[test]
fn machine_options_on_links_to_a_real_bus_are_refused() {
    let _one_module = crate::gate::enter(module_path!());
    // The machine file describes the emulated devices only; on a real bus it would be ignored.
    // Refused before the bus is opened (these interfaces need not exist).
    refused(
        &["can", "scan", "--link", "canopen-udp", "--machine", "FILE"],
        "--machine",
        "canopen-udp",
    );
    refused(
        &[
            "sdo",
            "read",
            "--link",
            "socketcan:vcan0",
            "--node",
            "1",
            "0x1000",
            "--set",
            "Z.node=5",
        ],
        "--set Z.node=5",
        "socketcan:vcan0",
    );
    refused(
        &[
            "scan",
            "--link",
            "ethercat:nonexistent0",
            "--set",
            "Z.drive=sercos-ax5000",
        ],
        "--set Z.drive=sercos-ax5000",
        "ethercat:nonexistent0",
    );
}

#[test]
fn commands_on_the_wrong_bus_family_name_the_link() {
    let _one_module = crate::gate::enter(module_path!());
    refused(
        &["scan", "--link", "canopen-emu"],
        "can scan",
        "canopen-emu",
    );
    refused(
        &[
            "idn",
            "read",
            "--link",
            "canopen-emu",
            "--device",
            "0",
            "S-0-0092",
        ],
        "--link",
        "canopen-emu",
    );
    refused(
        &["can", "scan", "--link", "ethercat-emu"],
        "--link",
        "ethercat-emu",
    );
}

#[test]
fn supported_captures_still_work() {
    let _one_module = crate::gate::enter(module_path!());
    // The same options where the link supports them: written, exit 0.
    let dir = tempfile::tempdir().unwrap();
    let pcap = dir.path().join("scan.pcap");
    let o = fieldprobe(&["scan", "--pcap", pcap.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        std::fs::metadata(&pcap).unwrap().len() > 24,
        "pcap header only"
    );
    let log = dir.path().join("scan.log");
    let o = fieldprobe(&[
        "can",
        "scan",
        "--link",
        "canopen-emu",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(&log).unwrap();
    // SDO requests to 0x1000 of every node id: 0x601 … 0x67F.
    assert!(
        text.lines().filter(|l| l.contains(" 6")).count() >= 127,
        "{text}"
    );
}
