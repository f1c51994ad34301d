//! `Profile` (with `ChannelInfo`) and `Profile/Dictionary` of a device or module.

use super::{Ctx, Res, U16, U32, U8};
use crate::esi::values;
use crate::esi::warn::Oddity;
use crate::esi::*;
use roxmltree::Node;

/// The `Profile` elements of a device: the first one, with the `ProfileNo` / `AddInfo` of any
/// further `Profile` element kept as a channel and its dictionary used when the first has none
/// (ETG.2000 allows several; the vendor files seen have one).
pub(super) fn parse_profiles(cx: &Ctx, parent: Node) -> Res<Option<Profile>> {
    let mut out: Option<Profile> = None;
    for p in cx.children(parent, "Profile") {
        let profile = parse_profile(cx, p)?;
        match &mut out {
            None => out = Some(profile),
            Some(first) => {
                if let Some(no) = profile.profile_no {
                    first.channels.push(ChannelInfo {
                        profile_no: no,
                        add_info: profile.add_info,
                        display_name: None,
                    });
                }
                first.channels.extend(profile.channels);
                if first.dictionary.is_none() {
                    first.dictionary = profile.dictionary;
                }
            }
        }
    }
    Ok(out)
}

fn parse_profile(cx: &Ctx, p: Node) -> Res<Profile> {
    let dictionary = cx
        .child(p, "Dictionary")
        .map(|d| parse_dictionary(cx, d))
        .transpose()?;
    let channels = cx
        .children(p, "ChannelInfo")
        .filter_map(|c| {
            let Some(no) = cx.child(c, "ProfileNo") else {
                let oddity = Oddity::LeftOut {
                    why: "ChannelInfo without ProfileNo: left out".to_string(),
                };
                cx.warn(c, None, oddity);
                return None;
            };
            Some(ChannelInfo {
                profile_no: cx.elem_opt_num(no, 0, U32)? as u32,
                add_info: cx.child_opt_num(c, "AddInfo", 0, U32).map(|v| v as u32),
                display_name: cx
                    .children(c, "DisplayName")
                    .next()
                    .map(|n| cx.text(n).to_string()),
            })
        })
        .collect();
    Ok(Profile {
        profile_no: cx.child_opt_num(p, "ProfileNo", 0, U32).map(|v| v as u32),
        add_info: cx.child_opt_num(p, "AddInfo", 0, U32).map(|v| v as u32),
        channels,
        dictionary,
    })
}

fn parse_dictionary(cx: &Ctx, d: Node) -> Res<Dictionary> {
    let mut dict = Dictionary::default();
    if let Some(dts) = cx.child(d, "DataTypes") {
        for t in cx.children(dts, "DataType") {
            dict.data_types.push(parse_data_type(cx, t)?);
        }
    }
    if let Some(objs) = cx.child(d, "Objects") {
        for o in cx.children(objs, "Object") {
            dict.objects.push(parse_object(cx, o)?);
        }
    }
    Ok(dict)
}

fn parse_data_type(cx: &Ctx, t: Node) -> Res<DataType> {
    let array = cx
        .child(t, "ArrayInfo")
        .map(|a| -> Res<ArrayInfo> {
            Ok(ArrayInfo {
                lbound: cx.required_num(a, "LBound", 0, U32)? as u32,
                elements: cx.required_num(a, "Elements", 0, U32)? as u32,
            })
        })
        .transpose()?;
    let subitems = cx
        .children(t, "SubItem")
        .map(|s| -> Res<DataTypeSubItem> {
            Ok(DataTypeSubItem {
                subindex: cx.child_num(s, "SubIdx", 0, U8)?.map(|v| v as u8),
                name: cx.required_text(s, "Name")?,
                type_name: cx.required_text(s, "Type")?,
                bit_size: cx.required_num(s, "BitSize", 0, U32)? as u32,
                bit_offs: cx.child_num(s, "BitOffs", 0, U32)?.unwrap_or(0) as u32,
                flags: parse_flags(cx, s),
            })
        })
        .collect::<Res<Vec<_>>>()?;
    Ok(DataType {
        name: cx.required_text(t, "Name")?,
        base_type: cx.child_text(t, "BaseType"),
        bit_size: cx.required_num(t, "BitSize", 0, U32)? as u32,
        array,
        subitems,
    })
}

/// `Flags`: an `Access` / `PdoMapping` text ETG.2000 does not define is read as not given,
/// with a warning.
fn parse_flags(cx: &Ctx, parent: Node) -> Flags {
    let Some(f) = cx.child(parent, "Flags") else {
        return Flags::default();
    };
    let access_node = cx.child(f, "Access");
    let access = access_node.and_then(|a| {
        let t = cx.text(a);
        let read = values::read_access(t);
        if read.is_none() {
            cx.warn(
                a,
                None,
                Oddity::Access {
                    text: t.to_string(),
                },
            );
        }
        read
    });
    let pdo_mapping = cx.child(f, "PdoMapping").and_then(|p| {
        let t = cx.text(p);
        values::read_pdo_mapping(t).unwrap_or_else(|()| {
            cx.warn(
                p,
                None,
                Oddity::PdoMapping {
                    text: t.to_string(),
                },
            );
            None
        })
    });
    Flags {
        access,
        write_restrictions: access_node
            .and_then(|a| a.attribute("WriteRestrictions"))
            .map(str::to_string),
        pdo_mapping,
        category: cx.child_text(f, "Category"),
    }
}

/// `Info/DefaultValue`, `MinValue`, `MaxValue` (numbers; unreadable ones left out with a
/// warning). Any 128-bit value is kept: the field's type is the object's.
fn info_values(cx: &Ctx, info: Option<Node>) -> InfoValues {
    let Some(i) = info else {
        return InfoValues::default();
    };
    let v = |name| cx.child_opt_num(i, name, i128::MIN, i128::MAX);
    InfoValues {
        default: v("DefaultValue"),
        min: v("MinValue"),
        max: v("MaxValue"),
    }
}

/// The default of an `Info` element as bytes: `DefaultData` (hexBinary), else `DefaultString`
/// (ETG.2000 `InfoType`: the default of a STRING object as text, e.g. Inovance's 0x1008
/// `SV660-ECAT`), its UTF-8 bytes.
fn default_bytes(cx: &Ctx, info: Node) -> Option<Vec<u8>> {
    if let Some(d) = cx.child(info, "DefaultData") {
        return cx.hex_bytes(d);
    }
    cx.child(info, "DefaultString")
        .map(|d| d.text().unwrap_or_default().as_bytes().to_vec())
}

fn parse_object(cx: &Ctx, o: Node) -> Res<Object> {
    let info = cx.child(o, "Info");
    let default_data = info.and_then(|i| default_bytes(cx, i));
    let subitems = match info {
        None => Vec::new(),
        Some(i) => cx
            .children(i, "SubItem")
            .map(|s| {
                let si = cx.child(s, "Info");
                ObjectSubItem {
                    name: cx.child_text(s, "Name").unwrap_or_default(),
                    default_data: si.and_then(|si| default_bytes(cx, si)),
                    values: info_values(cx, si),
                }
            })
            .collect(),
    };
    let index = cx.require(o, "Index")?;
    Ok(Object {
        index: cx.elem_num(index, 0, U16)? as u16,
        depend_on_slot: cx.depends_on_slot(Some(index))?,
        name: cx.required_text(o, "Name")?,
        type_name: cx.required_text(o, "Type")?,
        bit_size: cx.required_num(o, "BitSize", 0, U32)? as u32,
        default_data,
        values: info_values(cx, info),
        flags: parse_flags(cx, o),
        subitems,
    })
}
