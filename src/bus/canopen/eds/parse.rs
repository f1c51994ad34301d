//! The interpretation of the INI sections ([`super::ini`]) as an EDS / DCF (CiA 306 §4 – §6),
//! lenient: every problem a vendor's file can have is a warning ([`Parser::soft`]) that says
//! what is read instead, and the rest of the file is read. Only a file with no object section
//! at all is refused (it is no EDS), besides reading errors. [`super::ParseOptions::strict`]
//! turns the first warning into the error.
//!
//! What is read instead (besides the values, [`super::lenient`]):
//! * a header number (`FileVersion`, `VendorNumber` …) that does not parse: left out;
//! * a flag (`PDOMapping`, `SimpleBootUpSlave`, `BaudRate_…`) other than 0 / 1: a number ≠ 0
//!   or `TRUE` / `YES` is 1, anything else 0;
//! * no `[MandatoryObjects]`, no `SupportedObjects`: the objects come from their sections, the
//!   list from its numbered keys;
//! * `ObjectType` unknown: VAR, or RECORD where the section has `SubNumber`;
//! * `DataType` missing or unreadable on a VAR or sub-index: the entry is left out (nothing
//!   can be read or written without its size); a reserved `DataType` code: DOMAIN (a byte
//!   string); a type CiA 301 fixes (0x1000 / 0x1001 / 0x1017) declared otherwise: CiA 301's;
//! * `AccessType` missing: `rw`; unknown: `rw` when it has a `w` and an `r`, `wo` with only a
//!   `w`, else `ro`;
//! * `SubNumber` missing or not the number of sub-index sections present: the sections present;
//!   a sub-index section without its object, for a VAR, or given twice: ignored (the first
//!   counts); `CompactSubObj` on a non-ARRAY or together with `SubNumber`: ignored;
//! * a device type 0x1000 without a value, or whose profile number (bits 0 … 15) is no CiA
//!   device profile (CiA 401 … 4xx; 0 = none): read as written (0 without a value) — the node
//!   reports what its file says — with a warning (e.g. bytes that look swapped).

use std::collections::BTreeMap;

use super::ini::{lex, Key, Section};
use super::lenient::ValueRole;
use super::warning::{fold, EdsWarning};
use super::{
    parse_u64, AccessType, DataType, DeviceCommissioning, DeviceInfo, Eds, EdsError, EdsErrorKind,
    Entry, FileInfo, IntExpr, ObjectHeader, ObjectLists, ObjectType, ParseOptions, ValueError,
    ValueText,
};

pub(super) struct Parser<'f> {
    file: &'f str,
    options: ParseOptions,
    warnings: Vec<EdsWarning>,
}

impl Parser<'_> {
    pub fn err(
        &self,
        kind: EdsErrorKind,
        line: Option<usize>,
        section: Option<&str>,
        key: Option<&str>,
        column: Option<usize>,
        message: impl Into<String>,
    ) -> EdsError {
        let narrow = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
        EdsError {
            file: self.file.to_string(),
            line: line.map(narrow),
            column: column.map(narrow),
            section: section.map(str::to_string),
            key: key.map(str::to_string),
            kind,
            message: message.into(),
        }
    }

    fn key_err(
        &self,
        kind: EdsErrorKind,
        s: &Section,
        k: &Key,
        message: impl Into<String>,
    ) -> EdsError {
        self.err(
            kind,
            Some(k.line),
            Some(s.name),
            Some(k.name),
            Some(k.column),
            message,
        )
    }

    /// Records a warning (`used`: what is read instead), or fails in strict mode.
    pub fn soft(
        &mut self,
        e: EdsError,
        object: Option<(u16, u8)>,
        used: Option<String>,
    ) -> Result<(), EdsError> {
        if self.options.strict {
            Err(e)
        } else {
            self.warnings.push(EdsWarning::new(e, object, used));
            Ok(())
        }
    }

    /// An unsigned header number; an unreadable or too large one is a warning and `None`.
    fn number<T: TryFrom<u64>>(&mut self, s: &Section, k: &Key) -> Result<Option<T>, EdsError> {
        let (v, odd) = match parse_u64(k.value) {
            Some(v) => (v, None),
            None => {
                let lenient = IntExpr::parse_lenient(k.value)
                    .filter(|(e, _)| !e.uses_node_id())
                    .and_then(|(e, form)| u64::try_from(e.eval(0)).ok().map(|v| (v, form)));
                match lenient {
                    Some((v, form)) => (v, Some(form)),
                    None => {
                        let e = self.key_err(
                            EdsErrorKind::BadNumber,
                            s,
                            k,
                            format!("bad number {:?}", k.value),
                        );
                        self.soft(e, None, Some("ignored".into()))?;
                        return Ok(None);
                    }
                }
            }
        };
        match T::try_from(v) {
            Ok(t) => {
                if let Some(form) = odd {
                    let e = self.key_err(
                        EdsErrorKind::BadNumber,
                        s,
                        k,
                        format!("bad number {:?}", k.value),
                    );
                    let how = form.unwrap_or_else(|| "odd number form".into());
                    self.soft(e, None, Some(format!("{how}; read as {v}")))?;
                }
                Ok(Some(t))
            }
            Err(_) => {
                let e = self.key_err(
                    EdsErrorKind::BadNumber,
                    s,
                    k,
                    format!("{} is too large (max {})", k.value, type_max::<T>()),
                );
                self.soft(e, None, Some("ignored".into()))?;
                Ok(None)
            }
        }
    }

    /// An optional number: a key that is missing or has an empty value (`VendorNumber=`, as
    /// CANopenNode's own `DS301_profile.eds` has it) is absent, without a warning (CiA 306
    /// makes these header entries optional).
    fn opt_number<T: TryFrom<u64>>(
        &mut self,
        s: &Section,
        key: &str,
    ) -> Result<Option<T>, EdsError> {
        match s.get(key) {
            Some(k) if !k.value.trim().is_empty() => self.number(s, k),
            _ => Ok(None),
        }
    }

    /// A 0 / 1 flag; anything else is a warning (module documentation). A missing key or an
    /// empty value is 0.
    fn flag(&mut self, s: &Section, key: &str) -> Result<bool, EdsError> {
        let Some(k) = s.get(key).filter(|k| !k.value.trim().is_empty()) else {
            return Ok(false);
        };
        let word = k.value.trim().to_ascii_lowercase();
        let (read, e) = match parse_u64(k.value) {
            Some(0) => return Ok(false),
            Some(1) => return Ok(true),
            Some(_) => (
                true,
                self.key_err(
                    EdsErrorKind::BadValue,
                    s,
                    k,
                    format!("expected 0 or 1, got {:?}", k.value),
                ),
            ),
            None => (
                matches!(word.as_str(), "true" | "yes" | "on"),
                self.key_err(
                    EdsErrorKind::BadNumber,
                    s,
                    k,
                    format!("bad number {:?} (allowed: 0, 1)", k.value),
                ),
            ),
        };
        self.soft(e, None, Some(format!("read as {}", u8::from(read))))?;
        Ok(read)
    }
}

