//! The CoE object dictionary of an ESI file (`Profile/Dictionary`), read with roxmltree
//! independently of `fieldprobe::esi`, in the terms of SDO Information (ETG.1000.6) and of IgH's
//! `ethercat sdos` lines. Rules (ETG.2000): a base type (`UINT`, `DINT`, `STRING(n)` …) makes a
//! VAR with one entry (sub 0, the object's name); a data type with `SubItem`s a RECORD with
//! one entry per `SubIdx`. Access: `ro` = read in PREOP/SAFEOP/OP (0x07), `rw` = read + write
//! in every state (0x3F) or only in PREOP with `WriteRestrictions="PreOP"` (0x0F); PdoMapping
//! `R` adds 0x40, `T` 0x80.

#![allow(dead_code)] // each test crate uses its own subset

use std::path::Path;

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    pub sub: u8,
    pub name: String,
    /// CiA 301 data type index.
    pub data_type: u16,
    pub bits: u32,
    /// ETG.1000.6 object access bits.
    pub access: u16,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Object {
    pub index: u16,
    pub name: String,
    /// 7 VAR, 9 RECORD.
    pub object_code: u8,
    pub entries: Vec<Entry>,
}

fn number(s: &str) -> u32 {
    let t = s.trim();
    match t.strip_prefix("#x") {
        Some(h) => u32::from_str_radix(h, 16).unwrap(),
        None => t.parse().unwrap(),
    }
}

/// CiA 301 index of an ETG.2000 base type name.
pub fn base_type(name: &str) -> Option<u16> {
    Some(match name {
        "BOOL" => 1,
        "SINT" => 2,
        "INT" => 3,
        "DINT" => 4,
        "USINT" => 5,
        "UINT" => 6,
        "UDINT" => 7,
        "REAL" => 8,
        "LREAL" => 0x11,
        "LINT" => 0x15,
        "ULINT" => 0x1B,
        n if n.starts_with("STRING(") => 9,
        _ => return None,
    })
}

/// IgH `ethercat sdos` name of a data type index.
pub fn igh_type(dt: u16) -> &'static str {
    match dt {
        1 => "bool",
        2 => "int8",
        3 => "int16",
        4 => "int32",
        5 => "uint8",
        6 => "uint16",
        7 => "uint32",
        8 => "float",
        9 => "string",
        0x11 => "double",
        0x15 => "int64",
        0x1B => "uint64",
        _ => panic!("type {dt:#x} not expected in the ESI"),
    }
}

/// IgH's six access letters.
pub fn letters(a: u16) -> String {
    [
        (1, 'r'),
        (8, 'w'),
        (2, 'r'),
        (0x10, 'w'),
        (4, 'r'),
        (0x20, 'w'),
    ]
    .iter()
    .map(|&(b, c)| if a & b != 0 { c } else { '-' })
    .collect()
}

fn child<'a>(n: roxmltree::Node<'a, 'a>, tag: &str) -> Option<roxmltree::Node<'a, 'a>> {
    n.children().find(|c| c.has_tag_name(tag))
}

fn text<'a>(n: roxmltree::Node<'a, 'a>, tag: &str) -> String {
    child(n, tag)
        .and_then(|c| c.text())
        .unwrap_or_default()
        .trim()
        .to_string()
}

fn access(flags: Option<roxmltree::Node<'_, '_>>) -> u16 {
    let Some(f) = flags else { return 0 };
    let mut a = 0;
    if let Some(acc) = child(f, "Access") {
        a = match acc.text().unwrap_or("").trim() {
            "ro" => 0x07,
            "rw" if acc.attribute("WriteRestrictions") == Some("PreOP") => 0x0F,
            "rw" => 0x3F,
            other => panic!("access {other} not expected"),
        };
    }
    match text(f, "PdoMapping").as_str() {
        "R" => a |= 0x40,
        "T" => a |= 0x80,
        "RT" | "TR" => a |= 0xC0,
        _ => {}
    }
    a
}

/// The dictionary of the first device of the ESI file `path` (relative to the crate).
pub fn dictionary(path: &str) -> Vec<Object> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    let xml = std::fs::read_to_string(&p).unwrap();
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let dict = doc
        .descendants()
        .find(|n| n.has_tag_name("Dictionary"))
        .expect("ESI has a Dictionary");
    let types: Vec<roxmltree::Node> = dict
        .descendants()
        .filter(|n| {
            n.has_tag_name("DataType") && n.parent().is_some_and(|p| p.has_tag_name("DataTypes"))
        })
        .collect();
    let mut out = Vec::new();
    for o in dict.descendants().filter(|n| n.has_tag_name("Object")) {
        let index = number(&text(o, "Index")) as u16;
        let name = text(o, "Name");
        let ty = text(o, "Type");
        let bits = number(&text(o, "BitSize"));
        if let Some(dt) = base_type(&ty) {
            out.push(Object {
                index,
                name: name.clone(),
                object_code: 7,
                entries: vec![Entry {
                    sub: 0,
                    name,
                    data_type: dt,
                    bits,
                    access: access(child(o, "Flags")),
                }],
            });
            continue;
        }
        let t = types
            .iter()
            .find(|t| text(**t, "Name") == ty)
            .unwrap_or_else(|| panic!("type {ty} of {index:#x} not declared"));
        let entries = t
            .children()
            .filter(|c| c.has_tag_name("SubItem"))
            .map(|s| Entry {
                sub: number(&text(s, "SubIdx")) as u8,
                name: text(s, "Name"),
                data_type: base_type(&text(s, "Type")).unwrap(),
                bits: number(&text(s, "BitSize")),
                access: access(child(s, "Flags")),
            })
            .collect();
        out.push(Object {
            index,
            name,
            object_code: 9,
            entries,
        });
    }
    out.sort_by_key(|o| o.index);
    out
}

/// The lines IgH's `ethercat sdos` prints for `objects`.
pub fn sdos_lines(objects: &[Object]) -> Vec<String> {
    let mut v = Vec::new();
    for o in objects {
        v.push(format!("SDO {:#06x}, \"{}\"", o.index, o.name));
        for e in &o.entries {
            v.push(format!(
                "  {:#06x}:{:02x}, {}, {}, {} bit, \"{}\"",
                o.index,
                e.sub,
                letters(e.access),
                igh_type(e.data_type),
                e.bits,
                e.name
            ));
        }
    }
    v
}
