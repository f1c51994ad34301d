//! Emulated vendor CiA 402 drive: the device a vendor's ESI describes, played as that vendor's
//! device rather than as a device made to match a fieldprobe drive file.
//!
//! [`emulated_vendor_drive`] builds from the ESI device:
//! * **identity, SII, mailbox, DC**: the SII image the ESI gives ([`sii_from_device`]), so a
//!   master reads the vendor id, product code, revision, name, sync managers, PDOs and DC modes
//!   the ESI declares; 0x1018 carries the same identity (serial number 0, like the SII);
//! * **object dictionary**: every object of the ESI `Profile/Dictionary` with its data type,
//!   access and `DefaultData` ([`dictionary_entries`]); records and arrays sub-index by
//!   sub-index (array elements from the data type's `ArrayInfo`); the SDO Information service
//!   describes them from the same ESI ([`OdDescriptions::from_esi`]), PDO mapping flags
//!   included. The CiA 402 objects the drive model implements (0x6040, 0x6041, 0x6060,
//!   0x6061, 0x6064, 0x607A, 0x60F4, 0x6077, 0x60B8–0x60BD …, see [`ds402_objects`]) are backed
//!   by the model where the ESI declares them with the model's data type; every other object
//!   holds its value (its ESI default, then what a master writes). 0x1C00 (sync manager
//!   communication types) is added from the ESI's sync managers when the ESI omits it (a
//!   CoE device has it, ETG.1000.6 §5.6.7.4.1; SOEM reads it);
//! * **PDO assignment and mapping**: 0x1C12 / 0x1C13 hold the RxPDOs / TxPDOs the ESI assigns
//!   to the output / input sync manager (`Sm` attribute), each mapping object 0x16xx / 0x1Axx
//!   the entries of its ESI `RxPdo` / `TxPdo`; a master may rewrite them in PRE-OP under the
//!   rules of [`super::pdo_rules`] (abort codes named there), up to the sync managers' size
//!   ([`sm_limit`]);
//! * **process data**: the bus images follow the mapping the master wrote (checked on PRE-OP →
//!   SAFE-OP, AL status 0x001D / 0x001E when it cannot be served); each mapped object is
//!   wired by its index: an object of the drive model's layout goes to / comes from the model's
//!   image, any other mapped object is the dictionary's value (an RxPDO writes it, a TxPDO
//!   reads it — e.g. 0x60FF target velocity, 0x606C velocity actual value);
//! * **drive model**: the CiA 402 model of the base drive definition (`cia402-generic` for
//!   `fieldprobe sim ethercat`), its layout cut down to the objects the ESI declares mappable
//!   in that direction ([`model_definition`]): a device without 0x60B8 / 0x60B9 has no touch
//!   probe. It needs 0x6040 and 0x607A (RxPDO) and 0x6041 and 0x6064 (TxPDO), else
//!   [`ServoError::Vendor`] names what is missing.
//!
//! Time base and the safe state when leaving OP are those of [`super::device`].

use std::collections::BTreeMap;
use std::time::Duration;

use super::coe::{ds402_objects, Access, CoeServer, DataType, ObjectEntry};
use super::device::{assigned, mailbox_error, RoleLink, ServoApp, ServoError};
use super::pdo_rules::PdoRules;
use super::sdo_info::OdDescriptions;
use super::{Esc, EscConfig};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::model::DriveModel;
use crate::drive::pdo::PdoLayout;
use crate::drive::vendor::esi_plan::{object_leaves, role_sources};
use crate::drive::vendor::plan::RoleSource;
use crate::esi::sii;
use crate::esi::to_sii::sii_from_device;
use crate::esi::{Device, Dictionary, EsiFile, Flags, Pdo, SmKind};

/// Sub-indices a mapping object gets when the ESI dictionary does not declare it.
const MAPPING_CAPACITY: u8 = super::device::MAPPING_CAPACITY;