fn type_max<T: TryFrom<u64>>() -> u64 {
    // Largest of the maxima of u8, u16, u32, u64 that converts to T, for messages.
    [u8::MAX as u64, u16::MAX as u64, u32::MAX as u64, u64::MAX]
        .into_iter()
        .take_while(|&m| T::try_from(m).is_ok())
        .last()
        .unwrap_or(0)
}

/// An optional text; an empty value is an absent one, as for [`Parser::opt_number`].
fn key_text(s: &Section, key: &str) -> Option<String> {
    s.get(key)
        .map(|k| k.value.to_string())
        .filter(|v| !v.trim().is_empty())
}

/// The kind of an object-related section name.
enum SectionName {
    Object(u16),
    Sub(u16, u8),
    Names(u16),
    Values(u16),
    Denotations(u16),
    Other,
}

fn classify(name: &str) -> Result<SectionName, String> {
    let Some(head) = name.get(..4) else {
        return Ok(SectionName::Other);
    };
    if !head.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Ok(SectionName::Other);
    }
    let index = u16::from_str_radix(head, 16).map_err(|e| e.to_string())?;
    let tail = &name[4..];
    if tail.is_empty() {
        return Ok(SectionName::Object(index));
    }
    let lower = tail.to_ascii_lowercase();
    if let Some(sub) = lower.strip_prefix("sub") {
        if sub.is_empty() || sub.len() > 2 || !sub.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(format!(
                "bad sub-index {sub:?} (expected 1 or 2 hex digits)"
            ));
        }
        return Ok(SectionName::Sub(
            index,
            u8::from_str_radix(sub, 16).map_err(|e| e.to_string())?,
        ));
    }
    Ok(match lower.as_str() {
        "name" => SectionName::Names(index),
        "value" => SectionName::Values(index),
        "denotation" => SectionName::Denotations(index),
        _ => SectionName::Other,
    })
}

/// Sections this parser reads besides the objects.
const KNOWN: [&str; 9] = [
    "FileInfo",
    "DeviceInfo",
    "DummyUsage",
    "Comments",
    "MandatoryObjects",
    "OptionalObjects",
    "ManufacturerObjects",
    "DeviceComissioning",
    "DeviceCommissioning",
];

