//! Which objects of an ESI device play the CiA 402 roles, and which PDOs carry them — the
//! choice a configurator (TwinCAT, IgH's `ethercat` tool with a generated configuration) makes
//! from the vendor's ESI, made the same way for `fieldprobe drive from-esi` and for the emulated
//! vendor device.
//!
//! # Roles ([`role_sources`])
//!
//! A CiA 402 axis needs the controlword, target position, statusword and position actual value
//! (and uses the mode of operation, its display, the following error, the torque actual value
//! and the touch probe). A device offers each role, in this order of preference:
//!
//! 1. the CiA 402 object itself (0x6040 …), in its dictionary or in one of its PDOs, with CiA
//!    402's bit length;
//! 2. an object of Beckhoff's modular device profile (ETG.5001 MDP, profile 5001 in
//!    `ChannelInfo`: inputs at 0x6000 + n·0x10, outputs at 0x7000 + n·0x10), found by its
//!    sub-item name: `Controlword` / `Statusword` / `Target position` / `Modes of operation`
//!    / `Modes of operation display` / `Position` (the feedback module's position) /
//!    `Following error actual value` / `Torque actual value`, `TP1 Pos position` … `TP2 Neg
//!    position` (the four touch probe values) — the names Beckhoff's EL72x1 / EJ72x1 servo
//!    terminals use, laid out as MDP 742 describes them;
//! 3. the touch probe function and status as a word of single bits: an MDP record whose
//!    sub-items `TP1 Enable`, `TP1 Continous`, … sit at the bit offsets (ESI `BitOffs`) of the
//!    CiA 402 0x60B8 / 0x60B9 bits; the parts' bit within the word is their `BitOffs` less that
//!    of `TP1 Enable`;
//! 4. the position set-point of a fixed RxPDO that carries 0x6062 instead of 0x607A (the
//!    "position interface" fixed PDOs of the Beckhoff AX2000 / Kollmorgen AKD family, whose
//!    drive takes its cyclic position command there) — an interpretation, noted in every
//!    definition that uses it.
//!
//! # PDOs ([`plan`])
//!
//! Per direction: when the device has a PDO it lets the master map (ESI `Fixed` false), the
//! roles' objects are mapped into it (the PDO the ESI assigns to the sync manager by default,
//! else the first configurable one) — exactly the objects the device marks mappable in that
//! direction. When every PDO is fixed (or no configurable PDO can carry the required roles),
//! PDOs are chosen among those the ESI offers, as they are: the required roles first, then as
//! many wanted roles as possible, then the fewest bits; never two PDOs that exclude each other
//! (`Exclude`), never more than the sync manager holds (`MaxSize`), every `Mandatory` PDO
//! included. Objects a fixed RxPDO carries besides the roles get a value the drive can run with
//! (`[rxpdo] defaults`): a torque or speed limit its ESI default, else the type's largest value;
//! anything else 0.

use super::super::pdo::{self, DataType, EntrySpec};
use super::plan::{finish, Part, Plan, PlanError, RoleSource};
use crate::esi::{Access, Device, Dictionary, Flags, Object, Pdo, PdoMapping, SmKind};

/// One leaf of the device's dictionary: a sub-index of an object as its data type lays it out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Leaf {
    /// Index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// The sub-item's name (the object's for a plain object).
    pub name: String,
    /// ETG.2000 type name (`UINT`, `BOOL`, `BIT2`).
    pub type_name: String,
    /// Bit length.
    pub bits: u32,
    /// `BitOffs` within the record (0 for a plain object).
    pub bit_offs: u32,
    /// Flags (the sub-item's, else the object's).
    pub flags: Flags,
}

