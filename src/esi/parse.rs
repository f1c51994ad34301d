//! ETG.2000 XML → [`EsiFile`] with `roxmltree`.
//!
//! What is read how (see also the module docs of [`super`] and of [`super::values`]):
//! * A value the file writes in a form ETG.2000 does not define but that has one reading (C hex
//!   `0x1A00`, `TRUE`, odd-length hexBinary, `-1` in an unsigned field) is read that way with a
//!   warning ([`EsiWarning`](super::EsiWarning)).
//! * An optional value that has no reading (an `Access` text such as `rx`, a `DefaultData` that
//!   is not hex, a `LcId` that is not a number) is left out with a warning.
//! * A value that identifies the device or lays out its process data and has no reading
//!   (`Vendor/Id`, `Type ProductCode` / `RevisionNo`, PDO and entry `Index` / `SubIndex` /
//!   `BitLen`, `Sm StartAddress` / `ControlByte`, a boolean that is none of the forms) is an
//!   error naming file, line, column and element path, as is a missing required element.
//! * Elements the description does not model (images, `Info`, `InitCmd`, `Su`, …) are ignored.

mod dict;
mod modules;

use super::scan::element_path;
use super::values::{self, Fit, Hex};
use super::warn::{Collector, Oddity, Where};
use super::*;
use roxmltree::{Document, Node};
use std::cell::RefCell;
use std::sync::Arc;

/// Parser context: the document (for line numbers), the file name (for messages) and the
/// warnings so far.
struct Ctx<'a, 'input> {
    doc: &'a Document<'input>,
    file: &'a str,
    warnings: RefCell<Collector>,
}

type Res<T> = Result<T, EsiError>;

