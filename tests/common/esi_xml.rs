//! What a master must find for a device, read straight from its ESI file with roxmltree
//! (independently of `fieldprobe::esi`).

#![allow(dead_code)] // each test crate uses its own subset

use std::{ops::Deref, path::Path};

/// Identity and names of a device as written in its ESI file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EsiIdentity {
    pub vendor: u32,
    pub product: u32,
    pub revision: u32,
    /// `Type` text.
    pub type_name: String,
    /// English (`LcId` 1033) name.
    pub name: String,
}

/// [`EsiIdentity`] plus the default-mapped process data (derefs to the identity).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EsiDevice {
    pub identity: EsiIdentity,
    /// Bits of the RxPDOs assigned to a sync manager by default (`RxPdo@Sm`).
    pub out_bits: u32,
    /// Bits of the TxPDOs assigned by default.
    pub in_bits: u32,
}

impl Deref for EsiDevice {
    type Target = EsiIdentity;
    fn deref(&self) -> &EsiIdentity {
        &self.identity
    }
}

/// An ESI number: `#x…` / `0x…` hex or decimal.
pub fn esi_number(s: &str) -> u32 {
    let t = s.trim();
    match t.strip_prefix("#x").or_else(|| t.strip_prefix("0x")) {
        Some(h) => u32::from_str_radix(h, 16).expect("hex number"),
        None => t.parse().expect("decimal number"),
    }
}

fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> roxmltree::Node<'a, 'i> {
    n.children()
        .find(|c| c.has_tag_name(tag))
        .unwrap_or_else(|| panic!("no <{tag}> in <{}>", n.tag_name().name()))
}

/// Vendor ID, product code, revision, `Type` text, English name and default PDO bit sums of
/// the first device in the ESI file at `path`.
pub fn esi_device(path: &Path) -> EsiDevice {
    let text = std::fs::read_to_string(path).expect("read ESI");
    let doc = roxmltree::Document::parse(&text).expect("parse ESI");
    let root = doc.root_element();
    let vendor = esi_number(child(child(root, "Vendor"), "Id").text().unwrap_or(""));
    let device = child(child(child(root, "Descriptions"), "Devices"), "Device");
    let ty = child(device, "Type");
    let name = device
        .children()
        .filter(|c| c.has_tag_name("Name"))
        .find(|c| c.attribute("LcId") == Some("1033"))
        .and_then(|c| c.text())
        .unwrap_or("")
        .to_string();
    let pdo_bits = |tag: &str| -> u32 {
        device
            .children()
            .filter(|c| c.has_tag_name(tag) && c.attribute("Sm").is_some())
            .flat_map(|p| p.children().filter(|e| e.has_tag_name("Entry")))
            .map(|e| esi_number(child(e, "BitLen").text().unwrap_or("0")))
            .sum()
    };
    EsiDevice {
        identity: EsiIdentity {
            vendor,
            product: esi_number(ty.attribute("ProductCode").expect("ProductCode")),
            revision: esi_number(ty.attribute("RevisionNo").unwrap_or("0")),
            type_name: ty.text().unwrap_or("").trim().to_string(),
            name,
        },
        out_bits: pdo_bits("RxPdo"),
        in_bits: pdo_bits("TxPdo"),
    }
}

/// [`esi_device`] of each of `files` (relative to the crate directory), in order.
pub fn esi_devices(files: &[&str]) -> Vec<EsiDevice> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    files.iter().map(|f| esi_device(&dir.join(f))).collect()
}

/// [`esi_devices`] without the process data.
pub fn esi_identities(files: &[&str]) -> Vec<EsiIdentity> {
    esi_devices(files).into_iter().map(|d| d.identity).collect()
}

/// [`esi_device`] without the process data.
pub fn esi_identity(path: &Path) -> EsiIdentity {
    esi_device(path).identity
}
