//! EDS / DCF (CiA 306) parser: the two reference files, one test per error kind, and a
//! no-panic property test over random text and damaged copies of the reference files.
//!
//! Every expected value below was read by hand from the file text (line numbers in comments).

use fieldprobe::bus::canopen::eds::{
    self, AccessType, DataType, EdsErrorKind, Identity, ObjectType, ParseOptions, Value,
};
use proptest::prelude::*;

use crate::common::test_data;
use test_data::test_data;

/// The reference files, in `../shared/test-data/`.
const E35: &str = "eds/python-canopen-e35.eds";
const IPOS: &str = "eds/technosoft-ipos-cia402.eds";

/// The text of reference file `rel`; `None`: absent, `test` skips (see `common/test_data.rs`).
fn read(rel: &str, test: &str) -> Option<String> {
    let path = test_data(rel, test)?;
    let text = std::fs::read_to_string(&path);
    Some(text.unwrap_or_else(|e| panic!("{}: {e}", path.display())))
}

fn e35(test: &str) -> Option<eds::Eds> {
    Some(eds::parse(&read(E35, test)?, "e35.eds").unwrap_or_else(|e| panic!("{e}")))
}

fn ipos(test: &str) -> Option<eds::Eds> {
    Some(eds::parse(&read(IPOS, test)?, "ipos.eds").unwrap_or_else(|e| panic!("{e}")))
}

// ------------------------------------------------------------------------------------------------
// python-canopen examples/eds/e35.eds

#[test]
fn e35_header_sections() {
    let Some(e) = e35("e35_header_sections") else {
        return;
    };
    assert_eq!(e.file_info.file_name.as_deref(), Some("e35.eds"));
    assert_eq!(e.file_info.eds_version.as_deref(), Some("402")); // sic, line 5
    let d = &e.device_info;
    assert_eq!(d.vendor_name.as_deref(), Some("Manufacturer"));
    assert_eq!(d.vendor_number, Some(101)); // decimal in the file
    assert_eq!(d.product_name.as_deref(), Some("example"));
    assert_eq!(d.product_number, Some(25));
    assert_eq!(d.revision_number, Some(295));
    assert_eq!(d.baud_rates, vec![10, 20, 50, 125, 250, 500, 1000]); // BaudRate_800=0
    assert_eq!(d.granularity, Some(8));
    assert_eq!((d.nr_of_rx_pdo, d.nr_of_tx_pdo), (Some(4), Some(4)));
    assert!(d.lss_supported && d.simple_boot_up_slave && !d.simple_boot_up_master);
    let dummies: Vec<(u16, bool)> = e.dummy_usage.iter().map(|(&k, &v)| (k, v)).collect();
    assert_eq!(
        dummies,
        vec![
            (1, false),
            (2, false),
            (3, false),
            (4, false),
            (5, true),
            (6, true),
            (7, true)
        ]
    );
    assert!(e.comments.is_empty()); // Lines=0
    assert!(e.commissioning.is_none());
}

#[test]
fn e35_objects_and_lists() {
    let Some(e) = e35("e35_objects_and_lists") else {
        return;
    };
    // 211 object sections: 101 VAR + 63 RECORD + 47 ARRAY; 894 sub-index sections.
    assert_eq!(e.object_headers.len(), 211);
    assert_eq!(e.objects.len(), 101 + 894);
    assert_eq!(e.object_lists.mandatory, vec![0x1000, 0x1001, 0x1018]);
    assert_eq!(e.object_lists.optional.len(), 104);
    assert_eq!(e.object_lists.optional.last(), Some(&0x6505));
    assert_eq!(e.object_lists.manufacturer.len(), 104); // SupportedObjects=105, entry 105 absent
    assert_eq!(e.object_lists.manufacturer.first(), Some(&0x2000));
    // [23D1] SubNumber=0x83 (line 1506) and 131 sub sections.
    assert_eq!(e.object_headers[&0x23D1].sub_number, Some(0x83));
    assert_eq!(e.object_headers[&0x23D1].object_type, ObjectType::Record);
    assert_eq!(e.subs(0x23D1).count(), 131);
    // [1800] SubNumber=0x5 with subs 0, 1, 2, 3, 5 (no sub 4).
    let subs: Vec<u8> = e.subs(0x1800).map(|s| s.sub).collect();
    assert_eq!(subs, vec![0, 1, 2, 3, 5]);
}

#[test]
fn e35_object_list_defects_are_warnings() {
    let Some(text) = read(E35, "e35_object_list_defects_are_warnings") else {
        return;
    };
    let e = eds::parse(&text, "e35.eds").unwrap_or_else(|e| panic!("{e}"));
    let w: Vec<String> = e.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(
        w,
        vec![
            "e35.eds:115: [ManufacturerObjects] 105: missing; SupportedObjects=105",
            "e35.eds:6775: [OptionalObjects] 104: object 0x6505 is listed but has no section [6505]",
            "e35.eds:6662: [2FFF]: object is in no object list",
        ]
    );
    let err = eds::parse_with(&text, "e35.eds", ParseOptions { strict: true }).unwrap_err();
    assert_eq!(
        err.to_string(),
        "e35.eds:115: [ManufacturerObjects] 105: missing; SupportedObjects=105"
    );
    assert_eq!(err.kind, EdsErrorKind::ObjectList);
}

