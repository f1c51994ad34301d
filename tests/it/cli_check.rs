//! `fieldprobe check` (seed 004 §6): the commissioning check reads each drive's settings over
//! the link and names every mismatch with the axis parameters; exit 0 = nothing found, 1 = a
//! finding, 2 = bad input. Expected findings by hand from the seed's setting tables:
//! SERCOS §6.1 (P-AXIS-00060 = 2 needs S-0-0303 = 405 probe 1 enable, S-0-0307 = 409 probe 1
//! positive latched), Lightbus §6.2 (IN2MODE = 26), PROFIdrive §6.5 (P0660 = 80), CiA 402 §6.4
//! (0x60B9 and the selected 0x60BA … 0x60BD in the TxPDO, 0x60B8 in the RxPDO).

use crate::common::cli;
use cli::{fieldprobe, stdout};

/// A built-in drive file with `from` replaced by `to`, written to `dir`.
fn variant(dir: &tempfile::TempDir, builtin: &str, from: &str, to: &str) -> String {
    let path = format!("{}/drives/{builtin}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{builtin}.toml has no '{from}'");
    let out = dir.path().join(format!("{builtin}-variant.toml"));
    std::fs::write(&out, text.replacen(from, to, 1)).unwrap();
    out.to_string_lossy().into_owned()
}

#[test]
fn every_builtin_family_passes_the_check_as_shipped() {
    for drive in [
        "cia402-generic",
        "cia402-drive-defined",
        "sercos-ax5000",
        "profidrive-t105",
        "ax2000-lightbus",
        "kl5101-terminal",
        "el5101-terminal",
    ] {
        let set = format!("Z.drive={drive}");
        let o = fieldprobe(&["check", "--set", &set]);
        let out = stdout(&o);
        assert_eq!(o.status.code(), Some(0), "{drive}: {out}");
        assert!(out.contains(&format!("Z ({drive}, ")), "{drive}: {out}");
        assert_eq!(out.matches("  ok\n").count(), 3, "{drive}: {out}");
    }
}

#[test]
fn sercos_realtime_bit_mismatch_is_named() {
    // The drive ships with real-time bit 1 allocated (S-0-0301 = 405, S-0-0305 = 409); the axis
    // asks for bit 2.
    let o = fieldprobe(&[
        "check",
        "--set",
        "Z.drive=sercos-ax5000",
        "--set",
        "Z.P-AXIS-00060=2",
    ]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("S-0-0303 = 405"), "{out}");
    assert!(out.contains("S-0-0307 = 409"), "{out}");
    assert!(
        out.starts_with("X (cia402-generic, cia402):\n  ok\n"),
        "{out}"
    );
}

#[test]
fn lightbus_in2mode_and_profidrive_p0660_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let lb = variant(&dir, "ax2000-lightbus", "in2mode = 26", "in2mode = 3");
    let o = fieldprobe(&["check", "--set", &format!("Z.drive={lb}")]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("IN2MODE is 3") && out.contains("IN2MODE = 26"),
        "{out}"
    );
    // The same drive file named relative to a machine file in the same directory.
    let machine = dir.path().join("m.toml");
    std::fs::write(
        &machine,
        "[[axis]]\nname = \"X\"\ndrive = \"ax2000-lightbus-variant.toml\"\n",
    )
    .unwrap();
    let o = fieldprobe(&["check", "--machine", machine.to_str().unwrap()]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.starts_with("X (ax2000-lightbus, lightbus):\n  - "),
        "{out}"
    );

    let pd = variant(&dir, "profidrive-t105", "p0660 = 80", "p0660 = 0");
    let o = fieldprobe(&["check", "--set", &format!("Y.drive={pd}")]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("P0660 is 0") && out.contains("must be 80"),
        "{out}"
    );
}

#[test]
fn cia402_probe_value_outside_the_txpdo_is_named() {
    let dir = tempfile::tempdir().unwrap();
    // Probe 2 negative edge selects 0x60BD; drop it from the TxPDO.
    let f = variant(&dir, "cia402-generic", ", \"0x60BD:00\"", "");
    let o = fieldprobe(&[
        "check",
        "--set",
        &format!("Z.drive={f}"),
        "--set",
        "Z.P-AXIS-00517=2",
        "--set",
        "Z.P-AXIS-00518=NEG",
    ]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("0x60BD"), "{out}");
    // Probe 1 positive edge (0x60BA) is still mapped: no finding.
    let o = fieldprobe(&["check", "--set", &format!("Z.drive={f}")]);
    assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
}

#[test]
fn bad_drive_name_is_bad_input() {
    let o = fieldprobe(&["check", "--set", "Z.drive=no-such-drive"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no-such-drive") && err.contains("sercos-ax5000"),
        "{err}"
    );
}
