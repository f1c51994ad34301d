//! Issue 18, items 2 and 3: one number grammar for every option and argument (decimal, `0x`
//! hex, negative values without `--`; an object index without `0x` is decimal, with a note on
//! stderr) and `--type` with the CiA 301 basic types in fieldprobe's, IgH's and CiA 301's
//! spellings, little-endian.
//!
//! Expected values come from the specifications, computed here: CiA 301 data type sizes and
//! value ranges (Rust's `MIN` / `MAX` of the same widths), the little-endian transfer syntax
//! (CiA 301 §7.1.2: `to_le_bytes`), IEEE 754 bit patterns (`f32::to_bits`), the expedited SDO
//! download frame (CiA 301 §7.2.4.3.3: command 0x23 for 4 bytes, index LE, sub-index, data).
//!
//! Round trips need a device that keeps a written value between two commands: `fieldprobe sim
//! ethercat` on a veth pair (the emulated servo's CoE objects), and `fieldprobe sim canopen
//! --eds` over CAN-in-UDP with an EDS written here that has INTEGER64, UNSIGNED64, REAL32 and
//! REAL64 objects (the built-in dictionaries have no 64-bit or REAL objects). Both run in a
//! private user + network namespace; where that is not possible the test prints `SKIP`.

use crate::common::veth;

use std::ffi::OsString;
use std::process::Command;
use std::time::Duration;

/// `fieldprobe ARGS…` at most 60 s: (exit code, stdout, stderr).
fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let (status, out, err) = veth::netns::run_bounded(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR")),
        Duration::from_secs(60),
    );
    (status.and_then(|s| s.code()), out, err)
}

/// `run` that must exit 0; returns stdout.
#[track_caller]
fn ok(args: &[&str]) -> String {
    let (code, out, err) = run(args);
    assert_eq!(code, Some(0), "{args:?}: {out}{err}");
    out
}

/// The bytes of an `sdo read --type bytes` line: `0x6065:00 = [00 00 c0 bf] (4 bytes)`.
#[track_caller]
fn bytes_of(line: &str) -> Vec<u8> {
    let inner = line
        .split_once('[')
        .and_then(|(_, r)| r.split_once(']'))
        .unwrap_or_else(|| panic!("no [..] in {line:?}"))
        .0;
    inner
        .split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("hex byte"))
        .collect()
}

/// The value of an `sdo read` line: `0x6065:00 = -1.5 (0xbfc00000)` → `-1.5`.
#[track_caller]
fn value_of(line: &str) -> String {
    let v = line
        .split_once(" = ")
        .unwrap_or_else(|| panic!("no value in {line:?}"))
        .1;
    // The value, then ` (0x…)` or ` (N bytes)` (a string value may hold ` (` itself).
    v.rsplit_once(" (")
        .map_or(v, |(value, _)| value)
        .trim()
        .to_string()
}

// ---------------------------------------------------------------------------------------------
// The grammar
// ---------------------------------------------------------------------------------------------

#[test]
fn an_index_without_0x_is_decimal_and_says_so() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `sdo read --device 1 4104` silently read 0x4104. 4104 = 0x1008 (device name).
    let hex = format!("{:#06x}", 4104);
    assert_eq!(hex, "0x1008");
    for (target, id) in [("--device", "1"), ("--node", "1")] {
        let (code, out, err) = run(&["sdo", "read", target, id, "4104"]);
        assert_eq!(code, Some(0), "{target}: {out}{err}");
        assert!(out.starts_with(&format!("{hex}:00 = \"")), "{out}");
        assert_eq!(out, ok(&["sdo", "read", target, id, &hex]), "{target}");
        assert!(
            err.contains(&format!("object index 4104 (decimal) = {hex}")),
            "{target}: no note: {err}"
        );
        // Written in hex: no note.
        let (_, _, err) = run(&["sdo", "read", target, id, &hex]);
        assert!(!err.contains("note"), "{err}");
    }
    // A sub-index below 10 reads the same either way (no note); from 10 on, a decimal one is
    // noted (whatever the device answers).
    assert_eq!(
        ok(&["sdo", "read", "--device", "1", "0x1018:2"]),
        ok(&["sdo", "read", "--device", "1", "0x1018:0x02"])
    );
    let (_, _, err) = run(&["sdo", "read", "--device", "1", "0x1A00:16"]);
    assert!(err.contains("sub-index 16 (decimal) = 0x10"), "{err}");
    // No octal: 010 is ten.
    let (_, _, err) = run(&["sdo", "read", "--device", "1", "0x1A00:010"]);
    assert!(err.contains("sub-index 10 (decimal) = 0x0a"), "{err}");
}