/// An emulated vendor device and what the emulator had to assume to play it.
#[derive(Debug)]
pub struct VendorDrive {
    /// The device.
    pub esc: Esc,
    /// What the ESI left open and how the emulator filled it (e.g. an object a fixed PDO maps
    /// but the dictionary lacks, served as 0), one line each, for stderr.
    pub notes: Vec<String>,
}

/// Emulated vendor CiA 402 drive of the ESI `device` (see the module documentation): the
/// model of `base` (its `[model]`, `[probe]` and scaling; its PDO layout cut to the CiA 402
/// objects the device offers), stepping by `cycle` per exchange when free-running.
pub fn emulated_vendor_drive(
    esi: &EsiFile,
    device: &Device,
    base: &DriveDefinition,
    cycle: Duration,
) -> Result<VendorDrive, ServoError> {
    let cycle_ns = u64::try_from(cycle.as_nanos()).unwrap_or(u64::MAX);
    if cycle_ns == 0 {
        return Err(ServoError::ZeroCycle);
    }
    let content = sii_from_device(esi, device)?;
    let cfg = EscConfig::from_sii(sii::encode_padded(&content)?);
    let Some(mbx) = cfg.mailbox else {
        return Err(mailbox_error(device));
    };
    if let e @ ServoError::MailboxSize { .. } = mailbox_error(device) {
        return Err(e);
    }
    let dict = device.dictionary().ok_or_else(|| {
        ServoError::Vendor(format!(
            "ESI device {}: no Profile/Dictionary; a CiA 402 drive is played from its object dictionary",
            device.type_name
        ))
    })?;
    let sources = role_sources(device);
    let def = model_definition(&device.type_name, &sources, base)?;
    let model =
        crate::drive::model::for_definition(&def).map_err(|e| ServoError::Model(e.to_string()))?;
    let links: Vec<RoleLink> = sources
        .iter()
        .flat_map(|s| {
            s.parts.iter().map(|p| RoleLink {
                object: (p.index, p.sub),
                canonical: (s.index, s.sub),
                at: p.at,
            })
        })
        .collect();
    let mut notes = Vec::new();
    let mut entries = dictionary_entries(dict, model.as_ref());
    add_pdo_objects(&mut entries, device, &mut notes);
    // Whole-object roles answer from the model (an SDO of 0x7010:03 sets the mode 0x6060).
    let mut aliases = Vec::new();
    for s in sources.iter().filter(|s| s.word.is_none()) {
        let (index, sub) = s.object();
        if (index, sub) == (s.index, s.sub) || model.read_object(s.index, s.sub).is_err() {
            continue;
        }
        if let Some(e) = entries
            .iter_mut()
            .find(|e| e.index == index && e.sub == sub && e.data.is_some())
        {
            e.data = None;
            aliases.push(((index, sub), (s.index, s.sub)));
        }
    }
    let constant = |index, sub, ty, v| ObjectEntry::constant(index, sub, ty, v);
    for e in [
        constant(0x1018, 0, DataType::U8, 4),
        constant(0x1018, 1, DataType::U32, i64::from(esi.vendor.id)),
        constant(0x1018, 2, DataType::U32, i64::from(device.product_code)),
        constant(0x1018, 3, DataType::U32, i64::from(device.revision_no)),
        constant(0x1018, 4, DataType::U32, 0),
    ] {
        put(&mut entries, e);
    }
    if !entries.iter().any(|e| e.index == 0x1C00) {
        let n = device.sync_managers.len().min(32);
        entries.push(constant(0x1C00, 0, DataType::U8, n as i64));
        for (k, sm) in device.sync_managers.iter().take(n).enumerate() {
            let ty = match sm.kind {
                SmKind::MBoxOut => 1,
                SmKind::MBoxIn => 2,
                SmKind::Outputs => 3,
                SmKind::Inputs => 4,
                _ => 0,
            };
            entries.push(constant(0x1C00, k as u8 + 1, DataType::U8, ty));
        }
    }
    pdo_entries(&mut entries, 0x1C12, &device.rx_pdos, cfg.output_sm);
    pdo_entries(&mut entries, 0x1C13, &device.tx_pdos, cfg.input_sm);
    let mut coe = CoeServer::new(model, entries, usize::from(mbx.tx_size));
    coe.set_complete_access(super::device::esi_complete_access(device));
    for (entry, model) in aliases {
        coe.alias(entry, model);
    }
    coe.set_descriptions(OdDescriptions::from_esi(dict, coe.entries()));
    coe.set_pdo_rules(PdoRules::new(
        sm_limit(device, SmKind::Outputs),
        sm_limit(device, SmKind::Inputs),
    ));
    let app = ServoApp::vendor(coe, def.rxpdo.clone(), def.txpdo.clone(), links, cycle_ns)
        .map_err(|code| {
            ServoError::Vendor(format!(
                "ESI device {}: its default PDO mapping cannot be served (AL status {code:?})",
                device.type_name
            ))
        })?;
    Ok(VendorDrive {
        esc: Esc::new(cfg, Box::new(app)),
        notes,
    })
}

