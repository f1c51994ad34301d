//! ETG.2000 XML → [`EsiFile`] with `roxmltree`.
//!
//! Interpretations (see also the module docs of [`super`]):
//! - Numbers: `#x` prefix = hexadecimal, otherwise decimal (a leading `-` allowed where the
//!   value is signed). Values out of the target type's range are errors.
//! - Booleans: `true` / `false` / `1` / `0`.
//! - Elements the description does not model (images, `Info`, `InitCmd`, `Modules`, …) are
//!   ignored; a missing required element is an error naming its parent.

use super::device::*;
use super::{EsiError, Problem};
use roxmltree::{Document, Node};

/// Parser context: the document (for line numbers) and the file name (for messages).
struct Ctx<'a, 'input> {
    doc: &'a Document<'input>,
    file: &'a str,
}

type Res<T> = Result<T, EsiError>;

impl<'a, 'input> Ctx<'a, 'input> {
    fn err_at(&self, node: Node, pos: usize, problem: Problem) -> EsiError {
        let tp = self.doc.text_pos_at(pos);
        EsiError::Invalid {
            file: self.file.to_string(),
            line: tp.row,
            column: tp.col,
            path: element_path(node),
            problem,
        }
    }

    fn err(&self, node: Node, problem: Problem) -> EsiError {
        self.err_at(node, node.range().start, problem)
    }

    /// First child element named `name`.
    fn child<'n>(&self, node: Node<'n, 'input>, name: &str) -> Option<Node<'n, 'input>> {
        node.children()
            .find(|c| c.is_element() && c.tag_name().name() == name)
    }

    fn children<'n>(
        &self,
        node: Node<'n, 'input>,
        name: &'n str,
    ) -> impl Iterator<Item = Node<'n, 'input>> + 'n {
        node.children()
            .filter(move |c| c.is_element() && c.tag_name().name() == name)
    }

    fn require<'n>(&self, node: Node<'n, 'input>, name: &str) -> Res<Node<'n, 'input>> {
        self.child(node, name)
            .ok_or_else(|| self.err(node, Problem::MissingElement(name.to_string())))
    }

    /// Trimmed text of an element (empty if none).
    fn text<'n>(&self, node: Node<'n, 'input>) -> &'n str {
        node.text().map(str::trim).unwrap_or("")
    }

    fn child_text(&self, node: Node, name: &str) -> Option<String> {
        self.child(node, name).map(|c| self.text(c).to_string())
    }

    fn required_text(&self, node: Node, name: &str) -> Res<String> {
        let c = self.require(node, name)?;
        Ok(self.text(c).to_string())
    }

    /// Number in the text of a child element, range-checked to `[min, max]`.
    fn child_num(&self, node: Node, name: &str, min: i128, max: i128) -> Res<Option<i128>> {
        match self.child(node, name) {
            None => Ok(None),
            Some(c) => self.elem_num(c, min, max).map(Some),
        }
    }

    fn required_num(&self, node: Node, name: &str, min: i128, max: i128) -> Res<i128> {
        let c = self.require(node, name)?;
        self.elem_num(c, min, max)
    }

    fn elem_num(&self, node: Node, min: i128, max: i128) -> Res<i128> {
        let t = self.text(node);
        let v = parse_number(t).ok_or_else(|| self.err(node, Problem::BadNumber(t.to_string())))?;
        if v < min || v > max {
            return Err(self.err(node, Problem::OutOfRange(t.to_string())));
        }
        Ok(v)
    }

    /// Number in an attribute, range-checked.
    fn attr_num(&self, node: Node, name: &str, min: i128, max: i128) -> Res<Option<i128>> {
        let Some(a) = node.attribute_node(name) else {
            return Ok(None);
        };
        let t = a.value().trim();
        let pos = a.range().start;
        let v = parse_number(t).ok_or_else(|| {
            self.err_at(
                node,
                pos,
                Problem::BadAttribute(name.to_string(), t.to_string()),
            )
        })?;
        if v < min || v > max {
            return Err(self.err_at(
                node,
                pos,
                Problem::BadAttribute(name.to_string(), t.to_string()),
            ));
        }
        Ok(Some(v))
    }

    fn attr_bool(&self, node: Node, name: &str) -> Res<bool> {
        let Some(a) = node.attribute_node(name) else {
            return Ok(false);
        };
        match a.value().trim() {
            "true" | "1" => Ok(true),
            "false" | "0" => Ok(false),
            other => Err(self.err_at(
                node,
                a.range().start,
                Problem::BadAttribute(name.to_string(), other.to_string()),
            )),
        }
    }

    fn names(&self, node: Node) -> Res<Vec<LocalName>> {
        self.children(node, "Name")
            .map(|n| {
                Ok(LocalName {
                    lcid: self
                        .attr_num(n, "LcId", 0, u32::MAX.into())?
                        .map(|v| v as u32),
                    text: self.text(n).to_string(),
                })
            })
            .collect()
    }

    fn hex_bytes(&self, node: Node) -> Res<Vec<u8>> {
        let t = self.text(node);
        decode_hex_binary(t).ok_or_else(|| self.err(node, Problem::BadHexBinary(t.to_string())))
    }
}