#[test]
fn device_and_node_ids_in_hex() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `--device 0x1` and `--node 0x03` were refused ("invalid digit").
    assert_eq!(
        ok(&["sdo", "read", "--device", "0x1", "0x1000"]),
        ok(&["sdo", "read", "--device", "1", "0x1000"])
    );
    let by_hex = ok(&["sdo", "read", "--node", "0x03", "0x1018:1"]);
    assert_eq!(by_hex, ok(&["sdo", "read", "--node", "3", "0x1018:1"]));
    let drive = ["--set", "Z.drive=sercos-ax5000"];
    assert_eq!(
        ok(&[&["idn", "read", "--device", "0x3", "S-0-0092"][..], &drive].concat()),
        ok(&[&["idn", "read", "--device", "3", "S-0-0092"][..], &drive].concat())
    );
}

#[test]
fn positions_in_hex() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `--probe-at Z=0x64` was refused while `--set …=0x1` worked. 0x64 = 100.
    let meas1 = ["run", "examples/nc/seed004/meas1.nc", "--link", "sim"];
    let dec = ok(&[&meas1[..], &["--probe-at", "Z=100"]].concat());
    assert_eq!(dec, ok(&[&meas1[..], &["--probe-at", "Z=0x64"]].concat()));
    assert_eq!(
        dec.lines().collect::<Vec<_>>(),
        veth::netns::SEED004_MEAS1,
        "seed 004 §5"
    );
    assert_eq!(
        ok(&["jog", "--axis", "X", "--step", "0x5"]),
        ok(&["jog", "--axis", "X", "--step", "5"])
    );
}

#[test]
fn negative_values_need_no_double_dash() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `sdo write … 0x607A -12345` needed `--`. The frame on the bus: expedited
    // download of 4 bytes (command 0x23), index 0x607A little-endian, sub 0, then -12345 as
    // INTEGER32 little-endian.
    let want: Vec<u8> = [0x23, 0x7A, 0x60, 0x00]
        .into_iter()
        .chain((-12345i32).to_le_bytes())
        .collect();
    let want_hex: String = want.iter().map(|b| format!("{b:02X}")).collect();
    for value in ["-12345", "-0x3039"] {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("w.log");
        let out = ok(&[
            "sdo",
            "write",
            "--node",
            "1",
            "0x607A",
            value,
            "--candump",
            log.to_str().unwrap(),
        ]);
        assert_eq!(out.trim(), "0x607a:00 written (4 bytes)");
        let text = std::fs::read_to_string(&log).unwrap();
        assert!(
            text.lines()
                .any(|l| l.to_ascii_uppercase().ends_with(&format!("601#{want_hex}"))),
            "{value}: no 601#{want_hex} in\n{text}"
        );
    }
    ok(&["sdo", "write", "--device", "1", "0x607A", "-12345"]);
    // SERCOS: S-0-0047 position command value is signed (INT32 attribute).
    ok(&[
        "idn",
        "write",
        "--device",
        "3",
        "S-0-0047",
        "-100",
        "--set",
        "Z.drive=sercos-ax5000",
    ]);
}

