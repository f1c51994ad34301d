//! [`VendorDevice`] from an ESI device (ETG.2000 `Profile/Dictionary`): data types by their
//! ETG.2000 base type names, PDO directions from `Flags/PdoMapping` (`R`, `T`, `RT`), SDO
//! access from `Flags/Access`, defaults from `Info/DefaultData`.

use super::{VendorDevice, VendorObject, OBJECTS_READ};
use crate::drive::pdo::DataType;
use crate::esi::{Access, Device, EsiFile, Flags, Object};

/// The drive type of an ETG.2000 base type name (`UINT` → u16); `None` for the others.
fn base_type(name: &str) -> Option<DataType> {
    Some(match name.trim().to_ascii_uppercase().as_str() {
        "BOOL" | "BIT" => DataType::Bool,
        "SINT" => DataType::I8,
        "USINT" | "BYTE" => DataType::U8,
        "INT" => DataType::I16,
        "UINT" | "WORD" => DataType::U16,
        "DINT" => DataType::I32,
        "UDINT" | "DWORD" => DataType::U32,
        _ => return None,
    })
}

/// Little-endian default bytes as a value of `ty` (sign-extended for signed types).
fn default_value(bytes: Option<&[u8]>, ty: Option<DataType>) -> Option<i64> {
    let b = bytes?;
    if b.is_empty() || b.len() > 8 {
        return None;
    }
    let raw = b.iter().rev().fold(0u64, |acc, &x| acc << 8 | u64::from(x));
    match ty {
        Some(t) if t.is_signed() => {
            let shift = 64 - 8 * b.len() as u32;
            Some(((raw << shift) as i64) >> shift)
        }
        _ => i64::try_from(raw).ok(),
    }
}

fn entry(
    index: u16,
    sub: u8,
    name: &str,
    type_name: &str,
    bits: u32,
    flags: &Flags,
    default: Option<&[u8]>,
) -> VendorObject {
    let ty = base_type(type_name).filter(|t| t.size() as u32 * 8 == bits || *t == DataType::Bool);
    let mapping = flags.pdo_mapping;
    VendorObject {
        index,
        sub,
        plays: (index, sub),
        name: name.to_string(),
        type_name: type_name.to_string(),
        ty,
        bits,
        rx: mapping.is_some_and(|m| m.rx()),
        tx: mapping.is_some_and(|m| m.tx()),
        writable: matches!(flags.access, Some(Access::ReadWrite | Access::WriteOnly)),
        default: default_value(default, ty),
        low: None,
        high: None,
    }
}

/// Sub-index `sub` of a record or array object: type and flags from the dictionary's data
/// type, the default from the object's `Info/SubItem` of the same name (else the one at that
/// position).
fn sub_entry(device: &Device, o: &Object, sub: u8) -> Option<VendorObject> {
    let dt = device.dictionary()?.data_type(&o.type_name)?;
    let item = dt.subitems.iter().find(|s| s.subindex == Some(sub))?;
    let info = o
        .subitems
        .iter()
        .find(|s| s.name == item.name)
        .or_else(|| o.subitems.get(usize::from(sub)));
    Some(entry(
        o.index,
        sub,
        &item.name,
        &item.type_name,
        item.bit_size,
        &item.flags,
        info.and_then(|i| i.default_data.as_deref()),
    ))
}

/// Modular device profile names (lower case, without blanks) of the drive-function objects a
/// device without the CiA 402 object may have (Beckhoff EL72x1 / EJ72x1: "Torque limitation"
/// 0x7010:0B, "Following error window" / "Following error time out" 0x8010:50 / :51).
fn mdp_function_names(index: u16) -> &'static [&'static str] {
    match index {
        0x6072 => &["torquelimitation", "maxtorque"],
        0x6065 => &["followingerrorwindow"],
        0x6066 => &["followingerrortimeout"],
        _ => &[],
    }
}

impl VendorDevice {
    /// The device `device` of the ESI `file` ([`OBJECTS_READ`] from its dictionary; for a
    /// modular device profile terminal the objects of the same names), with the roles and PDOs
    /// [`esi_plan::plan`](super::esi_plan::plan) chooses.
    pub fn from_esi(file: &EsiFile, device: &Device) -> VendorDevice {
        let mut objects = Vec::new();
        let leaves = super::esi_plan::leaves(device);
        for &(index, sub) in OBJECTS_READ {
            let Some(o) = device.object(index) else {
                let names = mdp_function_names(index);
                if let Some(l) = leaves.iter().find(|l| {
                    sub == 0
                        && (0x6000..=0x8FFF).contains(&l.index)
                        && l.sub > 0
                        && names.contains(&super::esi_plan::normalized(&l.name).as_str())
                }) {
                    let mut v = entry(
                        l.index,
                        l.sub,
                        &l.name,
                        &l.type_name,
                        l.bits,
                        &l.flags,
                        None,
                    );
                    v.plays = (index, sub);
                    objects.push(v);
                }
                continue;
            };
            let simple = device
                .dictionary()
                .and_then(|d| d.data_type(&o.type_name))
                .is_none_or(|t| t.subitems.is_empty());
            let v = if sub == 0 && simple {
                Some(entry(
                    index,
                    0,
                    &o.name,
                    &o.type_name,
                    o.bit_size,
                    &o.flags,
                    o.default_data.as_deref(),
                ))
            } else {
                sub_entry(device, o, sub)
            };
            objects.extend(v);
        }
        let plan = super::esi_plan::plan(device);
        VendorDevice {
            file: file.file.clone(),
            kind: "ESI",
            vendor: file.vendor.name.clone(),
            vendor_id: Some(file.vendor.id),
            product: device.type_name.clone(),
            product_code: Some(device.product_code),
            revision: Some(device.revision_no),
            objects,
            plan: plan.as_ref().ok().cloned(),
            plan_error: plan.err(),
            reference: None,
        }
    }
}
