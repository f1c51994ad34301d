//! Unit tests of the emulated node (sans-IO: frames in with `now`, frames out).

use super::*;
use crate::bus::canopen::eds;
use crate::drive::catalogue;

const TECHNOSOFT: &str = "eds/technosoft-ipos-cia402.eds";

/// `../shared/test-data/REL` when the file exists. Otherwise: panics if
/// `FIELDPROBE_REQUIRE_TEST_DATA=1` (set by `.ci/run`), else prints `SKIP TEST_NAME: …` and
/// returns `None` (the test returns). Same rule as `tests/common/test_data.rs`.
fn test_data(rel: &str, test_name: &str) -> Option<std::path::PathBuf> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/test-data")
        .join(rel);
    if path.is_file() {
        return Some(path);
    }
    let why = format!(
        "{} not present (a plain clone without ../shared/test-data)",
        path.display()
    );
    if std::env::var("FIELDPROBE_REQUIRE_TEST_DATA").is_ok_and(|v| v == "1") {
        panic!("{test_name}: {why}; FIELDPROBE_REQUIRE_TEST_DATA=1 requires the test data");
    }
    eprintln!("SKIP {test_name}: {why}");
    None
}

/// One SDO request (8 bytes on 0x600 + 5) and the node's single reply on 0x585.
#[track_caller]
fn sdo(node: &mut EmulatedNode, req: [u8; 8]) -> [u8; 8] {
    let f = CanFrame::new(0x605, &req).unwrap();
    node.handle(&f, Nanos(1_000_000));
    let out = node.take_outgoing();
    assert_eq!(out.len(), 1, "{out:?}");
    assert_eq!(out[0].id, 0x585);
    out[0].data
}

/// Expedited upload of `index:sub`: `Ok(4 data bytes)` or `Err(abort code)`.
#[track_caller]
fn upload(node: &mut EmulatedNode, index: u16, sub: u8) -> Result<[u8; 4], u32> {
    let [lo, hi] = index.to_le_bytes();
    let r = sdo(node, [0x40, lo, hi, sub, 0, 0, 0, 0]);
    match r[0] {
        0x80 => Err(u32::from_le_bytes([r[4], r[5], r[6], r[7]])),
        c if c & 0xE3 == 0x43 => Ok([r[4], r[5], r[6], r[7]]),
        c => panic!("unexpected reply {c:#04x}: {r:02x?}"),
    }
}

/// Expedited download of 2 bytes: `Ok(())` or `Err(abort code)`.
#[track_caller]
fn download_u16(node: &mut EmulatedNode, index: u16, sub: u8, v: u16) -> Result<(), u32> {
    let [lo, hi] = index.to_le_bytes();
    let [a, b] = v.to_le_bytes();
    // 0x2B: expedited, size indicated, 2 bytes
    let r = sdo(node, [0x2B, lo, hi, sub, a, b, 0, 0]);
    match r[0] {
        0x60 => Ok(()),
        0x80 => Err(u32::from_le_bytes([r[4], r[5], r[6], r[7]])),
        c => panic!("unexpected reply {c:#04x}"),
    }
}

/// The Technosoft EDS as node 5, booted (`None`: file absent, test skipped).
fn technosoft_node(test_name: &str) -> Option<EmulatedNode> {
    let path = test_data(TECHNOSOFT, test_name)?;
    let def = catalogue::load("cia402-generic").unwrap();
    let eds = eds::load(path).unwrap();
    let mut n = EmulatedNode::from_eds(5, &def, &eds).unwrap();
    n.poll(Nanos(0)); // boot-up -> pre-operational
    let boot = n.take_outgoing();
    // 705 [1] 00: boot-up; no heartbeat follows because the EDS has 0x1017 = 0
    assert_eq!(boot, vec![CanFrame::new(0x705, &[0]).unwrap()]);
    Some(n)
}

#[test]
fn from_eds_takes_values_access_and_identity_from_the_file() {
    let Some(mut n) = technosoft_node("from_eds_takes_values_access_and_identity_from_the_file")
    else {
        return;
    };
    // Values as written in the file: [1000] DefaultValue=0x60192, [1018sub1] 0x000001A3.
    assert_eq!(upload(&mut n, 0x1000, 0), Ok(0x0006_0192u32.to_le_bytes()));
    assert_eq!(upload(&mut n, 0x1018, 0).map(|b| b[0]), Ok(4));
    assert_eq!(upload(&mut n, 0x1018, 1), Ok(0x1A3u32.to_le_bytes()));
    // No product code in the file ([1018sub2] without default, no ProductNumber): 0.
    assert_eq!(upload(&mut n, 0x1018, 2), Ok([0; 4]));
    // Serial number: none in the file -> the node id.
    assert_eq!(upload(&mut n, 0x1018, 4), Ok(5u32.to_le_bytes()));
    // [1008] const "iPOS" (4 bytes: expedited).
    assert_eq!(upload(&mut n, 0x1008, 0), Ok(*b"iPOS"));
    assert_eq!(download_u16(&mut n, 0x1008, 0, 0x4141), Err(0x0601_0002));
    // [1017] rw DefaultValue=0.
    assert_eq!(
        upload(&mut n, 0x1017, 0).map(|b| b[..2].to_vec()),
        Ok(vec![0, 0])
    );
    // Manufacturer objects: [2000] ro u16 0, [2010] rww u16 0.
    assert_eq!(
        upload(&mut n, 0x2000, 0).map(|b| b[..2].to_vec()),
        Ok(vec![0, 0])
    );
    assert_eq!(download_u16(&mut n, 0x2000, 0, 1), Err(0x0601_0002));
    assert_eq!(download_u16(&mut n, 0x2010, 0, 0xBEEF), Ok(()));
    assert_eq!(
        upload(&mut n, 0x2010, 0).map(|b| b[..2].to_vec()),
        Ok(vec![0xEF, 0xBE])
    );
    // A 4-byte write to a u16 object is refused (length does not match).
    let r = sdo(&mut n, [0x23, 0x10, 0x20, 0, 1, 2, 3, 4]);
    assert_eq!(r, [0x80, 0x10, 0x20, 0, 0x10, 0, 0x07, 0x06]);
    // Not in the file: built-in emulator notice 0x2000 is replaced, 0x1C00 gone.
    assert_eq!(upload(&mut n, 0x1C00, 0), Err(0x0602_0000));
    // PDO parameters as the node has them: TPDO1 COB-ID 0x185, first entry 0x6041:00 16 bit
    // (drives/cia402-generic.toml txpdo starts with the statusword).
    assert_eq!(upload(&mut n, 0x1800, 1), Ok(0x185u32.to_le_bytes()));
    assert_eq!(upload(&mut n, 0x1A00, 1), Ok(0x6041_0010u32.to_le_bytes()));
}