#[test]
fn sim_canopen_takes_hex_node_ids() {
    let _one_module = crate::gate::enter(module_path!());
    // Issue 18: `sim canopen --node 0x05` was refused. The ids are checked before the bus is
    // opened; this bus does not exist, so the command ends there (exit 2, naming --bus).
    let (code, _, err) = run(&[
        "sim",
        "canopen",
        "--bus",
        "socketcan:fp-no-such-can",
        "--node",
        "0x05",
        "--probe-at",
        "0x05=0x64",
        "--seconds",
        "0",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("node 5: CiA 402 drive"), "{err}");
    assert!(err.contains("probe surface at 100 mm"), "{err}");
    assert!(err.contains("--bus socketcan:fp-no-such-can"), "{err}");
    let (code, _, err) = run(&[
        "sim",
        "canopen",
        "--bus",
        "udp",
        "--node",
        "0x80",
        "--seconds",
        "0",
    ]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("--node 0x80: expected a CANopen node id 1 … 127"),
        "{err}"
    );
}

/// Bad input: exit 2, the message holds every `needles` entry (option, text, range).
#[track_caller]
fn refused(args: &[&str], needles: &[&str]) {
    let (code, out, err) = run(args);
    assert_eq!(code, Some(2), "{args:?}: {out}{err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {n:?} missing in: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_numbers_name_the_option_the_text_and_the_range() {
    let _one_module = crate::gate::enter(module_path!());
    let range16 = format!("0 … {}", u16::MAX);
    refused(
        &["sdo", "read", "--device", "0x1g", "0x1000"],
        &["--device", "0x1g", &range16],
    );
    refused(
        &["sdo", "read", "--device", "-1", "0x1000"],
        &["--device", "-1", &range16],
    );
    refused(
        &["sdo", "read", "--node", "0", "0x1000"],
        &["--node", "'0'", "1 … 127"],
    );
    refused(
        &["sdo", "read", "--node", "0x80", "0x1000"],
        &["--node", "0x80", "1 … 127"],
    );
    refused(
        &["sdo", "read", "--device", "1", "0x10000"],
        &["object 0x10000", &range16, "index is out of range"],
    );
    refused(
        &["sdo", "read", "--device", "1", "0x1000:256"],
        &["0x1000:256", "0 … 255", "sub-index is out of range"],
    );
    // Hex digits need 0x: never silently hex.
    refused(
        &["sdo", "read", "--device", "1", "0x1000:0a"],
        &["0x1000:0a", "sub-index is not a number"],
    );
    refused(
        &["sdo", "read", "--device", "1", "60a0"],
        &["60a0", "index is not a number"],
    );
    let meas1 = ["run", "examples/nc/seed004/meas1.nc", "--link", "sim"];
    for bad in ["Z=1,5", "Z=inf", "Z=NaN", "Z=0x", "Z=1e400"] {
        refused(
            &[&meas1[..], &["--probe-at", bad]].concat(),
            &[&format!("--probe-at {bad}"), "position in mm"],
        );
    }
    refused(
        &[&meas1[..], &["--rt-priority", "0x1FF"]].concat(),
        &["--rt-priority", "0x1FF", "1 … 99"],
    );
    refused(
        &["can", "dump", "--seconds", "-1"],
        &["--seconds -1", "0 … 86400"],
    );
    refused(
        &[
            "sim",
            "canopen",
            "--bus",
            "udp",
            "--node",
            "1",
            "--heartbeat-ms",
            "0x10000",
        ],
        &["--heartbeat-ms 0x10000", &range16],
    );
    refused(
        &[
            "sim",
            "ethercat",
            "--iface",
            "fp-none",
            "--device",
            "esi/fieldprobe-cia402-servo.xml",
            "--probe-at",
            "x=5",
        ],
        &["--probe-at x=5", "ring position"],
    );
}

#[test]
fn values_outside_the_type_are_refused_before_anything_is_sent() {
    let _one_module = crate::gate::enter(module_path!());
    // CiA 301 ranges of the integer types = Rust's of the same width.
    let cases: [(&str, i128, i128); 9] = [
        ("bool", 0, 1),
        ("uint8", 0, u8::MAX.into()),
        ("int8", i8::MIN.into(), i8::MAX.into()),
        ("uint16", 0, u16::MAX.into()),
        ("int16", i16::MIN.into(), i16::MAX.into()),
        ("uint32", 0, u32::MAX.into()),
        ("int32", i32::MIN.into(), i32::MAX.into()),
        ("uint64", 0, u64::MAX.into()),
        ("int64", i64::MIN.into(), i64::MAX.into()),
    ];
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("never.log");
    for (ty, lo, hi) in cases {
        for v in [lo - 1, hi + 1] {
            let text = v.to_string();
            refused(
                &[
                    "sdo",
                    "write",
                    "--node",
                    "1",
                    "0x2000",
                    &text,
                    "--type",
                    ty,
                    "--candump",
                    log.to_str().unwrap(),
                ],
                &[&format!("value {text}"), &format!("{lo} … {hi}")],
            );
        }
    }
    for (ty, bad) in [
        ("f32", "3.4028236e38"),
        ("float", "nan"),
        ("real32", "inf"),
        ("f64", "1e309"),
        ("double", "-inf"),
        ("bytes", "abc"),
    ] {
        refused(
            &[
                "sdo",
                "write",
                "--node",
                "1",
                "0x2000",
                bad,
                "--type",
                ty,
                "--candump",
                log.to_str().unwrap(),
            ],
            &[&format!("value {bad}"), "expected"],
        );
    }
    assert!(!log.exists(), "the bus was opened");
    refused(
        &["sdo", "read", "--device", "1", "0x1000", "--type", "u128"],
        &["--type", "u128", "uint64", "double", "octet_string"],
    );
}

#[test]
fn type_names_decode_the_bytes_as_the_spec_says() {
    let _one_module = crate::gate::enter(module_path!());
    // The bytes of 0x1000 (4), 0x6041 (2), 0x1C00:01 (1) of the emulated servo, then each
    // spelling of each type decodes them as Rust's from_le_bytes does.
    let raw = |obj: &str| {
        bytes_of(&ok(&[
            "sdo", "read", "--device", "1", obj, "--type", "bytes",
        ]))
    };
    let typed =
        |obj: &str, ty: &str| value_of(&ok(&["sdo", "read", "--device", "1", obj, "--type", ty]));
    let b4: [u8; 4] = raw("0x1000").try_into().expect("4 bytes");
    for ty in ["u32", "uint32", "UNSIGNED32", "udint"] {
        assert_eq!(
            typed("0x1000", ty),
            u32::from_le_bytes(b4).to_string(),
            "{ty}"
        );
    }
    for ty in ["i32", "int32", "INTEGER32", "dint"] {
        assert_eq!(
            typed("0x1000", ty),
            i32::from_le_bytes(b4).to_string(),
            "{ty}"
        );
    }
    for ty in ["f32", "float", "REAL32", "real"] {
        let v: f32 = typed("0x1000", ty).parse().expect("a number");
        assert_eq!(v.to_bits(), u32::from_le_bytes(b4), "{ty}");
    }
    let b2: [u8; 2] = raw("0x6041").try_into().expect("2 bytes");
    for ty in ["u16", "uint16", "UNSIGNED16"] {
        assert_eq!(
            typed("0x6041", ty),
            u16::from_le_bytes(b2).to_string(),
            "{ty}"
        );
    }
    for ty in ["i16", "int16", "INTEGER16"] {
        assert_eq!(
            typed("0x6041", ty),
            i16::from_le_bytes(b2).to_string(),
            "{ty}"
        );
    }
    let b1: [u8; 1] = raw("0x1C00:1").try_into().expect("1 byte");
    for ty in ["u8", "uint8", "UNSIGNED8"] {
        assert_eq!(typed("0x1C00:1", ty), b1[0].to_string(), "{ty}");
    }
    for ty in ["i8", "int8", "INTEGER8"] {
        assert_eq!(typed("0x1C00:1", ty), (b1[0] as i8).to_string(), "{ty}");
    }
    // A type of another size is refused, naming both sizes.
    let (code, _, err) = run(&["sdo", "read", "--device", "1", "0x1000", "--type", "uint64"]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("the object has 4 bytes, type u64 has 8"),
        "{err}"
    );
    // Strings: the same bytes as text and as an OCTET_STRING.
    let text = ok(&["sdo", "read", "--device", "1", "0x1008", "--type", "string"]);
    let name = value_of(&text);
    let name = name.trim_matches('"');
    assert_eq!(
        bytes_of(&ok(&[
            "sdo",
            "read",
            "--device",
            "1",
            "0x1008",
            "--type",
            "octet_string"
        ])),
        name.as_bytes()
    );
}

// ---------------------------------------------------------------------------------------------
// Round trips on emulators that keep the values
// ---------------------------------------------------------------------------------------------

/// `sdo OP LINK… REST…`.
fn sdo<'a>(op: &'a str, link: &[&'a str], rest: &[&'a str]) -> Vec<&'a str> {
    [&["sdo", op][..], link, rest].concat()
}