/// The leaves of `o` (a plain object: sub-index 0; a record: its `SubItem`s with `SubIdx`; an
/// array element `SubItem` expands to the elements `LBound` … `LBound + Elements − 1`).
pub fn object_leaves(dict: &Dictionary, o: &Object) -> Vec<Leaf> {
    use crate::bus::ethercat::sdo_info::data_type_of_esi_name;
    let single = |type_name: &str| {
        vec![Leaf {
            index: o.index,
            sub: 0,
            name: o.name.clone(),
            type_name: type_name.to_string(),
            bits: o.bit_size,
            bit_offs: 0,
            flags: o.flags.clone(),
        }]
    };
    if data_type_of_esi_name(&o.type_name).is_some() {
        return single(&o.type_name);
    }
    let Some(t) = dict.data_type(&o.type_name) else {
        return single(&o.type_name);
    };
    if t.subitems.is_empty() {
        return match t.base_type.as_deref() {
            Some(b) if t.array.is_none() => single(b),
            _ => single(&o.type_name),
        };
    }
    let mut out = Vec::new();
    for s in &t.subitems {
        let flags = if s.flags.access.is_some() || s.flags.pdo_mapping.is_some() {
            s.flags.clone()
        } else {
            o.flags.clone()
        };
        if let Some(k) = s.subindex {
            // An enumeration (`DT0800EN08`: `BaseType` USINT, `EnumInfo`s) is its base type.
            let type_name = dict
                .data_type(&s.type_name)
                .filter(|t| t.subitems.is_empty() && t.array.is_none())
                .and_then(|t| t.base_type.clone())
                .unwrap_or_else(|| s.type_name.clone());
            out.push(Leaf {
                index: o.index,
                sub: k,
                name: s.name.clone(),
                type_name,
                bits: s.bit_size,
                bit_offs: s.bit_offs,
                flags,
            });
            continue;
        }
        let Some(arr) = dict.data_type(&s.type_name) else {
            continue;
        };
        let (Some(info), Some(base)) = (arr.array, arr.base_type.as_deref()) else {
            continue;
        };
        let each = dict
            .data_type(base)
            .map(|b| b.bit_size)
            .filter(|&b| b > 0)
            .unwrap_or(arr.bit_size / info.elements.max(1));
        for k in info.lbound..info.lbound.saturating_add(info.elements).min(256) {
            out.push(Leaf {
                index: o.index,
                sub: k as u8,
                name: format!("{} {k}", s.name),
                type_name: base.to_string(),
                bits: each,
                bit_offs: s.bit_offs + (k - info.lbound) * each,
                flags: flags.clone(),
            });
        }
    }
    out
}

/// Every leaf of the device's dictionary.
pub fn leaves(device: &Device) -> Vec<Leaf> {
    let Some(dict) = device.dictionary() else {
        return Vec::new();
    };
    dict.objects
        .iter()
        .flat_map(|o| object_leaves(dict, o))
        .collect()
}

/// The roles a CiA 402 axis uses: (role name, CiA 402 index, master → drive, required).
const ROLES: [(&str, u16, bool, bool); 14] = [
    ("controlword", 0x6040, true, true),
    ("target_position", 0x607A, true, true),
    ("modes_of_operation", 0x6060, true, false),
    ("touch_probe_function", 0x60B8, true, false),
    ("statusword", 0x6041, false, true),
    ("position_actual_value", 0x6064, false, true),
    ("following_error_actual_value", 0x60F4, false, false),
    ("modes_of_operation_display", 0x6061, false, false),
    ("touch_probe_status", 0x60B9, false, false),
    ("touch_probe_1_positive_edge", 0x60BA, false, false),
    ("touch_probe_1_negative_edge", 0x60BB, false, false),
    ("touch_probe_2_positive_edge", 0x60BC, false, false),
    ("touch_probe_2_negative_edge", 0x60BD, false, false),
    ("torque_actual_value", 0x6077, false, false),
];

/// MDP sub-item names of a role (compared lower case without blanks, `_`, `-`).
fn mdp_names(index: u16) -> &'static [&'static str] {
    match index {
        0x6040 => &["controlword"],
        0x6041 => &["statusword"],
        0x6060 => &["modesofoperation"],
        0x6061 => &["modesofoperationdisplay"],
        0x607A => &["targetposition"],
        0x6064 => &["positionactualvalue", "position"],
        0x60F4 => &["followingerroractualvalue"],
        0x6077 => &["torqueactualvalue"],
        0x60BA => &["tp1posposition", "touchprobe1positiveedge"],
        0x60BB => &["tp1negposition", "touchprobe1negativeedge"],
        0x60BC => &["tp2posposition", "touchprobe2positiveedge"],
        0x60BD => &["tp2negposition", "touchprobe2negativeedge"],
        _ => &[],
    }
}

/// `name` lower case without blanks, `_` and `-`.
pub fn normalized(name: &str) -> String {
    name.chars()
        .filter(|c| !c.is_whitespace() && *c != '_' && *c != '-')
        .flat_map(char::to_lowercase)
        .collect()
}

fn in_pdo(pdos: &[Pdo], index: u16, sub: u8) -> Option<u16> {
    pdos.iter()
        .flat_map(|p| p.entries.iter())
        .find(|e| e.index == index && e.subindex == sub)
        .map(|e| e.bit_len)
}