#[test]
fn from_eds_keeps_the_drive_model_behind_its_objects() {
    let Some(mut n) = technosoft_node("from_eds_keeps_the_drive_model_behind_its_objects") else {
        return;
    };
    // 0x60B8 touch probe function is in the file; a write reaches the model.
    assert_eq!(download_u16(&mut n, 0x60B8, 0, 0x0011), Ok(()));
    assert_eq!(n.model().read_object(0x60B8, 0), Ok(0x0011));
    // 0x6041 statusword comes from the model, not from the file (which has no default).
    let sw = upload(&mut n, 0x6041, 0).map(|b| i64::from(u16::from_le_bytes([b[0], b[1]])));
    assert_eq!(sw, n.model().read_object(0x6041, 0));
    // Read-only model object stays read-only.
    assert_eq!(download_u16(&mut n, 0x6041, 0, 0), Err(0x0601_0002));
}

#[test]
fn from_eds_rejects_bad_node_ids_and_reads_odd_values() {
    let Some(path) = test_data(
        TECHNOSOFT,
        "from_eds_rejects_bad_node_ids_and_reads_odd_values",
    ) else {
        return;
    };
    let def = catalogue::load("cia402-generic").unwrap();
    let eds = eds::load(path).unwrap();
    assert!(EmulatedNode::from_eds(0, &def, &eds).is_err());
    assert!(EmulatedNode::from_eds(128, &def, &eds).is_err());
    // A default above UNSIGNED32 saturates (a warning of the parse); the node serves it.
    let odd = eds::parse(
        "[MandatoryObjects]\nSupportedObjects=1\n1=0x1000\n\n[1000]\nParameterName=Device type\n\
         ObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x1FFFFFFFF\nPDOMapping=0\n",
        "odd.eds",
    )
    .unwrap();
    assert!(
        odd.warnings
            .iter()
            .any(|w| w.object == Some((0x1000, 0)) && w.kind == eds::EdsErrorKind::OutOfRange),
        "{:?}",
        odd.warnings
    );
    let node = EmulatedNode::from_eds(5, &def, &odd).unwrap();
    assert_eq!(node.read_object(0x1000, 0), Ok(vec![0xFF; 4]));
}

// ------------------------------------------------------------------------------------------
// The node as a drive: SDO writes act at once, values valid from boot, EDS PDO defaults,
// transmission types. A one-node bus on virtual time; every frame goes through
// `CanopenSegment::run` as on `fieldprobe sim canopen`.

/// CiA 402 0x6041 state coding (CiA 402 §6.2 Table "statusword state coding"): mask 0x6F.
const SW_MASK: u16 = 0x006F;
const SW_READY_TO_SWITCH_ON: u16 = 0x0021;
const SW_SWITCHED_ON: u16 = 0x0023;
const SW_OPERATION_ENABLED: u16 = 0x0027;
/// SWITCH ON DISABLED is `x1xx 0000` under mask 0x4F.
const SW_SWITCH_ON_DISABLED: u16 = 0x0040;
/// 0x6041 right after start-up: switch on disabled (0x40), voltage enabled (0x10), remote
/// (0x200).
const SW_AFTER_START_UP: u16 = 0x0250;

const NODE: u8 = 5;

/// One node on a bus with a virtual clock (ms granularity is enough here).
struct Bench {
    seg: CanopenSegment,
    now: Nanos,
}

impl Bench {
    /// `node` booted into pre-operational at t = 0 (boot-up and heartbeat frames dropped).
    fn new(node: EmulatedNode) -> Self {
        let mut seg = CanopenSegment::new(vec![node], Nanos::from_micros(1000));
        seg.run(&[], Nanos(0));
        Bench { seg, now: Nanos(0) }
    }

    fn built_in() -> Self {
        let def = catalogue::load("cia402-generic").unwrap();
        Bench::new(EmulatedNode::new(NODE, &def).unwrap())
    }

    fn node(&self) -> &EmulatedNode {
        &self.seg.nodes()[0]
    }

