//! What SOEM (tests/pysoem/vendor.py) must find on an emulated vendor device, read straight from
//! its ESI file with roxmltree (independently of `fieldprobe::esi`): identity, name and `Type`
//! text (the SII order string a master such as ethercrab shows), default
//! PDO mapping and the PDOs the remapping checks may edit.

#![allow(dead_code)] // each test crate uses its own subset

use std::path::Path;

use serde_json::{json, Value};

use super::esi_xml::esi_number;

fn kid<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(tag))
}

/// A device as its ESI says: identity, name, default mapping (RxPdo / TxPdo with `Sm`, entries
/// in order as (index, sub, bits)), the default PDOs (`rx_pdo` / `tx_pdo`) and whether they are
/// `Fixed`, the first RxPDO that is not fixed (`rx_edit`, where the remapping rules are tried)
/// and one object the dictionary does not mark RxPDO-mappable (a VAR of 16 or 32 bits at 0x6000
/// or above without `R` in `Flags/PdoMapping`).
pub fn device_spec(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).expect("read ESI");
    let doc = roxmltree::Document::parse(&text).expect("parse ESI");
    let root = doc.root_element();
    let vendor = esi_number(
        kid(kid(root, "Vendor").unwrap(), "Id")
            .and_then(|n| n.text())
            .unwrap(),
    );
    let device = root
        .descendants()
        .find(|n| n.has_tag_name("Device"))
        .expect("a Device");
    let ty = kid(device, "Type").unwrap();
    let names: Vec<_> = device
        .children()
        .filter(|c| c.has_tag_name("Name"))
        .collect();
    let name = names
        .iter()
        .find(|c| c.attribute("LcId") == Some("1033"))
        .or(names.first())
        .and_then(|c| c.text())
        .unwrap_or("")
        .to_string();
    let assigned = |tag: &'static str| {
        device
            .children()
            .filter(move |c| c.has_tag_name(tag) && c.attribute("Sm").is_some())
    };
    let pdos = |tag: &'static str| -> Vec<[u32; 3]> {
        assigned(tag)
            .flat_map(|p| p.children().filter(|e| e.has_tag_name("Entry")))
            .map(|e| {
                let f = |t: &str| kid(e, t).and_then(|n| n.text()).map_or(0, esi_number);
                [f("Index"), f("SubIndex"), f("BitLen")]
            })
            .collect()
    };
    let index_of =
        |p: roxmltree::Node| kid(p, "Index").and_then(|n| n.text()).map_or(0, esi_number);
    let fixed = |p: roxmltree::Node| matches!(p.attribute("Fixed"), Some("1" | "true"));
    let pdo_index = |tag: &'static str| assigned(tag).next().map_or(0, index_of);
    let pdo_fixed = |tag: &'static str| assigned(tag).next().is_some_and(fixed);
    let rx_edit = device
        .children()
        .find(|c| c.has_tag_name("RxPdo") && !fixed(*c))
        .map_or(0, index_of);
    let not_mappable = device
        .descendants()
        .filter(|n| n.has_tag_name("Object"))
        .find_map(|o| {
            let index = esi_number(kid(o, "Index")?.text()?);
            let bits = esi_number(kid(o, "BitSize")?.text()?);
            let base = ["UINT", "UDINT", "INT", "DINT"].contains(&kid(o, "Type")?.text()?);
            let rx = kid(o, "Flags")
                .and_then(|f| kid(f, "PdoMapping"))
                .and_then(|m| m.text())
                .is_some_and(|m| m.to_ascii_uppercase().contains('R'));
            (index >= 0x6000 && base && !rx && (bits == 16 || bits == 32))
                .then_some([index, 0, bits])
        })
        .expect("an object that is not RxPDO-mappable");
    json!({
        "vendor": vendor,
        "product": esi_number(ty.attribute("ProductCode").unwrap()),
        "revision": esi_number(ty.attribute("RevisionNo").unwrap_or("0")),
        "name": name,
        "type": ty.text().unwrap_or("").trim(),
        "rx": pdos("RxPdo"),
        "tx": pdos("TxPdo"),
        "not_mappable": not_mappable,
        "rx_pdo": pdo_index("RxPdo"),
        "tx_pdo": pdo_index("TxPdo"),
        "rx_fixed": pdo_fixed("RxPdo"),
        "tx_fixed": pdo_fixed("TxPdo"),
        "rx_edit": rx_edit,
    })
}
