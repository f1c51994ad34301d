//! Issue 28 items 9, 10 and 11: inputs that used to be accepted and then misbehaved, each made to
//! happen here (a file written for it, a command line, an SDO request to the emulated node) with
//! the message that names the cause and the exit / abort code asserted.

use crate::common::cli::{fieldprobe, stderr, stdout};
use fieldprobe::bus::can::CanFrame;
use fieldprobe::bus::canopen::nmt::{self, NmtCommand};
use fieldprobe::drive::catalogue;
use fieldprobe::sim::canopen::{CanopenSegment, EmulatedNode};
use fieldprobe::units::Nanos;

const NODE: u8 = 5;

/// CiA 301 abort 0x0609_0030, "value range of parameter exceeded" / "invalid value for
/// parameter" (download only).
const INVALID_VALUE: u32 = 0x0609_0030;

fn write_file(dir: &std::path::Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

/// Expedited SDO download of 4 bytes to the node on the segment: `Err(abort code)`.
#[track_caller]
fn sdo_write_u32(seg: &mut CanopenSegment, index: u16, sub: u8, v: u32) -> Result<(), u32> {
    let [lo, hi] = index.to_le_bytes();
    let d = v.to_le_bytes();
    // CiA 301 §7.2.4.3.3: ccs 1, expedited, size indicated, 4 bytes.
    let req = [0x23, lo, hi, sub, d[0], d[1], d[2], d[3]];
    let out = seg.run(
        &[CanFrame::new(0x600 + u16::from(NODE), &req).unwrap()],
        Nanos(1_000_000),
    );
    let r: Vec<_> = out
        .iter()
        .filter(|f| f.id == 0x580 + u32::from(NODE))
        .collect();
    assert_eq!(r.len(), 1, "{out:?}");
    match r[0].data[0] {
        0x60 => Ok(()),
        0x80 => Err(u32::from_le_bytes([
            r[0].data[4],
            r[0].data[5],
            r[0].data[6],
            r[0].data[7],
        ])),
        c => panic!("unexpected SDO reply {c:#04x}"),
    }
}

/// Item 10: a PDO COB-ID on a restricted CAN-ID (CiA 301 §7.3.5) is refused by the emulated
/// node with abort 0x0609_0030, for TPDOs and RPDOs, and no frame ever leaves on 0x000.
#[test]
fn emulated_node_aborts_a_restricted_pdo_cob_id() {
    let def = catalogue::load("cia402-generic").unwrap();
    let mut seg = CanopenSegment::new(
        vec![EmulatedNode::new(NODE, &def).unwrap()],
        Nanos::from_micros(1000),
    );
    seg.run(&[], Nanos(0));
    // Destroy TPDO 1 first (bit 31): any identifier may be stored while it is not valid.
    assert_eq!(sdo_write_u32(&mut seg, 0x1800, 1, 0x8000_0000), Ok(()));
    for restricted in [
        0x000, 0x07F, 0x101, 0x180, 0x585, 0x605, 0x6E0, 0x705, 0x7FF,
    ] {
        assert_eq!(
            sdo_write_u32(&mut seg, 0x1800, 1, restricted),
            Err(INVALID_VALUE),
            "TPDO on {restricted:#05x}"
        );
        assert_eq!(
            sdo_write_u32(&mut seg, 0x1400, 1, restricted),
            Err(INVALID_VALUE),
            "RPDO on {restricted:#05x}"
        );
    }
    // A 29-bit identifier the node does not serve.
    assert_eq!(
        sdo_write_u32(&mut seg, 0x1800, 1, 0x2000_0185),
        Err(INVALID_VALUE)
    );
    // Allowed identifiers at the edges of the restricted ranges are taken.
    assert_eq!(sdo_write_u32(&mut seg, 0x1800, 1, 0x8000_0000), Ok(()));
    assert_eq!(sdo_write_u32(&mut seg, 0x1800, 1, 0x0000_0181), Ok(()));
    // Started and synchronised, the node sends nothing on the NMT identifier.
    let mut out = seg.run(&[NmtCommand::Start.frame(NODE)], Nanos(2_000_000));
    for ms in 3..10 {
        out.extend(seg.run(&[nmt::sync()], Nanos(ms * 1_000_000)));
    }
    assert!(out.iter().any(|f| f.id == 0x181), "{out:?}");
    assert!(out.iter().all(|f| f.id != 0x000), "{out:?}");
}

/// Item 10: an EDS whose TPDO 1 COB-ID is the NMT identifier is refused by `sim canopen --eds`,
/// naming the file, the object and the allowed CAN-IDs; exit 2 before any bus is opened.
#[test]
fn sim_canopen_refuses_an_eds_with_a_restricted_pdo_cob_id() {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/durand_cia402.eds"),
    )
    .unwrap();
    let bad = text.replace("DefaultValue=$NODEID+0x40000180", "DefaultValue=0x40000000");
    assert_ne!(bad, text, "the EDS has TPDO 1 at $NODEID+0x40000180");
    let dir = tempfile::tempdir().unwrap();
    let eds = write_file(dir.path(), "nmt_tpdo.eds", &bad);
    let o = fieldprobe(&[
        "sim",
        "canopen",
        "--bus",
        "udp",
        "--node",
        "5",
        "--eds",
        &eds,
        "--seconds",
        "0.1",
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("nmt_tpdo.eds"), "{err}");
    assert!(err.contains("0x1800:01"), "{err}");
    assert!(err.contains("CAN-ID 0x000 is restricted"), "{err}");
    assert!(err.contains("0x181-0x580"), "{err}");
}

/// Item 10: `sim canopen --drive` with a drive the CANopen emulator cannot play.
#[test]
fn sim_canopen_refuses_a_drive_it_cannot_play() {
    for drive in ["kl5101-terminal", "profidrive-t105", "sercos-ax5000"] {
        let o = fieldprobe(&[
            "sim",
            "canopen",
            "--bus",
            "udp",
            "--node",
            "5",
            "--drive",
            drive,
            "--seconds",
            "0.1",
        ]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{drive}: {err}");
        assert!(err.contains(&format!("drive '{drive}'")), "{err}");
        assert!(err.contains("CANopen emulator cannot play"), "{err}");
        assert!(err.contains("allowed: cia402-"), "{err}");
        assert!(!err.contains("allowed: sercos"), "{err}");
    }
}

/// Item 10: `sim ethercat --drive POS=DRIVE` with a drive the EtherCAT emulator cannot play.
#[test]
fn sim_ethercat_refuses_a_drive_it_cannot_play() {
    for drive in ["profidrive-t105", "kl5101-terminal", "ax2000-lightbus"] {
        let spec = format!("0={drive}");
        let o = fieldprobe(&[
            "sim",
            "ethercat",
            "--iface",
            "fp-no-such-if",
            "--device",
            "esi/fieldprobe-cia402-servo.xml",
            "--drive",
            &spec,
            "--seconds",
            "0.1",
        ]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{drive}: {err}");
        assert!(err.contains(&format!("--drive 0={drive}")), "{err}");
        assert!(err.contains("EtherCAT emulator cannot play"), "{err}");
        assert!(
            err.contains("sercos-ax5000") && err.contains("el5101-terminal"),
            "{err}"
        );
    }
}

/// Item 10: `idn read` of a CoE-only device (a CiA 402 servo): the mailbox error reply 0x0002
/// says the device does not support SoE; exit 1 (the device refused).
#[test]
fn idn_read_of_a_coe_only_device_says_it_does_not_support_soe() {
    let o = fieldprobe(&["idn", "read", "--device", "1", "S-0-0092"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("device 1"), "{err}");
    assert!(err.contains("does not support SoE"), "{err}");
    assert!(err.contains("unsupported protocol"), "{err}");
}

/// Item 10: a UTF-8 byte-order mark in front of the first line is skipped.
#[test]
fn nc_program_with_a_byte_order_mark_runs() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(
        dir.path(),
        "bom.nc",
        "\u{feff}%bom\nN10 G01 X10 F1000\nN20 #MSG SYN[\"X=%f\", V.A.ABS.X]\nN30 M30\n",
    );
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o), "X=10.000000\n");
    // Only at the very start: elsewhere it is still a character no block may hold.
    let p = write_file(
        dir.path(),
        "bom2.nc",
        "N10 G01 X10 F1000\n\u{feff}N20 M30\n",
    );
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("bom2.nc:2:1:"), "{}", stderr(&o));
}