/// [`super::parse_with`].
pub(super) fn run(text: &str, file: &str, options: ParseOptions) -> Result<Eds, EdsError> {
    let mut p = Parser {
        file,
        options,
        warnings: Vec::new(),
    };
    let sections = lex(text, &mut p)?;
    let find = |name: &str| sections.iter().find(|s| s.name.eq_ignore_ascii_case(name));

    let mut eds = Eds {
        file: file.to_string(),
        file_info: FileInfo::default(),
        device_info: DeviceInfo::default(),
        dummy_usage: BTreeMap::new(),
        comments: Vec::new(),
        object_lists: ObjectLists::default(),
        object_headers: BTreeMap::new(),
        objects: BTreeMap::new(),
        commissioning: None,
        other_sections: BTreeMap::new(),
        warnings: Vec::new(),
    };

    if let Some(s) = find("FileInfo") {
        eds.file_info = FileInfo {
            file_name: key_text(s, "FileName"),
            file_version: p.opt_number(s, "FileVersion")?,
            file_revision: p.opt_number(s, "FileRevision")?,
            eds_version: key_text(s, "EDSVersion"),
            description: key_text(s, "Description"),
            creation_time: key_text(s, "CreationTime"),
            creation_date: key_text(s, "CreationDate"),
            created_by: key_text(s, "CreatedBy"),
            modification_time: key_text(s, "ModificationTime"),
            modification_date: key_text(s, "ModificationDate"),
            modified_by: key_text(s, "ModifiedBy"),
        };
    }
    if let Some(s) = find("DeviceInfo") {
        eds.device_info = device_info(&mut p, s)?;
    }
    if let Some(s) = find("DummyUsage") {
        for k in &s.keys {
            let Some(n) = k
                .name
                .get(5..)
                .filter(|_| k.name[..5].eq_ignore_ascii_case("dummy"))
            else {
                continue;
            };
            let Ok(index) = u16::from_str_radix(n, 16) else {
                continue;
            };
            let on = p.flag(s, k.name)?;
            eds.dummy_usage.insert(index, on);
        }
    }
    if let Some(s) = find("Comments") {
        let lines: u32 = p.opt_number(s, "Lines")?.unwrap_or(0);
        for i in 1..=lines.min(10_000) {
            eds.comments
                .push(key_text(s, &format!("Line{i}")).unwrap_or_default());
        }
    }
    for name in ["DeviceComissioning", "DeviceCommissioning"] {
        if let Some(s) = find(name) {
            eds.commissioning = Some(DeviceCommissioning {
                node_id: p.opt_number(s, "NodeID")?,
                node_name: key_text(s, "NodeName"),
                baud_rate: p.opt_number(s, "Baudrate")?,
                net_number: p.opt_number(s, "NetNumber")?,
                network_name: key_text(s, "NetworkName"),
                canopen_manager: p.flag(s, "CANopenManager")?,
                lss_serial_number: p.opt_number(s, "LSS_SerialNumber")?,
            });
        }
    }

    // Object lists.
    match find("MandatoryObjects") {
        Some(s) => eds.object_lists.mandatory = object_list(&mut p, s)?,
        None => {
            let e = p.err(
                EdsErrorKind::MissingSection,
                None,
                Some("MandatoryObjects"),
                None,
                None,
                "missing section",
            );
            p.soft(
                e,
                None,
                Some("the objects are read from their sections".into()),
            )?;
        }
    }
    if let Some(s) = find("OptionalObjects") {
        eds.object_lists.optional = object_list(&mut p, s)?;
    }
    if let Some(s) = find("ManufacturerObjects") {
        eds.object_lists.manufacturer = object_list(&mut p, s)?;
    }

    // Object sections, then subs (a sub may come before its object in the file).
    let mut subs: Vec<(u16, u8, &Section)> = Vec::new();
    let mut extras: Vec<(SectionName, &Section)> = Vec::new();
    let mut by_index: BTreeMap<u16, &Section> = BTreeMap::new();
    for s in &sections {
        let kind = match classify(s.name) {
            Ok(kind) => kind,
            Err(m) => {
                let e = p.err(
                    EdsErrorKind::Syntax,
                    Some(s.line),
                    Some(s.name),
                    None,
                    None,
                    m,
                );
                p.soft(e, None, Some("the section is ignored".into()))?;
                continue;
            }
        };
        match kind {
            SectionName::Object(index) => {
                if let Some(first) = by_index.get(&index) {
                    let e = p.err(
                        EdsErrorKind::DuplicateSection,
                        Some(s.line),
                        Some(s.name),
                        None,
                        None,
                        format!("same object as [{}] at line {}", first.name, first.line),
                    );
                    p.soft(
                        e,
                        Some((index, 0)),
                        Some("ignored, the first counts".into()),
                    )?;
                    continue;
                }
                by_index.insert(index, s);
            }
            SectionName::Sub(index, sub) => subs.push((index, sub, s)),
            SectionName::Other => {
                if !KNOWN.iter().any(|n| n.eq_ignore_ascii_case(s.name)) {
                    let keys = s
                        .keys
                        .iter()
                        .map(|k| (k.name.to_string(), k.value.to_string()))
                        .collect();
                    eds.other_sections.insert(s.name.to_string(), keys);
                }
            }
            other => extras.push((other, s)),
        }
    }
    if by_index.is_empty() {
        return Err(p.err(
            EdsErrorKind::MissingSection,
            None,
            None,
            None,
            None,
            "no object section ([1000], [1018] …): not an EDS or DCF (CiA 306)",
        ));
    }
    for (&index, s) in &by_index {
        object(&mut p, &mut eds, index, s)?;
    }
    subs_of(&mut p, &mut eds, &subs)?;
    sub_numbers(&mut p, &eds, &by_index)?;
    compact_extras(&mut p, &mut eds, extras)?;
    lists_against_sections(&mut p, &eds, &by_index, &sections)?;
    device_type(&mut p, &eds)?;
    eds.warnings = fold(p.warnings);
    Ok(eds)
}