fn maps(flags: &Flags, rx: bool) -> bool {
    flags
        .pdo_mapping
        .is_some_and(|m: PdoMapping| if rx { m.rx() } else { m.tx() })
}

fn writable(flags: &Flags) -> bool {
    matches!(flags.access, Some(Access::ReadWrite | Access::WriteOnly))
}

/// Every way `device` offers each role of a CiA 402 axis, in the order of preference of the
/// module documentation (several sources per role possible; roles without one are absent).
pub fn role_sources(device: &Device) -> Vec<RoleSource> {
    let leaves = leaves(device);
    // A dictionary without any `PdoMapping` flag says nothing about mapping: the PDOs the ESI
    // describes are then the only word on it.
    let flagless = !leaves.iter().any(|l| l.flags.pdo_mapping.is_some());
    let mut out = Vec::new();
    for &(_, index, rx, _) in &ROLES {
        let pdos = if rx { &device.rx_pdos } else { &device.tx_pdos };
        let Some(ty) = pdo::lookup(index, 0).map(|o| o.ty) else {
            continue;
        };
        let bits = (ty.size() * 8) as u16;
        // 1. The CiA 402 object.
        let leaf = leaves.iter().find(|l| l.index == index && l.sub == 0);
        // A configurable PDO's default entries are rewritten by the master: only the
        // dictionary and the fixed PDOs say what the device has.
        let fixed: Vec<Pdo> = pdos.iter().filter(|p| p.fixed).cloned().collect();
        let pdo_bits = in_pdo(if flagless { pdos } else { &fixed }, index, 0);
        let own_bits = leaf.map(|l| l.bits).or(pdo_bits.map(u32::from));
        if own_bits == Some(u32::from(bits)) {
            out.push(RoleSource {
                index,
                sub: 0,
                rx,
                parts: vec![Part {
                    index,
                    sub: 0,
                    bits,
                    at: 0,
                }],
                word: None,
                how: "CiA 402 object",
                mappable: leaf.is_some_and(|l| maps(&l.flags, rx))
                    || (flagless && pdo_bits == Some(bits)),
                writable: leaf.is_some_and(|l| writable(&l.flags)),
            });
        }
        // 2. A modular device profile object of that name.
        let range = if rx { 0x7000..=0x7FFF } else { 0x6000..=0x6FFF };
        for l in leaves.iter().filter(|l| {
            range.contains(&l.index)
                && l.sub > 0
                && l.bits == u32::from(bits)
                && mdp_names(index).contains(&normalized(&l.name).as_str())
        }) {
            out.push(RoleSource {
                index,
                sub: 0,
                rx,
                parts: vec![Part {
                    index: l.index,
                    sub: l.sub,
                    bits,
                    at: 0,
                }],
                word: None,
                how: "modular device profile object",
                mappable: maps(&l.flags, rx)
                    || (flagless && in_pdo(pdos, l.index, l.sub) == Some(bits)),
                writable: writable(&l.flags),
            });
        }
        // 3. The touch probe function / status as a word of bits.
        if index == 0x60B8 || index == 0x60B9 {
            for first in leaves
                .iter()
                .filter(|l| range.contains(&l.index) && normalized(&l.name) == "tp1enable")
            {
                let parts: Vec<Part> = leaves
                    .iter()
                    .filter(|l| {
                        l.index == first.index
                            && l.sub > 0
                            && l.bits <= 2
                            && l.bit_offs >= first.bit_offs
                            && l.bit_offs + l.bits <= first.bit_offs + u32::from(bits)
                    })
                    .map(|l| Part {
                        index: l.index,
                        sub: l.sub,
                        bits: l.bits as u16,
                        at: (l.bit_offs - first.bit_offs) as u16,
                    })
                    .collect();
                if parts.is_empty() || (index == 0x60B9 && parts.len() < 2) {
                    continue;
                }
                let mappable = parts.iter().all(|p| {
                    leaves
                        .iter()
                        .find(|l| l.index == p.index && l.sub == p.sub)
                        .is_some_and(|l| maps(&l.flags, rx))
                        || (flagless && in_pdo(pdos, p.index, p.sub).is_some())
                });
                out.push(RoleSource {
                    index,
                    sub: 0,
                    rx,
                    parts,
                    word: Some(bits),
                    how: "modular device profile bits",
                    mappable,
                    writable: false,
                });
            }
        }
        // 4. The position set-point of a fixed position-interface RxPDO.
        if index == 0x607A && in_pdo(pdos, 0x6062, 0) == Some(32) {
            out.push(RoleSource {
                index,
                sub: 0,
                rx,
                parts: vec![Part {
                    index: 0x6062,
                    sub: 0,
                    bits: 32,
                    at: 0,
                }],
                word: None,
                how: "position set-point 0x6062 of a fixed position-interface RxPDO",
                mappable: false,
                writable: false,
            });
        }
    }
    out
}