    /// Frames the node sends for `frames` received at the current time.
    fn send(&mut self, frames: &[CanFrame]) -> Vec<CanFrame> {
        self.seg.run(frames, self.now)
    }

    fn at_ms(&mut self, ms: u64) -> Vec<CanFrame> {
        self.now = Nanos(ms * 1_000_000);
        self.send(&[])
    }

    fn sync(&mut self) -> Vec<CanFrame> {
        self.send(&[nmt::sync()])
    }

    fn nmt(&mut self, cmd: NmtCommand) -> Vec<CanFrame> {
        self.send(&[cmd.frame(NODE)])
    }

    /// One SDO request; the node's reply (0x580 + node).
    #[track_caller]
    fn sdo(&mut self, req: [u8; 8]) -> [u8; 8] {
        let out = self.send(&[CanFrame::new(0x600 + u16::from(NODE), &req).unwrap()]);
        let r: Vec<_> = out
            .iter()
            .filter(|f| f.id == 0x580 + u32::from(NODE))
            .collect();
        assert_eq!(r.len(), 1, "{out:?}");
        r[0].data
    }

    /// Expedited download of `data` (1 … 4 bytes).
    #[track_caller]
    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        let [lo, hi] = index.to_le_bytes();
        // CiA 301 §7.2.4.3.3: ccs 1, e = 1, s = 1, n = 4 - len.
        let mut req = [
            0x23 | ((4 - data.len() as u8) << 2),
            lo,
            hi,
            sub,
            0,
            0,
            0,
            0,
        ];
        req[4..4 + data.len()].copy_from_slice(data);
        let r = self.sdo(req);
        match r[0] {
            0x60 => Ok(()),
            0x80 => Err(u32::from_le_bytes([r[4], r[5], r[6], r[7]])),
            c => panic!("unexpected reply {c:#04x}"),
        }
    }

    /// Expedited upload as an unsigned number.
    #[track_caller]
    fn read(&mut self, index: u16, sub: u8) -> Result<u32, u32> {
        let [lo, hi] = index.to_le_bytes();
        let r = self.sdo([0x40, lo, hi, sub, 0, 0, 0, 0]);
        match r[0] {
            0x80 => Err(u32::from_le_bytes([r[4], r[5], r[6], r[7]])),
            // e = 1: 4 - n data bytes (n = 0 without the size bit).
            c if c & 0xE3 == 0x43 => {
                let n = 4 - usize::from((c >> 2) & 3);
                let mut b = [0u8; 4];
                b[..n].copy_from_slice(&r[4..4 + n]);
                Ok(u32::from_le_bytes(b))
            }
            c => panic!("unexpected reply {c:#04x}: {r:02x?}"),
        }
    }

    #[track_caller]
    fn statusword(&mut self) -> u16 {
        self.read(0x6041, 0).unwrap() as u16
    }

    /// CiA 301 remap procedure for PDO 1 of `dir`: COB-ID invalid, transmission type,
    /// mapping, COB-ID valid (0x200 / 0x180 + node). Inhibit time and event-timer for TPDOs.
    #[track_caller]
    fn map_pdo1(&mut self, dir: Direction, mapping: &[u32], ty: u8, inhibit: u16, event: u16) {
        let (comm, map, cob) = match dir {
            Direction::Rx => (0x1400, 0x1600, 0x200 + u32::from(NODE)),
            Direction::Tx => (0x1800, 0x1A00, 0x180 + u32::from(NODE)),
        };
        self.write(comm, 1, &(cob | 0x8000_0000).to_le_bytes())
            .unwrap();
        self.write(comm, 2, &[ty]).unwrap();
        if dir == Direction::Tx {
            self.write(comm, 3, &inhibit.to_le_bytes()).unwrap();
            self.write(comm, 5, &event.to_le_bytes()).unwrap();
        }
        self.write(map, 0, &[0]).unwrap();
        for (j, m) in mapping.iter().enumerate() {
            self.write(map, j as u8 + 1, &m.to_le_bytes()).unwrap();
        }
        self.write(map, 0, &[mapping.len() as u8]).unwrap();
        self.write(comm, 1, &cob.to_le_bytes()).unwrap();
    }
}

/// The frames on `cob` in `out`, as payloads.
fn on(out: &[CanFrame], cob: u32) -> Vec<Vec<u8>> {
    out.iter()
        .filter(|f| f.id == cob)
        .map(|f| f.payload().to_vec())
        .collect()
}

#[test]
fn statusword_is_switch_on_disabled_from_boot_before_any_sync() {
    let mut b = Bench::built_in();
    // Pre-operational, no SYNC ever: the SDO read gives the real statusword.
    assert_eq!(b.statusword(), SW_AFTER_START_UP);
    assert_eq!(b.statusword() & 0x4F, SW_SWITCH_ON_DISABLED);
    // TPDO1 = 0x6041 only, type 1: the TPDO of the very first SYNC carries it too.
    b.map_pdo1(Direction::Tx, &[0x6041_0010], 1, 0, 0);
    b.nmt(NmtCommand::Start);
    assert_eq!(b.node().state(), NmtState::Operational);
    let out = b.sync();
    assert_eq!(
        on(&out, 0x185),
        vec![SW_AFTER_START_UP.to_le_bytes().to_vec()]
    );
}

