//! Modular devices (ETG.2000 `Descriptions/Modules/Module`, `Device/Slots`) and the resolved
//! device: the device with one module per slot instance, its PDOs and objects laid out as a
//! configurator lays them out.
//!
//! Rules of [`Device::resolve`]:
//! * Slot instances are numbered from 0 in file order: each `Slot` element takes
//!   `MinInstances` instances by default (absent: 1), at most `MaxInstances`.
//! * A module's PDO whose `Index` has `DependOnSlot="true"` gets index + slot × `SlotPdoIncrement`;
//!   a PDO entry's or dictionary object's `Index` with `DependOnSlot` gets index + slot ×
//!   `SlotIndexIncrement` (the `Slot`'s own attribute where it has one, else the `Slots`'). So
//!   the Eyou module `#x119800` in slot 0 maps RxPDO 0x1600 with 0x6040…, in slot 1 it would be
//!   0x1610 with 0x6840… (`SlotPdoIncrement` 16, `SlotIndexIncrement` #x800). Gaps (index 0)
//!   never move.
//! * The modules' PDOs follow the device's own, slot by slot; their dictionaries' objects are
//!   added to the device's (an object the device already has is kept as the device has it).
//! * Without a choice a slot instance gets the slot's default module (`ModuleIdent
//!   Default="1"`); a slot with none is an error naming the slot and its choices.
//! * Not modelled: slot groups (`SlotGroupIndexIncrement`, `DependOnSlotGroup`), module
//!   `Mailbox/InitCmd`s, `ModulePdoGroup` alignment.

use super::{Device, LocalName, Pdo, Profile};
use crate::limits::{MAX_ESI_RESOLVED_ITEMS, MAX_ESI_SLOT_INSTANCES};
use std::collections::HashSet;
use std::sync::Arc;

/// `Descriptions/Modules/Module`.
#[derive(Debug, Clone, PartialEq)]
pub struct Module {
    /// `Type` text (e.g. `Axis (csv,csp,cst)`).
    pub type_name: String,
    /// `Type ModuleIdent`: the number a slot names it by (and the device reports in 0xF050).
    pub ident: u32,
    /// `Type ModuleClass`, if given.
    pub class: Option<String>,
    /// `Name` elements.
    pub names: Vec<LocalName>,
    /// `RxPdo` elements.
    pub rx_pdos: Vec<Pdo>,
    /// `TxPdo` elements.
    pub tx_pdos: Vec<Pdo>,
    /// `Profile`, if given.
    pub profile: Option<Profile>,
}

/// `Device/Slots`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Slots {
    /// `SlotIndexIncrement` (0 when absent).
    pub slot_index_increment: u32,
    /// `SlotPdoIncrement` (0 when absent).
    pub slot_pdo_increment: u32,
    /// `Slot` elements.
    pub slots: Vec<Slot>,
}

/// `Slots/Slot`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Slot {
    /// `Name` (first one), empty if absent.
    pub name: String,
    /// `MinInstances` (1 when absent).
    pub min_instances: u32,
    /// `MaxInstances` (1 when absent).
    pub max_instances: u32,
    /// `SlotIndexIncrement` of this slot, if it has its own.
    pub slot_index_increment: Option<u32>,
    /// `SlotPdoIncrement` of this slot, if it has its own.
    pub slot_pdo_increment: Option<u32>,
    /// `ModuleIdent` elements: the modules this slot takes.
    pub modules: Vec<SlotModule>,
    /// `ModuleClass` elements: further modules it takes, by class.
    pub classes: Vec<String>,
}

/// `Slot/ModuleIdent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotModule {
    /// The module's `ModuleIdent`.
    pub ident: u32,
    /// `Default="1"`: the module the slot has when nobody chooses.
    pub default: bool,
}

/// A module in a slot instance of a resolved device.
#[derive(Debug, Clone, PartialEq)]
pub struct PluggedModule {
    /// Slot instance number (0-based; the factor of the increments).
    pub slot: u32,
    /// The `Slot`'s name.
    pub slot_name: String,
    /// `ModuleIdent`.
    pub ident: u32,
    /// The module's `Type` text.
    pub type_name: String,
    /// The module's profile (its dictionary merged into the device's).
    pub profile: Option<Profile>,
}