/// The ETG.2000 data type of a PDO entry as a drive-file entry type: the CiA 401 / IEC names of
/// whole-byte integers, else an unsigned bit field of `bits` bits.
pub fn entry_spec(index: u16, sub: u8, bits: u16, data_type: Option<&str>) -> EntrySpec {
    if index == 0 {
        return EntrySpec::gap(bits);
    }
    let named = data_type.and_then(|t| match t.trim().to_ascii_uppercase().as_str() {
        "SINT" => Some(DataType::I8),
        "USINT" | "BYTE" => Some(DataType::U8),
        "INT" => Some(DataType::I16),
        "UINT" | "WORD" => Some(DataType::U16),
        "DINT" => Some(DataType::I32),
        "UDINT" | "DWORD" => Some(DataType::U32),
        _ => None,
    });
    let ty = named
        .filter(|t| t.size() * 8 == usize::from(bits))
        .or(match bits {
            8 => Some(DataType::U8),
            16 => Some(DataType::U16),
            32 => Some(DataType::U32),
            _ => None,
        });
    match ty {
        Some(ty) => EntrySpec::whole(index, sub, ty),
        None => EntrySpec {
            index,
            sub,
            ty: DataType::U32,
            bits,
        },
    }
    .normalized()
}

impl EntrySpec {
    /// The spec with a bit field's raw type narrowed to its length (`bit1` → u8).
    fn normalized(self) -> EntrySpec {
        if !self.is_gap() && usize::from(self.bits) != self.ty.size() * 8 {
            return pdo::parse_entry_spec(&pdo::entry_text(&self)).unwrap_or(self);
        }
        self
    }
}

/// Outputs of a fixed RxPDO whose 0 would stop the drive, with the value written instead when
/// the ESI gives no default: torque limits and speed limits, their type's largest value.
const LIMITS: [u16; 5] = [0x6072, 0x60E0, 0x60E1, 0x607F, 0x6080];

/// Weight of a role in the choice of fixed PDOs: required roles far above the rest.
fn weight(required: bool) -> i64 {
    if required {
        1000
    } else {
        10
    }
}

/// The plan for `device` (see the module documentation).
///
/// # Errors
/// [`PlanError`] naming each required role the device cannot carry.
pub fn plan(device: &Device) -> Result<Plan, PlanError> {
    let sources = role_sources(device);
    let mut p = Plan::default();
    let mut missing = Vec::new();
    for rx in [true, false] {
        let dir = direction(device, &sources, rx, &mut p);
        if let Err(m) = dir {
            missing.extend(m.into_iter().map(|i| (i, rx)));
        }
    }
    if !missing.is_empty() {
        return Err(PlanError {
            missing: missing_text(&sources, &missing),
        });
    }
    finish(&mut p);
    // The mode of operation, when no PDO carries it: written once by SDO, where the device
    // lets it be written.
    if p.source(0x6060).is_none() {
        if let Some(s) = sources.iter().find(|s| s.index == 0x6060 && s.writable) {
            let (i, sub) = s.object();
            p.notes.push(format!(
                "0x6060:00 modes of operation: in no PDO; the master writes {i:#06X}:{sub:02X} = 8 \
                 (cyclic synchronous position) by SDO in PRE-OP"
            ));
            p.used.push(s.clone());
        }
    }
    Ok(p)
}