/// Item 10: `#DRIVE` on a drive without drive functions renders the empty list in words.
#[test]
fn drive_function_missing_on_a_drive_without_functions_says_it_has_none() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(
        dir.path(),
        "nofn.nc",
        "N10 G01 X1 F1000\nN20 G01 X2\nN30 #DRIVE RD SYN [AX=Z KEY=TORQUE_LIMIT P=P1]\nN40 M30\n",
    );
    let o = fieldprobe(&[
        "run",
        &p,
        "--link",
        "sim",
        "--set",
        "Z.drive=kl5101-terminal",
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("has no function TORQUE_LIMIT; its definition has no drive functions (N30)"),
        "{err}"
    );
    assert!(!err.contains("it has  "), "{err}");
}

/// Item 9: a line above the cap is refused with file, line and the cap; exit 2, and the
/// refusal does not first collect the line (it would take ~400 MB for 32 MiB).
#[test]
fn nc_line_longer_than_the_cap_is_refused() {
    use fieldprobe::limits::MAX_NC_LINE_CHARS;
    let dir = tempfile::tempdir().unwrap();
    let long = format!(
        "N10 G01 X1 F1000\nN20 #MSG SYN[\"{}\"]\nN30 M30\n",
        "a".repeat(MAX_NC_LINE_CHARS)
    );
    let p = write_file(dir.path(), "long.nc", &long);
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("long.nc:2:1:"), "{err}");
    assert!(
        err.contains(&format!("limit of {MAX_NC_LINE_CHARS} characters")),
        "{err}"
    );
    // A block joined from continued lines is held to the same cap (a '[' that never closes).
    let line = format!("X[{}\n", "1+".repeat(1000));
    let open = format!("N10 G01 X1 F1000\nN20 G01 {}", line.repeat(40));
    let p = write_file(dir.path(), "open.nc", &open);
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("open.nc:2:1:"), "{err}");
    assert!(err.contains("is a '[' not closed?"), "{err}");
    // A line at the cap is still read.
    let ok = format!(
        "N10 G01 X1 F1000\nN20 #MSG SYN[\"{}\"]\nN30 M30\n",
        "a".repeat(MAX_NC_LINE_CHARS - 20)
    );
    let p = write_file(dir.path(), "ok.nc", &ok);
    let o = fieldprobe(&["run", &p, "--link", "sim"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

/// Item 11: every `fuzz/seeds/…` directory fuzz/README.md names exists.
#[test]
fn fuzz_readme_names_only_seed_directories_that_exist() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("fuzz/README.md")).unwrap();
    let mut named = 0;
    for (i, _) in readme.match_indices("fuzz/seeds/") {
        let rest = &readme[i + "fuzz/seeds/".len()..];
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        // `fuzz/seeds/TARGET` is the placeholder.
        if name.is_empty() || name == "TARGET" {
            continue;
        }
        named += 1;
        assert!(
            root.join("fuzz/seeds").join(&name).is_dir(),
            "fuzz/README.md names fuzz/seeds/{name}, which does not exist"
        );
    }
    // The README also names no seed directory for the targets that read shared files.
    assert!(!readme.contains("fuzz/seeds/eds"), "{named} named");
}

/// Item 9: a parsed program is held once — its clones (the executor's, `run`'s check) share
/// the blocks — and its items stay small (the rare large ones are boxed).
#[test]
fn parsed_program_is_shared_and_its_items_are_small() {
    use fieldprobe::nc::ast::{Expr, Item};
    let p = fieldprobe::nc::parser::parse("N10 G01 X1 Y2 F1000\nN20 X[INDP_SYN POS5]\nN30 M30\n")
        .unwrap();
    let q = p.clone();
    assert!(std::sync::Arc::ptr_eq(&p.blocks, &q.blocks));
    assert!(
        std::mem::size_of::<Expr>() <= 48,
        "{}",
        std::mem::size_of::<Expr>()
    );
    assert!(
        std::mem::size_of::<Item>() <= 88,
        "{}",
        std::mem::size_of::<Item>()
    );
}