#[test]
fn e35_values() {
    let Some(e) = e35("e35_values") else {
        return;
    };
    // [1000] DefaultValue=0x20192 (line 53).
    let dt = e.get(0x1000, 0).unwrap();
    assert_eq!(
        (dt.data_type, dt.access),
        (DataType::Unsigned32, AccessType::ReadOnly)
    );
    assert_eq!(dt.default_value(5), Some(Value::Unsigned(0x20192)));
    assert_eq!(dt.value_bytes(5), Some(vec![0x92, 0x01, 0x02, 0x00]));
    // [6072] Max torque: UNSIGNED16 rww 0x3E8 PDOMapping=0x1 (line 8243).
    let t = e.get(0x6072, 0).unwrap();
    assert_eq!(t.parameter_name, "Max torque");
    assert_eq!(
        (t.data_type, t.access),
        (DataType::Unsigned16, AccessType::ReadWriteOutput)
    );
    assert_eq!(t.default_value(5), Some(Value::Unsigned(1000)));
    assert!(e.pdo_mappable(0x6072, 0));
    assert_eq!(t.mapping_entry(), Some(0x6072_0010));
    // [60E0]/[60E1] INTEGER16 ±1000 (lines 8758, 8766).
    assert_eq!(e.get(0x60E0, 0).unwrap().data_type, DataType::Integer16);
    let neg = e.get(0x60E1, 0).unwrap();
    assert_eq!(neg.default_value(5), Some(Value::Integer(-1000)));
    assert_eq!(neg.value_bytes(5), Some(vec![0x18, 0xFC]));
    // [6065] DefaultValue=0xFFFFFFFF ParameterValue=0x1F4 (line 8149).
    let few = e.get(0x6065, 0).unwrap();
    assert_eq!(few.default_value(5), Some(Value::Unsigned(0xFFFF_FFFF)));
    assert_eq!(few.value(5), Some(Value::Unsigned(500)));
    // [1800sub1] DefaultValue=$NODEID+0x40000180, ParameterValue=0x400001A0 (line 7486).
    let cob = e.get(0x1800, 1).unwrap();
    assert!(cob.default.as_ref().unwrap().uses_node_id());
    assert_eq!(cob.default_value(5), Some(Value::Unsigned(0x4000_0185)));
    assert_eq!(cob.parameter_value(5), Some(Value::Unsigned(0x4000_01A0)));
    // [1014] $NODEID+0x80 (line 6961).
    assert_eq!(
        e.get(0x1014, 0).unwrap().default_value(5),
        Some(Value::Unsigned(0x85))
    );
    // [1008] VISIBLE_STRING "emcl" (line 6847).
    assert_eq!(
        e.get(0x1008, 0).unwrap().default_value(5),
        Some(Value::Text("emcl".into()))
    );
    // [2FFE] UNSIGNED64 0x657669724420794D is "My Drive" little-endian (line 6659).
    assert_eq!(
        e.get(0x2FFE, 0).unwrap().value_bytes(0),
        Some(b"My Drive".to_vec())
    );
    // [1018sub1..3] 0xFF, 0x01, 0x01 (lines 84-105), not [DeviceInfo] 101/25/295.
    assert_eq!(
        e.identity(),
        Identity {
            vendor_id: Some(0xFF),
            product_code: Some(1),
            revision_number: Some(1),
            serial_number: None
        }
    );
}

// ------------------------------------------------------------------------------------------------
// Technosoft iPOS (ros2_canopen cia402_slave.eds)

#[test]
fn ipos_header_sections() {
    let Some(e) = ipos("ipos_header_sections") else {
        return;
    };
    assert_eq!(e.file_info.file_name.as_deref(), Some("iPOS.D.v1.04.eds"));
    assert_eq!(
        (e.file_info.file_version, e.file_info.file_revision),
        (Some(1), Some(5))
    );
    let d = &e.device_info;
    assert_eq!(d.vendor_name.as_deref(), Some("Technosoft"));
    assert_eq!(d.vendor_number, Some(0x1A3));
    assert_eq!(d.product_name.as_deref(), Some("iPOS"));
    assert_eq!((d.product_number, d.revision_number), (None, None)); // not in the file
    assert_eq!(d.baud_rates, vec![125, 250, 500, 1000]);
    assert_eq!(d.compact_pdo, Some(0));
    assert!(e.dummy_usage.values().all(|&v| !v));
    assert!(!e.pdo_mappable(0x0005, 0));
    assert_eq!(e.object_headers.len(), 189);
    assert_eq!(e.objects.len(), 144 + 200); // 144 VAR objects + 200 sub sections
    assert_eq!(
        (
            e.object_lists.mandatory.len(),
            e.object_lists.optional.len(),
            e.object_lists.manufacturer.len()
        ),
        (3, 102, 84)
    );
    assert!(e.warnings.is_empty());
    assert_eq!(
        e.identity(),
        Identity {
            vendor_id: Some(0x1A3),
            product_code: None,
            revision_number: None,
            serial_number: None
        }
    );
}