/// Which module a slot instance gets (the `+MODULE` parts of a
/// [`Selector`](super::Selector)).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModuleChoice {
    /// The slot's default module (an empty `+` part).
    Default,
    /// By `ModuleIdent`.
    Ident(u32),
    /// By `Type` text (case-insensitive).
    Name(String),
}

impl std::fmt::Display for ModuleChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModuleChoice::Default => write!(f, "(default)"),
            ModuleChoice::Ident(i) => write!(f, "#x{i:X}"),
            ModuleChoice::Name(n) => write!(f, "{n}"),
        }
    }
}

/// Why a device cannot be resolved with the modules asked for.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ModuleError {
    /// Modules were named for a device without slots.
    #[error("the device has no slots; it takes no modules")]
    NotModular {
        /// Device type name.
        device: String,
    },
    /// More modules than the slots take.
    #[error("the device takes at most {max} module(s) ({slots}), {given} given")]
    TooMany {
        /// Device type name.
        device: String,
        /// Modules given.
        given: usize,
        /// Slot instances the device has room for.
        max: usize,
        /// The slots, for the message.
        slots: String,
    },
    /// A slot instance needs a module but its slot has no default.
    #[error("slot {slot} ({name}) has no default module; choose one of: {choices}")]
    NoDefault {
        /// Slot instance number.
        slot: u32,
        /// Slot name.
        name: String,
        /// The modules it takes.
        choices: String,
    },
    /// The module named is not one the slot takes.
    #[error("slot {slot} ({name}) does not take module {wanted}; it takes: {choices}")]
    NotInSlot {
        /// Slot instance number.
        slot: u32,
        /// Slot name.
        name: String,
        /// The module asked for.
        wanted: String,
        /// The modules it takes.
        choices: String,
    },
    /// A slot names a `ModuleIdent` the file has no `Module` for.
    #[error("slot {slot} ({name}): the file has no module with ModuleIdent #x{ident:X}")]
    MissingModule {
        /// Slot instance number.
        slot: u32,
        /// Slot name.
        name: String,
        /// The ident.
        ident: u32,
    },
    /// Index arithmetic leaves the 16-bit range, or too many slot instances.
    #[error("slot {slot} ({name}): {what}")]
    Layout {
        /// Slot instance number.
        slot: u32,
        /// Slot name.
        name: String,
        /// What does not fit.
        what: String,
    },
}

impl Slot {
    fn default_ident(&self) -> Option<u32> {
        self.modules.iter().find(|m| m.default).map(|m| m.ident)
    }
}

impl Device {
    /// The module the file has with this `ModuleIdent`.
    pub fn module(&self, ident: u32) -> Option<&Arc<Module>> {
        self.modules.iter().find(|m| m.ident == ident)
    }

    /// The modules the slots take (by ident and by class), in file order.
    fn slot_choices(&self, slot: &Slot) -> Vec<&Arc<Module>> {
        self.modules
            .iter()
            .filter(|m| {
                slot.modules.iter().any(|s| s.ident == m.ident)
                    || m.class.as_ref().is_some_and(|c| slot.classes.contains(c))
            })
            .collect()
    }

    /// The default module of each default slot instance (`MinInstances` per slot, the module
    /// marked `Default="1"`); slots without a default or whose default the file lacks are
    /// skipped. Empty for a device without slots.
    pub fn default_modules(&self) -> Vec<&Arc<Module>> {
        let Some(slots) = &self.slots else {
            return Vec::new();
        };
        slots
            .slots
            .iter()
            .flat_map(|s| {
                let m = s.default_ident().and_then(|i| self.module(i));
                let n = s.min_instances.min(MAX_ESI_SLOT_INSTANCES as u32) as usize;
                std::iter::repeat_n(m, n)
            })
            .flatten()
            .collect()
    }