const U8: i128 = u8::MAX as i128;
const U16: i128 = u16::MAX as i128;
const U32: i128 = u32::MAX as i128;

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

    /// Record a warning about `node`'s text (`attr` `None`) or one of its attributes.
    fn warn(&self, node: Node, attr: Option<&str>, oddity: Oddity) {
        let (offset, name) = match attr.and_then(|a| node.attribute_node(a)) {
            Some(a) => (a.range().start, format!("@{}", a.name())),
            None => (node.range().start, node.tag_name().name().to_string()),
        };
        let path = || match attr {
            Some(a) => format!("{}/@{a}", element_path(node)),
            None => element_path(node),
        };
        let subject = || subject(node);
        self.warnings.borrow_mut().add(
            Where {
                offset,
                name: &name,
                path: &path,
                subject: &subject,
            },
            oddity,
        );
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

    /// Read `t` for a field `[min, max]` of `node` (attribute `attr`): odd forms and two's
    /// complement readings are warned about; `Err` carries the problem when there is no reading.
    fn read_num(
        &self,
        node: Node,
        attr: Option<&str>,
        t: &str,
        min: i128,
        max: i128,
    ) -> Result<i128, Problem> {
        let bad = || match attr {
            Some(a) => Problem::BadAttribute(a.to_string(), t.to_string()),
            None => Problem::BadNumber(t.to_string()),
        };
        let n = values::read_number(t).ok_or_else(bad)?;
        let v = match values::fit(n.value, min, max) {
            Fit::Fits(v) => v,
            Fit::TwosComplement(v) => {
                let oddity = Oddity::TwosComplement {
                    text: t.to_string(),
                    read: v,
                };
                self.warn(node, attr, oddity);
                return Ok(v);
            }
            Fit::OutOfRange => {
                return Err(match attr {
                    Some(_) => bad(),
                    None => Problem::OutOfRange(t.to_string()),
                })
            }
        };
        if n.odd_form {
            let oddity = Oddity::NumberForm {
                text: t.to_string(),
                read: v,
            };
            self.warn(node, attr, oddity);
        }
        Ok(v)
    }

    /// Number in the text of `node`, range-checked to `[min, max]`: an error when unreadable.
    fn elem_num(&self, node: Node, min: i128, max: i128) -> Res<i128> {
        let t = self.text(node);
        self.read_num(node, None, t, min, max)
            .map_err(|p| self.err(node, p))
    }

    /// Number in the text of `node` for an optional field: unreadable → warning, `None`.
    fn elem_opt_num(&self, node: Node, min: i128, max: i128) -> Option<i128> {
        let t = self.text(node);
        match self.read_num(node, None, t, min, max) {
            Ok(v) => Some(v),
            Err(p) => {
                self.left_out(node, None, t, &p, min, max);
                None
            }
        }
    }

    fn left_out(&self, node: Node, attr: Option<&str>, t: &str, p: &Problem, min: i128, max: i128) {
        let why = match p {
            Problem::OutOfRange(_) => format!("is outside {min}..={max}"),
            _ if values::read_number(t).is_some() => format!("is outside {min}..={max}"),
            _ => "is not a number".to_string(),
        };
        let oddity = Oddity::NumberLeftOut {
            text: t.to_string(),
            why,
        };
        self.warn(node, attr, oddity);
    }

    /// Number in the text of a child element, range-checked (unreadable: an error).
    fn child_num(&self, node: Node, name: &str, min: i128, max: i128) -> Res<Option<i128>> {
        match self.child(node, name) {
            None => Ok(None),
            Some(c) => self.elem_num(c, min, max).map(Some),
        }
    }

    /// Number in the text of a child element of an optional field (unreadable: a warning).
    fn child_opt_num(&self, node: Node, name: &str, min: i128, max: i128) -> Option<i128> {
        self.child(node, name)
            .and_then(|c| self.elem_opt_num(c, min, max))
    }

    fn required_num(&self, node: Node, name: &str, min: i128, max: i128) -> Res<i128> {
        let c = self.require(node, name)?;
        self.elem_num(c, min, max)
    }

    /// Number in an attribute, range-checked (unreadable: an error).
    fn attr_num(&self, node: Node, name: &str, min: i128, max: i128) -> Res<Option<i128>> {
        let Some(a) = node.attribute_node(name) else {
            return Ok(None);
        };
        self.read_num(node, Some(name), a.value().trim(), min, max)
            .map(Some)
            .map_err(|p| self.err_at(node, a.range().start, p))
    }

    /// Number in an attribute of an optional field (unreadable: a warning, `None`).
    fn attr_opt_num(&self, node: Node, name: &str, min: i128, max: i128) -> Option<i128> {
        let a = node.attribute_node(name)?;
        let t = a.value().trim();
        match self.read_num(node, Some(name), t, min, max) {
            Ok(v) => Some(v),
            Err(p) => {
                self.left_out(node, Some(name), t, &p, min, max);
                None
            }
        }
    }

    /// A boolean attribute (false when absent); `TRUE`, `yes`, … with a warning; a text that
    /// is no boolean form is an error.
    fn attr_bool(&self, node: Node, name: &str) -> Res<bool> {
        let Some(a) = node.attribute_node(name) else {
            return Ok(false);
        };
        match values::read_bool(a.value()) {
            Some((v, false)) => Ok(v),
            Some((v, true)) => {
                let oddity = Oddity::Boolean {
                    text: a.value().to_string(),
                    read: v,
                };
                self.warn(node, Some(name), oddity);
                Ok(v)
            }
            None => Err(self.err_at(
                node,
                a.range().start,
                Problem::BadAttribute(name.to_string(), a.value().trim().to_string()),
            )),
        }
    }

    fn names(&self, node: Node) -> Vec<LocalName> {
        self.children(node, "Name")
            .map(|n| LocalName {
                lcid: self.attr_opt_num(n, "LcId", 0, U32).map(|v| v as u32),
                text: self.text(n).to_string(),
            })
            .collect()
    }

    /// hexBinary of an optional value: odd length read with a leading 0 nibble (warning), not
    /// hex: left out (warning).
    fn hex_bytes(&self, node: Node) -> Option<Vec<u8>> {
        let t = self.text(node);
        match values::read_hex_binary(t) {
            Hex::Bytes(b) => Some(b),
            Hex::Odd(b) => {
                let oddity = Oddity::OddHexBinary {
                    text: t.to_string(),
                    read: b.clone(),
                };
                self.warn(node, None, oddity);
                Some(b)
            }
            Hex::Bad => {
                self.warn(
                    node,
                    None,
                    Oddity::NotHexBinary {
                        text: t.to_string(),
                    },
                );
                None
            }
        }
    }

    /// `DependOnSlot` of an `Index` element.
    fn depends_on_slot(&self, index: Option<Node>) -> Res<bool> {
        index.map_or(Ok(false), |i| self.attr_bool(i, "DependOnSlot"))
    }
}