#[test]
fn ipos_touch_probe_objects() {
    let Some(e) = ipos("ipos_touch_probe_objects") else {
        return;
    };
    // Lines 2124-2164.
    let expect = [
        (
            0x60B8,
            "Touch probe function",
            DataType::Unsigned16,
            AccessType::ReadWriteOutput,
        ),
        (
            0x60B9,
            "Touch probe status",
            DataType::Unsigned16,
            AccessType::ReadOnly,
        ),
        (
            0x60BA,
            "Touch probe 1 positive edge",
            DataType::Integer32,
            AccessType::ReadOnly,
        ),
        (
            0x60BB,
            "Touch probe 1 negative edge",
            DataType::Integer32,
            AccessType::ReadOnly,
        ),
        (
            0x60BC,
            "Touch probe 2 positive edge",
            DataType::Integer32,
            AccessType::ReadOnly,
        ),
        (
            0x60BD,
            "Touch probe 2 negative edge",
            DataType::Integer32,
            AccessType::ReadOnly,
        ),
    ];
    for (index, name, data_type, access) in expect {
        let entry = e
            .get(index, 0)
            .unwrap_or_else(|| panic!("{index:#06x} missing"));
        assert_eq!(entry.parameter_name, name);
        assert_eq!(
            (entry.data_type, entry.access),
            (data_type, access),
            "{index:#06x}"
        );
        assert!(entry.pdo_mapping && e.pdo_mappable(index, 0));
        assert_eq!(entry.default, None);
    }
    assert_eq!(e.get(0x60B9, 0).unwrap().mapping_entry(), Some(0x60B9_0010));
    assert_eq!(e.get(0x60BA, 0).unwrap().mapping_entry(), Some(0x60BA_0020));
}

#[test]
fn ipos_values() {
    let Some(e) = ipos("ipos_values") else {
        return;
    };
    // [1013] AccessType=rwr, the only one in the file (line 386).
    assert_eq!(e.get(0x1013, 0).unwrap().access, AccessType::ReadWriteInput);
    assert_eq!(
        e.get(0x1008, 0).unwrap().default_value(0),
        Some(Value::Text("iPOS".into()))
    );
    assert_eq!(
        e.get(0x1000, 0).unwrap().default_value(0),
        Some(Value::Unsigned(0x60192))
    );
    // $NODEID terms for node 5: [1014] +0x80, [1400sub1] +0x200 (lines 396, 460).
    assert_eq!(
        e.get(0x1014, 0).unwrap().default_value(5),
        Some(Value::Unsigned(0x85))
    );
    assert_eq!(
        e.get(0x1400, 1).unwrap().default_value(5),
        Some(Value::Unsigned(0x205))
    );
    assert_eq!(
        e.get(0x1400, 1).unwrap().value_bytes(5),
        Some(vec![0x05, 0x02, 0, 0])
    );
    // [1A00] SubNumber=9; sub1 maps 0x6041 (statusword) 16 bits (line 1088).
    assert_eq!(e.object_headers[&0x1A00].sub_number, Some(9));
    assert_eq!(e.subs(0x1A00).count(), 9);
    assert_eq!(
        e.get(0x1A00, 1).unwrap().default_value(0),
        Some(Value::Unsigned(0x6041_0010))
    );
    // [6066] LowLimit=0 HighLimit=65535 (line 1530).
    let fe = e.get(0x6066, 0).unwrap();
    assert_eq!(fe.low_limit_value(0), Some(Value::Unsigned(0)));
    assert_eq!(fe.high_limit_value(0), Some(Value::Unsigned(65535)));
    // [1018sub0] DefaultValue=4 LowLimit=1 HighLimit=4.
    let n = e.get(0x1018, 0).unwrap();
    assert_eq!(n.default_value(0), Some(Value::Unsigned(4)));
    assert_eq!(n.high_limit_value(0), Some(Value::Unsigned(4)));
    assert!(e.get(0x6072, 0).is_none()); // no max torque in this drive
}

#[test]
fn load_reads_a_file() {
    let Some(path) = test_data(IPOS, "load_reads_a_file") else {
        return;
    };
    let e = eds::load(path).unwrap();
    assert_eq!(e.objects.len(), 344);
    let err = eds::load("/nonexistent/x.eds").unwrap_err();
    assert_eq!(err.kind, EdsErrorKind::Io);
}

// ------------------------------------------------------------------------------------------------
// Synthetic files: compact storage, DCF

const HEAD: &str = "[DeviceInfo]\nVendorNumber=0x1A3\n[MandatoryObjects]\nSupportedObjects=1\n1=0x1000\n\
                    [1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\n\
                    DefaultValue=0x60192\n";

#[test]
fn compact_storage_creates_subs() {
    let text = format!(
        "{HEAD}[OptionalObjects]\nSupportedObjects=1\n1=0x1016\n\
         [1016]\nParameterName=Consumer heartbeat time\nObjectType=0x8\nDataType=0x0007\n\
         AccessType=rw\nDefaultValue=0\nPDOMapping=0\nCompactSubObj=3\n\
         [1016Name]\nNrOfEntries=1\n2=Heartbeat of node 7\n\
         [1016Value]\nNrOfEntries=1\n1=0x00070064\n"
    );
    let e = eds::parse(&text, "c.eds").unwrap();
    let subs: Vec<(u8, &str)> = e
        .subs(0x1016)
        .map(|s| (s.sub, s.parameter_name.as_str()))
        .collect();
    assert_eq!(
        subs,
        vec![
            (0, "NrOfObjects"),
            (1, "Consumer heartbeat time1"),
            (2, "Heartbeat of node 7"),
            (3, "Consumer heartbeat time3")
        ]
    );
    let n = e.get(0x1016, 0).unwrap();
    assert_eq!(
        (n.data_type, n.access),
        (DataType::Unsigned8, AccessType::ReadOnly)
    );
    assert_eq!(n.default_value(0), Some(Value::Unsigned(3)));
    let s1 = e.get(0x1016, 1).unwrap();
    assert_eq!(
        (s1.data_type, s1.access),
        (DataType::Unsigned32, AccessType::ReadWrite)
    );
    assert_eq!(s1.value(0), Some(Value::Unsigned(0x0007_0064)));
    assert_eq!(e.get(0x1016, 3).unwrap().value(0), Some(Value::Unsigned(0)));
    assert_eq!(e.object_headers[&0x1016].compact_sub_obj, Some(3));
}