/// Write `value` as `ty` to `object` over `link` (`--link L --device N` / `--node N`), then
/// read it back as bytes (must be `want`, the little-endian encoding) and as `ty` (the value
/// again, compared by `same`).
#[track_caller]
fn round_trip(
    link: &[&str],
    object: &str,
    ty: &str,
    value: &str,
    want: &[u8],
    same: impl Fn(&str) -> bool,
) {
    ok(&sdo("write", link, &[object, value, "--type", ty]));
    let bytes = bytes_of(&ok(&sdo("read", link, &[object, "--type", "bytes"])));
    assert_eq!(bytes, want, "{object} {ty} {value}: bytes on the device");
    let back = value_of(&ok(&sdo("read", link, &[object, "--type", ty])));
    assert!(same(&back), "{object} {ty} {value}: read back {back}");
}

fn int_eq(want: i128) -> impl Fn(&str) -> bool {
    move |s| s.parse::<i128>() == Ok(want)
}

fn f32_eq(want: f32) -> impl Fn(&str) -> bool {
    move |s| s.parse::<f32>().map(f32::to_bits) == Ok(want.to_bits())
}

fn f64_eq(want: f64) -> impl Fn(&str) -> bool {
    move |s| s.parse::<f64>().map(f64::to_bits) == Ok(want.to_bits())
}