#[test]
fn sdo_controlword_6_7_f_reaches_operation_enabled_and_stays_until_an_rpdo() {
    let mut b = Bench::built_in();
    // RPDO1 = controlword only, synchronous (type 1).
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 1, 0, 0);
    b.nmt(NmtCommand::Start);
    // Each write acts at once, no SYNC in between (CiA 402 transitions 2, 3, 4).
    b.write(0x6040, 0, &6u16.to_le_bytes()).unwrap();
    assert_eq!(b.statusword() & SW_MASK, SW_READY_TO_SWITCH_ON);
    b.write(0x6040, 0, &7u16.to_le_bytes()).unwrap();
    assert_eq!(b.statusword() & SW_MASK, SW_SWITCHED_ON);
    b.write(0x6040, 0, &0xFu16.to_le_bytes()).unwrap();
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
    // A set-point by SDO as well (0x607A is in the drive's RPDO image, not in RPDO1).
    b.write(0x607A, 0, &1234i32.to_le_bytes()).unwrap();
    // SYNCs without any RPDO: nothing stale overwrites the SDO values.
    for ms in 1..=5 {
        b.at_ms(ms);
        b.sync();
        assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED, "SYNC {ms}");
    }
    assert_eq!(b.read(0x6040, 0), Ok(0x000F));
    assert_eq!(b.read(0x607A, 0), Ok(1234));
    // An RPDO brings controlword 6 (shutdown): synchronous, so it waits for the SYNC …
    b.send(&[CanFrame::new(0x205, &6u16.to_le_bytes()).unwrap()]);
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
    // … and takes over there (transition 8: OPERATION ENABLED → READY TO SWITCH ON).
    b.at_ms(6);
    b.sync();
    assert_eq!(b.statusword() & SW_MASK, SW_READY_TO_SWITCH_ON);
    assert_eq!(b.read(0x6040, 0), Ok(6));
    assert_eq!(b.read(0x607A, 0), Ok(1234));
}

#[test]
fn rpdo_type_255_is_taken_over_on_reception_type_1_at_the_next_sync() {
    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 255, 0, 0);
    b.nmt(NmtCommand::Start);
    b.send(&[CanFrame::new(0x205, &6u16.to_le_bytes()).unwrap()]);
    assert_eq!(b.statusword() & SW_MASK, SW_READY_TO_SWITCH_ON, "at once");
    b.send(&[CanFrame::new(0x205, &7u16.to_le_bytes()).unwrap()]);
    assert_eq!(b.statusword() & SW_MASK, SW_SWITCHED_ON, "at once");

    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 1, 0, 0);
    b.nmt(NmtCommand::Start);
    b.send(&[CanFrame::new(0x205, &6u16.to_le_bytes()).unwrap()]);
    assert_eq!(b.statusword(), SW_AFTER_START_UP, "waits for the SYNC");
    assert_eq!(b.read(0x6040, 0), Ok(0));
    b.sync();
    assert_eq!(b.statusword() & SW_MASK, SW_READY_TO_SWITCH_ON);
}

#[test]
fn tpdo_type_255_obeys_inhibit_time_and_event_timer_on_virtual_time() {
    let mut b = Bench::built_in();
    // Inhibit 50 × 100 µs = 5 ms, event-timer 20 ms (CiA 301 0x1800 sub 3, sub 5).
    b.map_pdo1(Direction::Tx, &[0x6041_0010], 255, 50, 20);
    let mut seen: Vec<(u64, Vec<u8>)> = Vec::new();
    let out = b.nmt(NmtCommand::Start);
    seen.extend(on(&out, 0x185).into_iter().map(|d| (0, d)));
    for ms in 1..=50 {
        if ms == 1 {
            // A change 1 ms after the first transmission: inhibited until 5 ms.
            b.now = Nanos(1_000_000);
            b.write(0x6040, 0, &6u16.to_le_bytes()).unwrap();
        }
        let out = b.at_ms(ms);
        seen.extend(on(&out, 0x185).into_iter().map(|d| (ms, d)));
    }
    let rtso = 0x0231u16.to_le_bytes().to_vec(); // READY TO SWITCH ON | voltage | remote
    assert_eq!(
        seen,
        vec![
            (0, SW_AFTER_START_UP.to_le_bytes().to_vec()), // at NMT start
            (5, rtso.clone()),                             // change, after the inhibit time
            (25, rtso.clone()),                            // event-timer, 20 ms later
            (45, rtso),                                    // and again
        ]
    );
    // Not at SYNCs.
    assert!(on(&b.sync(), 0x185).is_empty());
}

#[test]
fn tpdo_type_2_goes_out_every_second_sync_type_0_only_on_change() {
    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Tx, &[0x6041_0010], 2, 0, 0);
    b.nmt(NmtCommand::Start);
    let sent: Vec<usize> = (1..=6).map(|_| on(&b.sync(), 0x185).len()).collect();
    assert_eq!(sent, [0, 1, 0, 1, 0, 1]);

    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Tx, &[0x6041_0010], 0, 0, 0);
    b.nmt(NmtCommand::Start);
    assert_eq!(
        on(&b.sync(), 0x185),
        vec![SW_AFTER_START_UP.to_le_bytes().to_vec()],
        "first SYNC: never sent before"
    );
    assert!(on(&b.sync(), 0x185).is_empty(), "unchanged");
    assert!(on(&b.sync(), 0x185).is_empty(), "unchanged");
    b.write(0x6040, 0, &6u16.to_le_bytes()).unwrap();
    assert!(on(&b.send(&[]), 0x185).is_empty(), "only at a SYNC");
    assert_eq!(on(&b.sync(), 0x185), vec![0x0231u16.to_le_bytes().to_vec()]);
    assert!(on(&b.sync(), 0x185).is_empty(), "unchanged");
}

