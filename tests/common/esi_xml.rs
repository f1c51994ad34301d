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
    match t
        .strip_prefix("#x")
        .or_else(|| t.strip_prefix("#X"))
        .or_else(|| t.strip_prefix("0x"))
    {
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

/// What a configurator must find for every device of an ESI file, read straight from its XML
/// with roxmltree (independently of `fieldprobe::esi`): identity, the profile numbers it states
/// (its `Profile/ProfileNo`, its `Profile/ChannelInfo/ProfileNo`s and the `Profile` of each
/// slot's default module), 0x1000 as the file gives it, its PDO count and the modules of its
/// slots' defaults.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EsiDeviceFacts {
    pub identity: EsiIdentity,
    /// Every `ProfileNo` text found in the places above, as numbers.
    pub profile_numbers: Vec<u32>,
    /// `ChannelInfo` (ProfileNo, AddInfo) pairs of the device's own profile.
    pub channels: Vec<(u32, Option<u32>)>,
    /// 0x1000: `DefaultData` bytes zero-extended (little-endian), else `DefaultValue`.
    pub device_type: Option<u32>,
    /// `RxPdo` + `TxPdo` elements of the device plus those of its slots' default modules.
    pub pdo_count: usize,
    /// `Eeprom/ByteSize`.
    pub eeprom_bytes: Option<u32>,
}

/// The child elements of `n` named `tag`.
fn kids<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Vec<roxmltree::Node<'a, 'i>> {
    n.children().filter(|c| c.has_tag_name(tag)).collect()
}

/// [`EsiDeviceFacts`] of every device of the ESI file at `path`, in file order (a UTF-8 BOM is
/// skipped).
pub fn esi_file_facts(path: &Path) -> Vec<EsiDeviceFacts> {
    let text = std::fs::read_to_string(path).expect("read ESI");
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let doc = roxmltree::Document::parse(text).expect("parse ESI");
    let root = doc.root_element();
    let text_of = |n: roxmltree::Node<'_, '_>| n.text().unwrap_or("").trim().to_string();
    let vendor = esi_number(&text_of(child(child(root, "Vendor"), "Id")));
    let desc = child(root, "Descriptions");
    let modules: Vec<roxmltree::Node> = desc
        .children()
        .filter(|c| c.has_tag_name("Modules"))
        .flat_map(|m| kids(m, "Module"))
        .collect();
    let profile_numbers_of = |p: roxmltree::Node| -> Vec<u32> {
        kids(p, "ProfileNo")
            .into_iter()
            .chain(
                kids(p, "ChannelInfo")
                    .into_iter()
                    .flat_map(|c| kids(c, "ProfileNo")),
            )
            .map(|n| esi_number(&text_of(n)))
            .collect()
    };
    let mut out = Vec::new();
    for device in kids(child(desc, "Devices"), "Device") {
        let ty = child(device, "Type");
        let names = kids(device, "Name");
        let name = names
            .iter()
            .find(|c| c.attribute("LcId") == Some("1033"))
            .or(names.first())
            .map(|n| text_of(*n))
            .unwrap_or_else(|| text_of(ty));
        let mut profile_numbers: Vec<u32> = kids(device, "Profile")
            .into_iter()
            .flat_map(profile_numbers_of)
            .collect();
        let channels = kids(device, "Profile")
            .into_iter()
            .flat_map(|p| kids(p, "ChannelInfo"))
            .map(|c| {
                let add = kids(c, "AddInfo").first().map(|a| esi_number(&text_of(*a)));
                (esi_number(&text_of(child(c, "ProfileNo"))), add)
            })
            .collect();
        let mut pdo_count = kids(device, "RxPdo").len() + kids(device, "TxPdo").len();
        // each slot's default module (one instance per slot unless MinInstances says 0)
        for slot in kids(device, "Slots")
            .into_iter()
            .flat_map(|s| kids(s, "Slot"))
        {
            let n = slot.attribute("MinInstances").map_or(1, esi_number);
            let default = kids(slot, "ModuleIdent")
                .into_iter()
                .find(|m| matches!(m.attribute("Default"), Some("1" | "true")));
            let Some(default) = default else { continue };
            let ident = esi_number(&text_of(default));
            let module = modules
                .iter()
                .find(|m| {
                    child(**m, "Type").attribute("ModuleIdent").map(esi_number) == Some(ident)
                })
                .expect("the default module is in the file");
            for _ in 0..n {
                profile_numbers.extend(
                    kids(*module, "Profile")
                        .into_iter()
                        .flat_map(profile_numbers_of),
                );
                pdo_count += kids(*module, "RxPdo").len() + kids(*module, "TxPdo").len();
            }
        }
        let device_type = device
            .descendants()
            .filter(|n| n.has_tag_name("Object"))
            .find(|o| {
                kids(*o, "Index")
                    .first()
                    .is_some_and(|i| esi_number(&text_of(*i)) == 0x1000)
            })
            .and_then(|o| kids(o, "Info").first().copied())
            .and_then(|info| {
                if let Some(d) = kids(info, "DefaultData").first() {
                    let hex = text_of(*d);
                    // odd length: a leading 0 nibble (docs/interpretations.md E1)
                    let hex = if hex.len() % 2 == 1 {
                        format!("0{hex}")
                    } else {
                        hex
                    };
                    let bytes: Vec<u8> = (0..hex.len() / 2)
                        .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).expect("hex"))
                        .collect();
                    (bytes.len() <= 4)
                        .then(|| bytes.iter().rev().fold(0u32, |a, b| a << 8 | u32::from(*b)))
                } else {
                    kids(info, "DefaultValue")
                        .first()
                        .map(|v| esi_number(&text_of(*v)))
                }
            });
        let eeprom_bytes = kids(device, "Eeprom")
            .first()
            .and_then(|e| kids(*e, "ByteSize").first().copied())
            .map(|b| esi_number(&text_of(b)));
        out.push(EsiDeviceFacts {
            identity: EsiIdentity {
                vendor,
                product: esi_number(ty.attribute("ProductCode").expect("ProductCode")),
                revision: esi_number(ty.attribute("RevisionNo").unwrap_or("0")),
                type_name: text_of(ty),
                name,
            },
            profile_numbers,
            channels,
            device_type,
            pdo_count,
            eeprom_bytes,
        });
    }
    out
}
