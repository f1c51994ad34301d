//! `fieldprobe esi show FILE [--device PRODUCT_CODE] [--objects]`: exit 0 with the device
//! facts on stdout; a broken file → exit 2 with the parser's `file:line:column: path: problem`
//! on stderr. Expected lines by hand from esi/fieldprobe-cia402-servo.xml.

use crate::common::cli;
use cli::{fieldprobe, stderr, stdout};

const SERVO: &str = "esi/fieldprobe-cia402-servo.xml";

#[test]
fn show_servo() {
    let o = fieldprobe(&["esi", "show", SERVO]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    for line in [
        "vendor: 0x00000FB0 fieldprobe emulated devices",
        "device FP-CIA402-SERVO: fieldprobe CiA 402 servo drive (touch probe)",
        "  identity: vendor 0x00000FB0, product code 0x00010402, revision 0x00010000",
        "  mailbox: CoE (SdoInfo, PdoAssign, PdoConfig, CompleteAccess, SegmentedSdo); data link layer",
        "    SM0 MBoxOut: start 0x1000, default size 128, control 0x26, enabled",
        "    SM1 MBoxIn: start 0x1080, default size 128, control 0x22, enabled",
        "    SM2 Outputs: start 0x1100, default size 9, control 0x64, enabled",
        "    SM3 Inputs: start 0x1180, default size 31, control 0x20, enabled",
        "  RxPDO 0x1600 RxPDO 1 (CSP + touch probe): SM2, 72 bits, mandatory",
        "    0x6040:00 16 bits Controlword (UINT)",
        "    0x6060:00  8 bits Modes of operation (SINT)",
        "  TxPDO 0x1A00 TxPDO 1 (CSP + touch probe): SM3, 248 bits, mandatory",
        "    0x60BA:00 32 bits Touch probe 1 positive edge (DINT)",
        "    0x6077:00 16 bits Torque actual value (INT)",
        "  DC op modes: 2",
        "    FreeRun: assign activate 0x0000 (SM-synchronous (no DC))",
        "    DcSync: assign activate 0x0300, cycle SYNC0 0 ns (factor 1), shift SYNC0 0 ns",
        "  eeprom: 2048 bytes",
    ] {
        assert!(out.contains(line), "missing {line:?} in\n{out}");
    }
    let objects = out
        .lines()
        .find(|l| l.starts_with("  objects: "))
        .expect("objects line");
    let n: usize = objects["  objects: ".len()..].parse().unwrap();
    let xml = std::fs::read_to_string(format!("{}/{SERVO}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    assert_eq!(n, xml.matches("<Object>").count(), "{out}");
    assert!(!out.contains("0x6065 "), "no object list without --objects");
}

#[test]
fn show_objects_lists_defaults() {
    let o = fieldprobe(&["esi", "show", SERVO, "--objects"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    // header comment of the file: 0x6065 = 300000, 0x6072 = 3000
    let l6065 = out
        .lines()
        .find(|l| l.starts_with("    0x6065 "))
        .expect(&out);
    assert!(l6065.ends_with("default 300000"), "{l6065}");
    let l6072 = out
        .lines()
        .find(|l| l.starts_with("    0x6072 "))
        .expect(&out);
    assert!(l6072.ends_with("default 3000"), "{l6072}");
}

#[test]
fn device_filter() {
    let o = fieldprobe(&["esi", "show", SERVO, "--device", "0x10402"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("device FP-CIA402-SERVO"));
    let o = fieldprobe(&["esi", "show", SERVO, "--device", "#x10403"]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("no device with product code 0x00010403")
            && err.contains("0x00010402 (FP-CIA402-SERVO)"),
        "{err}"
    );
}

#[test]
fn coupler_without_mailbox() {
    let o = fieldprobe(&["esi", "show", "esi/fieldprobe-ek1100.xml"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}");
    assert!(out.contains("  mailbox: none"), "{out}");
    assert!(out.contains("  sync managers: 0"), "{out}");
    assert!(out.contains("  objects: 0"), "{out}");
}

#[test]
fn broken_file_exits_2_with_the_parsers_error() {
    let dir = tempfile::tempdir().unwrap();
    let xml = std::fs::read_to_string(format!("{}/{SERVO}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    // drop the <Index> of the first RxPDO entry
    let from = "<Index>#x6040</Index>";
    let rx = xml.find("<RxPdo").unwrap();
    let at = rx + xml[rx..].find(from).unwrap();
    let entry = xml[..at].rfind("<Entry>").unwrap();
    let entry_line = xml[..entry].matches('\n').count() + 1;
    assert_eq!(xml[..at].matches('\n').count(), entry_line);
    let broken = dir.path().join("broken.xml");
    std::fs::write(
        &broken,
        format!("{}{}", &xml[..at], &xml[at + from.len()..]),
    )
    .unwrap();
    let o = fieldprobe(&["esi", "show", broken.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stdout(&o));
    let err = stderr(&o);
    assert!(
        err.contains(&format!("broken.xml:{entry_line}:"))
            && err.contains("EtherCATInfo/Descriptions/Devices/Device/RxPdo/Entry[1]")
            && err.contains("missing element <Index>"),
        "{err}"
    );
    assert!(stdout(&o).is_empty());

    // not well-formed: truncated
    let cut = dir.path().join("cut.xml");
    std::fs::write(&cut, &xml[..xml.len() / 2]).unwrap();
    let o = fieldprobe(&["esi", "show", cut.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("cut.xml:"), "{}", stderr(&o));

    // missing file
    let o = fieldprobe(&["esi", "show", "esi/no-such-file.xml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("no-such-file.xml: cannot read"),
        "{}",
        stderr(&o)
    );
}