/// Sub-index sections into their objects.
fn subs_of(p: &mut Parser, eds: &mut Eds, subs: &[(u16, u8, &Section)]) -> Result<(), EdsError> {
    let mut sub_lines: BTreeMap<(u16, u8), (&str, usize)> = BTreeMap::new();
    for &(index, sub, s) in subs {
        let ignored = Some("the section is ignored".to_string());
        let Some(header) = eds.object_headers.get(&index) else {
            let e = p.err(
                EdsErrorKind::MissingSection,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!("sub-index section without its object section [{index:04X}]"),
            );
            p.soft(e, Some((index, sub)), ignored)?;
            continue;
        };
        if !header.object_type.has_subs() || header.compact_sub_obj.is_some() {
            let e = p.err(
                EdsErrorKind::BadValue,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!(
                    "sub-index section for an object that has none (ObjectType {:#x}{})",
                    header.object_type.code(),
                    if header.compact_sub_obj.is_some() {
                        ", CompactSubObj"
                    } else {
                        ""
                    }
                ),
            );
            p.soft(e, Some((index, sub)), ignored)?;
            continue;
        }
        if let Some(&(name, line)) = sub_lines.get(&(index, sub)) {
            let e = p.err(
                EdsErrorKind::DuplicateSection,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!("same sub-index as [{name}] at line {line}"),
            );
            p.soft(
                e,
                Some((index, sub)),
                Some("ignored, the first counts".into()),
            )?;
            continue;
        }
        sub_lines.insert((index, sub), (s.name, s.line));
        if let Some(entry) = entry(p, s, index, sub, None)? {
            eds.objects.insert((index, sub), entry);
        }
    }
    Ok(())
}

/// `SubNumber` against the sub-index sections present.
fn sub_numbers(
    p: &mut Parser,
    eds: &Eds,
    by_index: &BTreeMap<u16, &Section>,
) -> Result<(), EdsError> {
    for (&index, &s) in by_index {
        let Some(header) = eds.object_headers.get(&index) else {
            continue;
        };
        let present = eds.subs(index).count();
        let used = Some(format!(
            "the {present} sub-index section{} present {} read",
            if present == 1 { "" } else { "s" },
            if present == 1 { "is" } else { "are" }
        ));
        match (
            header.object_type.has_subs(),
            header.sub_number,
            header.compact_sub_obj,
        ) {
            (true, None, None) if s.get("SubNumber").is_none() => {
                let e = p.err(
                    EdsErrorKind::MissingKey,
                    Some(s.line),
                    Some(s.name),
                    Some("SubNumber"),
                    None,
                    "missing; required for an ARRAY or RECORD without CompactSubObj",
                );
                p.soft(e, Some((index, 0)), used)?;
            }
            (true, Some(n), None) if usize::from(n) != present => {
                let Some(k) = s.get("SubNumber") else {
                    continue;
                };
                let e = p.key_err(
                    EdsErrorKind::SubNumberMismatch,
                    s,
                    k,
                    format!(
                        "SubNumber={} but {present} sub-index sections are present",
                        k.value
                    ),
                );
                p.soft(e, Some((index, 0)), used)?;
            }
            _ => {}
        }
    }
    Ok(())
}

/// `[xxxxName]` / `[xxxxValue]` / `[xxxxDenotation]` of compact objects.
fn compact_extras(
    p: &mut Parser,
    eds: &mut Eds,
    extras: Vec<(SectionName, &Section)>,
) -> Result<(), EdsError> {
    for (kind, s) in extras {
        let (index, what) = match kind {
            SectionName::Names(i) => (i, "Name"),
            SectionName::Values(i) => (i, "Value"),
            SectionName::Denotations(i) => (i, "Denotation"),
            _ => continue,
        };
        let compact = eds
            .object_headers
            .get(&index)
            .and_then(|h| h.compact_sub_obj);
        let Some(n) = compact else {
            let e = p.err(
                EdsErrorKind::ObjectList,
                Some(s.line),
                Some(s.name),
                None,
                None,
                format!("[{index:04X}{what}] for an object without CompactSubObj; ignored"),
            );
            p.soft(e, Some((index, 0)), None)?;
            continue;
        };
        for k in &s.keys {
            if k.name.eq_ignore_ascii_case("NrOfEntries") {
                p.number::<u8>(s, k)?;
                continue;
            }
            let Some(sub) = k
                .name
                .parse::<u8>()
                .ok()
                .filter(|&sub| sub >= 1 && sub <= n)
            else {
                let e = p.key_err(
                    EdsErrorKind::BadValue,
                    s,
                    k,
                    format!("expected a sub-index 1..={n}"),
                );
                p.soft(e, Some((index, 0)), Some("ignored".into()))?;
                continue;
            };
            let Some(data_type) = eds.objects.get(&(index, sub)).map(|e| e.data_type) else {
                continue;
            };
            if what == "Value" {
                check_value(p, s, k, data_type, ValueRole::Value, (index, sub))?;
            }
            let Some(e) = eds.objects.get_mut(&(index, sub)) else {
                continue;
            };
            match what {
                "Name" => e.parameter_name = k.value.to_string(),
                "Denotation" => e.denotation = Some(k.value.to_string()),
                _ => {
                    e.parameter_value = Some(ValueText {
                        raw: k.value.to_string(),
                        line: k.line,
                    });
                }
            }
        }
    }
    Ok(())
}