const INNER: &str = "FIELDPROBE_CLI_NUMBERS_INNER";

#[test]
fn round_trips_over_ethercat_to_sim_ethercat() {
    let _one_module = crate::gate::enter(module_path!());
    const NAME: &str = "round_trips_over_ethercat_to_sim_ethercat";
    if veth::inner_env(INNER).is_none() {
        veth::run_in_veth_namespace(NAME, INNER, Duration::from_secs(240), || {
            OsString::from("1")
        });
        return;
    }
    let _pair = veth::VethPair::create();
    let (_emu, _log) = veth::start_emulator(
        &[
            "esi/fieldprobe-ek1100.xml",
            "esi/fieldprobe-cia402-servo.xml",
        ],
        "200",
        &[],
    );
    let link = ["--link", "ethercat:v0", "--device", "0x1"];
    // 0x6065 following error window (UNSIGNED32): any 4 bytes.
    round_trip(
        &link,
        "0x6065",
        "f32",
        "-1.5",
        &(-1.5f32).to_le_bytes(),
        f32_eq(-1.5),
    );
    round_trip(
        &link,
        "0x6065",
        "float",
        "3.4028235e38",
        &f32::MAX.to_le_bytes(),
        f32_eq(f32::MAX),
    );
    round_trip(
        &link,
        "0x6065",
        "uint32",
        "0xFFFFFFFF",
        &[0xFF; 4],
        int_eq(u32::MAX.into()),
    );
    round_trip(
        &link,
        "0x6065",
        "int32",
        "-2147483648",
        &i32::MIN.to_le_bytes(),
        int_eq(i32::MIN.into()),
    );
    round_trip(
        &link,
        "0x607A",
        "i32",
        "-12345",
        &(-12345i32).to_le_bytes(),
        int_eq(-12345),
    );
    round_trip(
        &link,
        "0x6072",
        "uint16",
        "65535",
        &[0xFF, 0xFF],
        int_eq(65535),
    );
    round_trip(
        &link,
        "0x60D0:1",
        "int16",
        "-32768",
        &i16::MIN.to_le_bytes(),
        int_eq(i16::MIN.into()),
    );
    round_trip(&link, "0x6060", "uint8", "8", &[8], int_eq(8));
    println!("INNER OK");
}

/// An EDS (CiA 306) with one read-write object per 64-bit and REAL type (CiA 301 data type
/// codes 0x0015 INTEGER64, 0x001B UNSIGNED64, 0x0008 REAL32, 0x0011 REAL64).
const NUMBERS_EDS: &str = "[FileInfo]\nFileName=numbers.eds\nFileVersion=1\nFileRevision=0\n\
EDSVersion=4.0\nDescription=cli_numbers test node\n\n[DeviceInfo]\nVendorName=fieldprobe tests\n\
VendorNumber=0\nProductName=numbers\nProductNumber=0\nRevisionNumber=0\nBaudRate_1000=1\n\
SimpleBootUpMaster=0\nSimpleBootUpSlave=1\nGranularity=8\nNrOfRXPDO=0\nNrOfTXPDO=0\n\
LSS_Supported=0\n\n[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n\n\
[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\n\
DefaultValue=0x00020192\nPDOMapping=0\n\n[1001]\nParameterName=Error register\nObjectType=0x7\n\
DataType=0x0005\nAccessType=ro\nDefaultValue=0\nPDOMapping=0\n\n[1018]\nParameterName=Identity\n\
ObjectType=0x9\nSubNumber=2\n\n[1018sub0]\nParameterName=Highest sub-index\nObjectType=0x7\n\
DataType=0x0005\nAccessType=ro\nDefaultValue=1\nPDOMapping=0\n\n[1018sub1]\n\
ParameterName=Vendor-ID\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0\n\
PDOMapping=0\n\n[ManufacturerObjects]\nSupportedObjects=4\n1=0x2001\n2=0x2002\n3=0x2003\n\
4=0x2004\n\n[2001]\nParameterName=INTEGER64 value\nObjectType=0x7\nDataType=0x0015\n\
AccessType=rw\nDefaultValue=0\nPDOMapping=0\n\n[2002]\nParameterName=UNSIGNED64 value\n\
ObjectType=0x7\nDataType=0x001B\nAccessType=rw\nDefaultValue=0\nPDOMapping=0\n\n[2003]\n\
ParameterName=REAL32 value\nObjectType=0x7\nDataType=0x0008\nAccessType=rw\nDefaultValue=0\n\
PDOMapping=0\n\n[2004]\nParameterName=REAL64 value\nObjectType=0x7\nDataType=0x0011\n\
AccessType=rw\nDefaultValue=0\nPDOMapping=0\n";