#[test]
fn dcf_commissioning() {
    let text = format!(
        "{HEAD}[DeviceComissioning]\nNodeID=0x20\nNodeName=axis X\nBaudrate=500\nNetNumber=1\n\
         CANopenManager=0\n[OptionalObjects]\nSupportedObjects=1\n1=0x1014\n\
         [1014]\nParameterName=COB-ID EMCY\nDataType=0x0007\nAccessType=rw\n\
         DefaultValue=$NODEID+0x80\nParameterValue=0xA0\n[Comments]\nLines=2\nLine1=first\nLine2=second\n"
    );
    let e = eds::parse(&text, "x.dcf").unwrap();
    let c = e.commissioning.as_ref().unwrap();
    assert_eq!(
        (c.node_id, c.baud_rate, c.node_name.as_deref()),
        (Some(0x20), Some(500), Some("axis X"))
    );
    assert_eq!(e.node_id(), Some(0x20));
    let emcy = e.get(0x1014, 0).unwrap();
    assert_eq!(emcy.object_type, ObjectType::Var); // ObjectType absent = VAR
    assert_eq!(emcy.default_value(0x20), Some(Value::Unsigned(0xA0)));
    assert_eq!(emcy.value(0x20), Some(Value::Unsigned(0xA0)));
    assert_eq!(e.comments, vec!["first", "second"]);
}

#[test]
fn crlf_bom_comments_and_case() {
    let text = "\u{feff}; comment\r\n[mandatoryobjects]\r\nsupportedobjects=1\r\n1=0x1000\r\n\
                [1000]\r\nPARAMETERNAME=x ; inline comment\r\nDataType=7\r\nAccessType=RO\r\n\
                #DefaultValue=1\r\nDefaultValue=010\r\n";
    let e = eds::parse(text, "c.eds").unwrap();
    let entry = e.get(0x1000, 0).unwrap();
    assert_eq!(entry.parameter_name, "x");
    assert_eq!(entry.access, AccessType::ReadOnly);
    assert_eq!(entry.default_value(0), Some(Value::Unsigned(8))); // octal
}

// ------------------------------------------------------------------------------------------------
// Values

#[test]
fn value_text_forms() {
    let u16_ = DataType::Unsigned16;
    assert_eq!(u16_.value_from_text("0x1F", 0), Ok(Value::Unsigned(31)));
    assert_eq!(u16_.value_from_text("017", 0), Ok(Value::Unsigned(15)));
    assert_eq!(
        u16_.value_from_text("$NODEID + 0x600", 3),
        Ok(Value::Unsigned(0x603))
    );
    assert_eq!(
        u16_.value_from_text("0x700+$nodeid", 3),
        Ok(Value::Unsigned(0x703))
    );
    assert!(u16_.value_from_text("0x10000", 0).is_err());
    assert_eq!(
        DataType::Integer16.value_from_text("0xFFFF", 0),
        Ok(Value::Integer(-1))
    );
    assert_eq!(
        DataType::Integer24.value_from_text("-8388608", 0),
        Ok(Value::Integer(-8_388_608))
    );
    assert_eq!(
        DataType::Boolean.value_from_text("1", 0),
        Ok(Value::Bool(true))
    );
    assert_eq!(
        DataType::Real32.value_from_text("0x3F800000", 0),
        Ok(Value::Real32(1.0))
    );
    assert_eq!(
        DataType::Real64.value_from_text("-2.5", 0),
        Ok(Value::Real64(-2.5))
    );
    assert_eq!(
        DataType::OctetString.value_from_text("01 ab", 0),
        Ok(Value::Bytes(vec![1, 0xAB]))
    );
    assert_eq!(
        DataType::Integer24.encode(&Value::Integer(-2)),
        Ok(vec![0xFE, 0xFF, 0xFF])
    );
    assert_eq!(
        DataType::Integer24.decode(&[0xFE, 0xFF, 0xFF]),
        Ok(Value::Integer(-2))
    );
    assert_eq!(DataType::Unsigned48.size(), Some(6));
    assert_eq!(DataType::VisibleString.size(), None);
    assert_eq!(DataType::from_code(0x17), None);
    assert_eq!(DataType::from_code(0x23), Some(DataType::Other(0x23)));
}

proptest! {
    #[test]
    fn integer_encode_decode_round_trip(code in prop::sample::select(vec![
        0x01u16, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x10, 0x12, 0x13, 0x14, 0x15, 0x16, 0x18,
        0x19, 0x1A, 0x1B]), raw in any::<u64>()) {
        let dt = DataType::from_code(code).unwrap();
        let size = dt.size().unwrap();
        let mut bytes = raw.to_le_bytes()[..size].to_vec();
        if dt == DataType::Boolean {
            bytes[0] &= 1;
        }
        let v = dt.decode(&bytes).unwrap();
        prop_assert_eq!(dt.encode(&v).unwrap(), bytes);
    }
}

// ------------------------------------------------------------------------------------------------
// Errors, one per kind

