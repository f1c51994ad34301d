//! Device selectors, modules and slots, and the lenient readings of ESI values (issue 25):
//! selector syntax (good and bad), module expansion (the Eyou file and a two-slot device
//! written here), odd-length hexBinary, `DefaultValue`, booleans and numbers in odd forms, the
//! grouping of warnings. Expected values are written out by hand from the XML.

use crate::common::test_data;

use fieldprobe::esi::{
    self, DeviceSelector, EsiError, ModuleChoice, ModuleError, Oddity, Problem, SelectError,
    Selector,
};

// ---------------------------------------------------------------------------------------------
// Selector syntax
// ---------------------------------------------------------------------------------------------

fn sel(s: &str) -> Selector {
    s.parse().unwrap_or_else(|e| panic!("{s}: {e}"))
}

#[test]
fn selector_forms() {
    let s = sel("EJ7211-0011");
    assert_eq!(
        s.device,
        DeviceSelector::Type {
            name: "EJ7211-0011".into(),
            revision: None
        }
    );
    assert!(s.modules.is_empty());
    assert_eq!(
        sel("EJ7211-0011/0x001B000B").device,
        DeviceSelector::Type {
            name: "EJ7211-0011".into(),
            revision: Some(0x001B_000B)
        }
    );
    assert_eq!(
        sel("0x1C2B2852/0x001B000B").device,
        DeviceSelector::Product {
            code: 0x1C2B_2852,
            revision: Some(0x001B_000B)
        }
    );
    assert_eq!(
        sel("#x1c2b2852").device,
        DeviceSelector::Product {
            code: 0x1C2B_2852,
            revision: None
        }
    );
    assert_eq!(
        sel("472590418/1769483").device,
        DeviceSelector::Product {
            code: 472_590_418,
            revision: Some(1_769_483)
        }
    );
    assert_eq!(sel("@3").device, DeviceSelector::Position(3));
    // modules: ident, type text, empty = the slot's default
    let s = sel("@1+#x219800+Axis (pp,pv,pt)++0x10");
    assert_eq!(s.device, DeviceSelector::Position(1));
    assert_eq!(
        s.modules,
        vec![
            ModuleChoice::Ident(0x21_9800),
            ModuleChoice::Name("Axis (pp,pv,pt)".into()),
            ModuleChoice::Default,
            ModuleChoice::Ident(0x10),
        ]
    );
    assert_eq!(s.to_string(), "@1+#x219800+Axis (pp,pv,pt)++#x10");
    // a '/' followed by no number is part of the type name
    assert_eq!(
        sel("A/B").device,
        DeviceSelector::Type {
            name: "A/B".into(),
            revision: None
        }
    );
}