/// `key` of INI section `[section]` in `text` as written (a minimal reader, independent of
/// the crate's EDS parser).
fn ini(text: &str, section: &str, key: &str) -> Option<String> {
    let mut inside = false;
    for line in text.lines().map(str::trim) {
        if line.starts_with('[') {
            inside = line[1..line.len() - 1].eq_ignore_ascii_case(section);
        } else if inside {
            if let Some((k, v)) = line.split_once('=') {
                if k.trim().eq_ignore_ascii_case(key) {
                    return Some(v.trim().to_string());
                }
            }
        }
    }
    None
}

fn ini_uint(text: &str, section: &str) -> u32 {
    let v = ini(text, section, "DefaultValue").unwrap_or_else(|| panic!("[{section}]"));
    match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16).unwrap(),
        None => v.parse().unwrap(),
    }
}

#[test]
fn technosoft_eds_pdo_defaults_are_the_boot_defaults_and_reset_communication_restores_them() {
    let name =
        "technosoft_eds_pdo_defaults_are_the_boot_defaults_and_reset_communication_restores_them";
    let Some(path) = test_data(TECHNOSOFT, name) else {
        return;
    };
    let text = String::from_utf8_lossy(&std::fs::read(&path).unwrap()).into_owned();
    let def = catalogue::load("cia402-generic").unwrap();
    let eds = eds::load(&path).unwrap();
    let mut b = Bench::new(EmulatedNode::from_eds(NODE, &def, &eds).unwrap());
    let rpdo1_type = ini_uint(&text, "1400sub2");
    let tpdo1_inhibit = ini_uint(&text, "1800sub3");
    let heartbeat = ini_uint(&text, "1017");
    assert_eq!((rpdo1_type, tpdo1_inhibit, heartbeat), (255, 300, 0));
    assert_eq!(b.read(0x1400, 2), Ok(rpdo1_type));
    assert_eq!(b.read(0x1800, 2), Ok(ini_uint(&text, "1800sub2")));
    assert_eq!(b.read(0x1800, 3), Ok(tpdo1_inhibit));
    assert_eq!(b.read(0x1017, 0), Ok(heartbeat));
    // COB-IDs with $NODEID: [1400sub1] $NODEID+0x200, [1802sub1] $NODEID+0x80000380.
    assert_eq!(
        ini(&text, "1400sub1", "DefaultValue").as_deref(),
        Some("$NODEID+0x200")
    );
    assert_eq!(b.read(0x1400, 1), Ok(0x205));
    assert_eq!(b.read(0x1802, 1), Ok(0x8000_0385));
    // Mapping: [1601sub2] 0x60600008, [1A01sub2] 0x60610008.
    assert_eq!(b.read(0x1601, 2), Ok(ini_uint(&text, "1601sub2")));
    assert_eq!(b.read(0x1A01, 0), Ok(ini_uint(&text, "1A01sub0")));
    // The EDS's RPDO1 has no sub-index 5 (deadline): the object is not there.
    assert_eq!(b.read(0x1400, 5), Err(0x0609_0011));
    // PDOs 5 and up are not served.
    assert_eq!(b.read(0x1404, 1).map_err(|c| c >> 16), Err(0x0602));

    // Changed by SDO, back to the EDS values after NMT reset communication.
    b.write(0x1400, 2, &[1]).unwrap();
    b.write(0x1800, 3, &7u16.to_le_bytes()).unwrap();
    // TPDO1's mapping changes only while the PDO does not exist (CiA 301 procedure).
    assert_eq!(b.write(0x1A00, 0, &[0]), Err(0x0609_0030));
    b.write(0x1800, 1, &0x8000_0185u32.to_le_bytes()).unwrap();
    b.write(0x1A00, 0, &[0]).unwrap();
    b.write(0x1017, 0, &50u16.to_le_bytes()).unwrap();
    b.nmt(NmtCommand::ResetCommunication);
    b.at_ms(1);
    assert_eq!(b.read(0x1400, 2), Ok(rpdo1_type));
    assert_eq!(b.read(0x1800, 3), Ok(tpdo1_inhibit));
    assert_eq!(b.read(0x1A00, 0), Ok(ini_uint(&text, "1A00sub0")));
    // [1800sub1] $NODEID+0x180 for node 5.
    assert_eq!(b.read(0x1800, 1), Ok(0x185));
    assert_eq!(b.read(0x1017, 0), Ok(heartbeat));
}