/// The object lists against the object sections.
fn lists_against_sections(
    p: &mut Parser,
    eds: &Eds,
    by_index: &BTreeMap<u16, &Section>,
    sections: &[Section],
) -> Result<(), EdsError> {
    let find = |name: &str| sections.iter().find(|s| s.name.eq_ignore_ascii_case(name));
    let mut listed: BTreeMap<u16, ()> = BTreeMap::new();
    for (list, name) in [
        (&eds.object_lists.mandatory, "MandatoryObjects"),
        (&eds.object_lists.optional, "OptionalObjects"),
        (&eds.object_lists.manufacturer, "ManufacturerObjects"),
    ] {
        let s = find(name);
        for (i, &index) in list.iter().enumerate() {
            listed.insert(index, ());
            if !by_index.contains_key(&index) {
                let key = (i + 1).to_string();
                let k = s.and_then(|s| s.get(&key));
                let e = p.err(
                    EdsErrorKind::MissingSection,
                    k.map(|k| k.line),
                    Some(name),
                    Some(&key),
                    k.map(|k| k.column),
                    format!("object 0x{index:04X} is listed but has no section [{index:04X}]"),
                );
                p.soft(e, Some((index, 0)), None)?;
            }
        }
    }
    for (&index, s) in by_index {
        if !listed.contains_key(&index) && index > 0x0FFF {
            let e = p.err(
                EdsErrorKind::ObjectList,
                Some(s.line),
                Some(s.name),
                None,
                None,
                "object is in no object list",
            );
            p.soft(e, Some((index, 0)), None)?;
        }
    }
    Ok(())
}

/// CiA device profile numbers (bits 0 … 15 of 0x1000): 0 = none, the CiA 4xx profiles.
fn is_profile(number: u32) -> bool {
    number == 0 || (301..=499).contains(&number)
}

/// 0x1000 device type: no value, or a profile number that is none (module documentation).
fn device_type(p: &mut Parser, eds: &Eds) -> Result<(), EdsError> {
    let Some(e) = eds.get(0x1000, 0) else {
        return Ok(());
    };
    let given = e.parameter_value.as_ref().or(e.default.as_ref());
    let Some(text) = given else {
        let err = p.err(
            EdsErrorKind::DeviceType,
            Some(e.line),
            Some("1000"),
            Some("DefaultValue"),
            None,
            "device type without a value",
        );
        return p.soft(
            err,
            Some((0x1000, 0)),
            Some(
                "read as 0x00000000 (no device profile): a node built from the file reports that"
                    .into(),
            ),
        );
    };
    let Some(v) = e.value(eds.node_id().unwrap_or(0)).and_then(|v| v.as_u64()) else {
        return Ok(());
    };
    let v = v as u32;
    let profile = v & 0xFFFF;
    if is_profile(profile) {
        return Ok(());
    }
    // CiA 402's profile number 0x0192 among the bytes in another order.
    let bytes = v.to_le_bytes();
    let hint = match (
        bytes.contains(&0x01),
        bytes.iter().find(|&&b| (0x91..=0xF3).contains(&b)),
    ) {
        (true, Some(&lo)) => format!(
            "; its bytes hold {lo:#04X} and 0x01, profile {} (0x01{lo:02X}) in another order: \
             the byte order looks swapped",
            0x100 | u32::from(lo)
        ),
        _ => String::new(),
    };
    let key = if e.parameter_value.is_some() {
        "ParameterValue"
    } else {
        "DefaultValue"
    };
    let err = p.err(
        EdsErrorKind::DeviceType,
        Some(text.line),
        Some("1000"),
        Some(key),
        None,
        format!(
            "device type {v:#010X} names device profile {profile} (bits 0 … 15), no CiA device \
             profile (CiA 401 … 4xx; 0 = none){hint}"
        ),
    );
    p.soft(
        err,
        Some((0x1000, 0)),
        Some(format!(
            "read as written: a node built from the file reports {v:#010X}"
        )),
    )
}

fn device_info(p: &mut Parser, s: &Section) -> Result<DeviceInfo, EdsError> {
    let mut baud_rates = Vec::new();
    for k in &s.keys {
        let Some(rate) = k
            .name
            .get(9..)
            .filter(|_| k.name[..9].eq_ignore_ascii_case("BaudRate_"))
        else {
            continue;
        };
        let Ok(rate) = rate.parse::<u32>() else {
            continue;
        };
        if p.flag(s, k.name)? {
            baud_rates.push(rate);
        }
    }
    baud_rates.sort_unstable();
    Ok(DeviceInfo {
        vendor_name: key_text(s, "VendorName"),
        vendor_number: p.opt_number(s, "VendorNumber")?,
        product_name: key_text(s, "ProductName"),
        product_number: p.opt_number(s, "ProductNumber")?,
        revision_number: p.opt_number(s, "RevisionNumber")?,
        order_code: key_text(s, "OrderCode"),
        baud_rates,
        simple_boot_up_master: p.flag(s, "SimpleBootUpMaster")?,
        simple_boot_up_slave: p.flag(s, "SimpleBootUpSlave")?,
        granularity: p.opt_number(s, "Granularity")?,
        dynamic_channels_supported: p.opt_number(s, "DynamicChannelsSupported")?,
        group_messaging: p.flag(s, "GroupMessaging")?,
        nr_of_rx_pdo: p.opt_number(s, "NrOfRXPDO")?,
        nr_of_tx_pdo: p.opt_number(s, "NrOfTXPDO")?,
        lss_supported: p.flag(s, "LSS_Supported")?,
        compact_pdo: p.opt_number(s, "CompactPDO")?,
    })
}