/// Most bytes the sync manager of `kind` may carry: its ESI `MaxSize`; without one, the space
/// up to the next sync manager's start address in three-buffer mode (the ESC reserves three
/// times the length, ETG.1000.4 §6.7.2), or for the last one up to the end of a 4 KiB process
/// RAM above 0x1000 (the smallest ESC process memory, ETG.1000.4 §6.1), also ÷ 3.
pub fn sm_limit(device: &Device, kind: SmKind) -> usize {
    let Some((_, sm)) = device.sync_manager(&kind) else {
        return 0;
    };
    if let Some(max) = sm.max_size {
        return usize::from(max);
    }
    let next = device
        .sync_managers
        .iter()
        .map(|s| s.start_address)
        .filter(|&a| a > sm.start_address)
        .min()
        .map_or(0x2000, usize::from);
    next.saturating_sub(usize::from(sm.start_address)) / 3
}

/// The drive definition the model runs with: `base` with its PDO layouts cut down to the CiA
/// 402 objects the device offers in that direction by any of its [`RoleSource`]s;
/// `[rxpdo] defaults` of objects that remain. The model needs the controlword and the target
/// position (master → drive), the statusword and the position actual value (drive → master),
/// else [`ServoError::Vendor`] names what is missing.
pub fn model_definition(
    device: &str,
    sources: &[RoleSource],
    base: &DriveDefinition,
) -> Result<DriveDefinition, ServoError> {
    let offered =
        |index: u16, rx: bool| -> bool { sources.iter().any(|s| s.index == index && s.rx == rx) };
    let missing: Vec<String> = [
        (0x6040u16, true),
        (0x607A, true),
        (0x6041, false),
        (0x6064, false),
    ]
    .iter()
    .filter(|(i, rx)| !offered(*i, *rx))
    .map(|(i, rx)| format!("{i:#06X} ({})", if *rx { "RxPDO" } else { "TxPDO" }))
    .collect();
    if !missing.is_empty() {
        return Err(ServoError::Vendor(format!(
            "ESI device {device}: the CiA 402 drive model needs {}: neither the CiA 402 object \
             nor an object of the device that plays it (drive from-esi names what it found)",
            missing.join(", ")
        )));
    }
    let cut = |layout: &PdoLayout, rx: bool| -> Result<PdoLayout, ServoError> {
        let kept: Vec<_> = layout
            .entries()
            .iter()
            .filter(|e| e.sub == 0 && offered(e.index, rx))
            .map(|e| (e.index, e.sub, e.ty))
            .collect();
        PdoLayout::from_objects(&kept).map_err(|e| ServoError::Model(e.to_string()))
    };
    let mut def = base.clone();
    def.rxpdo = cut(&base.rxpdo, true)?;
    def.txpdo = cut(&base.txpdo, false)?;
    def.roles.clear();
    let rx = def.rxpdo.clone();
    def.rxpdo_defaults.retain(|d| rx.contains(d.index, d.sub));
    Ok(def)
}