/// Plan one direction into `p`; `Err` lists the required roles it cannot carry.
fn direction(
    device: &Device,
    sources: &[RoleSource],
    rx: bool,
    p: &mut Plan,
) -> Result<(), Vec<u16>> {
    let pdos = if rx { &device.rx_pdos } else { &device.tx_pdos };
    let roles: Vec<(u16, bool)> = ROLES
        .iter()
        .filter(|r| r.2 == rx)
        .map(|r| (r.1, r.3))
        .collect();
    let flexible: Vec<&Pdo> = pdos.iter().filter(|p| !p.fixed).collect();
    let sm = if rx { 2 } else { 3 };
    let default_index = if rx { 0x1600 } else { 0x1A00 };
    // A configurable PDO (or none declared at all): map the roles' objects.
    if !flexible.is_empty() || pdos.is_empty() {
        let target = flexible
            .iter()
            .find(|p| p.sm == Some(sm))
            .or(flexible.first())
            .map_or(default_index, |p| p.index);
        let mut entries = Vec::new();
        let mut used = Vec::new();
        let mut missing = Vec::new();
        for &(index, required) in &roles {
            match sources.iter().find(|s| s.index == index && s.mappable) {
                Some(s) => {
                    entries.extend(role_entries(s));
                    used.push(s.clone());
                }
                None if required => missing.push(index),
                None => {}
            }
        }
        if missing.is_empty() {
            p.used.extend(used);
            let d = if rx { &mut p.rx } else { &mut p.tx };
            d.pdos = vec![target];
            d.fixed = false;
            d.entries = entries;
            return Ok(());
        }
        if pdos.iter().all(|p| !p.fixed) {
            return Err(missing);
        }
    }
    // Fixed PDOs: choose.
    let limit_bits = device
        .sync_manager(if rx {
            &SmKind::Outputs
        } else {
            &SmKind::Inputs
        })
        .and_then(|(_, s)| s.max_size)
        .map(|b| u32::from(b) * 8);
    let covers = |pdo: &Pdo, index: u16| -> Option<&RoleSource> {
        sources.iter().find(|s| {
            s.index == index
                && s.parts.iter().all(|part| {
                    pdo.entries
                        .iter()
                        .any(|e| e.index == part.index && e.subindex == part.sub)
                })
                && word_fits(s, pdo)
        })
    };
    let mut chosen: Vec<&Pdo> = pdos.iter().filter(|p| p.mandatory).collect();
    loop {
        let covered =
            |index: u16, chosen: &[&Pdo]| chosen.iter().any(|c| covers(c, index).is_some());
        let bits: u32 = chosen.iter().map(|c| c.bit_len()).sum();
        let mut best: Option<(i64, &Pdo)> = None;
        for cand in pdos {
            if chosen.iter().any(|c| c.index == cand.index)
                || chosen
                    .iter()
                    .any(|c| c.excludes.contains(&cand.index) || cand.excludes.contains(&c.index))
                || limit_bits.is_some_and(|l| bits + cand.bit_len() > l)
                || cand.entries.iter().any(|e| {
                    e.index != 0
                        && chosen.iter().any(|c| {
                            c.entries
                                .iter()
                                .any(|x| x.index == e.index && x.subindex == e.subindex)
                        })
                })
            {
                continue;
            }
            let gain: i64 = roles
                .iter()
                .filter(|(i, _)| !covered(*i, &chosen) && covers(cand, *i).is_some())
                .map(|&(_, req)| weight(req))
                .sum();
            if gain == 0 {
                continue;
            }
            let hazards = cand
                .entries
                .iter()
                .filter(|e| rx && LIMITS.contains(&e.index))
                .count() as i64;
            // The PDO the vendor assigns by default is what the device is made for.
            let default = if cand.sm == Some(sm) { 600 } else { 0 };
            let score = gain * 1000 + default - hazards * 500 - i64::from(cand.bit_len());
            if best.is_none_or(|(b, _)| score > b) {
                best = Some((score, cand));
            }
        }
        match best {
            Some((_, c)) => chosen.push(c),
            None => break,
        }
    }
    chosen.sort_by_key(|c| c.index);
    let missing: Vec<u16> = roles
        .iter()
        .filter(|(i, req)| *req && !chosen.iter().any(|c| covers(c, *i).is_some()))
        .map(|(i, _)| *i)
        .collect();
    if !missing.is_empty() {
        return Err(missing);
    }
    let mut entries = Vec::new();
    for c in &chosen {
        for e in &c.entries {
            let role = sources.iter().find(|s| {
                s.word.is_none()
                    && s.has(e.index, e.subindex)
                    && chosen.iter().any(|c| covers(c, s.index) == Some(s))
            });
            let spec = match role.and_then(|s| pdo::lookup(s.index, s.sub)) {
                // A role's object keeps CiA 402's type (same bits on the wire).
                Some(o) if o.ty.size() * 8 == usize::from(e.bit_len) => {
                    EntrySpec::whole(e.index, e.subindex, o.ty)
                }
                _ => entry_spec(e.index, e.subindex, e.bit_len, e.data_type.as_deref()),
            };
            entries.push(spec);
        }
    }
    let mut used: Vec<RoleSource> = Vec::new();
    for &(index, _) in &roles {
        if let Some(s) = chosen.iter().find_map(|c| covers(c, index)) {
            used.push(s.clone());
        }
    }
    let names: Vec<String> = chosen
        .iter()
        .map(|c| format!("{:#06X} {}", c.index, c.name))
        .collect();
    p.notes.push(format!(
        "{}: the device's fixed PDOs {} (assigned as they are)",
        if rx { "outputs" } else { "inputs" },
        names.join(", ")
    ));
    let mut defaults = Vec::new();
    if rx {
        for e in &entries {
            if e.is_gap()
                || !LIMITS.contains(&e.index)
                || used.iter().any(|s| s.has(e.index, e.sub))
            {
                continue;
            }
            let dict_default = device
                .object(e.index)
                .filter(|_| e.sub == 0)
                .and_then(Object::default_u64)
                .and_then(|v| i64::try_from(v).ok())
                // A limit of 0 stops the drive: such a default is no value to run with.
                .filter(|v| *v > 0 && e.ty.contains(*v));
            let (value, why) = match dict_default {
                Some(v) => (v, "the ESI default".to_string()),
                None => (
                    e.ty.range().1,
                    "no limit: the type's largest value".to_string(),
                ),
            };
            defaults.push((e.index, e.sub, value, why));
        }
    }
    p.used.extend(used);
    let d = if rx { &mut p.rx } else { &mut p.tx };
    d.pdos = chosen.iter().map(|c| c.index).collect();
    d.fixed = true;
    d.entries = entries;
    d.defaults = defaults;
    Ok(())
}