const U8: i128 = u8::MAX as i128;
const U16: i128 = u16::MAX as i128;
const U32: i128 = u32::MAX as i128;

/// `#x1A00` → 0x1A00, `42` → 42, `-3` → -3. `None` on anything else.
pub(crate) fn parse_number(t: &str) -> Option<i128> {
    let t = t.trim();
    if let Some(h) = t.strip_prefix("#x").or_else(|| t.strip_prefix("#X")) {
        if h.is_empty() || h.len() > 16 || !h.bytes().all(|b| b.is_ascii_hexdigit()) {
            return None;
        }
        return i128::from_str_radix(h, 16).ok();
    }
    let (neg, digits) = match t.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, t),
    };
    if digits.is_empty() || digits.len() > 20 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let v: i128 = digits.parse().ok()?;
    Some(if neg { -v } else { v })
}

/// ETG.2000 hexBinary (`92010200` → [0x92, 0x01, 0x02, 0x00]); whitespace allowed.
fn decode_hex_binary(t: &str) -> Option<Vec<u8>> {
    let digits: Vec<u8> = t.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if !digits.len().is_multiple_of(2) {
        return None;
    }
    digits
        .chunks(2)
        .map(|p| {
            let hi = (p[0] as char).to_digit(16)?;
            let lo = (p[1] as char).to_digit(16)?;
            Some((hi * 16 + lo) as u8)
        })
        .collect()
}

/// `EtherCATInfo/Descriptions/Devices/Device[2]/RxPdo[1]/Entry[3]`: the element names from the
/// root, with a 1-based position where a parent has more than one child of that name.
pub(crate) fn element_path(node: Node) -> String {
    let mut parts: Vec<String> = node
        .ancestors()
        .filter(|n| n.is_element())
        .map(|n| {
            let name = n.tag_name().name();
            let same = |s: &Node| s.is_element() && s.tag_name().name() == name;
            let before = n.prev_siblings().skip(1).filter(same).count();
            let after = n.next_siblings().skip(1).filter(same).count();
            if before + after > 0 {
                format!("{name}[{}]", before + 1)
            } else {
                name.to_string()
            }
        })
        .collect();
    parts.reverse();
    parts.join("/")
}