/// Objects the ESI's PDOs map but its dictionary lacks (vendor objects of a fixed PDO such as
/// MyActuator's 0x5FF1, the AX2000's 0x6062): added as plain values, 0 at start, read-write
/// in an RxPDO, read-only in a TxPDO, as many bytes as the entry's bits need; one note each.
fn add_pdo_objects(entries: &mut Vec<ObjectEntry>, device: &Device, notes: &mut Vec<String>) {
    for (pdos, rx) in [(&device.rx_pdos, true), (&device.tx_pdos, false)] {
        for p in pdos {
            for e in p.entries.iter().filter(|e| e.index != 0) {
                if entries
                    .iter()
                    .any(|x| x.index == e.index && x.sub == e.subindex)
                {
                    continue;
                }
                let ty = match (e.bit_len, e.data_type.as_deref().map(str::trim)) {
                    (16, Some("INT")) => DataType::I16,
                    (32, Some("DINT")) => DataType::I32,
                    (b, _) if b <= 8 => DataType::U8,
                    (b, _) if b <= 16 => DataType::U16,
                    (b, _) if b <= 32 => DataType::U32,
                    (b, _) => DataType::Bytes(usize::from(b).div_ceil(8)),
                };
                entries.push(ObjectEntry {
                    access: if rx { Access::Rw } else { Access::Ro },
                    ..ObjectEntry::constant(e.index, e.subindex, ty, 0)
                });
                notes.push(format!(
                    "{:#06X}:{:02X} ({} bits) is mapped by PDO {:#06X} but not in the ESI \
                     dictionary: served as a plain value, 0 at start",
                    e.index, e.subindex, e.bit_len, p.index
                ));
            }
        }
    }
}

/// The server entry type of an ESI type name with `bits` bits: the CiA 301 integer types by
/// their ESI names, byte strings (fixed length) for REAL / LREAL, strings and other types of
/// whole bytes; `None` for what cannot be stored (bit fields other than BOOL).
fn entry_type(name: &str, bits: u32) -> Option<DataType> {
    Some(match name.trim() {
        "BOOL" | "BIT" => DataType::Bool,
        // ETG.2000 BIT2 … BIT8: a few bits, held in a byte.
        n if n.starts_with("BIT") && bits <= 8 => DataType::U8,
        "SINT" => DataType::I8,
        "INT" => DataType::I16,
        "DINT" => DataType::I32,
        "LINT" => DataType::I64,
        "USINT" | "BYTE" => DataType::U8,
        "UINT" | "WORD" => DataType::U16,
        "UDINT" | "DWORD" => DataType::U32,
        "ULINT" => DataType::U64,
        _ if bits > 0 && bits.is_multiple_of(8) => DataType::Bytes((bits / 8) as usize),
        _ => return None,
    })
}

fn access_of(f: &Flags, fallback: Access) -> Access {
    match f.access {
        Some(crate::esi::Access::ReadOnly) => Access::Ro,
        Some(crate::esi::Access::ReadWrite) => Access::Rw,
        Some(crate::esi::Access::WriteOnly) => Access::Wo,
        None => fallback,
    }
}