/// Does a word source's layout in `pdo` equal the CiA 402 word bit for bit (its first part at
/// the word's bit 0, every part at its bit)? Whole-object sources always fit.
fn word_fits(s: &RoleSource, pdo: &Pdo) -> bool {
    if s.word.is_none() {
        return true;
    }
    let mut bit = 0u32;
    let mut start = None;
    let mut positions = Vec::new();
    for e in &pdo.entries {
        if let Some(part) = s
            .parts
            .iter()
            .find(|p| p.index == e.index && p.sub == e.subindex)
        {
            let first = *start.get_or_insert(bit);
            positions.push((bit - first, u32::from(part.at)));
        }
        bit += u32::from(e.bit_len);
    }
    !positions.is_empty() && positions.iter().all(|(got, want)| got == want)
}

/// The entries mapping source `s` into a configurable PDO: the object, or for a word its parts
/// at their bits with gaps between them, padded to the word's length.
fn role_entries(s: &RoleSource) -> Vec<EntrySpec> {
    let Some(word) = s.word else {
        let ty = pdo::lookup(s.index, s.sub).map_or(DataType::U32, |o| o.ty);
        let (i, sub) = s.object();
        return vec![EntrySpec::whole(i, sub, ty)];
    };
    let mut parts = s.parts.clone();
    parts.sort_by_key(|p| p.at);
    let mut out = Vec::new();
    let mut bit = 0u16;
    for part in parts {
        if part.at > bit {
            out.push(EntrySpec::gap(part.at - bit));
        }
        out.push(entry_spec(part.index, part.sub, part.bits, None));
        bit = part.at + part.bits;
    }
    if word > bit {
        out.push(EntrySpec::gap(word - bit));
    }
    out
}

fn missing_text(sources: &[RoleSource], missing: &[(u16, bool)]) -> Vec<String> {
    // Objects with the same reason are named together, the reason once.
    let mut out: Vec<(Vec<String>, String)> = Vec::new();
    for &(index, rx) in missing {
        let name = pdo::lookup(index, 0).map_or("object", |o| o.name);
        let why = if sources.iter().any(|s| s.index == index) {
            format!(
                "not mappable into {} and in no PDO of the device",
                if rx { "an RxPDO" } else { "a TxPDO" }
            )
        } else {
            "not in the file (no CiA 402 object in its dictionary or its fixed PDOs, no \
             modular device profile object of that name)"
                .to_string()
        };
        let object = format!("0x{index:04X}:00 {name}");
        match out.iter_mut().find(|(_, w)| *w == why) {
            Some((objects, _)) => objects.push(object),
            None => out.push((vec![object], why)),
        }
    }
    out.into_iter()
        .map(|(objects, why)| format!("{}: {why}", objects.join(", ")))
        .collect()
}