/// Best-effort path of the elements still open at the end of `text` (`EtherCATInfo/Vendor`),
/// for the message about a truncated file. A plain tag scan: comments, CDATA, processing
/// instructions and declarations are skipped; it is only used when the XML parser has already
/// failed.
pub(crate) fn open_elements(text: &str) -> String {
    let mut stack: Vec<&str> = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find('<') {
        rest = &rest[i..];
        let skip_to = |rest: &str, end: &str| rest.find(end).map(|j| j + end.len());
        let next = if rest.starts_with("<!--") {
            skip_to(rest, "-->")
        } else if rest.starts_with("<![CDATA[") {
            skip_to(rest, "]]>")
        } else if rest.starts_with("<?") {
            skip_to(rest, "?>")
        } else if rest.starts_with("<!") {
            skip_to(rest, ">")
        } else {
            let end = rest.find('>');
            let tag = &rest[1..end.unwrap_or(rest.len())];
            let name_end = tag
                .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
                .unwrap_or(tag.len());
            if let Some(closing) = tag.strip_prefix('/') {
                let name = closing.trim();
                if stack.last() == Some(&name) {
                    stack.pop();
                }
            } else if end.is_some() && !tag.ends_with('/') && name_end > 0 {
                stack.push(&tag[..name_end]);
            } else if end.is_none() && name_end > 0 {
                // cut inside a start tag
                stack.push(&tag[..name_end]);
            }
            end.map(|j| j + 1)
        };
        match next {
            Some(n) => rest = &rest[n..],
            None => break,
        }
    }
    stack.join("/")
}

/// The first start tag with more than `max` attributes: (byte offset of its `<`, its name).
/// A linear scan that runs before the XML parser, whose duplicate-attribute check is quadratic
/// in the number of attributes of one element (100,000 attributes took 18 s). Comments, CDATA,
/// processing instructions and declarations are skipped; quoted attribute values may contain
/// `=` and `>`.
pub(crate) fn too_many_attributes(text: &str, max: usize) -> Option<(usize, &str)> {
    let bytes = text.as_bytes();
    let mut i = 0;
    while let Some(k) = text[i..].find('<') {
        let start = i + k;
        let rest = &text[start..];
        let skip_to = |end: &str| rest.find(end).map(|j| start + j + end.len());
        let next = if rest.starts_with("<!--") {
            skip_to("-->")
        } else if rest.starts_with("<![CDATA[") {
            skip_to("]]>")
        } else if rest.starts_with("<?") {
            skip_to("?>")
        } else if rest.starts_with("<!") || rest.starts_with("</") {
            skip_to(">")
        } else {
            // A start tag: count `=` outside quoted values up to its `>`.
            let mut quote: Option<u8> = None;
            let mut count = 0usize;
            let mut j = start + 1;
            let mut end = None;
            while j < bytes.len() {
                let b = bytes[j];
                match quote {
                    Some(q) if b == q => quote = None,
                    Some(_) => {}
                    None if b == b'"' || b == b'\'' => quote = Some(b),
                    None if b == b'=' => count += 1,
                    None if b == b'>' => {
                        end = Some(j + 1);
                        break;
                    }
                    None => {}
                }
                j += 1;
            }
            if count > max {
                let tag = &text[start + 1..];
                let name_end = tag
                    .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
                    .unwrap_or(tag.len());
                return Some((start, &tag[..name_end]));
            }
            end
        };
        match next {
            Some(n) => i = n,
            None => break,
        }
    }
    None
}

/// Parse a whole document.
pub(crate) fn parse_document(doc: &Document, file: &str) -> Res<EsiFile> {
    let cx = Ctx { doc, file };
    let root = doc.root_element();
    if root.tag_name().name() != "EtherCATInfo" {
        return Err(cx.err(
            root,
            Problem::Unsupported(format!(
                "root element is <{}>, expected <EtherCATInfo>",
                root.tag_name().name()
            )),
        ));
    }
    let vendor = parse_vendor(&cx, cx.require(root, "Vendor")?)?;
    let desc = cx.require(root, "Descriptions")?;
    let mut groups = Vec::new();
    if let Some(g) = cx.child(desc, "Groups") {
        for group in cx.children(g, "Group") {
            groups.push(Group {
                group_type: cx.required_text(group, "Type")?,
                names: cx.names(group)?,
            });
        }
    }
    let devs = cx.require(desc, "Devices")?;
    let devices = cx
        .children(devs, "Device")
        .map(|d| parse_device(&cx, d))
        .collect::<Res<Vec<_>>>()?;
    Ok(EsiFile {
        file: file.to_string(),
        vendor,
        groups,
        devices,
    })
}