/// What the value at `node` belongs to, as written in the file: `device LC10E, object #x2001
/// SubItem[2]` (the second `Info/SubItem`). Ancestors only; small.
fn subject(node: Node) -> Option<String> {
    let text_of = |n: Node, tag: &str| {
        n.children()
            .find(|c| c.has_tag_name(tag))
            .and_then(|c| c.text())
            .map(|t| t.trim().to_string())
    };
    let mut parts: Vec<String> = Vec::new();
    let mut sub_item: Option<usize> = None;
    for a in node.ancestors().filter(|n| n.is_element()) {
        let tag = a.tag_name().name();
        match tag {
            "SubItem"
                if sub_item.is_none() && a.parent().is_some_and(|p| p.has_tag_name("Info")) =>
            {
                // 1-based position among the SubItems (prev_siblings starts with the node)
                let k = a
                    .prev_siblings()
                    .filter(|s| s.has_tag_name("SubItem"))
                    .count();
                sub_item = Some(k);
            }
            "Object" => {
                let mut s = format!("object {}", text_of(a, "Index").unwrap_or_default());
                if let Some(k) = sub_item {
                    s.push_str(&format!(" SubItem[{k}]"));
                }
                parts.push(s);
            }
            "RxPdo" | "TxPdo" => {
                parts.push(format!("{tag} {}", text_of(a, "Index").unwrap_or_default()));
            }
            "DataType" => parts.push(format!(
                "data type {}",
                text_of(a, "Name").unwrap_or_default()
            )),
            "Device" | "Module" => {
                parts.push(format!(
                    "{} {}",
                    tag.to_ascii_lowercase(),
                    text_of(a, "Type").unwrap_or_default()
                ));
            }
            _ => {}
        }
    }
    parts.reverse();
    (!parts.is_empty()).then(|| parts.join(", "))
}

/// Parse a whole document.
pub(crate) fn parse_document(doc: &Document, file: &str) -> Res<EsiFile> {
    let cx = Ctx {
        doc,
        file,
        warnings: RefCell::new(Collector::default()),
    };
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
                names: cx.names(group),
            });
        }
    }
    let modules: Vec<Arc<Module>> = match cx.child(desc, "Modules") {
        None => Vec::new(),
        Some(m) => modules::parse_modules(&cx, m)?,
    };
    let index = modules::ModuleIndex::new(&modules);
    let devs = cx.require(desc, "Devices")?;
    let devices = cx
        .children(devs, "Device")
        .map(|d| parse_device(&cx, d, &modules, &index))
        .collect::<Res<Vec<_>>>()?;
    let warnings = cx.warnings.into_inner().finish(doc.input_text(), file);
    Ok(EsiFile {
        file: file.to_string(),
        vendor,
        groups,
        devices,
        modules,
        warnings,
    })
}

fn parse_vendor(cx: &Ctx, v: Node) -> Res<Vendor> {
    Ok(Vendor {
        id: cx.required_num(v, "Id", 0, U32)? as u32,
        name: cx.child_text(v, "Name").unwrap_or_default(),
    })
}