#[test]
fn technosoft_eds_node_starts_with_its_pdo_defaults_event_driven() {
    let name = "technosoft_eds_node_starts_with_its_pdo_defaults_event_driven";
    let Some(path) = test_data(TECHNOSOFT, name) else {
        return;
    };
    let def = catalogue::load("cia402-generic").unwrap();
    let eds = eds::load(&path).unwrap();
    let mut b = Bench::new(EmulatedNode::from_eds(NODE, &def, &eds).unwrap());
    // The EDS default mapping (RPDO4 maps 0x60FF, outside the drive file's image) is served.
    let out = b.nmt(NmtCommand::Start);
    assert_eq!(b.node().state(), NmtState::Operational, "{out:?}");
    // TPDO1 (0x6041) and TPDO2 (0x6041, 0x6061) are type 255: sent at start, no SYNC needed;
    // TPDO3/4 have bit 31 set in the EDS COB-ID.
    assert_eq!(on(&out, 0x185), vec![vec![0x50, 0x02]]);
    assert_eq!(on(&out, 0x285), vec![vec![0x50, 0x02, 0x00]]);
    assert!(on(&out, 0x385).is_empty() && on(&out, 0x485).is_empty());
    // RPDO1 (0x6040, type 255) acts on reception; TPDO1 follows the change at once (inhibit
    // 30 ms after the start transmission at t = 0: the change goes out at 30 ms).
    b.at_ms(10);
    let out = b.send(&[CanFrame::new(0x205, &6u16.to_le_bytes()).unwrap()]);
    assert_eq!(b.statusword() & SW_MASK, SW_READY_TO_SWITCH_ON);
    assert!(on(&out, 0x185).is_empty(), "inhibited");
    assert!(on(&b.at_ms(29), 0x185).is_empty(), "inhibited");
    assert_eq!(on(&b.at_ms(30), 0x185), vec![vec![0x31, 0x02]]);
    // RPDO4: controlword 7 and 0x60FF target velocity, taken over at once.
    b.send(&[CanFrame::new(0x505, &[7, 0, 0x10, 0x27, 0, 0]).unwrap()]);
    assert_eq!(b.statusword() & SW_MASK, SW_SWITCHED_ON);
    assert_eq!(b.read(0x60FF, 0), Ok(10_000));
    // No SYNC ever came.
    assert_eq!(b.node().syncs(), 0);
}

/// Issue 15: a client that starts a segmented upload and goes away (no segment requests)
/// leaves the SDO server mid-transfer; NMT reset communication re-initialises the SDO server
/// (CiA 301 §7.3.2.2.2, communication objects), so the next client's first request is
/// answered normally instead of with an abort.
#[test]
fn reset_communication_ends_an_abandoned_sdo_transfer() {
    for cmd in [NmtCommand::ResetCommunication, NmtCommand::ResetNode] {
        let mut b = Bench::built_in();
        // Initiate upload of 0x1008 device name (a VISIBLE_STRING longer than 4 bytes):
        // CiA 301 §7.2.4.3.6: scs 2, e = 0, s = 1 → 0x41 with the size in bytes 4..8.
        let r = b.sdo([0x40, 0x08, 0x10, 0, 0, 0, 0, 0]);
        assert_eq!(r[0], 0x41, "segmented upload initiated: {r:02x?}");
        assert!(u32::from_le_bytes([r[4], r[5], r[6], r[7]]) > 4);
        // The client goes away; the master resets the node's communication.
        b.nmt(cmd);
        b.at_ms(1); // boot-up
                    // CiA 402 statusword of a drive that was never enabled: switch on disabled
                    // (bit 6 set, bits 0..3 clear, CiA 402 §6.2 table "statusword").
        let sw = b.read(0x6041, 0).expect("answered, not aborted");
        assert_eq!(sw & 0x4F, 0x40, "{sw:#06x}");
    }
}

// ------------------------------------------------------------------------------------------
// Issue 25: the drive keeps real time without 0x1006 ("The drive's clock").

/// Set-point ramp of the real-time tests: 100 mm/s of the generic drive (10 000 increments per
/// mm) is 1 000 000 increments/s — a tenth of its `max_velocity` (1000 mm/s), 40 times that
/// (what a 1 ms step per 40 ms SYNC asks) is far above it.
const RAMP_INC_PER_S: i64 = 1_000_000;

/// Enable the built-in drive of `b` in CSP (SDO: 0x6060 = 8, controlword 6, 7, 0xF), start it,
/// then SYNC `n` times `period_ms` apart (node clock), writing the target of a constant-speed
/// ramp before each SYNC (SDO into the RPDO image). With `cycle_us` the master's 0x1006 is
/// written first. The actual position 0x6064 after each SYNC, with the target it had.
fn ramp(period_ms: u64, cycle_us: Option<u32>, n: u64) -> (Vec<(i64, i64)>, Vec<Nanos>) {
    let mut b = Bench::built_in();
    if let Some(us) = cycle_us {
        b.write(0x1006, 0, &us.to_le_bytes()).unwrap();
    }
    b.write(0x6060, 0, &[8]).unwrap();
    for cw in [6u16, 7, 0xF] {
        b.write(0x6040, 0, &cw.to_le_bytes()).unwrap();
    }
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
    b.nmt(NmtCommand::Start);
    assert_eq!(b.node().state(), NmtState::Operational);
    let mut out = Vec::new();
    let mut steps = Vec::new();
    let mut t = 100;
    for k in 0..=n {
        // The set-point of the interval that ends at SYNC k: v · k · T (T = 40 ms, the
        // master's cycle, whatever the SYNC spacing on the node's clock).
        let target = RAMP_INC_PER_S * k as i64 * 40 / 1000;
        b.write(0x607A, 0, &(target as i32).to_le_bytes()).unwrap();
        b.at_ms(t);
        b.sync();
        steps.push(b.seg.last_sync_step().unwrap());
        let actual = i64::from(b.read(0x6064, 0).unwrap() as i32);
        out.push((target, actual));
        t += period_ms;
    }
    (out, steps)
}