fn parse_vendor(cx: &Ctx, v: Node) -> Res<Vendor> {
    Ok(Vendor {
        id: cx.required_num(v, "Id", 0, U32)? as u32,
        name: cx.child_text(v, "Name").unwrap_or_default(),
    })
}

fn parse_device(cx: &Ctx, d: Node) -> Res<Device> {
    let ty = cx.require(d, "Type")?;
    let product_code = cx
        .attr_num(ty, "ProductCode", 0, U32)?
        .ok_or_else(|| cx.err(ty, Problem::MissingAttribute("ProductCode".into())))?
        as u32;
    let revision_no = cx.attr_num(ty, "RevisionNo", 0, U32)?.unwrap_or(0) as u32;

    let fmmus = cx
        .children(d, "Fmmu")
        .map(|f| match cx.text(f) {
            "Outputs" => FmmuKind::Outputs,
            "Inputs" => FmmuKind::Inputs,
            "MBoxState" => FmmuKind::MBoxState,
            other => FmmuKind::Other(other.to_string()),
        })
        .collect();

    let sync_managers = cx
        .children(d, "Sm")
        .map(|sm| parse_sm(cx, sm))
        .collect::<Res<Vec<_>>>()?;
    check_sm_layout(cx, d, cx.text(ty), &sync_managers)?;
    let rx_pdos = cx
        .children(d, "RxPdo")
        .map(|p| parse_pdo(cx, p))
        .collect::<Res<Vec<_>>>()?;
    let tx_pdos = cx
        .children(d, "TxPdo")
        .map(|p| parse_pdo(cx, p))
        .collect::<Res<Vec<_>>>()?;
    let mailbox = cx
        .child(d, "Mailbox")
        .map(|m| parse_mailbox(cx, m))
        .transpose()?;
    let dc_op_modes = match cx.child(d, "Dc") {
        None => Vec::new(),
        Some(dc) => cx
            .children(dc, "OpMode")
            .map(|m| parse_op_mode(cx, m))
            .collect::<Res<Vec<_>>>()?,
    };
    let profile = cx
        .child(d, "Profile")
        .map(|p| parse_profile(cx, p))
        .transpose()?;
    let eeprom = cx
        .child(d, "Eeprom")
        .map(|e| parse_eeprom(cx, e))
        .transpose()?;

    Ok(Device {
        physics: d.attribute("Physics").map(str::to_string),
        type_name: cx.text(ty).to_string(),
        product_code,
        revision_no,
        names: cx.names(d)?,
        group: cx.child_text(d, "GroupType"),
        fmmus,
        sync_managers,
        rx_pdos,
        tx_pdos,
        mailbox,
        dc_op_modes,
        profile,
        eeprom,
    })
}

/// Sync manager channels of an ESC (ETG.1000.4 §6.7: SM0..SM15).
const MAX_SYNC_MANAGERS: usize = 16;