/// The server table of the ESI dictionary `dict` (see the module documentation): defaults from
/// `Info/DefaultData` (a record's or array's `Info/SubItem`s in sub-index order), the CiA 402
/// objects the model answers backed by `model`.
pub fn dictionary_entries(dict: &Dictionary, model: &dyn DriveModel) -> Vec<ObjectEntry> {
    let backed: BTreeMap<(u16, u8), DataType> = ds402_objects("")
        .into_iter()
        .filter(|e| e.data.is_none())
        .map(|e| ((e.index, e.sub), e.ty))
        .collect();
    let mut out = Vec::new();
    for o in &dict.objects {
        let subs = object_leaves(dict, o);
        let record = !(subs.len() == 1 && subs[0].sub == 0);
        for (n, leaf) in subs.into_iter().enumerate() {
            let (sub, type_name, bits, flags) = (leaf.sub, leaf.type_name, leaf.bits, &leaf.flags);
            let Some(ty) = entry_type(&type_name, bits) else {
                continue;
            };
            if out
                .iter()
                .any(|e: &ObjectEntry| e.index == o.index && e.sub == sub)
            {
                continue;
            }
            let access = access_of(flags, Access::Ro);
            // Backed by the model when the ESI gives the object the model's size (an enum or
            // unsigned type of the same width, as vendors declare 0x6060 or 0x6064, included).
            if backed
                .get(&(o.index, sub))
                .is_some_and(|t| t.size() == ty.size())
                && model.read_object(o.index, sub).is_ok()
            {
                out.push(ObjectEntry::model(o.index, sub, ty, access));
                continue;
            }
            // `DefaultData` (hexBinary), else `DefaultValue` (a number, as Inovance writes
            // 0x1000), little-endian in the entry's size.
            let size_of = ty.size().unwrap_or(match ty {
                DataType::Bytes(n) => n,
                _ => 0,
            });
            let number =
                |v: Option<i128>| v.map(|v| (v as i64).to_le_bytes()[..size_of.min(8)].to_vec());
            let default = if record {
                o.subitems
                    .get(n)
                    .and_then(|s| s.default_data.clone().or_else(|| number(s.values.default)))
            } else {
                o.default_data.clone().or_else(|| number(o.values.default))
            };
            let size = ty.size().unwrap_or(match ty {
                DataType::Bytes(n) => n,
                _ => 0,
            });
            let data = match (ty, default) {
                (DataType::Bytes(_), Some(d)) if type_name.starts_with("STRING") => {
                    d.into_iter().take(size).collect()
                }
                (_, Some(mut d)) => {
                    d.resize(size, 0);
                    d
                }
                (_, None) => vec![0; size],
            };
            out.push(ObjectEntry {
                index: o.index,
                sub,
                ty,
                access,
                data: Some(data),
            });
        }
    }
    out
}

/// Add `e`, or set the value of the entry at its index / sub-index (keeping its access).
fn put(entries: &mut Vec<ObjectEntry>, e: ObjectEntry) {
    match entries
        .iter_mut()
        .find(|x| x.index == e.index && x.sub == e.sub)
    {
        Some(x) => {
            x.data = e.data;
            x.ty = e.ty;
        }
        None => entries.push(e),
    }
}

/// Set the assignment object `assign` to the PDOs of `pdos` the ESI assigns to sync manager
/// `sm`, and every PDO's mapping object to its entries; objects the ESI dictionary lacks are
/// added read-write (read-only for a `Fixed` PDO's mapping).
fn pdo_entries(entries: &mut Vec<ObjectEntry>, assign: u16, pdos: &[Pdo], sm: u8) {
    let value = |index, sub, ty: DataType, v: i64, access| ObjectEntry {
        access,
        ..ObjectEntry::constant(index, sub, ty, v)
    };
    let defaults = assigned(pdos, sm);
    put(
        entries,
        value(assign, 0, DataType::U8, defaults.len() as i64, Access::Rw),
    );
    let declared = entries
        .iter()
        .filter(|e| e.index == assign && e.sub > 0)
        .count();
    let slots = declared.max(defaults.len()).max(1);
    for k in 1..=slots.min(255) {
        let pdo = defaults.get(k - 1).map_or(0, |p| i64::from(p.index));
        put(
            entries,
            value(assign, k as u8, DataType::U16, pdo, Access::Rw),
        );
    }
    for p in pdos {
        let access = if p.fixed { Access::Ro } else { Access::Rw };
        put(
            entries,
            value(p.index, 0, DataType::U8, p.entries.len() as i64, access),
        );
        let declared = entries
            .iter()
            .filter(|e| e.index == p.index && e.sub > 0)
            .count();
        let slots = if declared == 0 {
            usize::from(MAPPING_CAPACITY).max(p.entries.len())
        } else {
            declared.max(p.entries.len())
        };
        for j in 1..=slots.min(255) {
            let m = p
                .entries
                .get(j - 1)
                .map_or(0, |e| i64::from(e.mapping_value()));
            put(entries, value(p.index, j as u8, DataType::U32, m, access));
        }
    }
}