    /// This device with a module in each slot instance, laid out per the module docs. `choices`
    /// are taken in slot order; fewer choices than slot instances: the rest get their
    /// defaults. A device without slots and no choices resolves to itself. Resolving a resolved
    /// device again returns it unchanged (with no choices).
    pub fn resolve(&self, choices: &[ModuleChoice]) -> Result<Device, ModuleError> {
        let Some(slots) = self.slots.as_ref().filter(|_| self.plugged.is_none()) else {
            if !choices.is_empty() {
                return Err(ModuleError::NotModular {
                    device: self.type_name.clone(),
                });
            }
            return Ok(self.clone());
        };
        let max: usize = slots.slots.iter().map(|s| s.max_instances as usize).sum();
        if choices.len() > max {
            return Err(ModuleError::TooMany {
                device: self.type_name.clone(),
                given: choices.len(),
                max,
                slots: slots
                    .slots
                    .iter()
                    .map(|s| format!("{}: {}..{}", s.name, s.min_instances, s.max_instances))
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        let mut out = self.clone();
        let mut plugged = Vec::new();
        let mut next = choices.iter();
        let mut left = choices.len();
        let mut slot_no: u32 = 0;
        let mut items = 0usize;
        for (si, slot) in slots.slots.iter().enumerate() {
            // instances of this slot: its minimum, more while choices remain that the later
            // slots' minimums do not need
            let later_min: usize = slots.slots[si + 1..]
                .iter()
                .map(|s| s.min_instances as usize)
                .sum();
            let min = slot.min_instances as usize;
            let extra = left.saturating_sub(later_min).saturating_sub(min);
            let room = (slot.max_instances as usize).saturating_sub(min);
            let n = min + extra.min(room);
            for _ in 0..n {
                if slot_no as usize >= MAX_ESI_SLOT_INSTANCES {
                    return Err(ModuleError::Layout {
                        slot: slot_no,
                        name: slot.name.clone(),
                        what: format!(
                            "more than {MAX_ESI_SLOT_INSTANCES} slot instances (docs/limits.md)"
                        ),
                    });
                }
                let choice = next.next().unwrap_or(&ModuleChoice::Default);
                left = left.saturating_sub(1);
                let module = self.pick(slot, slot_no, choice)?;
                items += module_items(module);
                if items > MAX_ESI_RESOLVED_ITEMS {
                    return Err(ModuleError::Layout {
                        slot: slot_no,
                        name: slot.name.clone(),
                        what: format!(
                            "the modules add more than {MAX_ESI_RESOLVED_ITEMS} PDO entries and \
                             objects (docs/limits.md)"
                        ),
                    });
                }
                plug(&mut out, slots, slot, slot_no, module)?;
                plugged.push(PluggedModule {
                    slot: slot_no,
                    slot_name: slot.name.clone(),
                    ident: module.ident,
                    type_name: module.type_name.clone(),
                    profile: module.profile.as_ref().map(|p| Profile {
                        dictionary: None,
                        ..p.clone()
                    }),
                });
                slot_no += 1;
            }
        }
        out.plugged = Some(plugged);
        Ok(out)
    }

    /// The module `choice` names for slot instance `slot_no` of `slot`.
    fn pick(
        &self,
        slot: &Slot,
        slot_no: u32,
        choice: &ModuleChoice,
    ) -> Result<&Module, ModuleError> {
        let choices = self.slot_choices(slot);
        let list = || {
            let mut v: Vec<String> = slot
                .modules
                .iter()
                .map(|s| {
                    let name = self
                        .module(s.ident)
                        .map(|m| format!(" {}", m.type_name))
                        .unwrap_or_default();
                    let def = if s.default { " (default)" } else { "" };
                    format!("#x{:X}{name}{def}", s.ident)
                })
                .collect();
            v.extend(
                choices
                    .iter()
                    .filter(|m| !slot.modules.iter().any(|s| s.ident == m.ident))
                    .map(|m| format!("#x{:X} {}", m.ident, m.type_name)),
            );
            if v.is_empty() {
                "no modules".to_string()
            } else {
                v.join(", ")
            }
        };
        let ident = match choice {
            ModuleChoice::Default => {
                slot.default_ident().ok_or_else(|| ModuleError::NoDefault {
                    slot: slot_no,
                    name: slot.name.clone(),
                    choices: list(),
                })?
            }
            ModuleChoice::Ident(i) => *i,
            ModuleChoice::Name(n) => choices
                .iter()
                .find(|m| m.type_name.trim().eq_ignore_ascii_case(n.trim()))
                .map(|m| m.ident)
                .ok_or_else(|| ModuleError::NotInSlot {
                    slot: slot_no,
                    name: slot.name.clone(),
                    wanted: n.clone(),
                    choices: list(),
                })?,
        };
        if let Some(m) = choices.iter().find(|m| m.ident == ident) {
            return Ok(m);
        }
        if slot.modules.iter().any(|s| s.ident == ident) {
            return Err(ModuleError::MissingModule {
                slot: slot_no,
                name: slot.name.clone(),
                ident,
            });
        }
        Err(ModuleError::NotInSlot {
            slot: slot_no,
            name: slot.name.clone(),
            wanted: format!("#x{ident:X}"),
            choices: list(),
        })
    }
}

/// PDO entries and dictionary objects a module adds to a device.
fn module_items(m: &Module) -> usize {
    let entries: usize = m
        .rx_pdos
        .iter()
        .chain(&m.tx_pdos)
        .map(|p| p.entries.len() + 1)
        .sum();
    let objects = m
        .profile
        .as_ref()
        .and_then(|p| p.dictionary.as_ref())
        .map_or(0, |d| d.objects.len() + d.data_types.len());
    entries + objects
}

/// Add `module` in slot instance `slot_no` to `out`: PDOs and dictionary objects, moved.
fn plug(
    out: &mut Device,
    slots: &Slots,
    slot: &Slot,
    slot_no: u32,
    module: &Module,
) -> Result<(), ModuleError> {
    let pdo_inc = slot.slot_pdo_increment.unwrap_or(slots.slot_pdo_increment);
    let index_inc = slot
        .slot_index_increment
        .unwrap_or(slots.slot_index_increment);
    let moved = |index: u16, depends: bool, inc: u32, what: &str| -> Result<u16, ModuleError> {
        if !depends || index == 0 {
            return Ok(index);
        }
        u64::from(slot_no)
            .checked_mul(u64::from(inc))
            .and_then(|d| u64::from(index).checked_add(d))
            .and_then(|v| u16::try_from(v).ok())
            .ok_or_else(|| ModuleError::Layout {
                slot: slot_no,
                name: slot.name.clone(),
                what: format!("{what} #x{index:04X} + {slot_no} × {inc} is beyond #xFFFF"),
            })
    };
    let shift = |p: &Pdo| -> Result<Pdo, ModuleError> {
        let mut p = p.clone();
        p.index = moved(p.index, p.depend_on_slot, pdo_inc, "PDO index")?;
        for e in &mut p.entries {
            e.index = moved(e.index, e.depend_on_slot, index_inc, "PDO entry index")?;
        }
        Ok(p)
    };
    for p in &module.rx_pdos {
        out.rx_pdos.push(shift(p)?);
    }
    for p in &module.tx_pdos {
        out.tx_pdos.push(shift(p)?);
    }
    if let Some(dict) = module.profile.as_ref().and_then(|p| p.dictionary.as_ref()) {
        let profile = out.profile.get_or_insert_with(|| Profile {
            profile_no: None,
            add_info: None,
            channels: Vec::new(),
            dictionary: None,
        });
        let target = profile.dictionary.get_or_insert_with(Default::default);
        let mut types: HashSet<String> = target.data_types.iter().map(|t| t.name.clone()).collect();
        for t in &dict.data_types {
            if types.insert(t.name.clone()) {
                target.data_types.push(t.clone());
            }
        }
        let mut have: HashSet<u16> = target.objects.iter().map(|o| o.index).collect();
        for o in &dict.objects {
            let index = moved(o.index, o.depend_on_slot, index_inc, "object index")?;
            if have.insert(index) {
                let mut o = o.clone();
                o.index = index;
                target.objects.push(o);
            }
        }
    }
    Ok(())
}