#[cfg(test)]
mod tests {
    //! The choice on small ESI excerpts written here, one kind of device each.
    use super::*;

    /// A PDO of [`esi`]: (RxPDO, index, fixed, sync manager, excludes, entries (index, sub,
    /// bits)).
    type TestPdo<'a> = (bool, u16, bool, Option<u8>, &'a [u16], &'a [(u16, u8, u16)]);

    /// An ESI document: dictionary objects `(index, name, type, bits, mapping)` and PDOs
    /// `(rx, index, fixed, sm, excludes, entries (index, sub, bits))`.
    fn esi(objects: &[(u16, &str, &str, u32, &str)], pdos: &[TestPdo]) -> crate::esi::EsiFile {
        let mut x = String::from(
            "<EtherCATInfo><Vendor><Id>#x99</Id></Vendor><Descriptions><Devices><Device>\
             <Type ProductCode=\"#x1\" RevisionNo=\"#x1\">T</Type><Name>T</Name>\
             <Sm StartAddress=\"#x1000\" ControlByte=\"#x26\" DefaultSize=\"128\" Enable=\"1\">MBoxOut</Sm>\
             <Sm StartAddress=\"#x1080\" ControlByte=\"#x22\" DefaultSize=\"128\" Enable=\"1\">MBoxIn</Sm>\
             <Sm StartAddress=\"#x1100\" ControlByte=\"#x64\" Enable=\"1\">Outputs</Sm>\
             <Sm StartAddress=\"#x1180\" ControlByte=\"#x20\" Enable=\"1\">Inputs</Sm>",
        );
        for &(rx, index, fixed, sm, excludes, entries) in pdos {
            let tag = if rx { "RxPdo" } else { "TxPdo" };
            let sm = sm.map_or(String::new(), |s| format!(" Sm=\"{s}\""));
            x.push_str(&format!(
                "<{tag} Fixed=\"{}\"{sm}><Index>#x{index:X}</Index><Name>P</Name>",
                u8::from(fixed)
            ));
            for e in excludes {
                x.push_str(&format!("<Exclude>#x{e:X}</Exclude>"));
            }
            for &(i, s, b) in entries {
                x.push_str(&format!("<Entry><Index>#x{i:X}</Index><SubIndex>{s}</SubIndex><BitLen>{b}</BitLen></Entry>"));
            }
            x.push_str(&format!("</{tag}>"));
        }
        x.push_str(
            "<Mailbox><CoE/></Mailbox><Profile><ProfileNo>402</ProfileNo><Dictionary><DataTypes>",
        );
        x.push_str("<DataType><Name>DT7001</Name><BitSize>32</BitSize>\
            <SubItem><SubIdx>1</SubIdx><Name>TP1 Enable</Name><Type>BOOL</Type><BitSize>1</BitSize><BitOffs>16</BitOffs><Flags><PdoMapping>R</PdoMapping></Flags></SubItem>\
            <SubItem><SubIdx>5</SubIdx><Name>TP1 Enable pos edge</Name><Type>BOOL</Type><BitSize>1</BitSize><BitOffs>20</BitOffs><Flags><PdoMapping>R</PdoMapping></Flags></SubItem>\
            </DataType></DataTypes><Objects>");
        for &(index, name, ty, bits, mapping) in objects {
            x.push_str(&format!(
                "<Object><Index>#x{index:X}</Index><Name>{name}</Name><Type>{ty}</Type><BitSize>{bits}</BitSize>\
                 <Flags><Access>rw</Access><PdoMapping>{mapping}</PdoMapping></Flags></Object>"
            ));
        }
        x.push_str(
            "</Objects></Dictionary></Profile></Device></Devices></Descriptions></EtherCATInfo>",
        );
        crate::esi::parse(&x, "t.xml").unwrap_or_else(|e| panic!("{e}\n{x}"))
    }

    const CIA: &[(u16, &str, &str, u32, &str)] = &[
        (0x6040, "Controlword", "UINT", 16, "R"),
        (0x607A, "Target position", "DINT", 32, "R"),
        (0x6041, "Statusword", "UINT", 16, "T"),
        (0x6064, "Position actual value", "DINT", 32, "T"),
    ];

