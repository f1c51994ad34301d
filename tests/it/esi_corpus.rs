//! Every real vendor ESI file in `../shared/test-data/esi/` (issue 25): the folder is iterated,
//! so a file added later is tested the same way, with no per-file code. For each file and device:
//! it parses without error; its identity, the profiles it states, 0x1000 and its PDOs are what an
//! independent roxmltree reader finds (`common/esi_xml.rs`); every selector form picks it;
//! `esi list` lists it; its SII image builds and decodes back to its identity; each warning
//! points at a place in the file that holds what it says.
//!
//! Absent folder: `SKIP` (a plain clone), a failure with `FIELDPROBE_REQUIRE_TEST_DATA=1`.

use crate::common::cli;
use crate::common::esi_xml;
use crate::common::test_data;

use cli::{fieldprobe, stderr, stdout};
use esi_xml::{esi_file_facts, EsiDeviceFacts};
use fieldprobe::esi::{self, sii, to_sii, EsiFile, Oddity, SelectError, Selector};
use std::path::{Path, PathBuf};

/// The ESI files of the corpus, sorted; empty after printing `SKIP` when the folder is absent.
fn corpus(test: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/test-data/esi");
    if !dir.is_dir() {
        let why = format!("{} not present (a plain clone)", dir.display());
        if std::env::var(test_data::REQUIRE_ENV).is_ok_and(|v| v == "1") {
            panic!(
                "{test}: {why}; {}=1 requires the test data",
                test_data::REQUIRE_ENV
            );
        }
        eprintln!("SKIP {test}: {why}");
        return Vec::new();
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("read the corpus folder")
        .map(|e| e.expect("folder entry").path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml")))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{}: no ESI files", dir.display());
    files
}

/// Each file parsed, with its independent facts.
fn each(test: &str) -> Vec<(PathBuf, EsiFile, Vec<EsiDeviceFacts>)> {
    corpus(test)
        .into_iter()
        .map(|p| {
            let f = esi::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            let facts = esi_file_facts(&p);
            (p, f, facts)
        })
        .collect()
}

#[test]
fn every_file_parses_with_the_identities_it_states() {
    for (path, f, facts) in each("every_file_parses_with_the_identities_it_states") {
        let shown = path.display();
        assert_eq!(f.devices.len(), facts.len(), "{shown}");
        for (d, x) in f.devices.iter().zip(&facts) {
            assert_eq!(f.vendor.id, x.identity.vendor, "{shown}");
            assert_eq!(
                (
                    d.product_code,
                    d.revision_no,
                    d.type_name.as_str(),
                    d.name()
                ),
                (
                    x.identity.product,
                    x.identity.revision,
                    x.identity.type_name.as_str(),
                    x.identity.name.as_str()
                ),
                "{shown}"
            );
        }
        for w in &f.warnings {
            eprintln!("{w}");
        }
    }
}

#[test]
fn every_device_stating_402_reports_cia402() {
    for (path, f, facts) in each("every_device_stating_402_reports_cia402") {
        for (d, x) in f.devices.iter().zip(&facts) {
            let what = format!("{} {}", path.display(), x.identity.type_name);
            assert_eq!(d.is_cia402(), x.profile_numbers.contains(&402), "{what}");
            let mut mine = d.profile_numbers();
            mine.sort_unstable();
            let mut theirs = x.profile_numbers.clone();
            theirs.sort_unstable();
            theirs.dedup();
            assert_eq!(mine, theirs, "{what}");
            let channels: Vec<(u32, Option<u32>)> = d
                .profile
                .iter()
                .flat_map(|p| p.channels.iter().map(|c| (c.profile_no, c.add_info)))
                .collect();
            assert_eq!(channels, x.channels, "{what}");
            assert_eq!(
                d.is_mdp_servo(),
                x.channels.contains(&(5001, Some(513))),
                "{what}"
            );
            // 0x1000 as the file gives it (DefaultData zero-extended, else DefaultValue)
            assert_eq!(d.device_type(), x.device_type, "{what}");
        }
    }
}

/// The position (1-based) a configurator picks among the devices `matches` selects: the
/// highest revision, the first of equal ones.
fn best(facts: &[EsiDeviceFacts], matches: impl Fn(&EsiDeviceFacts) -> bool) -> usize {
    let mut best: Option<usize> = None;
    for (i, x) in facts.iter().enumerate() {
        if matches(x) && best.is_none_or(|b| x.identity.revision > facts[b].identity.revision) {
            best = Some(i);
        }
    }
    best.expect("the device itself matches") + 1
}

#[test]
fn every_selector_form_picks_each_device() {
    for (path, f, facts) in each("every_selector_form_picks_each_device") {
        let shown = path.display().to_string();
        let pick = |sel: &str| -> esi::Resolved {
            let s: Selector = sel.parse().unwrap_or_else(|e| panic!("{shown}#{sel}: {e}"));
            esi::resolve(&f, Some(&s)).unwrap_or_else(|e| panic!("{shown}#{sel}: {e}"))
        };
        for (i, x) in facts.iter().enumerate() {
            let id = &x.identity;
            let ty = id.type_name.to_lowercase();
            let mut forms: Vec<(String, usize)> = vec![
                (format!("@{}", i + 1), i + 1),
                (
                    format!("0x{:X}/#x{:X}", id.product, id.revision),
                    best(&facts, |o| {
                        (o.identity.product, o.identity.revision) == (id.product, id.revision)
                    }),
                ),
                (
                    format!("{}/{}", id.product, id.revision),
                    best(&facts, |o| {
                        (o.identity.product, o.identity.revision) == (id.product, id.revision)
                    }),
                ),
                (
                    format!("#x{:08x}", id.product),
                    best(&facts, |o| o.identity.product == id.product),
                ),
            ];
            // a type name that the selector syntax cannot carry is picked by the other forms
            let plain = !ty.contains(['+', '/', '#']) && !ty.starts_with('@');
            if plain && ty.parse::<u64>().is_err() {
                let same = |o: &EsiDeviceFacts| o.identity.type_name.eq_ignore_ascii_case(&ty);
                forms.push((ty.clone(), best(&facts, same)));
                forms.push((
                    format!("{ty}/0x{:08X}", id.revision),
                    best(&facts, |o| same(o) && o.identity.revision == id.revision),
                ));
            }
            for (sel, want) in forms {
                let r = pick(&sel);
                assert_eq!(r.position, want, "{shown}#{sel}");
                let w = &facts[want - 1];
                assert_eq!(
                    (r.product_code, r.revision_no, r.type_name.as_str()),
                    (
                        w.identity.product,
                        w.identity.revision,
                        w.identity.type_name.as_str()
                    ),
                    "{shown}#{sel}"
                );
                // resolved with its default modules
                assert_eq!(
                    r.rx_pdos.len() + r.tx_pdos.len(),
                    w.pdo_count,
                    "{shown}#{sel}"
                );
                // a choice among several says so
                let several = facts
                    .iter()
                    .filter(|o| o.identity.product == id.product)
                    .count();
                if sel.starts_with("#x") && several > 1 {
                    assert!(
                        r.notes.iter().any(|n| n.contains("highest revision")),
                        "{sel}"
                    );
                }
            }
        }
        // without a selector: the one device, or the list of them
        match esi::resolve(&f, None) {
            Ok(r) => assert_eq!((facts.len(), r.position), (1, 1), "{shown}"),
            Err(SelectError::Several { list, count, .. }) => {
                assert_eq!(count, facts.len(), "{shown}");
                for (i, x) in facts.iter().enumerate() {
                    let item = format!(
                        "@{} 0x{:08X} ({})",
                        i + 1,
                        x.identity.product,
                        x.identity.type_name
                    );
                    assert!(list.contains(&item), "{shown}: {item} not in {list}");
                }
            }
            Err(e) => panic!("{shown}: {e}"),
        }
        let beyond = format!("@{}", facts.len() + 1).parse::<Selector>().unwrap();
        let e = esi::resolve(&f, Some(&beyond)).unwrap_err();
        assert!(matches!(e, SelectError::NoMatch { .. }), "{shown}: {e}");
    }
}

#[test]
fn esi_list_lists_every_device_and_show_picks_by_position() {
    for path in corpus("esi_list_lists_every_device_and_show_picks_by_position") {
        let facts = esi_file_facts(&path);
        let file = path.to_str().unwrap();
        let o = fieldprobe(&["esi", "list", file]);
        assert_eq!(o.status.code(), Some(0), "{file}: {}", stderr(&o));
        let out = stdout(&o);
        let lines: Vec<&str> = out.lines().filter(|l| l.starts_with('@')).collect();
        assert_eq!(lines.len(), facts.len(), "{out}");
        for (i, (l, x)) in lines.iter().zip(&facts).enumerate() {
            let id = &x.identity;
            let head = format!(
                "@{} {} 0x{:08X}/0x{:08X} profiles ",
                i + 1,
                id.type_name,
                id.product,
                id.revision
            );
            assert!(l.starts_with(&head), "{l:?} does not start with {head:?}");
            assert!(l.ends_with(&format!("{:?}", id.name)), "{l}");
            assert_eq!(
                l.contains("profiles 402") || l.contains(",402"),
                x.profile_numbers.contains(&402),
                "{l}"
            );
        }
        // the warnings once, on stderr
        let warnings = stderr(&o)
            .lines()
            .filter(|l| l.starts_with("warning: "))
            .count();
        assert_eq!(warnings, esi::load(&path).unwrap().warnings.len(), "{file}");
        // the last device by position, through the CLI
        let n = facts.len();
        let id = &facts[n - 1].identity;
        let o = fieldprobe(&["esi", "show", &format!("{file}#@{n}")]);
        assert_eq!(o.status.code(), Some(0), "{file}: {}", stderr(&o));
        let want = format!(
            "  identity: vendor 0x{:08X}, product code 0x{:08X}, revision 0x{:08X}",
            id.vendor, id.product, id.revision
        );
        assert!(stdout(&o).contains(&want), "{}", stdout(&o));
        assert_eq!(stdout(&o).matches("\ndevice ").count(), 1);
    }
}

#[test]
fn every_device_has_an_sii_image_that_decodes_to_its_identity() {
    for (path, f, facts) in each("every_device_has_an_sii_image_that_decodes_to_its_identity") {
        for (i, x) in facts.iter().enumerate() {
            let what = format!("{} @{}", path.display(), i + 1);
            let sel: Selector = format!("@{}", i + 1).parse().unwrap();
            let d = esi::resolve(&f, Some(&sel)).unwrap();
            let built =
                to_sii::sii_from_device_noted(&f, &d).unwrap_or_else(|e| panic!("{what}: {e}"));
            let image =
                sii::encode_padded(&built.content).unwrap_or_else(|e| panic!("{what}: {e}"));
            let back = sii::decode(&image).unwrap_or_else(|e| panic!("{what}: {e}"));
            let h = &back.header;
            assert_eq!(
                (h.vendor_id, h.product_code, h.revision),
                (x.identity.vendor, x.identity.product, x.identity.revision),
                "{what}"
            );
            let g = back.general().expect("General category");
            let latin1 = |s: &str| -> String {
                s.chars()
                    .map(|c| if u32::from(c) <= 0xFF { c } else { '?' })
                    .take(255)
                    .collect()
            };
            assert_eq!(
                back.string(g.order_idx),
                Some(latin1(&x.identity.type_name).as_str()).filter(|s| !s.is_empty()),
                "{what}"
            );
            assert_eq!(
                back.string(g.name_idx),
                Some(latin1(&x.identity.name).as_str()).filter(|s| !s.is_empty()),
                "{what}"
            );
            assert_eq!(
                g.ds402_channels,
                u8::from(x.profile_numbers.contains(&402)),
                "{what}"
            );
            assert_eq!(
                back.tx_pdos().count() + back.rx_pdos().count(),
                x.pdo_count,
                "{what}"
            );
            // the EEPROM: the ESI's size when the image fits, else the next real size, noted
            let used = sii::encode(&built.content).unwrap().len();
            let declared = h.eeprom_size_bytes();
            assert_eq!(image.len(), declared, "{what}");
            assert!(
                declared.is_power_of_two() && declared >= 128,
                "{what}: {declared}"
            );
            let esi_size = x.eeprom_bytes.unwrap_or(2048) as usize;
            if used <= esi_size {
                assert_eq!(declared, esi_size, "{what}");
                assert!(built.notes.is_empty(), "{what}: {:?}", built.notes);
            } else {
                assert_eq!(declared, used.next_power_of_two(), "{what}");
                assert!(
                    built.notes[0].contains(&format!("needs {used} bytes")),
                    "{what}"
                );
            }
        }
    }
}

/// `<DefaultData>` texts of odd length in `text`, by a plain scan of the file's text.
fn odd_default_data(text: &str) -> usize {
    text.split("<DefaultData>")
        .skip(1)
        .filter_map(|rest| rest.split_once("</DefaultData>").map(|(v, _)| v.trim()))
        .filter(|v| v.len() % 2 == 1)
        .count()
}

/// The text at 1-based `line` and character `column` of `text`.
fn at(text: &str, line: u32, column: u32) -> String {
    let l = text
        .lines()
        .nth(line as usize - 1)
        .expect("the line exists");
    l.chars().skip(column as usize - 1).take(80).collect()
}

#[test]
fn warnings_point_at_what_they_say() {
    for (path, f, _) in each("warnings_point_at_what_they_say") {
        let raw = std::fs::read_to_string(&path).unwrap();
        let text = raw.strip_prefix('\u{feff}').unwrap_or(&raw);
        for w in &f.warnings {
            let here = at(text, w.line, w.column);
            match w.path.rsplit_once("/@") {
                Some((_, attr)) => assert!(here.starts_with(attr), "{w}\n  at: {here}"),
                None => {
                    let tag = w.path.rsplit('/').next().unwrap();
                    let tag = tag.split('[').next().unwrap();
                    assert!(here.starts_with(&format!("<{tag}")), "{w}\n  at: {here}");
                }
            }
        }
        // odd-length hexBinary: one warning, first place + count = every such value
        let odd = odd_default_data(text);
        let w = f.warnings.iter().find(|w| {
            matches!(w.oddity, Oddity::OddHexBinary { .. }) && w.path.ends_with("/DefaultData")
        });
        if odd == 0 {
            assert!(w.is_none(), "{}: {w:?}", path.display());
            continue;
        }
        let w = w.unwrap_or_else(|| panic!("{}: no odd-length warning", path.display()));
        assert_eq!(1 + w.more_count, odd, "{w}");
        let places =
            std::iter::once((w.line, w.column)).chain(w.more.iter().map(|p| (p.line, p.column)));
        for (line, column) in places {
            let here = at(text, line, column);
            let value = here
                .strip_prefix("<DefaultData>")
                .and_then(|v| v.split_once("</DefaultData>"))
                .map(|(v, _)| v.trim().to_string())
                .unwrap_or_else(|| panic!("{line}:{column} is not a DefaultData: {here}"));
            assert!(value.len() % 2 == 1, "{line}:{column}: {value}");
        }
        let shown = w.to_string();
        assert!(
            shown.starts_with(&format!("{}:{}:{}: ", f.file, w.line, w.column)),
            "{shown}"
        );
        assert!(
            shown.contains(&format!("{} more like it", w.more_count)),
            "{shown}"
        );
    }
}

#[test]
fn lc10e_odd_hex_is_read_with_a_leading_zero_nibble() {
    // README of the test data: 225 odd-length DefaultData values (`0`)
    let Some(path) = test_data::test_data(
        "esi/LCElectric-LC10E-V1.04.xml",
        "lc10e_odd_hex_is_read_with_a_leading_zero_nibble",
    ) else {
        return;
    };
    let f = esi::load(&path).unwrap();
    let w = f
        .warnings
        .iter()
        .find(|w| matches!(w.oddity, Oddity::OddHexBinary { .. }))
        .expect("the odd-hex warning");
    assert_eq!(1 + w.more_count, 225, "{w}");
    let text = std::fs::read_to_string(&path).unwrap();
    let here = at(&text, w.line, w.column);
    assert!(here.starts_with("<DefaultData>0</DefaultData>"), "{here}");
    assert_eq!(
        w.oddity,
        Oddity::OddHexBinary {
            text: "0".into(),
            read: vec![0]
        }
    );
    // each value named reads as the digits with a leading 0 nibble (`1` → 01, `100` → 01 00)
    let d = &f.devices[0];
    let places = std::iter::once((w.subject.clone(), Some("0".to_string())))
        .chain(w.more.iter().map(|p| (p.subject.clone(), p.text.clone())));
    let mut checked = 0;
    for (subject, value) in places {
        let (object, sub) = subject
            .as_deref()
            .and_then(|s| s.split_once("object #x"))
            .and_then(|(_, s)| s.split_once(" SubItem["))
            .expect("object and sub-item named");
        let index = u16::from_str_radix(object, 16).unwrap();
        let k: usize = sub.trim_end_matches(']').parse().unwrap();
        let padded = format!("0{}", value.unwrap());
        let want: Vec<u8> = (0..padded.len() / 2)
            .map(|i| u8::from_str_radix(&padded[2 * i..2 * i + 2], 16).unwrap())
            .collect();
        let o = d.object(index).expect("the object");
        assert_eq!(
            o.subitems[k - 1].default_data.as_deref(),
            Some(&want[..]),
            "{padded}"
        );
        checked += 1;
    }
    assert_eq!(checked, 1 + w.more.len());
}

#[test]
fn drive_from_esi_notes_what_does_not_say_402() {
    for path in corpus("drive_from_esi_notes_what_does_not_say_402") {
        let file = path.to_str().unwrap();
        for (i, x) in esi_file_facts(&path).iter().enumerate() {
            let states_402 = x.profile_numbers.contains(&402);
            let odd_type = x.device_type.filter(|t| t & 0xFFFF != 402);
            if states_402 && odd_type.is_none() {
                continue;
            }
            let o = fieldprobe(&["drive", "from-esi", &format!("{file}#@{}", i + 1)]);
            let err = stderr(&o);
            if err.contains("has no CoE object dictionary") {
                continue;
            }
            assert_eq!(
                err.contains("states no CiA 402 profile"),
                !states_402,
                "{file} @{}: {err}",
                i + 1
            );
            if let Some(t) = odd_type {
                assert!(
                    err.contains(&format!("0x1000 default 0x{t:08X} (as the file gives it)")),
                    "{file} @{}: {err}",
                    i + 1
                );
            }
        }
    }
}
