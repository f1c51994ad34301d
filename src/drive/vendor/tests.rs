use super::*;

fn obj(index: u16, ty: DataType, rx: bool, tx: bool) -> VendorObject {
    VendorObject {
        index,
        sub: 0,
        plays: (index, 0),
        name: format!("object {index:04X}"),
        type_name: ty.name().to_string(),
        ty: Some(ty),
        bits: ty.size() as u32 * 8,
        rx,
        tx,
        writable: rx,
        default: None,
        low: None,
        high: None,
    }
}

fn device(objects: Vec<VendorObject>) -> VendorDevice {
    VendorDevice {
        file: "x.eds".into(),
        kind: "EDS",
        vendor: "Acme Motion".into(),
        product: "Servo 7".into(),
        objects,
        ..VendorDevice::default()
    }
}

fn minimal() -> Vec<VendorObject> {
    vec![
        obj(0x6040, DataType::U16, true, false),
        obj(0x607A, DataType::I32, true, false),
        obj(0x6060, DataType::I8, true, false),
        obj(0x6041, DataType::U16, false, true),
        obj(0x6064, DataType::I32, false, true),
        obj(0x6061, DataType::I8, false, true),
    ]
}

#[test]
fn minimal_device_gives_a_definition_without_probe() {
    let g = generate(&device(minimal()), None).unwrap();
    let def = catalogue::parse(&g.toml, "t").unwrap();
    assert_eq!(def.name, "acme-servo-7");
    assert!(!g.touch_probe && !g.toml.contains("[probe]"));
    // Bytes: 0x6040 + 0x607A + 0x6060 out, 0x6041 + 0x6064 + 0x6061 in.
    assert_eq!(def.rxpdo.len(), 2 + 4 + 1);
    assert_eq!(def.txpdo.len(), 2 + 4 + 1);
    assert!(!def.has_drive_latch());
    assert!(def.functions.is_empty());
    assert!(
        g.notes.iter().any(|n| n.contains("no touch probe")),
        "{:?}",
        g.notes
    );
    assert!(
        g.notes.iter().any(|n| n.contains("0x60F4")),
        "{:?}",
        g.notes
    );
}

#[test]
fn a_required_object_in_the_wrong_direction_or_size_is_named() {
    let mut o = minimal();
    o[1].rx = false; // 0x607A only into a TxPDO
    o[3].bits = 32; // 0x6041 as 32 bits
    o.remove(5); // no 0x6061
    let e = generate(&device(o), None).unwrap_err().to_string();
    assert!(e.contains("x.eds") && e.contains("Servo 7"), "{e}");
    assert!(
        e.contains("0x607A:00 target position: not mappable into an RxPDO"),
        "{e}"
    );
    assert!(e.contains("0x6041:00 statusword: 32 bits"), "{e}");
    assert!(
        e.contains("0x6061:00 modes of operation display: not in the file"),
        "{e}"
    );
}

#[test]
fn probe_needs_function_status_and_a_value() {
    let mut o = minimal();
    o.push(obj(0x60B8, DataType::U16, true, false));
    o.push(obj(0x60B9, DataType::U16, false, true));
    let g = generate(&device(o.clone()), None).unwrap();
    assert!(!g.touch_probe);
    o.push(obj(0x60BA, DataType::I32, false, true));
    let g = generate(&device(o), None).unwrap();
    assert!(g.touch_probe);
    let def = catalogue::parse(&g.toml, "t").unwrap();
    assert!(def.rxpdo.contains(0x60B8, 0) && def.txpdo.contains(0x60BA, 0));
    assert!(!def.txpdo.contains(0x60BB, 0));
    assert!(
        g.notes.iter().any(|n| n.contains("0x60BB")),
        "{:?}",
        g.notes
    );
}