#[test]
fn selectors_built_in_code() {
    let s = Selector::new(
        DeviceSelector::Product {
            code: 0x1C2B_2852,
            revision: Some(0x001B_000B),
        },
        vec![ModuleChoice::Default],
    );
    assert_eq!(s.to_string(), "0x1C2B2852/0x001B000B+");
    assert_eq!(sel(&s.to_string()), s);
    // position 0 does not exist: no match, no panic
    let f = esi::parse(
        "<EtherCATInfo><Vendor><Id>1</Id></Vendor><Descriptions><Devices><Device>\
         <Type ProductCode=\"1\">A</Type></Device></Devices></Descriptions></EtherCATInfo>",
        "p.xml",
    )
    .unwrap();
    let s = Selector::new(DeviceSelector::Position(0), Vec::new());
    let e = esi::resolve(&f, Some(&s)).unwrap_err();
    assert!(matches!(e, SelectError::NoMatch { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("@1 0x00000001 (A) revision 0x00000000"),
        "{e}"
    );
}

#[test]
fn bad_selectors_name_the_problem() {
    for (text, why) in [
        ("", "no device"),
        ("+#x1", "no device"),
        ("@0", "@N needs a position"),
        ("@x", "@N needs a position"),
        ("@", "@N needs a position"),
        ("/0x10", "no type name or product code"),
    ] {
        let e = text.parse::<Selector>().unwrap_err();
        assert!(matches!(e, SelectError::Syntax { .. }), "{text}: {e:?}");
        assert!(e.to_string().contains(why), "{text}: {e}");
    }
}

#[test]
fn file_and_selector_split_after_xml() {
    assert_eq!(esi::split_spec("a.xml"), ("a.xml", None));
    assert_eq!(esi::split_spec("a.xml#EJ7211"), ("a.xml", Some("EJ7211")));
    assert_eq!(
        esi::split_spec("dir#1/a.XML##x1C2B2852/#x1B000B"),
        ("dir#1/a.XML", Some("#x1C2B2852/#x1B000B"))
    );
    assert_eq!(esi::split_spec("a.esi#@2"), ("a.esi", Some("@2")));
}

// ---------------------------------------------------------------------------------------------
// A two-slot modular device written here
// ---------------------------------------------------------------------------------------------

/// Two slots of one instance each (`Left`: default #x10, `Right`: no default), increments
/// #x800 / 16. Module #x10 maps 0x6040 (DependOnSlot) and a gap; #x20 maps 0x6041 without
/// DependOnSlot and has a dictionary object 0x6502 (DependOnSlot) and a profile 402.
const MODULAR: &str = r##"<?xml version="1.0"?>
<EtherCATInfo>
  <Vendor><Id>#x99</Id></Vendor>
  <Descriptions>
    <Devices>
      <Device>
        <Type ProductCode="#x1" RevisionNo="2">MOD</Type>
        <Profile><ProfileNo>5001</ProfileNo>
          <Dictionary><Objects>
            <Object><Index>#x1000</Index><Name>Device type</Name><Type>UDINT</Type><BitSize>32</BitSize>
              <Info><DefaultValue>#x00020192</DefaultValue><MinValue>0</MinValue><MaxValue>-1</MaxValue></Info></Object>
            <Object><Index>#x6040</Index><Name>Controlword</Name><Type>UINT</Type><BitSize>16</BitSize></Object>
          </Objects></Dictionary>
        </Profile>
        <Slots SlotIndexIncrement="#x800" SlotPdoIncrement="16">
          <Slot><Name>Left</Name><ModuleIdent Default="1">#x10</ModuleIdent><ModuleIdent>#x20</ModuleIdent></Slot>
          <Slot MinInstances="1" MaxInstances="1"><Name>Right</Name><ModuleIdent>#x10</ModuleIdent><ModuleIdent>#x20</ModuleIdent></Slot>
        </Slots>
      </Device>
    </Devices>
    <Modules>
      <Module>
        <Type ModuleIdent="#x10">Out</Type>
        <RxPdo Sm="2"><Index DependOnSlot="true">#x1600</Index><Name>Out</Name>
          <Entry><Index DependOnSlot="true">#x6040</Index><SubIndex>0</SubIndex><BitLen>16</BitLen></Entry>
          <Entry><Index>#x0</Index><BitLen>8</BitLen></Entry>
        </RxPdo>
      </Module>
      <Module>
        <Type ModuleIdent="#x20">In</Type>
        <TxPdo Sm="3"><Index DependOnSlot="1">#x1A00</Index><Name>In</Name>
          <Entry><Index>#x6041</Index><SubIndex>0</SubIndex><BitLen>16</BitLen></Entry>
        </TxPdo>
        <Profile><ProfileNo>402</ProfileNo>
          <Dictionary><Objects>
            <Object><Index DependOnSlot="true">#x6502</Index><Name>Supported drive modes</Name><Type>UDINT</Type><BitSize>32</BitSize></Object>
          </Objects></Dictionary>
        </Profile>
      </Module>
    </Modules>
  </Descriptions>
</EtherCATInfo>
"##;

fn modular() -> esi::EsiFile {
    esi::parse(MODULAR, "mod.xml").unwrap()
}

#[test]
fn a_slot_without_default_needs_a_choice() {
    let f = modular();
    let d = &f.devices[0];
    // as written: no module PDOs; only the Left default counts for the profiles
    assert!(d.rx_pdos.is_empty() && d.tx_pdos.is_empty());
    assert_eq!(d.profile_numbers(), vec![5001]);
    assert!(!d.is_cia402());
    let e = d.resolve(&[]).unwrap_err();
    assert_eq!(
        e,
        ModuleError::NoDefault {
            slot: 1,
            name: "Right".into(),
            choices: "#x10 Out, #x20 In".into()
        }
    );
    let e = esi::resolve(&f, None).unwrap_err();
    assert!(matches!(e, SelectError::Module { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("slot 1 (Right) has no default module"),
        "{e}"
    );
}

#[test]
fn module_pdos_and_objects_move_by_slot() {
    let f = modular();
    // slot 0 (Left) default #x10, slot 1 (Right) #x20 by name
    let r = esi::resolve(&f, Some(&sel("MOD++in"))).unwrap();
    let d = &r.device;
    assert_eq!(r.position, 1);
    // #x10 in slot 0: 0x1600 with 0x6040 and the gap, nothing moved
    assert_eq!(d.rx_pdos.len(), 1);
    assert_eq!(d.rx_pdos[0].index, 0x1600);
    let e: Vec<(u16, u8, u16)> = d.rx_pdos[0]
        .entries
        .iter()
        .map(|e| (e.index, e.subindex, e.bit_len))
        .collect();
    assert_eq!(e, [(0x6040, 0, 16), (0, 0, 8)]);
    // #x20 in slot 1: TxPDO 0x1A00 + 1·16 = 0x1A10, its entry without DependOnSlot stays
    assert_eq!(d.tx_pdos.len(), 1);
    assert_eq!(d.tx_pdos[0].index, 0x1A10);
    assert_eq!(d.tx_pdos[0].entries[0].index, 0x6041);
    // its object 0x6502 + 1·#x800 = 0x6D02 joins the dictionary; the device's objects stay
    assert!(d.object(0x6D02).is_some());
    assert!(d.object(0x6502).is_none());
    assert!(d.object(0x6040).is_some());
    // the plugged module's profile counts: 402 now
    assert!(d.is_cia402());
    assert_eq!(d.profile_numbers(), vec![5001, 402]);
    let plugged = d.plugged.as_ref().unwrap();
    assert_eq!(
        plugged
            .iter()
            .map(|p| (p.slot, p.ident, p.type_name.as_str()))
            .collect::<Vec<_>>(),
        [(0, 0x10, "Out"), (1, 0x20, "In")]
    );
    // the same module in both slots: slot 1 moves 0x1600 → 0x1610 and 0x6040 → 0x6840
    let r = esi::resolve(&f, Some(&sel("@1+#x10+#x10"))).unwrap();
    let idx: Vec<(u16, u16)> = r
        .rx_pdos
        .iter()
        .map(|p| (p.index, p.entries[0].index))
        .collect();
    assert_eq!(idx, [(0x1600, 0x6040), (0x1610, 0x6840)]);
    assert!(!r.is_cia402());
    // a module a slot does not take, too many modules
    let e = esi::resolve(&f, Some(&sel("@1+#x30+#x10"))).unwrap_err();
    assert!(
        e.to_string()
            .contains("slot 0 (Left) does not take module #x30"),
        "{e}"
    );
    let e = esi::resolve(&f, Some(&sel("@1+#x10+#x10+#x10"))).unwrap_err();
    assert!(e.to_string().contains("at most 2 module(s)"), "{e}");
    // DefaultValue / MinValue / MaxValue are numbers; 0x1000 from DefaultValue
    let o = f.devices[0].object(0x1000).unwrap();
    assert_eq!(o.default_data, None);
    assert_eq!(
        (o.values.default, o.values.min, o.values.max),
        (Some(0x0002_0192), Some(0), Some(-1))
    );
    assert_eq!(f.devices[0].device_type(), Some(0x0002_0192));
    assert!(f.warnings.is_empty(), "{:?}", f.warnings);
}

// ---------------------------------------------------------------------------------------------
// The Eyou ServoModule (one slot, three modules, no PDO at device level)
// ---------------------------------------------------------------------------------------------

#[test]
fn eyou_default_module_and_a_second_choice() {
    let Some(path) = test_data::test_data(
        "esi/Eyou-ServoModule-ECAT-V145.xml",
        "eyou_default_module_and_a_second_choice",
    ) else {
        return;
    };
    let f = esi::load(path).unwrap();
    let d = &f.devices[0];
    assert!(d.rx_pdos.is_empty() && d.tx_pdos.is_empty());
    // <Slot MinInstances="1" MaxInstances="1"> Axis 0, <ModuleIdent Default="1">#x119800
    let slots = d.slots.as_ref().unwrap();
    assert_eq!(
        (slots.slot_index_increment, slots.slot_pdo_increment),
        (0x800, 16)
    );
    assert_eq!(d.modules.len(), 3);
    assert_eq!(d.default_modules()[0].ident, 0x11_9800);
    let r = esi::resolve(&f, None).unwrap();
    // module "Axis (csv,csp,cst)": RxPdo #x1600 = 6040 16, 607A 32, 60FF 32, 6071 16, 6060 8,
    // gap 8; TxPdo #x1A00 = 6041 16, 6064 32, 606C 32, 6077 16, 6061 8, 603F 16, gap 8
    let rx: Vec<(u16, u16)> = r.rx_pdos[0]
        .entries
        .iter()
        .map(|e| (e.index, e.bit_len))
        .collect();
    assert_eq!(r.rx_pdos[0].index, 0x1600);
    assert_eq!(
        rx,
        [
            (0x6040, 16),
            (0x607A, 32),
            (0x60FF, 32),
            (0x6071, 16),
            (0x6060, 8),
            (0, 8)
        ]
    );
    assert_eq!(r.rx_pdos[0].sm, Some(2));
    assert_eq!(r.tx_pdos[0].index, 0x1A00);
    assert_eq!(r.tx_pdos[0].entries[0].index, 0x6041);
    assert_eq!(r.tx_pdos[0].entries.last().unwrap().index, 0);
    assert!(r.is_cia402());
    assert!(r
        .notes
        .iter()
        .any(|n| n.contains("default module(s) slot 0 (Axis 0): #x119800")));
    // the second module, by ident and by name
    for s in ["@1+#x219800", "eyou_servomodule_v145+Axis (pp,pv,pt)"] {
        let r = esi::resolve(&f, Some(&sel(s))).unwrap();
        assert_eq!(r.rx_pdos.len(), 1, "{s}");
        assert_eq!(r.rx_pdos[0].index, 0x1601, "{s}");
        assert!(r.rx_pdos[0].fixed, "{s}");
        assert_eq!(r.tx_pdos[0].index, 0x1A01, "{s}");
        assert_eq!(r.plugged.as_ref().unwrap()[0].ident, 0x21_9800);
    }
}

// ---------------------------------------------------------------------------------------------
// Lenient readings
// ---------------------------------------------------------------------------------------------

const HEAD: &str = "<?xml version=\"1.0\"?>\n<EtherCATInfo>\n  <Vendor><Id>#x10</Id></Vendor>\n  <Descriptions>\n    <Devices>\n";
const TAIL: &str = "    </Devices>\n  </Descriptions>\n</EtherCATInfo>\n";

fn object(index: &str, info: &str, flags: &str) -> String {
    format!(
        "            <Object><Index>{index}</Index><Name>o</Name><Type>UDINT</Type><BitSize>32</BitSize>{info}{flags}</Object>\n"
    )
}

fn device(inner: &str, objects: &str) -> String {
    format!(
        "{HEAD}      <Device>\n        <Type ProductCode=\"7\">X</Type>\n{inner}        <Profile><Dictionary><Objects>\n{objects}        </Objects></Dictionary></Profile>\n      </Device>\n{TAIL}"
    )
}

#[test]
fn odd_length_hex_binary_reads_with_a_leading_zero_nibble() {
    let objs = [
        object(
            "#x1000",
            "<Info><DefaultData>262546</DefaultData></Info>",
            "",
        ),
        object("#x2000", "<Info><DefaultData>0</DefaultData></Info>", ""),
        object("#x2001", "<Info><DefaultData>123</DefaultData></Info>", ""),
        object("#x2002", "<Info><DefaultData>7</DefaultData></Info>", ""),
        object("#x2003", "<Info><DefaultData>xyz</DefaultData></Info>", ""),
    ]
    .concat();
    let f = esi::parse(&device("", &objs), "h.xml").unwrap();
    let d = &f.devices[0];
    let data = |i| d.object(i).unwrap().default_data.clone();
    assert_eq!(data(0x2000), Some(vec![0x00]));
    assert_eq!(data(0x2001), Some(vec![0x01, 0x23]));
    assert_eq!(data(0x2002), Some(vec![0x07]));
    assert_eq!(data(0x2003), None);
    // 3 bytes of 0x1000, zero-extended
    assert_eq!(d.device_type(), Some(0x0046_2526));
    // one warning for the three odd values (first: line 10), one for the non-hex
    assert_eq!(f.warnings.len(), 2, "{:?}", f.warnings);
    let w = &f.warnings[0];
    assert_eq!((w.line, w.more_count, w.more.len()), (10, 2, 2));
    assert_eq!((w.more[0].line, w.more[1].line), (11, 12));
    assert_eq!(w.more[1].text.as_deref(), Some("7"));
    assert_eq!(w.subject.as_deref(), Some("device X, object #x2000"));
    assert!(w.path.ends_with("Object[2]/Info/DefaultData"), "{}", w.path);
    let shown = w.to_string();
    assert!(shown.starts_with("h.xml:10:"), "{shown}");
    assert!(shown.contains("odd-length hexBinary \"0\": read with a leading 0 nibble as bytes 00; 2 more like it at 11:"), "{shown}");
    assert_eq!(
        f.warnings[1].oddity,
        Oddity::NotHexBinary { text: "xyz".into() }
    );
}

#[test]
fn odd_forms_are_read_with_warnings_and_what_has_no_reading_stays_an_error() {
    let inner = "        <Sm StartAddress=\"0x1000\" ControlByte=\"#x26\" Enable=\"TRUE\" MinSize=\"-1\">MBoxOut</Sm>\n        <RxPdo Fixed=\"TRUE\" Sm=\"2\"><Index>#x1600</Index><Entry><Index>#x6040</Index><BitLen>+16</BitLen></Entry></RxPdo>\n";
    let objs = [
        object(
            "#x6040",
            "<Info><DefaultValue>0x10</DefaultValue></Info>",
            "<Flags><Access>RW</Access><PdoMapping>rt</PdoMapping></Flags>",
        ),
        object(
            "#x6041",
            "",
            "<Flags><Access>readwrite</Access><PdoMapping>X</PdoMapping></Flags>",
        ),
        object(
            "#x6042",
            "<Info><DefaultValue>ten</DefaultValue></Info>",
            "",
        ),
    ]
    .concat();
    let f = esi::parse(&device(inner, &objs), "o.xml").unwrap();
    let d = &f.devices[0];
    assert_eq!(d.sync_managers[0].start_address, 0x1000);
    assert!(d.sync_managers[0].enable);
    // -1 in a 16-bit field: its two's complement
    assert_eq!(d.sync_managers[0].min_size, Some(0xFFFF));
    assert!(d.rx_pdos[0].fixed);
    assert_eq!(d.rx_pdos[0].entries[0].bit_len, 16);
    let o = |i| d.object(i).unwrap();
    assert_eq!(o(0x6040).values.default, Some(16));
    assert_eq!(o(0x6040).flags.access, Some(esi::Access::ReadWrite));
    assert_eq!(o(0x6040).flags.pdo_mapping, Some(esi::PdoMapping::RxTx));
    assert_eq!(o(0x6041).flags.access, None);
    assert_eq!(o(0x6041).flags.pdo_mapping, None);
    assert_eq!(o(0x6042).values.default, None);
    let kinds: Vec<String> = f.warnings.iter().map(|w| w.to_string()).collect();
    for want in [
        "Sm/@StartAddress: device X: number \"0x1000\" is not #x hex or decimal: read as 4096",
        "Sm/@Enable: device X: boolean \"TRUE\" is not true/false/1/0: read as true",
        "Sm/@MinSize: device X: negative \"-1\" in an unsigned field: read as its two's \
         complement 0xFFFF",
        "RxPdo/@Fixed: device X, RxPdo #x1600: boolean \"TRUE\"",
        "BitLen: device X, RxPdo #x1600: number \"+16\" is not #x hex or decimal: read as 16",
        "Info/DefaultValue: device X, object #x6040: number \"0x10\"",
        "Flags/Access: device X, object #x6041: Access \"readwrite\" is not ro/rw/wo",
        "Flags/PdoMapping: device X, object #x6041: PdoMapping \"X\" is not R/T/RT/TR",
        "Info/DefaultValue: device X, object #x6042: \"ten\" is not a number: left out",
    ] {
        assert!(
            kinds.iter().any(|k| k.contains(want)),
            "{want:?} not in {kinds:#?}"
        );
    }
    assert_eq!(f.warnings.len(), 9, "{kinds:#?}");

    // no reading: an error with line and path, as before
    for (bad, problem) in [
        (
            "<Type ProductCode=\"7\">X</Type>",
            "<Type ProductCode=\"seven\">X</Type>",
        ),
        ("Fixed=\"TRUE\"", "Fixed=\"maybe\""),
        ("<Index>#x1600</Index>", "<Index>#x16000</Index>"),
    ] {
        let text = device(inner, &objs).replace(bad, problem);
        let e = esi::parse(&text, "e.xml").unwrap_err();
        assert!(matches!(e, EsiError::Invalid { .. }), "{problem}: {e:?}");
    }
    let text = device(inner, &objs).replace("<BitLen>+16</BitLen>", "<BitLen>70000</BitLen>");
    match esi::parse(&text, "e.xml").unwrap_err() {
        EsiError::Invalid { problem, line, .. } => {
            assert_eq!(problem, Problem::OutOfRange("70000".into()));
            assert_eq!(line, 9);
        }
        e => panic!("{e:?}"),
    }
}

#[test]
fn channel_info_profiles_and_mdp() {
    let inner = "        <Profile><ChannelInfo><ProfileNo>5001</ProfileNo><AddInfo>513</AddInfo><DisplayName>Servo interface</DisplayName></ChannelInfo><ChannelInfo><ProfileNo>402</ProfileNo></ChannelInfo></Profile>\n";
    let text = format!(
        "{HEAD}      <Device>\n        <Type ProductCode=\"7\">X</Type>\n{inner}      </Device>\n{TAIL}"
    );
    let f = esi::parse(&text, "c.xml").unwrap();
    let d = &f.devices[0];
    assert_eq!(d.profile_numbers(), vec![5001, 402]);
    assert_eq!(d.profile_infos(), vec![(5001, Some(513)), (402, None)]);
    assert!(d.is_cia402() && d.is_mdp_servo());
    let c = &d.channels()[0];
    assert_eq!(c.display_name.as_deref(), Some("Servo interface"));
    assert_eq!(d.device_type(), None);
    // without the 402 channel: an MDP servo that does not state 402
    let f = esi::parse(
        &text.replace("<ChannelInfo><ProfileNo>402</ProfileNo></ChannelInfo>", ""),
        "c.xml",
    )
    .unwrap();
    assert!(!f.devices[0].is_cia402() && f.devices[0].is_mdp_servo());
}

#[test]
fn many_alike_warnings_are_one_and_bounded() {
    let objs: String = (0..5000)
        .map(|i| {
            object(
                &format!("#x{:04X}", 0x2000 + i),
                "<Info><DefaultData>1</DefaultData></Info>",
                "<Flags><Access>x</Access></Flags>",
            )
        })
        .collect();
    let f = esi::parse(&device("", &objs), "m.xml").unwrap();
    assert_eq!(f.warnings.len(), 2);
    for w in &f.warnings {
        assert_eq!(w.more_count, 4999);
        assert_eq!(w.more.len(), fieldprobe::limits::MAX_ESI_WARNING_PLACES);
        assert!(w.to_string().ends_with(" and 4991 more"), "{w}");
    }
}