#[test]
fn without_0x1006_each_sync_steps_the_drive_by_the_time_since_the_previous_one() {
    // The segment's own cycle is 1 ms (`Bench`, as `sim canopen`); the master's SYNC comes
    // every 40 ms and it never writes 0x1006 (an EDS without it).
    let (track, steps) = ramp(40, None, 25);
    assert_eq!(
        steps[0],
        Nanos::from_micros(1000),
        "first SYNC: the segment's cycle"
    );
    assert!(
        steps[1..].iter().all(|&s| s == Nanos::from_micros(40_000)),
        "{steps:?}"
    );
    // CSP with velocity and acceleration feed-forward follows a constant-speed ramp with no
    // error once the start is over (docs/adapters.md); the start leaves at most the speed times
    // the speed loop's time constant (1 ms): 1000 increments = 0.1 mm, decaying. Stepping 1 ms
    // per SYNC instead, 25 SYNCs could move at most 25 ms × max_velocity = 250 000 increments
    // while the target is at 1 000 000.
    let (target, actual) = track[25];
    assert_eq!(target, 1_000_000);
    for (k, &(target, actual)) in track.iter().enumerate().skip(5) {
        assert!(
            (target - actual).abs() <= 1000,
            "SYNC {k}: target {target}, actual {actual}"
        );
    }
    assert!((target - actual).abs() <= 10, "{target} {actual}");
}

#[test]
fn with_0x1006_each_sync_steps_by_the_period_the_master_wrote() {
    // 0x1006 = 40 ms while the SYNCs come 1 ms apart on the node's clock: the drive steps
    // 40 ms per SYNC as before issue 25 — the same track as 40 ms of real time per SYNC.
    let (with, steps) = ramp(1, Some(40_000), 25);
    assert!(
        steps.iter().all(|&s| s == Nanos::from_micros(40_000)),
        "{steps:?}"
    );
    let (without, _) = ramp(40, None, 25);
    assert_eq!(with[1..], without[1..]);
}

#[test]
fn a_long_sync_gap_steps_at_most_max_sync_step() {
    let mut b = Bench::built_in();
    b.nmt(NmtCommand::Start);
    b.at_ms(10);
    b.sync();
    b.at_ms(50);
    b.sync();
    assert_eq!(b.seg.last_sync_step(), Some(Nanos::from_micros(40_000)));
    b.at_ms(5050);
    b.sync();
    assert_eq!(b.seg.last_sync_step(), Some(MAX_SYNC_STEP));
    // NMT pre-operational and start again: the next SYNC is a first one.
    b.nmt(NmtCommand::EnterPreOperational);
    b.nmt(NmtCommand::Start);
    b.at_ms(5090);
    b.sync();
    assert_eq!(b.seg.last_sync_step(), Some(Nanos::from_micros(1000)));
}

/// EMCY frames (code, register, manufacturer bytes) in `out`.
fn emcys(out: &[CanFrame]) -> Vec<(u16, u8, [u8; 5])> {
    on(out, 0x080 + u32::from(NODE))
        .iter()
        .map(|d| {
            assert_eq!(d.len(), 8, "EMCY is 8 bytes: {d:02x?}");
            (
                u16::from_le_bytes([d[0], d[1]]),
                d[2],
                [d[3], d[4], d[5], d[6], d[7]],
            )
        })
        .collect()
}

#[test]
fn the_mandatory_cia_301_objects_are_there() {
    let mut b = Bench::built_in();
    // 0x1000 device type: CiA 402 (0x0192), servo drive (0x0002).
    assert_eq!(b.read(0x1000, 0), Ok(0x0002_0192));
    // 0x1001 error register: no error.
    assert_eq!(b.read(0x1001, 0), Ok(0));
    // 0x1018 identity, sub 0 = 4 entries.
    assert_eq!(b.read(0x1018, 0), Ok(4));
    assert_eq!(b.read(0x1018, 1), Ok(VENDOR_ID));
    assert_eq!(b.read(0x1018, 4), Ok(u32::from(NODE)));
    // 0x1017 producer heartbeat time (instead of node guarding 0x100C / 0x100D).
    assert_eq!(b.read(0x1017, 0), Ok(u32::from(DEFAULT_HEARTBEAT_MS)));
    // 0x1200 default SDO server: 0x600 + node, 0x580 + node, read-only.
    assert_eq!(b.read(0x1200, 0), Ok(2));
    assert_eq!(b.read(0x1200, 1), Ok(0x600 + u32::from(NODE)));
    assert_eq!(b.read(0x1200, 2), Ok(0x580 + u32::from(NODE)));
    assert_eq!(
        b.write(0x1200, 1, &0x601u32.to_le_bytes()),
        Err(0x0601_0002)
    );
    // 0x1001 is read-only; 0x1003 starts empty.
    assert_eq!(b.write(0x1001, 0, &[0]), Err(0x0601_0002));
    assert_eq!(b.read(0x1003, 0), Ok(0));
    assert_eq!(b.read(0x1003, 1), Err(NO_DATA));
}