/// Every sync manager's area `[StartAddress, StartAddress + DefaultSize)` lies inside the ESC's
/// 64 KiB address space and no two areas overlap. Sync managers without a size (or size 0)
/// occupy nothing. The error points at the later sync manager and names the device.
fn check_sm_layout(cx: &Ctx, d: Node, device: &str, sms: &[SyncManager]) -> Res<()> {
    let nodes: Vec<Node> = cx.children(d, "Sm").collect();
    if let Some(&extra) = nodes.get(MAX_SYNC_MANAGERS) {
        return Err(cx.err(
            extra,
            Problem::SyncManagerLayout(format!(
                "device {device}: more than {MAX_SYNC_MANAGERS} sync managers (an ESC has at most \
                 {MAX_SYNC_MANAGERS}, ETG.1000.4)"
            )),
        ));
    }
    let area = |sm: &SyncManager| {
        let start = u32::from(sm.start_address);
        (start, start + u32::from(sm.default_size.unwrap_or(0)))
    };
    let name = |i: usize, sm: &SyncManager| format!("SM{i} ({})", sm_kind_name(&sm.kind));
    for (i, sm) in sms.iter().enumerate() {
        let (start, end) = area(sm);
        if end > 0x1_0000 {
            return Err(cx.err(
                nodes[i],
                Problem::SyncManagerLayout(format!(
                    "device {device}: {} at #x{start:04X} with {} bytes ends at #x{end:X}, \
                     beyond the ESC address space (last address #xFFFF)",
                    name(i, sm),
                    end - start
                )),
            ));
        }
        if start == end {
            continue;
        }
        // Quadratic in the sync managers of one device, at most 16 of them.
        for (j, other) in sms.iter().enumerate().take(i) {
            let (o_start, o_end) = area(other);
            if o_start < o_end && start < o_end && o_start < end {
                return Err(cx.err(
                    nodes[i],
                    Problem::SyncManagerLayout(format!(
                        "device {device}: {} (#x{start:04X}..#x{:04X}) overlaps {} \
                         (#x{o_start:04X}..#x{:04X})",
                        name(i, sm),
                        end - 1,
                        name(j, other),
                        o_end - 1
                    )),
                ));
            }
        }
    }
    Ok(())
}

fn sm_kind_name(kind: &SmKind) -> &str {
    match kind {
        SmKind::MBoxOut => "MBoxOut",
        SmKind::MBoxIn => "MBoxIn",
        SmKind::Outputs => "Outputs",
        SmKind::Inputs => "Inputs",
        SmKind::Other(s) => s,
    }
}

fn parse_sm(cx: &Ctx, sm: Node) -> Res<SyncManager> {
    let kind = match cx.text(sm) {
        "MBoxOut" => SmKind::MBoxOut,
        "MBoxIn" => SmKind::MBoxIn,
        "Outputs" => SmKind::Outputs,
        "Inputs" => SmKind::Inputs,
        other => SmKind::Other(other.to_string()),
    };
    let start_address = cx
        .attr_num(sm, "StartAddress", 0, U16)?
        .ok_or_else(|| cx.err(sm, Problem::MissingAttribute("StartAddress".into())))?
        as u16;
    let size = |name| -> Res<Option<u16>> { Ok(cx.attr_num(sm, name, 0, U16)?.map(|v| v as u16)) };
    Ok(SyncManager {
        kind,
        start_address,
        default_size: size("DefaultSize")?,
        min_size: size("MinSize")?,
        max_size: size("MaxSize")?,
        control_byte: cx.attr_num(sm, "ControlByte", 0, U8)?.unwrap_or(0) as u8,
        enable: cx.attr_num(sm, "Enable", 0, U8)?.unwrap_or(0) & 1 == 1,
    })
}

fn parse_pdo(cx: &Ctx, p: Node) -> Res<Pdo> {
    let entries = cx
        .children(p, "Entry")
        .map(|e| parse_entry(cx, e))
        .collect::<Res<Vec<_>>>()?;
    let excludes = cx
        .children(p, "Exclude")
        .map(|e| cx.elem_num(e, 0, U16).map(|v| v as u16))
        .collect::<Res<Vec<_>>>()?;
    Ok(Pdo {
        index: cx.required_num(p, "Index", 0, U16)? as u16,
        name: cx.child_text(p, "Name").unwrap_or_default(),
        sm: cx.attr_num(p, "Sm", 0, U8)?.map(|v| v as u8),
        fixed: cx.attr_bool(p, "Fixed")?,
        mandatory: cx.attr_bool(p, "Mandatory")?,
        excludes,
        entries,
    })
}

fn parse_entry(cx: &Ctx, e: Node) -> Res<PdoEntry> {
    let index = cx.required_num(e, "Index", 0, U16)? as u16;
    Ok(PdoEntry {
        index,
        subindex: cx.child_num(e, "SubIndex", 0, U8)?.unwrap_or(0) as u8,
        bit_len: cx.required_num(e, "BitLen", 0, U16)? as u16,
        name: cx.child_text(e, "Name").filter(|s| !s.is_empty()),
        data_type: cx.child_text(e, "DataType").filter(|s| !s.is_empty()),
    })
}