#[test]
fn round_trips_over_canopen_to_sim_canopen_with_64_bit_and_real_objects() {
    let _one_module = crate::gate::enter(module_path!());
    const NAME: &str = "round_trips_over_canopen_to_sim_canopen_with_64_bit_and_real_objects";
    if veth::netns::inner_python(INNER).is_none() {
        veth::netns::run_in_namespace(NAME, INNER, Duration::from_secs(240), false);
        return;
    }
    veth::netns::netns_setup();
    let dir = tempfile::tempdir().unwrap();
    let eds = dir.path().join("numbers.eds");
    std::fs::write(&eds, NUMBERS_EDS).unwrap();
    // A group and port of their own (the namespace is private anyway).
    let bus = "udp:239.74.163.18:43118";
    let mut sim = veth::Emulator(
        Command::new(env!("CARGO_BIN_EXE_fieldprobe"))
            .args(["sim", "canopen", "--bus", bus, "--node", "0x05", "--eds"])
            .arg(&eds)
            .args(["--seconds", "200"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("spawn sim canopen"),
    );
    let mut err = std::io::BufReader::new(sim.0.stderr.take().expect("stderr"));
    let mut line = String::new();
    loop {
        line.clear();
        let n = std::io::BufRead::read_line(&mut err, &mut line).expect("sim stderr");
        assert!(n > 0, "sim canopen ended before listening");
        if line.contains("listening on") {
            break;
        }
    }
    // The rest of its stderr goes into the test's output.
    std::thread::spawn(move || {
        for l in std::io::BufRead::lines(err).map_while(Result::ok) {
            eprintln!("sim canopen: {l}");
        }
    });
    let link_arg = format!("canopen-{bus}");
    let link = ["--link", link_arg.as_str(), "--node", "5"];
    // The nodes have booted when "listening" is printed; the retries (at most 10 of 0.5 s)
    // only ride out a loaded machine.
    let booted = (0..10).any(|_| run(&sdo("read", &link, &["0x1000"])).0 == Some(0));
    assert!(booted, "node 5 never answered SDO 0x1000");
    for v in [i64::MIN, -1, i64::MAX] {
        let text = v.to_string();
        round_trip(
            &link,
            "0x2001",
            "int64",
            &text,
            &v.to_le_bytes(),
            int_eq(v.into()),
        );
    }
    for v in [0, u64::MAX] {
        let text = v.to_string();
        round_trip(
            &link,
            "0x2002",
            "uint64",
            &text,
            &v.to_le_bytes(),
            int_eq(v.into()),
        );
    }
    round_trip(
        &link,
        "0x2002",
        "u64",
        "0x0123456789ABCDEF",
        &0x0123_4567_89AB_CDEFu64.to_le_bytes(),
        int_eq(0x0123_4567_89AB_CDEF),
    );
    // REAL32: the smallest subnormal, a negative fraction, the largest finite value.
    for (text, v) in [
        ("1e-45", f32::from_bits(1)),
        ("-0.1", -0.1f32),
        ("3.4028235e38", f32::MAX),
    ] {
        round_trip(&link, "0x2003", "real32", text, &v.to_le_bytes(), f32_eq(v));
    }
    for (text, v) in [
        ("-1.25e-300", -1.25e-300f64),
        ("1.7976931348623157e308", f64::MAX),
        ("0x10", 16.0),
    ] {
        round_trip(&link, "0x2004", "double", text, &v.to_le_bytes(), f64_eq(v));
    }
    // Sizes that do not match the object: the node refuses a REAL64 into a REAL32 (CiA 301
    // abort 0x06070010), the CLI a REAL32 read as REAL64.
    let (code, _, err) = run(&sdo("write", &link, &["0x2003", "1", "--type", "f64"]));
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("0x06070010"), "{err}");
    let (code, _, err) = run(&sdo("read", &link, &["0x2003", "--type", "f64"]));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("the object has 4 bytes, type f64 has 8"),
        "{err}"
    );
    println!("INNER OK");
}