fn parse_device(
    cx: &Ctx,
    d: Node,
    file_modules: &[Arc<Module>],
    index: &modules::ModuleIndex,
) -> Res<Device> {
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
    let rx_pdos = parse_pdos(cx, d, "RxPdo")?;
    let tx_pdos = parse_pdos(cx, d, "TxPdo")?;
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
    let profile = dict::parse_profiles(cx, d)?;
    let eeprom = cx.child(d, "Eeprom").map(|e| parse_eeprom(cx, e));
    let slots_node = cx.child(d, "Slots");
    let slots = slots_node
        .map(|s| modules::parse_slots(cx, s))
        .transpose()?;
    let modules = match (slots_node, &slots) {
        (Some(n), Some(s)) => modules::slot_modules(cx, n, s, file_modules, index)?,
        _ => Vec::new(),
    };

    Ok(Device {
        physics: d.attribute("Physics").map(str::to_string),
        type_name: cx.text(ty).to_string(),
        product_code,
        revision_no,
        names: cx.names(d),
        group: cx.child_text(d, "GroupType"),
        fmmus,
        sync_managers,
        rx_pdos,
        tx_pdos,
        mailbox,
        dc_op_modes,
        profile,
        eeprom,
        slots,
        modules,
        plugged: None,
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
    let size = |name| cx.attr_opt_num(sm, name, 0, U16).map(|v| v as u16);
    // `Enable` is a number (bit 0 used); `true` / `false` are read as 1 / 0 with a warning
    let enable = match sm.attribute("Enable") {
        Some(t) if values::read_number(t).is_none() && values::read_bool(t).is_some() => {
            let on = values::read_bool(t).is_some_and(|(on, _)| on);
            let oddity = Oddity::Boolean {
                text: t.to_string(),
                read: on,
            };
            cx.warn(sm, Some("Enable"), oddity);
            on
        }
        _ => cx.attr_num(sm, "Enable", 0, U8)?.unwrap_or(0) & 1 == 1,
    };
    Ok(SyncManager {
        kind,
        start_address,
        default_size: size("DefaultSize"),
        min_size: size("MinSize"),
        max_size: size("MaxSize"),
        control_byte: cx.attr_num(sm, "ControlByte", 0, U8)?.unwrap_or(0) as u8,
        enable,
    })
}

/// The `RxPdo` / `TxPdo` children of a device or module.
fn parse_pdos(cx: &Ctx, parent: Node, tag: &'static str) -> Res<Vec<Pdo>> {
    cx.children(parent, tag).map(|p| parse_pdo(cx, p)).collect()
}

fn parse_pdo(cx: &Ctx, p: Node) -> Res<Pdo> {
    let entries = cx
        .children(p, "Entry")
        .map(|e| parse_entry(cx, e))
        .collect::<Res<Vec<_>>>()?;
    let excludes = cx
        .children(p, "Exclude")
        .filter_map(|e| cx.elem_opt_num(e, 0, U16).map(|v| v as u16))
        .collect();
    let index = cx.require(p, "Index")?;
    Ok(Pdo {
        index: cx.elem_num(index, 0, U16)? as u16,
        name: cx.child_text(p, "Name").unwrap_or_default(),
        sm: cx.attr_num(p, "Sm", 0, U8)?.map(|v| v as u8),
        fixed: cx.attr_bool(p, "Fixed")?,
        mandatory: cx.attr_bool(p, "Mandatory")?,
        excludes,
        entries,
        depend_on_slot: cx.depends_on_slot(Some(index))?,
    })
}

fn parse_entry(cx: &Ctx, e: Node) -> Res<PdoEntry> {
    let index = cx.require(e, "Index")?;
    Ok(PdoEntry {
        index: cx.elem_num(index, 0, U16)? as u16,
        subindex: cx.child_num(e, "SubIndex", 0, U8)?.unwrap_or(0) as u8,
        bit_len: cx.required_num(e, "BitLen", 0, U16)? as u16,
        name: cx.child_text(e, "Name").filter(|s| !s.is_empty()),
        data_type: cx.child_text(e, "DataType").filter(|s| !s.is_empty()),
        depend_on_slot: cx.depends_on_slot(Some(index))?,
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
    const I64: (i128, i128) = (i64::MIN as i128, i64::MAX as i128);
    let time = |name: &str| -> Option<DcTime> {
        let t = cx.child(m, name)?;
        Some(DcTime {
            value: cx.elem_opt_num(t, I64.0, I64.1)? as i64,
            factor: cx.attr_opt_num(t, "Factor", I64.0, I64.1).map(|v| v as i64),
        })
    };
    Ok(DcOpMode {
        name: cx.required_text(m, "Name")?,
        desc: cx.child_text(m, "Desc"),
        assign_activate: cx.required_num(m, "AssignActivate", 0, U16)? as u16,
        cycle_time_sync0: time("CycleTimeSync0"),
        shift_time_sync0: time("ShiftTimeSync0"),
        cycle_time_sync1: time("CycleTimeSync1"),
        shift_time_sync1: time("ShiftTimeSync1"),
    })
}

fn parse_eeprom(cx: &Ctx, e: Node) -> Eeprom {
    Eeprom {
        byte_size: cx.child_opt_num(e, "ByteSize", 0, U32).map(|v| v as u32),
        config_data: cx.child(e, "ConfigData").and_then(|c| cx.hex_bytes(c)),
        boot_strap: cx.child(e, "BootStrap").and_then(|c| cx.hex_bytes(c)),
    }
}