fn parse_mailbox(cx: &Ctx, m: Node) -> Res<Mailbox> {
    let coe = cx
        .child(m, "CoE")
        .map(|c| -> Res<Coe> {
            Ok(Coe {
                sdo_info: cx.attr_bool(c, "SdoInfo")?,
                pdo_assign: cx.attr_bool(c, "PdoAssign")?,
                pdo_config: cx.attr_bool(c, "PdoConfig")?,
                pdo_upload: cx.attr_bool(c, "PdoUpload")?,
                complete_access: cx.attr_bool(c, "CompleteAccess")?,
                segmented_sdo: cx.attr_bool(c, "SegmentedSdo")?,
            })
        })
        .transpose()?;
    Ok(Mailbox {
        data_link_layer: cx.attr_bool(m, "DataLinkLayer")?,
        coe,
        soe: cx.child(m, "SoE").is_some(),
        eoe: cx.child(m, "EoE").is_some(),
        foe: cx.child(m, "FoE").is_some(),
        aoe: cx.child(m, "AoE").is_some(),
        voe: cx.child(m, "VoE").is_some(),
    })
}

fn parse_op_mode(cx: &Ctx, m: Node) -> Res<DcOpMode> {
    let time = |name: &str| -> Res<Option<DcTime>> {
        match cx.child(m, name) {
            None => Ok(None),
            Some(t) => Ok(Some(DcTime {
                value: cx.elem_num(t, i64::MIN.into(), i64::MAX.into())? as i64,
                factor: cx
                    .attr_num(t, "Factor", i64::MIN.into(), i64::MAX.into())?
                    .map(|v| v as i64),
            })),
        }
    };
    Ok(DcOpMode {
        name: cx.required_text(m, "Name")?,
        desc: cx.child_text(m, "Desc"),
        assign_activate: cx.required_num(m, "AssignActivate", 0, U16)? as u16,
        cycle_time_sync0: time("CycleTimeSync0")?,
        shift_time_sync0: time("ShiftTimeSync0")?,
        cycle_time_sync1: time("CycleTimeSync1")?,
        shift_time_sync1: time("ShiftTimeSync1")?,
    })
}

fn parse_eeprom(cx: &Ctx, e: Node) -> Res<Eeprom> {
    Ok(Eeprom {
        byte_size: cx.child_num(e, "ByteSize", 0, U32)?.map(|v| v as u32),
        config_data: cx
            .child(e, "ConfigData")
            .map(|c| cx.hex_bytes(c))
            .transpose()?,
        boot_strap: cx
            .child(e, "BootStrap")
            .map(|c| cx.hex_bytes(c))
            .transpose()?,
    })
}

