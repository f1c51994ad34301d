//! The EtherCAT command line: `scan`, `sdo read|write`, `idn read|write` on the emulated segment
//! of the machine file, `run` over EtherCAT by default with `--pcap`. Expected identities come
//! from the ESI XML text (read here without the ESI parser); the SERCOS value from the drive file.

use crate::common::cli;
use cli::{fieldprobe, stderr, stdout};

/// `ProductCode="#x…"` and `<Type …>NAME</Type>` of the first device, from the XML text.
fn identity(esi: &str) -> (u32, String) {
    let text = std::fs::read_to_string(format!("{}/{esi}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let at = text.find("ProductCode=\"#x").unwrap() + 15;
    let hex: String = text[at..]
        .chars()
        .take_while(|c| c.is_ascii_hexdigit())
        .collect();
    let t = text.find("<Type ").unwrap();
    let start = t + text[t..].find('>').unwrap() + 1;
    let end = start + text[start..].find('<').unwrap();
    (
        u32::from_str_radix(&hex, 16).unwrap(),
        text[start..end].to_string(),
    )
}

#[test]
fn scan_lists_the_emulated_segment_of_the_machine() {
    let o = fieldprobe(&["scan", "--set", "Z.drive=sercos-ax5000"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    let lines: Vec<&str> = out.lines().skip(1).collect();
    assert_eq!(lines.len(), 4, "{out}");
    let expect = [
        (0, "esi/fieldprobe-ek1100.xml"),
        (1, "esi/fieldprobe-cia402-servo.xml"),
        (2, "esi/fieldprobe-cia402-servo.xml"),
        (3, "esi/fieldprobe-ax5000-sercos.xml"),
    ];
    for (line, (pos, esi)) in lines.iter().zip(expect) {
        let (product, name) = identity(esi);
        let cols: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(cols[0], pos.to_string(), "{line}");
        assert_eq!(cols[1], format!("{:#06x}", 0x1000 + pos), "{line}");
        assert_eq!(cols[2], "0x00000fb0", "{line}");
        assert_eq!(cols[3], format!("{product:#010x}"), "{line}");
        assert_eq!(cols[5], "PREOP", "{line}");
        assert!(line.ends_with(&name), "{line} vs {name}");
    }
}

#[test]
fn sdo_read_write_and_abort_in_words() {
    let (product, _) = identity("esi/fieldprobe-cia402-servo.xml");
    let o = fieldprobe(&["sdo", "read", "--device", "1", "0x1018:02"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        stdout(&o).trim(),
        format!("0x1018:02 = {product} ({product:#x})")
    );
    // 0x1008 is longer than an expedited transfer: a normal / segmented upload.
    let o = fieldprobe(&["sdo", "read", "--device", "1", "0x1008"]);
    assert!(
        stdout(&o).contains("\"fieldprobe CiA 402 servo drive"),
        "{}",
        stdout(&o)
    );
    let o = fieldprobe(&["sdo", "write", "--device", "1", "0x6065:00", "12345"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o).trim(), "0x6065:00 written (4 bytes)");
    let o = fieldprobe(&["sdo", "read", "--device", "2", "0x5FFF:00"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("device 2")
            && stderr(&o).contains("0x5fff:00")
            && stderr(&o).contains("0x06020000 (object does not exist in the object dictionary)"),
        "{}",
        stderr(&o)
    );
    let o = fieldprobe(&["sdo", "read", "--device", "7", "0x1000"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("device 7: no such SubDevice (4 found"),
        "{}",
        stderr(&o)
    );
    let o = fieldprobe(&["sdo", "read", "--device", "1", "0x16000"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("index 0 … 65535 (0x0000 … 0xFFFF)"),
        "{}",
        stderr(&o)
    );
    let o = fieldprobe(&["sdo", "write", "--device", "1", "0x6040", "70000"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("out of range for u16"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn idn_read_and_write_over_soe() {
    let sercos = ["--set", "Z.drive=sercos-ax5000", "--device", "3"];
    let o = fieldprobe(&[&["idn", "read"][..], &sercos, &["S-0-0092"]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // drives/sercos-ax5000.toml [sercos] idn: S-0-0092 = 1000.
    assert!(stdout(&o).starts_with("S-0-0092 = 1000"), "{}", stdout(&o));
    let o = fieldprobe(&[&["idn", "write"][..], &sercos, &["S-0-0092", "500"]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = fieldprobe(&[&["idn", "write"][..], &sercos, &["S-0-0051", "5"]].concat());
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("device 3 (FP-AX5000-SOE)") && stderr(&o).contains("0x7004"),
        "{}",
        stderr(&o)
    );
    let o = fieldprobe(&[&["idn", "read"][..], &sercos, &["Q-0-0092"]].concat());
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn run_goes_over_ethercat_by_default_and_captures_frames() {
    let dir = tempfile::tempdir().unwrap();
    let pcap = dir.path().join("meas1.pcap");
    let pcap_s = pcap.to_str().unwrap();
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--pcap",
        pcap_s,
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("V.A.MEAS.ACS.VALUE.Z=100.000000"));
    // The capture holds the run's EtherCAT frames, both directions, every one decodable.
    let recs = fieldprobe::bus::ethercat::pcap::read_file(&pcap).unwrap();
    assert!(recs.len() > 1000, "{} frames", recs.len());
    let mut returned = 0;
    for r in &recs {
        let f = fieldprobe::bus::ethercat::wire::Frame::parse(&r.data).unwrap();
        assert!(f.datagrams().count() >= 1);
        returned += usize::from(r.data[6] & 0x02 != 0);
    }
    assert_eq!(returned * 2, recs.len(), "every frame came back once");
    // --pcap needs an EtherCAT link.
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--link",
        "sim",
        "--pcap",
        pcap_s,
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--pcap needs an EtherCAT link"),
        "{}",
        stderr(&o)
    );
    // A machine with a family the emulator does not play runs on the in-memory link.
    let o = fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--probe-at",
        "Z=100",
        "--set",
        "Z.drive=profidrive-t105",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}