fn err(text: &str) -> String {
    match eds::parse_with(text, "t.eds", ParseOptions { strict: true }) {
        Ok(_) => panic!("parsed"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn error_missing_mandatory_objects() {
    assert_eq!(
        err("[FileInfo]\nFileName=t.eds\n"),
        "t.eds: [MandatoryObjects]: missing section"
    );
}

#[test]
fn error_listed_object_without_section() {
    let text = HEAD.replace(
        "SupportedObjects=1\n1=0x1000\n",
        "SupportedObjects=2\n1=0x1000\n2=0x1001\n",
    );
    assert_eq!(
        err(&text),
        "t.eds:6: [MandatoryObjects] 2: object 0x1001 is listed but has no section [1001]"
    );
    // Lenient mode keeps it as a warning.
    let e = eds::parse(&text, "t.eds").unwrap();
    assert_eq!(e.warnings.len(), 1);
    assert_eq!(e.warnings[0].kind, EdsErrorKind::MissingSection);
}

#[test]
fn error_bad_number() {
    let text = HEAD.replace("DefaultValue=0x60192", "DefaultValue=0x60G92");
    assert_eq!(
        err(&text),
        "t.eds:11: [1000] DefaultValue: bad number \"0x60G92\""
    );
    // Read leniently: a warning at the value, and no value.
    let e = eds::parse(&text, "t.eds").unwrap();
    let w = &e.warnings[0];
    assert_eq!(
        (w.kind, w.line, w.column, w.object),
        (
            EdsErrorKind::BadNumber,
            Some(11),
            Some(14),
            Some((0x1000, 0))
        )
    );
    assert_eq!(
        w.to_string(),
        "t.eds:11: [1000] DefaultValue: bad number \"0x60G92\"; no value: the object reads 0 (empty)"
    );
    assert_eq!(e.get(0x1000, 0).unwrap().default_value(1), None);
    let text = HEAD.replace("VendorNumber=0x1A3", "VendorNumber=0x1A3_0000_0000");
    assert_eq!(
        err(&text),
        "t.eds:2: [DeviceInfo] VendorNumber: bad number \"0x1A3_0000_0000\""
    );
    let text = HEAD.replace("DefaultValue=0x60192", "DefaultValue=0x100000000");
    assert_eq!(
        err(&text),
        "t.eds:11: [1000] DefaultValue: 4294967296 is out of range for Unsigned32"
    );
    let text = HEAD.replace("DefaultValue=0x60192", "DefaultValue=$NODEID+0xFFFFFFFF");
    assert_eq!(
        err(&text),
        "t.eds:11: [1000] DefaultValue: 4294967296 is out of range for Unsigned32 (with $NODEID=1)"
    );
}

#[test]
fn error_unknown_data_type() {
    let text = HEAD.replace("DataType=0x0007", "DataType=0x0017");
    assert_eq!(
        err(&text),
        "t.eds:9: [1000] DataType: unknown data type code 0x0017 (CiA 301 data type table)"
    );
}

#[test]
fn error_unknown_access_type() {
    let text = HEAD.replace("AccessType=ro", "AccessType=r");
    assert_eq!(
        err(&text),
        "t.eds:10: [1000] AccessType: unknown access type \"r\" (allowed: ro, wo, rw, rwr, rww, const)"
    );
    let e = eds::parse(&text, "t.eds").unwrap();
    assert_eq!(e.warnings[0].kind, EdsErrorKind::UnknownAccessType);
    assert_eq!(e.warnings[0].used.as_deref(), Some("read as ro"));
    assert_eq!(e.get(0x1000, 0).unwrap().access, AccessType::ReadOnly);
}

#[test]
fn error_unknown_object_type() {
    let text = HEAD.replace("ObjectType=0x7", "ObjectType=0x3");
    assert_eq!(
        err(&text),
        "t.eds:8: [1000] ObjectType: unknown object type 0x3 (allowed: 0x0 NULL, 0x2 DOMAIN, \
         0x5 DEFTYPE, 0x6 DEFSTRUCT, 0x7 VAR, 0x8 ARRAY, 0x9 RECORD)"
    );
}

#[test]
fn error_duplicate_section() {
    let text = format!("{HEAD}[1000]\nParameterName=again\n");
    assert_eq!(
        err(&text),
        "t.eds:12: [1000]: duplicate section (first at line 6)"
    );
    let text = format!("{HEAD}[1018sub1]\nDataType=7\nAccessType=ro\n[1018sub01]\n");
    // The sub sections need their object first; the duplicate-sub check comes after that one.
    assert_eq!(
        err(&text),
        "t.eds:12: [1018sub1]: sub-index section without its object section [1018]"
    );
}

#[test]
fn error_duplicate_key() {
    let text = HEAD.replace("AccessType=ro\n", "AccessType=ro\naccesstype=rw\n");
    assert_eq!(
        err(&text),
        "t.eds:11: [1000] accesstype: duplicate key (first at line 10)"
    );
}

#[test]
fn error_key_outside_section() {
    assert_eq!(
        err(&format!("FileName=x.eds\n{HEAD}")),
        "t.eds:1: FileName: key before the first section header"
    );
}

#[test]
fn error_syntax() {
    assert_eq!(
        err(&format!("{HEAD}[1001\n")),
        "t.eds:12: section header without closing `]`"
    );
    assert_eq!(
        err(&format!("{HEAD}PDOMapping\n")),
        "t.eds:12: [1000]: expected `key=value`, got \"PDOMapping\""
    );
}

const RECORD: &str = "[OptionalObjects]\nSupportedObjects=1\n1=0x1018\n\
                      [1018]\nParameterName=Identity\nObjectType=0x9\nSubNumber=2\n\
                      [1018sub0]\nParameterName=n\nDataType=5\nAccessType=ro\nDefaultValue=1\n\
                      [1018sub1]\nParameterName=Vendor\nDataType=7\nAccessType=ro\nDefaultValue=0x1A3\n";

#[test]
fn record_parses() {
    let e = eds::parse(&format!("{HEAD}{RECORD}"), "t.eds").unwrap();
    assert_eq!(e.identity().vendor_id, Some(0x1A3));
    assert_eq!(e.subs(0x1018).count(), 2);
}

#[test]
fn error_sub_number_mismatch() {
    let text = format!("{HEAD}{}", RECORD.replace("SubNumber=2", "SubNumber=3"));
    assert_eq!(
        err(&text),
        "t.eds:18: [1018] SubNumber: SubNumber=3 but 2 sub-index sections are present"
    );
    let e = eds::parse(&text, "t.eds").unwrap();
    assert_eq!(e.warnings[0].kind, EdsErrorKind::SubNumberMismatch);
    assert_eq!(
        e.warnings[0].used.as_deref(),
        Some("the 2 sub-index sections present are read")
    );
    assert_eq!(e.subs(0x1018).count(), 2);
}

#[test]
fn error_duplicate_sub_index() {
    let text = format!("{HEAD}{}[1018sub01]\nDataType=5\nAccessType=ro\n", RECORD);
    assert_eq!(
        err(&text),
        "t.eds:29: [1018sub01]: same sub-index as [1018sub1] at line 24"
    );
}

#[test]
fn error_data_type_missing_on_var() {
    let text = HEAD.replace("DataType=0x0007\n", "");
    assert_eq!(
        err(&text),
        "t.eds:6: [1000] DataType: missing; required for a VAR"
    );
    let e = eds::parse(&text, "t.eds").unwrap();
    assert_eq!(e.warnings[0].kind, EdsErrorKind::MissingKey);
    assert_eq!(
        e.warnings[0].used.as_deref(),
        Some("the object is left out")
    );
    assert!(e.get(0x1000, 0).is_none());
}

// ------------------------------------------------------------------------------------------------
// Never panic

fn damage(text: &str, cuts: &[(usize, usize)], truncate: usize) -> String {
    let mut s = text.to_string();
    for &(at, len) in cuts {
        if s.is_empty() {
            break;
        }
        let mut a = at % s.len();
        while !s.is_char_boundary(a) {
            a -= 1;
        }
        let mut b = (a + len).min(s.len());
        while !s.is_char_boundary(b) {
            b += 1;
        }
        s.replace_range(a..b, "");
    }
    let mut t = truncate % (s.len() + 1);
    while !s.is_char_boundary(t) {
        t -= 1;
    }
    s.truncate(t);
    s
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn random_text_never_panics(text in ".{0,400}") {
        let _ = eds::parse(&text, "r.eds");
    }

    #[test]
    fn ini_shaped_text_never_panics(lines in prop::collection::vec(
        "(\\[[0-9A-Fa-f]{4}(sub[0-9A-Fa-f]{1,3}|Name|Value)?\\]|\\[MandatoryObjects\\]|[A-Za-z]{1,12}=[-+$0-9A-Za-z x]{0,12}|[0-9]=0x[0-9A-F]{4}|SupportedObjects=[0-9]|CompactSubObj=[0-9]{1,3}|SubNumber=[0-9]|ObjectType=[0-9]|DataType=0x00[0-9A-F]{2}|DefaultValue=\\$NODEID\\+0x[0-9A-F]{1,9})",
        0..40,
    )) {
        let _ = eds::parse(&lines.join("\n"), "r.eds");
    }

    #[test]
    fn decode_never_panics(code in 0u16..0x300, bytes in prop::collection::vec(any::<u8>(), 0..12)) {
        if let Some(dt) = DataType::from_code(code) {
            if let Ok(v) = dt.decode(&bytes) {
                let _ = dt.encode(&v);
            }
        }
    }
}

// The reference files as seeds: property tests over damaged copies. Each skips as a whole where
// the files are absent (closure form of `proptest!`, run only once the files are read).

fn seed_config() -> ProptestConfig {
    ProptestConfig {
        cases: 200,
        ..ProptestConfig::default()
    }
}

#[test]
fn damaged_e35_never_panics() {
    let Some(e35) = read(E35, "damaged_e35_never_panics") else {
        return;
    };
    proptest!(seed_config(), |(
        cuts in prop::collection::vec((any::<usize>(), 0usize..200), 0..4),
        truncate in any::<usize>(),
    )| {
        let text = damage(&e35, &cuts, truncate);
        let _ = eds::parse(&text, "e35.eds");
        let _ = eds::parse_with(&text, "e35.eds", ParseOptions { strict: true });
    });
}

#[test]
fn damaged_ipos_never_panics() {
    let Some(ipos) = read(IPOS, "damaged_ipos_never_panics") else {
        return;
    };
    proptest!(seed_config(), |(
        cuts in prop::collection::vec((any::<usize>(), 0usize..200), 0..4),
        truncate in any::<usize>(),
    )| {
        let text = damage(&ipos, &cuts, truncate);
        if let Ok(e) = eds::parse(&text, "ipos.eds") {
            for entry in e.objects.values() {
                let _ = entry.value_bytes(127);
                let _ = entry.low_limit_value(1);
            }
            let _ = e.identity();
        }
    });
}

#[test]
fn line_deletions_never_panic() {
    const TEST: &str = "line_deletions_never_panic";
    let (Some(e35), Some(ipos)) = (read(E35, TEST), read(IPOS, TEST)) else {
        return;
    };
    proptest!(seed_config(), |(
        which in prop::bool::ANY,
        drops in prop::collection::vec(any::<prop::sample::Index>(), 1..30),
    )| {
        let text = if which { &e35 } else { &ipos };
        let mut lines: Vec<&str> = text.lines().collect();
        for d in drops {
            if lines.is_empty() {
                break;
            }
            lines.remove(d.index(lines.len()));
        }
        let _ = eds::parse(&lines.join("\n"), "lines.eds");
    });
}

// ------------------------------------------------------------------------------------------------
// Files as vendors write them (issue 25): read leniently, each oddity a warning saying what is
// read instead; strict mode refuses at the first. Values by hand from the files / CiA 306.

const YIYOU: &str = "eds/Yiyou-EuServo-V1.4.eds";
const DEMACLENKO: &str = "eds/Demaclenko-emecdrv5-rev09.eds";

#[test]
fn yiyou_high_limit_65536_on_unsigned16_reads_as_65535_one_folded_warning() {
    let Some(text) = read(YIYOU, "yiyou_high_limit_65536_on_unsigned16_reads_as_65535") else {
        return;
    };
    let e = eds::parse(&text, "yiyou.eds").unwrap_or_else(|e| panic!("{e}"));
    // [2023] line 2062 and [2025] line 2084: DataType=0x0006, HighLimit=65536 (lines 2070, 2092).
    for index in [0x2023, 0x2025] {
        let x = e.get(index, 0).unwrap();
        assert_eq!(x.data_type, DataType::Unsigned16);
        assert_eq!(x.high_limit_value(1), Some(Value::Unsigned(65535)));
        assert_eq!(x.low_limit_value(1), Some(Value::Unsigned(0)));
    }
    let w: Vec<&eds::EdsWarning> = e
        .warnings
        .iter()
        .filter(|w| w.kind == EdsErrorKind::OutOfRange)
        .collect();
    assert_eq!(w.len(), 1, "{:?}", e.warnings);
    assert_eq!(w[0].count(), 2);
    assert_eq!(
        w[0].to_string(),
        "yiyou.eds:2070: [2023] HighLimit: 65536 is out of range for Unsigned16; read as 65535, \
         the largest Unsigned16 (and 1 more like it: [2025] line 2092)"
    );
    assert_eq!(w[0].object, Some((0x2023, 0)));
    // [1000] DefaultValue=131474 (decimal) = 0x00020192, CiA 402.
    assert_eq!(
        e.get(0x1000, 0).unwrap().default_value(1),
        Some(Value::Unsigned(0x0002_0192))
    );
    let strict = eds::parse_with(&text, "yiyou.eds", ParseOptions { strict: true }).unwrap_err();
    assert_eq!(
        strict.to_string(),
        "yiyou.eds:2070: [2023] HighLimit: 65536 is out of range for Unsigned16"
    );
}

#[test]
fn demaclenko_device_type_is_read_as_written_with_a_warning() {
    let Some(text) = read(DEMACLENKO, "demaclenko_device_type_is_read_as_written") else {
        return;
    };
    let e = eds::parse(&text, "emec.eds").unwrap_or_else(|e| panic!("{e}"));
    // [1000] line 103, DefaultValue=0x92020100 (line 108): bits 0 … 15 = 0x0100 = 256.
    assert_eq!(
        e.get(0x1000, 0).unwrap().default_value(1),
        Some(Value::Unsigned(0x9202_0100))
    );
    let w = e
        .warnings
        .iter()
        .find(|w| w.kind == EdsErrorKind::DeviceType)
        .expect("a device type warning");
    assert_eq!((w.line, w.object), (Some(108), Some((0x1000, 0))));
    let text = w.to_string();
    for want in [
        "device profile 256",
        "0x92 and 0x01",
        "byte order looks swapped",
        "reports 0x92020100",
    ] {
        assert!(text.contains(want), "{want:?} in {text}");
    }
    // 1 RPDO ([1400]/[1600]) and 4 TPDOs, NrOfRXPDO=1 (line 39).
    assert_eq!(e.device_info.nr_of_rx_pdo, Some(1));
    assert!(e.get(0x1401, 1).is_none());
    assert_eq!(e.subs(0x1600).count(), 9);
}

#[test]
fn every_vendor_file_reads_leniently() {
    let Some(dir) = test_data::test_data(YIYOU, "every_vendor_file_reads_leniently") else {
        return;
    };
    let dir = dir.parent().unwrap();
    let mut n = 0;
    for f in std::fs::read_dir(dir).unwrap() {
        let p = f.unwrap().path();
        if !p
            .extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("eds") || x.eq_ignore_ascii_case("dcf"))
        {
            continue;
        }
        let e = eds::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(!e.objects.is_empty(), "{}", p.display());
        // Every value of every entry reads in its type (what a node or a master uses).
        for x in e.objects.values() {
            if let Some(v) = x.value(1) {
                x.data_type
                    .encode(&v)
                    .unwrap_or_else(|err| panic!("{}: {x:?}: {err}", p.display()));
            }
        }
        n += 1;
    }
    assert!(n >= 8, "{n} files in {}", dir.display());
}

fn lenient(text: &str) -> eds::Eds {
    eds::parse(text, "t.eds").unwrap_or_else(|e| panic!("{e}"))
}

fn used(e: &eds::Eds, kind: EdsErrorKind) -> String {
    let w = e
        .warnings
        .iter()
        .find(|w| w.kind == kind)
        .unwrap_or_else(|| panic!("no {kind:?} warning in {:?}", e.warnings));
    w.used.clone().unwrap_or_default()
}

#[test]
fn odd_structure_is_read_with_warnings() {
    // Repeated key: the first counts.
    let e = lenient(&HEAD.replace("AccessType=ro\n", "AccessType=ro\nAccessType=rw\n"));
    assert_eq!(e.get(0x1000, 0).unwrap().access, AccessType::ReadOnly);
    assert_eq!(
        used(&e, EdsErrorKind::DuplicateKey),
        "this value is ignored, the first counts"
    );
    // Repeated section: ignored.
    let e = lenient(&format!("{HEAD}[1000]\nParameterName=again\n"));
    assert_eq!(e.get(0x1000, 0).unwrap().parameter_name, "Device type");
    // No [MandatoryObjects], no AccessType, an unknown ObjectType, a line without `=`.
    let text = "[1000]\nParameterName=Device type\nObjectType=0x3\nDataType=0x0007\n\
                DefaultValue=0x20192\ngarbage\n[1017]\nDataType=0x0007\nAccessType=rw\n\
                DefaultValue=100\n";
    let e = lenient(text);
    let d = e.get(0x1000, 0).unwrap();
    assert_eq!(
        (d.object_type, d.access),
        (ObjectType::Var, AccessType::ReadWrite)
    );
    assert_eq!(used(&e, EdsErrorKind::MissingKey), "read as rw");
    assert_eq!(used(&e, EdsErrorKind::UnknownObjectType), "read as 0x7");
    assert_eq!(used(&e, EdsErrorKind::Syntax), "the line is ignored");
    // 0x1017 declared UNSIGNED32: read as CiA 301's UNSIGNED16.
    assert_eq!(e.get(0x1017, 0).unwrap().data_type, DataType::Unsigned16);
    assert_eq!(
        e.get(0x1017, 0).unwrap().default_value(1),
        Some(Value::Unsigned(100))
    );
    // Text with no object section at all is no EDS.
    let err = eds::parse("[FileInfo]\nFileName=x\n", "t.eds").unwrap_err();
    assert_eq!(err.kind, EdsErrorKind::MissingSection);
}

#[test]
fn odd_values_are_read_and_many_identical_problems_are_one_warning() {
    let mut text = String::from(HEAD);
    text.push_str("[OptionalObjects]\nSupportedObjects=40\n");
    for i in 0..40 {
        text.push_str(&format!("{}=0x{:04X}\n", i + 1, 0x2000 + i));
    }
    for i in 0..40 {
        text.push_str(&format!(
            "[{:04X}]\nParameterName=p{i}\nDataType=0x0005\nAccessType=rw\nDefaultValue=0\n\
             LowLimit=-1\nHighLimit=256\n",
            0x2000 + i
        ));
    }
    // One more with odd number forms.
    text = text.replace("SupportedObjects=40", "SupportedObjects=41");
    text = text.replace("40=0x2027\n", "40=0x2027\n41=0x2100\n");
    text.push_str(
        "[2100]\nParameterName=odd\nDataType=0x0007\nAccessType=rw\nDefaultValue=0x 1A3\n\
         LowLimit=0189\nHighLimit=#xFFFF\n",
    );
    let e = lenient(&text);
    let x = e.get(0x2000, 0).unwrap();
    assert_eq!(x.low_limit_value(1), Some(Value::Unsigned(0)));
    assert_eq!(x.high_limit_value(1), Some(Value::Unsigned(255)));
    let ranges: Vec<&eds::EdsWarning> = e
        .warnings
        .iter()
        .filter(|w| w.kind == EdsErrorKind::OutOfRange)
        .collect();
    // 40 LowLimit=-1 and 40 HighLimit=256: two warnings, 40 places each.
    assert_eq!(ranges.len(), 2, "{ranges:?}");
    assert!(ranges.iter().all(|w| w.count() == 40));
    assert!(ranges[0]
        .to_string()
        .contains("(and 39 more like it: [2001] line"));
    let odd = e.get(0x2100, 0).unwrap();
    assert_eq!(odd.default_value(1), Some(Value::Unsigned(0x1A3)));
    assert_eq!(odd.low_limit_value(1), Some(Value::Unsigned(189)));
    assert_eq!(odd.high_limit_value(1), Some(Value::Unsigned(0xFFFF)));
    let forms: Vec<String> = e
        .warnings
        .iter()
        .filter(|w| w.object == Some((0x2100, 0)))
        .map(ToString::to_string)
        .collect();
    assert_eq!(forms.len(), 3, "{forms:?}");
    assert!(forms[0].contains("blanks inside the number"), "{forms:?}");
    assert!(
        forms[1].contains("leading 0 before a decimal number"),
        "{forms:?}"
    );
    assert!(forms[2].contains("`#x` hexadecimal prefix"), "{forms:?}");
}

#[test]
fn many_distinct_problems_read_in_linear_time() {
    // 100 000 lines that are not INI, each different: 100 000 warnings that do not fold. Folding
    // them pairwise would compare 10^10 times; the reader keys them instead. The bound is wide
    // for a loaded machine (a linear read takes well under a second).
    let mut text = String::from(HEAD);
    for i in 0..100_000 {
        text.push_str(&format!("not ini {i}\n"));
    }
    let t0 = std::time::Instant::now();
    let e = lenient(&text);
    assert!(
        t0.elapsed() < std::time::Duration::from_secs(30),
        "{:?}",
        t0.elapsed()
    );
    assert_eq!(e.warnings.len(), 100_000);
    assert!(e.get(0x1000, 0).is_some());
}