/// Most entries an object list is read with (CiA 306: one per object index).
const MAX_LIST: u32 = 0x1_0000;

fn object_list(p: &mut Parser, s: &Section) -> Result<Vec<u16>, EdsError> {
    let count: u32 = match s.get("SupportedObjects") {
        Some(k) => match p.number::<u16>(s, k)? {
            Some(n) => u32::from(n),
            None => numbered_keys(s),
        },
        None => {
            let e = p.err(
                EdsErrorKind::MissingKey,
                Some(s.line),
                Some(s.name),
                Some("SupportedObjects"),
                None,
                "missing",
            );
            p.soft(e, None, Some("the numbered keys are read".into()))?;
            numbered_keys(s)
        }
    };
    let mut out = Vec::new();
    for i in 1..=count.min(MAX_LIST) {
        match s.get(&i.to_string()) {
            Some(k) => {
                if let Some(index) = p.number::<u16>(s, k)? {
                    out.push(index);
                }
            }
            None => {
                let e = p.err(
                    EdsErrorKind::ObjectList,
                    Some(s.line),
                    Some(s.name),
                    Some(&i.to_string()),
                    None,
                    format!("missing; SupportedObjects={count}"),
                );
                p.soft(e, None, None)?;
            }
        }
    }
    for k in &s.keys {
        let in_range = k.name.parse::<u32>().is_ok_and(|n| n >= 1 && n <= count);
        if !in_range && !k.name.eq_ignore_ascii_case("SupportedObjects") {
            let e = p.key_err(
                EdsErrorKind::ObjectList,
                s,
                k,
                format!("unexpected key; SupportedObjects={count}"),
            );
            p.soft(e, None, None)?;
        }
    }
    Ok(out)
}

/// The largest numbered key of an object list section.
fn numbered_keys(s: &Section) -> u32 {
    s.keys
        .iter()
        .filter_map(|k| k.name.parse::<u32>().ok())
        .filter(|&n| n <= MAX_LIST)
        .max()
        .unwrap_or(0)
}

fn object_type(p: &mut Parser, s: &Section, at: (u16, u8)) -> Result<ObjectType, EdsError> {
    let Some(k) = s.get("ObjectType") else {
        return Ok(ObjectType::Var);
    };
    let fallback = if s.get("SubNumber").is_some() {
        ObjectType::Record
    } else {
        ObjectType::Var
    };
    let code: Option<u8> = p.number(s, k)?;
    if let Some(t) = code.and_then(ObjectType::from_code) {
        return Ok(t);
    }
    if code.is_some() {
        let e = p.key_err(
            EdsErrorKind::UnknownObjectType,
            s,
            k,
            format!(
                "unknown object type {} (allowed: {})",
                k.value,
                ObjectType::ALLOWED
            ),
        );
        p.soft(e, Some(at), Some(format!("read as {:#x}", fallback.code())))?;
    }
    Ok(fallback)
}

fn object(p: &mut Parser, eds: &mut Eds, index: u16, s: &Section) -> Result<(), EdsError> {
    let object_type = object_type(p, s, (index, 0))?;
    let sub_number: Option<u8> = p.opt_number(s, "SubNumber")?;
    let mut compact_sub_obj: Option<u8> = p.opt_number(s, "CompactSubObj")?;
    if let (Some(_), Some(k)) = (compact_sub_obj, s.get("CompactSubObj")) {
        let problem = if object_type != ObjectType::Array {
            Some("CompactSubObj is only allowed on an ARRAY (ObjectType=0x8)")
        } else if s.get("SubNumber").is_some() {
            Some("SubNumber and CompactSubObj exclude each other")
        } else {
            None
        };
        if let Some(problem) = problem {
            let k = if problem.starts_with("SubNumber") {
                s.get("SubNumber").unwrap_or(k)
            } else {
                k
            };
            let e = p.key_err(EdsErrorKind::BadValue, s, k, problem);
            p.soft(e, Some((index, 0)), Some("CompactSubObj is ignored".into()))?;
            compact_sub_obj = None;
        }
    }
    let header = ObjectHeader {
        index,
        parameter_name: key_text(s, "ParameterName").unwrap_or_default(),
        object_type,
        sub_number,
        compact_sub_obj,
        obj_flags: p.opt_number(s, "ObjFlags")?,
        line: s.line,
    };
    if let (Some(n), Some(k)) = (compact_sub_obj, s.get("CompactSubObj")) {
        let count = Entry {
            index,
            sub: 0,
            parameter_name: "NrOfObjects".into(),
            object_type: ObjectType::Var,
            data_type: DataType::Unsigned8,
            access: AccessType::ReadOnly,
            default: Some(ValueText {
                raw: n.to_string(),
                line: k.line,
            }),
            low_limit: None,
            high_limit: None,
            pdo_mapping: false,
            parameter_value: None,
            denotation: None,
            obj_flags: None,
            line: s.line,
        };
        eds.objects.insert((index, 0), count);
        for sub in 1..=n {
            let name = format!("{}{sub}", header.parameter_name);
            if let Some(e) = entry(p, s, index, sub, Some(name))? {
                eds.objects.insert((index, sub), e);
            }
        }
    } else if matches!(
        object_type,
        ObjectType::Var | ObjectType::DefType | ObjectType::Domain
    ) {
        if let Some(e) = entry(p, s, index, 0, None)? {
            eds.objects.insert((index, 0), e);
        }
    }
    eds.object_headers.insert(index, header);
    Ok(())
}