#[test]
fn a_drive_fault_sets_0x1001_and_0x1003_and_its_reset_sends_emcy_0000() {
    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 1, 0, 0);
    b.nmt(NmtCommand::Start);
    b.at_ms(1);
    let out = b.sync();
    assert!(emcys(&out).is_empty(), "{out:?}");

    b.seg.nodes_mut()[0].model_mut().inject_fault(0x8611);
    // The fault takes effect at the next model step (FAULT REACTION ACTIVE), the EMCY goes out
    // at the poll after it: 085 [8] 11 86 21 00 00 00 00 00 = following error (CiA 402),
    // register generic (bit 0) + device profile (bit 5).
    b.at_ms(2);
    let mut out = b.sync();
    out.extend(b.at_ms(3));
    assert_eq!(emcys(&out), vec![(0x8611, 0x21, [0; 5])]);
    // FAULT REACTION ACTIVE for one step, then FAULT.
    assert_eq!(b.statusword() & 0x4F, 0x0F, "FAULT REACTION ACTIVE");
    b.at_ms(3);
    assert!(emcys(&b.sync()).is_empty());
    assert_eq!(b.statusword() & 0x4F, 0x08, "FAULT");
    assert_eq!(b.read(0x1001, 0), Ok(0x21));
    assert_eq!(b.node().error_register(), 0x21);
    assert_eq!(b.read(0x1003, 0), Ok(1));
    assert_eq!(b.read(0x1003, 1), Ok(0x0000_8611));
    assert_eq!(b.read(0x1003, 2), Err(NO_DATA));
    // Still in FAULT at the next SYNCs: no second EMCY.
    for ms in 4..=6 {
        b.at_ms(ms);
        assert!(emcys(&b.sync()).is_empty());
    }

    // Fault reset: controlword 0 then 0x80 (rising edge of bit 7) by SDO, acted on at once
    // (transition 15, SWITCH ON DISABLED): EMCY 0x0000, error register 0x00.
    b.write(0x6040, 0, &0u16.to_le_bytes()).unwrap();
    let [lo, hi] = 0x80u16.to_le_bytes();
    let out = b.send(&[CanFrame::new(0x605, &[0x2B, 0x40, 0x60, 0, lo, hi, 0, 0]).unwrap()]);
    assert_eq!(emcys(&out), vec![(0x0000, 0x00, [0; 5])], "{out:?}");
    assert_eq!(b.statusword() & 0x4F, 0x40, "SWITCH ON DISABLED");
    assert_eq!(b.read(0x1001, 0), Ok(0));
    // The history keeps the fault …
    assert_eq!(b.read(0x1003, 0), Ok(1));
    assert_eq!(b.read(0x1003, 1), Ok(0x8611));
    // … until 0 is written to sub-index 0; any other value is refused.
    assert_eq!(b.write(0x1003, 0, &[1]), Err(0x0609_0030));
    assert_eq!(b.write(0x1003, 1, &0u32.to_le_bytes()), Err(0x0601_0002));
    assert_eq!(b.write(0x1003, 0, &[0]), Ok(()));
    assert_eq!(b.read(0x1003, 0), Ok(0));
    assert_eq!(b.read(0x1003, 1), Err(NO_DATA));
    // A second fault is history entry 1 again.
    b.seg.nodes_mut()[0].model_mut().inject_fault(0x2310);
    b.at_ms(7);
    let mut out = b.sync();
    out.extend(b.at_ms(8));
    assert_eq!(emcys(&out), vec![(0x2310, 0x03, [0; 5])]);
    assert_eq!(b.read(0x1003, 1), Ok(0x2310));
}

#[test]
fn the_error_history_holds_the_newest_eight_and_reset_node_clears_it() {
    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 1, 0, 0);
    b.nmt(NmtCommand::Start);
    let mut ms = 0;
    for k in 1..=10u16 {
        b.seg.nodes_mut()[0].model_mut().inject_fault(0x1000 + k);
        ms += 1;
        b.at_ms(ms);
        b.sync();
        // Reset by the RPDO (controlword 0x80 at the next SYNC) and 0 again.
        for cw in [0x80u16, 0] {
            b.send(&[CanFrame::new(0x205, &cw.to_le_bytes()).unwrap()]);
            ms += 1;
            b.at_ms(ms);
            b.sync();
        }
    }
    assert_eq!(b.read(0x1003, 0), Ok(8));
    for sub in 1..=8u8 {
        // Newest first: 0x100A, 0x1009, … 0x1003.
        assert_eq!(
            b.read(0x1003, sub),
            Ok(0x100A - u32::from(sub) + 1),
            "sub {sub}"
        );
    }
    assert_eq!(b.read(0x1003, 9), Err(0x0609_0011));
    b.nmt(NmtCommand::ResetNode);
    b.at_ms(ms + 1);
    assert_eq!(b.read(0x1003, 0), Ok(0));
}

#[test]
fn from_eds_the_error_objects_are_the_nodes_own_with_the_eds_size_of_0x1003() {
    let Some(mut n) = technosoft_node("from_eds_the_error_objects_are_the_nodes_own") else {
        return;
    };
    // The iPOS EDS lists 0x1003 with sub-indices 0 … 5 ([1003] SubNumber=6).
    assert_eq!(upload(&mut n, 0x1001, 0), Ok([0, 0, 0, 0]));
    assert_eq!(upload(&mut n, 0x1003, 0), Ok([0, 0, 0, 0]));
    assert_eq!(upload(&mut n, 0x1003, 5), Err(NO_DATA));
    assert_eq!(upload(&mut n, 0x1003, 6), Err(0x0609_0011));
    // 0x1001 stays read-only whatever the EDS says.
    let r = sdo(&mut n, [0x2F, 0x01, 0x10, 0, 1, 0, 0, 0]);
    assert_eq!(
        (r[0], u32::from_le_bytes([r[4], r[5], r[6], r[7]])),
        (0x80, 0x0601_0002)
    );
}

mod master_loss;