    /// All PDOs fixed: the one with every required role is taken, never together with a PDO
    /// it excludes; the default-assigned one wins a tie; a torque limit in it gets a value.
    #[test]
    fn fixed_pdos_chosen_among_alternatives() {
        let f = esi(
            CIA,
            &[
                (true, 0x1700, true, Some(2), &[0x1701], &[(0x6040, 0, 16)]),
                (
                    true,
                    0x1701,
                    true,
                    None,
                    &[0x1700],
                    &[
                        (0x6040, 0, 16),
                        (0x607A, 0, 32),
                        (0x0, 0, 8),
                        (0x6072, 0, 16),
                    ],
                ),
                (
                    false,
                    0x1B00,
                    true,
                    Some(3),
                    &[],
                    &[(0x6041, 0, 16), (0x6064, 0, 32)],
                ),
                (
                    false,
                    0x1B01,
                    true,
                    None,
                    &[],
                    &[(0x6041, 0, 16), (0x6064, 0, 32)],
                ),
            ],
        );
        let p = plan(&f.devices[0]).unwrap();
        assert_eq!((p.rx.pdos.as_slice(), p.rx.fixed), (&[0x1701][..], true));
        assert_eq!(p.rx.entries[2], EntrySpec::gap(8));
        assert_eq!(p.rx.defaults.len(), 1);
        assert_eq!((p.rx.defaults[0].0, p.rx.defaults[0].2), (0x6072, 65535));
        // Equal roles, equal bits: the PDO the ESI assigns by default.
        assert_eq!(p.tx.pdos, [0x1B00]);
    }

    /// No fixed PDO carries 0x607A: refused, naming it; a 0x6062 position set-point in a fixed
    /// RxPDO plays it instead (position interface).
    #[test]
    fn target_position_from_a_position_interface() {
        let without = esi(
            CIA,
            &[
                (true, 0x1700, true, Some(2), &[], &[(0x6040, 0, 16)]),
                (
                    false,
                    0x1B00,
                    true,
                    Some(3),
                    &[],
                    &[(0x6041, 0, 16), (0x6064, 0, 32)],
                ),
            ],
        );
        let e = plan(&without.devices[0]).unwrap_err();
        assert!(e.to_string().contains("0x607A:00 target position"), "{e}");
        let with = esi(
            CIA,
            &[
                (
                    true,
                    0x1701,
                    true,
                    Some(2),
                    &[],
                    &[(0x6062, 0, 32), (0x6040, 0, 16)],
                ),
                (
                    false,
                    0x1B00,
                    true,
                    Some(3),
                    &[],
                    &[(0x6041, 0, 16), (0x6064, 0, 32)],
                ),
            ],
        );
        let p = plan(&with.devices[0]).unwrap();
        let r = p.roles();
        assert_eq!((r[0].index, r[0].object), (0x607A, 0x6062));
    }

    /// A configurable PDO takes the roles' objects the dictionary marks mappable; a word of
    /// bits is mapped bit for bit with gaps, its role a 16-bit word from its first bit.
    #[test]
    fn configurable_pdo_and_a_word_of_bits() {
        let mut objects = CIA.to_vec();
        objects.push((0x7001, "FB Touch probe outputs", "DT7001", 32, ""));
        let f = esi(
            &objects,
            &[
                (true, 0x1600, false, Some(2), &[], &[(0x6040, 0, 16)]),
                (false, 0x1A00, false, Some(3), &[], &[(0x6041, 0, 16)]),
            ],
        );
        let sources = role_sources(&f.devices[0]);
        let tp = sources
            .iter()
            .find(|s| s.index == 0x60B8)
            .expect("a TP word");
        assert_eq!(tp.word, Some(16));
        assert_eq!(tp.parts.iter().map(|p| p.at).collect::<Vec<_>>(), [0, 4]);
        assert_eq!(
            role_entries(tp),
            [
                EntrySpec {
                    index: 0x7001,
                    sub: 1,
                    ty: DataType::U8,
                    bits: 1
                },
                EntrySpec::gap(3),
                EntrySpec {
                    index: 0x7001,
                    sub: 5,
                    ty: DataType::U8,
                    bits: 1
                },
                EntrySpec::gap(11),
            ]
        );
        let p = plan(&f.devices[0]).unwrap();
        assert_eq!((p.rx.pdos.as_slice(), p.rx.fixed), (&[0x1600][..], false));
        // Without a status word the touch probe is incomplete and left out.
        assert!(p.source(0x60B8).is_none());
        assert!(p.rx.entries.iter().all(|e| e.index != 0x7001));
    }
}