/// Check a value text of `at` for its data type (for every node id 1 … 127 when it uses
/// `$NODEID`); a value that does not read literally is a warning saying how it is read
/// ([`super::lenient`]).
fn check_value(
    p: &mut Parser,
    s: &Section,
    k: &Key,
    data_type: DataType,
    role: ValueRole,
    at: (u16, u8),
) -> Result<(), EdsError> {
    if let DataType::Other(code) = data_type {
        if role == ValueRole::Value && !k.value.is_empty() {
            let e = p.key_err(
                EdsErrorKind::BadValue,
                s,
                k,
                format!(
                    "a value of data type {code:#06x}, a complex or manufacturer-specific type \
                     (CiA 301) no value encoding is defined for"
                ),
            );
            p.soft(e, Some(at), Some("not read: the object reads empty".into()))?;
        }
        return Ok(());
    }
    for node in [1u8, 127] {
        let Err(e) = data_type.value_from_text(k.value, node) else {
            continue;
        };
        let kind = match e {
            ValueError::Syntax(_)
                if data_type.is_integer()
                    || matches!(data_type, DataType::Real32 | DataType::Real64) =>
            {
                EdsErrorKind::BadNumber
            }
            ValueError::OutOfRange { .. } => EdsErrorKind::OutOfRange,
            _ => EdsErrorKind::BadValue,
        };
        let mut message = e.to_string();
        let node_dependent = IntExpr::parse_lenient(k.value).is_some_and(|(x, _)| x.uses_node_id());
        if node_dependent {
            message = format!("{message} (with $NODEID={node})");
        }
        let used = match data_type.value_from_text_lenient(k.value, node, role) {
            Ok((_, Some(how))) => how,
            Ok((_, None)) => "read as written".into(),
            Err(_) => match role {
                ValueRole::Value => "no value: the object reads 0 (empty)".into(),
                ValueRole::Limit => "no limit".into(),
            },
        };
        let used = if node_dependent {
            format!("{used} (with $NODEID={node})")
        } else {
            used
        };
        let err = p.key_err(kind, s, k, message);
        return p.soft(err, Some(at), Some(used));
    }
    Ok(())
}

/// Communication objects whose data type CiA 301 fixes (§7.5.2): a master and the emulated
/// node read them with that type, so an EDS declaring another type is read with CiA 301's.
const FIXED_TYPES: &[(u16, u8, DataType, &str)] = &[
    (0x1000, 0, DataType::Unsigned32, "device type"),
    (0x1001, 0, DataType::Unsigned8, "error register"),
    (0x1017, 0, DataType::Unsigned16, "producer heartbeat time"),
];