fn parse_profile(cx: &Ctx, p: Node) -> Res<Profile> {
    let dictionary = cx
        .child(p, "Dictionary")
        .map(|d| parse_dictionary(cx, d))
        .transpose()?;
    Ok(Profile {
        profile_no: cx.child_num(p, "ProfileNo", 0, U32)?.map(|v| v as u32),
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
                flags: parse_flags(cx, s)?,
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

fn parse_flags(cx: &Ctx, parent: Node) -> Res<Flags> {
    let Some(f) = cx.child(parent, "Flags") else {
        return Ok(Flags::default());
    };
    let access = match cx.child(f, "Access") {
        None => None,
        Some(a) => Some(match cx.text(a) {
            "ro" | "RO" => Access::ReadOnly,
            "rw" | "RW" => Access::ReadWrite,
            "wo" | "WO" => Access::WriteOnly,
            other => return Err(cx.err(a, Problem::BadValue(other.to_string()))),
        }),
    };
    let write_restrictions = cx
        .child(f, "Access")
        .and_then(|a| a.attribute("WriteRestrictions"))
        .map(str::to_string);
    let pdo_mapping = match cx.child(f, "PdoMapping") {
        None => None,
        Some(p) => match cx.text(p).to_ascii_uppercase().as_str() {
            "R" => Some(PdoMapping::Rx),
            "T" => Some(PdoMapping::Tx),
            "RT" | "TR" => Some(PdoMapping::RxTx),
            "" => None,
            _ => return Err(cx.err(p, Problem::BadValue(cx.text(p).to_string()))),
        },
    };
    Ok(Flags {
        access,
        write_restrictions,
        pdo_mapping,
        category: cx.child_text(f, "Category"),
    })
}

fn parse_object(cx: &Ctx, o: Node) -> Res<Object> {
    let info = cx.child(o, "Info");
    let default_data = info
        .and_then(|i| cx.child(i, "DefaultData"))
        .map(|d| cx.hex_bytes(d))
        .transpose()?;
    let subitems = match info {
        None => Vec::new(),
        Some(i) => cx
            .children(i, "SubItem")
            .map(|s| -> Res<ObjectSubItem> {
                Ok(ObjectSubItem {
                    name: cx.child_text(s, "Name").unwrap_or_default(),
                    default_data: cx
                        .child(s, "Info")
                        .and_then(|si| cx.child(si, "DefaultData"))
                        .map(|d| cx.hex_bytes(d))
                        .transpose()?,
                })
            })
            .collect::<Res<Vec<_>>>()?,
    };
    Ok(Object {
        index: cx.required_num(o, "Index", 0, U16)? as u16,
        name: cx.required_text(o, "Name")?,
        type_name: cx.required_text(o, "Type")?,
        bit_size: cx.required_num(o, "BitSize", 0, U32)? as u32,
        default_data,
        flags: parse_flags(cx, o)?,
        subitems,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers() {
        assert_eq!(parse_number("#x1A00"), Some(0x1A00));
        assert_eq!(parse_number("#x1a00"), Some(0x1A00));
        assert_eq!(parse_number("42"), Some(42));
        assert_eq!(parse_number(" -3 "), Some(-3));
        assert_eq!(parse_number("#xZZ"), None);
        assert_eq!(parse_number("#x"), None);
        assert_eq!(parse_number("0x10"), None);
        assert_eq!(parse_number(""), None);
        assert_eq!(parse_number("-"), None);
        assert_eq!(parse_number("#x11112222333344445"), None);
    }

    #[test]
    fn hex_binary() {
        assert_eq!(decode_hex_binary("92010200"), Some(vec![0x92, 1, 2, 0]));
        assert_eq!(decode_hex_binary(""), Some(vec![]));
        assert_eq!(decode_hex_binary("123"), None);
        assert_eq!(decode_hex_binary("zz"), None);
    }

    #[test]
    fn attribute_count_scan() {
        let t =
            r#"<?xml version="1.0"?><!-- a=1 b=2 c=3 --><A x="=" y='>'><B p="1" q="2" r="3"/></A>"#;
        assert_eq!(too_many_attributes(t, 3), None);
        assert_eq!(
            too_many_attributes(t, 2),
            Some((t.find("<B").unwrap(), "B"))
        );
        assert_eq!(too_many_attributes("<![CDATA[<C a=1 b=2>]]><D/>", 1), None);
    }

    #[test]
    fn open_elements_at_cut() {
        assert_eq!(
            open_elements("<?xml?><A><!-- <X> --><B/><C x=\"1\"><D>t</D><E"),
            "A/C/E"
        );
        assert_eq!(open_elements("<A></A>"), "");
        assert_eq!(open_elements("<A><![CDATA[<B>"), "A");
    }

    #[test]
    fn path_names_positions() {
        let doc = Document::parse("<A><B/><B><C/></B></A>").unwrap();
        let c = doc.descendants().find(|n| n.has_tag_name("C")).unwrap();
        assert_eq!(element_path(c), "A/B[2]/C");
    }
}