#[test]
fn functions_take_the_file_type_and_limits() {
    let mut o = minimal();
    let mut pos = obj(0x60E0, DataType::I16, true, false);
    pos.high = Some(3000);
    o.push(pos);
    let mut window = obj(0x6065, DataType::U32, false, false);
    window.writable = true;
    o.push(window);
    let mut ro = obj(0x6072, DataType::U16, false, true);
    ro.writable = false;
    o.push(ro);
    let g = generate(&device(o), Some("mine")).unwrap();
    let def = catalogue::parse(&g.toml, "t").unwrap();
    assert_eq!(def.name, "mine");
    let f = def.function("TORQUE_LIMIT_POS").unwrap();
    assert_eq!(
        (f.ty, f.min, f.max, f.scale),
        (DataType::I16, 0, 3000, 10.0)
    );
    let w = def.function("MON_WINDOW").unwrap();
    assert_eq!((w.ty, w.max), (DataType::U32, u32::MAX as i64));
    assert!(def.function("TORQUE_LIMIT").is_none());
    assert!(
        g.notes.iter().any(|n| n.contains("read-only")),
        "{:?}",
        g.notes
    );
    assert!(def.idn("S-0-0159").is_some() && def.idn("S-0-0092").is_none());
}

#[test]
fn names_are_slugs() {
    assert_eq!(drive_name("Ingenia", "EVS-NET-01"), "ingenia-evs-net-01");
    assert_eq!(drive_name("Technosoft", "iPOS"), "technosoft-ipos");
    assert_eq!(
        drive_name("Technosoft SA", "Technosoft iPOS"),
        "technosoft-ipos"
    );
    assert_eq!(drive_name("", "\"\n"), "vendor-drive");
}

#[test]
fn the_pdos_of_an_eds_device_leave_out_what_has_no_room() {
    let mut objects = minimal();
    objects.extend([
        obj(0x60F4, DataType::I32, false, true),
        obj(0x6077, DataType::I16, false, true),
        obj(0x60B8, DataType::U16, true, false),
        obj(0x60B9, DataType::U16, false, true),
        obj(0x60BA, DataType::I32, false, true),
    ]);
    let dev = device(objects);
    // One RPDO of 8 entries: 0x6040 + 0x607A + 0x60B8 = 8 bytes, the touch probe stays
    // (0x6060 by SDO).
    let cap = PdoCapacity {
        rx: vec![8],
        tx: vec![8, 8],
    };
    let g = generate_in(&dev, None, Some(&cap)).unwrap();
    let def = catalogue::parse(&g.toml, "t").unwrap();
    assert!(g.touch_probe && def.rxpdo.contains(0x60B8, 0));
    assert!(
        g.toml
            .contains("1 RPDO (8 entries), 2 TPDOs (8, 8 entries)"),
        "{}",
        g.toml
    );
    // Inputs 2 + 4 + 4 + 1 + 2 + 4 + 2 = 19 bytes in two 8-byte TPDOs: 0x6077 goes (17),
    // then 0x60F4 (13: 0x6064 + 0x60BA, 0x6041 + 0x60B9 + 0x6061); the latch stays.
    assert!(!def.txpdo.contains(0x6077, 0) && !def.txpdo.contains(0x60F4, 0));
    assert!(def.txpdo.contains(0x60B9, 0) && def.txpdo.contains(0x60BA, 0));
    assert!(
        g.notes
            .iter()
            .any(|n| n.contains("0x6077:00") && n.contains("no room")),
        "{:?}",
        g.notes
    );
    // Two RPDOs of one entry: no room for 0x60B8, the touch probe goes with its inputs.
    let cap = PdoCapacity {
        rx: vec![1, 1],
        tx: vec![8; 4],
    };
    let g = generate_in(&dev, None, Some(&cap)).unwrap();
    let def = catalogue::parse(&g.toml, "t").unwrap();
    assert!(!g.touch_probe && !def.has_drive_latch());
    assert!(!def.txpdo.contains(0x60B9, 0) && !g.toml.contains("[probe]"));
    assert!(
        g.notes
            .iter()
            .any(|n| n.contains("no touch probe") && n.contains("no room")),
        "{:?}",
        g.notes
    );
    // One RPDO of one entry: controlword and target position find no room.
    let cap = PdoCapacity {
        rx: vec![1],
        tx: vec![8; 4],
    };
    let Err(VendorError::MissingObjects { missing, .. }) = generate_in(&dev, None, Some(&cap))
    else {
        panic!("refused");
    };
    assert!(
        missing[0].contains("0x6040:00, 0x607A:00: no room"),
        "{missing:?}"
    );
    // Without PDOs given: as generate.
    assert_eq!(generate_in(&dev, None, None), generate(&dev, None));
}