/// The entry of a VAR section, a sub-index section or (with `compact_name`) a compact sub;
/// `None` (a warning) when it has no readable data type.
fn entry(
    p: &mut Parser,
    s: &Section,
    index: u16,
    sub: u8,
    compact_name: Option<String>,
) -> Result<Option<Entry>, EdsError> {
    let at = Some((index, sub));
    let left_out = || Some("the object is left out".to_string());
    let object_type = if compact_name.is_some() {
        ObjectType::Var
    } else {
        object_type(p, s, (index, sub))?
    };
    let kind_word = if sub == 0 && compact_name.is_none() {
        "a VAR"
    } else {
        "a sub-index"
    };
    let mut data_type = match s.get("DataType") {
        Some(k) => {
            let Some(code) = p.number::<u16>(s, k)? else {
                return Ok(None);
            };
            match DataType::from_code(code) {
                Some(t) => t,
                None => {
                    let e = p.key_err(
                        EdsErrorKind::UnknownDataType,
                        s,
                        k,
                        format!(
                            "unknown data type code {} (CiA 301 data type table)",
                            k.value
                        ),
                    );
                    p.soft(e, at, Some("read as DOMAIN (a byte string)".into()))?;
                    DataType::Domain
                }
            }
        }
        None if object_type == ObjectType::Domain => DataType::Domain,
        None => {
            let e = p.err(
                EdsErrorKind::MissingKey,
                Some(s.line),
                Some(s.name),
                Some("DataType"),
                None,
                format!("missing; required for {kind_word}"),
            );
            p.soft(e, at, left_out())?;
            return Ok(None);
        }
    };
    if let Some(&(_, _, expected, what)) = FIXED_TYPES
        .iter()
        .find(|(i, j, _, _)| (*i, *j) == (index, sub))
    {
        if data_type != expected {
            let found = format!("{:#06x} ({data_type:?})", data_type.code());
            let message = format!(
                "object {index:#06x}:{sub:02x} ({what}) must have data type {:#06x} \
                 ({expected:?}, CiA 301), found {found}",
                expected.code()
            );
            let e = match s.get("DataType") {
                Some(k) => p.key_err(EdsErrorKind::BadValue, s, k, message),
                None => p.err(
                    EdsErrorKind::BadValue,
                    Some(s.line),
                    Some(s.name),
                    Some("DataType"),
                    None,
                    message,
                ),
            };
            p.soft(e, at, Some(format!("read as {expected:?} (CiA 301)")))?;
            data_type = expected;
        }
    }
    let access = match s.get("AccessType") {
        Some(k) => match AccessType::parse(k.value) {
            Some(a) => a,
            None => {
                let a = guess_access(k.value);
                let e = p.key_err(
                    EdsErrorKind::UnknownAccessType,
                    s,
                    k,
                    format!(
                        "unknown access type {:?} (allowed: {})",
                        k.value,
                        AccessType::ALLOWED
                    ),
                );
                p.soft(e, at, Some(format!("read as {}", access_name(a))))?;
                a
            }
        },
        None => {
            let e = p.err(
                EdsErrorKind::MissingKey,
                Some(s.line),
                Some(s.name),
                Some("AccessType"),
                None,
                format!(
                    "missing; required for {kind_word} (allowed: {})",
                    AccessType::ALLOWED
                ),
            );
            p.soft(e, at, Some("read as rw".into()))?;
            AccessType::ReadWrite
        }
    };
    let mut value = |key: &str, role: ValueRole| -> Result<Option<ValueText>, EdsError> {
        match s.get(key) {
            Some(k) if !k.value.is_empty() => {
                check_value(p, s, k, data_type, role, (index, sub))?;
                Ok(Some(ValueText {
                    raw: k.value.to_string(),
                    line: k.line,
                }))
            }
            _ => Ok(None),
        }
    };
    let default = value("DefaultValue", ValueRole::Value)?;
    let low_limit = value("LowLimit", ValueRole::Limit)?;
    let high_limit = value("HighLimit", ValueRole::Limit)?;
    let parameter_value = value("ParameterValue", ValueRole::Value)?;
    Ok(Some(Entry {
        index,
        sub,
        parameter_name: compact_name
            .unwrap_or_else(|| key_text(s, "ParameterName").unwrap_or_default()),
        object_type,
        data_type,
        access,
        default,
        low_limit,
        high_limit,
        pdo_mapping: p.flag(s, "PDOMapping")?,
        parameter_value,
        denotation: key_text(s, "Denotation"),
        obj_flags: p.opt_number(s, "ObjFlags")?,
        line: s.line,
    }))
}

/// An access type spelled otherwise (module documentation).
fn guess_access(text: &str) -> AccessType {
    let t = text.to_ascii_lowercase();
    match (t.contains('r'), t.contains('w')) {
        (true, true) => AccessType::ReadWrite,
        (false, true) => AccessType::WriteOnly,
        _ => AccessType::ReadOnly,
    }
}

fn access_name(a: AccessType) -> &'static str {
    match a {
        AccessType::ReadOnly => "ro",
        AccessType::WriteOnly => "wo",
        AccessType::ReadWrite => "rw",
        AccessType::ReadWriteInput => "rwr",
        AccessType::ReadWriteOutput => "rww",
        AccessType::Const => "const",
    }
}

#[cfg(test)]
mod tests {
    use crate::bus::canopen::eds::{parse_with, ParseOptions};

    /// The header of CANopenNode's `DS301_profile.eds` leaves the vendor and product entries
    /// empty; CiA 306 makes them optional, so an empty value reads as an absent one, without a
    /// warning, even in strict mode.
    #[test]
    fn empty_header_values_are_absent() {
        let text = "[DeviceInfo]\nVendorName=\nVendorNumber=\nProductName=\nProductNumber=\n\
                    RevisionNumber=  \nOrderCode=\nSimpleBootUpSlave=\nGranularity=8\n\
                    [MandatoryObjects]\nSupportedObjects=1\n1=0x1000\n\
                    [1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\n\
                    AccessType=ro\nDefaultValue=0x00000000\n";
        let e = parse_with(text, "DS301_profile.eds", ParseOptions { strict: true })
            .expect("empty optional header values are no error");
        assert!(e.warnings.is_empty(), "{:?}", e.warnings);
        let d = &e.device_info;
        assert_eq!(d.vendor_number, None);
        assert_eq!(d.product_number, None);
        assert_eq!(d.revision_number, None);
        assert_eq!(d.vendor_name, None);
        assert_eq!(d.product_name, None);
        assert_eq!(d.order_code, None);
        assert!(!d.simple_boot_up_slave);
        // A value that is there is still read, and a bad one still refused in strict mode.
        assert_eq!(d.granularity, Some(8));
        let bad = text.replace("VendorNumber=\n", "VendorNumber=0x12G\n");
        let err = parse_with(&bad, "t.eds", ParseOptions { strict: true }).unwrap_err();
        assert!(err.to_string().contains("VendorNumber"), "{err}");
        let lenient = parse_with(&bad, "t.eds", ParseOptions::default()).unwrap();
        assert_eq!(lenient.warnings.len(), 1, "{:?}", lenient.warnings);
        assert_eq!(lenient.device_info.vendor_number, None);
    }
}
